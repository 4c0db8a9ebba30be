/*
 * hr_nodes.c -- link endpoints for the hierarchical solvers (hr_nodes.h).
 *
 * Clusters are volumes seen through their projected area P(d) (hier.h):
 * as an emitter a cluster of mean radiosity B sends intensity B P(d) / pi
 * towards d (Sillion's isotropic cluster, 1995, had A / 4 in every
 * direction); as a receiver it takes in normal irradiance times P(u) over
 * its area A, u towards the source, and the push shares that power out
 * among the polygons inside by their orientation (hier.h).  Reciprocity
 * holds with the true area: A_r F(r <- s) = A_s F(s <- r).  A link's form
 * factor is made for uniform radiosity over a source cluster; the gather
 * uses it times node_emit_factor, what the cluster's brighter and darker
 * sides send towards the receiver.
 *
 * Sample points of a cluster are the centroids of up to n of its polygons,
 * spread over its range of order[], with those polygons' normals, so that
 * shadow rays start on real surfaces rather than inside objects; a point
 * whose polygon faces away from the other end is left out (ff_iso).
 */
#include "hr_nodes.h"

#include <math.h>

#include "vis.h"

static const rad_light *node_light(const rad_hier *h, uint32_t t)
{
	return &h->scene->lights[node_index(t)];
}

static void elem_patch(const rad_hier *h, uint32_t id, rad_patch *p)
{
	rad_elem_patch_id(h, id, p);
}

double node_luma_B(const rad_hier *h, uint32_t t)
{
	double b[3];
	node_B(h, t, b);
	return RAD_LUMA_R * b[0] + RAD_LUMA_G * b[1] + RAD_LUMA_B * b[2];
}

void node_B(const rad_hier *h, uint32_t t, double out[3])
{
	const float *b;
	if (node_is_light(t)) {
		for (int c = 0; c < 3; c++)
			out[c] = node_light(h, t)->intensity[c];
		return;
	}
	b = node_is_cluster(t) ? rad_cluster_at(h, t)->B : rad_elem_at(h, t)->B;
	for (int c = 0; c < 3; c++)
		out[c] = b[c];
	if (!node_is_cluster(t))
		node_exposed_emission(h, t, out);
}

void node_exposed_emission(const rad_hier *h, uint32_t t, double b[3])
{
	if (rad_elem_exposed_raw(h, t) == RAD_EXPOSED_ALL)
		return;
	const float *E = rad_elem_mat(h, t)->emit;
	double hidden = 1 - rad_elem_exposed(h, t);
	for (int c = 0; c < 3; c++)
		b[c] -= hidden * E[c];
}

double node_area_eff(const rad_hier *h, uint32_t t)
{
	if (node_is_cluster(t))
		return rad_cluster_at(h, t)->area;
	return rad_elem_area(h, t);
}

/* Projected area of cluster t towards unit direction u. */
static double cluster_proj(const rad_hier *h, uint32_t t, v3 u)
{
	return rad_cluster_proj(h, rad_cluster_at(h, t), u.x, u.y, u.z);
}

/* A cluster receiver's mean irradiance per unit normal irradiance from u. */
static double cluster_take(const rad_hier *h, uint32_t t, v3 u)
{
	double a = rad_cluster_at(h, t)->area;
	return a > 0 ? cluster_proj(h, t, u) / a : 0;
}

int node_splittable(const rad_hier *h, uint32_t t)
{
	if (node_is_light(t))
		return 0;
	if (node_is_cluster(t))
		return 1;
	return rad_elem_can_split(h, t);
}

static v3 cluster_center(const rad_cluster *c)
{
	return v3_make(0.5 * ((double)c->lo[0] + c->hi[0]),
	               0.5 * ((double)c->lo[1] + c->hi[1]),
	               0.5 * ((double)c->lo[2] + c->hi[2]));
}

static double cluster_diag(const rad_cluster *c)
{
	return v3_len(v3_sub(v3_f(c->hi), v3_f(c->lo)));
}

double node_size(const rad_hier *h, uint32_t t)
{
	if (node_is_cluster(t))
		return cluster_diag(rad_cluster_at(h, t));
	if (node_is_light(t))
		return 0;
	return rad_elem_edge(h, t);
}

/* An element's four quarters go to the same out[] as a leaf cluster's
 * polygons. */
_Static_assert(RAD_CLUSTER_LEAF_MAX >= 4, "node_children writes 4");

