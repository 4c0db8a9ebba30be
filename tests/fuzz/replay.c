/*
 * replay.c -- a fuzz harness without libFuzzer: LLVMFuzzerTestOneInput run
 * once on every file named on the command line, or found in a directory
 * named there (not below it; names starting with '.' are skipped, so an
 * empty regression directory can hold a .gitkeep).
 *
 *   fuzz_replay_frame DIR|FILE...
 *
 * Files are run in name order, each with its name printed first, so a
 * crash or a failed check shows which input it was.  Exits 0 when every
 * input ran (a fault aborts the program), 1 when a path cannot be read,
 * 2 on usage.  This is how the seed corpus and tests/fuzz/regress/ are
 * tested in every build, with the sanitizers of that build.
 */
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "fuzz.h"

/* Run the harness on one file; 0, or -1 when it cannot be read.  The
 * input is in a buffer of exactly its size (one byte for an empty file),
 * so that the sanitizers see any read past its end. */
static int run_file(const char *path)
{
	FILE *f = fopen(path, "rb");
	struct stat st;
	unsigned char *buf = NULL;
	size_t len = 0;
	int ok = 0;

	printf("%s\n", path);
	fflush(stdout);
	if (f && fstat(fileno(f), &st) == 0 && st.st_size >= 0) {
		len = (size_t)st.st_size;
		buf = malloc(len ? len : 1);
		ok = buf && fread(buf, 1, len, f) == len;
	}
	if (f)
		fclose(f);
	if (!ok) {
		fprintf(stderr, "replay: %s: cannot read it\n", path);
		free(buf);
		return -1;
	}
	LLVMFuzzerTestOneInput(buf, len);
	free(buf);
	return 0;
}

static int by_name(const void *a, const void *b)
{
	return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Run every file of a directory in name order; the count, or -1. */
static long run_dir(const char *dir)
{
	DIR *d = opendir(dir);
	struct dirent *e;
	char **names = NULL, **nn;
	size_t n = 0, cap = 0;
	long ran = 0;
	int bad = 0;

	if (!d) {
		fprintf(stderr, "replay: %s: %s\n", dir, strerror(errno));
		return -1;
	}
	while ((e = readdir(d))) {
		if (e->d_name[0] == '.')
			continue;
		if (n == cap) {
			cap = cap ? 2 * cap : 64;
			if (!(nn = realloc(names, cap * sizeof *names))) {
				bad = 1;
				break;
			}
			names = nn;
		}
		size_t len = strlen(dir) + strlen(e->d_name) + 2;
		if (!(names[n] = malloc(len))) {
			bad = 1;
			break;
		}
		snprintf(names[n++], len, "%s/%s", dir, e->d_name);
	}
	closedir(d);
	if (n)
		qsort(names, n, sizeof *names, by_name);
	for (size_t i = 0; i < n; i++) {
		struct stat st;
		if (!bad && stat(names[i], &st) == 0 && S_ISREG(st.st_mode)) {
			if (run_file(names[i]) != 0)
				bad = 1;
			else
				ran++;
		}
		free(names[i]);
	}
	free(names);
	if (bad)
		fprintf(stderr, "replay: %s: not every file could be read\n",
		        dir);
	return bad ? -1 : ran;
}

int main(int argc, char **argv)
{
	long total = 0;
	int bad = 0;

	if (argc < 2) {
		fprintf(stderr, "usage: %s DIR|FILE...\n", argv[0]);
		return 2;
	}
	for (int i = 1; i < argc; i++) {
		struct stat st;
		long ran;
		if (stat(argv[i], &st) != 0) {
			fprintf(stderr, "replay: %s: %s\n", argv[i],
			        strerror(errno));
			bad = 1;
			continue;
		}
		if (S_ISDIR(st.st_mode))
			ran = run_dir(argv[i]);
		else
			ran = run_file(argv[i]) == 0 ? 1 : -1;
		if (ran < 0)
			bad = 1;
		else
			total += ran;
	}
	printf("replay: %ld inputs run\n", total);
	return bad ? 1 : 0;
}
