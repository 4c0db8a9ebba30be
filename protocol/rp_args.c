/*
 * rp_args.c -- typed getters for request arguments.
 *
 * The daemon validates every request member through these, so the wire
 * rules live in one place: integers are JSON integers (5.0 is not a count),
 * numbers are finite, booleans are true/false (not 0/1), an optional
 * member is omitted rather than null, and every refusal names the member
 * and what was expected ("'eps' must be a finite number, got a string").
 */
#include "rp_int.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/*
 * Fetch obj[key]: returns the value, or NULL with *rc set to 1 (absent,
 * optional) or -1 (absent and required, or obj not an object).
 */
static json_t *lookup(const json_t *obj, const char *key, int required, int *rc,
                      rp_error *err)
{
	json_t *v;

	if (!json_is_object(obj)) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "request is not a JSON object (looking for '%s')", key);
		*rc = -1;
		return NULL;
	}
	v = json_object_get(obj, key);
	if (!v) {
		if (required)
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "missing required member '%s'", key);
		*rc = required ? -1 : 1;
	}
	return v;
}

int rp_arg_u64(const json_t *obj, const char *key, int required, uint64_t *out,
               rp_error *err)
{
	int rc;
	json_t *v = lookup(obj, key, required, &rc, err);

	if (!v)
		return rc;
	if (!json_is_integer(v) || json_integer_value(v) < 0) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' must be a non-negative integer, got %s", key,
		        json_is_integer(v) ? "a negative integer"
		                           : rp_json_kind(v));
		return -1;
	}
	*out = (uint64_t)json_integer_value(v);
	return 0;
}

int rp_arg_double(const json_t *obj, const char *key, int required, double *out,
                  rp_error *err)
{
	int rc;
	json_t *v = lookup(obj, key, required, &rc, err);

	if (!v)
		return rc;
	if (!json_is_number(v) || !isfinite(json_number_value(v))) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' must be a finite number, got %s", key,
		        rp_json_kind(v));
		return -1;
	}
	*out = json_number_value(v);
	return 0;
}

int rp_arg_bool(const json_t *obj, const char *key, int required, int *out,
                rp_error *err)
{
	int rc;
	json_t *v = lookup(obj, key, required, &rc, err);

	if (!v)
		return rc;
	if (!json_is_boolean(v)) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' must be true or false, got %s", key,
		        rp_json_kind(v));
		return -1;
	}
	*out = json_is_true(v);
	return 0;
}

int rp_arg_string(const json_t *obj, const char *key, int required,
                  const char **out, rp_error *err)
{
	int rc;
	json_t *v = lookup(obj, key, required, &rc, err);

	if (!v)
		return rc;
	if (!json_is_string(v)) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' must be a string, got %s", key, rp_json_kind(v));
		return -1;
	}
	*out = json_string_value(v);
	return 0;
}

/* Read a JSON array of exactly n finite numbers into out. */
static int read_vec(const json_t *v, double *out, size_t n, const char *what,
                    size_t index, rp_error *err)
{
	char where[96];

	if (index == (size_t)-1)
		snprintf(where, sizeof where, "'%s'", what);
	else
		snprintf(where, sizeof where, "'%s'[%zu]", what, index);
	if (!json_is_array(v) || json_array_size(v) != n) {
		if (json_is_array(v))
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "%s must be an array of %zu numbers, got %zu "
			        "elements",
			        where, n, json_array_size(v));
		else
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "%s must be an array of %zu numbers, got %s",
			        where, n, rp_json_kind(v));
		return -1;
	}
	for (size_t i = 0; i < n; i++) {
		json_t *e = json_array_get(v, i);
		if (!json_is_number(e) || !isfinite(json_number_value(e))) {
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "%s element %zu must be a finite number, "
			        "got %s",
			        where, i, rp_json_kind(e));
			return -1;
		}
		out[i] = json_number_value(e);
	}
	return 0;
}

int rp_arg_vec(const json_t *obj, const char *key, int required, double *out,
               size_t n, rp_error *err)
{
	int rc;
	double tmp[16];
	json_t *v = lookup(obj, key, required, &rc, err);

	if (!v)
		return rc;
	if (n == 0 || n > 16) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s': vectors of %zu numbers are not supported", key,
		        n);
		return -1;
	}
	/* Leave the caller's default untouched when the vector is bad. */
	if (read_vec(v, tmp, n, key, (size_t)-1, err) != 0)
		return -1;
	for (size_t i = 0; i < n; i++)
		out[i] = tmp[i];
	return 0;
}

int rp_arg_points(const json_t *obj, const char *key, size_t max_points,
                  double **out, size_t *n, rp_error *err)
{
	int rc;
	size_t count;
	double *p;
	json_t *v = lookup(obj, key, 1, &rc, err);

	*out = NULL;
	*n = 0;
	if (!v)
		return -1;
	if (!json_is_array(v)) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' must be an array of [x,y,z,nx,ny,nz] arrays, "
		        "got %s",
		        key, rp_json_kind(v));
		return -1;
	}
	count = json_array_size(v);
	if (count == 0) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' is empty: give at least one point", key);
		return -1;
	}
	if (count > max_points) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "'%s' holds %zu points, more than the limit of %zu",
		        key, count, max_points);
		return -1;
	}
	p = malloc(count * 6 * sizeof *p);
	if (!p) {
		if (err) {
			err->code = RP_ERR_NOMEM;
			snprintf(err->msg, sizeof err->msg,
			         "out of memory for %zu points", count);
		}
		return -1;
	}
	for (size_t i = 0; i < count; i++) {
		double *q = p + 6 * i;
		if (read_vec(json_array_get(v, i), q, 6, key, i, err) != 0) {
			free(p);
			return -1;
		}
		if (q[3] == 0 && q[4] == 0 && q[5] == 0) {
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "'%s'[%zu] has a zero normal", key, i);
			free(p);
			return -1;
		}
	}
	*out = p;
	*n = count;
	return 0;
}

/* ------------------------------------------------------------ points file */

int rp_point_line_parse(const char *line, double p[6], const char **why)
{
	const char *s = line;
	char *end;
	int k = 0;

	for (;;) {
		while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\n')
			s++;
		if (*s == '\0' || *s == '#') /* end, or a comment */
			break;
		if (k == 6) {
			*why = "more than 6 numbers";
			return -1;
		}
		errno = 0;
		p[k] = strtod(s, &end);
		if (end == s || !isfinite(p[k]) || errno == ERANGE ||
		    (*end && !strchr(" \t\r\n#", *end))) {
			*why = "not a finite number";
			return -1;
		}
		k++;
		s = end;
	}
	if (k == 0)
		return 0;
	if (k != 6) {
		*why = "expected 6 numbers: x y z nx ny nz";
		return -1;
	}
	if (p[3] == 0 && p[4] == 0 && p[5] == 0) {
		*why = "the normal is zero";
		return -1;
	}
	return 1;
}
