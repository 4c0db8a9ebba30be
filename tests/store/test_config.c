/*
 * test_config.c -- luxradd's configuration: the documented defaults, the
 * data directory taken from the environment, the config file (every value
 * type, comments, quotes, errors with file:line), flags over the file,
 * "none" listeners, --help / --version, the dump round trip, and the
 * shipped deploy/luxradd.conf yielding exactly the defaults.
 */
#include <fcntl.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "config.h"
#include "rad.h"

static char tmpdir[] = "/tmp/luxrad-test-config.XXXXXX";

/* Write text to tmpdir/name; returns the path (static buffer). */
static const char *write_file(const char *name, const char *text)
{
	static char path[512];
	snprintf(path, sizeof(path), "%s/%s", tmpdir, name);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
	return path;
}

/* Load text as a config file over the defaults: the return code. */
static int load_text(srv_config *c, const char *text, char *msg, size_t len)
{
	const char *path = write_file("t.conf", text);
	srv_config_default(c);
	msg[0] = '\0';
	return srv_config_load_file(c, path, 1, msg, len);
}

/* argv from a NULL-terminated list (getopt permutes, so copy). */
static int from_args(srv_config *c, char *msg, size_t len, ...)
{
	char *argv[32];
	int argc = 0;
	va_list ap;
	va_start(ap, len);
	argv[argc++] = "luxradd";
	for (char *a; (a = va_arg(ap, char *)) != NULL && argc < 31;)
		argv[argc++] = a;
	va_end(ap);
	argv[argc] = NULL;
	srv_config_default(c);
	msg[0] = '\0';
	return srv_config_from_args(c, argc, argv, msg, len);
}

typedef struct dump_buf {
	char text[16384];
} dump_buf;

static void dump_line(void *ud, const char *line)
{
	dump_buf *b = ud;
	strncat(b->text, line, sizeof(b->text) - strlen(b->text) - 2);
	strcat(b->text, "\n");
}

/* The dump without its first line (the config_file comment). */
static void dump_keys(const srv_config *c, dump_buf *b)
{
	dump_buf all = {{0}};
	srv_config_dump(c, dump_line, &all);
	const char *nl = strchr(all.text, '\n');
	assert_non_null(nl);
	snprintf(b->text, sizeof(b->text), "%s", nl + 1);
}

static void test_defaults_match_the_header(void **state)
{
	(void)state;
	srv_config c;
	char sock[4200];
	srv_config_default(&c);
	assert_string_equal(c.config_file, "");
	assert_string_equal(c.listen_tcp, "127.0.0.1:7420");
	assert_string_equal(c.metrics_listen, "127.0.0.1:7421");
	assert_true(c.data_dir[0] == '/');
	snprintf(sock, sizeof(sock), "%s/luxradd.sock", c.data_dir);
	assert_string_equal(c.listen_unix, sock);
	assert_string_equal(c.token_file, "");
	assert_int_equal(c.require_token, 0);
	assert_int_equal(c.workers, 2);
	assert_int_equal(c.solver_threads, 0);
	assert_int_equal(c.query_threads, 2);
	assert_int_equal(c.log_level, SRV_LOG_INFO);
	assert_int_equal(c.max_header_bytes, 4u << 20);
	assert_int_equal(c.max_scene_bytes, (size_t)1 << 30);
	assert_int_equal(c.max_connections, 64);
	assert_int_equal(c.max_scenes, 64);
	assert_int_equal(c.max_jobs, 256);
	assert_int_equal(c.max_subscriptions, 16);
	assert_int_equal(c.max_points, 1000000);
	assert_true(c.idle_timeout_s == 600);
	assert_int_equal(c.max_output_bytes, 8u << 20);
	assert_true(c.checkpoint_interval_s == 30);
	assert_int_equal(c.job_memory_budget, 0);
	assert_int_equal(c.bvh, RAD_BVH_COMPACT);
	char msg[512];
	assert_int_equal(srv_config_check(&c, msg, sizeof(msg)), 0);
}

