/*
 * test_scene.c -- the committed sample scenes and luxrad-scenegen, checked
 * through the importer the daemon uses (sio_load).
 *
 * The samples (scenes/cornell.gltf, scenes/office.gltf) must load with the
 * counts their README promises: triangles in, polygons after the engine's
 * parallelogram merging, shared materials, emitters, lights and bounds.
 * The generator is a separate program, so it is driven as a user would:
 * exec'd into a temporary file that is then loaded.  That checks the
 * analytic scenes (box, scaled room), the triangle target of `field`, the
 * study scenes against the report's polygon counts, determinism, and the
 * exit codes of misuse.  Every load also checks that no triangle was
 * skipped as degenerate or non-finite.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>

#include <cmocka.h>

#include <fcntl.h>
#include <math.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "sceneio.h"

#define SCENEGEN LUXRAD_BINARY_DIR "/luxrad-scenegen"

extern char **environ;

/* Whole file, or NULL (the message does not matter to the callers). */
static unsigned char *read_all(const char *path, size_t *len)
{
	unsigned char *buf;
	rad_error err;
	return sio_file_read(path, &buf, len, &err) == RAD_OK ? buf : NULL;
}

/* Load a scene file, fail the test on any error or skipped triangle. */
static rad_scene *load(const char *path, rad_scene_counts *c)
{
	rad_scene *s = NULL;
	rad_error err = {0};
	rad_status st = sio_load_file(path, &s, NULL, &err);
	if (st != RAD_OK)
		fail_msg("%s: %s", path, err.msg);
	rad_scene_counts_get(s, c);
	assert_int_equal(c->triangles_nonfinite, 0);
	assert_int_equal(c->triangles_degenerate, 0);
	return s;
}

static void assert_bounds(const rad_scene *s, const double lo[3],
                          const double hi[3], double tol)
{
	double l[3], h[3];
	rad_scene_bounds(s, l, h);
	for (int a = 0; a < 3; a++) {
		if (fabs(l[a] - lo[a]) > tol || fabs(h[a] - hi[a]) > tol)
			fail_msg("axis %d: bounds %g..%g, expected %g..%g", a,
			         l[a], h[a], lo[a], hi[a]);
	}
}

/* Run the generator with args (NULL-terminated, without -o); returns its
 * exit status, -1 if it did not exit normally.  quiet: no output. */
