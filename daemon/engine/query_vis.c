/*
 * query_vis.c -- the point query's visibility of pieces of source
 * (query.c): rays to a piece's corners and centroid, and the refinement
 * of the pieces those leave unsure once the point's total is known.
 *
 * DESIGN
 * Visibility of a piece of source (a leaf, an element taken whole, an
 * emitter): rays to its corners and centroid (trace_piece).  Corners,
 * because a straight shadow edge crossing a convex piece always leaves
 * corners on both sides: no such edge passes unseen, and a fixed ray
 * count settles nothing.  A piece whose rays disagree, or a large one
 * whose rays agree, is unsure: it goes to a per-point heap ordered by its
 * error.  Once the walk is done and the point's total is known
 * (query_refine_pieces), every agreeing piece larger than BIG_SHARE x
 * tau x total is split once (its quarters checked with their own rays;
 * as large as tau x total, a piece wholly wrong would be the tolerance
 * itself), and then the pieces whose rays disagree, largest errors
 * first, are split into quarters, each with its own exact kernel and
 * rays, until the errors left add up to less than tau / 2 of the total
 * (or VIS_SPLITS splits, or VIS_DEPTH levels).  Quarters take the
 * answers of rays already traced to their shared corners (their parent's
 * corners, centroid and edge midpoints: ray_memo), so a split traces 8
 * rays, not 20.  Judging against the final total, not a running one, is
 * what lets the first large source a point meets be resolved neither too
 * coarsely nor to the bottom.
 */
#include "query_vis.h"

#include <math.h>
#include <string.h>

#define VIS_DEPTH 10   /* splits of one piece, at most */
#define VIS_SPLITS 384 /* splits per point, at most */
#define BIG_SHARE 1.0  /* agreeing pieces above this x tau x total: split */

void query_patch_quarters(const rad_patch *p, rad_patch q[4])
{
	v3 a = v3_scale(p->e1, 0.5), b = v3_scale(p->e2, 0.5);
	v3 org[4] = {p->p0, v3_add(p->p0, a), v3_add(p->p0, b),
	             v3_add(v3_add(p->p0, a), b)};
	for (int k = 0; k < 4; k++) {
		q[k] = *p;
		q[k].p0 = org[k];
		q[k].e1 = a;
		q[k].e2 = b;
		q[k].area = p->area / 4;
	}
	if (!p->quad) {
		q[3].e1 = v3_scale(a, -1);
		q[3].e2 = v3_scale(b, -1);
	}
}

double query_patch_size(const rad_patch *p)
{
	v3 d = p->quad ? v3_add(p->e1, p->e2) : v3_sub(p->e2, p->e1);
	return fmax(fmax(v3_len(p->e1), v3_len(p->e2)), v3_len(d));
}

static void heap_swap(piece *a, piece *b)
{
	piece t = *a;
	*a = *b;
	*b = t;
}

/* Settle a piece as it is: its error is kept in the estimate. */
static void settle(gather *g, const piece *pc)
{
	if (pc->kind != PIECE_WHOLE)
		g->errvis += pc->e;
}

static void sift_up(gather *g, int i)
{
	while (i > 0 && g->heap[(i - 1) / 2].e < g->heap[i].e) {
		heap_swap(&g->heap[(i - 1) / 2], &g->heap[i]);
		i = (i - 1) / 2;
	}
}

/*
 * Full, the heap keeps the larger errors: the smallest held (a leaf of
 * the heap, the second half of the array) or the newcomer is settled.
 */
static void heap_push(gather *g, const piece *pc)
{
	if (g->nheap < VIS_HEAP) {
		g->heap[g->nheap] = *pc;
		sift_up(g, g->nheap++);
		return;
	}
	int m = VIS_HEAP / 2;
	for (int i = m + 1; i < VIS_HEAP; i++)
		if (g->heap[i].e < g->heap[m].e)
			m = i;
	if (g->heap[m].e >= pc->e) {
		settle(g, pc);
		return;
	}
	settle(g, &g->heap[m]);
	g->heap[m] = *pc;
	sift_up(g, m);
}

