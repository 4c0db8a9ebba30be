/*
 * gonio.c -- goniometric intensity tables (rad_candela_grid): checks,
 * bilinear lookup, the flux integral, and a point light's copy of its
 * table in the scene (rad_gonio, scene.h).
 *
 * DESIGN
 *  - One interpolation, used everywhere: the solvers' form factors
 *    (ff.c), the Monte Carlo reference (reference.c) and the photometry
 *    library's lookups all call rad_candela_at, so a luminaire reads the
 *    same wherever it is evaluated.  The reference stays independent in
 *    its transport, not in how a table is read.
 *  - The flux is the exact integral of that same interpolant: per C
 *    plane, the piecewise-linear I(gamma) times sin(gamma) integrates in
 *    closed form; across planes the intensity is linear in C, so the
 *    trapezoid rule over C is exact.  The flux a solver sees therefore
 *    equals rad_candela_flux to rounding, whatever the table's steps.
 *  - A light stores its table scaled to a peak of 1 in effect: the
 *    light's intensity is the peak (times the caller's RGB factor) and
 *    the table gives a factor in [0, 1], as a spot's cone does.  Every
 *    bound the solvers take from a light's intensity (1/d^2 per unit of
 *    it) stays a bound.
 */
#include <float.h>
#include <string.h>

#include "rad.h"
#include "scene.h"

#define DEG (M_PI / 180.0)

/* ------------------------------------------------------------- the grid */

static rad_status check_axis(const double *a, uint32_t n, double hi,
                             const char *what, rad_error *err)
{
	for (uint32_t i = 0; i < n; i++) {
		if (!(a[i] >= 0 && a[i] <= hi))
			return rad_fail(err, RAD_ERR_INVALID,
			                "candela table: %s angle %u is %g, "
			                "outside [0, %g]",
			                what, i, a[i], hi);
		if (i && !(a[i] > a[i - 1]))
			return rad_fail(err, RAD_ERR_INVALID,
			                "candela table: %s angles not "
			                "ascending at %u (%g after %g)",
			                what, i, a[i], a[i - 1]);
	}
	return RAD_OK;
}

rad_status rad_candela_check(const rad_candela_grid *g, rad_error *err)
{
	if (!g || !g->c_deg || !g->gamma_deg || !g->cd)
		return rad_fail(err, RAD_ERR_INVALID, "candela table: NULL");
	if (g->nc < 1 || g->ngamma < 2 || g->nc > RAD_CANDELA_MAX_ANGLES ||
	    g->ngamma > RAD_CANDELA_MAX_ANGLES ||
	    (uint64_t)g->nc * g->ngamma > RAD_CANDELA_MAX_VALUES)
		return rad_fail(err, RAD_ERR_INVALID,
		                "candela table: %u C planes x %u gamma angles "
		                "(need >= 1 x >= 2, at most %u per axis and "
		                "%u values)",
		                g->nc, g->ngamma, RAD_CANDELA_MAX_ANGLES,
		                RAD_CANDELA_MAX_VALUES);
	rad_status st = check_axis(g->c_deg, g->nc, 360.0, "C", err);
	if (st ||
	    (st = check_axis(g->gamma_deg, g->ngamma, 180.0, "gamma", err)))
		return st;
	size_t n = (size_t)g->nc * g->ngamma;
	for (size_t k = 0; k < n; k++)
		if (!(g->cd[k] >= 0 && g->cd[k] <= DBL_MAX))
			return rad_fail(
			        err, RAD_ERR_INVALID,
			        "candela table: value %zu (C plane %zu) "
			        "is %g; need finite and >= 0",
			        k, k / g->ngamma, g->cd[k]);
	return RAD_OK;
}

/* i with a[i] <= x <= a[i + 1], for a[0] <= x <= a[n - 1], n >= 2. */
static uint32_t bracket(const double *a, uint32_t n, double x)
{
	uint32_t lo = 0, hi = n - 1;
	while (hi - lo > 1) {
		uint32_t mid = lo + (hi - lo) / 2;
		if (a[mid] <= x)
			lo = mid;
		else
			hi = mid;
	}
	return lo;
}

/* Plane i at gamma between gamma_deg[j] and [j + 1], fraction t. */
static double plane_at(const rad_candela_grid *g, uint32_t i, uint32_t j,
                       double t)
{
	const double *row = g->cd + (size_t)i * g->ngamma;
	return row[j] + t * (row[j + 1] - row[j]);
}

double rad_candela_at(const rad_candela_grid *g, double c_deg, double gamma_deg)
{
	const double *ga = g->gamma_deg, *ca = g->c_deg;
	uint32_t ng = g->ngamma, nc = g->nc;
	if (!(gamma_deg >= ga[0] && gamma_deg <= ga[ng - 1]) ||
	    !isfinite(c_deg))
		return 0.0;
	uint32_t j = bracket(ga, ng, gamma_deg);
	double t = (gamma_deg - ga[j]) / (ga[j + 1] - ga[j]);
	if (nc == 1)
		return plane_at(g, 0, j, t);
	double c = fmod(c_deg, 360.0);
	if (c < 0)
		c += 360.0;
	uint32_t i0 = nc - 1, i1 = 0; /* the wrap: last plane to first */
	double u = 0;
	if (c >= ca[0] && c <= ca[nc - 1]) {
		i0 = bracket(ca, nc, c);
		i1 = i0 + 1;
		u = (c - ca[i0]) / (ca[i1] - ca[i0]);
	} else {
		double span = ca[0] + 360.0 - ca[nc - 1];
		double x = c < ca[0] ? c + 360.0 : c;
		u = span > 0 ? (x - ca[nc - 1]) / span : 0.0;
	}
	double a = plane_at(g, i0, j, t), b = plane_at(g, i1, j, t);
	return a + u * (b - a);
}

