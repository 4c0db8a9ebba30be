/*
 * test_daemon_isolation.c -- a fault in one solve fails that job alone,
 * over real sockets.
 *
 * Faults are real: LUXRAD_TEST_FAULT=KIND:JOB-NAME in the daemon's
 * environment makes the solver of the job of that name write through a
 * null pointer (segv), abort, or stop listening to its cancel flag
 * (hang, from the start of the step), in the second iteration; a kill -9 from
 * outside stands for the kernel's OOM killer.
 *  - isolation = thread (what every version before solver processes did):
 *    the segv takes the daemon down, and every other job with it;
 *  - isolation = process (the default): the same segv, an abort or a
 *    kill -9 fails that job alone, naming how its process ended; its
 *    iteration 1 still answers queries; another job solving meanwhile
 *    finishes with the lux it has alone; the daemon goes on serving;
 *  - a solver that does not stop is killed solver_stop_timeout after
 *    job.pause, job.cancel or a shutdown, which then reply in time;
 *  - both isolations give the same lux, to the last bit.
 */
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmocka.h>

#include "harness.h"

/* Cornell: 0.556 x 0.549 x 0.559 m, y up. */
#define NPTS 5
static const double pts[NPTS * 6] = {
        0.1, 0.0, 0.1,   0,    1,     0,     0.45, 0.0, 0.45,  0,
        1,   0,   0.278, 0.27, 0.001, 0,     0,    1,   0.001, 0.27,
        0.3, 1,   0,     0,    0.278, 0.548, 0.1,  0,   -1,    0};

/* Under a sanitizer, a SEGV is reported and ends the process with an
 * exit status, not the signal. */
static int sanitized(void)
{
	return getenv("ASAN_OPTIONS") || getenv("TSAN_OPTIONS");
}

static const char *error_of(const json_t *job)
{
	const char *e = json_string_value(json_object_get(job, "error"));
	return e ? e : "";
}

/* A job named name on scene, hr, one thread, tight eps: a few iterations
 * of a few tens of milliseconds each on the Cornell box. */
static json_t *named_job(dm_conn *c, const json_t *scene, const char *name)
{
	json_t *r = dm_ok(c, "{s:s, s:O, s:s, s:s, s:{s:i, s:f}}", "cmd",
	                  "job.create", "scene", scene, "name", name, "solver",
	                  "hr", "options", "threads", 1, "eps", 1e-5);
	json_t *id = json_incref(dm_get(r, "job"));
	json_decref(r);
	return id;
}

/* job.run for n more iterations. */
static void run_iterations(dm_conn *c, const json_t *job, int n)
{
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", n));
}

/* A daemon whose solvers commit fault ("KIND:JOB-NAME"), with args. */
static dm_daemon *start_with_fault(const char *fault, const char *const *args)
{
	setenv("LUXRAD_TEST_FAULT", fault, 1);
	dm_daemon *d = dm_start(args);
	unsetenv("LUXRAD_TEST_FAULT");
	return d;
}

static json_t *cornell(dm_conn *c)
{
	char buf[512];
	return dm_upload_file(c, dm_sample("cornell.gltf", buf, sizeof(buf)),
	                      "cornell");
}

/* Lux at pts from a fresh job run for `iterations` (no fault). */
static void reference_lux(dm_conn *c, const json_t *scene, int iterations,
                          double *lux)
{
	json_t *job = named_job(c, scene, "reference");
	run_iterations(c, job, iterations);
	json_decref(dm_wait_job(c, job, "paused|done", 60000));
	assert_int_equal(dm_query_points(c, job, pts, NPTS, lux), iterations);
	json_decref(job);
}

