/*
 * test_daemon_badinput.c -- malformed frames and requests against a real
 * luxradd, while a second client's job runs (PROTOCOL.md, rp.h LIMITS):
 *  - garbage bytes, invalid JSON, non-object JSON, a bad "bytes": each gets
 *    bad_frame and the connection closes;
 *  - a header longer than max_header_bytes with no newline gets too_large
 *    as soon as the limit is passed; a payload over max_scene_bytes
 *    announced (and never sent) gets too_large at once; both close;
 *  - a truncated header or payload followed by a close is forgotten;
 *  - unknown commands, missing and ill-typed arguments, unknown ids, bad
 *    options and a malformed scene get their documented errors (with a
 *    message) and the connection stays usable;
 *  - throughout, the other client's job keeps running, its queries are
 *    answered, its iteration events arrive in order and it ends done;
 *  - names chosen to forge a log line, drive a terminal or reorder text are
 *    written to the log escaped (test_names_are_escaped_in_the_log).
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>

#include <cmocka.h>

#include "harness.h"

#define MAX_HEADER 4096

/* The other client: a job running on a scene big enough to last. */
typedef struct bystander {
	dm_conn *c;
	json_t *scene, *job;
	long long last_iteration; /* last iteration event seen */
	int done;
	int checks;
} bystander;

static const double probe[3 * 6] = {
        6, 0.8, 4, 0, 1, 0, 12, 0.8, 8, 0, 1, 0, 18, 0.01, 12, 0, 1, 0,
};

static void bystander_start(bystander *b, const dm_daemon *d)
{
	char path[512];
	b->c = dm_open(d, NULL);
	b->scene = dm_upload_file(
	        b->c,
	        dm_gen_scene("hall-full.glb", "hall-full", path, sizeof(path)),
	        "hall");
	json_t *opt = json_pack("{s:i, s:f, s:i}", "threads", 1, "tol", 1e-4,
	                        "max_iterations", 10);
	b->job = dm_job_create(b->c, b->scene, "hr", opt);
	json_decref(opt);
	json_decref(
	        dm_ok(b->c, "{s:s, s:O}", "cmd", "subscribe", "job", b->job));
	json_decref(dm_ok(b->c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
	                  b->job, "converge", 1));
}

/* Drain the bystander's events; check iteration order. */
static void bystander_events(bystander *b, int wait_ms)
{
	json_t *e;
	while ((e = dm_event(b->c, wait_ms)) != NULL) {
		wait_ms = 0;
		const char *kind =
		        json_string_value(json_object_get(e, "event"));
		if (kind && !strcmp(kind, "iteration")) {
			long long it = dm_int(dm_get(e, "stats"), "iteration");
			if (it != b->last_iteration + 1)
				fail_msg(
				        "bystander: iteration event %lld after "
				        "%lld",
				        it, b->last_iteration);
			b->last_iteration = it;
		} else if (kind && !strcmp(kind, "state")) {
			const char *s =
			        json_string_value(json_object_get(e, "state"));
			if (s &&
			    (!strcmp(s, "failed") || !strcmp(s, "cancelled")))
				fail_msg("bystander's job went %s", s);
			if (s && !strcmp(s, "done"))
				b->done = 1;
		}
		json_decref(e);
	}
}

/* The bystander is undisturbed: status, job.info and (once there is a
 * solution) query.points answer, and the connection is open. */
static void bystander_check(bystander *b)
{
	json_decref(dm_ok(b->c, "{s:s}", "cmd", "status"));
	json_t *r = dm_ok(b->c, "{s:s, s:O}", "cmd", "job.info", "job", b->job);
	const char *s = json_string_value(
	        json_object_get(json_object_get(r, "job"), "state"));
	if (!s || !strcmp(s, "failed") || !strcmp(s, "cancelled"))
		fail_msg("bystander's job is %s", s ? s : "?");
	json_decref(r);
	bystander_events(b, 0);
	if (b->last_iteration >= 1) {
		double lux[3];
		dm_query_points(b->c, b->job, probe, 3, lux);
		for (int i = 0; i < 3; i++)
			assert_true(lux[i] >= 0);
	}
	b->checks++;
}

