/*
 * hier.c -- element quadtrees, the cluster tree, and the link store
 * (see the DESIGN note in hier.h).
 *
 * The cluster tree is built top-down by median splits of polygon centroids
 * along the longest axis of their bounds, so it is balanced (depth
 * log2(n/4)) and deterministic: the same scene always gives the same tree.
 * Polygons are permuted into order[] so every cluster covers one range.
 */
#include "hier.h"

#include <float.h>
#include <math.h>
#include <stdatomic.h>
#include <string.h>

#include "ff.h"
#include "rad.h"
#include "vis.h"

static v3 poly_centroid(const rad_scene *s, const rad_poly *p)
{
	/* Triangle: (p0 + p1 + p2)/3; parallelogram: p0 + (e1 + e2)/2. */
	double w = p->quad ? 0.5 : 1.0 / 3.0;
	return rad_poly_point(s, p, w, w);
}

static void poly_bounds(const rad_scene *s, const rad_poly *p, float lo[3],
                        float hi[3])
{
	v3 e2 = rad_poly_e2(s, p), a = rad_scene_vertex(s, p->v[0]);
	v3 b = v3_add(a, rad_poly_e1(s, p)), c = v3_add(a, e2);
	v3 d = v3_add(b, e2);
	v3 pts[4] = {a, b, c, d};
	int n = p->quad ? 4 : 3;
	for (int i = 0; i < n; i++) {
		double q[3] = {pts[i].x, pts[i].y, pts[i].z};
		for (int k = 0; k < 3; k++) {
			if ((float)q[k] < lo[k])
				lo[k] = (float)q[k];
			if ((float)q[k] > hi[k])
				hi[k] = (float)q[k];
		}
	}
}

/* Quickselect: order[lo..hi) partially sorted so that the element at k
 * has the k-th smallest key (ties broken by polygon id: deterministic). */
static void select_kth(const double *ctr, uint32_t *order, uint32_t lo,
                       uint32_t hi, uint32_t k, int axis)
{
	while (hi - lo > 1) {
		uint32_t mid = lo + (hi - lo) / 2;
		uint32_t pivot = order[mid];
		double pk = ctr[3 * (size_t)pivot + (size_t)axis];
		/* Three-way partition around (pk, pivot id). */
		uint32_t lt = lo, i = lo, gt = hi;
		while (i < gt) {
			uint32_t id = order[i];
			double key = ctr[3 * (size_t)id + (size_t)axis];
			int cmp = key < pk   ? -1
			          : key > pk ? 1
			                     : (id < pivot ? -1 : id > pivot);
			if (cmp < 0) {
				order[i++] = order[lt];
				order[lt++] = id;
			} else if (cmp > 0) {
				order[i] = order[--gt];
				order[gt] = id;
			} else {
				i++;
			}
		}
		if (k < lt)
			hi = lt;
		else if (k >= gt)
			lo = gt;
		else
			return;
	}
}

/* Second moment of the normals (hier.h): m += a n n^T. */
static void moments_add(double m[6], double a, v3 n)
{
	m[0] += a * n.x * n.x;
	m[1] += a * n.y * n.y;
	m[2] += a * n.z * n.z;
	m[3] += a * n.x * n.y;
	m[4] += a * n.x * n.z;
	m[5] += a * n.y * n.z;
}

/* Eigenvalues of the symmetric 3 x 3 matrix m (xx yy zz xy xz yz), by the
 * trigonometric solution of the characteristic cubic. */
static void sym3_eigen(const double m[6], double ev[3])
{
	double p1 = m[3] * m[3] + m[4] * m[4] + m[5] * m[5];
	double tr = (m[0] + m[1] + m[2]) / 3;
	if (p1 <= 1e-30 * (tr * tr + 1e-300)) {
		ev[0] = m[0];
		ev[1] = m[1];
		ev[2] = m[2];
		return;
	}
	double a = m[0] - tr, b = m[1] - tr, c = m[2] - tr;
	double p2 = a * a + b * b + c * c + 2 * p1;
	double p = sqrt(p2 / 6);
	/* det((m - tr I) / p) / 2 */
	double det = a * (b * c - m[5] * m[5]) -
	             m[3] * (m[3] * c - m[5] * m[4]) +
	             m[4] * (m[3] * m[5] - b * m[4]);
	double r = det / (2 * p * p * p);
	double phi = r <= -1 ? M_PI / 3 : r >= 1 ? 0 : acos(r) / 3;
	ev[0] = tr + 2 * p * cos(phi);
	ev[2] = tr + 2 * p * cos(phi + 2 * M_PI / 3);
	ev[1] = 3 * tr - ev[0] - ev[2];
}

/*
 * R_G(ev) = the mean over the unit sphere of sqrt(d^T M d): by symmetry the
 * mean over one octant of sqrt(l0 x^2 + l1 y^2 + l2 z^2), integrated with a
 * 12 x 12 Gauss-Legendre rule in (z, azimuth), where the integrand is
 * smooth (it only vanishes on the octant's edges).  Checked against the
 * closed forms sqrt(l) / 2 (one non-zero eigenvalue: exact), pi sqrt(l) / 4
 * (two equal ones: 2e-7 relative) and sqrt(l) (three equal: 1e-16).
 */
static double sphere_mean_sqrt(const double m[6])
{
	/* 12-point Gauss-Legendre on [0, 1]: nodes (1 +- x) / 2, weights w / 2
	 * for the 6 positive nodes x of the rule on [-1, 1]. */
	static const double x[6] = {0.1252334085114689, 0.3678314989981802,
	                            0.5873179542866175, 0.7699026741943047,
	                            0.9041172563704749, 0.9815606342467192};
	static const double w[6] = {0.2491470458134028, 0.2334925365383548,
	                            0.2031674267230659, 0.1600783285433462,
	                            0.1069393259953184, 0.0471753363865118};
	double t[12], wt[12], c2[12], ev[3], sum = 0;
	for (int i = 0; i < 6; i++) {
		t[i] = 0.5 * (1 - x[5 - i]);
		t[11 - i] = 0.5 * (1 + x[5 - i]);
		wt[i] = wt[11 - i] = 0.5 * w[5 - i];
	}
	for (int j = 0; j < 12; j++) { /* azimuth pi/2 t: cos^2 */
		double c = cos(0.5 * M_PI * t[j]);
		c2[j] = c * c;
	}
	sym3_eigen(m, ev);
	for (int k = 0; k < 3; k++)
		ev[k] = fmax(ev[k], 0);
	/* The largest along z: a flat cluster's integrand is then sqrt(l) z,
	 * which the rule integrates exactly. */
	if (ev[0] > ev[2]) {
		double tmp = ev[0];
		ev[0] = ev[2];
		ev[2] = tmp;
	}
	for (int i = 0; i < 12; i++) {
		double z = t[i], s2 = 1 - z * z;
		for (int j = 0; j < 12; j++) {
			double f = s2 * (ev[0] * c2[j] + ev[1] * (1 - c2[j])) +
			           ev[2] * z * z;
			sum += wt[i] * wt[j] * sqrt(f);
		}
	}
	return sum; /* the octant's area-mean: (1/(pi/2)) int dz dphi */
}

