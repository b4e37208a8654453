/* grid — the one definition of the tile grid, shared by daemon and client (DESIGN.md).
 *
 * Map space is plate carrée: longitude [-180, 180), latitude [-90, 90]. A level (lx, ly) has
 * 2^lx tiles across longitude and 2^ly down latitude; lx = ly + 1 is isotropic, lx < ly + 1 is
 * the anisotropic grid spherical clipmaps use near the poles. Tiles are T×T texels.
 *
 * Orientation (everywhere: tiles, images, textures): tile x = 0 starts at -180° and grows east;
 * tile y = 0 touches the north pole and grows south. Inside a tile, column i grows east and
 * row j grows south, so row 0 is the north edge — the order images are stored in.
 * "Level texels" (u, v) count texels across the whole level: u = x·T + i, v = y·T + j.
 * Texels are areas: texel (u, v) covers [u, u+1) × [v, v+1) and its centre is at +0.5.
 * x wraps around the antimeridian; y does not wrap.
 *
 * A window (seed 003 §5.1's quad, grown) is the S×S texels centred on a focus point, S a
 * power-of-two multiple of T: S = T is the quad, touching up to 2×2 tiles; the viewer's clipmap
 * uses S = GRID_WINDOW_TILES·T (up to 5×5 tiles). Where a level is narrower or shorter than S
 * the window is the whole level along that axis. The window lives in an S×S toroidal texture
 * where level texel (u, v) is stored at (u mod S, v mod S). Because S is a multiple of T, the
 * texture's wrap lines lie on tile borders, so each update region copies from one tile.
 *
 * Pure functions, no state: thread-safe.
 */
#ifndef CLIPMAP_GRID_H
#define CLIPMAP_GRID_H
#include <stdbool.h>
#include <stdint.h>

#define GRID_MAX_LEVEL 30

/* A tile: which node's output (its content hash) and where. */
struct tile_key {
	uint64_t node; /* content hash of the producing node (0 where not yet known) */
	uint32_t x, y;
	uint8_t lx, ly;
};

struct geo_rect {
	double west, south, east, north; /* degrees; east may equal 180 */
};

/* Levels: 0 ≤ ly ≤ GRID_MAX_LEVEL, 0 ≤ lx ≤ ly + 1 (and ≤ GRID_MAX_LEVEL). */
bool grid_level_valid(int lx, int ly);
bool grid_key_valid(const struct tile_key *k);
static inline uint32_t grid_tiles_x(int lx) { return (uint32_t)1 << lx; }
static inline uint32_t grid_tiles_y(int ly) { return (uint32_t)1 << ly; }
/* x modulo the number of tiles across (negative x wraps too). */
uint32_t grid_wrap_x(int lx, int64_t x);
bool grid_key_equal(const struct tile_key *a, const struct tile_key *b);
/* A well-mixed 64-bit hash of a key, for hash tables. */
uint64_t grid_key_hash(const struct tile_key *k);

/* The tile's area in degrees. */
void grid_tile_rect(const struct tile_key *k, struct geo_rect *r);
/* Level texel coordinate (edges at integers, centres at +0.5) ↔ degrees. */
double grid_u_to_lon(int lx, uint32_t T, double u);
double grid_v_to_lat(int ly, uint32_t T, double v);
/* |latitude| of the point of the band between latitudes a and b (either order, degrees)
 * nearest the equator: 0 for a band across it. Where a band's texels are widest. */
double grid_band_equator_lat(double a, double b);
double grid_lon_to_u(int lx, uint32_t T, double lon);
double grid_lat_to_v(int ly, uint32_t T, double lat);
/* Centre of texel (i, j) of a tile, in degrees. */
void grid_texel_center(const struct tile_key *k, uint32_t T, uint32_t i, uint32_t j, double *lon,
		       double *lat);

/* The tile one level coarser by (dlx, dly) ∈ {(1,1), (1,0), (0,1)} that contains k, and where
 * k's area sits inside it: texels [off_x, off_x + w) × [off_y, off_y + h) of the parent, where
 * w = T/2 if dlx else T, h = T/2 if dly else T. Returns 0 or -EINVAL (no such level). */
int grid_parent(const struct tile_key *k, int dlx, int dly, uint32_t T, struct tile_key *parent,
		uint32_t *off_x, uint32_t *off_y);
/* The tiles one level finer by (dlx, dly) under k, west→east then north→south.
 * Returns how many (4 or 2), or -EINVAL. */
