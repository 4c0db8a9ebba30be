/*
 * test_photometry.c -- the photometry library (daemon/photometry) on
 * sample files written for it (tests/data/photometry).
 *
 * The samples' values follow closed forms, one per symmetry, in
 *     f(C, gamma) = a(C) (1 + gamma / 60)
 * with a(C) = 100 + 40 cos C + 25 sin C + 10 cos 2C (no symmetry),
 * 100 + 40 cos C + 10 cos 2C (mirror about C0-C180), 100 + 25 sin C +
 * 10 cos 2C (about C90-C270), 100 + 10 cos 2C (both) and 100
 * (rotational); each file gives only the planes its symmetry needs.  The
 * table must give f at every plane round the circle, times the file's
 * factors.  Two files give I0 cos(gamma) with a stated flux: their
 * tables must integrate to it.  Every malformed input -- each sample cut
 * at every length, bad numbers, bad counts, angles out of order -- must
 * come back as an error naming a line.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "photometry.h"
#include "photometry_data.h"

#define IES "full_2002.ies"
#define LDT "quadrant.ldt"

typedef enum shape { NONE, C0, C90, QUAD, ROT } shape;

static double f(shape s, double c_deg, double g_deg)
{
	double c = c_deg * M_PI / 180, a = 100;
	if (s == NONE)
		a += 40 * cos(c) + 25 * sin(c) + 10 * cos(2 * c);
	else if (s == C0)
		a += 40 * cos(c) + 10 * cos(2 * c);
	else if (s == C90)
		a += 25 * sin(c) + 10 * cos(2 * c);
	else if (s == QUAD)
		a += 10 * cos(2 * c);
	return a * (1 + g_deg / 60);
}

static pho_table *parse_file(const char *name, const pho_opts *o)
{
	size_t len;
	char *b = pho_sample(name, &len), err[256];
	pho_table *t = NULL;
	pho_status st = pho_parse(b, len, o, &t, err, sizeof err);
	free(b);
	if (st != PHO_OK)
		fail_msg("%s: %s: %s", name, pho_status_name(st), err);
	return t;
}

/* ------------------------------------------------------------ symmetry */

typedef struct sample {
	const char *file;
	shape shape;
	pho_symmetry sym;
	double step;  /* the file's C step, degrees */
	double scale; /* file value -> candela */
	const char *version;
} sample;

static const sample samples[] = {
        {"full_2002.ies", NONE, PHO_SYM_NONE, 90, 1.0, "LM-63-2002"},
        /* multiplier 2 x ballast 0.9 x (1995) ballast-lamp 0.95 */
        {"quadrant_1995.ies", QUAD, PHO_SYM_QUADRANT, 30, 1.71, "LM-63-1995"},
        {"c0_180_1986.ies", C0, PHO_SYM_C0_C180, 45, 1.0, "LM-63-1986"},
        {"c90_270_2019.ies", C90, PHO_SYM_C90_C270, 45, 1.0, "LM-63-2019"},
        /* cd/klm x 2000 lm / 1000 */
        {"none.ldt", NONE, PHO_SYM_NONE, 30, 2.0, "EULUMDAT"},
        {"c0_180.ldt", C0, PHO_SYM_C0_C180, 30, 2.0, "EULUMDAT"},
        {"c90_270.ldt", C90, PHO_SYM_C90_C270, 30, 2.0, "EULUMDAT"},
        {"quadrant.ldt", QUAD, PHO_SYM_QUADRANT, 30, 2.0, "EULUMDAT"},
};

static void test_every_plane_follows_the_file_symmetry(void **state)
{
	(void)state;
	for (size_t k = 0; k < sizeof samples / sizeof *samples; k++) {
		const sample *s = &samples[k];
		pho_table *t = parse_file(s->file, NULL);
		const pho_info *in = pho_table_info(t);
		assert_int_equal(in->symmetry, s->sym);
		assert_string_equal(in->version, s->version);
		const rad_candela_grid *g = pho_table_grid(t);
		assert_int_equal(g->c_deg[0], 0);
		assert_true(g->c_deg[g->nc - 1] == 360);
		for (double c = 0; c <= 360; c += s->step)
			for (uint32_t j = 0; j < g->ngamma; j++) {
				double gm = g->gamma_deg[j];
				double want = s->scale * f(s->shape, c, gm);
				double got = pho_candela(t, c, gm);
				if (!(fabs(got - want) <= 1e-4 * s->scale))
					fail_msg("%s: C %g gamma %g: %.6f cd, "
					         "want %.6f",
					         s->file, c, gm, got, want);
			}
		/* Halfway between planes: linear in C. */
		double c = 0.5 * s->step, gm = 30;
		double want = 0.5 * s->scale *
		              (f(s->shape, 0, gm) + f(s->shape, s->step, gm));
		assert_true(fabs(pho_candela(t, c, gm) - want) < 1e-4);
		/* The same direction named by a C outside [0, 360). */
		assert_true(pho_candela(t, c - 360, gm) ==
		            pho_candela(t, c, gm));
		pho_free(t);
	}
}

