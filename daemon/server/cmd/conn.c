/*
 * conn.c -- protocol connections: accept, the input buffer decoded with
 * rp_frame_decode, the output queue, limits, the hello-first rule, idle
 * time and closing.
 *
 * Everything here runs on the I/O thread.  Sockets are non-blocking and
 * level-triggered in epoll.  A connection reads only while it may act on
 * what it reads: not while a deferred reply is owed (busy), not while its
 * output queue is over max_output_bytes, not while closing.  So a peer
 * that sends without reading, or pipelines requests, meets TCP
 * backpressure instead of growing our buffers.
 *
 * The input buffer holds at most one frame being received: its header is
 * bounded by max_header_bytes (the decoder's check), its payload by
 * max_scene_bytes (0 before hello).  Once the header is complete the
 * buffer is sized for the whole frame at once and the decoder is not
 * called again until the frame is complete.  A handler may take the
 * buffer (cmd_conn_steal_input) instead of copying a large payload.
 *
 * Closing: an error whose rp_err_closes() is set, EOF, or a write error.
 * A closing connection stops reading, flushes what is queued for at most
 * a few seconds and is then freed at the end of the loop turn (never
 * while a caller up the stack may still hold the pointer).
 */
#include <errno.h>
#include <netdb.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include "cmd.h"
#include "log.h"

#define READ_CHUNK (64 * 1024)
#define READ_BUDGET (4u << 20) /* per connection per loop turn */
#define CLOSE_FLUSH_S 15.0     /* time a closing connection may flush */
#define EOF_GRACE_S 60.0       /* half-closed peer awaiting a reply */

cmd_conn *cmd_conn_find(cmd_server *d, uint64_t id)
{
	for (cmd_conn *c = d->conns; c; c = c->next)
		if (c->id == id && !c->dead)
			return c;
	return NULL;
}

void cmd_conn_update_events(cmd_server *d, cmd_conn *c)
{
	srv *s = &d->core;
	if (c->dead)
		return;
	int reading = c->closing ? !c->eof
	                         : !c->busy && c->out_bytes <=
	                                               s->cfg.max_output_bytes;
	int want_out = c->out_head != NULL;
	if (reading == c->reading && want_out == c->want_out)
		return;
	if (el_watch_set(d->loop, &c->w,
	                 (reading ? EL_READABLE : 0u) |
	                         (want_out ? EL_WRITABLE : 0u)) != 0)
		srv_warn("connection %llu: epoll_ctl: %s",
		         (unsigned long long)c->id, strerror(errno));
	c->reading = reading;
	c->want_out = want_out;
}

/* Refuse a connection over max_connections with a one-shot error. */
static void refuse(int fd, int max)
{
	json_t *e =
	        rp_reply_error(NULL, RP_ERR_TOO_MANY_CONNECTIONS,
	                       "the daemon serves at most %d connections", max);
	unsigned char *buf;
	size_t len;
	if (e && rp_frame_encode(e, NULL, 0, &buf, &len) == 0) {
		if (send(fd, buf, len, MSG_NOSIGNAL | MSG_DONTWAIT) < 0)
			srv_debug("refused connection: %s", strerror(errno));
		free(buf);
	}
	json_decref(e);
	close(fd);
}

static void peer_text(int fd, int tcp, char *out, size_t len)
{
	struct sockaddr_storage ss;
	socklen_t sl = sizeof(ss);
	char host[64] = "?", port[16] = "?";
	if (!tcp) {
		snprintf(out, len, "unix");
		return;
	}
	if (getpeername(fd, (struct sockaddr *)&ss, &sl) == 0)
		getnameinfo((struct sockaddr *)&ss, sl, host, sizeof(host),
		            port, sizeof(port),
		            NI_NUMERICHOST | NI_NUMERICSERV);
	snprintf(out, len, "%s:%s", host, port);
}

static void conn_writable(cmd_server *d, cmd_conn *c);
static void conn_readable(cmd_server *d, cmd_conn *c);

