/*
 * wave.h -- the refinement waves of the hierarchical solvers (hr, rmb):
 * judging a list of pairs on the worker threads, applying the verdicts in
 * order on the calling thread.  wave.c says what a wave is and why its
 * result does not depend on the threads.
 */
#ifndef LUXRAD_WAVE_H
#define LUXRAD_WAVE_H

#include "hr_nodes.h"

/* What judging a pair decided. */
enum {
	WAVE_DROP = 0,  /* it carries nothing */
	WAVE_LEVEL,     /* it carries its transfer at this level (ff) */
	WAVE_SPLIT,     /* refine the larger end that can be split */
	WAVE_SPLIT_RCV, /* refine the receiver: the transfer varies over it */
};

typedef struct wave_verdict {
	float ff, spread; /* WAVE_LEVEL: form factor, spread (else zero) */
	uint8_t action;   /* WAVE_* */
	uint8_t held;     /* 1: at its level because of the memory budget */
} wave_verdict;

/* A growable array of a solver's items (its pairs), SCRATCH; the size of
 * an item is the wave's. */
typedef struct wave_list {
	void *v;
	size_t n, cap;
} wave_list;

typedef struct rad_wave {
	wave_list todo;        /* items waiting to be judged */
	wave_list held;        /* hr: the pairs a wave refused, to split next;
	                          rmb: the wave taken off the top of todo */
	wave_list parents;     /* hr: the pairs the last round held, whose
	                          children are being judged (hr_refine.c) */
	size_t parents_next;   /* the first of them not expanded yet */
	wave_verdict *verdict; /* one per item of the wave run, SCRATCH */
	size_t verdict_cap;
	uint64_t *rays;     /* per-thread ray counters, STUDY */
	uint32_t item_size; /* bytes per item */
	int force_store;    /* cancelled: pairs stay at the level reached */
	int at_budget;      /* the memory budget is reached: pairs stay at
	                       their level (wave_room) */
	/* Bytes the solver will still allocate besides its pools and the
	 * wave's lists, for the elements there are now (scratch its walk
	 * or gather grows): set by the solver, asked at each look at the
	 * budget. */
	size_t (*reserve)(const rad_solver *sv);
	size_t pending;      /* bytes the items applied so far will still
	                        take (hr: children of the pairs held) */
	size_t pending_kids; /* and the children pairs they will list */
	size_t todo_max;     /* hr: todo never holds more (its children are
	                        listed a batch at a time); 0: no bound */
	size_t link_cost;    /* bytes a pair at its level takes: hr a link;
	                        rmb nothing, its records being optional */
	size_t elem_extra;   /* the solver's scratch per element made (what
	                        w->reserve asks for each one a split makes) */
	int defer;     /* set by the caller: a cancel within a wave stops it
	                  after the block under way (WAVE_DEFER_BLOCK), the
	                  items not judged left for the caller to keep */
	size_t judged; /* wave_run: items judged and applied (all of them
	                  unless deferred) */
} rad_wave;

/* Items judged between two looks at the cancel flag in a deferrable
 * wave: a few milliseconds of form factors. */
#define WAVE_DEFER_BLOCK 2048

/*
 * Judge one item, on a worker thread: only read the hierarchy, write out
 * (zeroed before the call) and count rays into *rays; return WAVE_*.
 * may_split is 0 once the refinement was cancelled.
 */
typedef uint8_t (*wave_judge_fn)(rad_solver *sv, const void *item,
                                 int may_split, wave_verdict *out,
                                 uint64_t *rays);
/* Apply an item's verdict, on the calling thread, in list order. */
typedef rad_status (*wave_apply_fn)(rad_solver *sv, const void *item,
                                    const wave_verdict *v);

/* Items handed to the waves at once (polygon pairs without clustering,
 * rmb's stored roots), so that their lists stay bounded. */
#define WAVE_BLOCK_PAIRS (1u << 20)
/* Without clustering, the first step links every pair of polygons in
 * blocks of this many pairs and looks at the cancel flag after each, so
 * that a cancel, pause, time budget or shutdown is seen within one
 * block's form factors (hr_initial_links, rmb's first walk). */
#define WAVE_INIT_BLOCK_PAIRS (1u << 14)

/* Set up w for items of item_size bytes; RAD_ERR_NOMEM on failure. */
rad_status wave_init(rad_solver *sv, rad_wave *w, size_t item_size);
/* Free everything w holds. */
void wave_destroy(rad_solver *sv, rad_wave *w);
/* At the start of a step: ray counters zero, refining allowed. */
void wave_step_begin(rad_solver *sv, rad_wave *w);
/* Free the lists and verdicts once a step's refinement is done. */
void wave_release(rad_solver *sv, rad_wave *w);

/* Append a copy of item to l (w->todo or w->held). */
rad_status wave_push(rad_solver *sv, const rad_wave *w, wave_list *l,
                     const void *item);
