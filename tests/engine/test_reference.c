/*
 * test_reference.c -- the Monte Carlo reference (rad_reference_illuminance)
 * against closed forms derived here, never against the engine's kernels.
 *
 * Every comparison allows 3 standard errors of the estimate (as the
 * estimator reports it) plus a tiny absolute slack for float geometry:
 *   - point light of I cd over a plane: E = I cos / d^2 (x glTF's range
 *     window); spot light: x s^2 (glTF's smooth cone); directional light:
 *     E = E_n cos, and 0 under an occluder;
 *   - the same point light reflected by an infinite-like Lambertian floor
 *     onto a point facing down (one bounce):
 *       E = 2 rho I H h^2 \int_0^inf r dr / ((r^2 + H^2)^1.5 (r^2 + h^2)^2)
 *     integrated here by Simpson's rule;
 *   - a Lambertian square source of luminance L: E = pi L F, F by the
 *     corner formula for a parallel rectangle summed over four signed
 *     corners; also a point 1 cm under a 1 m panel and a 1 cm panel 2 m
 *     away, where the error bar must stay small (MIS at work);
 *   - furnace: a closed box whose faces all emit L and reflect rho gives
 *     E = pi L / (1 - rho) everywhere inside (rho 0.5, 0.9, 0.99, and a
 *     coloured rho, channel by channel);
 *   - a floor written as two coincident opposite faces (how real scenes
 *     write two-sided faces) reflects like a single front-facing floor,
 *     whichever of the two is added first; rad_vis_first_hit_front sees
 *     the front from both sides.
 * Also: bit-identical results for the same seed with 1 and 3 threads
 * (target mode too), bad input refused, cancellation, an injected
 * allocation failure.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "closed_forms.h"
#include "mem.h"
#include "rad.h"
#include "rad_reference.h"
#include "scene.h"
#include "vis.h"

/* --------------------------------------------------------------- scenes */

typedef struct builder {
	rad_scene *s;
	uint32_t node;
} builder;

static builder scene_begin(void)
{
	builder b;
	rad_error err;
	assert_int_equal(rad_scene_new(&b.s, &err), RAD_OK);
	assert_int_equal(rad_scene_add_node(b.s, "n", &b.node, &err), RAD_OK);
	return b;
}

static uint32_t material(builder *b, const double rho[3], double lum)
{
	const double L[3] = {lum, lum, lum};
	uint32_t id;
	rad_error err;
	assert_int_equal(rad_scene_add_material(b->s, rho, L, &id, &err),
	                 RAD_OK);
	return id;
}

static uint32_t grey(builder *b, double rho, double lum)
{
	const double r[3] = {rho, rho, rho};
	return material(b, r, lum);
}

/* Parallelogram p0, p0+e1, p0+e1+e2, p0+e2; its front is e1 x e2. */
static void quad(builder *b, uint32_t mat, const double p0[3],
                 const double e1[3], const double e2[3])
{
	double p[4][3], tri[18];
	for (int i = 0; i < 3; i++) {
		p[0][i] = p0[i];
		p[1][i] = p0[i] + e1[i];
		p[2][i] = p0[i] + e1[i] + e2[i];
		p[3][i] = p0[i] + e2[i];
	}
	const int idx[6] = {0, 1, 2, 0, 2, 3};
	for (int v = 0; v < 6; v++)
		memcpy(tri + 3 * v, p[idx[v]], sizeof(p[0]));
	rad_error err;
	assert_int_equal(
	        rad_scene_add_triangles(b->s, mat, b->node, tri, 2, &err),
	        RAD_OK);
}

/* Square floor [-h, h]^2 at z = 0; up = 1 faces +z, else -z. */
static void floor_quad(builder *b, uint32_t mat, double h, int up)
{
	const double p0[3] = {-h, -h, 0}, ex[3] = {2 * h, 0, 0},
	             ey[3] = {0, 2 * h, 0};
	if (up)
		quad(b, mat, p0, ex, ey);
	else
		quad(b, mat, p0, ey, ex);
}

