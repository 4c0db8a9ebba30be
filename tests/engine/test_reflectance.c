/*
 * test_reflectance.c -- triangles with their own reflectance (textured
 * surfaces, rad_scene_add_triangles_rho): checked input, quads that take
 * the area-weighted mean, materials shared by value and only those used
 * kept, and memory that returns to zero.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

#include "rad.h"

/* A unit square in the y = 0 plane, facing +y, as two triangles. */
static const double square[18] = {0, 0, 0, 0, 0, 1, 1, 0, 1,
                                  0, 0, 0, 1, 0, 1, 1, 0, 0};

static rad_scene *scene_with(uint32_t *mat, uint32_t *node)
{
	rad_scene *s = NULL;
	const double grey[3] = {0.5, 0.5, 0.5}, dark[3] = {0, 0, 0};
	assert_int_equal(rad_scene_new(&s, NULL), RAD_OK);
	assert_int_equal(rad_scene_add_material(s, grey, dark, mat, NULL),
	                 RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "floor", node, NULL), RAD_OK);
	return s;
}

static void polygon(const rad_scene *s, uint32_t i, rad_polygon_desc *p)
{
	assert_int_equal(rad_scene_polygon_get(s, i, p, NULL), RAD_OK);
}

static void quad_takes_the_mean(void **state)
{
	(void)state;
	uint32_t m, n;
	rad_scene *s = scene_with(&m, &n);
	const double rho[6] = {0.2, 0.4, 0.1, 0.6, 0.8, 0.3};
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square, rho, 2, NULL),
	        RAD_OK);
	assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.polygons, 1);
	assert_int_equal(c.quads, 1);
	assert_int_equal(c.materials, 1); /* the unused ones are gone */
	rad_polygon_desc p;
	polygon(s, 0, &p);
	assert_int_equal(p.ncorners, 4);
	assert_float_equal(p.area, 1.0, 1e-6);
	assert_float_equal(p.reflectance[0], 0.4, 1e-6);
	assert_float_equal(p.reflectance[1], 0.6, 1e-6);
	assert_float_equal(p.reflectance[2], 0.2, 1e-6);
	assert_float_equal(p.normal[1], 1.0, 1e-6);
	rad_scene_free(s);
}

static void plain_and_textured_stay_apart(void **state)
{
	(void)state;
	uint32_t m, n;
	rad_scene *s = scene_with(&m, &n);
	const double rho[3] = {0.5, 0.5, 0.5}; /* equal to the material's */
	assert_int_equal(rad_scene_add_triangles(s, m, n, square, 1, NULL),
	                 RAD_OK);
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square + 9, rho, 1, NULL),
	        RAD_OK);
	assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.polygons, 2);  /* not merged: other sources */
	assert_int_equal(c.materials, 1); /* but one value, shared */
	rad_scene_free(s);
}

/* Many distinct values go through the hash; equal ones share. */
static void many_values_share_by_value(void **state)
{
	(void)state;
	uint32_t m, n;
	rad_scene *s = scene_with(&m, &n);
	enum { N = 3000 };
	static double xyz[9 * N], rho[3 * N];
	for (int i = 0; i < N; i++) {
		const double t[9] = {i * 2.0, 0,           0, i * 2.0, 0,
		                     1,       i * 2.0 + 1, 0, 0};
		for (int k = 0; k < 9; k++)
			xyz[9 * i + k] = t[k];
		for (int c = 0; c < 3; c++)
			rho[3 * i + c] = (i % 1000) / 1000.0;
	}
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, xyz, rho, N, NULL),
	        RAD_OK);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.materials, 1000); /* 0.5 is the base's own */
	assert_int_equal(rad_scene_commit(s, NULL), RAD_OK);
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.polygons, N);
	assert_int_equal(c.materials, 1000);
	for (uint32_t i = 0; i < N; i += 997) {
		rad_polygon_desc p;
		polygon(s, i, &p);
		assert_float_equal(p.reflectance[0], (i % 1000) / 1000.0, 1e-7);
	}
	rad_mem_report r;
	rad_scene_memory(s, &r);
	assert_true(r.bytes[RAD_MEM_MATERIALS] >= 1000 * 24);
	assert_int_equal(r.bytes[RAD_MEM_SCRATCH], 0);
	rad_scene_free(s);
}

static void bad_reflectance_refused(void **state)
{
	(void)state;
	uint32_t m, n;
	rad_scene *s = scene_with(&m, &n);
	rad_error err;
	const double one[3] = {0.5, 1.0, 0.5}, nan[3] = {0.5, NAN, 0.5};
	const double neg[3] = {-0.1, 0.5, 0.5};
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square, one, 1, &err),
	        RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "reflectance"));
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square, nan, 1, &err),
	        RAD_ERR_INVALID);
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square, neg, 1, &err),
	        RAD_ERR_INVALID);
	assert_int_equal(
	        rad_scene_add_triangles_rho(s, m, n, square, NULL, 1, &err),
	        RAD_ERR_INVALID);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.triangles_in, 0); /* nothing half-added */
	rad_polygon_desc p;
	assert_int_equal(rad_scene_polygon_get(s, 0, &p, &err), RAD_ERR_STATE);
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(quad_takes_the_mean),
	        cmocka_unit_test(plain_and_textured_stay_apart),
	        cmocka_unit_test(many_values_share_by_value),
	        cmocka_unit_test(bad_reflectance_refused),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
