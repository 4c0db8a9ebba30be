/*
 * write.c -- sio_write: triangle meshes and lights as a glTF document.
 *
 * The document is built here as plain C data (gltf_doc.h) and serialized
 * by the shim.  Buffer 0 holds all vertex data, one bufferView per
 * attribute, each 4-byte aligned.  One node, mesh and triangle-list
 * primitive per non-empty sio_mesh, with POSITION (min/max set: glTF
 * requires them), optional COLOR_0 and _ILLUMINANCE and uint32 indices.
 * Materials are shared between meshes with equal factors; an emissive
 * factor above 1 (glTF caps it at 1) is folded into
 * KHR_materials_emissive_strength, which keeps the luminance.  Lights
 * become nodes aimed by a rotation of -Z, their RGB intensity split into
 * a colour (largest channel 1) and a scalar.  Input that would make
 * invalid glTF is refused with a message naming the mesh or light.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define KEY_LEN 7 /* base colour, emissive, strength: a material's key */

/* One export: the document under construction.  The arrays are sized
 * for the worst case up front; only the vertex data grows. */
typedef struct writer {
	unsigned char *data; /* buffer 0 */
	size_t size, data_cap;
	sio_out_view *views;         /* 4 per mesh at most */
	sio_out_accessor *accessors; /* 4 per mesh at most */
	sio_out_mesh *meshes;
	sio_out_material *materials;
	double (*keys)[KEY_LEN]; /* [material]: its factors, for sharing */
	sio_out_light *lights;
	sio_out_node *nodes;
	size_t nviews, naccessors, nmeshes, nmaterials, nlights, nnodes;
	rad_error *err;
} writer;

static rad_status nomem(const writer *W)
{
	return rad_fail(W->err, RAD_ERR_NOMEM,
	                "out of memory while exporting glTF");
}

static rad_status writer_init(writer *W, size_t nmeshes, size_t nlights,
                              rad_error *err)
{
	size_t m = nmeshes + 1; /* never calloc(0) */
	memset(W, 0, sizeof *W);
	W->err = err;
	W->views = calloc(4 * m, sizeof *W->views);
	W->accessors = calloc(4 * m, sizeof *W->accessors);
	W->meshes = calloc(m, sizeof *W->meshes);
	W->materials = calloc(m, sizeof *W->materials);
	W->keys = calloc(m, sizeof *W->keys);
	W->lights = calloc(nlights + 1, sizeof *W->lights);
	W->nodes = calloc(m + nlights, sizeof *W->nodes);
	if (!W->views || !W->accessors || !W->meshes || !W->materials ||
	    !W->keys || !W->lights || !W->nodes)
		return nomem(W);
	return RAD_OK;
}

static void writer_free(writer *W)
{
	free(W->data);
	free(W->views);
	free(W->accessors);
	free(W->meshes);
	free(W->materials);
	free(W->keys);
	free(W->lights);
	free(W->nodes);
}

static int all_finite(const float *p, size_t n)
{
	for (size_t i = 0; i < n; i++)
		if (!isfinite(p[i]))
			return 0;
	return 1;
}

static int in_range(const double v[3], double lo, double hi)
{
	for (int c = 0; c < 3; c++)
		if (!(v[c] >= lo && v[c] <= hi))
			return 0;
	return 1;
}

/* Refuse what would make the output invalid glTF. */
static rad_status check_mesh(const sio_mesh *g, size_t i, rad_error *err)
{
	size_t nv = g->nvertices;
	const char *bad = NULL;
	if (nv > UINT32_MAX || g->nindices > UINT32_MAX)
		bad = "more than 2^32 - 1 vertices or indices";
	else if (!g->position)
		bad = "no positions";
	else if (g->index ? g->nindices == 0 || g->nindices % 3 != 0
	                  : nv % 3 != 0)
		bad = "the triangle list is not a multiple of 3 long";
	else if (!all_finite(g->position, 3 * nv) ||
	         (g->color && !all_finite(g->color, 3 * nv)) ||
	         (g->illuminance && !all_finite(g->illuminance, nv)))
		bad = "a position, colour or illuminance is not finite";
	else if (!in_range(g->base_color, 0, 1) ||
	         !in_range(g->emissive, 0, HUGE_VAL) ||
	         !(g->emissive_strength >= 0 &&
	           g->emissive_strength < HUGE_VAL))
		bad = "base_color must be in [0,1], emissive and "
		      "emissive_strength finite and >= 0";
	if (bad)
		return rad_fail(err, RAD_ERR_INVALID, "mesh %zu '%s': %s", i,
		                g->name ? g->name : "", bad);
	for (size_t k = 0; g->index && k < g->nindices; k++)
		if (g->index[k] >= nv)
			return rad_fail(err, RAD_ERR_INVALID,
			                "mesh %zu '%s': index %u (at position "
			                "%zu) >= vertex count %zu",
			                i, g->name ? g->name : "", g->index[k],
			                k, nv);
	return RAD_OK;
}

