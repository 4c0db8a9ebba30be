/*
 * store_jobs.c -- job rows (jobs table), their solution checkpoints
 * (results/<id>-<gen>.sol) and the sensors added to them (sensors table,
 * deleted with their job by ON DELETE CASCADE).
 *
 * A checkpoint never overwrites the file its row names: it writes
 * generation gen + 1, commits the row that names it, and only then
 * unlinks generation gen (store_int.h's invariant).
 */
#include "log.h"
#include "store_int.h"
#include "textutil.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *const state_names[] = {"queued", "running", "paused",
                                          "done",   "failed",  "cancelled"};

const char *srv_job_state_name(srv_job_state s)
{
	return (unsigned)s < SRV_JOB_NSTATES ? state_names[s] : "unknown";
}

void srv_job_row_clear(srv_job_row *r)
{
	free(r->options_json);
	free(r->target_json);
	free(r->eps_log_json);
	free(r->stats_json);
	r->options_json = r->target_json = r->eps_log_json = r->stats_json =
	        NULL;
}

static int check_state(const srv_job_row *row, char *msg, size_t msglen)
{
	if ((unsigned)row->state >= SRV_JOB_NSTATES)
		return srv_fail(msg, msglen, "job state %d is not a state",
		                (int)row->state);
	return 0;
}

/*
 * Bind what a job's progress changes -- target, eps log, stats, state,
 * iterations, error -- as parameters first..first + 5: the order in
 * which JOB_INSERT, JOB_UPDATE and JOB_CHECKPOINT list those columns.
 */
static void bind_progress(sqlite3_stmt *s, int first, const srv_job_row *row)
{
	store_bind_text(s, first, row->target_json);
	store_bind_text(s, first + 1, row->eps_log_json);
	store_bind_text(s, first + 2, row->stats_json);
	sqlite3_bind_int(s, first + 3, (int)row->state);
	sqlite3_bind_int64(s, first + 4, row->iterations);
	store_bind_text(s, first + 5, row->error);
}

int srv_store_job_add(srv_store *st, srv_job_row *row, char *msg, size_t msglen)
{
	if (store_check_name("job", row->name, msg, msglen) < 0)
		return -1;
	if (check_state(row, msg, msglen) < 0)
		return -1;
	double t = srv_now_unix();
	if (row->created <= 0)
		row->created = t;
	if (row->updated <= 0)
		row->updated = row->created;
	sqlite3_stmt *s = store_stmt(st, ST_JOB_INSERT);
	sqlite3_bind_int64(s, 1, store_sql_id(row->scene_id));
	store_bind_text(s, 2, row->name);
	store_bind_text(s, 3, row->options_json);
	bind_progress(s, 4, row);
	sqlite3_bind_double(s, 10, row->created);
	sqlite3_bind_double(s, 11, row->updated);
	store_bind_text(s, 12, row->owner);
	int rc = sqlite3_step(s);
	sqlite3_reset(s);
	if ((rc & 0xff) == SQLITE_CONSTRAINT)
		return srv_fail(msg, msglen, "job: scene %llu not found",
		                (unsigned long long)row->scene_id);
	if (rc != SQLITE_DONE)
		return store_sql_fail(st, "job insert", msg, msglen);
	row->id = (uint64_t)sqlite3_last_insert_rowid(st->db);
	row->has_result = 0;
	return 0;
}

/* Bind the columns JOB_UPDATE and JOB_CHECKPOINT share (?1..?8). */
static void bind_job_update(sqlite3_stmt *s, const srv_job_row *row)
{
	sqlite3_bind_int64(s, 1, store_sql_id(row->id));
	bind_progress(s, 2, row);
	sqlite3_bind_double(s, 8,
	                    row->updated > 0 ? row->updated : srv_now_unix());
}

int srv_store_job_update(srv_store *st, const srv_job_row *row, char *msg,
                         size_t msglen)
{
	if (check_state(row, msg, msglen) < 0)
		return -1;
	sqlite3_stmt *s = store_stmt(st, ST_JOB_UPDATE);
	bind_job_update(s, row);
	if (store_run(st, s, "job update", msg, msglen) < 0)
		return -1;
	if (sqlite3_changes(st->db) == 0)
		return srv_fail(msg, msglen, "job %llu not found",
		                (unsigned long long)row->id);
	return 0;
}

/* A job's checkpoint: 1 found, 0 not found (msg filled), -1 error. */
static int job_result(srv_store *st, uint64_t id, int *has, int64_t *gen,
                      uint64_t *bytes, char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_JOB_RESULT);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW) {
		*has = sqlite3_column_int(s, 0);
		*gen = sqlite3_column_int64(s, 1);
		*bytes = (uint64_t)sqlite3_column_int64(s, 2);
	}
	sqlite3_reset(s);
	if (rc == SQLITE_DONE)
		return srv_fail(msg, msglen, "job %llu not found",
		                (unsigned long long)id),
		       0;
	return rc == SQLITE_ROW ? 1
	                        : store_sql_fail(st, "job read", msg, msglen);
}

