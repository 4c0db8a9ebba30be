/*
 * solution.c -- published solutions: immutable copies of a solver's
 * result that answer queries while the solver goes on, and their bytes
 * for checkpoints (rad_solution_* in rad.h).
 *
 * DESIGN
 * A solution is a rad_hier without links whose two pools are each one
 * block of live records in a compact numbering: polygon roots keep ids
 * 0 .. npolys-1, the root cluster keeps id 0, and every sibling run (4
 * quadtree children, 2 child clusters) gets consecutive new ids, in the
 * order a breadth-first walk meets them.  A one-block pool is a valid
 * rad_pool (rad_pool_at reads block 0 for every id below `first`), so the
 * query code of query.c runs on it unchanged.  Copying is O(live nodes),
 * small next to an iteration.
 *
 * Bytes: a fixed header (magic, format version, record sizes, counts, the
 * iteration, a digest of the scene's polygons) then the element records,
 * their sibling runs' records (one per 4 elements past the roots: runs
 * start at npolys here), the roots' exposed fractions, the cluster records, the
 * inner clusters' records (moment model; one per child pair: the pairs
 * are clusters 1-2, 3-4, ...) and the cluster order, in the machine's byte
 * order (checkpoints are read back by the daemon that wrote them).  As for
 * scenes and solvers, the struct itself is plain calloc, not counted.  Loading
 * trusts nothing: sizes must match exactly, every id must be in range, every
 * record must be reached exactly once from the roots (no cycles, no sharing),
 * and every value must be finite, so a damaged or foreign file is refused with
 * a message instead of crashing a later query.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "solver.h"

#define SOL_MAGIC 0x534c5852u /* "RXLS" little-endian: "luxrad solution" */
#define SOL_VERSION                                                            \
	16u /* 2: clusters carry their orientation moments; 3:                 \
	     * and where their irradiance came from; 4: elements their         \
	     * exposed fraction (hier.h, Covered parts); 5: their path, not    \
	     * their region (hier.h, Regions); 6: clusters no parent; 7: nor   \
	     * elements; 8: the moments of inner clusters only, after the      \
	     * cluster records; 9: no list heads in elements and clusters;     \
	     * 10: dB and ndB with the moments, inner clusters only;           \
	     * 11: polygon, depth, path and exposed fraction in a record per   \
	     * sibling run and the roots' exposed fractions, after the         \
	     * elements (hier.h, Runs; written as 10, the element size         \
	     * telling it apart); 12: an element's dB packed, 32-byte          \
	     * records (hier.h, Increments); 13: clusters without I, V and S   \
	     * (hier.h, rad_cluster_flux), 76-byte records; 14: inner          \
	     * clusters' records their moment models alone (hier.h,            \
	     * rad_cluster_deltas); 15: an inner cluster's normal sum in       \
	     * its record, a leaf's summed when asked (64-byte clusters);      \
	     * 16: polygons' normals octahedral in 32 bits (scene.h, Normal    \
	     * and area) */

struct rad_solution {
	const rad_scene *scene;
	rad_mem mem; /* everything the solution holds, kind SOLUTION */
	rad_hier h;  /* one-block pools, no links */
	uint32_t iteration;
};

typedef struct sol_header {
	uint32_t magic, version;
	uint32_t elem_size, cluster_size;
	uint32_t npolys, nelems, nclusters, norder, nleaves, iteration;
	uint64_t digest; /* of the scene's polygons */
} sol_header;

/* FNV-1a over the fields of every polygon (not its padding). */
static uint64_t scene_digest(const rad_scene *s)
{
	uint64_t h = 1469598103934665603ull;
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		unsigned char
		        buf[10 * sizeof(float) + 3 * sizeof(uint32_t) + 1];
		size_t o = 0;
		float f[9]; /* the polygon as the solvers see it */
		rad_poly_frame(s, p, f, f + 3, f + 6);
		memcpy(buf + o, f, sizeof f), o += sizeof f;
		memcpy(buf + o, p->oct, sizeof p->oct), o += sizeof p->oct;
		memcpy(buf + o, &p->area, sizeof p->area), o += sizeof p->area;
		uint32_t mat = p->mat; /* a bit-field: its value, as before */
		memcpy(buf + o, &mat, sizeof mat), o += sizeof mat;
		uint32_t node = rad_poly_node(s, i);
		memcpy(buf + o, &node, sizeof node), o += sizeof node;
		buf[o++] = p->quad;
		for (size_t k = 0; k < o; k++)
			h = (h ^ buf[k]) * 1099511628211ull;
	}
	return h;
}

