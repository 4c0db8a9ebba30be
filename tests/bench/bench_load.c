/*
 * bench_load.c -- luxrad-bench-load: a real luxradd under many clients,
 * some of them hostile, while two jobs solve (a program, not a test:
 * timings on a shared machine are too noisy to assert on).
 *
 * Three phases, each on a fresh daemon with the same configuration, the
 * same scene and the same two jobs (hr, one engine thread each, two
 * workers), measured in the same run:
 *   quiet    one client asks status 50 times a second;
 *   clients  N well-behaved clients (default 900) each ask status R times
 *            a second (default 1, as a dashboard polls), at jittered
 *            times, one request at a time;
 *   hostile  the same, plus H hostile connections (default 100) in four
 *            kinds, each reconnecting as soon as it is closed:
 *              slow hello   a hello trickled one byte every 0.5 s;
 *              slow header  after hello, a header trickled the same way;
 *              garbage      after hello, a line that is not JSON, or a
 *                           frame announcing a 1 TB payload;
 *              non-reader   after hello, subscribes to a job and sends
 *                           status requests without ever reading.
 * Well-behaved clients come from 127.0.1.1 .. 127.0.1.100 and hostile
 * ones from 127.0.2.1 .. 127.0.2.10 (Linux routes 127/8 to loopback), so
 * per-address limits apply as they would to distinct hosts.
 *
 * It reports, per phase: status latency (p50, p99, max) over every
 * well-behaved request, requests sent and answered, each job's solve
 * time (job.run to its "done" event) and the ratios to the quiet phase;
 * the daemon's refusals by cause (/metrics); and whether the jobs' lux
 * at five points is bit-identical to the quiet phase's.  Nothing lost
 * means: every well-behaved request answered "ok", no well-behaved
 * connection closed, both jobs done with the same lux.  The exit status
 * is 1 when something was lost.
 */
#include <errno.h>
#include <fcntl.h>
#include <jansson.h>
#include <math.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <unistd.h>

#include "bench_stats.h"
#include "harness.h"

#define NPTS 5
#define TRICKLE_MS 500.0

typedef enum role {
	LEGIT,
	SLOW_HELLO,
	SLOW_HEADER,
	GARBAGE,
	NOREAD,
	NROLES
} role;

static const char *const role_names[NROLES] = {
        "well-behaved", "slow hello", "slow header", "garbage", "non-reader"};

typedef struct peer {
	role r;
	int fd;       /* -1: waiting to reconnect */
	char src[32]; /* source address */
	int step;     /* 0 hello sent, 1 ready, 2 subscribed (NOREAD) */
	char *in;     /* received, not yet a whole line */
	size_t inlen, incap;
	double next;      /* ms: next request / byte / reconnect */
	double sent;      /* ms: LEGIT request outstanding since; 0 none */
	long long serial; /* garbage kind, trickle position */
} peer;

typedef struct phase {
	const char *name;
	int legit, hostile;
	double rate; /* requests per second per well-behaved client */
	/* results */
	double *lat; /* ms, one per answered request */
	long long nlat, cap, sent, errors, legit_closed, reconnects[NROLES];
	double solve_s[2], lux[2][NPTS];
	double refused[16];
} phase;

typedef struct bench {
	const char *scene;
	int legit, hostile;
	double rate;
	int json;
	const char *json_out; /* also write the JSON there */
	const char *causes[16];
	int ncauses;
} bench;

static void bench_fail(const char *msg)
{
	fprintf(stderr, "luxrad-bench-load: %s\n", msg);
	exit(1);
}

static void usage(FILE *f)
{
	fprintf(f, "Usage: luxrad-bench-load [options]\n"
	           "  --scene FILE     scene the two jobs solve [generated "
	           "hall-full]\n"
	           "  --clients N      well-behaved clients [900]\n"
	           "  --hostile N      hostile connections [100]\n"
	           "  --rate R         status requests per second per client "
	           "[1]\n"
	           "  --json           one JSON object on stdout\n"
	           "  --json-out FILE  print the table, write the JSON to "
	           "FILE\n");
}

/* ------------------------------------------------------------- sockets */

