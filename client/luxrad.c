/*
 * luxrad.c -- the luxrad command-line client: argv parsing, --help texts
 * and dispatch to the command functions (cmds.c, cmd_*.c, show.c).
 *
 * Every option is declared once (LX_OPTIONS in client.h and rad.h's
 * RAD_OPTIONS, as the rows of args.c's table); each command
 * says which options it takes, how many positional arguments, and its
 * help text with examples.  Parsing only collects strings: each command
 * converts and checks its own values, so a bad number is reported with
 * the option's name, and nothing reaches the daemon that does not parse.
 */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client.h"

#define GLOBAL_OPTS                                                            \
	(LX_BIT(HELP) | LX_BIT(JSON) | LX_BIT(CONNECT) | LX_BIT(TOKEN_FILE) |  \
	 LX_BIT(TLS_CA))
#define CREATE_OPTS (LX_BIT(NAME) | LX_BIT(SOLVER) | LX_ENGINE_BITS)

typedef struct cmd_def {
	const char *name;
	int (*fn)(lx_ctx *cx);
	int npos;          /* positional arguments required (exactly) */
	uint64_t opts;     /* accepted options besides the global ones */
	const char *usage; /* after "luxrad NAME" */
	const char *summary;
	const char *text; /* details and examples */
} cmd_def;

