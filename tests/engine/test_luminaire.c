/*
 * test_luminaire.c -- a point light with a photometric file's candela
 * table (rad_light_desc.candela), against the file.
 *
 * Black scenes, so what a point reads is the direct light alone:
 *   - under the luminaire, 3 m above a large floor, E = I(C, gamma) cos /
 *     d^2 with I the file's own value in the directions of its grid (the
 *     closed form its values were written from, test_photometry.c) and
 *     the linear mean of two planes between them: from the solver's query
 *     and from the Monte Carlo reference;
 *   - inside a closed box around it, the illuminance integrated over the
 *     walls is the luminaire's flux: the file's declared lumens and the
 *     table's integral (pho_lumens), within 0.5 %; and the scene's flux
 *     estimate is that integral.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>

#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "closed_forms.h"
#include "photometry.h"
#include "photometry_data.h"
#include "rad.h"
#include "rad_reference.h"
#include "scene.h"

#define HEIGHT 3.0

static pho_table *load(const char *name)
{
	char err[256];
	size_t len;
	char *b = pho_sample(name, &len);
	pho_table *t = NULL;
	if (pho_parse(b, len, NULL, &t, err, sizeof err) != PHO_OK)
		fail_msg("%s: %s", name, err);
	free(b);
	return t;
}

/* full_2002.ies: no symmetry, values 100 + 40 cos C + 25 sin C + 10 cos 2C
 * times (1 + gamma / 60), candela. */
static double file_cd(double c_deg, double g_deg)
{
	double c = c_deg * M_PI / 180;
	return (100 + 40 * cos(c) + 25 * sin(c) + 10 * cos(2 * c)) *
	       (1 + g_deg / 60);
}

static void quad(rad_scene *s, uint32_t mat, uint32_t node, const double p[3],
                 const double e1[3], const double e2[3])
{
	double t[18];
	for (int k = 0; k < 3; k++) {
		t[k] = p[k];
		t[3 + k] = p[k] + e1[k];
		t[6 + k] = p[k] + e1[k] + e2[k];
		t[9 + k] = p[k];
		t[12 + k] = p[k] + e1[k] + e2[k];
		t[15 + k] = p[k] + e2[k];
	}
	rad_error err;
	assert_int_equal(rad_scene_add_triangles(s, mat, node, t, 2, &err),
	                 RAD_OK);
}

/* A black scene with the luminaire at pos, shining down -z, C0 along +x;
 * box: a closed cube of half side 2 around it, else a 40 m floor. */
static rad_scene *scene_with(const pho_table *t, const double pos[3], int box)
{
	rad_scene *s;
	rad_error err;
	const double black[3] = {0, 0, 0};
	uint32_t mat, node;
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	assert_int_equal(rad_scene_add_material(s, black, black, &mat, &err),
	                 RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "walls", &node, &err), RAD_OK);
	if (!box) {
		const double p[3] = {-20, -20, 0}, e1[3] = {40, 0, 0},
		             e2[3] = {0, 40, 0};
		quad(s, mat, node, p, e1, e2);
	}
	for (int f = 0; box && f < 6; f++) {
		/* Face f: axis a = f / 2 at -2 (even f) or +2, facing in. */
		int a = f / 2, b = (a + 1) % 3, c = (a + 2) % 3;
		double p[3], e1[3] = {0}, e2[3] = {0};
		p[a] = pos[a] + (f % 2 ? 2 : -2);
		p[b] = pos[b] - 2;
		p[c] = pos[c] - 2;
		e1[b] = 4;
		e2[c] = 4;
		if (f % 2)
			quad(s, mat, node, p, e2, e1);
		else
			quad(s, mat, node, p, e1, e2);
	}
	rad_light_desc L = {.kind = RAD_LIGHT_POINT,
	                    .position = {pos[0], pos[1], pos[2]},
	                    .direction = {0, 0, -1},
	                    .intensity = {1, 1, 1},
	                    .candela = pho_table_grid(t),
	                    .c0_axis = {1, 0, 0},
	                    .name = "luminaire"};
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_OK);
	assert_int_equal(rad_scene_commit(s, &err), RAD_OK);
	return s;
}