static int connect_from(const dm_daemon *d, const char *src)
{
	char why[512];
	int fd = dm_tcp_socket(d->tcp_host, d->tcp_port, 0, src, why,
	                       sizeof(why));
	if (fd >= 0)
		fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) | O_NONBLOCK);
	return fd;
}

/* Best effort: what the socket takes now (hostile peers do not wait). */
static void put(peer *p, const char *s, size_t n)
{
	if (p->fd >= 0 && send(p->fd, s, n, MSG_NOSIGNAL | MSG_DONTWAIT) < 0 &&
	    errno != EAGAIN && errno != EWOULDBLOCK) {
		close(p->fd);
		p->fd = -1;
	}
}

static void puts_line(peer *p, const char *s)
{
	put(p, s, strlen(s));
}

static void hang_up(peer *p, double now)
{
	if (p->fd >= 0)
		close(p->fd);
	p->fd = -1;
	p->inlen = 0;
	p->step = 0;
	p->sent = 0;
	p->next = now + (p->r == GARBAGE ? 100 : 20);
}

static void start_peer(const dm_daemon *d, peer *p, double now, phase *ph)
{
	p->fd = connect_from(d, p->src);
	p->step = 0;
	p->inlen = 0;
	p->sent = 0;
	if (p->fd < 0) {
		p->next = now + 100;
		return;
	}
	ph->reconnects[p->r]++;
	if (p->r == SLOW_HELLO) {
		puts_line(
		        p,
		        "{\"cmd\": \"hello\", \"version\": 1, \"client\": \"");
		p->next = now + TRICKLE_MS;
		return;
	}
	puts_line(p, "{\"cmd\": \"hello\", \"version\": 1, \"id\": 0}\n");
	p->next = 0;
}

static void record(phase *ph, double ms)
{
	if (ph->nlat == ph->cap) {
		ph->cap = ph->cap ? 2 * ph->cap : 4096;
		ph->lat = realloc(ph->lat, (size_t)ph->cap * sizeof(double));
		if (!ph->lat)
			dm_fail("out of memory");
	}
	ph->lat[ph->nlat++] = ms;
}

/* A whole line arrived on p. */
static void on_line(peer *p, const char *line, double now, phase *ph,
                    const char *jobid)
{
	int ok = strstr(line, "\"ok\": true") || strstr(line, "\"ok\":true");
	if (p->r == LEGIT) {
		if (p->step == 0) {
			if (!ok)
				ph->errors++;
			p->step = 1;
			/* first request at a random phase of the period */
			p->next = now + 1e3 / ph->rate * drand48();
			return;
		}
		if (p->sent > 0) {
			record(ph, now - p->sent);
			if (!ok)
				ph->errors++;
			p->sent = 0;
		}
		return;
	}
	if (p->step != 0)
		return; /* replies to hostile requests: ignored */
	p->step = 1;
	switch (p->r) {
	case SLOW_HEADER:
		puts_line(p, "{\"cmd\": \"status\", \"pad\": \"");
		p->next = now + TRICKLE_MS;
		break;
	case GARBAGE: {
		char buf[128];
		if (p->serial++ % 2)
			snprintf(buf, sizeof(buf),
			         "{\"cmd\": \"scene.upload\", "
			         "\"bytes\": 1000000000000}\n");
		else
			snprintf(buf, sizeof(buf),
			         "\x01\x02 this is not json "
			         "%lld\n",
			         p->serial);
		puts_line(p, buf);
		break;
	}
	case NOREAD: {
		char buf[128];
		snprintf(buf, sizeof(buf),
		         "{\"cmd\": \"subscribe\", \"job\": %s, \"id\": 1}\n",
		         jobid);
		puts_line(p, buf);
		p->step = 2;
		p->next = now + 10;
		break;
	}
	default:
		break;
	}
}

