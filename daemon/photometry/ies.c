/*
 * ies.c -- IES LM-63 files (1986, 1991, 1995, 2002; the 2019 header is
 * read as 2002): keyword lines, the TILT line and its table, the
 * luminaire line, the ballast line, the angles and the candela values.
 *
 * DESIGN
 *  - Keyword lines are skipped to the TILT= line; nothing in them changes
 *    the table.  After it, numbers are separated by blanks, commas or
 *    line ends, as the standard allows, and are read as one stream.
 *  - Candela = file value x candela multiplier x ballast factor (x the
 *    ballast-lamp photometric factor of 1995 and earlier, a field later
 *    editions mark "future use" and ignore) x the tilt factor.
 *  - TILT=INCLUDE: the tilt table gives a factor for the lamp's tilt; we
 *    take it at pho_opts.tilt_deg (linear, held at the table's ends),
 *    which is 0 for a luminaire mounted as it was photometered -- the
 *    usual case, where the factor is normally 1.  The factor scales every
 *    value (LM-63 defines no per-direction tilt).  TILT=<file> names
 *    another file: refused, this library reads none.
 *  - Only type C photometry (gamma from the nadir, C planes about the
 *    vertical axis) maps onto the engine's table; types A and B are
 *    refused.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define FEET_M 0.3048
#define MAX_LAMPS 100000

/* The edition from the first line; 1986 files have no such line. */
static void edition(const char *s, size_t n, pho_info *info)
{
	const char *v = "LM-63-1986";
	if (n >= 16 && memcmp(s, "IESNA:LM-63-1995", 16) == 0)
		v = "LM-63-1995";
	else if (n >= 16 && memcmp(s, "IESNA:LM-63-2002", 16) == 0)
		v = "LM-63-2002";
	else if (n >= 14 && memcmp(s, "IES:LM-63-2019", 14) == 0)
		v = "LM-63-2019";
	else if (n >= 7 && memcmp(s, "IESNA91", 7) == 0)
		v = "LM-63-1991";
	else if (n >= 5 && memcmp(s, "IESNA", 5) == 0)
		v = "LM-63-2002"; /* a later header we do not know: as 2002 */
	snprintf(info->version, sizeof(info->version), "%s", v);
}

/* Skip to the TILT= line; *tilt and *tn get what follows the '='. */
static pho_status tilt_line(pho_lex *lx, pho_info *info, const char **tilt,
                            size_t *tn)
{
	const char *s;
	size_t n;
	for (int first = 1; pho_next_line(lx, &s, &n); first = 0) {
		if (first)
			edition(s, n, info);
		if (n >= 5 && memcmp(s, "TILT=", 5) == 0) {
			*tilt = s + 5;
			*tn = n - 5;
			while (*tn && (*tilt)[*tn - 1] == ' ')
				(*tn)--;
			return PHO_OK;
		}
	}
	return pho_fail(lx, PHO_ERR_INVALID,
	                "no TILT= line: not an IES LM-63 file");
}

/* TILT=INCLUDE: the table, and its factor at tilt_deg. */
static pho_status tilt_table(pho_lex *lx, double tilt_deg, pho_info *info)
{
	long geom, n;
	pho_status st =
	        pho_count(lx, 1, "lamp-to-luminaire geometry", 1, 3, &geom);
	if (st || (st = pho_count(lx, 1, "number of tilt angles", 1,
	                          RAD_CANDELA_MAX_ANGLES, &n)))
		return st;
	double *a = malloc(2 * (size_t)n * sizeof(double)), *f = a + n;
	if (!a)
		return pho_fail(lx, PHO_ERR_NOMEM, "out of memory");
	st = pho_numbers(lx, 1, "tilt angle", a, (size_t)n, 1, 0, 180);
	if (!st)
		st = pho_numbers(lx, 1, "tilt factor", f, (size_t)n, 0, 0, 0);
	if (!st) {
		double x = fmin(fmax(tilt_deg, a[0]), a[n - 1]), k = f[n - 1];
		for (long i = 0; i + 1 < n; i++)
			if (x <= a[i + 1]) {
				double u = (x - a[i]) / (a[i + 1] - a[i]);
				k = f[i] + u * (f[i + 1] - f[i]);
				break;
			}
		info->tilt_factor = k;
		info->tilt_geometry = (int)geom;
	}
	free(a);
	return st;
}

/* The symmetry the horizontal angles' range stands for. */
static pho_status symmetry(pho_lex *lx, const double *h, long nh,
                           pho_symmetry *sym)
{
	double lo = h[0], hi = h[nh - 1];
	if (nh == 1)
		*sym = PHO_SYM_ROTATIONAL;
	else if (lo == 0 && hi == 90)
		*sym = PHO_SYM_QUADRANT;
	else if (lo == 0 && hi == 180)
		*sym = PHO_SYM_C0_C180;
	else if (lo == 90 && hi == 270)
		*sym = PHO_SYM_C90_C270;
	else if (lo == 0 && hi > 180)
		*sym = PHO_SYM_NONE;
	else
		return pho_fail(lx, PHO_ERR_INVALID,
		                "horizontal angles run %g..%g; LM-63 allows 0, "
		                "0..90, 0..180, 90..270 or 0..(180, 360]",
		                lo, hi);
	return PHO_OK;
}

