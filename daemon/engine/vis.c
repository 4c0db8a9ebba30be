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
 *   the bytes of this scene's BVH, counted as RAD_MEM_BVH in s->mem
 *   (with this struct).  The monitor is called from TBB worker threads:
 *   rad_mem_count is atomic.
 * - The geometry is held once: Embree reads the scene's own arrays
 *   (rtcSetSharedGeometryBuffer), the vertices and, as the index buffer
 *   of geometry 0, the polygons: their first three corners are a
 *   triangle, or the first half of a parallelogram, so primitive i of
 *   geometry 0 is polygon i (the back faces, after every polygon the BVH
 *   holds, are left out).  Geometry 1 holds the parallelograms' second
 *   halves, with their own index buffer and polygon map (16 bytes a
 *   parallelogram, counted as BVH).  Shared corners are one vertex, so
 *   neighbours meet without cracks.  Measured against one quad geometry
 *   read straight from the polygons (triangles repeating their last
 *   corner): its BVH was 1.0 MB larger on the grand hall (hr, 4
 *   iterations, 2 threads) and the whole run about 5 % slower, as
 *   Embree tests both halves of every quad.
 * - Vertices are relative to the scene's origin (scene.h), and so are
 *   the rays: a scene far from 0 is traced at the precision of one near
 *   it.
 * - The layout (rad_bvh_set_mode): compact, whose leaves index our
 *   shared vertices instead of holding copies, or Embree's default
 *   (fast).  Same hits, so the same results to the bit.  Measured, 2
 *   threads, 4 iterations of hr, rays one by one: the grand hall's BVH
 *   10.5 MB compact, 20.0 MB fast, solve 2.92 -> 2.71 s; the hospital
 *   room's 1.5 and 2.8 MB, 3.40 -> 3.17 s.  With packets (below) fast
 *   saved 2-10 % of whole runs, so compact is the default: the 1M
 *   field's BVH is 41.6 MB where fast's is 71.4.
 * - Packets.  The rays of one form factor run from a few points to a few
 *   points, so they go down the same BVH nodes: the callers that trace
 *   several at once (a form factor's point pairs, an element's cover
 *   points, a query's rays to a leaf or a cluster) hand them over
 *   together (rad_vis_segments, rad_vis_covered_n), and Embree traces
 *   16 at a time.  The packet kernels find the same hits as the one-ray
 *   kernel (hr's and rmb's JSON the same on the four real rooms and the
 *   grand hall).  Handed over one receiver point at a time, a packet
 *   held 3.9 rays on average (the Graz office, hr, 4 iterations); a
 *   form factor's at once, 11.0.
 *   Measured, whole luxrad-solve runs alternated with the one-ray code,
 *   2 threads, median of 3 pairs: the Graz office hr 0.80x, rmb 0.81x;
 *   the hospital room 0.86x, 0.72x; the grand hall (4 iterations)
 *   0.86x, 0.87x; the 1M field 0.85x, 0.85x (its setup, 16 cover rays
 *   a polygon, 0.77 -> 0.42 s).
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
#include <stddef.h>
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
	rad_mem *mem;          /* the scene's counters */
	const rad_poly *polys; /* the scene's: geometry 0's primitives */
	uint32_t *second;      /* geometry 1's index buffer, 3 per triangle */
	uint32_t *second_poly; /* geometry 1's primitive -> polygon */
	const uint32_t *twin;  /* the scene's back faces (scene.h), or NULL */
	v3 origin;             /* of the scene's vertices and of the rays */
	double eps;            /* trimming distance, metres */
	char embree_msg[200];  /* last message of the error callback */
	enum RTCError embree_code; /* first code of the error callback */
};

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

/*
 * eps: scale-relative, floored at a few float ulps of the largest
 * coordinate.  Measured on a rotated 1 m box 5 km from the origin (float
 * spacing 0.5 mm there): without the floor 67 % of the rays between its
 * faces came back blocked, with 1 ulp none; 4 ulps is the margin.
 * World coordinates, though the BVH is traced relative to the vertices'
 * origin: the points the solvers trace from are made from float world
 * origins (hier.h, Regions), and a floor of local ulps let them sink
 * below their own surface (that box: a third of its rays blocked).
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
	rad_mem_free(v->mem, RAD_MEM_BVH, v->second);
	rad_mem_free(v->mem, RAD_MEM_BVH, v->second_poly);
	rad_mem_free(v->mem, RAD_MEM_BVH, v);
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

static _Atomic int bvh_mode = RAD_BVH_DEFAULT;

void rad_bvh_set_mode(rad_bvh_mode mode)
{
	atomic_store(&bvh_mode, (int)mode);
}

rad_bvh_mode rad_bvh_get_mode(void)
{
	return (rad_bvh_mode)atomic_load(&bvh_mode);
}

/* Geometry 1: the second half (corners 0, 2, 3) of each parallelogram
 * in the BVH; returns their count, or UINT32_MAX if out of memory. */
