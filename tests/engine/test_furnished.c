/*
 * test_furnished.c -- lux on a furnished room against the independent
 * estimator, not against another luxrad solver.
 *
 * scenes/office.gltf (desk, chair, window opening, two ceiling panels and
 * a desk lamp) is solved by hr and rmb with nothing set (the defaults a
 * user gets) and queried on a 0.8 m work plane; luxrad-reference's path
 * tracer gives the same points with a standard error s per point.  Each
 * point must lie within the default accuracy target (2 %) plus 3 s of
 * the reference.  (error_lux is not held to it here: it leaves out most
 * of the solution's own error and covers 7 of these 20 points.)
 *
 * Points 2 cm from two walls on the floor are left out: there both
 * solvers read 2-4 % high (the walls' leaves are brighter on average
 * than near the corner), a miss the validation study reports
 * (tests/bench/validate.sh), not one this test hides under a wider bound.
 *
 * The bright hall (luxrad-scenegen hall-bright) is held to the same bound
 * on its own 0.8 m work plane: its 16 emitting panels hang 1 mm below the
 * ceiling, and the ceiling's elements that straddle a panel's edge must
 * neither lose the covered part's light twice nor send from behind the
 * panel (hier.h, Covered parts; without that hr read 3.7 % low).
 *
 * A bare bulb (a small black emitting cube written twice over, both ways,
 * as the hospital room's bedside lamps are) beside a floor and a wall.
 * Written so, the inside of the bulb gathered twice what it sent and hr's
 * energy bound dimmed the whole scene (hr read 4.6 % low until a black
 * receiver was held to a full view, hr.c); now that a scene drops
 * repeated triangles at commit (scene.c) the copies no longer reach the
 * solvers, and the test holds the bare bulb, each face once each way, to
 * the reference.
 *
 * A ceiling luminaire half covered by a black board 1 mm below it
 * (luminaire_half_covered).
 *
 * Far closed objects that a loose final gather takes whole
 * (test_far_closed_objects_seen).
 *
 * A room whose slabs and walls run past its corners (test_slab_room).
 *
 * A thin luminaire whose edges light the ceiling they touch
 * (test_room_with_thin_luminaire).
 *
 * The far side of a plate's shadow on the floor, read through the ceiling
 * elements a panel partly covers (test_plate_shadow_far_side).
 *
 * Closed rooms keep their power (test_closed_rooms_keep_their_power):
 * what the leaves absorb equals what the emitters send, exactly, in a
 * room nothing leaves.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "generated.h"
#include "leaf_area.h"
#include "rad.h"
#include "rad_reference.h"
#include "sceneio.h"

#define NX 5
#define NZ 4
#define NPTS (NX * NZ)
#define MAXPTS 25
#define TARGET 0.02 /* the default accuracy (RAD_ACCURACY_DEFAULT) */

static void work_plane(double pts[NPTS][6])
{
	for (int i = 0; i < NX; i++)
		for (int j = 0; j < NZ; j++) {
			double *p = pts[i * NZ + j];
			p[0] = 0.4 + i * 0.8;
			p[1] = 0.8;
			p[2] = 0.4 + j * 2.2 / 3;
			p[3] = 0;
			p[4] = 1;
			p[5] = 0;
		}
}

static rad_scene *load_office(void)
{
	const char *path = LUXRAD_SOURCE_DIR "/scenes/office.gltf";
	rad_scene *s = NULL;
	rad_error err;
	if (sio_load_file(path, &s, NULL, &err))
		fail_msg("load %s: %s", path, err.msg);
	return s;
}

/* A solver of the given kind at the defaults, 2 threads, converged. */
static rad_solver *converged_solver(const rad_scene *s, rad_solver_kind kind)
{
	rad_options o;
	rad_options_default(&o);
	o.solver = kind;
	o.threads = 2;
	rad_solver *sv = NULL;
	rad_error err;
	assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
	assert_int_equal(rad_solver_converge(sv, 0, 200, &err), RAD_OK);
	return sv;
}

/* luxrad-reference's lux and standard errors at n points (0.4 %). */
static void reference_lux(const rad_scene *s, const double pts[][6], int n,
                          double ref[], double sd[])
{
	rad_ref_options ro;
	rad_ref_options_default(&ro);
	ro.target_error = 0.004;
	ro.threads = 2;
	rad_error err;
	assert_int_equal(rad_reference_illuminance(s, &pts[0][0], (size_t)n,
	                                           &ro, ref, sd, NULL, &err),
	                 RAD_OK);
}

