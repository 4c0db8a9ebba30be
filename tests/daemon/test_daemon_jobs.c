/*
 * test_daemon_jobs.c -- jobs on a real luxradd (PROTOCOL.md "Jobs",
 * "Streaming"):
 *  - job.create answers paused with every effective option; job.run
 *    iterations / converge / seconds, pause, set, cancel and delete move
 *    the job through the documented states;
 *  - two clients stepping jobs at once (requests interleaved on two
 *    connections, two workers) get exactly the lux of the same jobs run
 *    alone afterwards: the solve is deterministic for a thread count;
 *  - a subscriber sees state events, one iteration event per iteration in
 *    order with every documented stats member, and progress events inside
 *    the long iterations of a bigger scene; after unsubscribe, nothing;
 *  - a subscriber that reads nothing while a job runs to completion does
 *    not stop the job nor other clients; it is either kept consistent
 *    (every iteration and state event, progress maybe dropped and
 *    counted) or closed with slow_consumer;
 *  - max_scenes, max_jobs and max_subscriptions: "limit", the session
 *    goes on; deleting frees the slot;
 *  - hr without clustering, whose first iteration links every pair of
 *    polygons, answers pause and cancel, keeps a seconds budget and lets
 *    the daemon stop on SIGTERM within seconds.
 */
#include <math.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>

#include <cmocka.h>

#include "harness.h"

/* Probe points in the generated halls (24 x 6 x 16 m): a 5 x 4 grid at
 * desk height facing up, and points on the walls. */
#define NPROBE 24
static double probe[NPROBE * 6];

static void make_probe(void)
{
	int k = 0;
	for (int i = 0; i < 5; i++)
		for (int j = 0; j < 4; j++) {
			double p[6] = {2 + 5 * i, 0.8, 2 + 4 * j, 0, 1, 0};
			memcpy(&probe[6 * k++], p, sizeof(p));
		}
	double w[4][6] = {{0.001, 2, 8, 1, 0, 0},
	                  {23.999, 2, 8, -1, 0, 0},
	                  {12, 2, 0.001, 0, 0, 1},
	                  {12, 5.999, 8, 0, -1, 0}};
	for (int i = 0; i < 4; i++)
		memcpy(&probe[6 * k++], w[i], sizeof(w[i]));
}

static const char *hall(char *buf, size_t len)
{
	return dm_gen_scene("hall-full.glb", "hall-full", buf, len);
}

/* ------------------------------------------------------------- stats */

/* Every member PROTOCOL.md lists for <stats>. */
static void check_stats(const json_t *s)
{
	static const char *const top[] = {
	        "iteration", "seconds",     "seconds_total",
	        "links",     "energy_hist", "elements",
	        "clusters",  "leaves",      "refinements",
	        "rays",      "residual",    "error_estimate",
	        "converged", "memory",      NULL};
	dm_require_keys(s, "stats", top);
	static const char *const links[] = {
	        "stored",   "ss",        "sc",      "cc",      "light",
	        "active",   "passive",   "created", "deleted", "recreated",
	        "gathered", "transient", "useful",  NULL};
	dm_require_keys(dm_get(s, "links"), "stats.links", links);
	json_t *h = dm_get(s, "energy_hist");
	if (!json_is_array(h) || json_array_size(h) != 16)
		fail_msg("stats.energy_hist is not an array of 16");
	if (!json_is_boolean(dm_get(s, "converged")))
		fail_msg("stats.converged is not a boolean");
	json_t *m = dm_get(s, "memory");
	static const char *const mem[] = {"total_bytes",     "peak_bytes",
	                                  "peak_work_bytes", "peak_own_bytes",
	                                  "by_kind",         NULL};
	dm_require_keys(m, "stats.memory", mem);
	dm_require_keys(dm_get(m, "by_kind"), "stats.memory.by_kind",
	                dm_mem_kinds);
	assert_true(dm_num(s, "seconds") >= 0);
	assert_true(dm_num(s, "seconds_total") >= dm_num(s, "seconds"));
	assert_true(dm_num(m, "peak_bytes") >= dm_num(m, "total_bytes"));
	assert_true(dm_num(m, "peak_work_bytes") >=
	            dm_num(m, "peak_own_bytes"));
	assert_true(dm_num(m, "peak_own_bytes") > 0);
	assert_true(dm_int(s, "leaves") > 0);
}

/* ------------------------------------------------------------- options */

