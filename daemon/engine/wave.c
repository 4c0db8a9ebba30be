/*
 * wave.c -- the refinement waves of the hierarchical solvers (wave.h),
 * shared by hr (hr_refine.c) and rmb (rmb_refine.c).
 *
 * A wave is a list of items -- pairs (receiver, source), with whatever a
 * solver keeps beside them -- that the refinement judges at once.
 * Judging is the costly part: the oracle on an estimated or stored form
 * factor and, for a pair at its level, the accurate form factor with its
 * shadow rays.  It only reads the hierarchy and writes the item's own
 * verdict slot, so the worker threads share the wave out in chunks, in
 * whatever order they claim them (par.c).  Applying the verdicts is
 * cheap and changes the hierarchy -- links stored or transfers gathered,
 * elements split on demand (rad_elem_split is not thread-safe), children
 * pairs listed for a later wave -- so the calling thread does it alone,
 * in list order.
 *
 * Why the result does not depend on the threads: a verdict is a function
 * of its item and of the hierarchy as the wave found it, never of which
 * thread computed it or of what else that thread ran; and everything
 * that depends on order -- element and link ids taken from the pools, the
 * order of each receiver's links, every floating-point sum -- happens
 * while applying, in the one order of the list.  So for a given thread
 * count every run gives the same result, and the thread count itself only
 * changes who judges what: one thread or many, the result is the same bit
 * for bit.  Rays are counted per thread (no shared counter) and summed at
 * the end of the step.
 *
 * hr runs its waves breadth first: the children of the pairs a wave
 * refused make the next wave.  rmb walks its link trees depth first: its
 * work list is a stack, and a wave is the top chunk of it.  Once the
 * caller cancels, later waves keep every pair at the level reached, so
 * that the links left still make a consistent solution.
 */
#include "wave.h"

#include <string.h>

#include "rad.h"

/* Items judged per chunk of a worker: few, since an item may trace rays
 * and the cost of items varies a lot. */
#define WAVE_GRAIN 16

rad_status wave_init(rad_solver *sv, rad_wave *w, size_t item_size)
{
	memset(w, 0, sizeof(*w));
	w->item_size = (uint32_t)item_size;
	/* Statistics, and the one thing the wave holds per thread: charged
	 * to the budget, they would make its judgement depend on the
	 * threads (16 bytes more for two threads flipped a room check). */
	w->rays = rad_mem_calloc(&sv->mem, RAD_MEM_STUDY,
	                         (size_t)rad_par_threads(sv->par),
	                         sizeof(uint64_t));
	return w->rays ? RAD_OK : RAD_ERR_NOMEM;
}

void wave_destroy(rad_solver *sv, rad_wave *w)
{
	wave_release(sv, w);
	rad_mem_free(&sv->mem, RAD_MEM_STUDY, w->rays);
	w->rays = NULL;
}

void wave_count_rays(rad_solver *sv, rad_wave *w)
{
	int threads = rad_par_threads(sv->par);
	for (int t = 0; t < threads; t++) {
		sv->stats.rays += w->rays[t];
		w->rays[t] = 0;
	}
}

void wave_step_begin(rad_solver *sv, rad_wave *w)
{
	int threads = rad_par_threads(sv->par);
	memset(w->rays, 0, (size_t)threads * sizeof(uint64_t));
	w->force_store = 0;
	w->at_budget = 0;
	w->pending = w->pending_kids = 0;
}

static void list_free(rad_solver *sv, wave_list *l)
{
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, l->v);
	memset(l, 0, sizeof(*l));
}

void wave_release(rad_solver *sv, rad_wave *w)
{
	list_free(sv, &w->todo);
	list_free(sv, &w->held);
	list_free(sv, &w->parents);
	w->parents_next = 0;
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, w->verdict);
	w->verdict = NULL;
	w->verdict_cap = 0;
}

/* Capacity list l grows to for `need` items: doubled, or under a memory
 * budget with no room for that, an eighth more (at least `need`). */
