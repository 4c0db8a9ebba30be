/*
 * store.c -- luxradd's durable state: a SQLite database of scenes and jobs
 * beside the files that hold scene bytes and solution checkpoints.
 *
 * DESIGN
 * Layout under the data directory (every directory created 0700):
 *   luxradd.db (+ -wal, -shm)   SQLite in WAL mode, synchronous=FULL
 *   store.lock                flock()ed while open: one daemon per dir
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
 * row names and *.tmp files, which srv_store_open removes.
 *
 * srv_store_open also checks the other direction, for damage done from
 * outside (a file deleted or truncated by hand, a partial backup restore):
 *   - a job whose checkpoint is missing or has the wrong size gets
 *     has_result = 0 (its state is kept: the daemon decides whether to
 *     run it again);
 *   - a scene whose bytes are missing or of the wrong size is removed,
 *     with its jobs (nothing can be solved or queried without it).
 * Each repair, and a schema upgrade, is noted in srv_store_repairs() for
 * the daemon's log.
 * Files in scenes/ and results/ whose names are not ours are left alone.
 *
 * Schema versions: PRAGMA user_version (0 = empty database, 1 = scenes
 * and jobs, 2 = this layout: 1 plus the sensors added over the protocol).
 * An older database is brought up to date in one transaction at open; a
 * newer one is refused rather than misread.
 *
 * Not thread-safe: one caller at a time (the daemon holds its lock).
 */
#include "store.h"
#include "textutil.h"

#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define SCHEMA_VERSION 2
#define DIRLEN 4096  /* the data directory, at most */
#define PATHLEN 4200 /* DIRLEN + a file name of ours */

static const char schema_v1[] =
        "CREATE TABLE scenes("
        " id INTEGER PRIMARY KEY AUTOINCREMENT,"
        " name TEXT NOT NULL,"
        " bytes INTEGER NOT NULL,"
        " created REAL NOT NULL);"
        "CREATE TABLE jobs("
        " id INTEGER PRIMARY KEY AUTOINCREMENT,"
        " scene_id INTEGER NOT NULL REFERENCES scenes(id),"
        " name TEXT NOT NULL,"
        " options_json TEXT NOT NULL,"
        " target_json TEXT NOT NULL,"
        " eps_log_json TEXT NOT NULL,"
        " stats_json TEXT NOT NULL,"
        " state INTEGER NOT NULL,"
        " iterations INTEGER NOT NULL,"
        " has_result INTEGER NOT NULL DEFAULT 0,"
        " result_gen INTEGER NOT NULL DEFAULT 0," /* results/<id>-<gen> */
        " result_bytes INTEGER NOT NULL DEFAULT 0,"
        " error TEXT NOT NULL,"
        " created REAL NOT NULL,"
        " updated REAL NOT NULL);"
        "CREATE INDEX jobs_scene ON jobs(scene_id);"
        "PRAGMA user_version = 1;";

/* 1 -> 2: sensors go with their job (ON DELETE CASCADE). */
static const char schema_v2[] =
        "CREATE TABLE sensors("
        " job_id INTEGER NOT NULL REFERENCES jobs(id) ON DELETE CASCADE,"
        " name TEXT NOT NULL,"
        " x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,"
        " nx REAL NOT NULL, ny REAL NOT NULL, nz REAL NOT NULL,"
        " PRIMARY KEY(job_id, name));"
        "PRAGMA user_version = 2;";

#define JOB_COLS                                                               \
	"id, scene_id, name, options_json, target_json, eps_log_json, "        \
	"stats_json, state, iterations, has_result, error, created, updated"

/* Every statement, prepared once at open. */
#define STMTS(X)                                                               \
	X(BEGIN, "BEGIN IMMEDIATE")                                            \
	X(COMMIT, "COMMIT")                                                    \
	X(ROLLBACK, "ROLLBACK")                                                \
	X(SCENE_INSERT, "INSERT INTO scenes(name, bytes, created) "            \
	                "VALUES(?1, ?2, ?3)")                                  \
	X(SCENE_GET, "SELECT bytes FROM scenes WHERE id = ?1")                 \
	X(SCENE_DELETE, "DELETE FROM scenes WHERE id = ?1")                    \
	X(SCENE_LIST, "SELECT id, name, bytes, created FROM scenes "           \
	              "ORDER BY id")                                           \
	X(SCENE_JOBS, "SELECT count(*) FROM jobs WHERE scene_id = ?1")         \
	X(JOB_INSERT,                                                          \
	  "INSERT INTO jobs(scene_id, name, options_json, target_json, "       \
	  "eps_log_json, stats_json, state, iterations, error, created, "      \
	  "updated) VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11)")     \
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

