/*
 * solver.c -- what all solvers share: creation, stepping, timing,
 * statistics and memory reports.  The solvers themselves (matrix.c,
 * progressive.c, hr.c, rmb.c) only implement the ops table of solver.h.
 */
#include "solver.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "vis.h"

static const rad_solver_ops *const solver_table[RAD_SOLVER_NKINDS] = {
        [RAD_SOLVER_MATRIX] = &rad_solver_matrix_ops,
        [RAD_SOLVER_PROGRESSIVE] = &rad_solver_progressive_ops,
        [RAD_SOLVER_HR] = &rad_solver_hr_ops,
        [RAD_SOLVER_RMB] = &rad_solver_rmb_ops,
};

rad_status rad_solver_kind_parse(const char *name, rad_solver_kind *out)
{
	for (int k = 0; k < RAD_SOLVER_NKINDS; k++) {
		if (strcmp(name, solver_table[k]->name) == 0) {
			*out = (rad_solver_kind)k;
			return RAD_OK;
		}
	}
	return RAD_ERR_INVALID;
}

const char *rad_solver_kind_name(rad_solver_kind k)
{
	return (unsigned)k < RAD_SOLVER_NKINDS ? solver_table[k]->name : "?";
}

/* The solver's own state and hierarchy, freed (sv->impl NULL). */
static void solver_drop(rad_solver *sv)
{
	if (sv->ops && sv->impl)
		sv->ops->destroy(sv);
	sv->impl = NULL;
	rad_hier_destroy(&sv->h);
}

/* 1 if the solver's elements keep dB in floats: rmb sends it (hier.h,
 * Increments). */
static int exact_dB(const rad_options *o)
{
	return o->solver == RAD_SOLVER_RMB;
}

/* The solver's hierarchy and own state, from nothing. */
static rad_status solver_build(rad_solver *sv, rad_error *err)
{
	rad_status st = rad_hier_init(&sv->h, sv->scene, &sv->mem,
	                              sv->opt.min_edge_rel * sv->scene->diag,
	                              sv->opt.solver == RAD_SOLVER_HR,
	                              exact_dB(&sv->opt), sv->par, err);
	if (!st)
		st = sv->ops->init(sv, err);
	return st;
}

rad_status rad_solver_new(const rad_scene *scene, const rad_options *opt,
                          rad_solver **out, rad_error *err)
{
	*out = NULL;
	if (!scene || !scene->committed)
		return rad_fail(err, RAD_ERR_STATE, "scene is not committed");
	rad_status st = rad_options_check(opt, err);
	if (st)
		return st;
	/* The struct itself is not counted: it is fixed-size bookkeeping;
	 * everything that grows with the scene is. */
	rad_solver *sv = calloc(1, sizeof(*sv));
	if (!sv)
		return rad_fail(err, RAD_ERR_NOMEM, "solver: out of memory");
	sv->scene = scene;
	sv->opt = *opt;
	sv->ops = solver_table[opt->solver];
	rad_mem_init(&sv->mem);
	sv->mem.base = &scene->mem;
	rad_mem_set_budget(&sv->mem, (int64_t)(opt->memory_budget * 1048576.0));
	double flux = RAD_LUMA_R * scene->total_flux[0] +
	              RAD_LUMA_G * scene->total_flux[1] +
	              RAD_LUMA_B * scene->total_flux[2];
	sv->flux_scale = flux > 0 ? flux : 1.0;
	sv->tol = opt->converge_tol;
	st = rad_par_new(opt->threads, &sv->par, err);
	if (!st)
		st = solver_build(sv, err);
	if (st == RAD_ERR_NOMEM && atomic_load(&sv->mem.budget_refusals))
		rad_fail(err, st,
		         "%s: the memory budget (%g MiB) is smaller than this "
		         "scene's element and cluster hierarchy and the room "
		         "its first step starts with (%u polygons: %.1f MiB "
		         "for their root elements alone)",
		         sv->ops->name, opt->memory_budget, scene->npolys,
		         (double)scene->npolys *
		                 (rad_hier_elem_size(exact_dB(opt)) + 1) /
		                 1048576.0);
	if (st) {
		rad_solver_free(sv);
		return st;
	}
	rad_solver_stats(sv, &sv->stats);
	*out = sv;
	return RAD_OK;
}

