/*
 * recover.c -- startup from the store: scenes parsed again from their
 * bytes, jobs rebuilt from their rows and checkpoints.
 *
 * Runs before any thread starts and before luxradd.addr is written, so a
 * client that sees the address file sees every scene and job.  What
 * comes back (service.c, DESIGN, checkpoint rule):
 *   - done / failed / cancelled: state, stats and the checkpointed
 *     solution (rad_solution_load), so queries and export work at once.
 *     A done job whose checkpoint this engine refuses (a solution format
 *     or scene geometry of an earlier version) is re-queued: the worker
 *     replays it to its iteration, which the results being deterministic
 *     makes the same solution, and it ends done again, checkpointed;
 *   - queued / running: re-queued; the worker replays the solver to the
 *     checkpointed iteration (queries meanwhile read the checkpoint's
 *     solution) and goes on toward the stored target;
 *   - paused: paused, with its solution; the solver is rebuilt and
 *     replayed on resume.
 * A row that cannot be used (unknown scene, unreadable options) is
 * logged and left in the store untouched: nothing is deleted on our
 * own initiative.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core.h"
#include "log.h"

typedef struct row_list {
	srv_scene_row *scenes;
	size_t nscenes;
	srv_job_row *jobs;
	size_t njobs;
	int oom;
} row_list;

static void collect_scene(void *ud, const srv_scene_row *r)
{
	row_list *l = ud;
	srv_scene_row *n = realloc(l->scenes, (l->nscenes + 1) * sizeof(*n));
	if (!n) {
		l->oom = 1;
		return;
	}
	l->scenes = n;
	l->scenes[l->nscenes++] = *r;
}

static char *dup_str(const char *s)
{
	return strdup(s ? s : "");
}

static void collect_job(void *ud, const srv_job_row *r)
{
	row_list *l = ud;
	srv_job_row *n = realloc(l->jobs, (l->njobs + 1) * sizeof(*n));
	if (!n) {
		l->oom = 1;
		return;
	}
	l->jobs = n;
	srv_job_row *c = &l->jobs[l->njobs++];
	*c = *r;
	c->options_json = dup_str(r->options_json);
	c->target_json = dup_str(r->target_json);
	c->eps_log_json = dup_str(r->eps_log_json);
	c->stats_json = dup_str(r->stats_json);
}

static void recover_scene(srv *s, const srv_scene_row *r)
{
	unsigned char *bytes = NULL;
	size_t len = 0;
	char msg[512];
	rad_error err = {0};

	if (srv_store_scene_read(s->store, r->id, &bytes, &len, msg,
	                         sizeof(msg)) != 0) {
		srv_error("scene %llu: cannot read its bytes: %s",
		          (unsigned long long)r->id, msg);
		return;
	}
	srv_scene *sc =
	        srv_scene_load(r->id, r->name, r->created, bytes, len, &err);
	free(bytes);
	if (!sc) {
		srv_error("scene %llu: cannot load it again: %s",
		          (unsigned long long)r->id, err.msg);
		return;
	}
	snprintf(sc->owner, sizeof(sc->owner), "%s", r->owner);
	srv_scene_register(s, sc);
	srv_info("scene %llu '%s' restored (%u polygons)",
	         (unsigned long long)sc->id, sc->name, sc->counts.polygons);
}

/* ------------------------------------------------------------------- jobs */

static void parse_target(srv_job *j, const char *text)
{
	json_t *t = text && text[0] ? json_loads(text, 0, NULL) : NULL;
	const char *mode = json_string_value(json_object_get(t, "mode"));
	job_target *g = &j->target;
	memset(g, 0, sizeof(*g));
	if (mode && strcmp(mode, "iterations") == 0)
		g->mode = JOB_MODE_ITERATIONS;
	else if (mode && strcmp(mode, "converge") == 0)
		g->mode = JOB_MODE_CONVERGE;
	else if (mode && strcmp(mode, "seconds") == 0)
		g->mode = JOB_MODE_SECONDS;
	g->n = (uint32_t)json_integer_value(json_object_get(t, "n"));
	g->until = (uint32_t)json_integer_value(
	        json_object_get(t, "until_iteration"));
	g->seconds = json_number_value(json_object_get(t, "seconds"));
	g->left_s = json_number_value(json_object_get(t, "left_s"));
	g->complete = json_is_true(json_object_get(t, "complete"));
	json_t *pe = json_object_get(t, "pending_eps");
	if (json_is_number(pe) && json_number_value(pe) > 0) {
		j->has_pending_eps = 1;
		j->pending_eps = json_number_value(pe);
	}
	json_decref(t);
}

static int parse_eps_log(srv_job *j, const char *text)
{
	json_t *a = text && text[0] ? json_loads(text, 0, NULL) : NULL;
	size_t i, n = json_array_size(a);
	if (n) {
		j->eps_log = calloc(n, sizeof(*j->eps_log));
		if (!j->eps_log) {
			json_decref(a);
			return -1;
		}
		j->eps_cap = n;
	}
	for (i = 0; i < n; i++) {
		json_t *e = json_array_get(a, i);
		json_t *it = json_array_get(e, 0), *eps = json_array_get(e, 1);
		if (!json_is_integer(it) || !json_is_number(eps) ||
		    !(json_number_value(eps) > 0))
			continue;
		j->eps_log[j->neps++] =
		        (job_eps){.iteration = (uint32_t)json_integer_value(it),
		                  .eps = json_number_value(eps)};
	}
	json_decref(a);
	return 0;
}