/* The six faces of the box [lo, hi], all facing inwards. */
static void box_inward(builder *b, uint32_t mat, const double lo[3],
                       const double hi[3])
{
	double d[3] = {hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]};
	const double ex[3] = {d[0], 0, 0}, ey[3] = {0, d[1], 0},
	             ez[3] = {0, 0, d[2]};
	const double px[3] = {hi[0], lo[1], lo[2]},
	             py[3] = {lo[0], hi[1], lo[2]},
	             pz[3] = {lo[0], lo[1], hi[2]};
	quad(b, mat, lo, ex, ey); /* z = lo, +z */
	quad(b, mat, pz, ey, ex); /* z = hi, -z */
	quad(b, mat, lo, ey, ez); /* x = lo, +x */
	quad(b, mat, px, ez, ey); /* x = hi, -x */
	quad(b, mat, lo, ez, ex); /* y = lo, +y */
	quad(b, mat, py, ex, ez); /* y = hi, -y */
}

static void add_light(builder *b, const rad_light_desc *d)
{
	rad_error err;
	assert_int_equal(rad_scene_add_light(b->s, d, &err), RAD_OK);
}

static rad_scene *scene_commit(builder *b)
{
	rad_error err;
	assert_int_equal(rad_scene_commit(b->s, &err), RAD_OK);
	return b->s;
}

/* ------------------------------------------------------------ estimates */

#define MAXPTS 8

typedef struct result {
	double lux[MAXPTS], se[MAXPTS];
	uint64_t paths[MAXPTS];
} result;

static void estimate(const rad_scene *s, const double *pts, size_t n,
                     uint64_t samples, int threads, result *r)
{
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.samples = samples;
	o.threads = threads;
	rad_error err;
	memset(r, 0, sizeof(*r));
	assert_true(n <= MAXPTS);
	rad_status st = rad_reference_illuminance(s, pts, n, &o, r->lux, r->se,
	                                          r->paths, &err);
	if (st != RAD_OK)
		fail_msg("rad_reference_illuminance: %s", err.msg);
}

static double luma(const double c[3])
{
	return RAD_LUMA_R * c[0] + RAD_LUMA_G * c[1] + RAD_LUMA_B * c[2];
}

/* |lux - want| within 3 standard errors plus slack x want. */
static void expect_close(const char *what, double lux, double se, double want,
                         double slack)
{
	double tol = 3.0 * se + slack * fabs(want) + 1e-12;
	print_message("  %-34s %12.6g lux, want %12.6g (diff %+.3g, "
	              "stderr %.3g = %.3f%%)\n",
	              what, lux, want, lux - want, se,
	              want > 0 ? 100.0 * se / want : 0.0);
	if (!(fabs(lux - want) <= tol))
		fail_msg("%s: %.9g lux, expected %.9g +- %.3g", what, lux, want,
		         tol);
}

/* Float geometry: vertices and normals are stored as floats. */
#define SLACK 1e-5

/* --------------------------------------------------------------- lights */

static void test_point_light_inverse_square(void **state)
{
	(void)state;
	builder b = scene_begin();
	floor_quad(&b, grey(&b, 0.5, 0), 20, 1);
	rad_light_desc L = {.kind = RAD_LIGHT_POINT,
	                    .position = {0, 0, 2},
	                    .intensity = {300, 100, 50}};
	add_light(&b, &L);
	rad_light_desc R = L; /* a ranged light elsewhere, seen by pts 3-4 */
	R.position[0] = 10;
	R.range = 3;
	add_light(&b, &R);
	rad_scene *s = scene_commit(&b);
	/* On the floor facing up: nothing else in the scene reflects onto
	 * the floor, so the estimate is exact. */
	const double pts[] = {0, 0, 0, 0,  0, 1, 1.5, 0, 0, 0,   0, 1, 1, 2, 0,
	                      0, 0, 3, 10, 0, 0, 0,   0, 1, 9.0, 0, 0, 0, 0, 1};
	result r;
	estimate(s, pts, 5, 256, 1, &r);
	double I = luma(L.intensity);
	/* A point light at distance d and angle theta: I cos / d^2. */
	expect_close("under the light", r.lux[0], r.se[0], I / 4, SLACK);
	expect_close("1.5 m aside", r.lux[1], r.se[1],
	             I * 2 / pow(1.5 * 1.5 + 4, 1.5), SLACK);
	expect_close("(1, 2) aside, normal not unit", r.lux[2], r.se[2],
	             I * 2 / pow(1 + 4 + 4, 1.5), SLACK);
	/* Under the ranged light (d = 2 < 3) plus the far one (d ~ 10.2,
	 * beyond no range). */
	double w2 = 1 - pow(2.0 / 3.0, 4);
	double far = I * 2 / pow(100 + 4, 1.5);
	expect_close("under the ranged light", r.lux[3], r.se[3],
	             I / 4 * w2 + far, SLACK);
	/* 1 m aside the ranged light: d = sqrt 5, window 1 - (5/9)^2. */
	expect_close("ranged light, 1 m aside", r.lux[4], r.se[4],
	             I * 2 / pow(5, 1.5) * (1 - 25.0 / 81.0) +
	                     I * 2 / pow(81 + 4, 1.5),
	             SLACK);
	for (int i = 0; i < 5; i++)
		assert_true(r.se[i] <= 1e-9 * r.lux[i]);
	rad_scene_free(s);
}

