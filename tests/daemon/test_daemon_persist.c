/*
 * test_daemon_persist.c -- luxradd's state survives its process
 * (daemon/server/README.md, checkpoint rule): finished jobs come back with
 * their results; queued and running jobs are re-queued, replayed
 * deterministically from scratch to the checkpointed iteration, and
 * continue.
 *  - kill -9 in the middle of a solve, restart on the same data dir:
 *    scenes and jobs are all back under the same ids; finished and paused
 *    jobs answer queries with the lux they had; the interrupted and the
 *    queued job finish with exactly the lux of uninterrupted runs;
 *  - SIGTERM: exit status 0, and a restart shows the same state (states,
 *    iterations, options, names, results); a job running at SIGTERM
 *    finishes after the restart with the uninterrupted result; new ids
 *    do not reuse old ones;
 *  - a finished job whose checkpoint the engine refuses (as after an
 *    upgrade that changed the solution format or the scene's geometry)
 *    is replayed at the restart and answers with the same lux as before.
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

#define NPROBE 8
/* Points valid in both the Cornell box and the generated halls (the
 * numbers only need to be the same for the two runs compared). */
static const double probe[NPROBE * 6] = {
        0.1,   0.0,  0.1,   0, 1, 0, 0.45,  0.0, 0.45, 0, 1,  0,
        0.278, 0.27, 0.001, 0, 0, 1, 0.3,   0.5, 0.3,  0, -1, 0,
        4.0,   0.8,  4.0,   0, 1, 0, 12.0,  0.8, 8.0,  0, 1,  0,
        20.0,  0.01, 12.0,  0, 1, 0, 0.001, 2.0, 8.0,  1, 0,  0,
};

typedef struct snap {
	json_t *job;  /* id */
	json_t *info; /* job.info "job" object before the restart */
	double lux[NPROBE];
	int has_lux;
} snap;

static void snap_take(dm_conn *c, snap *s)
{
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", s->job);
	json_decref(s->info);
	s->info = json_incref(dm_get(r, "job"));
	json_decref(r);
	s->has_lux = dm_int(s->info, "iteration") > 0;
	if (s->has_lux)
		dm_query_points(c, s->job, probe, NPROBE, s->lux);
}

/* After the restart: same state, iteration, options, name, lux. */
static void snap_same(dm_conn *c, const snap *s, const char *what)
{
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", s->job);
	json_t *j = dm_get(r, "job");
	static const char *const same[] = {"state", "iteration", "options",
	                                   "name",  "solver",    "scene",
	                                   NULL};
	for (int k = 0; same[k]; k++)
		if (!json_equal(dm_get(j, same[k]), dm_get(s->info, same[k]))) {
			char *a = json_dumps(dm_get(s->info, same[k]),
			                     JSON_COMPACT | JSON_ENCODE_ANY);
			char *b = json_dumps(dm_get(j, same[k]),
			                     JSON_COMPACT | JSON_ENCODE_ANY);
			fail_msg("%s: job.%s was %s, after restart %s", what,
			         same[k], a, b);
		}
	json_decref(r);
	if (s->has_lux) {
		double lux[NPROBE];
		long long it = dm_query_points(c, s->job, probe, NPROBE, lux);
		assert_int_equal(it, dm_int(s->info, "iteration"));
		for (int i = 0; i < NPROBE; i++)
			if (!dm_close_enough(lux[i], s->lux[i], 1e-12))
				fail_msg("%s: point %d was %.17g lux, after "
				         "restart %.17g",
				         what, i, s->lux[i], lux[i]);
	}
}

static void snap_free(snap *s)
{
	json_decref(s->job);
	json_decref(s->info);
}

/* Run a fresh job with the same scene and options to the end; compare
 * its lux and iteration with the (resumed) job's. */
