/*
 * worker.c -- the solver process, `luxradd solve-worker PARENT-PID`
 * (runner.h for the design; runner.c is the daemon's side).
 *
 * It finds its control socket on descriptor 3, its page on 4, the
 * daemon's shared memory count on 5 and a memfd for solutions on 6, and
 * serves one job: W_INIT loads
 * the scene and makes the solver, W_STEP steps it once and sends the
 * statistics and the solution, W_EPS changes eps, W_QUIT (or the
 * socket's end) ends it.  It never writes to the log: every failure goes
 * back in a reply.  It dies with the daemon (PR_SET_PDEATHSIG), ignores
 * the signals a terminal or a service manager sends the daemon (the
 * daemon stops it), and leaves with _exit: the kernel takes its memory
 * back faster than the engine could free it.
 */
#include <malloc.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include "runner.h"

#define CTL_FD 3
#define PAGE_FD 4
#define SHARE_FD 5
#define SOL_FD 6 /* memfd: each step's solution, read by the daemon */
#define MEM_TICK_NS 50000000L /* memory by kind into the page: 50 ms */

typedef struct worker {
	srv_wpage *page;
	rad_scene *scene;
	rad_mem_report scene_mem;
	rad_solver *sv; /* set once (atomic): the monitor reads it */
	uint32_t steps; /* iterations done */
	/* LUXRAD_TEST_FAULT for this job: 0 none, else 's', 'a', 'h' */
	int fault;
} worker;

static void reply(const srv_wreply *r)
{
	srv_wmsg h = {.kind = 0, .len = sizeof(*r)};
	if (srv_wire_write(CTL_FD, &h, sizeof(h)) != 0 ||
	    srv_wire_write(CTL_FD, r, sizeof(*r)) != 0)
		_exit(0); /* the daemon is gone */
}

/* A step's solution into SOL_FD: the daemon maps it, then empties it. */
static int put_solution(const unsigned char *p, size_t len, rad_error *err)
{
	size_t off = 0;
	while (off < len) {
		ssize_t n = pwrite(SOL_FD, p + off, len - off, (off_t)off);
		if (n <= 0) {
			rad_fail(err, RAD_ERR_NOMEM,
			         "solver process: the solution's %zu bytes "
			         "could not be passed on",
			         len);
			return -1;
		}
		off += (size_t)n;
	}
	return 0;
}

/* Memory by kind into the page: the solver's and the scene's. */
static void publish_memory(worker *w)
{
	rad_mem_report m = w->scene_mem;
	rad_solver *sv = __atomic_load_n(&w->sv, __ATOMIC_ACQUIRE);
	if (sv) {
		rad_mem_report s;
		rad_solver_memory(sv, &s);
		for (int k = 0; k < RAD_MEM_NKINDS; k++)
			m.bytes[k] += s.bytes[k];
	}
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		__atomic_store_n(&w->page->mem[k], m.bytes[k],
		                 __ATOMIC_RELAXED);
}

static void *monitor(void *arg)
{
	worker *w = arg;
	for (;;) {
		struct timespec ts = {0, MEM_TICK_NS};
		nanosleep(&ts, NULL);
		publish_memory(w);
	}
	return NULL;
}

static void on_progress(void *ud, double fraction)
{
	worker *w = ud;
	__atomic_store(&w->page->fraction, &fraction, __ATOMIC_RELAXED);
	__atomic_fetch_add(&w->page->progress_seq, 1, __ATOMIC_RELEASE);
	if (w->fault && w->fault != 'h' && w->steps >= 1)
		srv_fault_commit(w->fault);
}

static void do_init(worker *w, unsigned char *buf, size_t len)
{
	srv_wreply r;
	srv_winit in;
	memset(&r, 0, sizeof(r));
	memcpy(&in, buf, sizeof(in));
	if (w->scene || len - sizeof(in) != in.scene_len) {
		rad_fail(&r.err, RAD_ERR_STATE, "solver process: bad init");
		reply(&r);
		return;
	}
	in.name[sizeof(in.name) - 1] = '\0';
	w->fault = srv_fault_for(in.name);
	rad_mem_set_limit(in.mem_limit);
	rad_bvh_set_mode(in.bvh_mode == RAD_BVH_COMPACT ? RAD_BVH_COMPACT
	                                                : RAD_BVH_FAST);
	uint64_t refusals = rad_mem_limit_refusals();
	sio_info info;
	sio_sensor *sensors = NULL;
	size_t nsensors = 0;
	if (sio_load(buf + sizeof(in), in.scene_len, &w->scene, &info, &sensors,
	             &nsensors, &r.err) != RAD_OK) {
		srv_memory_note_limit(in.mem_limit, refusals, r.err.msg,
		                      sizeof(r.err.msg));
		reply(&r);
		return;
	}
	sio_sensors_free(sensors);
	rad_scene_memory(w->scene, &w->scene_mem);
	rad_options o = in.opt;
	o.progress = on_progress;
	o.progress_ud = w;
	o.cancel = &w->page->cancel;
	rad_solver *sv = NULL;
	if (rad_solver_new(w->scene, &o, &sv, &r.err) == RAD_OK) {
		__atomic_store_n(&w->sv, sv, __ATOMIC_RELEASE);
		pthread_t t;
		if (pthread_create(&t, NULL, monitor, w) == 0)
			pthread_detach(t);
	} else {
		srv_memory_note_limit(in.mem_limit, refusals, r.err.msg,
		                      sizeof(r.err.msg));
	}
	publish_memory(w);
	reply(&r);
}

