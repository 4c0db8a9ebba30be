/*
 * pack_int.h -- what pack.c shares with pack_lum.c: the packer being
 * built and the binary chunk's one way in.
 */
#ifndef LUXRAD_SIO_PACK_INT_H
#define LUXRAD_SIO_PACK_INT_H

#include <jansson.h>
#include <limits.h>

#include "pack.h"

#include <stdio.h>

#define ALIGN 8              /* of each part of the binary chunk */
#define GLB_MAX 0xFFFFFFF0u  /* the GLB length field is 32 bits */
#define GLB_JSON 0x4E4F534Au /* chunk types: "JSON" */
#define GLB_BIN 0x004E4942u  /* "BIN\0" */

typedef struct packer {
	const char *dir;
	char realdir[PATH_MAX];
	const unsigned char *glb_bin; /* a GLB's binary chunk being repacked:
	                                 buffer 0 without a uri */
	size_t nglb_bin;
	unsigned char *bin; /* the binary chunk being built */
	size_t nbin, cap;
	sio_pack_info info;
	rad_error *err;
} packer;

/* pack_file.c: up to max bytes of an open stream (all of it when max is
 * 0), path naming it in errors. */
rad_status sio_pack_read_stream(FILE *f, const char *path, size_t max,
                                unsigned char **out, size_t *len,
                                rad_error *err);

/* pack_bin.c: bytes appended at the next multiple of ALIGN; *at gets
 * their offset. */
rad_status sio_pack_bin_append(packer *pk, const unsigned char *b, size_t n,
                               size_t *at);
/* pack_bin.c: bytes appended under a new bufferView, *view its index. */
rad_status sio_pack_add_view(packer *pk, json_t *root, const unsigned char *b,
                             size_t len, json_int_t *view);

/* pack_bin.c: node's extras.luxrad_photometry made the packed reference
 * to bufferView view, named by the file it came from. */
void sio_pack_photometry_ref(json_t *node, json_int_t view, const char *name);

/* pack_lum.c: the luminaires the user names attached to their lights'
 * nodes, their files in the chunk (as extras.luxrad_photometry). */
rad_status sio_pack_luminaires(packer *pk, json_t *root,
                               const sio_luminaire *lum, size_t nlum);

/* pack_lum.c: a GLB's JSON and binary chunks (bin NULL when it has
 * none), checked against its length. */
rad_status sio_glb_split(const unsigned char *b, size_t len,
                         const unsigned char **json, size_t *njson,
                         const unsigned char **bin, size_t *nbin,
                         rad_error *err);

#endif
