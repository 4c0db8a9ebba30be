/*
 * test_pack.c -- scenes as exporters write them: a .gltf beside its .bin
 * and images, packed into one GLB (daemon/sceneio/pack.c) and loaded.
 *
 * A real Blender export ("glTF Separate", ../shared/scenes/real/) loads
 * unmodified from its folder; a one-triangle scene written here in a
 * scratch folder loads the same whether its buffer is a file or a data:
 * URI; and every path that would leave the folder is refused with a
 * message naming the buffer: "..", an absolute path, a percent-encoded
 * "..", a scheme, a symbolic link out of the folder, a missing file, a
 * file shorter than byteLength.  Images are packed, PNG and JPEG only;
 * one left unpacked is reported in our words.  A Git LFS pointer (what a
 * clone without git-lfs holds) in place of a buffer, an image or the
 * scene file itself is named as one.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "sceneio.h"

#define REAL LUXRAD_SOURCE_DIR "/../shared/scenes/real/vinc3r-cornellbox"

/* One triangle, z = 0, facing +z: 3 float32 vertices. */
static const float tri[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};

/* The document, with the buffer's uri, its byteLength and the images
 * array filled in. */
static const char doc_fmt[] =
        "{\"asset\":{\"version\":\"2.0\"},\"scene\":0,"
        "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}],"
        "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
        "\"material\":0}]}],"
        "\"materials\":[{\"pbrMetallicRoughness\":{\"baseColorFactor\":"
        "[0.5,0.5,0.5,1]},\"emissiveFactor\":[1,1,1]}],"
        "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,"
        "\"count\":3,\"type\":\"VEC3\",\"min\":[0,0,0],\"max\":[1,1,0]}],"
        "\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],"
        "\"buffers\":[{\"uri\":\"%s\",\"byteLength\":%d}]%s}";

/* A Git LFS pointer file, as a clone without git-lfs has it. */
static const char lfs[] =
        "version https://git-lfs.github.com/spec/v1\n"
        "oid sha256:"
        "3e56584aaa453e1c72226646de4af1f777d69f01d497d7a26cf806c8005ea322\n"
        "size 108\n";

typedef struct scratch {
	char dir[64];   /* the scene's folder */
	char other[64]; /* a folder beside it */
	char path[160]; /* the .gltf */
} scratch;

static void put(const char *path, const void *b, size_t n)
{
	FILE *f = fopen(path, "wb");
	assert_non_null(f);
	assert_int_equal(fwrite(b, 1, n, f), n);
	assert_int_equal(fclose(f), 0);
}

static int setup(void **state)
{
	scratch *s = calloc(1, sizeof(*s));
	snprintf(s->dir, sizeof(s->dir), "/tmp/luxrad-pack-XXXXXX");
	snprintf(s->other, sizeof(s->other), "/tmp/luxrad-pack-out-XXXXXX");
	assert_non_null(mkdtemp(s->dir));
	assert_non_null(mkdtemp(s->other));
	snprintf(s->path, sizeof(s->path), "%s/scene.gltf", s->dir);
	char p[200];
	snprintf(p, sizeof(p), "%s/tri.bin", s->dir);
	put(p, tri, sizeof(tri));
	snprintf(p, sizeof(p), "%s/short.bin", s->dir);
	put(p, tri, 20);
	snprintf(p, sizeof(p), "%s/tri.bin", s->other);
	put(p, tri, sizeof(tri));
	snprintf(p, sizeof(p), "%s/link.bin", s->dir);
	char target[200];
	snprintf(target, sizeof(target), "%s/tri.bin", s->other);
	assert_int_equal(symlink(target, p), 0);
	snprintf(p, sizeof(p), "%s/img.png", s->dir);
	put(p, "\x89PNG not decoded", 16);
	snprintf(p, sizeof(p), "%s/img.gif", s->dir);
	put(p, "GIF89a", 6);
	snprintf(p, sizeof(p), "%s/lfs.bin", s->dir);
	put(p, lfs, strlen(lfs));
	snprintf(p, sizeof(p), "%s/lfs.png", s->dir);
	put(p, lfs, strlen(lfs));
	snprintf(p, sizeof(p), "%s/lfs.glb", s->dir);
	put(p, lfs, strlen(lfs));
	*state = s;
	return 0;
}

static int teardown(void **state)
{
	scratch *s = *state;
	char cmd[200];
	snprintf(cmd, sizeof(cmd), "rm -rf '%s' '%s'", s->dir, s->other);
	assert_int_equal(system(cmd), 0);
	free(s);
	return 0;
}

