/*
 * rng.h -- splitmix64, the engine's counter-based random numbers: a
 * stream is a 64-bit state the caller keys (reference.c by seed, point
 * and path; audit.c by seed and link), and each draw adds the golden
 * gamma to it and mixes.  Results depend on the key alone, never on
 * threads or call order.
 */
#ifndef LUXRAD_RNG_H
#define LUXRAD_RNG_H

#include <stdint.h>

#define RAD_GOLDEN 0x9E3779B97F4A7C15ull

/* splitmix64's finaliser: a bijective 64-bit mix. */
static inline uint64_t rad_mix64(uint64_t z)
{
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
	return z ^ (z >> 31);
}

/* The next draw of stream *state: uniform in [0, 1), 53 bits. */
static inline double rad_uniform(uint64_t *state)
{
	*state += RAD_GOLDEN;
	return (double)(rad_mix64(*state) >> 11) * 0x1.0p-53;
}

#endif
