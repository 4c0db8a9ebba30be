/*
 * hier_check.c -- the hierarchy's invariants, checked (rad_hier_check).
 *
 * Run after every step in the builds that define LUXRAD_CHECKS (Debug
 * and the sanitizer builds: solver.c); tests may call it at any time.
 * A broken invariant is a bug of the engine, never of its input, so the
 * check costs nothing in a release build and in a check build turns a
 * silent corruption into an error that names the node.
 *
 * What holds:
 *   - elements: each polygon root is element i at level 0; an
 *     element's four children name its polygon, one level
 *     more, and its four quarters in path order; the leaves counted
 *     are nleaves;
 *   - clusters: the children of a cluster split its range of order[] in
 *     two, in order, and its area (a cluster keeps no parent: nothing
 *     walks up the tree); a leaf holds RAD_CLUSTER_LEAF_MAX
 *     polygons, but for the last leaf of the order, which may hold
 *     fewer;
 *   - links: a node's list (classic HR's rad_hlink) stays inside the
 *     pool and the packed blocks without a loop, each link names a source
 *     inside its pool, and the packed blocks follow each other in walk
 *     order (clusters, then quadtrees, a node before its children),
 *     covering offsets 0 .. npacked-1 (hier.h, Packed lists).
 */
#include <math.h>
#include <stdio.h>

#include "hier.h"
#include "scene.h"

#define AREA_REL 1e-3 /* float sums of up to 4 children, relative */

typedef struct checker {
	const rad_hier *h;
	char *msg;
	size_t len;
	uint64_t leaves;
	uint64_t packed_end; /* end of the last packed block walked */
} checker;

static int fail(checker *c, const char *what, uint32_t id)
{
	snprintf(c->msg, c->len, "hierarchy invariant broken: %s (node %u)",
	         what, id);
	return -1;
}

static int near_area(double sum, double whole)
{
	return fabs(sum - whole) <= AREA_REL * fmax(whole, 1e-30);
}

static int check_links(checker *c, uint32_t head, uint32_t tagged)
{
	const rad_hier *h = c->h;
	uint64_t seen = 0;
	int packed = 0;
	for (uint32_t l = head; l != RAD_NONE; l = rad_hlist_step(h, l)) {
		uint32_t i = l & RAD_HREF_ID;
		if (!(l & RAD_HLIST) ||
		    ++seen > (uint64_t)h->links.count + h->npacked)
			return fail(c, "link list leaves the pool or loops",
			            tagged);
		if (!(l & RAD_HBASE) && (packed || i >= h->links.count))
			return fail(c, "link list leaves the pool or loops",
			            tagged);
		if ((l & RAD_HBASE) && i >= h->npacked)
			return fail(c, "link list leaves the packed blocks",
			            tagged);
		if ((l & RAD_HBASE) && !packed) {
			if (i != c->packed_end)
				return fail(c, "packed block out of walk order",
				            tagged);
			packed = 1;
		}
		if (l & RAD_HBASE)
			c->packed_end = i + 1;
		const rad_hlink *k = rad_hlink_at(h, l);
		if (rad_hlink_dead(k))
			continue;
		uint32_t src = rad_hlink_src(k) & ~RAD_TAG_MASK;
		uint32_t tag = rad_hlink_src(k) & RAD_TAG_MASK;
		if (tag == RAD_TAG_CLUSTER ? src >= h->clusters.count
		    : tag == RAD_TAG_LIGHT ? src >= h->scene->nlights
		                           : src >= h->elems.count)
			return fail(c, "link source outside its pool", tagged);
	}
	return 0;
}

