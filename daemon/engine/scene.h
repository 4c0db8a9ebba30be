/*
 * scene.h -- the engine's internal scene model.
 *
 * A committed scene is a read-only set of input polygons (triangles and
 * parallelograms), a shared material table, punctual/directional lights
 * and the Embree BVH over the polygons.  Solvers never modify it.
 *
 * A polygon is its corners, indices into the scene's one vertex array
 * (each distinct float point once, shared by every polygon that has it,
 * and by the BVH).  The engine sees it as an origin and two edges:
 *   triangle:      p0, p0+e1, p0+e2          (points p0 + s e1 + t e2,
 *                                             s,t >= 0, s+t <= 1)
 *   parallelogram: p0, p0+e1, p0+e1+e2, p0+e2 (s,t in [0,1])
 * which is also how quadtree elements describe their sub-region, so the
 * whole hierarchy shares one geometry representation.  The edges are
 * the float differences of the corners (rad_poly_frame).  The front side
 * is the side of n = normalize(e1 x e2).
 */
#ifndef LUXRAD_SCENE_H
#define LUXRAD_SCENE_H

#include <string.h>

#include "mem.h"
#include "rad.h"
#include "vec.h"

/* Degenerate: area below this x (longest edge)^2 (zero or sliver area). */
#define SLIVER_REL 1e-12
/* The normal of the stored (float) edges must agree with the input's to
 * this cosine, or rounding has made the stored shape meaningless. */
#define FLOAT_NORMAL_COS 0.9999

typedef struct rad_material {
	float rho[3];  /* diffuse reflectance per channel, [0, 1) */
	float emit[3]; /* exitance per channel, lux (pi x luminance) */
} rad_material;

/* FNV-1a over n 32-bit words by their bits, from h (RAD_HASH_SEED);
 * rad_hash_end gives the final mix.  Keys: the builder's materials and
 * vertices, the merger's edges. */
#define RAD_HASH_SEED 0x811c9dc5u
static inline uint32_t rad_hash_words(uint32_t h, const void *w, int n)
{
	const unsigned char *c = w;
	for (int i = 0; i < n; i++) {
		uint32_t bits;
		memcpy(&bits, c + 4 * i, sizeof(bits));
		h = (h ^ bits) * 0x01000193u;
		h ^= h >> 15;
	}
	return h;
}

static inline uint32_t rad_hash_end(uint32_t h)
{
	return h * 0x9e3779b1u;
}

/* Reflectance as stored: values just below 1 must not round up to 1.0f,
 * which would make a lossless surface out of a valid input. */
static inline float rad_rho_float(double r)
{
	float f = (float)r;
	return f < 1.0f ? f : nextafterf(1.0f, 0.0f);
}

/* 1 if material m emits in some channel. */
static inline int rad_material_emits(const rad_material *m)
{
	return m->emit[0] > 0 || m->emit[1] > 0 || m->emit[2] > 0;
}

typedef struct rad_poly {
	uint32_t v[4];     /* corners in s->verts: p0, p0+e1, then p0+e1+e2 and
	                      p0+e2 (a parallelogram; its third corner is the
	                      input's own vertex), or p0+e2 twice (a triangle):
	                      Embree's quad layout, so the BVH reads this array */
	int16_t oct[2];    /* unit normal, octahedral (Normal and area) */
	float area;        /* m2 */
	uint32_t mat : 28; /* index into the material table (fewer than
	                      RAD_SCENE_MAX_IDS: 2^28) */
	uint32_t quad : 1; /* 1 = parallelogram, 0 = triangle */
	uint32_t side : 2; /* rad_side */
} rad_poly;
_Static_assert(sizeof(rad_poly) == 28, "rad_poly layout");

/*
 * The node a run of polygons came from: polygons first .. (the next
 * run's first) - 1 (rad_poly_node).  Polygons are added a node at a
 * time, and merging, cutting and back faces keep their order, so there
 * are about as many runs as nodes (twice, with back faces), where a node
 * id in every polygon was 4 of its 40 bytes: 1.0 MB of the report's
 * grand hall, 2.9 MB of the 1M field.
 */