static const char *const stmt_sql[] = {
#define STMT_SQL_(name, sql) sql,
        STMTS(STMT_SQL_)
#undef STMT_SQL_
};

struct srv_store {
	sqlite3 *db;
	sqlite3_stmt *st[ST_COUNT];
	char dir[DIRLEN];      /* the data directory */
	char db_path[PATHLEN]; /* dir/luxradd.db, for messages */
	int lock_fd;           /* dir/store.lock, flock()ed */
	char repairs[2048];    /* what open() fixed, "" if nothing */
};

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

const char *srv_store_repairs(const srv_store *st)
{
	return st->repairs;
}

static void note_repair(srv_store *st, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));
static void note_repair(srv_store *st, const char *fmt, ...)
{
	size_t n = strlen(st->repairs);
	va_list ap;
	if (n + 2 >= sizeof(st->repairs))
		return;
	if (n)
		st->repairs[n++] = ';', st->repairs[n++] = ' ';
	st->repairs[n] = '\0';
	va_start(ap, fmt);
	vsnprintf(st->repairs + n, sizeof(st->repairs) - n, fmt, ap);
	va_end(ap);
}

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* ---------------------------------------------------------------- files */

static void scene_path(const srv_store *st, uint64_t id, char *buf)
{
	snprintf(buf, PATHLEN, "%s/scenes/%llu.bin", st->dir,
	         (unsigned long long)id);
}

static void result_path(const srv_store *st, uint64_t id, int64_t gen,
                        char *buf)
{
	snprintf(buf, PATHLEN, "%s/results/%llu-%lld.sol", st->dir,
	         (unsigned long long)id, (long long)gen);
}

