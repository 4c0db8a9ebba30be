/*
 * cmds.c -- the client commands over scenes, jobs and the daemon itself:
 * submit, scenes, jobs, create, run, pause/resume/cancel, set, delete-*,
 * info, status and shutdown.
 *
 * Each builds one request (two or three for submit --solve and run
 * --wait), prints the result for people -- ids alone where a script
 * would capture them ("job=$(luxrad create 1)") -- or, with --json, the
 * daemon's reply objects one per line.  Replies are read defensively: a
 * member missing from a reply prints as "?" rather than crashing, since
 * the daemon may be a newer version.
 */
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "client.h"
#include "pack.h"

/* ------------------------------------------------------- reply helpers */

json_t *lx_req_id(rp_cmd cmd, const char *key, long long id)
{
	json_t *r = rp_request(cmd, -1);
	json_object_set_new(r, key, json_integer(id));
	return r;
}

int lx_simple_call(lx_ctx *cx, json_t *req, json_t **reply)
{
	int rc = lx_open(cx);

	*reply = NULL;
	if (rc != LX_EXIT_OK) {
		json_decref(req);
		return rc;
	}
	rc = lx_call(cx, req, reply);
	if (rc == LX_EXIT_OK && cx->json)
		lx_print_json(*reply);
	return rc;
}

/* ------------------------------------------------------------ options */

/*
 * The engine options given, as job.create's "options" (rad.h's table: the
 * key, and the JSON type of each).  Values are checked for their type
 * here, so that nothing unparsable reaches the daemon; the daemon checks
 * the ranges, against the same table, and names the option.
 */
int lx_job_options(lx_ctx *cx, json_t *req)
{
	json_t *o = json_object();

	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		lx_opt opt = (lx_opt)(LX_OPT_ENGINE + i);
		json_t *v = NULL;
		double x;
		long long k;
		int r = 0;

		if (!cx->given[opt])
			continue;
		switch (d->type) {
		case RAD_OPT_BOOL: /* the flag sets the opposite */
			v = json_boolean(d->def == 0);
			break;
		case RAD_OPT_ENUM:
			v = json_string(cx->val[opt]);
			break;
		case RAD_OPT_INT:
			r = lx_opt_int(cx, opt, INT_MIN, INT_MAX, &k);
			v = r == 0 ? json_integer(k) : NULL;
			break;
		case RAD_OPT_DOUBLE:
			r = lx_opt_double(cx, opt, &x);
			v = r == 0 ? json_real(x) : NULL;
			break;
		}
		if (r < 0) {
			json_decref(o);
			return -1;
		}
		json_object_set_new(o, d->key, v);
	}
	if (cx->given[LX_OPT_SOLVER])
		json_object_set_new(req, "solver",
		                    json_string(cx->val[LX_OPT_SOLVER]));
	json_object_set_new(req, "options", o);
	return 0;
}

/* -------------------------------------------------------------- submit */

/*
 * Read a scene file as it will travel: a GLB as it is, a .gltf packed
 * into one GLB with the buffers and images beside it, and the --luminaire
 * files in it (sio_scene_read_lum: the daemon reads no file).  Usage error
 * (exit 2) when it cannot be read or packed.
 */
static int read_scene(lx_ctx *cx, const char *path, unsigned char **out,
                      size_t *len)
{
	struct stat st;
	rad_error err = {0};
	int e = stat(path, &st) != 0   ? errno
	        : !S_ISREG(st.st_mode) ? EISDIR
	                               : 0;
	if (e)
		return lx_usage_error(cx, "cannot read scene file '%s': %s",
		                      path, strerror(e));
	if (st.st_size == 0)
		return lx_usage_error(cx, "scene file '%s' is empty", path);
	size_t n = (size_t)cx->nluminaires;
	sio_luminaire *lum = calloc(n + 1, sizeof *lum);
	char(*names)[LX_LIGHT_NAME_MAX] = calloc(n + 1, sizeof *names);
	rad_status rs =
	        lum && names ? RAD_OK
	                     : rad_fail(&err, RAD_ERR_NOMEM, "out of memory");
	for (size_t k = 0; k < n && !rs; k++)
		rs = sio_luminaire_spec(cx->luminaires[k], names[k],
		                        sizeof names[k], &lum[k], &err);
	if (!rs)
		rs = sio_scene_read_lum(path, lum, n, out, len, NULL, &err);
	free(names);
	free(lum);
	return rs ? lx_usage_error(cx, "%s", err.msg) : 0;
}

