/*
 * modbus.c -- the Modbus TCP server of luxradd: its thread, its sockets
 * and the requests it answers (the register image is mb_image.c, the
 * config keys mb_config.c, the map regmap.h).
 *
 * DESIGN
 * One thread serves every client with poll(2): the listening socket, a
 * wake-up pipe (mb_server_stop) and each client.  Client sockets are
 * non-blocking; each client has a buffer the size of the largest Modbus
 * TCP frame (260 bytes) and bytes are appended as they come.  A request
 * is handed on only once its whole frame is buffered (the MBAP header's
 * length says how long it is), so a client that sends half a frame costs
 * a buffer and a timer, never a blocked call: libmodbus's own receive
 * path (modbus_receive) is not used because it blocks until a request is
 * complete.  libmodbus builds and sends every response (modbus_reply,
 * modbus_reply_exception) from a mapping made on the stack for the
 * request: the registers asked for, copied from the image in one lock
 * hold, so the response is one consistent snapshot.
 *
 * What is answered (MODBUS.md, "Requests"):
 *   - 0x04 read input registers, the only function served; quantity
 *     outside 1..125 or a PDU of the wrong length -> 03 ILLEGAL DATA
 *     VALUE; a register outside the served blocks -> 02 ILLEGAL DATA
 *     ADDRESS;
 *   - every other function code, reads of holding registers (0x03),
 *     coils and discrete inputs and every write among them -> 01 ILLEGAL
 *     FUNCTION: the map has no writable object and no other table;
 *     (function codes 0x80..0xFF, exception codes that are never a
 *     valid request, get 01 with the same code, fc | 0x80);
 *   - unit ids: the configured one, 0 and 255 (Modbus TCP practice for a
 *     device addressed by IP); any other -> 0B GATEWAY TARGET DEVICE
 *     FAILED TO RESPOND, an answer at once rather than a client timeout.
 * A frame whose MBAP protocol id is not 0 or whose length is outside
 * 2..254 is not Modbus TCP: the connection is closed (bad_frames).  So
 * is a client whose request stays incomplete past frame_timeout, or that
 * is silent past idle_timeout (timeouts), or that does not read its
 * responses (a send that would block fails and closes it).  Connections
 * beyond max_clients are accepted and closed at once (rejected).
 *
 * Counters are under stats_mu (the Modbus thread writes, any thread
 * reads); the client table, the pollfd array and the libmodbus context
 * belong to the Modbus thread alone.
 */
#include "modbus.h"

#include <errno.h>
#include <fcntl.h>
#include <modbus/modbus.h> /* not "modbus.h": that is ours */
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "mb_image.h"

#define FRAME_MAX MODBUS_TCP_MAX_ADU_LENGTH /* 260: MBAP 7 + PDU 253 */
#define MBAP_LEN_MAX 254                    /* unit id + PDU */
#define EXC_GATEWAY_TARGET 0x0B

typedef struct client {
	int fd;        /* -1: closed, removed after the poll round */
	size_t have;   /* bytes buffered */
	double since;  /* first byte of the incomplete request; 0 */
	double last;   /* last byte received (or connect) */
	char peer[80]; /* "addr:port", for logs */
	uint8_t buf[FRAME_MAX];
} client;

struct mb_server {
	mb_config cfg; /* immutable */
	mb_image *img; /* shared with publishers (its own lock) */
	mb_log_fn log; /* may be NULL */
	void *log_ud;
	int lfd;     /* listening socket; -1 when off */
	int wake[2]; /* pipe: a byte means stop */
	int port;    /* bound port; -1 when off */
	pthread_t thread;
	int started; /* thread created (joined by stop) */
	/* Modbus thread only */
	modbus_t *ctx; /* builds and sends responses */
	client *cl;    /* cfg.max_clients entries, ncl in use */
	int ncl;
	struct pollfd *pfd;       /* wake, listener, clients */
	double accept_pause_till; /* out of fds: stop accepting till */
	/* stats */
	pthread_mutex_t stats_mu; /* guards st */
	mb_stats st;
};

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