static void bystander_finish(bystander *b)
{
	double end = dm_now_ms() + 150000;
	while (!b->done && dm_now_ms() < end)
		bystander_events(b, 1000);
	if (!b->done)
		fail_msg("bystander's job not done (last iteration %lld)",
		         b->last_iteration);
	json_t *j = dm_wait_job(b->c, b->job, "done", 10000);
	assert_int_equal(dm_int(j, "iteration"), b->last_iteration);
	json_decref(j);
	json_decref(b->scene);
	json_decref(b->job);
}

/* The next non-event frame must be an error with this code, then the
 * daemon must close the connection. */
static void expect_error_and_close(dm_conn *c, const char *code,
                                   const char *what)
{
	json_t *f = NULL;
	double end = dm_now_ms() + DM_REPLY_MS;
	for (;;) {
		int left = (int)(end - dm_now_ms());
		int r = dm_recv(c, left > 0 ? left : 0, &f, NULL, NULL);
		if (r == 0)
			fail_msg("%s: no %s error within %d ms", what, code,
			         DM_REPLY_MS);
		if (r < 0)
			fail_msg("%s: connection closed without a %s error",
			         what, code);
		if (!json_object_get(f, "event"))
			break;
		json_decref(f);
	}
	if (strcmp(dm_err_code(f), code) != 0) {
		char *s = json_dumps(f, JSON_COMPACT);
		fail_msg("%s: wanted error %s, got %s", what, code, s);
	}
	json_t *m = json_object_get(json_object_get(f, "error"), "message");
	if (!json_is_string(m) || !json_string_length(m))
		fail_msg("%s: error %s without a message", what, code);
	json_decref(f);
	if (!dm_wait_closed(c, 10000))
		fail_msg("%s: connection still open after %s", what, code);
	dm_close(c);
}

/* Send raw bytes on a fresh connection (after hello if hello is set). */
static dm_conn *raw(const dm_daemon *d, int hello, const void *bytes,
                    size_t len)
{
	dm_conn *c = hello ? dm_open(d, NULL) : dm_connect_tcp(d);
	dm_send_raw(c, bytes, len);
	return c;
}

#define RAW(d, hello, s) raw(d, hello, s, sizeof(s) - 1)

static void test_bad_frames_close_only_their_connection(void **state)
{
	(void)state;
	const char *args[] = {"--max-header-bytes", "4096", "--max-scene-bytes",
	                      "4000000", NULL};
	dm_daemon *d = dm_start(args);
	bystander b = {0};
	bystander_start(&b, d);

	expect_error_and_close(RAW(d, 1, "\x01\x02\xfe\xff garbage \x7f\n"),
	                       "bad_frame", "garbage bytes");
	bystander_check(&b);
	expect_error_and_close(RAW(d, 0, "GET / HTTP/1.1\r\n\r\n"), "bad_frame",
	                       "garbage before hello");
	bystander_check(&b);
	expect_error_and_close(RAW(d, 1, "{cmd: status}\n"), "bad_frame",
	                       "invalid JSON");
	expect_error_and_close(RAW(d, 1, "[1, 2, 3]\n"), "bad_frame",
	                       "JSON array header");
	expect_error_and_close(RAW(d, 1, "\"status\"\n"), "bad_frame",
	                       "JSON string header");
	expect_error_and_close(RAW(d, 1, "42\n"), "bad_frame",
	                       "JSON number header");
	bystander_check(&b);
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":-1}\n"),
	        "bad_frame", "negative bytes");
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":\"12\"}\n"),
	        "bad_frame", "string bytes");
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":1.5}\n"),
	        "bad_frame", "fractional bytes");
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":1e3}\n"),
	        "bad_frame", "bytes written 1e3");
	expect_error_and_close(RAW(d, 1, "\n"), "bad_frame", "empty line");
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"status\",\"cmd\":\"status\"}\n"),
	        "bad_frame", "duplicate member");
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"status\",\"x\":\"a\\u0000b\"}\n"),
	        "bad_frame", "\\u0000 in a string");
	expect_error_and_close(RAW(d, 1, "{\"cmd\":\"st\xc3\x28tus\"}\n"),
	                       "bad_frame", "invalid UTF-8");
	bystander_check(&b);
	bystander_finish(&b);
	dm_pass();
}

