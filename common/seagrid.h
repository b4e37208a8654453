/* seagrid — the surface of a sea that follows a geoid, as the daemon sends it and the viewer
 * draws it: heights above the planet's sea_level on a latitude/longitude lattice, in
 * decimetres (docs/PLANETS.md `sea_geoid`, docs/PROTOCOL.md OPENED).
 *
 * Lattice: `rows` rows of `cols` nodes, row 0 at the south pole and row rows−1 at the north
 * pole ((rows − 1) equal steps of latitude), column 0 at −180° and cols equal steps east,
 * wrapping at the antimeridian. Between nodes the surface is bilinear.
 * Pure functions: thread-safe.
 */
#ifndef CLIPMAP_SEAGRID_H
#define CLIPMAP_SEAGRID_H
#include <stdint.h>

#define SEA_GRID_MIN 2
#define SEA_GRID_MAX_ROWS 1801 /* 0.1° */
#define SEA_GRID_MAX_COLS 3600

struct sea_grid {
	uint16_t rows, cols; /* 0, 0: no grid (a sea at sea_level everywhere) */
	int16_t *dm;	     /* rows × cols, south → north, decimetres above sea_level */
};

/* Whether rows × cols is a lattice this format allows (both 0: no grid). */
int sea_grid_valid_size(uint32_t rows, uint32_t cols);

/* The surface at (lat, lon) degrees, metres above sea_level; 0 without a grid. */
double sea_grid_at(const struct sea_grid *g, double lat, double lon);

/* The lowest and highest node, metres above sea_level; 0, 0 without a grid. */
void sea_grid_range(const struct sea_grid *g, double *lo, double *hi);

#endif