static double spot_expected(double I, double x, double h, double inner,
                            double outer)
{
	double d2 = x * x + h * h, c = h / sqrt(d2);
	double t = (c - cos(outer)) / (cos(inner) - cos(outer));
	t = t < 0 ? 0 : t > 1 ? 1 : t;
	return I * t * t * c / d2;
}

static void test_spot_and_directional(void **state)
{
	(void)state;
	builder b = scene_begin();
	uint32_t m = grey(&b, 0.5, 0);
	floor_quad(&b, m, 20, 1);
	/* A plate at z = 1 over x in [5, 7], y in [-1, 1], facing up. */
	const double p0[3] = {5, -1, 1}, ex[3] = {2, 0, 0}, ey[3] = {0, 2, 0};
	quad(&b, m, p0, ex, ey);
	rad_light_desc S = {.kind = RAD_LIGHT_SPOT,
	                    .position = {-10, 0, 2},
	                    .direction = {0, 0, -3},
	                    .intensity = {500, 500, 500},
	                    .inner_cone = 0.2,
	                    .outer_cone = 0.5};
	add_light(&b, &S);
	rad_light_desc D = {.kind = RAD_LIGHT_DIRECTIONAL,
	                    .direction = {0.6, 0, -0.8},
	                    .intensity = {1000, 1000, 1000}};
	add_light(&b, &D);
	rad_scene *s = scene_commit(&b);
	/* Spot: points at 0, 0.3, 0.6, 0.9 and 1.2 m from its foot
	 * (angles 0, 0.15, 0.29, 0.42, 0.54 rad: inside, across the
	 * falloff and outside).  Directional: everywhere 800 lux on the
	 * floor, except where the plate shades it (x = 6.75: the ray up
	 * towards the light crosses z = 1 at x = 6). */
	double pts[6 * 7] = {0};
	for (int i = 0; i < 5; i++) {
		pts[6 * i] = -10 + 0.3 * i;
		pts[6 * i + 5] = 1;
	}
	pts[6 * 5] = 6.75;
	pts[6 * 5 + 5] = 1;
	pts[6 * 6] = 3;
	pts[6 * 6 + 1] = 4;
	pts[6 * 6 + 5] = 1;
	result r;
	estimate(s, pts, 7, 256, 1, &r);
	double E_dir = 1000 * 0.8;
	for (int i = 0; i < 5; i++) {
		char what[64];
		snprintf(what, sizeof(what), "spot, %.1f m aside", 0.3 * i);
		expect_close(what, r.lux[i], r.se[i],
		             spot_expected(500, 0.3 * i, 2, 0.2, 0.5) + E_dir,
		             SLACK);
	}
	expect_close("directional, under the plate", r.lux[5], r.se[5], 0, 0);
	/* Spot at (-10,0,2) seen from (3,4,0): outside its cone. */
	expect_close("directional, open floor", r.lux[6], r.se[6], E_dir,
	             SLACK);
	rad_scene_free(s);
}

/* \int_0^inf r dr / ((r^2 + H^2)^1.5 (r^2 + h^2)^2), Simpson on [0, 200]
 * (the tail beyond is below 1e-10 of it for H, h ~ 1). */
