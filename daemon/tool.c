/*
 * tool.c -- see tool.h.
 */
#include "tool.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine_json.h"
#include "photometry.h"
#include "rp.h"

/* ------------------------------------------------------------ luminaires */

int tool_luminaire_arg(tool_luminaires *l, const char *spec, char *msg,
                       size_t len)
{
	const char *eq = strchr(spec, '=');
	if (!eq || eq == spec || !eq[1])
		return rp_cli_fail(msg, len,
		                   "--luminaire: invalid value '%s' (expected "
		                   "NAME=FILE)",
		                   spec);
	if (l->n >= TOOL_MAX_LUMINAIRES)
		return rp_cli_fail(msg, len,
		                   "--luminaire: more than %d of them",
		                   TOOL_MAX_LUMINAIRES);
	l->spec[l->n++] = spec;
	return 0;
}

/* The luminaires' tables, and which lights took them. */
typedef struct attach {
	const tool_luminaires *lum;
	pho_table *table[TOOL_MAX_LUMINAIRES];
	int used[TOOL_MAX_LUMINAIRES];
} attach;

static int name_is(const char *spec, const char *name)
{
	size_t n = (size_t)(strchr(spec, '=') - spec);
	return name && strlen(name) == n && memcmp(spec, name, n) == 0;
}

/* sio_light_hook: the table of the --luminaire naming this light. */
static rad_status attach_light(void *ud, const char *node, rad_light_desc *d,
                               rad_error *err)
{
	attach *a = ud;
	for (int k = 0; k < a->lum->n; k++) {
		const char *spec = a->lum->spec[k];
		if (!name_is(spec, node) && !name_is(spec, d->name))
			continue;
		if (d->kind != RAD_LIGHT_POINT)
			return rad_fail(err, RAD_ERR_INVALID,
			                "--luminaire %s: light '%s' is not a "
			                "point light",
			                spec, d->name ? d->name : node);
		a->used[k] = 1;
		return pho_light_set(a->table[k], d, err);
	}
	return RAD_OK;
}

/* Read and parse every luminaire file into a. */
static int read_luminaires(const char *prog, attach *a)
{
	for (int k = 0; k < a->lum->n; k++) {
		const char *file = strchr(a->lum->spec[k], '=') + 1;
		unsigned char *bytes = NULL;
		size_t len = 0;
		char msg[512];
		rad_error err;
		if (sio_file_read(file, &bytes, &len, &err) != RAD_OK) {
			fprintf(stderr, "%s: --luminaire: %s\n", prog, err.msg);
			return TOOL_FAIL;
		}
		pho_status st = pho_parse((const char *)bytes, len, NULL,
		                          &a->table[k], msg, sizeof msg);
		free(bytes);
		if (st != PHO_OK) {
			fprintf(stderr, "%s: %s: %s: %s\n", prog, file,
			        pho_status_name(st), msg);
			return TOOL_FAIL;
		}
	}
	return TOOL_OK;
}

/* -------------------------------------------------------------- scenes */

int tool_scene_load(const char *prog, const char *path,
                    const tool_luminaires *lum, rad_scene **sc, sio_info *info,
                    double *seconds)
{
	static const tool_luminaires none = {.n = 0};
	attach a = {.lum = lum ? lum : &none};
	unsigned char *bytes = NULL;
	size_t len = 0;
	rad_error err = {0};
	int rc = read_luminaires(prog, &a);
	rad_status st = RAD_OK;
	if (rc == TOOL_OK &&
	    (st = sio_scene_read(path, &bytes, &len, NULL, &err)) != RAD_OK) {
		fprintf(stderr, "%s: %s\n", prog, err.msg);
		rc = TOOL_FAIL;
	}
	double t0 = rad_seconds();
	if (rc == TOOL_OK)
		st = sio_load_hooked(bytes, len, attach_light, &a, sc, info,
		                     &err);
	*seconds = rad_seconds() - t0;
	free(bytes);
	if (rc == TOOL_OK && st != RAD_OK) {
		fprintf(stderr, "%s: %s: %s: %s\n", prog, path,
		        rad_status_name(err.code), err.msg);
		rc = TOOL_FAIL;
	}
	for (int k = 0; rc == TOOL_OK && k < a.lum->n; k++)
		if (!a.used[k]) {
			fprintf(stderr,
			        "%s: --luminaire %s: %s has no light of that "
			        "name\n",
			        prog, a.lum->spec[k], path);
			rad_scene_free(*sc);
			*sc = NULL;
			rc = TOOL_FAIL;
		}
	for (int k = 0; k < a.lum->n; k++)
		pho_free(a.table[k]);
	return rc;
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
