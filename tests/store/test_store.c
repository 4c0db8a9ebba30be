/*
 * test_store.c -- luxradd's durable state: scenes and jobs survive a
 * reopen, checkpoints replace each other atomically, a process killed
 * with SIGKILL mid-write leaves a consistent store, damage done from
 * outside (files deleted, truncated, left over) is repaired at open, a
 * corrupt database or an unwritable directory is a clear error, sensors
 * are kept with their job, and a schema 1 database is upgraded.
 */
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <setjmp.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

#include "store.h"

static char root[] = "/tmp/luxrad-test-store.XXXXXX";

/* A fresh data directory path under root (not created). */
static const char *new_dir(const char *name)
{
	static char path[512];
	snprintf(path, sizeof(path), "%s/%s", root, name);
	return path;
}

static srv_store *open_ok(const char *dir)
{
	char msg[1024] = "";
	srv_store *st = srv_store_open(dir, msg, sizeof(msg));
	if (!st)
		fail_msg("srv_store_open(%s): %s", dir, msg);
	return st;
}

/* Checkpoint bytes for iteration i: length and content follow from i, so
 * a file can be checked against the row that names it. */
static size_t sol_len(uint32_t i)
{
	return 1000 + (i * 7919u) % 200000u;
}

static unsigned char *sol_make(uint32_t i, size_t *len)
{
	*len = sol_len(i);
	unsigned char *b = malloc(*len);
	assert_non_null(b);
	for (size_t k = 0; k < *len; k++)
		b[k] = (unsigned char)(i * 31u + k);
	return b;
}

static int sol_check(uint32_t i, const unsigned char *b, size_t len)
{
	if (len != sol_len(i))
		return 0;
	for (size_t k = 0; k < len; k++)
		if (b[k] != (unsigned char)(i * 31u + k))
			return 0;
	return 1;
}

/* How many files in dir/sub end with suffix ("" = all). */
static int count_files(const char *dir, const char *sub, const char *suffix)
{
	char path[600];
	snprintf(path, sizeof(path), "%s/%s", dir, sub);
	DIR *d = opendir(path);
	struct dirent *e;
	int n = 0;
	assert_non_null(d);
	while ((e = readdir(d)) != NULL) {
		size_t l = strlen(e->d_name), s = strlen(suffix);
		if (e->d_name[0] == '.' && (strcmp(e->d_name, ".") == 0 ||
		                            strcmp(e->d_name, "..") == 0))
			continue;
		if (l >= s && strcmp(e->d_name + l - s, suffix) == 0)
			n++;
	}
	closedir(d);
	return n;
}

/* ---------------------------------------------------------------- rows */

typedef struct scenes_seen {
	int n;
	srv_scene_row rows[16];
} scenes_seen;

static void on_scene(void *ud, const srv_scene_row *r)
{
	scenes_seen *s = ud;
	if (s->n < 16)
		s->rows[s->n] = *r;
	s->n++;
}

typedef struct jobs_seen {
	int n;
	srv_job_row rows[16]; /* strings duplicated */
} jobs_seen;

static void on_job(void *ud, const srv_job_row *r)
{
	jobs_seen *s = ud;
	if (s->n < 16) {
		s->rows[s->n] = *r;
		s->rows[s->n].options_json = strdup(r->options_json);
		s->rows[s->n].target_json = strdup(r->target_json);
		s->rows[s->n].eps_log_json = strdup(r->eps_log_json);
		s->rows[s->n].stats_json = strdup(r->stats_json);
	}
	s->n++;
}

static void jobs_clear(jobs_seen *s)
{
	for (int i = 0; i < s->n && i < 16; i++)
		srv_job_row_clear(&s->rows[i]);
	s->n = 0;
}

static void list_all(srv_store *st, scenes_seen *sc, jobs_seen *jb)
{
	char msg[1024];
	memset(sc, 0, sizeof(*sc));
	memset(jb, 0, sizeof(*jb));
	assert_int_equal(
	        srv_store_scene_list(st, on_scene, sc, msg, sizeof(msg)), 0);
	assert_int_equal(srv_store_job_list(st, on_job, jb, msg, sizeof(msg)),
	                 0);
}

