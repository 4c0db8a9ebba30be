/*
 * job_reply.c -- replies the job commands owe until something happens:
 * until a worker has stopped (job.pause and job.cancel of a running job
 * answer once it has), until the job's row is written (every control
 * command), until the row is removed (job.delete).
 *
 * Waiters are the command layer's: a list on the I/O thread, answered by
 * an observer of the core when the job's state changes or the job goes.
 * A connection is named by its id, never by pointer: it may be gone when
 * the reply is ready, and the reply is then dropped.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "log.h"

/* ----------------------------------------------------------------- waiters */

struct cmd_waiter {
	cmd_waiter *next;
	uint64_t job;
	uint64_t conn_id;
	json_t *id; /* request id (ref) */
};

int cmd_job_add_waiter(cmd_server *d, srv_job *j, uint64_t conn_id, json_t *id)
{
	cmd_waiter *w = calloc(1, sizeof(*w));
	if (!w)
		return -1;
	w->job = j->id;
	w->conn_id = conn_id;
	w->id = json_incref(id);
	w->next = d->waiters;
	d->waiters = w;
	return 0;
}

/* Answer the job's waiters once no worker holds it. */
static void complete_waiters(cmd_server *d, srv_job *j)
{
	pthread_mutex_lock(&j->mu);
	int held = j->on_worker;
	srv_job_state st = j->state;
	pthread_mutex_unlock(&j->mu);
	if (held)
		return;
	cmd_waiter **pp = &d->waiters;
	while (*pp) {
		cmd_waiter *w = *pp;
		if (w->job != j->id) {
			pp = &w->next;
			continue;
		}
		*pp = w->next;
		json_t *reply = rp_reply_ok(w->id);
		json_object_set_new(reply, "job",
		                    json_integer((json_int_t)j->id));
		json_object_set_new(reply, "state",
		                    json_string(srv_job_state_name(st)));
		cmd_reply_deferred(d, w->conn_id, reply);
		json_decref(w->id);
		free(w);
	}
}

static void on_job_event(void *ud, srv_job *j, const srv_event *ev)
{
	if (ev->kind == EV_STATE)
		complete_waiters(ud, j);
}

static void on_job_gone(void *ud, srv_job *j)
{
	complete_waiters(ud, j);
}

int cmd_waiters_start(cmd_server *d)
{
	static const srv_observer ops = {.job_event = on_job_event,
	                                 .job_gone = on_job_gone};
	return srv_observe(&d->core, &ops, d);
}

void cmd_waiters_free_all(cmd_server *d)
{
	while (d->waiters) {
		cmd_waiter *w = d->waiters;
		d->waiters = w->next;
		json_decref(w->id);
		free(w);
	}
}

/* ------------------------------------------ after the row is written */

typedef struct persist_task {
	srv_task t;
	srv_job *job; /* ref */
	json_t *reply;
	srv_runner *drop; /* a cancelled job's solver, freed here */
} persist_task;

static void persist_run(srv *s, srv_task *t)
{
	persist_task *p = (persist_task *)t;
	char msg[512];
	srv_runner_free(p->drop);
	p->drop = NULL;
	if (srv_job_persist(s, p->job, NULL, -1, msg, sizeof(msg)) != 0) {
		srv_error("job %llu: cannot record the change: %s",
		          (unsigned long long)p->job->id, msg);
		json_decref(p->reply);
		p->reply =
		        rp_reply_error(t->id, RP_ERR_IO,
		                       "the change was made but could not be "
		                       "recorded: %s",
		                       msg);
	}
}

static void persist_done(srv *s, srv_task *t)
{
	persist_task *p = (persist_task *)t;
	srv_job_unref(s, p->job);
	cmd_task_reply(s, t, p->reply);
}

cmd_result cmd_persist_then_reply(cmd_req *r, srv_job *j, json_t *reply)
{
	srv *s = r->s;
	persist_task *p = calloc(1, sizeof(*p));
	if (!p || !reply) {
		free(p);
		json_decref(reply);
		return cmd_req_fail(r, RP_ERR_NOMEM,
		                    "out of memory (the change stands in "
		                    "memory but is not recorded yet)");
	}
	srv_job_ref(j);
	p->job = j;
	p->reply = reply;
	p->drop = srv_job_detach_solver(j);
	return cmd_req_defer(r, &s->store_pool, &p->t, persist_run,
	                     persist_done);
}

/* ------------------------------------------------------------ job.delete */

typedef struct delete_task {
	srv_task t;
	srv_job *job; /* the registry's ref, released here */
	int failed;
	char msg[512];
} delete_task;

static void delete_run(srv *s, srv_task *t)
{
	delete_task *dt = (delete_task *)t;
	dt->failed =
	        srv_job_store_remove(s, dt->job, dt->msg, sizeof(dt->msg)) != 0;
	/* Frees the solver here, off the I/O thread, unless a query still
	 * holds the solution (then only that is kept until it ends). */
	srv_job_unref(s, dt->job);
	dt->job = NULL;
}

static void delete_done(srv *s, srv_task *t)
{
	delete_task *dt = (delete_task *)t;
	json_t *reply = dt->failed ? rp_reply_error(t->id, RP_ERR_IO,
	                                            "the job was freed but its "
	                                            "row could not be removed: "
	                                            "%s",
	                                            dt->msg)
	                           : rp_reply_ok(t->id);
	cmd_task_reply(s, t, reply);
}

cmd_result cmd_job_delete_then_reply(cmd_req *r, srv_job *j)
{
	delete_task *dt = calloc(1, sizeof(*dt));
	if (!dt)
		return cmd_req_fail(r, RP_ERR_NOMEM, "out of memory");
	dt->job = j;
	return cmd_req_defer(r, &r->s->store_pool, &dt->t, delete_run,
	                     delete_done);
}
