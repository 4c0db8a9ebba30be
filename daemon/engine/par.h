/*
 * par.h -- a small fork-join thread pool for the engine's parallel loops.
 *
 * rad_par_for() splits [0, n) into chunks of `grain` indices and hands them
 * to the workers (the calling thread works too).  Which thread runs which
 * chunk varies from run to run, so callers write results only into slots
 * owned by the index (never into shared accumulators); that makes every
 * parallel loop of the engine give the same answer for any thread count.
 * Worker threads call rad_vis_thread_init() once at start.
 */
#ifndef LUXRAD_PAR_H
#define LUXRAD_PAR_H

#include <stddef.h>

#include "rad.h"

typedef struct rad_par rad_par;

typedef void (*rad_par_fn)(void *ud, size_t begin, size_t end, int thread);

/* nthreads <= 0 means the number of online cores. */
rad_status rad_par_new(int nthreads, rad_par **out, rad_error *err);
void rad_par_free(rad_par *p);
int rad_par_threads(const rad_par *p);

/* Run fn over [0, n) in chunks of grain (>= 1); returns when all are done.
 * p NULL: on the calling thread alone, as rad_par_threads counts it. */
void rad_par_for(rad_par *p, size_t n, size_t grain, rad_par_fn fn, void *ud);

#endif
