/*
 * query_cmd.c -- query.points, query.grid, query.surfaces, query.node and
 * export, run on the query threads.
 *
 * The I/O thread validates the request, takes a reference to the job's
 * latest published solution (a pointer copy under the job's mutex: it
 * never waits for a step) and submits a task.  The task computes on its
 * own thread from that immutable solution -- the solver keeps stepping
 * meanwhile -- builds and encodes the reply there (a million lux values
 * are no work for the I/O thread either), and the I/O thread only
 * queues the bytes.  A solution holds its scene, so a job or scene
 * deleted meanwhile stays readable until the task ends.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "engine_json.h"
#include "export.h"
#include "log.h"

typedef enum query_kind {
	Q_POINTS = 0,
	Q_GRID,
	Q_SURFACES,
	Q_NODE,
	Q_EXPORT
} query_kind;

typedef struct query_task {
	srv_task t;
	query_kind kind;
	uint64_t job;
	srv_sol *sol; /* ref */
	double *pts;  /* 6 per point (points, grid) */
	size_t n;
	int nu, nv;      /* grid */
	double spacing;  /* grid */
	int want_points; /* grid: include coordinates */
	uint32_t node;   /* node */
	int max_points;  /* node: the daemon's limit, checked on the pool */
	rp_err fail;     /* node: the wire error, when not the engine's */
	/* result */
	unsigned char *out, *payload;
	size_t out_len, payload_len;
} query_task;

