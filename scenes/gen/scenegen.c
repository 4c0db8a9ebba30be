/*
 * scenegen.c -- luxrad-scenegen, the parametric scene generator: its kinds
 * and options, the command line, and the output.
 *
 * Writes the scenes luxrad is tested and measured on as glTF 2.0 (GLB, or
 * .gltf JSON with embedded buffers) through sio_write: the Cornell box
 * from its published measurements, a small office, analytic test boxes and
 * rooms, random "field" scenes sized by triangle count, and synthetic
 * stand-ins for the study scenes of the report the engine follows (herd,
 * empty / full / very bright / grand hall; docs/ALGORITHM.md §9.1).
 *
 * Everything is deterministic: randomness comes from our own splitmix64
 * generator with fixed default seeds, never rand(), so a scene regenerated
 * anywhere is the same scene and measurements stay comparable.
 *
 * The parts: gen.h (what they share: geometry, random numbers, the scene
 * and the parameters), build.c (the scene builder and its shapes),
 * families.c (one builder a kind), and this file.
 *
 * DESIGN
 *  - The command line is table-driven (kinds[] and opts[]): --help and the
 *    check that an option applies to the chosen kind come from the tables.
 *  - A failed allocation while building is only noted (sg_oom, build.c);
 *    write_scene reports it once, before writing anything.
 */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gen.h"
#include "sceneio.h"

#define PROG "luxrad-scenegen"

/* ---------------------------------------------------------- kind table */

enum kind_id {
	KD_CORNELL,
	KD_OFFICE,
	KD_BOX,
	KD_ROOM,
	KD_OBSTRUCTED,
	KD_SLABROOM,
	KD_THINLUM,
	KD_COVE,
	KD_FIELD,
	KD_HERD,
	KD_HALL_EMPTY,
	KD_HALL_FULL,
	KD_HALL_BRIGHT,
	KD_HALL_GRAND,
	NKINDS
};

typedef struct kind {
	const char *name;
	void (*build)(scene *sc, const params *p);
	int report; /* the report's polygon count (study scenes), else 0 */
	const char *help;
} kind;

/* clang-format off */
static const kind kinds[NKINDS] = {
	[KD_CORNELL] = {"cornell", sg_build_cornell, 0,
		"the published Cornell Box, 0.556 x 0.549 x 0.559 m: 5 walls,\n"
		"2 blocks, a 3000 cd/m2 light 0.5 mm below the ceiling.\n"
		"32 triangles -> 21 polygons (18 with --square), 4 materials"},
	[KD_OFFICE] = {"office", sg_build_office, 0,
		"a 4 x 3 x 2.8 m office: window opening, desk, chair, two\n"
		"0.6 m ceiling panels of 2000 cd/m2, a 100 cd desk lamp.\n"
		"86 triangles -> 43 polygons, 6 materials, 1 point light"},
	[KD_BOX] = {"box", sg_build_box, 0,
		"a closed box seen from inside, every face emitting L and\n"
		"reflecting rho: B = pi L / (1 - rho) everywhere.\n"
		"12 N^2 triangles -> 6 N^2 polygons (N = --subdiv)"},
	[KD_ROOM] = {"room", sg_build_room, 0,
		"a black 4 x 4 x 3 m room lit by one 1 m2 ceiling panel\n"
		"of 1000 cd/m2. 14 triangles -> 7 polygons"},
	[KD_OBSTRUCTED] = {"obstructed", sg_build_obstructed, 0,
		"the room with a black plate under part of its panel:\n"
		"direct light through an obstruction. 26 triangles ->\n"
		"13 polygons"},
	[KD_SLABROOM] = {"slabroom", sg_build_slabroom, 0,
		"a grey 4 x 4 x 3 m room whose floor, ceiling and walls\n"
		"run 0.3 m past its corners, as architectural exports write\n"
		"them; a 1 m2 panel 8 cm under the ceiling. 14 triangles"},
	[KD_THINLUM] = {"thinlum", sg_build_thinlum, 0,
		"a grey 4 x 4 x 3 m room lit by a 0.75 m square luminaire\n"
		"1 cm deep under its ceiling, all five faces emitting\n"
		"1000 cd/m2. 22 triangles -> 11 polygons"},
	[KD_COVE] = {"cove", sg_build_cove, 0,
		"the thinlum room with the luminaire's bottom black: only\n"
		"its 1 cm sides emit. 22 triangles -> 11 polygons"},
	[KD_FIELD] = {"field", sg_build_field, 0,
		"random boxes, spheres and cylinders on a ground plane\n"
		"under emissive panels and point lights (clustering)"},
	[KD_HERD] = {"herd", sg_build_herd, HERD_REPORT,
		"report fig. 3.1: 65 animals on a 60 x 40 m ground, one\n"
		"sky source. 43,684 triangles -> 41,602 polygons\n"
		"(report: 43,464 polygons)"},
	[KD_HALL_EMPTY] = {"hall-empty", sg_build_hall_empty, 94,
		"report fig. 3.2: a 24 x 16 x 6 m hall, 6 pillars, a door,\n"
		"16 ceiling sources. 94 triangles -> 47 polygons\n"
		"(report: 94 polygons)"},
	[KD_HALL_FULL] = {"hall-full", sg_build_hall_full, 40886,
		"report fig. 3.3: the empty hall with tables, chairs, fruit\n"
		"and shelves. 40,634 triangles -> 27,885 polygons\n"
		"(report: 40,886 polygons)"},
	[KD_HALL_BRIGHT] = {"hall-bright", sg_build_hall_bright, 84,
		"report fig. 4.6: 4 pillars, 4 windows, 16 sources of\n"
		"30,000 cd/m2. 84 triangles -> 42 polygons\n"
		"(report: 84 polygons)"},
	[KD_HALL_GRAND] = {"hall-grand", sg_build_hall_grand, 288000,
		"report fig. 5.2: a furnished 48 x 32 x 10 m hall.\n"
		"291,664 triangles -> 258,616 polygons\n"
		"(report: 288,000 polygons)"},
};
/* clang-format on */

