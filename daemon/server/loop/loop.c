/*
 * loop.c -- the event loop of loop.h on epoll, an eventfd and a signalfd.
 *
 * Timers are kept in a list ordered by due time (ties in the order they
 * were added): a daemon has a handful of periodic duties, so an ordered
 * list is as fast as a heap and simpler to read.  The wait sleeps until
 * the nearest one.  The timers due at the start of the timer phase are
 * taken off the list first and run once each, so a callback that asks to
 * run again at once (0 s) cannot starve the descriptors.
 */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/signalfd.h>
#include <time.h>
#include <unistd.h>

#include "loop.h"

#define EL_BATCH 64 /* descriptors handled per wait */

typedef struct el_timer {
	struct el_timer *next;
	uint64_t id;
	double due; /* el_now() */
	el_timer_fn fn;
	void *ud;
	int ended; /* removed while in the running batch */
} el_timer;

struct el_loop {
	int epfd;
	int stop;
	el_timer *timers;  /* pending, by due time */
	el_timer *running; /* taken off for this turn's timer phase */
	uint64_t next_timer_id;
	el_watch wake_w, sig_w;
	el_hook_fn wake_fn, after_fn;
	void *wake_ud, *after_ud;
	el_signal_fn sig_fn;
	void *sig_ud;
};

