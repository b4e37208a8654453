/* clipmap — the level plan of the viewer's spherical clipmap, shared by the viewer (which
 * draws it) and the daemon's prefetch (which warms what viewers will ask for): ring radii
 * (seed 000 §3.4), the window of each level, the longitude grid level lx a level uses at a
 * latitude (anisotropic near the poles, seed 000 §4.1), and which levels give a ring its
 * colour and normals.
 *
 * Conventions: clipmap level i samples grid level (lx_i, ly = i); ring i covers the view-space
 * angles θ̃ ∈ [R(i+1), R(i)] around the point under the camera, R(i) = K·(π/2)/2^i for i ≥ 1,
 * R(0) = 2π/3 (level 0 is the whole globe). Each level's texture window is
 * CLIPMAP_WINDOW_TILES tiles wide (grid_window); ring i's heights come from level i, its colour
 * and normals from level i + CLIPMAP_DETAIL, whose window is as wide in angle as ring i needs.
 * Angles in radians unless named _deg. Pure functions: thread-safe.
 */
#ifndef CLIPMAP_CLIPMAP_H
#define CLIPMAP_CLIPMAP_H
#include "common/grid.h"

#define CLIPMAP_RING_K 0.75
#define CLIPMAP_WINDOW_TILES GRID_WINDOW_TILES
#define CLIPMAP_DETAIL 2
/* Tiles a viewer asks for around its focus at a level, per side of the focus's tile: the
 * window (CLIPMAP_WINDOW_TILES / 2, rounded up to whole tiles touched) and the prefetch ring. */
#define CLIPMAP_REACH_TILES (CLIPMAP_WINDOW_TILES / 2 + 1)

/* Ring i's outer radius in view-space angle. */
double clipmap_ring_radius(int i);
/* The half-width in longitude (radians) of a disk of angular radius r around latitude lat_deg,
 * π when the disk holds a pole. */
double clipmap_lon_extent(double lat_deg, double r);
/* The longitude grid level for clipmap level ly at the focus latitude: the finest lx ≤ ly + 1
 * whose window spans the longitude extent of the widest ring it is drawn on, ring
 * ly − CLIPMAP_DETAIL (a window as wide as the whole level when that ring holds a pole).
 * cur_lx (or -1) adds hysteresis: a coarser current lx is kept unless the finer one fits
 * with room to spare — one step coarser than the fit at most (lx − 1 where cur_lx is
 * coarser still), so the result is always in clipmap_level_lx_range. */
int clipmap_level_lx(int ly, double lat_deg, int cur_lx);
/* Every lx a viewer whose focus is anywhere in latitudes [lat_lo, lat_hi] may use at level ly
 * (hysteresis included): *lx_lo .. *lx_hi. */
void clipmap_level_lx_range(int ly, double lat_lo, double lat_hi, int *lx_lo, int *lx_hi);

#endif
