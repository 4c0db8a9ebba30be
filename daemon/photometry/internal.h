/*
 * internal.h -- what the photometry library's files share: the lexer
 * over the input bytes (lex.c) and the raw table the two parsers fill
 * and table.c expands (table.c).
 */
#ifndef LUXRAD_PHO_INTERNAL_H
#define LUXRAD_PHO_INTERNAL_H

#include "photometry.h"

/* ---------------------------------------------------------------- lex.c */

/* A cursor over the bytes; line counts from 1. */
typedef struct pho_lex {
	const char *p, *end;
	unsigned line; /* line of the next unread byte */
	unsigned at;   /* line of the last item read: errors name it */
	char *err;     /* the caller's message buffer; may be NULL */
	size_t errlen;
} pho_lex;

/* Fill the message "line N: ..." and return st. */
pho_status pho_fail(pho_lex *lx, pho_status st, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* The next line (without its end) in *s, *n; 0 at the end of the input. */
int pho_next_line(pho_lex *lx, const char **s, size_t *n);
/* The next number separated by blanks, commas or line ends (IES). */
pho_status pho_token(pho_lex *lx, const char *what, double *v);
/* The next line as one number, ',' read as the decimal point (LDT). */
pho_status pho_line_number(pho_lex *lx, const char *what, double *v);
/* An integer number in [lo, hi], by tokens (ies) or lines (!ies). */
pho_status pho_count(pho_lex *lx, int ies, const char *what, long lo, long hi,
                     long *v);
/* n numbers into a, by tokens or lines; ascending in [lo, hi] when
 * ascending, else finite and >= lo. */
pho_status pho_numbers(pho_lex *lx, int ies, const char *what, double *a,
                       size_t n, int ascending, double lo, double hi);

/* -------------------------------------------------------------- table.c */

/* A file's table as given: nc planes at c[] with its symmetry, ng gamma
 * angles, values plane after plane, times scale to make candela. */
typedef struct pho_raw {
	pho_symmetry sym;
	uint32_t nc, ng;
	const double *c, *g, *v;
	double scale;
} pho_raw;

struct pho_table {
	pho_info info;
	rad_candela_grid grid; /* into data[] */
	double data[];         /* C angles, gamma angles, values */
};

/* Expand raw to every C plane into a new table with info copied in (its
 * lumens and max_cd filled); lx names the line for errors. */
pho_status pho_table_make(pho_lex *lx, const pho_raw *raw, const pho_info *info,
                          pho_table **out);

/* The two parsers; info comes zeroed with the format set. */
pho_status pho_parse_ies(pho_lex *lx, const pho_opts *o, pho_info *info,
                         pho_table **out);
pho_status pho_parse_ldt(pho_lex *lx, const pho_opts *o, pho_info *info,
                         pho_table **out);

#endif
