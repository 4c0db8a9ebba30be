/*
 * test_ff.c -- form factors, visibility, light kernels and the scene
 * builder, against analytic references.
 *
 * References are closed forms from radiative transfer (parallel and
 * perpendicular rectangles, a differential area facing a rectangle corner,
 * a regular polygon on its axis), derived by hand for the polygon case
 * (each edge of a regular N-gon seen from the axis subtends a known angle
 * on a known plane), or brute-force integration of the defining integral
 * when no closed form exists (horizon clipping).  Scenes are built with
 * rad_scene_add_triangles directly, as an importer would.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "ff.h"
#include "scene.h"
#include "vis.h"

/* ------------------------------------------------------------- helpers */

static rad_patch patch(v3 p0, v3 e1, v3 e2, int quad)
{
	rad_patch p = {.p0 = p0, .e1 = e1, .e2 = e2, .quad = quad};
	v3 c = v3_cross(e1, e2);
	p.n = v3_norm(c);
	p.area = quad ? v3_len(c) : 0.5 * v3_len(c);
	return p;
}

static v3 V(double x, double y, double z)
{
	return v3_make(x, y, z);
}

static void assert_rel(double got, double want, double rel)
{
	if (!(fabs(got - want) <= rel * fabs(want)))
		fail_msg("got %.9g, want %.9g (rel. tolerance %g)", got, want,
		         rel);
}

static void assert_abs(double got, double want, double tol)
{
	if (!(fabs(got - want) <= tol))
		fail_msg("got %.12g, want %.12g (abs. tolerance %g)", got, want,
		         tol);
}

/* A scene with one grey material (id 0) and one node (id 0). */
static rad_scene *scene_start(void)
{
	rad_scene *s;
	uint32_t id;
	const double rho[3] = {0.5, 0.5, 0.5}, zero[3] = {0, 0, 0};
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	assert_int_equal(rad_scene_add_material(s, rho, zero, &id, NULL), 0);
	assert_int_equal(rad_scene_add_node(s, "node", &id, NULL), RAD_OK);
	return s;
}

/* Parallelogram p0, p0+e1, p0+e1+e2, p0+e2 as two triangles. */
static void add_quad(rad_scene *s, uint32_t mat, uint32_t node, v3 p0, v3 e1,
                     v3 e2)
{
	v3 a = p0, b = v3_add(p0, e1), c = v3_add(b, e2), d = v3_add(p0, e2);
	const double xyz[18] = {a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z,
	                        a.x, a.y, a.z, c.x, c.y, c.z, d.x, d.y, d.z};
	assert_int_equal(rad_scene_add_triangles(s, mat, node, xyz, 2, NULL),
	                 RAD_OK);
}

static void commit_ok(rad_scene *s)
{
	rad_error err;
	if (rad_scene_commit(s, &err) != RAD_OK)
		fail_msg("commit: %s", err.msg);
}

/* The committed polygon whose centroid is nearest to c. */
static rad_patch poly_near(const rad_scene *s, v3 c)
{
	rad_patch best = {0}, p;
	double dbest = INFINITY;
	for (uint32_t i = 0; i < s->npolys; i++) {
		rad_patch_from_poly(&p, s, &s->polys[i]);
		double d = v3_len(v3_sub(rad_patch_centroid(&p), c));
		if (d < dbest) {
			dbest = d;
			best = p;
		}
	}
	return best;
}

/* ---------------------------------------------------- analytic references */

/* Differential area on the normal through a corner of a w x h rectangle
 * at distance c, facing it. */
static double ff_corner(double w, double h, double c)
{
	double a = w / c, b = h / c;
	double sa = sqrt(1 + a * a), sb = sqrt(1 + b * b);
	return (a / sa * atan(b / sa) + b / sb * atan(a / sb)) / (2 * M_PI);
}

/* Parallel, directly opposed a x b rectangles at distance c. */
static double ff_parallel(double a, double b, double c)
{
	double X = a / c, Y = b / c, x2 = X * X, y2 = Y * Y;
	double t = 0.5 * log((1 + x2) * (1 + y2) / (1 + x2 + y2)) +
	           X * sqrt(1 + y2) * atan(X / sqrt(1 + y2)) +
	           Y * sqrt(1 + x2) * atan(Y / sqrt(1 + x2)) - X * atan(X) -
	           Y * atan(Y);
	return 2 * t / (M_PI * X * Y);
}

/* Perpendicular rectangles sharing an edge of length l; the receiver has
 * width w, the source height h (both measured away from the edge). */
static double ff_perpendicular(double l, double w, double h)
{
	double W = w / l, H = h / l, w2 = W * W, h2 = H * H;
	double r = sqrt(w2 + h2);
	double g = log((1 + w2) * (1 + h2) / (1 + w2 + h2)) +
	           w2 * log(w2 * (1 + w2 + h2) / ((1 + w2) * (w2 + h2))) +
	           h2 * log(h2 * (1 + h2 + w2) / ((1 + h2) * (h2 + w2)));
	return (W * atan(1 / W) + H * atan(1 / H) - r * atan(1 / r) + g / 4) /
	       (M_PI * W);
}

/*
 * Brute force: midpoint rule over an n x n grid of the source's (s, t)
 * square.  For a triangle, cells cut by the hypotenuse have their centre
 * on it and count half, which keeps the rule second order.
 */
static double ff_brute(v3 x, v3 nx, const rad_patch *s, int n)
{
	double sum = 0;
	for (int i = 0; i < n; i++) {
		for (int j = 0; j < n; j++) {
			double wgt = 1;
			if (!s->quad && i + j >= n - 1)
				wgt = i + j == n - 1 ? 0.5 : 0;
			double u = (i + 0.5) / n, w = (j + 0.5) / n;
			v3 y = v3_madd(v3_madd(s->p0, s->e1, u), s->e2, w);
			v3 d = v3_sub(y, x);
			double d2 = v3_dot(d, d), len = sqrt(d2);
			double cx = v3_dot(d, nx) / len;
			double cy = -v3_dot(d, s->n) / len;
			if (wgt > 0 && cx > 0 && cy > 0)
				sum += wgt * cx * cy / (M_PI * d2);
		}
	}
	return sum * v3_len(v3_cross(s->e1, s->e2)) / ((double)n * n);
}

/* ------------------------------------------------------------ form factors */

static const v3 O = {0, 0, 0};

static void test_ff_parallel_unit_squares(void **state)
{
	(void)state;
	rad_patch r = patch(O, V(1, 0, 0), V(0, 1, 0), 1);
	rad_patch s = patch(V(0, 0, 1), V(0, 1, 0), V(1, 0, 0), 1);
	double want = ff_parallel(1, 1, 1);
	assert_rel(want, 0.19982, 1e-4);
	double got = rad_ff_unoccluded(&r, &s, 16);
	assert_rel(got, want, 0.005);
	print_message("parallel squares: F = %.6f (exact %.6f, %+.3f%%)\n", got,
	              want, 100 * (got / want - 1));
	/* Centre and an off-centre point: sums of four corner rectangles. */
	double fc = rad_ff_point_patch(V(0.5, 0.5, 0), V(0, 0, 1), &s);
	assert_abs(fc, 4 * ff_corner(0.5, 0.5, 1), 1e-12);
	double fo = rad_ff_point_patch(V(0.2, 0.3, 0), V(0, 0, 1), &s);
	double wo = ff_corner(0.2, 0.3, 1) + ff_corner(0.8, 0.3, 1) +
	            ff_corner(0.2, 0.7, 1) + ff_corner(0.8, 0.7, 1);
	assert_abs(fo, wo, 1e-12);
}

