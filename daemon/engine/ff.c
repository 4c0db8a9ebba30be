/*
 * ff.c -- form factors between patches and direct light from punctual and
 * directional sources (see ff.h for the conventions).
 *
 * Every link of every solver gets its value here, so accuracy is decided
 * in this file: the point-to-polygon kernel is exact (Lambert's contour
 * integral), which removes the 1/d^2 singularity that ruins point-sampled
 * form factors between adjacent patches; only the receiver integral and
 * the visibility are sampled, on fixed patterns so that the same geometry
 * always gives the same number.
 *
 * DESIGN
 * - Lambert's formula.  For a differential area at x with unit normal n_x
 *   and a polygon with vertices v_k (counter-clockwise seen from its
 *   front), with r_k = v_k - x:
 *       F = 1/(2 pi) sum_k beta_k (n_x . g_k)
 *   where beta_k is the angle between r_k and r_k+1 and g_k the unit
 *   normal of the plane through x, v_k and v_k+1, oriented as
 *   r_k+1 x r_k (so that a polygon facing x gives F > 0).  It only holds
 *   for the part of the polygon above x's tangent plane, so the polygon
 *   is clipped to that half-space first (a triangle or parallelogram
 *   clipped by a plane has at most 5 vertices).  beta_k comes from
 *   atan2(|r_k x r_k+1|, r_k . r_k+1), accurate at every angle, where
 *   acos of a dot product loses all digits near 0 and pi.
 * - Sample patterns.  1 point is the centroid; 4 points are an
 *   equal-weight rule with one point in each quarter of the patch (the
 *   midpoint subdivision of a triangle, 2 x 2 cells of a parallelogram)
 *   that integrates quadratics exactly (cubics per direction for the
 *   parallelogram's Gauss points); 16 points are that rule in each quarter.
 *   Cell centroids (the midpoint rule) would be simpler, but measured on
 *   parallel unit squares they are 0.96 % high with 16 points where this
 *   rule is 0.04 % low, at the same cost.  A property kept on purpose:
 *   the 16 points of a patch are the 4 points of its four children.
 *   Points are numbered so that any prefix is spread out (the base-4
 *   digits of the index, coarsest first, pick the cell); other counts
 *   take the first n points of the next pattern, with equal weights: a
 *   slight bias, traded for determinism and no tables.
 * - Visibility from a receiver point is sampled only towards source
 *   points in front of its tangent plane: the rest of the source does not
 *   contribute, and a ray towards it would run under the receiver.
 */
#include "ff.h"
#include "vis.h"

/* A clipped vertex within this fraction of its distance from x of the
 * tangent plane counts as on it (no near-duplicate vertex is made). */
#define CLIP_TOL_REL 1e-12

/* ---------------------------------------------------------------- patches */

void rad_patch_from_floats(rad_patch *p, const float p0[3], const float e1[3],
                           const float e2[3], int quad)
{
	p->p0 = v3_f(p0);
	p->e1 = v3_f(e1);
	p->e2 = v3_f(e2);
	v3 c = v3_cross(p->e1, p->e2);
	double len = v3_len(c);
	p->n = v3_norm(c);
	p->area = quad ? len : 0.5 * len;
	p->quad = quad;
}

void rad_patch_from_poly(rad_patch *p, const rad_scene *s, const rad_poly *poly)
{
	float p0[3], e1[3], e2[3];
	rad_poly_frame(s, poly, p0, e1, e2);
	rad_patch_from_floats(p, p0, e1, e2, poly->quad);
}

v3 rad_patch_centroid(const rad_patch *p)
{
	double w = p->quad ? 0.5 : 1.0 / 3.0;
	return v3_madd(v3_madd(p->p0, p->e1, w), p->e2, w);
}

int rad_patch_vertices(const rad_patch *p, v3 out[4])
{
	out[0] = p->p0;
	out[1] = v3_add(p->p0, p->e1);
	if (!p->quad) {
		out[2] = v3_add(p->p0, p->e2);
		return 3;
	}
	out[2] = v3_add(out[1], p->e2);
	out[3] = v3_add(p->p0, p->e2);
	return 4;
}

/* --------------------------------------------------------- sample patterns */

typedef struct st2 {
	double s, t;
} st2;

static st2 st_mid(st2 a, st2 b)
{
	st2 m = {0.5 * (a.s + b.s), 0.5 * (a.t + b.t)};
	return m;
}

