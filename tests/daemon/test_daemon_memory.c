/*
 * test_daemon_memory.c -- the daemon's memory, over real sockets:
 *  - a job's memory is visible (job.info, status, /metrics) while its
 *    first iteration grows, not only once the iteration is over;
 *  - an upload whose BVH does not fit under memory_limit is answered
 *    nomem, naming the limit (it was "internal": Embree's out-of-memory
 *    was not recognised), and the daemon goes on;
 *  - a job that would pass memory_limit fails alone with nomem naming the
 *    limit, its memory is given back, and another job solves meanwhile;
 *  - while the limit is reached (lowered by SIGHUP below what is held),
 *    new uploads, jobs and runs are refused with nomem, and accepted again
 *    once it is raised;
 *  - a job's memory budget (job_memory_budget, the option memory_budget)
 *    holds its solver under it, and one below its hierarchy fails alone.
 * The scene is luxrad-scenegen's hall-full: 6 MB of geometry and BVH; hr
 * at eps 1e-5 grows to about 38 MB in a first iteration of a few
 * seconds.
 */
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "harness.h"

static const char *hall(void)
{
	static char buf[512];
	return dm_gen_scene("hall-full.glb", "hall-full", buf, sizeof(buf));
}

/* Upload the hall (*sc) and create a job on it that grows to ~38 MB. */
static json_t *greedy_job(dm_conn *c, json_t **sc)
{
	*sc = dm_upload_file(c, hall(), "hall");
	json_t *opt = json_pack("{s:i, s:f}", "threads", 1, "eps", 1e-5);
	json_t *job = dm_job_create(c, *sc, "hr", opt);
	json_decref(opt);
	return job;
}

static const char *error_message(const json_t *r)
{
	const char *m = json_string_value(
	        json_object_get(json_object_get(r, "error"), "message"));
	return m ? m : "";
}

