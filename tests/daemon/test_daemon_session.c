/*
 * test_daemon_session.c -- the session layer of a real luxradd, over real
 * sockets (PROTOCOL.md "Session"):
 *  - hello answers version, server, capabilities, solvers and the limits
 *    the daemon was started with, on TCP and on the Unix socket; ids are
 *    echoed; a second hello is "state";
 *  - a request before hello gets auth_required and the connection closes;
 *    an unsupported version gets "version" and closes;
 *  - with --require-token: a missing or wrong token gets auth_failed and
 *    closes, the right one is accepted, other sessions are unaffected;
 *  - status carries every documented member;
 *  - --max-connections: the connection over the limit gets
 *    too_many_connections, the others keep working, a freed slot is
 *    reusable;
 *  - --idle-timeout: a silent connection gets idle_timeout and closes, an
 *    active one stays;
 *  - /metrics answers Prometheus text with the documented families and
 *    404 elsewhere;
 *  - the shutdown command: ok, then the daemon exits 0.
 */
#include <setjmp.h>
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

static int array_has_string(const json_t *arr, const char *s)
{
	size_t i;
	json_t *v;
	json_array_foreach(arr, i, v)
	{
		if (json_is_string(v) && !strcmp(json_string_value(v), s))
			return 1;
	}
	return 0;
}

static void check_hello_reply(const json_t *r)
{
	assert_int_equal(dm_int(r, "version"), 1);
	const char *server = json_string_value(dm_get(r, "server"));
	assert_non_null(server);
	assert_int_equal(strncmp(server, "luxradd/", 8), 0);
	static const char *const caps[] = {
	        "scene.gltf",   "scene.glb",  "export.glb",     "subscribe",
	        "query.points", "query.grid", "query.surfaces", "metrics"};
	json_t *c = dm_get(r, "capabilities");
	for (size_t i = 0; i < sizeof(caps) / sizeof(caps[0]); i++)
		if (!array_has_string(c, caps[i]))
			fail_msg("hello: capability \"%s\" missing", caps[i]);
	static const char *const solvers[] = {"matrix", "progressive", "hr",
	                                      "rmb"};
	json_t *s = dm_get(r, "solvers");
	assert_int_equal(json_array_size(s), 4);
	for (size_t i = 0; i < 4; i++)
		if (!array_has_string(s, solvers[i]))
			fail_msg("hello: solver \"%s\" missing", solvers[i]);
}

static void test_hello_reports_version_capabilities_and_limits(void **state)
{
	(void)state;
	const char *args[] = {"--max-header-bytes",
	                      "65536",
	                      "--max-scene-bytes",
	                      "2000000",
	                      "--max-points",
	                      "777",
	                      "--max-subscriptions",
	                      "5",
	                      "--idle-timeout",
	                      "77",
	                      NULL};
	dm_daemon *d = dm_start(args);

	dm_conn *c = dm_connect_tcp(d);
	json_t *r = dm_call(c, "{s:s, s:i, s:s}", "cmd", "hello", "version", 1,
	                    "client", "test");
	assert_string_equal(dm_err_code(r), "");
	/* The id is echoed. */
	assert_true(json_is_integer(json_object_get(r, "id")));
	check_hello_reply(r);
	json_t *lim = dm_get(r, "limits");
	assert_int_equal(dm_int(lim, "max_header_bytes"), 65536);
	assert_int_equal(dm_int(lim, "max_scene_bytes"), 2000000);
	assert_int_equal(dm_int(lim, "max_points"), 777);
	assert_int_equal(dm_int(lim, "max_subscriptions"), 5);
	assert_true(dm_num(lim, "idle_timeout_s") == 77.0);
	json_decref(r);

	/* A string id is echoed as it was sent. */
	json_t *h = json_pack("{s:s, s:s}", "cmd", "status", "id", "abc-1");
	dm_send_frame(c, h, NULL, 0);
	json_decref(h);
	json_t *f = NULL;
	assert_int_equal(dm_recv(c, DM_REPLY_MS, &f, NULL, NULL), 1);
	assert_string_equal(json_string_value(json_object_get(f, "id")),
	                    "abc-1");
	assert_true(json_is_true(json_object_get(f, "ok")));
	json_decref(f);

	/* A second hello on a session is "state"; the session goes on. */
	json_decref(
	        dm_err(c, "state", "{s:s, s:i}", "cmd", "hello", "version", 1));
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));

	/* The Unix socket speaks the same protocol. */
	dm_conn *u = dm_connect_unix(d);
	r = dm_ok(u, "{s:s, s:i}", "cmd", "hello", "version", 1);
	check_hello_reply(r);
	json_decref(r);
	r = dm_ok(u, "{s:s}", "cmd", "status");
	json_decref(r);
	dm_pass();
}

