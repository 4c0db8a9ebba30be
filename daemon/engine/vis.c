/*
 * vis.c -- visibility queries over an Embree 3 BVH of the scene polygons.
 *
 * Every form factor and every light link asks "can a see b?", so this file
 * is the engine's hot path.  It keeps no state per query and allocates
 * nothing after the build; inputs are trusted (validated once by the scene
 * builder), as Embree itself does on its hot path.
 *
 * DESIGN
 * - One device per scene: a device's memory monitor then reports exactly
 *   the bytes of this scene's BVH, counted as RAD_MEM_BVH in s->mem.
 *   The monitor is called from TBB worker threads: rad_mem_count is
 *   atomic.  Our own buffers (vertices, indices, the primitive -> polygon
 *   map and this struct) are counted as BVH too: they exist only for
 *   Embree.  They are shared with Embree (rtcSetSharedGeometryBuffer), so
 *   the monitor does not see them and nothing is counted twice.
 * - The layout (rad_bvh_set_mode): Embree's default, or compact, whose
 *   leaves index our shared vertices instead of holding copies.  Same
 *   hits, so the same results to the bit.  Measured, 2 threads, 4
 *   iterations of hr: the grand hall's BVH 33.9 -> 24.4 MB (-28 %) for
 *   +8-10 % wall time; the hospital room's 5.0 -> 3.7 MB, time within
 *   the noise.  A quad geometry (a primitive per parallelogram) was
 *   tried too: its BVH was larger (35.9 MB), 25.4 MB compact.
 * - One triangle geometry; a parallelogram becomes two triangles, so
 *   prim_poly[] maps Embree's primitive ids back to scene polygons.
 * - Self-intersection (vis.h, docs/PITFALLS.md §1.1): both ends of a segment
 *   are moved off their surfaces along the normal and the ray is shortened
 *   by eps at both ends.  eps scales with the scene (RAD_VIS_EPS_REL x
 *   diagonal) so results are scale-invariant, but never drops below what
 *   float coordinates resolve at the scene's distance from the origin.
 * - Ray flags must be 0 and the mask all ones: Debian's Embree is built
 *   with ray masks, and mask 0 silently reports "never occluded".
 * - rad_vis_first_hit_front() filters hits through a filter in its own
 *   intersect context (RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION), not on the
 *   geometry: the other queries pass a context without a filter, so they
 *   pay one not-taken branch per candidate hit and nothing else.
 */
#include <float.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>

#include <embree3/rtcore.h>

#if defined(__SSE__)
#include <pmmintrin.h>
#include <xmmintrin.h>
#endif

#include "rad.h"
#include "vis.h"

struct rad_vis {
	RTCDevice device;
	RTCScene scene;
	rad_mem *mem;         /* the scene's counters */
	float *verts;         /* shared vertex buffer, padded */
	uint32_t *tris;       /* shared index buffer, 3 per triangle */
	uint32_t *prim_poly;  /* Embree primitive -> scene polygon */
	const uint32_t *twin; /* the scene's back faces (scene.h), or NULL */
	double eps;           /* trimming distance, metres */
	char embree_msg[200]; /* last message of the error callback */
	enum RTCError embree_code; /* first code of the error callback */
};

/* Embree reads the last vertex with a 16-byte load: pad 4 floats. */
#define VERT_PAD 4

/*
 * Allocations are reported before they happen (post = false), frees after
 * (post = true), each once, so the running sum is exact.  Measured on
 * 3.13.5: the sum is back to exactly zero once the scene is released
 * (the device itself reports nothing), which test_ff checks.
 */
static bool monitor_cb(void *ud, ssize_t bytes, bool post)
{
	/* An allocation refused here is not made (and not counted):
	 * Embree reports RTC_ERROR_OUT_OF_MEMORY. */
	if (bytes > 0 && !post && rad_mem_over_limit((size_t)bytes))
		return false;
	rad_mem_count(ud, RAD_MEM_BVH, (int64_t)bytes);
	return true;
}