typedef struct rad_node_run {
	uint32_t first; /* its first polygon */
	uint32_t node;  /* index into the node name table */
} rad_node_run;

/* Which faces of its sheet a polygon is. */
enum rad_side {
	RAD_SIDE_ONE = 0, /* one-sided: the back absorbs */
	RAD_SIDE_FRONT,   /* the front of a two-sided sheet (in the BVH) */
	RAD_SIDE_BACK     /* its back face (not in the BVH: s->twin) */
};

/*
 * A point light's goniometric table (gonio.c), one LIGHTS block: the
 * grid points into data[].  The light's intensity holds the table's peak
 * (times the caller's RGB factor); rad_gonio_factor gives the table over
 * its peak, in [0, 1].
 */
typedef struct rad_gonio {
	rad_candela_grid grid; /* the copy, in data[] */
	double nadir[3];       /* unit; gamma 0 */
	double axis0[3];       /* unit; C = 0, perpendicular to nadir */
	double axis90[3];      /* unit; C = 90: axis0 x nadir */
	double peak_cd;        /* largest value (0: a dark table) */
	double flux_per_peak;  /* lm per cd of peak */
	double data[];         /* C angles, gamma angles, values */
} rad_gonio;

typedef struct rad_light {
	rad_light_kind kind;
	double pos[3];       /* point, spot */
	double dir[3];       /* unit; direction the light travels */
	double intensity[3]; /* candela (point, spot), lux (directional) */
	double range;        /* 0 = infinite */
	double cos_inner, cos_outer; /* spot cone, cosines */
	char *name;                  /* may be NULL */
	rad_gonio *gonio;            /* LIGHTS; NULL = no table */
	double opening[2]; /* with gonio: luminous opening, metres (along
	                      axis0, axis90; a disk of diameter opening[0]
	                      if round); 0, 0: a point */
	int opening_round;
} rad_light;

/*
 * The point of light L's opening at (u, v) in [-1/2, 1/2]^2 (its centre at
 * 0, 0); a round opening is the disk inscribed in that square.
 */
static inline v3 rad_light_opening_point(const rad_light *L, double u, double v)
{
	const rad_gonio *g = L->gonio;
	double l = L->opening[0], w = L->opening_round ? l : L->opening[1];
	return v3_add(v3_d(L->pos), v3_add(v3_scale(v3_d(g->axis0), u * l),
	                                   v3_scale(v3_d(g->axis90), v * w)));
}

/* 1 if L has an opening (more than a point). */
static inline int rad_light_has_opening(const rad_light *L)
{
	return L->gonio && (L->opening[0] > 0 || L->opening[1] > 0);
}

/* Copy d->candela (checked) into a new LIGHTS block of mem. */
rad_status rad_gonio_new(rad_mem *mem, const rad_light_desc *d, uint32_t which,
                         rad_gonio **out, rad_error *err);
/* The table's intensity towards unit direction w, over its peak. */
double rad_gonio_factor(const rad_gonio *t, v3 w);

typedef struct rad_vis rad_vis; /* vis.h */

struct rad_scene {
	rad_mem mem; /* everything the scene holds */
	int committed;

	rad_poly *polys; /* GEOMETRY */
	uint32_t npolys, cap_polys;
	uint32_t nfront; /* after commit: polys[0 .. nfront-1] are in the
	                    BVH, the back faces after them are not */
	float *verts;    /* GEOMETRY: the distinct corners, 3 floats each,
	                    relative to origin, then RAD_VERT_PAD zeros */
	uint32_t nverts, cap_verts;
	uint32_t *vert_slots; /* GEOMETRY, until commit: open addressing,
	                         vertex id + 1 (0 = free), vert_mask + 1
	                         slots, so that shared corners are stored
	                         once and match by id */
	uint32_t vert_mask;
	double origin[3]; /* of the vertices: the first triangle's first
	                     corner, so that a scene far from 0 keeps its
	                     float edges exact to float precision */
	int merged;       /* quad merging done: no more triangles */

