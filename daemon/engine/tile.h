/* tile — an immutable, reference-counted block of T×T texels, the unit of generation, caching
 * and transfer. Row 0 is the north edge (see grid.h). Data is 64-byte aligned and tightly
 * packed (stride = T · pix_bytes(type)).
 *
 * Ownership: tile_create returns one owned reference; tile_ref adds one; tile_unref drops one
 * and frees at zero. Once published (handed to the cache or to another thread) a tile's data
 * must not change. Reference counts are atomic: any thread may ref/unref.
 */
#ifndef CLIPMAP_TILE_H
#define CLIPMAP_TILE_H
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/pixfmt.h"

struct tile {
	atomic_int refs;
	enum pix_type type;
	uint32_t size; /* T */
	struct tile_key key;
	size_t nbytes; /* size · size · pix_bytes(type) */
	unsigned char *data;
	/* What making it again would cost, ms of a worker: its own generation and, once per
	 * input node, that input's cost (its parent and neighbours in its own node left out,
	 * so the figure stays the chain's, not the level's). 0 when unknown (a loaded tile).
	 * Set once before the tile is shared; the cache evicts cheap tiles first (cache.h). */
	float cost_ms;
	bool layer; /* a planet layer's tile (what viewers ask for), not an intermediate one */
	/* Set by generate(): its node's lazy inputs were not needed for it (a blend's mask 0 on
	 * the whole tile), whether they were made or not; the scheduler's guess for its children
	 * (jobtab's skip memory). */
	bool lazy_unneeded;
};

/* A new tile with uninitialised data; returns one owned reference (aborts on ENOMEM). */
struct tile *tile_create(const struct tile_key *key, enum pix_type type, uint32_t size);
/* Adds a reference and returns t. */
struct tile *tile_ref(struct tile *t);
/* Drops a reference; NULL is a no-op. */
void tile_unref(struct tile *t);

static inline float *tile_f32(const struct tile *t) { return (float *)(void *)t->data; }

#endif
