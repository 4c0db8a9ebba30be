/*
 * query.c -- reading a published solution: illuminance at arbitrary points
 * with an estimate of its error (rad_solver_query, rad_solution_query) and
 * the per-leaf results for export (rad_solver_leaves).  Both only read the
 * hierarchy, so they work the same for every solver and may run
 * concurrently with each other.
 *
 * DESIGN
 * Illuminance at a point x with unit normal n is
 *   direct:  every scene light, exactly at x (rad_light_point, one ray);
 *   surfaces: a hierarchical final gather of the radiosity B published in
 *            the hierarchy, walking down from the root cluster.
 * Every decision is a ratio against one relative tolerance tau
 * (rad_options.query_tol, set by the accuracy knob) times the point's
 * total, so results do not depend on the scene's scale, and tightening
 * tau refines every approximation:
 *   far field: a node is evaluated as a whole when it is far (size <
 *     THETA x distance) and an upper bound of what it can give is below
 *     tau x the running total (never below FLOOR_REL x the scene's mean
 *     exitance, so dark points do not descend to every leaf); otherwise
 *     the walk descends.  Bounds: cluster luma(B) A / (pi dmin^2);
 *     element luma(B) F, F the exact unoccluded point-to-polygon kernel
 *     (rad_ff_point_patch).  Children are visited nearest first so the
 *     running total grows early.
 *   evaluation: cluster: an emitter of its projected area towards x
 *     (rad_cluster_proj) at the box centre times the share of it x sees,
 *     on rays to a few of its polygons (cluster_seen); inner element: its four
 *     children's radiosity weighted by their own kernels (no extra rays)
 *     times its visible fraction; leaf: B times its visible kernel.
 *   visibility of a piece of source (a leaf, an element taken whole, an
 *     emitter): rays to its corners and centroid, and the pieces those
 *     leave unsure refined once the point's total is known (query_vis.c).
 *   partly covered elements (hier.h, Covered parts): never taken whole;
 *     a leaf's radiosity B / exposed is that of its exposed part, and the
 *     share of it x sees is read on the points that measured `exposed`
 *     (covered_ff), so that the two shares cancel.
 * Emitters come out exact: when the walk reaches the root element of a
 * polygon whose material emits, the uniform part E is evaluated on the
 * whole polygon, and only the reflected part B - E goes down its quadtree.
 * Leaves nearer to x than their size and large in its total are read at
 * their quarters by a nested gather once the total is known (near_add,
 * near_leaves).
 *
 * Error estimate (error_lux).  Each approximation adds what it may miss:
 * an unsure piece its binomial error c sqrt(p (1 - p) / k) (c its share,
 * p its open fraction, k rays), added linearly (along one shadow edge the
 * errors have one sign); and, added in quadrature as independent errors:
 * a cluster taken as a whole half its share (few rays, projected-area model),
 * an inner element taken whole the difference its children's weighting
 * made (the next level's correction is of that order), a leaf the
 * difference between its radiosity and its parent's times its visible
 * kernel (the solution's own resolution there: what a finer mesh would
 * change).  The solver's convergence estimate (the relative error of B)
 * times the reflected part is added linearly.  It estimates the error
 * against the exact solution of the radiosity model; the tests hold it
 * against closed forms and luxrad-reference.
 *
 * A point lying on a surface sees the side its normal points to: rays
 * leave x with the given normal (rad_vis_segment offsets them), and the
 * polygon under x gets F = 0 from the kernel.  Points are independent and
 * evaluated in parallel, each writing only its own outputs; the walk of
 * one point is sequential, so results are identical for any thread count.
 * The walk allocates nothing: C stack only (depth: cluster tree plus
 * quadtree levels; the heap of unsure pieces, VIS_HEAP of them, lives in
 * the point's gather state).
 */
#include <math.h>
#include <string.h>

#include "query_vis.h"

#define THETA 0.5      /* far enough: size < THETA x distance */
#define FLOOR_REL 1e-3 /* running total floor, x scene mean exitance */
#define POINT_GRAIN 4  /* points per parallel chunk */
#define NOISE_REL 1e-6 /* B - E below this share of E is float noise */

static double gather_point(gather *g, const rad_hier *h, const rad_vis *vis,
                           v3 x, v3 n, double tau, double floor, int nested);

static void add_error(gather *g, double e)
{
	g->err2 += e * e;
}

static int far_enough(const gather *g, double size, double dist, double bound)
{
	return size < THETA * dist && bound <= g->tau * query_running(g);
}