static void test_job_lifecycle_follows_the_protocol(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("office.gltf", path, sizeof(path)), "office");

	json_t *r = dm_ok(c, "{s:s, s:O, s:s, s:s, s:{s:i}}", "cmd",
	                  "job.create", "scene", sc, "name", "life", "solver",
	                  "hr", "options", "threads", 1);
	assert_string_equal(json_string_value(dm_get(r, "state")), "paused");
	json_t *job = json_incref(dm_get(r, "job"));
	json_t *o = dm_get(r, "options");
	static const char *const opts[] = {
	        "accuracy",    "query_tol",    "eps",
	        "variation",   "min_edge_rel", "mesh_edge_rel",
	        "clustering",  "store",        "study",
	        "oracle",      "threads",      "rcv_samples",
	        "vis_samples", "tol",          "max_iterations",
	        NULL};
	dm_require_keys(o, "job.create options", opts);
	assert_true(dm_num(o, "tol") == 1e-3);
	assert_true(dm_num(o, "delay") == 0);
	assert_true(dm_num(o, "accuracy") == 0.02);
	assert_true(dm_num(o, "query_tol") == 0.01);
	assert_int_equal(dm_int(o, "max_iterations"), 10000);
	assert_int_equal(dm_int(o, "threads"), 1);
	json_decref(r);

	/* accuracy sets eps, tol and query_tol; eps beside it wins. */
	r = dm_ok(c, "{s:s, s:O, s:{s:f, s:f}}", "cmd", "job.create", "scene",
	          sc, "options", "eps", 1e-3, "accuracy", 0.01);
	o = dm_get(r, "options");
	assert_true(dm_num(o, "accuracy") == 0.01);
	assert_true(dm_num(o, "eps") == 1e-3);
	assert_true(fabs(dm_num(o, "tol") - 5e-4) < 1e-15);
	assert_true(dm_num(o, "query_tol") == 0.005);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job",
	                  dm_get(r, "job")));
	json_decref(r);
	json_decref(dm_err(c, "invalid", "{s:s, s:O, s:{s:f}}", "cmd",
	                   "job.create", "scene", sc, "options", "accuracy",
	                   0.9));

	/* Before the first run: target none, no stats. */
	r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
	json_t *ji = dm_get(r, "job");
	assert_string_equal(
	        json_string_value(dm_get(dm_get(ji, "target"), "mode")),
	        "none");
	assert_int_equal(dm_int(ji, "iteration"), 0);
	assert_string_equal(json_string_value(dm_get(ji, "state")), "paused");
	json_t *st0 = json_object_get(ji, "stats");
	assert_true(st0 == NULL || json_is_null(st0));
	json_decref(r);

	/* Never stepped: no solution. */
	json_decref(dm_err(c, "state", "{s:s, s:O, s:[[f,f,f,i,i,i]]}", "cmd",
	                   "query.points", "job", job, "points", 2.0, 0.01, 1.5,
	                   0, 1, 0));

	/* Two iterations, then paused at 2. */
	r = dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	          "iterations", 2);
	const char *st = json_string_value(dm_get(r, "state"));
	if (strcmp(st, "queued") && strcmp(st, "running"))
		fail_msg("job.run answered state %s", st);
	json_decref(r);
	json_t *j = dm_wait_job(c, job, "paused", 60000);
	assert_int_equal(dm_int(j, "iteration"), 2);
	check_stats(dm_get(j, "stats"));
	assert_int_equal(dm_int(dm_get(j, "stats"), "iteration"), 2);
	assert_string_equal(json_string_value(dm_get(j, "solver")), "hr");
	assert_string_equal(json_string_value(dm_get(j, "name")), "life");
	assert_true(dm_num(j, "updated") >= dm_num(j, "created"));
	assert_true(dm_num(j, "created") > 1.6e9); /* Unix time */
	json_t *tg = dm_get(j, "target");
	assert_string_equal(json_string_value(dm_get(tg, "mode")),
	                    "iterations");
	assert_int_equal(dm_int(tg, "n"), 2);
	json_decref(j);
	double lux;
	double pt[6] = {2.0, 0.01, 1.5, 0, 1, 0};
	assert_int_equal(dm_query_points(c, job, pt, 1, &lux), 2);
	assert_true(lux > 0);

	/* job.set between iterations. */
	r = dm_ok(c, "{s:s, s:O, s:f}", "cmd", "job.set", "job", job, "eps",
	          2e-4);
	assert_true(dm_num(r, "eps") == 2e-4);
	json_decref(r);

	/* Converge: done, converged or at max_iterations. */
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	j = dm_wait_job(c, job, "done|failed|cancelled", 120000);
	assert_string_equal(json_string_value(dm_get(j, "state")), "done");
	json_t *s = dm_get(j, "stats");
	check_stats(s);
	if (!json_is_true(dm_get(s, "converged")) &&
	    dm_int(j, "iteration") < 100)
		fail_msg("done at iteration %lld, neither converged nor at "
		         "max_iterations",
		         dm_int(j, "iteration"));
	if (json_is_true(dm_get(s, "converged")) &&
	    dm_num(s, "error_estimate") > 1e-3)
		fail_msg("converged with error_estimate %g > tol",
		         dm_num(s, "error_estimate"));
	json_decref(j);

	/* job.list shows it; job.delete forgets it. */
	r = dm_ok(c, "{s:s}", "cmd", "job.list");
	json_t *jobs = dm_get(r, "jobs");
	assert_int_equal(json_array_size(jobs), 1);
	static const char *const jl[] = {
	        "id",        "name",     "scene", "solver",       "state",
	        "iteration", "residual", "links", "memory_bytes", NULL};
	dm_require_keys(json_array_get(jobs, 0), "job.list entry", jl);
	assert_true(json_equal(dm_get(json_array_get(jobs, 0), "id"), job));
	json_decref(r);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	json_decref(dm_err(c, "not_found", "{s:s, s:O}", "cmd", "job.info",
	                   "job", job));
	json_decref(job);

	/* A long job: pause, resume, cancel (terminal), delete. */
	char hp[512];
	json_t *big = dm_upload_file(c, hall(hp, sizeof(hp)), "hall");
	json_t *opt = json_pack("{s:i, s:f, s:f, s:i}", "threads", 1, "eps",
	                        1e-5, "tol", 1e-6, "max_iterations", 50);
	job = dm_job_create(c, big, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_decref(dm_wait_job(c, job, "running", 60000));
	json_decref(dm_err(c, "state", "{s:s, s:O}", "cmd", "job.delete", "job",
	                   job));
	r = dm_ok(c, "{s:s, s:O}", "cmd", "job.pause", "job", job);
	assert_string_equal(json_string_value(dm_get(r, "state")), "paused");
	json_decref(r);
	/* Pausing a paused job is a no-op. */
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.pause", "job", job));
	j = dm_wait_job(c, job, "paused", 120000);
	long long it = dm_int(j, "iteration");
	json_decref(j);
	dm_sleep_ms(300);
	j = dm_wait_job(c, job, "paused", 1000);
	assert_int_equal(dm_int(j, "iteration"), it); /* stays paused */
	json_decref(j);
	r = dm_ok(c, "{s:s, s:O}", "cmd", "job.resume", "job", job);
	json_decref(r);
	json_decref(dm_wait_job(c, job, "running", 60000));
	r = dm_ok(c, "{s:s, s:O}", "cmd", "job.cancel", "job", job);
	assert_string_equal(json_string_value(dm_get(r, "state")), "cancelled");
	json_decref(r);
	j = dm_wait_job(c, job, "cancelled", 60000);
	json_decref(j);
	json_decref(dm_err(c, "state", "{s:s, s:O, s:i}", "cmd", "job.run",
	                   "job", job, "iterations", 1));
	json_decref(dm_err(c, "state", "{s:s, s:O}", "cmd", "job.cancel", "job",
	                   job));
	json_decref(dm_err(c, "state", "{s:s, s:O}", "cmd", "job.resume", "job",
	                   job));
	json_decref(dm_err(c, "state", "{s:s, s:O, s:f}", "cmd", "job.set",
	                   "job", job, "eps", 1e-3));
	/* The latest solution stays queryable. */
	if (it > 0)
		dm_query_points(c, job, pt, 1, &lux);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	json_decref(job);

	/* A seconds budget pauses a job that cannot converge in time. */
	opt = json_pack("{s:i, s:f, s:f, s:i}", "threads", 1, "eps", 1e-5,
	                "tol", 1e-9, "max_iterations", 100);
	job = dm_job_create(c, big, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:f}", "cmd", "job.run", "job", job,
	                  "seconds", 0.5));
	j = dm_wait_job(c, job, "paused|done|failed", 120000);
	assert_string_equal(json_string_value(dm_get(j, "state")), "paused");
	json_decref(j);
	json_decref(job);
	json_decref(big);
	json_decref(sc);
	dm_pass();
}

