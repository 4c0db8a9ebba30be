/*
 * config.h -- luxradd's configuration: embedded defaults, the config file
 * (deploy/luxradd.conf documents every key), and command-line flags, in
 * that order of precedence (flags win).
 *
 * The file format is "key = value" lines, '#' comments, blank lines; keys
 * are the long flag names without "--" (listen_tcp = 127.0.0.1:7420).
 * Unknown keys and bad values are errors naming the file and line: a
 * daemon must not start with a configuration it does not understand.
 */
#ifndef LUXRAD_SRV_CONFIG_H
#define LUXRAD_SRV_CONFIG_H

#include <stddef.h>
#include <stdint.h>

#include "modbus.h"

typedef enum srv_log_level {
	SRV_LOG_ERROR = 0,
	SRV_LOG_WARN,
	SRV_LOG_INFO,
	SRV_LOG_DEBUG
} srv_log_level;

/* Which TCP protocol listeners speak TLS (cmd/tls.c). */
typedef enum srv_tls_mode {
	SRV_TLS_AUTO, /* those beyond loopback (then a certificate is needed) */
	SRV_TLS_ALL,  /* every one, loopback too */
	SRV_TLS_OFF   /* none: tokens beyond loopback travel in clear text */
} srv_tls_mode;

typedef enum srv_isolation {
	SRV_ISOLATION_PROCESS, /* each job's solver in a process of its own */
	SRV_ISOLATION_THREAD /* on the daemon's threads: one fault stops all */
} srv_isolation;

typedef struct srv_config {
	char config_file[4096];   /* "" = none (embedded defaults only) */
	char listen_tcp[300];     /* host:port, "" = no TCP; default
	                             127.0.0.1:7420 */
	char listen_unix[4096];   /* socket path, "" = none; default
	                             <data_dir>/luxradd.sock, or
	                             $RUNTIME_DIRECTORY/luxradd.sock when
	                             systemd sets it */
	char metrics_listen[300]; /* host:port for GET /metrics, "" = off;
	                             default 127.0.0.1:7421 */
	char data_dir[4096];      /* default: $STATE_DIRECTORY, else
	                             $XDG_STATE_HOME/luxradd, else
	                             ~/.local/state/luxradd; /var/lib/luxradd
	                             for root */
	char token_file[4096];    /* "" = no token */
	char users_file[4096];    /* "" = no users (cmd/users.c) */
	srv_tls_mode tls;         /* which TCP listeners speak TLS */
	char tls_cert_file[4096]; /* PEM chain, leaf first; "" = none */
	char tls_key_file[4096];  /* PEM private key; "" = none */
	int require_token;        /* 1: token even on loopback / Unix */
	int workers;              /* jobs solved at once; default 2 */
	int solver_threads;       /* engine threads per job; 0 = cores /
	                             workers, at least 1 */
	int query_threads;        /* threads answering queries; default 2 */
	srv_isolation isolation;  /* where solvers run; default process */
	int bvh; /* scenes' BVH layout, a rad_bvh_mode; default compact */
	double solver_stop_timeout_s; /* a solver process asked to stop is
	                                 killed after this; 0 = never */
	double accuracy;              /* jobs' default accuracy (rad_options) */
	srv_log_level log_level;      /* default info; logs go to stderr */
	/* Limits: each breach is a clear error on the offending connection. */
	size_t max_header_bytes;         /* default 4 MiB */
	size_t max_scene_bytes;          /* default 1 GiB */
	int max_connections;             /* default 64 */
	int max_connections_per_address; /* TCP, per IPv4 address or IPv6
	                                    /64; default 16; 0 = no limit */
	double hello_timeout_s;   /* connect to hello; default 10; 0 = never */
	double header_timeout_s;  /* first byte of a header to its end;
	                             default 30; 0 = never */
	int max_scenes;           /* default 64 */
	int max_jobs;             /* default 256 (all states) */
	int max_subscriptions;    /* per connection; default 16 */
	int max_points;           /* per query; default 1,000,000 */
	double idle_timeout_s;    /* close connections silent this long;
	                             default 600; 0 = never */
	size_t max_output_bytes;  /* per-connection send buffer before the
	                             drop policy applies; default 8 MiB */
	size_t job_memory_budget; /* jobs' default memory_budget, bytes;
	                             0 = none */
	size_t memory_limit;      /* engine bytes, daemon-wide; 0 = 3/4
	                             of RAM or of the cgroup's limit */
	double checkpoint_interval_s; /* default 30 */
	mb_config modbus;    /* the modbus_* keys (modbus.h, MODBUS.md) */
	int listen_unix_set; /* listen_unix fixed (given in the file or a
	                        flag, or systemd's RUNTIME_DIRECTORY); until
	                        then it follows data_dir */
} srv_config;

/* Fill the embedded defaults (data_dir resolved from the environment). */
void srv_config_default(srv_config *c);

/*
 * Apply a config file over *c.  Returns 0, or -1 with msg (file:line:
 * what) filled.  A missing file is an error only when must_exist.
 */
int srv_config_load_file(srv_config *c, const char *path, int must_exist,
                         char *msg, size_t msglen);

/*
 * Parse argv: --config FILE is applied first (if given), then every flag
 * over it (--listen-tcp, --listen-unix, --metrics-listen, --data-dir,
 * --token-file, --require-token, --workers, --solver-threads,
 * --query-threads, --log-level, --max-*, --idle-timeout, ...; "none" or ""
 * disables a listener).  Returns 0 to run, 1 when --help / --version was
 * printed (exit 0), -1 on error (msg filled, exit 2).
 */
int srv_config_from_args(srv_config *c, int argc, char **argv, char *msg,
                         size_t msglen);

/*
 * Checks that involve several keys, run by srv_config_from_args (call it
 * after srv_config_load_file alone, e.g. on reload): a data_dir exists,
 * the Unix socket path fits in sun_path, require_token has a token_file,
 * at least one protocol listener.  0, or -1 with msg filled.
 */
int srv_config_check(const srv_config *c, char *msg, size_t msglen);

/* Print --help (every flag, its default and an example) to stdout. */
void srv_config_usage(const char *argv0);

/* Write the effective configuration as config-file lines (for logs). */
void srv_config_dump(const srv_config *c,
                     void (*line)(void *ud, const char *text), void *ud);

#endif