/* Where a cluster of n > RAD_CLUSTER_LEAF_MAX polygons splits: after
 * the first half of its leaves (ceil(n / LEAF_MAX) of them), so that
 * every leaf is full but the last of the order.  Halving n instead
 * fills leaves only where n is near LEAF_MAX times a power of 2: the
 * 1M-triangle field's 731,827 polygons made 262,144 leaves of 2 or 3
 * where 182,957 hold them, and a cluster costs about 130 bytes. */
static uint32_t split_at(uint32_t n)
{
	uint32_t leaves = (n + RAD_CLUSTER_LEAF_MAX - 1) / RAD_CLUSTER_LEAF_MAX;
	return (leaves / 2) * RAD_CLUSTER_LEAF_MAX;
}

/* The shape of cluster c's subtree (c's range already set): it depends on
 * the counts alone (split_at), so every cluster's range and children are
 * made before any polygon is read, in the order of a walk down the tree,
 * as the pool hands out their ids. */
static rad_status shape_tree(rad_hier *h, uint32_t c, rad_error *err)
{
	rad_cluster *cl = rad_cluster_at(h, c);
	cl->child = RAD_NONE;
	if (cl->count <= RAD_CLUSTER_LEAF_MAX)
		return RAD_OK; /* its projected area is summed exactly */
	uint32_t first = cl->first, count = cl->count;
	uint32_t half = split_at(count);
	uint32_t kids = rad_pool_add(&h->clusters, 2);
	if (kids == RAD_NONE)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "cluster tree: out of memory");
	if ((kids - 1) / 2 >= h->ninner) /* inner_clusters miscounted */
		return rad_fail(err, RAD_ERR_STATE,
		                "cluster tree: more inner clusters than the "
		                "%u counted",
		                h->ninner);
	cl = rad_cluster_at(h, c); /* records never move; reload for clarity */
	cl->child = kids;
	rad_cluster *a = rad_cluster_at(h, kids),
	            *b = rad_cluster_at(h, kids + 1);
	a->first = first;
	a->count = half;
	b->first = first + half;
	b->count = count - half;
	rad_status st = shape_tree(h, kids, err);
	return st ? st : shape_tree(h, kids + 1, err);
}

/* What a subtree's polygons add up to: area, sum of area x unit normal,
 * and moments (fill_cluster). */
typedef struct fill_sums {
	double area, n[3], m[6];
} fill_sums;

static void sums_add_poly(fill_sums *s, const rad_poly *p)
{
	v3 an = rad_poly_an(p);
	s->area += p->area;
	s->n[0] += an.x;
	s->n[1] += an.y;
	s->n[2] += an.z;
	moments_add(s->m, p->area, rad_poly_normal(p));
}

/* A leaf cluster's sums, over its polygons in order[]. */
static void sums_of_leaf(const rad_hier *h, const rad_cluster *cl, fill_sums *s)
{
	memset(s, 0, sizeof(*s));
	for (uint32_t i = cl->first; i < cl->first + cl->count; i++)
		sums_add_poly(s, &h->scene->polys[h->order[i]]);
}

/* Inner cluster cl's area and model from its children's sums a and b,
 * which become its own in *a, and its bounds: the union of its
 * children's, the same floats as over its polygons' corners (min and max
 * are exact), read once each instead of once a level (poly_bounds was 6 %
 * of a 1M-field rmb run on one thread). */
static void sums_to_inner(rad_hier *h, rad_cluster *cl, fill_sums *a,
                          const fill_sums *b)
{
	const rad_cluster *ka = rad_cluster_at(h, cl->child),
	                  *kb = rad_cluster_at(h, cl->child + 1);
	for (int k = 0; k < 3; k++) {
		cl->lo[k] = fminf(ka->lo[k], kb->lo[k]);
		cl->hi[k] = fmaxf(ka->hi[k], kb->hi[k]);
	}
	a->area += b->area;
	for (int k = 0; k < 3; k++)
		a->n[k] += b->n[k];
	for (int k = 0; k < 6; k++)
		a->m[k] += b->m[k];
	cl->area = (float)a->area;
	rad_cluster_inner *mo = &h->inner[rad_cluster_inner_index(cl)];
	for (int k = 0; k < 6; k++)
		mo->m[k] = (float)a->m[k];
	for (int k = 0; k < 3; k++)
		mo->n[k] = (float)a->n[k];
	double rg = sphere_mean_sqrt(a->m);
	mo->q = rg > 0 ? (float)(a->area / (2 * rg)) : 0;
}

/* What fill_cluster hands over to the threads: the subtrees below
 * `depth` levels (FILL_DEPTH), their roots in `roots`, and what each
 * adds up to, for the levels above (fill_top). */
#define FILL_DEPTH 5
typedef struct fill_work {
	rad_hier *h;
	const double *ctr;
	uint32_t roots[1u << FILL_DEPTH];
	fill_sums sums[1u << FILL_DEPTH];
	uint32_t nroots;
} fill_work;

/* Fill cluster c's subtree (shape_tree made it): order[] split between
 * the children along the longest axis of the centroids (ctr: 3 per
 * polygon), a leaf's bounds, and, post-order, the area, the model and
 * the bounds of every inner cluster from its children's (sums_to_inner;
 * its sums into *out): each polygon is read once, not once a level (the
 * 1M field's setup, 2 threads: 0.46 -> 0.41 s; lux within 1e-9 of the
 * sums in one run over each cluster's polygons, the same links).  With
 * w, the subtrees `depth` levels down are left in w->roots instead, and
 * the levels above wait for them (fill_top).  A subtree reads and
 * writes only its own clusters, models and range of order[], so who
 * fills it does not change the tree. */
static void fill_cluster(rad_hier *h, uint32_t c, const double *ctr, int depth,
                         fill_work *w, fill_sums *out)
{
	const rad_scene *s = h->scene;
	if (w && depth == 0) {
		w->roots[w->nroots++] = c;
		return;
	}
	rad_cluster *cl = rad_cluster_at(h, c);
	if (rad_cluster_is_leaf(cl)) {
		for (int k = 0; k < 3; k++) {
			cl->lo[k] = FLT_MAX;
			cl->hi[k] = -FLT_MAX;
		}
		for (uint32_t i = cl->first; i < cl->first + cl->count; i++)
			poly_bounds(s, &s->polys[h->order[i]], cl->lo, cl->hi);
		sums_of_leaf(h, cl, out);
		cl->area = (float)out->area;
		return;
	}
	double clo[3] = {DBL_MAX, DBL_MAX, DBL_MAX};
	double chi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX};
	for (uint32_t i = cl->first; i < cl->first + cl->count; i++) {
		const double *q = ctr + 3 * (size_t)h->order[i];
		for (int k = 0; k < 3; k++) {
			clo[k] = q[k] < clo[k] ? q[k] : clo[k];
			chi[k] = q[k] > chi[k] ? q[k] : chi[k];
		}
	}
	int axis = 0;
	for (int k = 1; k < 3; k++)
		if (chi[k] - clo[k] > chi[axis] - clo[axis])
			axis = k;
	uint32_t kids = cl->child;
	const rad_cluster *a = rad_cluster_at(h, kids);
	select_kth(ctr, h->order, cl->first, cl->first + cl->count,
	           cl->first + a->count, axis);
	fill_sums sb;
	fill_cluster(h, kids, ctr, depth - 1, w, out);
	fill_cluster(h, kids + 1, ctr, depth - 1, w, &sb);
	if (!w)
		sums_to_inner(h, cl, out, &sb);
}

