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
		st = rad_hier_init(&sv->h, scene, &sv->mem,
		                   opt->min_edge_rel * scene->diag,
		                   opt->solver == RAD_SOLVER_HR, err);
	if (!st)
		st = sv->ops->init(sv, err);
	if (st == RAD_ERR_NOMEM && atomic_load(&sv->mem.budget_refusals))
		rad_fail(err, st,
		         "%s: the memory budget (%g MiB) is smaller than this "
		         "scene's element and cluster hierarchy (%u polygons: "
		         "%.1f MiB for their root elements alone)",
		         sv->ops->name, opt->memory_budget, scene->npolys,
		         (double)scene->npolys * sizeof(rad_elem) / 1048576.0);
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

rad_status rad_solver_step(rad_solver *sv, rad_error *err)
{
	if (rad_solver_cancelled(sv))
		return rad_fail(err, RAD_ERR_CANCELLED, "cancelled");
	double t0 = rad_seconds();
	uint64_t splits0 = sv->h.splits;
	sv->stats.links_created = sv->stats.links_deleted = 0;
	sv->stats.links_recreated = sv->stats.links_gathered = 0;
	sv->stats.links_transient = sv->stats.links_useful = 0;
	sv->stats.budget_held = sv->stats.budget_transient = 0;
	memset(sv->stats.energy_hist, 0, sizeof(sv->stats.energy_hist));
	sv->stats.rays = 0;
	rad_status st = sv->ops->step(sv, err);
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
	sv->stats.refinements = sv->h.splits - splits0;
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
	out->elements = rad_pool_live(&sv->h.elems);
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
	rad_hier_census(&sv->h, out);
}

void rad_solver_free(rad_solver *sv)
{
	if (!sv)
		return;
	if (sv->ops && sv->impl)
		sv->ops->destroy(sv);
	rad_hier_destroy(&sv->h);
	rad_par_free(sv->par);
	free(sv);
}