static void test_ff_perpendicular_squares_sharing_edge(void **state)
{
	(void)state;
	rad_patch floor = patch(O, V(1, 0, 0), V(0, 1, 0), 1);
	rad_patch wall = patch(O, V(0, 1, 0), V(0, 0, 1), 1);
	double want = ff_perpendicular(1, 1, 1);
	assert_rel(want, 0.20004, 1e-4);
	double got = rad_ff_unoccluded(&floor, &wall, 16);
	assert_rel(got, want, 0.01);
	print_message("perpendicular squares: F = %.6f (exact %.6f, "
	              "%+.3f%%)\n",
	              got, want, 100 * (got / want - 1));
	/* Other proportions, both ways.  Sixteen points across a receiver
	 * twice as wide resolve the log-singular slope at the shared edge
	 * less well: 2 %. */
	rad_patch wide = patch(O, V(2, 0, 0), V(0, 1, 0), 1);
	assert_rel(rad_ff_unoccluded(&wide, &wall, 16),
	           ff_perpendicular(1, 2, 1), 0.02);
	assert_rel(rad_ff_unoccluded(&wall, &wide, 16),
	           ff_perpendicular(1, 1, 2), 0.02);
}

/*
 * Regular N-gon of circumradius R centred below x at depth h.  Seen from
 * x, the edge at apothem a = R cos(pi/N), half-length b = R sin(pi/N)
 * subtends beta with cos beta = (a^2 + h^2 - b^2) / (a^2 + h^2 + b^2), on
 * a plane whose normal makes cos = a / sqrt(a^2 + h^2) with the axis; the
 * spokes from the centre lie in planes containing the axis and add 0.
 */
static double ff_fan_edge(double R, int N, double h)
{
	double a = R * cos(M_PI / N), b = R * sin(M_PI / N);
	double beta = acos((a * a + h * h - b * b) / (a * a + h * h + b * b));
	return beta * a / sqrt(a * a + h * h) / (2 * M_PI);
}

static void test_ff_point_polygon_fan_matches_analytic(void **state)
{
	(void)state;
	const int N = 64;
	const double R = 1.3, h = 0.7;
	v3 x = V(0, 0, h), down = V(0, 0, -1);
	double sum = 0;
	for (int i = 0; i < N; i++) {
		double t0 = 2 * M_PI * i / N, t1 = 2 * M_PI * (i + 1) / N;
		v3 a = V(R * cos(t0), R * sin(t0), 0);
		v3 b = V(R * cos(t1), R * sin(t1), 0);
		rad_patch tri = patch(O, a, b, 0);
		double f = rad_ff_point_patch(x, down, &tri);
		assert_abs(f, ff_fan_edge(R, N, h), 1e-13);
		sum += f;
	}
	assert_abs(sum, N * ff_fan_edge(R, N, h), 1e-12);
	/* ... and the 64-gon is nearly the disc R^2 / (h^2 + R^2). */
	assert_rel(sum, R * R / (h * h + R * R), 0.01);
}

static void test_ff_point_polygon_hidden_sides_are_zero(void **state)
{
	(void)state;
	rad_patch s = patch(O, V(1, 0, 0), V(0, 1, 0), 1); /* faces +z */
	/* Source below a receiver that faces up: behind the receiver. */
	assert_true(rad_ff_point_patch(V(0.5, 0.5, 1), V(0, 0, 1), &s) == 0);
	/* Receiver below the source, looking at its back. */
	assert_true(rad_ff_point_patch(V(0.5, 0.5, -1), V(0, 0, 1), &s) == 0);
	/* In the source's plane. */
	assert_true(rad_ff_point_patch(V(2, 0.5, 0), V(-1, 0, 0), &s) == 0);
}

static void test_ff_point_polygon_horizon_clipping(void **state)
{
	(void)state;
	rad_patch s = patch(V(-0.5, -0.5, 0), V(1.5, 0, 0), V(0, 1, 0), 1);
	rad_patch t =
	        patch(V(-0.3, -0.4, 0), V(1.2, 0.1, 0), V(0.2, 1.0, 0), 0);
	v3 x = V(0.1, 0.2, 0.4);
	/* Tilted normals whose tangent planes cut the sources. */
	const v3 normals[3] = {v3_norm(V(0.9, 0, -0.5)),
	                       v3_norm(V(-0.3, 0.8, -0.4)),
	                       v3_norm(V(1, 1, -0.2))};
	for (int i = 0; i < 3; i++) {
		double got = rad_ff_point_patch(x, normals[i], &s);
		double want = ff_brute(x, normals[i], &s, 1500);
		assert_true(got > 0.01);
		assert_abs(got, want, 2e-4);
		got = rad_ff_point_patch(x, normals[i], &t);
		want = ff_brute(x, normals[i], &t, 1500);
		assert_abs(got, want, 2e-4);
	}
}

static void test_ff_point_polygon_near_surface_is_finite(void **state)
{
	(void)state;
	rad_patch s = patch(O, V(1, 0, 0), V(0, 1, 0), 1);
	v3 down = V(0, 0, -1);
	/* Just above the interior: the whole hemisphere is the source. */
	assert_abs(rad_ff_point_patch(V(0.5, 0.5, 1e-12), down, &s), 1.0, 1e-9);
	/* Just above an edge midpoint: half of it. */
	assert_abs(rad_ff_point_patch(V(0.5, 0, 1e-12), down, &s), 0.5, 1e-9);
	/* Just above a corner: a quarter. */
	assert_abs(rad_ff_point_patch(V(1, 1, 1e-12), down, &s), 0.25, 1e-9);
	/* Grazing and awkward positions never give NaN or leave [0, 1]. */
	const double zs[4] = {1e-300, 1e-15, 1e-8, 1e3};
	for (int i = 0; i < 4; i++) {
		for (int k = 0; k < 50; k++) {
			v3 x = V(-0.5 + 0.04 * k, 0.5, zs[i]);
			v3 n = v3_norm(V(1, 0.3 * k - 7, -0.01 * k));
			double f = rad_ff_point_patch(x, n, &s);
			assert_true(f >= 0 && f <= 1);
		}
	}
}

static void test_ff_reciprocity(void **state)
{
	(void)state;
	rad_patch r = patch(O, V(1, 0, 0), V(0, 1, 0), 0);
	rad_patch s =
	        patch(V(-0.5, 0.2, 1.2), V(0.2, 0.8, 0.4), V(1.5, 0.3, 0), 1);
	assert_true(s.n.z < 0); /* faces the triangle */
	double rs = r.area * rad_ff_unoccluded(&r, &s, 16);
	double sr = s.area * rad_ff_unoccluded(&s, &r, 16);
	assert_true(rs > 0.01);
	assert_rel(rs, sr, 0.01);
	print_message("reciprocity: A_r F_rs = %.6f, A_s F_sr = %.6f\n", rs,
	              sr);
}

static void test_ff_estimate_tracks_exact(void **state)
{
	(void)state;
	rad_patch r = patch(O, V(1, 0, 0), V(0, 1, 0), 1);
	rad_patch far = patch(V(0, 0, 10), V(0, 1, 0), V(1, 0, 0), 1);
	assert_rel(rad_ff_estimate(&r, &far), rad_ff_unoccluded(&r, &far, 16),
	           0.02);
	/* Back to back: 0.  Perpendicular corner: positive. */
	rad_patch below = patch(V(0, 0, -1), V(1, 0, 0), V(0, 1, 0), 1);
	assert_true(rad_ff_estimate(&r, &below) == 0);
	rad_patch wall = patch(O, V(0, 1, 0), V(0, 0, 1), 1);
	assert_true(rad_ff_estimate(&r, &wall) > 0.05);
	/* Centroid behind, a corner in front: still positive. */
	rad_patch tilted =
	        patch(V(-0.5, 0, -0.2), V(0, 1, 0), V(1.0, 0, 0.3), 1);
	assert_true(v3_dot(v3_sub(rad_patch_centroid(&tilted),
	                          rad_patch_centroid(&r)),
	                   r.n) < 0);
	assert_true(rad_ff_estimate(&r, &tilted) > 0);
	/* A 1 cm strip standing on a receiver's edge (a luminaire's side
	 * under a ceiling): the centroids see each other at cosine 0.01,
	 * and the estimate took 1/50 of the exact form factor. */
	rad_patch ceil = patch(O, V(0.75, 0, 0), V(0, 1, 0), 1);
	rad_patch strip = patch(O, V(0, 0, 0.01), V(0.75, 0, 0), 1);
	double exact = 0.01 / 1 * ff_perpendicular(0.75, 0.01, 1);
	double est = rad_ff_estimate(&ceil, &strip);
	print_message("strip on an edge: estimate %.3g, exact %.3g\n", est,
	              exact);
	assert_rel(est, exact, 0.5);
}

