/*
 * runner.c -- the daemon's side of a job's solver: a rad_solver on the
 * worker thread, or a solver process (see runner.h for the design;
 * worker.c is the process's side).
 */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "log.h"
#include "runner.h"

extern char **environ;

#define WAIT_TICK_MS 100 /* progress and the stop timeout, while waiting */
#define QUIT_WAIT_S 2.0  /* a quitting process gets this long */
#define FD_SPARE_BASE 10 /* descriptors moved above 3..5 before spawning */

/* The daemon's shared count, and its own share of it. */
typedef struct share_page {
	rad_mem_shared g;
	int64_t daemon_own;
} share_page;

struct srv_runner {
	srv *s;
	srv_job *j; /* borrowed: the job owns the runner */
	srv_runner_progress progress;
	void *ud;
	int cancel_local; /* thread: the engine's flag */
	int *cancel;      /* the flag in force: cancel_local or page->cancel */

	/* thread */
	rad_solver *sv;
	uint32_t steps; /* iterations done (fault injection) */
	int fault;      /* LUXRAD_TEST_FAULT for this job */

	/* process */
	pid_t pid; /* 0 once reaped; stored atomically: job.info reads it */
	int fd;    /* the control socket, -1 once closed */
	srv_wpage *page;  /* mapped, shared with the process */
	int gone;         /* died or killed (atomic) */
	char why[256];    /* how it went */
	srv_wreply reply; /* the last step's */
	int solfd;        /* memfd the process writes solutions in */
	size_t sol_len;   /* bytes of the last step's solution there */
	double recv_s;    /* seconds reading the last reply */
};

/* ------------------------------------------------------- fault injection */

int srv_fault_for(const char *job)
{
	const char *f = getenv("LUXRAD_TEST_FAULT");
	const char *colon = f ? strchr(f, ':') : NULL;
	if (!colon || strcmp(colon + 1, job) != 0)
		return 0;
	size_t n = (size_t)(colon - f);
	if (n == 4 && strncmp(f, "segv", 4) == 0)
		return 's';
	if (n == 5 && strncmp(f, "abort", 5) == 0)
		return 'a';
	if (n == 4 && strncmp(f, "hang", 4) == 0)
		return 'h';
	return 0;
}

void srv_fault_commit(int kind)
{
	if (kind == 's') {
		volatile int *volatile p = NULL;
		*p = 1;
	} else if (kind == 'a') {
		abort();
	}
	for (;;) /* 'h': deaf to the cancel flag */
		pause();
}

/* ------------------------------------------------------------ the share */