__attribute__((format(printf, 3, 4))) static void logf_(mb_server *s, int level,
                                                        const char *fmt, ...)
{
	if (!s->log)
		return;
	char line[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(line, sizeof line, fmt, ap);
	va_end(ap);
	s->log(s->log_ud, level, line);
}

/* Add delta (unsigned, so -(uint64_t)k subtracts k) to a counter. */
#define BUMP(s, field, delta)                                                  \
	do {                                                                   \
		pthread_mutex_lock(&(s)->stats_mu);                            \
		(s)->st.field += (delta);                                      \
		pthread_mutex_unlock(&(s)->stats_mu);                          \
	} while (0)

static void set_state(mb_server *s, mb_state st)
{
	pthread_mutex_lock(&s->stats_mu);
	s->st.state = st;
	pthread_mutex_unlock(&s->stats_mu);
}

const char *mb_state_name(mb_state st)
{
	static const char *const names[] = {"off", "listening", "failed"};
	return (unsigned)st < sizeof names / sizeof names[0] ? names[st] : "?";
}

/* ---------------------------------------------------------------- clients */

static void client_close(mb_server *s, client *c, const char *why)
{
	logf_(s, 3, "modbus: client %s closed (%s)", c->peer, why);
	close(c->fd);
	c->fd = -1;
}

/* Remove closed clients from the table (after a poll round). */
static void compact(mb_server *s)
{
	int j = 0;
	for (int i = 0; i < s->ncl; i++)
		if (s->cl[i].fd >= 0) {
			if (i != j)
				s->cl[j] = s->cl[i];
			j++;
		}
	if (j != s->ncl) {
		BUMP(s, clients, -(uint64_t)(s->ncl - j));
		s->ncl = j;
		mb_image_set_clients(s->img, (unsigned)j);
	}
}

static void peer_name(int fd, char *out, size_t len)
{
	struct sockaddr_storage ss;
	socklen_t sl = sizeof ss;
	char host[64] = "?", serv[16] = "?";
	if (getpeername(fd, (struct sockaddr *)&ss, &sl) == 0)
		getnameinfo((struct sockaddr *)&ss, sl, host, sizeof host, serv,
		            sizeof serv, NI_NUMERICHOST | NI_NUMERICSERV);
	snprintf(out, len, "%s%s%s:%s", ss.ss_family == AF_INET6 ? "[" : "",
	         host, ss.ss_family == AF_INET6 ? "]" : "", serv);
}

static void accept_all(mb_server *s, double now)
{
	for (;;) {
		int fd = accept4(s->lfd, NULL, NULL,
		                 SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0) {
			if (errno == EMFILE || errno == ENFILE ||
			    errno == ENOBUFS || errno == ENOMEM) {
				logf_(s, 1, "modbus: accept: %s; pausing 1 s",
				      strerror(errno));
				s->accept_pause_till = now + 1;
			}
			return; /* EAGAIN, ECONNABORTED, EINTR... */
		}
		char peer[80];
		peer_name(fd, peer, sizeof peer);
		if (s->ncl >= s->cfg.max_clients) {
			logf_(s, 2,
			      "modbus: client %s refused: %d clients "
			      "already (modbus_max_clients)",
			      peer, s->ncl);
			close(fd);
			BUMP(s, rejected, 1);
			continue;
		}
		int one = 1;
		setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
		client *c = &s->cl[s->ncl++];
		memset(c, 0, offsetof(client, buf));
		c->fd = fd;
		c->last = now;
		memcpy(c->peer, peer, sizeof peer);
		BUMP(s, accepted, 1);
		BUMP(s, clients, 1);
		mb_image_set_clients(s->img, (unsigned)s->ncl);
		logf_(s, 3, "modbus: client %s connected", c->peer);
	}
}

/* ---------------------------------------------------------------- requests */

/* The exception code for a complete frame f of n bytes, or 0 and the
 * registers asked for in regs / *addr / *count. */
static int check_request(mb_server *s, const uint8_t *f, size_t n,
                         uint16_t *regs, unsigned *addr, unsigned *count)
{
	unsigned unit = f[6], fc = f[7];
	if (unit != (unsigned)s->cfg.unit_id && unit != 0 && unit != 0xFF)
		return EXC_GATEWAY_TARGET;
	if (fc != 0x04)
		return MODBUS_EXCEPTION_ILLEGAL_FUNCTION;
	if (n != 12) /* MBAP 7 + fc 1 + address 2 + quantity 2 */
		return MODBUS_EXCEPTION_ILLEGAL_DATA_VALUE;
	*addr = (unsigned)f[8] << 8 | f[9];
	*count = (unsigned)f[10] << 8 | f[11];
	return mb_image_read(s->img, *addr, *count, regs);
}

/* Answer one complete frame; -1 when the response could not be sent. */
static int answer(mb_server *s, client *c, const uint8_t *f, size_t n)
{
	uint16_t regs[MODBUS_MAX_READ_REGISTERS];
	unsigned addr = 0, count = 0;
	int exc = check_request(s, f, n, regs, &addr, &count), rc;
	modbus_set_socket(s->ctx, c->fd);
	if (exc) {
		/* libmodbus answers fc + 0x80, which wraps for fc >= 0x80
		 * (codes never valid in a request): answer fc | 0x80. */
		uint8_t req[FRAME_MAX];
		memcpy(req, f, n);
		req[7] &= 0x7F;
		rc = modbus_reply_exception(s->ctx, req, (unsigned)exc);
		BUMP(s, exceptions, 1);
		logf_(s, 3,
		      "modbus: client %s: function 0x%02x -> exception "
		      "%d",
		      c->peer, f[7], exc);
	} else {
		modbus_mapping_t map;
		memset(&map, 0, sizeof map);
		map.start_input_registers = (int)addr;
		map.nb_input_registers = (int)count;
		map.tab_input_registers = regs;
		rc = modbus_reply(s->ctx, f, (int)n, &map);
	}
	BUMP(s, requests, 1);
	return rc < 0 ? -1 : 0;
}

/* Answer the complete frames buffered; -1 if c was closed. */
static int drain_frames(mb_server *s, client *c, double now)
{
	int consumed = 0;
	while (c->have >= 6) {
		unsigned proto = (unsigned)c->buf[2] << 8 | c->buf[3];
		unsigned len = (unsigned)c->buf[4] << 8 | c->buf[5];
		if (proto != 0 || len < 2 || len > MBAP_LEN_MAX) {
			client_close(s, c, "not a Modbus TCP frame");
			BUMP(s, bad_frames, 1);
			return -1;
		}
		size_t n = 6 + (size_t)len;
		if (c->have < n)
			break;
		if (answer(s, c, c->buf, n) < 0) {
			client_close(s, c, "response not sent");
			return -1;
		}
		memmove(c->buf, c->buf + n, c->have - n);
		c->have -= n;
		consumed = 1;
	}
	if (!c->have)
		c->since = 0;
	else if (consumed || !c->since)
		c->since = now;
	return 0;
}

static void client_input(mb_server *s, client *c, double now)
{
	ssize_t r = recv(c->fd, c->buf + c->have, sizeof c->buf - c->have, 0);
	if (r == 0) {
		client_close(s, c, "closed by the peer");
		return;
	}
	if (r < 0) {
		if (errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR)
			client_close(s, c, strerror(errno));
		return;
	}
	c->have += (size_t)r;
	c->last = now;
	drain_frames(s, c, now);
}

/* Close clients past their deadlines; the next deadline (or -1). */
static double expire(mb_server *s, double now)
{
	double next = -1;
	for (int i = 0; i < s->ncl; i++) {
		client *c = &s->cl[i];
		if (c->fd < 0)
			continue;
		double partial =
		        c->since ? c->since + s->cfg.frame_timeout_s : -1;
		double idle = s->cfg.idle_timeout_s > 0
		                      ? c->last + s->cfg.idle_timeout_s
		                      : -1;
		if ((partial >= 0 && partial <= now) ||
		    (idle >= 0 && idle <= now)) {
			client_close(s, c,
			             partial >= 0 && partial <= now
			                     ? "request left incomplete"
			                     : "idle");
			BUMP(s, timeouts, 1);
			continue;
		}
		double d = partial < 0 || (idle >= 0 && idle < partial)
		                   ? idle
		                   : partial;
		if (d >= 0 && (next < 0 || d < next))
			next = d;
	}
	return next;
}

/* ------------------------------------------------------------------ thread */

static int poll_timeout_ms(double next, double now)
{
	if (next < 0)
		return -1;
	double ms = (next - now) * 1000 + 1;
	return ms < 0 ? 0 : ms > 60000 ? 60000 : (int)ms;
}

static void *run(void *arg)
{
	mb_server *s = arg;
	double next = -1;
	for (;;) {
		double now = now_s();
		int accepting = now >= s->accept_pause_till;
		s->pfd[0] = (struct pollfd){s->wake[0], POLLIN, 0};
		s->pfd[1] = (struct pollfd){accepting ? s->lfd : -1, POLLIN, 0};
		for (int i = 0; i < s->ncl; i++)
			s->pfd[2 + i] = (struct pollfd){s->cl[i].fd, POLLIN, 0};
		double wake_at = next;
		if (!accepting &&
		    (wake_at < 0 || s->accept_pause_till < wake_at))
			wake_at = s->accept_pause_till;
		int rc = poll(s->pfd, (nfds_t)(2 + s->ncl),
		              poll_timeout_ms(wake_at, now));
		if (rc < 0 && errno != EINTR) {
			logf_(s, 0, "modbus: poll: %s; Modbus server stopped",
			      strerror(errno));
			set_state(s, MB_STATE_FAILED);
			break;
		}
		if (rc > 0 && s->pfd[0].revents)
			break;
		now = now_s();
		/* clients accepted below are polled in the next round */
		int n = s->ncl;
		for (int i = 0; rc > 0 && i < n; i++)
			if (s->pfd[2 + i].revents)
				client_input(s, &s->cl[i], now);
		compact(s);
		if (rc > 0 && (s->pfd[1].revents & POLLIN))
			accept_all(s, now);
		next = expire(s, now);
		compact(s);
	}
	for (int i = 0; i < s->ncl; i++)
		client_close(s, &s->cl[i], "server stopping");
	compact(s);
	return NULL;
}

/* ------------------------------------------------------------------- API */

__attribute__((format(printf, 3, 4))) static void say(char *msg, size_t len,
                                                      const char *fmt, ...)
{
	if (!msg || !len)
		return;
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, len, fmt, ap);
	va_end(ap);
}

