/*
 * test_options.c -- rad.h's options and statistics tables against every
 * place that shows them.
 *
 * The tables are the one declaration; luxrad-solve's command line, the
 * daemon's job options, the client's help, and the JSON of options and
 * statistics are made from them in code.  What code cannot make are the
 * documents, so this test reads them: PROTOCOL.md's option table must be
 * the one this program prints (`test_options --print-markdown` writes it
 * anew, and --print-stats-markdown its <stats> table), the README must
 * name every option, and the two tools' --help
 * must show every option with its default.
 *
 * Usage: test_options LUXRAD_SOLVE LUXRAD   (paths of the two tools)
 *        test_options --print-markdown | --print-stats-markdown
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "engine_json.h"
#include "rad.h"

static const char *solve_bin, *client_bin;

/* -------------------------------------------------------------- helpers */

static char *read_all(FILE *f)
{
	size_t len = 0, cap = 1 << 16;
	char *buf = malloc(cap);
	size_t n;
	assert_non_null(buf);
	while ((n = fread(buf + len, 1, cap - len - 1, f)) > 0) {
		len += n;
		if (cap - len < 2) {
			cap *= 2;
			buf = realloc(buf, cap);
			assert_non_null(buf);
		}
	}
	buf[len] = '\0';
	return buf;
}

static char *read_file(const char *rel)
{
	char path[1024];
	snprintf(path, sizeof(path), "%s/%s", LUXRAD_SOURCE_DIR, rel);
	FILE *f = fopen(path, "r");
	if (!f)
		fail_msg("cannot read %s", path);
	char *s = read_all(f);
	fclose(f);
	return s;
}

static char *run_help(const char *cmd)
{
	FILE *p = popen(cmd, "r");
	assert_non_null(p);
	char *s = read_all(p);
	assert_int_equal(pclose(p), 0);
	return s;
}

/* The Markdown table of the job options, as PROTOCOL.md must hold it. */
static void markdown(FILE *f)
{
	fprintf(f, "| Option | Type | Default | Meaning |\n"
	           "|--------|------|---------|---------|\n");
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		char rng[128], def[64];
		rad_option_range_text(d, rng, sizeof(rng));
		rad_option_default_text(d, def, sizeof(def));
		fprintf(f, "| `%s` | ", d->key);
		if (d->type == RAD_OPT_BOOL)
			fprintf(f, "boolean");
		else if (d->type == RAD_OPT_ENUM)
			for (int k = 0; d->choices[k]; k++)
				fprintf(f, "%s`\"%s\"`", k ? ", " : "",
				        d->choices[k]);
		else
			fprintf(f, "%s %s",
			        d->type == RAD_OPT_INT ? "integer" : "number",
			        rng);
		if (d->type == RAD_OPT_ENUM)
			fprintf(f, " | `\"%s\"` | %s |\n", def, d->help);
		else
			fprintf(f, " | %s | %s |\n", def, d->help);
	}
}

/* The Markdown table of <stats>, as PROTOCOL.md must hold it. */
static void stats_markdown(FILE *f)
{
	static const char *const kinds[] = {[RAD_STAT_GAUGE] = "now",
	                                    [RAD_STAT_STEP] = "last iteration",
	                                    [RAD_STAT_TOTAL] =
	                                            "all iterations"};
	fprintf(f, "| Key | Counts | Unit | Meaning |\n"
	           "|-----|--------|------|---------|\n");
#define STAT_ROW_(field, group, key, type, kind, unit, help)                   \
	fprintf(f, "| `%s%s%s` | %s | %s | %s |\n", group,                     \
	        group[0] ? "." : "", key, kinds[RAD_STAT_##kind],              \
	        unit[0] ? unit : "", help);
	RAD_STATS(STAT_ROW_)
#undef STAT_ROW_
}

/* ---------------------------------------------------------------- tests */

/* rad_options_default gives every row's default column. */
static void test_defaults(void **state)
{
	(void)state;
	rad_options o;
	rad_options_default(&o);
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		double v = rad_option_get(&o, d);
		if (!(fabs(v - d->def) <= 1e-12 * fabs(d->def)))
			fail_msg("%s: default %.17g, table says %.17g", d->key,
			         v, d->def);
	}
	assert_int_equal(rad_options_check(&o, NULL), RAD_OK);
}

/* Each range is enforced as written, ends included or not. */
static void test_ranges(void **state)
{
	(void)state;
	rad_options o;
	rad_error err;
	rad_options_default(&o);
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		int lo_ok = !(d->range & RAD_RANGE_LO_OPEN);
		int hi_ok = !(d->range & RAD_RANGE_HI_OPEN);
		assert_int_equal(rad_option_set(&o, d, d->lo, &err) == RAD_OK,
		                 lo_ok);
		if (!lo_ok)
			assert_non_null(strstr(err.msg, d->key));
		if (d->hi != HUGE_VAL)
			assert_int_equal(rad_option_set(&o, d, d->hi, &err) ==
			                         RAD_OK,
			                 hi_ok);
		assert_int_equal(rad_option_set(&o, d, NAN, &err),
		                 RAD_ERR_INVALID);
		if (d->type != RAD_OPT_DOUBLE)
			assert_int_equal(
			        rad_option_set(&o, d, d->lo + 0.5, &err),
			        RAD_ERR_INVALID);
		if (d->type == RAD_OPT_ENUM) {
			int n = 0;
			while (d->choices[n])
				n++;
			assert_int_equal(n, (int)d->hi + 1);
			assert_int_equal(
			        rad_option_choice(d, d->choices[n - 1]), n - 1);
			assert_int_equal(rad_option_choice(d, "nope"), -1);
		}
		assert_ptr_equal(rad_option_find(d->key), d);
		assert_ptr_equal(rad_option_find_cli(d->cli, strlen(d->cli)),
		                 d);
		rad_options_default(&o);
	}
}