static piece heap_pop(gather *g)
{
	piece top = g->heap[0];
	g->heap[0] = g->heap[--g->nheap];
	for (int i = 0;;) {
		int l = 2 * i + 1, r = l + 1, m = i;
		if (l < g->nheap && g->heap[l].e > g->heap[m].e)
			m = l;
		if (r < g->nheap && g->heap[r].e > g->heap[m].e)
			m = r;
		if (m == i)
			break;
		heap_swap(&g->heap[m], &g->heap[i]);
		i = m;
	}
	return top;
}

/*
 * The points a piece's rays go to: its corners pulled 1 % towards its
 * centroid (off the edges it shares), then the centroid.  Returns the
 * count (4 or 5).
 */
static int piece_targets(const rad_patch *s, v3 v[5])
{
	int nv = rad_patch_vertices(s, v);
	v3 c = rad_patch_centroid(s);
	for (int k = 0; k < nv; k++)
		v[k] = v3_add(c, v3_scale(v3_sub(v[k], c), 0.99));
	v[nv] = c;
	return nv + 1;
}

/*
 * Trace the rays of a piece to its corners and its centroid
 * (piece_targets): fills p (the visible fraction, half from the centroid,
 * half from the corners) and open[] (each ray's answer, -1 where none was
 * tried), and returns the number of rays counted.  Corners, because a
 * straight shadow edge that crosses a convex piece always leaves corners
 * on both sides: no such edge can pass between the rays unseen.  Rays go
 * only to points in front of the point's tangent plane (the rest of the
 * piece does not contribute, and a ray there would run under the
 * surface); 0 rays: the piece straddles the plane with no point in front,
 * counted visible.  With a memo (the quarters of a split piece), a target
 * within 3 % of the piece's size of a point already traced takes that
 * answer instead of a ray: the quarters' corners are their parent's
 * corners, centroid and edge midpoints, shared among them, so a split
 * costs 8 new rays of a parallelogram's 20 (7 of a triangle's 16).
 */
static int trace_piece(const gather *g, const rad_patch *s, double *p,
                       int8_t open[5], ray_memo *memo)
{
	v3 v[5];
	int nt = piece_targets(s, v), tried = 0;
	double open_v = 0, open_c = 0, nvt = 0, wc = 0;
	double tol = 0.03 * query_patch_size(s), tol2 = tol * tol;
	for (int k = 0; k < nt; k++) {
		open[k] = -1;
		if (!(v3_dot(v3_sub(v[k], g->x), g->n) > 0))
			continue;
		tried++;
		int o = -1;
		for (int i = 0; memo && i < memo->n && o < 0; i++) {
			v3 d = v3_sub(memo->at[i], v[k]);
			if (v3_dot(d, d) <= tol2)
				o = memo->open[i];
		}
		if (o < 0) {
			o = rad_vis_segment(g->vis, g->x, &g->n, v[k], &s->n);
			if (memo && memo->n < MEMO_RAYS) {
				memo->at[memo->n] = v[k];
				memo->open[memo->n++] = (int8_t)o;
			}
		}
		open[k] = (int8_t)o;
		if (k < nt - 1) {
			nvt++;
			open_v += o;
		} else {
			wc = 1;
			open_c = o;
		}
	}
	if (tried == 0)
		*p = 1;
	else if (nvt == 0)
		*p = open_c;
	else if (!wc)
		*p = open_v / nvt;
	else
		*p = 0.5 * open_c + 0.5 * open_v / nvt;
	return tried;
}

double query_piece_error(double c, double p, int tried)
{
	if (tried == 0)
		return c / 2;
	return c * sqrt(p * (1 - p) / tried);
}

