/*
 * pack.h -- a glTF scene as exporters write it ("glTF Separate": a .gltf
 * beside its .bin buffers and image files) packed into one GLB in
 * memory, so that a scene travels as one set of bytes.
 *
 * The offline tools load scenes through it, and the client packs before
 * upload: the daemon itself still reads no file.  A small library of its
 * own (luxrad_pack: C, jansson, no tinygltf), so the thin client can link
 * it.
 */
#ifndef LUXRAD_SIO_PACK_H
#define LUXRAD_SIO_PACK_H

#include <stddef.h>

#include "rad.h"

/* A node's photometric file, in its extras: a path beside the scene,
 * which packing turns into {"bufferView": n, "name": path}. */
#define SIO_PHOTOMETRY_EXTRA "luxrad_photometry"

/* What packing did, for the scene's report. */
typedef struct sio_pack_info {
	unsigned buffers_read;    /* buffers read from files beside the scene */
	unsigned images_read;     /* images read from files beside the scene */
	unsigned photometry_read; /* photometric files named by nodes
	                             (extras.luxrad_photometry) */
	unsigned data_uris; /* buffers and images decoded from data: URIs */
} sio_pack_info;

/*
 * Pack a glTF JSON document (json, len bytes) into a GLB (*glb, malloc'ed,
 * *glb_len bytes): every buffer becomes part of the one binary chunk,
 * every image with a uri gets a bufferView there, and so does every
 * photometric file a node names in extras.luxrad_photometry (which
 * becomes {"bufferView": n, "name": the path}).  URIs are data: URIs or
 * relative paths read from dir, the scene's folder: no scheme, no
 * absolute path, no "..", nothing that resolves (symbolic links
 * followed) outside dir.  info may be NULL.  RAD_ERR_INVALID names the
 * buffer or image and why; RAD_ERR_IO a file that cannot be read.
 */
rad_status sio_pack(const unsigned char *json, size_t len, const char *dir,
                    unsigned char **glb, size_t *glb_len, sio_pack_info *info,
                    rad_error *err);

/* A whole file (or pipe) into *out (malloc'ed); RAD_ERR_IO names it. */
rad_status sio_file_read(const char *path, unsigned char **out, size_t *len,
                         rad_error *err);

/* 1 if bytes start a GLB (the magic "glTF"). */
int sio_is_glb(const unsigned char *bytes, size_t len);

/*
 * 1 if bytes are a Git LFS pointer (they start "version
 * https://git-lfs.github.com/spec/"): the small text file a repository
 * cloned without git-lfs holds in place of a .glb, .bin or image.
 */
int sio_is_lfs_pointer(const unsigned char *bytes, size_t len);

/* What to do about one, for messages that found a pointer. */
#define SIO_LFS_HINT                                                           \
	"a Git LFS pointer, not the file's content: run git lfs pull"

/* A photometric file the user names for a light (--luminaire NAME=FILE):
 * every node named `light`, or carrying a KHR_lights_punctual light of
 * that name, gets the file as if its extras named it
 * (extras.luxrad_photometry). */
typedef struct sio_luminaire {
	const char *light, *file;
} sio_luminaire;

/* A --luminaire value "NAME=FILE" as a luminaire: NAME copied into
 * light[len], file pointing into spec.  RAD_ERR_INVALID, in the words a
 * command line shows, when it is not NAME=FILE or NAME does not fit. */
rad_status sio_luminaire_spec(const char *spec, char *light, size_t len,
                              sio_luminaire *out, rad_error *err);

/*
 * A scene file as one set of bytes: a GLB as it is, a .gltf packed with
 * the files beside it (sio_pack, dir = the file's folder).  *out is
 * malloc'ed.  info may be NULL.
 */
rad_status sio_scene_read(const char *path, unsigned char **out, size_t *len,
                          sio_pack_info *info, rad_error *err);
/* The same with luminaires attached (a GLB is then repacked).  A light
 * no node carries, or a file that cannot be read, is RAD_ERR_INVALID /
 * RAD_ERR_IO naming it; the file is parsed when the scene loads. */
rad_status sio_scene_read_lum(const char *path, const sio_luminaire *lum,
                              size_t nlum, unsigned char **out, size_t *len,
                              sio_pack_info *info, rad_error *err);

#endif
