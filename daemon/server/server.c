/*
 * server.c -- luxradd's event loop: listeners, signals, timers, the wake-up
 * from other threads, and the shutdown sequence.
 *
 * DESIGN
 *
 * Threads.  One I/O thread (the main thread) owns every socket, the
 * command table, the scene and job registries, subscriptions and timers.
 * It never blocks on a lock held for long and never does solver math:
 * requests that cost (uploads, queries, exports, store writes) become
 * tasks for a pool, and their replies come back through the inbox.
 *   - workers (cfg.workers) step jobs: one worker holds a job from
 *     queued to paused/done/failed/cancelled and is the only thread that
 *     touches its rad_solver.  After each iteration it publishes the
 *     stats (JSON text) and a rad_solution under the job's mutex, posts
 *     an iteration event to the inbox, and checkpoints when due;
 *   - the query pool (cfg.query_threads) answers query.* and export
 *     from a published solution it holds a reference to; it never waits
 *     for a step;
 *   - the store pool (one thread, so row writes keep their order) parses
 *     and stores uploads and writes job rows for control commands.
 * Other threads reach the I/O thread only through the inbox (a list
 * under inbox_mu plus the event loop's wake-up).
 *
 * Locks, and what each guards.
 *   store_mu    every srv_store call (SQLite is used from one thread at a
 *               time).  Order: store_mu before a job's mu.
 *   job->mu     a job's state, target, requests, eps log, published
 *               stats and solution pointer (see srv_job).  Held for
 *               copies and pointer swaps only, never across a step, a
 *               query or a store write.
 *   runq_mu     the run queue, busy_workers, runq_stop.  Taken inside
 *               job->mu (enqueue), never the other way round.
 *   inbox_mu    the inbox list.  A leaf lock.
 *   pool->mu    a pool's task list.  A leaf lock.
 * The engine's cancel flag (job->cancel) is written with atomic stores
 * by the I/O thread (pause, cancel, budgets, shutdown) and by the
 * stepping thread (its own budget check in the progress callback).
 *
 * Ownership.  Scenes, jobs and solutions are refcounted (atomic): the
 * registry holds one reference, each job holds its scene, each
 * solution holds its scene (it reads the geometry), each in-flight task
 * holds what it reads.  So a deleted job whose solution a query still
 * reads stays alive until that query ends, and scene.delete releases the
 * scene's memory when the last reader lets go.  A connection is named by
 * its id in tasks and waiters, never by pointer: it may be gone when the
 * reply is ready, and the reply is then dropped.
 *
 * Requests on one connection are handled in order: while a deferred
 * reply is owed the connection is "busy" and its next frames wait in
 * its input buffer (events still flow).  So replies come in request
 * order, and a client pipelining requests cannot make the daemon queue
 * unbounded work for it.
 *
 * Drop policy.  Each connection has an output queue.  Replies are always
 * queued (the client asked for them; a connection whose queue exceeds
 * max_output_bytes is not read until it drains).  Events are queued only
 * while the queue stays within max_output_bytes: a progress event that
 * does not fit is dropped and counted per subscription, and the next
 * iteration event delivered carries "dropped_progress": n; an iteration
 * or state event that does not fit gets the connection the error
 * slow_consumer, and it is closed.  Workers never wait for a subscriber:
 * they post to the inbox and go on.
 *
 * Checkpoint rule.  The engine is deterministic for a given scene,
 * options (including the thread count, resolved at job.create) and
 * sequence of eps changes.  So a checkpoint is the job row -- iterations
 * done, the eps log [[iteration, eps], ...], the run target -- plus the
 * latest solution's bytes (rad_solution_save).  Workers write one at
 * most every checkpoint_interval_s while stepping, and always when a job
 * pauses, finishes (done, failed, cancelled) or is interrupted by a
 * shutdown.  On restart (recover.c), finished jobs load their solution
 * and answer queries at once; queued and running jobs are re-queued:
 * the worker rebuilds the solver and replays it to the checkpointed
 * iteration, applying the eps log, while queries are answered from the
 * checkpoint's solution; then it continues toward the target.  Paused
 * jobs come back paused and replay when resumed.  The replay is exact
 * when no iteration of the original run was interrupted (a pause or a
 * time budget that stops a step early keeps the partial refinement,
 * which the replay does not repeat): the replayed solver then reaches
 * the same iteration count with a state as valid, not bit-identical.
 *
 * Shutdown (SIGTERM, SIGINT, "shutdown").  Stop accepting; raise every
 * running job's cancel flag; workers record their job as queued and
 * checkpoint it; then the pools finish their tasks, every connection
 * gets shutting_down, output is flushed (bounded), and the process
 * exits 0.  Signals are delivered by the event loop (loop.h): no
 * handlers.
 *
 * Timers.  The event loop (loop/) sleeps until the nearest timer; each
 * periodic duty is a timer its owner registers: time budgets (job.c),
 * metrics requests (metrics.c), the Modbus daemon block (mbpub.c).
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
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#include "log.h"
#include "server.h"

#define SHUTDOWN_FLUSH_S 2.0 /* time given to flush the last bytes */