/* A pool that is one block of n records, zero-filled. */
static int pool_one_block(rad_pool *p, rad_mem *mem, uint32_t rec_size,
                          uint32_t n)
{
	rad_pool_init(p, mem, RAD_MEM_SOLUTION, rec_size, 0, n ? n : 1);
	p->block = rad_mem_alloc(mem, RAD_MEM_SOLUTION, sizeof(*p->block));
	if (!p->block)
		return -1;
	p->block[0] = rad_mem_calloc(mem, RAD_MEM_SOLUTION, p->first, rec_size);
	if (!p->block[0]) {
		rad_mem_free(mem, RAD_MEM_SOLUTION, p->block);
		p->block = NULL;
		return -1;
	}
	p->nblocks = p->cap_blocks = 1;
	p->count = n;
	return 0;
}

static rad_solution *solution_alloc(const rad_scene *scene)
{
	rad_solution *s = calloc(1, sizeof(*s));
	if (!s)
		return NULL;
	s->scene = scene;
	rad_mem_init(&s->mem);
	s->h.scene = scene;
	s->h.mem = &s->mem;
	rad_pool_init(&s->h.elems, &s->mem, RAD_MEM_SOLUTION, sizeof(rad_elem),
	              0, 1);
	rad_pool_init(&s->h.runs, &s->mem, RAD_MEM_SOLUTION,
	              sizeof(rad_elem_run), 0, 1);
	s->h.run0 = scene->npolys;
	rad_pool_init(&s->h.clusters, &s->mem, RAD_MEM_SOLUTION,
	              sizeof(rad_cluster), 0, 1);
	rad_pool_init(&s->h.links, &s->mem, RAD_MEM_SOLUTION, sizeof(rad_link),
	              0, 1);
	return s;
}

void rad_solution_free(rad_solution *s)
{
	if (!s)
		return;
	rad_pool_destroy(&s->h.elems);
	rad_pool_destroy(&s->h.runs);
	rad_mem_free(&s->mem, RAD_MEM_SOLUTION, s->h.root_exposed);
	rad_pool_destroy(&s->h.clusters);
	rad_mem_free(&s->mem, RAD_MEM_SOLUTION, s->h.order);
	rad_mem_free(&s->mem, RAD_MEM_SOLUTION, s->h.inner);
	free(s);
}

/* ------------------------------------------------------------------ copy */

/* Records below (and including) node id, for the copy's one block. */
static uint32_t count_below(const rad_hier *h, uint32_t id)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (rad_elem_is_leaf(e))
		return 1;
	uint32_t n = 1;
	for (uint32_t k = 0; k < 4; k++)
		n += count_below(h, e->child + k);
	return n;
}

static uint32_t count_clusters(const rad_hier *h, uint32_t id)
{
	const rad_cluster *c = rad_cluster_at(h, id);
	if (rad_cluster_is_leaf(c))
		return 1;
	return 1 + count_clusters(h, c->child) +
	       count_clusters(h, c->child + 1);
}

/* Element id of src as a solution keeps it: dB packed (hier.h,
 * Increments), and no list in a leaf's child field (Leaves and lists). */
static rad_elem sol_elem(const rad_hier *src, uint32_t id)
{
	const rad_elem *e = rad_elem_at(src, id);
	rad_elem out = *e;
	if (rad_elem_is_leaf(e))
		out.child = RAD_NONE;
	float dB[3];
	rad_elem_dB(src, e, dB);
	out.dB = rad_shared3_pack(dB);
	return out;
}

/*
 * Breadth-first renumbering: dst record i is src record map[i]; children
 * runs are appended in the order their parents are met.
 */
static uint32_t copy_elems(const rad_hier *src, rad_hier *dst)
{
	uint32_t leaves = 0;
	uint32_t np = src->scene->npolys, next = np;
	rad_elem *out = (rad_elem *)dst->elems.block[0];
	rad_elem_run *runs = (rad_elem_run *)dst->runs.block[0];
	for (uint32_t p = 0; p < np; p++)
		out[p] = sol_elem(src, p);
	memcpy(dst->root_exposed, src->root_exposed, np);
	for (uint32_t i = 0; i < next; i++) {
		rad_elem *e = &out[i];
		if (rad_elem_is_leaf(e)) {
			leaves++;
			continue;
		}
		uint32_t first = next;
		for (uint32_t k = 0; k < 4; k++)
			out[first + k] = sol_elem(src, e->child + k);
		runs[(first - np) / 4] = *rad_elem_run_of(src, e->child);
		e->child = first;
		next += 4;
	}
	return leaves;
}

