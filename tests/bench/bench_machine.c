/* bench_machine — the header of every `make bench` report: what machine, and how fast memory
 * copies on it right now (the yardstick the file node and uploads are compared with), and how
 * fast a first write to fresh memory is (a tile cache that grows writes into fresh memory). */
#include <pthread.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/xthread.h"

struct job {
	size_t n;
	int reps;
	double gbps;
};

static void *copy_run(void *arg)
{
	struct job *j = arg;
	char *a = malloc(j->n), *b = malloc(j->n);
	if (!a || !b) {
		fprintf(stderr, "bench_machine: out of memory\n");
		exit(1);
	}
	memset(a, 1, j->n);
	memset(b, 2, j->n);
	double best = 1e9;
	for (int r = 0; r < j->reps; r++) {
		double t0 = clock_now_s();
		memcpy(b, a, j->n);
		__asm__ volatile("" : : "r"(b) : "memory");
		double t = clock_now_s() - t0;
		if (t < best)
			best = t;
		char *t2 = a;
		a = b;
		b = t2;
	}
	j->gbps = j->n / best / 1e9;
	free(a);
	free(b);
	return NULL;
}

static double copy_threads(size_t n, int reps, int threads)
{
	pthread_t th[8];
	struct job jobs[8];
	for (int i = 0; i < threads; i++) {
		jobs[i] = (struct job){ .n = n, .reps = reps };
		int rc = xthread_create(&th[i], copy_run, &jobs[i]);
		if (rc) {
			fprintf(stderr, "bench_machine: pthread_create: %s\n", strerror(-rc));
			exit(1);
		}
	}
	double sum = 0;
	for (int i = 0; i < threads; i++) {
		xthread_join(th[i]);
		sum += jobs[i].gbps;
	}
	return sum;
}

/* How a fresh mapping is given its pages before the first write (fresh_write). */
enum fresh_mode {
	FRESH_SMALL,	/* default pages, MAP_POPULATE */
	FRESH_HUGE,	/* aligned to 2 MiB, MADV_HUGEPAGE, faulted in by the write itself: as
			 * engine/tilemem.c maps its slabs */
	FRESH_HUGE_POP, /* the same, populated first with MADV_POPULATE_WRITE (counted) */
};

/* The first write to n bytes of fresh anonymous memory, GB/s (mapping and populating counted,
 * except MAP_POPULATE's own time). Under a hypervisor that shadows page tables the first write
 * to a default page is 20-50x slower than writing warm memory; on huge pages it is close to it
 * once the host has backed the memory (the first time the guest ever uses it, populating is
 * slow too: 1.6 s for a GiB, then 0.05 s, measured one after the other); on bare metal they are
 * close. Returns 0 when the mapping failed. */
static double fresh_write(size_t n, enum fresh_mode mode)
{
	const size_t H = (size_t)2 << 20;
	bool huge = mode != FRESH_SMALL;
	char *buf = malloc(256u << 10);
	if (!buf)
		return 0;
	memset(buf, 3, 256u << 10);
	double t0 = clock_now_s();
	char *m = mmap(NULL, n + H, PROT_READ | PROT_WRITE,
		       MAP_PRIVATE | MAP_ANONYMOUS | (huge ? 0 : MAP_POPULATE), -1, 0);
	if (m == MAP_FAILED) {
		free(buf);
		return 0;
	}
	char *a = huge ? (char *)(((uintptr_t)m + H - 1) & ~(uintptr_t)(H - 1)) : m;
#ifdef MADV_HUGEPAGE
	if (huge)
		(void)madvise(a, n, MADV_HUGEPAGE);
#endif
#ifdef MADV_POPULATE_WRITE
	if (mode == FRESH_HUGE_POP)
		(void)madvise(a, n, MADV_POPULATE_WRITE);
#endif
	if (!huge)
		t0 = clock_now_s(); /* MAP_POPULATE's own time is not the first write's */
	for (size_t o = 0; o + (256u << 10) <= n; o += 256u << 10)
		memcpy(a + o, buf, 256u << 10);
	__asm__ volatile("" : : "r"(a) : "memory");
	double t = clock_now_s() - t0;
	munmap(m, n + H);
	free(buf);
	return (double)n / t / 1e9;
}

int main(void)
{
	char model[256] = "unknown";
	FILE *f = fopen("/proc/cpuinfo", "r");
	if (f) {
		char line[512];
		while (fgets(line, sizeof line, f)) {
			if (strncmp(line, "model name", 10) == 0) {
				char *c = strchr(line, ':');
				if (c) {
					snprintf(model, sizeof model, "%s", c + 2);
					model[strcspn(model, "\n")] = '\0';
				}
				break;
			}
		}
		fclose(f);
	}
	printf("machine: %ld cores, %s, AVX2 %s, AVX-512 %s\n", sysconf(_SC_NPROCESSORS_ONLN), model,
	       __builtin_cpu_supports("avx2") ? "yes" : "no",
	       __builtin_cpu_supports("avx512f") ? "yes" : "no");
	printf("memcpy 64 MiB, 1 thread: %.1f GB/s\n", copy_threads(64u << 20, 8, 1));
	printf("memcpy 64 MiB, 2 threads: %.1f GB/s (sum)\n", copy_threads(64u << 20, 8, 2));
	printf("memcpy 1 MiB (cache-resident), 1 thread: %.1f GB/s\n", copy_threads(1u << 20, 200, 1));
	printf("memcpy 256 KiB (one 256x256 RGBA8 tile), 1 thread: %.1f GB/s\n",
	       copy_threads(256u << 10, 500, 1));
	printf("first write to fresh memory (256 MiB in 256 KiB tiles), 1 thread: %.2f GB/s on 4 KiB "
	       "pages (MAP_POPULATE), %.2f GB/s on 2 MiB pages faulted in by the write (as the "
	       "tile pool), %.2f GB/s on 2 MiB pages populated first (MADV_POPULATE_WRITE, "
	       "counted)\n",
	       fresh_write(256u << 20, FRESH_SMALL), fresh_write(256u << 20, FRESH_HUGE),
	       fresh_write(256u << 20, FRESH_HUGE_POP));
	return 0;
}