static void error_cb(void *ud, enum RTCError code, const char *str)
{
	rad_vis *v = ud;
	if (v->embree_code == RTC_ERROR_NONE)
		v->embree_code = code;
	snprintf(v->embree_msg, sizeof(v->embree_msg), "embree error %d: %s",
	         (int)code, str ? str : "");
}

/* Fill the shared buffers from the polygons (double sums, float store). */
static void fill_buffers(rad_vis *v, const rad_scene *s)
{
	uint32_t nv = 0, nt = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		const rad_poly *p = &s->polys[i];
		int corners = p->quad ? 4 : 3;
		if (p->side == RAD_SIDE_BACK) /* its sheet is there */
			continue;
		v3_store_f(v->verts + 3 * (size_t)nv,
		           rad_poly_point(s, p, 0, 0));
		v3_store_f(v->verts + 3 * (size_t)nv + 3,
		           rad_poly_point(s, p, 1, 0));
		v3_store_f(v->verts + 3 * (size_t)nv + 6,
		           rad_poly_point(s, p, 0, 1));
		if (p->quad)
			v3_store_f(v->verts + 3 * (size_t)nv + 9,
			           rad_poly_point(s, p, 1, 1));
		/* Triangle (0, 1, 2); a parallelogram adds (1, 3, 2). */
		static const uint32_t corner[2][3] = {{0, 1, 2}, {1, 3, 2}};
		for (int k = 0; k < (p->quad ? 2 : 1); k++) {
			for (int j = 0; j < 3; j++)
				v->tris[3 * (size_t)nt + j] = nv + corner[k][j];
			v->prim_poly[nt++] = i;
		}
		nv += (uint32_t)corners;
	}
}

/*
 * eps: scale-relative, floored at a few float ulps of the largest
 * coordinate.  Measured on a rotated 1 m box 5 km from the origin (float
 * spacing 0.5 mm there): without the floor 67 % of the rays between its
 * faces came back blocked, with 1 ulp none; 4 ulps is the margin.
 */
static double trim_eps(const rad_scene *s)
{
	double cmax = 0;
	for (int i = 0; i < 3; i++)
		cmax = fmax(cmax, fmax(fabs(s->lo[i]), fabs(s->hi[i])));
	return fmax(RAD_VIS_EPS_REL * s->diag, 4.0 * FLT_EPSILON * cmax);
}

/* Release what v holds; afterwards the BVH count is back where it was. */
static void vis_destroy(rad_vis *v)
{
	if (v->scene)
		rtcReleaseScene(v->scene);
	if (v->device)
		rtcReleaseDevice(v->device);
	rad_mem_free(v->mem, RAD_MEM_BVH, v->verts);
	rad_mem_free(v->mem, RAD_MEM_BVH, v->tris);
	rad_mem_free(v->mem, RAD_MEM_BVH, v->prim_poly);
	rad_mem_free(v->mem, RAD_MEM_BVH, v);
}

static rad_status alloc_buffers(rad_vis *v, const rad_scene *s,
                                uint32_t *nverts, uint32_t *ntris,
                                rad_error *err)
{
	size_t nv = 0, nt = 0;
	for (uint32_t i = 0; i < s->npolys; i++) {
		if (s->polys[i].side == RAD_SIDE_BACK)
			continue;
		nv += s->polys[i].quad ? 4 : 3;
		nt += s->polys[i].quad ? 2 : 1;
	}
	v->verts = rad_mem_alloc(v->mem, RAD_MEM_BVH,
	                         (3 * nv + VERT_PAD) * sizeof(float));
	v->tris = rad_mem_alloc(v->mem, RAD_MEM_BVH, 3 * nt * sizeof(uint32_t));
	v->prim_poly =
	        rad_mem_alloc(v->mem, RAD_MEM_BVH, nt * sizeof(uint32_t));
	if (!v->verts || !v->tris || !v->prim_poly)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "bvh: out of memory for %zu triangles", nt);
	memset(v->verts + 3 * nv, 0, VERT_PAD * sizeof(float));
	*nverts = (uint32_t)nv;
	*ntris = (uint32_t)nt;
	return RAD_OK;
}

