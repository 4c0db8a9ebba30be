/*
 * pack_file.c -- files as bytes, for the packer and the tools: a whole
 * file or stream read with its errors named, and what a file's first
 * bytes say it is (a GLB, a Git LFS pointer).
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "pack_int.h"

rad_status sio_pack_read_stream(FILE *f, const char *path, size_t max,
                                unsigned char **out, size_t *len,
                                rad_error *err)
{
	/* By doubling chunks rather than by the file's size, so pipes and
	 * special files work too. */
	unsigned char *buf = NULL;
	size_t n = 0, cap = 0;
	for (;;) {
		if (n == cap) {
			size_t ncap = cap ? 2 * cap : (size_t)1 << 16;
			unsigned char *nb = realloc(buf, ncap);
			if (!nb) {
				free(buf);
				return rad_fail(err, RAD_ERR_NOMEM,
				                "out of memory reading '%s'",
				                path);
			}
			buf = nb;
			cap = ncap;
		}
		size_t want = cap - n;
		if (max && want > max - n)
			want = max - n;
		size_t got = want ? fread(buf + n, 1, want, f) : 0;
		n += got;
		if (got == 0 || (max && n == max))
			break;
	}
	if (ferror(f)) {
		free(buf);
		return rad_fail(err, RAD_ERR_IO, "cannot read '%s': %s", path,
		                strerror(errno));
	}
	*out = buf;
	*len = n;
	return RAD_OK;
}

rad_status sio_file_read(const char *path, unsigned char **out, size_t *len,
                         rad_error *err)
{
	*out = NULL;
	*len = 0;
	FILE *f = fopen(path, "rb");
	if (!f)
		return rad_fail(err, RAD_ERR_IO, "cannot open '%s': %s", path,
		                strerror(errno));
	rad_status st = sio_pack_read_stream(f, path, 0, out, len, err);
	fclose(f);
	return st;
}

int sio_is_glb(const unsigned char *bytes, size_t len)
{
	return len >= 4 && memcmp(bytes, "glTF", 4) == 0;
}

int sio_is_lfs_pointer(const unsigned char *bytes, size_t len)
{
	static const char sig[] = "version https://git-lfs.github.com/spec/";
	return len >= sizeof(sig) - 1 &&
	       memcmp(bytes, sig, sizeof(sig) - 1) == 0;
}
