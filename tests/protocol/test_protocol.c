/*
 * test_protocol.c -- the wire protocol's frame codec and messages: frames
 * survive a round trip and any split of the byte stream, truncated input
 * never yields a frame, limits are enforced before buffers grow, garbage
 * is refused with a reason, mutated frames never crash the decoder (CI
 * runs this under ASan), and replies and the tables behave.  The argument
 * getters, addresses, utilities and the PROTOCOL.md drift check are in
 * test_protocol_args.c.
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

/* ---------------------------------------------------------------- helpers */

typedef struct buf {
	unsigned char *p;
	size_t n;
} buf;

static void buf_add(buf *b, const void *data, size_t n)
{
	b->p = realloc(b->p, b->n + n + 1);
	assert_non_null(b->p);
	memcpy(b->p + b->n, data, n);
	b->n += n;
	b->p[b->n] = '\0'; /* so strstr works on text frames */
}

static void buf_add_str(buf *b, const char *s)
{
	buf_add(b, s, strlen(s));
}

/* Encode {"cmd": cmd, ...} with an optional payload and append it to b. */
static void add_frame(buf *b, const char *json, const void *payload, size_t len)
{
	json_error_t jerr;
	json_t *h = json_loads(json, 0, &jerr);
	unsigned char *out;
	size_t out_len;

	assert_non_null(h);
	assert_int_equal(rp_frame_encode(h, payload, len, &out, &out_len), 0);
	buf_add(b, out, out_len);
	free(out);
	json_decref(h);
}

static rp_decode decode(const rp_limits *lim, const void *p, size_t n,
                        rp_frame *f, size_t *used, rp_error *err)
{
	return rp_frame_decode(lim, p, n, f, used, err);
}

/* Decode a NUL-terminated string and expect an error with code. */
static void expect_decode_error(const rp_limits *lim, const char *text,
                                rp_err code, const char *needle)
{
	rp_frame f;
	size_t used = 99;
	rp_error err = {0};

	rp_decode d = decode(lim, text, strlen(text), &f, &used, &err);
	if (d != RP_DECODE_ERROR)
		fail_msg("'%s' decoded as %d, expected an error", text, d);
	assert_int_equal(err.code, code);
	assert_null(f.header);
	assert_int_equal(used, 0);
	if (needle && !strstr(err.msg, needle))
		fail_msg("message '%s' for '%s' lacks '%s'", err.msg, text,
		         needle);
}

static const unsigned char mixed_payload[] = {'a',  '\n', 0,    'b', '\n',
                                              '\n', 0xff, 0x00, '{', '}'};

/* ------------------------------------------------------------ round trips */

