/* cache — the tile cache (seed 003 §4.2): key → immutable, reference-counted tile, one mutex
 * for the whole cache, a byte budget, and pruning by distance to the viewers' focus points:
 * each level's quad and the ring around it are kept while farther tiles go first (seed 003
 * Fig. 3a); among equally far tiles the least recently used goes first. Distance is weighed
 * against what a tile cost (tile.h cost_ms, layer): intermediate tiles that are cheap to
 * make again go before the layer tiles viewers ask for (cache.c keep_worth), since a rich
 * planet makes ~30 intermediate tiles per layer tile and a fast flight's windows and rings
 * hold more of them than the budget. Lineage tiles (a from_parent noise node's carries, from
 * which every finer tile of the node is built) are kept as layer tiles, at no less than the
 * cached layer tiles' mean cost, within one tile of a focus's window at their level (their
 * finer consumers' windows lie inside it); farther out, at their own cost.
 *
 * Each entry remembers when it was last used (monotonic time), which listings report as age.
 *
 * Threads: every function is thread-safe. The mutex protects the table, the LRU clock and the
 * counters; no tile data is touched under it and nothing blocks while it is held.
 * Ownership: the cache holds one reference per cached tile; lookups return a new reference.
 */
#ifndef CLIPMAP_CACHE_H
#define CLIPMAP_CACHE_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/clock.h"
#include "common/grid.h"
#include "tile.h"

struct cache;

struct cache_focus {
	double lon, lat; /* degrees */
};

struct cache_stats {
	uint64_t hits, misses, inserts, evictions;
	size_t bytes, tiles, budget;
	uint64_t prunes;	   /* rankings for eviction */
	uint64_t prune_ns;	   /* their time, all together */
	uint64_t prune_hold_max_ns; /* the longest the mutex was held by one of them */
};

/* A cache holding at most budget_bytes of tile data (0: unlimited). */
struct cache *cache_create(size_t budget_bytes);
void cache_destroy(struct cache *c);
/* A new reference to the cached tile, or NULL. Counts a hit or a miss. */
struct tile *cache_lookup(struct cache *c, const struct tile_key *k);
/* Whether k is cached, without counting or touching recency. */
bool cache_contains(struct cache *c, const struct tile_key *k);
/* Publishes t (the cache takes its own reference; the caller keeps theirs). If k is already
 * cached the old tile stays. Prunes when over budget. */
void cache_insert(struct cache *c, struct tile *t);
/* As cache_insert, but a new entry is stamped least recently used (an entry already there
 * keeps its stamp): among tiles as far from every focus it is evicted first. For bulk work
 * (prefetch) that must not push out what viewers use. */
void cache_insert_cold(struct cache *c, struct tile *t);
/* Replaces the focus points pruning measures distance to (copied). */
void cache_set_foci(struct cache *c, const struct cache_focus *foci, size_t n, uint32_t tile_size);
/* Evicts until at most `target` bytes remain (least worth keeping first, then least recent).
 * Returns at once when another thread is pruning (that thread goes on until its own target
 * holds). The mutex is held only to copy what the ranking reads and to evict, never while
 * ranking. */
void cache_prune(struct cache *c, size_t target);
void cache_stats(struct cache *c, struct cache_stats *out);
/* Tests: fn(ud) is called by each ranking for eviction, on the pruning thread, after the copy
 * and before the evictions, without the mutex (NULL: none). */
void cache_set_rank_hook(struct cache *c, void (*fn)(void *ud), void *ud);
/* Calls fn for each cached tile with the time of its last use (the last lookup or insert, as
 * a clock_now_ns time, common/clock.h), under the lock: fn must be quick and must not call the
 * cache. Stops early when fn returns non-zero. */
void cache_foreach(struct cache *c, int (*fn)(void *ud, const struct tile *t, uint64_t used_ns),
		   void *ud);
/* Temporary alias for daemon/session.c until it calls clock_now_ns itself; remove then. */
static inline uint64_t cache_now_ns(void)
{
	return clock_now_ns();
}
/* Drops every tile whose key.node equals node. Returns how many. */
size_t cache_drop_node(struct cache *c, uint64_t node);

#endif
