/*
 * rp.h -- the luxrad wire protocol: frame codec, command table, error codes
 * and limits, shared by the daemon (luxradd) and the client (luxrad).
 *
 * The library is pure: functions over byte buffers and jansson values, no
 * sockets, no engine, no globals that change.  The normative description
 * of every message is protocol/PROTOCOL.md; this header is its C face.
 *
 * WIRE FORMAT (version 1)
 * A connection carries frames in both directions.  A frame is
 *   - a header: one JSON object in UTF-8 on one line, ended by "\n"
 *     (JSON encoders escape newlines inside strings, so a line is a frame);
 *   - then, when the header has a member "bytes": N (a non-negative
 *     integer), exactly N raw payload bytes (a glTF/GLB scene uploaded,
 *     a GLB exported).  No base64 anywhere.
 * Requests carry "cmd" (a name from the command table) and an optional
 * "id" (any JSON scalar, echoed in the reply).  Replies carry "ok": true
 * and the command's results, or "ok": false and
 *   "error": {"code": "<rp_err name>", "message": "..."}.
 * Events (subscriptions) carry "event" and no "ok"; they may arrive between
 * a request and its reply.  The first request on a connection must be
 * "hello" (version, optional token); anything else gets "auth_required".
 *
 * LIMITS
 * The decoder refuses a header line longer than max_header_bytes and a
 * payload longer than max_payload_bytes before reading it: the peer gets
 * "too_large" and the connection is closed (the stream cannot be re-synced
 * without reading the payload).  A header that is not a JSON object, or
 * whose "bytes" is not a non-negative integer, is "bad_frame".
 */
#ifndef LUXRAD_RP_H
#define LUXRAD_RP_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

#define RP_VERSION 1
#define RP_DEFAULT_PORT 7420            /* protocol, TCP */
#define RP_DEFAULT_METRICS_PORT 7421    /* Prometheus /metrics, HTTP */
#define RP_ENV_CONNECT "LUXRAD_CONNECT" /* client: daemon address */
#define RP_ENV_TOKEN "LUXRAD_TOKEN"     /* client: the token itself */
#define RP_ENV_TOKEN_FILE "LUXRAD_TOKEN_FILE"

/* Default frame limits; the daemon's config may lower or raise them. */
#define RP_DEFAULT_MAX_HEADER_BYTES (4u << 20)         /* 4 MiB */
#define RP_DEFAULT_MAX_PAYLOAD_BYTES ((size_t)1 << 30) /* 1 GiB */

/* ------------------------------------------------------------ error codes */
/*
 * Wire error codes, listed once.  The string is what goes on the wire;
 * "close" says whether the daemon closes the connection after sending it.
 */
#define RP_ERRORS(X)                                                           \
	X(OK, "ok", 0)                   /* not an error */                    \
	X(BAD_FRAME, "bad_frame", 1)     /* header not a JSON object... */     \
	X(TOO_LARGE, "too_large", 1)     /* header or payload over limit */    \
	X(BAD_REQUEST, "bad_request", 0) /* missing/ill-typed argument */      \
	X(UNKNOWN_COMMAND, "unknown_command", 0)                               \
	X(VERSION, "version", 1) /* hello with unsupported version */          \
	X(AUTH_REQUIRED, "auth_required", 1) /* request before hello */        \
	X(AUTH_FAILED, "auth_failed", 1)     /* wrong or missing token */      \
	X(NOT_FOUND, "not_found", 0)         /* no such scene / job */         \
	X(FORBIDDEN, "forbidden", 0)         /* the token's role may not */    \
	X(STATE, "state", 0)                 /* not allowed in this state */   \
	X(BUSY, "busy", 0)                   /* scene still used by jobs */    \
	X(LIMIT, "limit", 0)                 /* jobs, scenes, subscriptions */ \
	X(INVALID, "invalid", 0)             /* scene or option refused */     \
	X(NOMEM, "nomem", 0)                 /* out of memory or budget */     \
	X(IO, "io", 0)                       /* data directory write failed */ \
	X(INTERNAL, "internal", 0)           /* a bug: please report */        \
	X(SHUTTING_DOWN, "shutting_down", 1)                                   \
	X(IDLE_TIMEOUT, "idle_timeout", 1)                                     \
	X(HELLO_TIMEOUT, "hello_timeout", 1)   /* no hello in time */          \
	X(HEADER_TIMEOUT, "header_timeout", 1) /* header line too slow */      \
	X(TOO_MANY_CONNECTIONS, "too_many_connections", 1)                     \
	X(SLOW_CONSUMER, "slow_consumer", 1) /* output buffer overflowed */

typedef enum rp_err {
#define RP_ERR_ENUM_(name, str, close) RP_ERR_##name,
	RP_ERRORS(RP_ERR_ENUM_)
#undef RP_ERR_ENUM_
	        RP_ERR_COUNT
} rp_err;

