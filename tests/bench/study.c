/*
 * study.c -- luxrad-study, the reduced-memory study (issue: rmb against
 * hr).  A program, not a test: it prints figures and writes files; the
 * ratios it reports are measured in one run on one machine.
 *
 * Two modes:
 *
 *   luxrad-study [options] SCENE...
 *       runs hr, rmb and rmb with the report's creation criterion alone
 *       (rmb-minimal) on each scene at the same eps for N iterations
 *       with study statistics on, and writes to --out DIR:
 *         iterations.csv  one row per scene x solver x iteration: every
 *                         counter of rad_stats, memory by structure, the
 *                         energy histogram
 *         census.csv      one row per scene x solver: where its elements
 *                         sit at the end (rad_census: by the depth to
 *                         which their polygon's quadtree is complete)
 *         summary.csv     one row per scene: links, peak memory, time for
 *                         N iterations, hr and rmb, their ratios, and the
 *                         grid difference (RMS, relative to hr's mean)
 *
 *   luxrad-study --trade [options] SCENE...
 *       for each scene, a reference solution (see --reference) and a
 *       ladder of eps values: hr, rmb (and progressive with
 *       --progressive) converged to --tol at each; writes trade.csv with
 *       the grid error against the reference, solve time, links and peak
 *       memory.
 *
 * The grid: --grid N x N points on a horizontal plane at a quarter of the
 * scene's height, inset 5 % from its bounds, normals up.  Peak memory is
 * rad_mem_report.peak_work (everything the solver and the scene hold,
 * study statistics excepted).
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "rad.h"
#include "sceneio.h"

typedef struct study_args {
	rad_options opt;
	uint32_t iterations;
	int grid;
	int trade;
	int progressive;
	double tol;
	uint32_t max_iter;
	const char *reference; /* "exact:LUX", "nocluster", "hr" */
	const char *out;
	char **scenes;
	int nscenes;
} study_args;

typedef struct run_result {
	double seconds;
	rad_stats last;
	int64_t peak;
	double *lux;
	uint32_t iterations;
} run_result;

static void usage(FILE *f)
{
	fprintf(f, "Usage: luxrad-study [options] SCENE.glb...\n"
	           "       luxrad-study --trade [options] SCENE.glb...\n"
	           "  --out DIR          output directory [tests/bench/out]\n"
	           "  --iterations N     iterations per solve (study) [4]\n"
	           "  --eps X            oracle threshold (study) [1e-4]\n"
	           "  --threads N        worker threads, 0 = all cores [0]\n"
	           "  --grid N           N x N illuminance grid [24]\n"
	           "  --trade            the speed/accuracy ladder instead\n"
	           "  --tol R            trade: convergence tolerance [1e-3]\n"
	           "  --max-iterations N trade: iteration cap [60]\n"
	           "  --reference R      trade: nocluster (hr without clusters "
	           "at\n"
	           "                     eps 1e-6), hr (hr at eps 3e-6) or\n"
	           "                     exact:LUX (known illuminance) "
	           "[nocluster]\n"
	           "  --progressive      trade: also run the progressive "
	           "solver\n");
}

