/*
 * job_cmd.c -- the job.* commands.
 *
 * Each handler validates its arguments, changes the job under its mutex
 * (never waiting for a worker: a running job is only flagged), tells
 * the core's observers of any state change it made, and replies once the change
 * is recorded in the store (cmd_persist_then_reply runs the row write on
 * the store thread).  pause and cancel of a running job reply when the
 * worker has actually stopped (a job waiter, answered from job_reply.c).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "engine_json.h"
#include "log.h"

/* A reply {"id", "ok": true, "job": id, "state": s}. */
static json_t *state_reply(cmd_req *r, srv_job *j, srv_job_state st)
{
	json_t *reply = rp_reply_ok(r->id);
	json_object_set_new(reply, "job", json_integer((json_int_t)j->id));
	json_object_set_new(reply, "state",
	                    json_string(srv_job_state_name(st)));
	return reply;
}

/* ----------------------------------------------------------------- create */

typedef struct create_task {
	srv_task t;
	srv_job *job; /* becomes the registry's ref */
	int failed;
	char msg[512];
} create_task;

static void create_run(srv *s, srv_task *t)
{
	create_task *c = (create_task *)t;
	c->failed = srv_job_store_add(s, c->job, c->msg, sizeof(c->msg)) != 0;
}

static void create_done(srv *s, srv_task *t)
{
	create_task *c = (create_task *)t;
	srv_job *j = c->job;
	json_t *reply;

	s->jobs_pending--;
	if (c->failed) {
		j->scene->njobs--;
		srv_job_unref(s, j);
		reply = rp_reply_error(t->id, RP_ERR_IO,
		                       "cannot store the job: %s", c->msg);
	} else {
		if (!j->name[0])
			snprintf(j->name, sizeof(j->name), "job-%llu",
			         (unsigned long long)j->id);
		srv_job_register(s, j);
		srv_info("job %llu '%s' created: scene %llu, solver %s, "
		         "%d threads",
		         (unsigned long long)j->id, j->name,
		         (unsigned long long)j->scene->id,
		         rad_solver_kind_name(j->opt.solver), j->opt.threads);
		reply = rp_reply_ok(t->id);
		json_object_set_new(reply, "job",
		                    json_integer((json_int_t)j->id));
		json_object_set_new(reply, "state", json_string("paused"));
		json_object_set_new(
		        reply, "solver",
		        json_string(rad_solver_kind_name(j->opt.solver)));
		json_object_set_new(reply, "options", srv_job_options_json(j));
	}
	cmd_task_reply(s, t, reply);
}

cmd_result cmd_job_create(cmd_req *r)
{
	srv *s = r->s;
	uint64_t scene_id = 0;
	const char *name = NULL, *solver = NULL;
	rad_options o;

	if (rp_arg_u64(r->hdr, "scene", 1, &scene_id, &r->err) != 0 ||
	    rp_arg_string(r->hdr, "name", 0, &name, &r->err) < 0 ||
	    rp_arg_string(r->hdr, "solver", 0, &solver, &r->err) < 0)
		return CMD_ERROR;
	if (name && strlen(name) > 255)
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"name\" is longer than 255 bytes");
	srv_scene *sc = cmd_find_scene(r, scene_id);
	if (!sc)
		return CMD_ERROR;
	if (srv_job_options_parse(s, json_object_get(r->hdr, "options"),
	                          solver ? solver : "hr", &o, &r->err) != 0)
		return CMD_ERROR;
	if (s->njobs + s->jobs_pending >= s->cfg.max_jobs)
		return cmd_req_fail(r, RP_ERR_LIMIT,
		                    "max_jobs (%d) jobs exist (all states "
		                    "count): delete one first",
		                    s->cfg.max_jobs);
	if (cmd_req_memory_full(r))
		return CMD_ERROR;
	create_task *c = calloc(1, sizeof(*c));
	srv_job *j = c ? srv_job_alloc(s, sc) : NULL;
	if (!j) {
		free(c);
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	}
	j->opt = o;
	snprintf(j->name, sizeof(j->name), "%s", name ? name : "");
	snprintf(j->owner, sizeof(j->owner), "%s", r->c->user);
	c->job = j;
	sc->njobs++;
	s->jobs_pending++;
	return cmd_req_defer(r, &s->store_pool, &c->t, create_run, create_done);
}

