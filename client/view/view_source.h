/* view_source — where the viewer's tiles come from: an interface so the same frame loop runs
 * over the in-process engine (view_source_local.h: tests, `clipmapview --planet`) or over the
 * network (a daemon session). The viewer says what it wants (the full, ordered set: each call
 * replaces the previous one) and polls, without blocking, for tiles that arrived.
 *
 * Threads: want, poll, release and destroy are called from the viewer's thread only; a source
 * may produce tiles on its own threads. wait may be called from that thread to sleep until a
 * tile arrives (offline rendering only; the interactive loop never blocks).
 * Ownership: a polled tile's texels are borrowed until release(); destroy frees the source.
 */
#ifndef CLIPMAP_VIEW_SOURCE_H
#define CLIPMAP_VIEW_SOURCE_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/seagrid.h"
#include "common/pixfmt.h"

#define VIEW_MAX_LAYERS 8

enum view_class {
	VIEW_CLASS_NONE = 0,
	VIEW_CLASS_VISIBLE, /* a quad the frame shows */
	VIEW_CLASS_PREFETCH, /* the ring around a quad */
	VIEW_CLASS_AHEAD     /* beyond the ring along the motion: after every ring tile */
};

struct view_want {
	uint8_t layer; /* index into view_planet.layer */
	uint8_t cls;   /* enum view_class */
	struct tile_key key; /* key.node is ignored: the source knows each layer's node */
};

struct view_focus {
	double lon, lat, alt; /* degrees, metres above the ellipsoid */
	double vel[3];	      /* east, north, up m/s */
};

/* The planet's air and sea (docs/PLANETS.md; all zero: no air, no sea). */
struct view_look {
	double air_density;   /* haze relative to Earth's; 0: no atmosphere */
	double air_height;    /* scale height, metres */
	uint8_t air_color[3]; /* the sky's colour at the ground, sRGB */
	bool sea;
	double sea_level;     /* metres above the ellipsoid */
	bool sea_mask;	      /* the colour layer's alpha says where a sea may lie (254: dry) */
	struct sea_grid sea_grid; /* a sea on a geoid: its surface above sea_level (owned by the
				   * source, which lives longer than the view); 0 × 0: none */
};

/* What the source serves: the body, its look and the published layers. */
struct view_planet {
	char name[64];
	double a, f;
	uint32_t tile_size;
	int max_level;
	struct view_look look;
	int nlayers;
	struct {
		char name[32];
		enum pix_type format;
		int normal_of; /* a normal layer that is the plain `normal` of height layer i:
				* i + 1 (the viewer may make it itself); else 0, as zeroed */
	} layer[VIEW_MAX_LAYERS];
};

/* A tile that arrived. texels: size × size texels of `format`, row 0 north, tightly packed;
 * NULL when its generation failed (err < 0). */
struct view_tile {
	uint8_t layer;
	struct tile_key key;
	enum pix_type format;
	uint32_t size;
	const void *texels; /* borrowed until release */
	int err;
	void *handle; /* the source's */
};

struct view_source;

struct view_source_ops {
	/* Replaces the want-set (n ≤ a few thousand, priority order). Returns 0 or -errno. */
	int (*want)(struct view_source *s, const struct view_want *w, size_t n,
		    const struct view_focus *focus);
	/* 1 and *out filled when a tile arrived, 0 when none is waiting, or -errno. Never blocks. */
	int (*poll)(struct view_source *s, struct view_tile *out);
	/* Sleeps until a tile is waiting or timeout_ms passes. Returns 1, 0 (timeout) or -errno. */
	int (*wait)(struct view_source *s, int timeout_ms);
	void (*release)(struct view_source *s, struct view_tile *t);
	void (*destroy)(struct view_source *s);
};

struct view_source {
	const struct view_source_ops *ops;
	struct view_planet planet;
};

static inline void view_source_destroy(struct view_source *s)
{
	if (s)
		s->ops->destroy(s);
}

#endif
