/*
 * persist.c -- job rows and checkpoints in the store.
 *
 * A row is always built from the job's current in-memory state, under
 * the store lock and then the job's mutex, and written before the store
 * lock is released.  So whichever thread writes last writes the newest
 * state: two writers cannot reorder an older snapshot over a newer one.
 * A worker's final transition (state := paused/done/..., on_worker := 0)
 * is made inside the same store-locked section as its row, for the same
 * reason: a control command's row written afterwards sees the new state.
 *
 * Rows carry iterations = the iteration of the last durable checkpoint
 * (not the live count): a restart replays to exactly the solution it
 * can load.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "server.h"

static char *dup_or_empty(const char *s)
{
	return strdup(s ? s : "");
}

/* Fill a row from the job (caller holds j->mu). */
static void fill_row(const srv_job *j, srv_job_row *row, const srv_sol *sol,
                     int final_state)
{
	memset(row, 0, sizeof(*row));
	row->id = j->id;
	row->scene_id = j->scene->id;
	snprintf(row->name, sizeof(row->name), "%s", j->name);
	row->options_json = srv_job_options_text(j);
	row->target_json = srv_job_target_text(j);
	row->eps_log_json = srv_job_eps_log_text(j);
	row->stats_json = dup_or_empty(j->stats_json);
	row->state = final_state >= 0 ? (srv_job_state)final_state : j->state;
	row->iterations = sol ? sol->iteration : j->ckpt_iter;
	row->has_result = sol ? 1 : j->has_result;
	snprintf(row->error, sizeof(row->error), "%s", j->error);
	row->created = j->created;
	row->updated = j->updated;
}

int srv_job_persist(srv *s, srv_job *j, srv_sol *sol, int final_state,
                    char *msg, size_t msglen)
{
	unsigned char *bytes = NULL;
	size_t len = 0;
	rad_error err = {0};
	srv_job_row row;
	int rc = 0;

	msg[0] = '\0';
	if (sol && rad_solution_save(sol->sol, &bytes, &len, &err) != RAD_OK) {
		srv_error("job %llu: cannot serialise the solution: %s",
		          (unsigned long long)j->id, err.msg);
		sol = NULL;
	}
	pthread_mutex_lock(&s->store_mu);
	pthread_mutex_lock(&j->mu);
	int deleted = j->deleted, requeue = 0;
	if (final_state == SRV_JOB_PAUSED && j->rerun_req) {
		/* job.run arrived while the worker was stopping. */
		final_state = SRV_JOB_QUEUED;
		requeue = 1;
	}
	if (!deleted)
		fill_row(j, &row, sol, final_state);
	pthread_mutex_unlock(&j->mu);
	if (!deleted) {
		if (!row.options_json || !row.target_json ||
		    !row.eps_log_json || !row.stats_json) {
			snprintf(msg, msglen, "out of memory building the row");
			rc = -1;
		} else if (sol) {
			rc = srv_store_job_checkpoint(s->store, &row, bytes,
			                              len, msg, msglen);
		} else {
			rc = srv_store_job_update(s->store, &row, msg, msglen);
		}
		srv_job_row_clear(&row);
	}
	pthread_mutex_lock(&j->mu);
	if (rc == 0 && sol && !deleted) {
		j->ckpt_iter = sol->iteration;
		j->has_result = 1;
	}
	if (final_state >= 0) {
		if (j->state != (srv_job_state)final_state) {
			j->state = (srv_job_state)final_state;
			j->state_seq++;
		}
		j->updated = srv_now_unix();
		j->on_worker = 0;
		if (requeue) {
			j->rerun_req = 0;
			srv_job_enqueue_locked(s, j);
		}
	}
	pthread_mutex_unlock(&j->mu);
	pthread_mutex_unlock(&s->store_mu);
	free(bytes);
	return rc;
}

/* ------------------------------------------- control commands' row writes */

typedef struct persist_task {
	srv_task t;
	srv_job *job; /* ref */
	json_t *reply;
	rad_solver *drop; /* a cancelled job's solver, freed here */
} persist_task;

