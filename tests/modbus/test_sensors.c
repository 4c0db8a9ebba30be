/*
 * test_sensors.c -- sensor nodes from glTF (sio_load, sensors.c in
 * daemon/sceneio): both ways of declaring one, positions and normals
 * through nested transforms (TRS and matrix), the default scene only,
 * each bad declaration refused with a message naming it, and the scene
 * and its sensors read in one pass.
 *
 * The document is written here.  Each bad case is the good document with
 * one string replaced, so it differs from a loading document by exactly
 * the defect it names.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sceneio.h"

/*
 * Scene 0 has roots 0 and 3; node 5 is in no scene.
 *   0 Room        T(10, 0, 0)              children 1, 4, 6
 *   1 sensor:desk T(1, 2, 3)               child 2      -> (11, 2, 3) +Y
 *   2 Probe       extras luxrad_sensor, R_x(90 deg), T(0, 0, 1)
 *                 -> (11, 2, 4), +Y turned to +Z
 *   3 sensor:wall matrix: R_z(-90 deg) scaled 3, T(5, 6, 7)
 *                 -> (5, 6, 7), +Y turned to +X
 *   4 Lamp        no sensor
 *   5 sensor:ghost (not in the scene)
 *   6 sensor:both with extras naming the same sensor, S(1, 0.5, 1)
 *                 -> (10, 0, 0), +Y
 */
static const char good_doc[] =
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,"
        "\"scenes\":[{\"nodes\":[0,3]}],\"nodes\":["
        "{\"name\":\"Room\",\"translation\":[10,0,0],"
        "\"children\":[1,4,6]},"
        "{\"name\":\"sensor:desk\",\"translation\":[1,2,3],\"scale\":"
        "[1,1,1],\"children\":[2]},"
        "{\"name\":\"Probe\",\"extras\":{\"luxrad_sensor\":\"probe\"},"
        "\"rotation\":[0.70710678118654752,0,0,0.70710678118654752],"
        "\"translation\":[0,0,1]},"
        "{\"name\":\"sensor:wall\",\"matrix\":[0,-3,0,0, 3,0,0,0, 0,0,3,0, "
        "5,6,7,1]},"
        "{\"name\":\"Lamp\"},"
        "{\"name\":\"sensor:ghost\"},"
        "{\"name\":\"sensor:both\",\"extras\":{\"luxrad_sensor\":"
        "\"both\"},\"scale\":[1,0.5,1]}]}";

/* Replace the first `from` (which must be present) by `to`. */
static char *subst(const char *s, const char *from, const char *to)
{
	const char *at = strstr(s, from);
	if (!at)
		fail_msg("'%s' not found in the document", from);
	size_t head = (size_t)(at - s), nf = strlen(from), nt = strlen(to);
	char *r = malloc(strlen(s) - nf + nt + 1);
	assert_non_null(r);
	memcpy(r, s, head);
	memcpy(r + head, to, nt);
	strcpy(r + head + nt, at + nf);
	return r;
}

static const sio_sensor *find(const sio_sensor *s, size_t n, const char *name)
{
	for (size_t i = 0; i < n; i++)
		if (strcmp(s[i].name, name) == 0)
			return &s[i];
	return NULL;
}

static void near3(const double *got, double x, double y, double z)
{
	assert_true(fabs(got[0] - x) < 1e-12);
	assert_true(fabs(got[1] - y) < 1e-12);
	assert_true(fabs(got[2] - z) < 1e-12);
}

static void test_sensors_from_nested_nodes(void **state)
{
	(void)state;
	sio_sensor *s = NULL;
	size_t n = 99;
	rad_error err;
	assert_int_equal(
	        sio_load(good_doc, strlen(good_doc), NULL, NULL, &s, &n, &err),
	        RAD_OK);
	assert_int_equal(n, 4); /* desk, probe, both, wall: not the ghost */
	assert_null(find(s, n, "ghost"));
	const sio_sensor *desk = find(s, n, "desk");
	assert_non_null(desk);
	assert_int_equal(desk->node, 1);
	near3(desk->position, 11, 2, 3);
	near3(desk->normal, 0, 1, 0);
	const sio_sensor *probe = find(s, n, "probe");
	assert_non_null(probe);
	assert_int_equal(probe->node, 2);
	near3(probe->position, 11, 2, 4);
	near3(probe->normal, 0, 0, 1);
	const sio_sensor *wall = find(s, n, "wall");
	assert_non_null(wall);
	near3(wall->position, 5, 6, 7);
	near3(wall->normal, 1, 0, 0); /* scale 3 normalised away */
	const sio_sensor *both = find(s, n, "both");
	assert_non_null(both);
	near3(both->position, 10, 0, 0);
	near3(both->normal, 0, 1, 0);
	/* depth-first walk order, roots in scene order */
	assert_string_equal(s[0].name, "desk");
	assert_string_equal(s[1].name, "probe");
	assert_string_equal(s[2].name, "both");
	assert_string_equal(s[3].name, "wall");
	sio_sensors_free(s);
}

