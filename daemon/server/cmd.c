/*
 * cmd.c -- the command table and dispatch, and the session commands
 * (hello, status, shutdown).
 *
 * conn.c only decodes frames; here a frame is checked (a JSON object
 * with a known "cmd", a scalar "id", a payload only where the command
 * takes one, hello first, not shutting down), then looked up in the
 * table and run.  A handler fills r->res and returns CMD_REPLY, fills
 * r->err and returns CMD_ERROR, or arranges a later reply (a task, a job
 * waiter) and returns CMD_DEFERRED, which marks the connection busy until
 * srv_reply_deferred delivers it.  The table also counts calls and
 * errors per command (reported by status).
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "log.h"
#include "server.h"

static cmd_result cmd_hello(srv_req *r);
static cmd_result cmd_status(srv_req *r);
static cmd_result cmd_shutdown(srv_req *r);

/*
 * The handler of each command of rp.h's RP_COMMANDS.  The table is made
 * from that list, so a command added to the protocol without a line here
 * does not compile (CMD_FN_<NAME> undeclared): the table cannot have a
 * hole.
 */
#define CMD_FN_HELLO cmd_hello
#define CMD_FN_STATUS cmd_status
#define CMD_FN_SHUTDOWN cmd_shutdown
#define CMD_FN_SCENE_UPLOAD srv_cmd_scene_upload
#define CMD_FN_SCENE_LIST srv_cmd_scene_list
#define CMD_FN_SCENE_INFO srv_cmd_scene_info
#define CMD_FN_SCENE_DELETE srv_cmd_scene_delete
#define CMD_FN_JOB_CREATE srv_cmd_job_create
#define CMD_FN_JOB_LIST srv_cmd_job_list
#define CMD_FN_JOB_INFO srv_cmd_job_info
#define CMD_FN_JOB_RUN srv_cmd_job_run
#define CMD_FN_JOB_PAUSE srv_cmd_job_pause
#define CMD_FN_JOB_RESUME srv_cmd_job_resume
#define CMD_FN_JOB_CANCEL srv_cmd_job_cancel
#define CMD_FN_JOB_SET srv_cmd_job_set
#define CMD_FN_JOB_DELETE srv_cmd_job_delete
#define CMD_FN_SUBSCRIBE srv_cmd_subscribe
#define CMD_FN_UNSUBSCRIBE srv_cmd_unsubscribe
#define CMD_FN_QUERY_POINTS srv_cmd_query_points
#define CMD_FN_QUERY_GRID srv_cmd_query_grid
#define CMD_FN_QUERY_SURFACES srv_cmd_query_surfaces
#define CMD_FN_EXPORT srv_cmd_export
#define CMD_FN_SENSOR_ADD srv_cmd_sensor_add
#define CMD_FN_SENSOR_LIST srv_cmd_sensor_list

static const srv_cmd_fn cmd_table[RP_CMD_COUNT] = {
#define CMD_ROW_(name, str, payload, help) [RP_CMD_##name] = CMD_FN_##name,
        RP_COMMANDS(CMD_ROW_)
#undef CMD_ROW_
};

cmd_result srv_req_fail(srv_req *r, rp_err code, const char *fmt, ...)
{
	va_list ap;
	r->err.code = code;
	va_start(ap, fmt);
	vsnprintf(r->err.msg, sizeof(r->err.msg), fmt, ap);
	va_end(ap);
	return CMD_ERROR;
}

/*
 * Every engine status has a wire code.  The switch has no default on
 * purpose: a status added to rad.h and not mapped here is a -Wswitch
 * warning, an error in CI's -Werror build.
 */
rp_err srv_err_from_rad(rad_status st)
{
	switch (st) {
	case RAD_OK:
		return RP_ERR_OK;
	case RAD_ERR_NOMEM:
	case RAD_ERR_LIMIT:
		return RP_ERR_NOMEM;
	case RAD_ERR_INVALID:
	case RAD_ERR_UNSUPPORTED:
		return RP_ERR_INVALID;
	case RAD_ERR_STATE:
	case RAD_ERR_CANCELLED:
		return RP_ERR_STATE;
	case RAD_ERR_IO:
		return RP_ERR_IO;
	case RAD_ERR_EMBREE:
		break;
	}
	return RP_ERR_INTERNAL;
}

