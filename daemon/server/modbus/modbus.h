/*
 * modbus.h -- luxradd's Modbus TCP server (prefix mb_): read-only input
 * registers that publish the daemon's state, its jobs' progress and the
 * illuminance at named sensors, for PLCs, SCADA and building management
 * systems.  The register map is regmap.h; MODBUS.md documents it.
 *
 * The server runs on its own thread (libmodbus calls block): one thread
 * polls the listening socket and every client, reads each client's bytes
 * without blocking into its own buffer and hands only complete requests
 * to libmodbus, so a slow, silent or hostile client never stalls another
 * one, nor the daemon.
 *
 * The daemon publishes values from any thread with the mb_publish_*
 * calls: they encode into the register image under one mutex (a leaf
 * lock, held for a few microseconds, never across I/O or a callback) and
 * the server copies the registers of a request under the same mutex, so
 * a response is one consistent snapshot and the two registers of a
 * 32-bit value are never torn.
 *
 * Slots.  Jobs and sensors sit in fixed slots (MODBUS.md, "Slots"):
 *   - a job takes the lowest free job slot the first time it is
 *     published and keeps it until mb_job_remove; when every slot is
 *     taken it stays unslotted (its values are kept) and takes the
 *     lowest free slot when one frees, the oldest unslotted job first
 *     (lowest id);
 *   - a sensor (job id, name) likewise among the sensor slots; removing
 *     a job removes its sensors.
 * So a client may rely on "slot 0 is this job" for the job's lifetime.
 * At startup, publish restored jobs in id order.
 *
 * All mb_publish_* / mb_*_remove calls accept a NULL server (no-ops), and
 * work on a server whose modbus_listen is off (state "off": the image is
 * kept but not served), so the daemon calls them unconditionally.
 */
#ifndef LUXRAD_SRV_MODBUS_H
#define LUXRAD_SRV_MODBUS_H

#include <stddef.h>
#include <stdint.h>

#include "regmap.h"

/* --------------------------------------------------------------- config */

/*
 * The config keys, once: X(key, field, type, lo, hi, metavar, default,
 * help).  type: LISTEN (host:port or none), INT (lo..hi), ORDER (abcd /
 * cdab), REAL (lo..hi), SECONDS (lo..hi; s, ms, m, h suffixes).  The
 * defaults are applied by mb_config_default through mb_config_set, so
 * this table is the only place they are written.
 */
#define MB_CONFIG_KEYS(X)                                                      \
	X(modbus_listen, listen, LISTEN, 0, 0, "HOST:PORT", "127.0.0.1:1502",  \
	  "Modbus TCP server (read-only registers, see MODBUS.md); "           \
	  "[::1]:1502 for IPv6, port 0 = any free port; none = off")           \
	X(modbus_unit_id, unit_id, INT, 1, 247, "N", "1",                      \
	  "Modbus unit id answered (1..247); 0 and 255 are answered too")      \
	X(modbus_word_order, word_order, ORDER, 0, 0, "ORDER", "abcd",         \
	  "32-bit values: abcd (high word first) or cdab (low word first)")    \
	X(modbus_max_clients, max_clients, INT, 1, 1024, "N", "16",            \
	  "Modbus clients at once (1..1024); more are closed on connect")      \
	X(modbus_job_slots, job_slots, INT, 1, MB_JOB_SLOTS_MAX, "N", "8",     \
	  "job slots in the register map (1..64)")                             \
	X(modbus_sensor_slots, sensor_slots, INT, 0, MB_SENSOR_SLOTS_MAX, "N", \
	  "32", "sensor slots in the register map (0..1024)")                  \
	X(modbus_lux_scale, lux_scale, REAL, 1e-6, 1e6, "X", "1",              \
	  "scaled lux registers hold round(lux x X), 0..65534 (1e-6..1e6)")    \
	X(modbus_idle_timeout, idle_timeout_s, SECONDS, 0, 31536000,           \
	  "DURATION", "60s",                                                   \
	  "close Modbus clients silent this long; 0 = never")                  \
	X(modbus_frame_timeout, frame_timeout_s, SECONDS, 0.01, 3600,          \
	  "DURATION", "2s",                                                    \
	  "close a Modbus client whose request stays incomplete this long "    \
	  "(0.01s..1h)")

typedef struct mb_config {
	char listen[300];         /* host:port; "" = off */
	int unit_id;              /* 1..247 */
	mb_word_order word_order; /* of every 32-bit value */
	int max_clients;          /* 1..1024 */
	int job_slots;            /* 1..MB_JOB_SLOTS_MAX */
	int sensor_slots;         /* 0..MB_SENSOR_SLOTS_MAX */
	double lux_scale;         /* scaled lux = round(lux * lux_scale) */
	double idle_timeout_s;    /* 0 = never */
	double frame_timeout_s;   /* a partial request older than this */
} mb_config;

typedef struct mb_config_key {
	const char *name, *metavar, *default_value, *help;
} mb_config_key;

/* The key table (MB_CONFIG_KEYS) for --help and dumps; *n entries. */
const mb_config_key *mb_config_keys(size_t *n);

/* Fill the defaults of MB_CONFIG_KEYS. */
void mb_config_default(mb_config *c);

/*
 * Parse one key ("modbus_word_order") and its value ("cdab") into *c.
 * Returns 0, or -1 with msg naming the key and what is wrong (unknown
 * key, bad value, out of range); *c is unchanged on error.
 */
int mb_config_set(mb_config *c, const char *key, const char *value, char *msg,
                  size_t len);

