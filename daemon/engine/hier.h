/*
 * hier.h -- the element hierarchy and the link store shared by all solvers.
 *
 * DESIGN
 * Three pools, each of fixed-size records addressed by 32-bit ids that
 * never move (mem.h):
 *   - surface elements (rad_elem): the quadtree of each input polygon.
 *     Ids 0 .. npolys-1 are the roots, one per scene polygon, same index.
 *     The four children of an element are stored together (child .. child+3).
 *   - clusters (rad_cluster): a binary volume hierarchy over all polygons
 *     up to one root cluster (id 0).  An inner cluster has two child
 *     clusters (child, child+1); a leaf cluster holds
 *     RAD_CLUSTER_LEAF_MAX polygons (the last leaf of the order may hold
 *     fewer), a contiguous range of order[].
 *     Every cluster covers a contiguous range of order[], so "the polygons
 *     in this cluster" is a range, never a list walk.
 *   - links: receiver <- source transfers with their form factor, of
 *     one of two kinds.  Classic HR (rad_hlink, 8 bytes) keeps them on
 *     their receiver's list, which says whose they are, packed in blocks
 *     of their own (Packed lists); the lists' heads are hr's alone, not a
 *     field of every element and cluster record (Leaves and lists).  The
 *     reduced-memory
 *     solver (rad_link, 16 bytes) keeps no lists; a link names both its
 *     ends, and a refined (passive) one keeps its children (consecutive
 *     records) for the link hierarchy.  Only passive links have
 *     children, so what says where they are (rad_link_ext, 12 bytes) is a
 *     record of a pool of its own (links_ext), named by the passive
 *     link in place of its spread, which moves there with it.  Active
 *     links -- two thirds of those rmb keeps -- are 16 bytes where one
 *     record for both kinds made every link 24.
 *
 * Leaves and lists.  A leaf has no children, so its child field holds
 * its list's head (hr) or RAD_NONE: a list's links are named by their
 * ids with RAD_HLIST set (rad_hlist_ref; RAD_NONE ends a list), and a
 * child field with that bit set is a leaf's (rad_elem_is_leaf,
 * rad_cluster_is_leaf; pools hand out ids below RAD_POOL_MAX_ID, so
 * none has it).  An inner element's head is one word per sibling run,
 * that of its children (rad_hier.run_heads, in step with runs), and an
 * inner cluster's one per inner record (inner_heads).  With a word for
 * every node, hr's links (lists included) were 12.8 MB on the report's
 * grand hall and 19.0 MB on the 1M field (4 iterations); with these,
 * 11.4 and 15.3 MB.
 *
 * Packed lists.  A list is a chain of the links made since the lists
 * were last packed (rad_hlink_new in the links pool, 12 bytes: the link
 * and the reference after it), then a packed block: consecutive links
 * in rad_hier.pack (8 bytes), the last with RAD_HLINK_LAST.  A reference
 * to a new link is its id with RAD_HLIST; to a packed one, its offset
 * with RAD_HLIST and RAD_HBASE.  A list reads newest first, as a chain
 * prepended to does.  Refinement makes links anywhere and takes them
 * off anywhere: a new one is freed, a packed one marked dead
 * (RAD_HLINK_DEAD) and skipped.  hr packs the lists (hlist.c,
 * hr_pack_lists) at the end of every refinement, and during one once the
 * new links pass a quarter of the packed, so that the gather reads
 * packed blocks only, in walk order, and a list keeps its links and
 * their order: the same sums.  Measured (luxrad-solve, hr, 4 iterations,
 * 2 threads): links 11.4 -> 7.7 MB and peak 54.5 -> 51.6 MB on the
 * report's grand hall, 15.3 -> 10.4 and 145.0 -> 141.0 MB on the 1M
 * field.  The peak is the last packing's: the new links held while the
 * blocks grow to take them.
 *
 * Liveness: walk the trees (polygon roots 0 .. npolys-1, root cluster 0),
 * never a pool's id range: pools may hold records skipped so that sibling
 * runs stay inside one block, and records released to the free list.
 *
 * Node ids in links are tagged: a plain id is a surface element, id with
 * RAD_TAG_CLUSTER a cluster, id with RAD_TAG_LIGHT a scene light (lights are
 * sources only and are never split).
 *
 * Radiometry on nodes (RGB floats):
 *   B  radiosity (exitance, lux); on inner nodes the area average of the
 *      leaves below (pull); on clusters the area average of contents.
 *   I  irradiance gathered by the node's own links this iteration.  On a
 *      cluster it is the mean over its polygons' area (power / area: the
 *      power a cluster takes from direction u is its projected area P(u)
 *      times the normal irradiance), handed down by the push (below).
 *   dB radiosity still to transmit (reduced-memory solver); free for other
 *      solvers to use as "previous B" or "unshot radiosity".
 * Emission E and reflectance rho come from the polygon's material.
 *
 * Increments.  Only rmb sends dB: every step's light leaves from it, and
 * its tail jump reads the rate at which it shrinks, to 5e-5 at rho 0.999.
 * hr reads it for its statistics and its tail alone (B + dB q / (1 - q)).
 * So rmb's elements keep dB in three floats (records of
 * RAD_ELEM_EXACT_SIZE, 40 bytes) and every other solver's in 32 bits
 * (rad_shared3: a shared exponent, 7-bit signed mantissas), which makes
 * an element 32 bytes.  Packed, rmb lost the jump: the increments of a
 * closed box at rho 0.99 all round alike, their rate wanders by the
 * rounding (up to 1/128), and it ran 330 steps to end 9.2 % low.  hr's
 * tail takes the rounding of the dB it extrapolates: 313,728-313,846 lux
 * at the points of a closed box at rho 0.999, 313,916-314,034 with
 * floats (exact 314,159).
 * rad_elem_dB and rad_elem_set_dB read and write either form; a saved
 * solution keeps the packed one.
 *
 * Clusters are seen through their projected area (rad_cluster_proj).  The
 * area polygons i (areas A_i, unit normals n_i) show in direction d is
 *   P(d) = sum A_i max(0, n_i . d) = (N . d + Q(d)) / 2,
 *   N = sum A_i n_i,  Q(d) = sum A_i |n_i . d|,
 * and the even part Q is modelled from the second moment M = sum A_i n_i
 * n_i^T as Q(d) = q sqrt(d^T M d), q chosen so that Q integrates over the
 * sphere to 2 pi A as the true one does: q = A / (2 R_G(eigenvalues of
 * M)), R_G Carlson's symmetric elliptic integral, the sphere mean of
 * sqrt(d^T M d).  Exact for a flat cluster, one-sided (P = A cos+) or
 * two-sided (P = A |cos| / 2: the coincident opposite pairs that MGF and
 * many exporters write), and for a sphere-like one (A / 4 everywhere);
 * always exact in total (P integrates to pi A), so a cluster neither
 * makes nor loses energy.  Between those it is only a blend (a 3-face
 * "U" shows 0.3 A outwards where it shows nothing), so rad_cluster_proj
 * sums exact leaves and the models of clusters two levels down.
 *
 * Regions.  An element holds no geometry of its own.  Its region is its
 * polygon's (p0, e1, e2) quartered `level` times: `path` keeps the
 * quarter taken at each level (0..3; level l in bits 2l-2 and 2l-1), and
 * rad_elem_region redoes the float operations of each split in the same
 * order, so the region is bit for bit the one a stored copy would hold.
 * The area is the polygon's times 4^-level and the longest edge its
 * times 2^-level, both exact in floating point.  A 32-bit path caps the
 * depth at RAD_ELEM_MAX_LEVEL (16): an element's edge is then at least
 * 1/65536 of its polygon's, where the default min_edge stops refinement
 * at 1/200 of the scene's diagonal.  Storing the region (36 bytes) and
 * the area made an element 96 bytes.  Nor does an element keep its
 * parent (the walks come down the trees, and progressive's fresh
 * children carry theirs) or, but in its child field, hr's list head.
 * Runs.  What the four children of one split share -- their polygon,
 * their depth and their parent's path -- and the exposed fraction each
 * measured (below) are one record of the run (rad_elem_run, 16 bytes,
 * rad_hier.runs), not fields of every element: sibling runs start at
 * run0 (the roots' count rounded up to 4 in a solver's hierarchy, padded
 * with unused records) and are 4-aligned from there, so element id's
 * run is record (id - run0) / 4 and its quarter (id - run0) % 4.  A root
 * is its own polygon at depth 0 with path 0, and keeps its exposed
 * fraction in root_exposed.  An element is then 40 bytes (child, B, I,
 * dB), where every field in it made 52: on the grand hall, whose
 * elements are nearly all roots, hr's 16.6 MB of elements became 13.3
 * MB (42 bytes an element with the runs, the roots' bytes and the
 * blocks' slack).  Packing dB (Increments) makes it 32 but for rmb.
 * Covered parts.  Scenes lay panels, windows, luminaires and boards a
 * few millimetres in front of walls and ceilings.  The part of a surface
 * behind such a cover takes no light and sends none, and an element that
 * straddles its edge paid for it twice: its mean B was lowered by the dark
 * part, and its sample points behind the cover were blocked when it sent.
 * So an element keeps the fraction of its area that is exposed, `exposed`
 * / RAD_EXPOSED_ALL: the share of 16 scattered points (rad_patch_scatter;
 * a regular grid lines up with a regular layout of panels) with nothing
 * in front of them closer than rad_hier_cover_dist.  Then
 *   - as a source it is sampled on its exposed points only
 *     (rad_elem_keep_exposed): B, the mean over the whole element, times
 *     the form factor from its exposed part is the power that part sends
 *     with its own radiosity B / exposed (an emitter's E is the exposed
 *     part's own: node_exposed_emission);
 *   - as a receiver, a sample point that sees nothing of a source while
 *     another does is left out when covered, and the mean over the rest
 *     is scaled by the exposed fraction (rad_ff_rcv_mean): the form
 *     factor is then that of the exposed part, as the push hands it out,
 *     whatever share of the few points the cover happens to hold;
 *   - the push hands children shares of the parent's irradiance in
 *     proportion to their exposed fractions (a covered quarter takes none;
 *     the shares keep the power), and a cluster hands its polygons shares
 *     weighted by theirs;
 *   - the point query reads B / exposed, since its rays towards the
 *     covered part are blocked anyway, and the share of a leaf partly
 *     covered that a point sees on the points that measured `exposed`;
 *     it does not take an element partly covered whole (query.c).
 * Every quarter measures its own (16 short rays per element made): the
 * parent's 16 points can miss a cover that a quarter straddles.  A
 * 0.75 m luminaire 1 cm under a 4 m ceiling (luxrad-scenegen thinlum,
 * cove) held none of the ceiling's points; its quarters, which then
 * inherited "wholly exposed", paid for the luminaire twice, and hr kept
 * 87 % of the cove's power (test_furnished).  Measured on the bright hall
 * (16 panels 1 mm below the ceiling), its 0.8 m work plane at defaults
 * against luxrad-reference: hr -3.7 % at worst, 1.4 % on average before
 * covers were measured at all, -1.9 % and 0.9 % after.
 * The matrix and progressive baselines sample sources whole, as before.
 *
 * Solvers and the query both see clusters through rad_cluster_proj.
 * Sillion's isotropic model (A / 4 in every direction, and 1/4 of a
 * cluster's normal irradiance to each polygon inside) lost 59 % of the
 * light of a closed box whose walls are 16 x 16 quads (rho 0.7): a flat
 * wall cluster shows up to A to the wall facing it, not A / 4.
 *
 * Push.  A cluster knows the power it took (I times its area), not where
 * it came from, and handing every polygon the mean (what the projected
 * area alone allows) lights the backs of objects as much as their fronts
 * (not measured apart: a uniform hand-out moved the Graz office's second
 * bounce under rmb by 0.3 %, where clusters take little).  So the gather
 * also records where the irradiance came from: V, the sum of (photopic)
 * normal irradiance times the unit direction towards its source, and S,
 * the sum of the normal irradiances (S >= |V|; a source too close to have
 * one direction adds to S only).  A polygon of normal n is then given a
 * share proportional to
 *   w(n) = max(0, n . V) + (S - |V|) / 4,
 * the exact cos+ law for light from one direction plus Sillion's 1/4 for
 * what cancels out, and the shares are scaled so that the polygons take
 * exactly the power the cluster took: the push moves energy, it never
 * makes or loses any.  A child cluster's share is w integrated over its
 * polygons, P_child(V) + (S - |V|) A_child / 4.
 *
 * Emission.  A cluster sends sum A_i B_i max(0, n_i . d) / pi towards d,
 * not its mean B times P(d): a wall written as two coincident faces, lit
 * on one side only, sends with its lit face (B A_lit cos+), where the mean
 * (half of it) times P (A_lit |cos|) gives half of that, and as much
 * through the wall (measured: rmb's second bounce in the Graz office,
 * 3 % more taken with it).  The pull keeps nB = sum A_i luma(B_i) n_i
 * (and ndB for dB), the odd part of the exact sum, and the even part stays
 * the mean times the projected area's: the sent light is mean B times
 *   e(d) = P(d) + (nB / luma(B) - N) . d / 2,
 * exact for flat clusters lit on either side or both, clamped to
 * 0 .. A.  rad_cluster_emit returns e(d) / P(d) (at most 4), the factor
 * a link's form factor, made for uniform radiosity, is used with.
 */
