/*
 * commit.c -- a scene's commit: pairs of triangles merged into quads,
 * bounds, the large polygons cut where others cross them (conform.c),
 * two-sided polygons' back faces, flux totals, then the BVH (vis.c); and
 * the scene's end, which frees what commit built with the rest.
 *
 * DESIGN
 * - At commit, pairs of triangles that share an edge and together form a
 *   parallelogram become one quad (half the elements, half the links for
 *   the very common case of rectangles exported as two triangles).
 *   Matching is greedy in input order, each triangle preferring its
 *   longest edge as the diagonal, which pairs the usual grid
 *   triangulations into their cells rather than into skewed neighbours.
 * - Triangles offered with their own reflectance (a textured surface)
 *   merge when they came with the same material; the quad reflects their
 *   area-weighted mean, and materials no polygon uses any more are
 *   dropped.
 * - After the cuts, each two-sided polygon gets its back face, appended
 *   after every polygon the BVH holds (make_back_faces).
 * - A failed commit leaves the scene uncommitted and may be retried (the
 *   merge is skipped once done: s->merged); once merged, the scene
 *   takes no more triangles.
 */
#include <float.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "scene.h"
#include "vis.h"

/* Quad merging: coplanarity as 1 - cos between normals, parallelogram
 * closure relative to the longest edge. */
#define MERGE_COPLANAR 1e-6
#define MERGE_CLOSE_REL 1e-6

/* ---------------------------------------------------------- quad merging */

/* Vertex k (mod 3) of triangle t: directed edge k runs from vertex k to
 * vertex k+1. */
static uint32_t tri_vertex(const rad_scene *s, uint32_t t, int k)
{
	return s->polys[t].v[k % 3];
}

/* The edge map: open addressing, linear probes.  A slot keeps t*3 + k in
 * its low bits and, in the bits those leave, its edge's hash: a probe
 * reads the triangle of a slot whose hash bits match its own only.  At
 * the load the map allows (3 edges a triangle in 4 slots) a probe meets
 * several edges of others, and each was a read of a triangle anywhere in
 * the scene: 0.7 s of the 1M-triangle field's load. */
typedef struct edge_map {
	const rad_scene *s;
	uint32_t *slot; /* tag | t*3 + k of a directed edge, or RAD_NONE;
	                   SCRATCH */
	uint32_t mask;  /* capacity - 1 (a power of two) */
	uint32_t tags;  /* a slot's bits above t*3 + k's (0: none) */
} edge_map;

static uint32_t edge_hash(uint32_t a, uint32_t b)
{
	const uint32_t ab[2] = {a, b};
	return rad_hash_end(rad_hash_words(RAD_HASH_SEED, ab, 2));
}

/* The edge t*3 + k a slot holds, or RAD_NONE. */
static uint32_t edge_of(const edge_map *m, uint32_t slot)
{
	return slot == RAD_NONE ? RAD_NONE : slot & ~m->tags;
}

/* Slot holding the directed edge a -> b (vertex ids), or the empty slot
 * ending the probe sequence; *tag (or NULL) gets the hash bits a slot of
 * that edge keeps. */
static uint32_t *edge_probe(const edge_map *m, uint32_t a, uint32_t b,
                            uint32_t *tag_out)
{
	uint32_t h = edge_hash(a, b), tag = h & m->tags;
	if (tag_out)
		*tag_out = tag;
	for (uint32_t i = h & m->mask;; i = (i + 1) & m->mask) {
		uint32_t e = m->slot[i];
		if (e == RAD_NONE)
			return &m->slot[i];
		if ((e & m->tags) != tag)
			continue;
		e &= ~m->tags;
		int k = (int)(e % 3);
		if (tri_vertex(m->s, e / 3, k) == a &&
		    tri_vertex(m->s, e / 3, k + 1) == b)
			return &m->slot[i];
	}
}

