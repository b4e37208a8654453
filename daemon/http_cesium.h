/* http_cesium — Cesium terrain from a planet's height tiles: the tileset description
 * (layer.json: quantized-mesh-1.0, TMS scheme on the geographic tiling, every tile available
 * down to the planet's finest level) and quantized-mesh-1.0 tiles
 * (https://github.com/CesiumGS/quantized-mesh). A tile is a regular grid of
 * (S + 1)² vertices, S = min(64, T), at the texel corners of the height tile (heights
 * interpolated from the texel centres, clamped at the tile's border, so neighbours can differ
 * by one texel's slope at a shared edge: Cesium's skirts close that), two triangles per cell.
 * Positions use the planet's own ellipsoid (a, f): a client must use the same one.
 *
 * Vertex normals (the `octvertexnormals` extension) come from the planet's normal layer made
 * of the terrain's heights (a `normal` node whose input is the height layer's node): seamless
 * texel normals (node_normal differences across tile borders), interpolated at the vertices
 * as the heights are, turned from the local east-north-up frame into Earth-centred
 * coordinates and oct-encoded in 2 bytes. Neighbours agree at a shared edge but for the
 * clamping at the border (one texel's change of normal), as for the heights. */
#ifndef CLIPMAP_HTTP_CESIUM_H
#define CLIPMAP_HTTP_CESIUM_H
#include <stdbool.h>
#include <stddef.h>

#include "engine/planet.h"
#include "engine/tile.h"

/* The layer of p whose normals are those of the heights of layer `heights` (a normal layer
 * whose node's input is heights' node), or NULL: the terrain is offered without normals. */
const struct planet_layer *cesium_normal_layer(const struct planet *p,
					       const struct planet_layer *heights);
/* A malloc'ed, NUL-terminated JSON document (*len bytes); normals: list the octvertexnormals
 * extension. */
char *cesium_layer_json(const struct planet *p, bool normals, size_t *len);
/* The quantized-mesh bytes of height tile t (PIX_HEIGHT, key (lx, ly) = (z + 1, z)) of p,
 * malloc'ed into *out (*n bytes); with nt (the normal tile of the same key, PIX_NORMAL, same
 * size) the octvertexnormals extension follows, else none. */
void cesium_quantized_mesh(const struct planet *p, const struct tile *t, const struct tile *nt,
			   unsigned char **out, size_t *n);

#endif
