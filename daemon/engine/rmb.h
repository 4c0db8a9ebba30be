/*
 * rmb.h -- what the reduced-memory solver's two files share: rmb.c runs
 * the iterations (radiosity to transmit, push, update, pull), and
 * rmb_refine.c walks the link hierarchy (RefineAndGather).
 */
#ifndef LUXRAD_RMB_H
#define LUXRAD_RMB_H

#include "wave.h"

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

/*
 * Receiver accuracy by element id (rmb_refine.c, rcv_too_coarse): nv
 * values an id, zero until written.  Few elements have any, so they are
 * an open-addressing map of slots (the id, RAD_NONE when empty, then
 * the values), at most three quarters full, until the map would take
 * as much as an array by id: then they are that array, to the elements
 * there are and a block of the pool more.  The walk's error sums (err,
 * emax) concern only the elements that can be split or were (an
 * element that cannot has no children to pass its sum on to, and no
 * cut of its own): 5,000-17,000 of the 1M field's 750,000 elements in
 * each step, where arrays by id held 8 bytes for every element (6 MB)
 * and the cuts 4 more.  A map becomes an array when its growth would
 * outgrow one over the elements there are then, and stays one: the
 * converged Graz office's cuts (77,000 of 375,000 elements) and its
 * error sums in 7 of its 11 steps end as arrays.
 */
typedef union rmb_acc_word {
	uint32_t id;
	float v;
} rmb_acc_word;
typedef struct rmb_acc {
	rmb_acc_word *slot; /* the map's cap slots of 1 + nv words */
	float *dense;       /* or the array's cap x nv values */
	size_t n, cap;      /* map: ids held, slots (a power of 2, or 0);
	                       array: ids covered */
	uint32_t nv;        /* values an id: 1 or 2 */
	rad_mem_kind kind;
} rmb_acc;

typedef struct rmb_state {
	rad_wave wave; /* items: rmb_item; its todo is the work list */
	uint32_t *roots;
	size_t nroots, cap_roots; /* stored root links, LINKS */
	float *arefl; /* per cluster id: area that reflects (0: none, the
	                 contents all rho = 0) */
	/* Per cluster id, the largest reflectance inside: one of the
	 * materials' largest (or 0), so rho_levels[rho_at[id]], 1 byte a
	 * cluster, where it was a float; where the materials have more than
	 * 256 of them (with 0), rhomax[id] (rmb_node_rho_max). */
	uint8_t *rho_at;
	float *rhomax;
	float rho_levels[256];
	uint32_t nlevels;
	uint32_t ncl;
	uint32_t iter;     /* iterations done */
	uint32_t init_row; /* without clustering: rows of polygon pairs the
	                      first walk has gathered; a cancelled first step
	                      goes on from the next one */
	double mean_dB;    /* area-mean photopic dB after the last update */
	double mean_B;     /* ... and B */
	double chg[3][3];  /* sum A |dB| per channel, last three steps */
	double q[3];       /* the tail jump's rates (tail_jump) */
	double qmax;       /* ... the largest */
	int jumped;        /* tail_jump done */
	rmb_set deleted;   /* study: pairs deleted so far */
	/* Per link id, one bit each (LINKS): fresh, made this iteration
	 * (no form factor until gathered; count_links clears it); dead,
	 * carries nothing (the walk's post-order removes it). */
	uint64_t *fresh, *dead;
	size_t cap_bits; /* words of each */
	/* Receiver accuracy (rcv_too_coarse, rmb_refine.c), by element id:
	 * cut   v[0]: links at least this error (a fraction of the limit)
	 *       go to the receiver's children; none held: no cut.  Sticky,
	 *       ELEM_SURFACE.
	 * err   v[0]: the sum of the errors of the links gathered this
	 *       iteration, v[1]: the largest of them; SCRATCH, for one
	 *       step. */
	rmb_acc cut, err;
	/* Delayed emission (rad_options.delay): what the leaves held back,
	 * sum A S_B / rho per channel, put back into their I at the step's
	 * start (rmb.c, hold_leaf). */
	double held[3];
} rmb_state;

/*
 * RefineAndGather (rmb_refine.c): walk the link trees -- the first step's
 * new roots, then the stored ones -- gathering every transfer at its
 * level into I, and settle them; then mark where receivers were too
 * coarse.
 */
rad_status rmb_refine_gather(rad_solver *sv, rmb_state *st);

static inline int rmb_bit(const uint64_t *v, uint32_t id)
{
	return (int)((v[id >> 6] >> (id & 63)) & 1);
}
static inline void rmb_set_bit(uint64_t *v, uint32_t id, int on)
{
	uint64_t m = (uint64_t)1 << (id & 63);
	v[id >> 6] = on ? v[id >> 6] | m : v[id >> 6] & ~m;
}
/* Link id is fresh: made this iteration (rmb_state.fresh). */
static inline int rmb_fresh(const rmb_state *st, uint32_t id)
{
	return rmb_bit(st->fresh, id);
}

/* rmb_nodes.c: */
/* Grow the link bits to cover every id of the link pool; RAD_ERR_NOMEM. */
rad_status rmb_cover_links(rad_solver *sv, rmb_state *st);
/* Links first .. first+n-1 were just made: fresh, not dead. */
void rmb_made_links(rmb_state *st, uint32_t first, uint32_t n);
/* 1 if no polygon of the node reflects (a pure source, or black). */
int rmb_node_black(const rad_solver *sv, uint32_t t);
/* Area of the node's polygons that reflect (rho > 0). */
double rmb_node_arefl(const rad_solver *sv, uint32_t t);
/* Largest reflectance inside a node (over channels), for anticipation. */
double rmb_node_rho_max(const rad_solver *sv, uint32_t t);
/* The receiver-accuracy budget of the iteration (lux). */
double rmb_spread_limit(const rad_solver *sv);
/* Link id, which the walk deletes: counted unless it was made this
 * iteration, and its pair kept for the study statistics (*rs: out of
 * memory). */
void rmb_count_deleted(rad_solver *sv, uint32_t id, rad_status *rs);
/* The largest reflectances there are (rho_levels), and where to keep
 * them by cluster; RAD_ERR_NOMEM. */
rad_status rmb_rho_init(rad_solver *sv, rmb_state *st);
/* Fill arefl[] and the largest reflectances for cluster id and below;
 * returns its reflecting area. */
double rmb_mark_black(rad_solver *sv, uint32_t id);
/* Receiver accuracy (rmb_acc): element id's values, or NULL when none
 * are held (or zeros); the values of id, added as zeros if new (NULL:
 * out of memory, or the budget refused the growth); bytes of the next
 * growth; free. */
const float *rmb_acc_get(const rmb_acc *m, uint32_t id);
float *rmb_acc_put(rad_solver *sv, rmb_acc *m, uint32_t id);
size_t rmb_acc_growth(const rad_solver *sv, const rmb_acc *m);
void rmb_acc_free(rad_solver *sv, rmb_acc *m);
/* The study set: a pair's key, and whether the set holds it. */
uint64_t rmb_pair_key(uint32_t r, uint32_t s);
int rmb_set_has(const rmb_set *s, uint64_t k);

#endif
