/*
 * progressive.c -- progressive refinement radiosity (Cohen, Chen, Wallace
 * and Greenberg 1988): the patches holding the most unshot power shoot it
 * to every receiver, and receivers are subdivided where the light they
 * receive varies.  Memory is O(elements): no form factor is stored, each
 * shot recomputes the ones it needs.  The solution is usable after every
 * step and converges to the same answer as the matrix solver.
 *
 * DESIGN
 * Shooters ("patches") are the leaves of a uniform mesh made at init
 * (edge mesh_edge_rel x diagonal); they never change.  Receivers are the
 * leaves below the patches, refined as shots demand.  Per patch, in
 * double: unshot radiosity U (E at start, then the area-weighted reflected
 * part of what its leaves receive) and the radiosity shot so far S.
 *
 * A step is one shot made of several sources, all evaluated together:
 *   - on the first step every scene light (lights shoot first);
 *   - a batch of patches, largest photopic power |luma(dB)| A of what
 *     they would shoot first (dB: U plus the overshoot below; ties to the
 *     lower index), until BATCH_FRACTION of the total or BATCH_MAX
 *     patches are taken.
 * Overshooting (Feda and Purgathofer 1992): a patch shoots U plus the
 * radiosity it can still expect to receive, rho x the ambient estimate of
 * Cohen et al. (mean unshot radiosity / (1 - mean reflectance)), and keeps
 * minus that amount as unshot.  Shooting any amount keeps the solution's
 * fixed point (B + (I - rho F)^-1 rho F U is invariant), so this only
 * changes the path: in enclosures it cuts the number of shots several
 * times; where the estimate was too high, the negative unshot is shot
 * back later.  Once U has mixed signs the ambient is about zero and the
 * tail converges as plain shooting does (a factor rho per pass over all
 * patches).  Published B is what leaves have received, never an ambient.
 *
 * Every receiver leaf gets the form factors of ff.c, the very ones the
 * matrix solver uses: rad_ff_patch_spread from each patch (exact kernel at
 * max(4, rcv_samples) receiver points, vis_samples shadow rays each),
 * rad_light_patch_spread from each light.  Both also give the spread of
 * the per-point values over the leaf.
 *
 * Adaptive subdivision: a leaf over which one source of the shot varies
 * (photopic irradiance spread over its points, times its area) by more
 * than eps x the total source flux is split (if rad_elem_can_split
 * allows), down to min_edge: the BFA oracle of the hierarchical solver
 * applied to the gradient of one shooter, as in the classic algorithm that
 * shoots one patch at a time.  Being relative to the total flux,
 * weak late shots rarely split anything.  A new child does not inherit
 * its parent's past irradiance (near an edge that would be wrong by
 * several per cent for good): it gathers it from the history -- every
 * light shot in earlier steps and every patch's S -- so each leaf always
 * holds what it would hold had it existed from the start.  The difference
 * with the parent's share goes to the patch's unshot radiosity, so energy
 * stays balanced.  That gather is O(patches) per child; splits come
 * mostly from the first, strong shots, when few patches have shot.
 *
 * Determinism and threads: receivers are evaluated in parallel, each
 * writing only its own item; splitting and applying the increments is a
 * serial pass in item order.  Cancellation is checked after each block of
 * the first evaluation round, before anything is modified, so a cancelled
 * step leaves the solver exactly as it was.
 *
 * Statistics: residual = |unshot| flux / flux shot so far (lights count
 * with the scene's flux estimate for them).  error_estimate is the
 * unshot-energy bound: the unshot flux U still to be delivered lands on
 * surfaces of mean reflectance rho and each bounce keeps rho of it, so
 * about U / (1 - rho) of irradiance flux is still to come; it is reported
 * relative to the irradiance flux delivered so far.
 *
 * Memory: the per-patch arrays live as long as the solver and are counted
 * as ELEM_SURFACE (per-element data); shooters and receiver items are
 * SCRATCH, freed at the end of the step.
 */
#include <math.h>
#include <string.h>

#include "ff.h"
#include "solver.h"
#include "vis.h"

#define BATCH_FRACTION 0.5 /* share of the unshot power one step shoots */
#define BATCH_MAX 32       /* most patches shot in one step */
#define BLOCK_PAIRS 65536  /* receiver x source pairs between cancel checks */