static void copy_clusters(const rad_hier *src, rad_hier *dst)
{
	uint32_t next = 1;
	rad_cluster *out = (rad_cluster *)dst->clusters.block[0];
	out[0] = *rad_cluster_at(src, 0);
	for (uint32_t i = 0; i < next; i++) {
		rad_cluster *c = &out[i];
		if (rad_cluster_is_leaf(c)) {
			c->child = RAD_NONE; /* no list (hier.h) */
			continue;
		}
		uint32_t first = next;
		const rad_cluster_inner *mo =
		        &src->inner[rad_cluster_inner_index(c)];
		for (uint32_t k = 0; k < 2; k++)
			out[first + k] = *rad_cluster_at(src, c->child + k);
		c->child = first;
		dst->inner[rad_cluster_inner_index(c)] = *mo;
		next += 2;
	}
}

/* The sibling runs of a solution's elements: 4 elements each past the
 * roots (check_header has checked the count divides). */
static uint32_t sol_nruns(const sol_header *hd)
{
	return hd->npolys ? (hd->nelems - hd->npolys) / 4 : 0;
}

/* The models of a solution's nc clusters: one per child pair. */
static uint32_t sol_ninner(uint32_t nc)
{
	return nc ? (nc - 1) / 2 : 0;
}

static int alloc_inner(rad_solution *s, uint32_t nc)
{
	s->h.ninner = sol_ninner(nc);
	s->h.inner = rad_mem_calloc(&s->mem, RAD_MEM_SOLUTION,
	                            s->h.ninner ? s->h.ninner : 1,
	                            sizeof(rad_cluster_inner));
	return s->h.inner ? 0 : -1;
}

rad_status rad_solution_new(const rad_solver *sv, rad_solution **out,
                            rad_error *err)
{
	if (!out)
		return rad_fail(err, RAD_ERR_INVALID, "solution: no output");
	*out = NULL;
	if (!sv)
		return rad_fail(err, RAD_ERR_INVALID, "solution: no solver");
	if (!sv->impl) /* a restart failed (solver.c): no hierarchy */
		return rad_fail(err, RAD_ERR_STATE,
		                "solution: the solver failed and has none");
	const rad_hier *src = &sv->h;
	uint32_t np = sv->scene->npolys;
	rad_solution *s = solution_alloc(sv->scene);
	if (!s)
		return rad_fail(err, RAD_ERR_NOMEM, "solution: out of memory");
	s->iteration = sv->stats.iteration;
	s->h.nleaves = src->nleaves;
	s->h.min_edge = src->min_edge;
	if (np > 0) {
		uint32_t ne = 0, nc = count_clusters(src, 0);
		for (uint32_t p = 0; p < np; p++)
			ne += count_below(src, p);
		if (pool_one_block(&s->h.elems, &s->mem, sizeof(rad_elem),
		                   ne) ||
		    pool_one_block(&s->h.runs, &s->mem, sizeof(rad_elem_run),
		                   (ne - np) / 4) ||
		    !(s->h.root_exposed =
		              rad_mem_alloc(&s->mem, RAD_MEM_SOLUTION, np)) ||
		    pool_one_block(&s->h.clusters, &s->mem, sizeof(rad_cluster),
		                   nc) ||
		    alloc_inner(s, nc) ||
		    !(s->h.order = rad_mem_alloc(&s->mem, RAD_MEM_SOLUTION,
		                                 np * sizeof(uint32_t)))) {
			rad_solution_free(s);
			return rad_fail(err, RAD_ERR_NOMEM,
			                "solution: out of memory copying %u "
			                "elements",
			                ne);
		}
		s->h.nleaves = copy_elems(src, &s->h);
		copy_clusters(src, &s->h);
		memcpy(s->h.order, src->order, np * sizeof(uint32_t));
	}
	*out = s;
	return RAD_OK;
}

/* --------------------------------------------------------------- queries */

