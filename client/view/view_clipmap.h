/* view_clipmap — the viewer's clipmap textures and the tiles in flight. Per layer role
 * (height R32F, normal RG8, colour sRGB8_A8) one 2D texture array with a slice per clipmap
 * level, S × S texels (S = CLIPMAP_WINDOW_TILES · T), addressed toroidally: level texel (u, v)
 * lives at (u mod S, v mod S); a level narrower than S repeats across it. Each level has a
 * target window (grid_window: where the camera wants it) and the window its texture holds;
 * when every tile of the target has arrived, only the changed regions are copied
 * (grid_update_regions); before that, the window's core once its tiles are in. Tiles are
 * kept while they are in or next to their level's target window (the prefetch ring) or ahead
 * of it along the camera's motion (view_clipmap_motion), released otherwise: the
 * client never holds more than that.
 *
 * Threads: one thread (the GL context's). Ownership: the clipmap borrows gl and the source,
 * owns its textures and the tiles it holds (released through the source).
 */
#ifndef CLIPMAP_VIEW_CLIPMAP_H
#define CLIPMAP_VIEW_CLIPMAP_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "gl_context.h"
#include "view_source.h"

enum view_role { VIEW_HEIGHT = 0, VIEW_NORMAL, VIEW_COLOR, VIEW_NROLES };

struct view_clipmap_stats {
	uint64_t bytes_uploaded;  /* texel bytes sent with glTexSubImage3D */
	uint64_t regions_uploaded;
	uint64_t tiles_received;
	uint64_t tiles_dropped;	  /* arrived but no longer needed */
	uint64_t tiles_failed;
	size_t tiles_held;
	uint64_t normals_derived; /* normal texels made from the heights (derive) */
	uint64_t derive_ns;	  /* CPU time that took */
};

struct view_clipmap;

/* Textures for nlevels levels of the source's planet (roles found by layer name, else by
 * format; a height layer is required). Returns 0 or -errno with err filled. */
int view_clipmap_create(const struct gl *gl, struct view_source *src, int nlevels,
			struct view_clipmap **out, char err[256]);
/* The same with the colour layer named (NULL: as view_clipmap_create); a planet without a
 * colour layer of that name is refused. normals false: the normal layer is never asked for;
 * the normal slices are made from the height mirror when heights are uploaded, with the
 * `normal` node's arithmetic (common/normalmap.h): the node's bytes except on the window's
 * outermost texels, whose stencils are cut to the window. */
int view_clipmap_create_layer(const struct gl *gl, struct view_source *src, int nlevels,
			      const char *color_layer, bool normals, struct view_clipmap **out,
			      char err[256]);
void view_clipmap_destroy(struct view_clipmap *cm);
/* Whether normals made from p's height layer are what its normal layer holds (the planet
 * says so: view_planet.layer[].normal_of), or it has no normal layer: then deriving them
 * (normals false above) draws what fetching would, or better than flat. */
bool view_clipmap_can_derive(const struct view_planet *p);

/* Sets level's target quad (NULL: the level is not wanted). Tiles farther than the ring
 * around the new quad are released. Returns whether the target changed. */
bool view_clipmap_target(struct view_clipmap *cm, int level, const struct grid_quad *q);
/* The camera's ground position (degrees) at time t (seconds, any monotonic origin), once per
 * frame after the targets are set: its smoothed velocity sets each level's look-ahead, the
 * lines of tiles beyond the ring that the camera reaches within ~0.15 s (up to 2 lines per
 * axis; none on levels it crosses slowly; no rows where the level will use another lx by the
 * time its window reaches them, as near a pole: clipmap_level_lx). Returns whether a look-ahead changed — the want-set
 * must then be sent again. Tiles that fall out of the look-ahead are released. Optional: a
 * caller that never calls it gets no look-ahead. */
bool view_clipmap_motion(struct view_clipmap *cm, double lon, double lat, double t);
/* Forgets the camera's motion (it jumped: the step is no velocity); the next
 * view_clipmap_motion starts from rest. */
void view_clipmap_motion_reset(struct view_clipmap *cm);

/* The want-set for the current targets: every missing tile of every target quad, coarse
 * levels first, each window from its middle out with a tile's layers together (the cores
 * view_clipmap_update draws first arrive first), then (prefetch) the missing ring tiles —
 * while the camera moves (view_clipmap_motion) only those on the side it moves to — then the
 * missing look-ahead tiles
 * (class VIEW_CLASS_AHEAD, at most 96). Returns the count (≤ cap). */
size_t view_clipmap_wants(const struct view_clipmap *cm, bool prefetch, struct view_want *out,
			  size_t cap);
/* Takes the tiles the source has ready: the first VIEW_RECEIVE_MIN of them whatever the time
 * (a level's quad of a layer: a frame whose first tile was slow to decode still takes the
 * tiles that came with it), then until clock_now_ms() reaches until_ms (0: every one). A
 * source that delivers faster than they are taken (a daemon with a burst ready, over a fast
 * link) would otherwise keep a frame in here for as long as the burst lasts: 0.1-1.2 s were
 * measured (bench_keepup). What is left waits in the socket for the next call. Returns how
 * many arrived, or -errno. */
