/*
 * export.h -- the solved mesh as glTF: one mesh per scene node, built from
 * a published solution's leaf elements, with per-vertex illuminance.
 *
 * Used by the daemon's "export" command and by luxrad-solve --export.
 * Each vertex carries _ILLUMINANCE (float, lux: the photopic irradiance)
 * and COLOR_0 (linear RGB in [0,1]: the reflected radiosity tone-mapped
 * with x / (x + white), white the 99th percentile of leaf values unless
 * given).  The output validates with the Khronos glTF validator.
 */
#ifndef LUXRAD_EXPORT_H
#define LUXRAD_EXPORT_H

#include <stddef.h>

#include "sceneio.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct sio_export_opts {
	sio_format format; /* GLB (default) or .gltf JSON */
	double white_lux;  /* tone-map white point; 0 = automatic */
	int flat;          /* 1: one value per leaf (no vertex sharing);
	                      0 (default): vertices shared within a node
	                      get the area-weighted mean of their leaves */
} sio_export_opts;

typedef struct sio_export_info {
	size_t meshes, vertices, triangles;
	double white_lux; /* the white point used */
} sio_export_info;

void sio_export_opts_default(sio_export_opts *o);

/* Serialize; *out malloc'ed (caller frees).  info may be NULL. */
rad_status sio_export_solution(const rad_scene *scene, const rad_solution *sol,
                               const sio_export_opts *o, unsigned char **out,
                               size_t *len, sio_export_info *info,
                               rad_error *err);

#ifdef __cplusplus
}
#endif
#endif
