/*
 * server.h -- luxradd's shared types: the daemon state, scenes, jobs,
 * published solutions, connections, tasks; and the functions each module
 * offers the others.  server.c holds the event loop and this file's
 * DESIGN essay (threads, locks, ownership, drop policy, checkpoints).
 *
 * Module map (one idea per file):
 *   main.c     argv, startup order, exit codes
 *   server.c   listeners, signals, the loop's turn, shutdown
 *   conn.c     connections: input framing, output queues, limits, auth
 *   cmd.c      command table, dispatch, hello/status/shutdown
 *   scenes.c   scene registry and scene.* commands
 *   jobcmd.c   job.* commands and job options
 *   job.c      job state machine and the solver worker threads
 *   publish.c  events to subscribers, subscriptions, the drop policy
 *   query.c    query.* and export, run on the query threads
 *   qsplit.c   one query's points shared out among the query threads
 *   pool.c     thread pools for tasks, the inbox back to the I/O thread
 *   observe.c  the observers of jobs (subscriptions, Modbus) and events
 *   loop/      the event loop (loop.h: watches, timers, wake-up, signals)
 *   persist.c  job rows and checkpoints in the store
 *   recover.c  startup from the store
 *   metrics.c  Prometheus text on a tiny HTTP/1.0 server
 *   log.c      log lines
 */
#ifndef LUXRAD_SRV_SERVER_H
#define LUXRAD_SRV_SERVER_H

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
typedef struct srv_conn srv_conn;
typedef struct srv_job srv_job;
typedef struct srv_scene srv_scene;
typedef struct srv_sol srv_sol;
typedef struct srv_task srv_task;

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

void srv_scene_ref(srv_scene *sc);
void srv_scene_unref(srv_scene *sc);
/* Registry lookup (I/O thread). */
srv_scene *srv_scene_find(srv *s, uint64_t id);
/* Load bytes into a scene object (refs = 1); NULL with err filled. */
srv_scene *srv_scene_load(uint64_t id, const char *name, double created,
                          const void *bytes, size_t len, rad_error *err);
/* Registry insert (I/O thread or startup); takes the caller's ref. */
void srv_scene_register(srv *s, srv_scene *sc);
json_t *srv_scene_json(const srv_scene *sc); /* upload/info body */

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
void srv_sol_ref(srv_sol *p);
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

/* A reply owed when a job leaves "running" (pause, cancel). */
typedef struct job_waiter {
	struct job_waiter *next;
	uint64_t conn_id;
	json_t *id; /* request id (ref) */
} job_waiter;

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
	/* The engine's cancel flag: raised (atomically) under mu by the
	 * I/O thread or the stepping thread, lowered by the worker. */
	volatile int cancel;

	/* worker-owned */
	rad_solver *solver;
	uint32_t solver_iter; /* iterations the solver has done */
	size_t eps_applied;   /* eps_log entries applied to the solver */
	double step_t0;       /* rad_seconds() at the current step's start */
	double last_progress; /* last progress event (rad_seconds) */
	double last_ckpt;     /* rad_seconds() of the last checkpoint */
	int quiet;            /* replaying: no progress events */

	/* I/O thread */
	srv_job *next;       /* registry */
	srv_job *runq_next;  /* run queue link (runq_mu) */
	job_waiter *waiters; /* replies owed on leaving "running" */
	uint64_t pub_seq;    /* state_seq of the last state event sent */
};

void srv_job_ref(srv_job *j);
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
	uint64_t conn_id; /* connection owed a reply (0 = none) */
	json_t *id;       /* the request's id (ref) or NULL */
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

/* ------------------------------------------------------------ connections */

typedef struct srv_chunk {
	struct srv_chunk *next;
	unsigned char *buf; /* owned */
	size_t len, off;
} srv_chunk;

