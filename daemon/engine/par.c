/*
 * par.c -- fork-join thread pool (see par.h).
 *
 * DESIGN
 * The pool owns nthreads-1 workers; the caller of rad_par_for is the last
 * worker.  A loop is published under the mutex with a generation number;
 * chunks are claimed with an atomic counter, so the load balances itself
 * while the results stay in per-index slots.  Workers join a loop only
 * under the mutex while it is `busy`, and count themselves `active`; the
 * caller clears `busy` only when every chunk is done and no worker is
 * active, so no worker can still be claiming chunks when the next loop
 * reuses the counters.  One loop runs at a time per pool; a nested
 * rad_par_for on the same pool runs inline.
 */
#include "par.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <unistd.h>

#include "rad.h"
#include "vis.h"

struct rad_par {
	int nthreads;         /* including the caller */
	pthread_t *workers;   /* nthreads - 1 */
	pthread_mutex_t lock; /* guards everything below but the atomics */
	pthread_cond_t wake;  /* a loop was published, or shutdown */
	pthread_cond_t idle;  /* a loop finished */
	uint64_t generation;  /* bumped per loop */
	int shutdown;
	int busy;      /* a loop is running (nesting runs inline) */
	int active;    /* workers inside the current loop */
	rad_par_fn fn; /* the current loop */
	void *ud;
	size_t n, grain, nchunks;
	_Atomic size_t next; /* next chunk to claim */
	_Atomic size_t done; /* chunks finished */
};

/* Claim and run chunks of the current loop until none is left. */
static void run_chunks(rad_par *p, int thread)
{
	for (;;) {
		size_t c = atomic_fetch_add(&p->next, 1);
		if (c >= p->nchunks)
			return;
		size_t b = c * p->grain;
		size_t e = b + p->grain < p->n ? b + p->grain : p->n;
		p->fn(p->ud, b, e, thread);
		if (atomic_fetch_add(&p->done, 1) + 1 == p->nchunks) {
			pthread_mutex_lock(&p->lock);
			pthread_cond_broadcast(&p->idle);
			pthread_mutex_unlock(&p->lock);
		}
	}
}

typedef struct worker_arg {
	rad_par *p;
	int thread;
} worker_arg;

static void *worker_main(void *arg)
{
	rad_par *p = ((worker_arg *)arg)->p;
	int thread = ((worker_arg *)arg)->thread;
	free(arg);
	rad_vis_thread_init();
	uint64_t seen = 0;
	pthread_mutex_lock(&p->lock);
	for (;;) {
		while (!p->shutdown && p->generation == seen)
			pthread_cond_wait(&p->wake, &p->lock);
		if (p->shutdown)
			break;
		seen = p->generation;
		if (!p->busy)
			continue; /* woke after that loop had finished */
		p->active++;
		pthread_mutex_unlock(&p->lock);
		run_chunks(p, thread);
		pthread_mutex_lock(&p->lock);
		if (--p->active == 0)
			pthread_cond_broadcast(&p->idle);
	}
	pthread_mutex_unlock(&p->lock);
	return NULL;
}

rad_status rad_par_new(int nthreads, rad_par **out, rad_error *err)
{
	*out = NULL;
	if (nthreads <= 0) {
		long c = sysconf(_SC_NPROCESSORS_ONLN);
		nthreads = c > 0 ? (int)c : 1;
	}
	if (nthreads > 256)
		return rad_fail(err, RAD_ERR_INVALID,
		                "threads: %d is more than the 256 supported",
		                nthreads);
	rad_par *p = calloc(1, sizeof(*p));
	if (!p)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "thread pool: out of memory");
	p->nthreads = nthreads;
	pthread_mutex_init(&p->lock, NULL);
	pthread_cond_init(&p->wake, NULL);
	pthread_cond_init(&p->idle, NULL);
	p->workers = calloc((size_t)nthreads, sizeof(pthread_t));
	if (!p->workers) {
		rad_par_free(p);
		return rad_fail(err, RAD_ERR_NOMEM,
		                "thread pool: out of memory");
	}
	for (int i = 1; i < nthreads; i++) {
		worker_arg *a = malloc(sizeof(*a));
		if (a) {
			a->p = p;
			a->thread = i;
		}
		if (!a || pthread_create(&p->workers[i - 1], NULL, worker_main,
		                         a) != 0) {
			free(a);
			p->nthreads = i; /* join only those started */
			rad_par_free(p);
			return rad_fail(err, RAD_ERR_NOMEM,
			                "thread pool: cannot start thread %d",
			                i);
		}
	}
	*out = p;
	return RAD_OK;
}

void rad_par_free(rad_par *p)
{
	if (!p)
		return;
	pthread_mutex_lock(&p->lock);
	p->shutdown = 1;
	pthread_cond_broadcast(&p->wake);
	pthread_mutex_unlock(&p->lock);
	for (int i = 1; i < p->nthreads && p->workers; i++)
		pthread_join(p->workers[i - 1], NULL);
	pthread_cond_destroy(&p->idle);
	pthread_cond_destroy(&p->wake);
	pthread_mutex_destroy(&p->lock);
	free(p->workers);
	free(p);
}

int rad_par_threads(const rad_par *p)
{
	return p ? p->nthreads : 1;
}

void rad_par_for(rad_par *p, size_t n, size_t grain, rad_par_fn fn, void *ud)
{
	if (n == 0)
		return;
	if (!p) {
		fn(ud, 0, n, 0);
		return;
	}
	if (grain == 0)
		grain = 1;
	pthread_mutex_lock(&p->lock);
	if (p->nthreads == 1 || p->busy || n <= grain) {
		pthread_mutex_unlock(&p->lock);
		fn(ud, 0, n, 0);
		return;
	}
	p->busy = 1;
	p->fn = fn;
	p->ud = ud;
	p->n = n;
	p->grain = grain;
	p->nchunks = (n + grain - 1) / grain;
	atomic_store(&p->next, 0);
	atomic_store(&p->done, 0);
	p->generation++;
	pthread_cond_broadcast(&p->wake);
	pthread_mutex_unlock(&p->lock);

	run_chunks(p, 0);

	pthread_mutex_lock(&p->lock);
	while (atomic_load(&p->done) < p->nchunks || p->active > 0)
		pthread_cond_wait(&p->idle, &p->lock);
	p->busy = 0;
	pthread_mutex_unlock(&p->lock);
}