/* Write the scene with this buffer uri and images, load it. */
static rad_status load(scratch *s, const char *uri, int byte_length,
                       const char *images, rad_scene **sc, rad_error *err)
{
	char doc[4096];
	snprintf(doc, sizeof(doc), doc_fmt, uri, byte_length, images);
	put(s->path, doc, strlen(doc));
	*sc = NULL;
	return sio_load_file(s->path, sc, NULL, err);
}

static void expect_refused(scratch *s, const char *uri, rad_status want,
                           const char *words)
{
	rad_scene *sc;
	rad_error err = {0};
	assert_int_equal(load(s, uri, 36, "", &sc, &err), want);
	assert_null(sc);
	if (!strstr(err.msg, words))
		fail_msg("uri '%s': \"%s\" lacks \"%s\"", uri, err.msg, words);
	assert_non_null(strstr(err.msg, "buffer 0"));
}

/* ----------------------------------------------------------------- tests */

static void test_blender_export_loads_from_its_folder(void **state)
{
	(void)state;
	static const char *const files[] = {
	        REAL "/BJS-2.79-Cycles-gltf/cornellBox-2.79-Cycles-gltf.gltf",
	        REAL "/BJS-2.80-Eevee-gltf/cornellBox-2.80-Eevee-gltf.gltf"};
	for (int i = 0; i < 2; i++) {
		rad_scene *sc = NULL;
		rad_error err = {0};
		sio_info info;
		if (sio_load_file(files[i], &sc, &info, &err) != RAD_OK)
			fail_msg("%s: %s", files[i], err.msg);
		rad_scene_counts c;
		rad_scene_counts_get(sc, &c);
		assert_int_equal(c.polygons, 4335);
		assert_int_equal(c.emitters, 5);
		/* The textures were packed and found: nothing was looked
		 * for on disk by the parser. */
		assert_null(strstr(info.warnings, "File not found"));
		rad_scene_free(sc);
	}
}

static void test_file_and_data_uri_give_one_scene(void **state)
{
	scratch *s = *state;
	rad_scene *a, *b;
	rad_error err = {0};
	assert_int_equal(load(s, "tri.bin", 36, "", &a, &err), RAD_OK);
	/* The same bytes as a data: URI (base64 of the 9 floats). */
	static const char data[] =
	        "data:application/octet-stream;base64,"
	        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
	assert_int_equal(load(s, data, 36, "", &b, &err), RAD_OK);
	double alo[3], ahi[3], blo[3], bhi[3];
	rad_scene_bounds(a, alo, ahi);
	rad_scene_bounds(b, blo, bhi);
	assert_memory_equal(alo, blo, sizeof(alo));
	assert_memory_equal(ahi, bhi, sizeof(ahi));
	rad_scene_counts ca, cb;
	rad_scene_counts_get(a, &ca);
	rad_scene_counts_get(b, &cb);
	assert_int_equal(ca.polygons, 1);
	assert_int_equal(cb.polygons, 1);
	assert_true(ahi[0] == 1.0 && ahi[1] == 1.0);
	rad_scene_free(a);
	rad_scene_free(b);
}

static void test_paths_out_of_the_folder_are_refused(void **state)
{
	scratch *s = *state;
	char abs[200];
	snprintf(abs, sizeof(abs), "%s/tri.bin", s->other);
	expect_refused(s, "../tri.bin", RAD_ERR_INVALID, "leaves the scene");
	expect_refused(s, abs, RAD_ERR_INVALID, "leaves the scene");
	expect_refused(s, "sub%2F..%2F..%2Ftri.bin", RAD_ERR_INVALID,
	               "leaves the scene");
	expect_refused(s, "file:///etc/hostname", RAD_ERR_INVALID,
	               "is not read");
	expect_refused(s, "link.bin", RAD_ERR_INVALID, "resolves outside");
	expect_refused(s, "missing.bin", RAD_ERR_IO, "not found beside");
	expect_refused(s, "short.bin", RAD_ERR_INVALID, "byteLength says 36");
}

static void test_images_are_packed_png_and_jpeg_only(void **state)
{
	scratch *s = *state;
	char doc[4096], dir[80];
	snprintf(doc, sizeof(doc), doc_fmt, "tri.bin", 36,
	         ",\"images\":[{\"uri\":\"img.png\"}]");
	snprintf(dir, sizeof(dir), "%s", s->dir);
	unsigned char *glb = NULL;
	size_t n = 0;
	sio_pack_info info;
	rad_error err = {0};
	assert_int_equal(sio_pack((const unsigned char *)doc, strlen(doc), dir,
	                          &glb, &n, &info, &err),
	                 RAD_OK);
	assert_true(sio_is_glb(glb, n));
	assert_int_equal(info.buffers_read, 1);
	assert_int_equal(info.images_read, 1);
	/* The JSON chunk names the image's bufferView and type, no uri; the
	 * unnamed image is named by its file, for messages. */
	assert_non_null(memmem(glb, n, "\"mimeType\":\"image/png\"", 22));
	assert_null(memmem(glb, n, "\"uri\"", 5));
	assert_non_null(memmem(glb, n, "\"name\":\"img.png\"", 16));
	free(glb);

	rad_scene *sc;
	assert_int_equal(load(s, "tri.bin", 36,
	                      ",\"images\":[{\"uri\":\"img.gif\"}]", &sc, &err),
	                 RAD_ERR_UNSUPPORTED);
	assert_non_null(strstr(err.msg, "image 0"));
}

