/*
 * rp_cli.c -- what the command-line tools (luxrad-solve,
 * luxrad-reference, luxrad) share about their command lines: the shape of
 * argv, and option tables printed alike.
 */
#include "rp.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

void rp_help_row(FILE *f, char shortopt, const char *name, const char *metavar,
                 const char *help, const char *def)
{
	enum { COL = 25, WIDTH = 79 };
	int col = COL;
	char lhs[96], text[1024];

	int n = shortopt ? snprintf(lhs, sizeof(lhs), "-%c, ", shortopt) : 0;
	snprintf(lhs + n, sizeof(lhs) - (size_t)n, "--%s%s%s", name,
	         metavar ? " " : "", metavar ? metavar : "");
	snprintf(text, sizeof(text), "%s%s%s%s", help,
	         def && def[0] ? " [" : "", def ? def : "",
	         def && def[0] ? "]" : "");
	help = text;

	fprintf(f, "  %-22s", lhs);
	if (strlen(lhs) > 22)
		fprintf(f, "\n%*s", COL - 1, "");
	for (const char *w = help; *w;) {
		size_t n = strcspn(w, " ");
		if (col > COL && col + 1 + (int)n > WIDTH) {
			fprintf(f, "\n%*s", COL, "");
			col = COL;
		} else {
			fputc(' ', f);
			col++;
		}
		fprintf(f, "%.*s", (int)n, w);
		col += (int)n;
		w += n;
		while (*w == ' ')
			w++;
	}
	fputc('\n', f);
}

int rp_cli_fail(char *msg, size_t len, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, len, fmt, ap);
	va_end(ap);
	return RP_CLI_USAGE;
}

int rp_cli_double(const char *s, double *out)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v))
		return -1;
	*out = v;
	return 0;
}

const void *rp_cli_find(const void *rows, size_t n, size_t size,
                        const char *name, size_t len)
{
	for (size_t i = 0; i < n; i++) {
		const char *const *row =
		        (const char *const *)((const char *)rows + i * size);
		if (strlen(*row) == len && strncmp(*row, name, len) == 0)
			return row;
	}
	return NULL;
}

/* One "--name[=value]" at argv[*i]; may consume argv[*i + 1]. */
static int scan_option(int argc, char **argv, int *i, const rp_cli_ops *ops,
                       void *ud, char *msg, size_t len)
{
	const char *arg = argv[*i] + 2, *metavar = NULL;
	const char *eq = strchr(arg, '=');
	size_t n = eq ? (size_t)(eq - arg) : strlen(arg);
	const char *value = eq ? eq + 1 : NULL;

	if (ops->find(ud, arg, n, &metavar) != 0)
		return rp_cli_fail(msg, len, "unknown option '%s'", argv[*i]);
	if (!metavar && value)
		return rp_cli_fail(msg, len, "--%.*s takes no value", (int)n,
		                   arg);
	if (metavar && !value) {
		if (*i + 1 >= argc)
			return rp_cli_fail(msg, len,
			                   "--%.*s needs a value (%s)", (int)n,
			                   arg, metavar);
		value = argv[++*i];
	}
	return ops->set(ud, arg, n, value, msg, len);
}

int rp_cli_scan(int argc, char **argv, const rp_cli_ops *ops, void *ud,
                const char **scene, int *help, char *msg, size_t len)
{
	int only_positional = 0, rc = 0;
	for (int i = 1; i < argc && rc == 0; i++) {
		const char *s = argv[i];
		if (!only_positional && strcmp(s, "--") == 0)
			only_positional = 1;
		else if (!only_positional && strncmp(s, "--", 2) == 0)
			rc = scan_option(argc, argv, &i, ops, ud, msg, len);
		else if (!only_positional && strcmp(s, "-h") == 0)
			rc = RP_CLI_HELP;
		else if (!only_positional && s[0] == '-' && s[1] != '\0')
			rc = rp_cli_fail(msg, len, "unknown option '%s'", s);
		else if (*scene)
			rc = rp_cli_fail(
			        msg, len,
			        "more than one scene given ('%s', '%s')",
			        *scene, s);
		else
			*scene = s;
	}
	if (rc == RP_CLI_HELP)
		*help = 1;
	return rc == RP_CLI_HELP ? 0 : rc;
}

int rp_points_read(const char *path, double **xyz, size_t *n, char *msg,
                   size_t len)
{
	FILE *f = fopen(path, "r");
	char *line = NULL;
	size_t cap = 0, have = 0;
	unsigned long lineno = 0;
	double *pts = NULL;
	int rc = 0;

	*xyz = NULL;
	*n = 0;
	if (!f) {
		snprintf(msg, len, "cannot open points file '%s': %s", path,
		         strerror(errno));
		return -1;
	}
	while (rc == 0 && getline(&line, &cap, f) != -1) {
		double p[6];
		const char *why = NULL;
		int r = rp_point_line_parse(line, p, &why);
		lineno++;
		if (r < 0) {
			rc = rp_cli_fail(msg, len, "%s:%lu: %s", path, lineno,
			                 why);
		} else if (r > 0 && *n == have) {
			size_t ncap = have ? 2 * have : 64;
			double *np = realloc(pts, ncap * 6 * sizeof(double));
			if (!np) {
				snprintf(msg, len, "out of memory");
				rc = -1;
			} else {
				pts = np;
				have = ncap;
			}
		}
		if (rc == 0 && r > 0)
			memcpy(pts + 6 * (*n)++, p, sizeof(p));
	}
	if (rc == 0 && ferror(f)) {
		snprintf(msg, len, "cannot read '%s'", path);
		rc = -1;
	}
	free(line);
	fclose(f);
	if (rc != 0) {
		free(pts);
		*n = 0;
		return rc;
	}
	*xyz = pts;
	return 0;
}
