/*
 * export.c -- the solved mesh as glTF: a published solution's leaf
 * elements become one triangle mesh per scene node, with per-vertex
 * illuminance (_ILLUMINANCE, lux) and a tone-mapped colour (COLOR_0).
 *
 * DESIGN
 * Leaves arrive from rad_solution_leaves as triangles or parallelograms
 * (nv = 3 or 4, counter-clockwise); a parallelogram p0 p1 p2 p3 becomes
 * the triangles (p0 p1 p2) and (p0 p2 p3).  A leaf's lux is the photopic
 * luma of its irradiance I; its colour is its radiosity B (light leaving
 * the surface: reflected plus, for emitters, emitted) tone-mapped per
 * channel with x / (x + white), so colours stay in [0, 1) and keep their
 * hue.  white is the 99th percentile (by leaf count) of the luma of B
 * unless the caller gives one: a few very bright leaves (the lamps) do not
 * wash the room out.
 *
 * flat = 1: every leaf gets its own vertices carrying its own values.
 * flat = 0: leaves of the same node that meet at a corner share one
 * vertex, whose values are the area-weighted mean of those leaves.
 * Corners are matched within WELD_REL x the scene's size (leaf corners
 * are computed in float from each element's own origin and edges, so
 * neighbours' shared corners differ in the last bits) and only between
 * leaves facing the same way (normals within ~2.5 degrees): the floor and
 * a wall of one node do not blend along their common edge.  The match
 * uses a hash of the position on a grid of the weld distance, probing the
 * 27 cells around a corner.
 *
 * Materials: base colour white, not metallic, so a viewer shows COLOR_0;
 * no lights are written (the result is the lighting).
 */
#include "export.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define WELD_REL 1e-5     /* weld distance, fraction of the scene size */
#define NORMAL_DOT 0.999  /* cos of the largest angle between welded */
#define WHITE_PCTILE 0.99 /* automatic white point: this quantile */

typedef struct leaf {
	float p[4][3]; /* corners, counter-clockwise */
	float n[3];    /* unit normal */
	float B[3];    /* radiosity, lux per channel */
	float lux;     /* luma of the irradiance */
	float area;    /* m2 */
	uint32_t node;
	int nv; /* 3 or 4 */
} leaf;

typedef struct leaf_list {
	leaf *v;
	size_t n, cap;
	int bad_nv;  /* a leaf with nv not 3 or 4 (its value) */
	int bad_val; /* a non-finite coordinate or value */
	int nomem;
} leaf_list;

static void on_leaf(void *ud, uint32_t node, const double p[4][3], int nv,
                    const double B[3], const double I[3])
{
	leaf_list *L = ud;
	if (L->nomem || L->bad_nv || L->bad_val)
		return;
	if (nv != 3 && nv != 4) {
		L->bad_nv = nv ? nv : -1;
		return;
	}
	if (L->n == L->cap) {
		size_t cap = L->cap ? 2 * L->cap : 1024;
		leaf *v = realloc(L->v, cap * sizeof(*v));
		if (!v) {
			L->nomem = 1;
			return;
		}
		L->v = v;
		L->cap = cap;
	}
	leaf *f = &L->v[L->n];
	double e1[3], e2[3], c[3];
	for (int k = 0; k < 3; k++) {
		for (int j = 0; j < nv; j++)
			f->p[j][k] = (float)p[j][k];
		f->B[k] = (float)B[k];
		/* diagonals: |d1 x d2| / 2 is the area of both shapes */
		e1[k] = p[2][k] - p[0][k];
		e2[k] = (nv == 4 ? p[3][k] - p[1][k] : p[1][k] - p[0][k]);
	}
	c[0] = e1[1] * e2[2] - e1[2] * e2[1];
	c[1] = e1[2] * e2[0] - e1[0] * e2[2];
	c[2] = e1[0] * e2[1] - e1[1] * e2[0];
	if (nv == 3) /* e2 x e1 order for a triangle: flip */
		c[0] = -c[0], c[1] = -c[1], c[2] = -c[2];
	double len = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
	f->area = (float)(0.5 * len);
	for (int k = 0; k < 3; k++)
		f->n[k] = len > 0 ? (float)(c[k] / len) : 0.0f;
	f->lux = (float)rad_luma3(I);
	f->node = node;
	f->nv = nv;
	int ok = isfinite(f->lux) && isfinite(f->area);
	for (int k = 0; k < 3; k++)
		ok = ok && isfinite(f->B[k]) && isfinite(B[k]);
	for (int j = 0; j < nv; j++)
		for (int k = 0; k < 3; k++)
			ok = ok && isfinite(f->p[j][k]);
	if (!ok) {
		L->bad_val = 1;
		return;
	}
	L->n++;
}

