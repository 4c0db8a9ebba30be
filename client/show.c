/*
 * show.c -- the two descriptive commands, info (one job) and status (the
 * daemon), printed for people; --json prints the daemon's reply as is.
 *
 * Replies are walked generically where the protocol has open-ended
 * objects (options, memory by kind): a daemon that adds an option or a
 * memory kind is shown correctly without a client update.
 */
#include <stdio.h>
#include <string.h>

#include "client.h"

/* Any scalar as short text. */
static const char *scalar(const json_t *v, char *buf, size_t len)
{
	switch (json_typeof(v)) {
	case JSON_STRING:
		return json_string_value(v);
	case JSON_INTEGER:
		snprintf(buf, len, "%lld", (long long)json_integer_value(v));
		return buf;
	case JSON_REAL:
		snprintf(buf, len, "%g", json_real_value(v));
		return buf;
	case JSON_TRUE:
		return "true";
	case JSON_FALSE:
		return "false";
	default:
		return "?";
	}
}

/* "key=value key=value ..." of an object's scalars, wrapped. */
static void print_pairs(const char *title, const json_t *obj, int skip_zero)
{
	const char *k;
	json_t *v;
	int col = printf("%s", title);

	json_object_foreach((json_t *)obj, k, v)
	{
		char buf[64], item[160];
		if (skip_zero && json_is_number(v) && json_number_value(v) == 0)
			continue;
		if (skip_zero && json_is_number(v))
			snprintf(item, sizeof item, " %s %s", k,
			         lx_fmt_bytes(json_number_value(v), buf,
			                      sizeof buf));
		else
			snprintf(item, sizeof item, " %s=%s", k,
			         scalar(v, buf, sizeof buf));
		if (col + (int)strlen(item) > 78) {
			col = printf("\n   ") - 1;
		}
		col += printf("%s", item);
	}
	printf("\n");
}

/* ----------------------------------------------------------------- info */

static void print_target(const json_t *t)
{
	const char *mode = lx_jstr(t, "mode");
	char buf[32];

	if (!strcmp(mode, "iterations"))
		printf(", target %lld iterations", lx_jint(t, "n"));
	else if (!strcmp(mode, "seconds"))
		printf(", target %s s",
		       lx_jnum(t, "seconds", "%g", buf, sizeof buf));
	else if (strcmp(mode, "?"))
		printf(", target %s", mode);
}

static void print_stats(const json_t *st)
{
	const json_t *links = json_object_get(st, "links");
	const json_t *mem = json_object_get(st, "memory");
	char a[32], b[32], c[32], d[32], e[32];

	if (!json_is_object(st)) {
		printf("no iteration yet\n");
		return;
	}
	printf("iteration %lld: links %lld, elements %lld, leaves %lld, "
	       "clusters %lld\n",
	       lx_jint(st, "iteration"), lx_jint(links, "stored"),
	       lx_jint(st, "elements"), lx_jint(st, "leaves"),
	       lx_jint(st, "clusters"));
	printf("residual %s, error estimate %s, converged %s\n",
	       lx_jnum(st, "residual", "%.3g", a, sizeof a),
	       lx_jnum(st, "error_estimate", "%.3g", b, sizeof b),
	       json_is_true(json_object_get(st, "converged")) ? "yes" : "no");
	printf("time %s s (last iteration %s s), memory %s (peak %s, the "
	       "solver's own %s)\n",
	       lx_jnum(st, "seconds_total", "%.3f", a, sizeof a),
	       lx_jnum(st, "seconds", "%.3f", b, sizeof b),
	       lx_jbytes(mem, "total_bytes", c, sizeof c),
	       lx_jbytes(mem, "peak_bytes", d, sizeof d),
	       lx_jbytes(mem, "peak_own_bytes", e, sizeof e));
	if (lx_jint(st, "budget_restarts") > 0)
		printf("the memory budget started the solve over %lld times, "
		       "at eps %s\n",
		       lx_jint(st, "budget_restarts"),
		       lx_jnum(st, "eps", "%g", a, sizeof a));
}

