/*
 * scene.c -- the scene builder: validated input, shared materials,
 * lights, nodes; commit.c turns what it gathered into a committed scene.
 *
 * Input arrives as loose triangles in double precision.  Each triangle is
 * checked once here (finite, not degenerate) so that nothing downstream
 * has to: form factors, the hierarchy and Embree all assume a unit normal
 * and a positive area.  Bad triangles are skipped and counted rather than
 * refused, because real meshes carry a few and the user wants the rest lit.
 * Bad materials, lights and ids are refused: they are authoring errors.
 *
 * DESIGN
 * - A triangle is stored at once as a rad_poly: its corners are vertex
 *   ids, each distinct float point stored once (rad_scene_vertex_id), so
 *   the shared vertices of a mesh are one vertex and the merger finds
 *   shared edges by id.  Vertices are relative to the first corner
 *   offered (s->origin), so a scene far from the origin keeps its edges,
 *   the float differences of its corners, as exact as one near it.  The
 *   normal and area are computed in double from the input, and the float
 *   edges must agree with them (rad_poly_check_edges).
 * - The rad_scene struct itself is allocated with plain calloc and is not
 *   counted: it holds the counters, so counting it would leave the report
 *   non-zero at the moment the last counted byte goes away.  Everything it
 *   points to is counted; after rad_scene_free() every kind is zero.
 */
#include <float.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "scene.h"

/* Ids stay far below RAD_NONE and the tag bits of hier.h; the edge map
 * (4 slots per triangle) fits 32-bit indices. */
#define MAX_IDS RAD_SCENE_MAX_IDS

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

rad_status rad_scene_check_open(const rad_scene *s, const char *what,
                                rad_error *err)
{
	if (s->committed)
		return rad_fail(err, RAD_ERR_STATE,
		                "%s: scene is already committed", what);
	return RAD_OK;
}

/* ---------------------------------------------------------- id indexes */

/*
 * The builder's indexes of distinct records, materials and vertices:
 * open addressing over their ids (id + 1 per slot, 0 = free), kept at
 * most half full, until commit.  A lookup probes from the key's hash to
 * the first free slot.
 */
typedef uint32_t (*id_hash_fn)(const rad_scene *s, uint32_t id);

static void index_put(uint32_t *slots, uint32_t mask, uint32_t hash,
                      uint32_t id)
{
	uint32_t i = hash & mask;
	while (slots[i])
		i = (i + 1) & mask;
	slots[i] = id + 1;
}

/* Room for n ids in the index (*slots, *mask): when it must grow (or is
 * gone), a new one of at least `least` slots holds ids 0 .. have-1 again.
 * 0 if out of memory. */
static int index_fit(rad_scene *s, rad_mem_kind kind, uint32_t **slots,
                     uint32_t *mask, size_t n, size_t least, uint32_t have,
                     id_hash_fn hash)
{
	if (*slots && 2 * n <= (size_t)*mask + 1)
		return 1;
	size_t cap = least;
	while (cap < 2 * n)
		cap *= 2;
	uint32_t *fresh = rad_mem_calloc(&s->mem, kind, cap, sizeof(*fresh));
	if (!fresh)
		return 0;
	rad_mem_free(&s->mem, kind, *slots);
	*slots = fresh;
	*mask = (uint32_t)(cap - 1);
	for (uint32_t id = 0; id < have; id++)
		index_put(fresh, *mask, hash(s, id), id);
	return 1;
}

/* ------------------------------------------------------------ materials */

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
		m->rho[c] = rad_rho_float(rho[c]);
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
 * Sharing: a linear search while the table is small (scenes offer
 * materials per glTF material, tens to a few thousands), then a hash,
 * which textured scenes need: each distinct texture mean under a polygon
 * is a material of its own.  The hash lives until commit.
 */
#define MAT_LINEAR 64

static uint32_t material_hash(const rad_material *m)
{
	return rad_hash_end(rad_hash_words(
	        rad_hash_words(RAD_HASH_SEED, m->rho, 3), m->emit, 3));
}