static void test_scenes_add_list_read_delete(void **state)
{
	(void)state;
	const char *dir = new_dir("scenes");
	srv_store *st = open_ok(dir);
	char msg[1024];
	uint64_t a, b, c;
	assert_int_equal(srv_store_scene_add(st, "box", "", "abc", 3, &a, msg,
	                                     sizeof(msg)),
	                 0);
	assert_int_equal(srv_store_scene_add(st, "hall", "", "0123456789", 10,
	                                     &b, msg, sizeof(msg)),
	                 0);
	assert_true(b > a);
	scenes_seen sc;
	jobs_seen jb;
	list_all(st, &sc, &jb);
	assert_int_equal(sc.n, 2);
	assert_int_equal(jb.n, 0);
	assert_string_equal(sc.rows[0].name, "box");
	assert_int_equal(sc.rows[1].bytes, 10);
	assert_true(sc.rows[1].created > 1.6e9);
	unsigned char *bytes;
	size_t len;
	assert_int_equal(
	        srv_store_scene_read(st, b, &bytes, &len, msg, sizeof(msg)), 0);
	assert_int_equal(len, 10);
	assert_memory_equal(bytes, "0123456789", 10);
	free(bytes);
	assert_int_equal(srv_store_scene_delete(st, b, msg, sizeof(msg)), 0);
	assert_int_equal(
	        srv_store_scene_read(st, b, &bytes, &len, msg, sizeof(msg)),
	        -1);
	assert_non_null(strstr(msg, "not found"));
	assert_int_equal(srv_store_scene_delete(st, b, msg, sizeof(msg)), -1);
	assert_int_equal(count_files(dir, "scenes", ".bin"), 1);
	/* A name longer than a row holds is refused, not truncated. */
	char longname[300];
	memset(longname, 'n', sizeof(longname) - 1);
	longname[sizeof(longname) - 1] = '\0';
	assert_int_equal(srv_store_scene_add(st, longname, "", "x", 1, &c, msg,
	                                     sizeof(msg)),
	                 -1);
	assert_non_null(strstr(msg, "scene name is 299 bytes"));
	srv_store_close(st);

	/* Ids are never reused, even across a reopen. */
	st = open_ok(dir);
	assert_int_equal(
	        srv_store_scene_add(st, "", "", "z", 1, &c, msg, sizeof(msg)),
	        0);
	assert_true(c > b);
	list_all(st, &sc, &jb);
	assert_int_equal(sc.n, 2);
	assert_int_equal(sc.rows[0].id, a);
	assert_int_equal(sc.rows[1].id, c);
	srv_store_close(st);
}