/* Bind and listen with libmodbus; fills s->lfd and s->port. */
static int bind_listener(mb_server *s, const char *host, int port, char *msg,
                         size_t len)
{
	char service[16];
	snprintf(service, sizeof service, "%d", port);
	s->ctx = modbus_new_tcp_pi(host, service);
	if (!s->ctx) {
		say(msg, len, "modbus_listen %s: %s", s->cfg.listen,
		    modbus_strerror(errno));
		return -1;
	}
	s->lfd = modbus_tcp_pi_listen(s->ctx, 64);
	if (s->lfd < 0) {
		say(msg, len, "modbus_listen %s: cannot listen: %s",
		    s->cfg.listen,
		    errno == ECONNREFUSED ? "address not found"
		                          : strerror(errno));
		return -1;
	}
	struct sockaddr_storage ss;
	socklen_t sl = sizeof ss;
	int fl = fcntl(s->lfd, F_GETFL);
	if (fl < 0 || fcntl(s->lfd, F_SETFL, fl | O_NONBLOCK) < 0 ||
	    fcntl(s->lfd, F_SETFD, FD_CLOEXEC) < 0 ||
	    getsockname(s->lfd, (struct sockaddr *)&ss, &sl) < 0) {
		say(msg, len, "modbus_listen %s: %s", s->cfg.listen,
		    strerror(errno));
		return -1;
	}
	s->port = ntohs(ss.ss_family == AF_INET6
	                        ? ((struct sockaddr_in6 *)&ss)->sin6_port
	                        : ((struct sockaddr_in *)&ss)->sin_port);
	return 0;
}