/* ------------------------------------------------------- concurrency */

typedef struct stepper {
	dm_conn *c;
	json_t *scene, *job;
	int steps_left; /* job.run iterations:1 still to send; -1: converge */
	int finished;
	long long iteration;
} stepper;

/* Advance a stepper: when its job is paused, ask for the next step. */
static void stepper_poll(stepper *s)
{
	if (s->finished)
		return;
	json_t *r = dm_ok(s->c, "{s:s, s:O}", "cmd", "job.info", "job", s->job);
	json_t *j = dm_get(r, "job");
	const char *st = json_string_value(dm_get(j, "state"));
	s->iteration = dm_int(j, "iteration");
	if (!strcmp(st, "failed") || !strcmp(st, "cancelled"))
		fail_msg("concurrent job went %s", st);
	if (!strcmp(st, "done"))
		s->finished = 1;
	else if (!strcmp(st, "paused")) {
		if (s->steps_left == 0)
			s->finished = 1;
		else if (s->steps_left > 0) {
			json_decref(dm_ok(s->c, "{s:s, s:O, s:i}", "cmd",
			                  "job.run", "job", s->job,
			                  "iterations", 1));
			s->steps_left--;
		}
	}
	json_decref(r);
}

static void test_two_clients_at_once_match_solo_runs(void **state)
{
	(void)state;
	make_probe();
	const char *args[] = {"--workers", "2", NULL};
	dm_daemon *d = dm_start(args);
	char path[512];
	hall(path, sizeof(path));
	json_t *opt = json_pack("{s:i}", "threads", 1);

	stepper a = {.c = dm_open(d, NULL), .steps_left = 4};
	stepper b = {.c = dm_open(d, NULL), .steps_left = -1};
	a.scene = dm_upload_file(a.c, path, "hall-a");
	b.scene = dm_upload_file(b.c, path, "hall-b");
	a.job = dm_job_create(a.c, a.scene, "hr", opt);
	b.job = dm_job_create(b.c, b.scene, "hr", opt);

	/* Both first runs go out before either reply is read. */
	json_t *ha = json_pack("{s:s, s:O, s:i, s:i}", "cmd", "job.run", "job",
	                       a.job, "iterations", 1, "id", 900);
	json_t *hb = json_pack("{s:s, s:O, s:b, s:i}", "cmd", "job.run", "job",
	                       b.job, "converge", 1, "id", 901);
	dm_send_frame(a.c, ha, NULL, 0);
	dm_send_frame(b.c, hb, NULL, 0);
	json_decref(ha);
	json_decref(hb);
	a.steps_left--;
	json_t *f;
	assert_int_equal(dm_recv(b.c, DM_REPLY_MS, &f, NULL, NULL), 1);
	assert_string_equal(dm_err_code(f), "");
	json_decref(f);
	assert_int_equal(dm_recv(a.c, DM_REPLY_MS, &f, NULL, NULL), 1);
	assert_string_equal(dm_err_code(f), "");
	json_decref(f);

	int overlapped = 0;
	double end = dm_now_ms() + 150000;
	while (!(a.finished && b.finished)) {
		if (dm_now_ms() > end)
			fail_msg(
			        "concurrent jobs not finished (a at %lld, b at "
			        "%lld)",
			        a.iteration, b.iteration);
		stepper_poll(&a);
		stepper_poll(&b);
		json_t *r = dm_ok(a.c, "{s:s}", "cmd", "status");
		if (dm_int(dm_get(r, "jobs"), "running") == 2)
			overlapped = 1;
		json_decref(r);
		dm_sleep_ms(20);
	}
	assert_int_equal(a.iteration, 4);
	if (!overlapped)
		print_message("note: the two jobs were never seen running at "
		              "the same time\n");

	double lux_a[NPROBE], lux_b[NPROBE];
	assert_int_equal(dm_query_points(a.c, a.job, probe, NPROBE, lux_a), 4);
	long long itb = dm_query_points(b.c, b.job, probe, NPROBE, lux_b);

	/* Solo runs of the same jobs, one after the other. */
	dm_conn *c = dm_open(d, NULL);
	json_t *sa = dm_job_create(c, a.scene, "hr", opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", sa,
	                  "iterations", 4));
	json_decref(dm_wait_job(c, sa, "paused|done", 150000));
	json_t *sb = dm_job_create(c, b.scene, "hr", opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", sb,
	                  "converge", 1));
	json_decref(dm_wait_job(c, sb, "done", 150000));
	double solo_a[NPROBE], solo_b[NPROBE];
	assert_int_equal(dm_query_points(c, sa, probe, NPROBE, solo_a), 4);
	assert_int_equal(dm_query_points(c, sb, probe, NPROBE, solo_b), itb);
	for (int i = 0; i < NPROBE; i++) {
		if (!dm_close_enough(lux_a[i], solo_a[i], 1e-12))
			fail_msg("stepped job, point %d: %.17g lux, solo %.17g",
			         i, lux_a[i], solo_a[i]);
		if (!dm_close_enough(lux_b[i], solo_b[i], 1e-12))
			fail_msg("converged job, point %d: %.17g lux, solo "
			         "%.17g",
			         i, lux_b[i], solo_b[i]);
	}
	/* And the statistics agree. */
	json_t *ja = dm_wait_job(c, a.job, "paused|done", 1000);
	json_t *jsa = dm_wait_job(c, sa, "paused|done", 1000);
	assert_int_equal(
	        dm_int(dm_get(dm_get(ja, "stats"), "links"), "stored"),
	        dm_int(dm_get(dm_get(jsa, "stats"), "links"), "stored"));
	assert_int_equal(dm_int(dm_get(ja, "stats"), "leaves"),
	                 dm_int(dm_get(jsa, "stats"), "leaves"));
	json_decref(ja);
	json_decref(jsa);
	json_decref(sa);
	json_decref(sb);
	json_decref(opt);
	json_decref(a.scene);
	json_decref(a.job);
	json_decref(b.scene);
	json_decref(b.job);
	dm_pass();
}