static void test_jobs_persist(void **state)
{
	(void)state;
	const char *dir = new_dir("jobs");
	srv_store *st = open_ok(dir);
	char msg[1024];
	uint64_t scene;
	assert_int_equal(srv_store_scene_add(st, "s", "", "data", 4, &scene,
	                                     msg, sizeof(msg)),
	                 0);
	srv_job_row row;
	memset(&row, 0, sizeof(row));
	row.scene_id = scene;
	snprintf(row.name, sizeof(row.name), "first");
	row.options_json = "{\"solver\":\"hr\",\"eps\":0.01}";
	row.state = SRV_JOB_PAUSED;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	uint64_t j1 = row.id;
	assert_true(j1 > 0 && row.created > 0);
	row.options_json = NULL; /* stored as "" */
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	uint64_t j2 = row.id;
	assert_true(j2 > j1);
	/* A job for a scene that does not exist. */
	row.scene_id = scene + 100;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), -1);
	assert_non_null(strstr(msg, "not found"));
	/* Update the first one. */
	row.id = j1;
	row.scene_id = scene;
	row.state = SRV_JOB_FAILED;
	row.iterations = 7;
	row.target_json = "{\"iterations\":3}";
	row.eps_log_json = "[[0,0.01],[4,0.005]]";
	row.stats_json = "{\"links\":12}";
	snprintf(row.error, sizeof(row.error), "out of memory");
	assert_int_equal(srv_store_job_update(st, &row, msg, sizeof(msg)), 0);
	row.id = 9999;
	assert_int_equal(srv_store_job_update(st, &row, msg, sizeof(msg)), -1);
	assert_string_equal(msg, "job 9999 not found");
	/* A scene in use cannot go. */
	assert_int_equal(srv_store_scene_delete(st, scene, msg, sizeof(msg)),
	                 -1);
	assert_non_null(strstr(msg, "is used by 2 jobs"));
	srv_store_close(st);

	st = open_ok(dir);
	scenes_seen sc;
	jobs_seen jb;
	list_all(st, &sc, &jb);
	assert_int_equal(jb.n, 2);
	srv_job_row *r = &jb.rows[0];
	assert_int_equal(r->id, j1);
	assert_int_equal(r->scene_id, scene);
	assert_string_equal(r->name, "first");
	assert_string_equal(r->options_json,
	                    "{\"solver\":\"hr\",\"eps\":0.01}");
	assert_string_equal(r->target_json, "{\"iterations\":3}");
	assert_string_equal(r->eps_log_json, "[[0,0.01],[4,0.005]]");
	assert_string_equal(r->stats_json, "{\"links\":12}");
	assert_int_equal(r->state, SRV_JOB_FAILED);
	assert_string_equal(srv_job_state_name(r->state), "failed");
	assert_int_equal(r->iterations, 7);
	assert_string_equal(r->error, "out of memory");
	assert_int_equal(r->has_result, 0);
	assert_string_equal(jb.rows[1].options_json, "");
	assert_int_equal(jb.rows[1].state, SRV_JOB_PAUSED);
	jobs_clear(&jb);
	assert_int_equal(srv_store_job_delete(st, j1, msg, sizeof(msg)), 0);
	assert_int_equal(srv_store_job_delete(st, j1, msg, sizeof(msg)), -1);
	assert_int_equal(srv_store_job_delete(st, j2, msg, sizeof(msg)), 0);
	assert_int_equal(srv_store_scene_delete(st, scene, msg, sizeof(msg)),
	                 0);
	srv_store_close(st);
}

static void test_checkpoint_then_reopen(void **state)
{
	(void)state;
	const char *dir = new_dir("checkpoint");
	srv_store *st = open_ok(dir);
	char msg[1024];
	uint64_t scene;
	assert_int_equal(srv_store_scene_add(st, "s", "", "data", 4, &scene,
	                                     msg, sizeof(msg)),
	                 0);
	srv_job_row row;
	memset(&row, 0, sizeof(row));
	row.scene_id = scene;
	row.state = SRV_JOB_RUNNING;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	unsigned char *b;
	size_t len;
	assert_int_equal(srv_store_job_result_read(st, row.id, &b, &len, msg,
	                                           sizeof(msg)),
	                 -1);
	assert_non_null(strstr(msg, "has no checkpoint"));
	for (uint32_t i = 1; i <= 3; i++) {
		unsigned char *sol = sol_make(i, &len);
		row.iterations = i;
		assert_int_equal(srv_store_job_checkpoint(st, &row, sol, len,
		                                          msg, sizeof(msg)),
		                 0);
		free(sol);
	}
	/* Only the latest checkpoint remains on disk. */
	assert_int_equal(count_files(dir, "results", ".sol"), 1);
	srv_store_close(st);

	st = open_ok(dir);
	assert_string_equal(srv_store_repairs(st), "");
	scenes_seen sc;
	jobs_seen jb;
	list_all(st, &sc, &jb);
	assert_int_equal(jb.rows[0].has_result, 1);
	assert_int_equal(jb.rows[0].iterations, 3);
	assert_int_equal(jb.rows[0].state, SRV_JOB_RUNNING);
	jobs_clear(&jb);
	assert_int_equal(srv_store_job_result_read(st, row.id, &b, &len, msg,
	                                           sizeof(msg)),
	                 0);
	assert_true(sol_check(3, b, len));
	free(b);
	/* Deleting the job removes its checkpoint. */
	assert_int_equal(srv_store_job_delete(st, row.id, msg, sizeof(msg)), 0);
	assert_int_equal(count_files(dir, "results", ".sol"), 0);
	srv_store_close(st);
}

