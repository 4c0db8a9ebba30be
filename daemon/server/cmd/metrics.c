/*
 * metrics.c -- Prometheus text exposition on a tiny HTTP/1.0 server
 * that lives on the I/O loop.
 *
 * GET /metrics answers 200 with "text/plain; version=0.0.4"; any other
 * path is 404, any other method 405.  A request is bounded in size
 * (HTTP_MAX_REQUEST bytes of headers) and time (HTTP_TIMEOUT_S from
 * accept to the last byte sent), and at most HTTP_MAX_CONNS are served
 * at once: a scraper cannot hold the loop or grow our memory.  The body
 * is built from the same summary as the status command, reading job
 * fields under their mutex (copies only).
 */
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "cmd.h"
#include "log.h"

#define HTTP_MAX_REQUEST 8192
#define HTTP_TIMEOUT_S 5.0
#define HTTP_MAX_CONNS 16
#define HTTP_TICK_S 0.1 /* deadlines; closes of answered requests */

typedef struct srv_http {
	el_watch w; /* ud: the srv */
	int fd;
	char req[HTTP_MAX_REQUEST];
	size_t len;
	char *out; /* response, once the request is read */
	size_t out_len, off;
	double deadline;
	int dead;
	struct srv_http *next;
} srv_http;

/* A growing text buffer; on allocation failure it stays truncated and
 * the response is a 500. */
typedef struct sbuf {
	char *b;
	size_t n, cap;
	int failed;
} sbuf;

static void sb_printf(sbuf *sb, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));
static void sb_printf(sbuf *sb, const char *fmt, ...)
{
	va_list ap;
	for (int tries = 0; tries < 2 && !sb->failed; tries++) {
		size_t room = sb->cap - sb->n;
		va_start(ap, fmt);
		int k = vsnprintf(sb->b ? sb->b + sb->n : NULL, room, fmt, ap);
		va_end(ap);
		if (k < 0) {
			sb->failed = 1;
			return;
		}
		if ((size_t)k < room) {
			sb->n += (size_t)k;
			return;
		}
		size_t ncap = (sb->cap + (size_t)k + 1) * 2;
		char *nb = realloc(sb->b, ncap);
		if (!nb) {
			sb->failed = 1;
			return;
		}
		sb->b = nb;
		sb->cap = ncap;
	}
}

static void gauge(sbuf *sb, const char *name, const char *help)
{
	sb_printf(sb, "# HELP %s %s\n# TYPE %s gauge\n", name, help, name);
}

