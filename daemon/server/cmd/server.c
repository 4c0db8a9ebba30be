/*
 * server.c -- the daemon put together: the event loop it runs, the core
 * inside it, listeners, signals, the end of every loop turn, shutdown.
 *
 * The threads, locks, ownership and checkpoint rules of the daemon are
 * the core's: see the DESIGN essay in core/service.c.  This file starts
 * the daemon (the core inside it, the loop, listeners, observers) and
 * runs the shutdown: stop accepting, let the core quiesce (workers
 * checkpoint, pools finish), tell every connection shutting_down, flush
 * (bounded), exit.  Signals are delivered by the event loop (loop.h): no
 * handlers.
 *
 * Timers.  The event loop (loop/) sleeps until the nearest timer; each
 * periodic duty is a timer its owner registers: time budgets
 * (core/job.c), metrics requests (metrics.c), the Modbus daemon block
 * (mb_glue.c).
 * Connections are reaped and their idle and flush limits checked at the
 * end of every turn (after_turn).
 */
#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "cmd.h"
#include "log.h"

#define SHUTDOWN_FLUSH_S 2.0 /* time given to flush the last bytes */

/* ------------------------------------------------------------------ token */

int cmd_load_token(cmd_server *d, const srv_config *cfg, char *msg,
                   size_t msglen)
{
	char buf[4097];
	if (!cfg->token_file[0]) {
		free(d->token);
		d->token = NULL;
		d->token_len = 0;
		return 0;
	}
	FILE *f = fopen(cfg->token_file, "r");
	if (!f) {
		snprintf(msg, msglen, "token file '%s': %s", cfg->token_file,
		         strerror(errno));
		return -1;
	}
	size_t n = fread(buf, 1, sizeof(buf) - 1, f);
	int bad = ferror(f), more = !feof(f) && fgetc(f) != EOF;
	fclose(f);
	if (bad || more) {
		snprintf(msg, msglen, "token file '%s': %s", cfg->token_file,
		         bad ? "read error" : "longer than 4096 bytes");
		return -1;
	}
	size_t a = 0;
	while (a < n && strchr(" \t\r\n", buf[a]))
		a++;
	while (n > a && strchr(" \t\r\n", buf[n - 1]))
		n--;
	if (n == a) {
		snprintf(msg, msglen, "token file '%s' is empty",
		         cfg->token_file);
		return -1;
	}
	char *t = malloc(n - a + 1);
	if (!t) {
		snprintf(msg, msglen, "token: out of memory");
		return -1;
	}
	memcpy(t, buf + a, n - a);
	t[n - a] = '\0';
	if (d->token) {
		memset(d->token, 0, d->token_len);
		free(d->token);
	}
	free(d->users);
	cmd_tls_free(d);
	d->token = t;
	d->token_len = n - a;
	memset(buf, 0, sizeof(buf));
	return 0;
}

int cmd_token_needed(const cmd_server *d, int listener_needs)
{
	const srv *s = &d->core;
	return s->cfg.require_token || listener_needs;
}

/* -------------------------------------------------------------- listeners */

static int set_nonblock(int fd)
{
	int fl = fcntl(fd, F_GETFL);
	return fl < 0 ? -1 : fcntl(fd, F_SETFL, fl | O_NONBLOCK);
}

static int sockaddr_is_loopback(const struct sockaddr *sa)
{
	if (sa->sa_family == AF_INET) {
		const struct sockaddr_in *in = (const void *)sa;
		return (ntohl(in->sin_addr.s_addr) >> 24) == 127;
	}
	if (sa->sa_family == AF_INET6) {
		const struct sockaddr_in6 *in6 = (const void *)sa;
		return IN6_IS_ADDR_LOOPBACK(&in6->sin6_addr);
	}
	return 0;
}

/* "HOST:PORT" of a bound socket, v6 in brackets. */
static void bound_text(int fd, char *out, size_t len)
{
	struct sockaddr_storage ss;
	socklen_t sl = sizeof(ss);
	char host[INET6_ADDRSTRLEN] = "?", port[16] = "?";
	if (getsockname(fd, (struct sockaddr *)&ss, &sl) == 0)
		getnameinfo((struct sockaddr *)&ss, sl, host, sizeof(host),
		            port, sizeof(port),
		            NI_NUMERICHOST | NI_NUMERICSERV);
	if (ss.ss_family == AF_INET6)
		snprintf(out, len, "[%s]:%s", host, port);
	else
		snprintf(out, len, "%s:%s", host, port);
}