/* A converged solver of the given kind at the defaults, queried at n
 * points: lux and error_lux (el may be NULL). */
static void solved_lux(const rad_scene *s, rad_solver_kind kind,
                       const double pts[][6], int n, double lux[], double el[])
{
	rad_solver *sv = converged_solver(s, kind);
	rad_error err;
	assert_true(n <= MAXPTS);
	assert_int_equal(
	        rad_solver_query(sv, &pts[0][0], (size_t)n, 0, lux, el, &err),
	        RAD_OK);
	rad_solver_free(sv);
}

/* Each point within the target plus 3 standard errors; returns the mean
 * signed relative error. */
static double check_solver(const rad_scene *s, rad_solver_kind kind,
                           const double pts[][6], int n, const double ref[],
                           const double sd[])
{
	double lux[MAXPTS], el[MAXPTS];
	solved_lux(s, kind, pts, n, lux, el);
	double worst = 0, mean = 0;
	for (int i = 0; i < n; i++) {
		double e = (lux[i] - ref[i]) / ref[i];
		mean += e / n;
		print_message("%s point %2d: %8.2f lux, reference %8.2f +- "
		              "%.2f, %+.2f %%, error_lux %.2f\n",
		              rad_solver_kind_name(kind), i, lux[i], ref[i],
		              sd[i], 100 * e, el[i]);
		if (fabs(e) > fabs(worst))
			worst = e;
		assert_true(fabs(lux[i] - ref[i]) <=
		            TARGET * ref[i] + 3 * sd[i]);
	}
	print_message("%s: worst %+.2f %%, mean %+.2f %%\n",
	              rad_solver_kind_name(kind), 100 * worst, 100 * mean);
	return mean;
}

/*
 * Hold hr and rmb, at the defaults, to luxrad-reference on the n points
 * (0.4 % standard error): each within the target plus 3 standard errors.
 * Frees the scene.
 */
static void hold_to_reference(rad_scene *s, const double pts[][6], int n)
{
	double ref[MAXPTS], sd[MAXPTS];
	assert_true(n <= MAXPTS);
	reference_lux(s, pts, n, ref, sd);
	check_solver(s, RAD_SOLVER_HR, pts, n, ref, sd);
	check_solver(s, RAD_SOLVER_RMB, pts, n, ref, sd);
	rad_scene_free(s);
}

static void test_office_work_plane(void **state)
{
	(void)state;
	rad_scene *s = load_office();
	double pts[NPTS][6];
	work_plane(pts);
	hold_to_reference(s, pts, NPTS);
}

/* Quad a b c d (counter-clockwise seen from its front) as 2 triangles. */
static void add_quad(rad_scene *s, uint32_t mat, uint32_t node,
                     const double q[4][3], int flip)
{
	static const int fwd[6] = {0, 1, 2, 0, 2, 3},
	                 rev[6] = {0, 2, 1, 0, 3, 2};
	double t[18];
	rad_error err;
	for (int k = 0; k < 6; k++)
		memcpy(&t[3 * k], q[(flip ? rev : fwd)[k]], sizeof(double[3]));
	assert_int_equal(rad_scene_add_triangles(s, mat, node, t, 2, &err),
	                 RAD_OK);
}

/* A material, its id. */
static uint32_t material(rad_scene *s, const double rho[3], const double lum[3])
{
	uint32_t id;
	rad_error err;
	assert_int_equal(rad_scene_add_material(s, rho, lum, &id, &err),
	                 RAD_OK);
	return id;
}

/* A new scene: a 4 x 4 m grey (0.5) floor and a 4 x 3 m wall at z = 0,
 * on node *node, to which a case adds its light. */
static rad_scene *floor_and_wall(uint32_t *node)
{
	rad_scene *s = NULL;
	rad_error err;
	const double grey[3] = {0.5, 0.5, 0.5}, dark[3] = {0, 0, 0};
	const double floor[4][3] = {{0, 0, 0}, {0, 0, 4}, {4, 0, 4}, {4, 0, 0}};
	const double wall[4][3] = {{0, 0, 0}, {4, 0, 0}, {4, 3, 0}, {0, 3, 0}};
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	uint32_t room = material(s, grey, dark);
	assert_int_equal(rad_scene_add_node(s, "room", node, &err), RAD_OK);
	add_quad(s, room, *node, floor, 0);
	add_quad(s, room, *node, wall, 0);
	return s;
}

