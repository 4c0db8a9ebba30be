/*
 * cmd_watch.c -- following a job's events: the watch command, and the wait of
 * run --wait.
 *
 * On a terminal the progress of the running iteration is a bar redrawn
 * in place ("\r"), and each finished iteration leaves one line of
 * statistics; state changes leave a line too.  Off a terminal (a pipe, a
 * log) the events are printed as they came, one JSON object per line,
 * flushed at once so a consumer sees them live.  Either way the loop
 * ends when the job is neither queued nor running: done, failed,
 * cancelled or paused.
 */
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "client.h"

#define BAR_WIDTH 30

int lx_state_exit(const char *state)
{
	return !strcmp(state, "failed") || !strcmp(state, "cancelled")
	               ? LX_EXIT_JOB
	               : LX_EXIT_OK;
}

static int active(const char *state)
{
	return !strcmp(state, "queued") || !strcmp(state, "running");
}

/* Erase the progress bar line, if one is drawn. */
static void clear_bar(FILE *live, int *bar)
{
	if (*bar) {
		fprintf(live, "\r%*s\r", BAR_WIDTH + 40, "");
		*bar = 0;
	}
}

static void draw_progress(FILE *live, const json_t *ev, int *bar)
{
	double f = lx_jdbl(ev, "fraction");
	char cells[BAR_WIDTH + 1];
	int full;

	if (f < 0)
		f = 0;
	if (f > 1)
		f = 1;
	full = (int)(f * BAR_WIDTH + 0.5);
	memset(cells, '#', (size_t)full);
	memset(cells + full, '.', (size_t)(BAR_WIDTH - full));
	cells[BAR_WIDTH] = '\0';
	fprintf(live, "\riteration %lld [%s] %3.0f%% %7.1f s",
	        lx_jint(ev, "iteration"), cells, 100 * f,
	        lx_jdbl(ev, "elapsed_s"));
	fflush(live);
	*bar = 1;
}

static void draw_iteration(FILE *live, const json_t *ev, int *bar)
{
	const json_t *st = json_object_get(ev, "stats");
	const json_t *mem = json_object_get(st, "memory");
	char m[32];

	clear_bar(live, bar);
	fprintf(live,
	        "it %4lld  links %9lld  leaves %8lld  mem %10s  residual "
	        "%9.3g  err %9.3g  %8.2f s",
	        lx_jint(st, "iteration"),
	        lx_jint(json_object_get(st, "links"), "stored"),
	        lx_jint(st, "leaves"),
	        lx_fmt_bytes(lx_jdbl(mem, "total_bytes"), m, sizeof m),
	        lx_jdbl(st, "residual"), lx_jdbl(st, "error_estimate"),
	        lx_jdbl(st, "seconds"));
	if (lx_jint(ev, "dropped_progress") > 0)
		fprintf(live, "  (%lld progress events dropped)",
		        lx_jint(ev, "dropped_progress"));
	fputc('\n', live);
	fflush(live);
}

int lx_follow_job(lx_ctx *cx, long long job, const char *state, FILE *live,
                  int json_lines, char *final_state, size_t fslen)
{
	char cur[32];
	int bar = 0, rc = LX_EXIT_OK;

	snprintf(cur, sizeof cur, "%s", state);
	while (active(cur)) {
		json_t *ev;
		if ((rc = lx_next_event(cx, &ev)) != LX_EXIT_OK)
			break;
		if (lx_jint(ev, "job") != job) {
			json_decref(ev);
			continue;
		}
		const char *kind = lx_jstr(ev, "event");
		if (json_lines)
			lx_print_json(ev);
		if (!strcmp(kind, "state")) {
			snprintf(cur, sizeof cur, "%s", lx_jstr(ev, "state"));
			if (live && active(cur)) { /* the final: caller's */
				clear_bar(live, &bar);
				fprintf(live, "job %lld: %s\n", job, cur);
			}
		} else if (live && !strcmp(kind, "progress")) {
			draw_progress(live, ev, &bar);
		} else if (live && !strcmp(kind, "iteration")) {
			draw_iteration(live, ev, &bar);
		}
		json_decref(ev);
	}
	if (live)
		clear_bar(live, &bar);
	snprintf(final_state, fslen, "%s", cur);
	return rc != LX_EXIT_OK ? rc : lx_state_exit(cur);
}

int lx_cmd_watch(lx_ctx *cx)
{
	long long job;
	json_t *req, *reply = NULL;
	char state[32];
	int rc, tty = !cx->json && isatty(1);

	if (lx_pos_id(cx, 0, "job", &job) != 0)
		return LX_EXIT_USAGE;
	if ((rc = lx_open(cx)) != 0)
		return rc;
	req = rp_request(RP_CMD_SUBSCRIBE, -1);
	json_object_set_new(req, "job", json_integer(job));
	if ((rc = lx_call(cx, req, &reply)) != LX_EXIT_OK) {
		json_decref(reply);
		return rc;
	}
	snprintf(state, sizeof state, "%s", lx_jstr(reply, "state"));
	if (cx->json)
		lx_print_json(reply);
	else if (tty)
		printf("job %lld: %s (iteration %lld)\n", job, state,
		       lx_jint(reply, "iteration"));
	json_decref(reply);
	/* On a terminal each state change is a line of its own. */
	rc = lx_follow_job(cx, job, state, tty ? stdout : NULL, !tty, state,
	                   sizeof state);
	if (tty && rc != LX_EXIT_CONN)
		printf("job %lld: %s\n", job, state);
	return rc;
}
