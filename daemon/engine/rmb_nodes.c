/*
 * rmb_nodes.c -- what the reduced-memory solver's walk (rmb_refine.c)
 * and its iterations (rmb.c) ask of nodes: do they reflect, how much
 * reflecting area, their largest reflectance, the accuracy asked of
 * receivers; and the set of deleted pairs kept for the study statistics.
 * Below both files, so that neither calls up into the other's.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "rmb.h"
#include "rng.h"

/* ------------------------------------------------------ reflectance */

int rmb_node_black(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 1;
	if (node_is_cluster(t))
		return st->arefl[node_index(t)] == 0;
	const float *rho = rad_elem_mat(&sv->h, t)->rho;
	return rho[0] == 0 && rho[1] == 0 && rho[2] == 0;
}

double rmb_node_arefl(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_cluster(t))
		return st->arefl[node_index(t)];
	return rmb_node_black(sv, t) ? 0 : node_area(&sv->h, t);
}

/* A material's largest reflectance over the channels. */
static double mat_rho_max(const rad_material *m)
{
	return fmax(m->rho[0], fmax(m->rho[1], m->rho[2]));
}

static double elem_rho_max(const rad_solver *sv, uint32_t id)
{
	return mat_rho_max(rad_elem_mat(&sv->h, id));
}

static int cmp_float(const void *a, const void *b)
{
	float x = *(const float *)a, y = *(const float *)b;
	return (x > y) - (x < y);
}

rad_status rmb_rho_init(rad_solver *sv, rmb_state *st)
{
	const rad_scene *s = sv->scene;
	uint32_t n = 1;
	st->rho_levels[0] = 0;
	for (uint32_t m = 0; m < s->nmats; m++) {
		float r = (float)mat_rho_max(&s->mats[m]);
		uint32_t k = 0;
		while (k < n && st->rho_levels[k] != r)
			k++;
		if (k < n)
			continue;
		if (n == 256) { /* more than a byte can index: floats */
			st->rhomax =
			        rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER,
			                       st->ncl, sizeof(float));
			return st->rhomax ? RAD_OK : RAD_ERR_NOMEM;
		}
		st->rho_levels[n++] = r;
	}
	qsort(st->rho_levels, n, sizeof(float), cmp_float);
	st->nlevels = n;
	st->rho_at = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->ncl, 1);
	return st->rho_at ? RAD_OK : RAD_ERR_NOMEM;
}

static float cluster_rho_max(const rmb_state *st, uint32_t id)
{
	return st->rho_at ? st->rho_levels[st->rho_at[id]] : st->rhomax[id];
}

static void set_cluster_rho_max(rmb_state *st, uint32_t id, float r)
{
	if (!st->rho_at) {
		st->rhomax[id] = r;
		return;
	}
	uint32_t lo = 0, hi = st->nlevels - 1; /* r is one of them */
	while (lo < hi) {
		uint32_t mid = (lo + hi) / 2;
		if (st->rho_levels[mid] < r)
			lo = mid + 1;
		else
			hi = mid;
	}
	st->rho_at[id] = (uint8_t)lo;
}

/* Fill arefl[] and the largest reflectances for cluster id and below. */
double rmb_mark_black(rad_solver *sv, uint32_t id)
{
	rmb_state *st = sv->impl;
	const rad_cluster *c = rad_cluster_at(&sv->h, id);
	double a = 0, rm = 0;
	if (!rad_cluster_is_leaf(c)) {
		a += rmb_mark_black(sv, c->child);
		a += rmb_mark_black(sv, c->child + 1);
		rm = fmax(cluster_rho_max(st, c->child),
		          cluster_rho_max(st, c->child + 1));
	} else {
		for (uint32_t j = c->first; j < c->first + c->count; j++) {
			a += rmb_node_arefl(sv, sv->h.order[j]);
			rm = fmax(rm, elem_rho_max(sv, sv->h.order[j]));
		}
	}
	set_cluster_rho_max(st, id, (float)rm);
	st->arefl[id] = (float)a;
	return a;
}

double rmb_node_rho_max(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 0;
	if (node_is_cluster(t))
		return cluster_rho_max(st, node_index(t));
	return elem_rho_max(sv, t);
}

/* ------------------------------------------------------------ budget */

/*
 * The receiver-accuracy budget of an iteration: variation times the mean
 * radiosity it transmits (in the first, the sources' mean exitance), but
 * never below variation x (1 - rho_max) x the mean radiosity B reached.
 * Against the increment alone the budget shrank with it, and the late
 * increments -- by then a fraction of a percent of the answer -- were
 * resolved as finely as the first bounce (measured on the Cornell box
 * converged to 1e-3 at eps 1e-4: elements 6,669 -> 111,789 over
 * iterations 5-9, 2.6 s, for a grid error of 2.69 % against 2.66 % with
 * the floor, in 0.13 s and 3,153 elements).  The energy bound keeps each
 * increment's power within rho_max of the last, so once the mean
 * increment is under (1 - rho_max) mean B, everything still to come adds
 * up to less than the answer already has: from there an increment is
 * resolved against that share of the answer, no finer.
 */