/* The scene's default name: the file name without directory and suffix. */
static void base_name(const char *path, char *out, size_t len)
{
	const char *b = strrchr(path, '/');
	char *dot;

	snprintf(out, len, "%s", b ? b + 1 : path);
	if ((dot = strrchr(out, '.')) && dot != out)
		*dot = '\0';
}

static int upload(lx_ctx *cx, const unsigned char *data, size_t len,
                  const char *name, long long *scene)
{
	json_t *lim = json_object_get(cx->conn.hello, "limits");
	json_t *max = json_object_get(lim, "max_scene_bytes");
	json_t *req, *reply = NULL;
	const char *warn;
	int rc;

	if (json_is_integer(max) &&
	    (long long)len > (long long)json_integer_value(max)) {
		fprintf(stderr,
		        "luxrad: too_large: '%s' is %zu bytes; this "
		        "daemon accepts scenes of at most %lld bytes\n",
		        cx->pos[0], len, (long long)json_integer_value(max));
		return LX_EXIT_DAEMON;
	}
	req = rp_request(RP_CMD_SCENE_UPLOAD, -1);
	json_object_set_new(req, "name", json_string(name));
	rc = lx_request(cx, req, data, len, &reply, NULL, NULL, NULL, NULL);
	json_decref(req);
	if (rc == LX_EXIT_OK) {
		*scene = lx_jint(reply, "scene");
		if (cx->json)
			lx_print_json(reply);
		warn = json_string_value(json_object_get(reply, "warnings"));
		if (warn && *warn && !cx->json)
			fprintf(stderr, "luxrad: scene %lld: warning: %s\n",
			        *scene, warn);
	}
	json_decref(reply);
	return rc;
}

/* job.create then job.run (converge): submit --solve. */
static int create_and_run(lx_ctx *cx, json_t *create, long long *job)
{
	json_t *reply = NULL;
	int rc = lx_call(cx, create, &reply);

	if (rc == LX_EXIT_OK) {
		*job = lx_jint(reply, "job");
		if (cx->json)
			lx_print_json(reply);
		json_decref(reply);
		json_t *run = lx_req_id(RP_CMD_JOB_RUN, "job", *job);
		json_object_set_new(run, "converge", json_true());
		rc = lx_call(cx, run, &reply);
		if (rc == LX_EXIT_OK && cx->json)
			lx_print_json(reply);
	}
	json_decref(reply);
	return rc;
}

int lx_cmd_submit(lx_ctx *cx)
{
	const uint64_t create_only =
	        ~(LX_BIT(HELP) | LX_BIT(JSON) | LX_BIT(CONNECT) |
	          LX_BIT(TOKEN_FILE) | LX_BIT(TLS_CA) | LX_BIT(NAME) |
	          LX_BIT(SOLVE) | LX_BIT(LUMINAIRE));
	char name[256];
	unsigned char *data = NULL;
	size_t len = 0;
	long long scene = 0, job = 0;
	json_t *create = NULL;
	int rc;

	for (int o = 0; o < LX_OPT_COUNT; o++)
		if (cx->given[o] && (create_only >> o & 1) &&
		    !cx->given[LX_OPT_SOLVE])
			return lx_usage_error(cx, "job options need --solve");
	if (cx->given[LX_OPT_SOLVE]) {
		create = rp_request(RP_CMD_JOB_CREATE, -1);
		if (lx_job_options(cx, create) != 0) {
			json_decref(create);
			return LX_EXIT_USAGE;
		}
	}
	if (cx->given[LX_OPT_NAME])
		snprintf(name, sizeof name, "%s", cx->val[LX_OPT_NAME]);
	else
		base_name(cx->pos[0], name, sizeof name);
	if ((rc = read_scene(cx, cx->pos[0], &data, &len)) == 0 &&
	    (rc = lx_open(cx)) == 0)
		rc = upload(cx, data, len, name, &scene);
	free(data);
	if (rc == 0 && create) {
		json_object_set_new(create, "scene", json_integer(scene));
		if (cx->given[LX_OPT_NAME])
			json_object_set_new(create, "name", json_string(name));
		rc = create_and_run(cx, create, &job);
		create = NULL;
	}
	json_decref(create);
	if (rc == 0 && !cx->json)
		printf("%lld\n", cx->given[LX_OPT_SOLVE] ? job : scene);
	return rc;
}