static void persist_run(srv *s, srv_task *t)
{
	persist_task *p = (persist_task *)t;
	char msg[512];
	rad_solver_free(p->drop);
	p->drop = NULL;
	if (srv_job_persist(s, p->job, NULL, -1, msg, sizeof(msg)) != 0) {
		srv_error("job %llu: cannot record the change: %s",
		          (unsigned long long)p->job->id, msg);
		json_decref(p->reply);
		p->reply =
		        rp_reply_error(t->id, RP_ERR_IO,
		                       "the change was made but could not be "
		                       "recorded: %s",
		                       msg);
	}
}

static void persist_done(srv *s, srv_task *t)
{
	persist_task *p = (persist_task *)t;
	srv_reply_deferred(s, t->conn_id, p->reply);
	srv_job_unref(s, p->job);
	json_decref(t->id);
	free(p);
}

cmd_result srv_persist_then_reply(srv_req *r, srv_job *j, json_t *reply)
{
	srv *s = r->s;
	persist_task *p = calloc(1, sizeof(*p));
	if (!p || !reply) {
		free(p);
		json_decref(reply);
		return srv_req_fail(r, RP_ERR_NOMEM,
		                    "out of memory (the change stands in "
		                    "memory but is not recorded yet)");
	}
	srv_job_ref(j);
	p->job = j;
	p->reply = reply;
	pthread_mutex_lock(&j->mu);
	if (srv_job_terminal(j->state) && !j->on_worker) {
		p->drop = j->solver;
		j->solver = NULL;
		memset(j->solver_mem, 0, sizeof(j->solver_mem));
	}
	pthread_mutex_unlock(&j->mu);
	p->t.run = persist_run;
	p->t.done = persist_done;
	p->t.conn_id = r->c->id;
	p->t.id = json_incref(r->id);
	srv_pool_submit(&s->store_pool, &p->t);
	return CMD_DEFERRED;
}

int srv_job_store_add(srv *s, srv_job *j, char *msg, size_t msglen)
{
	srv_job_row row;
	int rc;

	pthread_mutex_lock(&s->store_mu);
	pthread_mutex_lock(&j->mu);
	fill_row(j, &row, NULL, -1);
	pthread_mutex_unlock(&j->mu);
	if (!row.options_json || !row.target_json || !row.eps_log_json ||
	    !row.stats_json) {
		snprintf(msg, msglen, "out of memory building the row");
		rc = -1;
	} else {
		rc = srv_store_job_add(s->store, &row, msg, msglen);
	}
	pthread_mutex_unlock(&s->store_mu);
	if (rc == 0)
		j->id = row.id; /* not yet visible to other threads */
	srv_job_row_clear(&row);
	return rc;
}

typedef struct delete_task {
	srv_task t;
	srv_job *job; /* the registry's ref, released here */
	int failed;
	char msg[512];
} delete_task;

static void delete_run(srv *s, srv_task *t)
{
	delete_task *d = (delete_task *)t;
	pthread_mutex_lock(&s->store_mu);
	d->failed = srv_store_job_delete(s->store, d->job->id, d->msg,
	                                 sizeof(d->msg)) != 0;
	pthread_mutex_unlock(&s->store_mu);
	/* Frees the solver here, off the I/O thread, unless a query still
	 * holds the solution (then only that is kept until it ends). */
	srv_job_unref(s, d->job);
	d->job = NULL;
}

static void delete_done(srv *s, srv_task *t)
{
	delete_task *d = (delete_task *)t;
	json_t *reply = d->failed ? rp_reply_error(t->id, RP_ERR_IO,
	                                           "the job was freed but its "
	                                           "row could not be removed: "
	                                           "%s",
	                                           d->msg)
	                          : rp_reply_ok(t->id);
	srv_reply_deferred(s, t->conn_id, reply);
	json_decref(t->id);
	free(d);
}

cmd_result srv_job_store_delete(srv_req *r, srv_job *j)
{
	delete_task *d = calloc(1, sizeof(*d));
	if (!d)
		return srv_req_fail(r, RP_ERR_NOMEM, "out of memory");
	d->job = j;
	d->t.run = delete_run;
	d->t.done = delete_done;
	d->t.conn_id = r->c->id;
	d->t.id = json_incref(r->id);
	srv_pool_submit(&r->s->store_pool, &d->t);
	return CMD_DEFERRED;
}