static double len3(const double v[3])
{
	return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

static void cross3(const double a[3], const double b[3], double out[3])
{
	out[0] = a[1] * b[2] - a[2] * b[1];
	out[1] = a[2] * b[0] - a[0] * b[2];
	out[2] = a[0] * b[1] - a[1] * b[0];
}

/* ---------------------------------------------------------- on the pool */

static json_t *reply_base(query_task *q)
{
	json_t *reply = rp_reply_ok(q->t.id);
	json_object_set_new(reply, "job", json_integer((json_int_t)q->job));
	json_object_set_new(reply, "iteration",
	                    json_integer(q->sol->iteration));
	return reply;
}

/* The array of n values, as a reply member. */
static json_t *values_json(const double *v, size_t n)
{
	json_t *arr = json_array();
	for (size_t i = 0; i < n; i++)
		json_array_append_new(arr, ej_real(v[i]));
	return arr;
}

/* The query's lux (lux holds 2 n values: the lux, then their error
 * estimates) and the reply's common members; NULL with err. */
static json_t *gather_lux(cmd_server *d, query_task *q, double *lux,
                          rad_error *err)
{
	if (srv_query_illuminance(&d->core, q->sol, q->pts, q->n, lux,
	                          lux + q->n, err) != RAD_OK)
		return NULL;
	return reply_base(q);
}

static json_t *run_points(cmd_server *d, query_task *q, double *lux,
                          rad_error *err)
{
	json_t *reply = gather_lux(d, q, lux, err);
	if (!reply)
		return NULL;
	json_object_set_new(reply, "lux", values_json(lux, q->n));
	json_object_set_new(reply, "error_lux", values_json(lux + q->n, q->n));
	return reply;
}

typedef struct lux_stats {
	double mn, mx, sum, w, emax;
	size_t n;
} lux_stats;

static void stats_add(lux_stats *st, double lux, double elux, double w)
{
	if (st->n++ == 0)
		st->mn = st->mx = lux;
	st->mn = lux < st->mn ? lux : st->mn;
	st->mx = lux > st->mx ? lux : st->mx;
	st->sum += lux * w;
	st->w += w;
	st->emax = elux > st->emax ? elux : st->emax;
}

/* The values of the points not left out (skip[i] 0), null for the
 * others. */
static json_t *kept_json(const double *v, const unsigned char *skip, size_t n)
{
	json_t *arr = json_array();
	for (size_t i = 0; i < n; i++)
		json_array_append_new(arr,
		                      skip[i] ? json_null() : ej_real(v[i]));
	return arr;
}

/*
 * query.grid.  A point inside a closed object (a work plane through a
 * cabinet: rad_scene_points_inside) is left out: null in lux and
 * error_lux, not in min, mean, max or u0, counted in "inside".  No light
 * reaches it, and counted it made Emin 0 in every furnished room.
 */
static json_t *run_grid(cmd_server *d, query_task *q, double *lux,
                        rad_error *err)
{
	unsigned char *skip = calloc(q->n ? q->n : 1, 1);
	if (!skip) {
		q->fail = RP_ERR_NOMEM;
		snprintf(err->msg, sizeof(err->msg), "out of memory");
		return NULL;
	}
	if (rad_scene_points_inside(q->sol->scene->scene, q->pts, q->n, skip,
	                            err) != RAD_OK) {
		free(skip);
		return NULL;
	}
	json_t *reply = gather_lux(d, q, lux, err);
	if (!reply) {
		free(skip);
		return NULL;
	}
	lux_stats st = {0};
	for (size_t i = 0; i < q->n; i++)
		if (!skip[i])
			stats_add(&st, lux[i], lux[q->n + i], 1);
	size_t kept = st.n;
	double mn = st.mn, mx = st.mx, emax = st.emax;
	double mean = kept ? st.sum / st.w : 0;
	json_object_set_new(reply, "nu", json_integer(q->nu));
	json_object_set_new(reply, "nv", json_integer(q->nv));
	json_object_set_new(reply, "spacing", ej_real(q->spacing));
	json_object_set_new(reply, "inside",
	                    json_integer((json_int_t)(q->n - kept)));
	json_object_set_new(reply, "lux", kept_json(lux, skip, q->n));
	json_object_set_new(reply, "error_lux",
	                    kept_json(lux + q->n, skip, q->n));
	json_object_set_new(reply, "error_max", ej_real(emax));
	json_object_set_new(reply, "min", kept ? ej_real(mn) : json_null());
	json_object_set_new(reply, "mean", kept ? ej_real(mean) : json_null());
	json_object_set_new(reply, "max", kept ? ej_real(mx) : json_null());
	json_object_set_new(reply, "u0",
	                    mean > 0 ? ej_real(mn / mean) : json_null());
	if (q->want_points) {
		json_t *pa = json_array();
		for (size_t i = 0; i < q->n; i++) {
			const double *p = q->pts + 6 * i;
			json_array_append_new(
			        pa, json_pack("[fff]", p[0], p[1], p[2]));
		}
		json_object_set_new(reply, "points", pa);
	}
	free(skip);
	return reply;
}

typedef struct surf_acc {
	double area, sum, mn, mx;
	double lo[3], hi[3]; /* bounds of the leaves */
	uint64_t leaves;
} surf_acc;

typedef struct surf_ctx {
	surf_acc *acc;
	uint32_t n;
} surf_ctx;

static void surf_leaf(void *ud, uint32_t node, const double p[4][3], int nv,
                      const double radiosity[3], const double irr[3])
{
	surf_ctx *c = ud;
	double a[3] = {0, 0, 0};
	(void)radiosity;
	if (node >= c->n)
		return;
	for (int i = 1; i + 1 < nv; i++) {
		double e1[3], e2[3], x[3];
		for (int k = 0; k < 3; k++) {
			e1[k] = p[i][k] - p[0][k];
			e2[k] = p[i + 1][k] - p[0][k];
		}
		cross3(e1, e2, x);
		for (int k = 0; k < 3; k++)
			a[k] += x[k];
	}
	double area = 0.5 * len3(a);
	double lux =
	        RAD_LUMA_R * irr[0] + RAD_LUMA_G * irr[1] + RAD_LUMA_B * irr[2];
	surf_acc *s = &c->acc[node];
	if (s->leaves++ == 0) {
		s->mn = s->mx = lux;
		memcpy(s->lo, p[0], sizeof(s->lo));
		memcpy(s->hi, p[0], sizeof(s->hi));
	} else {
		s->mn = lux < s->mn ? lux : s->mn;
		s->mx = lux > s->mx ? lux : s->mx;
	}
	for (int i = 0; i < nv; i++)
		for (int k = 0; k < 3; k++) {
			s->lo[k] = p[i][k] < s->lo[k] ? p[i][k] : s->lo[k];
			s->hi[k] = p[i][k] > s->hi[k] ? p[i][k] : s->hi[k];
		}
	s->area += area;
	s->sum += lux * area;
}

static json_t *run_surfaces(query_task *q, rad_error *err)
{
	const rad_scene *sc = q->sol->scene->scene;
	surf_ctx c = {NULL, q->sol->scene->counts.nodes};
	c.acc = calloc(c.n ? c.n : 1, sizeof(*c.acc));
	if (!c.acc) {
		err->code = RAD_ERR_NOMEM;
		snprintf(err->msg, sizeof(err->msg), "surfaces: out of memory");
		return NULL;
	}
	rad_solution_leaves(q->sol->sol, surf_leaf, &c);
	json_t *reply = reply_base(q), *arr = json_array();
	for (uint32_t i = 0; i < c.n; i++) {
		surf_acc *s = &c.acc[i];
		if (s->leaves == 0 || !(s->area > 0))
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "node", json_integer(i));
		json_object_set_new(o, "name",
		                    json_string(rad_scene_node_name(sc, i)));
		json_object_set_new(o, "area", ej_real(s->area));
		json_object_set_new(o, "min", ej_real(s->mn));
		json_object_set_new(o, "mean", ej_real(s->sum / s->area));
		json_object_set_new(o, "max", ej_real(s->mx));
		json_object_set_new(o, "bounds",
		                    json_pack("{s:[fff], s:[fff]}", "min",
		                              s->lo[0], s->lo[1], s->lo[2],
		                              "max", s->hi[0], s->hi[1],
		                              s->hi[2]));
		json_array_append_new(arr, o);
	}
	free(c.acc);
	json_object_set_new(reply, "surfaces", arr);
	return reply;
}