/* -------------------------------------------------------- lists, create */

static void fmt_time(double t, char *buf, size_t len)
{
	time_t s = (time_t)t;
	struct tm tm;

	if (t <= 0 || !localtime_r(&s, &tm))
		snprintf(buf, len, "?");
	else
		strftime(buf, len, "%Y-%m-%d %H:%M:%S", &tm);
}

int lx_cmd_scenes(lx_ctx *cx)
{
	json_t *reply;
	int rc = lx_simple_call(cx, rp_request(RP_CMD_SCENE_LIST, -1), &reply);
	json_t *list = json_object_get(reply, "scenes"), *s;
	size_t i;

	if (rc == LX_EXIT_OK && !cx->json) {
		printf("%-5s %-24s %12s %9s %5s %11s  %s\n", "ID", "NAME",
		       "BYTES", "POLYGONS", "JOBS", "MEMORY", "CREATED");
		json_array_foreach(list, i, s)
		{
			char mem[32], when[32];
			fmt_time(json_number_value(
			                 json_object_get(s, "created")),
			         when, sizeof when);
			printf("%-5lld %-24.24s %12lld %9lld %5lld %11s  %s\n",
			       lx_jint(s, "id"), lx_jstr(s, "name"),
			       lx_jint(s, "bytes"), lx_jint(s, "polygons"),
			       lx_jint(s, "jobs"),
			       lx_jbytes(s, "memory_bytes", mem, sizeof mem),
			       when);
		}
	}
	json_decref(reply);
	return rc;
}

int lx_cmd_jobs(lx_ctx *cx)
{
	json_t *reply;
	int rc = lx_simple_call(cx, rp_request(RP_CMD_JOB_LIST, -1), &reply);
	json_t *list = json_object_get(reply, "jobs"), *j;
	size_t i;

	if (rc == LX_EXIT_OK && !cx->json) {
		printf("%-5s %-20s %5s %-11s %-9s %6s %10s %10s %11s\n", "ID",
		       "NAME", "SCENE", "SOLVER", "STATE", "ITER", "RESIDUAL",
		       "LINKS", "MEMORY");
		json_array_foreach(list, i, j)
		{
			char mem[32], res[32];
			printf("%-5lld %-20.20s %5lld %-11s %-9s %6lld %10s "
			       "%10lld "
			       "%11s\n",
			       lx_jint(j, "id"), lx_jstr(j, "name"),
			       lx_jint(j, "scene"), lx_jstr(j, "solver"),
			       lx_jstr(j, "state"), lx_jint(j, "iteration"),
			       lx_jnum(j, "residual", "%.3g", res, sizeof res),
			       lx_jint(j, "links"),
			       lx_jbytes(j, "memory_bytes", mem, sizeof mem));
		}
	}
	json_decref(reply);
	return rc;
}

