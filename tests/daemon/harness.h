/*
 * harness.h -- drive a real luxradd over real sockets from cmocka tests
 * (and from the daemon benchmark).
 *
 * A dm_daemon is a luxradd child process with its own data directory
 * (mkdtemp), ephemeral ports and its stderr captured to a file.  The
 * harness waits for <data_dir>/luxradd.addr to learn the addresses, and
 * on any failure prints the daemon's log before failing the test.
 *
 * A dm_conn is one client connection (TCP or Unix) with a receive buffer
 * decoded by the protocol library.  Every read has a deadline (poll), so
 * a test never hangs: a missing reply is a failure naming what was
 * awaited.  Replies and events are kept apart: dm_call waits for the
 * reply with its id and queues any events that arrive meanwhile, for
 * dm_event to return later in arrival order.
 *
 * Files: harness.c (the child process, fixtures, failures, registry),
 * harness_conn.c (connections, frames, requests, HTTP), harness_util.c
 * (scene/job/query helpers, files, numbers).
 *
 * DESIGN
 * Tests are single-threaded; concurrency is made by interleaving
 * requests on several connections.  Every daemon and connection is
 * registered so that dm_teardown (a cmocka teardown) can kill and free
 * them even when a test failed half-way; children also get
 * PR_SET_PDEATHSIG so a crashed test leaves no daemon behind.  Failures
 * go through dm_fail, which prints the logs of every live daemon, then
 * calls the failure hook (cmocka's fail_msg by default; the benchmark
 * installs its own).
 */
#ifndef LUXRAD_TEST_HARNESS_H
#define LUXRAD_TEST_HARNESS_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

/* Default deadlines, milliseconds (generous: tests run under ASan on a
 * shared 2-core machine). */
#define DM_START_MS 30000 /* daemon writes luxradd.addr */
#define DM_REPLY_MS 30000 /* a reply to a request */
#define DM_EXIT_MS 30000  /* a daemon exits after SIGTERM */

typedef struct dm_daemon {
	pid_t pid;           /* 0 when not running */
	int status;          /* waitpid status once reaped */
	int reaped;          /* 1 once waitpid returned it */
	char dir[256];       /* data directory */
	char log_path[300];  /* daemon stderr+stdout */
	char tcp_host[64];   /* from luxradd.addr */
	int tcp_port;        /* 0 when no TCP listener */
	char unix_path[300]; /* "" when no Unix listener */
	char metrics_host[64];
	int metrics_port; /* 0 when no metrics listener */
	char *extra[32];  /* extra flags given at start (owned) */
	int nextra;
	int keep_dir; /* 1: do not delete dir at teardown */
} dm_daemon;

typedef struct dm_conn {
	int fd;                 /* -1 once closed */
	unsigned char *buf;     /* received, not yet decoded */
	size_t len, cap;        /* bytes in buf, allocated */
	int eof;                /* peer closed (or reset) */
	int reset;              /* ... by a reset (ECONNRESET) */
	json_t *events;         /* queued events (array) */
	json_t *replies;        /* queued replies not yet claimed (array) */
	unsigned char *payload; /* payload of the last dm_call reply */
	size_t payload_len;
	long long next_id; /* request ids */
	int send_ms;       /* send deadline; 0 = DM_REPLY_MS */
	char what[64];     /* "tcp" / "unix", for messages */
} dm_conn;

/* ------------------------------------------------------------- failures */
/* Print the live daemons' logs, then fail (never returns). */
void dm_fail(const char *fmt, ...) __attribute__((format(printf, 1, 2)))
__attribute__((noreturn));
/* Failure hook: the default calls cmocka's fail_msg. */
extern void (*dm_fail_hook)(const char *msg);
/* Reply (and send) deadline of the helpers, ms; DM_REPLY_MS unless a
 * program changes it (the benchmark's big queries). */
extern int dm_reply_ms;
/* Print a daemon's log to stderr (last max_bytes bytes). */
void dm_print_log(const dm_daemon *d, size_t max_bytes);

/*
 * cmocka fixtures: dm_setup arms a watchdog (the whole test, seconds from
 * $LUXRAD_TEST_TIMEOUT, default 170) and clears the registry; dm_teardown
 * kills every daemon still running, closes every connection, prints the
 * logs when the test did not call dm_pass(), and removes data dirs of
 * tests that passed (unless $LUXRAD_TEST_KEEP is set).
 */
int dm_setup(void **state);
int dm_teardown(void **state);
void dm_pass(void);