static double reflect_integral(double H, double h)
{
	const int n = 200000;
	const double R = 200, dr = R / n;
	double sum = 0;
	for (int i = 0; i <= n; i++) {
		double r = i * dr, r2 = r * r;
		double f = r /
		           (pow(r2 + H * H, 1.5) * (r2 + h * h) * (r2 + h * h));
		sum += f * (i == 0 || i == n ? 1 : i % 2 ? 4 : 2);
	}
	return sum * dr / 3;
}

/* One bounce: a point light 2 m over a floor of reflectance rho, seen
 * by a point 1 m up facing down (the light's own ray does not reach it). */
static double reflected_expected(double I, double rho)
{
	double H = 2, h = 1;
	return 2 * rho * I * H * h * h * reflect_integral(H, h);
}

static void test_point_light_reflected_by_floor(void **state)
{
	(void)state;
	builder b = scene_begin();
	floor_quad(&b, grey(&b, 0.6, 0), 20, 1);
	rad_light_desc L = {.kind = RAD_LIGHT_POINT,
	                    .position = {0, 0, 2},
	                    .intensity = {1000, 1000, 1000}};
	add_light(&b, &L);
	rad_scene *s = scene_commit(&b);
	const double pts[] = {0, 0, 1, 0, 0, -1};
	result r;
	estimate(s, pts, 1, 16384, 1, &r);
	expect_close("floor reflection, 1 m up", r.lux[0], r.se[0],
	             reflected_expected(1000, 0.6), SLACK);
	rad_scene_free(s);
}

/* ---------------------------------------------------------- area source */

/* A square panel of side a centred over the origin at height h, facing
 * down, luminance lum; nothing else in the scene. */
static rad_scene *panel_scene(double a, double h, double lum)
{
	builder b = scene_begin();
	uint32_t m = grey(&b, 0, lum);
	const double p0[3] = {-a / 2, -a / 2, h}, e1[3] = {0, a, 0},
	             e2[3] = {a, 0, 0};
	quad(&b, m, p0, e1, e2);
	return scene_commit(&b);
}

static double panel_expected(double a, double h, double lum, double x, double y,
                             double z)
{
	return M_PI * lum *
	       ff_parallel(-a / 2 - x, a / 2 - x, -a / 2 - y, a / 2 - y, h - z);
}

static void test_area_source_form_factor(void **state)
{
	(void)state;
	rad_scene *s = panel_scene(1.0, 1.0, 1000);
	const double pts[] = {0, 0, 0,   0, 0, 1, 0.8, 0.3,  0,    0, 0, 1,
	                      2, 1, 0.5, 0, 0, 1, 0.1, -0.2, 0.99, 0, 0, 1};
	result r;
	estimate(s, pts, 4, 4096, 2, &r);
	expect_close("under the centre, 1 m", r.lux[0], r.se[0],
	             panel_expected(1, 1, 1000, 0, 0, 0), SLACK);
	expect_close("off centre (0.8, 0.3)", r.lux[1], r.se[1],
	             panel_expected(1, 1, 1000, 0.8, 0.3, 0), SLACK);
	expect_close("outside the footprint", r.lux[2], r.se[2],
	             panel_expected(1, 1, 1000, 2, 1, 0.5), SLACK);
	/* 1 cm under the panel: nearly pi L.  Emitter sampling alone would
	 * give a relative error near 1.5 % here (cos^2 / r^2 peaks at the
	 * foot of the point); the bounce ray finds the panel almost always,
	 * and MIS keeps the error bar near 0.2 %. */
	double want = panel_expected(1, 1, 1000, 0.1, -0.2, 0.99);
	expect_close("1 cm under the panel", r.lux[3], r.se[3], want, SLACK);
	assert_true(r.se[3] < 0.005 * want);
	assert_true(r.se[0] < 0.01 * r.lux[0]);
	rad_scene_free(s);

	/* A 1 cm panel 2 m away: emitter sampling finds it every time. */
	s = panel_scene(0.01, 2.0, 1e6);
	const double far[] = {0, 0, 0, 0, 0, 1, 0.5, 0.5, 0, -1, -1, 4};
	estimate(s, far, 2, 1024, 1, &r);
	want = panel_expected(0.01, 2, 1e6, 0, 0, 0);
	expect_close("1 cm panel, 2 m below", r.lux[0], r.se[0], want, SLACK);
	assert_true(r.se[0] < 0.002 * want);
	/* Tilted normal (-1,-1,4)/sqrt(18): the small panel seen at an
	 * angle; as a point source, cos_panel cos_point A / d^2 to 1e-5. */
	double d2 = 0.5 + 4, d = sqrt(d2);
	double cp = 2 / d, cx = (0.5 + 0.5 + 8) / sqrt(18) / d;
	expect_close("1 cm panel, tilted point", r.lux[1], r.se[1],
	             1e6 * cp * cx * 1e-4 / d2, 1e-4);
	rad_scene_free(s);
}

