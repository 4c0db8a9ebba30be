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
 *
 * The Monte Carlo estimator the solvers are validated against has a
 * header of its own, rad_reference.h: it is no part of solving.
 */
#ifndef LUXRAD_RAD_H
#define LUXRAD_RAD_H

#include <math.h>
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

/*
 * Fill err (when not NULL) with code and a printf-style message naming
 * what was wrong; returns code, so a failure path reads
 *     return rad_fail(err, RAD_ERR_INVALID, "node %u: ...", id);
 * The engine reports every failure this way, and so do the libraries
 * that report through rad_error (the scene library).
 */
rad_status rad_fail(rad_error *err, rad_status code, const char *fmt, ...)
        __attribute__((format(printf, 3, 4)));
/* Mark err as success (code RAD_OK, empty message). */
void rad_error_clear(rad_error *err);

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
	X(STUDY, "study")       /* statistics' own (rad_options.study; hr's    \
	                           per-thread tallies, the waves' per-thread   \
	                           ray counts) */                              \
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
	int64_t peak_total; /* high-water mark of total (a solver's stats:
	                       of the solver and its scene together) */
	int64_t peak_work;  /* high-water mark of total minus study: what a
	                       solve without study statistics needs */
	int64_t peak_own;   /* a solver's stats: the high-water mark of its
	                       own work, the scene left out (what
	                       memory_budget bounds); else peak_work */
} rad_mem_report;

/* JSON-friendly name of a kind ("geometry", "links"...). */
const char *rad_mem_kind_name(rad_mem_kind kind);

/*
 * A process-wide memory limit over every counted allocation (scenes,
 * solvers, solutions, Embree's BVH): with a limit set, an allocation that
 * would take the bytes counted in the process (or, after rad_mem_share,
 * in every process sharing the count) past it fails as if the
 * allocator had no memory, and the caller gets RAD_ERR_NOMEM (Embree's
 * allocations are refused through its memory monitor).  Threads check and
 * count separately, so the total may pass the limit by at most one
 * allocation per thread.  0 = no limit (the default).  The daemon's
 * memory_limit is this.
 */
void rad_mem_set_limit(int64_t bytes);
int64_t rad_mem_limit(void);
/* Bytes counted in the process now (every rad_mem added up). */
int64_t rad_mem_process_bytes(void);
/* Allocations the limit has refused since the process started. */
uint64_t rad_mem_limit_refusals(void);

/*
 * How the scenes committed from now on lay out their BVH, process-wide.
 * RAD_BVH_FAST is Embree's default (triangles copied into its leaves);
 * RAD_BVH_COMPACT keeps indices into the vertex buffer the engine shares
 * with Embree (RTC_SCENE_FLAG_COMPACT), the default.  The rays find the
 * same hits either way, so results are the same to the bit; fast trades
 * memory for ray speed (README, "Memory accounting": measured on the
 * grand hall, the real rooms and the 1M-triangle field).
 */
typedef enum rad_bvh_mode { RAD_BVH_FAST = 0, RAD_BVH_COMPACT } rad_bvh_mode;
#define RAD_BVH_CHOICES "fast", "compact" /* names, in the enum's order */
#define RAD_BVH_DEFAULT RAD_BVH_COMPACT
void rad_bvh_set_mode(rad_bvh_mode mode);
rad_bvh_mode rad_bvh_get_mode(void);

/*
 * One limit over several processes (the daemon and its solver
 * processes).  After rad_mem_share(g, own), every count of this process
 * is also added to g->bytes and to *own, the limit is judged against
 * g->bytes, and each refusal is also counted in g->refusals.  g and own
 * are meant to live in memory the processes map together (MAP_SHARED);
 * they are only touched with atomic operations.  *own is this process's
 * share, so that the process that made the mapping can take a dead
 * process's bytes back out of g->bytes.  The bytes already counted are
 * added on the call; rad_mem_share(NULL, NULL) takes them out again and
 * stops sharing.  Call it while no other thread allocates.
 */
typedef struct rad_mem_shared {
	int64_t bytes;     /* counted by every sharing process */
	uint64_t refusals; /* refused by the limit in any of them */
} rad_mem_shared;
void rad_mem_share(rad_mem_shared *g, int64_t *own);
/* What the limit is judged against: g->bytes while shared, else
 * rad_mem_process_bytes(). */
int64_t rad_mem_limit_held(void);

/* ------------------------------------------------------------------ scene */

typedef struct rad_scene rad_scene;