static void listener_ready(el_loop *l, el_watch *w, unsigned events)
{
	cmd_server *d = w->ud;
	cmd_listener *lis =
	        (cmd_listener *)((char *)w - offsetof(cmd_listener, w));
	(void)l;
	(void)events;
	if (lis->kind == 2)
		cmd_metrics_accept(d, lis->fd);
	else
		cmd_conn_accept(d, lis->fd, lis->kind == 0,
		                cmd_token_needed(d, lis->needs_token),
		                lis->tls);
}

static int listen_tcp(cmd_server *d, const char *spec, int kind, char *msg,
                      size_t msglen)
{
	rp_addr a;
	rp_error e = {0};
	struct addrinfo hints = {0}, *res = NULL;
	char port[16];
	const char *what = kind == 2 ? "metrics_listen" : "listen_tcp";

	if (rp_addr_parse_listen(spec, &a, &e) != 0) {
		snprintf(msg, msglen, "%s: %s", what, e.msg);
		return -1;
	}
	hints.ai_socktype = SOCK_STREAM;
	hints.ai_flags = AI_PASSIVE;
	snprintf(port, sizeof(port), "%u", (unsigned)a.port);
	int rc = getaddrinfo(a.host[0] ? a.host : NULL, port, &hints, &res);
	if (rc != 0) {
		snprintf(msg, msglen, "%s '%s': %s", what, spec,
		         gai_strerror(rc));
		return -1;
	}
	int fd = socket(res->ai_family, SOCK_STREAM | SOCK_CLOEXEC, 0);
	int one = 1;
	if (fd < 0 ||
	    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one)) != 0 ||
	    bind(fd, res->ai_addr, res->ai_addrlen) != 0 ||
	    listen(fd, SOMAXCONN) != 0 || set_nonblock(fd) != 0) {
		snprintf(msg, msglen, "%s '%s': cannot listen: %s", what, spec,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		freeaddrinfo(res);
		return -1;
	}
	cmd_listener *l = &d->lis[d->nlis];
	l->fd = fd;
	l->kind = kind;
	l->needs_token = !sockaddr_is_loopback(res->ai_addr);
	const srv_tls_mode tm = d->core.cfg.tls;
	l->tls = kind == 0 &&
	         (tm == SRV_TLS_ALL || (tm == SRV_TLS_AUTO && l->needs_token));
	freeaddrinfo(res);
	char hp[300];
	bound_text(fd, hp, sizeof(hp));
	snprintf(l->text, sizeof(l->text), "%s %s%s",
	         kind == 2 ? "metrics" : "tcp", hp, l->tls ? " tls" : "");
	d->nlis++;
	return el_watch_add(d->loop, &l->w, fd, EL_READABLE, listener_ready, d);
}

