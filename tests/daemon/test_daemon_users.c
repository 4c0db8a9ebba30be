/*
 * test_daemon_users.c -- users, roles and ownership on a real luxradd
 * over real sockets (PROTOCOL.md §4, daemon/server/cmd/users.c):
 *  - tokens made by `luxradd user-add` are accepted, a wrong one is
 *    auth_failed, and hello names the user and its role;
 *  - a submitter's scenes and jobs are invisible to another submitter:
 *    absent from every list and status, not_found to info, run, cancel,
 *    delete, query, export, subscribe and job.create on them;
 *  - a read user sees and queries everything, and is forbidden every
 *    change and shutdown; a submitter is forbidden shutdown;
 *  - an admin sees and changes everyone's objects; so does a connection
 *    that needs no token and sends none (the local admin);
 *  - owners survive a restart.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "harness.h"

typedef struct user {
	const char *name, *role;
	char token[128];
} user;

/* Add a user with luxradd user-add; its token is what it prints. */
static void add_user(const char *file, user *u)
{
	char cmd[1024];
	snprintf(cmd, sizeof(cmd), "'%s' user-add %s %s --users-file '%s'",
	         LUXRAD_DAEMON_PATH, u->name, u->role, file);
	char *out = NULL;
	if (dm_run(cmd, &out) != 0)
		fail_msg("%s failed", cmd);
	size_t n = strcspn(out, "\n");
	if (n == 0 || n >= sizeof(u->token) || strncmp(out, "lxr_", 4) != 0)
		fail_msg("user-add printed '%s', not a token", out);
	memcpy(u->token, out, n);
	u->token[n] = '\0';
	free(out);
}

/* The users, their file, and a daemon that reads it. */
typedef struct world {
	char *file;
	user alice, bob, carol, root;
	dm_daemon *d;
} world;

static void make_world(world *w)
{
	w->file = dm_tmp_file(".users", "", 0);
	unlink(w->file); /* user-add creates it, 0600 */
	w->alice = (user){.name = "alice", .role = "submit"};
	w->bob = (user){.name = "bob", .role = "submit"};
	w->carol = (user){.name = "carol", .role = "read"};
	w->root = (user){.name = "root", .role = "admin"};
	add_user(w->file, &w->alice);
	add_user(w->file, &w->bob);
	add_user(w->file, &w->carol);
	add_user(w->file, &w->root);
	const char *args[] = {"--users-file", w->file, NULL};
	w->d = dm_start(args);
}

static dm_conn *login(world *w, const user *u)
{
	dm_conn *c = dm_connect_tcp(w->d);
	json_t *r = dm_ok(c, "{s:s, s:i, s:s}", "cmd", "hello", "version", 1,
	                  "token", u->token);
	json_t *who = dm_get(r, "user");
	assert_string_equal(json_string_value(dm_get(who, "name")), u->name);
	assert_string_equal(json_string_value(dm_get(who, "role")), u->role);
	json_decref(r);
	return c;
}

/* Number of entries of list (a reply member) whose "id" is id. */
static int listed(const json_t *list, json_int_t id)
{
	size_t i;
	json_t *v;
	int n = 0;
	json_array_foreach(list, i, v)
	{
		n += json_integer_value(json_object_get(v, "id")) == id;
	}
	return n;
}

static int sees(dm_conn *c, const json_t *scene, const json_t *job)
{
	json_t *sl = dm_ok(c, "{s:s}", "cmd", "scene.list");
	json_t *jl = dm_ok(c, "{s:s}", "cmd", "job.list");
	json_t *st = dm_ok(c, "{s:s}", "cmd", "status");
	int n = listed(dm_get(sl, "scenes"), json_integer_value(scene)) +
	        listed(dm_get(jl, "jobs"), json_integer_value(job)) +
	        listed(dm_get(st, "scenes"), json_integer_value(scene)) +
	        listed(dm_get(st, "job_list"), json_integer_value(job));
	json_decref(sl);
	json_decref(jl);
	json_decref(st);
	return n;
}

static void test_tokens_name_users(void **state)
{
	(void)state;
	world w;
	make_world(&w);
	dm_conn *c = login(&w, &w.alice);
	json_decref(dm_ok(c, "{s:s}", "cmd", "status"));
	dm_conn *bad = dm_connect_tcp(w.d);
	json_decref(dm_err(bad, "auth_failed", "{s:s, s:i, s:s}", "cmd",
	                   "hello", "version", 1, "token",
	                   "lxr_not-a-token-at-all"));
	/* The file holds hashes, not tokens. */
	size_t len = 0;
	char *text = (char *)dm_read_file(w.file, &len);
	assert_null(strstr(text, w.alice.token + 4));
	assert_non_null(strstr(text, "alice submit sha256:"));
	free(text);
	unlink(w.file);
	free(w.file);
	dm_pass();
}

