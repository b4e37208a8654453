/* cache — see cache.h. A chained hash table (power-of-two buckets, each entry keeps its key
 * hash) under one mutex, with an LRU clock and the monotonic time stamped on lookup and insert.
 *
 * Pruning ranks every tile by what keeping it is worth (keep_worth): its cost to make again,
 * discounted by its distance (grid_quad_distance) to the nearest focus's window at the tile's
 * own level; it evicts the least worth first and, among equal worth, the least recently
 * stamped. Tiles of one cost go farthest first; with no foci and equal costs it is plain
 * LRU. Quads are computed
 * once per (focus, level) per prune. Evicted tiles are unreferenced after the mutex is
 * released, so freeing tile memory never happens under the lock.
 */
#include "cache.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "common/clock.h"
#include "common/xalloc.h"
#include "common/xthread.h"

#define NLX (GRID_MAX_LEVEL + 2)
#define NLY (GRID_MAX_LEVEL + 1)

struct centry {
	struct tile *t; /* the cache's own reference */
	uint64_t hash;
	uint64_t stamp;	  /* LRU clock value of the last lookup or insert */
	uint64_t used_ns; /* clock_now_ns() of the last lookup or insert */
	struct centry *next;
};

struct cache {
	pthread_mutex_t mu; /* protects everything below */
	struct centry **buckets;
	size_t nbuckets; /* power of two */
	size_t budget, bytes, ntiles;
	uint64_t clock, hits, misses, inserts, evictions;
	struct cache_focus *foci;
	size_t nfoci;
	uint32_t tile_size; /* for the foci's quads; 0: each tile's own size */
};

/* A tile considered for eviction. */
struct victim {
	float keep; /* what keeping it is worth: its cost, discounted by its distance */
	uint64_t stamp;
	struct centry *e;
};

struct cache *cache_create(size_t budget_bytes)
{
	struct cache *c = xcalloc(1, sizeof *c);
	xmutex_init(&c->mu);
	c->nbuckets = 1024;
	c->buckets = xcalloc(c->nbuckets, sizeof *c->buckets);
	c->budget = budget_bytes;
	return c;
}

void cache_destroy(struct cache *c)
{
	if (!c)
		return;
	for (size_t b = 0; b < c->nbuckets; b++) {
		struct centry *e = c->buckets[b];
		while (e) {
			struct centry *next = e->next;
			tile_unref(e->t);
			free(e);
			e = next;
		}
	}
	free(c->buckets);
	free(c->foci);
	xmutex_destroy(&c->mu);
	free(c);
}

/* Needs c->mu. */
static struct centry *find(struct cache *c, const struct tile_key *k, uint64_t h)
{
	for (struct centry *e = c->buckets[h & (c->nbuckets - 1)]; e; e = e->next)
		if (e->hash == h && grid_key_equal(&e->t->key, k))
			return e;
	return NULL;
}

/* Unlinks e from its chain (needs c->mu); the caller owns e and its reference afterwards. */
static void unlink_entry(struct cache *c, struct centry *e)
{
	struct centry **p = &c->buckets[e->hash & (c->nbuckets - 1)];
	while (*p != e)
		p = &(*p)->next;
	*p = e->next;
	c->bytes -= e->t->nbytes;
	c->ntiles--;
}

/* Needs c->mu. */
static void grow(struct cache *c)
{
	size_t n = c->nbuckets * 2;
	struct centry **b = xcalloc(n, sizeof *b);
	for (size_t i = 0; i < c->nbuckets; i++) {
		struct centry *e = c->buckets[i];
		while (e) {
			struct centry *next = e->next;
			e->next = b[e->hash & (n - 1)];
			b[e->hash & (n - 1)] = e;
			e = next;
		}
	}
	free(c->buckets);
	c->buckets = b;
	c->nbuckets = n;
}

struct tile *cache_lookup(struct cache *c, const struct tile_key *k)
{
	uint64_t h = grid_key_hash(k);
	struct tile *t = NULL;
	uint64_t now = clock_now_ns(); /* read before locking: nothing extra under the lock */
	xmutex_lock(&c->mu);
	struct centry *e = find(c, k, h);
	if (e) {
		e->stamp = ++c->clock;
		e->used_ns = now;
		t = tile_ref(e->t);
		c->hits++;
	} else {
		c->misses++;
	}
	xmutex_unlock(&c->mu);
	return t;
}