/* 1 if key is one of MB_CONFIG_KEYS. */
int mb_config_is_key(const char *key);

/* The value of key in config-file syntax (for dumps).  0 or -1. */
int mb_config_get(const mb_config *c, const char *key, char *buf, size_t len);

/* Split "host:port" / "[v6]:port" (rp_addr_parse_listen: port 0 = any
 * free port); "" or "none" gives host "" (off). */
int mb_listen_parse(const char *s, char *host, size_t hostlen, int *port,
                    char *msg, size_t len);

/* --------------------------------------------------------------- server */

typedef struct mb_server mb_server;

typedef enum mb_state {
	MB_STATE_OFF = 0,   /* modbus_listen = none: nothing served */
	MB_STATE_LISTENING, /* the thread serves clients */
	MB_STATE_FAILED     /* the thread stopped on an error (logged) */
} mb_state;

const char *mb_state_name(mb_state st); /* "off", "listening"... */

/* Counters, once: X(field, help).  All since start. */
#define MB_STATS(X)                                                            \
	X(clients, "clients connected now")                                    \
	X(accepted, "connections accepted")                                    \
	X(rejected, "connections closed at once: modbus_max_clients reached")  \
	X(requests, "requests answered, exceptions included")                  \
	X(exceptions, "exception responses sent")                              \
	X(timeouts, "clients closed: idle, or a request left incomplete")      \
	X(bad_frames, "clients closed: not Modbus TCP (protocol id, length)")

typedef struct mb_stats {
#define MB_STAT_FIELD_(name, help) uint64_t name;
	MB_STATS(MB_STAT_FIELD_)
#undef MB_STAT_FIELD_
	mb_state state;
	int port; /* bound port, -1 when off */
} mb_stats;

/* Log sink, called from the Modbus thread.  level: 0 error, 1 warning,
 * 2 info, 3 debug (the order of srv_log_level). */
typedef void (*mb_log_fn)(void *ud, int level, const char *msg);

/*
 * Bind c->listen (port 0 = any free port) and start the server thread.
 * With modbus_listen off, returns a server in state "off" (no thread, no
 * socket).  NULL with msg filled on error (bad address, port in use, no
 * memory).  log may be NULL.  Signals are blocked in the thread.
 */
mb_server *mb_server_start(const mb_config *c, mb_log_fn log, void *log_ud,
                           char *msg, size_t len);

/* The bound port (the real one when 0 was asked), -1 when off. */
int mb_server_port(const mb_server *s);

/* Close every client and the listener, join the thread, free s.  Every
 * publishing thread must be done with s.  NULL is a no-op. */
void mb_server_stop(mb_server *s);

/* A consistent copy of the counters and state (zeros for NULL). */
void mb_server_stats(const mb_server *s, mb_stats *out);

/*
 * Copy registers [addr, addr + n) as a client would read them.  0, or
 * the Modbus exception code a client would get (2: an address outside
 * the served blocks, 3: n outside 1..125).
 */
int mb_server_read(mb_server *s, unsigned addr, unsigned n, uint16_t *out);

/* ---------------------------------------------------------- publication */

typedef struct mb_daemon_vals {
	double start_mono_s;  /* daemon start, CLOCK_MONOTONIC seconds (as
	                         rad_seconds()); uptime counts from it */
	int64_t memory_bytes; /* scenes + jobs + solutions; < 0 = unknown */
} mb_daemon_vals;

/* The daemon block; jobs by state are counted from the jobs published. */
void mb_publish_daemon(mb_server *s, const mb_daemon_vals *v);

/* A job's values; mb_job_vals_init marks every value unknown. */
typedef struct mb_job_vals {
	uint64_t job_id;       /* > 0 */
	uint64_t scene_id;     /* 0 = unknown */
	mb_job_state state;    /* QUEUED..CANCELLED */
	int64_t iteration;     /* < 0 = unknown */
	double progress;       /* current run, 0..1; NaN = unknown */
	double residual;       /* NaN = none yet */
	double error_estimate; /* NaN = none yet */
	int64_t links;         /* links stored; < 0 = unknown */
	int64_t memory_bytes;  /* < 0 = unknown */
	double elapsed_s;      /* solving time; NaN = unknown */
	double eta_s;          /* estimated time left; NaN = unknown */
} mb_job_vals;

void mb_job_vals_init(mb_job_vals *v, uint64_t job_id);

/*
 * Publish (and, the first time, register) a job.  Returns its slot, -1
 * when it has none (every slot taken: kept until one frees), -2 when
 * refused (job id 0, state out of range, no memory).
 */
int mb_publish_job(mb_server *s, const mb_job_vals *v);

/* Forget a job and its sensors; their slots go to unslotted ones. */
void mb_job_remove(mb_server *s, uint64_t job_id);

/*
 * Publish (and, the first time, register) the sensor `name` of a job:
 * lux NaN = declared, no value yet.  iteration: the one the value comes
 * from.  Returns the slot, -1 (unslotted, kept) or -2 (refused: job id
 * 0, empty name or longer than MB_SENSOR_NAME_MAX - 1 bytes, no memory).
 */
#define MB_SENSOR_NAME_MAX 64
int mb_publish_sensor(mb_server *s, uint64_t job_id, const char *name,
                      double lux, uint32_t iteration);

void mb_sensor_remove(mb_server *s, uint64_t job_id, const char *name);

/* Current slots (-1: none / unknown), e.g. for the protocol's status. */
int mb_job_slot(mb_server *s, uint64_t job_id);
int mb_sensor_slot(mb_server *s, uint64_t job_id, const char *name);

#endif
