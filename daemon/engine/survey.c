/*
 * survey.c -- what a lighting report reads from a committed scene besides
 * the solution: the calculation faces of a named node (its polygons
 * grouped by facing, each covered by a rectangle in its plane, and the
 * points of a grid on that rectangle that lie on the polygons), the
 * scene's lights and its emitting surfaces per node.  Read-only, no
 * allocation: callers give the arrays.
 *
 * DESIGN
 * A node is whatever the file grouped under one name: a floor (one
 * facing), "walls" (four), a desk (six).  A calculation surface of EN
 * 12464-1 is planar, so the node is split by facing: polygons whose unit
 * normals agree within FACE_COS form one face, largest area first.  A
 * face's rectangle lies in the plane through its first polygon and spans
 * the projections of all its polygons (parallel polygons at other
 * offsets, a stepped floor, project onto it); a grid point is the cell
 * centre projected back along the normal onto the polygon it falls in,
 * with that polygon's normal, so the gather sees the surface itself.
 * Cells that fall on no polygon (an L-shaped floor's missing corner) are
 * off: the caller leaves them out of the statistics.
 *
 * The frame is fixed so that images read naturally: a face seen from its
 * front side has u to the right and v downwards (u x v = -normal); a
 * horizontal face (|ny| >= HORIZ_NY) has u = +x and v = +z whatever its
 * side, the plan view looking down -y, so floors, ceilings and work
 * planes share one orientation; a wall has v = -y (upright).
 *
 * A point of a work plane can fall inside furniture (a cabinet taller
 * than the plane): no light reaches it, and counted, it sets Emin to 0.
 * It is inside a closed object when, of the rays along its normal and
 * along four directions across it, at least three meet the backs of
 * surfaces first (rad_vis_first_hit_front, which shows a two-sided face
 * its front).  Not all: furniture stands on the floor and objects touch
 * (books on a shelf), and where a face coincides with another's front
 * the ray meets that front.  Under a desk (its underside, or a one-sided
 * top seen from below), the rays across meet the room's walls; in the
 * open they meet nothing: neither is inside.  A point beyond the room's
 * walls (a rectangle larger than an L-shaped room) is left out too where
 * three of its rays meet walls from behind.
 */
#include <math.h>
#include <string.h>

#include "scene.h"
#include "vis.h"

#define FACE_COS 0.999 /* normals this close belong to one face */
#define HORIZ_NY 0.7   /* |ny| at least this: a horizontal face */
#define EDGE_TOL 1e-9  /* parametric slack on polygon edges */

static int node_poly(const rad_scene *s, uint32_t node, uint32_t i)
{
	return rad_poly_node(s, i) == node && s->polys[i].area > 0;
}

/* Index of the face in faces[0..n) whose normal agrees with nrm, or -1. */
static int face_of(const rad_face *faces, int n, v3 nrm)
{
	for (int f = 0; f < n; f++)
		if (v3_dot(v3_d(faces[f].normal), nrm) >= FACE_COS)
			return f;
	return -1;
}

/* The face's frame: unit u, v in its plane (see DESIGN). */
static void face_frame(v3 n, v3 *u, v3 *v)
{
	if (fabs(n.y) >= HORIZ_NY) {
		v3 z = v3_make(0, 0, 1), x = v3_make(1, 0, 0);
		*v = v3_norm(v3_madd(z, n, -v3_dot(z, n)));
		*u = v3_norm(v3_madd(x, n, -v3_dot(x, n)));
		/* make u exactly orthogonal to v (a tilted face) */
		*u = v3_norm(v3_madd(*u, *v, -v3_dot(*u, *v)));
		return;
	}
	v3 down = v3_make(0, -1, 0);
	*v = v3_norm(v3_madd(down, n, -v3_dot(down, n)));
	*u = v3_cross(n, *v);
}

/* The box [a0, a1] x [b0, b1] of a polygon's corners in the frame (o, u,
 * v): box = {a0, a1, b0, b1}, grown (the caller starts it empty). */
