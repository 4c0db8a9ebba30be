/*
 * fuzz_args.c -- the argument getters (protocol/rp_args.c) and the pure
 * checks the daemon makes on a request's arguments.
 *
 * The input is a request header: JSON, parsed as the frame decoder
 * parses one (any value, duplicate keys refused).  Every getter --
 * rp_arg_u64, _double, _bool, _string, _vec (1 to 16 numbers, and the
 * sizes refused) and _points (with a small and the daemon's default
 * max_points) -- is called, required and optional, on each member the
 * daemon reads, on each member the input has and on one that is absent.
 * Each result is checked against the wire rules as rp.h states them,
 * written again here: integers are non-negative JSON integers, numbers
 * finite, booleans true or false; an absent optional member returns 1,
 * an absent required one -1; a refusal is bad_request, names the member
 * and leaves the caller's default alone.
 *
 * The checks the daemon makes beyond the getters, where they are pure
 * functions: job.create's "options" through ej_options_set (an accepted
 * set of options must read back the same through ej_options, the form
 * job.info reports) and its "solver" through rad_solver_kind_parse;
 * "cmd" through rp_cmd_lookup; and each string member as an address
 * (rp_addr_parse, rp_addr_parse_listen), a points-file line
 * (rp_point_line_parse) and a token (rp_token_equal); each number as a
 * grid size (rp_grid_spacing).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "engine_json.h"
#include "fuzz.h"
#include "rad.h"
#include "rp.h"

/* The members the daemon's commands read (daemon/server/cmd). */
static const char *const daemon_keys[] = {
        "cmd",        "id",       "version", "token",  "client",
        "scene",      "job",      "name",    "solver", "options",
        "iterations", "converge", "seconds", "eps",    "points",
        "point",      "normal",   "origin",  "u",      "v",
        "spacing",    "format",   "node",    "bytes",  "absent"};

/* A refusal: bad_request, naming the member (when short enough to fit
 * the message whole). */
static void check_refusal(const char *key, const rp_error *err)
{
	char quoted[64];

	FUZZ_CHECK(err->code == RP_ERR_BAD_REQUEST,
	           "a refused argument is bad_request");
	FUZZ_CHECK(memchr(err->msg, '\0', sizeof err->msg) != NULL,
	           "an error message is terminated");
	if (strlen(key) + 3 > sizeof quoted)
		return;
	snprintf(quoted, sizeof quoted, "'%s'", key);
	FUZZ_CHECK(strstr(err->msg, quoted) != NULL,
	           "a refusal names the member");
}

/*
 * What a getter returned for obj[key], given whether the value was of the
 * kind it takes (ok).  Returns 1 when the getter stored a value.
 */
static int check_rc(const json_t *obj, const char *key, int required, int ok,
                    int rc, const rp_error *err)
{
	const json_t *v = json_object_get(obj, key);

	if (!json_is_object(obj)) {
		FUZZ_CHECK(rc == -1 && err->code == RP_ERR_BAD_REQUEST,
		           "a request that is no object is refused");
		return 0;
	}
	if (!v) {
		FUZZ_CHECK(rc == (required ? -1 : 1),
		           "an absent member: -1 if required, else 1");
		if (required)
			check_refusal(key, err);
		return 0;
	}
	FUZZ_CHECK(rc == (ok ? 0 : -1),
	           "a member is taken exactly when it is of the kind asked");
	if (rc != 0)
		check_refusal(key, err);
	return rc == 0;
}

static int finite_number(const json_t *v)
{
	return json_is_number(v) && isfinite(json_number_value(v));
}

/* v is an array of n finite numbers. */
static int finite_vec(const json_t *v, size_t n)
{
	if (!json_is_array(v) || json_array_size(v) != n)
		return 0;
	for (size_t i = 0; i < n; i++)
		if (!finite_number(json_array_get(v, i)))
			return 0;
	return 1;
}