/* -------------------------------------------------------------- furnace */

static rad_scene *furnace_scene(const double rho[3], double lum)
{
	builder b = scene_begin();
	const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
	box_inward(&b, material(&b, rho, lum), lo, hi);
	return scene_commit(&b);
}

static const double furnace_pts[] = {
        0.5, 0.5, 0.5, 1, 0, 0, 0.05,  0.1, 0.9, 1,  1, -1,
        0.3, 0.6, 0,   0, 0, 1, 0.999, 0.5, 0.5, -1, 0, 0,
};

static void furnace_check(double rho, uint64_t samples, double max_rel)
{
	const double r3[3] = {rho, rho, rho};
	rad_scene *s = furnace_scene(r3, 100);
	result r;
	double t0 = rad_seconds();
	estimate(s, furnace_pts, 4, samples, 2, &r);
	double want = M_PI * 100 / (1 - rho);
	print_message("  furnace rho %g: %llu paths x 4 points in %.3f s\n",
	              rho, (unsigned long long)samples, rad_seconds() - t0);
	for (int i = 0; i < 4; i++) {
		char what[64];
		snprintf(what, sizeof(what), "furnace rho %g, point %d", rho,
		         i);
		expect_close(what, r.lux[i], r.se[i], want, SLACK);
		assert_true(r.se[i] < max_rel * want);
	}
	rad_scene_free(s);
}

static void test_furnace_rho_05(void **state)
{
	(void)state;
	furnace_check(0.5, 2048, 0.02);
}

static void test_furnace_rho_09(void **state)
{
	(void)state;
	furnace_check(0.9, 4096, 0.02);
}

static void test_furnace_rho_099(void **state)
{
	(void)state;
	furnace_check(0.99, 4096, 0.03);
}

/* Channels are traced separately: each converges to pi L / (1 - rho_c). */
static void test_furnace_coloured(void **state)
{
	(void)state;
	const double rho[3] = {0.2, 0.8, 0.5};
	rad_scene *s = furnace_scene(rho, 100);
	result r;
	estimate(s, furnace_pts, 2, 4096, 2, &r);
	double e[3];
	for (int c = 0; c < 3; c++)
		e[c] = M_PI * 100 / (1 - rho[c]);
	for (int i = 0; i < 2; i++)
		expect_close("coloured furnace", r.lux[i], r.se[i], luma(e),
		             SLACK);
	rad_scene_free(s);
}

/* ------------------------------------------------- two-sided coincident */

/*
 * A floor written as a coincident pair of opposite faces, both
 * reflecting; order 0 adds the up-facing one first.  Lit by a point
 * light 2 m up and seen from 1 m up facing down, it must reflect exactly
 * like a single up-facing floor: a bounce ray that stopped at the
 * down-facing twin would be absorbed and darken it.
 */
static rad_scene *twin_floor_scene(int order, int twin)
{
	builder b = scene_begin();
	uint32_t m = grey(&b, 0.6, 0);
	floor_quad(&b, m, 20, order == 0);
	if (twin)
		floor_quad(&b, m, 20, order != 0);
	rad_light_desc L = {.kind = RAD_LIGHT_POINT,
	                    .position = {0, 0, 2},
	                    .intensity = {1000, 1000, 1000}};
	add_light(&b, &L);
	return scene_commit(&b);
}