static void server_free(mb_server *s)
{
	if (s->lfd >= 0)
		close(s->lfd);
	for (int k = 0; k < 2; k++)
		if (s->wake[k] >= 0)
			close(s->wake[k]);
	if (s->ctx) {
		modbus_set_socket(s->ctx, -1);
		modbus_free(s->ctx);
	}
	mb_image_free(s->img);
	free(s->cl);
	free(s->pfd);
	pthread_mutex_destroy(&s->stats_mu);
	free(s);
}

/* Allocate the server and its image; the listener comes after. */
static mb_server *server_new(const mb_config *c, mb_log_fn log, void *ud)
{
	mb_server *s = calloc(1, sizeof *s);
	if (!s)
		return NULL;
	s->cfg = *c;
	s->log = log;
	s->log_ud = ud;
	s->lfd = s->wake[0] = s->wake[1] = s->port = -1;
	pthread_mutex_init(&s->stats_mu, NULL);
	s->st.port = -1;
	s->img = mb_image_new(c);
	s->cl = calloc((size_t)c->max_clients, sizeof *s->cl);
	s->pfd = calloc((size_t)c->max_clients + 2, sizeof *s->pfd);
	if (!s->img || !s->cl || !s->pfd) {
		server_free(s);
		return NULL;
	}
	return s;
}

