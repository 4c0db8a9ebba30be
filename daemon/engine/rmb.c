/*
 * rmb.c -- reduced-memory hierarchical radiosity: radiosity to transmit,
 * the link hierarchy and RefineAndGather (ALGORITHM.md §4, the report's
 * RMbright).
 *
 * Every node carries dB, the radiosity it still has to transmit.  At the
 * start dB = B = E (pulled up the trees); each iteration gathers
 * I = sum F dB over the links, pushes I down, sets dB = rho I and B += dB
 * on the leaves and pulls both up.  A light transmits in the first
 * iteration only.  The result equals classic HR for the same links (§4.2.2);
 * the oracle is applied to dB, so links coarsen as the increments shrink.
 *
 * DESIGN
 * The link hierarchy.  A link that was refined stays in memory as a
 * passive link whose children -- the links its refinement made -- are one
 * run of consecutive records (child, nchild; RAD_LINK_SPLIT_SRC says which
 * end was split).  Active links are the leaves of these trees; the roots
 * are listed in st->roots (with clustering: the root cluster's self-link).
 * Receivers keep no link lists: the walk over the link trees is the
 * gather.
 *
 * RefineAndGather, in chunks.  The recursive walk of fig. 4.2 runs over
 * a work list of items (receiver, source, record) used as a stack, so
 * that it stays about as short as the walk is deep.  Its waves (wave.c)
 * are the top chunks of the list: the worker threads judge them (oracle
 * on dB with the stored form factor, or on an estimate for a new pair;
 * shadow rays for a new pair at its level), and one thread applies them
 * in order: an item at its level adds F dB to its receiver, an item to
 * refine pushes its children -- the stored ones of a passive link, or new
 * ones.
 *
 * What happens "on return" in fig. 4.2 -- form factors from the children,
 * which links to keep -- needs the children's results, so it is a second,
 * post-order pass over the trees once the waves are done (post()).  New
 * children are therefore made as records at once (tentative links) when
 * their parent is a record and they could be kept; under a link whose
 * source is a pure source (reflectance 0, so dB is zero after the first
 * iteration) nothing can ever be kept, and the pairs below it are walked
 * as transient items that exist only in the wave (such a link weighs
 * nothing in its parent's recursive form factor: see child_weight()).
 * So are the children of a link that RAD_STORE_ANTICIPATE says a coarser
 * level will serve next time; their form factors are summed into that
 * link, weighted, so that it carries their recursive form factor.
 * This keeps the memory of iteration 1 -- where most transfers come from
 * the sources -- close to what is finally stored.
 *
 * Keeping (the creation criterion, §4.3.1): a link is kept when its source
 * and its receiver both reflect (RAD_STORE_MINIMAL, the report's rule).
 * RAD_STORE_ANTICIPATE also refuses to keep the children of a link whose
 * next increment -- this one times the source's largest reflectance --
 * will pass the oracle at the link's own level (coarse_next()): they are
 * used now and dropped, and the link stays active with their recursive
 * form factor.
 * A passive link with at least one child kept keeps its run (compacted
 * in place to the kept children); one with none becomes active again.  A
 * passive link found at its level deletes its whole subtree (§4.3.2).
 *
 * Recursive form factors (§4.3.4): every passive link's form factor is
 * rebuilt from its children after each walk, F = sum of w_c F_c
 * (child_weight()), which is exact for uniform radiosity over the
 * reflecting polygons and, for a cluster's self-link, gives the true
 * self-transfer (zero for convex contents) instead of the isotropic guess.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "err.h"
#include "wave.h"

/* rmb's own link flags, beside RAD_LINK_PASSIVE and RAD_LINK_SPLIT_SRC. */
enum {
	L_NEW = 1u << 4,   /* made this iteration: no form factor yet */
	L_DEAD = 1u << 5,  /* carries nothing: remove */
	L_PRUNE = 1u << 6, /* passive link used at its level: drop subtree */
};

typedef struct rmb_item {
	uint32_t rcv, src;
	uint32_t link; /* its record, or RAD_NONE for a transient pair */
	uint32_t anc;  /* transient: the record whose form factor it adds to */
	float w;       /* transient: its weight in anc's form factor */
} rmb_item;

/* Open-addressing set of 64-bit pair keys (study statistics, STUDY). */
typedef struct rmb_set {
	uint64_t *keys; /* 0 = empty slot; keys are stored + 1 */
	size_t n, cap;
} rmb_set;

