/* wantset — one session's want-set: the tiles it asked for, keyed by tile key (open
 * addressing), each WANTED (asked of the scheduler), READY (generated, waiting for output
 * room; held in a heap ordered by class, then level coarse first, then want order) or SENT.
 * A WANT replaces one planet's part of the set, carrying the state of keys that stay; a reload
 * rebinds every entry to its layer's new node. Pure bookkeeping: no sockets, no scheduler.
 *
 * Held tiles are budgeted: a READY entry keeps its tile only while the set's tiles total at
 * most the budget given to wantset_ready; beyond it the entry is READY without a tile
 * ("parked": t NULL, err 0) and the owner looks it up again (cache) when it comes off the heap,
 * or wants it afresh (wantset_rewant). Order and replacement work the same for both.
 *
 * Threads: one owner thread. Ownership: the set owns its READY entries' tile references and
 * borrows their nodes (the owner keeps the planets alive).
 */
#ifndef CLIPMAP_WANTSET_H
#define CLIPMAP_WANTSET_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "engine/sched.h"
#include "engine/tile.h"

enum wantset_state { WS_WANTED = 0, WS_READY, WS_SENT };

struct wantset_entry {
	struct tile_key key;
	struct node *node; /* borrowed */
	struct tile *t;	   /* WS_READY: owned reference (NULL when err < 0, or parked) */
	int err;
	uint32_t pid, seq, order; /* planet id, the WANT's seq, the position in it */
	uint8_t layer, cls, state;
};

struct wantset {
	struct wantset_entry *e;
	size_t n, cap;
	uint32_t *tab; /* open addressing: index + 1, 0 empty */
	size_t tcap;   /* power of two */
	uint32_t *heap; /* READY entries' indices, by wantset_prio */
	size_t nheap, capheap;
	uint64_t held; /* bytes of the tiles READY entries hold */
	size_t parked; /* READY entries parked (their tile not carried) */
};

/* What a replace or rebind let go: entries that left unsent (`dropped`) and generated tiles
 * thrown away unsent because the key left or its node changed (`stale`). */
struct wantset_drops {
	uint64_t dropped, stale;
};

void wantset_init(struct wantset *ws);
/* Releases the READY tiles and the storage. */
void wantset_fini(struct wantset *ws);
/* The index of key's entry, or -1. */
long wantset_find(const struct wantset *ws, const struct tile_key *k);
/* Makes add[0..n) (planet pid's entries in want order; state, t and err ignored) the planet's
 * part of the set. Entries of other planets stay as they are; a key that stays keeps its
 * state (a sent tile is not sent again, a ready one stays ready); a duplicate key in add
 * counts once (the first). Rebuilds the ready heap. */
void wantset_replace(struct wantset *ws, uint32_t pid, const struct wantset_entry *add,
		     size_t n, struct wantset_drops *d);
/* The node layer `layer` of planet `pid` now reads from, or NULL when the planet is gone. */
typedef struct node *wantset_resolve_fn(void *ud, uint32_t pid, uint8_t layer);
/* Rebinds every entry to resolve's node: a key whose node hash did not change keeps its state,
 * a changed one is wanted afresh under its new key, entries of gone planets (and keys that
 * now collide) leave. Rebuilds the ready heap. Returns how many are wanted afresh. */
size_t wantset_rebind(struct wantset *ws, wantset_resolve_fn *resolve, void *ud,
		      struct wantset_drops *d);
/* A tile's raw bytes for entry e (its node's format and tile size). */
uint64_t wantset_entry_bytes(const struct wantset_entry *e);
/* The first WANTED entries in the order the scheduler serves them (class, then level coarse
 * first, then want order) whose bytes, with those of the READY entries not yet sent (held or
 * parked), stay within `credit`: what a session asks to be made while its earlier tiles wait
 * for output room. At least one when nothing is READY. Beyond the credit, entries for which
 * `made` (may be NULL) says the tile exists already (the cache holds it: nothing to make)
 * come too. *n the count, *left whether WANTED entries were left out. An owned array (free
 * it). */
typedef bool wantset_made_fn(void *ud, const struct tile_key *k);
struct want *wantset_wants_within(const struct wantset *ws, uint64_t credit, wantset_made_fn *made,
				  void *ud, size_t *n, bool *left);
/* A tile for key is ready (t taken, NULL with err < 0, or NULL with `park`: ready but its
 * tile not carried). Returns false, releasing t, when the key is not waiting for one (it left
 * the set, or a repeated report). When holding t would take the held bytes over `budget` (and
 * some are held already), or with `park`, the entry is parked: t is released and *parked
 * set. */
bool wantset_ready(struct wantset *ws, const struct tile_key *k, struct tile *t, int err,
		   bool park, uint64_t budget, bool *parked);
/* Whether a popped entry is parked (READY without its tile: look it up again). */
static inline bool wantset_parked(const struct wantset_entry *e)
{
	return e->state == WS_READY && !e->t && e->err == 0;
}
/* How many READY entries are parked. */
static inline size_t wantset_nparked(const struct wantset *ws)
{
	return ws->parked;
}
/* Gives a popped parked entry its tile back (t taken). */
void wantset_unpark(struct wantset *ws, struct wantset_entry *e, struct tile *t);
/* Makes a popped entry WANTED again (its tile is to be asked of the scheduler again). */
void wantset_rewant(struct wantset *ws, struct wantset_entry *e);
/* Bytes of tiles held by READY entries. */
static inline uint64_t wantset_held(const struct wantset *ws)
{
	return ws->held;
}
/* How many entries wait in the ready heap. */
size_t wantset_nready(const struct wantset *ws);
/* Takes the first READY entry off the heap (the caller sends it, then wantset_sent); NULL when
 * the heap holds none. */
struct wantset_entry *wantset_pop(struct wantset *ws);
/* Marks e (popped) SENT and releases its tile. */
void wantset_sent(struct wantset *ws, struct wantset_entry *e);

#endif
