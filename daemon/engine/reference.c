/*
 * reference.c -- an independent Monte Carlo estimate of illuminance at
 * points (rad_reference_illuminance): the ground truth the radiosity
 * solvers are validated against.
 *
 * It shares nothing with the solvers but the scene model (scene.h) and the
 * Embree BVH (vis.h): no form factors, no hierarchy, none of the light code
 * of ff.c.  The light model is re-derived here from its definition, so that
 * a mistake in the solvers' version cannot hide in both:
 *   surfaces: Lambertian and one-sided.  The front of a polygon is the side
 *            of e1 x e2; only the front emits (radiance emit / pi, emit
 *            being the exitance in lux) and reflects (rho); a ray meeting
 *            a back face is absorbed.
 *   point:   E = I cos / d^2 x glTF's range window
 *            clamp(1 - (d / range)^4, 0, 1) (range 0 = none);
 *   spot:    the same x s^2, s = clamp((cos_axis - cos_outer) /
 *            (cos_inner - cos_outer), 0, 1) (glTF's smooth cone falloff;
 *            a hard edge when the two cones are equal);
 *   directional: E = I cos on a plane at angle theta, visible when a ray
 *            towards the light escapes the scene.
 *
 * DESIGN
 * Estimator.  E(x) = \int_H L(x, w) cos dw = pi \int_H L (cos / pi) dw:
 * the point is a white Lambertian vertex (albedo 1) and E is pi times the
 * radiance a path tracer finds there.  Every vertex v (the point, then
 * each front-face hit) with albedo a (rho per channel; 1 at the point)
 * adds, times the path throughput beta:
 *   - next-event estimation to the emitting polygons: one polygon drawn
 *     with probability luma(emit) x area / total, a uniform point y on it,
 *     (a / pi) (emit / pi) cos_v cos_y / (r^2 pdf_A) x visibility, weighted
 *     by the power heuristic against the cosine sampling below;
 *   - every punctual and directional light, deterministically, one shadow
 *     ray each (at the point itself once per point, not per path: the
 *     value is the same for every path);
 *   - the emission of the polygon the cosine-sampled bounce ray hits,
 *     weighted by the power heuristic against the emitter sampling.
 * The bounce multiplies beta by a (f cos / pdf for a Lambertian f = a / pi
 * and pdf = cos / pi).  Russian roulette then keeps the path with
 * probability q = min(1, max channel of beta) and divides beta by q:
 * unbiased, and with rho = 0.99 a path ends after 100 bounces on average.
 * MIS makes both hard cases cheap: points very near a large emitter (the
 * bounce ray finds it) and tiny emitters (emitter sampling finds them).
 * Paths stop after MAX_DEPTH bounces whatever the roulette says, a bias
 * below rho_max^MAX_DEPTH of the reflected light (0 in double at 0.99).
 *
 * Error.  Each path gives one photopic value (RGB traced per channel, then
 * luma); a point's estimate is their mean and its standard error
 * sqrt(var / n) from the sample variance.  Target mode plans FIRST_PATHS
 * paths per point, then, each time a point's plan is used up, more from
 * its variance, until stderr <= target x mean (or max_samples).
 *
 * Determinism.  Path j of point i draws its random numbers from a
 * counter-based generator keyed by (seed, i, j) (a splitmix64 stream from a
 * hashed key), so a path does not depend on which thread traces it.  Work
 * is cut into chunks of CHUNK paths of one point, handed out in rounds of
 * at most ROUND_CHUNKS (one parallel loop each; bounded scratch whatever
 * the path counts); each chunk keeps its own (n, mean, M2) in its own
 * slot, and a point merges its chunks in path order after the loop
 * (Chan's pairwise update).  Plans are made from the merged values only.
 * Results are therefore bit for bit the same for any thread count and
 * schedule.
 *
 * Rays leave surfaces as vis.c's do: the origin is moved eps (rad_vis_eps)
 * along the front normal and the ray starts at tnear = eps.  Bounce rays
 * use rad_vis_first_hit_front, which shows the front of a two-sided face
 * written as two coincident opposite triangles.  Scratch memory is counted
 * (kind SCRATCH) in a counter set of this call and freed before it returns.
 */
#include <math.h>
#include <stdatomic.h>
#include <string.h>

#if defined(__SSE__)
#include <xmmintrin.h>
#endif