static void test_oversized_header_and_payload_are_too_large(void **state)
{
	(void)state;
	const char *args[] = {"--max-header-bytes", "4096", "--max-scene-bytes",
	                      "4000000", NULL};
	dm_daemon *d = dm_start(args);
	bystander b = {0};
	bystander_start(&b, d);

	/* Twice the limit, no newline: the daemon cannot wait for one. */
	char *big = malloc(2 * MAX_HEADER);
	memset(big, 'a', 2 * MAX_HEADER);
	big[0] = '{';
	expect_error_and_close(raw(d, 1, big, 2 * MAX_HEADER), "too_large",
	                       "8 KiB header, no newline, limit 4 KiB");
	bystander_check(&b);
	/* Same before hello. */
	expect_error_and_close(raw(d, 0, big, 2 * MAX_HEADER), "too_large",
	                       "oversized header before hello");
	/* A long but valid JSON header (a string member) over the limit,
	 * with its newline. */
	char *hdr = malloc(3 * MAX_HEADER);
	int n = snprintf(hdr, 3 * MAX_HEADER, "{\"cmd\":\"status\",\"pad\":\"");
	memset(hdr + n, 'x', 2 * MAX_HEADER);
	memcpy(hdr + n + 2 * MAX_HEADER, "\"}\n", 3);
	expect_error_and_close(raw(d, 1, hdr, (size_t)n + 2 * MAX_HEADER + 3),
	                       "too_large", "oversized JSON header");
	free(hdr);
	free(big);
	bystander_check(&b);

	/* A payload over max_scene_bytes announced; we never send it. */
	expect_error_and_close(
	        RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":4000001}\n"),
	        "too_large", "payload of max_scene_bytes + 1 announced");
	expect_error_and_close(
	        RAW(d, 1,
	            "{\"cmd\":\"scene.upload\",\"bytes\":1000000000000}\n"),
	        "too_large", "1 TB payload announced");
	bystander_check(&b);

	/* Just under the limits is fine: a header of max - 100 bytes. */
	dm_conn *c = dm_open(d, NULL);
	char *ok = malloc(MAX_HEADER);
	n = snprintf(ok, MAX_HEADER, "{\"cmd\":\"status\",\"id\":7,\"pad\":\"");
	memset(ok + n, 'y', (size_t)(MAX_HEADER - 100 - n));
	memcpy(ok + MAX_HEADER - 100, "\"}\n", 3);
	dm_send_raw(c, ok, MAX_HEADER - 97);
	free(ok);
	json_t *f = NULL;
	assert_int_equal(dm_recv(c, DM_REPLY_MS, &f, NULL, NULL), 1);
	assert_string_equal(dm_err_code(f), "");
	assert_int_equal(json_integer_value(json_object_get(f, "id")), 7);
	json_decref(f);
	bystander_finish(&b);
	dm_pass();
}

