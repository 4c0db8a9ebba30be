/*
 * solve_args.c -- luxrad-solve's command line.
 *
 * Two kinds of option: the tool's own (what to read and write, how many
 * iterations, how to print), in the table below, and every engine option,
 * which is a row of rad.h's RAD_OPTIONS under its cli name.  Parsing,
 * range checks, error messages and --help read those rows, so an engine
 * option has one name, one range and one default in luxrad-solve, in the
 * daemon and in the client.
 *
 * --accuracy sets several knobs, and an engine option given beside it
 * wins whatever the order on the command line: the line is parsed once
 * to find the accuracy, then again over the defaults it gives.
 */
#include "solve_args.h"
#include "rp.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The tool's own options. */
typedef enum tool_kind {
	T_HELP,      /* --help */
	T_FLAG,      /* int field := 1 */
	T_U32,       /* uint32_t field, 1..1e9 */
	T_STRING,    /* const char * field */
	T_LUMINAIRE, /* tool_luminaires field: one more NAME=FILE */
	T_SOLVER,    /* rad_solver_kind field */
	T_BVH,       /* rad_bvh_mode field */
} tool_kind;

typedef struct tool_option {
	const char *name;    /* long name without the leading "--" */
	const char *metavar; /* NULL for flags */
	tool_kind kind;
	size_t off;       /* offset of the field in cli_args */
	const char *help; /* one line */
} tool_option;

#define ARG(field) offsetof(cli_args, field)

static const tool_option tool_options[] = {
        {"solver", "NAME", T_SOLVER, ARG(opt.solver),
         "matrix | progressive | hr (hierarchical radiosity) | rmb "
         "(reduced-memory hr)"},
        {"iterations", "N", T_U32, ARG(iterations),
         "run exactly N iterations (excludes --tol, --max-iterations)"},
        {"points", "FILE", T_STRING, ARG(points_path),
         "query illuminance at the points in FILE"},
        {"luminaire", "NAME=FILE", T_LUMINAIRE, ARG(luminaires),
         "light NAME shines with the IES/EULUMDAT FILE (repeatable)"},
        {"export", "FILE", T_STRING, ARG(export_path),
         "write the solved mesh to FILE (.glb; .gltf for JSON)"},
        {"polygons", "FILE", T_STRING, ARG(polygons_path),
         "write the scene's polygons as the solvers see them (corners, "
         "node, reflectance, luminance) to FILE as CSV"},
        {"audit-links", "N", T_U32, ARG(audit_every),
         "hr, rmb: hold one link in N to Monte Carlo after the solve, by "
         "class (stored / Monte Carlo transfer)"},
        {"json", NULL, T_FLAG, ARG(json),
         "print one JSON object on stdout instead of the report"},
        {"per-iteration", NULL, T_FLAG, ARG(per_iteration),
         "print statistics to stderr after every iteration"},
        {"bvh", "LAYOUT", T_BVH, ARG(bvh),
         "the BVH's layout: compact (the default: leaves index the "
         "vertices) or fast (Embree's: 1.2-1.9x its memory, 2-10 % "
         "faster solves measured); the same results"},
        {"compact-bvh", NULL, T_FLAG, ARG(compact_bvh),
         "the same as --bvh compact, the default"},
        {"help", NULL, T_HELP, ARG(help), "show this help"},
};

#define NTOOL (sizeof(tool_options) / sizeof(tool_options[0]))

/* ------------------------------------------------------------------ help */

/* An engine option's current value in a, as text. */
static void engine_value(const rad_option_def *d, const cli_args *a, char *buf,
                         size_t len)
{
	double v = rad_option_get(&a->opt, d);
	if (d->type == RAD_OPT_ENUM)
		snprintf(buf, len, "%s", d->choices[(int)v]);
	else if (d->type == RAD_OPT_BOOL)
		buf[0] = '\0'; /* a flag: the help says what it changes */
	else
		snprintf(buf, len, "%g", v);
}