static void same_as_uninterrupted(dm_conn *c, const json_t *job,
                                  const char *what)
{
	json_t *j = dm_wait_job(c, job, "done|failed|cancelled", 170000);
	if (strcmp(json_string_value(dm_get(j, "state")), "done"))
		fail_msg("%s ended %s after the restart", what,
		         json_string_value(dm_get(j, "state")));
	json_t *ref = dm_job_create(c, dm_get(j, "scene"),
	                            json_string_value(dm_get(j, "solver")),
	                            dm_get(j, "options"));
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", ref,
	                  "converge", 1));
	json_t *rj = dm_wait_job(c, ref, "done", 170000);
	double a[NPROBE], b[NPROBE];
	long long ia = dm_query_points(c, job, probe, NPROBE, a);
	long long ib = dm_query_points(c, ref, probe, NPROBE, b);
	if (ia != ib)
		fail_msg("%s: %lld iterations after the restart, %lld "
		         "uninterrupted",
		         what, ia, ib);
	for (int i = 0; i < NPROBE; i++)
		if (!dm_close_enough(a[i], b[i], 1e-12))
			fail_msg("%s: point %d %.17g lux after the restart, "
			         "%.17g uninterrupted",
			         what, i, a[i], b[i]);
	json_decref(rj);
	json_decref(ref);
	json_decref(j);
}

static json_t *list_of(dm_conn *c, const char *cmd, const char *key)
{
	json_t *r = dm_ok(c, "{s:s}", "cmd", cmd);
	json_t *l = json_incref(dm_get(r, key));
	json_decref(r);
	return l;
}

/* Same ids, names, bytes in scene.list. */
static void same_scenes(const json_t *before, const json_t *after)
{
	assert_int_equal(json_array_size(after), json_array_size(before));
	size_t i;
	json_t *b;
	json_array_foreach(before, i, b)
	{
		size_t k;
		json_t *a;
		int found = 0;
		json_array_foreach(after, k, a)
		{
			if (!json_equal(dm_get(a, "id"), dm_get(b, "id")))
				continue;
			found = 1;
			assert_true(json_equal(dm_get(a, "name"),
			                       dm_get(b, "name")));
			assert_true(json_equal(dm_get(a, "bytes"),
			                       dm_get(b, "bytes")));
			assert_true(json_equal(dm_get(a, "polygons"),
			                       dm_get(b, "polygons")));
		}
		if (!found)
			fail_msg("scene %s missing after the restart",
			         json_string_value(dm_get(b, "name")));
	}
}

