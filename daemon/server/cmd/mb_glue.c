/*
 * mb_glue.c -- luxradd's side of the Modbus server (modbus.h): starts and
 * stops it, turns jobs, job events and sensors into mb_publish_* calls,
 * evaluates sensors on each published solution, keeps each job's sensors
 * for sensor.add / sensor.list (sensor_cmd.c), and reports the server in
 * status and /metrics.
 *
 * DESIGN
 * Everything here runs on the I/O thread except the sensor evaluation
 * task's run(), which executes on a query thread with its own copy of the
 * points and a reference on the solution.  Per job, this file keeps a
 * record (mbp_job: I/O thread only) with the job's sensors -- the scene's,
 * then those added with sensor.add -- their latest value, and the error
 * estimates of the last two iterations (for the progress and the ETA).
 *
 * It is an observer of the core (core/observe.c), registered by
 * cmd_mb_start: restored jobs (with their sensor.add sensors from the
 * store, published in id order), created jobs, every job event (the job
 * is republished; after an iteration its sensors are evaluated) and
 * deleted jobs.  cmd_mb_stop runs after the workers are joined.
 *
 * Sensor values.  After each iteration event the job's latest solution
 * is evaluated at every sensor with rad_solution_query -- the call
 * query.points makes, with the same 6 doubles per point -- on the query
 * pool; the result is published on the I/O thread, per sensor only when
 * its iteration is newer than the one published (two evaluations may
 * finish out of order).  Sensors added with sensor.add are recorded in
 * the store (on the store thread, before the reply) and come back with
 * their job after a restart (cmd_mb_sensors_restore); the scene's come
 * back with the stored scene bytes.
 *
 * Progress (0..1, of the current run target):
 *   iterations  (iteration - first iteration of the run) / n;
 *   seconds     budget used / budget;
 *   converge    the larger of iteration / max_iterations and the
 *               log-scale way from the job's first error estimate to
 *               the tolerance: log(e0 / e) / log(e0 / tol);
 *   done        1; never run: unknown (NaN).
 * ETA (seconds): iterations left x the last iteration's time; seconds
 * mode: the budget left; converge: the iterations the error-estimate
 * trend needs (e_k = e * rho^k, rho = e / e_prev when 0 < rho < 1, at
 * most max_iterations - iteration) x the last iteration's time; 0 when
 * done; unknown (NaN) when paused, failed, cancelled or without a trend.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "log.h"
#include "modbus.h"

#define DAEMON_TICK_S 1.0 /* the daemon block's refresh */

typedef struct mbp_job {
	uint64_t id;
	cmd_sensor *sensors;
	size_t n, cap;
	int64_t stats_iter; /* iteration the numbers below come from */
	double err, err_prev, err_first, iter_s, total_s;
	struct mbp_job *next;
} mbp_job;

struct cmd_mbpub {
	mbp_job *jobs;
};

/* ------------------------------------------------------------ records */

static struct cmd_mbpub *state(cmd_server *d)
{
	if (!d->mbpub)
		d->mbpub = calloc(1, sizeof(*d->mbpub));
	return d->mbpub;
}

static mbp_job *find_job(cmd_server *d, uint64_t id)
{
	struct cmd_mbpub *m = d->mbpub;
	for (mbp_job *p = m ? m->jobs : NULL; p; p = p->next)
		if (p->id == id)
			return p;
	return NULL;
}

static cmd_sensor *find_sensor(mbp_job *p, const char *name)
{
	for (size_t i = 0; i < p->n; i++)
		if (strcmp(p->sensors[i].name, name) == 0)
			return &p->sensors[i];
	return NULL;
}

static cmd_sensor *add_sensor(mbp_job *p, const char *name, const double pt[6],
                              int added)
{
	if (p->n == p->cap) {
		size_t nc = p->cap ? 2 * p->cap : 8;
		cmd_sensor *ns = realloc(p->sensors, nc * sizeof(*ns));
		if (!ns)
			return NULL;
		p->sensors = ns;
		p->cap = nc;
	}
	cmd_sensor *x = &p->sensors[p->n++];
	memset(x, 0, sizeof(*x));
	snprintf(x->name, sizeof(x->name), "%s", name);
	memcpy(x->pt, pt, sizeof(x->pt));
	x->added = added;
	x->iter = -1;
	x->lux = NAN;
	return x;
}