static size_t list_target(const rad_solver *sv, const wave_list *l, size_t need,
                          size_t item)
{
	size_t c = l->cap ? l->cap : 1024;
	while (c < need)
		c *= 2;
	if (sv->mem.budget && !rad_mem_room(&sv->mem, (c - l->cap) * item)) {
		c = l->cap + l->cap / 8;
		if (c < need)
			c = need;
	}
	return c;
}

/* Room in l for `need` items, grown as list_target says (and as
 * list_growth counts). */
static rad_status list_reserve(rad_solver *sv, const rad_wave *w, wave_list *l,
                               size_t need)
{
	if (need <= l->cap)
		return RAD_OK;
	size_t c = list_target(sv, l, need, w->item_size);
	void *p = rad_mem_realloc(&sv->mem, RAD_MEM_SCRATCH, l->v,
	                          c * w->item_size);
	if (!p)
		return RAD_ERR_NOMEM;
	l->v = p;
	l->cap = c;
	return RAD_OK;
}

rad_status wave_push(rad_solver *sv, const rad_wave *w, wave_list *l,
                     const void *item)
{
	if (list_reserve(sv, w, l, l->n + 1))
		return RAD_ERR_NOMEM;
	memcpy((unsigned char *)l->v + l->n * w->item_size, item, w->item_size);
	l->n++;
	return RAD_OK;
}

void wave_list_fit(rad_solver *sv, const rad_wave *w, wave_list *l)
{
	if (l->n == 0 || l->cap - l->n < 4096)
		return;
	void *p = rad_mem_realloc(&sv->mem, RAD_MEM_SCRATCH, l->v,
	                          l->n * w->item_size);
	if (p) {
		l->v = p;
		l->cap = l->n;
	}
}

rad_status wave_take_top(rad_solver *sv, rad_wave *w, size_t n)
{
	if (list_reserve(sv, w, &w->held, n))
		return RAD_ERR_NOMEM;
	w->todo.n -= n;
	memcpy(w->held.v, (unsigned char *)w->todo.v + w->todo.n * w->item_size,
	       n * w->item_size);
	w->held.n = n;
	return RAD_OK;
}

typedef struct judge_job {
	rad_solver *sv;
	rad_wave *w;
	const unsigned char *items;
	wave_judge_fn judge;
} judge_job;

/* Which end of a pair to refine: 1 the receiver, 2 the source, 3 both
 * (a cluster's self-link). */
static int split_side(const rad_hier *h, uint32_t r, uint32_t s, int rcv_only)
{
	if (r == s)
		return 3;
	int rs = node_splittable(h, r), ss = node_splittable(h, s);
	if (rcv_only && rs)
		return 1;
	if (rs && ss)
		return node_size(h, r) >= node_size(h, s) ? 1 : 2;
	return rs ? 1 : 2;
}

/* Bytes an element split takes: four elements, their run's record and
 * hr's list head for the parent (hier.h, Leaves and lists), and the
 * solver's scratch for them. */
static size_t elem_split_bytes(const rad_hier *h, const rad_wave *w)
{
	return sizeof(rad_elem_run) + (h->lists ? sizeof(uint32_t) : 0) +
	       4 * (h->elems.rec_size + w->elem_extra);
}

/* 1 if splitting the pair item starts with makes no element and no link
 * record: rmb (whose children may stay transient) over elements already
 * split.  Items start with (receiver, source), as hr's and rmb's do. */
static int free_split(const rad_solver *sv, const rad_wave *w,
                      const unsigned char *item, int rcv_only)
{
	if (w->link_cost)
		return 0;
	uint32_t rs[2];
	memcpy(rs, item, sizeof(rs));
	const rad_hier *h = &sv->h;
	int side = split_side(h, rs[0], rs[1], rcv_only);
	for (int k = 0; k < 2; k++)
		if ((side & (1 << k)) && !node_is_cluster(rs[k]) &&
		    rad_elem_is_leaf(rad_elem_at(h, rs[k])))
			return 0;
	return 1;
}