static int cmp_float(const void *a, const void *b)
{
	float x = *(const float *)a, y = *(const float *)b;
	return (x > y) - (x < y);
}

/* The automatic white point: WHITE_PCTILE of the leaves' rad_luma3(B). */
static rad_status auto_white(const leaf_list *L, double *white, rad_error *err)
{
	float *v = malloc(L->n * sizeof(float));
	if (!v)
		return rad_fail(err, RAD_ERR_NOMEM, "export: out of memory");
	for (size_t i = 0; i < L->n; i++) {
		double B[3] = {L->v[i].B[0], L->v[i].B[1], L->v[i].B[2]};
		v[i] = (float)rad_luma3(B);
	}
	qsort(v, L->n, sizeof(float), cmp_float);
	*white = v[(size_t)floor(WHITE_PCTILE * (double)(L->n - 1))];
	free(v);
	if (!(*white > 0)) /* a dark solution: any positive white will do */
		*white = 1;
	return RAD_OK;
}

/* ---------------------------------------------------------------- meshes */

/* One output mesh being built (a node's leaves). */
typedef struct mesh_acc {
	float *pos, *color, *lux; /* per vertex */
	double *wsum, *wlux, *wB; /* smooth: area-weighted sums */
	float *nrm;               /* smooth: normal of the first leaf */
	uint32_t *index;
	size_t nv, cap_v, ni, cap_i;
	uint32_t *head, *next; /* smooth: weld hash (chains of vertices) */
	size_t hmask;
} mesh_acc;

static void mesh_free(mesh_acc *m)
{
	free(m->pos);
	free(m->color);
	free(m->lux);
	free(m->wsum);
	free(m->wlux);
	free(m->wB);
	free(m->nrm);
	free(m->index);
	free(m->head);
	free(m->next);
	memset(m, 0, sizeof(*m));
}

#define GROW(ptr, n, cap, ok)                                                  \
	do {                                                                   \
		void *np_ = realloc((ptr), (cap) * (n) * sizeof(*(ptr)));      \
		if (np_)                                                       \
			(ptr) = np_;                                           \
		else                                                           \
			(ok) = 0;                                              \
	} while (0)

/* Room for one more vertex; 0 when out of memory. */
static int reserve_vertex(mesh_acc *m)
{
	int ok = 1;
	if (m->nv < m->cap_v)
		return 1;
	size_t cap = m->cap_v ? 2 * m->cap_v : 256;
	GROW(m->pos, 3, cap, ok);
	GROW(m->color, 3, cap, ok);
	GROW(m->lux, 1, cap, ok);
	GROW(m->wsum, 1, cap, ok);
	GROW(m->wlux, 1, cap, ok);
	GROW(m->wB, 3, cap, ok);
	GROW(m->nrm, 3, cap, ok);
	GROW(m->next, 1, cap, ok);
	if (ok)
		m->cap_v = cap;
	return ok;
}