static rad_solver *solver_on(const rad_scene *s)
{
	rad_options o;
	rad_error err;
	rad_solver *sv;
	rad_options_default(&o);
	o.solver = RAD_SOLVER_HR;
	o.threads = 2;
	assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
	assert_int_equal(rad_solver_converge(sv, 1e-3, 10, &err), RAD_OK);
	return sv;
}

/* The Monte Carlo reference at n points, `paths` paths each. */
static void reference_lux(const rad_scene *s, const double *pts, size_t n,
                          uint64_t paths, double *lux)
{
	rad_ref_options ro;
	rad_error err;
	rad_ref_options_default(&ro);
	ro.samples = paths;
	if (rad_reference_illuminance(s, pts, n, &ro, lux, NULL, NULL, &err) !=
	    RAD_OK)
		fail_msg("reference: %s", err.msg);
}

static void test_floor_under_the_luminaire_reads_the_file(void **state)
{
	(void)state;
	pho_table *t = load("full_2002.ies");
	const double pos[3] = {0, 0, HEIGHT};
	rad_scene *s = scene_with(t, pos, 0);
	rad_solver *sv = solver_on(s);
	/* Planes of the file (0, 90, 180, 270) and halfway (45, 225); the
	 * values are linear in gamma, so 25 and 75 are exact too.  Not the
	 * nadir: there every plane meets, and this file's planes differ. */
	const double cs[] = {0, 90, 180, 270, 45, 225};
	const double gs[] = {10, 20, 25, 30, 40, 50, 60, 75};
	enum { NC = 6, NG = 8, N = NC * NG };
	double pts[N * 6], want[N], lux[N], ref[N];
	for (int i = 0; i < NC; i++)
		for (int j = 0; j < NG; j++) {
			double c = cs[i] * M_PI / 180, g = gs[j] * M_PI / 180;
			double r = HEIGHT * tan(g), d = HEIGHT / cos(g);
			double *p = pts + 6 * (i * NG + j);
			p[0] = r * cos(c);
			p[1] = r * sin(c);
			p[2] = 0;
			p[3] = p[4] = 0;
			p[5] = 1;
			double cd = i < 4 ? file_cd(cs[i], gs[j])
			                  : 0.5 * (file_cd(cs[i] - 45, gs[j]) +
			                           file_cd(cs[i] + 45, gs[j]));
			want[i * NG + j] = cd * cos(g) / (d * d);
		}
	rad_error err;
	assert_int_equal(rad_solver_illuminance(sv, pts, N, lux, &err), RAD_OK);
	reference_lux(s, pts, N, 4, ref);
	double worst = 0, worst_ref = 0;
	for (int k = 0; k < N; k++) {
		double e = fabs(lux[k] - want[k]) / want[k];
		double er = fabs(ref[k] - want[k]) / want[k];
		if (!(e <= 0.005) || !(er <= 0.005))
			fail_msg("point %d (C %g, gamma %g): query %.6f, "
			         "reference %.6f, file %.6f lux",
			         k, cs[k / NG], gs[k % NG], lux[k], ref[k],
			         want[k]);
		worst = fmax(worst, e);
		worst_ref = fmax(worst_ref, er);
	}
	print_message("  under the luminaire: %d points, worst %.2e (query), "
	              "%.2e (reference); C 0 gamma 10: %.4f lux, file %.4f\n",
	              N, worst, worst_ref, lux[0], want[0]);
	rad_solver_free(sv);
	rad_scene_free(s);
	pho_free(t);
}

/* The illuminance on the walls of the box, integrated (midpoint rule,
 * n x n points a face). */