typedef enum rad_light_kind {
	RAD_LIGHT_POINT = 0,  /* intensity in candela, isotropic, or a
	                         goniometric table (rad_light_desc.candela) */
	RAD_LIGHT_SPOT,       /* candela on axis, smooth glTF cone falloff */
	RAD_LIGHT_DIRECTIONAL /* illuminance in lux on a plane facing it */
} rad_light_kind;

/*
 * A goniometric intensity table (type C photometry, as IES LM-63 and
 * EULUMDAT files give it): intensity in candela at C-plane angles
 * (azimuth about the luminaire's axis) and gamma angles (from the nadir,
 * 0, to the zenith, 180), degrees.  Between the given angles the
 * intensity is bilinear in (C, gamma); C wraps round from the last plane
 * to the first + 360; outside [gamma first, gamma last] it is 0.  One C
 * plane means rotational symmetry.  Borrowed by the calls that take it.
 */
#define RAD_CANDELA_MAX_ANGLES 4096u      /* per axis */
#define RAD_CANDELA_MAX_VALUES (1u << 20) /* nc x ngamma */

typedef struct rad_candela_grid {
	uint32_t nc;             /* C planes, >= 1 */
	uint32_t ngamma;         /* gamma angles per plane, >= 2 */
	const double *c_deg;     /* nc, strictly ascending, in [0, 360] */
	const double *gamma_deg; /* ngamma, strictly ascending, in [0, 180] */
	const double *cd;        /* nc x ngamma, plane after plane: the value
	                            at (c_deg[i], gamma_deg[j]) is
	                            cd[i * ngamma + j]; finite, >= 0 */
} rad_candela_grid;

/* RAD_ERR_INVALID naming the defect, or RAD_OK for a usable grid. */
rad_status rad_candela_check(const rad_candela_grid *g, rad_error *err);
/* Intensity in the direction (c, gamma), degrees (any C; gamma outside
 * the table is 0).  g must have passed rad_candela_check. */
double rad_candela_at(const rad_candela_grid *g, double c_deg,
                      double gamma_deg);
/* Luminous flux, lm: the exact integral over the sphere of the bilinear
 * intensity rad_candela_at gives. */
double rad_candela_flux(const rad_candela_grid *g);
/* The largest value of the table, cd. */
double rad_candela_peak(const rad_candela_grid *g);

