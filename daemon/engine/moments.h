/*
 * moments.h -- running moments of a sample (count, mean, sum of squared
 * deviations), added one value at a time (Welford) and merged pairwise
 * (Chan et al.), for the Monte Carlo reference's per-point estimates.
 */
#ifndef LUXRAD_MOMENTS_H
#define LUXRAD_MOMENTS_H

#include <math.h>

/* Count, mean and sum of squared deviations of per-path lux values. */
typedef struct moments {
	double n, mean, m2;
} moments;

static inline void moments_add(moments *m, double x)
{
	m->n += 1.0;
	double d = x - m->mean;
	m->mean += d / m->n;
	m->m2 += d * (x - m->mean);
}

/* Chan et al.'s pairwise update: a := a + b. */
static inline void moments_merge(moments *a, const moments *b)
{
	if (b->n == 0)
		return;
	double n = a->n + b->n, d = b->mean - a->mean;
	a->mean += d * b->n / n;
	a->m2 += b->m2 + d * d * a->n * b->n / n;
	a->n = n;
}

static inline double moments_stderr(const moments *m)
{
	if (m->n < 2)
		return NAN;
	return sqrt(fmax(0.0, m->m2) / (m->n - 1) / m->n);
}

#endif