/* ---------------------------------------------------------- streaming */

typedef struct stream_log {
	long long last_iteration; /* last iteration event */
	int iterations;           /* iteration events */
	int progress;             /* progress events */
	double last_fraction;     /* within the running iteration */
	long long dropped;        /* sum of dropped_progress */
	char states[16][16];      /* state events in order */
	int nstates;
	json_t *last_stats;
} stream_log;

/* Check one event against the running log; returns 1 on a terminal or
 * paused state event. */
static int stream_take(stream_log *l, const json_t *e, const json_t *job)
{
	const char *kind = json_string_value(dm_get(e, "event"));
	if (!json_equal(dm_get(e, "job"), job))
		fail_msg("event for another job");
	if (json_object_get(e, "ok") || json_object_get(e, "id"))
		fail_msg("an event carries \"ok\" or \"id\"");
	if (!strcmp(kind, "iteration")) {
		json_t *s = dm_get(e, "stats");
		check_stats(s);
		long long it = dm_int(s, "iteration");
		if (it != l->last_iteration + 1)
			fail_msg("iteration event %lld after %lld", it,
			         l->last_iteration);
		if (l->last_stats &&
		    dm_num(s, "seconds_total") <
		            dm_num(l->last_stats, "seconds_total"))
			fail_msg("seconds_total decreased");
		json_t *dp = json_object_get(e, "dropped_progress");
		if (dp)
			l->dropped += json_integer_value(dp);
		l->last_iteration = it;
		l->iterations++;
		l->last_fraction = -1;
		json_decref(l->last_stats);
		l->last_stats = json_incref(s);
		return 0;
	}
	if (!strcmp(kind, "progress")) {
		long long it = dm_int(e, "iteration");
		double fr = dm_num(e, "fraction");
		if (it != l->last_iteration + 1)
			fail_msg("progress for iteration %lld while iteration "
			         "%lld is running",
			         it, l->last_iteration + 1);
		if (fr < 0 || fr > 1)
			fail_msg("progress fraction %g", fr);
		if (fr < l->last_fraction)
			fail_msg("progress went back from %g to %g",
			         l->last_fraction, fr);
		if (dm_num(e, "elapsed_s") < 0)
			fail_msg("negative elapsed_s");
		l->last_fraction = fr;
		l->progress++;
		return 0;
	}
	if (!strcmp(kind, "state")) {
		const char *s = json_string_value(dm_get(e, "state"));
		if (l->nstates < 16)
			snprintf(l->states[l->nstates++], 16, "%s", s);
		return !strcmp(s, "paused") || !strcmp(s, "done") ||
		       !strcmp(s, "failed") || !strcmp(s, "cancelled");
	}
	fail_msg("unknown event \"%s\"", kind);
	return 1;
}