double srv_now_unix(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

json_t *srv_jreal(double v)
{
	return isfinite(v) ? json_real(v) : json_null();
}

/* ------------------------------------------------------------------ token */

int srv_load_token(srv *s, const srv_config *cfg, char *msg, size_t msglen)
{
	char buf[4097];
	if (!cfg->token_file[0]) {
		free(s->token);
		s->token = NULL;
		s->token_len = 0;
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
	if (s->token) {
		memset(s->token, 0, s->token_len);
		free(s->token);
	}
	s->token = t;
	s->token_len = n - a;
	memset(buf, 0, sizeof(buf));
	return 0;
}

int srv_token_needed(const srv *s, int listener_needs)
{
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
	srv *s = w->ud;
	srv_listener *lis =
	        (srv_listener *)((char *)w - offsetof(srv_listener, w));
	(void)l;
	(void)events;
	if (lis->kind == 2)
		srv_metrics_accept(s, lis->fd);
	else
		srv_conn_accept(s, lis->fd, lis->kind == 0,
		                srv_token_needed(s, lis->needs_token));
}

static int listen_tcp(srv *s, const char *spec, int kind, char *msg,
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
	    listen(fd, 128) != 0 || set_nonblock(fd) != 0) {
		snprintf(msg, msglen, "%s '%s': cannot listen: %s", what, spec,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		freeaddrinfo(res);
		return -1;
	}
	srv_listener *l = &s->lis[s->nlis];
	l->fd = fd;
	l->kind = kind;
	l->needs_token = !sockaddr_is_loopback(res->ai_addr);
	freeaddrinfo(res);
	char hp[300];
	bound_text(fd, hp, sizeof(hp));
	snprintf(l->text, sizeof(l->text), "%s %s",
	         kind == 2 ? "metrics" : "tcp", hp);
	s->nlis++;
	return el_watch_add(s->loop, &l->w, fd, EL_READABLE, listener_ready, s);
}

static int listen_unix(srv *s, const char *path, char *msg, size_t msglen)
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
	    chmod(path, 0660) != 0 || listen(fd, 128) != 0 ||
	    set_nonblock(fd) != 0) {
		snprintf(msg, msglen, "listen_unix '%s': %s", path,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	srv_listener *l = &s->lis[s->nlis];
	l->fd = fd;
	l->kind = 1;
	snprintf(l->text, sizeof(l->text), "unix %s", path);
	s->nlis++;
	return el_watch_add(s->loop, &l->w, fd, EL_READABLE, listener_ready, s);
}

/* <data_dir>/luxradd.addr, written atomically (tmp, fsync, rename). */
static int write_addr_file(srv *s, char *msg, size_t msglen)
{
	char tmp[4300];
	snprintf(tmp, sizeof(tmp), "%s.tmp", s->addr_path);
	FILE *f = fopen(tmp, "w");
	if (!f) {
		snprintf(msg, msglen, "%.900s: %s", tmp, strerror(errno));
		return -1;
	}
	for (int i = 0; i < s->nlis; i++)
		fprintf(f, "%s\n", s->lis[i].text);
	char mbtext[400];
	if (srv_mb_addr_text(s, mbtext, sizeof(mbtext)))
		fprintf(f, "%s\n", mbtext);
	int bad = fflush(f) != 0 || fsync(fileno(f)) != 0;
	bad |= fclose(f) != 0;
	if (bad || rename(tmp, s->addr_path) != 0) {
		snprintf(msg, msglen, "%.900s: %s", s->addr_path,
		         strerror(errno));
		unlink(tmp);
		return -1;
	}
	return 0;
}

int srv_listen(srv *s, char *msg, size_t msglen)
{
	const srv_config *c = &s->cfg;
	if (c->listen_tcp[0] && listen_tcp(s, c->listen_tcp, 0, msg, msglen))
		return -1;
	for (int i = 0; i < s->nlis; i++) {
		if (s->lis[i].needs_token && !s->token) {
			snprintf(msg, msglen,
			         "refusing to listen on %s beyond loopback "
			         "without a token: set token_file "
			         "(--token-file)",
			         s->lis[i].text + 4);
			return -2;
		}
	}
	if (c->listen_unix[0] && listen_unix(s, c->listen_unix, msg, msglen))
		return -1;
	if (c->metrics_listen[0] &&
	    listen_tcp(s, c->metrics_listen, 2, msg, msglen))
		return -1;
	if (s->nlis == 0) {
		snprintf(msg, msglen,
		         "no listener configured (listen_tcp and "
		         "listen_unix are both off)");
		return -2;
	}
	for (int i = 0; i < s->nlis; i++) {
		if (s->lis[i].kind == 2 && s->lis[i].needs_token)
			srv_warn("metrics listener %s is reachable beyond "
			         "loopback and has no authentication",
			         s->lis[i].text + 8);
	}
	int rc = srv_mb_start(s, msg, msglen);
	if (rc == 0 && srv_subs_start(s) != 0) {
		snprintf(msg, msglen, "subscriptions: too many observers");
		rc = -1;
	}
	return rc;
}

/* Log the listeners and publish them in luxradd.addr. */
static int announce(srv *s, char *msg, size_t msglen)
{
	for (int i = 0; i < s->nlis; i++)
		srv_info("%s", s->lis[i].text);
	return write_addr_file(s, msg, msglen);
}

static void close_listeners(srv *s)
{
	for (int i = 0; i < s->nlis; i++) {
		if (s->lis[i].fd < 0)
			continue;
		el_watch_del(s->loop, &s->lis[i].w);
		close(s->lis[i].fd);
		s->lis[i].fd = -1;
		if (s->lis[i].kind == 1)
			unlink(s->lis[i].text + 5);
	}
	if (s->addr_path[0])
		unlink(s->addr_path);
}

/* ---------------------------------------------------------------- signals */

static void reload_config(srv *s)
{
	srv_config nc;
	char msg[1024] = "";

	srv_config_default(&nc);
	if (srv_config_from_args(&nc, s->argc, s->argv, msg, sizeof(msg)) !=
	    0) {
		srv_error("SIGHUP: configuration not reloaded: %s", msg);
		return;
	}
	if (srv_load_token(s, &nc, msg, sizeof(msg)) != 0) {
		srv_error("SIGHUP: token not reloaded (old one kept): %s", msg);
		snprintf(nc.token_file, sizeof(nc.token_file), "%s",
		         s->cfg.token_file);
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
	if (nc.require_token && !s->token) {
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
	s->cfg = nc;
	srv_log_set_level(nc.log_level);
	atomic_store(&s->ckpt_interval_ms,
	             (long long)(nc.checkpoint_interval_s * 1000.0));
	srv_info("SIGHUP: configuration reloaded (token %s)",
	         s->token ? "set" : "none");
}

static void on_signal(el_loop *l, int signo, void *ud)
{
	srv *s = ud;
	(void)l;
	if (signo == SIGHUP)
		reload_config(s);
	else
		srv_begin_shutdown(s, signo == SIGINT ? "SIGINT" : "SIGTERM");
}

/* ------------------------------------------------------------------- init */

static void config_line(void *ud, const char *text)
{
	(void)ud;
	srv_debug("config: %s", text);
}

static void inbox_wake(el_loop *l, void *ud)
{
	(void)l;
	srv_inbox_drain(ud);
}

int srv_init(srv *s, const srv_config *cfg, int argc, char **argv, char *msg,
             size_t msglen)
{
	static const int sigs[] = {SIGTERM, SIGINT, SIGHUP};

	memset(s, 0, sizeof(*s));
	s->cfg = *cfg;
	s->argc = argc;
	s->argv = argv;
	s->t0 = rad_seconds();
	s->lock_fd = -1;
	s->next_conn_id = 1;
	pthread_mutex_init(&s->store_mu, NULL);
	pthread_mutex_init(&s->inbox_mu, NULL);
	pthread_mutex_init(&s->runq_mu, NULL);
	pthread_cond_init(&s->runq_cv, NULL);
	atomic_store(&s->ckpt_interval_ms,
	             (long long)(cfg->checkpoint_interval_s * 1000.0));
	srv_config_dump(cfg, config_line, NULL);

	long cores = sysconf(_SC_NPROCESSORS_ONLN);
	int w = cfg->workers > 0 ? cfg->workers : 1;
	s->accuracy = cfg->accuracy;
	s->solver_threads = cfg->solver_threads > 0
	                            ? cfg->solver_threads
	                            : (int)(cores > w ? cores / w : 1);
	if (srv_load_token(s, cfg, msg, msglen) != 0)
		return -2;
	if (cfg->require_token && !s->token) {
		snprintf(msg, msglen,
		         "require_token is set but no token_file "
		         "is configured");
		return -2;
	}

	/* Signals come through the loop, before any thread is started:
	 * they inherit the mask, so none of them ever runs a handler. */
	signal(SIGPIPE, SIG_IGN);
	s->loop = el_new(msg, msglen);
	if (!s->loop ||
	    el_signals(s->loop, sigs, 3, on_signal, s, msg, msglen) != 0 ||
	    el_wake_init(s->loop, inbox_wake, s, msg, msglen) != 0)
		return -1;

	s->store = srv_store_open(cfg->data_dir, msg, msglen);
	if (!s->store)
		return -1;
	if (srv_store_repairs(s->store)[0])
		srv_warn("store %s: %s", cfg->data_dir,
		         srv_store_repairs(s->store));
	/* One daemon per data directory. */
	snprintf(s->lock_path, sizeof(s->lock_path), "%s/luxradd.lock",
	         cfg->data_dir);
	s->lock_fd = open(s->lock_path, O_RDWR | O_CREAT | O_CLOEXEC, 0600);
	if (s->lock_fd < 0 || flock(s->lock_fd, LOCK_EX | LOCK_NB) != 0) {
		snprintf(msg, msglen, "%s: %s", s->lock_path,
		         errno == EWOULDBLOCK
		                 ? "another luxradd uses this data directory"
		                 : strerror(errno));
		return -1;
	}
	snprintf(s->addr_path, sizeof(s->addr_path), "%s/luxradd.addr",
	         cfg->data_dir);
	return 0;
}

int srv_start_threads(srv *s, char *msg, size_t msglen)
{
	int q = s->cfg.query_threads > 0 ? s->cfg.query_threads : 1;
	if (srv_pool_start(s, &s->store_pool, "store", 1, msg, msglen) != 0 ||
	    srv_pool_start(s, &s->query_pool, "query", q, msg, msglen) != 0)
		return -1;
	return srv_workers_start(s, s->cfg.workers > 0 ? s->cfg.workers : 1,
	                         msg, msglen);
}

/* --------------------------------------------------------------- shutdown */

void srv_begin_shutdown(srv *s, const char *why)
{
	if (s->shutting_down)
		return;
	srv_info("shutting down (%s): checkpointing jobs", why);
	s->shutting_down = 1;
	close_listeners(s);
	srv_workers_stop_request(s);
}

/*
 * Called every loop turn while shutting down.  Phase 1: wait for the
 * workers to checkpoint and leave; then finish the pools' tasks and
 * deliver their replies.  Phase 2: tell every connection and flush.
 */
static void shutdown_progress(srv *s, double now)
{
	if (s->shutting_down == 1) {
		if (srv_workers_busy(s) > 0)
			return;
		srv_workers_join(s);
		srv_pool_stop(&s->query_pool);
		srv_pool_stop(&s->store_pool);
		srv_inbox_drain(s);
		for (srv_conn *c = s->conns; c; c = c->next)
			if (!c->dead && !c->closing)
				srv_conn_send_error(
				        s, c, NULL, RP_ERR_SHUTTING_DOWN,
				        "the daemon is shutting down");
		s->shutting_down = 2;
		s->shutdown_flush_at = now + SHUTDOWN_FLUSH_S;
		return;
	}
	int pending = 0;
	for (srv_conn *c = s->conns; c; c = c->next)
		pending |= !c->dead && c->out_head != NULL;
	if (!pending || now >= s->shutdown_flush_at)
		s->loop_done = 1;
}

/*
 * End of every loop turn: close dead connections, check idle ones and
 * stuck flushes (every turn, as the daemon always has), move the
 * shutdown on.
 */
static void after_turn(el_loop *l, void *ud)
{
	srv *s = ud;
	srv_conn_reap(s);
	srv_conn_tick(s, rad_seconds());
	if (s->shutting_down) {
		shutdown_progress(s, rad_seconds());
		srv_conn_reap(s);
	}
	if (s->loop_done)
		el_stop(l);
}

int srv_run(srv *s)
{
	char msg[1024];

	if (announce(s, msg, sizeof(msg)) != 0) {
		srv_error("%s", msg);
		return 1;
	}
	srv_info("ready: %d workers x %d solver threads, %d query threads",
	         s->nworkers, s->solver_threads, s->query_pool.nthreads);
	el_after_turn(s->loop, after_turn, s);
	if (el_run(s->loop, msg, sizeof(msg)) != 0) {
		srv_error("%s", msg);
		return 1;
	}
	srv_info("stopped");
	return 0;
}

void srv_destroy(srv *s)
{
	if (!s->shutting_down)
		close_listeners(s);
	else
		for (int i = 0; i < s->nlis; i++)
			if (s->lis[i].fd >= 0)
				close(s->lis[i].fd);
	srv_workers_stop_request(s);
	srv_workers_join(s);
	srv_pool_stop(&s->query_pool);
	srv_pool_stop(&s->store_pool);
	srv_inbox_drain(s);
	srv_mb_stop(s); /* workers joined, sensor tasks delivered */
	srv_conn_free_all(s);
	srv_metrics_free_all(s);
	while (s->jobs) {
		srv_job *j = s->jobs;
		s->jobs = j->next;
		srv_job_unref(s, j);
	}
	while (s->scenes) {
		srv_scene *sc = s->scenes;
		s->scenes = sc->next;
		srv_scene_unref(sc);
	}
	if (s->store)
		srv_store_close(s->store);
	if (s->lock_fd >= 0)
		close(s->lock_fd); /* never unlinked: a racing start locks it */
	el_free(s->loop);
	if (s->token) {
		memset(s->token, 0, s->token_len);
		free(s->token);
	}
	pthread_mutex_destroy(&s->store_mu);
	pthread_mutex_destroy(&s->inbox_mu);
	pthread_mutex_destroy(&s->runq_mu);
	pthread_cond_destroy(&s->runq_cv);
}