/* The levels fill_cluster left to wait for the subtrees (w->sums, in the
 * order it listed their roots, *next the first not taken). */
static void fill_top(rad_hier *h, uint32_t c, int depth, fill_work *w,
                     uint32_t *next, fill_sums *out)
{
	if (depth == 0) {
		*out = w->sums[(*next)++];
		return;
	}
	rad_cluster *cl = rad_cluster_at(h, c);
	if (rad_cluster_is_leaf(cl)) {
		sums_of_leaf(h, cl, out);
		return;
	}
	fill_sums sb;
	fill_top(h, cl->child, depth - 1, w, next, out);
	fill_top(h, cl->child + 1, depth - 1, w, next, &sb);
	sums_to_inner(h, cl, out, &sb);
}

static void fill_subtrees(void *ud, size_t begin, size_t end, int thread)
{
	fill_work *w = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++)
		fill_cluster(w->h, w->roots[i], w->ctr, 0, NULL, &w->sums[i]);
}

/* Inner clusters of a tree over n polygons (shape_tree's rule). */
static uint32_t inner_clusters(uint32_t n)
{
	if (n <= RAD_CLUSTER_LEAF_MAX)
		return 0;
	uint32_t h = split_at(n);
	return 1 + inner_clusters(h) + inner_clusters(n - h);
}

/* The cluster tree over every polygon, from root cluster 0 (range set):
 * its shape, then its contents, the top FILL_DEPTH levels on the calling
 * thread and the subtrees below them on par's (or NULL: the calling
 * thread's).  Each level reads every polygon's centroid, and the
 * polygons are read once, at the leaves (fill_cluster): the 1M-triangle
 * field's setup on one thread went 0.80 -> 0.70 s with that.  The same
 * tree, bit for bit, for any thread count.
 * The centroids every level sorts by are computed once (SCRATCH).  The
 * models: one per inner cluster, and one more, since the pool may skip
 * one record where a pair would straddle the end of its first block
 * (later blocks hold an even number of records from an even id). */
static rad_status build_clusters(rad_hier *h, rad_par *par, rad_error *err)
{
	const rad_scene *s = h->scene;
	h->ninner = inner_clusters(s->npolys) + 1;
	h->inner = rad_mem_alloc(h->mem, RAD_MEM_ELEM_CLUSTER,
	                         h->ninner * sizeof(rad_cluster_inner));
	double *ctr = rad_mem_alloc(h->mem, RAD_MEM_SCRATCH,
	                            3 * (size_t)s->npolys * sizeof(double));
	if (!h->inner || !ctr) {
		rad_mem_free(h->mem, RAD_MEM_SCRATCH, ctr);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "cluster tree: out of memory");
	}
	for (uint32_t i = 0; i < s->npolys; i++) {
		v3 c = poly_centroid(s, &s->polys[i]);
		ctr[3 * (size_t)i] = c.x;
		ctr[3 * (size_t)i + 1] = c.y;
		ctr[3 * (size_t)i + 2] = c.z;
	}
	rad_status st = shape_tree(h, 0, err);
	if (!st) {
		fill_work w = {.h = h, .ctr = ctr};
		fill_sums top;
		uint32_t next = 0;
		fill_cluster(h, 0, ctr, FILL_DEPTH, &w, &top);
		rad_par_for(par, w.nroots, 1, fill_subtrees, &w);
		fill_top(h, 0, FILL_DEPTH, &w, &next, &top);
	}
	rad_mem_free(h->mem, RAD_MEM_SCRATCH, ctr);
	return st;
}

/* ------------------------------------------------------- covered parts */

double rad_hier_cover_dist(const rad_hier *h, uint32_t poly)
{
	const rad_scene *s = h->scene;
	double edge = rad_elem_edge(h, poly);
	if (rad_material_emits(&s->mats[s->polys[poly].mat]))
		return fmin(0.05 * edge, 1e-3 * s->diag);
	return fmin(0.15 * edge, 5e-3 * s->diag);
}

/* Measure e's exposed fraction on RAD_COVER_SAMPLES points (vis: the BVH). */
static void measure_exposed(const rad_hier *h, uint32_t id)
{
	const rad_vis *v = h->scene->vis;
	double dist = rad_hier_cover_dist(h, rad_elem_poly(h, id));
	rad_patch p;
	v3 pts[RAD_COVER_SAMPLES];
	rad_elem_patch(h, id, &p);
	int n = rad_patch_scatter(&p, RAD_COVER_SAMPLES, pts);
	int open = rad_vis_keep_uncovered(v, p.n, dist, pts, NULL, n, NULL);
	uint8_t x = (uint8_t)((open * RAD_EXPOSED_ALL + n / 2) / n);
	if (id < h->run0)
		h->root_exposed[id] = x;
	else
		rad_elem_run_of(h, id)->exposed[(id - h->run0) & 3u] = x;
}

/* The roots' exposed fractions, on the solver's threads: each root writes
 * its own, so the answer does not depend on who measures it.  16 rays a
 * polygon were 1.35 of the 2.4 s the 1M-triangle field's hierarchy took
 * on one thread. */
#define COVER_GRAIN 1024

static void measure_roots(void *ud, size_t begin, size_t end, int thread)
{
	const rad_hier *h = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++)
		measure_exposed(h, (uint32_t)i);
}

int rad_elem_keep_exposed(const rad_hier *h, uint32_t id, v3 *pts, v3 *nrm,
                          int n, uint64_t *rays)
{
	if (rad_elem_exposed_raw(h, id) == RAD_EXPOSED_ALL)
		return n;
	uint32_t poly = rad_elem_poly(h, id);
	return rad_vis_keep_uncovered(
	        h->scene->vis, rad_poly_normal(&h->scene->polys[poly]),
	        rad_hier_cover_dist(h, poly), pts, nrm, n, rays);
}

/* hr's list heads: none of the n nodes at heads has a link yet. */
static void no_links(uint32_t *heads, uint32_t n)
{
	for (uint32_t k = 0; k < n; k++)
		heads[k] = RAD_NONE;
}

/* The pools, with blocks of about 1 << shift records. */
static void init_pools(rad_hier *h, rad_mem *mem, uint32_t shift, uint32_t n,
                       int lists)
{
	rad_pool_init(&h->elems, mem, RAD_MEM_ELEM_SURFACE,
	              (uint32_t)rad_hier_elem_size(h->exact_dB), shift, n);
	/* A run's record is 16 bytes: as many in a block as elements in
	 * elems' (a quarter made the allocations of a small solve 13 % more
	 * numerous). */
	rad_pool_init(&h->runs, mem, RAD_MEM_ELEM_SURFACE, sizeof(rad_elem_run),
	              shift, 0);
	rad_pool_init(&h->clusters, mem, RAD_MEM_ELEM_CLUSTER,
	              sizeof(rad_cluster), shift, 0);
	rad_pool_init(&h->links, mem, RAD_MEM_LINKS,
	              lists ? sizeof(rad_hlink_new) : sizeof(rad_link),
	              shift < 10 ? shift + 2 : 12, 0);
	/* The same blocks as runs': the same ids for the same adds. */
	rad_pool_init(&h->run_heads, mem, RAD_MEM_LINKS, sizeof(uint32_t),
	              shift, 0);
	rad_pool_init(&h->links_ext, mem, RAD_MEM_LINKS, sizeof(rad_link_ext),
	              shift < 10 ? shift + 1 : 11, 0);
}