int node_children(rad_hier *h, uint32_t t, uint32_t out[RAD_CLUSTER_LEAF_MAX])
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		if (!rad_cluster_is_leaf(c)) {
			out[0] = (c->child) | RAD_TAG_CLUSTER;
			out[1] = (c->child + 1) | RAD_TAG_CLUSTER;
			return 2;
		}
		for (uint32_t i = 0; i < c->count; i++)
			out[i] = h->order[c->first + i];
		return (int)c->count;
	}
	uint32_t first = rad_elem_split(h, t);
	if (first == RAD_NONE)
		return 0;
	for (uint32_t i = 0; i < 4; i++)
		out[i] = first + i;
	return 4;
}

/* 1 if some corner of box [lo, hi] lies strictly in front of the plane. */
static int box_in_front(const float lo[3], const float hi[3], v3 p, v3 n)
{
	/* The corner furthest along n decides. */
	v3 c = v3_make(n.x > 0 ? hi[0] : lo[0], n.y > 0 ? hi[1] : lo[1],
	               n.z > 0 ? hi[2] : lo[2]);
	return v3_dot(v3_sub(c, p), n) > 0;
}

/* 1 if the plane through p with normal n cuts box [lo, hi]. */
static int box_straddles(const float lo[3], const float hi[3], v3 p, v3 n)
{
	return box_in_front(lo, hi, p, n) &&
	       box_in_front(lo, hi, p, v3_scale(n, -1));
}

/* 1 if some vertex of patch a lies strictly in front of patch b. */
static int patch_in_front(const rad_patch *a, const rad_patch *b, double tol)
{
	v3 v[4];
	int n = rad_patch_vertices(a, v);
	for (int i = 0; i < n; i++)
		if (v3_dot(v3_sub(v[i], b->p0), b->n) > tol)
			return 1;
	return 0;
}

static int light_faces_patch(const rad_light *L, const rad_patch *p)
{
	if (L->kind == RAD_LIGHT_DIRECTIONAL)
		return v3_dot(v3_d(L->dir), p->n) < 0;
	return v3_dot(v3_sub(v3_d(L->pos), p->p0), p->n) > 0;
}

int node_facing(const rad_hier *h, uint32_t rcv, uint32_t src)
{
	rad_patch pr, ps;
	int rc = node_is_cluster(rcv), sc = node_is_cluster(src);
	if (node_is_light(src))
		return rc || (elem_patch(h, rcv, &pr),
		              light_faces_patch(node_light(h, src), &pr));
	if (rc && sc)
		return 1;
	if (rc) {
		const rad_cluster *c = rad_cluster_at(h, rcv);
		elem_patch(h, src, &ps);
		return box_in_front(c->lo, c->hi, ps.p0, ps.n);
	}
	elem_patch(h, rcv, &pr);
	if (sc) {
		const rad_cluster *c = rad_cluster_at(h, src);
		return box_in_front(c->lo, c->hi, pr.p0, pr.n);
	}
	elem_patch(h, src, &ps);
	double tol = 1e-9 * h->scene->diag;
	return patch_in_front(&ps, &pr, tol) && patch_in_front(&pr, &ps, tol);
}

v3 node_center(const rad_hier *h, uint32_t t)
{
	if (node_is_cluster(t))
		return cluster_center(rad_cluster_at(h, t));
	rad_patch p;
	elem_patch(h, t, &p);
	return rad_patch_centroid(&p);
}

int node_near(const rad_hier *h, uint32_t a, uint32_t b)
{
	double d = v3_len(v3_sub(node_center(h, a), node_center(h, b)));
	return fmax(node_size(h, a), node_size(h, b)) > d;
}

/* Isotropic estimate: source area-equivalent as over a distance d. */
static double iso_ff(double as, double cosr, double d2)
{
	double f = as * cosr / (M_PI * d2 + as);
	return f > 1 ? 1 : f;
}

static double light_estimate_cluster(const rad_hier *h, const rad_light *L,
                                     uint32_t rcv)
{
	if (L->kind == RAD_LIGHT_DIRECTIONAL)
		return 1.0;
	double half = 0.5 * node_size(h, rcv);
	v3 d = v3_sub(node_center(h, rcv), v3_d(L->pos));
	return 1.0 / (v3_dot(d, d) + half * half);
}

static double node_gap2(const rad_hier *h, uint32_t a, uint32_t b);

