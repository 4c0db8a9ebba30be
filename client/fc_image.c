/*
 * fc_image.c -- false-colour pictures of illuminance grids: the scale and
 * its colours, marching-squares isolines, the legend, the composed image
 * and its PNG encoding.  (fc_pixels.c holds the image and its drawing
 * primitives, fc_font.c the legend's digits.)
 *
 * DESIGN
 * Bands, not a continuous ramp: a reader compares a colour with the
 * legend, and with a handful of bands the comparison is exact; the
 * steps are the illuminances EN 12464-1 prescribes (..., 100, 150, 200,
 * 300, 500, 750, ... lux), so a band boundary reads as a requirement met
 * or not.  The picture is interpolated bilinearly between cell centres,
 * the same surface marching squares contours, so every isoline runs
 * along a band boundary.  The ramp is dark blue through teal and green
 * to yellow: lightness rises monotonically (it reads in grey too) and no
 * two bands share a hue.
 */
#include <math.h>
#include <png.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fc_image.h"

#define TARGET_PX 480 /* longer side of the plot when the size is free */
#define MARGIN 8
#define LEGEND_GAP 16
#define BAR_W 24
#define BAND_H 22
#define FONT_SCALE 2

static const unsigned char NO_POINT[3] = {224, 224, 224};
static const unsigned char FRAME[3] = {60, 60, 60};
static const unsigned char INK[3] = {20, 20, 20};
static const unsigned char PAPER[3] = {255, 255, 255};

/* The ramp's anchors, evenly spaced in t in [0, 1]. */
static const unsigned char RAMP[][3] = {{68, 1, 84},
                                        {59, 82, 139},
                                        {33, 145, 140},
                                        {94, 201, 98},
                                        {253, 231, 37}};
#define NRAMP ((int)(sizeof(RAMP) / sizeof(RAMP[0])))

/* ------------------------------------------------------------------ scale */

/* The next value of the series 1, 1.5, 2, 3, 5, 7.5 x 10^k above v. */
static double series_next(double v)
{
	static const double m[] = {1, 1.5, 2, 3, 5, 7.5, 10};
	double p = pow(10, floor(log10(v)));
	for (int i = 0; i < 7; i++)
		if (m[i] * p > v * (1 + 1e-9))
			return m[i] * p;
	return 10 * p;
}

static void scale_even(double lo, double hi, fc_scale *s)
{
	double raw = (hi - lo) / 5, p = pow(10, floor(log10(raw)));
	double step = raw / p <= 1     ? p
	              : raw / p <= 2   ? 2 * p
	              : raw / p <= 2.5 ? 2.5 * p
	              : raw / p <= 5   ? 5 * p
	                               : 10 * p;
	s->n = 0;
	for (double v = (floor(lo / step) + 1) * step;
	     v < hi && s->n < FC_LEVELS_MAX; v += step)
		s->level[s->n++] = fabs(v) < 1e-12 * step ? 0 : v;
}

void fc_scale_auto(double lo, double hi, fc_scale *s)
{
	double all[64];
	int n = 0;
	s->n = 0;
	if (!(hi > lo) || !isfinite(lo) || !isfinite(hi))
		return;
	/* below a fiftieth of the maximum is "dark": one band */
	double from = lo > hi / 50 ? lo : hi / 50;
	if (hi > 0)
		for (double v = series_next(from); v < hi && n < 64;
		     v = series_next(v))
			all[n++] = v;
	if (n < 4) {
		scale_even(lo, hi, s);
		return;
	}
	int stride = (n + FC_LEVELS_MAX - 3) / (FC_LEVELS_MAX - 2);
	for (int i = 0; i < n; i += stride)
		s->level[s->n++] = all[i];
}

int fc_band(const fc_scale *s, double v)
{
	int b = 0;
	while (b < s->n && v >= s->level[b])
		b++;
	return b;
}

