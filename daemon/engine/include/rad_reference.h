/*
 * rad_reference.h -- the engine's second public header, beside rad.h:
 * the Monte Carlo estimator, for luxrad-reference and the tests that
 * hold lux to it, and the audit of a solution's links against Monte
 * Carlo (luxrad-solve --audit-links).
 */
#ifndef LUXRAD_RAD_REFERENCE_H
#define LUXRAD_RAD_REFERENCE_H

#include "rad.h"

#ifdef __cplusplus
extern "C" {
#endif

/*
 * An independent Monte Carlo estimate of illuminance (reference.c): the
 * ground truth the solvers are validated against.  It shares only the
 * scene and its BVH with them.  Unbiased path tracing of one-sided
 * Lambertian surfaces (a ray meeting a back face is absorbed), with
 * next-event estimation to emitting polygons (combined with the bounce
 * by multiple importance sampling) and to every punctual and directional
 * light, and Russian roulette.  Each point gets a mean and the standard
 * error of that mean from the sample variance of its paths.
 *
 * Results depend on the seed, the options and each point's index in pts
 * (path j of point i is keyed by (seed, i, j)); never on the thread count
 * or the schedule: they are bit for bit reproducible.
 */
typedef struct rad_ref_options {
	uint64_t samples;     /* paths per point; 0 = run to target_error */
	double target_error;  /* samples 0: add paths to a point until its
	                         stderr <= target_error x its mean, (0, 1) */
	uint64_t max_samples; /* samples 0: paths per point at most, >= 2 */
	int threads;          /* 0..256; 0 = one per core */
	uint64_t seed;        /* any value; the same seed, the same result */
	/* Raised by another thread to stop early (RAD_ERR_CANCELLED);
	 * read with an atomic load, as rad_options.cancel. */
	const volatile int *cancel;
} rad_ref_options;

/* samples 0, target_error 0.005, max_samples 2^22, threads 0, seed 1. */
void rad_ref_options_default(rad_ref_options *o);

/*
 * Illuminance in lux at n points (6 doubles each: x y z nx ny nz, as
 * rad_solver_illuminance; a point sees the side its normal points to).
 * o may be NULL for the defaults.  lux[i] is the estimate, stderr_lux[i]
 * its standard error (NaN with fewer than 2 paths), samples_used[i] the
 * paths traced for it; stderr_lux and samples_used may be NULL.  The
 * scene must be committed (RAD_ERR_STATE); a non-finite point or a zero
 * normal is RAD_ERR_INVALID naming the point.  On RAD_ERR_CANCELLED the
 * outputs hold the estimates of the rounds completed.
 */
rad_status rad_reference_illuminance(const rad_scene *s, const double *pts,
                                     size_t n, const rad_ref_options *o,
                                     double *lux, double *stderr_lux,
                                     uint64_t *samples_used, rad_error *err);

/*
 * The links of an hr or rmb solution held to Monte Carlo (audit.c): every
 * `every`-th link the solver gathers (lights' excepted; rmb's active
 * ones, the leaves of its link hierarchy), in the order of
 * the hierarchy, has its transfer estimated again from `samples` random
 * point pairs and one shadow ray each, with nothing of the solvers' form
 * factors.  Sums are by class, index 4 near + 2 (receiver is a cluster) +
 * (source is a cluster); a pair is near when its larger end is larger
 * than the distance between their centres.  Each sum is of A_r x F x
 * photopic radiosity (lm):
 *   stored_form      the link's F, the source's mean radiosity;
 *   stored_transfer  the same times the cluster emission factor: what the
 *                    gather moves;
 *   mc_form          F by Monte Carlo, the source's mean radiosity;
 *   mc_transfer      by Monte Carlo with the radiosity of the leaf each
 *                    source sample falls on: what the link should move.
 * stored_form / mc_form is the form factors' error, stored_transfer /
 * mc_transfer the link's.  Deterministic for a given seed.  The point
 * kernel is unbounded where surfaces touch: there the estimate is
 * unbiased but heavy-tailed (its typical value reads low).
 */
#define RAD_AUDIT_CLASSES 8
typedef struct rad_audit_class {
	uint64_t links;
	double stored_form, stored_transfer, mc_form, mc_transfer;
} rad_audit_class;

typedef struct rad_audit {
	rad_audit_class cls[RAD_AUDIT_CLASSES];
	uint64_t links_total; /* gathered links from surfaces and clusters */
	uint64_t rays;        /* shadow rays traced */
} rad_audit;

typedef struct rad_audit_options {
	unsigned every;   /* audit one link in `every` (>= 1) */
	unsigned samples; /* point pairs per link (>= 1) */
	uint64_t seed;
} rad_audit_options;

/* every 10, samples 64, seed 1. */
void rad_audit_options_default(rad_audit_options *o);

/* Between steps (not while one runs).  RAD_ERR_UNSUPPORTED for matrix and
 * progressive, which keep no links; o NULL for the defaults.  For rmb,
 * the links are those of its last iteration (they coarsen as dB shrinks)
 * and the radiosity is B, not the dB it gathers: the audit is of their
 * form factors and of how a link averages its source. */
rad_status rad_solver_audit_links(rad_solver *sv, const rad_audit_options *o,
                                  rad_audit *out, rad_error *err);

#ifdef __cplusplus
}
#endif

#endif
