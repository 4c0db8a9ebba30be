/*
 * error.c -- status names and rad_error formatting.
 */
#include <stdarg.h>
#include <stdio.h>

#include "rad.h"

static const char *const status_names[] = {
        [RAD_OK] = "ok",
        [RAD_ERR_NOMEM] = "nomem",
        [RAD_ERR_INVALID] = "invalid",
        [RAD_ERR_UNSUPPORTED] = "unsupported",
        [RAD_ERR_STATE] = "state",
        [RAD_ERR_EMBREE] = "embree",
        [RAD_ERR_CANCELLED] = "cancelled",
        [RAD_ERR_LIMIT] = "limit",
        [RAD_ERR_IO] = "io",
};

const char *rad_status_name(rad_status st)
{
	if ((unsigned)st < sizeof(status_names) / sizeof(status_names[0]) &&
	    status_names[st])
		return status_names[st];
	return "unknown";
}

rad_status rad_fail(rad_error *err, rad_status code, const char *fmt, ...)
{
	if (err) {
		va_list ap;
		err->code = code;
		va_start(ap, fmt);
		vsnprintf(err->msg, sizeof(err->msg), fmt, ap);
		va_end(ap);
	}
	return code;
}

void rad_error_clear(rad_error *err)
{
	if (err) {
		err->code = RAD_OK;
		err->msg[0] = '\0';
	}
}