/*
 * Point k of the 4^levels-point pattern of a triangle, in (s, t).  The
 * leading digits of k descend the midpoint subdivision (children: the
 * corner triangles at A, B, C, then the middle one); the last picks a
 * point of the 4-point rule in the cell reached.  That rule is the
 * centroid plus three points at barycentric (1 - 2b, b, b) and
 * permutations, b = (1 - 1/sqrt 3) / 3: with equal weights it integrates
 * quadratics exactly, and each point lies in its own child cell.  The
 * corner points come first: the first three alone are centred.
 */
static st2 tri_point(int k, int levels)
{
	st2 v[3] = {{0, 0}, {1, 0}, {0, 1}};
	for (int l = 1; l < levels; l++, k >>= 2) {
		st2 ab = st_mid(v[0], v[1]), bc = st_mid(v[1], v[2]);
		st2 ca = st_mid(v[2], v[0]);
		st2 child[4][3] = {{v[0], ab, ca},
		                   {ab, v[1], bc},
		                   {ca, bc, v[2]},
		                   {bc, ca, ab}};
		for (int i = 0; i < 3; i++)
			v[i] = child[k & 3][i];
	}
	double w[3] = {1.0 / 3, 1.0 / 3, 1.0 / 3};
	if (levels > 0 && (k & 3) < 3) {
		const double b = (1.0 - 1.0 / sqrt(3.0)) / 3.0;
		w[0] = w[1] = w[2] = b;
		w[k & 3] = 1.0 - 2.0 * b;
	}
	st2 p = {w[0] * v[0].s + w[1] * v[1].s + w[2] * v[2].s,
	         w[0] * v[0].t + w[1] * v[1].t + w[2] * v[2].t};
	return p;
}

/*
 * Same for a parallelogram: leading digits pick quadrants, the last a
 * point of the 2 x 2 Gauss rule of the cell reached (exact for cubics in
 * each direction, equal weights, one point per quadrant).  The first two
 * points are diagonal, so a prefix of 2 is centred.
 */
static st2 quad_point(int k, int levels)
{
	static const int di[4] = {0, 1, 1, 0}, dj[4] = {0, 1, 0, 1};
	st2 o = {0, 0};
	double size = 1.0;
	for (int l = 1; l < levels; l++, k >>= 2) {
		size *= 0.5;
		o.s += di[k & 3] * size;
		o.t += dj[k & 3] * size;
	}
	if (levels == 0) {
		st2 c = {0.5, 0.5};
		return c;
	}
	const double g = 0.5 / sqrt(3.0); /* Gauss nodes at 1/2 -+ g */
	st2 p = {o.s + size * (0.5 + (di[k & 3] ? g : -g)),
	         o.t + size * (0.5 + (dj[k & 3] ? g : -g))};
	return p;
}

int rad_patch_samples(const rad_patch *p, int n, v3 *out)
{
	if (n < 1)
		n = 1;
	if (n > RAD_FF_MAX_SAMPLES)
		n = RAD_FF_MAX_SAMPLES;
	int levels = n == 1 ? 0 : n <= 4 ? 1 : 2;
	for (int k = 0; k < n; k++) {
		st2 c = p->quad ? quad_point(k, levels) : tri_point(k, levels);
		out[k] = v3_madd(v3_madd(p->p0, p->e1, c.s), p->e2, c.t);
	}
	return n;
}

/* ------------------------------------------------------ point to polygon */

/*
 * The part of s in front of x's tangent plane, as vectors from x, in the
 * polygon's order.  Returns the vertex count, or 0 when nothing lies
 * strictly in front.
 */
static int clip_front(v3 x, v3 nx, const rad_patch *s, v3 out[5])
{
	v3 v[4], r[4];
	double h[4];
	int n = rad_patch_vertices(s, v), front = 0;
	for (int i = 0; i < n; i++) {
		r[i] = v3_sub(v[i], x);
		h[i] = v3_dot(r[i], nx);
		if (fabs(h[i]) <= CLIP_TOL_REL * v3_len(r[i]))
			h[i] = 0;
		front |= h[i] > 0;
	}
	if (!front)
		return 0;
	int m = 0;
	for (int i = 0; i < n; i++) {
		int j = (i + 1) % n;
		if (h[i] >= 0)
			out[m++] = r[i];
		if ((h[i] > 0 && h[j] < 0) || (h[i] < 0 && h[j] > 0))
			out[m++] = v3_madd(r[i], v3_sub(r[j], r[i]),
			                   h[i] / (h[i] - h[j]));
	}
	return m;
}