typedef struct rmb_state {
	rad_wave wave; /* items: rmb_item; its todo is the work list */
	uint32_t *roots;
	size_t nroots, cap_roots; /* stored root links, LINKS */
	uint8_t *black;           /* per cluster id: contents all rho = 0 */
	float *arefl;             /* per cluster id: area that reflects */
	float *rhomax;            /* per cluster id: largest reflectance */
	uint32_t ncl;
	uint32_t iter;    /* iterations done */
	double mean_dB;   /* area-mean photopic dB after the last update */
	double mean_B;    /* ... and B */
	double chg[3][3]; /* sum A |dB| per channel, last three steps */
	double q[3];      /* the tail jump's rates (tail_jump) */
	double qmax;      /* ... the largest */
	int jumped;       /* tail_jump done */
	rmb_set deleted;  /* study: pairs deleted so far */
	/* Receiver accuracy (see rcv_too_coarse), by element id:
	 * cut   links at least this error (a fraction of the limit) go to
	 *       the receiver's children; 0 = none.  Sticky, ELEM_SURFACE.
	 * err   sum of the errors of the links gathered this iteration,
	 * emax  the largest of them; SCRATCH, for one step. */
	float *cut, *err, *emax;
	size_t cap_cut, cap_err, cap_emax;
} rmb_state;

/* ------------------------------------------------------------- helpers */

/* Push an item on the work list. */
static rad_status push_item(rad_solver *sv, rmb_item it)
{
	rmb_state *st = sv->impl;
	return wave_push(sv, &st->wave, &st->wave.todo, &it);
}

static uint64_t pair_key(uint32_t r, uint32_t s)
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

static int set_has(const rmb_set *s, uint64_t k)
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

/* 1 if no polygon of the node reflects (a pure source, or black). */
static int node_black(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 1;
	if (node_is_cluster(t))
		return st->black[node_index(t)];
	const rad_elem *e = rad_elem_at(&sv->h, t);
	const float *rho = rad_elem_mat(&sv->h, e)->rho;
	return rho[0] == 0 && rho[1] == 0 && rho[2] == 0;
}

/* Area of the node's polygons that reflect (rho > 0). */
static double node_arefl(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_cluster(t))
		return st->arefl[node_index(t)];
	return node_black(sv, t) ? 0 : node_area(&sv->h, t);
}

static double elem_rho_max(const rad_solver *sv, uint32_t id)
{
	const float *rho = rad_elem_mat(&sv->h, rad_elem_at(&sv->h, id))->rho;
	return fmax(rho[0], fmax(rho[1], rho[2]));
}

/* Fill black[], arefl[] and rhomax[] for cluster id and below. */
static double mark_black(rad_solver *sv, uint32_t id)
{
	rmb_state *st = sv->impl;
	const rad_cluster *c = rad_cluster_at(&sv->h, id);
	double a = 0, rm = 0;
	if (c->child != RAD_NONE) {
		a += mark_black(sv, c->child);
		a += mark_black(sv, c->child + 1);
		rm = fmax(st->rhomax[c->child], st->rhomax[c->child + 1]);
	} else {
		for (uint32_t j = c->first; j < c->first + c->count; j++) {
			a += node_arefl(sv, sv->h.order[j]);
			rm = fmax(rm, elem_rho_max(sv, sv->h.order[j]));
		}
	}
	st->rhomax[id] = (float)rm;
	st->arefl[id] = (float)a;
	st->black[id] = a == 0;
	return a;
}

/*
 * Weight of child link c in its parent p's recursive form factor
 * (ALGORITHM.md §4.3.4: F_p = sum of weight x F_c).  After the first
 * iteration only reflecting polygons transmit or use what they receive,
 * so both averages run over reflecting area: a split receiver gives the
 * mean over its reflecting children (a cluster's irradiance is the mean of
 * its polygons', hier.h); a split source, the sum
 * over its children scaled by their reflecting fractions, so that F_p
 * times the source's area-mean dB is exact when dB is uniform over the
 * reflecting part (sources inside a cluster keep dB = 0).
 */
static double child_weight(const rad_solver *sv, const rad_link *p,
                           const rad_link *c)
{
	const rad_hier *h = &sv->h;
	double w = 1;
	if (c->rcv != p->rcv) {
		double a = node_arefl(sv, p->rcv);
		w *= a > 0 ? node_arefl(sv, c->rcv) / a : 0;
	}
	if (c->src != p->src) {
		double fp = node_arefl(sv, p->src) / node_area(h, p->src);
		double fc = node_arefl(sv, c->src) / node_area(h, c->src);
		w *= fp > 0 ? fc / fp : 0;
	}
	return w;
}

/* Radiosity the node still has to transmit (a light: first iteration). */
static void node_dB(const rad_solver *sv, uint32_t t, double out[3])
{
	const rmb_state *st = sv->impl;
	const float *d;
	if (node_is_light(t)) {
		for (int c = 0; c < 3; c++)
			out[c] = st->iter == 0
			                 ? sv->scene->lights[node_index(t)]
			                           .intensity[c]
			                 : 0;
		return;
	}
	d = node_is_cluster(t) ? rad_cluster_at(&sv->h, t)->dB
	                       : rad_elem_at(&sv->h, t)->dB;
	for (int c = 0; c < 3; c++)
		out[c] = d[c];
	/* The first iteration sends the emission (dB = B = E). */
	if (st->iter == 0 && !node_is_cluster(t))
		node_exposed_emission(&sv->h, t, out);
}

static double luma3(const double c[3])
{
	return RAD_LUMA_R * c[0] + RAD_LUMA_G * c[1] + RAD_LUMA_B * c[2];
}