double rmb_spread_limit(const rad_solver *sv)
{
	const rmb_state *st = sv->impl;
	if (st->iter == 0)
		return sv->opt.variation * sv->flux_scale /
		       sv->scene->total_area;
	double floor = (1 - cluster_rho_max(st, 0)) * st->mean_B;
	return sv->opt.variation * fmax(st->mean_dB, floor);
}

/* ------------------------------------------ study: the pairs deleted */

uint64_t rmb_pair_key(uint32_t r, uint32_t s)
{
	return ((uint64_t)r << 32 | s) + 1;
}

static size_t set_slot(const rmb_set *s, uint64_t k)
{
	uint64_t x = k * 0x9E3779B97F4A7C15ull;
	size_t i = (size_t)(x >> 17) & (s->cap - 1);
	while (s->keys[i] && s->keys[i] != k)
		i = (i + 1) & (s->cap - 1);
	return i;
}

int rmb_set_has(const rmb_set *s, uint64_t k)
{
	return s->cap && s->keys[set_slot(s, k)] == k;
}

static rad_status set_add(rad_solver *sv, rmb_set *s, uint64_t k)
{
	if (2 * (s->n + 1) > s->cap) {
		rmb_set g = {NULL, 0, s->cap ? 2 * s->cap : 1024};
		g.keys = rad_mem_calloc(&sv->mem, RAD_MEM_STUDY, g.cap,
		                        sizeof(uint64_t));
		if (!g.keys)
			return RAD_ERR_NOMEM;
		for (size_t i = 0; i < s->cap; i++)
			if (s->keys[i])
				g.keys[set_slot(&g, s->keys[i])] = s->keys[i];
		g.n = s->n;
		rad_mem_free(&sv->mem, RAD_MEM_STUDY, s->keys);
		*s = g;
	}
	size_t i = set_slot(s, k);
	if (!s->keys[i]) {
		s->keys[i] = k;
		s->n++;
	}
	return RAD_OK;
}

/* ------------------------------------------ receiver accuracy: the map */

static size_t acc_slot(const rmb_acc_word *slot, size_t cap, uint32_t nv,
                       uint32_t id)
{
	uint64_t x = ((uint64_t)id + 1) * RAD_GOLDEN;
	size_t i = (size_t)(x >> 32) & (cap - 1);
	while (slot[i * (1 + nv)].id != RAD_NONE && slot[i * (1 + nv)].id != id)
		i = (i + 1) & (cap - 1);
	return i * (1 + nv);
}

const float *rmb_acc_get(const rmb_acc *m, uint32_t id)
{
	if (m->dense)
		return id < m->cap ? &m->dense[(size_t)id * m->nv] : NULL;
	if (!m->cap)
		return NULL;
	const rmb_acc_word *s = &m->slot[acc_slot(m->slot, m->cap, m->nv, id)];
	return s->id == id ? &s[1].v : NULL;
}

#define ACC_FIRST 1024

/* Ids an array would cover: the elements and a block of the pool more
 * (not twice as many: the doubling held 8.4 MB where 6.0 would do on
 * the 1M field). */
static size_t acc_dense_ids(const rad_solver *sv, uint32_t id)
{
	const rad_pool *e = &sv->h.elems;
	size_t n = (size_t)id + 1 > e->count ? (size_t)id + 1 : e->count;
	return n + ((size_t)1 << e->shift);
}

static size_t acc_bytes(const rmb_acc *m, size_t cap)
{
	return cap * (m->dense ? m->nv : 1 + m->nv) * sizeof(float);
}

size_t rmb_acc_growth(const rad_solver *sv, const rmb_acc *m)
{
	if (!m->dense)
		return acc_bytes(m, m->cap ? 2 * m->cap : ACC_FIRST) + 4096;
	size_t n = acc_dense_ids(sv, 0);
	return n > m->cap ? acc_bytes(m, n - m->cap) + 4096 : 0;
}

