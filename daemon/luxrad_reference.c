/*
 * luxrad_reference.c -- luxrad-reference, the ground-truth tool.
 *
 * Loads one glTF scene (.gltf or .glb) and estimates illuminance at the
 * points of a points file by unbiased Monte Carlo path tracing
 * (rad_reference_illuminance, reference.c), independently of every solver:
 * the numbers luxrad-solve is validated against.  Each value comes with
 * its standard error and the number of paths it took.  Either a fixed
 * number of paths per point (--samples) or paths added until the relative
 * standard error reaches a target (--target-error, the default).
 *
 * Options are one declarative table, as in luxrad-solve: the parser, the
 * range checks and --help all read it.  Exit codes as luxrad-solve: 0 ok,
 * 1 scene / I/O / engine error (message on stderr), 2 usage (bad option,
 * bad value, malformed points file).  In --json mode nothing but the JSON
 * goes to stdout.
 */
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "engine_json.h"
#include "rad.h"
#include "rad_reference.h"
#include "rp.h"
#include "sceneio.h"
#include "tool.h"

enum { EXIT_OKAY = 0, EXIT_FAIL = 1, EXIT_USAGE = 2 };

#define PROG "luxrad-reference"
#define MAX_PATHS_OPT 1099511627776.0 /* 2^40 paths per point */

typedef struct cli_args {
	const char *scene_path;
	const char *points_path;
	tool_luminaires luminaires; /* --luminaire NAME=FILE */
	rad_ref_options opt;
	int samples_given;     /* --samples seen */
	int target_given;      /* --target-error seen */
	int max_samples_given; /* --max-samples seen */
	int json;
	int help;
} cli_args;

typedef enum opt_kind {
	OPT_HELP,      /* --help */
	OPT_FLAG_ON,   /* int field := 1 */
	OPT_DOUBLE,    /* double field, finite, within (lo, hi) */
	OPT_INT,       /* int field, within [lo, hi] */
	OPT_U64,       /* uint64_t field, within [lo, hi] */
	OPT_STRING,    /* const char * field */
	OPT_LUMINAIRE, /* tool_luminaires field: one more NAME=FILE */
} opt_kind;

typedef struct cli_option {
	const char *name;    /* long name without the leading "--" */
	const char *metavar; /* NULL for flags */
	opt_kind kind;
	size_t off;       /* offset of the field in cli_args */
	size_t seen_off;  /* offset of an int set to 1 when given, or 0 */
	double lo, hi;    /* accepted range (exclusive for OPT_DOUBLE) */
	const char *help; /* one line; the default is added by --help */
} cli_option;

#define ARG(field) offsetof(cli_args, field)
#define OPT(field) offsetof(cli_args, opt.field)

static const cli_option cli_options[] = {
        {"points", "FILE", OPT_STRING, ARG(points_path), 0, 0, 0,
         "estimate illuminance at the points in FILE (required)"},
        {"luminaire", "NAME=FILE", OPT_LUMINAIRE, ARG(luminaires), 0, 0, 0,
         "light NAME shines with the IES/EULUMDAT FILE (repeatable)"},
        {"samples", "N", OPT_U64, OPT(samples), ARG(samples_given), 1,
         MAX_PATHS_OPT, "exactly N paths per point (excludes --target-error)"},
        {"target-error", "R", OPT_DOUBLE, OPT(target_error), ARG(target_given),
         0, 1, "add paths until stderr <= R x estimate, 0 < R < 1"},
        {"max-samples", "N", OPT_U64, OPT(max_samples), ARG(max_samples_given),
         2, MAX_PATHS_OPT, "paths per point at most, with --target-error"},
        {"threads", "N", OPT_INT, OPT(threads), 0, 0, 256,
         "tracing threads, 0..256; 0 = one per core"},
        {"seed", "S", OPT_U64, OPT(seed), 0, 0, 9223372036854775807.0,
         "random seed, 0..2^63-1 (same seed, same result)"},
        {"json", NULL, OPT_FLAG_ON, ARG(json), 0, 0, 0,
         "print one JSON object on stdout instead of the table"},
        {"help", NULL, OPT_HELP, ARG(help), 0, 0, 0, "show this help"},
};

#define NOPTIONS (sizeof(cli_options) / sizeof(cli_options[0]))

static int usage_error(const char *fmt, ...)
        __attribute__((format(printf, 1, 2)));
static int usage_error(const char *fmt, ...)
{
	va_list ap;
	fputs(PROG ": ", stderr);
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fputs("\nTry '" PROG " --help'.\n", stderr);
	return EXIT_USAGE;
}

/* ------------------------------------------------------------------ help */

