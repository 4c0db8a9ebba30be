/*
 * closed_forms.h -- form factors in closed form, the analytic references
 * of the engine tests (derived in test_direct.c's header).
 */
#ifndef LUXRAD_TEST_CLOSED_FORMS_H
#define LUXRAD_TEST_CLOSED_FORMS_H

#include <math.h>

/* A differential area and the rectangle [0,a] x [0,b] parallel to it at
 * distance h, its corner above the area; odd in a and in b. */
static inline double ff_corner(double a, double b, double h)
{
	double A = a / h, B = b / h;
	double sa = sqrt(1 + A * A), sb = sqrt(1 + B * B);
	return (A / sa * atan(B / sa) + B / sb * atan(A / sb)) / (2 * M_PI);
}

/* Point at the origin, normal towards the rectangle [x1,x2] x [y1,y2]
 * parallel to it at distance h (signed corners add up). */
static inline double ff_parallel(double x1, double x2, double y1, double y2,
                                 double h)
{
	return ff_corner(x2, y2, h) - ff_corner(x1, y2, h) -
	       ff_corner(x2, y1, h) + ff_corner(x1, y1, h);
}

#endif