/* Make m an array covering id and every element, its ids copied. */
static int acc_to_dense(rad_solver *sv, rmb_acc *m, uint32_t id)
{
	size_t n = acc_dense_ids(sv, id);
	float *d = rad_mem_calloc(&sv->mem, m->kind, n, m->nv * sizeof(float));
	if (!d)
		return -1;
	for (size_t i = 0; i < m->cap; i++) {
		const rmb_acc_word *s = &m->slot[i * (1 + m->nv)];
		if (s->id != RAD_NONE)
			for (uint32_t k = 0; k < m->nv; k++)
				d[(size_t)s->id * m->nv + k] = s[1 + k].v;
	}
	rad_mem_free(&sv->mem, m->kind, m->slot);
	m->slot = NULL;
	m->dense = d;
	m->cap = n;
	return 0;
}

static float *acc_dense_put(rad_solver *sv, rmb_acc *m, uint32_t id)
{
	if (id >= m->cap) {
		size_t n = acc_dense_ids(sv, id), old = m->cap;
		float *d = rad_mem_realloc(&sv->mem, m->kind, m->dense,
		                           n * m->nv * sizeof(float));
		if (!d)
			return NULL;
		memset(d + old * m->nv, 0, (n - old) * m->nv * sizeof(float));
		m->dense = d;
		m->cap = n;
	}
	return &m->dense[(size_t)id * m->nv];
}

float *rmb_acc_put(rad_solver *sv, rmb_acc *m, uint32_t id)
{
	if (m->dense)
		return acc_dense_put(sv, m, id);
	size_t w = 1 + m->nv;
	if (m->cap) {
		rmb_acc_word *s =
		        &m->slot[acc_slot(m->slot, m->cap, m->nv, id)];
		if (s->id == id)
			return &s[1].v;
	}
	if (4 * (m->n + 1) > 3 * m->cap) {
		size_t cap = m->cap ? 2 * m->cap : ACC_FIRST;
		if (cap * w >= acc_dense_ids(sv, id) * m->nv)
			return acc_to_dense(sv, m, id)
			               ? NULL
			               : acc_dense_put(sv, m, id);
		rmb_acc_word *g =
		        rad_mem_alloc(&sv->mem, m->kind, cap * w * sizeof(*g));
		if (!g)
			return NULL;
		for (size_t i = 0; i < cap * w; i++)
			g[i] = (rmb_acc_word){.v = 0};
		for (size_t i = 0; i < cap; i++)
			g[i * w].id = RAD_NONE;
		for (size_t i = 0; i < m->cap; i++)
			if (m->slot[i * w].id != RAD_NONE)
				memcpy(&g[acc_slot(g, cap, m->nv,
				                   m->slot[i * w].id)],
				       &m->slot[i * w], w * sizeof(*g));
		rad_mem_free(&sv->mem, m->kind, m->slot);
		m->slot = g;
		m->cap = cap;
	}
	rmb_acc_word *s = &m->slot[acc_slot(m->slot, m->cap, m->nv, id)];
	s->id = id;
	m->n++;
	return &s[1].v;
}

void rmb_acc_free(rad_solver *sv, rmb_acc *m)
{
	rad_mem_free(&sv->mem, m->kind, m->slot);
	rad_mem_free(&sv->mem, m->kind, m->dense);
	m->slot = NULL;
	m->dense = NULL;
	m->n = m->cap = 0;
}

rad_status rmb_cover_links(rad_solver *sv, rmb_state *st)
{
	size_t need = ((size_t)sv->h.links.count + 63) / 64;
	if (need <= st->cap_bits)
		return RAD_OK;
	size_t cap = st->cap_bits, old = st->cap_bits;
	uint64_t *f = rad_mem_grow(&sv->mem, RAD_MEM_LINKS, st->fresh, &cap,
	                           need, sizeof(uint64_t), 64);
	if (!f)
		return RAD_ERR_NOMEM;
	st->fresh = f;
	cap = old;
	uint64_t *d = rad_mem_grow(&sv->mem, RAD_MEM_LINKS, st->dead, &cap,
	                           need, sizeof(uint64_t), 64);
	if (!d)
		return RAD_ERR_NOMEM;
	st->dead = d;
	memset(f + old, 0, (cap - old) * sizeof(uint64_t));
	memset(d + old, 0, (cap - old) * sizeof(uint64_t));
	st->cap_bits = cap;
	return RAD_OK;
}

void rmb_made_links(rmb_state *st, uint32_t first, uint32_t n)
{
	for (uint32_t k = 0; k < n; k++) {
		rmb_set_bit(st->fresh, first + k, 1);
		rmb_set_bit(st->dead, first + k, 0);
	}
}

void rmb_count_deleted(rad_solver *sv, uint32_t id, rad_status *rs)
{
	rmb_state *st = sv->impl;
	const rad_link *l = rad_link_at(&sv->h, id);
	if (rmb_fresh(st, id))
		return;
	sv->stats.links_deleted++;
	if (sv->opt.study && !*rs)
		*rs = set_add(sv, &st->deleted, rmb_pair_key(l->rcv, l->src));
}