static void test_rotational_files_have_one_plane(void **state)
{
	(void)state;
	pho_table *t = parse_file("cosine_1000lm.ies", NULL);
	assert_int_equal(pho_table_grid(t)->nc, 1);
	assert_int_equal(pho_table_info(t)->symmetry, PHO_SYM_ROTATIONAL);
	/* 90 degrees in any plane is the same value. */
	assert_true(pho_candela(t, 17, 40) == pho_candela(t, 243, 40));
	/* Above the last gamma angle (90) the file gives nothing. */
	assert_true(pho_candela(t, 0, 120) == 0);
	pho_free(t);
	t = parse_file("cosine_1600lm.ldt", NULL);
	assert_int_equal(pho_table_grid(t)->nc, 1);
	pho_free(t);
}

/* -------------------------------------------------------------- lumens */

static void expect_rel(double got, double want, double tol, const char *what)
{
	double rel = fabs(got - want) / want;
	if (!(rel <= tol))
		fail_msg("%s: %.4f, want %.4f (%.3f %% > %.3f %%)", what, got,
		         want, 100 * rel, 100 * tol);
	print_message("  %s: %.4f lm vs %.4f (%.4f %%)\n", what, got, want,
	              100 * rel);
}

static void test_lumens_equal_what_the_file_declares(void **state)
{
	(void)state;
	pho_table *t = parse_file("cosine_1000lm.ies", NULL);
	const pho_info *in = pho_table_info(t);
	assert_int_equal(in->lamps, 1);
	assert_true(in->lamp_lumens == 1000);
	expect_rel(pho_lumens(t), in->lamp_lumens, 0.005, "IES lumens");
	assert_true(fabs(in->max_cd - 1000 / M_PI) < 1e-3);
	assert_true(fabs(in->opening_m[0] - 0.2) < 1e-12);
	assert_true(in->opening_circular);
	pho_free(t);

	t = parse_file("cosine_1600lm.ldt", NULL);
	in = pho_table_info(t);
	assert_true(fabs(in->lorl - 0.8) < 1e-12);
	assert_true(in->lamp_lumens == 2000);
	assert_true(fabs(in->lumens_declared - 1600) < 1e-9);
	expect_rel(pho_lumens(t), in->lumens_declared, 0.005, "LDT lumens");
	assert_true(fabs(in->opening_m[0] - 0.5) < 1e-12);
	assert_true(fabs(in->opening_m[1] - 0.25) < 1e-12);
	pho_free(t);
}

/* The closed-form flux against a fine midpoint sum of the lookups. */
static void test_flux_is_the_integral_of_the_lookup(void **state)
{
	(void)state;
	const char *files[] = {"full_2002.ies", "quadrant.ldt",
	                       "c90_270_2019.ies"};
	for (size_t k = 0; k < 3; k++) {
		pho_table *t = parse_file(files[k], NULL);
		const int n = 720;
		double sum = 0, h = M_PI / n, hc = 2 * M_PI / n;
		for (int i = 0; i < n; i++) {
			double gm = (i + 0.5) * h;
			double ring = 0;
			for (int j = 0; j < n; j++)
				ring += pho_candela(t, (j + 0.5) * 0.5,
				                    gm * 180 / M_PI);
			sum += ring * sin(gm) * h * hc;
		}
		expect_rel(sum, pho_lumens(t), 1e-4, files[k]);
		pho_free(t);
	}
}

/* ---------------------------------------------------- factors, options */

