/* tilemem — see tilemem.h. A class per buffer size (at most MAX_CLASSES; tiles come in a few
 * sizes: T² × 1, 2, 4 or 8 bytes for the planets' T), each with a stack of warm free buffers
 * (resident) and one of released ones (pages given back). Sizes under POOL_MIN, or beyond the
 * classes, are plain aligned allocations. */
#include "tilemem.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/mman.h>

#include "common/xalloc.h"

/* POOLED 0 under AddressSanitizer: plain allocations, so it sees every tile's lifetime. */
#if defined(__SANITIZE_ADDRESS__)
#define POOLED 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define POOLED 0
#endif
#endif
#ifndef POOLED
#define POOLED 1
#endif

#define PAGE 4096u
#define POOL_MIN (16u << 10)
#define SLAB_BYTES ((size_t)32 << 20)
#define MAX_CLASSES 16

struct stack {
	void **p;
	size_t n, cap;
};

struct cls {
	size_t size; /* 0: unused */
	struct stack warm, cold;
};

/* The slabs mapped, for the release path: once a slab gives pages back it is marked
 * MADV_NOHUGEPAGE (the whole slab, once: one VMA, not one per buffer). A huge page released in
 * part is split; without the mark, the next fault in an emptied 2 MiB range would populate all
 * of it again for one buffer, up to 8x the buffer (test_serve_load's slow readers: peak RSS 742
 * MiB against a bound of 347). */
struct slab {
	char *base;
	size_t bytes;
	bool small; /* marked MADV_NOHUGEPAGE */
};

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct cls classes[MAX_CLASSES];
static struct slab *slabs;
static size_t nslabs, capslabs;
static size_t keep_bytes = SIZE_MAX, warm_bytes, cold_bytes, mapped_bytes, used_bytes;
/* tilemem_prefault's budget: free buffers stay resident while in use + free is within it */
static size_t floor_bytes;
static bool prefaulting; /* a tilemem_prefault runs */

/* Whether a free buffer of sz more bytes stays resident. Needs mu. */
static bool keeps(size_t sz)
{
	return warm_bytes + sz <= keep_bytes || used_bytes + warm_bytes + sz <= floor_bytes;
}

static size_t round_page(size_t n) { return (n + PAGE - 1) & ~(size_t)(PAGE - 1); }

static void push(struct stack *s, void *p)
{
	if (s->n == s->cap) {
		s->cap = s->cap ? 2 * s->cap : 64;
		s->p = xrealloc(s->p, s->cap * sizeof *s->p);
	}
	s->p[s->n++] = p;
}

/* The class of rounded size sz, created if there is room; NULL: none. Needs mu. */
static struct cls *class_of(size_t sz, bool create)
{
	for (int i = 0; i < MAX_CLASSES; i++) {
		if (classes[i].size == sz)
			return &classes[i];
		if (classes[i].size == 0) {
			if (!create)
				return NULL;
			classes[i].size = sz;
			return &classes[i];
		}
	}
	return NULL;
}

#define HUGE ((size_t)2 << 20)

/* A slab for buffers of sz bytes, mapped with no lock held. Returns the base, NULL on ENOMEM;
 * *bytes its size.
 * The slab is aligned to 2 MiB and asks for transparent huge pages. Under a hypervisor that
 * shadows the guest's page tables (this project's VMs), the first write from user space to a
 * fresh 4 KiB page exits to the hypervisor, even after MAP_POPULATE: 0.3-0.9 GB/s for a first
 * write against ~20 GB/s for the next; on huge pages faulted in by the write itself the first
 * write runs at 12 GB/s (bench_machine's last line, the 2-core VM). A growing cache writes
 * every tile into fresh memory: serving stored tiles (bench_keepup "restarted"), the workers'
 * tilecodec_unfilter and the loop's socket copies stalled on first touches.
 * Not populated here: MADV_POPULATE_WRITE holds the process's mmap lock while it works (20-50
 * ms a slab the first time the VM uses the memory), and every other thread's mprotect waited
 * behind it (malloc growing a thread's arena: the scheduler's manager took 0.3-0.5 s to create
 * a want-set's jobs while workers kept making tiles, test_serve_load's slow readers went to
 * 700 MiB). A first touch faults in a whole huge page under the VMA's own lock. */
