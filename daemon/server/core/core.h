/*
 * core.h -- the service core of luxradd: scenes, jobs and the solver
 * workers, published solutions, the thread pools and the inbox back to
 * the I/O thread, persistence of jobs, recovery at startup, and the
 * observers it tells when jobs come, change and go.
 *
 * The core knows nothing of connections, frames or commands: the command
 * layer above it (cmd/) owns those, submits tasks to the pools, registers
 * itself as an observer (subscriptions, Modbus) and turns what the core
 * reports into replies and events.  Below it: the event loop (loop/),
 * the store (store/), the configuration (base/) and the engine.
 *
 * Files:
 *   service.c  start and stop of the core (store, lock, pools, workers)
 *   registry.c lookups in the scene and job registries
 *   runq.c     the run queue of jobs waiting for a worker
 *   scenes.c   the scene registry and loading a scene
 *   job.c      job state machine and the solver worker threads
 *   runner.c   where a job's solver runs: a thread or a solver process
 *   worker.c   the solver process (luxradd solve-worker)
 *   jobjson.c  job options and targets as JSON (job.info, rows)
 *   persist.c  job rows and checkpoints in the store
 *   recover.c  startup from the store
 *   pool.c     thread pools for tasks, the inbox back to the I/O thread
 *   observe.c  the observers of jobs and the events workers post
 *   qsplit.c   one query's points shared out among the query threads
 *   summary.c  jobs and memory summary (status, /metrics)
 *
 * The DESIGN essay (threads, locks, ownership, checkpoints) is in
 * service.c.
 */
#ifndef LUXRAD_SRV_CORE_H
#define LUXRAD_SRV_CORE_H

#include <jansson.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "config.h"
#include "loop.h"
#include "rad.h"
#include "rp.h"
#include "sceneio.h"
#include "store.h"

#define SRV_NAME "luxradd"
#define SRV_VERSION "0.1.0"

typedef struct srv srv;
typedef struct srv_job srv_job;
typedef struct srv_scene srv_scene;
typedef struct srv_sol srv_sol;
typedef struct srv_task srv_task;
typedef struct srv_runner srv_runner; /* runner.h */

/* ------------------------------------------------------------------ scenes */

/*
 * A parsed scene, shared read-only by every job on it.  Referenced by the
 * registry, by each job and by each published solution; freed (engine
 * scene and all) when the last reference goes, from whichever thread.
 */
struct srv_scene {
	atomic_int refs;
	uint64_t id;             /* the store's id */
	char name[256];          /* immutable */
	char owner[64];          /* the user who uploaded it ("" = the local
	                            admin); immutable */
	uint64_t bytes;          /* size uploaded */
	double created;          /* Unix time */
	rad_scene *scene;        /* committed: read-only, any thread */
	rad_scene_counts counts; /* immutable, read at load */
	sio_info info;           /* immutable */
	double lo[3], hi[3];     /* bounds, immutable */
	rad_mem_report mem;      /* engine memory, read once after commit */
	sio_sensor *sensors;     /* declared in the glTF (immutable) */
	size_t nsensors;
	int njobs;       /* jobs using it (I/O thread) */
	srv_scene *next; /* registry list (I/O thread) */
};

static inline void srv_scene_ref(srv_scene *sc)
{
	atomic_fetch_add(&sc->refs, 1);
}
void srv_scene_unref(srv_scene *sc);
/* Registry lookup (I/O thread). */
srv_scene *srv_scene_find(srv *s, uint64_t id);
/* Load bytes into a scene object (refs = 1); NULL with err filled. */
srv_scene *srv_scene_load(uint64_t id, const char *name, double created,
                          const void *bytes, size_t len, rad_error *err);
/* Registry insert (I/O thread or startup); takes the caller's ref. */
void srv_scene_register(srv *s, srv_scene *sc);
json_t *srv_scene_json(const srv_scene *sc); /* upload/info body */
/* Remove from the registry (I/O thread); the caller gets its ref. */
void srv_scene_unregister(srv *s, srv_scene *sc);
/*
 * Load and store a new scene (store thread): 0 with *out (refs = 1, not
 * registered); -1 when the bytes are refused (err from the loader); -2
 * when the store fails (err->msg says why).
 */
int srv_scene_create(srv *s, const char *name, const char *owner,
                     const void *bytes, size_t len, srv_scene **out,
                     rad_error *err);