double el_now(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

el_loop *el_new(char *msg, size_t msglen)
{
	el_loop *l = calloc(1, sizeof(*l));
	if (!l) {
		snprintf(msg, msglen, "event loop: out of memory");
		return NULL;
	}
	l->wake_w.fd = l->sig_w.fd = -1;
	l->next_timer_id = 1;
	l->epfd = epoll_create1(EPOLL_CLOEXEC);
	if (l->epfd < 0) {
		snprintf(msg, msglen, "cannot set up the event loop: %s",
		         strerror(errno));
		free(l);
		return NULL;
	}
	return l;
}

static void free_timers(el_timer *t)
{
	while (t) {
		el_timer *next = t->next;
		free(t);
		t = next;
	}
}

void el_free(el_loop *l)
{
	if (!l)
		return;
	free_timers(l->timers);
	free_timers(l->running);
	if (l->wake_w.fd >= 0)
		close(l->wake_w.fd);
	if (l->sig_w.fd >= 0)
		close(l->sig_w.fd);
	close(l->epfd);
	free(l);
}

/* ---------------------------------------------------------------- watches */

static uint32_t to_epoll(unsigned events)
{
	return (events & EL_READABLE ? EPOLLIN : 0u) |
	       (events & EL_WRITABLE ? EPOLLOUT : 0u);
}

static unsigned from_epoll(uint32_t ev)
{
	return (ev & EPOLLIN ? EL_READABLE : 0u) |
	       (ev & EPOLLOUT ? EL_WRITABLE : 0u) |
	       (ev & (EPOLLERR | EPOLLHUP) ? EL_ERROR : 0u);
}

int el_watch_add(el_loop *l, el_watch *w, int fd, unsigned events, el_fd_fn fn,
                 void *ud)
{
	w->fd = fd;
	w->events = events;
	w->fn = fn;
	w->ud = ud;
	struct epoll_event ev = {.events = to_epoll(events), .data.ptr = w};
	return epoll_ctl(l->epfd, EPOLL_CTL_ADD, fd, &ev);
}

int el_watch_set(el_loop *l, el_watch *w, unsigned events)
{
	struct epoll_event ev = {.events = to_epoll(events), .data.ptr = w};
	if (epoll_ctl(l->epfd, EPOLL_CTL_MOD, w->fd, &ev) != 0)
		return -1;
	w->events = events;
	return 0;
}

void el_watch_del(el_loop *l, el_watch *w)
{
	epoll_ctl(l->epfd, EPOLL_CTL_DEL, w->fd, NULL);
}

/* ----------------------------------------------------------------- timers */

static void insert_timer(el_loop *l, el_timer *t)
{
	el_timer **pp = &l->timers;
	while (*pp && (*pp)->due <= t->due)
		pp = &(*pp)->next;
	t->next = *pp;
	*pp = t;
}

uint64_t el_timer_add(el_loop *l, double after_s, el_timer_fn fn, void *ud)
{
	el_timer *t = calloc(1, sizeof(*t));
	if (!t)
		return 0;
	t->id = l->next_timer_id++;
	t->due = el_now() + (after_s > 0 ? after_s : 0);
	t->fn = fn;
	t->ud = ud;
	insert_timer(l, t);
	return t->id;
}

void el_timer_del(el_loop *l, uint64_t id)
{
	for (el_timer **pp = &l->timers; *pp; pp = &(*pp)->next) {
		if ((*pp)->id == id) {
			el_timer *t = *pp;
			*pp = t->next;
			free(t);
			return;
		}
	}
	for (el_timer *t = l->running; t; t = t->next)
		if (t->id == id)
			t->ended = 1;
}

/* Run the timers due now, each once. */
static void run_timers(el_loop *l)
{
	double now = el_now();
	el_timer **pp = &l->timers;
	while (*pp && (*pp)->due <= now)
		pp = &(*pp)->next;
	if (pp == &l->timers)
		return;
	l->running = l->timers;
	l->timers = *pp;
	*pp = NULL;
	while (l->running) {
		el_timer *t = l->running;
		double again = t->ended ? -1 : t->fn(l, t->ud, now);
		l->running = t->next;
		if (again < 0 || t->ended) {
			free(t);
			continue;
		}
		t->due = now + again;
		insert_timer(l, t);
	}
}

/* Milliseconds to the nearest timer, rounded up; -1 with none. */
static int wait_ms(const el_loop *l)
{
	if (!l->timers)
		return -1;
	double ms = ceil((l->timers->due - el_now()) * 1000.0);
	return ms <= 0 ? 0 : ms > 1e9 ? 1000000000 : (int)ms;
}

/* -------------------------------------------------------- wake, signals */

static void wake_ready(el_loop *l, el_watch *w, unsigned events)
{
	uint64_t v;
	(void)events;
	/* EAGAIN: another turn already took the count. */
	if (read(w->fd, &v, sizeof(v)) < 0 && errno != EAGAIN)
		return;
	l->wake_fn(l, l->wake_ud);
}

/* Watch a descriptor the loop made itself (fd < 0: its creation failed). */
static int watch_own(el_loop *l, el_watch *w, int fd, el_fd_fn fn,
                     const char *what, char *msg, size_t msglen)
{
	if (fd < 0 || el_watch_add(l, w, fd, EL_READABLE, fn, NULL) != 0) {
		snprintf(msg, msglen, "cannot set up %s: %s", what,
		         strerror(errno));
		if (fd >= 0)
			close(fd);
		w->fd = -1;
		return -1;
	}
	return 0;
}

int el_wake_init(el_loop *l, el_hook_fn fn, void *ud, char *msg, size_t msglen)
{
	int fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	if (watch_own(l, &l->wake_w, fd, wake_ready, "the wake-up", msg,
	              msglen) != 0)
		return -1;
	l->wake_fn = fn;
	l->wake_ud = ud;
	return 0;
}

void el_wake(el_loop *l)
{
	uint64_t one = 1;
	/* An eventfd counter cannot overflow at our rates; EAGAIN would
	 * only mean it is already readable. */
	while (write(l->wake_w.fd, &one, sizeof(one)) < 0 && errno == EINTR)
		;
}

static void signal_ready(el_loop *l, el_watch *w, unsigned events)
{
	struct signalfd_siginfo si;
	(void)events;
	while (read(w->fd, &si, sizeof(si)) == (ssize_t)sizeof(si))
		l->sig_fn(l, (int)si.ssi_signo, l->sig_ud);
}

int el_signals(el_loop *l, const int *sigs, int n, el_signal_fn fn, void *ud,
               char *msg, size_t msglen)
{
	sigset_t set;
	sigemptyset(&set);
	for (int i = 0; i < n; i++)
		sigaddset(&set, sigs[i]);
	pthread_sigmask(SIG_BLOCK, &set, NULL);
	int fd = signalfd(-1, &set, SFD_NONBLOCK | SFD_CLOEXEC);
	if (watch_own(l, &l->sig_w, fd, signal_ready, "signal delivery", msg,
	              msglen) != 0)
		return -1;
	l->sig_fn = fn;
	l->sig_ud = ud;
	return 0;
}

/* ------------------------------------------------------------------- run */

void el_after_turn(el_loop *l, el_hook_fn fn, void *ud)
{
	l->after_fn = fn;
	l->after_ud = ud;
}

void el_stop(el_loop *l)
{
	l->stop = 1;
}

int el_run(el_loop *l, char *msg, size_t msglen)
{
	struct epoll_event evs[EL_BATCH];
	while (!l->stop) {
		int n = epoll_wait(l->epfd, evs, EL_BATCH, wait_ms(l));
		if (n < 0 && errno != EINTR) {
			snprintf(msg, msglen, "epoll_wait: %s",
			         strerror(errno));
			return -1;
		}
		for (int i = 0; i < n; i++) {
			el_watch *w = evs[i].data.ptr;
			w->fn(l, w, from_epoll(evs[i].events));
		}
		run_timers(l);
		if (l->after_fn)
			l->after_fn(l, l->after_ud);
	}
	return 0;
}