int srv_runner_share_init(srv *s, char *msg, size_t msglen)
{
	int fd = memfd_create("luxradd-memory", MFD_CLOEXEC);
	if (fd < 0 || ftruncate(fd, sizeof(share_page)) != 0) {
		snprintf(msg, msglen, "memory count: memfd: %s",
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		return -1;
	}
	share_page *p = mmap(NULL, sizeof(*p), PROT_READ | PROT_WRITE,
	                     MAP_SHARED, fd, 0);
	if (p == MAP_FAILED) {
		snprintf(msg, msglen, "memory count: mmap: %s",
		         strerror(errno));
		close(fd);
		return -1;
	}
	s->mem_share = &p->g;
	s->mem_share_fd = fd;
	rad_mem_share(&p->g, &p->daemon_own);
	return 0;
}

void srv_runner_share_fini(srv *s)
{
	if (!s->mem_share)
		return;
	rad_mem_share(NULL, NULL);
	munmap(s->mem_share, sizeof(share_page));
	close(s->mem_share_fd);
	s->mem_share = NULL;
	s->mem_share_fd = -1;
}

/* ------------------------------------------------------------- plumbing */

int srv_wire_write(int fd, const void *buf, size_t len)
{
	const unsigned char *p = buf;
	while (len > 0) {
		ssize_t n = send(fd, p, len, MSG_NOSIGNAL);
		if (n < 0 && errno == EINTR)
			continue;
		if (n <= 0)
			return -1;
		p += n;
		len -= (size_t)n;
	}
	return 0;
}

int srv_wire_read(int fd, void *buf, size_t len)
{
	unsigned char *p = buf;
	while (len > 0) {
		ssize_t n = read(fd, p, len);
		if (n < 0 && errno == EINTR)
			continue;
		if (n <= 0)
			return -1;
		p += n;
		len -= (size_t)n;
	}
	return 0;
}

static void describe_status(int status, char *buf, size_t len)
{
	if (WIFSIGNALED(status)) {
		int sig = WTERMSIG(status);
		snprintf(buf, len, "died of signal %d (%s)", sig,
		         strsignal(sig));
	} else if (WIFEXITED(status)) {
		snprintf(buf, len, "exited with status %d",
		         WEXITSTATUS(status));
	} else {
		snprintf(buf, len, "ended (wait status %#x)", status);
	}
}

/* The process is gone: reap it, take its bytes back, say how. */
static void mark_gone(srv_runner *r, const char *how_if_unknown)
{
	int status = 0;
	char how[160];
	if (r->fd >= 0) {
		close(r->fd);
		r->fd = -1;
	}
	if (r->pid > 0) {
		pid_t p;
		do
			p = waitpid(r->pid, &status, 0);
		while (p < 0 && errno == EINTR);
		if (p == r->pid)
			describe_status(status, how, sizeof(how));
		else
			snprintf(how, sizeof(how), "%s", how_if_unknown);
		snprintf(r->why, sizeof(r->why),
		         "the solver process (pid %d) %s", (int)r->pid, how);
		__atomic_store_n(&r->pid, 0, __ATOMIC_RELAXED);
	}
	if (r->page && r->s->mem_share) {
		int64_t own =
		        __atomic_exchange_n(&r->page->own, 0, __ATOMIC_RELAXED);
		__atomic_fetch_sub(&r->s->mem_share->bytes, own,
		                   __ATOMIC_RELAXED);
	}
	__atomic_store_n(&r->gone, 1, __ATOMIC_RELEASE);
}

static rad_status gone_error(srv_runner *r, rad_error *err)
{
	return rad_fail(err, RAD_ERR_STATE, "%s",
	                r->why[0] ? r->why : "the solver process is gone");
}

static double stop_timeout(srv_runner *r)
{
	return (double)atomic_load(&r->s->solver_stop_ms) / 1000.0;
}

/*
 * Wait for the process's reply to the command just sent, reporting
 * progress (with_progress) and killing the process when the flag has
 * been up for the stop timeout.  0 with r->reply (and, for a step, the
 * solution's bytes) read; -1 when the process is gone (*st says as what:
 * RAD_ERR_CANCELLED when it was killed for not stopping).
 */
static int await_reply(srv_runner *r, int with_progress, rad_status *st,
                       rad_error *err)
{
	uint64_t seen =
	        __atomic_load_n(&r->page->progress_seq, __ATOMIC_ACQUIRE);
	double raised_at = 0;
	for (;;) {
		struct pollfd pfd = {.fd = r->fd, .events = POLLIN};
		int n = poll(&pfd, 1, WAIT_TICK_MS);
		if (n < 0 && errno != EINTR) {
			kill(r->pid, SIGKILL);
			mark_gone(r, "was lost");
			*st = gone_error(r, err);
			return -1;
		}
		if (n > 0)
			break;
		if (with_progress) {
			uint64_t seq = __atomic_load_n(&r->page->progress_seq,
			                               __ATOMIC_ACQUIRE);
			if (seq != seen) {
				seen = seq;
				double f;
				__atomic_load(&r->page->fraction, &f,
				              __ATOMIC_RELAXED);
				r->progress(r->ud, f);
			}
		}
		double tmo = stop_timeout(r);
		if (__atomic_load_n(r->cancel, __ATOMIC_RELAXED)) {
			double now = rad_seconds();
			if (raised_at == 0)
				raised_at = now;
			else if (tmo > 0 && now - raised_at >= tmo) {
				kill(r->pid, SIGKILL);
				mark_gone(r, "was killed");
				size_t n = strlen(r->why);
				snprintf(r->why + n, sizeof(r->why) - n,
				         ": it had not stopped %.1f s after it "
				         "was asked to (solver_stop_timeout)",
				         tmo);
				srv_warn("job %llu: %s",
				         (unsigned long long)r->j->id, r->why);
				*st = rad_fail(err, RAD_ERR_CANCELLED, "%s",
				               r->why);
				return -1;
			}
		} else {
			raised_at = 0;
		}
	}
	double t0 = rad_seconds();
	srv_wmsg h;
	r->sol_len = 0;
	if (srv_wire_read(r->fd, &h, sizeof(h)) != 0 ||
	    h.len != sizeof(srv_wreply) ||
	    srv_wire_read(r->fd, &r->reply, sizeof(r->reply)) != 0)
		goto lost;
	r->sol_len = r->reply.sol_len;
	r->recv_s = rad_seconds() - t0;
	*st = r->reply.err.code;
	if (*st != RAD_OK)
		*err = r->reply.err;
	return 0;
lost:
	r->sol_len = 0;
	/* A process that closed its end died; anything else is a broken
	 * reply, which the process will not survive either. */
	kill(r->pid, SIGKILL);
	mark_gone(r, "was lost");
	*st = gone_error(r, err);
	return -1;
}

static int send_msg(srv_runner *r, uint32_t kind, const void *a, size_t alen,
                    const void *b, size_t blen)
{
	srv_wmsg h = {.kind = kind, .len = alen + blen};
	if (srv_wire_write(r->fd, &h, sizeof(h)) == 0 &&
	    (!alen || srv_wire_write(r->fd, a, alen) == 0) &&
	    (!blen || srv_wire_write(r->fd, b, blen) == 0))
		return 0;
	kill(r->pid, SIGKILL);
	mark_gone(r, "was lost");
	return -1;
}

/* ------------------------------------------------------------- spawning */

static int spawn(srv_runner *r, rad_error *err)
{
	int sv[2] = {-1, -1}, pagefd = -1, moved[4] = {-1, -1, -1, -1};
	posix_spawn_file_actions_t fa;
	posix_spawnattr_t at;
	int fa_ok = 0, at_ok = 0, rc = -1;
	char ppid[32];
	char *argv[] = {"luxradd", "solve-worker", ppid, NULL};

	snprintf(ppid, sizeof(ppid), "%d", (int)getpid());
	if (socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv) != 0) {
		rad_fail(err, RAD_ERR_NOMEM, "solver process: socketpair: %s",
		         strerror(errno));
		goto out;
	}
	pagefd = memfd_create("luxradd-solver", MFD_CLOEXEC);
	if (pagefd < 0 || ftruncate(pagefd, sizeof(srv_wpage)) != 0) {
		rad_fail(err, RAD_ERR_NOMEM, "solver process: memfd: %s",
		         strerror(errno));
		goto out;
	}
	r->page = mmap(NULL, sizeof(srv_wpage), PROT_READ | PROT_WRITE,
	               MAP_SHARED, pagefd, 0);
	if (r->page == MAP_FAILED) {
		r->page = NULL;
		rad_fail(err, RAD_ERR_NOMEM, "solver process: mmap: %s",
		         strerror(errno));
		goto out;
	}
	r->cancel = &r->page->cancel;
	r->solfd = memfd_create("luxradd-solution", MFD_CLOEXEC);
	if (r->solfd < 0) {
		rad_fail(err, RAD_ERR_NOMEM, "solver process: memfd: %s",
		         strerror(errno));
		goto out;
	}
	/* Out of the way of 3..5, where the process finds them. */
	int src[4] = {sv[1], pagefd, r->s->mem_share_fd, r->solfd};
	for (int i = 0; i < 4; i++) {
		moved[i] = fcntl(src[i], F_DUPFD_CLOEXEC, FD_SPARE_BASE);
		if (moved[i] < 0) {
			rad_fail(err, RAD_ERR_NOMEM,
			         "solver process: descriptors: %s",
			         strerror(errno));
			goto out;
		}
	}
	if (posix_spawn_file_actions_init(&fa) != 0)
		goto nomem;
	fa_ok = 1;
	for (int i = 0; i < 4; i++)
		if (posix_spawn_file_actions_adddup2(&fa, moved[i], 3 + i) != 0)
			goto nomem;
	if (posix_spawn_file_actions_addclosefrom_np(&fa, 7) != 0)
		goto nomem;
	if (posix_spawnattr_init(&at) != 0)
		goto nomem;
	at_ok = 1;
	sigset_t none, dfl;
	sigemptyset(&none);
	sigemptyset(&dfl);
	sigaddset(&dfl, SIGINT);
	sigaddset(&dfl, SIGTERM);
	sigaddset(&dfl, SIGHUP);
	/* Its own process group: a terminal's ^C goes to the daemon, which
	 * checkpoints; the signal mask the daemon's threads block is not
	 * inherited. */
	if (posix_spawnattr_setflags(&at, POSIX_SPAWN_SETPGROUP |
	                                          POSIX_SPAWN_SETSIGMASK |
	                                          POSIX_SPAWN_SETSIGDEF) != 0 ||
	    posix_spawnattr_setpgroup(&at, 0) != 0 ||
	    posix_spawnattr_setsigmask(&at, &none) != 0 ||
	    posix_spawnattr_setsigdefault(&at, &dfl) != 0)
		goto nomem;
	int e = posix_spawn(&r->pid, r->s->worker_exe, &fa, &at, argv, environ);
	if (e != 0) {
		__atomic_store_n(&r->pid, 0, __ATOMIC_RELAXED);
		rad_fail(err, RAD_ERR_NOMEM,
		         "cannot start a solver process (%s): %s",
		         r->s->worker_exe, strerror(e));
		goto out;
	}
	r->fd = sv[0];
	sv[0] = -1;
	rc = 0;
	goto out;
nomem:
	rad_fail(err, RAD_ERR_NOMEM, "solver process: out of memory");
out:
	if (fa_ok)
		posix_spawn_file_actions_destroy(&fa);
	if (at_ok)
		posix_spawnattr_destroy(&at);
	for (int i = 0; i < 4; i++)
		if (moved[i] >= 0)
			close(moved[i]);
	for (int i = 0; i < 2; i++)
		if (sv[i] >= 0)
			close(sv[i]);
	if (pagefd >= 0)
		close(pagefd);
	return rc;
}

