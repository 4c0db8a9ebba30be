/*
 * out.c -- small output helpers shared by the commands: JSON lines, byte
 * counts for people, and lenient reads of reply members (a missing member
 * shows as "?", never a crash).
 */
#include <stdio.h>

#include "client.h"

void lx_print_json(const json_t *v)
{
	json_dumpf(v, stdout, JSON_COMPACT);
	putchar('\n');
	fflush(stdout);
}

const char *lx_fmt_bytes(double b, char *buf, size_t len)
{
	static const char *const unit[] = {"B", "KiB", "MiB", "GiB", "TiB"};
	int u = 0;

	while (b >= 1024 && u < 4) {
		b /= 1024;
		u++;
	}
	snprintf(buf, len, u ? "%.1f %s" : "%.0f %s", b, unit[u]);
	return buf;
}

long long lx_jint(const json_t *o, const char *k)
{
	return (long long)json_integer_value(json_object_get(o, k));
}

double lx_jdbl(const json_t *o, const char *k)
{
	return json_number_value(json_object_get(o, k));
}

const char *lx_jstr(const json_t *o, const char *k)
{
	const char *s = json_string_value(json_object_get(o, k));
	return s ? s : "?";
}

const char *lx_jnum(const json_t *o, const char *k, const char *fmt, char *buf,
                    size_t len)
{
	json_t *v = json_object_get(o, k);

	if (!json_is_number(v))
		return "?";
	snprintf(buf, len, fmt, json_number_value(v));
	return buf;
}

const char *lx_jbytes(const json_t *o, const char *k, char *buf, size_t len)
{
	json_t *v = json_object_get(o, k);

	return json_is_number(v) ? lx_fmt_bytes(json_number_value(v), buf, len)
	                         : "?";
}
