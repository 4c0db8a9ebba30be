/*
 * reply.c -- what every command handler shares: failing a request,
 * mapping an engine status to a wire code, finding the job a request
 * names, and delivering a reply that was deferred (a task or a waiter
 * finished) to a connection that may be gone by then.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "cmd.h"

cmd_result cmd_req_fail(cmd_req *r, rp_err code, const char *fmt, ...)
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
rp_err cmd_err_from_rad(rad_status st)
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

srv_job *cmd_req_job(cmd_req *r, int *failed)
{
	uint64_t id = 0;
	*failed = 1;
	if (rp_arg_u64(r->hdr, "job", 1, &id, &r->err) != 0)
		return NULL;
	/* Another user's job is as absent as one that never was. */
	srv_job *j = srv_job_find(r->s, id);
	if (!j || !cmd_visible(r->c, j->owner)) {
		cmd_req_fail(r, RP_ERR_NOT_FOUND, "no job %llu",
		             (unsigned long long)id);
		return NULL;
	}
	*failed = 0;
	return j;
}

srv_scene *cmd_find_scene(cmd_req *r, uint64_t id)
{
	/* Another user's scene is as absent as one that never was. */
	srv_scene *sc = srv_scene_find(r->s, id);
	if (!sc || !cmd_visible(r->c, sc->owner)) {
		cmd_req_fail(r, RP_ERR_NOT_FOUND, "no scene %llu",
		             (unsigned long long)id);
		return NULL;
	}
	return sc;
}

srv_scene *cmd_req_scene(cmd_req *r)
{
	uint64_t id = 0;
	if (rp_arg_u64(r->hdr, "scene", 1, &id, &r->err) != 0)
		return NULL;
	return cmd_find_scene(r, id);
}

void cmd_reply_deferred(cmd_server *d, uint64_t conn_id, json_t *reply)
{
	cmd_conn *c = cmd_conn_find(d, conn_id);
	if (c && reply) {
		cmd_conn_send_json(d, c, reply);
		json_t *e = json_object_get(reply, "error");
		const char *code =
		        json_string_value(json_object_get(e, "code"));
		if (code && rp_err_closes(rp_err_parse(code)))
			cmd_conn_close_after_flush(d, c);
	}
	json_decref(reply);
	if (c)
		cmd_conn_unbusy(d, c);
}

void cmd_reply_deferred_raw(cmd_server *d, uint64_t conn_id, unsigned char *buf,
                            size_t len, unsigned char *payload, size_t plen)
{
	cmd_conn *c = cmd_conn_find(d, conn_id);
	if (!c) {
		free(buf);
		free(payload);
		return;
	}
	cmd_conn_send(d, c, buf, len);
	if (payload)
		cmd_conn_send(d, c, payload, plen);
	cmd_conn_unbusy(d, c);
}

cmd_result cmd_req_defer(cmd_req *r, srv_pool *pool, srv_task *t,
                         void (*run)(srv *s, srv_task *t),
                         void (*done)(srv *s, srv_task *t))
{
	t->run = run;
	t->done = done;
	t->conn_id = r->c->id;
	t->id = json_incref(r->id);
	srv_pool_submit(pool, t);
	return CMD_DEFERRED;
}

void cmd_task_reply(srv *s, srv_task *t, json_t *reply)
{
	cmd_reply_deferred(cmd_of(s), t->conn_id, reply);
	json_decref(t->id);
	free(t);
}

int cmd_req_memory_full(cmd_req *r)
{
	char why[320];
	if (!srv_memory_full(r->s, why, sizeof(why)))
		return 0;
	cmd_req_fail(r, RP_ERR_NOMEM, "%s", why);
	return 1;
}
