/*
 * texture.c -- base-colour textures as reflectance: images decoded (PNG
 * with libpng, JPEG with libjpeg-turbo), turned to linear RGB, and the
 * mean of a texture over a triangle's UV footprint.
 *
 * A radiosity element has one reflectance, so what a texture gives a
 * polygon is the mean of its texels under the polygon, weighted by area:
 * within a triangle the UV map is affine, so equal areas on the surface
 * are equal areas in the image and the surface mean is the footprint's
 * mean in texel space.
 *
 * DESIGN
 *  - Texels are boxes (no filtering): the mean over a footprint is the
 *    integral of a piecewise-constant image divided by the footprint's
 *    area.  Each row keeps its prefix sums, so a row's integral between
 *    two abscissae is two lookups, wrap modes included (repeat and
 *    mirrored repeat are periodic, clamp extends the edge texels).  A
 *    triangle is integrated strip by strip, one texel row each, with
 *    two-point Gauss in y between the rows and corners (the chord is
 *    linear in y there, the prefix is piecewise linear in x).
 *  - A mip pyramid of box means bounds the work: a footprint taller than
 *    MAX_ROWS rows is integrated at the first level where it is not.  At
 *    the coarsest level (1 x 1, the image's mean) a footprint of any
 *    size costs one lookup.  Levels are made by exact box resampling
 *    (fractional weights), so every level keeps the image's mean.
 *  - Images over MAX_KEEP texels are resampled to under it as they are
 *    decoded: a footprint under one kept texel is where that shows.
 *    Larger than MAX_DECODE texels, they are not read at all.
 *  - glTF's base colour is sRGB-encoded whatever the file says; a PNG
 *    with another gamma is converted to sRGB by libpng first.  Alpha is
 *    dropped: every surface is opaque.
 *  - Images are decoded when a material first needs one, kept for the
 *    rest of the import within BUDGET bytes (least recently used go
 *    first, and are decoded again if needed), and all freed when the
 *    import ends: a scene holds reflectances, never texels.  An image
 *    that cannot be read is not an error: the material falls back to its
 *    baseColorFactor and a note says why, once per image.
 *  - Nothing here goes through the engine's counted allocator: this is
 *    the loader's scratch, gone before the scene is handed over.
 */
#include <math.h>
#include <setjmp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jpeglib.h>
#include <png.h>

#include "internal.h"
#include "pack.h"

#define MAX_ROWS 256                 /* per triangle, see DESIGN */
#define MAX_KEEP (1u << 21)          /* texels kept at level 0 */
#define MAX_DECODE ((size_t)1 << 26) /* texels decoded at most */
#define MAX_SIDE 65535u              /* pixels per side */
#define BUDGET ((size_t)512 << 20)   /* bytes of kept images */
#define MAX_LEVELS 32

typedef struct level {
	uint32_t w, h;
	float *pre; /* h rows of (w + 1) x 3 prefix sums of linear RGB */
} level;

struct sio_texture {
	level lv[MAX_LEVELS];
	int nlevels;
	size_t bytes;
};

typedef struct sio_tex_slot {
	sio_texture *t;
	uint64_t used; /* cache clock at last use */
	int failed;    /* cannot be read: noted once */
} sio_tex_slot;

/* ------------------------------------------------------------ decoding */

/* An 8-bit image as decoded: comps bytes per pixel, RGB first. */
typedef struct raw {
	unsigned char *px;
	uint32_t w, h;
	int comps;
} raw;

enum { DEC_OK = 0, DEC_BAD, DEC_NOMEM };

static int too_large(uint32_t w, uint32_t h, char *why, size_t n)
{
	if (w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE ||
	    (size_t)w * h > MAX_DECODE) {
		snprintf(why, n, "%u x %u pixels (at most %zu are read)", w, h,
		         MAX_DECODE);
		return 1;
	}
	return 0;
}

