/*
 * log.h -- luxradd's log: one line per message on stderr, with a UTC
 * timestamp and the level, written with a single write(2) so that lines
 * from different threads never interleave.  The level is a global that
 * SIGHUP may change while other threads log (an atomic int).
 */
#ifndef LUXRAD_SRV_LOG_H
#define LUXRAD_SRV_LOG_H

#include "config.h"

void srv_log_set_level(srv_log_level level);
srv_log_level srv_log_get_level(void);
/* 1 if a message at this level would be written. */
int srv_log_enabled(srv_log_level level);

void srv_log(srv_log_level level, const char *fmt, ...)
        __attribute__((format(printf, 2, 3)));

#define srv_error(...) srv_log(SRV_LOG_ERROR, __VA_ARGS__)
#define srv_warn(...) srv_log(SRV_LOG_WARN, __VA_ARGS__)
#define srv_info(...) srv_log(SRV_LOG_INFO, __VA_ARGS__)
#define srv_debug(...) srv_log(SRV_LOG_DEBUG, __VA_ARGS__)

/* The wall clock in Unix seconds (the one log lines are stamped with). */
double srv_now_unix(void);

#endif