static void test_truncated_frames_then_close_are_forgotten(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	bystander b = {0};
	bystander_start(&b, d);

	dm_close(RAW(d, 1, "{\"cmd\":\"status\""));
	dm_close(RAW(d, 0, "{\"cmd\":\"hel"));
	/* A payload announced, a tenth of it sent. */
	dm_conn *c = RAW(d, 1, "{\"cmd\":\"scene.upload\",\"bytes\":1000}\n");
	char part[100];
	memset(part, 'g', sizeof(part));
	dm_send_raw(c, part, sizeof(part));
	dm_close(c);
	/* Half a request and a shutdown of our side only. */
	c = RAW(d, 1, "{\"cmd\":\"job.list\",");
	shutdown(c->fd, SHUT_WR);
	if (!dm_wait_closed(c, 10000))
		fail_msg("the daemon keeps a half-closed connection with a "
		         "truncated frame open");
	dm_close(c);
	bystander_check(&b);
	/* Several at once, then the daemon still accepts connections. */
	for (int i = 0; i < 20; i++)
		dm_close(RAW(d, i & 1, "{\"cmd\":\"sta"));
	dm_conn *n = dm_open(d, NULL);
	json_t *r = dm_ok(n, "{s:s}", "cmd", "status");
	json_decref(r);
	bystander_check(&b);
	bystander_finish(&b);
	dm_pass();
}

static void test_bad_requests_get_errors_and_keep_the_session(void **state)
{
	(void)state;
	const char *args[] = {"--max-points", "100", NULL};
	dm_daemon *d = dm_start(args);
	bystander b = {0};
	bystander_start(&b, d);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("cornell.gltf", path, sizeof(path)), "cornell");
	json_t *job = dm_job_create(c, sc, "hr", NULL);

