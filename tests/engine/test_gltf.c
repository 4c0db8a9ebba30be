/*
 * test_gltf.c -- glTF import and export (daemon/sceneio: sio_load,
 * sio_write).
 *
 * Documents are built here, inline: a small JSON template over a buffer
 * that the test encodes as a base64 data: URI, or GLB bytes produced by
 * sio_write.  Each bad-input case is the good document with one
 * string replaced, so every case differs from a loading document by
 * exactly the defect it names.  The checks read the committed scene
 * through rad.h and, where rad.h has no accessor (materials, lights,
 * polygon normals), through the builder's own struct in scene.h.
 * Leaks are left to ASan/LSan (the CI runs this suite under ASan).
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

#include "scene.h"
#include "sceneio.h"

/* ------------------------------------------------------------- helpers */

static char *b64(const unsigned char *p, size_t n)
{
	static const char tab[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnop"
	                          "qrstuvwxyz0123456789+/";
	char *out = malloc(4 * ((n + 2) / 3) + 1), *o = out;
	assert_non_null(out);
	for (size_t i = 0; i < n; i += 3) {
		uint32_t v = (uint32_t)p[i] << 16;
		if (i + 1 < n)
			v |= (uint32_t)p[i + 1] << 8;
		if (i + 2 < n)
			v |= p[i + 2];
		*o++ = tab[v >> 18 & 63];
		*o++ = tab[v >> 12 & 63];
		*o++ = i + 1 < n ? tab[v >> 6 & 63] : '=';
		*o++ = i + 2 < n ? tab[v & 63] : '=';
	}
	*o = '\0';
	return out;
}

/* Replace the first `from` (which must be present) by `to`; frees s. */
static char *subst(char *s, const char *from, const char *to)
{
	char *at = strstr(s, from);
	if (!at)
		fail_msg("'%s' not found in the document", from);
	size_t head = (size_t)(at - s), nf = strlen(from), nt = strlen(to);
	char *r = malloc(strlen(s) - nf + nt + 1);
	assert_non_null(r);
	memcpy(r, s, head);
	memcpy(r + head, to, nt);
	strcpy(r + head + nt, at + nf);
	free(s);
	return r;
}

/* The unit square in z = 0, front +Z, as 4 vertices and 6 indices. */
static const float quad_pos[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
static const uint32_t quad_idx[] = {0, 1, 2, 0, 2, 3};

/* The JSON after "buffers": two views, two accessors, one material. */
static const char doc_tail[] =
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":%zu},"
        "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,"
        "\"count\":%zu,\"type\":\"VEC3\"},{\"bufferView\":1,"
        "\"componentType\":%d,\"count\":%zu,\"type\":\"SCALAR\"}],"
        "\"materials\":[{\"name\":\"Lamp\",\"pbrMetallicRoughness\":"
        "{\"baseColorFactor\":[0.5,0.6,0.7,1]},"
        "\"emissiveFactor\":[1,0.5,0.25],\"extensions\":"
        "{\"KHR_materials_emissive_strength\":{\"emissiveStrength\":4}}}],"
        "\"meshes\":[{\"name\":\"Quad\",\"primitives\":[{\"attributes\":"
        "{\"POSITION\":0},\"indices\":1,\"material\":0}]}],"
        "\"nodes\":[{\"name\":\"Panel\",\"mesh\":0}],"
        "\"scenes\":[{\"nodes\":[0]}]}";

/*
 * A .gltf document with one mesh: nv vertices, ni indices stored with
 * isize bytes each (1, 2, 4), in one data: URI buffer (or `uri`).
 */
static char *mesh_doc(const float *pos, size_t nv, const uint32_t *idx,
                      size_t ni, int isize, const char *uri)
{
	unsigned char bin[1024];
	size_t np = 12 * nv, nb = np + (ni * (size_t)isize + 3) / 4 * 4;
	assert_true(nb <= sizeof bin);
	memset(bin, 0, sizeof bin);
	memcpy(bin, pos, np);
	for (size_t k = 0; k < ni; k++)
		memcpy(bin + np + k * (size_t)isize, &idx[k], (size_t)isize);
	char *data = b64(bin, nb);
	char *doc = malloc(strlen(data) + 2048);
	assert_non_null(doc);
	int comp = isize == 1 ? 5121 : isize == 2 ? 5123 : 5125;
	int n = sprintf(doc,
	                "{\"asset\":{\"version\":\"2.0\"},\"buffers\":"
	                "[{\"byteLength\":%zu,\"uri\":\"%s%s\"}],",
	                nb, uri ? "" : "data:application/octet-stream;base64,",
	                uri ? uri : data);
	sprintf(doc + n, doc_tail, np, np, ni * (size_t)isize, nv, comp, ni);
	free(data);
	return doc;
}

static char *quad_doc(void)
{
	return mesh_doc(quad_pos, 4, quad_idx, 6, 2, NULL);
}

/* Load bytes that must load; the caller frees the scene. */
static rad_scene *load_ok(const void *bytes, size_t len, sio_info *info)
{
	rad_scene *s = NULL;
	rad_error err = {0};
	rad_status st = sio_load(bytes, len, &s, info, NULL, NULL, &err);
	if (st != RAD_OK)
		fail_msg("load failed (%s): %s", rad_status_name(st), err.msg);
	assert_non_null(s);
	return s;
}

static rad_scene_counts load_counts(const char *doc)
{
	rad_scene_counts c;
	rad_scene *s = load_ok(doc, strlen(doc), NULL);
	rad_scene_counts_get(s, &c);
	rad_scene_free(s);
	return c;
}

/* Expect a refusal with status `want` and a message containing `part`. */
static void expect_fail(const void *bytes, size_t len, rad_status want,
                        const char *part)
{
	rad_scene *s = (rad_scene *)1;
	rad_error err = {0};
	rad_status st = sio_load(bytes, len, &s, NULL, NULL, NULL, &err);
	if (st != want || !strstr(err.msg, part))
		fail_msg("got %s '%s', want %s with '%s'", rad_status_name(st),
		         err.msg, rad_status_name(want), part);
	assert_null(s);
	assert_int_equal(err.code, want);
}

/* The quad document with one replacement must fail as stated. */
static void expect_doc_fail(const char *from, const char *to, rad_status want,
                            const char *part)
{
	char *doc = subst(quad_doc(), from, to);
	expect_fail(doc, strlen(doc), want, part);
	free(doc);
}

static const rad_poly *poly0(const rad_scene *s)
{
	assert_true(s->npolys > 0);
	return &s->polys[0];
}

/* ------------------------------------------------------- import basics */

static void test_quad_loads_as_one_emissive_parallelogram(void **state)
{
	(void)state;
	char *doc = quad_doc();
	sio_info info;
	rad_scene *s = load_ok(doc, strlen(doc), &info);
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.triangles_in, 2);
	assert_int_equal(c.polygons, 1);
	assert_int_equal(c.quads, 1);
	assert_int_equal(c.materials, 1);
	assert_int_equal(c.emitters, 1);
	assert_int_equal(c.nodes, 1);
	assert_int_equal(info.meshes, 1);
	assert_int_equal(info.primitives, 1);
	assert_int_equal(info.nodes, 1);
	assert_int_equal(info.primitives_skipped, 0);
	assert_int_equal(info.metallic_materials, 1); /* glTF default: 1 */
	assert_float_equal(s->total_area, 1.0, 1e-6);
	assert_string_equal(s->nodes[rad_poly_node(s, 0)], "Panel");
	const rad_material *m = &s->mats[poly0(s)->mat];
	assert_float_equal(m->rho[0], 0.5, 1e-6);
	assert_float_equal(m->rho[1], 0.6, 1e-6);
	assert_float_equal(m->rho[2], 0.7, 1e-6);
	/* luminance = emissiveFactor x strength 4; exitance = pi x that */
	assert_float_equal(m->emit[0], M_PI * 4.0, 1e-4);
	assert_float_equal(m->emit[1], M_PI * 2.0, 1e-4);
	assert_float_equal(m->emit[2], M_PI * 1.0, 1e-4);
	assert_float_equal(rad_poly_normal(poly0(s)).z, 1.0, 1e-6);
	rad_scene_free(s);
	free(doc);
}

static void test_u8_and_u32_indices_load_like_u16(void **state)
{
	(void)state;
	for (int isize = 1; isize <= 4; isize *= 2) {
		char *doc = mesh_doc(quad_pos, 4, quad_idx, 6, isize, NULL);
		rad_scene_counts c = load_counts(doc);
		assert_int_equal(c.triangles_in, 2);
		assert_int_equal(c.polygons, 1);
		free(doc);
	}
}

static void test_non_indexed_strip_and_fan_cover_the_square(void **state)
{
	(void)state;
	static const float list[] = {0, 0, 0, 1, 0, 0, 1, 1, 0,
	                             0, 0, 0, 1, 1, 0, 0, 1, 0};
	static const float strip[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
	static const struct {
		const float *pos;
		size_t nv;
		const char *mode;
	} cases[] = {{list, 6, ""},
	             {strip, 4, ",\"mode\":5"},
	             {quad_pos, 4, ",\"mode\":6"}};
	for (size_t k = 0; k < 3; k++) {
		char *doc = mesh_doc(cases[k].pos, cases[k].nv, quad_idx, 0, 2,
		                     NULL);
		char mode[64];
		snprintf(mode, sizeof mode, "\"material\":0%s", cases[k].mode);
		doc = subst(doc, "\"indices\":1,\"material\":0", mode);
		rad_scene *s = load_ok(doc, strlen(doc), NULL);
		assert_int_equal(s->counts.triangles_in, 2);
		assert_float_equal(s->total_area, 1.0, 1e-6);
		for (uint32_t i = 0; i < s->npolys; i++) /* all face +Z */
			assert_float_equal(rad_poly_normal(&s->polys[i]).z, 1.0,
			                   1e-6);
		rad_scene_free(s);
		free(doc);
	}
}

static void test_points_and_lines_are_skipped_and_counted(void **state)
{
	(void)state;
	char *doc = subst(quad_doc(), "\"material\":0}",
	                  "\"material\":0},{\"attributes\":{\"POSITION\":0},"
	                  "\"mode\":1},{\"attributes\":{\"POSITION\":0},"
	                  "\"mode\":0}");
	sio_info info;
	rad_scene *s = load_ok(doc, strlen(doc), &info);
	assert_int_equal(info.primitives, 1);
	assert_int_equal(info.primitives_skipped, 2);
	assert_int_equal(s->counts.triangles_in, 2);
	rad_scene_free(s);
	free(doc);
}

static void test_nested_trs_and_matrix_transforms(void **state)
{
	(void)state;
	/* parent: T(10,0,0) R(90 deg about Z) S(2); child: matrix T(0,0,5).
	 * (x, y, 0) -> (10 - 2y, 2x, 10): x in [8,10], y in [0,2], z = 10 */
	char *doc = subst(
	        quad_doc(), "\"nodes\":[{\"name\":\"Panel\",\"mesh\":0}]",
	        "\"nodes\":[{\"name\":\"Arm\",\"translation\":[10,0,0],"
	        "\"rotation\":[0,0,0.70710678118654752,0.70710678118654752],"
	        "\"scale\":[2,2,2],\"children\":[1]},{\"name\":\"Panel\","
	        "\"mesh\":0,\"matrix\":[1,0,0,0,0,1,0,0,0,0,1,0,0,0,5,1]}]");
	sio_info info;
	rad_scene *s = load_ok(doc, strlen(doc), &info);
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	const double want_lo[3] = {8, 0, 10}, want_hi[3] = {10, 2, 10};
	for (int k = 0; k < 3; k++) {
		assert_float_equal(lo[k], want_lo[k], 1e-5);
		assert_float_equal(hi[k], want_hi[k], 1e-5);
	}
	assert_int_equal(info.nodes, 2);
	assert_float_equal(s->total_area, 4.0, 1e-5);
	rad_scene_free(s);
	free(doc);
}

static void test_mirroring_keeps_the_front_side(void **state)
{
	(void)state;
	/* A mirror in x reverses the winding; the loader swaps two corners
	 * so the front still faces +Z, where it geometrically is. */
	char *doc = subst(quad_doc(), "\"mesh\":0}",
	                  "\"mesh\":0,\"scale\":[-1,1,1]}");
	rad_scene *s = load_ok(doc, strlen(doc), NULL);
	assert_float_equal(rad_poly_normal(poly0(s)).z, 1.0, 1e-6);
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	assert_float_equal(lo[0], -1.0, 1e-6);
	assert_float_equal(hi[0], 0.0, 1e-6);
	rad_scene_free(s);
	free(doc);
}

static void test_materials_default_clamp_and_counters(void **state)
{
	(void)state;
	/* No material on the primitive: glTF's default white, clamped. */
	char *doc = subst(quad_doc(), ",\"material\":0", "");
	doc = subst(
	        doc, "\"pbrMetallicRoughness\":{",
	        "\"normalTexture\":{\"index\":0},\"pbrMetallicRoughness\":"
	        "{\"metallicFactor\":0,\"baseColorTexture\":{\"index\":0},");
	sio_info info;
	rad_scene *s = load_ok(doc, strlen(doc), &info);
	const rad_material *m = &s->mats[poly0(s)->mat];
	for (int c = 0; c < 3; c++) {
		assert_float_equal(m->rho[c], 0.999, 1e-6);
		assert_float_equal(m->emit[c], 0.0, 0.0);
	}
	assert_non_null(strstr(info.warnings, "clamped"));
	assert_int_equal(info.textures_ignored, 2);
	assert_int_equal(info.metallic_materials, 0);
	rad_scene_free(s);
	free(doc);
}

/* A 2 x 2 grey PNG (128: 0.2158605 linear), as a data: URI. */
#define GREY_PNG                                                               \
	"data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAIAAAACCAIAAAD91Jpz"   \
	"AAAAFklEQVR4nGNsaGhgYGBgYmBgYGBgAAASKgGEzwCOrgAAAABJRU5ErkJggg=="

/* The quad's material given a base colour texture, with its pieces. */
static char *textured_doc(const char *texinfo, const char *images,
                          const char *extra)
{
	char buf[1024];
	snprintf(buf, sizeof buf,
	         "\"pbrMetallicRoughness\":{\"baseColorTexture\":%s,", texinfo);
	char *doc = subst(quad_doc(), "\"pbrMetallicRoughness\":{", buf);
	snprintf(buf, sizeof buf,
	         "\"textures\":[{\"source\":0%s}],"
	         "\"images\":[%s],\"materials\":[",
	         extra, images);
	return subst(doc, "\"materials\":[", buf);
}

static void test_double_sided_adds_back_faces(void **state)
{
	(void)state;
	char *doc = subst(quad_doc(), "\"name\":\"Lamp\",",
	                  "\"name\":\"Lamp\",\"doubleSided\":true,");
	rad_scene_counts c = load_counts(doc);
	assert_int_equal(c.polygons, 2); /* the square and its back */
	assert_int_equal(c.back_faces, 1);
	assert_int_equal(c.emitters, 2); /* it shines both ways */
	free(doc);
	doc = quad_doc();
	c = load_counts(doc);
	assert_int_equal(c.polygons, 1);
	assert_int_equal(c.back_faces, 0);
	free(doc);
}

/* What the import cannot honour is said: no light, glass. */
static void test_unlit_and_unread_are_noted(void **state)
{
	(void)state;
	char *doc = subst(quad_doc(), "\"emissiveFactor\":[1,0.5,0.25]",
	                  "\"emissiveFactor\":[0,0,0]");
	doc = subst(doc, "\"asset\":",
	            "\"extensionsUsed\":[\"KHR_materials_transmission\","
	            "\"KHR_texture_transform\"],\"asset\":");
	sio_info info;
	rad_scene *s = load_ok(doc, strlen(doc), &info);
	assert_non_null(strstr(info.warnings, "has no light"));
	assert_non_null(strstr(info.warnings, "not read (their surfaces are "
	                                      "taken as opaque diffuse "
	                                      "reflectors): "
	                                      "KHR_materials_transmission"));
	assert_null(strstr(info.warnings, "KHR_texture_transform"));
	rad_scene_free(s);
	free(doc);
	doc = quad_doc(); /* emissive: lit, and nothing to say */
	s = load_ok(doc, strlen(doc), &info);
	assert_null(strstr(info.warnings, "no light"));
	rad_scene_free(s);
	free(doc);
}

static void test_textures_read_or_explained(void **state)
{
	(void)state;
	/* Refused: what the document gets wrong. */
	static const struct {
		const char *texinfo, *images, *extra, *part;
	} bad[] = {
	        {"{\"index\":3}", "{\"uri\":\"" GREY_PNG "\"}", "",
	         "baseColorTexture 3 out of range"},
	        {"{\"index\":0}", "{\"uri\":\"" GREY_PNG "\"}",
	         ",\"sampler\":2", "sampler 2 out of range"},
	        {"{\"index\":0,\"extensions\":{\"KHR_texture_transform\":"
	         "{\"scale\":\"big\"}}}",
	         "{\"uri\":\"" GREY_PNG "\"}", "", "KHR_texture_transform"},
	};
	for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
		char *doc = textured_doc(bad[k].texinfo, bad[k].images,
		                         bad[k].extra);
		expect_fail(doc, strlen(doc), RAD_ERR_INVALID, bad[k].part);
		free(doc);
	}
	/* Read as the factor alone, with a note: what cannot be used. */
	static const struct {
		const char *images, *note;
	} unread[] = {
	        {"{\"uri\":\"" GREY_PNG "\"}", "lacks"}, /* no TEXCOORD_0 */
	        {"{\"uri\":\"grey.png\"}", "external file not read"},
	        {"{\"uri\":\"data:image/png;base64,AAAA\"}",
	         "neither PNG nor JPEG"},
	};
	for (size_t k = 0; k < sizeof unread / sizeof unread[0]; k++) {
		char *doc = textured_doc("{\"index\":0}", unread[k].images, "");
		sio_info info;
		rad_scene *s = load_ok(doc, strlen(doc), &info);
		const rad_material *m = &s->mats[poly0(s)->mat];
		assert_float_equal(m->rho[0], 0.5, 1e-6);
		if (!strstr(info.warnings, unread[k].note))
			fail_msg("case %zu: %s", k, info.warnings);
		assert_int_equal(info.textures_read, 0);
		assert_int_equal(info.textures_ignored, 1);
		rad_scene_free(s);
		free(doc);
	}
	/* Required KHR_texture_transform is understood; others are not. */
	char *doc =
	        textured_doc("{\"index\":0}", "{\"uri\":\"" GREY_PNG "\"}", "");
	char *req = subst(strdup(doc), "\"asset\":",
	                  "\"extensionsRequired\":[\"KHR_texture_transform\"],"
	                  "\"asset\":");
	rad_scene_free(load_ok(req, strlen(req), NULL));
	free(req);
	req = subst(doc, "\"asset\":",
	            "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],"
	            "\"asset\":");
	expect_fail(req, strlen(req), RAD_ERR_UNSUPPORTED,
	            "KHR_draco_mesh_compression");
	free(req);
}

static void test_nan_and_degenerate_triangles_are_counted(void **state)
{
	(void)state;
	/* The square, plus a triangle through a NaN vertex and a sliver. */
	float pos[18];
	memcpy(pos, quad_pos, sizeof quad_pos);
	const float extra[6] = {NAN, 0, 0, 0.5f, 0, 0};
	memcpy(pos + 12, extra, sizeof extra);
	static const uint32_t idx[] = {0, 1, 2, 0, 2, 3, 0, 1, 4, 0, 5, 1};
	char *doc = mesh_doc(pos, 6, idx, 12, 2, NULL);
	rad_scene_counts c = load_counts(doc);
	assert_int_equal(c.triangles_in, 4);
	assert_int_equal(c.triangles_nonfinite, 1);
	assert_int_equal(c.triangles_degenerate, 1);
	assert_int_equal(c.polygons, 1);
	free(doc);
}

/* -------------------------------------------------------------- lights */

static const char lights_doc[] =
        "\"extensionsUsed\":[\"KHR_lights_punctual\"],\"extensions\":"
        "{\"KHR_lights_punctual\":{\"lights\":["
        "{\"name\":\"bulb\",\"type\":\"point\",\"color\":[1,0.5,0.25],"
        "\"intensity\":100,\"range\":7},"
        "{\"type\":\"spot\",\"intensity\":50,"
        "\"spot\":{\"innerConeAngle\":0.2,\"outerConeAngle\":0.5}},"
        "{\"type\":\"directional\",\"intensity\":1000}]}},"
        "\"nodes\":[{\"name\":\"Panel\",\"mesh\":0},"
        "{\"name\":\"Bulb\",\"translation\":[1,2,3],\"extensions\":"
        "{\"KHR_lights_punctual\":{\"light\":0}}},"
        "{\"name\":\"Spot\",\"translation\":[0,3,0],"
        "\"rotation\":[-0.70710678118654752,0,0,0.70710678118654752],"
        "\"extensions\":{\"KHR_lights_punctual\":{\"light\":1}}},"
        "{\"name\":\"Sun\",\"extensions\":"
        "{\"KHR_lights_punctual\":{\"light\":2}}}],"
        "\"scenes\":[{\"nodes\":[0,1,2,3]}]}";

static char *with_lights(void)
{
	return subst(quad_doc(),
	             "\"nodes\":[{\"name\":\"Panel\",\"mesh\":0}],"
	             "\"scenes\":[{\"nodes\":[0]}]}",
	             lights_doc);
}

static void test_punctual_lights_are_placed_and_aimed(void **state)
{
	(void)state;
	char *doc = with_lights();
	rad_scene *s = load_ok(doc, strlen(doc), NULL);
	assert_int_equal(s->counts.lights, 3);
	const rad_light *b = &s->lights[0], *sp = &s->lights[1],
	                *sun = &s->lights[2];
	assert_int_equal(b->kind, RAD_LIGHT_POINT);
	assert_string_equal(b->name, "bulb");
	const double bpos[3] = {1, 2, 3}, bI[3] = {100, 50, 25};
	for (int k = 0; k < 3; k++) {
		assert_float_equal(b->pos[k], bpos[k], 1e-9);
		assert_float_equal(b->intensity[k], bI[k], 1e-9);
		assert_float_equal(sp->intensity[k], 50, 1e-9); /* white */
	}
	assert_float_equal(b->range, 7, 0);
	assert_int_equal(sp->kind, RAD_LIGHT_SPOT);
	assert_string_equal(sp->name, "Spot"); /* unnamed: the node's */
	assert_float_equal(sp->dir[1], -1.0, 1e-9);
	assert_float_equal(sp->cos_inner, cos(0.2), 1e-9);
	assert_float_equal(sp->cos_outer, cos(0.5), 1e-9);
	assert_int_equal(sun->kind, RAD_LIGHT_DIRECTIONAL);
	assert_float_equal(sun->dir[2], -1.0, 1e-9);
	assert_float_equal(sun->intensity[0], 1000, 1e-9);
	rad_scene_free(s);
	free(doc);
}

static void test_bad_lights_are_refused_by_name(void **state)
{
	(void)state;
	static const struct {
		const char *from, *to, *part;
	} cases[] = {
	        {",\"spot\":{\"innerConeAngle\":0.2,\"outerConeAngle\":0.5}",
	         "", "\"spot\" object"},
	        {"\"innerConeAngle\":0.2", "\"innerConeAngle\":0.7", "light 1"},
	        {"\"light\":2", "\"light\":3", "node 3 'Sun'"},
	        {"\"light\":2", "\"light\":\"x\"", "node 3 'Sun'"},
	        {"\"type\":\"directional\"", "\"type\":\"area\"",
	         "unknown type 'area'"},
	        {"\"color\":[1,0.5,0.25]", "\"color\":[1,0.5]", "light 0"},
	};
	for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
		char *doc = subst(with_lights(), cases[k].from, cases[k].to);
		expect_fail(doc, strlen(doc), RAD_ERR_INVALID, cases[k].part);
		free(doc);
	}
}

