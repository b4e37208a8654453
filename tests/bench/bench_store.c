/* bench_store — the disk tier (engine/store.h, LMDB) beside the memory cache, on real tiles:
 * the procedural planet's height (f32), colour (rgba8) and normal (rg8) layers, 256², made
 * in-process. Figures:
 *   - generation rate of those tiles (2 workers), the rate the writer must keep up with;
 *   - write-behind throughput: puts of every tile until flush says they are durable (one
 *     writer thread, zstd-3, batched transactions with fsync);
 *   - bytes per tile at rest per layer type (the value, and what the accounting charges);
 *   - hit latency per 256² tile, p50/p99, with the file in the page cache (read txn, checksum,
 *     zstd decode, unfilter), and the memory cache's lookup for comparison;
 *   - hits with the file out of the page cache (as after a reboot; on this machine kind also a
 *     minute after the file was last touched): a get alone (its value faulted in a page at a
 *     time), contains then get (the scheduler's order: contains asks for the value's pages),
 *     and 16 contains then their 16 gets (jobs queued together), as tiles per second.
 * One run, one line per figure. The store file lives in a temporary directory under /tmp.
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
#include "engine/sched.h"
#include "engine/store.h"
#include "support/daemon_env.h"
#include "support/pagecache.h"

#define SIDE 6 /* SIDE × SIDE tiles per layer */
#define LEVEL 9
#define READS 8 /* gets per tile */

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

enum cold_way { COLD_GET, COLD_CONTAINS_GET, COLD_QUEUED };

/* Closes the store, drops its file from the page cache (clean pages no process maps), opens
 * it again and reads every tile the way asked, in a scattered order; per-tile latencies in
 * lat (n of them), the whole in *secs. Returns the tiles that came back wrong or not at all,
 * or -1 when the file's pages cannot be dropped (a file system that keeps them: tmpfs). */
static long cold_reads(struct store **st, const char *file, struct tilecodec *tc,
		       struct tile *const *t, size_t n, enum cold_way way, uint64_t *lat,
		       double *secs)
{
	char err[256];
	store_destroy(*st);
	if (pagecache_drop(file) != 0)
		return -1;
	if (store_lmdb_open(&(struct store_lmdb_desc){ .path = file }, st, err)) {
		fprintf(stderr, "bench_store: %s\n", err);
		exit(1);
	}
	long bad = 0;
	size_t batch = way == COLD_QUEUED ? 16 : 1;
	uint64_t t0 = clock_now_ns();
	for (size_t i = 0; i < n; i += batch) {
		uint64_t a = clock_now_ns();
		size_t m = i + batch <= n ? batch : n - i;
		for (size_t q = 0; q < m && way != COLD_GET; q++)
			bad += !store_contains(*st, &t[(i + q) * 37 % n]->key);
		for (size_t q = 0; q < m; q++) {
			const struct tile *x = t[(i + q) * 37 % n];
			struct tile *g = NULL;
			int e = store_get(*st, &x->key, x->type, x->size, tc, &g);
			bad += e != 0 || memcmp(g->data, x->data, g->nbytes) != 0;
			tile_unref(g);
			lat[i + q] = (clock_now_ns() - a) / m;
		}
	}
	*secs = (double)(clock_now_ns() - t0) * 1e-9;
	return bad;
}

struct at_rest {
	const struct planet *p;
	uint64_t bytes[8], n[8];
};

static int rest_fn(void *ud, const struct store_entry *e)
{
	struct at_rest *r = ud;
	for (size_t l = 0; l < r->p->nlayers && l < 8; l++)
		if (r->p->layers[l].node->hash == e->key.node) {
			r->bytes[l] += e->bytes;
			r->n[l]++;
		}
	return 0;
}

/* Bytes at rest per layer, as "store/at rest[ TAG] LAYER ...". */
static void print_at_rest(struct store *st, const struct planet *p, size_t nl, const char *tag)
{
	struct at_rest r = { .p = p };
	store_iterate(st, rest_fn, &r);
	for (size_t l = 0; l < nl; l++)
		printf("store/at rest%s %-6s (%s, %u²): %.0f bytes per tile, %.1f %% of raw\n", tag,
		       p->layers[l].name, pix_format_name(p->layers[l].type), p->tile_size,
		       r.n[l] ? (double)r.bytes[l] / (double)r.n[l] : 0.0,
		       r.n[l] ? 100.0 * (double)r.bytes[l] / (double)r.n[l] /
					(double)((size_t)p->tile_size * p->tile_size *
						 pix_bytes(p->layers[l].type))
			      : 0.0);
}

