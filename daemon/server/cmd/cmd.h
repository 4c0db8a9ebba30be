/*
 * cmd.h -- luxradd's command layer, the top of the daemon: listeners and
 * connections, the command table and its handlers (scene.*, job.*,
 * query.*, export, subscriptions, sensors), events to subscribers, the
 * Prometheus endpoint and the Modbus glue.  It drives the service core
 * (core.h) and registers with it as an observer; the core never calls it.
 *
 * Files, lowest first (each calls only those above it in this list, and
 * the core):
 *   conn.c       connections: input framing, output queues, limits, auth;
 *                a decoded frame goes to on_frame (cmd_dispatch)
 *   reply.c      what handlers share: errors, deferred replies
 *   publish.c    events to subscribers, subscriptions, the drop policy
 *   job_reply.c  replies owed until a worker stops or a row is written
 *   mb_glue.c    the Modbus server fed from the core's events; sensors
 *   metrics.c    Prometheus text on a tiny HTTP/1.0 server
 *   scene_cmd.c  scene.* commands
 *   job_cmd.c    job.* commands
 *   query_cmd.c  query.* and export, run on the query threads
 *   sensor_cmd.c sensor.add / sensor.list
 *   dispatch.c   command table, dispatch, hello/status/shutdown
 *   server.c     the daemon put together: listeners, signals, the loop's
 *                turn, shutdown
 */
#ifndef LUXRAD_SRV_CMD_H
#define LUXRAD_SRV_CMD_H

#include <jansson.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "core.h"
#include "loop.h"
#include "modbus.h"
#include "rp.h"

typedef struct cmd_server cmd_server;
typedef struct cmd_conn cmd_conn;
typedef struct ssl_st SSL; /* OpenSSL's, for tls.c */
typedef struct ssl_ctx_st SSL_CTX;

/* ------------------------------------------------------------ connections */

typedef struct cmd_chunk {
	struct cmd_chunk *next;
	unsigned char *buf; /* owned */
	size_t len, off;
} cmd_chunk;

typedef struct cmd_sub {
	uint64_t job;
	uint64_t dropped; /* progress events dropped since the last iteration
	                     event delivered */
	uint64_t seq0;    /* state_seq told in the subscribe reply */
	uint32_t iter0;   /* iteration told in the subscribe reply */
} cmd_sub;

struct cmd_conn {
	el_watch w; /* ud: the cmd_server */
	uint64_t id;
	int fd;
	int listener_tcp;  /* accepted on TCP (else Unix) */
	int needs_token;   /* hello must carry the token */
	SSL *ssl;          /* TLS session (tls.c); NULL on plain sockets */
	int tls_ready;     /* the TLS handshake is done */
	int authed;        /* hello accepted */
	char peer[128];    /* for logs */
	unsigned char *in; /* input buffer */
	size_t in_off, in_len, in_cap;
	cmd_chunk *out_head, *out_tail;
	size_t out_bytes;   /* queued, not yet written */
	int busy;           /* a deferred reply is owed: read no more frames */
	int closing;        /* flush, then close */
	int stolen;         /* the input buffer was taken by a handler */
	int eof;            /* the peer closed its side */
	int wr_shut;        /* closing: our FIN was sent */
	size_t need;        /* bytes the frame at in_off needs, 0 unknown */
	int dead;           /* close at the end of this loop turn */
	int want_out;       /* EPOLLOUT armed */
	int reading;        /* EPOLLIN armed */
	double close_at;    /* closing: give up flushing at this time */
	char user[64];      /* who said hello ("" = the local admin) */
	rp_role role;       /* what they may do; NONE before hello */
	double last_active; /* rad_seconds() of the last byte in or out */
	double opened;      /* rad_seconds() at accept: the hello deadline */
	double hdr_start;   /* first byte of a header still incomplete; 0
	                       when none is being received */
	unsigned char addr[16]; /* peer key for the per-address limit: an
	                           IPv4 address or an IPv6 /64 */
	int addr_len;           /* 4, 8, or 0 (Unix: not counted) */
	cmd_sub *subs;
	int nsubs, subs_cap;
	cmd_conn *next, *prev;
};