static void readable(peer *p, double now, phase *ph, const char *jobid)
{
	for (;;) {
		if (p->incap - p->inlen < 65536) {
			p->incap = p->incap ? 2 * p->incap : 65536;
			p->in = realloc(p->in, p->incap);
			if (!p->in)
				dm_fail("out of memory");
		}
		ssize_t n =
		        recv(p->fd, p->in + p->inlen, p->incap - p->inlen, 0);
		if (n < 0 && (errno == EAGAIN || errno == EINTR))
			break;
		if (n <= 0) {
			if (p->r == LEGIT)
				ph->legit_closed++;
			hang_up(p, now);
			return;
		}
		p->inlen += (size_t)n;
	}
	char *s = p->in, *nl;
	while ((nl = memchr(s, '\n', p->inlen - (size_t)(s - p->in)))) {
		*nl = '\0';
		on_line(p, s, now, ph, jobid);
		if (p->fd < 0)
			return;
		s = nl + 1;
	}
	p->inlen -= (size_t)(s - p->in);
	memmove(p->in, s, p->inlen);
}

/* Time has come for p's next move. */
static void act(const dm_daemon *d, peer *p, double now, phase *ph)
{
	if (p->fd < 0) {
		start_peer(d, p, now, ph);
		return;
	}
	switch (p->r) {
	case LEGIT:
		if (p->step == 1 && p->sent == 0) {
			char buf[64];
			snprintf(buf, sizeof(buf),
			         "{\"cmd\": \"status\", \"id\": %lld}\n",
			         ++p->serial);
			puts_line(p, buf);
			p->sent = now;
			ph->sent++;
			double period = 1e3 / ph->rate;
			p->next = p->next + period > now ? p->next + period
			                                 : now + period;
		}
		break;
	case SLOW_HELLO:
	case SLOW_HEADER:
		if (p->r == SLOW_HELLO || p->step == 1) {
			put(p, "x", 1);
			p->next = now + TRICKLE_MS;
		}
		break;
	case NOREAD:
		if (p->step == 2) {
			puts_line(p, "{\"cmd\": \"status\"}\n");
			p->next = now + 10;
		}
		break;
	default:
		p->next = now + 1000;
		break;
	}
}

/* ----------------------------------------------------------------- phase */

static void job_solve_done(json_t *e, const long long id[2], double now,
                           double *done_at)
{
	const char *kind = json_string_value(json_object_get(e, "event"));
	const char *st = json_string_value(json_object_get(e, "state"));
	long long job = json_integer_value(json_object_get(e, "job"));
	if (!kind || strcmp(kind, "state") || !st)
		return;
	if (!strcmp(st, "failed") || !strcmp(st, "cancelled"))
		dm_fail("a job ended %s", st);
	for (int k = 0; k < 2; k++)
		if (job == id[k] && !strcmp(st, "done"))
			done_at[k] = now;
}

