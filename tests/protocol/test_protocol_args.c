/*
 * test_protocol_args.c -- the protocol library around the codec: argument
 * getters refuse every wrong type and name the member; addresses parse in
 * every documented form and refuse bad ports, hosts and over-long paths;
 * tokens compare in constant time; grid spacing follows EN 12464-1; and
 * PROTOCOL.md's error and command tables match rp.h exactly, with every
 * JSON example a valid message (so the documentation cannot drift).
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "rp.h"

/* ------------------------------------------------------------ arg getters */

static json_t *args(void)
{
	json_error_t jerr;
	json_t *o = json_loads(
	        "{\"u\":5,\"neg\":-1,\"real\":2.5,\"whole\":3.0,\"s\":\"txt\","
	        "\"t\":true,\"f\":false,\"n\":null,\"a\":[1,2,3],\"o\":{},"
	        "\"big\":9223372036854775807}",
	        0, &jerr);
	assert_non_null(o);
	return o;
}

static const char *const all_keys[] = {"u", "neg", "real", "whole", "s",
                                       "t", "f",   "n",    "a",     "o"};

/* For each getter, the keys it must accept; every other key is refused. */
static void check_only_accepts(const char *getter, const char *accepted)
{
	json_t *o = args();

	for (size_t i = 0; i < sizeof all_keys / sizeof all_keys[0]; i++) {
		const char *k = all_keys[i];
		char want[16];
		snprintf(want, sizeof want, ",%s,", k);
		int should = strstr(accepted, want) != NULL;
		rp_error err = {0};
		uint64_t u = 77;
		double d = 77;
		int bo = 77;
		const char *s = "default";
		double v[3] = {7, 7, 7};
		int rc;
		if (!strcmp(getter, "u64"))
			rc = rp_arg_u64(o, k, 1, &u, &err);
		else if (!strcmp(getter, "double"))
			rc = rp_arg_double(o, k, 1, &d, &err);
		else if (!strcmp(getter, "bool"))
			rc = rp_arg_bool(o, k, 1, &bo, &err);
		else if (!strcmp(getter, "string"))
			rc = rp_arg_string(o, k, 1, &s, &err);
		else
			rc = rp_arg_vec(o, k, 1, v, 3, &err);
		if (should && rc != 0)
			fail_msg("%s refused '%s': %s", getter, k, err.msg);
		if (!should) {
			if (rc != -1)
				fail_msg("%s accepted '%s'", getter, k);
			assert_int_equal(err.code, RP_ERR_BAD_REQUEST);
			char quoted[16];
			snprintf(quoted, sizeof quoted, "'%s'", k);
			if (!strstr(err.msg, quoted))
				fail_msg("message '%s' does not name %s",
				         err.msg, quoted);
			/* Refused values leave the caller's default. */
			assert_true(u == 77 && d == 77 && bo == 77 &&
			            !strcmp(s, "default") && v[0] == 7);
		}
	}
	json_decref(o);
}

static void test_arg_getters_refuse_wrong_types(void **state)
{
	(void)state;
	check_only_accepts("u64", ",u,");
	check_only_accepts("double", ",u,neg,real,whole,");
	check_only_accepts("bool", ",t,f,");
	check_only_accepts("string", ",s,");
	check_only_accepts("vec", ",a,");
}