#ifndef LUXRAD_HIER_H
#define LUXRAD_HIER_H

#include <stddef.h>
#include <string.h>

#include "ff.h"
#include "mem.h"
#include "par.h"
#include "scene.h"
#include "shared3.h"
#include "vec.h"

#define RAD_TAG_CLUSTER 0x80000000u
#define RAD_TAG_LIGHT 0x40000000u
#define RAD_TAG_MASK (RAD_TAG_CLUSTER | RAD_TAG_LIGHT)
#define RAD_CLUSTER_LEAF_MAX 4

typedef struct rad_elem {
	uint32_t child;   /* first of 4 children; a leaf's: its hr list's
	                     head, or RAD_NONE (Leaves and lists) */
	float B[3], I[3]; /* see DESIGN */
	rad_shared3 dB;   /* see DESIGN; read and write it with rad_elem_dB
	                     and rad_elem_set_dB (Increments) */
} rad_elem;

/* What the four children of one split share, and what each measured of
 * its own (Runs): one record per sibling run, rad_hier.runs. */
typedef struct rad_elem_run {
	uint32_t poly;      /* root polygon (geometry, material, normal) */
	uint32_t path;      /* the parent's path (Regions) */
	uint8_t level;      /* the children's depth below the root, >= 1 */
	uint8_t exposed[4]; /* child k's, 0 .. RAD_EXPOSED_ALL (Covered parts)
	                     */
	uint8_t spare[3];
} rad_elem_run;

