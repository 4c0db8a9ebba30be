/*
 * gltf_doc.h -- a glTF document as plain C data: the C face of
 * gltf_shim.cc, the one C++ file, which alone sees tinygltf.
 *
 * Reading: sio_doc_parse() hands out the document tinygltf parsed, as it
 * stands.  Nothing in it is checked beyond what tinygltf checks (JSON
 * syntax, property types, array lengths of material factors): indices may
 * be out of range, sizes may disagree, buffers may be short.  The C
 * readers (accessor.c, walk.c, import.c, sensors.c) check every index and
 * every byte range before they use one, and name the object at fault.
 * Pointers point into tinygltf's model and live until sio_doc_free().
 *
 * Writing: sio_doc_write() serializes a document the C writer (write.c)
 * has built and checked; the shim only copies it into tinygltf's model.
 *
 * Strings carry their length: JSON may hold "\u0000", and a name is
 * compared and tested for emptiness as a whole, as tinygltf stores it.
 */
#ifndef LUXRAD_GLTF_DOC_H
#define LUXRAD_GLTF_DOC_H

#include <stddef.h>

#include "sceneio.h"

#ifdef __cplusplus
extern "C" {
#endif

/* glTF codes: modes, component types and targets are the spec's numbers;
 * accessor types are tinygltf's (the shim asserts both at compile time). */
enum {
	SIO_GL_TRIANGLES = 4,
	SIO_GL_TRIANGLE_STRIP = 5,
	SIO_GL_TRIANGLE_FAN = 6,
	SIO_GL_UNSIGNED_BYTE = 5121,
	SIO_GL_UNSIGNED_SHORT = 5123,
	SIO_GL_UNSIGNED_INT = 5125,
	SIO_GL_FLOAT = 5126,
	SIO_GL_ARRAY_BUFFER = 34962,
	SIO_GL_ELEMENT_ARRAY_BUFFER = 34963,
	SIO_GL_VEC2 = 2,
	SIO_GL_VEC3 = 3,
	SIO_GL_VEC4 = 4,
	SIO_GL_SCALAR = 65,
	SIO_GL_REPEAT = 10497, /* sampler wrap modes */
	SIO_GL_CLAMP_TO_EDGE = 33071,
	SIO_GL_MIRRORED_REPEAT = 33648
};

#define SIO_TEXCOORDS 4 /* TEXCOORD_0..3 are looked at */

#define SIO_LIGHTS_EXT "KHR_lights_punctual"
#define SIO_STRENGTH_EXT "KHR_materials_emissive_strength"
#define SIO_TRANSFORM_EXT "KHR_texture_transform"
#define SIO_SENSOR_EXTRA "luxrad_sensor" /* key in a node's extras */
/* SIO_PHOTOMETRY_EXTRA, a node's photometric file: pack.h. */

typedef struct sio_str {
	const char *s; /* NUL-terminated at len */
	size_t len;    /* bytes, NULs inside included */
} sio_str;

/* What a JSON property the C side asks about held. */
typedef enum sio_val {
	SIO_VAL_ABSENT = 0,
	SIO_VAL_NUMBER,
	SIO_VAL_STRING,
	SIO_VAL_OTHER /* present, of another type */
} sio_val;

typedef struct sio_doc_node {
	sio_str name;
	const double *matrix, *translation, *rotation, *scale;
	size_t nmatrix, ntranslation, nrotation, nscale; /* 0: absent */
	const int *children;
	size_t nchildren;
	int mesh; /* -1: none */
} sio_doc_node;

typedef struct sio_doc_prim {
	int mode;
	int has_position;            /* a POSITION attribute is present */
	int position;                /* its accessor */
	int indices;                 /* accessor, -1: not indexed */
	int material;                /* -1: glTF's default material */
	int texcoord[SIO_TEXCOORDS]; /* TEXCOORD_n accessors, -1: absent */
} sio_doc_prim;

typedef struct sio_doc_mesh {
	sio_str name;
	const sio_doc_prim *prims;
	size_t nprims;
} sio_doc_mesh;

typedef struct sio_doc_accessor {
	int sparse;
	int buffer_view; /* -1: none */
	int component_type;
	int type; /* SIO_GL_SCALAR, SIO_GL_VEC3... */
	int normalized;
	size_t count, byte_offset;
} sio_doc_accessor;

typedef struct sio_doc_view {
	int buffer;
	size_t byte_offset, byte_length, byte_stride; /* stride 0: packed */
} sio_doc_view;

typedef struct sio_doc_buffer {
	const unsigned char *data;
	size_t size;
} sio_doc_buffer;

typedef struct sio_doc_material {
	sio_str name;
	double base_color[3]; /* baseColorFactor RGB (tinygltf's default) */
	double emissive[3];   /* emissiveFactor */
	double metallic;      /* metallicFactor */
	int double_sided;     /* doubleSided */
	unsigned textures;    /* texture references (of the five kinds) */
	/* baseColorTexture: texture index (-1: none) and UV set; its
	 * KHR_texture_transform, the identity when absent. */
	int base_texture, base_texcoord;
	int has_transform;      /* the extension is present */
	int transform_bad;      /* ...but a member has the wrong type or size */
	int transform_texcoord; /* its texCoord override, -1: none */
	double offset[2], rotation, scale[2]; /* as the extension's members */
} sio_doc_material;

typedef struct sio_doc_texture {
	int source;  /* image, -1: none */
	int sampler; /* -1: glTF's default (repeat) */
} sio_doc_texture;

typedef struct sio_doc_sampler {
	int wrap_s, wrap_t;
} sio_doc_sampler;

/* An image: its bytes are a bufferView's, or a data: URI's that the
 * shim kept (data), or in a file no one read (external). */
typedef struct sio_doc_image {
	sio_str name, mime_type;
	int buffer_view;           /* -1: none */
	const unsigned char *data; /* a data: URI's bytes, else NULL */
	size_t size;
	int external; /* a uri other than data: (never read) */
} sio_doc_image;

typedef struct sio_doc_light {
	sio_str name, type;
	const double *color; /* 0 or 3 numbers, normally */
	size_t ncolor;
	double intensity, range, inner_cone, outer_cone;
} sio_doc_light;

typedef struct sio_doc_scene {
	const int *nodes;
	size_t nnodes;
} sio_doc_scene;

typedef struct sio_doc {
	const sio_doc_node *nodes;
	const sio_doc_mesh *meshes;
	const sio_doc_accessor *accessors;
	const sio_doc_view *views;
	const sio_doc_buffer *buffers;
	const sio_doc_material *materials;
	const sio_doc_texture *textures;
	const sio_doc_sampler *samplers;
	const sio_doc_image *images;
	const sio_doc_light *lights;
	const sio_doc_scene *scenes;
	const sio_str *required; /* extensionsRequired */
	const sio_str *used;     /* extensionsUsed */
	size_t nnodes, nmeshes, naccessors, nviews, nbuffers, nmaterials,
	        ntextures, nsamplers, nimages, nlights, nscenes, nrequired,
	        nused;
	int default_scene;         /* -1: none given */
	struct sio_doc_owner *own; /* tinygltf's model behind the pointers */
} sio_doc;

/*
 * Parse a .gltf (glb = 0) or a GLB (glb = 1) that sio_precheck() passed.
 * File access is refused (data: URIs and the GLB chunk are read), images
 * are not decoded (texture.c decodes those a material needs).  tinygltf's
 * warnings go to info (may be NULL).  On error *out is NULL and err names the
 * buffer or light at fault when tinygltf's message allows.
 */
rad_status sio_doc_parse(const unsigned char *bytes, size_t len, int glb,
                         sio_doc **out, sio_info *info, rad_error *err);
void sio_doc_free(sio_doc *d);

/*
 * Members of extensions and extras, looked up when the import reaches the
 * node or material (ni, mi in range), with tinygltf's own lookups.
 * *tag says what the member held; the value is set for NUMBER or STRING.
 * They fail only if tinygltf throws (out of memory: RAD_ERR_NOMEM).
 */
/* Node ni's KHR_lights_punctual: ABSENT (no extension), NUMBER ("light"
 * is one) or OTHER. */
rad_status sio_doc_node_light(const sio_doc *d, int ni, sio_val *tag,
                              double *light, rad_error *err);
/* Node ni's extras.luxrad_sensor: ABSENT, STRING or OTHER. */
rad_status sio_doc_node_sensor(const sio_doc *d, int ni, sio_val *tag,
                               sio_str *name, rad_error *err);
/* Node ni's extras.luxrad_photometry: ABSENT, STRING (a path: name),
 * NUMBER (packed: view is its bufferView, name the path it had) or
 * OTHER. */
rad_status sio_doc_node_photometry(const sio_doc *d, int ni, sio_val *tag,
                                   double *view, sio_str *name, rad_error *err);
/* Material mi's KHR_materials_emissive_strength.emissiveStrength:
 * ABSENT (no extension or no member), NUMBER or OTHER. */
rad_status sio_doc_material_strength(const sio_doc *d, int mi, sio_val *tag,
                                     double *strength, rad_error *err);

/* ------------------------------------------------------------ writing */

typedef struct sio_out_view {
	size_t offset, length; /* in the one buffer */
	int target;            /* SIO_GL_ARRAY_BUFFER... */
} sio_out_view;

typedef struct sio_out_accessor {
	int view, component_type, type;
	size_t count;
	int bounded; /* min and max given (POSITION needs them) */
	double min[3], max[3];
} sio_out_accessor;

typedef struct sio_out_attr {
	const char *name; /* "POSITION", "COLOR_0"... */
	int accessor;
} sio_out_attr;

/* A mesh of one triangle-list primitive. */
typedef struct sio_out_mesh {
	const char *name;
	sio_out_attr attrs[3];
	int nattrs;
	int indices; /* accessor, -1: none */
	int material;
} sio_out_mesh;

typedef struct sio_out_material {
	double base_color[3]; /* alpha 1, metallicFactor 0 */
	double emissive[3];
	int strength_ext; /* write KHR_materials_emissive_strength */
	double strength;
} sio_out_material;

typedef struct sio_out_light {
	const char *name, *type; /* "point", "spot", "directional" */
	double color[3], intensity, range, inner_cone, outer_cone;
} sio_out_light;

typedef struct sio_out_node {
	const char *name;
	int mesh, light; /* -1: none */
	int translated, rotated;
	double translation[3], rotation[4];
} sio_out_node;

/* Every node goes to the one scene, in order. */
typedef struct sio_out {
	const char *generator;
	const unsigned char *data; /* the one buffer; size 0: none */
	size_t size;
	const sio_out_view *views;
	const sio_out_accessor *accessors;
	const sio_out_mesh *meshes;
	const sio_out_material *materials;
	const sio_out_light *lights;
	const sio_out_node *nodes;
	const char *const *extensions_used;
	size_t nviews, naccessors, nmeshes, nmaterials, nlights, nnodes,
	        nextensions_used;
} sio_out;

/* Serialize as GLB or .gltf JSON; *bytes malloc'ed (caller frees). */
rad_status sio_doc_write(const sio_out *o, sio_format fmt, void **bytes,
                         size_t *len, rad_error *err);

#ifdef __cplusplus
}
#endif
#endif
