/*
 * pool.c -- thread pools for tasks, and the inbox that carries results
 * and events back to the I/O thread.
 *
 * A pool is a FIFO of tasks under one mutex and condition variable, with
 * n threads taking tasks from it.  The query pool answers queries and
 * exports; the store pool (one thread, so writes keep their order) parses
 * uploads and writes job rows.  A task's run() executes on a pool thread
 * and must not touch I/O-thread state; its done() is posted to the inbox
 * and executes on the I/O thread, where it sends the reply and frees the
 * task.
 *
 * The inbox is a mutex-protected list plus the event loop's wake-up: any
 * thread posts a message and rings it; the I/O thread, woken, takes
 * the whole list in one swap and handles it with no lock held.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "core.h"
#include "log.h"

static void *pool_main(void *arg)
{
	srv_pool *p = arg;
	for (;;) {
		pthread_mutex_lock(&p->mu);
		while (!p->head && !p->stop)
			pthread_cond_wait(&p->cv, &p->mu);
		srv_task *t = p->head;
		if (!t) { /* stop, and nothing left */
			pthread_mutex_unlock(&p->mu);
			return NULL;
		}
		p->head = t->next;
		if (!p->head)
			p->tail = NULL;
		SRV_CHECK(p->queued > 0);
		p->queued--;
		SRV_CHECK((p->head == NULL) == (p->queued == 0));
		pthread_mutex_unlock(&p->mu);
		t->next = NULL;
		if (t->run)
			t->run(p->s, t);
		srv_task_finish(p->s, t);
	}
}

int srv_pool_start(srv *s, srv_pool *p, const char *name, int n, char *msg,
                   size_t msglen)
{
	memset(p, 0, sizeof(*p));
	p->name = name;
	p->s = s;
	pthread_mutex_init(&p->mu, NULL);
	pthread_cond_init(&p->cv, NULL);
	p->threads = calloc((size_t)n, sizeof(pthread_t));
	if (!p->threads) {
		snprintf(msg, msglen, "%s pool: out of memory", name);
		return -1;
	}
	for (int i = 0; i < n; i++) {
		int rc = pthread_create(&p->threads[i], NULL, pool_main, p);
		if (rc != 0) {
			snprintf(msg, msglen,
			         "%s pool: cannot start thread: %s", name,
			         strerror(rc));
			srv_pool_stop(p);
			return -1;
		}
		p->nthreads++;
	}
	return 0;
}

void srv_pool_submit(srv_pool *p, srv_task *t)
{
	t->next = NULL;
	pthread_mutex_lock(&p->mu);
	SRV_CHECK(!p->stop); /* nothing is queued to a stopped pool */
	SRV_CHECK((p->head == NULL) == (p->queued == 0));
	if (p->tail)
		p->tail->next = t;
	else
		p->head = t;
	p->tail = t;
	p->queued++;
	pthread_cond_signal(&p->cv);
	pthread_mutex_unlock(&p->mu);
}

void srv_pool_stop(srv_pool *p)
{
	if (!p->threads)
		return;
	pthread_mutex_lock(&p->mu);
	p->stop = 1;
	pthread_cond_broadcast(&p->cv);
	pthread_mutex_unlock(&p->mu);
	for (int i = 0; i < p->nthreads; i++)
		pthread_join(p->threads[i], NULL);
	free(p->threads);
	p->threads = NULL;
	p->nthreads = 0;
	pthread_mutex_destroy(&p->mu);
	pthread_cond_destroy(&p->cv);
}

/* ------------------------------------------------------------------ inbox */

void srv_inbox_post(srv *s, srv_msg *m)
{
	m->next = NULL;
	pthread_mutex_lock(&s->inbox_mu);
	if (s->inbox_tail)
		s->inbox_tail->next = m;
	else
		s->inbox_head = m;
	s->inbox_tail = m;
	pthread_mutex_unlock(&s->inbox_mu);
	el_wake(s->loop);
}

void srv_task_finish(srv *s, srv_task *t)
{
	srv_msg *m = calloc(1, sizeof(*m));
	if (!m) {
		/* Cannot tell the I/O thread: the reply is lost and the
		 * connection stays busy until it times out.  Logged. */
		srv_error("out of memory posting a task result");
		return;
	}
	m->kind = MSG_TASK_DONE;
	m->task = t;
	srv_inbox_post(s, m);
}

void srv_event_post(srv *s, const srv_event *ev)
{
	srv_msg *m = malloc(sizeof(*m));
	if (!m) {
		srv_warn("job %llu: out of memory posting an event",
		         (unsigned long long)ev->job);
		return;
	}
	m->kind = MSG_EVENT;
	m->task = NULL;
	m->ev = *ev;
	srv_inbox_post(s, m);
}

void srv_inbox_drain(srv *s)
{
	pthread_mutex_lock(&s->inbox_mu);
	srv_msg *m = s->inbox_head;
	s->inbox_head = s->inbox_tail = NULL;
	pthread_mutex_unlock(&s->inbox_mu);
	while (m) {
		srv_msg *next = m->next;
		if (m->kind == MSG_TASK_DONE) {
			if (m->task->done)
				m->task->done(s, m->task);
		} else {
			srv_event_dispatch(s, &m->ev);
		}
		free(m);
		m = next;
	}
}