static void test_data_dir_from_environment(void **state)
{
	(void)state;
	srv_config c;
	char *saved[3];
	const char *names[3] = {"STATE_DIRECTORY", "XDG_STATE_HOME", "HOME"};
	for (int i = 0; i < 3; i++) {
		const char *v = getenv(names[i]);
		saved[i] = v ? strdup(v) : NULL;
	}
	/* systemd: the first of several StateDirectory entries. */
	setenv("STATE_DIRECTORY", "/var/lib/a:/var/lib/b", 1);
	setenv("XDG_STATE_HOME", "/xdg", 1);
	srv_config_default(&c);
	assert_string_equal(c.data_dir, "/var/lib/a");
	assert_string_equal(c.listen_unix, "/var/lib/a/luxradd.sock");
	/* systemd's RuntimeDirectory= holds the socket, wherever the data
	 * directory goes. */
	setenv("RUNTIME_DIRECTORY", "/run/luxradd", 1);
	char msg[512], *argv[] = {"luxradd", "--data-dir", "/srv/x", NULL};
	srv_config_default(&c);
	assert_string_equal(c.listen_unix, "/run/luxradd/luxradd.sock");
	assert_int_equal(srv_config_from_args(&c, 3, argv, msg, sizeof(msg)),
	                 0);
	assert_string_equal(c.listen_unix, "/run/luxradd/luxradd.sock");
	unsetenv("RUNTIME_DIRECTORY");
	unsetenv("STATE_DIRECTORY");
	srv_config_default(&c);
	assert_string_equal(c.data_dir, "/xdg/luxradd");
	/* A relative XDG_STATE_HOME is ignored (XDG base directory spec). */
	setenv("XDG_STATE_HOME", "relative", 1);
	setenv("HOME", "/home/someone", 1);
	srv_config_default(&c);
	if (geteuid() == 0)
		assert_string_equal(c.data_dir, "/var/lib/luxradd");
	else
		assert_string_equal(c.data_dir,
		                    "/home/someone/.local/state/luxradd");
	unsetenv("XDG_STATE_HOME");
	srv_config_default(&c);
	assert_true(c.data_dir[0] == '/');
	for (int i = 0; i < 3; i++) {
		if (saved[i])
			setenv(names[i], saved[i], 1);
		else
			unsetenv(names[i]);
		free(saved[i]);
	}
}

static void test_file_every_value_type(void **state)
{
	(void)state;
	srv_config c;
	char msg[512];
	int rc = load_text(&c,
	                   "# a comment line\n"
	                   "\n"
	                   "   # an indented comment\n"
	                   "listen_tcp = \"0.0.0.0:9000\"\n"
	                   "metrics_listen = [::1]:9001   # trailing comment\n"
	                   "data_dir = /srv/lux\r\n"
	                   "token_file = '/etc/lux/to#ken'\n"
	                   "require_token = yes\n"
	                   "workers=8\n"
	                   "solver_threads = 0\n"
	                   "query_threads = 3\n"
	                   "log_level = debug\n"
	                   "max_header_bytes = 64KiB\n"
	                   "max_scene_bytes = 2G\n"
	                   "max_connections = 10\n"
	                   "max_scenes = 5\n"
	                   "max_jobs = 6\n"
	                   "max_subscriptions = 7\n"
	                   "max_points = 1000\n"
	                   "idle_timeout = 5m\n"
	                   "max_output_bytes = 1048576\n"
	                   "checkpoint_interval = 1.5\n",
	                   msg, sizeof(msg));
	assert_int_equal(rc, 0);
	assert_string_equal(c.listen_tcp, "0.0.0.0:9000");
	assert_string_equal(c.metrics_listen, "[::1]:9001");
	assert_string_equal(c.data_dir, "/srv/lux");
	/* listen_unix follows data_dir until set. */
	assert_string_equal(c.listen_unix, "/srv/lux/luxradd.sock");
	assert_string_equal(c.token_file, "/etc/lux/to#ken");
	assert_int_equal(c.require_token, 1);
	assert_int_equal(c.workers, 8);
	assert_int_equal(c.query_threads, 3);
	assert_int_equal(c.log_level, SRV_LOG_DEBUG);
	assert_int_equal(c.max_header_bytes, 65536);
	assert_int_equal(c.max_scene_bytes, (size_t)2 << 30);
	assert_int_equal(c.max_connections, 10);
	assert_int_equal(c.max_scenes, 5);
	assert_int_equal(c.max_jobs, 6);
	assert_int_equal(c.max_subscriptions, 7);
	assert_int_equal(c.max_points, 1000);
	assert_true(c.idle_timeout_s == 300);
	assert_int_equal(c.max_output_bytes, 1048576);
	assert_true(c.checkpoint_interval_s == 1.5);
	assert_int_equal(srv_config_check(&c, msg, sizeof(msg)), 0);

	/* Booleans, sizes and durations in their other spellings. */
	const char *bools[] = {"true", "1", "on", "YES"};
	for (int i = 0; i < 4; i++) {
		char text[64];
		snprintf(text, sizeof(text), "require_token = %s\n", bools[i]);
		assert_int_equal(load_text(&c, text, msg, sizeof(msg)), 0);
		assert_int_equal(c.require_token, 1);
	}
	assert_int_equal(load_text(&c, "require_token = no\n", msg, 512), 0);
	assert_int_equal(c.require_token, 0);
	assert_int_equal(
	        load_text(&c, "max_scene_bytes = 3 MiB\nidle_timeout = 2h\n",
	                  msg, 512),
	        0);
	assert_int_equal(c.max_scene_bytes, 3u << 20);
	assert_true(c.idle_timeout_s == 7200);
	assert_int_equal(load_text(&c, "idle_timeout = 0\n", msg, 512), 0);
	assert_true(c.idle_timeout_s == 0);
	assert_int_equal(
	        load_text(&c, "checkpoint_interval = 250ms\n", msg, 512), 0);
	assert_true(c.checkpoint_interval_s == 0.25);
}

