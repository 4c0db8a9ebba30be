/*
 * test_daemon_query.c -- scenes and queries on a real luxradd
 * (PROTOCOL.md "Scenes", "Queries"; export and memory are in
 * test_daemon_export.c):
 *  - scene.upload of .gltf and .glb reports the counts and bounds that
 *    luxrad-solve reports for the same file; scene.list / scene.info;
 *  - query.points equals `luxrad-solve --points` for the same scene,
 *    solver and options (explicit thread count: the engine is then
 *    deterministic), for hr, rmb and progressive, converged or stepped;
 *  - query.grid: cell centres, nu = ceil(|u|/p), the EN 12464-1 default
 *    spacing 0.2 * 5^log10(d) capped at 10 m, min <= mean <= max, u0 =
 *    min/mean, values equal query.points at the returned points; the
 *    points inside a closed object (the office desk's top) left out;
 *  - query.surfaces: one entry per mesh node, named as in the file,
 *    min <= mean <= max, the office floor's area, a flat floor's bounds;
 *  - query.node: the floor one face facing up, the walls four vertical
 *    ones; the EN spacing per face, cells, statistics (u0, ud) from the
 *    values, a cell equal to query.points at its centre; by index as by
 *    name; unknown names and indices, bad types and spacings refused;
 *  - scene.info's luminaires: the office's two panels (flux = exitance x
 *    area) and its desk lamp;
 *  - pipelined requests are answered in order.
 */
#include <math.h>
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
#include "rp.h"

/* Office: 4 (x) x 2.8 (y) x 3 (z) m.  Floor, desk height, walls. */
#define NOFFICE 10
static const double office_pts[NOFFICE * 6] = {
        1.0,   0.0, 1.0,   0, 1, 0,  3.0,   0.0,   2.0, 0,   1,  0,
        2.0,   0.8, 1.5,   0, 1, 0,  0.5,   0.8,   2.5, 0,   1,  0,
        0.001, 1.5, 1.5,   1, 0, 0,  3.999, 1.5,   1.5, -1,  0,  0,
        2.0,   1.5, 0.001, 0, 0, 1,  2.0,   2.799, 1.5, 0,   -1, 0,
        1.0,   1.2, 2.0,   0, 0, -1, 3.5,   0.3,   0.5, 0.3, 1,  0.2,
};
/* Cornell: 0.556 x 0.549 x 0.559 m. */
#define NCORNELL 6
static const double cornell_pts[NCORNELL * 6] = {
        0.1,   0.0,  0.1,   0,  1, 0, 0.45,  0.0,   0.45, 0, 1,  0,
        0.278, 0.27, 0.001, 0,  0, 1, 0.001, 0.27,  0.3,  1, 0,  0,
        0.554, 0.27, 0.3,   -1, 0, 0, 0.278, 0.548, 0.1,  0, -1, 0,
};

/* Run luxrad-solve --json; returns its parsed output. */
static json_t *solve_cli(const char *scene, const char *args, const double *pts,
                         size_t n)
{
	char *text = malloc(n * 160 + 16);
	size_t off = 0;
	for (size_t i = 0; i < n; i++)
		off += (size_t)sprintf(
		        text + off, "%.17g %.17g %.17g %.17g %.17g %.17g\n",
		        pts[6 * i], pts[6 * i + 1], pts[6 * i + 2],
		        pts[6 * i + 3], pts[6 * i + 4], pts[6 * i + 5]);
	char *pf = dm_tmp_file(".pts", text, off);
	free(text);
	char cmd[2048];
	snprintf(cmd, sizeof(cmd),
	         "'%s/luxrad-solve' '%s' --json --points '%s' %s 2>/dev/null",
	         LUXRAD_BINARY_DIR, scene, pf, args);
	char *out = NULL;
	int rc = dm_run(cmd, &out);
	unlink(pf);
	free(pf);
	if (rc != 0)
		fail_msg("%s: exit %d", cmd, rc);
	json_error_t je;
	json_t *j = json_loads(out, 0, &je);
	free(out);
	if (!j)
		fail_msg("luxrad-solve output: %s", je.text);
	return j;
}

/* ------------------------------------------------------------- scenes */