typedef struct rad_cluster {
	float lo[3], hi[3];    /* bounding box of the contents */
	float area;            /* total area of the polygons inside */
	uint32_t child;        /* first of 2 child clusters; a leaf's: as
	                          rad_elem's */
	uint32_t first, count; /* range of order[] covered */
	float B[3];
	float nB[3]; /* sum of area x luma(B) x normal (pull) */
} rad_cluster;

/* What a cluster gathered in one step: its irradiance I, and V and S,
 * where it came from (DESIGN, push).  rmb gathers as it walks its links
 * and keeps one per cluster until the push (rad_hier.flux).  hr gathers
 * a cluster's links again when the push gets there (rad_push_own), so
 * its clusters hold none: 28 of a cluster's 104 bytes, 3.7 MB on the
 * report's grand hall and 10.3 MB on the 1M field (hr, 4 iterations). */
typedef struct rad_cluster_flux {
	float I[3];
	float V[3], S;
} rad_cluster_flux;

/* What an inner cluster has beside its rad_cluster.  A leaf holds at
 * most RAD_CLUSTER_LEAF_MAX polygons: its projected area is summed over
 * them and needs no model, its sum of area x normal, which only its
 * emission reads, is summed from them when asked (rad_cluster_normal,
 * right after the projected area read the same polygons), and its dB
 * and ndB, which only rmb's walk and hr's statistics read, are summed
 * from their root elements when asked (rad_cluster_delta), as the pull
 * would sum them.  So these are an array of their own, one per pair of
 * child clusters: half the tree's clusters are leaves, and every cluster
 * was 160 bytes with the model and 128 with dB and ndB.  B and nB, which
 * every gather reads, stay in every cluster: summing a leaf's in the
 * gather too made hr 3-8 % slower. */
typedef struct rad_cluster_inner {
	float m[6]; /* moment model: sum of area x n n^T, xx yy zz xy xz yz */
	float q;    /* scale of the even part */
	float n[3]; /* sum of area x unit normal, |n| <= area (a leaf's:
	               rad_cluster_normal) */
} rad_cluster_inner;

/* An inner cluster's increments, pulled from its two children: kept
 * (rad_hier.deltas, one per rad_cluster_inner) by rmb, which sends them
 * in every step.  hr reads only their photopic values, for its
 * statistics, and keeps those (8 bytes, not 24) only while it counts
 * (rad_hier_delta_lumas). */
typedef struct rad_cluster_deltas {
	float dB[3];  /* pulled from the two children */
	float ndB[3]; /* sum of area x luma(dB) x normal */
} rad_cluster_deltas;