/* Stats only if they describe the checkpointed iteration. */
static void restore_stats(srv_job *j, const char *text)
{
	json_t *st = text && text[0] ? json_loads(text, 0, NULL) : NULL;
	json_t *it = json_object_get(st, "iteration");
	if (json_is_integer(it) &&
	    (uint32_t)json_integer_value(it) == j->iteration) {
		j->stats_json = strdup(text);
		j->residual =
		        json_number_value(json_object_get(st, "residual"));
		j->links = (uint64_t)json_integer_value(json_object_get(
		        json_object_get(st, "links"), "stored"));
		j->converged = json_is_true(json_object_get(st, "converged"));
	}
	json_decref(st);
}

/* The error estimate of the restored statistics, 0 if none. */
static double stats_error_estimate(const srv_job *j)
{
	json_t *st = j->stats_json ? json_loads(j->stats_json, 0, NULL) : NULL;
	double e = json_number_value(json_object_get(st, "error_estimate"));
	json_decref(st);
	return e;
}

static void restore_solution(srv *s, srv_job *j)
{
	unsigned char *bytes = NULL;
	size_t len = 0;
	char msg[512];
	rad_error err = {0};
	rad_solution *sol = NULL;

	if (srv_store_job_result_read(s->store, j->id, &bytes, &len, msg,
	                              sizeof(msg)) != 0) {
		srv_warn("job %llu: cannot read its checkpoint: %s",
		         (unsigned long long)j->id, msg);
		return;
	}
	if (rad_solution_load(j->scene->scene, bytes, len, &sol, &err) !=
	    RAD_OK) {
		srv_warn("job %llu: checkpoint refused: %s",
		         (unsigned long long)j->id, err.msg);
	} else {
		j->sol = srv_sol_new(s, sol, j->scene, j->opt.query_tol,
		                     stats_error_estimate(j));
	}
	free(bytes);
}

static void recover_job(srv *s, const srv_job_row *r)
{
	rp_error e = {0};
	srv_scene *sc = srv_scene_find(s, r->scene_id);
	json_t *o = json_loads(r->options_json, 0, NULL);
	const char *solver = json_string_value(json_object_get(o, "solver"));
	srv_job *j = sc ? srv_job_alloc(s, sc) : NULL;

	if (!sc || !j ||
	    srv_job_options_parse(s, json_object_get(o, "options"), solver,
	                          &j->opt, &e) != 0 ||
	    parse_eps_log(j, r->eps_log_json) != 0) {
		srv_error("job %llu: not restored: %s",
		          (unsigned long long)r->id,
		          !sc  ? "its scene is missing"
		          : !j ? "out of memory"
		               : e.msg);
		srv_job_unref(s, j);
		json_decref(o);
		return;
	}
	json_decref(o);
	j->id = r->id;
	snprintf(j->name, sizeof(j->name), "%s", r->name);
	snprintf(j->owner, sizeof(j->owner), "%s", r->owner);
	if (!j->name[0])
		snprintf(j->name, sizeof(j->name), "job-%llu",
		         (unsigned long long)r->id);
	snprintf(j->error, sizeof(j->error), "%s", r->error);
	j->created = r->created;
	j->updated = r->updated;
	j->iteration = j->ckpt_iter = r->iterations;
	j->has_result = r->has_result;
	parse_target(j, r->target_json);
	restore_stats(j, r->stats_json);
	if (r->has_result)
		restore_solution(s, j);
	j->state = r->state < SRV_JOB_NSTATES ? r->state : SRV_JOB_PAUSED;
	if (j->state == SRV_JOB_DONE && r->has_result && !j->sol) {
		srv_warn("job %llu: replaying its %u iterations to make its "
		         "solution again",
		         (unsigned long long)j->id, j->iteration);
		j->state = SRV_JOB_QUEUED;
	}
	j->state_seq = 1;
	sc->njobs++;
	srv_job_register(s, j);
	if (j->state == SRV_JOB_QUEUED || j->state == SRV_JOB_RUNNING) {
		j->state = SRV_JOB_PAUSED; /* so that enqueue counts a change */
		pthread_mutex_lock(&j->mu);
		srv_job_enqueue_locked(s, j);
		pthread_mutex_unlock(&j->mu);
	}
	srv_info("job %llu '%s' restored: %s at iteration %u%s",
	         (unsigned long long)j->id, j->name,
	         srv_job_state_name(j->state), j->iteration,
	         j->sol ? ", solution loaded" : "");
}

int srv_recover(srv *s, char *msg, size_t msglen)
{
	row_list l = {0};
	int rc = 0;

	if (srv_store_scene_list(s->store, collect_scene, &l, msg, msglen) !=
	            0 ||
	    srv_store_job_list(s->store, collect_job, &l, msg, msglen) != 0)
		rc = -1;
	else if (l.oom) {
		snprintf(msg, msglen, "out of memory reading the store");
		rc = -1;
	}
	for (size_t i = 0; rc == 0 && i < l.nscenes; i++)
		recover_scene(s, &l.scenes[i]);
	for (size_t i = 0; rc == 0 && i < l.njobs; i++)
		recover_job(s, &l.jobs[i]);
	if (rc == 0)
		rc = srv_observers_recovered(s, msg, msglen);
	for (size_t i = 0; i < l.njobs; i++)
		srv_job_row_clear(&l.jobs[i]);
	free(l.scenes);
	free(l.jobs);
	return rc;
}
