/*
 * test_export.c -- the solved mesh as glTF (sio_export_solution): the GLB
 * is read back here (header, JSON chunk with jansson, BIN chunk) and
 * checked against the solution's leaves:
 *  - one mesh per node, named after it; vertex and triangle counts follow
 *    the leaves (a parallelogram is two triangles);
 *  - flat mode: each leaf's vertices carry its position, its lux and its
 *    radiosity tone-mapped with the white point given;
 *  - smooth mode: fewer vertices, each vertex's lux within [min, max] of
 *    the leaves that touch it, no blending across a crease;
 *  - POSITION min/max are the real bounds, COLOR_0 lies in [0, 1];
 *  - NULL arguments, bad options and an empty scene are clear errors.
 */
#include <jansson.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <cmocka.h>

#include "export.h"
#include "rad.h"
#include "sceneio.h"

/* ---------------------------------------------------------- the scene */

/* Rectangle o, o+u, o+u+v, o+v as two triangles; faces u x v. */
static void add_rect(rad_scene *s, uint32_t mat, uint32_t node,
                     const double o[3], const double u[3], const double v[3])
{
	double t[18];
	for (int k = 0; k < 3; k++) {
		double a = o[k], b = o[k] + u[k], c = o[k] + u[k] + v[k],
		       d = o[k] + v[k];
		t[k] = a, t[3 + k] = b, t[6 + k] = c;
		t[9 + k] = a, t[12 + k] = c, t[15 + k] = d;
	}
	rad_error err;
	if (rad_scene_add_triangles(s, mat, node, t, 2, &err) != RAD_OK)
		fail_msg("add: %s", err.msg);
}

/* A floor, two walls meeting at a corner (one node) and a ceiling lamp. */
static rad_scene *make_room(void)
{
	rad_scene *s;
	rad_error err;
	uint32_t grey, lamp, nf, nw, nl;
	const double rho[3] = {0.6, 0.5, 0.4}, zero[3] = {0, 0, 0};
	const double lum[3] = {200, 200, 200};
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	assert_int_equal(rad_scene_add_material(s, rho, zero, &grey, &err),
	                 RAD_OK);
	assert_int_equal(rad_scene_add_material(s, zero, lum, &lamp, &err),
	                 RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "floor", &nf, &err), RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "walls", &nw, &err), RAD_OK);
	assert_int_equal(rad_scene_add_node(s, "lamp", &nl, &err), RAD_OK);
	add_rect(s, grey, nf, (double[]){0, 0, 0}, (double[]){0, 0, 2},
	         (double[]){2, 0, 0});
	add_rect(s, grey, nw, (double[]){0, 0, 0}, (double[]){0, 2, 0},
	         (double[]){0, 0, 2});
	add_rect(s, grey, nw, (double[]){0, 0, 0}, (double[]){2, 0, 0},
	         (double[]){0, 2, 0});
	add_rect(s, lamp, nl, (double[]){0.7, 1.9, 0.7}, (double[]){0.6, 0, 0},
	         (double[]){0, 0, 0.6});
	if (rad_scene_commit(s, &err) != RAD_OK)
		fail_msg("commit: %s", err.msg);
	return s;
}

static rad_solution *solve(const rad_scene *s)
{
	rad_options o;
	rad_solver *sv;
	rad_solution *sol;
	rad_error err;
	rad_options_default(&o);
	o.threads = 2;
	o.eps = 1e-3;
	o.min_edge_rel = 0.03;
	assert_int_equal(rad_solver_new(s, &o, &sv, &err), RAD_OK);
	for (int i = 0; i < 3; i++)
		if (rad_solver_step(sv, &err) != RAD_OK)
			fail_msg("step: %s", err.msg);
	assert_int_equal(rad_solution_new(sv, &sol, &err), RAD_OK);
	rad_solver_free(sv);
	return sol;
}

/* The leaves as the solution reports them, in callback order. */
typedef struct leaf {
	uint32_t node;
	int nv;
	double p[4][3], B[3], lux;
} leaf;

typedef struct leaves {
	leaf v[20000];
	size_t n;
} leaves;

static void on_leaf(void *ud, uint32_t node, const double p[4][3], int nv,
                    const double B[3], const double I[3])
{
	leaves *L = ud;
	assert_true(L->n < 20000);
	leaf *f = &L->v[L->n++];
	f->node = node;
	f->nv = nv;
	memcpy(f->p, p, sizeof(f->p));
	memcpy(f->B, B, sizeof(f->B));
	f->lux = RAD_LUMA_R * I[0] + RAD_LUMA_G * I[1] + RAD_LUMA_B * I[2];
}

