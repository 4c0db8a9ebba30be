/*
 * scenegen.c -- luxrad-scenegen, the parametric scene generator.
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
 * DESIGN
 *  - Scenes are built in world coordinates (metres, +Y up) into a list of
 *    meshes with one material each; every mesh becomes one glTF mesh and
 *    node, so the engine sees object names.
 *  - A quad is always written as two triangles sharing the diagonal a-c,
 *    with shared vertices: the engine merges such a pair back into one
 *    polygon when it is an exact parallelogram (same material and node).
 *    The builder counts the parallelograms it writes so that the summary
 *    line can report the polygon count the engine will see.
 *  - The command line is table-driven (kinds[] and opts[]): --help and the
 *    check that an option applies to the chosen kind come from the tables.
 *  - Allocation failure is sticky: the first one sets `oom`, later appends
 *    do nothing, and main reports it once before writing anything.
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

#include "sceneio.h"

#define PROG "luxrad-scenegen"
#define PI 3.14159265358979323846

/* ------------------------------------------------------------- geometry */

typedef struct p3 {
	double x, y, z;
} p3;

static p3 P(double x, double y, double z)
{
	p3 r = {x, y, z};
	return r;
}

static p3 add(p3 a, p3 b)
{
	return P(a.x + b.x, a.y + b.y, a.z + b.z);
}

static p3 sub(p3 a, p3 b)
{
	return P(a.x - b.x, a.y - b.y, a.z - b.z);
}

static p3 mul(p3 a, double s)
{
	return P(a.x * s, a.y * s, a.z * s);
}

static double len(p3 a)
{
	return sqrt(a.x * a.x + a.y * a.y + a.z * a.z);
}

/* Proper rotation about +Y (keeps counter-clockwise faces CCW). */
static p3 rot_y(p3 v, double yaw)
{
	double c = cos(yaw), s = sin(yaw);
	return P(c * v.x + s * v.z, v.y, -s * v.x + c * v.z);
}

/* splitmix64: tiny, fast, and the same sequence on every platform. */
static uint64_t rng_next(uint64_t *s)
{
	uint64_t z = (*s += 0x9E3779B97F4A7C15u);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9u;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBu;
	return z ^ (z >> 31);
}

static double rng_range(uint64_t *s, double lo, double hi)
{
	return lo + (hi - lo) * (double)(rng_next(s) >> 11) * 0x1.0p-53;
}

/* --------------------------------------------------------- scene builder */

typedef struct mat {
	double rho[3]; /* diffuse reflectance, linear RGB */
	double lum;    /* luminance of a white Lambertian emitter, cd/m2 */
} mat;

typedef struct mesh {
	char name[48]; /* glTF node and mesh name */
	mat m;         /* the one material of all its triangles */
	float *pos;    /* 3 floats per vertex, world space */
	uint32_t *idx; /* 3 per triangle, counter-clockwise from the front */
	size_t nv, cap_v, ni, cap_i;
	size_t quads; /* exact parallelograms written as triangle pairs */
} mesh;

typedef struct scene {
	mesh **mesh; /* owned */
	size_t nmesh, cap_mesh;
	rad_light_desc *light; /* names point to string literals */
	size_t nlight, cap_light;
} scene;

/* Sticky allocation failure; see the DESIGN note. */
static bool oom;
/* Where appends go after a failed mesh_new: they all fail on `oom`. */
static mesh oom_sink;

/* buf with room for `need` elements (maybe moved), or NULL on failure. */
static void *grow(void *buf, size_t *cap, size_t need, size_t elem)
{
	if (oom)
		return NULL;
	if (need <= *cap)
		return buf;
	size_t ncap = *cap ? *cap : 64;
	while (ncap < need)
		ncap *= 2;
	void *nb = realloc(buf, ncap * elem);
	if (!nb) {
		oom = true;
		return NULL;
	}
	*cap = ncap;
	return nb;
}

static mat grey(double rho)
{
	mat m = {{rho, rho, rho}, 0};
	return m;
}

static mat rgb(double r, double g, double b)
{
	mat m = {{r, g, b}, 0};
	return m;
}

/* Our emitters are pure sources (reflectance 0): their radiosity is exactly
 * their exitance pi * L, which keeps analytic checks simple. */
static mat emitter(double lum)
{
	mat m = {{0, 0, 0}, lum};
	return m;
}

static mesh *mesh_new(scene *sc, mat m, const char *fmt, ...)
{
	mesh **nm = grow(sc->mesh, &sc->cap_mesh, sc->nmesh + 1, sizeof(*nm));
	mesh *me = nm ? calloc(1, sizeof(*me)) : NULL;
	if (nm)
		sc->mesh = nm;
	if (!me) {
		oom = true;
		return &oom_sink;
	}
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(me->name, sizeof(me->name), fmt, ap);
	va_end(ap);
	me->m = m;
	sc->mesh[sc->nmesh++] = me;
	return me;
}

static void add_light(scene *sc, const rad_light_desc *l)
{
	rad_light_desc *nl =
	        grow(sc->light, &sc->cap_light, sc->nlight + 1, sizeof(*nl));
	if (!nl)
		return;
	sc->light = nl;
	sc->light[sc->nlight++] = *l;
}

static void point_light(scene *sc, const char *name, p3 at, double cd)
{
	rad_light_desc l = {.kind = RAD_LIGHT_POINT,
	                    .position = {at.x, at.y, at.z},
	                    .intensity = {cd, cd, cd},
	                    .name = name};
	add_light(sc, &l);
}

static uint32_t vert(mesh *me, p3 p)
{
	float *np = grow(me->pos, &me->cap_v, me->nv + 1, 3 * sizeof(float));
	if (!np)
		return 0;
	me->pos = np;
	float *v = me->pos + 3 * me->nv;
	v[0] = (float)p.x;
	v[1] = (float)p.y;
	v[2] = (float)p.z;
	return (uint32_t)me->nv++;
}

static void tri(mesh *me, uint32_t a, uint32_t b, uint32_t c)
{
	uint32_t *ni = grow(me->idx, &me->cap_i, me->ni + 3, sizeof(*ni));
	if (!ni)
		return;
	me->idx = ni;
	ni[me->ni++] = a;
	ni[me->ni++] = b;
	ni[me->ni++] = c;
}

