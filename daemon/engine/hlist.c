/*
 * hlist.c -- classic HR's lists of received links: new links on chains,
 * packed ones in blocks (hier.h, Packed lists).
 *
 * DESIGN
 * Packing lays the lists out in the order of a walk of the trees -- the
 * cluster tree, then every polygon's quadtree, each node before its
 * children -- so a list's packed block always lies after those of the
 * nodes walked before it.  It takes two walks:
 *   1. forward: every packed block moves down over the dead links before
 *      it (never up, so in place);
 *   2. backward: each list, from the last node walked to the first,
 *      moves up by the new links of the nodes before it (again in place,
 *      since the blocks of the nodes before it lie below where it was),
 *      and takes its new links in front, in their order on the list.
 * Walk 1 is left out when asked (the dead links then move up with the
 * others, still dead), and walk 2 when no link is new.
 * A list reads the same links in the same order after as before, so
 * packing changes no sum and no decision; it only gives the new links'
 * chains (12 bytes a link) back to the blocks (8).
 */
#include <string.h>

#include "hier.h"

static uint32_t block_links(const rad_hier *h)
{
	return 1u << h->links.shift;
}

rad_status rad_hlist_add(rad_hier *h, uint32_t tagged, uint32_t src, float ff,
                         float spread)
{
	if ((src & ~RAD_TAG_MASK) >= RAD_HLINK_LAST)
		return RAD_ERR_NOMEM;
	uint32_t id = rad_pool_add(&h->links, 1);
	if (id == RAD_NONE)
		return RAD_ERR_NOMEM;
	if (id & ~RAD_HREF_ID) {
		rad_pool_release(&h->links, id);
		return RAD_ERR_NOMEM;
	}
	uint32_t *head = rad_node_links(h, tagged);
	rad_hlink_new *l = rad_hlink_new_at(h, id);
	l->l.srcl = src;
	rad_hlink_set(&l->l, ff, spread);
	l->next = *head;
	*head = rad_hlist_ref(id);
	return RAD_OK;
}

uint32_t rad_hlist_remove(rad_hier *h, uint32_t *prev, uint32_t ref)
{
	if (ref & RAD_HBASE) {
		rad_hlink *l = rad_hlink_packed(h, ref & RAD_HREF_ID);
		l->srcl = RAD_HLINK_DEAD | (l->srcl & RAD_HLINK_LAST);
		h->ndead++;
		return rad_hlist_next(h, ref);
	}
	*prev = rad_hlink_new_at(h, ref)->next;
	rad_pool_release(&h->links, ref & RAD_HREF_ID);
	return rad_hlist_live(h, *prev);
}

uint32_t rad_hlist_count(const rad_hier *h)
{
	return h->npacked - h->ndead + rad_pool_live(&h->links);
}

/* ------------------------------------------------------------ packing */

typedef struct pack_walk {
	rad_hier *h;
	uint32_t at;     /* 1: the packed links kept so far */
	uint32_t end;    /* 2: where the packed block of the node after
	                    the current one (in walk order) starts */
	uint64_t before; /* 2: new links of the nodes before the current */
} pack_walk;

/* The reference that ends the chain of new links from head: head, or
 * the last new link's next; *n counts the chain. */
static uint32_t *chain_end(rad_hier *h, uint32_t *head, uint32_t *n)
{
	uint32_t *ref = head;
	*n = 0;
	while (*ref != RAD_NONE && !(*ref & RAD_HBASE)) {
		ref = &rad_hlink_new_at(h, *ref)->next;
		(*n)++;
	}
	return ref;
}

/* Walk 1 at the node of list head: its block moves down over the dead
 * links. */
static void pack_down(pack_walk *w, uint32_t *head)
{
	rad_hier *h = w->h;
	uint32_t n;
	uint32_t *ref = chain_end(h, head, &n);
	if (*ref == RAD_NONE)
		return;
	uint32_t start = w->at;
	for (uint32_t i = *ref & RAD_HREF_ID;; i++) {
		rad_hlink l = *rad_hlink_packed(h, i);
		if (!rad_hlink_dead(&l)) {
			rad_hlink *to = rad_hlink_packed(h, w->at++);
			to->srcl = rad_hlink_src(&l);
			to->fs = l.fs;
		}
		if (l.srcl & RAD_HLINK_LAST)
			break;
	}
	if (w->at == start) {
		*ref = RAD_NONE;
		return;
	}
	rad_hlink_packed(h, w->at - 1)->srcl |= RAD_HLINK_LAST;
	*ref = RAD_HLIST | RAD_HBASE | start;
}

/* Walk 2 at the node of list head: its list, new links first, moves up
 * to its place. */