typedef struct srv_sub {
	uint64_t job;
	uint64_t dropped; /* progress events dropped since the last iteration
	                     event delivered */
	uint64_t seq0;    /* state_seq told in the subscribe reply */
	uint32_t iter0;   /* iteration told in the subscribe reply */
} srv_sub;

struct srv_conn {
	el_watch w; /* ud: the srv */
	uint64_t id;
	int fd;
	int listener_tcp;  /* accepted on TCP (else Unix) */
	int needs_token;   /* hello must carry the token */
	int authed;        /* hello accepted */
	char peer[128];    /* for logs */
	unsigned char *in; /* input buffer */
	size_t in_off, in_len, in_cap;
	srv_chunk *out_head, *out_tail;
	size_t out_bytes;   /* queued, not yet written */
	int busy;           /* a deferred reply is owed: read no more frames */
	int closing;        /* flush, then close */
	int stolen;         /* the input buffer was taken by a handler */
	int eof;            /* the peer closed its side */
	int wr_shut;        /* closing: our FIN was sent */
	size_t need;        /* bytes the frame at in_off needs, 0 unknown */
	int dead;           /* close at the end of this loop turn */
	int want_out;       /* EPOLLOUT armed */
	int reading;        /* EPOLLIN armed */
	double close_at;    /* closing: give up flushing at this time */
	double last_active; /* rad_seconds() of the last byte in or out */
	srv_sub *subs;
	int nsubs, subs_cap;
	srv_conn *next, *prev;
};

srv_conn *srv_conn_find(srv *s, uint64_t id);
void srv_conn_accept(srv *s, int lfd, int tcp, int needs_token);
/* Queue bytes (ownership of buf taken); flushes what the socket takes. */
int srv_conn_send(srv *s, srv_conn *c, unsigned char *buf, size_t len);
/* Encode and queue a JSON frame (header not stolen). */
int srv_conn_send_json(srv *s, srv_conn *c, json_t *hdr);
/* Send an error frame; closes the connection when the code says so. */
void srv_conn_send_error(srv *s, srv_conn *c, json_t *id, rp_err code,
                         const char *fmt, ...)
        __attribute__((format(printf, 5, 6)));
/* Forget queued output not yet started (the connection is closing). */
void srv_conn_drop_queued(srv_conn *c);
/* Stop reading; flush what is queued (bounded time); then close. */
void srv_conn_close_after_flush(srv *s, srv_conn *c);
/* A deferred reply was delivered: process buffered frames. */
void srv_conn_unbusy(srv *s, srv_conn *c);
void srv_conn_free_all(srv *s);
/* Close dead connections (I/O thread, end of a loop turn). */
void srv_conn_reap(srv *s);
/* Idle connections, stuck flushes (end of every loop turn). */
void srv_conn_tick(srv *s, double now);
/* Reading paused/unpaused by busy / output pressure. */
void srv_conn_update_events(srv *s, srv_conn *c);
/*
 * Take the connection's input buffer (holding the current frame) away:
 * the caller owns *buf (free), the connection keeps only the bytes after
 * used (the frame's end).
 */
unsigned char *srv_conn_steal_input(srv_conn *c, size_t used);

/* ------------------------------------------------------- command handlers */

typedef enum cmd_result {
	CMD_REPLY = 0, /* *res holds the result members; send ok */
	CMD_ERROR,     /* err filled; send the error */
	CMD_DEFERRED,  /* the reply comes later (conn busy) */
} cmd_result;

typedef struct srv_req {
	srv *s;
	srv_conn *c;
	rp_cmd cmd;
	json_t *hdr;                  /* the request header (borrowed) */
	json_t *id;                   /* "id" or NULL (borrowed) */
	const unsigned char *payload; /* NULL without "bytes" */
	size_t payload_len;
	size_t frame_used; /* bytes of this frame in the input buffer */
	json_t *res;       /* result object to fill (CMD_REPLY) */
	rp_error err;      /* CMD_ERROR */
} srv_req;

typedef cmd_result (*srv_cmd_fn)(srv_req *r);