const char *rp_err_name(rp_err e);
/* 1 if the daemon closes the connection after this error. */
int rp_err_closes(rp_err e);
/* Parse a wire name; RP_ERR_INTERNAL for an unknown one. */
rp_err rp_err_parse(const char *name);

typedef struct rp_error {
	rp_err code;
	char msg[256]; /* names the offending field, byte offset... */
} rp_error;

/* --------------------------------------------------------- command table */
/*
 * Every request, listed once: wire name, whether a payload may follow the
 * header ("bytes"), the least role that may send it (rp_role), and a
 * one-line summary (used by --help and docs).  The daemon dispatches on
 * rp_cmd; the arguments of each are specified in PROTOCOL.md and
 * validated with the rp_arg_* getters below.
 */
#define RP_COMMANDS(X)                                                         \
	X(HELLO, "hello", 0, NONE, "open the session: version, token")         \
	X(STATUS, "status", 0, READ, "daemon memory, jobs by state, uptime")   \
	X(SHUTDOWN, "shutdown", 0, ADMIN,                                      \
	  "checkpoint every job and stop the daemon")                          \
	X(SCENE_UPLOAD, "scene.upload", 1, SUBMIT,                             \
	  "upload glTF/GLB bytes as a scene")                                  \
	X(SCENE_LIST, "scene.list", 0, READ, "list scenes")                    \
	X(SCENE_INFO, "scene.info", 0, READ,                                   \
	  "one scene: counts, memory, jobs")                                   \
	X(SCENE_DELETE, "scene.delete", 0, SUBMIT, "free a scene no job uses") \
	X(JOB_CREATE, "job.create", 0, SUBMIT,                                 \
	  "a solve job: scene, solver, options")                               \
	X(JOB_LIST, "job.list", 0, READ, "list jobs")                          \
	X(JOB_INFO, "job.info", 0, READ,                                       \
	  "one job: state, options, latest stats")                             \
	X(JOB_RUN, "job.run", 0, SUBMIT,                                       \
	  "step N / to convergence / for a budget")                            \
	X(JOB_PAUSE, "job.pause", 0, SUBMIT,                                   \
	  "pause after the current iteration")                                 \
	X(JOB_RESUME, "job.resume", 0, SUBMIT, "resume a paused job")          \
	X(JOB_CANCEL, "job.cancel", 0, SUBMIT,                                 \
	  "cancel (stops within an iteration)")                                \
	X(JOB_SET, "job.set", 0, SUBMIT, "change eps between iterations")      \
	X(JOB_DELETE, "job.delete", 0, SUBMIT, "forget a finished job")        \
	X(SUBSCRIBE, "subscribe", 0, READ, "stream a job's events")            \
	X(UNSUBSCRIBE, "unsubscribe", 0, READ,                                 \
	  "stop streaming a job's events")                                     \
	X(QUERY_POINTS, "query.points", 0, READ, "lux at points")              \
	X(QUERY_GRID, "query.grid", 0, READ, "lux on a calculation grid")      \
	X(QUERY_SURFACES, "query.surfaces", 0, READ, "lux per surface (node)") \
	X(QUERY_NODE, "query.node", 0, READ,                                   \
	  "lux on a grid over a node's faces")                                 \
	X(EXPORT, "export", 0, READ, "the solved mesh as GLB (payload)")       \
	X(SENSOR_ADD, "sensor.add", 0, SUBMIT,                                 \
	  "a named illuminance sensor on a job")                               \
	X(SENSOR_LIST, "sensor.list", 0, READ, "a job's sensors and latest lux")

typedef enum rp_cmd {
#define RP_CMD_ENUM_(name, str, payload, role, help) RP_CMD_##name,
	RP_COMMANDS(RP_CMD_ENUM_)
#undef RP_CMD_ENUM_
	        RP_CMD_COUNT
} rp_cmd;

/*
 * Roles, least to most: a connection's token names one (PROTOCOL.md §4).
 * read: status, lists, info, queries, export, subscriptions; submit: that,
 * plus uploads and jobs of its own; admin: every object, shutdown.
 */
typedef enum rp_role {
	RP_ROLE_NONE, /* hello: before any role is known */
	RP_ROLE_READ,
	RP_ROLE_SUBMIT,
	RP_ROLE_ADMIN
} rp_role;

const char *rp_role_name(rp_role r);
/* -1 when name is none of "read", "submit", "admin". */
int rp_role_parse(const char *name);
/* The least role that may send c. */
rp_role rp_cmd_role(rp_cmd c);
const char *rp_cmd_name(rp_cmd c);
const char *rp_cmd_help(rp_cmd c);
int rp_cmd_takes_payload(rp_cmd c);
/* Look a wire name up; returns -1 (as int) when unknown. */
int rp_cmd_lookup(const char *name);