/* Photopic reflected radiosity B - E of an element's exposed part: the
 * point's rays to its covered part are blocked (hier.h, Covered parts). */
static double reflected(const rad_hier *h, uint32_t id, const float E[3])
{
	const rad_elem *e = rad_elem_at(h, id);
	float R[3] = {e->B[0] - E[0], e->B[1] - E[1], e->B[2] - E[2]};
	if (rad_elem_exposed_raw(h, id) == 0)
		return 0;
	return rad_luma(R) / rad_elem_exposed(h, id);
}

/*
 * Sum of R F over the four children of an element evaluated as a whole:
 * kernels only, no rays.  The element's mean R times its F would miss the
 * correlation of the two across it (a wall brighter on its side nearer
 * the point), a bias that adds up over many far elements.
 */
/* An element's region (hier.h, Regions), handed down the walk so that a
 * child's is one quarter step from its parent's. */
typedef struct region {
	float p0[3], e1[3], e2[3];
} region;

static region quarter(const region *r, int quad, int k)
{
	region q = *r;
	rad_region_quarter(q.p0, q.e1, q.e2, quad, k);
	return q;
}

static double children_rf(const gather *g, const rad_elem *e, int quad,
                          const region *re, const float E[3])
{
	double rf = 0;
	for (uint32_t k = 0; k < 4; k++) {
		region rc = quarter(re, quad, (int)k);
		rad_patch q;
		rad_patch_from_floats(&q, rc.p0, rc.e1, rc.e2, quad);
		rf += reflected(g->h, e->child + k, E) *
		      rad_ff_point_patch(g->x, g->n, &q);
	}
	return rf;
}

/*
 * The visible kernel of a leaf partly covered (hier.h, Covered parts).
 * Its r is the radiosity of its exposed part, the exposed fraction
 * measured on its first RAD_COVER_SAMPLES scattered points; the share x
 * sees is read on the same points, so that x seeing all of the exposed
 * part gets the leaf's B F whatever the points found: rays to covered
 * points meet the cover.  Five rays to its corners and centroid, set
 * against other points, do not cancel the exposed fraction: where a
 * cover's edge runs through a row of leaves' centroids, two corners of
 * four seen and the centroid not count a quarter of a leaf half
 * exposed.  With the descent into elements partly covered (gather_elem),
 * the floor beyond a plate's shadow (test_furnished,
 * test_plate_shadow_far_side) went from 1.48 % to 0.86 % on average
 * under hr.  Points behind x's tangent plane are not tried; none tried,
 * the leaf counts as seen as far as it is exposed.
 */
static double covered_ff(gather *g, uint32_t id, const rad_patch *p, double F,
                         double r)
{
	v3 y[RAD_COVER_SAMPLES];
	rad_vis_seg s[RAD_COVER_SAMPLES];
	unsigned char seen[RAD_COVER_SAMPLES];
	int n = rad_patch_scatter(p, RAD_COVER_SAMPLES, y), tried = 0, open = 0;
	for (int k = 0; k < n; k++)
		if (v3_dot(v3_sub(y[k], g->x), g->n) > 0)
			s[tried++] = (rad_vis_seg){g->x, g->n, y[k], p->n};
	rad_vis_segments(g->vis, s, tried, seen);
	for (int k = 0; k < tried; k++)
		open += seen[k];
	double v = tried ? (double)open / tried : rad_elem_exposed(g->h, id);
	add_error(g, query_piece_error(r * F, v, tried ? tried : 1));
	return F * v;
}

/*
 * Near leaves.  A leaf's radiosity is a mean over a piece that a point
 * near it sees unevenly: a wall near a floor corner is darker at the
 * corner than on average, and a point there read the mean (the Cornell
 * box's floor corner, 6.6 % high).  A leaf closer to x than its size whose
 * error (the difference from its parent's radiosity, gather_elem) matters
 * is kept here, the largest errors first; once the point's total is known
 * (near_leaves), those still over half of tau x total are read at their
 * quarters' centres by a gather of the solution there (one level: nested
 * gathers read leaves as they are), and x's kernel over the quarters
 * weights what each found.
 */
static void near_add(gather *g, const rad_patch *p, double irr, double c,
                     double e)
{
	int k = g->nnear;
	if (k == NEAR_MAX) {
		k = 0; /* replace the smallest error, if smaller */
		for (int i = 1; i < NEAR_MAX; i++)
			if (g->near[i].c < g->near[k].c)
				k = i;
		if (g->near[k].c >= c)
			return;
	} else {
		g->nnear++;
	}
	near *n = &g->near[k];
	n->s = *p;
	n->irr = irr;
	n->c = c;
	n->e = e;
}