static void option_default(const cli_option *o, const cli_args *a, char *buf,
                           size_t len)
{
	const char *p = (const char *)a + o->off;
	buf[0] = '\0';
	switch (o->kind) {
	case OPT_DOUBLE:
		snprintf(buf, len, "%g", *(const double *)p);
		break;
	case OPT_INT:
		snprintf(buf, len, "%d", *(const int *)p);
		break;
	case OPT_U64: /* 0 = unset (--samples): nothing to show */
		if (*(const uint64_t *)p || o->off == OPT(seed))
			snprintf(buf, len, "%llu",
			         (unsigned long long)*(const uint64_t *)p);
		break;
	default:
		break;
	}
}

static void print_help(const cli_args *defaults)
{
	printf("Usage: " PROG " SCENE --points FILE [options]\n\n"
	       "Estimate illuminance at points of a glTF 2.0 scene (.gltf or "
	       ".glb) by\nunbiased Monte Carlo path tracing, independently "
	       "of the radiosity\nsolvers, with a standard error per "
	       "point.\n\nOptions:\n");
	for (size_t i = 0; i < NOPTIONS; i++) {
		const cli_option *o = &cli_options[i];
		char def[64];
		option_default(o, defaults, def, sizeof(def));
		rp_help_row(stdout, 0, o->name, o->metavar, o->help, def);
	}
	printf("\nWithout --samples, paths are added to each point until its "
	       "standard\nerror is <= %g of its estimate, at most %llu paths "
	       "per point.\n\n"
	       "Method: one-sided Lambertian surfaces (a back face absorbs); "
	       "next-event\nestimation to emitting polygons, combined with "
	       "cosine-weighted bounces\nby multiple importance sampling, and "
	       "to every point, spot and\ndirectional light; Russian "
	       "roulette.  The estimate is unbiased; results\ndo not depend "
	       "on --threads.\n\n"
	       "Points file: one point per line, 'x y z nx ny nz': position in "
	       "metres\nand the normal of the side it sees (any non-zero "
	       "length); '#' starts\na comment, blank lines are ignored.\n\n"
	       "Units: lengths in metres (glTF); illuminance in lux; emissive "
	       "luminance\nin cd/m2; point and spot intensities in cd; "
	       "directional lights in lux;\ntimes in seconds.\n\n"
	       "Output: a table (lux, standard error, relative error, paths "
	       "per point),\nor with --json one object with keys "
	       "illuminance_lux, stderr_lux,\nsamples, seconds, "
	       "samples_per_second, threads, seed, target_error,\n"
	       "max_samples, load_seconds, scene.\n\n"
	       "Exit status: 0 success; 1 scene, engine or I/O error (message "
	       "on stderr);\n2 usage error (unknown option, bad value, "
	       "malformed points file).\n",
	       defaults->opt.target_error,
	       (unsigned long long)defaults->opt.max_samples);
}

/* --------------------------------------------------------------- parsing */

/* Decimal digits only (strtoull would take "-1" and " 1"). */
static int parse_u64(const char *s, uint64_t *out)
{
	char *end;
	if (*s < '0' || *s > '9')
		return -1;
	errno = 0;
	unsigned long long v = strtoull(s, &end, 10);
	if (*end != '\0' || errno == ERANGE)
		return -1;
	*out = v;
	return 0;
}

/* A value refused: the message in msg, the usage exit code. */
static int bad_value(const cli_option *o, const char *value, const char *what,
                     char *msg, size_t len)
{
	return rp_cli_fail(
	        msg, len,
	        "--%s: invalid value '%s' (expected %s in %c%.17g, %.17g%c)",
	        o->name, value, what, o->kind == OPT_DOUBLE ? '(' : '[', o->lo,
	        o->hi, o->kind == OPT_DOUBLE ? ')' : ']');
}

static int apply_value(const cli_option *o, const char *value, cli_args *a,
                       char *msg, size_t len)
{
	char *p = (char *)a + o->off;
	double v = 0;
	uint64_t u = 0;

	switch (o->kind) {
	case OPT_STRING:
		*(const char **)p = value;
		return 0;
	case OPT_LUMINAIRE:
		return tool_luminaire_arg((tool_luminaires *)p, value, msg,
		                          len);
	case OPT_U64:
		/* Every count fits JSON's (signed) integers. */
		if (parse_u64(value, &u) != 0 || u > (uint64_t)INT64_MAX ||
		    (double)u < o->lo || (double)u > o->hi)
			return bad_value(o, value, "an integer", msg, len);
		*(uint64_t *)p = u;
		return 0;
	case OPT_DOUBLE:
		if (rp_cli_double(value, &v) != 0 || !(v > o->lo && v < o->hi))
			return bad_value(o, value, "a number", msg, len);
		*(double *)p = v;
		return 0;
	case OPT_INT:
		if (rp_cli_double(value, &v) != 0 || v != floor(v) ||
		    v < o->lo || v > o->hi)
			return bad_value(o, value, "an integer", msg, len);
		*(int *)p = (int)v;
		return 0;
	default:
		return 0;
	}
}