bool cache_contains(struct cache *c, const struct tile_key *k)
{
	uint64_t h = grid_key_hash(k);
	xmutex_lock(&c->mu);
	bool found = find(c, k, h) != NULL;
	xmutex_unlock(&c->mu);
	return found;
}

static int cmp_victim(const void *pa, const void *pb)
{
	const struct victim *a = pa, *b = pb;
	if (a->keep != b->keep)
		return a->keep < b->keep ? -1 : 1; /* least worth keeping first */
	if (a->stamp != b->stamp)
		return a->stamp < b->stamp ? -1 : 1; /* then least recently used */
	return 0;
}

/* What keeping a tile at focus distance d is worth: its cost to make again (tile.h cost_ms,
 * at least COST_FLOOR_MS), divided by 4 per tile of distance. Among tiles of one cost the
 * farthest goes first, as before costs counted; a tile ten times dearer is kept over a
 * cheap one up to ~1.7 tiles nearer. A layer tile counts LAYER_WEIGHT times its cost (three
 * tiles of distance): it is what viewers ask for again, and making it again needs its
 * intermediate tiles too. In a cache smaller than the tiles around its foci (a fast flight
 * over the procedural planet at 50 km: ~30 intermediate tiles per layer tile, ~4 GiB in the
 * windows and rings against the shipped 1 GiB) the cheap intermediate tiles go before the
 * layer tiles they were made for: a third of the terrain tiles were made twice or more
 * before this (bench_keepup, KEEPUP_DEBUG). */
#define COST_FLOOR_MS 0.05f
#define LAYER_WEIGHT 64.0f
static float keep_worth(const struct tile *t, uint32_t d)
{
	float c = t->cost_ms > COST_FLOOR_MS ? t->cost_ms : COST_FLOOR_MS;
	if (t->layer)
		c *= LAYER_WEIGHT;
	return ldexpf(c, -2 * (int)(d < 60 ? d : 60));
}

/* Distance of tile t to the nearest focus's quad at t's level. quads/valid: lazily filled
 * table [focus][ly][lx]. Needs c->mu. */
static uint32_t focus_distance(struct cache *c, const struct tile *t, struct grid_quad *quads,
			       unsigned char *valid)
{
	uint32_t best = UINT32_MAX;
	const struct tile_key *k = &t->key;
	if (k->ly >= NLY || k->lx >= NLX)
		return best;
	uint32_t T = c->tile_size ? c->tile_size : t->size;
	for (size_t f = 0; f < c->nfoci; f++) {
		size_t i = (f * NLY + k->ly) * NLX + k->lx;
		/* A quad cached for another tile size is recomputed (tiles of layers whose T
		 * differs from the foci's are rare). */
		if (!valid[i] || quads[i].T != T) {
			grid_window(k->lx, k->ly, T, GRID_WINDOW_TILES * T, c->foci[f].lon,
				    c->foci[f].lat, &quads[i]);
			valid[i] = 1;
		}
		uint32_t d = grid_quad_distance(&quads[i], k);
		if (d < best)
			best = d;
	}
	return best;
}

/* Evicts until at most target bytes remain. Needs c->mu; returns the evicted tiles (owned
 * references, to unref once the lock is dropped) in *out, how many in *nout. */
static void prune_locked(struct cache *c, size_t target, struct tile ***out, size_t *nout)
{
	*out = NULL;
	*nout = 0;
	if (c->bytes <= target)
		return;
	struct victim *v = xmalloc(c->ntiles * sizeof *v);
	struct grid_quad *quads = NULL;
	unsigned char *valid = NULL;
	if (c->nfoci) {
		quads = xmalloc(c->nfoci * NLY * NLX * sizeof *quads);
		valid = xcalloc(c->nfoci * NLY * NLX, 1);
	}
	size_t n = 0;
	for (size_t b = 0; b < c->nbuckets; b++)
		for (struct centry *e = c->buckets[b]; e; e = e->next) {
			v[n].keep = keep_worth(e->t, c->nfoci ? focus_distance(c, e->t, quads, valid)
							      : 0);
			v[n].stamp = e->stamp;
			v[n].e = e;
			n++;
		}
	qsort(v, n, sizeof *v, cmp_victim);
	struct tile **tiles = xmalloc(n * sizeof *tiles);
	size_t m = 0;
	for (size_t i = 0; i < n && c->bytes > target; i++) {
		unlink_entry(c, v[i].e);
		tiles[m++] = v[i].e->t;
		free(v[i].e);
		c->evictions++;
	}
	free(v);
	free(quads);
	free(valid);
	*out = tiles;
	*nout = m;
}