	uint32_t *twin;       /* GEOMETRY, after commit; NULL when no polygon is
	                         two-sided: per polygon, its back face's index
	                         (RAD_NONE for none), so that hits from behind
	                         find it */
	uint32_t *stage_base; /* GEOMETRY, until commit; NULL until a
	                         triangle comes with its own reflectance:
	                         per polygon, what quad merging matches
	                         (rad_scene_merge_key) */

	rad_material *mats; /* MATERIALS; shared, stored once each */
	uint32_t nmats, cap_mats;
	uint32_t *mat_slots; /* MATERIALS, until commit; NULL while the
	                        table is small: open addressing, id + 1
	                        (0 = free), mat_mask + 1 slots */
	uint32_t mat_mask;

	rad_light *lights; /* LIGHTS */
	uint32_t nlights, cap_lights;

	char **nodes; /* NAMES: node/mesh instance names */
	uint32_t nnodes, cap_nodes;
	rad_node_run *runs; /* GEOMETRY: which node each polygon came from,
	                       first increasing from runs[0].first == 0;
	                       none while there is no polygon */
	uint32_t nruns, cap_runs;

	double lo[3], hi[3];  /* bounds of polygons and positional lights */
	double diag;          /* bounding-box diagonal, metres (> 0) */
	double total_area;    /* m2 */
	double total_flux[3]; /* lm emitted by surfaces and lights, estimate */

	rad_scene_counts counts;
	rad_vis *vis; /* BVH over the polygons, after commit */
};

/* Ids (polygons, materials, nodes) stay far below RAD_NONE and the tag
 * bits of hier.h; the edge map (4 slots per triangle) fits 32-bit
 * indices. */
#define RAD_SCENE_MAX_IDS (1u << 28)

/* The node polygon poly came from. */
static inline uint32_t rad_poly_node(const rad_scene *s, uint32_t poly)
{
	uint32_t lo = 0, hi = s->nruns; /* runs[lo].first <= poly */
	while (hi - lo > 1) {
		uint32_t mid = lo + (hi - lo) / 2;
		if (s->runs[mid].first <= poly)
			lo = mid;
		else
			hi = mid;
	}
	return s->runs[lo].node;
}

/* Polygons from `first` on come from node: a run starts there unless the
 * last one is node's.  The caller has made room (runs[*n] may be
 * written).  Dropping polygons or replacing one with pieces of it never
 * makes more runs than there were, so an array of the old count holds
 * the runs of the polygons merging or cutting keeps. */
static inline void rad_node_runs_note(rad_node_run *runs, uint32_t *n,
                                      uint32_t first, uint32_t node)
{
	if (*n && runs[*n - 1].node == node)
		return;
	runs[*n].first = first;
	runs[*n].node = node;
	++*n;
}

/* Stage bases of triangles offered with their own reflectance: the
 * material they came with, offset so they never match a plain one. */
#define RAD_TEXTURED_BASE RAD_SCENE_MAX_IDS

/* Triangles t and u may merge into a quad only if these agree. */
static inline uint32_t rad_scene_merge_key(const rad_scene *s, uint32_t t)
{
	return s->stage_base ? s->stage_base[t] : s->polys[t].mat;
}

/* The id of material m, added if no equal one is stored (scene.c). */
rad_status rad_scene_material_id(rad_scene *s, const rad_material *m,
                                 uint32_t *id, rad_error *err);
/* Release the material hash (commit: no more materials come). */
void rad_scene_material_index_free(rad_scene *s);

/* What became of a polygon's stored shape (rad_poly_check_edges). */
enum rad_poly_verdict { RAD_POLY_OK, RAD_POLY_NONFINITE, RAD_POLY_DEGENERATE };

/*
 * Check the float edges e1, e2 of a polygon against the exact area and
 * unit normal n it was made from: finite, not rounded to zero area, and
 * still giving n (FLOAT_NORMAL_COS).  Input triangles and the pieces of
 * cut polygons are both held to it.
 */
