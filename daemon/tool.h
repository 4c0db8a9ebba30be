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
 * Read a GLB, or a .gltf with the files beside it (packed:
 * sio_scene_read), into a committed scene; *seconds is the time the load
 * took (parse, build, BVH), the file read aside.  TOOL_OK, or TOOL_FAIL
 * after "PROG: why" on stderr.
 */
int tool_scene_load(const char *prog, const char *path, rad_scene **sc,
                    sio_info *info, double *seconds);

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