/* Increments are signed only by rounding: judge their magnitude. */
static double node_luma_dB(const rad_solver *sv, uint32_t t)
{
	double d[3];
	node_dB(sv, t, d);
	return fabs(luma3(d));
}

/* Largest reflectance inside a node (over channels), for anticipation. */
static double node_rho_max(const rad_solver *sv, uint32_t t)
{
	const rmb_state *st = sv->impl;
	if (node_is_light(t))
		return 0;
	if (node_is_cluster(t))
		return st->rhomax[node_index(t)];
	return elem_rho_max(sv, t);
}

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
static double spread_limit(const rad_solver *sv)
{
	const rmb_state *st = sv->impl;
	if (st->iter == 0)
		return sv->opt.variation * sv->flux_scale /
		       sv->scene->total_area;
	double floor = (1 - st->rhomax[0]) * st->mean_B;
	return sv->opt.variation * fmax(st->mean_dB, floor);
}

/*
 * Receiver accuracy, as in hr.c: a leaf receives every link of its
 * ancestors, each averaged over a larger region, and near corners their
 * errors add up (and, reflected many times at high reflectance, make the
 * solution drift: measured +8 % in a closed box at rho 0.9).  A link's
 * error is half its spread times the source's dB, as a fraction of
 * spread_limit.  A link over 1 goes to the receiver's children; so does
 * one over the receiver's cut, which mark_cuts() sets where the errors
 * summed down a quadtree passed 1 in an earlier iteration.
 */
static double link_err(const rad_solver *sv, double b, double spread)
{
	double lim = spread_limit(sv);
	return lim > 0 ? 0.5 * b * spread / lim : 0;
}

static int rcv_too_coarse(const rad_solver *sv, uint32_t r, double e)
{
	const rmb_state *st = sv->impl;
	if (e > 1)
		return 1;
	if (node_is_cluster(r) || node_is_light(r) || r >= st->cap_cut)
		return 0;
	return st->cut[r] > 0 && e >= st->cut[r];
}

/* ------------------------------------------------------------- judging */

/*
 * Judge one item: WAVE_LEVEL with its form factor when the link may carry
 * its transfer at this level, WAVE_SPLIT(_RCV) to refine, WAVE_DROP when
 * nothing passes.
 */
static uint8_t judge(rad_solver *sv, const void *item, int may_split,
                     wave_verdict *out, uint64_t *rays)
{
	const rad_hier *h = &sv->h;
	const rmb_item *it = item;
	uint32_t r = it->rcv, s = it->src;
	const rad_link *l =
	        it->link != RAD_NONE ? rad_link_at(h, it->link) : NULL;
	int fresh = !l || (l->flags & L_NEW);
	int passive = l && !fresh && l->child != RAD_NONE;
	double b = node_luma_dB(sv, s);
	if (passive && !may_split)
		return WAVE_SPLIT; /* cancelled: walk what exists, make nothing
		                    */
	if (r == s) { /* a cluster's self-link: opened up while it emits */
		if (!node_is_cluster(r))
			return WAVE_DROP;
		if (b > 0 && may_split)
			return WAVE_SPLIT;
		out->ff = fresh ? 0 : l->ff;
		return WAVE_LEVEL;
	}
	if (node_black(sv, r) || !node_facing(h, r, s))
		return WAVE_DROP;
	double f = !fresh ? (l->ff > 0 ? l->ff : node_ff_bound(h, r, s))
	                  : node_ff_estimate(h, r, s);
	if (may_split && wave_refinable(h, r, s) &&
	    node_oracle(sv, r, s, b, f) > sv->opt.eps)
		return WAVE_SPLIT;
	int rcv_split = may_split && node_splittable(h, r);
	if (!fresh) {
		if (rcv_split &&
		    rcv_too_coarse(sv, r, link_err(sv, b, l->spread)))
			return WAVE_SPLIT_RCV;
		out->ff = l->ff;
		out->spread = l->spread;
		return WAVE_LEVEL;
	}
	/* A pair that cannot be kept and carries nothing needs no rays. */
	if (b == 0 && (node_black(sv, s) || !l))
		return WAVE_LEVEL;
	double sp = 0;
	f = node_ff(sv, r, s, rays, &sp);
	if (rcv_split && rcv_too_coarse(sv, r, link_err(sv, b, sp)))
		return WAVE_SPLIT_RCV;
	return wave_at_level(sv, r, s, b, f, sp, may_split, out);
}

/* ------------------------------------------------------------ applying */

/* Grow a per-element float array to cover id (new entries zero). */
static rad_status cover(rad_solver *sv, rad_mem_kind kind, float **a,
                        size_t *cap, uint32_t id)
{
	if (id < *cap)
		return RAD_OK;
	size_t old = *cap;
	float *p = rad_mem_grow(&sv->mem, kind, *a, cap, (size_t)id + 1,
	                        sizeof(float), 1024);
	if (!p)
		return RAD_ERR_NOMEM;
	memset(p + old, 0, (*cap - old) * sizeof(float));
	*a = p;
	return RAD_OK;
}