static int listen_unix(cmd_server *d, const char *path, char *msg,
                       size_t msglen)
{
	struct sockaddr_un sa = {.sun_family = AF_UNIX};
	if (strlen(path) >= sizeof(sa.sun_path)) {
		snprintf(msg, msglen,
		         "listen_unix '%s': path longer than %zu bytes", path,
		         sizeof(sa.sun_path) - 1);
		return -1;
	}
	strcpy(sa.sun_path, path);
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0) {
		snprintf(msg, msglen, "listen_unix: %s", strerror(errno));
		return -1;
	}
	/* A socket file left by a crash is removed; a live one is not. */
	if (connect(fd, (struct sockaddr *)&sa, sizeof(sa)) == 0) {
		close(fd);
		snprintf(msg, msglen,
		         "listen_unix '%s': another daemon is listening there",
		         path);
		return -1;
	}
	close(fd);
	unlink(path);
	fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (fd < 0 || bind(fd, (struct sockaddr *)&sa, sizeof(sa)) != 0 ||
	    chmod(path, 0660) != 0 || listen(fd, SOMAXCONN) != 0 ||
	    set_nonblock(fd) != 0) {
		snprintf(msg, msglen, "listen_unix '%s': %s", path,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	cmd_listener *l = &d->lis[d->nlis];
	l->fd = fd;
	l->kind = 1;
	snprintf(l->text, sizeof(l->text), "unix %s", path);
	d->nlis++;
	return el_watch_add(d->loop, &l->w, fd, EL_READABLE, listener_ready, d);
}

/* <data_dir>/luxradd.addr, written atomically (tmp, fsync, rename). */
static int write_addr_file(cmd_server *d, char *msg, size_t msglen)
{
	char tmp[4300];
	snprintf(tmp, sizeof(tmp), "%s.tmp", d->addr_path);
	FILE *f = fopen(tmp, "w");
	if (!f) {
		snprintf(msg, msglen, "%.900s: %s", tmp, strerror(errno));
		return -1;
	}
	for (int i = 0; i < d->nlis; i++)
		fprintf(f, "%s\n", d->lis[i].text);
	char mbtext[400];
	if (cmd_mb_addr_text(d, mbtext, sizeof(mbtext)))
		fprintf(f, "%s\n", mbtext);
	int bad = fflush(f) != 0 || fsync(fileno(f)) != 0;
	bad |= fclose(f) != 0;
	if (bad || rename(tmp, d->addr_path) != 0) {
		snprintf(msg, msglen, "%.900s: %s", d->addr_path,
		         strerror(errno));
		unlink(tmp);
		return -1;
	}
	return 0;
}

/*
 * Descriptors: raise the soft limit to the hard one (a connection, a
 * linger or a query's file each hold one), say when max_connections
 * cannot be met, and keep a spare for refusing at EMFILE (conn.c).
 */
static void descriptors(cmd_server *d)
{
	const srv_config *c = &d->core.cfg;
	struct rlimit rl;
	if (getrlimit(RLIMIT_NOFILE, &rl) == 0) {
		if (rl.rlim_cur < rl.rlim_max) {
			rlim_t was = rl.rlim_cur;
			rl.rlim_cur = rl.rlim_max;
			if (setrlimit(RLIMIT_NOFILE, &rl) != 0)
				rl.rlim_cur = was;
		}
		/* room for the data directory, Modbus and the store */
		rlim_t want = (rlim_t)c->max_connections * 2 + 64;
		if (rl.rlim_cur != RLIM_INFINITY && rl.rlim_cur < want)
			srv_warn("open files limited to %llu: fewer than "
			         "max_connections (%d) need; raise the limit "
			         "(LimitNOFILE=, ulimit -n) or lower "
			         "max_connections",
			         (unsigned long long)rl.rlim_cur,
			         c->max_connections);
	}
	if (cmd_conn_init(d) != 0)
		srv_warn("no spare descriptor: %s; out of descriptors, new "
		         "connections will wait unanswered",
		         strerror(errno));
}

int cmd_server_listen(cmd_server *d, char *msg, size_t msglen)
{
	srv *s = &d->core;
	const srv_config *c = &s->cfg;
	descriptors(d);
	if (c->listen_tcp[0] && listen_tcp(d, c->listen_tcp, 0, msg, msglen))
		return -1;
	for (int i = 0; i < d->nlis; i++) {
		if (d->lis[i].tls && !d->tls_ctx) {
			snprintf(msg, msglen,
			         "%s speaks TLS (tls = %s) but no certificate "
			         "is configured: set tls_cert_file and "
			         "tls_key_file, or tls = off to send tokens in "
			         "clear text",
			         d->lis[i].text + 4,
			         c->tls == SRV_TLS_ALL ? "all" : "auto");
			return -2;
		}
		if (d->lis[i].kind == 0 && d->lis[i].needs_token &&
		    !d->lis[i].tls)
			srv_warn("%s is reachable beyond loopback without TLS "
			         "(tls = off): tokens travel in clear text",
			         d->lis[i].text + 4);
		if (d->lis[i].needs_token && !d->token && !d->users_on) {
			snprintf(msg, msglen,
			         "refusing to listen on %s beyond loopback "
			         "without a token: set token_file "
			         "(--token-file)",
			         d->lis[i].text + 4);
			return -2;
		}
	}
	if (c->listen_unix[0] && listen_unix(d, c->listen_unix, msg, msglen))
		return -1;
	if (c->metrics_listen[0] &&
	    listen_tcp(d, c->metrics_listen, 2, msg, msglen))
		return -1;
	if (d->nlis == 0) {
		snprintf(msg, msglen,
		         "no listener configured (listen_tcp and "
		         "listen_unix are both off)");
		return -2;
	}
	for (int i = 0; i < d->nlis; i++) {
		if (d->lis[i].kind == 2 && d->lis[i].needs_token)
			srv_warn("metrics listener %s is reachable beyond "
			         "loopback and has no authentication",
			         d->lis[i].text + 8);
	}
	int rc = cmd_mb_start(d, msg, msglen);
	if (rc == 0 && (cmd_subs_start(d) != 0 || cmd_waiters_start(d) != 0)) {
		snprintf(msg, msglen, "subscriptions: too many observers");
		rc = -1;
	}
	return rc;
}

/* Log the listeners and publish them in luxradd.addr. */
static int announce(cmd_server *d, char *msg, size_t msglen)
{
	for (int i = 0; i < d->nlis; i++)
		srv_info("%s", d->lis[i].text);
	return write_addr_file(d, msg, msglen);
}

static void close_listeners(cmd_server *d)
{
	for (int i = 0; i < d->nlis; i++) {
		if (d->lis[i].fd < 0)
			continue;
		el_watch_del(d->loop, &d->lis[i].w);
		close(d->lis[i].fd);
		d->lis[i].fd = -1;
		if (d->lis[i].kind == 1)
			unlink(d->lis[i].text + 5);
	}
	if (d->addr_path[0])
		unlink(d->addr_path);
}

/* ---------------------------------------------------------------- signals */

static void reload_config(cmd_server *d)
{
	srv *s = &d->core;
	srv_config nc;
	char msg[1024] = "";

	srv_config_default(&nc);
	if (srv_config_from_args(&nc, d->argc, d->argv, msg, sizeof(msg)) !=
	    0) {
		srv_error("SIGHUP: configuration not reloaded: %s", msg);
		return;
	}
	if (cmd_load_token(d, &nc, msg, sizeof(msg)) != 0) {
		srv_error("SIGHUP: token not reloaded (old one kept): %s", msg);
		snprintf(nc.token_file, sizeof(nc.token_file), "%s",
		         s->cfg.token_file);
	}
	if (cmd_tls_load(d, &nc, msg, sizeof(msg)) != 0) {
		srv_error("SIGHUP: TLS certificate not reloaded (old one "
		          "kept): %s",
		          msg);
		snprintf(nc.tls_cert_file, sizeof(nc.tls_cert_file), "%s",
		         s->cfg.tls_cert_file);
		snprintf(nc.tls_key_file, sizeof(nc.tls_key_file), "%s",
		         s->cfg.tls_key_file);
	}
	if (cmd_users_load(d, &nc, msg, sizeof(msg)) != 0) {
		srv_error("SIGHUP: users not reloaded (old ones kept): %s",
		          msg);
		snprintf(nc.users_file, sizeof(nc.users_file), "%s",
		         s->cfg.users_file);
	}
	if (strcmp(nc.listen_tcp, s->cfg.listen_tcp) ||
	    strcmp(nc.listen_unix, s->cfg.listen_unix) ||
	    strcmp(nc.metrics_listen, s->cfg.metrics_listen) ||
	    strcmp(nc.data_dir, s->cfg.data_dir) ||
	    nc.workers != s->cfg.workers ||
	    nc.query_threads != s->cfg.query_threads ||
	    nc.solver_threads != s->cfg.solver_threads)
		srv_warn("SIGHUP: listener, data directory and thread "
		         "changes need a restart; keeping the running ones");
	if (nc.require_token && !d->token && !d->users_on) {
		srv_error("SIGHUP: require_token without a token; keeping "
		          "the old setting");
		nc.require_token = s->cfg.require_token;
	}
	/* Keep what a restart would change; take the rest. */
	memcpy(nc.listen_tcp, s->cfg.listen_tcp, sizeof(nc.listen_tcp));
	memcpy(nc.listen_unix, s->cfg.listen_unix, sizeof(nc.listen_unix));
	memcpy(nc.metrics_listen, s->cfg.metrics_listen,
	       sizeof(nc.metrics_listen));
	memcpy(nc.data_dir, s->cfg.data_dir, sizeof(nc.data_dir));
	nc.workers = s->cfg.workers;
	nc.query_threads = s->cfg.query_threads;
	nc.solver_threads = s->cfg.solver_threads;
	srv_core_reconfigure(s, &nc);
	srv_log_set_level(nc.log_level);
	srv_info("SIGHUP: configuration reloaded (token %s, %d users)",
	         d->token ? "set" : "none", d->nusers);
}

static void on_signal(el_loop *l, int signo, void *ud)
{
	cmd_server *d = ud;
	(void)l;
	if (signo == SIGHUP)
		reload_config(d);
	else
		cmd_server_shutdown(d, signo == SIGINT ? "SIGINT" : "SIGTERM");
}

/* ------------------------------------------------------------------- init */

static void config_line(void *ud, const char *text)
{
	(void)ud;
	srv_debug("config: %s", text);
}

int cmd_server_init(cmd_server *d, const srv_config *cfg, int argc, char **argv,
                    char *msg, size_t msglen)
{
	static const int sigs[] = {SIGTERM, SIGINT, SIGHUP};

	memset(d, 0, sizeof(*d));
	d->core.lock_fd = -1;
	d->spare_fd = -1;
	d->argc = argc;
	d->argv = argv;
	d->next_conn_id = 1;
	d->on_frame = cmd_dispatch;
	srv_config_dump(cfg, config_line, NULL);
	if (cmd_load_token(d, cfg, msg, msglen) != 0 ||
	    cmd_users_load(d, cfg, msg, msglen) != 0 ||
	    cmd_tls_load(d, cfg, msg, msglen) != 0)
		return -2;
	if (cfg->require_token && !d->token && !d->users_on) {
		snprintf(msg, msglen,
		         "require_token is set but neither token_file nor "
		         "users_file is configured");
		return -2;
	}

	/* Signals come through the loop, before any thread is started:
	 * they inherit the mask, so none of them ever runs a handler. */
	signal(SIGPIPE, SIG_IGN);
	d->loop = el_new(msg, msglen);
	if (!d->loop ||
	    el_signals(d->loop, sigs, 3, on_signal, d, msg, msglen) != 0)
		return -1;
	if (srv_core_init(&d->core, cfg, d->loop, msg, msglen) != 0)
		return -1;
	snprintf(d->addr_path, sizeof(d->addr_path), "%s/luxradd.addr",
	         cfg->data_dir);
	return 0;
}

int cmd_server_start(cmd_server *d, char *msg, size_t msglen)
{
	return srv_core_start(&d->core, msg, msglen);
}

/* --------------------------------------------------------------- shutdown */

void cmd_server_shutdown(cmd_server *d, const char *why)
{
	if (d->shutting_down)
		return;
	srv_info("shutting down (%s): checkpointing jobs", why);
	d->shutting_down = 1;
	close_listeners(d);
	srv_workers_stop_request(&d->core);
}

/*
 * Called every loop turn while shutting down.  Phase 1: wait for the
 * core to quiesce (workers checkpointed and gone, the pools' replies
 * delivered).  Phase 2: tell every connection and flush.
 */
static void shutdown_progress(cmd_server *d, double now)
{
	if (d->shutting_down == 1) {
		if (!srv_core_quiesce(&d->core))
			return;
		for (cmd_conn *c = d->conns; c; c = c->next)
			if (!c->dead && !c->closing)
				cmd_conn_send_error(
				        d, c, NULL, RP_ERR_SHUTTING_DOWN,
				        "the daemon is shutting down");
		d->shutting_down = 2;
		d->shutdown_flush_at = now + SHUTDOWN_FLUSH_S;
		return;
	}
	int pending = 0;
	for (cmd_conn *c = d->conns; c; c = c->next)
		pending |= !c->dead && c->out_head != NULL;
	if (!pending || now >= d->shutdown_flush_at)
		d->loop_done = 1;
}

/*
 * End of every loop turn: close dead connections, check idle ones and
 * stuck flushes (every turn, as the daemon always has), move the
 * shutdown on.
 */
static void after_turn(el_loop *l, void *ud)
{
	cmd_server *d = ud;
	if (d->shutdown_asked)
		cmd_server_shutdown(d, d->shutdown_asked);
	cmd_conn_reap(d);
	cmd_conn_tick(d, rad_seconds());
	if (d->shutting_down) {
		shutdown_progress(d, rad_seconds());
		cmd_conn_reap(d);
	}
	if (d->loop_done)
		el_stop(l);
}

int cmd_server_run(cmd_server *d)
{
	char msg[1024];

	if (announce(d, msg, sizeof(msg)) != 0) {
		srv_error("%s", msg);
		return 1;
	}
	srv_info("ready: %d workers x %d solver threads, %d query threads",
	         d->core.nworkers, d->core.solver_threads,
	         d->core.query_pool.nthreads);
	el_after_turn(d->loop, after_turn, d);
	if (el_run(d->loop, msg, sizeof(msg)) != 0) {
		srv_error("%s", msg);
		return 1;
	}
	srv_info("stopped");
	return 0;
}

void cmd_server_destroy(cmd_server *d)
{
	if (!d->shutting_down)
		close_listeners(d);
	else
		for (int i = 0; i < d->nlis; i++)
			if (d->lis[i].fd >= 0)
				close(d->lis[i].fd);
	srv_core_stop(&d->core);
	cmd_mb_stop(d); /* workers joined, sensor tasks delivered */
	cmd_conn_free_all(d);
	cmd_metrics_free_all(d);
	cmd_waiters_free_all(d);
	srv_core_destroy(&d->core);
	el_free(d->loop);
	if (d->token) {
		memset(d->token, 0, d->token_len);
		free(d->token);
	}
}
