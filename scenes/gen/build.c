/*
 * build.c -- the scene builder of luxrad-scenegen: meshes and lights
 * appended to a scene, and the shapes the scene families are made of
 * (quads, boxes and their faces, panels, ellipsoids, cylinders, boxes in
 * a local frame), all cut into counter-clockwise triangles.
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
 *  - Allocation failure is sticky: the first one sets `sg_oom`, later
 *    appends do nothing, and main reports it once before writing anything.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "gen.h"

bool sg_oom;
/* Where appends go after a failed sg_mesh_new: they all fail on `sg_oom`. */
static mesh oom_sink;

/* buf with room for `need` elements (maybe moved), or NULL on failure. */
static void *grow(void *buf, size_t *cap, size_t need, size_t elem)
{
	if (sg_oom)
		return NULL;
	if (need <= *cap)
		return buf;
	size_t ncap = *cap ? *cap : 64;
	while (ncap < need)
		ncap *= 2;
	void *nb = realloc(buf, ncap * elem);
	if (!nb) {
		sg_oom = true;
		return NULL;
	}
	*cap = ncap;
	return nb;
}

mesh *sg_mesh_new(scene *sc, mat m, const char *fmt, ...)
{
	mesh **nm = grow(sc->mesh, &sc->cap_mesh, sc->nmesh + 1, sizeof(*nm));
	mesh *me = nm ? calloc(1, sizeof(*me)) : NULL;
	if (nm)
		sc->mesh = nm;
	if (!me) {
		sg_oom = true;
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

void sg_add_light(scene *sc, const rad_light_desc *l)
{
	rad_light_desc *nl =
	        grow(sc->light, &sc->cap_light, sc->nlight + 1, sizeof(*nl));
	if (!nl)
		return;
	sc->light = nl;
	sc->light[sc->nlight++] = *l;
}

void sg_point_light(scene *sc, const char *name, p3 at, double cd)
{
	rad_light_desc l = {.kind = RAD_LIGHT_POINT,
	                    .position = {at.x, at.y, at.z},
	                    .intensity = {cd, cd, cd},
	                    .name = name};
	sg_add_light(sc, &l);
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

void sg_quad(mesh *me, p3 a, p3 b, p3 c, p3 d)
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

/* Corners of each face, counter-clockwise seen from outside; corner bits:
 * 4 = +x, 2 = +y, 1 = +z. */
static const unsigned char FACE[NFACES][4] = {
        {0, 1, 3, 2}, {4, 6, 7, 5}, {0, 4, 5, 1},
        {2, 3, 7, 6}, {0, 2, 6, 4}, {1, 5, 7, 3},
};

static p3 corner(const obox *b, unsigned bits)
{
	p3 l = P(bits & 4 ? b->h.x : -b->h.x, bits & 2 ? b->h.y : -b->h.y,
	         bits & 1 ? b->h.z : -b->h.z);
	return add(b->c, rot_y(l, b->yaw));
}

void sg_box_face(mesh *me, const obox *b, int f, int n, bool inward)
{
	p3 o = corner(b, FACE[f][0]);
	p3 u = sub(corner(b, FACE[f][1]), o);
	p3 v = sub(corner(b, FACE[f][3]), o);
	if (inward)
		grid(me, o, v, u, n);
	else
		grid(me, o, u, v, n);
}

void sg_box(mesh *me, const obox *b, unsigned omit)
{
	for (int f = 0; f < NFACES; f++)
		if (!(omit & OMIT(f)))
			sg_box_face(me, b, f, 1, false);
}

void sg_rect_in(mesh *me, p3 lo, p3 hi, int f)
{
	obox b = aabb(lo, hi);
	sg_box_face(me, &b, f, 1, true);
}

void sg_panel_down(mesh *me, double x, double y, double z, double e)
{
	sg_rect_in(me, P(x - e / 2, y - 1, z - e / 2),
	           P(x + e / 2, y, z + e / 2), F_PY);
}

void sg_ellipsoid(mesh *me, p3 c, p3 r, double yaw, int slices, int stacks)
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

void sg_cylinder(mesh *me, p3 c, double r, double h, int slices, unsigned caps)
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

void sg_fbox(mesh *me, frame f, p3 c, p3 h, unsigned omit)
{
	obox b = {fpt(f, c), h, f.yaw};
	sg_box(me, &b, omit);
}

static void mesh_free(mesh *me)
{
	free(me->pos);
	free(me->idx);
	free(me);
}

void sg_drop_empty_meshes(scene *sc)
{
	size_t kept = 0;
	for (size_t i = 0; i < sc->nmesh; i++) {
		mesh *me = sc->mesh[i];
		if (me->ni > 0)
			sc->mesh[kept++] = me;
		else
			mesh_free(me);
	}
	sc->nmesh = kept;
}

void sg_scene_free(scene *sc)
{
	for (size_t i = 0; i < sc->nmesh; i++)
		mesh_free(sc->mesh[i]);
	free(sc->mesh);
	free(sc->light);
}