/* ------------------------------------------------------- option table */

enum opt_type { T_FLAG, T_STR, T_NUM, T_VEC3, T_FORMAT, T_SEED };

typedef struct opt {
	const char *name;
	char shortopt; /* 0 = long only */
	enum opt_type type;
	size_t off;     /* where in params the value goes */
	unsigned kinds; /* bit per kind_id it applies to */
	double lo, hi;  /* T_NUM / T_VEC3 range */
	bool integer;   /* T_NUM: must be a whole number */
	const char *arg, *help;
} opt;

#define K(id) (1u << (id))
#define K_ALL ((1u << NKINDS) - 1)
/* The kinds that draw random numbers. */
#define K_SEEDED (K(KD_FIELD) | K(KD_HERD) | K(KD_HALL_FULL) | K(KD_HALL_GRAND))
#define OFF(f) offsetof(params, f)

/* clang-format off */
static const opt opts[NOPTS] = {
	[O_OUTPUT] = {"output", 'o', T_STR, OFF(out), K_ALL, 0, 0, false,
		"FILE", "output file (required)"},
	[O_FORMAT] = {"format", 0, T_FORMAT, OFF(fmt), K_ALL, 0, 0, false,
		"glb|gltf", "GLB, or glTF JSON with data: URIs\n"
		"(default: JSON if FILE ends in .gltf)"},
	[O_SEED] = {"seed", 0, T_SEED, OFF(seed), K_SEEDED, 0, 0, false,
		"N", "random seed (default: fixed per kind)"},
	[O_SQUARE] = {"square", 0, T_FLAG, OFF(square), K(KD_CORNELL), 0, 0,
		false, NULL, "move the out-of-square walls to x = 556\n"
		"mm: all 5 walls become parallelograms"},
	[O_SUN] = {"sun", 0, T_NUM, OFF(sun_lux), K(KD_OFFICE), 0, 2e5, false,
		"LUX", "add a sun through the window, 35 degrees\n"
		"high (clear sky: about 80000)"},
	[O_SIZE] = {"size", 0, T_VEC3, OFF(size), K(KD_BOX), 1e-6, 1e6, false,
		"W,H,D", "box size, metres (default 1,1,1)"},
	[O_RHO] = {"rho", 0, T_NUM, OFF(rho), K(KD_BOX) | K(KD_ROOM) | K(KD_OBSTRUCTED) | K(KD_SLABROOM), 0, 0.999,
		false, "R", "reflectance (default: box, slabroom 0.5; room 0)"},
	[O_EMIT] = {"emit", 0, T_NUM, OFF(emit), K(KD_BOX), 0, 1e9, false,
		"L", "luminance of the faces, cd/m2 (def. 100)"},
	[O_SUBDIV] = {"subdiv", 0, T_NUM, OFF(subdiv), K(KD_BOX), 1, 512, true,
		"N", "quads per face edge (default 1)"},
	[O_SCALE] = {"scale", 0, T_NUM, OFF(scale), K(KD_ROOM) | K(KD_OBSTRUCTED), 1e-6, 1e6,
		false, "F", "multiply every coordinate (default 1)"},
	[O_OBJECTS] = {"objects", 0, T_NUM, OFF(objects), K(KD_FIELD), 1, 1e6,
		true, "N", "number of objects (default 100)"},
	[O_TPO] = {"tris-per-object", 0, T_NUM, OFF(tris_per_object),
		K(KD_FIELD), 10, 1e5, true, "T",
		"about T triangles per object (def. 200)"},
	[O_TRIANGLES] = {"triangles", 0, T_NUM, OFF(triangles), K(KD_FIELD),
		1, 5e7, true, "N", "add objects until there are at least N\n"
		"triangles (overrides --objects)"},
	[O_PANELS] = {"panels", 0, T_NUM, OFF(panels), K(KD_FIELD), 0, 1024,
		true, "K", "K emissive 1.5 m panels 6 m up, 5000\n"
		"cd/m2 (default 4)"},
	[O_POINTS] = {"points", 0, T_NUM, OFF(points), K(KD_FIELD), 0, 1024,
		true, "P", "P point lights of 500 cd 3 m up (def. 0)"},
	[O_HELP] = {"help", 'h', T_FLAG, OFF(help), K_ALL, 0, 0, false,
		NULL, "show this help"},
};
/* clang-format on */