/* Quad a b c d, counter-clockwise seen from its front: triangles abc, acd. */
static void quad(mesh *me, p3 a, p3 b, p3 c, p3 d)
{
	uint32_t i = vert(me, a), j = vert(me, b), k = vert(me, c);
	uint32_t l = vert(me, d);
	tri(me, i, j, k);
	tri(me, i, k, l);
	double skew = len(sub(add(a, c), add(b, d)));
	if (skew <= 1e-9 * (len(sub(b, a)) + len(sub(d, a))))
		me->quads++;
}

/* Parallelogram o, o+u, o+u+v, o+v cut into n x n cells sharing vertices. */
static void grid(mesh *me, p3 o, p3 u, p3 v, int n)
{
	uint32_t base = (uint32_t)me->nv;
	for (int j = 0; j <= n; j++)
		for (int i = 0; i <= n; i++)
			vert(me, add(o, add(mul(u, (double)i / n),
			                    mul(v, (double)j / n))));
	for (int j = 0; j < n; j++)
		for (int i = 0; i < n; i++) {
			uint32_t a = base + (uint32_t)(j * (n + 1) + i);
			uint32_t c = a + (uint32_t)n + 2;
			tri(me, a, a + 1, c);
			tri(me, a, c, c - 1);
		}
	me->quads += (size_t)n * (size_t)n;
}

/* A box turned by yaw about its vertical axis through its centre. */
typedef struct obox {
	p3 c;       /* centre */
	p3 h;       /* half extents along the box's own axes */
	double yaw; /* radians about +Y */
} obox;

enum { F_NX, F_PX, F_NY, F_PY, F_NZ, F_PZ, NFACES };
#define OMIT(f) (1u << (f))
/* Faces resting on something (a floor, a table top) are left out: they are
 * invisible, and a radiosity solver would spend elements on them. */
#define OMIT_BOTTOM OMIT(F_NY)
#define OMIT_ENDS (OMIT(F_NY) | OMIT(F_PY))

/* Corners of each face, counter-clockwise seen from outside; corner bits:
 * 4 = +x, 2 = +y, 1 = +z. */
static const unsigned char FACE[NFACES][4] = {
        {0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1},
        {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3},
};

static obox aabb(p3 lo, p3 hi)
{
	obox b = {mul(add(lo, hi), 0.5), mul(sub(hi, lo), 0.5), 0};
	return b;
}

static p3 corner(const obox *b, unsigned bits)
{
	p3 l = P(bits & 4 ? b->h.x : -b->h.x, bits & 2 ? b->h.y : -b->h.y,
	         bits & 1 ? b->h.z : -b->h.z);
	return add(b->c, rot_y(l, b->yaw));
}

/* Face f cut n x n; an inward face (room walls) is seen from inside. */
static void box_face(mesh *me, const obox *b, int f, int n, bool inward)
{
	p3 o = corner(b, FACE[f][0]);
	p3 u = sub(corner(b, FACE[f][1]), o);
	p3 v = sub(corner(b, FACE[f][3]), o);
	if (inward)
		grid(me, o, v, u, n);
	else
		grid(me, o, u, v, n);
}

static void box(mesh *me, const obox *b, unsigned omit)
{
	for (int f = 0; f < NFACES; f++)
		if (!(omit & OMIT(f)))
			box_face(me, b, f, 1, false);
}

/* The face of [lo, hi] on side f, facing into the box: walls, panels. */
static void rect_in(mesh *me, p3 lo, p3 hi, int f)
{
	obox b = aabb(lo, hi);
	box_face(me, &b, f, 1, true);
}

/* A downward-facing square panel of edge e centred at (x, y, z). */
static void panel_down(mesh *me, double x, double y, double z, double e)
{
	rect_in(me, P(x - e / 2, y - 1, z - e / 2), P(x + e / 2, y, z + e / 2),
	        F_PY);
}

/* UV ellipsoid, radii r along its own axes: 2 slices (stacks - 1) tris. */
static void ellipsoid(mesh *me, p3 c, p3 r, double yaw, int slices, int stacks)
{
	uint32_t top = vert(me, add(c, P(0, r.y, 0)));
	uint32_t ring = (uint32_t)me->nv, s = (uint32_t)slices;
	for (int i = 1; i < stacks; i++) {
		double phi = PI * i / stacks;
		for (int j = 0; j < slices; j++) {
			double th = 2 * PI * j / slices;
			p3 l = P(r.x * sin(phi) * cos(th), r.y * cos(phi),
			         r.z * sin(phi) * sin(th));
			vert(me, add(c, rot_y(l, yaw)));
		}
	}
	uint32_t bot = vert(me, add(c, P(0, -r.y, 0)));
	uint32_t last = ring + (uint32_t)(stacks - 2) * s;
	for (uint32_t j = 0; j < s; j++) {
		uint32_t jn = (j + 1) % s;
		tri(me, top, ring + jn, ring + j);
		for (uint32_t a = ring + j; a < last; a += s) {
			uint32_t b = a - j + jn;
			tri(me, a, b, b + s);
			tri(me, a, b + s, a + s);
		}
		tri(me, last + j, last + jn, bot);
	}
}

enum { CAP_TOP = 1, CAP_BOTTOM = 2 };

/* Vertical cylinder on base centre c: 2 slices side triangles (rectangles,
 * merged by the engine) plus a fan of `slices` per cap asked for. */
static void cylinder(mesh *me, p3 c, double r, double h, int slices,
                     unsigned caps)
{
	uint32_t first = (uint32_t)me->nv, s = (uint32_t)slices;
	for (uint32_t j = 0; j < s; j++) {
		double th = 2 * PI * j / slices;
		p3 rim = add(c, P(r * cos(th), 0, r * sin(th)));
		vert(me, rim);
		vert(me, add(rim, P(0, h, 0)));
	}
	for (uint32_t j = 0; j < s; j++) {
		uint32_t a = first + 2 * j, d = first + 2 * ((j + 1) % s);
		tri(me, a, a + 1, d + 1);
		tri(me, a, d + 1, d);
	}
	me->quads += s;
	if (caps & CAP_TOP) {
		uint32_t t = vert(me, add(c, P(0, h, 0)));
		for (uint32_t j = 0; j < s; j++)
			tri(me, t, first + 2 * ((j + 1) % s) + 1,
			    first + 2 * j + 1);
	}
	if (caps & CAP_BOTTOM) {
		uint32_t b = vert(me, c);
		for (uint32_t j = 0; j < s; j++)
			tri(me, b, first + 2 * j, first + 2 * ((j + 1) % s));
	}
}