#include "moments.h"
#include "par.h"
#include "rad.h"
#include "rad_reference.h"
#include "rng.h"
#include "scene.h"
#include "vis.h"

#define CHUNK 128         /* paths per work item */
#define ROUND_CHUNKS 8192 /* work items per parallel loop (a round) */
#define FIRST_PATHS 1024  /* target mode: paths per point in round 1 */
#define GROWTH_MAX 4      /* a new plan at most quadruples the paths */
#define NEED_MARGIN 1.1   /* aim this much past the predicted need */
#define MAX_DEPTH 65536   /* bounces; see the DESIGN note */
#define DEFAULT_TARGET 0.005
#define DEFAULT_MAX_SAMPLES (1ull << 22)
#define MAX_PATHS (1ull << 40) /* per point: keeps counts exact in double */

/* --------------------------------------------------------------- random */

typedef struct rng {
	uint64_t state;
} rng;

/* The stream of path `path` of point `point`. */
static rng rng_key(uint64_t seed, uint64_t point, uint64_t path)
{
	uint64_t k = rad_mix64(seed + RAD_GOLDEN);
	k = rad_mix64(k ^ (point * 0xD1B54A32D192ED03ull));
	k = rad_mix64(k ^ (path * 0x8CB92BA72F3D8DD7ull));
	rng r = {k};
	return r;
}

/* Uniform in [0, 1), 53 bits. */
static double rng_next(rng *r)
{
	return rad_uniform(&r->state);
}

/* ---------------------------------------------------------------- scene */

/* The emitting polygons, for next-event estimation. */
typedef struct emitters {
	uint32_t *poly;   /* emitting polygons */
	double *cdf;      /* cumulative share of luma(emit) x area */
	uint32_t n;       /* 0: no emitting polygon */
	double inv_power; /* 1 / sum luma(emit) x area */
} emitters;

/* What every path reads; shared read-only by the threads. */
typedef struct tracer {
	const rad_scene *s;
	const rad_vis *vis;
	double eps; /* rad_vis_eps */
	uint64_t seed;
	emitters em;
} tracer;

static double luma_f(const float c[3])
{
	const double d[3] = {c[0], c[1], c[2]};
	return rad_luma3(d);
}

static rad_status emitters_build(emitters *em, const rad_scene *s, rad_mem *mem,
                                 rad_error *err)
{
	uint32_t n = 0;
	for (uint32_t i = 0; i < s->npolys; i++)
		n += luma_f(s->mats[s->polys[i].mat].emit) > 0;
	em->n = n;
	if (n == 0)
		return RAD_OK;
	em->poly = rad_mem_alloc(mem, RAD_MEM_SCRATCH, n * sizeof(uint32_t));
	em->cdf = rad_mem_alloc(mem, RAD_MEM_SCRATCH, n * sizeof(double));
	if (!em->poly || !em->cdf)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "reference: out of memory for %u emitters", n);
	double sum = 0;
	uint32_t k = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		double w = luma_f(s->mats[p->mat].emit) * p->area;
		if (!(w > 0))
			continue;
		sum += w;
		em->poly[k] = i;
		em->cdf[k++] = sum;
	}
	for (k = 0; k < n; k++)
		em->cdf[k] /= sum;
	em->cdf[n - 1] = 1.0;
	em->inv_power = 1.0 / sum;
	return RAD_OK;
}

/* Index of the emitter whose cdf interval holds u. */
static uint32_t emitters_pick(const emitters *em, double u)
{
	uint32_t lo = 0, hi = em->n - 1;
	while (lo < hi) {
		uint32_t mid = lo + (hi - lo) / 2;
		if (u < em->cdf[mid])
			hi = mid;
		else
			lo = mid + 1;
	}
	return lo;
}

/* Area density of emitter sampling at any point of polygon p. */
static double emitter_pdf_area(const tracer *tr, const rad_poly *p)
{
	return luma_f(tr->s->mats[p->mat].emit) * tr->em.inv_power;
}

/* Uniform point on a polygon (triangle: the square-root warp). */
static v3 poly_sample(const rad_scene *s, const rad_poly *p, double u1,
                      double u2)
{
	if (p->quad)
		return rad_poly_point(s, p, u1, u2);
	double r = sqrt(u1);
	return rad_poly_point(s, p, r * (1.0 - u2), r * u2);
}