static rad_status edge_map_build(edge_map *m, rad_scene *s)
{
	uint32_t ntri = s->npolys, cap = 16; /* load factor <= 3/4 */
	while (cap < 4u * ntri)
		cap *= 2;
	m->s = s;
	m->mask = cap - 1;
	/* t*3 + k below 2^bits - 1, so that no slot in use is RAD_NONE. */
	int bits = 1;
	while (bits < 32 && (1ull << bits) - 1 <= 3ull * ntri)
		bits++;
	m->tags = bits < 32 ? ~((1u << bits) - 1) : 0;
	m->slot = rad_mem_alloc(&s->mem, RAD_MEM_SCRATCH, (size_t)cap * 4);
	if (!m->slot)
		return RAD_ERR_NOMEM;
	memset(m->slot, 0xff, (size_t)cap * 4);
	for (uint32_t t = 0; t < ntri; t++) {
		for (int k = 0; k < 3; k++) {
			uint32_t tag;
			uint32_t *slot =
			        edge_probe(m, tri_vertex(s, t, k),
			                   tri_vertex(s, t, k + 1), &tag);
			/* A repeated directed edge (non-manifold or
			 * duplicate geometry): the first keeps it. */
			if (*slot == RAD_NONE)
				*slot = tag | (t * 3 + (uint32_t)k);
		}
	}
	return RAD_OK;
}

/*
 * Can triangle t, seen as (a, b, c) with b -> c its edge k and a the
 * opposite corner, pair with u, which holds c -> b with opposite corner d, into
 * the parallelogram a, b, d, c?  Closure d = b + c - a is checked relative to
 * the longest edge, plus the rounding the float vertices carry.
 */
static int forms_parallelogram(const rad_scene *s, uint32_t t, int k,
                               uint32_t u, int j)
{
	const rad_poly *pt = &s->polys[t], *pu = &s->polys[u];
	if (rad_scene_merge_key(s, t) != rad_scene_merge_key(s, u) ||
	    rad_poly_node(s, t) != rad_poly_node(s, u) || pt->side != pu->side)
		return 0;
	if (v3_dot(rad_poly_normal(pt), rad_poly_normal(pu)) <
	    1.0 - MERGE_COPLANAR)
		return 0;
	v3 a = v3_f(rad_scene_vert(s, tri_vertex(s, t, k + 2)));
	v3 b = v3_f(rad_scene_vert(s, tri_vertex(s, t, k)));
	v3 c = v3_f(rad_scene_vert(s, tri_vertex(s, t, k + 1)));
	v3 d = v3_f(rad_scene_vert(s, tri_vertex(s, u, j + 2)));
	double lmax = fmax(v3_len(v3_sub(b, a)), v3_len(v3_sub(c, a)));
	double cmax = 0;
	const v3 pts[4] = {a, b, c, d};
	for (int i = 0; i < 4; i++)
		cmax = fmax(cmax, fmax(fabs(pts[i].x),
		                       fmax(fabs(pts[i].y), fabs(pts[i].z))));
	double tol = MERGE_CLOSE_REL * lmax + 4.0 * FLT_EPSILON * cmax;
	v3 gap = v3_sub(d, v3_sub(v3_add(b, c), a));
	return v3_len(gap) <= tol;
}

/*
 * The reflectance of the quad t and u make when each came with its own
 * (a textured surface): the area-weighted mean of theirs, a material of
 * its own, with t's luminance (both have their base's).
 */
static rad_status quad_material(rad_scene *s, uint32_t t, uint32_t u,
                                rad_error *err)
{
	rad_poly *pt = &s->polys[t];
	const rad_poly *pu = &s->polys[u];
	if (pt->mat == pu->mat)
		return RAD_OK;
	rad_material m = s->mats[pt->mat];
	const rad_material *mu = &s->mats[pu->mat];
	double at = pt->area, au = pu->area;
	for (int c = 0; c < 3; c++)
		m.rho[c] = rad_rho_float((at * m.rho[c] + au * mu->rho[c]) /
		                         (at + au));
	uint32_t id;
	rad_status st = rad_scene_material_id(s, &m, &id, err);
	if (!st)
		pt->mat = id;
	return st;
}

