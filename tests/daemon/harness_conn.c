/*
 * harness_conn.c -- client connections to luxradd: TCP and Unix sockets,
 * frames encoded and decoded by the protocol library, every read and write
 * under a deadline (poll), requests matched to their replies by id with
 * events queued aside, and a minimal HTTP GET for /metrics.
 */
#include "harness.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "rp.h"

/* ----------------------------------------------------------- connections */

static dm_conn *conn_new(int fd, const char *what)
{
	dm_conn *c = calloc(1, sizeof(*c));
	if (!c)
		dm_fail("out of memory");
	c->fd = fd;
	c->events = json_array();
	c->replies = json_array();
	c->next_id = 1;
	snprintf(c->what, sizeof(c->what), "%s", what);
	int fl = fcntl(fd, F_GETFL);
	fcntl(fd, F_SETFL, fl | O_NONBLOCK);
	dm_conn_register(c);
	return c;
}

int dm_tcp_socket(const char *host, int port, int rcvbuf, const char *src,
                  char *why, size_t len)
{
	int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0) {
		snprintf(why, len, "socket: %s", strerror(errno));
		return -1;
	}
	if (rcvbuf > 0)
		setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
	struct sockaddr_in me = {.sin_family = AF_INET};
	struct sockaddr_in sa = {.sin_family = AF_INET,
	                         .sin_port = htons((uint16_t)port)};
	if (src && (inet_pton(AF_INET, src, &me.sin_addr) != 1 ||
	            bind(fd, (struct sockaddr *)&me, sizeof(me)) != 0))
		snprintf(why, len, "bind to %s: %s", src, strerror(errno));
	else if (inet_pton(AF_INET, host, &sa.sin_addr) != 1)
		snprintf(why, len, "bad daemon address %s", host);
	else if (connect(fd, (struct sockaddr *)&sa, sizeof(sa)) != 0)
		snprintf(why, len, "connect %s:%d: %s", host, port,
		         strerror(errno));
	else
		return fd;
	close(fd);
	return -1;
}

static dm_conn *connect_tcp(const char *host, int port, int rcvbuf,
                            const char *src)
{
	char why[512];
	int fd = dm_tcp_socket(host, port, rcvbuf, src, why, sizeof(why));
	if (fd < 0)
		dm_fail("%s", why);
	int one = 1;
	setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
	return conn_new(fd, "tcp");
}

dm_conn *dm_connect_tcp(const dm_daemon *d)
{
	return connect_tcp(d->tcp_host, d->tcp_port, 0, NULL);
}

dm_conn *dm_connect_tcp_rcvbuf(const dm_daemon *d, int rcvbuf)
{
	return connect_tcp(d->tcp_host, d->tcp_port, rcvbuf, NULL);
}

dm_conn *dm_connect_tcp_from(const dm_daemon *d, const char *src)
{
	return connect_tcp(d->tcp_host, d->tcp_port, 0, src);
}

dm_conn *dm_connect_unix(const dm_daemon *d)
{
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0)
		dm_fail("socket: %s", strerror(errno));
	struct sockaddr_un sa = {.sun_family = AF_UNIX};
	size_t n = strlen(d->unix_path);
	if (n >= sizeof(sa.sun_path))
		dm_fail("unix socket path too long: %s", d->unix_path);
	memcpy(sa.sun_path, d->unix_path, n + 1);
	if (connect(fd, (struct sockaddr *)&sa, sizeof(sa)) != 0)
		dm_fail("connect unix:%s: %s", d->unix_path, strerror(errno));
	return conn_new(fd, "unix");
}

dm_conn *dm_open(const dm_daemon *d, const char *token)
{
	dm_conn *c = dm_connect_tcp(d);
	json_t *r;
	if (token)
		r = dm_ok(c, "{s:s, s:i, s:s, s:s}", "cmd", "hello", "version",
		          1, "token", token, "client", "test_daemon");
	else
		r = dm_ok(c, "{s:s, s:i, s:s}", "cmd", "hello", "version", 1,
		          "client", "test_daemon");
	json_decref(r);
	return c;
}

void dm_close(dm_conn *c)
{
	if (!c)
		return;
	dm_conn_forget(c);
	if (c->fd >= 0)
		close(c->fd);
	json_decref(c->events);
	json_decref(c->replies);
	free(c->buf);
	free(c->payload);
	free(c);
}

