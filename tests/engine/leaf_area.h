/*
 * leaf_area.h -- the area of a leaf as rad_solver_leaves hands it to the
 * engine tests: a triangle (nv 3) or a parallelogram (nv 4), its corners
 * in order around it.
 */
#ifndef LUXRAD_TEST_LEAF_AREA_H
#define LUXRAD_TEST_LEAF_AREA_H

#include <math.h>

/* Area of the fan p0, pk, pk+1 (k = 1 .. nv - 2). */
static inline double leaf_area(const double p[4][3], int nv)
{
	double a = 0;
	for (int k = 1; k + 1 < nv; k++) {
		double u[3], v[3];
		for (int i = 0; i < 3; i++) {
			u[i] = p[k][i] - p[0][i];
			v[i] = p[k + 1][i] - p[0][i];
		}
		double c[3] = {u[1] * v[2] - u[2] * v[1],
		               u[2] * v[0] - u[0] * v[2],
		               u[0] * v[1] - u[1] * v[0]};
		a += 0.5 * sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
	}
	return a;
}

#endif