/* Disk hits per layer (the file in the page cache), READS passes over each layer's tiles;
 * per: scratch for READS · SIDE² latencies. Returns the tiles read back wrong. */
static size_t print_layer_hits(struct store *st, const struct planet *p, size_t nl,
			       const struct want *w, struct tile *const *t, struct tilecodec *tc,
			       uint64_t *per, const char *tag)
{
	size_t bad = 0;
	for (size_t l = 0; l < nl; l++) {
		size_t m = 0;
		for (int pass = 0; pass < READS; pass++)
			for (size_t i = 0; i < SIDE * SIDE; i++) {
				size_t j = l * SIDE * SIDE + i;
				struct tile *g = NULL;
				uint64_t a = clock_now_ns();
				int e = store_get(st, &w[j].key, t[j]->type, t[j]->size, tc, &g);
				per[m++] = clock_now_ns() - a;
				bad += e != 0 || memcmp(g->data, t[j]->data, g->nbytes) != 0;
				tile_unref(g);
			}
		qsort(per, m, sizeof *per, cmp_u64);
		printf("store/disk hit%s %-6s: p50 %.3f ms, p99 %.3f ms\n", tag, p->layers[l].name,
		       (double)per[m / 2] * 1e-6, (double)per[m * 99 / 100] * 1e-6);
	}
	return bad;
}