size_t rad_hier_grow_blocks(const rad_hier *h)
{
	const rad_pool *third = h->lists ? &h->run_heads : &h->links_ext;
	return ((size_t)h->elems.rec_size << h->elems.shift) +
	       ((size_t)h->runs.rec_size << h->runs.shift) +
	       ((size_t)h->links.rec_size << h->links.shift) +
	       ((size_t)third->rec_size << third->shift);
}

rad_status rad_hier_init(rad_hier *h, const rad_scene *s, rad_mem *mem,
                         double min_edge, int lists, int exact_dB, rad_par *par,
                         rad_error *err)
{
	static _Atomic uint64_t next_gen = 1;
	memset(h, 0, sizeof(*h));
	h->gen = atomic_fetch_add(&next_gen, 1);
	h->scene = s;
	h->mem = mem;
	h->min_edge = min_edge;
	uint32_t n = s->npolys;
	/* The roots must be one run: size the first block to hold them. */
	/* Blocks of about n records (64 to 4096): small scenes do not pay
	 * for big blocks, big ones do not keep long block tables. */
	uint32_t shift = 6;
	while (shift < 12 && (1u << shift) < n)
		shift++;
	h->lists = lists;
	h->exact_dB = exact_dB;
	init_pools(h, mem, shift, n, lists);
	/* Under a memory budget a block of each pool that grows is kept free
	 * (wave_room_for): together they take at most a 64th of it (a
	 * 2 MiB budget lost 288 KiB to blocks of 4096).  The pools hold
	 * nothing yet: made again, they cost nothing. */
	while (mem->budget && shift > 6 &&
	       rad_hier_grow_blocks(h) > (size_t)mem->budget / 64)
		init_pools(h, mem, --shift, n, lists);
	if (n == 0)
		return rad_fail(err, RAD_ERR_INVALID, "scene has no polygons");
	h->order =
	        rad_mem_alloc(mem, RAD_MEM_ELEM_CLUSTER, n * sizeof(uint32_t));
	h->root_exposed = rad_mem_alloc(mem, RAD_MEM_ELEM_SURFACE, n);
	/* Runs start 4-aligned (Runs): the pad records after the roots are
	 * never in a tree.  Block 0 holds them (its size is a multiple of
	 * 64), and every later block starts 4-aligned too. */
	h->run0 = (n + 3) & ~3u;
	if (!h->order || !h->root_exposed ||
	    rad_pool_add(&h->clusters, 1) != 0) {
		rad_hier_destroy(h);
		return rad_fail(err, RAD_ERR_NOMEM, "hierarchy: out of memory");
	}
	for (uint32_t i = 0; i < n; i++) {
		h->root_exposed[i] = RAD_EXPOSED_ALL;
		h->order[i] = i;
	}
	rad_cluster *root = rad_cluster_at(h, 0);
	root->first = 0;
	root->count = n;
	/* The tree before the roots: its centroids' scratch (24 bytes a
	 * polygon) on top of them was the 10M field's hr peak. */
	rad_status st = build_clusters(h, par, err);
	if (!st && (rad_pool_add(&h->elems, n) != 0 ||
	            (h->run0 > n && rad_pool_add(&h->elems, h->run0 - n) != n)))
		st = rad_fail(err, RAD_ERR_NOMEM, "hierarchy: out of memory");
	if (!st) {
		for (uint32_t i = 0; i < n; i++)
			rad_elem_at(h, i)->child = RAD_NONE;
		h->nleaves = n;
		/* After the roots' edges are known (rad_hier_cover_dist). */
		if (s->vis)
			rad_par_for(par, n, COVER_GRAIN, measure_roots, h);
	}
	if (!st && lists) {
		h->inner_heads = rad_mem_alloc(mem, RAD_MEM_LINKS,
		                               h->ninner * sizeof(uint32_t));
		if (h->inner_heads)
			no_links(h->inner_heads, h->ninner);
		else
			st = rad_fail(err, RAD_ERR_NOMEM,
			              "hierarchy: out of memory");
	}
	if (st) {
		rad_hier_destroy(h);
		return st;
	}
	rad_hier_reset_emission(h);
	return RAD_OK;
}

void rad_hier_destroy(rad_hier *h)
{
	rad_pool_destroy(&h->elems);
	rad_pool_destroy(&h->runs);
	rad_mem_free(h->mem, RAD_MEM_ELEM_SURFACE, h->root_exposed);
	h->root_exposed = NULL;
	rad_pool_destroy(&h->clusters);
	rad_pool_destroy(&h->links);
	for (uint32_t b = 0; b < h->npack_blocks; b++)
		rad_mem_free(h->mem, RAD_MEM_LINKS, h->pack[b]);
	rad_mem_free(h->mem, RAD_MEM_LINKS, h->pack);
	h->pack = NULL;
	h->npack_blocks = h->pack_cap = h->npacked = h->ndead = 0;
	rad_pool_destroy(&h->links_ext);
	rad_pool_destroy(&h->run_heads);
	rad_mem_free(h->mem, RAD_MEM_LINKS, h->inner_heads);
	h->inner_heads = NULL;
	rad_mem_free(h->mem, RAD_MEM_ELEM_CLUSTER, h->order);
	h->order = NULL;
	rad_mem_free(h->mem, RAD_MEM_ELEM_CLUSTER, h->inner);
	h->inner = NULL;
	h->ninner = 0;
	rad_mem_free(h->mem, RAD_MEM_ELEM_CLUSTER, h->flux);
	h->flux = NULL;
	rad_hier_drop_deltas(h);
}

rad_status rad_hier_keep_flux(rad_hier *h, rad_error *err)
{
	if (!h->flux)
		h->flux = rad_mem_alloc(h->mem, RAD_MEM_ELEM_CLUSTER,
		                        h->clusters.count * sizeof(*h->flux));
	if (!h->flux)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "hierarchy: out of memory (clusters' flux)");
	memset(h->flux, 0, h->clusters.count * sizeof(*h->flux));
	return RAD_OK;
}

static double poly_edge(const rad_scene *s, const rad_poly *p)
{
	v3 a = rad_poly_e1(s, p), b = rad_poly_e2(s, p);
	/* The third edge: e2 - e1 (triangle) or the diagonal's sides. */
	double l = fmax(v3_len(a), v3_len(b));
	if (!p->quad)
		l = fmax(l, v3_len(v3_sub(b, a)));
	return l;
}

double rad_elem_edge(const rad_hier *h, uint32_t id)
{
	/* Halving a float vector is exact, and so is its length's half. */
	return ldexp(
	        poly_edge(h->scene, &h->scene->polys[rad_elem_poly(h, id)]),
	        -rad_elem_level(h, id));
}

int rad_elem_can_split(const rad_hier *h, uint32_t id)
{
	return rad_elem_level(h, id) < RAD_ELEM_MAX_LEVEL &&
	       rad_elem_edge(h, id) > h->min_edge;
}