static int decode_png(const unsigned char *b, size_t len, raw *r, char *why,
                      size_t n)
{
	png_image img;
	memset(&img, 0, sizeof img);
	img.version = PNG_IMAGE_VERSION;
	if (!png_image_begin_read_from_memory(&img, b, len)) {
		snprintf(why, n, "PNG: %s", img.message);
		return DEC_BAD;
	}
	img.format = PNG_FORMAT_RGBA; /* 8-bit sRGB, not premultiplied */
	if (too_large(img.width, img.height, why, n)) {
		png_image_free(&img);
		return DEC_BAD;
	}
	r->px = malloc(PNG_IMAGE_SIZE(img));
	if (!r->px) {
		png_image_free(&img);
		return DEC_NOMEM;
	}
	if (!png_image_finish_read(&img, NULL, r->px, 0, NULL)) {
		snprintf(why, n, "PNG: %s", img.message);
		free(r->px);
		r->px = NULL;
		png_image_free(&img);
		return DEC_BAD;
	}
	r->w = img.width;
	r->h = img.height;
	r->comps = 4;
	png_image_free(&img);
	return DEC_OK;
}

/* libjpeg reports errors through error_exit, which must not return. */
typedef struct jpeg_fail {
	struct jpeg_error_mgr pub;
	jmp_buf at;
	char msg[JMSG_LENGTH_MAX];
} jpeg_fail;

static void jpeg_exit(j_common_ptr c)
{
	jpeg_fail *f = (jpeg_fail *)c->err;
	c->err->format_message(c, f->msg);
	longjmp(f->at, 1);
}

static void jpeg_quiet(j_common_ptr c)
{
	(void)c; /* warnings: libjpeg would print them */
}

static int decode_jpeg(const unsigned char *b, size_t len, raw *r, char *why,
                       size_t n)
{
	struct jpeg_decompress_struct ci;
	jpeg_fail f;
	unsigned char *volatile px = NULL;
	volatile int verdict = DEC_BAD;
	ci.err = jpeg_std_error(&f.pub);
	f.pub.error_exit = jpeg_exit;
	f.pub.output_message = jpeg_quiet;
	f.msg[0] = 0;
	if (setjmp(f.at)) {
		jpeg_destroy_decompress(&ci);
		free(px);
		if (f.msg[0])
			snprintf(why, n, "JPEG: %s", f.msg);
		return verdict;
	}
	jpeg_create_decompress(&ci);
	jpeg_mem_src(&ci, b, (unsigned long)len);
	jpeg_read_header(&ci, TRUE);
	if (ci.jpeg_color_space == JCS_CMYK ||
	    ci.jpeg_color_space == JCS_YCCK) {
		snprintf(why, n, "JPEG: CMYK images are not read");
		longjmp(f.at, 1);
	}
	ci.out_color_space = JCS_RGB;
	if (too_large(ci.image_width, ci.image_height, why, n))
		longjmp(f.at, 1);
	jpeg_start_decompress(&ci);
	size_t row = (size_t)ci.output_width * 3;
	px = malloc(row * ci.output_height);
	if (!px) {
		verdict = DEC_NOMEM;
		longjmp(f.at, 1);
	}
	while (ci.output_scanline < ci.output_height) {
		JSAMPROW at = px + row * ci.output_scanline;
		jpeg_read_scanlines(&ci, &at, 1);
	}
	jpeg_finish_decompress(&ci);
	r->px = px;
	r->w = ci.output_width;
	r->h = ci.output_height;
	r->comps = 3;
	jpeg_destroy_decompress(&ci);
	return DEC_OK;
}

/* By content, not by mimeType: exporters get that wrong. */
static int decode(const unsigned char *b, size_t len, raw *r, char *why,
                  size_t n)
{
	static const unsigned char png_sig[8] = {0x89, 'P',  'N',  'G',
	                                         '\r', '\n', 0x1a, '\n'};
	if (len >= 8 && memcmp(b, png_sig, 8) == 0)
		return decode_png(b, len, r, why, n);
	if (len >= 3 && b[0] == 0xff && b[1] == 0xd8 && b[2] == 0xff)
		return decode_jpeg(b, len, r, why, n);
	if (sio_is_lfs_pointer(b, len))
		snprintf(why, n, "%s", SIO_LFS_HINT);
	else
		snprintf(why, n, "neither PNG nor JPEG");
	return DEC_BAD;
}

/* ------------------------------------------------------------- levels */