/* --------------------------------------------------------------- daemon */
/*
 * Start luxradd with a fresh data directory and the given extra flags
 * (NULL-terminated, may be NULL).  Waits for luxradd.addr; fails the test
 * (with the log) if the daemon exits or is too slow.
 */
dm_daemon *dm_start(const char *const *extra);
/* Start again on d's data directory with the same flags (after a kill). */
void dm_restart(dm_daemon *d);
/* Start luxradd expecting it to fail: returns its exit status (or -1 if
 * it is still running after timeout_ms, then it is killed). */
int dm_start_expect_exit(const char *const *extra, int timeout_ms);
/* Send a signal (no wait). */
void dm_signal(dm_daemon *d, int sig);
/* Wait for the child to exit: 1 when it did (status in d->status), 0 on
 * timeout. */
int dm_wait_exit(dm_daemon *d, int timeout_ms);
/* SIGKILL and reap. */
void dm_kill9(dm_daemon *d);
/* SIGTERM, wait, and require exit status 0. */
void dm_stop(dm_daemon *d);
/* 1 if the daemon process is still alive (reaps it if not). */
int dm_alive(dm_daemon *d);

/* ----------------------------------------------------------- connections */
dm_conn *dm_connect_tcp(const dm_daemon *d);
dm_conn *dm_connect_unix(const dm_daemon *d);
/* Connect with a small receive buffer (slow-consumer tests). */
dm_conn *dm_connect_tcp_rcvbuf(const dm_daemon *d, int rcvbuf);
/* From a source address of our own (127.0.0.2, ...: another peer as far
 * as per-address limits go). */
dm_conn *dm_connect_tcp_from(const dm_daemon *d, const char *src);
/* A blocking TCP socket connected to host:port, from src when not NULL,
 * with SO_RCVBUF rcvbuf when > 0: the fd, or -1 with why filled (for
 * callers that drive sockets themselves, as the load benchmark). */
int dm_tcp_socket(const char *host, int port, int rcvbuf, const char *src,
                  char *why, size_t len);
/* A session (hello done) once the daemon has a slot for it, retrying
 * while it refuses; NULL after timeout_ms.  src as dm_connect_tcp_from
 * (NULL: the default source). */
dm_conn *dm_open_when_free(const dm_daemon *d, const char *src, int timeout_ms);
/* Connect and say hello (token may be NULL); fails unless ok. */
dm_conn *dm_open(const dm_daemon *d, const char *token);
void dm_close(dm_conn *c);
/* The registry dm_teardown closes from (harness internals). */
void dm_conn_register(dm_conn *c);
void dm_conn_forget(dm_conn *c);

/* Send raw bytes (all of them, deadline c->send_ms); returns 0, -1 if
 * the peer closed (EPIPE / ECONNRESET), -2 if it stopped reading. */
int dm_send_raw(dm_conn *c, const void *bytes, size_t len);
/* Encode and send a frame (header not stolen). */
int dm_send_frame(dm_conn *c, json_t *header, const void *payload, size_t len);
/*
 * Read one frame: 1 with *hdr (new reference) and the payload copied
 * into *payload (malloc'ed, may be NULL), 0 on timeout, -1 when the
 * connection is closed with nothing left to decode.  A decode error
 * fails the test (the daemon sent a malformed frame).
 */
int dm_recv(dm_conn *c, int timeout_ms, json_t **hdr, unsigned char **payload,
            size_t *payload_len);
/* Wait until the peer closes: 1 if it did within timeout_ms; frames
 * received meanwhile are queued. */
int dm_wait_closed(dm_conn *c, int timeout_ms);

/*
 * Requests.  The header is built with json_pack (fmt, ...) and given an
 * id; the reply with that id is returned (new reference; its payload, if
 * any, in c->payload until the next call).  Events arriving meanwhile are
 * queued.  Fails the test on timeout or if the connection closes before
 * the reply, unless the _maybe form is used (returns NULL then).
 */
json_t *dm_call(dm_conn *c, const char *fmt, ...);
json_t *dm_call_maybe(dm_conn *c, int timeout_ms, const char *fmt, ...);
/* Same with a payload (scene.upload). */
json_t *dm_call_payload(dm_conn *c, const void *payload, size_t len,
                        const char *fmt, ...);
/* dm_call and require "ok": true (the error is printed otherwise). */
json_t *dm_ok(dm_conn *c, const char *fmt, ...);
/* dm_call and require an error with this code; returns the reply. */
json_t *dm_err(dm_conn *c, const char *code, const char *fmt, ...);
/* Send a header (stolen) with a fresh id, return its reply (new
 * reference); must: fail on timeout / close, else NULL then. */