void fc_band_colour(const fc_scale *s, int b, unsigned char rgb[3])
{
	double t = s->n > 0 ? (double)b / s->n : 0.5;
	double x = (t < 0 ? 0 : t > 1 ? 1 : t) * (NRAMP - 1);
	int k = (int)x < NRAMP - 1 ? (int)x : NRAMP - 2;
	double f = x - k;
	for (int c = 0; c < 3; c++)
		rgb[c] = (unsigned char)lround(RAMP[k][c] * (1 - f) +
		                               RAMP[k + 1][c] * f);
}

void fc_level_text(double v, char *buf, size_t len)
{
	snprintf(buf, len, "%.6g", v);
}

/* -------------------------------------------------------------- isolines */

/* Where the edge from (x0, y0) value a to (x1, y1) value b meets level. */
static void cross(double x0, double y0, double a, double x1, double y1,
                  double b, double level, double out[2])
{
	double f = b != a ? (level - a) / (b - a) : 0.5;
	out[0] = x0 + f * (x1 - x0);
	out[1] = y0 + f * (y1 - y0);
}

size_t fc_march(const double *v, int nu, int nv, double level, fc_seg_fn fn,
                void *ud)
{
	size_t nseg = 0;
	for (int j = 0; j + 1 < nv; j++) {
		for (int i = 0; i + 1 < nu; i++) {
			/* corners a (i,j), b (i+1,j), c (i+1,j+1), d (i,j+1) */
			double a = v[(size_t)j * nu + i];
			double b = v[(size_t)j * nu + i + 1];
			double c = v[(size_t)(j + 1) * nu + i + 1];
			double d = v[(size_t)(j + 1) * nu + i];
			if (!isfinite(a) || !isfinite(b) || !isfinite(c) ||
			    !isfinite(d))
				continue;
			int sa = a >= level, sb = b >= level, sc = c >= level,
			    sd = d >= level;
			double e[4][2]; /* top, right, bottom, left */
			int has[4] = {sa != sb, sb != sc, sc != sd, sd != sa};
			cross(i, j, a, i + 1, j, b, level, e[0]);
			cross(i + 1, j, b, i + 1, j + 1, c, level, e[1]);
			cross(i + 1, j + 1, c, i, j + 1, d, level, e[2]);
			cross(i, j + 1, d, i, j, a, level, e[3]);
			int pair[2][2], np = 0;
			if (has[0] && has[1] && has[2] && has[3]) {
				/* saddle: the centre decides which corners
				 * the lines cut off */
				int sm = (a + b + c + d) / 4 >= level;
				int same = sm == sa;
				pair[0][0] = same ? 0 : 3;
				pair[0][1] = same ? 1 : 0;
				pair[1][0] = same ? 2 : 1;
				pair[1][1] = same ? 3 : 2;
				np = 2;
			} else {
				int k = 0;
				for (int m = 0; m < 4; m++)
					if (has[m])
						pair[0][k++] = m;
				np = k == 2;
			}
			for (int p = 0; p < np; p++) {
				const double *s0 = e[pair[p][0]];
				const double *s1 = e[pair[p][1]];
				if (fn)
					fn(ud, s0[0], s0[1], s1[0], s1[1]);
				nseg++;
			}
		}
	}
	return nseg;
}

/* ---------------------------------------------------------------- picture */

/* The grid's value at grid coordinates (gx, gy), NaN where no point. */
static double sample(const double *v, int nu, int nv, double gx, double gy)
{
	int i0 = (int)floor(gx), j0 = (int)floor(gy);
	i0 = i0 < 0 ? 0 : i0 > nu - 1 ? nu - 1 : i0;
	j0 = j0 < 0 ? 0 : j0 > nv - 1 ? nv - 1 : j0;
	int i1 = i0 + 1 < nu ? i0 + 1 : i0, j1 = j0 + 1 < nv ? j0 + 1 : j0;
	double fx = gx - i0, fy = gy - j0;
	fx = fx < 0 ? 0 : fx > 1 ? 1 : fx;
	fy = fy < 0 ? 0 : fy > 1 ? 1 : fy;
	double a = v[(size_t)j0 * nu + i0], b = v[(size_t)j0 * nu + i1];
	double c = v[(size_t)j1 * nu + i1], d = v[(size_t)j1 * nu + i0];
	if (isfinite(a) && isfinite(b) && isfinite(c) && isfinite(d))
		return (a * (1 - fx) + b * fx) * (1 - fy) +
		       (d * (1 - fx) + c * fx) * fy;
	int ni = (int)lround(gx), nj = (int)lround(gy);
	ni = ni < 0 ? 0 : ni > nu - 1 ? nu - 1 : ni;
	nj = nj < 0 ? 0 : nj > nv - 1 ? nv - 1 : nj;
	return v[(size_t)nj * nu + ni];
}