/* Delete a scene's stored bytes (store thread): 0, or -1 with msg. */
int srv_scene_forget(srv *s, uint64_t id, char *msg, size_t msglen);

/* --------------------------------------------------------------- solutions */

/* A published rad_solution, refcounted: queries hold it while they run. */
struct srv_sol {
	atomic_int refs;
	rad_solution *sol; /* immutable */
	srv_scene *scene;  /* ref held: the solution reads the scene */
	uint32_t iteration;
	int64_t bytes; /* rad_solution_memory total, counted in s->sol_bytes */
	double query_tol;   /* the job's query tolerance */
	double solve_error; /* the solver's error_estimate then, >= 0 */
};

/*
 * Wrap a solution (steals it; takes a scene ref); NULL on no memory.
 * query_tol and solve_error: what queries of it use (rad_solution_query).
 */
srv_sol *srv_sol_new(srv *s, rad_solution *sol, srv_scene *sc, double query_tol,
                     double solve_error);
static inline void srv_sol_ref(srv_sol *p)
{
	atomic_fetch_add(&p->refs, 1);
}
void srv_sol_unref(srv *s, srv_sol *p);

/* -------------------------------------------------------------------- jobs */

typedef enum job_mode {
	JOB_MODE_NONE = 0,   /* never run */
	JOB_MODE_ITERATIONS, /* n more iterations */
	JOB_MODE_CONVERGE,   /* until converged / max_iterations */
	JOB_MODE_SECONDS     /* a time budget */
} job_mode;

/* A run request (job.run), as kept, persisted and resumed. */
typedef struct job_target {
	job_mode mode;
	uint32_t n;     /* ITERATIONS: as asked */
	uint32_t until; /* ITERATIONS: stop at this iteration count */
	double seconds; /* SECONDS: as asked */
	double left_s;  /* SECONDS: budget left (paused mid-budget) */
	int complete;   /* the target was reached: resume starts afresh */
} job_target;

typedef struct job_eps {
	uint32_t iteration; /* applied when the solver had done this many */
	double eps;
} job_eps;

/*
 * A solve job.  Three owners, by field group:
 *   - immutable after creation (no lock);
 *   - mu: state and everything the I/O side reads while a worker steps;
 *   - the worker holding the job (on_worker = 1) owns the solver;
 *     the I/O thread may touch it only while on_worker == 0 and the
 *     job is not queued.
 */
struct srv_job {
	atomic_int refs;
	/* immutable */
	srv *srv;
	uint64_t id;
	char name[256];
	char owner[64];   /* the user who created it ("" = the local admin) */
	srv_scene *scene; /* ref held */
	rad_options opt;  /* initial options (threads resolved) */
	double created;   /* Unix time */

	pthread_mutex_t mu; /* guards the group below; short holds only */
	srv_job_state state;
	uint64_t state_seq; /* +1 on every state change */
	job_target target;
	int pause_req;       /* job.pause while running */
	int rerun_req;       /* job.run while running: a new target */
	int cancel_req;      /* job.cancel while running */
	int has_pending_eps; /* job.set not yet applied */
	double pending_eps;
	job_eps *eps_log; /* applied (and, after a restart, future) changes */
	size_t neps, eps_cap;
	uint32_t iteration; /* iterations done (published) */
	uint32_t ckpt_iter; /* at the last durable checkpoint */
	int has_result;     /* a checkpoint file exists */
	char *stats_json;   /* latest <stats>, NULL before the first step */
	double residual;    /* from the latest stats */
	uint64_t links;     /* ditto */
	int converged;      /* ditto */
	int64_t solver_mem[RAD_MEM_NKINDS]; /* solver's own bytes, by kind */
	char error[512];                    /* failed: why */
	double updated;                     /* Unix time of the last change */
	int replaying;   /* rebuilding the solver after a restart */
	int on_worker;   /* a worker holds the job */
	int in_runq;     /* linked in the run queue */
	double deadline; /* SECONDS mode: rad_seconds() to stop at, 0 */
	srv_sol *sol;    /* latest published solution (ref), or NULL */
	int deleted;     /* removed from the registry */
	/* The job's solver (runner.h), set and cleared under mu by the
	 * worker: the I/O thread reads its memory, raises its cancel flag
	 * and reaps a process that died while the job waited; only the
	 * worker holding the job steps it. */
	srv_runner *runner;
	double stop_asked; /* rad_seconds() the flag was raised at, or 0 */

