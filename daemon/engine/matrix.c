/*
 * matrix.c -- matrix radiosity: the full form-factor matrix on a fixed mesh,
 * solved by Gauss-Seidel.  This is the exact reference the other solvers
 * are checked against on small scenes: no refinement oracle, no cluster
 * approximation, every pair of elements exchanges through its own form
 * factor.  Memory is O(N^2), so the solver refuses meshes whose matrix
 * would not fit a fixed cap.
 *
 * DESIGN
 * init meshes every polygon uniformly (edge mesh_edge_rel x diagonal),
 * lists the leaves once (their index is the matrix row/column) and fills
 *   F[i][j] = F(leaf i <- leaf j)   (rad_ff_patch, visibility included)
 *   Elight[i] = direct irradiance of leaf i from every scene light.
 * Each row is written by exactly one rad_par_for index, so the matrix is
 * the same bit for bit for any thread count.  Rows are built in batches
 * from the calling thread, which reports progress and checks the cancel
 * flag between batches; a cancelled build frees everything it made.
 *
 * step does one Gauss-Seidel sweep, all three channels in the same pass
 * over a row (the channels are independent systems, so this equals three
 * per-channel sweeps while reading the matrix once):
 *   I_i = Elight_i + sum_j F_ij B_j,   B_i = E_i + rho_i I_i
 * with B_j already updated for j < i.  The solution is kept in double here
 * and published as float into the leaves, then pulled up the hierarchy.
 * The sweep is sequential by nature; it is O(N^2) multiply-adds and cheap
 * next to the build.
 *
 * Memory: the matrix, the solution and the leaf list are RAD_MEM_MATRIX
 * (they live as long as the solver); the build's per-row counters and
 * patch copies are RAD_MEM_SCRATCH and are freed when init returns.
 */
#include <math.h>
#include <string.h>

#include "ff.h"
#include "solver.h"
#include "vis.h"

/* Largest form-factor matrix we agree to hold (4 bytes per entry). */
#define MATRIX_CAP_BYTES ((double)(2ull << 30))
/* Rows per parallel batch are chosen so a batch is about this many
 * element pairs: long enough to keep the workers busy, short enough that
 * progress and cancellation are seen every second or so. */
#define BATCH_PAIRS (1u << 20)

typedef struct matrix_impl {
	uint32_t n;     /* leaves = rows = columns */
	uint32_t *leaf; /* element id of each row */
	float *F;       /* n x n form factors, row-major */
	float *elight;  /* 3 per row: direct irradiance from lights, lux */
	double *B;      /* 3 per row: current solution, lux */
	uint64_t nnz;   /* non-zero F entries */
	uint64_t rays;  /* shadow rays of the build, reported by step 1 */
} matrix_impl;

/* Per-row results of the build, summed serially afterwards. */
typedef struct row_count {
	uint64_t rays;
	uint32_t nnz;
} row_count;

typedef struct build_ctx {
	const rad_solver *sv;
	matrix_impl *m;
	const rad_patch *patch; /* n patches, row order */
	row_count *count;       /* n */
	size_t row0;            /* first row of the current batch */
	double eps;             /* facing-test tolerance, metres */
} build_ctx;

static void impl_free(rad_solver *sv, matrix_impl *m)
{
	if (!m)
		return;
	rad_mem_free(&sv->mem, RAD_MEM_MATRIX, m->leaf);
	rad_mem_free(&sv->mem, RAD_MEM_MATRIX, m->F);
	rad_mem_free(&sv->mem, RAD_MEM_MATRIX, m->elight);
	rad_mem_free(&sv->mem, RAD_MEM_MATRIX, m->B);
	rad_mem_free(&sv->mem, RAD_MEM_MATRIX, m);
}

static void matrix_destroy(rad_solver *sv)
{
	impl_free(sv, sv->impl);
	sv->impl = NULL;
}

/*
 * Leaves the uniform mesh will make, computed before meshing so an
 * oversized request is refused before it costs memory.  Mirrors
 * rad_hier_mesh_uniform: an element splits while its longest edge exceeds
 * both the target and min_edge, and each split halves every edge exactly.
 */
static double predicted_leaves(const rad_hier *h, double edge)
{
	double total = 0;
	for (uint32_t i = 0; i < h->scene->npolys; i++) {
		double len = rad_elem_edge(h, i), leaves = 1;
		while (len > edge && len > h->min_edge && leaves < 1e12) {
			len *= 0.5;
			leaves *= 4;
		}
		total += leaves;
	}
	return total;
}

