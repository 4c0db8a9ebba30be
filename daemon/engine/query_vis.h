/*
 * query_vis.h -- the point query's visibility of pieces of source
 * (query_vis.c), for query.c's walk.
 */
#ifndef LUXRAD_QUERY_VIS_H
#define LUXRAD_QUERY_VIS_H

#include "gather.h"

/* Quarter a patch the way the quadtree does (the middle triangle of a
 * triangle points the other way but keeps the normal). */
void query_patch_quarters(const rad_patch *p, rad_patch q[4]);
/* Longest extent of a patch (its longest edge or diagonal). */
double query_patch_size(const rad_patch *p);

/*
 * The error of a traced piece of share c = w F whose rays disagree: the
 * binomial error of the fraction, c sqrt(p (1 - p) / k) with k rays
 * tried; c / 2 when none could be.  Agreeing rays leave no error (no
 * straight edge passes between corners unseen); a large piece is checked
 * once more all the same (query_refine_pieces).
 */
double query_piece_error(double c, double p, int tried);

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