static void test_arg_getters_values_and_absence(void **state)
{
	(void)state;
	json_t *o = args();
	rp_error err;
	uint64_t u = 0;
	double d = 0, v[3] = {9, 9, 9};
	int b = -1;
	const char *s = NULL;

	assert_int_equal(rp_arg_u64(o, "u", 1, &u, &err), 0);
	assert_int_equal(u, 5);
	assert_int_equal(rp_arg_u64(o, "big", 1, &u, &err), 0);
	assert_true(u == 9223372036854775807ULL);
	assert_int_equal(rp_arg_double(o, "real", 1, &d, &err), 0);
	assert_true(d == 2.5);
	assert_int_equal(rp_arg_double(o, "u", 1, &d, &err), 0);
	assert_true(d == 5.0);
	assert_int_equal(rp_arg_bool(o, "f", 1, &b, &err), 0);
	assert_int_equal(b, 0);
	assert_int_equal(rp_arg_bool(o, "t", 1, &b, &err), 0);
	assert_int_equal(b, 1);
	assert_int_equal(rp_arg_string(o, "s", 1, &s, &err), 0);
	assert_string_equal(s, "txt");
	assert_int_equal(rp_arg_vec(o, "a", 1, v, 3, &err), 0);
	assert_true(v[0] == 1 && v[1] == 2 && v[2] == 3);
	/* Wrong vector length. */
	assert_int_equal(rp_arg_vec(o, "a", 1, v, 2, &err), -1);
	assert_non_null(strstr(err.msg, "3 elements"));

	/* Absent optional: 1 and the default untouched. */
	u = 42;
	assert_int_equal(rp_arg_u64(o, "missing", 0, &u, &err), 1);
	assert_int_equal(u, 42);
	d = 4.5;
	assert_int_equal(rp_arg_double(o, "missing", 0, &d, &err), 1);
	assert_true(d == 4.5);
	assert_int_equal(rp_arg_bool(o, "missing", 0, &b, &err), 1);
	assert_int_equal(rp_arg_string(o, "missing", 0, &s, &err), 1);
	assert_int_equal(rp_arg_vec(o, "missing", 0, v, 3, &err), 1);
	/* Absent required: -1 naming the member. */
	assert_int_equal(rp_arg_string(o, "scene", 1, &s, &err), -1);
	assert_int_equal(err.code, RP_ERR_BAD_REQUEST);
	assert_non_null(strstr(err.msg, "missing required member 'scene'"));
	/* Not an object at all. */
	json_t *arr = json_array();
	assert_int_equal(rp_arg_u64(arr, "u", 0, &u, &err), -1);
	assert_int_equal(rp_arg_u64(NULL, "u", 0, &u, &err), -1);
	json_decref(arr);
	json_decref(o);
}

static void expect_points_error(const char *json, size_t max,
                                const char *needle)
{
	json_error_t jerr;
	json_t *o = json_loads(json, 0, &jerr);
	double *p = (double *)1;
	size_t n = 99;
	rp_error err = {0};

	assert_non_null(o);
	assert_int_equal(rp_arg_points(o, "points", max, &p, &n, &err), -1);
	assert_null(p);
	assert_int_equal(n, 0);
	assert_int_equal(err.code, RP_ERR_BAD_REQUEST);
	if (!strstr(err.msg, needle))
		fail_msg("message '%s' lacks '%s'", err.msg, needle);
	json_decref(o);
}

static void test_arg_points(void **state)
{
	(void)state;
	json_error_t jerr;
	json_t *o = json_loads("{\"points\":[[1,2,3,0,0,1],[4,5,6,0,-2,0]]}", 0,
	                       &jerr);
	double *p;
	size_t n;
	rp_error err;

	assert_int_equal(rp_arg_points(o, "points", 10, &p, &n, &err), 0);
	assert_int_equal(n, 2);
	assert_true(p[0] == 1 && p[5] == 1 && p[6] == 4 && p[10] == -2);
	free(p);
	json_decref(o);

	expect_points_error("{}", 10, "missing required member 'points'");
	expect_points_error("{\"points\":5}", 10, "an integer");
	expect_points_error("{\"points\":[]}", 10, "empty");
	expect_points_error("{\"points\":[[1,2,3,0,0,1],[1,2,3,0,0,1]]}", 1,
	                    "limit of 1");
	expect_points_error("{\"points\":[[1,2,3,0,0]]}", 10, "5 elements");
	expect_points_error("{\"points\":[[1,2,3,0,0,1],\"x\"]}", 10,
	                    "'points'[1]");
	expect_points_error("{\"points\":[[1,2,3,0,\"0\",1]]}", 10,
	                    "element 4");
	expect_points_error("{\"points\":[[1,2,3,0,0,0]]}", 10, "zero normal");
	expect_points_error("{\"points\":[[1,null,3,0,0,1]]}", 10, "null");
}