static void test_request_before_hello_is_auth_required(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *other = dm_open(d, NULL);

	dm_conn *c = dm_connect_tcp(d);
	json_decref(dm_err(c, "auth_required", "{s:s}", "cmd", "status"));
	if (!dm_wait_closed(c, 10000))
		fail_msg("connection still open after auth_required");

	/* Same on the Unix socket, with a command that takes arguments. */
	dm_conn *u = dm_connect_unix(d);
	json_decref(dm_err(u, "auth_required", "{s:s, s:i}", "cmd", "job.info",
	                   "job", 1));
	if (!dm_wait_closed(u, 10000))
		fail_msg("unix connection still open after auth_required");

	json_decref(dm_ok(other, "{s:s}", "cmd", "status"));
	dm_pass();
}

static void test_unsupported_version_is_refused(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *other = dm_open(d, NULL);

	dm_conn *c = dm_connect_tcp(d);
	json_decref(dm_err(c, "version", "{s:s, s:i}", "cmd", "hello",
	                   "version", 2));
	if (!dm_wait_closed(c, 10000))
		fail_msg("connection still open after a version error");

	c = dm_connect_tcp(d);
	json_decref(dm_err(c, "version", "{s:s, s:i}", "cmd", "hello",
	                   "version", 0));
	assert_true(dm_wait_closed(c, 10000));

	json_decref(dm_ok(other, "{s:s}", "cmd", "status"));
	dm_pass();
}

/* Write a token file in the daemon's parent directory; returns its path. */
static const char *write_token(const char *secret, char *path, size_t len)
{
	char dir[] = "/tmp/luxradd-token-XXXXXX";
	if (!mkdtemp(dir))
		fail_msg("mkdtemp");
	snprintf(path, len, "%s/token", dir);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fprintf(f, "%s\n", secret);
	fclose(f);
	return path;
}

static void test_token_required_refuses_missing_and_wrong(void **state)
{
	(void)state;
	char tok[300];
	write_token("s3cret-Token-42", tok, sizeof(tok));
	const char *args[] = {"--token-file", tok, "--require-token", NULL};
	dm_daemon *d = dm_start(args);

	dm_conn *good = dm_open(d, "s3cret-Token-42");
	json_decref(dm_ok(good, "{s:s}", "cmd", "status"));

	dm_conn *c = dm_connect_tcp(d);
	json_decref(dm_err(c, "auth_failed", "{s:s, s:i}", "cmd", "hello",
	                   "version", 1));
	if (!dm_wait_closed(c, 10000))
		fail_msg("open after hello without token");

	c = dm_connect_tcp(d);
	json_decref(dm_err(c, "auth_failed", "{s:s, s:i, s:s}", "cmd", "hello",
	                   "version", 1, "token", "s3cret-Token-43"));
	if (!dm_wait_closed(c, 10000))
		fail_msg("open after a wrong token");

	/* A prefix of the token is wrong too. */
	c = dm_connect_unix(d);
	json_decref(dm_err(c, "auth_failed", "{s:s, s:i, s:s}", "cmd", "hello",
	                   "version", 1, "token", "s3cret"));
	if (!dm_wait_closed(c, 10000))
		fail_msg("open after a token prefix (unix)");

	/* A request instead of hello is still auth_required. */
	c = dm_connect_tcp(d);
	json_decref(dm_err(c, "auth_required", "{s:s}", "cmd", "scene.list"));
	assert_true(dm_wait_closed(c, 10000));

	/* The right token works on both transports, the first session too. */
	dm_conn *u = dm_connect_unix(d);
	json_decref(dm_ok(u, "{s:s, s:i, s:s}", "cmd", "hello", "version", 1,
	                  "token", "s3cret-Token-42"));
	json_decref(dm_ok(u, "{s:s}", "cmd", "scene.list"));
	json_decref(dm_ok(good, "{s:s}", "cmd", "status"));
	dm_pass();
	unlink(tok);
	*strrchr(tok, '/') = 0;
	rmdir(tok);
}