static void metrics_body(cmd_server *d, sbuf *sb)
{
	srv *s = &d->core;
	srv_summary sum;
	srv_summarize(s, &sum);
	gauge(sb, "luxradd_uptime_seconds",
	      "Seconds since the daemon started.");
	sb_printf(sb, "luxradd_uptime_seconds %.3f\n", rad_seconds() - s->t0);
	gauge(sb, "luxradd_connections", "Open protocol connections.");
	sb_printf(sb, "luxradd_connections %d\n", d->nconns);
	int nohello = 0;
	for (const cmd_conn *c = d->conns; c; c = c->next)
		nohello += !c->dead && !c->closing && !c->authed;
	gauge(sb, "luxradd_connections_without_hello",
	      "Open protocol connections that have not said hello yet.");
	sb_printf(sb, "luxradd_connections_without_hello %d\n", nohello);
	sb_printf(sb, "# HELP luxradd_connections_refused_total Connections "
	              "refused at accept or closed by the daemon, by cause.\n"
	              "# TYPE luxradd_connections_refused_total counter\n");
	for (int k = 0; k < CMD_REFUSED_COUNT; k++)
		sb_printf(sb,
		          "luxradd_connections_refused_total{cause=\"%s\"} "
		          "%llu\n",
		          cmd_refusal_name((cmd_refusal)k),
		          (unsigned long long)d->refused[k]);
	gauge(sb, "luxradd_scenes", "Scenes loaded.");
	sb_printf(sb, "luxradd_scenes %d\n", s->nscenes);
	gauge(sb, "luxradd_jobs", "Jobs by state.");
	for (int k = 0; k < SRV_JOB_NSTATES; k++)
		sb_printf(sb, "luxradd_jobs{state=\"%s\"} %d\n",
		          srv_job_state_name((srv_job_state)k),
		          sum.jobs_by_state[k]);
	gauge(sb, "luxradd_memory_bytes",
	      "Engine memory by kind (scenes, solvers, solutions).");
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		sb_printf(sb, "luxradd_memory_bytes{kind=\"%s\"} %lld\n",
		          rad_mem_kind_name((rad_mem_kind)k),
		          (long long)sum.by_kind[k]);
	gauge(sb, "luxradd_memory_limit_bytes",
	      "The engine's memory limit (memory_limit, resolved).");
	sb_printf(sb, "luxradd_memory_limit_bytes %lld\n",
	          (long long)s->mem_limit);
	sb_printf(
	        sb,
	        "# HELP luxradd_memory_limit_refusals_total Engine "
	        "allocations refused by the memory limit (solver "
	        "processes included).\n"
	        "# TYPE luxradd_memory_limit_refusals_total counter\n"
	        "luxradd_memory_limit_refusals_total %llu\n",
	        (unsigned long long)(s->mem_share
	                                     ? __atomic_load_n(
	                                               &s->mem_share->refusals,
	                                               __ATOMIC_RELAXED)
	                                     : rad_mem_limit_refusals()));
	sb_printf(sb,
	          "# HELP luxradd_events_dropped_total Progress events "
	          "dropped for slow subscribers.\n"
	          "# TYPE luxradd_events_dropped_total counter\n"
	          "luxradd_events_dropped_total %llu\n",
	          (unsigned long long)d->events_dropped);
	sb_printf(sb, "# HELP luxradd_commands_total Requests by command.\n"
	              "# TYPE luxradd_commands_total counter\n");
	for (int k = 0; k < RP_CMD_COUNT; k++)
		sb_printf(sb, "luxradd_commands_total{cmd=\"%s\"} %llu\n",
		          rp_cmd_name((rp_cmd)k),
		          (unsigned long long)d->cmd_calls[k]);
	char *mbt = cmd_mb_metrics_text(d);
	if (mbt)
		sb_printf(sb, "%s", mbt);
	free(mbt);
	static const char *const names[4][2] = {
	        {"luxradd_job_iteration", "Iterations done."},
	        {"luxradd_job_residual", "Residual of the last iteration."},
	        {"luxradd_job_links", "Links stored."},
	        {"luxradd_job_memory_bytes", "Solver and solution memory."}};
	for (int m = 0; m < 4; m++) {
		gauge(sb, names[m][0], names[m][1]);
		for (srv_job *j = s->jobs; j; j = j->next) {
			pthread_mutex_lock(&j->mu);
			double v = m == 0   ? (double)j->iteration
			           : m == 1 ? j->residual
			           : m == 2 ? (double)j->links
			                    : (double)srv_job_memory_locked(j);
			pthread_mutex_unlock(&j->mu);
			sb_printf(sb, "%s{job=\"%llu\"} %.17g\n", names[m][0],
			          (unsigned long long)j->id, v);
		}
	}
}

/* Build the whole response for the request line in h->req. */
static void respond(cmd_server *d, srv_http *h)
{
	char method[16] = "", path[256] = "";
	const char *status = "200 OK";
	sbuf body = {0}, out = {0};

	if (sscanf(h->req, "%15s %255s", method, path) != 2)
		status = "400 Bad Request";
	else if (strcmp(method, "GET") != 0 && strcmp(method, "HEAD") != 0)
		status = "405 Method Not Allowed";
	else if (strcmp(path, "/metrics") != 0 &&
	         strncmp(path, "/metrics?", 9) != 0)
		status = "404 Not Found";
	if (status[0] == '2')
		metrics_body(d, &body);
	else
		sb_printf(&body, "%s\n", status);
	if (body.failed)
		status = "500 Internal Server Error";
	sb_printf(&out,
	          "HTTP/1.0 %s\r\nContent-Type: %s\r\nContent-Length: "
	          "%zu\r\nConnection: close\r\n\r\n",
	          status,
	          status[0] == '2' ? "text/plain; version=0.0.4; charset=utf-8"
	                           : "text/plain; charset=utf-8",
	          body.failed ? 0 : body.n);
	if (!body.failed && strcmp(method, "HEAD") != 0 && body.n)
		sb_printf(&out, "%.*s", (int)body.n, body.b);
	free(body.b);
	if (out.failed) {
		free(out.b);
		h->dead = 1;
		return;
	}
	h->out = out.b;
	h->out_len = out.n;
	el_watch_set(d->loop, &h->w, EL_WRITABLE);
}

