/* bench_redis — the fleet's Redis tier (daemon/store_redis.c) beside the disk tier (LMDB), on
 * the same real tiles in the same run: the procedural planet's height (f32), colour (rgba8)
 * and normal (rg8) layers, 256², made in-process. Figures:
 *   - write-behind to Redis: puts until every tile is written (one writer thread, pipelined);
 *   - hit latency per 256² tile, p50/p99, Redis (a private redis-server on a Unix socket: one
 *     round trip, the value over the socket, checksum, zstd decode) against the disk tier (page
 *     cache), interleaved tile by tile so that both see the same machine load; and the ratio.
 * Skipped (exit 0, a line saying so) when redis-server is not installed.
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/remote.h"
#include "engine/sched.h"
#include "engine/store.h"
#include "store_redis.h"
#include "support/daemon_env.h"
#include "support/redis_env.h"

#define SIDE 4 /* SIDE × SIDE tiles per layer */
#define LEVEL 9
#define READS 8 /* gets per tile and tier */

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

int main(void)
{
	if (!redis_env_installed()) {
		printf("bench_redis: redis-server is not installed: skipped\n");
		return 0;
	}
	char bindir[512], path[700], err[256];
	if (daemon_env_bindir(bindir, sizeof bindir)) {
		fprintf(stderr, "bench_redis: cannot find the build directory\n");
		return 1;
	}
	snprintf(path, sizeof path, "%s/../conf/planets/procedural.ini", bindir);
	struct planet *p;
	if (planet_load(path, &p, err)) {
		fprintf(stderr, "bench_redis: %s\n", err);
		return 1;
	}
	size_t nl = p->nlayers < 3 ? p->nlayers : 3;
	size_t n = nl * SIDE * SIDE;
	struct want *w = xcalloc(n, sizeof *w);
	for (size_t l = 0, i = 0; l < nl; l++)
		for (uint32_t y = 0; y < SIDE; y++)
			for (uint32_t x = 0; x < SIDE; x++, i++)
				w[i] = (struct want){
					.node = p->layers[l].node, .cls = SCHED_VISIBLE,
					.key = { .node = p->layers[l].node->hash, .lx = LEVEL + 1,
						 .ly = LEVEL, .x = 560 + x, .y = 150 + y } };
	struct cache *cache = cache_create(0);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = cache, .workers = 2 });
	struct tile **t = xcalloc(n, sizeof *t);
	if (sched_fetch(s, w, n, t)) {
		fprintf(stderr, "bench_redis: generation failed\n");
		return 1;
	}

	char dir[] = "/tmp/bench_redis_XXXXXX";
	if (!mkdtemp(dir)) {
		perror("bench_redis: mkdtemp");
		return 1;
	}
	struct redis_env re = { 0 };
	if (redis_env_start(&re, dir)) {
		fprintf(stderr, "bench_redis: redis-server did not start\n");
		return 1;
	}
	char file[64], addr[200];
	snprintf(file, sizeof file, "%s/tiles.lmdb", dir);
	snprintf(addr, sizeof addr, "unix:%s", re.sock);
	struct store *st;
	struct remote *rt;
	if (store_lmdb_open(&(struct store_lmdb_desc){ .path = file }, &st, err) ||
	    store_redis_open(&(struct store_redis_desc){ .addr = addr }, &rt, err)) {
		fprintf(stderr, "bench_redis: %s\n", err);
		redis_env_stop(&re);
		return 1;
	}
	for (size_t i = 0; i < n; i++)
		store_put(st, t[i], STORE_KEEP_INCIDENTAL);
	int rc = store_flush(st);
	uint64_t t0 = clock_now_ns();
	for (size_t i = 0; i < n; i++)
		rt->ops->put(rt, t[i], false);
	struct remote_stats rs;
	uint64_t end = t0 + 30000000000ull;
	do {
		usleep(1000);
		rt->ops->stat(rt, &rs);
	} while (rs.writes + rs.drops < n && clock_now_ns() < end);
	double put_s = (double)(clock_now_ns() - t0) * 1e-9;
	printf("redis/write-behind: %zu tiles written in %.3f s: %.0f tiles/s (%llu dropped)\n", n,
	       put_s, (double)n / put_s, (unsigned long long)rs.drops);

	struct tilecodec *tc = tilecodec_create();
	uint64_t *ld = xcalloc(n * READS, sizeof *ld), *lr = xcalloc(n * READS, sizeof *lr);
	size_t k = 0, bad = 0;
	for (int pass = 0; pass < READS + 1; pass++)
		for (size_t i = 0; i < n; i++) {
			size_t j = (i * 7 + (size_t)pass * 13) % n;
			struct tile *g = NULL, *h = NULL;
			uint64_t a = clock_now_ns();
			int e1 = store_get(st, &w[j].key, t[j]->type, t[j]->size, tc, &g);
			uint64_t b = clock_now_ns();
			int e2 = rt->ops->get(rt, &w[j].key, t[j]->type, t[j]->size, tc, false, &h);
			uint64_t c = clock_now_ns();
			bad += e1 != 0 || memcmp(g->data, t[j]->data, g->nbytes) != 0;
			bad += e2 != 0 || memcmp(h->data, t[j]->data, h->nbytes) != 0;
			tile_unref(g);
			tile_unref(h);
			if (pass > 0) { /* the first pass warms both */
				ld[k] = b - a;
				lr[k++] = c - b;
			}
		}
	qsort(ld, k, sizeof *ld, cmp_u64);
	qsort(lr, k, sizeof *lr, cmp_u64);
	double d50 = (double)ld[k / 2] * 1e-6, d99 = (double)ld[k * 99 / 100] * 1e-6;
	double r50 = (double)lr[k / 2] * 1e-6, r99 = (double)lr[k * 99 / 100] * 1e-6;
	printf("redis/hit per 256² tile (Unix socket, all layers): p50 %.3f ms, p99 %.3f ms; "
	       "disk hit, same run: p50 %.3f ms, p99 %.3f ms; Redis/disk p50 %.2fx, p99 %.2fx "
	       "(%zu gets each, %zu wrong%s)\n",
	       r50, r99, d50, d99, r50 / d50, r99 / d99, k, bad, rc ? ", disk write error" : "");

	tilecodec_destroy(tc);
	store_redis_destroy(rt);
	store_destroy(st);
	redis_env_stop(&re);
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	if (system(cmd) != 0)
		fprintf(stderr, "bench_redis: could not remove %s\n", dir);
	for (size_t i = 0; i < n; i++)
		tile_unref(t[i]);
	free(t);
	free(w);
	free(ld);
	free(lr);
	sched_destroy(s);
	cache_destroy(cache);
	planet_unref(p);
	return bad ? 1 : 0;
}
