/*
 * solve_args.h -- luxrad-solve's command line: what it asks for, parsed
 * and checked (solve_args.c).
 */
#ifndef LUXRAD_SOLVE_ARGS_H
#define LUXRAD_SOLVE_ARGS_H

#include <stdint.h>

#include "rad.h"
#include "tool.h"

enum { EXIT_OKAY = 0, EXIT_SOLVE = 1, EXIT_USAGE = 2 };

typedef struct cli_args {
	const char *scene_path;
	const char *points_path;    /* NULL: no illuminance queries */
	const char *export_path;    /* NULL: no solved-mesh export */
	const char *polygons_path;  /* NULL: no polygon table */
	tool_luminaires luminaires; /* --luminaire NAME=FILE */
	rad_options opt;            /* every engine option (rad.h's table) */
	uint32_t iterations;        /* > 0: exactly this many steps */
	uint32_t audit_every;       /* > 0: audit one link in this many */
	int json;                   /* one JSON object on stdout */
	int per_iteration;          /* a stats line on stderr after each step */
	rad_bvh_mode bvh;           /* --bvh (default RAD_BVH_DEFAULT) */
	int compact_bvh;            /* --compact-bvh: --bvh compact */
	int help;
	int given[RAD_NOPTIONS]; /* engine options seen on the line */
	int reparse;             /* cli_parse's second pass (--accuracy) */
} cli_args;

/*
 * Parse argv into *a.  Returns an exit code: EXIT_OKAY, or EXIT_USAGE
 * after a message on stderr.  With --help, a->help is set and the rest
 * need not be complete.
 */
int cli_parse(int argc, char **argv, cli_args *a);

/* --help on stdout, with the defaults a gives (after --accuracy). */
void cli_print_help(const cli_args *a);

#endif