/* Index of inner cluster c's record in rad_hier.inner: its children's
 * pair (ids child, child+1; every pair starts at least 2 after the one
 * before, so no two inner clusters share one). */
static inline uint32_t rad_cluster_inner_index(const rad_cluster *c)
{
	return (c->child - 1) / 2;
}

/* A link of the reduced-memory solver (rmb), active or passive. */
typedef struct rad_link {
	uint32_t rcv; /* tagged receiver id */
	uint32_t src; /* tagged source id */
	float ff;     /* F(rcv <- src), visibility included; for a light,
	                 irradiance (lux) per unit of its intensity */
	uint32_t aux; /* active: the bits of its spread, max - min of ff
	                 over the receiver's points (>= 0, so the sign bit
	                 is clear); passive: RAD_LINK_EXT | its ext's id */
} rad_link;

#define RAD_LINK_EXT 0x80000000u

/* What a passive link has beside its rad_link (links_ext). */
typedef struct rad_link_ext {
	float spread;       /* the link's spread */
	uint32_t child;     /* first of its consecutive children */
	uint16_t nchild;    /* how many */
	uint16_t split_src; /* 1: the source was split, 0: the receiver */
} rad_link_ext;

/* A link of classic HR, on its receiver's list (rad_node_links): in a
 * packed block, or, made since the lists were last packed, in a
 * rad_hlink_new (Packed lists). */
typedef struct rad_hlink {
	uint32_t srcl; /* tagged source id (rad_hlink_src), RAD_HLINK_LAST
	                  on a packed block's last link; RAD_HLINK_DEAD:
	                  taken off its list */
	uint32_t fs;   /* its ff and spread, as rad_link's, in 19 and 13 bits
	                  (rad_hlink_ff, rad_hlink_spread: Short floats) */
} rad_hlink;

/* A link made since the lists were last packed (rad_hier.links). */
typedef struct rad_hlink_new {
	rad_hlink l;
	uint32_t next; /* the reference after it on its list, or RAD_NONE */
} rad_hlink_new;

#define RAD_HLINK_LAST 0x20000000u /* in srcl: ids stay below it */
#define RAD_HLINK_DEAD RAD_TAG_MASK
static inline uint32_t rad_hlink_src(const rad_hlink *l)
{
	return l->srcl & ~RAD_HLINK_LAST;
}
static inline int rad_hlink_dead(const rad_hlink *l)
{
	return (l->srcl & RAD_TAG_MASK) == RAD_HLINK_DEAD;
}

/*
 * Short floats.  An hr link's form factor keeps a float's exponent and
 * its 11 leading mantissa bits (within 2^-12 of itself), its spread the
 * exponent and 5 (2^-6), both rounded to nearest: 19 and 13 bits, so that
 * a link is 8 bytes, not 16.  Both are >= 0 (the sign is dropped; a
 * negative value is stored as 0).  The form factor is fixed once the link
 * is made, so its rounding makes no noise from one step to the next; the
 * spread only ranks links against eps (hr_refine.c).
 */
static inline uint32_t rad_short_float(float x, int drop)
{
	uint32_t b;
	if (!(x > 0)) /* 0, negative; a NaN stays one */
		x = isnan(x) ? x : 0;
	memcpy(&b, &x, sizeof(b));
	b &= 0x7fffffffu;
	uint32_t half = 1u << (drop - 1);
	if (b < 0x7f800000u) /* finite: round; may reach infinity */
		b = b + half;
	return b >> drop;
}
static inline float rad_short_float_value(uint32_t code, int drop)
{
	uint32_t b = code << drop;
	float x;
	memcpy(&x, &b, sizeof(x));
	return x;
}
#define RAD_HLINK_FF_DROP 12     /* 19 bits kept */
#define RAD_HLINK_SPREAD_DROP 18 /* 13 bits kept */
static inline float rad_hlink_ff(const rad_hlink *l)
{
	return rad_short_float_value(l->fs >> 13, RAD_HLINK_FF_DROP);
}
static inline float rad_hlink_spread(const rad_hlink *l)
{
	return rad_short_float_value(l->fs & 0x1fffu, RAD_HLINK_SPREAD_DROP);
}
static inline void rad_hlink_set(rad_hlink *l, float ff, float spread)
{
	l->fs = rad_short_float(ff, RAD_HLINK_FF_DROP) << 13 |
	        rad_short_float(spread, RAD_HLINK_SPREAD_DROP);
}

/* Leaves and lists (DESIGN): a list's references carry RAD_HLIST, and
 * a packed link's RAD_HBASE too (Packed lists). */
#define RAD_HLIST 0x80000000u
#define RAD_HBASE 0x40000000u
#define RAD_HREF_ID 0x3fffffffu /* the id or offset; RAD_NONE's excluded */
_Static_assert(RAD_POOL_MAX_ID <= RAD_HLIST, "ids must leave RAD_HLIST");
static inline uint32_t rad_hlist_ref(uint32_t link)
{
	return link | RAD_HLIST;
}
static inline int rad_elem_is_leaf(const rad_elem *e)
{
	return (e->child & RAD_HLIST) != 0;
}
static inline int rad_cluster_is_leaf(const rad_cluster *c)
{
	return (c->child & RAD_HLIST) != 0;
}

/* Sizes the memory study measures by (Regions; links above). */
_Static_assert(sizeof(rad_elem) == 32, "rad_elem grew");
/* A record with dB in floats (Increments): the field and 8 bytes more. */
#define RAD_ELEM_EXACT_SIZE (sizeof(rad_elem) + 2 * sizeof(float))
_Static_assert(sizeof(rad_elem_run) == 16, "rad_elem_run grew");
_Static_assert(sizeof(rad_link) == 16, "rad_link grew");
_Static_assert(sizeof(rad_link_ext) == 12, "rad_link_ext grew");
_Static_assert(sizeof(rad_hlink) == 8, "rad_hlink grew");
_Static_assert(sizeof(rad_hlink_new) == 12, "rad_hlink_new grew");
_Static_assert(sizeof(rad_cluster) == 64, "rad_cluster grew");
_Static_assert(sizeof(rad_cluster_flux) == 28, "rad_cluster_flux grew");
_Static_assert(sizeof(rad_cluster_inner) == 40, "rad_cluster_inner grew");
_Static_assert(sizeof(rad_cluster_deltas) == 24, "rad_cluster_deltas grew");

