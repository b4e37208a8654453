/* pixel_nodes — the per-texel node types (colour and height filters, height→colour ramp,
 * blend) and the normal map from heights. Each is a `struct node_type` (node.h) defined in its
 * own daemon/node_*.c; the planet loader finds them through the node type registry.
 *
 * Thread-safety: as for every node type, create/destroy run while loading; deps/generate may
 * run on any worker concurrently (they only read the node).
 */
#ifndef CLIPMAP_PIXEL_NODES_H
#define CLIPMAP_PIXEL_NODES_H

#include "node.h"

/* `color_filter`: input (color) → color. levels, brightness, contrast, gamma (one LUT),
 * then hue rotation and saturation (a 3×3 matrix) when not identity; alpha passes. */
extern const struct node_type node_type_color_filter;
/* `height_filter`: input (height) → height: clamp(in · scale + offset, min, max). */
extern const struct node_type node_type_height_filter;
/* `ramp`: input (height) → color: hypsometric tint from `stops`, shifted by `sea_level`. */
extern const struct node_type node_type_ramp;
/* `blend`: a, b (same type), optional mask (height, 0..1) → a's type; mode = over | mask |
 * add | multiply, opacity, weight. */
extern const struct node_type node_type_blend;
/* `normal`: input (height) → normal (RG8), metric spacing from the body's ellipsoid, seamless
 * across tile borders, the antimeridian and the poles; `exaggeration`. */
extern const struct node_type node_type_normal;

#endif
