/*
 * runner.h -- where a job's solver runs, behind the one interface job.c
 * drives (core-internal).
 *
 * isolation = process (the default): the solver lives in a solver
 * process of its own, `luxradd solve-worker`, started with posix_spawn
 * the first time the job runs and kept while the job holds a solver.  It
 * loads the job's scene from the stored bytes, builds the solver with
 * the job's options and steps it on command; after each step it replies
 * with the statistics and writes the solution (rad_solution_save's
 * bytes) in a memfd both map, which the daemon loads against its own
 * copy of the scene, then empties.  A fault in the engine
 * (a crash, an abort) ends that process only: the job fails with the
 * signal named and keeps its last published iteration, and the daemon
 * and every other job go on.  The engine is deterministic, so the
 * process's results are the daemon's own, to the last bit.
 *
 * isolation = thread: the solver lives on the worker thread, as a plain
 * rad_solver; no process is started, and one fault stops every job.
 *
 * What the two share with the daemon:
 *   - the cancel flag (srv_runner_raise/lower): a process reads it in a
 *     page both map, so a raised flag is seen at the engine's next cancel
 *     point, as on a thread;
 *   - the memory limit: every process counts into the daemon's
 *     rad_mem_shared (rad_mem_share), so memory_limit holds for the
 *     daemon and its solver processes together, and a dead process's
 *     bytes are taken back out;
 *   - progress: the process writes the fraction in the page, and the
 *     worker thread waiting for its reply reports it (every 0.1 s);
 *   - memory by kind while a step grows it: written in the page by the
 *     process every 50 ms, read by srv_runner_memory.
 *
 * A solver process that has not answered solver_stop_timeout after the
 * flag was raised is killed: the step returns RAD_ERR_CANCELLED and the
 * runner is gone (srv_runner_gone); the job rebuilds and replays a new
 * one when it runs again.
 *
 * Tests inject faults with LUXRAD_TEST_FAULT=KIND:JOB-NAME in the
 * daemon's environment (KIND: segv, abort, hang): the solver process of
 * the job of that name commits it in the job's second iteration, at the
 * engine's first progress report (segv, abort) or as the step starts
 * (hang: the engine never sees the cancel flag).
 */
#ifndef LUXRAD_SRV_RUNNER_H
#define LUXRAD_SRV_RUNNER_H

#include <sys/types.h>

#include "core.h"

typedef struct srv_runner srv_runner;

/* Progress of a step, on the worker thread (never with j->mu held). */
typedef void (*srv_runner_progress)(void *ud, double fraction);

/*
 * A runner for job j, without a solver yet: for a process, the process is
 * started (fast; its scene is loaded by srv_runner_build).  0, or -1
 * with err filled.
 */
int srv_runner_new(srv *s, srv_job *j, srv_runner_progress progress, void *ud,
                   srv_runner **out, rad_error *err);
/* Load the scene (process) and make the solver; the matrix solver's form
 * factors are long and cancellable.  RAD_OK or the engine's error. */
rad_status srv_runner_build(srv_runner *r, rad_error *err);
/* One iteration, as rad_solver_converge(sv, tol, 1). */
rad_status srv_runner_step(srv_runner *r, double tol, rad_error *err);
rad_status srv_runner_set_eps(srv_runner *r, double eps, rad_error *err);
/* After a step that returned RAD_OK: its statistics, and a fresh
 * solution (NULL with err filled when none could be made). */
void srv_runner_stats(srv_runner *r, rad_stats *st);
rad_status srv_runner_solution(srv_runner *r, rad_solution **out,
                               rad_error *err);
/* What the solver holds now, by kind: a thread's solver without the
 * scene; a process's every counted byte, its copy of the scene included.
 * Any thread; the caller holds the job's mu. */
void srv_runner_memory(srv_runner *r, int64_t bytes[RAD_MEM_NKINDS]);
/* The engine's cancel flag (caller holds the job's mu). */
void srv_runner_raise(srv_runner *r);
void srv_runner_lower(srv_runner *r);
/*
 * 1 when the runner can no longer step: its process died or was killed
 * (why says how, when not NULL).  Reaps an idle process that died
 * (budget tick); caller holds the job's mu and no step is under way.
 */
int srv_runner_gone(srv_runner *r, char *why, size_t len);
/* The solver process's pid (0 for a thread, or once it is gone). */
pid_t srv_runner_pid(const srv_runner *r);
/* Free the solver: a process is told to quit, waited for, and killed if
 * it does not; its counted bytes are taken back.  NULL is a no-op. */
void srv_runner_free(srv_runner *r);

/*
 * LUXRAD_TEST_FAULT for the job of this name: 0 (none), 's' (segv),
 * 'a' (abort) or 'h' (hang); srv_fault_commit commits it.
 */
int srv_fault_for(const char *job);
void srv_fault_commit(int kind);

/* The daemon's side of the shared count (service.c): a page every solver
 * process maps.  0, or -1 with msg filled. */
int srv_runner_share_init(srv *s, char *msg, size_t msglen);
void srv_runner_share_fini(srv *s);

/* Wire between runner.c and worker.c (one program: raw structs).
 * Whole buffers over the control socket: 0, or -1 when the other end
 * is gone (EINTR retried; no SIGPIPE). */
int srv_wire_write(int fd, const void *buf, size_t len);
int srv_wire_read(int fd, void *buf, size_t len);

enum { W_INIT = 1, W_STEP, W_EPS, W_QUIT };

typedef struct srv_wmsg {
	uint32_t kind;
	uint32_t pad;
	uint64_t len; /* bytes after this header */
} srv_wmsg;

/* The page one solver process shares with the daemon. */
typedef struct srv_wpage {
	int cancel; /* the engine's cancel flag (atomic) */
	int pad;
	uint64_t progress_seq;       /* +1 per progress report (atomic) */
	double fraction;             /* of the step under way (atomic) */
	int64_t own;                 /* rad_mem_share: the process's count */
	int64_t mem[RAD_MEM_NKINDS]; /* by kind, every 50 ms (atomic) */
} srv_wpage;

typedef struct srv_winit {
	rad_options opt; /* pointers cleared */
	int64_t mem_limit;
	int bvh_mode;       /* rad_bvh_mode, the daemon's */
	char name[256];     /* the job's name (fault injection) */
	uint64_t scene_len; /* the scene's bytes follow */
} srv_winit;

typedef struct srv_wstep {
	double tol;
	int64_t mem_limit;
} srv_wstep;

typedef struct srv_wreply {
	rad_error err;     /* code RAD_OK on success */
	rad_stats st;      /* W_STEP */
	rad_error sol_err; /* W_STEP: why no solution came */
	uint64_t sol_len;  /* W_STEP: solution bytes in the memfd */
	double step_s;     /* W_STEP: the step's seconds */
	double sol_s;      /* W_STEP: the solution's, made and saved */
} srv_wreply;

#endif