/* sRGB-encoded byte to linear (IEC 61966-2-1). */
static const float *srgb_table(void)
{
	static float t[256];
	static int made;
	if (!made) {
		for (int i = 0; i < 256; i++) {
			double c = i / 255.0;
			t[i] = (float)(c <= 0.04045
			                       ? c / 12.92
			                       : pow((c + 0.055) / 1.055, 2.4));
		}
		made = 1;
	}
	return t;
}

/* A source of rows as prefix sums: (w + 1) x 3 doubles for row y. */
typedef struct rows {
	uint32_t w, h;
	const raw *r;    /* either the decoded image */
	const level *lv; /* or a level */
} rows;

static void row_prefix(const rows *s, uint32_t y, double *pre)
{
	pre[0] = pre[1] = pre[2] = 0;
	if (s->lv) {
		const float *p = s->lv->pre + (size_t)y * (s->w + 1) * 3;
		for (size_t k = 0; k < (size_t)(s->w + 1) * 3; k++)
			pre[k] = p[k];
		return;
	}
	const float *lin = srgb_table();
	const unsigned char *px = s->r->px + (size_t)y * s->w * s->r->comps;
	for (uint32_t x = 0; x < s->w; x++)
		for (int c = 0; c < 3; c++)
			pre[3 * (x + 1) + c] =
			        pre[3 * x + c] + lin[px[s->r->comps * x + c]];
}

/* Integral of a prefix row over [x0, x1] within [0, w], per channel. */
static void prefix_span(const double *pre, uint32_t w, double x0, double x1,
                        double out[3])
{
	double xs[2] = {x0, x1}, f[2][3];
	for (int k = 0; k < 2; k++) {
		double x = xs[k] < 0 ? 0 : xs[k] > w ? w : xs[k];
		uint32_t i = (uint32_t)x;
		if (i >= w)
			i = w - 1;
		double t = x - i;
		for (int c = 0; c < 3; c++)
			f[k][c] = pre[3 * i + c] +
			          t * (pre[3 * (i + 1) + c] - pre[3 * i + c]);
	}
	for (int c = 0; c < 3; c++)
		out[c] = f[1][c] - f[0][c];
}

/* Box-resample src to w x h texels into lv (prefix sums): every target
 * texel is the exact mean of the source area it covers. */
static int resample(const rows *src, uint32_t w, uint32_t h, level *lv)
{
	size_t stride = (size_t)(w + 1) * 3;
	double *pre = malloc((size_t)(src->w + 1) * 3 * sizeof(*pre));
	double *acc = calloc((size_t)w * 3, sizeof(*acc));
	lv->pre = malloc(stride * h * sizeof(*lv->pre));
	if (!pre || !acc || !lv->pre) {
		free(pre);
		free(acc);
		free(lv->pre);
		lv->pre = NULL;
		return 0;
	}
	lv->w = w;
	lv->h = h;
	double sx = (double)src->w / w, sy = (double)src->h / h;
	uint32_t sy0 = 0;
	for (uint32_t y = 0; y < h; y++) {
		double y0 = y * sy, y1 = (y + 1) * sy;
		memset(acc, 0, (size_t)w * 3 * sizeof(*acc));
		for (uint32_t j = sy0; j < src->h && j < y1; j++) {
			double wy = fmin(y1, j + 1.0) - fmax(y0, (double)j);
			if (!(wy > 0))
				continue;
			row_prefix(src, j, pre);
			for (uint32_t x = 0; x < w; x++) {
				double v[3];
				prefix_span(pre, src->w, x * sx, (x + 1) * sx,
				            v);
				for (int c = 0; c < 3; c++)
					acc[3 * x + c] += wy * v[c];
			}
		}
		sy0 = (uint32_t)floor(y1);
		float *out = lv->pre + stride * y;
		double run[3] = {0, 0, 0};
		out[0] = out[1] = out[2] = 0;
		for (uint32_t x = 0; x < w; x++)
			for (int c = 0; c < 3; c++) {
				run[c] += acc[3 * x + c] / (sx * sy);
				out[3 * (x + 1) + c] = (float)run[c];
			}
	}
	free(pre);
	free(acc);
	return 1;
}

static void texture_free(sio_texture *t)
{
	if (!t)
		return;
	for (int i = 0; i < t->nlevels; i++)
		free(t->lv[i].pre);
	free(t);
}

