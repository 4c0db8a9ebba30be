/*
 * store_repair.c -- the store's consistency at open: rows against their
 * files in both directions, and the log of what was repaired.
 *
 * The crash-safety invariant (store_int.h) means a crash can only leave
 * files that no row names, and *.tmp files; the sweep removes both.
 * Damage done from outside (a file deleted or truncated by hand, a
 * partial backup restore) is the other direction, also checked here:
 *   - a job whose checkpoint is missing or has the wrong size gets
 *     has_result = 0 (its state is kept: the daemon decides whether to
 *     run it again);
 *   - a scene whose bytes are missing or of the wrong size is removed,
 *     with its jobs (nothing can be solved or queried without it).
 * Each repair, and a schema upgrade, is noted in srv_store_repairs() for
 * the daemon's log.
 * Files in scenes/ and results/ whose names are not ours are left alone.
 */
#include "store_int.h"
#include "textutil.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* "<digits><suffix>" -> id (and, for results, "<id>-<gen>.sol"). */
static int parse_name(const char *name, const char *suffix, uint64_t *id,
                      int64_t *gen)
{
	char *end;
	if (name[0] < '0' || name[0] > '9')
		return -1;
	errno = 0;
	*id = strtoull(name, &end, 10);
	if (errno)
		return -1;
	if (gen) {
		if (*end != '-' || end[1] < '0' || end[1] > '9')
			return -1;
		*gen = strtoll(end + 1, &end, 10);
		if (errno)
			return -1;
	}
	return strcmp(end, suffix) == 0 ? 0 : -1;
}

static int ends_with(const char *s, const char *suffix)
{
	size_t n = strlen(s), m = strlen(suffix);
	return n >= m && strcmp(s + n - m, suffix) == 0;
}

/* Does file name in sub/ belong to a row?  -1 on SQL error. */
static int file_wanted(srv_store *st, int results, const char *name, char *msg,
                       size_t msglen)
{
	uint64_t id;
	int64_t gen = 0;
	if (parse_name(name, results ? ".sol" : ".bin", &id,
	               results ? &gen : NULL) < 0)
		return 2; /* not ours: leave it */
	sqlite3_stmt *s =
	        store_stmt(st, results ? ST_JOB_RESULT : ST_SCENE_GET);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	int rc = sqlite3_step(s), keep = 0;
	if (rc == SQLITE_ROW)
		keep = !results || (sqlite3_column_int(s, 0) &&
		                    sqlite3_column_int64(s, 1) == gen);
	sqlite3_reset(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_sql_fail(st, "file scan", msg, msglen);
	return keep;
}

/* Remove *.tmp and our files that no row names, in scenes/ or results/. */
static int sweep_dir(srv_store *st, int results, char *msg, size_t msglen)
{
	char dir[PATHLEN], path[PATHLEN + 300];
	snprintf(dir, sizeof(dir), "%s/%s", st->dir,
	         results ? "results" : "scenes");
	DIR *d = opendir(dir);
	struct dirent *e;
	int removed = 0, rc = 0;
	if (!d)
		return srv_fail(msg, msglen, "%s: cannot list: %s", dir,
		                strerror(errno));
	while ((e = readdir(d)) != NULL) {
		int keep = ends_with(e->d_name, ".tmp")
		                   ? 0
		                   : file_wanted(st, results, e->d_name, msg,
		                                 msglen);
		if (keep < 0) {
			rc = -1;
			break;
		}
		if (keep)
			continue;
		snprintf(path, sizeof(path), "%s/%s", dir, e->d_name);
		if (unlink(path) < 0) {
			srv_fail(msg, msglen, "%s: cannot remove: %s", path,
			         strerror(errno));
			rc = -1;
			break;
		}
		removed++;
	}
	closedir(d);
	if (removed)
		store_note_repair(
		        st,
		        "removed %d unreferenced or temporary file%s in "
		        "%s",
		        removed, removed > 1 ? "s" : "", dir);
	return rc;
}

/* Delete a scene row and its jobs (and their checkpoints) after its file
 * vanished. */
static int drop_scene(srv_store *st, int64_t scene, char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_JOB_SCENES);
	int64_t jobs[64];
	int n = 0, rc;
	char path[PATHLEN];
	do { /* delete in batches: the statement is reset between them */
		n = 0;
		while (n < 64 && (rc = sqlite3_step(s)) == SQLITE_ROW)
			if (sqlite3_column_int64(s, 1) == scene)
				jobs[n++] = sqlite3_column_int64(s, 0);
		sqlite3_reset(s);
		if (rc != SQLITE_ROW && rc != SQLITE_DONE)
			return store_sql_fail(st, "scene repair", msg, msglen);
		for (int i = 0; i < n; i++)
			if (srv_store_job_delete(st, (uint64_t)jobs[i], msg,
			                         msglen) < 0)
				return -1;
	} while (n == 64);
	sqlite3_stmt *d = store_stmt(st, ST_SCENE_DELETE);
	sqlite3_bind_int64(d, 1, scene);
	if (store_run(st, d, "scene repair", msg, msglen) < 0)
		return -1;
	store_scene_path(st, (uint64_t)scene, path);
	unlink(path);
	return 0;
}