double rad_seconds(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/*
 * Budget restarts.  hr stores every link it gathers, so a memory budget
 * reached in its first steps, which make the links of the direct light
 * and of the first bounce, goes to the first sources' transfers at eps,
 * and the rest of the scene keeps coarse pairs: at half its own peak,
 * hr's mean error was 4-11x the unbudgeted one on three of four scenes
 * (README, "Memory budget").  A coarser solution everywhere spends the
 * same memory better.  So where the budget is reached in one of the
 * first ops->restart_steps steps, the solve starts over at twice eps
 * (its hierarchy and links freed, the scene kept) and runs again to the
 * step it was at, at most RESTARTS_MAX times (eps x 64).  The attempt
 * stops as soon as its budget is reached (rad_solver_budget_reached
 * raises sv->abandon where one_step armed sv->restart_armed, and the
 * cancel paths see it) instead of running its step to the end, all of
 * which would be thrown away: the same solve, in 0.77-0.95x the time
 * on three scenes (README).  A budget reached
 * later holds pairs where they are, as before: the links still to
 * refine then carry reflected light (the Graz office reaches a budget
 * of half its peak in its fifth step, and holding pairs costs it
 * 1.15x).  The steps run again belong to the iteration that restarted:
 * its time includes them, and a cancel among them leaves the rest to
 * the next call (sv->redo) with the iteration count unchanged.  The
 * budget's judgement does not depend on the threads, nor do the
 * restarts.
 */
#define RESTARTS_MAX 6

/* What an iteration did to the links, zero.  A restart clears them too:
 * they describe what the iteration leaves, and its rays and time what
 * it cost. */
static void clear_step_counts(rad_stats *s)
{
	s->links_created = s->links_deleted = 0;
	s->links_recreated = s->links_gathered = 0;
	s->links_transient = s->links_useful = 0;
	s->budget_held = s->budget_transient = 0;
	memset(s->energy_hist, 0, sizeof(s->energy_hist));
}

/* 1 if a budget reached in step `step` of the solve (0: its first)
 * starts it over. */
static int restarts_at(const rad_solver *sv, uint32_t step)
{
	return sv->mem.budget && step < sv->ops->restart_steps &&
	       sv->stats.budget_restarts < RESTARTS_MAX;
}

/* Start the solve over at twice eps, `steps` steps to run again.  On
 * failure (out of memory: what was freed was taken meanwhile) the solver
 * is left without a hierarchy (sv->impl NULL): it may only be freed. */
static rad_status restart(rad_solver *sv, uint32_t steps, rad_error *err)
{
	solver_drop(sv);
	sv->opt.eps *= 2;
	sv->stats.budget_restarts++;
	clear_step_counts(&sv->stats);
	sv->prev_residual = 0;
	sv->done = 0;
	sv->redo = steps;
	rad_status st = solver_build(sv, err);
	if (st) {
		char why[sizeof(err->msg)] = "";
		if (err)
			memcpy(why, err->msg, sizeof(why));
		solver_drop(sv);
		return rad_fail(err, st,
		                "%s: starting over at eps %g under the memory "
		                "budget: %s",
		                sv->ops->name, sv->opt.eps, why);
	}
	return RAD_OK;
}

/* One step of the solver, seen by it as step sv->done of its solve. */
static rad_status one_step(rad_solver *sv, uint32_t iteration, rad_error *err)
{
	sv->stats.iteration = sv->done;
	sv->restart_armed = restarts_at(sv, sv->done);
	rad_status st = sv->ops->step(sv, err);
	sv->stats.iteration = iteration;
	if (!st)
		sv->done++;
	return st;
}

/* The steps of one iteration: the solver's next one (sv->redo 1), and
 * the restarts it calls for with the steps they run again; or, after a
 * cancel among those, the ones still to run. */
static rad_status iteration_steps(rad_solver *sv, rad_error *err)
{
	uint32_t it = sv->stats.iteration;
	rad_status st = RAD_OK;
	if (!sv->redo)
		sv->redo = 1;
	while (!st && sv->redo) {
		st = one_step(sv, it, err);
		if (rad_solver_abandoned(sv)) {
			/* The budget was reached in an armed step (one_step):
			 * stopped there, or ended anyway; start over. */
			__atomic_store_n(&sv->abandon, 0, __ATOMIC_RELAXED);
			if (!st || st == RAD_ERR_CANCELLED)
				st = restart(sv, it + 1, err);
			continue;
		}
		if (!st)
			sv->redo--;
	}
	return st;
}

rad_status rad_solver_step(rad_solver *sv, rad_error *err)
{
	if (!sv->impl)
		return rad_fail(err, RAD_ERR_STATE,
		                "%s: the solver failed in an earlier step and "
		                "may only be freed",
		                sv->ops->name);
	if (rad_solver_cancelled(sv))
		return rad_fail(err, RAD_ERR_CANCELLED, "cancelled");
	double t0 = rad_seconds();
	uint64_t splits0 = sv->h.splits;
	uint32_t restarts0 = sv->stats.budget_restarts;
	clear_step_counts(&sv->stats);
	sv->stats.rays = 0;
	rad_status st = iteration_steps(sv, err);
	if (st)
		return st;
#ifdef LUXRAD_CHECKS
	char why[sizeof(err->msg)];
	if (rad_hier_check(&sv->h, why, sizeof(why)) != 0)
		return rad_fail(err, RAD_ERR_STATE, "%s", why);
#endif
	sv->stats.iteration++;
	sv->stats.seconds = rad_seconds() - t0;
	sv->stats.seconds_total += sv->stats.seconds;
	/* A restart counts the splits of its new hierarchy only. */
	sv->stats.refinements =
	        sv->h.splits -
	        (sv->stats.budget_restarts == restarts0 ? splits0 : 0);
	sv->stats.converged = sv->stats.error_estimate <= sv->tol;
	rad_solver_stats(sv, &sv->stats);
	return RAD_OK;
}

rad_status rad_solver_converge(rad_solver *sv, double tol, uint32_t max_iter,
                               rad_error *err)
{
	if (tol == 0)
		tol = sv->opt.converge_tol;
	if (!(tol > 0))
		return rad_fail(err, RAD_ERR_INVALID,
		                "tolerance must be > 0 (got %g)", tol);
	sv->tol = tol;
	if (max_iter == 0)
		max_iter = (uint32_t)sv->opt.max_iterations;
	for (uint32_t i = 0; i < max_iter; i++) {
		rad_status st = rad_solver_step(sv, err);
		if (st)
			return st;
		if (sv->stats.converged)
			break;
	}
	return RAD_OK;
}

rad_status rad_solver_set_eps(rad_solver *sv, double eps, rad_error *err)
{
	if (!(eps > 0) || !isfinite(eps))
		return rad_fail(err, RAD_ERR_INVALID,
		                "eps must be a finite number > 0 (got %g)",
		                eps);
	sv->opt.eps = eps;
	return RAD_OK;
}

void rad_solver_stats(const rad_solver *sv, rad_stats *out)
{
	if (out != &sv->stats)
		*out = sv->stats;
	out->eps = sv->opt.eps;
	out->elements = rad_hier_elements(&sv->h);
	out->clusters = rad_pool_live(&sv->h.clusters);
	out->leaves = sv->h.nleaves;
	rad_mem_report_joint(&sv->mem, &out->mem);
}

void rad_solver_memory(const rad_solver *sv, rad_mem_report *out)
{
	rad_mem_report_clear(out);
	rad_mem_report_add(&sv->mem, out);
}

void rad_solver_census(const rad_solver *sv, rad_census *out)
{
	if (sv->impl)
		rad_hier_census(&sv->h, out);
	else
		memset(out, 0, sizeof(*out));
}

void rad_solver_free(rad_solver *sv)
{
	if (!sv)
		return;
	solver_drop(sv);
	rad_par_free(sv->par);
	free(sv);
}