/* Append n bytes as a new bufferView, keeping every view 4-aligned;
 * -1 when out of memory. */
static int add_view(writer *W, const void *p, size_t n, int target)
{
	size_t padded = (W->size + n + 3) & ~(size_t)3;
	if (padded > W->data_cap) {
		size_t cap = W->data_cap ? W->data_cap : 4096;
		while (cap < padded)
			cap *= 2;
		unsigned char *d = realloc(W->data, cap);
		if (!d)
			return -1;
		W->data = d;
		W->data_cap = cap;
	}
	W->views[W->nviews] = (sio_out_view){W->size, n, target};
	memcpy(W->data + W->size, p, n);
	memset(W->data + W->size + n, 0, padded - W->size - n);
	W->size = padded;
	return (int)W->nviews++;
}

/* A tightly packed accessor of 4-byte components over its own view. */
static int add_accessor(writer *W, const void *p, size_t count, int type,
                        int ncomp, int comp, int target)
{
	int view = add_view(W, p, 4 * (size_t)ncomp * count, target);
	if (view < 0)
		return -1;
	W->accessors[W->naccessors] =
	        (sio_out_accessor){view, comp, type, count, 0, {0}, {0}};
	return (int)W->naccessors++;
}

static int same_key(const double a[KEY_LEN], const double b[KEY_LEN])
{
	for (int k = 0; k < KEY_LEN; k++)
		if (a[k] != b[k])
			return 0;
	return 1;
}

/* Material of a mesh, shared by meshes with equal factors. */
static int add_material(writer *W, const sio_mesh *g)
{
	double e[3], strength = g->emissive_strength;
	double emax = sio_max(g->emissive[0],
	                      sio_max(g->emissive[1], g->emissive[2]));
	double scale = emax > 1 ? emax : 1;
	for (int c = 0; c < 3; c++)
		e[c] = g->emissive[c] / scale;
	strength = emax > 0 ? strength * scale : 1;
	const double key[KEY_LEN] = {g->base_color[0],
	                             g->base_color[1],
	                             g->base_color[2],
	                             e[0],
	                             e[1],
	                             e[2],
	                             strength};
	for (size_t k = 0; k < W->nmaterials; k++)
		if (same_key(W->keys[k], key))
			return (int)k;
	size_t n = W->nmaterials;
	sio_out_material *m = &W->materials[n];
	memcpy(m->base_color, g->base_color, sizeof m->base_color);
	memcpy(m->emissive, e, sizeof e);
	m->strength_ext = strength != 1;
	m->strength = strength;
	memcpy(W->keys[n], key, sizeof key);
	return (int)W->nmaterials++;
}