/* ------------------------------------------------------------- crashes */

/* The child: checkpoint job forever, and add/delete scenes, each step
 * announced on fd (so the parent can kill it mid-way). */
static void crash_child(const char *dir, uint64_t job, uint64_t scene, int fd)
{
	char msg[1024];
	srv_store *st = srv_store_open(dir, msg, sizeof(msg));
	if (!st)
		_exit(3);
	srv_job_row row;
	memset(&row, 0, sizeof(row));
	row.id = job;
	row.scene_id = scene;
	row.state = SRV_JOB_RUNNING;
	char stats[64];
	row.stats_json = stats;
	for (uint32_t i = 1;; i++) {
		size_t len;
		unsigned char *sol = sol_make(i, &len);
		row.iterations = i;
		snprintf(stats, sizeof(stats), "{\"iteration\":%u}", i);
		if (srv_store_job_checkpoint(st, &row, sol, len, msg,
		                             sizeof(msg)) < 0)
			_exit(4);
		free(sol);
		uint64_t id;
		char name[32];
		snprintf(name, sizeof(name), "crash-%u", i);
		sol = sol_make(i + 1000, &len);
		if (srv_store_scene_add(st, name, "", sol, len, &id, msg,
		                        sizeof(msg)) < 0)
			_exit(5);
		free(sol);
		if (i % 2 &&
		    srv_store_scene_delete(st, id, msg, sizeof(msg)) < 0)
			_exit(6);
		if (write(fd, "x", 1) != 1)
			_exit(7);
	}
}

typedef struct crash_check {
	srv_store *st;
	int bad, scenes;
} crash_check;

static void check_scene(void *ud, const srv_scene_row *r)
{
	crash_check *c = ud;
	unsigned char *b;
	size_t len;
	char msg[1024];
	unsigned i;
	c->scenes++;
	if (sscanf(r->name, "crash-%u", &i) != 1)
		return;
	if (srv_store_scene_read(c->st, r->id, &b, &len, msg, sizeof(msg))) {
		fprintf(stderr, "scene %llu: %s\n", (unsigned long long)r->id,
		        msg);
		c->bad++;
		return;
	}
	/* Scene "crash-i" holds sol_make(i + 1000): complete and intact. */
	if (!sol_check(i + 1000, b, len)) {
		fprintf(stderr, "scene %llu: bytes do not match its row\n",
		        (unsigned long long)r->id);
		c->bad++;
	}
	free(b);
}

static void check_job(void *ud, const srv_job_row *r)
{
	crash_check *c = ud;
	unsigned char *b;
	size_t len;
	char msg[1024], expect[64];
	if (!r->has_result)
		return; /* killed before the first checkpoint */
	if (srv_store_job_result_read(c->st, r->id, &b, &len, msg,
	                              sizeof(msg))) {
		fprintf(stderr, "job %llu: %s\n", (unsigned long long)r->id,
		        msg);
		c->bad++;
		return;
	}
	/* The file is the one the row describes: same iteration. */
	snprintf(expect, sizeof(expect), "{\"iteration\":%u}", r->iterations);
	if (!sol_check(r->iterations, b, len) ||
	    strcmp(r->stats_json, expect) != 0) {
		fprintf(stderr,
		        "job %llu: checkpoint does not match row "
		        "(iteration %u, %zu bytes)\n",
		        (unsigned long long)r->id, r->iterations, len);
		c->bad++;
	}
	free(b);
}

