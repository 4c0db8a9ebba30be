/*
 * import.c -- the engine scene from a glTF document: at each node the walk
 * visits, the node's mesh becomes an engine node of triangles and its
 * KHR_lights_punctual light an engine light.
 *
 * DESIGN
 *  - Positions are transformed to world space in double and triangles go
 *    to the builder in fixed-size batches.  Strips and fans become
 *    triangle lists; points and lines are skipped and counted.  A
 *    mirroring world transform swaps two corners so the front stays on
 *    the geometric side.  Non-finite and degenerate triangles are passed
 *    through: the builder skips and counts them.
 *  - Materials are material.c's: a textured one gives each triangle its
 *    own reflectance, which goes to the builder beside the triangle.
 *  - Pure grouping nodes are not checked: their transform only matters
 *    through descendants, which are.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"
#include "photometry.h"

#define BATCH_TRIANGLES 1024 /* per rad_scene_add_triangles call */

static rad_status nomem(const sio_import *im)
{
	return rad_fail(im->err, RAD_ERR_NOMEM,
	                "out of memory while importing glTF");
}

/* A node that places geometry or a light needs a usable world matrix. */
static rad_status check_world(const sio_import *im, int ni, const sio_mat4 *w)
{
	for (int k = 0; k < 16; k++)
		if (!isfinite(w->m[k]))
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "node %d '%s': world transform is not "
			                "finite",
			                ni, sio_node_name(im->d, ni));
	double det = sio_mat_det3(w);
	if (!isfinite(det))
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "node %d '%s': world transform overflows "
		                "(determinant not finite)",
		                ni, sio_node_name(im->d, ni));
	if (det == 0)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "node %d '%s': world transform is singular "
		                "(determinant 0)",
		                ni, sio_node_name(im->d, ni));
	return RAD_OK;
}

/* ------------------------------------------------------------- meshes */

/* One primitive's geometry. */
typedef struct prim {
	const char *where;   /* "mesh 2 'Chair' primitive 0" */
	int mode;            /* TRIANGLES, STRIP or FAN */
	const double *pos;   /* world-space vertices, 3 doubles each */
	size_t nv;           /* vertices in pos */
	const sio_view *idx; /* NULL when not indexed */
	int flip;            /* the world matrix mirrors: swap corners */
	uint32_t mat, node;  /* engine ids */
	sio_prim_tex tex;    /* tex.tex NULL: the material's reflectance */
	int two_sided;       /* the material is doubleSided */
} prim;

/* Read POSITION and transform it to world space: *out malloc'ed. */
static rad_status load_positions(sio_import *im, const sio_view *v,
                                 const sio_mat4 *w, double **out)
{
	double *pos = malloc(3 * v->count * sizeof(*pos));
	if (!pos)
		return nomem(im);
	for (size_t i = 0; i < v->count; i++) {
		float p[3];
		memcpy(p, v->p + i * v->stride, sizeof p);
		sio_mat_point(w, p, pos + 3 * i);
	}
	*out = pos;
	return RAD_OK;
}

/* Corners of triangle t of a list, strip or fan (glTF spec, 3.7.2.1). */
static void corners(int mode, size_t t, size_t c[3])
{
	if (mode == SIO_GL_TRIANGLE_STRIP) {
		c[0] = t;
		c[1] = t + 1 + t % 2;
		c[2] = t + 2 - t % 2;
	} else if (mode == SIO_GL_TRIANGLE_FAN) {
		c[0] = t + 1;
		c[1] = t + 2;
		c[2] = 0;
	} else {
		c[0] = 3 * t;
		c[1] = 3 * t + 1;
		c[2] = 3 * t + 2;
	}
}

static rad_status flush(sio_import *im, const prim *p)
{
	size_t n = im->nbatch / 9;
	if (n == 0)
		return RAD_OK;
	im->nbatch = 0;
	rad_surface_desc d = {p->mat,    p->node,
	                      im->batch, p->tex.tex ? im->rho : NULL,
	                      n,         p->two_sided};
	return rad_scene_add_surface(im->s, &d, im->err);
}

