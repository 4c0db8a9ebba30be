/*
 * mb_config.c -- the Modbus server's configuration keys (modbus_*): the
 * defaults, parsing one key at a time (config.c delegates these keys
 * here), and printing a value back for dumps.  Everything is driven by
 * MB_CONFIG_KEYS in modbus.h.
 */
#include "modbus.h"
#include "rp.h"
#include "textutil.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef enum ktype { K_LISTEN, K_INT, K_ORDER, K_REAL, K_SECONDS } ktype;

typedef struct kdef {
	mb_config_key doc;
	ktype type;
	size_t off;
	double lo, hi;
} kdef;

static const kdef keys[] = {
#define KEY_(key, field, type, lo, hi, metavar, def, help)                     \
	{{#key, metavar, def, help},                                           \
	 K_##type,                                                             \
	 offsetof(mb_config, field),                                           \
	 lo,                                                                   \
	 hi},
        MB_CONFIG_KEYS(KEY_)
#undef KEY_
};

#define NKEYS (sizeof keys / sizeof keys[0])

static const mb_config_key docs[] = {
#define DOC_(key, field, type, lo, hi, metavar, def, help)                     \
	{#key, metavar, def, help},
        MB_CONFIG_KEYS(DOC_)
#undef DOC_
};

const mb_config_key *mb_config_keys(size_t *n)
{
	*n = NKEYS;
	return docs;
}

static const kdef *find(const char *key)
{
	for (size_t i = 0; i < NKEYS; i++)
		if (strcmp(keys[i].doc.name, key) == 0)
			return &keys[i];
	return NULL;
}

int mb_config_is_key(const char *key)
{
	return find(key) != NULL;
}

void mb_config_default(mb_config *c)
{
	memset(c, 0, sizeof *c);
	for (size_t i = 0; i < NKEYS; i++) {
		int rc = mb_config_set(c, keys[i].doc.name,
		                       keys[i].doc.default_value, NULL, 0);
		(void)rc; /* the defaults parse: test_mb_unit checks it */
	}
}

int mb_listen_parse(const char *s, char *host, size_t hostlen, int *port,
                    char *msg, size_t len)
{
	rp_addr a;
	rp_error e;
	*port = 0;
	if (s[0] == '\0' || strcmp(s, "none") == 0) {
		host[0] = '\0';
		return 0;
	}
	if (rp_addr_parse_listen(s, &a, &e) != 0)
		return srv_fail(msg, len, "%s", e.msg);
	if (snprintf(host, hostlen, "%s", a.host) >= (int)hostlen)
		return srv_fail(msg, len, "'%s': host too long", s);
	*port = a.port;
	return 0;
}

static int set_number(mb_config *c, const kdef *k, const char *v, char *msg,
                      size_t len)
{
	char *p = (char *)c + k->off, *end;
	double x;
	if (k->type == K_INT) {
		errno = 0;
		long n = strtol(v, &end, 10);
		if (end == v || *end || errno)
			return srv_fail(msg, len, "%s: '%s' is not an integer",
			                k->doc.name, v);
		x = (double)n;
	} else if (k->type == K_REAL) {
		errno = 0;
		x = strtod(v, &end);
		if (end == v || *end || errno || !isfinite(x))
			return srv_fail(msg, len, "%s: '%s' is not a number",
			                k->doc.name, v);
	} else if (srv_parse_seconds(v, &x) < 0) {
		return srv_fail(
		        msg, len,
		        "%s: '%s' is not a duration (30, 30s, 250ms, 5m, "
		        "1h)",
		        k->doc.name, v);
	}
	if (!(x >= k->lo && x <= k->hi))
		return srv_fail(msg, len, "%s: %s is out of range %g..%g",
		                k->doc.name, v, k->lo, k->hi);
	if (k->type == K_INT)
		*(int *)p = (int)x;
	else
		*(double *)p = x;
	return 0;
}

int mb_config_set(mb_config *c, const char *key, const char *value, char *msg,
                  size_t len)
{
	const kdef *k = find(key);
	if (!k)
		return srv_fail(msg, len, "unknown Modbus key '%s'", key);
	if (k->type == K_LISTEN) {
		char host[sizeof c->listen];
		int port;
		char why[300];
		if (mb_listen_parse(value, host, sizeof host, &port, why,
		                    sizeof why) < 0)
			return srv_fail(msg, len, "%s: %s", key, why);
		if (!host[0])
			c->listen[0] = '\0';
		else
			snprintf(c->listen, sizeof c->listen, "%s", value);
		return 0;
	}
	if (k->type == K_ORDER) {
		if (mb_word_order_parse(value, &c->word_order) < 0)
			return srv_fail(msg, len,
			                "%s: '%s' is not abcd or cdab", key,
			                value);
		return 0;
	}
	return set_number(c, k, value, msg, len);
}

/* The shortest of %.15g / %.17g that reads back as v. */
static int print_double(char *buf, size_t len, double v, const char *suffix)
{
	int n = snprintf(buf, len, "%.15g%s", v, suffix);
	if (n >= 0 && (size_t)n < len && strtod(buf, NULL) != v)
		n = snprintf(buf, len, "%.17g%s", v, suffix);
	return n;
}

int mb_config_get(const mb_config *c, const char *key, char *buf, size_t len)
{
	const kdef *k = find(key);
	if (!k || len == 0)
		return -1;
	const char *p = (const char *)c + k->off;
	int n;
	switch (k->type) {
	case K_LISTEN:
		n = snprintf(buf, len, "%s", c->listen[0] ? c->listen : "none");
		break;
	case K_INT:
		n = snprintf(buf, len, "%d", *(const int *)p);
		break;
	case K_ORDER:
		n = snprintf(buf, len, "%s", mb_word_order_name(c->word_order));
		break;
	default:
		n = print_double(buf, len, *(const double *)p,
		                 k->type == K_SECONDS ? "s" : "");
		break;
	}
	return n < 0 || (size_t)n >= len ? -1 : 0;
}