static int fsync_dir(const char *dir, char *msg, size_t msglen)
{
	int fd = open(dir, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
	if (fd < 0 || fsync(fd) < 0) {
		srv_fail(msg, msglen, "%s: cannot sync directory: %s", dir,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	close(fd);
	return 0;
}

/*
 * Write buf to a new temporary file in dir (name returned in tmp), fsync
 * and close it.  On failure nothing is left behind.
 */
static int tmp_write(const char *dir, const void *buf, size_t len, char *tmp,
                     char *msg, size_t msglen)
{
	const unsigned char *p = buf;
	snprintf(tmp, PATHLEN, "%s/.XXXXXX.tmp", dir);
	int fd = mkostemps(tmp, 4, O_CLOEXEC);
	if (fd < 0) {
		srv_fail(msg, msglen, "%s: cannot create a temporary file: %s",
		         dir, strerror(errno));
		return -1;
	}
	while (len > 0) {
		ssize_t n = write(fd, p, len > (1u << 30) ? (1u << 30) : len);
		if (n < 0 && errno == EINTR)
			continue;
		if (n <= 0)
			goto bad;
		p += n;
		len -= (size_t)n;
	}
	if (fsync(fd) < 0)
		goto bad;
	if (close(fd) < 0) {
		fd = -1;
		goto bad;
	}
	return 0;
bad:
	srv_fail(msg, msglen, "%s: cannot write: %s", tmp,
	         errno ? strerror(errno) : "short write");
	if (fd >= 0)
		close(fd);
	unlink(tmp);
	return -1;
}

/* Rename tmp to path and make the rename durable. */
static int tmp_commit(const char *tmp, const char *path, const char *dir,
                      char *msg, size_t msglen)
{
	if (rename(tmp, path) < 0) {
		srv_fail(msg, msglen, "cannot rename %s to %s: %s", tmp, path,
		         strerror(errno));
		unlink(tmp);
		return -1;
	}
	return fsync_dir(dir, msg, msglen);
}

/* Read a whole file whose size must be expect bytes. */
static int file_read(const char *path, uint64_t expect, unsigned char **out,
                     size_t *len, char *msg, size_t msglen)
{
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	struct stat sb;
	if (fd < 0 || fstat(fd, &sb) < 0) {
		srv_fail(msg, msglen, "%s: cannot open: %s", path,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	if ((uint64_t)sb.st_size != expect) {
		srv_fail(msg, msglen, "%s: %lld bytes, the store recorded %llu",
		         path, (long long)sb.st_size,
		         (unsigned long long)expect);
		close(fd);
		return -1;
	}
	unsigned char *buf = malloc(expect ? (size_t)expect : 1);
	size_t got = 0;
	if (!buf) {
		srv_fail(msg, msglen, "%s: out of memory for %llu bytes", path,
		         (unsigned long long)expect);
		close(fd);
		return -1;
	}
	while (got < expect) {
		ssize_t n = read(fd, buf + got, (size_t)expect - got);
		if (n < 0 && errno == EINTR)
			continue;
		if (n <= 0) {
			srv_fail(msg, msglen, "%s: read failed: %s", path,
			         n < 0 ? strerror(errno) : "file shrank");
			free(buf);
			close(fd);
			return -1;
		}
		got += (size_t)n;
	}
	close(fd);
	*out = buf;
	*len = got;
	return 0;
}

/* ----------------------------------------------------------------- SQL */

static int sql_fail(srv_store *st, const char *what, char *msg, size_t msglen)
{
	srv_fail(msg, msglen, "%s: %s: %s", st->db_path, what,
	         sqlite3_errmsg(st->db));
	return -1;
}

/* Reset st[i] and return it ready for binding. */
static sqlite3_stmt *stmt(srv_store *st, int i)
{
	sqlite3_reset(st->st[i]);
	sqlite3_clear_bindings(st->st[i]);
	return st->st[i];
}

/* Run a statement that returns no rows. */
static int run(srv_store *st, sqlite3_stmt *s, const char *what, char *msg,
               size_t msglen)
{
	int rc = sqlite3_step(s);
	sqlite3_reset(s);
	if (rc != SQLITE_DONE)
		return sql_fail(st, what, msg, msglen);
	return 0;
}

static int begin(srv_store *st, char *msg, size_t msglen)
{
	return run(st, stmt(st, ST_BEGIN), "begin", msg, msglen);
}

static int commit(srv_store *st, char *msg, size_t msglen)
{
	if (run(st, stmt(st, ST_COMMIT), "commit", msg, msglen) == 0)
		return 0;
	sqlite3_step(stmt(st, ST_ROLLBACK));
	sqlite3_reset(st->st[ST_ROLLBACK]);
	return -1;
}

static void rollback(srv_store *st)
{
	if (!sqlite3_get_autocommit(st->db)) {
		sqlite3_step(stmt(st, ST_ROLLBACK));
		sqlite3_reset(st->st[ST_ROLLBACK]);
	}
}

static void bind_text(sqlite3_stmt *s, int i, const char *v)
{
	sqlite3_bind_text(s, i, v ? v : "", -1, SQLITE_TRANSIENT);
}

/* A strdup of column i ("" for NULL); NULL only when out of memory. */
static char *col_dup(sqlite3_stmt *s, int i)
{
	const char *t = (const char *)sqlite3_column_text(s, i);
	return strdup(t ? t : "");
}

static void col_copy(sqlite3_stmt *s, int i, char *dst, size_t size)
{
	const char *t = (const char *)sqlite3_column_text(s, i);
	snprintf(dst, size, "%s", t ? t : "");
}

/* ids on the wire are uint64; SQLite's are positive int64. */
static int64_t sql_id(uint64_t id)
{
	return id > INT64_MAX ? -1 : (int64_t)id;
}

/* ---------------------------------------------------------------- open */

/* mkdir -p with mode 0700 for what is created; an existing path must be a
 * directory. */
static int make_dirs(const char *path, char *msg, size_t msglen)
{
	char buf[PATHLEN];
	struct stat sb;
	if (snprintf(buf, sizeof(buf), "%s", path) >= (int)sizeof(buf))
		return srv_fail(msg, msglen, "%s: path too long", path);
	for (char *p = buf + 1;; p++) {
		if (*p != '/' && *p != '\0')
			continue;
		char c = *p;
		*p = '\0';
		if (mkdir(buf, 0700) < 0 && errno != EEXIST)
			return srv_fail(msg, msglen,
			                "cannot create directory %s: %s", buf,
			                strerror(errno));
		*p = c;
		if (c == '\0')
			break;
	}
	if (stat(path, &sb) < 0 || !S_ISDIR(sb.st_mode))
		return srv_fail(msg, msglen, "%s: not a directory", path);
	return 0;
}

static int take_lock(srv_store *st, char *msg, size_t msglen)
{
	char path[PATHLEN];
	snprintf(path, sizeof(path), "%s/store.lock", st->dir);
	st->lock_fd = open(path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
	if (st->lock_fd < 0)
		return srv_fail(msg, msglen, "%s: cannot open: %s", path,
		                strerror(errno));
	if (flock(st->lock_fd, LOCK_EX | LOCK_NB) < 0)
		return srv_fail(
		        msg, msglen, "%s: %s (is another luxradd using %s?)",
		        path, errno == EWOULDBLOCK ? "locked" : strerror(errno),
		        st->dir);
	return 0;
}

/* One-value PRAGMA; its text result copied into out. */
static int pragma(srv_store *st, const char *sql, char *out, size_t outlen,
                  char *msg, size_t msglen)
{
	sqlite3_stmt *s;
	if (sqlite3_prepare_v2(st->db, sql, -1, &s, NULL) != SQLITE_OK)
		return sql_fail(st, sql, msg, msglen);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && out)
		col_copy(s, 0, out, outlen);
	else if (out)
		out[0] = '\0';
	sqlite3_finalize(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return sql_fail(st, sql, msg, msglen);
	return 0;
}

static int open_db(srv_store *st, char *msg, size_t msglen)
{
	char v[256];
	snprintf(st->db_path, sizeof(st->db_path), "%s/luxradd.db", st->dir);
	if (sqlite3_open_v2(st->db_path, &st->db,
	                    SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE,
	                    NULL) != SQLITE_OK)
		return sql_fail(st, "cannot open", msg, msglen);
	sqlite3_extended_result_codes(st->db, 1);
	if (pragma(st, "PRAGMA journal_mode = WAL", v, sizeof(v), msg, msglen) <
	    0)
		return -1;
	if (strcmp(v, "wal") != 0)
		return srv_fail(msg, msglen,
		                "%s: cannot use WAL mode (got '%s')",
		                st->db_path, v);
	if (pragma(st, "PRAGMA synchronous = FULL", NULL, 0, msg, msglen) < 0 ||
	    pragma(st, "PRAGMA foreign_keys = ON", NULL, 0, msg, msglen) < 0)
		return -1;
	if (pragma(st, "PRAGMA quick_check", v, sizeof(v), msg, msglen) < 0)
		return -1;
	if (strcmp(v, "ok") != 0)
		return srv_fail(msg, msglen, "%s: database is damaged: %s",
		                st->db_path, v);
	if (pragma(st, "PRAGMA user_version", v, sizeof(v), msg, msglen) < 0)
		return -1;
	long ver = strtol(v, NULL, 10);
	if (ver > SCHEMA_VERSION)
		return srv_fail(msg, msglen,
		                "%s: schema version %ld is newer than this "
		                "luxradd's (%d)",
		                st->db_path, ver, SCHEMA_VERSION);
	if (ver < SCHEMA_VERSION) {
		char *err = NULL;
		if (sqlite3_exec(st->db, "BEGIN", NULL, NULL, NULL) !=
		            SQLITE_OK ||
		    (ver < 1 && sqlite3_exec(st->db, schema_v1, NULL, NULL,
		                             &err) != SQLITE_OK) ||
		    sqlite3_exec(st->db, schema_v2, NULL, NULL, &err) !=
		            SQLITE_OK ||
		    sqlite3_exec(st->db, "COMMIT", NULL, NULL, NULL) !=
		            SQLITE_OK) {
			srv_fail(msg, msglen,
			         "%s: cannot bring the schema from version %ld "
			         "to %d: %s",
			         st->db_path, ver, SCHEMA_VERSION,
			         err ? err : sqlite3_errmsg(st->db));
			sqlite3_free(err);
			sqlite3_exec(st->db, "ROLLBACK", NULL, NULL, NULL);
			return -1;
		}
		if (ver > 0)
			note_repair(st,
			            "schema upgraded from version %ld to %d",
			            ver, SCHEMA_VERSION);
	}
	for (int i = 0; i < ST_COUNT; i++)
		if (sqlite3_prepare_v3(st->db, stmt_sql[i], -1,
		                       SQLITE_PREPARE_PERSISTENT, &st->st[i],
		                       NULL) != SQLITE_OK)
			return sql_fail(st, stmt_sql[i], msg, msglen);
	return 0;
}

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
	sqlite3_stmt *s = stmt(st, results ? ST_JOB_RESULT : ST_SCENE_GET);
	sqlite3_bind_int64(s, 1, sql_id(id));
	int rc = sqlite3_step(s), keep = 0;
	if (rc == SQLITE_ROW)
		keep = !results || (sqlite3_column_int(s, 0) &&
		                    sqlite3_column_int64(s, 1) == gen);
	sqlite3_reset(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return sql_fail(st, "file scan", msg, msglen);
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
		note_repair(st,
		            "removed %d unreferenced or temporary file%s in "
		            "%s",
		            removed, removed > 1 ? "s" : "", dir);
	return rc;
}

/* 1 when path is a regular file of exactly len bytes. */
static int file_ok(const char *path, uint64_t len)
{
	struct stat sb;
	return stat(path, &sb) == 0 && S_ISREG(sb.st_mode) &&
	       (uint64_t)sb.st_size == len;
}

/* Delete a scene row and its jobs (and their checkpoints) after its file
 * vanished. */
static int drop_scene(srv_store *st, int64_t scene, char *msg, size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_JOB_SCENES);
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
			return sql_fail(st, "scene repair", msg, msglen);
		for (int i = 0; i < n; i++)
			if (srv_store_job_delete(st, (uint64_t)jobs[i], msg,
			                         msglen) < 0)
				return -1;
	} while (n == 64);
	sqlite3_stmt *d = stmt(st, ST_SCENE_DELETE);
	sqlite3_bind_int64(d, 1, scene);
	if (run(st, d, "scene repair", msg, msglen) < 0)
		return -1;
	scene_path(st, (uint64_t)scene, path);
	unlink(path);
	return 0;
}

/* Jobs whose checkpoint is missing or truncated: has_result = 0. */
static int check_results(srv_store *st, char *msg, size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_JOB_LIST);
	int64_t *bad = NULL, *nb;
	size_t n = 0, cap = 0;
	char path[PATHLEN];
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		int64_t id = sqlite3_column_int64(s, 0);
		if (!sqlite3_column_int(s, 9))
			continue;
		sqlite3_stmt *r = stmt(st, ST_JOB_RESULT);
		sqlite3_bind_int64(r, 1, id);
		if (sqlite3_step(r) != SQLITE_ROW)
			continue;
		result_path(st, (uint64_t)id, sqlite3_column_int64(r, 1), path);
		int ok = file_ok(path, (uint64_t)sqlite3_column_int64(r, 2));
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
		return sql_fail(st, "checkpoint check", msg, msglen);
	}
	for (size_t i = 0; i < n; i++) {
		sqlite3_stmt *u = stmt(st, ST_JOB_NO_RESULT);
		sqlite3_bind_int64(u, 1, bad[i]);
		if (run(st, u, "job repair", msg, msglen) < 0) {
			free(bad);
			return -1;
		}
		note_repair(st,
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
		sqlite3_stmt *s = stmt(st, ST_SCENE_LIST);
		n = 0;
		while (n < 64 && (rc = sqlite3_step(s)) == SQLITE_ROW) {
			scene_path(st, (uint64_t)sqlite3_column_int64(s, 0),
			           path);
			if (!file_ok(path,
			             (uint64_t)sqlite3_column_int64(s, 2)))
				bad[n++] = sqlite3_column_int64(s, 0);
		}
		sqlite3_reset(s);
		if (rc != SQLITE_ROW && rc != SQLITE_DONE)
			return sql_fail(st, "scene check", msg, msglen);
		for (int i = 0; i < n; i++) {
			note_repair(st,
			            "scene %lld: bytes missing or truncated, "
			            "scene and its jobs removed",
			            (long long)bad[i]);
			if (drop_scene(st, bad[i], msg, msglen) < 0)
				return -1;
		}
	} while (n == 64);
	return check_results(st, msg, msglen);
}

srv_store *srv_store_open(const char *data_dir, char *msg, size_t msglen)
{
	srv_store *st = calloc(1, sizeof(*st));
	char sub[PATHLEN];
	if (!st)
		return srv_fail(msg, msglen, "out of memory"), NULL;
	st->lock_fd = -1;
	if (!data_dir || !data_dir[0]) {
		srv_fail(msg, msglen, "no data directory given");
		goto bad;
	}
	if (snprintf(st->dir, sizeof(st->dir), "%s", data_dir) >=
	    (int)sizeof(st->dir) - 64) {
		srv_fail(msg, msglen, "%s: path too long", data_dir);
		goto bad;
	}
	if (make_dirs(st->dir, msg, msglen) < 0 || take_lock(st, msg, msglen))
		goto bad;
	snprintf(sub, sizeof(sub), "%s/scenes", st->dir);
	if (make_dirs(sub, msg, msglen) < 0)
		goto bad;
	snprintf(sub, sizeof(sub), "%s/results", st->dir);
	if (make_dirs(sub, msg, msglen) < 0 || open_db(st, msg, msglen) < 0)
		goto bad;
	if (check_rows(st, msg, msglen) < 0 || sweep_dir(st, 0, msg, msglen) ||
	    sweep_dir(st, 1, msg, msglen))
		goto bad;
	return st;
bad:
	srv_store_close(st);
	return NULL;
}

void srv_store_close(srv_store *st)
{
	if (!st)
		return;
	for (int i = 0; i < ST_COUNT; i++)
		sqlite3_finalize(st->st[i]);
	if (st->db)
		sqlite3_close(st->db);
	if (st->lock_fd >= 0)
		close(st->lock_fd); /* releases the flock */
	free(st);
}

/* -------------------------------------------------------------- scenes */

static int check_name(const char *what, const char *name, char *msg,
                      size_t msglen)
{
	size_t n = name ? strlen(name) : 0;
	if (n >= sizeof(((srv_scene_row *)0)->name))
		return srv_fail(msg, msglen,
		                "%s name is %zu bytes, at most %zu", what, n,
		                sizeof(((srv_scene_row *)0)->name) - 1);
	return 0;
}

int srv_store_scene_add(srv_store *st, const char *name, const void *bytes,
                        size_t len, uint64_t *id, char *msg, size_t msglen)
{
	char dir[PATHLEN], tmp[PATHLEN], path[PATHLEN];
	if (check_name("scene", name, msg, msglen) < 0)
		return -1;
	snprintf(dir, sizeof(dir), "%s/scenes", st->dir);
	if (tmp_write(dir, bytes, len, tmp, msg, msglen) < 0)
		return -1;
	/* The row and the rename commit together; a crash in between
	 * leaves <id>.bin without a row, which open() removes. */
	if (begin(st, msg, msglen) < 0)
		goto bad_tmp;
	sqlite3_stmt *s = stmt(st, ST_SCENE_INSERT);
	bind_text(s, 1, name);
	sqlite3_bind_int64(s, 2, (int64_t)len);
	sqlite3_bind_double(s, 3, now_s());
	if (run(st, s, "scene insert", msg, msglen) < 0)
		goto bad_tx;
	int64_t rowid = sqlite3_last_insert_rowid(st->db);
	scene_path(st, (uint64_t)rowid, path);
	if (tmp_commit(tmp, path, dir, msg, msglen) < 0)
		goto bad_file;
	if (commit(st, msg, msglen) < 0)
		goto bad_file;
	*id = (uint64_t)rowid;
	return 0;
bad_file:
	unlink(path);
	rollback(st);
	return -1;
bad_tx:
	rollback(st);
bad_tmp:
	unlink(tmp);
	return -1;
}

/* The recorded size of scene id: 1 found, 0 not found, -1 error. */
static int scene_size(srv_store *st, uint64_t id, uint64_t *bytes, char *msg,
                      size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_SCENE_GET);
	sqlite3_bind_int64(s, 1, sql_id(id));
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW)
		*bytes = (uint64_t)sqlite3_column_int64(s, 0);
	sqlite3_reset(s);
	if (rc == SQLITE_DONE)
		return srv_fail(msg, msglen, "scene %llu not found",
		                (unsigned long long)id),
		       0;
	return rc == SQLITE_ROW ? 1 : sql_fail(st, "scene read", msg, msglen);
}

int srv_store_scene_read(srv_store *st, uint64_t id, unsigned char **bytes,
                         size_t *len, char *msg, size_t msglen)
{
	char path[PATHLEN];
	uint64_t size = 0;
	if (scene_size(st, id, &size, msg, msglen) <= 0)
		return -1;
	scene_path(st, id, path);
	return file_read(path, size, bytes, len, msg, msglen);
}

int srv_store_scene_delete(srv_store *st, uint64_t id, char *msg, size_t msglen)
{
	char path[PATHLEN];
	uint64_t size;
	if (scene_size(st, id, &size, msg, msglen) <= 0)
		return -1;
	sqlite3_stmt *s = stmt(st, ST_SCENE_JOBS);
	sqlite3_bind_int64(s, 1, sql_id(id));
	int rc = sqlite3_step(s);
	int64_t jobs = rc == SQLITE_ROW ? sqlite3_column_int64(s, 0) : 0;
	sqlite3_reset(s);
	if (rc != SQLITE_ROW)
		return sql_fail(st, "scene delete", msg, msglen);
	if (jobs > 0)
		return srv_fail(
		        msg, msglen,
		        "scene %llu is used by %lld job%s: delete them first",
		        (unsigned long long)id, (long long)jobs,
		        jobs > 1 ? "s" : "");
	s = stmt(st, ST_SCENE_DELETE);
	sqlite3_bind_int64(s, 1, sql_id(id));
	if (run(st, s, "scene delete", msg, msglen) < 0)
		return -1;
	/* Row first, file second: a crash in between leaves an orphan
	 * file that open() removes, never a row without its file. */
	scene_path(st, id, path);
	if (unlink(path) < 0 && errno != ENOENT)
		return srv_fail(msg, msglen, "%s: cannot remove: %s", path,
		                strerror(errno));
	return 0;
}

int srv_store_scene_list(srv_store *st,
                         void (*fn)(void *ud, const srv_scene_row *r), void *ud,
                         char *msg, size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_SCENE_LIST);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		srv_scene_row r;
		memset(&r, 0, sizeof(r));
		r.id = (uint64_t)sqlite3_column_int64(s, 0);
		col_copy(s, 1, r.name, sizeof(r.name));
		r.bytes = (uint64_t)sqlite3_column_int64(s, 2);
		r.created = sqlite3_column_double(s, 3);
		fn(ud, &r);
	}
	sqlite3_reset(s);
	return rc == SQLITE_DONE ? 0 : sql_fail(st, "scene list", msg, msglen);
}