rad_status rad_solution_query(const rad_solution *s, const double *pts,
                              size_t n, double tol, double solve_error,
                              double *lux, double *error_lux, rad_error *err)
{
	if (!s)
		return rad_fail(err, RAD_ERR_INVALID,
		                "illuminance: no solution");
	rad_query_args a = {
	        pts,         n,   tol > 0 ? tol : RAD_QUERY_TOL_DEFAULT,
	        solve_error, lux, error_lux};
	return rad_query_illuminance(s->scene, &s->h, NULL, &a, err);
}

rad_status rad_solution_illuminance(const rad_solution *s, const double *pts,
                                    size_t n, double *lux, rad_error *err)
{
	return rad_solution_query(s, pts, n, 0, 0, lux, NULL, err);
}

void rad_solution_leaves(const rad_solution *s, rad_leaf_fn fn, void *ud)
{
	if (!s || !fn)
		return;
	rad_query_leaves(&s->h, fn, ud);
}

uint32_t rad_solution_iteration(const rad_solution *s)
{
	return s ? s->iteration : 0;
}

void rad_solution_memory(const rad_solution *s, rad_mem_report *out)
{
	rad_mem_report_clear(out);
	if (s)
		rad_mem_report_add(&s->mem, out);
}

const char *rad_scene_node_name(const rad_scene *s, uint32_t node)
{
	if (!s || node >= s->nnodes || !s->nodes[node])
		return "";
	return s->nodes[node];
}

/* ----------------------------------------------------------------- bytes */

rad_status rad_solution_save(const rad_solution *s, unsigned char **out,
                             size_t *len, rad_error *err)
{
	if (!s || !out || !len)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution save: NULL argument");
	uint32_t np = s->scene->npolys;
	sol_header hd = {SOL_MAGIC,
	                 SOL_VERSION,
	                 sizeof(rad_elem),
	                 sizeof(rad_cluster),
	                 np,
	                 np ? s->h.elems.count : 0,
	                 np ? s->h.clusters.count : 0,
	                 np,
	                 s->h.nleaves,
	                 s->iteration,
	                 scene_digest(s->scene)};
	size_t be = (size_t)hd.nelems * sizeof(rad_elem);
	size_t br = (size_t)sol_nruns(&hd) * sizeof(rad_elem_run);
	size_t bx = np;
	size_t bc = (size_t)hd.nclusters * sizeof(rad_cluster);
	size_t bm =
	        (size_t)sol_ninner(hd.nclusters) * sizeof(rad_cluster_inner);
	size_t bo = (size_t)hd.norder * sizeof(uint32_t);
	size_t n = sizeof hd + be + br + bx + bc + bm + bo;
	unsigned char *b = malloc(n);
	if (!b)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "solution save: out of memory (%zu bytes)", n);
	memcpy(b, &hd, sizeof hd);
	if (np) {
		unsigned char *o = b + sizeof hd;
		memcpy(o, s->h.elems.block[0], be), o += be;
		memcpy(o, s->h.runs.block[0], br), o += br;
		memcpy(o, s->h.root_exposed, bx), o += bx;
		memcpy(o, s->h.clusters.block[0], bc), o += bc;
		memcpy(o, s->h.inner, bm), o += bm;
		memcpy(o, s->h.order, bo);
	}
	*out = b;
	*len = n;
	return RAD_OK;
}