srv_job *srv_req_job(srv_req *r, int *failed)
{
	uint64_t id = 0;
	*failed = 1;
	if (rp_arg_u64(r->hdr, "job", 1, &id, &r->err) != 0)
		return NULL;
	srv_job *j = srv_job_find(r->s, id);
	if (!j) {
		srv_req_fail(r, RP_ERR_NOT_FOUND, "no job %llu",
		             (unsigned long long)id);
		return NULL;
	}
	*failed = 0;
	return j;
}

/* --------------------------------------------------------------- dispatch */

static int scalar(const json_t *v)
{
	return json_is_string(v) || json_is_number(v) || json_is_boolean(v) ||
	       json_is_null(v);
}

/* Check the frame before its handler runs; 0 = go on. */
static int precheck(srv *s, srv_conn *c, rp_frame *f, json_t *id,
                    const char *name, int *k)
{
	if (id && !scalar(id)) {
		srv_conn_send_error(s, c, NULL, RP_ERR_BAD_REQUEST,
		                    "\"id\" must be a string, number, boolean "
		                    "or null");
		return -1;
	}
	if (!name) {
		srv_conn_send_error(s, c, id, RP_ERR_BAD_REQUEST,
		                    "the request has no \"cmd\" string");
		return -1;
	}
	*k = rp_cmd_lookup(name);
	if (*k < 0) {
		srv_conn_send_error(s, c, id, RP_ERR_UNKNOWN_COMMAND,
		                    "unknown command \"%.64s\"", name);
		return -1;
	}
	if (s->shutting_down) {
		srv_conn_send_error(s, c, id, RP_ERR_SHUTTING_DOWN,
		                    "the daemon is shutting down");
		return -1;
	}
	if (!c->authed && *k != RP_CMD_HELLO) {
		srv_conn_send_error(s, c, id, RP_ERR_AUTH_REQUIRED,
		                    "the first request must be \"hello\"");
		return -1;
	}
	if (f->payload && !rp_cmd_takes_payload((rp_cmd)*k)) {
		srv_conn_send_error(s, c, id, RP_ERR_BAD_REQUEST,
		                    "\"%s\" takes no payload (\"bytes\")",
		                    name);
		return -1;
	}
	return 0;
}

void srv_cmd_dispatch(srv *s, srv_conn *c, rp_frame *f, size_t used)
{
	json_t *h = f->header, *id = json_object_get(h, "id");
	const char *name = json_string_value(json_object_get(h, "cmd"));
	int k = -1;

	if (precheck(s, c, f, id, name, &k) != 0)
		return;
	srv_req r = {.s = s,
	             .c = c,
	             .cmd = (rp_cmd)k,
	             .hdr = h,
	             .id = id,
	             .payload = f->payload,
	             .payload_len = f->payload_len,
	             .frame_used = used,
	             .res = json_object()};
	if (!r.res) {
		srv_conn_send_error(s, c, id, RP_ERR_NOMEM, "out of memory");
		return;
	}
	s->cmd_calls[k]++;
	cmd_result rc = cmd_table[k](&r);
	if (rc == CMD_REPLY) {
		json_t *reply = rp_reply_ok(id);
		if (!reply || json_object_update(reply, r.res) != 0)
			srv_conn_send_error(s, c, id, RP_ERR_NOMEM,
			                    "out of memory");
		else
			srv_conn_send_json(s, c, reply);
		json_decref(reply);
	} else if (rc == CMD_ERROR) {
		s->cmd_errors[k]++;
		srv_debug("connection %llu: %s: %s: %s",
		          (unsigned long long)c->id, name,
		          rp_err_name(r.err.code), r.err.msg);
		srv_conn_send_error(s, c, id, r.err.code, "%s", r.err.msg);
	} else {
		c->busy = 1;
		srv_conn_update_events(s, c);
	}
	json_decref(r.res);
}

void srv_reply_deferred(srv *s, uint64_t conn_id, json_t *reply)
{
	srv_conn *c = srv_conn_find(s, conn_id);
	if (c && reply) {
		srv_conn_send_json(s, c, reply);
		json_t *e = json_object_get(reply, "error");
		const char *code =
		        json_string_value(json_object_get(e, "code"));
		if (code && rp_err_closes(rp_err_parse(code)))
			srv_conn_close_after_flush(s, c);
	}
	json_decref(reply);
	if (c)
		srv_conn_unbusy(s, c);
}