/* ------------------------------------------------------------------ users */

/* ------------------------------------------------------------------- TLS */

/* The server context from tls_cert_file / tls_key_file (none: NULL);
 * -1 with msg, the old context kept. */
int cmd_tls_load(cmd_server *d, const srv_config *cfg, char *msg,
                 size_t msglen);
void cmd_tls_free(cmd_server *d);
/* A server-side TLS session on fd; NULL when it cannot be made. */
SSL *cmd_tls_new(cmd_server *d, int fd);
/* 1 done, 0 call again when the socket is ready, -1 failed (why). */
int cmd_tls_handshake(SSL *ssl, char *why, size_t len);
/* As read(2) / write(2); errno EAGAIN when OpenSSL wants the socket. */
ssize_t cmd_tls_read(SSL *ssl, void *buf, size_t len);
ssize_t cmd_tls_write(SSL *ssl, const void *buf, size_t len);
/* 1 if OpenSSL holds decrypted bytes not yet read. */
int cmd_tls_pending(SSL *ssl);
/* Send close_notify once, if the handshake was done. */
void cmd_tls_close_notify(SSL *ssl);

#define CMD_USER_NAME_MAX 64

/* One line of the users file (users.c). */
typedef struct cmd_user {
	char name[CMD_USER_NAME_MAX];
	rp_role role;
	unsigned char hash[32]; /* SHA-256 of the token */
} cmd_user;

/* Read cfg->users_file (none: no users); -1 with msg, the old kept. */
int cmd_users_load(cmd_server *d, const srv_config *cfg, char *msg,
                   size_t msglen);
/* The user whose token this is, or NULL. */
const cmd_user *cmd_users_check(const cmd_server *d, const char *token);
/* 1 if c may see (and, with its role, act on) an object of owner. */
int cmd_visible(const cmd_conn *c, const char *owner);
/* luxradd user-add: append NAME ROLE and a new token's hash to path,
 * print the token on out; -1 with msg. */
int cmd_user_add(const char *path, const char *name, const char *role,
                 FILE *out, char *msg, size_t msglen);

/*
 * Why the daemon refused or closed a connection itself, counted for
 * /metrics: at accept (max_connections, per_address, no_descriptors), to
 * make room (evicted: no hello yet), on a deadline, or for the closing
 * error the peer earned (auth, protocol).  Shutdown is not counted.
 */
#define CMD_REFUSALS(X)                                                        \
	X(MAX_CONNECTIONS, "max_connections")                                  \
	X(PER_ADDRESS, "per_address")                                          \
	X(NO_DESCRIPTORS, "no_descriptors")                                    \
	X(EVICTED, "evicted")                                                  \
	X(HELLO_TIMEOUT, "hello_timeout")                                      \
	X(HEADER_TIMEOUT, "header_timeout")                                    \
	X(IDLE_TIMEOUT, "idle_timeout")                                        \
	X(AUTH, "auth")                                                        \
	X(PROTOCOL, "protocol")                                                \
	X(SLOW_CONSUMER, "slow_consumer")

typedef enum cmd_refusal {
#define CMD_REFUSAL_ENUM_(name, str) CMD_REFUSED_##name,
	CMD_REFUSALS(CMD_REFUSAL_ENUM_)
#undef CMD_REFUSAL_ENUM_
	        CMD_REFUSED_COUNT
} cmd_refusal;

const char *cmd_refusal_name(cmd_refusal r);

cmd_conn *cmd_conn_find(cmd_server *d, uint64_t id);
/* The spare descriptor (cmd_server_listen); -1 when none can be had. */
int cmd_conn_init(cmd_server *d);
void cmd_conn_accept(cmd_server *d, int lfd, int tcp, int needs_token, int tls);
/* Queue bytes (ownership of buf taken); flushes what the socket takes. */
int cmd_conn_send(cmd_server *d, cmd_conn *c, unsigned char *buf, size_t len);
/* Encode and queue a JSON frame (header not stolen). */
int cmd_conn_send_json(cmd_server *d, cmd_conn *c, json_t *hdr);
/* Send an error frame; closes the connection when the code says so. */
void cmd_conn_send_error(cmd_server *d, cmd_conn *c, json_t *id, rp_err code,
                         const char *fmt, ...)
        __attribute__((format(printf, 5, 6)));