static void test_job_memory_is_seen_while_it_grows(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = NULL;
	json_t *job = greedy_job(c, &sc);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", 1));
	/* Sample job.info until the first iteration is published. */
	long long seen = 0, samples = 0, growing = 0, last = 0;
	for (double end = dm_now_ms() + 120000; dm_now_ms() < end;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		long long it = dm_int(dm_get(r, "job"), "iteration");
		long long mem = dm_int(dm_get(r, "job"), "memory_bytes");
		json_decref(r);
		if (it >= 1)
			break;
		samples++;
		if (mem > seen)
			seen = mem;
		growing += mem > last && last > 0;
		last = mem;
		dm_sleep_ms(20);
	}
	char series[96];
	snprintf(series, sizeof(series),
	         "luxradd_job_memory_bytes{job=\"%lld\"}",
	         (long long)json_integer_value(job));
	print_message("first iteration: %lld samples, up to %lld bytes "
	              "before it ended, grew %lld times\n",
	              samples, seen, growing);
	if (samples < 3)
		fail_msg("the first iteration ended too fast to be watched "
		         "(%lld samples)",
		         samples);
	if (seen < (1 << 20))
		fail_msg("job.info showed %lld bytes during a first iteration "
		         "that grows to tens of MB",
		         seen);
	if (growing < 1)
		fail_msg("job.info's memory_bytes never grew during the first "
		         "iteration");
	json_decref(dm_wait_job(c, job, "paused", 120000));
	assert_true(dm_metric(d, series) > 0);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

static void test_an_upload_over_the_limit_is_nomem(void **state)
{
	(void)state;
	const char *args[] = {"--memory-limit", "3M", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
	assert_int_equal(dm_int(dm_get(st, "limits"), "memory_limit"), 3 << 20);
	json_decref(st);
	size_t len = 0;
	unsigned char *bytes = dm_read_file(hall(), &len);
	json_t *r = dm_call_payload(c, bytes, len, "{s:s, s:s}", "cmd",
	                            "scene.upload", "name", "too big");
	free(bytes);
	if (strcmp(dm_err_code(r), "nomem") != 0)
		fail_msg("an upload over the memory limit: %s, want nomem",
		         dm_dumps(r));
	if (!strstr(error_message(r), "memory limit"))
		fail_msg("the refusal does not name the memory limit: %s",
		         error_message(r));
	json_decref(r);
	/* Nothing is held, and a small scene still fits and solves. */
	json_t *sc = NULL;
	json_t *job = dm_solve_sample(c, "cornell.gltf", &sc);
	assert_true(dm_metric(d, "luxradd_memory_limit_refusals_total") >= 1);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

static void test_a_job_over_the_limit_fails_alone(void **state)
{
	(void)state;
	const char *args[] = {"--memory-limit", "24M", "--workers", "2", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = NULL;
	json_t *big = greedy_job(c, &sc);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", big,
	                  "converge", 1));
	/* Meanwhile a small job solves. */
	json_t *small_sc = NULL;
	json_t *small = dm_solve_sample(c, "cornell.gltf", &small_sc);
	json_t *j = dm_wait_job(c, big, "failed|done", 120000);
	if (strcmp(json_string_value(dm_get(j, "state")), "failed") != 0)
		fail_msg("a job growing past the memory limit ended %s",
		         json_string_value(dm_get(j, "state")));
	const char *why = json_string_value(json_object_get(j, "error"));
	if (!why || !strstr(why, "memory limit"))
		fail_msg("the failed job does not name the memory limit: %s",
		         why ? why : "(no error)");
	print_message("the job failed: %s\n", why);
	json_decref(j);
	/* Its solver is gone: what is held is the scenes and solutions. */
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
	json_t *m = dm_get(st, "memory");
	assert_true(dm_int(m, "total_bytes") < 16 << 20);
	json_decref(st);
	json_t *info = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", small);
	assert_true(dm_int(dm_get(info, "job"), "iteration") >= 1);
	json_decref(info);
	json_decref(big);
	json_decref(small);
	json_decref(sc);
	json_decref(small_sc);
	dm_pass();
}

/*
 * A job's memory budget: the daemon's job_memory_budget for the jobs that
 * set none, the job option memory_budget for one that does.  The greedy
 * job solves within 12 MiB (its solver's own bytes, the scene left out)
 * and says the budget stopped it, or started it over at a coarser eps
 * (budget_restarts, eps: hr, solver.c); a job whose budget is below what
 * its hierarchy needs fails alone with nomem naming the budget.
 */
static void test_a_job_budget_holds(void **state)
{
	(void)state;
	const char *args[] = {"--job-memory-budget", "12M", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = NULL;
	json_t *job = greedy_job(c, &sc);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", 2));
	json_t *j = dm_wait_job(c, job, "paused|failed", 120000);
	if (strcmp(json_string_value(dm_get(j, "state")), "paused") != 0)
		fail_msg("a job under a 12 MiB budget ended %s: %s",
		         json_string_value(dm_get(j, "state")),
		         json_string_value(json_object_get(j, "error")));
	json_decref(j);
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
	json_t *info = dm_get(r, "job");
	json_t *st = dm_get(info, "stats");
	long long solver = dm_int(dm_get(st, "memory"), "peak_own_bytes");
	double budget = json_number_value(
	        json_object_get(dm_get(info, "options"), "memory_budget"));
	long long restarts = dm_int(st, "budget_restarts");
	double eps = json_number_value(json_object_get(st, "eps"));
	print_message("budget %.0f MiB: solver peak %.2f MiB, budget reached "
	              "%d, %lld restarts, eps %g\n",
	              budget, (double)solver / 1048576.0,
	              json_is_true(json_object_get(st, "budget_reached")),
	              restarts, eps);
	assert_true(budget == 12);
	assert_true(solver <= 12ll << 20);
	assert_true(json_is_true(json_object_get(st, "budget_reached")) ||
	            restarts > 0);
	/* eps is the option's, doubled at each restart */
	assert_true(eps == 1e-5 * (double)(1ll << restarts));
	json_decref(r);

	/* Its own budget, below its elements and clusters: nomem, alone. */
	json_t *opt =
	        json_pack("{s:i, s:f}", "threads", 1, "memory_budget", 0.05);
	json_t *tiny = dm_job_create(c, sc, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", tiny,
	                  "iterations", 1));
	j = dm_wait_job(c, tiny, "failed|paused", 120000);
	const char *why = json_string_value(json_object_get(j, "error"));
	if (!why || !strstr(why, "memory budget"))
		fail_msg("a job below its hierarchy's memory ended %s: %s",
		         json_string_value(dm_get(j, "state")),
		         why ? why : "(no error)");
	print_message("the tiny job failed: %s\n", why);
	json_decref(j);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", 1));
	json_decref(dm_wait_job(c, job, "paused", 120000));
	json_decref(tiny);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* The BVH of a job's scene in a daemon started with args, and its lux
 * at the Cornell box's floor. */
static long long job_bvh(const char **args, double *lux)
{
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = NULL;
	json_t *job = dm_solve_sample(c, "cornell.gltf", &sc);
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
	json_t *k = dm_get(dm_get(dm_get(dm_get(r, "job"), "stats"), "memory"),
	                   "by_kind");
	long long bvh = dm_int(k, "bvh");
	json_decref(r);
	const double pt[6] = {0.278, 0.001, 0.28, 0, 1, 0};
	dm_query_points(c, job, pt, 1, lux);
	json_decref(job);
	json_decref(sc);
	dm_close(c);
	dm_stop(d);
	return bvh;
}

/* bvh = fast: the job's solver process builds the larger BVH of
 * Embree's own layout, not the default compact one, and the lux is the
 * same to the bit. */
static void test_compact_bvh(void **state)
{
	(void)state;
	const char *fast_args[] = {"--bvh", "fast", NULL};
	double lux_fast, lux_compact;
	long long small = job_bvh(NULL, &lux_compact);
	long long fast = job_bvh(fast_args, &lux_fast);
	print_message("BVH %lld bytes, compact %lld; %.9g lx both\n", fast,
	              small, lux_fast);
	assert_true(small < fast);
	assert_true(lux_fast == lux_compact && lux_fast > 0);
	dm_pass();
}

static void write_limit(const char *path, const char *limit)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fprintf(f, "memory_limit = %s\n", limit);
	fclose(f);
}

static void test_no_new_work_while_the_limit_is_reached(void **state)
{
	(void)state;
	char *conf = dm_tmp_file(".conf", "", 0);
	write_limit(conf, "64M");
	const char *args[] = {"--config", conf, NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = dm_upload_file(c, hall(), "hall");
	json_t *job = dm_job_create(c, sc, "hr", NULL);

	write_limit(conf, "1M"); /* below the scene already held */
	dm_signal(d, SIGHUP);
	json_t *r = NULL;
	for (double end = dm_now_ms() + 10000; dm_now_ms() < end;) {
		json_decref(r);
		r = dm_call(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
		            "iterations", 1);
		if (!strcmp(dm_err_code(r), "nomem"))
			break;
		dm_sleep_ms(100);
	}
	if (strcmp(dm_err_code(r), "nomem") != 0 ||
	    !strstr(error_message(r), "memory limit is reached"))
		fail_msg("job.run at the memory limit: %s", dm_dumps(r));
	json_decref(r);
	json_decref(dm_err(c, "nomem", "{s:s, s:O}", "cmd", "job.create",
	                   "scene", sc));
	char path[512];
	size_t len = 0;
	unsigned char *bytes = dm_read_file(
	        dm_sample("cornell.gltf", path, sizeof(path)), &len);
	r = dm_call_payload(c, bytes, len, "{s:s}", "cmd", "scene.upload");
	free(bytes);
	if (strcmp(dm_err_code(r), "nomem") != 0)
		fail_msg("an upload at the memory limit: %s", dm_dumps(r));
	json_decref(r);

	write_limit(conf, "64M");
	dm_signal(d, SIGHUP);
	for (double end = dm_now_ms() + 10000;;) {
		r = dm_call(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
		            "iterations", 1);
		int ok = !strcmp(dm_err_code(r), "");
		json_decref(r);
		if (ok)
			break;
		if (dm_now_ms() > end)
			fail_msg("job.run still refused after the limit was "
			         "raised");
		dm_sleep_ms(100);
	}
	json_decref(dm_wait_job(c, job, "paused", 60000));
	json_decref(job);
	json_decref(sc);
	unlink(conf);
	free(conf);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_job_memory_is_seen_while_it_grows),
	        T(test_an_upload_over_the_limit_is_nomem),
	        T(test_a_job_over_the_limit_fails_alone),
	        T(test_no_new_work_while_the_limit_is_reached),
	        T(test_a_job_budget_holds),
	        T(test_compact_bvh),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