typedef struct prog_impl {
	uint32_t npatch;
	uint32_t *patch;      /* element id of each shooter, mesh order */
	double *unshot;       /* 3 per patch: U, lux; < 0 after overshooting */
	double *shot;         /* 3 per patch: S, radiosity shot so far, lux */
	double area;          /* total patch area, m2 */
	double rho_mean;      /* area-weighted photopic reflectance */
	double light_flux;    /* photopic lm of the scene lights (estimate) */
	double flux_shot;     /* photopic lm shot so far */
	double flux_received; /* photopic lm received by leaves so far */
	int lights_shot;      /* the lights have shot (first step) */
} prog_impl;

/* One source of a shot: a scene light or a patch. */
typedef struct shooter {
	uint32_t light; /* scene light index, RAD_NONE for a patch */
	uint32_t patch; /* patch index (patch sources) */
	uint32_t poly;  /* the patch's polygon: coplanar receivers get 0 */
	rad_patch geom; /* patch geometry */
	double dB[3];   /* radiosity shot, lux */
	double keep[3]; /* unshot left on the patch: minus the overshoot */
} shooter;

/* One receiver leaf in an evaluation round; written by one index only. */
typedef struct rcv_item {
	uint32_t elem;   /* leaf element id */
	uint32_t patch;  /* index of the patch it lies in */
	int fresh;       /* a new child: gathers its past irradiance first */
	uint32_t parent; /* fresh: the element it was split from */
	double past[3];  /* fresh: irradiance from all earlier shots, lux */
	double dI[3];    /* irradiance received from this shot, lux */
	double spread;   /* largest photopic spread one source gives, lux */
	uint64_t rays;
} rcv_item;

typedef struct shot {
	const rad_solver *sv;
	const prog_impl *p;
	const shooter *src;
	uint32_t nsrc;
	int lights_past; /* the lights shot in an earlier step */
	rcv_item *item;  /* the current round */
	size_t off;      /* first item of the current parallel block */
} shot;

static void prog_destroy(rad_solver *sv)
{
	prog_impl *p = sv->impl;
	if (!p)
		return;
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_SURFACE, p->patch);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_SURFACE, p->unshot);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_SURFACE, p->shot);
	rad_mem_free(&sv->mem, RAD_MEM_ELEM_SURFACE, p);
	sv->impl = NULL;
}

/* Leaf ids below element id, depth first; counted only when out is NULL. */
static void leaf_ids(const rad_hier *h, uint32_t id, uint32_t *out, uint32_t *n)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (rad_elem_is_leaf(e)) {
		if (out)
			out[*n] = id;
		(*n)++;
		return;
	}
	for (uint32_t k = 0; k < 4; k++)
		leaf_ids(h, e->child + k, out, n);
}

static rad_status prog_init(rad_solver *sv, rad_error *err)
{
	const rad_scene *s = sv->scene;
	rad_hier *h = &sv->h;
	rad_status st =
	        rad_hier_mesh_uniform(h, sv->opt.mesh_edge_rel * s->diag, err);
	if (st != RAD_OK)
		return st;
	prog_impl *p =
	        rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_SURFACE, 1, sizeof(*p));
	if (!p)
		return rad_fail(err, RAD_ERR_NOMEM, "progressive: state");
	sv->impl = p;
	for (uint32_t i = 0; i < s->npolys; i++)
		leaf_ids(h, i, NULL, &p->npatch);
	uint32_t np = p->npatch;
	p->patch = rad_mem_alloc(&sv->mem, RAD_MEM_ELEM_SURFACE,
	                         sizeof(uint32_t) * np);
	p->unshot = rad_mem_alloc(&sv->mem, RAD_MEM_ELEM_SURFACE,
	                          sizeof(double) * 3 * np);
	p->shot = rad_mem_calloc(&sv->mem, RAD_MEM_ELEM_SURFACE, 3 * (size_t)np,
	                         sizeof(double));
	if (!p->patch || !p->unshot || !p->shot) {
		prog_destroy(sv);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "progressive: radiosity of %u patches", np);
	}
	uint32_t n = 0;
	for (uint32_t i = 0; i < s->npolys; i++)
		leaf_ids(h, i, p->patch, &n);
	double rho = 0, emitted = 0;
	for (uint32_t i = 0; i < np; i++) {
		uint32_t e = p->patch[i];
		const rad_material *m = rad_elem_mat(h, e);
		for (int k = 0; k < 3; k++)
			p->unshot[3 * i + k] = m->emit[k];
		p->area += rad_elem_area(h, e);
		rho += rad_elem_area(h, e) * rad_luma(m->rho);
		emitted += rad_elem_area(h, e) * rad_luma(m->emit);
	}
	p->rho_mean = p->area > 0 ? rho / p->area : 0;
	p->light_flux = fmax(0, sv->flux_scale - emitted);
	return RAD_OK;
}