	/* worker-owned */
	uint32_t solver_iter; /* iterations the solver has done */
	size_t eps_applied;   /* eps_log entries applied to the solver */
	double step_t0;       /* rad_seconds() at the current step's start */
	double last_progress; /* last progress event (rad_seconds) */
	double last_ckpt;     /* rad_seconds() of the last checkpoint */
	int quiet;            /* replaying: no progress events */

	/* I/O thread */
	srv_job *next;      /* registry */
	srv_job *runq_next; /* run queue link (runq_mu) */
	uint64_t pub_seq;   /* state_seq of the last state event sent */
};

static inline void srv_job_ref(srv_job *j)
{
	atomic_fetch_add(&j->refs, 1);
}
void srv_job_unref(srv *s, srv_job *j);
srv_job *srv_job_find(srv *s, uint64_t id); /* I/O thread */
/* Allocate with defaults (refs = 1; scene ref taken). */
srv_job *srv_job_alloc(srv *s, srv_scene *sc);
/* Registry insert, observers told (takes the caller's ref). */
void srv_job_register(srv *s, srv_job *j);
/* Registry removal (the caller keeps the registry's ref), observers told. */
void srv_job_unregister(srv *s, srv_job *j);
/* Queue a job to run: state := queued (caller holds j->mu). */
void srv_job_enqueue_locked(srv *s, srv_job *j);
/* Raise the engine's cancel flag (caller holds j->mu). */
void srv_job_raise_cancel_locked(srv_job *j);
int srv_job_terminal(srv_job_state st);
/* Target as JSON for job.info; target_json for the store. */
json_t *srv_target_json(const job_target *t);
/* Build the rad_options + tol/max from a stored/created options JSON. */
int srv_job_options_parse(srv *s, json_t *opts, const char *solver,
                          rad_options *o, rp_error *err);
json_t *srv_job_options_json(const srv_job *j); /* effective options */
/* Solver memory of a job plus its solution (caller holds j->mu). */
int64_t srv_job_memory_locked(const srv_job *j);
/* The pid of the job's live solver process, else 0 (caller holds mu). */
int srv_job_solver_pid_locked(const srv_job *j);

/* Worker pool (job.c). */
int srv_workers_start(srv *s, int n, char *msg, size_t msglen);
/* Raise every running job's cancel flag and stop taking jobs. */
void srv_workers_stop_request(srv *s);
int srv_workers_busy(srv *s); /* jobs being stepped right now */
void srv_workers_join(srv *s);

/* Persistence (persist.c): build the row from the job under its lock. */
/*
 * Write the job's row; with sol, also the checkpoint file.  When
 * final_state >= 0, the job's in-memory state becomes final_state and
 * on_worker 0 inside the store lock (so no later row write can carry an
 * older state).  Returns 0 or -1 with msg filled.
 */
int srv_job_persist(srv *s, srv_job *j, srv_sol *sol, int final_state,
                    char *msg, size_t msglen);
/* Serialised pieces of a row. */
char *srv_job_target_text(const srv_job *j);  /* caller holds mu */
char *srv_job_eps_log_text(const srv_job *j); /* caller holds mu */
char *srv_job_options_text(const srv_job *j);

/* -------------------------------------------------------------- tasks */

/*
 * A unit of work for a pool thread (queries, exports, uploads, store
 * writes).  run() executes on the pool thread; done() then executes on
 * the I/O thread (through the inbox) to deliver the result and free the
 * task.  Tasks embed this struct first.
 */
struct srv_task {
	srv_task *next;
	void (*run)(srv *s, srv_task *t);
	void (*done)(srv *s, srv_task *t);
	/* The submitter's, for done(): the command layer names the
	 * connection owed a reply and the request's id (a ref, or NULL). */
	uint64_t conn_id;
	json_t *id;
};

typedef struct srv_pool {
	const char *name;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	srv_task *head, *tail; /* mu */
	size_t queued;         /* mu */
	int stop;              /* mu */
	pthread_t *threads;
	int nthreads;
	srv *s;
} srv_pool;

int srv_pool_start(srv *s, srv_pool *p, const char *name, int n, char *msg,
                   size_t msglen);
void srv_pool_submit(srv_pool *p, srv_task *t);
/* Finish queued tasks, then join the threads. */
void srv_pool_stop(srv_pool *p);

