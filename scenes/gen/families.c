/*
 * families.c -- the scene families of luxrad-scenegen, one builder a kind:
 * the Cornell box from its published measurements, a small office, the
 * analytic test boxes and rooms, random "field" scenes sized by triangle
 * count, and synthetic stand-ins for the study scenes of the report the
 * engine follows (herd, empty / full / very bright / grand hall;
 * docs/ALGORITHM.md §9.1).  Each is made of the builder's shapes (build.c)
 * and reads only the options that apply to its kind; opt_or gives the
 * kind's own default for one not given.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "gen.h"

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

void sg_build_cornell(scene *sc, const params *p)
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
		mesh *me = sg_mesh_new(sc, mats[cp->mat], "%s", cp->name);
		bool wall = cp->nquads == 1;
		for (int q = 0; q < cp->nquads; q++) {
			p3 v[4];
			for (int k = 0; k < 4; k++)
				v[k] = cornell_vertex(cp->q[q][k], wall,
				                      p->square);
			sg_quad(me, v[0], v[1], v[2], v[3]);
		}
	}
	/*
	 * The published emission spectrum is not reproduced: the light is a
	 * white Lambertian panel of 3000 cd/m2, exitance pi x 3000 = 9425 lux
	 * (about the 10,000 lux of a bright luminaire), about 129 lm in total.
	 */
	mesh *light = sg_mesh_new(sc, emitter(3000), "light");
	sg_rect_in(light, P(0.213, 0, 0.227),
	           P(0.343, CB_LIGHT_Y_MM * 1e-3, 0.332), F_PY);
}

/* -------------------------------------------------------------- office */

void sg_build_office(scene *sc, const params *p)
{
	const double W = 4.0, H = 2.8, D = 3.0; /* x, y, z */
	obox room = aabb(P(0, 0, 0), P(W, H, D));
	sg_box_face(sg_mesh_new(sc, grey(0.3), "floor"), &room, F_NY, 1, true);
	sg_box_face(sg_mesh_new(sc, grey(0.8), "ceiling"), &room, F_PY, 1,
	            true);
	mesh *walls = sg_mesh_new(sc, grey(0.7), "walls");
	sg_box_face(walls, &room, F_NX, 1, true);
	sg_box_face(walls, &room, F_PX, 1, true);
	sg_box_face(walls, &room, F_NZ, 1, true);
	/* The +z wall around a 1.6 x 1.2 m window opening, sill at 0.9 m.
	 * The opening is a hole: the engine has no glass, and a hole lets the
	 * optional sun in (and room light out, as an open window would). */
	sg_rect_in(walls, P(0, 0, 0), P(W, 0.9, D), F_PZ);
	sg_rect_in(walls, P(0, 2.1, 0), P(W, H, D), F_PZ);
	sg_rect_in(walls, P(0, 0.9, 0), P(1.2, 2.1, D), F_PZ);
	sg_rect_in(walls, P(2.8, 0.9, 0), P(W, 2.1, D), F_PZ);
	/* Two 0.6 x 0.6 m luminaires 1 mm below the ceiling, 2000 cd/m2
	 * (about 2260 lm each), centred over the two halves of the room. */
	for (int i = 0; i < 2; i++)
		sg_panel_down(
		        sg_mesh_new(sc, emitter(2000), "luminaire_%d", i + 1),
		        i ? 2.8 : 1.2, H - 0.001, 1.5, 0.6);
	/* Desk: a 1.4 x 0.7 m top, 3 cm thick at 0.75 m, on four 4 cm legs
	 * whose ends (under the top, on the floor) are hidden. */
	frame desk = {P(2.0, 0, 2.4), 0};
	mesh *dm = sg_mesh_new(sc, grey(0.5), "desk");
	sg_fbox(dm, desk, P(0, 0.735, 0), P(0.7, 0.015, 0.35), 0);
	for (int i = 0; i < 4; i++)
		sg_fbox(dm, desk,
		        P(i & 1 ? 0.63 : -0.63, 0.36, i & 2 ? 0.28 : -0.28),
		        P(0.02, 0.36, 0.02), OMIT_ENDS);
	/* A chair-like block: a 45 cm seat cube, a backrest standing on it. */
	frame chair = {P(2.0, 0, 1.75), 0};
	mesh *cm = sg_mesh_new(sc, grey(0.4), "chair");
	sg_fbox(cm, chair, P(0, 0.225, 0), P(0.225, 0.225, 0.225), OMIT_BOTTOM);
	sg_fbox(cm, chair, P(0, 0.7, -0.2), P(0.225, 0.25, 0.025), OMIT_BOTTOM);
	sg_point_light(sc, "desk_lamp", P(2.45, 1.15, 2.5), 100);
	if (GIVEN(p, O_SUN)) {
		/* Sun 35 degrees high, 20 degrees off the window's normal. */
		double el = 35 * PI / 180, az = 20 * PI / 180;
		rad_light_desc sun = {
		        .kind = RAD_LIGHT_DIRECTIONAL,
		        .direction = {-cos(el) * sin(az), -sin(el),
		                      -cos(el) * cos(az)},
		        .intensity = {p->sun_lux, p->sun_lux, p->sun_lux},
		        .name = "sun"};
		sg_add_light(sc, &sun);
	}
}