/* The accessors of one mesh's primitive; 0: out of memory. */
static int add_attributes(writer *W, const sio_mesh *g, sio_out_mesh *m)
{
	size_t nv = g->nvertices;
	int pa = add_accessor(W, g->position, nv, SIO_GL_VEC3, 3, SIO_GL_FLOAT,
	                      SIO_GL_ARRAY_BUFFER);
	if (pa < 0)
		return 0;
	sio_out_accessor *a = &W->accessors[pa];
	a->bounded = 1;
	for (int c = 0; c < 3; c++) {
		a->min[c] = HUGE_VAL;
		a->max[c] = -HUGE_VAL;
	}
	for (size_t k = 0; k < 3 * nv; k++) {
		double p = g->position[k];
		a->min[k % 3] = p < a->min[k % 3] ? p : a->min[k % 3];
		a->max[k % 3] = a->max[k % 3] < p ? p : a->max[k % 3];
	}
	m->attrs[m->nattrs++] = (sio_out_attr){"POSITION", pa};
	if (g->color)
		m->attrs[m->nattrs++] = (sio_out_attr){
		        "COLOR_0",
		        add_accessor(W, g->color, nv, SIO_GL_VEC3, 3,
		                     SIO_GL_FLOAT, SIO_GL_ARRAY_BUFFER)};
	if (g->illuminance)
		m->attrs[m->nattrs++] = (sio_out_attr){
		        "_ILLUMINANCE",
		        add_accessor(W, g->illuminance, nv, SIO_GL_SCALAR, 1,
		                     SIO_GL_FLOAT, SIO_GL_ARRAY_BUFFER)};
	for (int k = 0; k < m->nattrs; k++)
		if (m->attrs[k].accessor < 0)
			return 0;
	m->indices = -1;
	if (g->index)
		m->indices = add_accessor(W, g->index, g->nindices,
		                          SIO_GL_SCALAR, 1, SIO_GL_UNSIGNED_INT,
		                          SIO_GL_ELEMENT_ARRAY_BUFFER);
	return m->indices >= 0 || !g->index;
}

static rad_status write_mesh(writer *W, const sio_mesh *g, size_t i)
{
	if (g->nvertices == 0 && g->nindices == 0)
		return RAD_OK; /* nothing to draw; glTF forbids empty data */
	rad_status st = check_mesh(g, i, W->err);
	if (st != RAD_OK)
		return st;
	const char *name = g->name ? g->name : "";
	sio_out_mesh m = {name, {{0}}, 0, -1, -1};
	if (!add_attributes(W, g, &m))
		return nomem(W);
	m.material = add_material(W, g);
	W->meshes[W->nmeshes++] = m;
	W->nodes[W->nnodes++] =
	        (sio_out_node){name, (int)W->nmeshes - 1, -1, 0, 0, {0}, {0}};
	return RAD_OK;
}

static rad_status check_light(const rad_light_desc *d, size_t i, rad_error *err)
{
	int aimed = d->kind != RAD_LIGHT_POINT;
	double dlen2 = d->direction[0] * d->direction[0] +
	               d->direction[1] * d->direction[1] +
	               d->direction[2] * d->direction[2];
	int ok = (d->kind == RAD_LIGHT_POINT || d->kind == RAD_LIGHT_SPOT ||
	          d->kind == RAD_LIGHT_DIRECTIONAL) &&
	         in_range(d->position, -HUGE_VAL, HUGE_VAL) &&
	         in_range(d->intensity, 0, HUGE_VAL) &&
	         (!aimed || (dlen2 > 0 && dlen2 < HUGE_VAL)) && d->range >= 0 &&
	         d->range < HUGE_VAL &&
	         (d->kind != RAD_LIGHT_SPOT ||
	          (d->inner_cone >= 0 && d->inner_cone < d->outer_cone &&
	           d->outer_cone <= M_PI / 2));
	if (!ok)
		return rad_fail(err, RAD_ERR_INVALID,
		                "light %zu '%s': needs a known kind, finite "
		                "position, intensity >= 0, range >= 0, a "
		                "non-zero direction (spot, directional) and "
		                "0 <= inner < outer <= pi/2 (spot)",
		                i, d->name ? d->name : "");
	return RAD_OK;
}

/* Unit quaternion (x y z w) turning the local -Z axis onto direction d. */
static void aim(const double d[3], double q[4])
{
	double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
	double x = d[0] / len, y = d[1] / len, z = d[2] / len;
	/* Half-way quaternion (a x b, 1 + a.b) with a = -Z; when b = +Z the
	 * axis is undefined and any half turn about X or Y will do. */
	if (1 - z < 1e-12) {
		q[0] = 1;
		q[1] = q[2] = q[3] = 0;
		return;
	}
	double n = sqrt(y * y + x * x + (1 - z) * (1 - z));
	q[0] = y / n;
	q[1] = -x / n;
	q[2] = 0;
	q[3] = (1 - z) / n;
}