/* Out of memory is RAD_ERR_NOMEM, whichever way Embree tells it (the
 * callback has usually taken the code rtcGetDeviceError would give). */
static rad_status embree_fail(rad_vis *v, const char *what, rad_error *err)
{
	enum RTCError code = rtcGetDeviceError(v->device);
	if (v->embree_code == RTC_ERROR_OUT_OF_MEMORY)
		code = RTC_ERROR_OUT_OF_MEMORY;
	return rad_fail(err,
	                code == RTC_ERROR_OUT_OF_MEMORY ? RAD_ERR_NOMEM
	                                                : RAD_ERR_EMBREE,
	                "bvh: %s failed (%s)", what,
	                v->embree_msg[0] ? v->embree_msg : "no message");
}

static _Atomic int bvh_mode = RAD_BVH_FAST;

void rad_bvh_set_mode(rad_bvh_mode mode)
{
	atomic_store(&bvh_mode, (int)mode);
}

rad_bvh_mode rad_bvh_get_mode(void)
{
	return (rad_bvh_mode)atomic_load(&bvh_mode);
}

/* Device, geometry and committed scene over the filled buffers. */
static rad_status build_embree(rad_vis *v, uint32_t nverts, uint32_t ntris,
                               rad_error *err)
{
	v->device = rtcNewDevice(NULL);
	if (!v->device) {
		enum RTCError code = rtcGetDeviceError(NULL);
		return rad_fail(
		        err,
		        code == RTC_ERROR_OUT_OF_MEMORY ? RAD_ERR_NOMEM
		                                        : RAD_ERR_EMBREE,
		        "bvh: rtcNewDevice failed (embree error %d%s)",
		        (int)code,
		        code == RTC_ERROR_OUT_OF_MEMORY ? ": out of memory"
		                                        : "");
	}
	rtcSetDeviceErrorFunction(v->device, error_cb, v);
	rtcSetDeviceMemoryMonitorFunction(v->device, monitor_cb, v->mem);
	RTCGeometry g = rtcNewGeometry(v->device, RTC_GEOMETRY_TYPE_TRIANGLE);
	if (!g)
		return embree_fail(v, "rtcNewGeometry", err);
	rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
	                           RTC_FORMAT_FLOAT3, v->verts, 0,
	                           3 * sizeof(float), nverts);
	rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
	                           RTC_FORMAT_UINT3, v->tris, 0,
	                           3 * sizeof(uint32_t), ntris);
	rtcCommitGeometry(g);
	v->scene = rtcNewScene(v->device);
	if (v->scene) {
		rtcSetSceneFlags(
		        v->scene,
		        RTC_SCENE_FLAG_ROBUST |
		                RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION |
		                (rad_bvh_get_mode() == RAD_BVH_COMPACT
		                         ? RTC_SCENE_FLAG_COMPACT
		                         : RTC_SCENE_FLAG_NONE));
		rtcSetSceneBuildQuality(v->scene, RTC_BUILD_QUALITY_MEDIUM);
		rtcAttachGeometry(v->scene, g);
	}
	rtcReleaseGeometry(g);
	if (!v->scene)
		return embree_fail(v, "rtcNewScene", err);
	rtcCommitScene(v->scene);
	if (rtcGetDeviceError(v->device) != RTC_ERROR_NONE)
		return embree_fail(v, "rtcCommitScene", err);
	return RAD_OK;
}

rad_status rad_vis_build(rad_scene *s, rad_error *err)
{
	rad_vis_free(s);
	rad_vis *v = rad_mem_calloc(&s->mem, RAD_MEM_BVH, 1, sizeof(*v));
	if (!v)
		return rad_fail(err, RAD_ERR_NOMEM, "bvh: out of memory");
	v->mem = &s->mem;
	uint32_t nverts = 0, ntris = 0;
	rad_status st = alloc_buffers(v, s, &nverts, &ntris, err);
	if (!st) {
		fill_buffers(v, s);
		st = build_embree(v, nverts, ntris, err);
	}
	if (st) {
		vis_destroy(v);
		return st;
	}
	v->eps = trim_eps(s);
	v->twin = s->twin;
	s->vis = v;
	return RAD_OK;
}

