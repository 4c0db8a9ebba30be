/*
 * cmd_report.c -- luxrad report: what a lighting designer reads.  Asks
 * the daemon for the job, its scene (with the luminaires), the nodes,
 * the work plane (query.grid) and each chosen node's faces (query.node),
 * draws every grid as a false-colour PNG (fc_image.h) and writes one
 * self-contained HTML file (report_html.c), atomically: a temporary
 * beside the target, renamed over it once complete.
 *
 * DESIGN
 * The work plane follows EN 12464-1: a horizontal plane at the work
 * height over the room less a border band along the walls, gridded at
 * the standard's spacing (the daemon's default for query.grid).  The room
 * is the floor node's extent when the scene names one (a scene's bounds
 * also hold luminaires hung outside the walls), its height the scene's.
 * Defaults are for rooms people work in; a model room (the 0.55 m Cornell
 * box) would put a 0.8 m plane above its ceiling and a 0.5 m band across
 * its whole floor, so the plane is put at most half way up and the band
 * takes at most a quarter of the shorter side; the report says so when
 * it clipped either.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "client.h"
#include "fc_image.h"

#define DEFAULT_HEIGHT_M 0.8
#define DEFAULT_BORDER_M 0.5
#define MAX_DEFAULT_SURFACES 24

typedef struct report {
	lx_ctx *cx;
	long long job;
	json_t *jobinfo, *scene, *surfaces; /* replies */
	json_t *plane;                      /* query.grid reply, or NULL */
	json_t *nodes;                      /* query.node replies */
	double height_m, border_m;
	char plane_note[400];
	double query_s; /* wall time of the queries */
} report;

/* --------------------------------------------------------------- images */

/* The grid's lux (JSON numbers, null where no point) as a PNG. */
static int grid_png(const json_t *lux, long long nu, long long nv,
                    unsigned char **png, size_t *len)
{
	size_t n = (size_t)(nu * nv);
	double lo = HUGE_VAL, hi = -HUGE_VAL;
	*png = NULL;
	if (nu <= 0 || nv <= 0 || json_array_size(lux) != n)
		return -1;
	double *v = malloc(n * sizeof(double));
	if (!v)
		return -1;
	for (size_t i = 0; i < n; i++) {
		json_t *x = json_array_get(lux, i);
		v[i] = json_is_number(x) ? json_number_value(x) : NAN;
		if (isfinite(v[i])) {
			lo = v[i] < lo ? v[i] : lo;
			hi = v[i] > hi ? v[i] : hi;
		}
	}
	fc_scale s;
	fc_image im;
	fc_scale_auto(lo, hi, &s);
	int rc = fc_render(v, (int)nu, (int)nv, &s, 0, 1, &im);
	if (rc == 0)
		rc = fc_png_encode(&im, png, len);
	fc_image_free(&im);
	free(v);
	return rc;
}

static void figure(FILE *f, const json_t *grid, const char *caption)
{
	unsigned char *png;
	size_t len;
	if (grid_png(json_object_get(grid, "lux"), lx_jint(grid, "nu"),
	             lx_jint(grid, "nv"), &png, &len) != 0) {
		fputs("<p class=\"note\">(no image: the grid is empty or out "
		      "of memory)</p>\n",
		      f);
		return;
	}
	fputs("<figure>", f);
	lx_html_png(f, png, len, caption);
	fputs("<figcaption>", f);
	lx_html_text(f, caption);
	fputs("</figcaption></figure>\n", f);
	free(png);
}

/* -------------------------------------------------------------- queries */

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static json_t *call(report *r, json_t *req)
{
	json_t *reply = NULL;
	double t0 = now_s();
	int rc = lx_call(r->cx, req, &reply);
	r->query_s += now_s() - t0;
	if (rc != LX_EXIT_OK) {
		json_decref(reply);
		return NULL;
	}
	return reply;
}

/* The surface of query.surfaces named name, or NULL. */
static const json_t *surface_named(const report *r, const char *name)
{
	size_t i;
	json_t *s;
	json_array_foreach(json_object_get(r->surfaces, "surfaces"), i, s)
	{
		if (!strcmp(lx_jstr(s, "name"), name))
			return s;
	}
	return NULL;
}