static void pack_up(pack_walk *w, uint32_t *head)
{
	rad_hier *h = w->h;
	uint32_t n;
	uint32_t *end = chain_end(h, head, &n);
	uint32_t from = *end == RAD_NONE ? w->end : *end & RAD_HREF_ID;
	uint32_t kept = w->end - from;
	w->before -= n;
	uint32_t to = from + (uint32_t)w->before;
	/* Up (to + n >= from): the last link first. */
	for (uint32_t i = kept; i-- > 0;)
		*rad_hlink_packed(h, to + n + i) =
		        *rad_hlink_packed(h, from + i);
	uint32_t ref = *head;
	for (uint32_t i = 0; i < n; i++) {
		const rad_hlink_new *l = rad_hlink_new_at(h, ref);
		*rad_hlink_packed(h, to + i) = l->l;
		ref = l->next;
	}
	if (n + kept == 0)
		return;
	if (kept == 0)
		rad_hlink_packed(h, to + n - 1)->srcl |= RAD_HLINK_LAST;
	*head = RAD_HLIST | RAD_HBASE | to;
	w->end = from;
}

/* The trees in walk order (each node before its children), and the
 * reverse.  Quadtrees are at most RAD_ELEM_MAX_LEVEL deep and the cluster
 * tree splits its polygons in halves. */
static void down_elem(pack_walk *w, uint32_t id)
{
	rad_elem *e = rad_elem_at(w->h, id);
	pack_down(w, rad_elem_links(w->h, e));
	for (uint32_t k = 0; k < 4 && !rad_elem_is_leaf(e); k++)
		down_elem(w, e->child + k);
}

static void down_cluster(pack_walk *w, uint32_t id)
{
	rad_cluster *c = rad_cluster_at(w->h, id);
	pack_down(w, rad_cluster_links(w->h, c));
	for (uint32_t k = 0; k < 2 && !rad_cluster_is_leaf(c); k++)
		down_cluster(w, c->child + k);
}

static void up_elem(pack_walk *w, uint32_t id)
{
	rad_elem *e = rad_elem_at(w->h, id);
	for (uint32_t k = 4; k-- > 0 && !rad_elem_is_leaf(e);)
		up_elem(w, e->child + k);
	pack_up(w, rad_elem_links(w->h, e));
}

static void up_cluster(pack_walk *w, uint32_t id)
{
	rad_cluster *c = rad_cluster_at(w->h, id);
	for (uint32_t k = 2; k-- > 0 && !rad_cluster_is_leaf(c);)
		up_cluster(w, c->child + k);
	pack_up(w, rad_cluster_links(w->h, c));
}

/* Hold blocks for n packed links, freeing those past them; 0 if the
 * budget or the allocator refused (what is held stays). */
static int pack_reserve(rad_hier *h, uint64_t n)
{
	uint32_t bl = block_links(h);
	uint64_t need = (n + bl - 1) / bl;
	while (h->npack_blocks > need)
		rad_mem_free(h->mem, RAD_MEM_LINKS, h->pack[--h->npack_blocks]);
	if (h->npack_blocks == need)
		return 1;
	size_t bytes = (size_t)bl * sizeof(rad_hlink);
	if (!rad_mem_room(h->mem,
	                  (size_t)(need - h->npack_blocks) * bytes +
	                          (need > h->pack_cap
	                                   ? (size_t)need * sizeof(*h->pack)
	                                   : 0)))
		return 0;
	if (need > h->pack_cap) {
		uint32_t cap = h->pack_cap ? 2 * h->pack_cap : 8;
		while (cap < need)
			cap *= 2;
		rad_hlink **t = rad_mem_realloc(h->mem, RAD_MEM_LINKS, h->pack,
		                                cap * sizeof(*t));
		if (!t)
			return 0;
		h->pack = t;
		h->pack_cap = cap;
	}
	while (h->npack_blocks < need) {
		rad_hlink *b = rad_mem_alloc(h->mem, RAD_MEM_LINKS, bytes);
		if (!b)
			return 0;
		h->pack[h->npack_blocks++] = b;
	}
	return 1;
}

rad_status rad_hlist_pack(rad_hier *h, int drop_dead)
{
	uint32_t n = h->scene->npolys;
	pack_walk w = {.h = h};
	int clusters = h->clusters.count > 0;
	uint32_t fresh = rad_pool_live(&h->links); /* all on the chains */
	if (h->ndead && drop_dead) {
		if (clusters)
			down_cluster(&w, 0);
		for (uint32_t i = 0; i < n; i++)
			down_elem(&w, i);
		h->npacked = w.at;
		h->ndead = 0;
	}
	uint64_t total = (uint64_t)h->npacked + fresh;
	if (fresh == 0 || total > RAD_HREF_ID || !pack_reserve(h, total)) {
		pack_reserve(h, h->npacked); /* gives back what it can */
		return fresh ? RAD_ERR_NOMEM : RAD_OK;
	}
	w.end = h->npacked;
	w.before = fresh;
	for (uint32_t i = n; i-- > 0;)
		up_elem(&w, i);
	if (clusters)
		up_cluster(&w, 0);
	h->npacked = (uint32_t)total;
	rad_pool_destroy(&h->links);
	return RAD_OK;
}
