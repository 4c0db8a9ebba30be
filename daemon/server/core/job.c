/*
 * job.c -- jobs and the solver workers: the state machine a worker runs
 * from queued to paused / done / failed / cancelled, publication of
 * statistics and solutions after each iteration, progress, budgets,
 * eps changes, replays after a restart and checkpoints.
 *
 * DESIGN
 * A worker takes a job from the run queue and holds it (on_worker) until
 * it stops; only that worker steps the job's solver (runner.h: in a
 * solver process of the job's own, or on this thread).  Between
 * iterations it decides under the job's mutex what to do next
 * (next_action): cancel, pause, stop for a shutdown, finish (converged or
 * max_iterations), pause because the target is reached, or step; the
 * eps changes due at this iteration are applied there too, and logged
 * with the iteration they were applied at.  Requests from the I/O thread
 * (pause, cancel, a budget running out, shutdown) set a flag under the
 * mutex and raise the engine's cancel flag, so a long iteration stops at
 * its next cancel point; the worker lowers the flag before each step.
 *
 * After a successful step the worker publishes: stats JSON text, the
 * summary numbers, the solver's memory by kind and a fresh rad_solution
 * are swapped in under the mutex, and an iteration event is posted.  The
 * previous solution is released (queries that still hold it finish on
 * it).  The final transition is made inside srv_job_persist, under the
 * store lock, together with the row (and checkpoint) that records it.
 *
 * Replay: when a job's solver is (re)built after a restart, the worker
 * first steps it back to the published iteration count, applying the eps
 * log as the original run did; the cancel flag is not raised meanwhile
 * (an interrupted replay step would not be the original step), requests
 * are honoured between replayed steps, and no events are sent.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "core.h"
#include "engine_json.h"
#include "log.h"
#include "runner.h"

#define PROGRESS_MIN_S 0.1 /* progress events: at most ~10/s per job */
#define BUDGET_TICK_S 0.1  /* time budgets checked by the I/O thread */

typedef enum job_action {
	ACT_STEP = 0,
	ACT_CANCEL,
	ACT_PAUSE,    /* job.pause */
	ACT_TARGET,   /* target reached: pause */
	ACT_DONE,     /* converged or max_iterations */
	ACT_SHUTDOWN, /* back to queued */
	ACT_FAIL,     /* the engine failed (err filled) */
} job_action;

/* ------------------------------------------------------------ lifecycle */

srv_job *srv_job_alloc(srv *s, srv_scene *sc)
{
	srv_job *j = calloc(1, sizeof(*j));
	if (!j)
		return NULL;
	atomic_init(&j->refs, 1);
	j->srv = s;
	pthread_mutex_init(&j->mu, NULL);
	j->scene = sc;
	srv_scene_ref(sc);
	j->state = SRV_JOB_PAUSED;
	j->created = j->updated = srv_now_unix();
	rad_options_default(&j->opt);
	return j;
}

void srv_job_unref(srv *s, srv_job *j)
{
	if (!j || atomic_fetch_sub(&j->refs, 1) != 1)
		return;
	srv_runner_free(j->runner);
	srv_sol_unref(s, j->sol);
	free(j->stats_json);
	free(j->eps_log);
	srv_scene_unref(j->scene);
	pthread_mutex_destroy(&j->mu);
	free(j);
}

void srv_job_register(srv *s, srv_job *j)
{
	srv_job **pp = &s->jobs;
	while (*pp)
		pp = &(*pp)->next;
	j->next = NULL;
	*pp = j;
	s->njobs++;
	srv_job_added(s, j);
}

void srv_job_unregister(srv *s, srv_job *j)
{
	for (srv_job **pp = &s->jobs; *pp; pp = &(*pp)->next) {
		if (*pp == j) {
			*pp = j->next;
			break;
		}
	}
	s->njobs--;
	j->scene->njobs--;
	srv_job_gone(s, j);
}

srv_runner *srv_job_detach_solver(srv_job *j)
{
	srv_runner *drop = NULL;
	pthread_mutex_lock(&j->mu);
	if (srv_job_terminal(j->state) && !j->on_worker) {
		drop = j->runner;
		j->runner = NULL;
		memset(j->solver_mem, 0, sizeof(j->solver_mem));
	}
	pthread_mutex_unlock(&j->mu);
	return drop;
}

int64_t srv_job_memory_locked(const srv_job *j)
{
	SRV_HELD(&j->mu);
	int64_t b = 0;
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		b += j->solver_mem[k];
	return b + (j->sol ? j->sol->bytes : 0);
}