/* A cube of half-side a centred at c, its faces outwards (as in
 * test_solver's box, seen from outside), each face written `copies`
 * times, every other copy turned over. */
static void add_cube(rad_scene *s, uint32_t mat, uint32_t node,
                     const double c[3], double a, int copies)
{
	static const double u[6][4][3] = {
	        {{0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}},
	        {{0, 1, 0}, {0, 1, 1}, {1, 1, 1}, {1, 1, 0}},
	        {{0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}},
	        {{1, 0, 0}, {1, 1, 0}, {1, 1, 1}, {1, 0, 1}},
	        {{0, 0, 0}, {0, 1, 0}, {1, 1, 0}, {1, 0, 0}},
	        {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}},
	};
	for (int f = 0; f < 6; f++) {
		double q[4][3];
		for (int v = 0; v < 4; v++)
			for (int k = 0; k < 3; k++)
				q[v][k] = c[k] + a * (2 * u[f][v][k] - 1);
		for (int copy = 0; copy < copies; copy++)
			add_quad(s, mat, node, (const double(*)[3])q, copy & 1);
	}
}

static rad_scene *bulb_by_wall(void)
{
	rad_error err;
	const double black[3] = {0, 0, 0}, bright[3] = {2e4, 2e4, 2e4};
	uint32_t node;
	rad_scene *s = floor_and_wall(&node);
	uint32_t bulb = material(s, black, bright);
	/* A 5 cm cube 0.2 m off the wall, each face written four times. */
	const double c[3] = {2, 1.5, 0.2};
	add_cube(s, bulb, node, c, 0.025, 4);
	assert_int_equal(rad_scene_commit(s, &err), RAD_OK);
	return s;
}

static void test_bulb_written_twice(void **state)
{
	(void)state;
	rad_scene *s = bulb_by_wall();
	double pts[MAXPTS][6];
	int n = 0;
	for (int i = 0; i < 4; i++) {
		for (int j = 0; j < 2; j++) {
			double *p = pts[n++];
			p[0] = 0.5 + i;
			p[1] = j ? 0.8 : 0.01;
			p[2] = 0.5 + 0.8 * j + 0.5 * i;
			p[3] = p[5] = 0;
			p[4] = 1;
		}
	}
	hold_to_reference(s, pts, n);
}

/*
 * Far closed objects in the final gather: 144 white 10 cm cubes on a
 * black floor under a point light, read from points above them that face
 * down, so that all their light is what the cubes reflect.  With a loose
 * query tolerance (0.3) the gather takes far clusters whole.  It used to
 * test such a cluster's visibility on one ray to its box centre, which
 * lies inside a cube, and dropped the cubes so taken: -29 to -35 % here
 * (and 0.4 % of the light on test_blender's office ceiling, from its
 * shelf of books).  Now -6 to -13 %; held within 20 % of the reference,
 * what a gather that loose, taking clusters whole on a few rays and by
 * their projected-area model, allows.
 */
static rad_scene *cubes_on_black_floor(void)
{
	rad_error err;
	const double black[3] = {0, 0, 0}, white[3] = {0.8, 0.8, 0.8};
	rad_scene *s = NULL;
	uint32_t node;
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "room", &node, &err), RAD_OK);
	uint32_t dark = material(s, black, black);
	uint32_t cube = material(s, white, black);
	const double floor[4][3] = {{0, 0, 0}, {0, 0, 6}, {6, 0, 6}, {6, 0, 0}};
	add_quad(s, dark, node, floor, 0);
	for (int i = 0; i < 144; i++) {
		const double c[3] = {0.8 + 0.4 * (i % 12), 0.05,
		                     0.8 + 0.4 * (i / 12)};
		add_cube(s, cube, node, c, 0.05, 1);
	}
	rad_light_desc L;
	memset(&L, 0, sizeof(L));
	L.kind = RAD_LIGHT_POINT;
	L.position[0] = L.position[2] = 3;
	L.position[1] = 4;
	L.intensity[0] = L.intensity[1] = L.intensity[2] = 1000;
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_OK);
	assert_int_equal(rad_scene_commit(s, &err), RAD_OK);
	return s;
}