/* ----------------------------------------------------------- frame codec */
typedef struct rp_limits {
	size_t max_header_bytes;
	size_t max_payload_bytes;
} rp_limits;

void rp_limits_default(rp_limits *l);

/*
 * Incremental decoder over a receive buffer.  The caller appends bytes to
 * its own buffer and calls rp_frame_decode on the unread part:
 *   RP_DECODE_NEED  more bytes needed (*used is 0);
 *   RP_DECODE_FRAME a whole frame: *out holds the header (a new reference,
 *                   caller json_decref's it) and the payload (pointing
 *                   into buf, valid until the caller consumes *used bytes);
 *   RP_DECODE_ERROR err says why (bad_frame / too_large); the stream
 *                   cannot continue.
 * A header line over the limit is detected as soon as that many bytes are
 * buffered without a newline, so a peer cannot make the buffer grow.
 */
typedef enum rp_decode {
	RP_DECODE_NEED = 0,
	RP_DECODE_FRAME,
	RP_DECODE_ERROR
} rp_decode;

typedef struct rp_frame {
	json_t *header;
	const unsigned char *payload; /* NULL when the header has no "bytes" */
	size_t payload_len;
} rp_frame;

rp_decode rp_frame_decode(const rp_limits *lim, const unsigned char *buf,
                          size_t len, rp_frame *out, size_t *used,
                          rp_error *err);

/*
 * Encode a frame: the header (compact JSON, one line, "\n"), then the
 * payload if any.  When payload_len > 0 (or payload != NULL) the header
 * gets "bytes": payload_len set first; otherwise a "bytes" member is
 * removed (the peer would wait for a payload).  *out is malloc'ed (caller
 * frees); returns 0, or -1 on allocation failure, a header that is not an
 * object, or payload NULL with payload_len > 0.  The header is not stolen.
 */
int rp_frame_encode(json_t *header, const void *payload, size_t payload_len,
                    unsigned char **out, size_t *out_len);

/*
 * Encode only the header line of a frame whose payload of payload_len
 * bytes the caller sends itself (writev, a file, a large GLB: no copy).
 * Sets "bytes": payload_len (also when 0) in the header; *out is
 * malloc'ed; returns 0 or -1.  Without a payload (and with a header that
 * holds no "bytes" member), rp_frame_encode(h, NULL, 0, ...) is the one.
 */
int rp_frame_encode_header(json_t *header, size_t payload_len,
                           unsigned char **out, size_t *out_len);