/* ---------------------------------------------------------------- jobs */

int srv_store_job_add(srv_store *st, srv_job_row *row, char *msg, size_t msglen)
{
	if (check_name("job", row->name, msg, msglen) < 0)
		return -1;
	if ((unsigned)row->state >= SRV_JOB_NSTATES)
		return srv_fail(msg, msglen, "job state %d is not a state",
		                (int)row->state);
	double t = now_s();
	if (row->created <= 0)
		row->created = t;
	if (row->updated <= 0)
		row->updated = row->created;
	sqlite3_stmt *s = stmt(st, ST_JOB_INSERT);
	sqlite3_bind_int64(s, 1, sql_id(row->scene_id));
	bind_text(s, 2, row->name);
	bind_text(s, 3, row->options_json);
	bind_text(s, 4, row->target_json);
	bind_text(s, 5, row->eps_log_json);
	bind_text(s, 6, row->stats_json);
	sqlite3_bind_int(s, 7, (int)row->state);
	sqlite3_bind_int64(s, 8, row->iterations);
	bind_text(s, 9, row->error);
	sqlite3_bind_double(s, 10, row->created);
	sqlite3_bind_double(s, 11, row->updated);
	int rc = sqlite3_step(s);
	sqlite3_reset(s);
	if ((rc & 0xff) == SQLITE_CONSTRAINT)
		return srv_fail(msg, msglen, "job: scene %llu not found",
		                (unsigned long long)row->scene_id);
	if (rc != SQLITE_DONE)
		return sql_fail(st, "job insert", msg, msglen);
	row->id = (uint64_t)sqlite3_last_insert_rowid(st->db);
	row->has_result = 0;
	return 0;
}