double node_ff_estimate(const rad_hier *h, uint32_t rcv, uint32_t src)
{
	rad_patch pr, ps;
	if (node_is_light(src)) {
		if (node_is_cluster(rcv))
			return light_estimate_cluster(h, node_light(h, src),
			                              rcv);
		elem_patch(h, rcv, &pr);
		return rad_light_estimate(node_light(h, src), &pr);
	}
	if (!node_is_cluster(rcv) && !node_is_cluster(src)) {
		elem_patch(h, rcv, &pr);
		elem_patch(h, src, &ps);
		return rad_ff_estimate(&pr, &ps);
	}
	v3 cr = node_center(h, rcv), cs = node_center(h, src);
	v3 d = v3_sub(cs, cr);
	double d2 = v3_dot(d, d), len = sqrt(d2);
	/* A surface's cosine toward a cluster's centre says nothing when
	 * its plane cuts the cluster's box: contents on its front side may
	 * face it squarely (measured: a block top under a cluster holding
	 * the Cornell light and the ceiling got estimate 0, took the light
	 * at cluster level, and lost 30 % of its direct light).  Count 1. */
	double cosr = 1, as;
	v3 u = len > 0 ? v3_scale(d, 1 / len) : v3_make(0, 0, 0);
	/* A cluster end counts at least its sphere mean (A / 4 shown, 1/4
	 * taken): the centres' direction is not the direction all of its
	 * light travels, and estimated from it alone, links that the kernel
	 * gets wrong were left unrefined (measured: the bright hall lost 5 %
	 * of its power in the third bounce, 1.8 % -> 5.3 % mean error; a floor
	 * against a cluster of the three walls at its corner, none of which
	 * faces the cluster's centre from the floor's, got estimate 0). */
	if (node_is_cluster(rcv))
		cosr = len > 0 ? fmax(0.25, cluster_take(h, rcv, u)) : 1;
	if (!node_is_cluster(rcv) && len > 0) {
		elem_patch(h, rcv, &pr);
		cosr = fmax(0, v3_dot(pr.n, d) / len);
		if (node_is_cluster(src)) {
			const rad_cluster *c = rad_cluster_at(h, src);
			if (box_straddles(c->lo, c->hi, pr.p0, pr.n))
				cosr = 1;
		}
	}
	if (node_is_cluster(src)) {
		double a4 = 0.25 * rad_cluster_at(h, src)->area;
		as = len > 0 ? fmax(a4, cluster_proj(h, src, v3_scale(u, -1)))
		             : a4;
	} else {
		elem_patch(h, src, &ps);
		as = ps.area;
		double cs = len > 0 ? fmax(0, -v3_dot(ps.n, d) / len) : 1;
		if (node_is_cluster(rcv)) {
			const rad_cluster *c = rad_cluster_at(h, rcv);
			if (box_straddles(c->lo, c->hi, ps.p0, ps.n))
				cs = 1;
		}
		cosr *= cs;
	}
	/* The estimate puts a cluster's area at its centre.  When the boxes
	 * come closer than half the centres' distance, part of the cluster
	 * lies nearer than that, where the kernel is larger: take the
	 * distance as the larger of the gap and half the centres' distance.
	 * Estimated from the centres alone, a wall cluster meeting a ceiling
	 * element got a tenth of its transfer and stayed unrefined: in the
	 * hospital room's corridor, the ceiling's links from clusters within
	 * half their size carried 0.2 to 0.6 of what a Monte Carlo estimate
	 * of the same transfer gives. */
	d2 = fmin(d2, fmax(node_gap2(h, rcv, src), d2 / 4));
	return iso_ff(as, cosr, d2);
}

/*
 * Up to n sample points (with normals) of a node.  A source's covered
 * points are left out (hier.h, Covered parts); *rays counts the rays that
 * took.
 */
static int node_points(const rad_hier *h, uint32_t t, int n, int source,
                       v3 *pts, v3 *nrm, uint64_t *rays)
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		int m = (uint32_t)n < c->count ? n : (int)c->count, kept = 0;
		for (int k = 0; k < m; k++) {
			uint32_t j = rad_cluster_pick(h, c, (uint32_t)k,
			                              (uint32_t)m);
			rad_patch p;
			rad_patch_from_poly(&p, h->scene, &h->scene->polys[j]);
			pts[kept] = rad_patch_centroid(&p);
			nrm[kept] = p.n;
			if (source &&
			    rad_elem_keep_exposed(h, j, &pts[kept], &nrm[kept],
			                          1, rays) == 0)
				continue;
			kept++;
		}
		return kept;
	}
	rad_patch p;
	elem_patch(h, t, &p);
	int m = rad_patch_samples(&p, n, pts);
	for (int k = 0; k < m; k++)
		nrm[k] = p.n;
	return source ? rad_elem_keep_exposed(h, t, pts, nrm, m, rays) : m;
}

