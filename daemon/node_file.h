/* node_file — the `file` node type: an image file (OpenImageIO) resampled onto the tile grid.
 * See node_file.c for its parameters. The registry (node.c) will list node_type_file; until
 * then, this header declares it.
 */
#ifndef CLIPMAP_NODE_FILE_H
#define CLIPMAP_NODE_FILE_H
#include "node.h"

extern const struct node_type node_type_file;

#endif