static rad_status track_err(rad_solver *sv, rmb_state *st, uint32_t r, double e)
{
	if (cover(sv, RAD_MEM_SCRATCH, &st->err, &st->cap_err, r) ||
	    cover(sv, RAD_MEM_SCRATCH, &st->emax, &st->cap_emax, r))
		return RAD_ERR_NOMEM;
	st->err[r] += (float)e;
	if (e > st->emax[r])
		st->emax[r] = (float)e;
	return RAD_OK;
}

/* The transfer of an item at its level: I(rcv) += F dB(src). */
static rad_status gather(rad_solver *sv, uint32_t r, uint32_t s, double ff,
                         double spread, int transient)
{
	rmb_state *st = sv->impl;
	double d[3];
	node_dB(sv, s, d);
	float *I = node_is_cluster(r) ? rad_cluster_at(&sv->h, r)->I
	                              : rad_elem_at(&sv->h, r)->I;
	double fe = ff * node_emit_factor(&sv->h, r, s, 1);
	for (int c = 0; c < 3; c++)
		I[c] += (float)(fe * d[c]);
	node_took(&sv->h, r, s, fe * luma3(d));
	double b = fabs(luma3(d));
	if (!node_is_cluster(r)) {
		rad_status rs = track_err(sv, st, r, link_err(sv, b, spread));
		if (rs)
			return rs;
	}
	node_stat_exchange(sv, r, s, ff, b, b);
	sv->stats.links_transient += (uint64_t)transient;
	return RAD_OK;
}

/*
 * Anticipation (RAD_STORE_ANTICIPATE): will the next increment of this
 * link -- this one times the source's largest reflectance -- pass the
 * oracle at the link's own level?  Then the children it is about to get
 * will not be needed next time: they are walked as transient pairs and
 * the link stays active with their recursive form factor.
 */
static int coarse_next(const rad_solver *sv, uint32_t r, uint32_t s, double f)
{
	if (sv->opt.store != RAD_STORE_ANTICIPATE || r == s)
		return 0;
	double b = node_luma_dB(sv, s) * node_rho_max(sv, s);
	return node_oracle(sv, r, s, b, f) <= sv->opt.eps;
}

/* Refine an item: its children go to the next wave. */
static rad_status split_item(rad_solver *sv, const rmb_item *it, int rcv_only)
{
	rad_hier *h = &sv->h;
	rad_link *l = it->link != RAD_NONE ? rad_link_at(h, it->link) : NULL;
	if (l && !(l->flags & L_NEW) && l->child != RAD_NONE) {
		/* A passive link: walk the children it has. */
		for (uint32_t k = 0; k < l->nchild; k++) {
			const rad_link *c = rad_link_at(h, l->child + k);
			rmb_item ci = {c->rcv, c->src, l->child + k, RAD_NONE,
			               0};
			rad_status rs = push_item(sv, ci);
			if (rs)
				return rs;
		}
		return RAD_OK;
	}
	uint32_t kr[WAVE_KIDS], ks[WAVE_KIDS];
	int side, nk = wave_children(h, it->rcv, it->src, rcv_only, kr, ks,
	                             &side);
	if (nk < 0)
		return RAD_ERR_NOMEM;
	/* With a record and a reflecting source the children may be kept:
	 * make them as records now.  Otherwise they are transient. */
	rmb_item kid[WAVE_KIDS];
	int n = 0;
	for (int k = 0; k < nk; k++) {
		if (node_black(sv, kr[k]))
			continue; /* reflects nothing: no transfer to make */
		if (kr[k] != ks[k] && !node_facing(h, kr[k], ks[k]))
			continue; /* no record for what cannot carry */
		rmb_item c = {kr[k], ks[k], RAD_NONE, RAD_NONE, 0};
		kid[n++] = c;
	}
	if (n == 0) {
		if (l) /* nothing below: carries nothing */
			l->flags |= L_DEAD;
		return RAD_OK;
	}
	int keepable = l && !node_black(sv, it->src);
	if (keepable &&
	    coarse_next(sv, it->rcv, it->src,
	                l->flags & L_NEW ? node_ff_estimate(h, it->rcv, it->src)
	                                 : l->ff))
		keepable = 0;
	if (keepable) {
		uint32_t run = rad_pool_add(&h->links, (uint32_t)n);
		if (run == RAD_NONE)
			return RAD_ERR_NOMEM;
		l = rad_link_at(h, it->link); /* the table may have moved */
		l->child = run;
		l->nchild = (uint16_t)n;
		l->flags |= RAD_LINK_PASSIVE;
		if (side == 2)
			l->flags |= RAD_LINK_SPLIT_SRC;
		for (int k = 0; k < n; k++) {
			rad_link *c = rad_link_at(h, run + (uint32_t)k);
			c->rcv = kid[k].rcv;
			c->src = kid[k].src;
			c->next = c->child = RAD_NONE;
			c->flags = L_NEW;
			kid[k].link = run + (uint32_t)k;
		}
	} else if (l || it->anc != RAD_NONE) {
		/* Transient children: their form factors add up into the
		 * nearest record, weighted as in its recursion. */
		uint32_t anc = l ? it->link : it->anc;
		double w0 = l ? 1.0 : it->w;
		if (l)
			l->ff = 0;
		rad_link par = {.rcv = it->rcv, .src = it->src};
		for (int k = 0; k < n; k++) {
			rad_link ch = {.rcv = kid[k].rcv, .src = kid[k].src};
			kid[k].anc = anc;
			kid[k].w = (float)(w0 * child_weight(sv, &par, &ch));
		}
	}
	for (int k = 0; k < n; k++) {
		rad_status rs = push_item(sv, kid[k]);
		if (rs)
			return rs;
	}
	return RAD_OK;
}