static void test_kill9_leaves_consistent_store(void **state)
{
	(void)state;
	const char *d = new_dir("crash");
	char dir[512], msg[1024];
	snprintf(dir, sizeof(dir), "%s", d);
	srv_store *st = open_ok(dir);
	uint64_t scene;
	assert_int_equal(srv_store_scene_add(st, "base", "", "s", 1, &scene,
	                                     msg, sizeof(msg)),
	                 0);
	srv_job_row row;
	memset(&row, 0, sizeof(row));
	row.scene_id = scene;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	srv_store_close(st);
	srand((unsigned)time(NULL));
	for (int round = 0; round < 30; round++) {
		int p[2];
		assert_int_equal(pipe(p), 0);
		pid_t pid = fork();
		assert_true(pid >= 0);
		if (pid == 0) {
			close(p[0]);
			crash_child(dir, row.id, scene, p[1]);
		}
		close(p[1]);
		/* Let it run a few steps, then kill it somewhere inside
		 * the next one (a random delay of up to 10 ms). */
		char c;
		for (int k = 0; k < 2 + round % 5; k++)
			assert_int_equal(read(p[0], &c, 1), 1);
		struct timespec ts = {0, (long)(rand() % 10000) * 1000};
		nanosleep(&ts, NULL);
		kill(pid, SIGKILL);
		int status;
		assert_int_equal(waitpid(pid, &status, 0), pid);
		close(p[0]);
		assert_true(WIFSIGNALED(status));

		st = open_ok(dir);
		crash_check cc = {st, 0, 0};
		assert_int_equal(srv_store_scene_list(st, check_scene, &cc, msg,
		                                      sizeof(msg)),
		                 0);
		assert_int_equal(srv_store_job_list(st, check_job, &cc, msg,
		                                    sizeof(msg)),
		                 0);
		assert_int_equal(cc.bad, 0);
		/* No temporary left, one checkpoint, one file per scene. */
		assert_int_equal(count_files(dir, "results", ".tmp"), 0);
		assert_int_equal(count_files(dir, "scenes", ".tmp"), 0);
		assert_int_equal(count_files(dir, "results", ".sol"), 1);
		assert_int_equal(count_files(dir, "scenes", ".bin"), cc.scenes);
		srv_store_close(st);
	}
}

/* --------------------------------------------------------------- damage */

static void test_open_repairs_outside_damage(void **state)
{
	(void)state;
	const char *d = new_dir("damage");
	char dir[512], path[700], msg[1024];
	snprintf(dir, sizeof(dir), "%s", d);
	srv_store *st = open_ok(dir);
	uint64_t s1, s2;
	assert_int_equal(srv_store_scene_add(st, "keep", "", "1234", 4, &s1,
	                                     msg, sizeof(msg)),
	                 0);
	assert_int_equal(srv_store_scene_add(st, "lost", "", "5678", 4, &s2,
	                                     msg, sizeof(msg)),
	                 0);
	srv_job_row row;
	memset(&row, 0, sizeof(row));
	row.scene_id = s1;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	uint64_t j1 = row.id;
	size_t len;
	unsigned char *sol = sol_make(5, &len);
	row.iterations = 5;
	assert_int_equal(
	        srv_store_job_checkpoint(st, &row, sol, len, msg, sizeof(msg)),
	        0);
	free(sol);
	row.scene_id = s2;
	assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)), 0);
	srv_store_close(st);

	/* Damage: the job's checkpoint deleted, scene 2's bytes deleted, an
	 * orphan scene file, leftover temporaries, a foreign file. */
	snprintf(path, sizeof(path), "%s/results/%llu-1.sol", dir,
	         (unsigned long long)j1);
	assert_int_equal(unlink(path), 0);
	snprintf(path, sizeof(path), "%s/scenes/%llu.bin", dir,
	         (unsigned long long)s2);
	assert_int_equal(unlink(path), 0);
	const char *extra[] = {"scenes/777.bin", "scenes/.abc.tmp",
	                       "results/.x.tmp", "results/5-3.sol",
	                       "scenes/README"};
	for (int i = 0; i < 5; i++) {
		snprintf(path, sizeof(path), "%s/%s", dir, extra[i]);
		FILE *f = fopen(path, "w");
		assert_non_null(f);
		fputs("junk", f);
		fclose(f);
	}
	st = open_ok(dir);
	const char *rep = srv_store_repairs(st);
	assert_non_null(strstr(rep, "has_result cleared"));
	assert_non_null(strstr(rep, "scene and its jobs removed"));
	assert_non_null(strstr(rep, "removed 2 unreferenced or temporary"));
	scenes_seen sc;
	jobs_seen jb;
	list_all(st, &sc, &jb);
	assert_int_equal(sc.n, 1);
	assert_int_equal(sc.rows[0].id, s1);
	assert_int_equal(jb.n, 1); /* scene 2's job went with it */
	assert_int_equal(jb.rows[0].id, j1);
	assert_int_equal(jb.rows[0].has_result, 0);
	jobs_clear(&jb);
	assert_int_equal(count_files(dir, "scenes", ".tmp"), 0);
	assert_int_equal(count_files(dir, "results", ""), 0);
	assert_int_equal(count_files(dir, "scenes", ".bin"), 1);
	assert_int_equal(count_files(dir, "scenes", "README"), 1);

	/* A scene file truncated while open: read says so. */
	snprintf(path, sizeof(path), "%s/scenes/%llu.bin", dir,
	         (unsigned long long)s1);
	assert_int_equal(truncate(path, 2), 0);
	unsigned char *b;
	assert_int_equal(
	        srv_store_scene_read(st, s1, &b, &len, msg, sizeof(msg)), -1);
	assert_non_null(strstr(msg, "2 bytes, the store recorded 4"));
	assert_non_null(strstr(msg, path));
	srv_store_close(st);
}

