/*
 * qsplit.c -- one query's points spread over the query threads.
 *
 * The engine evaluates points independently (one sequential final gather
 * per point), so a big point set can be cut into chunks and shared out
 * without changing a single value.  The query's own task takes chunks in
 * turn with up to (query threads - 1) helper tasks queued on the same
 * pool; each taker claims the next chunk with one atomic add.  The query
 * task never waits for a helper to start -- only for chunks already
 * claimed to finish -- so a busy pool (helpers still queued when the last
 * chunk is taken) costs nothing and cannot deadlock: a helper that starts
 * late finds no chunk left and ends.  The shared state is reference
 * counted, so it outlives whichever of the query and its helpers ends
 * last; a late helper touches only that state, never the points or the
 * results, which belong to the query.
 */
#include <stdlib.h>
#include <string.h>

#include "core.h"

/* Points per chunk: about 30-100 ms of final gather on a large hall. */
#define QS_CHUNK 32

typedef struct qs_share {
	atomic_int refs;    /* the query and each helper queued */
	atomic_size_t next; /* first point of the next chunk to claim */
	size_t n;
	const srv_sol *sol;
	const double *pts; /* 6 per point; read only by chunk owners */
	double *lux, *error_lux;
	pthread_mutex_t mu;
	pthread_cond_t cv;
	size_t done;       /* mu: points finished */
	rad_status status; /* mu: the first failure */
	rad_error err;     /* mu */
} qs_share;

typedef struct qs_helper {
	srv_task t;
	qs_share *sh;
} qs_helper;

static void share_unref(qs_share *sh, int k)
{
	if (atomic_fetch_sub(&sh->refs, k) != k)
		return;
	pthread_mutex_destroy(&sh->mu);
	pthread_cond_destroy(&sh->cv);
	free(sh);
}

static rad_status one_chunk(const srv_sol *sol, const double *pts, size_t n,
                            double *lux, double *error_lux, rad_error *err)
{
	return rad_solution_query(sol->sol, pts, n, sol->query_tol,
	                          sol->solve_error, lux, error_lux, err);
}

/* Claim and evaluate chunks until none is left. */
static void take_chunks(qs_share *sh)
{
	for (;;) {
		size_t b = atomic_fetch_add(&sh->next, QS_CHUNK);
		if (b >= sh->n)
			return;
		size_t m = sh->n - b < QS_CHUNK ? sh->n - b : QS_CHUNK;
		rad_error err = {0};
		rad_status st = one_chunk(
		        sh->sol, sh->pts + 6 * b, m, sh->lux + b,
		        sh->error_lux ? sh->error_lux + b : NULL, &err);
		pthread_mutex_lock(&sh->mu);
		if (st != RAD_OK && sh->status == RAD_OK) {
			sh->status = st;
			sh->err = err;
		}
		sh->done += m;
		if (sh->done == sh->n)
			pthread_cond_signal(&sh->cv);
		pthread_mutex_unlock(&sh->mu);
	}
}

static void helper_run(srv *s, srv_task *t)
{
	(void)s;
	take_chunks(((qs_helper *)t)->sh);
}

static void helper_done(srv *s, srv_task *t)
{
	(void)s;
	share_unref(((qs_helper *)t)->sh, 1);
	free(t);
}

rad_status srv_query_illuminance(srv *s, const srv_sol *sol, const double *pts,
                                 size_t n, double *lux, double *error_lux,
                                 rad_error *err)
{
	size_t chunks = (n + QS_CHUNK - 1) / QS_CHUNK;
	size_t helpers = s->query_pool.nthreads > 1
	                         ? (size_t)s->query_pool.nthreads - 1
	                         : 0;
	if (helpers > chunks - (chunks > 0))
		helpers = chunks - (chunks > 0);
	qs_share *sh = helpers ? calloc(1, sizeof(*sh)) : NULL;
	if (!sh) /* one chunk, one thread, or no memory: all here */
		return one_chunk(sol, pts, n, lux, error_lux, err);
	atomic_init(&sh->refs, (int)helpers + 1);
	atomic_init(&sh->next, 0);
	sh->n = n;
	sh->sol = sol;
	sh->pts = pts;
	sh->lux = lux;
	sh->error_lux = error_lux;
	pthread_mutex_init(&sh->mu, NULL);
	pthread_cond_init(&sh->cv, NULL);
	for (size_t i = 0; i < helpers; i++) {
		qs_helper *h = calloc(1, sizeof(*h));
		if (!h) { /* fewer helpers: drop the refs of the missing */
			share_unref(sh, (int)(helpers - i));
			break;
		}
		h->sh = sh;
		h->t.run = helper_run;
		h->t.done = helper_done;
		srv_pool_submit(&s->query_pool, &h->t);
	}
	take_chunks(sh);
	pthread_mutex_lock(&sh->mu);
	while (sh->done < sh->n)
		pthread_cond_wait(&sh->cv, &sh->mu);
	rad_status st = sh->status;
	if (st != RAD_OK && err)
		*err = sh->err;
	pthread_mutex_unlock(&sh->mu);
	share_unref(sh, 1);
	return st;
}