typedef struct rad_hier {
	const rad_scene *scene;
	rad_mem *mem;          /* the owning solver's counters */
	rad_pool elems;        /* rad_elem, ELEM_SURFACE */
	rad_pool runs;         /* rad_elem_run, ELEM_SURFACE (Runs) */
	uint8_t *root_exposed; /* the roots' exposed fractions, ELEM_SURFACE */
	uint32_t run0;         /* id of the first sibling run's first child */
	rad_pool clusters;     /* rad_cluster, ELEM_CLUSTER */
	rad_pool links;        /* rad_link, or rad_hlink_new for hr; LINKS */
	rad_pool links_ext;    /* rad_link_ext of passive rad_links; LINKS */
	/* hr: the heads of the inner nodes' lists of links received
	 * (RAD_NONE: none; a leaf's is its child field), LINKS: inner
	 * elements' one per sibling run (their children's, a pool made in
	 * step with runs: the same ids), inner clusters' one per inner
	 * record (Leaves and lists).  Without lists (other solvers) both
	 * are empty. */
	int lists;
	int exact_dB; /* elements keep dB in floats (Increments) */
	rad_pool run_heads;
	uint32_t *inner_heads;
	/* hr: the packed links, offsets 0 .. npacked-1 in blocks of as
	 * many as the links pool's (1 << links.shift; Packed lists),
	 * LINKS; ndead of them dead. */
	rad_hlink **pack;
	uint32_t npack_blocks, pack_cap;
	uint32_t npacked, ndead;
	uint32_t *order; /* polygon ids in cluster order, ELEM_CLUSTER */
	rad_cluster_inner *inner;   /* inner clusters' records, ELEM_CLUSTER */
	rad_cluster_flux *flux;     /* rmb: one per cluster, ELEM_CLUSTER
	                               (rad_hier_keep_flux); else NULL */
	rad_cluster_deltas *deltas; /* one per inner record, ELEM_CLUSTER
	                               (rad_hier_keep_deltas); else NULL */
	uint32_t ninner;  /* entries (rad_cluster_inner_index below it) */
	uint32_t nleaves; /* surface leaves */
	double min_edge;  /* elements with a longer edge may split */
	uint64_t splits;  /* element splits since last reset */
	uint64_t gen;     /* unique per rad_hier_init (0: none), the key of
	                     rad_elem_patch_id's memo */
} rad_hier;

static inline rad_elem *rad_elem_at(const rad_hier *h, uint32_t id)
{
	return (rad_elem *)rad_pool_at(&h->elems, id);
}
/* Elements live: the pool's records but the pad before the first run. */
static inline uint32_t rad_hier_elements(const rad_hier *h)
{
	return rad_pool_live(&h->elems) - (h->run0 - h->scene->npolys);
}

/* The record of the sibling run element id (not a root) belongs to. */
static inline rad_elem_run *rad_elem_run_of(const rad_hier *h, uint32_t id)
{
	return (rad_elem_run *)rad_pool_at(&h->runs, (id - h->run0) >> 2);
}
/* Element id's polygon, depth and path (Regions, Runs). */
static inline uint32_t rad_elem_poly(const rad_hier *h, uint32_t id)
{
	return id < h->run0 ? id : rad_elem_run_of(h, id)->poly;
}
static inline int rad_elem_level(const rad_hier *h, uint32_t id)
{
	return id < h->run0 ? 0 : rad_elem_run_of(h, id)->level;
}
static inline uint32_t rad_elem_path(const rad_hier *h, uint32_t id)
{
	if (id < h->run0)
		return 0;
	const rad_elem_run *r = rad_elem_run_of(h, id);
	return r->path | ((id - h->run0) & 3u) << (2 * (r->level - 1));
}
/* Element id's exposed fraction as stored, 0 .. RAD_EXPOSED_ALL. */
static inline uint8_t rad_elem_exposed_raw(const rad_hier *h, uint32_t id)
{
	return id < h->run0
	               ? h->root_exposed[id]
	               : rad_elem_run_of(h, id)->exposed[(id - h->run0) & 3u];
}
/* Element e's dB (Increments): three floats from the field on, in
 * records of RAD_ELEM_EXACT_SIZE bytes, or packed in it.  The floats are
 * reached through the record's bytes, which run past the struct. */
#define RAD_ELEM_DB_AT offsetof(rad_elem, dB)
static inline void rad_elem_dB(const rad_hier *h, const rad_elem *e,
                               float dB[3])
{
	if (h->exact_dB)
		memcpy(dB, (const unsigned char *)e + RAD_ELEM_DB_AT,
		       3 * sizeof(float));
	else
		rad_shared3_unpack(e->dB, dB);
}
static inline void rad_elem_set_dB(const rad_hier *h, rad_elem *e,
                                   const float dB[3])
{
	if (h->exact_dB)
		memcpy((unsigned char *)e + RAD_ELEM_DB_AT, dB,
		       3 * sizeof(float));
	else
		e->dB = rad_shared3_pack(dB);
}
/* Element to's dB, from's as stored: no unpacking and packing again. */
static inline void rad_elem_copy_dB(const rad_hier *h, rad_elem *to,
                                    const rad_elem *from)
{
	memcpy((unsigned char *)to + RAD_ELEM_DB_AT,
	       (const unsigned char *)from + RAD_ELEM_DB_AT,
	       h->exact_dB ? 3 * sizeof(float) : sizeof(rad_shared3));
}
static inline rad_cluster *rad_cluster_at(const rad_hier *h, uint32_t id)
{
	return (rad_cluster *)rad_pool_at(&h->clusters, id & ~RAD_TAG_MASK);
}
static inline rad_link *rad_link_at(const rad_hier *h, uint32_t id)
{
	return (rad_link *)rad_pool_at(&h->links, id);
}
/* hr's lists (Packed lists): the link a list reference names, the
 * reference after it (dead ones included), and the first live link from
 * a reference on; RAD_NONE ends a list. */