static double box_flux(const rad_scene *s, const double pos[3], int n)
{
	size_t np = 6 * (size_t)n * n;
	double *pts = malloc(np * 6 * sizeof(double)),
	       *lux = malloc(np * sizeof(double));
	assert_true(pts && lux);
	size_t k = 0;
	for (int f = 0; f < 6; f++) {
		int a = f / 2, b = (a + 1) % 3, c = (a + 2) % 3;
		for (int i = 0; i < n; i++)
			for (int j = 0; j < n; j++, k++) {
				double *p = pts + 6 * k;
				p[a] = pos[a] + (f % 2 ? 2 : -2);
				p[b] = pos[b] - 2 + 4 * (i + 0.5) / n;
				p[c] = pos[c] - 2 + 4 * (j + 0.5) / n;
				p[3] = p[4] = p[5] = 0;
				p[3 + a] = f % 2 ? -1 : 1;
			}
	}
	reference_lux(s, pts, np, 2, lux);
	double sum = 0, da = 16.0 / ((double)n * n);
	for (size_t q = 0; q < np; q++)
		sum += lux[q] * da;
	free(pts);
	free(lux);
	return sum;
}

static void check_flux(const char *file, double declared)
{
	pho_table *t = load(file);
	const double pos[3] = {0.1, -0.2, 1.5};
	rad_scene *s = scene_with(t, pos, 1);
	double flux = box_flux(s, pos, 120), table = pho_lumens(t);
	double want = declared > 0 ? declared : table;
	double e = fabs(flux - want) / want, et = fabs(table - want) / want;
	print_message("  %s: walls %.3f lm, table %.3f lm, file %.3f lm "
	              "(%.3f %%, %.3f %%); scene estimate %.3f lm\n",
	              file, flux, table, want, 100 * e, 100 * et,
	              s->total_flux[1]);
	assert_true(e <= 0.005 && et <= 0.005);
	assert_true(fabs(flux - table) <= 0.005 * table);
	/* The scene's flux estimate is the table's integral (white). */
	for (int c = 0; c < 3; c++)
		assert_true(fabs(s->total_flux[c] - table) <= 1e-9 * table);
	rad_scene_free(s);
	pho_free(t);
}

static void test_walls_round_the_luminaire_take_its_lumens(void **state)
{
	(void)state;
	check_flux("cosine_1000lm.ies", 1000);
	check_flux("cosine_1600lm.ldt", 1600);
	check_flux("full_2002.ies", 0);
}

static void test_candela_lights_are_checked_and_counted(void **state)
{
	(void)state;
	pho_table *t = load("full_2002.ies");
	rad_scene *s;
	rad_error err;
	rad_mem_report m0, m1;
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	rad_scene_memory(s, &m0);
	rad_light_desc L = {.kind = RAD_LIGHT_SPOT,
	                    .direction = {0, 0, -1},
	                    .outer_cone = 1,
	                    .candela = pho_table_grid(t),
	                    .c0_axis = {1, 0, 0}};
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_ERR_INVALID);
	L.kind = RAD_LIGHT_POINT;
	L.c0_axis[0] = 0;
	L.c0_axis[2] = 1; /* along the nadir: no C = 0 direction */
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "c0_axis"));
	L.c0_axis[0] = 1;
	rad_candela_grid bad = *L.candela;
	double g[19];
	for (int k = 0; k < 19; k++)
		g[k] = bad.gamma_deg[k];
	g[3] = g[2];
	bad.gamma_deg = g;
	L.candela = &bad;
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "gamma angles not ascending at 3"));
	L.candela = pho_table_grid(t);
	assert_int_equal(rad_scene_add_light(s, &L, &err), RAD_OK);
	rad_scene_memory(s, &m1);
	size_t table = (5 + 19 + 5 * 19) * sizeof(double);
	assert_true(m1.bytes[RAD_MEM_LIGHTS] - m0.bytes[RAD_MEM_LIGHTS] >=
	            (int64_t)table);
	rad_scene_free(s);
	pho_free(t);
}

/*
 * An area luminaire: a 1.2 x 0.2 m opening whose table is I0 cos(gamma)
 * is a Lambertian rectangle of luminance I0 / A, so the floor under it
 * reads L pi F, F the closed form of a point facing a parallel rectangle
 * (closed_forms.h).  Checked 0.4 m, 1 m and 2.5 m below, under the
 * centre and off it, for the solver and the Monte Carlo reference (which
 * samples the opening its own way); the same table as a point source is
 * far off near the luminaire.
 */