json_t *dm_call_json(dm_conn *c, json_t *h, const void *payload, size_t len,
                     int timeout_ms, int must);
/* Compact JSON, cut at ~1500 characters (malloc'ed, for messages). */
char *dm_dumps(const json_t *j);
/* Fail (printing the reply) unless it is "ok": true. */
void dm_require_ok(const json_t *r, const char *what);
/* The error code of a reply ("" when ok, "?" when malformed). */
const char *dm_err_code(const json_t *reply);
/* Frames with no id and "ok": false received so far (e.g. slow_consumer,
 * idle_timeout): the code of the first one queued, or NULL. */
const char *dm_unsolicited_error(dm_conn *c);

/*
 * Next event (queued first, else read; replies read meanwhile are
 * queued): new reference, or NULL on timeout / close.
 */
json_t *dm_event(dm_conn *c, int timeout_ms);

/* ------------------------------------------------------- daemon helpers */
/* Upload a file as a scene; returns the id (new reference). */
json_t *dm_upload_file(dm_conn *c, const char *path, const char *name);
/* job.create with solver and options (a JSON object, not stolen; may be
 * NULL); returns the job id (new reference). */
json_t *dm_job_create(dm_conn *c, const json_t *scene, const char *solver,
                      const json_t *options);
/* The job's state from job.info (static buffer). */
const char *dm_job_state(dm_conn *c, const json_t *job);
/*
 * Poll job.info until the state is one of the '|'-separated states
 * (e.g. "done|failed"); returns the job object of the last job.info (new
 * reference).  Fails on timeout.
 */
json_t *dm_wait_job(dm_conn *c, const json_t *job, const char *states,
                    int timeout_ms);
/* query.points: lux values into lux[n] (n points, 6 doubles each);
 * returns the iteration the answer came from. */
long long dm_query_points(dm_conn *c, const json_t *job, const double *pts,
                          size_t n, double *lux);
/* Upload a sample scene, solve it (hr, threads 1, converge) and return
 * the job id; *scene gets the scene id (new references). */
json_t *dm_solve_sample(dm_conn *c, const char *sample, json_t **scene);
/* HTTP GET on the metrics listener: returns the status code, body
 * malloc'ed into *body (headers into *headers if not NULL). */
int dm_http_get(const dm_daemon *d, const char *path, char **headers,
                char **body);
/* The value of one series ("name" or "name{label=\"v\"}") in a /metrics
 * body; fails the test when it is missing. */
double dm_metrics_sample(const char *body, const char *series);
/* GET /metrics and return that series' value. */
double dm_metric(const dm_daemon *d, const char *series);

/* -------------------------------------------------------------- files */
/* Path of a committed sample scene (static buffer per call site). */
const char *dm_sample(const char *name, char *buf, size_t len);
/* A luxrad-scenegen scene, made once and cached in the build tree:
 * kind plus extra args ("--triangles 20000"); returns the path. */
const char *dm_gen_scene(const char *file, const char *args, char *buf,
                         size_t len);
/* A new temporary file holding data; returns its path (malloc'ed; the
 * caller unlinks and frees it). */
char *dm_tmp_file(const char *suffix, const void *data, size_t len);
/* Whole file (malloc'ed, caller frees); fails when unreadable. */
unsigned char *dm_read_file(const char *path, size_t *len);
/* Run a shell command, capture stdout (malloc'ed); returns exit status
 * (-1 if it could not run). */
int dm_run(const char *cmd, char **out);

/* ------------------------------------------------------------ numbers */
/* Monotonic milliseconds. */
double dm_now_ms(void);
void dm_sleep_ms(int ms);
/* A JSON number as double; fails if the member is missing or not a
 * number (names the member). */
double dm_num(const json_t *obj, const char *key);
/* Same for an integer member. */
long long dm_int(const json_t *obj, const char *key);
/* Member that must exist (borrowed). */
json_t *dm_get(const json_t *obj, const char *key);
/* obj must be an object holding every key of the NULL-ended list;
 * failures name what (e.g. "status.memory") and the member. */
void dm_require_keys(const json_t *obj, const char *what,
                     const char *const *keys);
/* The memory kinds PROTOCOL.md lists under memory.by_kind (NULL-ended). */
extern const char *const dm_mem_kinds[];
/* Compare two lux values within float rounding. */
int dm_close_enough(double a, double b, double rel);

#endif
