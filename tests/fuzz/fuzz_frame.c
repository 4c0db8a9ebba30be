/*
 * fuzz_frame.c -- the frame decoder (rp_frame_decode) on a connection's
 * bytes.
 *
 * The input is what a peer sent on one connection.  It is consumed as
 * daemon/server/cmd/conn.c consumes its input buffer: frames decoded one
 * after the other from the unread part until the decoder needs more bytes
 * or refuses the stream, with no payload allowed before a hello that
 * opens the session, and a frame's command looked up and checked as
 * dispatch.c does before a handler would run.  The same bytes are then
 * consumed again with the default limits and no session rule, and with
 * small limits (a 64-byte header, a 16-byte payload), so that the limit
 * checks meet frames on both sides of them.
 *
 * Checked on every frame, besides memory safety:
 *  - the decoder's result agrees with the bytes: a frame ends at the
 *    first newline plus its "bytes", within the limits; "need more" and
 *    an error leave nothing behind; an error is one that closes;
 *  - every shorter prefix of a frame decodes as "need more";
 *  - re-encoding the header and payload (rp_frame_encode) and decoding
 *    that gives the same header and payload, and rp_frame_encode_header
 *    writes the same header line;
 *  - an error reply the daemon would send (a refused stream, an unknown
 *    command, a refused hello) reads back with rp_reply_status as the
 *    same code, a message that begins as the one sent, and the same id.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz.h"
#include "rp.h"

typedef struct stream_rules {
	size_t max_header, max_payload;
	int hello_first; /* no payload, and hello first, as a fresh session */
} stream_rules;

/* Decode one encoded frame that must be whole; returns its header. */
static json_t *decode_whole(const unsigned char *buf, size_t len, rp_frame *f)
{
	size_t used = 0;
	rp_error err = {0};
	FUZZ_CHECK(rp_frame_decode(NULL, buf, len, f, &used, &err) ==
	                   RP_DECODE_FRAME,
	           "an encoded frame decodes");
	FUZZ_CHECK(used == len, "an encoded frame is used whole");
	return f->header;
}

/* The error reply the daemon sends, read back as a client reads it. */
static void check_error_reply(json_t *id, rp_err code, const char *msg)
{
	json_t *reply = rp_reply_error(id, code, "%s", msg);
	unsigned char *buf;
	size_t len;
	rp_frame f;
	rp_error back = {0};

	FUZZ_CHECK(reply != NULL, "rp_reply_error builds a reply");
	FUZZ_CHECK(rp_frame_encode(reply, NULL, 0, &buf, &len) == 0,
	           "an error reply encodes");
	json_decref(reply);
	decode_whole(buf, len, &f);
	FUZZ_CHECK(rp_reply_status(f.header, &back) == code,
	           "an error reply reads back as its code");
	FUZZ_CHECK(back.code == code, "rp_reply_status fills the code");
	FUZZ_CHECK(strncmp(back.msg, msg, strlen(back.msg)) == 0 ||
	                   strcmp(back.msg, "(message not valid UTF-8)") == 0,
	           "an error reply's message begins as the one sent");
	FUZZ_CHECK(id ? json_equal(json_object_get(f.header, "id"), id)
	              : json_object_get(f.header, "id") == NULL,
	           "an error reply carries the request's id");
	json_decref(f.header);
	free(buf);
}

