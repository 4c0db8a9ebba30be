/*
 * loop.h -- a small event loop: file-descriptor watches with callbacks,
 * deadline timers, a wake-up any thread may ring, and signals delivered
 * as callbacks.  One thread runs the loop; only el_wake() may be called
 * from other threads.
 *
 * It knows nothing of what it serves (no sockets, protocol or jobs):
 * whoever owns a descriptor or a periodic duty registers it here.  Built
 * on epoll, eventfd and signalfd (Linux).
 *
 * A turn of el_run: wait until a watched descriptor is ready or the
 * nearest timer is due; call the ready watches' callbacks; call the
 * timers that are due; call the after-turn hook.  A watch callback may
 * remove (and free) its own watch, never another one: objects that die
 * during a turn should be marked and freed in the after-turn hook.
 */
#ifndef LUXRAD_EL_LOOP_H
#define LUXRAD_EL_LOOP_H

#include <stddef.h>
#include <stdint.h>

typedef struct el_loop el_loop;

/* Readiness flags, for el_watch_add/el_watch_set and the callbacks. */
#define EL_READABLE 1u
#define EL_WRITABLE 2u
#define EL_ERROR 4u /* error or hang-up: reported whatever was asked */

typedef struct el_watch el_watch;
typedef void (*el_fd_fn)(el_loop *l, el_watch *w, unsigned events);

/* A watched descriptor; embedded by its owner, valid until removed. */
struct el_watch {
	int fd;
	unsigned events; /* EL_READABLE | EL_WRITABLE asked for */
	el_fd_fn fn;
	void *ud; /* the owner's */
};

/*
 * A timer's callback, given el_now() when called; returns the seconds
 * until it should run again, or a negative value to end the timer.
 */
typedef double (*el_timer_fn)(el_loop *l, void *ud, double now);
typedef void (*el_signal_fn)(el_loop *l, int signo, void *ud);
typedef void (*el_hook_fn)(el_loop *l, void *ud);

/* NULL with msg filled when the kernel objects cannot be made. */
el_loop *el_new(char *msg, size_t msglen);
void el_free(el_loop *l);

/* Seconds on a monotonic clock (the one timers use). */
double el_now(void);

int el_watch_add(el_loop *l, el_watch *w, int fd, unsigned events, el_fd_fn fn,
                 void *ud);
int el_watch_set(el_loop *l, el_watch *w, unsigned events);
void el_watch_del(el_loop *l, el_watch *w);

/* Run fn after_s seconds from now; returns an id (> 0) or 0 on no memory. */
uint64_t el_timer_add(el_loop *l, double after_s, el_timer_fn fn, void *ud);
void el_timer_del(el_loop *l, uint64_t id);

/*
 * The wake-up: el_wake (any thread) makes the loop call fn once soon;
 * several wakes before it runs make one call.  One handler per loop.
 */
int el_wake_init(el_loop *l, el_hook_fn fn, void *ud, char *msg, size_t msglen);
void el_wake(el_loop *l);

/*
 * Deliver these signals through the loop: they are blocked in the
 * calling thread (threads it starts later inherit the mask, so no
 * thread runs a handler) and fn is called on the loop for each one.
 */
int el_signals(el_loop *l, const int *sigs, int n, el_signal_fn fn, void *ud,
               char *msg, size_t msglen);

/* Called at the end of every turn (one hook per loop). */
void el_after_turn(el_loop *l, el_hook_fn fn, void *ud);

/* Run turns until el_stop; 0, or -1 with msg when the wait fails. */
int el_run(el_loop *l, char *msg, size_t msglen);
void el_stop(el_loop *l);

#endif
