/*
 * rad.h -- the public interface of the luxrad engine.
 *
 * The engine is a library: it holds a scene (geometry, materials, light
 * sources, the Embree BVH) and solvers over that scene (matrix, progressive,
 * hierarchical radiosity with clustering).  It does no I/O of its own: it
 * never prints, never exits, never aborts on bad input.  Every fallible call
 * returns a rad_status and, when the caller passes one, fills a rad_error
 * with a message that names what was wrong.
 *
 * Units: metres, lux (lm/m2) for illuminance and exitance, cd/m2 for
 * luminance, candela for point and spot intensities, lux for directional
 * lights.  Radiometric quantities are RGB triples (photometric "channels");
 * the lux reported by queries is the photopic combination of the three.
 *
 * Ownership: objects made by rad_X_new are freed by rad_X_free.  A scene
 * must outlive every solver made on it.  A committed scene is read-only and
 * may be shared by any number of solvers and threads; a solver is used by
 * one thread at a time, except rad_solver_illuminance() and
 * rad_solver_stats(), which read the last published solution and may run
 * concurrently with each other (not with rad_solver_step()).
 */
#ifndef LUXRAD_RAD_H
#define LUXRAD_RAD_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------- errors */

typedef enum rad_status {
	RAD_OK = 0,
	RAD_ERR_NOMEM,   /* an allocation failed; the object is unchanged */
	RAD_ERR_INVALID, /* bad input: malformed scene, bad option, NaN... */
	RAD_ERR_UNSUPPORTED, /* valid input that the engine does not handle */
	RAD_ERR_STATE,       /* call not allowed in the object's state */
	RAD_ERR_EMBREE,      /* the ray tracing kernel reported an error */
	RAD_ERR_CANCELLED,   /* the caller's cancel flag was raised */
	RAD_ERR_LIMIT,       /* a configured limit (memory budget...) was hit */
	RAD_ERR_IO,          /* a file could not be read (tools only) */
} rad_status;

typedef struct rad_error {
	rad_status code;
	char msg[512]; /* NUL-terminated, names the offending object */
} rad_error;

/* Short constant name of a status ("invalid", "nomem"...). */
const char *rad_status_name(rad_status st);

/* ------------------------------------------------------ memory accounting */

/*
 * Every byte the engine holds is counted under exactly one kind.  The kinds
 * are listed once here; the report is the exact sum of what the engine's
 * allocations hold (malloc_usable_size of each block, plus what Embree's
 * memory monitor reports for the BVH), and every kind reads zero once the
 * owning object is freed.
 */
#define RAD_MEM_KINDS(X)                                                       \
	X(GEOMETRY, "geometry")   /* input polygons, vertices */               \
	X(MATERIALS, "materials") /* the shared material table */              \
	X(LIGHTS, "lights")       /* punctual and directional lights */        \
	X(NAMES, "names")         /* node and mesh names */                    \
	X(BVH, "bvh")             /* Embree: BVH and its buffers */            \
	X(ELEM_SURFACE,                                                        \
	  "elements_surface") /* quadtree elements of polygons */              \
	X(ELEM_CLUSTER, "elements_cluster") /* volume clusters */              \
	X(LINKS, "links")       /* link pool (active and passive) */           \
	X(MATRIX, "matrix")     /* the matrix solver's form factors */         \
	X(SCRATCH, "scratch")   /* per-iteration work buffers */               \
	X(STUDY, "study")       /* study statistics (rad_options.study) */     \
	X(SOLUTION, "solution") /* published copies (rad_solution) */

typedef enum rad_mem_kind {
#define RAD_MEM_ENUM_(name, str) RAD_MEM_##name,
	RAD_MEM_KINDS(RAD_MEM_ENUM_)
#undef RAD_MEM_ENUM_
	        RAD_MEM_NKINDS
} rad_mem_kind;

typedef struct rad_mem_report {
	int64_t bytes[RAD_MEM_NKINDS]; /* current bytes by kind */
	int64_t total;                 /* sum of bytes[] */
	int64_t peak_total;            /* high-water mark of total */
	int64_t peak_work; /* high-water mark of total minus study: what a
	                      solve without study statistics needs */
} rad_mem_report;

/* JSON-friendly name of a kind ("geometry", "links"...). */
const char *rad_mem_kind_name(rad_mem_kind kind);

/* ------------------------------------------------------------------ scene */

typedef struct rad_scene rad_scene;

