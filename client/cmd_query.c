/*
 * cmd_query.c -- illuminance queries (points file, grid, surfaces) and the
 * GLB export.
 *
 * A points file may hold more points than one request can carry: the
 * request header is bounded by the daemon's max_header_bytes and its
 * max_points (both announced in the hello reply).  The points are sent
 * in batches that respect both, and the answers are concatenated, so
 * the output is the same as for one request.
 *
 * The export is written atomically: a temporary file in the target's
 * directory (created before asking, so an unwritable place fails
 * early), fsync'ed, then renamed over the target.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "client.h"

/* ---------------------------------------------------------- points file */

int lx_points_load(const char *path, json_t **points, size_t *n)
{
	char msg[1024];
	double *xyz;
	json_t *arr;

	*points = NULL;
	*n = 0;
	if (rp_points_read(path, &xyz, n, msg, sizeof(msg)) != 0) {
		fprintf(stderr, "luxrad: %s\n", msg);
		return LX_EXIT_USAGE;
	}
	if (*n == 0) {
		fprintf(stderr, "luxrad: %s: no points in the file\n", path);
		return LX_EXIT_USAGE;
	}
	arr = json_array();
	for (size_t i = 0; i < *n; i++) {
		const double *p = xyz + 6 * i;
		json_array_append_new(arr, json_pack("[ffffff]", p[0], p[1],
		                                     p[2], p[3], p[4], p[5]));
	}
	free(xyz);
	*points = arr;
	return LX_EXIT_OK;
}

/* ------------------------------------------------------------ queries */

/* The daemon's announced limit `key`, or dflt. */
static size_t hello_limit(const lx_ctx *cx, const char *key, size_t dflt)
{
	json_t *v =
	        json_object_get(json_object_get(cx->conn.hello, "limits"), key);
	long long x = json_integer_value(v);

	return json_is_integer(v) && x > 0 ? (size_t)x : dflt;
}

/*
 * Query the points in batches; *lux and *elux receive every answer and
 * its error estimate in order.  Returns an exit code; under --json each
 * reply is printed.
 */
static int query_points_batched(lx_ctx *cx, long long job, json_t *points,
                                json_t *lux, json_t *elux)
{
	size_t max_pts = hello_limit(cx, "max_points", 1000000);
	size_t max_hdr = hello_limit(cx, "max_header_bytes",
	                             RP_DEFAULT_MAX_HEADER_BYTES);
	size_t budget = max_hdr > 4096 ? max_hdr - 1024 : max_hdr / 2;
	size_t i = 0, n = json_array_size(points);

	while (i < n) {
		json_t *batch = json_array(), *req, *reply = NULL;
		size_t bytes = 0;
		int rc;
		while (i < n && json_array_size(batch) < max_pts) {
			json_t *p = json_array_get(points, i);
			char *text = json_dumps(p, JSON_COMPACT);
			size_t len = text ? strlen(text) + 1 : 0;
			free(text);
			if (json_array_size(batch) > 0 && bytes + len > budget)
				break;
			bytes += len;
			json_array_append(batch, p);
			i++;
		}
		req = rp_request(RP_CMD_QUERY_POINTS, -1);
		json_object_set_new(req, "job", json_integer(job));
		json_object_set(req, "points", batch);
		rc = lx_call(cx, req, &reply);
		json_t *l = json_object_get(reply, "lux");
		json_t *e = json_object_get(reply, "error_lux");
		if (rc == LX_EXIT_OK && cx->json)
			lx_print_json(reply);
		if (rc == LX_EXIT_OK &&
		    (json_array_size(l) != json_array_size(batch) ||
		     json_array_size(e) != json_array_size(batch))) {
			fprintf(stderr,
			        "luxrad: the daemon answered %zu of "
			        "%zu points\n",
			        json_array_size(l), json_array_size(batch));
			rc = LX_EXIT_DAEMON;
		}
		if (rc == LX_EXIT_OK) {
			json_array_extend(lux, l);
			json_array_extend(elux, e);
		}
		json_decref(batch);
		json_decref(reply);
		if (rc != LX_EXIT_OK)
			return rc;
	}
	return LX_EXIT_OK;
}

