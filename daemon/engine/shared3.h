/*
 * shared3.h -- three signed values in 32 bits, with one shared exponent.
 *
 * Radiance's RGBE (Ward, Graphics Gems II) keeps a colour as three 8-bit
 * mantissas and the exponent of the largest; this is the same with signed
 * mantissas, for a radiosity increment, which can fall as well as rise:
 *
 *   bits  0..7   channel 0, two's complement, -127 .. 127
 *   bits  8..15  channel 1
 *   bits 16..23  channel 2
 *   bits 24..31  e: the values are the mantissas times 2^(e - 133);
 *                255 holds NaN
 *
 * The largest magnitude keeps 7 significant bits (64 .. 127 of its
 * mantissa): every channel is rounded to within 1/127 of the largest,
 * and the largest to within 1/128 of itself.  Magnitudes from 2^-126
 * (the least normal float) to 1e38 keep that precision; below, a triple
 * is 0, and above (infinities included) its channels are held at 1e38.
 * Rounding is to nearest, so the same input packs to the same bits on
 * every machine.
 */
#ifndef LUXRAD_SHARED3_H
#define LUXRAD_SHARED3_H

#include <math.h>
#include <stdint.h>
#include <string.h>

typedef uint32_t rad_shared3;

#define RAD_SHARED3_BIAS 133 /* e - 133: the mantissas' scale */
#define RAD_SHARED3_NAN 0xff000000u
#define RAD_SHARED3_MAX 1e38f

static inline rad_shared3 rad_shared3_pack(const float v[3])
{
	float x[3], m = 0;
	for (int c = 0; c < 3; c++) {
		if (isnan(v[c]))
			return RAD_SHARED3_NAN;
		x[c] = fmaxf(-RAD_SHARED3_MAX, fminf(v[c], RAD_SHARED3_MAX));
		m = fmaxf(m, fabsf(x[c]));
	}
	if (!(m >= 0x1p-126f))
		return 0;
	int e;
	(void)frexpf(m, &e); /* m = f 2^e, f in [0.5, 1): m 2^(7-e) < 128 */
	for (;;) {
		long q[3];
		int over = 0;
		for (int c = 0; c < 3; c++) {
			q[c] = lrintf(ldexpf(x[c], 7 - e));
			over |= q[c] > 127 || q[c] < -127;
		}
		if (over) { /* rounded up to 128: one binade higher */
			e++;
			continue;
		}
		uint32_t p = (uint32_t)(e + RAD_SHARED3_BIAS - 7) << 24;
		for (int c = 0; c < 3; c++)
			p |= (uint32_t)(uint8_t)(int8_t)q[c] << (8 * c);
		return p;
	}
}

static inline void rad_shared3_unpack(rad_shared3 p, float out[3])
{
	uint32_t e = p >> 24;
	if (e == 0xff) {
		out[0] = out[1] = out[2] = NAN;
		return;
	}
	/* 2^(e - 133) as a double: always a normal one, so exact */
	uint64_t bits = (uint64_t)(e + 1023 - RAD_SHARED3_BIAS) << 52;
	double s;
	memcpy(&s, &bits, sizeof(s));
	for (int c = 0; c < 3; c++)
		out[c] = (float)((int8_t)(uint8_t)(p >> (8 * c)) * s);
}

#endif