static const cli_option *find_option(const char *name, size_t len)
{
	return rp_cli_find(cli_options, NOPTIONS, sizeof(cli_options[0]), name,
	                   len);
}

static int scan_find(void *ud, const char *name, size_t len,
                     const char **metavar)
{
	const cli_option *o = find_option(name, len);
	(void)ud;
	if (!o)
		return -1;
	*metavar = o->metavar;
	return 0;
}

static int scan_set(void *ud, const char *name, size_t len, const char *value,
                    char *msg, size_t msglen)
{
	const cli_option *o = find_option(name, len);
	cli_args *a = ud;
	if (o->seen_off)
		*(int *)((char *)a + o->seen_off) = 1;
	if (!o->metavar) {
		*(int *)((char *)a + o->off) = 1;
		return o->kind == OPT_HELP ? RP_CLI_HELP : 0;
	}
	return apply_value(o, value, a, msg, msglen);
}

static int check_combination(const cli_args *a)
{
	if (a->samples_given && (a->target_given || a->max_samples_given))
		return usage_error("--samples traces a fixed number of paths; "
		                   "it cannot be combined with %s",
		                   a->target_given ? "--target-error"
		                                   : "--max-samples");
	if (!a->scene_path)
		return usage_error("no scene file given");
	if (!a->points_path)
		return usage_error("no points file given (--points FILE)");
	return 0;
}

static int parse_args(int argc, char **argv, cli_args *a)
{
	static const rp_cli_ops ops = {scan_find, scan_set};
	char msg[512];
	if (rp_cli_scan(argc, argv, &ops, a, &a->scene_path, &a->help, msg,
	                sizeof(msg)) != 0)
		return usage_error("%s", msg);
	return a->help ? 0 : check_combination(a);
}

/* ----------------------------------------------------------------- input */

typedef struct point_list {
	double *xyz; /* 6 doubles per point: position, normal */
	size_t n;
} point_list;

/* ---------------------------------------------------------------- output */

/* Everything the run produced, for the two printers. */
typedef struct report {
	const cli_args *a;
	const rad_scene *scene;
	const sio_info *info;
	const point_list *pl;
	const double *lux, *se;
	const uint64_t *paths;
	uint64_t total_paths;
	double seconds, load_seconds;
	int threads; /* resolved: never 0 */
} report;

static json_t *json_scene(const report *r)
{
	json_t *o = tool_scene_json(r->scene, r->info);
	json_object_set_new(o, "path", json_string(r->a->scene_path));
	return o;
}

static double per_second(const report *r)
{
	return r->seconds > 0 ? (double)r->total_paths / r->seconds : NAN;
}

static int print_json(const report *r)
{
	const rad_ref_options *o = &r->a->opt;
	json_t *j = json_object(), *lux = json_array(), *se = json_array();
	json_t *n = json_array();

	for (size_t i = 0; i < r->pl->n; i++) {
		json_array_append_new(lux, ej_real(r->lux[i]));
		json_array_append_new(se, ej_real(r->se[i]));
		json_array_append_new(n, json_integer((json_int_t)r->paths[i]));
	}
	json_object_set_new(j, "illuminance_lux", lux);
	json_object_set_new(j, "stderr_lux", se);
	json_object_set_new(j, "samples", n);
	json_object_set_new(j, "seconds", ej_real(r->seconds));
	json_object_set_new(j, "samples_per_second", ej_real(per_second(r)));
	json_object_set_new(j, "threads", json_integer(r->threads));
	json_object_set_new(j, "seed", json_integer((json_int_t)o->seed));
	json_object_set_new(j, "target_error",
	                    o->samples ? json_null()
	                               : ej_real(o->target_error));
	json_object_set_new(j, "max_samples",
	                    o->samples
	                            ? json_null()
	                            : json_integer((json_int_t)o->max_samples));
	json_object_set_new(j, "load_seconds", ej_real(r->load_seconds));
	json_object_set_new(j, "scene", json_scene(r));

	int rc =
	        json_dumpf(j, stdout, JSON_INDENT(2) | JSON_REAL_PRECISION(17));
	json_decref(j);
	if (rc != 0 || fputc('\n', stdout) == EOF)
		return EXIT_FAIL;
	return EXIT_OKAY;
}