static void stream_until_stop(dm_conn *c, stream_log *l, const json_t *job,
                              int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	for (;;) {
		int left = (int)(end - dm_now_ms());
		json_t *e = dm_event(c, left > 0 ? left : 0);
		if (!e)
			fail_msg("no terminal state event within %d ms (last "
			         "iteration %lld)",
			         timeout_ms, l->last_iteration);
		int stop = stream_take(l, e, job);
		json_decref(e);
		if (stop)
			return;
	}
}

static int has_state(const stream_log *l, const char *s)
{
	for (int i = 0; i < l->nstates; i++)
		if (!strcmp(l->states[i], s))
			return 1;
	return 0;
}

static void test_subscriber_sees_ordered_events(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("office.gltf", path, sizeof(path)), "office");
	json_t *opt = json_pack("{s:i}", "threads", 1);
	json_t *job = dm_job_create(c, sc, "hr", opt);

	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", job);
	assert_true(json_equal(dm_get(r, "job"), job));
	assert_string_equal(json_string_value(dm_get(r, "state")), "paused");
	assert_int_equal(dm_int(r, "iteration"), 0);
	json_decref(r);
	/* Subscribing twice is a no-op: every event still arrives once. */
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", job));
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	stream_log l = {0};
	stream_until_stop(c, &l, job, 120000);
	if (!has_state(&l, "running"))
		fail_msg("no \"running\" state event");
	if (strcmp(l.states[l.nstates - 1], "done") != 0)
		fail_msg("last state event %s, want done",
		         l.states[l.nstates - 1]);
	if (l.iterations < 2)
		fail_msg("only %d iteration events", l.iterations);
	/* The events agree with job.info. */
	json_t *j = dm_wait_job(c, job, "done", 1000);
	assert_int_equal(dm_int(j, "iteration"), l.last_iteration);
	assert_true(json_equal(dm_get(j, "stats"), l.last_stats) ||
	            dm_int(dm_get(j, "stats"), "iteration") ==
	                    l.last_iteration);
	json_decref(j);
	json_decref(l.last_stats);

	/* Progress inside the long iterations of a bigger scene. */
	char hp[512];
	json_t *big = dm_upload_file(c, hall(hp, sizeof(hp)), "hall");
	json_t *o2 = json_pack("{s:i, s:f}", "threads", 1, "eps", 5e-5);
	json_t *job2 = dm_job_create(c, big, "hr", o2);
	json_decref(o2);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", job2));
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job2,
	                  "iterations", 2));
	stream_log l2 = {0};
	stream_until_stop(c, &l2, job2, 150000);
	assert_string_equal(l2.states[l2.nstates - 1], "paused");
	assert_int_equal(l2.iterations, 2);
	if (l2.progress + l2.dropped == 0)
		fail_msg("no progress event during two iterations of %s", hp);
	json_decref(l2.last_stats);

	/* Unsubscribed: no more events for that job on this connection. */
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "unsubscribe", "job", job2));
	json_t *left;
	while ((left = dm_event(c, 0)) != NULL) /* sent before the reply */
		json_decref(left);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job2,
	                  "iterations", 1));
	dm_conn *w = dm_open(d, NULL);
	json_decref(dm_wait_job(w, job2, "paused", 150000));
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
	json_t *late = dm_event(c, 300);
	if (late)
		fail_msg("an event after unsubscribe: %s",
		         json_dumps(late, JSON_COMPACT));
	json_decref(job2);
	json_decref(big);
	json_decref(opt);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* --------------------------------------------------------- slow reader */

