/*
 * mb_testserver.c -- a test driver for the Modbus module: starts an
 * mb_server on 127.0.0.1:0 (or as --set says), writes the bound port to a
 * file, and publishes a known, changing image for real clients (mbpoll,
 * pymodbus, mb_tornread) to check.  It stands in for nothing: the daemon
 * publishes through the same calls once it is wired to the module.
 *
 *   mb_testserver --port-file FILE [--set key=value]... [--mode M]
 *                 [--tick-ms N] [--done-after N] [--lifetime S] [--log]
 *
 * Mode "normal" (mbtest.py holds the same numbers):
 *   daemon  started 3600 s ago, 123456789 bytes of memory;
 *   job 7   scene 3, running: every tick the iteration goes up by one,
 *           progress = iteration / done_after, residual 1 / iteration,
 *           error estimate 0.5 / iteration, 1000 links per iteration,
 *           10 MiB, elapsed 0.05 s per iteration, eta the rest; done at
 *           iteration done_after;
 *   job 9   scene 3, done at iteration 42: residual 0.015625, error
 *           estimate 0.25, 123456 links, 5 MiB, 12 s, eta 0;
 *   job 12  paused, nothing known (every value its sentinel);
 *   sensors (7, desk) 123.456 lx, (7, floor) 0.5, (7, ramp) 1.5 x the
 *           iteration (iteration 7's), (9, window) 70000.25, (12,
 *           corner) not yet available.
 * Mode "torn": one thread republishes, as fast as it can, job 7's
 * iteration alternately 0x0000FFFF and 0x00010000 and its residual and
 * sensor (7, desk) alternately 1.0f and the float 0x40490FDB: both words
 * of each value differ between the two, so a reader that ever sees a
 * mixed pair has caught a torn update.
 *
 * SIGTERM / SIGINT stop it cleanly (exit 0); so does --lifetime (default
 * 120 s), so that a test that dies cannot leave it running.
 */
#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "modbus.h"

static volatile sig_atomic_t stop_flag;

static void on_signal(int sig)
{
	(void)sig;
	stop_flag = 1;
}

static double now_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void log_line(void *ud, int level, const char *msg)
{
	(void)ud;
	fprintf(stderr, "mb_testserver: [%d] %s\n", level, msg);
}

typedef struct opts {
	const char *port_file;
	const char *mode;
	int tick_ms, done_after, log;
	double lifetime_s;
	mb_config cfg;
} opts;

static int parse_args(int argc, char **argv, opts *o)
{
	char msg[256];
	mb_config_default(&o->cfg);
	mb_config_set(&o->cfg, "modbus_listen", "127.0.0.1:0", NULL, 0);
	o->mode = "normal";
	o->tick_ms = 50;
	o->done_after = 400;
	o->lifetime_s = 120;
	for (int i = 1; i < argc; i++) {
		const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
		if (strcmp(a, "--log") == 0) {
			o->log = 1;
			continue;
		}
		if (!v) {
			fprintf(stderr, "mb_testserver: %s needs a value\n", a);
			return -1;
		}
		i++;
		if (strcmp(a, "--port-file") == 0) {
			o->port_file = v;
		} else if (strcmp(a, "--mode") == 0) {
			o->mode = v;
		} else if (strcmp(a, "--tick-ms") == 0) {
			o->tick_ms = atoi(v);
		} else if (strcmp(a, "--done-after") == 0) {
			o->done_after = atoi(v);
		} else if (strcmp(a, "--lifetime") == 0) {
			o->lifetime_s = atof(v);
		} else if (strcmp(a, "--set") == 0) {
			char key[64];
			const char *eq = strchr(v, '=');
			if (!eq || (size_t)(eq - v) >= sizeof key) {
				fprintf(stderr,
				        "mb_testserver: --set key=value\n");
				return -1;
			}
			memcpy(key, v, (size_t)(eq - v));
			key[eq - v] = '\0';
			if (mb_config_set(&o->cfg, key, eq + 1, msg,
			                  sizeof msg)) {
				fprintf(stderr, "mb_testserver: %s\n", msg);
				return -1;
			}
		} else {
			fprintf(stderr, "mb_testserver: unknown option %s\n",
			        a);
			return -1;
		}
	}
	if (!o->port_file || o->tick_ms < 1 || o->done_after < 1 ||
	    (strcmp(o->mode, "normal") && strcmp(o->mode, "torn"))) {
		fprintf(stderr, "usage: mb_testserver --port-file FILE [--set "
		                "key=value]... [--mode normal|torn] [--tick-ms "
		                "N] [--done-after N] [--lifetime S] [--log]\n");
		return -1;
	}
	return 0;
}

/* ------------------------------------------------------------ normal mode */

static void publish_job7(mb_server *s, int it, int done_after)
{
	mb_job_vals v;
	mb_job_vals_init(&v, 7);
	v.scene_id = 3;
	v.state = it >= done_after ? MB_JOB_DONE : MB_JOB_RUNNING;
	v.iteration = it;
	v.progress = (double)it / done_after;
	v.residual = 1.0 / it;
	v.error_estimate = 0.5 / it;
	v.links = 1000 * (int64_t)it;
	v.memory_bytes = 10 << 20;
	v.elapsed_s = 0.05 * it;
	v.eta_s = 0.05 * (done_after - it);
	mb_publish_job(s, &v);
	mb_publish_sensor(s, 7, "ramp", 1.5 * it, (uint32_t)it);
}

