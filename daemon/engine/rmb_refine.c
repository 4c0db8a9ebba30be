/*
 * rmb_refine.c -- RefineAndGather over the reduced-memory solver's link
 * hierarchy (rmb.c; docs/ALGORITHM.md §5): each iteration walks the link
 * trees, gathers every transfer at its level, refines what the oracle
 * refuses, and settles which links to keep.
 *
 * DESIGN
 * The link hierarchy.  A link that was refined stays in memory as a
 * passive link whose children -- the links its refinement made -- are one
 * run of consecutive records (its rad_link_ext: child, nchild, and which
 * end was split; hier.h).  Active links are the leaves of these trees; the
 * roots are listed in st->roots (with clustering: the root cluster's
 * self-link). Receivers keep no link lists: the walk over the link trees is the
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
 * Keeping (the creation criterion, docs/ALGORITHM.md §5.4): a link is
 * kept when its source and its receiver both reflect (RAD_STORE_MINIMAL,
 * the report's rule).  RAD_STORE_ANTICIPATE also refuses to keep the
 * children of a link whose next increment -- this one times the source's
 * largest reflectance -- will pass the oracle at the link's own level
 * (coarse_next()): they are used now and dropped, and the link stays
 * active with their recursive form factor.
 * A passive link with at least one child kept keeps its run (compacted
 * in place to the kept children); one with none becomes active again.  A
 * passive link found at its level deletes its whole subtree
 * (docs/ALGORITHM.md §5.2).
 *
 * Recursive form factors (docs/ALGORITHM.md §5.5): every passive link's
 * form factor is rebuilt from its children after each walk, F = sum of
 * w_c F_c (child_weight()), which is exact for uniform radiosity over the
 * reflecting polygons and, for a cluster's self-link, gives the true
 * self-transfer (zero for convex contents) instead of the isotropic guess.
 */
#include <math.h>
#include <string.h>

#include "rmb.h"

/* ------------------------------------------------------------- helpers */

/* Push an item on the work list. */
static rad_status push_item(rad_solver *sv, rmb_item it)
{
	rmb_state *st = sv->impl;
	return wave_push(sv, &st->wave, &st->wave.todo, &it);
}

/*
 * Weight of child link c in its parent p's recursive form factor
 * (docs/ALGORITHM.md §5.5: F_p = sum of weight x F_c).  After the first
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
		double a = rmb_node_arefl(sv, p->rcv);
		w *= a > 0 ? rmb_node_arefl(sv, c->rcv) / a : 0;
	}
	if (c->src != p->src) {
		double fp = rmb_node_arefl(sv, p->src) / node_area(h, p->src);
		double fc = rmb_node_arefl(sv, c->src) / node_area(h, c->src);
		w *= fp > 0 ? fc / fp : 0;
	}
	return w;
}

/* Radiosity the node still has to transmit (a light: first iteration). */
static void node_dB(const rad_solver *sv, uint32_t t, double out[3])
{
	const rmb_state *st = sv->impl;
	float d[3];
	if (node_is_light(t)) {
		for (int c = 0; c < 3; c++)
			out[c] = st->iter == 0
			                 ? sv->scene->lights[node_index(t)]
			                           .intensity[c]
			                 : 0;
		return;
	}
	if (node_is_cluster(t)) {
		float m[3];
		rad_cluster_delta(&sv->h, rad_cluster_at(&sv->h, t), m, NULL);
		for (int c = 0; c < 3; c++)
			out[c] = m[c];
		return;
	}
	rad_elem_dB(&sv->h, rad_elem_at(&sv->h, t), d);
	for (int c = 0; c < 3; c++)
		out[c] = d[c];
	/* The first iteration sends the emission (dB = B = E). */
	if (st->iter == 0)
		node_exposed_emission(&sv->h, t, out);
}

/* Increments are signed only by rounding: judge their magnitude. */
static double node_luma_dB(const rad_solver *sv, uint32_t t)
{
	double d[3];
	node_dB(sv, t, d);
	return fabs(rad_luma3(d));
}

