/*
 * mem.h -- counted allocation and stable pools.
 *
 * Every allocation of the engine goes through rad_mem_alloc() and friends
 * with a kind from RAD_MEM_KINDS (rad.h) and a rad_mem counter set owned by
 * the object the memory belongs to (a scene or a solver).  What is counted
 * is what the C library really holds for the block (malloc_usable_size), so
 * the report adds up to the allocator's own figures, and reads zero once
 * the owner has freed everything.
 *
 * Every block starts with RAD_MEM_PREFIX bytes that keep the size asked
 * for (as Redis's zmalloc does where the allocator cannot say): a budget
 * must judge a count that does not depend on where in the heap a block
 * lands.  glibc hands out 16 bytes more than a request when the chunk it
 * splits would leave too little to keep, so what it holds for the same
 * requests varies by a few bytes from run to run, and a solver's choice
 * at a budget's edge (where to stop refining, when to restart) with it.
 * So beside what is held, each set counts what is charged: for each block
 * the most glibc can hold for its request (usable_bound), which the prefix
 * gives back at free.  Budgets judge the charge (rad_mem_room), reports
 * show what is held, and the charge is never below it.
 *
 * Counters are atomic: Embree's memory monitor reports from its own
 * threads.  rad_mem_alloc() may be called from several threads on the same
 * counter set.
 *
 * rad_pool is an array of fixed-size records addressed by 32-bit ids whose
 * records never move: storage is a table of fixed-size blocks, so a pointer
 * or id taken once stays valid while the pool grows.  Only the block table
 * is reallocated, and only while the pool grows.
 * Growing (rad_pool_add) is not thread-safe; the engine grows pools from
 * one thread only (see wave.c).
 */
#ifndef LUXRAD_MEM_H
#define LUXRAD_MEM_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "rad.h"

typedef struct rad_mem {
	_Atomic int64_t bytes[RAD_MEM_NKINDS]; /* current bytes held by kind */
	_Atomic int64_t total;                 /* sum of bytes[] */
	_Atomic int64_t peak;                  /* high-water mark of total */
	_Atomic int64_t work;                  /* total minus RAD_MEM_STUDY */
	_Atomic int64_t charged;   /* work as its requests bound it (above) */
	_Atomic int64_t peak_work; /* its high-water mark */
	/* What this set is used with (a solver's scene), or NULL: the
	 * high-water marks of total and work plus the base's at the time. */
	const struct rad_mem *base;
	_Atomic int64_t peak_joint, peak_work_joint;
	/* A budget over work (rad_mem_set_budget), 0 = none, and the
	 * allocations it refused. */
	int64_t budget;
	_Atomic uint64_t budget_refusals;
} rad_mem;

/*
 * Fault injection for tests: the nth counted allocation from now (0 = the
 * next one) and every later one fail, process-wide, until called again
 * with n < 0.  Production code never calls it.
 */
void rad_mem_inject_failure(int64_t n);

void rad_mem_init(rad_mem *m);
/* Add what m holds now into r (r is not cleared first). */
void rad_mem_report_add(const rad_mem *m, rad_mem_report *r);
/*
 * r = what m and its base hold now, with their joint peaks: the larger of
 * the base's own peak and m's joint one.  A sum of the two peaks would
 * count the scene's build (Embree's temporary memory) as if it were held
 * during the solve, which it never is.
 */
void rad_mem_report_joint(const rad_mem *m, rad_mem_report *r);
void rad_mem_report_clear(rad_mem_report *r);

/*
 * A hard budget for what m holds outside RAD_MEM_STUDY (its work): an
 * allocation that would take work past it fails like any other, and is
 * counted in m->budget_refusals.  0 removes it.  Solvers keep below it
 * by asking rad_mem_room before they grow (hr.c, rmb.c: Budget).
 */
void rad_mem_set_budget(rad_mem *m, int64_t bytes);
/* 1 if blocks of `bytes` in all (their allocator overhead included) fit
 * in m's budget now, judged on what m is charged; always 1 without a
 * budget. */
int rad_mem_room(const rad_mem *m, size_t bytes);

/* Bytes before each block's start (its request size). */
#define RAD_MEM_PREFIX 16
/* What the C library holds for block p of rad_mem_alloc and friends (the
 * figure every count uses; the prefix included). */