static inline rad_hlink *rad_hlink_packed(const rad_hier *h, uint32_t off)
{
	return h->pack[off >> h->links.shift] +
	       (off & ((1u << h->links.shift) - 1u));
}
static inline rad_hlink_new *rad_hlink_new_at(const rad_hier *h, uint32_t ref)
{
	return (rad_hlink_new *)rad_pool_at(&h->links, ref & RAD_HREF_ID);
}
static inline rad_hlink *rad_hlink_at(const rad_hier *h, uint32_t ref)
{
	return (ref & RAD_HBASE) ? rad_hlink_packed(h, ref & RAD_HREF_ID)
	                         : &rad_hlink_new_at(h, ref)->l;
}
static inline uint32_t rad_hlist_step(const rad_hier *h, uint32_t ref)
{
	if (ref & RAD_HBASE)
		return (rad_hlink_packed(h, ref & RAD_HREF_ID)->srcl &
		        RAD_HLINK_LAST)
		               ? RAD_NONE
		               : ref + 1;
	return rad_hlink_new_at(h, ref)->next;
}
static inline uint32_t rad_hlist_live(const rad_hier *h, uint32_t ref)
{
	while (ref != RAD_NONE && rad_hlink_dead(rad_hlink_at(h, ref)))
		ref = rad_hlist_step(h, ref);
	return ref;
}
static inline uint32_t rad_hlist_next(const rad_hier *h, uint32_t ref)
{
	return rad_hlist_live(h, rad_hlist_step(h, ref));
}

#define RAD_EXPOSED_ALL 255u

/* Polygon k of m taken evenly along cluster c's range of order[]
 * (k < m <= c->count): the sample polygons of solvers and queries. */
static inline uint32_t rad_cluster_pick(const rad_hier *h, const rad_cluster *c,
                                        uint32_t k, uint32_t m)
{
	return h->order[c->first + (uint32_t)(((uint64_t)k * c->count) / m)];
}

/* Points on which an element's exposed fraction is measured (Covered
 * parts): rad_patch_scatter's first RAD_COVER_SAMPLES. */
#define RAD_COVER_SAMPLES 16

/* The exposed fraction of an element's area (Covered parts). */
static inline double rad_elem_exposed(const rad_hier *h, uint32_t id)
{
	uint8_t x = rad_elem_exposed_raw(h, id);
	return x == RAD_EXPOSED_ALL ? 1.0 : x / (double)RAD_EXPOSED_ALL;
}

/*
 * Keep, of the n points pts (normals nrm, may be NULL) on element id, those
 * that are not covered; returns how many are left.  Costs nothing on an
 * element wholly exposed; *rays counts the rays traced.
 */
int rad_elem_keep_exposed(const rad_hier *h, uint32_t id, v3 *pts, v3 *nrm,
                          int n, uint64_t *rays);

/*
 * How close something in front of polygon poly must be to cover it:
 * 15 % of its longest edge, at most 1/200 of the scene's diagonal; for an
 * emitter 1/20 of its edge, at most 1/1000 of the diagonal.  A surface a
 * few centimetres under a board or the facing inner side of a slab is a
 * dark slot: light reaches it only at grazing angles, yet light pushed to
 * its polygon from above lit it, and two such faces then lit each other
 * (a Graz desk's inner faces, 3.3 cm apart, reached 100-140 lx where
 * luxrad-reference finds none).  Measured against luxrad-reference at the
 * defaults, hr, from 1/20 and 1/1000 for every surface: the Graz office's
 * worst point -19.5 -> -13.0 %, mean 2.87 -> 2.58 %; the hospital room
 * 7.48 -> 7.38 %; every scene of our own unchanged.  Emitters keep the
 * short reach: a luminaire's louvres a few centimetres in front of its
 * lamp do not cover it (at 1/100 of the diagonal the Graz office's
 * luminaires went dark, mean error 31 %).  Longer is not better for the
 * others either: 1/100 of the diagonal read one Graz point +16 %
 * (1/333 .. 1/133: worst -13.7 .. -12.4 %, mean 2.55 .. 2.64 %).
 */
double rad_hier_cover_dist(const rad_hier *h, uint32_t poly);

/*
 * Build the polygon roots and the cluster tree.  min_edge in metres;
 * lists: 1 for classic HR's links (rad_hlink, on their receivers' lists),
 * 0 for the others' (rad_link); par (or NULL: the calling thread alone)
 * measures the roots' exposed fractions and fills the cluster subtrees.
 * On failure everything allocated is released.
 */
/* Bytes of a block of each pool that grows: elements, links, and hr's
 * inner elements' list heads or rmb's passive links' records (a budget keeps
 * them free: wave_room_for). */
size_t rad_hier_grow_blocks(const rad_hier *h);
rad_status rad_hier_init(rad_hier *h, const rad_scene *s, rad_mem *mem,
                         double min_edge, int lists, int exact_dB, rad_par *par,
                         rad_error *err);
/* Give every cluster a flux record, zeroed (rmb); RAD_ERR_NOMEM. */
rad_status rad_hier_keep_flux(rad_hier *h, rad_error *err);
/* Keep the inner clusters' increments from now on, pulled from what the
 * leaves hold now (as the last pull made them); RAD_ERR_NOMEM.
 * rad_hier_drop_deltas frees them: rad_cluster_delta then pulls an inner
 * cluster's from its subtree when asked. */