static int push_index(mesh_acc *m, uint32_t a, uint32_t b, uint32_t c)
{
	if (m->ni + 3 > m->cap_i) {
		int ok = 1;
		size_t cap = m->cap_i ? 2 * m->cap_i : 768;
		GROW(m->index, 1, cap, ok);
		if (!ok)
			return 0;
		m->cap_i = cap;
	}
	m->index[m->ni++] = a;
	m->index[m->ni++] = b;
	m->index[m->ni++] = c;
	return 1;
}

static uint64_t cell_hash(int64_t x, int64_t y, int64_t z)
{
	uint64_t h = (uint64_t)x * 0x9E3779B97F4A7C15ull;
	h ^= (uint64_t)y * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
	h ^= (uint64_t)z * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
	return h ^ (h >> 29);
}

/* A welded vertex near p facing n, or UINT32_MAX. */
static uint32_t weld_find(const mesh_acc *m, const float p[3], const float n[3],
                          double cell)
{
	int64_t c[3];
	for (int k = 0; k < 3; k++)
		c[k] = (int64_t)floor(p[k] / cell);
	for (int dx = -1; dx <= 1; dx++)
		for (int dy = -1; dy <= 1; dy++)
			for (int dz = -1; dz <= 1; dz++) {
				uint64_t h = cell_hash(c[0] + dx, c[1] + dy,
				                       c[2] + dz);
				uint32_t v = m->head[h & m->hmask];
				for (; v != UINT32_MAX; v = m->next[v]) {
					const float *q = m->pos + 3 * v;
					const float *qn = m->nrm + 3 * v;
					if (fabsf(q[0] - p[0]) <= cell &&
					    fabsf(q[1] - p[1]) <= cell &&
					    fabsf(q[2] - p[2]) <= cell &&
					    qn[0] * n[0] + qn[1] * n[1] +
					                    qn[2] * n[2] >
					            NORMAL_DOT)
						return v;
				}
			}
	return UINT32_MAX;
}

/* The vertex for corner j of leaf f: new (flat, or no match) or welded. */
static uint32_t add_corner(mesh_acc *m, const leaf *f, int j, int flat,
                           double cell)
{
	const float *p = f->p[j];
	uint32_t v = flat ? UINT32_MAX : weld_find(m, p, f->n, cell);
	if (v == UINT32_MAX) {
		if (m->nv >= UINT32_MAX - 1 || !reserve_vertex(m))
			return UINT32_MAX;
		v = (uint32_t)m->nv++;
		memcpy(m->pos + 3 * v, p, 3 * sizeof(float));
		memcpy(m->nrm + 3 * v, f->n, 3 * sizeof(float));
		m->wsum[v] = m->wlux[v] = 0;
		m->wB[3 * v] = m->wB[3 * v + 1] = m->wB[3 * v + 2] = 0;
		if (!flat) {
			int64_t c[3];
			for (int k = 0; k < 3; k++)
				c[k] = (int64_t)floor(p[k] / cell);
			uint64_t h = cell_hash(c[0], c[1], c[2]) & m->hmask;
			m->next[v] = m->head[h];
			m->head[h] = v;
		}
	}
	/* flat: one leaf per vertex, w / w = 1 */
	double w = f->area > 0 ? f->area : 1e-30;
	m->wsum[v] += w;
	m->wlux[v] += w * f->lux;
	for (int k = 0; k < 3; k++)
		m->wB[3 * v + k] += w * f->B[k];
	return v;
}