static void test_far_closed_objects_seen(void **state)
{
	(void)state;
	rad_scene *s = cubes_on_black_floor();
	double pts[6][6], ref[6], sd[6], lux[6];
	for (int i = 0; i < 6; i++) {
		double *p = pts[i];
		p[0] = 1 + 2 * (i / 2);
		p[1] = 2 + i % 2;
		p[2] = 1.5 + 2 * (i % 2);
		p[3] = p[5] = 0;
		p[4] = -1;
	}
	reference_lux(s, (const double(*)[6])pts, 6, ref, sd);
	rad_solver *sv = converged_solver(s, RAD_SOLVER_HR);
	rad_error err;
	/* A loose gather: far clusters are taken whole. */
	assert_int_equal(
	        rad_solver_query(sv, &pts[0][0], 6, 0.3, lux, NULL, &err),
	        RAD_OK);
	for (int i = 0; i < 6; i++) {
		double e = lux[i] / ref[i] - 1;
		print_message("point %d: %.4f lux, reference %.4f, %+.1f %%\n",
		              i, lux[i], ref[i], 100 * e);
		assert_true(fabs(e) < 0.2);
	}
	rad_solver_free(sv);
	rad_scene_free(s);
}

/*
 * A ceiling luminaire half covered by a black board 1 mm below it, over
 * a floor and a wall, the points near the wall and out in the room: the
 * covered half sends nothing, directly or by reflection (hier.h, Covered
 * parts).  Measured: these lux do not change when the emitter's exposed
 * share of E (node_exposed_emission) is left out, so this holds the case
 * to the reference but does not guard that line.
 */
/*
 * The link audit (rad_reference.h) on the cubes.  Its Monte Carlo shares
 * no form-factor code with the solvers; where their form factors are
 * exact (pairs of surfaces, not near: the exact point-to-polygon kernel)
 * it agrees with them to 3 %, for hr and rmb.  The other classes are
 * printed: that is what the audit is for (hr's far cluster sources here
 * move 3.0 to 3.6 times their transfer, depending on which third of the
 * links is drawn: the projected-area model of a cube; their form-factor
 * ratio, 0.64 or 1.45, is ruled by a few large links).  It refuses the
 * solvers that keep no links and a zero sampling rate.
 */
static void audit_solver(const rad_scene *s, rad_solver_kind kind)
{
	rad_solver *sv = converged_solver(s, kind);
	rad_audit_options o;
	rad_audit au;
	rad_error err;
	rad_audit_options_default(&o);
	o.every = 3;
	o.samples = 256;
	assert_int_equal(rad_solver_audit_links(sv, &o, &au, &err), RAD_OK);
	assert_true(au.links_total > 0 && au.rays > 0);
	for (int k = 0; k < RAD_AUDIT_CLASSES; k++) {
		const rad_audit_class *c = &au.cls[k];
		if (c->links)
			print_message("%s class %d: %llu links, F stored/MC "
			              "%.4f, moved/MC %.4f\n",
			              rad_solver_kind_name(kind), k,
			              (unsigned long long)c->links,
			              c->stored_form / c->mc_form,
			              c->stored_transfer / c->mc_transfer);
	}
	const rad_audit_class *ss = &au.cls[0]; /* surface <- surface */
	assert_true(ss->links > 0);
	assert_true(fabs(ss->stored_form / ss->mc_form - 1) < 0.03);
	o.every = 0;
	assert_int_equal(rad_solver_audit_links(sv, &o, &au, &err),
	                 RAD_ERR_INVALID);
	rad_solver_free(sv);
}

static void test_audit_links(void **state)
{
	(void)state;
	rad_scene *s = cubes_on_black_floor();
	audit_solver(s, RAD_SOLVER_HR);
	audit_solver(s, RAD_SOLVER_RMB);
	static const rad_solver_kind others[] = {RAD_SOLVER_MATRIX,
	                                         RAD_SOLVER_PROGRESSIVE};
	for (int i = 0; i < 2; i++) {
		rad_options o;
		rad_options_default(&o);
		o.solver = others[i];
		o.threads = 1;
		rad_solver *sv = NULL;
		rad_audit au;
		rad_error err;
		assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
		assert_int_equal(rad_solver_audit_links(sv, NULL, &au, &err),
		                 RAD_ERR_UNSUPPORTED);
		rad_solver_free(sv);
	}
	rad_scene_free(s);
}