/* ---------------------------------------------------------- the sources */

/*
 * What patch i would shoot, its unshot radiosity plus the overshoot
 * rho x amb, into dB; returns its photopic power |luma(dB)| A.  With amb
 * zero, the power of the unshot radiosity itself.
 */
static double would_shoot(const rad_solver *sv, const prog_impl *p, uint32_t i,
                          const double amb[3], double dB[3])
{
	uint32_t e = p->patch[i];
	const rad_material *m = rad_elem_mat(&sv->h, e);
	for (int k = 0; k < 3; k++)
		dB[k] = p->unshot[3 * (size_t)i + k] + m->rho[k] * amb[k];
	return fabs(rad_luma3(dB)) * rad_elem_area(&sv->h, e);
}

/* Cohen's ambient estimate: the radiosity all unshot energy will still
 * add on average, bounces included (never negative). */
static void ambient(const rad_solver *sv, const prog_impl *p, double amb[3])
{
	double sum[3] = {0, 0, 0};
	for (uint32_t i = 0; i < p->npatch; i++) {
		double a = rad_elem_area(&sv->h, p->patch[i]);
		for (int k = 0; k < 3; k++)
			sum[k] += a * p->unshot[3 * i + k];
	}
	double r = 1.0 / (p->area * (1 - fmin(p->rho_mean, 0.99)));
	for (int k = 0; k < 3; k++)
		amb[k] = fmax(0, sum[k] * r);
}

static void patch_source(const rad_solver *sv, const prog_impl *p, uint32_t i,
                         const double amb[3], shooter *s)
{
	uint32_t e = p->patch[i];
	s->light = RAD_NONE;
	s->patch = i;
	s->poly = rad_elem_poly(&sv->h, e);
	rad_elem_patch(&sv->h, e, &s->geom);
	would_shoot(sv, p, i, amb, s->dB);
	for (int k = 0; k < 3; k++)
		s->keep[k] = p->unshot[3 * (size_t)i + k] - s->dB[k];
}

/*
 * The batch: patches in order of decreasing power of what they would
 * shoot, ties to the lower index.  Each pass takes the largest entry that
 * comes after the previous pick in that order, so no list of picks needs
 * searching.
 */
static uint32_t pick_patches(const rad_solver *sv, const prog_impl *p,
                             shooter *src, double *flux)
{
	double total = 0, taken = 0, prev_w = INFINITY, amb[3], dB[3];
	uint32_t prev_i = 0, n = 0;
	ambient(sv, p, amb);
	for (uint32_t i = 0; i < p->npatch; i++)
		total += would_shoot(sv, p, i, amb, dB);
	while (n < BATCH_MAX && taken < BATCH_FRACTION * total) {
		uint32_t best = RAD_NONE;
		double best_w = 0;
		for (uint32_t i = 0; i < p->npatch; i++) {
			double w = would_shoot(sv, p, i, amb, dB);
			int after = w < prev_w || (w == prev_w && i > prev_i);
			if (after && w > best_w) {
				best = i;
				best_w = w;
			}
		}
		if (best == RAD_NONE)
			break;
		patch_source(sv, p, best, amb, &src[n++]);
		taken += best_w;
		prev_w = best_w;
		prev_i = best;
	}
	*flux += taken;
	return n;
}

/* Lights (until they have shot) then a batch of patches; *flux receives
 * the photopic flux they carry. */
static uint32_t gather_sources(const rad_solver *sv, const prog_impl *p,
                               shooter *src, double *flux)
{
	const rad_scene *s = sv->scene;
	uint32_t n = 0;
	*flux = 0;
	if (!p->lights_shot) {
		for (uint32_t l = 0; l < s->nlights; l++)
			src[n++] = (shooter){.light = l,
			                     .patch = RAD_NONE,
			                     .poly = RAD_NONE};
		*flux += p->light_flux;
	}
	return n + pick_patches(sv, p, src + n, flux);
}

