/* view_source_local — a view_source over the engine in this process: a loaded planet, a tile
 * cache and the scheduler (daemon/engine/). Used by tests and `clipmapview --planet FILE`.
 * Threads: the scheduler's manager thread queues ready tiles under a mutex (which protects
 * only the queue); the viewer's thread drains it. Ownership: the source owns everything it
 * creates; polled tiles hold a tile reference until release.
 */
#ifndef CLIPMAP_VIEW_SOURCE_LOCAL_H
#define CLIPMAP_VIEW_SOURCE_LOCAL_H
#include <stddef.h>
#include <stdint.h>

#include "view_source.h"

struct view_source_local_opts {
	int workers;	   /* 0: one per CPU */
	size_t cache_mb;   /* 0: 512 */
	const char *store; /* optional: an LMDB tile store file under the cache, read and
			    * filled (created if missing) — possibly the one a running clipmapd
			    * uses (clipmapd.conf(5), [store] path: the rules) */
	uint32_t store_mb; /* the store's budget, MiB (0: 1024, as clipmapd's disk_mb) */
};

/* Loads the planet file and starts the engine. Returns 0 or -errno with err filled; on
 * success err may hold a note (the store file was found damaged, moved aside, recreated). */
int view_source_local_create(const char *planet_path, const struct view_source_local_opts *o,
			     struct view_source **out, char err[256]);
/* What the engine of s (from view_source_local_create) did so far, into line: "N tiles
 * generated, M loaded from the store" and, with a store, "; store: " and its summary
 * (store_summary: what is queued is committed first). */
void view_source_local_report(struct view_source *s, char *line, size_t n);

#endif