static int parse_args(int argc, char **argv, study_args *a)
{
	rad_options_default(&a->opt);
	a->iterations = 4;
	a->grid = 24;
	a->tol = 1e-3;
	a->max_iter = 60;
	a->reference = "nocluster";
	a->out = "tests/bench/out";
	for (int i = 1; i < argc; i++) {
		const char *o = argv[i];
		const char *v = i + 1 < argc ? argv[i + 1] : NULL;
		if (!strcmp(o, "--help")) {
			usage(stdout);
			exit(0);
		} else if (!strcmp(o, "--trade")) {
			a->trade = 1;
		} else if (!strcmp(o, "--progressive")) {
			a->progressive = 1;
		} else if (v && !strcmp(o, "--out")) {
			a->out = argv[++i];
		} else if (v && !strcmp(o, "--reference")) {
			a->reference = argv[++i];
		} else if (v && !strcmp(o, "--iterations")) {
			a->iterations = (uint32_t)strtoul(argv[++i], NULL, 10);
		} else if (v && !strcmp(o, "--max-iterations")) {
			a->max_iter = (uint32_t)strtoul(argv[++i], NULL, 10);
		} else if (v && !strcmp(o, "--eps")) {
			a->opt.eps = strtod(argv[++i], NULL);
		} else if (v && !strcmp(o, "--tol")) {
			a->tol = strtod(argv[++i], NULL);
		} else if (v && !strcmp(o, "--threads")) {
			a->opt.threads = atoi(argv[++i]);
		} else if (v && !strcmp(o, "--grid")) {
			a->grid = atoi(argv[++i]);
		} else if (o[0] == '-') {
			fprintf(stderr, "luxrad-study: bad option '%s'\n", o);
			usage(stderr);
			return 2;
		} else {
			a->scenes = argv + i;
			a->nscenes = argc - i;
			break;
		}
	}
	if (a->nscenes == 0 || a->iterations == 0 || a->grid < 1 ||
	    a->grid > 1000 || !(a->opt.eps > 0) || !(a->tol > 0)) {
		usage(stderr);
		return 2;
	}
	return 0;
}

/* The N x N grid of the header comment, 6 doubles per point. */
static double *make_grid(const rad_scene *s, int n)
{
	double lo[3], hi[3];
	rad_scene_bounds(s, lo, hi);
	double *p = malloc((size_t)n * n * 6 * sizeof(double));
	if (!p)
		return NULL;
	double y = lo[1] + 0.25 * (hi[1] - lo[1]);
	for (int i = 0; i < n; i++) {
		for (int j = 0; j < n; j++) {
			double *q = p + 6 * ((size_t)i * n + j);
			double u = 0.05 + 0.9 * (i + 0.5) / n;
			double v = 0.05 + 0.9 * (j + 0.5) / n;
			q[0] = lo[0] + u * (hi[0] - lo[0]);
			q[1] = y;
			q[2] = lo[2] + v * (hi[2] - lo[2]);
			q[3] = 0;
			q[4] = 1;
			q[5] = 0;
		}
	}
	return p;
}

/* RMS of a - b over n values, relative to the mean of b. */
static double rel_rms(const double *a, const double *b, size_t n)
{
	double d2 = 0, m = 0;
	for (size_t i = 0; i < n; i++) {
		d2 += (a[i] - b[i]) * (a[i] - b[i]);
		m += b[i];
	}
	m /= (double)n;
	return m > 0 ? sqrt(d2 / (double)n) / m : 0;
}

static void csv_header(FILE *f)
{
	fprintf(f, "scene,solver,iteration,seconds,links,links_active,"
	           "links_passive,links_created,links_deleted,"
	           "links_recreated,links_gathered,links_useful,"
	           "links_transient,elements,clusters,leaves,rays,residual,"
	           "mem_total,mem_peak_work");
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		fprintf(f, ",mem_%s", rad_mem_kind_name((rad_mem_kind)k));
	for (int k = 0; k < RAD_EHIST_BINS; k++)
		fprintf(f, ",ehist_%d", k);
	fputc('\n', f);
}

static void csv_row(FILE *f, const char *scene, const char *solver,
                    const rad_stats *s)
{
	fprintf(f,
	        "%s,%s,%u,%.6f,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,%llu,"
	        "%llu,%llu,%llu,%llu,%.6g,%lld,%lld",
	        scene, solver, s->iteration, s->seconds,
	        (unsigned long long)s->links,
	        (unsigned long long)s->links_active,
	        (unsigned long long)s->links_passive,
	        (unsigned long long)s->links_created,
	        (unsigned long long)s->links_deleted,
	        (unsigned long long)s->links_recreated,
	        (unsigned long long)s->links_gathered,
	        (unsigned long long)s->links_useful,
	        (unsigned long long)s->links_transient,
	        (unsigned long long)s->elements,
	        (unsigned long long)s->clusters, (unsigned long long)s->leaves,
	        (unsigned long long)s->rays, s->residual,
	        (long long)s->mem.total, (long long)s->mem.peak_work);
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		fprintf(f, ",%lld", (long long)s->mem.bytes[k]);
	for (int k = 0; k < RAD_EHIST_BINS; k++)
		fprintf(f, ",%llu", (unsigned long long)s->energy_hist[k]);
	fputc('\n', f);
}