/* The integral of plane i's I(gamma) sin(gamma) dgamma, exact for the
 * piecewise-linear I: on [a, b], h = b - a, the end values weigh
 * (h cos a + sin a - sin b) / h and (sin b - sin a - h cos b) / h. */
static double plane_flux(const rad_candela_grid *g, uint32_t i)
{
	const double *row = g->cd + (size_t)i * g->ngamma;
	double sum = 0;
	for (uint32_t j = 0; j + 1 < g->ngamma; j++) {
		double a = g->gamma_deg[j] * DEG, b = g->gamma_deg[j + 1] * DEG;
		double h = b - a, sa = sin(a), sb = sin(b);
		sum += row[j] * (h * cos(a) + sa - sb) / h +
		       row[j + 1] * (sb - sa - h * cos(b)) / h;
	}
	return sum;
}

double rad_candela_flux(const rad_candela_grid *g)
{
	if (g->nc == 1)
		return 2.0 * M_PI * plane_flux(g, 0);
	double sum = 0, first = plane_flux(g, 0), prev = first;
	for (uint32_t i = 1; i < g->nc; i++) {
		double cur = plane_flux(g, i);
		sum += 0.5 * (g->c_deg[i] - g->c_deg[i - 1]) * (prev + cur);
		prev = cur;
	}
	sum += 0.5 * (g->c_deg[0] + 360.0 - g->c_deg[g->nc - 1]) *
	       (prev + first);
	return sum * DEG;
}

double rad_candela_peak(const rad_candela_grid *g)
{
	double peak = 0;
	size_t n = (size_t)g->nc * g->ngamma;
	for (size_t k = 0; k < n; k++)
		peak = fmax(peak, g->cd[k]);
	return peak;
}

/* ------------------------------------------------------- a light's table */

static void store(double out[3], v3 a)
{
	out[0] = a.x;
	out[1] = a.y;
	out[2] = a.z;
}

/* The C = 0 axis: c0 made perpendicular to the nadir, else (only for a
 * rotationally symmetric table) any perpendicular. */
static int c0_frame(v3 nadir, const double c0[3], int symmetric, v3 *ax0)
{
	v3 a = v3_d(c0);
	if (v3_finite(a))
		a = v3_madd(a, nadir, -v3_dot(a, nadir));
	double len = v3_finite(a) ? v3_len(a) : 0;
	if (len > 1e-9 * fmax(1.0, v3_len(v3_d(c0)))) {
		*ax0 = v3_scale(a, 1.0 / len);
		return 1;
	}
	if (!symmetric)
		return 0;
	v3 e = fabs(nadir.x) < 0.5 ? v3_make(1, 0, 0) : v3_make(0, 1, 0);
	*ax0 = v3_norm(v3_madd(e, nadir, -v3_dot(e, nadir)));
	return 1;
}

rad_status rad_gonio_new(rad_mem *mem, const rad_light_desc *d, uint32_t which,
                         rad_gonio **out, rad_error *err)
{
	const rad_candela_grid *g = d->candela;
	rad_error why;
	rad_status st = rad_candela_check(g, &why);
	if (st)
		return rad_fail(err, st, "light %u: %s", which, why.msg);
	v3 nadir = v3_norm(v3_d(d->direction)), ax0;
	if (!c0_frame(nadir, d->c0_axis, g->nc == 1, &ax0))
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %u: c0_axis (%g, %g, %g) must be finite "
		                "and not along the direction",
		                which, d->c0_axis[0], d->c0_axis[1],
		                d->c0_axis[2]);
	size_t nv = (size_t)g->nc * g->ngamma;
	size_t nd = g->nc + g->ngamma + nv;
	rad_gonio *t = rad_mem_alloc(mem, RAD_MEM_LIGHTS,
	                             sizeof(*t) + nd * sizeof(double));
	if (!t)
		return rad_fail(err, RAD_ERR_NOMEM, "light %u: out of memory",
		                which);
	double *c = t->data, *gm = c + g->nc, *cd = gm + g->ngamma;
	memcpy(c, g->c_deg, g->nc * sizeof(double));
	memcpy(gm, g->gamma_deg, g->ngamma * sizeof(double));
	memcpy(cd, g->cd, nv * sizeof(double));
	t->grid = (rad_candela_grid){g->nc, g->ngamma, c, gm, cd};
	t->peak_cd = rad_candela_peak(g);
	t->flux_per_peak =
	        t->peak_cd > 0 ? rad_candela_flux(g) / t->peak_cd : 0;
	store(t->nadir, nadir);
	store(t->axis0, ax0);
	store(t->axis90, v3_cross(ax0, nadir));
	*out = t;
	return RAD_OK;
}

double rad_gonio_factor(const rad_gonio *t, v3 w)
{
	if (!(t->peak_cd > 0))
		return 0;
	double cg = v3_dot(w, v3_d(t->nadir));
	double gamma = acos(cg > 1 ? 1 : cg < -1 ? -1 : cg) / DEG;
	/* + 0.0 turns a -0 into +0: straight down reads plane 0, not 180. */
	double y = v3_dot(w, v3_d(t->axis90)) + 0.0;
	double x = v3_dot(w, v3_d(t->axis0)) + 0.0;
	double c = atan2(y, x) / DEG;
	return rad_candela_at(&t->grid, c, gamma) / t->peak_cd;
}
