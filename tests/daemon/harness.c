/*
 * harness.c -- luxradd as a child process, client connections with
 * deadlines, request/reply helpers.  See harness.h for the design.
 */
#include "harness.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <arpa/inet.h>
#include <cmocka.h>

#include "rp.h"

#ifndef LUXRAD_DAEMON_PATH
#error "LUXRAD_DAEMON_PATH must name the luxradd binary"
#endif

#define MAX_DAEMONS 16
#define MAX_CONNS 512

static dm_daemon *g_daemons[MAX_DAEMONS];
static dm_conn *g_conns[MAX_CONNS];
static int g_passed;
static int g_logs_printed; /* dm_fail printed them already */
/* For the watchdog: plain copies readable from a signal handler. */
static volatile pid_t g_pids[MAX_DAEMONS];
static char g_roots[MAX_DAEMONS][256];

static void cmocka_fail(const char *msg)
{
	fail_msg("%s", msg);
}

void (*dm_fail_hook)(const char *msg) = cmocka_fail;

/* ------------------------------------------------------------- failures */

void dm_print_log(const dm_daemon *d, size_t max_bytes)
{
	FILE *f = fopen(d->log_path, "rb");
	if (!f) {
		fprintf(stderr, "(no daemon log at %s)\n", d->log_path);
		return;
	}
	fseek(f, 0, SEEK_END);
	long size = ftell(f);
	long from = size > (long)max_bytes ? size - (long)max_bytes : 0;
	fseek(f, from, SEEK_SET);
	fprintf(stderr, "----- luxradd log %s%s -----\n", d->log_path,
	        from ? " (tail)" : "");
	char buf[4096];
	size_t n;
	while ((n = fread(buf, 1, sizeof(buf), f)) > 0)
		fwrite(buf, 1, n, stderr);
	fprintf(stderr, "----- end of log -----\n");
	fclose(f);
}

static void print_all_logs(void)
{
	for (int i = 0; i < MAX_DAEMONS; i++)
		if (g_daemons[i]) {
			dm_print_log(g_daemons[i], 16384);
			g_daemons[i]->keep_dir = 1;
		}
}

void dm_fail(const char *fmt, ...)
{
	char msg[2048];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof(msg), fmt, ap);
	va_end(ap);
	fprintf(stderr, "harness: %s\n", msg);
	if (!g_logs_printed)
		print_all_logs();
	g_logs_printed = 1;
	dm_fail_hook(msg);
	abort(); /* the hook does not return */
}

/* ------------------------------------------------------------- watchdog */

static void watchdog(int sig)
{
	(void)sig;
	static const char m[] = "\nharness: watchdog: the test took too long; "
	                        "daemons killed, data kept in:\n";
	ssize_t r = write(2, m, sizeof(m) - 1);
	for (int i = 0; i < MAX_DAEMONS; i++) {
		if (g_pids[i] > 0)
			kill(g_pids[i], SIGKILL);
		if (g_roots[i][0]) {
			r = write(2, g_roots[i], strlen(g_roots[i]));
			r = write(2, "\n", 1);
		}
	}
	(void)r;
	_exit(3);
}

int dm_setup(void **state)
{
	(void)state;
	g_passed = 0;
	g_logs_printed = 0;
	signal(SIGPIPE, SIG_IGN);
	signal(SIGALRM, watchdog);
	const char *t = getenv("LUXRAD_TEST_TIMEOUT");
	int secs = t ? atoi(t) : 170;
	alarm(secs > 0 ? (unsigned)secs : 170);
	return 0;
}

static void rm_rf(const char *path)
{
	char cmd[600];
	snprintf(cmd, sizeof(cmd), "rm -rf '%s'", path);
	int r = system(cmd);
	(void)r;
}

static void daemon_forget(dm_daemon *d)
{
	for (int i = 0; i < MAX_DAEMONS; i++)
		if (g_daemons[i] == d) {
			g_daemons[i] = NULL;
			g_pids[i] = 0;
			g_roots[i][0] = 0;
		}
}

