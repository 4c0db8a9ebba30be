/*
 * rp_frame.c -- the frame codec: one JSON header line, then "bytes" raw
 * payload bytes.
 *
 * DESIGN
 * The decoder is a pure function over the caller's receive buffer: it
 * never allocates the payload nor copies it, and it keeps no state between
 * calls (a partial frame is simply decoded again when more bytes have
 * arrived).  That makes it trivially safe to fuzz and to split at any
 * byte.  The cost of re-scanning is one memchr over the header line and a
 * re-parse of that line while a payload is arriving; headers are small
 * (an upload's is ~40 bytes), so this is noise next to the socket reads.
 *
 * Limits are enforced before anything grows: a header line is refused as
 * soon as max_header_bytes bytes are buffered without a newline (the
 * limit counts the newline), and a payload is refused from its announced
 * size, before any payload byte is read.  After an error the stream is
 * out of step for good, which is why both errors close the connection.
 */
#include "rp_int.h"

#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* json_int_t is long long in Debian's jansson (JSON_INTEGER_IS_LONG_LONG). */
#define PAYLOAD_MAX ((size_t)LLONG_MAX)

/*
 * Parse the header line (without its newline) and read its "bytes".
 * Returns the header (new reference) and sets *has_payload / *n, or NULL
 * with err filled.
 */
static json_t *parse_header(const rp_limits *lim, const unsigned char *line,
                            size_t line_len, int *has_payload, size_t *n,
                            rp_error *err)
{
	json_error_t jerr;
	json_t *h, *b;
	json_int_t v;

	h = json_loadb((const char *)line, line_len,
	               JSON_DECODE_ANY | JSON_REJECT_DUPLICATES, &jerr);
	if (!h) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "header is not valid JSON: %s (at byte %d)", jerr.text,
		        jerr.position);
		return NULL;
	}
	if (!json_is_object(h)) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "header is %s, expected a JSON object",
		        rp_json_kind(h));
		json_decref(h);
		return NULL;
	}
	*has_payload = 0;
	*n = 0;
	b = json_object_get(h, "bytes");
	if (!b)
		return h;
	if (!json_is_integer(b) || (v = json_integer_value(b)) < 0) {
		rp_fail(err, RP_ERR_BAD_FRAME,
		        "header member \"bytes\" must be a non-negative "
		        "integer, got %s",
		        json_is_integer(b) ? "a negative integer"
		                           : rp_json_kind(b));
		json_decref(h);
		return NULL;
	}
	if ((unsigned long long)v > lim->max_payload_bytes) {
		rp_fail(err, RP_ERR_TOO_LARGE,
		        "payload of %lld bytes exceeds the limit of %zu bytes",
		        (long long)v, lim->max_payload_bytes);
		json_decref(h);
		return NULL;
	}
	*has_payload = 1;
	*n = (size_t)v;
	return h;
}

rp_decode rp_frame_decode(const rp_limits *lim, const unsigned char *buf,
                          size_t len, rp_frame *out, size_t *used,
                          rp_error *err)
{
	rp_limits def;
	const unsigned char *nl;
	size_t scan, line_len, n;
	int has_payload;
	json_t *h;

	if (!lim) {
		rp_limits_default(&def);
		lim = &def;
	}
	out->header = NULL;
	out->payload = NULL;
	out->payload_len = 0;
	*used = 0;
	scan = len < lim->max_header_bytes ? len : lim->max_header_bytes;
	nl = scan ? memchr(buf, '\n', scan) : NULL;
	if (!nl) {
		if (len >= lim->max_header_bytes) {
			rp_fail(err, RP_ERR_TOO_LARGE,
			        "header line longer than the limit of %zu "
			        "bytes (no newline found)",
			        lim->max_header_bytes);
			return RP_DECODE_ERROR;
		}
		return RP_DECODE_NEED;
	}
	line_len = (size_t)(nl - buf);
	h = parse_header(lim, buf, line_len, &has_payload, &n, err);
	if (!h)
		return RP_DECODE_ERROR;
	if (len - (line_len + 1) < n) {
		json_decref(h);
		return RP_DECODE_NEED;
	}
	out->header = h;
	if (has_payload) {
		out->payload = buf + line_len + 1;
		out->payload_len = n;
	}
	*used = line_len + 1 + n;
	return RP_DECODE_FRAME;
}

/*
 * Serialise the header as one compact line ending in "\n", leaving extra
 * bytes of room after it.  Returns the malloc'ed buffer, or NULL.
 */
static unsigned char *dump_line(json_t *header, size_t extra, size_t *line_len)
{
	char *text = json_dumps(header, JSON_COMPACT);
	unsigned char *out;
	size_t n;

	if (!text)
		return NULL;
	n = strlen(text);
	if (extra > SIZE_MAX - n - 1 || !(out = malloc(n + 1 + extra))) {
		free(text);
		return NULL;
	}
	memcpy(out, text, n);
	out[n] = '\n';
	free(text);
	*line_len = n + 1;
	return out;
}

int rp_frame_encode(json_t *header, const void *payload, size_t payload_len,
                    unsigned char **out, size_t *out_len)
{
	unsigned char *buf;
	size_t line_len;
	int has_payload = payload != NULL || payload_len > 0;

	*out = NULL;
	*out_len = 0;
	if (!json_is_object(header) || (payload_len > 0 && !payload))
		return -1;
	if (has_payload) {
		if (payload_len > PAYLOAD_MAX ||
		    json_object_set_new(header, "bytes",
		                        json_integer((json_int_t)payload_len)))
			return -1;
	} else {
		/* A stale "bytes" would make the peer wait for a payload. */
		json_object_del(header, "bytes");
	}
	buf = dump_line(header, payload_len, &line_len);
	if (!buf)
		return -1;
	if (payload_len)
		memcpy(buf + line_len, payload, payload_len);
	*out = buf;
	*out_len = line_len + payload_len;
	return 0;
}

int rp_frame_encode_header(json_t *header, size_t payload_len,
                           unsigned char **out, size_t *out_len)
{
	*out = NULL;
	*out_len = 0;
	if (!json_is_object(header) || payload_len > PAYLOAD_MAX ||
	    json_object_set_new(header, "bytes",
	                        json_integer((json_int_t)payload_len)))
		return -1;
	*out = dump_line(header, 0, out_len);
	return *out ? 0 : -1;
}
