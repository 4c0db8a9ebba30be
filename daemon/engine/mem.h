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
 * Counters are atomic: Embree's memory monitor reports from its own
 * threads.  rad_mem_alloc() may be called from several threads on the same
 * counter set.
 *
 * rad_pool is an array of fixed-size records addressed by 32-bit ids whose
 * records never move: storage is a list of blocks, block k holding
 * base << k records, so a pointer or id taken once stays valid while the
 * pool grows, and a reader on another thread never sees a reallocation.
 * Growing (rad_pool_add) is not thread-safe; the engine grows pools from
 * one thread only (see the DESIGN note in hr.c).
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
void rad_mem_report_clear(rad_mem_report *r);

/* Count bytes allocated outside malloc (Embree's monitor); may be < 0. */
void rad_mem_count(rad_mem *m, rad_mem_kind kind, int64_t delta);

/* NULL on failure (nothing counted).  Size 0 returns a valid block. */
void *rad_mem_alloc(rad_mem *m, rad_mem_kind kind, size_t size);
void *rad_mem_calloc(rad_mem *m, rad_mem_kind kind, size_t n, size_t size);
/* On failure returns NULL and leaves p allocated and counted. */
void *rad_mem_realloc(rad_mem *m, rad_mem_kind kind, void *p, size_t size);
void rad_mem_free(rad_mem *m, rad_mem_kind kind, void *p);
char *rad_mem_strdup(rad_mem *m, rad_mem_kind kind, const char *s);

/* ------------------------------------------------------------ stable pool */

#define RAD_POOL_MAXBLOCKS 32
#define RAD_NONE UINT32_MAX /* the null id */

typedef struct rad_pool {
	rad_mem *mem;
	rad_mem_kind kind;
	uint32_t rec_size;   /* bytes per record */
	uint32_t base_shift; /* block k holds 1 << (base_shift + k) records */
	uint32_t count;      /* records handed out: ids 0 .. count-1 */
	uint32_t nblocks;    /* blocks allocated */
	uint32_t free_head;  /* head of the free list of released records */
	uint32_t nfree;      /* records on the free list */
	unsigned char *block[RAD_POOL_MAXBLOCKS];
} rad_pool;

void rad_pool_init(rad_pool *p, rad_mem *mem, rad_mem_kind kind,
                   uint32_t rec_size, uint32_t base_shift);
void rad_pool_destroy(rad_pool *p);

/*
 * Hand out n consecutive records, zero-filled; returns the first id or
 * RAD_NONE when out of memory.  n > 1 never reuses freed records, so runs
 * (siblings stored together) stay consecutive.
 */
uint32_t rad_pool_add(rad_pool *p, uint32_t n);
/* Release one record to the free list (reused by later rad_pool_add(1)). */
void rad_pool_release(rad_pool *p, uint32_t id);

/* Records handed out and still live. */
static inline uint32_t rad_pool_live(const rad_pool *p)
{
	return p->count - p->nfree;
}

static inline void *rad_pool_at(const rad_pool *p, uint32_t id)
{
	/* Block k starts at id (2^k - 1) << base_shift. */
	uint32_t q = (id >> p->base_shift) + 1;
	uint32_t k = 31u - (uint32_t)__builtin_clz(q);
	uint32_t first = ((1u << k) - 1u) << p->base_shift;
	return p->block[k] + (size_t)(id - first) * p->rec_size;
}

/* Capacity in records of the blocks allocated so far. */
uint32_t rad_pool_capacity(const rad_pool *p);

#endif