/* ---------------------------------------------------------------- address */

/* rp_addr_parse or rp_addr_parse_listen. */
typedef int (*addr_parser)(const char *text, rp_addr *out, rp_error *err);

static void expect_tcp_by(addr_parser parse, const char *text, const char *host,
                          unsigned port)
{
	rp_addr a;
	rp_error err = {0};

	if (parse(text, &a, &err) != 0)
		fail_msg("'%s' refused: %s", text, err.msg);
	assert_int_equal(a.kind, RP_ADDR_TCP);
	assert_string_equal(a.host, host);
	assert_int_equal(a.port, port);
}

static void expect_tcp(const char *text, const char *host, unsigned port)
{
	expect_tcp_by(rp_addr_parse, text, host, port);
}

static void expect_unix(const char *text, const char *path)
{
	rp_addr a;
	rp_error err = {0};

	if (rp_addr_parse(text, &a, &err) != 0)
		fail_msg("'%s' refused: %s", text, err.msg);
	assert_int_equal(a.kind, RP_ADDR_UNIX);
	assert_string_equal(a.path, path);
}

static void expect_error_by(addr_parser parse, const char *text,
                            const char *needle)
{
	rp_addr a;
	rp_error err = {0};

	if (parse(text, &a, &err) == 0)
		fail_msg("'%s' accepted", text ? text : "(null)");
	assert_int_equal(err.code, RP_ERR_BAD_REQUEST);
	if (!strstr(err.msg, needle))
		fail_msg("message '%s' lacks '%s'", err.msg, needle);
}

static void expect_addr_error(const char *text, const char *needle)
{
	expect_error_by(rp_addr_parse, text, needle);
}

static void test_address_forms(void **state)
{
	(void)state;
	expect_tcp("127.0.0.1:7420", "127.0.0.1", 7420);
	expect_tcp("localhost", "localhost", RP_DEFAULT_PORT);
	expect_tcp("tcp:example.org:80", "example.org", 80);
	expect_tcp("tcp:db-1.lan", "db-1.lan", RP_DEFAULT_PORT);
	expect_tcp("[::1]:9000", "::1", 9000);
	expect_tcp("[fe80::1%eth0]", "fe80::1%eth0", RP_DEFAULT_PORT);
	expect_tcp("::1", "::1", RP_DEFAULT_PORT);
	expect_tcp("h:1", "h", 1);
	expect_tcp("h:65535", "h", 65535);
	expect_tcp("h:007420", "h", 7420);
	expect_unix("unix:/run/luxradd.sock", "/run/luxradd.sock");
	expect_unix("unix:rel.sock", "rel.sock");
	expect_unix("/tmp/x.sock", "/tmp/x.sock");
	expect_unix("./x.sock", "./x.sock");

	char path[200] = "/";
	memset(path + 1, 'p', 106); /* 107 bytes: fits sun_path */
	path[107] = '\0';
	expect_unix(path, path);
	path[107] = 'p'; /* 108 bytes: no room for the NUL */
	path[108] = '\0';
	expect_addr_error(path, "too long");
}