#define VIEW_RECEIVE_MIN 16
/* How long a real-time frame takes tiles before it plans and draws (view.c, and bench_keepup's
 * headless frame): a 256² tile costs ~30 µs from a Unix socket, ~0.3 ms with zstd over TCP
 * (bench_codec), so 13-130 tiles. */
#define VIEW_RECEIVE_MS 4.0
int view_clipmap_receive(struct view_clipmap *cm, double until_ms);
/* If level's target quad is complete, copies the changed regions into the textures. Else,
 * where the tiles of its core are in (grid_window_core: the middle half of the window, else
 * the middle quarter) and that core reaches farther round the window's middle than what the
 * texture holds, copies the core: the level can be drawn from it (a ring needs only the
 * middle of its level's window) before the rest arrives; view_clipmap_held says what is held.
 * Returns 1 when the texture holds the target quad, 0 when tiles are missing. */
int view_clipmap_update(struct view_clipmap *cm, int level);
/* The quad level's texture holds, or NULL (nothing uploaded yet). */
const struct grid_quad *view_clipmap_held(const struct view_clipmap *cm, int level);
const struct grid_quad *view_clipmap_target_of(const struct view_clipmap *cm, int level);
/* The ground height at (lon, lat) from the finest level that holds it. 0 or -ENOENT. */
int view_clipmap_ground(const struct view_clipmap *cm, double lon, double lat, double *h);
/* Keep a CPU copy of the colour's alpha (a planet whose sea_mask is in it) for
 * view_clipmap_alpha. Off by default. */
void view_clipmap_keep_alpha(struct view_clipmap *cm, bool on);
/* The colour's alpha (0..1) at (lon, lat) from the finest level holding it, bilinear. Returns 0,
 * or -ENOENT where no level holds it (or view_clipmap_keep_alpha is off). */
int view_clipmap_alpha(const struct view_clipmap *cm, double lon, double lat, double *a);

/* The range of the heights a level's height slice holds (metres, not exaggerated): what the
 * shader can sample there, for culling. 0, or -ENOENT before the level's first upload. */
int view_clipmap_height_range(struct view_clipmap *cm, int level, double *lo, double *hi);
/* The same over what the shader can sample for points within angle r of (lon, lat) (a ring's
 * disk): tighter culling bounds than the whole slice's. Falls back to the whole slice where
 * the disk holds a pole or leaves the window. The last two disks per level are remembered
 * until the slice changes. 0, or -ENOENT before the level's first upload. */
int view_clipmap_height_range_near(struct view_clipmap *cm, int level, double lon, double lat,
				   double r, double *lo, double *hi);
/* The same over what the shader can sample at texel coordinates [x0, x1] × [y0, y1] of the
 * level (view_level_params' units: u may leave 0..S, it wraps; v clamped by the caller). */
int view_clipmap_height_range_box(struct view_clipmap *cm, int level, double x0, double x1,
				  double y0, double y1, double *lo, double *hi);

/* Colour layer switches. The colour role draws one layer of the planet at a time;
 * view_clipmap_set_color switches it to layer (an index into the source's planet, a colour
 * layer): the old layer's tiles are released, the want-set asks for the new layer's (coarse
 * levels first), and each held level keeps drawing its old colour until every colour tile of
 * its target has arrived, then its whole colour slice is replaced at once — a slice never
 * mixes two layers. Heights and normals stay. Returns 1 (switched), 0 (already drawn) or
 * -EINVAL (not a colour layer, or the planet has none). */
int view_clipmap_set_color(struct view_clipmap *cm, int layer);
/* The colour layer drawn (index into the planet), -1 without one. */
int view_clipmap_color_layer(const struct view_clipmap *cm);
/* The index of the planet's colour layer called name, or -1. */
int view_clipmap_color_find(const struct view_clipmap *cm, const char *name);
/* Whether level's colour slice still holds a layer drawn before the last switch. */
bool view_clipmap_color_stale(const struct view_clipmap *cm, int level);

unsigned view_clipmap_texture(const struct view_clipmap *cm, enum view_role r); /* 0: absent */
/* Reads every slice of a role's texture (S × S × nlevels texels, slice-major) into out.
 * Returns 0 or -ENOENT. */
int view_clipmap_read(const struct view_clipmap *cm, enum view_role r, void *out, size_t size);
uint32_t view_clipmap_tile_size(const struct view_clipmap *cm);
uint32_t view_clipmap_window_size(const struct view_clipmap *cm); /* S */
/* Changes whenever a level's heights (its slice's mirror) change. */
uint64_t view_clipmap_height_version(const struct view_clipmap *cm, int level);
int view_clipmap_levels(const struct view_clipmap *cm);
void view_clipmap_get_stats(const struct view_clipmap *cm, struct view_clipmap_stats *out);

#endif