int lx_cmd_info(lx_ctx *cx)
{
	long long id;
	json_t *reply = NULL, *j;
	char a[32], b[32];
	int rc;

	if (lx_pos_id(cx, 0, "job", &id) != 0)
		return LX_EXIT_USAGE;
	rc = lx_simple_call(cx, lx_req_id(RP_CMD_JOB_INFO, "job", id), &reply);
	if (rc != LX_EXIT_OK || cx->json) {
		json_decref(reply);
		return rc;
	}
	j = json_object_get(reply, "job");
	printf("job %lld \"%s\" on scene %lld, solver %s\n", lx_jint(j, "id"),
	       lx_jstr(j, "name"), lx_jint(j, "scene"), lx_jstr(j, "solver"));
	printf("state %s, iteration %lld", lx_jstr(j, "state"),
	       lx_jint(j, "iteration"));
	print_target(json_object_get(j, "target"));
	printf("\n");
	if (json_is_string(json_object_get(j, "error")))
		printf("error: %s\n", lx_jstr(j, "error"));
	print_pairs("options:", json_object_get(j, "options"), 0);
	print_stats(json_object_get(j, "stats"));
	printf("created %s, updated %s (Unix time)\n",
	       lx_jnum(j, "created", "%.0f", a, sizeof a),
	       lx_jnum(j, "updated", "%.0f", b, sizeof b));
	json_decref(reply);
	return LX_EXIT_OK;
}

/* --------------------------------------------------------------- status */

static void print_uptime(double s)
{
	long t = (long)s;

	if (t >= 86400)
		printf("%ldd %ldh %ldm", t / 86400, t % 86400 / 3600,
		       t % 3600 / 60);
	else if (t >= 3600)
		printf("%ldh %ldm %lds", t / 3600, t % 3600 / 60, t % 60);
	else
		printf("%ldm %lds", t / 60, t % 60);
}

int lx_cmd_status(lx_ctx *cx)
{
	json_t *reply = NULL, *mem, *v;
	char a[32], b[32], c[32];
	size_t i;
	int rc;

	if ((rc = lx_open(cx)) != 0)
		return rc;
	rc = lx_call(cx, rp_request(RP_CMD_STATUS, -1), &reply);
	if (rc != LX_EXIT_OK || cx->json) {
		if (rc == LX_EXIT_OK)
			lx_print_json(reply);
		json_decref(reply);
		return rc;
	}
	printf("%s (protocol %lld) at %s, up ",
	       lx_jstr(cx->conn.hello, "server"), lx_jint(reply, "version"),
	       cx->conn.where);
	print_uptime(json_number_value(json_object_get(reply, "uptime_s")));
	printf(", %lld connection(s)\n", lx_jint(reply, "connections"));
	print_pairs("jobs:", json_object_get(reply, "jobs"), 0);
	mem = json_object_get(reply, "memory");
	printf("memory: %s (scenes %s, jobs %s)\n",
	       lx_jbytes(mem, "total_bytes", a, sizeof a),
	       lx_jbytes(mem, "scenes_bytes", b, sizeof b),
	       lx_jbytes(mem, "jobs_bytes", c, sizeof c));
	print_pairs("  by kind:", json_object_get(mem, "by_kind"), 1);
	json_array_foreach(json_object_get(reply, "scenes"), i, v) printf(
	        "scene %lld \"%s\": %s\n", lx_jint(v, "id"), lx_jstr(v, "name"),
	        lx_jbytes(v, "memory_bytes", a, sizeof a));
	json_array_foreach(json_object_get(reply, "job_list"), i, v) printf(
	        "job %lld (%s): %s\n", lx_jint(v, "id"), lx_jstr(v, "state"),
	        lx_jbytes(v, "memory_bytes", a, sizeof a));
	v = json_object_get(reply, "modbus");
	if (json_is_object(v)) {
		if (json_is_integer(json_object_get(v, "port")))
			printf("modbus: %s on port %lld, %lld client(s)\n",
			       lx_jstr(v, "state"), lx_jint(v, "port"),
			       lx_jint(v, "clients"));
		else
			printf("modbus: %s\n", lx_jstr(v, "state"));
	}
	json_decref(reply);
	return LX_EXIT_OK;
}
