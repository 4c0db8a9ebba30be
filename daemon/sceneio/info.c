/*
 * info.c -- the load report (sio_info): notes appended as a scene is read,
 * by the parser's shim and the importer alike, "; " between them and cut
 * at the report's size; and errors prefixed with the object they are
 * about.
 *
 * The report is UTF-8 (it goes into JSON replies, which jansson refuses
 * otherwise): the names a note quotes come from the document, valid UTF-8,
 * but a cut -- a note's "%.60s", the report's size -- can split a
 * character, and its remains are dropped.
 */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "internal.h"

/* Drop from s what a cut left of a character: a lead byte without all the
 * continuation bytes it announces, and those it has. */
static void drop_split_chars(char *s)
{
	unsigned char *r = (unsigned char *)s, *w = r;

	while (*r) {
		/* The bytes the character at r takes: 1 for ASCII (and a
		 * stray continuation byte, dropped below). */
		size_t want = *r < 0xc0 ? 1 : *r < 0xe0 ? 2 : *r < 0xf0 ? 3 : 4;
		size_t k = 1;
		while (k < want && (r[k] & 0xc0) == 0x80)
			k++;
		if (k == want && (want > 1 || (*r & 0xc0) != 0x80)) {
			memmove(w, r, k);
			w += k;
		}
		r += k;
	}
	*w = '\0';
}

void sio_note(sio_info *info, const char *fmt, ...)
{
	if (!info)
		return;
	size_t used = strlen(info->warnings);
	size_t cap = sizeof(info->warnings);
	if (used + 3 >= cap)
		return; /* full: no room for "; " and a character */
	if (used) {
		memcpy(info->warnings + used, "; ", 3);
		used += 2;
	}
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(info->warnings + used, cap - used, fmt, ap);
	va_end(ap);
	drop_split_chars(info->warnings + used);
}

rad_status sio_blame(rad_error *err, rad_status st, const char *label)
{
	if (st != RAD_OK && err) {
		char msg[sizeof err->msg];
		memcpy(msg, err->msg, sizeof msg);
		rad_fail(err, st, "%s: %s", label, msg);
	}
	return st;
}