/* The job's record, made with the scene's sensors the first time. */
static mbp_job *job_record(cmd_server *d, srv_job *j)
{
	mbp_job *p = find_job(d, j->id);
	struct cmd_mbpub *m = state(d);
	if (p || !m)
		return p;
	p = calloc(1, sizeof(*p));
	if (!p)
		return NULL;
	p->id = j->id;
	p->stats_iter = -1;
	p->err = p->err_prev = p->err_first = NAN;
	p->iter_s = p->total_s = NAN;
	for (size_t i = 0; i < j->scene->nsensors; i++) {
		const sio_sensor *g = &j->scene->sensors[i];
		double pt[6] = {g->position[0], g->position[1], g->position[2],
		                g->normal[0],   g->normal[1],   g->normal[2]};
		if (!add_sensor(p, g->name, pt, 0))
			srv_warn("job %llu: out of memory for sensor '%s'",
			         (unsigned long long)j->id, g->name);
	}
	p->next = m->jobs;
	m->jobs = p;
	return p;
}

static void free_job(mbp_job *p)
{
	free(p->sensors);
	free(p);
}

/* ------------------------------------------------------------- values */

static mb_job_state mb_state_of(srv_job_state st)
{
	return (mb_job_state)((int)st + 1); /* same order, 0 = empty */
}

/* Take the error estimate and timings from the latest stats text. */
static void update_stats(mbp_job *p, uint32_t iter, const char *text)
{
	json_t *o = text ? json_loads(text, 0, NULL) : NULL;
	if (!o)
		return;
	json_t *e = json_object_get(o, "error_estimate");
	json_t *sec = json_object_get(o, "seconds");
	json_t *tot = json_object_get(o, "seconds_total");
	double err = json_is_number(e) ? json_number_value(e) : NAN;
	if ((int64_t)iter == p->stats_iter + 1)
		p->err_prev = p->err;
	else
		p->err_prev = NAN; /* no trend across a gap */
	p->err = err;
	if (isnan(p->err_first) && isfinite(err) && err > 0)
		p->err_first = err;
	p->iter_s = json_is_number(sec) ? json_number_value(sec) : NAN;
	p->total_s = json_is_number(tot) ? json_number_value(tot) : NAN;
	p->stats_iter = iter;
	json_decref(o);
}

static double clamp01(double x)
{
	return x < 0 ? 0 : x > 1 ? 1 : x;
}

typedef struct job_snap {
	srv_job_state st;
	uint32_t iter;
	double residual;
	uint64_t links;
	int64_t mem;
	job_target t;
	double deadline;
	char *stats; /* copy, when newer than the record's */
} job_snap;

static double progress_of(const job_snap *js, const mbp_job *p,
                          const srv_job *j, double now)
{
	const job_target *t = &js->t;
	if (js->st == SRV_JOB_DONE)
		return 1;
	if (t->mode == JOB_MODE_NONE)
		return NAN;
	if (t->complete)
		return 1;
	switch (t->mode) {
	case JOB_MODE_ITERATIONS: {
		if (t->n == 0)
			return 1;
		double first = (double)t->until - (double)t->n;
		return clamp01(((double)js->iter - first) / (double)t->n);
	}
	case JOB_MODE_SECONDS: {
		if (!(t->seconds > 0))
			return 1;
		double left = js->st == SRV_JOB_RUNNING && js->deadline > 0
		                      ? js->deadline - now
		                      : t->left_s;
		return clamp01(1 - left / t->seconds);
	}
	case JOB_MODE_CONVERGE: {
		double tol = j->opt.converge_tol;
		double pi = (double)js->iter / (double)j->opt.max_iterations;
		double pe = 0;
		if (p && p->err_first > tol && p->err > 0 && tol > 0)
			pe = log(p->err_first / p->err) /
			     log(p->err_first / tol);
		return clamp01(pi > pe ? pi : pe);
	}
	default:
		return NAN;
	}
}

