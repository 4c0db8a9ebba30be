/*
 * jobjson.c -- a job's options, target, eps log and statistics as JSON:
 * what job.create accepts, what job.info and the iteration events show
 * and what the store keeps.
 *
 * Options are one declarative table (opt_defs): the parser, the range
 * checks, the error messages and the effective-options output all read
 * it, so an option cannot be accepted without being reported back.  The
 * stored form of a job's options is {"solver": name, "options": {every
 * effective value}} with threads resolved to a number: a replay after a
 * restart must use the same thread count to be deterministic.
 */
#include <math.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "server.h"

/* Everything job.create's "options" sets. */
typedef struct opt_values {
	rad_options o;
	double tol;
	int max_iter;
} opt_values;

typedef enum opt_kind { O_DOUBLE, O_INT, O_BOOL, O_ENUM } opt_kind;

static const char *const oracle_names[] = {[RAD_ORACLE_BFA] = "bfa",
                                           [RAD_ORACLE_F] = "f",
                                           [RAD_ORACLE_BF] = "bf",
                                           NULL};
static const char *const store_names[] = {[RAD_STORE_ANTICIPATE] = "anticipate",
                                          [RAD_STORE_MINIMAL] = "minimal",
                                          NULL};

typedef struct opt_def {
	const char *name;
	opt_kind kind;
	size_t off;
	double lo, hi;
	int lo_open, hi_open;     /* range ends excluded */
	const char *const *names; /* O_ENUM */
} opt_def;

#define OV(f) offsetof(opt_values, f)

/*
 * "accuracy" comes first: it sets eps, variation, query_tol and tol
 * together (rad_options_accuracy), and any of those given beside it
 * overrides it whatever the order of the keys.
 */
static const opt_def opt_defs[] = {
        {"accuracy", O_DOUBLE, OV(o.accuracy), RAD_ACCURACY_MIN,
         RAD_ACCURACY_MAX, 0, 0, NULL},
        {"eps", O_DOUBLE, OV(o.eps), 0, HUGE_VAL, 1, 1, NULL},
        {"oracle", O_ENUM, OV(o.oracle), 0, 0, 0, 0, oracle_names},
        {"variation", O_DOUBLE, OV(o.variation), 0, HUGE_VAL, 1, 1, NULL},
        /* The engine refuses 1 (a single element per polygon side). */
        {"min_edge_rel", O_DOUBLE, OV(o.min_edge_rel), 0, 1, 1, 1, NULL},
        {"mesh_edge_rel", O_DOUBLE, OV(o.mesh_edge_rel), 0, 1, 1, 0, NULL},
        {"clustering", O_BOOL, OV(o.clustering), 0, 0, 0, 0, NULL},
        {"store", O_ENUM, OV(o.store), 0, 0, 0, 0, store_names},
        {"study", O_BOOL, OV(o.study), 0, 0, 0, 0, NULL},
        {"threads", O_INT, OV(o.threads), 0, 256, 0, 0, NULL},
        {"rcv_samples", O_INT, OV(o.rcv_samples), 1, 16, 0, 0, NULL},
        {"vis_samples", O_INT, OV(o.vis_samples), 1, 16, 0, 0, NULL},
        {"query_tol", O_DOUBLE, OV(o.query_tol), 0, 1, 1, 1, NULL},
        {"tol", O_DOUBLE, OV(tol), 0, 1, 1, 0, NULL},
        {"max_iterations", O_INT, OV(max_iter), 1, 1e9, 0, 0, NULL},
};

#define NOPT_DEFS (sizeof(opt_defs) / sizeof(opt_defs[0]))