void srv_reply_deferred_raw(srv *s, uint64_t conn_id, unsigned char *buf,
                            size_t len, unsigned char *payload, size_t plen)
{
	srv_conn *c = srv_conn_find(s, conn_id);
	if (!c) {
		free(buf);
		free(payload);
		return;
	}
	srv_conn_send(s, c, buf, len);
	if (payload)
		srv_conn_send(s, c, payload, plen);
	srv_conn_unbusy(s, c);
}

/* ---------------------------------------------------------------- session */

static json_t *limits_json(const srv *s)
{
	const srv_config *c = &s->cfg;
	json_t *o = json_object();
	json_object_set_new(o, "max_header_bytes",
	                    json_integer((json_int_t)c->max_header_bytes));
	json_object_set_new(o, "max_scene_bytes",
	                    json_integer((json_int_t)c->max_scene_bytes));
	json_object_set_new(o, "max_points", json_integer(c->max_points));
	json_object_set_new(o, "max_subscriptions",
	                    json_integer(c->max_subscriptions));
	json_object_set_new(o, "idle_timeout_s", json_real(c->idle_timeout_s));
	json_object_set_new(o, "max_connections",
	                    json_integer(c->max_connections));
	json_object_set_new(o, "max_scenes", json_integer(c->max_scenes));
	json_object_set_new(o, "max_jobs", json_integer(c->max_jobs));
	json_object_set_new(o, "max_output_bytes",
	                    json_integer((json_int_t)c->max_output_bytes));
	return o;
}

static cmd_result cmd_hello(srv_req *r)
{
	srv *s = r->s;
	srv_conn *c = r->c;
	uint64_t version = 0;
	const char *token = NULL, *client = NULL;

	if (rp_arg_u64(r->hdr, "version", 1, &version, &r->err) < 0 ||
	    rp_arg_string(r->hdr, "token", 0, &token, &r->err) < 0 ||
	    rp_arg_string(r->hdr, "client", 0, &client, &r->err) < 0)
		return CMD_ERROR;
	if (version != RP_VERSION)
		return srv_req_fail(r, RP_ERR_VERSION,
		                    "protocol version %llu is not supported "
		                    "(this daemon speaks version %d)",
		                    (unsigned long long)version, RP_VERSION);
	if (c->authed)
		return srv_req_fail(r, RP_ERR_STATE,
		                    "the session is already open (second "
		                    "hello)");
	/* A token on a connection that does not need one is ignored. */
	if (c->needs_token &&
	    (!token || !s->token ||
	     !rp_token_equal(token, strlen(token), s->token, s->token_len)))
		return srv_req_fail(r, RP_ERR_AUTH_FAILED,
		                    token ? "wrong token"
		                          : "this connection needs a token in "
		                            "hello");
	c->authed = 1;
	srv_debug("connection %llu (%s): hello from %.100s",
	          (unsigned long long)c->id, c->peer, client ? client : "?");
	json_t *caps = json_pack("[sssssss]", "scene.gltf", "scene.glb",
	                         "export.glb", "subscribe", "query.points",
	                         "query.grid", "query.surfaces");
	if (s->cfg.metrics_listen[0])
		json_array_append_new(caps, json_string("metrics"));
	json_t *solvers = json_array();
	for (int k = 0; k < RAD_SOLVER_NKINDS; k++)
		json_array_append_new(solvers, json_string(rad_solver_kind_name(
		                                       (rad_solver_kind)k)));
	json_object_set_new(r->res, "version", json_integer(RP_VERSION));
	json_object_set_new(r->res, "server",
	                    json_string(SRV_NAME "/" SRV_VERSION));
	json_object_set_new(r->res, "capabilities", caps);
	json_object_set_new(r->res, "solvers", solvers);
	json_object_set_new(r->res, "limits", limits_json(s));
	return CMD_REPLY;
}

void srv_summarize(srv *s, srv_summary *sum)
{
	memset(sum, 0, sizeof(*sum));
	for (srv_scene *sc = s->scenes; sc; sc = sc->next) {
		for (int k = 0; k < RAD_MEM_NKINDS; k++)
			sum->by_kind[k] += sc->mem.bytes[k];
		sum->scenes_bytes += sc->mem.total;
	}
	for (srv_job *j = s->jobs; j; j = j->next) {
		pthread_mutex_lock(&j->mu);
		sum->jobs_by_state[j->state]++;
		for (int k = 0; k < RAD_MEM_NKINDS; k++) {
			sum->by_kind[k] += j->solver_mem[k];
			sum->jobs_bytes += j->solver_mem[k];
		}
		pthread_mutex_unlock(&j->mu);
	}
	/* Every live solution, also one a query still reads after its job
	 * published a newer one: what the process really holds. */
	int64_t sol = atomic_load(&s->sol_bytes);
	sum->by_kind[RAD_MEM_SOLUTION] += sol;
	sum->jobs_bytes += sol;
	sum->total = sum->scenes_bytes + sum->jobs_bytes;
}

