/*
 * log.c -- the daemon's log lines on stderr.
 *
 * Format: "2024-05-01T12:00:00.123Z INFO message".  Each line is formatted
 * into a stack buffer and written with one write(2) call (atomic for a
 * pipe up to PIPE_BUF bytes, and never interleaved within a line for the
 * sizes we write), so no lock is needed and a log call never blocks on
 * another thread.  Long messages are truncated with "...".
 */
#include "log.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

static atomic_int log_level = SRV_LOG_INFO;

static const char *const level_names[] = {
        [SRV_LOG_ERROR] = "ERROR",
        [SRV_LOG_WARN] = "WARN",
        [SRV_LOG_INFO] = "INFO",
        [SRV_LOG_DEBUG] = "DEBUG",
};

void srv_log_set_level(srv_log_level level)
{
	atomic_store(&log_level, (int)level);
}

srv_log_level srv_log_get_level(void)
{
	return (srv_log_level)atomic_load(&log_level);
}

int srv_log_enabled(srv_log_level level)
{
	return (int)level <= atomic_load(&log_level);
}

void srv_log(srv_log_level level, const char *fmt, ...)
{
	char line[1024];
	struct timespec ts;
	struct tm tm;
	size_t n;
	va_list ap;

	if (!srv_log_enabled(level))
		return;
	clock_gettime(CLOCK_REALTIME, &ts);
	gmtime_r(&ts.tv_sec, &tm);
	n = strftime(line, sizeof(line), "%Y-%m-%dT%H:%M:%S", &tm);
	n += (size_t)snprintf(
	        line + n, sizeof(line) - n, ".%03ldZ %s ",
	        ts.tv_nsec / 1000000L,
	        level_names[(unsigned)level <= SRV_LOG_DEBUG ? level
	                                                     : SRV_LOG_DEBUG]);
	va_start(ap, fmt);
	int k = vsnprintf(line + n, sizeof(line) - n - 1, fmt, ap);
	va_end(ap);
	if (k < 0)
		k = 0;
	if ((size_t)k >= sizeof(line) - n - 1) {
		n = sizeof(line) - 5;
		memcpy(line + n, "...", 3);
		n += 3;
	} else {
		n += (size_t)k;
	}
	line[n++] = '\n';
	const char *p = line;
	while (n > 0) {
		ssize_t w = write(STDERR_FILENO, p, n);
		if (w <= 0)
			break;
		p += w;
		n -= (size_t)w;
	}
}

double srv_now_unix(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_REALTIME, &ts);
	return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