/* Bind the columns JOB_UPDATE and JOB_CHECKPOINT share (?1..?8). */
static void bind_job_update(sqlite3_stmt *s, const srv_job_row *row)
{
	sqlite3_bind_int64(s, 1, sql_id(row->id));
	bind_text(s, 2, row->target_json);
	bind_text(s, 3, row->eps_log_json);
	bind_text(s, 4, row->stats_json);
	sqlite3_bind_int(s, 5, (int)row->state);
	sqlite3_bind_int64(s, 6, row->iterations);
	bind_text(s, 7, row->error);
	sqlite3_bind_double(s, 8, row->updated > 0 ? row->updated : now_s());
}

int srv_store_job_update(srv_store *st, const srv_job_row *row, char *msg,
                         size_t msglen)
{
	if ((unsigned)row->state >= SRV_JOB_NSTATES)
		return srv_fail(msg, msglen, "job state %d is not a state",
		                (int)row->state);
	sqlite3_stmt *s = stmt(st, ST_JOB_UPDATE);
	bind_job_update(s, row);
	if (run(st, s, "job update", msg, msglen) < 0)
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
	sqlite3_stmt *s = stmt(st, ST_JOB_RESULT);
	sqlite3_bind_int64(s, 1, sql_id(id));
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
	return rc == SQLITE_ROW ? 1 : sql_fail(st, "job read", msg, msglen);
}

