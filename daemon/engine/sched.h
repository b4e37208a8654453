/* sched — the manager thread and the worker pool (seed 003 §6).
 *
 * Requesters (sessions, `clipmapctl render`, prefetch jobs) each own a sched_req and give it
 * ordered want lists; each list replaces the previous one. The manager resolves dependencies
 * depth-first through the graph, merges duplicates with queued and running work, orders
 * ready work by class (visible, web, prefetch, bulk), then level (coarse first), then the order in
 * which it was wanted, and cancels queued work no requester wants any more. Workers (lower OS
 * priority) generate with no lock held, publish into the cache, and hand completion back to
 * the manager, which tells every requester that still wants the tile.
 *
 * Threads: all functions are thread-safe except where noted. Ready callbacks run on the
 * manager thread with no scheduler lock held; they must be quick and must not call back into
 * the scheduler for the same request (queue work elsewhere, e.g. write an eventfd).
 * Locks: the scheduler's two locks (inbox, ready queue) are never nested, and neither is held
 * across generation, a callback or a cache call, so the cache's lock is never taken under them
 * (the design note in sched.c lists what each protects).
 */
#ifndef CLIPMAP_SCHED_H
#define CLIPMAP_SCHED_H
#include <stddef.h>
#include <stdint.h>

#include "cache.h"
#include "node.h"
#include "remote.h"
#include "store.h"

enum sched_class {
	SCHED_NONE = 0,
	SCHED_VISIBLE,	/* what a viewer shows now */
	SCHED_WEB,	/* HTTP requests (daemon/http.c): after what a viewer shows (a GDAL export
			 * must not starve it), before speculative prefetch (a person or a
			 * program waits on each one) */
	SCHED_PREFETCH, /* the ring around and the path ahead */
	SCHED_AHEAD,	/* a viewer's speculation: its look-ahead rows (the protocol's bulk class
			 * from a session) and the server's look-ahead along its path
			 * (lookahead.h); after the ring, before operator jobs, and like the
			 * classes above its tiles go into the memory cache, also those loaded
			 * from the store */
	SCHED_BULK,	/* operator prefetch jobs: with a store, kept on disk only */
	SCHED_NCLASS
};

struct want {
	struct node *node; /* borrowed: must outlive the request's interest in it */
	struct tile_key key; /* key.node must equal node->hash */
	enum sched_class cls;
};

/* Called once per wanted key when its tile is ready (t borrowed: tile_ref it to keep it) or
 * its generation failed (t NULL, err < 0). Runs on the manager thread. A key is reported
 * again only if a later want list asks for it again. */
typedef void (*sched_ready_fn)(void *ud, const struct want *w, struct tile *t, int err);

struct sched_desc {
	struct cache *cache; /* borrowed; required */
	struct store *store; /* borrowed, optional: the tier below the cache (store.h); tried
			      * before generating, and every generated tile is put there */
	struct remote *remote; /* borrowed, optional: the shared tier below the store
				* (remote.h); its wake is set here. Outlives the scheduler. */
	int workers;	     /* 0: one per online CPU */
	int worker_nice;     /* added niceness for workers; 0: default (+5); <0: unchanged */
};

struct sched_stats {
	uint64_t queued[SCHED_NCLASS]; /* ready jobs waiting for a worker, per class */
	uint64_t waiting;	       /* jobs waiting for their inputs */
	uint64_t running;	       /* workers busy */
	uint64_t generated;	       /* tiles generated since start */
	uint64_t loaded;	       /* tiles loaded from the store since start */
	uint64_t merged;	       /* wants that joined existing work instead of adding a job */
	uint64_t skipped;	       /* inputs found not needed before they were made (node.h lazy) */
	uint64_t cancelled;	       /* queued jobs dropped because nobody wanted them */
	uint64_t failed;	       /* generations that returned an error */
	int workers;
};

struct sched;
struct sched_req;

/* Starts the manager and the workers. Returns NULL only on ENOMEM (thread start failures
 * abort with a message: the daemon cannot run without them). */
struct sched *sched_create(const struct sched_desc *d);
/* Cancels everything, joins all threads, frees. Requests must be destroyed first. */
void sched_destroy(struct sched *s);

struct sched_req *sched_req_create(struct sched *s, sched_ready_fn fn, void *ud);
/* Replaces the request's want list (copied); n = 0 cancels everything it wanted. Cached tiles
 * are reported at once (from the manager thread). Returns 0 or -errno. */
int sched_req_want(struct sched_req *r, const struct want *w, size_t n);
/* Stops the request: after this returns, its callback is never called again. From another
 * thread it waits while a callback for r is running; from inside a callback (for another
 * request) it returns at once and r's pending callbacks are dropped. */
void sched_req_destroy(struct sched_req *r);

/* Stops the request without waiting (what an event loop calls): the manager frees it at its
 * next iteration. Until then r's callback may still run (on the manager thread), so ud must
 * stay valid: fin(ud), when not NULL, is called once on the manager thread after the last
 * callback for r (or by sched_destroy), the place to release ud. fin must be quick and must
 * not call into the scheduler. r must not be used after this call. */
void sched_req_release(struct sched_req *r, void (*fin)(void *ud));
/* Waits until every request released (or destroyed) before the call is freed and its fin
 * called. Not from a ready callback. */
void sched_barrier(struct sched *s);

/* Blocking convenience for offline use and tests: generates (or finds) every wanted tile and
 * stores an owned reference in out[i] (NULL where generation failed). Returns 0 if all
 * succeeded, else the first error (in list order). Never call it from a ready callback: it
 * waits for the manager thread that runs callbacks. */
int sched_fetch(struct sched *s, const struct want *w, size_t n, struct tile **out);

void sched_get_stats(struct sched *s, struct sched_stats *out);
/* 0, or the first -errno a worker got lowering its priority (setpriority refusals for lack of
 * privilege, EPERM/EACCES, are not errors: the worker just runs at the default priority). */
int sched_worker_nice_error(struct sched *s);
/* The remote tier given at creation (borrowed), or NULL. */
struct remote *sched_remote(struct sched *s);
/* The store given at creation (borrowed), or NULL. */
struct store *sched_store(struct sched *s);

#endif