static const cmd_def commands[] = {
        {"submit", lx_cmd_submit, 1,
         CREATE_OPTS | LX_BIT(SOLVE) | LX_BIT(LUMINAIRE),
         "FILE [--name N] [--luminaire NAME=FILE]... [--solve [create "
         "options]]",
         "upload a .gltf/.glb scene; prints the scene id",
         "A .gltf is packed with the files beside it (buffers, images, the\n"
         "photometric files its nodes name) into one GLB.  --luminaire "
         "gives the\nlight NAME (its node's or its own glTF name) the IES "
         "or EULUMDAT FILE;\nthe file travels with the scene.  With "
         "--solve, also creates a job\n(create options apply) and runs it "
         "to convergence in the background;\nprints the job id instead. "
         "--json prints each reply (upload, create,\nrun) as one JSON "
         "line.\n\nExamples:\n  luxrad submit scenes/cornell.gltf\n"
         "  luxrad submit office.glb --name office --solve --eps 1e-3\n"
         "  luxrad submit office.gltf --luminaire lamp=downlight.ies "
         "--solve\n"},
        {"scenes", lx_cmd_scenes, 0, 0, "", "list scenes",
         "Examples:\n  luxrad scenes\n  luxrad scenes --json\n"},
        {"jobs", lx_cmd_jobs, 0, 0, "", "list jobs",
         "Examples:\n  luxrad jobs\n"},
        {"create", lx_cmd_create, 1, CREATE_OPTS, "SCENE [create options]",
         "create a solve job (paused); prints the job id",
         "The daemon checks the ranges; defaults in brackets are the "
         "daemon's.\n\nExamples:\n  luxrad create 1\n"
         "  luxrad create 1 --solver rmb --eps 5e-4 --tol 1e-4 --name "
         "fine\n"},
        {"run", lx_cmd_run, 1,
         LX_BIT(ITERATIONS) | LX_BIT(CONVERGE) | LX_BIT(SECONDS) | LX_BIT(WAIT),
         "JOB [--iterations N | --converge | --seconds T] [--wait]",
         "start or continue a job",
         "Without --wait, returns once the daemon has queued the job. With "
         "--wait,\nblocks until the job stops (progress on stderr when it "
         "is a terminal);\nexit status 0 when it is done or paused, 4 "
         "when it failed or was\ncancelled.\n\nExamples:\n  luxrad run 4 "
         "--wait\n  luxrad run 4 --iterations 2\n  luxrad run 4 --seconds "
         "30 --wait\n"},
        {"watch", lx_cmd_watch, 1, 0, "JOB", "follow a job's progress",
         "On a terminal: a progress bar and one line of statistics per "
         "iteration\n(iteration, links, leaves, memory, residual, error "
         "estimate, seconds).\nOtherwise one JSON object per event. Exits "
         "when the job is done, failed,\ncancelled or paused (at once if it "
         "is not running): status 0, or 4 when it\nfailed or was "
         "cancelled.\n\nExamples:\n  luxrad watch 4\n  luxrad watch 4 | "
         "jq .stats.residual\n"},
        {"query", lx_cmd_query, 1,
         LX_BIT(POINTS) | LX_BIT(GRID) | LX_BIT(SURFACES) | LX_BIT(ORIGIN) |
                 LX_BIT(U) | LX_BIT(V) | LX_BIT(SPACING) | LX_BIT(NORMAL),
         "JOB (--points FILE | --grid --origin X,Y,Z --u X,Y,Z --v X,Y,Z "
         "[--spacing P] [--normal X,Y,Z] | --surfaces)",
         "illuminance from the latest solution (CSV, or --json)",
         "Points file: one point per line, 'x y z nx ny nz': position in "
         "metres and\nthe normal of the surface the point lies on (any "
         "non-zero length); '#'\nstarts a comment, blank lines are ignored "
         "(as luxrad-solve --points).\n\nThe grid covers origin + s*u + "
         "t*v, s,t in [0,1], one point at each\ncell centre; the default "
         "spacing follows EN 12464-1 (0.2 * 5^log10(d),\nd the longer "
         "side). Its summary (min, mean, max, uniformity) goes to\nstderr.\n"
         "\nCSV columns: points x,y,z,nx,ny,nz,lux,error_lux; grid "
         "i,j,x,y,z,lux,error_lux;\nsurfaces node,name,area_m2,min_lux,"
         "mean_lux,max_lux. error_lux is the\nestimated error of each "
         "value (the job's accuracy sets its target).\n\n"
         "Examples:\n  luxrad query 4 --points desk.txt\n"
         "  luxrad query 4 --grid --origin 0,0.8,0 --u 4,0,0 --v 0,0,3\n"
         "  luxrad query 4 --surfaces --json\n"},
        {"export", lx_cmd_export, 1, LX_BIT(OUTPUT), "JOB -o FILE.glb",
         "write the solved mesh as GLB",
         "One mesh per scene node, COLOR_0 (tone-mapped illuminance) and "
         "_ILLUMINANCE\n(lux per vertex). The file is written atomically "
         "(a temporary, then\nrenamed).\n\nExamples:\n  luxrad export 4 -o "
         "box-lit.glb\n"},
        {"report", lx_cmd_report, 1,
         LX_BIT(OUTPUT) | LX_BIT(WORKPLANE_HEIGHT) | LX_BIT(BORDER) |
                 LX_BIT(FLOOR) | LX_BIT(SURFACE),
         "JOB -o FILE.html [--workplane-height H] [--border B] [--floor "
         "NODE]\n       [--surface NODE]...",
         "write a lighting report (one self-contained HTML file)",
         "The report holds the scene and the job, the luminaires, the "
         "solve's accuracy\nand cost, and the calculation surfaces with "
         "their Em, Emin, Emax, U0 =\nEmin/Em and Ud = Emin/Emax and "
         "false-colour images (PNG, embedded):\n- the work plane: a "
         "horizontal grid H above the floor over the room's extent\n  "
         "(the --floor node's, by default a node named \"floor\", else "
         "the scene's\n  bounds) less a border band B, at the EN 12464-1 "
         "spacing; a plan view with\n  a legend and isolines. In a room "
         "under 2 H tall the plane is put at half\n  its height; the band "
         "is at most a quarter of the shorter side.\n- each --surface "
         "node (by default every node with polygons, at most 24):\n  its "
         "faces gridded on the polygons themselves (query.node).\nThe "
         "file has no external references; it is written atomically.\n\n"
         "Examples:\n  luxrad report 4 -o report.html\n  luxrad report 4 "
         "-o office.html --workplane-height 0.75 --border 0.5 \\\n      "
         "--surface floor --surface walls\n"},
        {"pause", lx_cmd_control, 1, 0, "JOB",
         "pause a job (within its current iteration)",
         "Examples:\n  luxrad pause 4\n"},
        {"resume", lx_cmd_control, 1, 0, "JOB",
         "resume a paused job toward its last target",
         "Examples:\n  luxrad resume 4\n"},
        {"cancel", lx_cmd_control, 1, 0, "JOB", "cancel a job (terminal)",
         "Examples:\n  luxrad cancel 4\n"},
        {"set", lx_cmd_set, 1, LX_ENGINE_BIT(eps), "JOB --eps E",
         "change a job's refinement threshold",
         "Applied before the job's next iteration.\n\nExamples:\n  luxrad "
         "set 4 --eps 5e-4\n"},
        {"delete-job", lx_cmd_delete, 1, 0, "JOB",
         "forget a job that is not running",
         "Examples:\n  luxrad delete-job 4\n"},
        {"delete-scene", lx_cmd_delete, 1, 0, "SCENE",
         "delete a scene no job uses", "Examples:\n  luxrad delete-scene 1\n"},
        {"info", lx_cmd_info, 1, 0, "JOB",
         "one job: state, options, latest statistics",
         "Examples:\n  luxrad info 4\n  luxrad info 4 --json\n"},
        {"sensor-add", lx_cmd_sensor_add, 2, LX_BIT(AT) | LX_BIT(NORMAL),
         "JOB NAME --at X,Y,Z [--normal X,Y,Z]",
         "add a named illuminance sensor to a job (Modbus)",
         "The daemon evaluates the sensor after every iteration, as luxrad "
         "query\n--points would, and publishes its lux in a Modbus sensor "
         "slot\n(daemon/server/modbus/MODBUS.md). The normal is that of the "
         "surface "
         "the sensor\nlies on (upward by default, for a work plane). The "
         "sensor is stored with\nthe job: it survives a daemon restart and "
         "goes when the job is deleted.\nNAME is 1..63 bytes.\n\nExamples:\n"
         "  luxrad sensor-add 4 desk --at 2.0,0.75,1.5\n"
         "  luxrad sensor-add 4 wall --at 0,1.2,1.5 --normal 1,0,0\n"},
        {"sensors", lx_cmd_sensors, 1, 0, "JOB",
         "a job's sensors: source, Modbus slot, latest lux",
         "source is scene (a glTF node named sensor:<name>) or added "
         "(sensor-add);\nlux and iteration are ? before the first value.\n\n"
         "Examples:\n  luxrad sensors 4\n  luxrad sensors 4 --json\n"},
        {"status", lx_cmd_status, 0, 0, "",
         "daemon: uptime, jobs by state, memory",
         "Examples:\n  luxrad status\n"},
        {"shutdown", lx_cmd_shutdown, 0, 0, "",
         "checkpoint every job and stop the daemon",
         "Examples:\n  luxrad shutdown\n"},
};

