/*
 * gen.h -- what the parts of luxrad-scenegen share: the geometry and the
 * random numbers (inline), the scene being built and the builder that
 * appends to it (build.c), the parsed command line the scene families read
 * (filled in by scenegen.c) and the families themselves (families.c).
 */
#ifndef LUXRAD_SCENEGEN_GEN_H
#define LUXRAD_SCENEGEN_GEN_H

#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "sceneio.h"

#define PI 3.14159265358979323846

/* ------------------------------------------------------------- geometry */

typedef struct p3 {
	double x, y, z;
} p3;

static inline p3 P(double x, double y, double z)
{
	p3 r = {x, y, z};
	return r;
}

static inline p3 add(p3 a, p3 b)
{
	return P(a.x + b.x, a.y + b.y, a.z + b.z);
}

static inline p3 sub(p3 a, p3 b)
{
	return P(a.x - b.x, a.y - b.y, a.z - b.z);
}

static inline p3 mul(p3 a, double s)
{
	return P(a.x * s, a.y * s, a.z * s);
}

static inline double len(p3 a)
{
	return sqrt(a.x * a.x + a.y * a.y + a.z * a.z);
}

/* Proper rotation about +Y (keeps counter-clockwise faces CCW). */
static inline p3 rot_y(p3 v, double yaw)
{
	double c = cos(yaw), s = sin(yaw);
	return P(c * v.x + s * v.z, v.y, -s * v.x + c * v.z);
}

/* splitmix64: tiny, fast, and the same sequence on every platform. */
static inline uint64_t rng_next(uint64_t *s)
{
	uint64_t z = (*s += 0x9E3779B97F4A7C15u);
	z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9u;
	z = (z ^ (z >> 27)) * 0x94D049BB133111EBu;
	return z ^ (z >> 31);
}

static inline double rng_range(uint64_t *s, double lo, double hi)
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

/* Sticky allocation failure; see the DESIGN note in build.c. */
extern bool sg_oom;

static inline mat grey(double rho)
{
	mat m = {{rho, rho, rho}, 0};
	return m;
}

static inline mat rgb(double r, double g, double b)
{
	mat m = {{r, g, b}, 0};
	return m;
}

/* Our emitters are pure sources (reflectance 0): their radiosity is exactly
 * their exitance pi * L, which keeps analytic checks simple. */
static inline mat emitter(double lum)
{
	mat m = {{0, 0, 0}, lum};
	return m;
}

/* A new empty mesh of material m named by fmt, appended to sc; after an
 * allocation failure a shared sink whose appends all do nothing. */
mesh *sg_mesh_new(scene *sc, mat m, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
void sg_add_light(scene *sc, const rad_light_desc *l);
void sg_point_light(scene *sc, const char *name, p3 at, double cd);
/* Quad a b c d, counter-clockwise seen from its front: triangles abc, acd. */
void sg_quad(mesh *me, p3 a, p3 b, p3 c, p3 d);

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

static inline obox aabb(p3 lo, p3 hi)
{
	obox b = {mul(add(lo, hi), 0.5), mul(sub(hi, lo), 0.5), 0};
	return b;
}

/* Face f cut n x n; an inward face (room walls) is seen from inside. */
void sg_box_face(mesh *me, const obox *b, int f, int n, bool inward);
/* The faces of b not in omit (OMIT bits), seen from outside. */
void sg_box(mesh *me, const obox *b, unsigned omit);
/* The face of [lo, hi] on side f, facing into the box: walls, panels. */
void sg_rect_in(mesh *me, p3 lo, p3 hi, int f);
/* A downward-facing square panel of edge e centred at (x, y, z). */
void sg_panel_down(mesh *me, double x, double y, double z, double e);
/* UV ellipsoid, radii r along its own axes: 2 slices (stacks - 1) tris. */
void sg_ellipsoid(mesh *me, p3 c, p3 r, double yaw, int slices, int stacks);

enum { CAP_TOP = 1, CAP_BOTTOM = 2 };

/* Vertical cylinder on base centre c: 2 slices side triangles (rectangles,
 * merged by the engine) plus a fan of `slices` per cap asked for. */
void sg_cylinder(mesh *me, p3 c, double r, double h, int slices, unsigned caps);

/* A local frame on the floor: origin and heading; places furniture parts. */
typedef struct frame {
	p3 o;
	double yaw;
} frame;

static inline p3 fpt(frame f, p3 local)
{
	return add(f.o, rot_y(local, f.yaw));
}

/* A box of half extents h centred at c in frame f, turned with it. */
void sg_fbox(mesh *me, frame f, p3 c, p3 h, unsigned omit);

/* Kinds may leave a mesh empty (a hall without doors): glTF forbids empty
 * accessors, so such meshes are dropped before writing. */
void sg_drop_empty_meshes(scene *sc);
void sg_scene_free(scene *sc);

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
static inline double opt_or(const params *p, enum opt_id id, double v,
                            double def)
{
	return GIVEN(p, id) ? v : def;
}

/* ------------------------------------------------------- scene families */

/* Report, fig. 3.1: the herd has 43,464 polygons and one source. */
#define HERD_REPORT 43464

/* Each builds one kind of scene (families.c) into an empty scene. */
void sg_build_cornell(scene *sc, const params *p);
void sg_build_office(scene *sc, const params *p);
void sg_build_box(scene *sc, const params *p);
void sg_build_room(scene *sc, const params *p);
void sg_build_obstructed(scene *sc, const params *p);
void sg_build_slabroom(scene *sc, const params *p);
void sg_build_thinlum(scene *sc, const params *p);
void sg_build_cove(scene *sc, const params *p);
void sg_build_field(scene *sc, const params *p);
void sg_build_herd(scene *sc, const params *p);
void sg_build_hall_empty(scene *sc, const params *p);
void sg_build_hall_full(scene *sc, const params *p);
void sg_build_hall_bright(scene *sc, const params *p);
void sg_build_hall_grand(scene *sc, const params *p);

#endif
