/*
 * users.c -- who a connection is: the users file, tokens checked against
 * it, and what a user may see.
 *
 * The users file (users_file) holds one user per line:
 *
 *     NAME ROLE sha256:HEX
 *
 * NAME is 1..63 of [A-Za-z0-9._-], ROLE one of read, submit, admin, and
 * HEX the SHA-256 of the token, so the file holds no secret: a token is
 * only ever shown once, by `luxradd user-add`.  Blank lines and lines
 * starting with '#' are ignored; a malformed line or a name given twice
 * refuses the whole file (at start, exit 2; on SIGHUP the old users
 * stay).  Tokens are 256 random bits, so a plain hash is enough: a slow
 * password hash protects guessable secrets, which these are not.  A token
 * is compared with every user's hash in constant time, without stopping
 * at a match.
 *
 * Roles: read sees every scene and job and may query, export and watch
 * them (dashboards, like Modbus and /metrics, which are read-only too);
 * submit sees and changes only what it uploaded and created; admin sees
 * and changes everything, and may shut the daemon down.  A connection
 * that needs no token (loopback or the Unix socket without
 * require_token) and sends none is the local admin, whose name is "";
 * so is the shared token of token_file.  Objects stored before users
 * existed belong to the local admin.
 */
#include <errno.h>
#include <fcntl.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/random.h>
#include <sys/stat.h>
#include <unistd.h>

#include "cmd.h"
#include "log.h"

#define HASH_PREFIX "sha256:"

static int sha256(const void *data, size_t len, unsigned char out[32])
{
	unsigned int n = 0;
	return EVP_Digest(data, len, out, &n, EVP_sha256(), NULL) == 1 &&
	                       n == 32
	               ? 0
	               : -1;
}

static int name_ok(const char *s)
{
	size_t n = strlen(s);
	return n >= 1 && n < CMD_USER_NAME_MAX &&
	       strspn(s, "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
	                 "0123456789._-") == n;
}

static int unhex(const char *s, unsigned char out[32])
{
	if (strlen(s) != 64)
		return -1;
	for (int i = 0; i < 32; i++) {
		unsigned v = 0;
		for (int k = 0; k < 2; k++) {
			char c = s[2 * i + k];
			v <<= 4;
			if (c >= '0' && c <= '9')
				v |= (unsigned)(c - '0');
			else if (c >= 'a' && c <= 'f')
				v |= (unsigned)(c - 'a' + 10);
			else
				return -1;
		}
		out[i] = (unsigned char)v;
	}
	return 0;
}

/* Parse the users file into *out (*n users); -1 with msg. */
static int parse_users(const char *path, cmd_user **out, int *n, char *msg,
                       size_t msglen)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		snprintf(msg, msglen, "users file '%s': %s", path,
		         strerror(errno));
		return -1;
	}
	cmd_user *u = NULL;
	int nu = 0, cap = 0, lineno = 0, rc = 0;
	char line[512];
	while (rc == 0 && fgets(line, sizeof(line), f)) {
		lineno++;
		char name[128], role[32], hash[128], extra[8];
		char *p = line + strspn(line, " \t");
		if (*p == '#' || *p == '\n' || *p == '\0')
			continue;
		int k = sscanf(p, "%127s %31s %127s %7s", name, role, hash,
		               extra);
		int r = k == 3 ? rp_role_parse(role) : -1;
		if (k != 3 || !name_ok(name) || r < 0 ||
		    strncmp(hash, HASH_PREFIX, strlen(HASH_PREFIX)) != 0) {
			snprintf(msg, msglen,
			         "users file '%s':%d: want NAME ROLE "
			         "sha256:HEX (NAME of [A-Za-z0-9._-], ROLE "
			         "read, submit or admin)",
			         path, lineno);
			rc = -1;
			break;
		}
		for (int i = 0; i < nu; i++)
			if (strcmp(u[i].name, name) == 0) {
				snprintf(msg, msglen,
				         "users file '%s':%d: user '%s' is "
				         "given twice",
				         path, lineno, name);
				rc = -1;
			}
		if (rc)
			break;
		if (nu == cap) {
			cap = cap ? 2 * cap : 8;
			cmd_user *nb = realloc(u, (size_t)cap * sizeof(*u));
			if (!nb) {
				snprintf(msg, msglen, "users: out of memory");
				rc = -1;
				break;
			}
			u = nb;
		}
		snprintf(u[nu].name, sizeof(u[nu].name), "%s", name);
		u[nu].role = (rp_role)r;
		if (unhex(hash + strlen(HASH_PREFIX), u[nu].hash) != 0) {
			snprintf(msg, msglen,
			         "users file '%s':%d: the hash is not 64 "
			         "lower-case hex digits",
			         path, lineno);
			rc = -1;
			break;
		}
		nu++;
	}
	if (rc == 0 && ferror(f)) {
		snprintf(msg, msglen, "users file '%s': read error", path);
		rc = -1;
	}
	fclose(f);
	if (rc) {
		free(u);
		return -1;
	}
	*out = u;
	*n = nu;
	return 0;
}