/* ------------------------------------------------------ analytic scenes */

/* Closed box, every face emitting L and reflecting rho: in the exact
 * solution every point has radiosity B = pi L / (1 - rho). */
void sg_build_box(scene *sc, const params *p)
{
	double w = opt_or(p, O_SIZE, p->size[0], 1.0);
	double h = opt_or(p, O_SIZE, p->size[1], 1.0);
	double d = opt_or(p, O_SIZE, p->size[2], 1.0);
	double rho = opt_or(p, O_RHO, p->rho, 0.5);
	mat m = {{rho, rho, rho}, opt_or(p, O_EMIT, p->emit, 100.0)};
	int n = (int)opt_or(p, O_SUBDIV, p->subdiv, 1);
	obox b = aabb(P(0, 0, 0), P(w, h, d));
	mesh *me = sg_mesh_new(sc, m, "box");
	for (int f = 0; f < NFACES; f++)
		sg_box_face(me, &b, f, n, true);
}

/* Black 4 x 4 x 3 m room lit by one 1 m2 ceiling panel of 1000 cd/m2;
 * --scale multiplies every coordinate (unit-robustness tests). */
void sg_build_room(scene *sc, const params *p)
{
	double s = opt_or(p, O_SCALE, p->scale, 1.0);
	double rho = opt_or(p, O_RHO, p->rho, 0.0);
	obox r = aabb(P(0, 0, 0), P(4 * s, 3 * s, 4 * s));
	mesh *me = sg_mesh_new(sc, grey(rho), "room");
	for (int f = 0; f < NFACES; f++)
		sg_box_face(me, &r, f, 1, true);
	sg_panel_down(sg_mesh_new(sc, emitter(1000), "panel"), 2 * s,
	              (3 - 0.001) * s, 2 * s, s);
}

/* The black room with a black 0.8 x 0.02 x 1.2 m plate hung 0.5 m under
 * the panel, off its centre: from the floor the panel is whole, partly
 * hidden or gone (the CIE 171:2006 test 5.7 kind of case: direct light
 * of an area source through an obstruction). */
void sg_build_obstructed(scene *sc, const params *p)
{
	double s = opt_or(p, O_SCALE, p->scale, 1.0);
	sg_build_room(sc, p);
	obox plate = aabb(P(1.9 * s, 2.49 * s, 1.4 * s),
	                  P(2.7 * s, 2.51 * s, 2.6 * s));
	mesh *me = sg_mesh_new(sc, grey(0), "plate");
	for (int f = 0; f < NFACES; f++)
		sg_box_face(me, &plate, f, 1, false);
}

/*
 * The room as architectural exports write it (the Graz office of
 * ../shared/scenes/real is built so): the floor and ceiling slabs run
 * 0.3 m past the walls, and each wall 0.3 m past the walls it meets, so
 * part of every large polygon lies outside the room, where no light
 * goes.  A 1 m2 panel of 1000 cd/m2 hangs 8 cm under the ceiling; every
 * surface reflects rho (default 0.5).  4 x 4 x 3 m inside.
 */
