/* Tile cache tests: hit/miss accounting, the byte budget, pruning by distance to the foci's
 * quads (the quad and its ring survive, far tiles go first), LRU order without foci,
 * costs (cheap intermediate tiles before layer tiles), reference counting across eviction,
 * invalidation by node, last-use times, ranking without the mutex (a tile used meanwhile is
 * kept), and concurrent use. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <pthread.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/grid.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/tile.h"

#define T 16 /* texels: 1 KiB per height tile */
#define TILE_BYTES ((size_t)T * T * 4)

static struct tile_key key(uint64_t node, int lx, int ly, uint32_t x, uint32_t y)
{
	struct tile_key k = { .node = node, .x = x, .y = y, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
	return k;
}

/* A tile whose texels all hold a value derived from its key, so readers can check it. */
static float key_value(const struct tile_key *k)
{
	return (float)(k->node * 1000003u % 4096 + k->x * 64 + k->y + k->lx * 7 + k->ly * 11);
}

static struct tile *make_tile(const struct tile_key *k)
{
	struct tile *t = tile_create(k, PIX_HEIGHT, T);
	float v = key_value(k);
	for (int i = 0; i < T * T; i++)
		tile_f32(t)[i] = v;
	return t;
}

static void insert_new(struct cache *c, const struct tile_key *k)
{
	struct tile *t = make_tile(k);
	cache_insert(c, t);
	tile_unref(t);
}

static void hit_miss(void **state)
{
	(void)state;
	struct cache *c = cache_create(0);
	struct tile_key a = key(1, 1, 0, 0, 0), b = key(1, 1, 0, 1, 0), other = key(2, 1, 0, 0, 0);
	insert_new(c, &a);
	insert_new(c, &b);
	insert_new(c, &a); /* already cached: the old tile stays, no second insert */
	struct tile *t = cache_lookup(c, &a);
	assert_non_null(t);
	assert_true(grid_key_equal(&t->key, &a));
	assert_true(tile_f32(t)[5] == key_value(&a));
	tile_unref(t);
	assert_null(cache_lookup(c, &other));
	assert_true(cache_contains(c, &b));
	assert_false(cache_contains(c, &other));
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.hits, 1);
	assert_int_equal(st.misses, 1);
	assert_int_equal(st.inserts, 2);
	assert_int_equal(st.tiles, 2);
	assert_int_equal(st.bytes, 2 * TILE_BYTES);
	assert_int_equal(st.evictions, 0);
	cache_destroy(c);
}

static void budget_respected(void **state)
{
	(void)state;
	struct cache *c = cache_create(10 * TILE_BYTES);
	struct cache_stats st;
	for (uint32_t i = 0; i < 200; i++) {
		struct tile_key k = key(1, 8, 7, i, i % 128);
		insert_new(c, &k);
		cache_stats(c, &st);
		assert_true(st.bytes <= 10 * TILE_BYTES);
	}
	cache_stats(c, &st);
	assert_int_equal(st.inserts, 200);
	assert_int_equal(st.evictions + st.tiles, 200);
	assert_true(st.tiles >= 9); /* pruned to 90 %, not emptied */
	cache_destroy(c);
}

/* A cache of room for 10 tiles holding the first 10 of the 11 keys it writes to k (one level,
 * one row), inserted in order: k[0] is the least recently used. */
static struct cache *ten_of_eleven(struct tile_key k[11])
{
	struct cache *c = cache_create(10 * TILE_BYTES);
	for (uint32_t i = 0; i < 11; i++)
		k[i] = key(1, 4, 3, i, 0);
	for (int i = 0; i < 10; i++)
		insert_new(c, &k[i]);
	return c;
}

static void lru_without_foci(void **state)
{
	(void)state;
	struct tile_key k[11];
	struct cache *c = ten_of_eleven(k);
	/* Use 0..4 again: 5 and 6 become the least recently used. */
	for (int i = 0; i < 5; i++)
		tile_unref(cache_lookup(c, &k[i]));
	insert_new(c, &k[10]); /* 11 tiles > 10: prune to 9 */
	for (int i = 0; i < 11; i++)
		assert_int_equal(cache_contains(c, &k[i]), i != 5 && i != 6);
	cache_destroy(c);
}

/* During a ranking for eviction, another thread looks a tile up: it must not wait for the
 * ranking (the mutex is not held while ranking: the event loop looks tiles up), and the tile
 * it used is kept although it ranked first to go. */
