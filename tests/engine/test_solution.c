/*
 * test_solution.c -- published solutions (rad_solution_*):
 *  - a solution answers exactly what its solver answered when it was
 *    taken (same lux, same leaves), for every solver;
 *  - it stays unchanged while the solver steps on;
 *  - save/load round trips bit for bit; bytes from another scene, a
 *    truncated or damaged file are refused with a message, and thousands
 *    of random mutations never crash (CI runs this under ASan);
 *  - its memory is counted under "solution" and returns to zero.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "rad.h"
#include "sceneio.h"

#define NPTS 6

static rad_scene *load_cornell(void)
{
	rad_scene *s = NULL;
	rad_error err;
	if (sio_load_file(LUXRAD_SOURCE_DIR "/scenes/cornell.gltf", &s, NULL,
	                  &err) != RAD_OK)
		fail_msg("load: %s", err.msg);
	return s;
}

/* Points inside the Cornell box, facing every way. */
static void make_points(const rad_scene *s, double pts[NPTS * 6])
{
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	for (int i = 0; i < NPTS; i++) {
		double *p = pts + 6 * i;
		for (int k = 0; k < 3; k++)
			p[k] = lo[k] + (0.2 + 0.12 * i) * (hi[k] - lo[k]);
		p[3] = p[4] = p[5] = 0;
		p[3 + i % 3] = (i & 1) ? 1 : -1;
	}
}

typedef struct leaf_sum {
	size_t n;
	double b, e;
} leaf_sum;

static void on_leaf(void *ud, uint32_t node, const double p[4][3], int nv,
                    const double B[3], const double I[3])
{
	leaf_sum *a = ud;
	(void)node, (void)p, (void)nv;
	a->n++;
	a->b += B[0] + B[1] + B[2];
	a->e += I[0] + I[1] + I[2];
}

static rad_solver *new_solver(rad_scene *s, rad_solver_kind kind)
{
	rad_options o;
	rad_options_default(&o);
	o.solver = kind;
	o.threads = 2;
	o.eps = 1e-3;
	o.mesh_edge_rel = 0.15; /* matrix, progressive: a coarse mesh */
	rad_solver *sv = NULL;
	rad_error err;
	if (rad_solver_new(s, &o, &sv, &err) != RAD_OK)
		fail_msg("solver: %s", err.msg);
	return sv;
}

static void check_kind(rad_solver_kind kind)
{
	rad_scene *s = load_cornell();
	rad_solver *sv = new_solver(s, kind);
	rad_error err;
	for (int i = 0; i < 2; i++)
		assert_int_equal(rad_solver_step(sv, &err), RAD_OK);
	double pts[NPTS * 6], a[NPTS], b[NPTS], c[NPTS];
	make_points(s, pts);
	assert_int_equal(rad_solver_illuminance(sv, pts, NPTS, a, &err),
	                 RAD_OK);
	leaf_sum la = {0}, lb = {0}, lc = {0};
	rad_solver_leaves(sv, on_leaf, &la);

	rad_solution *sol = NULL;
	assert_int_equal(rad_solution_new(sv, &sol, &err), RAD_OK);
	assert_int_equal(rad_solution_iteration(sol), 2);
	assert_int_equal(rad_solution_illuminance(sol, pts, NPTS, b, &err),
	                 RAD_OK);
	rad_solution_leaves(sol, on_leaf, &lb);
	for (int i = 0; i < NPTS; i++) {
		assert_true(a[i] > 0);
		assert_memory_equal(&a[i], &b[i], sizeof(double));
	}
	assert_int_equal(la.n, lb.n);
	assert_memory_equal(&la.b, &lb.b, sizeof(double));
	assert_memory_equal(&la.e, &lb.e, sizeof(double));
	rad_mem_report m;
	rad_solution_memory(sol, &m);
	assert_true(m.bytes[RAD_MEM_SOLUTION] > 0);
	assert_int_equal(m.total, m.bytes[RAD_MEM_SOLUTION]);

	/* The solver moves on; the solution does not. */
	assert_int_equal(rad_solver_step(sv, &err), RAD_OK);
	assert_int_equal(rad_solution_illuminance(sol, pts, NPTS, c, &err),
	                 RAD_OK);
	assert_memory_equal(b, c, sizeof b);

	/* Bytes round trip. */
	unsigned char *bytes = NULL;
	size_t len = 0;
	assert_int_equal(rad_solution_save(sol, &bytes, &len, &err), RAD_OK);
	rad_solution *back = NULL;
	if (rad_solution_load(s, bytes, len, &back, &err) != RAD_OK)
		fail_msg("load: %s", err.msg);
	assert_int_equal(rad_solution_iteration(back), 2);
	assert_int_equal(rad_solution_illuminance(back, pts, NPTS, c, &err),
	                 RAD_OK);
	assert_memory_equal(b, c, sizeof b);
	rad_solution_leaves(back, on_leaf, &lc);
	assert_int_equal(lc.n, lb.n);
	rad_solution_free(back);
	free(bytes);
	rad_solution_free(sol);
	rad_solver_free(sv);
	rad_scene_free(s);
}