/* ------------------------------------------------------------ interface */

int srv_runner_new(srv *s, srv_job *j, srv_runner_progress progress, void *ud,
                   srv_runner **out, rad_error *err)
{
	srv_runner *r = calloc(1, sizeof(*r));
	if (!r) {
		rad_fail(err, RAD_ERR_NOMEM, "solver: out of memory");
		return -1;
	}
	r->s = s;
	r->j = j;
	r->progress = progress;
	r->ud = ud;
	r->fd = -1;
	r->solfd = -1;
	r->cancel = &r->cancel_local;
	if (atomic_load(&s->isolation) == SRV_ISOLATION_PROCESS &&
	    spawn(r, err) != 0) {
		srv_runner_free(r);
		return -1;
	}
	*out = r;
	return 0;
}

/* A thread's solver out of memory because of the limit says so (a
 * solver process says it itself, worker.c). */
static rad_status limit_noted(rad_status st, uint64_t refusals_before,
                              rad_error *err)
{
	if (st == RAD_ERR_NOMEM)
		srv_memory_note_limit(rad_mem_limit(), refusals_before,
		                      err->msg, sizeof(err->msg));
	return st;
}

/* A thread's progress: the job's, after the fault a test asked for. */
static void thread_progress(void *ud, double fraction)
{
	srv_runner *r = ud;
	if (r->fault && r->fault != 'h' && r->steps >= 1)
		srv_fault_commit(r->fault);
	r->progress(r->ud, fraction);
}

