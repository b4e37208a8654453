/* synth_source — a synthetic view_source for the viewer's tests: an in-process "planet" whose
 * tiles are computed from their key by a callback the test supplies, delivered as soon as
 * they are wanted (poll hands them out in want-set order; wait never sleeps).
 *
 * Single-threaded. The source owns its want list and the tiles' buffers until release;
 * view_source_destroy frees it. The callback's ctx stays the caller's.
 */
#ifndef CLIPMAP_SYNTH_SOURCE_H
#define CLIPMAP_SYNTH_SOURCE_H
#include <stddef.h>
#include <stdint.h>

#include "client/view/view_source.h"

/* Fills one tile (T×T texels of format f, tightly packed) for want w. */
typedef void (*synth_fill_fn)(void *ctx, const struct view_want *w, uint32_t T, enum pix_type f,
			      void *data);

/* A WGS84-size planet "synth" with tile size T, levels 0..max_level and the given layers
 * (names and formats, nlayers ≤ VIEW_MAX_LAYERS). fill NULL: every texel zero. */
struct view_source *synth_source_create(uint32_t T, int max_level, int nlayers,
					const char *const names[], const enum pix_type formats[],
					synth_fill_fn fill, void *ctx);
/* How many want-sets it received. */
size_t synth_source_wants(const struct view_source *vs);

#endif