/* Sensors first, then jobs 7, 9, 12: slots follow publication order. */
static void publish_static(mb_server *s, int done_after)
{
	mb_daemon_vals d = {now_s() - 3600, 123456789};
	mb_publish_daemon(s, &d);
	mb_publish_sensor(s, 7, "desk", 123.456, 1);
	mb_publish_sensor(s, 7, "floor", 0.5, 1);
	mb_publish_sensor(s, 7, "ramp", 1.5, 1);
	mb_publish_sensor(s, 9, "window", 70000.25, 42);
	mb_publish_sensor(s, 12, "corner", NAN, 0);
	publish_job7(s, 1, done_after);
	mb_job_vals v;
	mb_job_vals_init(&v, 9);
	v.scene_id = 3;
	v.state = MB_JOB_DONE;
	v.iteration = 42;
	v.progress = 1;
	v.residual = 0.015625;
	v.error_estimate = 0.25;
	v.links = 123456;
	v.memory_bytes = 5 << 20;
	v.elapsed_s = 12;
	v.eta_s = 0;
	mb_publish_job(s, &v);
	mb_job_vals_init(&v, 12);
	v.state = MB_JOB_PAUSED;
	mb_publish_job(s, &v);
}

/* ------------------------------------------------------------- torn mode */

typedef struct flipper {
	mb_server *s;
	atomic_int stop;
	atomic_ulong flips;
} flipper;

static void *flip(void *arg)
{
	flipper *f = arg;
	mb_job_vals v;
	mb_job_vals_init(&v, 7);
	v.state = MB_JOB_RUNNING;
	const uint32_t pi_bits = 0x40490FDB;
	float pi;
	memcpy(&pi, &pi_bits, sizeof pi);
	for (unsigned long k = 0; !atomic_load(&f->stop); k++) {
		int odd = k & 1;
		v.iteration = odd ? 0x00010000 : 0x0000FFFF;
		v.residual = odd ? pi : 1.0f;
		mb_publish_job(f->s, &v);
		mb_publish_sensor(f->s, 7, "desk", odd ? pi : 1.0f, 1);
		atomic_fetch_add(&f->flips, 1);
	}
	return NULL;
}

/* ------------------------------------------------------------------- main */

static int write_port(const char *path, int port)
{
	char tmp[4096];
	snprintf(tmp, sizeof tmp, "%s.tmp", path);
	FILE *f = fopen(tmp, "w");
	if (!f || fprintf(f, "%d\n", port) < 0 || fclose(f) != 0 ||
	    rename(tmp, path) != 0) {
		fprintf(stderr, "mb_testserver: %s: %s\n", path,
		        strerror(errno));
		return -1;
	}
	return 0;
}

int main(int argc, char **argv)
{
	opts o = {0};
	char msg[512];
	if (parse_args(argc, argv, &o) < 0)
		return 2;
	struct sigaction sa = {0};
	sa.sa_handler = on_signal;
	sigaction(SIGTERM, &sa, NULL);
	sigaction(SIGINT, &sa, NULL);
	mb_server *s = mb_server_start(&o.cfg, o.log ? log_line : NULL, NULL,
	                               msg, sizeof msg);
	if (!s) {
		fprintf(stderr, "mb_testserver: %s\n", msg);
		return 1;
	}
	int torn = strcmp(o.mode, "torn") == 0;
	flipper f = {.s = s};
	pthread_t th;
	publish_static(s, o.done_after);
	if (torn && pthread_create(&th, NULL, flip, &f) != 0)
		return 1;
	if (write_port(o.port_file, mb_server_port(s)) < 0)
		return 1;
	double t0 = now_s();
	int it = 1;
	while (!stop_flag && now_s() - t0 < o.lifetime_s) {
		struct timespec ts = {o.tick_ms / 1000,
		                      (o.tick_ms % 1000) * 1000000L};
		nanosleep(&ts, NULL);
		if (!torn && it < o.done_after)
			publish_job7(s, ++it, o.done_after);
	}
	if (torn) {
		atomic_store(&f.stop, 1);
		pthread_join(th, NULL);
		fprintf(stderr, "mb_testserver: %lu flips\n",
		        (unsigned long)atomic_load(&f.flips));
	}
	mb_stats st;
	mb_server_stats(s, &st);
	fprintf(stderr,
	        "mb_testserver: state %s, %llu accepted, %llu rejected, "
	        "%llu requests, %llu exceptions, %llu timeouts, %llu bad "
	        "frames\n",
	        mb_state_name(st.state), (unsigned long long)st.accepted,
	        (unsigned long long)st.rejected,
	        (unsigned long long)st.requests,
	        (unsigned long long)st.exceptions,
	        (unsigned long long)st.timeouts,
	        (unsigned long long)st.bad_frames);
	mb_server_stop(s);
	return 0;
}