/* Build one node's mesh from its n leaves lv[]. */
static rad_status build_mesh(mesh_acc *m, const leaf *const *lv, size_t n,
                             int flat, double cell, double white,
                             rad_error *err)
{
	if (!flat) {
		size_t size = 64;
		while (size < 2 * 4 * n)
			size *= 2;
		m->head = malloc(size * sizeof(uint32_t));
		if (!m->head)
			return rad_fail(err, RAD_ERR_NOMEM,
			                "export: out of memory");
		memset(m->head, 0xff, size * sizeof(uint32_t));
		m->hmask = size - 1;
	}
	for (size_t i = 0; i < n; i++) {
		const leaf *f = lv[i];
		uint32_t v[4];
		for (int j = 0; j < f->nv; j++)
			if ((v[j] = add_corner(m, f, j, flat, cell)) ==
			    UINT32_MAX)
				return rad_fail(err, RAD_ERR_NOMEM,
				                "export: out of memory (%zu "
				                "vertices)",
				                m->nv);
		if (!push_index(m, v[0], v[1], v[2]) ||
		    (f->nv == 4 && !push_index(m, v[0], v[2], v[3])))
			return rad_fail(err, RAD_ERR_NOMEM,
			                "export: out of memory");
	}
	for (size_t v = 0; v < m->nv; v++) {
		m->lux[v] = (float)(m->wlux[v] / m->wsum[v]);
		for (int k = 0; k < 3; k++) {
			double x = m->wB[3 * v + k] / m->wsum[v];
			x = x > 0 ? x : 0;
			m->color[3 * v + k] = (float)(x / (x + white));
		}
	}
	return RAD_OK;
}

/* ------------------------------------------------------------------ API */

void sio_export_opts_default(sio_export_opts *o)
{
	memset(o, 0, sizeof(*o));
	o->format = SIO_FORMAT_GLB;
	o->white_lux = 0;
	o->flat = 0;
}

/* Group leaves by node: *order lists leaf pointers node by node, *start
 * (nnodes + 1 entries) where each node begins. */
static rad_status group_by_node(const leaf_list *L, const leaf ***order,
                                size_t **start, uint32_t *nnodes,
                                rad_error *err)
{
	uint32_t nn = 0;
	for (size_t i = 0; i < L->n; i++)
		if (L->v[i].node >= nn)
			nn = L->v[i].node + 1;
	size_t *s = calloc((size_t)nn + 1, sizeof(size_t));
	const leaf **o = malloc(L->n * sizeof(*o));
	if (!s || !o) {
		free(s);
		free(o);
		return rad_fail(err, RAD_ERR_NOMEM, "export: out of memory");
	}
	for (size_t i = 0; i < L->n; i++)
		s[L->v[i].node + 1]++;
	for (uint32_t k = 0; k < nn; k++)
		s[k + 1] += s[k];
	for (size_t i = 0; i < L->n; i++) /* stable: uses s[] as cursors */
		o[s[L->v[i].node]++] = &L->v[i];
	for (uint32_t k = nn; k > 0; k--) /* restore the starts */
		s[k] = s[k - 1];
	s[0] = 0;
	*order = o;
	*start = s;
	*nnodes = nn;
	return RAD_OK;
}

static rad_status collect(const rad_solution *sol, leaf_list *L, rad_error *err)
{
	rad_solution_leaves(sol, on_leaf, L);
	if (L->nomem)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "export: out of memory after %zu leaves", L->n);
	if (L->bad_nv)
		return rad_fail(err, RAD_ERR_INVALID,
		                "export: leaf %zu has %d vertices (3 or 4 "
		                "expected)",
		                L->n, L->bad_nv);
	if (L->bad_val)
		return rad_fail(err, RAD_ERR_INVALID,
		                "export: leaf %zu has a non-finite coordinate "
		                "or value",
		                L->n);
	if (L->n == 0)
		return rad_fail(err, RAD_ERR_INVALID,
		                "export: the solution has no leaf elements "
		                "(empty scene?)");
	return RAD_OK;
}

