/*
 * scene_file.c -- reading a scene file from disk, for the offline tools
 * and tests.  The glTF loader itself only takes bytes (a daemon never
 * reads a path a client names); this is the one place a local program
 * turns a path into those bytes.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sceneio.h"

rad_status sio_file_read(const char *path, unsigned char **out, size_t *len,
                         rad_error *err)
{
	*out = NULL;
	*len = 0;
	FILE *f = fopen(path, "rb");
	if (!f)
		return rad_fail(err, RAD_ERR_IO, "cannot open '%s': %s", path,
		                strerror(errno));
	/* Read by doubling chunks rather than by the file's size, so pipes
	 * and special files work too. */
	unsigned char *buf = NULL;
	size_t n = 0, cap = 0;
	rad_status st = RAD_OK;
	for (;;) {
		if (n == cap) {
			size_t ncap = cap ? 2 * cap : (size_t)1 << 16;
			unsigned char *nb = realloc(buf, ncap);
			if (!nb) {
				st = rad_fail(err, RAD_ERR_NOMEM,
				              "out of memory reading '%s'",
				              path);
				break;
			}
			buf = nb;
			cap = ncap;
		}
		size_t got = fread(buf + n, 1, cap - n, f);
		n += got;
		if (got == 0)
			break;
	}
	if (!st && ferror(f))
		st = rad_fail(err, RAD_ERR_IO, "cannot read '%s': %s", path,
		              strerror(errno));
	fclose(f);
	if (st) {
		free(buf);
		return st;
	}
	*out = buf;
	*len = n;
	return RAD_OK;
}

rad_status sio_load_file(const char *path, rad_scene **out, sio_info *info,
                         rad_error *err)
{
	unsigned char *bytes;
	size_t len;
	*out = NULL;
	rad_status st = sio_file_read(path, &bytes, &len, err);
	if (st)
		return st;
	st = sio_load(bytes, len, out, info, NULL, NULL, err);
	free(bytes);
	return st;
}
