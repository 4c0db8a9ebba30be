/*
 * test_daemon_export.c -- export and scene memory on a real luxradd
 * (PROTOCOL.md 5.6 scene.delete, 5.18 export):
 *  - export: a GLB (magic, version 2, length) that the Khronos validator
 *    accepts, one mesh per node with COLOR_0 and _ILLUMINANCE; "state"
 *    before the first iteration;
 *  - COLOR_0 = lux / (lux + L_white), L_white the 99th percentile of the
 *    vertex illuminance;
 *  - scene.delete: busy while a job uses the scene; afterwards the
 *    scene's memory is gone and the daemon total is back to its value
 *    before the upload.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "harness.h"

/* ------------------------------------------------------------- export */

static uint32_t le32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
	       (uint32_t)p[3] << 24;
}

/* Read component k of element i of a glTF accessor from the BIN chunk,
 * as a double (float, or normalized unsigned byte / short). */
static double acc_get(const json_t *doc, const unsigned char *bin,
                      size_t binlen, const json_t *acc, size_t i, int k)
{
	const char *type = json_string_value(dm_get(acc, "type"));
	int ncomp = !strcmp(type, "SCALAR") ? 1
	            : !strcmp(type, "VEC2") ? 2
	            : !strcmp(type, "VEC3") ? 3
	            : !strcmp(type, "VEC4") ? 4
	                                    : 0;
	assert_true(ncomp > 0 && k < ncomp);
	long long ct = dm_int(acc, "componentType");
	size_t csize = ct == 5126 ? 4 : ct == 5123 ? 2 : ct == 5121 ? 1 : 0;
	if (!csize)
		fail_msg("accessor componentType %lld not handled", ct);
	json_t *bv = json_array_get(dm_get(doc, "bufferViews"),
	                            (size_t)dm_int(acc, "bufferView"));
	json_t *o = json_object_get(bv, "byteOffset");
	json_t *ao = json_object_get(acc, "byteOffset");
	json_t *st = json_object_get(bv, "byteStride");
	size_t stride =
	        st ? (size_t)json_integer_value(st) : (size_t)ncomp * csize;
	size_t off = (o ? (size_t)json_integer_value(o) : 0) +
	             (ao ? (size_t)json_integer_value(ao) : 0) + i * stride +
	             (size_t)k * csize;
	if (off + csize > binlen)
		fail_msg("accessor reads past the BIN chunk");
	const unsigned char *p = bin + off;
	if (ct == 5126) {
		float f;
		memcpy(&f, p, 4);
		return f;
	}
	if (ct == 5123)
		return (p[0] | p[1] << 8) / 65535.0;
	return p[0] / 255.0;
}

/*
 * PROTOCOL.md 5.18: COLOR_0 is the radiosity B (light leaving the
 * surface) tone-mapped per channel, B / (B + white), white the 99th
 * percentile of the leaves' luma(B).  B is not in the file, so what can be
 * checked from it: every channel in [0, 1), and the colour follows the
 * light -- vertices above the median illuminance are brighter on average
 * than those below it (false for an inverted or random mapping).
 */
typedef struct lux_col {
	double lux, luma;
} lux_col;

static int cmp_lux(const void *a, const void *b)
{
	double x = ((const lux_col *)a)->lux, y = ((const lux_col *)b)->lux;
	return x < y ? -1 : x > y;
}