static void test_thread_isolation_a_crash_takes_the_daemon(void **state)
{
	(void)state;
	const char *args[] = {"--isolation", "thread", NULL};
	dm_daemon *d = start_with_fault("segv:crasher", args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = cornell(c);
	json_t *job = named_job(c, sc, "crasher");
	run_iterations(c, job, 3);
	if (!dm_wait_exit(d, 30000))
		fail_msg("with isolation = thread, the daemon outlived a "
		         "segfault in a solve");
	print_message("isolation = thread: the daemon ended with wait "
	              "status %#x (%s)\n",
	              d->status,
	              WIFSIGNALED(d->status) ? strsignal(WTERMSIG(d->status))
	                                     : "an exit");
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/*
 * The crash of one job's solver process, with another job solving at the
 * same time: kind is the fault (segv, abort), want what the error says.
 */
static void crash_fails_one_job(const char *kind, const char *want)
{
	char fault[64];
	snprintf(fault, sizeof(fault), "%s:crasher", kind);
	const char *args[] = {"--workers", "2", NULL};
	dm_daemon *d = start_with_fault(fault, args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = cornell(c);
	double alone[NPTS], lux[NPTS];
	reference_lux(c, sc, 4, alone);

	json_t *bystander = named_job(c, sc, "bystander");
	json_t *crasher = named_job(c, sc, "crasher");
	run_iterations(c, bystander, 4);
	run_iterations(c, crasher, 3);
	json_t *info = dm_wait_job(c, crasher, "failed|paused|done", 60000);
	const char *st = json_string_value(json_object_get(info, "state"));
	const char *err = error_of(info);
	print_message("%s: job %s: %s\n", kind, st, err);
	if (strcmp(st, "failed") != 0)
		fail_msg("the crashing job ended %s, not failed", st);
	if (!strstr(err, "solver process") ||
	    !(strstr(err, want) ||
	      (sanitized() && strstr(err, "exited with status"))) ||
	    !strstr(err, "during iteration 2"))
		fail_msg("the error does not say what happened: %s", err);
	assert_int_equal(dm_int(info, "iteration"), 1);
	assert_null(json_object_get(info, "solver_pid"));
	json_decref(info);

	/* Its iteration 1 still answers. */
	assert_int_equal(dm_query_points(c, crasher, pts, NPTS, lux), 1);
	for (int i = 0; i < NPTS; i++)
		assert_true(lux[i] > 0);

	/* The other job finished, with what it computes alone. */
	info = dm_wait_job(c, bystander, "paused|done|failed", 60000);
	assert_string_equal(json_string_value(json_object_get(info, "state")),
	                    "paused");
	json_decref(info);
	assert_int_equal(dm_query_points(c, bystander, pts, NPTS, lux), 4);
	assert_memory_equal(lux, alone, sizeof(lux));

	/* The daemon goes on: a new job solves, and the memory the dead
	 * process held was given back. */
	json_t *after = named_job(c, sc, "after");
	run_iterations(c, after, 4);
	json_decref(dm_wait_job(c, after, "paused", 60000));
	assert_int_equal(dm_query_points(c, after, pts, NPTS, lux), 4);
	assert_memory_equal(lux, alone, sizeof(lux));
	assert_true(dm_alive(d));
	json_decref(after);
	json_decref(crasher);
	json_decref(bystander);
	json_decref(sc);
	dm_stop(d);
	dm_pass();
}

static void test_a_segfault_fails_that_job_alone(void **state)
{
	(void)state;
	crash_fails_one_job("segv", "signal 11");
}

static void test_an_abort_fails_that_job_alone(void **state)
{
	(void)state;
	crash_fails_one_job("abort", "signal 6");
}

/* kill -9 of a solver process mid-iteration, as the OOM killer would. */
static void test_a_killed_solver_process_fails_its_job(void **state)
{
	(void)state;
	char buf[512];
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = dm_upload_file(
	        c, dm_gen_scene("hall-full.glb", "hall-full", buf, sizeof(buf)),
	        "hall");
	json_t *opt = json_pack("{s:i, s:f}", "threads", 1, "eps", 1e-5);
	json_t *job = dm_job_create(c, sc, "hr", opt);
	json_decref(opt);
	run_iterations(c, job, 1);
	long long pid = 0;
	for (double end = dm_now_ms() + 30000; !pid && dm_now_ms() < end;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		json_t *p = json_object_get(dm_get(r, "job"), "solver_pid");
		pid = p ? json_integer_value(p) : 0;
		json_decref(r);
		if (!pid)
			dm_sleep_ms(10);
	}
	if (!pid)
		fail_msg("job.info never showed the job's solver_pid");
	dm_sleep_ms(200); /* inside the first iteration (seconds long) */
	assert_int_equal(kill((pid_t)pid, SIGKILL), 0);
	json_t *info = dm_wait_job(c, job, "failed|paused", 30000);
	print_message("kill -9: %s\n", error_of(info));
	assert_string_equal(json_string_value(json_object_get(info, "state")),
	                    "failed");
	if (!strstr(error_of(info), "signal 9"))
		fail_msg("the error does not name the signal: %s",
		         error_of(info));
	json_decref(info);
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
	json_decref(st);
	json_decref(job);
	json_decref(sc);
	dm_stop(d);
	dm_pass();
}

/* Seconds job.cmd took to reply, and the state it left. */
static double timed(dm_conn *c, const char *cmd, const json_t *job)
{
	double t0 = dm_now_ms();
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", cmd, "job", job));
	return (dm_now_ms() - t0) / 1000.0;
}

static void test_a_solver_that_does_not_stop_is_killed(void **state)
{
	(void)state;
	const char *args[] = {"--solver-stop-timeout", "1s", NULL};
	dm_daemon *d = start_with_fault("hang:deaf", args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = cornell(c);
	json_t *job = named_job(c, sc, "deaf");
	run_iterations(c, job, 3);
	/* Iteration 1 is published, then the solver stops listening. */
	for (double end = dm_now_ms() + 30000; dm_now_ms() < end;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		long long it = dm_int(dm_get(r, "job"), "iteration");
		json_decref(r);
		if (it >= 1)
			break;
		dm_sleep_ms(10);
	}
	dm_sleep_ms(300);
	assert_string_equal(dm_job_state(c, job), "running");
	double s = timed(c, "job.pause", job);
	print_message("job.pause of a deaf solver replied in %.2f s\n", s);
	assert_true(s >= 0.9 && s < 5.0);
	json_t *info = dm_wait_job(c, job, "paused", 1000);
	assert_int_equal(dm_int(info, "iteration"), 1);
	assert_null(json_object_get(info, "solver_pid"));
	json_decref(info);

	/* Resumed: a new process replays iteration 1, then goes deaf
	 * again; job.cancel is answered the same way.  A cancel waits for
	 * the replay's step by design (srv_job_raise_cancel_locked): the
	 * replay must end first, and under TSan one Cornell step took
	 * 6.4 s on a slow machine, where a fixed 1 s wait timed it too. */
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.resume", "job", job));
	dm_sleep_ms(300);
	for (double end = dm_now_ms() + 60000; dm_now_ms() < end;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		int replaying = json_is_true(
		        json_object_get(dm_get(r, "job"), "replaying"));
		json_decref(r);
		if (!replaying)
			break;
		dm_sleep_ms(50);
	}
	dm_sleep_ms(300);
	s = timed(c, "job.cancel", job);
	print_message("job.cancel of a deaf solver replied in %.2f s\n", s);
	assert_true(s < 5.0);
	assert_string_equal(dm_job_state(c, job), "cancelled");

	/* And a shutdown with a deaf solver still ends. */
	json_t *again = named_job(c, sc, "deaf");
	run_iterations(c, again, 3);
	dm_sleep_ms(1500);
	double t0 = dm_now_ms();
	dm_stop(d);
	print_message("shutdown with a deaf solver took %.2f s\n",
	              (dm_now_ms() - t0) / 1000.0);
	json_decref(again);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* Each isolation's lux at pts after 3 iterations of hr and of rmb. */
static void solve_in(const char *isolation, double lux[2][NPTS])
{
	const char *args[] = {"--isolation", isolation, NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = cornell(c);
	const char *solvers[2] = {"hr", "rmb"};
	for (int k = 0; k < 2; k++) {
		json_t *opt = json_pack("{s:i}", "threads", 2);
		json_t *job = dm_job_create(c, sc, solvers[k], opt);
		json_decref(opt);
		run_iterations(c, job, 3);
		json_decref(dm_wait_job(c, job, "paused|done", 60000));
		dm_query_points(c, job, pts, NPTS, lux[k]);
		json_decref(job);
	}
	json_decref(sc);
	dm_stop(d);
}

static void test_both_isolations_give_the_same_lux(void **state)
{
	(void)state;
	double thread[2][NPTS], process[2][NPTS];
	solve_in("thread", thread);
	solve_in("process", process);
	assert_memory_equal(thread, process, sizeof(thread));
	print_message("hr and rmb, 3 iterations: %d points, identical bits "
	              "(e.g. %.9g lux)\n",
	              NPTS, process[0][0]);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test_setup_teardown(
	                test_thread_isolation_a_crash_takes_the_daemon,
	                dm_setup, dm_teardown),
	        cmocka_unit_test_setup_teardown(
	                test_a_segfault_fails_that_job_alone, dm_setup,
	                dm_teardown),
	        cmocka_unit_test_setup_teardown(
	                test_an_abort_fails_that_job_alone, dm_setup,
	                dm_teardown),
	        cmocka_unit_test_setup_teardown(
	                test_a_killed_solver_process_fails_its_job, dm_setup,
	                dm_teardown),
	        cmocka_unit_test_setup_teardown(
	                test_a_solver_that_does_not_stop_is_killed, dm_setup,
	                dm_teardown),
	        cmocka_unit_test_setup_teardown(
	                test_both_isolations_give_the_same_lux, dm_setup,
	                dm_teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