/* What the decoder said about buf[0..len), checked against the bytes. */
static void check_result(const rp_limits *lim, const unsigned char *buf,
                         size_t len, rp_decode rc, const rp_frame *f,
                         size_t used, const rp_error *err)
{
	if (rc != RP_DECODE_FRAME) {
		FUZZ_CHECK(rc == RP_DECODE_NEED || rc == RP_DECODE_ERROR,
		           "the decoder returns need, frame or error");
		FUZZ_CHECK(used == 0 && !f->header && !f->payload &&
		                   f->payload_len == 0,
		           "need and error leave no frame");
		if (rc == RP_DECODE_ERROR)
			FUZZ_CHECK((err->code == RP_ERR_BAD_FRAME ||
			            err->code == RP_ERR_TOO_LARGE) &&
			                   rp_err_closes(err->code) &&
			                   err->msg[0],
			           "a decode error is bad_frame or too_large, "
			           "closes, and says why");
		return;
	}
	const unsigned char *nl = memchr(buf, '\n', len);
	FUZZ_CHECK(nl != NULL, "a frame has a newline");
	size_t line = (size_t)(nl - buf);
	FUZZ_CHECK(line < lim->max_header_bytes,
	           "a frame's header line is within the limit");
	FUZZ_CHECK(json_is_object(f->header), "a frame's header is an object");
	json_t *b = json_object_get(f->header, "bytes");
	if (b) {
		FUZZ_CHECK(json_is_integer(b) && json_integer_value(b) >= 0 &&
		                   (size_t)json_integer_value(b) ==
		                           f->payload_len,
		           "the payload is as long as \"bytes\" says");
		FUZZ_CHECK(f->payload == buf + line + 1,
		           "the payload follows the header line");
		FUZZ_CHECK(f->payload_len <= lim->max_payload_bytes,
		           "the payload is within the limit");
	} else {
		FUZZ_CHECK(!f->payload && f->payload_len == 0,
		           "no \"bytes\", no payload");
	}
	FUZZ_CHECK(used == line + 1 + f->payload_len && used <= len,
	           "a frame uses its header line and payload");
}

/* Decode buf[0..len) and check the result; returns rc. */
static rp_decode decode(const rp_limits *lim, const unsigned char *buf,
                        size_t len, rp_frame *f, size_t *used, rp_error *err)
{
	*used = 7; /* the decoder must set it */
	rp_decode rc = rp_frame_decode(lim, buf, len, f, used, err);
	check_result(lim, buf, len, rc, f, *used, err);
	return rc;
}

/* Every prefix of a frame is "need more"; the frame alone decodes the
 * same.  The prefixes tried: none of the newline, the header line
 * without its payload's last byte, and one byte short. */
static void check_prefixes(const rp_limits *lim, const unsigned char *buf,
                           size_t used)
{
	size_t line =
	        (size_t)((const unsigned char *)memchr(buf, '\n', used) - buf);
	size_t cut[3] = {line, used - 1, line + 1};
	rp_frame f;
	rp_error err = {0};
	size_t u;

	for (int i = 0; i < 3; i++) {
		if (cut[i] >= used)
			continue;
		FUZZ_CHECK(decode(lim, buf, cut[i], &f, &u, &err) ==
		                   RP_DECODE_NEED,
		           "a prefix of a frame needs more");
	}
	FUZZ_CHECK(decode(lim, buf, used, &f, &u, &err) == RP_DECODE_FRAME &&
	                   u == used,
	           "a frame alone decodes as a frame");
	json_decref(f.header);
}

/* Encode the frame again and decode that: the same header and payload. */
static void check_round_trip(const rp_frame *f)
{
	json_t *copy = json_deep_copy(f->header);
	unsigned char *buf, *line;
	size_t len, line_len;
	rp_frame back;

	FUZZ_CHECK(copy != NULL, "a header can be copied");
	FUZZ_CHECK(rp_frame_encode(copy, f->payload, f->payload_len, &buf,
	                           &len) == 0,
	           "a decoded frame encodes");
	decode_whole(buf, len, &back);
	FUZZ_CHECK(json_equal(back.header, f->header),
	           "a re-encoded header decodes the same");
	FUZZ_CHECK(back.payload_len == f->payload_len &&
	                   !back.payload == !f->payload &&
	                   (!f->payload_len ||
	                    !memcmp(back.payload, f->payload, f->payload_len)),
	           "a re-encoded payload decodes the same");
	if (f->payload) {
		FUZZ_CHECK(rp_frame_encode_header(copy, f->payload_len, &line,
		                                  &line_len) == 0,
		           "a header line encodes alone");
		FUZZ_CHECK(line_len + f->payload_len == len &&
		                   !memcmp(line, buf, line_len),
		           "the header line alone is the frame's header line");
		free(line);
	}
	json_decref(back.header);
	json_decref(copy);
	free(buf);
}