/* ----------------------------------------------------------- bad input */

static void test_empty_and_garbage_input_is_refused(void **state)
{
	(void)state;
	expect_fail(NULL, 0, RAD_ERR_INVALID, "empty");
	expect_fail("", 0, RAD_ERR_INVALID, "empty");
	static const char junk[] = "{\"asset\": {\"version\": \"2.0\"";
	expect_fail(junk, strlen(junk), RAD_ERR_INVALID, "malformed glTF");
	expect_fail("glTF", 4, RAD_ERR_INVALID, "truncated GLB");
	expect_fail("\x01\x02", 2, RAD_ERR_INVALID, "malformed glTF");
}

static void test_deep_nesting_is_refused_before_parsing(void **state)
{
	(void)state;
	/* 100,000 levels of "extras" overflow tinygltf's recursive copy. */
	size_t depth = 100000;
	char *doc = malloc(2 * depth + 64), *p = doc;
	assert_non_null(doc);
	p += sprintf(p, "{\"asset\":{\"version\":\"2.0\"},\"extras\":");
	memset(p, '[', depth);
	memset(p + depth, ']', depth);
	strcpy(p + 2 * depth, "}");
	expect_fail(doc, strlen(doc), RAD_ERR_INVALID, "JSON nests deeper");
	free(doc);
	/* Brackets inside strings (escaped quotes too) do not count. */
	doc = subst(quad_doc(), "\"Quad\"",
	            "\"[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[["
	            "[[[[[[[[[[[[[[\\\"[[[\"");
	rad_scene_free(load_ok(doc, strlen(doc), NULL));
	free(doc);
}