/* ------------------------------------------------- inbox to the I/O thread */

typedef enum msg_kind {
	MSG_TASK_DONE = 0, /* a task finished: run its done() */
	MSG_EVENT,         /* a job event for the observers */
} msg_kind;

typedef enum ev_kind {
	EV_PROGRESS = 0, /* may be dropped */
	EV_ITERATION,
	EV_STATE,
} ev_kind;

/* A job event, as observers receive it (the data, never a frame). */
typedef struct srv_event {
	ev_kind kind;
	uint64_t job;
	uint32_t iteration;  /* PROGRESS: the one under way */
	double fraction;     /* PROGRESS: of that iteration */
	double elapsed_s;    /* PROGRESS: since the step began */
	rad_stats stats;     /* ITERATION: after it */
	srv_job_state state; /* STATE: the new state */
	uint64_t seq;        /* STATE: the job's state_seq after the change */
	int fresh;           /* STATE: newer than every state reported before */
	char error[512];     /* STATE, failed: why */
} srv_event;

typedef struct srv_msg {
	struct srv_msg *next;
	msg_kind kind;
	srv_task *task; /* MSG_TASK_DONE */
	srv_event ev;   /* MSG_EVENT */
} srv_msg;

/* Post to the I/O thread and wake it (any thread). */
void srv_inbox_post(srv *s, srv_msg *m);
/* Post a task's completion. */
void srv_task_finish(srv *s, srv_task *t);
/* Post a job event (copied) for the observers (any thread). */
void srv_event_post(srv *s, const srv_event *ev);
/* I/O thread: drain the inbox (on the loop's wake-up). */
void srv_inbox_drain(srv *s);

/* observe.c: observers of the core (I/O thread). */
typedef struct srv_observer {
	/* srv_recover has restored the registries (0, or -1 with msg). */
	int (*recovered)(void *ud, char *msg, size_t msglen);
	/* A job was created (after recovery; restored ones: recovered). */
	void (*job_added)(void *ud, srv_job *j);
	void (*job_event)(void *ud, srv_job *j, const srv_event *ev);
	/* A job left the registry (job.delete). */
	void (*job_gone)(void *ud, srv_job *j);
} srv_observer;
#define SRV_MAX_OBSERVERS 4
/* Called in registration order; -1 when the table is full. */
int srv_observe(srv *s, const srv_observer *ops, void *ud);
/* Tell the observers (srv_recover's end; after it, jobs are "live"). */
int srv_observers_recovered(srv *s, char *msg, size_t msglen);
void srv_job_added(srv *s, srv_job *j);
void srv_job_gone(srv *s, srv_job *j);
/* An event reached the I/O thread: to every observer. */
void srv_event_dispatch(srv *s, srv_event *ev);
/* The state event of a job (caller holds j->mu). */
void srv_state_event_locked(const srv_job *j, srv_event *ev);
/* The I/O thread changed a job's state (caller released mu): tell the
 * observers now. */
void srv_job_state_changed(srv *s, srv_job *j);

/* Insert a new job's row; sets j->id (store thread). */
int srv_job_store_add(srv *s, srv_job *j, char *msg, size_t msglen);
/* Remove a job's row and checkpoint (store thread); 0 or -1 with msg. */
int srv_job_store_remove(srv *s, srv_job *j, char *msg, size_t msglen);
/* A finished job's solver, taken away (NULL when the job is live or has
 * none): the caller frees it (srv_runner_free), off the I/O thread. */
srv_runner *srv_job_detach_solver(srv_job *j);
void srv_runner_free(srv_runner *r);
/* `luxradd solve-worker PARENT-PID`, the solver process a job runs in
 * (worker.c; started by the daemon itself, runner.c). */
int srv_worker_main(int argc, char **argv);

/*
 * rad_solution_illuminance for one query, spread over the query threads
 * (qsplit.c); call from a query-pool task.  Same values as one call.
 */
rad_status srv_query_illuminance(srv *s, const srv_sol *sol, const double *pts,
                                 size_t n, double *lux, double *error_lux,
                                 rad_error *err);

/* Jobs and memory summary shared by status and /metrics (I/O thread). */
typedef struct srv_summary {
	int jobs_by_state[SRV_JOB_NSTATES];
	int64_t by_kind[RAD_MEM_NKINDS];
	int64_t total, scenes_bytes, jobs_bytes;
} srv_summary;
void srv_summarize(srv *s, srv_summary *sum);