static void test_area_luminaire_matches_the_closed_form(void **state)
{
	(void)state;
	enum { NG = 181 };
	static double c_deg[1] = {0}, g_deg[NG], cd[NG];
	const double I0 = 1000, len = 1.2, wid = 0.2;
	for (int k = 0; k < NG; k++) {
		g_deg[k] = k;
		cd[k] = k <= 90 ? I0 * cos(k * M_PI / 180) : 0;
	}
	cd[90] = 0;
	const rad_candela_grid grid = {1, NG, c_deg, g_deg, cd};
	static const double heights[] = {0.4, 1.0, 2.5};
	static const double at[][2] = {{0, 0}, {0.5, 0.1}, {1.0, -0.3}};
	for (size_t h = 0; h < sizeof heights / sizeof heights[0]; h++) {
		double H = heights[h], worst = 0, worst_point = 0;
		for (int area = 0; area <= 1; area++) {
			rad_scene *s;
			rad_error err;
			const double black[3] = {0, 0, 0};
			uint32_t mat, node;
			assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
			assert_int_equal(rad_scene_add_material(s, black, black,
			                                        &mat, &err),
			                 RAD_OK);
			assert_int_equal(
			        rad_scene_add_node(s, "floor", &node, &err),
			        RAD_OK);
			const double p[3] = {-20, -20, 0}, e1[3] = {40, 0, 0},
			             e2[3] = {0, 40, 0};
			quad(s, mat, node, p, e1, e2);
			rad_light_desc L = {
			        .kind = RAD_LIGHT_POINT,
			        .position = {0, 0, H},
			        .direction = {0, 0, -1},
			        .intensity = {1, 1, 1},
			        .candela = &grid,
			        .c0_axis = {1, 0, 0},
			        .opening = {area ? len : 0, area ? wid : 0}};
			assert_int_equal(rad_scene_add_light(s, &L, &err),
			                 RAD_OK);
			assert_int_equal(rad_scene_commit(s, &err), RAD_OK);
			double pts[3 * 6], lux[3], ref[3];
			for (int k = 0; k < 3; k++) {
				const double q[6] = {at[k][0], at[k][1], 0,
				                     0,        0,        1};
				memcpy(pts + 6 * k, q, sizeof q);
			}
			rad_solver *sv = solver_on(s);
			assert_int_equal(rad_solver_query(sv, pts, 3, 0, lux,
			                                  NULL, &err),
			                 RAD_OK);
			rad_solver_free(sv);
			reference_lux(s, pts, 3, 64, ref);
			for (int k = 0; k < 3; k++) {
				double x = at[k][0], y = at[k][1];
				double want =
				        I0 / (len * wid) * M_PI *
				        ff_parallel(-len / 2 - x, len / 2 - x,
				                    -wid / 2 - y, wid / 2 - y,
				                    H);
				double e = fabs(lux[k] - want) / want;
				if (!area) {
					worst_point = fmax(worst_point, e);
					continue;
				}
				worst = fmax(worst, e);
				if (e > 0.01 ||
				    fabs(ref[k] - want) > 0.01 * want)
					fail_msg("%g m below, point %d: solver "
					         "%g, reference %g, closed "
					         "form %g lux",
					         H, k, lux[k], ref[k], want);
			}
			rad_scene_free(s);
		}
		print_message("area luminaire %.1f m above: worst %.3f %% "
		              "(as a point: %.1f %%)\n",
		              H, 100 * worst, 100 * worst_point);
		if (H < 1)
			assert_true(worst_point > 0.1); /* a point is not it */
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_floor_under_the_luminaire_reads_the_file),
	        cmocka_unit_test(
	                test_walls_round_the_luminaire_take_its_lumens),
	        cmocka_unit_test(test_candela_lights_are_checked_and_counted),
	        cmocka_unit_test(test_area_luminaire_matches_the_closed_form),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
