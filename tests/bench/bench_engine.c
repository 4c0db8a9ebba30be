/*
 * bench_engine.c -- luxrad-bench, the engine benchmark (a program, not a
 * test: timings on a shared machine are too noisy to assert on).
 *
 * For each scene file given it measures, in this order:
 *   load   sio_load: parse + scene build + quad merging + BVH
 *   bvh    the BVH alone: the loaded scene's BVH is freed and rebuilt
 *          through the engine's internal vis.h, so the build is timed
 *          without parsing; its memory is Embree's own count (RAD_MEM_BVH)
 *   solve  one solver (hr by default) for N iterations or to convergence;
 *          links, elements, clusters, leaves, shadow rays and rays/s
 *          (rays summed over iterations / solve wall time), memory by
 *          structure after the last iteration.
 * Output is a readable report or, with --json, one JSON object that
 * tests/bench/run_bench.sh turns into a Markdown table.
 */
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "engine_json.h"
#include "rad.h"
#include "sceneio.h"
#include "vis.h"

typedef struct bench_args {
	rad_options opt;
	uint32_t iterations; /* 0: converge to tol */
	double tol;
	uint32_t max_iter;
	int json;
	char **scenes;
	int nscenes;
} bench_args;

typedef struct bench_result {
	const char *path;
	size_t file_bytes;
	double load_s, bvh_s, solve_s;
	uint64_t rays;
	int converged;
	rad_scene_counts counts;
	rad_stats st; /* after the last iteration */
	int64_t bvh_bytes;
} bench_result;

static void usage(FILE *f)
{
	fprintf(f, "Usage: luxrad-bench [options] SCENE.gltf|SCENE.glb...\n"
	           "  --threads N     worker threads, 0 = one per core [0]\n"
	           "  --solver NAME   matrix | progressive | hr [hr]\n"
	           "  --eps X         refinement threshold [engine default]\n"
	           "  --iterations N  run exactly N iterations [3]\n"
	           "  --tol T         instead, iterate until error <= T\n"
	           "  --json          one JSON object on stdout\n"
	           "  --help          this text\n"
	           "Times in seconds, memory in bytes, rays/s = shadow rays of "
	           "all\niterations / solve wall time.\n");
}

/* Parse a whole string as a finite number within [lo, hi]. */
static int number(const char *s, double lo, double hi, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end || errno || !isfinite(v) || v < lo || v > hi)
		return -1;
	*out = v;
	return 0;
}

/* Apply option o with value v; -1 if unknown or out of range. */
static int apply_option(bench_args *a, const char *o, const char *v)
{
	double x = 0;
	if (strcmp(o, "--solver") == 0)
		return rad_solver_kind_parse(v, &a->opt.solver) ? -1 : 0;
	if (strcmp(o, "--threads") == 0 && !number(v, 0, 256, &x))
		a->opt.threads = (int)x;
	else if (strcmp(o, "--eps") == 0 && !number(v, 1e-12, 1e9, &x))
		a->opt.eps = x;
	else if (strcmp(o, "--iterations") == 0 && !number(v, 1, 1e6, &x) &&
	         x == floor(x))
		a->iterations = (uint32_t)x;
	else if (strcmp(o, "--tol") == 0 && !number(v, 1e-12, 1, &x))
		a->tol = x;
	else
		return -1;
	if (strcmp(o, "--tol") == 0)
		a->iterations = 0; /* converge mode */
	return 0;
}

static int parse_args(int argc, char **argv, bench_args *a)
{
	for (int i = 1; i < argc; i++) {
		const char *o = argv[i];
		if (strcmp(o, "--json") == 0) {
			a->json = 1;
		} else if (strcmp(o, "--help") == 0) {
			usage(stdout);
			exit(0);
		} else if (strncmp(o, "--", 2) != 0) {
			a->scenes[a->nscenes++] = argv[i];
		} else if (i + 1 >= argc || apply_option(a, o, argv[++i])) {
			fprintf(stderr,
			        "luxrad-bench: bad option or value: %s\n", o);
			return -1;
		}
	}
	return a->nscenes > 0 ? 0 : -1;
}

/* Load the scene, then time a BVH rebuild on its own. */
static int bench_load(const char *path, rad_scene **sc, bench_result *r)
{
	rad_error err = {0};
	rad_mem_report m;
	unsigned char *bytes;

	if (sio_file_read(path, &bytes, &r->file_bytes, &err) != RAD_OK) {
		fprintf(stderr, "luxrad-bench: %s\n", err.msg);
		return -1;
	}
	double t0 = rad_seconds();
	rad_status st =
	        sio_load(bytes, r->file_bytes, sc, NULL, NULL, NULL, &err);
	r->load_s = rad_seconds() - t0;
	free(bytes);
	if (st == RAD_OK) {
		rad_vis_free(*sc);
		t0 = rad_seconds();
		st = rad_vis_build(*sc, &err);
		r->bvh_s = rad_seconds() - t0;
	}
	if (st != RAD_OK) {
		fprintf(stderr, "luxrad-bench: %s: %s\n", path, err.msg);
		return -1;
	}
	rad_scene_counts_get(*sc, &r->counts);
	rad_scene_memory(*sc, &m);
	r->bvh_bytes = m.bytes[RAD_MEM_BVH];
	return 0;
}