static void test_coincident_pair_shows_front(void **state)
{
	(void)state;
	const double pts[] = {0, 0, 1, 0, 0, -1};
	double want = reflected_expected(1000, 0.6);
	result one, pair[2];
	rad_vis_thread_init();
	rad_scene *s = twin_floor_scene(0, 0);
	estimate(s, pts, 1, 16384, 1, &one);
	rad_scene_free(s);
	for (int order = 0; order < 2; order++) {
		s = twin_floor_scene(order, 1);
		estimate(s, pts, 1, 16384, 1, &pair[order]);
		/* Both faces of the pair are seen from their fronts. */
		v3 up = v3_make(0, 0, 1), down = v3_make(0, 0, -1);
		const v3 from[2] = {v3_make(0.3, 0.2, 1),
		                    v3_make(0.3, 0.2, -1)};
		for (int k = 0; k < 2; k++) {
			double t;
			int front;
			uint32_t hit = rad_vis_first_hit_front(s->vis, from[k],
			                                       k ? up : down, 0,
			                                       10, &t, &front);
			assert_int_not_equal(hit, UINT32_MAX);
			assert_int_equal(front, 1);
			assert_true(fabs(t - 1) < 1e-5);
			assert_true(v3_dot(rad_poly_normal(&s->polys[hit]),
			                   k ? up : down) < 0);
		}
		rad_scene_free(s);
	}
	expect_close("single floor", one.lux[0], one.se[0], want, SLACK);
	for (int order = 0; order < 2; order++) {
		char what[64];
		snprintf(what, sizeof(what), "coincident pair, order %d",
		         order);
		expect_close(what, pair[order].lux[0], pair[order].se[0], want,
		             SLACK);
		double se = hypot(one.se[0], pair[order].se[0]);
		assert_true(fabs(one.lux[0] - pair[order].lux[0]) <= 3 * se);
	}
}

/* A back face that is not coincident still wins (and absorbs). */
static void test_back_face_in_front_absorbs(void **state)
{
	(void)state;
	builder b = scene_begin();
	uint32_t m = grey(&b, 0.5, 0);
	floor_quad(&b, m, 1, 1);
	/* A down-facing plate 1 cm above the floor. */
	const double p0[3] = {-1, -1, 0.01}, ex[3] = {2, 0, 0},
	             ey[3] = {0, 2, 0};
	quad(&b, m, p0, ey, ex);
	rad_scene *s = scene_commit(&b);
	rad_vis_thread_init();
	double t;
	int front;
	uint32_t hit = rad_vis_first_hit_front(
	        s->vis, v3_make(0, 0, 1), v3_make(0, 0, -1), 0, 10, &t, &front);
	assert_int_not_equal(hit, UINT32_MAX);
	assert_int_equal(front, 0);
	assert_true(fabs(t - 0.99) < 1e-5);
	hit = rad_vis_first_hit_front(s->vis, v3_make(0, 0, 1),
	                              v3_make(0, 0, 1), 0, 10, &t, &front);
	assert_int_equal(hit, UINT32_MAX);
	assert_int_equal(front, 0);
	rad_scene_free(s);
}

/* --------------------------------------------------------- determinism */

/* A closed room with a ceiling panel and a block: occlusion, bounces. */
static rad_scene *room_scene(void)
{
	builder b = scene_begin();
	const double lo[3] = {0, 0, 0}, hi[3] = {4, 3, 2.5};
	box_inward(&b, grey(&b, 0.7, 0), lo, hi);
	uint32_t lamp = grey(&b, 0.0, 2000);
	const double p0[3] = {1.5, 1, 2.49}, e1[3] = {0, 1, 0},
	             e2[3] = {1, 0, 0};
	quad(&b, lamp, p0, e1, e2);
	const double bl[3] = {1, 1, 0}, bh[3] = {2, 2, 1};
	double rho[3] = {0.3, 0.5, 0.2};
	uint32_t blk = material(&b, rho, 0);
	/* The block's faces facing out: the inward box turned inside out
	 * by swapping each face's edges. */
	double d[3] = {1, 1, 1};
	const double ex[3] = {d[0], 0, 0}, ey[3] = {0, d[1], 0},
	             ez[3] = {0, 0, d[2]};
	const double px[3] = {bh[0], bl[1], bl[2]},
	             py[3] = {bl[0], bh[1], bl[2]},
	             pz[3] = {bl[0], bl[1], bh[2]};
	quad(&b, blk, pz, ex, ey);
	quad(&b, blk, bl, ez, ey);
	quad(&b, blk, px, ey, ez);
	quad(&b, blk, bl, ex, ez);
	quad(&b, blk, py, ez, ex);
	rad_light_desc L = {.kind = RAD_LIGHT_SPOT,
	                    .position = {3, 2, 2.3},
	                    .direction = {0, 0, -1},
	                    .intensity = {300, 300, 300},
	                    .inner_cone = 0.3,
	                    .outer_cone = 0.7};
	add_light(&b, &L);
	return scene_commit(&b);
}