/* census.csv: where the elements sit at the end of a solve (rad_census):
 * per depth d to which a polygon's quadtree is complete, the polygons and
 * the elements of their trees. */
static void census_header(FILE *f)
{
	fprintf(f, "scene,solver,polygons,elements,below_emitters");
	for (int d = 0; d < RAD_CENSUS_DEPTHS; d++)
		fprintf(f, ",polys_d%d", d);
	for (int d = 0; d < RAD_CENSUS_DEPTHS; d++)
		fprintf(f, ",elements_d%d", d);
	fputc('\n', f);
}

static void census_row(FILE *f, const char *scene, const char *solver,
                       const rad_solver *sv)
{
	rad_census c;
	uint64_t np = 0;
	rad_solver_census(sv, &c);
	for (int d = 0; d < RAD_CENSUS_DEPTHS; d++)
		np += c.polys_by_depth[d];
	fprintf(f, "%s,%s,%llu,%llu,%llu", scene, solver,
	        (unsigned long long)np, (unsigned long long)c.elements,
	        (unsigned long long)c.below_emitters);
	for (int d = 0; d < RAD_CENSUS_DEPTHS; d++)
		fprintf(f, ",%llu", (unsigned long long)c.polys_by_depth[d]);
	for (int d = 0; d < RAD_CENSUS_DEPTHS; d++)
		fprintf(f, ",%llu", (unsigned long long)c.elements_by_depth[d]);
	fputc('\n', f);
}

/*
 * Solve: `iterations` steps, or to tol when iterations is 0.  Per-iteration
 * rows go to csv, and where the elements sit at the end to census, when
 * given.  Fills r (r->lux allocated for the grid).
 */
static int solve(const rad_scene *sc, const rad_options *opt,
                 uint32_t iterations, double tol, uint32_t max_iter,
                 const double *grid, size_t npts, FILE *csv, FILE *census,
                 const char *name, const char *label, run_result *r)
{
	rad_solver *sv;
	rad_error err;
	memset(r, 0, sizeof(*r));
	if (rad_solver_new(sc, opt, &sv, &err)) {
		fprintf(stderr, "luxrad-study: %s\n", err.msg);
		return 1;
	}
	uint32_t n = iterations ? iterations : max_iter;
	for (uint32_t i = 0; i < n; i++) {
		if (rad_solver_step(sv, &err)) {
			fprintf(stderr, "luxrad-study: %s: %s\n", name,
			        err.msg);
			rad_solver_free(sv);
			return 1;
		}
		rad_solver_stats(sv, &r->last);
		if (csv)
			csv_row(csv, name, label, &r->last);
		if (!iterations && r->last.error_estimate <= tol)
			break;
	}
	if (census)
		census_row(census, name, label, sv);
	r->iterations = r->last.iteration;
	r->seconds = r->last.seconds_total;
	r->peak = r->last.mem.peak_work;
	r->lux = malloc(npts * sizeof(double));
	int rc = !r->lux ||
	         rad_solver_illuminance(sv, grid, npts, r->lux, &err) != RAD_OK;
	if (rc)
		fprintf(stderr, "luxrad-study: %s: grid query failed\n", name);
	rad_solver_free(sv);
	return rc;
}

static const char *base_name(const char *path)
{
	const char *s = strrchr(path, '/');
	return s ? s + 1 : path;
}

