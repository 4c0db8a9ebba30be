/*
 * jobjson.c -- a job's options, target and eps log as JSON:
 * what job.create accepts, what job.info and the iteration events show
 * and what the store keeps.
 *
 * Options and statistics are rad.h's tables, read and written by
 * engine_json.c, so an option cannot be accepted without being reported
 * back, and the statistics have one shape everywhere.  The stored form
 * of a job's options is {"solver": name, "options": {every effective
 * value}} with threads resolved to a number: a replay after a restart
 * must use the same thread count to be deterministic.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "engine_json.h"

int srv_job_options_parse(srv *s, json_t *opts, const char *solver,
                          rad_options *o, rp_error *err)
{
	rad_options ov;
	ej_status st;

	rad_options_default(&ov);
	rad_options_accuracy(&ov, s->accuracy, NULL);
	ov.memory_budget = s->job_budget_mib;
	if (solver && rad_solver_kind_parse(solver, &ov.solver) != RAD_OK) {
		err->code = RP_ERR_INVALID;
		snprintf(err->msg, sizeof(err->msg),
		         "unknown solver \"%.64s\" (hr, rmb, matrix or "
		         "progressive)",
		         solver);
		return -1;
	}
	st = ej_options_set(&ov, opts, err->msg, sizeof(err->msg));
	if (st != EJ_OK) {
		err->code = st == EJ_TYPE ? RP_ERR_BAD_REQUEST : RP_ERR_INVALID;
		return -1;
	}
	if (ov.threads == 0)
		ov.threads = s->solver_threads;
	*o = ov;
	return 0;
}

json_t *srv_job_options_json(const srv_job *j)
{
	return ej_options(&j->opt);
}

char *srv_job_options_text(const srv_job *j)
{
	json_t *o = json_object();
	json_object_set_new(o, "solver",
	                    json_string(rad_solver_kind_name(j->opt.solver)));
	json_object_set_new(o, "options", srv_job_options_json(j));
	char *t = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(o);
	return t;
}

/* ---------------------------------------------------------------- target */

json_t *srv_target_json(const job_target *t)
{
	json_t *o = json_object();
	switch (t->mode) {
	case JOB_MODE_NONE:
		json_object_set_new(o, "mode", json_string("none"));
		break;
	case JOB_MODE_ITERATIONS:
		json_object_set_new(o, "mode", json_string("iterations"));
		json_object_set_new(o, "n", json_integer(t->n));
		json_object_set_new(o, "until_iteration",
		                    json_integer(t->until));
		break;
	case JOB_MODE_CONVERGE:
		json_object_set_new(o, "mode", json_string("converge"));
		break;
	case JOB_MODE_SECONDS:
		json_object_set_new(o, "mode", json_string("seconds"));
		json_object_set_new(o, "seconds", ej_real(t->seconds));
		json_object_set_new(o, "left_s", ej_real(t->left_s));
		break;
	}
	json_object_set_new(o, "complete", json_boolean(t->complete));
	return o;
}

char *srv_job_target_text(const srv_job *j)
{
	json_t *o = srv_target_json(&j->target);
	if (j->has_pending_eps)
		json_object_set_new(o, "pending_eps",
		                    json_real(j->pending_eps));
	char *t = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(o);
	return t;
}

char *srv_job_eps_log_text(const srv_job *j)
{
	json_t *a = json_array();
	for (size_t i = 0; i < j->neps; i++)
		json_array_append_new(
		        a,
		        json_pack("[I f]", (json_int_t)j->eps_log[i].iteration,
		                  j->eps_log[i].eps));
	char *t = json_dumps(a, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(a);
	return t;
}
