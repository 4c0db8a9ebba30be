/*
 * store_schema.c -- the store's database: the connection and its settings
 * (WAL, synchronous=FULL, foreign keys), an integrity check before any
 * row is trusted, and the schema with its versions.
 *
 * Schema versions: PRAGMA user_version (0 = empty database, 1 = scenes
 * and jobs, 2 = 1 plus the sensors added over the protocol, 3 = this
 * layout: 2 plus each scene's and job's owner).
 * An older database is brought up to date in one transaction at open; a
 * newer one is refused rather than misread.
 */
#include "store_int.h"
#include "textutil.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SCHEMA_VERSION 3

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

/* 2 -> 3: scenes and jobs belong to the user who made them ("" = the
 * local admin, which every row written before users existed is). */
static const char schema_v3[] =
        "ALTER TABLE scenes ADD COLUMN owner TEXT NOT NULL DEFAULT '';"
        "ALTER TABLE jobs ADD COLUMN owner TEXT NOT NULL DEFAULT '';"
        "PRAGMA user_version = 3;";

/* One-value PRAGMA; its text result copied into out. */
static int pragma(srv_store *st, const char *sql, char *out, size_t outlen,
                  char *msg, size_t msglen)
{
	sqlite3_stmt *s;
	if (sqlite3_prepare_v2(st->db, sql, -1, &s, NULL) != SQLITE_OK)
		return store_sql_fail(st, sql, msg, msglen);
	int rc = sqlite3_step(s);
	if (rc == SQLITE_ROW && out)
		store_col_copy(s, 0, out, outlen);
	else if (out)
		out[0] = '\0';
	sqlite3_finalize(s);
	if (rc != SQLITE_ROW && rc != SQLITE_DONE)
		return store_sql_fail(st, sql, msg, msglen);
	return 0;
}

/* The connection's settings, then PRAGMA quick_check. */
static int configure(srv_store *st, char *msg, size_t msglen)
{
	char v[256];
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
	return 0;
}

/* Bring the schema from version ver to SCHEMA_VERSION in one transaction. */
static int upgrade(srv_store *st, long ver, char *msg, size_t msglen)
{
	char *err = NULL;
	if (sqlite3_exec(st->db, "BEGIN", NULL, NULL, NULL) != SQLITE_OK ||
	    (ver < 1 &&
	     sqlite3_exec(st->db, schema_v1, NULL, NULL, &err) != SQLITE_OK) ||
	    (ver < 2 &&
	     sqlite3_exec(st->db, schema_v2, NULL, NULL, &err) != SQLITE_OK) ||
	    sqlite3_exec(st->db, schema_v3, NULL, NULL, &err) != SQLITE_OK ||
	    sqlite3_exec(st->db, "COMMIT", NULL, NULL, NULL) != SQLITE_OK) {
		srv_fail(msg, msglen,
		         "%s: cannot bring the schema from version %ld to %d: "
		         "%s",
		         st->db_path, ver, SCHEMA_VERSION,
		         err ? err : sqlite3_errmsg(st->db));
		sqlite3_free(err);
		sqlite3_exec(st->db, "ROLLBACK", NULL, NULL, NULL);
		return -1;
	}
	if (ver > 0)
		store_note_repair(st, "schema upgraded from version %ld to %d",
		                  ver, SCHEMA_VERSION);
	return 0;
}

int store_schema_open(srv_store *st, char *msg, size_t msglen)
{
	char v[256];
	snprintf(st->db_path, sizeof(st->db_path), "%s/luxradd.db", st->dir);
	if (sqlite3_open_v2(st->db_path, &st->db,
	                    SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE,
	                    NULL) != SQLITE_OK)
		return store_sql_fail(st, "cannot open", msg, msglen);
	sqlite3_extended_result_codes(st->db, 1);
	if (configure(st, msg, msglen) < 0 ||
	    pragma(st, "PRAGMA user_version", v, sizeof(v), msg, msglen) < 0)
		return -1;
	long ver = strtol(v, NULL, 10);
	if (ver > SCHEMA_VERSION)
		return srv_fail(msg, msglen,
		                "%s: schema version %ld is newer than this "
		                "luxradd's (%d)",
		                st->db_path, ver, SCHEMA_VERSION);
	if (ver < SCHEMA_VERSION && upgrade(st, ver, msg, msglen) < 0)
		return -1;
	return store_sql_prepare(st, msg, msglen);
}

const char *srv_store_repairs(const srv_store *st)
{
	return st->repairs;
}

void store_note_repair(srv_store *st, const char *fmt, ...)
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
