/*
 * ldt.c -- EULUMDAT (.ldt) files: the fixed layout of one field per
 * line -- the header (type, symmetry, plane counts, texts, dimensions in
 * mm, DFF, LORL, conversion factor, tilt), the lamp sets, the ten direct
 * ratios, the C and gamma angles and the values in cd per 1000 lm.
 *
 * DESIGN
 *  - Candela = value x conversion factor x (total lamp flux) / 1000, the
 *    flux summed over the lamp sets.  A negative lamp count marks
 *    absolute photometry: the flux field is then the luminaire's.  The
 *    luminaire's flux the file declares is LORL x lamp flux (absolute:
 *    the flux field).
 *  - The stored planes follow the symmetry (Isym): all Mc; one; C0..C180
 *    (Mc/2 + 1); C90..C270 (Mc/2 + 1, starting at plane Mc/4); C0..C90
 *    (Mc/4 + 1).  Their angles are checked against what the symmetry
 *    needs (e.g. the last of C0..C180 is 180).
 *  - Numbers may use a decimal comma (German writers do); text fields
 *    are skipped whatever they hold.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define MAX_LAMP_SETS 100

/* Skip one text line; an error if the file has ended. */
static pho_status text(pho_lex *lx, const char *what)
{
	const char *s;
	size_t n;
	if (!pho_next_line(lx, &s, &n))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "the file ends before the %s", what);
	return PHO_OK;
}

static pho_status num(pho_lex *lx, const char *what, double *v)
{
	return pho_line_number(lx, what, v);
}

typedef struct header {
	long isym, mc, ng;
	double conv;
} header;

/* Lines 1-25. */
static pho_status head(pho_lex *lx, pho_info *info, header *h)
{
	static const char *texts[] = {"report number", "luminaire name",
	                              "luminaire number", "file name",
	                              "date/user"};
	long ityp;
	double x, dims[9];
	pho_status st = text(lx, "company line");
	if (st || (st = pho_count(lx, 0, "type indicator Ityp", 0, 3, &ityp)) ||
	    (st = pho_count(lx, 0, "symmetry indicator Isym", 0, 4,
	                    &h->isym)) ||
	    (st = pho_count(lx, 0, "number of C planes Mc", 1,
	                    RAD_CANDELA_MAX_ANGLES, &h->mc)) ||
	    (st = num(lx, "C plane distance Dc", &x)) ||
	    (st = pho_count(lx, 0, "number of gamma angles Ng", 2,
	                    RAD_CANDELA_MAX_ANGLES, &h->ng)) ||
	    (st = num(lx, "gamma angle distance Dg", &x)))
		return st;
	for (int k = 0; k < 5 && !st; k++)
		st = text(lx, texts[k]);
	if (st ||
	    (st = pho_numbers(lx, 0, "dimension (mm), line 13 +", dims, 9, 0, 0,
	                      0)) ||
	    (st = num(lx, "downward flux fraction", &x)) ||
	    (st = num(lx, "light output ratio LORL", &info->lorl)) ||
	    (st = num(lx, "conversion factor", &h->conv)) ||
	    (st = num(lx, "tilt during measurement", &x)))
		return st;
	if (!(info->lorl >= 0 && info->lorl <= 100) || !(h->conv > 0))
		return pho_fail(
		        lx, PHO_ERR_INVALID,
		        "LORL %g %%, conversion factor %g: need LORL in "
		        "[0, 100] and a factor > 0",
		        info->lorl, h->conv);
	info->lorl /= 100.0;
	info->opening_circular = dims[4] == 0;
	info->opening_m[0] = dims[3] / 1000.0; /* length or diameter */
	info->opening_m[1] = (dims[4] == 0 ? dims[3] : dims[4]) / 1000.0;
	info->opening_m[2] =
	        fmax(fmax(dims[5], dims[6]), fmax(dims[7], dims[8])) / 1000.0;
	if ((h->isym >= 3 && h->mc % 4) || (h->isym == 2 && h->mc % 2))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "Isym %ld with Mc %ld: Mc must divide by %d",
		                h->isym, h->mc, h->isym == 2 ? 2 : 4);
	if ((uint64_t)h->mc * (uint64_t)h->ng > RAD_CANDELA_MAX_VALUES)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "%ld x %ld values: more than %u", h->mc, h->ng,
		                RAD_CANDELA_MAX_VALUES);
	return PHO_OK;
}