/* The work plane's rectangle; -1 when the room has no floor area. */
static int plane_rect(report *r, double o[3], double u[3], double v[3])
{
	const char *floor = r->cx->val[LX_OPT_FLOOR];
	const json_t *fs = surface_named(r, floor ? floor : "floor");
	const json_t *b = fs ? json_object_get(fs, "bounds")
	                     : json_object_get(r->scene, "bounds");
	const json_t *lo = json_object_get(b, "min"),
	             *hi = json_object_get(b, "max");
	const json_t *shi =
	        json_object_get(json_object_get(r->scene, "bounds"), "max");
	double x0 = json_number_value(json_array_get(lo, 0));
	double x1 = json_number_value(json_array_get(hi, 0));
	double z0 = json_number_value(json_array_get(lo, 2));
	double z1 = json_number_value(json_array_get(hi, 2));
	double y0 = json_number_value(json_array_get(lo, 1));
	double room_h = json_number_value(json_array_get(shi, 1)) - y0;
	double w = x1 - x0, d = z1 - z0, side = w < d ? w : d;
	double h = r->height_m, bb = r->border_m;
	int n = snprintf(r->plane_note, sizeof r->plane_note,
	                 "Room extent from %s%s%s. ",
	                 fs ? "node \"" : "the scene's bounds",
	                 fs ? lx_jstr(fs, "name") : "", fs ? "\"" : "");
	if (!(side > 0) || !(room_h > 0))
		return -1;
	if (h > room_h / 2) {
		h = room_h / 2;
		n += snprintf(r->plane_note + n,
		              sizeof r->plane_note - (size_t)n,
		              "Work plane height %.3g m clipped to %.3g m "
		              "(half the room's %.3g m). ",
		              r->height_m, h, room_h);
	}
	if (bb > side / 4) {
		bb = side / 4;
		snprintf(r->plane_note + n, sizeof r->plane_note - (size_t)n,
		         "Border band %.3g m clipped to %.3g m (a quarter of "
		         "the shorter side, %.3g m).",
		         r->border_m, bb, side);
	}
	r->height_m = h;
	r->border_m = bb;
	double oo[3] = {x0 + bb, y0 + h, z0 + bb};
	double uu[3] = {w - 2 * bb, 0, 0}, vv[3] = {0, 0, d - 2 * bb};
	memcpy(o, oo, sizeof(oo));
	memcpy(u, uu, sizeof(uu));
	memcpy(v, vv, sizeof(vv));
	return 0;
}

static json_t *vec3(const double v[3])
{
	return json_pack("[fff]", v[0], v[1], v[2]);
}

static int query_plane(report *r)
{
	double o[3], u[3], v[3], up[3] = {0, 1, 0};
	if (plane_rect(r, o, u, v) != 0)
		return 0; /* no plane: the report says so */
	json_t *req = rp_request(RP_CMD_QUERY_GRID, -1);
	json_object_set_new(req, "job", json_integer(r->job));
	json_object_set_new(req, "origin", vec3(o));
	json_object_set_new(req, "u", vec3(u));
	json_object_set_new(req, "v", vec3(v));
	json_object_set_new(req, "normal", vec3(up));
	if (!(r->plane = call(r, req)))
		return -1;
	/* what query.node gives and query.grid does not */
	double mn = lx_jdbl(r->plane, "min"), mx = lx_jdbl(r->plane, "max");
	json_object_set_new(r->plane, "ud",
	                    mx > 0 ? json_real(mn / mx) : json_null());
	json_object_set_new(r->plane, "area", json_real(u[0] * v[2]));
	/* Points inside closed objects are left out (query.grid). */
	json_object_set_new(
	        r->plane, "points",
	        json_integer(lx_jint(r->plane, "nu") * lx_jint(r->plane, "nv") -
	                     lx_jint(r->plane, "inside")));
	return 0;
}

static int query_node(report *r, json_t *node)
{
	json_t *req = rp_request(RP_CMD_QUERY_NODE, -1);
	json_object_set_new(req, "job", json_integer(r->job));
	json_object_set_new(req, "node", node);
	json_t *reply = call(r, req);
	if (!reply)
		return -1;
	json_array_append_new(r->nodes, reply);
	return 0;
}

static int query_nodes(report *r)
{
	if (r->cx->nsurfaces > 0) {
		for (int i = 0; i < r->cx->nsurfaces; i++)
			if (query_node(r, json_string(r->cx->surfaces[i])) != 0)
				return -1;
		return 0;
	}
	size_t i;
	json_t *s;
	json_array_foreach(json_object_get(r->surfaces, "surfaces"), i, s)
	{
		if (i >= MAX_DEFAULT_SURFACES)
			break;
		if (query_node(r, json_integer(lx_jint(s, "node"))) != 0)
			return -1;
	}
	return 0;
}

static int gather(report *r)
{
	json_t *req = lx_req_id(RP_CMD_JOB_INFO, "job", r->job);
	json_t *ji = call(r, req);
	if (!ji)
		return -1;
	r->jobinfo = json_incref(json_object_get(ji, "job"));
	json_decref(ji);
	req = lx_req_id(RP_CMD_SCENE_INFO, "scene",
	                lx_jint(r->jobinfo, "scene"));
	if (!(r->scene = call(r, req)))
		return -1;
	req = lx_req_id(RP_CMD_QUERY_SURFACES, "job", r->job);
	if (!(r->surfaces = call(r, req)))
		return -1;
	if (query_plane(r) != 0)
		return -1;
	return query_nodes(r);
}

