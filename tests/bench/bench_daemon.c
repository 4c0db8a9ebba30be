/*
 * bench_daemon.c -- luxrad-bench-daemon, the daemon benchmark (a program,
 * not a test: timings on a shared machine are too noisy to assert on).
 *
 * It starts a real luxradd (tests/daemon/harness.c) and measures, in the
 * same run so that both sides see the same machine load:
 *   (a) solve   the same scene and options solved through the daemon
 *               (job.run -> "done" state event, wall time seen by the
 *               client) and by luxrad-solve (spawned; its own solve time
 *               and its process wall time), runs interleaved, median of
 *               N; the ratio daemon / luxrad-solve (goal <= 1.05);
 *   (b) query   query.points with 10,000 points on the solved job: round
 *               trip latency p50 / p99 over Q queries;
 *   (c) fanout  the daemon solve with 50 subscribers reading every event
 *               vs with none, interleaved, median of N; the ratio.
 * Output: a readable report, or --json one object; the per-run times
 * go to stderr as they come.
 */
#include <jansson.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench_stats.h"
#include "harness.h"

typedef struct bench_args {
	const char *scene;     /* NULL: generated hall-full */
	int runs;              /* N for (a) and (c) */
	int threads;           /* engine threads, both sides */
	int points;            /* (b) points per query */
	int queries;           /* (b) Q */
	int subscribers;       /* (c) */
	double eps;            /* 0: engine default */
	const char *isolation; /* the daemon's isolation [process] */
	int json;
} bench_args;

static void bench_fail(const char *msg)
{
	fprintf(stderr, "luxrad-bench-daemon: %s\n", msg);
	exit(1);
}

static void usage(FILE *f)
{
	fprintf(f,
	        "Usage: luxrad-bench-daemon [options]\n"
	        "  --scene FILE       scene to solve [generated hall-full]\n"
	        "  --runs N           solves per side for (a) and (c) [5]\n"
	        "  --threads N        engine threads, daemon and luxrad-solve "
	        "[1]\n"
	        "  --eps X            refinement threshold [engine default]\n"
	        "  --points N         points per query for (b) [10000]\n"
	        "  --queries N        queries for (b) [10]\n"
	        "  --subscribers N    subscribers for (c) [50]\n"
	        "  --isolation MODE   the daemon's: process or thread "
	        "[process]\n"
	        "  --json             one JSON object on stdout\n"
	        "Times in seconds; no pass/fail on speed.\n");
}

static json_t *job_options(const bench_args *a)
{
	json_t *o = json_pack("{s:i, s:f, s:i}", "threads", a->threads, "tol",
	                      1e-3, "max_iterations", 100);
	if (a->eps > 0)
		json_object_set_new(o, "eps", json_real(a->eps));
	return o;
}

/* Drain whatever the subscribers have, without waiting. */
static void drain(dm_conn **subs, int n, struct pollfd *pf, long long *events)
{
	if (n <= 0)
		return;
	for (int i = 0; i < n; i++) {
		pf[i].fd = subs[i]->fd;
		pf[i].events = POLLIN;
		pf[i].revents = 0;
	}
	if (poll(pf, (nfds_t)n, 0) <= 0)
		return;
	for (int i = 0; i < n; i++) {
		if (!(pf[i].revents & (POLLIN | POLLHUP | POLLERR)))
			continue;
		json_t *h;
		while (dm_recv(subs[i], 0, &h, NULL, NULL) == 1) {
			(*events)++;
			json_decref(h);
		}
	}
}

/*
 * One daemon solve: create a job, subscribe (and the n subscribers),
 * run to convergence, wait for the "done" event.  Returns the wall time
 * from job.run to the event; *engine_s gets stats.seconds_total.
 */
