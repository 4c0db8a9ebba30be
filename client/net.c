/*
 * net.c -- the client's connection to luxradd: blocking sockets (TCP via
 * getaddrinfo, or a Unix socket), the hello handshake with the optional
 * token, and request/reply exchanges over the protocol library's frame
 * codec.
 *
 * DESIGN
 * One receive buffer per connection.  A decoded frame's payload points
 * into it, so the bytes of the last frame stay put until the next read
 * ("pending"), which is when they are consumed; the buffer is compacted
 * only when room is needed.  Requests carry increasing integer ids and a
 * reply must echo its request's id: the daemon answers in order, so any
 * other id is a protocol error, not something to wait out.  Events that
 * arrive while a reply is awaited are handed to the caller's callback.
 * Payloads are sent straight from the caller's memory after the header
 * line (rp_frame_encode_header): a 1 GiB scene is never copied.
 */
#include <errno.h>
#include <netdb.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/types.h>
#include <sys/un.h>
#include <unistd.h>

#include "client.h"

static int conn_error(lx_conn *c, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));

/* Print "luxrad: <where>: <message>" and return LX_EXIT_CONN. */
static int conn_error(lx_conn *c, const char *fmt, ...)
{
	va_list ap;

	fprintf(stderr, "luxrad: %s: ", c->where);
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fputc('\n', stderr);
	return LX_EXIT_CONN;
}

/* ------------------------------------------------------------- connect */

static int connect_unix(lx_conn *c, const rp_addr *a)
{
	struct sockaddr_un sa;
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);

	if (fd < 0)
		return conn_error(c, "socket: %s", strerror(errno));
	memset(&sa, 0, sizeof sa);
	sa.sun_family = AF_UNIX;
	memcpy(sa.sun_path, a->path, strlen(a->path) + 1);
	if (connect(fd, (struct sockaddr *)&sa, sizeof sa) != 0) {
		int e = errno;
		close(fd);
		return conn_error(c,
		                  "cannot connect: %s (is luxradd running? "
		                  "see --connect)",
		                  strerror(e));
	}
	c->fd = fd;
	return LX_EXIT_OK;
}

static int connect_tcp(lx_conn *c, const rp_addr *a)
{
	struct addrinfo hints, *res = NULL, *ai;
	char port[8];
	int rc, e = 0;

	memset(&hints, 0, sizeof hints);
	hints.ai_socktype = SOCK_STREAM;
	snprintf(port, sizeof port, "%u", (unsigned)a->port);
	rc = getaddrinfo(a->host, port, &hints, &res);
	if (rc != 0)
		return conn_error(c, "cannot resolve '%s': %s", a->host,
		                  gai_strerror(rc));
	for (ai = res; ai; ai = ai->ai_next) {
		int fd = socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC,
		                ai->ai_protocol);
		if (fd < 0) {
			e = errno;
			continue;
		}
		if (connect(fd, ai->ai_addr, ai->ai_addrlen) == 0) {
			c->fd = fd;
			break;
		}
		e = errno;
		close(fd);
	}
	freeaddrinfo(res);
	if (c->fd < 0)
		return conn_error(c,
		                  "cannot connect: %s (is luxradd running? "
		                  "see --connect)",
		                  strerror(e));
	return LX_EXIT_OK;
}

/*
 * TLS over the connected socket (a tls: address): TLS 1.2 at least, the
 * daemon's certificate verified against --tls-ca, $LUXRAD_TLS_CA or the
 * system's CAs, and against the address's host name or IP literal.
 */