void rad_region_quarter(float p0[3], float e1[3], float e2[3], int quad, int k)
{
	/* Triangle: three corner copies and the inverted centre triangle;
	 * parallelogram: the four quarter cells.  Same orientation.  Sums
	 * in double, rounded once to float (the origin of quarter 3 is
	 * (p0 + e1/2) + e2/2, not two float sums). */
	double s = k == 3 && !quad ? -0.5 : 0.5;
	for (int i = 0; i < 3; i++) {
		double o = p0[i], h1 = 0.5 * (double)e1[i],
		       h2 = 0.5 * (double)e2[i];
		if (k & 1)
			o += h1;
		if (k & 2)
			o += h2;
		p0[i] = (float)o;
		e1[i] = (float)(s * (double)e1[i]);
		e2[i] = (float)(s * (double)e2[i]);
	}
}

void rad_elem_region(const rad_hier *h, uint32_t id, float p0[3], float e1[3],
                     float e2[3])
{
	const rad_poly *p = &h->scene->polys[rad_elem_poly(h, id)];
	rad_poly_frame(h->scene, p, p0, e1, e2);
	int level = rad_elem_level(h, id);
	uint32_t path = rad_elem_path(h, id);
	for (int l = 0; l < level; l++)
		rad_region_quarter(p0, e1, e2, p->quad,
		                   (int)(path >> (2 * l)) & 3);
}

void rad_elem_patch(const rad_hier *h, uint32_t id, rad_patch *p)
{
	float p0[3], e1[3], e2[3];
	rad_elem_region(h, id, p0, e1, e2);
	rad_patch_from_floats(p, p0, e1, e2, rad_elem_quad(h, id));
}

#define PATCH_MEMO 4 /* entries, by element id modulo */
static _Thread_local struct {
	uint64_t gen;
	uint32_t id;
	rad_patch p;
} patch_memo[PATCH_MEMO];

void rad_elem_patch_id(const rad_hier *h, uint32_t id, rad_patch *p)
{
	unsigned k = id % PATCH_MEMO;
	if (h->gen && patch_memo[k].gen == h->gen && patch_memo[k].id == id) {
		*p = patch_memo[k].p;
		return;
	}
	rad_elem_patch(h, id, p);
	if (h->gen) {
		patch_memo[k].gen = h->gen;
		patch_memo[k].id = id;
		patch_memo[k].p = *p;
	}
}

uint32_t rad_elem_split(rad_hier *h, uint32_t id)
{
	rad_elem *e = rad_elem_at(h, id);
	if (!rad_elem_is_leaf(e))
		return e->child;
	uint32_t c = rad_pool_add(&h->elems, 4);
	if (c == RAD_NONE)
		return RAD_NONE;
	/* The run's record: runs are never released, so the next one made
	 * is the one a new run needs (a reused run has its own already). */
	uint32_t r = (c - h->run0) >> 2;
	while (h->runs.count <= r || (h->lists && h->run_heads.count <= r)) {
		rad_pool *p = h->runs.count <= r ? &h->runs : &h->run_heads;
		if (rad_pool_add(p, 1) == RAD_NONE) {
			rad_pool_release_run(&h->elems, c, 4);
			return RAD_NONE;
		}
	}
	e = rad_elem_at(h, id);
	/* Its list (a leaf's, in its child field) moves to the run's word
	 * (Leaves and lists). */
	if (h->lists)
		*(uint32_t *)rad_pool_at(&h->run_heads, r) = e->child;
	rad_elem_run *run = rad_pool_at(&h->runs, r);
	run->poly = rad_elem_poly(h, id);
	run->level = (uint8_t)(rad_elem_level(h, id) + 1);
	run->path = rad_elem_path(h, id);
	uint8_t exposed = rad_elem_exposed_raw(h, id);
	for (uint32_t k = 0; k < 4; k++) {
		rad_elem *ch = rad_elem_at(h, c + k);
		ch->child = RAD_NONE;
		memcpy(ch->B, e->B, sizeof(ch->B));
		rad_elem_copy_dB(h, ch, e);
		/* Every quarter measures its own: a parent's points can
		 * miss a cover that a quarter straddles (hier.h). */
		run->exposed[k] = exposed;
		if (h->scene->vis)
			measure_exposed(h, c + k);
	}
	e->child = c;
	h->nleaves += 3;
	h->splits++;
	return c;
}

static rad_status mesh_down(rad_hier *h, uint32_t id, double edge,
                            rad_error *err)
{
	if (rad_elem_edge(h, id) <= edge || !rad_elem_can_split(h, id))
		return RAD_OK;
	uint32_t c = rad_elem_split(h, id);
	if (c == RAD_NONE)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "uniform mesh: out of memory");
	for (uint32_t k = 0; k < 4; k++) {
		rad_status st = mesh_down(h, c + k, edge, err);
		if (st)
			return st;
	}
	return RAD_OK;
}

rad_status rad_hier_mesh_uniform(rad_hier *h, double edge, rad_error *err)
{
	if (!(edge > 0))
		return rad_fail(err, RAD_ERR_INVALID,
		                "mesh edge must be > 0 (got %g)", edge);
	for (uint32_t i = 0; i < h->scene->npolys; i++) {
		rad_status st = mesh_down(h, i, edge, err);
		if (st)
			return st;
	}
	return RAD_OK;
}

/* Counts the elements of the tree below id (id included) into *n;
 * returns the depth to which it is complete: every node above that level
 * split. */
static int census_tree(const rad_hier *h, uint32_t id, uint64_t *n)
{
	const rad_elem *e = rad_elem_at(h, id);
	int d = RAD_ELEM_MAX_LEVEL;
	++*n;
	if (rad_elem_is_leaf(e))
		return 0;
	for (uint32_t k = 0; k < 4; k++) {
		int c = census_tree(h, e->child + k, n);
		if (c < d)
			d = c;
	}
	return d + 1;
}

_Static_assert(RAD_CENSUS_DEPTHS == RAD_ELEM_MAX_LEVEL + 1, "census depths");

void rad_hier_census(const rad_hier *h, rad_census *out)
{
	const rad_scene *s = h->scene;
	memset(out, 0, sizeof(*out));
	for (uint32_t p = 0; p < s->npolys; p++) {
		const rad_material *m = &s->mats[s->polys[p].mat];
		uint64_t n = 0;
		int d = census_tree(h, p, &n);
		out->elements += n;
		out->polys_by_depth[d]++;
		out->elements_by_depth[d] += n;
		if (!(m->rho[0] > 0 || m->rho[1] > 0 || m->rho[2] > 0) &&
		    (m->emit[0] > 0 || m->emit[1] > 0 || m->emit[2] > 0))
			out->below_emitters += n - 1;
	}
}

/* Set B = E on the leaves below element id; I and dB cleared. */
static void reset_tree(rad_hier *h, uint32_t id)
{
	rad_elem *e = rad_elem_at(h, id);
	const rad_material *m = rad_elem_mat(h, id);
	for (int c = 0; c < 3; c++) {
		e->B[c] = m->emit[c];
		e->I[c] = 0;
	}
	static const float zero[3] = {0, 0, 0};
	rad_elem_set_dB(h, e, zero);
	if (!rad_elem_is_leaf(e))
		for (uint32_t k = 0; k < 4; k++)
			reset_tree(h, e->child + k);
}

void rad_hier_reset_emission(rad_hier *h)
{
	for (uint32_t i = 0; i < h->scene->npolys; i++)
		reset_tree(h, i);
	if (h->flux)
		memset(h->flux, 0, h->clusters.count * sizeof(*h->flux));
	rad_hier_pull(h);
}