typedef enum rad_light_kind {
	RAD_LIGHT_POINT = 0,  /* intensity in candela, isotropic */
	RAD_LIGHT_SPOT,       /* candela on axis, smooth glTF cone falloff */
	RAD_LIGHT_DIRECTIONAL /* illuminance in lux on a plane facing it */
} rad_light_kind;

typedef struct rad_light_desc {
	rad_light_kind kind;
	double position[3];  /* metres (point, spot) */
	double direction[3]; /* direction light travels (spot, directional) */
	double intensity[3]; /* candela (point, spot) or lux (directional) */
	double range;        /* metres; 0 = infinite (glTF default) */
	double inner_cone;   /* radians, spot only */
	double outer_cone;   /* radians, spot only */
	const char *name;    /* copied; may be NULL */
} rad_light_desc;

typedef struct rad_scene_counts {
	uint32_t triangles_in;         /* triangles offered to the builder */
	uint32_t triangles_nonfinite;  /* skipped: NaN or Inf coordinate */
	uint32_t triangles_degenerate; /* skipped: zero or sliver area */
	uint32_t triangles_duplicate;  /* dropped: a copy of an earlier one,
	                                  same vertices, same facing */
	uint32_t polygons;             /* polygons kept (after quad merging
	                                  and cutting) */
	uint32_t polygons_cut;         /* large polygons cut where another
	                                  surface runs across them */
	uint32_t quads;                /* of which parallelograms */
	uint32_t materials;            /* distinct materials stored */
	uint32_t materials_offered;    /* materials offered (before sharing) */
	uint32_t lights;
	uint32_t emitters; /* polygons with non-zero exitance */
	uint32_t nodes;
} rad_scene_counts;

/* Make an empty scene to be filled by the calls below, then committed. */
rad_status rad_scene_new(rad_scene **out, rad_error *err);

/*
 * Add a material; returns its id in *id.  Identical materials share one
 * entry (the id of the first is returned).  reflectance in [0,1) per
 * channel; luminance in cd/m2 (a Lambertian emitter's exitance is pi*L).
 */
rad_status rad_scene_add_material(rad_scene *s, const double reflectance[3],
                                  const double luminance[3], uint32_t *id,
                                  rad_error *err);

/* Add a named node (glTF node or mesh instance); returns its id. */
rad_status rad_scene_add_node(rad_scene *s, const char *name, uint32_t *id,
                              rad_error *err);

/*
 * Add ntri triangles given as 9 doubles each (three world-space vertices,
 * counter-clockwise seen from the front), all with one material and node.
 * Triangles with a non-finite coordinate or a degenerate shape are skipped
 * and counted, not refused.
 */
rad_status rad_scene_add_triangles(rad_scene *s, uint32_t material,
                                   uint32_t node, const double *xyz,
                                   size_t ntri, rad_error *err);

rad_status rad_scene_add_light(rad_scene *s, const rad_light_desc *light,
                               rad_error *err);

/*
 * Finish the scene: merge coplanar triangle pairs into parallelograms,
 * compute bounds and build the BVH.  After this the scene is read-only.
 */
rad_status rad_scene_commit(rad_scene *s, rad_error *err);

void rad_scene_counts_get(const rad_scene *s, rad_scene_counts *out);
void rad_scene_memory(const rad_scene *s, rad_mem_report *out);
/* Axis-aligned bounds of the geometry and the lights, metres. */
void rad_scene_bounds(const rad_scene *s, double lo[3], double hi[3]);
void rad_scene_free(rad_scene *s);

/* ----------------------------------------------------------------- solver */

typedef enum rad_solver_kind {
	RAD_SOLVER_MATRIX = 0,  /* full form-factor matrix, Gauss-Seidel */
	RAD_SOLVER_PROGRESSIVE, /* shooting with adaptive subdivision */
	RAD_SOLVER_HR,          /* hierarchical radiosity (+ clustering) */
	RAD_SOLVER_RMB, /* reduced-memory HR: radiosity to transmit, link
	                   hierarchy, RefineAndGather (ALGORITHM.md §4) */
	RAD_SOLVER_NKINDS
} rad_solver_kind;

typedef enum rad_oracle {
	RAD_ORACLE_BFA = 0, /* emitter radiosity x form factor x rcv area */
	RAD_ORACLE_F,       /* form factor alone */
	RAD_ORACLE_BF,      /* emitter radiosity x form factor */
} rad_oracle;

