/*
 * walk.c -- the node hierarchy of a glTF document: which nodes a scene
 * holds, their local transforms (matrix, or T * R * S) and the world
 * transforms composed down the tree, in double precision.
 *
 * The walk is depth first with an explicit stack: a hostile document may
 * nest nodes deeper than the C stack allows.  A node met twice means a
 * cycle or a shared child (glTF requires a forest) and is refused.  The
 * walk itself checks only what it uses (node and child indices, the
 * shape of local transforms); the visitors check the rest.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

static sio_mat4 mat_identity(void)
{
	sio_mat4 r = {{0}};
	r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1;
	return r;
}

static sio_mat4 mat_mul(const sio_mat4 *a, const sio_mat4 *b)
{
	sio_mat4 r;
	for (int c = 0; c < 4; c++)
		for (int row = 0; row < 4; row++) {
			double s = 0;
			for (int k = 0; k < 4; k++)
				s += a->m[k * 4 + row] * b->m[c * 4 + k];
			r.m[c * 4 + row] = s;
		}
	return r;
}

double sio_mat_det3(const sio_mat4 *a)
{
	const double *x = a->m, *y = a->m + 4, *z = a->m + 8;
	return x[0] * (y[1] * z[2] - y[2] * z[1]) -
	       x[1] * (y[0] * z[2] - y[2] * z[0]) +
	       x[2] * (y[0] * z[1] - y[1] * z[0]);
}

void sio_mat_point(const sio_mat4 *a, const float p[3], double out[3])
{
	for (int r = 0; r < 3; r++)
		out[r] = a->m[r] * p[0] + a->m[4 + r] * p[1] +
		         a->m[8 + r] * p[2] + a->m[12 + r];
}

const char *sio_node_name(const sio_doc *d, int ni)
{
	return d->nodes[(size_t)ni].name.s;
}

/* Local transform of a node from its matrix, or T * R * S. */
static rad_status node_local(const sio_doc *d, int ni, sio_mat4 *out,
                             rad_error *err)
{
	const sio_doc_node *n = &d->nodes[(size_t)ni];
	*out = mat_identity();
	if (n->nmatrix) {
		if (n->nmatrix != 16)
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d '%s': matrix has %zu numbers, "
			                "expected 16",
			                ni, sio_node_name(d, ni), n->nmatrix);
		memcpy(out->m, n->matrix, sizeof out->m);
		return RAD_OK;
	}
	if ((n->ntranslation && n->ntranslation != 3) ||
	    (n->nrotation && n->nrotation != 4) ||
	    (n->nscale && n->nscale != 3))
		return rad_fail(err, RAD_ERR_INVALID,
		                "node %d '%s': translation, rotation and scale "
		                "need 3, 4 and 3 numbers",
		                ni, sio_node_name(d, ni));
	double q[4] = {0, 0, 0, 1}, s[3] = {1, 1, 1};
	if (n->nrotation) {
		const double *r = n->rotation;
		double len = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2] +
		                  r[3] * r[3]);
		if (!(len > 0) || !isfinite(len))
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d '%s': rotation is not a "
			                "usable quaternion",
			                ni, sio_node_name(d, ni));
		for (int k = 0; k < 4; k++)
			q[k] = r[k] / len;
	}
	if (n->nscale)
		memcpy(s, n->scale, sizeof s);
	const double x = q[0], y = q[1], z = q[2], w = q[3];
	const double r[3][3] = {
	        {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),
	         2 * (x * z + y * w)},
	        {2 * (x * y + z * w), 1 - 2 * (x * x + z * z),
	         2 * (y * z - x * w)},
	        {2 * (x * z - y * w), 2 * (y * z + x * w),
	         1 - 2 * (x * x + y * y)},
	};
	for (int c = 0; c < 3; c++)
		for (int row = 0; row < 3; row++)
			out->m[c * 4 + row] = r[row][c] * s[c];
	for (size_t k = 0; k < n->ntranslation; k++)
		out->m[12 + k] = n->translation[k];
	return RAD_OK;
}

/*
 * Room for element n of an array of elem-byte elements at v (capacity
 * *cap), doubling from one, each time into a new block rather than by
 * realloc: an import keeps the heap traffic the engine's memory figures
 * have always been measured with (load.c).  NULL when out of memory (v
 * is then kept).
 */
static void *grow(void *v, size_t n, size_t *cap, size_t elem)
{
	if (n < *cap)
		return v;
	size_t ncap = *cap ? 2 * *cap : 1;
	void *nv = malloc(ncap * elem);
	if (!nv)
		return NULL;
	if (n)
		memcpy(nv, v, n * elem);
	free(v);
	*cap = ncap;
	return nv;
}

/* The roots to walk. */
typedef struct int_list {
	int *v;
	size_t n, cap;
} int_list;

