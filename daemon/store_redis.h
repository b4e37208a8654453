/* store_redis — the fleet's shared tile tier on Redis (hiredis), implementing the engine's
 * remote tier (engine/remote.h). docs/FLEET.md describes the keys, the leases and degradation.
 *
 * Keys (a Redis Cluster hash tag around the tile's identity, so a tile and its lease share a
 * slot): "cm:t:{HEX}" the value, "cm:l:{HEX}" the lease, HEX = the 18-byte store key
 * (store_key_encode: node content hash, level, position) in hex. A value is the disk store's
 * record (store_value_encode: header, XXH3 checksum over header, key and payload, zstd tile);
 * every read verifies it, a bad one is counted, deleted and treated as a miss.
 *
 * Threads: workers call get on connections from a small pool; a writer thread pipelines the
 * queued writes and lease releases (bounded queue, drops counted); a waiter thread polls the
 * keys of parked jobs (pipelined EXISTS with per-key backoff) and, while Redis is down,
 * reconnects with backoff. Redis unreachable: get says "generate" at once (no network wait),
 * writes are dropped, waits are woken; the transition is logged once each way.
 */
#ifndef CLIPMAP_STORE_REDIS_H
#define CLIPMAP_STORE_REDIS_H
#include <stddef.h>
#include <stdint.h>

#include "engine/remote.h"

struct store_redis_desc {
	const char *addr;     /* "unix:/path" or "host:port"; required */
	const char *password; /* AUTH; NULL: none */
	uint32_t lease_ms;    /* a lease's lifetime; 0: 2000 */
	size_t queue_max;     /* writes queued before drops; 0: 1024 */
	int zstd_level;	      /* 0: 1 */
};

/* Creates the tier and starts its threads. Redis need not be up (the daemon starts and
 * shares once it is). Returns 0 with *out owned, or -EINVAL with err filled (a bad address). */
int store_redis_open(const struct store_redis_desc *d, struct remote **out, char err[256]);
/* Writes what is queued (bounded by a short wait), stops the threads, frees. NULL: no-op.
 * The scheduler using it must be destroyed first. */
void store_redis_destroy(struct remote *r);

#endif