static void near_leaves(gather *g)
{
	for (int i = 0; i < g->nnear; i++) {
		near *n = &g->near[i];
		if (n->c <= g->tau * g->total)
			continue;
		rad_patch q[4];
		query_patch_quarters(&n->s, q);
		/* An error in a quarter's irradiance weighs c / total in x's.
		 */
		double tau = fmin(0.25, 0.5 * g->tau * g->total / n->c);
		double wf = 0, f = 0;
		for (int k = 0; k < 4; k++) {
			double fk = rad_ff_point_patch(g->x, g->n, &q[k]);
			if (!(fk > 0))
				continue;
			gather in; /* on the stack: only one level deep */
			wf += fk * gather_point(&in, g->h, g->vis,
			                        rad_patch_centroid(&q[k]),
			                        q[k].n, tau, g->floor, 1);
			f += fk;
		}
		if (!(f > 0))
			continue;
		/* Only a darker view is taken: the quarters' gathers sit on
		 * the leaf and see what the leaf's own links averaged away,
		 * and where they read more than its mean they were seeing
		 * through gaps between two-sided faces (measured: a point
		 * 0.1 m from a wall of the Graz office, +17 % -> +86 %).  The
		 * case this is for, a leaf darker near a corner x is near,
		 * only darkens; under half the mean is not believed either. */
		double ratio = wf / (f * n->irr);
		if (!(ratio >= 0.5 && ratio <= 1))
			continue;
		double fix = n->c * (ratio - 1);
		g->total += fix;
		/* The leaf's error is now what reading it finer changed. */
		g->err2 = fmax(0, g->err2 - n->e * n->e) + fix * fix;
	}
}

/* The reflected radiosity B - E of element id and below (E: the uniform
 * emission already counted exactly on the whole polygon, or zero; rp: the
 * parent's B - E, or -1 for a root). */
static void gather_elem(gather *g, uint32_t id, const region *re,
                        const float E[3], double rp, ray_memo *memo)
{
	const rad_elem *e = rad_elem_at(g->h, id);
	double r = reflected(g->h, id, E);
	/* On a black emitter B - E is only the rounding of the pull. */
	if (r <= NOISE_REL * rad_luma(E))
		return;
	int quad = rad_elem_quad(g->h, id);
	int whole = rad_elem_exposed_raw(g->h, id) == RAD_EXPOSED_ALL;
	rad_patch p;
	rad_patch_from_floats(&p, re->p0, re->e1, re->e2, quad);
	/* The kernel is additive over a partition: F = 0 here means nothing
	 * below is seen either. */
	double F = rad_ff_point_patch(g->x, g->n, &p);
	if (F <= 0)
		return;
	if (rad_elem_is_leaf(e)) {
		double fv = whole ? query_visible_ff(g, &p, F, r, memo)
		                  : covered_ff(g, id, &p, F, r);
		g->total += r * fv;
		if (rp < 0)
			return;
		double el = fabs(r - rp) * fv, irr = rad_luma(e->I);
		add_error(g, el);
		if (!g->nested && el > 0 && irr > 0 &&
		    v3_len(v3_sub(rad_patch_centroid(&p), g->x)) <
		            query_patch_size(&p))
			near_add(g, &p, irr, r * fv, el);
		return;
	}
	double d = v3_len(v3_sub(rad_patch_centroid(&p), g->x));
	if (!whole || !far_enough(g, query_patch_size(&p), d, r * F)) {
		ray_memo kids;
		kids.n = 0;
		for (uint32_t k = 0; k < 4; k++) {
			region rc = quarter(re, quad, (int)k);
			gather_elem(g, e->child + k, &rc, E, r, &kids);
		}
		return;
	}
	/* The children's weighting rf / F is the piece's radiosity weight. */
	double rf = children_rf(g, e, quad, re, E);
	if (!(rf > 0))
		return;
	double v = query_visible_ff(g, &p, F, rf / F, memo) / F;
	g->total += rf * v;
	add_error(g, fabs(rf - r * F) * v);
}

