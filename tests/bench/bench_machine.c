/* bench_machine — the header of every `make bench` report: what machine, and how fast memory
 * copies on it right now (the yardstick the file node and uploads are compared with). */
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
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
	return 0;
}