/* Rewrite triangle t as the parallelogram with corner a (opposite its
 * edge k) and, opposite a, corner j + 2 of triangle u. */
static void make_quad(rad_scene *s, uint32_t t, int k, uint32_t u, int j)
{
	rad_poly *p = &s->polys[t];
	uint32_t a = tri_vertex(s, t, k + 2), b = tri_vertex(s, t, k),
	         c = tri_vertex(s, t, k + 1), d = tri_vertex(s, u, j + 2);
	p->v[0] = a;
	p->v[1] = b;
	p->v[2] = d;
	p->v[3] = c;
	p->area = (float)v3_len(v3_cross(rad_poly_e1(s, p), rad_poly_e2(s, p)));
	p->quad = 1;
}

/* Edges of t, longest first: the diagonal of a cell is tried first. */
static void edges_by_length(const rad_scene *s, uint32_t t, int order[3])
{
	double len[3];
	for (int k = 0; k < 3; k++) {
		float e[3];
		rad_scene_edge(s, tri_vertex(s, t, k), tri_vertex(s, t, k + 1),
		               e);
		order[k] = k;
		len[k] = v3_len(v3_f(e));
	}
	for (int i = 1; i < 3; i++)
		for (int j = i; j > 0 && len[order[j]] > len[order[j - 1]];
		     j--) {
			int tmp = order[j];
			order[j] = order[j - 1];
			order[j - 1] = tmp;
		}
}

/* What merging made of each triangle. */
enum { PAIR_NONE, PAIR_QUAD, PAIR_ABSORBED, PAIR_DUPLICATE };

/*
 * 1 if triangle t repeats an earlier one: the same three vertices in the
 * same turn (so facing the same way).  Such copies are one surface to
 * every renderer but were two to the solvers, each receiving and sending
 * in full.  Half the hospital room's triangles are copies, its bedside
 * bulbs among them, which sent their light twice.  The reversed twin of a
 * two-sided face is not a copy and stays.  The edge map holds the first
 * owner of each directed edge, so a copy finds its original through one of
 * its edges, unless other triangles own all three first (then it stays).
 */
static int duplicate_of_earlier(const rad_scene *s, const edge_map *m,
                                uint32_t t)
{
	for (int k = 0; k < 3; k++) {
		uint32_t e =
		        edge_of(m, *edge_probe(m, tri_vertex(s, t, k),
		                               tri_vertex(s, t, k + 1), NULL));
		uint32_t u = e / 3;
		if (e == RAD_NONE || u >= t)
			continue;
		int du = (int)(e % 3) - k, same = 1;
		for (int i = 0; i < 3; i++)
			same &= tri_vertex(s, t, i) ==
			        tri_vertex(s, u, i + du + 3);
		if (same)
			return 1;
	}
	return 0;
}

/* Pair t with its first mergeable free neighbour. */
static rad_status pair_triangle(rad_scene *s, const edge_map *m, uint8_t *pair,
                                uint32_t t, rad_error *err)
{
	int order[3];
	edges_by_length(s, t, order);
	for (int i = 0; i < 3; i++) {
		int k = order[i];
		uint32_t e = edge_of(m, *edge_probe(m, tri_vertex(s, t, k + 1),
		                                    tri_vertex(s, t, k), NULL));
		if (e == RAD_NONE || e / 3 == t || pair[e / 3] != PAIR_NONE)
			continue;
		uint32_t u = e / 3;
		if (!forms_parallelogram(s, t, k, u, (int)(e % 3)))
			continue;
		rad_status st = quad_material(s, t, u, err);
		if (st)
			return st;
		make_quad(s, t, k, u, (int)(e % 3));
		pair[t] = PAIR_QUAD;
		pair[u] = PAIR_ABSORBED;
		return RAD_OK;
	}
	return RAD_OK;
}