/* rmb: which links RefineAndGather keeps (ALGORITHM.md §4, criterion). */
typedef enum rad_store {
	/* The default: the report's rule, and also no children for a link
	 * whose next increment (this one times the source's largest
	 * reflectance) will pass the oracle at the link's own level -- a
	 * coarser level will do next time.  Measured: fewer links and a lower
	 * peak for the same error (README, "reduced-memory study"). */
	RAD_STORE_ANTICIPATE = 0,
	/* The report's rule alone: keep every link except those from or to
	 * a pure source (reflectance 0), whose transfer never changes. */
	RAD_STORE_MINIMAL,
} rad_store;

typedef struct rad_options {
	rad_solver_kind solver;
	rad_oracle oracle;
	/*
	 * Refinement threshold.  BFA: fraction of the total emitted flux a
	 * link may carry; BF: fraction of the mean emitted exitance; F: form
	 * factor.  Smaller is finer, slower, bigger.
	 */
	double eps;
	/*
	 * Receiver accuracy: a link is pushed to smaller receivers while the
	 * irradiance it brings varies over its receiver by more than this
	 * fraction of the scene's mean radiosity (hr: of the receiver's own
	 * irradiance where that is less, down to half).  Smaller is more
	 * accurate near corners and shadow edges, and finer.  hr and rmb (rmb
	 * applies it to each iteration's increment).
	 */
	double variation;
	/* Smallest element, as a fraction of the scene's bounding-box
	 * diagonal (edge length).  Stops refinement at corners. */
	double min_edge_rel;
	/* Matrix solver (and progressive's starting mesh): element edge,
	 * as a fraction of the bounding-box diagonal. */
	double mesh_edge_rel;
	int clustering;  /* hr, rmb: volume clusters on (default 1) */
	rad_store store; /* rmb: link creation criterion */
	/* Study statistics (re-created links): costs memory, counted as
	 * "study" and left out of mem.peak_work.  Off by default. */
	int study;
	/*
	 * Relative tolerance of illuminance queries: the final gather refines
	 * visibility, near field and far-field cut-offs until its estimated
	 * error is below this fraction of the answer.  Set by
	 * rad_options_accuracy(); > 0.
	 */
	double query_tol;
	/* error_estimate below which the solution counts as converged
	 * (rad_solver_converge with tol 0, stats.converged). */
	double converge_tol;
	double accuracy; /* what rad_options_accuracy() was given */
	int threads;     /* worker threads; 0 = number of cores */
	int rcv_samples; /* receiver points per form factor (1..16) */
	int vis_samples; /* shadow rays per receiver point (1..16) */
	/* Called from the stepping thread within long iterations; may be NULL.
	 */
	void (*progress)(void *ud, double fraction);
	void *progress_ud;
	/* Raised by another thread to stop a step early (RAD_ERR_CANCELLED);
	 * the engine reads it with an atomic load, so write it with one
	 * (__atomic_store_n or a C11 atomic store of the same int). */
	const volatile int *cancel;
} rad_options;

/*
 * Defaults: rad_options_accuracy(o, RAD_ACCURACY_DEFAULT) on top of the
 * solver-independent settings.
 */
void rad_options_default(rad_options *o);

/*
 * The one accuracy knob: queried lux should be within `accuracy` (a
 * relative error, e.g. 0.01 for 1 %) of the truth.  Sets eps, variation,
 * query_tol and converge_tol together; the expert knobs may still be
 * overridden afterwards.  o->accuracy records the value.
 * RAD_ERR_INVALID unless RAD_ACCURACY_MIN <= accuracy <= RAD_ACCURACY_MAX.
 */
#define RAD_ACCURACY_DEFAULT 0.02
#define RAD_ACCURACY_MIN 1e-3
#define RAD_ACCURACY_MAX 0.5
/* The query tolerance the default accuracy gives (rad_solution_query). */
#define RAD_QUERY_TOL_DEFAULT (RAD_ACCURACY_DEFAULT / 2)
rad_status rad_options_accuracy(rad_options *o, double accuracy,
                                rad_error *err);
/* Parse "matrix" / "progressive" / "hr" / "rmb"; RAD_ERR_INVALID if unknown. */
rad_status rad_solver_kind_parse(const char *name, rad_solver_kind *out);
const char *rad_solver_kind_name(rad_solver_kind k);

#define RAD_EHIST_BINS 16

