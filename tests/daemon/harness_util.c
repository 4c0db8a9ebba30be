/*
 * harness_util.c -- helpers over the harness: scenes, jobs and queries in
 * one call, sample and generated scene files, subprocesses, JSON numbers.
 */
#include "harness.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

/* ------------------------------------------------------- daemon helpers */

json_t *dm_upload_file(dm_conn *c, const char *path, const char *name)
{
	size_t len;
	unsigned char *bytes = dm_read_file(path, &len);
	json_t *r = dm_call_payload(c, bytes, len, "{s:s, s:s}", "cmd",
	                            "scene.upload", "name", name);
	free(bytes);
	dm_require_ok(r, "scene.upload");
	json_t *id = json_object_get(r, "scene");
	if (!id)
		dm_fail("scene.upload reply without \"scene\"");
	json_incref(id);
	json_decref(r);
	return id;
}

json_t *dm_job_create(dm_conn *c, const json_t *scene, const char *solver,
                      const json_t *options)
{
	json_t *h = json_pack("{s:s, s:O}", "cmd", "job.create", "scene",
	                      (json_t *)scene);
	if (solver)
		json_object_set_new(h, "solver", json_string(solver));
	if (options)
		json_object_set_new(h, "options", json_deep_copy(options));
	json_t *r = dm_call_json(c, h, NULL, 0, dm_reply_ms, 1);
	dm_require_ok(r, "job.create");
	json_t *id = json_object_get(r, "job");
	if (!id)
		dm_fail("job.create reply without \"job\"");
	json_incref(id);
	json_decref(r);
	return id;
}

const char *dm_job_state(dm_conn *c, const json_t *job)
{
	static char state[32];
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
	const char *s = json_string_value(
	        json_object_get(json_object_get(r, "job"), "state"));
	snprintf(state, sizeof(state), "%s", s ? s : "?");
	json_decref(r);
	return state;
}

static int state_in(const char *state, const char *states)
{
	size_t n = strlen(state);
	const char *p = states;
	while (*p) {
		const char *bar = strchr(p, '|');
		size_t len = bar ? (size_t)(bar - p) : strlen(p);
		if (len == n && !strncmp(p, state, n))
			return 1;
		if (!bar)
			break;
		p = bar + 1;
	}
	return 0;
}

json_t *dm_wait_job(dm_conn *c, const json_t *job, const char *states,
                    int timeout_ms)
{
	double end = dm_now_ms() + timeout_ms;
	char last[32] = "?";
	for (;;) {
		json_t *r =
		        dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", job);
		json_t *j = json_object_get(r, "job");
		const char *s = json_string_value(json_object_get(j, "state"));
		snprintf(last, sizeof(last), "%s", s ? s : "?");
		if (s && state_in(s, states)) {
			json_incref(j);
			json_decref(r);
			return j;
		}
		json_decref(r);
		if (dm_now_ms() > end)
			break;
		dm_sleep_ms(50);
	}
	dm_fail("job did not reach %s within %d ms (last state %s)", states,
	        timeout_ms, last);
}

long long dm_query_points(dm_conn *c, const json_t *job, const double *pts,
                          size_t n, double *lux)
{
	json_t *arr = json_array();
	for (size_t i = 0; i < n; i++) {
		json_t *p = json_array();
		for (int k = 0; k < 6; k++)
			json_array_append_new(p, json_real(pts[6 * i + k]));
		json_array_append_new(arr, p);
	}
	json_t *h = json_pack("{s:s, s:O, s:o}", "cmd", "query.points", "job",
	                      (json_t *)job, "points", arr);
	json_t *r = dm_call_json(c, h, NULL, 0, dm_reply_ms, 1);
	dm_require_ok(r, "query.points");
	json_t *l = json_object_get(r, "lux");
	if (!json_is_array(l) || json_array_size(l) != n)
		dm_fail("query.points: \"lux\" is not an array of %zu numbers",
		        n);
	json_t *e = json_object_get(r, "error_lux");
	if (!json_is_array(e) || json_array_size(e) != n)
		dm_fail("query.points: \"error_lux\" is not an array of %zu "
		        "numbers",
		        n);
	for (size_t i = 0; i < n; i++) {
		json_t *v = json_array_get(l, i), *ev = json_array_get(e, i);
		if (!json_is_number(v))
			dm_fail("query.points: lux[%zu] is not a number", i);
		if (!json_is_number(ev) || !(json_number_value(ev) >= 0))
			dm_fail("query.points: error_lux[%zu] is not a "
			        "number >= 0",
			        i);
		lux[i] = json_number_value(v);
	}
	long long it = dm_int(r, "iteration");
	json_decref(r);
	return it;
}