/* ------------------------------------------------------- command line */

static void put_indented(FILE *f, const char *s, int indent)
{
	for (; *s; s++) {
		fputc(*s, f);
		if (*s == '\n')
			fprintf(f, "%*s", indent, "");
	}
	fputc('\n', f);
}

static void print_help(FILE *f)
{
	fputs("usage: " PROG " KIND [options] -o FILE\n\n"
	      "Writes a deterministic glTF 2.0 scene (metres, +Y up) and "
	      "prints one\nsummary line to stderr: triangles, polygons after "
	      "the engine's\nparallelogram merging, materials, lights, "
	      "bounds.\n\nKinds:\n",
	      f);
	for (int i = 0; i < NKINDS; i++) {
		fprintf(f, "  %-12s ", kinds[i].name);
		put_indented(f, kinds[i].help, 15);
	}
	fputs("\nOptions [kinds they apply to]:\n", f);
	for (int i = 0; i < NOPTS; i++) {
		const opt *o = &opts[i];
		char head[64];
		snprintf(head, sizeof(head), "%c%c%c --%s %s",
		         o->shortopt ? '-' : ' ',
		         o->shortopt ? o->shortopt : ' ',
		         o->shortopt ? ',' : ' ', o->name,
		         o->arg ? o->arg : "");
		fprintf(f, "  %-28s ", head);
		put_indented(f, o->help, 31);
		if (o->kinds == K_ALL)
			continue;
		fprintf(f, "%31s[", "");
		for (int k = 0, first = 1; k < NKINDS; k++)
			if (o->kinds & K(k)) {
				fprintf(f, "%s%s", first ? "" : " ",
				        kinds[k].name);
				first = 0;
			}
		fputs("]\n", f);
	}
	fputs("\nExit status: 0 ok, 1 failure (memory, export, I/O), 2 usage "
	      "error.\n",
	      f);
}

static int usage_error(const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fputs(PROG ": ", stderr);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fputs("\nTry '" PROG " --help'.\n", stderr);
	return 2;
}

