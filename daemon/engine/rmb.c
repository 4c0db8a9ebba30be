/*
 * rmb.c -- reduced-memory hierarchical radiosity (docs/ALGORITHM.md §5, the
 * report's RMbright): radiosity to transmit, and the iterations over it.
 *
 * Every node carries dB, the radiosity it still has to transmit.  At the
 * start dB = B = E (pulled up the trees); each iteration gathers
 * I = sum F dB over the links, pushes I down, sets dB = rho I and B += dB
 * on the leaves and pulls both up.  A light transmits in the first
 * iteration only.  The result equals classic HR for the same links
 * (docs/ALGORITHM.md §5.1); the oracle is applied to dB, so links coarsen
 * as the increments shrink.
 *
 * DESIGN
 * The links are the leaves of a link hierarchy that rmb_refine.c walks
 * every iteration, gathering I as it goes (RefineAndGather); what the
 * walk asks of nodes is rmb_nodes.c's.  This file holds the iteration
 * around it (energy bound, push, update, pull, the tail jump) and its
 * statistics.
 */
#include <math.h>
#include <string.h>

#include "rad.h"
#include "rmb.h"

/* ------------------------------------------------- push, update, pull */

typedef struct push_acc {
	double change, total; /* sum A |luma of B's change|, sum A luma B */
	double chg[3];        /* sum A |dB| per channel */
	double shot;          /* sum A |luma dB|: what goes out next */
	const double *q;      /* after the tail jump: its rates, else NULL */
	double hold_below;    /* delayed emission: a leaf holds R back while
	                         |luma R| is below this (0: never) */
	double held;          /* sum A |luma S_B| held back */
} push_acc;

/*
 * Delayed emission (docs/ALGORITHM.md §6, the report's §5.3), with
 * rad_options.delay = alpha > 0.  A leaf's radiosity to transmit,
 * R = rho I (I gathered this step plus what it held back), is held back
 * while its photopic value is below alpha times the mean dB sent last
 * step (the first: the mean flux), and sent in full once it is not.  A
 * held leaf sends nothing (dB = 0), and its B does not take R; so the
 * links from it coarsen or go (rmb's oracle reads dB).  What it holds
 * costs no storage: its reported I, the total irradiance, is
 * (B + S_B - E) / rho, so S_B = rho I - (B - E) is read back from it at
 * the next step's start and becomes the I the gather adds to (hold_leaf).
 * The answer the leaves report includes S_B; the B that sources send and
 * the final gather reads does not (at most alpha times the mean dB a
 * leaf, which falls with it).  The tail jump, which takes every leaf's
 * dB to be a geometric series, is not made: a held leaf's is not.
 */
static void hold_leaf(rad_hier *h, uint32_t id, rad_elem *e, double P[3])
{
	const rad_material *m = rad_elem_mat(h, id);
	double area = rad_elem_area(h, id);
	for (int c = 0; c < 3; c++) {
		double s = m->rho[c] * (double)e->I[c] -
		           ((double)e->B[c] - m->emit[c]);
		e->I[c] = m->rho[c] > 0 && s > 0 ? (float)(s / m->rho[c]) : 0;
		P[c] += area * e->I[c];
	}
}

/* Clear the I (and a cluster's V, S) the gather adds to, in node t's
 * tree; with held (delayed emission), a leaf keeps what it holds back
 * instead (hold_leaf), summed into held. */
static void zero_I(rad_hier *h, uint32_t t, double *held)
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		memset(&h->flux[t & ~RAD_TAG_MASK], 0, sizeof(*h->flux));
		if (!rad_cluster_is_leaf(c)) {
			zero_I(h, (c->child) | RAD_TAG_CLUSTER, held);
			zero_I(h, (c->child + 1) | RAD_TAG_CLUSTER, held);
		}
		return;
	}
	rad_elem *e = rad_elem_at(h, t);
	if (held && rad_elem_is_leaf(e)) {
		hold_leaf(h, t, e, held);
		return;
	}
	memset(e->I, 0, sizeof(e->I));
	if (!rad_elem_is_leaf(e))
		for (uint32_t k = 0; k < 4; k++)
			zero_I(h, e->child + k, held);
}