/*
 * atan2(y, x) for y >= 0, the angle an edge subtends (0 .. pi).  The point
 * query spends most of its arithmetic here: libm's atan2 took 16 % of the
 * full hall's query time.  Reduced to |u| <= tan(pi/8), atan(u) = u q(u^2)
 * with q the degree-7 interpolant of atan(sqrt(s))/sqrt(s) at the
 * Chebyshev nodes of [0, tan(pi/8)^2]: at most 2.8e-13 rad off.
 */
static double edge_angle(double y, double x)
{
	static const double q[8] = {
	        0.99999999999924449,  -0.33333333276916066,
	        0.19999993053110954,  -0.14285386540040962,
	        0.11103456693779999,  -0.089925511211191647,
	        0.069741902318458546, -0.037654982631026769,
	};
	const double tan_pi_8 = 0.41421356237309503;
	double ax = fabs(x), t, base = 0, a, p = 0;
	int steep = y > ax;
	if (!(y > 0))
		return x < 0 ? M_PI : 0;
	t = steep ? ax / y : y / ax;
	if (t > tan_pi_8) {
		t = (t - 1) / (t + 1);
		base = M_PI / 4;
	}
	for (int k = 7; k >= 0; k--)
		p = p * (t * t) + q[k];
	a = base + t * p;
	if (steep)
		a = M_PI / 2 - a;
	return x < 0 ? M_PI - a : a;
}

/* Lambert's contour sum over vertices r (relative to x); see DESIGN. */
static double contour(const v3 *r, int n, v3 nx)
{
	double sum = 0;
	for (int i = 0; i < n; i++) {
		v3 a = r[i], b = r[(i + 1) % n];
		v3 g = v3_cross(b, a);
		double len = v3_len(g);
		/* Collinear with x: the edge subtends no solid angle. */
		if (!(len > 0))
			continue;
		sum += edge_angle(len, v3_dot(a, b)) * v3_dot(g, nx) / len;
	}
	return sum / (2.0 * M_PI);
}

/* Point kernel; also returns the clipped polygon for visibility. */
static double point_ff(v3 x, v3 nx, const rad_patch *s, v3 clip[5], int *m)
{
	*m = 0;
	/* Only the front of the source emits. */
	if (!(v3_dot(v3_sub(x, s->p0), s->n) > 0))
		return 0;
	*m = clip_front(x, nx, s, clip);
	if (!*m)
		return 0;
	double f = contour(clip, *m, nx);
	/* Rounding can push F a hair outside [0, 1]; NaN is impossible for
	 * a valid patch but would fail the comparison and give 0. */
	return f > 0 ? fmin(f, 1.0) : 0.0;
}

double rad_ff_point_patch(v3 x, v3 nx, const rad_patch *s)
{
	v3 clip[5];
	int m;
	return point_ff(x, nx, s, clip, &m);
}

/* -------------------------------------------------------- patch to patch */

/*
 * Cosine of the best-placed vertex of `other` seen from point c with
 * normal n: positive as soon as any part of `other` is in front of c's
 * plane.
 */
static double best_vertex_cos(v3 c, v3 n, const rad_patch *other)
{
	v3 v[4];
	int nv = rad_patch_vertices(other, v);
	double best = -1;
	for (int i = 0; i < nv; i++) {
		v3 d = v3_sub(v[i], c);
		double len = v3_len(d);
		if (len > 0)
			best = fmax(best, v3_dot(d, n) / len);
	}
	return best;
}

/*
 * F(r <- s) of a near pair from the smaller patch's centroid, with the
 * exact point-to-polygon form factor to the larger one (by reciprocity
 * when the source is the smaller).  The centroids' kernel misses a thin
 * patch that touches a large one at right angles: a luminaire's 1 cm side
 * under a ceiling has its centre 5 mm below the ceiling's plane, cosine
 * 0.01 from a ceiling element's centre, while half of its light lands
 * within centimetres of it.  Estimated so, such pairs were called
 * negligible and never refined (the lamp of the Blender export of the
 * Cornell box: 2 % of its light lost).
 */