/* A reply, as a client reads one: a code, and an error's name back. */
static void check_reply_status(const json_t *h)
{
	rp_error err = {0};
	rp_err c = rp_reply_status(h, &err);

	FUZZ_CHECK((unsigned)c < RP_ERR_COUNT && err.code == c,
	           "a reply's status is a known code");
	FUZZ_CHECK(rp_err_parse(rp_err_name(c)) == c,
	           "an error code's name parses back");
}

/*
 * What conn.c and dispatch.c decide before a handler runs, in their
 * order, and the session's hello.  Returns 1 when the daemon would close
 * the connection or stop reading.
 */
static int dispatch(const rp_frame *f, int *authed)
{
	json_t *h = f->header, *id = json_object_get(h, "id");
	const char *name = json_string_value(json_object_get(h, "cmd"));
	int k = rp_cmd_lookup(name);
	rp_error err = {0};
	uint64_t version = 0;
	char msg[512];

	/* Before the session opens, any line but a hello is refused. */
	if (!*authed && (!name || strcmp(name, "hello") != 0))
		return 1;
	if (id && !json_is_string(id) && !json_is_number(id) &&
	    !json_is_boolean(id) && !json_is_null(id))
		return 0; /* bad_request: the frame is skipped */
	if (k < 0) {
		if (name) {
			snprintf(msg, sizeof msg, "unknown command \"%.64s\"",
			         name);
			check_error_reply(id, RP_ERR_UNKNOWN_COMMAND, msg);
		}
		return 0;
	}
	FUZZ_CHECK(strcmp(rp_cmd_name((rp_cmd)k), name) == 0 &&
	                   rp_cmd_help((rp_cmd)k) != NULL,
	           "a command looked up has that name and a summary");
	if (f->payload && !rp_cmd_takes_payload((rp_cmd)k))
		return 0; /* bad_request */
	if (k == RP_CMD_SHUTDOWN)
		return 1;
	if (k != RP_CMD_HELLO || *authed)
		return 0;
	if (rp_arg_u64(h, "version", 1, &version, &err) != 0) {
		check_error_reply(id, err.code, err.msg);
		return 0; /* bad_request does not close */
	}
	if (version != RP_VERSION)
		return 1;
	*authed = 1;
	return 0;
}

/* Consume the whole input as one connection under the given rules. */
static void consume(const unsigned char *buf, size_t len, const stream_rules *r)
{
	int authed = !r->hello_first;
	size_t off = 0;

	while (off < len) {
		rp_limits lim = {r->max_header, authed ? r->max_payload : 0};
		rp_frame f;
		rp_error err = {0};
		size_t used;
		rp_decode rc =
		        decode(&lim, buf + off, len - off, &f, &used, &err);
		if (rc == RP_DECODE_NEED)
			break; /* the peer would send more */
		if (rc == RP_DECODE_ERROR) {
			check_error_reply(NULL, err.code, err.msg);
			break; /* the connection closes */
		}
		check_prefixes(&lim, buf + off, used);
		check_round_trip(&f);
		check_reply_status(f.header);
		int stop = r->hello_first && dispatch(&f, &authed);
		json_decref(f.header);
		if (stop)
			break;
		off += used;
	}
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	static const stream_rules rules[] = {
	        {RP_DEFAULT_MAX_HEADER_BYTES, RP_DEFAULT_MAX_PAYLOAD_BYTES, 1},
	        {RP_DEFAULT_MAX_HEADER_BYTES, RP_DEFAULT_MAX_PAYLOAD_BYTES, 0},
	        {64, 16, 0},
	};

	for (size_t i = 0; i < sizeof rules / sizeof rules[0]; i++)
		consume(data, size, &rules[i]);
	return 0;
}