typedef struct rad_stats {
	uint32_t iteration;     /* iterations done so far */
	double seconds;         /* wall time of the last iteration */
	double seconds_total;   /* wall time of all iterations */
	uint64_t links;         /* links stored */
	uint64_t links_ss;      /* surface -> surface */
	uint64_t links_sc;      /* involving one cluster */
	uint64_t links_cc;      /* cluster -> cluster (incl. self-links) */
	uint64_t links_light;   /* from point/spot/directional lights */
	uint64_t links_active;  /* active (leaf) links */
	uint64_t links_passive; /* passive links (hierarchy kept) */
	uint64_t links_created; /* stored this iteration */
	uint64_t links_deleted; /* stored before, removed this iteration */
	/* Of links_created, pairs deleted in an earlier iteration (counted
	 * only with rad_options.study, else 0). */
	uint64_t links_recreated;
	uint64_t links_gathered;  /* exchanges carried this iteration */
	uint64_t links_transient; /* of those, by links never stored */
	/* Of links_gathered, those whose increment (this iteration's
	 * transfer minus the last one's) would fail the oracle one level up
	 * (4 x its oracle value > eps): the links the exchange needs at
	 * their level, the report's "useful" links (§3.2.4). */
	uint64_t links_useful;
	/* Exchanges by energy carried (the oracle's BFA value: flux as a
	 * fraction of the total source flux): bin k counts values in
	 * [10^-(k+1), 10^-k); the last bin everything smaller, zero too. */
	uint64_t energy_hist[RAD_EHIST_BINS];
	uint64_t elements; /* surface elements */
	uint64_t clusters;
	uint64_t leaves;       /* surface leaves (the mesh) */
	uint64_t refinements;  /* element splits this iteration */
	uint64_t rays;         /* shadow rays this iteration */
	double residual;       /* relative change / unshot energy */
	double error_estimate; /* estimated remaining relative error */
	int converged;         /* error_estimate below the tolerance */
	rad_mem_report mem;    /* solver + scene memory */
} rad_stats;

typedef struct rad_solver rad_solver;

rad_status rad_solver_new(const rad_scene *scene, const rad_options *opt,
                          rad_solver **out, rad_error *err);

/*
 * One iteration (refine, gather, push-pull; or one sweep / batch of shots).
 * RAD_ERR_CANCELLED: the cancel flag was raised; the solution published is
 * consistent (refinement stopped at the level reached) and stepping may go
 * on once the flag is lowered.  Any other error (NOMEM, EMBREE) leaves a
 * solver that may be queried and freed, but not stepped again.
 */
rad_status rad_solver_step(rad_solver *sv, rad_error *err);

/* Step until error_estimate <= tol (0: opt.converge_tol) or max_iter
 * iterations were done. */
rad_status rad_solver_converge(rad_solver *sv, double tol, uint32_t max_iter,
                               rad_error *err);

/* Change the refinement threshold between iterations. */
rad_status rad_solver_set_eps(rad_solver *sv, double eps, rad_error *err);

void rad_solver_stats(const rad_solver *sv, rad_stats *out);

/*
 * Illuminance in lux at n points.  pts holds 6 doubles per point
 * (x y z nx ny nz); the normal need not be unit length but must not be
 * zero.  A point on a surface sees the side its normal points to.
 */
rad_status rad_solver_illuminance(const rad_solver *sv, const double *pts,
                                  size_t n, double *lux, rad_error *err);

/*
 * Illuminance with an error estimate.  tol is the relative tolerance of
 * the final gather (<= 0: the solver's query_tol); error_lux (may be NULL)
 * receives, per point, an estimate of |lux - truth| in lux: the gather's
 * own error (visibility, cut-offs, the solution's variation below its
 * leaves) plus the solver's convergence error_estimate times the
 * reflected part.
 */
rad_status rad_solver_query(const rad_solver *sv, const double *pts, size_t n,
                            double tol, double *lux, double *error_lux,
                            rad_error *err);

/* Per-leaf results, for export: calls fn once per leaf element. */
typedef void (*rad_leaf_fn)(void *ud, uint32_t node, const double p[4][3],
                            int nv, const double radiosity[3],
                            const double irradiance[3]);
void rad_solver_leaves(const rad_solver *sv, rad_leaf_fn fn, void *ud);

void rad_solver_free(rad_solver *sv);

/* --------------------------------------------------------------- solution */
/*
 * A solution is an immutable copy of a solver's published result (the
 * element and cluster hierarchy with its radiosity; no links).  It answers
 * the same queries as the solver, from any number of threads at once,
 * while the solver goes on stepping; the daemon publishes one per
 * iteration.  It holds no threads: queries run on the caller's thread.
 * A solution refers to its scene, which must outlive it.
 */
typedef struct rad_solution rad_solution;

