/*
 * textutil.c -- see textutil.h.
 */
#include "textutil.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int srv_fail(char *msg, size_t len, const char *fmt, ...)
{
	if (msg && len) {
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(msg, len, fmt, ap);
		va_end(ap);
	}
	return -1;
}

int srv_parse_seconds(const char *v, double *out)
{
	static const struct {
		const char *suffix;
		double mult;
	} units[] = {{"", 1},   {"s", 1},    {"ms", 0.001},
	             {"m", 60}, {"min", 60}, {"h", 3600}};
	char *end;
	if ((*v < '0' || *v > '9') && *v != '.')
		return -1;
	errno = 0;
	double x = strtod(v, &end);
	if (errno || !isfinite(x) || end == v)
		return -1;
	while (*end == ' ' || *end == '\t')
		end++;
	for (size_t i = 0; i < sizeof units / sizeof units[0]; i++)
		if (strcmp(end, units[i].suffix) == 0) {
			*out = x * units[i].mult;
			return 0;
		}
	return -1;
}