static double eta_of(const job_snap *js, const mbp_job *p, const srv_job *j,
                     double now)
{
	const job_target *t = &js->t;
	if (js->st == SRV_JOB_DONE)
		return 0;
	if (js->st != SRV_JOB_RUNNING && js->st != SRV_JOB_QUEUED)
		return NAN;
	double it = p ? p->iter_s : NAN;
	switch (t->mode) {
	case JOB_MODE_ITERATIONS:
		return t->until > js->iter ? (double)(t->until - js->iter) * it
		                           : 0;
	case JOB_MODE_SECONDS:
		if (js->st == SRV_JOB_RUNNING && js->deadline > 0)
			return js->deadline > now ? js->deadline - now : 0;
		return t->left_s;
	case JOB_MODE_CONVERGE: {
		double tol = j->opt.converge_tol;
		double left = (double)j->opt.max_iterations - js->iter;
		if (!p || !(p->err > 0) || !(tol > 0))
			return NAN;
		if (p->err <= tol)
			return 0;
		double rho = p->err / p->err_prev;
		if (!(rho > 0 && rho < 1))
			return NAN;
		double k = ceil(log(tol / p->err) / log(rho));
		double cap = left > 0 ? left : 0;
		return (k < cap ? k : cap) * it;
	}
	default:
		return NAN;
	}
}

/* Publish a job's values (I/O thread). */
static void publish_job(cmd_server *d, srv_job *j)
{
	mbp_job *p = job_record(d, j);
	job_snap js = {0};
	double now = rad_seconds();

	pthread_mutex_lock(&j->mu);
	js.st = j->state;
	js.iter = j->iteration;
	js.residual = j->residual;
	js.links = j->links;
	js.mem = srv_job_memory_locked(j);
	js.t = j->target;
	js.deadline = j->deadline;
	if (p && j->stats_json && p->stats_iter != (int64_t)j->iteration)
		js.stats = strdup(j->stats_json);
	pthread_mutex_unlock(&j->mu);
	if (p && js.stats)
		update_stats(p, js.iter, js.stats);
	free(js.stats);

	mb_job_vals v;
	mb_job_vals_init(&v, j->id);
	v.scene_id = j->scene->id;
	v.state = mb_state_of(js.st);
	v.iteration = js.iter;
	v.progress = progress_of(&js, p, j, now);
	if (js.iter > 0) {
		v.residual = js.residual;
		v.links = (int64_t)js.links;
	}
	v.error_estimate = p ? p->err : NAN;
	v.memory_bytes = js.mem;
	v.elapsed_s = p ? p->total_s : NAN;
	v.eta_s = eta_of(&js, p, j, now);
	mb_publish_job(d->mb, &v);
}

/* ------------------------------------------------------------ sensors */

typedef struct eval_task {
	srv_task t;
	uint64_t job;
	srv_sol *sol; /* ref */
	size_t n;
	char (*names)[MB_SENSOR_NAME_MAX];
	double *pts, *lux;
	int ok;
	char err[sizeof(((rad_error *)0)->msg)];
} eval_task;

static void eval_free(cmd_server *d, eval_task *e)
{
	srv *s = &d->core;
	srv_sol_unref(s, e->sol);
	free(e->names);
	free(e->pts);
	free(e->lux);
	free(e);
}

/* Lux at sensors: the call query.points makes, with the job's tolerance. */
static rad_status eval_lux(const srv_sol *sol, const double *pts, size_t n,
                           double *lux, rad_error *err)
{
	return rad_solution_query(sol->sol, pts, n, sol->query_tol,
	                          sol->solve_error, lux, NULL, err);
}

static void eval_run(srv *s, srv_task *t)
{
	eval_task *e = (eval_task *)t;
	rad_error err = {0};
	(void)s;
	e->ok = eval_lux(e->sol, e->pts, e->n, e->lux, &err) == RAD_OK;
	if (!e->ok)
		snprintf(e->err, sizeof(e->err), "%s", err.msg);
	/* the pool posts the task to the I/O thread: eval_done */
}