/* Each bad line, alone at line 3, fails with "PATH:3: " + expect. */
static void test_file_errors_name_file_and_line(void **state)
{
	(void)state;
	static const struct {
		const char *line, *expect;
	} cases[] = {
	        {"bogus = 1", "unknown key 'bogus'"},
	        {"workers = 0", "workers: 0 is out of range 1..256"},
	        {"workers = 257", "out of range"},
	        {"workers = two", "workers: 'two' is not an integer"},
	        {"max_scene_bytes = 12X",
	         "max_scene_bytes: '12X' is not a size"},
	        {"max_header_bytes = 0",
	         "max_header_bytes: '0' is out of range"},
	        {"max_scene_bytes = 99999999999T", "is not a size"},
	        {"idle_timeout = 5y", "idle_timeout: '5y' is not a duration"},
	        {"idle_timeout = -1", "is not a duration"},
	        {"checkpoint_interval = 0",
	         "checkpoint_interval: '0' is out of"},
	        {"require_token = maybe",
	         "require_token: 'maybe' is not a bool"},
	        {"log_level = loud", "log_level: 'loud' is not a log level"},
	        {"listen_tcp = localhost",
	         "listen_tcp: address 'localhost' is not HOST:PORT"},
	        {"listen_tcp = 1.2.3.4:70000",
	         "port 70000 is out of range 0..65535"},
	        {"listen_tcp = :7420", "empty host (0.0.0.0 = every IPv4"},
	        {"metrics_listen = [::1]7421", "expected ':PORT' after ']'"},
	        {"listen_tcp = /tmp/s.sock", "is a Unix socket path"},
	        {"data_dir = none", "data_dir: a data directory is required"},
	        {"workers 4", "expected 'key = value'"},
	        {"= 4", "expected 'key = value'"},
	        {"token_file = \"/x", "unterminated \" quote"},
	        {"token_file = \"/x\" y", "unexpected text after the closing"},
	};
	char text[256], msg[512], expect[600];
	srv_config c;
	for (size_t i = 0; i < sizeof(cases) / sizeof(cases[0]); i++) {
		snprintf(text, sizeof(text), "# header\nworkers = 3\n%s\n",
		         cases[i].line);
		int rc = load_text(&c, text, msg, sizeof(msg));
		snprintf(expect, sizeof(expect), "%s/t.conf:3: ", tmpdir);
		if (rc != -1 || strncmp(msg, expect, strlen(expect)) != 0 ||
		    !strstr(msg, cases[i].expect))
			fail_msg("line '%s': rc %d, message '%s', expected "
			         "'%s%s...'",
			         cases[i].line, rc, msg, expect,
			         cases[i].expect);
	}
}

static void test_missing_file(void **state)
{
	(void)state;
	srv_config c;
	char path[512], msg[512] = "";
	srv_config_default(&c);
	snprintf(path, sizeof(path), "%s/absent.conf", tmpdir);
	assert_int_equal(srv_config_load_file(&c, path, 0, msg, sizeof(msg)),
	                 0);
	assert_int_equal(srv_config_load_file(&c, path, 1, msg, sizeof(msg)),
	                 -1);
	assert_non_null(strstr(msg, "absent.conf: cannot open config file"));
	assert_int_equal(
	        from_args(&c, msg, sizeof(msg), "--config", path, NULL), -1);
	assert_non_null(strstr(msg, "absent.conf"));
}