/* A local frame on the floor: origin and heading; places furniture parts. */
typedef struct frame {
	p3 o;
	double yaw;
} frame;

static p3 fpt(frame f, p3 local)
{
	return add(f.o, rot_y(local, f.yaw));
}

static void fbox(mesh *me, frame f, p3 c, p3 h, unsigned omit)
{
	obox b = {fpt(f, c), h, f.yaw};
	box(me, &b, omit);
}

/* ---------------------------------------------------- command-line model */

typedef struct params {
	const char *out;
	int fmt; /* sio_format, or -1: from the file name */
	bool square, help;
	double sun_lux, rho, emit, scale;
	double size[3];
	double subdiv, objects, tris_per_object, triangles, panels, points;
	uint64_t seed;
	uint32_t set; /* bit per opts[] entry given on the command line */
} params;

/* clang-format off */
enum opt_id {
	O_OUTPUT, O_FORMAT, O_SEED, O_SQUARE, O_SUN, O_SIZE, O_RHO, O_EMIT,
	O_SUBDIV, O_SCALE, O_OBJECTS, O_TPO, O_TRIANGLES, O_PANELS, O_POINTS,
	O_HELP, NOPTS
};
/* clang-format on */

#define GIVEN(p, id) (((p)->set >> (id)) & 1u)

/* Option value, or the kind's default when the option was not given. */
static double opt_or(const params *p, enum opt_id id, double v, double def)
{
	return GIVEN(p, id) ? v : def;
}

/* ------------------------------------------------------------- cornell */

/*
 * The Cornell Box data of the Cornell University Program of Computer
 * Graphics, in millimetres, Y up, every quad counter-clockwise seen from
 * inside the box (walls) or from outside the block (blocks).  The measured
 * box is slightly out of square: floor, back wall and left wall are not
 * parallelograms (x = 549.6 and 552.8 where the ceiling has 556.0) and the
 * block tops are off by 1-2 mm, so those stay two triangles in the engine;
 * --square snaps the walls to x = 556.0 so all of them merge.  The block
 * bottoms are not in the data: they rest on the floor, invisible.
 */
enum { CB_WHITE, CB_RED, CB_GREEN, CB_NMAT };

/* clang-format off */
static const struct cornell_part {
	const char *name;
	int mat;           /* CB_* */
	int nquads;        /* 1 for a wall, 5 for a block */
	double q[5][4][3]; /* mm */
} cornell_parts[] = {
	{"floor", CB_WHITE, 1, {
		{{552.8, 0, 0}, {0, 0, 0}, {0, 0, 559.2}, {549.6, 0, 559.2}}}},
	{"ceiling", CB_WHITE, 1, {
		{{556, 548.8, 0}, {556, 548.8, 559.2}, {0, 548.8, 559.2},
		 {0, 548.8, 0}}}},
	{"back_wall", CB_WHITE, 1, {
		{{549.6, 0, 559.2}, {0, 0, 559.2}, {0, 548.8, 559.2},
		 {556, 548.8, 559.2}}}},
	{"right_wall", CB_GREEN, 1, {
		{{0, 0, 559.2}, {0, 0, 0}, {0, 548.8, 0}, {0, 548.8, 559.2}}}},
	{"left_wall", CB_RED, 1, {
		{{552.8, 0, 0}, {549.6, 0, 559.2}, {556, 548.8, 559.2},
		 {556, 548.8, 0}}}},
	{"short_block", CB_WHITE, 5, {
		{{130, 165, 65}, {82, 165, 225}, {240, 165, 272}, {290, 165, 114}},
		{{290, 0, 114}, {290, 165, 114}, {240, 165, 272}, {240, 0, 272}},
		{{130, 0, 65}, {130, 165, 65}, {290, 165, 114}, {290, 0, 114}},
		{{82, 0, 225}, {82, 165, 225}, {130, 165, 65}, {130, 0, 65}},
		{{240, 0, 272}, {240, 165, 272}, {82, 165, 225}, {82, 0, 225}}}},
	{"tall_block", CB_WHITE, 5, {
		{{423, 330, 247}, {265, 330, 296}, {314, 330, 456}, {472, 330, 406}},
		{{423, 0, 247}, {423, 330, 247}, {472, 330, 406}, {472, 0, 406}},
		{{472, 0, 406}, {472, 330, 406}, {314, 330, 456}, {314, 0, 456}},
		{{314, 0, 456}, {314, 330, 456}, {265, 330, 296}, {265, 0, 296}},
		{{265, 0, 296}, {265, 330, 296}, {423, 330, 247}, {423, 0, 247}}}},
};
/* clang-format on */

/* The light sits in the data's opening (x 213..343, z 227..332 mm) 0.5 mm
 * below the ceiling, so that it does not overlap the ceiling coplanarly. */
#define CB_LIGHT_Y_MM 548.3

static p3 cornell_vertex(const double v[3], bool wall, bool square)
{
	double x = v[0];
	/* Only the walls' out-of-square x values move. */
	if (square && wall && (x == 549.6 || x == 552.8))
		x = 556.0;
	return P(x * 1e-3, v[1] * 1e-3, v[2] * 1e-3);
}