static void run_phase(const bench *b, phase *ph)
{
	const char *dargs[] = {"--workers",
	                       "2",
	                       "--solver-threads",
	                       "1",
	                       "--max-connections",
	                       "1100",
	                       "--hello-timeout",
	                       "5",
	                       "--header-timeout",
	                       "5",
	                       "--log-level",
	                       "error",
	                       NULL};
	dm_daemon *d = dm_start(dargs);
	dm_conn *ctl = dm_open(d, NULL);
	json_t *sc = dm_upload_file(ctl, b->scene, "load");
	json_t *opt = json_pack("{s:i, s:f, s:i}", "threads", 1, "tol", 1e-3,
	                        "max_iterations", 100);
	json_t *job[2];
	long long id[2];
	for (int k = 0; k < 2; k++) {
		job[k] = dm_job_create(ctl, sc, "hr", opt);
		id[k] = json_integer_value(job[k]);
		json_decref(dm_ok(ctl, "{s:s, s:O}", "cmd", "subscribe", "job",
		                  job[k]));
	}
	json_decref(opt);
	char jobid[32];
	snprintf(jobid, sizeof(jobid), "%lld", id[0]);

	int n = ph->legit + ph->hostile;
	peer *p = calloc((size_t)n, sizeof(*p));
	struct pollfd *pf = calloc((size_t)n + 1, sizeof(*pf));
	int *map = calloc((size_t)n, sizeof(int));
	double now = dm_now_ms();
	for (int i = 0; i < n; i++) {
		p[i].r =
		        i < ph->legit ? LEGIT : (role)(1 + (i - ph->legit) % 4);
		if (p[i].r == LEGIT)
			snprintf(p[i].src, sizeof(p[i].src), "127.0.1.%d",
			         1 + i % 100);
		else
			snprintf(p[i].src, sizeof(p[i].src), "127.0.2.%d",
			         1 + (i - ph->legit) % 10);
		p[i].fd = -1;
		start_peer(d, &p[i], now, ph);
		if (p[i].r == LEGIT && p[i].fd < 0)
			dm_fail("well-behaved client %d could not connect", i);
	}

	/* Run the loop; the jobs start once every client said hello. */
	double t_run = 0, done_at[2] = {0, 0};
	int started = 0;
	while (!(done_at[0] > 0 && done_at[1] > 0)) {
		now = dm_now_ms();
		if (!started) {
			int ready = 0;
			for (int i = 0; i < ph->legit; i++)
				ready += p[i].step == 1;
			if (ready == ph->legit) {
				for (int k = 0; k < 2; k++)
					json_decref(
					        dm_ok(ctl, "{s:s, s:O, s:b}",
					              "cmd", "job.run", "job",
					              job[k], "converge", 1));
				t_run = now = dm_now_ms();
				started = 1;
			}
		}
		double wake = now + 50;
		int m = 0;
		for (int i = 0; i < n; i++) {
			if (p[i].next > 0 && p[i].next <= now &&
			    (started || p[i].r != LEGIT || p[i].step == 0))
				act(d, &p[i], now, ph);
			if (p[i].next > 0 && p[i].next < wake)
				wake = p[i].next;
			if (p[i].fd < 0)
				continue;
			/* non-readers never read once subscribed */
			if (p[i].r == NOREAD && p[i].step == 2)
				continue;
			pf[m].fd = p[i].fd;
			pf[m].events = POLLIN;
			pf[m].revents = 0;
			map[m++] = i;
		}
		pf[m].fd = ctl->fd;
		pf[m].events = POLLIN;
		pf[m].revents = 0;
		int ms = (int)(wake - dm_now_ms());
		if (poll(pf, (nfds_t)m + 1, ms > 0 ? ms : 0) < 0 &&
		    errno != EINTR)
			dm_fail("poll: %s", strerror(errno));
		now = dm_now_ms();
		for (int k = 0; k < m; k++)
			if (pf[k].revents)
				readable(&p[map[k]], now, ph, jobid);
		if (pf[m].revents) {
			json_t *e;
			while ((e = dm_event(ctl, 0))) {
				job_solve_done(e, id, now, done_at);
				json_decref(e);
			}
		}
		if (started && now - t_run > 1800e3)
			dm_fail("the jobs did not finish in 30 minutes");
	}
	for (int k = 0; k < 2; k++)
		ph->solve_s[k] = (done_at[k] - t_run) / 1e3;
	/* The requests in flight are answered too (10 s at most). */
	for (double end = dm_now_ms() + 10e3; dm_now_ms() < end;) {
		int m = 0;
		for (int i = 0; i < ph->legit; i++) {
			if (p[i].fd < 0 || p[i].sent == 0)
				continue;
			pf[m].fd = p[i].fd;
			pf[m].events = POLLIN;
			pf[m].revents = 0;
			map[m++] = i;
		}
		if (m == 0)
			break;
		poll(pf, (nfds_t)m, 100);
		now = dm_now_ms();
		for (int k = 0; k < m; k++)
			if (pf[k].revents)
				readable(&p[map[k]], now, ph, jobid);
	}

	/* What the daemon refused, then the results. */
	char *body = NULL;
	if (dm_http_get(d, "/metrics", NULL, &body) != 200)
		dm_fail("GET /metrics failed");
	for (int c = 0; c < b->ncauses; c++) {
		char series[128];
		snprintf(series, sizeof(series),
		         "luxradd_connections_refused_total{cause=\"%s\"}",
		         b->causes[c]);
		ph->refused[c] = dm_metrics_sample(body, series);
	}
	free(body);
	static const double pts[NPTS * 6] = {
	        0, 0.8, 0, 0, 1,   0, 3, 0.8, 2, 0,  1,   0, -4, 0.8, -3,
	        0, 1,   0, 8, 0.8, 5, 0, 1,   0, -9, 0.8, 4, 0,  1,   0};
	for (int k = 0; k < 2; k++)
		dm_query_points(ctl, job[k], pts, NPTS, ph->lux[k]);
	for (int i = 0; i < n; i++) {
		if (p[i].fd >= 0)
			close(p[i].fd);
		free(p[i].in);
	}
	free(p);
	free(pf);
	free(map);
	for (int k = 0; k < 2; k++)
		json_decref(job[k]);
	json_decref(sc);
	dm_close(ctl);
	dm_stop(d);
}

