/*
 * info.c -- the load report (sio_info): notes appended as a scene is read,
 * by the parser's shim and the importer alike, "; " between them and cut
 * at the report's size; and errors prefixed with the object they are
 * about.
 */
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "internal.h"

void sio_note(sio_info *info, const char *fmt, ...)
{
	if (!info)
		return;
	size_t used = strlen(info->warnings);
	size_t cap = sizeof(info->warnings);
	if (used && used + 2 < cap) {
		memcpy(info->warnings + used, "; ", 3);
		used += 2;
	}
	if (used + 1 >= cap)
		return;
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(info->warnings + used, cap - used, fmt, ap);
	va_end(ap);
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
