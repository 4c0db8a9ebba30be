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
 *
 * Admission.  A slot is held from accept, so what a peer may do before
 * it has proved anything is bounded: hello within hello_timeout of the
 * accept, every header line complete within header_timeout of its first
 * byte (the idle timeout alone, reset by each byte, let one byte a
 * minute hold a slot for ever), at most max_connections_per_address
 * connections per IPv4 address or IPv6 /64.  When every slot is taken, a
 * new connection takes the place of the oldest one that has waited
 * EVICT_AFTER_S without saying hello; when there is none it is refused.
 * A refused socket gets its too_many_connections frame, then our FIN,
 * and is read until the peer's EOF (a linger, bounded in number and
 * time) before it is closed: closing a socket with unread input sends a
 * reset, which the peer may see before the frame.  A spare descriptor,
 * given up for a moment, lets the daemon accept and refuse even when the
 * process is out of descriptors.  Every refusal and forced close is
 * counted by cause (cmd_refusal) for /metrics.
 *
 * TLS (tls.c).  On a TLS listener a connection's bytes go through its
 * session: the handshake runs first, on readable events, within the
 * hello deadline; conn_write and the reads call tls.c, which answers as
 * write(2) and read(2) do; a refused peer gets its frame inside a session
 * the linger makes.  Everything above (frames, limits, closing) is the
 * same for both.
 */
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include <openssl/ssl.h>

#include "cmd.h"
#include "log.h"

#define READ_CHUNK (64 * 1024)
#define READ_BUDGET (4u << 20) /* per connection per loop turn */
#define CLOSE_FLUSH_S 15.0     /* time a closing connection may flush */
#define EOF_GRACE_S 60.0       /* half-closed peer awaiting a reply */
#define EVICT_AFTER_S 1.0      /* no hello this long: may give way */
#define LINGER_S 2.0           /* a refused socket read until EOF */
#define LINGER_MAX 256         /* refused sockets lingering at once */

static const char *const refusal_names[] = {
#define CMD_REFUSAL_NAME_(name, str) str,
        CMD_REFUSALS(CMD_REFUSAL_NAME_)
#undef CMD_REFUSAL_NAME_
};

const char *cmd_refusal_name(cmd_refusal r)
{
	return (unsigned)r < CMD_REFUSED_COUNT ? refusal_names[r] : "?";
}

/* The refusal a closing error stands for; CMD_REFUSED_COUNT for none. */
static cmd_refusal refusal_of(rp_err code)
{
	switch (code) {
	case RP_ERR_TOO_MANY_CONNECTIONS:
		return CMD_REFUSED_EVICTED;
	case RP_ERR_HELLO_TIMEOUT:
		return CMD_REFUSED_HELLO_TIMEOUT;
	case RP_ERR_HEADER_TIMEOUT:
		return CMD_REFUSED_HEADER_TIMEOUT;
	case RP_ERR_IDLE_TIMEOUT:
		return CMD_REFUSED_IDLE_TIMEOUT;
	case RP_ERR_AUTH_REQUIRED:
	case RP_ERR_AUTH_FAILED:
		return CMD_REFUSED_AUTH;
	case RP_ERR_BAD_FRAME:
	case RP_ERR_TOO_LARGE:
	case RP_ERR_VERSION:
		return CMD_REFUSED_PROTOCOL;
	case RP_ERR_SLOW_CONSUMER:
		return CMD_REFUSED_SLOW_CONSUMER;
	default:
		return CMD_REFUSED_COUNT;
	}
}

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
	/* A header's deadline does not run while we do not read it. */
	if (reading && !c->reading && c->hdr_start > 0)
		c->hdr_start = rad_seconds();
	c->reading = reading;
	c->want_out = want_out;
}

/* -------------------------------------------------------------- admission */

/* A refused socket, read and discarded until the peer's EOF. */
typedef struct lingering {
	el_watch w; /* ud: the cmd_server */
	double until;
	SSL *ssl;             /* TLS listener: the frame goes after the
	                         handshake (NULL: sent, or plain) */
	unsigned char *frame; /* ... and is this (malloc'ed) */
	size_t len;
	struct lingering *next, *prev;
} lingering;

static void linger_free(cmd_server *d, lingering *g)
{
	if (g->prev)
		g->prev->next = g->next;
	else
		d->lingers = g->next;
	if (g->next)
		g->next->prev = g->prev;
	d->nlingers--;
	el_watch_del(d->loop, &g->w);
	close(g->w.fd);
	SSL_free(g->ssl);
	free(g->frame);
	free(g);
}

/* Read what is there; 1 once the peer's EOF (or an error) is seen. */
static int discard_input(int fd)
{
	char buf[16384];
	for (int i = 0; i < 16; i++) {
		ssize_t n = read(fd, buf, sizeof(buf));
		if (n > 0)
			continue;
		if (n < 0 && (errno == EAGAIN || errno == EINTR))
			return 0;
		return 1;
	}
	return 0;
}

