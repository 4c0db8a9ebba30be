/*
 * rmb_nodes.c -- what the reduced-memory solver's walk (rmb_refine.c)
 * and its iterations (rmb.c) ask of nodes: do they reflect, how much
 * reflecting area, their largest reflectance, the accuracy asked of
 * receivers; and the set of deleted pairs kept for the study statistics.
 * Below both files, so that neither calls up into the other's.
 */
#include <math.h>
#include <string.h>

#include "rad.h"
#include "rmb.h"

/* ------------------------------------------------------ reflectance */

int rmb_node_black(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 1;
	if (node_is_cluster(t))
		return st->black[node_index(t)];
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

static double elem_rho_max(const rad_solver *sv, uint32_t id)
{
	const float *rho = rad_elem_mat(&sv->h, id)->rho;
	return fmax(rho[0], fmax(rho[1], rho[2]));
}

/* Fill black[], arefl[] and rhomax[] for cluster id and below. */
double rmb_mark_black(rad_solver *sv, uint32_t id)
{
	rmb_state *st = sv->impl;
	const rad_cluster *c = rad_cluster_at(&sv->h, id);
	double a = 0, rm = 0;
	if (!rad_cluster_is_leaf(c)) {
		a += rmb_mark_black(sv, c->child);
		a += rmb_mark_black(sv, c->child + 1);
		rm = fmax(st->rhomax[c->child], st->rhomax[c->child + 1]);
	} else {
		for (uint32_t j = c->first; j < c->first + c->count; j++) {
			a += rmb_node_arefl(sv, sv->h.order[j]);
			rm = fmax(rm, elem_rho_max(sv, sv->h.order[j]));
		}
	}
	st->rhomax[id] = (float)rm;
	st->arefl[id] = (float)a;
	st->black[id] = a == 0;
	return a;
}

double rmb_node_rho_max(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 0;
	if (node_is_cluster(t))
		return st->rhomax[node_index(t)];
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
	double floor = (1 - st->rhomax[0]) * st->mean_B;
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