/* -------------------------------------------------------- reading GLB */

typedef struct glb {
	json_t *doc;
	const unsigned char *bin;
	size_t binlen;
} glb;

static uint32_t rd32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
	       (uint32_t)p[3] << 24;
}

static void glb_open(glb *g, const unsigned char *b, size_t len)
{
	assert_true(len >= 28);
	assert_int_equal(rd32(b), 0x46546C67); /* "glTF" */
	assert_int_equal(rd32(b + 4), 2);
	assert_int_equal(rd32(b + 8), len);
	uint32_t jlen = rd32(b + 12);
	assert_int_equal(rd32(b + 16), 0x4E4F534A); /* "JSON" */
	assert_true(20 + (size_t)jlen + 8 <= len);
	json_error_t je;
	g->doc = json_loadb((const char *)b + 20, jlen, 0, &je);
	if (!g->doc)
		fail_msg("GLB JSON: %s", je.text);
	const unsigned char *c = b + 20 + jlen;
	assert_int_equal(rd32(c + 4), 0x004E4942); /* "BIN\0" */
	g->bin = c + 8;
	g->binlen = rd32(c);
	assert_true(20 + jlen + 8 + g->binlen <= len);
}

/* Accessor a's data: count, components, and a pointer into BIN. */
static const void *accessor(const glb *g, int a, size_t *count, int *ncomp,
                            int want_type)
{
	json_t *acc = json_array_get(json_object_get(g->doc, "accessors"), a);
	assert_non_null(acc);
	json_t *bv = json_array_get(
	        json_object_get(g->doc, "bufferViews"),
	        json_integer_value(json_object_get(acc, "bufferView")));
	assert_non_null(bv);
	assert_int_equal(
	        json_integer_value(json_object_get(acc, "componentType")),
	        want_type);
	const char *type = json_string_value(json_object_get(acc, "type"));
	*ncomp = strcmp(type, "VEC3") == 0 ? 3 : 1;
	*count = (size_t)json_integer_value(json_object_get(acc, "count"));
	size_t off =
	        (size_t)json_integer_value(json_object_get(bv, "byteOffset")) +
	        (size_t)json_integer_value(json_object_get(acc, "byteOffset"));
	assert_null(json_object_get(bv, "byteStride")); /* tightly packed */
	assert_true(off + *count * (size_t)*ncomp * 4 <= g->binlen);
	return g->bin + off;
}

/* One exported mesh, its arrays pointing into the GLB. */
typedef struct xmesh {
	const char *name;
	const float *pos, *color, *lux;
	const uint32_t *index;
	size_t nv, ni;
	json_t *min, *max;
} xmesh;

static xmesh mesh_get(const glb *g, size_t i)
{
	xmesh m;
	size_t n;
	int nc;
	json_t *mesh = json_array_get(json_object_get(g->doc, "meshes"), i);
	json_t *prim = json_array_get(json_object_get(mesh, "primitives"), 0);
	json_t *at = json_object_get(prim, "attributes");
	m.name = json_string_value(json_object_get(mesh, "name"));
	int pa = (int)json_integer_value(json_object_get(at, "POSITION"));
	m.pos = accessor(g, pa, &m.nv, &nc, 5126);
	assert_int_equal(nc, 3);
	json_t *pacc = json_array_get(json_object_get(g->doc, "accessors"), pa);
	m.min = json_object_get(pacc, "min");
	m.max = json_object_get(pacc, "max");
	m.color = accessor(
	        g, (int)json_integer_value(json_object_get(at, "COLOR_0")), &n,
	        &nc, 5126);
	assert_int_equal(n, m.nv);
	m.lux = accessor(
	        g, (int)json_integer_value(json_object_get(at, "_ILLUMINANCE")),
	        &n, &nc, 5126);
	assert_int_equal(n, m.nv);
	assert_int_equal(nc, 1);
	m.index = accessor(
	        g, (int)json_integer_value(json_object_get(prim, "indices")),
	        &m.ni, &nc, 5125);
	return m;
}

/* ---------------------------------------------------------------- tests */

typedef struct fixture {
	rad_scene *scene;
	rad_solution *sol;
	leaves *L;
} fixture;

static int setup(void **state)
{
	fixture *f = calloc(1, sizeof(*f));
	f->scene = make_room();
	f->sol = solve(f->scene);
	f->L = calloc(1, sizeof(leaves));
	rad_solution_leaves(f->sol, on_leaf, f->L);
	*state = f;
	return 0;
}

