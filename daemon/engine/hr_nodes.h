/*
 * hr_nodes.h -- uniform view of link endpoints for the hierarchical
 * solvers: a tagged id is a surface element, a cluster or a light, and the
 * refinement code asks each the same questions (where, how big, how
 * bright, can it split, what are its children) and gets form factors for
 * any pair.  Clusters are seen through their projected area (hier.h),
 * not the isotropic volume (area A/4 everywhere) of docs/ALGORITHM.md §4.6.
 */
#ifndef LUXRAD_HR_NODES_H
#define LUXRAD_HR_NODES_H

#include "ff.h"
#include "hier.h"
#include "solver.h"

static inline int node_is_cluster(uint32_t t)
{
	return (t & RAD_TAG_CLUSTER) != 0;
}
static inline int node_is_light(uint32_t t)
{
	return (t & RAD_TAG_LIGHT) != 0;
}
static inline uint32_t node_index(uint32_t t)
{
	return t & ~RAD_TAG_MASK;
}

/* Photopic radiosity of a source node (a light: its intensity). */
double node_luma_B(const rad_hier *h, uint32_t t);
/* RGB radiosity of a source node, as doubles: the radiosity its links'
 * form factors are made for (a partly covered element: node_exposed_emission).
 */
void node_B(const rad_hier *h, uint32_t t, double out[3]);
/*
 * A partly covered element sends only from its exposed points (hier.h,
 * Covered parts), where its mean reflected radiosity stands for what the
 * exposed part reflects but its emission E would count the covered part's
 * as well: b -= (1 - exposed) E.  Nothing changes on an element wholly
 * exposed.
 */
void node_exposed_emission(const rad_hier *h, uint32_t t, double b[3]);
/* Area that turns the node's irradiance into received flux. */
double node_area_eff(const rad_hier *h, uint32_t t);
/* 1 if the node can be split into children. */
int node_splittable(const rad_hier *h, uint32_t t);
/* Characteristic length: longest edge (element), box diagonal (cluster). */
double node_size(const rad_hier *h, uint32_t t);
/* Centre of a surface or cluster node: the element's centroid, the
 * cluster's box centre. */
v3 node_center(const rad_hier *h, uint32_t t);
/* 1 if the larger of two surface or cluster nodes is larger (node_size)
 * than the distance between their centres: the link audit's "near". */
int node_near(const rad_hier *h, uint32_t a, uint32_t b);
/*
 * Children of a splittable node, tagged, into out[RAD_CLUSTER_LEAF_MAX]
 * (elements are split on demand: not thread-safe).  Returns the count, 0
 * when out of memory.
 */
int node_children(rad_hier *h, uint32_t t, uint32_t out[RAD_CLUSTER_LEAF_MAX]);

/* 0 when src cannot send anything to rcv (both sides face away). */
int node_facing(const rad_hier *h, uint32_t rcv, uint32_t src);
/*
 * Upper bound of F(rcv <- src) from the gap between the two bounding
 * boxes, whatever the orientations inside (1 when the boxes touch).
 */
double node_ff_bound(const rad_hier *h, uint32_t rcv, uint32_t src);
/* Cheap unoccluded estimate of F(rcv <- src), for the oracle. */
double node_ff_estimate(const rad_hier *h, uint32_t rcv, uint32_t src);
/*
 * F(rcv <- src) with visibility (see rad_link.ff), and its spread over the
 * receiver's points (0 for a cluster receiver, which has no variation to
 * resolve: it is isotropic).  Thread-safe.
 */
double node_ff(const rad_solver *sv, uint32_t rcv, uint32_t src, uint64_t *rays,
               double *spread);

/*
 * Oracle value of a transfer of form factor f from a source of photopic
 * radiosity b (hr: B, rmb: the radiosity still to transmit), in units of
 * eps (see rad_options.eps).  Cluster ends count at their worst (x4).
 */
double node_oracle(const rad_solver *sv, uint32_t rcv, uint32_t src, double b,
                   double f);
/*
 * Study statistics of one exchange of form factor ff from src to rcv:
 * counts it in S as gathered, as useful when its increment (photopic inc)
 * would fail the oracle one level up, and in the energy histogram by
 * what it carries (photopic radiosity b).  See rad_stats.
 */
void node_stat_exchange(const rad_solver *sv, rad_stats *S, uint32_t r,
                        uint32_t s, double ff, double b, double inc);
/* Count a stored link rcv <- src in s->links and its kind (links_ss ...
 * light). */
void node_count_link(rad_stats *s, uint32_t rcv, uint32_t src);
/*
 * The factor a link's form factor is used with when src is a cluster: what
 * it sends towards rcv against its mean radiosity (delta: dB) times its
 * projected area (rad_cluster_emit); 1 for any other source.
 */
double node_emit_factor(const rad_hier *h, uint32_t rcv, uint32_t src,
                        int delta);
/*
 * What src sends to rcv in a gather: out = its B (delta 0, node_B) or dB
 * (1, a cluster's; a surface's or light's the caller's own), and the
 * factor node_emit_factor returns, from one summing of a leaf cluster's
 * dB and ndB (rad_cluster_delta).
 */
double node_sends(const rad_hier *h, uint32_t rcv, uint32_t src, int delta,
                  double out[3]);
/*
 * After a gather of photopic value e (power per unit area) by a cluster
 * receiver from src: record its direction for the push in the cluster's
 * flux f (hier.h).  Does nothing for a surface receiver (f NULL).  Not
 * thread-safe per receiver.
 */
void node_took(const rad_hier *h, rad_cluster_flux *f, uint32_t rcv,
               uint32_t src, double e);
/*
 * Energy bound shared by hr and rmb: what receivers took from surfaces in
 * one step (got, A I per channel) against what the polygons sent (their
 * pulled B, or dB when delta): k[c] = sent / got where got exceeds it,
 * else 1.  Returns the smallest k (1: the bound holds).
 */
double node_energy_scale(const rad_hier *h, int delta, const double got[3],
                         double k[3]);
/*
 * The tail jump shared by hr and rmb (hr.c explains it).  chg holds
 * sum A |dB| per channel of the last three steps, newest first (3 x 3).
 * node_tail_rates sets q[c] to the rate of each channel that shrinks
 * steadily by more than half a step (0 for the others) and returns 1,
 * or returns 0 when a slow channel is not steady yet.  node_tail_add
 * gives every leaf dB q / (1 - q), pulls, and returns the new area-mean
 * photopic B (the solvers' refinement budgets are relative to it).
 */
int node_tail_rates(const double *chg, double q[3]);
double node_tail_add(rad_hier *h, const double q[3]);
/* Surface area of a node (0 for a light). */
double node_area(const rad_hier *h, uint32_t t);
#endif