int srv_store_job_checkpoint(srv_store *st, const srv_job_row *row,
                             const void *sol, size_t len, char *msg,
                             size_t msglen)
{
	char dir[PATHLEN], tmp[PATHLEN], path[PATHLEN], old[PATHLEN];
	int has;
	int64_t gen;
	uint64_t oldlen;
	if ((unsigned)row->state >= SRV_JOB_NSTATES)
		return srv_fail(msg, msglen, "job state %d is not a state",
		                (int)row->state);
	if (job_result(st, row->id, &has, &gen, &oldlen, msg, msglen) <= 0)
		return -1;
	snprintf(dir, sizeof(dir), "%s/results", st->dir);
	result_path(st, row->id, gen + 1, path);
	if (tmp_write(dir, sol, len, tmp, msg, msglen) < 0 ||
	    tmp_commit(tmp, path, dir, msg, msglen) < 0)
		return -1;
	sqlite3_stmt *s = stmt(st, ST_JOB_CHECKPOINT);
	bind_job_update(s, row);
	sqlite3_bind_int64(s, 9, gen + 1);
	sqlite3_bind_int64(s, 10, (int64_t)len);
	if (run(st, s, "job checkpoint", msg, msglen) < 0) {
		unlink(path); /* the row still names the previous file */
		return -1;
	}
	/* The row now names generation gen + 1; the old file is garbage
	 * (if this unlink is lost, open() removes it). */
	result_path(st, row->id, gen, old);
	if (has)
		unlink(old);
	return 0;
}