static void http_ready(el_loop *l, el_watch *w, unsigned events);
static double http_tick(el_loop *l, void *ud, double now);

void cmd_metrics_accept(cmd_server *d, int lfd)
{
	if (!d->http_timer)
		d->http_timer =
		        el_timer_add(d->loop, HTTP_TICK_S, http_tick, d);
	for (;;) {
		int fd = accept4(lfd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0)
			return;
		srv_http *h = d->nhttps < HTTP_MAX_CONNS ? calloc(1, sizeof(*h))
		                                         : NULL;
		if (!h) {
			close(fd);
			continue;
		}
		h->fd = fd;
		h->deadline = rad_seconds() + HTTP_TIMEOUT_S;
		if (el_watch_add(d->loop, &h->w, fd, EL_READABLE, http_ready,
		                 d) != 0) {
			close(fd);
			free(h);
			continue;
		}
		h->next = d->https;
		d->https = h;
		d->nhttps++;
	}
}

static void http_read(cmd_server *d, srv_http *h)
{
	ssize_t n = read(h->fd, h->req + h->len, sizeof(h->req) - 1 - h->len);
	if (n <= 0) {
		if (n == 0 || (errno != EAGAIN && errno != EINTR))
			h->dead = 1;
		return;
	}
	h->len += (size_t)n;
	h->req[h->len] = '\0';
	if (strstr(h->req, "\r\n\r\n") || strstr(h->req, "\n\n"))
		respond(d, h);
	else if (h->len >= sizeof(h->req) - 1)
		h->dead = 1; /* headers over the limit: no answer */
}

static void http_write(srv_http *h)
{
	while (h->off < h->out_len) {
		ssize_t w = send(h->fd, h->out + h->off, h->out_len - h->off,
		                 MSG_NOSIGNAL | MSG_DONTWAIT);
		if (w < 0) {
			if (errno != EAGAIN && errno != EINTR)
				h->dead = 1;
			return;
		}
		h->off += (size_t)w;
	}
	h->dead = 1; /* all sent: HTTP/1.0 closes */
}

static void http_reap(cmd_server *d)
{
	srv_http **pp = (srv_http **)&d->https;
	while (*pp) {
		srv_http *h = *pp;
		if (h->dead) {
			*pp = h->next;
			el_watch_del(d->loop, &h->w);
			close(h->fd);
			free(h->out);
			free(h);
			d->nhttps--;
		} else {
			pp = &h->next;
		}
	}
}

static void http_ready(el_loop *l, el_watch *w, unsigned events)
{
	cmd_server *d = w->ud;
	srv_http *h = (srv_http *)((char *)w - offsetof(srv_http, w));
	(void)l;
	if (h->dead)
		return;
	if (events & EL_ERROR && !(events & EL_READABLE))
		h->dead = 1;
	else if (h->out)
		http_write(h);
	else
		http_read(d, h);
	if (h->out && !h->dead && h->off == 0)
		http_write(h);
	if (h->dead) /* HTTP/1.0: the close ends the response */
		http_reap(d);
}

/* Timer: requests past their deadline; connections done with. */
static double http_tick(el_loop *l, void *ud, double now)
{
	cmd_server *d = ud;
	(void)l;
	for (srv_http *h = d->https; h; h = h->next)
		if (now >= h->deadline)
			h->dead = 1;
	http_reap(d);
	return HTTP_TICK_S;
}

void cmd_metrics_free_all(cmd_server *d)
{
	for (srv_http *h = d->https; h; h = h->next)
		h->dead = 1;
	http_reap(d);
}