/*
 * Energy bound.  What all receivers gather in one iteration cannot
 * exceed what the sources had to transmit: sum A I <= sum A dB (equal in
 * a closed scene).  Discrete form factors can break it (a leaf's links
 * come from several receiver levels, and their errors near corners do
 * not cancel), and at reflectance near 1 the excess compounds: the
 * increments stop shrinking and the solution diverges (measured: a
 * closed box at rho 0.99 ran away past +300 % in 600 iterations).  So,
 * per channel, the gathered irradiance is scaled down when it exceeds the
 * power sent, which bounds every increment by rho_max times the last and
 * makes the iteration converge for any reflectance below 1.  Nothing
 * changes when the bound holds (any open scene, most closed ones).
 * Sources: the leaves' dB (after the first iteration; in the first,
 * lights and emitters send flux the bound is not written for).
 */
static void node_power(const rad_hier *h, uint32_t id, double P[3])
{
	const rad_elem *e = rad_elem_at(h, id);
	for (int c = 0; c < 3; c++)
		P[c] += (double)rad_elem_area(h, id) * e->I[c];
	if (!rad_elem_is_leaf(e))
		for (uint32_t k = 0; k < 4; k++)
			node_power(h, e->child + k, P);
}

static void cluster_power(const rad_hier *h, uint32_t id, double P[3])
{
	const rad_cluster *c = rad_cluster_at(h, id);
	/* A cluster's I is the mean over its area (hier.h): power A I. */
	const float *I = h->flux[id & ~RAD_TAG_MASK].I;
	for (int k = 0; k < 3; k++)
		P[k] += (double)c->area * I[k];
	if (!rad_cluster_is_leaf(c)) {
		cluster_power(h, c->child | RAD_TAG_CLUSTER, P);
		cluster_power(h, (c->child + 1) | RAD_TAG_CLUSTER, P);
	}
}

static void scale_I(rad_hier *h, uint32_t t, const double k[3])
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		float *I = h->flux[t & ~RAD_TAG_MASK].I;
		for (int i = 0; i < 3; i++)
			I[i] = (float)(I[i] * k[i]);
		if (!rad_cluster_is_leaf(c)) {
			scale_I(h, c->child | RAD_TAG_CLUSTER, k);
			scale_I(h, (c->child + 1) | RAD_TAG_CLUSTER, k);
		}
		return;
	}
	rad_elem *e = rad_elem_at(h, t);
	for (int i = 0; i < 3; i++)
		e->I[i] = (float)(e->I[i] * k[i]);
	if (!rad_elem_is_leaf(e))
		for (uint32_t c = 0; c < 4; c++)
			scale_I(h, e->child + c, k);
}

/* Returns the largest scale-down applied (1 = none). */
static double energy_bound(rad_solver *sv)
{
	rad_hier *h = &sv->h;
	uint32_t np = sv->scene->npolys;
	double got[3] = {0, 0, 0}, k[3];
	for (uint32_t i = 0; i < np; i++)
		node_power(h, i, got);
	if (np > 0)
		cluster_power(h, RAD_TAG_CLUSTER, got);
	/* What the leaves held back was sent before (hold_leaf); where the
	 * bound scales the rest, it is scaled with it. */
	const rmb_state *st = sv->impl;
	for (int c = 0; c < 3; c++)
		got[c] -= st->held[c];
	double worst = node_energy_scale(h, 1, got, k);
	if (worst >= 1)
		return 1;
	scale_I(h, RAD_TAG_CLUSTER, k);
	for (uint32_t i = 0; i < np; i++)
		scale_I(h, i, k);
	return worst;
}

/* A leaf's update: dB = rho I, B += dB. */
static void update_leaf(rad_hier *h, uint32_t id, rad_elem *e,
                        const float *extra, void *ud)
{
	(void)extra;
	push_acc *acc = ud;
	const rad_material *m = rad_elem_mat(h, id);
	float area = rad_elem_area(h, id);
	float inc[3], dB[3], R[3];
	rad_elem_dB(h, e, dB); /* the last increment, exact (hier.h) */
	for (int c = 0; c < 3; c++)
		R[c] = m->rho[c] * e->I[c];
	int hold = fabs(rad_luma(R)) < acc->hold_below;
	for (int c = 0; c < 3; c++) {
		double d = hold ? 0 : R[c];
		/* After the jump (tail_jump) B takes what the increment adds
		 * beyond the geometric tail already counted. */
		inc[c] = acc->q ? (float)((d - acc->q[c] * dB[c]) /
		                          (1 - acc->q[c]))
		                : (float)d;
		dB[c] = (float)d;
		e->B[c] += inc[c];
		acc->chg[c] += area * fabs(d);
		/* Leaves report the total irradiance, not the increment
		 * (a black leaf gathers nothing: it keeps the last one). */
		if (m->rho[c] > 0)
			e->I[c] = (e->B[c] + (hold ? R[c] : 0) - m->emit[c]) /
			          m->rho[c];
	}
	rad_elem_set_dB(h, e, dB);
	if (hold)
		acc->held += area * fabs(rad_luma(R));
	acc->change += area * fabs(rad_luma(inc));
	acc->shot += area * fabs(rad_luma(dB));
	acc->total += area * rad_luma(e->B);
}