rad_status srv_runner_build(srv_runner *r, rad_error *err)
{
	srv_job *j = r->j;
	if (!r->page) {
		rad_options o = j->opt;
		r->fault = srv_fault_for(j->name);
		o.progress = thread_progress;
		o.progress_ud = r;
		o.cancel = &r->cancel_local;
		rad_solver *sv = NULL;
		uint64_t before = rad_mem_limit_refusals();
		rad_status st = limit_noted(
		        rad_solver_new(j->scene->scene, &o, &sv, err), before,
		        err);
		/* The I/O thread reads its memory under the job's mutex. */
		pthread_mutex_lock(&j->mu);
		r->sv = sv;
		pthread_mutex_unlock(&j->mu);
		return st;
	}
	if (__atomic_load_n(&r->gone, __ATOMIC_ACQUIRE))
		return gone_error(r, err);

	unsigned char *bytes = NULL;
	size_t len = 0;
	char msg[512];
	pthread_mutex_lock(&r->s->store_mu);
	int rc = srv_store_scene_read(r->s->store, j->scene->id, &bytes, &len,
	                              msg, sizeof(msg));
	pthread_mutex_unlock(&r->s->store_mu);
	if (rc != 0)
		return rad_fail(err, RAD_ERR_IO, "cannot read scene %llu: %s",
		                (unsigned long long)j->scene->id, msg);
	srv_winit in;
	memset(&in, 0, sizeof(in));
	in.opt = j->opt;
	in.opt.progress = NULL;
	in.opt.progress_ud = NULL;
	in.opt.cancel = NULL;
	in.mem_limit = rad_mem_limit();
	in.bvh_mode = (int)rad_bvh_get_mode();
	snprintf(in.name, sizeof(in.name), "%s", j->name);
	in.scene_len = len;
	rad_status st;
	double t0 = rad_seconds();
	if (send_msg(r, W_INIT, &in, sizeof(in), bytes, len) != 0)
		st = gone_error(r, err);
	else
		await_reply(r, 0, &st, err);
	free(bytes);
	if (st == RAD_OK)
		srv_debug("job %llu: solver process %d ready in %.3f s (scene "
		          "of %zu bytes loaded, solver made)",
		          (unsigned long long)j->id, (int)r->pid,
		          rad_seconds() - t0, len);
	return st;
}

