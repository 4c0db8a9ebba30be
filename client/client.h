/*
 * client.h -- the luxrad CLI's shared types: parsed command lines, the
 * connection to the daemon, exit codes, and the command functions each
 * file implements.
 *
 * Module map, from the bottom up (no file calls one above it):
 *   args.c         the option table and typed getters of option values
 *   out.c          JSON lines, byte counts, lenient reads of replies
 *   net.c          the connection: connect, hello, requests, frames
 *   cmds.c         scenes, jobs and daemon commands (submit, create...)
 *   show.c         info and status, printed for people
 *   cmd_query.c    query (points file, grid, surfaces) and export
 *   cmd_watch.c    watch and run --wait: events, progress bar, JSON lines
 *   cmd_sensors.c  sensor-add and sensors
 *   report_html.c  the report's HTML: escaping, tables, embedded images
 *   cmd_report.c   report: work plane, surfaces, images, the HTML file
 *   luxrad.c       main: the command table, argv parsing, --help, dispatch
 *
 * The CLI is thin on purpose: it checks what it can check locally
 * (syntax, numbers, files) and leaves every semantic decision (ranges,
 * states) to the daemon, whose error it reports verbatim.
 */
#ifndef LUXRAD_CLIENT_H
#define LUXRAD_CLIENT_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "rad.h"
#include "rp.h"

#define LX_VERSION "0.1.0"
#define LX_DEFAULT_CONNECT "127.0.0.1:7420"
/* Replies may be much larger than requests (a grid with its points): the
 * client trusts its daemon further than the daemon trusts a client. */
#define LX_MAX_REPLY_HEADER ((size_t)256 << 20)

/* Exit codes (documented in --help). */
enum {
	LX_EXIT_OK = 0,
	LX_EXIT_DAEMON =
	        1,         /* the daemon returned an error; output unwritable */
	LX_EXIT_USAGE = 2, /* bad command line or input file */
	LX_EXIT_CONN = 3,  /* cannot connect, connection lost */
	LX_EXIT_JOB = 4    /* run --wait / watch: job failed or cancelled */
};

/*
 * Every option of the client's own, listed once: id, long name, takes a
 * value, value name, help.  The engine's options (eps, tol, threads...)
 * follow them, one per row of rad.h's RAD_OPTIONS, under their cli names:
 * LX_OPT_ENGINE + RAD_OPT_<field>.  Which command accepts which is said
 * by the command table.
 */
#define LX_OPTIONS(X)                                                          \
	X(HELP, "help", 0, NULL, "show help for the command")                  \
	X(JSON, "json", 0, NULL, "print the daemon's reply objects as JSON")   \
	X(CONNECT, "connect", 1, "ADDR",                                       \
	  "daemon address [$LUXRAD_CONNECT, 127.0.0.1:7420]")                  \
	X(TOKEN_FILE, "token-file", 1, "FILE",                                 \
	  "token [$LUXRAD_TOKEN_FILE, $LUXRAD_TOKEN]")                         \
	X(TLS_CA, "tls-ca", 1, "FILE",                                         \
	  "CA certificates for a tls: address [$LUXRAD_TLS_CA, the system's]") \
	X(NAME, "name", 1, "NAME", "a name for the scene or job")              \
	X(SOLVE, "solve", 0, NULL,                                             \
	  "also create a job and run it to convergence")                       \
	X(SOLVER, "solver", 1, "S", "hr | rmb | matrix | progressive [hr]")    \
	X(ITERATIONS, "iterations", 1, "N", "run N more iterations")           \
	X(CONVERGE, "converge", 0, NULL, "run until converged (the default)")  \
	X(SECONDS, "seconds", 1, "T", "run for a budget of T seconds")         \
	X(WAIT, "wait", 0, NULL, "block until the job stops running")          \
	X(POINTS, "points", 1, "FILE", "illuminance at the points in FILE")    \
	X(GRID, "grid", 0, NULL, "illuminance on a calculation grid")          \
	X(SURFACES, "surfaces", 0, NULL, "illuminance per surface (node)")     \
	X(ORIGIN, "origin", 1, "X,Y,Z", "grid: a corner of the rectangle")     \
	X(U, "u", 1, "X,Y,Z", "grid: first side, from the origin")             \
	X(V, "v", 1, "X,Y,Z", "grid: second side, from the origin")            \
	X(SPACING, "spacing", 1, "P",                                          \
	  "grid: point spacing in metres [EN 12464-1]")                        \
	X(NORMAL, "normal", 1, "X,Y,Z",                                        \
	  "surface normal (grid: [u x v]; sensor-add: [0,1,0])")               \
	X(AT, "at", 1, "X,Y,Z", "sensor-add: the sensor's position, metres")   \
	X(OUTPUT, "output", 1, "FILE",                                         \
	  "export, report: the file to write (-o)")                            \
	X(WORKPLANE_HEIGHT, "workplane-height", 1, "H",                        \
	  "report: work plane height above the floor, m [0.8]")                \
	X(BORDER, "border", 1, "B", "report: work plane border band, m [0.5]") \
	X(FLOOR, "floor", 1, "NODE",                                           \
	  "report: the node whose extent is the room's [floor]")               \
	X(SURFACE, "surface", 1, "NODE",                                       \
	  "report: a node to grid (repeatable) [every node]")                  \
	X(LUMINAIRE, "luminaire", 1, "NAME=FILE",                              \
	  "submit: the light NAME shines as the IES or EULUMDAT FILE "         \
	  "(repeatable)")