/*
 * The tail jump, as hr.c's: once the increments shrink at a steady rate q
 * (per channel), B takes dB q / (1 - q) at once.  rmb then goes on
 * shooting dB as before, but a leaf's B only takes what each new
 * increment adds beyond the geometric tail already counted,
 * (dB' - q dB) / (1 - q) (update_leaf): summed over the steps to come
 * that is exactly what they add minus the tail, so the fixed point is
 * unchanged.  Once per solve.  Returns 1 when it jumped.
 */
static int tail_jump(rad_solver *sv, rmb_state *st)
{
	if (st->jumped || st->iter < 4 || sv->opt.delay > 0 ||
	    !node_tail_rates(&st->chg[0][0], st->q))
		return 0;
	st->mean_B = node_tail_add(&sv->h, st->q);
	st->qmax = fmax(st->q[0], fmax(st->q[1], st->q[2]));
	st->jumped = 1;
	return 1;
}

/* --------------------------------------------------------- statistics */

/* Count the links stored by kind; new ones were created this iteration. */
static void count_tree(rad_solver *sv, rmb_state *st, uint32_t id)
{
	rad_stats *s = &sv->stats;
	const rad_link *l = rad_link_at(&sv->h, id);
	node_count_link(s, l->rcv, l->src);
	if (rmb_fresh(st, id)) {
		s->links_created++;
		if (sv->opt.study &&
		    rmb_set_has(&st->deleted, rmb_pair_key(l->rcv, l->src)))
			s->links_recreated++;
		rmb_set_bit(st->fresh, id, 0);
	}
	uint32_t n, child = rad_link_child(&sv->h, l, &n);
	if (n == 0) {
		s->links_active++;
		return;
	}
	s->links_passive++;
	for (uint32_t k = 0; k < n; k++)
		count_tree(sv, st, child + k);
}

static void count_links(rad_solver *sv)
{
	rmb_state *st = sv->impl;
	rad_stats *s = &sv->stats;
	s->links = s->links_ss = s->links_sc = s->links_cc = 0;
	s->links_light = s->links_active = s->links_passive = 0;
	for (size_t i = 0; i < st->nroots; i++)
		count_tree(sv, st, st->roots[i]);
}

/* ------------------------------------------------------------- solver */

/* Under a budget, room for the receiver-accuracy maps (err, made again
 * by every walk, and cut) to grow once each (and a slot for each element
 * a split will make, w->elem_extra; a growth the budget refuses past
 * that only leaves receivers uncut: rmb_refine.c, track_err), and for
 * the link bits (fresh, dead) to double once.  Counted from the
 * capacity they have, so that what they hold, which the budget's work
 * includes, is not counted again (arrays by element id counted whole at
 * each step's start kept the Graz office at 12.2 of 12.4 MiB where 10.6
 * of it was what it used). */
static size_t step_reserve(const rad_solver *sv)
{
	const rmb_state *st = sv->impl;
	return rmb_acc_growth(sv, &st->err) + rmb_acc_growth(sv, &st->cut) +
	       4 * st->cap_bits * sizeof(uint64_t);
}

static rad_status rmb_init(rad_solver *sv, rad_error *err)
{
	rmb_state *st =
	        rad_mem_calloc(&sv->mem, RAD_MEM_SCRATCH, 1, sizeof(*st));
	if (!st)
		return rad_fail(err, RAD_ERR_NOMEM, "rmb: out of memory");
	sv->impl = st;
	rad_status rs = wave_init(sv, &st->wave, sizeof(rmb_item));
	st->wave.elem_extra = 3 * sizeof(float); /* err's 2 and cut's 1 */
	st->err.nv = 2;
	st->err.kind = RAD_MEM_SCRATCH;
	st->cut.nv = 1;
	st->cut.kind = RAD_MEM_ELEM_SURFACE;
	st->ncl = sv->h.clusters.count;
	st->arefl = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->ncl,
	                           sizeof(float));
	if (rs || !st->arefl || rmb_rho_init(sv, st))
		return rad_fail(err, RAD_ERR_NOMEM, "rmb: out of memory");
	if ((rs = rad_hier_keep_flux(&sv->h, err)) ||
	    (rs = rad_hier_keep_deltas(&sv->h, err)))
		return rs;
	/* A budget the first step's reserve and a block of each pool do not
	 * fit in is refused with the hierarchy's (rad_solver_new), not by
	 * that step. */
	st->wave.reserve = step_reserve;
	rs = wave_start_room(sv, &st->wave, err);
	if (rs)
		return rs;
	rmb_mark_black(sv, 0);
	/* B = E everywhere, then the initial pull: dB = B on every node. */
	rad_hier_reset_emission(&sv->h);
	for (uint32_t i = 0; i < sv->scene->npolys; i++) {
		rad_elem *e = rad_elem_at(&sv->h, i);
		rad_elem_set_dB(&sv->h, e, e->B);
	}
	rad_hier_pull(&sv->h);
	return RAD_OK;
}