/* Free the subtree below link id (not the link itself). */
static void free_children(rad_solver *sv, rmb_state *st, uint32_t id,
                          rad_status *rs)
{
	rad_hier *h = &sv->h;
	rad_link *l = rad_link_at(h, id);
	if (l->child == RAD_NONE)
		return;
	for (uint32_t k = 0; k < l->nchild; k++) {
		uint32_t c = l->child + k;
		free_children(sv, st, c, rs);
		rad_link *cl = rad_link_at(h, c);
		if (!(cl->flags & L_NEW)) {
			sv->stats.links_deleted++;
			if (sv->opt.study && !*rs)
				*rs = set_add(sv, &st->deleted,
				              pair_key(cl->rcv, cl->src));
		}
	}
	rad_pool_release_run(&h->links, l->child, l->nchild);
	l->child = RAD_NONE;
	l->nchild = 0;
	l->flags &= (uint16_t) ~(RAD_LINK_PASSIVE | RAD_LINK_SPLIT_SRC);
}

/* Items judged at once: enough for the threads, small enough that the
 * work list stays short (it is a stack: depth x chunk x children). */
#define RMB_CHUNK 4096

/* Apply an item's verdict: gather it at its level, or refine it (its
 * children are pushed on the work list). */
static rad_status apply(rad_solver *sv, const void *item, const wave_verdict *v)
{
	rmb_state *st = sv->impl;
	rad_hier *h = &sv->h;
	const rmb_item *it = item;
	rad_link *l = it->link != RAD_NONE ? rad_link_at(h, it->link) : NULL;
	rad_status rs = RAD_OK;
	switch (v->action) {
	case WAVE_DROP:
		if (l)
			l->flags |= L_DEAD;
		break;
	case WAVE_LEVEL:
		rs = gather(sv, it->rcv, it->src, v->ff, v->spread, l == NULL);
		if (l && (l->flags & L_NEW)) {
			l->ff = v->ff;
			l->spread = v->spread;
		} else if (l && l->child != RAD_NONE) {
			/* A coarser level will do: the subtree goes now, so
			 * that this walk reuses its records. */
			free_children(sv, st, it->link, &rs);
		} else if (!l && it->anc != RAD_NONE) {
			rad_link_at(h, it->anc)->ff += it->w * v->ff;
		}
		break;
	default:
		rs = split_item(sv, it, v->action == WAVE_SPLIT_RCV);
	}
	return rs;
}

/* Run the work list to its end, a wave from its top at a time. */
static rad_status run_waves(rad_solver *sv, rmb_state *st)
{
	rad_wave *w = &st->wave;
	while (w->todo.n > 0) {
		size_t n = w->todo.n < RMB_CHUNK ? w->todo.n : RMB_CHUNK;
		rad_status rs = wave_take_top(sv, w, n);
		if (!rs)
			rs = wave_run(sv, w, w->held.v, n, judge, apply);
		if (rs)
			return rs;
	}
	return RAD_OK;
}

/* ----------------------------------------------------------- post-order */

/* May a childless link be kept (the creation criterion)? */
static int storable(const rad_solver *sv, const rad_link *l)
{
	if (l->flags & L_DEAD)
		return 0;
	if (node_is_light(l->src) || node_black(sv, l->src) ||
	    node_black(sv, l->rcv))
		return 0;
	return 1;
}

/*
 * Settle link id after the walk: rebuild a passive link's form factor and
 * spread from its children, drop what is not to be kept (compacting the
 * sibling run in place), count.  Returns 1 if the link stays.
 */