#define E(code, ...) json_decref(dm_err(c, code, __VA_ARGS__))
	E("unknown_command", "{s:s}", "cmd", "frobnicate");
	E("unknown_command", "{s:s}", "cmd", "job.explode");
	bystander_check(&b);

	/* No cmd, or not a string. */
	E("bad_request", "{s:i}", "x", 1);
	E("bad_request", "{s:i}", "cmd", 5);
	E("bad_request", "{s:n}", "cmd");

	/* Missing and ill-typed arguments ("null" is a wrong type). */
	E("bad_request", "{s:s, s:n}", "cmd", "job.info", "job");
	E("bad_request", "{s:s, s:f}", "cmd", "job.info", "job", 1.5);
	E("bad_request", "{s:s, s:s}", "cmd", "job.info", "job", "1");
	E("bad_request", "{s:s}", "cmd", "job.info");
	E("bad_request", "{s:s, s:[i]}", "cmd", "job.info", "job", 1);
	E("bad_request", "{s:s, s:b}", "cmd", "job.info", "job", 1);
	E("bad_request", "{s:s, s:{}}", "cmd", "scene.info", "scene");
	E("bad_request", "{s:s}", "cmd", "scene.delete");
	E("bad_request", "{s:s}", "cmd", "job.create");
	E("bad_request", "{s:s, s:O, s:i}", "cmd", "job.create", "scene", sc,
	  "solver", 42);
	E("bad_request", "{s:s, s:O, s:s}", "cmd", "job.create", "scene", sc,
	  "options", "fast");
	E("bad_request", "{s:s}", "cmd", "job.run");
	E("bad_request", "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	  "iterations", -3);
	E("bad_request", "{s:s, s:O, s:s}", "cmd", "job.run", "job", job,
	  "iterations", "3");
	E("bad_request", "{s:s, s:O, s:s}", "cmd", "job.run", "job", job,
	  "seconds", "long");
	E("bad_request", "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	  "iterations", 0);
	E("bad_request", "{s:s, s:O, s:f}", "cmd", "job.run", "job", job,
	  "seconds", -1.0);
	E("bad_request", "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	  "converge", 0);
	E("bad_request", "{s:s, s:O, s:i, s:b}", "cmd", "job.run", "job", job,
	  "iterations", 2, "converge", 1);
	E("bad_request", "{s:s, s:O, s:i, s:f}", "cmd", "job.run", "job", job,
	  "iterations", 2, "seconds", 1.0);
	E("bad_request", "{s:s, s:O, s:s}", "cmd", "job.set", "job", job, "eps",
	  "small");
	E("bad_request", "{s:s, s:O}", "cmd", "job.set", "job", job);
	E("bad_request", "{s:s}", "cmd", "subscribe");
	E("bad_request", "{s:s, s:s}", "cmd", "subscribe", "job", "all");
	bystander_check(&b);
	E("bad_request", "{s:s}", "cmd", "query.surfaces");
	E("bad_request", "{s:s}", "cmd", "export");
	/* scene.upload without its payload. */
	E("bad_request", "{s:s, s:s}", "cmd", "scene.upload", "name", "x");
	bystander_check(&b);

	/* Unknown ids. */
	E("not_found", "{s:s, s:i}", "cmd", "job.info", "job", 987654);
	E("not_found", "{s:s, s:i}", "cmd", "scene.info", "scene", 987654);
	E("not_found", "{s:s, s:i}", "cmd", "job.create", "scene", 987654);
	E("not_found", "{s:s, s:i, s:[[i,i,i,i,i,i]]}", "cmd", "query.points",
	  "job", 987654, "points", 0, 0, 0, 0, 1, 0);
	E("not_found", "{s:s, s:i}", "cmd", "subscribe", "job", 987654);

	/* Refused options: invalid, with a message naming the option. */
	json_t *r = dm_err(c, "invalid", "{s:s, s:O, s:{s:f}}", "cmd",
	                   "job.create", "scene", sc, "options", "eps", -1.0);
	const char *m = json_string_value(
	        json_object_get(json_object_get(r, "error"), "message"));
	if (!strstr(m, "eps"))
		fail_msg("invalid eps: message \"%s\" does not name eps", m);
	json_decref(r);
	E("invalid", "{s:s, s:O, s:s}", "cmd", "job.create", "scene", sc,
	  "solver", "magic");
	/* A misspelt option must not pass silently. */
	r = dm_err(c, "invalid", "{s:s, s:O, s:{s:f}}", "cmd", "job.create",
	           "scene", sc, "options", "epsilon", 1e-3);
	m = json_string_value(
	        json_object_get(json_object_get(r, "error"), "message"));
	if (!strstr(m, "epsilon"))
		fail_msg("unknown option: message \"%s\" does not name it", m);
	json_decref(r);
	E("invalid", "{s:s, s:O, s:{s:f}}", "cmd", "job.create", "scene", sc,
	  "options", "tol", 2.0);
	E("bad_request", "{s:s, s:O, s:{s:s}}", "cmd", "job.create", "scene",
	  sc, "options", "eps", "small");
	E("invalid", "{s:s, s:O, s:f}", "cmd", "job.set", "job", job, "eps",
	  0.0);
	r = dm_err(c, "invalid", "{s:s, s:O, s:{s:i}}", "cmd", "job.create",
	           "scene", sc, "options", "rcv_samples", 99);
	m = json_string_value(
	        json_object_get(json_object_get(r, "error"), "message"));
	if (!strstr(m, "rcv_samples"))
		fail_msg("invalid rcv_samples: message \"%s\" does not name it",
		         m);
	json_decref(r);
	r = dm_err(c, "invalid", "{s:s, s:O, s:{s:s}}", "cmd", "job.create",
	           "scene", sc, "options", "oracle", "crystal-ball");
	json_decref(r);

	/* State: no solution before the first step. */
	E("state", "{s:s, s:O, s:[[f,f,f,i,i,i]]}", "cmd", "query.points",
	  "job", job, "points", 0.2, 0.01, 0.2, 0, 1, 0);
	E("state", "{s:s, s:O}", "cmd", "query.surfaces", "job", job);
	E("state", "{s:s, s:O}", "cmd", "export", "job", job);
	E("state", "{s:s, s:O}", "cmd", "job.resume", "job", job);

	/* A malformed scene: invalid, session kept. */
	static const char junk[] = "{\"asset\": {\"version\": \"2.0\"}, "
	                           "\"meshes\": [{\"primitives\": 7}]}";
	r = dm_call_payload(c, junk, sizeof(junk) - 1, "{s:s, s:s}", "cmd",
	                    "scene.upload", "name", "junk");
	assert_string_equal(dm_err_code(r), "invalid");
	json_decref(r);
	static const char bin[] = "glTF\x02\x00\x00\x00\xff\xff\xff\x7f";
	r = dm_call_payload(c, bin, sizeof(bin) - 1, "{s:s, s:s}", "cmd",
	                    "scene.upload", "name", "bad-glb");
	assert_string_equal(dm_err_code(r), "invalid");
	json_decref(r);
	bystander_check(&b);

	/* The session is intact: the good job runs. */
	json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job", job,
	                  "iterations", 2));
	json_t *j = dm_wait_job(c, job, "paused|done", 60000);
	assert_int_equal(dm_int(j, "iteration"), 2);
	json_decref(j);
	E("bad_request", "{s:s, s:O, s:[f,f,f], s:[f,f,f], s:[f,f,f], s:f}",
	  "cmd", "query.grid", "job", job, "origin", 0.0, 0.01, 0.0, "u", 0.5,
	  0.0, 0.0, "v", 0.0, 0.0, 0.5, "spacing", 0.01); /* 2500 points */
	/* Argument errors of queries, on a job with a solution. */
	E("bad_request", "{s:s, s:O}", "cmd", "query.points", "job", job);
	E("bad_request", "{s:s, s:O, s:s}", "cmd", "query.points", "job", job,
	  "points", "here");
	E("bad_request", "{s:s, s:O, s:[[i,i,i]]}", "cmd", "query.points",
	  "job", job, "points", 1, 2, 3);
	E("bad_request", "{s:s, s:O, s:[[f,f,f,i,i,i]]}", "cmd", "query.points",
	  "job", job, "points", 0.2, 0.2, 0.2, 0, 0, 0);
	E("bad_request", "{s:s, s:O, s:[[f,f,s,i,i,i]]}", "cmd", "query.points",
	  "job", job, "points", 0.2, 0.2, "z", 0, 1, 0);
	E("bad_request", "{s:s, s:O, s:[i,i], s:[i,i,i], s:[i,i,i]}", "cmd",
	  "query.grid", "job", job, "origin", 0, 0, "u", 1, 0, 0, "v", 0, 0, 1);
	E("bad_request", "{s:s, s:O, s:[i,i,i], s:[i,i,i]}", "cmd",
	  "query.grid", "job", job, "origin", 0, 0, 0, "u", 1, 0, 0);
	E("bad_request", "{s:s, s:O, s:[]}", "cmd", "query.points", "job", job,
	  "points");
	E("bad_request", "{s:s, s:O, s:[i,i,i], s:[i,i,i], s:[i,i,i]}", "cmd",
	  "query.grid", "job", job, "origin", 0, 0, 0, "u", 1, 0, 0, "v", 2, 0,
	  0); /* u parallel to v */
	E("bad_request", "{s:s, s:O, s:[i,i,i], s:[i,i,i], s:[i,i,i]}", "cmd",
	  "query.grid", "job", job, "origin", 0, 0, 0, "u", 0, 0, 0, "v", 0, 0,
	  1); /* zero u */
	E("bad_request", "{s:s, s:O, s:[i,i,i], s:[i,i,i], s:[i,i,i], s:f}",
	  "cmd", "query.grid", "job", job, "origin", 0, 0, 0, "u", 1, 0, 0, "v",
	  0, 0, 1, "spacing", 0.0);
	E("bad_request",
	  "{s:s, s:O, s:[i,i,i], s:[i,i,i], s:[i,i,i], s:[i,i,i]}", "cmd",
	  "query.grid", "job", job, "origin", 0, 0, 0, "u", 1, 0, 0, "v", 0, 0,
	  1, "normal", 0, 0, 0);
	/* max_points (100 here): one more is refused, grid points too. */
	json_t *many = json_array();
	for (int i = 0; i < 101; i++)
		json_array_append_new(many, json_pack("[f,f,f,i,i,i]", 0.2,
		                                      0.01, 0.2, 0, 1, 0));
	E("bad_request", "{s:s, s:O, s:O}", "cmd", "query.points", "job", job,
	  "points", many);
	json_decref(many);
	E("invalid", "{s:s, s:O, s:s}", "cmd", "export", "job", job, "format",
	  "obj");
	E("state", "{s:s, s:i}", "cmd", "hello", "version", 1);
	json_decref(dm_ok(c, "{s:s, s:O, s:[[f,f,f,i,i,i]]}", "cmd",
	                  "query.points", "job", job, "points", 0.2, 0.01, 0.2,
	                  0, 1, 0));
#undef E
	json_decref(sc);
	json_decref(job);
	bystander_finish(&b);
	dm_pass();
}

