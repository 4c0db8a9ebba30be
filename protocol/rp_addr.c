/*
 * rp_addr.c -- the one parser of daemon addresses: the client's --connect
 * and $LUXRAD_CONNECT (rp_addr_parse), and the daemon's TCP listeners,
 * listen_tcp, metrics_listen and modbus_listen (rp_addr_parse_listen).
 * One grammar and one set of messages, so that a mistake reads the same
 * wherever it is made.
 *
 * Accepted forms (no DNS, no sockets: pure text):
 *   unix:PATH         a Unix socket (any non-empty path)
 *   /abs/path, ./rel  a Unix socket (text starting with '/' or '.')
 *   tcp:HOST:PORT     TCP; "tcp:" may prefix every TCP form below
 *   tls:HOST:PORT     TCP with TLS (also tls://HOST:PORT): the same forms
 *                     after the prefix; to connect only
 *   HOST:PORT         TCP, HOST a name or an IPv4 literal
 *   HOST              TCP on RP_DEFAULT_PORT
 *   [V6]:PORT, [V6]   TCP, an IPv6 literal in brackets
 *   V6                an unbracketed IPv6 literal (two or more ':'),
 *                     default port; a port needs the brackets
 * PORT is decimal, 1..65535.  A listener takes the TCP forms with a port
 * only (a default would hide a typo in a config file), and port 0 too,
 * "any free port".  A path must fit sun_path (at most 107 bytes).
 */
#include "rp_int.h"

#include <arpa/inet.h>
#include <ctype.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

/* What the address is for (the two entry points). */
typedef enum addr_use { FOR_CONNECT, FOR_LISTEN } addr_use;

static int parse_port(const char *s, addr_use use, const char *text,
                      uint16_t *port, rp_error *err)
{
	unsigned lo = use == FOR_LISTEN ? 0 : 1;
	unsigned long v = 0;
	size_t n = strlen(s);

	if (n == 0 || strspn(s, "0123456789") != n) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': port '%.16s' is not a number "
		        "%u..65535",
		        text, s, lo);
		return -1;
	}
	for (size_t i = 0; i < n && v <= 65535; i++)
		v = v * 10 + (unsigned long)(s[i] - '0');
	if (v > 65535) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': port %.16s is out of range "
		        "%u..65535",
		        text, s, lo);
		return -1;
	}
	if (v < lo) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': port 0 is only for listening", text);
		return -1;
	}
	*port = (uint16_t)v;
	return 0;
}

/* Host names and literals: letters, digits, '-', '.', '_', and for IPv6
 * ':' and '%' (zone).  Spaces, '/', '@' and the rest are typos. */
static int check_host(const char *h, size_t n, int v6, addr_use use,
                      const char *text, rp_error *err)
{
	if (n == 0) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': empty host%s", text,
		        use == FOR_LISTEN ? " (0.0.0.0 = every IPv4 interface, "
		                            "[::] = every IPv6 one)"
		                          : "");
		return -1;
	}
	if (n > 255) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.60s...': host longer than 255 bytes", text);
		return -1;
	}
	for (size_t i = 0; i < n; i++) {
		unsigned char c = (unsigned char)h[i];
		if (isalnum(c) || c == '-' || c == '.' || c == '_' ||
		    (v6 && (c == ':' || c == '%')))
			continue;
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': character '%c' not allowed in "
		        "a host",
		        text, isprint(c) ? c : '?');
		return -1;
	}
	return 0;
}

static int parse_unix(const char *path, const char *text, rp_addr *out,
                      rp_error *err)
{
	size_t n = strlen(path);

	if (n == 0) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s': empty Unix socket path", text);
		return -1;
	}
	if (n >= sizeof out->path) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "Unix socket path of %zu bytes is too long (at "
		        "most %zu): '%.60s...'",
		        n, sizeof out->path - 1, path);
		return -1;
	}
	out->kind = RP_ADDR_UNIX;
	memcpy(out->path, path, n + 1);
	return 0;
}