static void grow_box(const rad_scene *s, const rad_poly *p, v3 o, v3 u, v3 v,
                     double box[4])
{
	v3 c[4];
	int nc = rad_poly_corners(s, p, c);
	for (int k = 0; k < nc; k++) {
		v3 d = v3_sub(c[k], o);
		double a = v3_dot(d, u), b = v3_dot(d, v);
		box[0] = a < box[0] ? a : box[0];
		box[1] = a > box[1] ? a : box[1];
		box[2] = b < box[2] ? b : box[2];
		box[3] = b > box[3] ? b : box[3];
	}
}

/* Rectangle of face f over the projections of its polygons. */
static void face_rect(const rad_scene *s, uint32_t node, rad_face *f)
{
	v3 n = v3_d(f->normal), u, v, ref = v3_make(0, 0, 0);
	double box[4] = {HUGE_VAL, -HUGE_VAL, HUGE_VAL, -HUGE_VAL};
	int have_ref = 0;
	face_frame(n, &u, &v);
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		if (!node_poly(s, node, i) ||
		    v3_dot(rad_poly_normal(p), n) < FACE_COS)
			continue;
		if (!have_ref) {
			ref = rad_scene_vertex(s, p->v[0]);
			have_ref = 1;
		}
		grow_box(s, p, ref, u, v, box);
	}
	v3 o = v3_madd(v3_madd(ref, u, box[0]), v, box[2]);
	v3 eu = v3_scale(u, box[1] - box[0]), ev = v3_scale(v, box[3] - box[2]);
	memcpy(f->origin, &o, sizeof(f->origin));
	memcpy(f->u, &eu, sizeof(f->u));
	memcpy(f->v, &ev, sizeof(f->v));
}

rad_status rad_scene_node_faces(const rad_scene *s, uint32_t node,
                                rad_face *faces, int max, int *nfaces,
                                double *skipped_m2, rad_error *err)
{
	*nfaces = 0;
	*skipped_m2 = 0;
	if (!s->committed)
		return rad_fail(err, RAD_ERR_STATE,
		                "node faces: the scene is "
		                "not committed");
	if (node >= s->nnodes)
		return rad_fail(err, RAD_ERR_INVALID,
		                "node faces: no node %u (the scene has %u)",
		                node, s->nnodes);
	if (max < 1)
		return rad_fail(err, RAD_ERR_INVALID,
		                "node faces: room for %d faces", max);
	/* Group by facing; a facing beyond max is counted as skipped. */
	int n = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		if (!node_poly(s, node, i))
			continue;
		const rad_poly *p = &s->polys[i];
		v3 pn = rad_poly_normal(p);
		int f = face_of(faces, n, pn);
		if (f < 0 && n == max) {
			*skipped_m2 += p->area;
			continue;
		}
		if (f < 0) {
			f = n++;
			memset(&faces[f], 0, sizeof(faces[f]));
			faces[f].normal[0] = pn.x;
			faces[f].normal[1] = pn.y;
			faces[f].normal[2] = pn.z;
		}
		faces[f].area_m2 += p->area;
		faces[f].polygons++;
	}
	/* Largest first (insertion sort: a handful of faces). */
	for (int i = 1; i < n; i++) {
		rad_face t = faces[i];
		int j = i;
		for (; j > 0 && faces[j - 1].area_m2 < t.area_m2; j--)
			faces[j] = faces[j - 1];
		faces[j] = t;
	}
	for (int f = 0; f < n; f++)
		face_rect(s, node, &faces[f]);
	*nfaces = n;
	return RAD_OK;
}

/* Parameters (a, b) of a 2-D point q in the basis (e1, e2); 0 when the
 * basis is degenerate. */
static int solve2(const double e1[2], const double e2[2], const double q[2],
                  double *a, double *b)
{
	double det = e1[0] * e2[1] - e1[1] * e2[0];
	if (!(fabs(det) > 0))
		return 0;
	*a = (q[0] * e2[1] - q[1] * e2[0]) / det;
	*b = (e1[0] * q[1] - e1[1] * q[0]) / det;
	return 1;
}

/* Mark the cells of the nu x nv grid on face f whose centres fall on
 * polygon p, filling their points. */
