/*
 * harness.c -- luxradd as a child process, the cmocka fixtures, the
 * failure path and the registry of what a test opened.  Connections are
 * in harness_conn.c, helpers in harness_util.c; harness.h has the design.
 */
#include "harness.h"
#include "rp.h"

#include <errno.h>
#include <fcntl.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

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
int dm_reply_ms = DM_REPLY_MS;

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
	/* Every listener on an ephemeral port: programs run in parallel. */
	argv[n++] = (char *)"--modbus-listen";
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

/* "HOST:PORT" / "[V6]:PORT" of a listener, as luxradd.addr reports it. */
static int split_hostport(const char *s, char *host, size_t hlen, int *port)
{
	rp_addr a;
	rp_error err;
	if (rp_addr_parse(s, &a, &err) != 0 || a.kind != RP_ADDR_TCP ||
	    snprintf(host, hlen, "%s", a.host) >= (int)hlen)
		return -1;
	*port = a.port;
	return 0;
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

/* ------------------------------------------------------------- registry */

void dm_conn_register(dm_conn *c)
{
	for (int i = 0; i < MAX_CONNS; i++)
		if (!g_conns[i]) {
			g_conns[i] = c;
			return;
		}
	dm_fail("too many connections in one test");
}

void dm_conn_forget(dm_conn *c)
{
	for (int i = 0; i < MAX_CONNS; i++)
		if (g_conns[i] == c)
			g_conns[i] = NULL;
}