static int query_points(lx_ctx *cx, long long job)
{
	json_t *points, *lux, *elux;
	size_t n;
	int rc = lx_points_load(cx->val[LX_OPT_POINTS], &points, &n);

	if (rc != LX_EXIT_OK)
		return rc;
	if ((rc = lx_open(cx)) != LX_EXIT_OK) {
		json_decref(points);
		return rc;
	}
	lux = json_array();
	elux = json_array();
	rc = query_points_batched(cx, job, points, lux, elux);
	if (rc == LX_EXIT_OK && !cx->json) {
		printf("x,y,z,nx,ny,nz,lux,error_lux\n");
		for (size_t i = 0; i < n; i++) {
			json_t *p = json_array_get(points, i);
			for (size_t k = 0; k < 6; k++)
				printf("%.9g,",
				       json_number_value(json_array_get(p, k)));
			printf("%.6g,%.2g\n",
			       json_number_value(json_array_get(lux, i)),
			       json_number_value(json_array_get(elux, i)));
		}
	}
	json_decref(points);
	json_decref(lux);
	json_decref(elux);
	return rc;
}

static json_t *vec3(const double v[3])
{
	return json_pack("[fff]", v[0], v[1], v[2]);
}

/* The grid request from --origin/--u/--v/--spacing/--normal. */
static json_t *grid_request(lx_ctx *cx, long long job)
{
	double o[3], u[3], v[3], nrm[3], p;
	json_t *req;

	if (!cx->given[LX_OPT_ORIGIN] || !cx->given[LX_OPT_U] ||
	    !cx->given[LX_OPT_V]) {
		lx_usage_error(cx, "--grid needs --origin, --u and --v");
		return NULL;
	}
	if (lx_opt_vec3(cx, LX_OPT_ORIGIN, o) || lx_opt_vec3(cx, LX_OPT_U, u) ||
	    lx_opt_vec3(cx, LX_OPT_V, v) ||
	    (cx->given[LX_OPT_NORMAL] && lx_opt_vec3(cx, LX_OPT_NORMAL, nrm)) ||
	    lx_opt_double(cx, LX_OPT_SPACING, &p) < 0)
		return NULL;
	if (cx->given[LX_OPT_SPACING] && p <= 0) {
		lx_usage_error(cx, "--spacing: must be > 0 metres");
		return NULL;
	}
	req = rp_request(RP_CMD_QUERY_GRID, -1);
	json_object_set_new(req, "job", json_integer(job));
	json_object_set_new(req, "origin", vec3(o));
	json_object_set_new(req, "u", vec3(u));
	json_object_set_new(req, "v", vec3(v));
	if (cx->given[LX_OPT_NORMAL])
		json_object_set_new(req, "normal", vec3(nrm));
	if (cx->given[LX_OPT_SPACING])
		json_object_set_new(req, "spacing", json_real(p));
	json_object_set_new(req, "points", json_boolean(!cx->json));
	return req;
}

