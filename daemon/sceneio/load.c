/*
 * load.c -- sio_load: one import from bytes to a committed engine scene
 * and the document's sensors, with one parse and one walk.
 *
 * DESIGN
 *  - Order: the raw bytes are prechecked (precheck.c), parsed by the shim
 *    (gltf_shim.cc), the required extensions checked, then one walk of the
 *    default scene (walk.c) visits each node once, for the scene
 *    (import.c) and for the sensors (sensors.c); last the scene is
 *    committed.
 *  - A document that fails as a scene reports the scene's error, even
 *    when a sensor declaration fails earlier in the walk: a sensor error
 *    is kept aside and reported only once the scene has committed.  With
 *    no scene asked for, the first sensor error ends the walk.
 *  - On any failure every output is empty and nothing is leaked.
 *  - Heap traffic: the engine's memory figures count malloc_usable_size,
 *    so they depend on what else is allocated between the engine's own
 *    allocations.  An import keeps them as they were measured: the shim's
 *    C view is off the heap (pages of its own), extension members are
 *    looked up with tinygltf's own lookups as the walk reaches them, and
 *    scratch comes and goes at the same points (walk.c; import.c:
 *    positions per primitive, the batch and material table until after
 *    the commit).  Sensors are new to the walk: a scene that declares
 *    some can read a few bytes differently.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

/* The extensions the import reads. */
static const char *const read_exts[] = {SIO_LIGHTS_EXT, SIO_STRENGTH_EXT,
                                        SIO_TRANSFORM_EXT};
/* Extensions that change nothing a diffuse solver reads. */
static const char *const moot_exts[] = {
        "KHR_materials_specular",  "KHR_materials_ior",
        "KHR_materials_clearcoat", "KHR_materials_sheen",
        "KHR_materials_unlit",     "KHR_mesh_quantization"};

static int listed(sio_str ext, const char *const *list, size_t n)
{
	for (size_t k = 0; k < n; k++)
		if (sio_str_is(ext, list[k]))
			return 1;
	return 0;
}

#define LISTED(ext, list) listed(ext, list, sizeof list / sizeof list[0])

/* Refuse documents that need an extension we do not implement. */
static rad_status check_required(const sio_doc *d, rad_error *err)
{
	for (size_t k = 0; k < d->nrequired; k++)
		if (!LISTED(d->required[k], read_exts))
			return rad_fail(err, RAD_ERR_UNSUPPORTED,
			                "extensionsRequired: '%s' is not "
			                "supported",
			                d->required[k].s);
	return RAD_OK;
}

/* Say which extensions the document uses that the import does not read
 * (transmission, volume...): their surfaces are taken as opaque and
 * diffuse, which the user should know. */
static void note_unread(const sio_doc *d, sio_info *info)
{
	char list[256] = "";
	size_t n = 0;
	for (size_t k = 0; k < d->nused && n + 1 < sizeof list; k++) {
		if (LISTED(d->used[k], read_exts) ||
		    LISTED(d->used[k], moot_exts))
			continue;
		int w = snprintf(list + n, sizeof list - n, "%s%.60s",
		                 n ? ", " : "", d->used[k].s);
		if (w < 0)
			break;
		n += (size_t)w;
	}
	if (list[0])
		sio_note(info,
		         "extensions used but not read (their surfaces are "
		         "taken as opaque diffuse reflectors): %s",
		         list);
}

/* The info counters that depend on the document alone. */
static void count_document(const sio_doc *d, sio_info *info)
{
	if (!info)
		return;
	for (size_t k = 0; k < d->nmaterials; k++) {
		info->textures_ignored += d->materials[k].textures;
		info->metallic_materials += d->materials[k].metallic > 0;
	}
	info->meshes = (uint32_t)d->nmeshes;
}

/* One walk: the scene (when built) and the sensors (when asked for). */
typedef struct pass {
	sio_import *im;          /* NULL: sensors only */
	sio_sensor_set *sensors; /* NULL: none asked for */
	rad_status sensor_st;    /* the first sensor error */
	rad_error *sensor_err;   /* where its message goes */
} pass;