static uint32_t material_hash_id(const rad_scene *s, uint32_t id)
{
	return material_hash(&s->mats[id]);
}

/* Room for n materials in the hash, once past MAT_LINEAR; 0 if out of
 * memory. */
static int material_index_fit(rad_scene *s, uint32_t n)
{
	return n < MAT_LINEAR ||
	       index_fit(s, RAD_MEM_MATERIALS, &s->mat_slots, &s->mat_mask, n,
	                 2 * (size_t)MAT_LINEAR, s->nmats, material_hash_id);
}

void rad_scene_material_index_free(rad_scene *s)
{
	rad_mem_free(&s->mem, RAD_MEM_MATERIALS, s->mat_slots);
	s->mat_slots = NULL;
	s->mat_mask = 0;
}

static int material_find(const rad_scene *s, const rad_material *m,
                         uint32_t *id)
{
	if (!s->mat_slots) {
		for (uint32_t i = 0; i < s->nmats; i++)
			if (same_material(&s->mats[i], m)) {
				*id = i;
				return 1;
			}
		return 0;
	}
	for (uint32_t i = material_hash(m) & s->mat_mask; s->mat_slots[i];
	     i = (i + 1) & s->mat_mask)
		if (same_material(&s->mats[s->mat_slots[i] - 1], m)) {
			*id = s->mat_slots[i] - 1;
			return 1;
		}
	return 0;
}

rad_status rad_scene_material_id(rad_scene *s, const rad_material *m,
                                 uint32_t *id, rad_error *err)
{
	if (material_find(s, m, id))
		return RAD_OK;
	if (s->nmats >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "material: too many");
	if (!grow(&s->mem, RAD_MEM_MATERIALS, (void **)&s->mats, &s->cap_mats,
	          s->nmats + 1, sizeof(*s->mats)) ||
	    !material_index_fit(s, s->nmats + 1))
		return rad_fail(err, RAD_ERR_NOMEM, "material: out of memory");
	s->mats[s->nmats] = *m;
	if (s->mat_slots)
		index_put(s->mat_slots, s->mat_mask, material_hash(m),
		          s->nmats);
	*id = s->nmats++;
	s->counts.materials = s->nmats;
	return RAD_OK;
}

rad_status rad_scene_add_material(rad_scene *s, const double reflectance[3],
                                  const double luminance[3], uint32_t *id,
                                  rad_error *err)
{
	rad_status st = rad_scene_check_open(s, "material", err);
	if (st)
		return st;
	rad_material m;
	st = make_material(reflectance, luminance, s->counts.materials_offered,
	                   &m, err);
	if (st)
		return st;
	s->counts.materials_offered++;
	return rad_scene_material_id(s, &m, id, err);
}

/* ----------------------------------------------------------------- nodes */