static void test_address_errors(void **state)
{
	(void)state;
	expect_addr_error("", "empty address");
	expect_addr_error(NULL, "empty address");
	expect_addr_error("unix:", "empty Unix socket path");
	expect_addr_error("host:", "port '' is not a number 1..65535");
	expect_addr_error("host:-1", "not a number");
	expect_addr_error("host:+80", "not a number");
	expect_addr_error("host:80a", "not a number");
	expect_addr_error("host:80 ", "not a number");
	expect_addr_error("host:0x50", "not a number");
	expect_addr_error("host:65536", "port 65536 is out of range 1..65535");
	expect_addr_error("host:123456", "out of range");
	expect_addr_error("host:99999999999999999999", "out of range");
	expect_addr_error("host:0", "port 0 is only for listening");
	expect_addr_error("[::1]:0", "port 0 is only for listening");
	expect_addr_error(":7420", "empty host");
	expect_addr_error("[::1", "without ']'");
	expect_addr_error("[::1:7420", "without ']'");
	expect_addr_error("[::1]x", "':PORT'");
	expect_addr_error("[::1]:80]", "not a number");
	expect_addr_error("[]:80", "empty host");
	expect_addr_error("my host:80", "not allowed");
	expect_addr_error("user@host", "not allowed");
	expect_addr_error("tcp:/tmp/s", "not allowed");
	expect_addr_error("tcp:", "empty host");

	char host[300];
	memset(host, 'h', 299);
	host[299] = '\0';
	expect_addr_error(host, "255");
}

/* tls: and tls:// mark TCP with TLS, to connect only. */
static void test_address_tls(void **state)
{
	(void)state;
	rp_addr a;
	rp_error e;
	static const char *const forms[] = {"tls://127.0.0.1:7420",
	                                    "tls:127.0.0.1:7420",
	                                    "tls://[::1]:7420", "tls://h"};
	for (size_t i = 0; i < sizeof(forms) / sizeof(forms[0]); i++) {
		assert_int_equal(rp_addr_parse(forms[i], &a, &e), 0);
		assert_int_equal(a.kind, RP_ADDR_TCP);
		assert_int_equal(a.tls, 1);
	}
	assert_int_equal(rp_addr_parse("tcp:h:7420", &a, &e), 0);
	assert_int_equal(a.tls, 0);
	expect_tcp_by(rp_addr_parse, "tls://host.lan:7000", "host.lan", 7000);
	expect_error_by(rp_addr_parse_listen, "tls://0.0.0.0:7420",
	                "speaks TLS by the tls key");
	expect_addr_error("tls://", "empty host");
	/* "tls:/" is the short prefix and then "/": refused, and read
	 * within the string (the fuzzer caught the parser skipping six). */
	assert_int_equal(rp_addr_parse("tls:/", &a, &e), -1);
	assert_int_equal(rp_addr_parse("tls:", &a, &e), -1);
}

/* Listeners: a port is required, 0 is "any free port", no Unix socket. */
static void test_address_listen(void **state)
{
	(void)state;
	static const addr_parser L = rp_addr_parse_listen;
	expect_tcp_by(L, "0.0.0.0:7420", "0.0.0.0", 7420);
	expect_tcp_by(L, "127.0.0.1:0", "127.0.0.1", 0);
	expect_tcp_by(L, "[::]:0", "::", 0);
	expect_tcp_by(L, "[::1]:1502", "::1", 1502);
	expect_tcp_by(L, "tcp:localhost:7421", "localhost", 7421);
	expect_tcp_by(L, "my-host.lan:65535", "my-host.lan", 65535);

	expect_error_by(L, "", "empty address");
	expect_error_by(L, "localhost", "'localhost' is not HOST:PORT");
	expect_error_by(L, "[::1]", "is not HOST:PORT");
	expect_error_by(L, "::1:7420", "is not HOST:PORT (IPv6 as [V6]:PORT)");
	expect_error_by(L, ":7420", "empty host (0.0.0.0 = every IPv4");
	expect_error_by(L, "[]:7420", "empty host");
	expect_error_by(L, "h:65536", "port 65536 is out of range 0..65535");
	expect_error_by(L, "h:x", "port 'x' is not a number 0..65535");
	expect_error_by(L, "h:", "not a number");
	expect_error_by(L, "h:80 ", "not a number");
	expect_error_by(L, "[::1", "'[' without ']'");
	expect_error_by(L, "[::1]7421", "expected ':PORT' after ']'");
	expect_error_by(L, "my host:80", "not allowed in a host");
	expect_error_by(L, "/tmp/s.sock", "is a Unix socket path");
	expect_error_by(L, "unix:/tmp/s.sock", "is a Unix socket path");
}

