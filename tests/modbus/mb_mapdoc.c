/*
 * mb_mapdoc.c -- MODBUS.md's generated sections, from the one definition
 * of the map (regmap.h) and of the config keys (MB_CONFIG_KEYS).
 *
 *   mb_mapdoc                print both sections to stdout
 *   mb_mapdoc --check FILE   exit 1 when FILE's sections differ (CTest)
 *   mb_mapdoc --update FILE  rewrite FILE's sections in place
 *
 * A section is the text between "<!-- BEGIN GENERATED NAME" (to the end
 * of that line) and "<!-- END GENERATED NAME -->".
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "modbus.h"

typedef struct section {
	const char *name;
	int (*write)(FILE *f);
} section;

static int write_config(FILE *f)
{
	size_t n;
	const mb_config_key *k = mb_config_keys(&n);
	fprintf(f, "| Key | Value | Default | Meaning |\n|---|---|---|---|\n");
	for (size_t i = 0; i < n; i++)
		fprintf(f, "| `%s` | %s | `%s` | %s |\n", k[i].name,
		        k[i].metavar, k[i].default_value, k[i].help);
	return ferror(f) ? -1 : 0;
}

static const section sections[] = {
        {"REGMAP", mb_map_write_markdown},
        {"CONFIG", write_config},
};
#define NSECTIONS (sizeof sections / sizeof sections[0])

/* The section's text, malloc'ed. */
static char *generate(const section *s)
{
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	if (!f || s->write(f) < 0 || fclose(f) != 0) {
		fprintf(stderr, "mb_mapdoc: cannot generate %s\n", s->name);
		exit(2);
	}
	return buf;
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	char *buf = NULL;
	size_t cap = 0, len = 0, r;
	if (!f) {
		perror(path);
		exit(2);
	}
	do {
		if (len + 4096 + 1 > cap) {
			cap = 2 * cap + 8192;
			buf = realloc(buf, cap);
			if (!buf)
				exit(2);
		}
		r = fread(buf + len, 1, 4096, f);
		len += r;
	} while (r > 0);
	fclose(f);
	buf[len] = '\0';
	return buf;
}

/* Locate a section's body in doc: [*lo, *hi).  -1 when markers miss. */
static int find(const char *doc, const char *name, size_t *lo, size_t *hi)
{
	char begin[64], end[64];
	snprintf(begin, sizeof begin, "<!-- BEGIN GENERATED %s", name);
	snprintf(end, sizeof end, "<!-- END GENERATED %s -->", name);
	const char *b = strstr(doc, begin);
	const char *nl = b ? strchr(b, '\n') : NULL;
	const char *e = nl ? strstr(nl, end) : NULL;
	if (!e)
		return -1;
	*lo = (size_t)(nl + 1 - doc);
	*hi = (size_t)(e - doc);
	return 0;
}

int main(int argc, char **argv)
{
	if (argc == 1) {
		for (size_t i = 0; i < NSECTIONS; i++) {
			char *g = generate(&sections[i]);
			fputs(g, stdout);
			free(g);
		}
		return 0;
	}
	int update = argc == 3 && strcmp(argv[1], "--update") == 0;
	if (argc != 3 || (!update && strcmp(argv[1], "--check") != 0)) {
		fprintf(stderr, "usage: mb_mapdoc [--check|--update FILE]\n");
		return 2;
	}
	char *doc = slurp(argv[2]);
	int stale = 0;
	for (size_t i = 0; i < NSECTIONS; i++) {
		size_t lo, hi;
		if (find(doc, sections[i].name, &lo, &hi) < 0) {
			fprintf(stderr,
			        "mb_mapdoc: %s: no GENERATED %s markers\n",
			        argv[2], sections[i].name);
			return 1;
		}
		char *g = generate(&sections[i]);
		if (strlen(g) == hi - lo && memcmp(doc + lo, g, hi - lo) == 0) {
			free(g);
			continue;
		}
		stale = 1;
		if (!update) {
			fprintf(stderr,
			        "mb_mapdoc: %s: section %s differs from the "
			        "code; "
			        "run mb_mapdoc --update %s\n--- expected:\n%s",
			        argv[2], sections[i].name, argv[2], g);
			free(g);
			continue;
		}
		size_t glen = strlen(g), dlen = strlen(doc);
		char *nd = malloc(dlen - (hi - lo) + glen + 1);
		if (!nd)
			return 2;
		memcpy(nd, doc, lo);
		memcpy(nd + lo, g, glen);
		memcpy(nd + lo + glen, doc + hi, dlen - hi + 1);
		free(doc);
		free(g);
		doc = nd;
	}
	if (update && stale) {
		FILE *f = fopen(argv[2], "wb");
		if (!f || fputs(doc, f) < 0 || fclose(f) != 0) {
			perror(argv[2]);
			return 2;
		}
	}
	free(doc);
	return update ? 0 : stale;
}