/* Mean of |x - c|^2 over the samples. */
static double second_moment(const rad_patch *p, int n)
{
	v3 pts[RAD_FF_MAX_SAMPLES], c = rad_patch_centroid(p);
	double m = 0;
	assert_int_equal(rad_patch_samples(p, n, pts), n);
	for (int j = 0; j < n; j++) {
		v3 d = v3_sub(pts[j], c);
		m += v3_dot(d, d) / n;
	}
	return m;
}

static void test_ff_sample_patterns_are_balanced(void **state)
{
	(void)state;
	v3 e1 = V(2, 0, 0.5), e2 = V(0.3, 1, 0);
	rad_patch q = patch(V(1, 2, 3), e1, e2, 1);
	rad_patch t = patch(V(1, 2, 3), e1, e2, 0);
	const rad_patch *ps[2] = {&q, &t};
	const int counts[5] = {1, 2, 3, 4, 16};
	for (int i = 0; i < 2; i++) {
		v3 c = rad_patch_centroid(ps[i]);
		for (int k = 0; k < 5; k++) {
			int n = counts[k];
			/* Prefixes of 1, 4, 16, 2 (quad) and 3 (triangle)
			 * are exactly centred. */
			if ((n == 2 && !ps[i]->quad) || (n == 3 && ps[i]->quad))
				continue;
			v3 pts[RAD_FF_MAX_SAMPLES], m = O;
			assert_int_equal(rad_patch_samples(ps[i], n, pts), n);
			for (int j = 0; j < n; j++)
				m = v3_madd(m, pts[j], 1.0 / n);
			assert_abs(v3_len(v3_sub(m, c)), 0, 1e-12);
		}
	}
	/* 4 and 16 points integrate quadratics exactly: the polar moment
	 * about the centroid per unit area is (|e1|^2 + |e2|^2) / 12 for a
	 * parallelogram, (a^2 + b^2 + c^2) / 36 for a triangle of sides
	 * a, b, c. */
	double jq = (v3_dot(e1, e1) + v3_dot(e2, e2)) / 12;
	v3 e3 = v3_sub(e2, e1);
	double jt = (v3_dot(e1, e1) + v3_dot(e2, e2) + v3_dot(e3, e3)) / 36;
	for (int n = 4; n <= 16; n += 12) {
		assert_rel(second_moment(&q, n), jq, 1e-12);
		assert_rel(second_moment(&t, n), jt, 1e-12);
	}
	/* Sixteen distinct points; out-of-range counts are clamped. */
	v3 pts[RAD_FF_MAX_SAMPLES];
	assert_int_equal(rad_patch_samples(&t, 99, pts), 16);
	for (int a = 0; a < 16; a++)
		for (int b = a + 1; b < 16; b++)
			assert_true(v3_len(v3_sub(pts[a], pts[b])) > 0.05);
	assert_int_equal(rad_patch_samples(&t, 0, pts), 1);
}

/* ------------------------------------------------------------- visibility */

/* A 1 m floor, its ceiling 1 m up, and a 0.5 m plate halfway between
 * over the middle; *r and *c: the floor's and the ceiling's patches. */
static rad_scene *plate_scene(rad_patch *r, rad_patch *c)
{
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, O, V(1, 0, 0), V(0, 1, 0));
	add_quad(s, 0, 0, V(0, 0, 1), V(0, 1, 0), V(1, 0, 0));
	add_quad(s, 0, 0, V(0.25, 0.25, 0.5), V(0.5, 0, 0), V(0, 0.5, 0));
	commit_ok(s);
	*r = poly_near(s, V(0.5, 0.5, 0));
	*c = poly_near(s, V(0.5, 0.5, 1));
	return s;
}

static void test_vis_occluder_reduces_ff(void **state)
{
	(void)state;
	rad_patch r, c;
	rad_scene *s = plate_scene(&r, &c);
	uint64_t rays = 0;
	double open = rad_ff_unoccluded(&r, &c, 16);
	double shaded = rad_ff_patch(s->vis, &r, &c, 16, 16, &rays);
	assert_int_equal(rays, 16 * 16);
	assert_true(shaded < 0.8 * open && shaded > 0.2 * open);
	rad_scene_free(s);

	/* A plane larger than both blocks everything. */
	s = scene_start();
	add_quad(s, 0, 0, O, V(1, 0, 0), V(0, 1, 0));
	add_quad(s, 0, 0, V(0, 0, 1), V(0, 1, 0), V(1, 0, 0));
	add_quad(s, 0, 0, V(-1, -1, 0.5), V(3, 0, 0), V(0, 3, 0));
	commit_ok(s);
	r = poly_near(s, V(0.5, 0.5, 0));
	c = poly_near(s, V(0.5, 0.5, 1));
	assert_true(rad_ff_patch(s->vis, &r, &c, 16, 16, NULL) == 0);
	rad_scene_free(s);
}

/*
 * A source half hidden where it is far: a plate at half height hides the
 * floor beyond x = 1.5 from a point 1 m above the origin, so the point
 * sees the near part, which carries most of the kernel.  The share of
 * rays that pass (here 8 of 16) under-counts it; weighted by the point
 * kernel they must give the visible part's own form factor (exact).
 */
static void test_vis_partly_hidden_source_weighted(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, V(-0.5, -0.5, 0), V(4, 0, 0), V(0, 1, 0));
	add_quad(s, 0, 0, V(-0.01, -0.01, 1), V(0, 0.02, 0), V(0.02, 0, 0));
	add_quad(s, 0, 0, V(0.75, -2, 0.5), V(4.25, 0, 0), V(0, 4, 0));
	commit_ok(s);
	rad_patch src = poly_near(s, V(1.5, 0, 0));
	rad_patch rcv = poly_near(s, V(0, 0, 1));
	rad_patch seen = patch(V(-0.5, -0.5, 0), V(2, 0, 0), V(0, 1, 0), 1);
	double want = rad_ff_point_patch(V(0, 0, 1), V(0, 0, -1), &seen);
	double whole = rad_ff_point_patch(V(0, 0, 1), V(0, 0, -1), &src);
	double got = rad_ff_patch_spread(s->vis, &rcv, &src, 4, 16, 0, 0, NULL,
	                                 NULL);
	print_message("partly hidden source: F = %.5f, visible part %.5f "
	              "(%+.2f %%), whole %.5f\n",
	              got, want, 100 * (got / want - 1), whole);
	assert_rel(got, want, 0.05);
	rad_scene_free(s);
}

/*
 * Every sample point of the receiver under a small occluder 1 mm above it
 * (luminaires under a ceiling, on a grid that lines up with the sample
 * pattern): the rays all fail, yet the receiver sees the source almost
 * whole.  Zero must be re-checked on points that no grid lines up with,
 * for patches and for lights, with the 4- and with the 16-point rule
 * (occluders over both: a 16-point recheck alone was fooled by them).
 */