static void test_no_sensors(void **state)
{
	(void)state;
	static const char doc[] = "{\"asset\":{\"version\":\"2.0\"},"
	                          "\"nodes\":[{\"name\":\"sensorless\"}]}";
	sio_sensor *s = (sio_sensor *)1;
	size_t n = 7;
	assert_int_equal(sio_load(doc, strlen(doc), NULL, NULL, &s, &n, NULL),
	                 RAD_OK);
	assert_null(s);
	assert_int_equal(n, 0);
}

/* The good document with one defect: refused, message has `want`. */
static void refused(const char *from, const char *to, const char *want)
{
	char *doc = subst(good_doc, from, to);
	sio_sensor *s = (sio_sensor *)1;
	size_t n = 7;
	rad_error err;
	rad_status st = sio_load(doc, strlen(doc), NULL, NULL, &s, &n, &err);
	if (st != RAD_ERR_INVALID || !strstr(err.msg, want))
		fail_msg("'%s' -> '%s': status %d, message '%s', expected "
		         "'%s'",
		         from, to, st, err.msg, want);
	assert_null(s);
	assert_int_equal(n, 0);
	free(doc);
}

static void test_bad_declarations(void **state)
{
	(void)state;
	refused("sensor:desk",
	        "sensor:", "node 1 'sensor:': empty sensor name");
	refused("\"luxrad_sensor\":\"probe\"", "\"luxrad_sensor\":\"\"",
	        "node 2 'Probe': empty sensor name");
	refused("\"luxrad_sensor\":\"probe\"", "\"luxrad_sensor\":5",
	        "node 2 'Probe': extras.luxrad_sensor must be a string");
	refused("\"luxrad_sensor\":\"both\"", "\"luxrad_sensor\":\"other\"",
	        "node 6 'sensor:both': declares sensor 'both' by its name and "
	        "'other'");
	refused("sensor:wall", "sensor:desk",
	        "sensor 'desk' declared twice (nodes 1 and 3)");
	refused("\"Lamp\"", "\"sensor:desk\"",
	        "sensor 'desk' declared twice (nodes 1 and 4)");
	refused("sensor:desk", "sensor:desk\\u0001",
	        "node 1: sensor name has a control character");
	refused("sensor:desk",
	        "sensor:0123456789012345678901234567890123456789012345678901"
	        "234567890123",
	        "node 1: sensor name of 64 bytes (at most 63)");
	/* 63 bytes is the longest name accepted */
	char *doc = subst(good_doc, "sensor:desk",
	                  "sensor:012345678901234567890123456789012345678901"
	                  "234567890123456789012");
	sio_sensor *s = NULL;
	size_t n;
	assert_int_equal(sio_load(doc, strlen(doc), NULL, NULL, &s, &n, NULL),
	                 RAD_OK);
	assert_int_equal(strlen(s[0].name), 63);
	sio_sensors_free(s);
	free(doc);
}

static void test_bad_geometry(void **state)
{
	(void)state;
	/* a scale that flattens the sensor's +Y axis */
	refused("\"scale\":[1,1,1]", "\"scale\":[1,0,1]",
	        "sensor 'desk' (node 1): normal (the node's +Y axis in world "
	        "space) is zero");
	refused("\"scale\":[1,0.5,1]", "\"scale\":[1,0,1]",
	        "sensor 'both' (node 6): normal");
	/* overflow through the hierarchy: 1e308 + 1e308 */
	char *doc = subst(good_doc, "\"translation\":[10,0,0]",
	                  "\"translation\":[1e308,0,0]");
	char *doc2 = subst(doc, "\"translation\":[1,2,3]",
	                   "\"translation\":[1e308,2,3]");
	sio_sensor *s = NULL;
	size_t n;
	rad_error err;
	assert_int_equal(sio_load(doc2, strlen(doc2), NULL, NULL, &s, &n, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "sensor 'desk' (node 1): position is "
	                                "not finite"));
	free(doc);
	free(doc2);
	/* 1e300 x 1e300: the axis itself overflows */
	doc = subst(good_doc, "\"name\":\"Room\",",
	            "\"name\":\"Room\",\"scale\":[1e300,1e300,1e300],");
	doc2 = subst(doc, "\"scale\":[1,1,1]", "\"scale\":[1e300,1e300,1e300]");
	assert_int_equal(sio_load(doc2, strlen(doc2), NULL, NULL, &s, &n, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "sensor 'desk' (node 1): normal (the "
	                                "node's +Y axis in world space) is "
	                                "not finite"));
	free(doc);
	free(doc2);
	/* huge but finite: still a unit normal */
	doc = subst(good_doc, "\"scale\":[1,1,1]",
	            "\"scale\":[1e200,1e200,1e200]");
	assert_int_equal(sio_load(doc, strlen(doc), NULL, NULL, &s, &n, &err),
	                 RAD_OK);
	near3(find(s, n, "desk")->normal, 0, 1, 0);
	sio_sensors_free(s);
	free(doc);
}

