/*
 * rp_int.h -- helpers shared by the protocol library's files; not part of
 * its interface (rp.h).
 */
#ifndef LUXRAD_RP_INT_H
#define LUXRAD_RP_INT_H

#include "rp.h"

/* Fill err (when not NULL) with code and a formatted message. */
void rp_fail(rp_error *err, rp_err code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));

/* "an object", "an array", "a string"...: a JSON value's type, for
 * messages that say what was found instead of what was expected. */
const char *rp_json_kind(const json_t *v);

#endif