struct rank_probe {
	struct cache *c;
	struct tile_key k;
	int calls;
	bool found, done;
	pthread_mutex_t mu;
	pthread_cond_t cv;
};

static void *probe_lookup(void *arg)
{
	struct rank_probe *p = arg;
	struct tile *t = cache_lookup(p->c, &p->k);
	pthread_mutex_lock(&p->mu);
	p->found = t != NULL;
	p->done = true;
	pthread_cond_signal(&p->cv);
	pthread_mutex_unlock(&p->mu);
	tile_unref(t);
	return NULL;
}

static void rank_hook(void *ud)
{
	struct rank_probe *p = ud;
	p->calls++;
	pthread_t th;
	assert_int_equal(pthread_create(&th, NULL, probe_lookup, p), 0);
	struct timespec dl;
	clock_gettime(CLOCK_REALTIME, &dl);
	dl.tv_sec += 10;
	pthread_mutex_lock(&p->mu);
	while (!p->done)
		if (pthread_cond_timedwait(&p->cv, &p->mu, &dl) != 0)
			break;
	bool done = p->done;
	pthread_mutex_unlock(&p->mu);
	if (!done)
		fail_msg("a lookup waited 10 s for the ranking: the ranking holds the cache's mutex");
	pthread_join(th, NULL);
}

static void ranking_without_the_lock(void **state)
{
	(void)state;
	struct tile_key k[11];
	struct cache *c = ten_of_eleven(k);
	struct rank_probe p = { .c = c, .k = k[0] };
	pthread_mutex_init(&p.mu, NULL);
	pthread_cond_init(&p.cv, NULL);
	cache_set_rank_hook(c, rank_hook, &p);
	insert_new(c, &k[10]); /* 11 tiles > 10: prune to 9; 0, 1 and 2 rank first to go */
	assert_int_equal(p.calls, 1);
	assert_true(p.found);
	for (int i = 0; i < 11; i++)
		assert_int_equal(cache_contains(c, &k[i]), i != 1 && i != 2);
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.prunes, 1);
	assert_int_equal(st.evictions, 2);
	assert_true(st.prune_hold_max_ns <= st.prune_ns);
	cache_set_rank_hook(c, NULL, NULL);
	pthread_cond_destroy(&p.cv);
	pthread_mutex_destroy(&p.mu);
	cache_destroy(c);
}

/* The viewer's window around (lon, lat) at level (lx, ly): what the cache ranks by. */
static void window(int lx, int ly, double lon, double lat, struct grid_quad *q)
{
	grid_window(lx, ly, T, GRID_WINDOW_TILES * T, lon, lat, q);
}

/* Keys within Chebyshev distance ≤ 1 of the focus's window at level (lx, ly). */
static bool in_ring(int lx, int ly, double lon, double lat, const struct tile_key *k)
{
	struct grid_quad q;
	window(lx, ly, lon, lat, &q);
	return grid_quad_distance(&q, k) <= 1;
}