static void test_solution_matches_hr(void **state)
{
	(void)state;
	check_kind(RAD_SOLVER_HR);
}

static void test_solution_matches_rmb(void **state)
{
	(void)state;
	check_kind(RAD_SOLVER_RMB);
}

static void test_solution_matches_matrix(void **state)
{
	(void)state;
	check_kind(RAD_SOLVER_MATRIX);
}

static void test_solution_matches_progressive(void **state)
{
	(void)state;
	check_kind(RAD_SOLVER_PROGRESSIVE);
}

/* A solution before the first step is valid: emission only. */
static void test_solution_before_first_step(void **state)
{
	(void)state;
	rad_scene *s = load_cornell();
	rad_solver *sv = new_solver(s, RAD_SOLVER_HR);
	rad_solution *sol = NULL;
	rad_error err;
	assert_int_equal(rad_solution_new(sv, &sol, &err), RAD_OK);
	assert_int_equal(rad_solution_iteration(sol), 0);
	double pts[NPTS * 6], lux[NPTS];
	make_points(s, pts);
	assert_int_equal(rad_solution_illuminance(sol, pts, NPTS, lux, &err),
	                 RAD_OK);
	for (int i = 0; i < NPTS; i++)
		assert_true(isfinite(lux[i]) && lux[i] >= 0);
	rad_solution_free(sol);
	rad_solver_free(sv);
	rad_scene_free(s);
}

static unsigned char *saved(rad_scene *s, size_t *len)
{
	rad_solver *sv = new_solver(s, RAD_SOLVER_HR);
	rad_error err;
	assert_int_equal(rad_solver_step(sv, &err), RAD_OK);
	rad_solution *sol = NULL;
	assert_int_equal(rad_solution_new(sv, &sol, &err), RAD_OK);
	unsigned char *b = NULL;
	assert_int_equal(rad_solution_save(sol, &b, len, &err), RAD_OK);
	rad_solution_free(sol);
	rad_solver_free(sv);
	return b;
}

static void expect_refused(rad_scene *s, const void *b, size_t len,
                           const char *what)
{
	rad_solution *sol = (rad_solution *)1;
	rad_error err = {0};
	assert_int_equal(rad_solution_load(s, b, len, &sol, &err),
	                 RAD_ERR_INVALID);
	assert_null(sol);
	if (!strstr(err.msg, what))
		fail_msg("expected '%s' in '%s'", what, err.msg);
}