/* Cosine-weighted direction around unit n (Duff et al.'s basis). */
static v3 cosine_dir(v3 n, double u1, double u2)
{
	double sign = copysign(1.0, n.z);
	double a = -1.0 / (sign + n.z), b = n.x * n.y * a;
	v3 t = v3_make(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
	v3 bt = v3_make(b, sign + n.y * n.y * a, -n.y);
	double r = sqrt(u1), phi = 2.0 * M_PI * u2;
	v3 d = v3_scale(n, sqrt(fmax(0.0, 1.0 - u1)));
	d = v3_madd(d, t, r * cos(phi));
	return v3_madd(d, bt, r * sin(phi));
}

static double power_heuristic(double a, double b)
{
	return a * a / (a * a + b * b);
}

/* ---------------------------------------------------------------- lights */

static double range_window(double range, double d)
{
	if (!(range > 0))
		return 1.0;
	double q = d / range;
	q *= q;
	return fmin(1.0, fmax(0.0, 1.0 - q * q));
}

static double cone_falloff(const rad_light *L, double cos_axis)
{
	double span = L->cos_inner - L->cos_outer;
	if (!(span > 0))
		return cos_axis >= L->cos_inner ? 1.0 : 0.0;
	double s = fmin(1.0, fmax(0.0, (cos_axis - L->cos_outer) / span));
	return s * s;
}

/* Illuminance per unit intensity at x (unit normal n), shadows included. */
static double light_at_pos(const tracer *tr, const rad_light *L, v3 pos, v3 x,
                           v3 n);

/*
 * A luminous opening, sampled apart from the solvers' cells: with r, one
 * point uniform over it (a disk by rejection), an unbiased estimate; on
 * the first visit of a query point (r NULL), the mean over a fine grid
 * (OPENING_GRID a side), each sample with its own visibility.
 */
#define OPENING_GRID 24

static double opening_at(const tracer *tr, const rad_light *L, v3 x, v3 n,
                         rng *r)
{
	if (r) {
		double u, v;
		do {
			u = rng_next(r) - 0.5;
			v = rng_next(r) - 0.5;
		} while (L->opening_round && u * u + v * v > 0.25);
		return light_at_pos(tr, L, rad_light_opening_point(L, u, v), x,
		                    n);
	}
	double sum = 0;
	int m = 0;
	for (int i = 0; i < OPENING_GRID; i++)
		for (int j = 0; j < OPENING_GRID; j++) {
			double u = (i + 0.5) / OPENING_GRID - 0.5;
			double v = (j + 0.5) / OPENING_GRID - 0.5;
			if (L->opening_round && u * u + v * v > 0.25)
				continue;
			sum += light_at_pos(
			        tr, L, rad_light_opening_point(L, u, v), x, n);
			m++;
		}
	return sum / m;
}

static double light_at(const tracer *tr, const rad_light *L, v3 x, v3 n, rng *r)
{
	if (L->kind == RAD_LIGHT_DIRECTIONAL) {
		v3 to = v3_scale(v3_d(L->dir), -1.0);
		double c = v3_dot(to, n);
		if (!(c > 0) || !rad_vis_ray_free(tr->vis, x, &n, to))
			return 0.0;
		return c;
	}
	if (rad_light_has_opening(L))
		return opening_at(tr, L, x, n, r);
	return light_at_pos(tr, L, v3_d(L->pos), x, n);
}

/* A positional light L shining from pos. */
static double light_at_pos(const tracer *tr, const rad_light *L, v3 pos, v3 x,
                           v3 n)
{
	v3 d = v3_sub(pos, x);
	double dist = v3_len(d);
	if (!(dist > 0))
		return 0.0;
	double c = v3_dot(d, n) / dist;
	if (!(c > 0))
		return 0.0;
	double e = c / (dist * dist) * range_window(L->range, dist);
	if (L->kind == RAD_LIGHT_SPOT)
		e *= cone_falloff(L, -v3_dot(d, v3_d(L->dir)) / dist);
	else if (L->gonio) /* the one table lookup (gonio.c) */
		e *= rad_gonio_factor(L->gonio, v3_scale(d, -1.0 / dist));
	if (!(e > 0) || !rad_vis_segment(tr->vis, x, &n, pos, NULL))
		return 0.0;
	return e;
}

/* Sum over the punctual and directional lights, RGB lux, into e (r as
 * opening_at). */
static void lights_at(const tracer *tr, v3 x, v3 n, rng *r, double e[3])
{
	e[0] = e[1] = e[2] = 0.0;
	for (uint32_t i = 0; i < tr->s->nlights; i++) {
		const rad_light *L = &tr->s->lights[i];
		if (!(L->intensity[0] > 0 || L->intensity[1] > 0 ||
		      L->intensity[2] > 0))
			continue;
		double g = light_at(tr, L, x, n, r);
		for (int c = 0; c < 3; c++)
			e[c] += g * L->intensity[c];
	}
}

/* ------------------------------------------------------------------ paths */

/* A path vertex: a point with the side it sees and its albedo. */
typedef struct vertex {
	v3 x, n;      /* position, unit normal of the side it sees */
	double a[3];  /* albedo (rho; 1 at the measured point) */
	int is_point; /* the measured point: lights done once per point */
} vertex;

/*
 * Emitter NEE at v, MIS-weighted (w) against the cosine-sampled bounce:
 * adds the radiance v reflects towards the path,
 * beta (a / pi) (emit / pi) cos_v cos_y / (r^2 pdf_A) w, into sum.
 */
static void nee_emitter(const tracer *tr, const vertex *v, const double *beta,
                        rng *r, double sum[3])
{
	const emitters *em = &tr->em;
	const rad_poly *p =
	        &tr->s->polys[em->poly[emitters_pick(em, rng_next(r))]];
	double u1 = rng_next(r), u2 = rng_next(r);
	v3 y = poly_sample(tr->s, p, u1, u2), ny = rad_poly_normal(p);
	v3 d = v3_sub(y, v->x);
	double r2 = v3_dot(d, d);
	if (!(r2 > 0))
		return;
	double dist = sqrt(r2);
	double cv = v3_dot(d, v->n) / dist, cy = -v3_dot(d, ny) / dist;
	if (!(cv > 0 && cy > 0))
		return;
	double pdf_a = emitter_pdf_area(tr, p);
	double pdf_light = pdf_a * r2 / cy, pdf_bsdf = cv / M_PI;
	if (!rad_vis_segment(tr->vis, v->x, &v->n, y, &ny))
		return;
	double k = power_heuristic(pdf_light, pdf_bsdf) * cv / pdf_light /
	           (M_PI * M_PI);
	const float *emit = tr->s->mats[p->mat].emit;
	for (int c = 0; c < 3; c++)
		sum[c] += beta[c] * v->a[c] * emit[c] * k;
}

/* Direct light at a vertex: emitter NEE and (on surfaces) the lights.
 * A black vertex reflects nothing: no rays. */
static void direct_at(const tracer *tr, const vertex *v, const double *beta,
                      rng *r, double sum[3])
{
	if (!(v->a[0] > 0 || v->a[1] > 0 || v->a[2] > 0))
		return;
	if (tr->em.n)
		nee_emitter(tr, v, beta, r, sum);
	if (v->is_point || tr->s->nlights == 0)
		return;
	double e[3];
	lights_at(tr, v->x, v->n, r, e);
	for (int c = 0; c < 3; c++)
		sum[c] += beta[c] * v->a[c] / M_PI * e[c];
}

/* Russian roulette on beta; 0 ends the path. */
static int survive(double beta[3], rng *r)
{
	double q = fmin(1.0, fmax(beta[0], fmax(beta[1], beta[2])));
	if (!(q > 0))
		return 0;
	if (q < 1.0) {
		if (rng_next(r) >= q)
			return 0;
		for (int c = 0; c < 3; c++)
			beta[c] /= q;
	}
	return 1;
}

/*
 * Follow the bounce ray from v: adds the MIS-weighted emission of what it
 * hits and turns *v into the next vertex.  0 when the path ends (miss,
 * back face, black surface).
 */
static int bounce(const tracer *tr, vertex *v, double beta[3], rng *r,
                  double sum[3])
{
	double u1 = rng_next(r), u2 = rng_next(r);
	v3 dir = cosine_dir(v->n, u1, u2);
	double cv = v3_dot(dir, v->n);
	v3 org = v3_madd(v->x, v->n, tr->eps);
	double t;
	int front;
	uint32_t hit = rad_vis_first_hit_front(tr->vis, org, dir, tr->eps,
	                                       INFINITY, &t, &front);
	if (hit == UINT32_MAX || !front)
		return 0;
	const rad_poly *p = &tr->s->polys[hit];
	const rad_material *m = &tr->s->mats[p->mat];
	v3 ny = rad_poly_normal(p);
	if (tr->em.n && luma_f(m->emit) > 0) {
		double cy = -v3_dot(dir, ny);
		double w = 1.0;
		if (cy > 0 && t > 0)
			w = power_heuristic(cv / M_PI, emitter_pdf_area(tr, p) *
			                                       t * t / cy);
		for (int c = 0; c < 3; c++)
			sum[c] += beta[c] * m->emit[c] / M_PI * w;
	}
	v->x = v3_madd(org, dir, t);
	v->n = ny;
	v->is_point = 0;
	for (int c = 0; c < 3; c++)
		v->a[c] = m->rho[c];
	return 1;
}

/*
 * One path from the point (x, n): its RGB estimate of E(x) without the
 * lights at x itself (added once per point).
 */
static void trace_path(const tracer *tr, v3 x, v3 n, rng *r, double out[3])
{
	vertex v = {.x = x, .n = n, .a = {1, 1, 1}, .is_point = 1};
	double beta[3] = {1, 1, 1}, sum[3] = {0, 0, 0};
	for (int depth = 0; depth < MAX_DEPTH; depth++) {
		direct_at(tr, &v, beta, r, sum);
		for (int c = 0; c < 3; c++)
			beta[c] *= v.a[c];
		if (!survive(beta, r) || !bounce(tr, &v, beta, r, sum))
			break;
	}
	for (int c = 0; c < 3; c++)
		out[c] = M_PI * sum[c];
}

/* ------------------------------------------------------------ the driver */

/* One measured point. */
typedef struct point_state {
	v3 x, n;          /* position, unit normal */
	double direct;    /* lux from the lights at x (every path) */
	moments mo;       /* of the per-path lux, merged in path order */
	uint64_t paths;   /* traced and merged so far */
	uint64_t pending; /* planned, not yet handed out */
	int done;         /* no more paths will be planned */
} point_state;

/* A work item: paths [first, first + count) of one point. */
typedef struct chunk {
	uint32_t point;
	uint32_t count;
	uint64_t first;
	moments mo; /* the chunk's result */
} chunk;

typedef struct run {
	const tracer *tr;
	point_state *pt;
	size_t n;
	chunk *ck; /* ROUND_CHUNKS slots */
	const volatile int *cancel;
	_Atomic int cancelled;
} run;

static int cancel_raised(const volatile int *flag)
{
	return flag && __atomic_load_n((const int *)flag, __ATOMIC_RELAXED);
}

static void run_chunks(void *ud, size_t begin, size_t end, int thread)
{
	run *rn = ud;
	(void)thread;
	for (size_t i = begin; i < end; i++) {
		if (cancel_raised(rn->cancel)) {
			atomic_store(&rn->cancelled, 1);
			return;
		}
		chunk *c = &rn->ck[i];
		const point_state *ps = &rn->pt[c->point];
		c->mo = (moments){0, 0, 0};
		for (uint32_t j = 0; j < c->count; j++) {
			rng r = rng_key(rn->tr->seed, c->point, c->first + j);
			double rgb[3];
			trace_path(rn->tr, ps->x, ps->n, &r, rgb);
			moments_add(&c->mo, ps->direct + rad_luma3(rgb));
		}
	}
}

/*
 * Paths a point gets next in target mode, from its merged moments (0 =
 * done).  Aims NEED_MARGIN past the count the current variance predicts,
 * never more than GROWTH_MAX times what it has (an early variance
 * estimate can be far off), never past max.  Whole chunks but at the cap.
 */
static uint64_t plan_more(const point_state *ps, double target, uint64_t max)
{
	double se = moments_stderr(&ps->mo), mean = ps->mo.mean;
	if (ps->paths >= max || !(se > target * mean))
		return 0;
	double ratio = se / (target * mean);
	double need = NEED_MARGIN * ratio * ratio * (double)ps->paths;
	double more = fmin(need - (double)ps->paths,
	                   (double)(GROWTH_MAX - 1) * (double)ps->paths);
	uint64_t add = more < CHUNK ? CHUNK : (uint64_t)more;
	add = (add + CHUNK - 1) / CHUNK * CHUNK;
	return add > max - ps->paths ? max - ps->paths : add;
}

/*
 * Hand out up to ROUND_CHUNKS chunks of pending paths, points in order,
 * each point's from its next path on; returns their count.  A plan
 * larger than one round spills into the next ones.  Chunks start at
 * multiples of CHUNK (only a plan's last one may be short), so how plans
 * are cut into rounds changes nothing: not the chunks, not their order.
 */
static size_t plan_chunks(point_state *pt, size_t n, chunk *ck)
{
	size_t k = 0;
	for (size_t i = 0; i < n && k < ROUND_CHUNKS; i++) {
		point_state *ps = &pt[i];
		uint64_t f = 0;
		while (f < ps->pending && k < ROUND_CHUNKS) {
			uint64_t left = ps->pending - f;
			ck[k].point = (uint32_t)i;
			ck[k].first = ps->paths + f;
			ck[k].count = (uint32_t)(left < CHUNK ? left : CHUNK);
			f += ck[k++].count;
		}
		ps->pending -= f;
	}
	return k;
}

/* Merge a round's chunks into their points, in order; plan the points
 * whose plan is used up (target mode). */
static void merge_round(run *rn, const chunk *ck, size_t nck,
                        const rad_ref_options *o)
{
	for (size_t k = 0; k < nck; k++) {
		point_state *ps = &rn->pt[ck[k].point];
		moments_merge(&ps->mo, &ck[k].mo);
		ps->paths += ck[k].count;
	}
	for (size_t i = 0; i < rn->n; i++) {
		point_state *ps = &rn->pt[i];
		if (ps->done || ps->pending)
			continue;
		if (!o->samples)
			ps->pending =
			        plan_more(ps, o->target_error, o->max_samples);
		ps->done = ps->pending == 0;
	}
}

/* Rounds of parallel chunks until no point has paths planned. */
static rad_status run_rounds(run *rn, const rad_ref_options *o, rad_par *par,
                             rad_mem *mem, rad_error *err)
{
	rn->ck = rad_mem_alloc(mem, RAD_MEM_SCRATCH,
	                       ROUND_CHUNKS * sizeof(chunk));
	if (!rn->ck)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "reference: out of memory for work items");
	for (;;) {
		size_t nck = plan_chunks(rn->pt, rn->n, rn->ck);
		if (nck == 0)
			return RAD_OK;
		rad_par_for(par, nck, 1, run_chunks, rn);
		if (atomic_load(&rn->cancelled))
			return rad_fail(err, RAD_ERR_CANCELLED,
			                "reference: cancelled");
		merge_round(rn, rn->ck, nck, o);
	}
}