static void test_tilt_and_lamp_lumens_scale_the_table(void **state)
{
	(void)state;
	pho_table *t = parse_file("quadrant_1995.ies", NULL);
	double base = pho_table_info(t)->max_cd;
	assert_int_equal(pho_table_info(t)->tilt_geometry, 1);
	assert_true(pho_table_info(t)->tilt_factor == 1.0);
	/* circular opening, 0.3 m (units: metres) */
	assert_true(pho_table_info(t)->opening_circular);
	assert_true(fabs(pho_table_info(t)->opening_m[1] - 0.3) < 1e-12);
	pho_free(t);
	const double tilt[][2] = {{45, 0.9}, {22.5, 0.95}, {200, 0.7}};
	for (int k = 0; k < 3; k++) {
		pho_opts o = {.tilt_deg = tilt[k][0]};
		t = parse_file("quadrant_1995.ies", &o);
		assert_true(fabs(pho_table_info(t)->max_cd -
		                 tilt[k][1] * base) < 1e-9 * base);
		pho_free(t);
	}
	pho_opts o = {.lamp_lumens = 2500};
	t = parse_file("cosine_1000lm.ies", &o);
	expect_rel(pho_lumens(t), 2500, 0.005, "rescaled to 2500 lm");
	pho_free(t);
	/* Feet: the 1986 file's opening, 1 x 2 ft. */
	t = parse_file("c0_180_1986.ies", NULL);
	assert_true(fabs(pho_table_info(t)->opening_m[0] - 0.6096) < 1e-12);
	assert_true(fabs(pho_table_info(t)->opening_m[1] - 0.3048) < 1e-12);
	assert_true(pho_table_info(t)->absolute);
	pho_free(t);
}

/* ---------------------------------------------------------- bad input */

/* The sample with the first `from` replaced by `to`, parsed. */
static pho_status edited(const char *file, const char *from, const char *to,
                         const pho_opts *o, char *err, size_t errlen)
{
	size_t len;
	char *b = pho_sample(file, &len);
	char *at = memmem(b, len, from, strlen(from));
	if (!at)
		fail_msg("%s: no '%s'", file, from);
	size_t nf = strlen(from), nt = strlen(to), tail = len - (at - b) - nf;
	char *c = malloc(len - nf + nt);
	assert_non_null(c);
	memcpy(c, b, at - b);
	memcpy(c + (at - b), to, nt);
	memcpy(c + (at - b) + nt, at + nf, tail);
	pho_table *t = NULL;
	pho_status st = pho_parse(c, len - nf + nt, o, &t, err, errlen);
	if (st == PHO_OK)
		pho_free(t);
	else
		assert_null(t);
	free(c);
	free(b);
	return st;
}

static void expect_refused(const char *file, const char *from, const char *to,
                           pho_status want, const char *says)
{
	char err[256] = "";
	pho_status st = edited(file, from, to, NULL, err, sizeof err);
	if (st != want || !strstr(err, says) || strncmp(err, "line ", 5))
		fail_msg("%s with '%s' -> '%s': %s '%s'; want %s and '%s'",
		         file, from, to, pho_status_name(st), err,
		         pho_status_name(want), says);
}

static void test_bad_input_is_refused_naming_the_line(void **state)
{
	(void)state;
	static const struct {
		const char *file, *from, *to;
		pho_status want;
		const char *says;
	} cases[] = {
	        {IES, "TILT=NONE", "TILT=lamp.tlt", PHO_ERR_UNSUPPORTED,
	         "line 6: TILT=lamp.tlt names a tilt file"},
	        {IES, "19 5 1 2", "19 5 2 2", PHO_ERR_UNSUPPORTED, "type B"},
	        {IES, "19 5 1 2", "19 5 3 2", PHO_ERR_UNSUPPORTED, "type A"},
	        {IES, "0  10  20  30", "0  10  30  20", PHO_ERR_INVALID,
	         "vertical angle 4 (20) is not above"},
	        {IES, "0  90  180  270  360", "0  90  180  270  nan",
	         PHO_ERR_INVALID, "'nan' is not a number"},
	        {IES, "0  90  180  270  360", "45  90  180  270  360",
	         PHO_ERR_INVALID, "horizontal angles run 45..360"},
	        {IES, "1 1000 1.0 19 5", "-1 1000 1.0 19 5", PHO_ERR_INVALID,
	         "number of lamps is -1"},
	        {IES, "1 1000 1.0 19 5", "1 1000 1.0 19 5000000",
	         PHO_ERR_INVALID, "number of horizontal angles"},
	        {IES, "1 1000 1.0 19 5", "1 1000 1.0 4000 4000",
	         PHO_ERR_INVALID, "more than 1048576"},
	        {IES, "1 1000 1.0", "1 0 1.0", PHO_ERR_INVALID,
	         "lumens per lamp 0"},
	        {IES, "1 1000 1.0", "1 1000 0", PHO_ERR_INVALID,
	         "candela multiplier 0"},
	        {IES, "TILT=NONE", "TILT=INCLUDE\n1\n2\n0 0\n1 1",
	         PHO_ERR_INVALID, "tilt angle 2 (0) is not above"},
	        {IES, "TILT=NONE", "TILE=NONE", PHO_ERR_INVALID,
	         "no TILT= line"},
	        {"cosine_1000lm.ies", "318.3099", "-318.3099", PHO_ERR_INVALID,
	         "candela value 1 is -318.31"},
	        {LDT, "\r\n4\r\n12\r\n", "\r\n5\r\n12\r\n", PHO_ERR_INVALID,
	         "line 3: symmetry indicator Isym"},
	        {LDT, "\r\n4\r\n12\r\n", "\r\n4\r\n10\r\n", PHO_ERR_INVALID,
	         "Isym 4 with Mc 10"},
	        {LDT, "\r\n4\r\n12\r\n", "\r\n4\r\n-12\r\n", PHO_ERR_INVALID,
	         "line 4: number of C planes Mc"},
	        {LDT, "\r\n60\r\n90\r\n", "\r\n60\r\n9x0\r\n", PHO_ERR_INVALID,
	         "C angle 4: '9x0' is not a number"},
	        {LDT, "\r\n60\r\n90\r\n", "\r\n60\r\n100\r\n", PHO_ERR_INVALID,
	         "Isym 4 stores C planes 0..90"},
	        {LDT, "\r\n2000\r\n", "\r\n0\r\n", PHO_ERR_INVALID,
	         "lamp set 1: flux 0 lm"},
	};
	for (size_t k = 0; k < sizeof cases / sizeof *cases; k++)
		expect_refused(cases[k].file, cases[k].from, cases[k].to,
		               cases[k].want, cases[k].says);
	char err[64];
	pho_table *t = (pho_table *)1;
	assert_int_equal(pho_parse("", 0, NULL, &t, err, sizeof err),
	                 PHO_ERR_INVALID);
	assert_null(t);
	assert_string_equal(err, "line 1: empty input");
	/* absolute photometry has no lamp flux to rescale */
	pho_opts o = {.lamp_lumens = 100};
	assert_int_equal(
	        edited("c90_270_2019.ies", "TILT", "TILT", &o, err, sizeof err),
	        PHO_ERR_INVALID);
}