static int run_gen(const char *const *args, const char *out, int quiet)
{
	const char *argv[32] = {SCENEGEN};
	int n = 1;
	while (*args && n < 28)
		argv[n++] = *args++;
	if (out) {
		argv[n++] = "-o";
		argv[n++] = out;
	}
	argv[n] = NULL;
	posix_spawn_file_actions_t fa;
	posix_spawn_file_actions_init(&fa);
	for (int fd = 1; quiet && fd <= 2; fd++)
		posix_spawn_file_actions_addopen(&fa, fd, "/dev/null", O_WRONLY,
		                                 0);
	pid_t pid;
	int st = posix_spawn(&pid, SCENEGEN, &fa, NULL, (char *const *)argv,
	                     environ);
	posix_spawn_file_actions_destroy(&fa);
	if (st != 0) /* test_scene does not build the generator itself */
		fail_msg("cannot run %s: %s (build target luxrad-scenegen)",
		         SCENEGEN, strerror(st));
	assert_int_equal(waitpid(pid, &st, 0), pid);
	return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

/* A fresh temporary path ending in .glb (the generator picks GLB). */
static void temp_path(char path[64])
{
	strcpy(path, "/tmp/luxrad-test-scene-XXXXXX.glb");
	int fd = mkstemps(path, 4);
	assert_true(fd >= 0);
	close(fd);
}

/* Generate into a temporary file and load it; the file is removed. */
static rad_scene *generate(const char *const *args, rad_scene_counts *c)
{
	char path[64];
	temp_path(path);
	int rc = run_gen(args, path, 0);
	if (rc != 0) {
		unlink(path);
		fail_msg("%s %s: exit status %d", SCENEGEN, args[0], rc);
	}
	rad_scene *s = load(path, c);
	unlink(path);
	return s;
}

/*
 * The published Cornell box is out of square: the floor, back and left
 * walls and the two block tops are not parallelograms and stay two
 * triangles each; ceiling, right wall, light and the 8 block sides merge
 * (21 polygons).  Then the blocks standing on the floor cut its two
 * triangles along the lines of their sides (conform.c): 51 in all.
 */
static void cornell_sample_matches_published_box(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s = load(LUXRAD_SOURCE_DIR "/scenes/cornell.gltf", &c);
	assert_int_equal(c.triangles_in, 32);
	assert_int_equal(c.quads, 11);
	assert_int_equal(c.polygons, 51);
	assert_int_equal(c.polygons_cut, 2);
	assert_int_equal(c.materials, 4); /* white, red, green, light */
	assert_int_equal(c.emitters, 1);
	assert_int_equal(c.lights, 0);
	assert_bounds(s, (double[]){0, 0, 0}, (double[]){0.556, 0.5488, 0.5592},
	              1e-6);
	rad_scene_free(s);
}

static void cornell_square_merges_all_walls(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s =
	        generate((const char *[]){"cornell", "--square", NULL}, &c);
	assert_int_equal(c.triangles_in, 32);
	/* 5 walls, light, 8 block sides merge (18 polygons); then the
	 * turned blocks cut the floor into triangles (conform.c). */
	assert_int_equal(c.quads, 13);
	assert_int_equal(c.polygons_cut, 1);
	assert_int_equal(c.polygons, 53);
	rad_scene_free(s);
}

static void office_sample_has_its_furniture_and_lights(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s = load(LUXRAD_SOURCE_DIR "/scenes/office.gltf", &c);
	assert_int_equal(c.triangles_in, 86);
	/* Every quad is a rectangle (43 polygons); walls and furniture that
	 * run right across three large ones cut them into rectangles. */
	assert_int_equal(c.polygons, 46);
	assert_int_equal(c.quads, 46);
	assert_int_equal(c.polygons_cut, 3);
	assert_int_equal(c.materials, 6);
	assert_int_equal(c.emitters, 2); /* two ceiling luminaires */
	assert_int_equal(c.lights, 1);   /* the desk lamp */
	assert_bounds(s, (double[]){0, 0, 0}, (double[]){4, 2.8, 3}, 1e-6);
	rad_scene_free(s);
}

static void office_sun_adds_a_directional_light(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s = generate(
	        (const char *[]){"office", "--sun", "80000", NULL}, &c);
	assert_int_equal(c.lights, 2);
	/* A directional light has no position: bounds stay the room's. */
	assert_bounds(s, (double[]){0, 0, 0}, (double[]){4, 2.8, 3}, 1e-6);
	rad_scene_free(s);
}

static void box_is_closed_subdivided_and_emitting(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s = generate((const char *[]){"box", "--size", "2,1,3",
	                                         "--subdiv", "4", "--rho",
	                                         "0.5", "--emit", "100", NULL},
	                        &c);
	assert_int_equal(c.triangles_in, 6 * 16 * 2);
	assert_int_equal(c.polygons, 6 * 16);
	assert_int_equal(c.quads, 6 * 16);
	assert_int_equal(c.emitters, 6 * 16);
	assert_int_equal(c.materials, 1);
	assert_bounds(s, (double[]){0, 0, 0}, (double[]){2, 1, 3}, 1e-6);
	rad_scene_free(s);
}

static void room_scales_to_millimetres(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s =
	        generate((const char *[]){"room", "--scale", "1e-3", NULL}, &c);
	assert_int_equal(c.triangles_in, 14);
	assert_int_equal(c.polygons, 7);
	assert_int_equal(c.emitters, 1);
	assert_int_equal(c.materials, 2);
	assert_bounds(s, (double[]){0, 0, 0}, (double[]){0.004, 0.003, 0.004},
	              1e-9);
	rad_scene_free(s);
}

static void field_reaches_its_triangle_target(void **state)
{
	(void)state;
	rad_scene_counts c;
	rad_scene *s = generate(
	        (const char *[]){"field", "--triangles", "100000", NULL}, &c);
	assert_true(c.triangles_in >= 100000);
	assert_true(c.triangles_in < 101000); /* overshoot: one object */
	assert_int_equal(c.emitters, 4);
	rad_scene_free(s);
}

/* Triangle counts within 5% of the report's polygon counts. */
static void study_scenes_match_report_counts(void **state)
{
	(void)state;
	static const struct {
		const char *kind;
		uint32_t report, emitters;
	} study[] = {{"herd", 43464, 1},
	             {"hall-empty", 94, 16},
	             {"hall-full", 40886, 16},
	             {"hall-bright", 84, 16},
	             {"hall-grand", 288000, 16}};
	for (size_t i = 0; i < sizeof(study) / sizeof(study[0]); i++) {
		rad_scene_counts c;
		rad_scene *s =
		        generate((const char *[]){study[i].kind, NULL}, &c);
		double rel = (double)c.triangles_in / study[i].report - 1;
		if (fabs(rel) > 0.05)
			fail_msg("%s: %u triangles, report %u", study[i].kind,
			         c.triangles_in, study[i].report);
		assert_int_equal(c.emitters, study[i].emitters);
		rad_scene_free(s);
	}
}

static int same_file(const char *a, const char *b)
{
	size_t la = 0, lb = 0;
	unsigned char *x = read_all(a, &la), *y = read_all(b, &lb);
	int same = x && y && la == lb && memcmp(x, y, la) == 0;
	free(x);
	free(y);
	return same;
}

static void generator_is_deterministic(void **state)
{
	(void)state;
	char a[64], b[64];
	temp_path(a);
	temp_path(b);
	const char *args[] = {"field", "--objects", "50", NULL};
	assert_int_equal(run_gen(args, a, 1), 0);
	assert_int_equal(run_gen(args, b, 1), 0);
	assert_true(same_file(a, b));
	const char *seeded[] = {"field",  "--objects", "50",
	                        "--seed", "7",         NULL};
	assert_int_equal(run_gen(seeded, b, 1), 0);
	assert_false(same_file(a, b));
	unlink(a);
	unlink(b);
}

static void generator_rejects_misuse(void **state)
{
	(void)state;
	char path[64];
	temp_path(path);
	assert_int_equal(run_gen((const char *[]){NULL}, path, 1), 2);
	assert_int_equal(run_gen((const char *[]){"cornel", NULL}, path, 1), 2);
	assert_int_equal(run_gen((const char *[]){"box", NULL}, NULL, 1), 2);
	assert_int_equal(
	        run_gen((const char *[]){"cornell", "--size", "1,1,1", NULL},
	                path, 1),
	        2);
	assert_int_equal(
	        run_gen((const char *[]){"box", "--rho", "1.5", NULL}, path, 1),
	        2);
	assert_int_equal(run_gen((const char *[]){"box", "--size", "1,2", NULL},
	                         path, 1),
	                 2);
	assert_int_equal(run_gen((const char *[]){"box", NULL},
	                         "/nonexistent-dir/x.glb", 1),
	                 1);
	assert_int_equal(run_gen((const char *[]){"--help", NULL}, NULL, 1), 0);
	unlink(path);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(cornell_sample_matches_published_box),
	        cmocka_unit_test(cornell_square_merges_all_walls),
	        cmocka_unit_test(office_sample_has_its_furniture_and_lights),
	        cmocka_unit_test(office_sun_adds_a_directional_light),
	        cmocka_unit_test(box_is_closed_subdivided_and_emitting),
	        cmocka_unit_test(room_scales_to_millimetres),
	        cmocka_unit_test(field_reaches_its_triangle_target),
	        cmocka_unit_test(study_scenes_match_report_counts),
	        cmocka_unit_test(generator_is_deterministic),
	        cmocka_unit_test(generator_rejects_misuse),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