/* ------------------------------------------------------------ validation */

static rad_status check_options(const rad_ref_options *o, rad_error *err)
{
	if (o->samples > MAX_PATHS)
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: samples %llu exceeds %llu",
		                (unsigned long long)o->samples,
		                (unsigned long long)MAX_PATHS);
	if (o->samples)
		goto threads;
	if (!(o->target_error > 0 && o->target_error < 1))
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: target_error %g must be in (0, 1) "
		                "when samples is 0",
		                o->target_error);
	if (o->max_samples < 2 || o->max_samples > MAX_PATHS)
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: max_samples %llu must be in "
		                "[2, %llu]",
		                (unsigned long long)o->max_samples,
		                (unsigned long long)MAX_PATHS);
threads:
	if (o->threads < 0 || o->threads > 256)
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: threads %d must be in [0, 256] "
		                "(0 = one per core)",
		                o->threads);
	return RAD_OK;
}

static rad_status check_points(const double *pts, size_t n, rad_error *err)
{
	if (n && !pts)
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: NULL points for %zu", n);
	if (n > UINT32_MAX)
		return rad_fail(err, RAD_ERR_LIMIT,
		                "reference: %zu points, at most %u", n,
		                UINT32_MAX);
	for (size_t i = 0; i < n; i++) {
		const double *p = pts + 6 * i;
		v3 x = v3_d(p), nn = v3_d(p + 3);
		if (!v3_finite(x) || !v3_finite(nn))
			return rad_fail(
			        err, RAD_ERR_INVALID,
			        "reference: point %zu (%g %g %g, normal "
			        "%g %g %g) is not finite",
			        i, p[0], p[1], p[2], p[3], p[4], p[5]);
		if (!(v3_len(nn) > 0))
			return rad_fail(
			        err, RAD_ERR_INVALID,
			        "reference: point %zu has a zero normal", i);
	}
	return RAD_OK;
}