static void test_second_open_is_refused(void **state)
{
	(void)state;
	const char *dir = new_dir("lock");
	char msg[1024];
	srv_store *a = open_ok(dir);
	assert_null(srv_store_open(dir, msg, sizeof(msg)));
	assert_non_null(strstr(msg, "another luxradd"));
	srv_store_close(a);
	srv_store_close(open_ok(dir));
}

static void test_corrupt_database_is_an_error(void **state)
{
	(void)state;
	const char *d = new_dir("corrupt");
	char dir[512], path[700], msg[1024] = "";
	snprintf(dir, sizeof(dir), "%s", d);
	assert_int_equal(mkdir(dir, 0700), 0);
	snprintf(path, sizeof(path), "%s/luxradd.db", dir);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	for (int i = 0; i < 4096; i++)
		fputc("not a database "[i % 15], f);
	fclose(f);
	assert_null(srv_store_open(dir, msg, sizeof(msg)));
	assert_non_null(strstr(msg, path));
	assert_non_null(strstr(msg, "not a database"));

	/* A database from a newer luxradd is refused, not misread. */
	assert_int_equal(unlink(path), 0);
	sqlite3 *db;
	assert_int_equal(sqlite3_open(path, &db), SQLITE_OK);
	assert_int_equal(
	        sqlite3_exec(db, "PRAGMA user_version = 99", NULL, NULL, NULL),
	        SQLITE_OK);
	sqlite3_close(db);
	assert_null(srv_store_open(dir, msg, sizeof(msg)));
	assert_non_null(strstr(msg, "schema version 99 is newer"));
}

typedef struct sensors_seen {
	int n;
	uint64_t job[8];
	char name[8][64];
	double pt[8][6];
} sensors_seen;

static void on_sensor(void *ud, uint64_t job, const char *name,
                      const double pt[6])
{
	sensors_seen *s = ud;
	assert_true(s->n < 8);
	s->job[s->n] = job;
	snprintf(s->name[s->n], sizeof(s->name[0]), "%s", name);
	memcpy(s->pt[s->n], pt, sizeof(s->pt[0]));
	s->n++;
}

static sensors_seen sensors_of(srv_store *st)
{
	sensors_seen seen;
	char msg[1024];
	memset(&seen, 0, sizeof(seen));
	assert_int_equal(
	        srv_store_sensor_list(st, on_sensor, &seen, msg, sizeof(msg)),
	        0);
	return seen;
}

/* Add a scene and n jobs on it (ids into job[]). */
static void scene_with_jobs(srv_store *st, int n, uint64_t *job)
{
	char msg[1024];
	uint64_t scene;
	assert_int_equal(srv_store_scene_add(st, "s", "", "data", 4, &scene,
	                                     msg, sizeof(msg)),
	                 0);
	for (int i = 0; i < n; i++) {
		srv_job_row row;
		memset(&row, 0, sizeof(row));
		row.scene_id = scene;
		assert_int_equal(srv_store_job_add(st, &row, msg, sizeof(msg)),
		                 0);
		job[i] = row.id;
	}
}