/*
 * A scene and a job named to forge a log line (a newline, then a line of
 * the log's own form), clear the terminal (ESC [2J), open a C1 control
 * sequence (U+009B), reverse what follows (U+202E) and fake an escape (a
 * literal backslash-x0a).  The log stays one line per message, each
 * starting with the daemon's timestamp, with no control byte but the
 * newlines that end lines and no hidden code point; the names appear
 * escaped.  Before names were escaped, the forged line stood in the log
 * as a line of its own.
 */
static void test_names_are_escaped_in_the_log(void **state)
{
	(void)state;
	static const char evil[] = "lobby\n2030-01-01T00:00:00.000Z ERROR "
	                           "forged\x1b[2J\xc2\x9b"
	                           "31m\xe2\x80\xae"
	                           "tpircs\\x0a";
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char path[512];
	json_t *sc = dm_upload_file(
	        c, dm_sample("cornell.gltf", path, sizeof(path)), evil);
	json_t *r = dm_ok(c, "{s:s, s:O, s:s}", "cmd", "job.create", "scene",
	                  sc, "name", evil);
	json_decref(r);
	/* The same names come back unchanged over the protocol. */
	r = dm_ok(c, "{s:s}", "cmd", "scene.list");
	json_t *first = json_array_get(json_object_get(r, "scenes"), 0);
	assert_string_equal(json_string_value(json_object_get(first, "name")),
	                    evil);
	json_decref(r);
	dm_stop(d);

	size_t n;
	unsigned char *log = dm_read_file(d->log_path, &n);
	int lines = 0;
	for (size_t i = 0; i < n; i++) {
		if ((i == 0 || log[i - 1] == '\n') &&
		    (n - i < 4 || memcmp(log + i, "===", 3) != 0)) {
			/* "YYYY-MM-DDTHH:MM:SS.mmmZ LEVEL ", not 2030's (the
			 * harness's own lines start "=== harness"). */
			if (!(n - i > 25 && log[i + 4] == '-' &&
			      log[i + 10] == 'T' && log[i + 23] == 'Z' &&
			      memcmp(log + i, "2030-", 5) != 0))
				dm_fail("log line %d is not the daemon's: "
				        "%.40s",
				        lines + 1, (const char *)log + i);
			lines++;
		}
		if ((log[i] < 0x20 && log[i] != '\n') || log[i] == 0x7f)
			dm_fail("control byte 0x%02x in the log at %zu", log[i],
			        i);
	}
	assert_true(lines > 3);
	/* No NUL inside (the loop above), and dm_read_file ends it with one:
	 * a C string. */
	const char *text = (const char *)log;
	assert_null(strstr(text, "\xc2\x9b"));
	assert_null(strstr(text, "\xe2\x80\xae"));
	/* Each name written escaped: in the upload's and the job's lines. */
	assert_non_null(strstr(text,
	                       "lobby\\x0a2030-01-01T00:00:00.000Z ERROR forged"
	                       "\\x1b[2J\\u009b31m\\u202etpircs\\\\x0a"));
	assert_non_null(strstr(text, "scene 1 'lobby\\x0a"));
	assert_non_null(strstr(text, "job 1 'lobby\\x0a"));
	free(log);
	json_decref(sc);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_bad_frames_close_only_their_connection),
	        T(test_oversized_header_and_payload_are_too_large),
	        T(test_truncated_frames_then_close_are_forgotten),
	        T(test_bad_requests_get_errors_and_keep_the_session),
	        T(test_names_are_escaped_in_the_log),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
