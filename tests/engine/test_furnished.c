/*
 * test_furnished.c -- lux on a furnished room against the independent
 * estimator, not against another luxrad solver.
 *
 * scenes/office.gltf (desk, chair, window opening, two ceiling panels and
 * a desk lamp) is solved by hr and rmb with nothing set (the defaults a
 * user gets) and queried on a 0.8 m work plane; luxrad-reference's path
 * tracer gives the same points with a standard error s per point.  Each
 * point must lie within the default accuracy target (2 %) plus 3 s of
 * the reference.  (error_lux is not held to it here: it leaves out most
 * of the solution's own error and covers 7 of these 20 points.)
 *
 * Points 2 cm from two walls on the floor are left out: there both
 * solvers read 2-3.5 % high (the walls' leaves are brighter on average
 * than near the corner), a miss the validation study reports
 * (tests/bench/validate.sh), not one this test hides under a wider bound.
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

#include "gltf.h"
#include "rad.h"

#define NX 5
#define NZ 4
#define NPTS (NX * NZ)
#define TARGET 0.02 /* the default accuracy (RAD_ACCURACY_DEFAULT) */

static void work_plane(double pts[NPTS][6])
{
	for (int i = 0; i < NX; i++)
		for (int j = 0; j < NZ; j++) {
			double *p = pts[i * NZ + j];
			p[0] = 0.4 + i * 0.8;
			p[1] = 0.8;
			p[2] = 0.4 + j * 2.2 / 3;
			p[3] = 0;
			p[4] = 1;
			p[5] = 0;
		}
}

static rad_scene *load_office(void)
{
	const char *path = LUXRAD_SOURCE_DIR "/scenes/office.gltf";
	rad_scene *s = NULL;
	rad_error err;
	if (rad_gltf_load_file(path, &s, NULL, &err))
		fail_msg("load %s: %s", path, err.msg);
	return s;
}

static void check_solver(const rad_scene *s, rad_solver_kind kind,
                         const double pts[NPTS][6], const double ref[NPTS],
                         const double sd[NPTS])
{
	rad_options o;
	rad_options_default(&o);
	o.solver = kind;
	o.threads = 2;
	rad_solver *sv = NULL;
	rad_error err;
	assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
	assert_int_equal(rad_solver_converge(sv, 0, 200, &err), RAD_OK);
	double lux[NPTS], el[NPTS];
	assert_int_equal(
	        rad_solver_query(sv, &pts[0][0], NPTS, 0, lux, el, &err),
	        RAD_OK);
	double worst = 0;
	for (int i = 0; i < NPTS; i++) {
		double e = (lux[i] - ref[i]) / ref[i];
		print_message("%s point %2d: %8.2f lux, reference %8.2f +- "
		              "%.2f, %+.2f %%, error_lux %.2f\n",
		              rad_solver_kind_name(kind), i, lux[i], ref[i],
		              sd[i], 100 * e, el[i]);
		if (fabs(e) > fabs(worst))
			worst = e;
		assert_true(fabs(lux[i] - ref[i]) <=
		            TARGET * ref[i] + 3 * sd[i]);
	}
	print_message("%s: worst %+.2f %%\n", rad_solver_kind_name(kind),
	              100 * worst);
	rad_solver_free(sv);
}

static void test_office_work_plane(void **state)
{
	(void)state;
	rad_scene *s = load_office();
	double pts[NPTS][6], ref[NPTS], sd[NPTS];
	work_plane(pts);
	rad_ref_options ro;
	rad_ref_options_default(&ro);
	ro.target_error = 0.004;
	ro.threads = 2;
	rad_error err;
	assert_int_equal(rad_reference_illuminance(s, &pts[0][0], NPTS, &ro,
	                                           ref, sd, NULL, &err),
	                 RAD_OK);
	check_solver(s, RAD_SOLVER_HR, pts, ref, sd);
	check_solver(s, RAD_SOLVER_RMB, pts, ref, sd);
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_office_work_plane),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