/* Halve a level's sides (each at least 1); 0 when it was 1 x 1. */
static int halve(uint32_t *w, uint32_t *h)
{
	if (*w == 1 && *h == 1)
		return 0;
	*w = *w > 1 ? *w / 2 : 1;
	*h = *h > 1 ? *h / 2 : 1;
	return 1;
}

/* The sides level 0 keeps of a w x h image: at most MAX_KEEP texels. */
static void kept_sides(uint32_t *w, uint32_t *h)
{
	while ((size_t)*w * *h > MAX_KEEP)
		halve(w, h);
}

static size_t level_bytes(uint32_t w, uint32_t h)
{
	return (size_t)(w + 1) * 3 * h * sizeof(float);
}

/* What prepare() will hold for a w x h image, before it is made. */
static size_t pyramid_bytes(uint32_t w, uint32_t h)
{
	size_t n = 0;
	int k = 0;
	kept_sides(&w, &h);
	do
		n += level_bytes(w, h);
	while (++k < MAX_LEVELS && halve(&w, &h));
	return n;
}

/* Level 0 (at most MAX_KEEP texels) and the pyramid down to 1 x 1. */
static sio_texture *prepare(const raw *r)
{
	sio_texture *t = calloc(1, sizeof(*t));
	if (!t)
		return NULL;
	uint32_t w = r->w, h = r->h;
	kept_sides(&w, &h);
	rows src = {r->w, r->h, r, NULL};
	do {
		level *lv = &t->lv[t->nlevels];
		if (!resample(&src, w, h, lv)) {
			texture_free(t);
			return NULL;
		}
		t->bytes += level_bytes(w, h);
		t->nlevels++;
		src = (rows){w, h, NULL, lv};
	} while (t->nlevels < MAX_LEVELS && halve(&w, &h));
	return t;
}

/* ------------------------------------------------------- the footprint */

/* Row j of the infinite, wrapped image, as a row of lv. */
static uint32_t wrap_row(int64_t j, uint32_t h, int wrap)
{
	if (wrap == SIO_GL_CLAMP_TO_EDGE)
		return j < 0 ? 0 : j >= h ? h - 1 : (uint32_t)j;
	if (wrap == SIO_GL_MIRRORED_REPEAT) {
		int64_t m = j % (2 * (int64_t)h);
		if (m < 0)
			m += 2 * (int64_t)h;
		return m < h ? (uint32_t)m : (uint32_t)(2 * (int64_t)h - 1 - m);
	}
	int64_t m = j % (int64_t)h;
	return (uint32_t)(m < 0 ? m + h : m);
}

/* Prefix of row p at r in [0, w] (linear within a texel), RGB. */
static void prefix_at(const float *p, uint32_t w, double r, double out[3])
{
	r = r < 0 ? 0 : r > w ? w : r;
	uint32_t i = r >= w ? w - 1 : (uint32_t)r;
	const float *a = p + 3 * i;
	double t = r - i;
	for (int c = 0; c < 3; c++)
		out[c] = a[c] + t * (a[3 + c] - a[c]);
}

/* Integral from 0 to x of row p (w texels) wrapped as wrap, RGB. */
static void row_integral(const float *p, uint32_t w, int wrap, double x,
                         double out[3])
{
	const float *total = p + 3 * w;
	if (wrap == SIO_GL_CLAMP_TO_EDGE) {
		if (x <= 0) {
			for (int c = 0; c < 3; c++)
				out[c] = x * (p[3 + c] - p[c]);
		} else if (x >= w) {
			for (int c = 0; c < 3; c++)
				out[c] = total[c] +
				         (x - w) * (total[c] - total[c - 3]);
		} else {
			prefix_at(p, w, x, out);
		}
		return;
	}
	double in[3];
	if (wrap == SIO_GL_MIRRORED_REPEAT) {
		/* Over [w, 2w] the row runs backwards: the integral to r is
		 * total + (total - P(2w - r)). */
		double k = floor(x / (2.0 * w)), r = x - k * 2.0 * w;
		prefix_at(p, w, r <= w ? r : 2.0 * w - r, in);
		for (int c = 0; c < 3; c++)
			out[c] = 2 * k * total[c] +
			         (r <= w ? in[c] : 2 * total[c] - in[c]);
		return;
	}
	double k = floor(x / w);
	prefix_at(p, w, x - k * w, in);
	for (int c = 0; c < 3; c++)
		out[c] = k * total[c] + in[c];
}

