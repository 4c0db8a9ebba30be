/*
 * args.c -- the client's options and arguments: the option table (the
 * client's own rows, then rad.h's engine options), and the typed getters
 * commands read their values with, each refusal a usage error naming the
 * option.
 */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client.h"

const lx_opt_row lx_opt_table[LX_OPT_COUNT] = {
#define LX_OPT_ROW_(id, name, arg, meta, help) {name, meta, help, arg},
        LX_OPTIONS(LX_OPT_ROW_)
#undef LX_OPT_ROW_
/* from LX_OPT_ENGINE on: the rows of RAD_OPTIONS */
#define LX_ENGINE_ROW_(field, key, cli, type, def, lo, hi, range, choices,     \
                       metavar, unit, help)                                    \
	{cli, RAD_OPT_##type == RAD_OPT_BOOL ? NULL : metavar, help,           \
	 RAD_OPT_##type != RAD_OPT_BOOL},
                RAD_OPTIONS(LX_ENGINE_ROW_)
#undef LX_ENGINE_ROW_
};

int lx_usage_error(const lx_ctx *cx, const char *fmt, ...)
{
	va_list ap;

	fprintf(stderr, "luxrad: ");
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	if (cx && cx->cmd)
		fprintf(stderr, "\nTry 'luxrad %s --help'.\n", cx->cmd);
	else
		fprintf(stderr, "\nTry 'luxrad --help'.\n");
	return LX_EXIT_USAGE;
}

int lx_opt_double(const lx_ctx *cx, lx_opt o, double *out)
{
	const char *s = cx->val[o];
	char *end;

	if (!cx->given[o])
		return 1;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno == ERANGE || !isfinite(v)) {
		lx_usage_error(cx, "--%s: '%s' is not a finite number",
		               lx_opt_table[o].name, s);
		return -1;
	}
	*out = v;
	return 0;
}

int lx_opt_int(const lx_ctx *cx, lx_opt o, long long lo, long long hi,
               long long *out)
{
	const char *s = cx->val[o];
	char *end;

	if (!cx->given[o])
		return 1;
	errno = 0;
	long long v = strtoll(s, &end, 10);
	if (end == s || *end || errno == ERANGE || v < lo || v > hi) {
		lx_usage_error(cx, "--%s: '%s' is not an integer in %lld..%lld",
		               lx_opt_table[o].name, s, lo, hi);
		return -1;
	}
	*out = v;
	return 0;
}

int lx_opt_vec3(const lx_ctx *cx, lx_opt o, double out[3])
{
	const char *s = cx->val[o];
	char *end;

	for (int i = 0; i < 3; i++) {
		errno = 0;
		out[i] = strtod(s, &end);
		if (end == s || errno == ERANGE || !isfinite(out[i]) ||
		    *end != (i < 2 ? ',' : '\0')) {
			lx_usage_error(cx,
			               "--%s: '%s' is not three finite numbers "
			               "'x,y,z'",
			               lx_opt_table[o].name, cx->val[o]);
			return -1;
		}
		s = end + 1;
	}
	return 0;
}

int lx_pos_id(const lx_ctx *cx, int i, const char *what, long long *out)
{
	const char *s = cx->pos[i];
	char *end;

	errno = 0;
	long long v = strtoll(s, &end, 10);
	if (end == s || *end || errno == ERANGE || v <= 0 ||
	    strspn(s, "0123456789") != strlen(s)) {
		lx_usage_error(cx, "%s id '%s' is not a positive integer", what,
		               s);
		return -1;
	}
	*out = v;
	return 0;
}