typedef struct iso_ctx {
	fc_image *im;
	int x0, y0, cell;
	unsigned char rgb[3];
} iso_ctx;

static void iso_seg(void *ud, double x0, double y0, double x1, double y1)
{
	iso_ctx *c = ud;
	fc_line(c->im, c->x0 + (int)floor((x0 + 0.5) * c->cell),
	        c->y0 + (int)floor((y0 + 0.5) * c->cell),
	        c->x0 + (int)floor((x1 + 0.5) * c->cell),
	        c->y0 + (int)floor((y1 + 0.5) * c->cell), c->rgb);
}

static void plot(fc_image *im, int x0, int y0, const double *lux, int nu,
                 int nv, const fc_scale *s, int cell)
{
	for (int py = 0; py < nv * cell; py++) {
		for (int px = 0; px < nu * cell; px++) {
			double gx = (px + 0.5) / cell - 0.5;
			double gy = (py + 0.5) / cell - 0.5;
			double v = sample(lux, nu, nv, gx, gy);
			unsigned char rgb[3];
			if (isfinite(v))
				fc_band_colour(s, fc_band(s, v), rgb);
			else
				memcpy(rgb, NO_POINT, 3);
			fc_fill(im, x0 + px, y0 + py, 1, 1, rgb);
		}
	}
	for (int k = 0; k < s->n; k++) {
		iso_ctx c = {im, x0, y0, cell, {0, 0, 0}};
		unsigned char below[3];
		fc_band_colour(s, k, below);
		double luma = 0.2126 * below[0] + 0.7152 * below[1] +
		              0.0722 * below[2];
		memcpy(c.rgb, luma > 110 ? INK : PAPER, 3);
		fc_march(lux, nu, nv, s->level[k], iso_seg, &c);
	}
	int w = nu * cell, h = nv * cell;
	fc_line(im, x0 - 1, y0 - 1, x0 + w, y0 - 1, FRAME);
	fc_line(im, x0 - 1, y0 + h, x0 + w, y0 + h, FRAME);
	fc_line(im, x0 - 1, y0 - 1, x0 - 1, y0 + h, FRAME);
	fc_line(im, x0 + w, y0 - 1, x0 + w, y0 + h, FRAME);
}

static int legend_width(const fc_scale *s)
{
	int tw = fc_text_width("lux", FONT_SCALE);
	for (int k = 0; k < s->n; k++) {
		char buf[32];
		fc_level_text(s->level[k], buf, sizeof(buf));
		int w = fc_text_width(buf, FONT_SCALE);
		tw = w > tw ? w : tw;
	}
	return BAR_W + 6 + tw;
}

static int legend_height(const fc_scale *s)
{
	return FC_FONT_H * FONT_SCALE + 10 + (s->n + 1) * BAND_H;
}

static void legend(fc_image *im, int x, int y, const fc_scale *s)
{
	fc_text(im, x, y, FONT_SCALE, "lux", INK);
	int top = y + FC_FONT_H * FONT_SCALE + 10;
	for (int b = s->n; b >= 0; b--) {
		unsigned char rgb[3];
		fc_band_colour(s, b, rgb);
		fc_fill(im, x, top + (s->n - b) * BAND_H, BAR_W, BAND_H, rgb);
	}
	for (int k = 0; k < s->n; k++) { /* boundary between k and k+1 */
		int yb = top + (s->n - k) * BAND_H;
		char buf[32];
		fc_level_text(s->level[k], buf, sizeof(buf));
		fc_line(im, x + BAR_W, yb, x + BAR_W + 4, yb, INK);
		fc_text(im, x + BAR_W + 6, yb - FC_FONT_H * FONT_SCALE / 2,
		        FONT_SCALE, buf, INK);
	}
	int h = (s->n + 1) * BAND_H;
	fc_line(im, x - 1, top - 1, x + BAR_W, top - 1, FRAME);
	fc_line(im, x - 1, top + h, x + BAR_W, top + h, FRAME);
	fc_line(im, x - 1, top - 1, x - 1, top + h, FRAME);
	fc_line(im, x + BAR_W, top - 1, x + BAR_W, top + h, FRAME);
}