static void test_vis_aliased_zero_rechecked(void **state)
{
	(void)state;
	rad_patch r0 = patch(O, V(1, 0, 0), V(0, 1, 0), 1);
	v3 x[4 + 16];
	assert_int_equal(rad_patch_samples(&r0, 4, x), 4);
	assert_int_equal(rad_patch_samples(&r0, 16, x + 4), 16);
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, O, V(1, 0, 0), V(0, 1, 0));
	add_quad(s, 0, 0, V(0, 0, 1), V(0, 1, 0), V(1, 0, 0));
	for (int k = 0; k < 20; k++) /* 4 cm squares, 1 mm up, facing down */
		add_quad(s, 0, 0, v3_add(x[k], V(-0.02, -0.02, 0.001)),
		         V(0, 0.04, 0), V(0.04, 0, 0));
	rad_light_desc d = {.kind = RAD_LIGHT_POINT,
	                    .position = {0.5, 0.5, 0.5},
	                    .intensity = {1, 1, 1}};
	rad_error err;
	if (rad_scene_add_light(s, &d, &err))
		fail_msg("light: %s", err.msg);
	commit_ok(s);
	rad_patch r = poly_near(s, V(0.5, 0.5, 0));
	rad_patch c = poly_near(s, V(0.5, 0.5, 1));
	double open = rad_ff_unoccluded(&r, &c, 16);
	const rad_light *L = &s->lights[0];
	double e_open = rad_light_patch(NULL, L, &r, 16, NULL);
	for (int n = 4; n <= 16; n += 12) {
		uint64_t rays = 0;
		double f = rad_ff_patch(s->vis, &r, &c, n, 4, &rays);
		/* n x 4 rays failed, then 16 scattered points' 64. */
		assert_int_equal(rays, (uint64_t)n * 4 + 64);
		assert_true(f > 0.9 * open && f <= open);
		double e = rad_light_patch(s->vis, L, &r, n, NULL);
		assert_true(e > 0.9 * e_open && e <= e_open * (1 + 1e-12));
	}
	rad_scene_free(s);
}

/* A placement: origin and orthonormal axes. */
typedef struct frame {
	v3 o, x, y, z;
} frame;

static v3 dir_in(const frame *f, double x, double y, double z)
{
	return v3_madd(v3_madd(v3_scale(f->x, x), f->y, y), f->z, z);
}

static v3 at(const frame *f, double x, double y, double z)
{
	return v3_add(f->o, dir_in(f, x, y, z));
}

/* Inward-facing box [0,L]^3 placed by f; the floor as two triangles on two
 * nodes so that its diagonal stays a shared edge rays may end on. */
static rad_scene *box_scene(const frame *f, double L)
{
	rad_scene *s = scene_start();
	uint32_t node2;
	assert_int_equal(rad_scene_add_node(s, "floor2", &node2, NULL), 0);
	const v3 c[4] = {at(f, 0, 0, 0), at(f, L, 0, 0), at(f, L, L, 0),
	                 at(f, 0, L, 0)};
	const double tri[2][9] = {{c[0].x, c[0].y, c[0].z, c[1].x, c[1].y,
	                           c[1].z, c[2].x, c[2].y, c[2].z},
	                          {c[0].x, c[0].y, c[0].z, c[2].x, c[2].y,
	                           c[2].z, c[3].x, c[3].y, c[3].z}};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, tri[0], 1, NULL), 0);
	assert_int_equal(rad_scene_add_triangles(s, 0, node2, tri[1], 1, NULL),
	                 0);
	v3 ex = dir_in(f, L, 0, 0), ey = dir_in(f, 0, L, 0);
	v3 ez = dir_in(f, 0, 0, L);
	add_quad(s, 0, 0, at(f, 0, 0, L), ey, ex); /* ceiling */
	add_quad(s, 0, 0, c[0], ey, ez);           /* x = 0 */
	add_quad(s, 0, 0, c[1], ez, ey);           /* x = L */
	add_quad(s, 0, 0, c[0], ez, ex);           /* y = 0 */
	add_quad(s, 0, 0, c[3], ex, ez);           /* y = L */
	commit_ok(s);
	return s;
}

/* Points of a 16 x 16 grid of cell centres on a patch. */
static void grid16(const rad_patch *p, v3 out[256])
{
	for (int i = 0; i < 16; i++)
		for (int j = 0; j < 16; j++)
			out[16 * i + j] =
			        v3_madd(v3_madd(p->p0, p->e1, (i + 0.5) / 16),
			                p->e2, (j + 0.5) / 16);
}

/*
 * Rays between 16 x 16 grids on the floor and on three other faces of a
 * closed box (opposite, adjacent, adjacent) must all pass, whatever the
 * scale, and also for a tilted box far from the origin, where float
 * coordinates are coarse compared with the box.
 */
static void test_vis_no_self_occlusion_at_any_scale(void **state)
{
	(void)state;
	const double sizes[4] = {1e-3, 1, 1e3, 1};
	const frame axes = {O, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
	/* Rotated by 0.3 rad about x, then 0.7 about y; 5 km out. */
	const double ca = cos(0.3), sa = sin(0.3), cb = cos(0.7), sb = sin(0.7);
	const frame far = {{5e3, 5e3, 5e3},
	                   {cb, 0, -sb},
	                   {sb * sa, ca, cb * sa},
	                   {sb * ca, -sa, cb * ca}};
	static v3 a[256], b[256];
	rad_vis_thread_init();
	for (int k = 0; k < 4; k++) {
		const frame *f = k < 3 ? &axes : &far;
		double L = sizes[k], h = L / 2;
		rad_scene *s = box_scene(f, L);
		assert_int_equal(s->counts.polygons, 7);
		v3 up = f->z;
		rad_patch floor =
		        patch(f->o, dir_in(f, L, 0, 0), dir_in(f, 0, L, 0), 1);
		const v3 targets[3] = {at(f, h, h, L), at(f, 0, h, h),
		                       at(f, h, L, h)};
		grid16(&floor, a);
		long blocked = 0, total = 0;
		for (int t = 0; t < 3; t++) {
			rad_patch dst = poly_near(s, targets[t]);
			grid16(&dst, b);
			for (int i = 0; i < 256; i++)
				for (int j = 0; j < 256; j++, total++)
					blocked += !rad_vis_segment(
					        s->vis, a[i], &floor.n, b[j],
					        &dst.n);
		}
		print_message("box %g at %g: %ld of %ld rays falsely blocked "
		              "(eps %.3g)\n",
		              L, f->o.x, blocked, total, rad_vis_eps(s->vis));
		assert_int_equal(blocked, 0);
		/* The walls do block: from inside to outside. */
		v3 in = at(f, h, h, h), out = at(f, h, h, 2 * L);
		assert_false(rad_vis_segment(s->vis, in, NULL, out, NULL));
		assert_false(rad_vis_ray_free(s->vis, in, NULL, up));
		double t;
		uint32_t hit = rad_vis_first_hit(s->vis, in, v3_scale(up, 3),
		                                 10 * L, &t);
		assert_true(hit < s->npolys);
		/* The ceiling, at half the box's height. */
		assert_rel(v3_dot(rad_poly_normal(&s->polys[hit]), up), -1,
		           1e-6);
		assert_rel(t, h, 1e-3);
		rad_scene_free(s);
	}
}

/*
 * The packet paths answer as the single rays do, ray by ray: segments
 * from a 16 x 16 grid on the floor to one on the ceiling, a plate between
 * them hiding some and not others, traced in runs of every length from
 * 0 to 40 (packets full, partial and of one lane, and none).  And the
 * floor's grid tested for cover in runs of 0, 13, 26, 39 and 256: the
 * plate, 0.5 m over the floor's middle, covers some points within
 * 0.6 m and none within 0.4 m.
 */
static void test_vis_packets_answer_as_single_rays(void **state)
{
	(void)state;
	rad_patch r, c;
	rad_scene *s = plate_scene(&r, &c);
	rad_vis_thread_init();
	static v3 a[256], b[256];
	static rad_vis_seg seg[256];
	static unsigned char open[256];
	grid16(&r, a);
	grid16(&c, b);
	for (int k = 0; k < 256; k++)
		seg[k] = (rad_vis_seg){a[k], r.n, b[(k * 37) % 256], c.n};
	int blocked = 0, used = 0;
	for (int n = 0; n <= 40; n++) {
		rad_vis_segments(s->vis, seg + used, n, open);
		for (int k = 0; k < n; k++) {
			const rad_vis_seg *g = &seg[used + k];
			int one = rad_vis_segment(s->vis, g->a, &g->na, g->b,
			                          &g->nb);
			assert_int_equal(open[k], one);
			blocked += !one;
		}
		used = (used + n) % 200;
	}
	assert_true(blocked > 0); /* the plate hides some of them */
	/* Cover: 0.6 m reaches the plate from the floor, 0.4 m does not. */
	static unsigned char cov[256];
	for (int n = 0; n <= 256; n += n < 39 ? 13 : 256 - 39) {
		rad_vis_covered_n(s->vis, r.n, 0.6, a, n, cov);
		int hidden = 0;
		for (int k = 0; k < n; k++) {
			assert_int_equal(cov[k], rad_vis_covered(s->vis, a[k],
			                                         r.n, 0.6));
			hidden += cov[k];
		}
		rad_vis_covered_n(s->vis, r.n, 0.4, a, n, cov);
		for (int k = 0; k < n; k++)
			assert_int_equal(cov[k], 0);
		if (n == 256)
			assert_true(hidden > 0 && hidden < n);
	}
	rad_scene_free(s);
}

/* ------------------------------------------------------------------ lights */

static rad_scene *floor_with_light(const rad_light_desc *d, int roof)
{
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, V(-5, -5, 0), V(10, 0, 0), V(0, 10, 0));
	if (roof) /* a small roof at z = 1 over the origin */
		add_quad(s, 0, 0, V(-0.5, -0.5, 1), V(0, 1, 0), V(1, 0, 0));
	rad_error err;
	if (rad_scene_add_light(s, d, &err))
		fail_msg("light: %s", err.msg);
	commit_ok(s);
	return s;
}