/* Line 26 and the lamp sets; the direct ratios. */
static pho_status lamps(pho_lex *lx, pho_info *info)
{
	long sets, n;
	double flux, watts;
	pho_status st = pho_count(lx, 0, "number of lamp sets", 1,
	                          MAX_LAMP_SETS, &sets);
	for (long k = 0; k < sets && !st; k++) {
		if ((st = pho_count(lx, 0, "number of lamps",
		                    -MAX_LAMP_SETS * 1000L,
		                    MAX_LAMP_SETS * 1000L, &n)) ||
		    (st = text(lx, "lamp type")) ||
		    (st = num(lx, "lamp flux", &flux)) ||
		    (st = text(lx, "colour temperature")) ||
		    (st = text(lx, "colour rendering")) ||
		    (st = num(lx, "lamp wattage", &watts)))
			break;
		if (!(flux > 0))
			return pho_fail(lx, PHO_ERR_INVALID,
			                "lamp set %ld: flux %g lm, need > 0",
			                k + 1, flux);
		info->absolute |= n < 0;
		info->lamps += (int)labs(n);
		info->lamp_lumens += flux;
		info->input_watts += watts;
	}
	for (int k = 0; k < 10 && !st; k++) {
		double dr;
		st = num(lx, "direct ratio", &dr);
	}
	return st;
}

/* The stored planes: first index and count, and the angles they need. */
static pho_status stored(pho_lex *lx, const header *h, const double *c,
                         pho_raw *raw)
{
	static const pho_symmetry sym[] = {PHO_SYM_NONE, PHO_SYM_ROTATIONAL,
	                                   PHO_SYM_C0_C180, PHO_SYM_C90_C270,
	                                   PHO_SYM_QUADRANT};
	long mc = h->mc, first = 0, count = mc;
	double want_lo = c[0], want_hi = c[mc - 1];
	switch (h->isym) {
	case 1:
		count = 1;
		want_hi = want_lo;
		break;
	case 2:
		count = mc / 2 + 1, want_lo = 0, want_hi = 180;
		break;
	case 3:
		first = mc / 4, count = mc / 2 + 1, want_lo = 90, want_hi = 270;
		break;
	case 4:
		count = mc / 4 + 1, want_lo = 0, want_hi = 90;
		break;
	}
	if (first + count > mc || c[first] != want_lo ||
	    c[first + count - 1] != want_hi)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "Isym %ld stores C planes %g..%g; the C angles "
		                "give %g..%g",
		                h->isym, want_lo, want_hi, c[first],
		                first + count <= mc ? c[first + count - 1]
		                                    : NAN);
	raw->sym = sym[h->isym];
	raw->nc = (uint32_t)count;
	raw->c = c + first;
	return PHO_OK;
}

pho_status pho_parse_ldt(pho_lex *lx, const pho_opts *o, pho_info *info,
                         pho_table **out)
{
	header h;
	snprintf(info->version, sizeof(info->version), "EULUMDAT");
	info->tilt_factor = info->ballast_factor = 1.0;
	pho_status st = head(lx, info, &h);
	if (st || (st = lamps(lx, info)))
		return st;
	size_t nval = (size_t)h.mc * (size_t)h.ng;
	double *c =
	        malloc(((size_t)h.mc + (size_t)h.ng + nval) * sizeof(double));
	if (!c)
		return pho_fail(lx, PHO_ERR_NOMEM, "out of memory");
	double *g = c + h.mc, *v = g + h.ng;
	pho_raw raw = {.ng = (uint32_t)h.ng, .g = g, .v = v};
	st = pho_numbers(lx, 0, "C angle", c, (size_t)h.mc, 1, 0, 360);
	if (!st)
		st = pho_numbers(lx, 0, "gamma angle", g, (size_t)h.ng, 1, 0,
		                 180);
	if (!st)
		st = stored(lx, &h, c, &raw);
	if (!st)
		st = pho_numbers(lx, 0, "intensity (cd/klm)", v,
		                 (size_t)raw.nc * h.ng, 0, 0, 0);
	double flux = info->lamp_lumens;
	if (!st && o->lamp_lumens > 0 && info->absolute)
		st = pho_fail(lx, PHO_ERR_INVALID,
		              "absolute photometry cannot be rescaled to %g "
		              "lamp lumens",
		              o->lamp_lumens);
	if (!st) {
		if (o->lamp_lumens > 0)
			flux = info->lamp_lumens = o->lamp_lumens;
		info->lumens_declared =
		        info->absolute ? flux : info->lorl * flux;
		if (info->absolute)
			info->lamp_lumens = 0;
		info->multiplier = raw.scale = h.conv * flux / 1000.0;
		info->symmetry = raw.sym;
		info->nc_file = (uint32_t)h.mc;
		info->ngamma = (uint32_t)h.ng;
		st = pho_table_make(lx, &raw, info, out);
	}
	free(c);
	return st;
}