static void test_kill9_mid_solve_then_restart_resumes(void **state)
{
	(void)state;
	const char *args[] = {"--workers", "1", "--checkpoint-interval", "0.2s",
	                      NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	char p[512], hp[512];
	json_t *cornell = dm_upload_file(
	        c, dm_sample("cornell.gltf", p, sizeof(p)), "cornell");
	json_t *hall = dm_upload_file(
	        c, dm_gen_scene("hall-full.glb", "hall-full", hp, sizeof(hp)),
	        "hall");
	json_t *opt = json_pack("{s:i}", "threads", 1);

	snap done = {.job = dm_job_create(c, cornell, "hr", opt)};
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
	                  done.job, "converge", 1));
	json_decref(dm_wait_job(c, done.job, "done", 120000));
	snap_take(c, &done);
	snap paused = {.job = dm_job_create(c, cornell, "rmb", opt)};
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job",
	                  paused.job, "iterations", 2));
	json_decref(dm_wait_job(c, paused.job, "paused", 120000));
	snap_take(c, &paused);

	/* The running one and one queued behind it (one worker). */
	json_t *hopt = json_pack("{s:i, s:f, s:i}", "threads", 1, "tol", 1e-5,
	                         "max_iterations", 12);
	json_t *running = dm_job_create(c, hall, "hr", hopt);
	json_t *queued = dm_job_create(c, hall, "hr", opt);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", running));
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
	                  running, "converge", 1));
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", queued,
	                  "converge", 1));
	/* Wait for two iterations, and a little more for a checkpoint. */
	long long it = 0;
	double end = dm_now_ms() + 150000;
	while (it < 2) {
		json_t *e = dm_event(c, 1000);
		if (e &&
		    !strcmp(json_string_value(dm_get(e, "event")), "iteration"))
			it = dm_int(dm_get(e, "stats"), "iteration");
		if (e &&
		    !strcmp(json_string_value(dm_get(e, "event")), "state") &&
		    strcmp(json_string_value(dm_get(e, "state")), "running") &&
		    strcmp(json_string_value(dm_get(e, "state")), "queued"))
			fail_msg("the long job went %s before the kill",
			         json_string_value(dm_get(e, "state")));
		json_decref(e);
		if (dm_now_ms() > end)
			fail_msg("the long job did not reach 2 iterations");
	}
	dm_sleep_ms(100);
	assert_string_equal(dm_job_state(c, running), "running");
	assert_string_equal(dm_job_state(c, queued), "queued");
	json_t *scenes = list_of(c, "scene.list", "scenes");
	json_t *jobs = list_of(c, "job.list", "jobs");
	dm_close(c);

	dm_kill9(d);
	assert_true(WIFSIGNALED(d->status));
	dm_restart(d);
	c = dm_open(d, NULL);

	json_t *scenes2 = list_of(c, "scene.list", "scenes");
	same_scenes(scenes, scenes2);
	json_t *jobs2 = list_of(c, "job.list", "jobs");
	assert_int_equal(json_array_size(jobs2), json_array_size(jobs));
	snap_same(c, &done, "finished job");
	snap_same(c, &paused, "paused job");
	const char *s = dm_job_state(c, running);
	if (strcmp(s, "queued") && strcmp(s, "running") && strcmp(s, "done"))
		fail_msg("interrupted job is %s after the restart, want "
		         "re-queued",
		         s);
	s = dm_job_state(c, queued);
	if (strcmp(s, "queued") && strcmp(s, "running") && strcmp(s, "done"))
		fail_msg("queued job is %s after the restart", s);
	same_as_uninterrupted(c, running, "interrupted job");
	same_as_uninterrupted(c, queued, "queued job");

	json_decref(scenes);
	json_decref(scenes2);
	json_decref(jobs);
	json_decref(jobs2);
	snap_free(&done);
	snap_free(&paused);
	json_decref(running);
	json_decref(queued);
	json_decref(opt);
	json_decref(hopt);
	json_decref(cornell);
	json_decref(hall);
	dm_pass();
}

/* A sensor added with sensor.add: the job's sensor.list entry, which must
 * be there with the point given; waits (up to 30 s) for its value. */
static double sensor_lux(dm_conn *c, const json_t *job, const char *name,
                         const double pt[6])
{
	for (int tries = 0; tries < 300; tries++) {
		json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "sensor.list", "job",
		                  job);
		json_t *arr = dm_get(r, "sensors"), *found = NULL;
		for (size_t i = 0; i < json_array_size(arr); i++) {
			json_t *x = json_array_get(arr, i);
			const char *n =
			        json_string_value(json_object_get(x, "name"));
			if (n && !strcmp(n, name))
				found = x;
		}
		if (!found)
			fail_msg("sensor '%s' is gone: %s", name, dm_dumps(r));
		assert_string_equal(
		        json_string_value(json_object_get(found, "source")),
		        "added");
		json_t *p = json_object_get(found, "point");
		for (int k = 0; k < 6; k++)
			assert_true(json_number_value(json_array_get(p, k)) ==
			            pt[k]);
		json_t *lux = json_object_get(found, "lux");
		if (json_is_number(lux)) {
			double v = json_number_value(lux);
			json_decref(r);
			return v;
		}
		json_decref(r);
		usleep(100000);
	}
	fail_msg("sensor '%s' got no value in 30 s", name);
	return 0;
}