static void conn_ready(el_loop *l, el_watch *w, unsigned events)
{
	cmd_server *d = w->ud;
	cmd_conn *c = (cmd_conn *)((char *)w - offsetof(cmd_conn, w));
	(void)l;
	if (!c->dead && (events & (EL_WRITABLE | EL_ERROR)))
		conn_writable(d, c);
	if (!c->dead && (events & (EL_READABLE | EL_ERROR)))
		conn_readable(d, c);
}

void cmd_conn_accept(cmd_server *d, int lfd, int tcp, int needs_token)
{
	srv *s = &d->core;
	for (;;) {
		int fd = accept4(lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0) {
			if (errno != EAGAIN && errno != EINTR &&
			    errno != ECONNABORTED)
				srv_warn("accept: %s", strerror(errno));
			return;
		}
		if (d->nconns >= s->cfg.max_connections) {
			srv_warn("connection refused: max_connections (%d) "
			         "reached",
			         s->cfg.max_connections);
			refuse(fd, s->cfg.max_connections);
			continue;
		}
		cmd_conn *c = calloc(1, sizeof(*c));
		if (!c) {
			close(fd);
			continue;
		}
		c->id = d->next_conn_id++;
		c->fd = fd;
		c->listener_tcp = tcp;
		c->needs_token = needs_token;
		c->reading = 1;
		c->last_active = rad_seconds();
		peer_text(fd, tcp, c->peer, sizeof(c->peer));
		if (el_watch_add(d->loop, &c->w, fd, EL_READABLE, conn_ready,
		                 d) != 0) {
			close(fd);
			free(c);
			continue;
		}
		c->next = d->conns;
		if (d->conns)
			d->conns->prev = c;
		d->conns = c;
		d->nconns++;
		d->conns_total++;
		srv_debug("connection %llu from %s", (unsigned long long)c->id,
		          c->peer);
	}
}

/* ----------------------------------------------------------------- output */

static void flush(cmd_server *d, cmd_conn *c)
{
	while (c->out_head && !c->dead) {
		struct iovec iov[32];
		int n = 0;
		for (cmd_chunk *k = c->out_head; k && n < 32; k = k->next) {
			iov[n].iov_base = k->buf + k->off;
			iov[n].iov_len = k->len - k->off;
			n++;
		}
		struct msghdr mh = {.msg_iov = iov, .msg_iovlen = (size_t)n};
		ssize_t w = sendmsg(c->fd, &mh, MSG_NOSIGNAL | MSG_DONTWAIT);
		if (w < 0) {
			if (errno == EAGAIN || errno == EINTR)
				break;
			srv_debug("connection %llu: send: %s",
			          (unsigned long long)c->id, strerror(errno));
			c->dead = 1;
			return;
		}
		c->last_active = rad_seconds();
		size_t left = (size_t)w;
		c->out_bytes -= left;
		while (left > 0) {
			cmd_chunk *k = c->out_head;
			size_t take = k->len - k->off;
			if (take > left) {
				k->off += left;
				break;
			}
			left -= take;
			c->out_head = k->next;
			if (!c->out_head)
				c->out_tail = NULL;
			free(k->buf);
			free(k);
		}
	}
	if (c->closing && !c->out_head && !c->busy && !c->dead) {
		/* All said: send FIN, then wait for the peer's EOF (reading
		 * and discarding), so that unread input does not turn our
		 * close into a reset that would lose the last frame. */
		if (!c->wr_shut) {
			shutdown(c->fd, SHUT_WR);
			c->wr_shut = 1;
		}
		if (c->eof)
			c->dead = 1;
	}
	cmd_conn_update_events(d, c);
}

int cmd_conn_send(cmd_server *d, cmd_conn *c, unsigned char *buf, size_t len)
{
	if (c->dead) {
		free(buf);
		return -1;
	}
	cmd_chunk *k = malloc(sizeof(*k));
	if (!k) {
		free(buf);
		c->dead = 1; /* a lost frame would desynchronise the peer */
		return -1;
	}
	k->next = NULL;
	k->buf = buf;
	k->len = len;
	k->off = 0;
	if (c->out_tail)
		c->out_tail->next = k;
	else
		c->out_head = k;
	c->out_tail = k;
	c->out_bytes += len;
	flush(d, c);
	return 0;
}