int dm_send_raw(dm_conn *c, const void *bytes, size_t len)
{
	const unsigned char *p = bytes;
	double end = dm_now_ms() + (c->send_ms > 0 ? c->send_ms : dm_reply_ms);
	while (len > 0) {
		ssize_t n = send(c->fd, p, len, MSG_NOSIGNAL);
		if (n > 0) {
			p += n;
			len -= (size_t)n;
			continue;
		}
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0 && (errno == EPIPE || errno == ECONNRESET))
			return -1;
		if (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)
			dm_fail("send on %s: %s", c->what, strerror(errno));
		int left = (int)(end - dm_now_ms());
		if (left <= 0)
			return -2; /* the peer does not read */
		struct pollfd pf = {.fd = c->fd, .events = POLLOUT};
		poll(&pf, 1, left);
	}
	return 0;
}

int dm_send_frame(dm_conn *c, json_t *header, const void *payload, size_t len)
{
	unsigned char *out = NULL;
	size_t out_len = 0;
	if (rp_frame_encode(header, payload, len, &out, &out_len) != 0)
		dm_fail("rp_frame_encode failed");
	int r = dm_send_raw(c, out, out_len);
	free(out);
	return r;
}

/* Read what is available (waiting up to timeout_ms for the first byte):
 * 1 read something, 0 timeout, -1 eof. */
static int fill(dm_conn *c, int timeout_ms)
{
	if (c->eof)
		return -1;
	struct pollfd pf = {.fd = c->fd, .events = POLLIN};
	int pr = poll(&pf, 1, timeout_ms < 0 ? 0 : timeout_ms);
	if (pr < 0 && errno == EINTR)
		return 0;
	if (pr <= 0)
		return 0;
	if (c->cap - c->len < 65536) {
		size_t ncap = c->cap ? c->cap * 2 : 131072;
		unsigned char *nb = realloc(c->buf, ncap);
		if (!nb)
			dm_fail("out of memory");
		c->buf = nb;
		c->cap = ncap;
	}
	ssize_t n = recv(c->fd, c->buf + c->len, c->cap - c->len, 0);
	if (n > 0) {
		c->len += (size_t)n;
		return 1;
	}
	if (n == 0 || (errno != EAGAIN && errno != EINTR)) {
		c->reset = n < 0 && errno == ECONNRESET;
		c->eof = 1;
		return -1;
	}
	return 0;
}

int dm_recv(dm_conn *c, int timeout_ms, json_t **hdr, unsigned char **payload,
            size_t *payload_len)
{
	rp_limits lim = {.max_header_bytes = (size_t)64 << 20,
	                 .max_payload_bytes = (size_t)2 << 30};
	double end = dm_now_ms() + timeout_ms;
	int tried = 0; /* a zero timeout still reads what is there */
	for (;;) {
		rp_frame fr;
		size_t used = 0;
		rp_error err;
		rp_decode r =
		        rp_frame_decode(&lim, c->buf, c->len, &fr, &used, &err);
		if (r == RP_DECODE_ERROR)
			dm_fail("the daemon sent a malformed frame on %s: %s",
			        c->what, err.msg);
		if (r == RP_DECODE_FRAME) {
			*hdr = fr.header;
			if (payload) {
				*payload = NULL;
				if (fr.payload) {
					*payload = malloc(fr.payload_len + 1);
					if (!*payload)
						dm_fail("out of memory");
					memcpy(*payload, fr.payload,
					       fr.payload_len);
				}
				*payload_len = fr.payload ? fr.payload_len : 0;
			}
			memmove(c->buf, c->buf + used, c->len - used);
			c->len -= used;
			return 1;
		}
		int left = (int)(end - dm_now_ms());
		if (c->eof)
			return -1;
		if (left <= 0 && tried)
			return 0;
		tried = 1;
		if (fill(c, left > 0 ? left : 0) < 0 && c->len == 0)
			return -1;
	}
}

/* Route a received frame: events and stray replies are queued. */
static void queue_frame(dm_conn *c, json_t *h)
{
	if (json_object_get(h, "event"))
		json_array_append_new(c->events, h);
	else
		json_array_append_new(c->replies, h);
}