/* ------------------------------------------------------------------- API */

void rad_ref_options_default(rad_ref_options *o)
{
	memset(o, 0, sizeof(*o));
	o->target_error = DEFAULT_TARGET;
	o->max_samples = DEFAULT_MAX_SAMPLES;
	o->seed = 1;
}

/* Points, their lights-at-x value and round 1's path counts. */
static void init_points(const tracer *tr, const double *pts, size_t n,
                        const rad_ref_options *o, point_state *pt)
{
	uint64_t first = o->samples;
	if (!first)
		first = o->max_samples < FIRST_PATHS ? o->max_samples
		                                     : FIRST_PATHS;
	for (size_t i = 0; i < n; i++) {
		point_state *ps = &pt[i];
		ps->x = v3_d(pts + 6 * i);
		ps->n = v3_norm(v3_d(pts + 6 * i + 3));
		double e[3];
		lights_at(tr, ps->x, ps->n, NULL, e);
		ps->direct = rad_luma3(e);
		ps->pending = first;
	}
}

static void write_results(const point_state *pt, size_t n, double *lux,
                          double *stderr_lux, uint64_t *samples_used)
{
	for (size_t i = 0; i < n; i++) {
		lux[i] = pt[i].mo.mean;
		if (stderr_lux)
			stderr_lux[i] = moments_stderr(&pt[i].mo);
		if (samples_used)
			samples_used[i] = pt[i].paths;
	}
}