static inline enum rad_poly_verdict
rad_poly_check_edges(const float e1[3], const float e2[3], double area, v3 n)
{
	v3 cf = v3_cross(v3_f(e1), v3_f(e2));
	double lf = v3_len(cf);
	if (!isfinite((float)area) || !isfinite(lf))
		return RAD_POLY_NONFINITE;
	if ((float)area == 0.0f || !(v3_dot(cf, n) > FLOAT_NORMAL_COS * lf))
		return RAD_POLY_DEGENERATE;
	return RAD_POLY_OK;
}

/* Embree reads a vertex with a 16-byte load: the array ends with this
 * many zero floats. */
#define RAD_VERT_PAD 4

/* The id of the vertex at float point p (relative to s->origin), added
 * if no vertex has its bits (-0 counts as +0; scene.c); RAD_ERR_NOMEM or
 * RAD_ERR_LIMIT. */
rad_status rad_scene_vertex_id(rad_scene *s, const float p[3], uint32_t *id,
                               rad_error *err);
/* The vertex hash goes at commit, once every vertex is in (scene.c). */
void rad_scene_vertex_index_free(rad_scene *s);

static inline const float *rad_scene_vert(const rad_scene *s, uint32_t i)
{
	return s->verts + 3 * (size_t)i;
}

/* Vertex i in world coordinates. */
static inline v3 rad_scene_vertex(const rad_scene *s, uint32_t i)
{
	return v3_add(v3_d(s->origin), v3_f(rad_scene_vert(s, i)));
}

/* Edge a -> b of the vertex array, as the float difference. */
static inline void rad_scene_edge(const rad_scene *s, uint32_t a, uint32_t b,
                                  float e[3])
{
	const float *pa = rad_scene_vert(s, a), *pb = rad_scene_vert(s, b);
	for (int c = 0; c < 3; c++)
		e[c] = pb[c] - pa[c];
}

/* p's origin (world, rounded to float) and edges, the way quadtree
 * regions hold them (hier.h). */
static inline void rad_poly_frame(const rad_scene *s, const rad_poly *p,
                                  float p0[3], float e1[3], float e2[3])
{
	v3_store_f(p0, rad_scene_vertex(s, p->v[0]));
	rad_scene_edge(s, p->v[0], p->v[1], e1);
	rad_scene_edge(s, p->v[0], p->v[3], e2);
}

static inline v3 rad_poly_e1(const rad_scene *s, const rad_poly *p)
{
	float e[3];
	rad_scene_edge(s, p->v[0], p->v[1], e);
	return v3_f(e);
}

static inline v3 rad_poly_e2(const rad_scene *s, const rad_poly *p)
{
	float e[3];
	rad_scene_edge(s, p->v[0], p->v[3], e);
	return v3_f(e);
}

/*
 * Normal and area.  A polygon keeps its area in a float and its unit
 * normal in 32 bits: two 16-bit coordinates of its octahedral projection
 * (x and y over |x| + |y| + |z|, the lower half folded out to the
 * corners), where three floats were 12 bytes: 8 bytes less a polygon,
 * 2.1 MB of the report's grand hall and 5.9 MB of the 1M field.  (Its
 * node is not in it either: rad_node_run.)  A coordinate is within 1/65534 of
 * the exact one, so the normal is within about 3e-5 radians (axis-aligned ones
 * are exact); the corners and every quadtree region's float edges are the
 * geometry.  Decoding costs the clusters, which read their polygons' normals
 * for every link they gather: hr took 1.06x the time on the grand hall (4
 * iterations).  Keeping the area over the decoded vector's length instead, to
 * spare the square root, cost as much, the area's readers paying it; working
 * both out from the corners, 1.13x. A back face keeps its front's code and
 * decodes it negated, so its normal is the front's turned over, bit for bit.
 */
#define RAD_OCT_ONE 32767.0