static void test_flags_override_file(void **state)
{
	(void)state;
	srv_config c;
	char msg[512];
	const char *conf =
	        write_file("flags.conf", "workers = 8\n"
	                                 "require_token = yes\n"
	                                 "token_file = /etc/tok\n"
	                                 "log_level = debug\n"
	                                 "listen_unix = /run/x.sock\n");
	/* --config last on the line is still applied first. */
	int rc = from_args(&c, msg, sizeof(msg), "--workers", "3",
	                   "--require-token=no", "--idle-timeout", "90s",
	                   "--max-scene-bytes", "10M", "--config", conf, NULL);
	assert_int_equal(rc, 0);
	assert_string_equal(c.config_file, conf);
	assert_int_equal(c.workers, 3);
	assert_int_equal(c.require_token, 0);
	assert_string_equal(c.token_file, "/etc/tok");
	assert_int_equal(c.log_level, SRV_LOG_DEBUG);
	assert_string_equal(c.listen_unix, "/run/x.sock");
	assert_true(c.idle_timeout_s == 90);
	assert_int_equal(c.max_scene_bytes, 10u << 20);

	/* A bare boolean flag means yes; --data-dir moves the socket. */
	rc = from_args(&c, msg, sizeof(msg), "--require-token", "--token-file",
	               "/etc/tok", "--data-dir", "/srv/d", NULL);
	assert_int_equal(rc, 0);
	assert_int_equal(c.require_token, 1);
	assert_string_equal(c.listen_unix, "/srv/d/luxradd.sock");
	/* Relative paths are made absolute against the working directory. */
	char cwd[1024], expect[1100];
	assert_non_null(getcwd(cwd, sizeof(cwd)));
	rc = from_args(&c, msg, sizeof(msg), "--data-dir", "rel/dir", NULL);
	assert_int_equal(rc, 0);
	snprintf(expect, sizeof(expect), "%s/rel/dir", cwd);
	assert_string_equal(c.data_dir, expect);
}

static void test_none_disables_listeners(void **state)
{
	(void)state;
	srv_config c;
	char msg[512];
	int rc =
	        from_args(&c, msg, sizeof(msg), "--listen-tcp", "none",
	                  "--metrics-listen", "", "--data-dir", "/srv/n", NULL);
	assert_int_equal(rc, 0);
	assert_string_equal(c.listen_tcp, "");
	assert_string_equal(c.metrics_listen, "");
	assert_string_equal(c.listen_unix, "/srv/n/luxradd.sock");
	assert_int_equal(load_text(&c, "listen_unix = none\ndata_dir = /a\n",
	                           msg, sizeof(msg)),
	                 0);
	assert_string_equal(c.listen_unix, ""); /* stays off */
	/* Both protocol listeners off: nobody could connect. */
	rc = from_args(&c, msg, sizeof(msg), "--listen-tcp", "none",
	               "--listen-unix", "none", NULL);
	assert_int_equal(rc, -1);
	assert_non_null(strstr(msg, "both none"));
}

static void test_cross_key_checks(void **state)
{
	(void)state;
	srv_config c;
	char msg[512], longdir[300];
	int rc = from_args(&c, msg, sizeof(msg), "--require-token", NULL);
	assert_int_equal(rc, -1);
	assert_non_null(strstr(msg, "require_token is set but token_file"));
	memset(longdir, 'd', sizeof(longdir));
	longdir[0] = '/';
	longdir[sizeof(longdir) - 1] = '\0';
	rc = from_args(&c, msg, sizeof(msg), "--data-dir", longdir, NULL);
	assert_int_equal(rc, -1);
	assert_non_null(strstr(msg, "listen_unix: "));
	assert_non_null(strstr(msg, "longer than a Unix socket path"));
	rc = from_args(&c, msg, sizeof(msg), "--data-dir", longdir,
	               "--listen-unix", "/run/short.sock", NULL);
	assert_int_equal(rc, 0);
}

