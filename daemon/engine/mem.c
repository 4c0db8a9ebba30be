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
	atomic_init(&m->work, 0);
	atomic_init(&m->peak_work, 0);
	atomic_init(&m->charged, 0);
	m->base = NULL;
	atomic_init(&m->peak_joint, 0);
	atomic_init(&m->peak_work_joint, 0);
	m->budget = 0;
	atomic_init(&m->budget_refusals, 0);
}

void rad_mem_set_budget(rad_mem *m, int64_t bytes)
{
	m->budget = bytes > 0 ? bytes : 0;
}

/*
 * The most malloc_usable_size can give for a request of size, prefix
 * included (glibc, 64-bit).  In the heap a chunk is the request plus 8
 * rounded up to 16 (at least 32), of which 8 are the allocator's, and
 * the chunk taken may be 16 bytes longer when the rest would be too
 * small to keep.  From 128 KiB (the least mmap threshold; it rises by
 * itself up to 32 MiB) a block may be mapped instead: whole pages, less
 * 16 bytes.
 */
static size_t usable_bound(size_t size)
{
	size_t chunk = (size + 8 + 15) & ~(size_t)15;
	size_t heap = (chunk < 32 ? 32 : chunk) + 8;
	if (size < 128 * 1024)
		return heap;
	size_t mapped = (size + 32 + 4095) & ~(size_t)4095;
	return mapped > heap ? mapped : heap;
}

int rad_mem_room(const rad_mem *m, size_t bytes)
{
	return m->budget <= 0 ||
	       atomic_load(&m->charged) + (int64_t)bytes <= m->budget;
}

/* The malloc block of p, a pointer rad_mem_alloc and friends handed
 * out: where its prefix starts. */
static void *block_of(const void *p)
{
	return (unsigned char *)(uintptr_t)p - RAD_MEM_PREFIX;
}

/* The size asked for block b, prefix included (its prefix). */
static size_t *asked(void *b)
{
	return (size_t *)b;
}

size_t rad_mem_usable(const void *p)
{
	return malloc_usable_size(block_of(p));
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
	r->peak_work += atomic_load(&m->peak_work);
	r->peak_own += atomic_load(&m->peak_work);
}

void rad_mem_report_joint(const rad_mem *m, rad_mem_report *r)
{
	rad_mem_report_clear(r);
	rad_mem_report_add(m, r);
	if (!m->base)
		return;
	rad_mem_report_add(m->base, r);
	r->peak_own = atomic_load(&m->peak_work);
	int64_t p = atomic_load(&m->peak_joint);
	int64_t w = atomic_load(&m->peak_work_joint);
	int64_t bp = atomic_load(&m->base->peak);
	int64_t bw = atomic_load(&m->base->peak_work);
	r->peak_total = p > bp ? p : bp;
	r->peak_work = w > bw ? w : bw;
}

/* The process-wide limit (rad.h): every count adds to process_bytes. */
static _Atomic int64_t limit_bytes = 0;
static _Atomic int64_t process_bytes = 0;
static _Atomic uint64_t limit_refusals = 0;

void rad_mem_set_limit(int64_t bytes)
{
	atomic_store(&limit_bytes, bytes > 0 ? bytes : 0);
}

int64_t rad_mem_limit(void)
{
	return atomic_load(&limit_bytes);
}

int64_t rad_mem_process_bytes(void)
{
	return atomic_load(&process_bytes);
}

uint64_t rad_mem_limit_refusals(void)
{
	return atomic_load(&limit_refusals);
}

/* Shared with other processes (rad_mem_share): set while no other
 * thread allocates, read by every count. */
static rad_mem_shared *shared_g;
static int64_t *shared_own;

void rad_mem_share(rad_mem_shared *g, int64_t *own)
{
	int64_t now = atomic_load(&process_bytes);
	if (shared_g) {
		__atomic_fetch_sub(&shared_g->bytes, now, __ATOMIC_RELAXED);
		__atomic_fetch_sub(shared_own, now, __ATOMIC_RELAXED);
	}
	shared_g = g && own ? g : NULL;
	shared_own = g && own ? own : NULL;
	if (shared_g) {
		__atomic_fetch_add(&shared_g->bytes, now, __ATOMIC_RELAXED);
		__atomic_fetch_add(shared_own, now, __ATOMIC_RELAXED);
	}
}

int64_t rad_mem_limit_held(void)
{
	if (shared_g)
		return __atomic_load_n(&shared_g->bytes, __ATOMIC_RELAXED);
	return atomic_load_explicit(&process_bytes, memory_order_relaxed);
}