static void test_light_point_inverse_square(void **state)
{
	(void)state;
	rad_light_desc d = {.kind = RAD_LIGHT_POINT,
	                    .position = {0, 0, 2},
	                    .intensity = {100, 100, 100}};
	rad_scene *s = floor_with_light(&d, 0);
	const rad_light *L = &s->lights[0];
	v3 up = V(0, 0, 1);
	uint64_t rays = 0;
	assert_abs(100 * rad_light_point(s->vis, L, O, up, &rays), 25, 1e-9);
	assert_int_equal(rays, 1);
	/* Off axis: I cos / d^2 with cos = 2 / sqrt(5), d^2 = 5. */
	assert_abs(100 * rad_light_point(s->vis, L, V(1, 0, 0), up, NULL),
	           100 * 2 / pow(5, 1.5), 1e-9);
	/* Facing away: 0. */
	assert_true(rad_light_point(s->vis, L, O, V(0, 0, -1), NULL) == 0);
	/* Small patch: average and estimate close to the point value. */
	rad_patch p =
	        patch(V(-0.01, -0.01, 0), V(0.02, 0, 0), V(0, 0.02, 0), 1);
	assert_rel(100 * rad_light_patch(s->vis, L, &p, 4, NULL), 25, 1e-3);
	assert_rel(100 * rad_light_estimate(L, &p), 25, 1e-9);
	rad_scene_free(s);

	/* glTF range window 1 - (d/range)^4. */
	d.range = 4;
	s = floor_with_light(&d, 0);
	assert_abs(rad_light_point(s->vis, &s->lights[0], O, up, NULL),
	           (1 - 1.0 / 16) / 4, 1e-12);
	assert_true(rad_light_point(s->vis, &s->lights[0], V(4, 0, 0), up,
	                            NULL) == 0);
	rad_scene_free(s);
}

static void test_light_spot_cone_edges(void **state)
{
	(void)state;
	const double inner = 30 * M_PI / 180, outer = 45 * M_PI / 180;
	rad_light_desc d = {.kind = RAD_LIGHT_SPOT,
	                    .position = {0, 0, 1},
	                    .direction = {0, 0, -3},
	                    .intensity = {1, 1, 1},
	                    .inner_cone = inner,
	                    .outer_cone = outer};
	rad_scene *s = floor_with_light(&d, 0);
	const rad_light *L = &s->lights[0];
	v3 up = V(0, 0, 1);
	const double deg[6] = {0, 20, 29.9, 40, 45.1, 60};
	for (int i = 0; i < 6; i++) {
		double a = deg[i] * M_PI / 180;
		v3 x = V(tan(a), 0, 0);
		double c = cos(a), k = 1;
		if (a >= outer)
			k = 0;
		else if (a > inner)
			k = pow((c - cos(outer)) / (cos(inner) - cos(outer)),
			        2);
		/* I cos / d^2 with d = 1 / cos. */
		assert_abs(rad_light_point(s->vis, L, x, up, NULL),
		           k * c * c * c, 1e-12);
	}
	rad_scene_free(s);
}

static void test_light_directional_cosine_and_shadow(void **state)
{
	(void)state;
	const double a = 60 * M_PI / 180;
	rad_light_desc d = {.kind = RAD_LIGHT_DIRECTIONAL,
	                    .direction = {sin(a), 0, -cos(a)},
	                    .intensity = {1000, 1000, 1000}};
	rad_scene *s = floor_with_light(&d, 1);
	const rad_light *L = &s->lights[0];
	v3 up = V(0, 0, 1);
	assert_abs(1000 * rad_light_point(s->vis, L, V(3, 3, 0), up, NULL), 500,
	           1e-9);
	/* The roof (z = 1 over the origin) shades the floor at x = tan a. */
	v3 shadowed = V(tan(a), 0, 0);
	assert_true(rad_light_point(s->vis, L, shadowed, up, NULL) == 0);
	rad_patch p = patch(shadowed, V(0.01, 0, 0), V(0, 0.01, 0), 1);
	assert_abs(rad_light_estimate(L, &p), 0.5, 1e-12);
	assert_true(rad_light_patch(s->vis, L, &p, 4, NULL) == 0);
	rad_scene_free(s);
}

static void test_light_point_occluded(void **state)
{
	(void)state;
	rad_light_desc d = {.kind = RAD_LIGHT_POINT,
	                    .position = {0, 0, 2},
	                    .intensity = {100, 100, 100}};
	rad_scene *s = floor_with_light(&d, 1);
	assert_true(rad_light_point(s->vis, &s->lights[0], O, V(0, 0, 1),
	                            NULL) == 0);
	assert_true(rad_light_point(s->vis, &s->lights[0], V(3, 0, 0),
	                            V(0, 0, 1), NULL) > 0);
	rad_scene_free(s);
}

/* ----------------------------------------------------------- scene builder */

static void test_scene_shares_identical_materials(void **state)
{
	(void)state;
	rad_scene *s;
	uint32_t id[4];
	const double rho[3] = {0.2, 0.4, 0.6}, lum[3] = {1, 2, 3};
	const double other[3] = {0.2, 0.4, 0.61};
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	for (int i = 0; i < 3; i++)
		assert_int_equal(
		        rad_scene_add_material(s, rho, lum, &id[i], NULL), 0);
	assert_int_equal(rad_scene_add_material(s, other, lum, &id[3], NULL),
	                 0);
	assert_int_equal(id[0], 0);
	assert_int_equal(id[1], 0);
	assert_int_equal(id[2], 0);
	assert_int_equal(id[3], 1);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.materials, 2);
	assert_int_equal(c.materials_offered, 4);
	/* Exitance is pi x luminance. */
	assert_rel(s->mats[0].emit[2], 3 * M_PI, 1e-6);
	rad_scene_free(s);
}

static void test_scene_refuses_bad_materials(void **state)
{
	(void)state;
	rad_scene *s;
	rad_error err;
	uint32_t id;
	const double zero[3] = {0, 0, 0};
	const double bad_rho[4][3] = {
	        {0.5, 1.0, 0.5}, {-0.1, 0, 0}, {NAN, 0, 0}, {INFINITY, 0, 0}};
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	for (int i = 0; i < 4; i++) {
		assert_int_equal(
		        rad_scene_add_material(s, bad_rho[i], zero, &id, &err),
		        RAD_ERR_INVALID);
		assert_non_null(strstr(err.msg, "reflectance"));
	}
	const double neg[3] = {0, -1, 0}, huge[3] = {1e300, 0, 0};
	assert_int_equal(rad_scene_add_material(s, zero, neg, &id, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "luminance"));
	assert_int_equal(rad_scene_add_material(s, zero, huge, &id, &err),
	                 RAD_ERR_INVALID);
	/* Just below 1 is valid and stays below 1 once stored as float. */
	const double almost[3] = {0.999999999, 0, 0};
	assert_int_equal(rad_scene_add_material(s, almost, zero, &id, &err), 0);
	assert_true(s->mats[id].rho[0] < 1.0f);
	rad_scene_free(s);
}

