/*
 * service.c -- the service core's life: start (store, data-directory
 * lock, thread counts, the inbox's wake-up, pools, workers), shutdown
 * (workers checkpoint, pools finish, inbox drained) and the end; and the
 * summary of jobs and memory that status and /metrics report.
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
 *     steps its solver.  After each iteration it publishes the stats
 *     (JSON text) and a rad_solution under the job's mutex, posts an
 *     iteration event to the inbox, and checkpoints when due;
 *   - the solver itself runs, by default (isolation = process), in a
 *     solver process of the job's own (runner.h): the worker sends it
 *     commands and waits for its replies, so a crash in the engine ends
 *     that process, fails that job and nothing else;
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
 * The engine's cancel flag (the runner's: in a page the solver process
 * maps, or the runner's own for a thread) is written with atomic stores
 * under job->mu by the I/O thread (pause, cancel, budgets, shutdown) and
 * by the worker (its own budget check on progress).  A solver process
 * that has not stopped solver_stop_timeout after it was raised is
 * killed, so no engine phase can hold a job, or a shutdown, for long.
 *
 * Ownership.  Scenes, jobs and solutions are refcounted (atomic): the
 * registry holds one reference, each job holds its scene, each
 * solution holds its scene (it reads the geometry), each in-flight task
 * holds what it reads.  So a deleted job whose solution a query still
 * reads stays alive until that query ends, and scene.delete releases the
 * scene's memory when the last reader lets go.  A connection is named by
 * its id in tasks and waiters (the command layer's), never by pointer: it may
 * be gone when the reply is ready, and the reply is then dropped.
 *
 * Requests on one connection are handled in order: while a deferred
 * reply is owed the connection is "busy" and its next frames wait in
 * its input buffer (events still flow).  So replies come in request
 * order, and a client pipelining requests cannot make the daemon queue
 * unbounded work for it.
 *
 * Drop policy (cmd/publish.c).  Each connection has an output queue.  Replies
 * are always queued (the client asked for them; a connection whose queue
 * exceeds max_output_bytes is not read until it drains).  Events are queued
 * only while the queue stays within max_output_bytes: a progress event that
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
 * Shutdown (SIGTERM, SIGINT, "shutdown", cmd/server.c).  Stop
 * accepting; raise every running job's cancel flag; workers record their
 * job as queued and checkpoint it; then the pools finish their tasks
 * (srv_core_quiesce), every connection gets shutting_down, output is
 * flushed (bounded), the solver processes are told to quit (and killed
 * after 2 s), and the process exits 0.  Solver processes ignore SIGINT,
 * SIGTERM and SIGHUP (a terminal's ^C or a service manager's stop is the
 * daemon's to handle) and die with the daemon (PR_SET_PDEATHSIG).
 *
 */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/file.h>
#include <time.h>
#include <unistd.h>

#include "core.h"
#include "log.h"
#include "runner.h"

/* ------------------------------------------------------------------ start */

static void inbox_wake(el_loop *l, void *ud)
{
	(void)l;
	srv_inbox_drain(ud);
}

int srv_core_init(srv *s, const srv_config *cfg, el_loop *loop, char *msg,
                  size_t msglen)
{
	s->cfg = *cfg;
	s->t0 = rad_seconds();
	s->loop = loop;
	s->lock_fd = -1;
	pthread_mutex_init(&s->store_mu, NULL);
	pthread_mutex_init(&s->inbox_mu, NULL);
	pthread_mutex_init(&s->runq_mu, NULL);
	pthread_cond_init(&s->runq_cv, NULL);
	atomic_store(&s->ckpt_interval_ms,
	             (long long)(cfg->checkpoint_interval_s * 1000.0));
	atomic_store(&s->isolation, (int)cfg->isolation);
	atomic_store(&s->solver_stop_ms,
	             (long long)(cfg->solver_stop_timeout_s * 1000.0));
	snprintf(s->worker_exe, sizeof(s->worker_exe), "/proc/self/exe");
	s->mem_share_fd = -1;
	srv_memory_limit_apply(s);
	if (srv_runner_share_init(s, msg, msglen) != 0)
		return -1;

	long cores = sysconf(_SC_NPROCESSORS_ONLN);
	int w = cfg->workers > 0 ? cfg->workers : 1;
	s->accuracy = cfg->accuracy;
	rad_bvh_set_mode(cfg->bvh == RAD_BVH_COMPACT ? RAD_BVH_COMPACT
	                                             : RAD_BVH_FAST);
	s->job_budget_mib = (double)cfg->job_memory_budget / 1048576.0;
	s->solver_threads = cfg->solver_threads > 0
	                            ? cfg->solver_threads
	                            : (int)(cores > w ? cores / w : 1);
	if (el_wake_init(loop, inbox_wake, s, msg, msglen) != 0)
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
	return 0;
}