int srv_job_solver_pid_locked(const srv_job *j)
{
	SRV_HELD(&j->mu);
	return j->runner ? (int)srv_runner_pid(j->runner) : 0;
}

void srv_job_raise_cancel_locked(srv_job *j)
{
	SRV_HELD(&j->mu);
	/* Not while replaying: an interrupted replay step would differ
	 * from the original one.  Requests are checked between steps.  No
	 * runner yet: attach_runner raises it if a request is pending. */
	if (!j->replaying && j->runner) {
		srv_runner_raise(j->runner);
		if (j->stop_asked == 0)
			j->stop_asked = rad_seconds();
	}
}

/* A request is pending that the cancel flag stands for (caller holds
 * mu). */
static int stop_wanted_locked(srv *s, srv_job *j)
{
	SRV_HELD(&j->mu);
	return j->cancel_req || j->pause_req || atomic_load(&s->stopping) ||
	       (j->deadline > 0 && rad_seconds() >= j->deadline);
}

/* ------------------------------------------------------------- solutions */

srv_sol *srv_sol_new(srv *s, rad_solution *sol, srv_scene *sc, double query_tol,
                     double solve_error)
{
	srv_sol *p = calloc(1, sizeof(*p));
	rad_mem_report m;
	if (!p) {
		rad_solution_free(sol);
		return NULL;
	}
	atomic_init(&p->refs, 1);
	p->sol = sol;
	p->scene = sc;
	srv_scene_ref(sc);
	p->iteration = rad_solution_iteration(sol);
	p->query_tol = query_tol;
	p->solve_error =
	        isfinite(solve_error) && solve_error > 0 ? solve_error : 0;
	rad_solution_memory(sol, &m);
	p->bytes = m.total;
	atomic_fetch_add(&s->sol_bytes, p->bytes);
	return p;
}

void srv_sol_unref(srv *s, srv_sol *p)
{
	if (!p || atomic_fetch_sub(&p->refs, 1) != 1)
		return;
	atomic_fetch_sub(&s->sol_bytes, p->bytes);
	rad_solution_free(p->sol);
	srv_scene_unref(p->scene);
	free(p);
}

/* ---------------------------------------------------------- publication */

/* Called by the engine on the stepping thread within an iteration. */
static void on_progress(void *ud, double fraction)
{
	srv_job *j = ud;
	double now = rad_seconds();

	pthread_mutex_lock(&j->mu);
	if (j->deadline > 0 && now >= j->deadline)
		srv_job_raise_cancel_locked(j);
	pthread_mutex_unlock(&j->mu);
	if (j->quiet || now - j->last_progress < PROGRESS_MIN_S)
		return;
	j->last_progress = now;
	srv_event ev = {.kind = EV_PROGRESS,
	                .job = j->id,
	                .iteration = j->solver_iter + 1,
	                .fraction = fraction,
	                .elapsed_s = now - j->step_t0};
	srv_event_post(j->srv, &ev);
}

