/*
 * sceneio.h -- glTF 2.0 import and export, the C face of the one C++ file
 * (gltf.cc) that uses tinygltf.
 *
 * Import takes bytes (a .gltf JSON document with embedded data: URI
 * buffers, or a .glb), never a path: external URIs are refused.  It builds
 * and commits a rad_scene: every mesh primitive of mode TRIANGLES in the
 * default scene (or all root nodes when there is none), with node
 * transforms (matrix or TRS, nested) applied; materials from
 * baseColorFactor (reflectance) and emissiveFactor x
 * KHR_materials_emissive_strength (luminance, cd/m2); KHR_lights_punctual
 * lights.  Malformed input gets RAD_ERR_INVALID and a message naming the
 * accessor / mesh / node and what is wrong.
 *
 * Export writes triangle meshes with optional per-vertex COLOR_0 and a
 * custom _ILLUMINANCE attribute (scalar float, lux) as GLB or .gltf bytes.
 */
#ifndef LUXRAD_SCENEIO_H
#define LUXRAD_SCENEIO_H

#include <stddef.h>
#include <stdint.h>

#include "../engine/rad.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct sio_info {
	uint32_t meshes, primitives, nodes;
	uint32_t primitives_skipped; /* non-triangle modes (points, lines) */
	uint32_t textures_ignored;   /* baseColorTexture etc. present */
	uint32_t metallic_materials; /* metallicFactor > 0 (treated diffuse) */
	char warnings[512];          /* tinygltf warnings, truncated */
} sio_info;

/*
 * Parse bytes and build a committed scene.  info may be NULL.  On error
 * *out is NULL and nothing is leaked.
 */
rad_status sio_load(const void *bytes, size_t len, rad_scene **out,
                    sio_info *info, rad_error *err);

/*
 * Read a whole file (scene_file.c): *out is malloc'ed, caller frees with
 * free().  RAD_ERR_IO names the path and the system's reason.  For local
 * tools and tests only: the daemon never reads a path a client names.
 */
rad_status sio_file_read(const char *path, unsigned char **out, size_t *len,
                         rad_error *err);

/* sio_file_read() then sio_load(). */
rad_status sio_load_file(const char *path, rad_scene **out, sio_info *info,
                         rad_error *err);

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
 * Every sensor of the document, in the walk's order (depth first, roots
 * in scene order).  *out is malloc'ed (NULL when there is none), freed
 * with sio_sensors_free.  RAD_ERR_INVALID names the node for an
 * empty, too long or duplicate name, conflicting declarations, a
 * non-string extras.luxrad_sensor, a zero or non-finite normal or a
 * non-finite position, and for every error sio_load would report
 * on the document's parsing or node hierarchy.  Parses the whole
 * document again (the scene's load does not keep it).
 */
rad_status sio_sensors(const void *bytes, size_t len, sio_sensor **out,
                       size_t *n, rad_error *err);
void sio_sensors_free(sio_sensor *s);

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
