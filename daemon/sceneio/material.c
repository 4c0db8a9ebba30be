/*
 * material.c -- glTF materials as the engine's: reflectance and
 * luminance from the factors, and for a textured base colour, each
 * triangle's reflectance from the texture under it.
 *
 * DESIGN
 *  - Reflectance is baseColorFactor (linear RGB), whatever metallicFactor
 *    says (metals become diffuse reflectors: the engine has no specular
 *    transport); alpha is ignored.  With a baseColorTexture, a triangle
 *    reflects baseColorFactor x the texture's mean over its UV footprint
 *    (texture.c), after KHR_texture_transform and with the sampler's wrap
 *    modes.  Reflectance is clamped to MAX_REFLECTANCE because rho = 1
 *    in a closed room makes I - rho F singular.  Luminance is
 *    emissiveFactor x KHR_materials_emissive_strength (cd/m2); emissive
 *    textures are not read.
 *  - Each glTF material is offered to the builder once, when a primitive
 *    first uses it; its texture is bound then too.  A texture that cannot
 *    be used (no UV set on the primitive, an image that does not decode)
 *    leaves the factor alone, with a note: the user gets a lit scene and
 *    is told what was not read.  A texture the document gets wrong (an
 *    index out of range, a bad wrap mode or transform) is an error, as
 *    any other malformed reference.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "internal.h"

#define MAX_REFLECTANCE 0.999 /* see the DESIGN note */

/* Reflectance and luminance of glTF material mi (>= 0), unclamped. */
static rad_status material_values(const sio_import *im, int mi,
                                  const char *label, double rho[3],
                                  double lum[3])
{
	const sio_doc_material *mat = &im->d->materials[mi];
	double strength = 1; /* KHR_materials_emissive_strength's default */
	sio_val tag;
	rad_status st =
	        sio_doc_material_strength(im->d, mi, &tag, &strength, im->err);
	if (st != RAD_OK)
		return st;
	if (tag != SIO_VAL_ABSENT &&
	    (tag != SIO_VAL_NUMBER || !(strength >= 0)))
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: %s.emissiveStrength must be a number >= 0",
		                label, SIO_STRENGTH_EXT);
	for (int c = 0; c < 3; c++) {
		if (!(mat->base_color[c] >= 0) || !(mat->emissive[c] >= 0))
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "%s: negative baseColorFactor or "
			                "emissiveFactor",
			                label);
		rho[c] = mat->base_color[c];
		lum[c] = mat->emissive[c] * strength;
	}
	return RAD_OK;
}

static int valid_wrap(int w)
{
	return w == SIO_GL_REPEAT || w == SIO_GL_CLAMP_TO_EDGE ||
	       w == SIO_GL_MIRRORED_REPEAT;
}

/*
 * The base colour texture of material mi, bound into *t: its image, wrap
 * modes, UV set and transform.  t->image stays -1 when there is none.
 */
static rad_status bind_texture(const sio_import *im, int mi, const char *label,
                               sio_mat_tex *t)
{
	const sio_doc *d = im->d;
	const sio_doc_material *mat = &d->materials[mi];
	t->image = -1;
	if (mat->base_texture < 0)
		return RAD_OK;
	if ((size_t)mat->base_texture >= d->ntextures)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: baseColorTexture %d out of range (%zu "
		                "textures)",
		                label, mat->base_texture, d->ntextures);
	const sio_doc_texture *tex = &d->textures[mat->base_texture];
	if (tex->source >= (int64_t)d->nimages || tex->source < -1)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: texture %d: source %d out of range (%zu "
		                "images)",
		                label, mat->base_texture, tex->source,
		                d->nimages);
	t->wrap[0] = t->wrap[1] = SIO_GL_REPEAT;
	if (tex->sampler >= 0) {
		if ((size_t)tex->sampler >= d->nsamplers)
			return rad_fail(
			        im->err, RAD_ERR_INVALID,
			        "%s: texture %d: sampler %d out of range "
			        "(%zu samplers)",
			        label, mat->base_texture, tex->sampler,
			        d->nsamplers);
		const sio_doc_sampler *sm = &d->samplers[tex->sampler];
		if (!valid_wrap(sm->wrap_s) || !valid_wrap(sm->wrap_t))
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "sampler %d: wrapS %d, wrapT %d: each "
			                "must be 10497, 33071 or 33648",
			                tex->sampler, sm->wrap_s, sm->wrap_t);
		t->wrap[0] = sm->wrap_s;
		t->wrap[1] = sm->wrap_t;
	}
	if (mat->transform_bad)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: %s: offset and scale must be 2 numbers, "
		                "rotation a number, texCoord an index",
		                label, SIO_TRANSFORM_EXT);
	/* u' = cs u + sn v + ox, v' = -sn u + cs v + oy, after scaling
	 * (the extension's translation x rotation x scale). */
	double cs = cos(mat->rotation), sn = sin(mat->rotation);
	const double m[6] = {cs * mat->scale[0], sn * mat->scale[1],
	                     mat->offset[0],     -sn * mat->scale[0],
	                     cs * mat->scale[1], mat->offset[1]};
	for (int k = 0; k < 6; k++)
		if (!isfinite(m[k]))
			return rad_fail(im->err, RAD_ERR_INVALID,
			                "%s: %s is not finite", label,
			                SIO_TRANSFORM_EXT);
	memcpy(t->m, m, sizeof m);
	t->texcoord = mat->transform_texcoord >= 0 ? mat->transform_texcoord
	                                           : mat->base_texcoord;
	t->image = tex->source;
	for (int c = 0; c < 3; c++)
		t->factor[c] = mat->base_color[c];
	return RAD_OK;
}