/* What the slow subscriber's connection held when it was read. */
typedef struct slow_log {
	stream_log s;
	int replies, closed_with, done;
} slow_log;

/* Read the slow subscriber's connection until it closes, its stream is
 * complete, or 30 s pass. */
static void read_slow(dm_conn *slow, const json_t *job, int sent, slow_log *l)
{
	double rend = dm_now_ms() + 30000;
	for (;;) {
		json_t *f = NULL;
		int left = (int)(rend - dm_now_ms());
		int r = dm_recv(slow, left > 0 ? left : 0, &f, NULL, NULL);
		if (r <= 0)
			break;
		if (json_object_get(f, "event")) {
			if (stream_take(&l->s, f, job) &&
			    !strcmp(l->s.states[l->s.nstates - 1], "done"))
				l->done = 1;
		} else if (!strcmp(dm_err_code(f), "slow_consumer")) {
			l->closed_with = 1;
		} else if (!strcmp(dm_err_code(f), "")) {
			l->replies++;
		} else {
			fail_msg("slow subscriber got error %s",
			         dm_err_code(f));
		}
		json_decref(f);
		if (l->done && l->replies == sent)
			break;
	}
}

static void test_slow_subscriber_does_not_stall_anyone(void **state)
{
	(void)state;
	make_probe();
	const char *args[] = {"--max-output-bytes", "16K", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(c, hall(path, sizeof(path)), "hall");
	json_t *opt = json_pack("{s:i}", "threads", 1);
	json_t *job = dm_job_create(c, sc, "hr", opt);
	/* A small solved job whose grids are quick to compute. */
	char cp[512];
	json_t *csc = dm_upload_file(
	        c, dm_sample("cornell.gltf", cp, sizeof(cp)), "cornell");
	json_t *cjob = dm_job_create(c, csc, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", cjob,
	                  "converge", 1));
	json_decref(dm_wait_job(c, cjob, "done", 60000));

	/* The slow one, subscribed, never reads.  On a Unix socket the
	 * kernel buffers little (one socket buffer, ~200 KiB), so the
	 * daemon's own queue fills. */
	dm_conn *slow = dm_connect_unix(d);
	json_decref(dm_ok(slow, "{s:s, s:i}", "cmd", "hello", "version", 1));
	json_decref(dm_ok(slow, "{s:s, s:O}", "cmd", "subscribe", "job", job));
	/* A normal subscriber. */
	dm_conn *fast = dm_open(d, NULL);
	json_decref(dm_ok(fast, "{s:s, s:O}", "cmd", "subscribe", "job", job));

	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	stream_log fl = {0};
	slow_log sl = {0};
	int flooded = 0, queries = 0, sent = 0, slow_read = 0;
	double end = dm_now_ms() + 170000;
	for (;;) {
		json_t *e = dm_event(fast, 100);
		if (e) {
			int stop = stream_take(&fl, e, job);
			json_decref(e);
			if (stop)
				break;
		}
		if (dm_now_ms() > end)
			fail_msg(
			        "the job did not finish with a slow subscriber "
			        "(last iteration %lld)",
			        fl.last_iteration);
		/* The other clients are served all along.  Once the daemon
		 * says it closed a slow consumer, its error frame waits in the
		 * socket for at most the close's flush time: read it now. */
		json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
		int closed_now = dm_int(st, "slow_consumers") > 0;
		json_decref(st);
		if (closed_now && !slow_read) {
			read_slow(slow, job, sent, &sl);
			slow_read = 1;
		}
		if (fl.last_iteration >= 1) {
			double lux[NPROBE];
			dm_query_points(c, job, probe, NPROBE, lux);
			queries++;
		}
		/* Once there is a solution, the slow one also asks for
		 * large answers it will not read: small requests with
		 * replies of ~600 KB each (a grid of 10,000 points with
		 * their coordinates, outside the Cornell box so that they
		 * cost little to compute: a point inside costs ~1 ms). */
		if (fl.last_iteration >= 1 && !flooded) {
			slow->send_ms = 1000;
			for (int k = 0; k < 10; k++) {
				json_t *h = json_pack(
				        "{s:s, s:O, s:[f,f,f], s:[f,f,f], "
				        "s:[f,f,f], s:f, s:b, s:i}",
				        "cmd", "query.grid", "job", cjob,
				        "origin", 3.0, 3.0, 3.0, "u", 0.0, 0.0,
				        0.5, "v", 0.5, 0.0, 0.0, "spacing",
				        0.005, "points", 1, "id", 5000 + k);
				int sr = dm_send_frame(slow, h, NULL, 0);
				json_decref(h);
				if (sr != 0)
					break; /* closed or not reading */
				sent++;
			}
			flooded = 1;
		}
	}
	assert_string_equal(fl.states[fl.nstates - 1], "done");
	json_decref(fl.last_stats);
	assert_true(queries > 0);
	assert_true(dm_alive(d));

	/* Now read the slow one, if it was not read at its close: closed
	 * with slow_consumer, or everything consistent. */
	if (!slow_read)
		read_slow(slow, job, sent, &sl);
	int replies = sl.replies, closed_with = sl.closed_with, done = sl.done;
	json_decref(sl.s.last_stats);
	if (closed_with) {
		if (!dm_wait_closed(slow, 10000))
			fail_msg("slow_consumer sent but the connection stays "
			         "open");
	} else {
		if (slow->eof)
			fail_msg("the slow subscriber was closed without "
			         "slow_consumer");
		if (!done)
			fail_msg("slow subscriber kept open but its stream "
			         "lacks the final done state (last iteration "
			         "%lld of %lld)",
			         sl.s.last_iteration, fl.last_iteration);
		assert_int_equal(sl.s.last_iteration, fl.last_iteration);
		assert_int_equal(replies, sent);
	}
	print_message("slow subscriber: %s (%d requests sent, %d replies, %d "
	              "iteration events, %lld progress dropped)\n",
	              closed_with ? "closed with slow_consumer" : "kept", sent,
	              replies, sl.s.iterations, sl.s.dropped);
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
	json_decref(job);
	json_decref(sc);
	json_decref(cjob);
	json_decref(csc);
	dm_pass();
}

