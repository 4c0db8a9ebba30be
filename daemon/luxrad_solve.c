/*
 * luxrad_solve.c -- luxrad-solve, the offline batch tool.
 *
 * Loads one glTF scene (.gltf or .glb) from a file, runs one solver over it
 * (a fixed number of iterations, or until the estimated error falls below
 * a tolerance), queries illuminance at the points of an optional points
 * file and prints either a readable report or one JSON object.  It is the
 * engine's whole public API driven from a command line, so it is also what
 * outside acceptance checks call: its options, output keys and exit codes
 * are a stable interface.
 *
 * Options are one declarative table (cli_options below): the parser, the
 * range checks and --help all read it, so an option cannot exist without
 * being documented.  Exit codes: 0 ok, 1 scene / solve / I/O error (the
 * engine's message on stderr), 2 usage (bad option, bad value, malformed
 * points file).  In --json mode nothing but the JSON goes to stdout.
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
#include <sys/stat.h>
#include <unistd.h>

#include "export.h"
#include "rad.h"
#include "rp.h"
#include "sceneio.h"

enum { EXIT_OKAY = 0, EXIT_SOLVE = 1, EXIT_USAGE = 2 };

/*
 * Default convergence: the solve stops when the engine's estimate of the
 * remaining relative error is below the tolerance the accuracy asks for
 * (rad_options.converge_tol: 1e-3 at the default accuracy, 0.1 % of the
 * converged illuminance).  The iteration cap is generous so that scenes
 * with reflectances near 1, which converge slowly, still get there; it
 * only guards against a solver that stalls.
 */
#define DEFAULT_MAX_ITER 10000u

typedef struct cli_args {
	const char *scene_path;
	const char *points_path; /* NULL: no illuminance queries */
	const char *export_path; /* NULL: no solved-mesh export */
	rad_options opt;
	uint32_t iterations; /* > 0: exactly this many steps */
	double tol;          /* converge mode: error_estimate target */
	uint32_t max_iter;   /* converge mode: iteration cap */
	int tol_given;       /* --converge seen (excludes --iterations) */
	double accuracy;     /* --accuracy: relative target error */
	int accuracy_given;  /* --accuracy seen */
	int max_iter_given;  /* --max-iterations seen (ditto) */
	int json;            /* one JSON object on stdout */
	int per_iteration;   /* a stats line on stderr after each step */
	int help;
} cli_args;

/* How an option's value is parsed and where it is stored. */
typedef enum opt_kind {
	OPT_HELP,     /* --help */
	OPT_FLAG_ON,  /* int field := 1 */
	OPT_FLAG_OFF, /* int field := 0 */
	OPT_DOUBLE,   /* double field, finite, within [lo, hi] */
	OPT_INT,      /* int field, within [lo, hi] */
	OPT_U32,      /* uint32_t field, within [lo, hi] */
	OPT_STRING,   /* const char * field */
	OPT_SOLVER,   /* rad_solver_kind field */
	OPT_ORACLE,   /* rad_oracle field */
} opt_kind;

typedef struct cli_option {
	const char *name;    /* long name without the leading "--" */
	const char *metavar; /* NULL for flags */
	opt_kind kind;
	size_t off;       /* offset of the field in cli_args */
	size_t seen_off;  /* offset of an int set to 1 when given, or 0 */
	double lo, hi;    /* accepted range for numbers (inclusive) */
	int excl;         /* bounds refused: 1 = lo (eps > 0), 2 = hi */
	const char *help; /* one line; the default is added by --help */
} cli_option;

#define ARG(field) offsetof(cli_args, field)
#define OPT(field) offsetof(cli_args, opt.field)