/* The grid as CSV rows (points from the reply), its summary on stderr. */
static void print_grid(const json_t *reply)
{
	long long nu = lx_jint(reply, "nu"), nv = lx_jint(reply, "nv");
	json_t *lux = json_object_get(reply, "lux");
	json_t *elux = json_object_get(reply, "error_lux");
	json_t *pts = json_object_get(reply, "points");
	char u0[32] = "-"; /* null when the mean is 0 */

	printf("i,j,x,y,z,lux,error_lux\n");
	for (long long j = 0; j < nv; j++) {
		for (long long i = 0; i < nu; i++) {
			size_t k = (size_t)(j * nu + i);
			json_t *p = json_array_get(pts, k);
			json_t *l = json_array_get(lux, k);
			printf("%lld,%lld,%.9g,%.9g,%.9g,", i, j,
			       json_number_value(json_array_get(p, 0)),
			       json_number_value(json_array_get(p, 1)),
			       json_number_value(json_array_get(p, 2)));
			/* A point inside a closed object: empty fields. */
			if (json_is_number(l))
				printf("%.6g,%.2g\n", json_number_value(l),
				       json_number_value(
				               json_array_get(elux, k)));
			else
				printf(",\n");
		}
	}
	if (json_is_number(json_object_get(reply, "u0")))
		snprintf(u0, sizeof u0, "%.3f", lx_jdbl(reply, "u0"));
	fprintf(stderr, "grid %lld x %lld, spacing %.4g m: ", nu, nv,
	        lx_jdbl(reply, "spacing"));
	fprintf(stderr, "min %.4g, mean %.4g, max %.4g lux, U0 %s, ",
	        lx_jdbl(reply, "min"), lx_jdbl(reply, "mean"),
	        lx_jdbl(reply, "max"), u0);
	fprintf(stderr, "largest error estimate %.2g lux ",
	        lx_jdbl(reply, "error_max"));
	if (lx_jint(reply, "inside") > 0)
		fprintf(stderr, "(%lld points inside objects left out) ",
		        lx_jint(reply, "inside"));
	fprintf(stderr, "(iteration %lld)\n", lx_jint(reply, "iteration"));
}

static int query_grid(lx_ctx *cx, long long job)
{
	json_t *req = grid_request(cx, job), *reply = NULL;
	int rc;

	if (!req)
		return LX_EXIT_USAGE;
	if ((rc = lx_open(cx)) != LX_EXIT_OK) {
		json_decref(req);
		return rc;
	}
	rc = lx_call(cx, req, &reply);
	if (rc == LX_EXIT_OK && cx->json)
		lx_print_json(reply);
	else if (rc == LX_EXIT_OK)
		print_grid(reply);
	json_decref(reply);
	return rc;
}

/* A CSV field, quoted when it holds a separator, a quote or a newline. */
static void csv_field(const char *s)
{
	if (!strpbrk(s, ",\"\r\n")) {
		fputs(s, stdout);
		return;
	}
	putchar('"');
	for (; *s; s++) {
		if (*s == '"')
			putchar('"');
		putchar(*s);
	}
	putchar('"');
}

static int query_surfaces(lx_ctx *cx, long long job)
{
	json_t *req, *reply = NULL, *s;
	size_t i;
	int rc;

	if ((rc = lx_open(cx)) != LX_EXIT_OK)
		return rc;
	req = rp_request(RP_CMD_QUERY_SURFACES, -1);
	json_object_set_new(req, "job", json_integer(job));
	rc = lx_call(cx, req, &reply);
	if (rc == LX_EXIT_OK && cx->json) {
		lx_print_json(reply);
	} else if (rc == LX_EXIT_OK) {
		printf("node,name,area_m2,min_lux,mean_lux,max_lux\n");
		json_array_foreach(json_object_get(reply, "surfaces"), i, s)
		{
			const char *name =
			        json_string_value(json_object_get(s, "name"));
			printf("%lld,", lx_jint(s, "node"));
			csv_field(name ? name : "");
			printf(",%.6g,%.6g,%.6g,%.6g\n", lx_jdbl(s, "area"),
			       lx_jdbl(s, "min"), lx_jdbl(s, "mean"),
			       lx_jdbl(s, "max"));
		}
	}
	json_decref(reply);
	return rc;
}