static void prune_keeps_quad_and_ring(void **state)
{
	(void)state;
	const double lon = 37.3, lat = -21.7;
	struct cache *c = cache_create(0);
	struct cache_focus f = { lon, lat };
	cache_set_foci(c, &f, 1, T);
	/* Two levels, 32×16 and 64×32 tiles. Quad and ring tiles are inserted first, so the
	 * least recently used are exactly the ones distance must protect. */
	const int lv[2][2] = { { 5, 4 }, { 6, 5 } };
	size_t total = 0, ring = 0;
	for (int pass = 0; pass < 2; pass++)
		for (int l = 0; l < 2; l++)
			for (uint32_t y = 0; y < grid_tiles_y(lv[l][1]); y++)
				for (uint32_t x = 0; x < grid_tiles_x(lv[l][0]); x++) {
					struct tile_key k = key(9, lv[l][0], lv[l][1], x, y);
					bool r = in_ring(lv[l][0], lv[l][1], lon, lat, &k);
					if (r != (pass == 0))
						continue;
					insert_new(c, &k);
					total++;
					ring += r;
				}
	const int n = GRID_WINDOW_TILES;
	assert_true(ring >= 2 * (size_t)((n + 2) * (n + 2)) && ring <= 2 * (size_t)((n + 3) * (n + 3)));
	size_t keep = ring + 40;
	cache_prune(c, keep * TILE_BYTES);
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.tiles, keep);
	assert_int_equal(st.evictions, total - keep);
	/* Every quad/ring tile stayed; every surviving tile is at most as far as every evicted. */
	uint32_t max_kept = 0, min_evicted = UINT32_MAX;
	for (int l = 0; l < 2; l++) {
		struct grid_quad q;
		window(lv[l][0], lv[l][1], lon, lat, &q);
		for (uint32_t y = 0; y < grid_tiles_y(lv[l][1]); y++)
			for (uint32_t x = 0; x < grid_tiles_x(lv[l][0]); x++) {
				struct tile_key k = key(9, lv[l][0], lv[l][1], x, y);
				uint32_t d = grid_quad_distance(&q, &k);
				bool has = cache_contains(c, &k);
				if (d <= 1)
					assert_true(has);
				if (has && d > max_kept)
					max_kept = d;
				if (!has && d < min_evicted)
					min_evicted = d;
			}
	}
	assert_true(max_kept <= min_evicted);
	assert_true(max_kept >= 2); /* 40 non-ring tiles: the next ring out */
	/* Squeezing to the windows' size finally takes ring tiles, the ring before the window. */
	struct grid_quad q[2];
	struct tile_key qt[2][GRID_WINDOW_MAX_KEYS];
	int nq[2];
	for (int l = 0; l < 2; l++) {
		window(lv[l][0], lv[l][1], lon, lat, &q[l]);
		nq[l] = grid_quad_tiles(&q[l], 9, qt[l]);
	}
	cache_prune(c, (size_t)(nq[0] + nq[1]) * TILE_BYTES);
	cache_stats(c, &st);
	assert_int_equal(st.tiles, nq[0] + nq[1]);
	for (int l = 0; l < 2; l++)
		for (int i = 0; i < nq[l]; i++)
			assert_true(cache_contains(c, &qt[l][i]));
	cache_destroy(c);
}

/* An unbounded cache with one focus at (lon, lat), and the focus's window at (lx, ly). */
static struct cache *focused(double lon, double lat, int lx, int ly, struct grid_quad *q)
{
	struct cache *c = cache_create(0);
	struct cache_focus f = { lon, lat };
	cache_set_foci(c, &f, 1, T);
	window(lx, ly, lon, lat, q);
	return c;
}

/* Prunes c to n tiles' bytes and checks that n tiles are left. */
static void prune_to_tiles(struct cache *c, size_t n)
{
	cache_prune(c, n * TILE_BYTES);
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.tiles, n);
}

/* Costs (tile.h cost_ms, layer): in a budget smaller than the tiles around the focus, the
 * cheap intermediate tiles of the window go before the layer tiles of its ring (what viewers
 * ask for again), a dear intermediate tile stays beside them, and a layer tile far from the
 * focus still goes before a cheap one near it. */
static void cheap_intermediates_go_first(void **state)
{
	(void)state;
	const int lx = 7, ly = 6;
	struct grid_quad q;
	struct cache *c = focused(12.5, 41.9, lx, ly, &q);
	size_t nlayer = 0, ncheap = 0;
	struct tile_key dear = { 0 }, far = { 0 };
	bool have_dear = false, have_far = false;
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(3, lx, ly, x, y);
			uint32_t d = grid_quad_distance(&q, &k);
			struct tile *t = NULL;
			if (d == 0) { /* the window: intermediate tiles of two nodes */
				t = make_tile(&k);
				t->cost_ms = 0.2f;
				cache_insert(c, t);
				tile_unref(t);
				ncheap++;
				struct tile_key k2 = key(4, lx, ly, x, y);
				t = make_tile(&k2);
				t->cost_ms = have_dear ? 0.3f : 40.0f;
				if (!have_dear)
					dear = k2, have_dear = true;
				else
					ncheap++;
			} else if (d == 1) { /* the ring: layer tiles */
				struct tile_key k2 = key(5, lx, ly, x, y);
				t = make_tile(&k2);
				t->cost_ms = 10.0f;
				t->layer = true;
				nlayer++;
			} else if (d == 8 && !have_far) {
				far = key(5, lx, ly, x, y);
				t = make_tile(&far);
				t->cost_ms = 10.0f;
				t->layer = true;
				have_far = true;
			}
			if (t) {
				cache_insert(c, t);
				tile_unref(t);
			}
		}
	assert_true(have_dear && have_far && nlayer > 0 && ncheap > 0);
	/* The layer tiles and the dear one stay; the cheap ones (inserted later than some of
	 * the layer tiles: recency alone would keep them) and the far layer tile go. */
	cache_prune(c, (nlayer + 1) * TILE_BYTES);
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(5, lx, ly, x, y);
			if (grid_quad_distance(&q, &k) == 1)
				assert_true(cache_contains(c, &k));
			assert_false(cache_contains(c, &(struct tile_key){ .node = 3, .x = x, .y = y,
									  .lx = lx, .ly = ly }));
		}
	assert_true(cache_contains(c, &dear));
	assert_false(cache_contains(c, &far));
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.tiles, nlayer + 1);
	cache_destroy(c);
}

