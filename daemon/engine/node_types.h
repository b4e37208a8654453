/* node_types — the registry of node types a planet file can name (`type = ...`). Each type
 * lives in its own daemon/engine/nodes/node_<name>.c.
 *
 * Everything here is static const data or pure lookups: thread-safe.
 */
#ifndef CLIPMAP_NODE_TYPES_H
#define CLIPMAP_NODE_TYPES_H
#include "node.h"

/* `constant`: a height (metres) or a colour everywhere. */
extern const struct node_type node_type_constant;
/* `noise`: seeded fBm / ridged simplex noise on the sphere, a height source or detail added
 * to an optional input height (node_noise.c lists the parameters). */
extern const struct node_type node_type_noise;
/* `color_filter`: input (color) → color. levels, brightness, contrast, gamma (one LUT),
 * then hue rotation and saturation (a 3×3 matrix) when not identity; alpha passes. */
extern const struct node_type node_type_color_filter;
/* `color_mask`: input (color) → height 0..1: 1 within `near` of one of `colors` (RGB
 * distance), 0 beyond `far`, smoothstep between — land cover from a colour layer. */
extern const struct node_type node_type_color_mask;
/* `height_filter`: input (height) → height: clamp(in · scale + offset, min, max). */
extern const struct node_type node_type_height_filter;
/* `ramp`: input (height) → color: hypsometric tint from `stops`, shifted by `sea_level`,
 * with an optional snow line by latitude and sea ice. */
extern const struct node_type node_type_ramp;
/* `blend`: a, b (same type), optional mask (height, 0..1) → a's type; mode = over | mask |
 * add | multiply, opacity, weight. */
extern const struct node_type node_type_blend;
/* `normal`: input (height) → normal (RG8), metric spacing from the body's ellipsoid, seamless
 * across tile borders, the antimeridian and the poles; `exaggeration`. */
extern const struct node_type node_type_normal;
/* The height node a `normal` node with exaggeration 1 makes its normals of, or NULL (not a
 * normal node, or exaggerated): what a viewer can make itself from that node's tiles. */
const struct node *node_normal_plain_input(const struct node *n);
/* `slope`: input (height) → height: the slope magnitude |∇h| (m/m), metric, seamless like
 * `normal`; `scale` (m) measures it over a fixed distance on every finer level. */
extern const struct node_type node_type_slope;
/* `file`: an equirectangular raster (global or within `bounds`) read through OpenImageIO,
 * resampled bilinearly, filtered from MIP levels when coarser than the file. */
extern const struct node_type node_type_file;
/* `geoid`: input (height above the geoid) → height above the ellipsoid: + N(lat, lon) from a
 * GTX geoid grid (default EGM96 from proj-data); `sign = -1` reverses it. */
extern const struct node_type node_type_geoid;
/* `open_sea`: where a sea may lie (the ocean and closed basins of at least min_area), read
 * from a global height raster: a 0..1 mask (color_filter's `alpha` carries it to a viewer). */
extern const struct node_type node_type_open_sea;
/* The surface of an `open_sea` node's closed seas with a level of their own (its `levels`,
 * metres relative to sea_level) into *level where a cell of one lies within reach degrees (of
 * latitude, and of longitude) of (lat, lon), else 0; *mixed (if not NULL): whether a sea at
 * another level (the ocean, a basin at sea level or at another level) lies there too. False
 * if n is not an open_sea node. */
bool open_sea_level(const struct node *n, double lat, double lon, double reach, double *level,
		    bool *mixed);
/* A `geoid` node's undulation N at (lat, lon) degrees, metres (whatever its sign); false if n
 * is not a geoid node. */
bool geoid_undulation(const struct node *n, double lat, double lon, double *out);
/* `craters`: seeded, size-distributed impact craters on the sphere, a height source or added
 * to an optional input height; band-limited per level (node_craters.c lists the parameters). */
extern const struct node_type node_type_craters;
/* `cells`: a patchwork of seeded Voronoi cells on the sphere, one value each in [0, 1) with
 * optional borders (−1) between them, band-limited per level (node_cells.c). */
extern const struct node_type node_type_cells;
/* What a `cells` tile of key k and size T (no input) holds at texel (i, j), evaluated alone,
 * without the tile's skipping of texels near the last one evaluated: an oracle for tests. */
float cells_texel(const struct node *n, const struct tile_key *k, uint32_t T, uint32_t i,
		  uint32_t j);
/* `vector`: a GDAL/OGR vector source (GeoJSON, GeoPackage, Shapefile, …) rasterized per tile
 * with exact area coverage: RGBA (styled by an attribute) or a 0..1 mask (node_vector.c). */
extern const struct node_type node_type_vector;

/* The type named `name` in the NULL-terminated list `types`, or NULL (borrowed). */
const struct node_type *node_types_find_in(const struct node_type *const *types, const char *name);

#endif
