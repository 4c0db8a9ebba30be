/*
 * test_fc_image.c -- the false-colour images of luxrad report
 * (client/fc_image.h), checked by decoding what they encode:
 *  - the scale: EN 12464-1 steps inside the range, evenly spaced round
 *    steps for a narrow one, none for a uniform grid; bands and colours
 *    ordered (lightness rises with the band);
 *  - marching squares: the segments of a level on r^2 lie on the circle,
 *    squares with a missing corner give none;
 *  - the picture round trip through libpng: dimensions, each cell's
 *    colour its band's, grey where there is no point, white margins,
 *    isoline pixels between two bands, legend text drawn in ink;
 *  - the font: a glyph's pixels as its bitmap says.
 */
#include <math.h>
#include <png.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "fc_image.h"

static void test_scale_steps(void **state)
{
	(void)state;
	fc_scale s;
	fc_scale_auto(80, 800, &s);
	static const double want[] = {100, 150, 200, 300, 500, 750};
	assert_int_equal(s.n, 6);
	for (int i = 0; i < 6; i++)
		assert_true(fabs(s.level[i] - want[i]) < 1e-9);
	fc_scale_auto(100, 120, &s); /* narrow: even round steps */
	assert_true(s.n >= 3);
	for (int i = 1; i < s.n; i++)
		assert_true(fabs((s.level[i] - s.level[i - 1]) -
		                 (s.level[1] - s.level[0])) < 1e-9);
	assert_true(s.level[0] > 100 && s.level[s.n - 1] < 120);
	fc_scale_auto(0, 5000, &s); /* dark below a fiftieth: one band */
	assert_true(s.n >= 4 && s.n <= FC_LEVELS_MAX - 2);
	assert_true(s.level[0] >= 100);
	fc_scale_auto(42, 42, &s);
	assert_int_equal(s.n, 0);
	assert_int_equal(fc_band(&s, 42), 0);
	fc_scale_auto(80, 800, &s);
	assert_int_equal(fc_band(&s, 99), 0);
	assert_int_equal(fc_band(&s, 100), 1);
	assert_int_equal(fc_band(&s, 799), 6);
	double last = -1;
	for (int b = 0; b <= s.n; b++) {
		unsigned char c[3];
		fc_band_colour(&s, b, c);
		double l = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
		assert_true(l > last);
		last = l;
	}
	char buf[32];
	fc_level_text(0.75, buf, sizeof buf);
	assert_string_equal(buf, "0.75");
	fc_level_text(1500, buf, sizeof buf);
	assert_string_equal(buf, "1500");
}

typedef struct segs {
	size_t n;
	double worst;
} segs;

static void on_seg(void *ud, double x0, double y0, double x1, double y1)
{
	segs *s = ud;
	double r0 = hypot(x0 - 10, y0 - 10), r1 = hypot(x1 - 10, y1 - 10);
	s->n++;
	s->worst = fmax(s->worst, fmax(fabs(r0 - 5), fabs(r1 - 5)));
}

static void test_march_circle(void **state)
{
	(void)state;
	double v[21 * 21];
	for (int j = 0; j < 21; j++)
		for (int i = 0; i < 21; i++)
			v[j * 21 + i] =
			        (i - 10) * (i - 10) + (j - 10) * (j - 10);
	segs s = {0, 0};
	size_t n = fc_march(v, 21, 21, 25, on_seg, &s);
	assert_int_equal(n, s.n);
	assert_true(n >= 28); /* about 2 pi 5 / 1 squares crossed */
	assert_true(s.worst < 0.1);
	/* a missing corner removes the squares around it */
	v[10 * 21 + 15] = NAN; /* on the circle, at (15, 10) */
	segs t = {0, 0};
	assert_true(fc_march(v, 21, 21, 25, on_seg, &t) < n);
	/* no crossing, no segment */
	assert_int_equal(fc_march(v, 21, 21, 1e6, NULL, NULL), 0);
}

/* Decode PNG bytes to RGB with libpng's simplified API. */
static unsigned char *decode(const unsigned char *png, size_t len, int *w,
                             int *h)
{
	png_image im;
	memset(&im, 0, sizeof im);
	im.version = PNG_IMAGE_VERSION;
	assert_true(png_image_begin_read_from_memory(&im, png, len));
	im.format = PNG_FORMAT_RGB;
	unsigned char *rgb = malloc(PNG_IMAGE_SIZE(im));
	assert_non_null(rgb);
	assert_true(png_image_finish_read(&im, NULL, rgb, 0, NULL));
	*w = (int)im.width;
	*h = (int)im.height;
	return rgb;
}