static void test_scene_skips_and_counts_bad_triangles(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	const double xyz[7][9] = {
	        {0, 0, 0, 1, 0, 0, 0, 1, 0},        /* good */
	        {0, 0, 0, NAN, 0, 0, 0, 1, 0},      /* NaN */
	        {0, 0, 0, 1, 0, 0, 0, INFINITY, 0}, /* Inf */
	        {0, 0, 0, 1e39, 0, 0, 0, 1, 0},     /* beyond float */
	        {0, 0, 0, 1, 1, 1, 2, 2, 2},        /* collinear */
	        {0, 0, 0, 1, 0, 0, 0.5, 1e-13, 0},  /* sliver */
	        {1, 1, 1, 1, 1, 1, 1, 1, 1},        /* a point */
	};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, xyz[0], 7, NULL), 0);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.triangles_in, 7);
	assert_int_equal(c.triangles_nonfinite, 3);
	assert_int_equal(c.triangles_degenerate, 3);
	assert_int_equal(c.polygons, 1);
	/* Bad ids are refused and name the id. */
	rad_error err;
	assert_int_equal(rad_scene_add_triangles(s, 7, 0, xyz[0], 1, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "material 7"));
	assert_int_equal(rad_scene_add_triangles(s, 0, 3, xyz[0], 1, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "node 3"));
	rad_scene_free(s);
}

/*
 * A repeated triangle (same vertices, same turn, whichever vertex it
 * starts from) is one surface: dropped at commit and counted.  The
 * reversed twin of a two-sided face is not a copy and stays, and a copy
 * of one half of a square does not keep the square from merging.
 */
static void test_scene_drops_repeated_triangles(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, V(0, 0, 0), V(1, 0, 0), V(0, 1, 0)); /* faces +z */
	const double copies[3][9] = {
	        {0, 0, 0, 1, 0, 0, 1, 1, 0}, /* the first half again */
	        {1, 0, 0, 1, 1, 0, 0, 0, 0}, /* the same, rotated */
	        {0, 0, 0, 1, 1, 0, 1, 0, 0}, /* reversed: faces -z */
	};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, copies[0], 3, NULL),
	                 RAD_OK);
	commit_ok(s);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.triangles_in, 5);
	assert_int_equal(c.triangles_duplicate, 2);
	assert_int_equal(c.polygons, 2); /* the square and the reversed half */
	assert_int_equal(c.quads, 1);
	rad_scene_free(s);
}

/* Commit s and return its counts and its polygons' total area. */
static double commit_area(rad_scene *s, rad_scene_counts *c)
{
	commit_ok(s);
	rad_scene_counts_get(s, c);
	double a = 0;
	for (uint32_t i = 0; i < s->npolys; i++)
		a += s->polys[i].area;
	return a;
}

/*
 * Cutting at commit (conform.c).  A wall standing across a floor from
 * edge to edge cuts it in two; a partition that stops inside the floor
 * does not; four walls meeting at their corners on a floor that runs past
 * them cut it along their four lines (3 x 3 pieces); a small box standing
 * on it does not.  The area is kept.
 */
static void test_scene_cuts_along_walls(void **state)
{
	(void)state;
	rad_scene_counts c;
	/* floor 4 x 4 facing +y, a 2 m wall at x = 1 across it */
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, V(0, 0, 0), V(0, 0, 4), V(4, 0, 0));
	add_quad(s, 0, 0, V(1, 0, 0), V(0, 2, 0), V(0, 0, 4));
	assert_float_equal(commit_area(s, &c), 24, 1e-5);
	assert_int_equal(c.polygons_cut, 1);
	assert_int_equal(c.polygons, 3);
	assert_int_equal(c.quads, 3);
	rad_scene_free(s);
	/* the same wall, stopping half-way */
	s = scene_start();
	add_quad(s, 0, 0, V(0, 0, 0), V(0, 0, 4), V(4, 0, 0));
	add_quad(s, 0, 0, V(1, 0, 0), V(0, 2, 0), V(0, 0, 2));
	assert_float_equal(commit_area(s, &c), 20, 1e-5);
	assert_int_equal(c.polygons_cut, 0);
	assert_int_equal(c.polygons, 2);
	rad_scene_free(s);
	/* a 6 x 6 floor, a 4 x 4 room of walls meeting at its corners */
	s = scene_start();
	add_quad(s, 0, 0, V(-1, 0, -1), V(0, 0, 6), V(6, 0, 0));
	add_quad(s, 0, 0, V(0, 0, 0), V(0, 2, 0), V(0, 0, 4));
	add_quad(s, 0, 0, V(4, 0, 0), V(0, 0, 4), V(0, 2, 0));
	add_quad(s, 0, 0, V(0, 0, 0), V(4, 0, 0), V(0, 2, 0));
	add_quad(s, 0, 0, V(0, 0, 4), V(0, 2, 0), V(4, 0, 0));
	assert_float_equal(commit_area(s, &c), 36 + 4 * 8, 1e-4);
	assert_int_equal(c.polygons_cut, 1);
	assert_int_equal(c.polygons, 9 + 4);
	rad_scene_free(s);
	/* a 0.1 m box standing on the 4 x 4 floor */
	s = scene_start();
	add_quad(s, 0, 0, V(0, 0, 0), V(0, 0, 4), V(4, 0, 0));
	add_quad(s, 0, 0, V(2, 0, 2), V(0, 0.1, 0), V(0, 0, 0.1));
	add_quad(s, 0, 0, V(2.1, 0, 2), V(0, 0, 0.1), V(0, 0.1, 0));
	add_quad(s, 0, 0, V(2, 0, 2), V(0.1, 0, 0), V(0, 0.1, 0));
	add_quad(s, 0, 0, V(2, 0, 2.1), V(0, 0.1, 0), V(0.1, 0, 0));
	commit_area(s, &c);
	assert_int_equal(c.polygons_cut, 0);
	assert_int_equal(c.polygons, 5);
	rad_scene_free(s);
}

static void test_scene_merges_square_into_one_parallelogram(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	add_quad(s, 0, 0, V(1, 2, 3), V(0, 1, 0), V(0, 0, 1)); /* faces +x */
	commit_ok(s);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.polygons, 1);
	assert_int_equal(c.quads, 1);
	const rad_poly *p = &s->polys[0];
	assert_int_equal(p->quad, 1);
	assert_rel(p->area, 1, 1e-7);
	assert_rel(rad_poly_normal(p).x, 1, 1e-7);
	v3 e = v3_cross(rad_poly_e1(s, p), rad_poly_e2(s, p));
	assert_true(e.x > 0); /* same orientation as the triangles */
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	assert_abs(lo[1], 2, 1e-7);
	assert_abs(hi[2], 4, 1e-7);
	assert_rel(s->diag, sqrt(2), 1e-7);
	assert_rel(s->total_area, 1, 1e-7);
	rad_scene_free(s);
}

static void test_scene_merges_triangulated_grid_into_cells(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	/* A 4 x 4 grid, each cell cut along the same diagonal, in one call. */
	double xyz[32 * 9];
	int t = 0;
	for (int i = 0; i < 4; i++) {
		for (int j = 0; j < 4; j++) {
			const double c[4][3] = {{i, j, 0},
			                        {i + 1, j, 0},
			                        {i + 1, j + 1, 0},
			                        {i, j + 1, 0}};
			const int tri[2][3] = {{0, 1, 2}, {0, 2, 3}};
			for (int k = 0; k < 2; k++, t++)
				for (int v = 0; v < 3; v++)
					memcpy(xyz + 9 * t + 3 * v,
					       c[tri[k][v]], sizeof(c[0]));
		}
	}
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, xyz, 32, NULL), 0);
	commit_ok(s);
	assert_int_equal(s->counts.polygons, 16);
	assert_int_equal(s->counts.quads, 16);
	for (uint32_t i = 0; i < s->npolys; i++)
		assert_rel(s->polys[i].area, 1, 1e-6); /* unit cells */
	rad_scene_free(s);
}

