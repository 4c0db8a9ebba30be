/*
 * rp.c -- the protocol's tables and small messages: error codes and the
 * command table (both expanded from the X-macro lists in rp.h), reply and
 * request constructors, reply classification, the constant-time token
 * comparison and the EN 12464-1 grid spacing.
 *
 * Everything here is a pure function of its arguments; the tables are
 * const and built at compile time, so the library has no initialisation
 * and no state to share between threads.
 */
#include "rp_int.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* ------------------------------------------------------------ error codes */

static const struct {
	const char *name;
	int closes;
} err_table[RP_ERR_COUNT] = {
#define RP_ERR_ROW_(name, str, close) {str, close},
        RP_ERRORS(RP_ERR_ROW_)
#undef RP_ERR_ROW_
};

const char *rp_err_name(rp_err e)
{
	if ((unsigned)e >= RP_ERR_COUNT)
		return "internal";
	return err_table[e].name;
}

int rp_err_closes(rp_err e)
{
	if ((unsigned)e >= RP_ERR_COUNT)
		return 0;
	return err_table[e].closes;
}

rp_err rp_err_parse(const char *name)
{
	if (!name)
		return RP_ERR_INTERNAL;
	for (int i = 0; i < RP_ERR_COUNT; i++)
		if (strcmp(err_table[i].name, name) == 0)
			return (rp_err)i;
	return RP_ERR_INTERNAL;
}

/* --------------------------------------------------------- command table */

static const struct {
	const char *name;
	int payload;
	rp_role role;
	const char *help;
} cmd_table[RP_CMD_COUNT] = {
#define RP_CMD_ROW_(name, str, payload, role, help)                            \
	{str, payload, RP_ROLE_##role, help},
        RP_COMMANDS(RP_CMD_ROW_)
#undef RP_CMD_ROW_
};

static const char *const role_names[] = {"none", "read", "submit", "admin"};

const char *rp_role_name(rp_role r)
{
	return (unsigned)r <= RP_ROLE_ADMIN ? role_names[r] : "?";
}

int rp_role_parse(const char *name)
{
	for (int r = RP_ROLE_READ; r <= RP_ROLE_ADMIN; r++)
		if (name && strcmp(name, role_names[r]) == 0)
			return r;
	return -1;
}

rp_role rp_cmd_role(rp_cmd c)
{
	return (unsigned)c < RP_CMD_COUNT ? cmd_table[c].role : RP_ROLE_ADMIN;
}

const char *rp_cmd_name(rp_cmd c)
{
	if ((unsigned)c >= RP_CMD_COUNT)
		return NULL;
	return cmd_table[c].name;
}

const char *rp_cmd_help(rp_cmd c)
{
	if ((unsigned)c >= RP_CMD_COUNT)
		return NULL;
	return cmd_table[c].help;
}

int rp_cmd_takes_payload(rp_cmd c)
{
	if ((unsigned)c >= RP_CMD_COUNT)
		return 0;
	return cmd_table[c].payload;
}

int rp_cmd_lookup(const char *name)
{
	if (!name)
		return -1;
	for (int i = 0; i < RP_CMD_COUNT; i++)
		if (strcmp(cmd_table[i].name, name) == 0)
			return i;
	return -1;
}

/* --------------------------------------------------------------- messages */

void rp_limits_default(rp_limits *l)
{
	l->max_header_bytes = RP_DEFAULT_MAX_HEADER_BYTES;
	l->max_payload_bytes = RP_DEFAULT_MAX_PAYLOAD_BYTES;
}

/* A fresh reply object carrying the request's id (if any) and "ok". */
static json_t *reply_new(json_t *id, int ok)
{
	json_t *r = json_object();

	if (!r)
		return NULL;
	if ((id && json_object_set(r, "id", id) != 0) ||
	    json_object_set_new(r, "ok", json_boolean(ok)) != 0) {
		json_decref(r);
		return NULL;
	}
	return r;
}

json_t *rp_reply_ok(json_t *id)
{
	return reply_new(id, 1);
}

json_t *rp_reply_error(json_t *id, rp_err code, const char *fmt, ...)
{
	char msg[512];
	va_list ap;
	json_t *r = reply_new(id, 0);

	if (!r)
		return NULL;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	/* jansson refuses invalid UTF-8: vsnprintf may have cut a
	 * character in two (trim it), or the message quotes peer bytes. */
	json_t *m = json_string(msg);
	for (size_t len = strlen(msg), k = 0; !m && k < 3 && len > 0; k++) {
		msg[--len] = '\0';
		m = json_string(msg);
	}
	if (!m)
		m = json_string("(message not valid UTF-8)");
	json_t *e = json_pack("{s:s, s:o*}", "code", rp_err_name(code),
	                      "message", m);
	if (!e || json_object_set_new(r, "error", e) != 0) {
		json_decref(r);
		return NULL;
	}
	return r;
}

json_t *rp_request(rp_cmd cmd, long long id)
{
	const char *name = rp_cmd_name(cmd);
	json_t *r;

	if (!name)
		return NULL;
	r = json_object();
	if (!r)
		return NULL;
	if (json_object_set_new(r, "cmd", json_string(name)) != 0 ||
	    (id >= 0 && json_object_set_new(r, "id", json_integer(id)) != 0)) {
		json_decref(r);
		return NULL;
	}
	return r;
}

rp_err rp_reply_status(const json_t *reply, rp_error *err)
{
	const json_t *ok, *e, *code, *msg;
	rp_err c;

	if (!json_is_object(reply)) {
		rp_fail(err, RP_ERR_BAD_FRAME, "reply is not a JSON object");
		return RP_ERR_BAD_FRAME;
	}
	ok = json_object_get(reply, "ok");
	if (json_is_true(ok)) {
		rp_fail(err, RP_ERR_OK, "%s", "");
		return RP_ERR_OK;
	}
	if (!json_is_false(ok)) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "reply has no boolean member 'ok'");
		return RP_ERR_BAD_FRAME;
	}
	e = json_object_get(reply, "error");
	code = json_object_get(e, "code");
	msg = json_object_get(e, "message");
	if (!json_is_object(e) || !json_is_string(code)) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "error reply without an 'error' object holding a "
		        "string 'code'");
		return RP_ERR_BAD_FRAME;
	}
	c = rp_err_parse(json_string_value(code));
	if (c == RP_ERR_OK) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "error reply with error code \"ok\"");
		return RP_ERR_BAD_FRAME;
	}
	if (json_is_string(msg))
		rp_fail(err, c, "%s", json_string_value(msg));
	else
		rp_fail(err, c, "(no message)");
	/* An unknown code maps to internal; keep the peer's name visible. */
	if (err && c == RP_ERR_INTERNAL &&
	    strcmp(json_string_value(code), "internal") != 0)
		snprintf(err->msg, sizeof err->msg,
		         "unknown error code '%.64s': "
		         "%.160s",
		         json_string_value(code),
		         json_is_string(msg) ? json_string_value(msg) : "");
	return c;
}

