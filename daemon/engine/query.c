/*
 * query.c -- reading a published solution: illuminance at arbitrary points
 * (rad_solver_illuminance) and the per-leaf results for export
 * (rad_solver_leaves).  Both only read the hierarchy, so they work the same
 * for every solver and may run concurrently with each other.
 *
 * DESIGN
 * Illuminance at a point x with unit normal n is
 *   direct:  every scene light, exactly at x (rad_light_point, one ray);
 *   surfaces: a hierarchical final gather of the radiosity B published in
 *            the hierarchy, walking down from the root cluster.
 * For each node the walk has an upper bound of what it can give:
 *   cluster: luma(B) A / (pi dmin^2), dmin the distance from x to its box
 *            (every square metre inside radiates at most B / (pi d^2));
 *   element: luma(B) F, F the exact unoccluded point-to-polygon kernel
 *            (rad_ff_point_patch: Lambert's contour integral, clipped to
 *            x's hemisphere, zero for back faces and coplanar polygons).
 * A node is evaluated as a whole when it is far (size < THETA x distance)
 * and its bound is below FRACTION of the total gathered so far (never
 * taken below FLOOR_REL x the scene's mean exitance, so dark points do
 * not descend to every leaf); otherwise the walk descends.  Children are
 * visited nearest first so the running total grows early.  Evaluation:
 *   cluster: isotropic emitter of area A/4 at the box centre, times the
 *            visibility of the centre;
 *   element: exact kernel x visible fraction (visible_ff); surface leaves
 *            are always evaluated this way.  An inner element weights its
 *            four children's radiosity by their own kernels (no extra
 *            rays), so a gradient across it is not averaged away.
 * visible_ff traces VIS_RAYS rays to sample points of the source; when
 * some but not all are blocked and the source is near, it splits the
 * source geometrically into quarters (up to VIS_DEPTH levels) and sums the
 * exact kernel of each visible part.
 *
 * Emitters come out exact: when the walk reaches the root element of a
 * polygon whose material emits, the uniform part E is evaluated on the
 * whole polygon with the exact kernel, and only the reflected part B - E
 * goes down its quadtree.  Every threshold is a ratio (size/distance,
 * share of the total), so results do not depend on the scene's scale.
 *
 * A point lying on a surface sees the side its normal points to: rays
 * leave x with the given normal (rad_vis_segment offsets them), and the
 * polygon under x gets F = 0 from the kernel.  Points are independent and
 * evaluated in parallel, each writing only lux[i]; the walk of one point
 * is sequential, so results are identical for any thread count (a query
 * made while the pool is busy with another runs on its caller's thread).
 * The walk allocates nothing: C stack only (depth: cluster tree plus
 * quadtree levels).
 */
#include <math.h>

#include "ff.h"
#include "solver.h"
#include "vis.h"

#define THETA 0.5      /* far enough: size < THETA x distance */
#define FRACTION 0.01  /* ... and bound < FRACTION x running total */
#define FLOOR_REL 1e-3 /* running total floor, x scene mean exitance */
#define VIS_RAYS 4     /* shadow rays to a surface node */
#define VIS_DEPTH 3    /* geometric splits of a partly visible source */
#define POINT_GRAIN 4  /* points per parallel chunk */
#define NOISE_REL 1e-6 /* B - E below this share of E is float noise */

typedef struct gather {
	const rad_hier *h;
	const rad_vis *vis;
	v3 x, n;      /* the point and its unit normal */
	double total; /* photopic lux gathered so far */
	double floor; /* smallest running total used by the far test */
} gather;

static double luma_d(const double c[3])
{
	return RAD_LUMA_R * c[0] + RAD_LUMA_G * c[1] + RAD_LUMA_B * c[2];
}

/* Quarter a patch the way the quadtree does (the middle triangle of a
 * triangle points the other way but keeps the normal). */