/* ------------------------------------------------------------- list, info */

cmd_result cmd_job_list(cmd_req *r)
{
	json_t *arr = json_array();
	for (srv_job *j = r->s->jobs; j; j = j->next) {
		if (!cmd_visible(r->c, j->owner))
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "id", json_integer((json_int_t)j->id));
		json_object_set_new(o, "name", json_string(j->name));
		json_object_set_new(o, "owner", json_string(j->owner));
		json_object_set_new(o, "scene",
		                    json_integer((json_int_t)j->scene->id));
		json_object_set_new(
		        o, "solver",
		        json_string(rad_solver_kind_name(j->opt.solver)));
		pthread_mutex_lock(&j->mu);
		json_object_set_new(o, "state",
		                    json_string(srv_job_state_name(j->state)));
		json_object_set_new(o, "iteration", json_integer(j->iteration));
		json_object_set_new(o, "residual",
		                    j->stats_json ? ej_real(j->residual)
		                                  : json_null());
		json_object_set_new(o, "links",
		                    json_integer((json_int_t)j->links));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(srv_job_memory_locked(j)));
		pthread_mutex_unlock(&j->mu);
		json_array_append_new(arr, o);
	}
	json_object_set_new(r->res, "jobs", arr);
	return CMD_REPLY;
}

cmd_result cmd_job_info(cmd_req *r)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	json_t *o = json_object();
	json_object_set_new(o, "id", json_integer((json_int_t)j->id));
	json_object_set_new(o, "name", json_string(j->name));
	json_object_set_new(o, "owner", json_string(j->owner));
	json_object_set_new(o, "scene", json_integer((json_int_t)j->scene->id));
	json_object_set_new(o, "solver",
	                    json_string(rad_solver_kind_name(j->opt.solver)));
	json_object_set_new(o, "options", srv_job_options_json(j));
	json_object_set_new(o, "created", json_real(j->created));
	pthread_mutex_lock(&j->mu);
	char *stats = j->stats_json ? strdup(j->stats_json) : NULL;
	json_object_set_new(o, "state",
	                    json_string(srv_job_state_name(j->state)));
	json_object_set_new(o, "iteration", json_integer(j->iteration));
	json_object_set_new(o, "target", srv_target_json(&j->target));
	json_object_set_new(o, "updated", json_real(j->updated));
	json_object_set_new(o, "replaying", json_boolean(j->replaying));
	json_object_set_new(o, "checkpoint_iteration",
	                    json_integer(j->ckpt_iter));
	json_object_set_new(o, "memory_bytes",
	                    json_integer(srv_job_memory_locked(j)));
	int pid = srv_job_solver_pid_locked(j);
	if (pid > 0)
		json_object_set_new(o, "solver_pid", json_integer(pid));
	if (j->has_pending_eps)
		json_object_set_new(o, "pending_eps",
		                    json_real(j->pending_eps));
	if (j->state == SRV_JOB_FAILED)
		json_object_set_new(o, "error", json_string(j->error));
	pthread_mutex_unlock(&j->mu);
	json_t *st = stats ? json_loads(stats, 0, NULL) : NULL;
	free(stats);
	json_object_set_new(o, "stats", st ? st : json_null());
	json_object_set_new(r->res, "job", o);
	return CMD_REPLY;
}

/* -------------------------------------------------------------------- run */

