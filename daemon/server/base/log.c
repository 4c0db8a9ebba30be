/*
 * log.c -- the daemon's log lines on stderr.
 *
 * Format: "2024-05-01T12:00:00.123Z INFO message".  Each line is formatted
 * into a stack buffer and written with one write(2) call (atomic for a
 * pipe up to PIPE_BUF bytes, and never interleaved within a line for the
 * sizes we write), so no lock is needed and a log call never blocks on
 * another thread.  Long messages are truncated with "...".
 *
 * A message carries what clients chose: scene and job names, sensor names,
 * paths and error texts from their files.  It is escaped before it is
 * written (log_escape), so that a name cannot end the line and forge the
 * next one ("x\n2026-01-01T00:00:00.000Z ERROR ..."), drive the terminal
 * a log is read on (ESC sequences, C1 controls), or reorder what is shown
 * (bidirectional overrides).  Valid UTF-8 text passes unchanged, but for
 * a backslash, written twice so that an escape cannot be forged either.
 */
#include "log.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
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

/* Length of the UTF-8 sequence starting at p (n bytes left), or 0 when
 * it is not valid (overlong, surrogate, beyond U+10FFFF, cut short). */
static size_t utf8_len(const unsigned char *p, size_t n, uint32_t *cp)
{
	size_t len;
	uint32_t c, min;
	if (p[0] >= 0xc2 && p[0] <= 0xdf) {
		len = 2, c = p[0] & 0x1f, min = 0x80;
	} else if (p[0] >= 0xe0 && p[0] <= 0xef) {
		len = 3, c = p[0] & 0x0f, min = 0x800;
	} else if (p[0] >= 0xf0 && p[0] <= 0xf4) {
		len = 4, c = p[0] & 0x07, min = 0x10000;
	} else {
		return 0;
	}
	if (len > n)
		return 0;
	for (size_t k = 1; k < len; k++) {
		if ((p[k] & 0xc0) != 0x80)
			return 0;
		c = (c << 6) | (p[k] & 0x3f);
	}
	if (c < min || c > 0x10ffff || (c >= 0xd800 && c <= 0xdfff))
		return 0;
	*cp = c;
	return len;
}

/* Code points written as \uXXXX: C1 controls, the line and paragraph
 * separators, and the bidirectional embeddings, overrides and isolates. */
static int hidden_cp(uint32_t c)
{
	return (c >= 0x80 && c <= 0x9f) || c == 0x2028 || c == 0x2029 ||
	       (c >= 0x202a && c <= 0x202e) || (c >= 0x2066 && c <= 0x2069);
}

/*
 * Copy in[0..n) to out (cap bytes, cap >= 4), escaped: a backslash as
 * "\\", a control byte (below 0x20, 0x7f) and a byte that is not valid
 * UTF-8 as "\xNN", a hidden code point (hidden_cp) as "\uXXXX".  Stops
 * before the piece that would not fit and ends with "..." then.  Returns
 * the bytes written (no terminating NUL).
 */
static size_t log_escape(const char *in, size_t n, char *out, size_t cap)
{
	const unsigned char *p = (const unsigned char *)in;
	size_t o = 0, i = 0;
	while (i < n) {
		char piece[8];
		size_t len = 1, plen;
		uint32_t cp = 0;
		if (p[i] == '\\') {
			plen = 2;
			memcpy(piece, "\\\\", 2);
		} else if (p[i] < 0x20 || p[i] == 0x7f) {
			plen = (size_t)snprintf(piece, sizeof(piece), "\\x%02x",
			                        p[i]);
		} else if (p[i] < 0x80) {
			plen = 1;
			piece[0] = (char)p[i];
		} else if ((len = utf8_len(p + i, n - i, &cp)) == 0) {
			len = 1;
			plen = (size_t)snprintf(piece, sizeof(piece), "\\x%02x",
			                        p[i]);
		} else if (hidden_cp(cp)) {
			plen = (size_t)snprintf(piece, sizeof(piece), "\\u%04x",
			                        (unsigned)cp);
		} else {
			plen = len;
			memcpy(piece, p + i, len);
		}
		if (o + plen > cap - 3) {
			memcpy(out + o, "...", 3);
			return o + 3;
		}
		memcpy(out + o, piece, plen);
		o += plen;
		i += len;
	}
	return o;
}

void srv_log(srv_log_level level, const char *fmt, ...)
{
	char msg[1024], line[1100];
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
	int k = vsnprintf(msg, sizeof(msg), fmt, ap);
	va_end(ap);
	size_t m = k < 0 ? 0 : (size_t)k;
	if (m >= sizeof(msg)) {
		m = sizeof(msg) - 4;
		memcpy(msg + m, "...", 3);
		m += 3;
	}
	n += log_escape(msg, m, line + n, sizeof(line) - n - 1);
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