static void test_status_has_documented_members(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	dm_conn *c2 = dm_open(d, NULL);
	(void)c2;
	json_t *r = dm_ok(c, "{s:s}", "cmd", "status");
	static const char *const top[] = {"version",  "uptime_s", "connections",
	                                  "jobs",     "memory",   "scenes",
	                                  "job_list", "limits",   NULL};
	dm_require_keys(r, "status", top);
	assert_int_equal(dm_int(r, "version"), 1);
	assert_true(dm_int(r, "connections") >= 2);
	assert_true(dm_num(r, "uptime_s") >= 0);
	static const char *const states[] = {"queued", "running", "paused",
	                                     "done",   "failed",  "cancelled",
	                                     NULL};
	dm_require_keys(dm_get(r, "jobs"), "status.jobs", states);
	json_t *m = dm_get(r, "memory");
	static const char *const mk[] = {"total_bytes", "by_kind",
	                                 "scenes_bytes", "jobs_bytes", NULL};
	dm_require_keys(m, "status.memory", mk);
	dm_require_keys(dm_get(m, "by_kind"), "status.memory.by_kind",
	                dm_mem_kinds);
	/* The report is the exact sum of its kinds. */
	long long sum = 0;
	for (size_t i = 0; dm_mem_kinds[i]; i++)
		sum += dm_int(dm_get(m, "by_kind"), dm_mem_kinds[i]);
	assert_int_equal(sum, dm_int(m, "total_bytes"));
	assert_int_equal(dm_int(m, "scenes_bytes") + dm_int(m, "jobs_bytes"),
	                 dm_int(m, "total_bytes"));
	assert_true(json_is_array(dm_get(r, "job_list")));
	assert_true(json_is_array(dm_get(r, "scenes")));
	json_decref(r);
	dm_pass();
}