/* Forget queued output not yet started (the connection is closing). */
void cmd_conn_drop_queued(cmd_conn *c);
/* Stop reading; flush what is queued (bounded time); then close. */
void cmd_conn_close_after_flush(cmd_server *d, cmd_conn *c);
/* A deferred reply was delivered: process buffered frames. */
void cmd_conn_unbusy(cmd_server *d, cmd_conn *c);
void cmd_conn_free_all(cmd_server *d);

/* Close dead connections (I/O thread, end of a loop turn). */
void cmd_conn_reap(cmd_server *d);
/* Deadlines (hello, header, idle), stuck flushes, and the bytes OpenSSL
 * holds decrypted on TLS connections (end of every loop turn). */
void cmd_conn_tick(cmd_server *d, double now);
/* Reading paused/unpaused by busy / output pressure. */
void cmd_conn_update_events(cmd_server *d, cmd_conn *c);
/*
 * Take the connection's input buffer (holding the current frame) away:
 * the caller owns *buf (free), the connection keeps only the bytes after
 * used (the frame's end).
 */
unsigned char *cmd_conn_steal_input(cmd_conn *c, size_t used);

/* ------------------------------------------------------- command handlers */

typedef enum cmd_result {
	CMD_REPLY = 0, /* *res holds the result members; send ok */
	CMD_ERROR,     /* err filled; send the error */
	CMD_DEFERRED,  /* the reply comes later (conn busy) */
} cmd_result;

typedef struct cmd_req {
	cmd_server *d;
	srv *s; /* &d->core */
	cmd_conn *c;
	rp_cmd cmd;
	json_t *hdr;                  /* the request header (borrowed) */
	json_t *id;                   /* "id" or NULL (borrowed) */
	const unsigned char *payload; /* NULL without "bytes" */
	size_t payload_len;
	size_t frame_used; /* bytes of this frame in the input buffer */
	json_t *res;       /* result object to fill (CMD_REPLY) */
	rp_error err;      /* CMD_ERROR */
} cmd_req;

typedef cmd_result (*cmd_fn)(cmd_req *r);

/* reply.c: what handlers share.  Fill r->err and return CMD_ERROR. */
cmd_result cmd_req_fail(cmd_req *r, rp_err code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* Fail r with nomem when the daemon's memory limit is reached (no new
 * upload, job or run while it is): 1 if it did. */
int cmd_req_memory_full(cmd_req *r);
/* Send a reply owed to a connection that may be gone (I/O thread):
 * reply is stolen; unbusies the connection. */
void cmd_reply_deferred(cmd_server *d, uint64_t conn_id, json_t *reply);
/* Same with a pre-encoded frame (buf owned), plus an optional payload. */
void cmd_reply_deferred_raw(cmd_server *d, uint64_t conn_id, unsigned char *buf,
                            size_t len, unsigned char *payload, size_t plen);
/*
 * Run task t (the first member of a malloc'ed struct) on pool for request
 * r: done() then owes r's connection the reply.  Returns CMD_DEFERRED.
 */
cmd_result cmd_req_defer(cmd_req *r, srv_pool *pool, srv_task *t,
                         void (*run)(srv *s, srv_task *t),
                         void (*done)(srv *s, srv_task *t));
/* From a deferred task's done(): send reply (stolen) to the connection
 * owed it, release the request id, free the task. */
void cmd_task_reply(srv *s, srv_task *t, json_t *reply);
/* Look up {job: id} in a request; CMD_ERROR with not_found. */
srv_job *cmd_req_job(cmd_req *r, int *failed);
/* The request's "scene": NULL (r failed) when absent or not the
 * connection's to see. */