void sg_build_slabroom(scene *sc, const params *p)
{
	double rho = opt_or(p, O_RHO, p->rho, 0.5);
	double lo = -0.3, hi = 4.3;
	mesh *me = sg_mesh_new(sc, grey(rho), "room");
	sg_quad(me, P(lo, 0, lo), P(lo, 0, hi), P(hi, 0, hi), P(hi, 0, lo));
	sg_quad(me, P(lo, 3, lo), P(hi, 3, lo), P(hi, 3, hi), P(lo, 3, hi));
	sg_quad(me, P(0, 0, lo), P(0, 3, lo), P(0, 3, hi), P(0, 0, hi));
	sg_quad(me, P(4, 0, lo), P(4, 0, hi), P(4, 3, hi), P(4, 3, lo));
	sg_quad(me, P(lo, 0, 0), P(hi, 0, 0), P(hi, 3, 0), P(lo, 3, 0));
	sg_quad(me, P(lo, 0, 4), P(lo, 3, 4), P(hi, 3, 4), P(hi, 0, 4));
	sg_panel_down(sg_mesh_new(sc, emitter(1000), "panel"), 2, 3 - 0.08, 2,
	              1);
}

/*
 * A grey 4 x 4 x 3 m room (floor and walls 0.5, ceiling 0.8) lit by a
 * thin luminaire mounted under the ceiling's centre: a 0.75 m square box
 * 1 cm deep of 1000 cd/m2.  thinlum: all five outer faces emit, as in
 * the Blender export of the Cornell box (the sides send 5 % of the
 * light, half of it onto the ceiling within centimetres); cove: only the
 * sides emit and the bottom is black, so every lux on the floor comes
 * from them, most of it by way of the ceiling band they light.
 */
static void thin_luminaire_room(scene *sc, int cove)
{
	mesh *room = sg_mesh_new(sc, grey(0.5), "room");
	mesh *ceiling = sg_mesh_new(sc, grey(0.8), "ceiling");
	obox r = aabb(P(0, 0, 0), P(4, 3, 4));
	for (int f = 0; f < NFACES; f++)
		sg_box_face(f == F_PY ? ceiling : room, &r, f, 1, true);
	obox box = aabb(P(1.625, 2.99, 1.625), P(2.375, 3, 2.375));
	mesh *lum = sg_mesh_new(sc, emitter(1000), "luminaire");
	sg_box(lum, &box, OMIT(F_PY) | (cove ? OMIT(F_NY) : 0));
	if (cove)
		sg_box_face(sg_mesh_new(sc, grey(0), "luminaire-bottom"), &box,
		            F_NY, 1, false);
}

void sg_build_thinlum(scene *sc, const params *p)
{
	(void)p;
	thin_luminaire_room(sc, 0);
}

void sg_build_cove(scene *sc, const params *p)
{
	(void)p;
	thin_luminaire_room(sc, 1);
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
				sg_box_face(me, &b, f, n, false);
		break;
	}
	case 1: {
		int st = (int)fmax(3, round(sqrt(tpo / 4.0)) + 1);
		sg_ellipsoid(me, P(x, r, z), P(r, r, r), yaw, 2 * (st - 1), st);
		break;
	}
	default:
		sg_cylinder(me, P(x, 0, z), r, rng_range(rng, 0.4, 2.0),
		            (int)fmax(3, round(tpo / 3.0)), CAP_TOP);
	}
}

/* Objects on a jittered 2.5 m grid (rows grow as needed), a ground plane,
 * then K panels 6 m up and P point lights 3 m up spread over it. */
void sg_build_field(scene *sc, const params *p)
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
		mesh *me = sg_mesh_new(sc, *palette(&rng), "object_%05ld", k);
		field_object(me, x, z, tpo, &rng);
		tris += me->ni / 3;
		if (sg_oom)
			return;
	}
	double wx = cols * cell, wz = ceil((double)k / cols) * cell;
	sg_rect_in(sg_mesh_new(sc, grey(0.3), "ground"), P(-1, 0, -1),
	           P(wx + 1, 1, wz + 1), F_NY);
	int np = (int)opt_or(p, O_PANELS, p->panels, 4);
	int g = (int)ceil(sqrt(np));
	for (int i = 0; i < np; i++)
		sg_panel_down(sg_mesh_new(sc, emitter(5000), "panel_%d", i),
		              (i % g + 0.5) * wx / g, 6.0,
		              (i / g + 0.5) * wz / g, 1.5);
	int npt = (int)opt_or(p, O_POINTS, p->points, 0);
	for (int i = 0; i < npt; i++)
		sg_point_light(
		        sc, "point",
		        P(rng_range(&rng, 0, wx), 3.0, rng_range(&rng, 0, wz)),
		        500);
}

/* ---------------------------------------------------------------- herd */

