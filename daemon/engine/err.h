/*
 * err.h -- filling a rad_error.  Every engine module reports failures
 * through rad_fail(), which formats the message into the caller's
 * rad_error (if any) and returns the code, so a failure path reads
 *     return rad_fail(err, RAD_ERR_INVALID, "node %u: ...", id);
 */
#ifndef LUXRAD_ERR_H
#define LUXRAD_ERR_H

#include "rad.h"

rad_status rad_fail(rad_error *err, rad_status code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));

/* Mark err as success (code RAD_OK, empty message). */
void rad_error_clear(rad_error *err);

#endif
