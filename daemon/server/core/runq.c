/*
 * runq.c -- the run queue: jobs waiting for a solver worker, in the order
 * they were queued.  Workers take from it (job.c); control commands,
 * recovery and a worker's own final transition put jobs on it.  Guarded
 * by runq_mu, taken inside the job's mu (DESIGN, service.c).
 */
#include "check.h"
#include "core.h"
#include "log.h"

void srv_job_enqueue_locked(srv *s, srv_job *j)
{
	SRV_HELD(&j->mu);
	SRV_CHECK(!srv_job_terminal(j->state));
	if (j->state != SRV_JOB_QUEUED) {
		j->state = SRV_JOB_QUEUED;
		j->state_seq++;
	}
	j->updated = srv_now_unix();
	if (j->in_runq || j->on_worker)
		return; /* a running job keeps running toward the target */
	srv_job_ref(j);
	j->in_runq = 1;
	pthread_mutex_lock(&s->runq_mu);
	j->runq_next = NULL;
	if (s->runq_tail)
		s->runq_tail->runq_next = j;
	else
		s->runq_head = j;
	s->runq_tail = j;
	pthread_cond_signal(&s->runq_cv);
	pthread_mutex_unlock(&s->runq_mu);
}