/* Jobs whose checkpoint is missing or truncated: has_result = 0. */
static int check_results(srv_store *st, char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_JOB_LIST);
	int64_t *bad = NULL, *nb;
	size_t n = 0, cap = 0;
	char path[PATHLEN];
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		int64_t id = sqlite3_column_int64(s, 0);
		if (!sqlite3_column_int(s, 9))
			continue;
		sqlite3_stmt *r = store_stmt(st, ST_JOB_RESULT);
		sqlite3_bind_int64(r, 1, id);
		if (sqlite3_step(r) != SQLITE_ROW)
			continue;
		store_result_path(st, (uint64_t)id, sqlite3_column_int64(r, 1),
		                  path);
		int ok = store_file_ok(path,
		                       (uint64_t)sqlite3_column_int64(r, 2));
		sqlite3_reset(r);
		if (ok)
			continue;
		if (n == cap) {
			cap = cap ? 2 * cap : 16;
			if (!(nb = realloc(bad, cap * sizeof(*bad)))) {
				free(bad);
				sqlite3_reset(s);
				return srv_fail(msg, msglen, "out of memory");
			}
			bad = nb;
		}
		bad[n++] = id;
	}
	sqlite3_reset(s);
	if (rc != SQLITE_DONE) {
		free(bad);
		return store_sql_fail(st, "checkpoint check", msg, msglen);
	}
	for (size_t i = 0; i < n; i++) {
		sqlite3_stmt *u = store_stmt(st, ST_JOB_NO_RESULT);
		sqlite3_bind_int64(u, 1, bad[i]);
		if (store_run(st, u, "job repair", msg, msglen) < 0) {
			free(bad);
			return -1;
		}
		store_note_repair(st,
		                  "job %lld: checkpoint missing or truncated, "
		                  "has_result cleared",
		                  (long long)bad[i]);
	}
	free(bad);
	return 0;
}

/* Rows whose file is missing or damaged (see the DESIGN note). */
static int check_rows(srv_store *st, char *msg, size_t msglen)
{
	char path[PATHLEN];
	int64_t bad[64];
	int n, rc;
	do { /* scenes */
		sqlite3_stmt *s = store_stmt(st, ST_SCENE_LIST);
		n = 0;
		while (n < 64 && (rc = sqlite3_step(s)) == SQLITE_ROW) {
			store_scene_path(
			        st, (uint64_t)sqlite3_column_int64(s, 0), path);
			if (!store_file_ok(
			            path, (uint64_t)sqlite3_column_int64(s, 2)))
				bad[n++] = sqlite3_column_int64(s, 0);
		}
		sqlite3_reset(s);
		if (rc != SQLITE_ROW && rc != SQLITE_DONE)
			return store_sql_fail(st, "scene check", msg, msglen);
		for (int i = 0; i < n; i++) {
			store_note_repair(
			        st,
			        "scene %lld: bytes missing or truncated, "
			        "scene and its jobs removed",
			        (long long)bad[i]);
			if (drop_scene(st, bad[i], msg, msglen) < 0)
				return -1;
		}
	} while (n == 64);
	return check_results(st, msg, msglen);
}

int store_repair(srv_store *st, char *msg, size_t msglen)
{
	if (check_rows(st, msg, msglen) < 0 || sweep_dir(st, 0, msg, msglen) ||
	    sweep_dir(st, 1, msg, msglen))
		return -1;
	return 0;
}