static void test_upload_reports_what_luxrad_solve_reports(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	const char *files[3];
	char p0[512], p1[512], p2[512];
	files[0] = dm_sample("cornell.gltf", p0, sizeof(p0));
	files[1] = dm_sample("office.gltf", p1, sizeof(p1));
	files[2] = dm_gen_scene("hall-empty.glb", "hall-empty", p2, sizeof(p2));
	static const char *const counts[] = {"triangles_in",
	                                     "triangles_nonfinite",
	                                     "triangles_degenerate",
	                                     "triangles_duplicate",
	                                     "polygons",
	                                     "polygons_cut",
	                                     "quads",
	                                     "materials",
	                                     "materials_offered",
	                                     "lights",
	                                     "emitters",
	                                     "nodes",
	                                     NULL};
	json_t *ids[3];
	for (int f = 0; f < 3; f++) {
		size_t len;
		unsigned char *b = dm_read_file(files[f], &len);
		char name[32];
		snprintf(name, sizeof(name), "scene-%d", f);
		json_t *r = dm_call_payload(c, b, len, "{s:s, s:s}", "cmd",
		                            "scene.upload", "name", name);
		free(b);
		if (strcmp(dm_err_code(r), ""))
			fail_msg("upload %s: %s", files[f], dm_err_code(r));
		ids[f] = json_incref(dm_get(r, "scene"));
		assert_string_equal(json_string_value(dm_get(r, "name")), name);
		/* The size is "size_bytes": a top-level "bytes" would announce
		 * a payload (PROTOCOL.md 5.3). */
		assert_int_equal(dm_int(r, "size_bytes"), (long long)len);
		assert_null(json_object_get(r, "bytes"));
		assert_true(dm_int(r, "memory_bytes") > 0);
		assert_true(json_is_string(dm_get(r, "warnings")));
		json_t *ref = solve_cli(files[f], "--iterations 1 --threads 1",
		                        NULL, 0);
		json_t *rs = dm_get(ref, "scene");
		json_t *rc = dm_get(r, "counts");
		for (int k = 0; counts[k]; k++)
			if (dm_int(rc, counts[k]) != dm_int(rs, counts[k]))
				fail_msg("%s: counts.%s %lld, luxrad-solve "
				         "says %lld",
				         files[f], counts[k],
				         dm_int(rc, counts[k]),
				         dm_int(rs, counts[k]));
		json_t *bd = dm_get(r, "bounds");
		for (int k = 0; k < 3; k++) {
			double lo = json_number_value(
			        json_array_get(dm_get(bd, "min"), k));
			double hi = json_number_value(
			        json_array_get(dm_get(bd, "max"), k));
			double rlo = json_number_value(
			        json_array_get(dm_get(rs, "bounds_min"), k));
			double rhi = json_number_value(
			        json_array_get(dm_get(rs, "bounds_max"), k));
			assert_true(dm_close_enough(lo, rlo, 1e-9));
			assert_true(dm_close_enough(hi, rhi, 1e-9));
		}
		json_decref(ref);
		/* scene.info = the upload result plus jobs. */
		json_t *info = dm_ok(c, "{s:s, s:O}", "cmd", "scene.info",
		                     "scene", ids[f]);
		assert_true(json_equal(dm_get(info, "counts"), rc));
		assert_int_equal(json_array_size(dm_get(info, "jobs")), 0);
		json_decref(info);
		json_decref(r);
	}
	/* Default names: scene-<id>, job-<id>. */
	size_t blen;
	unsigned char *b = dm_read_file(files[0], &blen);
	json_t *r = dm_call_payload(c, b, blen, "{s:s}", "cmd", "scene.upload");
	free(b);
	char want[64];
	snprintf(want, sizeof(want), "scene-%lld", dm_int(r, "scene"));
	assert_string_equal(json_string_value(dm_get(r, "name")), want);
	json_t *js = dm_job_create(c, dm_get(r, "scene"), NULL, NULL);
	json_t *ji = dm_ok(c, "{s:s, s:O}", "cmd", "job.info", "job", js);
	snprintf(want, sizeof(want), "job-%lld",
	         (long long)json_integer_value(js));
	assert_string_equal(
	        json_string_value(dm_get(dm_get(ji, "job"), "name")), want);
	assert_string_equal(
	        json_string_value(dm_get(dm_get(ji, "job"), "solver")), "hr");
	json_decref(ji);
	json_decref(js);
	json_decref(r);

	/* The README's figures for the Cornell box. */
	json_t *info =
	        dm_ok(c, "{s:s, s:O}", "cmd", "scene.info", "scene", ids[0]);
	assert_int_equal(dm_int(dm_get(info, "counts"), "triangles_in"), 32);
	assert_int_equal(dm_int(dm_get(info, "counts"), "polygons"), 51);
	json_decref(info);

	json_t *l = dm_ok(c, "{s:s}", "cmd", "scene.list");
	json_t *sl = dm_get(l, "scenes");
	assert_int_equal(json_array_size(sl), 4);
	static const char *const lk[] = {"id",       "name", "bytes",
	                                 "polygons", "jobs", "memory_bytes",
	                                 "created",  NULL};
	for (int f = 0; f < 3; f++) {
		int found = 0;
		for (size_t i = 0; i < 4; i++) {
			json_t *e = json_array_get(sl, i);
			for (int k = 0; lk[k]; k++)
				dm_get(e, lk[k]);
			found += json_equal(dm_get(e, "id"), ids[f]);
		}
		assert_int_equal(found, 1);
	}
	json_decref(l);
	for (int f = 0; f < 3; f++)
		json_decref(ids[f]);
	dm_pass();
}

