/*
 * textutil.h -- small text helpers shared by the daemon's parsers and
 * stores (base/config.c, mb_config.c, store/).  In luxrad_modbus, the lowest
 * of the daemon's libraries, so that every one of them can use it.
 */
#ifndef LUXRAD_TEXTUTIL_H
#define LUXRAD_TEXTUTIL_H

#include <stddef.h>

/* Format into msg[len] (nothing when msg is NULL or len 0); returns -1,
 * so that "return srv_fail(...);" reports a failure. */
int srv_fail(char *msg, size_t len, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));

/*
 * A duration in seconds: a number, optionally followed (blanks allowed)
 * by s, ms, m, min or h: "30", "30s", "250 ms", "1.5m", "1h".  0, or -1
 * when malformed (out untouched).
 */
int srv_parse_seconds(const char *v, double *out);

#endif