/* 1 if the boxes of two nodes overlap (a light: its position). */
static int node_boxes_overlap(const rad_hier *h, uint32_t a, uint32_t b);

/*
 * Unit direction from node `from` towards node `to` (a light: its
 * position, or against its direction for a directional one) into u;
 * 0 when their boxes overlap and no one direction stands for the light
 * between them.
 */
static int link_dir(const rad_hier *h, uint32_t from, uint32_t to, v3 *u)
{
	if (node_is_light(to) &&
	    node_light(h, to)->kind == RAD_LIGHT_DIRECTIONAL) {
		*u = v3_scale(v3_d(node_light(h, to)->dir), -1);
		return 1;
	}
	if (node_boxes_overlap(h, from, to))
		return 0;
	v3 t = node_is_light(to) ? v3_d(node_light(h, to)->pos)
	                         : node_center(h, to);
	v3 d = v3_sub(t, node_center(h, from));
	double len = v3_len(d);
	if (!(len > 0))
		return 0;
	*u = v3_scale(d, 1 / len);
	return 1;
}

void node_took(const rad_hier *h, rad_cluster_flux *f, uint32_t rcv,
               uint32_t src, double e)
{
	if (!f || e == 0)
		return;
	v3 u = v3_make(0, 0, 0);
	/* e is power per unit of the cluster's area: normal irradiance is
	 * that over the share of the area it shows (1/4 without direction;
	 * never below 1/16, so a grazing direction cannot blow it up). */
	double take = 0.25;
	if (link_dir(h, rcv, src, &u))
		take = fmax(1.0 / 16, cluster_take(h, rcv, u));
	rad_cluster_took(f, e / take, u.x, u.y, u.z);
}

/* The emission factor of cluster src towards rcv, of B (mean B) and nB
 * (or dB and ndB). */
static double cluster_emit_factor(const rad_hier *h, uint32_t rcv, uint32_t src,
                                  const float B[3], const float nB[3])
{
	v3 u;
	if (!link_dir(h, src, rcv, &u))
		return 1;
	const rad_cluster *c = rad_cluster_at(h, src);
	return rad_cluster_emit(h, c, B, nB,
	                        rad_cluster_proj(h, c, u.x, u.y, u.z), u.x, u.y,
	                        u.z);
}

double node_emit_factor(const rad_hier *h, uint32_t rcv, uint32_t src,
                        int delta)
{
	double b[3];
	return node_is_cluster(src) ? node_sends(h, rcv, src, delta, b) : 1;
}

double node_sends(const rad_hier *h, uint32_t rcv, uint32_t src, int delta,
                  double out[3])
{
	if (!node_is_cluster(src)) {
		if (!delta)
			node_B(h, src, out);
		return 1;
	}
	const rad_cluster *c = rad_cluster_at(h, src);
	float dB[3], ndB[3];
	if (delta)
		rad_cluster_delta(h, c, dB, ndB);
	for (int k = 0; k < 3; k++)
		out[k] = delta ? dB[k] : c->B[k];
	return delta ? cluster_emit_factor(h, rcv, src, dB, ndB)
	             : cluster_emit_factor(h, rcv, src, c->B, c->nB);
}

double node_energy_scale(const rad_hier *h, int delta, const double got[3],
                         double k[3])
{
	double sent[3] = {0, 0, 0}, worst = 1;
	for (uint32_t i = 0; i < h->scene->npolys; i++) {
		const rad_elem *e = rad_elem_at(h, i); /* pulled: the mean */
		float dB[3];
		const float *b = e->B;
		if (delta) {
			rad_elem_dB(h, e, dB);
			b = dB;
		}
		for (int c = 0; c < 3; c++)
			sent[c] += (double)rad_elem_area(h, i) * b[c];
	}
	for (int c = 0; c < 3; c++) {
		k[c] = got[c] > sent[c] && got[c] > 0 ? sent[c] / got[c] : 1;
		worst = fmin(worst, k[c]);
	}
	return worst;
}