static int post(rad_solver *sv, rmb_state *st, uint32_t id, rad_status *rs)
{
	rad_hier *h = &sv->h;
	rad_link *l = rad_link_at(h, id);
	if (l->child != RAD_NONE && (l->flags & (L_PRUNE | L_DEAD)))
		free_children(sv, st, id, rs);
	if (l->child != RAD_NONE) {
		uint32_t run = l->child, n = l->nchild, kept = 0;
		uint8_t keep[16];
		double f = 0, lo = INFINITY, hi = -INFINITY, sum_sp = 0;
		for (uint32_t k = 0; k < n; k++) {
			keep[k] = (uint8_t)post(sv, st, run + k, rs);
			kept += keep[k];
			l = rad_link_at(h, id);
			const rad_link *c = rad_link_at(h, run + k);
			f += child_weight(sv, l, c) * c->ff;
			lo = fmin(lo, c->ff - 0.5 * c->spread);
			hi = fmax(hi, c->ff + 0.5 * c->spread);
			sum_sp += c->spread;
		}
		l->ff = (float)f;
		if (node_is_cluster(l->rcv))
			l->spread = 0;
		else if (l->flags & RAD_LINK_SPLIT_SRC)
			l->spread = (float)sum_sp;
		else
			l->spread = (float)(hi - lo);
		if (kept == 0) {
			/* The children were counted (and their subtrees
			 * freed) by their own post(). */
			rad_pool_release_run(&h->links, run, n);
			l->child = RAD_NONE;
			l->nchild = 0;
			l->flags &= (uint16_t) ~(RAD_LINK_PASSIVE |
			                         RAD_LINK_SPLIT_SRC);
		} else if (kept < n) {
			uint32_t to = run;
			for (uint32_t k = 0; k < n; k++) {
				if (!keep[k])
					continue;
				if (run + k != to)
					memcpy(rad_link_at(h, to),
					       rad_link_at(h, run + k),
					       sizeof(rad_link));
				to++;
			}
			rad_pool_release_run(&h->links, to, n - kept);
			l->nchild = (uint16_t)kept;
		}
		if (kept) {
			l->flags &= (uint16_t) ~(L_DEAD | L_PRUNE);
			return 1;
		}
	}
	/* New links still carry L_NEW: count_tree() counts them. */
	int keep = storable(sv, l);
	l->flags &= (uint16_t)~L_PRUNE;
	if (!keep && !(l->flags & L_NEW)) {
		sv->stats.links_deleted++;
		if (sv->opt.study && !*rs)
			*rs = set_add(sv, &st->deleted,
			              pair_key(l->rcv, l->src));
	}
	return keep;
}

static rad_status root_push(rad_solver *sv, rmb_state *st, uint32_t id)
{
	uint32_t *r =
	        rad_mem_grow(&sv->mem, RAD_MEM_LINKS, st->roots, &st->cap_roots,
	                     st->nroots + 1, sizeof(*r), 64);
	if (!r)
		return RAD_ERR_NOMEM;
	st->roots = r;
	st->roots[st->nroots++] = id;
	return RAD_OK;
}

/*
 * Walk the items in the work list (roots of link trees), then settle the
 * records among them; the ones kept are appended to st->roots.
 */
static rad_status walk_roots(rad_solver *sv, rmb_state *st, uint32_t *ids,
                             size_t nids)
{
	rad_status rs = run_waves(sv, st);
	for (size_t i = 0; i < nids && !rs; i++) {
		if (post(sv, st, ids[i], &rs))
			rs = rs ? rs : root_push(sv, st, ids[i]);
		else
			rad_pool_release(&sv->h.links, ids[i]);
	}
	return rs;
}

/* Ids of the new root records of one walk (SCRATCH). */
typedef struct id_vec {
	uint32_t *v;
	size_t n, cap;
} id_vec;

/* A new root record (rcv <- src), or a transient item for a pure source. */
static rad_status new_root(rad_solver *sv, uint32_t r, uint32_t s, id_vec *ids)
{
	rmb_item it = {r, s, RAD_NONE, RAD_NONE, 0};
	if (node_black(sv, r) && r != s)
		return RAD_OK;
	if (!node_black(sv, s)) {
		uint32_t *v =
		        rad_mem_grow(&sv->mem, RAD_MEM_SCRATCH, ids->v,
		                     &ids->cap, ids->n + 1, sizeof(*v), 64);
		if (!v)
			return RAD_ERR_NOMEM;
		ids->v = v;
		it.link = rad_link_new(&sv->h, r, s, 0, 0);
		if (it.link == RAD_NONE)
			return RAD_ERR_NOMEM;
		rad_link_at(&sv->h, it.link)->flags = L_NEW;
		ids->v[ids->n++] = it.link;
	}
	return push_item(sv, it);
}

static rad_status first_walk(rad_solver *sv, rmb_state *st)
{
	const rad_scene *s = sv->scene;
	id_vec ids = {NULL, 0, 0};
	rad_status rs = RAD_OK;
	if (sv->opt.clustering) {
		for (uint32_t l = 0; l < s->nlights && !rs; l++)
			rs = new_root(sv, RAD_TAG_CLUSTER, l | RAD_TAG_LIGHT,
			              &ids);
		if (!rs)
			rs = new_root(sv, RAD_TAG_CLUSTER, RAD_TAG_CLUSTER,
			              &ids);
		if (!rs)
			rs = walk_roots(sv, st, ids.v, ids.n);
	} else {
		/* Every pair of polygons, in blocks of rows. */
		uint32_t n = s->npolys;
		for (uint32_t i = 0; i < n && !rs; i++) {
			for (uint32_t l = 0; l < s->nlights && !rs; l++)
				rs = new_root(sv, i, l | RAD_TAG_LIGHT, &ids);
			for (uint32_t j = 0; j < n && !rs; j++)
				if (i != j)
					rs = new_root(sv, i, j, &ids);
			if (!rs && (st->wave.todo.n >= WAVE_BLOCK_PAIRS ||
			            i + 1 == n)) {
				rs = walk_roots(sv, st, ids.v, ids.n);
				ids.n = 0;
				rad_solver_progress(sv, 0.8 * (i + 1) / n);
			}
		}
	}
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, ids.v);
	return rs;
}