/* s without its "tcp:" prefix; text as given, for messages. */
static int parse_tcp(const char *s, addr_use use, const char *text,
                     rp_addr *out, rp_error *err)
{
	const char *host = s, *port = NULL, *colon;
	size_t hlen;
	int v6 = 0;

	if (*s == '[') {
		const char *close = strchr(s, ']');
		if (!close) {
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "address '%.200s': '[' without ']'", text);
			return -1;
		}
		host = s + 1;
		hlen = (size_t)(close - host);
		v6 = 1;
		if (close[1] == ':')
			port = close + 2;
		else if (close[1] != '\0') {
			rp_fail(err, RP_ERR_BAD_REQUEST,
			        "address '%.200s': expected ':PORT' after "
			        "']'",
			        text);
			return -1;
		}
	} else if ((colon = strchr(s, ':')) && strchr(colon + 1, ':')) {
		hlen = strlen(s); /* bare IPv6 literal, default port */
		v6 = 1;
	} else if (colon) {
		hlen = (size_t)(colon - s);
		port = colon + 1;
	} else {
		hlen = strlen(s);
	}
	if (check_host(host, hlen, v6, use, text, err) != 0)
		return -1;
	if (!port && use == FOR_LISTEN) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s' is not HOST:PORT (IPv6 as "
		        "[V6]:PORT)",
		        text);
		return -1;
	}
	out->kind = RP_ADDR_TCP;
	memcpy(out->host, host, hlen);
	out->host[hlen] = '\0';
	out->port = RP_DEFAULT_PORT;
	if (port && parse_port(port, use, text, &out->port, err) != 0)
		return -1;
	return 0;
}

static int parse(const char *text, addr_use use, rp_addr *out, rp_error *err)
{
	const char *path;
	rp_addr a;

	memset(&a, 0, sizeof a);
	if (!text || !*text) {
		rp_fail(err, RP_ERR_BAD_REQUEST, "empty address");
		return -1;
	}
	path = strncmp(text, "unix:", 5) == 0     ? text + 5
	       : text[0] == '/' || text[0] == '.' ? text
	                                          : NULL;
	if (path && use == FOR_LISTEN) {
		rp_fail(err, RP_ERR_BAD_REQUEST,
		        "address '%.200s' is a Unix socket path, not HOST:PORT",
		        text);
		return -1;
	}
	if (path) {
		if (parse_unix(path, text, &a, err) != 0)
			return -1;
	} else {
		const char *t = text;
		size_t tls = strncmp(t, "tls://", 6) == 0 ? 6
		             : strncmp(t, "tls:", 4) == 0 ? 4
		                                          : 0;
		if (tls) {
			if (use == FOR_LISTEN) {
				rp_fail(err, RP_ERR_BAD_REQUEST,
				        "address '%.200s': a listener speaks "
				        "TLS by the tls key, not a prefix",
				        text);
				return -1;
			}
			a.tls = 1;
			t += tls;
		} else if (strncmp(t, "tcp:", 4) == 0) {
			t += 4;
		}
		if (parse_tcp(t, use, text, &a, err) != 0)
			return -1;
	}
	*out = a;
	return 0;
}

int rp_addr_parse(const char *text, rp_addr *out, rp_error *err)
{
	return parse(text, FOR_CONNECT, out, err);
}

int rp_addr_parse_listen(const char *text, rp_addr *out, rp_error *err)
{
	return parse(text, FOR_LISTEN, out, err);
}

/*
 * Loopback: "localhost" (any case, optional trailing dot), 127.0.0.0/8,
 * ::1 and the IPv4-mapped ::ffff:127.x.y.z.  A Unix socket is local too
 * (reachable only from this machine, guarded by file permissions), so it
 * counts as loopback for the auth rule.  Anything else -- names, 0.0.0.0,
 * "::" -- may be reachable from elsewhere.
 */
int rp_addr_is_loopback(const rp_addr *a)
{
	struct in_addr v4;
	struct in6_addr v6;
	static const unsigned char mapped[12] = {0, 0, 0, 0, 0,    0,
	                                         0, 0, 0, 0, 0xff, 0xff};

	if (a->kind == RP_ADDR_UNIX)
		return 1;
	if (strcasecmp(a->host, "localhost") == 0 ||
	    strcasecmp(a->host, "localhost.") == 0)
		return 1;
	if (inet_pton(AF_INET, a->host, &v4) == 1)
		return (ntohl(v4.s_addr) >> 24) == 127;
	if (inet_pton(AF_INET6, a->host, &v6) == 1) {
		if (IN6_IS_ADDR_LOOPBACK(&v6))
			return 1;
		return memcmp(v6.s6_addr, mapped, 12) == 0 &&
		       v6.s6_addr[12] == 127;
	}
	return 0;
}