#define NCOMMANDS (sizeof commands / sizeof commands[0])

/* ------------------------------------------------------------------ help */

/* One option's help line; an engine option's shows the daemon's default
 * (a job's accuracy moves the ones it sets). */
static void print_option(lx_opt o)
{
	char def[64] = "";

	if (o >= LX_OPT_ENGINE &&
	    rad_option_defs[o - LX_OPT_ENGINE].type != RAD_OPT_BOOL)
		rad_option_default_text(&rad_option_defs[o - LX_OPT_ENGINE],
		                        def, sizeof def);
	rp_help_row(stdout, o == LX_OPT_OUTPUT ? 'o' : 0, lx_opt_table[o].name,
	            lx_opt_table[o].meta, lx_opt_table[o].help, def);
}

static void print_common(void)
{
	printf("\nCommon options:\n");
	print_option(LX_OPT_CONNECT);
	print_option(LX_OPT_TOKEN_FILE);
	print_option(LX_OPT_TLS_CA);
	print_option(LX_OPT_JSON);
	print_option(LX_OPT_HELP);
}

static void help_main(void)
{
	printf("Usage: luxrad [options] COMMAND [arguments]\n\n"
	       "The command-line client of luxradd, the radiosity lighting "
	       "daemon.\n\nCommands:\n");
	for (size_t i = 0; i < NCOMMANDS; i++)
		printf("  %-13s %s\n", commands[i].name, commands[i].summary);
	print_common();
	printf("\n'luxrad COMMAND --help' shows a command's options and "
	       "examples.\n\n"
	       "Address (--connect, else $LUXRAD_CONNECT, else %s):\n"
	       "  HOST:PORT, HOST (port %d), [V6]:PORT, tcp:HOST:PORT,\n"
	       "  unix:PATH or a path starting with '/' or '.' (Unix "
	       "socket);\n"
	       "  tls://HOST:PORT: TLS, the daemon's certificate checked "
	       "against\n  --tls-ca FILE, else $LUXRAD_TLS_CA, else the "
	       "system's CAs, and HOST.\n"
	       "Token (sent when given): --token-file FILE, else "
	       "$LUXRAD_TOKEN_FILE,\nelse $LUXRAD_TOKEN. A daemon listening "
	       "beyond loopback requires one.\n\n"
	       "Exit status:\n"
	       "  0  success\n"
	       "  1  the daemon returned an error (stderr: \"luxrad: <code>: "
	       "<message>\"),\n     or the output file could not be written\n"
	       "  2  usage error: bad option or value, unreadable or malformed "
	       "input file\n"
	       "  3  cannot connect to the daemon, or the connection was lost\n"
	       "  4  run --wait / watch: the job failed or was cancelled\n\n"
	       "Examples:\n"
	       "  luxrad submit scenes/cornell.gltf --solve --eps 1e-3\n"
	       "  luxrad run 1 --wait\n"
	       "  luxrad query 1 --points points.txt\n"
	       "  luxrad export 1 -o lit.glb\n"
	       "  LUXRAD_CONNECT=unix:/run/luxradd/luxradd.sock luxrad "
	       "status\n",
	       LX_DEFAULT_CONNECT, RP_DEFAULT_PORT);
}