static void judge_range(void *ud, size_t b, size_t e, int thread)
{
	const judge_job *j = ud;
	rad_wave *w = j->w;
	int may_split = !w->force_store;
	for (size_t i = b; i < e; i++) {
		wave_verdict *v = &w->verdict[i];
		const unsigned char *item = j->items + i * w->item_size;
		v->ff = v->spread = 0;
		v->held = 0;
		v->action =
		        j->judge(j->sv, item, may_split, v, &w->rays[thread]);
		/* At the budget a pair to split stays at its level, unless
		 * it cannot (a cluster's self-link always opens up) or its
		 * split costs nothing that lasts (rmb, elements there). */
		if (w->at_budget && may_split &&
		    (v->action == WAVE_SPLIT || v->action == WAVE_SPLIT_RCV) &&
		    !free_split(j->sv, w, item, v->action == WAVE_SPLIT_RCV)) {
			v->ff = v->spread = 0;
			v->action =
			        j->judge(j->sv, item, 0, v, &w->rays[thread]);
			v->held = v->action != WAVE_SPLIT;
		}
	}
}

/* Under a budget, blocks whose worst case (wave_room) is at most a
 * 64th of the budget: a small budget is not spent on one block's
 * reserve. */
static size_t budget_block(const rad_solver *sv, const rad_wave *w)
{
	size_t pair = WAVE_KIDS * (2 * (size_t)w->item_size + w->link_cost) +
	              elem_split_bytes(&sv->h, w);
	size_t m = (size_t)sv->mem.budget / 64 / pair;
	return m < 64 ? 64 : m > WAVE_DEFER_BLOCK ? WAVE_DEFER_BLOCK : m;
}

rad_status wave_run(rad_solver *sv, rad_wave *w, const void *items, size_t n,
                    wave_judge_fn judge, wave_apply_fn apply)
{
	/* One block, or blocks of WAVE_DEFER_BLOCK when deferrable or
	 * under a budget: a judge only reads the hierarchy, which apply
	 * does not change in a way it reads (links are stored, pairs
	 * held), so the verdicts and the order they are applied in are
	 * the same either way.  Verdicts are held for one block. */
	size_t block = sv->mem.budget ? budget_block(sv, w)
	               : w->defer     ? WAVE_DEFER_BLOCK
	                              : n;
	size_t held = n < block ? n : block;
	if (held > w->verdict_cap) {
		wave_verdict *v =
		        rad_mem_realloc(&sv->mem, RAD_MEM_SCRATCH, w->verdict,
		                        held * sizeof(*v));
		if (!v)
			return RAD_ERR_NOMEM;
		w->verdict = v;
		w->verdict_cap = held;
	}
	w->judged = 0;
	for (size_t off = 0; off < n; off += block) {
		size_t m = n - off < block ? n - off : block;
		if (!w->at_budget && !wave_room(sv, w, m, n - off - m)) {
			w->at_budget = 1;
			rad_solver_budget_reached(sv);
		}
		judge_job job = {sv, w,
		                 (const unsigned char *)items +
		                         off * w->item_size,
		                 judge};
		rad_par_for(sv->par, m, WAVE_GRAIN, judge_range, &job);
		for (size_t i = 0; i < m; i++) {
			rad_status rs = apply(sv, job.items + i * w->item_size,
			                      &w->verdict[i]);
			if (rs)
				return rs;
			sv->stats.budget_held += w->verdict[i].held;
		}
		w->judged = off + m;
		if (w->judged < n && rad_solver_abandoned(sv)) {
			wave_count_rays(sv, w); /* what the attempt cost */
			return RAD_ERR_CANCELLED;
		}
		if (w->defer && w->judged < n && rad_solver_cancelled(sv))
			return RAD_OK;
	}
	if (rad_solver_cancelled(sv))
		w->force_store = 1; /* finish at the current level */
	return RAD_OK;
}

/*
 * A cluster's few sample points seeing nothing of the other end prove
 * nothing about its contents.  While the pair could carry little even at
 * its bound (box gap), it stays as a zero link that later iterations
 * re-test on that bound; else it is looked at closer now.  Between
 * surfaces the samples cover both ends, and an all-blocked answer has
 * already been re-checked with other points (rad_ff_patch_spread): zero
 * means zero.
 */