/* Git LFS pointers are named, whether longer or shorter than the buffer's
 * byteLength (a shorter one used to read as index garbage); an image that
 * is one is skipped with a warning that says so; a scene file that is one
 * is refused. */
static void test_git_lfs_pointers_are_named(void **state)
{
	scratch *s = *state;
	expect_refused(s, "lfs.bin", RAD_ERR_INVALID, "Git LFS pointer");
	rad_scene *sc;
	rad_error err = {0};
	assert_int_equal(load(s, "lfs.bin", 756, "", &sc, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "'lfs.bin' is a Git LFS pointer"));

	char doc[4096];
	snprintf(doc, sizeof(doc), doc_fmt, "tri.bin", 36,
	         ",\"images\":[{\"uri\":\"lfs.png\"}],"
	         "\"textures\":[{\"source\":0}]");
	/* The material uses the texture: put it in after the factor. */
	char *m = strstr(doc, "\"baseColorFactor\"");
	assert_non_null(m);
	char with[4096];
	snprintf(with, sizeof(with),
	         "%.*s\"baseColorTexture\":{\"index\":0},%s", (int)(m - doc),
	         doc, m);
	put(s->path, with, strlen(with));
	sio_info info;
	sc = NULL;
	assert_int_equal(sio_load_file(s->path, &sc, &info, &err), RAD_OK);
	if (!strstr(info.warnings, "'lfs.png' not read (a Git LFS pointer"))
		fail_msg("warnings \"%s\"", info.warnings);
	rad_scene_free(sc);

	char glb[200];
	snprintf(glb, sizeof(glb), "%s/lfs.glb", s->dir);
	assert_int_equal(sio_load_file(glb, &sc, NULL, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "the scene file is a Git LFS pointer"));
}

/* Edge documents: an empty buffer packs (nothing read), a top level that
 * is not an object is refused by name. */
static void test_edge_documents(void **state)
{
	scratch *s = *state;
	char doc[4096];
	unsigned char *glb = NULL;
	size_t n = 0;
	rad_error err = {0};
	snprintf(doc, sizeof(doc), doc_fmt, "missing.bin", 0, "");
	assert_int_equal(sio_pack((const unsigned char *)doc, strlen(doc),
	                          s->dir, &glb, &n, NULL, &err),
	                 RAD_OK);
	assert_true(sio_is_glb(glb, n));
	free(glb);
	assert_int_equal(sio_pack((const unsigned char *)"[]", 2, s->dir, &glb,
	                          &n, NULL, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "not a glTF document"));
	assert_null(glb);
}

/* Raw bytes (as the daemon gets them) with an external image: loaded,
 * the image reported in our words, not tinygltf's "File not found". */
static void test_unpacked_image_is_reported_plainly(void **state)
{
	(void)state;
	static const char data[] =
	        "data:application/octet-stream;base64,"
	        "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA";
	char doc[4096];
	snprintf(doc, sizeof(doc), doc_fmt, data, 36,
	         ",\"images\":[{\"uri\":\"img.png\"}]");
	rad_scene *sc = NULL;
	sio_info info;
	rad_error err = {0};
	assert_int_equal(sio_load((const unsigned char *)doc, strlen(doc), &sc,
	                          &info, NULL, NULL, &err),
	                 RAD_OK);
	assert_non_null(strstr(info.warnings, "1 image with an external file "
	                                      "not read"));
	assert_null(strstr(info.warnings, "File not found"));
	rad_scene_free(sc);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_blender_export_loads_from_its_folder),
	        cmocka_unit_test_setup_teardown(
	                test_file_and_data_uri_give_one_scene, setup, teardown),
	        cmocka_unit_test_setup_teardown(
	                test_paths_out_of_the_folder_are_refused, setup,
	                teardown),
	        cmocka_unit_test_setup_teardown(
	                test_images_are_packed_png_and_jpeg_only, setup,
	                teardown),
	        cmocka_unit_test_setup_teardown(test_git_lfs_pointers_are_named,
	                                        setup, teardown),
	        cmocka_unit_test_setup_teardown(test_edge_documents, setup,
	                                        teardown),
	        cmocka_unit_test(test_unpacked_image_is_reported_plainly),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