/*
 * Points inside closed objects (rad_scene_points_inside): the centre of a
 * cube, whatever the normal, is inside; beside the cubes, above them
 * (looking up into the open or down onto a cube's top) and a NaN point
 * are not.
 */
static void test_points_inside(void **state)
{
	(void)state;
	rad_scene *s = cubes_on_black_floor();
	const double pts[][6] = {
	        {0.8, 0.05, 0.8, 0, 1, 0},  {0.8, 0.05, 0.8, 1, 0, 0},
	        {0.8, 0.05, 0.8, 0, 0, -1}, {1.0, 0.05, 0.8, 0, 1, 0},
	        {0.8, 0.5, 0.8, 0, 1, 0},   {0.8, 0.5, 0.8, 0, -1, 0},
	        {NAN, 0.05, 0.8, 0, 1, 0},  {0.8, 0.05, 0.8, 0, 0, 0},
	};
	const unsigned char want[] = {1, 1, 1, 0, 0, 0, 0, 0};
	size_t n = sizeof(want);
	unsigned char in[sizeof(want)];
	rad_error err;
	assert_int_equal(rad_scene_points_inside(s, &pts[0][0], n, in, &err),
	                 RAD_OK);
	for (size_t i = 0; i < n; i++)
		assert_int_equal(in[i], want[i]);
	rad_scene_free(s);
	rad_scene *open = NULL;
	assert_int_equal(rad_scene_new(&open, &err), RAD_OK);
	assert_int_equal(rad_scene_points_inside(open, &pts[0][0], 1, in, &err),
	                 RAD_ERR_STATE);
	rad_scene_free(open);
}

static rad_scene *luminaire_half_covered(void)
{
	rad_error err;
	const double black[3] = {0, 0, 0}, lum[3] = {2000, 2000, 2000};
	uint32_t node;
	rad_scene *s = floor_and_wall(&node);
	uint32_t lamp = material(s, black, lum),
	         board = material(s, black, black);
	/* Facing down: the panel at 2.5 m, the board over its x < 2 half. */
	const double panel[4][3] = {{1.5, 2.5, 1.5},
	                            {2.5, 2.5, 1.5},
	                            {2.5, 2.5, 2.5},
	                            {1.5, 2.5, 2.5}};
	const double cover[4][3] = {{1.4, 2.499, 1.4},
	                            {2, 2.499, 1.4},
	                            {2, 2.499, 2.6},
	                            {1.4, 2.499, 2.6}};
	add_quad(s, lamp, node, panel, 0);
	add_quad(s, board, node, cover, 0);
	assert_int_equal(rad_scene_commit(s, &err), RAD_OK);
	return s;
}

static void test_luminaire_half_covered(void **state)
{
	(void)state;
	rad_scene *s = luminaire_half_covered();
	double pts[MAXPTS][6];
	int n = 0;
	for (int i = 0; i < 4; i++)
		for (int j = 0; j < 2; j++) {
			double *p = pts[n++];
			p[0] = 0.5 + i;
			p[1] = j ? 0.8 : 0.01;
			p[2] = j ? 0.3 : 0.5 + i; /* near the wall, and out */
			p[3] = p[5] = 0;
			p[4] = 1;
		}
	hold_to_reference(s, pts, n);
}

/* A 5 x 5 work plane at 0.8 m: x0 + i dx, z0 + j dz. */
static void grid_5x5(double pts[MAXPTS][6], double x0, double dx, double z0,
                     double dz)
{
	for (int i = 0; i < 5; i++)
		for (int j = 0; j < 5; j++) {
			double *p = pts[i * 5 + j];
			p[0] = x0 + dx * i;
			p[1] = 0.8;
			p[2] = z0 + dz * j;
			p[3] = p[5] = 0;
			p[4] = 1;
		}
}

static void test_hall_covered_ceiling(void **state)
{
	(void)state;
	rad_scene *s = generated_scene("hall-bright"); /* 24 x 6 x 16 m */
	double pts[MAXPTS][6];
	grid_5x5(pts, 1, 5.5, 1, 3.5);
	hold_to_reference(s, pts, MAXPTS);
}