/* Lineage tiles (tile.h lineage: a from_parent noise node's carry, from which every finer tile
 * of its node is built) are kept as layer tiles are, at the layer tiles' mean cost when theirs
 * is less: in a budget that holds the window's layer and carry tiles but not its intermediate
 * ones nor the ring's layer tiles, the carries stay — though each cost less to make (0.3 ms)
 * than any intermediate tile (2 ms), and were inserted first — and the others go (at its own
 * cost a carry in the window would go before a layer tile in the ring). Before 5 December a carry
 * counted its own 0.3 ms and went first: the procedural planet made its coarse carries up to
 * 60 times in one 8 s flight (bench_keepup). */
static void lineage_kept_as_layers(void **state)
{
	(void)state;
	const int lx = 7, ly = 6;
	struct grid_quad q;
	struct cache *c = focused(-150.0, 0.5, lx, ly, &q);
	size_t nwin = 0;
	for (int pass = 0; pass < 3; pass++) /* carries, then layer tiles, then intermediates */
		for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
			for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
				struct tile_key k = key(6 + (uint64_t)pass, lx, ly, x, y);
				uint32_t d = grid_quad_distance(&q, &k);
				if (d > (pass == 1 ? 1u : 0u)) /* layer tiles in the ring too */
					continue;
				struct tile *t = make_tile(&k);
				t->cost_ms = pass == 0 ? 0.3f : pass == 1 ? 6.0f : 2.0f;
				t->lineage = pass == 0;
				t->layer = pass == 1;
				cache_insert(c, t);
				tile_unref(t);
				nwin += pass == 0;
			}
	assert_true(nwin > 0);
	prune_to_tiles(c, 2 * nwin);
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(6, lx, ly, x, y);
			if (grid_quad_distance(&q, &k) != 0)
				continue;
			assert_true(cache_contains(c, &k)); /* the carry */
			k.node = 7;
			assert_true(cache_contains(c, &k)); /* the layer tile */
			k.node = 8;
			assert_false(cache_contains(c, &k)); /* the intermediate */
		}
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(7, lx, ly, x, y);
			if (grid_quad_distance(&q, &k) == 1)
				assert_false(cache_contains(c, &k)); /* the ring's layer tiles */
		}
	/* With no layer tile cached a carry counts its own cost, as a layer tile would (×
	 * LAYER_WEIGHT): it still stays before intermediates dearer than itself. */
	cache_drop_node(c, 7);
	struct tile_key ki = { .node = 8, .lx = lx, .ly = ly, .x = q.tx0, .y = q.ty0 };
	struct tile *t = make_tile(&ki);
	t->cost_ms = 2.0f;
	cache_insert(c, t);
	tile_unref(t);
	prune_to_tiles(c, nwin);
	assert_false(cache_contains(c, &ki));
	cache_destroy(c);
}

/* Beyond LINEAGE_REACH (one tile) of a focus's window a lineage tile is ranked at its own
 * cost, as an intermediate tile: carries two tiles out go before the window's intermediate
 * tiles (2 ms each, 0.3 ms a carry), though with layer tiles cached a carry in reach counts
 * their mean cost. Kept as layer tiles at every distance they took 46 % of a 1 GiB cache in
 * a flight over the procedural planet's land, and terrain tiles near the focus went instead. */