rad_status rad_scene_add_node(rad_scene *s, const char *name, uint32_t *id,
                              rad_error *err)
{
	rad_status st = rad_scene_check_open(s, "node", err);
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

/* ------------------------------------------------------------- vertices */

static uint32_t vertex_hash(const float x[3])
{
	return rad_hash_end(rad_hash_words(RAD_HASH_SEED, x, 3));
}

static uint32_t vertex_hash_id(const rad_scene *s, uint32_t id)
{
	return vertex_hash(rad_scene_vert(s, id));
}

/* Room for one more vertex in the hash, which is built again from the
 * vertices when it has gone (a commit retried after it was freed); 0 if
 * out of memory. */
static int vertex_index_fit(rad_scene *s)
{
	return index_fit(s, RAD_MEM_GEOMETRY, &s->vert_slots, &s->vert_mask,
	                 (size_t)s->nverts + 1, 1024, s->nverts,
	                 vertex_hash_id);
}

rad_status rad_scene_vertex_id(rad_scene *s, const float p[3], uint32_t *id,
                               rad_error *err)
{
	/* + 0.0f turns -0 into +0: keys are bits. */
	const float x[3] = {p[0] + 0.0f, p[1] + 0.0f, p[2] + 0.0f};
	if (!vertex_index_fit(s))
		return rad_fail(err, RAD_ERR_NOMEM,
		                "vertices: out of memory (%u vertices)",
		                s->nverts);
	uint32_t i = vertex_hash(x) & s->vert_mask;
	for (; s->vert_slots[i]; i = (i + 1) & s->vert_mask) {
		uint32_t v = s->vert_slots[i] - 1;
		if (memcmp(rad_scene_vert(s, v), x, 3 * sizeof(float)) == 0) {
			*id = v;
			return RAD_OK;
		}
	}
	if (s->nverts >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "vertices: more than %u",
		                MAX_IDS);
	if (s->nverts == s->cap_verts) {
		uint32_t cap = s->cap_verts ? 2 * s->cap_verts : 1024;
		float *v = rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->verts,
		                           (3 * (size_t)cap + RAD_VERT_PAD) *
		                                   sizeof(float));
		if (!v)
			return rad_fail(err, RAD_ERR_NOMEM,
			                "vertices: out of memory (%u vertices)",
			                s->nverts);
		s->verts = v;
		s->cap_verts = cap;
	}
	memcpy(s->verts + 3 * (size_t)s->nverts, x, 3 * sizeof(float));
	s->vert_slots[i] = s->nverts + 1;
	*id = s->nverts++;
	return RAD_OK;
}

void rad_scene_vertex_index_free(rad_scene *s)
{
	rad_mem_free(&s->mem, RAD_MEM_GEOMETRY, s->vert_slots);
	s->vert_slots = NULL;
	s->vert_mask = 0;
	/* Fit the array (keeping the old block if that fails is harmless)
	 * and zero the pad Embree reads past the last vertex. */
	size_t n = 3 * (size_t)s->nverts + RAD_VERT_PAD;
	float *v = rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->verts,
	                           n * sizeof(float));
	if (v) {
		s->verts = v;
		s->cap_verts = s->nverts;
	}
	if (s->verts)
		memset(s->verts + 3 * (size_t)s->nverts, 0,
		       RAD_VERT_PAD * sizeof(float));
}

/* ------------------------------------------------------------ triangles */

/*
 * Turn one input triangle into a stored polygon, but for its corners'
 * vertex ids: the corners rounded to float relative to s->origin go to
 * f (the first triangle sets the origin).  Coordinates beyond float range
 * count as non-finite: they would be infinite once stored.
 */
static enum rad_poly_verdict make_triangle(rad_scene *s, const double *xyz,
                                           rad_poly *p, float f[9])
{
	v3 v[3];
	for (int k = 0; k < 9; k++)
		if (!(fabs(xyz[k]) <= FLT_MAX))
			return RAD_POLY_NONFINITE;
	if (s->nverts == 0)
		memcpy(s->origin, xyz, sizeof(s->origin));
	for (int k = 0; k < 3; k++) {
		v[k] = v3_d(xyz + 3 * k);
		for (int c = 0; c < 3; c++) {
			f[3 * k + c] = (float)(xyz[3 * k + c] - s->origin[c]);
			if (!isfinite(f[3 * k + c]))
				return RAD_POLY_NONFINITE;
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
	float e1f[3], e2f[3];
	for (int k = 0; k < 3; k++) {
		e1f[k] = f[3 + k] - f[k];
		e2f[k] = f[6 + k] - f[k];
	}
	v3 n = v3_scale(c, 0.5 / area);
	enum rad_poly_verdict verdict = rad_poly_check_edges(e1f, e2f, area, n);
	if (verdict != RAD_POLY_OK)
		return verdict;
	p->quad = 0;
	rad_poly_set_shape(p, n, area);
	return RAD_POLY_OK;
}

/* Room for ntri more polygons. */
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
	if (s->stage_base) {
		uint32_t *base = rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY,
		                                 s->stage_base,
		                                 (size_t)cap * sizeof(*base));
		if (!base)
			return rad_fail(err, RAD_ERR_NOMEM,
			                "triangles: out of memory");
		s->stage_base = base;
	}
	s->cap_polys = cap;
	return RAD_OK;
}