int node_tail_rates(const double *chg, double q[3])
{
	int any = 0;
	for (int c = 0; c < 3; c++) {
		double a = chg[c], b = chg[3 + c], d = chg[6 + c];
		q[c] = 0;
		if (!(a > 0 && b > 0 && d > 0))
			continue;
		double q1 = a / b, q0 = b / d;
		if (q1 < 0.5)
			continue;
		if (!(q1 < 0.9999) || fabs(q1 - q0) > 0.05 * q1 * (1 - q1))
			return 0;
		q[c] = q1;
		any = 1;
	}
	return any;
}

static void tail_tree(rad_hier *h, uint32_t id, const double k[3])
{
	rad_elem *e = rad_elem_at(h, id);
	if (!rad_elem_is_leaf(e)) {
		for (uint32_t c = 0; c < 4; c++)
			tail_tree(h, e->child + c, k);
		return;
	}
	float dB[3];
	rad_elem_dB(h, e, dB);
	for (int c = 0; c < 3; c++)
		e->B[c] += (float)(k[c] * dB[c]);
}

double node_tail_add(rad_hier *h, const double q[3])
{
	double k[3], sum = 0;
	for (int c = 0; c < 3; c++)
		k[c] = q[c] / (1 - q[c]);
	for (uint32_t i = 0; i < h->scene->npolys; i++)
		tail_tree(h, i, k);
	rad_hier_pull(h);
	for (uint32_t i = 0; i < h->scene->npolys; i++) {
		const rad_elem *e = rad_elem_at(h, i); /* pulled: the mean */
		sum += rad_elem_area(h, i) * rad_luma(e->B);
	}
	return sum / h->scene->total_area;
}

/* Light -> cluster: normal irradiance at the cluster's sample points,
 * times the share of it the polygons inside take (cluster_take). */
static double ff_light_cluster(const rad_solver *sv, const rad_light *L,
                               uint32_t rcv, uint64_t *rays)
{
	v3 y[RAD_FF_MAX_SAMPLES], ny[RAD_FF_MAX_SAMPLES];
	int m = node_points(&sv->h, rcv, sv->opt.rcv_samples, 0, y, ny, NULL);
	double acc = 0;
	for (int k = 0; k < m; k++) {
		v3 toward = L->kind == RAD_LIGHT_DIRECTIONAL
		                    ? v3_scale(v3_d(L->dir), -1)
		                    : v3_norm(v3_sub(v3_d(L->pos), y[k]));
		/* Facing the light: kernel cosine 1, normal irradiance. */
		double e =
		        rad_light_point(sv->scene->vis, L, y[k], toward, rays);
		acc += e * cluster_take(&sv->h, rcv, toward);
	}
	return m ? acc / m : 0;
}

/*
 * How close a cover must be to a receiver element's points to leave them
 * out of its integral (ff.h), and the fraction of it that is exposed,
 * which scales the integral over the rest back to the whole element:
 * the push hands the power to the exposed children only (hier.h).
 */
static double rcv_cover(const rad_hier *h, uint32_t rcv, double *exposed)
{
	*exposed = rad_elem_exposed(h, rcv);
	return h->scene->vis ? rad_hier_cover_dist(h, rad_elem_poly(h, rcv))
	                     : 0;
}

/*
 * The mean of a receiver's rows (one per sample point).  A surface
 * receiver (points xs) also gives their spread, leaves its covered points
 * out (rad_ff_rcv_mean) and scales by its exposed fraction (rcv_cover).
 */
static double rcv_rows(const rad_hier *h, uint32_t rcv, const v3 *xs,
                       const double *rows, int n, uint64_t *rays,
                       double *spread)
{
	if (!xs)
		return rad_ff_rcv_mean(NULL, v3_make(0, 0, 0), NULL, rows, n, 0,
		                       NULL, NULL);
	double ex, cover = rcv_cover(h, rcv, &ex);
	v3 nr = rad_poly_normal(&h->scene->polys[rad_elem_poly(h, rcv)]);
	double f = rad_ff_rcv_mean(h->scene->vis, nr, xs, rows, n, cover, rays,
	                           spread);
	*spread *= ex;
	return ex * f;
}

