/* view_source_local — a view_source over the engine in this process: a loaded planet, a tile
 * cache and the scheduler (daemon/engine/). Used by tests and `clipmapview --planet FILE`.
 * Threads: the scheduler's manager thread queues ready tiles under a mutex (which protects
 * only the queue); the viewer's thread drains it. Ownership: the source owns everything it
 * creates; polled tiles hold a tile reference until release.
 */
#ifndef CLIPMAP_VIEW_SOURCE_LOCAL_H
#define CLIPMAP_VIEW_SOURCE_LOCAL_H
#include <stddef.h>

#include "view_source.h"

struct view_source_local_opts {
	int workers;	 /* 0: one per CPU */
	size_t cache_mb; /* 0: 512 */
};

/* Loads the planet file and starts the engine. Returns 0 or -errno with err filled. */
int view_source_local_create(const char *planet_path, const struct view_source_local_opts *o,
			     struct view_source **out, char err[256]);

#endif