static const double room_pts[] = {
        0.5, 0.5, 0,   0, 0, 1,  2.5, 1.5, 0,   0,  0,  1,
        1.5, 1.5, 1,   0, 0, 1,  3.9, 1.5, 1.2, -1, 0,  0,
        3,   2.5, 2.5, 0, 0, -1, 1.5, 2.5, 0.5, 1,  -1, 0,
};

static void run_room(const rad_scene *s, uint64_t samples, double target,
                     int threads, uint64_t seed, result *r)
{
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.samples = samples;
	o.target_error = target;
	o.threads = threads;
	o.seed = seed;
	rad_error err;
	memset(r, 0, sizeof(*r));
	assert_int_equal(rad_reference_illuminance(s, room_pts, 6, &o, r->lux,
	                                           r->se, r->paths, &err),
	                 RAD_OK);
}

static void test_same_seed_same_bits_any_threads(void **state)
{
	(void)state;
	rad_scene *s = room_scene();
	result a, b, c, d;
	run_room(s, 1000, 0, 1, 7, &a);
	run_room(s, 1000, 0, 1, 7, &b);
	run_room(s, 1000, 0, 3, 7, &c);
	run_room(s, 1000, 0, 1, 8, &d);
	assert_memory_equal(&a, &b, sizeof(a));
	assert_memory_equal(&a, &c, sizeof(a));
	assert_memory_not_equal(a.lux, d.lux, sizeof(a.lux));
	for (int i = 0; i < 6; i++) {
		assert_int_equal(a.paths[i], 1000);
		assert_true(a.lux[i] > 0 && a.se[i] > 0);
		/* Another seed: another sample of the same mean. */
		assert_true(fabs(a.lux[i] - d.lux[i]) <=
		            4 * hypot(a.se[i], d.se[i]));
	}
	/* Target mode: rounds are decided from merged results only. */
	run_room(s, 0, 0.03, 1, 7, &a);
	run_room(s, 0, 0.03, 3, 7, &b);
	assert_memory_equal(&a, &b, sizeof(a));
	rad_scene_free(s);
}

static void test_target_error_reached(void **state)
{
	(void)state;
	rad_scene *s = room_scene();
	result r;
	run_room(s, 0, 0.02, 2, 1, &r);
	uint64_t lo = UINT64_MAX, hi = 0;
	for (int i = 0; i < 6; i++) {
		print_message("  point %d: %.6g lux, rel %.4f, %llu paths\n", i,
		              r.lux[i], r.se[i] / r.lux[i],
		              (unsigned long long)r.paths[i]);
		assert_true(r.se[i] <= 0.02 * r.lux[i]);
		lo = r.paths[i] < lo ? r.paths[i] : lo;
		hi = r.paths[i] > hi ? r.paths[i] : hi;
	}
	/* Points of different difficulty get different path counts. */
	assert_true(hi > lo);
	/* The cap holds: at most max_samples, then stop. */
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.target_error = 1e-4;
	o.max_samples = 300;
	rad_error err;
	assert_int_equal(rad_reference_illuminance(s, room_pts, 6, &o, r.lux,
	                                           NULL, r.paths, &err),
	                 RAD_OK);
	for (int i = 0; i < 6; i++)
		assert_int_equal(r.paths[i], 300);
	rad_scene_free(s);
}

/* ------------------------------------------------------------ bad input */