static const cli_option cli_options[] = {
        {"solver", "NAME", OPT_SOLVER, OPT(solver), 0, 0, 0, 0,
         "matrix | progressive | hr (hierarchical radiosity) | rmb "
         "(reduced-memory hr)"},
        {"accuracy", "R", OPT_DOUBLE, ARG(accuracy), ARG(accuracy_given),
         RAD_ACCURACY_MIN, RAD_ACCURACY_MAX, 0,
         "target relative error of the lux reported; sets --eps, "
         "--variation,\n                         --converge and the query "
         "tolerance together (they override it)"},
        {"eps", "X", OPT_DOUBLE, OPT(eps), 0, 0, 1e9, 1,
         "refinement threshold, > 0; smaller is finer (see --oracle)"},
        {"iterations", "N", OPT_U32, ARG(iterations), 0, 1, 1e9, 0,
         "run exactly N iterations (excludes --converge)"},
        {"converge", "R", OPT_DOUBLE, ARG(tol), ARG(tol_given), 0, 1, 1,
         "iterate until the estimated relative error <= R"},
        {"max-iterations", "N", OPT_U32, ARG(max_iter), ARG(max_iter_given), 1,
         1e9, 0, "iteration cap when converging"},
        {"threads", "N", OPT_INT, OPT(threads), 0, 0, 256, 0,
         "worker threads, 0..256; 0 = one per core"},
        {"points", "FILE", OPT_STRING, ARG(points_path), 0, 0, 0, 0,
         "query illuminance at the points in FILE"},
        {"export", "FILE", OPT_STRING, ARG(export_path), 0, 0, 0, 0,
         "write the solved mesh to FILE (.glb; .gltf for JSON)"},
        {"json", NULL, OPT_FLAG_ON, ARG(json), 0, 0, 0, 0,
         "print one JSON object on stdout instead of the report"},
        {"per-iteration", NULL, OPT_FLAG_ON, ARG(per_iteration), 0, 0, 0, 0,
         "print statistics to stderr after every iteration"},
        {"oracle", "NAME", OPT_ORACLE, OPT(oracle), 0, 0, 0, 0,
         "refinement test: bfa (flux) | bf (exitance) | f (form factor)"},
        {"no-clustering", NULL, OPT_FLAG_OFF, OPT(clustering), 0, 0, 0, 0,
         "hr, rmb: no volume clusters (every polygon pair linked)"},
        {"minimal-store", NULL, OPT_FLAG_ON, OPT(store), 0, 0, 0, 0,
         "rmb: the report's creation criterion alone (no anticipation)"},
        {"study", NULL, OPT_FLAG_ON, OPT(study), 0, 0, 0, 0,
         "count re-created links (memory counted as \"study\")"},
        {"variation", "X", OPT_DOUBLE, OPT(variation), 0, 0, 1e9, 3,
         "hr, rmb: receiver accuracy, fraction of the mean radiosity"},
        {"min-edge", "X", OPT_DOUBLE, OPT(min_edge_rel), 0, 0, 1, 3,
         "smallest element edge, fraction of the scene diagonal"},
        {"mesh-edge", "X", OPT_DOUBLE, OPT(mesh_edge_rel), 0, 0, 1, 1,
         "matrix/progressive mesh edge, fraction of the diagonal"},
        {"rcv-samples", "N", OPT_INT, OPT(rcv_samples), 0, 1, 16, 0,
         "receiver points per form factor (1..16)"},
        {"vis-samples", "N", OPT_INT, OPT(vis_samples), 0, 1, 16, 0,
         "shadow rays per receiver point (1..16)"},
        {"help", NULL, OPT_HELP, ARG(help), 0, 0, 0, 0, "show this help"},
};

#define NOPTIONS (sizeof(cli_options) / sizeof(cli_options[0]))

static const char *const oracle_names[] = {
        [RAD_ORACLE_BFA] = "bfa",
        [RAD_ORACLE_F] = "f",
        [RAD_ORACLE_BF] = "bf",
};

/* Report a usage error on stderr; returns the usage exit code. */
static int usage_error(const char *fmt, ...)
        __attribute__((format(printf, 1, 2)));
static int usage_error(const char *fmt, ...)
{
	va_list ap;
	fputs("luxrad-solve: ", stderr);
	va_start(ap, fmt);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fputs("\nTry 'luxrad-solve --help'.\n", stderr);
	return EXIT_USAGE;
}

/* ------------------------------------------------------------------ help */

/* The current value of a table option in a, as text for --help. */
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
	case OPT_U32: /* 0 = unset (--iterations): nothing to show */
		if (*(const uint32_t *)p)
			snprintf(buf, len, "%u", *(const uint32_t *)p);
		break;
	case OPT_SOLVER:
		snprintf(buf, len, "%s",
		         rad_solver_kind_name(*(const rad_solver_kind *)p));
		break;
	case OPT_ORACLE:
		snprintf(buf, len, "%s", oracle_names[*(const rad_oracle *)p]);
		break;
	default:
		break;
	}
}

