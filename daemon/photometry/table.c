/*
 * table.c -- the table every file becomes: its C planes expanded from
 * the file's symmetry to the whole circle, values in absolute candela;
 * the table's accessors.
 *
 * DESIGN
 *  - A symmetric file gives some planes; each given plane also stands
 *    for its mirror images (C0-C180: 360 - C; C90-C270: 180 - C; both:
 *    all four).  The planes and their images are sorted by C, images
 *    falling on a given plane dropped, and a plane at 0 repeated at 360,
 *    so the table covers 0..360 as the file's symmetry says.  Between
 *    planes the engine's lookup is linear in C, as between the file's.
 *  - One block holds the table: the struct, then the C angles, the gamma
 *    angles and the values.  The engine copies what it keeps.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

typedef struct plane {
	double c;
	uint32_t src; /* the file's plane it repeats */
} plane;

static int by_c(const void *a, const void *b)
{
	const plane *x = a, *y = b;
	if (x->c != y->c)
		return x->c < y->c ? -1 : 1;
	return x->src < y->src ? -1 : x->src > y->src;
}

/* The images of angle c under the symmetry, in [0, 360); their count. */
static int images(pho_symmetry sym, double c, double out[4])
{
	int n = 0;
	out[n++] = c;
	if (sym == PHO_SYM_C0_C180 || sym == PHO_SYM_QUADRANT)
		out[n++] = 360.0 - c;
	if (sym == PHO_SYM_C90_C270 || sym == PHO_SYM_QUADRANT)
		out[n++] = 180.0 - c;
	if (sym == PHO_SYM_QUADRANT)
		out[n++] = 180.0 + c;
	for (int k = 0; k < n; k++) {
		out[k] = fmod(out[k], 360.0);
		if (out[k] < 0)
			out[k] += 360.0;
	}
	return n;
}

/* The planes of the whole circle, sorted, into p (4 nc + 1); count. */
static uint32_t expand(const pho_raw *raw, plane *p)
{
	if (raw->sym == PHO_SYM_ROTATIONAL) {
		p[0] = (plane){0.0, 0};
		return 1;
	}
	uint32_t n = 0;
	for (uint32_t i = 0; i < raw->nc; i++) {
		double im[4];
		int k = images(raw->sym, raw->c[i], im);
		for (int j = 0; j < k; j++)
			p[n++] = (plane){im[j], i};
	}
	qsort(p, n, sizeof(*p), by_c);
	uint32_t m = 0;
	for (uint32_t i = 0; i < n; i++)
		if (m == 0 || p[i].c - p[m - 1].c > 1e-9)
			p[m++] = p[i];
	if (m > 1 && p[0].c == 0.0 && p[m - 1].c < 360.0)
		p[m++] = (plane){360.0, p[0].src};
	return m;
}

pho_status pho_table_make(pho_lex *lx, const pho_raw *raw, const pho_info *info,
                          pho_table **out)
{
	plane *p = malloc((4 * (size_t)raw->nc + 1) * sizeof(*p));
	if (!p)
		return pho_fail(lx, PHO_ERR_NOMEM, "out of memory");
	uint32_t nc = expand(raw, p), ng = raw->ng;
	if (nc > RAD_CANDELA_MAX_ANGLES ||
	    (uint64_t)nc * ng > RAD_CANDELA_MAX_VALUES) {
		free(p);
		return pho_fail(lx, PHO_ERR_INVALID,
		                "%u C planes x %u gamma angles once the "
		                "symmetry is expanded: more than %u values",
		                nc, ng, RAD_CANDELA_MAX_VALUES);
	}
	size_t nv = (size_t)nc * ng;
	pho_table *t = malloc(sizeof(*t) + (nc + ng + nv) * sizeof(double));
	if (!t) {
		free(p);
		return pho_fail(lx, PHO_ERR_NOMEM, "out of memory");
	}
	double *c = t->data, *g = c + nc, *v = g + ng;
	memcpy(g, raw->g, ng * sizeof(double));
	for (uint32_t i = 0; i < nc; i++) {
		c[i] = p[i].c;
		const double *src = raw->v + (size_t)p[i].src * ng;
		for (uint32_t j = 0; j < ng; j++)
			v[(size_t)i * ng + j] = src[j] * raw->scale;
	}
	free(p);
	t->grid = (rad_candela_grid){nc, ng, c, g, v};
	t->info = *info;
	rad_error e;
	if (rad_candela_check(&t->grid, &e)) {
		free(t);
		return pho_fail(lx, PHO_ERR_INVALID, "%s", e.msg);
	}
	t->info.lumens = rad_candela_flux(&t->grid);
	t->info.max_cd = rad_candela_peak(&t->grid);
	*out = t;
	return PHO_OK;
}

void pho_free(pho_table *t)
{
	free(t);
}

const pho_info *pho_table_info(const pho_table *t)
{
	return &t->info;
}

const rad_candela_grid *pho_table_grid(const pho_table *t)
{
	return &t->grid;
}

double pho_candela(const pho_table *t, double c_deg, double gamma_deg)
{
	return rad_candela_at(&t->grid, c_deg, gamma_deg);
}

double pho_lumens(const pho_table *t)
{
	return t->info.lumens;
}

const char *pho_status_name(pho_status st)
{
	switch (st) {
	case PHO_OK:
		return "ok";
	case PHO_ERR_INVALID:
		return "invalid";
	case PHO_ERR_UNSUPPORTED:
		return "unsupported";
	case PHO_ERR_NOMEM:
		return "nomem";
	}
	return "?";
}

rad_status pho_light_set(const pho_table *t, rad_light_desc *d, rad_error *err)
{
	if (d->kind != RAD_LIGHT_POINT)
		return rad_fail(err, RAD_ERR_INVALID,
		                "a photometric file needs a point light");
	double top =
	        fmax(d->intensity[0], fmax(d->intensity[1], d->intensity[2]));
	for (int c = 0; c < 3; c++)
		d->intensity[c] = top > 0 ? d->intensity[c] / top : 1;
	d->candela = &t->grid;
	/* The opening's height (luminous sides) is not modelled: the
	 * table radiates from the opening's plane. */
	d->opening[0] = fabs(t->info.opening_m[0]);
	d->opening[1] = fabs(t->info.opening_m[1]);
	d->opening_round = t->info.opening_circular;
	return RAD_OK;
}