static int parse_args(int argc, char **argv, bench *b)
{
	for (int i = 1; i < argc; i++) {
		const char *o = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
		if (!strcmp(o, "--json")) {
			b->json = 1;
		} else if (!strcmp(o, "--help")) {
			usage(stdout);
			exit(0);
		} else if (v && !strcmp(o, "--json-out")) {
			b->json_out = v;
			i++;
		} else if (v && !strcmp(o, "--scene")) {
			b->scene = v;
			i++;
		} else if (v && !strcmp(o, "--clients")) {
			b->legit = atoi(v);
			i++;
		} else if (v && !strcmp(o, "--hostile")) {
			b->hostile = atoi(v);
			i++;
		} else if (v && !strcmp(o, "--rate")) {
			b->rate = atof(v);
			i++;
		} else {
			usage(stderr);
			return -1;
		}
	}
	if (b->legit < 1 || b->hostile < 0 || b->legit + b->hostile > 1050 ||
	    !(b->rate > 0)) {
		fprintf(stderr, "luxrad-bench-load: --clients >= 1, --hostile "
		                ">= 0, at most 1050 in all, --rate > 0\n");
		return -1;
	}
	return 0;
}

static json_t *phase_json(const bench *b, phase *ph, const phase *quiet)
{
	double p50 = bench_pct(ph->lat, (int)ph->nlat, 50),
	       p99 = bench_pct(ph->lat, (int)ph->nlat, 99),
	       mx = bench_pct(ph->lat, (int)ph->nlat, 100);
	double q99 = bench_pct(quiet->lat, (int)quiet->nlat, 99);
	int same = 1;
	for (int k = 0; k < 2; k++)
		for (int i = 0; i < NPTS; i++)
			same &= ph->lux[k][i] == quiet->lux[k][i];
	json_t *refused = json_object(), *rc = json_object();
	for (int c = 0; c < b->ncauses; c++)
		json_object_set_new(refused, b->causes[c],
		                    json_integer((json_int_t)ph->refused[c]));
	for (int r = 0; r < NROLES; r++)
		json_object_set_new(rc, role_names[r],
		                    json_integer(ph->reconnects[r]));
	return json_pack(
	        "{s:s, s:i, s:i, s:f, s:I, s:I, s:I, s:I, s:f, s:f, s:f, "
	        "s:f, s:[f, f], s:[f, f], s:b, s:o, s:o}",
	        "phase", ph->name, "clients", ph->legit, "hostile", ph->hostile,
	        "rate", ph->rate, "requests_sent", ph->sent,
	        "requests_answered", ph->nlat, "errors", ph->errors,
	        "clients_closed", ph->legit_closed, "status_p50_ms", p50,
	        "status_p99_ms", p99, "status_max_ms", mx, "status_p99_ratio",
	        p99 / q99, "solve_s", ph->solve_s[0], ph->solve_s[1],
	        "solve_ratio", ph->solve_s[0] / quiet->solve_s[0],
	        ph->solve_s[1] / quiet->solve_s[1], "lux_identical", same,
	        "refused", refused, "connections_made", rc);
}