srv_scene *cmd_req_scene(cmd_req *r);
/* The same for a scene id the caller has parsed. */
srv_scene *cmd_find_scene(cmd_req *r, uint64_t id);
/* Map an engine status to a wire error code (every status has one). */
rp_err cmd_err_from_rad(rad_status st);

/* dispatch.c: check one decoded frame, run its handler (I/O thread);
 * conn.c calls it through cmd_server.on_frame. */
void cmd_dispatch(cmd_server *d, cmd_conn *c, rp_frame *f, size_t used);

cmd_result cmd_scene_upload(cmd_req *r);
cmd_result cmd_scene_list(cmd_req *r);
cmd_result cmd_scene_info(cmd_req *r);
cmd_result cmd_scene_delete(cmd_req *r);
cmd_result cmd_job_create(cmd_req *r);
cmd_result cmd_job_list(cmd_req *r);
cmd_result cmd_job_info(cmd_req *r);
cmd_result cmd_job_run(cmd_req *r);
cmd_result cmd_job_pause(cmd_req *r);
cmd_result cmd_job_resume(cmd_req *r);
cmd_result cmd_job_cancel(cmd_req *r);
cmd_result cmd_job_set(cmd_req *r);
cmd_result cmd_job_delete(cmd_req *r);
cmd_result cmd_subscribe(cmd_req *r);
cmd_result cmd_unsubscribe(cmd_req *r);
cmd_result cmd_query_points(cmd_req *r);
cmd_result cmd_query_grid(cmd_req *r);
cmd_result cmd_query_surfaces(cmd_req *r);
cmd_result cmd_query_node(cmd_req *r);
cmd_result cmd_export(cmd_req *r);
cmd_result cmd_sensor_add(cmd_req *r);
cmd_result cmd_sensor_list(cmd_req *r);

/* publish.c: subscriptions (an observer of the core). */
int cmd_subs_start(cmd_server *d);

/* job_reply.c: replies owed when a job leaves "running" (pause, cancel;
 * an observer of the core), after its row is written or removed. */
int cmd_waiters_start(cmd_server *d);
void cmd_waiters_free_all(cmd_server *d);
int cmd_job_add_waiter(cmd_server *d, srv_job *j, uint64_t conn_id, json_t *id);
/* Persist a job's row on the store thread, then send reply (stolen);
 * returns CMD_DEFERRED (or CMD_ERROR with r->err filled). */
cmd_result cmd_persist_then_reply(cmd_req *r, srv_job *j, json_t *reply);
/* Remove a job's row and checkpoint, releasing the registry's ref to j
 * on the store thread; replies when done (CMD_DEFERRED). */
cmd_result cmd_job_delete_then_reply(cmd_req *r, srv_job *j);

/* metrics.c */
/* Accept on the metrics listener; the first call starts its timer. */
void cmd_metrics_accept(cmd_server *d, int lfd);
void cmd_metrics_free_all(cmd_server *d);

/* mb_glue.c: the daemon's side of the Modbus server (modbus.h), an
 * observer of the core.  All on the I/O thread unless said otherwise. */
struct cmd_mbpub;
/* Start the server (modbus_listen none: nothing started); -2 with msg
 * when it cannot (bad address, port in use). */
int cmd_mb_start(cmd_server *d, char *msg, size_t msglen);
/* After the worker threads are joined. */
void cmd_mb_stop(cmd_server *d);
/* "modbus HOST:PORT" for luxradd.addr; 0 when the server is off. */
int cmd_mb_addr_text(cmd_server *d, char *buf, size_t len);
json_t *cmd_mb_status_json(cmd_server *d);
char *cmd_mb_metrics_text(cmd_server *d); /* Prometheus lines, malloc'ed */
/* A job's sensor: the scene's or one added with sensor.add. */
typedef struct cmd_sensor {
	char name[MB_SENSOR_NAME_MAX];
	double pt[6]; /* x y z nx ny nz, as query.points takes them */
	int added;    /* sensor.add (else from the scene) */
	int64_t iter; /* iteration of lux; -1 = none yet */
	double lux;
} cmd_sensor;
/* The job's sensors (*n of them; NULL and 0 when out of memory). */
const cmd_sensor *cmd_mb_sensors(cmd_server *d, srv_job *j, size_t *n);
/* Add a sensor, publish its slot and evaluate it: 0 with *slot (-1 when
 * the map has no room), -1 out of memory, -2 the name is taken. */