static rad_status visit(void *ud, int ni, const sio_mat4 *w)
{
	pass *p = ud;
	if (p->im) {
		rad_status st = sio_import_node(p->im, ni, w);
		if (st != RAD_OK)
			return st;
	}
	if (p->sensors && p->sensor_st == RAD_OK)
		p->sensor_st =
		        sio_sensor_node(p->sensors, ni, w, p->sensor_err);
	return p->im ? RAD_OK : p->sensor_st;
}

/* Walk d into s (may be NULL) and ss (may be NULL), then commit s. */
static rad_status build(const sio_doc *d, rad_scene *s, sio_sensor_set *ss,
                        sio_info *info, rad_error *err)
{
	sio_import im;
	rad_error deferred = {0};
	pass p = {s ? &im : NULL, ss, RAD_OK, s ? &deferred : err};
	rad_status st = RAD_OK;
	if (s)
		st = sio_import_init(&im, d, s, info, err);
	if (st == RAD_OK)
		st = sio_walk(d, visit, &p, err);
	if (s) {
		sio_tex_cache_free(&im.tex); /* before the BVH is built */
		if (st == RAD_OK)
			st = rad_scene_commit(s, err);
		rad_scene_counts c = {0};
		if (st == RAD_OK)
			rad_scene_counts_get(s, &c);
		if (st == RAD_OK && c.lights == 0 && c.emitters == 0)
			sio_note(info,
			         "the scene has no light (no emissive "
			         "material, no KHR_lights_punctual light): "
			         "every illuminance is 0");
		sio_import_done(&im);
	}
	if (st == RAD_OK && p.sensor_st != RAD_OK) {
		if (err)
			*err = deferred;
		st = p.sensor_st;
	}
	return st;
}

/* Parse and build; *scene (when asked for) is set only on success. */
static rad_status load(const unsigned char *b, size_t len, rad_scene **scene,
                       sio_info *info, sio_sensor_set *ss, rad_error *err)
{
	int glb;
	sio_doc *d = NULL;
	rad_status st = sio_precheck(b, len, &glb, err);
	if (st == RAD_OK)
		st = sio_doc_parse(b, len, glb, &d, info, err);
	if (st == RAD_OK)
		st = check_required(d, err);
	if (st != RAD_OK) {
		sio_doc_free(d);
		return st;
	}
	count_document(d, info);
	note_unread(d, info);
	if (ss)
		ss->d = d;
	rad_scene *s = NULL;
	if (scene)
		st = rad_scene_new(&s, err);
	if (st == RAD_OK)
		st = build(d, s, ss, info, err);
	sio_doc_free(d);
	if (st != RAD_OK) {
		rad_scene_free(s);
		return st;
	}
	if (scene)
		*scene = s;
	return RAD_OK;
}

rad_status sio_load(const void *bytes, size_t len, rad_scene **scene,
                    sio_info *info, sio_sensor **sensors, size_t *nsensors,
                    rad_error *err)
{
	rad_error_clear(err);
	if (info)
		memset(info, 0, sizeof *info);
	if ((!scene && !sensors) || !sensors != !nsensors)
		return rad_fail(err, RAD_ERR_INVALID, "sio_load: no out");
	if (scene)
		*scene = NULL;
	if (sensors) {
		*sensors = NULL;
		*nsensors = 0;
	}
	if (!bytes || len == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "empty input: no glTF bytes");
	if (len > UINT32_MAX) /* tinygltf takes 32-bit lengths */
		return rad_fail(err, RAD_ERR_UNSUPPORTED,
		                "input of %zu bytes: glTF over 4 GiB is not "
		                "supported",
		                len);
	sio_sensor_set ss = {0};
	rad_status st =
	        load(bytes, len, scene, info, sensors ? &ss : NULL, err);
	if (st == RAD_OK && sensors)
		sio_sensor_set_take(&ss, sensors, nsensors);
	sio_sensor_set_free(&ss);
	return st;
}

void sio_sensors_free(sio_sensor *s)
{
	free(s);
}