int main(int argc, char **argv)
{
	bench b = {.legit = 900, .hostile = 100, .rate = 1};
	if (parse_args(argc, argv, &b) != 0)
		return 2;
	dm_fail_hook = bench_fail;
	signal(SIGPIPE, SIG_IGN);
	srand48(1);
	struct rlimit rl;
	if (getrlimit(RLIMIT_NOFILE, &rl) == 0 && rl.rlim_cur < rl.rlim_max) {
		rl.rlim_cur = rl.rlim_max;
		setrlimit(RLIMIT_NOFILE, &rl);
	}
	char gen[512];
	if (!b.scene)
		b.scene = dm_gen_scene("hall-full.glb", "hall-full", gen,
		                       sizeof(gen));
	static const char *const causes[] = {
	        "max_connections", "per_address",  "evicted", "hello_timeout",
	        "header_timeout",  "idle_timeout", "auth",    "protocol",
	        "slow_consumer"};
	b.ncauses = (int)(sizeof(causes) / sizeof(causes[0]));
	memcpy(b.causes, causes, sizeof(causes));

	phase ph[3] = {{.name = "quiet", .legit = 1, .hostile = 0, .rate = 50},
	               {.name = "clients",
	                .legit = b.legit,
	                .hostile = 0,
	                .rate = b.rate},
	               {.name = "hostile",
	                .legit = b.legit,
	                .hostile = b.hostile,
	                .rate = b.rate}};
	for (int i = 0; i < 3; i++) {
		run_phase(&b, &ph[i]);
		fprintf(stderr,
		        "%s: %lld requests answered, jobs %.2f s and %.2f s\n",
		        ph[i].name, ph[i].nlat, ph[i].solve_s[0],
		        ph[i].solve_s[1]);
	}
	json_t *out = json_pack("{s:s, s:[]}", "scene", b.scene, "phases");
	int lost = 0;
	for (int i = 0; i < 3; i++) {
		json_t *o = phase_json(&b, &ph[i], &ph[0]);
		lost |= ph[i].errors || ph[i].legit_closed ||
		        ph[i].nlat != ph[i].sent ||
		        !json_is_true(json_object_get(o, "lux_identical"));
		json_array_append_new(json_object_get(out, "phases"), o);
	}
	json_object_set_new(out, "nothing_lost", json_boolean(!lost));
	if (b.json_out && json_dump_file(out, b.json_out, JSON_INDENT(2)) != 0)
		dm_fail("cannot write the JSON");
	if (b.json) {
		json_dumpf(out, stdout, JSON_INDENT(2));
		fputc('\n', stdout);
	} else {
		printf("| phase | clients | hostile | status p50 ms | p99 ms | "
		       "max ms | p99 / quiet | answered / sent | job A s | "
		       "job B s | solve / quiet | lux identical |\n"
		       "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
		size_t i;
		json_t *o;
		json_array_foreach(json_object_get(out, "phases"), i, o)
		{
			json_t *s = json_object_get(o, "solve_s"),
			       *r = json_object_get(o, "solve_ratio");
			printf("| %s | %d | %d | %.2f | %.2f | %.2f | %.2f | "
			       "%lld / %lld | %.2f | %.2f | %.3f, %.3f | %s "
			       "|\n",
			       ph[i].name, ph[i].legit, ph[i].hostile,
			       dm_num(o, "status_p50_ms"),
			       dm_num(o, "status_p99_ms"),
			       dm_num(o, "status_max_ms"),
			       dm_num(o, "status_p99_ratio"), ph[i].nlat,
			       ph[i].sent,
			       json_real_value(json_array_get(s, 0)),
			       json_real_value(json_array_get(s, 1)),
			       json_real_value(json_array_get(r, 0)),
			       json_real_value(json_array_get(r, 1)),
			       json_is_true(json_object_get(o, "lux_identical"))
			               ? "yes"
			               : "NO");
		}
		printf("\nrefused or closed by the daemon (hostile phase):");
		for (int c = 0; c < b.ncauses; c++)
			printf(" %s %.0f", b.causes[c], ph[2].refused[c]);
		printf("\nconnections made (hostile phase):");
		for (int r = 0; r < NROLES; r++)
			printf(" %s %lld", role_names[r], ph[2].reconnects[r]);
		printf("\nnothing lost: %s\n", lost ? "NO" : "yes");
	}
	json_decref(out);
	for (int i = 0; i < 3; i++)
		free(ph[i].lat);
	dm_pass();
	dm_teardown(NULL);
	return lost;
}
