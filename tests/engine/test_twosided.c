/*
 * test_twosided.c -- two-sided surfaces (rad_surface_desc.two_sided,
 * glTF doubleSided): both faces emit and reflect, each with its own
 * radiosity, and nothing passes through the sheet.
 *
 * References: the closed form of a differential area facing a parallel
 * rectangle (as test_direct.c, derived there) for a sheet that emits on
 * both sides; symmetry for a sheet lit from behind (it must reflect as
 * the same sheet turned to face the light does, and a one-sided sheet so
 * lit must reflect nothing); the Monte Carlo reference for the same scene;
 * and zero light behind a two-sided partition.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

#include "closed_forms.h"
#include "rad.h"
#include "rad_reference.h"

#define SHEET_L 1000.0 /* cd/m2 */

/* The parallelogram p0, p0 + e1, p0 + e1 + e2, p0 + e2 (front e1 x e2)
 * as two triangles. */
static void quad(rad_scene *s, uint32_t mat, uint32_t node, const double p0[3],
                 const double e1[3], const double e2[3], int two_sided)
{
	double t[18];
	for (int c = 0; c < 3; c++) {
		t[c] = p0[c];
		t[3 + c] = p0[c] + e1[c];
		t[6 + c] = p0[c] + e1[c] + e2[c];
		t[9 + c] = p0[c];
		t[12 + c] = p0[c] + e1[c] + e2[c];
		t[15 + c] = p0[c] + e2[c];
	}
	rad_surface_desc d = {mat, node, t, NULL, 2, two_sided};
	assert_int_equal(rad_scene_add_surface(s, &d, NULL), RAD_OK);
}

static uint32_t material(rad_scene *s, double rho, double lum)
{
	const double r[3] = {rho, rho, rho}, l[3] = {lum, lum, lum};
	uint32_t id;
	assert_int_equal(rad_scene_add_material(s, r, l, &id, NULL), RAD_OK);
	return id;
}

static rad_scene *new_scene(uint32_t *node)
{
	rad_scene *s = NULL;
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "sheet", node, NULL), RAD_OK);
	return s;
}

/* Lux at n points (6 doubles each) after the solver converges. */
static void solve_lux(const rad_scene *s, rad_solver_kind kind,
                      const double *pts, size_t n, double *lux)
{
	rad_options o;
	rad_options_default(&o);
	o.solver = kind;
	o.threads = 1;
	rad_solver *sv = NULL;
	rad_error err;
	assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
	for (int i = 0; i < 30; i++)
		assert_int_equal(rad_solver_step(sv, &err), RAD_OK);
	if (rad_solver_query(sv, pts, n, 0, lux, NULL, &err) != RAD_OK)
		fail_msg("query: %s", err.msg);
	rad_solver_free(sv);
}

static void reference_lux(const rad_scene *s, const double *pts, size_t n,
                          double *lux)
{
	rad_ref_options o;
	rad_ref_options_default(&o);
	o.target_error = 0.003;
	rad_error err;
	if (rad_reference_illuminance(s, pts, n, &o, lux, NULL, NULL, &err) !=
	    RAD_OK)
		fail_msg("reference: %s", err.msg);
}

/* A 1 m emitting sheet in z = 0 (front +z): seen from above and below. */
static void emitting_sheet_shines_both_ways(void **state)
{
	(void)state;
	for (int two = 0; two <= 1; two++) {
		uint32_t node;
		rad_scene *s = new_scene(&node);
		const double p0[3] = {0, 0, 0}, e1[3] = {1, 0, 0},
		             e2[3] = {0, 1, 0};
		quad(s, material(s, 0, SHEET_L), node, p0, e1, e2, two);
		assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
		rad_scene_counts c;
		rad_scene_counts_get(s, &c);
		assert_int_equal(c.back_faces, two ? 1 : 0);
		assert_int_equal(c.polygons, two ? 2 : 1);
		assert_int_equal(c.emitters, two ? 2 : 1);
		const double pts[12] = {0.3, 0.2, 0.8,  0, 0, -1,
		                        0.3, 0.2, -0.8, 0, 0, 1};
		double lux[2], ref[2];
		solve_lux(s, RAD_SOLVER_HR, pts, 2, lux);
		reference_lux(s, pts, 2, ref);
		double want =
		        SHEET_L * M_PI * ff_parallel(-0.3, 0.7, -0.2, 0.8, 0.8);
		assert_float_equal(lux[0], want, 0.01 * want);
		assert_float_equal(ref[0], want, 0.02 * want);
		if (two) {
			assert_float_equal(lux[1], want, 0.01 * want);
			assert_float_equal(ref[1], want, 0.02 * want);
		} else {
			assert_float_equal(lux[1], 0.0, 0.0);
			assert_float_equal(ref[1], 0.0, 0.0);
		}
		rad_scene_free(s);
	}
}