static void test_sigterm_exits_zero_and_restart_keeps_state(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char p[512], hp[512];
	json_t *cornell = dm_upload_file(
	        c, dm_sample("cornell.gltf", p, sizeof(p)), "cornell");
	json_t *office = dm_upload_file(
	        c, dm_sample("office.gltf", p, sizeof(p)), "office");
	json_t *hall = dm_upload_file(
	        c, dm_gen_scene("hall-full.glb", "hall-full", hp, sizeof(hp)),
	        "hall");
	json_t *opt = json_pack("{s:i, s:f}", "threads", 1, "eps", 2e-4);

	snap js[4] = {{0}};
	js[0].job = dm_job_create(c, cornell, "hr", opt); /* done */
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
	                  js[0].job, "converge", 1));
	js[1].job = dm_job_create(c, office, "progressive", opt); /* paused */
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job",
	                  js[1].job, "iterations", 3));
	js[2].job = dm_job_create(c, office, "matrix", opt); /* never run */
	js[3].job = dm_job_create(c, cornell, "rmb", opt);   /* cancelled */
	json_decref(
	        dm_ok(c, "{s:s, s:O}", "cmd", "job.cancel", "job", js[3].job));
	json_decref(dm_wait_job(c, js[0].job, "done", 120000));
	json_decref(dm_wait_job(c, js[1].job, "paused", 120000));
	json_decref(dm_wait_job(c, js[3].job, "cancelled", 120000));
	for (int i = 0; i < 4; i++)
		snap_take(c, &js[i]);
	/* Sensors added over the protocol are recorded with their job. */
	static const double desk[6] = {0.278, 0, 0.2796, 0, 1, 0};
	json_decref(dm_ok(c, "{s:s, s:O, s:s, s:[ffffff]}", "cmd", "sensor.add",
	                  "job", js[0].job, "name", "desk", "point", desk[0],
	                  desk[1], desk[2], desk[3], desk[4], desk[5]));
	double desk_lux = sensor_lux(c, js[0].job, "desk", desk);
	/* A job's sensors go with it. */
	json_t *gone = dm_job_create(c, cornell, "hr", opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:s, s:[ffffff]}", "cmd", "sensor.add",
	                  "job", gone, "name", "desk", "point", desk[0],
	                  desk[1], desk[2], desk[3], desk[4], desk[5]));
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", gone));
	/* A job running at SIGTERM. */
	json_t *hopt = json_pack("{s:i}", "threads", 1);
	json_t *running = dm_job_create(c, hall, "hr", hopt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
	                  running, "converge", 1));
	json_decref(dm_wait_job(c, running, "running", 60000));
	json_t *scenes = list_of(c, "scene.list", "scenes");
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
	json_t *counts = json_incref(dm_get(st, "jobs"));
	json_decref(st);

	dm_stop(d); /* exit 0 required */
	assert_int_equal(dm_wait_closed(c, 1000), 1);
	dm_restart(d);
	c = dm_open(d, NULL);
	json_t *scenes2 = list_of(c, "scene.list", "scenes");
	same_scenes(scenes, scenes2);
	static const char *const what[] = {"done job", "paused job",
	                                   "job never run", "cancelled job"};
	for (int i = 0; i < 4; i++)
		snap_same(c, &js[i], what[i]);
	/* The added sensor is back, with the same value from the restored
	 * solution, and still refuses a second sensor of its name. */
	assert_true(sensor_lux(c, js[0].job, "desk", desk) == desk_lux);
	json_decref(dm_err(c, "state", "{s:s, s:O, s:s, s:[ffffff]}", "cmd",
	                   "sensor.add", "job", js[0].job, "name", "desk",
	                   "point", desk[0], desk[1], desk[2], desk[3], desk[4],
	                   desk[5]));
	json_decref(dm_err(c, "not_found", "{s:s, s:O}", "cmd", "sensor.list",
	                   "job", gone));
	json_decref(dm_err(c, "state", "{s:s, s:O, s:[[f,f,f,i,i,i]]}", "cmd",
	                   "query.points", "job", js[2].job, "points", 1.0,
	                   0.01, 1.0, 0, 1, 0));
	/* The running job comes back queued or running and finishes with the
	 * uninterrupted result. */
	const char *s = dm_job_state(c, running);
	if (strcmp(s, "queued") && strcmp(s, "running") && strcmp(s, "done"))
		fail_msg("job running at SIGTERM is %s after the restart", s);
	same_as_uninterrupted(c, running, "job running at SIGTERM");
	/* The other counts are as before. */
	st = dm_ok(c, "{s:s}", "cmd", "status");
	json_t *c2 = dm_get(st, "jobs");
	static const char *const same[] = {"paused", "cancelled", NULL};
	for (int k = 0; same[k]; k++)
		assert_int_equal(dm_int(c2, same[k]), dm_int(counts, same[k]));
	json_decref(st);
	/* New ids are new. */
	json_t *nj = dm_job_create(c, cornell, "hr", opt);
	for (int i = 0; i < 4; i++)
		assert_false(json_equal(nj, js[i].job));
	assert_false(json_equal(nj, running));
	json_t *ns = dm_upload_file(c, p, "office-again");
	assert_false(json_equal(ns, cornell));
	assert_false(json_equal(ns, office));
	assert_false(json_equal(ns, hall));
	/* And a second SIGTERM, idle, exits 0 too. */
	dm_stop(d);

	json_decref(nj);
	json_decref(ns);
	json_decref(gone);
	json_decref(counts);
	json_decref(scenes);
	json_decref(scenes2);
	for (int i = 0; i < 4; i++)
		snap_free(&js[i]);
	json_decref(running);
	json_decref(opt);
	json_decref(hopt);
	json_decref(cornell);
	json_decref(office);
	json_decref(hall);
	dm_pass();
}