int lx_cmd_create(lx_ctx *cx)
{
	long long scene;
	json_t *req, *reply;
	int rc;

	if (lx_pos_id(cx, 0, "scene", &scene) != 0)
		return LX_EXIT_USAGE;
	req = lx_req_id(RP_CMD_JOB_CREATE, "scene", scene);
	if (lx_job_options(cx, req) != 0) {
		json_decref(req);
		return LX_EXIT_USAGE;
	}
	if (cx->given[LX_OPT_NAME])
		json_object_set_new(req, "name",
		                    json_string(cx->val[LX_OPT_NAME]));
	rc = lx_simple_call(cx, req, &reply);
	if (rc == LX_EXIT_OK && !cx->json)
		printf("%lld\n", lx_jint(reply, "job"));
	json_decref(reply);
	return rc;
}

/* ------------------------------------------------------------------ run */

typedef struct run_watch {
	lx_ctx *cx;
	long long job;
	char state[32]; /* latest state event, "" if none yet */
	json_t *early;  /* --json: events to print after the reply */
} run_watch;

/* Events seen while the run request is in flight. */
static void run_event(void *ud, json_t *ev)
{
	run_watch *w = ud;

	if (lx_jint(ev, "job") != w->job)
		return;
	if (w->cx->json)
		json_array_append(w->early, ev);
	if (!strcmp(lx_jstr(ev, "event"), "state"))
		snprintf(w->state, sizeof w->state, "%s", lx_jstr(ev, "state"));
}

/* The run request: exactly one target, checked locally. */
static json_t *run_request(lx_ctx *cx, long long job)
{
	json_t *req = lx_req_id(RP_CMD_JOB_RUN, "job", job);
	long long n;
	double t;

	if (!!cx->given[LX_OPT_ITERATIONS] + !!cx->given[LX_OPT_CONVERGE] +
	            !!cx->given[LX_OPT_SECONDS] >
	    1) {
		lx_usage_error(cx, "give one of --iterations, --converge and "
		                   "--seconds");
		json_decref(req);
		return NULL;
	}
	if (lx_opt_int(cx, LX_OPT_ITERATIONS, 1, 4294967295LL, &n) == 0)
		json_object_set_new(req, "iterations", json_integer(n));
	else if (cx->given[LX_OPT_ITERATIONS])
		goto bad;
	if (lx_opt_double(cx, LX_OPT_SECONDS, &t) == 0) {
		if (t <= 0) {
			lx_usage_error(cx, "--seconds: must be > 0");
			goto bad;
		}
		json_object_set_new(req, "seconds", json_real(t));
	} else if (cx->given[LX_OPT_SECONDS]) {
		goto bad;
	}
	if (!cx->given[LX_OPT_ITERATIONS] && !cx->given[LX_OPT_SECONDS])
		json_object_set_new(req, "converge", json_true());
	return req;
bad:
	json_decref(req);
	return NULL;
}

/* run --wait: the final line (or nothing under --json). */
static void print_outcome(lx_ctx *cx, long long job, const char *state)
{
	json_t *reply = NULL, *j, *st;
	char a[32], b[32];

	if (lx_call(cx, lx_req_id(RP_CMD_JOB_INFO, "job", job), &reply) != 0) {
		printf("job %lld: %s\n", job, state);
		json_decref(reply);
		return;
	}
	j = json_object_get(reply, "job");
	st = json_object_get(j, "stats");
	printf("job %lld: %s (iteration %lld, error estimate %s, %s s)\n", job,
	       state, lx_jint(j, "iteration"),
	       lx_jnum(st, "error_estimate", "%.3g", a, sizeof a),
	       lx_jnum(st, "seconds_total", "%.2f", b, sizeof b));
	if (json_is_string(json_object_get(j, "error")))
		printf("error: %s\n", lx_jstr(j, "error"));
	json_decref(reply);
}