/* Sensors added over the protocol: kept per job, in order, through a
 * reopen; a duplicate name or an unknown job is refused; deleting the
 * job removes them. */
static void test_sensors_persist(void **state)
{
	(void)state;
	const char *dir = new_dir("sensors");
	srv_store *st = open_ok(dir);
	char msg[1024];
	uint64_t jobs[2];
	scene_with_jobs(st, 2, jobs);
	uint64_t j1 = jobs[0], j2 = jobs[1];
	const double desk[6] = {0.278, 0, 0.2796, 0, 1, 0};
	const double door[6] = {-1.5, 2.25e-3, 1e6, 1, 0, -0.5};
	assert_int_equal(
	        srv_store_sensor_add(st, j2, "desk", door, msg, sizeof(msg)),
	        0);
	assert_int_equal(
	        srv_store_sensor_add(st, j1, "desk", desk, msg, sizeof(msg)),
	        0);
	assert_int_equal(
	        srv_store_sensor_add(st, j1, "door", door, msg, sizeof(msg)),
	        0);
	assert_int_equal(
	        srv_store_sensor_add(st, j1, "desk", door, msg, sizeof(msg)),
	        -1);
	assert_non_null(strstr(msg, "UNIQUE"));
	assert_int_equal(
	        srv_store_sensor_add(st, j2 + 50, "x", desk, msg, sizeof(msg)),
	        -1);
	assert_non_null(strstr(msg, "FOREIGN KEY"));
	srv_store_close(st);

	st = open_ok(dir);
	sensors_seen seen = sensors_of(st);
	assert_int_equal(seen.n, 3);
	assert_true(seen.job[0] == j1 && seen.job[1] == j1 &&
	            seen.job[2] == j2);
	assert_string_equal(seen.name[0], "desk");
	assert_string_equal(seen.name[1], "door");
	assert_string_equal(seen.name[2], "desk");
	assert_memory_equal(seen.pt[0], desk, sizeof(desk));
	assert_memory_equal(seen.pt[1], door, sizeof(door));
	assert_memory_equal(seen.pt[2], door, sizeof(door));
	assert_int_equal(srv_store_job_delete(st, j1, msg, sizeof(msg)), 0);
	seen = sensors_of(st);
	assert_int_equal(seen.n, 1);
	assert_true(seen.job[0] == j2);
	srv_store_close(st);
}

/* Version 1 (before sensors were stored) and version 2 (before owners)
 * databases are brought up to version 3 at open, their scenes and jobs
 * kept, owned by the local admin (""). */
static void test_old_schemas_are_upgraded(void **state)
{
	(void)state;
	static const char *const downgrade[] = {
	        "DROP TABLE sensors; ALTER TABLE scenes DROP COLUMN owner; "
	        "ALTER TABLE jobs DROP COLUMN owner; PRAGMA user_version = 1",
	        "ALTER TABLE scenes DROP COLUMN owner; "
	        "ALTER TABLE jobs DROP COLUMN owner; PRAGMA user_version = 2"};
	for (int v = 1; v <= 2; v++) {
		char name[32], dir[512], path[700], msg[1024], want[128];
		snprintf(name, sizeof(name), "schema%d", v);
		snprintf(dir, sizeof(dir), "%s", new_dir(name));
		srv_store *st = open_ok(dir);
		uint64_t job;
		scene_with_jobs(st, 1, &job);
		srv_store_close(st);
		/* Make it what luxradd with schema v left. */
		snprintf(path, sizeof(path), "%s/luxradd.db", dir);
		sqlite3 *db;
		assert_int_equal(sqlite3_open(path, &db), SQLITE_OK);
		assert_int_equal(
		        sqlite3_exec(db, downgrade[v - 1], NULL, NULL, NULL),
		        SQLITE_OK);
		sqlite3_close(db);

		st = open_ok(dir);
		snprintf(want, sizeof(want),
		         "schema upgraded from version %d to 3", v);
		assert_string_equal(srv_store_repairs(st), want);
		scenes_seen sc;
		jobs_seen jb;
		list_all(st, &sc, &jb);
		assert_int_equal(sc.n, 1);
		assert_int_equal(jb.n, 1);
		jobs_clear(&jb);
		const double pt[6] = {1, 2, 3, 0, 0, 1};
		assert_int_equal(srv_store_sensor_add(st, job, "s", pt, msg,
		                                      sizeof(msg)),
		                 0);
		srv_store_close(st);
		assert_int_equal(sqlite3_open(path, &db), SQLITE_OK);
		sqlite3_stmt *q;
		assert_int_equal(sqlite3_prepare_v2(db, "PRAGMA user_version",
		                                    -1, &q, NULL),
		                 SQLITE_OK);
		assert_int_equal(sqlite3_step(q), SQLITE_ROW);
		assert_int_equal(sqlite3_column_int(q, 0), 3);
		sqlite3_finalize(q);
		sqlite3_close(db);
	}
}