static void build_cornell(scene *sc, const params *p)
{
	/*
	 * RGB stand-ins for the measured reflectance spectra (4 nm samples
	 * from 400 to 700 nm): the white paint is flat near 0.73-0.75 over
	 * most of the range; red and green are the usual averages of their
	 * spectra over the long, middle and short thirds of the range.
	 */
	const mat mats[CB_NMAT] = {grey(0.73), rgb(0.63, 0.065, 0.05),
	                           rgb(0.14, 0.45, 0.09)};
	size_t nparts = sizeof(cornell_parts) / sizeof(cornell_parts[0]);
	for (size_t i = 0; i < nparts; i++) {
		const struct cornell_part *cp = &cornell_parts[i];
		mesh *me = mesh_new(sc, mats[cp->mat], "%s", cp->name);
		bool wall = cp->nquads == 1;
		for (int q = 0; q < cp->nquads; q++) {
			p3 v[4];
			for (int k = 0; k < 4; k++)
				v[k] = cornell_vertex(cp->q[q][k], wall,
				                      p->square);
			quad(me, v[0], v[1], v[2], v[3]);
		}
	}
	/*
	 * The published emission spectrum is not reproduced: the light is a
	 * white Lambertian panel of 3000 cd/m2, exitance pi x 3000 = 9425 lux
	 * (about the 10,000 lux of a bright luminaire), about 129 lm in total.
	 */
	mesh *light = mesh_new(sc, emitter(3000), "light");
	rect_in(light, P(0.213, 0, 0.227),
	        P(0.343, CB_LIGHT_Y_MM * 1e-3, 0.332), F_PY);
}

/* -------------------------------------------------------------- office */

static void build_office(scene *sc, const params *p)
{
	const double W = 4.0, H = 2.8, D = 3.0; /* x, y, z */
	obox room = aabb(P(0, 0, 0), P(W, H, D));
	box_face(mesh_new(sc, grey(0.3), "floor"), &room, F_NY, 1, true);
	box_face(mesh_new(sc, grey(0.8), "ceiling"), &room, F_PY, 1, true);
	mesh *walls = mesh_new(sc, grey(0.7), "walls");
	box_face(walls, &room, F_NX, 1, true);
	box_face(walls, &room, F_PX, 1, true);
	box_face(walls, &room, F_NZ, 1, true);
	/* The +z wall around a 1.6 x 1.2 m window opening, sill at 0.9 m.
	 * The opening is a hole: the engine has no glass, and a hole lets the
	 * optional sun in (and room light out, as an open window would). */
	rect_in(walls, P(0, 0, 0), P(W, 0.9, D), F_PZ);
	rect_in(walls, P(0, 2.1, 0), P(W, H, D), F_PZ);
	rect_in(walls, P(0, 0.9, 0), P(1.2, 2.1, D), F_PZ);
	rect_in(walls, P(2.8, 0.9, 0), P(W, 2.1, D), F_PZ);
	/* Two 0.6 x 0.6 m luminaires 1 mm below the ceiling, 2000 cd/m2
	 * (about 2260 lm each), centred over the two halves of the room. */
	for (int i = 0; i < 2; i++)
		panel_down(mesh_new(sc, emitter(2000), "luminaire_%d", i + 1),
		           i ? 2.8 : 1.2, H - 0.001, 1.5, 0.6);
	/* Desk: a 1.4 x 0.7 m top, 3 cm thick at 0.75 m, on four 4 cm legs
	 * whose ends (under the top, on the floor) are hidden. */
	frame desk = {P(2.0, 0, 2.4), 0};
	mesh *dm = mesh_new(sc, grey(0.5), "desk");
	fbox(dm, desk, P(0, 0.735, 0), P(0.7, 0.015, 0.35), 0);
	for (int i = 0; i < 4; i++)
		fbox(dm, desk,
		     P(i & 1 ? 0.63 : -0.63, 0.36, i & 2 ? 0.28 : -0.28),
		     P(0.02, 0.36, 0.02), OMIT_ENDS);
	/* A chair-like block: a 45 cm seat cube, a backrest standing on it. */
	frame chair = {P(2.0, 0, 1.75), 0};
	mesh *cm = mesh_new(sc, grey(0.4), "chair");
	fbox(cm, chair, P(0, 0.225, 0), P(0.225, 0.225, 0.225), OMIT_BOTTOM);
	fbox(cm, chair, P(0, 0.7, -0.2), P(0.225, 0.25, 0.025), OMIT_BOTTOM);
	point_light(sc, "desk_lamp", P(2.45, 1.15, 2.5), 100);
	if (GIVEN(p, O_SUN)) {
		/* Sun 35 degrees high, 20 degrees off the window's normal. */
		double el = 35 * PI / 180, az = 20 * PI / 180;
		rad_light_desc sun = {
		        .kind = RAD_LIGHT_DIRECTIONAL,
		        .direction = {-cos(el) * sin(az), -sin(el),
		                      -cos(el) * cos(az)},
		        .intensity = {p->sun_lux, p->sun_lux, p->sun_lux},
		        .name = "sun"};
		add_light(sc, &sun);
	}
}

/* ------------------------------------------------------ analytic scenes */

/* Closed box, every face emitting L and reflecting rho: in the exact
 * solution every point has radiosity B = pi L / (1 - rho). */
static void build_box(scene *sc, const params *p)
{
	double w = opt_or(p, O_SIZE, p->size[0], 1.0);
	double h = opt_or(p, O_SIZE, p->size[1], 1.0);
	double d = opt_or(p, O_SIZE, p->size[2], 1.0);
	double rho = opt_or(p, O_RHO, p->rho, 0.5);
	mat m = {{rho, rho, rho}, opt_or(p, O_EMIT, p->emit, 100.0)};
	int n = (int)opt_or(p, O_SUBDIV, p->subdiv, 1);
	obox b = aabb(P(0, 0, 0), P(w, h, d));
	mesh *me = mesh_new(sc, m, "box");
	for (int f = 0; f < NFACES; f++)
		box_face(me, &b, f, n, true);
}

/* Black 4 x 4 x 3 m room lit by one 1 m2 ceiling panel of 1000 cd/m2;
 * --scale multiplies every coordinate (unit-robustness tests). */
static void build_room(scene *sc, const params *p)
{
	double s = opt_or(p, O_SCALE, p->scale, 1.0);
	double rho = opt_or(p, O_RHO, p->rho, 0.0);
	obox r = aabb(P(0, 0, 0), P(4 * s, 3 * s, 4 * s));
	mesh *me = mesh_new(sc, grey(rho), "room");
	for (int f = 0; f < NFACES; f++)
		box_face(me, &r, f, 1, true);
	panel_down(mesh_new(sc, emitter(1000), "panel"), 2 * s, (3 - 0.001) * s,
	           2 * s, s);
}