/*
 * Receiver accuracy, as in hr_refine.c: a leaf receives every link of its
 * ancestors, each averaged over a larger region, and near corners their
 * errors add up (and, reflected many times at high reflectance, make the
 * solution drift: measured +8 % in a closed box at rho 0.9).  A link's
 * error is half its spread times the source's dB, as a fraction of
 * rmb_spread_limit.  A link over 1 goes to the receiver's children; so does
 * one over the receiver's cut, which mark_cuts() sets where the errors
 * summed down a quadtree passed 1 in an earlier iteration.
 */
static double link_err(const rad_solver *sv, double b, double spread)
{
	double lim = rmb_spread_limit(sv);
	return lim > 0 ? 0.5 * b * spread / lim : 0;
}

static int rcv_too_coarse(const rad_solver *sv, uint32_t r, double e)
{
	const rmb_state *st = sv->impl;
	if (e > 1)
		return 1;
	if (node_is_cluster(r) || node_is_light(r))
		return 0;
	const float *cut = rmb_acc_get(&st->cut, r);
	return cut && cut[0] > 0 && e >= cut[0];
}

/* ------------------------------------------------------------- judging */

/*
 * 1 if pair r <- s is to be refined: its oracle (node_oracle) passes eps,
 * counted RMB_NEAR times where one end is a cluster and the pair is near
 * (node_near, the link audit's "near" classes).
 * Such a pair's form factor is read from the kernel at a few polygon
 * centroids (ff_iso, node_ff_estimate), which the audit finds low by a
 * quarter to a half.  rmb's oracle reads dB, which shrinks at every
 * bounce, so rmb leaves more of the later bounces' transfer at those
 * coarse levels than hr, whose oracle reads B: at the defaults the
 * hospital room passed on 0.47 of each bounce under rmb against 0.55
 * under hr (the same direct light, then sum A dB 8,248 -> 3,868 where
 * hr's increments of sum A B went 8,249 -> 4,550), and its points read
 * 14 % low on average where hr's read 5 %.  Counted as carrying
 * RMB_NEAR times its estimate (the factor node_oracle gives a cluster
 * end), such a pair is refined until that little is left.  Measured
 * with luxrad-solve at the defaults, 2 threads, mean error against
 * luxrad-reference: the hospital room 14.3 -> 10.2 % (+8 % links, +5 %
 * memory), the Graz office 6.3 -> 4.8 % (+28 % memory, 1.5-1.8x the
 * time); a factor of 8 gave 7.9 % and 4.3 % for 1.1x and 1.6x the
 * memory.  Only the split test counts it: anticipation (coarse_next)
 * counting it too gave the same errors and 1.14x the Graz office's
 * memory.  hr is left as it is: refining every such pair under hr
 * moved its Graz office from 2.8 % to 4.1 % (README, Limitations).
 */
#define RMB_NEAR 4.0
static int rmb_refines(const rad_solver *sv, uint32_t r, uint32_t s, double b,
                       double f)
{
	double o = node_oracle(sv, r, s, b, f);
	if (o > sv->opt.eps)
		return 1;
	/* The centres (an element's patch) only where the factor decides. */
	if (!(RMB_NEAR * o > sv->opt.eps) || node_is_light(s) ||
	    (!node_is_cluster(r) && !node_is_cluster(s)))
		return 0;
	return node_near(&sv->h, r, s);
}

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
	int fresh = !l || rmb_fresh(sv->impl, it->link);
	int passive = l && !fresh && rad_link_passive(l);
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
	if (rmb_node_black(sv, r) || !node_facing(h, r, s))
		return WAVE_DROP;
	double f = !fresh ? (l->ff > 0 ? l->ff : node_ff_bound(h, r, s))
	                  : node_ff_estimate(h, r, s);
	if (may_split && wave_refinable(h, r, s) && rmb_refines(sv, r, s, b, f))
		return WAVE_SPLIT;
	int rcv_split = may_split && node_splittable(h, r);
	if (!fresh) {
		float spread = rad_link_spread(h, l);
		if (rcv_split && rcv_too_coarse(sv, r, link_err(sv, b, spread)))
			return WAVE_SPLIT_RCV;
		out->ff = l->ff;
		out->spread = spread;
		return WAVE_LEVEL;
	}
	/* A pair that cannot be kept and carries nothing needs no rays. */
	if (b == 0 && (rmb_node_black(sv, s) || !l))
		return WAVE_LEVEL;
	double sp = 0;
	f = node_ff(sv, r, s, rays, &sp);
	if (rcv_split && rcv_too_coarse(sv, r, link_err(sv, b, sp)))
		return WAVE_SPLIT_RCV;
	return wave_at_level(sv, r, s, b, f, sp, may_split, out);
}

