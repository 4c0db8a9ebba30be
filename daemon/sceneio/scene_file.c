/*
 * scene_file.c -- loading a scene file from disk, for the offline tools
 * and tests: a GLB as it is, a .gltf packed with the files beside it
 * (pack.c).  The glTF loader itself only takes bytes (a daemon never
 * reads a path a client names).
 */
#include <stdlib.h>

#include "sceneio.h"

rad_status sio_load_file(const char *path, rad_scene **out, sio_info *info,
                         rad_error *err)
{
	unsigned char *bytes;
	size_t len;
	*out = NULL;
	rad_status st = sio_scene_read(path, &bytes, &len, NULL, err);
	if (st)
		return st;
	st = sio_load(bytes, len, out, info, NULL, NULL, err);
	free(bytes);
	return st;
}