json_t *dm_solve_sample(dm_conn *c, const char *sample, json_t **scene)
{
	char p[512];
	*scene = dm_upload_file(c, dm_sample(sample, p, sizeof(p)), sample);
	json_t *opt = json_pack("{s:i}", "threads", 1);
	json_t *job = dm_job_create(c, *scene, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_decref(dm_wait_job(c, job, "done", 150000));
	return job;
}

/* -------------------------------------------------------------- files */

char *dm_tmp_file(const char *suffix, const void *data, size_t len)
{
	char *path = malloc(64);
	snprintf(path, 64, "/tmp/luxradd-t-XXXXXX%s", suffix);
	int fd = mkstemps(path, (int)strlen(suffix));
	if (fd < 0)
		dm_fail("mkstemps: %s", strerror(errno));
	if (write(fd, data, len) != (ssize_t)len)
		dm_fail("write %s: %s", path, strerror(errno));
	close(fd);
	return path;
}

const char *dm_sample(const char *name, char *buf, size_t len)
{
	snprintf(buf, len, "%s/scenes/%s", LUXRAD_SOURCE_DIR, name);
	return buf;
}

const char *dm_gen_scene(const char *file, const char *args, char *buf,
                         size_t len)
{
	char dir[512];
	snprintf(dir, sizeof(dir), "%s/tests/daemon/scenes", LUXRAD_BINARY_DIR);
	snprintf(buf, len, "%s/%s", dir, file);
	if (access(buf, R_OK) == 0)
		return buf;
	char cmd[2048];
	snprintf(cmd, sizeof(cmd),
	         "mkdir -p '%s' && '%s/luxrad-scenegen' %s -o '%s.%d.tmp' "
	         "2>/dev/null && mv '%s.%d.tmp' '%s'",
	         dir, LUXRAD_BINARY_DIR, args, buf, (int)getpid(), buf,
	         (int)getpid(), buf);
	if (system(cmd) != 0)
		dm_fail("could not generate %s: %s", buf, cmd);
	return buf;
}

unsigned char *dm_read_file(const char *path, size_t *len)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		dm_fail("cannot open %s: %s", path, strerror(errno));
	fseek(f, 0, SEEK_END);
	long size = ftell(f);
	fseek(f, 0, SEEK_SET);
	unsigned char *b = malloc((size_t)size + 1);
	if (!b || fread(b, 1, (size_t)size, f) != (size_t)size)
		dm_fail("cannot read %s", path);
	fclose(f);
	b[size] = 0;
	*len = (size_t)size;
	return b;
}

int dm_run(const char *cmd, char **out)
{
	fflush(NULL);
	FILE *p = popen(cmd, "r");
	if (!p)
		return -1;
	size_t cap = 65536, n = 0;
	char *b = malloc(cap);
	size_t r;
	while ((r = fread(b + n, 1, cap - n - 1, p)) > 0) {
		n += r;
		if (cap - n < 4096) {
			cap *= 2;
			b = realloc(b, cap);
		}
	}
	b[n] = 0;
	int st = pclose(p);
	if (out)
		*out = b;
	else
		free(b);
	if (st == -1)
		return -1;
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

/* ------------------------------------------------------------ numbers */

json_t *dm_get(const json_t *obj, const char *key)
{
	json_t *v = json_object_get(obj, key);
	if (!v) {
		char *s = dm_dumps(obj);
		char got[1600];
		snprintf(got, sizeof(got), "%s", s ? s : "(not an object)");
		free(s);
		dm_fail("missing member \"%s\" in %s", key, got);
	}
	return v;
}

double dm_num(const json_t *obj, const char *key)
{
	json_t *v = dm_get(obj, key);
	if (!json_is_number(v))
		dm_fail("member \"%s\" is not a number", key);
	return json_number_value(v);
}

long long dm_int(const json_t *obj, const char *key)
{
	json_t *v = dm_get(obj, key);
	if (!json_is_integer(v))
		dm_fail("member \"%s\" is not an integer", key);
	return (long long)json_integer_value(v);
}

void dm_require_keys(const json_t *obj, const char *what,
                     const char *const *keys)
{
	if (!json_is_object(obj))
		dm_fail("%s is not an object", what);
	for (size_t i = 0; keys[i]; i++)
		if (!json_object_get(obj, keys[i]))
			dm_fail("%s: member \"%s\" missing", what, keys[i]);
}

const char *const dm_mem_kinds[] = {"geometry",
                                    "materials",
                                    "lights",
                                    "names",
                                    "bvh",
                                    "elements_surface",
                                    "elements_cluster",
                                    "links",
                                    "matrix",
                                    "scratch",
                                    "study",
                                    "solution",
                                    NULL};

int dm_close_enough(double a, double b, double rel)
{
	double scale = fmax(fabs(a), fabs(b));
	return fabs(a - b) <= rel * scale + 1e-12;
}

double dm_metrics_sample(const char *body, const char *series)
{
	size_t n = strlen(series);
	const char *p = body;
	while (p && *p) {
		if (!strncmp(p, series, n) && p[n] == ' ')
			return strtod(p + n + 1, NULL);
		p = strchr(p, '\n');
		if (p)
			p++;
	}
	dm_fail("/metrics: no sample %s", series);
	return 0;
}

double dm_metric(const dm_daemon *d, const char *series)
{
	char *body = NULL;
	int code = dm_http_get(d, "/metrics", NULL, &body);
	if (code != 200)
		dm_fail("GET /metrics: status %d", code);
	double v = dm_metrics_sample(body, series);
	free(body);
	return v;
}