static rad_status write_light(writer *W, const rad_light_desc *d, size_t i)
{
	rad_status st = check_light(d, i, W->err);
	if (st != RAD_OK)
		return st;
	sio_out_light *g = &W->lights[W->nlights++];
	g->type = d->kind == RAD_LIGHT_POINT  ? "point"
	          : d->kind == RAD_LIGHT_SPOT ? "spot"
	                                      : "directional";
	/* glTF splits intensity into a colour in [0,1] and a scalar. */
	double imax = sio_max(d->intensity[0],
	                      sio_max(d->intensity[1], d->intensity[2]));
	g->intensity = imax;
	for (int c = 0; c < 3; c++)
		g->color[c] = imax > 0 ? d->intensity[c] / imax : 1;
	g->range = d->range;
	g->inner_cone = d->inner_cone;
	g->outer_cone = d->outer_cone;
	g->name = d->name ? d->name : "";
	sio_out_node *n = &W->nodes[W->nnodes++];
	*n = (sio_out_node){g->name, -1, (int)W->nlights - 1, 0, 0, {0}, {0}};
	if (d->position[0] != 0 || d->position[1] != 0 || d->position[2] != 0) {
		n->translated = 1;
		memcpy(n->translation, d->position, sizeof n->translation);
	}
	if (d->kind != RAD_LIGHT_POINT) {
		n->rotated = 1;
		aim(d->direction, n->rotation);
	}
	return RAD_OK;
}

/* Build the document, then let the shim serialize it. */
static rad_status write(writer *W, const sio_mesh *meshes, size_t nmeshes,
                        const rad_light_desc *lights, size_t nlights,
                        sio_format fmt, void **out, size_t *outlen)
{
	rad_status st = RAD_OK;
	for (size_t i = 0; st == RAD_OK && i < nmeshes; i++)
		st = write_mesh(W, &meshes[i], i);
	for (size_t i = 0; st == RAD_OK && i < nlights; i++)
		st = write_light(W, &lights[i], i);
	if (st != RAD_OK)
		return st;
	if (W->size > UINT32_MAX / 2)
		return rad_fail(W->err, RAD_ERR_LIMIT,
		                "%zu bytes of vertex data: glTF output is "
		                "limited to 2 GiB",
		                W->size);
	const char *used[2];
	size_t nused = 0;
	for (size_t k = 0; k < W->nmaterials; k++)
		if (W->materials[k].strength_ext) {
			used[nused++] = SIO_STRENGTH_EXT;
			break;
		}
	if (nlights)
		used[nused++] = SIO_LIGHTS_EXT;
	sio_out o = {.generator = "luxrad",
	             .data = W->data,
	             .size = W->size,
	             .views = W->views,
	             .accessors = W->accessors,
	             .meshes = W->meshes,
	             .materials = W->materials,
	             .lights = W->lights,
	             .nodes = W->nodes,
	             .extensions_used = used,
	             .nviews = W->nviews,
	             .naccessors = W->naccessors,
	             .nmeshes = W->nmeshes,
	             .nmaterials = W->nmaterials,
	             .nlights = W->nlights,
	             .nnodes = W->nnodes,
	             .nextensions_used = nused};
	return sio_doc_write(&o, fmt, out, outlen, W->err);
}

rad_status sio_write(const sio_mesh *meshes, size_t nmeshes,
                     const rad_light_desc *lights, size_t nlights,
                     sio_format fmt, void **out, size_t *outlen, rad_error *err)
{
	rad_error_clear(err);
	if (!out || !outlen || (nmeshes && !meshes) || (nlights && !lights) ||
	    (fmt != SIO_FORMAT_GLB && fmt != SIO_FORMAT_JSON))
		return rad_fail(err, RAD_ERR_INVALID,
		                "sio_write: bad arguments");
	*out = NULL;
	*outlen = 0;
	writer W;
	rad_status st = writer_init(&W, nmeshes, nlights, err);
	if (st == RAD_OK)
		st = write(&W, meshes, nmeshes, lights, nlights, fmt, out,
		           outlen);
	writer_free(&W);
	return st;
}