static void patch_quarters(const rad_patch *p, rad_patch q[4])
{
	v3 a = v3_scale(p->e1, 0.5), b = v3_scale(p->e2, 0.5);
	v3 org[4] = {p->p0, v3_add(p->p0, a), v3_add(p->p0, b),
	             v3_add(v3_add(p->p0, a), b)};
	for (int k = 0; k < 4; k++) {
		q[k] = *p;
		q[k].p0 = org[k];
		q[k].e1 = a;
		q[k].e2 = b;
		q[k].area = p->area / 4;
	}
	if (!p->quad) {
		q[3].e1 = v3_scale(a, -1);
		q[3].e2 = v3_scale(b, -1);
	}
}

/* Longest extent of a patch (its longest edge or diagonal). */
static double patch_size(const rad_patch *p)
{
	v3 d = p->quad ? v3_add(p->e1, p->e2) : v3_sub(p->e2, p->e1);
	return fmax(fmax(v3_len(p->e1), v3_len(p->e2)), v3_len(d));
}

/*
 * F (the exact unoccluded kernel of s at the point) times the visible
 * fraction of s.  Rays go only to sample points in front of the point's
 * tangent plane (the rest of s does not contribute, and a ray there would
 * run under the surface).  A near source seen in part, or straddling the
 * plane with no sample in front, is split into quarters, each with its own
 * exact kernel.
 */
static double visible_ff(const gather *g, const rad_patch *s, double F,
                         int depth)
{
	v3 pts[RAD_FF_MAX_SAMPLES];
	int np = rad_patch_samples(s, VIS_RAYS, pts), tried = 0, open = 0;
	for (int k = 0; k < np; k++) {
		if (!(v3_dot(v3_sub(pts[k], g->x), g->n) > 0))
			continue;
		tried++;
		open += rad_vis_segment(g->vis, g->x, &g->n, pts[k], &s->n);
	}
	double d = v3_len(v3_sub(rad_patch_centroid(s), g->x));
	int settled = open == 0 || open == tried || patch_size(s) < THETA * d;
	if (depth >= VIS_DEPTH || (tried > 0 && settled))
		return tried > 0 ? F * open / tried : F;
	rad_patch q[4];
	patch_quarters(s, q);
	double sum = 0;
	for (int k = 0; k < 4; k++) {
		double f = rad_ff_point_patch(g->x, g->n, &q[k]);
		if (f > 0)
			sum += visible_ff(g, &q[k], f, depth + 1);
	}
	return sum;
}

static int far_enough(const gather *g, double size, double dist, double bound)
{
	return size < THETA * dist &&
	       bound <= FRACTION * fmax(g->total, g->floor);
}

/*
 * Sum of R F over the four children of an element evaluated as a whole:
 * kernels only, no rays.  The element's mean R times its F would miss the
 * correlation of the two across it (a wall brighter on its side nearer
 * the point), a bias that adds up over many far elements.
 */
static double children_rf(const gather *g, const rad_elem *e, const float E[3])
{
	double rf = 0;
	for (uint32_t k = 0; k < 4; k++) {
		const rad_elem *c = rad_elem_at(g->h, e->child + k);
		float R[3] = {c->B[0] - E[0], c->B[1] - E[1], c->B[2] - E[2]};
		rad_patch q;
		rad_patch_from_floats(&q, c->p0, c->e1, c->e2, c->quad);
		rf += rad_luma(R) * rad_ff_point_patch(g->x, g->n, &q);
	}
	return rf;
}

/* The reflected radiosity B - E of element id and below (E: the uniform
 * emission already counted exactly on the whole polygon, or zero). */
static void gather_elem(gather *g, uint32_t id, const float E[3])
{
	const rad_elem *e = rad_elem_at(g->h, id);
	float R[3] = {e->B[0] - E[0], e->B[1] - E[1], e->B[2] - E[2]};
	double r = rad_luma(R);
	/* On a black emitter B - E is only the rounding of the pull. */
	if (r <= NOISE_REL * rad_luma(E))
		return;
	rad_patch p;
	rad_patch_from_floats(&p, e->p0, e->e1, e->e2, e->quad);
	/* The kernel is additive over a partition: F = 0 here means nothing
	 * below is seen either. */
	double F = rad_ff_point_patch(g->x, g->n, &p);
	if (F <= 0)
		return;
	if (e->child == RAD_NONE) {
		g->total += r * visible_ff(g, &p, F, 0);
		return;
	}
	double d = v3_len(v3_sub(rad_patch_centroid(&p), g->x));
	if (!far_enough(g, patch_size(&p), d, r * F)) {
		for (uint32_t k = 0; k < 4; k++)
			gather_elem(g, e->child + k, E);
		return;
	}
	/* visible_ff / F: the element's visible fraction. */
	g->total += children_rf(g, e, E) * visible_ff(g, &p, F, 0) / F;
}

