/*
 * scene.c -- the scene builder: validated input, shared materials,
 * parallelogram merging, bounds and flux, then the BVH (vis.c).
 *
 * Input arrives as loose triangles in double precision.  Each triangle is
 * checked once here (finite, not degenerate) so that nothing downstream
 * has to: form factors, the hierarchy and Embree all assume a unit normal
 * and a positive area.  Bad triangles are skipped and counted rather than
 * refused, because real meshes carry a few and the user wants the rest lit.
 * Bad materials, lights and ids are refused: they are authoring errors.
 *
 * DESIGN
 * - A triangle is stored at once as a rad_poly whose edges are computed
 *   in double from the input and then rounded, so the stored shape is
 *   accurate even far from the origin.  The float-rounded input vertices
 *   are kept beside it (s->stage) until commit: shared vertices of a mesh
 *   round to bit-identical floats, which lets the merger find shared edges
 *   by exact key instead of by a tolerance search.
 * - At commit, pairs of triangles that share an edge and together form a
 *   parallelogram become one quad (half the elements, half the links for
 *   the very common case of rectangles exported as two triangles).
 *   Matching is greedy in input order, each triangle preferring its
 *   longest edge as the diagonal, which pairs the usual grid
 *   triangulations into their cells rather than into skewed neighbours.
 * - The rad_scene struct itself is allocated with plain calloc and is not
 *   counted: it holds the counters, so counting it would leave the report
 *   non-zero at the moment the last counted byte goes away.  Everything it
 *   points to is counted; after rad_scene_free() every kind is zero.
 * - A failed commit leaves the scene uncommitted and may be retried (the
 *   merge is skipped once done: s->stage is gone); once merged, the scene
 *   takes no more triangles.
 */
#include <float.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "scene.h"
#include "vis.h"

/* Ids stay far below RAD_NONE and the tag bits of hier.h; the edge map
 * (4 slots per triangle) fits 32-bit indices. */
#define MAX_IDS (1u << 28)

/* Quad merging: coplanarity as 1 - cos between normals, parallelogram
 * closure relative to the longest edge. */
#define MERGE_COPLANAR 1e-6
#define MERGE_CLOSE_REL 1e-6

rad_status rad_scene_new(rad_scene **out, rad_error *err)
{
	rad_scene *s = calloc(1, sizeof(*s));
	*out = NULL;
	if (!s)
		return rad_fail(err, RAD_ERR_NOMEM, "scene: out of memory");
	rad_mem_init(&s->mem);
	*out = s;
	rad_error_clear(err);
	return RAD_OK;
}

/* Make room for one more element in a counted array (doubling). */
static int grow(rad_mem *m, rad_mem_kind kind, void **arr, uint32_t *cap,
                uint32_t need, size_t elsize)
{
	if (need <= *cap)
		return 1;
	uint32_t ncap = *cap ? *cap : 16;
	while (ncap < need)
		ncap *= 2;
	void *p = rad_mem_realloc(m, kind, *arr, (size_t)ncap * elsize);
	if (!p)
		return 0;
	*arr = p;
	*cap = ncap;
	return 1;
}

