/*
 * internal.h -- what the files of the scene library share with each
 * other; callers use sceneio.h and export.h only.
 *
 * An import (load.c) runs in this order: precheck.c looks at the raw
 * bytes, the shim (gltf_shim.cc) parses them into a sio_doc, walk.c
 * walks the default scene's nodes with their world transforms, and at
 * each node import.c adds meshes and lights to the engine scene while
 * sensors.c collects sensor declarations.  accessor.c resolves the byte
 * ranges import.c reads.  All of them take the document as hostile.
 */
#ifndef LUXRAD_SCENEIO_INTERNAL_H
#define LUXRAD_SCENEIO_INTERNAL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "gltf_doc.h"

#ifdef __cplusplus
extern "C" {
#endif

/* std::max's rule (the first when neither is larger): NaN stays put. */
static inline double sio_max(double a, double b)
{
	return a < b ? b : a;
}

/* s is the string lit, NULs included. */
static inline int sio_str_is(sio_str s, const char *lit)
{
	return s.len == strlen(lit) && memcmp(s.s, lit, s.len) == 0;
}

/* info.c: append a warning to info->warnings ("; "-separated, truncated;
 * info may be NULL). */
void sio_note(sio_info *info, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));
/* info.c: put label (the glTF object) in front of err's message when st
 * is an error; returns st. */
rad_status sio_blame(rad_error *err, rad_status st, const char *label);

/* precheck.c: refuse what tinygltf must not see; *glb says which parser
 * the bytes are for. */
rad_status sio_precheck(const unsigned char *b, size_t len, int *glb,
                        rad_error *err);

/* ------------------------------------------------------------ walk.c */

typedef struct sio_mat4 {
	double m[16]; /* column-major like glTF: m[col * 4 + row] */
} sio_mat4;

/* Determinant of the linear part; its sign tells whether winding flips. */
double sio_mat_det3(const sio_mat4 *a);
/* a * p; the bottom row is ignored (glTF matrices are affine). */
void sio_mat_point(const sio_mat4 *a, const float p[3], double out[3]);
/* Node ni's name for messages (ni already range-checked). */
const char *sio_node_name(const sio_doc *d, int ni);

/* Called at each node with its world transform; non-zero ends the walk. */
typedef rad_status (*sio_visit)(void *ud, int node, const sio_mat4 *world);

/*
 * Walk the default scene (else scene 0, else every root node) depth
 * first, roots in scene order, children in order.  Refuses out-of-range
 * nodes, cycles and shared children, and malformed local transforms.
 */
rad_status sio_walk(const sio_doc *d, sio_visit visit, void *ud,
                    rad_error *err);

/* -------------------------------------------------------- accessor.c */

/* An accessor resolved to bytes; every element lies inside its buffer. */
typedef struct sio_view {
	const unsigned char *p; /* first element */
	size_t stride;          /* bytes between elements */
	size_t count;           /* elements */
	size_t size;            /* bytes per element read */
} sio_view;

/* POSITION accessor ai (VEC3 of FLOAT) of the primitive named where. */
rad_status sio_position_view(const sio_doc *d, const char *where, int ai,
                             sio_view *v, rad_error *err);
/* Index accessor ai (SCALAR of unsigned byte, short or int). */
rad_status sio_index_view(const sio_doc *d, const char *where, int ai,
                          sio_view *v, rad_error *err);
/* Element k of an index view. */
size_t sio_index_at(const sio_view *v, size_t k);
/* TEXCOORD accessor ai (VEC2 of FLOAT, or normalized unsigned byte or
 * short) and its element k. */
rad_status sio_uv_view(const sio_doc *d, const char *where, int ai, sio_view *v,
                       rad_error *err);
void sio_uv_at(const sio_view *v, size_t k, double uv[2]);
/* The bytes of bufferView vi (an image's), checked against its buffer. */
rad_status sio_view_bytes(const sio_doc *d, const char *where, int vi,
                          const unsigned char **p, size_t *len, rad_error *err);

/* --------------------------------------------------------- texture.c */

/* An image ready for means: linear RGB, a pyramid of prefix sums. */
typedef struct sio_texture sio_texture;

/* The images of one import, decoded when first needed (texture.c). */
typedef struct sio_tex_cache {
	const sio_doc *d;
	sio_info *info;
	struct sio_tex_slot *slot; /* one per glTF image */
	size_t bytes;              /* held by the prepared images */
	uint64_t clock;
} sio_tex_cache;