/* The black room with a black 0.8 x 0.02 x 1.2 m plate hung 0.5 m under
 * the panel, off its centre: from the floor the panel is whole, partly
 * hidden or gone (the CIE 171:2006 test 5.7 kind of case: direct light
 * of an area source through an obstruction). */
static void build_obstructed(scene *sc, const params *p)
{
	double s = opt_or(p, O_SCALE, p->scale, 1.0);
	build_room(sc, p);
	obox plate = aabb(P(1.9 * s, 2.49 * s, 1.4 * s),
	                  P(2.7 * s, 2.51 * s, 2.6 * s));
	mesh *me = mesh_new(sc, grey(0), "plate");
	for (int f = 0; f < NFACES; f++)
		box_face(me, &plate, f, 1, false);
}

/*
 * The room as architectural exports write it (the Graz office of
 * ../shared/scenes/real is built so): the floor and ceiling slabs run
 * 0.3 m past the walls, and each wall 0.3 m past the walls it meets, so
 * part of every large polygon lies outside the room, where no light
 * goes.  A 1 m2 panel of 1000 cd/m2 hangs 8 cm under the ceiling; every
 * surface reflects rho (default 0.5).  4 x 4 x 3 m inside.
 */
static void build_slabroom(scene *sc, const params *p)
{
	double rho = opt_or(p, O_RHO, p->rho, 0.5);
	double lo = -0.3, hi = 4.3;
	mesh *me = mesh_new(sc, grey(rho), "room");
	quad(me, P(lo, 0, lo), P(lo, 0, hi), P(hi, 0, hi), P(hi, 0, lo));
	quad(me, P(lo, 3, lo), P(hi, 3, lo), P(hi, 3, hi), P(lo, 3, hi));
	quad(me, P(0, 0, lo), P(0, 3, lo), P(0, 3, hi), P(0, 0, hi));
	quad(me, P(4, 0, lo), P(4, 0, hi), P(4, 3, hi), P(4, 3, lo));
	quad(me, P(lo, 0, 0), P(hi, 0, 0), P(hi, 3, 0), P(lo, 3, 0));
	quad(me, P(lo, 0, 4), P(lo, 3, 4), P(hi, 3, 4), P(hi, 0, 4));
	panel_down(mesh_new(sc, emitter(1000), "panel"), 2, 3 - 0.08, 2, 1);
}

/* --------------------------------------------------------------- field */

static const mat *palette(uint64_t *rng)
{
	static const mat pal[] = {
	        {{0.6, 0.6, 0.6}, 0}, {{0.7, 0.3, 0.2}, 0},
	        {{0.2, 0.5, 0.3}, 0}, {{0.25, 0.35, 0.7}, 0},
	        {{0.8, 0.7, 0.3}, 0}, {{0.15, 0.15, 0.15}, 0},
	};
	return &pal[rng_next(rng) % (sizeof(pal) / sizeof(pal[0]))];
}

/* One random object of about `tpo` triangles standing on the floor at
 * (x, z): a subdivided box, a sphere or a capped cylinder. */
static void field_object(mesh *me, double x, double z, int tpo, uint64_t *rng)
{
	double yaw = rng_range(rng, 0, 2 * PI);
	double r = rng_range(rng, 0.3, 0.7);
	switch (rng_next(rng) % 3) {
	case 0: {
		int n = (int)fmax(1, round(sqrt(tpo / 10.0)));
		obox b = {P(x, r, z), P(r, r, rng_range(rng, 0.3, 0.7)), yaw};
		for (int f = 0; f < NFACES; f++)
			if (f != F_NY)
				box_face(me, &b, f, n, false);
		break;
	}
	case 1: {
		int st = (int)fmax(3, round(sqrt(tpo / 4.0)) + 1);
		ellipsoid(me, P(x, r, z), P(r, r, r), yaw, 2 * (st - 1), st);
		break;
	}
	default:
		cylinder(me, P(x, 0, z), r, rng_range(rng, 0.4, 2.0),
		         (int)fmax(3, round(tpo / 3.0)), CAP_TOP);
	}
}

/* Objects on a jittered 2.5 m grid (rows grow as needed), a ground plane,
 * then K panels 6 m up and P point lights 3 m up spread over it. */
static void build_field(scene *sc, const params *p)
{
	uint64_t rng = GIVEN(p, O_SEED) ? p->seed : 0x5EED0001u;
	int tpo = (int)opt_or(p, O_TPO, p->tris_per_object, 200);
	double target = opt_or(p, O_TRIANGLES, p->triangles, 0);
	long n = (long)opt_or(p, O_OBJECTS, p->objects, 100);
	if (target > 0)
		n = (long)ceil(target / tpo);
	long cols = (long)ceil(sqrt((double)n)), k = 0;
	const double cell = 2.5;
	size_t tris = 0;
	for (; target > 0 ? (double)tris < target : k < n; k++) {
		double x = (k % cols + 0.5) * cell + rng_range(&rng, -.4, .4);
		double z = (k / cols + 0.5) * cell + rng_range(&rng, -.4, .4);
		mesh *me = mesh_new(sc, *palette(&rng), "object_%05ld", k);
		field_object(me, x, z, tpo, &rng);
		tris += me->ni / 3;
		if (oom)
			return;
	}
	double wx = cols * cell, wz = ceil((double)k / cols) * cell;
	rect_in(mesh_new(sc, grey(0.3), "ground"), P(-1, 0, -1),
	        P(wx + 1, 1, wz + 1), F_NY);
	int np = (int)opt_or(p, O_PANELS, p->panels, 4);
	int g = (int)ceil(sqrt(np));
	for (int i = 0; i < np; i++)
		panel_down(mesh_new(sc, emitter(5000), "panel_%d", i),
		           (i % g + 0.5) * wx / g, 6.0, (i / g + 0.5) * wz / g,
		           1.5);
	int npt = (int)opt_or(p, O_POINTS, p->points, 0);
	for (int i = 0; i < npt; i++)
		point_light(
		        sc, "point",
		        P(rng_range(&rng, 0, wx), 3.0, rng_range(&rng, 0, wz)),
		        500);
}

