/*
 * publish.c -- events to subscribers: subscribe / unsubscribe, the
 * fan-out of events posted by workers, the drop policy.
 *
 * Runs on the I/O thread only, as an observer of the core (core/observe.c):
 * each job event is encoded here once and copied into the output queue
 * of every connection subscribed to the job, under the drop policy
 * (core/service.c, DESIGN): a progress event that would take a queue past
 * max_output_bytes is dropped and counted on the subscription; an
 * iteration or state event that does not fit closes the connection with
 * slow_consumer.  The next iteration event delivered carries
 * "dropped_progress": n.
 *
 * Ordering: state events carry the job's state_seq.  The I/O thread
 * reports its own state changes at once; a worker's change still in
 * the inbox when the I/O thread has reported a later one is stale
 * (not fresh) and skipped.  A subscription remembers the state_seq and
 * iteration that its subscribe reply reported, and gets only events after
 * those, so a client neither misses nor repeats a transition.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cmd.h"
#include "engine_json.h"
#include "log.h"

static cmd_sub *find_sub(cmd_conn *c, uint64_t job)
{
	for (int i = 0; i < c->nsubs; i++)
		if (c->subs[i].job == job)
			return &c->subs[i];
	return NULL;
}

/* The iteration event with "dropped_progress": n spliced in before the
 * closing brace of the header. */
static unsigned char *splice_dropped(const unsigned char *data, size_t len,
                                     uint64_t n, size_t *out_len)
{
	char extra[48];
	int k = snprintf(extra, sizeof(extra), ",\"dropped_progress\":%llu}\n",
	                 (unsigned long long)n);
	if (len < 2 || data[len - 2] != '}' || data[len - 1] != '\n')
		return NULL;
	unsigned char *b = malloc(len - 2 + (size_t)k);
	if (!b)
		return NULL;
	memcpy(b, data, len - 2);
	memcpy(b + len - 2, extra, (size_t)k);
	*out_len = len - 2 + (size_t)k;
	return b;
}

/* Queue one event on one subscribed connection, applying the policy. */
static void deliver(cmd_server *d, cmd_conn *c, cmd_sub *sub, ev_kind ev,
                    const unsigned char *data, size_t len)
{
	srv *s = &d->core;
	unsigned char *b = NULL;
	size_t blen = len;

	if (ev == EV_ITERATION && sub->dropped > 0)
		b = splice_dropped(data, len, sub->dropped, &blen);
	if (c->out_bytes + blen > s->cfg.max_output_bytes) {
		free(b);
		if (ev == EV_PROGRESS) {
			sub->dropped++;
			d->events_dropped++;
			return;
		}
		d->slow_consumers++;
		size_t queued = c->out_bytes;
		cmd_conn_drop_queued(c); /* closing: the error goes next */
		cmd_conn_send_error(d, c, NULL, RP_ERR_SLOW_CONSUMER,
		                    "events for job %llu do not fit in the "
		                    "output queue (%zu bytes queued, limit "
		                    "%zu): read faster",
		                    (unsigned long long)sub->job, queued,
		                    s->cfg.max_output_bytes);
		return;
	}
	if (!b) {
		b = malloc(len);
		if (!b) {
			c->dead = 1;
			return;
		}
		memcpy(b, data, len);
	} else {
		sub->dropped = 0;
	}
	cmd_conn_send(d, c, b, blen);
}

static void fan_out(cmd_server *d, uint64_t job, ev_kind ev,
                    const unsigned char *data, size_t len, uint64_t seq,
                    uint32_t iter)
{
	for (cmd_conn *c = d->conns; c; c = c->next) {
		if (c->dead || c->closing)
			continue;
		cmd_sub *sub = find_sub(c, job);
		if (!sub)
			continue;
		if (ev == EV_STATE && seq <= sub->seq0)
			continue;
		if (ev == EV_ITERATION && iter <= sub->iter0)
			continue;
		deliver(d, c, sub, ev, data, len);
	}
}