/* I/O thread: publish what is newer than what each sensor shows. */
static void eval_apply(cmd_server *d, eval_task *e)
{
	mbp_job *p = find_job(d, e->job);
	if (!p)
		return; /* deleted meanwhile */
	if (!e->ok) {
		srv_warn("job %llu: sensors not evaluated at iteration %u: %s",
		         (unsigned long long)e->job, e->sol->iteration, e->err);
		return;
	}
	for (size_t i = 0; i < e->n; i++) {
		cmd_sensor *x = find_sensor(p, e->names[i]);
		if (!x || x->iter >= (int64_t)e->sol->iteration)
			continue;
		x->iter = e->sol->iteration;
		x->lux = e->lux[i];
		mb_publish_sensor(d->mb, e->job, x->name, x->lux,
		                  e->sol->iteration);
	}
}

static void eval_done(srv *s, srv_task *t)
{
	cmd_server *d = cmd_of(s);
	eval_task *e = (eval_task *)t;
	eval_apply(d, e);
	eval_free(d, e);
}

/*
 * Evaluate sensors [from, p->n) of a job on its latest solution: on the
 * query pool, or on this thread when the pool is not running (startup,
 * shutdown).
 */
static void evaluate(cmd_server *d, srv_job *j, mbp_job *p, size_t from)
{
	srv *s = &d->core;
	if (!p || from >= p->n)
		return;
	pthread_mutex_lock(&j->mu);
	srv_sol *sol = j->sol;
	if (sol)
		srv_sol_ref(sol);
	pthread_mutex_unlock(&j->mu);
	if (!sol)
		return;
	size_t n = p->n - from, fresh = 0;
	for (size_t i = from; i < p->n; i++)
		fresh += p->sensors[i].iter < (int64_t)sol->iteration;
	eval_task *e = calloc(1, sizeof(*e));
	if (e) {
		e->names = malloc(n * sizeof(*e->names));
		e->pts = malloc(n * 6 * sizeof(double));
		e->lux = malloc(n * sizeof(double));
	}
	if (!e) {
		srv_sol_unref(s, sol);
		srv_warn("job %llu: out of memory evaluating sensors",
		         (unsigned long long)j->id);
		return;
	}
	e->sol = sol; /* eval_free releases it */
	if (!fresh || !e->names || !e->pts || !e->lux) {
		if (fresh)
			srv_warn("job %llu: out of memory evaluating sensors",
			         (unsigned long long)j->id);
		eval_free(d, e);
		return;
	}
	e->job = j->id;
	e->n = n;
	for (size_t i = 0; i < n; i++) {
		memcpy(e->names[i], p->sensors[from + i].name,
		       MB_SENSOR_NAME_MAX);
		memcpy(e->pts + 6 * i, p->sensors[from + i].pt,
		       6 * sizeof(double));
	}
	if (s->query_pool.threads && !d->shutting_down) {
		e->t.run = eval_run;
		e->t.done = eval_done;
		srv_pool_submit(&s->query_pool, &e->t);
		return;
	}
	rad_error err = {0};
	e->ok = eval_lux(sol, e->pts, n, e->lux, &err) == RAD_OK;
	if (!e->ok)
		snprintf(e->err, sizeof(e->err), "%s", err.msg);
	eval_apply(d, e);
	eval_free(d, e);
}

/* -------------------------------------------------------------- hooks */

/* The daemon block: memory and uptime. */
static void publish_daemon(cmd_server *d)
{
	srv *s = &d->core;
	srv_summary sum;
	srv_summarize(s, &sum);
	mb_publish_daemon(d->mb, &(mb_daemon_vals){s->t0, sum.total});
}

static double daemon_tick(el_loop *l, void *ud, double now)
{
	(void)l;
	(void)now;
	publish_daemon(ud);
	return DAEMON_TICK_S;
}

static void mb_log(void *ud, int level, const char *msg)
{
	(void)ud;
	srv_log(level <= 0   ? SRV_LOG_ERROR
	        : level == 1 ? SRV_LOG_WARN
	        : level == 2 ? SRV_LOG_INFO
	                     : SRV_LOG_DEBUG,
	        "%s", msg);
}

void cmd_mb_stop(cmd_server *d)
{
	mb_server_stop(d->mb);
	d->mb = NULL;
	if (!d->mbpub)
		return;
	while (d->mbpub->jobs) {
		mbp_job *p = d->mbpub->jobs;
		d->mbpub->jobs = p->next;
		free_job(p);
	}
	free(d->mbpub);
	d->mbpub = NULL;
}