static void print_help(const cli_args *defaults)
{
	printf("Usage: luxrad-solve SCENE [options]\n\n"
	       "Solve the diffuse interreflection of a glTF 2.0 scene (.gltf "
	       "or .glb)\nand report illuminance and solver statistics.\n\n"
	       "Options:\n");
	for (size_t i = 0; i < NOPTIONS; i++) {
		const cli_option *o = &cli_options[i];
		char lhs[40], def[64];
		snprintf(lhs, sizeof(lhs), "--%s%s%s", o->name,
		         o->metavar ? " " : "", o->metavar ? o->metavar : "");
		option_default(o, defaults, def, sizeof(def));
		printf("  %-22s %s%s%s%s\n", lhs, o->help, def[0] ? " [" : "",
		       def, def[0] ? "]" : "");
	}
	printf("\nWith neither --iterations nor --converge the solve runs "
	       "until the\nestimated relative error is <= %g (at most %u "
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
	       "object with keys\nilluminance_lux, error_lux, accuracy, "
	       "query_tolerance, query_seconds,\niterations, seconds, links, "
	       "elements, clusters, leaves,\nrays, memory_bytes, solver, eps, "
	       "converged, error_estimate, scene,\nper_iteration.\n\n"
	       "Exit status: 0 success; 1 scene, solve or I/O error (message "
	       "on stderr);\n2 usage error (unknown option, bad value, "
	       "malformed points file).\n",
	       defaults->tol, DEFAULT_MAX_ITER, RAD_ACCURACY_DEFAULT);
}

/* --------------------------------------------------------------- parsing */

/* Parse a whole string as a finite double; 0 on success. */
static int parse_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

static int in_range(const cli_option *o, double v)
{
	if ((o->excl & 1) ? v <= o->lo : v < o->lo)
		return 0;
	return (o->excl & 2) ? v < o->hi : v <= o->hi;
}

/* Store value for option o into a; returns an exit code (0 = ok). */
static int apply_value(const cli_option *o, const char *value, cli_args *a)
{
	char *p = (char *)a + o->off;
	double v = 0;

	switch (o->kind) {
	case OPT_STRING:
		*(const char **)p = value;
		return 0;
	case OPT_SOLVER:
		if (rad_solver_kind_parse(value, (rad_solver_kind *)p) !=
		    RAD_OK)
			return usage_error("--%s: unknown solver '%s' (matrix, "
			                   "progressive or hr)",
			                   o->name, value);
		return 0;
	case OPT_ORACLE:
		for (size_t i = 0; i < 3; i++) {
			if (strcmp(value, oracle_names[i]) == 0) {
				*(rad_oracle *)p = (rad_oracle)i;
				return 0;
			}
		}
		return usage_error("--%s: unknown oracle '%s' (bfa, bf or f)",
		                   o->name, value);
	default:
		break;
	}
	if (parse_double(value, &v) != 0 || !in_range(o, v) ||
	    (o->kind != OPT_DOUBLE && v != floor(v)))
		return usage_error("--%s: invalid value '%s' (expected %s in "
		                   "%c%g, %g%c)",
		                   o->name, value,
		                   o->kind == OPT_DOUBLE ? "a number"
		                                         : "an integer",
		                   (o->excl & 1) ? '(' : '[', o->lo, o->hi,
		                   (o->excl & 2) ? ')' : ']');
	if (o->kind == OPT_DOUBLE)
		*(double *)p = v;
	else if (o->kind == OPT_INT)
		*(int *)p = (int)v;
	else
		*(uint32_t *)p = (uint32_t)v;
	return 0;
}

static const cli_option *find_option(const char *name, size_t len)
{
	for (size_t i = 0; i < NOPTIONS; i++)
		if (strlen(cli_options[i].name) == len &&
		    strncmp(cli_options[i].name, name, len) == 0)
			return &cli_options[i];
	return NULL;
}

/* One "--name[=value]" at argv[*i]; may consume argv[*i + 1]. */
static int parse_option(int argc, char **argv, int *i, cli_args *a)
{
	const char *arg = argv[*i] + 2;
	const char *eq = strchr(arg, '=');
	size_t len = eq ? (size_t)(eq - arg) : strlen(arg);
	const cli_option *o = find_option(arg, len);
	const char *value = eq ? eq + 1 : NULL;

	if (!o)
		return usage_error("unknown option '%s'", argv[*i]);
	if (o->seen_off)
		*(int *)((char *)a + o->seen_off) = 1;
	if (!o->metavar) {
		if (value)
			return usage_error("--%s takes no value", o->name);
		*(int *)((char *)a + o->off) = o->kind != OPT_FLAG_OFF;
		return 0;
	}
	if (!value) {
		if (*i + 1 >= argc)
			return usage_error("--%s needs a value (%s)", o->name,
			                   o->metavar);
		value = argv[++*i];
	}
	return apply_value(o, value, a);
}

/* Options that only make sense together, checked after parsing. */
static int check_combination(const cli_args *a)
{
	if (a->iterations && (a->tol_given || a->max_iter_given))
		return usage_error("--iterations runs a fixed number of steps; "
		                   "it cannot be combined with %s",
		                   a->tol_given ? "--converge"
		                                : "--max-iterations");
	if (!a->scene_path)
		return usage_error("no scene file given");
	return 0;
}