enum { BODY_SL = 20, BODY_ST = 12, HEAD_SL = 12, HEAD_ST = 8, LEG_SL = 8 };
/* Triangles of one animal: see sg_ellipsoid() and sg_cylinder(). */
#define HERD_ANIMAL_TRIS                                                       \
	(2 * BODY_SL * (BODY_ST - 1) + 2 * HEAD_SL * (HEAD_ST - 1) +           \
	 4 * 2 * LEG_SL)

/* A stylised cow of scale s heading along +x of its frame: body, head and
 * four uncapped legs (their ends are inside the body and on the ground). */
static void animal(mesh *me, frame f, double s)
{
	sg_ellipsoid(me, fpt(f, P(0, 1.15 * s, 0)), mul(P(0.95, 0.55, 0.42), s),
	             f.yaw, BODY_SL, BODY_ST);
	sg_ellipsoid(me, fpt(f, P(1.05 * s, 1.45 * s, 0)),
	             mul(P(0.32, 0.24, 0.2), s), f.yaw, HEAD_SL, HEAD_ST);
	for (int i = 0; i < 4; i++) {
		p3 foot = P(i & 1 ? 0.6 : -0.6, 0, i & 2 ? 0.25 : -0.25);
		sg_cylinder(me, fpt(f, mul(foot, s)), 0.08 * s, s, LEG_SL, 0);
	}
}

/* Animals on a jittered grid over a 60 x 40 m ground, random headings,
 * sizes and coats; their number is derived from the report's count. */
void sg_build_herd(scene *sc, const params *p)
{
	uint64_t rng = GIVEN(p, O_SEED) ? p->seed : 0x5EED0002u;
	const double W = 60, D = 40;
	/* Ground and source are 2 triangles each; animals make up the rest. */
	int n = (int)lround((HERD_REPORT - 4.0) / HERD_ANIMAL_TRIS);
	int cols = (int)ceil(sqrt(n * W / D)), rows = (n + cols - 1) / cols;
	double cx = W / cols, cz = D / rows;
	const mat coats[] = {rgb(0.35, 0.22, 0.12), grey(0.7), grey(0.06)};
	sg_rect_in(sg_mesh_new(sc, rgb(0.12, 0.25, 0.07), "ground"),
	           P(-W / 2, 0, -D / 2), P(W / 2, 1, D / 2), F_NY);
	for (int i = 0; i < n; i++) {
		double x = (i % cols + 0.5 + rng_range(&rng, -.2, .2)) * cx;
		double z = (i / cols + 0.5 + rng_range(&rng, -.2, .2)) * cz;
		frame f = {P(x - W / 2, 0, z - D / 2),
		           rng_range(&rng, 0, 2 * PI)};
		mesh *me = sg_mesh_new(sc, coats[rng_next(&rng) % 3],
		                       "animal_%03d", i);
		animal(me, f, rng_range(&rng, 0.85, 1.15));
	}
	/* The one source: an 8 x 8 m sky panel 20 m up, 20,000 cd/m2, about
	 * 3000 lux on the ground below it. */
	sg_panel_down(sg_mesh_new(sc, emitter(20000), "sky"), 0, 20, 0, 8);
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
	sg_box_face(sg_mesh_new(sc, grey(0.4), "floor"), &room, F_NY, 1, true);
	sg_box_face(sg_mesh_new(sc, grey(0.75), "ceiling"), &room, F_PY, 1,
	            true);
	mesh *walls = sg_mesh_new(sc, grey(0.6), "walls");
	for (int f = 0; f < NFACES; f++)
		if (f != F_NY && f != F_PY)
			sg_box_face(walls, &room, f, 1, true);
	mesh *pil = sg_mesh_new(sc, grey(0.6), "pillars");
	for (int i = 0; i < c->pillars_x * c->pillars_z; i++) {
		obox b = {pillar_at(c, i),
		          P(c->pillar / 2, c->h / 2, c->pillar / 2), 0};
		sg_box(pil, &b, OMIT_ENDS);
	}
	/* Doors and windows are opaque quads 1 mm in front of the walls. */
	mesh *doors = sg_mesh_new(sc, rgb(0.3, 0.2, 0.12), "doors");
	for (int i = 0; i < c->doors; i++) {
		double z = (i + 1) * c->d / (c->doors + 1);
		sg_rect_in(doors, P(0.001, 0, z - 0.6), P(1, 2.4, z + 0.6),
		           F_NX);
	}
	mesh *win = sg_mesh_new(sc, grey(0.08), "windows");
	for (int i = 0; i < c->windows; i++) {
		double z = (i + 1) * c->d / (c->windows + 1);
		sg_rect_in(win, P(c->w - 1, 1.2, z - 1),
		           P(c->w - 0.001, 3.2, z + 1), F_PX);
	}
	for (int i = 0; i < 16; i++)
		sg_panel_down(
		        sg_mesh_new(sc, emitter(c->lum), "source_%02d", i + 1),
		        (i % 4 + 0.5) * c->w / 4, c->h - 0.001,
		        (i / 4 + 0.5) * c->d / 4, c->panel);
}