int cmd_conn_send_json(cmd_server *d, cmd_conn *c, json_t *hdr)
{
	unsigned char *buf;
	size_t len;
	if (rp_frame_encode(hdr, NULL, 0, &buf, &len) != 0) {
		srv_error("connection %llu: cannot encode a reply",
		          (unsigned long long)c->id);
		c->dead = 1;
		return -1;
	}
	return cmd_conn_send(d, c, buf, len);
}

void cmd_conn_drop_queued(cmd_conn *c)
{
	cmd_chunk **pp = &c->out_head;
	if (*pp && (*pp)->off > 0) /* partly sent: must be finished */
		pp = &(*pp)->next;
	while (*pp) {
		cmd_chunk *k = *pp;
		*pp = k->next;
		c->out_bytes -= k->len - k->off;
		free(k->buf);
		free(k);
	}
	c->out_tail = NULL;
	for (cmd_chunk *k = c->out_head; k; k = k->next)
		c->out_tail = k;
}

void cmd_conn_close_after_flush(cmd_server *d, cmd_conn *c)
{
	if (!c->closing) {
		c->closing = 1;
		c->close_at = rad_seconds() + CLOSE_FLUSH_S;
	}
	flush(d, c);
}

void cmd_conn_send_error(cmd_server *d, cmd_conn *c, json_t *id, rp_err code,
                         const char *fmt, ...)
{
	char msg[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof(msg), fmt, ap);
	va_end(ap);
	json_t *e = rp_reply_error(id, code, "%s", msg);
	if (e)
		cmd_conn_send_json(d, c, e);
	json_decref(e);
	if (rp_err_closes(code)) {
		srv_info("connection %llu (%s) closed: %s: %s",
		         (unsigned long long)c->id, c->peer, rp_err_name(code),
		         msg);
		cmd_conn_close_after_flush(d, c);
	}
}

static void conn_writable(cmd_server *d, cmd_conn *c)
{
	srv *s = &d->core;
	flush(d, c);
	/* Output pressure relieved: frames may be waiting. */
	if (!c->dead && !c->busy && !c->closing &&
	    c->out_bytes <= s->cfg.max_output_bytes && c->in_len > c->in_off)
		cmd_conn_unbusy(d, c);
}

/* ------------------------------------------------------------------ input */

unsigned char *cmd_conn_steal_input(cmd_conn *c, size_t used)
{
	unsigned char *old = c->in;
	size_t rest = c->in_len - c->in_off - used;
	unsigned char *nb = NULL;
	if (rest > 0) {
		nb = malloc(rest > READ_CHUNK ? rest : READ_CHUNK);
		if (!nb)
			return NULL;
		memcpy(nb, old + c->in_off + used, rest);
	}
	c->in = nb;
	c->in_cap = nb ? (rest > READ_CHUNK ? rest : READ_CHUNK) : 0;
	c->in_off = 0;
	c->in_len = rest;
	c->need = 0;
	c->stolen = 1;
	return old;
}

/* Before hello: a complete first line that is not hello is refused
 * without reading any payload it announces. */
static int check_first_frame(cmd_server *d, cmd_conn *c)
{
	srv *s = &d->core;
	const unsigned char *p = c->in + c->in_off;
	size_t avail = c->in_len - c->in_off;
	size_t scan = avail < s->cfg.max_header_bytes ? avail
	                                              : s->cfg.max_header_bytes;
	const unsigned char *nl = memchr(p, '\n', scan);
	if (!nl)
		return 0;
	json_t *h = json_loadb((const char *)p, (size_t)(nl - p), 0, NULL);
	if (!json_is_object(h)) { /* the decoder reports it */
		json_decref(h);
		return 0;
	}
	const char *cmd = json_string_value(json_object_get(h, "cmd"));
	int ok = cmd && strcmp(cmd, "hello") == 0;
	if (!ok)
		cmd_conn_send_error(d, c, json_object_get(h, "id"),
		                    RP_ERR_AUTH_REQUIRED,
		                    "the first request must be \"hello\" "
		                    "(got %s%s%s)",
		                    cmd ? "\"" : "", cmd ? cmd : "no \"cmd\"",
		                    cmd ? "\"" : "");
	json_decref(h);
	return ok ? 0 : -1;
}

