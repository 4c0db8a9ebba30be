/*
 * mem.c -- counted allocation and stable pools (see mem.h).
 */
#include "mem.h"

#include <malloc.h>
#include <stdlib.h>
#include <string.h>

static const char *const kind_names[RAD_MEM_NKINDS] = {
#define RAD_MEM_NAME_(name, str) str,
        RAD_MEM_KINDS(RAD_MEM_NAME_)
#undef RAD_MEM_NAME_
};

const char *rad_mem_kind_name(rad_mem_kind kind)
{
	return (unsigned)kind < RAD_MEM_NKINDS ? kind_names[kind] : "?";
}

void rad_mem_init(rad_mem *m)
{
	for (int k = 0; k < RAD_MEM_NKINDS; k++)
		atomic_init(&m->bytes[k], 0);
	atomic_init(&m->total, 0);
	atomic_init(&m->peak, 0);
}

void rad_mem_report_clear(rad_mem_report *r)
{
	memset(r, 0, sizeof(*r));
}

void rad_mem_report_add(const rad_mem *m, rad_mem_report *r)
{
	int64_t total = 0;
	for (int k = 0; k < RAD_MEM_NKINDS; k++) {
		int64_t b = atomic_load(&m->bytes[k]);
		r->bytes[k] += b;
		total += b;
	}
	r->total += total;
	r->peak_total += atomic_load(&m->peak);
}

void rad_mem_count(rad_mem *m, rad_mem_kind kind, int64_t delta)
{
	atomic_fetch_add(&m->bytes[kind], delta);
	int64_t t = atomic_fetch_add(&m->total, delta) + delta;
	int64_t p = atomic_load(&m->peak);
	while (t > p && !atomic_compare_exchange_weak(&m->peak, &p, t))
		;
}

static _Atomic int64_t fail_countdown = -1; /* < 0: injection off */

void rad_mem_inject_failure(int64_t n)
{
	atomic_store(&fail_countdown, n);
}

/* 1 if this allocation must fail (see rad_mem_inject_failure). */
static int inject_failure(rad_mem *m)
{
	(void)m;
	int64_t n = atomic_load(&fail_countdown);
	while (n > 0 &&
	       !atomic_compare_exchange_weak(&fail_countdown, &n, n - 1))
		;
	return n == 0;
}

void *rad_mem_alloc(rad_mem *m, rad_mem_kind kind, size_t size)
{
	if (inject_failure(m))
		return NULL;
	void *p = malloc(size ? size : 1);
	if (p)
		rad_mem_count(m, kind, (int64_t)malloc_usable_size(p));
	return p;
}

void *rad_mem_calloc(rad_mem *m, rad_mem_kind kind, size_t n, size_t size)
{
	if (size && n > SIZE_MAX / size)
		return NULL;
	if (inject_failure(m))
		return NULL;
	void *p = calloc(n ? n : 1, size ? size : 1);
	if (p)
		rad_mem_count(m, kind, (int64_t)malloc_usable_size(p));
	return p;
}

void *rad_mem_realloc(rad_mem *m, rad_mem_kind kind, void *p, size_t size)
{
	if (!p)
		return rad_mem_alloc(m, kind, size);
	if (inject_failure(m))
		return NULL;
	int64_t before = (int64_t)malloc_usable_size(p);
	void *q = realloc(p, size ? size : 1);
	if (!q)
		return NULL;
	rad_mem_count(m, kind, (int64_t)malloc_usable_size(q) - before);
	return q;
}

void rad_mem_free(rad_mem *m, rad_mem_kind kind, void *p)
{
	if (!p)
		return;
	rad_mem_count(m, kind, -(int64_t)malloc_usable_size(p));
	free(p);
}

char *rad_mem_strdup(rad_mem *m, rad_mem_kind kind, const char *s)
{
	size_t n = strlen(s) + 1;
	char *d = rad_mem_alloc(m, kind, n);
	if (d)
		memcpy(d, s, n);
	return d;
}

/* ------------------------------------------------------------ stable pool */

void rad_pool_init(rad_pool *p, rad_mem *mem, rad_mem_kind kind,
                   uint32_t rec_size, uint32_t base_shift)
{
	memset(p, 0, sizeof(*p));
	p->mem = mem;
	p->kind = kind;
	/* The free list threads a uint32_t through released records. */
	p->rec_size = rec_size < sizeof(uint32_t) ? sizeof(uint32_t) : rec_size;
	p->base_shift = base_shift;
	p->free_head = RAD_NONE;
}

void rad_pool_destroy(rad_pool *p)
{
	for (uint32_t k = 0; k < p->nblocks; k++)
		rad_mem_free(p->mem, p->kind, p->block[k]);
	rad_pool_init(p, p->mem, p->kind, p->rec_size, p->base_shift);
}

uint32_t rad_pool_capacity(const rad_pool *p)
{
	if (p->nblocks == 0)
		return 0;
	return ((1u << p->nblocks) - 1u) << p->base_shift;
}

uint32_t rad_pool_add(rad_pool *p, uint32_t n)
{
	if (n == 1 && p->free_head != RAD_NONE) {
		uint32_t id = p->free_head;
		void *rec = rad_pool_at(p, id);
		memcpy(&p->free_head, rec, sizeof(uint32_t));
		memset(rec, 0, p->rec_size);
		p->nfree--;
		return id;
	}
	if (n == 0)
		return RAD_NONE;
	/* A run must not straddle two blocks: skip to the next block if
	 * needed (the skipped records go to the free list). */
	uint32_t id = p->count;
	for (;;) {
		if ((uint64_t)id + n > RAD_NONE - 1u)
			return RAD_NONE;
		uint32_t q = (id >> p->base_shift) + 1;
		uint32_t k = 31u - (uint32_t)__builtin_clz(q);
		uint32_t first = ((1u << k) - 1u) << p->base_shift;
		uint32_t size = 1u << (p->base_shift + k);
		if (n > size && k + 1 < RAD_POOL_MAXBLOCKS) {
			id = first + size; /* too small: try the next block */
			continue;
		}
		if (id + n > first + size) {
			id = first + size;
			continue;
		}
		while (p->nblocks <= k) {
			size_t bytes = (size_t)p->rec_size
			               << (p->base_shift + p->nblocks);
			unsigned char *b =
			        rad_mem_alloc(p->mem, p->kind, bytes);
			if (!b)
				return RAD_NONE;
			p->block[p->nblocks++] = b;
		}
		break;
	}
	/* Records skipped to keep the run in one block become free. */
	for (uint32_t s = p->count; s < id; s++) {
		void *rec = rad_pool_at(p, s);
		memcpy(rec, &p->free_head, sizeof(uint32_t));
		p->free_head = s;
		p->nfree++;
	}
	memset(rad_pool_at(p, id), 0, (size_t)n * p->rec_size);
	p->count = id + n;
	return id;
}

void rad_pool_release(rad_pool *p, uint32_t id)
{
	void *rec = rad_pool_at(p, id);
	memcpy(rec, &p->free_head, sizeof(uint32_t));
	p->free_head = id;
	p->nfree++;
}
