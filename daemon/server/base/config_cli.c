/*
 * config_cli.c -- luxradd's configuration as users write it: the config
 * file (KEY = VALUE lines, "FILE:LINE: " in errors), the command line
 * (--flag VALUE for every key, --config, --help, --version) and the
 * --help text.  Each value is parsed by config.c's table (cfg_set_value).
 */
#include "config.h"
#include "config_int.h"
#include "textutil.h"

#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define LUXRADD_VERSION "0.1.0"
#define MAX_LINE 8192 /* longest config-file line accepted */

/* ------------------------------------------------------------- the file */

/*
 * Split one line into key and value (both NUL-terminated in place).
 * Returns 1 for a setting, 0 for a blank or comment line, -1 on a syntax
 * error (msg filled).
 */
static int split_line(char *line, char **key, size_t *keylen, char **val,
                      char *msg, size_t msglen)
{
	char *s = line, *e;
	while (*s == ' ' || *s == '\t')
		s++;
	if (*s == '\0' || *s == '#')
		return 0;
	*key = s;
	while (*s == '_' || *s == '-' || (*s >= 'a' && *s <= 'z') ||
	       (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9'))
		s++;
	*keylen = (size_t)(s - *key);
	while (*s == ' ' || *s == '\t')
		s++;
	if (*keylen == 0 || *s != '=')
		return srv_fail(msg, msglen, "expected 'key = value'");
	s++;
	while (*s == ' ' || *s == '\t')
		s++;
	if (*s == '"' || *s == '\'') {
		char q = *s++;
		e = strchr(s, q);
		if (!e)
			return srv_fail(msg, msglen, "unterminated %c quote",
			                q);
		*e++ = '\0';
		*val = s;
		while (*e == ' ' || *e == '\t')
			e++;
		if (*e && *e != '#')
			return srv_fail(
			        msg, msglen,
			        "unexpected text after the closing quote");
		return 1;
	}
	*val = s;
	for (e = s; *e; e++) /* a comment starts at '#' after a blank */
		if (*e == '#' && (e == s || e[-1] == ' ' || e[-1] == '\t'))
			break;
	*e = '\0';
	while (e > s && (e[-1] == ' ' || e[-1] == '\t'))
		*--e = '\0';
	return 1;
}

static int load_line(srv_config *c, char *line, const char *path,
                     unsigned lineno, char *msg, size_t msglen)
{
	char *key = NULL, *val = NULL, why[600];
	size_t keylen;
	int r = split_line(line, &key, &keylen, &val, why, sizeof(why));
	if (r <= 0) {
		if (r < 0)
			srv_fail(msg, msglen, "%s:%u: %s", path, lineno, why);
		return r;
	}
	const cfg_key *k = cfg_find_key(key, keylen);
	if (!k) {
		srv_fail(msg, msglen, "%s:%u: unknown key '%.*s'", path, lineno,
		         (int)(keylen > 100 ? 100 : keylen), key);
		return -1;
	}
	if (cfg_set_value(c, k, val, why, sizeof(why)) < 0) {
		srv_fail(msg, msglen, "%s:%u: %s: %s", path, lineno, k->name,
		         why);
		return -1;
	}
	return 0;
}

int srv_config_load_file(srv_config *c, const char *path, int must_exist,
                         char *msg, size_t msglen)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		if (errno == ENOENT && !must_exist)
			return 0;
		srv_fail(msg, msglen, "%s: cannot open config file: %s", path,
		         strerror(errno));
		return -1;
	}
	char *line = NULL;
	size_t cap = 0;
	ssize_t n;
	unsigned lineno = 0;
	int rc = 0;
	while (rc == 0 && (n = getline(&line, &cap, f)) >= 0) {
		lineno++;
		if (n > MAX_LINE) {
			srv_fail(msg, msglen,
			         "%s:%u: line longer than %d bytes", path,
			         lineno, MAX_LINE);
			rc = -1;
		} else if ((size_t)n != strlen(line)) {
			srv_fail(msg, msglen,
			         "%s:%u: NUL byte (not a text file?)", path,
			         lineno);
			rc = -1;
		} else {
			line[strcspn(line, "\r\n")] = '\0';
			rc = load_line(c, line, path, lineno, msg, msglen) < 0
			             ? -1
			             : 0;
		}
	}
	if (rc == 0 && ferror(f)) {
		srv_fail(msg, msglen, "%s: read error: %s", path,
		         strerror(errno));
		rc = -1;
	}
	free(line);
	fclose(f);
	return rc;
}