void rad_vis_free(rad_scene *s)
{
	if (s->vis)
		vis_destroy(s->vis);
	s->vis = NULL;
}

void rad_vis_thread_init(void)
{
#if defined(__SSE__)
	_MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
	_MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
#endif
}

double rad_vis_eps(const rad_vis *v)
{
	return v->eps;
}

/* 1 if something lies on org + t dir, tnear < t < tfar (dir unit). */
static int occluded(const rad_vis *v, v3 org, v3 dir, double tnear, double tfar)
{
	struct RTCIntersectContext ctx;
	rtcInitIntersectContext(&ctx);
	struct RTCRay ray = {
	        .org_x = (float)org.x,
	        .org_y = (float)org.y,
	        .org_z = (float)org.z,
	        .tnear = (float)tnear,
	        .dir_x = (float)dir.x,
	        .dir_y = (float)dir.y,
	        .dir_z = (float)dir.z,
	        .time = 0.0f,
	        .tfar = (float)tfar,
	        .mask = 0xFFFFFFFFu,
	        .id = 0,
	        .flags = 0,
	};
	rtcOccluded1(v->scene, &ctx, &ray);
	/* Embree marks an occluded ray by setting tfar to -inf. */
	return ray.tfar < 0.0f;
}

/* Move a surface point off its surface by eps, to the side of `towards`. */
static v3 lift(v3 p, const v3 *n, v3 towards, double eps)
{
	if (!n)
		return p;
	double side = v3_dot(v3_sub(towards, p), *n) >= 0 ? eps : -eps;
	return v3_madd(p, *n, side);
}

int rad_vis_segment(const rad_vis *v, v3 a, const v3 *na, v3 b, const v3 *nb)
{
	double eps = v->eps;
	/* Closer than the trimming can resolve: nothing fits in between. */
	if (v3_len(v3_sub(b, a)) <= 3.0 * eps)
		return 1;
	v3 a2 = lift(a, na, b, eps), b2 = lift(b, nb, a, eps);
	v3 d = v3_sub(b2, a2);
	double len = v3_len(d);
	if (len <= 3.0 * eps)
		return 1;
	return !occluded(v, a2, v3_scale(d, 1.0 / len), eps, len - eps);
}

int rad_vis_covered(const rad_vis *v, v3 x, v3 n, double dist)
{
	if (!(dist > 2.0 * v->eps))
		return 0;
	return occluded(v, v3_madd(x, n, v->eps), n, v->eps, dist);
}

int rad_vis_keep_uncovered(const rad_vis *v, v3 n, double dist, v3 *pts,
                           v3 *nrm, int count, uint64_t *rays)
{
	int m = 0;
	for (int k = 0; k < count; k++) {
		if (rays)
			(*rays)++;
		if (rad_vis_covered(v, pts[k], n, dist))
			continue;
		pts[m] = pts[k];
		if (nrm)
			nrm[m] = nrm[k];
		m++;
	}
	return m;
}

int rad_vis_ray_free(const rad_vis *v, v3 a, const v3 *na, v3 d)
{
	v3 a2 = lift(a, na, v3_add(a, d), v->eps);
	return !occluded(v, a2, d, v->eps, INFINITY);
}

/* On a miss *t is set to tfar. */
uint32_t rad_vis_first_hit(const rad_vis *v, v3 org, v3 dir, double tfar,
                           double *t)
{
	*t = tfar;
	double len = v3_len(dir);
	if (!(len > 0))
		return UINT32_MAX;
	dir = v3_scale(dir, 1.0 / len);
	struct RTCIntersectContext ctx;
	rtcInitIntersectContext(&ctx);
	struct RTCRayHit rh;
	memset(&rh, 0, sizeof(rh));
	rh.ray.org_x = (float)org.x;
	rh.ray.org_y = (float)org.y;
	rh.ray.org_z = (float)org.z;
	rh.ray.dir_x = (float)dir.x;
	rh.ray.dir_y = (float)dir.y;
	rh.ray.dir_z = (float)dir.z;
	rh.ray.tfar = (float)tfar;
	rh.ray.mask = 0xFFFFFFFFu;
	rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
	rtcIntersect1(v->scene, &ctx, &rh);
	if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
		return UINT32_MAX;
	*t = rh.ray.tfar;
	return v->prim_poly[rh.hit.primID];
}