static double daemon_solve(dm_conn *c, const json_t *scene, const bench_args *a,
                           dm_conn **subs, int n, double *engine_s,
                           long long *sub_events, long long *iterations)
{
	json_t *opt = job_options(a);
	json_t *job = dm_job_create(c, scene, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "subscribe", "job", job));
	for (int i = 0; i < n; i++)
		json_decref(dm_ok(subs[i], "{s:s, s:O}", "cmd", "subscribe",
		                  "job", job));
	struct pollfd *pf = calloc((size_t)n + 1, sizeof(*pf));
	double t0 = dm_now_ms();
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	double t1 = 0;
	for (;;) {
		json_t *e = dm_event(c, n ? 5 : 60000);
		if (n)
			drain(subs, n, pf, sub_events);
		if (!e) {
			if (!n || dm_now_ms() - t0 > 600000)
				dm_fail("no done event");
			continue;
		}
		const char *kind =
		        json_string_value(json_object_get(e, "event"));
		const char *st = json_string_value(json_object_get(e, "state"));
		int end = kind && !strcmp(kind, "state") && st &&
		          (!strcmp(st, "done") || !strcmp(st, "failed") ||
		           !strcmp(st, "cancelled"));
		if (end && strcmp(st, "done"))
			dm_fail("job ended %s", st);
		json_decref(e);
		if (end) {
			t1 = dm_now_ms();
			break;
		}
	}
	/* The subscribers get their last events too. */
	for (int i = 0; i < n; i++) {
		json_t *h;
		while (dm_recv(subs[i], 200, &h, NULL, NULL) == 1) {
			(*sub_events)++;
			const char *st =
			        json_string_value(json_object_get(h, "state"));
			int last = st && !strcmp(st, "done");
			json_decref(h);
			if (last)
				break;
		}
		json_decref(dm_ok(subs[i], "{s:s, s:O}", "cmd", "unsubscribe",
		                  "job", job));
	}
	free(pf);
	json_t *j = dm_wait_job(c, job, "done", 10000);
	*engine_s = dm_num(dm_get(j, "stats"), "seconds_total");
	*iterations = dm_int(j, "iteration");
	json_decref(j);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	json_decref(job);
	return (t1 - t0) / 1e3;
}

/*
 * luxrad-solve on the same scene and options: its solve seconds, and the
 * process wall time in *wall_s.  With a points file, *query_s gets the
 * time left for the queries: wall - load - solve (process start-up and
 * output included, a few ms).
 */
static double cli_solve(const char *scene, const bench_args *a,
                        const char *points, double *wall_s,
                        long long *iterations, double *query_s)
{
	char cmd[2048], eps[64] = "", pts[600] = "";
	if (a->eps > 0)
		snprintf(eps, sizeof(eps), "--eps %.17g", a->eps);
	if (points)
		snprintf(pts, sizeof(pts), "--points '%s'", points);
	snprintf(cmd, sizeof(cmd),
	         "'%s/luxrad-solve' '%s' --json --threads %d --tol 1e-3 "
	         "--max-iterations 100 %s %s 2>/dev/null",
	         LUXRAD_BINARY_DIR, scene, a->threads, eps, pts);
	char *out = NULL;
	double t0 = dm_now_ms();
	int rc = dm_run(cmd, &out);
	*wall_s = (dm_now_ms() - t0) / 1e3;
	if (rc != 0)
		dm_fail("%s: exit %d", cmd, rc);
	json_error_t je;
	json_t *j = json_loads(out, 0, &je);
	free(out);
	if (!j)
		dm_fail("luxrad-solve --json: %s", je.text);
	double s = dm_num(j, "seconds");
	*iterations = dm_int(dm_get(j, "stats"), "iteration");
	if (query_s)
		*query_s = *wall_s - dm_num(j, "load_seconds") - s;
	json_decref(j);
	return s;
}

static int parse_args(int argc, char **argv, bench_args *a)
{
	*a = (bench_args){.runs = 5,
	                  .threads = 1,
	                  .points = 10000,
	                  .queries = 10,
	                  .subscribers = 50,
	                  .isolation = "process"};
	for (int i = 1; i < argc; i++) {
		const char *o = argv[i];
		const char *v = i + 1 < argc ? argv[i + 1] : NULL;
		if (!strcmp(o, "--json")) {
			a->json = 1;
			continue;
		}
		if (!strcmp(o, "--help")) {
			usage(stdout);
			exit(0);
		}
		if (!v) {
			usage(stderr);
			return -1;
		}
		i++;
		if (!strcmp(o, "--scene"))
			a->scene = v;
		else if (!strcmp(o, "--runs"))
			a->runs = atoi(v);
		else if (!strcmp(o, "--threads"))
			a->threads = atoi(v);
		else if (!strcmp(o, "--eps"))
			a->eps = atof(v);
		else if (!strcmp(o, "--points"))
			a->points = atoi(v);
		else if (!strcmp(o, "--queries"))
			a->queries = atoi(v);
		else if (!strcmp(o, "--subscribers"))
			a->subscribers = atoi(v);
		else if (!strcmp(o, "--isolation"))
			a->isolation = v;
		else {
			usage(stderr);
			return -1;
		}
	}
	if (a->runs < 1 || a->threads < 0 || a->points < 1 || a->queries < 1 ||
	    a->subscribers < 0) {
		usage(stderr);
		return -1;
	}
	return 0;
}