/* JSON: every option under its key, read back to the same options;
 * every statistic under its key. */
static void test_json(void **state)
{
	(void)state;
	rad_options a, b;
	char msg[256];
	rad_options_default(&a);
	a.eps = 3e-5;
	a.store = RAD_STORE_MINIMAL;
	a.clustering = 0;
	a.max_iterations = 77;
	json_t *j = ej_options(&a);
	assert_int_equal(json_object_size(j), RAD_NOPTIONS);
	rad_options_default(&b);
	assert_int_equal(ej_options_set(&b, j, msg, sizeof(msg)), EJ_OK);
	for (int i = 0; i < RAD_NOPTIONS; i++)
		assert_true(rad_option_get(&a, &rad_option_defs[i]) ==
		            rad_option_get(&b, &rad_option_defs[i]));
	json_decref(j);

	j = json_pack("{s:f, s:f}", "eps", 1e-3, "accuracy", 0.05);
	rad_options_default(&b);
	assert_int_equal(ej_options_set(&b, j, msg, sizeof(msg)), EJ_OK);
	assert_true(b.eps == 1e-3); /* given beside accuracy: it wins */
	assert_true(b.converge_tol == 0.05 / 20);
	json_decref(j);
	j = json_pack("{s:s}", "eps", "x");
	assert_int_equal(ej_options_set(&b, j, msg, sizeof(msg)), EJ_TYPE);
	json_decref(j);
	j = json_pack("{s:i}", "rcv_samples", 17);
	assert_int_equal(ej_options_set(&b, j, msg, sizeof(msg)), EJ_INVALID);
	assert_non_null(strstr(msg, "rcv_samples"));
	json_decref(j);

	rad_stats st;
	memset(&st, 0, sizeof(st));
	j = ej_stats(&st);
#define CHECK_STAT_(field, group, key, ...)                                    \
	assert_non_null(json_object_get(                                       \
	        group[0] ? json_object_get(j, group) : j, key));
	RAD_STATS(CHECK_STAT_)
#undef CHECK_STAT_
	json_decref(j);
}

/* PROTOCOL.md holds the table this program prints. */
static void test_protocol_md(void **state)
{
	(void)state;
	char *doc = read_file("protocol/PROTOCOL.md");
	char *gen = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&gen, &len);
	markdown(f);
	fclose(f);
	if (!strstr(doc, gen))
		fail_msg("protocol/PROTOCOL.md's option table differs from "
		         "rad.h's RAD_OPTIONS: replace it with the output of "
		         "'test_options --print-markdown'");
	free(gen);
	f = open_memstream(&gen, &len);
	stats_markdown(f);
	fclose(f);
	if (!strstr(doc, gen))
		fail_msg("protocol/PROTOCOL.md's <stats> table differs from "
		         "rad.h's RAD_STATS: replace it with the output of "
		         "'test_options --print-stats-markdown'");
	free(gen);
	free(doc);
}

/* The README's luxrad-solve table names every option. */
static void test_readme(void **state)
{
	(void)state;
	char *doc = read_file("README.md");
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		char want[64];
		snprintf(want, sizeof(want), "`--%s", rad_option_defs[i].cli);
		if (!strstr(doc, want))
			fail_msg("README.md does not document %s`", want);
	}
	free(doc);
}

/* A --help lists every option with its value name and default. */
static void check_help(const char *cmd)
{
	char *h = run_help(cmd);
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		char want[96], def[64];
		if (d->type == RAD_OPT_BOOL)
			snprintf(want, sizeof(want), "--%s ", d->cli);
		else
			snprintf(want, sizeof(want), "--%s %s", d->cli,
			         d->metavar);
		if (!strstr(h, want))
			fail_msg("'%s' lacks '%s'", cmd, want);
		if (d->type == RAD_OPT_BOOL)
			continue;
		rad_option_default_text(d, def, sizeof(def));
		snprintf(want, sizeof(want), "[%s]", def);
		if (!strstr(h, want))
			fail_msg("'%s' lacks the default %s of --%s", cmd, want,
			         d->cli);
	}
	free(h);
}

static void test_help(void **state)
{
	(void)state;
	char cmd[1200];
	snprintf(cmd, sizeof(cmd), "'%s' --help", solve_bin);
	check_help(cmd);
	snprintf(cmd, sizeof(cmd), "'%s' create --help", client_bin);
	check_help(cmd);
}

int main(int argc, char **argv)
{
	if (argc == 2 && strcmp(argv[1], "--print-markdown") == 0) {
		markdown(stdout);
		return 0;
	}
	if (argc == 2 && strcmp(argv[1], "--print-stats-markdown") == 0) {
		stats_markdown(stdout);
		return 0;
	}
	if (argc != 3) {
		fprintf(stderr, "usage: test_options LUXRAD_SOLVE LUXRAD | "
		                "--print-markdown\n");
		return 2;
	}
	solve_bin = argv[1];
	client_bin = argv[2];
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_defaults),
	        cmocka_unit_test(test_ranges),
	        cmocka_unit_test(test_json),
	        cmocka_unit_test(test_protocol_md),
	        cmocka_unit_test(test_readme),
	        cmocka_unit_test(test_help),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