int dm_teardown(void **state)
{
	(void)state;
	alarm(0);
	for (int i = 0; i < MAX_CONNS; i++)
		if (g_conns[i])
			dm_close(g_conns[i]);
	if (!g_passed && !g_logs_printed)
		print_all_logs();
	for (int i = 0; i < MAX_DAEMONS; i++) {
		dm_daemon *d = g_daemons[i];
		if (!d)
			continue;
		if (d->pid > 0 && !d->reaped) {
			kill(d->pid, SIGKILL);
			waitpid(d->pid, &d->status, 0);
		}
		char root[256];
		memcpy(root, g_roots[i], sizeof(root));
		if (!g_passed || d->keep_dir || getenv("LUXRAD_TEST_KEEP"))
			fprintf(stderr, "harness: data kept in %s\n", root);
		else
			rm_rf(root);
		for (int k = 0; k < d->nextra; k++)
			free(d->extra[k]);
		daemon_forget(d);
		free(d);
	}
	return 0;
}

void dm_pass(void)
{
	g_passed = 1;
}

/* ---------------------------------------------------------------- time */

double dm_now_ms(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return ts.tv_sec * 1e3 + ts.tv_nsec / 1e6;
}

void dm_sleep_ms(int ms)
{
	struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
	while (nanosleep(&ts, &ts) != 0 && errno == EINTR)
		;
}

/* --------------------------------------------------------------- daemon */

static void spawn(dm_daemon *d)
{
	char *argv[64];
	int n = 0;
	char unix_path[320];
	snprintf(unix_path, sizeof(unix_path), "%s/s.sock", d->dir);
	argv[n++] = (char *)LUXRAD_DAEMON_PATH;
	argv[n++] = (char *)"--data-dir";
	argv[n++] = d->dir;
	argv[n++] = (char *)"--listen-tcp";
	argv[n++] = (char *)"127.0.0.1:0";
	argv[n++] = (char *)"--listen-unix";
	argv[n++] = unix_path;
	argv[n++] = (char *)"--metrics-listen";
	argv[n++] = (char *)"127.0.0.1:0";
	for (int i = 0; i < d->nextra; i++)
		argv[n++] = d->extra[i];
	argv[n] = NULL;

	FILE *lf = fopen(d->log_path, "a");
	if (lf) {
		fprintf(lf, "=== harness: starting");
		for (int i = 0; i < n; i++)
			fprintf(lf, " %s", argv[i]);
		fprintf(lf, "\n");
		fclose(lf);
	}
	fflush(NULL);
	pid_t parent = getpid();
	pid_t pid = fork();
	if (pid < 0)
		dm_fail("fork: %s", strerror(errno));
	if (pid == 0) {
		prctl(PR_SET_PDEATHSIG, SIGKILL);
		if (getppid() != parent)
			_exit(127);
		int fd = open(d->log_path, O_WRONLY | O_CREAT | O_APPEND, 0644);
		int in = open("/dev/null", O_RDONLY);
		if (fd < 0 || in < 0)
			_exit(127);
		dup2(in, 0);
		dup2(fd, 1);
		dup2(fd, 2);
		signal(SIGPIPE, SIG_DFL);
		signal(SIGALRM, SIG_DFL);
		execv(argv[0], argv);
		dprintf(2, "harness: exec %s: %s\n", argv[0], strerror(errno));
		_exit(127);
	}
	d->pid = pid;
	d->reaped = 0;
	d->status = 0;
	for (int i = 0; i < MAX_DAEMONS; i++)
		if (g_daemons[i] == d)
			g_pids[i] = pid;
}

static int split_hostport(const char *s, char *host, size_t hlen, int *port)
{
	const char *colon = strrchr(s, ':');
	if (!colon)
		return -1;
	size_t n = (size_t)(colon - s);
	if (n >= hlen)
		return -1;
	memcpy(host, s, n);
	host[n] = 0;
	if (host[0] == '[') { /* [v6] */
		memmove(host, host + 1, n);
		char *e = strchr(host, ']');
		if (e)
			*e = 0;
	}
	*port = atoi(colon + 1);
	return *port > 0 ? 0 : -1;
}