int rad_mem_over_limit(size_t size)
{
	int64_t lim = atomic_load_explicit(&limit_bytes, memory_order_relaxed);
	if (lim <= 0 || rad_mem_limit_held() + (int64_t)size <= lim)
		return 0;
	atomic_fetch_add(&limit_refusals, 1);
	if (shared_g)
		__atomic_fetch_add(&shared_g->refusals, 1, __ATOMIC_RELAXED);
	return 1;
}

static void raise_to(_Atomic int64_t *peak, int64_t t)
{
	int64_t p = atomic_load(peak);
	while (t > p && !atomic_compare_exchange_weak(peak, &p, t))
		;
}

/* Count delta bytes held, of which charge is charged (delta's bound). */
static void count(rad_mem *m, rad_mem_kind kind, int64_t delta, int64_t charge)
{
	atomic_fetch_add_explicit(&process_bytes, delta, memory_order_relaxed);
	if (shared_g) {
		__atomic_fetch_add(&shared_g->bytes, delta, __ATOMIC_RELAXED);
		__atomic_fetch_add(shared_own, delta, __ATOMIC_RELAXED);
	}
	atomic_fetch_add(&m->bytes[kind], delta);
	int64_t t = atomic_fetch_add(&m->total, delta) + delta;
	raise_to(&m->peak, t);
	if (m->base)
		raise_to(&m->peak_joint, t + atomic_load(&m->base->total));
	if (kind == RAD_MEM_STUDY)
		return;
	atomic_fetch_add(&m->charged, charge);
	t = atomic_fetch_add(&m->work, delta) + delta;
	raise_to(&m->peak_work, t);
	if (m->base)
		raise_to(&m->peak_work_joint, t + atomic_load(&m->base->work));
}

void rad_mem_count(rad_mem *m, rad_mem_kind kind, int64_t delta)
{
	count(m, kind, delta, delta);
}

static _Atomic int64_t fail_countdown = -1; /* < 0: injection off */

void rad_mem_inject_failure(int64_t n)
{
	atomic_store(&fail_countdown, n);
}

/* 1 if an allocation of size bytes (at most grow bytes more held once
 * made) must fail: injected (rad_mem_inject_failure), refused by the
 * process-wide limit or by m's budget. */
static int must_fail(rad_mem *m, rad_mem_kind kind, size_t size, size_t grow)
{
	int64_t n = atomic_load(&fail_countdown);
	while (n > 0 &&
	       !atomic_compare_exchange_weak(&fail_countdown, &n, n - 1))
		;
	if (n == 0 || rad_mem_over_limit(size))
		return 1;
	if (kind != RAD_MEM_STUDY && grow > 0 && !rad_mem_room(m, grow)) {
		atomic_fetch_add(&m->budget_refusals, 1);
		return 1;
	}
	return 0;
}

/* Block b of malloc's for a request of size (prefix included): its
 * prefix written and counted; what the caller gets. */
static void *take(rad_mem *m, rad_mem_kind kind, void *b, size_t size)
{
	*asked(b) = size;
	count(m, kind, (int64_t)malloc_usable_size(b),
	      (int64_t)usable_bound(size));
	return (unsigned char *)b + RAD_MEM_PREFIX;
}

void *rad_mem_alloc(rad_mem *m, rad_mem_kind kind, size_t size)
{
	if (size > SIZE_MAX - RAD_MEM_PREFIX)
		return NULL;
	size += RAD_MEM_PREFIX;
	if (must_fail(m, kind, size, usable_bound(size)))
		return NULL;
	void *b = malloc(size);
	return b ? take(m, kind, b, size) : NULL;
}

void *rad_mem_calloc(rad_mem *m, rad_mem_kind kind, size_t n, size_t size)
{
	if (size && n > (SIZE_MAX - RAD_MEM_PREFIX) / size)
		return NULL;
	size_t all = n * size + RAD_MEM_PREFIX;
	if (must_fail(m, kind, all, usable_bound(all)))
		return NULL;
	void *b = calloc(1, all);
	return b ? take(m, kind, b, all) : NULL;
}

void *rad_mem_realloc(rad_mem *m, rad_mem_kind kind, void *p, size_t size)
{
	if (!p)
		return rad_mem_alloc(m, kind, size);
	if (size > SIZE_MAX - RAD_MEM_PREFIX)
		return NULL;
	size += RAD_MEM_PREFIX;
	void *b = block_of(p);
	int64_t before = (int64_t)malloc_usable_size(b);
	int64_t charged = (int64_t)usable_bound(*asked(b));
	int64_t most = (int64_t)usable_bound(size);
	if (must_fail(m, kind,
	              size > (size_t)before ? size - (size_t)before : 0,
	              most > charged ? (size_t)(most - charged) : 0))
		return NULL;
	void *q = realloc(b, size);
	if (!q)
		return NULL;
	*asked(q) = size;
	count(m, kind, (int64_t)malloc_usable_size(q) - before, most - charged);
	return (unsigned char *)q + RAD_MEM_PREFIX;
}