/* Parse job.run's target (at most one of three); 0 or -1. */
static int parse_target(cmd_req *r, job_target *t)
{
	uint64_t n = 0;
	int conv = 0;
	double sec = 0;
	int gi = rp_arg_u64(r->hdr, "iterations", 0, &n, &r->err);
	int gc = gi < 0 ? -1
	                : rp_arg_bool(r->hdr, "converge", 0, &conv, &r->err);
	int gs = gc < 0 ? -1
	                : rp_arg_double(r->hdr, "seconds", 0, &sec, &r->err);
	if (gi < 0 || gc < 0 || gs < 0)
		return -1;
	if ((gi == 0) + (gc == 0) + (gs == 0) > 1) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		             "give at most one of \"iterations\", \"converge\" "
		             "and \"seconds\"");
		return -1;
	}
	memset(t, 0, sizeof(*t));
	if (gi == 0) {
		if (n < 1 || n > 1000000000u) {
			cmd_req_fail(
			        r, RP_ERR_BAD_REQUEST,
			        "\"iterations\" must be 1 to 1e9 (got %llu)",
			        (unsigned long long)n);
			return -1;
		}
		t->mode = JOB_MODE_ITERATIONS;
		t->n = (uint32_t)n;
	} else if (gs == 0) {
		if (!(sec > 0)) {
			cmd_req_fail(r, RP_ERR_BAD_REQUEST,
			             "\"seconds\" must be > 0 (got %g)", sec);
			return -1;
		}
		t->mode = JOB_MODE_SECONDS;
		t->seconds = t->left_s = sec;
	} else {
		if (gc == 0 && !conv) {
			cmd_req_fail(r, RP_ERR_BAD_REQUEST,
			             "\"converge\" may only be true");
			return -1;
		}
		t->mode = JOB_MODE_CONVERGE;
	}
	return 0;
}

/*
 * Lock j->mu for a command that needs a live job; a done, failed or
 * cancelled one fails r ("job N is <already><state><why>") and leaves
 * the mutex unlocked.  Returns 1 when locked.
 */
static int lock_live(cmd_req *r, srv_job *j, const char *already,
                     const char *why)
{
	pthread_mutex_lock(&j->mu);
	srv_job_state st = j->state;
	if (!srv_job_terminal(st))
		return 1;
	pthread_mutex_unlock(&j->mu);
	cmd_req_fail(r, RP_ERR_STATE, "job %llu is %s%s%s",
	             (unsigned long long)j->id, already, srv_job_state_name(st),
	             why);
	return 0;
}

cmd_result cmd_job_run(cmd_req *r)
{
	int failed;
	job_target t;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed || parse_target(r, &t) != 0)
		return CMD_ERROR;
	if (!lock_live(r, j, "", ": nothing to run"))
		return CMD_ERROR;
	if (!j->on_worker && cmd_req_memory_full(r)) {
		pthread_mutex_unlock(&j->mu);
		return CMD_ERROR;
	}
	srv_job_state st = j->state;
	if (t.mode == JOB_MODE_ITERATIONS) {
		uint64_t until = (uint64_t)j->iteration + t.n;
		t.until = until > 0xFFFFFFFFu ? 0xFFFFFFFFu : (uint32_t)until;
	}
	j->target = t;
	j->deadline = t.mode == JOB_MODE_SECONDS && j->on_worker
	                      ? rad_seconds() + t.seconds
	                      : 0;
	j->pause_req = 0;
	if (j->on_worker)
		j->rerun_req = 1;
	if (st == SRV_JOB_PAUSED && !j->on_worker)
		srv_job_enqueue_locked(r->s, j);
	j->updated = srv_now_unix();
	st = j->state;
	pthread_mutex_unlock(&j->mu);
	srv_job_state_changed(r->s, j);
	return cmd_persist_then_reply(r, j, state_reply(r, j, st));
}

/* ------------------------------------------------ pause, resume, cancel */

/*
 * A job on a worker is asked to stop (*req set, the engine's cancel flag
 * raised); the reply waits until the worker has stopped it.  Called with
 * j->mu held; releases it.
 */
static cmd_result stop_worker(cmd_req *r, srv_job *j, int *req)
{
	*req = 1;
	srv_job_raise_cancel_locked(j);
	int rc = cmd_job_add_waiter(r->d, j, r->c->id, r->id);
	pthread_mutex_unlock(&j->mu);
	return rc == 0 ? CMD_DEFERRED
	               : cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
}

