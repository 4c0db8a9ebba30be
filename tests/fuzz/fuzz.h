/*
 * fuzz.h -- what the fuzz harnesses share: the libFuzzer entry point they
 * each define, and the check that turns a broken invariant into a crash.
 *
 * A harness is one C file defining LLVMFuzzerTestOneInput.  Built with
 * LUXRAD_FUZZ (clang, -fsanitize=fuzzer) it is a fuzzer; linked with
 * replay.c (every build) it runs once on each file it is given, which is
 * how the seed corpus and the regression inputs are tested in CI.
 *
 * A failed FUZZ_CHECK prints the harness's file and line and what was
 * expected, then aborts: libFuzzer records the input as a crash and the
 * replay stops with a failure, exactly as for a sanitizer report.
 */
#ifndef LUXRAD_FUZZ_H
#define LUXRAD_FUZZ_H

#include <stddef.h>
#include <stdint.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* Print "file:line: fuzz check failed: what" to stderr and abort. */
_Noreturn void fuzz_fail(const char *file, int line, const char *what);

#define FUZZ_CHECK(cond, what)                                                 \
	do {                                                                   \
		if (!(cond))                                                   \
			fuzz_fail(__FILE__, __LINE__, what);                   \
	} while (0)

#endif
