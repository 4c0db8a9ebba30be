/*
 * fc_pixels.c -- the RGB image of the false-colour pictures and its two
 * drawing primitives, a filled rectangle and a one-pixel line, both
 * clipped to the image (fc_image.h).
 */
#include <stdlib.h>
#include <string.h>

#include "fc_image.h"

int fc_image_new(fc_image *im, int w, int h, const unsigned char bg[3])
{
	im->w = im->h = 0;
	im->rgb = NULL;
	if (w <= 0 || h <= 0 || (size_t)w * (size_t)h > ((size_t)1 << 28))
		return -1;
	im->rgb = malloc((size_t)w * (size_t)h * 3);
	if (!im->rgb)
		return -1;
	im->w = w;
	im->h = h;
	fc_fill(im, 0, 0, w, h, bg);
	return 0;
}

void fc_image_free(fc_image *im)
{
	free(im->rgb);
	im->rgb = NULL;
	im->w = im->h = 0;
}

static void put(fc_image *im, int x, int y, const unsigned char rgb[3])
{
	if (x >= 0 && y >= 0 && x < im->w && y < im->h)
		memcpy(im->rgb + 3 * ((size_t)y * (size_t)im->w + (size_t)x),
		       rgb, 3);
}

void fc_fill(fc_image *im, int x, int y, int w, int h,
             const unsigned char rgb[3])
{
	int x0 = x < 0 ? 0 : x, y0 = y < 0 ? 0 : y;
	int x1 = x + w > im->w ? im->w : x + w;
	int y1 = y + h > im->h ? im->h : y + h;
	for (int j = y0; j < y1; j++)
		for (int i = x0; i < x1; i++)
			put(im, i, j, rgb);
}

void fc_line(fc_image *im, int x0, int y0, int x1, int y1,
             const unsigned char rgb[3])
{
	int dx = abs(x1 - x0), dy = -abs(y1 - y0);
	int sx = x0 < x1 ? 1 : -1, sy = y0 < y1 ? 1 : -1, e = dx + dy;
	for (;;) {
		put(im, x0, y0, rgb);
		if (x0 == x1 && y0 == y1)
			return;
		int e2 = 2 * e;
		if (e2 >= dy) {
			e += dy;
			x0 += sx;
		}
		if (e2 <= dx) {
			e += dx;
			y0 += sy;
		}
	}
}