/* Fill r->err and return CMD_ERROR. */
cmd_result srv_req_fail(srv_req *r, rp_err code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* Dispatch one decoded frame (I/O thread). */
void srv_cmd_dispatch(srv *s, srv_conn *c, rp_frame *f, size_t used);
/* Send a reply owed to a connection that may be gone (I/O thread):
 * reply is stolen; unbusies the connection. */
void srv_reply_deferred(srv *s, uint64_t conn_id, json_t *reply);
/* Same with a pre-encoded frame (buf owned), plus an optional payload. */
void srv_reply_deferred_raw(srv *s, uint64_t conn_id, unsigned char *buf,
                            size_t len, unsigned char *payload, size_t plen);
/* Look up {job: id} in a request; CMD_ERROR with not_found. */
srv_job *srv_req_job(srv_req *r, int *failed);

cmd_result srv_cmd_scene_upload(srv_req *r);
cmd_result srv_cmd_scene_list(srv_req *r);
cmd_result srv_cmd_scene_info(srv_req *r);
cmd_result srv_cmd_scene_delete(srv_req *r);
cmd_result srv_cmd_job_create(srv_req *r);
cmd_result srv_cmd_job_list(srv_req *r);
cmd_result srv_cmd_job_info(srv_req *r);
cmd_result srv_cmd_job_run(srv_req *r);
cmd_result srv_cmd_job_pause(srv_req *r);
cmd_result srv_cmd_job_resume(srv_req *r);
cmd_result srv_cmd_job_cancel(srv_req *r);
cmd_result srv_cmd_job_set(srv_req *r);
cmd_result srv_cmd_job_delete(srv_req *r);
cmd_result srv_cmd_subscribe(srv_req *r);
cmd_result srv_cmd_unsubscribe(srv_req *r);
cmd_result srv_cmd_query_points(srv_req *r);
cmd_result srv_cmd_query_grid(srv_req *r);
cmd_result srv_cmd_query_surfaces(srv_req *r);
cmd_result srv_cmd_export(srv_req *r);
/*
 * rad_solution_illuminance for one query, spread over the query threads
 * (qsplit.c); call from a query-pool task.  Same values as one call.
 */
rad_status srv_query_illuminance(srv *s, const srv_sol *sol, const double *pts,
                                 size_t n, double *lux, double *error_lux,
                                 rad_error *err);

/* Persist a job's row on the store thread, then send reply (stolen);
 * returns CMD_DEFERRED (or CMD_ERROR with r->err filled). */
cmd_result srv_persist_then_reply(srv_req *r, srv_job *j, json_t *reply);
/* Insert a new job's row; sets j->id (store thread). */
int srv_job_store_add(srv *s, srv_job *j, char *msg, size_t msglen);
/* Remove a job's row and checkpoint, releasing the registry's ref to j
 * on the store thread; replies when done. */
cmd_result srv_job_store_delete(srv_req *r, srv_job *j);
/* Map an engine status to a wire error code. */
rp_err srv_err_from_rad(rad_status st);

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

/* publish.c: subscriptions (an observer) and job waiters. */
int srv_subs_start(srv *s);
int srv_job_add_waiter(srv_job *j, uint64_t conn_id, json_t *id);

/* metrics.c */
/* Accept on the metrics listener; the first call starts its timer. */
void srv_metrics_accept(srv *s, int lfd);
void srv_metrics_free_all(srv *s);
/* Jobs and memory summary shared by status and /metrics (I/O thread). */
typedef struct srv_summary {
	int jobs_by_state[SRV_JOB_NSTATES];
	int64_t by_kind[RAD_MEM_NKINDS];
	int64_t total, scenes_bytes, jobs_bytes;
} srv_summary;
void srv_summarize(srv *s, srv_summary *sum);

/* recover.c */
int srv_recover(srv *s, char *msg, size_t msglen);

/* mbpub.c: the daemon's side of the Modbus server (modbus.h).  All on
 * the I/O thread unless said otherwise. */
struct srv_mbpub;
/* Start the server (modbus_listen none: nothing started); -2 with msg
 * when it cannot (bad address, port in use). */
int srv_mb_start(srv *s, char *msg, size_t msglen);
/* After the worker threads are joined. */
void srv_mb_stop(srv *s);
/* "modbus HOST:PORT" for luxradd.addr; 0 when the server is off. */
int srv_mb_addr_text(srv *s, char *buf, size_t len);
json_t *srv_mb_status_json(srv *s);
char *srv_mb_metrics_text(srv *s); /* Prometheus lines, malloc'ed */
cmd_result srv_cmd_sensor_add(srv_req *r);
cmd_result srv_cmd_sensor_list(srv_req *r);

/* -------------------------------------------------------------- the daemon */

#define SRV_MAX_LISTENERS 3

typedef struct srv_listener {
	el_watch w; /* ud: the srv */
	int fd;
	int kind;        /* 0 tcp, 1 unix, 2 metrics */
	int needs_token; /* tcp beyond loopback */
	char text[4200]; /* "tcp HOST:PORT" line for luxradd.addr */
} srv_listener;

struct srv {
	srv_config cfg; /* I/O thread (SIGHUP reloads it) */
	int argc;
	char **argv;
	double t0; /* rad_seconds() at start */
	srv_store *store;
	pthread_mutex_t store_mu; /* serialises every store call */

	/* I/O thread */
	el_loop *loop;
	srv_listener lis[SRV_MAX_LISTENERS];
	int nlis;
	srv_conn *conns;
	int nconns;
	uint64_t next_conn_id;
	void *https; /* metrics.c's connection list */
	int nhttps;
	uint64_t http_timer; /* metrics.c's timer, once a request came */
	srv_scene *scenes;
	int nscenes, scenes_pending; /* pending: uploads in flight */
	srv_job *jobs;
	int njobs, jobs_pending; /* pending: job.create in flight */
	char *token;             /* NULL = none configured */
	size_t token_len;
	int shutting_down; /* stop accepting, checkpoint, exit */
	int loop_done;
	double shutdown_flush_at;
	uint64_t cmd_calls[RP_CMD_COUNT], cmd_errors[RP_CMD_COUNT];
	uint64_t conns_total, events_dropped, slow_consumers;
	char addr_path[4200];
	char lock_path[4200];
	int lock_fd;
	int solver_threads; /* resolved default threads per job */
	double accuracy;    /* default accuracy of jobs (config) */

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

	atomic_int stopping;           /* workers: checkpoint and stop */
	atomic_llong sol_bytes;        /* live published solutions */
	atomic_llong ckpt_interval_ms; /* checkpoint_interval_s */

	struct {
		const srv_observer *ops;
		void *ud;
	} obs[SRV_MAX_OBSERVERS]; /* I/O thread */
	int nobs;
	int live; /* recovery done: new jobs are told to observers */

	struct mb_server *mb;    /* Modbus server (NULL when off) */
	struct srv_mbpub *mbpub; /* mbpub.c's state (I/O thread) */
};

/* server.c */
int srv_init(srv *s, const srv_config *cfg, int argc, char **argv, char *msg,
             size_t msglen);
int srv_listen(srv *s, char *msg, size_t msglen);
int srv_start_threads(srv *s, char *msg, size_t msglen);
int srv_run(srv *s);
void srv_destroy(srv *s);
void srv_begin_shutdown(srv *s, const char *why);
double srv_now_unix(void);
/* Read the token file into s->token; -1 with msg on failure. */
int srv_load_token(srv *s, const srv_config *cfg, char *msg, size_t msglen);
/* Does this connection need the token? */
int srv_token_needed(const srv *s, int listener_needs);

/* jansson refuses NaN and infinities: those become null. */
json_t *srv_jreal(double v);

#endif
