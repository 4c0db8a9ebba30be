/*
 * solver.c -- what all solvers share: options, creation, stepping, timing,
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

void rad_options_default(rad_options *o)
{
	memset(o, 0, sizeof(*o));
	o->solver = RAD_SOLVER_HR;
	o->oracle = RAD_ORACLE_BFA;
	o->min_edge_rel = 5e-3;
	o->mesh_edge_rel = 0.05;
	o->clustering = 1;
	o->threads = 0;
	o->rcv_samples = 4;
	o->vis_samples = 4;
	rad_options_accuracy(o, RAD_ACCURACY_DEFAULT, NULL);
}

/*
 * What one accuracy R asks of each knob.  The query's gather gets half of
 * the budget; the solution the rest: the convergence tolerance a
 * twentieth (the iteration error is cheap to remove), the link threshold
 * eps (a flux fraction: a link's error is second order in its size) and,
 * for looser R only, the receiver variation in proportion.  At the
 * default R = 0.02 these are the long-standing defaults (eps 1e-4,
 * variation 0.5, convergence 1e-3, query tolerance 1e-2).  A variation
 * finer than 0.5 makes points a few centimetres from a corner (floor and
 * two walls) brighter, not closer (the office's floor corners: +3.4 % at
 * 0.5, +12.7 % at 0.25, against luxrad-reference; README, Limitations),
 * and bought little elsewhere in the validation study (Cornell box,
 * obstructed source, bright hall, closed boxes and room: within 0.4 % at
 * --accuracy 0.01), so a tighter R leaves it at 0.5 until leaves near
 * corners are right.
 */
rad_status rad_options_accuracy(rad_options *o, double accuracy, rad_error *err)
{
	if (!(accuracy >= RAD_ACCURACY_MIN && accuracy <= RAD_ACCURACY_MAX))
		return rad_fail(err, RAD_ERR_INVALID,
		                "accuracy must be in [%g, %g] (got %g)",
		                RAD_ACCURACY_MIN, RAD_ACCURACY_MAX, accuracy);
	double r = accuracy / RAD_ACCURACY_DEFAULT;
	o->accuracy = accuracy;
	o->query_tol = accuracy / 2;
	o->converge_tol = accuracy / 20;
	o->eps = 1e-4 * r * r;
	o->variation = 0.5 * fmax(r, 1.0);
	return RAD_OK;
}

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

double rad_error_estimate(double r_prev, double r_now)
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

void rad_solver_set_residual(rad_solver *sv, double r)
{
	sv->stats.residual = r;
	sv->stats.error_estimate = rad_error_estimate(sv->prev_residual, r);
	sv->prev_residual = r;
}

static rad_status check_options(const rad_options *o, rad_error *err)
{
	if ((unsigned)o->solver >= RAD_SOLVER_NKINDS)
		return rad_fail(err, RAD_ERR_INVALID, "unknown solver %d",
		                (int)o->solver);
	if ((unsigned)o->oracle > RAD_ORACLE_BF)
		return rad_fail(err, RAD_ERR_INVALID, "unknown oracle %d",
		                (int)o->oracle);
	if ((unsigned)o->store > RAD_STORE_MINIMAL)
		return rad_fail(err, RAD_ERR_INVALID,
		                "unknown link creation criterion %d",
		                (int)o->store);
	if (!(o->eps > 0) || !isfinite(o->eps))
		return rad_fail(err, RAD_ERR_INVALID,
		                "eps must be a finite number > 0 (got %g)",
		                o->eps);
	if (!(o->variation > 0) || !isfinite(o->variation))
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "variation must be a finite number > 0 (got %g)",
		        o->variation);
	if (!(o->query_tol > 0 && o->query_tol < 1))
		return rad_fail(err, RAD_ERR_INVALID,
		                "query tolerance must be in (0, 1) (got %g)",
		                o->query_tol);
	if (!(o->converge_tol > 0) || !isfinite(o->converge_tol))
		return rad_fail(err, RAD_ERR_INVALID,
		                "convergence tolerance must be a finite "
		                "number > 0 (got %g)",
		                o->converge_tol);
	if (!(o->min_edge_rel > 0) || !(o->min_edge_rel < 1))
		return rad_fail(err, RAD_ERR_INVALID,
		                "min_edge_rel must be in (0, 1) (got %g)",
		                o->min_edge_rel);
	if (!(o->mesh_edge_rel > 0) || !(o->mesh_edge_rel <= 1))
		return rad_fail(err, RAD_ERR_INVALID,
		                "mesh_edge_rel must be in (0, 1] (got %g)",
		                o->mesh_edge_rel);
	if (o->threads < 0 || o->threads > 256)
		return rad_fail(err, RAD_ERR_INVALID,
		                "threads must be 0 (all cores) to 256 (got %d)",
		                o->threads);
	if (o->rcv_samples < 1 || o->rcv_samples > 16 || o->vis_samples < 1 ||
	    o->vis_samples > 16)
		return rad_fail(err, RAD_ERR_INVALID,
		                "samples must be 1..16 (got rcv %d, vis %d)",
		                o->rcv_samples, o->vis_samples);
	return RAD_OK;
}

rad_status rad_solver_new(const rad_scene *scene, const rad_options *opt,
                          rad_solver **out, rad_error *err)
{
	*out = NULL;
	if (!scene || !scene->committed)
		return rad_fail(err, RAD_ERR_STATE, "scene is not committed");
	rad_status st = check_options(opt, err);
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
	double flux = RAD_LUMA_R * scene->total_flux[0] +
	              RAD_LUMA_G * scene->total_flux[1] +
	              RAD_LUMA_B * scene->total_flux[2];
	sv->flux_scale = flux > 0 ? flux : 1.0;
	sv->tol = opt->converge_tol;
	st = rad_par_new(opt->threads, &sv->par, err);
	if (!st)
		st = rad_hier_init(&sv->h, scene, &sv->mem,
		                   opt->min_edge_rel * scene->diag, err);
	if (!st)
		st = sv->ops->init(sv, err);
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
	memset(sv->stats.energy_hist, 0, sizeof(sv->stats.energy_hist));
	sv->stats.rays = 0;
	rad_status st = sv->ops->step(sv, err);
	if (st)
		return st;
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
	rad_mem_report_clear(&out->mem);
	rad_mem_report_add(&sv->mem, &out->mem);
	rad_mem_report_add(&sv->scene->mem, &out->mem);
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