int cmd_mb_addr_text(cmd_server *d, char *buf, size_t len)
{
	srv *s = &d->core;
	char host[300], why[200];
	int port = mb_server_port(d->mb);
	if (!d->mb || port < 0 ||
	    mb_listen_parse(s->cfg.modbus.listen, host, sizeof(host), &port,
	                    why, sizeof(why)) != 0)
		return 0;
	port = mb_server_port(d->mb);
	snprintf(buf, len,
	         strchr(host, ':') ? "modbus [%s]:%d" : "modbus %s:%d", host,
	         port);
	return 1;
}

static void on_job_added(void *ud, srv_job *j)
{
	cmd_server *d = ud;
	mbp_job *p = job_record(d, j);
	publish_job(d, j);
	for (size_t i = 0; p && i < p->n; i++)
		mb_publish_sensor(d->mb, j->id, p->sensors[i].name, NAN, 0);
	evaluate(d, j, p, 0); /* a restored job's solution */
}

static int cmp_job_id(const void *a, const void *b)
{
	uint64_t x = (*(srv_job *const *)a)->id;
	uint64_t y = (*(srv_job *const *)b)->id;
	return x < y ? -1 : x > y;
}

static void restore_sensor(void *ud, uint64_t job, const char *name,
                           const double pt[6])
{
	cmd_server *d = ud;
	srv_job *j = srv_job_find(&d->core, job);
	mbp_job *p = j ? job_record(d, j) : NULL;
	if (!p) {
		srv_warn("sensor '%s' of job %llu not restored: %s", name,
		         (unsigned long long)job,
		         j ? "out of memory" : "no such job");
		return;
	}
	if (find_sensor(p, name)) {
		srv_warn("job %llu: stored sensor '%s' duplicates one of the "
		         "scene's; the scene's is kept",
		         (unsigned long long)job, name);
		return;
	}
	if (!add_sensor(p, name, pt, 1))
		srv_warn("job %llu: out of memory for sensor '%s'",
		         (unsigned long long)job, name);
}

/* Observer: the registries are restored; the sensors added to jobs come
 * back from the store, then every job is published, in id order. */
static int on_recovered(void *ud, char *msg, size_t msglen)
{
	cmd_server *d = ud;
	srv *s = &d->core;
	size_t n = 0, k = 0;
	if (srv_store_sensor_list(s->store, restore_sensor, d, msg, msglen) !=
	    0)
		return -1;
	for (srv_job *j = s->jobs; j; j = j->next)
		n++;
	srv_job **v = n ? malloc(n * sizeof(*v)) : NULL;
	if (n && !v) {
		srv_warn("modbus: out of memory publishing restored jobs");
		return 0;
	}
	for (srv_job *j = s->jobs; j; j = j->next)
		v[k++] = j;
	if (n > 1) /* qsort's array must not be NULL, even for n = 0 */
		qsort(v, n, sizeof(*v), cmp_job_id);
	for (size_t i = 0; i < n; i++)
		on_job_added(d, v[i]);
	free(v);
	if (d->mb)
		publish_daemon(d);
	return 0;
}

static void on_job_event(void *ud, srv_job *j, const srv_event *ev)
{
	cmd_server *d = ud;
	publish_job(d, j);
	if (ev->kind == EV_ITERATION)
		evaluate(d, j, find_job(d, j->id), 0);
}

static void on_job_gone(void *ud, srv_job *j)
{
	cmd_server *d = ud;
	struct cmd_mbpub *m = d->mbpub;
	mb_job_remove(d->mb, j->id);
	for (mbp_job **pp = m ? &m->jobs : NULL; pp && *pp; pp = &(*pp)->next) {
		if ((*pp)->id == j->id) {
			mbp_job *p = *pp;
			*pp = p->next;
			free_job(p);
			break;
		}
	}
}

