/*
 * fc_image.h -- false-colour images of illuminance grids, as PNG: the
 * colour scale and its steps, the picture of a grid with isolines at the
 * steps, a legend with the step values, and the PNG encoding (libpng).
 * Library luxrad_image: C and libpng only, no engine, no protocol, so
 * the thin client links it to draw reports.
 *
 * A grid is nu x nv lux values, row-major, rows along v (as query.grid
 * and query.node return them), NaN where there is no point.  Drawn, cell
 * (i, j) is a square whose centre is at pixel ((i + 0.5) c, (j + 0.5) c)
 * of the plot, c the cell size in pixels: u to the right, v down.
 *
 * Functions return 0, or -1 when out of memory or given nonsense (a
 * size <= 0); nothing is printed.
 */
#ifndef LUXRAD_FC_IMAGE_H
#define LUXRAD_FC_IMAGE_H

#include <stddef.h>

#define FC_FONT_W 5 /* glyph cell, pixels at scale 1 */
#define FC_FONT_H 7
#define FC_LEVELS_MAX 12 /* steps of a scale */

/* An RGB image, 8 bits per channel, rows top first. */
typedef struct fc_image {
	int w, h;
	unsigned char *rgb; /* 3 w h bytes; free with fc_image_free */
} fc_image;

int fc_image_new(fc_image *im, int w, int h, const unsigned char bg[3]);
void fc_image_free(fc_image *im);
/* Fill a rectangle, clipped to the image. */
void fc_fill(fc_image *im, int x, int y, int w, int h,
             const unsigned char rgb[3]);
/* A one-pixel line, clipped. */
void fc_line(fc_image *im, int x0, int y0, int x1, int y1,
             const unsigned char rgb[3]);

/* fc_font.c: text in the built-in 5 x 7 font at an integer scale; (x, y)
 * the top left.  Width in pixels of s at that scale. */
void fc_text(fc_image *im, int x, int y, int scale, const char *s,
             const unsigned char rgb[3]);
int fc_text_width(const char *s, int scale);

/*
 * A colour scale: n ascending steps dividing lux into n + 1 bands, each
 * band one colour of a perceptually ordered ramp (dark blue through green
 * to yellow).  fc_scale_auto picks the steps for values in [lo, hi]: the
 * EN 12464-1 series of illuminances (1, 1.5, 2, 3, 5, 7.5 times a power
 * of ten: 100, 150, 200, 300, 500, 750 lux...) that fall inside, from a
 * fiftieth of hi up (darker is one band), thinned to at most
 * FC_LEVELS_MAX - 2; when fewer than 4 fall inside, evenly spaced round
 * values (1, 2, 2.5 or 5 times a power of ten).  No steps
 * when hi <= lo (one band).
 */
typedef struct fc_scale {
	int n;
	double level[FC_LEVELS_MAX];
} fc_scale;

void fc_scale_auto(double lo, double hi, fc_scale *s);
/* Band of a value: 0 below level[0] ... n at or above level[n-1]. */
int fc_band(const fc_scale *s, double v);
/* Colour of band b of the scale. */
void fc_band_colour(const fc_scale *s, int b, unsigned char rgb[3]);
/* A step's value as the legend prints it ("0.75", "150", "1500"). */
void fc_level_text(double v, char *buf, size_t len);

/*
 * Marching squares: the line where the grid (bilinear between cell
 * centres, NaN cells skipped) crosses level, as segments in grid
 * coordinates (cell centre (i, j) at (i, j)), one call of fn each.
 * Returns the number of segments.
 */
typedef void (*fc_seg_fn)(void *ud, double x0, double y0, double x1, double y1);
size_t fc_march(const double *v, int nu, int nv, double level, fc_seg_fn fn,
                void *ud);

/*
 * The picture: the grid in its bands at cell px per cell (bilinear
 * between centres, flat next to missing cells, grey where there is no
 * point), isolines at every step, a frame; with a legend on the right
 * when legend is set (the bands top = brightest, the step values at
 * their boundaries, "lux" above).  cell_px <= 0 picks a size that makes
 * the longer side about 480 pixels.
 */
int fc_render(const double *lux, int nu, int nv, const fc_scale *s, int cell_px,
              int legend, fc_image *out);

/* Encode as an 8-bit RGB PNG; *png malloc'ed, caller frees. */
int fc_png_encode(const fc_image *im, unsigned char **png, size_t *len);

#endif