static void help_command(const cmd_def *c)
{
	printf("Usage: luxrad %s%s%s\n\n%s.\n", c->name, c->usage[0] ? " " : "",
	       c->usage, c->summary);
	if (c->opts) {
		printf("\nOptions:\n");
		for (int o = 0; o < LX_OPT_COUNT; o++)
			if (c->opts & ((uint64_t)1 << o))
				print_option((lx_opt)o);
	}
	print_common();
	printf("\n%s", c->text);
}

/* -------------------------------------------------------------- parsing */

static int find_option(const char *name, size_t len)
{
	for (int o = 0; o < LX_OPT_COUNT; o++)
		if (strlen(lx_opt_table[o].name) == len &&
		    !strncmp(lx_opt_table[o].name, name, len))
			return o;
	return -1;
}

/*
 * Parse argv[*i] (an option) with its value; allowed is the mask of
 * options accepted here.  Returns 0 or a usage error.
 */
static int parse_option(lx_ctx *cx, int argc, char **argv, int *i,
                        uint64_t allowed)
{
	const char *a = argv[*i], *name, *eq, *value = NULL;
	int o;

	if (!strcmp(a, "-o") || !strcmp(a, "-h")) {
		o = a[1] == 'o' ? LX_OPT_OUTPUT : LX_OPT_HELP;
	} else {
		name = a + 2;
		eq = strchr(name, '=');
		o = find_option(name, eq ? (size_t)(eq - name) : strlen(name));
		if (o < 0 || a[1] != '-')
			return lx_usage_error(cx, "unknown option '%s'", a);
		if (eq)
			value = eq + 1;
	}
	if (!(allowed & ((uint64_t)1 << o)) && cx->cmd)
		return lx_usage_error(cx, "option --%s does not apply to '%s'",
		                      lx_opt_table[o].name, cx->cmd);
	if (!(allowed & ((uint64_t)1 << o)))
		return lx_usage_error(cx, "option --%s must follow the command",
		                      lx_opt_table[o].name);
	if (lx_opt_table[o].arg && !value) {
		if (*i + 1 >= argc)
			return lx_usage_error(cx,
			                      "option --%s needs a value "
			                      "(%s)",
			                      lx_opt_table[o].name,
			                      lx_opt_table[o].meta);
		value = argv[++*i];
	} else if (!lx_opt_table[o].arg && value) {
		return lx_usage_error(cx, "option --%s takes no value",
		                      lx_opt_table[o].name);
	}
	cx->val[o] = value;
	cx->given[o]++;
	if (o == LX_OPT_SURFACE)
		cx->surfaces[cx->nsurfaces++] = value;
	if (o == LX_OPT_LUMINAIRE)
		cx->luminaires[cx->nluminaires++] = value;
	return 0;
}