static uint32_t fill_second(rad_vis *v, const rad_scene *s)
{
	uint32_t nq = 0;
	for (uint32_t i = 0; i < s->nfront; i++)
		nq += s->polys[i].quad;
	if (nq == 0)
		return 0;
	v->second = rad_mem_alloc(v->mem, RAD_MEM_BVH,
	                          3 * (size_t)nq * sizeof(uint32_t));
	v->second_poly =
	        rad_mem_alloc(v->mem, RAD_MEM_BVH, nq * sizeof(uint32_t));
	if (!v->second || !v->second_poly)
		return UINT32_MAX;
	uint32_t k = 0;
	for (uint32_t i = 0; i < s->nfront; i++) {
		const rad_poly *p = &s->polys[i];
		if (!p->quad)
			continue;
		v->second[3 * (size_t)k] = p->v[0];
		v->second[3 * (size_t)k + 1] = p->v[2];
		v->second[3 * (size_t)k + 2] = p->v[3];
		v->second_poly[k++] = i;
	}
	return nq;
}

/* A triangle geometry over the scene's vertices and the given index
 * buffer, attached as the next geometry id; 0 on failure. */
static int attach_triangles(rad_vis *v, const rad_scene *s, const void *index,
                            size_t offset, size_t stride, uint32_t count)
{
	RTCGeometry g = rtcNewGeometry(v->device, RTC_GEOMETRY_TYPE_TRIANGLE);
	if (!g)
		return 0;
	/* The vertex array ends with RAD_VERT_PAD zeros for Embree's 16-byte
	 * loads (scene.h). */
	rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
	                           RTC_FORMAT_FLOAT3, s->verts, 0,
	                           3 * sizeof(float), s->nverts);
	rtcSetSharedGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
	                           RTC_FORMAT_UINT3, index, offset, stride,
	                           count);
	rtcCommitGeometry(g);
	rtcAttachGeometry(v->scene, g);
	rtcReleaseGeometry(g);
	return 1;
}

/* Device, geometries and committed scene over the scene's arrays. */
static rad_status build_embree(rad_vis *v, const rad_scene *s, rad_error *err)
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
	uint32_t nq = fill_second(v, s);
	if (nq == UINT32_MAX)
		return rad_fail(err, RAD_ERR_NOMEM,
		                "bvh: out of memory for %u polygons",
		                s->nfront);
	v->scene = rtcNewScene(v->device);
	if (!v->scene)
		return embree_fail(v, "rtcNewScene", err);
	rtcSetSceneFlags(v->scene,
	                 RTC_SCENE_FLAG_ROBUST |
	                         RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION |
	                         (rad_bvh_get_mode() == RAD_BVH_COMPACT
	                                  ? RTC_SCENE_FLAG_COMPACT
	                                  : RTC_SCENE_FLAG_NONE));
	rtcSetSceneBuildQuality(v->scene, RTC_BUILD_QUALITY_MEDIUM);
	if (!attach_triangles(v, s, s->polys, offsetof(rad_poly, v),
	                      sizeof(rad_poly), s->nfront) ||
	    (nq &&
	     !attach_triangles(v, s, v->second, 0, 3 * sizeof(uint32_t), nq)))
		return embree_fail(v, "rtcNewGeometry", err);
	rtcCommitScene(v->scene);
	if (rtcGetDeviceError(v->device) != RTC_ERROR_NONE)
		return embree_fail(v, "rtcCommitScene", err);
	return RAD_OK;
}

/* The polygon of primitive prim of geometry geom. */
static uint32_t hit_poly(const rad_vis *v, unsigned geom, unsigned prim)
{
	return geom == 0 ? prim : v->second_poly[prim];
}