/* How many triangles the primitive makes, checked. */
static rad_status count_triangles(sio_import *im, const prim *p, size_t *ntri)
{
	size_t n = p->idx ? p->idx->count : p->nv;
	if (p->mode == SIO_GL_TRIANGLES) {
		if (n % 3 != 0)
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "%s: %zu %s is not a multiple of 3",
			                p->where, n,
			                p->idx ? "indices" : "vertices");
		*ntri = n / 3;
	} else {
		*ntri = n >= 3 ? n - 2 : 0;
	}
	if (*ntri > UINT32_MAX - im->triangles)
		return rad_fail(im->err, RAD_ERR_LIMIT,
		                "%s: the scene would exceed %u triangles",
		                p->where, UINT32_MAX);
	im->triangles += *ntri;
	return RAD_OK;
}

/* Assemble the triangles of a primitive and hand them to the builder. */
static rad_status emit_triangles(sio_import *im, const prim *p)
{
	size_t ntri = 0;
	rad_status st = count_triangles(im, p, &ntri);
	if (st != RAD_OK)
		return st;
	for (size_t t = 0; t < ntri; t++) {
		size_t c[3], v[3];
		corners(p->mode, t, c);
		for (int k = 0; k < 3; k++) {
			v[k] = p->idx ? sio_index_at(p->idx, c[k]) : c[k];
			if (v[k] >= p->nv)
				return rad_fail(im->err, RAD_ERR_INVALID,
				                "%s: index %zu (at position "
				                "%zu) >= vertex count %zu",
				                p->where, v[k], c[k], p->nv);
		}
		if (p->flip) {
			size_t tmp = v[1];
			v[1] = v[2];
			v[2] = tmp;
		}
		if (p->tex.tex) {
			sio_material_rho(&p->tex, v, im->rho + im->nbatch / 3);
			if (im->info)
				im->info->textured_triangles++;
		}
		for (int k = 0; k < 3; k++) {
			memcpy(im->batch + im->nbatch, p->pos + 3 * v[k],
			       3 * sizeof(double));
			im->nbatch += 3;
		}
		if (im->nbatch == 9 * BATCH_TRIANGLES) {
			st = flush(im, p);
			if (st != RAD_OK)
				return st;
		}
	}
	return flush(im, p);
}

static rad_status add_primitive(sio_import *im, int mi, size_t pi,
                                const sio_mat4 *w, uint32_t node)
{
	const sio_doc_mesh *mesh = &im->d->meshes[mi];
	const sio_doc_prim *gp = &mesh->prims[pi];
	char where[192];
	snprintf(where, sizeof where, "mesh %d '%s' primitive %zu", mi,
	         mesh->name.s, pi);
	if (gp->mode < 0 || gp->mode > SIO_GL_TRIANGLE_FAN)
		return rad_fail(im->err, RAD_ERR_INVALID, "%s: unknown mode %d",
		                where, gp->mode);
	if (gp->mode < SIO_GL_TRIANGLES) { /* points and lines */
		if (im->info)
			im->info->primitives_skipped++;
		return RAD_OK;
	}
	if (!gp->has_position)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: no POSITION attribute", where);
	prim p = {where, gp->mode, NULL, 0, NULL, sio_mat_det3(w) < 0,
	          0,     node,     {0},  0};
	sio_view view, idx;
	double *pos = NULL;
	rad_status st =
	        sio_position_view(im->d, where, gp->position, &view, im->err);
	if (st == RAD_OK) {
		st = load_positions(im, &view, w, &pos);
		p.pos = pos;
		p.nv = view.count;
	}
	if (st == RAD_OK && gp->indices != -1) {
		st = sio_index_view(im->d, where, gp->indices, &idx, im->err);
		p.idx = &idx;
	}
	if (st == RAD_OK)
		st = sio_material_id(im, gp->material, where, &p.mat);
	if (st == RAD_OK)
		st = sio_material_texture(im, gp->material, where, gp, &p.tex);
	p.two_sided = gp->material >= 0 &&
	              gp->material < (int64_t)im->d->nmaterials &&
	              im->d->materials[gp->material].double_sided;
	if (st == RAD_OK)
		st = emit_triangles(im, &p);
	if (st == RAD_OK && im->info)
		im->info->primitives++;
	free(pos);
	return st;
}