static int finite3(const double v[3])
{
	return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static rad_status check_open(const rad_scene *s, const char *what,
                             rad_error *err)
{
	if (s->committed)
		return rad_fail(err, RAD_ERR_STATE,
		                "%s: scene is already committed", what);
	return RAD_OK;
}

/* ------------------------------------------------------------ materials */

/* Reflectance as stored: values just below 1 must not round up to 1.0f,
 * which would make a lossless surface out of a valid input. */
static float rho_float(double r)
{
	float f = (float)r;
	return f < 1.0f ? f : nextafterf(1.0f, 0.0f);
}

static rad_status make_material(const double rho[3], const double lum[3],
                                uint32_t which, rad_material *m, rad_error *err)
{
	for (int c = 0; c < 3; c++) {
		if (!(rho[c] >= 0.0 && rho[c] < 1.0))
			return rad_fail(err, RAD_ERR_INVALID,
			                "material %u: reflectance (%g, %g, %g) "
			                "must be finite and in [0, 1)",
			                which, rho[0], rho[1], rho[2]);
		/* Exitance of a Lambertian emitter is pi x luminance. */
		double e = M_PI * lum[c];
		if (!(lum[c] >= 0.0 && e <= FLT_MAX))
			return rad_fail(err, RAD_ERR_INVALID,
			                "material %u: luminance (%g, %g, %g) "
			                "cd/m2 must be finite and >= 0",
			                which, lum[0], lum[1], lum[2]);
		m->rho[c] = rho_float(rho[c]);
		m->emit[c] = (float)e;
	}
	return RAD_OK;
}

static int same_material(const rad_material *a, const rad_material *b)
{
	for (int c = 0; c < 3; c++)
		if (a->rho[c] != b->rho[c] || a->emit[c] != b->emit[c])
			return 0;
	return 1;
}

/*
 * Sharing is a linear search: scenes offer materials per glTF material or
 * primitive (tens to a few thousands), never per triangle, so the table
 * stays small and a hash would cost more code than it saves time.
 */
rad_status rad_scene_add_material(rad_scene *s, const double reflectance[3],
                                  const double luminance[3], uint32_t *id,
                                  rad_error *err)
{
	rad_status st = check_open(s, "material", err);
	if (st)
		return st;
	rad_material m;
	st = make_material(reflectance, luminance, s->counts.materials_offered,
	                   &m, err);
	if (st)
		return st;
	s->counts.materials_offered++;
	for (uint32_t i = 0; i < s->nmats; i++) {
		if (same_material(&s->mats[i], &m)) {
			*id = i;
			return RAD_OK;
		}
	}
	if (s->nmats >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "material: too many");
	if (!grow(&s->mem, RAD_MEM_MATERIALS, (void **)&s->mats, &s->cap_mats,
	          s->nmats + 1, sizeof(*s->mats)))
		return rad_fail(err, RAD_ERR_NOMEM, "material: out of memory");
	s->mats[s->nmats] = m;
	*id = s->nmats++;
	s->counts.materials = s->nmats;
	return RAD_OK;
}

/* ----------------------------------------------------------------- nodes */

rad_status rad_scene_add_node(rad_scene *s, const char *name, uint32_t *id,
                              rad_error *err)
{
	rad_status st = check_open(s, "node", err);
	if (st)
		return st;
	if (s->nnodes >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "node: too many");
	if (!grow(&s->mem, RAD_MEM_NAMES, (void **)&s->nodes, &s->cap_nodes,
	          s->nnodes + 1, sizeof(*s->nodes)))
		return rad_fail(err, RAD_ERR_NOMEM, "node: out of memory");
	char *copy = NULL;
	if (name && !(copy = rad_mem_strdup(&s->mem, RAD_MEM_NAMES, name)))
		return rad_fail(err, RAD_ERR_NOMEM, "node '%s': out of memory",
		                name);
	s->nodes[s->nnodes] = copy;
	*id = s->nnodes++;
	s->counts.nodes = s->nnodes;
	return RAD_OK;
}

/* ------------------------------------------------------------- triangles */

/*
 * Turn one input triangle into a stored polygon and its staged vertices.
 * Coordinates beyond float range count as non-finite: they would be
 * infinite once stored.
 */
static enum rad_poly_verdict make_triangle(const double *xyz, rad_poly *p,
                                           float stage[9])
{
	v3 v[3];
	for (int k = 0; k < 3; k++) {
		v[k] = v3_d(xyz + 3 * k);
		for (int c = 0; c < 3; c++) {
			double x = xyz[3 * k + c];
			if (!(fabs(x) <= FLT_MAX))
				return RAD_POLY_NONFINITE;
			/* + 0.0f turns -0 into +0 for exact edge keys. */
			stage[3 * k + c] = (float)x + 0.0f;
		}
	}
	v3 e1 = v3_sub(v[1], v[0]), e2 = v3_sub(v[2], v[0]);
	v3 e3 = v3_sub(v[2], v[1]);
	double lmax2 =
	        fmax(v3_dot(e1, e1), fmax(v3_dot(e2, e2), v3_dot(e3, e3)));
	v3 c = v3_cross(e1, e2);
	double area = 0.5 * v3_len(c);
	if (!(area > SLIVER_REL * lmax2))
		return RAD_POLY_DEGENERATE;
	v3_store_f(p->p0, v[0]);
	v3_store_f(p->e1, e1);
	v3_store_f(p->e2, e2);
	v3 n = v3_scale(c, 0.5 / area);
	enum rad_poly_verdict verdict = rad_poly_check_stored(p, area, n);
	if (verdict != RAD_POLY_OK)
		return verdict;
	v3_store_f(p->n, n);
	p->area = (float)area;
	p->quad = 0;
	return RAD_POLY_OK;
}

/* Room for ntri more polygons; the stage array always has the capacity of
 * the polygon array. */
static rad_status reserve_polys(rad_scene *s, size_t ntri, rad_error *err)
{
	if (ntri > MAX_IDS - s->npolys)
		return rad_fail(err, RAD_ERR_LIMIT,
		                "triangles: more than %u polygons", MAX_IDS);
	uint32_t need = s->npolys + (uint32_t)ntri, cap = s->cap_polys;
	if (!grow(&s->mem, RAD_MEM_GEOMETRY, (void **)&s->polys, &cap, need,
	          sizeof(*s->polys)))
		return rad_fail(err, RAD_ERR_NOMEM, "triangles: out of memory");
	if (cap == s->cap_polys)
		return RAD_OK;
	float *stage = rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->stage,
	                               (size_t)cap * 9 * sizeof(float));
	if (!stage)
		return rad_fail(err, RAD_ERR_NOMEM, "triangles: out of memory");
	s->stage = stage;
	s->cap_polys = cap;
	return RAD_OK;
}