/* Give back what l holds beyond its items, once that is more than a
 * few thousand (its doubling left it up to half empty); l stays as it
 * is if the allocator cannot. */
void wave_list_fit(rad_solver *sv, const rad_wave *w, wave_list *l);
/* Move the top n items of todo (the last pushed) to held, in order: a
 * wave of a work list used as a stack. */
rad_status wave_take_top(rad_solver *sv, rad_wave *w, size_t n);

/*
 * Run one wave: judge items[0 .. n) in parallel, then apply the verdicts
 * in order (stopping at the first failure); once the caller has
 * cancelled, later waves keep their pairs at their level.  Under a memory
 * budget the wave runs in blocks of WAVE_DEFER_BLOCK, and once a block
 * might not fit (wave_room) it and every later one keep their pairs at
 * their level (w->at_budget).
 */
rad_status wave_run(rad_solver *sv, rad_wave *w, const void *items, size_t n,
                    wave_judge_fn judge, wave_apply_fn apply);

/* 1 if either end of the pair can be split. */
static inline int wave_refinable(const rad_hier *h, uint32_t r, uint32_t s)
{
	return node_splittable(h, r) || node_splittable(h, s);
}

/*
 * The verdict on a pair at its level whose form factor f (spread sp) was
 * just computed from sample points, for a source of photopic radiosity b
 * (as the oracle takes it); fills out when the pair carries light.
 */
uint8_t wave_at_level(const rad_solver *sv, uint32_t r, uint32_t s, double b,
                      double f, double sp, int may_split, wave_verdict *out);

/*
 * The children pairs of a pair to refine, into kr[k] <- ks[k]: its larger
 * end that can be split is split (the receiver when rcv_only and it can;
 * both ends of a cluster's self-link), and an element paired with itself
 * is left out (planar: F = 0).  Elements are split on demand: the applying
 * thread only. Returns how many, or -1 when out of memory; *side says which end
 * was split (1 the receiver, 2 the source, 3 both).
 */
#define WAVE_KIDS (RAD_CLUSTER_LEAF_MAX * RAD_CLUSTER_LEAF_MAX)
int wave_children(rad_hier *h, uint32_t r, uint32_t s, int rcv_only,
                  uint32_t kr[WAVE_KIDS], uint32_t ks[WAVE_KIDS], int *side);

/*
 * 1 if refining n more items (each split, at worst, into WAVE_KIDS
 * children pairs: list items, new elements and links), then storing the
 * `rest` of the wave as links, still fits (wave_room_for).  When it is 0 the
 * wave keeps its pairs at their level: w->at_budget, counted in
 * stats.budget_held.
 */
int wave_room(const rad_solver *sv, const rad_wave *w, size_t n, size_t rest);
/* Under a memory budget, the largest of n, n/2, n/4 ... 1 items a wave
 * may take off the top of todo so that the children they may push
 * still fit (wave_room_for): the work list of a depth-first walk stays
 * within the budget however deep the walk goes.  n without a budget. */
size_t wave_top_fit(const rad_solver *sv, const rad_wave *w, size_t n);
/* 1 if `bytes` more still leave a block for each pool and w->reserve's
 * bytes free under the solver's memory budget (always 1 without one). */
int wave_room_for(const rad_solver *sv, const rad_wave *w, size_t bytes);
/* RAD_OK if the budget has room for a first step (as wave_room_for
 * says, w->reserve set); else refuse the solver, counted as the budget's
 * refusal so that rad_solver_new names the budget. */
rad_status wave_start_room(rad_solver *sv, const rad_wave *w, rad_error *err);
/* Count in w->pending (and pending_kids) what splitting pair r <- s will
 * take at most once its children are made (as wave_children would:
 * element splits, a link for each child); sign -1 takes it off again,
 * never below zero, as the pair's children are made. */
void wave_pend_split(const rad_hier *h, rad_wave *w, uint32_t r, uint32_t s,
                     int rcv_only, int sign);
/* 1 if that split, with one more pair split at worst, still fits beside
 * what is pending (wave_room). */
int wave_room_split(const rad_solver *sv, const rad_wave *w, uint32_t r,
                    uint32_t s, int rcv_only);

/* Add the rays the judges traced to the step's, and zero them: at the
 * step's end (wave_step_end), or where an attempt the solve starts over
 * from stops (solver.c, Budget restarts). */
void wave_count_rays(rad_solver *sv, rad_wave *w);

/* A refinement's failure (out of memory), reported with the pool sizes. */
rad_status wave_failed(const rad_solver *sv, rad_status rs, rad_error *err);
/*
 * End of a step: add the threads' ray counts to the stats, report full
 * progress, and RAD_ERR_CANCELLED when refinement was cut short.
 */
rad_status wave_step_end(rad_solver *sv, rad_wave *w, rad_error *err);

#endif