static rad_status next_walk(rad_solver *sv, rmb_state *st)
{
	/* The stored roots, in blocks; the ones kept are re-listed. */
	size_t n = st->nroots;
	uint32_t *old = st->roots;
	st->roots = NULL;
	st->nroots = st->cap_roots = 0;
	rad_status rs = RAD_OK;
	for (size_t b = 0; b < n && !rs; b += WAVE_BLOCK_PAIRS) {
		size_t e = b + WAVE_BLOCK_PAIRS < n ? b + WAVE_BLOCK_PAIRS : n;
		for (size_t i = b; i < e && !rs; i++) {
			const rad_link *l = rad_link_at(&sv->h, old[i]);
			rmb_item it = {l->rcv, l->src, old[i], RAD_NONE, 0};
			rs = push_item(sv, it);
		}
		if (!rs)
			rs = walk_roots(sv, st, old + b, e - b);
	}
	rad_mem_free(&sv->mem, RAD_MEM_LINKS, old);
	return rs;
}

/* ------------------------------------------------- push, update, pull */

typedef struct push_acc {
	double change, total; /* sum A |luma of B's change|, sum A luma B */
	double chg[3];        /* sum A |dB| per channel */
	double shot;          /* sum A |luma dB|: what goes out next */
	const double *q;      /* after the tail jump: its rates, else NULL */
} push_acc;

static void zero_I(rad_hier *h, uint32_t t)
{
	if (node_is_cluster(t)) {
		rad_cluster *c = rad_cluster_at(h, t);
		memset(c->I, 0, sizeof(c->I));
		memset(c->V, 0, sizeof(c->V));
		c->S = 0;
		if (c->child != RAD_NONE) {
			zero_I(h, (c->child) | RAD_TAG_CLUSTER);
			zero_I(h, (c->child + 1) | RAD_TAG_CLUSTER);
		}
		return;
	}
	rad_elem *e = rad_elem_at(h, t);
	memset(e->I, 0, sizeof(e->I));
	if (e->child != RAD_NONE)
		for (uint32_t k = 0; k < 4; k++)
			zero_I(h, e->child + k);
}

/*
 * After a walk: sum the link errors down each quadtree; where the sum
 * passes 1 on an element that can still be split, its largest links
 * are to go to its children next time (the
 * cut only ever decreases, so a receiver once found too coarse does not flip
 * back).
 */
static rad_status mark_cuts(rad_solver *sv, rmb_state *st, uint32_t id,
                            double above)
{
	double mine = id < st->cap_err ? st->err[id] : 0;
	double tot = above + mine;
	rad_elem *e = rad_elem_at(&sv->h, id);
	if (tot > 1 && mine > 0 && rad_elem_can_split(&sv->h, e)) {
		if (cover(sv, RAD_MEM_ELEM_SURFACE, &st->cut, &st->cap_cut, id))
			return RAD_ERR_NOMEM;
		/* The links of half the largest error or more (a quarter of
		 * the sum pushes more of them: measured, leaves even out but
		 * the closed box at rho 0.99 loses 9 % instead of 4 %). */
		float c = 0.5f * st->emax[id];
		if (st->cut[id] == 0 || c < st->cut[id])
			st->cut[id] = c;
	}
	if (e->child == RAD_NONE)
		return RAD_OK;
	for (uint32_t k = 0; k < 4; k++) {
		rad_status rs = mark_cuts(sv, st, e->child + k, tot);
		if (rs)
			return rs;
	}
	return RAD_OK;
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
		P[c] += (double)e->area * e->I[c];
	if (e->child != RAD_NONE)
		for (uint32_t k = 0; k < 4; k++)
			node_power(h, e->child + k, P);
}

static void cluster_power(const rad_hier *h, uint32_t id, double P[3])
{
	const rad_cluster *c = rad_cluster_at(h, id);
	/* A cluster's I is the mean over its area (hier.h): power A I. */
	for (int k = 0; k < 3; k++)
		P[k] += (double)c->area * c->I[k];
	if (c->child != RAD_NONE) {
		cluster_power(h, c->child | RAD_TAG_CLUSTER, P);
		cluster_power(h, (c->child + 1) | RAD_TAG_CLUSTER, P);
	}
}