static int start_tls(lx_ctx *cx, lx_conn *c, const rp_addr *a)
{
	const char *ca = cx->val[LX_OPT_TLS_CA];
	if (!ca || !*ca)
		ca = getenv("LUXRAD_TLS_CA");
	SSL_CTX *ctx = SSL_CTX_new(TLS_client_method());
	SSL *ssl = NULL;
	char why[256] = "";
	int ok = ctx && SSL_CTX_set_min_proto_version(ctx, TLS1_2_VERSION);
	if (ok)
		ok = ca && *ca ? SSL_CTX_load_verify_locations(ctx, ca, NULL)
		               : SSL_CTX_set_default_verify_paths(ctx);
	if (ok) {
		SSL_CTX_set_verify(ctx, SSL_VERIFY_PEER, NULL);
		ssl = SSL_new(ctx);
		ok = ssl && SSL_set_fd(ssl, c->fd) == 1 &&
		     SSL_set1_host(ssl, a->host) == 1 &&
		     SSL_set_tlsext_host_name(ssl, a->host) == 1 &&
		     SSL_connect(ssl) == 1;
	}
	if (!ok) {
		unsigned long e = ERR_get_error();
		long v = ssl ? SSL_get_verify_result(ssl) : X509_V_OK;
		if (v != X509_V_OK)
			snprintf(why, sizeof why, "%s",
			         X509_verify_cert_error_string(v));
		else if (e)
			ERR_error_string_n(e, why, sizeof why);
		SSL_free(ssl);
		SSL_CTX_free(ctx);
		return conn_error(c, "TLS: %s%s%s%s", why[0] ? why : "failed",
		                  ca && *ca ? " (CA file " : "",
		                  ca && *ca ? ca : "", ca && *ca ? ")" : "");
	}
	c->ssl = ssl;
	c->ssl_ctx = ctx;
	return LX_EXIT_OK;
}

/*
 * The token: --token-file, $LUXRAD_TOKEN_FILE, then $LUXRAD_TOKEN.  A
 * file's leading and trailing whitespace is removed, as the daemon does
 * with its own.  Returns 0 (*tok malloc'ed or NULL) or an exit code.
 */
static int read_token(lx_ctx *cx, char **tok)
{
	const char *file = cx->val[LX_OPT_TOKEN_FILE];
	char buf[4097];
	size_t n, a = 0;
	FILE *f;

	*tok = NULL;
	if (!file)
		file = getenv(RP_ENV_TOKEN_FILE);
	if (!file || !*file) {
		const char *t = getenv(RP_ENV_TOKEN);
		if (t && *t && !(*tok = strdup(t)))
			return LX_EXIT_CONN;
		return 0;
	}
	if (!(f = fopen(file, "r"))) {
		fprintf(stderr, "luxrad: cannot read token file '%s': %s\n",
		        file, strerror(errno));
		return LX_EXIT_USAGE;
	}
	n = fread(buf, 1, sizeof buf - 1, f);
	fclose(f);
	if (n == sizeof buf - 1) {
		fprintf(stderr,
		        "luxrad: token file '%s' is longer than 4096 "
		        "bytes\n",
		        file);
		return LX_EXIT_USAGE;
	}
	while (a < n && strchr(" \t\r\n", buf[a]))
		a++;
	while (n > a && strchr(" \t\r\n", buf[n - 1]))
		n--;
	if (n == a) {
		fprintf(stderr, "luxrad: token file '%s' is empty\n", file);
		return LX_EXIT_USAGE;
	}
	buf[n] = '\0';
	*tok = strdup(buf + a);
	memset(buf, 0, sizeof buf);
	return *tok ? 0 : LX_EXIT_CONN;
}

static int say_hello(lx_ctx *cx, char *token)
{
	json_t *req = rp_request(RP_CMD_HELLO, -1), *reply = NULL;
	int rc;

	json_object_set_new(req, "version", json_integer(RP_VERSION));
	json_object_set_new(req, "client", json_string("luxrad/" LX_VERSION));
	if (token)
		json_object_set_new(req, "token", json_string(token));
	rc = lx_request(cx, req, NULL, 0, &reply, NULL, NULL, NULL, NULL);
	json_decref(req);
	const char *code = json_string_value(
	        json_object_get(json_object_get(reply, "error"), "code"));
	if (rc == LX_EXIT_DAEMON && !token && code &&
	    !strcmp(code, "auth_failed"))
		fprintf(stderr, "luxrad: this daemon needs a token: give "
		                "--token-file FILE or set LUXRAD_TOKEN_FILE / "
		                "LUXRAD_TOKEN\n");
	if (rc == LX_EXIT_OK)
		cx->conn.hello = reply;
	else
		json_decref(reply);
	return rc;
}