static void test_malformed_documents_name_the_culprit(void **state)
{
	(void)state;
	static const struct {
		const char *from, *to;
		rad_status want;
		const char *part;
	} cases[] = {
	        /* accessor, bufferView and buffer bounds */
	        {"\"count\":4", "\"count\":5", RAD_ERR_INVALID,
	         "POSITION accessor 0 (offset 0, count 5, stride 12) reads "
	         "past the end of bufferView 0"},
	        {"\"count\":4", "\"count\":4611686018427387904",
	         RAD_ERR_INVALID, "POSITION accessor 0"},
	        {"\"count\":4", "\"count\":4,\"byteOffset\":40",
	         RAD_ERR_INVALID, "reads past the end of bufferView 0"},
	        {"\"byteOffset\":48,\"byteLength\":12",
	         "\"byteOffset\":48,\"byteLength\":16", RAD_ERR_INVALID,
	         "bufferView 1 (offset 48, length 16) runs past the end of "
	         "buffer 0"},
	        {"{\"buffer\":0,\"byteLength\":48}",
	         "{\"buffer\":0,\"byteLength\":48,\"byteStride\":8}",
	         RAD_ERR_INVALID, "byteStride 8"},
	        {"{\"buffer\":0,\"byteLength\":48}",
	         "{\"buffer\":3,\"byteLength\":48}", RAD_ERR_INVALID,
	         "buffer 3 out of range"},
	        {"\"bufferView\":0", "\"bufferView\":9", RAD_ERR_INVALID,
	         "bufferView 9 out of range"},
	        {"\"byteLength\":60", "\"byteLength\":64", RAD_ERR_INVALID,
	         "buffer 0: the data: URI"},
	        /* types */
	        {"\"componentType\":5126", "\"componentType\":5123",
	         RAD_ERR_INVALID,
	         "mesh 0 'Quad' primitive 0: POSITION "
	         "accessor 0 must be VEC3 of FLOAT"},
	        {"\"type\":\"VEC3\"", "\"type\":\"VEC2\"", RAD_ERR_INVALID,
	         "POSITION accessor 0"},
	        {"\"componentType\":5123", "\"componentType\":5126",
	         RAD_ERR_INVALID, "index accessor 1 must be SCALAR"},
	        {"\"count\":6", "\"count\":5", RAD_ERR_INVALID,
	         "5 indices is not a multiple of 3"},
	        {"\"count\":4",
	         "\"count\":4,\"sparse\":{\"count\":1,"
	         "\"indices\":{\"bufferView\":1,"
	         "\"componentType\":5123},\"values\":"
	         "{\"bufferView\":0}}",
	         RAD_ERR_UNSUPPORTED, "accessor 0 is sparse"},
	        /* indices into the document's arrays */
	        {"\"indices\":1", "\"indices\":-4", RAD_ERR_INVALID,
	         "index accessor -4 out of range"},
	        {"\"POSITION\":0", "\"POSITION\":7", RAD_ERR_INVALID,
	         "POSITION accessor 7 out of range"},
	        {"\"material\":0", "\"material\":4", RAD_ERR_INVALID,
	         "material 4 out of range"},
	        {"\"mesh\":0", "\"mesh\":7", RAD_ERR_INVALID,
	         "node 0 'Panel': mesh 7 out of range"},
	        {"\"nodes\":[0]", "\"nodes\":[3]", RAD_ERR_INVALID,
	         "scene 0: node 3 out of range"},
	        {"\"scenes\"", "\"scene\":2,\"scenes\"", RAD_ERR_INVALID,
	         "default scene 2"},
	        {"\"mesh\":0", "\"mesh\":0,\"children\":[0]", RAD_ERR_INVALID,
	         "node 0 'Panel' is reached twice"},
	        {"\"mesh\":0", "\"mesh\":0,\"children\":[5]", RAD_ERR_INVALID,
	         "node 0 'Panel': child 5 out of range"},
	        /* materials: the builder's refusal names the glTF material */
	        {"\"emissiveStrength\":4", "\"emissiveStrength\":1e308",
	         RAD_ERR_INVALID, "material 0 'Lamp': material 0: luminance"},
	        {"\"emissiveStrength\":4", "\"emissiveStrength\":-1",
	         RAD_ERR_INVALID, "material 0 'Lamp': KHR_materials_emissive"},
	        /* transforms */
	        {"\"mesh\":0",
	         "\"mesh\":0,\"matrix\":[1e308,0,0,0,0,1e308,0,0,0,0,1e308,0,"
	         "0,0,0,1]",
	         RAD_ERR_INVALID, "node 0 'Panel': world transform"},
	        {"\"mesh\":0", "\"mesh\":0,\"scale\":[1,0,1]", RAD_ERR_INVALID,
	         "node 0 'Panel': world transform is singular"},
	        {"\"mesh\":0", "\"mesh\":0,\"matrix\":[1,0,0]", RAD_ERR_INVALID,
	         "matrix has 3 numbers"},
	        {"\"mesh\":0", "\"mesh\":0,\"rotation\":[0,0,0,0]",
	         RAD_ERR_INVALID, "rotation is not a usable quaternion"},
	        /* external resources */
	        {"\"scenes\"",
	         "\"extensionsRequired\":"
	         "[\"KHR_draco_mesh_compression\"],\"scenes\"",
	         RAD_ERR_UNSUPPORTED, "KHR_draco_mesh_compression"},
	};
	for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++)
		expect_doc_fail(cases[k].from, cases[k].to, cases[k].want,
		                cases[k].part);
}