static int parse_args(int argc, char **argv, cli_args *a)
{
	int only_positional = 0;
	for (int i = 1; i < argc; i++) {
		const char *s = argv[i];
		int rc;
		if (!only_positional && strcmp(s, "--") == 0) {
			only_positional = 1;
		} else if (!only_positional && strncmp(s, "--", 2) == 0) {
			rc = parse_option(argc, argv, &i, a);
			if (rc != 0 || a->help)
				return rc;
		} else if (!only_positional && s[0] == '-' && s[1] != '\0') {
			if (strcmp(s, "-h") == 0) {
				a->help = 1;
				return 0;
			}
			return usage_error("unknown option '%s'", s);
		} else if (a->scene_path) {
			return usage_error("more than one scene given ('%s', "
			                   "'%s')",
			                   a->scene_path, s);
		} else {
			a->scene_path = s;
		}
	}
	return check_combination(a);
}

static void args_default(cli_args *a, double accuracy)
{
	memset(a, 0, sizeof(*a));
	rad_options_default(&a->opt);
	if (accuracy > 0)
		rad_options_accuracy(&a->opt, accuracy, NULL);
	a->accuracy = a->opt.accuracy;
	a->tol = a->opt.converge_tol;
	a->max_iter = DEFAULT_MAX_ITER;
}

/*
 * --accuracy sets several knobs, and an expert knob given beside it wins
 * whatever the order on the command line: parse once to find the
 * accuracy, then again over the defaults it gives.
 */
static int parse_with_accuracy(int argc, char **argv, cli_args *a)
{
	args_default(a, 0);
	int rc = parse_args(argc, argv, a);
	if (rc != EXIT_OKAY || a->help || !a->accuracy_given)
		return rc;
	args_default(a, a->accuracy);
	return parse_args(argc, argv, a);
}

/* ----------------------------------------------------------------- input */

typedef struct point_list {
	double *xyz; /* 6 doubles per point: position, normal */
	size_t n, cap;
} point_list;

static int points_push(point_list *pl, const double p[6])
{
	if (pl->n == pl->cap) {
		size_t ncap = pl->cap ? 2 * pl->cap : 64;
		double *nx = realloc(pl->xyz, ncap * 6 * sizeof(double));
		if (!nx)
			return -1;
		pl->xyz = nx;
		pl->cap = ncap;
	}
	memcpy(pl->xyz + 6 * pl->n++, p, 6 * sizeof(double));
	return 0;
}

/* Load a points file; malformed lines are usage errors naming file:line. */
static int load_points(const char *path, point_list *pl)
{
	FILE *f = fopen(path, "r");
	char *line = NULL;
	size_t cap = 0;
	unsigned long lineno = 0;
	int rc = EXIT_OKAY;

	if (!f) {
		fprintf(stderr,
		        "luxrad-solve: cannot open points file '%s': "
		        "%s\n",
		        path, strerror(errno));
		return EXIT_SOLVE;
	}
	while (rc == EXIT_OKAY && getline(&line, &cap, f) != -1) {
		double p[6];
		const char *why = NULL;
		lineno++;
		int r = rp_point_line_parse(line, p, &why);
		if (r < 0) {
			fprintf(stderr, "luxrad-solve: %s:%lu: %s\n", path,
			        lineno, why);
			rc = EXIT_USAGE;
		} else if (r > 0 && points_push(pl, p) != 0) {
			fprintf(stderr, "luxrad-solve: out of memory\n");
			rc = EXIT_SOLVE;
		}
	}
	if (rc == EXIT_OKAY && ferror(f)) {
		fprintf(stderr, "luxrad-solve: cannot read '%s'\n", path);
		rc = EXIT_SOLVE;
	}
	free(line);
	fclose(f);
	return rc;
}

/* ----------------------------------------------------------------- solve */

typedef struct run_log {
	rad_stats *it; /* stats after each iteration, in order */
	size_t n, cap;
	uint64_t rays;        /* sum over iterations */
	double load_seconds;  /* parse + scene build + BVH */
	double solve_seconds; /* wall time of all iterations */
	int converged;
} run_log;

static int log_push(run_log *lg, const rad_stats *st)
{
	if (lg->n == lg->cap) {
		size_t ncap = lg->cap ? 2 * lg->cap : 32;
		rad_stats *nit = realloc(lg->it, ncap * sizeof(*nit));
		if (!nit)
			return -1;
		lg->it = nit;
		lg->cap = ncap;
	}
	lg->it[lg->n++] = *st;
	lg->rays += st->rays;
	return 0;
}

static void print_progress(const rad_stats *st)
{
	fprintf(stderr,
	        "iteration %u: %.3f s, %llu links, %llu elements, %llu "
	        "leaves, residual %.3g, error %.3g, %lld bytes\n",
	        st->iteration, st->seconds, (unsigned long long)st->links,
	        (unsigned long long)st->elements,
	        (unsigned long long)st->leaves, st->residual,
	        st->error_estimate, (long long)st->mem.total);
}