/* ------------------------------------------------------------ applying */

/* Add a link's error e to receiver r's sums (mark_cuts reads them),
 * unless r is a leaf that cannot be split: its sum would have no
 * children to go down to and no cut to make (rmb.h, rmb_acc).  Under a
 * memory budget that refuses the map's growth, r's error goes
 * untracked this step (the receiver is not cut for it): the walk goes
 * on. */
static rad_status track_err(rad_solver *sv, rmb_state *st, uint32_t r, double e)
{
	const rad_hier *h = &sv->h;
	if (rad_elem_is_leaf(rad_elem_at(h, r)) && !rad_elem_can_split(h, r))
		return RAD_OK;
	float *v = rmb_acc_put(sv, &st->err, r);
	if (!v)
		return sv->mem.budget ? RAD_OK : RAD_ERR_NOMEM;
	v[0] += (float)e;
	if (e > v[1])
		v[1] = (float)e;
	return RAD_OK;
}

/* The transfer of an item at its level: I(rcv) += F dB(src). */
static rad_status gather(rad_solver *sv, uint32_t r, uint32_t s, double ff,
                         double spread, int transient)
{
	rmb_state *st = sv->impl;
	double d[3];
	double fe = ff * node_sends(&sv->h, r, s, 1, d);
	if (!node_is_cluster(s))
		node_dB(sv, s, d);
	rad_cluster_flux *f =
	        node_is_cluster(r) ? &sv->h.flux[r & ~RAD_TAG_MASK] : NULL;
	float *I = f ? f->I : rad_elem_at(&sv->h, r)->I;
	for (int c = 0; c < 3; c++)
		I[c] += (float)(fe * d[c]);
	node_took(&sv->h, f, r, s, fe * rad_luma3(d));
	double b = fabs(rad_luma3(d));
	if (!node_is_cluster(r)) {
		rad_status rs = track_err(sv, st, r, link_err(sv, b, spread));
		if (rs)
			return rs;
	}
	node_stat_exchange(sv, &sv->stats, r, s, ff, b, b);
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
	double b = node_luma_dB(sv, s) * rmb_node_rho_max(sv, s);
	return node_oracle(sv, r, s, b, f) <= sv->opt.eps;
}

