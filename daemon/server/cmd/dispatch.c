/*
 * dispatch.c -- the command table and dispatch, and the session commands
 * (hello, status, shutdown).
 *
 * conn.c only decodes frames; here a frame is checked (a JSON object
 * with a known "cmd", a scalar "id", a payload only where the command
 * takes one, hello first, not shutting down), then looked up in the
 * table and run.  A handler fills r->res and returns CMD_REPLY, fills
 * r->err and returns CMD_ERROR, or arranges a later reply (a task, a job
 * waiter) and returns CMD_DEFERRED, which marks the connection busy until
 * cmd_reply_deferred delivers it.  The table also counts calls and
 * errors per command (reported by status).
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "log.h"

static cmd_result cmd_hello(cmd_req *r);
static cmd_result cmd_status(cmd_req *r);
static cmd_result cmd_shutdown(cmd_req *r);

/*
 * The handler of each command of rp.h's RP_COMMANDS.  The table is made
 * from that list, so a command added to the protocol without a line here
 * does not compile (CMD_FN_<NAME> undeclared): the table cannot have a
 * hole.
 */
#define CMD_FN_HELLO cmd_hello
#define CMD_FN_STATUS cmd_status
#define CMD_FN_SHUTDOWN cmd_shutdown
#define CMD_FN_SCENE_UPLOAD cmd_scene_upload
#define CMD_FN_SCENE_LIST cmd_scene_list
#define CMD_FN_SCENE_INFO cmd_scene_info
#define CMD_FN_SCENE_DELETE cmd_scene_delete
#define CMD_FN_JOB_CREATE cmd_job_create
#define CMD_FN_JOB_LIST cmd_job_list
#define CMD_FN_JOB_INFO cmd_job_info
#define CMD_FN_JOB_RUN cmd_job_run
#define CMD_FN_JOB_PAUSE cmd_job_pause
#define CMD_FN_JOB_RESUME cmd_job_resume
#define CMD_FN_JOB_CANCEL cmd_job_cancel
#define CMD_FN_JOB_SET cmd_job_set
#define CMD_FN_JOB_DELETE cmd_job_delete
#define CMD_FN_SUBSCRIBE cmd_subscribe
#define CMD_FN_UNSUBSCRIBE cmd_unsubscribe
#define CMD_FN_QUERY_POINTS cmd_query_points
#define CMD_FN_QUERY_GRID cmd_query_grid
#define CMD_FN_QUERY_SURFACES cmd_query_surfaces
#define CMD_FN_QUERY_NODE cmd_query_node
#define CMD_FN_EXPORT cmd_export
#define CMD_FN_SENSOR_ADD cmd_sensor_add
#define CMD_FN_SENSOR_LIST cmd_sensor_list

