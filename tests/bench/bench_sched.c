/* Scheduler overhead: tiles per second through manager and workers for a node that does
 * (almost) nothing, and the latency from sched_req_want to the callback for a cached tile.
 * Prints one line per figure. */
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/node.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/tile.h"

static int gen_cheap(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		     struct tile *const *in, int nin, struct tile *out)
{
	(void)n, (void)g, (void)k, (void)in, (void)nin;
	tile_f32(out)[0] = 1.0f; /* the rest stays uninitialised: we time the machinery */
	return 0;
}

static const struct node_type t_cheap = { .name = "cheap", .generate = gen_cheap };

struct counter {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	size_t n, target;
	uint64_t t_ready; /* ns, when the last callback ran */
};

static void on_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	(void)w, (void)t, (void)err;
	struct counter *c = ud;
	xmutex_lock(&c->mu);
	c->t_ready = clock_now_ns();
	if (++c->n >= c->target)
		xcond_signal(&c->cv);
	xmutex_unlock(&c->mu);
}

static void wait_count(struct counter *c)
{
	xmutex_lock(&c->mu);
	while (c->n < c->target)
		xcond_wait(&c->cv, &c->mu);
	xmutex_unlock(&c->mu);
}

static void node_setup(struct node *n, struct planet *p, uint64_t hash)
{
	memset(n, 0, sizeof *n);
	n->name = (char *)"cheap";
	n->type = &t_cheap;
	n->out = PIX_HEIGHT;
	n->hash = hash;
	n->planet = p;
	atomic_init(&n->generated, 0);
	atomic_init(&n->gen_ns, 0);
}

/* Tiles per second: one want list of every tile of a level, callbacks counted. */
static void throughput(uint32_t T, int workers, int ly)
{
	struct planet p = { .tile_size = T, .max_level = 12 };
	struct node n;
	node_setup(&n, &p, 0x1234 + (uint64_t)T * 31 + (uint64_t)workers);
	struct cache *c = cache_create((size_t)256 << 20);
	struct sched_desc d = { .cache = c, .workers = workers };
	struct sched *s = sched_create(&d);
	size_t nx = (size_t)1 << (ly + 1), ny = (size_t)1 << ly, total = nx * ny;
	struct want *w = malloc(total * sizeof *w);
	if (!w || !s || !c) {
		fprintf(stderr, "bench_sched: out of memory\n");
		exit(1);
	}
	size_t i = 0;
	for (uint32_t y = 0; y < ny; y++)
		for (uint32_t x = 0; x < nx; x++) {
			struct tile_key k = { .node = n.hash, .x = x, .y = y,
					      .lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly };
			w[i++] = (struct want){ .node = &n, .key = k, .cls = SCHED_BULK };
		}
	struct counter cnt = { .target = total };
	xmutex_init(&cnt.mu);
	xcond_init(&cnt.cv);
	struct sched_req *r = sched_req_create(s, on_ready, &cnt);
	uint64_t t0 = clock_now_ns();
	if (sched_req_want(r, w, total) != 0) {
		fprintf(stderr, "bench_sched: want refused\n");
		exit(1);
	}
	wait_count(&cnt);
	double sec = (double)(cnt.t_ready - t0) * 1e-9;
	printf("sched/throughput T=%u %d worker%s: %.0f tiles/s (%zu tiles, %.1f us/tile)\n", T,
	       workers, workers == 1 ? "" : "s", (double)total / sec, total, sec * 1e6 / (double)total);
	sched_req_destroy(r);
	sched_destroy(s);
	cache_destroy(c);
	xmutex_destroy(&cnt.mu);
	xcond_destroy(&cnt.cv);
	free(w);
}

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

/* Want → callback for a tile already in the cache, one want list at a time. */
static void cached_latency(int rounds)
{
	struct planet p = { .tile_size = 256, .max_level = 12 };
	struct node n;
	node_setup(&n, &p, 0x777);
	struct cache *c = cache_create(0);
	struct sched_desc d = { .cache = c, .workers = 1 };
	struct sched *s = sched_create(&d);
	struct tile_key k = { .node = n.hash, .x = 3, .y = 2, .lx = 4, .ly = 3 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, 256);
	memset(t->data, 0, t->nbytes);
	cache_insert(c, t);
	tile_unref(t);
	struct want w = { .node = &n, .key = k, .cls = SCHED_VISIBLE };
	struct counter cnt = { .target = 0 };
	xmutex_init(&cnt.mu);
	xcond_init(&cnt.cv);
	struct sched_req *r = sched_req_create(s, on_ready, &cnt);
	uint64_t *lat = malloc((size_t)rounds * sizeof *lat);
	if (!lat || !s || !c) {
		fprintf(stderr, "bench_sched: out of memory\n");
		exit(1);
	}
	for (int i = 0; i < rounds; i++) {
		xmutex_lock(&cnt.mu);
		cnt.target++;
		xmutex_unlock(&cnt.mu);
		uint64_t t0 = clock_now_ns();
		if (sched_req_want(r, &w, 1) != 0) {
			fprintf(stderr, "bench_sched: want refused\n");
			exit(1);
		}
		wait_count(&cnt);
		lat[i] = cnt.t_ready - t0;
	}
	qsort(lat, (size_t)rounds, sizeof *lat, cmp_u64);
	printf("sched/cached want->callback: p50 %.1f us\n", (double)lat[rounds / 2] * 1e-3);
	printf("sched/cached want->callback: p99 %.1f us\n", (double)lat[rounds * 99 / 100] * 1e-3);
	sched_req_destroy(r);
	sched_destroy(s);
	cache_destroy(c);
	xmutex_destroy(&cnt.mu);
	xcond_destroy(&cnt.cv);
	free(lat);
}

int main(void)
{
	throughput(256, 1, 7);
	throughput(256, 2, 7);
	throughput(16, 1, 7);
	throughput(16, 2, 7);
	cached_latency(5000);
	return 0;
}