static void test_submitters_see_only_their_own(void **state)
{
	(void)state;
	world w;
	make_world(&w);
	dm_conn *a = login(&w, &w.alice), *b = login(&w, &w.bob);
	json_t *sc = NULL;
	json_t *job = dm_solve_sample(a, "cornell.gltf", &sc);
	assert_int_equal(sees(a, sc, job), 4);
	if (sees(b, sc, job) != 0)
		fail_msg("bob sees alice's scene or job in a list or status");

	/* Every way to touch them is not_found, as if they did not exist. */
	static const char *const on_job[] = {
	        "job.info",   "job.pause",   "job.resume",
	        "job.cancel", "job.delete",  "subscribe",
	        "export",     "sensor.list", NULL};
	for (int i = 0; on_job[i]; i++)
		json_decref(dm_err(b, "not_found", "{s:s, s:O}", "cmd",
		                   on_job[i], "job", job));
	json_decref(dm_err(b, "not_found", "{s:s, s:O, s:i}", "cmd", "job.run",
	                   "job", job, "iterations", 1));
	json_decref(dm_err(b, "not_found", "{s:s, s:O, s:f}", "cmd", "job.set",
	                   "job", job, "eps", 0.01));
	json_decref(dm_err(b, "not_found", "{s:s, s:O, s:[[f,f,f,f,f,f]]}",
	                   "cmd", "query.points", "job", job, "points", 0.2,
	                   0.0, 0.2, 0.0, 1.0, 0.0));
	json_decref(dm_err(b, "not_found", "{s:s, s:O}", "cmd", "scene.info",
	                   "scene", sc));
	json_decref(dm_err(b, "not_found", "{s:s, s:O}", "cmd", "scene.delete",
	                   "scene", sc));
	json_decref(dm_err(b, "not_found", "{s:s, s:O}", "cmd", "job.create",
	                   "scene", sc));
	/* ...and alice's job is untouched. */
	json_t *info = dm_ok(a, "{s:s, s:O}", "cmd", "job.info", "job", job);
	assert_string_equal(
	        json_string_value(dm_get(dm_get(info, "job"), "state")),
	        "done");
	assert_string_equal(
	        json_string_value(dm_get(dm_get(info, "job"), "owner")),
	        "alice");
	json_decref(info);

	/* Bob's own work is his, and alice does not see it either. */
	json_t *bsc = NULL;
	json_t *bjob = dm_solve_sample(b, "cornell.gltf", &bsc);
	assert_int_equal(sees(b, bsc, bjob), 4);
	assert_int_equal(sees(a, bsc, bjob), 0);

	/* Owners survive a restart. */
	dm_stop(w.d);
	dm_restart(w.d);
	a = login(&w, &w.alice);
	b = login(&w, &w.bob);
	assert_int_equal(sees(a, sc, job), 4);
	assert_int_equal(sees(b, sc, job), 0);
	json_decref(dm_err(b, "not_found", "{s:s, s:O}", "cmd", "job.info",
	                   "job", job));
	json_decref(job);
	json_decref(sc);
	json_decref(bjob);
	json_decref(bsc);
	unlink(w.file);
	free(w.file);
	dm_pass();
}

static void test_roles_bound_what_a_user_may_do(void **state)
{
	(void)state;
	world w;
	make_world(&w);
	dm_conn *a = login(&w, &w.alice), *r = login(&w, &w.carol);
	json_t *sc = NULL;
	json_t *job = dm_solve_sample(a, "cornell.gltf", &sc);

	/* read: sees everything, queries, changes nothing. */
	assert_int_equal(sees(r, sc, job), 4);
	double lux = 0;
	const double pt[6] = {0.278, 0.0, 0.28, 0, 1, 0};
	assert_true(dm_query_points(r, job, pt, 1, &lux) >= 1);
	assert_true(lux > 0);
	json_decref(dm_err(r, "forbidden", "{s:s, s:O, s:i}", "cmd", "job.run",
	                   "job", job, "iterations", 1));
	json_decref(dm_err(r, "forbidden", "{s:s, s:O}", "cmd", "job.create",
	                   "scene", sc));
	json_t *e = dm_err(r, "forbidden", "{s:s}", "cmd", "shutdown");
	const char *m = json_string_value(
	        json_object_get(json_object_get(e, "error"), "message"));
	if (!m || !strstr(m, "carol") || !strstr(m, "admin"))
		fail_msg("the refusal does not say who and what role: %s",
		         m ? m : "");
	json_decref(e);
	size_t len = 0;
	char path[512];
	unsigned char *bytes = dm_read_file(
	        dm_sample("cornell.gltf", path, sizeof(path)), &len);
	json_t *up =
	        dm_call_payload(r, bytes, len, "{s:s}", "cmd", "scene.upload");
	assert_string_equal(dm_err_code(up), "forbidden");
	json_decref(up);
	free(bytes);
	/* submit: may not shut the daemon down. */
	json_decref(dm_err(a, "forbidden", "{s:s}", "cmd", "shutdown"));

	/* admin, and the local admin (loopback, no token): everything. */
	dm_conn *root = login(&w, &w.root);
	assert_int_equal(sees(root, sc, job), 4);
	json_decref(dm_ok(root, "{s:s, s:O}", "cmd", "job.delete", "job", job));
	dm_conn *local = dm_open(w.d, NULL);
	assert_int_equal(sees(local, sc, job), 2); /* the scene only now */
	json_decref(
	        dm_ok(local, "{s:s, s:O}", "cmd", "scene.delete", "scene", sc));
	json_decref(dm_ok(root, "{s:s}", "cmd", "shutdown"));
	json_decref(job);
	json_decref(sc);
	unlink(w.file);
	free(w.file);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_tokens_name_users),
	        T(test_submitters_see_only_their_own),
	        T(test_roles_bound_what_a_user_may_do),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