static double near_estimate(const rad_patch *r, const rad_patch *s, v3 cr,
                            v3 cs)
{
	if (s->area <= r->area)
		return s->area / r->area * rad_ff_point_patch(cs, s->n, r);
	return rad_ff_point_patch(cr, r->n, s);
}

/*
 * A_s cos_r cos_s / (pi d^2 + A_s): the disc-like approximation, which
 * tends to the right limit (<= 1) as patches come close.  Pairs whose
 * centroids do not face each other but whose polygons partly do (corners,
 * grazing) get the cosines of their best-placed vertices instead, so an
 * oracle never calls a partly facing pair negligible.  Near pairs (closer
 * than the larger one's size) take near_estimate where it is larger.
 */
double rad_ff_estimate(const rad_patch *r, const rad_patch *s)
{
	v3 cr = rad_patch_centroid(r), cs = rad_patch_centroid(s);
	v3 d = v3_sub(cs, cr);
	double d2 = v3_dot(d, d), len = sqrt(d2);
	double cos_r = len > 0 ? v3_dot(d, r->n) / len : 0;
	double cos_s = len > 0 ? -v3_dot(d, s->n) / len : 0;
	if (!(cos_r > 0 && cos_s > 0)) {
		cos_r = best_vertex_cos(cr, r->n, s);
		cos_s = best_vertex_cos(cs, s->n, r);
		if (!(cos_r > 0 && cos_s > 0))
			return 0;
	}
	double f = s->area * cos_r * cos_s / (M_PI * d2 + s->area);
	if (d2 < fmax(r->area, s->area))
		f = fmax(f, near_estimate(r, s, cr, cs));
	return fmin(f, 1.0);
}

double rad_ff_unoccluded(const rad_patch *r, const rad_patch *s, int nrcv)
{
	v3 xs[RAD_FF_MAX_SAMPLES];
	int n = rad_patch_samples(r, nrcv, xs);
	double sum = 0;
	for (int k = 0; k < n; k++)
		sum += rad_ff_point_patch(xs[k], r->n, s);
	return sum / n;
}

/*
 * Visible share of the kernel from each receiver point x to the source
 * points in front of x's tangent plane: each ray weighted by the point
 * kernel cos cos / r^2 at its source point.  Not the plain share of rays
 * that pass: occluders tend to hide the far, grazing part of a source,
 * which carries little of the kernel, and the plain share counted it as
 * much as the near part (test_ff: a floor hidden beyond a plate at half
 * height, seen from 1 m above, read -47 % with 16 rays, +0.3 % weighted).
 * When no source point is in front, one ray to the clipped polygon's
 * vertex mean (in front, on the source) stands for them.
 * The rays of every receiver point are traced together (rad_vis_segments:
 * packets of up to 16 where one point's were 4 at the defaults).
 */