/* Once the header line is in, how many bytes the whole frame needs. */
static size_t frame_need(const cmd_conn *c)
{
	const unsigned char *p = c->in + c->in_off;
	size_t avail = c->in_len - c->in_off;
	const unsigned char *nl = memchr(p, '\n', avail);
	if (!nl)
		return 0;
	json_t *h = json_loadb((const char *)p, (size_t)(nl - p), 0, NULL);
	json_t *b = json_object_get(h, "bytes");
	size_t need = (size_t)(nl - p) + 1;
	if (json_is_integer(b) && json_integer_value(b) > 0)
		need += (size_t)json_integer_value(b);
	json_decref(h);
	return need;
}

/* Decode and dispatch the frames buffered, while allowed to. */
static void process(cmd_server *d, cmd_conn *c)
{
	srv *s = &d->core;
	while (!c->dead && !c->closing && !c->busy &&
	       c->out_bytes <= s->cfg.max_output_bytes) {
		size_t avail = c->in_len - c->in_off, used = 0;
		if (avail == 0 || (c->need && avail < c->need))
			break;
		if (!c->authed && check_first_frame(d, c) != 0)
			break;
		rp_limits lim = {s->cfg.max_header_bytes,
		                 c->authed ? s->cfg.max_scene_bytes : 0};
		rp_frame f;
		rp_error err = {0};
		rp_decode rc = rp_frame_decode(&lim, c->in + c->in_off, avail,
		                               &f, &used, &err);
		if (rc == RP_DECODE_NEED) {
			c->need = frame_need(c);
			break;
		}
		if (rc == RP_DECODE_ERROR) {
			cmd_conn_send_error(d, c, NULL, err.code, "%s",
			                    err.msg);
			break;
		}
		c->need = 0;
		c->stolen = 0;
		d->on_frame(d, c, &f, used);
		json_decref(f.header);
		if (c->stolen) {
			c->stolen = 0;
			continue;
		}
		c->in_off += used;
		if (c->in_off == c->in_len)
			c->in_off = c->in_len = 0;
	}
	cmd_conn_update_events(d, c);
}

void cmd_conn_unbusy(cmd_server *d, cmd_conn *c)
{
	c->busy = 0;
	if (c->closing)
		flush(d, c);
	else
		process(d, c);
}

/* Make room for at least one read; -1 when the frame cannot fit. */
static int reserve(cmd_server *d, cmd_conn *c)
{
	srv *s = &d->core;
	size_t want = READ_CHUNK;
	if (c->need > c->in_len - c->in_off)
		want = c->need - (c->in_len - c->in_off);
	if (c->in_cap - c->in_len >= want ||
	    (c->in_cap - c->in_len >= READ_CHUNK && !c->need))
		return 0;
	if (c->in_off > 0) {
		memmove(c->in, c->in + c->in_off, c->in_len - c->in_off);
		c->in_len -= c->in_off;
		c->in_off = 0;
		if (c->in_cap - c->in_len >= want)
			return 0;
	}
	size_t ncap = c->in_len + (want > READ_CHUNK ? want : READ_CHUNK);
	if (!c->need && ncap < 2 * c->in_cap)
		ncap = 2 * c->in_cap;
	size_t lim =
	        s->cfg.max_header_bytes + s->cfg.max_scene_bytes + READ_CHUNK;
	if (ncap > lim)
		ncap = lim > c->in_len + READ_CHUNK ? lim
		                                    : c->in_len + READ_CHUNK;
	unsigned char *nb = realloc(c->in, ncap);
	if (!nb)
		return -1;
	c->in = nb;
	c->in_cap = ncap;
	(void)s;
	return 0;
}