static void check_scalars(const json_t *obj, const char *key, int required)
{
	const json_t *v = json_object_get(obj, key);
	rp_error err = {0};
	uint64_t u = 77;
	double d = 77;
	int b = 77;
	const char *s = "default";
	int rc, ok;

	/* Each getter stores what the member holds, or leaves the default. */
	rc = rp_arg_u64(obj, key, required, &u, &err);
	ok = json_is_integer(v) && json_integer_value(v) >= 0;
	FUZZ_CHECK(check_rc(obj, key, required, ok, rc, &err)
	                   ? u == (uint64_t)json_integer_value(v)
	                   : u == 77,
	           "rp_arg_u64: the value stored, or the default left");
	rc = rp_arg_double(obj, key, required, &d, &err);
	FUZZ_CHECK(check_rc(obj, key, required, finite_number(v), rc, &err)
	                   ? d == json_number_value(v)
	                   : d == 77,
	           "rp_arg_double: the value stored, or the default left");
	rc = rp_arg_bool(obj, key, required, &b, &err);
	FUZZ_CHECK(check_rc(obj, key, required, json_is_boolean(v), rc, &err)
	                   ? b == json_is_true(v)
	                   : b == 77,
	           "rp_arg_bool: the value stored, or the default left");
	rc = rp_arg_string(obj, key, required, &s, &err);
	FUZZ_CHECK(check_rc(obj, key, required, json_is_string(v), rc, &err)
	                   ? s == json_string_value(v)
	                   : !strcmp(s, "default"),
	           "rp_arg_string: the value stored, or the default left");
}

static void check_vecs(const json_t *obj, const char *key, int required)
{
	static const size_t sizes[] = {0, 1, 2, 3, 6, 16, 17};
	const json_t *v = json_object_get(obj, key);

	for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
		size_t n = sizes[k];
		double out[17];
		rp_error err = {0};
		for (size_t i = 0; i < 17; i++)
			out[i] = 77;
		int rc = rp_arg_vec(obj, key, required, out, n, &err);
		int ok = n >= 1 && n <= 16 && finite_vec(v, n);
		if (check_rc(obj, key, required, ok, rc, &err)) {
			for (size_t i = 0; i < n; i++)
				FUZZ_CHECK(
				        out[i] == json_number_value(
				                          json_array_get(v, i)),
				        "rp_arg_vec stores the numbers");
		}
		for (size_t i = rc == 0 ? n : 0; i < 17; i++)
			FUZZ_CHECK(out[i] == 77, "rp_arg_vec writes only what "
			                         "it stores");
	}
}

/* v holds 1..max points [x,y,z,nx,ny,nz], finite, normals not zero. */
static int valid_points(const json_t *v, size_t max)
{
	size_t n = json_array_size(v);

	if (!json_is_array(v) || n == 0 || n > max)
		return 0;
	for (size_t i = 0; i < n; i++) {
		const json_t *p = json_array_get(v, i);
		if (!finite_vec(p, 6))
			return 0;
		if (json_number_value(json_array_get(p, 3)) == 0 &&
		    json_number_value(json_array_get(p, 4)) == 0 &&
		    json_number_value(json_array_get(p, 5)) == 0)
			return 0;
	}
	return 1;
}

static void check_points(const json_t *obj, const char *key)
{
	static const size_t max[] = {1, 3, 1000000};
	const json_t *v = json_object_get(obj, key);

	for (size_t k = 0; k < sizeof max / sizeof max[0]; k++) {
		double *p = NULL;
		size_t n = 77;
		rp_error err = {0};
		int rc = rp_arg_points(obj, key, max[k], &p, &n, &err);
		if (check_rc(obj, key, 1, valid_points(v, max[k]), rc, &err)) {
			FUZZ_CHECK(n == json_array_size(v) && p != NULL,
			           "rp_arg_points returns every point");
			for (size_t i = 0; i < 6 * n; i++)
				FUZZ_CHECK(
				        p[i] == json_number_value(
				                        json_array_get(
				                                json_array_get(
				                                        v,
				                                        i / 6),
				                                i % 6)),
				        "rp_arg_points stores the numbers");
		} else {
			FUZZ_CHECK(p == NULL && n == 0,
			           "refused points return none");
		}
		free(p);
	}
}

static void check_key(const json_t *obj, const char *key)
{
	for (int required = 0; required < 2; required++) {
		check_scalars(obj, key, required);
		check_vecs(obj, key, required);
	}
	check_points(obj, key);
}