static void lineage_beyond_reach_ranked_at_cost(void **state)
{
	(void)state;
	const int lx = 7, ly = 6;
	struct grid_quad q;
	struct cache *c = focused(-150.0, 0.5, lx, ly, &q);
	size_t nwin = 0, nfar = 0;
	/* far carries first (the least recently used), then the window's layer, carry and
	 * intermediate tiles */
	for (int pass = 0; pass < 4; pass++)
		for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
			for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
				struct tile_key k = key(6 + (uint64_t)pass, lx, ly, x, y);
				if (grid_quad_distance(&q, &k) != (pass == 0 ? 2u : 0u))
					continue;
				struct tile *t = make_tile(&k);
				t->cost_ms = pass == 1 ? 6.0f : pass == 3 ? 2.0f : 0.3f;
				t->lineage = pass == 0 || pass == 2;
				t->layer = pass == 1;
				cache_insert(c, t);
				tile_unref(t);
				nfar += pass == 0;
				nwin += pass == 1;
			}
	assert_true(nwin > 0 && nfar > 0);
	prune_to_tiles(c, 3 * nwin);
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(6, lx, ly, x, y);
			uint32_t d = grid_quad_distance(&q, &k);
			for (uint64_t node = 6; node <= 9; node++) {
				k.node = node;
				if (node == 6)
					assert_false(cache_contains(c, &k)); /* far carries: none */
				else
					assert_true(cache_contains(c, &k) == (d == 0));
			}
		}
	cache_destroy(c);
}

static void budget_prune_uses_foci(void **state)
{
	(void)state;
	const double lon = -120.0, lat = 45.0;
	/* 108 after a prune ≥ 2 windows of 5×5 tiles with their rings (2 × 49) */
	struct cache *c = cache_create(120 * TILE_BYTES);
	struct cache_focus f[2] = { { lon, lat }, { 100.0, -10.0 } };
	cache_set_foci(c, f, 2, T);
	const int lx = 5, ly = 4;
	for (int pass = 0; pass < 2; pass++)
		for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
			for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
				struct tile_key k = key(3, lx, ly, x, y);
				bool r = in_ring(lx, ly, f[0].lon, f[0].lat, &k) ||
					 in_ring(lx, ly, f[1].lon, f[1].lat, &k);
				if (r == (pass == 0))
					insert_new(c, &k);
			}
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = key(3, lx, ly, x, y);
			if (in_ring(lx, ly, f[0].lon, f[0].lat, &k) ||
			    in_ring(lx, ly, f[1].lon, f[1].lat, &k))
				assert_true(cache_contains(c, &k));
		}
	cache_destroy(c);
}

static void evicted_tile_stays_readable(void **state)
{
	(void)state;
	struct cache *c = cache_create(0);
	struct tile_key k = key(5, 3, 2, 4, 1);
	struct tile *mine = make_tile(&k);
	cache_insert(c, mine);
	struct tile *held = cache_lookup(c, &k);
	cache_prune(c, 0);
	assert_false(cache_contains(c, &k));
	/* Both the creator's and the lookup's references still read the data (ASan checks). */
	assert_true(tile_f32(held)[T * T - 1] == key_value(&k));
	tile_unref(held);
	assert_true(tile_f32(mine)[0] == key_value(&k));
	tile_unref(mine);
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.evictions, 1);
	assert_int_equal(st.bytes, 0);
	cache_destroy(c);
}

static int count_node(void *ud, const struct tile *t, uint64_t used_ns)
{
	size_t *n = ud;
	(void)used_ns;
	if (t->key.node == 7)
		n[0]++;
	else
		n[1]++;
	return 0;
}

static void drop_node_and_foreach(void **state)
{
	(void)state;
	struct cache *c = cache_create(0);
	for (uint32_t i = 0; i < 20; i++) {
		struct tile_key k = key(i % 2 ? 7 : 8, 6, 5, i, 3);
		insert_new(c, &k);
	}
	size_t n[2] = { 0, 0 };
	cache_foreach(c, count_node, n);
	assert_int_equal(n[0], 10);
	assert_int_equal(n[1], 10);
	assert_int_equal(cache_drop_node(c, 7), 10);
	n[0] = n[1] = 0;
	cache_foreach(c, count_node, n);
	assert_int_equal(n[0], 0);
	assert_int_equal(n[1], 10);
	struct cache_stats st;
	cache_stats(c, &st);
	assert_int_equal(st.tiles, 10);
	assert_int_equal(st.bytes, 10 * TILE_BYTES);
	cache_destroy(c);
}

struct worker_arg {
	struct cache *c;
	unsigned seed;
	int bad;
};

