/*
 * pack_lum.c -- luminaires a user names on the command line, packed with
 * the scene: `--luminaire NAME=FILE` on luxrad submit and the offline
 * tools gives the light NAME the photometric file FILE.
 *
 * DESIGN
 * The file travels in the GLB exactly as a file a node names in its
 * extras does (pack.c: a bufferView, extras.luxrad_photometry =
 * {"bufferView": n, "name": ...}), so one path reads both, in the
 * importer, and the daemon gets the file with the scene.  FILE is the
 * user's own path (no folder rule: it was named, not found in a
 * document).  A GLB given luminaires is split into its JSON and binary
 * chunks and packed again, its binary chunk taking the place of buffer 0.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "pack_int.h"

static uint32_t get32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
	       (uint32_t)p[3] << 24;
}

rad_status sio_glb_split(const unsigned char *b, size_t len,
                         const unsigned char **json, size_t *njson,
                         const unsigned char **bin, size_t *nbin,
                         rad_error *err)
{
	*bin = NULL;
	*nbin = 0;
	if (len < 20 || get32(b + 4) != 2 || get32(b + 8) > len ||
	    get32(b + 8) < 20)
		return rad_fail(err, RAD_ERR_INVALID,
		                "not a GLB 2.0 container (header or length)");
	size_t end = get32(b + 8), at = 12;
	for (int k = 0; at + 8 <= end; k++) {
		size_t n = get32(b + at);
		uint32_t type = get32(b + at + 4);
		if (n > end - at - 8)
			return rad_fail(err, RAD_ERR_INVALID,
			                "GLB chunk %d runs past the end", k);
		if (k == 0 && type != GLB_JSON)
			return rad_fail(err, RAD_ERR_INVALID,
			                "GLB: the first chunk is not JSON");
		if (k == 0) {
			*json = b + at + 8;
			*njson = n;
		} else if (k == 1 && type == GLB_BIN) {
			*bin = b + at + 8;
			*nbin = n;
		}
		at += 8 + n;
	}
	if (at == 12)
		return rad_fail(err, RAD_ERR_INVALID, "GLB without chunks");
	return RAD_OK;
}

rad_status sio_luminaire_spec(const char *spec, char *light, size_t len,
                              sio_luminaire *out, rad_error *err)
{
	const char *eq = strchr(spec, '=');
	if (!eq || eq == spec || !eq[1])
		return rad_fail(err, RAD_ERR_INVALID,
		                "--luminaire: invalid value '%.200s' (expected "
		                "NAME=FILE)",
		                spec);
	if ((size_t)(eq - spec) >= len)
		return rad_fail(err, RAD_ERR_INVALID,
		                "--luminaire: the light's name is longer than "
		                "%zu bytes",
		                len - 1);
	memcpy(light, spec, (size_t)(eq - spec));
	light[eq - spec] = '\0';
	*out = (sio_luminaire){light, eq + 1};
	return RAD_OK;
}

/* 1 if node carries a light named name, or is so named. */
static int names_light(json_t *root, json_t *node, const char *name)
{
	json_t *ext = json_object_get(json_object_get(node, "extensions"),
	                              "KHR_lights_punctual");
	json_t *li = json_object_get(ext, "light");
	if (!json_is_integer(li))
		return 0;
	const char *nn = json_string_value(json_object_get(node, "name"));
	json_t *lights = json_object_get(
	        json_object_get(json_object_get(root, "extensions"),
	                        "KHR_lights_punctual"),
	        "lights");
	json_t *light = json_array_get(lights, (size_t)json_integer_value(li));
	const char *ln = json_string_value(json_object_get(light, "name"));
	return (nn && !strcmp(nn, name)) || (ln && !strcmp(ln, name));
}

/* The file's last path component, for the packed member's name. */
static const char *base_name(const char *path)
{
	const char *s = strrchr(path, '/');
	return s ? s + 1 : path;
}

rad_status sio_pack_luminaires(packer *pk, json_t *root,
                               const sio_luminaire *lum, size_t nlum)
{
	json_t *nodes = json_object_get(root, "nodes");
	for (size_t k = 0; k < nlum; k++) {
		size_t hits = 0;
		json_int_t view = -1;
		for (size_t i = 0; i < json_array_size(nodes); i++) {
			json_t *node = json_array_get(nodes, i);
			if (!names_light(root, node, lum[k].light))
				continue;
			rad_status st = RAD_OK;
			if (view < 0) {
				unsigned char *bytes = NULL;
				size_t len = 0;
				st = sio_file_read(lum[k].file, &bytes, &len,
				                   pk->err);
				if (!st)
					st = sio_pack_add_view(pk, root, bytes,
					                       len, &view);
				free(bytes);
			}
			if (st)
				return st;
			sio_pack_photometry_ref(node, view,
			                        base_name(lum[k].file));
			hits++;
		}
		if (!hits)
			return rad_fail(pk->err, RAD_ERR_INVALID,
			                "luminaire '%.80s': the scene has no "
			                "light of that name",
			                lum[k].light);
	}
	return RAD_OK;
}