/* job.create's options, as srv_job_options_parse reads them. */
static void check_options(json_t *opts)
{
	rad_options o, back;
	char msg[256] = "";

	rad_options_default(&o);
	rad_options_accuracy(&o, RAD_ACCURACY_DEFAULT, NULL);
	ej_status st = ej_options_set(&o, opts, msg, sizeof msg);
	FUZZ_CHECK(st == EJ_OK || st == EJ_TYPE || st == EJ_INVALID,
	           "ej_options_set says ok, type or invalid");
	if (st != EJ_OK) {
		FUZZ_CHECK(msg[0] != '\0', "a refused option says why");
		return;
	}
	/* What job.info reports must be accepted as the same options. */
	json_t *shown = ej_options(&o);
	rad_options_default(&back);
	FUZZ_CHECK(ej_options_set(&back, shown, msg, sizeof msg) == EJ_OK,
	           "the options reported are accepted");
	json_t *again = ej_options(&back);
	FUZZ_CHECK(json_equal(shown, again),
	           "the options reported read back the same");
	json_decref(again);
	json_decref(shown);
}

/* A string as the daemon's other parsers would see it. */
static void check_string(const char *s, const char *other)
{
	rp_addr a;
	rp_error err = {0};
	double p[6];
	const char *why = NULL;

	if (rp_addr_parse(s, &a, &err) == 0) {
		FUZZ_CHECK(a.kind == RP_ADDR_UNIX
		                   ? a.path[0] != '\0' &&
		                             memchr(a.path, '\0', sizeof a.path)
		                   : a.port > 0 && memchr(a.host, '\0',
		                                          sizeof a.host),
		           "a parsed address has a path or a host and a port");
		(void)rp_addr_is_loopback(&a);
	}
	if (rp_addr_parse_listen(s, &a, &err) == 0)
		FUZZ_CHECK(a.kind == RP_ADDR_TCP, "a listener is TCP");
	int rc = rp_point_line_parse(s, p, &why);
	FUZZ_CHECK(rc >= -1 && rc <= 1, "a points line: -1, 0 or 1");
	if (rc == 1)
		for (int i = 0; i < 6; i++)
			FUZZ_CHECK(isfinite(p[i]) && (p[3] != 0 || p[4] != 0 ||
			                              p[5] != 0),
			           "a point is finite with a normal");
	if (rc == -1)
		FUZZ_CHECK(why != NULL, "a refused points line says why");
	size_t ls = strlen(s), lo = strlen(other);
	FUZZ_CHECK(rp_token_equal(s, ls, other, lo) ==
	                   (ls == lo && !memcmp(s, other, ls)),
	           "rp_token_equal is equality");
}

/* The checks beyond the getters on one member. */
static void check_member(const char *key, json_t *v)
{
	if (json_is_string(v))
		check_string(json_string_value(v), key);
	if (json_is_number(v)) {
		double sp = rp_grid_spacing(json_number_value(v));
		FUZZ_CHECK(sp > 0 && sp <= 10, "a grid spacing is in (0, 10]");
	}
	if (!strcmp(key, "options"))
		check_options(v);
	if (!strcmp(key, "solver") && json_is_string(v)) {
		rad_solver_kind k;
		if (rad_solver_kind_parse(json_string_value(v), &k) == RAD_OK)
			FUZZ_CHECK(!strcmp(rad_solver_kind_name(k),
			                   json_string_value(v)),
			           "a solver parses as its own name");
	}
	if (!strcmp(key, "cmd")) {
		int k = rp_cmd_lookup(json_string_value(v));
		FUZZ_CHECK(k < 0 || !strcmp(rp_cmd_name((rp_cmd)k),
		                            json_string_value(v)),
		           "a command looked up has that name");
	}
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	json_t *obj =
	        json_loadb((const char *)data, size,
	                   JSON_DECODE_ANY | JSON_REJECT_DUPLICATES, NULL);
	const char *key;
	json_t *v;

	if (!obj)
		return 0;
	for (size_t i = 0; i < sizeof daemon_keys / sizeof daemon_keys[0]; i++)
		check_key(obj, daemon_keys[i]);
	json_object_foreach(obj, key, v)
	{
		check_key(obj, key);
		check_member(key, v);
	}
	/* The whole request as options: unknown keys are refused. */
	check_options(obj);
	json_decref(obj);
	return 0;
}