int dm_wait_closed(dm_conn *c, int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	for (;;) {
		json_t *h;
		int left = (int)(end - dm_now_ms());
		int r = dm_recv(c, left > 0 ? left : 0, &h, NULL, NULL);
		if (r == 1) {
			queue_frame(c, h);
			continue;
		}
		if (r < 0)
			return 1;
		if (dm_now_ms() >= end)
			return 0;
	}
}

static json_t *take_reply(dm_conn *c, const json_t *id)
{
	size_t i;
	json_t *v;
	json_array_foreach(c->replies, i, v)
	{
		json_t *rid = json_object_get(v, "id");
		if (rid && json_equal(rid, id)) {
			json_incref(v);
			json_array_remove(c->replies, i);
			return v;
		}
	}
	return NULL;
}

/*
 * Send header (stolen) with a fresh id and wait for its reply.  must: fail
 * on timeout / close; else return NULL then.
 */
json_t *dm_call_json(dm_conn *c, json_t *h, const void *payload, size_t len,
                     int timeout_ms, int must)
{
	if (!h)
		dm_fail("bad request format (json_pack)");
	json_t *id = json_integer(c->next_id++);
	json_object_set(h, "id", id);
	const char *cmd = json_string_value(json_object_get(h, "cmd"));
	char cmdname[64];
	snprintf(cmdname, sizeof(cmdname), "%s", cmd ? cmd : "?");
	int sr = dm_send_frame(c, h, payload, len);
	json_decref(h);
	free(c->payload);
	c->payload = NULL;
	c->payload_len = 0;
	if (sr != 0 && must && sr == -2)
		dm_fail("%s: the daemon stopped reading on %s", cmdname,
		        c->what);
	double end = dm_now_ms() + timeout_ms;
	for (;;) {
		json_t *r = take_reply(c, id);
		if (r) {
			json_decref(id);
			return r;
		}
		json_t *fh;
		unsigned char *pl = NULL;
		size_t plen = 0;
		int left = (int)(end - dm_now_ms());
		int rr = dm_recv(c, left > 0 ? left : 0, &fh, &pl, &plen);
		if (rr == 1) {
			json_t *rid = json_object_get(fh, "id");
			if (!json_object_get(fh, "event") && rid &&
			    json_equal(rid, id)) {
				c->payload = pl;
				c->payload_len = plen;
				json_decref(id);
				return fh;
			}
			free(pl);
			queue_frame(c, fh);
			continue;
		}
		json_decref(id);
		if (!must)
			return NULL;
		if (rr < 0)
			dm_fail("%s: connection (%s) closed before the reply%s",
			        cmdname, c->what,
			        dm_unsolicited_error(c) ? " (after an error)"
			                                : "");
		dm_fail("%s: no reply on %s within %d ms", cmdname, c->what,
		        timeout_ms);
	}
}

/* The request header from json_pack arguments; fails the test when they
 * do not pack. */
static json_t *vpack(const char *fmt, va_list ap)
{
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	return h;
}

json_t *dm_call(dm_conn *c, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_t *h = vpack(fmt, ap);
	va_end(ap);
	return dm_call_json(c, h, NULL, 0, dm_reply_ms, 1);
}

json_t *dm_call_maybe(dm_conn *c, int timeout_ms, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_t *h = vpack(fmt, ap);
	va_end(ap);
	return dm_call_json(c, h, NULL, 0, timeout_ms, 0);
}

json_t *dm_call_payload(dm_conn *c, const void *payload, size_t len,
                        const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_t *h = vpack(fmt, ap);
	va_end(ap);
	return dm_call_json(c, h, payload, len, dm_reply_ms, 1);
}

const char *dm_err_code(const json_t *reply)
{
	json_t *ok = json_object_get(reply, "ok");
	if (json_is_true(ok))
		return "";
	const char *code = json_string_value(
	        json_object_get(json_object_get(reply, "error"), "code"));
	return code ? code : "?";
}

char *dm_dumps(const json_t *j)
{
	char *s = json_dumps(j, JSON_COMPACT);
	if (s && strlen(s) > 1500)
		strcpy(s + 1490, "...");
	return s;
}

void dm_require_ok(const json_t *r, const char *what)
{
	if (!json_is_true(json_object_get(r, "ok"))) {
		char *s = dm_dumps(r);
		char msg[1800];
		snprintf(msg, sizeof(msg), "%s", s ? s : "?");
		free(s);
		dm_fail("%s: expected ok, got %s", what, msg);
	}
}