void rad_mem_free(rad_mem *m, rad_mem_kind kind, void *p)
{
	if (!p)
		return;
	void *b = block_of(p);
	count(m, kind, -(int64_t)malloc_usable_size(b),
	      -(int64_t)usable_bound(*asked(b)));
	free(b);
}

void *rad_mem_grow(rad_mem *m, rad_mem_kind kind, void *p, size_t *cap,
                   size_t need, size_t size, size_t first)
{
	if (need <= *cap)
		return p;
	size_t c = *cap ? *cap : first;
	while (c < need)
		c *= 2;
	void *q = rad_mem_realloc(m, kind, p, c * size);
	if (q)
		*cap = c;
	return q;
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
                   uint32_t rec_size, uint32_t shift, uint32_t first)
{
	memset(p, 0, sizeof(*p));
	p->mem = mem;
	p->kind = kind;
	/* The free lists thread a uint32_t through released records. */
	p->rec_size = rec_size < sizeof(uint32_t) ? sizeof(uint32_t) : rec_size;
	p->shift = shift;
	uint32_t bs = 1u << shift;
	p->first = first <= bs ? bs : (first + bs - 1) / bs * bs;
	for (int n = 0; n <= RAD_POOL_RUNMAX; n++)
		p->free_head[n] = RAD_NONE;
}

void rad_pool_destroy(rad_pool *p)
{
	for (uint32_t k = 0; k < p->nblocks; k++)
		rad_mem_free(p->mem, p->kind, p->block[k]);
	rad_mem_free(p->mem, p->kind, p->block);
	rad_pool_init(p, p->mem, p->kind, p->rec_size, p->shift, p->first);
}

uint32_t rad_pool_capacity(const rad_pool *p)
{
	if (p->nblocks == 0)
		return 0;
	return p->first + ((p->nblocks - 1) << p->shift);
}

/* Make sure the block holding record id exists. */
static int pool_reserve(rad_pool *p, uint32_t id)
{
	while (rad_pool_capacity(p) <= id) {
		if (p->nblocks == p->cap_blocks) {
			uint32_t cap = p->cap_blocks ? 2 * p->cap_blocks : 8;
			unsigned char **t = rad_mem_realloc(
			        p->mem, p->kind, p->block, cap * sizeof(*t));
			if (!t)
				return 0;
			p->block = t;
			p->cap_blocks = cap;
		}
		size_t recs = p->nblocks ? 1u << p->shift : p->first;
		unsigned char *b =
		        rad_mem_alloc(p->mem, p->kind, recs * p->rec_size);
		if (!b)
			return 0;
		p->block[p->nblocks++] = b;
	}
	return 1;
}

uint32_t rad_pool_add(rad_pool *p, uint32_t n)
{
	if (n == 0)
		return RAD_NONE;
	if (n <= RAD_POOL_RUNMAX && p->free_head[n] != RAD_NONE) {
		uint32_t id = p->free_head[n];
		void *rec = rad_pool_at(p, id);
		memcpy(&p->free_head[n], rec, sizeof(uint32_t));
		memset(rec, 0, (size_t)n * p->rec_size);
		p->nfree -= n;
		return id;
	}
	/* A run must not straddle two blocks: skip to the next block if
	 * needed (the skipped records become free singles). */
	uint32_t id = p->count;
	uint32_t end =
	        id < p->first ? p->first
	                      : p->first + (((id - p->first) >> p->shift) + 1) *
	                                           (1u << p->shift);
	if (id + n > end) {
		if (n > (1u << p->shift))
			return RAD_NONE;
		id = end;
	}
	if ((uint64_t)id + n > RAD_POOL_MAX_ID || !pool_reserve(p, id + n - 1))
		return RAD_NONE;
	for (uint32_t s = p->count; s < id; s++)
		rad_pool_release_run(p, s, 1);
	memset(rad_pool_at(p, id), 0, (size_t)n * p->rec_size);
	p->count = id + n;
	return id;
}

void rad_pool_release_run(rad_pool *p, uint32_t id, uint32_t n)
{
	if (n > RAD_POOL_RUNMAX) {
		for (uint32_t k = 0; k < n; k++)
			rad_pool_release_run(p, id + k, 1);
		return;
	}
	void *rec = rad_pool_at(p, id);
	memcpy(rec, &p->free_head[n], sizeof(uint32_t));
	p->free_head[n] = id;
	p->nfree += n;
}