int srv_store_job_result_read(srv_store *st, uint64_t id, unsigned char **bytes,
                              size_t *len, char *msg, size_t msglen)
{
	char path[PATHLEN];
	int has;
	int64_t gen;
	uint64_t size;
	if (job_result(st, id, &has, &gen, &size, msg, msglen) <= 0)
		return -1;
	if (!has)
		return srv_fail(msg, msglen, "job %llu has no checkpoint",
		                (unsigned long long)id);
	result_path(st, id, gen, path);
	return file_read(path, size, bytes, len, msg, msglen);
}

int srv_store_job_delete(srv_store *st, uint64_t id, char *msg, size_t msglen)
{
	char path[PATHLEN];
	int has;
	int64_t gen;
	uint64_t size;
	if (job_result(st, id, &has, &gen, &size, msg, msglen) <= 0)
		return -1;
	sqlite3_stmt *s = stmt(st, ST_JOB_DELETE);
	sqlite3_bind_int64(s, 1, sql_id(id));
	if (run(st, s, "job delete", msg, msglen) < 0)
		return -1;
	result_path(st, id, gen, path);
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
	col_copy(s, 2, r->name, sizeof(r->name));
	r->options_json = col_dup(s, 3);
	r->target_json = col_dup(s, 4);
	r->eps_log_json = col_dup(s, 5);
	r->stats_json = col_dup(s, 6);
	int state = sqlite3_column_int(s, 7);
	r->iterations = (uint32_t)sqlite3_column_int64(s, 8);
	r->has_result = sqlite3_column_int(s, 9) != 0;
	col_copy(s, 10, r->error, sizeof(r->error));
	r->created = sqlite3_column_double(s, 11);
	r->updated = sqlite3_column_double(s, 12);
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
	sqlite3_stmt *s = stmt(st, ST_JOB_LIST);
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
	return rc == SQLITE_DONE ? 0 : sql_fail(st, "job list", msg, msglen);
}