/* Copy the solver's published result (between steps). */
rad_status rad_solution_new(const rad_solver *sv, rad_solution **out,
                            rad_error *err);
/* Same as rad_solver_illuminance, single-threaded. */
rad_status rad_solution_illuminance(const rad_solution *s, const double *pts,
                                    size_t n, double *lux, rad_error *err);
/*
 * Same as rad_solver_query.  tol <= 0 means RAD_QUERY_TOL_DEFAULT;
 * solve_error is the solver's error_estimate when the solution was taken
 * (rad_stats.error_estimate; a solution does not store it), 0 if unknown.
 */
rad_status rad_solution_query(const rad_solution *s, const double *pts,
                              size_t n, double tol, double solve_error,
                              double *lux, double *error_lux, rad_error *err);
void rad_solution_leaves(const rad_solution *s, rad_leaf_fn fn, void *ud);
/* Iteration the solution was taken after. */
uint32_t rad_solution_iteration(const rad_solution *s);
/* Bytes held (kind SOLUTION). */
void rad_solution_memory(const rad_solution *s, rad_mem_report *out);
/*
 * Serialize to bytes (*out malloc'ed, caller frees) and back.  Loading
 * checks the bytes against the scene (format version, polygon count, a
 * digest of the geometry, every id in range, finite values): bytes from
 * another scene or a damaged file get RAD_ERR_INVALID, never a crash.
 */
rad_status rad_solution_save(const rad_solution *s, unsigned char **out,
                             size_t *len, rad_error *err);
rad_status rad_solution_load(const rad_scene *scene, const void *bytes,
                             size_t len, rad_solution **out, rad_error *err);
void rad_solution_free(rad_solution *s);

/* -------------------------------------------------------------- reference */
/*
 * An independent Monte Carlo estimate of illuminance (reference.c): the
 * ground truth the solvers are validated against.  It shares only the
 * scene and its BVH with them.  Unbiased path tracing of one-sided
 * Lambertian surfaces (a ray meeting a back face is absorbed), with
 * next-event estimation to emitting polygons (combined with the bounce
 * by multiple importance sampling) and to every punctual and directional
 * light, and Russian roulette.  Each point gets a mean and the standard
 * error of that mean from the sample variance of its paths.
 *
 * Results depend on the seed, the options and each point's index in pts
 * (path j of point i is keyed by (seed, i, j)); never on the thread count
 * or the schedule: they are bit for bit reproducible.
 */
typedef struct rad_ref_options {
	uint64_t samples;     /* paths per point; 0 = run to target_error */
	double target_error;  /* samples 0: add paths to a point until its
	                         stderr <= target_error x its mean, (0, 1) */
	uint64_t max_samples; /* samples 0: paths per point at most, >= 2 */
	int threads;          /* 0..256; 0 = one per core */
	uint64_t seed;        /* any value; the same seed, the same result */
	/* Raised by another thread to stop early (RAD_ERR_CANCELLED);
	 * read with an atomic load, as rad_options.cancel. */
	const volatile int *cancel;
} rad_ref_options;

/* samples 0, target_error 0.005, max_samples 2^22, threads 0, seed 1. */
void rad_ref_options_default(rad_ref_options *o);

/*
 * Illuminance in lux at n points (6 doubles each: x y z nx ny nz, as
 * rad_solver_illuminance; a point sees the side its normal points to).
 * o may be NULL for the defaults.  lux[i] is the estimate, stderr_lux[i]
 * its standard error (NaN with fewer than 2 paths), samples_used[i] the
 * paths traced for it; stderr_lux and samples_used may be NULL.  The
 * scene must be committed (RAD_ERR_STATE); a non-finite point or a zero
 * normal is RAD_ERR_INVALID naming the point.  On RAD_ERR_CANCELLED the
 * outputs hold the estimates of the rounds completed.
 */
rad_status rad_reference_illuminance(const rad_scene *s, const double *pts,
                                     size_t n, const rad_ref_options *o,
                                     double *lux, double *stderr_lux,
                                     uint64_t *samples_used, rad_error *err);

/* Name of a scene node (glTF node / mesh), "" when it has none. */
const char *rad_scene_node_name(const rad_scene *s, uint32_t node);

/* Seconds on a monotonic clock (the one the statistics are timed with). */
double rad_seconds(void);

/* Photopic weights used to turn RGB into one lux value. */
#define RAD_LUMA_R 0.2126
#define RAD_LUMA_G 0.7152
#define RAD_LUMA_B 0.0722

#ifdef __cplusplus
}
#endif
#endif