static int check_elem(checker *c, uint32_t id)
{
	const rad_hier *h = c->h;
	const rad_elem *e = rad_elem_at(h, id);
	int leaf = rad_elem_is_leaf(e);
	if (leaf && !h->lists && e->child != RAD_NONE)
		return fail(c, "leaf holds a list in a solver without", id);
	if (!leaf && (uint64_t)e->child + 4 > h->elems.count)
		return fail(c, "element's children outside the pool", id);
	if (!leaf &&
	    (e->child < h->run0 || (e->child - h->run0) % 4 != 0 ||
	     (e->child - h->run0) / 4 >= h->runs.count ||
	     (h->lists && (e->child - h->run0) / 4 >= h->run_heads.count)))
		return fail(c, "children are not a run of their own", id);
	/* Where the list is depends on the child field checked above. */
	if (h->lists && check_links(c, *rad_node_links(h, id), id) != 0)
		return -1;
	if (leaf) {
		c->leaves++;
		return 0;
	}
	int level = rad_elem_level(h, id);
	uint32_t path = rad_elem_path(h, id);
	for (uint32_t k = 0; k < 4; k++) {
		uint32_t ch = e->child + k;
		if (rad_elem_poly(h, ch) != rad_elem_poly(h, id) ||
		    rad_elem_level(h, ch) != level + 1)
			return fail(c, "child element disowns its parent", id);
		if (rad_elem_level(h, ch) > RAD_ELEM_MAX_LEVEL ||
		    rad_elem_path(h, ch) != (path | k << (2 * level)))
			return fail(c, "child element is not its quarter", id);
	}
	for (uint32_t k = 0; k < 4; k++)
		if (check_elem(c, e->child + k) != 0)
			return -1;
	return 0;
}

static int check_cluster(checker *c, uint32_t id, unsigned depth)
{
	const rad_hier *h = c->h;
	const rad_cluster *cl = rad_cluster_at(h, id);
	if (depth > 64)
		return fail(c, "cluster tree deeper than 64", id);
	int leaf = rad_cluster_is_leaf(cl);
	if (leaf && !h->lists && cl->child != RAD_NONE)
		return fail(c, "leaf holds a list in a solver without", id);
	if (!leaf &&
	    ((uint64_t)cl->child + 2 > h->clusters.count || cl->child == 0 ||
	     rad_cluster_inner_index(cl) >= h->ninner))
		return fail(c, "cluster's children outside the pool", id);
	if (h->lists && check_links(c, *rad_node_links(h, id | RAD_TAG_CLUSTER),
	                            id | RAD_TAG_CLUSTER) != 0)
		return -1;
	if (leaf) {
		if (cl->count > RAD_CLUSTER_LEAF_MAX)
			return fail(c, "leaf cluster of too many polygons", id);
		if (cl->count < RAD_CLUSTER_LEAF_MAX &&
		    cl->first + cl->count != h->scene->npolys)
			return fail(c, "leaf cluster not full", id);
		return 0;
	}
	const rad_cluster *a = rad_cluster_at(h, cl->child);
	const rad_cluster *b = rad_cluster_at(h, cl->child + 1);
	if (a->first != cl->first || b->first != a->first + a->count ||
	    a->count + b->count != cl->count)
		return fail(c, "child clusters do not split the range", id);
	if (!near_area((double)a->area + b->area, cl->area))
		return fail(c, "child clusters do not cover the area", id);
	if (check_cluster(c, cl->child, depth + 1) != 0)
		return -1;
	return check_cluster(c, cl->child + 1, depth + 1);
}

int rad_hier_check(const rad_hier *h, char *msg, size_t len)
{
	checker c = {h, msg, len, 0, 0};
	uint32_t npolys = h->scene->npolys;
	if (h->elems.count < npolys || h->run0 < npolys)
		return fail(&c, "fewer elements than polygons", npolys);
	/* Clusters first: the packed blocks' walk order. */
	if (h->clusters.count > 0 && check_cluster(&c, 0, 0) != 0)
		return -1;
	for (uint32_t i = 0; i < npolys; i++) {
		if (check_elem(&c, i) != 0)
			return -1;
	}
	if (c.leaves != h->nleaves)
		return fail(&c, "leaf count differs from nleaves",
		            (uint32_t)c.leaves);
	if (c.packed_end != h->npacked)
		return fail(&c, "packed blocks not all on lists",
		            (uint32_t)c.packed_end);
	return 0;
}