/* Area-weighted sums of B and dB into acc[0..5]. */
static void acc_node(double acc[6], float area, const float B[3],
                     const float dB[3])
{
	for (int c = 0; c < 3; c++) {
		acc[c] += (double)area * B[c];
		acc[3 + c] += (double)area * dB[c];
	}
}

static void set_avg(float B[3], float dB[3], const double acc[6], double area)
{
	for (int c = 0; c < 3; c++) {
		B[c] = area > 0 ? (float)(acc[c] / area) : 0;
		dB[c] = area > 0 ? (float)(acc[3 + c] / area) : 0;
	}
}

/* Post-order: B and dB of an inner element are its children's averages. */
static void pull_elem(rad_hier *h, uint32_t id)
{
	rad_elem *e = rad_elem_at(h, id);
	if (rad_elem_is_leaf(e))
		return;
	double acc[6] = {0}, area = 0;
	for (uint32_t k = 0; k < 4; k++) {
		pull_elem(h, e->child + k);
		const rad_elem *ch = rad_elem_at(h, e->child + k);
		float a = rad_elem_area(h, e->child + k), dB[3];
		rad_elem_dB(h, ch, dB);
		acc_node(acc, a, ch->B, dB);
		area += a;
	}
	float dB[3];
	set_avg(e->B, dB, acc, area);
	rad_elem_set_dB(h, e, dB);
}

/* B, dB (area averages) and nB, ndB of leaf cluster cl, summed from its
 * polygons' root elements. */
static void leaf_sums(const rad_hier *h, const rad_cluster *cl, double acc[6],
                      double nb[6])
{
	for (uint32_t j = cl->first; j < cl->first + cl->count; j++) {
		const rad_elem *e = rad_elem_at(h, h->order[j]);
		v3 u = rad_poly_normal(&h->scene->polys[h->order[j]]);
		const double n[3] = {u.x, u.y, u.z};
		float a = rad_elem_area(h, h->order[j]), dB[3];
		rad_elem_dB(h, e, dB);
		double b = (double)a * rad_luma(e->B);
		double d = (double)a * rad_luma(dB);
		acc_node(acc, a, e->B, dB);
		for (int c = 0; c < 3; c++) {
			nb[c] += b * n[c];
			nb[3 + c] += d * n[c];
		}
	}
}

/* dB and ndB of inner cluster cl from its children's, as pull_cluster
 * sums them; for every inner cluster of the subtree, into out
 * (rad_hier_keep_deltas) and luma(dB) into luma (rad_hier_delta_lumas)
 * too, either when not NULL. */
static void pull_deltas(const rad_hier *h, const rad_cluster *cl, float dB[3],
                        float ndB[3], rad_cluster_deltas *out, double *luma)
{
	double acc[3] = {0, 0, 0}, nb[3] = {0, 0, 0};
	for (uint32_t k = 0; k < 2; k++) {
		const rad_cluster *ch = rad_cluster_at(h, cl->child + k);
		float cdB[3], cndB[3];
		if (!rad_cluster_is_leaf(ch))
			pull_deltas(h, ch, cdB, cndB, out, luma);
		else
			rad_cluster_delta(h, ch, cdB, cndB);
		for (int c = 0; c < 3; c++) {
			acc[c] += (double)ch->area * cdB[c];
			nb[c] += cndB[c];
		}
	}
	for (int c = 0; c < 3; c++) {
		dB[c] = cl->area > 0 ? (float)(acc[c] / cl->area) : 0;
		ndB[c] = (float)nb[c];
	}
	if (out) {
		rad_cluster_deltas *d = &out[rad_cluster_inner_index(cl)];
		memcpy(d->dB, dB, sizeof(d->dB));
		memcpy(d->ndB, ndB, sizeof(d->ndB));
	}
	if (luma)
		luma[rad_cluster_inner_index(cl)] = rad_luma(dB);
}

void rad_cluster_delta(const rad_hier *h, const rad_cluster *cl, float dB[3],
                       float ndB[3])
{
	if (!rad_cluster_is_leaf(cl)) {
		float d[3], nd[3];
		if (h->deltas) {
			const rad_cluster_deltas *k =
			        &h->deltas[rad_cluster_inner_index(cl)];
			memcpy(d, k->dB, sizeof(d));
			memcpy(nd, k->ndB, sizeof(nd));
		} else {
			pull_deltas(h, cl, d, nd, NULL, NULL);
		}
		if (dB)
			memcpy(dB, d, sizeof(d));
		if (ndB)
			memcpy(ndB, nd, sizeof(nd));
		return;
	}
	/* leaf_sums' dB and ndB alone: the same sums in the same order */
	double acc[3] = {0, 0, 0}, nb[3] = {0, 0, 0};
	for (uint32_t j = cl->first; j < cl->first + cl->count; j++) {
		const rad_elem *e = rad_elem_at(h, h->order[j]);
		float a = rad_elem_area(h, h->order[j]), eB[3];
		rad_elem_dB(h, e, eB);
		for (int c = 0; c < 3; c++)
			acc[c] += (double)a * eB[c];
		if (!ndB)
			continue;
		v3 u = rad_poly_normal(&h->scene->polys[h->order[j]]);
		const double n[3] = {u.x, u.y, u.z};
		double d = (double)a * rad_luma(eB);
		for (int c = 0; c < 3; c++)
			nb[c] += d * n[c];
	}
	for (int c = 0; c < 3; c++) {
		if (dB)
			dB[c] = cl->area > 0 ? (float)(acc[c] / cl->area) : 0;
		if (ndB)
			ndB[c] = (float)nb[c];
	}
}

rad_status rad_hier_keep_deltas(rad_hier *h, rad_error *err)
{
	if (!h->deltas) {
		rad_cluster_deltas *d =
		        rad_mem_alloc(h->mem, RAD_MEM_ELEM_CLUSTER,
		                      h->ninner * sizeof(*h->deltas));
		if (!d)
			return rad_fail(err, RAD_ERR_NOMEM,
			                "hierarchy: out of memory (clusters' "
			                "increments)");
		memset(d, 0, h->ninner * sizeof(*d));
		const rad_cluster *root = rad_cluster_at(h, 0);
		if (!rad_cluster_is_leaf(root)) {
			float dB[3], ndB[3];
			pull_deltas(h, root, dB, ndB, d, NULL);
		}
		h->deltas = d;
	}
	return RAD_OK;
}

void rad_hier_delta_lumas(const rad_hier *h, double *out)
{
	const rad_cluster *root = rad_cluster_at(h, 0);
	float dB[3], ndB[3];
	if (!rad_cluster_is_leaf(root))
		pull_deltas(h, root, dB, ndB, NULL, out);
}

void rad_hier_drop_deltas(rad_hier *h)
{
	rad_mem_free(h->mem, RAD_MEM_ELEM_CLUSTER, h->deltas);
	h->deltas = NULL;
}

/* Post-order: B and nB of every cluster, dB and ndB of the inner ones
 * (a leaf's are summed when asked, rad_cluster_delta), after the
 * polygons' trees are pulled; cluster id's dB and ndB also go to its
 * parent through dB and ndB. */