/* --------------------------------------------------------------- messages */
/* {"id": id?, "ok": true} (id may be NULL); new reference. */
json_t *rp_reply_ok(json_t *id);
/* {"id": id?, "ok": false, "error": {"code": ..., "message": ...}}. */
json_t *rp_reply_error(json_t *id, rp_err code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* {"cmd": name} with an integer id when id >= 0. */
json_t *rp_request(rp_cmd cmd, long long id);
/*
 * A reply's outcome: RP_ERR_OK, or the code of its "error" (message copied
 * to err).  A reply that is neither well-formed success nor error is
 * RP_ERR_BAD_FRAME.
 */
rp_err rp_reply_status(const json_t *reply, rp_error *err);

/*
 * Typed argument getters for request validation.  Each returns 0 and
 * stores the value, 1 when the member is absent and not required (the
 * output is left as the caller's default), or -1 with err filled
 * (RP_ERR_BAD_REQUEST, naming the member and what was expected).
 */
int rp_arg_u64(const json_t *obj, const char *key, int required, uint64_t *out,
               rp_error *err);
int rp_arg_double(const json_t *obj, const char *key, int required, double *out,
                  rp_error *err); /* finite only */
int rp_arg_bool(const json_t *obj, const char *key, int required, int *out,
                rp_error *err);
int rp_arg_string(const json_t *obj, const char *key, int required,
                  const char **out, rp_error *err); /* borrowed */
/* A JSON array of n doubles (finite), e.g. a point or a normal. */
int rp_arg_vec(const json_t *obj, const char *key, int required, double *out,
               size_t n, rp_error *err);

/*
 * Points: an array of [x, y, z, nx, ny, nz] arrays -> malloc'ed doubles
 * (6 per point; caller frees).  Refuses non-finite values, zero normals
 * and more than max_points points.
 */
int rp_arg_points(const json_t *obj, const char *key, size_t max_points,
                  double **out, size_t *n, rp_error *err);

/* --------------------------------------------------------------- address */
/*
 * Daemon addresses: "unix:/path", "/path" (Unix socket), "tcp:host:port",
 * "host:port", "host" (default port), "[v6]:port".  Pure parsing; no DNS.
 * Messages name the text and what is wrong in it (see rp_addr.c).
 */
typedef enum rp_addr_kind { RP_ADDR_TCP = 0, RP_ADDR_UNIX } rp_addr_kind;

typedef struct rp_addr {
	rp_addr_kind kind;
	char host[256]; /* TCP: host name or literal, without brackets */
	uint16_t port;  /* TCP */
	int tls;        /* TCP: "tls:" or "tls://" given (connect only) */
	char path[108]; /* Unix: sun_path */
} rp_addr;

/* An address to connect to: every form, port 1..65535.  0, or -1 with
 * err filled (RP_ERR_BAD_REQUEST). */
int rp_addr_parse(const char *text, rp_addr *out, rp_error *err);
/*
 * A TCP listener's address (listen_tcp, metrics_listen, modbus_listen):
 * HOST:PORT or [V6]:PORT only, the port required, 0 allowed (any free
 * port).  Same grammar and messages as rp_addr_parse.
 */
int rp_addr_parse_listen(const char *text, rp_addr *out, rp_error *err);
/*
 * 1 if a TCP host is a loopback literal (127.0.0.0/8, ::1,
 * ::ffff:127.x.y.z) or "localhost", and for a Unix socket (local by
 * nature); 0 for anything else, names and wildcards included.
 */
int rp_addr_is_loopback(const rp_addr *a);

/* ------------------------------------------------------------- utilities */
/*
 * One line of a points file (the format of luxrad --points and
 * luxrad-solve --points): six finite numbers "x y z nx ny nz" separated
 * by blanks, the normal not zero; '#' starts a comment to the end of the
 * line.  Returns 1 and fills p for a point, 0 for a blank or comment
 * line, -1 with a reason in *why.
 */
int rp_point_line_parse(const char *line, double p[6], const char **why);

/* ---------------------------------------------- command-line tools (rp_cli.c)
 */

/*
 * One row of a command-line tool's option table: "[-o, ]--name METAVAR"
 * in 22 columns (shortopt 0: none; metavar NULL: a flag), then the help
 * and " [def]" (def NULL or "": none) wrapped at 79 columns under itself.
 */
void rp_help_row(FILE *f, char shortopt, const char *name, const char *metavar,
                 const char *help, const char *def);

/*
 * argv as the tools read it: "--name value", "--name=value", flags, "-h",
 * "--" (everything after it positional), and one positional argument,
 * the scene, stored in *scene.  The tool says what its options are:
 *   find  0 if the name (len bytes, not NUL-terminated) is an option,
 *         with *metavar its value's name or NULL for a flag
 *   set   store a value (NULL for a flag)
 * The callbacks return 0, RP_CLI_USAGE with a message in msg, or
 * RP_CLI_HELP to stop with *help set (as "-h" does).  rp_cli_scan returns
 * 0 or RP_CLI_USAGE with the message: an unknown option, a value given to
 * a flag or missing, a second scene, or what a callback said.
 */
enum { RP_CLI_USAGE = 2, RP_CLI_HELP = 3 };
typedef struct rp_cli_ops {
	int (*find)(void *ud, const char *name, size_t len,
	            const char **metavar);
	int (*set)(void *ud, const char *name, size_t len, const char *value,
	           char *msg, size_t msglen);
} rp_cli_ops;
int rp_cli_scan(int argc, char **argv, const rp_cli_ops *ops, void *ud,
                const char **scene, int *help, char *msg, size_t len);
/*
 * Read a points file (rp_point_line_parse's format): *xyz gets 6 doubles
 * per point (malloc'ed, the caller frees; NULL when there are none), *n
 * the count.  Returns 0; RP_CLI_USAGE with "PATH:LINE: why" for a
 * malformed line; -1 with the reason when the file cannot be opened or
 * read, or memory runs out.
 */
int rp_points_read(const char *path, double **xyz, size_t *n, char *msg,
                   size_t len);
/* Format a usage message into msg; returns RP_CLI_USAGE. */
int rp_cli_fail(char *msg, size_t len, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* A whole string as a finite double: 0, or -1 (nothing else touched). */
int rp_cli_double(const char *s, double *out);
/* The row of a tool's option table (n rows of size bytes, each starting
 * with its name as a const char *) named name (len bytes); NULL if none. */
const void *rp_cli_find(const void *rows, size_t n, size_t size,
                        const char *name, size_t len);

/* Constant-time comparison of two byte strings (lengths may differ). */
int rp_token_equal(const void *a, size_t alen, const void *b, size_t blen);

/*
 * The EN 12464-1 grid spacing for a calculation area whose longer side is
 * d metres: p = 0.2 * 5^log10(d), capped at 10 m (from d ~ 269 m on).
 * d below 0.01 m -- zero, negative and NaN included -- is taken as
 * 0.01 m, giving p = 8 mm; an infinite d gives 10 m.
 */
double rp_grid_spacing(double d_m);

#ifdef __cplusplus
}
#endif
#endif