static void test_too_many_connections_affects_only_the_extra(void **state)
{
	(void)state;
	const char *args[] = {"--max-connections", "2", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *a = dm_open(d, NULL);
	dm_conn *b = dm_open(d, NULL);

	dm_conn *c = dm_connect_tcp(d);
	/* The daemon may answer before or after reading hello. */
	json_t *h = json_pack("{s:s, s:i, s:i}", "cmd", "hello", "version", 1,
	                      "id", 1);
	dm_send_frame(c, h, NULL, 0);
	json_decref(h);
	json_t *f = NULL;
	if (dm_recv(c, DM_REPLY_MS, &f, NULL, NULL) != 1)
		fail_msg("no too_many_connections error for the third "
		         "connection");
	assert_string_equal(dm_err_code(f), "too_many_connections");
	json_decref(f);
	if (!dm_wait_closed(c, 10000))
		fail_msg("the connection over the limit stays open");
	dm_close(c);

	json_decref(dm_ok(a, "{s:s}", "cmd", "status"));
	json_decref(dm_ok(b, "{s:s}", "cmd", "scene.list"));

	/* Free a slot: a new connection gets in (the daemon may need a
	 * moment to notice the close). */
	dm_close(a);
	dm_conn *n = dm_open_when_free(d, NULL, 10000);
	if (!n)
		fail_msg("a freed connection slot is not reusable");
	json_decref(dm_ok(n, "{s:s}", "cmd", "status"));
	json_decref(dm_ok(b, "{s:s}", "cmd", "status"));
	dm_pass();
}

static void test_idle_timeout_closes_only_silent_connections(void **state)
{
	(void)state;
	const char *args[] = {"--idle-timeout", "1", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *busy = dm_open(d, NULL);
	dm_conn *idle = dm_open(d, NULL);
	dm_conn *never = dm_connect_tcp(d); /* not even a hello */

	double t0 = dm_now_ms();
	int idle_closed = 0, never_closed = 0;
	double idle_at = 0;
	while (dm_now_ms() - t0 < 15000 && !(idle_closed && never_closed)) {
		json_decref(dm_ok(busy, "{s:s}", "cmd", "status"));
		if (!idle_closed && dm_wait_closed(idle, 250)) {
			idle_closed = 1;
			idle_at = dm_now_ms() - t0;
		}
		if (!never_closed && dm_wait_closed(never, 50))
			never_closed = 1;
	}
	if (!idle_closed)
		fail_msg("an idle connection was not closed 15 s after a 1 s "
		         "idle timeout");
	if (!never_closed)
		fail_msg("a connection that never said hello was not closed "
		         "by the idle timeout");
	if (idle_at < 500)
		fail_msg("the idle connection was closed after %.0f ms, "
		         "before its 1 s timeout",
		         idle_at);
	const char *code = dm_unsolicited_error(idle);
	if (!code || strcmp(code, "idle_timeout") != 0)
		fail_msg("the idle connection was closed without an "
		         "idle_timeout error (got %s)",
		         code ? code : "nothing");
	/* The active one is alive after several timeouts' worth of time. */
	json_decref(dm_ok(busy, "{s:s}", "cmd", "status"));
	dm_pass();
}

/* A metric family is present: its "# TYPE" line and at least a sample. */
static void require_family(const char *body, const char *name)
{
	char type[256];
	snprintf(type, sizeof(type), "# TYPE %s ", name);
	if (!strstr(body, type))
		fail_msg("/metrics: no \"# TYPE %s\" line", name);
	/* A sample line starts with the name at the beginning of a line. */
	const char *p = body;
	size_t n = strlen(name);
	for (;;) {
		if (!strncmp(p, name, n) && (p[n] == ' ' || p[n] == '{' ||
		                             !strncmp(p + n, "_bucket", 7) ||
		                             !strncmp(p + n, "_sum", 4) ||
		                             !strncmp(p + n, "_count", 6)))
			return;
		p = strchr(p, '\n');
		if (!p)
			break;
		p++;
	}
	fail_msg("/metrics: family %s has no sample", name);
}

/*
 * The families luxradd serves (daemon/server/cmd/metrics.c; PROTOCOL.md
 * leaves /metrics out of the protocol).
 */
static const char *const families[] = {
        "luxradd_uptime_seconds",
        "luxradd_connections",
        "luxradd_scenes",
        "luxradd_jobs",
        "luxradd_memory_bytes",
        "luxradd_events_dropped_total",
        "luxradd_commands_total",
        "luxradd_job_iteration",
        NULL,
};

/* The value of the sample "series" (name with labels); fails if absent. */
static void test_metrics_serves_prometheus_text(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("cornell.gltf", path, sizeof(path)), "cornell");
	json_t *job = dm_job_create(c, sc, "hr", NULL);
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", 1));
	json_decref(dm_wait_job(c, job, "paused", 60000));
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");

	char *headers = NULL, *body = NULL;
	int code = dm_http_get(d, "/metrics", &headers, &body);
	if (code != 200)
		fail_msg("GET /metrics: status %d\n%s", code, headers);
	if (!strcasestr(headers, "content-type: text/plain"))
		fail_msg("GET /metrics: not text/plain:\n%s", headers);
	for (size_t i = 0; families[i]; i++)
		require_family(body, families[i]);
	/* The samples agree with status. */
	assert_true(dm_metrics_sample(body, "luxradd_scenes") == 1);
	assert_true(dm_metrics_sample(body, "luxradd_connections") >= 1);
	assert_true(dm_metrics_sample(body, "luxradd_jobs{state=\"paused\"}") ==
	            1);
	assert_true(dm_metrics_sample(body, "luxradd_jobs{state=\"done\"}") ==
	            0);
	char series[128];
	snprintf(series, sizeof(series), "luxradd_job_iteration{job=\"%lld\"}",
	         (long long)json_integer_value(job));
	assert_true(dm_metrics_sample(body, series) == 1);
	double total = 0;
	for (int k = 0; dm_mem_kinds[k]; k++) {
		snprintf(series, sizeof(series),
		         "luxradd_memory_bytes{kind=\"%s\"}", dm_mem_kinds[k]);
		total += dm_metrics_sample(body, series);
	}
	assert_true(total ==
	            (double)dm_int(dm_get(st, "memory"), "total_bytes"));
	assert_true(dm_metrics_sample(
	                    body, "luxradd_commands_total{cmd=\"job.run\"}") ==
	            1);
	/* Every non-comment line is "name[{labels}] value". */
	char *save = NULL;
	for (char *line = strtok_r(body, "\n", &save); line;
	     line = strtok_r(NULL, "\n", &save)) {
		if (line[0] == '#' || line[0] == 0)
			continue;
		char *sp = strrchr(line, ' ');
		if (!sp)
			fail_msg("/metrics: malformed line \"%s\"", line);
		char *end = NULL;
		strtod(sp + 1, &end);
		if (end == sp + 1 || (*end && *end != '\r'))
			fail_msg("/metrics: value not a number in \"%s\"",
			         line);
	}
	free(headers);
	free(body);
	json_decref(st);

	code = dm_http_get(d, "/nope", &headers, &body);
	if (code != 404)
		fail_msg("GET /nope: status %d, want 404", code);
	free(headers);
	free(body);
	code = dm_http_get(d, "/", NULL, &body);
	assert_int_equal(code, 404);
	free(body);
	code = dm_http_get(d, "/metricsx", NULL, &body);
	assert_int_equal(code, 404);
	free(body);
	/* The protocol listener is still fine. */
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

static void test_shutdown_command_stops_the_daemon(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *a = dm_open(d, NULL);
	dm_conn *b = dm_open(d, NULL);
	json_decref(dm_ok(a, "{s:s}", "cmd", "shutdown"));
	/* b's later request gets shutting_down or finds the door closed. */
	json_t *r = dm_call_maybe(b, 10000, "{s:s}", "cmd", "status");
	if (r && strcmp(dm_err_code(r), "shutting_down") != 0 &&
	    strcmp(dm_err_code(r), "") != 0)
		fail_msg("request during shutdown: error %s", dm_err_code(r));
	json_decref(r);
	if (!dm_wait_exit(d, DM_EXIT_MS))
		fail_msg("luxradd still running %d ms after shutdown",
		         DM_EXIT_MS);
	assert_true(WIFEXITED(d->status));
	assert_int_equal(WEXITSTATUS(d->status), 0);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_hello_reports_version_capabilities_and_limits),
	        T(test_request_before_hello_is_auth_required),
	        T(test_unsupported_version_is_refused),
	        T(test_token_required_refuses_missing_and_wrong),
	        T(test_status_has_documented_members),
	        T(test_too_many_connections_affects_only_the_extra),
	        T(test_idle_timeout_closes_only_silent_connections),
	        T(test_metrics_serves_prometheus_text),
	        T(test_shutdown_command_stops_the_daemon),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