static int opt_fail(rp_error *err, rp_err code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
static int opt_fail(rp_error *err, rp_err code, const char *fmt, ...)
{
	va_list ap;
	err->code = code;
	va_start(ap, fmt);
	vsnprintf(err->msg, sizeof(err->msg), fmt, ap);
	va_end(ap);
	return -1;
}

static void range_text(const opt_def *d, char *out, size_t len)
{
	if (d->hi == HUGE_VAL)
		snprintf(out, len, "%s %g", d->lo_open ? ">" : ">=", d->lo);
	else
		snprintf(out, len, "in %c%g, %g%c", d->lo_open ? '(' : '[',
		         d->lo, d->hi, d->hi_open ? ')' : ']');
}

static int in_range(const opt_def *d, double v)
{
	if (!isfinite(v) || (d->lo_open ? v <= d->lo : v < d->lo))
		return 0;
	return d->hi_open ? v < d->hi : v <= d->hi;
}

static int enum_index(const char *const *names, const char *v)
{
	for (int i = 0; names[i]; i++)
		if (strcmp(names[i], v) == 0)
			return i;
	return -1;
}

static int set_option(const opt_def *d, json_t *v, opt_values *ov,
                      rp_error *err)
{
	char *p = (char *)ov + d->off, rng[64];
	range_text(d, rng, sizeof(rng));
	switch (d->kind) {
	case O_BOOL:
		if (!json_is_boolean(v))
			return opt_fail(err, RP_ERR_BAD_REQUEST,
			                "option \"%s\" must be true or false",
			                d->name);
		*(int *)p = json_is_true(v);
		return 0;
	case O_ENUM: {
		int k = json_is_string(v)
		                ? enum_index(d->names, json_string_value(v))
		                : -2;
		if (k == -2)
			return opt_fail(err, RP_ERR_BAD_REQUEST,
			                "option \"%s\" must be a string",
			                d->name);
		if (k < 0)
			return opt_fail(
			        err, RP_ERR_INVALID,
			        "option \"%s\": unknown value \"%.64s\"",
			        d->name, json_string_value(v));
		*(int *)p = k;
		return 0;
	}
	case O_INT:
		if (!json_is_integer(v))
			return opt_fail(err, RP_ERR_BAD_REQUEST,
			                "option \"%s\" must be an integer",
			                d->name);
		if (!in_range(d, (double)json_integer_value(v)))
			return opt_fail(err, RP_ERR_INVALID,
			                "option \"%s\" must be %s (got %lld)",
			                d->name, rng,
			                (long long)json_integer_value(v));
		*(int *)p = (int)json_integer_value(v);
		return 0;
	case O_DOUBLE:
		if (!json_is_number(v))
			return opt_fail(err, RP_ERR_BAD_REQUEST,
			                "option \"%s\" must be a number",
			                d->name);
		if (!in_range(d, json_number_value(v)))
			return opt_fail(err, RP_ERR_INVALID,
			                "option \"%s\" must be %s (got %g)",
			                d->name, rng, json_number_value(v));
		*(double *)p = json_number_value(v);
		return 0;
	}
	return -1;
}

int srv_job_options_parse(srv *s, json_t *opts, const char *solver,
                          rad_options *o, double *tol, uint32_t *max_iter,
                          rp_error *err)
{
	opt_values ov;
	const char *key;
	json_t *v;

	rad_options_default(&ov.o);
	ov.o.accuracy = s->accuracy;
	ov.max_iter = 100;
	if (solver && rad_solver_kind_parse(solver, &ov.o.solver) != RAD_OK)
		return opt_fail(err, RP_ERR_INVALID,
		                "unknown solver \"%.64s\" (hr, rmb, matrix or "
		                "progressive)",
		                solver);
	if (opts && !json_is_object(opts))
		return opt_fail(err, RP_ERR_BAD_REQUEST,
		                "\"options\" must be an object");
	v = json_object_get(opts, opt_defs[0].name);
	if (v && set_option(&opt_defs[0], v, &ov, err) != 0)
		return -1;
	rad_options_accuracy(&ov.o, ov.o.accuracy, NULL);
	ov.tol = ov.o.converge_tol;
	json_object_foreach(opts, key, v)
	{
		size_t i = 0;
		while (i < NOPT_DEFS && strcmp(opt_defs[i].name, key) != 0)
			i++;
		if (i == NOPT_DEFS)
			return opt_fail(err, RP_ERR_INVALID,
			                "unknown option \"%.64s\"", key);
		if (set_option(&opt_defs[i], v, &ov, err) != 0)
			return -1;
	}
	if (ov.o.threads == 0)
		ov.o.threads = s->solver_threads;
	*o = ov.o;
	*tol = ov.tol;
	*max_iter = (uint32_t)ov.max_iter;
	return 0;
}

json_t *srv_job_options_json(const srv_job *j)
{
	opt_values ov = {
	        .o = j->opt, .tol = j->tol, .max_iter = (int)j->max_iter};
	json_t *o = json_object();
	for (size_t i = 0; i < NOPT_DEFS; i++) {
		const opt_def *d = &opt_defs[i];
		const char *p = (const char *)&ov + d->off;
		json_t *v = NULL;
		switch (d->kind) {
		case O_BOOL:
			v = json_boolean(*(const int *)p);
			break;
		case O_ENUM:
			v = json_string(d->names[*(const int *)p]);
			break;
		case O_INT:
			v = json_integer(*(const int *)p);
			break;
		case O_DOUBLE:
			v = srv_jreal(*(const double *)p);
			break;
		}
		json_object_set_new(o, d->name, v);
	}
	return o;
}

char *srv_job_options_text(const srv_job *j)
{
	json_t *o = json_object();
	json_object_set_new(o, "solver",
	                    json_string(rad_solver_kind_name(j->opt.solver)));
	json_object_set_new(o, "options", srv_job_options_json(j));
	char *t = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(o);
	return t;
}

/* ---------------------------------------------------------------- target */

json_t *srv_target_json(const job_target *t)
{
	json_t *o = json_object();
	switch (t->mode) {
	case JOB_MODE_NONE:
		json_object_set_new(o, "mode", json_string("none"));
		break;
	case JOB_MODE_ITERATIONS:
		json_object_set_new(o, "mode", json_string("iterations"));
		json_object_set_new(o, "n", json_integer(t->n));
		json_object_set_new(o, "until_iteration",
		                    json_integer(t->until));
		break;
	case JOB_MODE_CONVERGE:
		json_object_set_new(o, "mode", json_string("converge"));
		break;
	case JOB_MODE_SECONDS:
		json_object_set_new(o, "mode", json_string("seconds"));
		json_object_set_new(o, "seconds", srv_jreal(t->seconds));
		json_object_set_new(o, "left_s", srv_jreal(t->left_s));
		break;
	}
	json_object_set_new(o, "complete", json_boolean(t->complete));
	return o;
}

char *srv_job_target_text(const srv_job *j)
{
	json_t *o = srv_target_json(&j->target);
	if (j->has_pending_eps)
		json_object_set_new(o, "pending_eps",
		                    json_real(j->pending_eps));
	char *t = json_dumps(o, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(o);
	return t;
}

char *srv_job_eps_log_text(const srv_job *j)
{
	json_t *a = json_array();
	for (size_t i = 0; i < j->neps; i++)
		json_array_append_new(
		        a,
		        json_pack("[I f]", (json_int_t)j->eps_log[i].iteration,
		                  j->eps_log[i].eps));
	char *t = json_dumps(a, JSON_COMPACT | JSON_REAL_PRECISION(17));
	json_decref(a);
	return t;
}

/* ----------------------------------------------------------------- stats */

static json_t *jint(uint64_t v)
{
	return json_integer((json_int_t)v);
}

json_t *srv_stats_json(const rad_stats *st)
{
	json_t *o = json_object(), *links = json_object();
	json_t *hist = json_array(), *mem = json_object(),
	       *kinds = json_object();

	json_object_set_new(o, "iteration", jint(st->iteration));
	json_object_set_new(o, "seconds", srv_jreal(st->seconds));
	json_object_set_new(o, "seconds_total", srv_jreal(st->seconds_total));
#define LINK_(key, f) json_object_set_new(links, key, jint(st->f));
	LINK_("stored", links)
	LINK_("ss", links_ss)
	LINK_("sc", links_sc)
	LINK_("cc", links_cc)
	LINK_("light", links_light)
	LINK_("active", links_active)
	LINK_("passive", links_passive)
	LINK_("created", links_created)
	LINK_("deleted", links_deleted)
	LINK_("recreated", links_recreated)
	LINK_("gathered", links_gathered)
	LINK_("transient", links_transient)
	LINK_("useful", links_useful)
#undef LINK_
	json_object_set_new(o, "links", links);
	for (int k = 0; k < RAD_EHIST_BINS; k++)
		json_array_append_new(hist, jint(st->energy_hist[k]));
	json_object_set_new(o, "energy_hist", hist);
	json_object_set_new(o, "elements", jint(st->elements));
	json_object_set_new(o, "clusters", jint(st->clusters));
	json_object_set_new(o, "leaves", jint(st->leaves));
	json_object_set_new(o, "refinements", jint(st->refinements));
	json_object_set_new(o, "rays", jint(st->rays));
	json_object_set_new(o, "residual", srv_jreal(st->residual));
	json_object_set_new(o, "error_estimate", srv_jreal(st->error_estimate));
	json_object_set_new(o, "converged", json_boolean(st->converged));
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		json_object_set_new(kinds, rad_mem_kind_name((rad_mem_kind)k),
		                    json_integer(st->mem.bytes[k]));
	json_object_set_new(mem, "total_bytes", json_integer(st->mem.total));
	json_object_set_new(mem, "peak_bytes",
	                    json_integer(st->mem.peak_total));
	json_object_set_new(mem, "peak_work_bytes",
	                    json_integer(st->mem.peak_work));
	json_object_set_new(mem, "by_kind", kinds);
	json_object_set_new(o, "memory", mem);
	return o;
}