/*
 * Run the solver.  Every iteration goes through rad_solver_converge with a
 * cap of one step, so that the engine judges convergence against our
 * tolerance in both modes while every iteration's statistics are kept;
 * --iterations simply never stops early.
 */
static int run_solver(rad_solver *sv, const cli_args *a, run_log *lg,
                      rad_error *err)
{
	uint32_t limit = a->iterations ? a->iterations : a->max_iter;
	double t0 = rad_seconds();
	rad_stats st = {0};

	for (uint32_t i = 0; i < limit; i++) {
		if (rad_solver_converge(sv, a->tol, 1, err) != RAD_OK)
			return -1;
		rad_solver_stats(sv, &st);
		if (log_push(lg, &st) != 0) {
			snprintf(err->msg, sizeof(err->msg), "out of memory");
			return -1;
		}
		if (a->per_iteration)
			print_progress(&st);
		if (!a->iterations && st.converged)
			break;
	}
	lg->solve_seconds = rad_seconds() - t0;
	lg->converged = st.converged;
	return 0;
}

/* ---------------------------------------------------------------- output */

/* jansson refuses NaN and infinities: those become null. */
static json_t *jreal(double v)
{
	return isfinite(v) ? json_real(v) : json_null();
}

static json_t *jint(uint64_t v)
{
	return json_integer((json_int_t)v);
}

static json_t *json_memory(const rad_mem_report *m)
{
	json_t *o = json_object();
	json_object_set_new(o, "total", json_integer(m->total));
	json_object_set_new(o, "peak_total", json_integer(m->peak_total));
	json_object_set_new(o, "peak_work", json_integer(m->peak_work));
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		json_object_set_new(o, rad_mem_kind_name((rad_mem_kind)k),
		                    json_integer(m->bytes[k]));
	return o;
}

/*
 * The integer counters written as-is under their field names, one list
 * per struct so that the JSON keys are the names documented in rad.h.
 */
/* clang-format off */
#define STATS_COUNTERS(X)                                                      \
	X(iteration) X(links) X(links_ss) X(links_sc) X(links_cc)              \
	X(links_light) X(links_active) X(links_passive) X(links_created)       \
	X(links_deleted) X(links_recreated) X(links_gathered)                  \
	X(links_transient) X(links_useful) X(elements) X(clusters) X(leaves)   \
	X(refinements) X(rays)
#define SCENE_COUNTERS(X)                                                      \
	X(triangles_in) X(triangles_nonfinite) X(triangles_degenerate)         \
	X(triangles_duplicate) X(polygons) X(polygons_cut) X(quads) X(materials) X(materials_offered) X(lights)       \
	X(emitters) X(nodes)
#define GLTF_COUNTERS(X)                                                       \
	X(meshes) X(primitives) X(primitives_skipped) X(textures_ignored)      \
	X(metallic_materials)
/* clang-format on */

static json_t *json_iteration(const rad_stats *s)
{
	json_t *o = json_object();
#define SET_(f) json_object_set_new(o, #f, jint(s->f));
	STATS_COUNTERS(SET_)
#undef SET_
	json_object_set_new(o, "seconds", jreal(s->seconds));
	json_object_set_new(o, "residual", jreal(s->residual));
	json_object_set_new(o, "error_estimate", jreal(s->error_estimate));
	json_object_set_new(o, "memory_bytes", json_memory(&s->mem));
	json_t *h = json_array();
	for (int k = 0; k < RAD_EHIST_BINS; k++)
		json_array_append_new(h, jint(s->energy_hist[k]));
	json_object_set_new(o, "energy_hist", h);
	return o;
}

static json_t *json_vec3(const double v[3])
{
	json_t *a = json_array();
	for (int i = 0; i < 3; i++)
		json_array_append_new(a, jreal(v[i]));
	return a;
}

static json_t *json_scene(const rad_scene *sc, const rad_scene_counts *c,
                          const sio_info *g)
{
	json_t *o = json_object();
	double lo[3], hi[3];

	rad_scene_bounds(sc, lo, hi);
	json_object_set_new(o, "bounds_min", json_vec3(lo));
	json_object_set_new(o, "bounds_max", json_vec3(hi));
#define SET_(f) json_object_set_new(o, #f, jint(c->f));
	SCENE_COUNTERS(SET_)
#undef SET_
#define SET_(f) json_object_set_new(o, #f, jint(g->f));
	GLTF_COUNTERS(SET_)
#undef SET_
	json_object_set_new(o, "warnings", json_string(g->warnings));
	return o;
}