static int int_push(int_list *l, int x)
{
	int *v = grow(l->v, l->n, &l->cap, sizeof(*v));
	if (!v)
		return 0;
	l->v = v;
	l->v[l->n++] = x;
	return 1;
}

/* n flags, all set. */
static char *flags_set(size_t n)
{
	char *p = malloc(n);
	if (p)
		memset(p, 1, n);
	return p;
}

static rad_status nomem(rad_error *err)
{
	return rad_fail(err, RAD_ERR_NOMEM,
	                "out of memory while importing glTF");
}

/* Roots to walk: the default scene, else scene 0, else every root node. */
static rad_status scene_roots(const sio_doc *d, int_list *roots, rad_error *err)
{
	int sc = d->default_scene;
	if (sc < -1 || (sc >= 0 && (size_t)sc >= d->nscenes))
		return rad_fail(err, RAD_ERR_INVALID,
		                "default scene %d out of range (%zu scenes)",
		                sc, d->nscenes);
	if (sc == -1 && d->nscenes)
		sc = 0;
	if (sc >= 0) {
		const sio_doc_scene *s = &d->scenes[sc];
		for (size_t k = 0; k < s->nnodes; k++) {
			int ni = s->nodes[k];
			if (ni < 0 || (size_t)ni >= d->nnodes)
				return rad_fail(err, RAD_ERR_INVALID,
				                "scene %d: node %d out of "
				                "range (%zu nodes)",
				                sc, ni, d->nnodes);
			if (!int_push(roots, ni))
				return nomem(err);
		}
		return RAD_OK;
	}
	if (d->nnodes == 0)
		return RAD_OK;
	/* Every node is a root until it is found to be a child. */
	char *root = flags_set(d->nnodes);
	if (!root)
		return nomem(err);
	for (size_t ni = 0; ni < d->nnodes; ni++)
		for (size_t k = 0; k < d->nodes[ni].nchildren; k++) {
			int c = d->nodes[ni].children[k];
			if (c >= 0 && (size_t)c < d->nnodes)
				root[c] = 0;
		}
	rad_status st = RAD_OK;
	for (size_t ni = 0; ni < d->nnodes && !st; ni++)
		if (root[ni] && !int_push(roots, (int)ni))
			st = nomem(err);
	free(root);
	return st;
}

/* The walk's stack: nodes still to visit with their parent's transform. */
typedef struct item {
	int node;
	sio_mat4 parent;
} item;

typedef struct stack {
	item *v;
	size_t n, cap;
} stack;

static int push(stack *s, int node, const sio_mat4 *parent)
{
	item *v = grow(s->v, s->n, &s->cap, sizeof(*v));
	if (!v)
		return 0;
	s->v = v;
	s->v[s->n].node = node;
	s->v[s->n].parent = *parent;
	s->n++;
	return 1;
}

/* Visit the node on top of the stack, then stack its children. */
static rad_status step(const sio_doc *d, stack *stk, char *unseen,
                       sio_visit visit, void *ud, rad_error *err)
{
	item it = stk->v[--stk->n];
	if (!unseen[it.node])
		return rad_fail(err, RAD_ERR_INVALID,
		                "node %d '%s' is reached twice (cycle or "
		                "shared child)",
		                it.node, sio_node_name(d, it.node));
	unseen[it.node] = 0;
	sio_mat4 local;
	rad_status st = node_local(d, it.node, &local, err);
	if (st != RAD_OK)
		return st;
	sio_mat4 world = mat_mul(&it.parent, &local);
	st = visit(ud, it.node, &world);
	const sio_doc_node *n = &d->nodes[(size_t)it.node];
	for (size_t k = n->nchildren; st == RAD_OK && k-- > 0;) {
		int c = n->children[k];
		if (c < 0 || (size_t)c >= d->nnodes)
			return rad_fail(err, RAD_ERR_INVALID,
			                "node %d '%s': child %d out of range "
			                "(%zu nodes)",
			                it.node, sio_node_name(d, it.node), c,
			                d->nnodes);
		if (!push(stk, c, &world))
			return nomem(err);
	}
	return st;
}

rad_status sio_walk(const sio_doc *d, sio_visit visit, void *ud, rad_error *err)
{
	int_list roots = {0};
	stack stk = {0};
	char *unseen = NULL;
	rad_status st = scene_roots(d, &roots, err);
	if (st == RAD_OK && d->nnodes && !(unseen = flags_set(d->nnodes)))
		st = nomem(err);
	sio_mat4 id = mat_identity();
	for (size_t k = roots.n; st == RAD_OK && k-- > 0;)
		if (!push(&stk, roots.v[k], &id))
			st = nomem(err);
	while (st == RAD_OK && stk.n)
		st = step(d, &stk, unseen, visit, ud, err);
	free(stk.v);
	free(unseen);
	free(roots.v);
	return st;
}
