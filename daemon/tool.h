/*
 * tool.h -- what the offline tools (luxrad-solve, luxrad-reference)
 * share: reading a scene file and a points file with the messages and
 * exit codes of a command-line tool, and the scene's summary as JSON.
 */
#ifndef LUXRAD_TOOL_H
#define LUXRAD_TOOL_H

#include <jansson.h>
#include <stddef.h>

#include "rad.h"
#include "sceneio.h"

/* The tools' exit codes. */
enum { TOOL_OK = 0, TOOL_FAIL = 1, TOOL_USAGE = 2 };

/*
 * --luminaire NAME=FILE, repeatable: the light named NAME (its glTF node's
 * name, or its KHR_lights_punctual name) shines with the candela table
 * of the IES or EULUMDAT FILE.  The file's absolute candela replace the
 * glTF intensity; the glTF colour is kept, scaled so its largest channel
 * is 1 (white when the light is black).  The luminaire's nadir (gamma
 * 0) is the light's direction, local -Z, and its C = 0 plane holds the
 * node's local +X.  Every NAME must match a light.  The file is packed
 * with the scene (sio_scene_read_lum), as luxrad submit does.
 */
#define TOOL_MAX_LUMINAIRES 64
#define TOOL_LIGHT_NAME_MAX 256 /* bytes with the NUL */

typedef struct tool_luminaires {
	const char *spec[TOOL_MAX_LUMINAIRES]; /* "NAME=FILE", from argv */
	int n;
} tool_luminaires;

/* Add one --luminaire value: 0, or RP_CLI_USAGE with the reason in msg
 * when it is not NAME=FILE or there are too many. */
int tool_luminaire_arg(tool_luminaires *l, const char *spec, char *msg,
                       size_t len);

/*
 * Read a GLB, or a .gltf with the files beside it (packed:
 * sio_scene_read), into a committed scene, with the luminaires in lum
 * (NULL or empty for none); *seconds is the time the load took (parse,
 * build, BVH), the files read aside.  TOOL_OK, or TOOL_FAIL after "PROG:
 * why" on stderr.
 */
int tool_scene_load(const char *prog, const char *path,
                    const tool_luminaires *lum, rad_scene **sc, sio_info *info,
                    double *seconds);

/*
 * Read a points file (rp_points_read): *xyz gets 6 doubles per point.
 * TOOL_OK; TOOL_USAGE for a malformed line, TOOL_FAIL when the file
 * cannot be read (the message on stderr, "PROG: ").
 */
int tool_points_load(const char *prog, const char *path, double **xyz,
                     size_t *n);

/* The scene's bounds, counters, import counters and warnings. */
json_t *tool_scene_json(const rad_scene *sc, const sio_info *info);

#endif