static void test_flag_errors(void **state)
{
	(void)state;
	srv_config c;
	char msg[512];
	assert_int_equal(from_args(&c, msg, sizeof(msg), "--bogus", NULL), -1);
	assert_non_null(strstr(msg, "'--bogus'"));
	assert_int_equal(from_args(&c, msg, sizeof(msg), "--workers", NULL),
	                 -1);
	assert_non_null(strstr(msg, "needs a value"));
	assert_int_equal(
	        from_args(&c, msg, sizeof(msg), "--workers", "abc", NULL), -1);
	assert_string_equal(msg, "--workers: 'abc' is not an integer");
	assert_int_equal(
	        from_args(&c, msg, sizeof(msg), "--query-threads", "0", NULL),
	        -1);
	assert_non_null(strstr(msg, "--query-threads: 0 is out of range"));
	assert_int_equal(from_args(&c, msg, sizeof(msg), "extra", NULL), -1);
	assert_non_null(strstr(msg, "unexpected argument 'extra'"));
	assert_int_equal(from_args(&c, msg, sizeof(msg), "-x", NULL), -1);
	assert_non_null(strstr(msg, "'-x'"));
}

/* Run from_args with stdout captured into out. */
static int capture(char *out, size_t len, const char *flag)
{
	char path[512], msg[512];
	srv_config c;
	snprintf(path, sizeof(path), "%s/stdout.txt", tmpdir);
	fflush(stdout);
	int saved = dup(1);
	int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
	assert_true(saved >= 0 && fd >= 0);
	dup2(fd, 1);
	close(fd);
	int rc = from_args(&c, msg, sizeof(msg), flag, NULL);
	fflush(stdout);
	dup2(saved, 1);
	close(saved);
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	size_t n = fread(out, 1, len - 1, f);
	out[n] = '\0';
	fclose(f);
	return rc;
}

static void test_help_and_version(void **state)
{
	(void)state;
	static char out[32768];
	assert_int_equal(capture(out, sizeof(out), "--help"), 1);
	assert_non_null(strstr(out, "Usage: luxradd"));
	assert_non_null(strstr(out, "--listen-tcp HOST:PORT"));
	assert_non_null(strstr(out, "default: 127.0.0.1:7420"));
	assert_non_null(strstr(out, "--checkpoint-interval DURATION"));
	assert_non_null(strstr(out, "default: 30s"));
	assert_non_null(strstr(out, "default: 4M"));
	assert_non_null(strstr(out, "Examples:"));
	assert_int_equal(capture(out, sizeof(out), "--version"), 1);
	assert_string_equal(out, "luxradd 0.1.0\n");
}

static void test_dump_round_trip(void **state)
{
	(void)state;
	srv_config c, back;
	char msg[512];
	dump_buf a = {{0}}, b = {{0}};
	int rc = from_args(
	        &c, msg, sizeof(msg), "--listen-tcp", "[::]:7000",
	        "--listen-unix", "/run/with space#.sock", "--metrics-listen",
	        "none", "--data-dir", "/srv/r", "--token-file", "/etc/t",
	        "--require-token", "--workers", "5", "--log-level", "warn",
	        "--max-header-bytes", "12345", "--max-scene-bytes", "3G",
	        "--idle-timeout", "0.1", "--checkpoint-interval", "2m", NULL);
	assert_int_equal(rc, 0);
	dump_keys(&c, &a);
	const char *path = write_file("dump.conf", a.text);
	srv_config_default(&back);
	assert_int_equal(srv_config_load_file(&back, path, 1, msg, sizeof(msg)),
	                 0);
	dump_keys(&back, &b);
	assert_string_equal(a.text, b.text);
	assert_string_equal(back.listen_unix, "/run/with space#.sock");
	assert_true(back.idle_timeout_s == 0.1);
	assert_int_equal(back.max_header_bytes, 12345);
	assert_non_null(strstr(a.text, "metrics_listen = none\n"));
	assert_non_null(strstr(a.text, "max_scene_bytes = 3G\n"));
}

/* The modbus_* keys: from a file, overridden by a flag, rejected with the
 * file and line, in the dump, and in --help. */