/* (b): Q queries of n points on the floor of the scene's bounds; and
 * luxrad-solve answering the same points once (*cli_s). */
static void bench_queries(dm_conn *c, const json_t *scene,
                          const char *scene_path, const bench_args *a,
                          double *p50, double *p99, long long *iters,
                          double *cli_s)
{
	json_t *opt = job_options(a);
	json_t *job = dm_job_create(c, scene, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_t *j = dm_wait_job(c, job, "done", 600000);
	*iters = dm_int(j, "iteration");
	json_decref(j);
	json_t *info =
	        dm_ok(c, "{s:s, s:O}", "cmd", "scene.info", "scene", scene);
	json_t *b = dm_get(info, "bounds");
	double lo[3], hi[3];
	for (int k = 0; k < 3; k++) {
		lo[k] = json_number_value(json_array_get(dm_get(b, "min"), k));
		hi[k] = json_number_value(json_array_get(dm_get(b, "max"), k));
	}
	json_decref(info);
	/* A fixed pseudo-random set: points 1 cm above the floor, up. */
	json_t *pts = json_array();
	char *text = malloc((size_t)a->points * 128 + 1);
	size_t tl = 0;
	uint64_t s = 0x9E3779B97F4A7C15ull;
	for (int i = 0; i < a->points; i++) {
		double r[2];
		for (int k = 0; k < 2; k++) {
			s ^= s << 13;
			s ^= s >> 7;
			s ^= s << 17;
			r[k] = (double)(s >> 11) / 9007199254740992.0;
		}
		double x = lo[0] + r[0] * (hi[0] - lo[0]), y = lo[1] + 0.01,
		       z = lo[2] + r[1] * (hi[2] - lo[2]);
		json_array_append_new(
		        pts, json_pack("[f,f,f,i,i,i]", x, y, z, 0, 1, 0));
		tl += (size_t)sprintf(text + tl, "%.17g %.17g %.17g 0 1 0\n", x,
		                      y, z);
	}
	char *pf = dm_tmp_file(".pts", text, tl);
	free(text);
	double wall;
	long long it;
	cli_solve(scene_path, a, pf, &wall, &it, cli_s);
	unlink(pf);
	free(pf);
	double *ms = malloc((size_t)a->queries * sizeof(double));
	for (int q = 0; q < a->queries; q++) {
		double t0 = dm_now_ms();
		json_t *r = dm_ok(c, "{s:s, s:O, s:O}", "cmd", "query.points",
		                  "job", job, "points", pts);
		ms[q] = dm_now_ms() - t0;
		if (json_array_size(dm_get(r, "lux")) != (size_t)a->points)
			dm_fail("query.points answered %zu values",
			        json_array_size(dm_get(r, "lux")));
		json_decref(r);
	}
	*p50 = bench_pct(ms, a->queries, 50);
	*p99 = bench_pct(ms, a->queries, 99);
	free(ms);
	json_decref(pts);
	json_decref(dm_ok(c, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	json_decref(job);
}

int main(int argc, char **argv)
{
	bench_args a;
	if (parse_args(argc, argv, &a) != 0)
		return 2;
	dm_fail_hook = bench_fail;
	dm_reply_ms = 3600 * 1000; /* 10,000 points take seconds each */
	signal(SIGPIPE, SIG_IGN);
	char gen[512];
	const char *scene = a.scene ? a.scene
	                            : dm_gen_scene("hall-full.glb", "hall-full",
	                                           gen, sizeof(gen));
	char thr[16];
	snprintf(thr, sizeof(thr), "%d", a.threads);
	const char *dargs[] = {"--workers",
	                       "1",
	                       "--solver-threads",
	                       thr,
	                       "--max-subscriptions",
	                       "16",
	                       "--max-points",
	                       "1000000",
	                       "--log-level",
	                       "warn",
	                       "--isolation",
	                       a.isolation,
	                       NULL};
	dm_daemon *d = dm_start(dargs);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = dm_upload_file(c, scene, "bench");

	/* (a) daemon vs luxrad-solve, interleaved. */
	int n = a.runs;
	double *dw = calloc((size_t)n, sizeof(double)),
	       *de = calloc((size_t)n, sizeof(double)),
	       *cs = calloc((size_t)n, sizeof(double)),
	       *cw = calloc((size_t)n, sizeof(double));
	long long dit = 0, cit = 0, ev = 0;
	/* A warm-up of each (page cache, first BVH build). */
	double tmp;
	daemon_solve(c, sc, &a, NULL, 0, &tmp, &ev, &dit);
	cli_solve(scene, &a, NULL, &tmp, &cit, NULL);
	for (int i = 0; i < n; i++) {
		dw[i] = daemon_solve(c, sc, &a, NULL, 0, &de[i], &ev, &dit);
		cs[i] = cli_solve(scene, &a, NULL, &cw[i], &cit, NULL);
		fprintf(stderr,
		        "(a) run %d: daemon %.3f s (engine %.3f s), "
		        "luxrad-solve %.3f s (process %.3f s)\n",
		        i + 1, dw[i], de[i], cs[i], cw[i]);
	}
	double m_dw = bench_median(dw, n), m_de = bench_median(de, n),
	       m_cs = bench_median(cs, n), m_cw = bench_median(cw, n);

	/* (b) query latency. */
	double p50 = 0, p99 = 0, cli_q = 0;
	long long qit = 0;
	bench_queries(c, sc, scene, &a, &p50, &p99, &qit, &cli_q);

	/* (c) 50 subscribers vs none, interleaved. */
	dm_conn **subs = calloc((size_t)a.subscribers + 1, sizeof(*subs));
	for (int i = 0; i < a.subscribers; i++)
		subs[i] = dm_open(d, NULL);
	double *w0 = calloc((size_t)n, sizeof(double)),
	       *w1 = calloc((size_t)n, sizeof(double));
	long long sub_events = 0, it0 = 0, it1 = 0;
	for (int i = 0; i < n; i++) {
		w0[i] = daemon_solve(c, sc, &a, NULL, 0, &tmp, &ev, &it0);
		w1[i] = daemon_solve(c, sc, &a, subs, a.subscribers, &tmp,
		                     &sub_events, &it1);
		fprintf(stderr,
		        "(c) run %d: no subscriber %.3f s, %d "
		        "subscribers %.3f s\n",
		        i + 1, w0[i], a.subscribers, w1[i]);
	}
	double m_w0 = bench_median(w0, n), m_w1 = bench_median(w1, n);

	if (a.json) {
		json_t *o = json_pack(
		        "{s:s, s:s, s:i, s:i, s:{s:f, s:f, s:f, s:f, s:f, s:I, "
		        "s:I}, "
		        "s:{s:i, s:i, s:f, s:f, s:f, s:I}, s:{s:i, s:f, s:f, "
		        "s:f, "
		        "s:I}}",
		        "scene", scene, "isolation", a.isolation, "runs", n,
		        "threads", a.threads, "solve", "daemon_s", m_dw,
		        "daemon_engine_s", m_de, "cli_solve_s", m_cs,
		        "cli_process_s", m_cw, "ratio", m_dw / m_cs,
		        "daemon_iterations", dit, "cli_iterations", cit,
		        "query", "points", a.points, "queries", a.queries,
		        "p50_ms", p50, "p99_ms", p99, "cli_query_ms",
		        cli_q * 1e3, "iterations", qit, "fanout", "subscribers",
		        a.subscribers, "none_s", m_w0, "with_s", m_w1, "ratio",
		        m_w1 / m_w0, "events_read", sub_events);
		json_dumpf(o, stdout, JSON_INDENT(2));
		fputc('\n', stdout);
		json_decref(o);
	} else {
		printf("scene %s, threads %d, median of %d runs\n", scene,
		       a.threads, n);
		printf("(a) solve: daemon %.3f s (engine %.3f s, %lld "
		       "iterations), luxrad-solve %.3f s (process %.3f s, %lld "
		       "iterations)\n",
		       m_dw, m_de, dit, m_cs, m_cw, cit);
		printf("    ratio daemon / luxrad-solve = %.3f (goal <= "
		       "1.05); vs process wall %.3f\n",
		       m_dw / m_cs, m_dw / m_cw);
		printf("(b) query.points, %d points, %d queries: p50 %.2f ms, "
		       "p99 %.2f ms (%.0f points/s at p50); luxrad-solve "
		       "--points, same points: %.2f ms\n",
		       a.points, a.queries, p50, p99, a.points / (p50 / 1e3),
		       cli_q * 1e3);
		printf("(c) solve with %d subscribers %.3f s vs none %.3f s: "
		       "ratio %.3f (%lld events read)\n",
		       a.subscribers, m_w1, m_w0, m_w1 / m_w0, sub_events);
	}
	free(dw);
	free(de);
	free(cs);
	free(cw);
	free(w0);
	free(w1);
	free(subs);
	json_decref(sc);
	dm_stop(d);
	dm_pass();
	dm_teardown(NULL);
	return 0;
}