size_t rad_mem_usable(const void *p);

/* 1 if allocating size more bytes would pass the process-wide limit
 * (rad_mem_set_limit); counts the refusal. */
int rad_mem_over_limit(size_t size);

/* Count bytes allocated outside malloc (Embree's monitor); may be < 0. */
void rad_mem_count(rad_mem *m, rad_mem_kind kind, int64_t delta);

/* NULL on failure (nothing counted).  Size 0 returns a valid block. */
void *rad_mem_alloc(rad_mem *m, rad_mem_kind kind, size_t size);
void *rad_mem_calloc(rad_mem *m, rad_mem_kind kind, size_t n, size_t size);
/* On failure returns NULL and leaves p allocated and counted. */
void *rad_mem_realloc(rad_mem *m, rad_mem_kind kind, void *p, size_t size);
void rad_mem_free(rad_mem *m, rad_mem_kind kind, void *p);
/*
 * Grow array p of elements of `size` bytes so that it holds at least need:
 * capacity doubles (from `first` when empty).  Returns the array, p itself
 * when it is large enough, or NULL on failure (p still valid, *cap kept).
 */
void *rad_mem_grow(rad_mem *m, rad_mem_kind kind, void *p, size_t *cap,
                   size_t need, size_t size, size_t first);
char *rad_mem_strdup(rad_mem *m, rad_mem_kind kind, const char *s);

/* ------------------------------------------------------------ stable pool */

#define RAD_NONE UINT32_MAX /* the null id */
/* Ids a pool hands out are below this: the top bit stays free for tags
 * (hier.h, Leaves and lists), and a tagged id is never RAD_NONE. */
#define RAD_POOL_MAX_ID 0x7fffffffu
#define RAD_POOL_RUNMAX 16 /* longest run with a free list of its own */

typedef struct rad_pool {
	rad_mem *mem;
	rad_mem_kind kind;
	uint32_t rec_size; /* bytes per record */
	uint32_t shift;    /* blocks after the first hold 1 << shift records */
	uint32_t first;    /* records in block 0 (>= 1 << shift) */
	uint32_t count;    /* records handed out: ids 0 .. count-1 */
	uint32_t nblocks;  /* blocks allocated */
	uint32_t cap_blocks;
	unsigned char **block; /* the block table, counted under kind */
	/* Released runs, one list per length (index 1 = single records). */
	uint32_t free_head[RAD_POOL_RUNMAX + 1];
	uint32_t nfree; /* records on the free lists */
} rad_pool;

/*
 * Block 0 holds `first` records (rounded up to a whole block), so that a
 * long initial run -- the polygon roots -- fits in it; every later block
 * holds 1 << shift.  Capacity therefore exceeds use by less than one block
 * plus the released records.
 */
void rad_pool_init(rad_pool *p, rad_mem *mem, rad_mem_kind kind,
                   uint32_t rec_size, uint32_t shift, uint32_t first);
void rad_pool_destroy(rad_pool *p);

/*
 * Hand out n consecutive records, zero-filled; returns the first id or
 * RAD_NONE when out of memory (or when n exceeds a block).  A run of
 * n <= RAD_POOL_RUNMAX reuses a released run of the same length first, so
 * a solver that frees and remakes sibling runs does not grow the pool.
 */
uint32_t rad_pool_add(rad_pool *p, uint32_t n);
/* Release a run of n records made by rad_pool_add(p, n) (or n singles). */
void rad_pool_release_run(rad_pool *p, uint32_t id, uint32_t n);
static inline void rad_pool_release(rad_pool *p, uint32_t id)
{
	rad_pool_release_run(p, id, 1);
}

/* Records handed out and still live. */
static inline uint32_t rad_pool_live(const rad_pool *p)
{
	return p->count - p->nfree;
}

static inline void *rad_pool_at(const rad_pool *p, uint32_t id)
{
	if (id < p->first)
		return p->block[0] + (size_t)id * p->rec_size;
	id -= p->first;
	return p->block[1 + (id >> p->shift)] +
	       (size_t)(id & ((1u << p->shift) - 1u)) * p->rec_size;
}

/* Capacity in records of the blocks allocated so far. */
uint32_t rad_pool_capacity(const rad_pool *p);

#endif
