/*
 * check.h -- the daemon's invariant checks (SQLite's habit: state what
 * must hold where it must hold, and let debug builds prove it).
 *
 * With LUXRAD_CHECKS (Debug and sanitizer builds, CMakeLists.txt) a
 * broken invariant prints what and where and aborts, so the test that
 * reached it fails at the cause instead of at a symptom.  Without it the
 * checks compile to nothing: a release daemon pays for none of them.
 *
 * SRV_HELD(m): the caller of a *_locked function holds m.  A trylock
 * that fails with EBUSY shows the mutex is held -- by some thread: the
 * check catches a caller that took no lock, which is the mistake a
 * *_locked name invites.
 */
#ifndef LUXRAD_SRV_CHECK_H
#define LUXRAD_SRV_CHECK_H

#ifdef LUXRAD_CHECKS
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>

#define SRV_CHECK(cond)                                                        \
	do {                                                                   \
		if (!(cond)) {                                                 \
			fprintf(stderr, "%s:%d: invariant broken: %s\n",       \
			        __FILE__, __LINE__, #cond);                    \
			abort();                                               \
		}                                                              \
	} while (0)

static inline int srv_mutex_held(pthread_mutex_t *m)
{
	if (pthread_mutex_trylock(m) != 0)
		return 1;
	pthread_mutex_unlock(m);
	return 0;
}
#define SRV_HELD(m) SRV_CHECK(srv_mutex_held((pthread_mutex_t *)(m)))
#else
#define SRV_CHECK(cond) ((void)0)
#define SRV_HELD(m) ((void)0)
#endif

#endif
