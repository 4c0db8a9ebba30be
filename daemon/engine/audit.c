/*
 * audit.c -- the links of an hr or rmb solution against Monte Carlo
 * (rad_reference.h).
 *
 * Each audited link's transfer, A_r F(r <- s) times the source's
 * radiosity, is estimated again by sampling point pairs: a receiver point
 * (uniform over an element, or on a cluster's polygons by area, with the
 * polygon's normal), a source point likewise, the point kernel
 * cos cos / (pi r^2) and one shadow ray.  Nothing of ff.c or hr_nodes.c's
 * form factors is used, only the scene, its BVH and the hierarchy's
 * geometry.  Two sums come out per link: with the source's mean radiosity
 * (the form factor alone) and with the radiosity of the leaf or polygon
 * each source sample falls on (what the link should move, given how the
 * source's light is spread over it).
 *
 * Random numbers: a splitmix64 stream keyed by (seed, link id), so the
 * result depends on neither threads nor call order.
 */
#include <math.h>
#include <string.h>

#include "hr.h"
#include "hr_nodes.h"
#include "rad_reference.h"
#include "rmb.h"
#include "rng.h"
#include "solver.h"
#include "vis.h"

static v3 patch_point(const rad_patch *p, uint64_t *s)
{
	double a = rad_uniform(s), b = rad_uniform(s);
	if (!p->quad && a + b > 1) {
		a = 1 - a;
		b = 1 - b;
	}
	return v3_madd(v3_madd(p->p0, p->e1, a), p->e2, b);
}

/* The leaf under element id where a uniform point falls (children split
 * their parent into four equal areas), into *leaf; its patch into p. */
static void leaf_patch(const rad_hier *h, uint32_t id, uint64_t *s,
                       rad_patch *p, uint32_t *leaf)
{
	const rad_elem *e = rad_elem_at(h, id);
	while (!rad_elem_is_leaf(e)) {
		uint32_t k = (uint32_t)(rad_uniform(s) * 4);
		id = e->child + (k > 3 ? 3 : k);
		e = rad_elem_at(h, id);
	}
	rad_elem_patch(h, id, p);
	*leaf = id;
}

/* A polygon of cluster t by area (cum: prefix areas of its range). */
static uint32_t cluster_poly(const rad_hier *h, const rad_cluster *c,
                             const double *cum, uint64_t *s)
{
	double t = rad_uniform(s) * cum[c->count];
	uint32_t lo = 0, hi = c->count - 1;
	while (lo < hi) {
		uint32_t mid = lo + (hi - lo + 1) / 2;
		if (cum[mid] <= t)
			lo = mid;
		else
			hi = mid - 1;
	}
	return h->order[c->first + lo];
}

static void cluster_cum(const rad_hier *h, const rad_cluster *c, double *cum)
{
	cum[0] = 0;
	for (uint32_t i = 0; i < c->count; i++)
		cum[i + 1] =
		        cum[i] + h->scene->polys[h->order[c->first + i]].area;
}

/* A sample point of node t with its normal and the photopic radiosity
 * there (the leaf's or, in a cluster, the polygon's leaf). */
static v3 node_sample(const rad_hier *h, uint32_t t, const double *cum,
                      uint64_t *s, v3 *n, double *b)
{
	rad_patch p;
	uint32_t leaf;
	uint32_t root = node_is_cluster(t)
	                        ? cluster_poly(h, rad_cluster_at(h, t), cum, s)
	                        : t;
	leaf_patch(h, root, s, &p, &leaf);
	*n = p.n;
	*b = rad_luma(rad_elem_at(h, leaf)->B);
	return patch_point(&p, s);
}