/* Parse luxradd.addr; 1 when complete (all three listeners), else 0. */
static int read_addr(dm_daemon *d)
{
	char path[320];
	snprintf(path, sizeof(path), "%s/luxradd.addr", d->dir);
	FILE *f = fopen(path, "r");
	if (!f)
		return 0;
	char text[4096];
	size_t n = fread(text, 1, sizeof(text) - 1, f);
	fclose(f);
	text[n] = 0;
	if (n == 0 || text[n - 1] != '\n')
		return 0;
	int got_tcp = 0, got_unix = 0, got_metrics = 0;
	char *save = NULL;
	for (char *line = strtok_r(text, "\n", &save); line;
	     line = strtok_r(NULL, "\n", &save)) {
		if (!strncmp(line, "tcp ", 4))
			got_tcp = !split_hostport(line + 4, d->tcp_host,
			                          sizeof(d->tcp_host),
			                          &d->tcp_port);
		else if (!strncmp(line, "unix ", 5)) {
			snprintf(d->unix_path, sizeof(d->unix_path), "%s",
			         line + 5);
			got_unix = 1;
		} else if (!strncmp(line, "metrics ", 8))
			got_metrics = !split_hostport(line + 8, d->metrics_host,
			                              sizeof(d->metrics_host),
			                              &d->metrics_port);
	}
	return got_tcp && got_unix && got_metrics;
}

static void wait_ready(dm_daemon *d)
{
	double end = dm_now_ms() + DM_START_MS;
	while (dm_now_ms() < end) {
		if (read_addr(d))
			return;
		if (!dm_alive(d))
			dm_fail("luxradd exited during start-up (status %s %d) "
			        "before writing %s/luxradd.addr",
			        WIFEXITED(d->status) ? "exit" : "signal",
			        WIFEXITED(d->status) ? WEXITSTATUS(d->status)
			                             : WTERMSIG(d->status),
			        d->dir);
		dm_sleep_ms(20);
	}
	dm_fail("luxradd did not write a complete %s/luxradd.addr (tcp, "
	        "unix, metrics lines) within %d ms",
	        d->dir, DM_START_MS);
}

static dm_daemon *daemon_new(const char *const *extra)
{
	dm_daemon *d = calloc(1, sizeof(*d));
	if (!d)
		dm_fail("out of memory");
	int slot = -1;
	for (int i = 0; i < MAX_DAEMONS; i++)
		if (!g_daemons[i]) {
			slot = i;
			break;
		}
	if (slot < 0)
		dm_fail("too many daemons in one test");
	char root[] = "/tmp/luxradd-test-XXXXXX";
	if (!mkdtemp(root))
		dm_fail("mkdtemp: %s", strerror(errno));
	snprintf(g_roots[slot], sizeof(g_roots[slot]), "%s", root);
	snprintf(d->dir, sizeof(d->dir), "%s/data", root);
	snprintf(d->log_path, sizeof(d->log_path), "%s/daemon.log", root);
	if (mkdir(d->dir, 0700) != 0)
		dm_fail("mkdir %s: %s", d->dir, strerror(errno));
	for (int i = 0; extra && extra[i]; i++) {
		if (d->nextra == 32)
			dm_fail("too many extra flags");
		d->extra[d->nextra++] = strdup(extra[i]);
	}
	g_daemons[slot] = d;
	return d;
}

dm_daemon *dm_start(const char *const *extra)
{
	dm_daemon *d = daemon_new(extra);
	spawn(d);
	wait_ready(d);
	return d;
}

void dm_restart(dm_daemon *d)
{
	if (d->pid > 0 && !d->reaped && dm_alive(d))
		dm_fail("dm_restart: the daemon is still running");
	char path[320];
	snprintf(path, sizeof(path), "%s/luxradd.addr", d->dir);
	unlink(path);
	d->tcp_port = d->metrics_port = 0;
	d->unix_path[0] = 0;
	spawn(d);
	wait_ready(d);
}

int dm_start_expect_exit(const char *const *extra, int timeout_ms)
{
	dm_daemon *d = daemon_new(extra);
	spawn(d);
	if (!dm_wait_exit(d, timeout_ms)) {
		dm_kill9(d);
		return -1;
	}
	return WIFEXITED(d->status) ? WEXITSTATUS(d->status)
	                            : 128 + WTERMSIG(d->status);
}

void dm_signal(dm_daemon *d, int sig)
{
	if (d->pid > 0 && !d->reaped)
		kill(d->pid, sig);
}