int grid_children(const struct tile_key *k, int dlx, int dly, struct tile_key out[4]);
/* Neighbour (dx, dy) ∈ [-1,1]² of k. x wraps. Across a pole the neighbour is the tile on the
 * other side of the pole (x + half the tiles across, same y) and *flip is set: its rows run
 * the other way. Returns 0. */
int grid_neighbor(const struct tile_key *k, int dx, int dy, struct tile_key *out, bool *flip);

/* The clipmap window of the viewer, in tiles per side: S = GRID_WINDOW_TILES·T texels. The
 * daemon's cache ranks tiles by their distance to this window around each viewer's focus. */
#define GRID_WINDOW_TILES 4
#define GRID_WINDOW_MAX_TILES 8 /* S/T at most */
/* Tiles a window touches, regions an update copies: at most. */
#define GRID_WINDOW_MAX_KEYS ((GRID_WINDOW_MAX_TILES + 1) * (GRID_WINDOW_MAX_TILES + 1))
#define GRID_MAX_REGIONS ((GRID_WINDOW_MAX_TILES + 3) * (GRID_WINDOW_MAX_TILES + 3))

struct grid_quad {
	uint8_t lx, ly;
	uint32_t T, S;	   /* tile size; window size (T · a power of two ≤ GRID_WINDOW_MAX_TILES) */
	int64_t u0, v0;	   /* window origin in level texels: u0 ∈ [0, W), v0 ∈ [0, H - h] */
	uint32_t w, h;	   /* the window's extent: S, or the level's width/height if smaller */
	uint32_t tx0, ty0; /* the first tile the window touches (x wraps) */
	uint8_t ntx, nty;  /* how many it touches per axis */
};

/* The quad: the T×T window centred on (lon, lat) at level (lx, ly) with tile size T. */
void grid_quad(int lx, int ly, uint32_t T, double lon, double lat, struct grid_quad *q);
/* The S×S window centred on (lon, lat). S: T times a power of two ≤ GRID_WINDOW_MAX_TILES. */
void grid_window(int lx, int ly, uint32_t T, uint32_t S, double lon, double lat,
		 struct grid_quad *q);
/* The distinct tiles the window touches (ntx · nty ≤ GRID_WINDOW_MAX_KEYS), their node field
 * set to `node`, row by row from the north-west one. Returns the count. */
int grid_quad_tiles(const struct grid_quad *q, uint64_t node, struct tile_key *out);
bool grid_quad_equal(const struct grid_quad *a, const struct grid_quad *b);
/* The window `w` texels wide and high in the middle of q's window, on q's texture (same S:
 * texel (u, v) at (u mod S, v mod S)), its rows kept inside the level as q's are: q's core, the
 * part of it a viewer needs first (view_clipmap: a level is drawn once the tiles its ring needs
 * are in, before the rest of its window). Where q holds whole parallels the core does too (only
 * its rows shrink); an extent of q no larger than w stays; so where neither shrinks,
 * *out = *q. */
void grid_window_core(const struct grid_quad *q, uint32_t w, struct grid_quad *out);
/* Level texel column u (any real) relative to q's first column, the short way round the
 * level: within [-(W - w)/2, (W + w)/2], so inside the window is [0, w). */
double grid_window_rel_u(const struct grid_quad *q, double u);

struct grid_region {
	uint32_t x, y, w, h; /* texels in the S×S toroidal texture */
	uint32_t tx, ty;     /* source tile (at the window's level) */
	uint32_t sx, sy;     /* where the region starts inside it */
};

/* The regions of `next`'s window that `prev` did not hold (seed 003 §5.2), each inside one
 * tile and one period of the texture: none when nothing changed, a few for a small move.
 * prev's extent may differ from next's (a core, grid_window_core, growing to its window).
 * prev == NULL, another level/size, or a move of the window's size or more gives the full
 * window (one region per tile it touches). Every texel of the window is in exactly one region
 * or was in prev. out holds GRID_MAX_REGIONS. */
int grid_update_regions(const struct grid_quad *prev, const struct grid_quad *next,
			struct grid_region *out);

/* Chebyshev distance in tiles from k (at the window's level) to the tiles the window touches,
 * x wrapping: 0 inside, 1 for the ring around it. Keys at other levels: UINT32_MAX. */
uint32_t grid_quad_distance(const struct grid_quad *q, const struct tile_key *k);

#endif