/* One engine node per glTF node that carries a mesh. */
static rad_status add_mesh_node(sio_import *im, int ni, const sio_mat4 *w)
{
	const sio_doc_node *n = &im->d->nodes[ni];
	if (n->mesh < 0 || (size_t)n->mesh >= im->d->nmeshes)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "node %d '%s': mesh %d out of range (%zu "
		                "meshes)",
		                ni, n->name.s, n->mesh, im->d->nmeshes);
	const sio_doc_mesh *mesh = &im->d->meshes[n->mesh];
	char fallback[24];
	snprintf(fallback, sizeof fallback, "node%d", ni);
	const char *name = n->name.len      ? n->name.s
	                   : mesh->name.len ? mesh->name.s
	                                    : fallback;
	uint32_t id;
	rad_status st = rad_scene_add_node(im->s, name, &id, im->err);
	for (size_t pi = 0; st == RAD_OK && pi < mesh->nprims; pi++)
		st = add_primitive(im, n->mesh, pi, w, id);
	return st;
}

/* -------------------------------------------------------------- lights */

/* Index of the KHR_lights_punctual light node ni carries, or -1. */
static rad_status node_light(const sio_import *im, int ni, int *li)
{
	const sio_doc_node *n = &im->d->nodes[ni];
	*li = -1;
	sio_val tag;
	double x = -1; /* what a "light" other than a number reads as */
	rad_status st = sio_doc_node_light(im->d, ni, &tag, &x, im->err);
	if (st != RAD_OK || tag == SIO_VAL_ABSENT)
		return st;
	if (!(x >= 0 && x < (double)im->d->nlights) || x != floor(x))
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "node %d '%s': %s.light must be the index of "
		                "one of the %zu lights",
		                ni, n->name.s, SIO_LIGHTS_EXT, im->d->nlights);
	*li = (int)x;
	return RAD_OK;
}

/* Kind, intensity, range and cone of light li, checked. */
static rad_status light_values(const sio_import *im, int li, rad_light_desc *d)
{
	const sio_doc_light *g = &im->d->lights[li];
	const char *name = g->name.s;
	if (sio_str_is(g->type, "point"))
		d->kind = RAD_LIGHT_POINT;
	else if (sio_str_is(g->type, "spot"))
		d->kind = RAD_LIGHT_SPOT;
	else if (sio_str_is(g->type, "directional"))
		d->kind = RAD_LIGHT_DIRECTIONAL;
	else
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "light %d '%s': unknown type '%s'", li, name,
		                g->type.s);
	if (g->ncolor && g->ncolor != 3)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "light %d '%s': color has %zu numbers, "
		                "expected 3",
		                li, name, g->ncolor);
	for (int c = 0; c < 3; c++) {
		double col = g->ncolor ? g->color[c] : 1; /* white */
		d->intensity[c] = col * g->intensity;
		if (!(col >= 0) || !(g->intensity >= 0))
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "light %d '%s': negative color or "
			                "intensity",
			                li, name);
	}
	d->range = g->range; /* 0 (absent) = infinite */
	d->inner_cone = g->inner_cone;
	d->outer_cone = g->outer_cone;
	if (!(g->range >= 0) ||
	    (d->kind == RAD_LIGHT_SPOT &&
	     !(d->inner_cone >= 0 && d->inner_cone < d->outer_cone &&
	       d->outer_cone <= M_PI / 2)))
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "light %d '%s': needs range >= 0 and, for a "
		                "spot, 0 <= innerConeAngle < outerConeAngle "
		                "<= pi/2",
		                li, name);
	return RAD_OK;
}

/* A light placed by node ni: lights shine down their local -Z. */
/*
 * The photometric file node ni carries (extras.luxrad_photometry, packed
 * into a bufferView), made d's candela table; *t is freed once d is
 * added (the scene copies the table).
 */