/*
 * A 2 m grey sheet in z = 0 and a 100 cd point light 1 m below it.  The
 * sheet faces down (one-sided), or faces up two-sided, or faces up
 * one-sided; a point between them, facing the sheet, sees no light
 * directly: what it gets is reflected.  The first two must agree, the
 * third be dark.
 */
static void sheet_lit_from_behind_reflects(void **state)
{
	(void)state;
	const double pts[6] = {0.4, -0.3, -0.5, 0, 0, 1};
	double lux[3][3];
	for (int k = 0; k < 3; k++) {
		uint32_t node;
		rad_scene *s = new_scene(&node);
		const double down[3][3] = {{-1, -1, 0}, {0, 2, 0}, {2, 0, 0}};
		const double up[3][3] = {{-1, -1, 0}, {2, 0, 0}, {0, 2, 0}};
		const double(*g)[3] = k == 0 ? down : up;
		quad(s, material(s, 0.6, 0), node, g[0], g[1], g[2], k == 1);
		rad_light_desc L = {.kind = RAD_LIGHT_POINT,
		                    .position = {0, 0, -1},
		                    .intensity = {100, 100, 100}};
		assert_int_equal(rad_scene_add_light(s, &L, NULL), RAD_OK);
		assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
		solve_lux(s, RAD_SOLVER_HR, pts, 1, &lux[k][0]);
		solve_lux(s, RAD_SOLVER_RMB, pts, 1, &lux[k][1]);
		reference_lux(s, pts, 1, &lux[k][2]);
		rad_scene_free(s);
	}
	for (int m = 0; m < 3; m++) {
		assert_true(lux[0][m] > 1.0);
		assert_float_equal(lux[1][m], lux[0][m], 0.005 * lux[0][m]);
		assert_float_equal(lux[2][m], 0.0, 0.0);
	}
	/* The solvers against the reference on the two-sided sheet. */
	assert_float_equal(lux[1][0], lux[1][2], 0.03 * lux[1][2]);
	assert_float_equal(lux[1][1], lux[1][2], 0.03 * lux[1][2]);
}

/* A closed 2 x 1 x 1 box of grey walls facing in, cut in two by a
 * two-sided sheet at x = 1; the light is in the left half. */
static void partition_does_not_leak(void **state)
{
	(void)state;
	uint32_t node;
	rad_scene *s = new_scene(&node);
	uint32_t m = material(s, 0.5, 0);
	static const double walls[6][3][3] = {
	        {{0, 0, 0}, {0, 1, 0}, {2, 0, 0}}, /* floor, up */
	        {{0, 0, 1}, {2, 0, 0}, {0, 1, 0}}, /* ceiling, down */
	        {{0, 0, 0}, {2, 0, 0}, {0, 0, 1}}, /* y = 0, +y */
	        {{0, 1, 0}, {0, 0, 1}, {2, 0, 0}}, /* y = 1, -y */
	        {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}}, /* x = 0, +x */
	        {{2, 0, 0}, {0, 1, 0}, {0, 0, 1}}, /* x = 2, -x */
	};
	for (int k = 0; k < 6; k++)
		quad(s, m, node, walls[k][0], walls[k][1], walls[k][2], 0);
	const double p0[3] = {1, 0, 0}, e1[3] = {0, 1, 0}, e2[3] = {0, 0, 1};
	quad(s, m, node, p0, e1, e2, 1);
	rad_light_desc L = {.kind = RAD_LIGHT_POINT,
	                    .position = {0.5, 0.5, 0.5},
	                    .intensity = {50, 50, 50}};
	assert_int_equal(rad_scene_add_light(s, &L, NULL), RAD_OK);
	assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
	const double pts[18] = {1.5,  0.5, 0.01, 0,  0, 1,  /* right floor */
	                        1.01, 0.5, 0.5,  1,  0, 0,  /* on the sheet */
	                        0.99, 0.5, 0.5,  -1, 0, 0}; /* left of it */
	double lux[3], ref[3];
	for (int k = RAD_SOLVER_HR; k <= RAD_SOLVER_RMB; k++) {
		solve_lux(s, (rad_solver_kind)k, pts, 3, lux);
		assert_float_equal(lux[0], 0.0, 0.0);
		assert_float_equal(lux[1], 0.0, 0.0);
		assert_true(lux[2] > 10.0);
	}
	reference_lux(s, pts, 3, ref);
	assert_float_equal(ref[0], 0.0, 0.0);
	assert_float_equal(ref[1], 0.0, 0.0);
	assert_float_equal(lux[2], ref[2], 0.05 * ref[2]);
	/* The back face: the sheet turned over, after every front. */
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.back_faces, 1);
	/* Each back face: a front at its place, turned the other way. */
	int backs = 0;
	for (uint32_t i = 0; i < c.polygons; i++) {
		rad_polygon_desc b, f;
		assert_int_equal(rad_scene_polygon_get(s, i, &b, NULL), RAD_OK);
		if (!b.back_face)
			continue;
		backs++;
		int found = 0;
		for (uint32_t j = 0; j < c.polygons && !found; j++) {
			assert_int_equal(rad_scene_polygon_get(s, j, &f, NULL),
			                 RAD_OK);
			found = !f.back_face && f.area == b.area &&
			        f.normal[0] == -b.normal[0] &&
			        memcmp(f.corners[0], b.corners[0],
			               sizeof(f.corners[0])) == 0;
		}
		assert_true(found);
		assert_float_equal(b.corners[0][0], 1.0, 1e-6); /* x = 1 */
	}
	assert_int_equal(backs, c.back_faces);
	rad_scene_free(s);
}