/* A chair facing +z in its frame: seat, four legs, backrest. */
static void chair(mesh *me, frame f)
{
	sg_fbox(me, f, P(0, 0.45, 0), P(0.21, 0.02, 0.21), 0);
	for (int i = 0; i < 4; i++)
		sg_fbox(me, f,
		        P(i & 1 ? 0.18 : -0.18, 0.215, i & 2 ? 0.18 : -0.18),
		        P(0.02, 0.215, 0.02), OMIT_ENDS);
	sg_fbox(me, f, P(0, 0.69, -0.19), P(0.21, 0.22, 0.02), OMIT_BOTTOM);
}

/* A table with chairs on both long sides; a vase and fruit on the top. */
static void table_set(mesh *wood, mesh *ware, frame f, const hall_cfg *c,
                      uint64_t *rng)
{
	sg_fbox(wood, f, P(0, 0.74, 0), P(0.8, 0.02, 0.45), 0);
	for (int i = 0; i < 4; i++)
		sg_fbox(wood, f,
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
	sg_cylinder(ware, fpt(f, P(rng_range(rng, -.5, .5), 0.76, 0)), 0.06,
	            0.25, 16, CAP_TOP);
	for (int i = 0; i < c->fruit; i++) {
		double r = rng_range(rng, 0.04, 0.08);
		p3 at = fpt(f, P(rng_range(rng, -.6, .6), 0.76 + r,
		                 rng_range(rng, -.3, .3)));
		sg_ellipsoid(ware, at, P(r, r, r), 0, c->fruit_slices,
		             c->fruit_slices / 2);
	}
}

/* A 1 x 0.4 x 2 m shelf unit, back on the wall, facing +z in its frame:
 * two sides, a back, five boards, books on the lower four. */
static void shelf_unit(mesh *wood, mesh *books, frame f, int nbooks,
                       uint64_t *rng)
{
	for (int s = -1; s <= 1; s += 2)
		sg_fbox(wood, f, P(0.49 * s, 1.0, 0.2), P(0.01, 1.0, 0.2),
		        OMIT_BOTTOM);
	sg_fbox(wood, f, P(0, 1.0, 0.005), P(0.48, 1.0, 0.005), OMIT_BOTTOM);
	for (int b = 0; b < 5; b++) {
		double y = 0.08 + 0.475 * b, x = -0.46;
		sg_fbox(wood, f, P(0, y, 0.205), P(0.48, 0.01, 0.195), 0);
		for (int k = 0; b < 4 && k < nbooks; k++) {
			double t = rng_range(rng, 0.02, 0.05);
			double hb = rng_range(rng, 0.18, 0.3);
			sg_fbox(books, f, P(x + t / 2, y + 0.01 + hb / 2, 0.22),
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
		        sg_mesh_new(sc, rgb(0.45, 0.3, 0.18), "table_%03d", i);
		mesh *ware =
		        sg_mesh_new(sc, *palette(&rng), "tableware_%03d", i);
		table_set(wood, ware, f, c, &rng);
	}
	for (int i = 0; i < 2 * c->shelves; i++) {
		bool far = i >= c->shelves;
		double x = (i % c->shelves + 0.5) * c->w / c->shelves;
		frame f = {P(x, 0, far ? c->d - 0.001 : 0.001), far ? PI : 0};
		shelf_unit(
		        sg_mesh_new(sc, rgb(0.5, 0.35, 0.2), "shelf_%03d", i),
		        sg_mesh_new(sc, *palette(&rng), "books_%03d", i), f,
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

void sg_build_hall_empty(scene *sc, const params *p)
{
	build_hall(sc, p, &hall_empty);
}

void sg_build_hall_full(scene *sc, const params *p)
{
	build_hall(sc, p, &hall_full);
}

void sg_build_hall_bright(scene *sc, const params *p)
{
	build_hall(sc, p, &hall_bright);
}

void sg_build_hall_grand(scene *sc, const params *p)
{
	build_hall(sc, p, &hall_grand);
}