cmd_result cmd_job_pause(cmd_req *r)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	if (!lock_live(r, j, "", ""))
		return CMD_ERROR;
	srv_job_state st = j->state;
	if (j->on_worker) /* running: reply once it has stopped */
		return stop_worker(r, j, &j->pause_req);
	if (st == SRV_JOB_QUEUED) {
		j->state = SRV_JOB_PAUSED;
		j->state_seq++;
		j->updated = srv_now_unix();
	}
	pthread_mutex_unlock(&j->mu);
	srv_job_state_changed(r->s, j);
	return cmd_persist_then_reply(r, j, state_reply(r, j, SRV_JOB_PAUSED));
}

cmd_result cmd_job_resume(cmd_req *r)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	pthread_mutex_lock(&j->mu);
	const char *why = NULL;
	if (j->state != SRV_JOB_PAUSED || j->on_worker)
		why = "is not paused";
	else if (j->target.mode == JOB_MODE_NONE)
		why = "has never run: use job.run";
	else if (j->target.complete)
		why = "has reached its last target: use job.run for a new one";
	if (why) {
		srv_job_state st = j->state;
		pthread_mutex_unlock(&j->mu);
		return cmd_req_fail(r, RP_ERR_STATE, "job %llu (%s) %s",
		                    (unsigned long long)j->id,
		                    srv_job_state_name(st), why);
	}
	if (cmd_req_memory_full(r)) {
		pthread_mutex_unlock(&j->mu);
		return CMD_ERROR;
	}
	srv_job_enqueue_locked(r->s, j);
	pthread_mutex_unlock(&j->mu);
	srv_job_state_changed(r->s, j);
	return cmd_persist_then_reply(r, j, state_reply(r, j, SRV_JOB_QUEUED));
}

cmd_result cmd_job_cancel(cmd_req *r)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	if (!lock_live(r, j, "already ", ""))
		return CMD_ERROR;
	if (j->on_worker)
		return stop_worker(r, j, &j->cancel_req);
	j->state = SRV_JOB_CANCELLED;
	j->state_seq++;
	j->target.complete = 1;
	j->updated = srv_now_unix();
	pthread_mutex_unlock(&j->mu);
	srv_info("job %llu: cancelled", (unsigned long long)j->id);
	srv_job_state_changed(r->s, j);
	return cmd_persist_then_reply(r, j,
	                              state_reply(r, j, SRV_JOB_CANCELLED));
}

/* -------------------------------------------------------------------- set */

cmd_result cmd_job_set(cmd_req *r)
{
	int failed;
	double eps = 0;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed || rp_arg_double(r->hdr, "eps", 1, &eps, &r->err) != 0)
		return CMD_ERROR;
	if (!(eps > 0))
		return cmd_req_fail(r, RP_ERR_INVALID,
		                    "\"eps\" must be > 0 (got %g)", eps);
	if (!lock_live(r, j, "", ""))
		return CMD_ERROR;
	j->pending_eps = eps;
	j->has_pending_eps = 1;
	j->updated = srv_now_unix();
	pthread_mutex_unlock(&j->mu);
	json_t *reply = rp_reply_ok(r->id);
	json_object_set_new(reply, "job", json_integer((json_int_t)j->id));
	json_object_set_new(reply, "eps", json_real(eps));
	return cmd_persist_then_reply(r, j, reply);
}

/* ----------------------------------------------------------------- delete */

cmd_result cmd_job_delete(cmd_req *r)
{
	srv *s = r->s;
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	pthread_mutex_lock(&j->mu);
	srv_job_state st = j->state;
	int busy =
	        st == SRV_JOB_QUEUED || st == SRV_JOB_RUNNING || j->on_worker;
	if (!busy)
		j->deleted = 1;
	pthread_mutex_unlock(&j->mu);
	if (busy)
		return cmd_req_fail(r, RP_ERR_STATE,
		                    "job %llu is %s: pause or cancel it first",
		                    (unsigned long long)j->id,
		                    srv_job_state_name(st));
	srv_job_unregister(s, j);
	srv_info("job %llu deleted", (unsigned long long)j->id);
	return cmd_job_delete_then_reply(r, j);
}