static void test_bad_documents(void **state)
{
	(void)state;
	refused("\"children\":[1,4,6]", "\"children\":[1,4,60]",
	        "node 0 'Room': child 60 out of range");
	refused("\"children\":[2]", "\"children\":[0]", "reached twice");
	refused("\"scene\":0", "\"scene\":3", "default scene 3 out of range");
	sio_sensor *s = NULL;
	size_t n;
	rad_error err;
	assert_int_equal(sio_load("{", 1, NULL, NULL, &s, &n, &err),
	                 RAD_ERR_INVALID);
	assert_int_equal(sio_load(NULL, 0, NULL, NULL, &s, &n, &err),
	                 RAD_ERR_INVALID);
	assert_int_equal(sio_load(good_doc, strlen(good_doc), NULL, NULL, NULL,
	                          &n, &err),
	                 RAD_ERR_INVALID);
}

/* The good document with a triangle on the lamp's node: a scene too. */
static char *scene_doc(void)
{
	char *with_mesh = subst(good_doc, "{\"name\":\"Lamp\"}",
	                        "{\"name\":\"Lamp\",\"mesh\":0}");
	char *doc = subst(
	        with_mesh, "],\"nodes\":[",
	        "],\"meshes\":[{\"primitives\":[{\"attributes\":"
	        "{\"POSITION\":0}}]}],\"accessors\":[{\"bufferView\":0,"
	        "\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],"
	        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
	        "\"buffers\":[{\"byteLength\":36,\"uri\":\"data:application/"
	        "octet-stream;base64,"
	        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAAAAA"
	        "AIC/\"}],\"nodes\":[");
	free(with_mesh);
	return doc;
}

static void test_scene_and_sensors_in_one_pass(void **state)
{
	(void)state;
	char *doc = scene_doc();
	rad_scene *scene = NULL;
	sio_info info;
	sio_sensor *s = NULL;
	size_t n = 0;
	rad_error err;
	assert_int_equal(
	        sio_load(doc, strlen(doc), &scene, &info, &s, &n, &err),
	        RAD_OK);
	assert_non_null(scene);
	rad_scene_counts c;
	rad_scene_counts_get(scene, &c);
	assert_int_equal(c.triangles_in, 1);
	assert_int_equal(info.primitives, 1);
	assert_int_equal(n, 4);
	near3(find(s, n, "probe")->position, 11, 2, 4);
	rad_scene_free(scene);
	sio_sensors_free(s);
	free(doc);
}

/* A scene's own error comes first, even after an earlier sensor error;
 * a sensor error alone refuses the scene too. */
static void test_scene_errors_before_sensor_errors(void **state)
{
	(void)state;
	char *doc = scene_doc();
	char *bad_sensor = subst(doc, "sensor:desk", "sensor:");
	char *both = subst(bad_sensor, "\"mesh\":0", "\"mesh\":5");
	rad_scene *scene = (rad_scene *)1;
	sio_sensor *s = (sio_sensor *)1;
	size_t n = 7;
	rad_error err;
	assert_int_equal(
	        sio_load(both, strlen(both), &scene, NULL, &s, &n, &err),
	        RAD_ERR_INVALID);
	assert_string_equal(err.msg, "node 4 'Lamp': mesh 5 out of range (1 "
	                             "meshes)");
	assert_int_equal(sio_load(bad_sensor, strlen(bad_sensor), &scene, NULL,
	                          &s, &n, &err),
	                 RAD_ERR_INVALID);
	assert_string_equal(err.msg, "node 1 'sensor:': empty sensor name");
	assert_null(scene);
	assert_null(s);
	assert_int_equal(n, 0);
	free(both);
	free(bad_sensor);
	free(doc);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_sensors_from_nested_nodes),
	        cmocka_unit_test(test_no_sensors),
	        cmocka_unit_test(test_bad_declarations),
	        cmocka_unit_test(test_bad_geometry),
	        cmocka_unit_test(test_bad_documents),
	        cmocka_unit_test(test_scene_and_sensors_in_one_pass),
	        cmocka_unit_test(test_scene_errors_before_sensor_errors),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