static int bench_solve(const bench_args *a, const rad_scene *sc,
                       bench_result *r)
{
	rad_solver *sv = NULL;
	rad_error err = {0};
	uint32_t n = a->iterations ? a->iterations : a->max_iter;

	if (rad_solver_new(sc, &a->opt, &sv, &err) != RAD_OK) {
		fprintf(stderr, "luxrad-bench: %s: %s\n", r->path, err.msg);
		return -1;
	}
	double t0 = rad_seconds();
	for (uint32_t i = 0; i < n; i++) {
		if (rad_solver_converge(sv, a->tol, 1, &err) != RAD_OK) {
			fprintf(stderr, "luxrad-bench: %s: %s\n", r->path,
			        err.msg);
			rad_solver_free(sv);
			return -1;
		}
		rad_solver_stats(sv, &r->st);
		r->rays += r->st.rays;
		if (!a->iterations && r->st.converged)
			break;
	}
	r->solve_s = rad_seconds() - t0;
	r->converged = r->st.converged;
	rad_solver_free(sv);
	return 0;
}

static json_t *result_json(const bench_result *r)
{
	json_t *o = json_object();

	json_object_set_new(o, "scene", json_string(r->path));
	json_object_set_new(o, "file_bytes",
	                    json_integer((json_int_t)r->file_bytes));
	json_object_set_new(o, "triangles",
	                    json_integer(r->counts.triangles_in));
	json_object_set_new(o, "polygons", json_integer(r->counts.polygons));
	json_object_set_new(o, "load_seconds", json_real(r->load_s));
	json_object_set_new(o, "bvh_seconds", json_real(r->bvh_s));
	json_object_set_new(o, "bvh_bytes", json_integer(r->bvh_bytes));
	json_object_set_new(o, "converged", json_boolean(r->converged));
	json_object_set_new(o, "solve_seconds", json_real(r->solve_s));
	json_object_set_new(o, "rays_total", json_integer((json_int_t)r->rays));
	json_object_set_new(
	        o, "rays_per_second",
	        json_real(r->solve_s > 0 ? (double)r->rays / r->solve_s : 0.0));
	json_object_set_new(o, "stats", ej_stats(&r->st));
	return o;
}

static void result_text(const bench_result *r)
{
	const rad_stats *s = &r->st;
	printf("%s (%zu bytes): %u triangles, %u polygons\n", r->path,
	       r->file_bytes, r->counts.triangles_in, r->counts.polygons);
	printf("  load (parse + build + BVH) %.4f s; BVH build alone %.4f s, "
	       "%lld bytes\n",
	       r->load_s, r->bvh_s, (long long)r->bvh_bytes);
	printf("  solve: %u iteration(s)%s in %.4f s: links %llu, elements "
	       "%llu, clusters %llu, leaves %llu\n",
	       s->iteration, r->converged ? " (converged)" : "", r->solve_s,
	       (unsigned long long)s->links, (unsigned long long)s->elements,
	       (unsigned long long)s->clusters, (unsigned long long)s->leaves);
	printf("  rays %llu, %.3g rays/s\n", (unsigned long long)r->rays,
	       r->solve_s > 0 ? (double)r->rays / r->solve_s : 0.0);
	printf("  memory (bytes):");
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		printf(" %s %lld", rad_mem_kind_name((rad_mem_kind)k),
		       (long long)s->mem.bytes[k]);
	printf("; total %lld, peak %lld\n", (long long)s->mem.total,
	       (long long)s->mem.peak_total);
}

int main(int argc, char **argv)
{
	bench_args a = {.iterations = 3, .tol = 1e-3, .max_iter = 10000};
	char **scenes = calloc((size_t)argc, sizeof(char *));
	json_t *all = json_array();
	int rc = 0;

	rad_options_default(&a.opt);
	a.scenes = scenes;
	if (!scenes || parse_args(argc, argv, &a) != 0) {
		usage(stderr);
		free(scenes);
		json_decref(all);
		return 2;
	}
	for (int i = 0; i < a.nscenes && rc == 0; i++) {
		bench_result r = {.path = a.scenes[i]};
		rad_scene *sc = NULL;
		if (bench_load(r.path, &sc, &r) != 0 ||
		    bench_solve(&a, sc, &r) != 0)
			rc = 1;
		else if (a.json)
			json_array_append_new(all, result_json(&r));
		else
			result_text(&r);
		rad_scene_free(sc);
	}
	if (rc == 0 && a.json) {
		json_t *o = json_pack("{s:s, s:i, s:f, s:O}", "solver",
		                      rad_solver_kind_name(a.opt.solver),
		                      "threads", a.opt.threads, "eps",
		                      a.opt.eps, "scenes", all);
		json_dumpf(o, stdout, JSON_INDENT(2));
		putchar('\n');
		json_decref(o);
	}
	json_decref(all);
	free(scenes);
	return rc;
}