/* ----------------------------------------------------------------- HTML */

static void stats_cells(FILE *f, const json_t *o)
{
	static const struct {
		const char *k, *fmt;
	} cols[] = {{"points", "%.0f"}, {"spacing", "%.3g"},  {"mean", "%.4g"},
	            {"min", "%.4g"},    {"max", "%.4g"},      {"u0", "%.2f"},
	            {"ud", "%.2f"},     {"error_max", "%.2g"}};
	for (size_t c = 0; c < sizeof(cols) / sizeof(cols[0]); c++) {
		fputs("<td class=\"n\">", f);
		lx_html_num(f, o, cols[c].k, cols[c].fmt);
		fputs("</td>", f);
	}
	fputs("</tr>\n", f);
}

/* The face's caption: its node, which way it faces, its size. */
static void face_caption(const json_t *node, const json_t *face, size_t k,
                         char *buf, size_t len)
{
	const json_t *nrm = json_object_get(face, "normal");
	double n[3];
	for (int i = 0; i < 3; i++)
		n[i] = json_number_value(json_array_get(nrm, (size_t)i));
	const char *dir = n[1] > 0.7    ? "facing up"
	                  : n[1] < -0.7 ? "facing down"
	                  : fabs(n[0]) > fabs(n[2])
	                          ? (n[0] > 0 ? "facing +x" : "facing -x")
	                          : (n[2] > 0 ? "facing +z" : "facing -z");
	snprintf(buf, len, "%s, face %zu (%s, %.3g m2): %.4g lux mean",
	         lx_jstr(node, "name"), k + 1, dir, lx_jdbl(face, "area"),
	         lx_jdbl(face, "mean"));
}

static void surfaces_table(FILE *f, const report *r)
{
	size_t i, k;
	json_t *n, *face;
	fputs("<h2>Calculation surfaces</h2>\n<table id=\"surfaces\"><tr>"
	      "<th>Surface</th><th>Area (m&sup2;)</th><th>Points</th>"
	      "<th>Spacing (m)</th><th>E<sub>m</sub></th><th>E<sub>min"
	      "</sub></th><th>E<sub>max</sub></th><th>U<sub>0</sub></th>"
	      "<th>U<sub>d</sub></th><th>Largest error (lux)</th></tr>\n",
	      f);
	if (r->plane) {
		long long in = lx_jint(r->plane, "inside");
		fprintf(f, "<tr><td>Work plane, %.3g m", r->height_m);
		if (in > 0)
			fprintf(f, " (%lld point%s inside objects left out)",
			        in, in == 1 ? "" : "s");
		fputs("</td><td class=\"n\">", f);
		lx_html_num(f, r->plane, "area", "%.4g");
		fputs("</td>", f);
		stats_cells(f, r->plane);
	}
	json_array_foreach(r->nodes, i, n)
	{
		json_t *faces = json_object_get(n, "faces");
		fputs("<tr><td>", f);
		lx_html_text(f, lx_jstr(n, "name"));
		fputs("</td><td class=\"n\">", f);
		lx_html_num(f, n, "area", "%.4g");
		fputs("</td>", f);
		if (json_array_size(faces) == 1) /* the node's spacing */
			json_object_set(
			        n, "spacing",
			        json_object_get(json_array_get(faces, 0),
			                        "spacing"));
		stats_cells(f, n);
		if (json_array_size(faces) < 2)
			continue;
		json_array_foreach(faces, k, face)
		{
			char cap[400];
			face_caption(n, face, k, cap, sizeof cap);
			fprintf(f,
			        "<tr><td>&nbsp;&nbsp;face %zu</td>"
			        "<td class=\"n\">",
			        k + 1);
			lx_html_num(f, face, "area", "%.4g");
			fputs("</td>", f);
			stats_cells(f, face);
		}
	}
	fputs("</table>\n", f);
}

/* Largest error estimate relative to its surface's mean. */
static double worst_error(const report *r)
{
	double worst = 0;
	size_t i;
	json_t *n;
	if (r->plane && lx_jdbl(r->plane, "mean") > 0)
		worst = lx_jdbl(r->plane, "error_max") /
		        lx_jdbl(r->plane, "mean");
	json_array_foreach(r->nodes, i, n)
	{
		double m = lx_jdbl(n, "mean"), e = lx_jdbl(n, "error_max");
		if (m > 0 && e / m > worst)
			worst = e / m;
	}
	return worst;
}