rad_status rad_scene_add_triangles(rad_scene *s, uint32_t material,
                                   uint32_t node, const double *xyz,
                                   size_t ntri, rad_error *err)
{
	rad_status st = check_open(s, "triangles", err);
	if (st)
		return st;
	if (material >= s->nmats)
		return rad_fail(err, RAD_ERR_INVALID,
		                "triangles: material %u does not exist "
		                "(%u materials)",
		                material, s->nmats);
	if (node >= s->nnodes)
		return rad_fail(err, RAD_ERR_INVALID,
		                "triangles: node %u does not exist (%u nodes)",
		                node, s->nnodes);
	if (ntri && !xyz)
		return rad_fail(err, RAD_ERR_INVALID,
		                "triangles: NULL coordinates for %zu", ntri);
	/* Polygons without staged vertices were merged by a commit that then
	 * failed: new triangles could not be merged with them. */
	if (s->npolys && !s->stage)
		return rad_fail(err, RAD_ERR_STATE,
		                "triangles: a failed commit has merged the "
		                "scene; only commit may be retried");
	if ((st = reserve_polys(s, ntri, err)))
		return st;
	for (size_t i = 0; i < ntri; i++) {
		rad_poly *p = &s->polys[s->npolys];
		float *stage = s->stage + (size_t)9 * s->npolys;
		s->counts.triangles_in++;
		switch (make_triangle(xyz + 9 * i, p, stage)) {
		case RAD_POLY_NONFINITE:
			s->counts.triangles_nonfinite++;
			continue;
		case RAD_POLY_DEGENERATE:
			s->counts.triangles_degenerate++;
			continue;
		case RAD_POLY_OK:
			break;
		}
		p->mat = material;
		p->node = node;
		s->npolys++;
	}
	s->counts.polygons = s->npolys;
	return RAD_OK;
}

/* ---------------------------------------------------------------- lights */

static rad_status check_spot(const rad_light_desc *d, uint32_t which,
                             rad_error *err)
{
	if (!(d->inner_cone >= 0.0 && d->inner_cone < d->outer_cone &&
	      d->outer_cone <= M_PI / 2))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: spot cones inner %g, outer %g rad "
		                "need 0 <= inner < outer <= pi/2",
		                which, d->inner_cone, d->outer_cone);
	return RAD_OK;
}