/* ------------------------------------------------------------- points */

static void compare_with_cli(dm_conn *c, const char *scene_path,
                             const char *solver, int iterations,
                             const double *pts, size_t n)
{
	json_t *sc = dm_upload_file(c, scene_path, solver);
	json_t *opt = json_pack(
	        "{s:i, s:f, s:f, s:f, s:i, s:i, s:f, s:i}", "threads", 1, "eps",
	        1e-4, "variation", 0.5, "min_edge_rel", 0.005, "rcv_samples", 4,
	        "vis_samples", 4, "tol", 1e-3, "max_iterations", 100);
	json_t *job = dm_job_create(c, sc, solver, opt);
	json_decref(opt);
	if (iterations)
		json_decref(dm_ok(c, "{s:s, s:O, s:i}", "cmd", "job.run", "job",
		                  job, "iterations", iterations));
	else
		json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job",
		                  job, "converge", 1));
	json_decref(dm_wait_job(c, job, iterations ? "paused|done" : "done",
	                        150000));
	double lux[16];
	long long it = dm_query_points(c, job, pts, n, lux);

	char args[512];
	snprintf(args, sizeof(args),
	         "--solver %s --threads 1 --eps 1e-4 --variation 0.5 "
	         "--min-edge 0.005 --rcv-samples 4 --vis-samples 4 %s",
	         solver, iterations ? "" : "--tol 1e-3");
	if (iterations) {
		size_t l = strlen(args);
		snprintf(args + l, sizeof(args) - l, "--iterations %d",
		         iterations);
	}
	json_t *ref = solve_cli(scene_path, args, pts, n);
	assert_int_equal(it, dm_int(dm_get(ref, "stats"), "iteration"));
	json_t *rl = dm_get(ref, "illuminance_lux");
	for (size_t i = 0; i < n; i++) {
		double want = json_number_value(json_array_get(rl, i));
		if (!dm_close_enough(lux[i], want, 1e-9))
			fail_msg("%s on %s, point %zu: daemon %.17g lux, "
			         "luxrad-solve %.17g",
			         solver, scene_path, i, lux[i], want);
	}
	json_decref(ref);
	json_decref(job);
	json_decref(sc);
}

static void test_query_points_equal_luxrad_solve(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	char p[512];
	compare_with_cli(c, dm_sample("office.gltf", p, sizeof(p)), "hr", 0,
	                 office_pts, NOFFICE);
	compare_with_cli(c, dm_sample("cornell.gltf", p, sizeof(p)), "hr", 0,
	                 cornell_pts, NCORNELL);
	compare_with_cli(c, dm_sample("cornell.gltf", p, sizeof(p)), "rmb", 0,
	                 cornell_pts, NCORNELL);
	compare_with_cli(c, dm_sample("office.gltf", p, sizeof(p)),
	                 "progressive", 3, office_pts, NOFFICE);
	compare_with_cli(c, dm_sample("office.gltf", p, sizeof(p)), "hr", 2,
	                 office_pts, NOFFICE);
	dm_pass();
}

/*
 * A big query.points is shared out among the query threads in chunks
 * (core/qsplit.c): its values must be those of the same points asked a few at
 * a time (below one chunk, so each on one thread), to the last bit.
 */