int srv_core_start(srv *s, char *msg, size_t msglen)
{
	int q = s->cfg.query_threads > 0 ? s->cfg.query_threads : 1;
	if (srv_pool_start(s, &s->store_pool, "store", 1, msg, msglen) != 0 ||
	    srv_pool_start(s, &s->query_pool, "query", q, msg, msglen) != 0)
		return -1;
	return srv_workers_start(s, s->cfg.workers > 0 ? s->cfg.workers : 1,
	                         msg, msglen);
}

void srv_core_reconfigure(srv *s, const srv_config *cfg)
{
	s->cfg = *cfg;
	srv_memory_limit_apply(s);
	atomic_store(&s->isolation, (int)cfg->isolation);
	atomic_store(&s->solver_stop_ms,
	             (long long)(cfg->solver_stop_timeout_s * 1000.0));
	atomic_store(&s->ckpt_interval_ms,
	             (long long)(cfg->checkpoint_interval_s * 1000.0));
}

/* ------------------------------------------------------------------- stop */

void srv_core_stop(srv *s)
{
	if (!atomic_load(&s->stopping))
		srv_workers_stop_request(s);
	srv_workers_join(s);
	srv_pool_stop(&s->query_pool);
	srv_pool_stop(&s->store_pool);
	srv_inbox_drain(s);
}

int srv_core_quiesce(srv *s)
{
	if (!atomic_load(&s->stopping))
		srv_workers_stop_request(s);
	if (srv_workers_busy(s) > 0)
		return 0;
	srv_core_stop(s);
	return 1;
}

void srv_core_destroy(srv *s)
{
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
	pthread_mutex_destroy(&s->store_mu);
	pthread_mutex_destroy(&s->inbox_mu);
	pthread_mutex_destroy(&s->runq_mu);
	pthread_cond_destroy(&s->runq_cv);
	srv_runner_share_fini(s);
}

/* ---------------------------------------------------------------- summary */

void srv_summarize(srv *s, srv_summary *sum)
{
	memset(sum, 0, sizeof(*sum));
	for (srv_scene *sc = s->scenes; sc; sc = sc->next) {
		for (int k = 0; k < RAD_MEM_NKINDS; k++)
			sum->by_kind[k] += sc->mem.bytes[k];
		sum->scenes_bytes += sc->mem.total;
	}
	for (srv_job *j = s->jobs; j; j = j->next) {
		pthread_mutex_lock(&j->mu);
		sum->jobs_by_state[j->state]++;
		for (int k = 0; k < RAD_MEM_NKINDS; k++) {
			sum->by_kind[k] += j->solver_mem[k];
			sum->jobs_bytes += j->solver_mem[k];
		}
		pthread_mutex_unlock(&j->mu);
	}
	/* Every live solution, also one a query still reads after its job
	 * published a newer one: what the process really holds. */
	int64_t sol = atomic_load(&s->sol_bytes);
	sum->by_kind[RAD_MEM_SOLUTION] += sol;
	sum->jobs_bytes += sol;
	sum->total = sum->scenes_bytes + sum->jobs_bytes;
}
