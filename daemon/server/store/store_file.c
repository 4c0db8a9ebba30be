/*
 * store_file.c -- the store's files on disk: directories created 0700,
 * files written atomically, and whole files read back against the size
 * their row recorded.  Nothing here knows about SQLite or rows.
 *
 * An atomic write is two steps so that the caller can commit its row in
 * between or after (store_int.h's invariant): store_tmp_write leaves a
 * complete, fsync'ed temporary in the destination's directory, and
 * store_tmp_commit renames it into place and fsyncs the directory so the
 * rename survives a crash.  The temporaries end in ".tmp", which the
 * sweep at open removes (store_repair.c).
 */
#include "store_int.h"
#include "textutil.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int store_make_dirs(const char *path, char *msg, size_t msglen)
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

int store_tmp_write(const char *dir, const void *buf, size_t len, char *tmp,
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

int store_tmp_commit(const char *tmp, const char *path, const char *dir,
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

int store_file_read(const char *path, uint64_t expect, unsigned char **out,
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

int store_file_ok(const char *path, uint64_t len)
{
	struct stat sb;
	return stat(path, &sb) == 0 && S_ISREG(sb.st_mode) &&
	       (uint64_t)sb.st_size == len;
}

void store_scene_path(const srv_store *st, uint64_t id, char *buf)
{
	snprintf(buf, PATHLEN, "%s/scenes/%llu.bin", st->dir,
	         (unsigned long long)id);
}

void store_result_path(const srv_store *st, uint64_t id, int64_t gen, char *buf)
{
	snprintf(buf, PATHLEN, "%s/results/%llu-%lld.sol", st->dir,
	         (unsigned long long)id, (long long)gen);
}