/* ---------------------------------------------------------------- herd */

/* Report, fig. 3.1: the herd has 43,464 polygons and one source. */
#define HERD_REPORT 43464
enum { BODY_SL = 20, BODY_ST = 12, HEAD_SL = 12, HEAD_ST = 8, LEG_SL = 8 };
/* Triangles of one animal: see ellipsoid() and cylinder(). */
#define HERD_ANIMAL_TRIS                                                       \
	(2 * BODY_SL * (BODY_ST - 1) + 2 * HEAD_SL * (HEAD_ST - 1) +           \
	 4 * 2 * LEG_SL)

/* A stylised cow of scale s heading along +x of its frame: body, head and
 * four uncapped legs (their ends are inside the body and on the ground). */
static void animal(mesh *me, frame f, double s)
{
	ellipsoid(me, fpt(f, P(0, 1.15 * s, 0)), mul(P(0.95, 0.55, 0.42), s),
	          f.yaw, BODY_SL, BODY_ST);
	ellipsoid(me, fpt(f, P(1.05 * s, 1.45 * s, 0)),
	          mul(P(0.32, 0.24, 0.2), s), f.yaw, HEAD_SL, HEAD_ST);
	for (int i = 0; i < 4; i++) {
		p3 foot = P(i & 1 ? 0.6 : -0.6, 0, i & 2 ? 0.25 : -0.25);
		cylinder(me, fpt(f, mul(foot, s)), 0.08 * s, s, LEG_SL, 0);
	}
}

/* Animals on a jittered grid over a 60 x 40 m ground, random headings,
 * sizes and coats; their number is derived from the report's count. */
static void build_herd(scene *sc, const params *p)
{
	uint64_t rng = GIVEN(p, O_SEED) ? p->seed : 0x5EED0002u;
	const double W = 60, D = 40;
	/* Ground and source are 2 triangles each; animals make up the rest. */
	int n = (int)lround((HERD_REPORT - 4.0) / HERD_ANIMAL_TRIS);
	int cols = (int)ceil(sqrt(n * W / D)), rows = (n + cols - 1) / cols;
	double cx = W / cols, cz = D / rows;
	const mat coats[] = {rgb(0.35, 0.22, 0.12), grey(0.7), grey(0.06)};
	rect_in(mesh_new(sc, rgb(0.12, 0.25, 0.07), "ground"),
	        P(-W / 2, 0, -D / 2), P(W / 2, 1, D / 2), F_NY);
	for (int i = 0; i < n; i++) {
		double x = (i % cols + 0.5 + rng_range(&rng, -.2, .2)) * cx;
		double z = (i / cols + 0.5 + rng_range(&rng, -.2, .2)) * cz;
		frame f = {P(x - W / 2, 0, z - D / 2),
		           rng_range(&rng, 0, 2 * PI)};
		mesh *me = mesh_new(sc, coats[rng_next(&rng) % 3],
		                    "animal_%03d", i);
		animal(me, f, rng_range(&rng, 0.85, 1.15));
	}
	/* The one source: an 8 x 8 m sky panel 20 m up, 20,000 cd/m2, about
	 * 3000 lux on the ground below it. */
	panel_down(mesh_new(sc, emitter(20000), "sky"), 0, 20, 0, 8);
}

/* --------------------------------------------------------------- halls */

typedef struct hall_cfg {
	double w, h, d;           /* inside size, metres: x, y, z */
	int pillars_x, pillars_z; /* grid of full-height square pillars */
	double pillar;            /* pillar edge, metres */
	int doors, windows;       /* dark quads on the -x / +x walls */
	double panel, lum;        /* the 4 x 4 ceiling sources: edge, cd/m2 */
	int sets_x, sets_z;       /* table sets on a grid (0: empty hall) */
	int chairs;               /* per table, even */
	int fruit, fruit_slices;  /* tessellated fruit on each table */
	int shelves;              /* shelf units along each long wall */
	int books;                /* per shelf board, at most 17 */
} hall_cfg;

/* Centre of pillar i: the pillars split the hall into equal bays. */
static p3 pillar_at(const hall_cfg *c, int i)
{
	return P((i % c->pillars_x + 1) * c->w / (c->pillars_x + 1), c->h / 2,
	         (i / c->pillars_x + 1) * c->d / (c->pillars_z + 1));
}

static void hall_shell(scene *sc, const hall_cfg *c)
{
	obox room = aabb(P(0, 0, 0), P(c->w, c->h, c->d));
	box_face(mesh_new(sc, grey(0.4), "floor"), &room, F_NY, 1, true);
	box_face(mesh_new(sc, grey(0.75), "ceiling"), &room, F_PY, 1, true);
	mesh *walls = mesh_new(sc, grey(0.6), "walls");
	for (int f = 0; f < NFACES; f++)
		if (f != F_NY && f != F_PY)
			box_face(walls, &room, f, 1, true);
	mesh *pil = mesh_new(sc, grey(0.6), "pillars");
	for (int i = 0; i < c->pillars_x * c->pillars_z; i++) {
		obox b = {pillar_at(c, i),
		          P(c->pillar / 2, c->h / 2, c->pillar / 2), 0};
		box(pil, &b, OMIT_ENDS);
	}
	/* Doors and windows are opaque quads 1 mm in front of the walls. */
	mesh *doors = mesh_new(sc, rgb(0.3, 0.2, 0.12), "doors");
	for (int i = 0; i < c->doors; i++) {
		double z = (i + 1) * c->d / (c->doors + 1);
		rect_in(doors, P(0.001, 0, z - 0.6), P(1, 2.4, z + 0.6), F_NX);
	}
	mesh *win = mesh_new(sc, grey(0.08), "windows");
	for (int i = 0; i < c->windows; i++) {
		double z = (i + 1) * c->d / (c->windows + 1);
		rect_in(win, P(c->w - 1, 1.2, z - 1),
		        P(c->w - 0.001, 3.2, z + 1), F_PX);
	}
	for (int i = 0; i < 16; i++)
		panel_down(mesh_new(sc, emitter(c->lum), "source_%02d", i + 1),
		           (i % 4 + 0.5) * c->w / 4, c->h - 0.001,
		           (i / 4 + 0.5) * c->d / 4, c->panel);
}