static void test_modbus_keys(void **state)
{
	(void)state;
	srv_config c;
	char msg[512];
	srv_config_default(&c);
	assert_string_equal(c.modbus.listen, "127.0.0.1:1502");
	assert_int_equal(c.modbus.job_slots, 8);
	const char *conf = write_file("mb.conf", "modbus_word_order = cdab\n"
	                                         "modbus_job_slots = 12\n"
	                                         "modbus_listen = none\n");
	int rc = from_args(&c, msg, sizeof(msg), "--config", conf,
	                   "--modbus-job-slots", "3", "--modbus-idle-timeout",
	                   "2m", NULL);
	if (rc != 0)
		fail_msg("%s", msg);
	assert_int_equal(c.modbus.word_order, MB_CDAB);
	assert_int_equal(c.modbus.job_slots, 3); /* the flag wins */
	assert_true(c.modbus.idle_timeout_s == 120);
	assert_string_equal(c.modbus.listen, "");
	dump_buf a = {{0}};
	dump_keys(&c, &a);
	assert_non_null(strstr(a.text, "modbus_listen = none\n"));
	assert_non_null(strstr(a.text, "modbus_word_order = cdab\n"));
	assert_non_null(strstr(a.text, "modbus_job_slots = 3\n"));

	const char *bad = write_file("mbbad.conf", "\nmodbus_job_slots = 65\n");
	srv_config_default(&c);
	assert_int_equal(srv_config_load_file(&c, bad, 1, msg, sizeof(msg)),
	                 -1);
	assert_non_null(strstr(msg, "mbbad.conf:2: "));
	assert_non_null(strstr(msg, "modbus_job_slots"));
	rc = from_args(&c, msg, sizeof(msg), "--modbus-word-order", "badc",
	               NULL);
	assert_int_equal(rc, -1);
	assert_non_null(strstr(msg, "--modbus-word-order"));
}

/* The shipped file documents every key, commented out: it must parse and
 * change nothing, and it must mention every key the dump knows. */
static void test_shipped_conf_is_the_defaults(void **state)
{
	(void)state;
	srv_config d, c;
	char msg[512];
	dump_buf a = {{0}}, b = {{0}};
	srv_config_default(&d);
	srv_config_default(&c);
	int rc = srv_config_load_file(&c,
	                              LUXRAD_SOURCE_DIR "/deploy/luxradd.conf",
	                              1, msg, sizeof(msg));
	if (rc != 0)
		fail_msg("%s", msg);
	dump_keys(&d, &a);
	dump_keys(&c, &b);
	assert_string_equal(a.text, b.text);

	/* Uncommenting every "# key = value" line gives the defaults too,
	 * except data_dir and listen_unix (environment-dependent): each
	 * documented default is the real one. */
	FILE *f = fopen(LUXRAD_SOURCE_DIR "/deploy/luxradd.conf", "r");
	assert_non_null(f);
	char line[1024], text[16384] = "";
	int keys = 0;
	while (fgets(line, sizeof(line), f)) {
		/* exactly "# key = value": the key right after "# " */
		char key[64];
		size_t n = strspn(line + 2, "abcdefghijklmnopqrstuvwxyz_");
		if (strncmp(line, "# ", 2) != 0 || n == 0 || n >= sizeof(key) ||
		    strncmp(line + 2 + n, " = ", 3) != 0)
			continue;
		memcpy(key, line + 2, n);
		key[n] = '\0';
		if (strcmp(key, "data_dir") == 0 ||
		    strcmp(key, "listen_unix") == 0) {
			keys++;
			continue;
		}
		strncat(text, line + 2, sizeof(text) - strlen(text) - 1);
		keys++;
	}
	fclose(f);
	const char *path = write_file("uncommented.conf", text);
	srv_config_default(&c);
	rc = srv_config_load_file(&c, path, 1, msg, sizeof(msg));
	if (rc != 0)
		fail_msg("uncommented deploy/luxradd.conf: %s", msg);
	memset(b.text, 0, sizeof(b.text));
	dump_keys(&c, &b);
	assert_string_equal(a.text, b.text);
	/* One "# key = default" line per key of the dump. */
	int dumped = 0;
	for (const char *p = a.text; (p = strchr(p, '\n')) != NULL; p++)
		dumped++;
	assert_int_equal(keys, dumped);
}

static int setup(void **state)
{
	(void)state;
	unsetenv("RUNTIME_DIRECTORY"); /* as when not started by systemd */
	return mkdtemp(tmpdir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[600];
	snprintf(cmd, sizeof(cmd), "rm -rf '%s'", tmpdir);
	return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_defaults_match_the_header),
	        cmocka_unit_test(test_data_dir_from_environment),
	        cmocka_unit_test(test_file_every_value_type),
	        cmocka_unit_test(test_file_errors_name_file_and_line),
	        cmocka_unit_test(test_missing_file),
	        cmocka_unit_test(test_flags_override_file),
	        cmocka_unit_test(test_none_disables_listeners),
	        cmocka_unit_test(test_cross_key_checks),
	        cmocka_unit_test(test_flag_errors),
	        cmocka_unit_test(test_help_and_version),
	        cmocka_unit_test(test_dump_round_trip),
	        cmocka_unit_test(test_modbus_keys),
	        cmocka_unit_test(test_shipped_conf_is_the_defaults),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