static const unsigned char *px(const unsigned char *rgb, int w, int x, int y)
{
	return rgb + 3 * ((size_t)y * (size_t)w + (size_t)x);
}

static void test_picture_round_trip(void **state)
{
	(void)state;
	/* 4 x 3 cells: left half 100 lux, right half 400, one missing */
	double lux[12];
	for (int j = 0; j < 3; j++)
		for (int i = 0; i < 4; i++)
			lux[j * 4 + i] = i < 2 ? 100 : 400;
	lux[11] = NAN; /* cell (3, 2) */
	fc_scale s = {.n = 1, .level = {200}};
	fc_image im;
	assert_int_equal(fc_render(lux, 4, 3, &s, 20, 0, &im), 0);
	unsigned char *png;
	size_t len;
	assert_int_equal(fc_png_encode(&im, &png, &len), 0);
	int w, h;
	unsigned char *rgb = decode(png, len, &w, &h);
	assert_int_equal(w, 4 * 20 + 16);
	assert_int_equal(h, 3 * 20 + 16);
	assert_memory_equal(px(rgb, w, 0, 0), "\xff\xff\xff", 3);
	unsigned char lo[3], hi[3];
	fc_band_colour(&s, 0, lo);
	fc_band_colour(&s, 1, hi);
	assert_memory_equal(px(rgb, w, 8 + 10, 8 + 10), lo, 3);
	assert_memory_equal(px(rgb, w, 8 + 70, 8 + 10), hi, 3);
	assert_memory_equal(px(rgb, w, 8 + 70, 8 + 50), "\xe0\xe0\xe0", 3);
	/* the isoline at 200 lux crosses between columns 1 and 2, at a
	 * third of the way: x = 1 + 1/3 cells from the first centre */
	int iso = 8 + (int)floor((1 + 1.0 / 3 + 0.5) * 20);
	const unsigned char *c = px(rgb, w, iso, 8 + 30);
	assert_true(memcmp(c, lo, 3) != 0 && memcmp(c, hi, 3) != 0);
	free(rgb);
	free(png);
	fc_image_free(&im);

	/* with a legend: wider, ink in the label column */
	fc_scale_auto(100, 400, &s);
	assert_int_equal(fc_render(lux, 4, 3, &s, 20, 1, &im), 0);
	assert_true(im.w > 4 * 20 + 16 + 40);
	assert_true(im.h >= 16 + 7 * 2 + 10 + (s.n + 1) * 22);
	int ink = 0;
	for (int y = 0; y < im.h; y++)
		for (int x = 4 * 20 + 16 + 16 + 30; x < im.w; x++)
			ink += im.rgb[3 * ((size_t)y * im.w + x)] < 40;
	assert_true(ink > 50);
	fc_image_free(&im);
	assert_int_equal(fc_render(lux, 0, 3, &s, 20, 1, &im), -1);
}

static void test_font_glyph(void **state)
{
	(void)state;
	static const unsigned char white[3] = {255, 255, 255};
	static const unsigned char black[3] = {0, 0, 0};
	fc_image im;
	assert_int_equal(fc_image_new(&im, 20, 10, white), 0);
	fc_text(&im, 1, 1, 1, "1", black);
	/* "1": 0x04 0x0c 0x04 0x04 0x04 0x04 0x0e: 12 pixels, the stem in
	 * column 2 on every row */
	int n = 0;
	for (int i = 0; i < 20 * 10; i++)
		n += im.rgb[3 * i] == 0;
	assert_int_equal(n, 10);
	for (int r = 0; r < 7; r++)
		assert_int_equal(im.rgb[3 * ((r + 1) * 20 + 3)], 0);
	assert_int_equal(fc_text_width("150", 2), 3 * 12 - 2);
	fc_image_free(&im);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_scale_steps),
	        cmocka_unit_test(test_march_circle),
	        cmocka_unit_test(test_picture_round_trip),
	        cmocka_unit_test(test_font_glyph),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