/* A chair facing +z in its frame: seat, four legs, backrest. */
static void chair(mesh *me, frame f)
{
	fbox(me, f, P(0, 0.45, 0), P(0.21, 0.02, 0.21), 0);
	for (int i = 0; i < 4; i++)
		fbox(me, f,
		     P(i & 1 ? 0.18 : -0.18, 0.215, i & 2 ? 0.18 : -0.18),
		     P(0.02, 0.215, 0.02), OMIT_ENDS);
	fbox(me, f, P(0, 0.69, -0.19), P(0.21, 0.22, 0.02), OMIT_BOTTOM);
}

/* A table with chairs on both long sides; a vase and fruit on the top. */
static void table_set(mesh *wood, mesh *ware, frame f, const hall_cfg *c,
                      uint64_t *rng)
{
	fbox(wood, f, P(0, 0.74, 0), P(0.8, 0.02, 0.45), 0);
	for (int i = 0; i < 4; i++)
		fbox(wood, f,
		     P(i & 1 ? 0.72 : -0.72, 0.36, i & 2 ? 0.37 : -0.37),
		     P(0.025, 0.36, 0.025), OMIT_ENDS);
	int side = c->chairs / 2;
	for (int i = 0; i < c->chairs; i++) {
		bool far = i >= side;
		double x = ((i % side) + 0.5) * 1.6 / side - 0.8;
		frame cf = {fpt(f, P(x, 0, far ? 0.75 : -0.75)),
		            f.yaw + (far ? PI : 0) + rng_range(rng, -.15, .15)};
		chair(wood, cf);
	}
	cylinder(ware, fpt(f, P(rng_range(rng, -.5, .5), 0.76, 0)), 0.06, 0.25,
	         16, CAP_TOP);
	for (int i = 0; i < c->fruit; i++) {
		double r = rng_range(rng, 0.04, 0.08);
		p3 at = fpt(f, P(rng_range(rng, -.6, .6), 0.76 + r,
		                 rng_range(rng, -.3, .3)));
		ellipsoid(ware, at, P(r, r, r), 0, c->fruit_slices,
		          c->fruit_slices / 2);
	}
}

/* A 1 x 0.4 x 2 m shelf unit, back on the wall, facing +z in its frame:
 * two sides, a back, five boards, books on the lower four. */
static void shelf_unit(mesh *wood, mesh *books, frame f, int nbooks,
                       uint64_t *rng)
{
	for (int s = -1; s <= 1; s += 2)
		fbox(wood, f, P(0.49 * s, 1.0, 0.2), P(0.01, 1.0, 0.2),
		     OMIT_BOTTOM);
	fbox(wood, f, P(0, 1.0, 0.005), P(0.48, 1.0, 0.005), OMIT_BOTTOM);
	for (int b = 0; b < 5; b++) {
		double y = 0.08 + 0.475 * b, x = -0.46;
		fbox(wood, f, P(0, y, 0.205), P(0.48, 0.01, 0.195), 0);
		for (int k = 0; b < 4 && k < nbooks; k++) {
			double t = rng_range(rng, 0.02, 0.05);
			double hb = rng_range(rng, 0.18, 0.3);
			fbox(books, f, P(x + t / 2, y + 0.01 + hb / 2, 0.22),
			     P(t / 2, hb / 2, rng_range(rng, 0.1, 0.15)),
			     OMIT_BOTTOM);
			x += t + 0.002;
		}
	}
}

/* Does a table set (with its chairs) centred at (x, z) hit a pillar? */
static bool hits_pillar(const hall_cfg *c, double x, double z)
{
	double m = c->pillar / 2 + 0.2; /* pillar half edge and a gap */
	for (int i = 0; i < c->pillars_x * c->pillars_z; i++) {
		p3 at = pillar_at(c, i);
		if (fabs(at.x - x) < 1.0 + m && fabs(at.z - z) < 1.25 + m)
			return true;
	}
	return false;
}

static void hall_furniture(scene *sc, const hall_cfg *c, uint64_t rng)
{
	/* Sets fill the floor between the shelves (0.4 m deep, along z = 0
	 * and z = d) with room for chairs, skipping cells on a pillar. */
	const double mx = 1.2, mz = 1.8;
	double cx = (c->w - 2 * mx) / c->sets_x,
	       cz = (c->d - 2 * mz) / c->sets_z;
	for (int i = 0; i < c->sets_x * c->sets_z; i++) {
		frame f = {P(mx + (i % c->sets_x + 0.5) * cx, 0,
		             mz + (i / c->sets_x + 0.5) * cz),
		           0};
		if (hits_pillar(c, f.o.x, f.o.z))
			continue;
		mesh *wood =
		        mesh_new(sc, rgb(0.45, 0.3, 0.18), "table_%03d", i);
		mesh *ware = mesh_new(sc, *palette(&rng), "tableware_%03d", i);
		table_set(wood, ware, f, c, &rng);
	}
	for (int i = 0; i < 2 * c->shelves; i++) {
		bool far = i >= c->shelves;
		double x = (i % c->shelves + 0.5) * c->w / c->shelves;
		frame f = {P(x, 0, far ? c->d - 0.001 : 0.001), far ? PI : 0};
		shelf_unit(mesh_new(sc, rgb(0.5, 0.35, 0.2), "shelf_%03d", i),
		           mesh_new(sc, *palette(&rng), "books_%03d", i), f,
		           c->books, &rng);
	}
}

/*
 * The report's halls (figs. 3.2, 3.3, 4.6, 5.2).  Only polygon and source
 * counts are published, so the layouts are ours: triangle counts are tuned
 * to within 5% of the report's polygon counts.  Sources are 16 ceiling
 * panels; the very bright hall's are 10x brighter.  The report gives no
 * source count for the grand hall: we keep 16, larger.
 */