/* The triangle's chord at height y: [*xl, *xr]. */
static void chord(const double p[3][2], double y, double *xl, double *xr)
{
	*xl = INFINITY;
	*xr = -INFINITY;
	for (int k = 0; k < 3; k++) {
		const double *a = p[k], *b = p[(k + 1) % 3];
		if (a[1] == b[1] || y < fmin(a[1], b[1]) ||
		    y > fmax(a[1], b[1]))
			continue;
		double x = a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
		*xl = fmin(*xl, x);
		*xr = fmax(*xr, x);
	}
}

/* Integrate over the triangle p (texel coordinates of lv). */
static int integrate(const level *lv, const int wrap[2], const double p[3][2],
                     double rgb[3])
{
	double ys[3] = {p[0][1], p[1][1], p[2][1]};
	for (int i = 1; i < 3; i++) /* sort the corners' heights */
		for (int j = i; j > 0 && ys[j] < ys[j - 1]; j--) {
			double t = ys[j];
			ys[j] = ys[j - 1];
			ys[j - 1] = t;
		}
	double sum[3] = {0, 0, 0}, area = 0;
	const double g = 0.5 / sqrt(3.0);
	for (double j = floor(ys[0]); j < ys[2]; j++) {
		const float *row =
		        lv->pre + (size_t)wrap_row((int64_t)j, lv->h, wrap[1]) *
		                          (lv->w + 1) * 3;
		/* The strip's part of the triangle, cut at the middle
		 * corner: the chord is linear in y on each piece. */
		double cut[3] = {fmax(j, ys[0]), ys[1], fmin(j + 1, ys[2])};
		int n = 3;
		if (!(ys[1] > cut[0] && ys[1] < cut[2])) {
			cut[1] = cut[2];
			n = 2;
		}
		for (int s = 0; s + 1 < n; s++) {
			double a = cut[s], b = cut[s + 1], h = b - a;
			if (!(h > 0))
				continue;
			for (int q = -1; q <= 1; q += 2) {
				double xl, xr;
				chord(p, 0.5 * (a + b) + q * g * h, &xl, &xr);
				if (!(xr > xl))
					continue;
				double fr[3], fl[3];
				row_integral(row, lv->w, wrap[0], xr, fr);
				row_integral(row, lv->w, wrap[0], xl, fl);
				area += 0.5 * h * (xr - xl);
				for (int c = 0; c < 3; c++)
					sum[c] += 0.5 * h * (fr[c] - fl[c]);
			}
		}
	}
	if (!(area > 0))
		return 0;
	for (int c = 0; c < 3; c++)
		rgb[c] = sum[c] / area;
	return 1;
}

/* The texel under point (x, y) of lv. */
static void texel(const level *lv, const int wrap[2], double x, double y,
                  double rgb[3])
{
	const float *row =
	        lv->pre + (size_t)wrap_row((int64_t)floor(y), lv->h, wrap[1]) *
	                          (lv->w + 1) * 3;
	double x0 = floor(x), f1[3], f0[3];
	row_integral(row, lv->w, wrap[0], x0 + 1, f1);
	row_integral(row, lv->w, wrap[0], x0, f0);
	for (int c = 0; c < 3; c++)
		rgb[c] = f1[c] - f0[c];
}

void sio_tex_mean(const sio_texture *t, const int wrap[2],
                  const double uv[3][2], double rgb[3])
{
	int L = 0;
	double p[3][2];
	for (;; L++) {
		const level *lv = &t->lv[L];
		double lo = INFINITY, hi = -INFINITY;
		for (int k = 0; k < 3; k++) {
			p[k][0] = uv[k][0] * lv->w;
			p[k][1] = uv[k][1] * lv->h;
			lo = fmin(lo, p[k][1]);
			hi = fmax(hi, p[k][1]);
		}
		if (ceil(hi) - floor(lo) <= MAX_ROWS || L + 1 == t->nlevels)
			break;
	}
	const level *lv = &t->lv[L];
	double cy = (p[0][1] + p[1][1] + p[2][1]) / 3;
	double cx = (p[0][0] + p[1][0] + p[2][0]) / 3;
	int coarsest = lv->w == 1 && lv->h == 1;
	if (coarsest || !integrate(lv, wrap, p, rgb))
		texel(coarsest ? lv : &t->lv[0], wrap,
		      coarsest ? 0 : cx * t->lv[0].w / lv->w,
		      coarsest ? 0 : cy * t->lv[0].h / lv->h, rgb);
}