/* recover.c: restore scenes and jobs from the store, then tell the
 * observers (srv_observers_recovered). */
int srv_recover(srv *s, char *msg, size_t msglen);

/* ---------------------------------------------------------------- the core */

struct srv {
	srv_config cfg; /* I/O thread (SIGHUP reloads it) */
	double t0;      /* rad_seconds() at start */
	srv_store *store;
	pthread_mutex_t store_mu; /* serialises every store call */
	char lock_path[4200];
	int lock_fd;   /* one daemon per data directory */
	el_loop *loop; /* the I/O thread's (timers, the inbox wake-up) */

	/* I/O thread */
	srv_scene *scenes;
	int nscenes, scenes_pending; /* pending: uploads in flight */
	srv_job *jobs;
	int njobs, jobs_pending; /* pending: job.create in flight */
	int solver_threads;      /* resolved default threads per job */
	double accuracy;         /* default accuracy of jobs (config) */
	double job_budget_mib;   /* default memory_budget of jobs (config) */

	/* inbox: any thread -> I/O thread */
	pthread_mutex_t inbox_mu;
	srv_msg *inbox_head, *inbox_tail;

	/* run queue and solver workers */
	pthread_mutex_t runq_mu;
	pthread_cond_t runq_cv;
	srv_job *runq_head, *runq_tail; /* runq_mu */
	int runq_stop;                  /* runq_mu */
	int busy_workers;               /* runq_mu */
	pthread_t *workers;
	int nworkers;

	srv_pool query_pool; /* queries and exports */
	srv_pool store_pool; /* uploads, job rows: one thread, in order */

	atomic_int stopping;    /* workers: checkpoint and stop */
	atomic_llong sol_bytes; /* live published solutions */
	int64_t mem_limit;      /* the engine's limit in force (memory.c) */
	/* The memory count the daemon and its solver processes share
	 * (runner.c), and the page's descriptor they inherit. */
	rad_mem_shared *mem_share;
	int mem_share_fd;
	atomic_int isolation;          /* srv_isolation, for new solvers */
	atomic_llong solver_stop_ms;   /* solver_stop_timeout */
	char worker_exe[64];           /* the solver process's program */
	atomic_llong ckpt_interval_ms; /* checkpoint_interval_s */

	struct {
		const srv_observer *ops;
		void *ud;
	} obs[SRV_MAX_OBSERVERS]; /* I/O thread */
	int nobs;
	int live; /* recovery done: new jobs are told to observers */
};

/* service.c */
/*
 * Open the store (and lock the data directory), resolve the thread
 * counts, hook the inbox to loop's wake-up.  s is zeroed by the caller.
 * 0, or -1 with msg filled.
 */
int srv_core_init(srv *s, const srv_config *cfg, el_loop *loop, char *msg,
                  size_t msglen);
/* Start the pools and the solver workers. */
int srv_core_start(srv *s, char *msg, size_t msglen);
/* New config (SIGHUP): take what can change while running. */
void srv_core_reconfigure(srv *s, const srv_config *cfg);

/* memory.c: the engine's memory limit from cfg.memory_limit (0: 3/4 of
 * the machine's or the cgroup's memory); at start and on reload. */
void srv_memory_limit_apply(srv *s);
/* 1 with why filled when the limit is reached: no new work. */
int srv_memory_full(const srv *s, char *why, size_t len);
/* Append to msg that the limit refused an allocation, if it did since
 * rad_mem_limit_refusals() read refusals_before. */
void srv_memory_note(const srv *s, uint64_t refusals_before, char *msg,
                     size_t len);
/* The same for a given limit (a solver, in whichever process it runs). */
void srv_memory_note_limit(int64_t limit, uint64_t refusals_before, char *msg,
                           size_t len);
/*
 * Shutting down: the first call asks the workers to checkpoint and stop;
 * returns 1 once they have, the pools have finished their tasks and the
 * inbox is drained (the replies delivered), else 0.  Call every turn.
 */
int srv_core_quiesce(srv *s);
/* The same, waiting: workers stopped and joined, pools stopped, inbox
 * drained.  Safe to call again, and when nothing was started. */
void srv_core_stop(srv *s);
/* Free the registries, close the store (after srv_core_quiesce or when
 * nothing was started). */
void srv_core_destroy(srv *s);

#endif