/*
 * Textured surfaces leave materials no polygon uses (a triangle's own,
 * once its quad took the mean): the table keeps the used ones, in order.
 */
static rad_status drop_unused_materials(rad_scene *s, rad_error *err)
{
	uint32_t *to =
	        rad_mem_calloc(&s->mem, RAD_MEM_SCRATCH, s->nmats, sizeof(*to));
	if (!to)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "commit: out of memory sorting %u materials",
		                s->nmats);
	for (uint32_t i = 0; i < s->npolys; i++)
		to[s->polys[i].mat] = 1;
	uint32_t n = 0;
	for (uint32_t i = 0; i < s->nmats; i++)
		if (to[i]) {
			s->mats[n] = s->mats[i];
			to[i] = n++;
		}
	for (uint32_t i = 0; i < s->npolys; i++)
		s->polys[i].mat = to[s->polys[i].mat];
	rad_mem_free(&s->mem, RAD_MEM_SCRATCH, to);
	rad_material *fit = rad_mem_realloc(&s->mem, RAD_MEM_MATERIALS, s->mats,
	                                    n * sizeof(*s->mats));
	if (fit) {
		s->mats = fit;
		s->cap_mats = n;
	}
	s->nmats = n;
	s->counts.materials = n;
	return RAD_OK;
}

static rad_status merge_quads(rad_scene *s, rad_error *err)
{
	edge_map m;
	uint8_t *pair = rad_mem_calloc(&s->mem, RAD_MEM_SCRATCH, s->npolys, 1);
	/* The kept polygons' runs (no more than there are). */
	rad_node_run *runs = rad_mem_alloc(&s->mem, RAD_MEM_GEOMETRY,
	                                   (size_t)s->nruns * sizeof(*runs));
	if (!pair || (s->nruns && !runs) || edge_map_build(&m, s)) {
		rad_mem_free(&s->mem, RAD_MEM_SCRATCH, pair);
		rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, runs);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "commit: out of memory "
		                "merging %u triangles",
		                s->npolys);
	}
	for (uint32_t t = 0; t < s->npolys; t++)
		if (duplicate_of_earlier(s, &m, t)) {
			pair[t] = PAIR_DUPLICATE;
			s->counts.triangles_duplicate++;
		}
	rad_status st = RAD_OK;
	for (uint32_t t = 0; t < s->npolys && !st; t++)
		if (pair[t] == PAIR_NONE)
			st = pair_triangle(s, &m, pair, t, err);
	if (st) {
		rad_mem_free(&s->mem, RAD_MEM_SCRATCH, m.slot);
		rad_mem_free(&s->mem, RAD_MEM_SCRATCH, pair);
		rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, runs);
		return st;
	}
	uint32_t n = 0, nruns = 0;
	for (uint32_t t = 0; t < s->npolys; t++)
		if (pair[t] == PAIR_NONE || pair[t] == PAIR_QUAD) {
			rad_node_runs_note(runs, &nruns, n,
			                   rad_poly_node(s, t));
			s->polys[n++] = s->polys[t];
		}
	s->npolys = n;
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->runs);
	s->runs = runs;
	s->nruns = s->cap_runs = nruns;
	rad_mem_free(&s->mem, RAD_MEM_SCRATCH, m.slot);
	rad_mem_free(&s->mem, RAD_MEM_SCRATCH, pair);
	s->merged = 1;
	rad_scene_fit_polys(s);
	rad_scene_material_index_free(s);
	if (!s->stage_base)
		return RAD_OK;
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->stage_base);
	s->stage_base = NULL;
	return drop_unused_materials(s, err);
}

/* ---------------------------------------------------------- back faces */

/*
 * The back face of each two-sided polygon: the same sheet turned over
 * (the same vertices, e1 and e2 swapped, the normal negated), appended
 * after every polygon the BVH holds.  Both faces are polygons to the
 * solvers, each with its own elements and radiosity; the sheet is in the
 * BVH once, and s->twin leads a hit from behind to the back face.
 */