int srv_store_job_checkpoint(srv_store *st, const srv_job_row *row,
                             const void *sol, size_t len, char *msg,
                             size_t msglen)
{
	char dir[PATHLEN], tmp[PATHLEN], path[PATHLEN], old[PATHLEN];
	int has;
	int64_t gen;
	uint64_t oldlen;
	if (check_state(row, msg, msglen) < 0)
		return -1;
	if (job_result(st, row->id, &has, &gen, &oldlen, msg, msglen) <= 0)
		return -1;
	snprintf(dir, sizeof(dir), "%s/results", st->dir);
	store_result_path(st, row->id, gen + 1, path);
	if (store_tmp_write(dir, sol, len, tmp, msg, msglen) < 0 ||
	    store_tmp_commit(tmp, path, dir, msg, msglen) < 0)
		return -1;
	sqlite3_stmt *s = store_stmt(st, ST_JOB_CHECKPOINT);
	bind_job_update(s, row);
	sqlite3_bind_int64(s, 9, gen + 1);
	sqlite3_bind_int64(s, 10, (int64_t)len);
	if (store_run(st, s, "job checkpoint", msg, msglen) < 0) {
		unlink(path); /* the row still names the previous file */
		return -1;
	}
	/* The row now names generation gen + 1; the old file is garbage
	 * (if this unlink is lost, open() removes it). */
	store_result_path(st, row->id, gen, old);
	if (has)
		unlink(old);
	return 0;
}

/* The job's checkpoint file: *has, its size and path; -1 with msg when
 * the row cannot be read or is missing. */
static int result_file(srv_store *st, uint64_t id, int *has, uint64_t *size,
                       char *path, char *msg, size_t msglen)
{
	int64_t gen;
	if (job_result(st, id, has, &gen, size, msg, msglen) <= 0)
		return -1;
	store_result_path(st, id, gen, path);
	return 0;
}

int srv_store_job_result_read(srv_store *st, uint64_t id, unsigned char **bytes,
                              size_t *len, char *msg, size_t msglen)
{
	char path[PATHLEN];
	int has;
	uint64_t size;
	if (result_file(st, id, &has, &size, path, msg, msglen) < 0)
		return -1;
	if (!has)
		return srv_fail(msg, msglen, "job %llu has no checkpoint",
		                (unsigned long long)id);
	return store_file_read(path, size, bytes, len, msg, msglen);
}

int srv_store_job_delete(srv_store *st, uint64_t id, char *msg, size_t msglen)
{
	char path[PATHLEN];
	int has;
	uint64_t size;
	if (result_file(st, id, &has, &size, path, msg, msglen) < 0)
		return -1;
	sqlite3_stmt *s = store_stmt(st, ST_JOB_DELETE);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	if (store_run(st, s, "job delete", msg, msglen) < 0)
		return -1;
	if (has && unlink(path) < 0 && errno != ENOENT)
		return srv_fail(msg, msglen, "%s: cannot remove: %s", path,
		                strerror(errno));
	return 0;
}

/* Fill r from a JOB_LIST row; -1 when out of memory. */
static int job_from_row(sqlite3_stmt *s, srv_job_row *r)
{
	memset(r, 0, sizeof(*r));
	r->id = (uint64_t)sqlite3_column_int64(s, 0);
	r->scene_id = (uint64_t)sqlite3_column_int64(s, 1);
	store_col_copy(s, 2, r->name, sizeof(r->name));
	r->options_json = store_col_dup(s, 3);
	r->target_json = store_col_dup(s, 4);
	r->eps_log_json = store_col_dup(s, 5);
	r->stats_json = store_col_dup(s, 6);
	int state = sqlite3_column_int(s, 7);
	r->iterations = (uint32_t)sqlite3_column_int64(s, 8);
	r->has_result = sqlite3_column_int(s, 9) != 0;
	store_col_copy(s, 10, r->error, sizeof(r->error));
	r->created = sqlite3_column_double(s, 11);
	r->updated = sqlite3_column_double(s, 12);
	store_col_copy(s, 13, r->owner, sizeof(r->owner));
	if (state < 0 || state >= SRV_JOB_NSTATES) { /* edited by hand */
		r->state = SRV_JOB_FAILED;
		snprintf(r->error, sizeof(r->error),
		         "stored state %d is unknown", state);
	} else {
		r->state = (srv_job_state)state;
	}
	if (!r->options_json || !r->target_json || !r->eps_log_json ||
	    !r->stats_json) {
		srv_job_row_clear(r);
		return -1;
	}
	return 0;
}

int srv_store_job_list(srv_store *st,
                       void (*fn)(void *ud, const srv_job_row *r), void *ud,
                       char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_JOB_LIST);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		srv_job_row r;
		if (job_from_row(s, &r) < 0) {
			sqlite3_reset(s);
			return srv_fail(msg, msglen, "job list: out of memory");
		}
		fn(ud, &r);
		srv_job_row_clear(&r);
	}
	sqlite3_reset(s);
	return rc == SQLITE_DONE ? 0
	                         : store_sql_fail(st, "job list", msg, msglen);
}

/* --------------------------------------------------------------- sensors */

int srv_store_sensor_add(srv_store *st, uint64_t job, const char *name,
                         const double pt[6], char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_SENSOR_INSERT);
	sqlite3_bind_int64(s, 1, store_sql_id(job));
	store_bind_text(s, 2, name);
	for (int k = 0; k < 6; k++)
		sqlite3_bind_double(s, 3 + k, pt[k]);
	return store_run(st, s, "sensor insert", msg, msglen);
}

int srv_store_sensor_list(srv_store *st,
                          void (*fn)(void *ud, uint64_t job, const char *name,
                                     const double pt[6]),
                          void *ud, char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_SENSOR_LIST);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		char name[256];
		double pt[6];
		store_col_copy(s, 1, name, sizeof(name));
		for (int k = 0; k < 6; k++)
			pt[k] = sqlite3_column_double(s, 2 + k);
		fn(ud, (uint64_t)sqlite3_column_int64(s, 0), name, pt);
	}
	sqlite3_reset(s);
	return rc == SQLITE_DONE
	               ? 0
	               : store_sql_fail(st, "sensor list", msg, msglen);
}