void cli_print_help(const cli_args *a)
{
	char def[64];

	printf("Usage: luxrad-solve SCENE [options]\n\n"
	       "Solve the diffuse interreflection of a glTF 2.0 scene (.gltf "
	       "or .glb)\nand report illuminance and solver statistics.\n\n"
	       "Options:\n");
	for (size_t i = 0; i < NTOOL; i++) {
		const tool_option *o = &tool_options[i];
		snprintf(def, sizeof(def), "%s",
		         o->kind == T_SOLVER
		                 ? rad_solver_kind_name(a->opt.solver)
		                 : "");
		rp_help_row(stdout, 0, o->name, o->metavar, o->help, def);
	}
	printf("\nEngine options (the daemon's job options too: "
	       "protocol/PROTOCOL.md):\n");
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		engine_value(d, a, def, sizeof(def));
		rp_help_row(stdout, 0, d->cli,
		            d->type == RAD_OPT_BOOL ? NULL : d->metavar,
		            d->help, def);
	}
	printf("\nWith neither --iterations nor --tol the solve runs until "
	       "the\nestimated relative error is <= %g (at most %d "
	       "iterations).\n\n"
	       "--accuracy R: the lux reported should be within R (relative) "
	       "of the\ntruth; the default asks for %g.  Each point's "
	       "estimated error is\nprinted beside it (error_lux in "
	       "--json).\n\n"
	       "--eps by oracle: bfa = fraction of the total emitted flux one "
	       "link may\ncarry; bf = source exitance x form factor, as a "
	       "fraction of the mean\nemitted exitance (flux / total area); "
	       "f = form factor alone.\n\n"
	       "Points file: one point per line, 'x y z nx ny nz': position in "
	       "metres\nand the normal of the surface the point lies on (any "
	       "non-zero length);\n'#' starts a comment, blank lines are "
	       "ignored.\n\n"
	       "Units: lengths in metres (glTF); illuminance in lux; emissive "
	       "luminance\nin cd/m2; point and spot intensities in cd; "
	       "directional lights in lux;\ntimes in seconds; memory in "
	       "bytes.\n\n"
	       "Output: a readable report (scene counts, per-iteration table, "
	       "memory by\nstructure, lux per point), or with --json one "
	       "object with keys\nilluminance_lux, error_lux, solver, options "
	       "(every engine option), seconds,\nload_seconds, query_seconds, "
	       "converged, rays_total, stats (the last\niteration's), "
	       "per_iteration (stats of each) and scene.\n\n"
	       "Exit status: 0 success; 1 scene, solve or I/O error (message "
	       "on stderr);\n2 usage error (unknown option, bad value, "
	       "malformed points file).\n",
	       a->opt.converge_tol, a->opt.max_iterations,
	       RAD_ACCURACY_DEFAULT);
}

/* --------------------------------------------------------------- parsing */

/* An engine option's value from the command line. */
static int engine_set(const rad_option_def *d, const char *value, cli_args *a,
                      char *msg, size_t len)
{
	char rng[128];
	double v;

	a->given[d - rad_option_defs] = 1;
	if (d->type == RAD_OPT_BOOL)
		v = d->def == 0;
	else if (d->type == RAD_OPT_ENUM) {
		v = rad_option_choice(d, value);
		if (v < 0) {
			rad_option_range_text(d, rng, sizeof(rng));
			return rp_cli_fail(msg, len,
			                   "--%s: unknown value '%s' (%s)",
			                   d->cli, value, rng);
		}
	} else if (rp_cli_double(value, &v) != 0) {
		v = NAN; /* refused below, with the range */
	}
	/* The second pass starts from what the accuracy gives (cli_parse):
	 * setting it again would undo the options before it. */
	if (d == &rad_option_defs[RAD_OPT_accuracy] && a->reparse)
		return EXIT_OKAY;
	if (rad_option_set(&a->opt, d, v, NULL) != RAD_OK) {
		rad_option_range_text(d, rng, sizeof(rng));
		return rp_cli_fail(
		        msg, len, "--%s: invalid value '%s' (expected %s %s)",
		        d->cli, value,
		        d->type == RAD_OPT_INT ? "an integer" : "a number",
		        rng);
	}
	return EXIT_OKAY;
}