/* ------------------------------------------------------------- limits */

static void test_job_and_subscription_limits(void **state)
{
	(void)state;
	const char *args[] = {
	        "--max-jobs", "3", "--max-subscriptions", "2", "--max-scenes",
	        "2",          NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("cornell.gltf", path, sizeof(path)), "cornell");
	/* Two scenes at most. */
	json_t *sc2 = dm_upload_file(c, path, "cornell-2");
	size_t len;
	unsigned char *bytes = dm_read_file(path, &len);
	json_t *r =
	        dm_call_payload(c, bytes, len, "{s:s}", "cmd", "scene.upload");
	free(bytes);
	assert_string_equal(dm_err_code(r), "limit");
	json_decref(r);
	json_decref(
	        dm_ok(c, "{s:s, s:O}", "cmd", "scene.delete", "scene", sc2));
	json_decref(sc2);
	sc2 = dm_upload_file(c, path, "cornell-3");
	json_decref(sc2);

	json_t *j[3];
	for (int i = 0; i < 3; i++)
		j[i] = dm_job_create(c, sc, "hr", NULL);
	json_decref(dm_err(c, "limit", "{s:s, s:O}", "cmd", "job.create",
	                   "scene", sc));
	/* Another connection hits the same (daemon-wide) limit. */
	dm_conn *c2 = dm_open(d, NULL);
	json_decref(dm_err(c2, "limit", "{s:s, s:O}", "cmd", "job.create",
	                   "scene", sc));
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", j[2]));
	json_decref(j[2]);
	j[2] = dm_job_create(c2, sc, "hr", NULL);

	/* Two subscriptions per connection. */
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", j[0]));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", j[1]));
	json_decref(dm_err(c, "limit", "{s:s, s:O}", "cmd", "subscribe", "job",
	                   j[2]));
	/* Others may still subscribe; unsubscribing frees a slot. */
	json_decref(dm_ok(c2, "{s:s, s:O}", "cmd", "subscribe", "job", j[2]));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "unsubscribe", "job", j[1]));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", j[2]));
	/* The session is fine: a subscribed job streams. */
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", j[2],
	                  "iterations", 1));
	stream_log l = {0};
	stream_until_stop(c, &l, j[2], 60000);
	assert_int_equal(l.iterations, 1);
	json_decref(l.last_stats);
	for (int i = 0; i < 3; i++)
		json_decref(j[i]);
	json_decref(sc);
	dm_pass();
}