static int finite3(const float v[3])
{
	return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static int elem_ok(const rad_elem *e, uint32_t np, uint32_t ne)
{
	if (e->child != RAD_NONE &&
	    (e->child < np || e->child >= ne || ne - e->child < 4 ||
	     (e->child - np) % 4 != 0))
		return 0;
	float dB[3];
	rad_shared3_unpack(e->dB, dB); /* packed in a solution */
	return finite3(e->B) && finite3(e->I) && finite3(dB);
}

/*
 * An element's region is not data of its own (hier.h, Regions): a root is
 * its polygon, a child the quarter its path names.  A run's polygon,
 * depth and path are checked against its parent's, so that damage there
 * (a path no split made, a depth past the cap) is refused, not traced.
 */
static int run_matches(const rad_hier *h, uint32_t parent,
                       const rad_elem_run *r)
{
	return r->poly == rad_elem_poly(h, parent) &&
	       r->level == rad_elem_level(h, parent) + 1 &&
	       r->level <= RAD_ELEM_MAX_LEVEL &&
	       r->path == rad_elem_path(h, parent);
}

/* Every element reached once from the roots, children of one polygon. */
static rad_status check_elems(rad_solution *s, uint32_t np, uint32_t ne,
                              unsigned char *seen, rad_error *err)
{
	const rad_elem *a = (const rad_elem *)s->h.elems.block[0];
	for (uint32_t i = 0; i < ne; i++)
		if (!elem_ok(&a[i], np, ne))
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: element %u is damaged", i);
	uint32_t reached = np, leaves = 0;
	/* Ids of children always exceed their parent's (breadth-first), so
	 * one forward pass visits the forest. */
	for (uint32_t i = 0; i < ne; i++) {
		if (i >= np && !seen[i])
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: element %u is unreachable",
			                i);
		if (a[i].child == RAD_NONE) {
			leaves++;
			continue;
		}
		if (a[i].child <= i)
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: element %u has an earlier "
			                "child",
			                i);
		/* Parents come before their children: i's own run has
		 * been checked when its polygon, depth and path are read. */
		if (!run_matches(&s->h, i, rad_elem_run_of(&s->h, a[i].child)))
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: the children of element %u "
			                "are not its quarters",
			                i);
		for (uint32_t k = 0; k < 4; k++) {
			uint32_t c = a[i].child + k;
			if (seen[c])
				return rad_fail(err, RAD_ERR_INVALID,
				                "solution: element %u is "
				                "shared",
				                c);
			seen[c] = 1;
			reached++;
		}
	}
	if (reached != ne || leaves != s->h.nleaves)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: %u of %u elements reached, %u "
		                "leaves for %u announced",
		                reached, ne, leaves, s->h.nleaves);
	return RAD_OK;
}

static rad_status check_clusters(rad_solution *s, uint32_t np, uint32_t nc,
                                 unsigned char *seen, rad_error *err)
{
	const rad_cluster *a = (const rad_cluster *)s->h.clusters.block[0];
	for (uint32_t i = 0; i < np; i++)
		if (s->h.order[i] >= np)
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: order[%u] out of range", i);
	memset(seen, 0, nc);
	uint32_t reached = 1;
	for (uint32_t i = 0; i < nc; i++) {
		const rad_cluster *c = &a[i];
		if ((i > 0 && !seen[i]) || c->first > np ||
		    c->count > np - c->first || !finite3(c->lo) ||
		    !finite3(c->hi) || !finite3(c->B) || !finite3(c->nB) ||
		    !isfinite(c->area))
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: cluster %u is damaged", i);
		if (c->child == RAD_NONE)
			continue;
		if (c->child <= i || c->child >= nc || nc - c->child < 2)
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: cluster %u has a bad child",
			                i);
		const rad_cluster_inner *mo =
		        &s->h.inner[rad_cluster_inner_index(c)];
		if (!finite3(mo->m) || !finite3(mo->m + 3) ||
		    !isfinite(mo->q) || !finite3(mo->n))
			return rad_fail(err, RAD_ERR_INVALID,
			                "solution: cluster %u's model is "
			                "damaged",
			                i);
		for (uint32_t k = 0; k < 2; k++) {
			if (seen[c->child + k])
				return rad_fail(err, RAD_ERR_INVALID,
				                "solution: cluster %u shared",
				                c->child + k);
			seen[c->child + k] = 1;
			reached++;
		}
	}
	if (reached != nc)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: %u of %u clusters reached", reached,
		                nc);
	return RAD_OK;
}

