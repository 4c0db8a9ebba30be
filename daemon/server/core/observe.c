/*
 * observe.c -- the core's observers: who is told when jobs come, change
 * and go, and the events workers post for them.
 *
 * The core encodes nothing for the outside world.  Front ends (the
 * subscriptions of the command layer, the Modbus glue) register a table
 * of callbacks at startup (srv_observe) and are called on the I/O thread,
 * in the order they registered, with the job and the event's data.
 *
 * Workers post events through the inbox (srv_event_post); the I/O thread
 * also reports its own state changes at once (srv_job_state_changed).
 * State events carry the job's state_seq: one older than a state already
 * reported (a worker's change still in the inbox when the I/O thread
 * reported a later one) reaches observers with fresh = 0.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "core.h"
#include "log.h"

int srv_observe(srv *s, const srv_observer *ops, void *ud)
{
	if (s->nobs == SRV_MAX_OBSERVERS)
		return -1;
	s->obs[s->nobs].ops = ops;
	s->obs[s->nobs].ud = ud;
	s->nobs++;
	return 0;
}

int srv_observers_recovered(srv *s, char *msg, size_t msglen)
{
	s->live = 1;
	for (int i = 0; i < s->nobs; i++)
		if (s->obs[i].ops->recovered &&
		    s->obs[i].ops->recovered(s->obs[i].ud, msg, msglen) != 0)
			return -1;
	return 0;
}

void srv_job_added(srv *s, srv_job *j)
{
	for (int i = 0; s->live && i < s->nobs; i++)
		if (s->obs[i].ops->job_added)
			s->obs[i].ops->job_added(s->obs[i].ud, j);
}

void srv_job_gone(srv *s, srv_job *j)
{
	for (int i = 0; i < s->nobs; i++)
		if (s->obs[i].ops->job_gone)
			s->obs[i].ops->job_gone(s->obs[i].ud, j);
}

void srv_event_dispatch(srv *s, srv_event *ev)
{
	srv_job *j = srv_job_find(s, ev->job);
	if (!j)
		return; /* deleted meanwhile */
	if (ev->kind == EV_STATE) {
		ev->fresh = ev->seq > j->pub_seq;
		if (ev->fresh)
			j->pub_seq = ev->seq;
	}
	for (int i = 0; i < s->nobs; i++)
		if (s->obs[i].ops->job_event)
			s->obs[i].ops->job_event(s->obs[i].ud, j, ev);
}

void srv_state_event_locked(const srv_job *j, srv_event *ev)
{
	SRV_HELD(&j->mu);
	memset(ev, 0, sizeof(*ev));
	ev->kind = EV_STATE;
	ev->job = j->id;
	ev->state = j->state;
	ev->seq = j->state_seq;
	if (j->state == SRV_JOB_FAILED)
		snprintf(ev->error, sizeof(ev->error), "%s", j->error);
}

void srv_job_state_changed(srv *s, srv_job *j)
{
	srv_event ev;
	pthread_mutex_lock(&j->mu);
	srv_state_event_locked(j, &ev);
	pthread_mutex_unlock(&j->mu);
	srv_event_dispatch(s, &ev);
}