static void test_index_beyond_the_vertices_is_named(void **state)
{
	(void)state;
	static const uint32_t idx[] = {0, 1, 2, 0, 9, 3};
	char *doc = mesh_doc(quad_pos, 4, idx, 6, 2, NULL);
	expect_fail(doc, strlen(doc), RAD_ERR_INVALID,
	            "mesh 0 'Quad' primitive 0: index 9 (at position 4) >= "
	            "vertex count 4");
	free(doc);
}

static void test_external_uris_are_refused(void **state)
{
	(void)state;
	static const char *uris[] = {"file.bin", "../../etc/passwd",
	                             "/etc/passwd", "%2E%2E/secret.bin"};
	for (size_t k = 0; k < sizeof uris / sizeof uris[0]; k++) {
		char *doc = mesh_doc(quad_pos, 4, quad_idx, 6, 2, uris[k]);
		char part[96];
		snprintf(part, sizeof part, "buffer 0: external URI '%s",
		         k == 3 ? "../secret.bin" : uris[k]);
		expect_fail(doc, strlen(doc), RAD_ERR_INVALID, part);
		free(doc);
	}
	char *doc = subst(quad_doc(), "\"uri\"", "\"name\"");
	expect_fail(doc, strlen(doc), RAD_ERR_INVALID, "buffer 0 has no uri");
	free(doc);
}