static void linger_ready(el_loop *l, el_watch *w, unsigned events)
{
	cmd_server *d = w->ud;
	lingering *g = (lingering *)((char *)w - offsetof(lingering, w));
	(void)l;
	(void)events;
	if (g->ssl) { /* a TLS peer: the frame once the handshake is done */
		char why[256];
		int h = cmd_tls_handshake(g->ssl, why, sizeof(why));
		if (h < 0 ||
		    (h == 1 && cmd_tls_write(g->ssl, g->frame, g->len) !=
		                       (ssize_t)g->len)) {
			linger_free(d, g);
			return;
		}
		if (h == 0)
			return;
		cmd_tls_close_notify(g->ssl);
		shutdown(w->fd, SHUT_WR);
		SSL_free(g->ssl);
		g->ssl = NULL;
	}
	if (discard_input(w->fd))
		linger_free(d, g);
}

/*
 * Refuse fd with a too_many_connections frame.  The frame fits in an
 * empty socket buffer; our FIN follows it, and the socket lingers (read
 * until EOF, LINGER_S at most) so that the peer's hello, unread, does not
 * turn the close into a reset.  With no room to linger (or no descriptor
 * to spare, may_linger 0) what has arrived is read before closing.
 */
static void refuse(cmd_server *d, int fd, int tls, cmd_refusal why,
                   int may_linger, const char *fmt, ...)
{
	char msg[256];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof(msg), fmt, ap);
	va_end(ap);
	d->refused[why]++;
	json_t *e =
	        rp_reply_error(NULL, RP_ERR_TOO_MANY_CONNECTIONS, "%s", msg);
	unsigned char *buf = NULL;
	size_t len = 0;
	if (!e || rp_frame_encode(e, NULL, 0, &buf, &len) != 0)
		buf = NULL;
	json_decref(e);
	lingering *g = may_linger && d->nlingers < LINGER_MAX
	                       ? calloc(1, sizeof(*g))
	                       : NULL;
	if (tls) { /* the frame can only go inside the session */
		if (g && buf && (g->ssl = cmd_tls_new(d, fd)) != NULL) {
			g->frame = buf;
			g->len = len;
			buf = NULL;
		} else {
			free(g);
			g = NULL;
		}
	} else {
		if (buf && send(fd, buf, len, MSG_NOSIGNAL | MSG_DONTWAIT) < 0)
			srv_debug("refused connection: %s", strerror(errno));
		shutdown(fd, SHUT_WR);
		if (discard_input(fd)) {
			free(g);
			g = NULL;
		}
	}
	free(buf);
	if (!g || el_watch_add(d->loop, &g->w, fd, EL_READABLE, linger_ready,
	                       d) != 0) {
		if (g) {
			SSL_free(g->ssl);
			free(g->frame);
			free(g);
		}
		close(fd);
		return;
	}
	g->until = rad_seconds() + LINGER_S;
	g->next = d->lingers;
	if (g->next)
		((lingering *)g->next)->prev = g;
	d->lingers = g;
	d->nlingers++;
}

static void lingers_tick(cmd_server *d, double now, int all)
{
	lingering *g = d->lingers;
	while (g) {
		lingering *next = g->next;
		if (all || now >= g->until)
			linger_free(d, g);
		g = next;
	}
}

/* The per-address key: the IPv4 address (IPv4-mapped IPv6 included) or
 * the /64 of an IPv6 address; 0 bytes for anything else. */
static int peer_key(const struct sockaddr_storage *ss, unsigned char key[16])
{
	static const unsigned char v4mapped[12] = {0, 0, 0, 0, 0,    0,
	                                           0, 0, 0, 0, 0xff, 0xff};
	if (ss->ss_family == AF_INET) {
		memcpy(key, &((const struct sockaddr_in *)ss)->sin_addr, 4);
		return 4;
	}
	if (ss->ss_family == AF_INET6) {
		const unsigned char *a =
		        ((const struct sockaddr_in6 *)ss)->sin6_addr.s6_addr;
		if (memcmp(a, v4mapped, 12) == 0) {
			memcpy(key, a + 12, 4);
			return 4;
		}
		memcpy(key, a, 8);
		return 8;
	}
	return 0;
}

static void peer_text(const struct sockaddr_storage *ss, socklen_t sl, int tcp,
                      char *out, size_t len)
{
	char host[64] = "?", port[16] = "?";
	if (!tcp) {
		snprintf(out, len, "unix");
		return;
	}
	getnameinfo((const struct sockaddr *)ss, sl, host, sizeof(host), port,
	            sizeof(port), NI_NUMERICHOST | NI_NUMERICSERV);
	snprintf(out, len, "%s:%s", host, port);
}