static rad_status check_call(const rad_scene *s, const double *pts, size_t n,
                             const rad_ref_options *o, const double *lux,
                             rad_error *err)
{
	if (!s || !s->committed || !s->vis)
		return rad_fail(err, RAD_ERR_STATE,
		                "reference: scene is not committed");
	if (n && !lux)
		return rad_fail(err, RAD_ERR_INVALID,
		                "reference: NULL output for %zu points", n);
	rad_status st = check_options(o, err);
	return st ? st : check_points(pts, n, err);
}

rad_status rad_reference_illuminance(const rad_scene *s, const double *pts,
                                     size_t n, const rad_ref_options *o,
                                     double *lux, double *stderr_lux,
                                     uint64_t *samples_used, rad_error *err)
{
	rad_ref_options def;
	if (!o) {
		rad_ref_options_default(&def);
		o = &def;
	}
	rad_status st = check_call(s, pts, n, o, lux, err);
	if (st || n == 0)
		return st;
	rad_mem mem;
	rad_mem_init(&mem);
	tracer tr = {.s = s,
	             .vis = s->vis,
	             .eps = rad_vis_eps(s->vis),
	             .seed = o->seed};
	run rn = {.tr = &tr, .n = n, .cancel = o->cancel};
	rad_par *par = NULL;
#if defined(__SSE__)
	unsigned csr = _mm_getcsr(); /* the caller traces too: restored */
#endif
	rad_vis_thread_init();
	rn.pt = rad_mem_calloc(&mem, RAD_MEM_SCRATCH, n, sizeof(point_state));
	if (!rn.pt)
		st = rad_fail(err, RAD_ERR_NOMEM,
		              "reference: out of memory for %zu points", n);
	if (!st)
		st = emitters_build(&tr.em, s, &mem, err);
	if (!st)
		st = rad_par_new(o->threads, &par, err);
	if (!st) {
		init_points(&tr, pts, n, o, rn.pt);
		st = run_rounds(&rn, o, par, &mem, err);
	}
	if (!st || st == RAD_ERR_CANCELLED)
		write_results(rn.pt, n, lux, stderr_lux, samples_used);
	if (!st)
		rad_error_clear(err);
	rad_par_free(par);
	rad_mem_free(&mem, RAD_MEM_SCRATCH, rn.ck);
	rad_mem_free(&mem, RAD_MEM_SCRATCH, rn.pt);
	rad_mem_free(&mem, RAD_MEM_SCRATCH, tr.em.poly);
	rad_mem_free(&mem, RAD_MEM_SCRATCH, tr.em.cdf);
#if defined(__SSE__)
	_mm_setcsr(csr);
#endif
	return st;
}