int cmd_users_load(cmd_server *d, const srv_config *cfg, char *msg,
                   size_t msglen)
{
	cmd_user *u = NULL;
	int n = 0;
	if (cfg->users_file[0] &&
	    parse_users(cfg->users_file, &u, &n, msg, msglen) != 0)
		return -1;
	free(d->users);
	d->users = u;
	d->nusers = n;
	d->users_on = cfg->users_file[0] != '\0';
	return 0;
}

const cmd_user *cmd_users_check(const cmd_server *d, const char *token)
{
	unsigned char h[32];
	const cmd_user *found = NULL;
	if (sha256(token, strlen(token), h) != 0)
		return NULL;
	for (int i = 0; i < d->nusers; i++)
		if (CRYPTO_memcmp(h, d->users[i].hash, 32) == 0)
			found = &d->users[i];
	return found;
}

int cmd_visible(const cmd_conn *c, const char *owner)
{
	return c->role != RP_ROLE_SUBMIT || strcmp(owner, c->user) == 0;
}

/* ------------------------------------------------------ luxradd user-add */

/* Base64url without padding (RFC 4648 §5), by OpenSSL's base64. */
static void base64url(const unsigned char *in, size_t n, char *out)
{
	int len = EVP_EncodeBlock((unsigned char *)out, in, (int)n);
	while (len > 0 && out[len - 1] == '=')
		len--;
	out[len] = '\0';
	for (char *p = out; *p; p++)
		*p = *p == '+' ? '-' : *p == '/' ? '_' : *p;
}

int cmd_user_add(const char *path, const char *name, const char *role,
                 FILE *out, char *msg, size_t msglen)
{
	if (!name_ok(name)) {
		snprintf(msg, msglen,
		         "user name '%s': 1 to %d of A-Z a-z 0-9 . _ -", name,
		         CMD_USER_NAME_MAX - 1);
		return -1;
	}
	if (rp_role_parse(role) < 0) {
		snprintf(msg, msglen, "role '%s': read, submit or admin", role);
		return -1;
	}
	cmd_user *u = NULL;
	int n = 0;
	if (access(path, F_OK) == 0 &&
	    parse_users(path, &u, &n, msg, msglen) != 0)
		return -1;
	for (int i = 0; i < n; i++)
		if (strcmp(u[i].name, name) == 0) {
			free(u);
			snprintf(msg, msglen,
			         "%s already has a user '%s': remove its line "
			         "first to give it a new token",
			         path, name);
			return -1;
		}
	free(u);
	unsigned char raw[32], h[32];
	if (getrandom(raw, sizeof(raw), 0) != (ssize_t)sizeof(raw)) {
		snprintf(msg, msglen, "getrandom: %s", strerror(errno));
		return -1;
	}
	char token[64] = "lxr_";
	base64url(raw, sizeof(raw), token + 4);
	memset(raw, 0, sizeof(raw));
	if (sha256(token, strlen(token), h) != 0) {
		snprintf(msg, msglen, "sha256 failed");
		return -1;
	}
	char line[256];
	int k = snprintf(line, sizeof(line), "%s %s " HASH_PREFIX, name, role);
	for (int i = 0; i < 32; i++)
		k += snprintf(line + k, sizeof(line) - (size_t)k, "%02x", h[i]);
	line[k++] = '\n';
	int fd = open(path, O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0600);
	if (fd < 0 || write(fd, line, (size_t)k) != k || fsync(fd) != 0) {
		snprintf(msg, msglen, "%s: %s", path, strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	close(fd);
	fprintf(out, "%s\n", token);
	memset(token, 0, sizeof(token));
	return 0;
}