static void test_address_loopback(void **state)
{
	(void)state;
	static const struct {
		const char *text;
		int loopback;
	} cases[] = {
	        {"127.0.0.1", 1},         {"127.1.2.3:5", 1},
	        {"localhost:1", 1},       {"LocalHost", 1},
	        {"[::1]:7420", 1},        {"[::ffff:127.0.0.1]", 1},
	        {"/tmp/s.sock", 1},       {"0.0.0.0", 0},
	        {"[::]:7420", 0},         {"192.168.1.2", 0},
	        {"10.0.0.1", 0},          {"example.org", 0},
	        {"localhost.evil", 0},    {"128.0.0.1", 0},
	        {"[::ffff:10.0.0.1]", 0},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		rp_addr a;
		rp_error err;
		assert_int_equal(rp_addr_parse(cases[i].text, &a, &err), 0);
		if (rp_addr_is_loopback(&a) != cases[i].loopback)
			fail_msg("'%s': loopback %d, expected %d",
			         cases[i].text, rp_addr_is_loopback(&a),
			         cases[i].loopback);
	}
}

/* -------------------------------------------------------------- utilities */

static void test_token_compare(void **state)
{
	(void)state;
	assert_true(rp_token_equal("secret", 6, "secret", 6));
	assert_false(rp_token_equal("secret", 6, "Secret", 6));
	assert_false(rp_token_equal("secret", 6, "secreT", 6));
	assert_false(rp_token_equal("secret", 6, "secret2", 7));
	assert_false(rp_token_equal("secret", 6, "secre", 5));
	assert_false(rp_token_equal("", 0, "x", 1));
	assert_true(rp_token_equal("", 0, "", 0));
	/* Trailing NULs are bytes too: length differences always count. */
	assert_false(rp_token_equal("ab\0", 3, "ab", 2));
	/* A length differing by a multiple of 256 is not "equal". */
	char a[300], b[300];
	memset(a, 'k', sizeof a);
	memset(b, 'k', sizeof b);
	assert_true(rp_token_equal(a, 300, b, 300));
	assert_false(rp_token_equal(a, 44, b, 300));
}

static void test_grid_spacing_reference_values(void **state)
{
	(void)state;
	assert_float_equal(rp_grid_spacing(1.0), 0.2, 1e-12);
	assert_float_equal(rp_grid_spacing(10.0), 1.0, 1e-12);
	assert_float_equal(rp_grid_spacing(100.0), 5.0, 1e-12);
	assert_float_equal(rp_grid_spacing(5.0), 0.2 * pow(5, log10(5)), 1e-12);
	/* Capped at 10 m from d = 10^(log5 50) ~ 269 m on. */
	assert_float_equal(rp_grid_spacing(260.0), 0.2 * pow(5, log10(260)),
	                   1e-12);
	assert_true(rp_grid_spacing(260.0) < 10.0);
	assert_float_equal(rp_grid_spacing(280.0), 10.0, 0);
	assert_float_equal(rp_grid_spacing(1e6), 10.0, 0);
	assert_float_equal(rp_grid_spacing(INFINITY), 10.0, 0);
	/* Tiny and non-positive sizes are taken as 1 cm: p = 8 mm. */
	assert_float_equal(rp_grid_spacing(0.01), 0.008, 1e-12);
	assert_float_equal(rp_grid_spacing(1e-9), 0.008, 1e-12);
	assert_float_equal(rp_grid_spacing(0.0), 0.008, 1e-12);
	assert_float_equal(rp_grid_spacing(-3.0), 0.008, 1e-12);
	assert_float_equal(rp_grid_spacing(NAN), 0.008, 1e-12);
}

/* ----------------------------------------------------- docs do not drift */

/*
 * Rows "| `name` | yes/no | ..." between <!-- rp:TAG --> and
 * <!-- /rp:TAG --> in PROTOCOL.md, in order: name and flag, and the
 * third column's word in roles (when not NULL).
 */
