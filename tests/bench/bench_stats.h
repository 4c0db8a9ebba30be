/*
 * bench_stats.h -- order statistics shared by the daemon benchmarks.
 */
#ifndef LUXRAD_BENCH_STATS_H
#define LUXRAD_BENCH_STATS_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

static inline int bench_cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return x < y ? -1 : x > y;
}

/* Percentile (0..100) of n values, nearest rank; sorts v. */
static inline double bench_pct(double *v, int n, double p)
{
	if (n <= 0)
		return NAN;
	qsort(v, (size_t)n, sizeof(double), bench_cmp_double);
	int k = (int)ceil(p / 100.0 * n) - 1;
	if (k < 0)
		k = 0;
	if (k >= n)
		k = n - 1;
	return v[k];
}

/* Median of n values (v left as it is). */
static inline double bench_median(const double *v, int n)
{
	double *c = malloc((size_t)n * sizeof(double));
	if (!c)
		return NAN;
	memcpy(c, v, (size_t)n * sizeof(double));
	qsort(c, (size_t)n, sizeof(double), bench_cmp_double);
	double m = n % 2 ? c[n / 2] : 0.5 * (c[n / 2 - 1] + c[n / 2]);
	free(c);
	return m;
}

#endif