static size_t sample_poly(const rad_scene *sc, const rad_poly *p,
                          const rad_face *f, int nu, int nv, double *pts,
                          unsigned char *on)
{
	v3 o = v3_d(f->origin), fu = v3_d(f->u), fv = v3_d(f->v);
	double lu = v3_len(fu), lv = v3_len(fv);
	v3 u = v3_scale(fu, lu > 0 ? 1 / lu : 0);
	v3 v = v3_scale(fv, lv > 0 ? 1 / lv : 0);
	double cu = lu > 0 ? lu / nu : 1, cv = lv > 0 ? lv / nv : 1;
	v3 p0 = rad_scene_vertex(sc, p->v[0]);
	v3 pe1 = rad_poly_e1(sc, p), pe2 = rad_poly_e2(sc, p);
	v3 pn = rad_poly_normal(p);
	double box[4] = {HUGE_VAL, -HUGE_VAL, HUGE_VAL, -HUGE_VAL};
	grow_box(sc, p, o, u, v, box);
	double e1[2] = {v3_dot(pe1, u), v3_dot(pe1, v)};
	double e2[2] = {v3_dot(pe2, u), v3_dot(pe2, v)};
	double q0[2] = {v3_dot(v3_sub(p0, o), u), v3_dot(v3_sub(p0, o), v)};
	int i0 = (int)floor(box[0] / cu - 0.5);
	int i1 = (int)ceil(box[1] / cu - 0.5);
	int j0 = (int)floor(box[2] / cv - 0.5);
	int j1 = (int)ceil(box[3] / cv - 0.5);
	i0 = i0 < 0 ? 0 : i0;
	j0 = j0 < 0 ? 0 : j0;
	i1 = i1 >= nu ? nu - 1 : i1;
	j1 = j1 >= nv ? nv - 1 : j1;
	size_t added = 0;
	for (int j = j0; j <= j1; j++) {
		for (int i = i0; i <= i1; i++) {
			size_t k = (size_t)j * (size_t)nu + (size_t)i;
			double q[2] = {(i + 0.5) * cu - q0[0],
			               (j + 0.5) * cv - q0[1]};
			double s, t;
			if (on[k] || !solve2(e1, e2, q, &s, &t))
				continue;
			if (s < -EDGE_TOL || t < -EDGE_TOL ||
			    (p->quad ? s > 1 + EDGE_TOL || t > 1 + EDGE_TOL
			             : s + t > 1 + EDGE_TOL))
				continue;
			v3 x = v3_madd(v3_madd(p0, pe1, s), pe2, t);
			double *out = pts + 6 * k;
			out[0] = x.x;
			out[1] = x.y;
			out[2] = x.z;
			out[3] = pn.x;
			out[4] = pn.y;
			out[5] = pn.z;
			on[k] = 1;
			added++;
		}
	}
	return added;
}

rad_status rad_scene_face_sample(const rad_scene *s, uint32_t node,
                                 const rad_face *f, int nu, int nv, double *pts,
                                 unsigned char *on, size_t *non, rad_error *err)
{
	*non = 0;
	if (!s->committed || node >= s->nnodes || nu < 1 || nv < 1)
		return rad_fail(err, RAD_ERR_INVALID,
		                "face sample: node %u, grid %d x %d refused",
		                node, nu, nv);
	size_t n = (size_t)nu * (size_t)nv;
	memset(on, 0, n);
	for (size_t k = 0; k < n; k++)
		for (int m = 0; m < 6; m++)
			pts[6 * k + m] = NAN;
	v3 nrm = v3_d(f->normal);
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		if (node_poly(s, node, i) &&
		    v3_dot(rad_poly_normal(p), nrm) >= FACE_COS)
			*non += sample_poly(s, p, f, nu, nv, pts, on);
	}
	return RAD_OK;
}

/* 1 if the first surface the ray from x along unit d meets shows its
 * back. */
static int meets_back(const rad_vis *v, v3 x, v3 d)
{
	double t;
	int front = 0;
	uint32_t hit = rad_vis_first_hit_front(v, x, d, rad_vis_eps(v), 1e30,
	                                       &t, &front);
	return hit != UINT32_MAX && !front;
}