static void *hammer(void *p)
{
	struct worker_arg *a = p;
	uint64_t s = a->seed * 2654435761u + 1;
	for (int i = 0; i < 4000; i++) {
		s = s * 6364136223846793005u + 1442695040888963407u;
		struct tile_key k = key(1 + (s >> 60) % 3, 7, 6, (uint32_t)(s >> 33) % 128,
					(uint32_t)(s >> 20) % 64);
		if ((s >> 10) % 3 == 0) {
			insert_new(a->c, &k);
		} else {
			struct tile *t = cache_lookup(a->c, &k);
			if (t && (!grid_key_equal(&t->key, &k) || tile_f32(t)[17] != key_value(&k)))
				a->bad++;
			tile_unref(t);
		}
	}
	return NULL;
}

static void concurrent(void **state)
{
	(void)state;
	struct cache *c = cache_create(300 * TILE_BYTES);
	struct cache_focus f = { 10.0, 20.0 };
	cache_set_foci(c, &f, 1, T);
	pthread_t th[8];
	struct worker_arg a[8];
	for (int i = 0; i < 8; i++) {
		a[i] = (struct worker_arg){ c, (unsigned)i + 1, 0 };
		assert_int_equal(xthread_create(&th[i], hammer, &a[i]), 0);
	}
	for (int i = 0; i < 8; i++) {
		xthread_join(th[i]);
		assert_int_equal(a[i].bad, 0);
	}
	struct cache_stats st;
	cache_stats(c, &st);
	assert_true(st.bytes <= 300 * TILE_BYTES);
	assert_int_equal(st.hits + st.misses + st.inserts > 0, 1);
	assert_int_equal(st.inserts, st.tiles + st.evictions);
	cache_destroy(c);
}

struct used_at {
	struct tile_key k;
	uint64_t used_ns;
	int seen;
};

static int find_used(void *ud, const struct tile *t, uint64_t used_ns)
{
	struct used_at *u = ud;
	for (int i = 0; i < 2; i++)
		if (grid_key_equal(&t->key, &u[i].k)) {
			u[i].used_ns = used_ns;
			u[i].seen++;
		}
	return 0;
}

/* Each tile's last use is its last lookup or insert: a tile used 1.1 s ago is that old, one
 * looked up just now is not (what CACHE_LS reports as age). */
static void last_use_reported(void **state)
{
	(void)state;
	struct cache *c = cache_create(0);
	struct used_at u[2] = { { .k = key(1, 1, 0, 0, 0) }, { .k = key(1, 1, 0, 1, 0) } };
	insert_new(c, &u[0].k);
	insert_new(c, &u[1].k);
	uint64_t t0 = clock_now_ns();
	struct timespec d = { 1, 100000000 };
	while (nanosleep(&d, &d) != 0)
		;
	struct tile *t = cache_lookup(c, &u[1].k); /* used again now */
	assert_non_null(t);
	tile_unref(t);
	uint64_t now = clock_now_ns();
	cache_foreach(c, find_used, u);
	assert_int_equal(u[0].seen, 1);
	assert_int_equal(u[1].seen, 1);
	assert_true(u[0].used_ns <= t0);
	assert_true(now - u[0].used_ns >= 1100000000ull);
	assert_true(u[1].used_ns > t0 + 1000000000ull && u[1].used_ns <= now);
	/* cache_contains does not count as a use */
	assert_true(cache_contains(c, &u[0].k));
	cache_foreach(c, find_used, u);
	assert_true(u[0].used_ns <= t0);
	cache_destroy(c);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(hit_miss),
		cmocka_unit_test(budget_respected),
		cmocka_unit_test(lru_without_foci),
		cmocka_unit_test(ranking_without_the_lock),
		cmocka_unit_test(prune_keeps_quad_and_ring),
		cmocka_unit_test(budget_prune_uses_foci),
		cmocka_unit_test(cheap_intermediates_go_first),
		cmocka_unit_test(lineage_kept_as_layers),
		cmocka_unit_test(lineage_beyond_reach_ranked_at_cost),
		cmocka_unit_test(evicted_tile_stays_readable),
		cmocka_unit_test(drop_node_and_foreach),
		cmocka_unit_test(last_use_reported),
		cmocka_unit_test(concurrent),
	};
	return cmocka_run_group_tests_name("cache", tests, NULL, NULL);
}