static rad_status check_size(double n, rad_error *err)
{
	double bytes = 4.0 * n * n;
	if (bytes <= MATRIX_CAP_BYTES)
		return RAD_OK;
	return rad_fail(err, RAD_ERR_LIMIT,
	                "matrix solver: %.0f elements need %.2f GiB of form "
	                "factors (cap %.0f GiB); raise mesh_edge_rel or use "
	                "the hr solver",
	                n, bytes / (1u << 30), MATRIX_CAP_BYTES / (1u << 30));
}

/* Depth-first walk below a polygon root, appending leaves in order. */
static void collect_leaves(const rad_hier *h, uint32_t id, uint32_t *out,
                           uint32_t *n)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (rad_elem_is_leaf(e)) {
		out[(*n)++] = id;
		return;
	}
	for (uint32_t k = 0; k < 4; k++)
		collect_leaves(h, e->child + k, out, n);
}

/* 1 if some vertex of b lies strictly in front of a's plane and vice
 * versa: pairs failing this exchange nothing (F = 0 without a ray). */
static int facing(const rad_patch *a, const rad_patch *b, double eps)
{
	v3 va[4], vb[4];
	int na = rad_patch_vertices(a, va), nb = rad_patch_vertices(b, vb);
	int ab = 0, ba = 0;
	for (int k = 0; k < nb && !ab; k++)
		ab = v3_dot(a->n, v3_sub(vb[k], a->p0)) > eps;
	for (int k = 0; k < na && !ba; k++)
		ba = v3_dot(b->n, v3_sub(va[k], b->p0)) > eps;
	return ab && ba;
}

static void build_row(const build_ctx *c, uint32_t i)
{
	const rad_solver *sv = c->sv;
	const rad_scene *s = sv->scene;
	const matrix_impl *m = c->m;
	const rad_patch *pi = &c->patch[i];
	float *row = m->F + (size_t)i * m->n;
	row_count *rc = &c->count[i];

	for (uint32_t j = 0; j < m->n; j++) {
		/* i == j: a planar element does not see itself. */
		if (j == i || !facing(pi, &c->patch[j], c->eps)) {
			row[j] = 0;
			continue;
		}
		row[j] = (float)rad_ff_patch(s->vis, pi, &c->patch[j],
		                             sv->opt.rcv_samples,
		                             sv->opt.vis_samples, &rc->rays);
		rc->nnz += row[j] != 0;
	}
	float *el = m->elight + 3 * (size_t)i;
	el[0] = el[1] = el[2] = 0;
	for (uint32_t l = 0; l < s->nlights; l++) {
		const rad_light *L = &s->lights[l];
		double g = rad_light_patch(s->vis, L, pi, sv->opt.rcv_samples,
		                           &rc->rays);
		for (int k = 0; k < 3; k++)
			el[k] += (float)(g * L->intensity[k]);
	}
}

static void build_range(void *ud, size_t begin, size_t end, int thread)
{
	const build_ctx *c = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++)
		build_row(c, (uint32_t)(c->row0 + i));
}

/* Fill F and Elight in batches; returns RAD_ERR_CANCELLED if asked to. */
static rad_status build_matrix(rad_solver *sv, matrix_impl *m,
                               const rad_patch *patch, row_count *count,
                               rad_error *err)
{
	build_ctx c = {sv, m, patch, count, 0, 1e-6 * sv->scene->diag};
	size_t batch = BATCH_PAIRS / (m->n ? m->n : 1);
	if (batch < 1)
		batch = 1;
	rad_solver_progress(sv, 0);
	for (size_t row0 = 0; row0 < m->n; row0 += batch) {
		if (rad_solver_cancelled(sv))
			return rad_fail(err, RAD_ERR_CANCELLED,
			                "matrix solver: build cancelled at "
			                "row %zu of %u",
			                row0, m->n);
		size_t rows = m->n - row0 < batch ? m->n - row0 : batch;
		c.row0 = row0;
		rad_par_for(sv->par, rows, 1, build_range, &c);
		rad_solver_progress(sv, (double)(row0 + rows) / m->n);
	}
	for (uint32_t i = 0; i < m->n; i++) {
		m->nnz += count[i].nnz;
		m->rays += count[i].rays;
	}
	return RAD_OK;
}