static char *map_slab(size_t sz, size_t *bytes)
{
	size_t per = SLAB_BYTES / sz;
	if (per < 1)
		per = 1;
	*bytes = per * sz;
	size_t span = *bytes + HUGE;
	char *m = mmap(NULL, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
	if (m == MAP_FAILED)
		return NULL;
	char *a = (char *)(((uintptr_t)m + HUGE - 1) & ~(uintptr_t)(HUGE - 1));
	if (a > m)
		(void)munmap(m, (size_t)(a - m));
	if (a + *bytes < m + span)
		(void)munmap(a + *bytes, (size_t)(m + span - (a + *bytes)));
#ifdef MADV_HUGEPAGE
	(void)madvise(a, *bytes, MADV_HUGEPAGE);
#endif
	return a;
}

/* Adds the slab at a (bytes long) to class c's warm buffers. Needs mu. */
static void add_slab(struct cls *c, char *a, size_t bytes)
{
	if (nslabs == capslabs) {
		capslabs = capslabs ? 2 * capslabs : 16;
		slabs = xrealloc(slabs, capslabs * sizeof *slabs);
	}
	slabs[nslabs++] = (struct slab){ .base = a, .bytes = bytes };
	mapped_bytes += bytes;
	for (size_t i = bytes / c->size; i-- > 0;)
		push(&c->warm, a + i * c->size);
	warm_bytes += bytes;
}

/* Marks the slab holding p as about to give pages back. Needs mu. Returns the slab's range
 * when it must leave huge pages first (the first release in it), else NULL. */
static char *mark_small(void *p, size_t *bytes)
{
	for (size_t i = 0; i < nslabs; i++) {
		struct slab *b = &slabs[i];
		if ((char *)p >= b->base && (char *)p < b->base + b->bytes) {
			if (b->small)
				return NULL;
			b->small = true;
			*bytes = b->bytes;
			return b->base;
		}
	}
	return NULL;
}

/* Gives buffer p's sz bytes back to the system, its slab off huge pages first (slab NULL when
 * it is already). No lock held. */
static void release(void *p, size_t sz, char *slab, size_t slab_bytes)
{
#ifdef MADV_NOHUGEPAGE
	if (slab)
		(void)madvise(slab, slab_bytes, MADV_NOHUGEPAGE);
#else
	(void)slab;
	(void)slab_bytes;
#endif
	(void)madvise(p, sz, MADV_DONTNEED);
}

void *tilemem_alloc(size_t n)
{
	size_t sz = round_page(n);
	if (POOLED && n >= POOL_MIN) {
		void *p = NULL;
		bool populate = false;
		pthread_mutex_lock(&mu);
		struct cls *c = class_of(sz, true);
		if (c && !c->warm.n && !c->cold.n) {
			pthread_mutex_unlock(&mu);
			size_t bytes;
			char *a = map_slab(sz, &bytes);
			pthread_mutex_lock(&mu);
			if (a) /* another thread may have added one meanwhile: both stay */
				add_slab(c, a, bytes);
		}
		if (c) {
			if (c->warm.n) {
				p = c->warm.p[--c->warm.n];
				warm_bytes -= sz;
			} else if (c->cold.n) {
				p = c->cold.p[--c->cold.n];
				cold_bytes -= sz;
				populate = true;
			}
			if (p)
				used_bytes += sz;
		}
		pthread_mutex_unlock(&mu);
		if (p) {
#ifdef MADV_POPULATE_WRITE
			if (populate)
				(void)madvise(p, sz, MADV_POPULATE_WRITE); /* else faults as touched */
#else
			(void)populate;
#endif
			return p;
		}
		if (c)
			xalloc_fail(n); /* the class exists but no slab could be mapped */
	}
	return xaligned_alloc(64, n);
}

void tilemem_free(void *p, size_t n)
{
	if (!p)
		return;
	size_t sz = round_page(n);
	if (POOLED && n >= POOL_MIN) {
		pthread_mutex_lock(&mu);
		struct cls *c = class_of(sz, false);
		if (c) {
			used_bytes -= sz;
			if (keeps(sz)) {
				push(&c->warm, p);
				warm_bytes += sz;
				pthread_mutex_unlock(&mu);
				return;
			}
			size_t sb = 0;
			char *slab = mark_small(p, &sb);
			pthread_mutex_unlock(&mu);
			release(p, sz, slab, sb);
			pthread_mutex_lock(&mu);
			push(&c->cold, p);
			cold_bytes += sz;
			pthread_mutex_unlock(&mu);
			return;
		}
		pthread_mutex_unlock(&mu);
	}
	free(p);
}

void tilemem_keep(size_t bytes)
{
	pthread_mutex_lock(&mu);
	keep_bytes = bytes;
	/* Release warm buffers beyond the new bound now (a cache shrunk by a reload). */
	for (int i = 0; i < MAX_CLASSES && !keeps(0); i++) {
		struct cls *c = &classes[i];
		while (c->warm.n && !keeps(0)) {
			void *p = c->warm.p[--c->warm.n];
			size_t sb = 0;
			char *slab = mark_small(p, &sb);
			release(p, c->size, slab, sb); /* under mu: a reload's rare shrink */
			push(&c->cold, p);
			warm_bytes -= c->size;
			cold_bytes += c->size;
		}
	}
	pthread_mutex_unlock(&mu);
}

size_t tilemem_prefault(size_t n, size_t bytes, const _Atomic bool *stop)
{
	size_t sz = round_page(n), done = 0;
	if (!POOLED || n < POOL_MIN)
		return 0;
	tilemem_prefault_expect(bytes);
	for (;;) {
		pthread_mutex_lock(&mu);
		struct cls *c = class_of(sz, true);
		bool more = c && mapped_bytes < bytes && !(stop && atomic_load(stop));
		pthread_mutex_unlock(&mu);
		size_t sb = 0;
		char *a = more ? map_slab(sz, &sb) : NULL;
		if (!a)
			break;
		/* one write per 4 KiB page (a whole huge page faults in on its first); a stop asked
		 * is seen within 2 MiB (the slab joins the pool untouched beyond) */
		for (size_t o = 0; o < sb; o += PAGE) {
			if (o % HUGE == 0 && stop && atomic_load(stop))
				break;
			((volatile char *)a)[o] = 0;
		}
		pthread_mutex_lock(&mu);
		add_slab(c, a, sb);
		pthread_mutex_unlock(&mu);
		done += sb;
	}
	pthread_mutex_lock(&mu);
	prefaulting = false;
	pthread_mutex_unlock(&mu);
	return done;
}

void tilemem_prefault_expect(size_t bytes)
{
	if (!POOLED)
		return;
	pthread_mutex_lock(&mu);
	floor_bytes = bytes;
	prefaulting = bytes > 0;
	pthread_mutex_unlock(&mu);
}

void tilemem_stats(struct tilemem_stats *out)
{
	pthread_mutex_lock(&mu);
	*out = (struct tilemem_stats){ .mapped = mapped_bytes, .in_use = used_bytes,
				       .free_warm = warm_bytes, .released = cold_bytes,
				       .prefault_left = prefaulting && floor_bytes > mapped_bytes
							       ? floor_bytes - mapped_bytes
							       : 0 };
	pthread_mutex_unlock(&mu);
}