int dm_alive(dm_daemon *d)
{
	if (d->pid <= 0 || d->reaped)
		return 0;
	pid_t r = waitpid(d->pid, &d->status, WNOHANG);
	if (r == d->pid) {
		d->reaped = 1;
		return 0;
	}
	return 1;
}

int dm_wait_exit(dm_daemon *d, int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	do {
		if (!dm_alive(d))
			return 1;
		dm_sleep_ms(10);
	} while (dm_now_ms() < end);
	return !dm_alive(d);
}

void dm_kill9(dm_daemon *d)
{
	dm_signal(d, SIGKILL);
	if (d->pid > 0 && !d->reaped) {
		waitpid(d->pid, &d->status, 0);
		d->reaped = 1;
	}
}

void dm_stop(dm_daemon *d)
{
	dm_signal(d, SIGTERM);
	if (!dm_wait_exit(d, DM_EXIT_MS))
		dm_fail("luxradd did not exit within %d ms of SIGTERM",
		        DM_EXIT_MS);
	if (!WIFEXITED(d->status) || WEXITSTATUS(d->status) != 0)
		dm_fail("luxradd stopped by SIGTERM: %s %d (want exit 0)",
		        WIFEXITED(d->status) ? "exit status" : "signal",
		        WIFEXITED(d->status) ? WEXITSTATUS(d->status)
		                             : WTERMSIG(d->status));
}

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
	for (int i = 0; i < MAX_CONNS; i++)
		if (!g_conns[i]) {
			g_conns[i] = c;
			return c;
		}
	dm_fail("too many connections in one test");
}

static dm_conn *connect_tcp(const char *host, int port, int rcvbuf)
{
	int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0)
		dm_fail("socket: %s", strerror(errno));
	if (rcvbuf > 0)
		setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf));
	struct sockaddr_in sa = {.sin_family = AF_INET,
	                         .sin_port = htons((uint16_t)port)};
	if (inet_pton(AF_INET, host, &sa.sin_addr) != 1)
		dm_fail("bad daemon address %s", host);
	if (connect(fd, (struct sockaddr *)&sa, sizeof(sa)) != 0)
		dm_fail("connect %s:%d: %s", host, port, strerror(errno));
	int one = 1;
	setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
	return conn_new(fd, "tcp");
}

dm_conn *dm_connect_tcp(const dm_daemon *d)
{
	return connect_tcp(d->tcp_host, d->tcp_port, 0);
}

