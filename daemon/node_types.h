/* node_types — the registry of node types a planet file can name (`type = ...`), and the
 * loader entry point that resolves types against a caller-given registry (tests and tools that
 * add their own types). Each type lives in its own daemon/node_<name>.c.
 *
 * Everything here is static const data or pure lookups: thread-safe.
 */
#ifndef CLIPMAP_NODE_TYPES_H
#define CLIPMAP_NODE_TYPES_H
#include "node.h"
#include "planet.h"

extern const struct node_type node_type_constant, node_type_noise, node_type_color_filter,
	node_type_height_filter, node_type_ramp, node_type_blend, node_type_normal, node_type_file;

/* The type named `name` in the NULL-terminated list `types`, or NULL (borrowed). */
const struct node_type *node_types_find_in(const struct node_type *const *types, const char *name);

/* planet_load, resolving node types in `types` (NULL-terminated, borrowed; must outlive the
 * planet) instead of node_types_all(). Returns 0 or -errno with err filled. */
int planet_load_types(const char *path, const struct node_type *const *types, struct planet **out,
		      char err[256]);

#endif