static rad_status check_light(const rad_light_desc *d, uint32_t which,
                              rad_error *err)
{
	if ((unsigned)d->kind > RAD_LIGHT_DIRECTIONAL)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: kind %d unknown", which,
		                (int)d->kind);
	const double *I = d->intensity;
	if (!finite3(I) || I[0] < 0 || I[1] < 0 || I[2] < 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: intensity (%g, %g, %g) must be "
		                "finite and >= 0",
		                which, I[0], I[1], I[2]);
	if (!(d->range >= 0.0 && isfinite(d->range)))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: range %g must be finite and >= 0",
		                which, d->range);
	if (d->kind != RAD_LIGHT_DIRECTIONAL && !finite3(d->position))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: position is not finite", which);
	if (d->kind == RAD_LIGHT_POINT)
		return RAD_OK;
	v3 dir = v3_d(d->direction);
	if (!v3_finite(dir) || !(v3_len(dir) > 0))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: direction must be finite and "
		                "non-zero",
		                which);
	return d->kind == RAD_LIGHT_SPOT ? check_spot(d, which, err) : RAD_OK;
}

rad_status rad_scene_add_light(rad_scene *s, const rad_light_desc *d,
                               rad_error *err)
{
	rad_status st = check_open(s, "light", err);
	if (st || (st = check_light(d, s->nlights, err)))
		return st;
	if (s->nlights >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "light: too many");
	if (!grow(&s->mem, RAD_MEM_LIGHTS, (void **)&s->lights, &s->cap_lights,
	          s->nlights + 1, sizeof(*s->lights)))
		return rad_fail(err, RAD_ERR_NOMEM, "light: out of memory");
	rad_light L = {.kind = d->kind, .range = d->range};
	if (d->name &&
	    !(L.name = rad_mem_strdup(&s->mem, RAD_MEM_NAMES, d->name)))
		return rad_fail(err, RAD_ERR_NOMEM, "light: out of memory");
	memcpy(L.intensity, d->intensity, sizeof(L.intensity));
	v3 dir = v3_make(0, 0, -1); /* unused by point lights: glTF's -Z */
	if (d->kind != RAD_LIGHT_POINT)
		dir = v3_norm(v3_d(d->direction));
	L.dir[0] = dir.x;
	L.dir[1] = dir.y;
	L.dir[2] = dir.z;
	if (d->kind != RAD_LIGHT_DIRECTIONAL)
		memcpy(L.pos, d->position, sizeof(L.pos));
	/* Point and directional lights have no cone: -1 lets every
	 * direction through should anyone test it. */
	L.cos_inner = L.cos_outer = -1.0;
	if (d->kind == RAD_LIGHT_SPOT) {
		L.cos_inner = cos(d->inner_cone);
		L.cos_outer = cos(d->outer_cone);
	}
	s->lights[s->nlights++] = L;
	s->counts.lights = s->nlights;
	return RAD_OK;
}

/* ---------------------------------------------------------- quad merging */

/* Directed edge k of staged triangle t runs from vertex k to vertex k+1. */
static const float *stage_vertex(const float *stage, uint32_t t, int k)
{
	return stage + (size_t)9 * t + 3 * (k % 3);
}

static uint32_t edge_hash(const float *a, const float *b)
{
	uint32_t h = 0x811c9dc5u;
	for (int i = 0; i < 6; i++) {
		uint32_t bits;
		memcpy(&bits, i < 3 ? a + i : b + i - 3, sizeof(bits));
		h = (h ^ bits) * 0x01000193u;
		h ^= h >> 15;
	}
	return h * 0x9e3779b1u;
}

typedef struct edge_map {
	const float *stage;
	uint32_t *slot; /* t*3 + k of a directed edge, or RAD_NONE; SCRATCH */
	uint32_t mask;  /* capacity - 1 (a power of two) */
} edge_map;

static int same_point(const float *a, const float *b)
{
	return a[0] == b[0] && a[1] == b[1] && a[2] == b[2];
}

/* Slot holding the directed edge a -> b, or the empty slot ending the
 * probe sequence. */
static uint32_t *edge_probe(const edge_map *m, const float *a, const float *b)
{
	uint32_t i = edge_hash(a, b) & m->mask;
	for (;; i = (i + 1) & m->mask) {
		uint32_t e = m->slot[i];
		if (e == RAD_NONE)
			return &m->slot[i];
		const float *ea = stage_vertex(m->stage, e / 3, (int)(e % 3));
		const float *eb =
		        stage_vertex(m->stage, e / 3, (int)(e % 3) + 1);
		if (same_point(ea, a) && same_point(eb, b))
			return &m->slot[i];
	}
}

