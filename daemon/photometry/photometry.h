/*
 * photometry.h -- luminaire photometric files (IES LM-63, EULUMDAT) as
 * candela tables (the photometry library, prefix pho_).
 *
 * pho_parse() takes the bytes of a file, never a path: the library does
 * no I/O.  It reads IES LM-63 (1986 without a header line, 1991, 1995,
 * 2002 and the 2019 header) and EULUMDAT (.ldt), and hands back a table
 * of absolute candela over C-planes and gamma angles (type C
 * photometry), expanded from the file's symmetry to every C plane, as
 * the engine's rad_candela_grid.  Lookups and the flux are the engine's
 * (rad_candela_at, rad_candela_flux), so a table reads here exactly as a
 * light made from it shines in a scene.
 *
 * Every defect of the input -- truncation, a bad number, counts out of
 * range, angles not ascending -- is an error naming the line, never a
 * crash or a read past len.
 */
#ifndef LUXRAD_PHOTOMETRY_H
#define LUXRAD_PHOTOMETRY_H

#include <stddef.h>
#include <stdint.h>

#include "rad.h"

typedef enum pho_status {
	PHO_OK = 0,
	PHO_ERR_INVALID,     /* malformed file; the message names the line */
	PHO_ERR_UNSUPPORTED, /* valid, but not handled: TILT=<file>, type
	                        A or B photometry */
	PHO_ERR_NOMEM,
} pho_status;

typedef enum pho_format { PHO_IES = 1, PHO_LDT } pho_format;

/* The file's horizontal (C-plane) symmetry, before expansion. */
typedef enum pho_symmetry {
	PHO_SYM_NONE = 0,   /* every plane given (IES 0..>180, LDT Isym 0) */
	PHO_SYM_ROTATIONAL, /* one plane (IES 0, LDT Isym 1) */
	PHO_SYM_C0_C180,    /* mirror about C0-C180 (IES 0..180, Isym 2) */
	PHO_SYM_C90_C270,   /* mirror about C90-C270 (IES 90..270, Isym 3) */
	PHO_SYM_QUADRANT,   /* both planes (IES 0..90, Isym 4) */
} pho_symmetry;

typedef struct pho_opts {
	double tilt_deg;    /* TILT=INCLUDE: the lamp's tilt as installed,
	                       degrees; 0 (mounted as photometered) takes the
	                       table's factor at 0 */
	double lamp_lumens; /* > 0: rescale relative photometry to lamps
	                       of this total flux, lm (0 = as the file) */
} pho_opts;

typedef struct pho_info {
	pho_format format;
	char version[16];       /* "LM-63-2002", ..., "LM-63-1986",
	                           "EULUMDAT" */
	pho_symmetry symmetry;  /* as the file gives it */
	int absolute;           /* absolute photometry (IES lumens -1, LDT
	                           negative lamp count) */
	int lamps;              /* number of lamps (sum over LDT lamp sets) */
	double lamp_lumens;     /* total rated lamp flux, lm (0: absolute) */
	double lumens_declared; /* the luminaire's flux the file states, lm:
	                           LDT LORL x lamp flux (absolute: the flux
	                           field); IES: none (0), its lamps' flux
	                           stands for it */
	double lumens;          /* the table's integral, rad_candela_flux */
	double multiplier;      /* file values x multiplier = candela: IES
	                           multiplier x ballast factor (x the 1995
	                           ballast-lamp factor) x tilt factor; LDT
	                           conversion factor x lamp flux / 1000 */
	double tilt_factor;     /* applied (1 without a tilt table) */
	int tilt_geometry;      /* IES lamp-to-luminaire geometry 1..3, 0 */
	double ballast_factor;  /* IES (1 for LDT) */
	double input_watts;     /* IES input watts; LDT lamp sets' sum */
	double lorl;            /* LDT light output ratio, fraction (IES 0) */
	double opening_m[3];    /* luminous opening: length (along C0),
	                           width (along C90), height; metres */
	int opening_circular;   /* opening_m[0] is then the diameter */
	uint32_t nc_file;       /* C planes in the file */
	uint32_t ngamma;        /* gamma angles */
	double max_cd;          /* the table's largest value */
} pho_info;

typedef struct pho_table pho_table;

/*
 * Parse len bytes (an IES file when a line starts "IESNA", "IES:" or
 * "TILT=", else EULUMDAT) into *out (caller frees with pho_free).  opts
 * may be NULL (defaults: zeros).  On error *out is NULL and err (errlen
 * bytes, may be NULL) holds a message, "line N: ...".
 */
pho_status pho_parse(const char *bytes, size_t len, const pho_opts *opts,
                     pho_table **out, char *err, size_t errlen);
void pho_free(pho_table *t);

/* What the file said and what came of it; borrowed from t. */
const pho_info *pho_table_info(const pho_table *t);
/* The table, absolute candela, borrowed from t: C planes cover 0..360
 * (or one plane), for rad_light_desc.candela. */
const rad_candela_grid *pho_table_grid(const pho_table *t);
/* Candela towards (c, gamma), degrees: bilinear (rad_candela_at). */
double pho_candela(const pho_table *t, double c_deg, double gamma_deg);
/* The table's flux, lm: the exact integral of the bilinear intensity
 * over the sphere (rad_candela_flux). */
double pho_lumens(const pho_table *t);

/*
 * Make d (a point light) the luminaire t: its candela table (borrowed:
 * t must live until d is added to a scene, which copies it), its
 * intensity the RGB factor of its colour with the largest channel 1
 * (white for a black light), so that the file's candela are what it
 * gives.  RAD_ERR_INVALID if d is not a point light.
 */
rad_status pho_light_set(const pho_table *t, rad_light_desc *d, rad_error *err);

/* Short name of a status ("invalid"...). */
const char *pho_status_name(pho_status st);

#endif
