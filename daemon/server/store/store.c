/*
 * store.c -- luxradd's durable state: a SQLite database of scenes and jobs
 * beside the files that hold scene bytes and solution checkpoints.  This
 * file holds the data directory itself: opening it (directories, the lock,
 * the database, the repairs), closing it, and where each file lives.
 *
 * The layout, the crash-safety invariant and the list of the store's
 * files are in store_int.h's DESIGN note.
 */
#include "store_int.h"
#include "textutil.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <unistd.h>

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
	if (store_make_dirs(st->dir, msg, msglen) < 0 ||
	    take_lock(st, msg, msglen))
		goto bad;
	snprintf(sub, sizeof(sub), "%s/scenes", st->dir);
	if (store_make_dirs(sub, msg, msglen) < 0)
		goto bad;
	snprintf(sub, sizeof(sub), "%s/results", st->dir);
	if (store_make_dirs(sub, msg, msglen) < 0 ||
	    store_schema_open(st, msg, msglen) < 0 ||
	    store_repair(st, msg, msglen) < 0)
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