rad_status rad_hier_keep_deltas(rad_hier *h, rad_error *err);
void rad_hier_drop_deltas(rad_hier *h);
/* rad_luma of every inner cluster's dB, as rad_cluster_delta gives it,
 * into out[rad_cluster_inner_index] (h->ninner entries; hr's
 * statistics). */
void rad_hier_delta_lumas(const rad_hier *h, double *out);
/* Bytes of an element's record: exact_dB as rad_hier_init's. */
static inline size_t rad_hier_elem_size(int exact_dB)
{
	return exact_dB ? RAD_ELEM_EXACT_SIZE : sizeof(rad_elem);
}
void rad_hier_destroy(rad_hier *h);
/*
 * Check the trees and link lists (hier_check.c): 0, or -1 with msg naming
 * the first broken invariant.  Run after every step when LUXRAD_CHECKS is
 * defined (Debug and sanitizer builds).
 */
int rad_hier_check(const rad_hier *h, char *msg, size_t len);

#define RAD_ELEM_MAX_LEVEL 16 /* 2 bits of rad_elem.path a level */

/* Element id's region (Regions): origin and edges, as rad_poly's. */
void rad_elem_region(const rad_hier *h, uint32_t id, float p0[3], float e1[3],
                     float e2[3]);
/* Element id's region as a patch (rad_patch_from_floats). */
void rad_elem_patch(const rad_hier *h, uint32_t id, rad_patch *p);
/* The same for element id, through a small memo per thread: judging a
 * pair asks for its two patches several times (hr_nodes.c).  An element
 * keeps its id and region while its hierarchy lives, and a hierarchy's
 * gen is never reused, so a memo entry is never stale. */
void rad_elem_patch_id(const rad_hier *h, uint32_t id, rad_patch *p);
/* Quarter k (0..3) of the region (p0, e1, e2), in place: the geometry
 * rad_elem_split gives child k. */
void rad_region_quarter(float p0[3], float e1[3], float e2[3], int quad, int k);

/* Area of element id, m2: its polygon's times 4^-level, exact: the
 * factor is built from its exponent bits (level <= RAD_ELEM_MAX_LEVEL, so it is
 * a normal float), and a product with a power of two rounds as ldexpf does,
 * without its call (the gather asks for it per link). */
static inline float rad_elem_area(const rad_hier *h, uint32_t id)
{
	if (id < h->run0)
		return h->scene->polys[id].area;
	const rad_elem_run *r = rad_elem_run_of(h, id);
	uint32_t bits = (uint32_t)(127 - 2 * (int)r->level) << 23;
	float quarter;
	memcpy(&quarter, &bits, sizeof quarter);
	return h->scene->polys[r->poly].area * quarter;
}
/* 1 if element id's polygon is a parallelogram, 0 for a triangle. */
static inline int rad_elem_quad(const rad_hier *h, uint32_t id)
{
	return h->scene->polys[rad_elem_poly(h, id)].quad;
}

/* Longest edge of element id's region, metres. */
double rad_elem_edge(const rad_hier *h, uint32_t id);
/* 1 if element id may be split (its edge exceeds min_edge). */
int rad_elem_can_split(const rad_hier *h, uint32_t id);
/*
 * Make the four children of element id if it has none (B, dB copied from
 * the parent, I zero).  Returns the first child id, or RAD_NONE when out
 * of memory.  Not thread-safe.
 */
uint32_t rad_elem_split(rad_hier *h, uint32_t id);

/* Subdivide every polygon uniformly until edges are <= edge (matrix mesh). */
rad_status rad_hier_mesh_uniform(rad_hier *h, double edge, rad_error *err);

/* Where the surface elements sit (rad_solver_census, rad.h). */
void rad_hier_census(const rad_hier *h, rad_census *out);

/* Set B = E and clear I, dB on every node (pull included). */
void rad_hier_reset_emission(rad_hier *h);

/*
 * Pull: recompute B and dB on inner surface elements and clusters as area
 * averages of the leaves' values.
 */
void rad_hier_pull(rad_hier *h);

/*
 * Push: add each node's I to its children's, down the cluster tree (each
 * child its share by orientation, DESIGN) and the quadtrees, and call
 * leaf() on every surface leaf with its total irradiance in e->I.
 * A solver may push a payload of RAD_PUSH_EXTRA floats per node with it
 * (extra: the node's own, or NULL for none; read before the next call,
 * which may reuse it), shared out and summed as I is; the leaf gets the
 * total (NULL when extra is NULL).  A cluster's own I, V and S come from
 * own (hr: its links gathered there), or from h->flux when own is NULL;
 * with own, the leaves are updated once every cluster has been, and extra
 * must be NULL (the roots would need what their clusters carried), and
 * the clusters' subtrees are pushed on par's threads (own must be
 * thread-safe); the leaves are updated on the calling thread.
 */
#define RAD_PUSH_EXTRA 4
typedef const float *(*rad_push_extra)(const rad_hier *h, uint32_t tagged,
                                       void *ud);
typedef void (*rad_push_own)(rad_hier *h, uint32_t id, rad_cluster_flux *out,
                             void *ud);
typedef void (*rad_leaf_update)(rad_hier *h, uint32_t id, rad_elem *leaf,
                                const float *extra, void *ud);
void rad_hier_push(rad_hier *h, rad_leaf_update leaf, rad_push_extra extra,
                   rad_push_own own, void *ud, rad_par *par);

/* Material of the polygon element id belongs to. */
static inline const rad_material *rad_elem_mat(const rad_hier *h, uint32_t id)
{
	return &h->scene->mats[h->scene->polys[rad_elem_poly(h, id)].mat];
}

/* Photopic luminance of an RGB value. */
static inline double rad_luma(const float c[3])
{
	return RAD_LUMA_R * c[0] + RAD_LUMA_G * c[1] + RAD_LUMA_B * c[2];
}