/* ------------------------------------------------------------- export */

/* A lit floor (indexed, with colours and lux), a lamp, three lights. */
static rad_status write_sample(sio_format fmt, void **out, size_t *len)
{
	static const float color[12] = {1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
	static const float lux[4] = {10, 20, 30, 40};
	static const float lamp[9] = {0, 0, 2, 0, 1, 2, 1, 0, 2};
	sio_mesh m[3] = {
	        {.name = "Floor",
	         .position = quad_pos,
	         .color = color,
	         .illuminance = lux,
	         .index = quad_idx,
	         .nvertices = 4,
	         .nindices = 6,
	         .base_color = {0.5, 0.5, 0.5},
	         .emissive_strength = 1},
	        {.name = "Lamp",
	         .position = lamp,
	         .nvertices = 3,
	         .base_color = {0.2, 0.2, 0.2},
	         .emissive = {2, 1, 0.5},
	         .emissive_strength = 1},
	        {.name = "Empty"}, /* nothing to draw: left out */
	};
	rad_light_desc l[3] = {
	        {.kind = RAD_LIGHT_POINT,
	         .position = {0.5, 0.5, 1},
	         .intensity = {30, 20, 10},
	         .range = 5,
	         .name = "bulb"},
	        {.kind = RAD_LIGHT_SPOT,
	         .position = {0, 0, 3},
	         .direction = {0.6, 0, -0.8},
	         .intensity = {5, 5, 5},
	         .inner_cone = 0.1,
	         .outer_cone = 0.4},
	        {.kind = RAD_LIGHT_DIRECTIONAL,
	         .direction = {0, 0, 1},
	         .intensity = {100, 100, 100}},
	};
	rad_error err = {0};
	rad_status st = sio_write(m, 3, l, 3, fmt, out, len, &err);
	if (st != RAD_OK)
		fail_msg("write: %s", err.msg);
	return st;
}

static void check_sample(const rad_scene *s)
{
	assert_int_equal(s->counts.triangles_in, 3);
	assert_int_equal(s->counts.polygons, 2);
	assert_int_equal(s->counts.materials, 2);
	assert_int_equal(s->counts.emitters, 1);
	assert_int_equal(s->counts.lights, 3);
	assert_int_equal(s->counts.nodes, 2);
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_material *m = &s->mats[s->polys[i].mat];
		if (m->emit[0] > 0) { /* factor 2 folded into the strength */
			assert_float_equal(m->emit[0], M_PI * 2, 1e-4);
			assert_float_equal(m->emit[2], M_PI * 0.5, 1e-4);
		}
	}
	const rad_light *sp = &s->lights[1], *sun = &s->lights[2];
	assert_float_equal(s->lights[0].intensity[1], 20, 1e-9);
	assert_float_equal(s->lights[0].range, 5, 1e-9);
	assert_float_equal(sp->dir[0], 0.6, 1e-9);
	assert_float_equal(sp->dir[2], -0.8, 1e-9);
	assert_float_equal(sp->pos[2], 3, 1e-9);
	assert_float_equal(sp->cos_outer, cos(0.4), 1e-9);
	assert_float_equal(sun->dir[2], 1.0, 1e-9); /* the half-turn case */
}