rad_status rad_vis_build(rad_scene *s, rad_error *err)
{
	rad_vis_free(s);
	rad_vis *v = rad_mem_calloc(&s->mem, RAD_MEM_BVH, 1, sizeof(*v));
	if (!v)
		return rad_fail(err, RAD_ERR_NOMEM, "bvh: out of memory");
	v->mem = &s->mem;
	v->polys = s->polys;
	v->origin = v3_d(s->origin);
	rad_status st = build_embree(v, s, err);
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
	org = v3_sub(org, v->origin);
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

/* A ray for occluded_n: occluded()'s arguments. */
typedef struct vis_ray {
	v3 org, dir;
	double tnear, tfar;
} vis_ray;

/* Rays traced together: Embree's widest packet. */
#define VIS_PACKET 16

/*
 * occluded() for each of n rays: blocked[k] its answer.  Rays go to
 * Embree VIS_PACKET at a time (rtcOccluded16, the lanes past n invalid),
 * a lone ray as one.  See DESIGN, packets.
 */
static void occluded_n(const rad_vis *v, const vis_ray *r, int n,
                       unsigned char *blocked)
{
	for (int base = 0; base < n; base += VIS_PACKET) {
		int m = n - base < VIS_PACKET ? n - base : VIS_PACKET;
		if (m == 1) {
			const vis_ray *q = &r[base];
			blocked[base] = (unsigned char)occluded(
			        v, q->org, q->dir, q->tnear, q->tfar);
			continue;
		}
		struct RTCRay16 p;
		int valid[VIS_PACKET];
		for (int k = 0; k < VIS_PACKET; k++) {
			valid[k] = k < m ? -1 : 0;
			const vis_ray *q = &r[base + (k < m ? k : 0)];
			v3 o = v3_sub(q->org, v->origin);
			p.org_x[k] = (float)o.x;
			p.org_y[k] = (float)o.y;
			p.org_z[k] = (float)o.z;
			p.tnear[k] = (float)q->tnear;
			p.dir_x[k] = (float)q->dir.x;
			p.dir_y[k] = (float)q->dir.y;
			p.dir_z[k] = (float)q->dir.z;
			p.time[k] = 0.0f;
			p.tfar[k] = (float)q->tfar;
			p.mask[k] = 0xFFFFFFFFu;
			p.id[k] = 0;
			p.flags[k] = 0;
		}
		struct RTCIntersectContext ctx;
		rtcInitIntersectContext(&ctx);
		rtcOccluded16(valid, v->scene, &ctx, &p);
		for (int k = 0; k < m; k++)
			blocked[base + k] = p.tfar[k] < 0.0f;
	}
}

/* Move a surface point off its surface by eps, to the side of `towards`. */
static v3 lift(v3 p, const v3 *n, v3 towards, double eps)
{
	if (!n)
		return p;
	double side = v3_dot(v3_sub(towards, p), *n) >= 0 ? eps : -eps;
	return v3_madd(p, *n, side);
}

/* The ray that decides segment a -> b (DESIGN, self-intersection), or 0
 * when the ends are too close for anything to fit between them. */
static int segment_ray(const rad_vis *v, v3 a, const v3 *na, v3 b, const v3 *nb,
                       vis_ray *r)
{
	double eps = v->eps;
	/* Closer than the trimming can resolve: nothing fits in between. */
	if (v3_len(v3_sub(b, a)) <= 3.0 * eps)
		return 0;
	v3 a2 = lift(a, na, b, eps), b2 = lift(b, nb, a, eps);
	v3 d = v3_sub(b2, a2);
	double len = v3_len(d);
	if (len <= 3.0 * eps)
		return 0;
	*r = (vis_ray){a2, v3_scale(d, 1.0 / len), eps, len - eps};
	return 1;
}

int rad_vis_segment(const rad_vis *v, v3 a, const v3 *na, v3 b, const v3 *nb)
{
	vis_ray r;
	if (!segment_ray(v, a, na, b, nb, &r))
		return 1;
	return !occluded(v, r.org, r.dir, r.tnear, r.tfar);
}

void rad_vis_segments(const rad_vis *v, const rad_vis_seg *s, int n,
                      unsigned char *open)
{
	vis_ray r[VIS_PACKET];
	int at[VIS_PACKET];
	unsigned char blocked[VIS_PACKET];
	for (int base = 0; base < n;) {
		int m = 0;
		for (; base < n && m < VIS_PACKET; base++) {
			open[base] = 1;
			if (segment_ray(v, s[base].a, &s[base].na, s[base].b,
			                &s[base].nb, &r[m]))
				at[m++] = base;
		}
		occluded_n(v, r, m, blocked);
		for (int k = 0; k < m; k++)
			open[at[k]] = !blocked[k];
	}
}

/* The ray that decides whether surface point x (normal n) is covered
 * within dist: from just off the surface, along the normal. */
static vis_ray cover_ray(const rad_vis *v, v3 x, v3 n, double dist)
{
	return (vis_ray){v3_madd(x, n, v->eps), n, v->eps, dist};
}

int rad_vis_covered(const rad_vis *v, v3 x, v3 n, double dist)
{
	if (!(dist > 2.0 * v->eps))
		return 0;
	vis_ray r = cover_ray(v, x, n, dist);
	return occluded(v, r.org, r.dir, r.tnear, r.tfar);
}

void rad_vis_covered_n(const rad_vis *v, v3 n, double dist, const v3 *pts,
                       int count, unsigned char *covered)
{
	if (!(dist > 2.0 * v->eps)) {
		memset(covered, 0, (size_t)(count > 0 ? count : 0));
		return;
	}
	for (int base = 0; base < count; base += VIS_PACKET) {
		int c = count - base < VIS_PACKET ? count - base : VIS_PACKET;
		vis_ray r[VIS_PACKET];
		for (int k = 0; k < c; k++)
			r[k] = cover_ray(v, pts[base + k], n, dist);
		occluded_n(v, r, c, covered + base);
	}
}

int rad_vis_keep_uncovered(const rad_vis *v, v3 n, double dist, v3 *pts,
                           v3 *nrm, int count, uint64_t *rays)
{
	if (rays)
		*rays += (uint64_t)(count > 0 ? count : 0);
	int m = 0;
	for (int base = 0; base < count; base += VIS_PACKET) {
		int c = count - base < VIS_PACKET ? count - base : VIS_PACKET;
		unsigned char covered[VIS_PACKET];
		rad_vis_covered_n(v, n, dist, pts + base, c, covered);
		for (int k = 0; k < c; k++) {
			if (covered[k])
				continue;
			pts[m] = pts[base + k];
			if (nrm)
				nrm[m] = nrm[base + k];
			m++;
		}
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
	org = v3_sub(org, v->origin);
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
	return hit_poly(v, rh.hit.geomID, rh.hit.primID);
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
	uint32_t back_poly; /* its polygon */
} front_ctx;

/* 1 if dir meets polygon i from its front. */
static int poly_front(const rad_vis *v, uint32_t i, v3 dir)
{
	return v3_dot(rad_poly_dir(&v->polys[i]), dir) < 0;
}

/*
 * Called for every candidate hit nearer than the current one, in no
 * particular order.  Back faces are noted (the nearest one) and rejected,
 * so the traversal goes on to find the nearest front face.  Offsets of the
 * packet layout of rtcore_ray.h (its accessors are C++ only): tfar is
 * float 8N + i of the ray, primID and geomID unsigned 5N + i and 6N + i
 * of the hit; Embree has put the candidate's distance in tfar.
 */
static void front_filter(const struct RTCFilterFunctionNArguments *args)
{
	front_ctx *fc = (front_ctx *)args->context;
	unsigned n = args->N;
	for (unsigned i = 0; i < n; i++) {
		if (args->valid[i] == 0)
			continue;
		const unsigned *hit = (const unsigned *)args->hit;
		uint32_t poly = hit_poly(fc->v, hit[6 * n + i], hit[5 * n + i]);
		if (poly_front(fc->v, poly, fc->dir))
			continue;
		float t = ((const float *)args->ray)[8 * n + i];
		if (t < fc->back_t) {
			fc->back_t = t;
			fc->back_poly = poly;
		}
		args->valid[i] = 0;
	}
}

uint32_t rad_vis_first_hit_front(const rad_vis *v, v3 org, v3 dir, double tnear,
                                 double tfar, double *t, int *front)
{
	front_ctx fc = {.v = v, .dir = dir, .back_t = INFINITY};
	org = v3_sub(org, v->origin);
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
		uint32_t poly = fc.back_poly;
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
	return hit ? hit_poly(v, rh.hit.geomID, rh.hit.primID) : UINT32_MAX;
}