/* One link r <- s of form factor ff: its sums into its class. */
static void audit_link(const rad_solver *sv, uint32_t r, uint32_t s, double ff,
                       uint32_t id, const rad_audit_options *o, double *cum_r,
                       double *cum_s, rad_audit *out)
{
	const rad_hier *h = &sv->h;
	int k = 4 * node_near(h, r, s) + 2 * node_is_cluster(r) +
	        node_is_cluster(s);
	double ar = node_area(h, r), as = node_area(h, s);
	double bs = node_luma_B(h, s);
	if (node_is_cluster(r))
		cluster_cum(h, rad_cluster_at(h, r), cum_r);
	if (node_is_cluster(s))
		cluster_cum(h, rad_cluster_at(h, s), cum_s);
	uint64_t st = rad_mix64(o->seed ^ rad_mix64(id));
	double form = 0, transfer = 0;
	for (unsigned i = 0; i < o->samples; i++) {
		v3 nx, ny;
		double bx, by;
		v3 x = node_sample(h, r, cum_r, &st, &nx, &bx);
		v3 y = node_sample(h, s, cum_s, &st, &ny, &by);
		v3 d = v3_sub(y, x);
		double d2 = v3_dot(d, d);
		double c1 = v3_dot(d, nx), c2 = -v3_dot(d, ny);
		if (!(d2 > 0) || c1 <= 0 || c2 <= 0)
			continue;
		out->rays++;
		if (!rad_vis_segment(sv->scene->vis, x, &nx, y, &ny))
			continue;
		double kern = c1 * c2 / (M_PI * d2 * d2);
		form += kern;
		transfer += kern * by;
	}
	double n = o->samples;
	rad_audit_class *c = &out->cls[k];
	c->links++;
	c->stored_form += ar * ff * bs;
	c->stored_transfer += ar * ff * node_emit_factor(h, r, s, 0) * bs;
	c->mc_form += ar * as * form / n * bs;
	c->mc_transfer += ar * as * transfer / n;
}

void rad_audit_options_default(rad_audit_options *o)
{
	o->every = 10;
	o->samples = 64;
	o->seed = 1;
}

typedef struct audit_walk {
	const rad_solver *sv;
	const rad_audit_options *o;
	rad_audit *out;
	double *cum_r, *cum_s;
	uint64_t seen;
} audit_walk;

/* One gathered link, if it is the one in `every` to audit. */
static void visit(audit_walk *w, uint32_t r, uint32_t s, double ff, uint32_t id)
{
	/* Not from a light: its transfer is exact already. */
	if (!node_is_light(s) && w->seen++ % w->o->every == 0)
		audit_link(w->sv, r, s, ff, id, w->o, w->cum_r, w->cum_s,
		           w->out);
}

/* rmb: the leaves of the link hierarchy under link id are what it
 * gathers (rmb.h). */
static void walk_tree(audit_walk *w, uint32_t id)
{
	const rad_link *l = rad_link_at(&w->sv->h, id);
	uint32_t n, child = rad_link_child(&w->sv->h, l, &n);
	if (n == 0) {
		visit(w, l->rcv, l->src, l->ff, id);
		return;
	}
	for (uint32_t k = 0; k < n; k++)
		walk_tree(w, child + k);
}

/* hr: the links node t receives (hr_walk_all visits every node). */
static rad_status node_links(rad_solver *sv, void *ud, uint32_t t)
{
	const rad_hier *h = &sv->h;
	for (uint32_t id = rad_hlist_live(h, *rad_node_links(h, t));
	     id != RAD_NONE; id = rad_hlist_next(h, id)) {
		const rad_hlink *l = rad_hlink_at(h, id);
		visit(ud, t, rad_hlink_src(l), rad_hlink_ff(l), id);
	}
	return RAD_OK;
}

rad_status rad_solver_audit_links(rad_solver *sv, const rad_audit_options *o,
                                  rad_audit *out, rad_error *err)
{
	rad_audit_options def;
	if (!o) {
		rad_audit_options_default(&def);
		o = &def;
	}
	memset(out, 0, sizeof(*out));
	if (sv->opt.solver != RAD_SOLVER_HR && sv->opt.solver != RAD_SOLVER_RMB)
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "audit: matrix and progressive keep no links");
	if (o->every < 1 || o->samples < 1)
		return rad_fail(err, RAD_ERR_INVALID,
		                "audit: every and samples must be >= 1");
	if (!sv->scene->vis)
		return rad_fail(err, RAD_ERR_STATE, "audit: no visibility");
	size_t np = sv->scene->npolys + 1;
	double *cum = rad_mem_alloc(&sv->mem, RAD_MEM_SCRATCH,
	                            2 * np * sizeof(double));
	if (!cum)
		return rad_fail(err, RAD_ERR_NOMEM, "audit: out of memory");
	audit_walk w = {sv, o, out, cum, cum + np, 0};
	if (sv->opt.solver == RAD_SOLVER_RMB) {
		const rmb_state *st = sv->impl;
		for (size_t i = 0; i < st->nroots; i++)
			walk_tree(&w, st->roots[i]);
	} else {
		hr_walk_all(sv, node_links, &w);
	}
	out->links_total = w.seen;
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, cum);
	return RAD_OK;
}
