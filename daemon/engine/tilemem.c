/* tilemem — see tilemem.h. A class per buffer size (at most MAX_CLASSES; tiles come in a few
 * sizes: T² × 1, 2, 4 or 8 bytes for the planets' T), each with a stack of warm free buffers
 * (resident) and one of released ones (pages given back). Sizes under POOL_MIN, or beyond the
 * classes, are plain aligned allocations. */
#include "tilemem.h"

#include <errno.h>
#include <pthread.h>
#include <stdbool.h>
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

static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct cls classes[MAX_CLASSES];
static size_t keep_bytes = SIZE_MAX, warm_bytes, cold_bytes, mapped_bytes, used_bytes;

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

/* Maps a slab for class c and pushes its buffers onto the warm stack. Needs mu. Returns 0 or
 * -ENOMEM. */
static int grow(struct cls *c)
{
	size_t per = SLAB_BYTES / c->size;
	if (per < 1)
		per = 1;
	size_t bytes = per * c->size;
	void *m = mmap(NULL, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS | MAP_POPULATE,
		       -1, 0);
	if (m == MAP_FAILED)
		return -ENOMEM;
	mapped_bytes += bytes;
	for (size_t i = per; i-- > 0;)
		push(&c->warm, (char *)m + i * c->size);
	warm_bytes += bytes;
	return 0;
}

void *tilemem_alloc(size_t n)
{
	size_t sz = round_page(n);
	if (POOLED && n >= POOL_MIN) {
		void *p = NULL;
		bool populate = false;
		pthread_mutex_lock(&mu);
		struct cls *c = class_of(sz, true);
		if (c) {
			if (!c->warm.n && !c->cold.n)
				(void)grow(c);
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
			bool release = warm_bytes + sz > keep_bytes;
			if (release) {
				(void)madvise(p, sz, MADV_DONTNEED);
				push(&c->cold, p);
				cold_bytes += sz;
			} else {
				push(&c->warm, p);
				warm_bytes += sz;
			}
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
	for (int i = 0; i < MAX_CLASSES && warm_bytes > keep_bytes; i++) {
		struct cls *c = &classes[i];
		while (c->warm.n && warm_bytes > keep_bytes) {
			void *p = c->warm.p[--c->warm.n];
			(void)madvise(p, c->size, MADV_DONTNEED);
			push(&c->cold, p);
			warm_bytes -= c->size;
			cold_bytes += c->size;
		}
	}
	pthread_mutex_unlock(&mu);
}

void tilemem_stats(struct tilemem_stats *out)
{
	pthread_mutex_lock(&mu);
	*out = (struct tilemem_stats){ .mapped = mapped_bytes, .in_use = used_bytes,
				       .free_warm = warm_bytes, .released = cold_bytes };
	pthread_mutex_unlock(&mu);
}
