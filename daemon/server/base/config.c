/*
 * config.c -- luxradd's configuration: embedded defaults, the config file
 * and the command line, in that order of precedence.
 *
 * Every option is one row of the key table below (name, type, field,
 * range, example, help).  The file parser, the flag parser, --help and
 * srv_config_dump all read that table, so an option cannot be parsed
 * without being documented, and deploy/luxradd.conf is checked against
 * the defaults by test_config.  The modbus_* rows come from modbus.h's
 * MB_CONFIG_KEYS and delegate to mb_config_set / mb_config_get.
 *
 * DESIGN
 * Values are parsed and range-checked one at a time (set_value), with a
 * message naming the key and the bad text; the file parser prefixes
 * "FILE:LINE: " and the flag parser "--flag: ".  Checks that involve
 * several keys (require_token needs a token file, the Unix socket path
 * must fit in sun_path) run once at the end (srv_config_check).
 *
 * Paths (data_dir, listen_unix, token_file) are made absolute when set,
 * against the working directory at that moment, so a later chdir cannot
 * change their meaning.  listen_unix follows data_dir
 * (<data_dir>/luxradd.sock) until it is set explicitly -- except under
 * systemd with RuntimeDirectory=, where the default is
 * $RUNTIME_DIRECTORY/luxradd.sock: a DynamicUser's state directory sits
 * behind /var/lib/private (0700 root), where no client could reach it.
 *
 * The default data directory, first match wins:
 *   1. $STATE_DIRECTORY (systemd's StateDirectory=; the first entry when
 *      it lists several, separated by ':');
 *   2. $XDG_STATE_HOME/luxradd, when that variable is an absolute path
 *      (the XDG spec says relative values are to be ignored);
 *   3. /var/lib/luxradd when running as root (root's $HOME is /root on
 *      every system, so $HOME would otherwise always win: a root daemon
 *      belongs under /var/lib);
 *   4. $HOME/.local/state/luxradd, then the passwd entry's home;
 *   5. none: data_dir stays "" and srv_config_check asks for one.
 */
#include "config.h"
#include "config_int.h"
#include "rad.h"
#include "rp.h"
#include "textutil.h"

#include <errno.h>
#include <math.h>
#include <pwd.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/un.h>
#include <unistd.h>

#define SOCK_NAME "luxradd.sock"
#define KiB ((uint64_t)1 << 10)
#define MiB ((uint64_t)1 << 20)
#define GiB ((uint64_t)1 << 30)
#define TiB ((uint64_t)1 << 40)

#define F(field) offsetof(srv_config, field), sizeof(((srv_config *)0)->field)