static void pull_cluster(rad_hier *h, uint32_t id, float dB[3], float ndB[3])
{
	rad_cluster *cl = rad_cluster_at(h, id);
	double acc[6] = {0}, nb[6] = {0};
	if (rad_cluster_is_leaf(cl)) {
		leaf_sums(h, cl, acc, nb);
		set_avg(cl->B, dB, acc, cl->area);
		for (int c = 0; c < 3; c++) {
			cl->nB[c] = (float)nb[c];
			ndB[c] = (float)nb[3 + c];
		}
		return;
	}
	for (uint32_t k = 0; k < 2; k++) {
		float cdB[3], cndB[3];
		pull_cluster(h, cl->child + k, cdB, cndB);
		const rad_cluster *ch = rad_cluster_at(h, cl->child + k);
		acc_node(acc, ch->area, ch->B, cdB);
		for (int c = 0; c < 3; c++) {
			nb[c] += ch->nB[c];
			nb[3 + c] += cndB[c];
		}
	}
	set_avg(cl->B, dB, acc, cl->area);
	for (int c = 0; c < 3; c++) {
		cl->nB[c] = (float)nb[c];
		ndB[c] = (float)nb[3 + c];
	}
	if (h->deltas) {
		rad_cluster_deltas *d = &h->deltas[rad_cluster_inner_index(cl)];
		memcpy(d->dB, dB, sizeof(d->dB));
		memcpy(d->ndB, ndB, sizeof(d->ndB));
	}
}

/* One push: the leaf update, the optional payload and its user data. */
typedef struct push_ctx {
	rad_hier *h;
	rad_leaf_update leaf;
	rad_push_extra extra;
	rad_push_own own;
	void *ud;
	struct push_task *tasks; /* with own: the subtrees handed out */
	uint32_t ntasks;
} push_ctx;

/*
 * With own, the push gathers every cluster on its way down, and nothing
 * it writes is shared between two subtrees (a root takes shares from its
 * one leaf cluster): below PUSH_TASK_DEPTH the subtrees are pushed on the
 * pool's threads, each with what its parent passed down, the same sums
 * in any order (a serial walk of the clusters' links was 14 % of a step
 * on the report's grand hall).
 */
#define PUSH_TASK_DEPTH 6
typedef struct push_task {
	uint32_t id;
	float up[3], V[3], S;
} push_task;

/* x = up + the node's own payload (zeros without a payload). */
static void extra_add(const push_ctx *p, uint32_t tagged, const float up[],
                      float x[RAD_PUSH_EXTRA])
{
	const float *own = p->extra ? p->extra(p->h, tagged, p->ud) : NULL;
	for (int k = 0; k < RAD_PUSH_EXTRA; k++)
		x[k] = up[k] + (own ? own[k] : 0);
}

static void push_elem(const push_ctx *p, uint32_t id, const float up[3],
                      const float upx[RAD_PUSH_EXTRA])
{
	rad_elem *e = rad_elem_at(p->h, id);
	float x[RAD_PUSH_EXTRA];
	extra_add(p, id, upx, x);
	for (int c = 0; c < 3; c++)
		e->I[c] += up[c];
	if (rad_elem_is_leaf(e)) {
		p->leaf(p->h, id, e, p->extra ? x : NULL, p->ud);
		return;
	}
	double ex[4], sum = 0;
	int even = 1;
	for (uint32_t k = 0; k < 4; k++) {
		ex[k] = rad_elem_exposed(p->h, e->child + k);
		sum += ex[k];
		even &= ex[k] == ex[0];
	}
	for (uint32_t k = 0; k < 4; k++) {
		/* Shares by exposed fraction (hier.h, Covered parts). */
		double f = even || !(sum > 0) ? 1 : 4 * ex[k] / sum;
		float si[3];
		for (int c = 0; c < 3; c++)
			si[c] = (float)(f * e->I[c]);
		push_elem(p, e->child + k, si, x);
	}
}

/* Share weight w(n) per unit area of a polygon of normal n (hier.h). */
static double shape_poly(v3 n, const double V[3], double iso)
{
	double c = n.x * V[0] + n.y * V[1] + n.z * V[2];
	return (c > 0 ? c : 0) + iso;
}

/* w integrated over a cluster's polygons. */
static double shape_cluster(const rad_hier *h, const rad_cluster *c,
                            const double V[3], double vlen, double iso)
{
	double w = iso * c->area;
	if (vlen > 0)
		w += vlen * rad_cluster_proj(h, c, V[0] / vlen, V[1] / vlen,
		                             V[2] / vlen);
	return w;
}

/* Hand a share f of a cluster's I and payload to a child. */
static void share_of(double f, const float I[3], const float x[], float si[3],
                     float sx[RAD_PUSH_EXTRA])
{
	for (int c = 0; c < 3; c++)
		si[c] = (float)(f * I[c]);
	for (int k = 0; k < RAD_PUSH_EXTRA; k++)
		sx[k] = (float)(f * x[k]);
}

static void push_cluster(push_ctx *p, uint32_t id, const float up[3],
                         const float upV[3], float upS,
                         const float upx[RAD_PUSH_EXTRA], unsigned depth)
{
	rad_hier *h = p->h;
	const rad_cluster *cl = rad_cluster_at(h, id);
	float x[RAD_PUSH_EXTRA], si[3], sx[RAD_PUSH_EXTRA];
	rad_cluster_flux f;
	if (p->tasks && depth == PUSH_TASK_DEPTH && !rad_cluster_is_leaf(cl)) {
		push_task *t = &p->tasks[p->ntasks++];
		t->id = id;
		memcpy(t->up, up, sizeof(t->up));
		memcpy(t->V, upV, sizeof(t->V));
		t->S = upS;
		return;
	}
	extra_add(p, id | RAD_TAG_CLUSTER, upx, x);
	if (p->own)
		p->own(h, id, &f, p->ud);
	else
		f = h->flux[id];
	for (int c = 0; c < 3; c++) {
		f.I[c] += up[c];
		f.V[c] += upV[c];
	}
	f.S += upS;
	double V[3] = {f.V[0], f.V[1], f.V[2]};
	double vlen = sqrt(V[0] * V[0] + V[1] * V[1] + V[2] * V[2]);
	double iso = 0.25 * fmax(0, f.S - vlen);
	if (!rad_cluster_is_leaf(cl)) {
		const rad_cluster *k[2] = {rad_cluster_at(h, cl->child),
		                           rad_cluster_at(h, cl->child + 1)};
		double w[2], sum = 0;
		for (int i = 0; i < 2; i++)
			sum += w[i] = shape_cluster(h, k[i], V, vlen, iso);
		for (int i = 0; i < 2; i++) {
			/* No direction recorded (no light): the mean. */
			double w_i =
			        sum > 0 && k[i]->area > 0
			                ? cl->area * w[i] / (sum * k[i]->area)
			                : 1;
			share_of(w_i, f.I, x, si, sx);
			push_cluster(p, cl->child + (uint32_t)i, si, f.V, f.S,
			             sx, depth + 1);
		}
		return;
	}
	double sum = 0, shape[RAD_CLUSTER_LEAF_MAX];
	for (uint32_t j = cl->first; j < cl->first + cl->count; j++) {
		const rad_poly *q = &h->scene->polys[h->order[j]];
		double ex = rad_elem_exposed(h, h->order[j]);
		double *sh = &shape[j - cl->first];
		*sh = shape_poly(rad_poly_normal(q), V, iso);
		sum += ex * q->area * *sh;
	}
	for (uint32_t j = cl->first; j < cl->first + cl->count; j++) {
		double ex = rad_elem_exposed(h, h->order[j]);
		double w = sum > 0 ? ex * cl->area * shape[j - cl->first] / sum
		                   : 1;
		share_of(w, f.I, x, si, sx);
		if (p->own) { /* the roots' trees wait (rad_hier_push) */
			rad_elem *e = rad_elem_at(h, h->order[j]);
			for (int c = 0; c < 3; c++)
				e->I[c] += si[c];
		} else {
			push_elem(p, h->order[j], si, sx);
		}
	}
}