/* Link store (rad_link): allocate one active link, or RAD_NONE. */
uint32_t rad_link_new(rad_hier *h, uint32_t rcv, uint32_t src, float ff,
                      float spread);

static inline int rad_link_passive(const rad_link *l)
{
	return (l->aux & RAD_LINK_EXT) != 0;
}
static inline rad_link_ext *rad_link_ext_of(const rad_hier *h,
                                            const rad_link *l)
{
	return (rad_link_ext *)rad_pool_at(&h->links_ext,
	                                   l->aux & ~RAD_LINK_EXT);
}
static inline float rad_link_spread(const rad_hier *h, const rad_link *l)
{
	if (rad_link_passive(l))
		return rad_link_ext_of(h, l)->spread;
	float f;
	memcpy(&f, &l->aux, sizeof(f));
	return f;
}
/* Set a link's spread (>= 0; -0 and NaN are stored as 0). */
static inline void rad_link_set_spread(const rad_hier *h, rad_link *l,
                                       float spread)
{
	spread = spread > 0 ? spread : 0;
	if (rad_link_passive(l))
		rad_link_ext_of(h, l)->spread = spread;
	else
		memcpy(&l->aux, &spread, sizeof(spread));
}
/* First child and number of children of link l (RAD_NONE, 0: active). */
static inline uint32_t rad_link_child(const rad_hier *h, const rad_link *l,
                                      uint32_t *n)
{
	if (!rad_link_passive(l)) {
		*n = 0;
		return RAD_NONE;
	}
	const rad_link_ext *x = rad_link_ext_of(h, l);
	*n = x->nchild;
	return x->child;
}
/* Make active link id passive over the run child .. child+n-1 (its
 * spread kept); RAD_ERR_NOMEM when the ext pool cannot grow. */
rad_status rad_link_make_passive(rad_hier *h, uint32_t id, uint32_t child,
                                 uint32_t n, int split_src);
/* Make passive link id active again (the run is the caller's to free). */
void rad_link_make_active(rad_hier *h, uint32_t id);
/* Projected area of a cluster's polygons in unit direction d (DESIGN):
 * exact over a leaf cluster's polygons, the moment model RAD_PROJ_DEPTH
 * levels below an inner one (the sum of up to 4 models, each exact if it
 * is a leaf). */
#define RAD_PROJ_DEPTH 2
double rad_cluster_proj(const rad_hier *h, const rad_cluster *c, double dx,
                        double dy, double dz);

/*
 * What cluster c sends towards unit d, relative to its mean radiosity
 * times p = P(d), its rad_cluster_proj (DESIGN, emission): of B with
 * B = c->B and nB = c->nB, of dB with its dB and ndB (rad_cluster_delta).
 */
double rad_cluster_emit(const rad_hier *h, const rad_cluster *c,
                        const float B[3], const float nB[3], double p,
                        double dx, double dy, double dz);

/* Cluster c's sum of area x unit normal: an inner cluster's record, or
 * a leaf's summed over its polygons as the tree's build sums it. */
void rad_cluster_normal(const rad_hier *h, const rad_cluster *c, float n[3]);

/*
 * The dB and ndB of cluster c (either may be NULL): an inner cluster's
 * pulled record, or without h->deltas its children's pulled from its
 * subtree, or a leaf's summed from its polygons' root elements, as the
 * pull sums them (the same bits while those elements hold what was
 * pulled).
 */
void rad_cluster_delta(const rad_hier *h, const rad_cluster *c, float dB[3],
                       float ndB[3]);

/*
 * Record in a cluster's flux c that it took irradiance of photopic value e
 * (normal irradiance, lux) from unit direction (dx, dy, dz); a zero
 * direction counts as no direction (DESIGN, push).
 */
static inline void rad_cluster_took(rad_cluster_flux *c, double e, double dx,
                                    double dy, double dz)
{
	e = e < 0 ? -e : e;
	c->V[0] += (float)(e * dx);
	c->V[1] += (float)(e * dy);
	c->V[2] += (float)(e * dz);
	c->S += (float)e;
}

/* Where the head of a node's received-links list is (element or cluster;
 * Leaves and lists): its child field if a leaf, its run's or inner
 * record's word if not.  A split moves a leaf's head (rad_elem_split). */
uint32_t *rad_node_links(const rad_hier *h, uint32_t tagged);
/* The same, of an element's or a cluster's record. */
static inline uint32_t *rad_elem_links(const rad_hier *h, rad_elem *e)
{
	return rad_elem_is_leaf(e)
	               ? &e->child
	               : (uint32_t *)rad_pool_at(&h->run_heads,
	                                         (e->child - h->run0) >> 2);
}
static inline uint32_t *rad_cluster_links(const rad_hier *h, rad_cluster *c)
{
	return rad_cluster_is_leaf(c)
	               ? &c->child
	               : &h->inner_heads[rad_cluster_inner_index(c)];
}

/* hr's lists (Packed lists).  Prepend link src, ff, spread to tagged's
 * list; RAD_ERR_NOMEM (the pool's or the references' ids exhausted, or a
 * source id of RAD_HLINK_LAST or more). */
rad_status rad_hlist_add(rad_hier *h, uint32_t tagged, uint32_t src, float ff,
                         float spread);
/* Take the link ref off its list (*prev: the reference to it, if it is
 * new); returns the first live reference after it. */
uint32_t rad_hlist_remove(rad_hier *h, uint32_t *prev, uint32_t ref);
/* Links on the lists. */
uint32_t rad_hlist_count(const rad_hier *h);
/* Pack every list: new links into the blocks, dead ones dropped if
 * drop_dead, the order of each list kept.  RAD_ERR_NOMEM (the budget, or
 * the allocator, refused the blocks: the new links stay where they are,
 * the lists whole). */
rad_status rad_hlist_pack(rad_hier *h, int drop_dead);

#endif
