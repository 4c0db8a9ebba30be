/*
 * sceneio.h -- the scene library: glTF 2.0 in and out of the engine.
 *
 * Import takes bytes (a .gltf JSON document with embedded data: URI
 * buffers, or a .glb), never a path: external URIs are refused.  One
 * parse builds and commits a rad_scene and reads the document's sensor
 * nodes: every mesh primitive of mode TRIANGLES in the default scene (or
 * all root nodes when there is none), with node transforms (matrix or
 * TRS, nested) applied; materials from baseColorFactor times the base
 * colour texture's mean under each triangle (reflectance), doubleSided
 * (both faces), emissiveFactor x KHR_materials_emissive_strength
 * (luminance, cd/m2); KHR_lights_punctual lights, with the photometric
 * file a node names (extras.luxrad_photometry, packed).  Malformed input
 * gets RAD_ERR_INVALID and a message naming the accessor / mesh / node
 * and what is wrong.
 *
 * Export writes triangle meshes with optional per-vertex COLOR_0 and a
 * custom _ILLUMINANCE attribute (scalar float, lux) as GLB or .gltf bytes
 * (export.h builds them from a solution).
 *
 * tinygltf is behind one small C++ file (gltf_shim.cc); the rest of the
 * library is C (README.md lists the files).
 */
#ifndef LUXRAD_SCENEIO_H
#define LUXRAD_SCENEIO_H

#include <stddef.h>
#include <stdint.h>

#include "pack.h"
#include "rad.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct sio_info {
	uint32_t meshes, primitives, nodes;
	uint32_t primitives_skipped; /* non-triangle modes (points, lines) */
	uint32_t textures_ignored;   /* texture references not used: normal,
	                                occlusion, metallic-roughness,
	                                emissive, unreadable base colours */
	uint32_t textures_read;      /* materials whose reflectance comes from
	                                their base colour texture */
	uint32_t images_decoded;     /* image decodes (once each, unless the
	                                memory budget evicted one) */
	uint32_t textured_triangles; /* triangles given a texture's mean */
	uint32_t photometric_lights; /* lights given a photometric file by
	                                their node's extras */
	uint32_t metallic_materials; /* metallicFactor > 0 (treated diffuse) */
	char warnings[512];          /* tinygltf warnings, truncated */
} sio_info;

/*
 * Sensors: the points where the daemon publishes illuminance (Modbus).  A
 * node declares one by its name, "sensor:<name>", or by its extras,
 * {"luxrad_sensor": "<name>"} (both on one node must agree).  The sensor
 * sits at the node's world-space origin and faces the node's +Y axis in
 * world space (glTF's up: an untransformed sensor node measures on a
 * floor facing up), normalised; under a non-uniform scale that is the
 * image of the axis, not the normal of the node's XZ plane.  Nodes are
 * taken from the default scene as sio_load walks it; a sensor node
 * may also carry a mesh, which is then geometry as usual.
 */
#define SIO_SENSOR_NAME_MAX 64 /* bytes with the NUL */

typedef struct sio_sensor {
	char name[SIO_SENSOR_NAME_MAX]; /* non-empty, no control chars */
	double position[3];             /* metres, world space */
	double normal[3];               /* world space, unit length */
	uint32_t node;                  /* glTF node index */
} sio_sensor;

/*
 * Parse bytes once; build and commit the scene and read its sensors.
 *
 * scene: where the committed scene goes, or NULL to read the sensors
 * alone (the document is then checked only as far as sensors need: its
 * parsing and node hierarchy, not meshes, materials or lights).  info
 * may be NULL.  sensors and nsensors: both NULL for none, else every
 * sensor of the document in the walk's order (depth first, roots in
 * scene order); *sensors is malloc'ed (NULL when there is none), freed
 * with sio_sensors_free.
 *
 * RAD_ERR_INVALID names the node for an empty, too long or duplicate
 * sensor name, conflicting declarations, a non-string
 * extras.luxrad_sensor, a zero or non-finite normal or a non-finite
 * position.  A document that fails as a scene reports the scene's error
 * first.  On error every output is NULL or 0 and nothing is leaked.
 */
rad_status sio_load(const void *bytes, size_t len, rad_scene **scene,
                    sio_info *info, sio_sensor **sensors, size_t *nsensors,
                    rad_error *err);
void sio_sensors_free(sio_sensor *s);

/* sio_scene_read() (pack.h: a .gltf packed with the files beside it)
 * then sio_load() without sensors.  For local tools and tests only: the
 * daemon never reads a path a client names. */
rad_status sio_load_file(const char *path, rad_scene **out, sio_info *info,
                         rad_error *err);

typedef struct sio_mesh {
	const char *name;      /* node and mesh name; may be NULL */
	const float *position; /* 3 floats per vertex */
	const float *color;    /* COLOR_0, 3 floats per vertex (linear); NULL */
	const float *illuminance; /* _ILLUMINANCE, 1 float per vertex; NULL */
	const uint32_t *index;    /* 3 per triangle; NULL = non-indexed */
	size_t nvertices, nindices;
	double base_color[3];     /* reflectance */
	double emissive[3];       /* emissiveFactor, in [0,1] */
	double emissive_strength; /* KHR_materials_emissive_strength; 1 = none
	                           */
} sio_mesh;

typedef enum sio_format { SIO_FORMAT_GLB = 0, SIO_FORMAT_JSON } sio_format;

/*
 * Serialize meshes and lights.  *out is malloc'ed (caller frees with
 * free()); JSON output embeds buffers as data: URIs.
 */
rad_status sio_write(const sio_mesh *meshes, size_t nmeshes,
                     const rad_light_desc *lights, size_t nlights,
                     sio_format fmt, void **out, size_t *outlen,
                     rad_error *err);

#ifdef __cplusplus
}
#endif
#endif
