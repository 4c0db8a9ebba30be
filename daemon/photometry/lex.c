/*
 * lex.c -- reading numbers and lines out of a photometric file's bytes,
 * bounded by the length given (the input need not end in a NUL).
 *
 * Line ends are LF, CRLF or a lone CR.  A number is copied out (at most
 * 63 bytes) and read with strtod in the C locale's syntax; it must use
 * the whole token and be finite ("nan" and "inf" are refused).
 */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define NUM_MAX 64 /* bytes of one number with its NUL */

pho_status pho_fail(pho_lex *lx, pho_status st, const char *fmt, ...)
{
	if (!lx->err || !lx->errlen)
		return st;
	int k = snprintf(lx->err, lx->errlen, "line %u: ", lx->at);
	if (k < 0 || (size_t)k >= lx->errlen)
		return st;
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(lx->err + k, lx->errlen - (size_t)k, fmt, ap);
	va_end(ap);
	return st;
}

/* Step over a line end at p (LF, CR or CRLF); 1 if there was one. */
static int line_end(pho_lex *lx)
{
	if (lx->p >= lx->end || (*lx->p != '\n' && *lx->p != '\r'))
		return 0;
	if (*lx->p == '\r' && lx->p + 1 < lx->end && lx->p[1] == '\n')
		lx->p++;
	lx->p++;
	lx->line++;
	return 1;
}

int pho_next_line(pho_lex *lx, const char **s, size_t *n)
{
	if (lx->p >= lx->end)
		return 0;
	lx->at = lx->line;
	const char *b = lx->p;
	while (lx->p < lx->end && *lx->p != '\n' && *lx->p != '\r')
		lx->p++;
	*s = b;
	*n = (size_t)(lx->p - b);
	line_end(lx);
	return 1;
}

/* Read s[0..n) as one finite number; comma_point reads ',' as '.'. */
static pho_status number(pho_lex *lx, const char *what, const char *s, size_t n,
                         int comma_point, double *v)
{
	char buf[NUM_MAX];
	if (n == 0)
		return pho_fail(lx, PHO_ERR_INVALID, "%s: no number", what);
	if (n >= NUM_MAX)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "%s: %zu characters, not a number", what, n);
	memcpy(buf, s, n);
	buf[n] = 0;
	for (size_t k = 0; comma_point && k < n; k++)
		if (buf[k] == ',')
			buf[k] = '.';
	char *stop = NULL;
	errno = 0;
	double x = strtod(buf, &stop);
	if (stop != buf + n || !isfinite(x) || errno == ERANGE)
		return pho_fail(lx, PHO_ERR_INVALID, "%s: '%s' is not a number",
		                what, buf);
	*v = x;
	return PHO_OK;
}

static int separator(char c)
{
	return c == ' ' || c == '\t' || c == ',' || c == '\f' || c == '\v';
}

pho_status pho_token(pho_lex *lx, const char *what, double *v)
{
	for (;;) { /* separators and line ends; line_end may reach end */
		if (lx->p < lx->end && separator(*lx->p))
			lx->p++;
		else if (!line_end(lx))
			break;
	}
	if (lx->p >= lx->end)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "the file ends before the %s", what);
	lx->at = lx->line;
	const char *b = lx->p;
	while (lx->p < lx->end && !separator(*lx->p) && *lx->p != '\n' &&
	       *lx->p != '\r')
		lx->p++;
	return number(lx, what, b, (size_t)(lx->p - b), 0, v);
}

pho_status pho_line_number(pho_lex *lx, const char *what, double *v)
{
	const char *s;
	size_t n;
	if (!pho_next_line(lx, &s, &n))
		return pho_fail(lx, PHO_ERR_INVALID,
		                "the file ends before the %s", what);
	while (n && (*s == ' ' || *s == '\t'))
		s++, n--;
	while (n && (s[n - 1] == ' ' || s[n - 1] == '\t'))
		n--;
	return number(lx, what, s, n, 1, v);
}

static pho_status next(pho_lex *lx, int ies, const char *what, double *v)
{
	return ies ? pho_token(lx, what, v) : pho_line_number(lx, what, v);
}

pho_status pho_count(pho_lex *lx, int ies, const char *what, long lo, long hi,
                     long *v)
{
	double x;
	pho_status st = next(lx, ies, what, &x);
	if (st)
		return st;
	if (x != floor(x) || x < (double)lo || x > (double)hi)
		return pho_fail(lx, PHO_ERR_INVALID,
		                "%s is %g; need a whole number in [%ld, %ld]",
		                what, x, lo, hi);
	*v = (long)x;
	return PHO_OK;
}

pho_status pho_numbers(pho_lex *lx, int ies, const char *what, double *a,
                       size_t n, int ascending, double lo, double hi)
{
	for (size_t k = 0; k < n; k++) {
		char label[96];
		snprintf(label, sizeof label, "%s %zu", what, k + 1);
		pho_status st = next(lx, ies, label, &a[k]);
		if (st)
			return st;
		if (!ascending && a[k] < lo)
			return pho_fail(lx, PHO_ERR_INVALID,
			                "%s %zu is %g; need >= %g", what, k + 1,
			                a[k], lo);
		if (ascending && (a[k] < lo || a[k] > hi))
			return pho_fail(lx, PHO_ERR_INVALID,
			                "%s %zu is %g; need [%g, %g]", what,
			                k + 1, a[k], lo, hi);
		if (ascending && k && !(a[k] > a[k - 1]))
			return pho_fail(
			        lx, PHO_ERR_INVALID,
			        "%s %zu (%g) is not above the one before "
			        "(%g)",
			        what, k + 1, a[k], a[k - 1]);
	}
	return PHO_OK;
}