uint8_t wave_at_level(const rad_solver *sv, uint32_t r, uint32_t s, double b,
                      double f, double sp, int may_split, wave_verdict *out)
{
	if (!(f > 0) && (node_is_cluster(r) || node_is_cluster(s))) {
		if (may_split &&
		    node_oracle(sv, r, s, b, node_ff_bound(&sv->h, r, s)) >
		            sv->opt.eps)
			return WAVE_SPLIT;
		return WAVE_LEVEL;
	}
	out->ff = (float)f;
	out->spread = (float)sp;
	return f > 0 ? WAVE_LEVEL : WAVE_DROP;
}

int wave_children(rad_hier *h, uint32_t r, uint32_t s, int rcv_only,
                  uint32_t kr[WAVE_KIDS], uint32_t ks[WAVE_KIDS], int *side)
{
	uint32_t cr[RAD_CLUSTER_LEAF_MAX] = {r}, cs[RAD_CLUSTER_LEAF_MAX] = {s};
	int nr = 1, ns = 1, n = 0;
	*side = split_side(h, r, s, rcv_only);
	if (*side & 1)
		nr = node_children(h, r, cr);
	if (*side == 3) {
		ns = nr;
		memcpy(cs, cr, sizeof(cs));
	} else if (*side & 2) {
		ns = node_children(h, s, cs);
	}
	if (nr == 0 || ns == 0)
		return -1;
	for (int a = 0; a < nr; a++) {
		for (int b = 0; b < ns; b++) {
			if (cr[a] == cs[b] && !node_is_cluster(cr[a]))
				continue; /* planar: F = 0 */
			kr[n] = cr[a];
			ks[n] = cs[b];
			n++;
		}
	}
	return n;
}

/* Bytes list l grows by (list_target) to take `extra` more items of
 * `item` bytes; 0 while its capacity holds them. */
static size_t list_growth(const rad_solver *sv, const wave_list *l,
                          size_t extra, size_t item)
{
	if (l->n + extra <= l->cap)
		return 0;
	return (list_target(sv, l, l->n + extra, item) - l->cap) * item;
}

/* wave_room with one more split of `more` bytes and `more_kids` children
 * pairs besides those pending. */
static int room_with(const rad_solver *sv, const rad_wave *w, size_t n,
                     size_t rest, size_t more, size_t more_kids)
{
	if (!sv->mem.budget)
		return 1;
	/* Each of the n pairs to judge may be held and split, at worst
	 * into WAVE_KIDS children pairs (list items, links) with an element
	 * split; each of the rest judged after them may become a link; the
	 * pairs applied already take w->pending (and pending_kids items). */
	size_t item = w->item_size;
	size_t kids = n * WAVE_KIDS + w->pending_kids + more_kids;
	/* Where they are listed a batch at a time (hr), todo holds at most
	 * w->todo_max of them at once. */
	if (w->todo_max && w->todo.n + kids > w->todo_max)
		kids = w->todo_max > w->todo.n ? w->todo_max - w->todo.n : 0;
	size_t bytes =
	        list_growth(sv, &w->todo, kids, item) +
	        list_growth(sv, &w->held, n, item) +
	        n * (WAVE_KIDS * w->link_cost + elem_split_bytes(&sv->h, w)) +
	        rest * w->link_cost + w->pending + more;
	return wave_room_for(sv, w, bytes);
}

int wave_room(const rad_solver *sv, const rad_wave *w, size_t n, size_t rest)
{
	return room_with(sv, w, n, rest, 0, 0);
}

size_t wave_top_fit(const rad_solver *sv, const rad_wave *w, size_t n)
{
	if (!sv->mem.budget)
		return n;
	/* Taking n leaves todo.n - n, and their children may bring it to
	 * todo.n - n + n x WAVE_KIDS. */
	while (n > 1 &&
	       !wave_room_for(sv, w,
	                      list_growth(sv, &w->todo, n * (WAVE_KIDS - 1),
	                                  w->item_size)))
		n /= 2;
	return n;
}