static const cmd_def *find_command(const char *name)
{
	for (size_t i = 0; i < NCOMMANDS; i++)
		if (!strcmp(commands[i].name, name))
			return &commands[i];
	return NULL;
}

/* Collect the command's options and positional arguments. */
static int parse_command_line(lx_ctx *cx, const cmd_def *c, int argc,
                              char **argv, int first)
{
	int only_pos = 0;

	for (int i = first; i < argc; i++) {
		const char *a = argv[i];
		if (!only_pos && !strcmp(a, "--")) {
			only_pos = 1;
		} else if (!only_pos && a[0] == '-' && a[1] != '\0') {
			int rc = parse_option(cx, argc, argv, &i,
			                      GLOBAL_OPTS | c->opts);
			if (rc)
				return rc;
		} else {
			cx->pos[cx->npos++] = argv[i];
		}
	}
	if (cx->given[LX_OPT_HELP])
		return 0;
	if (cx->npos != c->npos) {
		if (cx->npos < c->npos)
			return lx_usage_error(cx,
			                      "missing argument: luxrad %s "
			                      "%s",
			                      c->name, c->usage);
		return lx_usage_error(cx, "unexpected argument '%s'",
		                      cx->pos[c->npos]);
	}
	return 0;
}

/* Parse, then run the command; returns the exit status. */
static int dispatch(lx_ctx *cx, int argc, char **argv)
{
	const cmd_def *c = NULL;
	int i, rc;

	for (i = 1; i < argc && argv[i][0] == '-' && argv[i][1]; i++) {
		if (!strcmp(argv[i], "--version")) {
			printf("luxrad %s (protocol %d)\n", LX_VERSION,
			       RP_VERSION);
			return LX_EXIT_OK;
		}
		if ((rc = parse_option(cx, argc, argv, &i, GLOBAL_OPTS)))
			return rc;
	}
	if (i == argc) {
		if (cx->given[LX_OPT_HELP]) {
			help_main();
			return LX_EXIT_OK;
		}
		return lx_usage_error(NULL, "no command given");
	}
	if (!strcmp(argv[i], "help")) {
		c = i + 1 < argc ? find_command(argv[i + 1]) : NULL;
		if (i + 1 < argc && !c)
			return lx_usage_error(NULL, "unknown command '%s'",
			                      argv[i + 1]);
		c ? help_command(c) : help_main();
		return LX_EXIT_OK;
	}
	if (!(c = find_command(argv[i])))
		return lx_usage_error(NULL, "unknown command '%s'", argv[i]);
	cx->cmd = c->name;
	if ((rc = parse_command_line(cx, c, argc, argv, i + 1)))
		return rc;
	if (cx->given[LX_OPT_HELP]) {
		help_command(c);
		return LX_EXIT_OK;
	}
	cx->json = cx->given[LX_OPT_JSON] > 0;
	return c->fn(cx);
}

int main(int argc, char **argv)
{
	lx_ctx cx;
	int rc;

	memset(&cx, 0, sizeof cx);
	cx.pos = calloc((size_t)argc + 1, sizeof *cx.pos);
	cx.surfaces = calloc((size_t)argc + 1, sizeof *cx.surfaces);
	cx.luminaires = calloc((size_t)argc + 1, sizeof *cx.luminaires);
	if (!cx.pos || !cx.surfaces || !cx.luminaires) {
		free(cx.pos);
		free(cx.surfaces);
		free(cx.luminaires);
		fprintf(stderr, "luxrad: out of memory\n");
		return LX_EXIT_USAGE;
	}
	rc = dispatch(&cx, argc, argv);
	lx_close(&cx);
	free(cx.pos);
	free(cx.surfaces);
	free(cx.luminaires);
	if (fflush(stdout) != 0 && rc == LX_EXIT_OK) {
		fprintf(stderr, "luxrad: cannot write to stdout\n");
		rc = LX_EXIT_DAEMON;
	}
	return rc;
}
