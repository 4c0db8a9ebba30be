/*
 * vec.h -- the few 3-vector operations the engine needs, in double.
 * Storage is float where memory matters; arithmetic is done in double.
 */
#ifndef LUXRAD_VEC_H
#define LUXRAD_VEC_H

#include <math.h>

typedef struct v3 {
	double x, y, z;
} v3;

static inline v3 v3_make(double x, double y, double z)
{
	v3 r = {x, y, z};
	return r;
}
static inline v3 v3_f(const float *f)
{
	return v3_make(f[0], f[1], f[2]);
}
static inline v3 v3_d(const double *d)
{
	return v3_make(d[0], d[1], d[2]);
}
static inline void v3_store_f(float *f, v3 a)
{
	f[0] = (float)a.x;
	f[1] = (float)a.y;
	f[2] = (float)a.z;
}
static inline v3 v3_add(v3 a, v3 b)
{
	return v3_make(a.x + b.x, a.y + b.y, a.z + b.z);
}
static inline v3 v3_sub(v3 a, v3 b)
{
	return v3_make(a.x - b.x, a.y - b.y, a.z - b.z);
}
static inline v3 v3_scale(v3 a, double s)
{
	return v3_make(a.x * s, a.y * s, a.z * s);
}
static inline v3 v3_madd(v3 a, v3 b, double s) /* a + b*s */
{
	return v3_make(a.x + b.x * s, a.y + b.y * s, a.z + b.z * s);
}
/* fmax(0, x) as an inline compare (GCC calls libm's fmax, which must
 * honour NaN: so does this, NaN and -0 both giving +0), for the
 * projected areas and box gaps asked for per link. */
static inline double rad_pos(double x)
{
	return x > 0 ? x : 0;
}
static inline double v3_dot(v3 a, v3 b)
{
	return a.x * b.x + a.y * b.y + a.z * b.z;
}
static inline v3 v3_cross(v3 a, v3 b)
{
	return v3_make(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z,
	               a.x * b.y - a.y * b.x);
}
static inline double v3_len(v3 a)
{
	return sqrt(v3_dot(a, a));
}
static inline v3 v3_norm(v3 a)
{
	double l = v3_len(a);
	return l > 0 ? v3_scale(a, 1.0 / l) : a;
}
static inline int v3_finite(v3 a)
{
	return isfinite(a.x) && isfinite(a.y) && isfinite(a.z);
}

#endif