/* Bounds are written !(in range) so that NaN fails them. */
static bool parse_num(const char *s, const opt *o, double *out,
                      const char **rest)
{
	char *end;
	errno = 0;
	double v = strtod(s, &end);
	if (end == s || errno || !(v >= o->lo && v <= o->hi) ||
	    (o->integer && v != floor(v)))
		return false;
	*out = v;
	*rest = end;
	return true;
}

static bool parse_value(const opt *o, const char *s, params *p)
{
	char *dst = (char *)p + o->off;
	const char *rest = s;
	switch (o->type) {
	case T_FLAG:
		*(bool *)dst = true;
		return true;
	case T_STR:
		*(const char **)dst = s;
		return *s != '\0';
	case T_NUM:
		return parse_num(s, o, (double *)dst, &rest) && !*rest;
	case T_VEC3:
		for (int i = 0; i < 3; i++) {
			if (!parse_num(rest, o, (double *)dst + i, &rest))
				return false;
			if (i < 2 && *rest++ != ',')
				return false;
		}
		return !*rest;
	case T_FORMAT:
		*(int *)dst = !strcmp(s, "glb")    ? SIO_FORMAT_GLB
		              : !strcmp(s, "gltf") ? SIO_FORMAT_JSON
		                                   : -1;
		return *(int *)dst >= 0;
	case T_SEED: {
		char *end;
		errno = 0;
		*(uint64_t *)dst = strtoull(s, &end, 0);
		return end != s && !*end && !errno && *s != '-';
	}
	}
	return false;
}

static bool ends_with(const char *s, const char *suffix)
{
	size_t n = strlen(s), m = strlen(suffix);
	return n >= m && !strcmp(s + n - m, suffix);
}

/* Returns -1 to go on, else the exit code (0 after --help, 2 on misuse). */
static int parse_args(int argc, char **argv, params *p, const kind **kp)
{
	struct option lo[NOPTS + 1];
	memset(lo, 0, sizeof(lo));
	for (int i = 0; i < NOPTS; i++) {
		lo[i].name = opts[i].name;
		lo[i].has_arg = opts[i].type == T_FLAG ? no_argument
		                                       : required_argument;
		lo[i].val = opts[i].shortopt ? opts[i].shortopt : 256 + i;
	}
	memset(p, 0, sizeof(*p));
	p->fmt = -1;
	for (int c; (c = getopt_long(argc, argv, "o:h", lo, NULL)) != -1;) {
		int id = c == 'o' ? O_OUTPUT : c == 'h' ? O_HELP : c - 256;
		if (id < 0 || id >= NOPTS) /* getopt has said what */
			return usage_error("bad command line");
		if (!parse_value(&opts[id], optarg, p))
			return usage_error("bad value '%s' for --%s (%s)",
			                   optarg, opts[id].name, opts[id].arg);
		p->set |= 1u << id;
	}
	if (p->help) {
		print_help(stdout);
		return 0;
	}
	if (optind != argc - 1)
		return usage_error(optind < argc ? "one KIND expected"
		                                 : "no KIND given");
	int k = 0;
	while (k < NKINDS && strcmp(argv[optind], kinds[k].name))
		k++;
	if (k == NKINDS)
		return usage_error("unknown kind '%s'", argv[optind]);
	for (int i = 0; i < NOPTS; i++)
		if (GIVEN(p, i) && !(opts[i].kinds & K(k)))
			return usage_error("--%s does not apply to kind '%s'",
			                   opts[i].name, kinds[k].name);
	if (!p->out)
		return usage_error("no output file (-o FILE)");
	if (p->fmt < 0)
		p->fmt = ends_with(p->out, ".gltf") ? SIO_FORMAT_JSON
		                                    : SIO_FORMAT_GLB;
	*kp = &kinds[k];
	return -1;
}

/* -------------------------------------------------------------- output */

static int fail(const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	fputs(PROG ": error: ", stderr);
	vfprintf(stderr, fmt, ap);
	va_end(ap);
	fputc('\n', stderr);
	return 1;
}

static bool same_mat(const mat *a, const mat *b)
{
	return a->rho[0] == b->rho[0] && a->rho[1] == b->rho[1] &&
	       a->rho[2] == b->rho[2] && a->lum == b->lum;
}