static int doc_table(const char *doc, const char *tag, char names[][64],
                     int flags[], char roles[][8], int max)
{
	char open[64], close[64];
	snprintf(open, sizeof open, "<!-- rp:%s -->", tag);
	snprintf(close, sizeof close, "<!-- /rp:%s -->", tag);
	const char *s = strstr(doc, open), *e = strstr(doc, close);
	int n = 0;

	if (!s || !e || e < s)
		fail_msg("PROTOCOL.md lacks the %s ... %s markers", open,
		         close);
	for (const char *l = s; l && l < e;
	     l = strchr(l, '\n'), l = l ? l + 1 : l) {
		char name[64], flag[8], role[8] = "";
		int k = sscanf(l, "| `%63[^`]` | %7[a-z] | %7[a-z] |", name,
		               flag, role);
		if (k < 2)
			continue;
		assert_true(n < max);
		snprintf(names[n], 64, "%s", name);
		if (roles)
			snprintf(roles[n], 8, "%s", role);
		if (strcmp(flag, "yes") && strcmp(flag, "no"))
			fail_msg("%s row '%s': flag '%s' is not yes/no", tag,
			         name, flag);
		flags[n++] = !strcmp(flag, "yes");
	}
	return n;
}

/*
 * Every ```json block of PROTOCOL.md holds one or more JSON objects, each
 * a real message: valid JSON, and a request's "cmd" is in the table.
 */
static void check_json_examples(const char *doc)
{
	const char *p = doc;
	int blocks = 0, messages = 0;

	while ((p = strstr(p, "```json\n"))) {
		const char *start = p + 8, *end = strstr(start, "\n```");
		assert_non_null(end);
		size_t off = 0, len = (size_t)(end - start);
		while (off < len) {
			while (off < len && strchr(" \n", start[off]))
				off++;
			if (off == len)
				break;
			json_error_t jerr;
			json_t *v = json_loadb(start + off, len - off,
			                       JSON_DISABLE_EOF_CHECK |
			                               JSON_REJECT_DUPLICATES,
			                       &jerr);
			if (!json_is_object(v))
				fail_msg("PROTOCOL.md example %d: %s near "
				         "'%.40s'",
				         blocks + 1,
				         v ? "not an object" : jerr.text,
				         start + off);
			json_t *cmd = json_object_get(v, "cmd");
			if (cmd && rp_cmd_lookup(json_string_value(cmd)) < 0)
				fail_msg("PROTOCOL.md example uses unknown "
				         "command '%s'",
				         json_string_value(cmd));
			/* A top-level "bytes" announces a payload: only an
			 * upload request and an export reply carry one. */
			int upload = cmd && !strcmp(json_string_value(cmd),
			                            "scene.upload");
			if (json_object_get(v, "bytes") && !upload &&
			    !json_object_get(v, "vertices"))
				fail_msg("PROTOCOL.md example %d has a "
				         "top-level "
				         "\"bytes\" but no payload: '%.60s'",
				         blocks + 1, start + off);
			json_decref(v);
			off += (size_t)jerr.position;
			messages++;
		}
		blocks++;
		p = end + 4;
	}
	/* The spec shows a request or reply for every command. */
	assert_true(blocks >= 25 && messages >= blocks);
}