/*
 * A room as architectural exports write it (luxrad-scenegen slabroom):
 * floor, ceiling and walls run 0.3 m past its corners.  The parts beyond
 * are dark, and before the commit cut those polygons along the walls
 * (conform.c) hr read the work plane 3-10 % low.  The polygons must come
 * out cut: six large ones, each along two lines.
 */
static void test_slab_room(void **state)
{
	(void)state;
	rad_scene *s = generated_scene("slabroom"); /* 4 x 3 x 4 m inside */
	rad_scene_counts c;
	rad_scene_counts_get(s, &c);
	assert_int_equal(c.polygons_cut, 6);
	double pts[MAXPTS][6];
	grid_5x5(pts, 0.5, 0.75, 0.5, 0.75);
	hold_to_reference(s, pts, MAXPTS);
}

/*
 * A closed room lit by a thin luminaire under its ceiling
 * (luxrad-scenegen thinlum: a 0.75 m square box 1 cm deep, all five faces
 * emitting).  The sides send 5 % of the light, and half of it lands on
 * the ceiling within a few centimetres of them.  Seen from the centres
 * of a large ceiling element and of a side, the pair grazes (cosine
 * 0.01) and the element's sample points lie decimetres from where the
 * light lands: the pair was estimated negligible and its form factor
 * came out tens of times too small.  Each point within the target, and
 * the plane's mean error (the light the solution gained or lost; 0.08 %
 * standard error over 25 points) within 1 %: hr read -2.2 % (rmb
 * -1.5 %), every point low, before thin sources near large receivers
 * were estimated and integrated from the source's side (ff.c
 * near_estimate, hr_nodes.c small_source_near); -0.8 % now.
 */
static void test_room_with_thin_luminaire(void **state)
{
	(void)state;
	rad_scene *s = generated_scene("thinlum");
	double pts[MAXPTS][6], ref[MAXPTS], sd[MAXPTS];
	grid_5x5(pts, 0.4, 0.8, 0.4, 0.8);
	reference_lux(s, pts, MAXPTS, ref, sd);
	assert_true(fabs(check_solver(s, RAD_SOLVER_HR, pts, MAXPTS, ref, sd)) <
	            0.01);
	assert_true(fabs(check_solver(s, RAD_SOLVER_RMB, pts, MAXPTS, ref,
	                              sd)) < 0.01);
	rad_scene_free(s);
}

/* Mean |relative error| of a solver's lux at n points. */
static double mean_abs_error(const rad_scene *s, rad_solver_kind kind,
                             const double pts[][6], int n, const double ref[])
{
	double lux[MAXPTS], mean = 0;
	solved_lux(s, kind, pts, n, lux, NULL);
	for (int i = 0; i < n; i++)
		mean += fabs(lux[i] - ref[i]) / ref[i] / n;
	print_message("%s: mean |error| %.2f %%\n", rad_solver_kind_name(kind),
	              100 * mean);
	return mean;
}

/*
 * luxrad-scenegen obstructed (rho 0.5): a 1 m2 panel 1 mm under the
 * ceiling, and a black plate under part of it.  The ceiling's elements
 * around the panel are partly covered.  The query took them whole when
 * far: their children's mean radiosity, which counts the dark part
 * behind the panel, times the share of them seen on five rays, which the
 * panel blocks again.  It now reads each child's radiosity as that of
 * its exposed part, goes down to the leaves of an element partly
 * covered, and reads the share of such a leaf seen on the points that
 * measured its exposed fraction (query.c, covered_ff).  The floor beyond
 * the shadow's edge had read low: these 10 points
 * (scenes/validation/obstructed.points, x 2.5-3.5 m on its two lines)
 * 1.48 % on average under hr and 1.96 % under rmb; 0.86 % and 1.34 %
 * since.
 */