static void test_split_query_equals_small_queries(void **state)
{
	(void)state;
	const char *args[] = {"--query-threads", "3", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc = NULL;
	json_t *job = dm_solve_sample(c, "office.gltf", &sc);
	enum { N = 203, SMALL = 7 }; /* 7 chunks of 32, the last short */
	static double pts[N * 6], big[N], small[N];
	for (int i = 0; i < N; i++) {
		double *p = pts + 6 * i;
		p[0] = 0.1 + 3.8 * (i % 29) / 28.0;
		p[1] = i % 3 == 0 ? 0.0 : 0.75;
		p[2] = 0.1 + 2.8 * (i / 29) / 6.0;
		p[3] = p[5] = 0, p[4] = 1;
	}
	dm_query_points(c, job, pts, N, big);
	for (int i = 0; i < N; i += SMALL)
		dm_query_points(c, job, pts + 6 * i,
		                (size_t)(N - i < SMALL ? N - i : SMALL),
		                small + i);
	for (int i = 0; i < N; i++)
		if (memcmp(&big[i], &small[i], sizeof(double)) != 0)
			fail_msg("point %d: %.17g lux in the big query, %.17g "
			         "asked alone",
			         i, big[i], small[i]);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* ---------------------------------------------------------- pipelining */

/*
 * PROTOCOL.md 3: the requests of one connection are answered in the order
 * received, even when the later ones are quicker (a status after a
 * query.points of many points, run on the query threads).
 */
static void test_pipelined_requests_are_answered_in_order(void **state)
{
	(void)state;
	const char *args[] = {"--query-threads", "2", NULL};
	dm_daemon *d = dm_start(args);
	dm_conn *c = dm_open(d, NULL);
	char p[512];
	json_t *sc = dm_upload_file(c, dm_sample("office.gltf", p, sizeof(p)),
	                            "office");
	json_t *opt = json_pack("{s:i}", "threads", 1);
	json_t *job = dm_job_create(c, sc, "hr", opt);
	json_decref(opt);
	json_decref(dm_ok(c, "{s:s, s:O, s:b}", "cmd", "job.run", "job", job,
	                  "converge", 1));
	json_decref(dm_wait_job(c, job, "done", 150000));

	json_t *heavy = json_array(); /* ~0.3 s of work */
	for (int i = 0; i < 300; i++)
		json_array_append_new(heavy,
		                      json_pack("[f,f,f,i,i,i]", 0.2 + 0.01 * i,
		                                0.8, 1.5, 0, 1, 0));
	json_t *light = json_pack("[[f,f,f,i,i,i]]", 2.0, 0.0, 1.5, 0, 1, 0);
	enum { N = 24 };
	unsigned char *all = NULL;
	size_t all_len = 0;
	for (int k = 0; k < N; k++) {
		json_t *h;
		switch (k % 4) {
		case 0:
			h = json_pack("{s:s, s:O, s:O}", "cmd", "query.points",
			              "job", job, "points", heavy);
			break;
		case 1:
			h = json_pack("{s:s}", "cmd", "status");
			break;
		case 2:
			h = json_pack("{s:s, s:O, s:O}", "cmd", "query.points",
			              "job", job, "points", light);
			break;
		default:
			h = json_pack("{s:s, s:O}", "cmd", "job.info", "job",
			              job);
		}
		json_object_set_new(h, "id", json_integer(1000 + k));
		unsigned char *f;
		size_t flen;
		assert_int_equal(rp_frame_encode(h, NULL, 0, &f, &flen), 0);
		json_decref(h);
		all = realloc(all, all_len + flen);
		memcpy(all + all_len, f, flen);
		all_len += flen;
		free(f);
	}
	assert_int_equal(dm_send_raw(c, all, all_len), 0);
	free(all);
	for (int k = 0; k < N; k++) {
		json_t *f = NULL;
		if (dm_recv(c, DM_REPLY_MS, &f, NULL, NULL) != 1)
			fail_msg("pipelined reply %d missing", k);
		if (json_integer_value(json_object_get(f, "id")) != 1000 + k)
			fail_msg("pipelined reply %d carries id %lld: replies "
			         "out of order",
			         k,
			         (long long)json_integer_value(
			                 json_object_get(f, "id")));
		assert_string_equal(dm_err_code(f), "");
		if (k % 4 == 0)
			assert_int_equal(json_array_size(dm_get(f, "lux")),
			                 300);
		json_decref(f);
	}
	json_decref(heavy);
	json_decref(light);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* --------------------------------------------------------------- grid */

static double en12464_spacing(double d)
{
	double p = 0.2 * pow(5.0, log10(d));
	return p > 10 ? 10 : p;
}

/* Check one grid answer; returns nothing, fails on any inconsistency. */
static void check_grid(dm_conn *c, const json_t *job, const double o[3],
                       const double u[3], const double v[3], const double n[3],
                       double spacing, double want_p)
{
	json_t *h = json_pack("{s:s, s:O, s:[f,f,f], s:[f,f,f], s:[f,f,f], "
	                      "s:b}",
	                      "cmd", "query.grid", "job", job, "origin", o[0],
	                      o[1], o[2], "u", u[0], u[1], u[2], "v", v[0],
	                      v[1], v[2], "points", 1);
	if (n)
		json_object_set_new(h, "normal",
		                    json_pack("[f,f,f]", n[0], n[1], n[2]));
	if (spacing > 0)
		json_object_set_new(h, "spacing", json_real(spacing));
	char *req = json_dumps(h, JSON_COMPACT);
	/* Send through dm_call's path: a format of one object. */
	json_t *r = dm_call(c, "O", h);
	json_decref(h);
	if (strcmp(dm_err_code(r), ""))
		fail_msg("%s: error %s", req, dm_err_code(r));
	double lu = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
	double lv = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
	double p = dm_num(r, "spacing");
	if (!dm_close_enough(p, want_p, 1e-9))
		fail_msg("%s: spacing %.17g, want %.17g", req, p, want_p);
	long long nu = dm_int(r, "nu"), nv = dm_int(r, "nv");
	if (nu != (long long)ceil(lu / want_p - 1e-9) ||
	    nv != (long long)ceil(lv / want_p - 1e-9))
		fail_msg("%s: nu %lld nv %lld, want %g %g", req, nu, nv,
		         ceil(lu / want_p), ceil(lv / want_p));
	json_t *lux = dm_get(r, "lux"), *pts = dm_get(r, "points");
	size_t cnt = (size_t)(nu * nv);
	assert_int_equal(json_array_size(lux), cnt);
	assert_int_equal(json_array_size(pts), cnt);
	double mn = INFINITY, mx = -INFINITY, sum = 0;
	double *q = malloc(cnt * 6 * sizeof(double));
	double nn[3];
	if (n)
		memcpy(nn, n, sizeof(nn));
	else {
		nn[0] = u[1] * v[2] - u[2] * v[1];
		nn[1] = u[2] * v[0] - u[0] * v[2];
		nn[2] = u[0] * v[1] - u[1] * v[0];
	}
	for (size_t i = 0; i < cnt; i++) {
		double l = json_number_value(json_array_get(lux, i));
		mn = fmin(mn, l);
		mx = fmax(mx, l);
		sum += l;
		/* Row-major, nu per row: column along u, row along v. */
		size_t col = i % (size_t)nu, row = i / (size_t)nu;
		double s = (col + 0.5) / (double)nu,
		       t = (row + 0.5) / (double)nv;
		json_t *pt = json_array_get(pts, i);
		for (int k = 0; k < 3; k++) {
			double want = o[k] + s * u[k] + t * v[k];
			double got = json_number_value(json_array_get(pt, k));
			if (fabs(got - want) > 1e-9)
				fail_msg(
				        "%s: point %zu coordinate %d is %.17g, "
				        "want the cell centre %.17g",
				        req, i, k, got, want);
			q[6 * i + k] = got;
			q[6 * i + 3 + k] = nn[k];
		}
	}
	double mean = sum / (double)cnt;
	assert_true(dm_close_enough(dm_num(r, "min"), mn, 1e-12));
	assert_true(dm_close_enough(dm_num(r, "max"), mx, 1e-12));
	assert_true(dm_close_enough(dm_num(r, "mean"), mean, 1e-9));
	assert_true(mn <= mean && mean <= mx);
	if (mean > 0)
		assert_true(dm_close_enough(dm_num(r, "u0"), mn / mean, 1e-9));
	/* The grid's lux are the lux at its points. */
	double *pl = malloc(cnt * sizeof(double));
	dm_query_points(c, job, q, cnt, pl);
	for (size_t i = 0; i < cnt; i++) {
		double l = json_number_value(json_array_get(lux, i));
		if (!dm_close_enough(l, pl[i], 1e-9))
			fail_msg("%s: grid lux[%zu] %.17g, query.points %.17g",
			         req, i, l, pl[i]);
	}
	free(pl);
	free(q);
	free(req);
	json_decref(r);
}

static void test_query_grid_cells_spacing_and_uniformity(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc;
	json_t *job = dm_solve_sample(c, "office.gltf", &sc);

	/* The work plane at 0.8 m: u along z, v along x (u x v = +y). */
	const double o[3] = {0.2, 0.8, 0.2}, u[3] = {0, 0, 2.6},
	             v[3] = {3.6, 0, 0};
	check_grid(c, job, o, u, v, NULL, 0, en12464_spacing(3.6));
	check_grid(c, job, o, u, v, NULL, 1.0, 1.0);
	const double down[3] = {0, -1, 0};
	check_grid(c, job, o, u, v, down, 0.7, 0.7);
	/* The floor, 4 x 3 m: d = 4. */
	const double fo[3] = {0, 0, 0}, fu[3] = {0, 0, 3}, fv[3] = {4, 0, 0};
	check_grid(c, job, fo, fu, fv, NULL, 0, en12464_spacing(4));
	/* A wall, longer side 2.8 m: u along y, v along x (u x v = -z). */
	const double wo[3] = {0, 0, 2.999}, wu[3] = {0, 2.8, 0},
	             wv[3] = {2.5, 0, 0};
	check_grid(c, job, wo, wu, wv, NULL, 0, en12464_spacing(2.8));

	/* Spacing is capped at 10 m: a 2 km strip (d = 2000). */
	json_t *r = dm_ok(c, "{s:s, s:O, s:[f,f,f], s:[f,f,f], s:[f,f,f]}",
	                  "cmd", "query.grid", "job", job, "origin", 0.0, 0.01,
	                  0.0, "u", 0.0, 0.0, 1.0, "v", 2000.0, 0.0, 0.0);
	assert_true(dm_close_enough(dm_num(r, "spacing"), 10.0, 1e-12));
	assert_int_equal(dm_int(r, "nv"), 200);
	assert_int_equal(dm_int(r, "nu"), 1);
	assert_null(json_object_get(r, "points")); /* not asked for */
	json_decref(r);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* A grid through the office desk's top, a closed slab 0.72 .. 0.75 m over
 * x 1.3 .. 2.7, z 2.05 .. 2.75: its 3 x 6 cells inside the slab receive
 * nothing and are left out (null, counted in "inside"); the rest hold
 * min, mean and max, min well above 0. */
static void test_query_grid_leaves_out_inside_objects(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc;
	json_t *job = dm_solve_sample(c, "office.gltf", &sc);
	json_t *r = dm_ok(c, "{s:s, s:O, s:[f,f,f], s:[f,f,f], s:[f,f,f], s:f}",
	                  "cmd", "query.grid", "job", job, "origin", 0.0, 0.735,
	                  3.0, "u", 4.0, 0.0, 0.0, "v", 0.0, 0.0, -3.0,
	                  "spacing", 0.25);
	assert_int_equal(dm_int(r, "nu"), 16);
	assert_int_equal(dm_int(r, "nv"), 12);
	assert_int_equal(dm_int(r, "inside"), 18);
	json_t *lux = dm_get(r, "lux"), *el = dm_get(r, "error_lux");
	double mn = HUGE_VAL;
	for (int j = 0; j < 12; j++) {
		for (int i = 0; i < 16; i++) {
			double x = 0.125 + 0.25 * i, z = 2.875 - 0.25 * j;
			int in = x > 1.3 && x < 2.7 && z > 2.05 && z < 2.75;
			json_t *v = json_array_get(lux, (size_t)(j * 16 + i));
			json_t *e = json_array_get(el, (size_t)(j * 16 + i));
			assert_int_equal(json_is_null(v), in);
			assert_int_equal(json_is_null(e), in);
			if (!in)
				mn = fmin(mn, json_number_value(v));
		}
	}
	assert_true(dm_close_enough(dm_num(r, "min"), mn, 1e-12));
	assert_true(mn > 1);
	json_decref(r);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* ----------------------------------------------------------- surfaces */

static void test_query_surfaces_per_node(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc;
	json_t *job = dm_solve_sample(c, "office.gltf", &sc);
	json_t *r = dm_ok(c, "{s:s, s:O}", "cmd", "query.surfaces", "job", job);
	json_t *s = dm_get(r, "surfaces");
	static const char *const meshes[] = {
	        "floor",       "ceiling", "walls", "luminaire_1",
	        "luminaire_2", "desk",    "chair", NULL};
	int seen[7] = {0};
	size_t i;
	json_t *e;
	json_array_foreach(s, i, e)
	{
		dm_int(e, "node");
		const char *name = json_string_value(dm_get(e, "name"));
		double area = dm_num(e, "area"), mn = dm_num(e, "min"),
		       mean = dm_num(e, "mean"), mx = dm_num(e, "max");
		int k;
		for (k = 0; meshes[k]; k++)
			if (name && !strcmp(name, meshes[k]))
				break;
		if (!meshes[k])
			fail_msg("surface \"%s\" is not a mesh node of "
			         "office.gltf",
			         name ? name : "(null)");
		seen[k]++;
		if (!(area > 0))
			fail_msg("%s: area %g", name, area);
		if (!(mn <= mean && mean <= mx && mn >= 0))
			fail_msg("%s: min %g mean %g max %g", name, mn, mean,
			         mx);
		if (!strcmp(name, "floor") && fabs(area - 12.0) > 0.06)
			fail_msg("floor area %g m2, want 12", area);
		if (!strcmp(name, "ceiling") && fabs(area - 12.0) > 0.06)
			fail_msg("ceiling area %g m2, want 12", area);
		if (!strncmp(name, "luminaire", 9) &&
		    fabs(area - 0.36) > 0.01 && fabs(area - 0.72) > 0.01)
			fail_msg("%s area %g m2, want 0.36 (one side) or "
			         "0.72",
			         name, area);
	}
	for (int k = 0; meshes[k]; k++)
		if (seen[k] != 1)
			fail_msg("node %s appears %d times in query.surfaces",
			         meshes[k], seen[k]);
	assert_int_equal(json_array_size(s), 7);
	json_decref(r);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

/* ------------------------------------------------- node grids, luminaires */

/* One face of query.node: its grid, statistics and the points behind
 * them (a cell centre re-asked through query.points gives its lux). */
static void check_face(dm_conn *c, const json_t *job, const json_t *f,
                       const char *what)
{
	long long nu = dm_int(f, "nu"), nv = dm_int(f, "nv");
	json_t *lux = dm_get(f, "lux");
	const json_t *o = dm_get(f, "origin"), *u = dm_get(f, "u"),
	             *v = dm_get(f, "v"), *n = dm_get(f, "normal");
	double lu = 0, lv = 0, mn = HUGE_VAL, mx = 0, sum = 0;
	long long on = 0;
	for (int k = 0; k < 3; k++) {
		double a = json_number_value(json_array_get(u, k));
		double b = json_number_value(json_array_get(v, k));
		lu += a * a;
		lv += b * b;
	}
	lu = sqrt(lu);
	lv = sqrt(lv);
	double sp = dm_num(f, "spacing");
	if (fabs(sp - en12464_spacing(lu > lv ? lu : lv)) > 1e-9 * sp)
		fail_msg("%s: spacing %g for sides %g, %g", what, sp, lu, lv);
	if (nu != (long long)ceil(lu / sp) || nv != (long long)ceil(lv / sp))
		fail_msg("%s: %lld x %lld cells for %g x %g at %g", what, nu,
		         nv, lu, lv, sp);
	assert_int_equal(json_array_size(lux), (size_t)(nu * nv));
	long long probe = -1;
	for (size_t i = 0; i < json_array_size(lux); i++) {
		json_t *x = json_array_get(lux, i);
		if (json_is_null(x))
			continue;
		double e = json_number_value(x);
		on++;
		mn = e < mn ? e : mn;
		mx = e > mx ? e : mx;
		sum += e;
		if (probe < 0 && e > 0)
			probe = (long long)i;
	}
	assert_int_equal(dm_int(f, "points"), on);
	if (on == 0)
		return;
	double mean = sum / on;
	if (fabs(dm_num(f, "min") - mn) > 1e-9 * mx ||
	    fabs(dm_num(f, "max") - mx) > 1e-9 * mx ||
	    fabs(dm_num(f, "mean") - mean) > 1e-9 * mx)
		fail_msg("%s: min/mean/max %g %g %g, want %g %g %g", what,
		         dm_num(f, "min"), dm_num(f, "mean"), dm_num(f, "max"),
		         mn, mean, mx);
	if (fabs(dm_num(f, "u0") - mn / mean) > 1e-9 ||
	    fabs(dm_num(f, "ud") - mn / mx) > 1e-9)
		fail_msg("%s: u0 %g ud %g", what, dm_num(f, "u0"),
		         dm_num(f, "ud"));
	if (probe < 0)
		return;
	/* the probe cell's centre, on the face's plane, asked directly */
	double s = (probe % nu + 0.5) / nu, t = (probe / nu + 0.5) / nv;
	double pt[6], got;
	for (int k = 0; k < 3; k++) {
		pt[k] = json_number_value(json_array_get(o, k)) +
		        s * json_number_value(json_array_get(u, k)) +
		        t * json_number_value(json_array_get(v, k));
		pt[3 + k] = json_number_value(json_array_get(n, k));
	}
	dm_query_points(c, job, pt, 1, &got);
	double want = json_number_value(json_array_get(lux, (size_t)probe));
	if (fabs(got - want) > 1e-3 * want + 1e-6)
		fail_msg("%s: cell %lld has %g lux, query.points %g", what,
		         probe, want, got);
}

static void test_query_node_faces_and_luminaires(void **state)
{
	(void)state;
	dm_daemon *d = dm_start(NULL);
	dm_conn *c = dm_open(d, NULL);
	json_t *sc;
	json_t *job = dm_solve_sample(c, "office.gltf", &sc);

	/* the floor: one face, facing up, 12 m2, covered by its grid */
	json_t *fl = dm_ok(c, "{s:s, s:O, s:s}", "cmd", "query.node", "job",
	                   job, "node", "floor");
	json_t *faces = dm_get(fl, "faces");
	assert_int_equal(json_array_size(faces), 1);
	json_t *f0 = json_array_get(faces, 0);
	assert_true(json_number_value(json_array_get(dm_get(f0, "normal"), 1)) >
	            0.999);
	assert_true(fabs(dm_num(fl, "area") - 12.0) < 0.06);
	check_face(c, job, f0, "floor");
	assert_true(dm_int(fl, "points") ==
	            dm_int(f0, "nu") * dm_int(f0, "nv"));
	assert_true(dm_num(fl, "min") <= dm_num(fl, "mean") &&
	            dm_num(fl, "mean") <= dm_num(fl, "max"));

	/* by index, the same answer */
	json_t *byi = dm_ok(c, "{s:s, s:O, s:I}", "cmd", "query.node", "job",
	                    job, "node", (json_int_t)dm_int(fl, "node"));
	assert_true(dm_num(byi, "mean") == dm_num(fl, "mean"));

	/* the walls: four vertical faces, each checked, points adding up */
	json_t *w = dm_ok(c, "{s:s, s:O, s:s}", "cmd", "query.node", "job", job,
	                  "node", "walls");
	faces = dm_get(w, "faces");
	assert_int_equal(json_array_size(faces), 4);
	long long pts = 0;
	size_t i;
	json_t *f;
	json_array_foreach(faces, i, f)
	{
		double ny = json_number_value(
		        json_array_get(dm_get(f, "normal"), 1));
		assert_true(fabs(ny) < 1e-6);
		check_face(c, job, f, "walls");
		pts += dm_int(f, "points");
	}
	assert_int_equal(dm_int(w, "points"), pts);

	/* a spacing asked is used on every face */
	json_t *sp = dm_ok(c, "{s:s, s:O, s:s, s:f}", "cmd", "query.node",
	                   "job", job, "node", "ceiling", "spacing", 0.5);
	assert_true(dm_num(json_array_get(dm_get(sp, "faces"), 0), "spacing") ==
	            0.5);

	/* bad input */
	json_decref(dm_err(c, "not_found", "{s:s, s:O, s:s}", "cmd",
	                   "query.node", "job", job, "node", "no such node"));
	json_decref(dm_err(c, "not_found", "{s:s, s:O, s:i}", "cmd",
	                   "query.node", "job", job, "node", 9999));
	json_decref(dm_err(c, "bad_request", "{s:s, s:O, s:i}", "cmd",
	                   "query.node", "job", job, "node", -1));
	json_decref(dm_err(c, "bad_request", "{s:s, s:O, s:b}", "cmd",
	                   "query.node", "job", job, "node", 1));
	json_decref(dm_err(c, "bad_request", "{s:s, s:O}", "cmd", "query.node",
	                   "job", job));
	json_decref(dm_err(c, "bad_request", "{s:s, s:O, s:s, s:f}", "cmd",
	                   "query.node", "job", job, "node", "floor", "spacing",
	                   0.0));
	json_decref(dm_err(c, "bad_request", "{s:s, s:O, s:s, s:f}", "cmd",
	                   "query.node", "job", job, "node", "floor", "spacing",
	                   1e-4));
	json_decref(dm_err(c, "not_found", "{s:s, s:i, s:s}", "cmd",
	                   "query.node", "job", 9999, "node", "floor"));

	/* scene.info's luminaires: the two emitting panels, the lamp */
	json_t *si = dm_ok(c, "{s:s, s:O}", "cmd", "scene.info", "scene", sc);
	json_t *lum = dm_get(si, "luminaires");
	json_t *em = dm_get(lum, "emitters"), *lights = dm_get(lum, "lights");
	assert_int_equal(json_array_size(em), 2);
	json_array_foreach(em, i, f)
	{
		assert_true(!strncmp(json_string_value(dm_get(f, "name")),
		                     "luminaire_", 10));
		assert_true(
		        dm_num(f, "flux_lm") > 0 &&
		        fabs(dm_num(f, "flux_lm") -
		             dm_num(f, "exitance_lux") * dm_num(f, "area")) <
		                1e-6 * dm_num(f, "flux_lm"));
	}
	assert_int_equal(json_array_size(lights),
	                 dm_int(dm_get(si, "counts"), "lights"));
	assert_string_equal(
	        json_string_value(dm_get(json_array_get(lights, 0), "name")),
	        "desk_lamp");
	assert_true(dm_num(json_array_get(lights, 0), "candela") > 0);

	/* query.surfaces' bounds: the floor is flat */
	json_t *qs =
	        dm_ok(c, "{s:s, s:O}", "cmd", "query.surfaces", "job", job);
	json_array_foreach(dm_get(qs, "surfaces"), i, f)
	{
		if (strcmp(json_string_value(dm_get(f, "name")), "floor"))
			continue;
		json_t *b = dm_get(f, "bounds");
		assert_true(
		        json_number_value(
		                json_array_get(dm_get(b, "min"), 1)) ==
		        json_number_value(json_array_get(dm_get(b, "max"), 1)));
	}
	json_decref(qs);
	json_decref(si);
	json_decref(sp);
	json_decref(w);
	json_decref(byi);
	json_decref(fl);
	json_decref(job);
	json_decref(sc);
	dm_pass();
}

int main(void)
{
	const struct CMUnitTest tests[] = {
#define T(f) cmocka_unit_test_setup_teardown(f, dm_setup, dm_teardown)
	        T(test_upload_reports_what_luxrad_solve_reports),
	        T(test_query_points_equal_luxrad_solve),
	        T(test_split_query_equals_small_queries),
	        T(test_pipelined_requests_are_answered_in_order),
	        T(test_query_grid_cells_spacing_and_uniformity),
	        T(test_query_grid_leaves_out_inside_objects),
	        T(test_query_surfaces_per_node),
	        T(test_query_node_faces_and_luminaires),
#undef T
	};
	const char *filter = getenv("LUXRAD_TEST_FILTER");
	if (filter)
		cmocka_set_test_filter(filter);
	return cmocka_run_group_tests(tests, NULL, NULL);
}