static void test_solution_bad_bytes_refused(void **state)
{
	(void)state;
	rad_scene *s = load_cornell();
	size_t len;
	unsigned char *b = saved(s, &len);
	expect_refused(s, b, 10, "shorter than a header");
	expect_refused(s, b, len - 1, "truncated");
	unsigned char *c = malloc(len);
	memcpy(c, b, len);
	c[0] ^= 0xff;
	expect_refused(s, c, len, "magic");
	/* The last inner cluster's model ends where the cluster order
	 * (a uint32_t per polygon) starts: a NaN in its q. */
	memcpy(c, b, len);
	rad_scene_counts n;
	rad_scene_counts_get(s, &n);
	float nan = NAN;
	memcpy(c + len - n.polygons * sizeof(uint32_t) - sizeof(float), &nan,
	       sizeof nan);
	expect_refused(s, c, len, "model is damaged");
	/* The first sibling run's record (hier.h, Runs) follows the
	 * elements: a header of ten uint32_t (the record size at 8, the
	 * polygons at 16, the elements at 20) and a uint64_t, then the
	 * elements; the run's path (4 bytes after its polygon) names a
	 * quarter no split made. */
	uint32_t esize, npolys, nelems;
	memcpy(&esize, b + 8, sizeof esize);
	memcpy(&npolys, b + 16, sizeof npolys);
	memcpy(&nelems, b + 20, sizeof nelems);
	assert_true(nelems > npolys); /* one step of hr splits some */
	size_t run = 48 + (size_t)nelems * esize;
	memcpy(c, b, len);
	c[run + 4] ^= 1;
	expect_refused(s, c, len, "are not its quarters");
	memcpy(c, b, len);
	c[run] ^= 1; /* its polygon */
	expect_refused(s, c, len, "are not its quarters");
	free(c);

	/* Another scene (a box) with the Cornell box's bytes. */
	rad_scene *o = NULL;
	rad_error err;
	assert_int_equal(rad_scene_new(&o, &err), RAD_OK);
	double r[3] = {0.5, 0.5, 0.5}, l[3] = {1, 1, 1};
	uint32_t mat, node;
	assert_int_equal(rad_scene_add_material(o, r, l, &mat, &err), RAD_OK);
	assert_int_equal(rad_scene_add_node(o, "t", &node, &err), RAD_OK);
	double t[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
	assert_int_equal(rad_scene_add_triangles(o, mat, node, t, 1, &err),
	                 RAD_OK);
	assert_int_equal(rad_scene_commit(o, &err), RAD_OK);
	expect_refused(o, b, len, "another scene");
	rad_scene_free(o);
	free(b);
	rad_scene_free(s);
}

/* Random damage: refused, or loaded and queryable; never a crash. */
static void test_solution_mutations_never_crash(void **state)
{
	(void)state;
	rad_scene *s = load_cornell();
	size_t len;
	unsigned char *b = saved(s, &len);
	unsigned char *c = malloc(len);
	double pts[NPTS * 6], lux[NPTS];
	make_points(s, pts);
	uint64_t x = 88172645463325252ull;
	int refused = 0, loaded = 0;
	for (int it = 0; it < 3000; it++) {
		memcpy(c, b, len);
		int flips = 1 + it % 4;
		for (int k = 0; k < flips; k++) {
			x ^= x << 13, x ^= x >> 7, x ^= x << 17;
			/* Skip the header most of the time: reach the records.
			 */
			size_t at = it % 5 ? 48 + x % (len - 48) : x % len;
			c[at] ^= (unsigned char)(1u << (x >> 40) % 8);
		}
		rad_solution *sol = NULL;
		rad_error err;
		if (rad_solution_load(s, c, len, &sol, &err) != RAD_OK) {
			refused++;
			continue;
		}
		loaded++;
		assert_int_equal(
		        rad_solution_illuminance(sol, pts, NPTS, lux, &err),
		        RAD_OK);
		rad_solution_free(sol);
	}
	print_message("mutations: %d refused, %d loaded and queried\n", refused,
	              loaded);
	assert_true(refused > 0);
	free(c);
	free(b);
	rad_scene_free(s);
}

static void test_scene_node_names(void **state)
{
	(void)state;
	rad_scene *s = load_cornell();
	rad_scene_counts n;
	rad_scene_counts_get(s, &n);
	assert_true(n.nodes > 0);
	int named = 0;
	for (uint32_t i = 0; i < n.nodes; i++)
		named += rad_scene_node_name(s, i)[0] != 0;
	assert_true(named > 0);
	assert_string_equal(rad_scene_node_name(s, n.nodes), "");
	assert_string_equal(rad_scene_node_name(NULL, 0), "");
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_solution_matches_hr),
	        cmocka_unit_test(test_solution_matches_rmb),
	        cmocka_unit_test(test_solution_matches_matrix),
	        cmocka_unit_test(test_solution_matches_progressive),
	        cmocka_unit_test(test_solution_before_first_step),
	        cmocka_unit_test(test_solution_bad_bytes_refused),
	        cmocka_unit_test(test_solution_mutations_never_crash),
	        cmocka_unit_test(test_scene_node_names),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