/* In hall_cfg order: w h d, pillars x z, pillar edge, doors, windows,
 * panel edge, luminance; then sets x z, chairs, fruit, fruit slices,
 * shelves, books. */
/* clang-format off */
static const hall_cfg hall_empty  = {24,  6, 16, 3, 2, 0.5, 1, 0, 1.2,  3000,
				     0, 0, 0, 0,  0,  0,  0};
static const hall_cfg hall_bright = {24,  6, 16, 2, 2, 0.5, 0, 4, 1.2, 30000,
				     0, 0, 0, 0,  0,  0,  0};
static const hall_cfg hall_full   = {24,  6, 16, 3, 2, 0.5, 1, 0, 1.2,  3000,
				     7, 4, 4, 3, 16, 13, 16};
static const hall_cfg hall_grand  = {48, 10, 32, 5, 3, 0.8, 2, 4, 2.4,  3000,
				    14, 9, 6, 4, 24, 24, 10};
/* clang-format on */

static void build_hall(scene *sc, const params *p, const hall_cfg *c)
{
	hall_shell(sc, c);
	if (c->sets_x)
		hall_furniture(sc, c, GIVEN(p, O_SEED) ? p->seed : 0x5EED0003u);
}

/* ---------------------------------------------------------- kind table */

enum kind_id {
	KD_CORNELL,
	KD_OFFICE,
	KD_BOX,
	KD_ROOM,
	KD_OBSTRUCTED,
	KD_SLABROOM,
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
	void (*build)(scene *sc, const params *p); /* NULL for halls */
	const hall_cfg *hall;
	int report; /* the report's polygon count (study scenes), else 0 */
	const char *help;
} kind;

/* clang-format off */
static const kind kinds[NKINDS] = {
	[KD_CORNELL] = {"cornell", build_cornell, NULL, 0,
		"the published Cornell Box, 0.556 x 0.549 x 0.559 m: 5 walls,\n"
		"2 blocks, a 3000 cd/m2 light 0.5 mm below the ceiling.\n"
		"32 triangles -> 21 polygons (18 with --square), 4 materials"},
	[KD_OFFICE] = {"office", build_office, NULL, 0,
		"a 4 x 3 x 2.8 m office: window opening, desk, chair, two\n"
		"0.6 m ceiling panels of 2000 cd/m2, a 100 cd desk lamp.\n"
		"86 triangles -> 43 polygons, 6 materials, 1 point light"},
	[KD_BOX] = {"box", build_box, NULL, 0,
		"a closed box seen from inside, every face emitting L and\n"
		"reflecting rho: B = pi L / (1 - rho) everywhere.\n"
		"12 N^2 triangles -> 6 N^2 polygons (N = --subdiv)"},
	[KD_ROOM] = {"room", build_room, NULL, 0,
		"a black 4 x 4 x 3 m room lit by one 1 m2 ceiling panel\n"
		"of 1000 cd/m2. 14 triangles -> 7 polygons"},
	[KD_OBSTRUCTED] = {"obstructed", build_obstructed, NULL, 0,
		"the room with a black plate under part of its panel:\n"
		"direct light through an obstruction. 26 triangles ->\n"
		"13 polygons"},
	[KD_SLABROOM] = {"slabroom", build_slabroom, NULL, 0,
		"a grey 4 x 4 x 3 m room whose floor, ceiling and walls\n"
		"run 0.3 m past its corners, as architectural exports write\n"
		"them; a 1 m2 panel 8 cm under the ceiling. 14 triangles"},
	[KD_FIELD] = {"field", build_field, NULL, 0,
		"random boxes, spheres and cylinders on a ground plane\n"
		"under emissive panels and point lights (clustering)"},
	[KD_HERD] = {"herd", build_herd, NULL, HERD_REPORT,
		"report fig. 3.1: 65 animals on a 60 x 40 m ground, one\n"
		"sky source. 43,684 triangles -> 41,602 polygons\n"
		"(report: 43,464 polygons)"},
	[KD_HALL_EMPTY] = {"hall-empty", NULL, &hall_empty, 94,
		"report fig. 3.2: a 24 x 16 x 6 m hall, 6 pillars, a door,\n"
		"16 ceiling sources. 94 triangles -> 47 polygons\n"
		"(report: 94 polygons)"},
	[KD_HALL_FULL] = {"hall-full", NULL, &hall_full, 40886,
		"report fig. 3.3: the empty hall with tables, chairs, fruit\n"
		"and shelves. 40,634 triangles -> 27,885 polygons\n"
		"(report: 40,886 polygons)"},
	[KD_HALL_BRIGHT] = {"hall-bright", NULL, &hall_bright, 84,
		"report fig. 4.6: 4 pillars, 4 windows, 16 sources of\n"
		"30,000 cd/m2. 84 triangles -> 42 polygons\n"
		"(report: 84 polygons)"},
	[KD_HALL_GRAND] = {"hall-grand", NULL, &hall_grand, 288000,
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
	if (oom)
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

/* Kinds may leave a mesh empty (a hall without doors): glTF forbids empty
 * accessors, so such meshes are dropped before writing. */
static void drop_empty_meshes(scene *sc)
{
	size_t kept = 0;
	for (size_t i = 0; i < sc->nmesh; i++) {
		mesh *me = sc->mesh[i];
		if (me->ni > 0) {
			sc->mesh[kept++] = me;
			continue;
		}
		free(me->pos);
		free(me->idx);
		free(me);
	}
	sc->nmesh = kept;
}

static void scene_free(scene *sc)
{
	for (size_t i = 0; i < sc->nmesh; i++) {
		free(sc->mesh[i]->pos);
		free(sc->mesh[i]->idx);
		free(sc->mesh[i]);
	}
	free(sc->mesh);
	free(sc->light);
}

int main(int argc, char **argv)
{
	params p;
	const kind *k = NULL;
	int rc = parse_args(argc, argv, &p, &k);
	if (rc >= 0)
		return rc;
	scene sc = {0};
	if (k->hall)
		build_hall(&sc, &p, k->hall);
	else
		k->build(&sc, &p);
	drop_empty_meshes(&sc);
	rc = write_scene(&sc, &p, k);
	scene_free(&sc);
	return rc;
}
