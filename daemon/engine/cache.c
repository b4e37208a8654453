/* cache — see cache.h. A chained hash table (power-of-two buckets, each entry keeps its key
 * hash) under one mutex, with an LRU clock and the monotonic time stamped on lookup and insert.
 *
 * Pruning ranks every tile by what keeping it is worth (keep_worth): its cost to make again,
 * discounted by its distance (grid_quad_distance) to the nearest focus's window at the tile's
 * own level; it evicts the least worth first and, among equal worth, the least recently
 * stamped. Tiles of one cost go farthest first; with no foci and equal costs it is plain
 * LRU. The ranking runs without the mutex, on a copy of what it reads (cache_prune); each level's
 * distinct focus windows are computed once per ranking. Evicted tiles are unreferenced after
 * the mutex is released, so freeing tile memory never happens under the lock.
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
	uint64_t prunes, prune_ns, prune_hold_max_ns;
	bool pruning; /* a thread is ranking tiles for eviction (cache_prune) */
	void (*rank_hook)(void *ud); /* tests (cache_set_rank_hook) */
	void *rank_ud;
	struct cache_focus *foci;
	size_t nfoci;
	uint32_t tile_size; /* for the foci's quads; 0: each tile's own size */
};

/* A tile considered for eviction: what ranking it needs, copied under the mutex (the
 * ranking runs without it). */