rad_status srv_runner_step(srv_runner *r, double tol, rad_error *err)
{
	if (!r->page) {
		if (r->fault == 'h' && r->steps >= 1)
			srv_fault_commit(r->fault);
		uint64_t before = rad_mem_limit_refusals();
		rad_status st = limit_noted(
		        rad_solver_converge(r->sv, tol, 1, err), before, err);
		r->steps += st == RAD_OK;
		return st;
	}
	if (__atomic_load_n(&r->gone, __ATOMIC_ACQUIRE))
		return gone_error(r, err);
	srv_wstep in = {.tol = tol, .mem_limit = rad_mem_limit()};
	rad_status st;
	if (send_msg(r, W_STEP, &in, sizeof(in), NULL, 0) != 0)
		return gone_error(r, err);
	await_reply(r, 1, &st, err);
	return st;
}

rad_status srv_runner_set_eps(srv_runner *r, double eps, rad_error *err)
{
	if (!r->page)
		return rad_solver_set_eps(r->sv, eps, err);
	if (__atomic_load_n(&r->gone, __ATOMIC_ACQUIRE))
		return gone_error(r, err);
	rad_status st;
	if (send_msg(r, W_EPS, &eps, sizeof(eps), NULL, 0) != 0)
		return gone_error(r, err);
	await_reply(r, 0, &st, err);
	return st;
}

void srv_runner_stats(srv_runner *r, rad_stats *st)
{
	if (!r->page)
		rad_solver_stats(r->sv, st);
	else
		*st = r->reply.st;
}

rad_status srv_runner_solution(srv_runner *r, rad_solution **out,
                               rad_error *err)
{
	if (!r->page)
		return rad_solution_new(r->sv, out, err);
	if (!r->sol_len) {
		*err = r->reply.sol_err;
		if (err->code == RAD_OK)
			rad_fail(err, RAD_ERR_STATE,
			         "the solver process sent no solution");
		return err->code;
	}
	/* Read where the process wrote it, then let the pages go. */
	double t0 = rad_seconds();
	rad_status st;
	void *p = mmap(NULL, r->sol_len, PROT_READ, MAP_SHARED | MAP_POPULATE,
	               r->solfd, 0);
	if (p == MAP_FAILED) {
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "the solver process's solution: mmap: %s",
		              strerror(errno));
	} else {
		st = rad_solution_load(r->j->scene->scene, p, r->sol_len, out,
		                       err);
		munmap(p, r->sol_len);
	}
	if (ftruncate(r->solfd, 0) != 0)
		srv_warn("job %llu: cannot empty the solution's memfd: %s",
		         (unsigned long long)r->j->id, strerror(errno));
	srv_debug("job %llu: iteration %u: step %.3f s; solution of %zu "
	          "bytes made and saved %.3f s, received %.3f s, loaded %.3f "
	          "s",
	          (unsigned long long)r->j->id, r->reply.st.iteration,
	          r->reply.step_s, r->sol_len, r->reply.sol_s, r->recv_s,
	          rad_seconds() - t0);
	r->sol_len = 0;
	return st;
}

