/*
 * hr.h -- what the classic hierarchical radiosity solver's two files
 * share: hr.c runs the iterations (gather, push, update, pull), and
 * hr_refine.c makes and re-tests the links they gather over.
 */
#ifndef LUXRAD_HR_H
#define LUXRAD_HR_H

#include "wave.h"

typedef struct hr_pair {
	uint32_t rcv, src;
	uint32_t rcv_only; /* split the receiver, not the larger end */
} hr_pair;

typedef struct hr_state {
	rad_wave wave;     /* items: hr_pair */
	int started;       /* initial links made */
	uint32_t init_row; /* without clustering: rows of polygon pairs linked
	                      so far (hr_initial_links goes on from there) */
	double mean_B;     /* area-mean photopic radiosity of the last step */
	double last_r;     /* residual of the last step */
	int frozen;        /* refinement stopped (hr_step) */
	int pending;       /* a cancelled re-test left pairs (hr_refine_left) */
	int clip;          /* leaves' gain held below 1 (node_extra) */
	double chg[3][3];  /* sum A |dB| per channel, last three steps */
	double q_jump;     /* rate of the last extrapolation (tail) */
	int since;         /* steps since it (or since the start) */
	double *vals;      /* scratch for budget_cut */
	size_t vals_cap;
	uint32_t batch; /* children pairs listed at a time (hr_init) */
	/* One per thread: the statistics' walks (hr.c, tally_walk).  STUDY,
	 * which a memory budget leaves out: their size depends on the
	 * threads, and the budget's judgement must not. */
	rad_stats *tally;
	/* While study_node counts: rad_luma of each inner cluster's dB
	 * (rad_hier_delta_lumas), STUDY too; else NULL. */
	double *dluma;
} hr_state;

/* Children pairs listed at a time by the waves (hr_refine.c), at most.
 * A batch and its verdicts are held while it is judged: 2^15 made the
 * grand hall's hr peak (4 iterations) 55.07 MB where 2^13 makes it 54.48,
 * the same JSON, and whole runs 0.96-1.02x the time (alternated, median
 * of 3 pairs, the real rooms and the large scenes). */
#define HR_BATCH_PAIRS (1u << 13)
/* Under a memory budget, the pairs a batch takes at most a 64th of it
 * (hr_init), and never fewer than this. */
#define HR_BATCH_MIN 256u
/* The first step's links (hr_refine.c): the root cluster's self-link and
 * the lights', refined; without clustering, every pair of polygons. */
rad_status hr_initial_links(rad_solver *sv, hr_state *st);
/*
 * Later steps: re-test every stored link, refine those that fail (the
 * clustered first step's waves defer the same way).  A
 * cancel stops the re-test where it is and the waves within a few
 * thousand pairs: RAD_ERR_CANCELLED with the pairs not judged yet kept in
 * st->wave (todo, and the pairs to split: parents, held), which
 * hr_refine_pending judges at the next step.
 */
rad_status hr_retest_links(rad_solver *sv, hr_state *st);
rad_status hr_refine_pending(rad_solver *sv, hr_state *st);
/* 1 if a cancelled refinement left pairs to judge or split. */
int hr_refine_left(const hr_state *st);
/*
 * Pack the lists (hier.h, Packed lists): once a step's refinement is
 * over and its scratch released (done: if any link is new or dead), or
 * while it makes links, once those made since the last packing pass a
 * quarter of those packed and an eighth of the nodes (at least 2^16).
 * A packing walks every node, twice where it drops the dead links: when
 * done, or once they are an eighth of those packed.  One refused (the
 * budget) leaves the lists as they are, and the next one tries again.
 * The eighth of the nodes spares the large scenes' first steps walks
 * without moving the peaks (grand hall 51.6 MB, 1M field 141.0: hr, 4
 * iterations, 2 threads).
 */
void hr_pack_lists(rad_solver *sv, int done);

/* Pre-order walk over the live nodes (see hier.h on liveness): clusters,
 * then every polygon's quadtree; stops at the first failure. */
typedef rad_status (*hr_node_fn)(rad_solver *sv, void *ud, uint32_t tagged);
rad_status hr_walk_all(rad_solver *sv, hr_node_fn fn, void *ud);
/*
 * The same nodes on the solver's threads, in no set order: fn gets the
 * ud of the thread that runs it (uds + thread x ud_size, one per
 * rad_par_threads) and must not fail (its status is ignored) nor write
 * anything but its ud.  For counts, whose sums do not depend on who
 * counted what.
 */
void hr_walk_par(rad_solver *sv, hr_node_fn fn, void *uds, size_t ud_size);

#endif