/* Everything the run produced, gathered for the two printers. */
typedef struct report {
	const cli_args *a;
	const rad_scene *scene;
	const rad_scene_counts *counts;
	const sio_info *info;
	const run_log *lg;
	const rad_stats *final;  /* stats after the last iteration */
	const double *pts;       /* 6 per point, as read */
	const double *lux;       /* one per point */
	const double *error_lux; /* one per point: estimated |error| */
	size_t npoints;
	double query_seconds; /* wall time of the illuminance query */
} report;

static int print_json(const report *r)
{
	const rad_stats *s = r->final;
	json_t *o = json_object(), *lux = json_array(), *its = json_array();
	json_t *elux = json_array();

	for (size_t i = 0; i < r->npoints; i++) {
		json_array_append_new(lux, jreal(r->lux[i]));
		json_array_append_new(elux, jreal(r->error_lux[i]));
	}
	for (size_t i = 0; i < r->lg->n; i++)
		json_array_append_new(its, json_iteration(&r->lg->it[i]));
	json_object_set_new(o, "illuminance_lux", lux);
	json_object_set_new(o, "error_lux", elux);
	json_object_set_new(o, "accuracy", jreal(r->a->opt.accuracy));
	json_object_set_new(o, "query_tolerance", jreal(r->a->opt.query_tol));
	json_object_set_new(o, "query_seconds", jreal(r->query_seconds));
	json_object_set_new(
	        o, "solver",
	        json_string(rad_solver_kind_name(r->a->opt.solver)));
	json_object_set_new(o, "eps", jreal(r->a->opt.eps));
	json_object_set_new(o, "iterations", jint(s->iteration));
	json_object_set_new(o, "seconds", jreal(r->lg->solve_seconds));
	json_object_set_new(o, "load_seconds", jreal(r->lg->load_seconds));
	json_object_set_new(o, "converged", json_boolean(r->lg->converged));
	json_object_set_new(o, "tolerance", jreal(r->a->tol));
	json_object_set_new(o, "error_estimate", jreal(s->error_estimate));
	json_object_set_new(o, "links", jint(s->links));
	json_object_set_new(o, "elements", jint(s->elements));
	json_object_set_new(o, "clusters", jint(s->clusters));
	json_object_set_new(o, "leaves", jint(s->leaves));
	json_object_set_new(o, "rays", jint(r->lg->rays));
	json_object_set_new(o, "memory_bytes", json_memory(&s->mem));
	json_object_set_new(o, "memory_peak_bytes",
	                    json_integer(s->mem.peak_total));
	json_object_set_new(o, "scene",
	                    json_scene(r->scene, r->counts, r->info));
	json_object_set_new(o, "per_iteration", its);

	int rc =
	        json_dumpf(o, stdout, JSON_INDENT(2) | JSON_REAL_PRECISION(17));
	json_decref(o);
	if (rc != 0 || fputc('\n', stdout) == EOF)
		return EXIT_SOLVE;
	return EXIT_OKAY;
}

static void print_text_scene(const report *r)
{
	const rad_scene_counts *c = r->counts;
	printf("scene %s\n", r->a->scene_path);
	printf("  triangles %u (skipped: %u non-finite, %u degenerate, "
	       "%u repeated), polygons %u (%u quads; %u large ones cut "
	       "where surfaces cross them)\n",
	       c->triangles_in, c->triangles_nonfinite, c->triangles_degenerate,
	       c->triangles_duplicate, c->polygons, c->quads, c->polygons_cut);
	printf("  materials %u (of %u offered), emitters %u, lights %u, "
	       "nodes %u\n",
	       c->materials, c->materials_offered, c->emitters, c->lights,
	       c->nodes);
	printf("  meshes %u, primitives %u (%u skipped), loaded in %.3f s\n",
	       r->info->meshes, r->info->primitives,
	       r->info->primitives_skipped, r->lg->load_seconds);
	if (r->info->warnings[0])
		printf("  glTF warnings: %s\n", r->info->warnings);
}