/* The first triangles with their own reflectance: every polygon so far
 * merges by its material. */
static rad_status start_stage_base(rad_scene *s, rad_error *err)
{
	if (s->stage_base || s->cap_polys == 0)
		return RAD_OK;
	s->stage_base =
	        rad_mem_alloc(&s->mem, RAD_MEM_GEOMETRY,
	                      (size_t)s->cap_polys * sizeof(*s->stage_base));
	if (!s->stage_base)
		return rad_fail(err, RAD_ERR_NOMEM, "triangles: out of memory");
	for (uint32_t i = 0; i < s->npolys; i++)
		s->stage_base[i] = s->polys[i].mat;
	return RAD_OK;
}

rad_status rad_scene_add_surface(rad_scene *s, const rad_surface_desc *d,
                                 rad_error *err)
{
	uint32_t material = d->material, node = d->node;
	const double *xyz = d->xyz, *rho = d->rho;
	size_t ntri = d->ntri;
	rad_status st = rad_scene_check_open(s, "triangles", err);
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
	/* A commit that then failed has merged the polygons: new triangles
	 * could not be merged with them. */
	if (s->merged)
		return rad_fail(err, RAD_ERR_STATE,
		                "triangles: a failed commit has merged the "
		                "scene; only commit may be retried");
	for (size_t i = 0; rho && i < 3 * ntri; i++)
		if (!(rho[i] >= 0.0 && rho[i] < 1.0))
			return rad_fail(err, RAD_ERR_INVALID,
			                "triangles: reflectance %g of triangle "
			                "%zu must be finite and in [0, 1)",
			                rho[i], i / 3);
	if ((st = reserve_polys(s, ntri, err)))
		return st;
	/* At most one run more: this node's, unless the last run is. */
	if (!grow(&s->mem, RAD_MEM_GEOMETRY, (void **)&s->runs, &s->cap_runs,
	          s->nruns + 1, sizeof(*s->runs)))
		return rad_fail(err, RAD_ERR_NOMEM, "triangles: out of memory");
	if (rho && (st = start_stage_base(s, err)))
		return st;
	for (size_t i = 0; i < ntri; i++) {
		rad_poly *p = &s->polys[s->npolys];
		float f[9];
		s->counts.triangles_in++;
		switch (make_triangle(s, xyz + 9 * i, p, f)) {
		case RAD_POLY_NONFINITE:
			s->counts.triangles_nonfinite++;
			continue;
		case RAD_POLY_DEGENERATE:
			s->counts.triangles_degenerate++;
			continue;
		case RAD_POLY_OK:
			break;
		}
		for (int k = 0; k < 3; k++)
			if ((st = rad_scene_vertex_id(s, f + 3 * k, &p->v[k],
			                              err)))
				return st;
		p->v[3] = p->v[2];
		p->mat = material;
		p->side = d->two_sided ? RAD_SIDE_FRONT : RAD_SIDE_ONE;
		if (rho) {
			rad_material m = s->mats[material];
			for (int c = 0; c < 3; c++)
				m.rho[c] = rad_rho_float(rho[3 * i + c]);
			uint32_t id;
			if ((st = rad_scene_material_id(s, &m, &id, err)))
				return st;
			p->mat = id;
		}
		if (s->stage_base)
			s->stage_base[s->npolys] =
			        rho ? RAD_TEXTURED_BASE + material : p->mat;
		rad_node_runs_note(s->runs, &s->nruns, s->npolys, node);
		s->npolys++;
	}
	s->counts.polygons = s->npolys;
	return RAD_OK;
}

rad_status rad_scene_add_triangles(rad_scene *s, uint32_t material,
                                   uint32_t node, const double *xyz,
                                   size_t ntri, rad_error *err)
{
	rad_surface_desc d = {material, node, xyz, NULL, ntri, 0};
	return rad_scene_add_surface(s, &d, err);
}

