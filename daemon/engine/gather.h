/*
 * gather.h -- the state of one point's final gather, shared by the point
 * query's two files (query.c walks the hierarchy for a point, query_vis.c
 * settles the visibility of the pieces of source it meets).
 */
#ifndef LUXRAD_GATHER_H
#define LUXRAD_GATHER_H

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

#endif
