/*
 * store_int.h -- what the store's files share and nothing else uses: the
 * srv_store struct, its prepared statements, and the helpers one file
 * provides to the others.  Callers include store.h only.
 *
 * DESIGN
 * Layout under the data directory (every directory created 0700):
 *   luxradd.db (+ -wal, -shm)   SQLite in WAL mode, synchronous=FULL
 *   store.lock                  flock()ed while open: one daemon per dir
 *   scenes/<id>.bin             scene bytes as uploaded
 *   results/<id>-<gen>.sol      job <id>'s checkpoint, generation <gen>
 * Ids are INTEGER PRIMARY KEY AUTOINCREMENT: SQLite never hands out an id
 * again, even after the row is deleted.
 *
 * Invariant: a committed row names a file only once that file is durable
 * (written to a temporary in the same directory, fsync'ed, renamed,
 * directory fsync'ed).  A checkpoint never overwrites the file the row
 * names: it writes the next generation, commits the row that names it,
 * and only then unlinks the previous one.  So a crash at any instant
 * leaves every row with a complete file (the old or the new one, matching
 * the row's iterations and stats); what it can leave behind is files no
 * row names and *.tmp files, which srv_store_open removes
 * (store_repair.c).
 *
 * The files, one concept each:
 *   store.c          the data directory: open, close, lock
 *   store_file.c     durable files: paths, atomic write, whole-file read
 *   store_schema.c   the database connection, its schema and versions,
 *                    the log of what opening repaired
 *   store_sql.c      prepared statements and the helpers that run them
 *   store_repair.c   rows against files at open, and the repairs log
 *   store_scenes.c   scene rows and their bytes
 *   store_jobs.c     job rows, their checkpoints, and their sensors
 *
 * Not thread-safe: one caller at a time (the daemon holds its lock).
 */
#ifndef LUXRAD_SRV_STORE_INT_H
#define LUXRAD_SRV_STORE_INT_H

#include "store.h"

#include <sqlite3.h>
#include <stddef.h>
#include <stdint.h>

#define DIRLEN 4096  /* the data directory, at most */
#define PATHLEN 4200 /* DIRLEN + a file name of ours */

#define JOB_COLS                                                               \
	"id, scene_id, name, options_json, target_json, eps_log_json, "        \
	"stats_json, state, iterations, has_result, error, created, updated, " \
	"owner"

/* Every statement, prepared once at open (store_sql_prepare). */
#define STMTS(X)                                                               \
	X(BEGIN, "BEGIN IMMEDIATE")                                            \
	X(COMMIT, "COMMIT")                                                    \
	X(ROLLBACK, "ROLLBACK")                                                \
	X(SCENE_INSERT, "INSERT INTO scenes(name, bytes, created, owner) "     \
	                "VALUES(?1, ?2, ?3, ?4)")                              \
	X(SCENE_GET, "SELECT bytes FROM scenes WHERE id = ?1")                 \
	X(SCENE_DELETE, "DELETE FROM scenes WHERE id = ?1")                    \
	X(SCENE_LIST, "SELECT id, name, bytes, created, owner FROM scenes "    \
	              "ORDER BY id")                                           \
	X(SCENE_JOBS, "SELECT count(*) FROM jobs WHERE scene_id = ?1")         \
	X(JOB_INSERT,                                                          \
	  "INSERT INTO jobs(scene_id, name, options_json, target_json, "       \
	  "eps_log_json, stats_json, state, iterations, error, created, "      \
	  "updated, owner) "                                                   \
	  "VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12)")         \
	X(JOB_UPDATE,                                                          \
	  "UPDATE jobs SET target_json = ?2, eps_log_json = ?3, "              \
	  "stats_json = ?4, state = ?5, iterations = ?6, error = ?7, "         \
	  "updated = ?8 WHERE id = ?1")                                        \
	X(JOB_CHECKPOINT,                                                      \
	  "UPDATE jobs SET target_json = ?2, eps_log_json = ?3, "              \
	  "stats_json = ?4, state = ?5, iterations = ?6, error = ?7, "         \
	  "updated = ?8, has_result = 1, result_gen = ?9, "                    \
	  "result_bytes = ?10 WHERE id = ?1")                                  \
	X(JOB_RESULT, "SELECT has_result, result_gen, result_bytes FROM jobs " \
	              "WHERE id = ?1")                                         \
	X(JOB_NO_RESULT, "UPDATE jobs SET has_result = 0 WHERE id = ?1")       \
	X(JOB_DELETE, "DELETE FROM jobs WHERE id = ?1")                        \
	X(JOB_LIST, "SELECT " JOB_COLS " FROM jobs ORDER BY id")               \
	X(JOB_SCENES, "SELECT id, scene_id FROM jobs ORDER BY id")             \
	X(SENSOR_INSERT, "INSERT INTO sensors(job_id, name, x, y, z, nx, ny, " \
	                 "nz) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)")         \
	X(SENSOR_LIST, "SELECT job_id, name, x, y, z, nx, ny, nz FROM "        \
	               "sensors ORDER BY job_id, rowid")

