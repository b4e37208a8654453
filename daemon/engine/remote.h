/* remote — the shared tier below the disk store, as the engine sees it: tiles other daemons
 * of a fleet generated, and a lease per key so that a tile is generated once fleet-wide. The
 * engine has no sockets: the server wing implements this vtable (daemon/store_redis.c, on
 * Redis) and hands it to the scheduler (sched_desc.remote). The scheduler tries memory, then
 * the disk store, then this tier, and generates only what it finds nowhere.
 *
 * A worker asks get(): a hit, or -ENOENT (generate it: this daemon now holds the key's lease),
 * or -ENOLINK (generate it, without a lease: the tier is unreachable and every daemon fends
 * for itself), or -EINPROGRESS (another daemon holds the lease and is generating it). A job may wait in the queue a while before a
 * worker generates it: confirm() then renews the lease (or says that another daemon took it
 * over meanwhile, and the job waits after all). Then the scheduler parks the job with wait(),
 * which never blocks: the implementation calls r->wake(r->wake_ud, token) from a thread of its
 * own once the key is worth asking again (the tile arrived, the lease ended — its holder died —,
 * the tier went away, or a bound passed), and the job goes back to a worker (get with
 * retry = true; a lease taken then is a takeover). A generated layer tile goes to put(), which
 * queues it (write-behind, never waits; a full queue drops it, counted) and whose write
 * releases the lease; a failed generation calls release().
 *
 * Threads: get, confirm, put and release from any worker; wait from the manager; wake from the
 * implementation's thread. Ownership: the server owns the remote; tiles given to put are
 * borrowed (the implementation takes its own reference); get returns an owned tile.
 */
#ifndef CLIPMAP_REMOTE_H
#define CLIPMAP_REMOTE_H
#include <stdbool.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/pixfmt.h"
#include "tile.h"

struct tilecodec;

struct remote_stats {
	uint64_t hits;	     /* gets that returned a tile */
	uint64_t misses;     /* gets that found no tile */
	uint64_t writes;     /* tiles written */
	uint64_t drops;	     /* tiles not written (queue full, tier unreachable, write refused) */
	uint64_t bad;	     /* records whose checksum or header failed (treated as misses) */
	uint64_t waits;	     /* gets that found another daemon's lease and waited */
	uint64_t takeovers;  /* leases taken after a wait whose holder never delivered */
	uint64_t expired;    /* tiles written after their lease had expired (generation outlived
			      * it: another daemon may have generated the tile too) */
	uint64_t generated;  /* layer tiles this daemon generated and offered to the tier */
	uint64_t errors;     /* failed commands and connections */
	uint64_t connected;  /* 1 while the tier is reachable */
};

struct remote;

struct remote_ops {
	/* The tile for k, decoded with tc (the caller's), as an owned reference in *out; type and
	 * size as the caller expects (another is a miss). Returns 0, -ENOENT (generate it under
	 * this daemon's lease), -ENOLINK (generate it, no lease: the tier is unreachable or
	 * refused) or -EINPROGRESS (another daemon holds the lease: wait). retry: this get
	 * follows a wait. */
	int (*get)(struct remote *r, const struct tile_key *k, enum pix_type type, uint32_t size,
		   struct tilecodec *tc, bool retry, struct tile **out);
	/* Right before generating k under a lease get gave: renews the lease (taking it again if
	 * it expired meanwhile) and returns 0 (generate), or -EINPROGRESS when another daemon
	 * holds it now or its tile exists (wait instead). 0 as well when the tier is down. */
	int (*confirm)(struct remote *r, const struct tile_key *k);
	/* Queues generated tile t for writing; leased: generated under this daemon's lease,
	 * which the write releases. Never waits. */
	void (*put)(struct remote *r, struct tile *t, bool leased);
	/* Queues the release of k's lease (its generation failed). Never waits. */
	void (*release)(struct remote *r, const struct tile_key *k);
	/* Calls r->wake(r->wake_ud, token) once, later, from another thread (see above). */
	void (*wait)(struct remote *r, const struct tile_key *k, void *token);
	/* Forgets every wait without waking it; when it returns no wake runs or will run. */
	void (*cancel_waits)(struct remote *r);
	void (*stat)(struct remote *r, struct remote_stats *out);
};

/* Every implementation embeds this first. wake and wake_ud are set by the scheduler. */
struct remote {
	const struct remote_ops *ops;
	void (*wake)(void *ud, void *token);
	void *wake_ud;
};

#endif