/* ------------------------------------------------------- the receivers */

/* Append the leaves below element id as receiver items of patch. */
static void leaf_items(const rad_hier *h, uint32_t id, uint32_t patch,
                       rcv_item *out, size_t *n)
{
	const rad_elem *e = rad_elem_at(h, id);
	if (rad_elem_is_leaf(e)) {
		out[(*n)++] = (rcv_item){.elem = id, .patch = patch};
		return;
	}
	for (uint32_t k = 0; k < 4; k++)
		leaf_items(h, e->child + k, patch, out, n);
}

/* Round-one items: every leaf below every patch (SCRATCH), or NULL. */
static rcv_item *collect_receivers(rad_solver *sv, const prog_impl *p,
                                   size_t *n)
{
	uint32_t count = 0;
	for (uint32_t i = 0; i < p->npatch; i++)
		leaf_ids(&sv->h, p->patch[i], NULL, &count);
	rcv_item *it =
	        rad_mem_alloc(&sv->mem, RAD_MEM_SCRATCH, sizeof(*it) * count);
	size_t k = 0;
	for (uint32_t i = 0; it && i < p->npatch; i++)
		leaf_items(&sv->h, p->patch[i], i, it, &k);
	*n = count;
	return it;
}

/* Receiver points: the solver's rcv_samples, at least 4 so that the
 * spread over the leaf is measured. */
static int rcv_points(const rad_solver *sv)
{
	return sv->opt.rcv_samples > 4 ? sv->opt.rcv_samples : 4;
}

/* Past irradiance of a fresh leaf: earlier lights and every patch's S. */
static void eval_past(const shot *sh, rcv_item *it, const rad_patch *r,
                      uint32_t poly)
{
	const rad_solver *sv = sh->sv;
	const rad_scene *s = sv->scene;
	int nrcv = rcv_points(sv);
	memset(it->past, 0, sizeof(it->past));
	for (uint32_t l = 0; sh->lights_past && l < s->nlights; l++) {
		const rad_light *L = &s->lights[l];
		double g = rad_light_patch(s->vis, L, r, nrcv, &it->rays);
		for (int c = 0; c < 3; c++)
			it->past[c] += g * L->intensity[c];
	}
	for (uint32_t j = 0; j < sh->p->npatch; j++) {
		const double *S = sh->p->shot + 3 * (size_t)j;
		uint32_t e = sh->p->patch[j];
		if (rad_elem_poly(&sv->h, e) == poly ||
		    (S[0] == 0 && S[1] == 0 && S[2] == 0))
			continue;
		rad_patch g;
		rad_elem_patch(&sv->h, e, &g);
		double f = rad_ff_patch(s->vis, r, &g, nrcv,
		                        sv->opt.vis_samples, &it->rays);
		for (int c = 0; c < 3; c++)
			it->past[c] += f * S[c];
	}
}

/*
 * This shot's irradiance on a leaf, and the largest spread over the leaf's
 * points that one of its sources gives: the test the classic algorithm,
 * one shooter at a time, would make.
 */
static void eval_item(const shot *sh, rcv_item *it)
{
	const rad_solver *sv = sh->sv;
	const rad_scene *s = sv->scene;
	uint32_t poly = rad_elem_poly(&sv->h, it->elem);
	int nrcv = rcv_points(sv);
	rad_patch r;
	rad_elem_patch(&sv->h, it->elem, &r);
	if (it->fresh)
		eval_past(sh, it, &r, poly);
	for (uint32_t i = 0; i < sh->nsrc; i++) {
		const shooter *src = &sh->src[i];
		const double *amount = src->dB;
		double f, spread;
		if (src->light != RAD_NONE) {
			const rad_light *L = &s->lights[src->light];
			amount = L->intensity;
			f = rad_light_patch_spread(s->vis, L, &r, nrcv, 0,
			                           &it->rays, &spread);
		} else if (src->poly != poly) { /* coplanar: nothing */
			f = rad_ff_patch_spread(s->vis, &r, &src->geom, nrcv,
			                        sv->opt.vis_samples, 0, 0,
			                        &it->rays, &spread);
		} else {
			continue;
		}
		for (int c = 0; c < 3; c++)
			it->dI[c] += f * amount[c];
		it->spread = fmax(it->spread, spread * fabs(rad_luma3(amount)));
	}
}