static void unref_all(struct tile **tiles, size_t n)
{
	for (size_t i = 0; i < n; i++)
		tile_unref(tiles[i]);
	free(tiles);
}

static void insert(struct cache *c, struct tile *t, bool cold)
{
	uint64_t h = grid_key_hash(&t->key);
	struct tile **ev = NULL;
	size_t nev = 0;
	uint64_t now = clock_now_ns();
	xmutex_lock(&c->mu);
	struct centry *e = find(c, &t->key, h);
	if (e) {
		if (!cold) {
			e->stamp = ++c->clock;
			e->used_ns = now;
		}
	} else {
		e = xmalloc(sizeof *e);
		e->t = tile_ref(t);
		e->hash = h;
		e->stamp = cold ? 0 : ++c->clock;
		e->used_ns = now;
		e->next = c->buckets[h & (c->nbuckets - 1)];
		c->buckets[h & (c->nbuckets - 1)] = e;
		c->bytes += t->nbytes;
		c->ntiles++;
		c->inserts++;
		if (c->ntiles > c->nbuckets)
			grow(c);
		/* Prune to 90 % so the next few inserts do not each pay for a full ranking. */
		if (c->budget && c->bytes > c->budget)
			prune_locked(c, c->budget - c->budget / 10, &ev, &nev);
	}
	xmutex_unlock(&c->mu);
	unref_all(ev, nev);
}

void cache_insert(struct cache *c, struct tile *t)
{
	insert(c, t, false);
}

void cache_insert_cold(struct cache *c, struct tile *t)
{
	insert(c, t, true);
}

void cache_set_foci(struct cache *c, const struct cache_focus *foci, size_t n, uint32_t tile_size)
{
	struct cache_focus *copy = NULL;
	if (n) {
		copy = xmalloc(n * sizeof *copy);
		memcpy(copy, foci, n * sizeof *copy);
	}
	xmutex_lock(&c->mu);
	struct cache_focus *old = c->foci;
	c->foci = copy;
	c->nfoci = n;
	c->tile_size = tile_size;
	xmutex_unlock(&c->mu);
	free(old);
}

void cache_prune(struct cache *c, size_t target)
{
	struct tile **ev;
	size_t nev;
	xmutex_lock(&c->mu);
	prune_locked(c, target, &ev, &nev);
	xmutex_unlock(&c->mu);
	unref_all(ev, nev);
}

void cache_stats(struct cache *c, struct cache_stats *out)
{
	xmutex_lock(&c->mu);
	out->hits = c->hits;
	out->misses = c->misses;
	out->inserts = c->inserts;
	out->evictions = c->evictions;
	out->bytes = c->bytes;
	out->tiles = c->ntiles;
	out->budget = c->budget;
	xmutex_unlock(&c->mu);
}

void cache_foreach(struct cache *c, int (*fn)(void *ud, const struct tile *t, uint64_t used_ns),
		   void *ud)
{
	xmutex_lock(&c->mu);
	for (size_t b = 0; b < c->nbuckets; b++)
		for (struct centry *e = c->buckets[b]; e; e = e->next)
			if (fn(ud, e->t, e->used_ns) != 0)
				goto out;
out:
	xmutex_unlock(&c->mu);
}

size_t cache_drop_node(struct cache *c, uint64_t node)
{
	struct tile **dropped = NULL;
	size_t n = 0, cap = 0;
	xmutex_lock(&c->mu);
	for (size_t b = 0; b < c->nbuckets; b++) {
		struct centry **p = &c->buckets[b];
		while (*p) {
			struct centry *e = *p;
			if (e->t->key.node != node) {
				p = &e->next;
				continue;
			}
			*p = e->next;
			c->bytes -= e->t->nbytes;
			c->ntiles--;
			if (n == cap) {
				cap = cap ? cap * 2 : 64;
				dropped = xrealloc(dropped, cap * sizeof *dropped);
			}
			dropped[n++] = e->t;
			free(e);
		}
	}
	xmutex_unlock(&c->mu);
	unref_all(dropped, n);
	return n;
}