static void print_text_iterations(const report *r)
{
	printf("\nsolver %s, eps %g\n", rad_solver_kind_name(r->a->opt.solver),
	       r->a->opt.eps);
	printf("%5s %9s %10s %10s %9s %10s %8s %11s %10s %10s %12s\n", "iter",
	       "seconds", "links", "elements", "clusters", "leaves", "refine",
	       "rays", "residual", "error", "memory");
	for (size_t i = 0; i < r->lg->n; i++) {
		const rad_stats *s = &r->lg->it[i];
		printf("%5u %9.3f %10llu %10llu %9llu %10llu %8llu %11llu "
		       "%10.3g %10.3g %12lld\n",
		       s->iteration, s->seconds, (unsigned long long)s->links,
		       (unsigned long long)s->elements,
		       (unsigned long long)s->clusters,
		       (unsigned long long)s->leaves,
		       (unsigned long long)s->refinements,
		       (unsigned long long)s->rays, s->residual,
		       s->error_estimate, (long long)s->mem.total);
	}
	printf("%s after %u iterations in %.3f s (error estimate %.3g, "
	       "tolerance %g)\n",
	       r->lg->converged ? "converged" : "NOT converged",
	       r->final->iteration, r->lg->solve_seconds,
	       r->final->error_estimate, r->a->tol);
	printf("links %llu (ss %llu, sc %llu, cc %llu, light %llu), "
	       "rays %llu\n",
	       (unsigned long long)r->final->links,
	       (unsigned long long)r->final->links_ss,
	       (unsigned long long)r->final->links_sc,
	       (unsigned long long)r->final->links_cc,
	       (unsigned long long)r->final->links_light,
	       (unsigned long long)r->lg->rays);
}

static void print_text(const report *r)
{
	const rad_mem_report *m = &r->final->mem;

	print_text_scene(r);
	print_text_iterations(r);
	printf("\nmemory by structure (bytes)\n");
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		printf("  %-18s %14lld\n", rad_mem_kind_name((rad_mem_kind)k),
		       (long long)m->bytes[k]);
	printf("  %-18s %14lld (peak %lld)\n", "total", (long long)m->total,
	       (long long)m->peak_total);
	if (r->npoints)
		printf("\nilluminance (lux, +- estimated error; query %.3f "
		       "s)\n",
		       r->query_seconds);
	for (size_t i = 0; i < r->npoints; i++) {
		const double *p = r->pts + 6 * i;
		printf("  (%g %g %g) n (%g %g %g): %.6g +- %.2g\n", p[0], p[1],
		       p[2], p[3], p[4], p[5], r->lux[i], r->error_lux[i]);
	}
}

/* ------------------------------------------------------------------ main */

static int engine_error(const char *what, const rad_error *err)
{
	fprintf(stderr, "luxrad-solve: %s: %s: %s\n", what,
	        rad_status_name(err->code), err->msg[0] ? err->msg : "failed");
	return EXIT_SOLVE;
}

static int load_scene(const char *path, rad_scene **sc, sio_info *info,
                      double *seconds)
{
	unsigned char *bytes = NULL;
	size_t len = 0;
	rad_error err = {0};
	rad_status st = sio_file_read(path, &bytes, &len, &err);

	if (st != RAD_OK) {
		fprintf(stderr, "luxrad-solve: %s\n", err.msg);
		return EXIT_SOLVE;
	}
	double t0 = rad_seconds();
	st = sio_load(bytes, len, sc, info, NULL, NULL, &err);
	*seconds = rad_seconds() - t0;
	free(bytes);
	if (st != RAD_OK) {
		fprintf(stderr, "luxrad-solve: %s: %s: %s\n", path,
		        rad_status_name(err.code), err.msg);
		return EXIT_SOLVE;
	}
	return EXIT_OKAY;
}

/* ---------------------------------------------------------------- export */

/* Write buf to path atomically: a temporary beside it, fsync, rename. */
static int write_file_atomic(const char *path, const void *buf, size_t len)
{
	size_t n = strlen(path) + 8;
	char *tmp = malloc(n);
	const unsigned char *p = buf;
	int fd = -1, made = 0;
	const char *why = "out of memory";
	if (!tmp)
		goto bad;
	snprintf(tmp, n, "%s.XXXXXX", path);
	if ((fd = mkstemp(tmp)) < 0)
		goto bad_errno;
	made = 1;
	mode_t um = umask(0); /* mkstemp makes 0600: use the usual mode */
	umask(um);
	if (fchmod(fd, 0666 & ~um) < 0)
		goto bad_errno;
	while (len > 0) {
		ssize_t w = write(fd, p, len);
		if (w < 0 && errno == EINTR)
			continue;
		if (w <= 0)
			goto bad_errno;
		p += w;
		len -= (size_t)w;
	}
	if (fsync(fd) < 0)
		goto bad_errno;
	int rc = close(fd);
	fd = -1;
	if (rc < 0 || rename(tmp, path) < 0)
		goto bad_errno;
	free(tmp);
	return EXIT_OKAY;
bad_errno:
	why = strerror(errno);
bad:
	fprintf(stderr, "luxrad-solve: cannot write %s: %s\n", path, why);
	if (fd >= 0)
		close(fd);
	if (made)
		unlink(tmp);
	free(tmp);
	return EXIT_SOLVE;
}