static void test_plate_shadow_far_side(void **state)
{
	(void)state;
	rad_scene *s = generated_scene("obstructed --rho 0.5");
	double pts[10][6], ref[10], sd[10];
	for (int i = 0; i < 10; i++) {
		double *p = pts[i];
		p[0] = 2.5 + 0.25 * (i % 5);
		p[1] = 0.001;
		p[2] = i < 5 ? 2.0 : 1.7;
		p[3] = p[5] = 0;
		p[4] = 1;
	}
	reference_lux(s, pts, 10, ref, sd);
	assert_true(mean_abs_error(s, RAD_SOLVER_HR, pts, 10, ref) < 0.012);
	assert_true(mean_abs_error(s, RAD_SOLVER_RMB, pts, 10, ref) < 0.017);
	rad_scene_free(s);
}

/*
 * The power a solution's leaves absorb, sum of (1 - rho) I A, in lm:
 * photopic, rho per node (each node of the rooms below has one material).
 */
typedef struct absorbed {
	double rho[16][3];
	double lm;
} absorbed;

static void absorb_leaf(void *ud, uint32_t node, const double p[4][3], int nv,
                        const double radiosity[3], const double irradiance[3])
{
	absorbed *a = ud;
	(void)radiosity;
	assert_true(node < 16);
	double area = leaf_area(p, nv);
	const double w[3] = {RAD_LUMA_R, RAD_LUMA_G, RAD_LUMA_B};
	for (int j = 0; j < 3; j++)
		a->lm += w[j] * (1 - a->rho[node][j]) * irradiance[j] * area;
}

/*
 * A closed room loses nothing: its leaves absorb what its emitters send.
 * luxrad-scenegen thinlum and cove hang a 0.75 m luminaire 1 cm deep
 * under a 4 m ceiling, and none of the ceiling's 16 scattered points
 * fell under it.  Its quarters inherited "wholly exposed", so the
 * ceiling elements around the luminaire paid for it twice when they
 * sent (hier.h, Covered parts): their mean radiosity counted the dark
 * part behind it, and their sample points there were blocked again.  hr
 * kept 87 % of the cove's power so (rmb 86 %; thinlum 98.6 % and 97.6 %)
 * until every quarter measured its own exposed fraction (hier.c,
 * rad_elem_split).  Now hr keeps 99 %, rmb 98 %: the bound is 3 %.
 */
static void test_closed_rooms_keep_their_power(void **state)
{
	(void)state;
	static const char *kinds[] = {"thinlum", "cove"};
	static const rad_solver_kind solvers[] = {RAD_SOLVER_HR,
	                                          RAD_SOLVER_RMB};
	for (int i = 0; i < 2; i++) {
		rad_scene *s = generated_scene(kinds[i]);
		absorbed a = {0};
		rad_scene_counts n;
		rad_scene_counts_get(s, &n);
		for (uint32_t k = 0; k < n.polygons; k++) {
			rad_polygon_desc d;
			rad_error err;
			assert_int_equal(rad_scene_polygon_get(s, k, &d, &err),
			                 RAD_OK);
			assert_true(d.node < 16);
			memcpy(a.rho[d.node], d.reflectance,
			       sizeof(d.reflectance));
		}
		rad_emitter em[16];
		int more = 0;
		uint32_t ne = rad_scene_emitters(s, em, 16, &more);
		assert_false(more);
		double sent = 0;
		for (uint32_t k = 0; k < ne; k++)
			sent += em[k].flux_lm;
		for (int j = 0; j < 2; j++) {
			rad_solver *sv = converged_solver(s, solvers[j]);
			a.lm = 0;
			rad_solver_leaves(sv, absorb_leaf, &a);
			print_message("%s %s: sent %.2f lm, absorbed %.2f lm "
			              "(%.4f)\n",
			              kinds[i],
			              rad_solver_kind_name(solvers[j]), sent,
			              a.lm, a.lm / sent);
			assert_true(fabs(a.lm / sent - 1) < 0.03);
			rad_solver_free(sv);
		}
		rad_scene_free(s);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_office_work_plane),
	        cmocka_unit_test(test_hall_covered_ceiling),
	        cmocka_unit_test(test_bulb_written_twice),
	        cmocka_unit_test(test_far_closed_objects_seen),
	        cmocka_unit_test(test_audit_links),
	        cmocka_unit_test(test_points_inside),
	        cmocka_unit_test(test_luminaire_half_covered),
	        cmocka_unit_test(test_slab_room),
	        cmocka_unit_test(test_room_with_thin_luminaire),
	        cmocka_unit_test(test_plate_shadow_far_side),
	        cmocka_unit_test(test_closed_rooms_keep_their_power),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
