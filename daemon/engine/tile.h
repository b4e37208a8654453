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
	/* The tile whose bytes data points into (tile_alias, tile_fill_uniform), one reference
	 * held; NULL when data is this tile's own buffer. */
	struct tile *base;
	bool uniform; /* base is a shared uniform buffer (tile_fill_uniform): no memory of its own */
	/* Heights only, when summarized: the least and greatest texel (NaN left out; lo > hi when
	 * every texel is NaN) and whether any texel is NaN. Set before the tile is shared, by
	 * the worker (tile_summarize) or by a node that knows them for free; readers that find
	 * it unset scan the texels instead. */
	bool summarized, any_nan;
	float lo, hi;
	/* What making it again would cost, ms of a worker: its own generation and, once per
	 * input node, that input's cost (its parent and neighbours in its own node left out,
	 * so the figure stays the chain's, not the level's). 0 when unknown (a loaded tile).
	 * Set once before the tile is shared; the cache evicts cheap tiles first (cache.h). */
	float cost_ms;
	bool layer; /* a planet layer's tile (what viewers ask for), not an intermediate one */
	bool lineage; /* its node's finer tiles are built from it (node_type.lineage) */
	/* Set by generate(): its node's lazy inputs were not needed for it (a blend's mask 0 on
	 * the whole tile), whether they were made or not; the scheduler's guess for its children
	 * (jobtab's skip memory). */
	bool lazy_unneeded;
};

/* A new tile with uninitialised data; returns one owned reference (aborts on ENOMEM). */
struct tile *tile_create(const struct tile_key *key, enum pix_type type, uint32_t size);
/* Makes t's texels src's (same type and size; t not yet shared): t's own buffer goes back
 * and t holds a reference to the tile owning src's bytes, so a node whose output equals an
 * input byte for byte writes nothing. Copies src's summary. */
void tile_alias(struct tile *t, struct tile *src);
/* Makes every texel of t (not yet shared) the pix_bytes(t->type) bytes at texel, on a
 * process-wide buffer shared by every tile of that type, size and value (a few dozen values
 * at most; beyond them t's own buffer is filled). Sets the summary of a height tile. */
void tile_fill_uniform(struct tile *t, const void *texel);
/* A height tile (not yet shared) whose texels all hold one value, bit for bit, moves onto
 * the shared uniform buffer of that value (as tile_fill_uniform, summary set) and returns
 * true: it costs the cache nothing and the nodes reading it can tell (a filter or blend of
 * uniform inputs writes nothing). Otherwise, or when the registry of shared values is full,
 * t is left as it was: false. The scan leaves at the first 64 texels that differ. */
bool tile_share_if_uniform(struct tile *t);
/* The bytes t holds memory for, as the cache counts them: none on a shared uniform buffer.
 * (An alias of another tile counts its full size: the bytes it keeps alive once that tile
 * has gone.) */
static inline size_t tile_charge(const struct tile *t) { return t->uniform ? 0 : t->nbytes; }
/* Scans a height tile (not yet shared) for its summary; other types are left unsummarized. */
void tile_summarize(struct tile *t);
/* Sets a height tile's summary from 16 lanes, as tile_summarize reduces them for a tile of a
 * multiple of 16 texels: lane k the least and greatest of the texels i ≡ k (mod 16), each
 * kept as v < lo ? v : lo and v > hi ? v : hi from ±∞ (so NaN is left out), and whether any
 * texel is NaN. A kernel that writes the texels can keep the lanes as it goes and save the
 * scan; the summary is tile_summarize's to the bit. */
void tile_summary_from_lanes(struct tile *t, const float lo[16], const float hi[16], bool nan);
/* Adds a reference and returns t. */
struct tile *tile_ref(struct tile *t);
/* Drops a reference; NULL is a no-op. */
void tile_unref(struct tile *t);

static inline float *tile_f32(const struct tile *t) { return (float *)(void *)t->data; }

#endif