int lx_open(lx_ctx *cx)
{
	const char *text = cx->val[LX_OPT_CONNECT], *from = "--connect";
	lx_conn *c = &cx->conn;
	rp_addr a;
	rp_error err;
	char *token = NULL;
	int rc;

	if (cx->connected)
		return LX_EXIT_OK;
	if (!text) {
		text = getenv(RP_ENV_CONNECT);
		from = "$" RP_ENV_CONNECT;
	}
	if (!text || !*text) {
		text = LX_DEFAULT_CONNECT;
		from = "the default";
	}
	if (rp_addr_parse(text, &a, &err) != 0)
		return lx_usage_error(cx, "bad address (from %s): %s", from,
		                      err.msg);
	memset(c, 0, sizeof *c);
	c->fd = -1;
	c->next_id = 1;
	rp_limits_default(&c->lim);
	c->lim.max_header_bytes = LX_MAX_REPLY_HEADER;
	snprintf(c->where, sizeof c->where, "%s %.250s",
	         a.kind == RP_ADDR_UNIX ? "unix"
	         : a.tls                ? "tls"
	                                : "tcp",
	         a.kind == RP_ADDR_UNIX ? a.path : text);
	if ((rc = read_token(cx, &token)) != 0)
		return rc;
	rc = a.kind == RP_ADDR_UNIX ? connect_unix(c, &a) : connect_tcp(c, &a);
	if (rc == LX_EXIT_OK && a.tls)
		rc = start_tls(cx, c, &a);
	if (rc == LX_EXIT_OK) {
		cx->connected = 1;
		rc = say_hello(cx, token);
	}
	if (token) {
		memset(token, 0, strlen(token));
		free(token);
	}
	return rc;
}

void lx_close(lx_ctx *cx)
{
	lx_conn *c = &cx->conn;

	if (!cx->connected)
		return;
	if (c->ssl) {
		SSL_shutdown(c->ssl);
		SSL_free(c->ssl);
		SSL_CTX_free(c->ssl_ctx);
		c->ssl = c->ssl_ctx = NULL;
	}
	if (c->fd >= 0)
		close(c->fd);
	c->fd = -1;
	free(c->buf);
	c->buf = NULL;
	json_decref(c->hello);
	c->hello = NULL;
	cx->connected = 0;
}

/* -------------------------------------------------------------- frames */

static int send_all(lx_conn *c, const void *data, size_t len)
{
	const unsigned char *p = data;

	while (len > 0) {
		ssize_t n;
		if (c->ssl) {
			size_t put = 0;
			n = SSL_write_ex(c->ssl, p, len, &put) == 1
			            ? (ssize_t)put
			            : -1;
		} else {
			n = send(c->fd, p, len, MSG_NOSIGNAL);
		}
		if (n < 0 && errno == EINTR)
			continue;
		if (n <= 0)
			return -1;
		p += n;
		len -= (size_t)n;
	}
	return 0;
}

/* Make room for at least one more read in the receive buffer. */
static int make_room(lx_conn *c)
{
	if (c->off > 0) {
		memmove(c->buf, c->buf + c->off, c->len - c->off);
		c->len -= c->off;
		c->off = 0;
	}
	if (c->len == c->cap) {
		size_t ncap = c->cap ? 2 * c->cap : 65536;
		unsigned char *nb = realloc(c->buf, ncap);
		if (!nb)
			return conn_error(c, "out of memory for %zu bytes",
			                  ncap);
		c->buf = nb;
		c->cap = ncap;
	}
	return 0;
}

/* Block until the next whole frame; its bytes stay until the next call. */
static int read_frame(lx_conn *c, rp_frame *f)
{
	c->off += c->pending;
	c->pending = 0;
	for (;;) {
		size_t used;
		rp_error err;
		rp_decode d = rp_frame_decode(&c->lim, c->buf + c->off,
		                              c->len - c->off, f, &used, &err);
		if (d == RP_DECODE_FRAME) {
			c->pending = used;
			return 0;
		}
		if (d == RP_DECODE_ERROR)
			return conn_error(c,
			                  "the daemon sent a malformed frame "
			                  "(%s): %s",
			                  rp_err_name(err.code), err.msg);
		if (make_room(c) != 0)
			return LX_EXIT_CONN;
		ssize_t n;
		if (c->ssl) {
			size_t got = 0;
			int r = SSL_read_ex(c->ssl, c->buf + c->len,
			                    c->cap - c->len, &got);
			int e = r == 1 ? SSL_ERROR_NONE
			               : SSL_get_error(c->ssl, r);
			n = r == 1 ? (ssize_t)got
			    : e == SSL_ERROR_ZERO_RETURN ||
			                    (e == SSL_ERROR_SYSCALL &&
			                     errno == 0)
			            ? 0
			            : -1;
			if (n < 0 && e != SSL_ERROR_SYSCALL)
				errno = EPROTO;
		} else {
			n = recv(c->fd, c->buf + c->len, c->cap - c->len, 0);
		}
		if (n < 0 && errno == EINTR)
			continue;
		if (n == 0)
			return conn_error(c, "connection closed by the daemon");
		if (n < 0)
			return conn_error(c, "connection lost: %s",
			                  strerror(errno));
		c->len += (size_t)n;
	}
}