int cmd_mb_sensor_add(cmd_server *d, srv_job *j, const char *name,
                      const double pt[6], int *slot);
/* The sensor's Modbus slot, or -1. */
int cmd_mb_sensor_slot(cmd_server *d, uint64_t job, const char *name);

/* -------------------------------------------------------------- the daemon */

#define CMD_MAX_LISTENERS 3

typedef struct cmd_listener {
	el_watch w; /* ud: the cmd_server */
	int fd;
	int kind;        /* 0 tcp, 1 unix, 2 metrics */
	int needs_token; /* tcp beyond loopback */
	int tls;         /* protocol over TLS (tls.c) */
	char text[4200]; /* "tcp HOST:PORT" line for luxradd.addr */
} cmd_listener;

typedef struct cmd_waiter cmd_waiter;

/* The daemon: the core it drives, and what the command layer owns. */
struct cmd_server {
	int argc;
	char **argv;
	el_loop *loop;
	srv core; /* the service (core.h); cmd_of() finds us from it */

	/* I/O thread */
	cmd_listener lis[CMD_MAX_LISTENERS];
	int nlis;
	cmd_conn *conns;
	int nconns;
	uint64_t next_conn_id;
	void *https; /* metrics.c's connection list */
	int nhttps;
	uint64_t http_timer; /* metrics.c's timer, once a request came */
	cmd_waiter *waiters; /* job_cmd.c: replies owed */
	char *token;         /* NULL = none configured */
	size_t token_len;
	cmd_user *users; /* the users file (users.c) */
	int nusers;
	int users_on;     /* a users file is configured */
	SSL_CTX *tls_ctx; /* tls.c: NULL when no certificate is configured */
	/* A decoded frame, handed on by conn.c (cmd_dispatch). */
	void (*on_frame)(cmd_server *d, cmd_conn *c, rp_frame *f, size_t used);
	const char
	        *shutdown_asked; /* why, once asked: the turn's end starts it */
	int shutting_down;       /* 1 checkpointing, 2 flushing */
	int loop_done;
	double shutdown_flush_at;
	uint64_t cmd_calls[RP_CMD_COUNT], cmd_errors[RP_CMD_COUNT];
	uint64_t conns_total, events_dropped, slow_consumers;
	uint64_t refused[CMD_REFUSED_COUNT]; /* by cause (conn.c) */
	void *lingers; /* conn.c: refused sockets read until the peer's EOF */
	int nlingers;
	int spare_fd; /* conn.c: held to accept and refuse at EMFILE */
	char addr_path[4200];

	struct mb_server *mb;    /* Modbus server (NULL when off) */
	struct cmd_mbpub *mbpub; /* mb_glue.c's state (I/O thread) */
};

/* The command layer's state around a core it was handed back (task
 * callbacks): every srv the daemon runs is the core of a cmd_server. */
static inline cmd_server *cmd_of(srv *s)
{
	return (cmd_server *)((char *)s - offsetof(cmd_server, core));
}

/* server.c */
int cmd_server_init(cmd_server *d, const srv_config *cfg, int argc, char **argv,
                    char *msg, size_t msglen);
int cmd_server_listen(cmd_server *d, char *msg, size_t msglen);
int cmd_server_start(cmd_server *d, char *msg, size_t msglen);
int cmd_server_run(cmd_server *d);
void cmd_server_destroy(cmd_server *d);
void cmd_server_shutdown(cmd_server *d, const char *why);
/* Read the token file into d->token; -1 with msg on failure. */
int cmd_load_token(cmd_server *d, const srv_config *cfg, char *msg,
                   size_t msglen);
/* Does this connection need the token? */
int cmd_token_needed(const cmd_server *d, int listener_needs);

#endif