void srv_config_usage(const char *argv0)
{
	srv_config d;
	char lhs[64], def[4200], flag[48];
	srv_config_default(&d);
	printf("Usage: %s [--config FILE] [OPTIONS]\n\n"
	       "luxradd, the luxrad radiosity daemon: stores scenes, solves "
	       "them in\nbackground jobs and answers illuminance queries over "
	       "TCP and a Unix\nsocket.\n\n"
	       "  -c, --config FILE        read FILE first (key = value "
	       "lines); flags win\n"
	       "  -h, --help               show this help\n"
	       "  -V, --version            print the version\n\n"
	       "Every option below is also a config-file key: --listen-tcp X "
	       "is\nlisten_tcp = X.  Boolean flags alone mean yes; give a "
	       "value as\n--require-token=no.\n\n",
	       argv0 && argv0[0] ? argv0 : "luxradd");
	size_t nkeys;
	const cfg_key *keys = cfg_keys(&nkeys);
	for (size_t i = 0; i < nkeys; i++) {
		const cfg_key *k = &keys[i];
		size_t j;
		for (j = 0; k->name[j] && j + 1 < sizeof(flag); j++)
			flag[j] = k->name[j] == '_' ? '-' : k->name[j];
		flag[j] = '\0';
		snprintf(lhs, sizeof(lhs), "--%s %s", flag, k->metavar);
		cfg_fmt_value(&d, k, def, sizeof(def));
		printf("  %s\n      %s\n      default: %s; e.g. --%s%s%s\n",
		       lhs, k->help, def, flag, k->type == K_BOOL ? "=" : " ",
		       k->example);
	}
	printf("\nExamples:\n"
	       "  luxradd --config /etc/luxradd/luxradd.conf\n"
	       "  luxradd --data-dir /tmp/lx --listen-tcp none --workers 4\n"
	       "  luxradd --listen-tcp 0.0.0.0:7420 --token-file "
	       "/etc/luxradd/token\n");
}

/* ----------------------------------------------------------------- argv */

enum { OPT_CONFIG = 'c', OPT_HELP = 'h', OPT_VERSION = 'V', OPT_KEY = 256 };

static void build_longopts(struct option *lo, char names[][48])
{
	size_t i, nkeys;
	const cfg_key *keys = cfg_keys(&nkeys);
	for (i = 0; i < nkeys; i++) {
		size_t j;
		for (j = 0; keys[i].name[j] && j + 1 < 48; j++)
			names[i][j] =
			        keys[i].name[j] == '_' ? '-' : keys[i].name[j];
		names[i][j] = '\0';
		lo[i] = (struct option){names[i],
		                        keys[i].type == K_BOOL
		                                ? optional_argument
		                                : required_argument,
		                        NULL, OPT_KEY + (int)i};
	}
	lo[i++] =
	        (struct option){"config", required_argument, NULL, OPT_CONFIG};
	lo[i++] = (struct option){"help", no_argument, NULL, OPT_HELP};
	lo[i++] = (struct option){"version", no_argument, NULL, OPT_VERSION};
	lo[i] = (struct option){NULL, 0, NULL, 0};
}

/* Describe getopt's complaint about argv[optind - 1]. */
static void getopt_error(int r, int argc, char **argv, char *msg, size_t msglen)
{
	const char *arg =
	        optind >= 1 && optind - 1 < argc ? argv[optind - 1] : "?";
	if (r == ':')
		srv_fail(msg, msglen, "option '%s' needs a value", arg);
	else if (optopt && strncmp(arg, "--", 2) != 0)
		srv_fail(msg, msglen, "unknown option '-%c'", optopt);
	else
		srv_fail(msg, msglen, "unknown or ambiguous option '%s'", arg);
}

/*
 * One pass over argv.  Pass 0 handles --help, --version and --config;
 * pass 1 applies every other flag.  Returns 0, 1 (help/version printed)
 * or -1.
 */
static int args_pass(srv_config *c, int pass, int argc, char **argv,
                     const struct option *lo, char *msg, size_t msglen)
{
	int r;
	optind = 0; /* glibc: full re-initialisation */
	opterr = 0;
	while ((r = getopt_long(argc, argv, ":c:hV", lo, NULL)) != -1) {
		if (r == '?' || r == ':') {
			getopt_error(r, argc, argv, msg, msglen);
			return -1;
		}
		if (pass == 0 && r == OPT_HELP) {
			srv_config_usage(argv[0]);
			return 1;
		}
		if (pass == 0 && r == OPT_VERSION) {
			printf("luxradd " LUXRADD_VERSION "\n");
			return 1;
		}
		if (pass == 0 && r == OPT_CONFIG) {
			if (cfg_set_path(c->config_file, sizeof(c->config_file),
			                 optarg, msg, msglen) < 0)
				return -1;
			if (srv_config_load_file(c, c->config_file, 1, msg,
			                         msglen) < 0)
				return -1;
		}
		if (pass == 1 && r >= OPT_KEY) {
			size_t nkeys;
			const cfg_key *k = &cfg_keys(&nkeys)[r - OPT_KEY];
			char why[600];
			const char *v = optarg ? optarg : "yes";
			if (cfg_set_value(c, k, v, why, sizeof(why)) < 0) {
				srv_fail(msg, msglen, "--%s: %s",
				         lo[r - OPT_KEY].name, why);
				return -1;
			}
		}
	}
	if (optind < argc) {
		srv_fail(msg, msglen,
		         "unexpected argument '%s' (boolean flags take a value "
		         "as --flag=value)",
		         argv[optind]);
		return -1;
	}
	return 0;
}

int srv_config_from_args(srv_config *c, int argc, char **argv, char *msg,
                         size_t msglen)
{
	struct option lo[CFG_MAX_KEYS + 4];
	char names[CFG_MAX_KEYS][48];
	build_longopts(lo, names);
	for (int pass = 0; pass < 2; pass++) {
		int r = args_pass(c, pass, argc, argv, lo, msg, msglen);
		if (r != 0)
			return r;
	}
	return srv_config_check(c, msg, msglen) < 0 ? -1 : 0;
}
