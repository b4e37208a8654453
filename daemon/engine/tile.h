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
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"

/* What a node produces. 0 is invalid so a zeroed struct is "unset". */
enum pix_type {
	PIX_NONE = 0,
	PIX_HEIGHT, /* float32 metres above the body's ellipsoid */
	PIX_COLOR,  /* RGBA8, sRGB, straight (not premultiplied) alpha */
	PIX_NORMAL, /* RG8: east and north components of the unit normal in the local tangent
		     * frame, each mapped [-1, 1] → [0, 255] as round((c + 1) · 127.5); up = sqrt(1-e²-n²) */
};

size_t pix_bytes(enum pix_type t);	      /* bytes per texel: 4, 4, 2 */
const char *pix_type_name(enum pix_type t);   /* "height", "color", "normal" */
enum pix_type pix_type_parse(const char *s);  /* PIX_NONE when unknown */
const char *pix_format_name(enum pix_type t); /* wire/layer format: "f32", "rgba8", "rg8" */

struct tile {
	atomic_int refs;
	enum pix_type type;
	uint32_t size; /* T */
	struct tile_key key;
	size_t nbytes; /* size · size · pix_bytes(type) */
	unsigned char *data;
};

/* A new tile with uninitialised data; returns one owned reference (aborts on ENOMEM). */
struct tile *tile_create(const struct tile_key *key, enum pix_type type, uint32_t size);
/* Adds a reference and returns t. */
struct tile *tile_ref(struct tile *t);
/* Drops a reference; NULL is a no-op. */
void tile_unref(struct tile *t);

static inline float *tile_f32(const struct tile *t) { return (float *)(void *)t->data; }

#endif