static int teardown(void **state)
{
	fixture *f = *state;
	rad_solution_free(f->sol);
	rad_scene_free(f->scene);
	free(f->L);
	free(f);
	return 0;
}

static unsigned char *export(fixture *f, int flat, double white, size_t *len,
                             sio_export_info *info)
{
	sio_export_opts o;
	rad_error err;
	unsigned char *out;
	sio_export_opts_default(&o);
	o.flat = flat;
	o.white_lux = white;
	if (sio_export_solution(f->scene, f->sol, &o, &out, len, info, &err) !=
	    RAD_OK)
		fail_msg("export: %s", err.msg);
	return out;
}

static int close_rel(double a, double b, double rel)
{
	return fabs(a - b) <= rel * fmax(fabs(a), fabs(b)) + 1e-9;
}

/* Common checks: names, bounds, colours, indices; per-node counts. */
static void check_meshes(const glb *g, const leaves *L, int flat)
{
	const char *names[3] = {"floor", "walls", "lamp"};
	json_t *meshes = json_object_get(g->doc, "meshes");
	assert_int_equal(json_array_size(meshes), 3);
	for (size_t k = 0; k < 3; k++) {
		xmesh m = mesh_get(g, k);
		size_t nv = 0, ntri = 0;
		assert_string_equal(m.name, names[k]);
		for (size_t i = 0; i < L->n; i++)
			if (L->v[i].node == k) {
				nv += (size_t)L->v[i].nv;
				ntri += (size_t)L->v[i].nv - 2;
			}
		assert_true(ntri > 2); /* the solver did subdivide */
		assert_int_equal(m.ni, 3 * ntri);
		if (flat)
			assert_int_equal(m.nv, nv);
		else
			assert_true(m.nv < nv);
		double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL},
		       hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
		for (size_t v = 0; v < m.nv; v++)
			for (int c = 0; c < 3; c++) {
				lo[c] = fmin(lo[c], m.pos[3 * v + c]);
				hi[c] = fmax(hi[c], m.pos[3 * v + c]);
				assert_true(m.color[3 * v + c] >= 0 &&
				            m.color[3 * v + c] <= 1);
			}
		for (int c = 0; c < 3; c++) {
			assert_true(json_number_value(
			                    json_array_get(m.min, c)) == lo[c]);
			assert_true(json_number_value(
			                    json_array_get(m.max, c)) == hi[c]);
		}
		for (size_t i = 0; i < m.ni; i++)
			assert_true(m.index[i] < m.nv);
	}
}

static void test_flat_carries_each_leaf(void **state)
{
	fixture *f = *state;
	size_t len;
	sio_export_info info;
	const double white = 100;
	unsigned char *out = export(f, 1, white, &len, &info);
	glb g;
	glb_open(&g, out, len);
	check_meshes(&g, f->L, 1);
	assert_int_equal(info.meshes, 3);
	assert_true(info.white_lux == white);
	/* Leaves are written node by node, in the order they came. */
	size_t tv = 0, tt = 0;
	for (uint32_t k = 0; k < 3; k++) {
		xmesh m = mesh_get(&g, k);
		size_t v = 0;
		for (size_t i = 0; i < f->L->n; i++) {
			const leaf *lf = &f->L->v[i];
			if (lf->node != k)
				continue;
			for (int j = 0; j < lf->nv; j++, v++) {
				for (int c = 0; c < 3; c++) {
					assert_true(m.pos[3 * v + c] ==
					            (float)lf->p[j][c]);
					double x = lf->B[c] > 0 ? lf->B[c] : 0;
					assert_true(close_rel(
					        m.color[3 * v + c],
					        x / (x + white), 1e-6));
				}
				assert_true(close_rel(m.lux[v], lf->lux, 1e-6));
			}
			tt += (size_t)lf->nv - 2;
		}
		assert_int_equal(v, m.nv);
		tv += v;
	}
	assert_int_equal(info.vertices, tv);
	assert_int_equal(info.triangles, tt);
	json_decref(g.doc);
	free(out);
}