typedef enum lx_opt {
#define LX_OPT_ENUM_(id, name, arg, meta, help) LX_OPT_##id,
	LX_OPTIONS(LX_OPT_ENUM_)
#undef LX_OPT_ENUM_
	        LX_OPT_ENGINE,
	LX_OPT_COUNT = LX_OPT_ENGINE + RAD_NOPTIONS
} lx_opt;

/* Options accepted by a command, as a mask (at most 64 options). */
#define LX_BIT(o) ((uint64_t)1 << LX_OPT_##o)
#define LX_ENGINE_OPT(field) (LX_OPT_ENGINE + RAD_OPT_##field)
#define LX_ENGINE_BIT(field) ((uint64_t)1 << LX_ENGINE_OPT(field))
#define LX_ENGINE_BITS (((uint64_t)1 << LX_OPT_COUNT) - LX_BIT(ENGINE))
_Static_assert(LX_OPT_COUNT < 64, "options must fit a command's mask");

/* One option (args.c): long name, value name (NULL: a flag), help, and
 * whether it takes a value. */
typedef struct lx_opt_row {
	const char *name, *meta, *help;
	int arg;
} lx_opt_row;
extern const lx_opt_row lx_opt_table[LX_OPT_COUNT];

/* The connection to the daemon (net.c). */
typedef struct lx_conn {
	int fd;               /* -1 when closed */
	void *ssl;            /* OpenSSL's SSL (tls: addresses), or NULL */
	void *ssl_ctx;        /* ... and its SSL_CTX */
	unsigned char *buf;   /* receive buffer */
	size_t off, len, cap; /* consumed / filled / allocated */
	size_t pending; /* bytes of the last frame, consumed on next read */
	rp_limits lim;
	long long next_id;
	char where[300]; /* the address, for messages */
	json_t *hello;   /* the hello reply (limits, capabilities) */
} lx_conn;

#define LX_LIGHT_NAME_MAX 256 /* a --luminaire NAME, with the NUL */

typedef struct lx_ctx {
	const char *cmd;               /* the command name */
	const char *val[LX_OPT_COUNT]; /* option values (last one wins) */
	int given[LX_OPT_COUNT];       /* times each option was given */
	char **pos;                    /* positional arguments */
	int npos;
	int json;              /* --json */
	const char **surfaces; /* every --surface, in order */
	int nsurfaces;
	const char **luminaires; /* every --luminaire, in order */
	int nluminaires;
	lx_conn conn;
	int connected;
} lx_ctx;

/* An event seen while waiting for a reply (or in a watch loop). */
typedef void (*lx_event_fn)(void *ud, json_t *event);

/* ---------------------------------------------------------------- net.c */

/*
 * Connect (address from --connect, $LUXRAD_CONNECT, default) and say
 * hello (token from --token-file, $LUXRAD_TOKEN_FILE, $LUXRAD_TOKEN).
 * Returns an exit code; messages printed.
 */
int lx_open(lx_ctx *cx);
void lx_close(lx_ctx *cx);

/*
 * Send a request (an "id" is added; payload may be NULL) and wait for its
 * reply; events arriving meanwhile go to on_event (or are ignored).  On
 * success *reply is the reply (caller decrefs) and, if the reply has a
 * payload, *rpayload / *rlen point into the connection's buffer until the
 * next call.  Returns LX_EXIT_OK, LX_EXIT_DAEMON (error printed as
 * "luxrad: <code>: <message>"; *reply still set, for --json) or
 * LX_EXIT_CONN.
 */
int lx_request(lx_ctx *cx, json_t *req, const void *payload, size_t plen,
               json_t **reply, const unsigned char **rpayload, size_t *rlen,
               lx_event_fn on_event, void *ud);
/* The common case: no payloads, events ignored.  req is stolen. */
int lx_call(lx_ctx *cx, json_t *req, json_t **reply);
/*
 * Wait for the next frame that is an event (replies are not expected
 * here: one is a protocol error).  Returns LX_EXIT_OK with *event set, or
 * LX_EXIT_CONN / LX_EXIT_DAEMON (an unsolicited error, printed).
 */