static void gather_poly(gather *g, uint32_t pid)
{
	static const float none[3] = {0, 0, 0};
	const rad_scene *s = g->h->scene;
	const rad_poly *poly = &s->polys[pid];
	const rad_material *m = &s->mats[poly->mat];
	double e = rad_luma(m->emit);
	if (e <= 0) {
		gather_elem(g, pid, none);
		return;
	}
	rad_patch p;
	rad_patch_from_poly(&p, poly);
	double F = rad_ff_point_patch(g->x, g->n, &p);
	if (F > 0)
		g->total += e * visible_ff(g, &p, F, 0);
	gather_elem(g, pid, m->emit);
}

static v3 box_centre(const rad_cluster *c)
{
	return v3_scale(v3_add(v3_f(c->lo), v3_f(c->hi)), 0.5);
}

/* 1 if the whole box lies behind the point's tangent plane. */
static int box_behind(const gather *g, const rad_cluster *c)
{
	for (int k = 0; k < 8; k++) {
		v3 q = v3_make(k & 1 ? c->hi[0] : c->lo[0],
		               k & 2 ? c->hi[1] : c->lo[1],
		               k & 4 ? c->hi[2] : c->lo[2]);
		if (v3_dot(g->n, v3_sub(q, g->x)) > 0)
			return 0;
	}
	return 1;
}

static double box_distance(const rad_cluster *c, v3 x)
{
	double p[3] = {x.x, x.y, x.z}, d2 = 0;
	for (int k = 0; k < 3; k++) {
		double t = fmax(fmax(c->lo[k] - p[k], p[k] - c->hi[k]), 0);
		d2 += t * t;
	}
	return sqrt(d2);
}

/* Isotropic cluster: area A/4 radiating B from its centre. */
static void eval_cluster(gather *g, const rad_cluster *c, double b, v3 ctr,
                         double d)
{
	double cosx = v3_dot(g->n, v3_sub(ctr, g->x)) / d;
	if (cosx <= 0 || !rad_vis_segment(g->vis, g->x, &g->n, ctr, NULL))
		return;
	g->total += b * (c->area / 4) * cosx / (M_PI * d * d);
}

static void gather_cluster(gather *g, uint32_t cid)
{
	const rad_cluster *c = rad_cluster_at(g->h, cid);
	double b = rad_luma(c->B);
	if (b <= 0 || c->area <= 0 || box_behind(g, c))
		return;
	v3 ctr = box_centre(c);
	double size = v3_len(v3_sub(v3_f(c->hi), v3_f(c->lo)));
	double d = v3_len(v3_sub(ctr, g->x));
	if (size < THETA * d) {
		double dmin = box_distance(c, g->x);
		double bound = b * c->area / (M_PI * dmin * dmin);
		if (far_enough(g, size, d, bound)) {
			eval_cluster(g, c, b, ctr, d);
			return;
		}
	}
	if (c->child == RAD_NONE) {
		for (uint32_t k = c->first; k < c->first + c->count; k++)
			gather_poly(g, g->h->order[k]);
		return;
	}
	/* Nearest child first: its contribution raises the running total
	 * before the farther one is tested. */
	uint32_t a = c->child, z = c->child + 1;
	v3 ca = box_centre(rad_cluster_at(g->h, a));
	v3 cz = box_centre(rad_cluster_at(g->h, z));
	if (v3_len(v3_sub(cz, g->x)) < v3_len(v3_sub(ca, g->x))) {
		a = z;
		z = c->child;
	}
	gather_cluster(g, a);
	gather_cluster(g, z);
}

/* ------------------------------------------------------------- queries */

typedef struct query {
	const rad_scene *scene;
	const rad_hier *h;
	const double *pts;
	double *lux;
	double floor;
} query;