typedef struct rad_light_desc {
	rad_light_kind kind;
	double position[3];  /* metres (point, spot) */
	double direction[3]; /* direction light travels (spot, directional);
	                        with candela: the nadir, gamma 0 */
	double intensity[3]; /* candela (point, spot) or lux (directional);
	                        with candela: an RGB factor on the table
	                        (1, 1, 1 = the table's candela) */
	double range;        /* metres; 0 = infinite (glTF default) */
	double inner_cone;   /* radians, spot only */
	double outer_cone;   /* radians, spot only */
	const char *name;    /* copied; may be NULL */
	const rad_candela_grid *candela; /* point only: a luminaire's
	                                    distribution, copied; NULL =
	                                    isotropic */
	double c0_axis[3]; /* with candela: the direction of C = 0 (made
	                      perpendicular to direction); C = 90 is
	                      c0_axis x direction.  May be zero when
	                      candela->nc is 1 */
	/* With candela: the luminous opening, metres: its length along
	 * C = 0 and width along C = 90 (a rectangle), or with opening_round
	 * a disk of diameter opening[0]; 0, 0: a point.  The intensity is
	 * spread evenly over it, each part radiating the table. */
	double opening[2];
	int opening_round;
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
	uint32_t back_faces;           /* of which the back faces of
	                                  two-sided polygons */
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
/* Name of a scene node (glTF node / mesh), "" when it has none. */
const char *rad_scene_node_name(const rad_scene *s, uint32_t node);

/*
 * Add ntri triangles given as 9 doubles each (three world-space vertices,
 * counter-clockwise seen from the front), all with one material and node.
 * Triangles with a non-finite coordinate or a degenerate shape are skipped
 * and counted, not refused.
 */
rad_status rad_scene_add_triangles(rad_scene *s, uint32_t material,
                                   uint32_t node, const double *xyz,
                                   size_t ntri, rad_error *err);

/*
 * As rad_scene_add_triangles, each triangle with its own reflectance (3
 * per triangle, each in [0, 1)) in place of the material's, which still
 * gives the luminance: a textured surface, where each polygon reflects
 * the mean of its texture.  Triangles offered together under one material
 * still merge into quads; a quad reflects the area-weighted mean of its
 * two triangles'.  Materials are made per distinct reflectance and
 * counted as any others.
 */
rad_status rad_scene_add_triangles_rho(rad_scene *s, uint32_t material,
                                       uint32_t node, const double *xyz,
                                       const double *rho, size_t ntri,
                                       rad_error *err);

/* Triangles of one material and node, in full (the calls above are
 * this with rho NULL and one-sided). */
typedef struct rad_surface_desc {
	uint32_t material, node;
	const double *xyz; /* 9 per triangle, as rad_scene_add_triangles */
	const double *rho; /* NULL, or 3 per triangle: their reflectance */
	size_t ntri;
	/*
	 * 1: each triangle reflects (and emits) on both sides: a wall, a
	 * partition, a ceiling panel modelled as one sheet.  Its back face is
	 * a polygon of its own for the solvers (counted in back_faces: it
	 * has its own elements and radiosity), while the BVH holds the sheet
	 * once: what hits it from behind meets the back face, and nothing
	 * passes through.
	 */
	int two_sided;
} rad_surface_desc;

rad_status rad_scene_add_surface(rad_scene *s, const rad_surface_desc *d,
                                 rad_error *err);

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

/* A committed scene's polygon as stored: what the solvers see. */
typedef struct rad_polygon_desc {
	double corners[4][3]; /* counter-clockwise seen from the front */
	int ncorners;         /* 3, or 4 for a parallelogram */
	double normal[3];     /* unit, front side */
	double area;          /* m2 */
	uint32_t node;        /* rad_scene_node_name() */
	int back_face;        /* the back face of a two-sided polygon */
	double reflectance[3];
	double luminance[3]; /* cd/m2 */
} rad_polygon_desc;

/* Polygon i, i < rad_scene_counts.polygons, of a committed scene. */
rad_status rad_scene_polygon_get(const rad_scene *s, uint32_t i,
                                 rad_polygon_desc *out, rad_error *err);

/* ----------------------------------------------------------------- solver */

typedef enum rad_solver_kind {
	RAD_SOLVER_MATRIX = 0,  /* full form-factor matrix, Gauss-Seidel */
	RAD_SOLVER_PROGRESSIVE, /* shooting with adaptive subdivision */
	RAD_SOLVER_HR,          /* hierarchical radiosity (+ clustering) */
	RAD_SOLVER_RMB, /* reduced-memory HR: radiosity to transmit, link
	                   hierarchy, RefineAndGather (docs/ALGORITHM.md §5) */
	RAD_SOLVER_NKINDS
} rad_solver_kind;

typedef enum rad_oracle {
	RAD_ORACLE_BFA = 0, /* emitter radiosity x form factor x rcv area */
	RAD_ORACLE_F,       /* form factor alone */
	RAD_ORACLE_BF,      /* emitter radiosity x form factor */
} rad_oracle;

/* rmb: which links RefineAndGather keeps (docs/ALGORITHM.md §5.4). */
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

/*
 * Every tunable option of the engine, declared once.  luxrad-solve's
 * command line, the protocol's job options and their checks, the client's
 * help, the daemon's job defaults, PROTOCOL.md's table and the JSON of a
 * job's effective options are all made from this list; test_options
 * fails when a document differs from it.
 *
 * X(field, key, cli, type, def, lo, hi, range, choices, metavar, unit, help)
 *   field    the rad_options member
 *   key      its name in the protocol, the config file and JSON
 *   cli      the long option of luxrad-solve and luxrad, without "--";
 *            for a BOOL, the flag that sets the opposite of the default
 *   type     DOUBLE, INT, BOOL or ENUM (an int indexing `choices`)
 *   def      the default; for the options `accuracy` sets, the value it
 *            gives at RAD_ACCURACY_DEFAULT
 *   lo, hi   accepted range of numbers (hi may be HUGE_VAL)
 *   range    which ends are excluded: RAD_RANGE_CLOSED, _LO_OPEN,
 *            _HI_OPEN, _OPEN
 *   choices  ENUM: a macro listing the names in enum order; else
 *            RAD_NO_CHOICES
 *   metavar  the value's name in help text; unit: "" when none
 *   help     one line
 *
 * `accuracy` comes first: it sets eps, variation, query_tol and tol
 * together (rad_options_accuracy), and any of those given beside it
 * overrides it whatever the order they were given in.
 *
 * What the knobs mean in more words:
 * - eps.  BFA: fraction of the total emitted flux a link may carry; BF:
 *   fraction of the mean emitted exitance; F: form factor.
 * - variation.  A link is pushed to smaller receivers while the
 *   irradiance it brings varies over its receiver by more than this
 *   fraction of the scene's mean radiosity (hr: of the receiver's own
 *   irradiance where that is less, down to half).  Smaller is more
 *   accurate near corners and shadow edges, and finer.  rmb applies it
 *   to each iteration's increment.
 * - min_edge_rel stops refinement at corners; mesh_edge_rel is the
 *   matrix solver's element and progressive's starting mesh.
 * - study keeps statistics of re-created links: its memory is counted as
 *   "study" and left out of mem.peak_work.
 * - query_tol: the final gather refines visibility, near field and
 *   far-field cut-offs until its estimated error is below this fraction
 *   of the answer.
 * - converge_tol: rad_solver_converge with tol 0 and stats.converged.
 */
#define RAD_ACCURACY_DEFAULT 0.02
#define RAD_ACCURACY_MIN 1e-3
#define RAD_ACCURACY_MAX 0.5
/* The query tolerance the default accuracy gives (rad_solution_query). */
#define RAD_QUERY_TOL_DEFAULT (RAD_ACCURACY_DEFAULT / 2)
#define RAD_ORACLE_CHOICES "bfa", "f", "bf"
#define RAD_STORE_CHOICES "anticipate", "minimal"
#define RAD_NO_CHOICES NULL
/* clang-format off */
#define RAD_OPTIONS(X)                                                         \
	X(accuracy, "accuracy", "accuracy", DOUBLE, RAD_ACCURACY_DEFAULT,      \
	  RAD_ACCURACY_MIN, RAD_ACCURACY_MAX,                                  \
	  RAD_RANGE_CLOSED, RAD_NO_CHOICES, "R", "",                           \
	  "target relative error of the lux reported; sets eps, variation, "   \
	  "tol and query_tol together (each given beside it overrides it)")    \
	X(eps, "eps", "eps", DOUBLE, 1e-4, 0, HUGE_VAL, RAD_RANGE_OPEN,        \
	  RAD_NO_CHOICES, "E", "",                                             \
	  "refinement threshold; smaller is finer (meaning by oracle)")        \
	X(oracle, "oracle", "oracle", ENUM, RAD_ORACLE_BFA, 0, 2,              \
	  RAD_RANGE_CLOSED, RAD_ORACLE_CHOICES, "NAME", "",                    \
	  "refinement test: bfa (flux), bf (exitance), f (form factor)")       \
	X(variation, "variation", "variation", DOUBLE, 0.5, 0, HUGE_VAL,       \
	  RAD_RANGE_OPEN, RAD_NO_CHOICES, "V", "",                             \
	  "hr, rmb: receiver accuracy, fraction of the mean radiosity")        \
	X(min_edge_rel, "min_edge_rel", "min-edge", DOUBLE, 5e-3, 0, 1,        \
	  RAD_RANGE_OPEN, RAD_NO_CHOICES, "X", "",                             \
	  "smallest element edge, fraction of the scene diagonal")             \
	X(mesh_edge_rel, "mesh_edge_rel", "mesh-edge", DOUBLE, 0.05, 0, 1,     \
	  RAD_RANGE_LO_OPEN, RAD_NO_CHOICES, "X", "",                          \
	  "matrix, progressive: mesh element edge, fraction of the diagonal")  \
	X(clustering, "clustering", "no-clustering", BOOL, 1, 0, 1,            \
	  RAD_RANGE_CLOSED, RAD_NO_CHOICES, "BOOL", "",                        \
	  "hr, rmb: volume clusters (off: every polygon pair linked)")         \
	X(delay, "delay", "delay", DOUBLE, 0, 0, 1, RAD_RANGE_CLOSED,          \
	  RAD_NO_CHOICES, "A", "",                                             \
	  "rmb: delayed emission; a leaf holds back radiosity to send below "  \
	  "this fraction of the last mean (0 = off)")                         \
	X(store, "store", "store", ENUM, RAD_STORE_ANTICIPATE, 0, 1,           \
	  RAD_RANGE_CLOSED, RAD_STORE_CHOICES, "NAME", "",                     \
	  "rmb: link creation criterion; minimal = the report's rule alone")   \
	X(study, "study", "study", BOOL, 0, 0, 1, RAD_RANGE_CLOSED,            \
	  RAD_NO_CHOICES, "BOOL", "",                                          \
	  "count re-created links (memory counted as study)")                  \
	X(threads, "threads", "threads", INT, 0, 0, 256, RAD_RANGE_CLOSED,     \
	  RAD_NO_CHOICES, "N", "",                                             \
	  "engine threads; 0 = one per core (luxradd: its solver_threads)")    \
	X(rcv_samples, "rcv_samples", "rcv-samples", INT, 4, 1, 16,            \
	  RAD_RANGE_CLOSED, RAD_NO_CHOICES, "N", "",                           \
	  "receiver points per form factor")                                   \
	X(vis_samples, "vis_samples", "vis-samples", INT, 4, 1, 16,            \
	  RAD_RANGE_CLOSED, RAD_NO_CHOICES, "N", "",                           \
	  "shadow rays per receiver point")                                    \
	X(query_tol, "query_tol", "query-tol", DOUBLE, 0.01, 0, 1,             \
	  RAD_RANGE_OPEN, RAD_NO_CHOICES, "T", "",                             \
	  "relative tolerance of the final gather of illuminance queries")     \
	X(converge_tol, "tol", "tol", DOUBLE, 1e-3, 0, 1, RAD_RANGE_LO_OPEN,   \
	  RAD_NO_CHOICES, "T", "",                                             \
	  "converged when the estimated relative error is at most this")       \
	X(max_iterations, "max_iterations", "max-iterations", INT, 10000, 1,   \
	  1e9, RAD_RANGE_CLOSED, RAD_NO_CHOICES, "N", "",                      \
	  "iteration cap when converging") \
	X(memory_budget, "memory_budget", "memory-budget", DOUBLE, 0, 0,       \
	  HUGE_VAL, RAD_RANGE_HI_OPEN, RAD_NO_CHOICES, "MIB", "MiB",           \
	  "the solver's memory, MiB; hr and rmb refine no further than it "   \
	  "allows (0 = no budget)")
/* clang-format on */

typedef enum rad_opt_type {
	RAD_OPT_DOUBLE,
	RAD_OPT_INT,
	RAD_OPT_BOOL,
	RAD_OPT_ENUM
} rad_opt_type;

enum {
	RAD_RANGE_CLOSED = 0,
	RAD_RANGE_LO_OPEN = 1,
	RAD_RANGE_HI_OPEN = 2,
	RAD_RANGE_OPEN = 3
};

#define RAD_OPT_CTYPE_DOUBLE double
#define RAD_OPT_CTYPE_INT int
#define RAD_OPT_CTYPE_BOOL int
#define RAD_OPT_CTYPE_ENUM int

typedef struct rad_options {
	rad_solver_kind solver;
#define RAD_OPT_FIELD_(field, key, cli, type, ...) RAD_OPT_CTYPE_##type field;
	RAD_OPTIONS(RAD_OPT_FIELD_)
#undef RAD_OPT_FIELD_
	/* Called from the stepping thread within long iterations; may be NULL.
	 */
	void (*progress)(void *ud, double fraction);
	void *progress_ud;
	/* Raised by another thread to stop a step early (RAD_ERR_CANCELLED);
	 * the engine reads it with an atomic load, so write it with one
	 * (__atomic_store_n or a C11 atomic store of the same int). */
	const volatile int *cancel;
} rad_options;

/* One row of RAD_OPTIONS, for code that walks the options. */
typedef struct rad_option_def {
	const char *key, *cli;
	rad_opt_type type;
	size_t offset; /* of the field in rad_options */
	double def, lo, hi;
	int range;                  /* RAD_RANGE_* */
	const char *const *choices; /* ENUM: names, NULL-terminated */
	const char *metavar, *unit, *help;
} rad_option_def;

enum {
#define RAD_OPT_COUNT_(field, ...) RAD_OPT_##field,
	RAD_OPTIONS(RAD_OPT_COUNT_)
#undef RAD_OPT_COUNT_
	        RAD_NOPTIONS
};

/* The rows of RAD_OPTIONS in order (RAD_NOPTIONS of them). */
extern const rad_option_def rad_option_defs[RAD_NOPTIONS];

/* The row whose key (or, for _cli, whose cli name of len bytes) this
 * is; NULL when none. */
const rad_option_def *rad_option_find(const char *key);
const rad_option_def *rad_option_find_cli(const char *cli, size_t len);

/* An option's value as a double (INT, BOOL and ENUM as their int). */
double rad_option_get(const rad_options *o, const rad_option_def *d);

/*
 * Set an option from a number after checking it: finite, within the
 * range, whole for INT, 0/1 for BOOL, a choice index for ENUM.
 * RAD_ERR_INVALID names the key and its range: option "eps" must be > 0
 * (got -1).  Setting `accuracy` sets the knobs it governs too
 * (rad_options_accuracy): set it before the options that override them.
 */
rad_status rad_option_set(rad_options *o, const rad_option_def *d, double v,
                          rad_error *err);

/* Index of `name` among an ENUM's choices, -1 if it is none of them. */
int rad_option_choice(const rad_option_def *d, const char *name);

/* The accepted range as text: "> 0", "in [1, 16]", "in (0, 1)". */
void rad_option_range_text(const rad_option_def *d, char *buf, size_t len);

/* The default as text: "1e-4" style numbers, "true", or a choice name. */
void rad_option_default_text(const rad_option_def *d, char *buf, size_t len);

/* Check every option against the table and the solver kind, as
 * rad_solver_new does. */
rad_status rad_options_check(const rad_options *o, rad_error *err);

/* Every option at its default (the def column), solver hr, no progress
 * callback, no cancel flag. */
void rad_options_default(rad_options *o);

/*
 * The one accuracy knob: queried lux should be within `accuracy` (a
 * relative error, e.g. 0.01 for 1 %) of the truth.  Sets eps, variation,
 * query_tol and converge_tol together; the expert knobs may still be
 * overridden afterwards.  o->accuracy records the value.
 * RAD_ERR_INVALID unless RAD_ACCURACY_MIN <= accuracy <= RAD_ACCURACY_MAX.
 */
rad_status rad_options_accuracy(rad_options *o, double accuracy,
                                rad_error *err);
/* Parse "matrix" / "progressive" / "hr" / "rmb"; RAD_ERR_INVALID if unknown. */
rad_status rad_solver_kind_parse(const char *name, rad_solver_kind *out);
const char *rad_solver_kind_name(rad_solver_kind k);

#define RAD_EHIST_BINS 16

/* The kind column of RAD_STATS, as a consumer pastes it: RAD_STAT_##kind. */
typedef enum rad_stat_kind {
	RAD_STAT_GAUGE,
	RAD_STAT_STEP,
	RAD_STAT_TOTAL
} rad_stat_kind;

/*
 * A solver's statistics, declared once: the struct, the one JSON encoding
 * (luxrad-solve --json, job.info, iteration events) and the documentation
 * are made from this list.
 *
 * X(field, group, key, type, kind, unit, help)
 *   group    "" or the JSON object the value sits in ("links")
 *   key      its name there
 *   type     U32, U64, DOUBLE, BOOL, HIST (RAD_EHIST_BINS counts) or MEM
 *   kind     GAUGE (a state: the value now), STEP (what the last
 *            iteration did), TOTAL (summed over all iterations)
 */
/* clang-format off */
#define RAD_STATS(X)                                                           \
	X(iteration, "", "iteration", U32, TOTAL, "", "iterations done so far") \
	X(seconds, "", "seconds", DOUBLE, STEP, "s",                           \
	  "wall time of the last iteration")                                   \
	X(seconds_total, "", "seconds_total", DOUBLE, TOTAL, "s",              \
	  "wall time of all iterations")                                       \
	X(links, "links", "stored", U64, GAUGE, "", "links stored")            \
	X(links_ss, "links", "ss", U64, GAUGE, "", "surface to surface")       \
	X(links_sc, "links", "sc", U64, GAUGE, "", "involving one cluster")    \
	X(links_cc, "links", "cc", U64, GAUGE, "",                             \
	  "cluster to cluster (self-links too)")                               \
	X(links_light, "links", "light", U64, GAUGE, "",                       \
	  "from point, spot and directional lights")                           \
	X(links_active, "links", "active", U64, GAUGE, "", "active (leaf) links") \
	X(links_passive, "links", "passive", U64, GAUGE, "",                   \
	  "passive links (the hierarchy kept)")                                \
	X(links_created, "links", "created", U64, STEP, "",                    \
	  "stored this iteration")                                             \
	X(links_deleted, "links", "deleted", U64, STEP, "",                    \
	  "stored before, removed this iteration")                             \
	X(links_recreated, "links", "recreated", U64, STEP, "",                \
	  "of created, pairs deleted in an earlier iteration (study only)")    \
	X(links_gathered, "links", "gathered", U64, STEP, "",                  \
	  "exchanges carried this iteration")                                  \
	X(links_transient, "links", "transient", U64, STEP, "",                \
	  "of gathered, by links never stored")                                \
	X(links_useful, "links", "useful", U64, STEP, "",                      \
	  "of gathered, those whose increment fails the oracle one level up")  \
	X(budget_held, "links", "budget_held", U64, STEP, "",                  \
	  "pairs kept at a coarser level by the memory budget")                \
	X(budget_transient, "links", "budget_transient", U64, STEP, "",        \
	  "rmb: links not kept for want of memory, made again when needed")    \
	X(energy_hist, "", "energy_hist", HIST, STEP, "",                      \
	  "exchanges by flux fraction: bin k counts [1e-(k+1), 1e-k)")         \
	X(elements, "", "elements", U64, GAUGE, "", "surface elements")        \
	X(clusters, "", "clusters", U64, GAUGE, "", "volume clusters")         \
	X(leaves, "", "leaves", U64, GAUGE, "", "surface leaves (the mesh)")   \
	X(refinements, "", "refinements", U64, STEP, "",                       \
	  "element splits this iteration")                                     \
	X(rays, "", "rays", U64, STEP, "", "shadow rays this iteration")       \
	X(residual, "", "residual", DOUBLE, STEP, "",                          \
	  "relative change, or unshot energy")                                 \
	X(error_estimate, "", "error_estimate", DOUBLE, GAUGE, "",             \
	  "estimated remaining relative error")                                \
	X(converged, "", "converged", BOOL, GAUGE, "",                         \
	  "error_estimate is at most the tolerance")                           \
	X(budget_reached, "", "budget_reached", BOOL, GAUGE, "",               \
	  "the memory budget stopped refinement in the last iteration")        \
	X(budget_restarts, "", "budget_restarts", U32, TOTAL, "",              \
	  "hr: times the budget, reached in the first two steps, started the " \
	  "solve over at twice eps")                                           \
	X(eps, "", "eps", DOUBLE, GAUGE, "",                                   \
	  "refinement threshold in use (a budget restart doubles it)")        \
	X(mem, "", "memory", MEM, GAUGE, "B", "solver and scene memory")
/* clang-format on */

#define RAD_STAT_CTYPE_U32 uint32_t
#define RAD_STAT_CTYPE_U64 uint64_t
#define RAD_STAT_CTYPE_DOUBLE double
#define RAD_STAT_CTYPE_BOOL int
#define RAD_STAT_CTYPE_HIST uint64_t
#define RAD_STAT_CTYPE_MEM rad_mem_report
#define RAD_STAT_DIM_U32
#define RAD_STAT_DIM_U64
#define RAD_STAT_DIM_DOUBLE
#define RAD_STAT_DIM_BOOL
#define RAD_STAT_DIM_HIST [RAD_EHIST_BINS]
#define RAD_STAT_DIM_MEM

/*
 * links_useful are the report's "useful" links: their increment
 * (this iteration's transfer minus the last one's) would fail the oracle
 * one level up (4 x its oracle value > eps), so the exchange needs them at
 * their level.  energy_hist bins the oracle's BFA value (flux as a
 * fraction of the total source flux); the last bin takes everything
 * smaller, zero too.  Useful links: docs/ALGORITHM.md §9.2.
 */
typedef struct rad_stats {
#define RAD_STAT_FIELD_(field, group, key, type, ...)                          \
	RAD_STAT_CTYPE_##type field RAD_STAT_DIM_##type;
	RAD_STATS(RAD_STAT_FIELD_)
#undef RAD_STAT_FIELD_
} rad_stats;

typedef struct rad_solver rad_solver;

rad_status rad_solver_new(const rad_scene *scene, const rad_options *opt,
                          rad_solver **out, rad_error *err);

/*
 * One iteration (refine, gather, push-pull; or one sweep / batch of shots).
 * RAD_ERR_CANCELLED: the cancel flag was raised; the solution published is
 * consistent (refinement stopped at the level reached) and stepping may go
 * on once the flag is lowered.  hr comes back within a few thousand
 * form factors of the flag in its later steps: cancelled during the
 * refinement, the pairs not judged yet wait for the next step, which
 * finishes them before its gather; cancelled at the gather, the push is
 * not made.  Either way the radiosity (and the statistics) stay the last
 * iteration's.  Any other error (NOMEM, EMBREE) leaves a
 * solver that may be queried and freed, but not stepped again.
 */
rad_status rad_solver_step(rad_solver *sv, rad_error *err);

/* Step until error_estimate <= tol (0: opt.converge_tol) or max_iter
 * iterations were done (0: opt.max_iterations). */
rad_status rad_solver_converge(rad_solver *sv, double tol, uint32_t max_iter,
                               rad_error *err);

/* Change the refinement threshold between iterations. */
rad_status rad_solver_set_eps(rad_solver *sv, double eps, rad_error *err);

void rad_solver_stats(const rad_solver *sv, rad_stats *out);

/*
 * What the solver itself holds now, by kind (its scene's memory left
 * out).  Unlike rad_solver_stats this may be called from any thread while
 * another steps the solver: it reads the counters the solver's
 * allocations update, so a long iteration's growth is seen as it happens.
 */
void rad_solver_memory(const rad_solver *sv, rad_mem_report *out);

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

/*
 * Where the surface elements sit, for the reduced-memory study.  A
 * polygon's quadtree is complete to depth d when every element above
 * level d is split (d = 0: its root is a leaf, or one of its children
 * is).  A regular grid of 4^d radiosity values (a radiosity texture,
 * docs/ALGORITHM.md §10) could stand for the (4^(d+1) - 4) / 3 elements
 * of levels 1 to d; the elements below them are not counted in that.
 * Emitters: polygons that reflect nothing (rho 0) and emit, whose
 * radiosity is E all over: the elements below their roots are what
 * splitting them as sources made.  Not to be called while another thread
 * steps the solver.
 */
#define RAD_CENSUS_DEPTHS 17 /* 0 .. RAD_ELEM_MAX_LEVEL */
typedef struct rad_census {
	uint64_t elements; /* surface elements, the roots included */
	uint64_t polys_by_depth[RAD_CENSUS_DEPTHS];    /* complete to d */
	uint64_t elements_by_depth[RAD_CENSUS_DEPTHS]; /* in those trees */
	uint64_t below_emitters; /* below the roots of pure emitters */
} rad_census;
void rad_solver_census(const rad_solver *sv, rad_census *out);

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

/* ------------------------------------------------------ survey (survey.c) */
/*
 * What a lighting report reads from a committed scene.  A node's
 * polygons grouped by facing are its faces (calculation surfaces): each
 * is covered by the rectangle origin + s u + t v (s, t in [0, 1]) in its
 * plane, u to the right and v downwards seen from the front (a
 * horizontal face: u = +x, v = +z, the plan view).
 */
typedef struct rad_face {
	double normal[3];             /* unit, the side sampled */
	double origin[3], u[3], v[3]; /* rectangle over the face, metres */
	double area_m2;               /* area of its polygons */
	uint32_t polygons;
} rad_face;

/*
 * The faces of node, largest first, at most max of them (*nfaces set);
 * *skipped_m2 receives the area of polygons facing beyond the max-th
 * facing.  RAD_ERR_INVALID for a node out of range, RAD_ERR_STATE before
 * commit.  A node without polygons has no faces.
 */
rad_status rad_scene_node_faces(const rad_scene *s, uint32_t node,
                                rad_face *faces, int max, int *nfaces,
                                double *skipped_m2, rad_error *err);
/*
 * Sample face f (from rad_scene_node_faces) at the centres of nu x nv
 * cells, row-major, rows along v: where a centre falls on one of the
 * face's polygons, on[i] = 1 and pts[6 i..] is the point on the polygon
 * and its normal (as rad_solver_query takes them); elsewhere on[i] = 0
 * and the point is NaN.  *non counts the points on.  pts holds 6 nu nv
 * doubles, on nu nv bytes.
 */
rad_status rad_scene_face_sample(const rad_scene *s, uint32_t node,
                                 const rad_face *f, int nu, int nv, double *pts,
                                 unsigned char *on, size_t *non,
                                 rad_error *err);

/* inside[i] = 1 where point i (as rad_solver_query) lies within a closed
 * object (survey.c); after commit. */
rad_status rad_scene_points_inside(const rad_scene *s, const double *pts,
                                   size_t n, unsigned char *inside,
                                   rad_error *err);

/* Light i (0 <= i < counts.lights), its name borrowed from the scene. */
rad_status rad_scene_light_get(const rad_scene *s, uint32_t i,
                               rad_light_desc *out, rad_error *err);

/* Emitting surfaces of one node. */
typedef struct rad_emitter {
	uint32_t node, polygons;
	double area_m2;
	double exitance[3]; /* area-weighted mean, lux */
	double flux_lm;     /* luma of exitance x area */
} rad_emitter;
/* The nodes with emitting polygons, in order of their first polygon:
 * fills at most max and returns how many were filled; *more is set when
 * further nodes emit. */
uint32_t rad_scene_emitters(const rad_scene *s, rad_emitter *out, uint32_t max,
                            int *more);

/* Seconds on a monotonic clock (the one the statistics are timed with). */
double rad_seconds(void);

/* Photopic weights used to turn RGB into one lux value. */
#define RAD_LUMA_R 0.2126
#define RAD_LUMA_G 0.7152
#define RAD_LUMA_B 0.0722

/* The photopic value of an RGB triple (lux from RGB lux...). */
static inline double rad_luma3(const double c[3])
{
	return RAD_LUMA_R * c[0] + RAD_LUMA_G * c[1] + RAD_LUMA_B * c[2];
}

#ifdef __cplusplus
}
#endif
#endif
