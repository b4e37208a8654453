/* encq — the shared cache of encoded tiles and the threads that encode them. A TILE payload
 * depends on the tile and the encoding only (codec, its default filter, level 1), never on
 * the session, so each (tile key, codec) is encoded once, off the event loop, and every
 * session that wants it queues a reference to the same bytes (conn.h writes them out with
 * sendmsg from there, with a small per-session header). A `none` encoding copies nothing:
 * its payload is the tile's own texels (the tile is held), only the checksum is computed.
 *
 * Why a pool of its own rather than the scheduler's workers or its ready callback: the
 * encoding depends on the session's link (compress = auto picks raw or zstd per link and
 * may change its mind), a cached tile needs encoding without any generation, and the ready
 * callback runs on the manager thread, which must not spend milliseconds per tile. Encoding
 * is a few hundred microseconds per 256² tile; ENCQ_THREADS threads keep up with the links
 * of a 2-core machine.
 *
 * Memory: the cache keeps encodings up to a byte budget (payload bytes; a `none` encoding
 * counts its tile's bytes, which it keeps alive), least recently used first out. Encodings
 * still wanted by a session's output are not freed by eviction (references), and are
 * counted in that session's queued bytes (its max_pending allowance) as if copied.
 *
 * Threads: encq_get, encq_drain, encq_stats and every etile field marked (loop) on the event
 * loop's thread; the encoder threads only read the tile and write payload, enc and err of
 * the etiles they were handed, which the loop reads only after encq_drain took them back
 * through the done list (its mutex orders the accesses). Lock order: mu alone; never held
 * while encoding or calling out. Ownership: the cache owns one reference per cached etile;
 * queued jobs and done items own one each.
 */
#ifndef CLIPMAP_ENCQ_H
#define CLIPMAP_ENCQ_H
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/tilecodec.h"
#include "engine/tile.h"
#include "readyq.h"

#define ENCQ_THREADS 2

/* One encoding of one tile, reference-counted (any thread). */
struct etile {
	atomic_int refs;
	struct tile_key key;
	uint8_t codec;		 /* the encoding asked for (the cache key with key) */
	struct tilecodec_lossy_opts lossy; /* a lossy codec's knobs (fixed per key and codec:
					    * the step follows the level, the quality the conf) */
	bool ready;		 /* (loop) payload, len, enc and err may be read */
	int err;		 /* < 0: the encoding failed (ready); nothing is sent */
	struct tilecodec_hdr enc; /* what the payload is (codec `none` when it did not pay) */
	const uint8_t *payload;	 /* len bytes: buf, or the tile's texels */
	uint32_t len;
	struct tile *t; /* the source: held until encoded, and for ever by a `none` encoding */
	uint8_t *buf;	/* owned encoded bytes; NULL for `none` */
	/* (loop) the cache's links and the sessions waiting for it */
	bool cached;
	struct etile *hnext, *older, *newer;
	struct ready_src **waiters;
	size_t nwait, capwait;
	struct etile *qnext; /* the job or done list (under mu) */
};

struct etile *etile_ref(struct etile *e);
/* Drops a reference, freeing at zero (any thread); NULL is a no-op. */
void etile_unref(struct etile *e);
/* Payload plus frame header: the TILE frame's size once ready, else an upper bound. */
size_t etile_frame_bytes(const struct etile *e);

struct encq_stats {
	uint64_t encoded;  /* encodings made (one per tile key and codec while cached) */
	uint64_t shared;   /* requests answered by an encoding already made or under way */
	uint64_t failed;   /* encodings that failed */
	uint64_t evicted;  /* encodings the budget let go */
	uint64_t bytes;	   /* bytes the cache holds (see Memory above) */
	uint64_t entries;  /* encodings it holds */
	uint64_t queued;   /* encodings waiting for or in an encoder thread */
};

struct encq;
/* Wakes the session of a waiting ready_src (not dead) whose encoding became ready. */
typedef void (*encq_wake_fn)(struct session *s);

/* Starts nthreads encoders (at least 1) and a cache of budget bytes. Returns 0 or -errno
 * (eventfd, threads) with *out NULL. */
int encq_create(unsigned nthreads, uint64_t budget, encq_wake_fn wake, struct encq **out);
/* Stops the threads (queued encodings are dropped) and frees the cache. Every etile still
 * referenced elsewhere stays valid until its last unref. NULL is a no-op. */
void encq_destroy(struct encq *q);
/* The eventfd the loop watches (readable when encodings are done: call encq_drain). */
int encq_fd(const struct encq *q);
/* The encoding codec of tile t (borrowed): a new reference, ready or under way. When not
 * ready, src (borrowed; a reference is taken) is woken once it is. lossy: a lossy codec's
 * knobs (NULL: its defaults), taken when the encoding is made; an encoding of the same key
 * and codec already cached is shared whatever its knobs were (a SIGHUP that changes
 * webp_quality applies to tiles encoded after it). */
struct etile *encq_get(struct encq *q, struct tile *t, enum tcodec codec,
		       const struct tilecodec_lossy_opts *lossy, struct ready_src *src);
/* Takes the finished encodings back, marks them ready, wakes their waiters and applies the
 * budget. */
void encq_drain(struct encq *q);
void encq_stats(const struct encq *q, struct encq_stats *out);

#endif