int lx_cmd_run(lx_ctx *cx)
{
	run_watch w = {.cx = cx};
	json_t *req, *reply = NULL, *ev;
	char state[32];
	size_t i;
	int rc;

	if (lx_pos_id(cx, 0, "job", &w.job) != 0)
		return LX_EXIT_USAGE;
	if (!(req = run_request(cx, w.job)))
		return LX_EXIT_USAGE;
	if ((rc = lx_open(cx)) != 0) {
		json_decref(req);
		return rc;
	}
	/* Subscribe first: no transition can then slip by unseen. */
	if (cx->given[LX_OPT_WAIT] &&
	    (rc = lx_call(cx, lx_req_id(RP_CMD_SUBSCRIBE, "job", w.job),
	                  &reply)) != 0) {
		json_decref(req);
		json_decref(reply);
		return rc;
	}
	json_decref(reply);
	w.early = json_array();
	rc = lx_request(cx, req, NULL, 0, &reply, NULL, NULL, run_event, &w);
	json_decref(req);
	if (rc == LX_EXIT_OK) {
		if (cx->json)
			lx_print_json(reply);
		json_array_foreach(w.early, i, ev) lx_print_json(ev);
		/* A state event seen meanwhile is newer than the reply. */
		snprintf(state, sizeof state, "%s",
		         w.state[0] ? w.state : lx_jstr(reply, "state"));
		if (!cx->given[LX_OPT_WAIT] && !cx->json)
			printf("job %lld: %s\n", w.job, state);
	}
	json_decref(reply);
	json_decref(w.early);
	if (rc != LX_EXIT_OK || !cx->given[LX_OPT_WAIT])
		return rc;
	rc = lx_follow_job(cx, w.job, state, isatty(2) ? stderr : NULL,
	                   cx->json, state, sizeof state);
	if ((rc == LX_EXIT_OK || rc == LX_EXIT_JOB) && !cx->json)
		print_outcome(cx, w.job, state);
	return rc;
}

/* ------------------------------------------------------ small commands */

int lx_cmd_control(lx_ctx *cx)
{
	long long job;
	json_t *reply;
	rp_cmd cmd = !strcmp(cx->cmd, "pause")    ? RP_CMD_JOB_PAUSE
	             : !strcmp(cx->cmd, "resume") ? RP_CMD_JOB_RESUME
	                                          : RP_CMD_JOB_CANCEL;
	int rc;

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	rc = lx_simple_call(cx, lx_req_id(cmd, "job", job), &reply);
	if (rc == LX_EXIT_OK && !cx->json)
		printf("job %lld: %s\n", job, lx_jstr(reply, "state"));
	json_decref(reply);
	return rc;
}

int lx_cmd_set(lx_ctx *cx)
{
	long long job;
	double eps;
	json_t *req, *reply;
	int rc;

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	rc = lx_opt_double(cx, LX_ENGINE_OPT(eps), &eps);
	if (rc > 0)
		return lx_usage_error(cx, "nothing to set: give --eps E");
	if (rc < 0)
		return LX_EXIT_USAGE;
	req = lx_req_id(RP_CMD_JOB_SET, "job", job);
	json_object_set_new(req, "eps", json_real(eps));
	rc = lx_simple_call(cx, req, &reply);
	if (rc == LX_EXIT_OK && !cx->json)
		printf("job %lld: eps %g\n", job,
		       json_number_value(json_object_get(reply, "eps")));
	json_decref(reply);
	return rc;
}

int lx_cmd_delete(lx_ctx *cx)
{
	int job = !strcmp(cx->cmd, "delete-job");
	const char *what = job ? "job" : "scene";
	long long id;
	json_t *reply;
	int rc;

	if (lx_pos_id(cx, 0, what, &id) != 0)
		return LX_EXIT_USAGE;
	rc = lx_simple_call(
	        cx,
	        lx_req_id(job ? RP_CMD_JOB_DELETE : RP_CMD_SCENE_DELETE, what,
	                  id),
	        &reply);
	if (rc == LX_EXIT_OK && !cx->json)
		printf("deleted %s %lld\n", what, id);
	json_decref(reply);
	return rc;
}

int lx_cmd_shutdown(lx_ctx *cx)
{
	json_t *reply;
	int rc = lx_simple_call(cx, rp_request(RP_CMD_SHUTDOWN, -1), &reply);

	if (rc == LX_EXIT_OK && !cx->json)
		printf("luxradd is shutting down (jobs are checkpointed)\n");
	json_decref(reply);
	return rc;
}