static rad_status node_photometry(sio_import *im, int ni, rad_light_desc *d,
                                  pho_table **t)
{
	sio_val tag;
	double view = -1;
	sio_str name = {"", 0};
	rad_status st =
	        sio_doc_node_photometry(im->d, ni, &tag, &view, &name, im->err);
	if (st != RAD_OK || tag == SIO_VAL_ABSENT)
		return st;
	const char *node = sio_node_name(im->d, ni);
	if (tag == SIO_VAL_STRING)
		return rad_fail(
		        im->err, RAD_ERR_INVALID,
		        "node %d '%s': photometric file '%.80s' is not "
		        "in the scene: a scene sent as bytes carries its "
		        "files (luxrad submit and the tools pack a .gltf "
		        "with the files beside it)",
		        ni, node, name.s);
	if (tag != SIO_VAL_NUMBER || !(view >= 0 && view <= INT32_MAX) ||
	    view != floor(view))
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "node %d '%s': extras.%s must name a file "
		                "beside the scene",
		                ni, node, SIO_PHOTOMETRY_EXTRA);
	char where[192], msg[256];
	snprintf(where, sizeof where, "node %d '%s': %s '%s'", ni, node,
	         SIO_PHOTOMETRY_EXTRA, name.s);
	const unsigned char *b;
	size_t len;
	st = sio_view_bytes(im->d, where, (int)view, &b, &len, im->err);
	if (st != RAD_OK)
		return st;
	pho_status ps =
	        pho_parse((const char *)b, len, NULL, t, msg, sizeof msg);
	if (ps != PHO_OK)
		return rad_fail(im->err,
		                ps == PHO_ERR_NOMEM ? RAD_ERR_NOMEM
		                : ps == PHO_ERR_UNSUPPORTED
		                        ? RAD_ERR_UNSUPPORTED
		                        : RAD_ERR_INVALID,
		                "%s: %s", where, msg);
	if (im->info)
		im->info->photometric_lights++;
	return sio_blame(im->err, pho_light_set(*t, d, im->err), where);
}

static rad_status add_light(sio_import *im, int ni, int li, const sio_mat4 *w)
{
	rad_light_desc d = {0};
	pho_table *table = NULL;
	rad_status st = light_values(im, li, &d);
	if (st != RAD_OK)
		return st;
	const double *x = w->m, *z = w->m + 8;
	double len = sqrt(z[0] * z[0] + z[1] * z[1] +
	                  z[2] * z[2]); /* > 0: w is regular */
	double lx = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
	for (int k = 0; k < 3; k++) {
		d.position[k] = w->m[12 + k];
		d.direction[k] = -z[k] / len;
		d.c0_axis[k] = x[k] / lx; /* a luminaire's C = 0 */
	}
	sio_str lname = im->d->lights[li].name;
	d.name = lname.len ? lname.s : sio_node_name(im->d, ni);
	char label[192];
	snprintf(label, sizeof label, "node %d '%s'", ni,
	         sio_node_name(im->d, ni));
	st = node_photometry(im, ni, &d, &table);
	if (st == RAD_OK)
		st = sio_blame(im->err, rad_scene_add_light(im->s, &d, im->err),
		               label);
	pho_free(table);
	return st;
}

/* ---------------------------------------------------------- the import */

rad_status sio_import_init(sio_import *im, const sio_doc *d, rad_scene *s,
                           sio_info *info, rad_error *err)
{
	memset(im, 0, sizeof *im);
	im->d = d;
	im->s = s;
	im->info = info;
	im->err = err;
	im->mat_ids = malloc((d->nmaterials + 1) * sizeof(*im->mat_ids));
	im->mat_tex = calloc(d->nmaterials + 1, sizeof(*im->mat_tex));
	im->tex_used = calloc(d->nmaterials + 1, 1);
	im->batch = malloc(9 * BATCH_TRIANGLES * sizeof(*im->batch));
	im->rho = malloc(3 * BATCH_TRIANGLES * sizeof(*im->rho));
	if (!im->mat_ids || !im->mat_tex || !im->tex_used || !im->batch ||
	    !im->rho)
		return nomem(im);
	rad_status st = sio_tex_cache_init(&im->tex, d, info, err);
	if (st != RAD_OK)
		return st;
	for (size_t k = 0; k <= d->nmaterials; k++)
		im->mat_ids[k] = -1;
	return RAD_OK;
}

rad_status sio_import_node(void *ud, int ni, const sio_mat4 *w)
{
	sio_import *im = ud;
	int li;
	rad_status st = node_light(im, ni, &li);
	if (im->info)
		im->info->nodes++;
	int has_mesh = im->d->nodes[ni].mesh != -1;
	if (st != RAD_OK || (!has_mesh && li < 0))
		return st;
	st = check_world(im, ni, w);
	if (st == RAD_OK && has_mesh)
		st = add_mesh_node(im, ni, w);
	if (st == RAD_OK && li >= 0)
		st = add_light(im, ni, li, w);
	return st;
}

void sio_import_done(sio_import *im)
{
	sio_tex_cache_free(&im->tex);
	free(im->rho);
	free(im->batch);
	free(im->tex_used);
	free(im->mat_tex);
	free(im->mat_ids);
}