/*
 * Pairs involving a cluster: average over receiver points x and source
 * points y of the kernel times visibility.  A surface end brings its
 * cosine (and a source its area), a cluster end its projected area
 * towards the other point (cluster_proj; as a receiver, per unit of its
 * area).  A cluster's sample point lies on one of its polygons: when that
 * polygon faces away from the other point, a ray from it says nothing
 * about the cluster's other polygons that do face it, so such pairs are
 * left out of the average (all of them only if no pair is left).
 */
static double ff_iso(const rad_solver *sv, uint32_t rcv, uint32_t src,
                     uint64_t *rays, double *spread)
{
	const rad_hier *h = &sv->h;
	v3 x[RAD_FF_MAX_SAMPLES], nx[RAD_FF_MAX_SAMPLES];
	v3 y[RAD_FF_MAX_SAMPLES], ny[RAD_FF_MAX_SAMPLES];
	int mr = node_points(h, rcv, sv->opt.rcv_samples, 0, x, nx, NULL);
	int ms = node_points(h, src, sv->opt.vis_samples, 1, y, ny, rays);
	int rsurf = !node_is_cluster(rcv), ssurf = !node_is_cluster(src);
	double as = ssurf ? rad_elem_area(h, src) : 0;
	double rows[RAD_FF_MAX_SAMPLES];
	int used = 0;
	*spread = 0;
	if (!mr || !ms)
		return 0;
	/* Every point pair's ray, traced together (rad_vis_segments), and
	 * what it adds to its receiver point's row when open. */
	rad_vis_seg seg[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
	double add[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
	unsigned char open[RAD_FF_MAX_SAMPLES * RAD_FF_MAX_SAMPLES];
	int owner[RAD_FF_MAX_SAMPLES], end[RAD_FF_MAX_SAMPLES];
	for (int pass = 0; pass < 2 && used == 0; pass++) {
		int n = 0, owners = 0;
		for (int i = 0; i < mr; i++) {
			v3 u[RAD_FF_MAX_SAMPLES];
			double d2[RAD_FF_MAX_SAMPLES];
			int ok[RAD_FF_MAX_SAMPLES], nrow = 0;
			for (int j = 0; j < ms; j++) {
				v3 d = v3_sub(y[j], x[i]);
				d2[j] = v3_dot(d, d);
				ok[j] = d2[j] > 0;
				if (!ok[j])
					continue;
				u[j] = v3_scale(d, 1 / sqrt(d2[j]));
				if (pass == 0 &&
				    ((!rsurf && v3_dot(nx[i], u[j]) <= 0) ||
				     (!ssurf && v3_dot(ny[j], u[j]) >= 0)))
					ok[j] = 0;
				nrow += ok[j];
			}
			if (nrow == 0)
				continue;
			/* A surface source: the mean over its points.  A
			 * cluster's projected area is shared by its points
			 * that face x: each is 1/nrow of it, not all of it
			 * (as one disk, the kernel saturates and loses a
			 * cluster's light near it: with the share, rmb's
			 * second bounce in the Graz office took 7 % more, and
			 * the 16 x 16-quad box under hr went -1.1 % to
			 * -0.5 %). */
			double share = ssurf ? 1.0 / nrow : 1;
			double sa = ssurf ? as : 1.0 / nrow;
			for (int j = 0; j < ms; j++) {
				if (!ok[j])
					continue;
				double cr = v3_dot(nx[i], u[j]);
				double cs = -v3_dot(ny[j], u[j]);
				double c = rsurf ? fmax(0, cr)
				                 : cluster_take(h, rcv, u[j]);
				double a =
				        ssurf ? sa * fmax(0, cs)
				              : sa * cluster_proj(h, src,
				                                  v3_scale(u[j],
				                                           -1));
				if (c <= 0 || a <= 0)
					continue;
				if (rays)
					(*rays)++;
				/* A point facing away leaves from its back. */
				v3 na = cr > 0 ? nx[i] : v3_scale(nx[i], -1);
				v3 nb = cs > 0 ? ny[j] : v3_scale(ny[j], -1);
				seg[n] = (rad_vis_seg){x[i], na, y[j], nb};
				add[n++] = share * iso_ff(a, c, d2[j]);
			}
			owner[owners] = i;
			end[owners++] = n;
		}
		if (n > 0)
			rad_vis_segments(sv->scene->vis, seg, n, open);
		for (int k = 0, q = 0; k < owners; k++) {
			double row = 0;
			for (; q < end[k]; q++)
				if (open[q])
					row += add[q];
			x[used] = x[owner[k]];
			rows[used++] = row;
		}
	}
	return rsurf ? rcv_rows(h, rcv, x, rows, used, rays, spread)
	             : rcv_rows(h, rcv, NULL, rows, used, rays, NULL);
}

/*
 * A source less than a quarter of its receiver's area, closer to it than
 * the receiver's size: its form factor is integrated over the source's
 * points (F(r <- s) = A_s / A_r F(s <- r), each point with the exact form
 * factor of the whole receiver), not over the receiver's.  A few points on
 * a large receiver miss where a small source's light lands when that is
 * within centimetres of it (a luminaire's 1 cm side under a ceiling: the
 * ceiling element's points, decimetres away, gave F tens of times too
 * small).  The spread stays the receiver's: the variation test still
 * splits a receiver that sees the source unevenly.
 */
static int small_source_near(const rad_patch *pr, const rad_patch *ps)
{
	v3 d = v3_sub(rad_patch_centroid(pr), rad_patch_centroid(ps));
	return 4 * ps->area < pr->area && v3_dot(d, d) < pr->area;
}

double node_ff(const rad_solver *sv, uint32_t rcv, uint32_t src, uint64_t *rays,
               double *spread)
{
	const rad_hier *h = &sv->h;
	rad_patch pr, ps;
	double ex, f;
	if (node_is_light(src)) {
		const rad_light *L = node_light(h, src);
		if (node_is_cluster(rcv)) {
			*spread = 0;
			return ff_light_cluster(sv, L, rcv, rays);
		}
		elem_patch(h, rcv, &pr);
		f = rad_light_patch_spread(
		        sv->scene->vis, L, &pr, sv->opt.rcv_samples,
		        rcv_cover(h, rcv, &ex), rays, spread);
		*spread *= ex;
		return f * ex;
	}
	if (node_is_cluster(rcv) || node_is_cluster(src))
		return ff_iso(sv, rcv, src, rays, spread);
	elem_patch(h, rcv, &pr);
	elem_patch(h, src, &ps);
	double cover = rad_elem_exposed_raw(h, src) == RAD_EXPOSED_ALL
	                       ? 0
	                       : rad_hier_cover_dist(h, rad_elem_poly(h, src));
	double rcover = rcv_cover(h, rcv, &ex);
	f = rad_ff_patch_spread(sv->scene->vis, &pr, &ps, sv->opt.rcv_samples,
	                        sv->opt.vis_samples, cover, rcover, rays,
	                        spread);
	if (small_source_near(&pr, &ps)) {
		double sp;
		double g = rad_ff_patch_spread(
		        sv->scene->vis, &ps, &pr, sv->opt.vis_samples,
		        sv->opt.rcv_samples, rcover, cover, rays, &sp);
		f = g * ps.area / pr.area;
	}
	*spread *= ex;
	return f * ex;
}

/* Axis-aligned bounds of a node, as doubles. */
static void node_box(const rad_hier *h, uint32_t t, double lo[3], double hi[3])
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		for (int k = 0; k < 3; k++) {
			lo[k] = c->lo[k];
			hi[k] = c->hi[k];
		}
		return;
	}
	rad_patch p;
	v3 v[4];
	elem_patch(h, t, &p);
	int n = rad_patch_vertices(&p, v);
	lo[0] = hi[0] = v[0].x;
	lo[1] = hi[1] = v[0].y;
	lo[2] = hi[2] = v[0].z;
	for (int i = 1; i < n; i++) {
		double q[3] = {v[i].x, v[i].y, v[i].z};
		for (int k = 0; k < 3; k++) {
			lo[k] = fmin(lo[k], q[k]);
			hi[k] = fmax(hi[k], q[k]);
		}
	}
}