static void check_tone_map(const json_t *doc, const unsigned char *bin,
                           size_t binlen)
{
	size_t nv = 0, cap = 1024, i, k;
	lux_col *v = malloc(cap * sizeof(*v));
	json_t *m, *prim;
	json_array_foreach(dm_get(doc, "meshes"), i, m)
	{
		json_array_foreach(dm_get(m, "primitives"), k, prim)
		{
			json_t *at = dm_get(prim, "attributes");
			json_t *accs = dm_get(doc, "accessors");
			json_t *ai = json_array_get(
			        accs, (size_t)dm_int(at, "_ILLUMINANCE"));
			json_t *ac = json_array_get(
			        accs, (size_t)dm_int(at, "COLOR_0"));
			size_t n = (size_t)dm_int(ai, "count");
			assert_int_equal(dm_int(ac, "count"), n);
			for (size_t j = 0; j < n; j++) {
				double e = acc_get(doc, bin, binlen, ai, j, 0);
				double c[3];
				for (int ch = 0; ch < 3; ch++) {
					c[ch] = acc_get(doc, bin, binlen, ac, j,
					                ch);
					if (!(c[ch] >= 0 && c[ch] < 1))
						fail_msg("COLOR_0 %g", c[ch]);
				}
				if (!(e >= 0) || !isfinite(e))
					fail_msg("_ILLUMINANCE %g", e);
				if (nv == cap) {
					cap *= 2;
					v = realloc(v, cap * sizeof(*v));
				}
				v[nv].lux = e;
				v[nv++].luma = 0.2126 * c[0] + 0.7152 * c[1] +
				               0.0722 * c[2];
			}
		}
	}
	assert_true(nv > 10);
	qsort(v, nv, sizeof(*v), cmp_lux);
	double lo = 0, hi = 0;
	for (size_t j = 0; j < nv / 2; j++)
		lo += v[j].luma;
	for (size_t j = nv - nv / 2; j < nv; j++)
		hi += v[j].luma;
	if (!(hi > lo))
		fail_msg(
		        "COLOR_0 does not follow the light: mean luma %g above "
		        "the median illuminance, %g below",
		        hi / (double)(nv / 2), lo / (double)(nv / 2));
	free(v);
}

/* Export the solved office and check the GLB; tone_map: also check the
 * colour mapping (after the validator, so that both are reported). */