void sio_tex_image_mean(const sio_texture *t, double rgb[3])
{
	const level *lv = &t->lv[t->nlevels - 1];
	for (int c = 0; c < 3; c++)
		rgb[c] = lv->pre[3 * lv->w + c] / lv->w;
}

/* -------------------------------------------------------------- cache */

rad_status sio_tex_cache_init(sio_tex_cache *c, const sio_doc *d,
                              sio_info *info, rad_error *err)
{
	memset(c, 0, sizeof(*c));
	c->d = d;
	c->info = info;
	if (d->nimages && !(c->slot = calloc(d->nimages, sizeof(*c->slot))))
		return rad_fail(err, RAD_ERR_NOMEM,
		                "out of memory while importing glTF");
	return RAD_OK;
}

void sio_tex_cache_free(sio_tex_cache *c)
{
	for (size_t i = 0; c->slot && i < c->d->nimages; i++)
		texture_free(c->slot[i].t);
	free(c->slot);
	c->slot = NULL;
}

/* Make room for need more bytes: the least recently used go. */
static void evict(sio_tex_cache *c, size_t need)
{
	while (c->bytes + need > BUDGET) {
		sio_tex_slot *lru = NULL;
		for (size_t i = 0; i < c->d->nimages; i++)
			if (c->slot[i].t &&
			    (!lru || c->slot[i].used < lru->used))
				lru = &c->slot[i];
		if (!lru)
			return;
		c->bytes -= lru->t->bytes;
		texture_free(lru->t);
		lru->t = NULL;
	}
}

/* The encoded bytes of image ii, or a reason why there are none. */
static rad_status image_bytes(const sio_tex_cache *c, int ii,
                              const unsigned char **b, size_t *len, char *why,
                              size_t n)
{
	const sio_doc_image *img = &c->d->images[ii];
	*b = NULL;
	*len = 0;
	if (img->buffer_view >= 0) {
		rad_error e;
		char where[32];
		snprintf(where, sizeof where, "image %d", ii);
		if (sio_view_bytes(c->d, where, img->buffer_view, b, len, &e) !=
		    RAD_OK)
			snprintf(why, n, "%.150s", e.msg);
	} else if (img->data) {
		*b = img->data;
		*len = img->size;
	} else {
		snprintf(why, n,
		         img->external ? "its file was not packed with the "
		                         "scene"
		                       : "no data");
	}
	return RAD_OK;
}

rad_status sio_tex_image(sio_tex_cache *c, int ii, const sio_texture **out,
                         rad_error *err)
{
	sio_tex_slot *s = &c->slot[ii];
	*out = NULL;
	if (s->failed)
		return RAD_OK;
	if (!s->t) {
		char why[160] = "";
		const unsigned char *b;
		size_t len;
		raw r = {0};
		image_bytes(c, ii, &b, &len, why, sizeof why);
		int dec = b ? decode(b, len, &r, why, sizeof why) : DEC_BAD;
		if (dec == DEC_OK) {
			/* Room first, so the pyramid is made within BUDGET. */
			evict(c, pyramid_bytes(r.w, r.h));
			s->t = prepare(&r);
			free(r.px);
			if (!s->t)
				dec = DEC_NOMEM;
		}
		if (dec == DEC_NOMEM)
			return rad_fail(err, RAD_ERR_NOMEM,
			                "image %d: out of memory decoding it",
			                ii);
		if (dec != DEC_OK) {
			s->failed = 1;
			sio_note(c->info,
			         "image %d '%s' not read (%s): its materials "
			         "use baseColorFactor alone",
			         ii, c->d->images[ii].name.s, why);
			return RAD_OK;
		}
		c->bytes += s->t->bytes;
		if (c->info)
			c->info->images_decoded++;
	}
	s->used = ++c->clock;
	*out = s->t;
	return RAD_OK;
}