/* Where the last value starts: any shorter prefix must fail.  Values end
 * at blanks and commas in IES files, at line ends in EULUMDAT ones
 * (where a comma may be the decimal point). */
static size_t last_value_at(const char *file, const char *b, size_t len)
{
	const char *sep = strstr(file, ".ldt") ? "\r\n" : " \t\r\n,";
	size_t k = len;
	while (k && strchr(sep, b[k - 1]))
		k--;
	while (k && !strchr(sep, b[k - 1]))
		k--;
	return k;
}

static void test_every_truncation_fails_cleanly(void **state)
{
	(void)state;
	const char *files[] = {"full_2002.ies",     "quadrant_1995.ies",
	                       "c0_180_1986.ies",   "c90_270_2019.ies",
	                       "cosine_1000lm.ies", "none.ldt",
	                       "c0_180.ldt",        "c90_270.ldt",
	                       "quadrant.ldt",      "cosine_1600lm.ldt"};
	size_t tried = 0;
	for (size_t k = 0; k < sizeof files / sizeof *files; k++) {
		size_t len;
		char *b = pho_sample(files[k], &len);
		size_t must_fail = last_value_at(files[k], b, len);
		for (size_t n = 0; n < len; n++) {
			/* An exact-size copy: a read past it is a bug the
			 * sanitizer build reports. */
			char *c = malloc(n ? n : 1), err[256] = "";
			memcpy(c, b, n);
			pho_table *t = NULL;
			pho_status st =
			        pho_parse(c, n, NULL, &t, err, sizeof err);
			if (st == PHO_OK)
				pho_free(t);
			if (n < must_fail && st == PHO_OK)
				fail_msg("%s cut at %zu of %zu parsed",
				         files[k], n, len);
			if (st != PHO_OK && strncmp(err, "line ", 5))
				fail_msg("%s cut at %zu: message '%s'",
				         files[k], n, err);
			free(c);
			tried++;
		}
		free(b);
	}
	print_message("  %zu truncated copies refused or read\n", tried);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_every_plane_follows_the_file_symmetry),
	        cmocka_unit_test(test_rotational_files_have_one_plane),
	        cmocka_unit_test(test_lumens_equal_what_the_file_declares),
	        cmocka_unit_test(test_flux_is_the_integral_of_the_lookup),
	        cmocka_unit_test(test_tilt_and_lamp_lumens_scale_the_table),
	        cmocka_unit_test(test_bad_input_is_refused_naming_the_line),
	        cmocka_unit_test(test_every_truncation_fails_cleanly),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