/* Squared distance between two boxes (0 when they touch or overlap). */
static double box_gap2(const double al[3], const double ah[3],
                       const double bl[3], const double bh[3])
{
	double d2 = 0;
	for (int k = 0; k < 3; k++) {
		double a = bl[k] - ah[k], b = al[k] - bh[k];
		double gap = rad_pos(a > b ? a : b);
		d2 += gap * gap;
	}
	return d2;
}

/* box_gap2 of two surface or cluster nodes. */
static double node_gap2(const rad_hier *h, uint32_t a, uint32_t b)
{
	double al[3], ah[3], bl[3], bh[3];
	node_box(h, a, al, ah);
	node_box(h, b, bl, bh);
	return box_gap2(al, ah, bl, bh);
}

/*
 * A light's "form factor" is irradiance per unit of intensity: at most
 * 1 / d^2 (lux per cd) from a point or spot at distance d from the
 * receiver's box, at most 1 (lux per lux) from a directional light.
 */
static double light_ff_bound(const rad_hier *h, uint32_t rcv, uint32_t src)
{
	const rad_light *L = &h->scene->lights[src & ~RAD_TAG_MASK];
	if (L->kind == RAD_LIGHT_DIRECTIONAL)
		return 1;
	double lo[3], hi[3], p[3] = {L->pos[0], L->pos[1], L->pos[2]};
	node_box(h, rcv, lo, hi);
	double d2 = box_gap2(lo, hi, p, p);
	/* Inside the box: no finite bound; the caller refines. */
	return d2 > 0 ? 1 / d2 : 1e30;
}