static void test_scene_keeps_non_parallelogram_pairs(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	uint32_t mat2, node2;
	const double rho[3] = {0.3, 0.3, 0.3}, zero[3] = {0, 0, 0};
	assert_int_equal(rad_scene_add_material(s, rho, zero, &mat2, NULL), 0);
	assert_int_equal(rad_scene_add_node(s, NULL, &node2, NULL), 0);
	/* Kite: shares an edge, fourth vertex off the parallelogram. */
	const double kite[18] = {0, 0, 0, 1, 0, 0, 1,    1, 0,
	                         0, 0, 0, 1, 1, 0, -0.2, 1, 0};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, kite, 2, NULL), 0);
	/* Folded square: not coplanar. */
	const double fold[18] = {0, 0, 5, 1, 0, 5, 1, 1, 5,
	                         0, 0, 5, 1, 1, 5, 0, 1, 5.3};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, fold, 2, NULL), 0);
	/* Opposite orientations: the edge is not shared the same way. */
	const double flip[18] = {0, 0, 10, 1, 0, 10, 1, 1, 10,
	                         0, 0, 10, 0, 1, 10, 1, 1, 10};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, flip, 2, NULL), 0);
	/* A square split across two materials, and across two nodes. */
	const double half[2][9] = {{0, 0, 15, 1, 0, 15, 1, 1, 15},
	                           {0, 0, 15, 1, 1, 15, 0, 1, 15}};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, half[0], 1, NULL), 0);
	assert_int_equal(rad_scene_add_triangles(s, mat2, 0, half[1], 1, NULL),
	                 0);
	const double half2[2][9] = {{0, 0, 20, 1, 0, 20, 1, 1, 20},
	                            {0, 0, 20, 1, 1, 20, 0, 1, 20}};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, half2[0], 1, NULL),
	                 0);
	assert_int_equal(
	        rad_scene_add_triangles(s, 0, node2, half2[1], 1, NULL), 0);
	commit_ok(s);
	assert_int_equal(s->counts.polygons, 10);
	assert_int_equal(s->counts.quads, 0);
	rad_scene_free(s);
}

static void test_scene_states_and_light_validation(void **state)
{
	(void)state;
	rad_error err;
	rad_scene *s = scene_start();
	rad_light_desc spot = {.kind = RAD_LIGHT_SPOT,
	                       .direction = {0, 0, -1},
	                       .intensity = {1, 1, 1},
	                       .inner_cone = 0.5,
	                       .outer_cone = 0.5};
	assert_int_equal(rad_scene_add_light(s, &spot, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "cone"));
	spot.outer_cone = 2.0;
	assert_int_equal(rad_scene_add_light(s, &spot, &err), RAD_ERR_INVALID);
	rad_light_desc dir = {.kind = RAD_LIGHT_DIRECTIONAL,
	                      .intensity = {1, 1, 1}};
	assert_int_equal(rad_scene_add_light(s, &dir, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "direction"));
	rad_light_desc pt = {.kind = RAD_LIGHT_POINT,
	                     .position = {0, 0, 9},
	                     .intensity = {1, -1, 1}};
	assert_int_equal(rad_scene_add_light(s, &pt, &err), RAD_ERR_INVALID);
	pt.intensity[1] = 1;
	pt.name = "bulb";
	assert_int_equal(rad_scene_add_light(s, &pt, &err), RAD_OK);
	/* Lights alone are not a scene. */
	assert_int_equal(rad_scene_commit(s, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "no polygons"));
	add_quad(s, 0, 0, O, V(1, 0, 0), V(0, 1, 0));
	commit_ok(s);
	/* Bounds reach the light; flux is 4 pi I. */
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	assert_abs(hi[2], 9, 0);
	assert_rel(s->total_flux[0], 4 * M_PI, 1e-12);
	assert_int_equal(rad_scene_commit(s, &err), RAD_ERR_STATE);
	assert_int_equal(rad_scene_add_light(s, &pt, &err), RAD_ERR_STATE);
	uint32_t id;
	assert_int_equal(rad_scene_add_node(s, "late", &id, &err),
	                 RAD_ERR_STATE);
	rad_scene_free(s);
}

static int64_t names_bytes(const rad_scene *s)
{
	int64_t n = (int64_t)rad_mem_usable(s->nodes);
	for (uint32_t i = 0; i < s->nnodes; i++)
		n += s->nodes[i] ? (int64_t)rad_mem_usable(s->nodes[i]) : 0;
	for (uint32_t i = 0; i < s->nlights; i++)
		if (s->lights[i].name)
			n += (int64_t)rad_mem_usable(s->lights[i].name);
	return n;
}

/* The report equals what the scene's arrays hold, so freeing them (as
 * rad_scene_free does) takes every kind back to zero. */
static void test_scene_memory_is_exact(void **state)
{
	(void)state;
	rad_light_desc pt = {.kind = RAD_LIGHT_POINT,
	                     .position = {0, 0, 2},
	                     .intensity = {1, 1, 1},
	                     .name = "lamp"};
	rad_scene *s = floor_with_light(&pt, 1);
	rad_mem_report r;
	rad_scene_memory(s, &r);
	assert_true(r.bytes[RAD_MEM_BVH] > 0);
	assert_int_equal(r.bytes[RAD_MEM_SCRATCH], 0);
	assert_int_equal(r.bytes[RAD_MEM_GEOMETRY],
	                 rad_mem_usable(s->polys) + rad_mem_usable(s->verts) +
	                         rad_mem_usable(s->runs));
	assert_int_equal(r.bytes[RAD_MEM_MATERIALS], rad_mem_usable(s->mats));
	assert_int_equal(r.bytes[RAD_MEM_LIGHTS], rad_mem_usable(s->lights));
	assert_int_equal(r.bytes[RAD_MEM_NAMES], names_bytes(s));
	print_message("bvh: %lld bytes for %u polygons\n",
	              (long long)r.bytes[RAD_MEM_BVH], s->npolys);
	rad_vis_free(s);
	rad_scene_memory(s, &r);
	assert_int_equal(r.bytes[RAD_MEM_BVH], 0);
	rad_scene_free(s);
}

/* Fail the k-th allocation of a commit, for every k: the error is NOMEM,
 * nothing leaks (ASan), nothing stays counted, and a retry succeeds. */
static void test_scene_commit_survives_allocation_failures(void **state)
{
	(void)state;
	for (int k = 0;; k++) {
		rad_scene *s = scene_start();
		add_quad(s, 0, 0, O, V(1, 0, 0), V(0, 1, 0));
		add_quad(s, 0, 0, V(0, 0, 1), V(0, 1, 0), V(1, 0, 0));
		rad_mem_report before, after;
		rad_scene_memory(s, &before);
		rad_mem_inject_failure(k);
		rad_error err;
		rad_status st = rad_scene_commit(s, &err);
		rad_mem_inject_failure(-1);
		if (st == RAD_OK) {
			rad_scene_free(s);
			assert_true(k > 2);
			return;
		}
		assert_int_equal(st, RAD_ERR_NOMEM);
		rad_scene_memory(s, &after);
		assert_int_equal(after.bytes[RAD_MEM_SCRATCH], 0);
		assert_int_equal(after.bytes[RAD_MEM_BVH], 0);
		if (s->merged) { /* merged before failing: no more triangles */
			const double tri[9] = {0, 0, 2, 1, 0, 2, 0, 1, 2};
			assert_int_equal(
			        rad_scene_add_triangles(s, 0, 0, tri, 1, &err),
			        RAD_ERR_STATE);
		}
		commit_ok(s);
		assert_int_equal(s->counts.quads, 2);
		rad_scene_free(s);
	}
}

