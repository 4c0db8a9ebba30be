/*
 * test_real.c -- lux in rooms that other people made, against the
 * independent estimator.
 *
 * The RenderPark scenes in ../shared/scenes/real (beside the clone, as CI
 * has them) are furnished rooms written by another program for another
 * renderer: the Graz office (53,856 triangles) and the hospital room
 * (83,466 triangles, half of them repeated, saturated colours with a
 * channel at 0.999).  hr and rmb are run at the defaults a user gets and
 * queried at the validation study's points (scenes/validation, NAME.points);
 * luxrad-reference gives the same points to 0.5 % (one standard error).
 *
 * The accuracy target is 2 % at every point, and these rooms do not meet
 * it yet (README, Validation).  So this test is a ratchet, not the
 * target: each solver's mean and worst relative error must stay within
 * the level last measured here (the tables below: what this test printed
 * at the commit that set them, plus half a point on the mean and two to
 * three on the worst point), and the tables are tightened as the solvers
 * improve.  The reference is deterministic for its seed and thread
 * count, so the comparison does not move unless the code does.  What it guards
 * is that no change to the engine makes a real room worse unseen, which every
 * other test here, built on scenes of our own, could miss.
 */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "rad.h"
#include "rad_reference.h"
#include "sceneio.h"

#define MAXPTS 128
#define REAL_DIR LUXRAD_SOURCE_DIR "/../shared/scenes/real/renderpark/"
#define POINTS_DIR LUXRAD_SOURCE_DIR "/scenes/validation/"

/* The level reached: mean and worst |relative error| at the defaults. */
typedef struct level {
	rad_solver_kind kind;
	double mean, worst;
} level;

/* Read 'x y z nx ny nz' lines ('#' comments) into pts; returns the count. */
static int read_points(const char *path, double pts[][6])
{
	FILE *f = fopen(path, "r");
	if (!f)
		fail_msg("%s: %s", path, strerror(errno));
	char line[256];
	int n = 0;
	while (fgets(line, sizeof(line), f)) {
		char *h = strchr(line, '#');
		if (h)
			*h = '\0';
		double *p = pts[n];
		int k = sscanf(line, "%lf %lf %lf %lf %lf %lf", &p[0], &p[1],
		               &p[2], &p[3], &p[4], &p[5]);
		if (k <= 0)
			continue;
		if (k != 6 || n == MAXPTS - 1) {
			fclose(f);
			fail_msg("%s: bad line or too many points", path);
		}
		n++;
	}
	fclose(f);
	return n;
}

static void hold_room(const char *scene, const char *points,
                      const level *levels, int nlevels)
{
	char path[512];
	snprintf(path, sizeof(path), "%s%s", REAL_DIR, scene);
	rad_scene *s = NULL;
	rad_error err;
	if (sio_load_file(path, &s, NULL, &err))
		fail_msg("%s: %s (the real scenes are read from ../shared "
		         "beside the clone)",
		         path, err.msg);
	static double pts[MAXPTS][6];
	snprintf(path, sizeof(path), "%s%s", POINTS_DIR, points);
	int n = read_points(path, pts);
	double ref[MAXPTS], sd[MAXPTS], lux[MAXPTS];
	rad_ref_options ro;
	rad_ref_options_default(&ro);
	ro.target_error = 0.005;
	ro.threads = 2;
	assert_int_equal(rad_reference_illuminance(s, &pts[0][0], (size_t)n,
	                                           &ro, ref, sd, NULL, &err),
	                 RAD_OK);
	for (int l = 0; l < nlevels; l++) {
		rad_options o;
		rad_options_default(&o);
		o.solver = levels[l].kind;
		o.threads = 2;
		rad_solver *sv = NULL;
		assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
		assert_int_equal(rad_solver_converge(sv, 0, 200, &err), RAD_OK);
		assert_int_equal(rad_solver_query(sv, &pts[0][0], (size_t)n, 0,
		                                  lux, NULL, &err),
		                 RAD_OK);
		double sum = 0, worst = 0;
		for (int i = 0; i < n; i++) {
			double e = (lux[i] - ref[i]) / ref[i];
			sum += fabs(e);
			if (fabs(e) > fabs(worst))
				worst = e;
		}
		const char *name = rad_solver_kind_name(levels[l].kind);
		print_message("%s %s: mean %.2f %% (level %.2f), worst %+.2f "
		              "%% (level %.2f), %d points\n",
		              scene, name, 100 * sum / n, 100 * levels[l].mean,
		              100 * worst, 100 * levels[l].worst, n);
		assert_true(sum / n <= levels[l].mean);
		assert_true(fabs(worst) <= levels[l].worst);
		rad_solver_free(sv);
	}
	rad_scene_free(s);
}

static void test_graz_office(void **state)
{
	(void)state;
	static const level lv[] = {{RAD_SOLVER_HR, 0.031, 0.20},
	                           {RAD_SOLVER_RMB, 0.054, 0.25}};
	hold_room("graz.gltf", "graz.points", lv, 2);
}

static void test_hospital_room(void **state)
{
	(void)state;
	static const level lv[] = {{RAD_SOLVER_HR, 0.057, 0.16},
	                           {RAD_SOLVER_RMB, 0.107, 0.31}};
	hold_room("hospital.gltf", "hospital.points", lv, 2);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_graz_office),
	        cmocka_unit_test(test_hospital_room),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