struct victim {
	struct tile_key key;
	uint64_t hash;
	uint64_t stamp; /* to tell whether it was used while the ranking ran */
	float cost;	/* tile.h cost_ms */
	float keep;	/* what keeping it is worth: its cost, discounted by its distance */
	uint32_t size;	/* T */
	bool layer;
	bool lineage; /* tile.h: its node's finer tiles are built from it */
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
	c->bytes -= tile_charge(e->t);
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
static float keep_worth(float cost_ms, bool layer, uint32_t d)
{
	float c = cost_ms > COST_FLOOR_MS ? cost_ms : COST_FLOOR_MS;
	if (layer)
		c *= LAYER_WEIGHT;
	return ldexpf(c, -2 * (int)(d < 60 ? d : 60));
}

static void unref_all(struct tile **tiles, size_t n)
{
	for (size_t i = 0; i < n; i++)
		tile_unref(tiles[i]);
	free(tiles);
}

/* The foci's distinct windows per level (lx, ly), filled as the ranking meets each level:
 * 200 viewers flying over one region share most of their coarse windows. */
struct ranking {
	const struct cache_focus *foci;
	size_t nfoci;
	uint32_t T; /* the foci's tile size; 0: each tile's own */
	struct level_quads {
		uint32_t T; /* 0: not filled */
		size_t n;
		struct grid_quad *q;
	} lv[NLY][NLX];
};

static int cmp_quad(const void *pa, const void *pb)
{
	const struct grid_quad *a = pa, *b = pb;
	if (a->ty0 != b->ty0)
		return a->ty0 < b->ty0 ? -1 : 1;
	if (a->tx0 != b->tx0)
		return a->tx0 < b->tx0 ? -1 : 1;
	if (a->nty != b->nty)
		return a->nty < b->nty ? -1 : 1;
	return (a->ntx > b->ntx) - (a->ntx < b->ntx);
}

/* Distance of a tile to the nearest focus's window at its level. */
static uint32_t focus_distance(struct ranking *r, const struct victim *v)
{
	const struct tile_key *k = &v->key;
	if (k->ly >= NLY || k->lx >= NLX)
		return UINT32_MAX;
	uint32_t T = r->T ? r->T : v->size;
	struct level_quads *L = &r->lv[k->ly][k->lx];
	if (L->T != T) {
		/* first met (or, rarely, a layer of another tile size: the level's list is
		 * rebuilt for it) */
		if (!L->q)
			L->q = xmalloc(r->nfoci * sizeof *L->q);
		for (size_t f = 0; f < r->nfoci; f++)
			grid_window(k->lx, k->ly, T, GRID_WINDOW_TILES * T, r->foci[f].lon,
				    r->foci[f].lat, &L->q[f]);
		qsort(L->q, r->nfoci, sizeof *L->q, cmp_quad);
		size_t n = 0;
		for (size_t f = 0; f < r->nfoci; f++)
			if (n == 0 || cmp_quad(&L->q[n - 1], &L->q[f]) != 0)
				L->q[n++] = L->q[f];
		L->n = n;
		L->T = T;
	}
	uint32_t best = UINT32_MAX;
	for (size_t i = 0; i < L->n && best > 0; i++) {
		uint32_t d = grid_quad_distance(&L->q[i], k);
		if (d < best)
			best = d;
	}
	return best;
}

/* How far (tiles from a focus's window at their level) lineage tiles count as layer tiles.
 * A carry of level L is read by level L's tiles of its node and by level L + 1's carries,
 * whose window and ring lie inside level L's window (a finer window covers its middle half),
 * so beyond its ring a carry is the trail behind the motion. Kept at every distance they
 * took 46 % of a 1 GiB cache in a flight over the procedural planet's land (1 950 of 4 250
 * tiles, 520 of them two to five tiles out), and the terrain tiles one or two tiles out
 * went instead, each made again with its chain; within one tile, 3-12 % less worker time
 * per key at 80 km, 6000 m and 50 m (bench_keepup, 5 December). */
#define LINEAGE_REACH 1u

static int cmp_victim(const void *pa, const void *pb)
{
	const struct victim *a = pa, *b = pb;
	if (a->keep != b->keep)
		return a->keep < b->keep ? -1 : 1; /* least worth keeping first */
	if (a->stamp != b->stamp)
		return a->stamp < b->stamp ? -1 : 1; /* then least recently used */
	return 0;
}

/* Sorts v least worth keeping first (no lock: v and foci are copies). */
static void rank(struct victim *v, size_t n, const struct cache_focus *foci, size_t nf,
		 uint32_t T)
{
	struct ranking *r = xcalloc(1, sizeof *r);
	r->foci = foci;
	r->nfoci = nf;
	r->T = T;
	/* A lineage tile (a from_parent noise node's carry) is worth a layer tile within
	 * LINEAGE_REACH tiles of a focus's window at its level: each finer tile of its node below
	 * it is built from it, so one evicted there is made again for every finer tile made after
	 * (its own cost left the chain out). Farther out it is ranked at its own cost. */
	double layer_ms = 0;
	size_t nlayer = 0;
	for (size_t i = 0; i < n; i++)
		if (v[i].layer) {
			layer_ms += v[i].cost;
			nlayer++;
		}
	float lineage_ms = nlayer ? (float)(layer_ms / (double)nlayer) : 0;
	for (size_t i = 0; i < n; i++) {
		uint32_t d = nf ? focus_distance(r, &v[i]) : 0;
		bool lineage = v[i].lineage && d <= LINEAGE_REACH;
		float cost = lineage && lineage_ms > v[i].cost ? lineage_ms : v[i].cost;
		v[i].keep = keep_worth(cost, v[i].layer || lineage, d);
	}
	qsort(v, n, sizeof *v, cmp_victim);
	for (int y = 0; y < NLY; y++)
		for (int x = 0; x < NLX; x++)
			free(r->lv[y][x].q);
	free(r);
}

/* Evicts until at most target bytes remain, least worth keeping first. The mutex is held
 * only to copy what the ranking needs and then to evict: with a 1 GiB cache of 256² tiles
 * and 200 viewers' foci, ranking under it held it for up to 104 ms, and the event loop,
 * which looks tiles up, waited that long (attack.py moving, loop.over_50ms.blocked). A tile
 * used while the ranking ran is kept (its stamp moved); one more round ranks what is left
 * if that leaves the cache over target. One thread ranks at a time: another that finds a
 * ranking under way leaves the pruning to it (its rounds continue until the target holds).
 * Called without the mutex; frees the evicted tiles' references without it too. */
void cache_prune(struct cache *c, size_t target)
{
	for (int round = 0; round < 8; round++) {
		xmutex_lock(&c->mu);
		if (c->bytes <= target || c->pruning) {
			xmutex_unlock(&c->mu);
			return;
		}
		uint64_t t0 = clock_now_ns();
		c->pruning = true;
		size_t n = 0, nf = c->nfoci;
		struct victim *v = xmalloc((c->ntiles ? c->ntiles : 1) * sizeof *v);
		struct cache_focus *foci = nf ? xmalloc(nf * sizeof *foci) : NULL;
		if (nf)
			memcpy(foci, c->foci, nf * sizeof *foci);
		uint32_t T = c->tile_size;
		void (*hook)(void *) = c->rank_hook;
		void *hook_ud = c->rank_ud;
		for (size_t b = 0; b < c->nbuckets; b++)
			for (struct centry *e = c->buckets[b]; e; e = e->next)
				v[n++] = (struct victim){ .key = e->t->key, .hash = e->hash,
							  .stamp = e->stamp, .cost = e->t->cost_ms,
							  .size = e->t->size, .layer = e->t->layer,
							  .lineage = e->t->lineage };
		uint64_t hold = clock_now_ns() - t0;
		xmutex_unlock(&c->mu);

		rank(v, n, foci, nf, T);
		free(foci);
		if (hook)
			hook(hook_ud);

		struct tile **tiles = xmalloc((n ? n : 1) * sizeof *tiles);
		size_t m = 0;
		xmutex_lock(&c->mu);
		uint64_t t1 = clock_now_ns();
		for (size_t i = 0; i < n && c->bytes > target; i++) {
			struct centry *e = find(c, &v[i].key, v[i].hash);
			if (!e || e->stamp != v[i].stamp)
				continue; /* gone, or used meanwhile */
			unlink_entry(c, e);
			tiles[m++] = e->t;
			free(e);
			c->evictions++;
		}
		uint64_t t2 = clock_now_ns();
		hold = hold > t2 - t1 ? hold : t2 - t1;
		c->pruning = false;
		c->prunes++;
		c->prune_ns += t2 - t0;
		if (hold > c->prune_hold_max_ns)
			c->prune_hold_max_ns = hold;
		bool again = c->bytes > target;
		xmutex_unlock(&c->mu);
		free(v);
		unref_all(tiles, m);
		if (!again)
			return;
	}
}

static void insert(struct cache *c, struct tile *t, bool cold)
{
	uint64_t h = grid_key_hash(&t->key);
	bool over = false;
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
		c->bytes += tile_charge(t);
		c->ntiles++;
		c->inserts++;
		if (c->ntiles > c->nbuckets)
			grow(c);
		over = c->budget && c->bytes > c->budget && !c->pruning;
	}
	xmutex_unlock(&c->mu);
	/* Prune to 90 % so the next few inserts do not each pay for a full ranking. */
	if (over)
		cache_prune(c, c->budget - c->budget / 10);
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

void cache_set_rank_hook(struct cache *c, void (*fn)(void *ud), void *ud)
{
	xmutex_lock(&c->mu);
	c->rank_hook = fn;
	c->rank_ud = ud;
	xmutex_unlock(&c->mu);
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
	out->prunes = c->prunes;
	out->prune_ns = c->prune_ns;
	out->prune_hold_max_ns = c->prune_hold_max_ns;
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
			c->bytes -= tile_charge(e->t);
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