static double point_lux(const query *q, v3 x, v3 n)
{
	const rad_scene *s = q->scene;
	gather g = {q->h, s->vis, x, n, 0, q->floor};
	for (uint32_t l = 0; l < s->nlights; l++) {
		const rad_light *L = &s->lights[l];
		g.total += rad_light_point(s->vis, L, x, n, NULL) *
		           luma_d(L->intensity);
	}
	if (s->npolys > 0)
		gather_cluster(&g, 0 | RAD_TAG_CLUSTER);
	return g.total;
}

static void query_range(void *ud, size_t begin, size_t end, int thread)
{
	const query *q = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++) {
		const double *p = q->pts + 6 * i;
		q->lux[i] = point_lux(q, v3_d(p), v3_norm(v3_d(p + 3)));
	}
}

static rad_status check_points(const double *pts, size_t n, rad_error *err)
{
	for (size_t i = 0; i < n; i++) {
		v3 x = v3_d(pts + 6 * i), nx = v3_d(pts + 6 * i + 3);
		if (!v3_finite(x) || !v3_finite(nx))
			return rad_fail(err, RAD_ERR_INVALID,
			                "illuminance: point %zu has a "
			                "non-finite coordinate or normal",
			                i);
		if (!(v3_len(nx) > 0))
			return rad_fail(err, RAD_ERR_INVALID,
			                "illuminance: point %zu has a zero "
			                "normal",
			                i);
	}
	return RAD_OK;
}

rad_status rad_query_illuminance(const rad_scene *scene, const rad_hier *h,
                                 rad_par *par, const double *pts, size_t n,
                                 double *lux, rad_error *err)
{
	if (n > 0 && (!pts || !lux))
		return rad_fail(err, RAD_ERR_INVALID,
		                "illuminance: %zu points but %s is NULL", n,
		                pts ? "the output" : "the point array");
	rad_status st = check_points(pts, n, err);
	if (st != RAD_OK || n == 0)
		return st;
	query q = {scene, h, pts, lux, 0};
	if (scene->npolys > 0)
		q.floor = FLOOR_REL *
		          rad_luma(rad_cluster_at(h, RAD_TAG_CLUSTER)->B);
	if (par)
		rad_par_for(par, n, POINT_GRAIN, query_range, &q);
	else
		query_range(&q, 0, n, 0);
	return RAD_OK;
}

rad_status rad_solver_illuminance(const rad_solver *sv, const double *pts,
                                  size_t n, double *lux, rad_error *err)
{
	if (!sv)
		return rad_fail(err, RAD_ERR_INVALID, "illuminance: no solver");
	return rad_query_illuminance(sv->scene, &sv->h, sv->par, pts, n, lux,
	                             err);
}

/* ---------------------------------------------------------------- leaves */

static void leaves_below(const rad_hier *h, uint32_t id, rad_leaf_fn fn,
                         void *ud)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (e->child != RAD_NONE) {
		for (uint32_t k = 0; k < 4; k++)
			leaves_below(h, e->child + k, fn, ud);
		return;
	}
	rad_patch p;
	v3 v[4];
	double pos[4][3] = {{0}};
	rad_patch_from_floats(&p, e->p0, e->e1, e->e2, e->quad);
	int nv = rad_patch_vertices(&p, v);
	for (int k = 0; k < nv; k++) {
		pos[k][0] = v[k].x;
		pos[k][1] = v[k].y;
		pos[k][2] = v[k].z;
	}
	double B[3] = {e->B[0], e->B[1], e->B[2]};
	double I[3] = {e->I[0], e->I[1], e->I[2]};
	fn(ud, h->scene->polys[e->poly].node, pos, nv, B, I);
}

void rad_query_leaves(const rad_hier *h, rad_leaf_fn fn, void *ud)
{
	for (uint32_t p = 0; p < h->scene->npolys; p++)
		leaves_below(h, p, fn, ud);
}

void rad_solver_leaves(const rad_solver *sv, rad_leaf_fn fn, void *ud)
{
	if (!sv || !fn)
		return;
	rad_query_leaves(&sv->h, fn, ud);
}