rad_status sio_material_id(sio_import *im, int mi, const char *where,
                           uint32_t *id)
{
	if (mi < -1 || mi >= (int64_t)im->d->nmaterials)
		return rad_fail(im->err, RAD_ERR_INVALID,
		                "%s: material %d out of range (%zu materials)",
		                where, mi, im->d->nmaterials);
	int64_t *slot = &im->mat_ids[mi + 1];
	if (*slot >= 0) {
		*id = (uint32_t)*slot;
		return RAD_OK;
	}
	char label[192];
	double rho[3] = {1, 1, 1}, lum[3] = {0, 0, 0}; /* glTF default */
	sio_mat_tex *t = &im->mat_tex[mi + 1];
	t->image = -1;
	if (mi < 0) {
		snprintf(label, sizeof label, "default material");
	} else {
		snprintf(label, sizeof label, "material %d '%s'", mi,
		         im->d->materials[mi].name.s);
		rad_status st = material_values(im, mi, label, rho, lum);
		if (st == RAD_OK)
			st = bind_texture(im, mi, label, t);
		if (st != RAD_OK)
			return st;
	}
	int clamped = 0;
	for (int c = 0; c < 3; c++)
		if (rho[c] > MAX_REFLECTANCE) {
			rho[c] = MAX_REFLECTANCE;
			clamped = 1;
		}
	if (clamped && t->image < 0)
		sio_note(im->info, "%s: reflectance clamped to %g", label,
		         MAX_REFLECTANCE);
	uint32_t u;
	rad_status st = sio_blame(
	        im->err, rad_scene_add_material(im->s, rho, lum, &u, im->err),
	        label);
	if (st != RAD_OK)
		return st;
	*slot = u;
	*id = u;
	return RAD_OK;
}

rad_status sio_material_texture(sio_import *im, int mi, const char *where,
                                const sio_doc_prim *gp, sio_prim_tex *pt)
{
	const sio_mat_tex *t = &im->mat_tex[mi + 1];
	pt->tex = NULL;
	pt->mat = t;
	if (t->image < 0)
		return RAD_OK;
	const sio_texture *tex = NULL;
	rad_status st = sio_tex_image(&im->tex, t->image, &tex, im->err);
	if (st != RAD_OK || !tex)
		return st;
	int ai = t->texcoord < SIO_TEXCOORDS ? gp->texcoord[t->texcoord] : -1;
	if (ai < 0) {
		sio_note(im->info,
		         "%s: its material's base colour texture reads "
		         "TEXCOORD_%d, which it lacks: baseColorFactor alone",
		         where, t->texcoord);
		return RAD_OK;
	}
	st = sio_uv_view(im->d, where, ai, &pt->uv, im->err);
	if (st != RAD_OK)
		return st;
	pt->tex = tex;
	if (!im->tex_used[mi + 1] && im->info) {
		im->info->textures_read++;
		im->info->textures_ignored--;
	}
	im->tex_used[mi + 1] = 1;
	return RAD_OK;
}

void sio_material_rho(const sio_prim_tex *pt, const size_t v[3], double rho[3])
{
	const sio_mat_tex *t = pt->mat;
	double uv[3][2], mean[3];
	int finite = 1;
	for (int k = 0; k < 3; k++) {
		double a[2];
		sio_uv_at(&pt->uv, v[k], a);
		uv[k][0] = t->m[0] * a[0] + t->m[1] * a[1] + t->m[2];
		uv[k][1] = t->m[3] * a[0] + t->m[4] * a[1] + t->m[5];
		finite &= isfinite(uv[k][0]) && isfinite(uv[k][1]) &&
		          fabs(uv[k][0]) < 1e9 && fabs(uv[k][1]) < 1e9;
	}
	if (finite)
		sio_tex_mean(pt->tex, t->wrap, (const double(*)[2])uv, mean);
	else
		sio_tex_image_mean(pt->tex, mean);
	for (int c = 0; c < 3; c++) {
		double r = t->factor[c] * mean[c];
		rho[c] = r > MAX_REFLECTANCE ? MAX_REFLECTANCE : r;
	}
}