/* One line: what the engine will see, so runs can be checked at a glance. */
static void print_summary(const scene *sc, const kind *k, const params *p,
                          size_t bytes)
{
	size_t tris = 0, quads = 0, mats = 0, emitting = 0;
	double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3];
	for (int a = 0; a < 3; a++)
		hi[a] = -INFINITY;
	for (size_t i = 0; i < sc->nmesh; i++) {
		const mesh *me = sc->mesh[i];
		size_t j = 0;
		while (j < i && !same_mat(&sc->mesh[j]->m, &me->m))
			j++;
		mats += j == i;
		emitting += me->m.lum > 0;
		tris += me->ni / 3;
		quads += me->quads;
		for (size_t v = 0; v < 3 * me->nv; v++) {
			lo[v % 3] = fmin(lo[v % 3], me->pos[v]);
			hi[v % 3] = fmax(hi[v % 3], me->pos[v]);
		}
	}
	for (size_t i = 0; i < sc->nlight; i++)
		for (int a = 0;
		     a < 3 && sc->light[i].kind != RAD_LIGHT_DIRECTIONAL; a++) {
			lo[a] = fmin(lo[a], sc->light[i].position[a]);
			hi[a] = fmax(hi[a], sc->light[i].position[a]);
		}
	char report[64] = "";
	if (k->report)
		snprintf(report, sizeof(report), " (report: %d, %+.1f%%)",
		         k->report, 100.0 * ((double)tris / k->report - 1));
	fprintf(stderr,
	        PROG ": %s: %zu triangles -> %zu polygons%s, %zu meshes, "
	             "%zu materials, %zu lights, %zu emitting meshes, bounds "
	             "(%g %g %g)..(%g %g %g) m, %zu bytes %s -> %s\n",
	        k->name, tris, tris - quads, report, sc->nmesh, mats,
	        sc->nlight, emitting, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2],
	        bytes, p->fmt == SIO_FORMAT_JSON ? "gltf" : "glb", p->out);
}

static int write_file(const char *path, const void *bytes, size_t n)
{
	FILE *f = fopen(path, "wb");
	if (!f)
		return fail("cannot create '%s': %s", path, strerror(errno));
	bool ok = fwrite(bytes, 1, n, f) == n;
	int saved = errno;
	if (fclose(f) != 0 && ok) {
		ok = false;
		saved = errno;
	}
	if (ok)
		return 0;
	remove(path); /* never leave a truncated scene behind */
	return fail("cannot write '%s': %s", path, strerror(saved));
}

static int write_scene(const scene *sc, const params *p, const kind *k)
{
	if (sg_oom)
		return fail("out of memory while building '%s'", k->name);
	sio_mesh *gm = calloc(sc->nmesh ? sc->nmesh : 1, sizeof(*gm));
	if (!gm)
		return fail("out of memory");
	for (size_t i = 0; i < sc->nmesh; i++) {
		const mesh *me = sc->mesh[i];
		double e = me->m.lum > 0 ? 1 : 0;
		gm[i] = (sio_mesh){.name = me->name,
		                   .position = me->pos,
		                   .index = me->idx,
		                   .nvertices = me->nv,
		                   .nindices = me->ni,
		                   .base_color = {me->m.rho[0], me->m.rho[1],
		                                  me->m.rho[2]},
		                   .emissive = {e, e, e},
		                   .emissive_strength =
		                           me->m.lum > 0 ? me->m.lum : 1};
	}
	void *bytes = NULL;
	size_t n = 0;
	rad_error err = {0};
	rad_status st = sio_write(gm, sc->nmesh, sc->light, sc->nlight,
	                          (sio_format)p->fmt, &bytes, &n, &err);
	free(gm);
	if (st != RAD_OK)
		return fail("glTF export failed (%s): %s", rad_status_name(st),
		            err.msg);
	int rc = write_file(p->out, bytes, n);
	free(bytes);
	if (rc == 0)
		print_summary(sc, k, p, n);
	return rc;
}

int main(int argc, char **argv)
{
	params p;
	const kind *k = NULL;
	int rc = parse_args(argc, argv, &p, &k);
	if (rc >= 0)
		return rc;
	scene sc = {0};
	k->build(&sc, &p);
	sg_drop_empty_meshes(&sc);
	rc = write_scene(&sc, &p, k);
	sg_scene_free(&sc);
	return rc;
}