/* Report an error reply; returns LX_EXIT_DAEMON. */
static int report_error(lx_ctx *cx, json_t *reply)
{
	json_t *e = json_object_get(reply, "error");
	const char *code = json_string_value(json_object_get(e, "code"));
	const char *msg = json_string_value(json_object_get(e, "message"));

	fprintf(stderr, "luxrad: %s: %s\n", code ? code : "internal",
	        msg ? msg : "(no message)");
	if (cx->json)
		lx_print_json(reply);
	return LX_EXIT_DAEMON;
}

/*
 * The payload could not be sent: the daemon may have refused the header
 * (too_large) and closed.  Read what it said before giving up.
 */
static int send_failed(lx_ctx *cx, json_t **reply)
{
	lx_conn *c = &cx->conn;
	int e = errno;
	rp_frame f;

	shutdown(c->fd, SHUT_WR);
	while (read_frame(c, &f) == 0) {
		if (json_is_false(json_object_get(f.header, "ok"))) {
			*reply = f.header;
			return report_error(cx, f.header);
		}
		json_decref(f.header);
	}
	return conn_error(c, "connection lost while sending: %s", strerror(e));
}

int lx_request(lx_ctx *cx, json_t *req, const void *payload, size_t plen,
               json_t **reply, const unsigned char **rpayload, size_t *rlen,
               lx_event_fn on_event, void *ud)
{
	lx_conn *c = &cx->conn;
	long long id = c->next_id++;
	unsigned char *line;
	size_t line_len;
	int rc;

	*reply = NULL;
	json_object_set_new(req, "id", json_integer(id));
	rc = payload ? rp_frame_encode_header(req, plen, &line, &line_len)
	             : rp_frame_encode(req, NULL, 0, &line, &line_len);
	if (rc != 0)
		return conn_error(c, "out of memory encoding a request");
	rc = send_all(c, line, line_len);
	free(line);
	if (rc != 0 || (payload && send_all(c, payload, plen) != 0))
		return send_failed(cx, reply);
	for (;;) {
		rp_frame f;
		rp_error err;
		if ((rc = read_frame(c, &f)) != 0)
			return rc;
		json_t *h = f.header, *rid = json_object_get(h, "id");
		if (json_object_get(h, "event") && !json_object_get(h, "ok")) {
			if (on_event)
				on_event(ud, h);
			json_decref(h);
			continue;
		}
		*reply = h;
		if (!rid && json_is_false(json_object_get(h, "ok")))
			return report_error(cx,
			                    h); /* unsolicited, then closed */
		if (!json_is_integer(rid) || json_integer_value(rid) != id)
			return conn_error(c, "reply for another request "
			                     "(protocol error)");
		if (rpayload) {
			*rpayload = f.payload;
			*rlen = f.payload_len;
		}
		switch (rp_reply_status(h, &err)) {
		case RP_ERR_OK:
			return LX_EXIT_OK;
		case RP_ERR_BAD_FRAME:
			return conn_error(c, "malformed reply: %s", err.msg);
		default:
			return report_error(cx, h);
		}
	}
}

int lx_call(lx_ctx *cx, json_t *req, json_t **reply)
{
	int rc = lx_request(cx, req, NULL, 0, reply, NULL, NULL, NULL, NULL);
	json_decref(req);
	return rc;
}

int lx_next_event(lx_ctx *cx, json_t **event)
{
	rp_frame f;
	int rc;

	*event = NULL;
	if ((rc = read_frame(&cx->conn, &f)) != 0)
		return rc;
	if (json_object_get(f.header, "event")) {
		*event = f.header;
		return LX_EXIT_OK;
	}
	if (json_is_false(json_object_get(f.header, "ok")) &&
	    !json_object_get(f.header, "id")) {
		rc = report_error(cx, f.header);
		json_decref(f.header);
		return rc;
	}
	json_decref(f.header);
	return conn_error(&cx->conn, "unexpected reply while waiting for "
	                             "events (protocol error)");
}