/*
 * A closed box of 9,600 quads, hr with clustering off: the first iteration
 * links all 92 M pairs of polygons, minutes of form factors.  The engine
 * looks at the cancel flag between blocks of pairs (hr_refine.c), so
 * job.pause and job.cancel reply within 10 s, a seconds budget of 0.5 s
 * pauses the job within 10 s, and SIGTERM stops the daemon, status 0,
 * within 15 s.  Before, none of them came back before the whole loop had
 * run.
 */
static json_t *timed(dm_conn *c, const char *what, const char *cmd, json_t *job,
                     const char *state)
{
	double t0 = dm_now_ms();
	json_t *r =
	        dm_call_maybe(c, 10000, "{s:s, s:O}", "cmd", cmd, "job", job);
	if (!r)
		dm_fail("%s: no reply within 10 s", what);
	dm_require_ok(r, what);
	assert_string_equal(json_string_value(dm_get(r, "state")), state);
	print_message("%s: reply in %.0f ms\n", what, dm_now_ms() - t0);
	return r;
}

/* Run job to convergence and wait 0.3 s into its first iteration. */
static void run_a_while(dm_conn *c, json_t *job)
{
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_decref(dm_wait_job(c, job, "running", 60000));
	dm_sleep_ms(300);
}

/* A new hr job on sc with clustering off, one thread. */
static json_t *unclustered_job(dm_conn *c, const json_t *sc, const char *solver)
{
	json_t *opt = json_pack("{s:i, s:b}", "threads", 1, "clustering", 0);
	json_t *job = dm_job_create(c, sc, solver, opt);
	json_decref(opt);
	return job;
}

static void test_unclustered_job_stops_when_asked(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(c,
	                            dm_gen_scene("box40.glb",
	                                         "box --subdiv 40 --rho 0.5",
	                                         path, sizeof(path)),
	                            "box40");
	static const char *const solvers[] = {"hr", "rmb"};
	json_t *job;
	double t0;
	for (int k = 0; k < 2; k++) {
		print_message("%s:\n", solvers[k]);
		job = unclustered_job(c, sc, solvers[k]);
		run_a_while(c, job);
		json_decref(timed(c, "job.pause", "job.pause", job, "paused"));
		json_decref(dm_wait_job(c, job, "paused", 10000));

		/* A budget of half a second, spent within the first
		 * iteration. */
		t0 = dm_now_ms();
		json_decref(dm_ok(c, "{s:s, s:O, s:f}", "cmd", "job.run", "job",
		                  job, "seconds", 0.5));
		json_t *j = dm_wait_job(c, job, "paused", 10000);
		print_message("seconds 0.5: paused after %.0f ms\n",
		              dm_now_ms() - t0);
		assert_int_equal(dm_int(j, "iteration"), 0);
		json_decref(j);

		run_a_while(c, job);
		json_decref(
		        timed(c, "job.cancel", "job.cancel", job, "cancelled"));
		json_decref(dm_wait_job(c, job, "cancelled", 10000));
		json_decref(job);
	}

	/* A second such job running when the daemon is told to stop. */
	job = unclustered_job(c, sc, "rmb");
	run_a_while(c, job);
	t0 = dm_now_ms();
	dm_signal(d, SIGTERM);
	if (!dm_wait_exit(d, 15000))
		dm_fail("SIGTERM: still running after 15 s");
	print_message("SIGTERM: exited after %.0f ms\n", dm_now_ms() - t0);
	assert_true(WIFEXITED(d->status) && WEXITSTATUS(d->status) == 0);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_job_lifecycle_follows_the_protocol),
	        T(test_two_clients_at_once_match_solo_runs),
	        T(test_subscriber_sees_ordered_events),
	        T(test_slow_subscriber_does_not_stall_anyone),
	        T(test_job_and_subscription_limits),
	        T(test_unclustered_job_stops_when_asked),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