/* The front's direction; a back face's is its negation. */
static inline v3 rad_poly_front_dir(const rad_poly *p)
{
	/* Without branches: the clusters decode a polygon's for every link
	 * they gather, facing every way. */
	double x = p->oct[0] * (1 / RAD_OCT_ONE);
	double y = p->oct[1] * (1 / RAD_OCT_ONE);
	double z = 1 - fabs(x) - fabs(y);
	double t = z < 0 ? -z : 0; /* unfolds the lower half */
	x += x < 0 ? t : -t;
	y += y < 0 ? t : -t;
	return v3_make(x, y, z);
}

static inline v3 rad_poly_dir(const rad_poly *p)
{
	v3 d = rad_poly_front_dir(p);
	return p->side == RAD_SIDE_BACK ? v3_scale(d, -1) : d;
}

/* The polygon's area times max(0, normal . (dx, dy, dz)), m2: what it
 * shows towards a unit direction. */
static inline double rad_poly_shown(const rad_poly *p, double dx, double dy,
                                    double dz)
{
	v3 d = rad_poly_front_dir(p);
	double c = d.x * dx + d.y * dy + d.z * dz;
	c = p->side == RAD_SIDE_BACK ? -c : c;
	return c > 0 ? p->area * c / v3_len(d) : 0;
}

/* Area times unit normal, m2. */
static inline v3 rad_poly_an(const rad_poly *p)
{
	v3 d = rad_poly_dir(p);
	return v3_scale(d, p->area / v3_len(d));
}

/* Unit normal, front side. */
static inline v3 rad_poly_normal(const rad_poly *p)
{
	return v3_norm(rad_poly_dir(p));
}

/* Set the polygon's unit normal n (front side) and area (m2). */
static inline void rad_poly_set_shape(rad_poly *p, v3 n, double area)
{
	double l1 = fabs(n.x) + fabs(n.y) + fabs(n.z);
	double x = n.x / l1, y = n.y / l1;
	if (n.z < 0) { /* folded out to the corners (rad_poly_dir) */
		double fx = (1 - fabs(y)) * (x < 0 ? -1 : 1);
		y = (1 - fabs(x)) * (y < 0 ? -1 : 1);
		x = fx;
	}
	p->oct[0] = (int16_t)lround(x * RAD_OCT_ONE);
	p->oct[1] = (int16_t)lround(y * RAD_OCT_ONE);
	p->area = (float)area;
}

/* Shrink the polygon array to its count (the memory merging or cutting
 * freed goes back). */
static inline void rad_scene_fit_polys(rad_scene *s)
{
	/* Keeping the old block when realloc fails is harmless. */
	rad_poly *fit = rad_mem_realloc(&s->mem, RAD_MEM_GEOMETRY, s->polys,
	                                (size_t)s->npolys * sizeof(*s->polys));
	if (fit) {
		s->polys = fit;
		s->cap_polys = s->npolys;
	}
}

/* The scene is not committed yet: RAD_OK, or RAD_ERR_STATE naming what
 * (scene.c). */
rad_status rad_scene_check_open(const rad_scene *s, const char *what,
                                rad_error *err);

/* Cut the large polygons along the lines where other polygons run right
 * across them (conform.c); at commit, after quad merging and bounds. */
rad_status rad_scene_conform(rad_scene *s, rad_error *err);

/* Position of parametric point (u, t) on polygon p (world). */
static inline v3 rad_poly_point(const rad_scene *s, const rad_poly *p, double u,
                                double t)
{
	return v3_madd(
	        v3_madd(rad_scene_vertex(s, p->v[0]), rad_poly_e1(s, p), u),
	        rad_poly_e2(s, p), t);
}

/* A polygon's corners (world), counter-clockwise seen from its front;
 * returns their count (3 or 4). */
static inline int rad_poly_corners(const rad_scene *s, const rad_poly *p,
                                   v3 v[4])
{
	int n = p->quad ? 4 : 3;
	for (int k = 0; k < n; k++)
		v[k] = rad_scene_vertex(s, p->v[k]);
	return n;
}

#endif
