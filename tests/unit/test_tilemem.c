/* Tile memory pool tests (engine/tilemem.h): a freed buffer is reused for the next tile of its
 * size, sizes do not mix, the keep bound gives pages back and a released buffer comes back
 * writable, small sizes bypass the pool, threads never get one buffer twice, and slabs sit on
 * huge pages where the kernel has them. Under
 * AddressSanitizer the pool is bypassed: the checks of reuse and of the counters are skipped
 * there, the rest runs. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <pthread.h>
#include <sched.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/xthread.h"
#include "engine/tilemem.h"
#include "support/proc_rss.h"

#define TILE ((size_t)256 * 256 * 4)

/* Whether this build pools (not under ASan): a pooled allocation maps a slab. */
static bool pooled(void)
{
	struct tilemem_stats a, b;
	tilemem_stats(&a);
	void *p = tilemem_alloc(TILE);
	tilemem_stats(&b);
	tilemem_free(p, TILE);
	return b.in_use == a.in_use + TILE;
}

static void reuse_by_size(void **state)
{
	(void)state;
	void *a = tilemem_alloc(TILE);
	memset(a, 0x5a, TILE);
	assert_int_equal((uintptr_t)a % 64, 0);
	tilemem_free(a, TILE);
	void *other = tilemem_alloc(TILE / 4); /* another class: not a's buffer */
	memset(other, 1, TILE / 4);
	void *b = tilemem_alloc(TILE);
	memset(b, 0x33, TILE);
	if (pooled()) {
		assert_ptr_not_equal(other, a);
		assert_ptr_equal(b, a); /* the freed buffer, warm, is the next one handed out */
	}
	tilemem_free(other, TILE / 4);
	tilemem_free(b, TILE);
	/* A size that is not a page multiple is rounded up, and is writable to its end. */
	void *odd = tilemem_alloc(TILE + 100);
	memset(odd, 7, TILE + 100);
	tilemem_free(odd, TILE + 100);
	/* Small sizes are plain allocations. */
	void *small = tilemem_alloc(1000);
	memset(small, 9, 1000);
	tilemem_free(small, 1000);
	tilemem_free(NULL, TILE);
}

static void keep_bound_releases(void **state)
{
	(void)state;
	if (!pooled()) {
		skip();
		return;
	}
	enum { N = 64 };
	void *p[N];
	for (int i = 0; i < N; i++) {
		p[i] = tilemem_alloc(TILE);
		memset(p[i], i, TILE);
	}
	tilemem_keep(4 * TILE);
	struct tilemem_stats st;
	tilemem_stats(&st);
	assert_true(st.free_warm <= 4 * TILE);
	for (int i = 0; i < N; i++)
		tilemem_free(p[i], TILE);
	tilemem_stats(&st);
	assert_true(st.free_warm <= 4 * TILE);
	assert_true(st.released >= (N - 4) * TILE);
	/* Released buffers come back, populated again, and hold what is written. */
	for (int i = 0; i < N; i++) {
		p[i] = tilemem_alloc(TILE);
		unsigned char *b = p[i];
		memset(b, 0xc3, TILE);
		assert_int_equal(b[0], 0xc3);
		assert_int_equal(b[TILE - 1], 0xc3);
	}
	for (int i = 0; i < N; i++)
		tilemem_free(p[i], TILE);
	tilemem_keep(SIZE_MAX);
	tilemem_stats(&st);
	assert_int_equal(st.in_use, 0); /* every buffer of these tests was given back */
}

/* Threads allocating, filling with their own mark, checking and freeing: a buffer handed to
 * two at once shows as a foreign mark. */
struct worker {
	unsigned char mark;
	int bad;
};

static void *churn(void *arg)
{
	struct worker *w = arg;
	static const size_t sizes[3] = { TILE, TILE / 4, TILE * 2 };
	for (int i = 0; i < 400; i++) {
		size_t n = sizes[i % 3];
		unsigned char *p = tilemem_alloc(n);
		memset(p, w->mark, n);
		sched_yield();
		for (size_t k = 0; k < n; k += 4093)
			w->bad += p[k] != w->mark;
		w->bad += p[n - 1] != w->mark;
		tilemem_free(p, n);
	}
	return NULL;
}

static void threads_never_share(void **state)
{
	(void)state;
	enum { NT = 4 };
	pthread_t th[NT];
	struct worker w[NT];
	for (int i = 0; i < NT; i++) {
		w[i] = (struct worker){ (unsigned char)(0x10 + i), 0 };
		assert_int_equal(xthread_create(&th[i], churn, &w[i]), 0);
	}
	for (int i = 0; i < NT; i++) {
		xthread_join(th[i]);
		assert_int_equal(w[i].bad, 0);
	}
}