static void eval_range(void *ud, size_t begin, size_t end, int thread)
{
	const shot *sh = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++)
		eval_item(sh, &sh->item[sh->off + i]);
}

/* First round, in blocks: progress, and cancellation after each block
 * (stepping has checked before it); nothing is modified here. */
static rad_status eval_first_round(rad_solver *sv, shot *sh, size_t n,
                                   rad_error *err)
{
	size_t block = BLOCK_PAIRS / sh->nsrc;
	if (block < 64)
		block = 64;
	for (size_t off = 0; off < n; off += block) {
		size_t m = n - off < block ? n - off : block;
		sh->off = off;
		rad_par_for(sv->par, m, 4, eval_range, sh);
		rad_solver_progress(sv, (double)(off + m) / n);
		if (rad_solver_cancelled(sv))
			return rad_fail(err, RAD_ERR_CANCELLED,
			                "progressive: step cancelled before "
			                "shooting (%zu of %zu receivers done)",
			                off + m, n);
	}
	sh->off = 0;
	return RAD_OK;
}

/* ------------------------------------------------- applying the shot */

static int wants_split(const rad_hier *h, const rcv_item *it, double limit)
{
	return it->spread * rad_elem_area(h, it->elem) > limit &&
	       rad_elem_can_split(h, it->elem);
}

/* A fresh leaf takes its gathered past; what it holds beyond its share
 * of the parent's irradiance is reflected into its patch's unshot. */
static void adopt_past(rad_solver *sv, prog_impl *p, const rcv_item *it)
{
	rad_elem *e = rad_elem_at(&sv->h, it->elem);
	const rad_elem *parent = rad_elem_at(&sv->h, it->parent);
	const rad_material *m = rad_elem_mat(&sv->h, it->elem);
	double w = rad_elem_area(&sv->h, it->elem) /
	           rad_elem_area(&sv->h, p->patch[it->patch]);
	double *U = p->unshot + 3 * (size_t)it->patch;
	for (int k = 0; k < 3; k++) {
		U[k] += m->rho[k] * (it->past[k] - parent->I[k]) * w;
		e->I[k] = (float)it->past[k];
		e->B[k] = (float)(m->emit[k] + m->rho[k] * it->past[k]);
	}
}

/* Add a leaf's increment to its irradiance, its radiosity and the unshot
 * radiosity of its patch (area-weighted: the patch shoots its average). */
static void apply(rad_solver *sv, prog_impl *p, const rcv_item *it)
{
	rad_elem *e = rad_elem_at(&sv->h, it->elem);
	const rad_material *m = rad_elem_mat(&sv->h, it->elem);
	double w = rad_elem_area(&sv->h, it->elem) /
	           rad_elem_area(&sv->h, p->patch[it->patch]);
	double *U = p->unshot + 3 * (size_t)it->patch;
	for (int k = 0; k < 3; k++) {
		double I = e->I[k] + it->dI[k];
		e->I[k] = (float)I;
		e->B[k] = (float)(m->emit[k] + m->rho[k] * I);
		U[k] += m->rho[k] * it->dI[k] * w;
	}
	p->flux_received += rad_luma3(it->dI) * rad_elem_area(&sv->h, it->elem);
}

/*
 * Settle one round in item order: split the leaves that ask for it (their
 * children are queued in next, fresh) and apply the others.  next == NULL
 * means no splitting (none wanted, or no memory for the queue).  Returns
 * the number of children queued.
 */
static size_t settle_round(rad_solver *sv, prog_impl *p, const rcv_item *item,
                           size_t n, rcv_item *next, int *nomem, uint64_t *rays)
{
	rad_hier *h = &sv->h;
	double limit = sv->opt.eps * sv->flux_scale;
	size_t nn = 0;
	for (size_t i = 0; i < n; i++) {
		const rcv_item *it = &item[i];
		uint32_t c = RAD_NONE;
		*rays += it->rays;
		if (it->fresh)
			adopt_past(sv, p, it);
		if (next && wants_split(h, it, limit)) {
			c = rad_elem_split(h, it->elem);
			*nomem |= c == RAD_NONE;
		}
		if (c == RAD_NONE) {
			apply(sv, p, it);
			continue;
		}
		for (uint32_t k = 0; k < 4; k++)
			next[nn++] = (rcv_item){.elem = c + k,
			                        .patch = it->patch,
			                        .fresh = 1,
			                        .parent = it->elem};
	}
	return nn;
}