static void push_subtrees(void *ud, size_t b, size_t e, int thread)
{
	const push_ctx *p = ud;
	push_ctx mine = *p;
	const float zero[RAD_PUSH_EXTRA] = {0};
	(void)thread;
	mine.tasks = NULL;
	for (size_t i = b; i < e; i++) {
		const push_task *t = &p->tasks[i];
		push_cluster(&mine, t->id, t->up, t->V, t->S, zero,
		             PUSH_TASK_DEPTH);
	}
}

void rad_hier_push(rad_hier *h, rad_leaf_update leaf, rad_push_extra extra,
                   rad_push_own own, void *ud, rad_par *par)
{
	const float zero[RAD_PUSH_EXTRA > 3 ? RAD_PUSH_EXTRA : 3] = {0};
	push_task tasks[1u << PUSH_TASK_DEPTH];
	push_ctx p = {h, leaf, extra, own, ud, own ? tasks : NULL, 0};
	push_cluster(&p, 0, zero, zero, 0, zero, 0);
	if (p.ntasks)
		rad_par_for(par, p.ntasks, 1, push_subtrees, &p);
	/* A cluster gathered here reads its sources' B as the step found
	 * them, so no leaf is updated before the last of them: the roots
	 * took their clusters' shares into I, and their trees are pushed now,
	 * in the order the single pass reaches them (the same sums). */
	if (own)
		for (uint32_t j = 0; j < h->scene->npolys; j++)
			push_elem(&p, h->order[j], zero, zero);
}

void rad_hier_pull(rad_hier *h)
{
	/* The trees, not the pools, say which records are live: a pool may
	 * hold records skipped to keep sibling runs in one block. */
	for (uint32_t i = 0; i < h->scene->npolys; i++)
		pull_elem(h, i);
	float dB[3], ndB[3]; /* the root's, kept in its record */
	pull_cluster(h, 0, dB, ndB);
}

uint32_t rad_link_new(rad_hier *h, uint32_t rcv, uint32_t src, float ff,
                      float spread)
{
	uint32_t id = rad_pool_add(&h->links, 1);
	if (id == RAD_NONE)
		return RAD_NONE;
	rad_link *l = rad_link_at(h, id);
	l->rcv = rcv;
	l->src = src;
	l->ff = ff;
	l->aux = 0;
	rad_link_set_spread(h, l, spread);
	return id;
}

rad_status rad_link_make_passive(rad_hier *h, uint32_t id, uint32_t child,
                                 uint32_t n, int split_src)
{
	uint32_t x = rad_pool_add(&h->links_ext, 1);
	if (x == RAD_NONE)
		return RAD_ERR_NOMEM;
	rad_link *l = rad_link_at(h, id);
	rad_link_ext *e = rad_pool_at(&h->links_ext, x);
	e->spread = rad_link_spread(h, l);
	e->child = child;
	e->nchild = (uint16_t)n;
	e->split_src = (uint16_t)(split_src != 0);
	l->aux = RAD_LINK_EXT | x;
	return RAD_OK;
}

void rad_link_make_active(rad_hier *h, uint32_t id)
{
	rad_link *l = rad_link_at(h, id);
	uint32_t x = l->aux & ~RAD_LINK_EXT;
	float spread = rad_link_ext_of(h, l)->spread;
	rad_pool_release(&h->links_ext, x);
	l->aux = 0;
	rad_link_set_spread(h, l, spread);
}

/* The moment model of inner cluster c (hier.h). */
static double proj_model(const rad_hier *h, const rad_cluster *c, double dx,
                         double dy, double dz)
{
	const rad_cluster_inner *mo = &h->inner[rad_cluster_inner_index(c)];
	const float *m = mo->m;
	double q = m[0] * dx * dx + m[1] * dy * dy + m[2] * dz * dz +
	           2 * (m[3] * dx * dy + m[4] * dx * dz + m[5] * dy * dz);
	double odd = mo->n[0] * dx + mo->n[1] * dy + mo->n[2] * dz;
	return rad_pos(0.5 * (odd + mo->q * sqrt(rad_pos(q))));
}

static double proj_at(const rad_hier *h, const rad_cluster *c, double dx,
                      double dy, double dz, int depth)
{
	if (rad_cluster_is_leaf(c)) { /* a few polygons: exact */
		double p = 0;
		for (uint32_t j = c->first; j < c->first + c->count; j++) {
			const rad_poly *q = &h->scene->polys[h->order[j]];
			p += rad_poly_shown(q, dx, dy, dz);
		}
		return p;
	}
	if (depth == 0)
		return proj_model(h, c, dx, dy, dz);
	const rad_cluster *k = rad_cluster_at(h, c->child | RAD_TAG_CLUSTER);
	return proj_at(h, k, dx, dy, dz, depth - 1) +
	       proj_at(h, k + 1, dx, dy, dz, depth - 1);
}

double rad_cluster_proj(const rad_hier *h, const rad_cluster *c, double dx,
                        double dy, double dz)
{
	return proj_at(h, c, dx, dy, dz, RAD_PROJ_DEPTH);
}

void rad_cluster_normal(const rad_hier *h, const rad_cluster *c, float n[3])
{
	if (!rad_cluster_is_leaf(c)) {
		memcpy(n, h->inner[rad_cluster_inner_index(c)].n,
		       3 * sizeof(*n));
		return;
	}
	double s[3] = {0, 0, 0}; /* fill_cluster's sums */
	for (uint32_t i = c->first; i < c->first + c->count; i++) {
		const rad_poly *p = &h->scene->polys[h->order[i]];
		v3 an = rad_poly_an(p);
		s[0] += an.x;
		s[1] += an.y;
		s[2] += an.z;
	}
	for (int k = 0; k < 3; k++)
		n[k] = (float)s[k];
}

double rad_cluster_emit(const rad_hier *h, const rad_cluster *c,
                        const float B[3], const float nB[3], double p,
                        double dx, double dy, double dz)
{
	double mean = rad_luma(B);
	if (!(p > 1e-6 * c->area) || mean == 0)
		return 1;
	float n[3];
	rad_cluster_normal(h, c, n);
	double odd = (nB[0] * dx + nB[1] * dy + nB[2] * dz) / mean -
	             (n[0] * dx + n[1] * dy + n[2] * dz);
	double e = p + 0.5 * odd;
	e = e < 0 ? 0 : e > c->area ? c->area : e;
	return e / p > 4 ? 4 : e / p;
}

uint32_t *rad_node_links(const rad_hier *h, uint32_t tagged)
{
	if (tagged & RAD_TAG_CLUSTER)
		return rad_cluster_links(h, rad_cluster_at(h, tagged));
	return rad_elem_links(h, rad_elem_at(h, tagged));
}