/* The AnonHugePages of the mapping holding p, kB (/proc/self/smaps); -1 when not found. */
static long huge_kb(const void *p)
{
	FILE *f = fopen("/proc/self/smaps", "r");
	if (!f)
		return -1;
	char line[512];
	bool in = false;
	long kb = -1;
	while (fgets(line, sizeof line, f)) {
		unsigned long lo, hi;
		if (sscanf(line, "%lx-%lx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' ')) {
			in = (uintptr_t)p >= lo && (uintptr_t)p < hi;
			continue;
		}
		if (in && sscanf(line, "AnonHugePages: %ld kB", &kb) == 1)
			break;
	}
	fclose(f);
	return kb;
}

/* The pool's slabs are on transparent huge pages where the kernel offers them (first writes to
 * fresh memory: 12 GB/s on them against 0.3-0.9 on 4 KiB pages on this project's VMs), faulted
 * in by the tiles' own writes. */
static void slabs_on_huge_pages(void **state)
{
	(void)state;
	char mode[128] = "";
	FILE *f = fopen("/sys/kernel/mm/transparent_hugepage/enabled", "r");
	if (f) {
		if (!fgets(mode, sizeof mode, f))
			mode[0] = '\0';
		fclose(f);
	}
	if (!pooled() || (!strstr(mode, "[madvise]") && !strstr(mode, "[always]")))
		skip(); /* sanitized build, or no transparent huge pages here */
	const size_t sz = (size_t)384 << 10; /* a class no other test uses: a fresh slab */
	enum { N = 16 };			/* 6 MiB: at least two whole huge pages */
	void *b[N];
	for (int i = 0; i < N; i++) {
		b[i] = tilemem_alloc(sz);
		memset(b[i], i + 1, sz);
	}
	long kb = huge_kb(b[0]);
	print_message("the slab holds %ld kB on huge pages\n", kb);
	assert_true(kb >= 2048);
	for (int i = 0; i < N; i++) {
		assert_int_equal(((unsigned char *)b[i])[sz - 1], i + 1);
		tilemem_free(b[i], sz);
	}
}

/* tilemem_prefault (last: it sets the pool's resident floor for the process): a stop already
 * asked maps nothing; then the pool maps its bytes, resident (RSS grows by them before any
 * tile is made), as free buffers the next allocations take without mapping more; freed again
 * under a keep bound of 0 they stay resident (within the prefaulted bytes), and one beyond them
 * goes back. */
static void prefault_resident(void **state)
{
	(void)state;
	if (!pooled()) {
		assert_int_equal(tilemem_prefault(TILE, 64u << 20, NULL), 0); /* bypassed */
		skip();
		return;
	}
	struct tilemem_stats st0, st;
	tilemem_stats(&st0);
	_Atomic bool stop = true;
	assert_int_equal(tilemem_prefault(TILE, st0.mapped + (64u << 20), &stop), 0);
	tilemem_stats(&st);
	assert_int_equal(st.mapped, st0.mapped);
	long r0 = (long)proc_rss_kb(0);
	size_t want = st0.mapped + (64u << 20);
	size_t done = tilemem_prefault(TILE, want, NULL);
	tilemem_stats(&st);
	long r1 = (long)proc_rss_kb(0);
	print_message("prefault: %zu MiB faulted in, RSS %ld -> %ld MiB\n", done >> 20, r0 >> 10,
		      r1 >> 10);
	assert_true(done >= (64u << 20));
	assert_true(st.mapped >= want);
	assert_true(st.free_warm >= (64u << 20));
	assert_true(r1 - r0 >= (60 << 10)); /* faulted in, not only mapped */
	enum { N = 64 << 20 >> 18 }; /* 256 buffers of 256 KiB */
	void **p = calloc(N + 1, sizeof *p);
	for (int i = 0; i < N; i++)
		p[i] = tilemem_alloc(TILE);
	struct tilemem_stats st2;
	tilemem_stats(&st2);
	assert_int_equal(st2.mapped, st.mapped); /* taken from the faulted-in buffers */
	tilemem_keep(0);
	for (int i = 0; i < N; i++)
		tilemem_free(p[i], TILE);
	tilemem_stats(&st2);
	assert_int_equal(st2.released, st.released); /* within the floor: all stay resident */
	/* beyond the prefaulted bytes a freed buffer goes back under keep 0 */
	size_t m = want / TILE + 2;
	void **q = calloc(m, sizeof *q);
	for (size_t i = 0; i < m; i++)
		q[i] = tilemem_alloc(TILE);
	for (size_t i = 0; i < m; i++)
		tilemem_free(q[i], TILE);
	tilemem_stats(&st2);
	assert_true(st2.released > st.released);
	tilemem_keep(SIZE_MAX);
	free(p);
	free(q);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(reuse_by_size),
		cmocka_unit_test(keep_bound_releases),
		cmocka_unit_test(threads_never_share),
		cmocka_unit_test(slabs_on_huge_pages),
		cmocka_unit_test(prefault_resident),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