/*
 * The geometry held once: a 2 x 2 grid of unit squares is 9 vertices and
 * 4 parallelograms, and the BVH, reading the polygons' own corner ids,
 * finds each square on both its halves (the second half is geometry 1,
 * through its polygon map: a triangle first makes its ids differ from the
 * polygons').  A two-sided square's back face has the same
 * vertices in the other turn, and a hit from behind finds it.
 */
static void test_scene_shares_vertices_with_the_bvh(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	const double tri[9] = {5, 0, -1, 6, 0, -1, 5, 1, -1};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, tri, 1, NULL),
	                 RAD_OK);
	for (int i = 0; i < 2; i++)
		for (int j = 0; j < 2; j++)
			add_quad(s, 0, 0, V(i, j, 0), V(1, 0, 0), V(0, 1, 0));
	/* A two-sided square above them. */
	v3 a = V(0, 0, 1), b = V(0, 1, 1), c = V(1, 1, 1), d = V(1, 0, 1);
	const double sheet[18] = {a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z,
	                          a.x, a.y, a.z, c.x, c.y, c.z, d.x, d.y, d.z};
	rad_surface_desc desc = {0, 0, sheet, NULL, 2, 1};
	assert_int_equal(rad_scene_add_surface(s, &desc, NULL), RAD_OK);
	commit_ok(s);
	/* The triangle, 4 squares, the sheet and its back. */
	assert_int_equal(s->npolys, 7);
	assert_int_equal(s->nfront, 6);
	assert_int_equal(s->nverts, 3 + 9 + 4);
	assert_null(s->vert_slots); /* the hash goes at commit */
	rad_vis_thread_init();
	for (uint32_t i = 1; i <= 4; i++) {
		const rad_poly *p = &s->polys[i];
		assert_int_equal(p->quad, 1);
		/* Both halves: s > t is the first triangle, s < t the second.
		 */
		for (int half = 0; half < 2; half++) {
			v3 x = rad_poly_point(s, p, half ? 0.2 : 0.8,
			                      half ? 0.8 : 0.2);
			double t;
			uint32_t hit = rad_vis_first_hit(
			        s->vis, v3_add(x, V(0, 0, 0.5)), V(0, 0, -1), 2,
			        &t);
			assert_int_equal(hit, i);
			assert_abs(t, 0.5, 1e-6);
		}
	}
	uint32_t front = 5, back = s->twin[front];
	assert_int_equal(back, 6);
	const rad_poly *f = &s->polys[front], *k = &s->polys[back];
	assert_int_equal(k->side, RAD_SIDE_BACK);
	assert_int_equal(k->v[0], f->v[0]);
	assert_int_equal(k->v[1], f->v[3]);
	assert_int_equal(k->v[2], f->v[2]);
	assert_int_equal(k->v[3], f->v[1]);
	assert_rel(v3_dot(rad_poly_e1(s, k), rad_poly_e2(s, f)), 1, 1e-7);
	/* the normal negated, bit for bit (scene.h, Normal and area) */
	assert_true(rad_poly_normal(k).z == -rad_poly_normal(f).z);
	int facing = 0;
	double t;
	/* From the floor up to the sheet: the front, not the back. */
	uint32_t hit = rad_vis_first_hit_front(s->vis, V(0.3, 0.6, 0.5),
	                                       V(0, 0, 1), 0, 2, &t, &facing);
	uint32_t down = rad_poly_normal(f).z < 0 ? front : back;
	assert_int_equal(hit, down);
	assert_int_equal(facing, 1);
	/* From above: the other face. */
	hit = rad_vis_first_hit_front(s->vis, V(0.3, 0.6, 1.5), V(0, 0, -1), 0,
	                              2, &t, &facing);
	assert_int_equal(hit, down == front ? back : front);
	assert_int_equal(facing, 1);
	rad_scene_free(s);
}

/*
 * A scene far from the origin keeps exact edges: its vertices are stored
 * relative to its first corner, so a 1 cm triangle 5 km out has edges as
 * exact as one at the origin (world floats are 0.5 mm apart there: 5 %
 * of its edge).
 */
static void test_scene_far_from_origin_keeps_exact_edges(void **state)
{
	(void)state;
	rad_scene *s = scene_start();
	const double X = 5000, Y = 5000;
	add_quad(s, 0, 0, V(X, Y, 0), V(10, 0, 0), V(0, 10, 0));
	const double tri[9] = {X + 3.1, Y + 4.7, 1.3,      X + 3.11, Y + 4.7,
	                       1.3,     X + 3.1, Y + 4.71, 1.3};
	assert_int_equal(rad_scene_add_triangles(s, 0, 0, tri, 1, NULL),
	                 RAD_OK);
	commit_ok(s);
	assert_int_equal(s->npolys, 2);
	const rad_poly *p = &s->polys[1];
	assert_int_equal(p->quad, 0);
	v3 e1 = rad_poly_e1(s, p), e2 = rad_poly_e2(s, p);
	assert_rel(e1.x, 0.01, 1e-4);
	assert_abs(e1.y, 0, 1e-6);
	assert_rel(e2.y, 0.01, 1e-4);
	assert_abs(e2.x, 0, 1e-6);
	v3 p0 = rad_scene_vertex(s, p->v[0]);
	assert_abs(p0.x, X + 3.1, 1e-6);
	assert_abs(p0.y, Y + 4.7, 1e-6);
	assert_rel(p->area, 0.5e-4, 1e-6);
	/* The BVH, traced relative to the same origin, finds it. */
	rad_vis_thread_init();
	double t;
	uint32_t hit = rad_vis_first_hit(s->vis, V(X + 3.102, Y + 4.702, 2),
	                                 V(0, 0, -1), 5, &t);
	assert_int_equal(hit, 1);
	assert_abs(t, 0.7, 1e-5);
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_ff_parallel_unit_squares),
	        cmocka_unit_test(test_ff_perpendicular_squares_sharing_edge),
	        cmocka_unit_test(test_ff_point_polygon_fan_matches_analytic),
	        cmocka_unit_test(test_ff_point_polygon_hidden_sides_are_zero),
	        cmocka_unit_test(test_ff_point_polygon_horizon_clipping),
	        cmocka_unit_test(test_ff_point_polygon_near_surface_is_finite),
	        cmocka_unit_test(test_ff_reciprocity),
	        cmocka_unit_test(test_ff_estimate_tracks_exact),
	        cmocka_unit_test(test_ff_sample_patterns_are_balanced),
	        cmocka_unit_test(test_vis_occluder_reduces_ff),
	        cmocka_unit_test(test_vis_partly_hidden_source_weighted),
	        cmocka_unit_test(test_vis_aliased_zero_rechecked),
	        cmocka_unit_test(test_vis_no_self_occlusion_at_any_scale),
	        cmocka_unit_test(test_vis_packets_answer_as_single_rays),
	        cmocka_unit_test(test_light_point_inverse_square),
	        cmocka_unit_test(test_light_spot_cone_edges),
	        cmocka_unit_test(test_light_directional_cosine_and_shadow),
	        cmocka_unit_test(test_light_point_occluded),
	        cmocka_unit_test(test_scene_shares_identical_materials),
	        cmocka_unit_test(test_scene_refuses_bad_materials),
	        cmocka_unit_test(test_scene_skips_and_counts_bad_triangles),
	        cmocka_unit_test(
	                test_scene_merges_square_into_one_parallelogram),
	        cmocka_unit_test(test_scene_drops_repeated_triangles),
	        cmocka_unit_test(test_scene_cuts_along_walls),
	        cmocka_unit_test(
	                test_scene_merges_triangulated_grid_into_cells),
	        cmocka_unit_test(test_scene_keeps_non_parallelogram_pairs),
	        cmocka_unit_test(test_scene_states_and_light_validation),
	        cmocka_unit_test(test_scene_memory_is_exact),
	        cmocka_unit_test(test_scene_shares_vertices_with_the_bvh),
	        cmocka_unit_test(test_scene_far_from_origin_keeps_exact_edges),
	        cmocka_unit_test(
	                test_scene_commit_survives_allocation_failures),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
