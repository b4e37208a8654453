/* readyq — the queue through which the scheduler's manager thread hands ready tiles to the
 * event loop: a mutex-protected array plus an eventfd the loop watches, written only on the
 * empty → non-empty transition. The loop swaps the whole array out and works without the lock.
 *
 * Threads: readyq_push from any thread; everything else on the loop thread. The mutex guards
 * the array and the signalled flag only and is never held while calling out.
 * Ownership: the queue owns the tile references of the items it holds and its eventfd.
 */
#ifndef CLIPMAP_READYQ_H
#define CLIPMAP_READYQ_H
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>

#include "common/grid.h"
#include "engine/tile.h"

struct session;
struct prefetch_job;
struct readyq;
struct ready_item;

/* A requester's handle that outlives it: the scheduler may still report tiles for a session
 * after the session closed (its request is released without waiting for the manager), so
 * such reports carry a reference to the handle instead of trusting the session pointer. The
 * loop marks it dead when the session closes and then drops every item that names it.
 * Reference-counted (any thread); `dead` and `s` are read and written on the loop thread
 * only, `q` is fixed.
 * `queued` bounds the tile memory its reports hold while they wait for the loop: the scheduler's
 * workers can outrun the loop (a loop busy writing to many sockets takes a batch of hundreds),
 * and a report holds its tile even after the cache let it go. A report that would take the
 * queued bytes past `queue_cap` travels without its tile (ready_item.parked): the loop parks
 * the entry and looks the tile up in the cache when the session has room for it. */
struct ready_src {
	atomic_int refs;
	bool dead;
	struct session *s;
	struct readyq *q;
	atomic_uint_fast64_t queued; /* bytes of the tiles its queued reports hold */
	uint64_t queue_cap;	     /* 0: no bound */
};

/* A handle for s on q with one reference (the caller's). */
struct ready_src *ready_src_new(struct readyq *q, struct session *s);
struct ready_src *ready_src_ref(struct ready_src *src);
/* Queues a report of tile t (borrowed; NULL with err < 0 for a failure) for src's session,
 * with a reference of the tile unless that would pass src->queue_cap (see struct ready_src).
 * Any thread. */
void ready_src_report(struct ready_src *src, const struct tile_key *key, struct tile *t,
		      int err);
/* The loop took it: its bytes leave src->queued. */
void ready_item_taken(struct ready_item *it);
/* Drops a reference and frees the handle at zero; NULL is a no-op. */
void ready_src_unref(struct ready_src *src);

struct ready_item {
	struct session *s;	  /* the requester (borrowed; outlives its items: readyq_purge),
				   * unless src is set: then valid only while !src->dead */
	struct ready_src *src;	  /* NULL, or an owned reference (see struct ready_src) */
	struct prefetch_job *job; /* the session's job that wanted it; NULL: the want-set */
	struct tile_key key;
	struct tile *t; /* owned reference, or NULL when err < 0 or parked */
	int err;
	bool parked;	 /* ready, but sent without its tile (ready_src.queue_cap) */
	uint64_t queued; /* bytes counted in src->queued for it (the loop takes them off) */
};

struct readyq {
	int evfd; /* readable while items wait (watch it for EPOLLIN) */
	pthread_mutex_t mu; /* protects items, n, cap, signalled */
	struct ready_item *items;
	size_t n, cap;
	bool signalled;
};

/* Makes the eventfd. Returns 0 or -errno. */
int readyq_init(struct readyq *q);
/* Releases the queued tiles and closes the eventfd. */
void readyq_fini(struct readyq *q);
/* Queues *it (any thread; takes it->t's reference) and wakes the loop when needed. */
void readyq_push(struct readyq *q, const struct ready_item *it);
/* Takes every queued item (loop thread, after the eventfd fired). Returns them as an owned
 * array of *n items (free it; their tile and src references are the caller's), NULL when
 * empty. */
struct ready_item *readyq_take(struct readyq *q, size_t *n);
/* Drops the items of session s (after its scheduler requests are destroyed or released). */
void readyq_purge(struct readyq *q, const struct session *s);

#endif