static int tool_set(const tool_option *o, const char *value, cli_args *a,
                    char *msg, size_t len)
{
	char *p = (char *)a + o->off;
	double v;

	switch (o->kind) {
	case T_STRING:
		*(const char **)p = value;
		return EXIT_OKAY;
	case T_LUMINAIRE:
		return tool_luminaire_arg((tool_luminaires *)p, value, msg,
		                          len);
	case T_SOLVER:
		if (rad_solver_kind_parse(value, (rad_solver_kind *)p) !=
		    RAD_OK)
			return rp_cli_fail(msg, len,
			                   "--%s: unknown solver '%s' (matrix, "
			                   "progressive, hr or rmb)",
			                   o->name, value);
		return EXIT_OKAY;
	case T_BVH: {
		static const char *const names[] = {RAD_BVH_CHOICES};
		for (size_t i = 0; i < sizeof(names) / sizeof(names[0]); i++)
			if (!strcmp(value, names[i])) {
				*(rad_bvh_mode *)p = (rad_bvh_mode)i;
				return EXIT_OKAY;
			}
		return rp_cli_fail(msg, len,
		                   "--%s: unknown layout '%s' (compact or "
		                   "fast)",
		                   o->name, value);
	}
	case T_U32:
		if (rp_cli_double(value, &v) != 0 || v < 1 || v > 1e9 ||
		    v != floor(v))
			return rp_cli_fail(
			        msg, len,
			        "--%s: invalid value '%s' (expected an "
			        "integer in [1, 1e+09])",
			        o->name, value);
		*(uint32_t *)p = (uint32_t)v;
		return EXIT_OKAY;
	case T_HELP:
		*(int *)p = 1;
		return RP_CLI_HELP;
	default:
		*(int *)p = 1;
		return EXIT_OKAY;
	}
}

static const tool_option *find_tool(const char *name, size_t len)
{
	return rp_cli_find(tool_options, NTOOL, sizeof(tool_options[0]), name,
	                   len);
}

static int scan_find(void *ud, const char *name, size_t len,
                     const char **metavar)
{
	const tool_option *t = find_tool(name, len);
	const rad_option_def *d = rad_option_find_cli(name, len);
	(void)ud;
	if (t)
		*metavar = t->metavar;
	else if (d)
		*metavar = d->type == RAD_OPT_BOOL ? NULL : d->metavar;
	return t || d ? 0 : -1;
}

static int scan_set(void *ud, const char *name, size_t len, const char *value,
                    char *msg, size_t msglen)
{
	const tool_option *t = find_tool(name, len);
	if (t)
		return tool_set(t, value, ud, msg, msglen);
	return engine_set(rad_option_find_cli(name, len), value, ud, msg,
	                  msglen);
}

static int check_combination(const cli_args *a, char *msg, size_t len)
{
	int tol = a->given[RAD_OPT_converge_tol];
	if (a->iterations && (tol || a->given[RAD_OPT_max_iterations]))
		return rp_cli_fail(
		        msg, len,
		        "--iterations runs a fixed number of steps; it "
		        "cannot be combined with %s",
		        tol ? "--tol" : "--max-iterations");
	if (a->audit_every && a->opt.solver != RAD_SOLVER_HR &&
	    a->opt.solver != RAD_SOLVER_RMB)
		return rp_cli_fail(msg, len,
		                   "--audit-links holds links to Monte Carlo: "
		                   "--solver %s keeps none (hr or rmb do)",
		                   rad_solver_kind_name(a->opt.solver));
	if (a->compact_bvh && a->bvh != RAD_BVH_COMPACT)
		return rp_cli_fail(msg, len,
		                   "--compact-bvh and --bvh fast ask for two "
		                   "layouts; give one");
	if (!a->scene_path)
		return rp_cli_fail(msg, len, "no scene file given");
	return EXIT_OKAY;
}

/* One pass over argv into *a (defaults already there). */
static int parse_line(int argc, char **argv, cli_args *a)
{
	static const rp_cli_ops ops = {scan_find, scan_set};
	char msg[512];
	int rc = rp_cli_scan(argc, argv, &ops, a, &a->scene_path, &a->help, msg,
	                     sizeof(msg));
	if (rc == EXIT_OKAY && !a->help)
		rc = check_combination(a, msg, sizeof(msg));
	if (rc != EXIT_OKAY)
		fprintf(stderr,
		        "luxrad-solve: %s\nTry 'luxrad-solve --help'.\n", msg);
	return rc;
}

/* *a with nothing given: every default. */
static void args_default(cli_args *a)
{
	memset(a, 0, sizeof(*a));
	rad_options_default(&a->opt);
	a->bvh = RAD_BVH_DEFAULT;
}

int cli_parse(int argc, char **argv, cli_args *a)
{
	args_default(a);
	int rc = parse_line(argc, argv, a);
	if (rc != EXIT_OKAY || a->help || !a->given[RAD_OPT_accuracy])
		return rc;
	double accuracy = a->opt.accuracy;
	args_default(a);
	rad_options_accuracy(&a->opt, accuracy, NULL);
	a->reparse = 1;
	return parse_line(argc, argv, a);
}
