/*
 * tool.c -- see tool.h.
 */
#include "tool.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine_json.h"
#include "rp.h"

/* ------------------------------------------------------------ luminaires */

int tool_luminaire_arg(tool_luminaires *l, const char *spec, char *msg,
                       size_t len)
{
	char light[TOOL_LIGHT_NAME_MAX];
	sio_luminaire one;
	rad_error err;
	if (sio_luminaire_spec(spec, light, sizeof light, &one, &err) != RAD_OK)
		return rp_cli_fail(msg, len, "%s", err.msg);
	if (l->n >= TOOL_MAX_LUMINAIRES)
		return rp_cli_fail(msg, len,
		                   "--luminaire: more than %d of them",
		                   TOOL_MAX_LUMINAIRES);
	l->spec[l->n++] = spec;
	return 0;
}

/* -------------------------------------------------------------- scenes */

int tool_scene_load(const char *prog, const char *path,
                    const tool_luminaires *lum, rad_scene **sc, sio_info *info,
                    double *seconds)
{
	sio_luminaire named[TOOL_MAX_LUMINAIRES];
	char light[TOOL_MAX_LUMINAIRES][TOOL_LIGHT_NAME_MAX];
	int n = lum ? lum->n : 0;
	unsigned char *bytes = NULL;
	size_t len = 0;
	rad_error err = {0};
	rad_status st = RAD_OK;
	*seconds = 0;
	for (int k = 0; k < n && !st; k++) /* checked when parsed */
		st = sio_luminaire_spec(lum->spec[k], light[k], sizeof light[k],
		                        &named[k], &err);
	if (st || sio_scene_read_lum(path, named, (size_t)n, &bytes, &len, NULL,
	                             &err) != RAD_OK) {
		fprintf(stderr, "%s: %s\n", prog, err.msg);
		return TOOL_FAIL;
	}
	double t0 = rad_seconds();
	st = sio_load(bytes, len, sc, info, NULL, NULL, &err);
	*seconds = rad_seconds() - t0;
	free(bytes);
	if (st != RAD_OK) {
		fprintf(stderr, "%s: %s: %s: %s\n", prog, path,
		        rad_status_name(err.code), err.msg);
		return TOOL_FAIL;
	}
	return TOOL_OK;
}

int tool_points_load(const char *prog, const char *path, double **xyz,
                     size_t *n)
{
	char msg[1024];
	int rc = rp_points_read(path, xyz, n, msg, sizeof(msg));
	if (rc != 0)
		fprintf(stderr, "%s: %s\n", prog, msg);
	return rc == 0 ? TOOL_OK : rc == RP_CLI_USAGE ? TOOL_USAGE : TOOL_FAIL;
}

/* The scene's counters under their field names (rad.h, sceneio.h). */
/* clang-format off */
#define SCENE_COUNTERS(X)                                                      \
	X(triangles_in) X(triangles_nonfinite) X(triangles_degenerate)         \
	X(triangles_duplicate) X(polygons) X(polygons_cut) X(quads)            \
	X(back_faces)                                                          \
	X(materials) X(materials_offered) X(lights) X(emitters) X(nodes)
#define IMPORT_COUNTERS(X)                                                     \
	X(meshes) X(primitives) X(primitives_skipped) X(textures_ignored)      \
	X(textures_read) X(images_decoded) X(textured_triangles)               \
	X(photometric_lights)                                                  \
	X(metallic_materials)
/* clang-format on */

static json_t *vec3(const double v[3])
{
	json_t *a = json_array();
	for (int i = 0; i < 3; i++)
		json_array_append_new(a, ej_real(v[i]));
	return a;
}

json_t *tool_scene_json(const rad_scene *sc, const sio_info *info)
{
	json_t *o = json_object();
	rad_scene_counts c;
	double lo[3], hi[3];

	rad_scene_counts_get(sc, &c);
	rad_scene_bounds(sc, lo, hi);
	json_object_set_new(o, "bounds_min", vec3(lo));
	json_object_set_new(o, "bounds_max", vec3(hi));
#define SET_(f) json_object_set_new(o, #f, json_integer((json_int_t)c.f));
	SCENE_COUNTERS(SET_)
#undef SET_
#define SET_(f) json_object_set_new(o, #f, json_integer((json_int_t)info->f));
	IMPORT_COUNTERS(SET_)
#undef SET_
	json_object_set_new(o, "warnings", json_string(info->warnings));
	return o;
}