int fc_render(const double *lux, int nu, int nv, const fc_scale *s, int cell_px,
              int with_legend, fc_image *out)
{
	out->rgb = NULL;
	out->w = out->h = 0;
	if (nu <= 0 || nv <= 0 || nu > 65536 || nv > 65536)
		return -1;
	int cell = cell_px > 0 ? cell_px : TARGET_PX / (nu > nv ? nu : nv);
	cell = cell < 1 ? 1 : cell > 64 ? 64 : cell;
	int pw = nu * cell, ph = nv * cell;
	int w = pw + 2 * MARGIN, h = ph + 2 * MARGIN;
	if (with_legend) {
		int lh = legend_height(s) + 2 * MARGIN;
		w += LEGEND_GAP + legend_width(s);
		h = lh > h ? lh : h;
	}
	if (fc_image_new(out, w, h, PAPER) != 0)
		return -1;
	plot(out, MARGIN, MARGIN, lux, nu, nv, s, cell);
	if (with_legend)
		legend(out, MARGIN + pw + LEGEND_GAP, MARGIN, s);
	return 0;
}

/* -------------------------------------------------------------------- PNG */

typedef struct membuf {
	unsigned char *p;
	size_t len, cap;
	int failed;
} membuf;

static void png_write_mem(png_structp png, png_bytep data, png_size_t n)
{
	membuf *m = png_get_io_ptr(png);
	if (m->failed)
		return;
	if (m->len + n > m->cap) {
		size_t cap = m->cap ? m->cap : 4096;
		while (cap < m->len + n)
			cap *= 2;
		unsigned char *p = realloc(m->p, cap);
		if (!p) {
			m->failed = 1;
			return;
		}
		m->p = p;
		m->cap = cap;
	}
	memcpy(m->p + m->len, data, n);
	m->len += n;
}

static void png_flush_mem(png_structp png)
{
	(void)png;
}

/* libpng reports errors by longjmp; nothing may be printed. */
static void png_quiet(png_structp png, png_const_charp msg)
{
	(void)msg;
	png_longjmp(png, 1);
}

static void png_quiet_warn(png_structp png, png_const_charp msg)
{
	(void)png;
	(void)msg;
}

int fc_png_encode(const fc_image *im, unsigned char **png_out, size_t *len)
{
	*png_out = NULL;
	*len = 0;
	if (!im->rgb || im->w <= 0 || im->h <= 0)
		return -1;
	/* on the heap: what libpng's callbacks change survives a longjmp */
	membuf *m = calloc(1, sizeof(*m));
	if (!m)
		return -1;
	png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL,
	                                          png_quiet, png_quiet_warn);
	png_infop info = png ? png_create_info_struct(png) : NULL;
	if (!info) {
		png_destroy_write_struct(&png, NULL);
		free(m);
		return -1;
	}
	if (setjmp(png_jmpbuf(png))) {
		png_destroy_write_struct(&png, &info);
		free(m->p);
		free(m);
		return -1;
	}
	png_set_write_fn(png, m, png_write_mem, png_flush_mem);
	png_set_IHDR(png, info, (png_uint_32)im->w, (png_uint_32)im->h, 8,
	             PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
	             PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
	png_write_info(png, info);
	for (int y = 0; y < im->h; y++)
		png_write_row(png, im->rgb + 3 * (size_t)y * (size_t)im->w);
	png_write_end(png, NULL);
	png_destroy_write_struct(&png, &info);
	int failed = m->failed;
	if (failed)
		free(m->p);
	else {
		*png_out = m->p;
		*len = m->len;
	}
	free(m);
	return failed ? -1 : 0;
}