static rad_status check_header(const sol_header *hd, const rad_scene *scene,
                               size_t len, rad_error *err)
{
	if (hd->magic != SOL_MAGIC)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: not a luxrad solution (bad magic)");
	if (hd->version != SOL_VERSION || hd->elem_size != sizeof(rad_elem) ||
	    hd->cluster_size != sizeof(rad_cluster))
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: format %u (record sizes %u/%u) is "
		                "not this engine's %u (%zu/%zu)",
		                hd->version, hd->elem_size, hd->cluster_size,
		                SOL_VERSION, sizeof(rad_elem),
		                sizeof(rad_cluster));
	if (hd->npolys != scene->npolys || hd->norder != scene->npolys ||
	    hd->digest != scene_digest(scene))
		return rad_fail(
		        err, RAD_ERR_INVALID,
		        "solution: made for another scene, or for this one as "
		        "an earlier engine stored its geometry (%u polygons, "
		        "this one has %u; their digests differ)",
		        hd->npolys, scene->npolys);
	int empty = hd->npolys == 0;
	if (empty ? (hd->nelems || hd->nclusters)
	          : (hd->nelems < hd->npolys || hd->nclusters < 1 ||
	             hd->nelems > UINT32_MAX / 2 ||
	             (hd->nelems - hd->npolys) % 4 != 0))
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: bad record counts");
	size_t want =
	        sizeof *hd + (size_t)hd->nelems * sizeof(rad_elem) +
	        (size_t)sol_nruns(hd) * sizeof(rad_elem_run) + hd->npolys +
	        (size_t)hd->nclusters * sizeof(rad_cluster) +
	        (size_t)sol_ninner(hd->nclusters) * sizeof(rad_cluster_inner) +
	        (size_t)hd->norder * sizeof(uint32_t);
	if (len != want)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: %zu bytes, expected %zu (truncated "
		                "or damaged)",
		                len, want);
	return RAD_OK;
}

rad_status rad_solution_load(const rad_scene *scene, const void *bytes,
                             size_t len, rad_solution **out, rad_error *err)
{
	if (!out)
		return rad_fail(err, RAD_ERR_INVALID, "solution: no output");
	*out = NULL;
	if (!scene || (!bytes && len))
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution load: NULL argument");
	sol_header hd;
	if (len < sizeof hd)
		return rad_fail(err, RAD_ERR_INVALID,
		                "solution: %zu bytes is shorter than a header",
		                len);
	memcpy(&hd, bytes, sizeof hd);
	rad_status st = check_header(&hd, scene, len, err);
	if (st != RAD_OK)
		return st;
	rad_solution *s = solution_alloc(scene);
	if (!s)
		return rad_fail(err, RAD_ERR_NOMEM, "solution: out of memory");
	s->iteration = hd.iteration;
	s->h.nleaves = hd.nleaves;
	if (hd.npolys > 0) {
		const unsigned char *b =
		        (const unsigned char *)bytes + sizeof hd;
		size_t be = (size_t)hd.nelems * sizeof(rad_elem);
		size_t br = (size_t)sol_nruns(&hd) * sizeof(rad_elem_run);
		size_t bx = hd.npolys;
		size_t bc = (size_t)hd.nclusters * sizeof(rad_cluster);
		size_t bm = (size_t)sol_ninner(hd.nclusters) *
		            sizeof(rad_cluster_inner);
		unsigned char *seen = NULL;
		if (pool_one_block(&s->h.elems, &s->mem, sizeof(rad_elem),
		                   hd.nelems) ||
		    pool_one_block(&s->h.runs, &s->mem, sizeof(rad_elem_run),
		                   sol_nruns(&hd)) ||
		    !(s->h.root_exposed =
		              rad_mem_alloc(&s->mem, RAD_MEM_SOLUTION, bx)) ||
		    pool_one_block(&s->h.clusters, &s->mem, sizeof(rad_cluster),
		                   hd.nclusters) ||
		    alloc_inner(s, hd.nclusters) ||
		    !(s->h.order =
		              rad_mem_alloc(&s->mem, RAD_MEM_SOLUTION,
		                            hd.npolys * sizeof(uint32_t))) ||
		    !(seen = calloc(hd.nelems > hd.nclusters ? hd.nelems
		                                             : hd.nclusters,
		                    1))) {
			rad_solution_free(s);
			return rad_fail(err, RAD_ERR_NOMEM,
			                "solution: out of memory");
		}
		memcpy(s->h.elems.block[0], b, be), b += be;
		memcpy(s->h.runs.block[0], b, br), b += br;
		memcpy(s->h.root_exposed, b, bx), b += bx;
		memcpy(s->h.clusters.block[0], b, bc), b += bc;
		memcpy(s->h.inner, b, bm), b += bm;
		memcpy(s->h.order, b, hd.npolys * sizeof(uint32_t));
		st = check_elems(s, hd.npolys, hd.nelems, seen, err);
		if (st == RAD_OK)
			st = check_clusters(s, hd.npolys, hd.nclusters, seen,
			                    err);
		free(seen);
		if (st != RAD_OK) {
			rad_solution_free(s);
			return st;
		}
	}
	*out = s;
	return RAD_OK;
}