static void test_glb_and_json_round_trip(void **state)
{
	(void)state;
	void *glb, *json;
	size_t nglb, njson;
	write_sample(SIO_FORMAT_GLB, &glb, &nglb);
	write_sample(SIO_FORMAT_JSON, &json, &njson);
	assert_memory_equal(glb, "glTF", 4);
	assert_int_equal(nglb % 4, 0);
	assert_int_equal(((const char *)json)[0], '{');
	assert_non_null(memmem(json, njson, "_ILLUMINANCE", 12));
	assert_non_null(
	        memmem(json, njson, "KHR_materials_emissive_strength", 31));
	sio_info info;
	rad_scene *a = load_ok(glb, nglb, &info),
	          *b = load_ok(json, njson, NULL);
	assert_int_equal(info.meshes, 2);
	assert_int_equal(info.warnings[0], '\0');
	check_sample(a);
	check_sample(b);
	assert_memory_equal(&a->counts, &b->counts, sizeof a->counts);
	rad_scene_free(a);
	rad_scene_free(b);
	free(glb);
	free(json);
}

static void test_write_refuses_invalid_meshes_and_lights(void **state)
{
	(void)state;
	static const uint32_t bad_idx[] = {0, 1, 7};
	float nan_pos[12];
	memcpy(nan_pos, quad_pos, sizeof nan_pos);
	nan_pos[4] = NAN;
	sio_mesh m[3] = {
	        {.name = "A",
	         .position = quad_pos,
	         .index = bad_idx,
	         .nvertices = 4,
	         .nindices = 3,
	         .emissive_strength = 1},
	        {.name = "B",
	         .position = nan_pos,
	         .index = quad_idx,
	         .nvertices = 4,
	         .nindices = 6,
	         .emissive_strength = 1},
	        {.name = "C",
	         .position = quad_pos,
	         .index = quad_idx,
	         .nvertices = 4,
	         .nindices = 6,
	         .base_color = {1.5, 0, 0},
	         .emissive_strength = 1},
	};
	static const char *want[] = {"mesh 0 'A': index 7 (at position 2)",
	                             "mesh 0 'B': a position",
	                             "mesh 0 'C': base_color"};
	void *out = (void *)1;
	size_t len = 1;
	rad_error err;
	for (int k = 0; k < 3; k++) {
		assert_int_equal(sio_write(&m[k], 1, NULL, 0, SIO_FORMAT_GLB,
		                           &out, &len, &err),
		                 RAD_ERR_INVALID);
		assert_non_null(strstr(err.msg, want[k]));
		assert_null(out);
	}
	rad_light_desc l = {.kind = RAD_LIGHT_SPOT,
	                    .direction = {0, 0, -1},
	                    .inner_cone = 0.5,
	                    .outer_cone = 0.5};
	assert_int_equal(
	        sio_write(NULL, 0, &l, 1, SIO_FORMAT_JSON, &out, &len, &err),
	        RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "light 0"));
}