static void write_html(FILE *f, report *r)
{
	char title[400];
	snprintf(title, sizeof title, "Lighting report: %s, job %lld",
	         lx_jstr(r->scene, "name"), r->job);
	lx_html_head(f, title);
	lx_html_summary(f, r->jobinfo, r->scene);
	surfaces_table(f, r);
	fprintf(f,
	        "<p>Largest error estimate of the table, relative to its "
	        "surface's E<sub>m</sub>: %.2g %%. Queries took %.3f s.</p>\n",
	        100 * worst_error(r), r->query_s);
	fputs("<h2>Work plane</h2>\n<p>", f);
	lx_html_text(f, r->plane_note);
	if (r->plane) {
		fprintf(f,
		        "</p>\n<p>Plan view (x to the right, z down), %.3g m "
		        "above the floor, border band %.3g m, %lld &times; "
		        "%lld points at %.3g m. Isolines at the legend's "
		        "steps.</p>\n",
		        r->height_m, r->border_m, lx_jint(r->plane, "nu"),
		        lx_jint(r->plane, "nv"), lx_jdbl(r->plane, "spacing"));
		figure(f, r->plane, "Work plane, plan view");
	} else {
		fputs(" The room has no floor area: no work plane.</p>\n", f);
	}
	fputs("<h2>Surfaces</h2>\n<p>Each face seen from its front (floors "
	      "and ceilings in plan, x to the right, z down); grey: no "
	      "point (off the polygons).</p>\n",
	      f);
	size_t i, k;
	json_t *n, *face;
	json_array_foreach(r->nodes, i, n)
	{
		json_array_foreach(json_object_get(n, "faces"), k, face)
		{
			char cap[400];
			face_caption(n, face, k, cap, sizeof cap);
			figure(f, face, cap);
		}
	}
	lx_html_foot(f);
}

/* Write the page to a temporary beside path, then rename it over path. */
static int write_file(report *r, const char *path)
{
	size_t len = strlen(path) + 16;
	char *tmp = malloc(len);
	if (!tmp)
		return LX_EXIT_USAGE;
	snprintf(tmp, len, "%s.tmpXXXXXX", path);
	int fd = mkstemp(tmp);
	FILE *f = fd >= 0 ? fdopen(fd, "w") : NULL;
	if (!f) {
		fprintf(stderr, "luxrad: %s: cannot write: %s\n", path,
		        fd >= 0 ? "fdopen failed"
		                : "cannot create a file beside it");
		if (fd >= 0) {
			close(fd);
			unlink(tmp);
		}
		free(tmp);
		return LX_EXIT_USAGE;
	}
	write_html(f, r);
	int bad = ferror(f) | (fflush(f) != 0) | (fsync(fileno(f)) != 0);
	bad |= fclose(f) != 0;
	if (bad || rename(tmp, path) != 0) {
		fprintf(stderr, "luxrad: %s: write failed\n", path);
		unlink(tmp);
		free(tmp);
		return LX_EXIT_DAEMON;
	}
	free(tmp);
	return LX_EXIT_OK;
}

int lx_cmd_report(lx_ctx *cx)
{
	report r = {.cx = cx,
	            .height_m = DEFAULT_HEIGHT_M,
	            .border_m = DEFAULT_BORDER_M};
	const char *out = cx->val[LX_OPT_OUTPUT];
	int rc = lx_pos_id(cx, 0, "job", &r.job);
	if (rc != LX_EXIT_OK)
		return rc;
	if (!out)
		return lx_usage_error(cx, "report needs -o FILE.html");
	if (lx_opt_double(cx, LX_OPT_WORKPLANE_HEIGHT, &r.height_m) < 0 ||
	    lx_opt_double(cx, LX_OPT_BORDER, &r.border_m) < 0)
		return LX_EXIT_USAGE;
	if (!(r.height_m >= 0) || !(r.border_m >= 0))
		return lx_usage_error(cx, "--workplane-height and --border "
		                          "must be >= 0");
	if ((rc = lx_open(cx)) != LX_EXIT_OK)
		return rc;
	r.nodes = json_array();
	if (gather(&r) != 0)
		rc = LX_EXIT_DAEMON;
	else
		rc = write_file(&r, out);
	if (rc == LX_EXIT_OK && !cx->json)
		printf("%s: %s%zu surfaces\n", out,
		       r.plane ? "work plane and " : "no work plane, ",
		       json_array_size(r.nodes));
	else if (rc == LX_EXIT_OK) {
		json_t *o = json_pack("{s:s, s:b, s:i}", "report", out,
		                      "work_plane", r.plane != NULL, "surfaces",
		                      (int)json_array_size(r.nodes));
		lx_print_json(o);
		json_decref(o);
	}
	json_decref(r.jobinfo);
	json_decref(r.scene);
	json_decref(r.surfaces);
	json_decref(r.plane);
	json_decref(r.nodes);
	return rc;
}