static void expect_refused(const rad_scene *s, const double *pts, size_t n,
                           const rad_ref_options *o, rad_status code,
                           const char *needle)
{
	double lux[4];
	rad_error err = {0};
	assert_int_equal(
	        rad_reference_illuminance(s, pts, n, o, lux, NULL, NULL, &err),
	        code);
	assert_int_equal(err.code, code);
	if (!strstr(err.msg, needle))
		fail_msg("message '%s' lacks '%s'", err.msg, needle);
}

static void test_bad_input_refused(void **state)
{
	(void)state;
	rad_scene *s = panel_scene(1, 1, 100);
	const double nan_pt[] = {0, 0, 0, 0, 0, 1, 0, NAN, 0, 0, 0, 1};
	const double inf_n[] = {0, 0, 0, 0, 0, INFINITY};
	const double zero_n[] = {0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0};
	expect_refused(s, nan_pt, 2, NULL, RAD_ERR_INVALID, "point 1");
	expect_refused(s, inf_n, 1, NULL, RAD_ERR_INVALID, "point 0");
	expect_refused(s, zero_n, 2, NULL, RAD_ERR_INVALID, "zero normal");
	expect_refused(s, NULL, 1, NULL, RAD_ERR_INVALID, "NULL");
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.target_error = 0;
	expect_refused(s, zero_n, 1, &o, RAD_ERR_INVALID, "target_error");
	o.target_error = NAN;
	expect_refused(s, zero_n, 1, &o, RAD_ERR_INVALID, "target_error");
	rad_ref_options_default(&o);
	o.max_samples = 1;
	expect_refused(s, zero_n, 1, &o, RAD_ERR_INVALID, "max_samples");
	rad_ref_options_default(&o);
	o.threads = -1;
	expect_refused(s, zero_n, 1, &o, RAD_ERR_INVALID, "threads");
	/* No points is nothing to do. */
	rad_error err;
	assert_int_equal(rad_reference_illuminance(s, NULL, 0, NULL, NULL, NULL,
	                                           NULL, &err),
	                 RAD_OK);
	rad_scene_free(s);

	builder b = scene_begin(); /* not committed */
	floor_quad(&b, grey(&b, 0.5, 0), 1, 1);
	expect_refused(b.s, zero_n, 1, NULL, RAD_ERR_STATE, "not committed");
	rad_scene_free(b.s);
}

static void test_cancel_and_nomem(void **state)
{
	(void)state;
	rad_scene *s = room_scene();
	static volatile int flag = 1;
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.cancel = &flag;
	o.threads = 2;
	double lux[6];
	rad_error err;
	assert_int_equal(rad_reference_illuminance(s, room_pts, 6, &o, lux,
	                                           NULL, NULL, &err),
	                 RAD_ERR_CANCELLED);
	o.cancel = NULL;
	rad_mem_inject_failure(0);
	rad_status st = rad_reference_illuminance(s, room_pts, 6, &o, lux, NULL,
	                                          NULL, &err);
	rad_mem_inject_failure(-1);
	assert_int_equal(st, RAD_ERR_NOMEM);
	assert_non_null(strstr(err.msg, "out of memory"));
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_point_light_inverse_square),
	        cmocka_unit_test(test_spot_and_directional),
	        cmocka_unit_test(test_point_light_reflected_by_floor),
	        cmocka_unit_test(test_area_source_form_factor),
	        cmocka_unit_test(test_furnace_rho_05),
	        cmocka_unit_test(test_furnace_rho_09),
	        cmocka_unit_test(test_furnace_rho_099),
	        cmocka_unit_test(test_furnace_coloured),
	        cmocka_unit_test(test_coincident_pair_shows_front),
	        cmocka_unit_test(test_back_face_in_front_absorbs),
	        cmocka_unit_test(test_same_seed_same_bits_any_threads),
	        cmocka_unit_test(test_target_error_reached),
	        cmocka_unit_test(test_bad_input_refused),
	        cmocka_unit_test(test_cancel_and_nomem),
	};
	/* LUXRAD_TEST_FILTER=pattern runs a subset (cmocka wildcards). */
	if (getenv("LUXRAD_TEST_FILTER"))
		cmocka_set_test_filter(getenv("LUXRAD_TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