static void do_step(worker *w, const srv_wstep *in)
{
	srv_wreply r;
	unsigned char *bytes = NULL;
	size_t len = 0;
	memset(&r, 0, sizeof(r));
	if (!w->sv) {
		rad_fail(&r.err, RAD_ERR_STATE, "solver process: no solver");
		reply(&r);
		return;
	}
	rad_mem_set_limit(in->mem_limit);
	uint64_t refusals = rad_mem_limit_refusals();
	if (w->fault == 'h' && w->steps >= 1)
		srv_fault_commit(w->fault);
	double t0 = rad_seconds();
	if (rad_solver_converge(w->sv, in->tol, 1, &r.err) == RAD_OK) {
		w->steps++;
		double t1 = rad_seconds();
		rad_solution *sol = NULL;
		rad_solver_stats(w->sv, &r.st);
		if (rad_solution_new(w->sv, &sol, &r.sol_err) == RAD_OK &&
		    rad_solution_save(sol, &bytes, &len, &r.sol_err) ==
		            RAD_OK &&
		    put_solution(bytes, len, &r.sol_err) == 0)
			r.sol_len = len;
		rad_solution_free(sol);
		r.step_s = t1 - t0;
		r.sol_s = rad_seconds() - t1;
	} else {
		srv_memory_note_limit(in->mem_limit, refusals, r.err.msg,
		                      sizeof(r.err.msg));
	}
	publish_memory(w);
	free(bytes);
	/* The solution's bytes went to the memfd: give the pages back
	 * rather than keep them in the allocator's free lists. */
	malloc_trim(0);
	reply(&r);
}

static void do_eps(worker *w, double eps)
{
	srv_wreply r;
	memset(&r, 0, sizeof(r));
	if (!w->sv)
		rad_fail(&r.err, RAD_ERR_STATE, "solver process: no solver");
	else
		rad_solver_set_eps(w->sv, eps, &r.err);
	reply(&r);
}

int srv_worker_main(int argc, char **argv)
{
	static worker w;
	if (argc < 3) {
		fprintf(stderr, "luxradd solve-worker: started by luxradd "
		                "itself, not by hand\n");
		return 2;
	}
	/* Dies with the daemon; if the daemon is already gone, go. */
	prctl(PR_SET_PDEATHSIG, SIGKILL);
	if (getppid() != (pid_t)atoi(argv[2]))
		_exit(1);
	signal(SIGPIPE, SIG_IGN);
	signal(SIGINT, SIG_IGN);
	signal(SIGTERM, SIG_IGN);
	signal(SIGHUP, SIG_IGN);
	w.page = mmap(NULL, sizeof(srv_wpage), PROT_READ | PROT_WRITE,
	              MAP_SHARED, PAGE_FD, 0);
	rad_mem_shared *g =
	        mmap(NULL, sizeof(rad_mem_shared), PROT_READ | PROT_WRITE,
	             MAP_SHARED, SHARE_FD, 0);
	if (w.page == MAP_FAILED || g == MAP_FAILED)
		_exit(1);
	close(PAGE_FD);
	close(SHARE_FD);
	rad_mem_share(g, &w.page->own);

	for (;;) {
		srv_wmsg h;
		if (srv_wire_read(CTL_FD, &h, sizeof(h)) != 0 ||
		    h.kind == W_QUIT)
			_exit(0);
		unsigned char *buf = NULL;
		size_t min = h.kind == W_INIT   ? sizeof(srv_winit)
		             : h.kind == W_STEP ? sizeof(srv_wstep)
		             : h.kind == W_EPS  ? sizeof(double)
		                                : SIZE_MAX;
		if (h.len < min || h.len > SIZE_MAX / 2 ||
		    !(buf = malloc(h.len)) ||
		    srv_wire_read(CTL_FD, buf, h.len) != 0)
			_exit(1);
		if (h.kind == W_INIT)
			do_init(&w, buf, h.len);
		else if (h.kind == W_STEP)
			do_step(&w, (const srv_wstep *)buf);
		else {
			double eps;
			memcpy(&eps, buf, sizeof(eps));
			do_eps(&w, eps);
		}
		free(buf);
	}
}