int lx_next_event(lx_ctx *cx, json_t **event);

/* ----------------------------------------------------------- args.c */

/* Print "luxrad: <message>" and a hint, return LX_EXIT_USAGE. */
int lx_usage_error(const lx_ctx *cx, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));
/* Parse option o as a finite double / an integer in [lo, hi]; 1 absent,
 * 0 parsed, -1 usage error printed. */
int lx_opt_double(const lx_ctx *cx, lx_opt o, double *out);
int lx_opt_int(const lx_ctx *cx, lx_opt o, long long lo, long long hi,
               long long *out);
/* Parse "x,y,z"; -1 usage error printed. */
int lx_opt_vec3(const lx_ctx *cx, lx_opt o, double out[3]);
/* Positional argument i as a positive id ("job" / "scene" in messages). */
int lx_pos_id(const lx_ctx *cx, int i, const char *what, long long *out);
/* ------------------------------------------------------------ out.c */

/* Print a JSON value on stdout, one line. */
void lx_print_json(const json_t *v);
/* Human-readable bytes ("70.5 KiB"). */
const char *lx_fmt_bytes(double bytes, char *buf, size_t len);
/* Reply members: integer (0 when absent), number (0), string ("?"); a
 * number formatted with fmt or as bytes, "?" when absent or null. */
long long lx_jint(const json_t *o, const char *k);
double lx_jdbl(const json_t *o, const char *k);
const char *lx_jstr(const json_t *o, const char *k);
const char *lx_jnum(const json_t *o, const char *k, const char *fmt, char *buf,
                    size_t len);
const char *lx_jbytes(const json_t *o, const char *k, char *buf, size_t len);

/* ---------------------------------------------------------- cmds.c */

/* A request naming one object: {"cmd": name, key: id}. */
json_t *lx_req_id(rp_cmd cmd, const char *key, long long id);
/* Connect, send req (stolen) and wait for the reply, printed under
 * --json; the caller prints it otherwise and decrefs *reply either way. */
int lx_simple_call(lx_ctx *cx, json_t *req, json_t **reply);

/* ------------------------------------------------------------- commands */

int lx_cmd_submit(lx_ctx *cx);
int lx_cmd_scenes(lx_ctx *cx);
int lx_cmd_jobs(lx_ctx *cx);
int lx_cmd_create(lx_ctx *cx);
int lx_cmd_run(lx_ctx *cx);
int lx_cmd_control(lx_ctx *cx); /* pause, resume, cancel */
int lx_cmd_set(lx_ctx *cx);
int lx_cmd_delete(lx_ctx *cx); /* delete-job, delete-scene */
int lx_cmd_info(lx_ctx *cx);
int lx_cmd_status(lx_ctx *cx);
int lx_cmd_shutdown(lx_ctx *cx);
int lx_cmd_watch(lx_ctx *cx);
int lx_cmd_query(lx_ctx *cx);
int lx_cmd_export(lx_ctx *cx);
int lx_cmd_sensor_add(lx_ctx *cx);
int lx_cmd_sensors(lx_ctx *cx);
int lx_cmd_report(lx_ctx *cx);

/* Build job.create's "options" from the command line; -1 usage error. */
int lx_job_options(lx_ctx *cx, json_t *req);

/*
 * cmd_watch.c: having subscribed to job (its current state given), show its
 * events until it is neither queued nor running.  live: where to draw
 * the progress bar and statistics lines (a terminal), or NULL; json_lines:
 * print each event as a JSON line on stdout.  final_state receives the
 * last state.  Returns an exit code (LX_EXIT_JOB when the job failed or
 * was cancelled, LX_EXIT_CONN when the connection was lost).
 */
int lx_follow_job(lx_ctx *cx, long long job, const char *state, FILE *live,
                  int json_lines, char *final_state, size_t fslen);
/* Exit code for a final state. */
int lx_state_exit(const char *state);

/* -------------------------------------------------------- report_html.c */

/* Text with & < > " ' escaped, for element content and attributes. */
void lx_html_text(FILE *f, const char *s);
/* A number of an object ("-" when absent or null) with fmt. */
void lx_html_num(FILE *f, const json_t *o, const char *k, const char *fmt);
/* <img> of PNG bytes as a data: URI, alt text escaped. */
void lx_html_png(FILE *f, const unsigned char *png, size_t len,
                 const char *alt);
/* The page head (title escaped, inline CSS) and foot. */
void lx_html_head(FILE *f, const char *title);
void lx_html_foot(FILE *f);
/* The summary tables: scene, job, luminaires, accuracy and cost. */
void lx_html_summary(FILE *f, const json_t *job, const json_t *scene);

/* cmd_query.c: the points file format of luxrad-solve --points. */
int lx_points_load(const char *path, json_t **points, size_t *n);

#endif