static int node_boxes_overlap(const rad_hier *h, uint32_t a, uint32_t b)
{
	double al[3], ah[3], bl[3], bh[3];
	node_box(h, a, al, ah);
	if (node_is_light(b)) {
		const rad_light *L = node_light(h, b);
		for (int k = 0; k < 3; k++)
			bl[k] = bh[k] = L->pos[k];
	} else {
		node_box(h, b, bl, bh);
	}
	return box_gap2(al, ah, bl, bh) == 0;
}

double node_ff_bound(const rad_hier *h, uint32_t rcv, uint32_t src)
{
	if (node_is_light(src))
		return light_ff_bound(h, rcv, src);
	double d2 = node_gap2(h, rcv, src);
	double as = node_is_cluster(src) ? rad_cluster_at(h, src)->area
	                                 : rad_elem_area(h, src);
	double f = as / (M_PI * d2);
	return d2 > 0 && f < 1 ? f : 1;
}

double node_oracle(const rad_solver *sv, uint32_t rcv, uint32_t src, double b,
                   double f)
{
	const rad_hier *h = &sv->h;
	/* The projected-area model of a cluster (hier.h) is exact for flat
	 * and sphere-like contents, but in between it can be off by tens of
	 * per cent either way (measured: a 3-face "U" of a box, 0.3 A
	 * modelled where nothing is shown): count the transfer as if the
	 * cluster showed four times its modelled area, as the isotropic
	 * model's worst case did, so that the threshold bounds the error
	 * rather than the model's own estimate of it. */
	if (node_is_cluster(rcv))
		f *= 4;
	if (node_is_cluster(src))
		f *= 4;
	rad_oracle o = sv->opt.oracle;
	if (node_is_light(src) && o == RAD_ORACLE_F)
		o = RAD_ORACLE_BFA; /* a light's "form factor" is in lux/cd */
	switch (o) {
	case RAD_ORACLE_F:
		return f;
	case RAD_ORACLE_BF:
		return b * f * h->scene->total_area / sv->flux_scale;
	case RAD_ORACLE_BFA:
	default:
		return b * f * node_area_eff(h, rcv) / sv->flux_scale;
	}
}

double node_area(const rad_hier *h, uint32_t t)
{
	if (node_is_light(t))
		return 0;
	if (node_is_cluster(t))
		return rad_cluster_at(h, t)->area;
	return rad_elem_area(h, t);
}

void node_stat_exchange(const rad_solver *sv, rad_stats *S, uint32_t r,
                        uint32_t s, double ff, double b, double inc)
{
	/* What it carries: the oracle's BFA value without the clusters'
	 * worst-case factor. */
	double e = b * ff * node_area_eff(&sv->h, r) / sv->flux_scale;
	S->links_gathered++;
	if (4 * node_oracle(sv, r, s, inc, ff) > sv->opt.eps)
		S->links_useful++;
	int bin = RAD_EHIST_BINS - 1;
	if (e > 0) {
		double d = floor(-log10(e));
		if (d < 0)
			d = 0;
		if (d < RAD_EHIST_BINS - 1)
			bin = (int)d;
	}
	S->energy_hist[bin]++;
}

void node_count_link(rad_stats *s, uint32_t rcv, uint32_t src)
{
	int rc = node_is_cluster(rcv);
	s->links++;
	if (node_is_light(src))
		s->links_light++;
	else if (rc && node_is_cluster(src))
		s->links_cc++;
	else if (rc || node_is_cluster(src))
		s->links_sc++;
	else
		s->links_ss++;
}