typedef struct vis_rays {
	rad_vis_seg seg[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
	double w[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
	unsigned char open[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
} vis_rays;

/* Receiver point x's rays into vr from index n; returns the new count.
 * *tried counts the points in front of x, as rays (rays to a point of
 * zero kernel are counted and not traced). */
static int add_rays(vis_rays *vr, int n, v3 x, v3 nx, const rad_patch *s,
                    const v3 *ys, int ny, uint64_t *tried)
{
	for (int j = 0; j < ny; j++) {
		v3 d = v3_sub(ys[j], x);
		double cx = v3_dot(d, nx);
		if (!(cx > 0))
			continue;
		double d2 = v3_dot(d, d);
		double w = cx * fmax(-v3_dot(d, s->n), 0) / (d2 * d2);
		(*tried)++;
		if (!(w > 0))
			continue;
		vr->seg[n] = (rad_vis_seg){x, nx, ys[j], s->n};
		vr->w[n++] = w;
	}
	return n;
}

/*
 * Every ray blocked while the unoccluded kernel is positive is weak
 * evidence: the few sample points can all fall on covered spots, and the
 * regular patterns fall on them together when the scene is regular too
 * (measured: the hall of 16 panels mounted 1 mm below its ceiling on a
 * 4 x 4 grid; the 16-point rule of the ceiling, like the 4-point rule of
 * its quarters, puts every point above a panel, so hr dropped the links
 * of the whole ceiling as hidden; its row sum fell from 0.97 to 0.19 and
 * the work plane came out 19 % dark with --rcv-samples 16).  Such a pair
 * is sampled again on scattered points (scatter_point), which no grid of
 * the scene can line up with, before zero is believed.  Truly hidden
 * pairs pay those rays once.
 */
#define RECHECK_POINTS RAD_FF_MAX_SAMPLES

/*
 * Point k of a scattered set over the patch: the additive recurrence
 * with the plastic number's steps (Roberts' R2 sequence), whose points
 * keep a low discrepancy and whose irrational steps match no regular
 * layout.  A triangle takes the point folded into its half of the unit
 * square.
 */
static st2 scatter_point(int k, int quad)
{
	const double a1 = 0.7548776662466927, a2 = 0.5698402909980532;
	double s = 0.5 + a1 * (k + 1), t = 0.5 + a2 * (k + 1);
	st2 p = {s - floor(s), t - floor(t)};
	if (!quad && p.s + p.t > 1) {
		p.s = 1 - p.s;
		p.t = 1 - p.t;
	}
	return p;
}

int rad_patch_scatter(const rad_patch *p, int n, v3 *out)
{
	for (int k = 0; k < n; k++) {
		st2 c = scatter_point(k, p->quad);
		out[k] = v3_madd(v3_madd(p->p0, p->e1, c.s), p->e2, c.t);
	}
	return n;
}

/* See ff.h.  Without it, one point of four under a ceiling panel stands
 * for a quarter of the receiver, however small the panel: in the hospital
 * room a corridor ceiling element's link to the floor beside a panel lost
 * 40 % of its form factor (0.036 where Monte Carlo gives 0.061). */
double rad_ff_rcv_mean(const rad_vis *vis, v3 nr, const v3 *xs, const double *f,
                       int n, double rcover, uint64_t *rays, double *spread)
{
	double sum = 0, lo = INFINITY, hi = 0;
	int any = 0, used = 0, nt = 0;
	v3 test[RAD_FF_MAX_SAMPLES];
	unsigned char covered[RAD_FF_MAX_SAMPLES];
	for (int k = 0; k < n; k++)
		any |= f[k] > 0;
	int check = any && rcover > 0 && vis;
	for (int k = 0; check && k < n; k++)
		if (!(f[k] > 0))
			test[nt++] = xs[k];
	if (nt > 0)
		rad_vis_covered_n(vis, nr, rcover, test, nt, covered);
	if (rays)
		*rays += (uint64_t)nt;
	for (int k = 0, t = 0; k < n; k++) {
		if (check && !(f[k] > 0) && covered[t++])
			continue;
		sum += f[k];
		lo = fmin(lo, f[k]);
		hi = fmax(hi, f[k]);
		used++;
	}
	if (spread)
		*spread = used ? hi - lo : 0;
	return used ? sum / used : 0;
}

/* The receiver integral over points xs, visibility towards ys
 * (rad_ff_rcv_mean); sets *front when any point has the source in front. */
static double ff_sampled(const rad_vis *vis, const rad_patch *r,
                         const rad_patch *s, const v3 *xs, int nx, const v3 *ys,
                         int ny, double rcover, uint64_t *rays, double *spread,
                         int *front)
{
	v3 clip[5];
	double f[RAD_FF_MAX_SAMPLES];
	int end[RAD_FF_MAX_SAMPLES], n = 0;
	uint64_t tried = 0;
	vis_rays vr;
	*front = 0;
	for (int k = 0; k < nx; k++) {
		int m;
		f[k] = point_ff(xs[k], r->n, s, clip, &m);
		*front |= f[k] > 0;
		if (f[k] > 0 && vis)
			n = add_rays(&vr, n, xs[k], r->n, s, ys, ny, &tried);
		end[k] = n;
	}
	if (n > 0)
		rad_vis_segments(vis, vr.seg, n, vr.open);
	for (int k = 0, i = 0; k < nx; k++) {
		if (!(f[k] > 0) || !vis)
			continue;
		double all = 0, seen = 0;
		for (; i < end[k]; i++) {
			all += vr.w[i];
			if (vr.open[i])
				seen += vr.w[i];
		}
		if (all > 0) {
			f[k] *= seen / all;
			continue;
		}
		/* No source point in front: the clipped polygon's vertex
		 * mean, asked of point_ff again (rare). */
		int m;
		point_ff(xs[k], r->n, s, clip, &m);
		v3 c = v3_make(0, 0, 0);
		for (int j = 0; j < m; j++)
			c = v3_add(c, clip[j]);
		tried++;
		f[k] *= rad_vis_segment(vis, xs[k], &r->n,
		                        v3_madd(xs[k], c, 1.0 / m), &s->n);
	}
	if (rays)
		*rays += tried;
	return rad_ff_rcv_mean(vis, r->n, xs, f, nx, rcover, rays, spread);
}

/* Keep the points of ys on s that nothing covers closer than cover. */
static int uncovered(const rad_vis *vis, const rad_patch *s, double cover,
                     v3 *ys, int ny, uint64_t *rays)
{
	if (!(cover > 0) || !vis)
		return ny;
	return rad_vis_keep_uncovered(vis, s->n, cover, ys, NULL, ny, rays);
}

double rad_ff_patch_spread(const rad_vis *vis, const rad_patch *r,
                           const rad_patch *s, int nrcv, int nvis, double cover,
                           double rcover, uint64_t *rays, double *spread)
{
	v3 xs[RAD_FF_MAX_SAMPLES], ys[RAD_FF_MAX_SAMPLES];
	int nx = rad_patch_samples(r, nrcv, xs);
	int ny = rad_patch_samples(s, nvis, ys);
	int n = ny, front;
	ny = uncovered(vis, s, cover, ys, ny, rays);
	if (spread)
		*spread = 0;
	if (ny == 0)
		return 0;
	double f = ff_sampled(vis, r, s, xs, nx, ys, ny, rcover, rays, spread,
	                      &front);
	if (f > 0 || !vis || !front)
		return f;
	nx = rad_patch_scatter(r, RECHECK_POINTS, xs);
	ny = uncovered(vis, s, cover, ys, rad_patch_scatter(s, n, ys), rays);
	if (ny == 0)
		return 0;
	return ff_sampled(vis, r, s, xs, nx, ys, ny, rcover, rays, spread,
	                  &front);
}

double rad_ff_patch(const rad_vis *vis, const rad_patch *r, const rad_patch *s,
                    int nrcv, int nvis, uint64_t *rays)
{
	return rad_ff_patch_spread(vis, r, s, nrcv, nvis, 0, 0, rays, NULL);
}

/* ------------------------------------------------------------------ lights */

/*
 * glTF's recommended range window: clamp(1 - (d/range)^4, 0, 1), applied
 * on top of the inverse square law (KHR_lights_punctual, "Range
 * Property").  range 0 means infinite.
 */
static double range_window(double range, double dist)
{
	if (range <= 0)
		return 1.0;
	double q2 = (dist / range) * (dist / range);
	return fmax(0.0, 1.0 - q2 * q2);
}

/*
 * glTF's spot cone: t = clamp((cos - cos_outer) / (cos_inner -
 * cos_outer), 0, 1), factor t^2.  The reference code floors the
 * denominator at 0.001 (a GPU guard that would widen cones narrower than
 * ~2.6 degrees); we use it as given and fall back to a hard edge only
 * when the two cosines are equal in double.
 */
static double spot_factor(const rad_light *L, v3 to_x)
{
	double c = v3_dot(to_x, v3_d(L->dir));
	double span = L->cos_inner - L->cos_outer;
	if (!(span > 0))
		return c >= L->cos_inner ? 1.0 : 0.0;
	double t = (c - L->cos_outer) / span;
	t = t < 0 ? 0 : t > 1 ? 1 : t;
	return t * t;
}

/* Unoccluded irradiance per unit intensity at x (normal nx) from a
 * positional light L placed at pos. */
static double light_from(const rad_light *L, v3 pos, v3 x, v3 nx)
{
	v3 d = v3_sub(pos, x);
	double d2 = v3_dot(d, d);
	if (!(d2 > 0))
		return 0;
	double dist = sqrt(d2), cos_r = v3_dot(d, nx) / dist;
	if (!(cos_r > 0))
		return 0;
	double e = cos_r / d2 * range_window(L->range, dist);
	if (L->kind == RAD_LIGHT_SPOT)
		e *= spot_factor(L, v3_scale(d, -1.0 / dist));
	else if (L->gonio)
		e *= rad_gonio_factor(L->gonio, v3_scale(d, -1.0 / dist));
	return e;
}

/*
 * A luminous opening as a grid of cells, each a point source with its
 * share of the intensity.  A cell of size s seen from distance r gives an
 * error of about (s / r)^2 / 6 against the exact area integral (measured
 * on a Lambertian 1.2 x 0.2 m opening: 0.7 % at s / r = 0.2), so cells
 * are OPENING_CELL_REL of the distance to the opening's nearest part, at
 * most OPENING_CELLS a side: a receiver far away costs one cell.
 * Visibility is tested from the centre (rad_light_point).
 */
#define OPENING_CELL_REL 0.17
#define OPENING_CELLS 16

static int opening_cells(double size, double dist)
{
	if (!(dist > 0))
		return size > 0 ? OPENING_CELLS : 1;
	double k = ceil(size / (OPENING_CELL_REL * dist));
	return !(k > 1) ? 1 : k < OPENING_CELLS ? (int)k : OPENING_CELLS;
}

static double light_geometry(const rad_light *L, v3 x, v3 nx)
{
	if (L->kind == RAD_LIGHT_DIRECTIONAL)
		return fmax(0.0, -v3_dot(v3_d(L->dir), nx));
	if (!rad_light_has_opening(L))
		return light_from(L, v3_d(L->pos), x, nx);
	/* Cells are sized by the distance to the opening's nearest part. */
	double half = 0.5 * hypot(L->opening[0], L->opening[1]);
	double near = v3_len(v3_sub(v3_d(L->pos), x)) - half;
	int k0 = opening_cells(L->opening[0], near);
	int k1 = opening_cells(L->opening[1], near);
	double sum = 0;
	int n = 0;
	for (int i = 0; i < k0; i++)
		for (int j = 0; j < k1; j++) {
			double u = (i + 0.5) / k0 - 0.5,
			       v = (j + 0.5) / k1 - 0.5;
			if (L->opening_round && u * u + v * v > 0.25)
				continue;
			sum += light_from(L, rad_light_opening_point(L, u, v),
			                  x, nx);
			n++;
		}
	return n ? sum / n : light_from(L, v3_d(L->pos), x, nx);
}

double rad_light_point(const rad_vis *vis, const rad_light *L, v3 x, v3 nx,
                       uint64_t *rays)
{
	double e = light_geometry(L, x, nx);
	if (!(e > 0) || !vis)
		return e;
	if (rays)
		(*rays)++;
	int seen = L->kind == RAD_LIGHT_DIRECTIONAL
	                   ? rad_vis_ray_free(vis, x, &nx,
	                                      v3_scale(v3_d(L->dir), -1.0))
	                   : rad_vis_segment(vis, x, &nx, v3_d(L->pos), NULL);
	return seen ? e : 0.0;
}

/* The mean irradiance over points xs (rad_ff_rcv_mean); sets *front as
 * ff_sampled. */
static double light_sampled(const rad_vis *vis, const rad_light *L,
                            const rad_patch *r, const v3 *xs, int n,
                            double rcover, uint64_t *rays, double *spread,
                            int *front)
{
	double e[RAD_FF_MAX_SAMPLES];
	*front = 0;
	for (int k = 0; k < n; k++) {
		e[k] = rad_light_point(vis, L, xs[k], r->n, rays);
		*front |= light_geometry(L, xs[k], r->n) > 0;
	}
	return rad_ff_rcv_mean(vis, r->n, xs, e, n, rcover, rays, spread);
}

double rad_light_patch_spread(const rad_vis *vis, const rad_light *L,
                              const rad_patch *r, int nrcv, double rcover,
                              uint64_t *rays, double *spread)
{
	v3 xs[RAD_FF_MAX_SAMPLES];
	int n = rad_patch_samples(r, nrcv, xs), front;
	double e =
	        light_sampled(vis, L, r, xs, n, rcover, rays, spread, &front);
	/* All points in shadow: as for patches, on scattered points. */
	if (e > 0 || !vis || !front)
		return e;
	n = rad_patch_scatter(r, RECHECK_POINTS, xs);
	return light_sampled(vis, L, r, xs, n, rcover, rays, spread, &front);
}

double rad_light_patch(const rad_vis *vis, const rad_light *L,
                       const rad_patch *r, int nrcv, uint64_t *rays)
{
	return rad_light_patch_spread(vis, L, r, nrcv, 0, rays, NULL);
}

double rad_light_estimate(const rad_light *L, const rad_patch *r)
{
	return light_geometry(L, rad_patch_centroid(r), r->n);
}