static FILE *open_out(const study_args *a, const char *file)
{
	char path[4096];
	snprintf(path, sizeof(path), "%s/%s", a->out, file);
	FILE *f = fopen(path, "w");
	if (!f)
		fprintf(stderr, "luxrad-study: %s: %s\n", path,
		        strerror(errno));
	return f;
}

static rad_scene *load_scene(const char *path)
{
	rad_scene *sc;
	rad_error err;
	if (sio_load_file(path, &sc, NULL, &err)) {
		fprintf(stderr, "luxrad-study: %s\n", err.msg);
		return NULL;
	}
	return sc;
}

static int run_study(const study_args *a)
{
	FILE *csv = open_out(a, "iterations.csv");
	FILE *sum = open_out(a, "summary.csv");
	FILE *census = open_out(a, "census.csv");
	if (!csv || !sum || !census)
		return 1;
	csv_header(csv);
	census_header(census);
	fprintf(sum, "scene,polygons,eps,iterations,links_hr,links_rmb,"
	             "links_ratio,peak_hr,peak_rmb,peak_ratio,seconds_hr,"
	             "seconds_rmb,time_ratio,grid_rms_rel,grid_mean_hr,"
	             "grid_mean_rmb,links_rmb_minimal,peak_rmb_minimal,"
	             "seconds_rmb_minimal,grid_rms_rel_minimal\n");
	int rc = 0;
	for (int i = 0; i < a->nscenes && !rc; i++) {
		rad_scene *sc = load_scene(a->scenes[i]);
		if (!sc)
			return 1;
		rad_scene_counts cnt;
		rad_scene_counts_get(sc, &cnt);
		size_t npts = (size_t)a->grid * a->grid;
		double *grid = make_grid(sc, a->grid);
		run_result r[3];
		memset(r, 0, sizeof(r));
		const char *name = base_name(a->scenes[i]);
		/* hr, rmb, rmb with the report's criterion alone */
		static const char *const label[3] = {"hr", "rmb",
		                                     "rmb-minimal"};
		for (int k = 0; k < 3 && grid && !rc; k++) {
			rad_options o = a->opt;
			o.solver = k ? RAD_SOLVER_RMB : RAD_SOLVER_HR;
			o.store = k == 2 ? RAD_STORE_MINIMAL
			                 : RAD_STORE_ANTICIPATE;
			o.study = 1;
			fprintf(stderr, "luxrad-study: %s: %s...\n", name,
			        label[k]);
			rc = solve(sc, &o, a->iterations, 0, 0, grid, npts, csv,
			           census, name, label[k], &r[k]);
		}
		if (!grid)
			rc = 1;
		if (!rc) {
			double m0 = 0, m1 = 0;
			for (size_t p = 0; p < npts; p++) {
				m0 += r[0].lux[p] / (double)npts;
				m1 += r[1].lux[p] / (double)npts;
			}
			fprintf(sum,
			        "%s,%u,%g,%u,%llu,%llu,%.4f,%lld,%lld,%.4f,%."
			        "4f,"
			        "%.4f,%.4f,%.6f,%.4f,%.4f,%llu,%lld,%.4f,%."
			        "6f\n",
			        name, cnt.polygons, a->opt.eps, a->iterations,
			        (unsigned long long)r[0].last.links,
			        (unsigned long long)r[1].last.links,
			        (double)r[1].last.links /
			                (double)(r[0].last.links
			                                 ? r[0].last.links
			                                 : 1),
			        (long long)r[0].peak, (long long)r[1].peak,
			        (double)r[1].peak / (double)r[0].peak,
			        r[0].seconds, r[1].seconds,
			        r[1].seconds /
			                (r[0].seconds > 0 ? r[0].seconds : 1),
			        rel_rms(r[1].lux, r[0].lux, npts), m0, m1,
			        (unsigned long long)r[2].last.links,
			        (long long)r[2].peak, r[2].seconds,
			        rel_rms(r[2].lux, r[0].lux, npts));
			fflush(sum);
			fflush(csv);
		}
		for (int k = 0; k < 3; k++)
			free(r[k].lux);
		free(grid);
		rad_scene_free(sc);
	}
	fclose(csv);
	fclose(sum);
	fclose(census);
	return rc;
}