/*
 * query.node: the node's faces (rad_scene_node_faces), each sampled on its
 * own grid at its own EN 12464-1 spacing (or the one asked), the points on
 * the polygons gathered in one call.  Statistics per face over its points
 * (they carry equal areas); the node's mean weights each point by its
 * cell's area, so a finely gridded small face does not outweigh a large
 * one.
 */
#define NODE_FACES_MAX 16

typedef struct node_face {
	rad_face f;
	int nu, nv;
	double spacing, cell_m2;
	size_t first, n; /* cells: first index, count */
} node_face;

static void stats_json(json_t *o, const lux_stats *st)
{
	double mean = st->w > 0 ? st->sum / st->w : 0;
	int any = st->n > 0;
	json_object_set_new(o, "points", json_integer((json_int_t)st->n));
	json_object_set_new(o, "min", any ? ej_real(st->mn) : json_null());
	json_object_set_new(o, "mean", any ? ej_real(mean) : json_null());
	json_object_set_new(o, "max", any ? ej_real(st->mx) : json_null());
	json_object_set_new(o, "u0",
	                    any && mean > 0 ? ej_real(st->mn / mean)
	                                    : json_null());
	json_object_set_new(o, "ud",
	                    any && st->mx > 0 ? ej_real(st->mn / st->mx)
	                                      : json_null());
	json_object_set_new(o, "error_max",
	                    any ? ej_real(st->emax) : json_null());
}

static json_t *vec_json(const double v[3])
{
	return json_pack("[fff]", v[0], v[1], v[2]);
}