static const cfg_key keys[] = {
        {"listen_tcp", K_TCP, F(listen_tcp), 0, 0, "HOST:PORT", "0.0.0.0:7420",
         "protocol over TCP; [::1]:7420 for IPv6, port 0 = any free port; "
         "none = off"},
        {"listen_unix", K_UNIX, F(listen_unix), 0, 0, "PATH",
         "/run/luxradd/luxradd.sock",
         "protocol over a Unix socket (default <data_dir>/" SOCK_NAME
         ", or $RUNTIME_DIRECTORY/" SOCK_NAME " under systemd); none = off"},
        {"metrics_listen", K_TCP, F(metrics_listen), 0, 0, "HOST:PORT",
         "0.0.0.0:7421", "Prometheus GET /metrics over HTTP; none = off"},
        {"data_dir", K_DIR, F(data_dir), 0, 0, "DIR", "/srv/luxradd",
         "scenes, job checkpoints and the database (created 0700)"},
        {"token_file", K_FILE, F(token_file), 0, 0, "FILE",
         "/etc/luxradd/token",
         "file holding the shared secret clients send in hello; none = no "
         "token"},
        {"users_file", K_FILE, F(users_file), 0, 0, "FILE",
         "/etc/luxradd/users",
         "named tokens with roles, one \"NAME ROLE sha256:HEX\" per line "
         "(luxradd user-add writes them); none = no users"},
        {"tls", K_CHOICE, F(tls), 0, 0, "MODE", "all",
         "TLS on TCP listeners: auto = those beyond loopback (they then need "
         "a certificate), all = every one, off = none (tokens in clear "
         "text)"},
        {"tls_cert_file", K_FILE, F(tls_cert_file), 0, 0, "FILE",
         "/etc/luxradd/cert.pem",
         "the server's certificate chain, PEM, leaf first; none = no TLS"},
        {"tls_key_file", K_FILE, F(tls_key_file), 0, 0, "FILE",
         "/etc/luxradd/key.pem", "the certificate's private key, PEM"},
        {"require_token", K_BOOL, F(require_token), 0, 1, "BOOL", "yes",
         "ask for the token on loopback and Unix connections too"},
        {"workers", K_INT, F(workers), 1, 256, "N", "4",
         "jobs solved at the same time (1..256)"},
        {"solver_threads", K_INT, F(solver_threads), 0, 1024, "N", "2",
         "engine threads per job (0..1024); 0 = cores / workers, at least 1"},
        {"isolation", K_CHOICE, F(isolation), 0, 0, "MODE", "process",
         "where a job's solver runs: process = a process of its own, so a "
         "fault in it fails that job alone; thread = the daemon's threads "
         "(no process start, but one fault stops every job)"},
        {"solver_stop_timeout", K_SECONDS, F(solver_stop_timeout_s), 0, 3600,
         "DURATION", "10s",
         "a solver process that has not stopped this long after it was asked "
         "to (pause, cancel, time budget, shutdown) is killed; its job keeps "
         "its last iteration; 0 = never"},
        {"bvh", K_CHOICE, F(bvh), 0, 0, "LAYOUT", "fast",
         "how scenes lay out their BVH: compact (the default) = leaves "
         "index the vertices; fast = Embree's default, 1.2-1.9x the "
         "memory for 2-10 % faster solves (measured); the same results"},
        {"query_threads", K_INT, F(query_threads), 1, 256, "N", "4",
         "threads answering queries and exports (1..256)"},
        {"accuracy", K_REAL, F(accuracy), RAD_ACCURACY_MIN, RAD_ACCURACY_MAX,
         "R", "0.02",
         "accuracy of jobs that set none: target relative error of the lux "
         "(0.001..0.5)"},
        {"log_level", K_LEVEL, F(log_level), 0, 0, "LEVEL", "debug",
         "error | warn | info | debug; logs go to stderr"},
        {"max_header_bytes", K_SIZE, F(max_header_bytes), (double)KiB,
         (double)GiB, "SIZE", "16M",
         "longest request header line (1K..1G; K, M, G = KiB, MiB, GiB)"},
        {"max_scene_bytes", K_SIZE, F(max_scene_bytes), (double)KiB,
         (double)TiB, "SIZE", "4G", "largest scene upload (1K..1T)"},
        {"max_connections", K_INT, F(max_connections), 1, 65536, "N", "256",
         "client connections open at once (1..65536)"},
        {"max_connections_per_address", K_INT, F(max_connections_per_address),
         0, 65536, "N", "8",
         "TCP connections open at once from one IPv4 address or IPv6 /64 "
         "(0..65536); 0 = no limit"},
        {"hello_timeout", K_SECONDS, F(hello_timeout_s), 0, 3600, "DURATION",
         "5s",
         "close a connection that has not said hello this long after "
         "connecting; 0 = never"},
        {"header_timeout", K_SECONDS, F(header_timeout_s), 0, 3600, "DURATION",
         "10s",
         "close a connection whose request header is not complete this long "
         "after its first byte; 0 = never"},
        {"max_scenes", K_INT, F(max_scenes), 1, 1000000, "N", "16",
         "scenes stored at once (1..1000000)"},
        {"max_jobs", K_INT, F(max_jobs), 1, 1000000, "N", "1024",
         "jobs stored at once, in any state (1..1000000)"},
        {"max_subscriptions", K_INT, F(max_subscriptions), 1, 65536, "N", "64",
         "job subscriptions per connection (1..65536)"},
        {"max_points", K_INT, F(max_points), 1, 100000000, "N", "100000",
         "points in one query (1..100000000)"},
        {"idle_timeout", K_SECONDS, F(idle_timeout_s), 0, 31536000, "DURATION",
         "30m",
         "close connections silent this long; 0 = never (s, m, h suffixes)"},
        {"memory_limit", K_SIZE, F(memory_limit), 0, (double)(1024 * TiB),
         "SIZE", "12G",
         "engine memory of every scene, job and solution together; an "
         "allocation past it fails that upload or job with nomem; 0 = 3/4 "
         "of the machine's (or the cgroup's) memory"},
        {"job_memory_budget", K_SIZE, F(job_memory_budget), 0,
         (double)(1024 * TiB), "SIZE", "2G",
         "memory budget of the jobs that set none (their option "
         "memory_budget): a job's solver refines no further than it "
         "allows; 0 = none"},
        {"max_output_bytes", K_SIZE, F(max_output_bytes), (double)KiB,
         (double)TiB, "SIZE", "64M",
         "send buffer per connection before events are dropped (1K..1T)"},
        {"checkpoint_interval", K_SECONDS, F(checkpoint_interval_s), 0.01,
         86400, "DURATION", "5m",
         "a running job's solution is saved at most this often (0.01s..24h)"},
/* The modbus_* keys, from their one table (modbus.h): K_MODBUS rows
 * delegate parsing and printing to mb_config_set / mb_config_get. */
#define MB_ROW(key, field, type, lo, hi, metavar, def, help)                   \
	{#key, K_MODBUS, 0, 0, 0, 0, metavar, def, help},
        MB_CONFIG_KEYS(MB_ROW)
#undef MB_ROW
};

#define NKEYS (sizeof(keys) / sizeof(keys[0]))
_Static_assert(NKEYS <= CFG_MAX_KEYS, "raise CFG_MAX_KEYS");

const cfg_key *cfg_keys(size_t *n)
{
	*n = NKEYS;
	return keys;
}

/* K_CHOICE keys: the names (value = index) and what one is called in
 * errors.  Their fields are enums, stored as an int. */
typedef struct cfg_choice {
	size_t off;               /* the key's field */
	const char *const *names; /* NULL-terminated */
	const char *what;
} cfg_choice;
static const char *const tls_names[] = {"auto", "all", "off", NULL};
static const char *const isolation_names[] = {"process", "thread", NULL};
static const char *const bvh_names[] = {RAD_BVH_CHOICES, NULL};
static const cfg_choice choices[] = {
        {offsetof(srv_config, tls), tls_names, "a TLS mode"},
        {offsetof(srv_config, isolation), isolation_names, "an isolation"},
        {offsetof(srv_config, bvh), bvh_names, "a BVH layout"},
};
_Static_assert(sizeof(srv_tls_mode) == sizeof(int) &&
                       sizeof(srv_isolation) == sizeof(int),
               "K_CHOICE fields are int-sized");

static const cfg_choice *choice_of(const cfg_key *k)
{
	for (size_t i = 0; i < sizeof(choices) / sizeof(choices[0]); i++)
		if (choices[i].off == k->off)
			return &choices[i];
	return NULL;
}

static const char *const level_names[] = {"error", "warn", "info", "debug"};

/* ------------------------------------------------------------- defaults */

/* Copy s into dst[size]; 0, or -1 when it does not fit. */
static int copy_str(char *dst, size_t size, const char *s)
{
	size_t n = strlen(s);
	if (n >= size)
		return -1;
	memcpy(dst, s, n + 1);
	return 0;
}

static int join_path(char *dst, size_t size, const char *a, const char *b)
{
	int n = snprintf(dst, size, "%s%s%s", a,
	                 a[0] && a[strlen(a) - 1] == '/' ? "" : "/", b);
	return n < 0 || (size_t)n >= size ? -1 : 0;
}

/* First entry of a systemd directory list ("/a:/b"), if absolute. */
static int systemd_dir(const char *var, char *dst, size_t size)
{
	const char *v = getenv(var);
	size_t n = v ? strcspn(v, ":") : 0;
	if (!v || v[0] != '/' || n >= size)
		return 0;
	memcpy(dst, v, n);
	dst[n] = '\0';
	return 1;
}

/* The default data directory (see the list at the top of the file). */
static void default_data_dir(char *dst, size_t size)
{
	const char *xdg = getenv("XDG_STATE_HOME");
	const char *home = getenv("HOME");
	dst[0] = '\0';
	if (systemd_dir("STATE_DIRECTORY", dst, size))
		return;
	if (xdg && xdg[0] == '/') {
		if (join_path(dst, size, xdg, "luxradd") < 0)
			dst[0] = '\0';
		return;
	}
	if (geteuid() == 0) {
		copy_str(dst, size, "/var/lib/luxradd");
		return;
	}
	if (!home || home[0] != '/') {
		struct passwd *pw = getpwuid(geteuid());
		home = pw && pw->pw_dir && pw->pw_dir[0] == '/' ? pw->pw_dir
		                                                : NULL;
	}
	if (home && join_path(dst, size, home, ".local/state/luxradd") < 0)
		dst[0] = '\0';
}

void srv_config_default(srv_config *c)
{
	char run[4096];
	memset(c, 0, sizeof(*c));
	copy_str(c->listen_tcp, sizeof(c->listen_tcp), "127.0.0.1:7420");
	copy_str(c->metrics_listen, sizeof(c->metrics_listen),
	         "127.0.0.1:7421");
	default_data_dir(c->data_dir, sizeof(c->data_dir));
	if (systemd_dir("RUNTIME_DIRECTORY", run, sizeof(run))) {
		c->listen_unix_set = 1; /* stays there when data_dir moves */
		if (join_path(c->listen_unix, sizeof(c->listen_unix), run,
		              SOCK_NAME) < 0)
			c->listen_unix[0] = '\0';
	} else if (c->data_dir[0] &&
	           join_path(c->listen_unix, sizeof(c->listen_unix),
	                     c->data_dir, SOCK_NAME) < 0) {
		c->listen_unix[0] = '\0';
	}
	c->require_token = 0;
	c->workers = 2;
	c->solver_threads = 0;
	c->query_threads = 2;
	c->isolation = SRV_ISOLATION_PROCESS;
	c->solver_stop_timeout_s = 10;
	c->accuracy = RAD_ACCURACY_DEFAULT;
	c->log_level = SRV_LOG_INFO;
	c->max_header_bytes = 4 * MiB;
	c->max_scene_bytes = GiB;
	c->max_connections = 64;
	c->max_connections_per_address = 16;
	c->hello_timeout_s = 10;
	c->header_timeout_s = 30;
	c->max_scenes = 64;
	c->max_jobs = 256;
	c->max_subscriptions = 16;
	c->max_points = 1000000;
	c->idle_timeout_s = 600;
	c->max_output_bytes = 8 * MiB;
	c->memory_limit = 0;
	c->job_memory_budget = 0;
	c->bvh = RAD_BVH_DEFAULT;
	c->checkpoint_interval_s = 30;
	mb_config_default(&c->modbus);
}

/* --------------------------------------------------------------- values */

static int is_none(const char *v)
{
	return v[0] == '\0' || strcmp(v, "none") == 0;
}

static int parse_bool(const char *v, int *out)
{
	static const char *const t[] = {"true", "yes", "on", "1"};
	static const char *const f[] = {"false", "no", "off", "0"};
	for (size_t i = 0; i < 4; i++) {
		if (strcasecmp(v, t[i]) == 0)
			return *out = 1, 0;
		if (strcasecmp(v, f[i]) == 0)
			return *out = 0, 0;
	}
	return -1;
}

/* "1234", "4K", "4KiB", "16 M", "1G"...: binary units.  -1 if malformed
 * or past 2^63. */
static int parse_size(const char *v, uint64_t *out)
{
	static const struct {
		const char *s;
		uint64_t mult;
	} units[] = {{"", 1},    {"b", 1},     {"k", KiB}, {"kib", KiB},
	             {"m", MiB}, {"mib", MiB}, {"g", GiB}, {"gib", GiB},
	             {"t", TiB}, {"tib", TiB}};
	char *end;
	if (*v < '0' || *v > '9')
		return -1;
	errno = 0;
	unsigned long long n = strtoull(v, &end, 10);
	if (errno)
		return -1;
	while (*end == ' ' || *end == '\t')
		end++;
	for (size_t i = 0; i < sizeof(units) / sizeof(units[0]); i++) {
		if (strcasecmp(end, units[i].s) != 0)
			continue;
		if (n > (UINT64_MAX >> 1) / units[i].mult)
			return -1;
		*out = n * units[i].mult;
		return 0;
	}
	return -1;
}

/* Store path v (absolute, or made absolute) into dst[size]. */
int cfg_set_path(char *dst, size_t size, const char *v, char *msg,
                 size_t msglen)
{
	char cwd[4096];
	if (v[0] == '/') {
		if (copy_str(dst, size, v) < 0)
			return srv_fail(msg, msglen,
			                "path too long (%zu bytes max)",
			                size - 1);
		return 0;
	}
	if (!getcwd(cwd, sizeof(cwd)))
		return srv_fail(msg, msglen,
		                "'%s' is relative and the working directory is "
		                "unknown (%s): give an absolute path",
		                v, strerror(errno));
	if (join_path(dst, size, cwd, v) < 0)
		return srv_fail(msg, msglen, "path too long (%zu bytes max)",
		                size - 1);
	return 0;
}

static int set_number(srv_config *c, const cfg_key *k, const char *v, char *msg,
                      size_t msglen)
{
	char *p = (char *)c + k->off;
	if (k->type == K_INT) {
		char *end;
		errno = 0;
		long n = strtol(v, &end, 10);
		if (end == v || *end || errno)
			return srv_fail(msg, msglen, "'%s' is not an integer",
			                v);
		if (n < k->lo || n > k->hi)
			return srv_fail(msg, msglen,
			                "%ld is out of range %g..%g", n, k->lo,
			                k->hi);
		*(int *)p = (int)n;
	} else if (k->type == K_SIZE) {
		uint64_t n;
		if (parse_size(v, &n) < 0)
			return srv_fail(msg, msglen,
			                "'%s' is not a size (bytes, or with a "
			                "K, M, G or T suffix: 4M, 1GiB)",
			                v);
		if ((double)n < k->lo || (double)n > k->hi)
			return srv_fail(msg, msglen,
			                "'%s' is out of range %.0f..%.0f bytes",
			                v, k->lo, k->hi);
		*(size_t *)p = (size_t)n;
	} else if (k->type == K_REAL) {
		char *end;
		errno = 0;
		double d = strtod(v, &end);
		if (end == v || *end || errno || !isfinite(d))
			return srv_fail(msg, msglen, "'%s' is not a number", v);
		if (d < k->lo || d > k->hi)
			return srv_fail(msg, msglen,
			                "%g is out of range %g..%g", d, k->lo,
			                k->hi);
		*(double *)p = d;
	} else {
		double s;
		if (srv_parse_seconds(v, &s) < 0)
			return srv_fail(
			        msg, msglen,
			        "'%s' is not a duration (seconds, or with s, "
			        "m, h, ms suffixes: 30, 30s, 5m)",
			        v);
		if (s < k->lo || s > k->hi)
			return srv_fail(msg, msglen,
			                "'%s' is out of range %gs..%gs", v,
			                k->lo, k->hi);
		*(double *)p = s;
	}
	return 0;
}

int cfg_set_value(srv_config *c, const cfg_key *k, const char *v, char *msg,
                  size_t msglen)
{
	char *p = (char *)c + k->off;
	rp_addr a;
	rp_error e;
	int b;
	switch (k->type) {
	case K_TCP:
		if (is_none(v))
			return p[0] = '\0', 0;
		if (rp_addr_parse_listen(v, &a, &e) != 0)
			return srv_fail(msg, msglen, "%s", e.msg);
		if (copy_str(p, k->size, v) < 0)
			return srv_fail(msg, msglen, "'%s' is too long", v);
		return 0;
	case K_UNIX:
		c->listen_unix_set = 1;
		if (is_none(v))
			return p[0] = '\0', 0;
		return cfg_set_path(p, k->size, v, msg, msglen);
	case K_FILE:
		if (is_none(v))
			return p[0] = '\0', 0;
		return cfg_set_path(p, k->size, v, msg, msglen);
	case K_DIR:
		if (is_none(v))
			return srv_fail(msg, msglen,
			                "a data directory is required");
		if (cfg_set_path(p, k->size, v, msg, msglen) < 0)
			return -1;
		if (!c->listen_unix_set &&
		    join_path(c->listen_unix, sizeof(c->listen_unix), p,
		              SOCK_NAME) < 0)
			return srv_fail(msg, msglen, "path too long");
		return 0;
	case K_BOOL:
		if (parse_bool(v, &b) < 0)
			return srv_fail(msg, msglen,
			                "'%s' is not a boolean (true/false, "
			                "yes/no, on/off, 1/0)",
			                v);
		*(int *)p = b;
		return 0;
	case K_LEVEL:
		for (int i = 0; i < 4; i++)
			if (strcasecmp(v, level_names[i]) == 0 ||
			    (i == SRV_LOG_WARN &&
			     strcasecmp(v, "warning") == 0))
				return *(srv_log_level *)p = (srv_log_level)i,
				                       0;
		return srv_fail(
		        msg, msglen,
		        "'%s' is not a log level (error, warn, info, debug)",
		        v);
	case K_CHOICE: {
		const cfg_choice *ch = choice_of(k);
		char names[128] = "";
		for (int i = 0; ch->names[i]; i++) {
			if (strcasecmp(v, ch->names[i]) == 0)
				return *(int *)p = i, 0;
			snprintf(names + strlen(names),
			         sizeof(names) - strlen(names), "%s%s",
			         i ? ", " : "", ch->names[i]);
		}
		return srv_fail(msg, msglen, "'%s' is not %s (%s)", v, ch->what,
		                names);
	}
	case K_MODBUS:
		return mb_config_set(&c->modbus, k->name, v, msg, msglen);
	default:
		return set_number(c, k, v, msg, msglen);
	}
}

/* The key named name (underscores or dashes), or NULL. */
const cfg_key *cfg_find_key(const char *name, size_t len)
{
	for (size_t i = 0; i < NKEYS; i++) {
		const char *k = keys[i].name;
		size_t j = 0;
		if (strlen(k) != len)
			continue;
		while (j < len &&
		       (name[j] == k[j] || (name[j] == '-' && k[j] == '_')))
			j++;
		if (j == len)
			return &keys[i];
	}
	return NULL;
}

/* ----------------------------------------------------- cross-key checks */

int srv_config_check(const srv_config *c, char *msg, size_t msglen)
{
	struct sockaddr_un sun;
	if (!c->data_dir[0]) {
		srv_fail(msg, msglen,
		         "data_dir: no default (STATE_DIRECTORY, "
		         "XDG_STATE_HOME and HOME are unset): set data_dir");
		return -1;
	}
	if (strlen(c->listen_unix) >= sizeof(sun.sun_path)) {
		srv_fail(msg, msglen,
		         "listen_unix: '%s' is longer than a Unix socket path "
		         "may be (%zu bytes): set listen_unix to a shorter "
		         "path, or none",
		         c->listen_unix, sizeof(sun.sun_path) - 1);
		return -1;
	}
	if (c->require_token && !c->token_file[0]) {
		srv_fail(msg, msglen,
		         "require_token is set but token_file is none");
		return -1;
	}
	if (!c->listen_tcp[0] && !c->listen_unix[0]) {
		srv_fail(msg, msglen,
		         "listen_tcp and listen_unix are both none: clients "
		         "could not connect");
		return -1;
	}
	return 0;
}

/* ------------------------------------------------------------ printing */

/* Shortest decimal that reads back as x. */
static void fmt_double(char *buf, size_t len, double x)
{
	for (int prec = 6; prec <= 17; prec++) {
		snprintf(buf, len, "%.*g", prec, x);
		if (strtod(buf, NULL) == x)
			return;
	}
}

void cfg_fmt_value(const srv_config *c, const cfg_key *k, char *buf, size_t len)
{
	const char *p = (const char *)c + k->off;
	switch (k->type) {
	case K_TCP:
	case K_UNIX:
	case K_FILE:
	case K_DIR:
		if (!p[0])
			snprintf(buf, len, "none");
		else if (strpbrk(p, " \t#\"'") || strcmp(p, "none") == 0)
			snprintf(buf, len, strchr(p, '"') ? "'%s'" : "\"%s\"",
			         p);
		else
			snprintf(buf, len, "%s", p);
		break;
	case K_BOOL:
		snprintf(buf, len, "%s", *(const int *)p ? "yes" : "no");
		break;
	case K_INT:
		snprintf(buf, len, "%d", *(const int *)p);
		break;
	case K_LEVEL:
		snprintf(buf, len, "%s",
		         level_names[*(const srv_log_level *)p]);
		break;
	case K_CHOICE:
		snprintf(buf, len, "%s", choice_of(k)->names[*(const int *)p]);
		break;
	case K_SIZE: {
		uint64_t n = *(const size_t *)p;
		static const char sfx[] = "TGMK";
		for (int i = 0; i < 4; i++) {
			uint64_t m = (uint64_t)1 << (10 * (4 - i));
			if (n && n % m == 0) {
				snprintf(buf, len, "%llu%c",
				         (unsigned long long)(n / m), sfx[i]);
				return;
			}
		}
		snprintf(buf, len, "%llu", (unsigned long long)n);
		break;
	}
	case K_REAL:
		fmt_double(buf, len, *(const double *)p);
		break;
	case K_SECONDS: {
		char d[40];
		fmt_double(d, sizeof(d), *(const double *)p);
		snprintf(buf, len, "%ss", d);
		break;
	}
	case K_MODBUS:
		if (mb_config_get(&c->modbus, k->name, buf, len) < 0)
			snprintf(buf, len, "?");
		break;
	}
}

void srv_config_dump(const srv_config *c,
                     void (*line)(void *ud, const char *text), void *ud)
{
	char text[4400], val[4200];
	snprintf(text, sizeof(text), "# config_file: %s",
	         c->config_file[0] ? c->config_file : "none");
	line(ud, text);
	for (size_t i = 0; i < NKEYS; i++) {
		cfg_fmt_value(c, &keys[i], val, sizeof(val));
		snprintf(text, sizeof(text), "%s = %s", keys[i].name, val);
		line(ud, text);
	}
}