/* Closing: read and discard until EOF (bounded by close_at). */
static void drain(cmd_conn *c)
{
	char buf[16384];
	for (int i = 0; i < 64; i++) {
		ssize_t n = read(c->fd, buf, sizeof(buf));
		if (n > 0)
			continue;
		if (n < 0 && (errno == EAGAIN || errno == EINTR))
			return;
		c->eof = 1; /* EOF or error */
		if (c->wr_shut || n < 0)
			c->dead = 1;
		return;
	}
}

static void conn_readable(cmd_server *d, cmd_conn *c)
{
	size_t budget = READ_BUDGET;
	int eof = 0;

	if (!c->reading) {
		/* Not reading: only a hang-up or an error brings us here. */
		c->dead = 1;
		return;
	}
	if (c->closing) {
		drain(c);
		cmd_conn_update_events(d, c);
		return;
	}
	while (budget > 0) {
		if (reserve(d, c) != 0) {
			cmd_conn_send_error(
			        d, c, NULL, RP_ERR_NOMEM,
			        "out of memory for the input buffer");
			c->dead = 1;
			return;
		}
		ssize_t n =
		        read(c->fd, c->in + c->in_len, c->in_cap - c->in_len);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			if (errno != EAGAIN)
				c->dead = 1;
			break;
		}
		if (n == 0) {
			eof = 1;
			break;
		}
		c->in_len += (size_t)n;
		c->last_active = rad_seconds();
		budget = (size_t)n >= budget ? 0 : budget - (size_t)n;
		if (c->need && c->in_len - c->in_off < c->need)
			continue;
		break;
	}
	if (!c->dead)
		process(d, c);
	if (eof && !c->dead) {
		c->eof = 1;
		if (!c->busy && !c->out_head) {
			c->dead = 1;
		} else if (!c->closing) {
			c->closing = 1;
			c->close_at = rad_seconds() + EOF_GRACE_S;
			cmd_conn_update_events(d, c);
		}
	}
}

/* ---------------------------------------------------------- lifecycle */

static void conn_free(cmd_server *d, cmd_conn *c)
{
	el_watch_del(d->loop, &c->w);
	close(c->fd);
	while (c->out_head) {
		cmd_chunk *k = c->out_head;
		c->out_head = k->next;
		free(k->buf);
		free(k);
	}
	free(c->in);
	free(c->subs);
	free(c);
}

void cmd_conn_reap(cmd_server *d)
{
	cmd_conn *c = d->conns;
	while (c) {
		cmd_conn *next = c->next;
		if (c->dead) {
			if (c->prev)
				c->prev->next = c->next;
			else
				d->conns = c->next;
			if (c->next)
				c->next->prev = c->prev;
			d->nconns--;
			srv_debug("connection %llu (%s) closed",
			          (unsigned long long)c->id, c->peer);
			conn_free(d, c);
		}
		c = next;
	}
}

void cmd_conn_tick(cmd_server *d, double now)
{
	srv *s = &d->core;
	double idle = s->cfg.idle_timeout_s;
	for (cmd_conn *c = d->conns; c; c = c->next) {
		if (c->dead)
			continue;
		if (c->closing) {
			if (now >= c->close_at)
				c->dead = 1;
			continue;
		}
		if (idle > 0 && !c->busy && !c->out_head &&
		    now - c->last_active > idle)
			cmd_conn_send_error(d, c, NULL, RP_ERR_IDLE_TIMEOUT,
			                    "nothing received or sent for %g s",
			                    idle);
	}
}

void cmd_conn_free_all(cmd_server *d)
{
	while (d->conns) {
		cmd_conn *c = d->conns;
		d->conns = c->next;
		conn_free(d, c);
	}
	d->nconns = 0;
}