/* Connections open from this key. */
static int count_from(const cmd_server *d, const unsigned char *key, int n)
{
	int k = 0;
	for (const cmd_conn *c = d->conns; c; c = c->next)
		k += !c->dead && c->addr_len == n &&
		     memcmp(c->addr, key, n) == 0;
	return k;
}

/*
 * The slots in use: connections open and not closing (*live), those
 * closing (*closing: flushing their last frame, reading until EOF), and
 * the oldest live one that has waited EVICT_AFTER_S without hello.
 */
static cmd_conn *census(cmd_server *d, double now, int *live, int *closing)
{
	cmd_conn *old = NULL;
	*live = *closing = 0;
	for (cmd_conn *c = d->conns; c; c = c->next) {
		if (c->dead)
			continue;
		if (c->closing) {
			(*closing)++;
			continue;
		}
		(*live)++;
		if (!c->authed && now - c->opened >= EVICT_AFTER_S &&
		    (!old || c->opened < old->opened))
			old = c;
	}
	return old;
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

int cmd_conn_init(cmd_server *d)
{
	d->spare_fd = open("/dev/null", O_RDONLY | O_CLOEXEC);
	return d->spare_fd >= 0 ? 0 : -1;
}

/* Out of descriptors: give up the spare to accept one peer and refuse
 * it, so that it hears why instead of waiting in the backlog (and the
 * listener does not stay readable for ever).  0 when one was refused. */
static int refuse_without_descriptors(cmd_server *d, int lfd, int tls)
{
	if (d->spare_fd < 0)
		return -1;
	close(d->spare_fd);
	int fd = accept4(lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
	if (fd >= 0)
		refuse(d, fd, tls, CMD_REFUSED_NO_DESCRIPTORS, 0,
		       "the daemon is out of file descriptors");
	d->spare_fd = open("/dev/null", O_RDONLY | O_CLOEXEC);
	return fd >= 0 ? 0 : -1;
}

void cmd_conn_accept(cmd_server *d, int lfd, int tcp, int needs_token, int tls)
{
	srv *s = &d->core;
	const srv_config *cfg = &s->cfg;
	for (;;) {
		struct sockaddr_storage ss;
		socklen_t sl = sizeof(ss);
		int fd = accept4(lfd, (struct sockaddr *)&ss, &sl,
		                 SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0) {
			if ((errno == EMFILE || errno == ENFILE) &&
			    refuse_without_descriptors(d, lfd, tls) == 0) {
				srv_warn("connection refused: out of file "
				         "descriptors");
				continue;
			}
			if (errno != EAGAIN && errno != EINTR &&
			    errno != ECONNABORTED)
				srv_warn("accept: %s", strerror(errno));
			return;
		}
		double now = rad_seconds();
		unsigned char key[16];
		int klen = tcp ? peer_key(&ss, key) : 0;
		char peer[128];
		peer_text(&ss, sl, tcp, peer, sizeof(peer));
		if (klen && cfg->max_connections_per_address > 0 &&
		    count_from(d, key, klen) >=
		            cfg->max_connections_per_address) {
			srv_warn("connection from %s refused: "
			         "max_connections_per_address (%d) reached",
			         peer, cfg->max_connections_per_address);
			refuse(d, fd, tls, CMD_REFUSED_PER_ADDRESS, 1,
			       "this address already has %d connections open "
			       "(max_connections_per_address)",
			       cfg->max_connections_per_address);
			continue;
		}
		int live, closing;
		cmd_conn *old = census(d, now, &live, &closing);
		if (live >= cfg->max_connections) {
			/* Those closing are bounded too: each waits at most
			 * CLOSE_FLUSH_S for its peer's EOF. */
			if (!old || closing >= cfg->max_connections) {
				srv_warn("connection from %s refused: "
				         "max_connections (%d) reached",
				         peer, cfg->max_connections);
				refuse(d, fd, tls, CMD_REFUSED_MAX_CONNECTIONS,
				       1,
				       "the daemon serves at most %d "
				       "connections",
				       cfg->max_connections);
				continue;
			}
			cmd_conn_send_error(
			        d, old, NULL, RP_ERR_TOO_MANY_CONNECTIONS,
			        "closed to make room for a new connection: no "
			        "hello %.1f s after connecting",
			        now - old->opened);
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
		c->last_active = c->opened = now;
		if (tls && !(c->ssl = cmd_tls_new(d, fd))) {
			srv_warn("connection from %s: no TLS session", peer);
			close(fd);
			free(c);
			continue;
		}
		memcpy(c->addr, key, (size_t)klen);
		c->addr_len = klen;
		snprintf(c->peer, sizeof(c->peer), "%s", peer);
		if (el_watch_add(d->loop, &c->w, fd, EL_READABLE, conn_ready,
		                 d) != 0) {
			SSL_free(c->ssl);
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

/* Write what the socket takes of the queue: a gather write, or one
 * chunk through the TLS session. */
static ssize_t conn_write(cmd_conn *c)
{
	if (c->ssl) {
		cmd_chunk *k = c->out_head;
		if (!c->tls_ready) {
			errno = EAGAIN;
			return -1;
		}
		return cmd_tls_write(c->ssl, k->buf + k->off, k->len - k->off);
	}
	struct iovec iov[32];
	int n = 0;
	for (cmd_chunk *k = c->out_head; k && n < 32; k = k->next) {
		iov[n].iov_base = k->buf + k->off;
		iov[n].iov_len = k->len - k->off;
		n++;
	}
	struct msghdr mh = {.msg_iov = iov, .msg_iovlen = (size_t)n};
	return sendmsg(c->fd, &mh, MSG_NOSIGNAL | MSG_DONTWAIT);
}

static void flush(cmd_server *d, cmd_conn *c)
{
	while (c->out_head && !c->dead) {
		ssize_t w = conn_write(c);
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
			cmd_tls_close_notify(c->ssl);
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
		cmd_refusal why = refusal_of(code);
		if (why != CMD_REFUSED_COUNT)
			d->refused[why]++;
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
			/* The header deadline runs until the line is in. */
			if (c->need)
				c->hdr_start = 0;
			else if (c->hdr_start == 0)
				c->hdr_start = rad_seconds();
			break;
		}
		if (rc == RP_DECODE_ERROR) {
			cmd_conn_send_error(d, c, NULL, err.code, "%s",
			                    err.msg);
			break;
		}
		c->need = 0;
		c->hdr_start = 0;
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
	if (c->ssl && !c->tls_ready) {
		/* A plain protocol client on a TLS listener: tell it so, in
		 * its own words, instead of a failed handshake. */
		char first = 0;
		if (recv(c->fd, &first, 1, MSG_PEEK | MSG_DONTWAIT) == 1 &&
		    first == '{') {
			SSL_free(c->ssl);
			c->ssl = NULL;
			cmd_conn_send_error(d, c, NULL, RP_ERR_BAD_FRAME,
			                    "this listener speaks TLS: connect "
			                    "with tls://HOST:PORT");
			return;
		}
		char why[256] = "";
		int h = cmd_tls_handshake(c->ssl, why, sizeof(why));
		if (h < 0) {
			srv_info("connection %llu (%s): TLS handshake failed: "
			         "%s",
			         (unsigned long long)c->id, c->peer,
			         why[0] ? why : strerror(errno));
			c->dead = 1;
			return;
		}
		if (h == 0)
			return; /* the hello deadline bounds the handshake */
		c->tls_ready = 1;
		c->last_active = rad_seconds();
		flush(d, c);
	}
	while (budget > 0) {
		if (reserve(d, c) != 0) {
			cmd_conn_send_error(
			        d, c, NULL, RP_ERR_NOMEM,
			        "out of memory for the input buffer");
			c->dead = 1;
			return;
		}
		ssize_t n = c->ssl ? cmd_tls_read(c->ssl, c->in + c->in_len,
		                                  c->in_cap - c->in_len)
		                   : read(c->fd, c->in + c->in_len,
		                          c->in_cap - c->in_len);
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
		if ((c->need && c->in_len - c->in_off < c->need) ||
		    cmd_tls_pending(c->ssl))
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
	SSL_free(c->ssl);
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
	const srv_config *cfg = &d->core.cfg;
	double idle = cfg->idle_timeout_s, hello = cfg->hello_timeout_s,
	       header = cfg->header_timeout_s;
	lingers_tick(d, now, 0);
	for (cmd_conn *c = d->conns; c; c = c->next) {
		if (c->dead)
			continue;
		if (c->closing) {
			if (now >= c->close_at)
				c->dead = 1;
			continue;
		}
		/* What OpenSSL holds decrypted: the socket no longer says. */
		if (c->reading && cmd_tls_pending(c->ssl)) {
			conn_readable(d, c);
			if (c->dead || c->closing)
				continue;
		}
		if (hello > 0 && !c->authed && now - c->opened > hello)
			cmd_conn_send_error(d, c, NULL, RP_ERR_HELLO_TIMEOUT,
			                    "no hello %g s after connecting",
			                    hello);
		else if (header > 0 && c->hdr_start > 0 && c->reading &&
		         now - c->hdr_start > header)
			cmd_conn_send_error(d, c, NULL, RP_ERR_HEADER_TIMEOUT,
			                    "a request header was not complete "
			                    "%g s after its first byte",
			                    header);
		else if (idle > 0 && !c->busy && !c->out_head &&
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
	lingers_tick(d, 0, 1);
	if (d->spare_fd >= 0)
		close(d->spare_fd);
	d->spare_fd = -1;
}