/* The checkpoint file of job `job` in data directory dir. */
static void checkpoint_path(const char *dir, long long job, char *out,
                            size_t len)
{
	char cmd[512], *found = NULL;
	snprintf(cmd, sizeof(cmd), "ls %s/results/%lld-*.sol", dir, job);
	if (dm_run(cmd, &found) != 0 || !found || !found[0])
		fail_msg("no checkpoint for job %lld in %s/results", job, dir);
	found[strcspn(found, "\n")] = 0;
	snprintf(out, len, "%s", found);
	free(found);
}

static void test_refused_checkpoint_is_replayed(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *scene = NULL;
	json_t *job = dm_solve_sample(c, "cornell.gltf", &scene);
	double lux0[NPROBE], lux1[NPROBE];
	long long it0 = dm_query_points(c, job, probe, 4, lux0);
	dm_stop(d);
	assert_int_equal(dm_wait_closed(c, 1000), 1);

	/* The scene digest in the solution's header (solution.c: ten
	 * 32-bit words, then the digest) no longer matches. */
	char path[600];
	checkpoint_path(d->dir, json_integer_value(job), path, sizeof(path));
	FILE *f = fopen(path, "r+b");
	assert_non_null(f);
	assert_int_equal(fseek(f, 40, SEEK_SET), 0);
	int b = fgetc(f);
	assert_true(b != EOF);
	assert_int_equal(fseek(f, 40, SEEK_SET), 0);
	assert_int_equal(fputc(b ^ 0xff, f), b ^ 0xff);
	assert_int_equal(fclose(f), 0);

	dm_restart(d);
	c = dm_open(d, NULL);
	json_decref(dm_wait_job(c, job, "done", 150000));
	long long it1 = dm_query_points(c, job, probe, 4, lux1);
	assert_int_equal(it1, it0);
	for (int i = 0; i < 4; i++)
		if (lux1[i] != lux0[i])
			fail_msg("point %d: %.9g lux after the replay, %.9g "
			         "before",
			         i, lux1[i], lux0[i]);
	size_t n = 0;
	char *log = (char *)dm_read_file(d->log_path, &n);
	assert_non_null(log);
	assert_non_null(strstr(log, "checkpoint refused"));
	assert_non_null(strstr(log, "replaying its"));
	free(log);
	dm_stop(d);
	json_decref(job);
	json_decref(scene);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_kill9_mid_solve_then_restart_resumes),
	        T(test_sigterm_exits_zero_and_restart_keeps_state),
	        T(test_refused_checkpoint_is_replayed),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