/* Owners are stored and listed back. */
static void test_owners_round_trip(void **state)
{
	(void)state;
	char dir[512], msg[1024];
	snprintf(dir, sizeof(dir), "%s", new_dir("owners"));
	srv_store *st = open_ok(dir);
	uint64_t scene;
	assert_int_equal(srv_store_scene_add(st, "s", "alice", "data", 4,
	                                     &scene, msg, sizeof(msg)),
	                 0);
	srv_job_row r = {.scene_id = scene,
	                 .options_json = "{}",
	                 .target_json = "",
	                 .eps_log_json = "[]",
	                 .stats_json = "",
	                 .error = ""};
	snprintf(r.name, sizeof(r.name), "j");
	snprintf(r.owner, sizeof(r.owner), "bob");
	assert_int_equal(srv_store_job_add(st, &r, msg, sizeof(msg)), 0);
	srv_store_close(st);
	st = open_ok(dir);
	scenes_seen sc;
	jobs_seen jb;
	list_all(st, &sc, &jb);
	assert_int_equal(sc.n, 1);
	assert_int_equal(jb.n, 1);
	assert_string_equal(sc.rows[0].owner, "alice");
	assert_string_equal(jb.rows[0].owner, "bob");
	jobs_clear(&jb);
	srv_store_close(st);
}

static void test_unwritable_directory_is_an_error(void **state)
{
	(void)state;
	if (geteuid() == 0) {
		printf("test_unwritable_directory_is_an_error: skipped "
		       "(running as root, permissions do not apply)\n");
		return;
	}
	const char *d = new_dir("readonly");
	char dir[512], sub[600], msg[1024] = "";
	snprintf(dir, sizeof(dir), "%s", d);
	assert_int_equal(mkdir(dir, 0500), 0);
	snprintf(sub, sizeof(sub), "%s/data", dir);
	assert_null(srv_store_open(sub, msg, sizeof(msg)));
	assert_non_null(strstr(msg, sub));
	assert_non_null(strstr(msg, strerror(EACCES)));
	chmod(dir, 0700);
}

static int setup(void **state)
{
	(void)state;
	return mkdtemp(root) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[600];
	snprintf(cmd, sizeof(cmd), "chmod -R u+rwx '%s'; rm -rf '%s'", root,
	         root);
	return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_scenes_add_list_read_delete),
	        cmocka_unit_test(test_jobs_persist),
	        cmocka_unit_test(test_checkpoint_then_reopen),
	        cmocka_unit_test(test_kill9_leaves_consistent_store),
	        cmocka_unit_test(test_open_repairs_outside_damage),
	        cmocka_unit_test(test_second_open_is_refused),
	        cmocka_unit_test(test_corrupt_database_is_an_error),
	        cmocka_unit_test(test_unwritable_directory_is_an_error),
	        cmocka_unit_test(test_sensors_persist),
	        cmocka_unit_test(test_old_schemas_are_upgraded),
	        cmocka_unit_test(test_owners_round_trip),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
