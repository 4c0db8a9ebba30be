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

#include "core.h"
#include "log.h"

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
	snprintf(row->owner, sizeof(row->owner), "%s", j->owner);
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

int srv_job_store_remove(srv *s, srv_job *j, char *msg, size_t msglen)
{
	pthread_mutex_lock(&s->store_mu);
	int rc = srv_store_job_delete(s->store, j->id, msg, msglen);
	pthread_mutex_unlock(&s->store_mu);
	return rc;
}