static json_t *memory_json(const srv_summary *sum)
{
	json_t *kinds = json_object(), *o = json_object();
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		json_object_set_new(kinds, rad_mem_kind_name((rad_mem_kind)k),
		                    json_integer(sum->by_kind[k]));
	json_object_set_new(o, "total_bytes", json_integer(sum->total));
	json_object_set_new(o, "by_kind", kinds);
	json_object_set_new(o, "scenes_bytes", json_integer(sum->scenes_bytes));
	json_object_set_new(o, "jobs_bytes", json_integer(sum->jobs_bytes));
	return o;
}

static json_t *commands_json(const srv *s)
{
	json_t *cmds = json_object();
	for (int k = 0; k < RP_CMD_COUNT; k++) {
		if (!s->cmd_calls[k])
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "calls",
		                    json_integer((json_int_t)s->cmd_calls[k]));
		json_object_set_new(o, "errors",
		                    json_integer((json_int_t)s->cmd_errors[k]));
		json_object_set_new(cmds, rp_cmd_name((rp_cmd)k), o);
	}
	return cmds;
}

static cmd_result cmd_status(srv_req *r)
{
	srv *s = r->s;
	srv_summary sum;
	json_t *jobs = json_object(), *scenes = json_array();
	json_t *jlist = json_array();

	srv_summarize(s, &sum);
	for (int k = 0; k < SRV_JOB_NSTATES; k++)
		json_object_set_new(jobs, srv_job_state_name((srv_job_state)k),
		                    json_integer(sum.jobs_by_state[k]));
	for (srv_scene *sc = s->scenes; sc; sc = sc->next) {
		json_t *o = json_object();
		json_object_set_new(o, "id", json_integer((json_int_t)sc->id));
		json_object_set_new(o, "name", json_string(sc->name));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(sc->mem.total));
		json_array_append_new(scenes, o);
	}
	for (srv_job *j = s->jobs; j; j = j->next) {
		json_t *o = json_object();
		pthread_mutex_lock(&j->mu);
		json_object_set_new(o, "id", json_integer((json_int_t)j->id));
		json_object_set_new(o, "state",
		                    json_string(srv_job_state_name(j->state)));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(srv_job_memory_locked(j)));
		pthread_mutex_unlock(&j->mu);
		json_array_append_new(jlist, o);
	}
	json_object_set_new(r->res, "version", json_integer(RP_VERSION));
	json_object_set_new(r->res, "server",
	                    json_string(SRV_NAME "/" SRV_VERSION));
	json_object_set_new(r->res, "uptime_s",
	                    json_real(rad_seconds() - s->t0));
	json_object_set_new(r->res, "connections", json_integer(s->nconns));
	json_object_set_new(r->res, "jobs", jobs);
	json_object_set_new(r->res, "memory", memory_json(&sum));
	json_object_set_new(r->res, "scenes", scenes);
	/* PROTOCOL.md's example also names this list "jobs", which the
	 * counts by state already are: a JSON object cannot hold both. */
	json_object_set_new(r->res, "job_list", jlist);
	json_object_set_new(r->res, "limits", limits_json(s));
	json_object_set_new(r->res, "commands", commands_json(s));
	json_object_set_new(r->res, "events_dropped",
	                    json_integer((json_int_t)s->events_dropped));
	json_object_set_new(r->res, "slow_consumers",
	                    json_integer((json_int_t)s->slow_consumers));
	json_object_set_new(r->res, "modbus", srv_mb_status_json(s));
	return CMD_REPLY;
}

static cmd_result cmd_shutdown(srv_req *r)
{
	srv_info("shutdown requested by connection %llu (%s)",
	         (unsigned long long)r->c->id, r->c->peer);
	/* Only raises flags and closes the listeners: the reply {} goes
	 * out as usual, the loop does the rest. */
	srv_begin_shutdown(r->s, "shutdown command");
	return CMD_REPLY;
}