int main(void)
{
	char bindir[512], path[700], err[256];
	if (daemon_env_bindir(bindir, sizeof bindir)) {
		fprintf(stderr, "bench_store: cannot find the build directory\n");
		return 1;
	}
	snprintf(path, sizeof path, "%s/../conf/planets/procedural.ini", bindir);
	struct planet *p;
	if (planet_load(path, &p, err)) {
		fprintf(stderr, "bench_store: %s\n", err);
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
	uint64_t t0 = clock_now_ns();
	if (sched_fetch(s, w, n, t)) {
		fprintf(stderr, "bench_store: generation failed\n");
		return 1;
	}
	double gen_s = (double)(clock_now_ns() - t0) * 1e-9;
	struct sched_stats ss;
	sched_get_stats(s, &ss);
	printf("store/generate: %zu layer tiles (%llu with their inputs) in %.2f s, 2 workers: "
	       "%.0f layer tiles/s (what the writer must keep up with)\n",
	       n, (unsigned long long)ss.generated, gen_s, (double)n / gen_s);

	char dir[] = "/tmp/bench_store_XXXXXX";
	if (!mkdtemp(dir)) {
		perror("bench_store: mkdtemp");
		return 1;
	}
	char file[64];
	snprintf(file, sizeof file, "%s/tiles.lmdb", dir);
	struct store *st;
	if (store_lmdb_open(&(struct store_lmdb_desc){ .path = file }, &st, err)) {
		fprintf(stderr, "bench_store: %s\n", err);
		return 1;
	}
	uint64_t raw = 0;
	t0 = clock_now_ns();
	for (size_t i = 0; i < n; i++) {
		store_put(st, t[i], STORE_KEEP_INCIDENTAL);
		raw += t[i]->nbytes;
	}
	uint64_t t_queued = clock_now_ns() - t0;
	int rc = store_flush(st);
	double put_s = (double)(clock_now_ns() - t0) * 1e-9;
	struct store_stats sst;
	store_stat(st, &sst);
	printf("store/write-behind: %zu puts queued in %.3f ms (callers never wait); durable after "
	       "%.3f s: %.0f tiles/s, %.0f MB/s raw (%s, %llu dropped)\n",
	       n, (double)t_queued * 1e-6, put_s, (double)n / put_s, (double)raw / put_s * 1e-6,
	       rc ? "write error" : "ok", (unsigned long long)sst.write_drops);

	print_at_rest(st, p, nl, "");
	printf("store/at rest: %llu tiles charged %llu bytes (values in whole pages + index); file "
	       "%llu bytes\n",
	       (unsigned long long)sst.tiles, (unsigned long long)sst.bytes,
	       (unsigned long long)sst.file_bytes);

	/* Hits, the file in the page cache (just written and read once). */
	struct tilecodec *tc = tilecodec_create();
	uint64_t *lat = xcalloc(n * READS, sizeof *lat);
	uint64_t *per = xcalloc(n * READS, sizeof *per);
	size_t k = 0, bad = 0;
	for (int pass = 0; pass < READS + 1; pass++)
		for (size_t i = 0; i < n; i++) {
			size_t j = (i * 7 + (size_t)pass * 13) % n;
			struct tile *g = NULL;
			uint64_t a = clock_now_ns();
			int e = store_get(st, &w[j].key, t[j]->type, t[j]->size, tc, &g);
			uint64_t b = clock_now_ns();
			bad += e != 0 || memcmp(g->data, t[j]->data, g->nbytes) != 0;
			tile_unref(g);
			if (pass > 0)
				lat[k++] = b - a;
		}
	qsort(lat, k, sizeof *lat, cmp_u64);
	printf("store/disk hit per 256² tile (page cache, all layers): p50 %.3f ms, p99 %.3f ms, "
	       "%zu gets, %zu wrong\n",
	       (double)lat[k / 2] * 1e-6, (double)lat[k * 99 / 100] * 1e-6, k, bad);
	bad += print_layer_hits(st, p, nl, w, t, tc, per, "");
	/* The same tiles in a store that writes lz4 ([store] disk_codec = lz4): what serving a
	 * disk hit costs against what the file takes. */
	char file4[80];
	snprintf(file4, sizeof file4, "%s/tiles-lz4.lmdb", dir);
	struct store *st4;
	if (store_lmdb_open(&(struct store_lmdb_desc){ .path = file4, .codec = TCODEC_LZ4 }, &st4,
			    err)) {
		fprintf(stderr, "bench_store: %s\n", err);
		return 1;
	}
	for (size_t i = 0; i < n; i++)
		store_put(st4, t[i], STORE_KEEP_INCIDENTAL);
	if (store_flush(st4))
		bad++;
	print_at_rest(st4, p, nl, " (lz4)");
	for (size_t i = 0; i < n; i++) { /* read once: in the page cache, as above */
		struct tile *g = NULL;
		bad += store_get(st4, &w[i].key, t[i]->type, t[i]->size, tc, &g) != 0;
		tile_unref(g);
	}
	bad += print_layer_hits(st4, p, nl, w, t, tc, per, " (lz4)");
	store_destroy(st4);
	k = 0;
	for (int pass = 0; pass < READS; pass++)
		for (size_t i = 0; i < n; i++) {
			uint64_t a = clock_now_ns();
			struct tile *g = cache_lookup(cache, &w[i].key);
			lat[k++] = clock_now_ns() - a;
			tile_unref(g);
		}
	qsort(lat, k, sizeof *lat, cmp_u64);
	printf("store/memory hit (cache_lookup, for comparison): p50 %.4f ms, p99 %.4f ms\n",
	       (double)lat[k / 2] * 1e-6, (double)lat[k * 99 / 100] * 1e-6);

	/* 37 is prime: i·37 mod n visits every tile while n is not a multiple of it */
	static const char *const way_name[] = { "get alone (faulted a page at a time)",
						"contains then get (the value read ahead)",
						"16 contains then 16 gets (queued jobs)" };
	for (int way = COLD_GET; way <= COLD_QUEUED && n % 37 != 0; way++) {
		double secs;
		long b = cold_reads(&st, file, tc, t, n, (enum cold_way)way, lat, &secs);
		if (b < 0) {
			printf("store/disk hit, file not in the page cache: skipped (its pages cannot be "
			       "dropped here)\n");
			break;
		}
		bad += (size_t)b;
		qsort(lat, n, sizeof *lat, cmp_u64);
		printf("store/disk hit, file not in the page cache, %s: p50 %.3f ms, p99 %.3f ms, "
		       "%.0f tiles/s, %ld wrong\n",
		       way_name[way], (double)lat[n / 2] * 1e-6, (double)lat[n * 99 / 100] * 1e-6,
		       (double)n / secs, b);
	}

	tilecodec_destroy(tc);
	store_destroy(st);
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	if (system(cmd) != 0)
		fprintf(stderr, "bench_store: could not remove %s\n", dir);
	for (size_t i = 0; i < n; i++)
		tile_unref(t[i]);
	free(t);
	free(w);
	free(lat);
	free(per);
	sched_destroy(s);
	cache_destroy(cache);
	planet_unref(p);
	return bad ? 1 : 0;
}
