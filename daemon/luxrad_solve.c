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
 * The command line is solve_args.c's; the engine's options and statistics
 * are written as JSON by engine_json.c, in the shape the daemon uses for
 * job.info and iteration events.  Exit codes: 0 ok, 1 scene / solve / I/O error
 * (the engine's message on stderr), 2 usage (bad option, bad value, malformed
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

#include "engine_json.h"
#include "export.h"
#include "rad.h"
#include "rad_reference.h"
#include "rp.h"
#include "sceneio.h"
#include "solve_args.h"
#include "tool.h"

#define PROG "luxrad-solve"

/* ----------------------------------------------------------------- input */

typedef struct point_list {
	double *xyz; /* 6 doubles per point: position, normal */
	size_t n;
} point_list;

/* ----------------------------------------------------------------- solve */

typedef struct run_log {
	rad_stats *it; /* stats after each iteration, in order */
	size_t n, cap;
	uint64_t rays;        /* sum over iterations */
	double load_seconds;  /* parse + scene build + BVH */
	double setup_seconds; /* the solver's hierarchy (rad_solver_new) */
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
	uint32_t limit =
	        a->iterations ? a->iterations : (uint32_t)a->opt.max_iterations;
	double t0 = rad_seconds();
	rad_stats st = {0};

	for (uint32_t i = 0; i < limit; i++) {
		if (rad_solver_converge(sv, a->opt.converge_tol, 1, err) !=
		    RAD_OK)
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

static json_t *jint(uint64_t v)
{
	return json_integer((json_int_t)v);
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
	double query_seconds;   /* wall time of the illuminance query */
	const rad_audit *audit; /* --audit-links, else NULL */
} report;

/* The audit's classes: receiver <- source, near or not (rad_reference.h). */
static const char *audit_class_name(int k)
{
	static const char *const names[RAD_AUDIT_CLASSES] = {
	        "surface <- surface",      "surface <- cluster",
	        "cluster <- surface",      "cluster <- cluster",
	        "surface <- surface near", "surface <- cluster near",
	        "cluster <- surface near", "cluster <- cluster near"};
	return names[k];
}

static json_t *ej_audit(const rad_audit *au)
{
	json_t *o = json_object(), *cls = json_array();
	for (int k = 0; k < RAD_AUDIT_CLASSES; k++) {
		const rad_audit_class *c = &au->cls[k];
		json_t *e = json_object();
		json_object_set_new(e, "class",
		                    json_string(audit_class_name(k)));
		json_object_set_new(e, "links", jint(c->links));
		json_object_set_new(e, "stored_form", ej_real(c->stored_form));
		json_object_set_new(e, "stored_transfer",
		                    ej_real(c->stored_transfer));
		json_object_set_new(e, "mc_form", ej_real(c->mc_form));
		json_object_set_new(e, "mc_transfer", ej_real(c->mc_transfer));
		json_array_append_new(cls, e);
	}
	json_object_set_new(o, "links_total", jint(au->links_total));
	json_object_set_new(o, "rays", jint(au->rays));
	json_object_set_new(o, "classes", cls);
	return o;
}

static void print_text_audit(const rad_audit *au)
{
	unsigned long long n = 0;
	for (int k = 0; k < RAD_AUDIT_CLASSES; k++)
		n += au->cls[k].links;
	printf("\nlinks against Monte Carlo (%llu of %llu links, %llu rays; "
	       "A F B in lm)\n",
	       n, (unsigned long long)au->links_total,
	       (unsigned long long)au->rays);
	printf("  %-24s %8s %11s %11s %7s %11s %11s %7s\n", "class", "links",
	       "F stored", "F by MC", "ratio", "moved", "by MC", "ratio");
	for (int k = 0; k < RAD_AUDIT_CLASSES; k++) {
		const rad_audit_class *c = &au->cls[k];
		if (!c->links)
			continue;
		printf("  %-24s %8llu %11.5g %11.5g %7.4f %11.5g %11.5g "
		       "%7.4f\n",
		       audit_class_name(k), (unsigned long long)c->links,
		       c->stored_form, c->mc_form,
		       c->mc_form > 0 ? c->stored_form / c->mc_form : NAN,
		       c->stored_transfer, c->mc_transfer,
		       c->mc_transfer > 0 ? c->stored_transfer / c->mc_transfer
		                          : NAN);
	}
}

static int print_json(const report *r)
{
	const rad_stats *s = r->final;
	json_t *o = json_object(), *lux = json_array(), *its = json_array();
	json_t *elux = json_array();

	for (size_t i = 0; i < r->npoints; i++) {
		json_array_append_new(lux, ej_real(r->lux[i]));
		json_array_append_new(elux, ej_real(r->error_lux[i]));
	}
	for (size_t i = 0; i < r->lg->n; i++)
		json_array_append_new(its, ej_stats(&r->lg->it[i]));
	json_object_set_new(o, "illuminance_lux", lux);
	json_object_set_new(o, "error_lux", elux);
	json_object_set_new(
	        o, "solver",
	        json_string(rad_solver_kind_name(r->a->opt.solver)));
	json_object_set_new(o, "options", ej_options(&r->a->opt));
	json_object_set_new(o, "seconds", ej_real(r->lg->solve_seconds));
	json_object_set_new(o, "load_seconds", ej_real(r->lg->load_seconds));
	json_object_set_new(o, "setup_seconds", ej_real(r->lg->setup_seconds));
	json_object_set_new(o, "query_seconds", ej_real(r->query_seconds));
	json_object_set_new(o, "converged", json_boolean(r->lg->converged));
	json_object_set_new(o, "rays_total", jint(r->lg->rays));
	json_object_set_new(o, "stats", ej_stats(s));
	json_object_set_new(o, "scene", tool_scene_json(r->scene, r->info));
	json_object_set_new(o, "per_iteration", its);
	if (r->audit)
		json_object_set_new(o, "audit", ej_audit(r->audit));

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
	if (c->back_faces)
		printf("  two-sided: %u back faces (among the polygons)\n",
		       c->back_faces);
	if (r->info->textures_read || r->info->textures_ignored)
		printf("  textures: %u read (%u images decoded, %u triangles), "
		       "%u ignored\n",
		       r->info->textures_read, r->info->images_decoded,
		       r->info->textured_triangles, r->info->textures_ignored);
	if (r->info->photometric_lights)
		printf("  photometric lights: %u\n",
		       r->info->photometric_lights);
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
	       "tolerance %g; solver made in %.3f s)\n",
	       r->lg->converged ? "converged" : "NOT converged",
	       r->final->iteration, r->lg->solve_seconds,
	       r->final->error_estimate, r->a->opt.converge_tol,
	       r->lg->setup_seconds);
	printf("links %llu (ss %llu, sc %llu, cc %llu, light %llu), "
	       "rays %llu\n",
	       (unsigned long long)r->final->links,
	       (unsigned long long)r->final->links_ss,
	       (unsigned long long)r->final->links_sc,
	       (unsigned long long)r->final->links_cc,
	       (unsigned long long)r->final->links_light,
	       (unsigned long long)r->lg->rays);
	if (r->final->budget_restarts)
		printf("the memory budget, reached in the first two "
		       "iterations, started the solve over %u times: eps %g\n",
		       r->final->budget_restarts, r->final->eps);
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
	if (r->audit)
		print_text_audit(r->audit);
}

/* ------------------------------------------------------------------ main */

static int engine_error(const char *what, const rad_error *err)
{
	fprintf(stderr, "luxrad-solve: %s: %s: %s\n", what,
	        rad_status_name(err->code), err->msg[0] ? err->msg : "failed");
	return EXIT_SOLVE;
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

/*
 * --polygons: the committed scene's polygons as CSV, one per line, so a
 * user can see what was read (a textured polygon's reflectance is its
 * texture's mean under it).  Corners 4 are empty for triangles.
 */
static int write_polygons(const char *path, const rad_scene *sc)
{
	rad_scene_counts counts;
	rad_polygon_desc p;
	rad_error err = {0};
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	if (!f) {
		fprintf(stderr, "luxrad-solve: out of memory\n");
		return EXIT_SOLVE;
	}
	rad_scene_counts_get(sc, &counts);
	fprintf(f, "polygon,node,corners");
	for (int k = 0; k < 4; k++)
		fprintf(f, ",x%d,y%d,z%d", k, k, k);
	fprintf(f, ",area,rho_r,rho_g,rho_b,lum_r,lum_g,lum_b\n");
	for (uint32_t i = 0; i < counts.polygons; i++) {
		if (rad_scene_polygon_get(sc, i, &p, &err) != RAD_OK) {
			fclose(f);
			free(buf);
			return engine_error("polygons", &err);
		}
		/* A node name is quoted, its quotes doubled (RFC 4180). */
		fprintf(f, "%u,\"", i);
		for (const char *c = rad_scene_node_name(sc, p.node); *c; c++) {
			if (*c == '"')
				fputc('"', f);
			fputc(*c, f);
		}
		fprintf(f, "\",%d", p.ncorners);
		for (int k = 0; k < 4; k++)
			for (int c = 0; c < 3; c++)
				if (k < p.ncorners)
					fprintf(f, ",%.9g", p.corners[k][c]);
				else
					fputs(",", f);
		fprintf(f, ",%.9g", p.area);
		for (int c = 0; c < 3; c++)
			fprintf(f, ",%.9g", p.reflectance[c]);
		for (int c = 0; c < 3; c++)
			fprintf(f, ",%.9g", p.luminance[c]);
		fputc('\n', f);
	}
	if (fclose(f) != 0) {
		free(buf);
		fprintf(stderr, "luxrad-solve: out of memory\n");
		return EXIT_SOLVE;
	}
	int rc = write_file_atomic(path, buf, len);
	free(buf);
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

static rad_status audit_links(rad_solver *sv, uint32_t every, rad_audit *out,
                              rad_error *err)
{
	rad_audit_options o;
	rad_audit_options_default(&o);
	o.every = every;
	return rad_solver_audit_links(sv, &o, out, err);
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
	rad_audit audit;
	double *lux = calloc(pl->n ? 2 * pl->n : 1, sizeof(double));
	double *elux = lux + pl->n, tq = 0;
	int rc = EXIT_SOLVE;

	if (!lux) {
		fprintf(stderr, "luxrad-solve: out of memory\n");
		return EXIT_SOLVE;
	}
	double t0 = rad_seconds();
	rad_status made = rad_solver_new(sc, &a->opt, &sv, &err);
	lg.setup_seconds = rad_seconds() - t0;
	if (made != RAD_OK) {
		rc = engine_error("cannot make the solver", &err);
	} else if (run_solver(sv, a, &lg, &err) != 0) {
		rc = engine_error("solve failed", &err);
	} else if (a->export_path &&
	           export_mesh(a->export_path, sc, sv, &xinfo) != EXIT_OKAY) {
		rc = EXIT_SOLVE;
	} else if (pl->n &&
	           query_points(sv, pl, lux, elux, &tq, &err) != RAD_OK) {
		rc = engine_error("illuminance query failed", &err);
	} else if (a->audit_every &&
	           audit_links(sv, a->audit_every, &audit, &err) != RAD_OK) {
		rc = engine_error("link audit failed", &err);
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
		            .query_seconds = tq,
		            .audit = a->audit_every ? &audit : NULL};
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

	int rc = cli_parse(argc, argv, &a);
	if (rc != EXIT_OKAY)
		return rc;
	if (a.help) {
		cli_print_help(&a);
		return EXIT_OKAY;
	}
	rad_bvh_set_mode(a.bvh);
	if (a.points_path)
		rc = tool_points_load(PROG, a.points_path, &pl.xyz, &pl.n);
	if (rc == EXIT_OKAY)
		rc = tool_scene_load(PROG, a.scene_path, &a.luminaires, &sc,
		                     &info, &load_seconds);
	if (rc == EXIT_OKAY && a.polygons_path)
		rc = write_polygons(a.polygons_path, sc);
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