double query_visible_ff(gather *g, const rad_patch *s, double F, double w,
                        ray_memo *memo)
{
	double p;
	int8_t open[5];
	int tried = trace_piece(g, s, &p, open, memo);
	piece pc = {*s, w, F, w * F * p, 0, 0, PIECE_WHOLE, {0}};
	memcpy(pc.open, open, sizeof(open));
	if (tried == 0 || (p > 0 && p < 1)) {
		pc.kind = PIECE_PARTIAL;
		pc.e = query_piece_error(w * F, p, tried);
	} else if (w * F > BIG_SHARE * g->tau * query_running(g)) {
		/* Large so far (the total only grows): checked once the
		 * total is known. */
		pc.e = w * F / (tried + 2);
	}
	if (pc.e > 0)
		heap_push(g, &pc);
	return F * p;
}

/* Split one unsure piece into quarters, each with its own exact kernel
 * and rays; the total is corrected by the difference.  Returns the sum of
 * the errors of the quarters put back in the heap. */
static double split_piece(gather *g, const piece *pc)
{
	rad_patch q[4];
	double pushed = 0;
	ray_memo memo;
	memo.n = 0;
	int nt = piece_targets(&pc->s, memo.at);
	for (int k = 0; k < nt; k++)
		if (pc->open[k] >= 0) {
			memo.at[memo.n] = memo.at[k];
			memo.open[memo.n++] = pc->open[k];
		}
	query_patch_quarters(&pc->s, q);
	g->total -= pc->est;
	for (int k = 0; k < 4; k++) {
		double f = rad_ff_point_patch(g->x, g->n, &q[k]), p;
		if (!(f > 0))
			continue;
		int8_t open[5];
		int tried = trace_piece(g, &q[k], &p, open, &memo);
		int kind = tried == 0 || (p > 0 && p < 1) ? PIECE_PARTIAL
		                                          : PIECE_WHOLE;
		piece c = {q[k],          pc->w, f,
		           pc->w * f * p, 0,     (uint8_t)(pc->depth + 1),
		           (uint8_t)kind, {0}};
		memcpy(c.open, open, sizeof(open));
		g->total += c.est;
		/* Quarters whose rays agree are settled. */
		if (kind == PIECE_PARTIAL)
			c.e = query_piece_error(pc->w * f, p, tried);
		if (c.e <= 0)
			continue;
		if (c.depth >= VIS_DEPTH || g->nheap == VIS_HEAP) {
			g->errvis += c.e;
			continue;
		}
		heap_push(g, &c);
		pushed += c.e;
	}
	return pushed;
}

/*
 * Once the point's total is known: a whole piece whose rays agreed is
 * unsure only if it is large (over BIG_SHARE x tau x total: its quarters
 * get rays of their own); then the pieces with the largest errors are
 * split until their errors add up to less than half the tolerance, or the
 * split budget is spent.  Errors are added linearly: along one shadow
 * edge they have the same sign.
 */
void query_refine_pieces(gather *g)
{
	double big = BIG_SHARE * g->tau * query_running(g), sum = 0;
	piece whole[VIS_HEAP];
	int n = g->nheap, nw = 0;
	g->nheap = 0;
	for (int i = 0; i < n; i++) {
		piece pc = g->heap[i];
		if (pc.kind == PIECE_WHOLE) {
			if (pc.w * pc.F > big)
				whole[nw++] = pc;
			continue;
		}
		heap_push(g, &pc);
		sum += pc.e;
	}
	/* Each large agreeing piece is checked once, its quarters with rays
	 * of their own, before the shadow edges: mixed in one heap, at a
	 * tight tolerance these checks filled it and spent the budget, and a
	 * partly hidden source kept its first rays (measured: --accuracy
	 * 0.005 read +11 % / -13 % beside a plate's shadow). */
	for (int i = 0; i < nw; i++)
		sum += split_piece(g, &whole[i]);
	for (int splits = 0; g->nheap > 0 && splits < VIS_SPLITS; splits++) {
		if (sum <= 0.5 * g->tau * query_running(g))
			break;
		piece pc = heap_pop(g);
		sum -= pc.e;
		sum += split_piece(g, &pc);
	}
	for (int i = 0; i < g->nheap; i++)
		g->errvis += g->heap[i].e;
	g->nheap = 0;
}