int cmd_mb_start(cmd_server *d, char *msg, size_t msglen)
{
	srv *s = &d->core;
	static const srv_observer ops = {.recovered = on_recovered,
	                                 .job_added = on_job_added,
	                                 .job_event = on_job_event,
	                                 .job_gone = on_job_gone};
	char why[1024] = "";
	if (!state(d) || srv_observe(s, &ops, d) != 0) {
		snprintf(msg, msglen, "modbus: out of memory");
		return -2;
	}
	if (!s->cfg.modbus.listen[0]) {
		srv_info("modbus: off (modbus_listen = none)");
		return 0;
	}
	d->mb = mb_server_start(&s->cfg.modbus, mb_log, NULL, why, sizeof(why));
	if (!d->mb) {
		snprintf(msg, msglen, "%s", why);
		return -2;
	}
	publish_daemon(d);
	if (!el_timer_add(d->loop, DAEMON_TICK_S, daemon_tick, d)) {
		snprintf(msg, msglen, "modbus: out of memory");
		return -2;
	}
	return 0;
}

json_t *cmd_mb_status_json(cmd_server *d)
{
	srv *s = &d->core;
	mb_stats st;
	json_t *o = json_object();
	mb_server_stats(d->mb, &st);
	if (!d->mb)
		st.state = MB_STATE_OFF;
	json_object_set_new(o, "state", json_string(mb_state_name(st.state)));
	json_object_set_new(o, "listen",
	                    s->cfg.modbus.listen[0]
	                            ? json_string(s->cfg.modbus.listen)
	                            : json_null());
	json_object_set_new(o, "port",
	                    d->mb && st.port >= 0 ? json_integer(st.port)
	                                          : json_null());
	json_object_set_new(o, "unit_id", json_integer(s->cfg.modbus.unit_id));
#define MB_STAT_JSON_(name, help)                                              \
	json_object_set_new(o, #name, json_integer((json_int_t)st.name));
	MB_STATS(MB_STAT_JSON_)
#undef MB_STAT_JSON_
	return o;
}

char *cmd_mb_metrics_text(cmd_server *d)
{
	mb_stats st;
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	if (!f)
		return NULL;
	mb_server_stats(d->mb, &st);
	if (!d->mb)
		st.state = MB_STATE_OFF;
	fprintf(f,
	        "# HELP luxradd_modbus_up 1 when the Modbus server is "
	        "listening.\n# TYPE luxradd_modbus_up gauge\n"
	        "luxradd_modbus_up %d\n",
	        st.state == MB_STATE_LISTENING);
	fprintf(f,
	        "# HELP luxradd_modbus_clients Modbus clients connected "
	        "now.\n# TYPE luxradd_modbus_clients gauge\n"
	        "luxradd_modbus_clients %llu\n",
	        (unsigned long long)st.clients);
#define MB_STAT_PROM_(name, help)                                              \
	if (strcmp(#name, "clients") != 0)                                     \
		fprintf(f,                                                     \
		        "# HELP luxradd_modbus_" #name "_total Modbus " help   \
		        ".\n# TYPE luxradd_modbus_" #name "_total counter\n"   \
		        "luxradd_modbus_" #name "_total %llu\n",               \
		        (unsigned long long)st.name);
	MB_STATS(MB_STAT_PROM_)
#undef MB_STAT_PROM_
	if (fclose(f) != 0) {
		free(buf);
		return NULL;
	}
	return buf;
}

/* -------------------------------------------- sensors for sensor_cmd.c */

const cmd_sensor *cmd_mb_sensors(cmd_server *d, srv_job *j, size_t *n)
{
	mbp_job *p = job_record(d, j);
	*n = p ? p->n : 0;
	return p ? p->sensors : NULL;
}

int cmd_mb_sensor_add(cmd_server *d, srv_job *j, const char *name,
                      const double pt[6], int *slot)
{
	mbp_job *p = job_record(d, j);
	if (!p)
		return -1;
	if (find_sensor(p, name))
		return -2;
	cmd_sensor *x = add_sensor(p, name, pt, 1);
	if (!x)
		return -1;
	*slot = mb_publish_sensor(d->mb, j->id, x->name, NAN, 0);
	srv_info("job %llu: sensor '%s' added (slot %d)",
	         (unsigned long long)j->id, x->name, *slot);
	evaluate(d, j, p, p->n - 1);
	return 0;
}

int cmd_mb_sensor_slot(cmd_server *d, uint64_t job, const char *name)
{
	return mb_sensor_slot(d->mb, job, name);
}