static void export_office(int tone_map)
{
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char p[512];
	json_t *sc = dm_upload_file(c, dm_sample("cornell.gltf", p, sizeof(p)),
	                            "cornell");
	json_t *job = dm_job_create(c, sc, "hr", NULL);
	json_decref(
	        dm_err(c, "state", "{s:s, s:O}", "cmd", "export", "job", job));
	json_decref(job);
	json_decref(sc);
	job = dm_solve_sample(c, "office.gltf", &sc);

	json_t *r = dm_ok(c, "{s:s, s:O, s:s}", "cmd", "export", "job", job,
	                  "format", "glb");
	size_t n = c->payload_len;
	const unsigned char *g = c->payload;
	assert_int_equal(dm_int(r, "bytes"), (long long)n);
	assert_true(dm_int(r, "vertices") > 0);
	assert_true(dm_int(r, "triangles") > 0);
	assert_true(dm_int(r, "iteration") > 0);
	if (n < 20 || memcmp(g, "glTF", 4) != 0)
		fail_msg("export payload (%zu bytes) does not start with "
		         "\"glTF\"",
		         n);
	assert_int_equal(le32(g + 4), 2);
	assert_int_equal(le32(g + 8), n);
	/* First chunk: JSON. */
	uint32_t jlen = le32(g + 12);
	assert_int_equal(le32(g + 16), 0x4E4F534A); /* "JSON" */
	assert_true(20 + (size_t)jlen <= n);
	json_error_t je;
	json_t *doc = json_loadb((const char *)g + 20, jlen, 0, &je);
	if (!doc)
		fail_msg("GLB JSON chunk: %s", je.text);
	json_t *meshes = dm_get(doc, "meshes");
	assert_true(json_array_size(meshes) >= 7); /* one per node */
	long long verts = 0;
	size_t i;
	json_t *m;
	json_array_foreach(meshes, i, m)
	{
		size_t k;
		json_t *prim;
		json_array_foreach(dm_get(m, "primitives"), k, prim)
		{
			json_t *at = dm_get(prim, "attributes");
			dm_get(at, "COLOR_0");
			dm_get(at, "_ILLUMINANCE");
			long long pos = dm_int(at, "POSITION");
			verts += dm_int(json_array_get(dm_get(doc, "accessors"),
			                               (size_t)pos),
			                "count");
		}
	}
	assert_int_equal(verts, dm_int(r, "vertices"));
	/* Second chunk: BIN. */
	size_t bo = 20 + (size_t)jlen;
	assert_true(bo + 8 <= n);
	assert_int_equal(le32(g + bo + 4), 0x004E4942); /* "BIN\0" */
	size_t blen = le32(g + bo);
	assert_true(bo + 8 + blen <= n);
	const unsigned char *bin = g + bo + 8;

	char *path = dm_tmp_file(".glb", g, n);
	char cmd[1024];
	snprintf(cmd, sizeof(cmd),
	         "node '%s/tests/tools/validate_gltf.js' '%s' 2>&1",
	         LUXRAD_SOURCE_DIR, path);
	char *out = NULL;
	int rc = dm_run(cmd, &out);
	if (rc != 0)
		fail_msg("the glTF validator refuses the export (exit %d):\n%s",
		         rc, out);
	free(out);
	unlink(path);
	free(path);
	if (tone_map)
		check_tone_map(doc, bin, blen);
	json_decref(doc);
	json_decref(r);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* ------------------------------------------------------- scene memory */

static void test_export_is_a_valid_glb(void **state)
{
	(void)state;
	export_office(0);
}

static void test_export_colour_is_tone_mapped_lux(void **state)
{
	(void)state;
	export_office(1);
}

static json_t *memory_of(dm_conn *c)
{
	json_t *r = dm_ok(c, "{s:s}", "cmd", "status");
	json_t *m = json_incref(dm_get(r, "memory"));
	json_decref(r);
	return m;
}

static void test_scene_delete_releases_its_memory(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *m0 = memory_of(c);

	char p[512];
	json_t *sc = dm_upload_file(
	        c, dm_gen_scene("hall-empty.glb", "hall-empty", p, sizeof(p)),
	        "hall");
	json_t *m1 = memory_of(c);
	if (!(dm_int(m1, "total_bytes") > dm_int(m0, "total_bytes")))
		fail_msg("status memory did not grow with a scene");
	json_t *r = dm_ok(c, "{s:s}", "cmd", "status");
	int listed = 0;
	size_t i;
	json_t *e;
	json_array_foreach(dm_get(r, "scenes"), i, e)
	{
		if (json_equal(dm_get(e, "id"), sc)) {
			listed = 1;
			assert_true(dm_int(e, "memory_bytes") > 0);
		}
	}
	assert_true(listed);
	json_decref(r);

	/* Busy while a job uses it, whatever the job's state. */
	json_t *opt = json_pack("{s:i}", "threads", 1);
	json_t *job = dm_job_create(c, sc, "hr", opt);
	json_decref(dm_err(c, "busy", "{s:s, s:O}", "cmd", "scene.delete",
	                   "scene", sc));
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_decref(dm_err(c, "busy", "{s:s, s:O}", "cmd", "scene.delete",
	                   "scene", sc));
	json_decref(dm_wait_job(c, job, "done", 150000));
	json_t *info = dm_ok(c, "{s:s, s:O}", "cmd", "scene.info", "scene", sc);
	assert_int_equal(json_array_size(dm_get(info, "jobs")), 1);
	json_decref(info);
	json_decref(dm_err(c, "busy", "{s:s, s:O}", "cmd", "scene.delete",
	                   "scene", sc));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "scene.delete", "scene", sc));

	json_t *m2 = memory_of(c);
	if (dm_int(m2, "total_bytes") != dm_int(m0, "total_bytes")) {
		char *a = json_dumps(m0, JSON_COMPACT);
		char *b = json_dumps(m2, JSON_COMPACT);
		fail_msg("memory after scene.delete differs from before the "
		         "upload:\nbefore %s\nafter  %s",
		         a, b);
	}
	assert_true(json_equal(dm_get(m2, "by_kind"), dm_get(m0, "by_kind")));
	r = dm_ok(c, "{s:s}", "cmd", "status");
	json_array_foreach(dm_get(r, "scenes"), i, e)
	{
		if (json_equal(dm_get(e, "id"), sc))
			fail_msg("status still lists the deleted scene");
	}
	json_decref(r);
	json_decref(dm_err(c, "not_found", "{s:s, s:O}", "cmd", "scene.info",
	                   "scene", sc));
	r = dm_ok(c, "{s:s}", "cmd", "scene.list");
	assert_int_equal(json_array_size(dm_get(r, "scenes")), 0);
	json_decref(r);
	json_decref(job);
	json_decref(opt);
	json_decref(sc);
	json_decref(m0);
	json_decref(m1);
	json_decref(m2);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_export_is_a_valid_glb),
	        T(test_export_colour_is_tone_mapped_lux),
	        T(test_scene_delete_releases_its_memory),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