/* Allocate the solver state for n leaves and list them. */
static rad_status impl_alloc(rad_solver *sv, uint32_t n, matrix_impl **out,
                             rad_error *err)
{
	matrix_impl *m =
	        rad_mem_calloc(&sv->mem, RAD_MEM_MATRIX, 1, sizeof(*m));
	if (!m)
		return rad_fail(err, RAD_ERR_NOMEM, "matrix solver: state");
	m->leaf = rad_mem_alloc(&sv->mem, RAD_MEM_MATRIX, sizeof(uint32_t) * n);
	m->F = rad_mem_alloc(&sv->mem, RAD_MEM_MATRIX,
	                     sizeof(float) * (size_t)n * n);
	m->elight =
	        rad_mem_alloc(&sv->mem, RAD_MEM_MATRIX, sizeof(float) * 3 * n);
	m->B = rad_mem_alloc(&sv->mem, RAD_MEM_MATRIX, sizeof(double) * 3 * n);
	if (!m->leaf || !m->F || !m->elight || !m->B) {
		impl_free(sv, m);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "matrix solver: %u x %u form factors", n, n);
	}
	const rad_hier *h = &sv->h;
	for (uint32_t p = 0; p < sv->scene->npolys; p++)
		collect_leaves(h, p, m->leaf, &m->n);
	for (uint32_t i = 0; i < m->n; i++) {
		const rad_elem *e = rad_elem_at(h, m->leaf[i]);
		for (int k = 0; k < 3; k++)
			m->B[3 * i + k] = e->B[k]; /* = E after meshing */
	}
	*out = m;
	return RAD_OK;
}

static rad_status matrix_init(rad_solver *sv, rad_error *err)
{
	const rad_scene *s = sv->scene;
	double edge = sv->opt.mesh_edge_rel * s->diag;
	rad_status st = check_size(predicted_leaves(&sv->h, edge), err);
	if (st == RAD_OK)
		st = rad_hier_mesh_uniform(&sv->h, edge, err);
	if (st == RAD_OK)
		st = check_size(sv->h.nleaves, err);
	if (st != RAD_OK)
		return st;

	uint32_t n = sv->h.nleaves;
	matrix_impl *m = NULL;
	if ((st = impl_alloc(sv, n, &m, err)) != RAD_OK)
		return st;
	rad_patch *patch =
	        rad_mem_alloc(&sv->mem, RAD_MEM_SCRATCH, sizeof(*patch) * n);
	row_count *count =
	        rad_mem_calloc(&sv->mem, RAD_MEM_SCRATCH, n, sizeof(*count));
	if (!patch || !count) {
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "matrix solver: build scratch");
	} else {
		for (uint32_t i = 0; i < n; i++)
			rad_elem_patch(&sv->h, m->leaf[i], &patch[i]);
		st = build_matrix(sv, m, patch, count, err);
	}
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, patch);
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, count);
	if (st != RAD_OK) {
		impl_free(sv, m);
		return st;
	}
	sv->impl = m;
	return RAD_OK;
}

/* One Gauss-Seidel sweep; returns sum A |dB| and sum A B (photopic). */
static void sweep(rad_solver *sv, matrix_impl *m, double *change, double *level)
{
	const rad_hier *h = &sv->h;
	const uint32_t n = m->n;
	*change = *level = 0;
	for (uint32_t i = 0; i < n; i++) {
		const float *row = m->F + (size_t)i * n;
		double g[3] = {0, 0, 0};
		for (uint32_t j = 0; j < n; j++) {
			const double *Bj = m->B + 3 * (size_t)j;
			g[0] += row[j] * Bj[0];
			g[1] += row[j] * Bj[1];
			g[2] += row[j] * Bj[2];
		}
		rad_elem *e = rad_elem_at(h, m->leaf[i]);
		const rad_material *mat = rad_elem_mat(h, m->leaf[i]);
		double *Bi = m->B + 3 * (size_t)i;
		float dB[3], Bf[3];
		for (int k = 0; k < 3; k++) {
			double I = m->elight[3 * i + k] + g[k];
			double B = mat->emit[k] + mat->rho[k] * I;
			dB[k] = (float)(B - Bi[k]);
			Bi[k] = B;
			Bf[k] = (float)B;
			e->B[k] = (float)B;
			e->I[k] = (float)I;
		}
		*change += rad_elem_area(h, m->leaf[i]) * fabs(rad_luma(dB));
		*level += rad_elem_area(h, m->leaf[i]) * rad_luma(Bf);
	}
}

static rad_status matrix_step(rad_solver *sv, rad_error *err)
{
	matrix_impl *m = sv->impl;
	double change, level;
	(void)err;
	sweep(sv, m, &change, &level);
	rad_hier_pull(&sv->h);

	rad_solver_set_residual(sv, level > 0 ? change / level : 0);
	rad_stats *st = &sv->stats;
	st->links = st->links_ss = m->nnz;
	/* The rays were traced while building, before the first sweep. */
	st->rays = st->iteration == 0 ? m->rays : 0;
	return RAD_OK;
}

const rad_solver_ops rad_solver_matrix_ops = {
        .name = "matrix",
        .init = matrix_init,
        .step = matrix_step,
        .destroy = matrix_destroy,
};