mb_server *mb_server_start(const mb_config *c, mb_log_fn log, void *log_ud,
                           char *msg, size_t len)
{
	char host[sizeof c->listen];
	int port;
	if (mb_listen_parse(c->listen, host, sizeof host, &port, msg, len) < 0)
		return NULL;
	mb_server *s = server_new(c, log, log_ud);
	if (!s) {
		say(msg, len, "modbus: out of memory");
		return NULL;
	}
	if (!host[0])
		return s; /* state off */
	if (bind_listener(s, host, port, msg, len) < 0) {
		server_free(s);
		return NULL;
	}
	if (pipe2(s->wake, O_CLOEXEC | O_NONBLOCK) < 0) {
		say(msg, len, "modbus: pipe: %s", strerror(errno));
		server_free(s);
		return NULL;
	}
	s->st.port = s->port;
	s->st.state = MB_STATE_LISTENING;
	sigset_t all, old;
	sigfillset(&all);
	pthread_sigmask(SIG_SETMASK, &all, &old);
	int rc = pthread_create(&s->thread, NULL, run, s);
	pthread_sigmask(SIG_SETMASK, &old, NULL);
	if (rc != 0) {
		say(msg, len, "modbus: thread: %s", strerror(rc));
		server_free(s);
		return NULL;
	}
	s->started = 1;
	logf_(s, 2, "modbus: listening on %s (port %d, unit %d, %s)", c->listen,
	      s->port, c->unit_id, mb_word_order_name(c->word_order));
	return s;
}

int mb_server_port(const mb_server *s)
{
	return s ? s->port : -1;
}

void mb_server_stop(mb_server *s)
{
	if (!s)
		return;
	if (s->started) {
		ssize_t w;
		do
			w = write(s->wake[1], "x", 1);
		while (w < 0 && errno == EINTR);
		pthread_join(s->thread, NULL);
	}
	server_free(s);
}

void mb_server_stats(const mb_server *s, mb_stats *out)
{
	memset(out, 0, sizeof *out);
	out->port = -1;
	if (!s)
		return;
	pthread_mutex_lock((pthread_mutex_t *)&s->stats_mu);
	*out = s->st;
	pthread_mutex_unlock((pthread_mutex_t *)&s->stats_mu);
}

int mb_server_read(mb_server *s, unsigned addr, unsigned n, uint16_t *out)
{
	return s ? mb_image_read(s->img, addr, n, out)
	         : MODBUS_EXCEPTION_ILLEGAL_DATA_ADDRESS;
}

/* ----------------------------------------------------------- publication */

void mb_publish_daemon(mb_server *s, const mb_daemon_vals *v)
{
	if (s)
		mb_image_daemon(s->img, v);
}

int mb_publish_job(mb_server *s, const mb_job_vals *v)
{
	return s ? mb_image_job(s->img, v) : -2;
}

void mb_job_remove(mb_server *s, uint64_t job_id)
{
	if (s)
		mb_image_job_remove(s->img, job_id);
}

int mb_publish_sensor(mb_server *s, uint64_t job_id, const char *name,
                      double lux, uint32_t iteration)
{
	return s ? mb_image_sensor(s->img, job_id, name, lux, iteration) : -2;
}

void mb_sensor_remove(mb_server *s, uint64_t job_id, const char *name)
{
	if (s)
		mb_image_sensor_remove(s->img, job_id, name);
}

int mb_job_slot(mb_server *s, uint64_t job_id)
{
	return s ? mb_image_job_slot(s->img, job_id) : -1;
}

int mb_sensor_slot(mb_server *s, uint64_t job_id, const char *name)
{
	return s ? mb_image_sensor_slot(s->img, job_id, name) : -1;
}
