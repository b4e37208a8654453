/* http_cesium — Cesium terrain from a planet's height tiles: the tileset description
 * (layer.json: quantized-mesh-1.0, TMS scheme on the geographic tiling, every tile available
 * down to the planet's finest level) and quantized-mesh-1.0 tiles
 * (https://github.com/CesiumGS/quantized-mesh). A tile is a regular grid of
 * (S + 1)² vertices, S = min(64, T), at the texel corners of the height tile (heights
 * interpolated from the texel centres, clamped at the tile's border, so neighbours can differ
 * by one texel's slope at a shared edge: Cesium's skirts close that), two triangles per cell.
 * Positions use the planet's own ellipsoid (a, f): a client must use the same one. */
#ifndef CLIPMAP_HTTP_CESIUM_H
#define CLIPMAP_HTTP_CESIUM_H
#include <stddef.h>

#include "engine/planet.h"
#include "engine/tile.h"

/* A malloc'ed, NUL-terminated JSON document (*len bytes). */
char *cesium_layer_json(const struct planet *p, size_t *len);
/* The quantized-mesh bytes of height tile t (PIX_HEIGHT, key (lx, ly) = (z + 1, z)) of p,
 * malloc'ed into *out (*n bytes). */
void cesium_quantized_mesh(const struct planet *p, const struct tile *t, unsigned char **out,
			   size_t *n);

#endif