/* Plan the faces' grids; the number of cells, or 0 with q->fail set. */
static size_t node_plan(query_task *q, node_face *nf, int n, rad_error *err)
{
	size_t cells = 0;
	for (int i = 0; i < n; i++) {
		double lu = len3(nf[i].f.u), lv = len3(nf[i].f.v);
		double sp = q->spacing > 0 ? q->spacing
		                           : rp_grid_spacing(lu > lv ? lu : lv);
		double nu = lu > 0 ? ceil(lu / sp) : 1;
		double nv = lv > 0 ? ceil(lv / sp) : 1;
		if ((double)cells + nu * nv > (double)q->max_points) {
			q->fail = RP_ERR_BAD_REQUEST;
			snprintf(err->msg, sizeof(err->msg),
			         "node %u: the grids have over max_points (%d) "
			         "points: use a larger \"spacing\"",
			         q->node, q->max_points);
			return 0;
		}
		nf[i].nu = (int)nu;
		nf[i].nv = (int)nv;
		nf[i].spacing = sp;
		nf[i].cell_m2 = (lu > 0 ? lu / nu : 0) * (lv > 0 ? lv / nv : 0);
		nf[i].first = cells;
		nf[i].n = (size_t)nf[i].nu * (size_t)nf[i].nv;
		cells += nf[i].n;
	}
	return cells;
}

/* One face of the reply: its frame, grid, values (null off the face). */
static json_t *face_json(const node_face *nf, const unsigned char *on,
                         const double *lux, const double *elux, lux_stats *node)
{
	json_t *o = json_object(), *l = json_array(), *e = json_array();
	lux_stats st = {0};
	for (size_t k = nf->first; k < nf->first + nf->n; k++) {
		if (!on[k]) {
			json_array_append_new(l, json_null());
			json_array_append_new(e, json_null());
			continue;
		}
		stats_add(&st, lux[k], elux[k], 1);
		stats_add(node, lux[k], elux[k], nf->cell_m2);
		json_array_append_new(l, ej_real(lux[k]));
		json_array_append_new(e, ej_real(elux[k]));
	}
	json_object_set_new(o, "normal", vec_json(nf->f.normal));
	json_object_set_new(o, "origin", vec_json(nf->f.origin));
	json_object_set_new(o, "u", vec_json(nf->f.u));
	json_object_set_new(o, "v", vec_json(nf->f.v));
	json_object_set_new(o, "area", ej_real(nf->f.area_m2));
	json_object_set_new(o, "polygons", json_integer(nf->f.polygons));
	json_object_set_new(o, "nu", json_integer(nf->nu));
	json_object_set_new(o, "nv", json_integer(nf->nv));
	json_object_set_new(o, "spacing", ej_real(nf->spacing));
	stats_json(o, &st);
	json_object_set_new(o, "lux", l);
	json_object_set_new(o, "error_lux", e);
	return o;
}

/* Sample every face, gather the points on them; lux and elux per cell. */
static int node_gather(cmd_server *d, query_task *q, const node_face *nf, int n,
                       size_t cells, unsigned char *on, double *lux,
                       double *elux, rad_error *err)
{
	const rad_scene *sc = q->sol->scene->scene;
	double *pts = malloc(cells * 6 * sizeof(double));
	size_t m = 0;
	if (!pts)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory for %zu "
		                "points",
		                cells);
	for (int i = 0; i < n; i++) {
		size_t non;
		if (rad_scene_face_sample(sc, q->node, &nf[i].f, nf[i].nu,
		                          nf[i].nv, pts + 6 * nf[i].first,
		                          on + nf[i].first, &non,
		                          err) != RAD_OK) {
			free(pts);
			return -1;
		}
	}
	for (size_t k = 0; k < cells; k++) /* compact: the points on */
		if (on[k])
			memmove(pts + 6 * m++, pts + 6 * k, 6 * sizeof(double));
	int rc = m ? srv_query_illuminance(&d->core, q->sol, pts, m, lux, elux,
	                                   err)
	           : RAD_OK;
	free(pts);
	if (rc != RAD_OK)
		return -1;
	for (size_t k = cells, j = m; k-- > 0;) /* spread back */
		if (on[k]) {
			j--;
			lux[k] = lux[j];
			elux[k] = elux[j];
		}
	return 0;
}