/* Refine an item: its children go to the next wave. */
static rad_status split_item(rad_solver *sv, const rmb_item *it, int rcv_only)
{
	rad_hier *h = &sv->h;
	rmb_state *st = sv->impl;
	rad_link *l = it->link != RAD_NONE ? rad_link_at(h, it->link) : NULL;
	int fresh = l && rmb_fresh(st, it->link);
	if (l && !fresh && rad_link_passive(l)) {
		/* A passive link: walk the children it has. */
		uint32_t nc, child = rad_link_child(h, l, &nc);
		for (uint32_t k = 0; k < nc; k++) {
			const rad_link *c = rad_link_at(h, child + k);
			rmb_item ci = {c->rcv, c->src, child + k, RAD_NONE, 0};
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
		if (rmb_node_black(sv, kr[k]))
			continue; /* reflects nothing: no transfer to make */
		if (kr[k] != ks[k] && !node_facing(h, kr[k], ks[k]))
			continue; /* no record for what cannot carry */
		rmb_item c = {kr[k], ks[k], RAD_NONE, RAD_NONE, 0};
		kid[n++] = c;
	}
	if (n == 0) {
		if (l) /* nothing below: carries nothing */
			rmb_set_bit(st->dead, it->link, 1);
		return RAD_OK;
	}
	int keepable = l && !rmb_node_black(sv, it->src);
	if (keepable &&
	    coarse_next(sv, it->rcv, it->src,
	                fresh ? node_ff_estimate(h, it->rcv, it->src) : l->ff))
		keepable = 0;
	/* The link cache (Budget): children the budget has no room to
	 * keep are walked as transient pairs, made again when needed. */
	if (keepable && !wave_room_for(sv, &st->wave,
	                               (size_t)n * sizeof(rad_link) +
	                                       sizeof(rad_link_ext))) {
		keepable = 0;
		sv->stats.budget_transient += (uint64_t)n;
	}
	if (keepable) {
		uint32_t run = rad_pool_add(&h->links, (uint32_t)n);
		if (run == RAD_NONE)
			return RAD_ERR_NOMEM;
		if (rmb_cover_links(sv, st) ||
		    rad_link_make_passive(h, it->link, run, (uint32_t)n,
		                          side == 2)) {
			rad_pool_release_run(&h->links, run, (uint32_t)n);
			return RAD_ERR_NOMEM;
		}
		rmb_made_links(st, run, (uint32_t)n);
		for (int k = 0; k < n; k++) {
			rad_link *c = rad_link_at(h, run + (uint32_t)k);
			c->rcv = kid[k].rcv;
			c->src = kid[k].src;
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
	uint32_t n, child = rad_link_child(h, l, &n);
	if (n == 0)
		return;
	for (uint32_t k = 0; k < n; k++) {
		free_children(sv, st, child + k, rs);
		rmb_count_deleted(sv, child + k, rs);
	}
	rad_pool_release_run(&h->links, child, n);
	rad_link_make_active(h, id);
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
			rmb_set_bit(st->dead, it->link, 1);
		break;
	case WAVE_LEVEL:
		rs = gather(sv, it->rcv, it->src, v->ff, v->spread, l == NULL);
		if (l && rmb_fresh(st, it->link)) {
			l->ff = v->ff;
			rad_link_set_spread(h, l, v->spread);
		} else if (l && rad_link_passive(l)) {
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
		size_t n = wave_top_fit(
		        sv, w, w->todo.n < RMB_CHUNK ? w->todo.n : RMB_CHUNK);
		rad_status rs = wave_take_top(sv, w, n);
		if (!rs)
			rs = wave_run(sv, w, w->held.v, n, judge, apply);
		if (rs)
			return rs;
	}
	return RAD_OK;
}

/* ----------------------------------------------------------- post-order */

/* May childless link id be kept (the creation criterion)? */
static int storable(const rad_solver *sv, const rmb_state *st, uint32_t id)
{
	const rad_link *l = rad_link_at(&sv->h, id);
	if (rmb_bit(st->dead, id))
		return 0;
	if (node_is_light(l->src) || rmb_node_black(sv, l->src) ||
	    rmb_node_black(sv, l->rcv))
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
	if (rad_link_passive(l) && rmb_bit(st->dead, id))
		free_children(sv, st, id, rs);
	uint32_t n, run = rad_link_child(h, rad_link_at(h, id), &n);
	if (n > 0) {
		uint32_t kept = 0;
		uint8_t keep[WAVE_KIDS];
		double f = 0, lo = INFINITY, hi = -INFINITY, sum_sp = 0;
		for (uint32_t k = 0; k < n; k++) {
			keep[k] = (uint8_t)post(sv, st, run + k, rs);
			kept += keep[k];
			l = rad_link_at(h, id);
			const rad_link *c = rad_link_at(h, run + k);
			double sp = rad_link_spread(h, c);
			f += child_weight(sv, l, c) * c->ff;
			lo = fmin(lo, c->ff - 0.5 * sp);
			hi = fmax(hi, c->ff + 0.5 * sp);
			sum_sp += sp;
		}
		rad_link_ext *x = rad_link_ext_of(h, l);
		l->ff = (float)f;
		if (node_is_cluster(l->rcv))
			x->spread = 0;
		else if (x->split_src)
			x->spread = (float)sum_sp;
		else
			x->spread = (float)(hi - lo);
		if (kept == 0) {
			/* The children were counted (and their subtrees
			 * freed) by their own post(). */
			rad_pool_release_run(&h->links, run, n);
			rad_link_make_active(h, id);
		} else if (kept < n) {
			/* Compact the run to its kept links, their bits
			 * with them. */
			uint32_t to = run;
			for (uint32_t k = 0; k < n; k++) {
				if (!keep[k])
					continue;
				if (run + k != to) {
					memcpy(rad_link_at(h, to),
					       rad_link_at(h, run + k),
					       sizeof(rad_link));
					rmb_set_bit(st->fresh, to,
					            rmb_fresh(st, run + k));
					rmb_set_bit(st->dead, to,
					            rmb_bit(st->dead, run + k));
				}
				to++;
			}
			rad_pool_release_run(&h->links, to, n - kept);
			x->nchild = (uint16_t)kept;
		}
		if (kept) {
			rmb_set_bit(st->dead, id, 0);
			return 1;
		}
	}
	/* Fresh links stay fresh: count_tree() counts them. */
	int keep = storable(sv, st, id);
	if (!keep)
		rmb_count_deleted(sv, id, rs);
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
	if (rmb_node_black(sv, r) && r != s)
		return RAD_OK;
	if (!rmb_node_black(sv, s)) {
		uint32_t *v =
		        rad_mem_grow(&sv->mem, RAD_MEM_SCRATCH, ids->v,
		                     &ids->cap, ids->n + 1, sizeof(*v), 64);
		if (!v)
			return RAD_ERR_NOMEM;
		ids->v = v;
		it.link = rad_link_new(&sv->h, r, s, 0, 0);
		if (it.link == RAD_NONE)
			return RAD_ERR_NOMEM;
		if (rmb_cover_links(sv, sv->impl)) {
			rad_pool_release(&sv->h.links, it.link);
			return RAD_ERR_NOMEM;
		}
		rmb_made_links(sv->impl, it.link, 1);
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
		/* Every pair of polygons, in blocks of rows.  The cancel flag
		 * is looked at after each block: the rows gathered so far
		 * stay gathered (I, err, emax and the roots kept), and the
		 * next step goes on from st->init_row (rmb_step). */
		uint32_t n = s->npolys;
		for (uint32_t i = st->init_row; i < n && !rs; i++) {
			for (uint32_t l = 0; l < s->nlights && !rs; l++)
				rs = new_root(sv, i, l | RAD_TAG_LIGHT, &ids);
			for (uint32_t j = 0; j < n && !rs; j++)
				if (i != j)
					rs = new_root(sv, i, j, &ids);
			if (!rs && (st->wave.todo.n >= WAVE_INIT_BLOCK_PAIRS ||
			            i + 1 == n)) {
				rs = walk_roots(sv, st, ids.v, ids.n);
				ids.n = 0;
				st->init_row = i + 1;
				rad_solver_progress(sv, 0.8 * (i + 1) / n);
				if (!rs && i + 1 < n &&
				    rad_solver_cancelled(sv))
					rs = RAD_ERR_CANCELLED;
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

/* ------------------------------------------------ receiver accuracy */

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
	const float *err = rmb_acc_get(&st->err, id);
	double mine = err ? err[0] : 0;
	double tot = above + mine;
	if (tot > 1 && mine > 0 && rad_elem_can_split(&sv->h, id)) {
		/* The links of half the largest error or more (a quarter of
		 * the sum pushes more of them: measured, leaves even out but
		 * the closed box at rho 0.99 loses 9 % instead of 4 %). */
		float c = 0.5f * err[1];
		float *cut = rmb_acc_put(sv, &st->cut, id);
		if (!cut && !sv->mem.budget)
			return RAD_ERR_NOMEM;
		if (cut && (cut[0] == 0 || c < cut[0]))
			cut[0] = c; /* a budget that refuses it: no cut */
	}
	const rad_elem *e = rad_elem_at(&sv->h, id);
	if (rad_elem_is_leaf(e))
		return RAD_OK;
	for (uint32_t k = 0; k < 4; k++) {
		rad_status rs = mark_cuts(sv, st, e->child + k, tot);
		if (rs)
			return rs;
	}
	return RAD_OK;
}

rad_status rmb_refine_gather(rad_solver *sv, rmb_state *st)
{
	rad_status rs = st->iter == 0 ? first_walk(sv, st) : next_walk(sv, st);
	if (rs == RAD_ERR_CANCELLED)
		return rs; /* a first walk cut between rows: not finished */
	for (uint32_t i = 0; !rs && i < sv->scene->npolys; i++)
		rs = mark_cuts(sv, st, i, 0);
	return rs;
}