/* ------------------------------------------------------------- utilities */

/*
 * Constant time: every byte of the longer string is visited whatever the
 * contents, and the length difference is folded into the accumulator, so
 * the time depends on the lengths only, never on where the strings
 * differ.  Bytes past the end of the shorter string compare against 0.
 */
int rp_token_equal(const void *a, size_t alen, const void *b, size_t blen)
{
	const unsigned char *pa = a, *pb = b;
	size_t n = alen > blen ? alen : blen;
	volatile unsigned char acc = 0;
	size_t lendiff = alen ^ blen;

	for (size_t i = 0; i < n; i++) {
		unsigned char x = i < alen ? pa[i] : 0;
		unsigned char y = i < blen ? pb[i] : 0;
		acc |= (unsigned char)(x ^ y);
	}
	for (size_t k = 0; k < sizeof lendiff; k++)
		acc |= (unsigned char)(lendiff >> (8 * k));
	return acc == 0;
}

/*
 * p = 0.2 * 5^log10(d).  Below 1 cm (and for zero, negative or NaN
 * sizes, which a caller should have refused) d is taken as 0.01 m, giving
 * p = 8 mm: the formula then stays finite and positive.  The result is
 * capped at 10 m (reached at d ~ 269 m), also for an infinite d.
 */
double rp_grid_spacing(double d_m)
{
	double p;

	if (!(d_m >= 0.01)) /* also catches NaN */
		d_m = 0.01;
	if (isinf(d_m))
		return 10.0;
	p = 0.2 * pow(5.0, log10(d_m));
	return p > 10.0 ? 10.0 : p;
}

/* ---------------------------------------------------- internal helpers */

void rp_fail(rp_error *err, rp_err code, const char *fmt, ...)
{
	va_list ap;

	if (!err)
		return;
	err->code = code;
	va_start(ap, fmt);
	vsnprintf(err->msg, sizeof err->msg, fmt, ap);
	va_end(ap);
}

const char *rp_json_kind(const json_t *v)
{
	switch (json_typeof(v)) {
	case JSON_OBJECT:
		return "an object";
	case JSON_ARRAY:
		return "an array";
	case JSON_STRING:
		return "a string";
	case JSON_INTEGER:
		return "an integer";
	case JSON_REAL:
		return "a real number";
	case JSON_TRUE:
	case JSON_FALSE:
		return "a boolean";
	case JSON_NULL:
		return "null";
	}
	return "unknown";
}