enum {
#define STMT_ENUM_(name, sql) ST_##name,
	STMTS(STMT_ENUM_)
#undef STMT_ENUM_
	        ST_COUNT
};

struct srv_store {
	sqlite3 *db;
	sqlite3_stmt *st[ST_COUNT];
	char dir[DIRLEN];      /* the data directory */
	char db_path[PATHLEN]; /* dir/luxradd.db, for messages */
	int lock_fd;           /* dir/store.lock, flock()ed */
	char repairs[2048];    /* what open() fixed, "" if nothing */
};

/* ------------------------------------------------------- store_file.c */

/* dir/scenes/<id>.bin and dir/results/<id>-<gen>.sol into buf[PATHLEN]. */
void store_scene_path(const srv_store *st, uint64_t id, char *buf);
void store_result_path(const srv_store *st, uint64_t id, int64_t gen,
                       char *buf);

/* mkdir -p with mode 0700 for what is created; an existing path must be a
 * directory. */
int store_make_dirs(const char *path, char *msg, size_t msglen);

/*
 * Write buf to a new temporary file in dir (name returned in tmp, at
 * least PATHLEN bytes), fsync and close it.  On failure nothing is left
 * behind.
 */
int store_tmp_write(const char *dir, const void *buf, size_t len, char *tmp,
                    char *msg, size_t msglen);

/* Rename tmp to path and make the rename durable (fsync of dir). */
int store_tmp_commit(const char *tmp, const char *path, const char *dir,
                     char *msg, size_t msglen);

/* Read a whole file whose size must be expect bytes (malloc'ed into
 * *out, caller frees). */
int store_file_read(const char *path, uint64_t expect, unsigned char **out,
                    size_t *len, char *msg, size_t msglen);

/* 1 when path is a regular file of exactly len bytes. */
int store_file_ok(const char *path, uint64_t len);

/* ----------------------------------------------------- store_schema.c */

/* Open dir/luxradd.db, bring its schema up to date and prepare every
 * statement. */
int store_schema_open(srv_store *st, char *msg, size_t msglen);

/* -------------------------------------------------------- store_sql.c */

/* Prepare STMTS into st->st; called once the schema is current. */
int store_sql_prepare(srv_store *st, char *msg, size_t msglen);

/* "<db>: <what>: <sqlite's message>" into msg; returns -1. */
int store_sql_fail(srv_store *st, const char *what, char *msg, size_t msglen);

/* Reset statement i and return it ready for binding. */
sqlite3_stmt *store_stmt(srv_store *st, int i);

/* Run a statement that returns no rows. */
int store_run(srv_store *st, sqlite3_stmt *s, const char *what, char *msg,
              size_t msglen);

/* BEGIN IMMEDIATE / COMMIT (rolls back when the commit fails) / ROLLBACK
 * if a transaction is open. */
int store_begin(srv_store *st, char *msg, size_t msglen);
int store_commit(srv_store *st, char *msg, size_t msglen);
void store_rollback(srv_store *st);

/* Bind v ("" for NULL) as text parameter i. */
void store_bind_text(sqlite3_stmt *s, int i, const char *v);

/* A strdup of column i ("" for NULL); NULL only when out of memory. */
char *store_col_dup(sqlite3_stmt *s, int i);

/* Column i's text ("" for NULL) into dst[size], truncated. */
void store_col_copy(sqlite3_stmt *s, int i, char *dst, size_t size);

/* ids on the wire are uint64; SQLite's are positive int64 (-1 matches no
 * row). */
int64_t store_sql_id(uint64_t id);

/* ----------------------------------------------------- store_repair.c */

/* Check rows against their files and sweep files no row names (see that
 * file's note); each repair is noted. */
int store_repair(srv_store *st, char *msg, size_t msglen);

/* ----------------------------------------------------- store_schema.c */

/* Append one repair to st->repairs ("; " between them). */
void store_note_repair(srv_store *st, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));

/* ----------------------------------------------------- store_scenes.c */

/* A scene or job name must fit its row's name[] ("scene" / "job"). */
int store_check_name(const char *what, const char *name, char *msg,
                     size_t msglen);

#endif