static json_t *run_node(cmd_server *d, query_task *q, rad_error *err)
{
	const rad_scene *sc = q->sol->scene->scene;
	rad_face faces[NODE_FACES_MAX];
	node_face nf[NODE_FACES_MAX];
	int n;
	double skipped;
	if (rad_scene_node_faces(sc, q->node, faces, NODE_FACES_MAX, &n,
	                         &skipped, err) != RAD_OK)
		return NULL;
	for (int i = 0; i < n; i++)
		nf[i].f = faces[i];
	size_t cells = node_plan(q, nf, n, err);
	if (q->fail)
		return NULL;
	unsigned char *on = calloc(cells ? cells : 1, 1);
	double *lux = malloc((cells ? 2 * cells : 1) * sizeof(double));
	json_t *reply = NULL;
	if (!on || !lux)
		rad_fail(err, RAD_ERR_NOMEM, "out of memory for %zu points",
		         cells);
	else if (node_gather(d, q, nf, n, cells, on, lux, lux + cells, err) ==
	         0) {
		reply = reply_base(q);
		json_t *arr = json_array();
		lux_stats st = {0};
		double area = skipped;
		for (int i = 0; i < n; i++) {
			json_array_append_new(arr, face_json(&nf[i], on, lux,
			                                     lux + cells, &st));
			area += nf[i].f.area_m2;
		}
		json_object_set_new(reply, "node", json_integer(q->node));
		json_object_set_new(
		        reply, "name",
		        json_string(rad_scene_node_name(sc, q->node)));
		json_object_set_new(reply, "area", ej_real(area));
		json_object_set_new(reply, "area_skipped", ej_real(skipped));
		stats_json(reply, &st);
		json_object_set_new(reply, "faces", arr);
	}
	free(on);
	free(lux);
	return reply;
}

static json_t *run_export(query_task *q, rad_error *err)
{
	sio_export_opts o;
	sio_export_info info = {0};
	sio_export_opts_default(&o);
	if (sio_export_solution(q->sol->scene->scene, q->sol->sol, &o,
	                        &q->payload, &q->payload_len, &info,
	                        err) != RAD_OK)
		return NULL;
	json_t *reply = reply_base(q);
	json_object_set_new(reply, "vertices",
	                    json_integer((json_int_t)info.vertices));
	json_object_set_new(reply, "triangles",
	                    json_integer((json_int_t)info.triangles));
	return reply;
}

static void query_run(srv *s, srv_task *t)
{
	cmd_server *d = cmd_of(s);
	query_task *q = (query_task *)t;
	rad_error err = {0};
	json_t *reply = NULL;
	double *lux = NULL;

	if (q->kind == Q_POINTS || q->kind == Q_GRID) {
		lux = malloc((q->n ? 2 * q->n : 1) * sizeof(double));
		if (!lux) {
			err.code = RAD_ERR_NOMEM;
			snprintf(err.msg, sizeof(err.msg),
			         "out of memory for %zu values", q->n);
		}
	}
	if (q->kind == Q_POINTS && lux)
		reply = run_points(d, q, lux, &err);
	else if (q->kind == Q_GRID && lux)
		reply = run_grid(d, q, lux, &err);
	else if (q->kind == Q_SURFACES)
		reply = run_surfaces(q, &err);
	else if (q->kind == Q_NODE)
		reply = run_node(d, q, &err);
	else if (q->kind == Q_EXPORT)
		reply = run_export(q, &err);
	free(lux);
	if (!reply)
		reply = rp_reply_error(
		        t->id, q->fail ? q->fail : cmd_err_from_rad(err.code),
		        "%s", err.msg[0] ? err.msg : "query failed");
	int rc = q->payload ? rp_frame_encode_header(reply, q->payload_len,
	                                             &q->out, &q->out_len)
	                    : rp_frame_encode(reply, NULL, 0, &q->out,
	                                      &q->out_len);
	if (rc != 0) {
		free(q->payload);
		q->payload = NULL;
		json_t *e = rp_reply_error(t->id, RP_ERR_NOMEM,
		                           "out of memory encoding the reply");
		if (rp_frame_encode(e, NULL, 0, &q->out, &q->out_len) != 0)
			q->out = NULL;
		json_decref(e);
	}
	json_decref(reply);
}