dm_conn *dm_connect_tcp_rcvbuf(const dm_daemon *d, int rcvbuf)
{
	return connect_tcp(d->tcp_host, d->tcp_port, rcvbuf);
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
	for (int i = 0; i < MAX_CONNS; i++)
		if (g_conns[i] == c)
			g_conns[i] = NULL;
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
	double end = dm_now_ms() + (c->send_ms > 0 ? c->send_ms : DM_REPLY_MS);
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
static json_t *call_json(dm_conn *c, json_t *h, const void *payload, size_t len,
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

json_t *dm_call(dm_conn *c, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	va_end(ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	return call_json(c, h, NULL, 0, DM_REPLY_MS, 1);
}

json_t *dm_call_maybe(dm_conn *c, int timeout_ms, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	va_end(ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	return call_json(c, h, NULL, 0, timeout_ms, 0);
}

json_t *dm_call_payload(dm_conn *c, const void *payload, size_t len,
                        const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	va_end(ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	return call_json(c, h, payload, len, DM_REPLY_MS, 1);
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

static char *dumps(const json_t *j)
{
	char *s = json_dumps(j, JSON_COMPACT);
	if (s && strlen(s) > 1500)
		strcpy(s + 1490, "...");
	return s;
}

static void require_ok(const json_t *r, const char *what)
{
	if (!json_is_true(json_object_get(r, "ok"))) {
		char *s = dumps(r);
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
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	va_end(ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	char what[64];
	snprintf(what, sizeof(what), "%s",
	         json_string_value(json_object_get(h, "cmd")));
	json_t *r = call_json(c, h, NULL, 0, DM_REPLY_MS, 1);
	require_ok(r, what);
	return r;
}

json_t *dm_err(dm_conn *c, const char *code, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	json_error_t je;
	json_t *h = json_vpack_ex(&je, 0, fmt, ap);
	va_end(ap);
	if (!h)
		dm_fail("json_pack '%s': %s", fmt, je.text);
	char *req = dumps(h);
	char reqs[600];
	snprintf(reqs, sizeof(reqs), "%s", req ? req : "?");
	free(req);
	json_t *r = call_json(c, h, NULL, 0, DM_REPLY_MS, 0);
	if (!r)
		dm_fail("%s: no reply (wanted error %s)", reqs, code);
	if (strcmp(dm_err_code(r), code) != 0) {
		char *s = dumps(r);
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

/* ------------------------------------------------------- daemon helpers */

json_t *dm_upload_file(dm_conn *c, const char *path, const char *name)
{
	size_t len;
	unsigned char *bytes = dm_read_file(path, &len);
	json_t *r = dm_call_payload(c, bytes, len, "{s:s, s:s}", "cmd",
	                            "scene.upload", "name", name);
	free(bytes);
	require_ok(r, "scene.upload");
	json_t *id = json_object_get(r, "scene");
	if (!id)
		dm_fail("scene.upload reply without \"scene\"");
	json_incref(id);
	json_decref(r);
	return id;
}

json_t *dm_job_create(dm_conn *c, const json_t *scene, const char *solver,
                      const json_t *options)
{
	json_t *h = json_pack("{s:s, s:O}", "cmd", "job.create", "scene",
	                      (json_t *)scene);
	if (solver)
		json_object_set_new(h, "solver", json_string(solver));
	if (options)
		json_object_set_new(h, "options", json_deep_copy(options));
	json_t *r = call_json(c, h, NULL, 0, DM_REPLY_MS, 1);
	require_ok(r, "job.create");
	json_t *id = json_object_get(r, "job");
	if (!id)
		dm_fail("job.create reply without \"job\"");
	json_incref(id);
	json_decref(r);
	return id;
}

const char *dm_job_state(dm_conn *c, const json_t *job)
{
	static char state[32];
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
	const char *s = json_string_value(
	        json_object_get(json_object_get(r, "job"), "state"));
	snprintf(state, sizeof(state), "%s", s ? s : "?");
	json_decref(r);
	return state;
}

static int state_in(const char *state, const char *states)
{
	size_t n = strlen(state);
	const char *p = states;
	while (*p) {
		const char *bar = strchr(p, '|');
		size_t len = bar ? (size_t)(bar - p) : strlen(p);
		if (len == n && !strncmp(p, state, n))
			return 1;
		if (!bar)
			break;
		p = bar + 1;
	}
	return 0;
}

json_t *dm_wait_job(dm_conn *c, const json_t *job, const char *states,
                    int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	char last[32] = "?";
	for (;;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		json_t *j = json_object_get(r, "job");
		const char *s = json_string_value(json_object_get(j, "state"));
		snprintf(last, sizeof(last), "%s", s ? s : "?");
		if (s && state_in(s, states)) {
			json_incref(j);
			json_decref(r);
			return j;
		}
		json_decref(r);
		if (dm_now_ms() > end)
			break;
		dm_sleep_ms(50);
	}
	dm_fail("job did not reach %s within %d ms (last state %s)", states,
	        timeout_ms, last);
}

long long dm_query_points(dm_conn *c, const json_t *job, const double *pts,
                          size_t n, double *lux)
{
	json_t *arr = json_array();
	for (size_t i = 0; i < n; i++) {
		json_t *p = json_array();
		for (int k = 0; k < 6; k++)
			json_array_append_new(p, json_real(pts[6 * i + k]));
		json_array_append_new(arr, p);
	}
	json_t *h = json_pack("{s:s, s:O, s:o}", "cmd", "query.points", "job",
	                      (json_t *)job, "points", arr);
	json_t *r = call_json(c, h, NULL, 0, DM_REPLY_MS, 1);
	require_ok(r, "query.points");
	json_t *l = json_object_get(r, "lux");
	if (!json_is_array(l) || json_array_size(l) != n)
		dm_fail("query.points: \"lux\" is not an array of %zu numbers",
		        n);
	for (size_t i = 0; i < n; i++) {
		json_t *v = json_array_get(l, i);
		if (!json_is_number(v))
			dm_fail("query.points: lux[%zu] is not a number", i);
		lux[i] = json_number_value(v);
	}
	long long it = dm_int(r, "iteration");
	json_decref(r);
	return it;
}

int dm_http_get(const dm_daemon *d, const char *path, char **headers,
                char **body)
{
	dm_conn *c = connect_tcp(d->metrics_host, d->metrics_port, 0);
	char req[512];
	int n = snprintf(req, sizeof(req),
	                 "GET %s HTTP/1.1\r\nHost: %s:%d\r\nConnection: "
	                 "close\r\nAccept: text/plain\r\n\r\n",
	                 path, d->metrics_host, d->metrics_port);
	if (dm_send_raw(c, req, (size_t)n) != 0)
		dm_fail("GET %s: send failed", path);
	double end = dm_now_ms() + DM_REPLY_MS;
	while (!c->eof) {
		int left = (int)(end - dm_now_ms());
		if (left <= 0)
			dm_fail("GET %s: the response was not closed within "
			        "%d ms (%zu bytes read)",
			        path, DM_REPLY_MS, c->len);
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

/* -------------------------------------------------------------- files */

const char *dm_sample(const char *name, char *buf, size_t len)
{
	snprintf(buf, len, "%s/scenes/%s", LUXRAD_SOURCE_DIR, name);
	return buf;
}

const char *dm_gen_scene(const char *file, const char *args, char *buf,
                         size_t len)
{
	char dir[512];
	snprintf(dir, sizeof(dir), "%s/tests/daemon/scenes", LUXRAD_BINARY_DIR);
	snprintf(buf, len, "%s/%s", dir, file);
	if (access(buf, R_OK) == 0)
		return buf;
	char cmd[2048];
	snprintf(cmd, sizeof(cmd),
	         "mkdir -p '%s' && '%s/luxrad-scenegen' %s -o '%s.%d.tmp' "
	         "2>/dev/null && mv '%s.%d.tmp' '%s'",
	         dir, LUXRAD_BINARY_DIR, args, buf, (int)getpid(), buf,
	         (int)getpid(), buf);
	if (system(cmd) != 0)
		dm_fail("could not generate %s: %s", buf, cmd);
	return buf;
}

unsigned char *dm_read_file(const char *path, size_t *len)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		dm_fail("cannot open %s: %s", path, strerror(errno));
	fseek(f, 0, SEEK_END);
	long size = ftell(f);
	fseek(f, 0, SEEK_SET);
	unsigned char *b = malloc((size_t)size + 1);
	if (!b || fread(b, 1, (size_t)size, f) != (size_t)size)
		dm_fail("cannot read %s", path);
	fclose(f);
	b[size] = 0;
	*len = (size_t)size;
	return b;
}

int dm_run(const char *cmd, char **out)
{
	fflush(NULL);
	FILE *p = popen(cmd, "r");
	if (!p)
		return -1;
	size_t cap = 65536, n = 0;
	char *b = malloc(cap);
	size_t r;
	while ((r = fread(b + n, 1, cap - n - 1, p)) > 0) {
		n += r;
		if (cap - n < 4096) {
			cap *= 2;
			b = realloc(b, cap);
		}
	}
	b[n] = 0;
	int st = pclose(p);
	if (out)
		*out = b;
	else
		free(b);
	if (st == -1)
		return -1;
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

/* ------------------------------------------------------------ numbers */

json_t *dm_get(const json_t *obj, const char *key)
{
	json_t *v = json_object_get(obj, key);
	if (!v) {
		char *s = dumps(obj);
		char got[1600];
		snprintf(got, sizeof(got), "%s", s ? s : "(not an object)");
		free(s);
		dm_fail("missing member \"%s\" in %s", key, got);
	}
	return v;
}

double dm_num(const json_t *obj, const char *key)
{
	json_t *v = dm_get(obj, key);
	if (!json_is_number(v))
		dm_fail("member \"%s\" is not a number", key);
	return json_number_value(v);
}

long long dm_int(const json_t *obj, const char *key)
{
	json_t *v = dm_get(obj, key);
	if (!json_is_integer(v))
		dm_fail("member \"%s\" is not an integer", key);
	return (long long)json_integer_value(v);
}

int dm_close_enough(double a, double b, double rel)
{
	double scale = fmax(fabs(a), fabs(b));
	return fabs(a - b) <= rel * scale + 1e-12;
}