/* Build every node's mesh and serialize. */
static rad_status write_meshes(const rad_scene *scene, const leaf_list *L,
                               const sio_export_opts *o, double white,
                               unsigned char **out, size_t *len,
                               sio_export_info *info, rad_error *err)
{
	const leaf **order = NULL;
	size_t *start = NULL;
	uint32_t nn = 0;
	double lo[3], hi[3], size = 0;
	rad_status st = group_by_node(L, &order, &start, &nn, err);
	if (st != RAD_OK)
		return st;
	rad_scene_bounds(scene, lo, hi);
	for (int k = 0; k < 3; k++) {
		size = fmax(size, hi[k] - lo[k]);
		size = fmax(size, fmax(fabs(lo[k]), fabs(hi[k])));
	}
	double cell = WELD_REL * (size > 0 ? size : 1);
	mesh_acc *acc = calloc(nn ? nn : 1, sizeof(*acc));
	sio_mesh *gm = calloc(nn ? nn : 1, sizeof(*gm));
	char(*names)[32] = calloc(nn ? nn : 1, sizeof(*names));
	size_t nm = 0, nverts = 0, ntris = 0;
	if (!acc || !gm || !names)
		st = rad_fail(err, RAD_ERR_NOMEM, "export: out of memory");
	for (uint32_t k = 0; st == RAD_OK && k < nn; k++) {
		size_t n = start[k + 1] - start[k];
		if (n == 0)
			continue;
		st = build_mesh(&acc[k], order + start[k], n, o->flat, cell,
		                white, err);
		const char *name = rad_scene_node_name(scene, k);
		if (!name || !name[0]) {
			snprintf(names[k], sizeof(names[k]), "node%u", k);
			name = names[k];
		}
		gm[nm] = (sio_mesh){.name = name,
		                    .position = acc[k].pos,
		                    .color = acc[k].color,
		                    .illuminance = acc[k].lux,
		                    .index = acc[k].index,
		                    .nvertices = acc[k].nv,
		                    .nindices = acc[k].ni,
		                    .base_color = {1, 1, 1},
		                    .emissive_strength = 1};
		nm++;
		nverts += acc[k].nv;
		ntris += acc[k].ni / 3;
	}
	void *bytes = NULL;
	if (st == RAD_OK)
		st = sio_write(gm, nm, NULL, 0, o->format, &bytes, len, err);
	if (st == RAD_OK) {
		*out = bytes;
		if (info)
			*info = (sio_export_info){nm, nverts, ntris, white};
	}
	for (uint32_t k = 0; acc && k < nn; k++)
		mesh_free(&acc[k]);
	free(acc);
	free(gm);
	free(names);
	free(order);
	free(start);
	return st;
}

rad_status sio_export_solution(const rad_scene *scene, const rad_solution *sol,
                               const sio_export_opts *o, unsigned char **out,
                               size_t *len, sio_export_info *info,
                               rad_error *err)
{
	sio_export_opts def;
	leaf_list L = {0};
	double white;
	rad_error_clear(err);
	if (out)
		*out = NULL;
	if (len)
		*len = 0;
	if (!scene || !sol || !out || !len)
		return rad_fail(err, RAD_ERR_INVALID,
		                "sio_export_solution: %s is NULL",
		                !scene ? "scene"
		                : !sol ? "solution"
		                : !out ? "out"
		                       : "len");
	if (!o) {
		sio_export_opts_default(&def);
		o = &def;
	}
	if (o->format != SIO_FORMAT_GLB && o->format != SIO_FORMAT_JSON)
		return rad_fail(err, RAD_ERR_INVALID,
		                "export: unknown format %d", (int)o->format);
	if (!(o->white_lux >= 0) || !isfinite(o->white_lux))
		return rad_fail(err, RAD_ERR_INVALID,
		                "export: white_lux %g must be finite and >= 0 "
		                "(0 = automatic)",
		                o->white_lux);
	rad_status st = collect(sol, &L, err);
	if (st == RAD_OK) {
		white = o->white_lux;
		if (white == 0)
			st = auto_white(&L, &white, err);
	}
	if (st == RAD_OK)
		st = write_meshes(scene, &L, o, white, out, len, info, err);
	free(L.v);
	return st;
}