static rad_status make_back_faces(rad_scene *s, rad_error *err)
{
	uint32_t nf = s->npolys, nb = 0;
	for (uint32_t i = 0; i < nf; i++)
		nb += s->polys[i].side == RAD_SIDE_FRONT;
	if (nb == 0)
		return RAD_OK;
	if (nb > RAD_SCENE_MAX_IDS - nf)
		return rad_fail(err, RAD_ERR_LIMIT,
		                "commit: %u polygons and %u back faces are "
		                "more than %u",
		                nf, nb, RAD_SCENE_MAX_IDS);
	/* The back faces' runs follow their front faces': no more again. */
	rad_node_run *runs =
	        rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->runs,
	                        2 * (size_t)s->nruns * sizeof(*runs));
	if (runs) {
		s->runs = runs;
		s->cap_runs = 2 * s->nruns;
	}
	uint32_t *twin = runs ? rad_mem_alloc(&s->mem, RAD_MEM_GEOMETRY,
	                                      nf * sizeof(*twin))
	                      : NULL;
	rad_poly *polys =
	        twin ? rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->polys,
	                               (size_t)(nf + nb) * sizeof(*polys))
	             : NULL;
	if (!polys) {
		rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, twin);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "commit: out of memory for %u back faces", nb);
	}
	s->polys = polys;
	uint32_t k = nf;
	for (uint32_t i = 0; i < nf; i++) {
		twin[i] = RAD_NONE;
		if (polys[i].side != RAD_SIDE_FRONT)
			continue;
		rad_poly b = polys[i];
		/* e1 and e2 swapped: the corners in the other turn. */
		if (b.quad) {
			b.v[1] = polys[i].v[3];
			b.v[3] = polys[i].v[1];
		} else {
			b.v[1] = polys[i].v[2];
			b.v[2] = b.v[3] = polys[i].v[1];
		}
		b.side = RAD_SIDE_BACK;
		rad_node_runs_note(s->runs, &s->nruns, k, rad_poly_node(s, i));
		polys[k] = b;
		twin[i] = k++;
	}
	s->npolys = s->cap_polys = k;
	s->counts.back_faces = nb;
	s->twin = twin;
	return RAD_OK;
}

/* -------------------------------------------------------- bounds and flux */

static void grow_bounds(rad_scene *s, v3 p)
{
	const double c[3] = {p.x, p.y, p.z};
	for (int i = 0; i < 3; i++) {
		s->lo[i] = fmin(s->lo[i], c[i]);
		s->hi[i] = fmax(s->hi[i], c[i]);
	}
}

static void compute_bounds(rad_scene *s)
{
	for (int i = 0; i < 3; i++) {
		s->lo[i] = INFINITY;
		s->hi[i] = -INFINITY;
	}
	for (uint32_t i = 0; i < s->npolys; i++) {
		v3 v[4];
		int nv = rad_poly_corners(s, &s->polys[i], v);
		for (int k = 0; k < nv; k++)
			grow_bounds(s, v[k]);
	}
	for (uint32_t i = 0; i < s->nlights; i++)
		if (s->lights[i].kind != RAD_LIGHT_DIRECTIONAL)
			grow_bounds(s, v3_d(s->lights[i].pos));
	s->diag = v3_len(v3_sub(v3_d(s->hi), v3_d(s->lo)));
	/* Polygons have positive area, so diag > 0; a fallback keeps the
	 * "diag > 0" promise of scene.h even against float underflow. */
	if (!(s->diag > 0))
		s->diag = 1.0;
}

/*
 * Flux (lm) of one light, per unit intensity.  Used only to scale
 * refinement thresholds, so the range window is ignored (an upper bound).
 * A point light with a table: the table's exact flux over its peak
 * (gonio.c).
 * Spot: 2 pi int I(mu) dmu over the cone, exact for glTF's quadratic
 * falloff: (1 - ci) + (ci - co) / 3.  Directional: the scene's bounding
 * box intercepts E x its projected area |d.x| Ly Lz + |d.y| Lx Lz + ...
 */
