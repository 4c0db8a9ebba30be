/*
 * engine_json.c -- rad.h's options and statistics tables as JSON (see
 * engine_json.h).
 */
#include "engine_json.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

json_t *ej_real(double v)
{
	return isfinite(v) ? json_real(v) : json_null();
}

static json_t *jint(uint64_t v)
{
	return json_integer((json_int_t)v);
}

json_t *ej_memory(const rad_mem_report *m)
{
	json_t *o = json_object(), *kinds = json_object();
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		json_object_set_new(kinds, rad_mem_kind_name((rad_mem_kind)k),
		                    json_integer(m->bytes[k]));
	json_object_set_new(o, "total_bytes", json_integer(m->total));
	json_object_set_new(o, "peak_bytes", json_integer(m->peak_total));
	json_object_set_new(o, "peak_work_bytes", json_integer(m->peak_work));
	json_object_set_new(o, "peak_own_bytes", json_integer(m->peak_own));
	json_object_set_new(o, "by_kind", kinds);
	return o;
}

static json_t *hist(const uint64_t *h)
{
	json_t *a = json_array();
	for (int k = 0; k < RAD_EHIST_BINS; k++)
		json_array_append_new(a, jint(h[k]));
	return a;
}

#define EJ_U32(v) jint(v)
#define EJ_U64(v) jint(v)
#define EJ_DOUBLE(v) ej_real(v)
#define EJ_BOOL(v) json_boolean(v)
#define EJ_HIST(v) hist(v)
#define EJ_MEM(v) ej_memory(&(v))

/* The object a stat goes into: o itself, or its group's, made once. */
static json_t *group_of(json_t *o, const char *group)
{
	if (!group[0])
		return o;
	json_t *g = json_object_get(o, group);
	if (!g) {
		g = json_object();
		json_object_set_new(o, group, g);
	}
	return g;
}

json_t *ej_stats(const rad_stats *st)
{
	json_t *o = json_object();
#define EJ_STAT_(field, group, key, type, ...)                                 \
	json_object_set_new(group_of(o, group), key, EJ_##type(st->field));
	RAD_STATS(EJ_STAT_)
#undef EJ_STAT_
	return o;
}

json_t *ej_options(const rad_options *o)
{
	json_t *obj = json_object();
	for (int i = 0; i < RAD_NOPTIONS; i++) {
		const rad_option_def *d = &rad_option_defs[i];
		double v = rad_option_get(o, d);
		json_t *j = NULL;
		switch (d->type) {
		case RAD_OPT_BOOL:
			j = json_boolean(v != 0);
			break;
		case RAD_OPT_ENUM:
			j = json_string(d->choices[(int)v]);
			break;
		case RAD_OPT_INT:
			j = json_integer((json_int_t)v);
			break;
		case RAD_OPT_DOUBLE:
			j = ej_real(v);
			break;
		}
		json_object_set_new(obj, d->key, j);
	}
	return obj;
}

static ej_status fail(ej_status st, char *msg, size_t len, const char *fmt, ...)
        __attribute__((format(printf, 4, 5)));
static ej_status fail(ej_status st, char *msg, size_t len, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, len, fmt, ap);
	va_end(ap);
	return st;
}

/* One key's JSON value, checked for its type, then by the engine. */
static ej_status set_one(rad_options *o, const rad_option_def *d, json_t *v,
                         char *msg, size_t len)
{
	double x;
	rad_error err;

	switch (d->type) {
	case RAD_OPT_BOOL:
		if (!json_is_boolean(v))
			return fail(EJ_TYPE, msg, len,
			            "option \"%s\" must be true or false",
			            d->key);
		x = json_is_true(v);
		break;
	case RAD_OPT_ENUM:
		if (!json_is_string(v))
			return fail(EJ_TYPE, msg, len,
			            "option \"%s\" must be a string", d->key);
		x = rad_option_choice(d, json_string_value(v));
		if (x < 0)
			return fail(EJ_INVALID, msg, len,
			            "option \"%s\": unknown value \"%.64s\"",
			            d->key, json_string_value(v));
		break;
	case RAD_OPT_INT:
		if (!json_is_integer(v))
			return fail(EJ_TYPE, msg, len,
			            "option \"%s\" must be an integer", d->key);
		x = (double)json_integer_value(v);
		break;
	default:
		if (!json_is_number(v))
			return fail(EJ_TYPE, msg, len,
			            "option \"%s\" must be a number", d->key);
		x = json_number_value(v);
		break;
	}
	if (rad_option_set(o, d, x, &err) != RAD_OK)
		return fail(EJ_INVALID, msg, len, "%s", err.msg);
	return EJ_OK;
}

ej_status ej_options_set(rad_options *o, json_t *obj, char *msg, size_t len)
{
	const rad_option_def *acc = &rad_option_defs[RAD_OPT_accuracy];
	const char *key;
	json_t *v;
	ej_status st;

	if (!obj)
		return EJ_OK;
	if (!json_is_object(obj))
		return fail(EJ_TYPE, msg, len, "\"options\" must be an object");
	v = json_object_get(obj, acc->key);
	if (v && (st = set_one(o, acc, v, msg, len)) != EJ_OK)
		return st;
	json_object_foreach(obj, key, v)
	{
		const rad_option_def *d = rad_option_find(key);
		if (!d)
			return fail(EJ_INVALID, msg, len,
			            "unknown option \"%.64s\"", key);
		if (d != acc && (st = set_one(o, d, v, msg, len)) != EJ_OK)
			return st;
	}
	return EJ_OK;
}