static rad_status edge_map_build(edge_map *m, rad_mem *mem, const float *stage,
                                 uint32_t ntri)
{
	uint32_t cap = 16; /* load factor <= 3/4 */
	while (cap < 4u * ntri)
		cap *= 2;
	m->stage = stage;
	m->mask = cap - 1;
	m->slot = rad_mem_alloc(mem, RAD_MEM_SCRATCH, (size_t)cap * 4);
	if (!m->slot)
		return RAD_ERR_NOMEM;
	memset(m->slot, 0xff, (size_t)cap * 4);
	for (uint32_t t = 0; t < ntri; t++) {
		for (int k = 0; k < 3; k++) {
			uint32_t *slot =
			        edge_probe(m, stage_vertex(stage, t, k),
			                   stage_vertex(stage, t, k + 1));
			/* A repeated directed edge (non-manifold or
			 * duplicate geometry): the first keeps it. */
			if (*slot == RAD_NONE)
				*slot = t * 3 + (uint32_t)k;
		}
	}
	return RAD_OK;
}

/*
 * Can triangle t, seen as (a, b, c) with b -> c its edge k and a the
 * opposite corner, pair with u, which holds c -> b with opposite corner d, into
 * the parallelogram a, b, d, c?  Closure d = b + c - a is checked relative to
 * the longest edge, plus the rounding the staged floats carry.
 */