int lx_cmd_query(lx_ctx *cx)
{
	long long job;
	int kinds = !!cx->given[LX_OPT_POINTS] + !!cx->given[LX_OPT_GRID] +
	            !!cx->given[LX_OPT_SURFACES];

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	if (kinds != 1)
		return lx_usage_error(cx, "give exactly one of --points FILE, "
		                          "--grid and --surfaces");
	if (!cx->given[LX_OPT_GRID] &&
	    (cx->given[LX_OPT_ORIGIN] || cx->given[LX_OPT_U] ||
	     cx->given[LX_OPT_V] || cx->given[LX_OPT_SPACING] ||
	     cx->given[LX_OPT_NORMAL]))
		return lx_usage_error(cx, "--origin, --u, --v, --spacing and "
		                          "--normal apply to --grid only");
	if (cx->given[LX_OPT_POINTS])
		return query_points(cx, job);
	if (cx->given[LX_OPT_GRID])
		return query_grid(cx, job);
	return query_surfaces(cx, job);
}

/* ---------------------------------------------------------------- export */

static int write_all(int fd, const unsigned char *p, size_t n)
{
	while (n > 0) {
		ssize_t w = write(fd, p, n);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0)
			return -1;
		p += w;
		n -= (size_t)w;
	}
	return 0;
}

/*
 * Fill the temporary, give it the permissions a new file would have
 * (mkstemp makes it 0600), close it and rename it over path; 0 or -1
 * with errno.  fd is closed in every case.
 */
static int commit_file(int fd, const char *tmp, const char *path,
                       const unsigned char *data, size_t len)
{
	mode_t mask = umask(0);
	int e;

	umask(mask);
	if (fchmod(fd, 0666 & ~mask) != 0 || write_all(fd, data, len) != 0 ||
	    fsync(fd) != 0) {
		e = errno;
		close(fd);
		errno = e;
		return -1;
	}
	if (close(fd) != 0)
		return -1;
	return rename(tmp, path);
}

int lx_cmd_export(lx_ctx *cx)
{
	const char *path = cx->val[LX_OPT_OUTPUT];
	const unsigned char *glb = NULL;
	size_t glb_len = 0;
	long long job;
	char tmp[4200];
	json_t *req, *reply = NULL;
	int fd, rc;

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	if (!path || !*path)
		return lx_usage_error(cx, "give the output file: -o FILE.glb");
	snprintf(tmp, sizeof tmp, "%s.tmp.XXXXXX", path);
	if ((fd = mkstemp(tmp)) < 0) {
		fprintf(stderr, "luxrad: cannot write '%s': %s\n", path,
		        strerror(errno));
		return LX_EXIT_DAEMON;
	}
	if ((rc = lx_open(cx)) == LX_EXIT_OK) {
		req = rp_request(RP_CMD_EXPORT, -1);
		json_object_set_new(req, "job", json_integer(job));
		json_object_set_new(req, "format", json_string("glb"));
		rc = lx_request(cx, req, NULL, 0, &reply, &glb, &glb_len, NULL,
		                NULL);
		json_decref(req);
	}
	if (rc == LX_EXIT_OK && !glb) {
		fprintf(stderr, "luxrad: the export reply carried no GLB\n");
		rc = LX_EXIT_DAEMON;
	}
	if (rc == LX_EXIT_OK) {
		if (commit_file(fd, tmp, path, glb, glb_len) != 0) {
			fprintf(stderr, "luxrad: cannot write '%s': %s\n", path,
			        strerror(errno));
			rc = LX_EXIT_DAEMON;
		}
		fd = -1;
	}
	if (fd >= 0)
		close(fd);
	if (rc != LX_EXIT_OK)
		unlink(tmp);
	else if (cx->json)
		lx_print_json(reply);
	else
		printf("wrote %s: %zu bytes, %lld vertices, %lld triangles "
		       "(job %lld, iteration %lld)\n",
		       path, glb_len, lx_jint(reply, "vertices"),
		       lx_jint(reply, "triangles"), job,
		       lx_jint(reply, "iteration"));
	json_decref(reply);
	return rc;
}