/* --------------------------------------------------------------- sensors */

int srv_store_sensor_add(srv_store *st, uint64_t job, const char *name,
                         const double pt[6], char *msg, size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_SENSOR_INSERT);
	sqlite3_bind_int64(s, 1, sql_id(job));
	bind_text(s, 2, name);
	for (int k = 0; k < 6; k++)
		sqlite3_bind_double(s, 3 + k, pt[k]);
	return run(st, s, "sensor insert", msg, msglen);
}

int srv_store_sensor_list(srv_store *st,
                          void (*fn)(void *ud, uint64_t job, const char *name,
                                     const double pt[6]),
                          void *ud, char *msg, size_t msglen)
{
	sqlite3_stmt *s = stmt(st, ST_SENSOR_LIST);
	int rc;
	while ((rc = sqlite3_step(s)) == SQLITE_ROW) {
		char name[256];
		double pt[6];
		col_copy(s, 1, name, sizeof(name));
		for (int k = 0; k < 6; k++)
			pt[k] = sqlite3_column_double(s, 2 + k);
		fn(ud, (uint64_t)sqlite3_column_int64(s, 0), name, pt);
	}
	sqlite3_reset(s);
	return rc == SQLITE_DONE ? 0 : sql_fail(st, "sensor list", msg, msglen);
}