static void print_text(const report *r)
{
	const rad_ref_options *o = &r->a->opt;
	rad_scene_counts c;

	rad_scene_counts_get(r->scene, &c);
	printf("scene %s: %u polygons (%u quads), %u emitters, %u lights, "
	       "loaded in %.3f s\n",
	       r->a->scene_path, c.polygons, c.quads, c.emitters, c.lights,
	       r->load_seconds);
	if (o->samples)
		printf("%llu paths per point", (unsigned long long)o->samples);
	else
		printf("target relative error %g, at most %llu paths per point",
		       o->target_error, (unsigned long long)o->max_samples);
	printf(", seed %llu, %d threads\n\n", (unsigned long long)o->seed,
	       r->threads);
	printf("%5s  %-36s %-22s %13s %11s %8s %11s\n", "point", "position",
	       "normal", "lux", "stderr", "rel", "paths");
	for (size_t i = 0; i < r->pl->n; i++) {
		const double *p = r->pl->xyz + 6 * i;
		char pos[64], nrm[64];
		snprintf(pos, sizeof(pos), "%.5g %.5g %.5g", p[0], p[1], p[2]);
		snprintf(nrm, sizeof(nrm), "%.3g %.3g %.3g", p[3], p[4], p[5]);
		double rel = r->lux[i] > 0 ? r->se[i] / r->lux[i] : 0.0;
		printf("%5zu  %-36s %-22s %13.6g %11.4g %7.3f%% %11llu\n", i,
		       pos, nrm, r->lux[i], r->se[i], 100.0 * rel,
		       (unsigned long long)r->paths[i]);
	}
	printf("\n%llu paths in %.3f s: %.4g paths/s (%.4g per thread)\n",
	       (unsigned long long)r->total_paths, r->seconds, per_second(r),
	       per_second(r) / r->threads);
}

/* ------------------------------------------------------------------ main */

static int estimate_and_report(const cli_args *a, const rad_scene *sc,
                               const sio_info *info, const point_list *pl,
                               double load_seconds)
{
	size_t n = pl->n ? pl->n : 1;
	double *lux = calloc(n, sizeof(double));
	double *se = calloc(n, sizeof(double));
	uint64_t *paths = calloc(n, sizeof(uint64_t));
	rad_error err = {0};
	int rc = EXIT_FAIL;

	if (!lux || !se || !paths) {
		fprintf(stderr, PROG ": out of memory\n");
		goto out;
	}
	double t0 = rad_seconds();
	rad_status st = rad_reference_illuminance(sc, pl->xyz, pl->n, &a->opt,
	                                          lux, se, paths, &err);
	double seconds = rad_seconds() - t0;
	if (st != RAD_OK) {
		fprintf(stderr, PROG ": %s: %s\n", rad_status_name(err.code),
		        err.msg);
		goto out;
	}
	report r = {.a = a,
	            .scene = sc,
	            .info = info,
	            .pl = pl,
	            .lux = lux,
	            .se = se,
	            .paths = paths,
	            .seconds = seconds,
	            .load_seconds = load_seconds,
	            .threads = a->opt.threads};
	if (r.threads <= 0) {
		long cores = sysconf(_SC_NPROCESSORS_ONLN);
		r.threads = cores > 0 ? (int)cores : 1;
	}
	for (size_t i = 0; i < pl->n; i++)
		r.total_paths += paths[i];
	if (a->json) {
		rc = print_json(&r);
	} else {
		print_text(&r);
		rc = EXIT_OKAY;
	}
out:
	free(lux);
	free(se);
	free(paths);
	return rc;
}

int main(int argc, char **argv)
{
	cli_args a = {0};
	point_list pl = {0};
	rad_scene *sc = NULL;
	sio_info info = {0};
	double load_seconds = 0;

	rad_ref_options_default(&a.opt);
	int rc = parse_args(argc, argv, &a);
	if (rc != EXIT_OKAY)
		return rc;
	if (a.help) {
		print_help(&a);
		return EXIT_OKAY;
	}
	rc = tool_points_load(PROG, a.points_path, &pl.xyz, &pl.n);
	if (rc == EXIT_OKAY)
		rc = tool_scene_load(PROG, a.scene_path, &a.luminaires, &sc,
		                     &info, &load_seconds);
	if (rc == EXIT_OKAY)
		rc = estimate_and_report(&a, sc, &info, &pl, load_seconds);
	rad_scene_free(sc);
	free(pl.xyz);
	if (fflush(stdout) != 0 || ferror(stdout)) {
		fprintf(stderr, PROG ": cannot write the output\n");
		rc = EXIT_FAIL;
	}
	return rc;
}