void srv_runner_memory(srv_runner *r, int64_t bytes[RAD_MEM_NKINDS])
{
	if (!r->page) {
		rad_mem_report m;
		if (!r->sv) { /* still being made */
			memset(bytes, 0, RAD_MEM_NKINDS * sizeof(*bytes));
			return;
		}
		rad_solver_memory(r->sv, &m);
		for (int k = 0; k < RAD_MEM_NKINDS; k++)
			bytes[k] = m.bytes[k] > 0 ? m.bytes[k] : 0;
		return;
	}
	int gone = __atomic_load_n(&r->gone, __ATOMIC_ACQUIRE);
	for (int k = 0; k < RAD_MEM_NKINDS; k++) {
		int64_t b = gone ? 0
		                 : __atomic_load_n(&r->page->mem[k],
		                                   __ATOMIC_RELAXED);
		bytes[k] = b > 0 ? b : 0;
	}
}

void srv_runner_raise(srv_runner *r)
{
	__atomic_store_n(r->cancel, 1, __ATOMIC_RELAXED);
}

void srv_runner_lower(srv_runner *r)
{
	__atomic_store_n(r->cancel, 0, __ATOMIC_RELAXED);
}

int srv_runner_gone(srv_runner *r, char *why, size_t len)
{
	if (r->page && !__atomic_load_n(&r->gone, __ATOMIC_ACQUIRE) &&
	    r->pid > 0) {
		int status = 0;
		if (waitpid(r->pid, &status, WNOHANG) == r->pid) {
			char how[160];
			describe_status(status, how, sizeof(how));
			snprintf(r->why, sizeof(r->why),
			         "the solver process (pid %d) %s", (int)r->pid,
			         how);
			__atomic_store_n(&r->pid, 0, __ATOMIC_RELAXED);
			mark_gone(r, "");
		}
	}
	int gone = __atomic_load_n(&r->gone, __ATOMIC_ACQUIRE);
	if (gone && why)
		snprintf(why, len, "%s", r->why);
	return gone;
}

pid_t srv_runner_pid(const srv_runner *r)
{
	return r->page && !__atomic_load_n(&r->gone, __ATOMIC_ACQUIRE)
	               ? __atomic_load_n(&r->pid, __ATOMIC_RELAXED)
	               : 0;
}

void srv_runner_free(srv_runner *r)
{
	if (!r)
		return;
	rad_solver_free(r->sv);
	if (r->pid > 0) {
		srv_wmsg h = {.kind = W_QUIT};
		if (r->fd >= 0)
			(void)srv_wire_write(r->fd, &h, sizeof(h));
		double until = rad_seconds() + QUIT_WAIT_S;
		int status;
		pid_t p;
		while ((p = waitpid(r->pid, &status, WNOHANG)) == 0) {
			if (rad_seconds() >= until) {
				kill(r->pid, SIGKILL);
				break;
			}
			struct timespec ts = {0, 2000000};
			nanosleep(&ts, NULL);
		}
		if (p == r->pid)
			__atomic_store_n(&r->pid, 0, __ATOMIC_RELAXED);
		mark_gone(r, "quit"); /* reaps it if it was killed */
	} else if (r->page) {
		mark_gone(r, "");
	}
	if (r->fd >= 0)
		close(r->fd);
	if (r->page)
		munmap(r->page, sizeof(srv_wpage));
	if (r->solfd >= 0)
		close(r->solfd);
	free(r);
}