/* The point of no return: the sources' energy leaves them. */
static void commit_sources(prog_impl *p, const shot *sh, double flux)
{
	for (uint32_t i = 0; i < sh->nsrc; i++)
		if (sh->src[i].light == RAD_NONE)
			memcpy(p->unshot + 3 * (size_t)sh->src[i].patch,
			       sh->src[i].keep, sizeof(sh->src[i].keep));
	p->lights_shot = 1;
	p->flux_shot += flux;
}

/* Once every round is settled the shot becomes history for later splits. */
static void record_history(prog_impl *p, const shot *sh)
{
	for (uint32_t i = 0; i < sh->nsrc; i++) {
		const shooter *s = &sh->src[i];
		for (int k = 0; s->light == RAD_NONE && k < 3; k++)
			p->shot[3 * (size_t)s->patch + k] += s->dB[k];
	}
}

static rad_status shoot(rad_solver *sv, prog_impl *p, shot *sh, double flux,
                        uint64_t *rays, rad_error *err)
{
	size_t n;
	rcv_item *item = collect_receivers(sv, p, &n);
	if (!item)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "progressive: %zu receiver work items", n);
	sh->item = item;
	rad_status st = eval_first_round(sv, sh, n, err);
	if (st != RAD_OK) {
		rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, item);
		return st;
	}
	commit_sources(p, sh, flux);
	int nomem = 0;
	double limit = sv->opt.eps * sv->flux_scale;
	while (n > 0) {
		size_t want = 0;
		for (size_t i = 0; i < n; i++)
			want += (size_t)wants_split(&sv->h, &item[i], limit);
		rcv_item *next = NULL;
		if (want) {
			next = rad_mem_calloc(&sv->mem, RAD_MEM_SCRATCH,
			                      4 * want, sizeof(*next));
			nomem |= next == NULL;
		}
		size_t nn = settle_round(sv, p, item, n, next, &nomem, rays);
		rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, item);
		item = next;
		n = nn;
		sh->item = item;
		if (n)
			rad_par_for(sv->par, n, 1, eval_range, sh);
	}
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, item);
	record_history(p, sh);
	if (nomem)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "progressive: out of memory subdividing "
		                "receivers (the shot was applied unrefined)");
	return RAD_OK;
}

/* ------------------------------------------------------------ the step */

static void publish(rad_solver *sv, const prog_impl *p, uint64_t rays)
{
	rad_hier_pull(&sv->h);
	const double none[3] = {0, 0, 0};
	double unshot = 0, dB[3];
	for (uint32_t i = 0; i < p->npatch; i++)
		unshot += would_shoot(sv, p, i, none, dB);
	rad_stats *st = &sv->stats;
	st->residual = p->flux_shot > 0 ? unshot / p->flux_shot : 0;
	double reach = unshot / (1 - fmin(p->rho_mean, 0.99));
	if (p->flux_received > 0)
		st->error_estimate = reach / p->flux_received;
	else
		st->error_estimate = unshot > 0 ? 1 : 0;
	st->rays = rays;
}

static rad_status prog_step(rad_solver *sv, rad_error *err)
{
	prog_impl *p = sv->impl;
	uint32_t cap = (p->lights_shot ? 0 : sv->scene->nlights) + BATCH_MAX;
	shooter *src =
	        rad_mem_alloc(&sv->mem, RAD_MEM_SCRATCH, sizeof(*src) * cap);
	if (!src)
		return rad_fail(err, RAD_ERR_NOMEM, "progressive: %u sources",
		                cap);
	double flux;
	shot sh = {.sv = sv, .p = p, .src = src, .lights_past = p->lights_shot};
	sh.nsrc = gather_sources(sv, p, src, &flux);
	uint64_t rays = 0;
	rad_status st = RAD_OK;
	if (sh.nsrc)
		st = shoot(sv, p, &sh, flux, &rays, err);
	rad_mem_free(&sv->mem, RAD_MEM_SCRATCH, src);
	publish(sv, p, rays);
	return st;
}

const rad_solver_ops rad_solver_progressive_ops = {
        .name = "progressive",
        .init = prog_init,
        .step = prog_step,
        .destroy = prog_destroy,
};
