/*
 * store_sql.c -- the store's statements: every one is listed once in
 * store_int.h's STMTS table, prepared once at open (persistent), and run
 * through the helpers below, which reset a statement before it is bound
 * and after it ran so that none holds a read transaction open between
 * calls.  Errors name the database and the operation.
 */
#include "store_int.h"
#include "textutil.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const stmt_sql[] = {
#define STMT_SQL_(name, sql) sql,
        STMTS(STMT_SQL_)
#undef STMT_SQL_
};

int store_sql_prepare(srv_store *st, char *msg, size_t msglen)
{
	for (int i = 0; i < ST_COUNT; i++)
		if (sqlite3_prepare_v3(st->db, stmt_sql[i], -1,
		                       SQLITE_PREPARE_PERSISTENT, &st->st[i],
		                       NULL) != SQLITE_OK)
			return store_sql_fail(st, stmt_sql[i], msg, msglen);
	return 0;
}

int store_sql_fail(srv_store *st, const char *what, char *msg, size_t msglen)
{
	srv_fail(msg, msglen, "%s: %s: %s", st->db_path, what,
	         sqlite3_errmsg(st->db));
	return -1;
}

sqlite3_stmt *store_stmt(srv_store *st, int i)
{
	sqlite3_reset(st->st[i]);
	sqlite3_clear_bindings(st->st[i]);
	return st->st[i];
}

int store_run(srv_store *st, sqlite3_stmt *s, const char *what, char *msg,
              size_t msglen)
{
	int rc = sqlite3_step(s);
	sqlite3_reset(s);
	if (rc != SQLITE_DONE)
		return store_sql_fail(st, what, msg, msglen);
	return 0;
}

int store_begin(srv_store *st, char *msg, size_t msglen)
{
	return store_run(st, store_stmt(st, ST_BEGIN), "begin", msg, msglen);
}

int store_commit(srv_store *st, char *msg, size_t msglen)
{
	if (store_run(st, store_stmt(st, ST_COMMIT), "commit", msg, msglen) ==
	    0)
		return 0;
	sqlite3_step(store_stmt(st, ST_ROLLBACK));
	sqlite3_reset(st->st[ST_ROLLBACK]);
	return -1;
}

void store_rollback(srv_store *st)
{
	if (!sqlite3_get_autocommit(st->db)) {
		sqlite3_step(store_stmt(st, ST_ROLLBACK));
		sqlite3_reset(st->st[ST_ROLLBACK]);
	}
}

void store_bind_text(sqlite3_stmt *s, int i, const char *v)
{
	sqlite3_bind_text(s, i, v ? v : "", -1, SQLITE_TRANSIENT);
}

char *store_col_dup(sqlite3_stmt *s, int i)
{
	const char *t = (const char *)sqlite3_column_text(s, i);
	return strdup(t ? t : "");
}

void store_col_copy(sqlite3_stmt *s, int i, char *dst, size_t size)
{
	const char *t = (const char *)sqlite3_column_text(s, i);
	snprintf(dst, size, "%s", t ? t : "");
}

int64_t store_sql_id(uint64_t id)
{
	return id > INT64_MAX ? -1 : (int64_t)id;
}