static void query_done(srv *s, srv_task *t)
{
	cmd_server *d = cmd_of(s);
	query_task *q = (query_task *)t;
	if (q->out)
		cmd_reply_deferred_raw(d, t->conn_id, q->out, q->out_len,
		                       q->payload, q->payload_len);
	else /* nothing to send: at least release the connection */
		cmd_reply_deferred(d, t->conn_id, NULL);
	srv_sol_unref(s, q->sol);
	free(q->pts);
	json_decref(t->id);
	free(q);
}

/* -------------------------------------------------------- on the I/O side */

/* A task for the job in the request, holding its latest solution. */
static query_task *begin(cmd_req *r, query_kind kind)
{
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return NULL;
	pthread_mutex_lock(&j->mu);
	srv_sol *sol = j->sol;
	uint32_t iter = j->iteration;
	if (sol)
		srv_sol_ref(sol);
	pthread_mutex_unlock(&j->mu);
	if (!sol) {
		if (iter == 0)
			cmd_req_fail(r, RP_ERR_STATE,
			             "job %llu has no solution yet: it has not "
			             "completed an iteration",
			             (unsigned long long)j->id);
		else
			cmd_req_fail(r, RP_ERR_STATE,
			             "job %llu has no solution now: its "
			             "checkpoint of iteration %u was not "
			             "restored at the daemon's start (see its "
			             "log); a done, queued or running job "
			             "replays it, a paused one when resumed",
			             (unsigned long long)j->id, iter);
		return NULL;
	}
	query_task *q = calloc(1, sizeof(*q));
	if (!q) {
		srv_sol_unref(r->s, sol);
		cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
		return NULL;
	}
	q->kind = kind;
	q->job = j->id;
	q->sol = sol;
	return q;
}

static cmd_result submit(cmd_req *r, query_task *q)
{
	return cmd_req_defer(r, &r->s->query_pool, &q->t, query_run,
	                     query_done);
}

static cmd_result abandon(cmd_req *r, query_task *q)
{
	srv_sol_unref(r->s, q->sol);
	free(q->pts);
	json_decref(q->t.id);
	free(q);
	return CMD_ERROR;
}

cmd_result cmd_query_points(cmd_req *r)
{
	query_task *q = begin(r, Q_POINTS);
	if (!q)
		return CMD_ERROR;
	if (rp_arg_points(r->hdr, "points", (size_t)r->s->cfg.max_points,
	                  &q->pts, &q->n, &r->err) != 0)
		return abandon(r, q);
	if (q->n == 0) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST, "\"points\" is empty");
		return abandon(r, q);
	}
	return submit(r, q);
}

/* Grid geometry from the request; fills q->pts. */
static int grid_points(cmd_req *r, query_task *q)
{
	double o[3], u[3], v[3], nrm[3], sp = 0;
	int want = 0;
	if (rp_arg_vec(r->hdr, "origin", 1, o, 3, &r->err) != 0 ||
	    rp_arg_vec(r->hdr, "u", 1, u, 3, &r->err) != 0 ||
	    rp_arg_vec(r->hdr, "v", 1, v, 3, &r->err) != 0)
		return -1;
	int hn = rp_arg_vec(r->hdr, "normal", 0, nrm, 3, &r->err);
	int hs =
	        hn < 0 ? -1 : rp_arg_double(r->hdr, "spacing", 0, &sp, &r->err);
	if (hs < 0 || rp_arg_bool(r->hdr, "points", 0, &want, &r->err) < 0)
		return -1;
	double lu = len3(u), lv = len3(v), x[3];
	cross3(u, v, x);
	if (!(lu > 0) || !(lv > 0) || !(len3(x) > 1e-12 * lu * lv)) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		             "degenerate rectangle: \"u\" and \"v\" must be "
		             "non-zero and not parallel");
		return -1;
	}
	if (hn != 0)
		memcpy(nrm, x, sizeof(nrm));
	else if (!(len3(nrm) > 0)) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST, "\"normal\" is zero");
		return -1;
	}
	if (hs == 0 && !(sp > 0)) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		             "\"spacing\" must be > 0 (got %g)", sp);
		return -1;
	}
	if (hs != 0)
		sp = rp_grid_spacing(lu > lv ? lu : lv);
	double nu = ceil(lu / sp), nv = ceil(lv / sp);
	if (nu * nv > (double)r->s->cfg.max_points) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		             "the grid has %.0f x %.0f points, over max_points "
		             "(%d): use a larger \"spacing\"",
		             nu, nv, r->s->cfg.max_points);
		return -1;
	}
	q->nu = (int)nu;
	q->nv = (int)nv;
	q->n = (size_t)q->nu * (size_t)q->nv;
	q->spacing = sp;
	q->want_points = want;
	q->pts = malloc(q->n * 6 * sizeof(double));
	if (!q->pts) {
		cmd_req_fail(r, RP_ERR_NOMEM, "out of memory for the grid");
		return -1;
	}
	for (int jv = 0; jv < q->nv; jv++) {
		for (int iu = 0; iu < q->nu; iu++) {
			double s = (iu + 0.5) / nu, t = (jv + 0.5) / nv;
			double *p = q->pts + 6 * ((size_t)jv * q->nu + iu);
			for (int k = 0; k < 3; k++) {
				p[k] = o[k] + s * u[k] + t * v[k];
				p[3 + k] = nrm[k];
			}
		}
	}
	return 0;
}

