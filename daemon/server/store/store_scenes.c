/*
 * store_scenes.c -- scene rows (scenes table) and their bytes
 * (scenes/<id>.bin).  Adding a scene writes the file first and commits the
 * row and the rename together; deleting one removes the row first and
 * the file second, so that a crash never leaves a row without its file
 * (store_int.h).  A scene with jobs cannot be deleted.
 */
#include "log.h"
#include "store_int.h"
#include "textutil.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

int store_check_name(const char *what, const char *name, char *msg,
                     size_t msglen)
{
	size_t n = name ? strlen(name) : 0;
	if (n >= sizeof(((srv_scene_row *)0)->name))
		return srv_fail(msg, msglen,
		                "%s name is %zu bytes, at most %zu", what, n,
		                sizeof(((srv_scene_row *)0)->name) - 1);
	return 0;
}

int srv_store_scene_add(srv_store *st, const char *name, const char *owner,
                        const void *bytes, size_t len, uint64_t *id, char *msg,
                        size_t msglen)
{
	char dir[PATHLEN], tmp[PATHLEN], path[PATHLEN];
	if (store_check_name("scene", name, msg, msglen) < 0)
		return -1;
	snprintf(dir, sizeof(dir), "%s/scenes", st->dir);
	if (store_tmp_write(dir, bytes, len, tmp, msg, msglen) < 0)
		return -1;
	/* The row and the rename commit together; a crash in between
	 * leaves <id>.bin without a row, which open() removes. */
	if (store_begin(st, msg, msglen) < 0)
		goto bad_tmp;
	sqlite3_stmt *s = store_stmt(st, ST_SCENE_INSERT);
	store_bind_text(s, 1, name);
	sqlite3_bind_int64(s, 2, (int64_t)len);
	sqlite3_bind_double(s, 3, srv_now_unix());
	store_bind_text(s, 4, owner ? owner : "");
	if (store_run(st, s, "scene insert", msg, msglen) < 0)
		goto bad_tx;
	int64_t rowid = sqlite3_last_insert_rowid(st->db);
	store_scene_path(st, (uint64_t)rowid, path);
	if (store_tmp_commit(tmp, path, dir, msg, msglen) < 0)
		goto bad_file;
	if (store_commit(st, msg, msglen) < 0)
		goto bad_file;
	*id = (uint64_t)rowid;
	return 0;
bad_file:
	unlink(path);
	store_rollback(st);
	return -1;
bad_tx:
	store_rollback(st);
bad_tmp:
	unlink(tmp);
	return -1;
}

/* The recorded size of scene id: 1 found, 0 not found, -1 error. */
static int scene_size(srv_store *st, uint64_t id, uint64_t *bytes, char *msg,
                      size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_SCENE_GET);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW)
		*bytes = (uint64_t)sqlite3_column_int64(s, 0);
	sqlite3_reset(s);
	if (rc == SQLITE_DONE)
		return srv_fail(msg, msglen, "scene %llu not found",
		                (unsigned long long)id),
		       0;
	return rc == SQLITE_ROW ? 1
	                        : store_sql_fail(st, "scene read", msg, msglen);
}

int srv_store_scene_read(srv_store *st, uint64_t id, unsigned char **bytes,
                         size_t *len, char *msg, size_t msglen)
{
	char path[PATHLEN];
	uint64_t size = 0;
	if (scene_size(st, id, &size, msg, msglen) <= 0)
		return -1;
	store_scene_path(st, id, path);
	return store_file_read(path, size, bytes, len, msg, msglen);
}

int srv_store_scene_delete(srv_store *st, uint64_t id, char *msg, size_t msglen)
{
	char path[PATHLEN];
	uint64_t size;
	if (scene_size(st, id, &size, msg, msglen) <= 0)
		return -1;
	sqlite3_stmt *s = store_stmt(st, ST_SCENE_JOBS);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	int rc = sqlite3_step(s);
	int64_t jobs = rc == SQLITE_ROW ? sqlite3_column_int64(s, 0) : 0;
	sqlite3_reset(s);
	if (rc != SQLITE_ROW)
		return store_sql_fail(st, "scene delete", msg, msglen);
	if (jobs > 0)
		return srv_fail(
		        msg, msglen,
		        "scene %llu is used by %lld job%s: delete them first",
		        (unsigned long long)id, (long long)jobs,
		        jobs > 1 ? "s" : "");
	s = store_stmt(st, ST_SCENE_DELETE);
	sqlite3_bind_int64(s, 1, store_sql_id(id));
	if (store_run(st, s, "scene delete", msg, msglen) < 0)
		return -1;
	/* Row first, file second: a crash in between leaves an orphan
	 * file that open() removes, never a row without its file. */
	store_scene_path(st, id, path);
	if (unlink(path) < 0 && errno != ENOENT)
		return srv_fail(msg, msglen, "%s: cannot remove: %s", path,
		                strerror(errno));
	return 0;
}

int srv_store_scene_list(srv_store *st,
                         void (*fn)(void *ud, const srv_scene_row *r), void *ud,
                         char *msg, size_t msglen)
{
	sqlite3_stmt *s = store_stmt(st, ST_SCENE_LIST);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		srv_scene_row r;
		memset(&r, 0, sizeof(r));
		r.id = (uint64_t)sqlite3_column_int64(s, 0);
		store_col_copy(s, 1, r.name, sizeof(r.name));
		r.bytes = (uint64_t)sqlite3_column_int64(s, 2);
		r.created = sqlite3_column_double(s, 3);
		store_col_copy(s, 4, r.owner, sizeof(r.owner));
		fn(ud, &r);
	}
	sqlite3_reset(s);
	return rc == SQLITE_DONE
	               ? 0
	               : store_sql_fail(st, "scene list", msg, msglen);
}