/* The event's frame: the protocol's event header, encoded once. */
static int encode(const srv_event *ev, unsigned char **data, size_t *len)
{
	static const char *const names[] = {"progress", "iteration", "state"};
	json_t *h = json_object();
	json_object_set_new(h, "event", json_string(names[ev->kind]));
	json_object_set_new(h, "job", json_integer((json_int_t)ev->job));
	switch (ev->kind) {
	case EV_PROGRESS:
		json_object_set_new(h, "iteration",
		                    json_integer(ev->iteration));
		json_object_set_new(h, "fraction", ej_real(ev->fraction));
		json_object_set_new(h, "elapsed_s", json_real(ev->elapsed_s));
		break;
	case EV_ITERATION:
		json_object_set_new(h, "stats", ej_stats(&ev->stats));
		break;
	case EV_STATE:
		json_object_set_new(h, "state",
		                    json_string(srv_job_state_name(ev->state)));
		if (ev->state == SRV_JOB_FAILED && ev->error[0])
			json_object_set_new(h, "error", json_string(ev->error));
		break;
	}
	int rc = rp_frame_encode(h, NULL, 0, data, len);
	json_decref(h);
	return rc;
}

/* Observer: a job event reached the I/O thread. */
static void on_job_event(void *ud, srv_job *j, const srv_event *ev)
{
	cmd_server *d = ud;
	(void)j;
	unsigned char *data;
	size_t len;

	if ((ev->kind != EV_STATE || ev->fresh) &&
	    encode(ev, &data, &len) == 0) {
		fan_out(d, ev->job, ev->kind, data, len, ev->seq,
		        ev->kind == EV_ITERATION ? ev->iteration : 0);
		free(data);
	} else if (ev->kind != EV_STATE || ev->fresh) {
		srv_warn("job %llu: out of memory encoding an event",
		         (unsigned long long)ev->job);
	}
}

/* Observer: a job was deleted; its subscriptions end. */
static void on_job_gone(void *ud, srv_job *j)
{
	cmd_server *d = ud;
	for (cmd_conn *c = d->conns; c; c = c->next) {
		cmd_sub *sub = find_sub(c, j->id);
		if (sub) {
			*sub = c->subs[c->nsubs - 1];
			c->nsubs--;
		}
	}
}

int cmd_subs_start(cmd_server *d)
{
	srv *s = &d->core;
	static const srv_observer ops = {.job_event = on_job_event,
	                                 .job_gone = on_job_gone};
	return srv_observe(s, &ops, d);
}

/* ------------------------------------------------------------- commands */

cmd_result cmd_subscribe(cmd_req *r)
{
	cmd_conn *c = r->c;
	int failed;
	srv_job *j = cmd_req_job(r, &failed);
	if (failed)
		return CMD_ERROR;
	cmd_sub *sub = find_sub(c, j->id);
	if (!sub) {
		if (c->nsubs >= r->s->cfg.max_subscriptions)
			return cmd_req_fail(r, RP_ERR_LIMIT,
			                    "max_subscriptions (%d) reached on "
			                    "this connection",
			                    r->s->cfg.max_subscriptions);
		if (c->nsubs == c->subs_cap) {
			int cap = c->subs_cap ? 2 * c->subs_cap : 4;
			cmd_sub *ns =
			        realloc(c->subs, (size_t)cap * sizeof(*ns));
			if (!ns)
				return cmd_req_fail(r, RP_ERR_NOMEM,
				                    "out of memory");
			c->subs = ns;
			c->subs_cap = cap;
		}
		sub = &c->subs[c->nsubs++];
		memset(sub, 0, sizeof(*sub));
		sub->job = j->id;
	}
	pthread_mutex_lock(&j->mu);
	sub->seq0 = j->state_seq;
	sub->iter0 = j->iteration;
	json_object_set_new(r->res, "job", json_integer((json_int_t)j->id));
	json_object_set_new(r->res, "state",
	                    json_string(srv_job_state_name(j->state)));
	json_object_set_new(r->res, "iteration", json_integer(j->iteration));
	pthread_mutex_unlock(&j->mu);
	return CMD_REPLY;
}

cmd_result cmd_unsubscribe(cmd_req *r)
{
	uint64_t id = 0;
	if (rp_arg_u64(r->hdr, "job", 1, &id, &r->err) != 0)
		return CMD_ERROR;
	cmd_sub *sub = find_sub(r->c, id);
	if (sub) {
		*sub = r->c->subs[r->c->nsubs - 1];
		r->c->nsubs--;
	}
	return CMD_REPLY;
}