rad_status rad_scene_add_triangles_rho(rad_scene *s, uint32_t material,
                                       uint32_t node, const double *xyz,
                                       const double *rho, size_t ntri,
                                       rad_error *err)
{
	if (ntri && !rho)
		return rad_fail(err, RAD_ERR_INVALID,
		                "triangles: NULL reflectances for %zu", ntri);
	rad_surface_desc d = {material, node, xyz, rho, ntri, 0};
	return rad_scene_add_surface(s, &d, err);
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
	if (d->candela && d->kind != RAD_LIGHT_POINT)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: a candela table needs a point light",
		                which);
	if (d->candela && !(d->opening[0] >= 0 && d->opening[0] < 1e3 &&
	                    d->opening[1] >= 0 && d->opening[1] < 1e3))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: luminous opening %g x %g m must be "
		                "finite, >= 0 and under 1 km",
		                which, d->opening[0], d->opening[1]);
	if (d->kind == RAD_LIGHT_POINT && !d->candela)
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
	rad_status st = rad_scene_check_open(s, "light", err);
	if (st || (st = check_light(d, s->nlights, err)))
		return st;
	if (s->nlights >= MAX_IDS)
		return rad_fail(err, RAD_ERR_LIMIT, "light: too many");
	if (!grow(&s->mem, RAD_MEM_LIGHTS, (void **)&s->lights, &s->cap_lights,
	          s->nlights + 1, sizeof(*s->lights)))
		return rad_fail(err, RAD_ERR_NOMEM, "light: out of memory");
	rad_light L = {.kind = d->kind, .range = d->range};
	if (d->candela) {
		L.opening[0] = d->opening[0];
		L.opening[1] = d->opening_round ? d->opening[0] : d->opening[1];
		L.opening_round = d->opening_round != 0;
	}
	if (d->candela &&
	    (st = rad_gonio_new(&s->mem, d, s->nlights, &L.gonio, err)))
		return st;
	if (d->name &&
	    !(L.name = rad_mem_strdup(&s->mem, RAD_MEM_NAMES, d->name))) {
		rad_mem_free(&s->mem, RAD_MEM_LIGHTS, L.gonio);
		return rad_fail(err, RAD_ERR_NOMEM, "light: out of memory");
	}
	for (int c = 0; c < 3; c++)
		L.intensity[c] =
		        d->intensity[c] * (L.gonio ? L.gonio->peak_cd : 1.0);
	v3 dir = v3_make(0, 0, -1); /* unused by point lights: glTF's -Z */
	if (d->kind != RAD_LIGHT_POINT || d->candela)
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

rad_status rad_scene_polygon_get(const rad_scene *s, uint32_t i,
                                 rad_polygon_desc *out, rad_error *err)
{
	if (!s->committed)
		return rad_fail(err, RAD_ERR_STATE,
		                "polygon: the scene is not committed");
	if (i >= s->npolys)
		return rad_fail(err, RAD_ERR_INVALID,
		                "polygon %u does not exist (%u polygons)", i,
		                s->npolys);
	const rad_poly *p = &s->polys[i];
	const rad_material *m = &s->mats[p->mat];
	v3 v[4];
	out->ncorners = rad_poly_corners(s, p, v);
	for (int k = 0; k < out->ncorners; k++) {
		out->corners[k][0] = v[k].x;
		out->corners[k][1] = v[k].y;
		out->corners[k][2] = v[k].z;
	}
	v3 n = rad_poly_normal(p);
	out->normal[0] = n.x;
	out->normal[1] = n.y;
	out->normal[2] = n.z;
	for (int c = 0; c < 3; c++) {
		out->reflectance[c] = m->rho[c];
		out->luminance[c] = m->emit[c] / M_PI;
	}
	out->area = p->area;
	out->node = rad_poly_node(s, i);
	out->back_face = p->side == RAD_SIDE_BACK;
	return RAD_OK;
}