/* The luminaire line's counts and factors into info; *nv, *nh. */
static pho_status luminaire_line(pho_lex *lx, const pho_opts *o, pho_info *info,
                                 long *nv, long *nh)
{
	long lamps, type, units;
	double lm, mult, dim[3], bf, blpf, watts;
	pho_status st =
	        pho_count(lx, 1, "number of lamps", 1, MAX_LAMPS, &lamps);
	if (st || (st = pho_token(lx, "lumens per lamp", &lm)))
		return st;
	if (!(lm > 0 || lm == -1))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "lumens per lamp %g: need > 0, or -1 for "
		                "absolute photometry",
		                lm);
	if ((st = pho_token(lx, "candela multiplier", &mult)))
		return st;
	if (!(mult > 0))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "candela multiplier %g: need > 0", mult);
	if ((st = pho_count(lx, 1, "number of vertical angles", 2,
	                    RAD_CANDELA_MAX_ANGLES, nv)) ||
	    (st = pho_count(lx, 1, "number of horizontal angles", 1,
	                    RAD_CANDELA_MAX_ANGLES, nh)) ||
	    (st = pho_count(lx, 1, "photometric type", 1, 3, &type)) ||
	    (st = pho_count(lx, 1, "units type", 1, 2, &units)) ||
	    (st = pho_numbers(lx, 1, "opening dimension", dim, 3, 0, -1e9,
	                      0)) ||
	    (st = pho_token(lx, "ballast factor", &bf)) ||
	    (st = pho_token(lx, "ballast-lamp factor", &blpf)) ||
	    (st = pho_token(lx, "input watts", &watts)))
		return st;
	if (type != 1)
		return pho_fail(lx, PHO_ERR_UNSUPPORTED,
		                "photometric type %s: only type C is supported",
		                type == 2 ? "B" : "A");
	if ((uint64_t)*nv * (uint64_t)*nh > RAD_CANDELA_MAX_VALUES)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "%ld x %ld candela values: more than %u", *nv,
		                *nh, RAD_CANDELA_MAX_VALUES);
	if (!(bf > 0) || !(blpf > 0))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "ballast factor %g, ballast-lamp factor %g: "
		                "need > 0",
		                bf, blpf);
	info->absolute = lm == -1;
	info->lamps = (int)lamps;
	info->lamp_lumens = info->absolute ? 0 : (double)lamps * lm;
	info->ballast_factor = bf;
	info->input_watts = watts;
	double unit = units == 1 ? FEET_M : 1.0;
	info->opening_circular = dim[0] < 0 || dim[1] < 0;
	info->opening_m[0] = fabs(dim[1]) * unit; /* length, along C0 */
	info->opening_m[1] = fabs(dim[0]) * unit; /* width, along C90 */
	if (info->opening_circular)
		info->opening_m[0] = info->opening_m[1] =
		        fmax(info->opening_m[0], info->opening_m[1]);
	info->opening_m[2] = fabs(dim[2]) * unit;
	int old = strcmp(info->version, "LM-63-1995") <= 0 &&
	          strncmp(info->version, "LM-63-19", 8) == 0;
	info->multiplier = mult * bf * (old ? blpf : 1.0) * info->tilt_factor;
	if (o->lamp_lumens > 0) {
		if (info->absolute)
			return pho_fail(
			        lx, PHO_ERR_INVALID,
			        "absolute photometry (lumens -1) cannot "
			        "be rescaled to %g lamp lumens",
			        o->lamp_lumens);
		info->multiplier *= o->lamp_lumens / info->lamp_lumens;
		info->lamp_lumens = o->lamp_lumens;
	}
	return PHO_OK;
}

/* The angles and values after the ballast line. */
static pho_status body(pho_lex *lx, pho_info *info, long nv, long nh,
                       pho_table **out)
{
	size_t nval = (size_t)nv * (size_t)nh;
	double *g = malloc(((size_t)nv + (size_t)nh + nval) * sizeof(double));
	if (!g)
		return pho_fail(lx, PHO_ERR_NOMEM, "out of memory");
	double *h = g + nv, *v = h + nh;
	pho_raw raw = {0, (uint32_t)nh,    (uint32_t)nv, h, g,
	               v, info->multiplier};
	pho_status st =
	        pho_numbers(lx, 1, "vertical angle", g, (size_t)nv, 1, 0, 180);
	if (!st)
		st = pho_numbers(lx, 1, "horizontal angle", h, (size_t)nh, 1, 0,
		                 360);
	if (!st)
		st = symmetry(lx, h, nh, &raw.sym);
	if (!st)
		st = pho_numbers(lx, 1, "candela value", v, nval, 0, 0, 0);
	info->symmetry = raw.sym;
	info->nc_file = (uint32_t)nh;
	info->ngamma = (uint32_t)nv;
	if (!st)
		st = pho_table_make(lx, &raw, info, out);
	free(g);
	return st;
}

pho_status pho_parse_ies(pho_lex *lx, const pho_opts *o, pho_info *info,
                         pho_table **out)
{
	const char *tilt = NULL;
	size_t tn = 0;
	long nv, nh;
	info->tilt_factor = 1.0;
	pho_status st = tilt_line(lx, info, &tilt, &tn);
	if (st)
		return st;
	if (tn == 7 && memcmp(tilt, "INCLUDE", 7) == 0)
		st = tilt_table(lx, o->tilt_deg, info);
	else if (!(tn == 4 && memcmp(tilt, "NONE", 4) == 0))
		return pho_fail(lx, PHO_ERR_UNSUPPORTED,
		                "TILT=%.*s names a tilt file; only TILT=NONE "
		                "and TILT=INCLUDE are read (no file access)",
		                (int)(tn > 64 ? 64 : tn), tilt);
	if (!st)
		st = luminaire_line(lx, o, info, &nv, &nh);
	return st ? st : body(lx, info, nv, nh, out);
}