static void test_smooth_averages_neighbours(void **state)
{
	fixture *f = *state;
	size_t len;
	sio_export_info info;
	unsigned char *out = export(f, 0, 0, &len, &info);
	glb g;
	glb_open(&g, out, len);
	check_meshes(&g, f->L, 0);
	assert_true(info.white_lux > 0);
	for (uint32_t k = 0; k < 3; k++) {
		xmesh m = mesh_get(&g, k);
		for (size_t v = 0; v < m.nv; v++) {
			double lo = HUGE_VAL, hi = -HUGE_VAL;
			for (size_t i = 0; i < f->L->n; i++) {
				const leaf *lf = &f->L->v[i];
				for (int j = 0; lf->node == k && j < lf->nv;
				     j++) {
					double d = 0;
					for (int c = 0; c < 3; c++)
						d = fmax(
						        d,
						        fabs(lf->p[j][c] -
						             m.pos[3 * v + c]));
					if (d < 1e-4) {
						lo = fmin(lo, lf->lux);
						hi = fmax(hi, lf->lux);
					}
				}
			}
			assert_true(lo <= hi); /* some leaf touches it */
			assert_true(m.lux[v] >= lo * (1 - 1e-5) - 1e-6 &&
			            m.lux[v] <= hi * (1 + 1e-5) + 1e-6);
		}
	}
	/* The walls meet along x = 0, z = 0: the floor-level corner there
	 * is one vertex per wall, not one blended vertex. */
	xmesh w = mesh_get(&g, 1);
	int corner = 0;
	for (size_t v = 0; v < w.nv; v++)
		corner += fabsf(w.pos[3 * v]) < 1e-6f &&
		          fabsf(w.pos[3 * v + 1]) < 1e-6f &&
		          fabsf(w.pos[3 * v + 2]) < 1e-6f;
	assert_int_equal(corner, 2);
	json_decref(g.doc);
	free(out);
}

static void test_bad_arguments_are_errors(void **state)
{
	fixture *f = *state;
	sio_export_opts o;
	rad_error err;
	unsigned char *out = (unsigned char *)&err;
	size_t len = 5;
	sio_export_opts_default(&o);
	assert_int_equal(
	        sio_export_solution(NULL, f->sol, &o, &out, &len, NULL, &err),
	        RAD_ERR_INVALID);
	assert_string_equal(err.msg, "sio_export_solution: scene is NULL");
	assert_null(out);
	assert_int_equal(len, 0);
	assert_int_equal(
	        sio_export_solution(f->scene, NULL, &o, &out, &len, NULL, &err),
	        RAD_ERR_INVALID);
	assert_string_equal(err.msg, "sio_export_solution: solution is NULL");
	assert_int_equal(sio_export_solution(f->scene, f->sol, &o, NULL, &len,
	                                     NULL, &err),
	                 RAD_ERR_INVALID);
	o.white_lux = -1;
	assert_int_equal(sio_export_solution(f->scene, f->sol, &o, &out, &len,
	                                     NULL, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "white_lux"));
	o.white_lux = NAN;
	assert_int_equal(sio_export_solution(f->scene, f->sol, &o, &out, &len,
	                                     NULL, &err),
	                 RAD_ERR_INVALID);
	sio_export_opts_default(&o);
	o.format = (sio_format)7;
	assert_int_equal(sio_export_solution(f->scene, f->sol, &o, &out, &len,
	                                     NULL, &err),
	                 RAD_ERR_INVALID);
	assert_non_null(strstr(err.msg, "unknown format 7"));
	/* NULL options mean the defaults; the .gltf JSON form works too. */
	assert_int_equal(sio_export_solution(f->scene, f->sol, NULL, &out, &len,
	                                     NULL, &err),
	                 RAD_OK);
	assert_int_equal(rd32(out), 0x46546C67);
	free(out);
	o.format = SIO_FORMAT_JSON;
	assert_int_equal(sio_export_solution(f->scene, f->sol, &o, &out, &len,
	                                     NULL, &err),
	                 RAD_OK);
	json_t *doc = json_loadb((const char *)out, len, 0, NULL);
	assert_non_null(doc);
	assert_int_equal(json_array_size(json_object_get(doc, "meshes")), 3);
	json_decref(doc);
	free(out);
}

/* An empty scene never gets a solution: the engine refuses to commit it,
 * and says why. */
static void test_empty_scene_is_refused(void **state)
{
	(void)state;
	rad_scene *s;
	rad_error err;
	assert_int_equal(rad_scene_new(&s, &err), RAD_OK);
	assert_int_not_equal(rad_scene_commit(s, &err), RAD_OK);
	assert_non_null(strstr(err.msg, "no polygons"));
	rad_scene_free(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
	        cmocka_unit_test(test_flat_carries_each_leaf),
	        cmocka_unit_test(test_smooth_averages_neighbours),
	        cmocka_unit_test(test_bad_arguments_are_errors),
	        cmocka_unit_test(test_empty_scene_is_refused),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