static void test_roundtrip_without_payload(void **state)
{
	(void)state;
	buf b = {0};
	rp_frame f;
	size_t used;
	rp_error err;

	/* A string with a newline inside: escaped, so still one line. */
	add_frame(&b, "{\"cmd\":\"job.info\",\"id\":7,\"name\":\"a\\nb\"}",
	          NULL, 0);
	assert_ptr_equal(memchr(b.p, '\n', b.n), b.p + b.n - 1);
	assert_int_equal(decode(NULL, b.p, b.n, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_int_equal(used, b.n);
	assert_null(f.payload);
	assert_int_equal(f.payload_len, 0);
	assert_string_equal(json_string_value(json_object_get(f.header, "cmd")),
	                    "job.info");
	assert_string_equal(
	        json_string_value(json_object_get(f.header, "name")), "a\nb");
	assert_int_equal(json_integer_value(json_object_get(f.header, "id")),
	                 7);
	assert_null(json_object_get(f.header, "bytes"));
	json_decref(f.header);
	free(b.p);
}

static void test_roundtrip_payload_with_newlines_and_nuls(void **state)
{
	(void)state;
	buf b = {0};
	rp_frame f;
	size_t used;
	rp_error err;

	add_frame(&b, "{\"cmd\":\"scene.upload\"}", mixed_payload,
	          sizeof mixed_payload);
	assert_int_equal(decode(NULL, b.p, b.n, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_int_equal(used, b.n);
	assert_int_equal(f.payload_len, sizeof mixed_payload);
	assert_memory_equal(f.payload, mixed_payload, sizeof mixed_payload);
	assert_int_equal(json_integer_value(json_object_get(f.header, "bytes")),
	                 sizeof mixed_payload);
	json_decref(f.header);
	free(b.p);
}

static void test_roundtrip_empty_payload(void **state)
{
	(void)state;
	buf b = {0};
	rp_frame f;
	size_t used;
	rp_error err;
	static const char nothing[1];

	add_frame(&b, "{\"cmd\":\"scene.upload\"}", nothing, 0);
	assert_non_null(strstr((char *)b.p, "\"bytes\":0"));
	/* A following frame must not be taken for the payload. */
	add_frame(&b, "{\"cmd\":\"status\"}", NULL, 0);
	assert_int_equal(decode(NULL, b.p, b.n, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_non_null(f.payload); /* "bytes": 0 is a payload, empty */
	assert_int_equal(f.payload_len, 0);
	json_decref(f.header);
	assert_int_equal(decode(NULL, b.p + used, b.n - used, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_string_equal(json_string_value(json_object_get(f.header, "cmd")),
	                    "status");
	json_decref(f.header);
	free(b.p);
}

static void test_encode_drops_stale_bytes_member(void **state)
{
	(void)state;
	json_t *h = json_pack("{s:s, s:i}", "cmd", "status", "bytes", 12);
	unsigned char *out;
	size_t n;

	assert_int_equal(rp_frame_encode(h, NULL, 0, &out, &n), 0);
	assert_null(memmem(out, n, "bytes", 5));
	free(out);
	/* A length without data is a caller bug, refused. */
	assert_int_equal(rp_frame_encode(h, NULL, 5, &out, &n), -1);
	assert_null(out);
	json_decref(h);
	h = json_array();
	assert_int_equal(rp_frame_encode(h, NULL, 0, &out, &n), -1);
	json_decref(h);
}

static void test_encode_header_only(void **state)
{
	(void)state;
	json_t *h = json_pack("{s:b}", "ok", 1);
	unsigned char *out;
	size_t n;
	buf b = {0};
	rp_frame f;
	size_t used;
	rp_error err;

	assert_int_equal(rp_frame_encode_header(h, 3, &out, &n), 0);
	assert_int_equal(out[n - 1], '\n');
	buf_add(&b, out, n);
	free(out);
	assert_int_equal(decode(NULL, b.p, b.n, &f, &used, &err),
	                 RP_DECODE_NEED);
	buf_add_str(&b, "xyz");
	assert_int_equal(decode(NULL, b.p, b.n, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_memory_equal(f.payload, "xyz", 3);
	json_decref(f.header);
	json_decref(h);
	free(b.p);
}

/* ------------------------------------------------- splits and truncation */

/* Three frames back to back: with, without, and with an empty payload. */
static void three_frames(buf *b, size_t ends[3])
{
	add_frame(b, "{\"cmd\":\"scene.upload\",\"id\":1}", mixed_payload,
	          sizeof mixed_payload);
	ends[0] = b->n;
	add_frame(b, "{\"cmd\":\"status\",\"id\":\"two\"}", NULL, 0);
	ends[1] = b->n;
	add_frame(b, "{\"event\":\"state\",\"job\":3}", "", 0);
	ends[2] = b->n;
}

static void test_several_frames_in_one_buffer(void **state)
{
	(void)state;
	buf b = {0};
	size_t ends[3], off = 0, used;
	rp_frame f;
	rp_error err;

	three_frames(&b, ends);
	for (int i = 0; i < 3; i++) {
		assert_int_equal(
		        decode(NULL, b.p + off, b.n - off, &f, &used, &err),
		        RP_DECODE_FRAME);
		off += used;
		assert_int_equal(off, ends[i]);
		json_decref(f.header);
	}
	assert_int_equal(decode(NULL, b.p + off, 0, &f, &used, &err),
	                 RP_DECODE_NEED);
	free(b.p);
}

/* Every prefix shorter than the first frame is NEED, never a frame. */
static void test_truncated_frames_need_more(void **state)
{
	(void)state;
	buf b = {0};
	size_t ends[3], used;
	rp_frame f;
	rp_error err;

	three_frames(&b, ends);
	for (size_t k = 0; k < ends[0]; k++) {
		rp_decode d = decode(NULL, b.p, k, &f, &used, &err);
		if (d != RP_DECODE_NEED)
			fail_msg("prefix of %zu bytes gave %d", k, d);
		assert_int_equal(used, 0);
		assert_null(f.header);
	}
	free(b.p);
}

/*
 * A stream delivered in two parts split at every byte position (and
 * byte by byte) yields the same three frames in order.
 */
static void test_decoding_split_at_every_byte(void **state)
{
	(void)state;
	buf b = {0};
	size_t ends[3];

	three_frames(&b, ends);
	for (size_t cut = 0; cut <= b.n + 1; cut++) {
		buf rx = {0};
		size_t pos = 0, got = 0, fed = 0;
		while (fed < b.n) {
			/* cut == b.n + 1: one byte at a time. */
			size_t step =
			        cut > b.n ? 1
			                  : (fed < cut ? cut - fed : b.n - fed);
			if (step == 0)
				step = b.n - fed;
			buf_add(&rx, b.p + fed, step);
			fed += step;
			for (;;) {
				rp_frame f;
				size_t used;
				rp_error err;
				rp_decode d =
				        decode(NULL, rx.p + pos, rx.n - pos, &f,
				               &used, &err);
				if (d == RP_DECODE_NEED)
					break;
				assert_int_equal(d, RP_DECODE_FRAME);
				pos += used;
				assert_true(got < 3);
				assert_int_equal(pos, ends[got]);
				got++;
				json_decref(f.header);
			}
		}
		if (got != 3)
			fail_msg("cut at %zu: %zu frames", cut, got);
		free(rx.p);
	}
	free(b.p);
}

/* ----------------------------------------------------------------- limits */

static void test_oversized_header_detected_without_newline(void **state)
{
	(void)state;
	rp_limits lim = {.max_header_bytes = 64, .max_payload_bytes = 100};
	char line[200];
	rp_frame f;
	size_t used;
	rp_error err;

	memset(line, ' ', sizeof line);
	line[0] = '{';
	/* 63 bytes, no newline: could still become a 64-byte line. */
	assert_int_equal(decode(&lim, line, 63, &f, &used, &err),
	                 RP_DECODE_NEED);
	/* 64 bytes without a newline: refused before the 65th arrives. */
	assert_int_equal(decode(&lim, line, 64, &f, &used, &err),
	                 RP_DECODE_ERROR);
	assert_int_equal(err.code, RP_ERR_TOO_LARGE);
	assert_non_null(strstr(err.msg, "64"));
	assert_int_equal(decode(&lim, line, sizeof line, &f, &used, &err),
	                 RP_DECODE_ERROR);
	/* Exactly 64 bytes including the newline is accepted. */
	line[62] = '}';
	line[63] = '\n';
	assert_int_equal(decode(&lim, line, 64, &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_int_equal(used, 64);
	json_decref(f.header);
	/* A newline past the limit does not rescue the line. */
	line[63] = ' ';
	line[100] = '\n';
	line[62] = ' ';
	line[99] = '}';
	assert_int_equal(decode(&lim, line, 101, &f, &used, &err),
	                 RP_DECODE_ERROR);
	assert_int_equal(err.code, RP_ERR_TOO_LARGE);
}

static void test_default_header_limit(void **state)
{
	(void)state;
	size_t n = RP_DEFAULT_MAX_HEADER_BYTES;
	char *big = malloc(n);
	rp_frame f;
	size_t used;
	rp_error err;

	assert_non_null(big);
	memset(big, 'x', n);
	assert_int_equal(decode(NULL, big, n - 1, &f, &used, &err),
	                 RP_DECODE_NEED);
	assert_int_equal(decode(NULL, big, n, &f, &used, &err),
	                 RP_DECODE_ERROR);
	assert_int_equal(err.code, RP_ERR_TOO_LARGE);
	free(big);
}

/* The payload size is judged from the header, before any payload byte. */
static void test_oversized_payload_refused_from_header(void **state)
{
	(void)state;
	rp_limits lim = {.max_header_bytes = 1024, .max_payload_bytes = 100};
	rp_frame f;
	size_t used;
	rp_error err;

	expect_decode_error(&lim, "{\"cmd\":\"scene.upload\",\"bytes\":101}\n",
	                    RP_ERR_TOO_LARGE, "101");
	expect_decode_error(NULL, "{\"bytes\":9223372036854775807}\n",
	                    RP_ERR_TOO_LARGE, "limit");
	const char *ok = "{\"cmd\":\"scene.upload\",\"bytes\":100}\n";
	assert_int_equal(decode(&lim, ok, strlen(ok), &f, &used, &err),
	                 RP_DECODE_NEED);
}

/* ---------------------------------------------------------------- garbage */

static void test_garbage_is_bad_frame(void **state)
{
	(void)state;
	static const struct {
		const char *text, *needle;
	} cases[] = {
	        {"not json\n", "not valid JSON"},
	        {"\n", "not valid JSON"},
	        {"{\"cmd\":\"status\"\n", "not valid JSON"},
	        {"[1,2]\n", "an array"},
	        {"\"status\"\n", "a string"},
	        {"42\n", "an integer"},
	        {"null\n", "null"},
	        {"{\"a\":1} {\"b\":2}\n", "not valid JSON"},
	        {"{\"a\":1,\"a\":2}\n", "duplicate"},
	        {"{\"s\":\"\\u0000\"}\n", "not valid JSON"},
	        {"{\"s\":\"\xff\xfe\"}\n", "not valid JSON"},
	        {"{\"bytes\":-1}\n", "negative"},
	        {"{\"bytes\":1.5}\n", "a real number"},
	        {"{\"bytes\":2.0}\n", "a real number"},
	        {"{\"bytes\":1e30}\n", "a real number"},
	        {"{\"bytes\":\"10\"}\n", "a string"},
	        {"{\"bytes\":null}\n", "null"},
	        {"{\"bytes\":true}\n", "a boolean"},
	        {"{\"bytes\":[1]}\n", "an array"},
	        {"{\"bytes\":99999999999999999999999}\n", "not valid JSON"},
	        {"{\"n\":1e999}\n", "not valid JSON"},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
		expect_decode_error(NULL, cases[i].text, RP_ERR_BAD_FRAME,
		                    cases[i].needle);
}

static void test_nul_byte_and_deep_nesting_refused(void **state)
{
	(void)state;
	static const char nul[] = "{\"a\":\"x\0y\"}\n";
	rp_frame f;
	size_t used;
	rp_error err;

	assert_int_equal(decode(NULL, nul, sizeof nul - 1, &f, &used, &err),
	                 RP_DECODE_ERROR);
	assert_int_equal(err.code, RP_ERR_BAD_FRAME);

	/* 100k nested arrays: refused by the parser's depth limit, no stack
	 * overflow. */
	size_t depth = 100000;
	char *deep = malloc(2 * depth + 8);
	assert_non_null(deep);
	size_t n = 0;
	deep[n++] = '{';
	memcpy(deep + n, "\"a\":", 4);
	n += 4;
	memset(deep + n, '[', depth);
	n += depth;
	memset(deep + n, ']', depth);
	n += depth;
	deep[n++] = '}';
	deep[n++] = '\n';
	assert_int_equal(decode(NULL, deep, n, &f, &used, &err),
	                 RP_DECODE_ERROR);
	assert_int_equal(err.code, RP_ERR_BAD_FRAME);
	free(deep);
}

static void test_crlf_line_end_accepted(void **state)
{
	(void)state;
	const char *t = "{\"cmd\":\"status\"}\r\n";
	rp_frame f;
	size_t used;
	rp_error err;

	assert_int_equal(decode(NULL, t, strlen(t), &f, &used, &err),
	                 RP_DECODE_FRAME);
	assert_int_equal(used, strlen(t));
	json_decref(f.header);
}

/* ------------------------------------------------------------------- fuzz */

static uint64_t rng_state;

static uint32_t rng(void)
{
	/* xorshift64*: deterministic, so a failure reproduces. */
	rng_state ^= rng_state >> 12;
	rng_state ^= rng_state << 25;
	rng_state ^= rng_state >> 27;
	return (uint32_t)((rng_state * 0x2545F4914F6CDD1DULL) >> 32);
}

static void mutate(buf *b)
{
	static const char specials[] = "\n{}[]\":,0123456789-.e \\\0\xff";
	int kinds = 1 + (int)(rng() % 4);

	for (int k = 0; k < kinds && b->n > 0; k++) {
		size_t at = rng() % b->n;
		switch (rng() % 6) {
		case 0: /* flip a bit */
			b->p[at] ^= (unsigned char)(1u << (rng() % 8));
			break;
		case 1: /* overwrite with a structural character */
			b->p[at] = (unsigned char)
			        specials[rng() % (sizeof specials - 1)];
			break;
		case 2: /* delete a byte */
			memmove(b->p + at, b->p + at + 1, b->n - at - 1);
			b->n--;
			break;
		case 3: { /* insert a byte */
			unsigned char c = (unsigned char)
			        specials[rng() % (sizeof specials - 1)];
			buf_add(b, "", 1);
			memmove(b->p + at + 1, b->p + at, b->n - at - 1);
			b->p[at] = c;
			break;
		}
		case 4: /* truncate */
			b->n = at;
			break;
		default: { /* duplicate a segment */
			size_t len = rng() % (b->n - at) + 1;
			unsigned char *tmp = malloc(len);
			assert_non_null(tmp);
			memcpy(tmp, b->p + at, len);
			buf_add(b, tmp, len);
			free(tmp);
			break;
		}
		}
	}
}

/*
 * Decode everything in b; check the decoder's promises on each result.
 * counts[d] is bumped for each outcome.
 */
static void decode_all(const rp_limits *lim, const buf *b, int counts[3])
{
	size_t off = 0;

	for (;;) {
		rp_frame f;
		size_t used = 12345;
		rp_error err = {0};
		rp_decode d =
		        decode(lim, b->p + off, b->n - off, &f, &used, &err);
		counts[d]++;
		if (d != RP_DECODE_FRAME) {
			assert_int_equal(used, 0);
			assert_null(f.header);
			if (d == RP_DECODE_ERROR)
				assert_true(err.code == RP_ERR_BAD_FRAME ||
				            err.code == RP_ERR_TOO_LARGE);
			return;
		}
		assert_true(used > 0 && used <= b->n - off);
		assert_true(json_is_object(f.header));
		if (f.payload)
			assert_true(f.payload >= b->p + off &&
			            f.payload + f.payload_len ==
			                    b->p + off + used);
		json_decref(f.header);
		off += used;
	}
}

static void test_mutation_fuzz_never_crashes(void **state)
{
	(void)state;
	rp_limits lim = {.max_header_bytes = 256, .max_payload_bytes = 64};
	buf seed = {0};
	size_t ends[3];

	three_frames(&seed, ends);
	add_frame(&seed,
	          "{\"cmd\":\"query.points\",\"job\":4,\"points\":[[1,2,3,0,0,"
	          "1],[0.5,-1e-3,2e2,1,0,0]],\"name\":\"\\u00e9\\n\"}",
	          NULL, 0);
	int counts[3] = {0, 0, 0};
	rng_state = 0x9E3779B97F4A7C15ULL;
	for (int i = 0; i < 5000; i++) {
		buf b = {0};
		buf_add(&b, seed.p, seed.n);
		mutate(&b);
		decode_all(i % 2 ? &lim : NULL, &b, counts);
		free(b.p);
	}
	free(seed.p);
	/* The mutations reach every outcome, often. */
	printf("fuzz: %d need, %d frames, %d errors\n", counts[0], counts[1],
	       counts[2]);
	assert_true(counts[RP_DECODE_NEED] > 500);
	assert_true(counts[RP_DECODE_FRAME] > 5000);
	assert_true(counts[RP_DECODE_ERROR] > 1000);
}

/* --------------------------------------------------- tables and messages */

static void test_error_and_command_tables(void **state)
{
	(void)state;
	for (int i = 0; i < RP_ERR_COUNT; i++)
		assert_int_equal(rp_err_parse(rp_err_name((rp_err)i)), i);
	assert_int_equal(rp_err_parse("no_such_code"), RP_ERR_INTERNAL);
	assert_int_equal(rp_err_parse(NULL), RP_ERR_INTERNAL);
	assert_true(rp_err_closes(RP_ERR_TOO_LARGE));
	assert_false(rp_err_closes(RP_ERR_NOT_FOUND));
	for (int i = 0; i < RP_CMD_COUNT; i++) {
		assert_int_equal(rp_cmd_lookup(rp_cmd_name((rp_cmd)i)), i);
		assert_non_null(rp_cmd_help((rp_cmd)i));
	}
	assert_int_equal(rp_cmd_lookup("job.explode"), -1);
	assert_int_equal(rp_cmd_lookup(NULL), -1);
	assert_true(rp_cmd_takes_payload(RP_CMD_SCENE_UPLOAD));
	assert_false(rp_cmd_takes_payload(RP_CMD_STATUS));
	assert_null(rp_cmd_name(RP_CMD_COUNT));
}

static void test_replies(void **state)
{
	(void)state;
	json_t *id = json_string("req-1");
	json_t *r = rp_reply_ok(id);
	rp_error err;

	assert_true(json_equal(json_object_get(r, "id"), id));
	assert_int_equal(rp_reply_status(r, &err), RP_ERR_OK);
	json_decref(r);

	r = rp_reply_error(id, RP_ERR_NOT_FOUND, "no job %d", 42);
	assert_int_equal(rp_reply_status(r, &err), RP_ERR_NOT_FOUND);
	assert_string_equal(err.msg, "no job 42");
	assert_string_equal(json_string_value(json_object_get(
	                            json_object_get(r, "error"), "code")),
	                    "not_found");
	json_decref(r);

	/* A message cut inside a multi-byte character is still sent. */
	char longmsg[600];
	memset(longmsg, 'a', sizeof longmsg);
	memcpy(longmsg + 510, "\xc3\xa9\xc3\xa9", 4);
	longmsg[599] = '\0';
	r = rp_reply_error(NULL, RP_ERR_INVALID, "%s", longmsg + 1);
	assert_non_null(r);
	assert_null(json_object_get(r, "id"));
	json_decref(r);

	r = rp_request(RP_CMD_JOB_RUN, 5);
	assert_string_equal(json_string_value(json_object_get(r, "cmd")),
	                    "job.run");
	assert_int_equal(json_integer_value(json_object_get(r, "id")), 5);
	json_decref(r);
	r = rp_request(RP_CMD_STATUS, -1);
	assert_null(json_object_get(r, "id"));
	json_decref(r);
	json_decref(id);

	static const struct {
		const char *json;
		rp_err want;
	} cases[] = {
	        {"{\"ok\":false,\"error\":{\"code\":\"busy\",\"message\":"
	         "\"m\"}}",
	         RP_ERR_BUSY},
	        {"{\"ok\":false,\"error\":{\"code\":\"whatever\"}}",
	         RP_ERR_INTERNAL},
	        {"{\"ok\":false,\"error\":{\"code\":\"ok\"}}",
	         RP_ERR_BAD_FRAME},
	        {"{\"ok\":false}", RP_ERR_BAD_FRAME},
	        {"{\"ok\":1}", RP_ERR_BAD_FRAME},
	        {"{\"event\":\"state\"}", RP_ERR_BAD_FRAME},
	        {"[true]", RP_ERR_BAD_FRAME},
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		json_error_t jerr;
		json_t *v = json_loads(cases[i].json, JSON_DECODE_ANY, &jerr);
		assert_int_equal(rp_reply_status(v, &err), cases[i].want);
		json_decref(v);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_roundtrip_without_payload),
	        cmocka_unit_test(test_roundtrip_payload_with_newlines_and_nuls),
	        cmocka_unit_test(test_roundtrip_empty_payload),
	        cmocka_unit_test(test_encode_drops_stale_bytes_member),
	        cmocka_unit_test(test_encode_header_only),
	        cmocka_unit_test(test_several_frames_in_one_buffer),
	        cmocka_unit_test(test_truncated_frames_need_more),
	        cmocka_unit_test(test_decoding_split_at_every_byte),
	        cmocka_unit_test(
	                test_oversized_header_detected_without_newline),
	        cmocka_unit_test(test_default_header_limit),
	        cmocka_unit_test(test_oversized_payload_refused_from_header),
	        cmocka_unit_test(test_garbage_is_bad_frame),
	        cmocka_unit_test(test_nul_byte_and_deep_nesting_refused),
	        cmocka_unit_test(test_crlf_line_end_accepted),
	        cmocka_unit_test(test_mutation_fuzz_never_crashes),
	        cmocka_unit_test(test_error_and_command_tables),
	        cmocka_unit_test(test_replies),
	};
	if (getenv("LUXRAD_TEST_FILTER"))
		cmocka_set_test_filter(getenv("LUXRAD_TEST_FILTER"));
	return cmocka_run_group_tests(tests, NULL, NULL);
}