/*
 * Polygons keep no node id: one record per run of polygons of a node
 * (scene.h, rad_node_run).  Every polygon must still name the node it
 * came from, after triangles are merged into quads, a large floor is cut
 * where a wall stands across it, and back faces are appended; a node
 * whose triangles all are degenerate holds none, and a node may come
 * back after another.  Each node's polygons are at heights of its own.
 */
static void nodes_follow_polygons(void **state)
{
	(void)state;
	rad_scene *s = NULL;
	uint32_t node[4], none;
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	const char *names[4] = {"floor", "wall", "panel", "shelf"};
	for (int k = 0; k < 4; k++)
		assert_int_equal(
		        rad_scene_add_node(s, names[k], &node[k], NULL),
		        RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "sliver", &none, NULL), RAD_OK);
	uint32_t m = material(s, 0.5, 0);
	/* floor (z = 0), cut by the wall standing across it at y = 0 */
	quad(s, m, node[0], (double[]){-5, -5, 0}, (double[]){10, 0, 0},
	     (double[]){0, 10, 0}, 0);
	quad(s, m, node[1], (double[]){-5, 0, 0}, (double[]){0, 0, 3},
	     (double[]){10, 0, 0}, 0);
	const double flat[9] = {0, 0, 1, 1, 1, 1, 2, 2, 1}; /* no area */
	rad_surface_desc d = {m, none, flat, NULL, 1, 0};
	assert_int_equal(rad_scene_add_surface(s, &d, NULL), RAD_OK);
	/* two-sided panels at z = 2, a shelf at z = 1, then a panel again */
	quad(s, m, node[2], (double[]){-1, -1, 2}, (double[]){1, 0, 0},
	     (double[]){0, 1, 0}, 1);
	quad(s, m, node[3], (double[]){2, 2, 1}, (double[]){1, 0, 0},
	     (double[]){0, 1, 0}, 1);
	quad(s, m, node[2], (double[]){1, 1, 2}, (double[]){1, 0, 0},
	     (double[]){0, 1, 0}, 1);
	assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_true(c.polygons_cut >= 1);
	assert_int_equal(c.back_faces, 3);
	int seen[4] = {0, 0, 0, 0};
	for (uint32_t i = 0; i < c.polygons; i++) {
		rad_polygon_desc p;
		assert_int_equal(rad_scene_polygon_get(s, i, &p, NULL), RAD_OK);
		double zmin = p.corners[0][2], zmax = zmin;
		for (int k = 1; k < p.ncorners; k++) {
			zmin = fmin(zmin, p.corners[k][2]);
			zmax = fmax(zmax, p.corners[k][2]);
		}
		int want = zmax > zmin ? 1 : zmin == 0 ? 0 : zmin == 1 ? 3 : 2;
		assert_int_equal(p.node, node[want]);
		assert_string_equal(rad_scene_node_name(s, p.node),
		                    names[want]);
		seen[want]++;
	}
	/* the floor in pieces, the wall whole; each panel and the shelf a
	 * quad with its back face */
	assert_true(seen[0] >= 2);
	assert_int_equal(seen[1], 1);
	assert_int_equal(seen[2], 4);
	assert_int_equal(seen[3], 2);
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(emitting_sheet_shines_both_ways),
	        cmocka_unit_test(sheet_lit_from_behind_reflects),
	        cmocka_unit_test(partition_does_not_leak),
	        cmocka_unit_test(nodes_follow_polygons),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