rad_status sio_tex_cache_init(sio_tex_cache *c, const sio_doc *d,
                              sio_info *info, rad_error *err);
void sio_tex_cache_free(sio_tex_cache *c);
/* Image ii (in range) prepared, *out NULL when it cannot be read (a note
 * says why, once).  Fails only for want of memory. */
rad_status sio_tex_image(sio_tex_cache *c, int ii, const sio_texture **out,
                         rad_error *err);
/* Mean linear RGB of t over the triangle uv (glTF UVs: one image per unit,
 * v down), wrap[0] along u and wrap[1] along v (SIO_GL_REPEAT...). */
void sio_tex_mean(const sio_texture *t, const int wrap[2],
                  const double uv[3][2], double rgb[3]);
/* Mean linear RGB of the whole image. */
void sio_tex_image_mean(const sio_texture *t, double rgb[3]);

/* ---------------------------------------------------------- import.c */

/* A material's base colour texture, bound (material.c). */
typedef struct sio_mat_tex {
	int image;        /* -1: none, or not to be read */
	int wrap[2];      /* along u, v: SIO_GL_REPEAT... */
	int texcoord;     /* the UV set, n of TEXCOORD_n */
	double m[6];      /* KHR_texture_transform: u' = m0 u + m1 v + m2,
	                     v' = m3 u + m4 v + m5 */
	double factor[3]; /* baseColorFactor RGB */
} sio_mat_tex;

/* A primitive's view of its material's texture. */
typedef struct sio_prim_tex {
	const sio_mat_tex *mat;
	const sio_texture *tex; /* NULL: the material's factor alone */
	sio_view uv;            /* its TEXCOORD accessor */
} sio_prim_tex;

/* One import into an engine scene, node by node. */
typedef struct sio_import {
	const sio_doc *d;
	rad_scene *s;
	sio_info *info;          /* may be NULL */
	rad_error *err;          /* may be NULL */
	int64_t *mat_ids;        /* [glTF material + 1]: scene id, or -1 */
	sio_mat_tex *mat_tex;    /* [glTF material + 1], set with mat_ids */
	unsigned char *tex_used; /* [glTF material + 1]: texture counted */
	sio_tex_cache tex;       /* the images decoded so far */
	double *batch;           /* triangles waiting for the builder */
	double *rho;             /* their reflectances, when textured */
	size_t nbatch;           /* doubles in batch (9 per triangle) */
	uint64_t triangles;      /* offered so far (the engine counts 32-bit) */
} sio_import;

/* material.c: the engine id of glTF material mi (-1: glTF's default),
 * offered to the builder and its texture bound on first use. */
rad_status sio_material_id(sio_import *im, int mi, const char *where,
                           uint32_t *id);
/* The texture of material mi (already offered) as primitive gp reads it;
 * pt->tex NULL when the primitive gets the factor alone. */
rad_status sio_material_texture(sio_import *im, int mi, const char *where,
                                const sio_doc_prim *gp, sio_prim_tex *pt);
/* Reflectance of the triangle of vertices v under a textured pt. */
void sio_material_rho(const sio_prim_tex *pt, const size_t v[3], double rho[3]);

rad_status sio_import_init(sio_import *im, const sio_doc *d, rad_scene *s,
                           sio_info *info, rad_error *err);
/* A sio_visit: the node's mesh and light, if any, go to the scene. */
rad_status sio_import_node(void *im, int ni, const sio_mat4 *world);
void sio_import_done(sio_import *im);

/* --------------------------------------------------------- sensors.c */

/* The sensors found so far, and their names for finding duplicates. */
typedef struct sio_sensor_set {
	const sio_doc *d;
	sio_sensor *v;
	size_t n, cap;
	uint32_t *slots; /* open addressing: index + 1 into v, 0 = free */
	size_t nslots;   /* a power of two, at least 2 n */
} sio_sensor_set;

/* The sensor node ni declares, if any, placed by its world transform. */
rad_status sio_sensor_node(sio_sensor_set *ss, int ni, const sio_mat4 *world,
                           rad_error *err);
/* Hand the sensors over (*out NULL when none) and empty the set. */
void sio_sensor_set_take(sio_sensor_set *ss, sio_sensor **out, size_t *n);
void sio_sensor_set_free(sio_sensor_set *ss);

#ifdef __cplusplus
}
#endif
#endif
