/*
 * photometry_data.h -- the sample photometric files of tests/data/
 * photometry/, read whole, for test_photometry and test_luminaire.
 * Include after cmocka.h.
 */
#ifndef LUXRAD_TEST_PHOTOMETRY_DATA_H
#define LUXRAD_TEST_PHOTOMETRY_DATA_H

#include <stdio.h>
#include <stdlib.h>

#define PHO_DATA LUXRAD_SOURCE_DIR "/tests/data/photometry/"

/* The bytes of sample file `name` (malloc'ed, under 64 KiB). */
static inline char *pho_sample(const char *name, size_t *len)
{
	char path[512];
	snprintf(path, sizeof path, PHO_DATA "%s", name);
	FILE *fp = fopen(path, "rb");
	if (!fp)
		fail_msg("cannot open %s", path);
	char *b = malloc(1 << 16);
	assert_non_null(b);
	*len = fread(b, 1, 1 << 16, fp);
	fclose(fp);
	return b;
}

#endif