rad_status rad_scene_points_inside(const rad_scene *s, const double *pts,
                                   size_t n, unsigned char *inside,
                                   rad_error *err)
{
	if (!s->committed || !s->vis)
		return rad_fail(err, RAD_ERR_STATE,
		                "points inside: the scene is not committed");
	for (size_t i = 0; i < n; i++) {
		const double *p = pts + 6 * i;
		v3 x = v3_make(p[0], p[1], p[2]);
		v3 d = v3_make(p[3], p[4], p[5]);
		double len = v3_len(d);
		inside[i] = 0;
		if (!isfinite(p[0] + p[1] + p[2]) || !(len > 0) ||
		    !isfinite(len))
			continue;
		d = v3_scale(d, 1 / len);
		/* Across: t1 off the axis least along d, t2 = d x t1. */
		v3 a = fabs(d.x) < fabs(d.y)
		               ? (fabs(d.x) < fabs(d.z) ? v3_make(1, 0, 0)
		                                        : v3_make(0, 0, 1))
		               : (fabs(d.y) < fabs(d.z) ? v3_make(0, 1, 0)
		                                        : v3_make(0, 0, 1));
		v3 t1 = v3_norm(v3_cross(d, a)), t2 = v3_cross(d, t1);
		const v3 dirs[5] = {d, t1, v3_scale(t1, -1), t2,
		                    v3_scale(t2, -1)};
		int backs = 0;
		for (int k = 0; k < 5; k++)
			backs += meets_back(s->vis, x, dirs[k]);
		inside[i] = backs >= 3;
	}
	return RAD_OK;
}

rad_status rad_scene_light_get(const rad_scene *s, uint32_t i,
                               rad_light_desc *out, rad_error *err)
{
	if (i >= s->nlights)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: the scene has %u", i, s->nlights);
	const rad_light *l = &s->lights[i];
	memset(out, 0, sizeof(*out));
	out->kind = l->kind;
	memcpy(out->position, l->pos, sizeof(out->position));
	memcpy(out->direction, l->dir, sizeof(out->direction));
	memcpy(out->intensity, l->intensity, sizeof(out->intensity));
	out->range = l->range;
	if (l->kind == RAD_LIGHT_SPOT) {
		out->inner_cone = acos(fmin(1, fmax(-1, l->cos_inner)));
		out->outer_cone = acos(fmin(1, fmax(-1, l->cos_outer)));
	}
	out->name = l->name;
	if (l->gonio) { /* as it was given: an RGB factor on the table */
		double peak = l->gonio->peak_cd;
		for (int c = 0; c < 3; c++)
			out->intensity[c] =
			        peak > 0 ? l->intensity[c] / peak : 0;
		out->candela = &l->gonio->grid;
		memcpy(out->c0_axis, l->gonio->axis0, sizeof(out->c0_axis));
		memcpy(out->opening, l->opening, sizeof(out->opening));
		out->opening_round = l->opening_round;
	}
	return RAD_OK;
}

uint32_t rad_scene_emitters(const rad_scene *s, rad_emitter *out, uint32_t max,
                            int *more)
{
	uint32_t n = 0;
	*more = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		const rad_material *m = &s->mats[p->mat];
		if (!rad_material_emits(m) || !(p->area > 0))
			continue;
		uint32_t e = 0, node = rad_poly_node(s, i);
		while (e < n && out[e].node != node)
			e++;
		if (e == n && n == max) {
			*more = 1;
			continue;
		}
		if (e == n) {
			memset(&out[n], 0, sizeof(out[n]));
			out[n++].node = node;
		}
		out[e].polygons++;
		out[e].area_m2 += p->area;
		for (int k = 0; k < 3; k++)
			out[e].exitance[k] += (double)m->emit[k] * p->area;
	}
	for (uint32_t e = 0; e < n; e++) {
		double *x = out[e].exitance;
		out[e].flux_lm = RAD_LUMA_R * x[0] + RAD_LUMA_G * x[1] +
		                 RAD_LUMA_B * x[2];
		for (int k = 0; k < 3; k++)
			x[k] /= out[e].area_m2;
	}
	return n;
}
