/* cacheop — cache inspection and maintenance (CACHE_OP): stat (tiles and bytes per planet,
 * layer, level and tier), purge (a planet's tiles on disk, optionally in a bbox and a level
 * range), gc (disk entries whose node hash no planet uses) and verify (every stored value's
 * checksum; damaged ones removed). Each runs on a thread of its own — its work scales with
 * the store, never on the event loop — and builds its replies there.
 *
 * Threads: created and destroyed on the owner's thread; done(ud) runs on the op's thread, at
 * most once and never after cacheop_destroy began, only to tell the owner, which then takes
 * the replies (cacheop_replies) on its thread.
 * Ownership: cacheop_start copies what it needs of the planets (names, node hashes); the
 * cache and store are borrowed and must outlive the op (destroy joins its thread: bounded, the
 * thread checks for it between entries).
 */
#ifndef CLIPMAP_CACHEOP_H
#define CLIPMAP_CACHEOP_H
#include <stddef.h>

#include "common/proto.h"
#include "engine/cache.h"
#include "engine/planets.h"
#include "engine/store.h"

struct cacheop;

/* Starts q. Returns 0 with *out owned, or -errno with err filled (ENOENT: q names no planet
 * of ps; ENODEV: purge, gc and verify need a store). */
int cacheop_start(const struct proto_cache_op *q, const struct planet_set *ps,
		  struct cache *cache, struct store *store, void (*done)(void *ud), void *ud,
		  struct cacheop **out, char err[256]);
/* CACHE_LS the same way: the memory tier's tiles and the disk tier's entries matching q (a
 * disk entry's age is unknown: UINT32_MAX), in CACHE_ENTRIES parts. */
int cacheop_start_ls(const struct proto_cache_ls *q, const struct planet_set *ps,
		     struct cache *cache, struct store *store, void (*done)(void *ud), void *ud,
		     struct cacheop **out, char err[256]);
/* After done: the replies in order (CACHE_STAT parts, then CACHE_DONE), borrowed from op. */
size_t cacheop_replies(struct cacheop *op, const struct proto_msg **msgs);
/* Stops the thread (waits for it) and frees. NULL is a no-op. */
void cacheop_destroy(struct cacheop *op);

#endif
