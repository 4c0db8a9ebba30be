/*
 * ff.h -- form factors and direct illumination from lights.
 *
 * Conventions.  F(r <- s) is the form factor from receiver r to source s:
 * the irradiance r receives, averaged over r, per unit radiosity of s.  For
 * surfaces this is the classic F_rs = (1/A_r) int_r int_s cos cos V/(pi d^2).
 *
 * The unoccluded kernel is exact at each receiver point: the point-to-
 * polygon form factor by Lambert's contour integral, with the source
 * polygon clipped to the receiver point's upper hemisphere, and only the
 * front side of the source emitting.  The receiver integral uses a fixed,
 * deterministic pattern of points (the same pattern for the same
 * geometry, whatever the thread or call order).  Visibility is the
 * fraction of unblocked shadow rays between receiver points and a fixed
 * pattern of source points.
 */
#ifndef LUXRAD_FF_H
#define LUXRAD_FF_H

#include "scene.h"
#include "vec.h"

/* A planar patch: triangle or parallelogram (see scene.h), in double. */
typedef struct rad_patch {
	v3 p0, e1, e2;
	v3 n;        /* unit front normal */
	double area; /* m2 */
	int quad;
} rad_patch;

#define RAD_FF_MAX_SAMPLES 16

void rad_patch_from_poly(rad_patch *p, const rad_scene *s,
                         const rad_poly *poly);
void rad_patch_from_floats(rad_patch *p, const float p0[3], const float e1[3],
                           const float e2[3], int quad);
v3 rad_patch_centroid(const rad_patch *p);
/* Vertices in order (3 or 4); returns the count. */
int rad_patch_vertices(const rad_patch *p, v3 out[4]);

/*
 * n deterministic sample points (1 <= n <= RAD_FF_MAX_SAMPLES) spread over
 * the patch with equal weights (stratified: one point in each of n
 * equal-area cells where n is 1, 4 or 16 -- the centroid for 1, a rule
 * exact for quadratics over the patch for 4, and over each quarter for 16;
 * other n are served from the next larger pattern).  Returns the number
 * of points written.
 */
int rad_patch_samples(const rad_patch *p, int n, v3 *out);
/* n points scattered over the patch by Roberts' R2 sequence, which no
 * regular layout of a scene lines up with (ff.c). */
int rad_patch_scatter(const rad_patch *p, int n, v3 *out);

/* Exact point-to-polygon form factor (unoccluded) from a differential
 * area at x with unit normal nx to the patch; 0 if the patch is behind x
 * or x is behind the patch. */
double rad_ff_point_patch(v3 x, v3 nx, const rad_patch *s);

/* Cheap estimate of F(r <- s) for refinement oracles (no visibility). */
double rad_ff_estimate(const rad_patch *r, const rad_patch *s);

/* Unoccluded F(r <- s): receiver integral of the exact point kernel. */
double rad_ff_unoccluded(const rad_patch *r, const rad_patch *s, int nrcv);

/*
 * F(r <- s) with visibility: nrcv receiver points, nvis shadow rays from
 * each towards a fixed pattern of source points.  *rays (may be NULL) is
 * incremented by the number of rays traced.  vis may be NULL (no
 * occluders: unoccluded result).
 */
double rad_ff_patch(const rad_vis *vis, const rad_patch *r, const rad_patch *s,
                    int nrcv, int nvis, uint64_t *rays);

/*
 * The same, and the spread (max - min) of the per-point values over the
 * receiver points in *spread (may be NULL): how far the receiver is from
 * seeing the source uniformly, the refinement oracles' error measure.
 * cover > 0 leaves out the source points that something in front of them
 * closer than cover hides (hier.h, Covered parts); 0 samples all of it.
 * rcover > 0 does the same for receiver points that see nothing of the
 * source while others do: the result is then F from the receiver's
 * exposed part, to be scaled by its exposed fraction.
 */
double rad_ff_patch_spread(const rad_vis *vis, const rad_patch *r,
                           const rad_patch *s, int nrcv, int nvis, double cover,
                           double rcover, uint64_t *rays, double *spread);

/*
 * The receiver integral from the values f[] at n points xs of a surface
 * of unit normal nr: their mean, and their spread (max - min) in *spread
 * (may be NULL).  With rcover > 0, a point that receives nothing while
 * another receives something is left out when something in front of it
 * closer than rcover covers it (hier.h, Covered parts; one ray, counted
 * in *rays): the mean is then over the receiver's exposed part, and the
 * caller scales it by the exposed fraction.  n <= RAD_FF_MAX_SAMPLES.
 */
double rad_ff_rcv_mean(const rad_vis *vis, v3 nr, const v3 *xs, const double *f,
                       int n, double rcover, uint64_t *rays, double *spread);

/*
 * Irradiance (lux per unit intensity, scalar geometry factor) that light L
 * gives at point x with unit normal nx, visibility included (one ray).
 * Multiply by L->intensity[c] for channel c.  nx may face away: 0.
 */
double rad_light_point(const rad_vis *vis, const rad_light *L, v3 x, v3 nx,
                       uint64_t *rays);

/* Same, averaged over nrcv points of patch r. */
double rad_light_patch(const rad_vis *vis, const rad_light *L,
                       const rad_patch *r, int nrcv, uint64_t *rays);

/* Same, with the spread over the receiver points and the receiver's
 * covered points left out as rad_ff_patch_spread does (see above). */
double rad_light_patch_spread(const rad_vis *vis, const rad_light *L,
                              const rad_patch *r, int nrcv, double rcover,
                              uint64_t *rays, double *spread);

/* Unoccluded estimate of rad_light_patch at the centroid (for oracles). */
double rad_light_estimate(const rad_light *L, const rad_patch *r);

#endif