static void test_protocol_md_tables_match_header(void **state)
{
	(void)state;
	const char *path = LUXRAD_SOURCE_DIR "/protocol/PROTOCOL.md";
	FILE *f = fopen(path, "rb");
	char *doc;
	long len;
	char names[64][64];
	int flags[64], n;

	if (!f)
		fail_msg("cannot open %s", path);
	fseek(f, 0, SEEK_END);
	len = ftell(f);
	rewind(f);
	doc = calloc(1, (size_t)len + 1);
	assert_non_null(doc);
	assert_int_equal(fread(doc, 1, (size_t)len, f), (size_t)len);
	fclose(f);

	check_json_examples(doc);
	n = doc_table(doc, "errors", names, flags, NULL, 64);
	if (n != RP_ERR_COUNT)
		fail_msg("PROTOCOL.md lists %d error codes, rp.h %d", n,
		         RP_ERR_COUNT);
	for (int i = 0; i < n; i++) {
		if (strcmp(names[i], rp_err_name((rp_err)i)))
			fail_msg("error row %d: PROTOCOL.md '%s', rp.h '%s'", i,
			         names[i], rp_err_name((rp_err)i));
		if (flags[i] != rp_err_closes((rp_err)i))
			fail_msg("error '%s': PROTOCOL.md says closes=%d, rp.h "
			         "%d",
			         names[i], flags[i], rp_err_closes((rp_err)i));
	}
	char roles[64][8];
	n = doc_table(doc, "commands", names, flags, roles, 64);
	if (n != RP_CMD_COUNT)
		fail_msg("PROTOCOL.md lists %d commands, rp.h %d", n,
		         RP_CMD_COUNT);
	for (int i = 0; i < n; i++) {
		if (strcmp(names[i], rp_cmd_name((rp_cmd)i)))
			fail_msg("command row %d: PROTOCOL.md '%s', rp.h '%s'",
			         i, names[i], rp_cmd_name((rp_cmd)i));
		if (flags[i] != rp_cmd_takes_payload((rp_cmd)i))
			fail_msg("command '%s': PROTOCOL.md payload=%d, rp.h "
			         "%d",
			         names[i], flags[i],
			         rp_cmd_takes_payload((rp_cmd)i));
		if (strcmp(roles[i], rp_role_name(rp_cmd_role((rp_cmd)i))))
			fail_msg("command '%s': PROTOCOL.md role '%s', rp.h "
			         "'%s'",
			         names[i], roles[i],
			         rp_role_name(rp_cmd_role((rp_cmd)i)));
	}
	free(doc);
}

/* Points-file lines, the format shared by luxrad and luxrad-solve. */
static void test_point_lines(void **state)
{
	(void)state;
	double p[6];
	const char *why = NULL;
	assert_int_equal(rp_point_line_parse(" 1 2 3\t0 1 0\r\n", p, &why), 1);
	assert_true(p[0] == 1 && p[2] == 3 && p[4] == 1);
	assert_int_equal(rp_point_line_parse("   \n", p, &why), 0);
	assert_int_equal(rp_point_line_parse("", p, &why), 0);
	assert_int_equal(rp_point_line_parse("  # a comment\n", p, &why), 0);
	assert_int_equal(rp_point_line_parse("1 2 3 0 1 0# desk", p, &why), 1);
	assert_true(p[5] == 0 && p[4] == 1);
	why = NULL;
	assert_int_equal(rp_point_line_parse("1 2 3 # 0 1 0", p, &why), -1);
	assert_non_null(why);
	const char *bad[] = {"1 2 3 0 0 0",  "1 2 3 0 1",     "1 2 3 0 1 0 7",
	                     "1 2 x 0 1 0",  "1 2 3 0 1 nan", "1 2 3 0 1 1e999",
	                     "1 2 3,0 1 0 0"};
	for (size_t i = 0; i < sizeof(bad) / sizeof(bad[0]); i++) {
		why = NULL;
		assert_int_equal(rp_point_line_parse(bad[i], p, &why), -1);
		assert_non_null(why);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_arg_getters_refuse_wrong_types),
	        cmocka_unit_test(test_arg_getters_values_and_absence),
	        cmocka_unit_test(test_arg_points),
	        cmocka_unit_test(test_address_forms),
	        cmocka_unit_test(test_address_errors),
	        cmocka_unit_test(test_address_tls),
	        cmocka_unit_test(test_address_listen),
	        cmocka_unit_test(test_address_loopback),
	        cmocka_unit_test(test_token_compare),
	        cmocka_unit_test(test_grid_spacing_reference_values),
	        cmocka_unit_test(test_protocol_md_tables_match_header),
	        cmocka_unit_test(test_point_lines),
	};
	if (getenv("LUXRAD_TEST_FILTER"))
		cmocka_set_test_filter(getenv("LUXRAD_TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