static void scale_I(rad_hier *h, uint32_t t, const double k[3])
{
	if (node_is_cluster(t)) {
		rad_cluster *c = rad_cluster_at(h, t);
		for (int i = 0; i < 3; i++)
			c->I[i] = (float)(c->I[i] * k[i]);
		if (c->child != RAD_NONE) {
			scale_I(h, c->child | RAD_TAG_CLUSTER, k);
			scale_I(h, (c->child + 1) | RAD_TAG_CLUSTER, k);
		}
		return;
	}
	rad_elem *e = rad_elem_at(h, t);
	for (int i = 0; i < 3; i++)
		e->I[i] = (float)(e->I[i] * k[i]);
	if (e->child != RAD_NONE)
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
	double worst = node_energy_scale(h, 1, got, k);
	if (worst >= 1)
		return 1;
	scale_I(h, RAD_TAG_CLUSTER, k);
	for (uint32_t i = 0; i < np; i++)
		scale_I(h, i, k);
	return worst;
}

/* A leaf's update: dB = rho I, B += dB. */
static void update_leaf(rad_hier *h, rad_elem *e, const float *extra, void *ud)
{
	(void)extra;
	push_acc *acc = ud;
	const rad_material *m = rad_elem_mat(h, e);
	float inc[3];
	for (int c = 0; c < 3; c++) {
		double d = m->rho[c] * e->I[c];
		/* After the jump (tail_jump) B takes what the increment adds
		 * beyond the geometric tail already counted. */
		inc[c] = acc->q ? (float)((d - acc->q[c] * e->dB[c]) /
		                          (1 - acc->q[c]))
		                : (float)d;
		e->dB[c] = (float)d;
		e->B[c] += inc[c];
		acc->chg[c] += e->area * fabs(d);
		/* Leaves report the total irradiance, not the increment
		 * (a black leaf gathers nothing: it keeps the last one). */
		if (m->rho[c] > 0)
			e->I[c] = (e->B[c] - m->emit[c]) / m->rho[c];
	}
	acc->change += e->area * fabs(rad_luma(inc));
	acc->shot += e->area * fabs(rad_luma(e->dB));
	acc->total += e->area * rad_luma(e->B);
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
	if (st->jumped || st->iter < 4 ||
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
	rad_link *l = rad_link_at(&sv->h, id);
	node_count_link(s, l);
	if (l->flags & L_NEW) {
		s->links_created++;
		if (sv->opt.study &&
		    set_has(&st->deleted, pair_key(l->rcv, l->src)))
			s->links_recreated++;
		l->flags &= (uint16_t)~L_NEW;
	}
	if (l->child == RAD_NONE) {
		s->links_active++;
		return;
	}
	s->links_passive++;
	for (uint32_t k = 0; k < l->nchild; k++)
		count_tree(sv, st, l->child + k);
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

static rad_status rmb_init(rad_solver *sv, rad_error *err)
{
	rmb_state *st =
	        rad_mem_calloc(&sv->mem, RAD_MEM_SCRATCH, 1, sizeof(*st));
	if (!st)
		return rad_fail(err, RAD_ERR_NOMEM, "rmb: out of memory");
	sv->impl = st;
	rad_status rs = wave_init(sv, &st->wave, sizeof(rmb_item));
	st->ncl = sv->h.clusters.count;
	st->black = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->ncl, 1);
	st->arefl = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->ncl,
	                           sizeof(float));
	st->rhomax = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->ncl,
	                            sizeof(float));
	if (rs || !st->black || !st->arefl || !st->rhomax)
		return rad_fail(err, RAD_ERR_NOMEM, "rmb: out of memory");
	mark_black(sv, 0);
	/* B = E everywhere, then the initial pull: dB = B on every node. */
	rad_hier_reset_emission(&sv->h);
	for (uint32_t i = 0; i < sv->scene->npolys; i++) {
		rad_elem *e = rad_elem_at(&sv->h, i);
		memcpy(e->dB, e->B, sizeof(e->dB));
	}
	rad_hier_pull(&sv->h);
	return RAD_OK;
}

static void release_scratch(rad_solver *sv, rmb_state *st)
{
	wave_release(sv, &st->wave);
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, st->err);
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, st->emax);
	st->err = st->emax = NULL;
	st->cap_err = st->cap_emax = 0;
}

static rad_status rmb_step(rad_solver *sv, rad_error *err)
{
	rmb_state *st = sv->impl;
	rad_hier *h = &sv->h;
	wave_step_begin(sv, &st->wave);
	zero_I(h, RAD_TAG_CLUSTER);
	for (uint32_t i = 0; i < sv->scene->npolys; i++)
		zero_I(h, i);
	rad_status rs = st->iter == 0 ? first_walk(sv, st) : next_walk(sv, st);
	for (uint32_t i = 0; !rs && i < sv->scene->npolys; i++)
		rs = mark_cuts(sv, st, i, 0);
	release_scratch(sv, st);
	if (rs)
		return wave_failed(sv, rs, err);
	if (st->iter > 0)
		energy_bound(sv);
	rad_solver_progress(sv, 0.9);
	push_acc acc = {0, 0, {0, 0, 0}, 0, st->jumped ? st->q : NULL};
	rad_hier_push(h, update_leaf, NULL, &acc);
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
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->black);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->arefl);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_CLUSTER, st->rhomax);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_SURFACE, st->cut);
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