cmd_result cmd_query_grid(cmd_req *r)
{
	query_task *q = begin(r, Q_GRID);
	if (!q)
		return CMD_ERROR;
	if (grid_points(r, q) != 0)
		return abandon(r, q);
	return submit(r, q);
}

cmd_result cmd_query_surfaces(cmd_req *r)
{
	query_task *q = begin(r, Q_SURFACES);
	return q ? submit(r, q) : CMD_ERROR;
}

/* The request's "node": a name (the first node of that name) or an
 * index; -1 with the error set. */
static int64_t req_node(cmd_req *r, const rad_scene *sc, uint32_t nnodes)
{
	json_t *v = json_object_get(r->hdr, "node");
	if (json_is_string(v)) {
		const char *name = json_string_value(v);
		for (uint32_t i = 0; i < nnodes; i++)
			if (!strcmp(rad_scene_node_name(sc, i), name))
				return i;
		cmd_req_fail(r, RP_ERR_NOT_FOUND, "no node named \"%.100s\"",
		             name);
		return -1;
	}
	if (!json_is_integer(v) || json_integer_value(v) < 0) {
		cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		             "\"node\" must be a node name or a non-negative "
		             "integer index");
		return -1;
	}
	if (json_integer_value(v) >= (json_int_t)nnodes) {
		cmd_req_fail(r, RP_ERR_NOT_FOUND,
		             "no node %lld (the scene has %u)",
		             (long long)json_integer_value(v), nnodes);
		return -1;
	}
	return json_integer_value(v);
}

cmd_result cmd_query_node(cmd_req *r)
{
	double sp = 0;
	int hs = rp_arg_double(r->hdr, "spacing", 0, &sp, &r->err);
	if (hs < 0)
		return CMD_ERROR;
	if (hs == 0 && !(sp > 0))
		return cmd_req_fail(r, RP_ERR_BAD_REQUEST,
		                    "\"spacing\" must be > 0 (got %g)", sp);
	query_task *q = begin(r, Q_NODE);
	if (!q)
		return CMD_ERROR;
	const srv_scene *sc = q->sol->scene;
	int64_t node = req_node(r, sc->scene, sc->counts.nodes);
	if (node < 0)
		return abandon(r, q);
	q->node = (uint32_t)node;
	q->spacing = hs == 0 ? sp : 0;
	q->max_points = r->s->cfg.max_points;
	return submit(r, q);
}

cmd_result cmd_export(cmd_req *r)
{
	const char *fmt = NULL;
	if (rp_arg_string(r->hdr, "format", 0, &fmt, &r->err) < 0)
		return CMD_ERROR;
	if (fmt && strcmp(fmt, "glb") != 0)
		return cmd_req_fail(r, RP_ERR_INVALID,
		                    "unknown export format \"%.32s\" (only "
		                    "\"glb\")",
		                    fmt);
	query_task *q = begin(r, Q_EXPORT);
	return q ? submit(r, q) : CMD_ERROR;
}
