/*
 * query.h -- what the point query's two files share (query.c walks the
 * hierarchy for a point, query_vis.c settles the visibility of the
 * pieces of source it meets): the state of one point's gather.
 */
#ifndef LUXRAD_QUERY_H
#define LUXRAD_QUERY_H

#include "ff.h"
#include "solver.h"
#include "vis.h"

#define VIS_HEAP 256 /* unsure pieces held per point */
#define NEAR_MAX 8   /* near leaves read finer per point, at most */

/*
 * A piece of source whose visible fraction is not settled: w its
 * radiosity weight (the lux it gives per unit of kernel), F its exact
 * kernel, est = w F p what it added to the total, e its error estimate.
 */
typedef struct piece {
	rad_patch s;
	double w, F, est, e;
	uint8_t depth;
	uint8_t kind;   /* PIECE_* */
	int8_t open[5]; /* its rays (trace_piece): corners, centroid; -1 none */
} piece;

/* Rays already traced to the corners of neighbouring pieces -- a split
 * piece and its quarters, four sibling elements, an emitter and its root
 * element -- that trace_piece reuses: a piece's 5 and four more pieces'. */
#define MEMO_RAYS (5 + 4 * 5)
typedef struct ray_memo {
	v3 at[MEMO_RAYS];
	int8_t open[MEMO_RAYS];
	int n;
} ray_memo;

enum {
	PIECE_PARTIAL, /* its rays disagree: a shadow edge crosses it */
	PIECE_WHOLE,   /* rays agree: only a large top piece is checked */
};

/* A leaf near the point whose radiosity may vary across what x sees. */
typedef struct near {
	rad_patch s;
	double irr;  /* its mean irradiance */
	double c, e; /* what it added (r x visible kernel), its error */
} near;

typedef struct gather {
	const rad_hier *h;
	const rad_vis *vis;
	v3 x, n;       /* the point and its unit normal */
	double tau;    /* relative tolerance */
	double total;  /* photopic lux gathered so far */
	double floor;  /* smallest running total used by the tests */
	double err2;   /* sum of squared independent error estimates */
	double errvis; /* visibility error given up on (heap full, depth) */
	double direct; /* of total: lights and emission (not reflected) */
	int nested;    /* 1 inside a near leaf's own gather (no deeper) */
	piece heap[VIS_HEAP]; /* max-heap on e */
	int nheap;
	near near[NEAR_MAX]; /* near leaves to read finer (near_leaves) */
	int nnear;
} gather;

/* The running total the tests are relative to (never below the floor). */
static inline double query_running(const gather *g)
{
	return fmax(g->total, g->floor);
}

/* Quarter a patch the way the quadtree does (the middle triangle of a
 * triangle points the other way but keeps the normal). */
void query_patch_quarters(const rad_patch *p, rad_patch q[4]);
/* Longest extent of a patch (its longest edge or diagonal). */
double query_patch_size(const rad_patch *p);

/*
 * Visible kernel of a piece of source of radiosity weight w (the top of a
 * source: a leaf, an element taken whole, an emitter), exact kernel F:
 * five rays now, fewer where memo (siblings in one quadtree, an emitter
 * and its root element; may be NULL) already has its corners.  A piece
 * they leave unsure waits in the point's heap for query_refine_pieces.
 */
double query_visible_ff(gather *g, const rad_patch *s, double F, double w,
                        ray_memo *memo);
/* Once the point's total is known: settle the unsure pieces, correcting
 * the total, and add what is left of their errors to errvis. */
void query_refine_pieces(gather *g);

#endif