/* ---------------------------------------------------------------- GLB */

static void put32(unsigned char *p, uint32_t v)
{
	for (int k = 0; k < 4; k++)
		p[k] = (unsigned char)(v >> 8 * k);
}

static void test_broken_glb_containers_are_refused(void **state)
{
	(void)state;
	void *glb;
	size_t n;
	write_sample(SIO_FORMAT_GLB, &glb, &n);
	unsigned char *b = malloc(n);
	assert_non_null(b);

	memcpy(b, glb, n);
	expect_fail(b, 30, RAD_ERR_INVALID, "GLB header gives a length");
	expect_fail(b, 12, RAD_ERR_INVALID, "truncated GLB");
	put32(b + 8, (uint32_t)n + 4);
	expect_fail(b, n, RAD_ERR_INVALID, "GLB header gives a length");

	memcpy(b, glb, n);
	put32(b + 4, 1);
	expect_fail(b, n, RAD_ERR_UNSUPPORTED, "GLB container version 1");

	/* A BIN chunk claiming the 8 bytes after the file (tinygltf 2.7.0
	 * would read them). */
	memcpy(b, glb, n);
	uint32_t jlen =
	        (uint32_t)b[12] | (uint32_t)b[13] << 8 | (uint32_t)b[14] << 16;
	uint32_t blen = (uint32_t)(n - 28 - jlen);
	put32(b + 20 + jlen, blen + 8);
	expect_fail(b, n, RAD_ERR_INVALID, "inside the file (length");

	memcpy(b, glb, n);
	put32(b + 16, 0x12345678);
	expect_fail(b, n, RAD_ERR_INVALID, "first chunk must be JSON");
	free(b);
	free(glb);
}