json_t *dm_ok(dm_conn *c, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_t *h = vpack(fmt, ap);
	va_end(ap);
	char what[64];
	snprintf(what, sizeof(what), "%s",
	         json_string_value(json_object_get(h, "cmd")));
	json_t *r = dm_call_json(c, h, NULL, 0, dm_reply_ms, 1);
	dm_require_ok(r, what);
	return r;
}

json_t *dm_err(dm_conn *c, const char *code, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_t *h = vpack(fmt, ap);
	va_end(ap);
	char *req = dm_dumps(h);
	char reqs[600];
	snprintf(reqs, sizeof(reqs), "%s", req ? req : "?");
	free(req);
	json_t *r = dm_call_json(c, h, NULL, 0, dm_reply_ms, 0);
	if (!r)
		dm_fail("%s: no reply (wanted error %s)", reqs, code);
	if (strcmp(dm_err_code(r), code) != 0) {
		char *s = dm_dumps(r);
		char got[1600];
		snprintf(got, sizeof(got), "%s", s ? s : "?");
		free(s);
		json_decref(r);
		dm_fail("%s: wanted error %s, got %s", reqs, code, got);
	}
	const char *m = json_string_value(
	        json_object_get(json_object_get(r, "error"), "message"));
	if (!m || !m[0])
		dm_fail("%s: error %s without a message", reqs, code);
	return r;
}

const char *dm_unsolicited_error(dm_conn *c)
{
	size_t i;
	json_t *v;
	json_array_foreach(c->replies, i, v)
	{
		if (json_is_false(json_object_get(v, "ok")))
			return dm_err_code(v);
	}
	return NULL;
}

json_t *dm_event(dm_conn *c, int timeout_ms)
{
	if (json_array_size(c->events) > 0) {
		json_t *e = json_incref(json_array_get(c->events, 0));
		json_array_remove(c->events, 0);
		return e;
	}
	double end = dm_now_ms() + timeout_ms;
	for (;;) {
		json_t *h;
		int left = (int)(end - dm_now_ms());
		int r = dm_recv(c, left > 0 ? left : 0, &h, NULL, NULL);
		if (r != 1)
			return NULL;
		if (json_object_get(h, "event"))
			return h;
		json_array_append_new(c->replies, h);
	}
}

dm_conn *dm_open_when_free(const dm_daemon *d, const char *src, int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	for (;;) {
		dm_conn *c =
		        src ? dm_connect_tcp_from(d, src) : dm_connect_tcp(d);
		json_t *r = dm_call_maybe(c, timeout_ms, "{s:s, s:i}", "cmd",
		                          "hello", "version", 1);
		int ok = r && !strcmp(dm_err_code(r), "");
		json_decref(r);
		if (ok)
			return c;
		dm_close(c);
		if (dm_now_ms() > end)
			return NULL;
		dm_sleep_ms(100);
	}
}

int dm_http_get(const dm_daemon *d, const char *path, char **headers,
                char **body)
{
	dm_conn *c = connect_tcp(d->metrics_host, d->metrics_port, 0, NULL);
	char req[512];
	int n = snprintf(req, sizeof(req),
	                 "GET %s HTTP/1.1\r\nHost: %s:%d\r\nConnection: "
	                 "close\r\nAccept: text/plain\r\n\r\n",
	                 path, d->metrics_host, d->metrics_port);
	if (dm_send_raw(c, req, (size_t)n) != 0)
		dm_fail("GET %s: send failed", path);
	double end = dm_now_ms() + dm_reply_ms;
	while (!c->eof) {
		int left = (int)(end - dm_now_ms());
		if (left <= 0)
			dm_fail("GET %s: the response was not closed within "
			        "%d ms (%zu bytes read)",
			        path, dm_reply_ms, c->len);
		fill(c, left);
	}
	char *text = malloc(c->len + 1);
	memcpy(text, c->buf, c->len);
	text[c->len] = 0;
	dm_close(c);
	int code = 0;
	if (sscanf(text, "HTTP/1.%*d %d", &code) != 1)
		dm_fail("GET %s: not an HTTP response: %.200s", path, text);
	char *sep = strstr(text, "\r\n\r\n");
	if (!sep)
		dm_fail("GET %s: no end of headers", path);
	*sep = 0;
	if (headers)
		*headers = strdup(text);
	if (body)
		*body = strdup(sep + 4);
	free(text);
	return code;
}