static double light_flux_per_unit(const rad_scene *s, const rad_light *L)
{
	switch (L->kind) {
	case RAD_LIGHT_POINT:
		return L->gonio ? L->gonio->flux_per_peak : 4.0 * M_PI;
	case RAD_LIGHT_SPOT:
		return 2.0 * M_PI *
		       ((1.0 - L->cos_inner) +
		        (L->cos_inner - L->cos_outer) / 3.0);
	case RAD_LIGHT_DIRECTIONAL:
		break;
	}
	double ext[3];
	for (int i = 0; i < 3; i++)
		ext[i] = s->hi[i] - s->lo[i];
	return fabs(L->dir[0]) * ext[1] * ext[2] +
	       fabs(L->dir[1]) * ext[0] * ext[2] +
	       fabs(L->dir[2]) * ext[0] * ext[1];
}

static void compute_totals(rad_scene *s)
{
	s->total_area = 0;
	s->counts.emitters = 0;
	s->counts.quads = 0;
	for (int c = 0; c < 3; c++)
		s->total_flux[c] = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		const rad_material *m = &s->mats[p->mat];
		s->total_area += p->area;
		s->counts.quads += p->quad;
		s->counts.emitters += rad_material_emits(m);
		for (int c = 0; c < 3; c++)
			s->total_flux[c] += (double)p->area * m->emit[c];
	}
	for (uint32_t i = 0; i < s->nlights; i++) {
		const rad_light *L = &s->lights[i];
		double k = light_flux_per_unit(s, L);
		for (int c = 0; c < 3; c++)
			s->total_flux[c] += k * L->intensity[c];
	}
	s->counts.polygons = s->npolys;
}

rad_status rad_scene_commit(rad_scene *s, rad_error *err)
{
	rad_status st = rad_scene_check_open(s, "commit", err);
	if (st)
		return st;
	if (s->npolys == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "scene has no polygons (%u triangles offered, "
		                "%u non-finite, %u degenerate)",
		                s->counts.triangles_in,
		                s->counts.triangles_nonfinite,
		                s->counts.triangles_degenerate);
	if (!s->merged && (st = merge_quads(s, err)))
		return st;
	compute_bounds(s);
	/* A commit retried after the BVH failed has done these already. */
	if (!s->twin && (st = rad_scene_conform(s, err)))
		return st;
	if (!s->twin) {
		s->nfront = s->npolys;
		if ((st = make_back_faces(s, err)))
			return st;
	}
	rad_scene_vertex_index_free(s);
	compute_totals(s);
	if ((st = rad_vis_build(s, err)))
		return st;
	s->committed = 1;
	rad_error_clear(err);
	return RAD_OK;
}

/* ------------------------------------------------------------------ free */

void rad_scene_free(rad_scene *s)
{
	if (!s)
		return;
	rad_vis_free(s);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->polys);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->verts);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->vert_slots);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->stage_base);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->twin);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->runs);
	rad_mem_free(&s->mem, RAD_MEM_MATERIALS, s->mats);
	rad_scene_material_index_free(s);
	for (uint32_t i = 0; i < s->nlights; i++) {
		rad_mem_free(&s->mem, RAD_MEM_NAMES, s->lights[i].name);
		rad_mem_free(&s->mem, RAD_MEM_LIGHTS, s->lights[i].gonio);
	}
	rad_mem_free(&s->mem, RAD_MEM_LIGHTS, s->lights);
	for (uint32_t i = 0; i < s->nnodes; i++)
		rad_mem_free(&s->mem, RAD_MEM_NAMES, s->nodes[i]);
	rad_mem_free(&s->mem, RAD_MEM_NAMES, s->nodes);
	free(s);
}