int wave_room_for(const rad_solver *sv, const rad_wave *w, size_t bytes)
{
	if (!sv->mem.budget)
		return 1;
	size_t reserve = w->reserve ? w->reserve(sv) : 0;
	return rad_mem_room(&sv->mem,
	                    rad_hier_grow_blocks(&sv->h) + reserve + bytes);
}

rad_status wave_start_room(rad_solver *sv, const rad_wave *w, rad_error *err)
{
	if (wave_room_for(sv, w, 0))
		return RAD_OK;
	atomic_fetch_add(&sv->mem.budget_refusals, 1);
	return rad_fail(err, RAD_ERR_NOMEM,
	                "%s: no room for a step in the memory budget",
	                sv->ops->name);
}

/* Children of node t a split makes, and whether an element is split. */
static int child_count(const rad_hier *h, uint32_t t, int *splits)
{
	if (node_is_cluster(t)) {
		const rad_cluster *c = rad_cluster_at(h, t);
		return !rad_cluster_is_leaf(c) ? 2 : (int)c->count;
	}
	*splits += rad_elem_is_leaf(rad_elem_at(h, t));
	return 4;
}

/* Bytes that making the children pairs of pair r <- s (as wave_children
 * would: element splits) and storing each at its level takes at most;
 * *kids gets how many children pairs. */
static size_t split_cost(const rad_hier *h, const rad_wave *w, uint32_t r,
                         uint32_t s, int rcv_only, size_t *kids)
{
	int side = split_side(h, r, s, rcv_only), splits = 0;
	int nr = side & 1 ? child_count(h, r, &splits) : 1;
	int ns = side == 3 ? nr : side & 2 ? child_count(h, s, &splits) : 1;
	*kids = (size_t)(nr * ns);
	return *kids * w->link_cost + (size_t)splits * elem_split_bytes(h, w);
}

void wave_pend_split(const rad_hier *h, rad_wave *w, uint32_t r, uint32_t s,
                     int rcv_only, int sign)
{
	size_t kids, b = split_cost(h, w, r, s, rcv_only, &kids);
	if (sign > 0) {
		w->pending += b;
		w->pending_kids += kids;
		return;
	}
	w->pending = w->pending > b ? w->pending - b : 0;
	w->pending_kids = w->pending_kids > kids ? w->pending_kids - kids : 0;
}

int wave_room_split(const rad_solver *sv, const rad_wave *w, uint32_t r,
                    uint32_t s, int rcv_only)
{
	size_t kids;
	size_t b = split_cost(&sv->h, w, r, s, rcv_only, &kids);
	return room_with(sv, w, 1, 0, b, kids);
}

/* The links held, packed ones included (hr: hier.h, Packed lists). */
static uint32_t wave_links(const rad_hier *h)
{
	return h->lists ? rad_hlist_count(h) : rad_pool_live(&h->links);
}

rad_status wave_failed(const rad_solver *sv, rad_status rs, rad_error *err)
{
	if (sv->mem.budget && atomic_load(&sv->mem.budget_refusals))
		return rad_fail(err, rs,
		                "%s: the memory budget (%g MiB) is too small "
		                "for this scene's coarsest links (%u elements, "
		                "%u links held)",
		                sv->ops->name,
		                (double)sv->mem.budget / 1048576.0,
		                rad_hier_elements(&sv->h), wave_links(&sv->h));
	return rad_fail(err, rs,
	                "%s: refinement ran out of memory (%u elements, %u "
	                "links)",
	                sv->ops->name, rad_hier_elements(&sv->h),
	                wave_links(&sv->h));
}

rad_status wave_step_end(rad_solver *sv, rad_wave *w, rad_error *err)
{
	sv->stats.budget_reached = w->at_budget;
	wave_count_rays(sv, w);
	rad_solver_progress(sv, 1.0);
	if (w->force_store)
		return rad_fail(err, RAD_ERR_CANCELLED,
		                "cancelled during refinement; the solution "
		                "is consistent at the level reached");
	return RAD_OK;
}