static int run_trade(const study_args *a)
{
	static const double ladder[] = {3e-3, 1e-3, 3e-4, 1e-4, 3e-5};
	/* progressive's knob is its mesh: one edge per rung */
	static const double mesh[] = {0.1, 0.07, 0.05, 0.035, 0.025};
	FILE *f = open_out(a, "trade.csv");
	if (!f)
		return 1;
	fprintf(f, "scene,solver,eps,iterations,converged,seconds,links,"
	           "peak_bytes,grid_rms_rel,grid_mean,reference_mean\n");
	int rc = 0;
	for (int i = 0; i < a->nscenes && !rc; i++) {
		rad_scene *sc = load_scene(a->scenes[i]);
		if (!sc)
			return 1;
		const char *name = base_name(a->scenes[i]);
		size_t npts = (size_t)a->grid * a->grid;
		double *grid = make_grid(sc, a->grid);
		double *ref = malloc(npts * sizeof(double));
		rc = !grid || !ref;
		if (!rc && !strncmp(a->reference, "exact:", 6)) {
			double v = strtod(a->reference + 6, NULL);
			for (size_t p = 0; p < npts; p++)
				ref[p] = v;
		} else if (!rc) {
			rad_options o = a->opt;
			o.solver = RAD_SOLVER_HR;
			o.variation = 0.1;
			o.eps = 3e-6;
			if (!strcmp(a->reference, "nocluster")) {
				o.clustering = 0;
				o.eps = 1e-6;
			}
			run_result r;
			fprintf(stderr, "luxrad-study: %s: reference...\n",
			        name);
			rc = solve(sc, &o, 0, a->tol / 10, 200, grid, npts,
			           NULL, NULL, name, "reference", &r);
			if (!rc)
				memcpy(ref, r.lux, npts * sizeof(double));
			free(r.lux);
		}
		double rmean = 0;
		for (size_t p = 0; !rc && p < npts; p++)
			rmean += ref[p] / (double)npts;
		int nsolvers = a->progressive ? 3 : 2;
		for (size_t e = 0; !rc && e < sizeof(ladder) / sizeof(*ladder);
		     e++) {
			for (int k = 0; k < nsolvers && !rc; k++) {
				rad_options o = a->opt;
				o.solver = k == 0   ? RAD_SOLVER_HR
				           : k == 1 ? RAD_SOLVER_RMB
				                    : RAD_SOLVER_PROGRESSIVE;
				o.eps = ladder[e];
				if (k == 2)
					o.mesh_edge_rel = mesh[e];
				run_result r;
				fprintf(stderr, "luxrad-study: %s: %s eps %g\n",
				        name, rad_solver_kind_name(o.solver),
				        ladder[e]);
				rc = solve(sc, &o, 0, a->tol, a->max_iter, grid,
				           npts, NULL, NULL, name, NULL, &r);
				if (rc)
					break;
				double m = 0;
				for (size_t p = 0; p < npts; p++)
					m += r.lux[p] / (double)npts;
				fprintf(f,
				        "%s,%s,%g,%u,%d,%.4f,%llu,%lld,%.6f,"
				        "%.4f,%.4f\n",
				        name, rad_solver_kind_name(o.solver),
				        ladder[e], r.iterations,
				        r.last.converged, r.seconds,
				        (unsigned long long)r.last.links,
				        (long long)r.peak,
				        rel_rms(r.lux, ref, npts), m, rmean);
				fflush(f);
				free(r.lux);
			}
		}
		free(grid);
		free(ref);
		rad_scene_free(sc);
	}
	fclose(f);
	return rc;
}

int main(int argc, char **argv)
{
	study_args a;
	memset(&a, 0, sizeof(a));
	int rc = parse_args(argc, argv, &a);
	if (rc)
		return rc;
	return a.trade ? run_trade(&a) : run_study(&a);
}
