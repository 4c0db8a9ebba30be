/*
 * parse.c -- pho_parse: the input's checks and which parser reads it (an
 * IES file when its first line is an IES header or a line starts
 * "TILT=", else EULUMDAT, whose first line is free text).
 */
#include <math.h>
#include <string.h>

#include "internal.h"

#define MAX_INPUT (64u << 20) /* bytes: no photometric file is near it */

static int starts(const char *s, size_t n, const char *word)
{
	size_t k = strlen(word);
	return n >= k && memcmp(s, word, k) == 0;
}

/* IES when a line starts with its header or its TILT= line. */
static int looks_ies(const char *b, size_t len)
{
	pho_lex lx = {b, b + len, 1, 1, NULL, 0};
	const char *s;
	size_t n;
	for (int first = 1; pho_next_line(&lx, &s, &n); first = 0)
		if ((first &&
		     (starts(s, n, "IESNA") || starts(s, n, "IES:"))) ||
		    starts(s, n, "TILT="))
			return 1;
	return 0;
}

pho_status pho_parse(const char *bytes, size_t len, const pho_opts *opts,
                     pho_table **out, char *err, size_t errlen)
{
	pho_opts none = {0};
	pho_info info = {0};
	pho_lex lx = {bytes, bytes + len, 1, 1, err, errlen};
	*out = NULL;
	if (err && errlen)
		err[0] = 0;
	if (!bytes || len == 0)
		return pho_fail(&lx, PHO_ERR_INVALID, "empty input");
	if (len > MAX_INPUT)
		return pho_fail(&lx, PHO_ERR_INVALID,
		                "%zu bytes: more than a photometric file "
		                "(limit %u)",
		                len, MAX_INPUT);
	if (len >= 3 && memcmp(bytes, "\xEF\xBB\xBF", 3) == 0)
		lx.p += 3; /* a UTF-8 byte order mark */
	if (opts && !(isfinite(opts->tilt_deg) && opts->lamp_lumens >= 0 &&
	              isfinite(opts->lamp_lumens)))
		return pho_fail(&lx, PHO_ERR_INVALID,
		                "options: tilt %g, lamp lumens %g",
		                opts->tilt_deg, opts->lamp_lumens);
	if (looks_ies(lx.p, (size_t)(lx.end - lx.p))) {
		info.format = PHO_IES;
		return pho_parse_ies(&lx, opts ? opts : &none, &info, out);
	}
	info.format = PHO_LDT;
	return pho_parse_ldt(&lx, opts ? opts : &none, &info, out);
}