/*
 * Deterministic mutations of a valid GLB (byte flips, truncations) and of
 * a valid .gltf (digits changed, which moves indices, counts and
 * offsets): none may crash, hang or leak (ASan); each either loads or
 * fails with a message.
 */
static void try_mutant(const unsigned char *b, size_t n)
{
	rad_scene *s = NULL;
	rad_error err = {0};
	rad_status st = sio_load(b, n, &s, NULL, NULL, NULL, &err);
	if (st == RAD_OK) {
		assert_non_null(s);
		rad_scene_free(s);
	} else {
		assert_null(s);
		assert_true(err.msg[0] != '\0');
	}
}

static uint32_t lcg(uint32_t *x)
{
	*x = *x * 1664525u + 1013904223u;
	return *x >> 8;
}

static void test_mutated_inputs_never_crash(void **state)
{
	(void)state;
	void *glb;
	size_t n;
	write_sample(SIO_FORMAT_GLB, &glb, &n);
	char *doc = with_lights();
	size_t nd = strlen(doc);
	unsigned char *b = malloc(n > nd ? n : nd);
	assert_non_null(b);
	uint32_t x = 12345;
	for (int it = 0; it < 120; it++) {
		memcpy(b, glb, n);
		size_t len = n;
		if (it % 4 == 3)
			len = lcg(&x) % n;
		else
			for (int k = 0; k <= it % 3; k++)
				b[lcg(&x) % n] ^=
				        (unsigned char)(1 + lcg(&x) % 255);
		try_mutant(b, len);
	}
	for (int it = 0; it < 100; it++) {
		memcpy(b, doc, nd);
		for (int k = 0; k < 2; k++) {
			size_t at = lcg(&x) % nd;
			while (at < nd && (b[at] < '0' || b[at] > '9'))
				at++;
			if (at < nd)
				b[at] = (unsigned char)('0' + lcg(&x) % 10);
		}
		try_mutant(b, nd);
	}
	free(b);
	free(doc);
	free(glb);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_quad_loads_as_one_emissive_parallelogram),
	        cmocka_unit_test(test_u8_and_u32_indices_load_like_u16),
	        cmocka_unit_test(
	                test_non_indexed_strip_and_fan_cover_the_square),
	        cmocka_unit_test(test_points_and_lines_are_skipped_and_counted),
	        cmocka_unit_test(test_nested_trs_and_matrix_transforms),
	        cmocka_unit_test(test_mirroring_keeps_the_front_side),
	        cmocka_unit_test(test_materials_default_clamp_and_counters),
	        cmocka_unit_test(test_textures_read_or_explained),
	        cmocka_unit_test(test_unlit_and_unread_are_noted),
	        cmocka_unit_test(test_double_sided_adds_back_faces),
	        cmocka_unit_test(test_nan_and_degenerate_triangles_are_counted),
	        cmocka_unit_test(test_punctual_lights_are_placed_and_aimed),
	        cmocka_unit_test(test_bad_lights_are_refused_by_name),
	        cmocka_unit_test(test_empty_and_garbage_input_is_refused),
	        cmocka_unit_test(test_deep_nesting_is_refused_before_parsing),
	        cmocka_unit_test(test_malformed_documents_name_the_culprit),
	        cmocka_unit_test(test_index_beyond_the_vertices_is_named),
	        cmocka_unit_test(test_external_uris_are_refused),
	        cmocka_unit_test(test_glb_and_json_round_trip),
	        cmocka_unit_test(test_write_refuses_invalid_meshes_and_lights),
	        cmocka_unit_test(test_broken_glb_containers_are_refused),
	        cmocka_unit_test(test_mutated_inputs_never_crash),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
