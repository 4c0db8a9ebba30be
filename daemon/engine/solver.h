/*
 * solver.h -- what every solver shares: the hierarchy, counters, the
 * thread pool, options and published statistics; and the table of solver
 * implementations (matrix.c, progressive.c, hr.c, rmb.c).
 */
#ifndef LUXRAD_SOLVER_H
#define LUXRAD_SOLVER_H

#include "hier.h"
#include "par.h"
#include "rad.h"

typedef struct rad_solver_ops {
	const char *name;
	rad_status (*init)(rad_solver *sv, rad_error *err);
	/* One iteration; fills the iteration-specific fields of sv->stats
	 * (links, residual, error_estimate, rays...).  The caller times it,
	 * counts memory and bumps sv->stats.iteration. */
	rad_status (*step)(rad_solver *sv, rad_error *err);
	void (*destroy)(rad_solver *sv); /* frees sv->impl */
	/* Under a memory budget: a budget reached in one of the first
	 * restart_steps steps starts the solve over at twice eps (solver.c,
	 * "Budget restarts"); 0: never. */
	uint32_t restart_steps;
} rad_solver_ops;

struct rad_solver {
	const rad_scene *scene;
	rad_options opt;
	rad_mem mem;  /* everything this solver holds */
	rad_hier h;   /* elements, clusters, links */
	rad_par *par; /* worker threads */
	const rad_solver_ops *ops;
	void *impl;           /* solver-private state, counted in mem */
	rad_stats stats;      /* published after each step */
	double flux_scale;    /* photopic flux of all sources (lm), > 0 */
	double tol;           /* convergence tolerance for error_estimate */
	double prev_residual; /* residual of the previous step, 0 before */
	uint32_t done;        /* steps of the solve since its last start */
	uint32_t redo;        /* steps a restart has still to run again */
	int restart_armed;    /* a budget reached in the step now running
	                         starts the solve over (solver.c) */
	int abandon; /* the step now running will be run again at twice eps:
	                stop it (solver.c, Budget restarts); atomic */
};

extern const rad_solver_ops rad_solver_matrix_ops;
extern const rad_solver_ops rad_solver_progressive_ops;
extern const rad_solver_ops rad_solver_hr_ops;
extern const rad_solver_ops rad_solver_rmb_ops;

/*
 * 1 if the caller's cancel flag is raised.  The flag is written by
 * another thread, so it is read with an atomic load (relaxed: it orders
 * nothing, it only has to be seen); a plain volatile read is a data race
 * in C11 terms, and ThreadSanitizer reports it.
 */
static inline int rad_solver_cancelled(const rad_solver *sv)
{
	return (sv->opt.cancel &&
	        __atomic_load_n(sv->opt.cancel, __ATOMIC_RELAXED) != 0) ||
	       __atomic_load_n(&sv->abandon, __ATOMIC_RELAXED) != 0;
}

/* 1 if the step now running is to stop because the solve will start
 * over (solver.c, Budget restarts): seen by rad_solver_cancelled too,
 * so the cancel paths stop it; here for the waves, which go on after a
 * cancel unless deferrable. */
static inline int rad_solver_abandoned(const rad_solver *sv)
{
	return __atomic_load_n(&sv->abandon, __ATOMIC_RELAXED) != 0;
}

/*
 * The memory budget has just been reached in the step now running (its
 * first time in this step).  Where that sends the solve back to its start
 * (solver.c, Budget restarts: one_step says so in sv->restart_armed), the
 * step is told to stop: what it would still do is thrown away.  Inline,
 * so that the waves below solver.c do not call up into it.
 */
static inline void rad_solver_budget_reached(rad_solver *sv)
{
	if (sv->restart_armed)
		__atomic_store_n(&sv->abandon, 1, __ATOMIC_RELAXED);
}

/* Report progress within an iteration (fraction in [0,1]). */
static inline void rad_solver_progress(const rad_solver *sv, double f)
{
	if (sv->opt.progress)
		sv->opt.progress(sv->opt.progress_ud, f);
}

/*
 * Estimate the remaining relative error from the last two residuals of a
 * linearly converging iteration: r_k q / (1 - q) with q = r_k / r_{k-1}.
 */
static inline double rad_error_estimate(double r_prev, double r_now)
{
	if (!(r_now > 0))
		return 0;
	if (!(r_prev > 0))
		return r_now; /* first iteration: no rate known yet */
	double q = r_now / r_prev;
	/* A rate near or above 1 (refinement just changed the solution)
	 * tells nothing about the tail: report a large, finite estimate. */
	if (q >= 0.999)
		return r_now * 1000.0;
	return r_now * q / (1.0 - q);
}
/* Publish a step's residual and the error estimate it gives. */
static inline void rad_solver_set_residual(rad_solver *sv, double r)
{
	sv->stats.residual = r;
	sv->stats.error_estimate = rad_error_estimate(sv->prev_residual, r);
	sv->prev_residual = r;
}

/*
 * Queries over any hierarchy (query.c): a solver's own, or a published
 * solution's (solution.c).  par NULL runs on the caller's thread.
 */
typedef struct rad_query_args {
	const double *pts; /* 6 per point */
	size_t n;
	double tol;         /* relative tolerance of the gather, (0, 1) */
	double solve_error; /* the solution's relative error, >= 0 */
	double *lux;        /* n outputs */
	double *error_lux;  /* n outputs, or NULL */
} rad_query_args;
rad_status rad_query_illuminance(const rad_scene *scene, const rad_hier *h,
                                 rad_par *par, const rad_query_args *a,
                                 rad_error *err);
void rad_query_leaves(const rad_hier *h, rad_leaf_fn fn, void *ud);

#endif