/* --export: the solved mesh as GLB (or .gltf JSON, by the extension). */
static int export_mesh(const char *path, const rad_scene *sc,
                       const rad_solver *sv, sio_export_info *info)
{
	rad_solution *sol = NULL;
	rad_error err = {0};
	sio_export_opts o;
	unsigned char *out = NULL;
	size_t len = 0, n = strlen(path);

	sio_export_opts_default(&o);
	if (n >= 5 && strcmp(path + n - 5, ".gltf") == 0)
		o.format = SIO_FORMAT_JSON;
	if (rad_solution_new(sv, &sol, &err) != RAD_OK)
		return engine_error("export", &err);
	rad_status st =
	        sio_export_solution(sc, sol, &o, &out, &len, info, &err);
	rad_solution_free(sol);
	if (st != RAD_OK)
		return engine_error("export", &err);
	int rc = write_file_atomic(path, out, len);
	free(out);
	return rc;
}

/* Solve the loaded scene, query the points and print the report. */
/* Lux and error estimates at every point, timed. */
static rad_status query_points(const rad_solver *sv, const point_list *pl,
                               double *lux, double *elux, double *seconds,
                               rad_error *err)
{
	double t0 = rad_seconds();
	rad_status st = rad_solver_query(sv, pl->xyz, pl->n, 0, lux, elux, err);
	*seconds = rad_seconds() - t0;
	return st;
}

static int solve_and_report(const cli_args *a, const rad_scene *sc,
                            const sio_info *info, const point_list *pl,
                            double load_seconds)
{
	rad_solver *sv = NULL;
	rad_error err = {0};
	run_log lg = {.load_seconds = load_seconds};
	rad_scene_counts counts;
	rad_stats final;
	sio_export_info xinfo;
	double *lux = calloc(pl->n ? 2 * pl->n : 1, sizeof(double));
	double *elux = lux + pl->n, tq = 0;
	int rc = EXIT_SOLVE;

	if (!lux) {
		fprintf(stderr, "luxrad-solve: out of memory\n");
		return EXIT_SOLVE;
	}
	if (rad_solver_new(sc, &a->opt, &sv, &err) != RAD_OK) {
		rc = engine_error("cannot make the solver", &err);
	} else if (run_solver(sv, a, &lg, &err) != 0) {
		rc = engine_error("solve failed", &err);
	} else if (a->export_path &&
	           export_mesh(a->export_path, sc, sv, &xinfo) != EXIT_OKAY) {
		rc = EXIT_SOLVE;
	} else if (pl->n &&
	           query_points(sv, pl, lux, elux, &tq, &err) != RAD_OK) {
		rc = engine_error("illuminance query failed", &err);
	} else {
		rad_solver_stats(sv, &final);
		rad_scene_counts_get(sc, &counts);
		report r = {.a = a,
		            .scene = sc,
		            .counts = &counts,
		            .info = info,
		            .lg = &lg,
		            .final = &final,
		            .pts = pl->xyz,
		            .lux = lux,
		            .error_lux = elux,
		            .npoints = pl->n,
		            .query_seconds = tq};
		if (a->json) {
			rc = print_json(&r);
		} else {
			print_text(&r);
			if (a->export_path)
				printf("\nexported %s: %zu meshes, %zu "
				       "vertices, "
				       "%zu triangles (white point %.6g lux)\n",
				       a->export_path, xinfo.meshes,
				       xinfo.vertices, xinfo.triangles,
				       xinfo.white_lux);
			rc = EXIT_OKAY;
		}
		if (!lg.converged && !a->iterations)
			fprintf(stderr,
			        "luxrad-solve: warning: not converged "
			        "after %u iterations\n",
			        final.iteration);
	}
	rad_solver_free(sv);
	free(lg.it);
	free(lux);
	return rc;
}

int main(int argc, char **argv)
{
	cli_args a;
	point_list pl = {0};
	rad_scene *sc = NULL;
	sio_info info = {0};
	double load_seconds = 0;

	int rc = parse_with_accuracy(argc, argv, &a);
	if (rc != EXIT_OKAY)
		return rc;
	if (a.help) {
		print_help(&a);
		return EXIT_OKAY;
	}
	if (a.points_path)
		rc = load_points(a.points_path, &pl);
	if (rc == EXIT_OKAY)
		rc = load_scene(a.scene_path, &sc, &info, &load_seconds);
	if (rc == EXIT_OKAY)
		rc = solve_and_report(&a, sc, &info, &pl, load_seconds);
	rad_scene_free(sc);
	free(pl.xyz);
	if (fflush(stdout) != 0 || ferror(stdout)) {
		fprintf(stderr, "luxrad-solve: cannot write the output\n");
		rc = EXIT_SOLVE;
	}
	return rc;
}
