/*
 * fuzz_gltf.c -- the glTF loader on an uploaded scene's bytes.
 *
 * The input is a scene.upload payload: a .gltf with embedded data: URIs
 * or a .glb.  It goes through srv_scene_load, the call the daemon makes
 * for an upload and again for every stored scene at a restart
 * (daemon/server/core/scenes.c): sio_load with every output -- the
 * precheck, tinygltf's parse, the walk, meshes and accessors, materials
 * with their base colour textures decoded (PNG, JPEG) and averaged under
 * each triangle (KHR_texture_transform, samplers), emissive strength,
 * KHR_lights_punctual lights with a photometric file packed in a node's
 * extras (IES, EULUMDAT), sensor nodes -- then the scene committed (the
 * BVH built) and its counts, bounds and memory read.  The reply the
 * upload gets (srv_scene_json) is built and encoded as a frame, and the
 * scene is freed.
 *
 * Checked, besides memory safety and leaks: a refused document has an
 * error code and a message; an accepted one gives the engine only sane
 * polygons (3 or 4 finite corners, a unit normal, a positive area,
 * reflectance in [0, 1), finite non-negative luminance, a node that
 * exists) and sane sensors (a short printable unique name, a finite
 * position, a unit normal); loading the sensors alone (sio_load without
 * a scene) gives the same sensors; and the upload's reply encodes, with
 * its warnings.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "fuzz.h"
#include "rp.h"
#include "sceneio.h"

static int finite3(const double v[3])
{
	return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static int unit3(const double v[3])
{
	double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	return fabs(n - 1) < 1e-6;
}

static void check_polygons(const rad_scene *s, const rad_scene_counts *c)
{
	for (uint32_t i = 0; i < c->polygons; i++) {
		rad_polygon_desc p;
		rad_error err;
		FUZZ_CHECK(rad_scene_polygon_get(s, i, &p, &err) == RAD_OK,
		           "every polygon counted can be read");
		FUZZ_CHECK(p.ncorners == 3 || p.ncorners == 4,
		           "a polygon has 3 or 4 corners");
		for (int k = 0; k < p.ncorners; k++)
			FUZZ_CHECK(finite3(p.corners[k]),
			           "a polygon's corners are finite");
		FUZZ_CHECK(unit3(p.normal), "a polygon's normal is a unit");
		FUZZ_CHECK(isfinite(p.area) && p.area > 0,
		           "a polygon's area is positive");
		FUZZ_CHECK(p.node < c->nodes &&
		                   rad_scene_node_name(s, p.node) != NULL,
		           "a polygon's node exists");
		for (int k = 0; k < 3; k++) {
			FUZZ_CHECK(p.reflectance[k] >= 0 &&
			                   p.reflectance[k] < 1,
			           "a reflectance is in [0, 1)");
			FUZZ_CHECK(isfinite(p.luminance[k]) &&
			                   p.luminance[k] >= 0,
			           "a luminance is finite and not negative");
		}
	}
}

static void check_sensors(const sio_sensor *s, size_t n)
{
	for (size_t i = 0; i < n; i++) {
		size_t len = strnlen(s[i].name, SIO_SENSOR_NAME_MAX);
		FUZZ_CHECK(len > 0 && len < SIO_SENSOR_NAME_MAX,
		           "a sensor's name is 1 to 63 bytes");
		for (size_t k = 0; k < len; k++)
			FUZZ_CHECK((unsigned char)s[i].name[k] >= 0x20 &&
			                   s[i].name[k] != 0x7f,
			           "a sensor's name has no control character");
		for (size_t j = 0; j < i; j++)
			FUZZ_CHECK(strcmp(s[i].name, s[j].name) != 0,
			           "sensor names are unique");
		FUZZ_CHECK(finite3(s[i].position) && unit3(s[i].normal),
		           "a sensor has a finite position and a unit normal");
	}
}

/* sio_load without a scene finds the same sensors. */
static void check_sensors_alone(const uint8_t *data, size_t size,
                                const srv_scene *sc)
{
	sio_sensor *s = NULL;
	size_t n = 0;
	rad_error err;

	FUZZ_CHECK(sio_load(data, size, NULL, NULL, &s, &n, &err) == RAD_OK,
	           "a scene's sensors load alone");
	FUZZ_CHECK(n == sc->nsensors, "the sensors alone are as many");
	for (size_t i = 0; i < n; i++)
		FUZZ_CHECK(!strcmp(s[i].name, sc->sensors[i].name) &&
		                   s[i].node == sc->sensors[i].node &&
		                   !memcmp(s[i].position,
		                           sc->sensors[i].position,
		                           sizeof s[i].position) &&
		                   !memcmp(s[i].normal, sc->sensors[i].normal,
		                           sizeof s[i].normal),
		           "the sensors alone are the same");
	sio_sensors_free(s);
}

/* scene.upload's reply body, sent as a frame. */
static void check_reply(const srv_scene *sc)
{
	json_t *body = srv_scene_json(sc);
	unsigned char *buf;
	size_t len;

	FUZZ_CHECK(json_is_string(json_object_get(body, "warnings")),
	           "the upload's reply has its warnings");
	FUZZ_CHECK(rp_frame_encode(body, NULL, 0, &buf, &len) == 0,
	           "the upload's reply encodes");
	free(buf);
	json_decref(body);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	rad_error err;
	srv_scene *sc = srv_scene_load(1, "fuzz", 0, data, size, &err);

	if (!sc) {
		FUZZ_CHECK(err.code != RAD_OK && err.msg[0],
		           "a refused scene has an error and says why");
		return 0;
	}
	check_polygons(sc->scene, &sc->counts);
	check_sensors(sc->sensors, sc->nsensors);
	check_sensors_alone(data, size, sc);
	check_reply(sc);
	srv_scene_unref(sc);
	return 0;
}