static int forms_parallelogram(const rad_scene *s, uint32_t t, int k,
                               uint32_t u, int j)
{
	const rad_poly *pt = &s->polys[t], *pu = &s->polys[u];
	if (pt->mat != pu->mat || pt->node != pu->node)
		return 0;
	if (v3_dot(v3_f(pt->n), v3_f(pu->n)) < 1.0 - MERGE_COPLANAR)
		return 0;
	v3 a = v3_f(stage_vertex(s->stage, t, k + 2));
	v3 b = v3_f(stage_vertex(s->stage, t, k));
	v3 c = v3_f(stage_vertex(s->stage, t, k + 1));
	v3 d = v3_f(stage_vertex(s->stage, u, j + 2));
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

/* Rewrite triangle t as the parallelogram with corner a (opposite edge k). */
static void make_quad(rad_scene *s, uint32_t t, int k)
{
	rad_poly *p = &s->polys[t];
	v3 a = v3_f(stage_vertex(s->stage, t, k + 2));
	v3 e1 = v3_sub(v3_f(stage_vertex(s->stage, t, k)), a);
	v3 e2 = v3_sub(v3_f(stage_vertex(s->stage, t, k + 1)), a);
	v3_store_f(p->p0, a);
	v3_store_f(p->e1, e1);
	v3_store_f(p->e2, e2);
	p->area = (float)v3_len(v3_cross(v3_f(p->e1), v3_f(p->e2)));
	p->quad = 1;
}

/* Edges of t, longest first: the diagonal of a cell is tried first. */
static void edges_by_length(const float *stage, uint32_t t, int order[3])
{
	double len[3];
	for (int k = 0; k < 3; k++) {
		order[k] = k;
		len[k] = v3_len(v3_sub(v3_f(stage_vertex(stage, t, k + 1)),
		                       v3_f(stage_vertex(stage, t, k))));
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
		uint32_t e = *edge_probe(m, stage_vertex(s->stage, t, k),
		                         stage_vertex(s->stage, t, k + 1));
		uint32_t u = e / 3;
		if (e == RAD_NONE || u >= t)
			continue;
		int du = (int)(e % 3) - k, same = 1;
		for (int i = 0; i < 3; i++)
			same &= same_point(
			        stage_vertex(s->stage, t, i),
			        stage_vertex(s->stage, u, i + du + 3));
		if (same)
			return 1;
	}
	return 0;
}

/* Pair t with its first mergeable free neighbour. */
static void pair_triangle(rad_scene *s, const edge_map *m, uint8_t *pair,
                          uint32_t t)
{
	int order[3];
	edges_by_length(s->stage, t, order);
	for (int i = 0; i < 3; i++) {
		int k = order[i];
		uint32_t e = *edge_probe(m, stage_vertex(s->stage, t, k + 1),
		                         stage_vertex(s->stage, t, k));
		if (e == RAD_NONE || e / 3 == t || pair[e / 3] != PAIR_NONE)
			continue;
		uint32_t u = e / 3;
		if (!forms_parallelogram(s, t, k, u, (int)(e % 3)))
			continue;
		make_quad(s, t, k);
		pair[t] = PAIR_QUAD;
		pair[u] = PAIR_ABSORBED;
		return;
	}
}

static rad_status merge_quads(rad_scene *s, rad_error *err)
{
	edge_map m;
	uint8_t *pair = rad_mem_calloc(&s->mem, RAD_MEM_SCRATCH, s->npolys, 1);
	if (!pair || edge_map_build(&m, &s->mem, s->stage, s->npolys)) {
		rad_mem_free(&s->mem, RAD_MEM_SCRATCH, pair);
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
	for (uint32_t t = 0; t < s->npolys; t++)
		if (pair[t] == PAIR_NONE)
			pair_triangle(s, &m, pair, t);
	uint32_t n = 0;
	for (uint32_t t = 0; t < s->npolys; t++)
		if (pair[t] == PAIR_NONE || pair[t] == PAIR_QUAD)
			s->polys[n++] = s->polys[t];
	s->npolys = n;
	rad_mem_free(&s->mem, RAD_MEM_SCRATCH, m.slot);
	rad_mem_free(&s->mem, RAD_MEM_SCRATCH, pair);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->stage);
	s->stage = NULL;
	rad_scene_fit_polys(s);
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
		int nv = rad_poly_corners(&s->polys[i], v);
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
 * Spot: 2 pi int I(mu) dmu over the cone, exact for glTF's quadratic
 * falloff: (1 - ci) + (ci - co) / 3.  Directional: the scene's bounding
 * box intercepts E x its projected area |d.x| Ly Lz + |d.y| Lx Lz + ...
 */
static double light_flux_per_unit(const rad_scene *s, const rad_light *L)
{
	switch (L->kind) {
	case RAD_LIGHT_POINT:
		return 4.0 * M_PI;
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
	rad_status st = check_open(s, "commit", err);
	if (st)
		return st;
	if (s->npolys == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "scene has no polygons (%u triangles offered, "
		                "%u non-finite, %u degenerate)",
		                s->counts.triangles_in,
		                s->counts.triangles_nonfinite,
		                s->counts.triangles_degenerate);
	if (s->stage && (st = merge_quads(s, err)))
		return st;
	compute_bounds(s);
	if ((st = rad_scene_conform(s, err)))
		return st;
	compute_totals(s);
	if ((st = rad_vis_build(s, err)))
		return st;
	s->committed = 1;
	rad_error_clear(err);
	return RAD_OK;
}

/* ----------------------------------------------------------------- query */

void rad_scene_counts_get(const rad_scene *s, rad_scene_counts *out)
{
	*out = s->counts;
}

void rad_scene_memory(const rad_scene *s, rad_mem_report *out)
{
	rad_mem_report_clear(out);
	rad_mem_report_add(&s->mem, out);
}

void rad_scene_bounds(const rad_scene *s, double lo[3], double hi[3])
{
	memcpy(lo, s->lo, sizeof(s->lo));
	memcpy(hi, s->hi, sizeof(s->hi));
}

void rad_scene_free(rad_scene *s)
{
	if (!s)
		return;
	rad_vis_free(s);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->polys);
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->stage);
	rad_mem_free(&s->mem, RAD_MEM_MATERIALS, s->mats);
	for (uint32_t i = 0; i < s->nlights; i++)
		rad_mem_free(&s->mem, RAD_MEM_NAMES, s->lights[i].name);
	rad_mem_free(&s->mem, RAD_MEM_LIGHTS, s->lights);
	for (uint32_t i = 0; i < s->nnodes; i++)
		rad_mem_free(&s->mem, RAD_MEM_NAMES, s->nodes[i]);
	rad_mem_free(&s->mem, RAD_MEM_NAMES, s->nodes);
	free(s);
}