static void gather_poly(gather *g, uint32_t pid)
{
	static const float none[3] = {0, 0, 0};
	const rad_scene *s = g->h->scene;
	const rad_poly *poly = &s->polys[pid];
	const rad_material *m = &s->mats[poly->mat];
	double e = rad_luma(m->emit);
	region root;
	rad_poly_frame(s, poly, root.p0, root.e1, root.e2);
	if (e <= 0) {
		gather_elem(g, pid, &root, none, -1, NULL);
		return;
	}
	rad_patch p;
	rad_patch_from_poly(&p, s, poly);
	double F = rad_ff_point_patch(g->x, g->n, &p);
	ray_memo memo;
	memo.n = 0;
	if (F > 0) {
		double c = e * query_visible_ff(g, &p, F, e, &memo);
		g->total += c;
		g->direct += c;
	}
	gather_elem(g, pid, &root, m->emit, -1, &memo);
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

/*
 * The share of a cluster that x sees, on rays to the centroids of up to
 * CLUSTER_RAYS of its polygons that face x (spread over its polygon
 * order), each leaving its polygon on the side it shows.  Not to the box
 * centre: that lies inside a closed object (a book, a board, a cabinet),
 * whose own faces then block the ray, so a far object taken whole was
 * dropped (test_blender's SketchUp-like office, with its shelf of 48
 * books, at --accuracy 0.01 against luxrad-reference: 22 points on its
 * ceiling and upper walls -3.10 % on average, -2.68 % since).  When none
 * of the polygons looked at faces x, they are used seen from their
 * backs.
 */
#define CLUSTER_RAYS 4
#define CLUSTER_LOOKS 16
static double cluster_seen(const gather *g, const rad_cluster *c)
{
	const rad_scene *sc = g->h->scene;
	uint32_t look = c->count < CLUSTER_LOOKS ? c->count : CLUSTER_LOOKS;
	v3 y[CLUSTER_RAYS], ny[CLUSTER_RAYS];
	int n = 0;
	for (int pass = 0; pass < 2 && n == 0; pass++) {
		for (uint32_t k = 0; k < look && n < CLUSTER_RAYS; k++) {
			const rad_poly *p =
			        &sc->polys[rad_cluster_pick(g->h, c, k, look)];
			rad_patch pa;
			rad_patch_from_poly(&pa, sc, p);
			v3 yc = rad_patch_centroid(&pa);
			double f = v3_dot(pa.n, v3_sub(g->x, yc));
			if (pass == 0 && !(f > 0))
				continue;
			y[n] = yc;
			ny[n++] = f > 0 ? pa.n : v3_scale(pa.n, -1);
		}
	}
	rad_vis_seg s[CLUSTER_RAYS];
	unsigned char open[CLUSTER_RAYS];
	for (int k = 0; k < n; k++)
		s[k] = (rad_vis_seg){g->x, g->n, y[k], ny[k]};
	rad_vis_segments(g->vis, s, n, open);
	int seen = 0;
	for (int k = 0; k < n; k++)
		seen += open[k];
	return n ? (double)seen / n : 0;
}

/* Cluster: its projected area towards x radiating B from its centre,
 * times the share of it x sees (cluster_seen); half its share is the
 * error estimate. */
static void eval_cluster(gather *g, const rad_cluster *c, double b, v3 ctr,
                         double d)
{
	double cosx = v3_dot(g->n, v3_sub(ctr, g->x)) / d;
	if (cosx <= 0)
		return;
	v3 u = v3_scale(v3_sub(g->x, ctr), 1 / d);
	double p = rad_cluster_proj(g->h, c, u.x, u.y, u.z);
	double share =
	        b * p *
	        rad_cluster_emit(g->h, c, c->B, c->nB, p, u.x, u.y, u.z) *
	        cosx / (M_PI * d * d);
	if (!(share > 0))
		return;
	add_error(g, share / 2);
	g->total += share * cluster_seen(g, c);
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
	if (rad_cluster_is_leaf(c)) {
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
	double *lux, *error_lux;
	double floor, tau, solve_error;
} query;

/* Photopic illuminance at x (normal n) into a gather set up here:
 * lights, then the walk, its refinement and the near leaves. */
static double gather_point(gather *g, const rad_hier *h, const rad_vis *vis,
                           v3 x, v3 n, double tau, double floor, int nested)
{
	const rad_scene *s = h->scene;
	g->h = h;
	g->vis = vis;
	g->x = x;
	g->n = n;
	g->tau = tau;
	g->floor = floor;
	g->nested = nested;
	g->total = g->err2 = g->errvis = 0;
	g->nheap = g->nnear = 0;
	for (uint32_t l = 0; l < s->nlights; l++) {
		const rad_light *L = &s->lights[l];
		g->total += rad_light_point(vis, L, x, n, NULL) *
		            rad_luma3(L->intensity);
	}
	g->direct = g->total;
	if (s->npolys > 0)
		gather_cluster(g, 0 | RAD_TAG_CLUSTER);
	query_refine_pieces(g);
	near_leaves(g);
	return g->total;
}

static double point_lux(const query *q, v3 x, v3 n, double *error)
{
	gather g; /* not zeroed as a whole: the heap is large */
	gather_point(&g, q->h, q->scene->vis, x, n, q->tau, q->floor, 0);
	*error = sqrt(g.err2) + g.errvis +
	         q->solve_error * fmax(g.total - g.direct, 0);
	return g.total;
}

static void query_range(void *ud, size_t begin, size_t end, int thread)
{
	const query *q = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++) {
		const double *p = q->pts + 6 * i;
		double e;
		q->lux[i] = point_lux(q, v3_d(p), v3_norm(v3_d(p + 3)), &e);
		if (q->error_lux)
			q->error_lux[i] = e;
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
                                 rad_par *par, const rad_query_args *a,
                                 rad_error *err)
{
	size_t n = a->n;
	if (n > 0 && (!a->pts || !a->lux))
		return rad_fail(err, RAD_ERR_INVALID,
		                "illuminance: %zu points but %s is NULL", n,
		                a->pts ? "the output" : "the point array");
	if (!(a->tol > 0 && a->tol < 1))
		return rad_fail(err, RAD_ERR_INVALID,
		                "illuminance: tolerance must be in (0, 1) "
		                "(got %g)",
		                a->tol);
	if (!(a->solve_error >= 0) || !isfinite(a->solve_error))
		return rad_fail(err, RAD_ERR_INVALID,
		                "illuminance: solution error must be a finite "
		                "number >= 0 (got %g)",
		                a->solve_error);
	rad_status st = check_points(a->pts, n, err);
	if (st != RAD_OK || n == 0)
		return st;
	query q = {scene,        h, a->pts, a->lux,
	           a->error_lux, 0, a->tol, a->solve_error};
	if (scene->npolys > 0)
		q.floor = FLOOR_REL *
		          rad_luma(rad_cluster_at(h, RAD_TAG_CLUSTER)->B);
	if (par)
		rad_par_for(par, n, POINT_GRAIN, query_range, &q);
	else
		query_range(&q, 0, n, 0);
	return RAD_OK;
}

rad_status rad_solver_query(const rad_solver *sv, const double *pts, size_t n,
                            double tol, double *lux, double *error_lux,
                            rad_error *err)
{
	if (!sv)
		return rad_fail(err, RAD_ERR_INVALID, "illuminance: no solver");
	if (!sv->impl) /* a restart failed (solver.c): no hierarchy */
		return rad_fail(err, RAD_ERR_STATE,
		                "illuminance: the solver failed and has no "
		                "solution");
	double se = sv->stats.error_estimate;
	rad_query_args a = {pts,
	                    n,
	                    tol > 0 ? tol : sv->opt.query_tol,
	                    isfinite(se) && se > 0 ? se : 0,
	                    lux,
	                    error_lux};
	return rad_query_illuminance(sv->scene, &sv->h, sv->par, &a, err);
}

rad_status rad_solver_illuminance(const rad_solver *sv, const double *pts,
                                  size_t n, double *lux, rad_error *err)
{
	return rad_solver_query(sv, pts, n, 0, lux, NULL, err);
}

/* ---------------------------------------------------------------- leaves */

static void leaves_below(const rad_hier *h, uint32_t id, rad_leaf_fn fn,
                         void *ud)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (!rad_elem_is_leaf(e)) {
		for (uint32_t k = 0; k < 4; k++)
			leaves_below(h, e->child + k, fn, ud);
		return;
	}
	rad_patch p;
	v3 v[4];
	double pos[4][3] = {{0}};
	rad_elem_patch(h, id, &p);
	int nv = rad_patch_vertices(&p, v);
	for (int k = 0; k < nv; k++) {
		pos[k][0] = v[k].x;
		pos[k][1] = v[k].y;
		pos[k][2] = v[k].z;
	}
	double B[3] = {e->B[0], e->B[1], e->B[2]};
	double I[3] = {e->I[0], e->I[1], e->I[2]};
	fn(ud, rad_poly_node(h->scene, rad_elem_poly(h, id)), pos, nv, B, I);
}

void rad_query_leaves(const rad_hier *h, rad_leaf_fn fn, void *ud)
{
	for (uint32_t p = 0; p < h->scene->npolys; p++)
		leaves_below(h, p, fn, ud);
}

void rad_solver_leaves(const rad_solver *sv, rad_leaf_fn fn, void *ud)
{
	if (!sv || !fn || !sv->impl)
		return;
	rad_query_leaves(&sv->h, fn, ud);
}
