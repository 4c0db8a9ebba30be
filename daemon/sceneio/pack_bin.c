/*
 * pack_bin.c -- the packed GLB's binary chunk as it grows: bytes appended
 * at 8-byte boundaries, bufferViews over them, and the references nodes
 * keep to the photometric files packed there.
 */
#include <stdlib.h>
#include <string.h>

#include "pack_int.h"

rad_status sio_pack_bin_append(packer *pk, const unsigned char *b, size_t n,
                               size_t *at)
{
	size_t start = (pk->nbin + ALIGN - 1) / ALIGN * ALIGN;
	if (start + n > GLB_MAX)
		return rad_fail(pk->err, RAD_ERR_LIMIT,
		                "the packed scene would exceed 4 GiB, the GLB "
		                "limit");
	if (start + n > pk->cap) {
		size_t ncap = pk->cap ? pk->cap : (size_t)1 << 16;
		while (ncap < start + n)
			ncap *= 2;
		unsigned char *nb = realloc(pk->bin, ncap);
		if (!nb)
			return rad_fail(pk->err, RAD_ERR_NOMEM,
			                "out of memory");
		pk->bin = nb;
		pk->cap = ncap;
	}
	if (start > pk->nbin)
		memset(pk->bin + pk->nbin, 0, start - pk->nbin);
	if (n)
		memcpy(pk->bin + start, b, n);
	pk->nbin = start + n;
	*at = start;
	return RAD_OK;
}

rad_status sio_pack_add_view(packer *pk, json_t *root, const unsigned char *b,
                             size_t len, json_int_t *view)
{
	size_t at = 0;
	rad_status st = sio_pack_bin_append(pk, b, len, &at);
	if (st)
		return st;
	json_t *views = json_object_get(root, "bufferViews");
	if (!views) {
		views = json_array();
		json_object_set_new(root, "bufferViews", views);
	}
	json_t *v = json_object();
	json_object_set_new(v, "buffer", json_integer(0));
	json_object_set_new(v, "byteOffset", json_integer((json_int_t)at));
	json_object_set_new(v, "byteLength", json_integer((json_int_t)len));
	*view = (json_int_t)json_array_size(views);
	json_array_append_new(views, v);
	return RAD_OK;
}

void sio_pack_photometry_ref(json_t *node, json_int_t view, const char *name)
{
	json_t *extras = json_object_get(node, "extras");
	if (!json_is_object(extras)) {
		extras = json_object();
		json_object_set_new(node, "extras", extras);
	}
	json_object_set_new(
	        extras, SIO_PHOTOMETRY_EXTRA,
	        json_pack("{s:I, s:s}", "bufferView", view, "name", name));
}