static void release_scratch(rad_solver *sv, rmb_state *st)
{
	wave_release(sv, &st->wave);
	rmb_acc_free(sv, &st->err);
}

static rad_status rmb_step(rad_solver *sv, rad_error *err)
{
	rmb_state *st = sv->impl;
	rad_hier *h = &sv->h;
	wave_step_begin(sv, &st->wave);
	/* A first step cancelled between rows resumes its gather. */
	if (st->iter > 0 || st->init_row == 0) {
		double *held = sv->opt.delay > 0 ? st->held : NULL;
		zero_I(h, RAD_TAG_CLUSTER, NULL);
		memset(st->held, 0, sizeof(st->held));
		for (uint32_t i = 0; i < sv->scene->npolys; i++)
			zero_I(h, i, held);
	}
	rad_status rs = rmb_refine_gather(sv, st);
	if (rs == RAD_ERR_CANCELLED) {
		wave_release(sv, &st->wave); /* err goes on */
		wave_step_end(sv, &st->wave, err);
		return rad_fail(err, rs,
		                "rmb: cancelled while linking every pair of "
		                "polygons (%u of %u rows gathered); the next "
		                "step goes on from there",
		                st->init_row, sv->scene->npolys);
	}
	release_scratch(sv, st);
	if (rs)
		return wave_failed(sv, rs, err);
	if (st->iter > 0)
		energy_bound(sv);
	rad_solver_progress(sv, 0.9);
	push_acc acc = {0, 0, {0, 0, 0}, 0, st->jumped ? st->q : NULL, 0, 0};
	if (sv->opt.delay > 0)
		acc.hold_below =
		        sv->opt.delay *
		        (st->iter == 0 ? sv->flux_scale / sv->scene->total_area
		                       : st->mean_dB);
	rad_hier_push(h, update_leaf, NULL, NULL, &acc, NULL);
	rad_hier_pull(h);
	memmove(st->chg[1], st->chg[0], 2 * sizeof(st->chg[0]));
	memcpy(st->chg[0], acc.chg, sizeof(acc.chg));
	st->iter++;
	st->mean_dB = acc.shot / sv->scene->total_area;
	st->mean_B = acc.total / sv->scene->total_area;
	double r = acc.total > 0 ? acc.change / acc.total : 0;
	/* After the jump, as in hr.c: the error estimate is never made from
	 * a faster rate than the one jumped over. */
	if (st->jumped && sv->prev_residual > 0 &&
	    r < st->qmax * sv->prev_residual)
		sv->prev_residual = r / st->qmax;
	rad_solver_set_residual(sv, r);
	tail_jump(sv, st);
	count_links(sv);
	return wave_step_end(sv, &st->wave, err);
}

static void rmb_destroy(rad_solver *sv)
{
	rmb_state *st = sv->impl;
	if (!st)
		return;
	release_scratch(sv, st);
	wave_destroy(sv, &st->wave);
	rad_mem_free(&sv->mem, RAD_MEM_LINKS, st->roots);
	rad_mem_free(&sv->mem, RAD_MEM_LINKS, st->fresh);
	rad_mem_free(&sv->mem, RAD_MEM_LINKS, st->dead);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->rho_at);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->arefl);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->rhomax);
	rmb_acc_free(sv, &st->cut);
	rad_mem_free(&sv->mem, RAD_MEM_STUDY, st->deleted.keys);
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, st);
	sv->impl = NULL;
}

const rad_solver_ops rad_solver_rmb_ops = {
        .name = "rmb",
        .init = rmb_init,
        .step = rmb_step,
        .destroy = rmb_destroy,
};