/* Swap in the solver's state as the job's published result. */
static void publish(srv *s, srv_job *j, int send_event)
{
	rad_stats st;
	rad_error err = {0};
	rad_solution *rs = NULL;
	srv_sol *ns = NULL;

	srv_runner_stats(j->runner, &st);
	json_t *stats = ej_stats(&st);
	char *text = json_dumps(stats, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(stats);
	if (srv_runner_solution(j->runner, &rs, &err) == RAD_OK)
		ns = srv_sol_new(s, rs, j->scene, j->opt.query_tol,
		                 st.error_estimate);
	else
		srv_warn("job %llu: cannot publish the solution of "
		         "iteration %u (queries keep the previous one): %s",
		         (unsigned long long)j->id, st.iteration, err.msg);
	pthread_mutex_lock(&j->mu);
	srv_sol *old = ns ? j->sol : NULL;
	if (ns)
		j->sol = ns;
	if (text) {
		free(j->stats_json);
		j->stats_json = text;
	}
	j->iteration = st.iteration;
	j->residual = st.residual;
	j->links = st.links;
	j->converged = st.converged;
	srv_runner_memory(j->runner, j->solver_mem);
	j->updated = srv_now_unix();
	pthread_mutex_unlock(&j->mu);
	srv_sol_unref(s, old);
	j->solver_iter = st.iteration;
	if (send_event) {
		srv_event ev = {.kind = EV_ITERATION,
		                .job = j->id,
		                .iteration = st.iteration,
		                .stats = st};
		srv_event_post(s, &ev);
	}
}

static void post_state(srv *s, srv_job *j)
{
	srv_event ev;
	pthread_mutex_lock(&j->mu);
	srv_state_event_locked(j, &ev);
	pthread_mutex_unlock(&j->mu);
	srv_event_post(s, &ev);
}

/* --------------------------------------------------------------- stepping */

/* Apply due eps changes (caller holds mu). */
static int apply_eps_locked(srv_job *j, rad_error *err)
{
	SRV_HELD(&j->mu);
	if (!j->runner)
		return 0; /* applied once the solver exists */
	while (j->eps_applied < j->neps &&
	       j->eps_log[j->eps_applied].iteration <= j->solver_iter) {
		if (srv_runner_set_eps(j->runner,
		                       j->eps_log[j->eps_applied].eps,
		                       err) != RAD_OK)
			return -1;
		j->eps_applied++;
	}
	if (j->has_pending_eps && !j->replaying) {
		if (srv_runner_set_eps(j->runner, j->pending_eps, err) !=
		    RAD_OK)
			return -1;
		/* A later decision overrides what a lost run had planned. */
		j->neps = j->eps_applied;
		if (j->neps == j->eps_cap) {
			size_t cap = j->eps_cap ? 2 * j->eps_cap : 8;
			job_eps *nl = realloc(j->eps_log, cap * sizeof(*nl));
			if (!nl) {
				err->code = RAD_ERR_NOMEM;
				snprintf(err->msg, sizeof(err->msg),
				         "eps log: out of memory");
				return -1;
			}
			j->eps_log = nl;
			j->eps_cap = cap;
		}
		j->eps_log[j->neps++] = (job_eps){.iteration = j->solver_iter,
		                                  .eps = j->pending_eps};
		j->eps_applied = j->neps;
		j->has_pending_eps = 0;
	}
	return 0;
}

/* What to do before the next step (requests, targets, eps). */
static job_action next_action(srv *s, srv_job *j, rad_error *err)
{
	job_action a = ACT_STEP;
	pthread_mutex_lock(&j->mu);
	if (j->runner)
		srv_runner_lower(j->runner);
	j->stop_asked = 0;
	if (j->cancel_req)
		a = ACT_CANCEL;
	else if (j->pause_req)
		a = ACT_PAUSE;
	else if (atomic_load(&s->stopping))
		a = ACT_SHUTDOWN;
	else if (!j->replaying &&
	         ((j->converged && j->iteration > 0) ||
	          j->solver_iter >= (uint32_t)j->opt.max_iterations))
		a = ACT_DONE;
	else if (!j->replaying && j->target.mode == JOB_MODE_ITERATIONS &&
	         j->solver_iter >= j->target.until)
		a = ACT_TARGET;
	else if (!j->replaying && j->target.mode == JOB_MODE_SECONDS &&
	         j->deadline > 0 && rad_seconds() >= j->deadline)
		a = ACT_TARGET;
	if (a == ACT_STEP && apply_eps_locked(j, err) != 0)
		a = ACT_FAIL;
	if (a == ACT_STEP)
		j->rerun_req = 0; /* the latest target is the one in force */
	if (a == ACT_TARGET)
		j->target.complete = 1;
	pthread_mutex_unlock(&j->mu);
	return a;
}

/* Drop the job's runner (its process died or was killed): the next run
 * builds a new one and replays it to the published iteration. */
static void drop_runner(srv_job *j)
{
	pthread_mutex_lock(&j->mu);
	srv_runner *r = j->runner;
	j->runner = NULL;
	pthread_mutex_unlock(&j->mu);
	srv_runner_free(r);
	j->solver_iter = 0;
	j->eps_applied = 0;
}

static int build_solver(srv *s, srv_job *j, rad_error *err)
{
	srv_runner *r = NULL;
	if (srv_runner_new(s, j, on_progress, j, &r, err) != 0)
		return -1;
	/* Seen by the I/O thread from here on (memory, the cancel flag). */
	pthread_mutex_lock(&j->mu);
	j->runner = r;
	j->solver_iter = 0;
	j->eps_applied = 0;
	if (stop_wanted_locked(s, j))
		srv_job_raise_cancel_locked(j);
	pthread_mutex_unlock(&j->mu);
	if (srv_runner_build(r, err) != RAD_OK) {
		drop_runner(j);
		return -1;
	}
	return 0;
}

static void checkpoint(srv *s, srv_job *j)
{
	char msg[512];
	pthread_mutex_lock(&j->mu);
	srv_sol *sol = j->sol;
	if (sol && sol->iteration > j->ckpt_iter)
		srv_sol_ref(sol);
	else
		sol = NULL;
	pthread_mutex_unlock(&j->mu);
	if (srv_job_persist(s, j, sol, -1, msg, sizeof(msg)) != 0)
		srv_error("job %llu: checkpoint failed: %s",
		          (unsigned long long)j->id, msg);
	srv_sol_unref(s, sol);
	j->last_ckpt = rad_seconds();
}

/*
 * Leave the worker: record the final state (with a checkpoint of the
 * latest solution if newer than the last one), release the solver of a
 * finished job, and tell the I/O thread.
 */
static void finish(srv *s, srv_job *j, srv_job_state st, const char *error)
{
	char msg[512];
	double now = rad_seconds();

	pthread_mutex_lock(&j->mu);
	if (st == SRV_JOB_FAILED)
		snprintf(j->error, sizeof(j->error), "%s", error);
	if (j->target.mode == JOB_MODE_SECONDS && j->deadline > 0)
		j->target.left_s = j->deadline > now ? j->deadline - now : 0;
	j->deadline = 0;
	j->pause_req = 0;
	srv_sol *sol = j->sol;
	if (sol && sol->iteration > j->ckpt_iter)
		srv_sol_ref(sol);
	else
		sol = NULL;
	srv_runner *drop = NULL;
	if (srv_job_terminal(st)) {
		memset(j->solver_mem, 0, sizeof(j->solver_mem));
		j->target.complete = 1;
		drop = j->runner;
		j->runner = NULL;
	}
	pthread_mutex_unlock(&j->mu);
	srv_runner_free(drop);
	double t0 = rad_seconds();
	if (srv_job_persist(s, j, sol, (int)st, msg, sizeof(msg)) != 0)
		srv_error("job %llu: cannot record state %s: %s",
		          (unsigned long long)j->id, srv_job_state_name(st),
		          msg);
	else
		srv_debug("job %llu: state %s recorded%s in %.3f s",
		          (unsigned long long)j->id, srv_job_state_name(st),
		          sol ? " with a checkpoint" : "", rad_seconds() - t0);
	srv_sol_unref(s, sol);
	srv_info("job %llu: %s at iteration %u%s%s", (unsigned long long)j->id,
	         srv_job_state_name(st), j->solver_iter, error ? ": " : "",
	         error ? error : "");
	post_state(s, j);
}

/* Step the rebuilt solver back to the published iteration count. */
static int replay(srv *s, srv_job *j, job_action *stop, rad_error *err)
{
	double t0 = rad_seconds();
	uint32_t target;

	pthread_mutex_lock(&j->mu);
	j->replaying = 1;
	target = j->iteration;
	pthread_mutex_unlock(&j->mu);
	j->quiet = 1;
	srv_info("job %llu: replaying %u iterations", (unsigned long long)j->id,
	         target);
	*stop = ACT_STEP;
	while (j->solver_iter < target) {
		*stop = next_action(s, j, err);
		if (*stop == ACT_FAIL)
			return -1;
		if (*stop != ACT_STEP)
			break;
		if (srv_runner_step(j->runner, j->opt.converge_tol, err) !=
		    RAD_OK)
			return -1;
		j->solver_iter++;
	}
	pthread_mutex_lock(&j->mu);
	j->replaying = 0;
	int fresh = !j->sol || j->sol->iteration != j->solver_iter;
	pthread_mutex_unlock(&j->mu);
	j->quiet = 0;
	if (*stop == ACT_STEP) {
		srv_info("job %llu: replayed to iteration %u in %.3f s",
		         (unsigned long long)j->id, j->solver_iter,
		         rad_seconds() - t0);
		if (fresh) /* no usable checkpoint solution */
			publish(s, j, 0);
	}
	return 0;
}

static srv_job_state action_state(job_action a)
{
	switch (a) {
	case ACT_CANCEL:
		return SRV_JOB_CANCELLED;
	case ACT_DONE:
		return SRV_JOB_DONE;
	case ACT_SHUTDOWN:
		return SRV_JOB_QUEUED;
	default:
		return SRV_JOB_PAUSED;
	}
}

/* Start the solver's deadline for a time budget (caller holds mu). */
static void arm_budget_locked(srv_job *j)
{
	SRV_HELD(&j->mu);
	j->deadline = j->target.mode == JOB_MODE_SECONDS
	                      ? rad_seconds() + j->target.left_s
	                      : 0;
}

/*
 * Build the solver (the matrix solver computes its form factors here, a
 * long phase that the cancel flag may interrupt).  Returns ACT_STEP with
 * a solver, or the action that interrupted it, or ACT_FAIL.
 */
static job_action ensure_solver(srv *s, srv_job *j, rad_error *err)
{
	while (!j->runner) {
		if (build_solver(s, j, err) == 0)
			break;
		if (err->code != RAD_ERR_CANCELLED)
			return ACT_FAIL;
		job_action a = next_action(s, j, err);
		if (a != ACT_STEP)
			return a;
	}
	return ACT_STEP;
}

/* 1 when the job's solver process is gone (died or killed). */
static int runner_gone(srv_job *j, char *why, size_t len)
{
	pthread_mutex_lock(&j->mu);
	int gone = j->runner && srv_runner_gone(j->runner, why, len);
	pthread_mutex_unlock(&j->mu);
	return gone;
}

/*
 * A solver at the published iteration: a process that died while the
 * job waited is replaced, the solver built, and a new one replayed.
 */
static job_action prepare(srv *s, srv_job *j, int first, rad_error *err)
{
	char why[256];
	if (runner_gone(j, why, sizeof(why))) {
		srv_info("job %llu: a new solver process replaces the one "
		         "that ended while the job waited (%s)",
		         (unsigned long long)j->id, why);
		drop_runner(j);
	}
	job_action a = ensure_solver(s, j, err);
	if (a == ACT_STEP && j->solver_iter < j->iteration) {
		if (replay(s, j, &a, err) != 0)
			a = ACT_FAIL;
		if (first) {
			pthread_mutex_lock(&j->mu);
			arm_budget_locked(j); /* the replay is not the
			                         job's time */
			pthread_mutex_unlock(&j->mu);
		}
	}
	return a;
}

static void run_job(srv *s, srv_job *j)
{
	rad_error err = {0};
	job_action a;

	j->last_ckpt = rad_seconds();
	pthread_mutex_lock(&j->mu);
	arm_budget_locked(j);
	pthread_mutex_unlock(&j->mu);
	a = prepare(s, j, 1, &err);
	while (a == ACT_STEP) {
		a = next_action(s, j, &err);
		if (a != ACT_STEP)
			break;
		if (!j->runner) { /* killed for not stopping: a new one */
			a = prepare(s, j, 0, &err);
			continue;
		}
		j->step_t0 = rad_seconds();
		rad_status st =
		        srv_runner_step(j->runner, j->opt.converge_tol, &err);
		if (st == RAD_ERR_CANCELLED) {
			pthread_mutex_lock(&j->mu);
			double asked = j->stop_asked;
			pthread_mutex_unlock(&j->mu);
			if (asked > 0)
				srv_debug(
				        "job %llu: iteration %u stopped %.3f s "
				        "after it was asked to",
				        (unsigned long long)j->id,
				        j->solver_iter + 1,
				        rad_seconds() - asked);
			if (runner_gone(j, NULL, 0))
				drop_runner(j);
			continue; /* next_action tells why */
		}
		if (st != RAD_OK) {
			if (runner_gone(j, NULL, 0)) {
				size_t n = strlen(err.msg);
				if (j->iteration > 0)
					snprintf(
					        err.msg + n,
					        sizeof(err.msg) - n,
					        " during iteration %u; the job "
					        "keeps iteration %u's solution",
					        j->solver_iter + 1,
					        j->iteration);
				else
					snprintf(err.msg + n,
					         sizeof(err.msg) - n,
					         " during iteration 1");
			}
			a = ACT_FAIL;
			break;
		}
		publish(s, j, 1);
		double iv = (double)atomic_load(&s->ckpt_interval_ms) / 1000.0;
		if (rad_seconds() - j->last_ckpt >= iv)
			checkpoint(s, j);
	}
	if (a == ACT_FAIL)
		finish(s, j, SRV_JOB_FAILED, err.msg);
	else
		finish(s, j, action_state(a), NULL);
}

/* ---------------------------------------------------------------- workers */

/*
 * Timer: raise the cancel flag of jobs past their time budget (the
 * progress callback does it too, but some phases report no progress),
 * and read a stepping solver's memory as it grows: job.info, status and
 * /metrics show it within BUDGET_TICK_S, not at the iteration's end.
 */
static double budget_tick(el_loop *l, void *ud, double now)
{
	srv *s = ud;
	(void)l;
	for (srv_job *j = s->jobs; j; j = j->next) {
		pthread_mutex_lock(&j->mu);
		if (j->on_worker && j->deadline > 0 && now >= j->deadline &&
		    !j->replaying)
			srv_job_raise_cancel_locked(j);
		if (j->on_worker && j->runner)
			srv_runner_memory(j->runner, j->solver_mem);
		/* A waiting job's process that died: reaped, its memory
		 * let go; the job replays a new one when it runs. */
		char why[256];
		if (!j->on_worker && j->runner && srv_runner_pid(j->runner) &&
		    srv_runner_gone(j->runner, why, sizeof(why))) {
			srv_warn("job %llu: %s while the job waited; a new one "
			         "replays it when it runs",
			         (unsigned long long)j->id, why);
			memset(j->solver_mem, 0, sizeof(j->solver_mem));
		}
		pthread_mutex_unlock(&j->mu);
	}
	return BUDGET_TICK_S;
}

static void *worker_main(void *arg)
{
	srv *s = arg;
	for (;;) {
		pthread_mutex_lock(&s->runq_mu);
		while (!s->runq_head && !s->runq_stop)
			pthread_cond_wait(&s->runq_cv, &s->runq_mu);
		if (s->runq_stop) {
			pthread_mutex_unlock(&s->runq_mu);
			return NULL;
		}
		srv_job *j = s->runq_head;
		s->runq_head = j->runq_next;
		if (!s->runq_head)
			s->runq_tail = NULL;
		s->busy_workers++;
		pthread_mutex_unlock(&s->runq_mu);

		pthread_mutex_lock(&j->mu);
		j->in_runq = 0;
		int go = j->state == SRV_JOB_QUEUED && !j->deleted;
		if (go) {
			j->state = SRV_JOB_RUNNING;
			j->state_seq++;
			j->on_worker = 1;
		}
		pthread_mutex_unlock(&j->mu);
		if (go) {
			post_state(s, j);
			run_job(s, j);
		}
		srv_job_unref(s, j);
		pthread_mutex_lock(&s->runq_mu);
		s->busy_workers--;
		pthread_mutex_unlock(&s->runq_mu);
	}
}

int srv_workers_start(srv *s, int n, char *msg, size_t msglen)
{
	if (!el_timer_add(s->loop, BUDGET_TICK_S, budget_tick, s)) {
		snprintf(msg, msglen, "workers: out of memory");
		return -1;
	}
	s->workers = calloc((size_t)n, sizeof(pthread_t));
	if (!s->workers) {
		snprintf(msg, msglen, "workers: out of memory");
		return -1;
	}
	for (int i = 0; i < n; i++) {
		int rc = pthread_create(&s->workers[i], NULL, worker_main, s);
		if (rc != 0) {
			snprintf(msg, msglen, "cannot start worker: %s",
			         strerror(rc));
			return -1;
		}
		s->nworkers++;
	}
	return 0;
}

void srv_workers_stop_request(srv *s)
{
	atomic_store(&s->stopping, 1);
	for (srv_job *j = s->jobs; j; j = j->next) {
		pthread_mutex_lock(&j->mu);
		if (j->on_worker)
			srv_job_raise_cancel_locked(j);
		pthread_mutex_unlock(&j->mu);
	}
	pthread_mutex_lock(&s->runq_mu);
	s->runq_stop = 1;
	pthread_cond_broadcast(&s->runq_cv);
	pthread_mutex_unlock(&s->runq_mu);
}

int srv_workers_busy(srv *s)
{
	pthread_mutex_lock(&s->runq_mu);
	int n = s->busy_workers;
	pthread_mutex_unlock(&s->runq_mu);
	return n;
}

void srv_workers_join(srv *s)
{
	for (int i = 0; i < s->nworkers; i++)
		pthread_join(s->workers[i], NULL);
	free(s->workers);
	s->workers = NULL;
	s->nworkers = 0;
	/* Jobs still queued stay queued (their rows say so). */
	pthread_mutex_lock(&s->runq_mu);
	srv_job *j = s->runq_head;
	s->runq_head = s->runq_tail = NULL;
	pthread_mutex_unlock(&s->runq_mu);
	while (j) {
		srv_job *next = j->runq_next;
		pthread_mutex_lock(&j->mu);
		j->in_runq = 0;
		pthread_mutex_unlock(&j->mu);
		srv_job_unref(s, j);
		j = next;
	}
}
