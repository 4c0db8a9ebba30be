/*
 * vis.h -- visibility through Embree 3.
 *
 * One Embree device and one committed scene per rad_scene, built at commit
 * and shared read-only by every solver and thread.  Robust mode, build
 * quality medium.  Bytes Embree allocates are counted as RAD_MEM_BVH in
 * the scene's counters through the device memory monitor.
 *
 * Ray ends are trimmed by eps = RAD_VIS_EPS_REL x the scene's
 * bounding-box diagonal (more for a scene far from the origin, where float
 * coordinates are coarser), so results do not change when the whole scene
 * is scaled: an endpoint that lies on a surface is moved off it by eps along
 * the surface normal (towards the side the other endpoint is on) and the
 * segment is shortened by eps at both ends.
 *
 * All queries are thread-safe and do no allocation.  Each thread that
 * traces must first call rad_vis_thread_init() (sets flush-to-zero and
 * denormals-are-zero, as Embree asks).
 */
#ifndef LUXRAD_VIS_H
#define LUXRAD_VIS_H

#include "rad.h"
#include "scene.h"
#include "vec.h"

#define RAD_VIS_EPS_REL 1e-5

/* Build s->vis from s->polys; counts BVH memory into s->mem. */
rad_status rad_vis_build(rad_scene *s, rad_error *err);
/* Release s->vis (BVH memory count returns to zero). */
void rad_vis_free(rad_scene *s);

void rad_vis_thread_init(void);

/* The trimming distance for this scene, metres. */
double rad_vis_eps(const rad_vis *v);

/*
 * 1 if the segment a -> b is unblocked.  na / nb are the surface normals
 * at a / b, or NULL where the endpoint is not on a surface (light, cluster
 * centre).  The trimming above is applied here.
 */
int rad_vis_segment(const rad_vis *v, v3 a, const v3 *na, v3 b, const v3 *nb);
/* A segment between two surface points, with their normals. */
typedef struct rad_vis_seg {
	v3 a, na, b, nb;
} rad_vis_seg;
/* rad_vis_segment(v, s.a, &s.na, s.b, &s.nb) for each of n segments,
 * traced in packets: open[k] is segment k's answer, the same one. */
void rad_vis_segments(const rad_vis *v, const rad_vis_seg *s, int n,
                      unsigned char *open);

/*
 * 1 if something lies in front of the surface point x (unit normal n),
 * between the trimming distance and dist: x is covered (hier.h).
 */
int rad_vis_covered(const rad_vis *v, v3 x, v3 n, double dist);
/* rad_vis_covered for each of the count points pts (normal n), traced in
 * packets: covered[k] is point k's answer, the same one. */
void rad_vis_covered_n(const rad_vis *v, v3 n, double dist, const v3 *pts,
                       int count, unsigned char *covered);

/*
 * Keep, of the count points pts on a surface of unit normal n, those not
 * covered closer than dist (rad_vis_covered), in order; nrm (or NULL) is
 * kept in step, and *rays (or NULL) counts the rays.  Returns how many
 * are left.
 */
int rad_vis_keep_uncovered(const rad_vis *v, v3 n, double dist, v3 *pts,
                           v3 *nrm, int count, uint64_t *rays);

/* 1 if the ray from a (normal na or NULL) in unit direction d escapes to
 * infinity (directional lights). */
int rad_vis_ray_free(const rad_vis *v, v3 a, const v3 *na, v3 d);

/*
 * Nearest hit of a ray: returns the polygon index (into scene->polys) or
 * UINT32_MAX for a miss; *t receives the distance.
 */
uint32_t rad_vis_first_hit(const rad_vis *v, v3 org, v3 dir, double tfar,
                           double *t);

/*
 * Nearest hit for a path tracer over one-sided surfaces.  Real scenes
 * write a two-sided face as two coincident triangles facing opposite
 * ways, and Embree's choice between exactly coincident hits is arbitrary:
 * here a back-face hit loses to a front-face hit up to eps (rad_vis_eps)
 * behind it, so such a pair always shows its front.  The ray is
 * org + t dir, dir unit, tnear < t < tfar (the caller offsets org off its
 * surface).  Returns the polygon or UINT32_MAX for a miss; *t receives the
 * distance (tfar on a miss), *front 1 when the ray meets the polygon's
 * front side (e1 x e2 against dir).  Costs rad_vis_first_hit's existing
 * callers nothing: the filter lives in this query's own context.
 */
uint32_t rad_vis_first_hit_front(const rad_vis *v, v3 org, v3 dir, double tnear,
                                 double tfar, double *t, int *front);

#endif