/*
 * The context of rad_vis_first_hit_front: Embree's context first, so the
 * filter can cast the pointer it is given back to the whole struct.
 */
typedef struct front_ctx {
	struct RTCIntersectContext ctx;
	const rad_vis *v;
	v3 dir;             /* the ray's direction */
	float back_t;       /* nearest back-face hit so far, or +inf */
	unsigned back_prim; /* its primitive */
} front_ctx;

/* 1 if dir meets primitive prim from its front (e1 x e2, as built by
 * fill_buffers; a parallelogram's second triangle has the same sense). */
static int prim_front(const rad_vis *v, unsigned prim, v3 dir)
{
	const uint32_t *t = v->tris + 3 * (size_t)prim;
	v3 a = v3_f(v->verts + 3 * (size_t)t[0]);
	v3 e1 = v3_sub(v3_f(v->verts + 3 * (size_t)t[1]), a);
	v3 e2 = v3_sub(v3_f(v->verts + 3 * (size_t)t[2]), a);
	return v3_dot(v3_cross(e1, e2), dir) < 0;
}

/*
 * Called for every candidate hit nearer than the current one, in no
 * particular order.  Back faces are noted (the nearest one) and rejected,
 * so the traversal goes on to find the nearest front face.  Offsets of the
 * packet layout of rtcore_ray.h (its accessors are C++ only): tfar is
 * float 8N + i of the ray, primID unsigned 5N + i of the hit; Embree has
 * put the candidate's distance in tfar.
 */
static void front_filter(const struct RTCFilterFunctionNArguments *args)
{
	front_ctx *fc = (front_ctx *)args->context;
	unsigned n = args->N;
	for (unsigned i = 0; i < n; i++) {
		if (args->valid[i] == 0)
			continue;
		unsigned prim = ((const unsigned *)args->hit)[5 * n + i];
		if (prim_front(fc->v, prim, fc->dir))
			continue;
		float t = ((const float *)args->ray)[8 * n + i];
		if (t < fc->back_t) {
			fc->back_t = t;
			fc->back_prim = prim;
		}
		args->valid[i] = 0;
	}
}

uint32_t rad_vis_first_hit_front(const rad_vis *v, v3 org, v3 dir, double tnear,
                                 double tfar, double *t, int *front)
{
	front_ctx fc = {.v = v, .dir = dir, .back_t = INFINITY};
	rtcInitIntersectContext(&fc.ctx);
	fc.ctx.filter = front_filter;
	struct RTCRayHit rh;
	memset(&rh, 0, sizeof(rh));
	rh.ray.org_x = (float)org.x;
	rh.ray.org_y = (float)org.y;
	rh.ray.org_z = (float)org.z;
	rh.ray.tnear = (float)tnear;
	rh.ray.dir_x = (float)dir.x;
	rh.ray.dir_y = (float)dir.y;
	rh.ray.dir_z = (float)dir.z;
	rh.ray.tfar = (float)tfar;
	rh.ray.mask = 0xFFFFFFFFu;
	rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
	rtcIntersect1(v->scene, &fc.ctx, &rh);
	int hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
	/* A back face wins only when it lies clearly before the front. */
	if (fc.back_t < INFINITY &&
	    (!hit || (double)fc.back_t < (double)rh.ray.tfar - v->eps)) {
		uint32_t poly = v->prim_poly[fc.back_prim];
		*t = fc.back_t;
		/* The back of a two-sided sheet is a face of its own. */
		if (v->twin && v->twin[poly] != RAD_NONE) {
			*front = 1;
			return v->twin[poly];
		}
		*front = 0;
		return poly;
	}
	*front = hit;
	*t = hit ? rh.ray.tfar : tfar;
	return hit ? v->prim_poly[rh.hit.primID] : UINT32_MAX;
}