static const cmd_fn cmd_table[RP_CMD_COUNT] = {
#define CMD_ROW_(name, str, payload, role, help)                               \
	[RP_CMD_##name] = CMD_FN_##name,
        RP_COMMANDS(CMD_ROW_)
#undef CMD_ROW_
};

/* --------------------------------------------------------------- dispatch */

static int scalar(const json_t *v)
{
	return json_is_string(v) || json_is_number(v) || json_is_boolean(v) ||
	       json_is_null(v);
}

/* Check the frame before its handler runs; 0 = go on. */
static int precheck(cmd_server *d, cmd_conn *c, rp_frame *f, json_t *id,
                    const char *name, int *k)
{
	if (id && !scalar(id)) {
		cmd_conn_send_error(d, c, NULL, RP_ERR_BAD_REQUEST,
		                    "\"id\" must be a string, number, boolean "
		                    "or null");
		return -1;
	}
	if (!name) {
		cmd_conn_send_error(d, c, id, RP_ERR_BAD_REQUEST,
		                    "the request has no \"cmd\" string");
		return -1;
	}
	*k = rp_cmd_lookup(name);
	if (*k < 0) {
		cmd_conn_send_error(d, c, id, RP_ERR_UNKNOWN_COMMAND,
		                    "unknown command \"%.64s\"", name);
		return -1;
	}
	if (d->shutting_down || d->shutdown_asked) {
		cmd_conn_send_error(d, c, id, RP_ERR_SHUTTING_DOWN,
		                    "the daemon is shutting down");
		return -1;
	}
	if (!c->authed && *k != RP_CMD_HELLO) {
		cmd_conn_send_error(d, c, id, RP_ERR_AUTH_REQUIRED,
		                    "the first request must be \"hello\"");
		return -1;
	}
	if (c->authed && rp_cmd_role((rp_cmd)*k) > c->role) {
		cmd_conn_send_error(
		        d, c, id, RP_ERR_FORBIDDEN,
		        "\"%s\" needs the role %s; this "
		        "connection's user %s%s%s has the role %s",
		        name, rp_role_name(rp_cmd_role((rp_cmd)*k)),
		        c->user[0] ? "'" : "", c->user[0] ? c->user : "(local)",
		        c->user[0] ? "'" : "", rp_role_name(c->role));
		return -1;
	}
	if (f->payload && !rp_cmd_takes_payload((rp_cmd)*k)) {
		cmd_conn_send_error(d, c, id, RP_ERR_BAD_REQUEST,
		                    "\"%s\" takes no payload (\"bytes\")",
		                    name);
		return -1;
	}
	return 0;
}

void cmd_dispatch(cmd_server *d, cmd_conn *c, rp_frame *f, size_t used)
{
	srv *s = &d->core;
	json_t *h = f->header, *id = json_object_get(h, "id");
	const char *name = json_string_value(json_object_get(h, "cmd"));
	int k = -1;

	if (precheck(d, c, f, id, name, &k) != 0)
		return;
	cmd_req r = {.d = d,
	             .s = s,
	             .c = c,
	             .cmd = (rp_cmd)k,
	             .hdr = h,
	             .id = id,
	             .payload = f->payload,
	             .payload_len = f->payload_len,
	             .frame_used = used,
	             .res = json_object()};
	if (!r.res) {
		cmd_conn_send_error(d, c, id, RP_ERR_NOMEM, "out of memory");
		return;
	}
	d->cmd_calls[k]++;
	cmd_result rc = cmd_table[k](&r);
	if (rc == CMD_REPLY) {
		json_t *reply = rp_reply_ok(id);
		if (!reply || json_object_update(reply, r.res) != 0)
			cmd_conn_send_error(d, c, id, RP_ERR_NOMEM,
			                    "out of memory");
		else
			cmd_conn_send_json(d, c, reply);
		json_decref(reply);
	} else if (rc == CMD_ERROR) {
		d->cmd_errors[k]++;
		srv_debug("connection %llu: %s: %s: %s",
		          (unsigned long long)c->id, name,
		          rp_err_name(r.err.code), r.err.msg);
		cmd_conn_send_error(d, c, id, r.err.code, "%s", r.err.msg);
	} else {
		c->busy = 1;
		cmd_conn_update_events(d, c);
	}
	json_decref(r.res);
}

/* ---------------------------------------------------------------- session */

static json_t *limits_json(const cmd_server *d)
{
	const srv *s = &d->core;
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
	json_object_set_new(o, "max_connections_per_address",
	                    json_integer(c->max_connections_per_address));
	json_object_set_new(o, "hello_timeout_s",
	                    json_real(c->hello_timeout_s));
	json_object_set_new(o, "header_timeout_s",
	                    json_real(c->header_timeout_s));
	json_object_set_new(o, "max_scenes", json_integer(c->max_scenes));
	json_object_set_new(o, "max_jobs", json_integer(c->max_jobs));
	json_object_set_new(o, "max_output_bytes",
	                    json_integer((json_int_t)c->max_output_bytes));
	json_object_set_new(o, "memory_limit", json_integer(s->mem_limit));
	return o;
}

static cmd_result cmd_hello(cmd_req *r)
{
	cmd_server *d = r->d;
	srv *s = r->s;
	cmd_conn *c = r->c;
	uint64_t version = 0;
	const char *token = NULL, *client = NULL;

	if (rp_arg_u64(r->hdr, "version", 1, &version, &r->err) < 0 ||
	    rp_arg_string(r->hdr, "token", 0, &token, &r->err) < 0 ||
	    rp_arg_string(r->hdr, "client", 0, &client, &r->err) < 0)
		return CMD_ERROR;
	if (version != RP_VERSION)
		return cmd_req_fail(r, RP_ERR_VERSION,
		                    "protocol version %llu is not supported "
		                    "(this daemon speaks version %d)",
		                    (unsigned long long)version, RP_VERSION);
	if (c->authed)
		return cmd_req_fail(r, RP_ERR_STATE,
		                    "the session is already open (second "
		                    "hello)");
	/* A token names a user (users.c) or is the shared token_file
	 * secret (the admin); without one, a connection that needs none is
	 * the local admin.  With neither users nor a token configured, a
	 * token is ignored. */
	const cmd_user *u = token ? cmd_users_check(d, token) : NULL;
	int shared =
	        token && d->token &&
	        rp_token_equal(token, strlen(token), d->token, d->token_len);
	int checked = d->users_on || d->token;
	if (token && checked && !u && !shared)
		return cmd_req_fail(r, RP_ERR_AUTH_FAILED, "wrong token");
	if (!token && c->needs_token)
		return cmd_req_fail(r, RP_ERR_AUTH_FAILED,
		                    "this connection needs a token in hello");
	snprintf(c->user, sizeof(c->user), "%s", u ? u->name : "");
	c->role = u ? u->role : RP_ROLE_ADMIN;
	c->authed = 1;
	srv_debug("connection %llu (%s): hello from %.100s as %s (%s)",
	          (unsigned long long)c->id, c->peer, client ? client : "?",
	          c->user[0] ? c->user : "the local admin",
	          rp_role_name(c->role));
	json_t *caps = json_pack("[ssssssss]", "scene.gltf", "scene.glb",
	                         "export.glb", "subscribe", "query.points",
	                         "query.grid", "query.surfaces", "query.node");
	if (s->cfg.metrics_listen[0])
		json_array_append_new(caps, json_string("metrics"));
	json_t *solvers = json_array();
	for (int k = 0; k < RAD_SOLVER_NKINDS; k++)
		json_array_append_new(solvers, json_string(rad_solver_kind_name(
		                                       (rad_solver_kind)k)));
	json_object_set_new(r->res, "user",
	                    json_pack("{s:s, s:s}", "name", c->user, "role",
	                              rp_role_name(c->role)));
	json_object_set_new(r->res, "version", json_integer(RP_VERSION));
	json_object_set_new(r->res, "server",
	                    json_string(SRV_NAME "/" SRV_VERSION));
	json_object_set_new(r->res, "capabilities", caps);
	json_object_set_new(r->res, "solvers", solvers);
	json_object_set_new(r->res, "limits", limits_json(d));
	return CMD_REPLY;
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

static json_t *commands_json(const cmd_server *d)
{
	json_t *cmds = json_object();
	for (int k = 0; k < RP_CMD_COUNT; k++) {
		if (!d->cmd_calls[k])
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "calls",
		                    json_integer((json_int_t)d->cmd_calls[k]));
		json_object_set_new(o, "errors",
		                    json_integer((json_int_t)d->cmd_errors[k]));
		json_object_set_new(cmds, rp_cmd_name((rp_cmd)k), o);
	}
	return cmds;
}

static cmd_result cmd_status(cmd_req *r)
{
	cmd_server *d = r->d;
	srv *s = r->s;
	srv_summary sum;
	json_t *jobs = json_object(), *scenes = json_array();
	json_t *jlist = json_array();

	srv_summarize(s, &sum);
	for (int k = 0; k < SRV_JOB_NSTATES; k++)
		json_object_set_new(jobs, srv_job_state_name((srv_job_state)k),
		                    json_integer(sum.jobs_by_state[k]));
	/* The lists show what this connection may see; the counts and
	 * the memory are the daemon's. */
	for (srv_scene *sc = s->scenes; sc; sc = sc->next) {
		if (!cmd_visible(r->c, sc->owner))
			continue;
		json_t *o = json_object();
		json_object_set_new(o, "id", json_integer((json_int_t)sc->id));
		json_object_set_new(o, "name", json_string(sc->name));
		json_object_set_new(o, "memory_bytes",
		                    json_integer(sc->mem.total));
		json_array_append_new(scenes, o);
	}
	for (srv_job *j = s->jobs; j; j = j->next) {
		if (!cmd_visible(r->c, j->owner))
			continue;
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
	json_object_set_new(r->res, "connections", json_integer(d->nconns));
	json_object_set_new(r->res, "jobs", jobs);
	json_object_set_new(r->res, "memory", memory_json(&sum));
	json_object_set_new(r->res, "scenes", scenes);
	/* PROTOCOL.md's example also names this list "jobs", which the
	 * counts by state already are: a JSON object cannot hold both. */
	json_object_set_new(r->res, "job_list", jlist);
	json_object_set_new(r->res, "limits", limits_json(d));
	json_object_set_new(r->res, "commands", commands_json(d));
	json_object_set_new(r->res, "events_dropped",
	                    json_integer((json_int_t)d->events_dropped));
	json_object_set_new(r->res, "slow_consumers",
	                    json_integer((json_int_t)d->slow_consumers));
	json_object_set_new(r->res, "modbus", cmd_mb_status_json(d));
	return CMD_REPLY;
}

static cmd_result cmd_shutdown(cmd_req *r)
{
	srv_info("shutdown requested by connection %llu (%s)",
	         (unsigned long long)r->c->id, r->c->peer);
	/* The reply {} goes out as usual; the end of this loop turn starts
	 * the shutdown (server.c), and no later frame is run. */
	r->d->shutdown_asked = "shutdown command";
	return CMD_REPLY;
}
