/* store — the storage tiers under the memory cache: a small vtable (as renderd's storage
 * backends) with get / contains / put / delete / iterate / stat / flush, and the value format
 * every backend stores. The scheduler tries memory (cache.h), then a store, then generation.
 *
 * Keys are content-addressed: the producing node's content hash and the tile's level and
 * position (struct tile_key), so a planet change misses naturally and stale entries are only
 * garbage to collect. A value is the tile encoded with the tile codec (zstd at rest) behind a
 * 40-byte header carrying an XXH3-64 checksum of the header, the key and the payload; every
 * read verifies it, so a damaged entry is reported as corrupt, never served.
 *
 * Threads: every operation is thread-safe. get decodes with the caller's tilecodec (one per
 * thread). put and delete are write-behind: they queue and return at once; flush waits until
 * everything queued so far is durable.
 * Ownership: a store is owned by whoever opened it (store_destroy); tiles passed to put are
 * borrowed (the store takes its own reference); get returns an owned tile.
 */
#ifndef CLIPMAP_STORE_H
#define CLIPMAP_STORE_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "common/grid.h"
#include "common/pixfmt.h"
#include "common/tilecodec.h"
#include "tile.h"

struct tilecodec;
struct node;

/* Tier numbers as CACHE_ENTRIES reports them (docs/PROTOCOL.md). */
enum store_tier { STORE_TIER_NONE = 0, STORE_TIER_MEMORY = 1, STORE_TIER_DISK = 2,
		  STORE_TIER_REMOTE = 3 };

struct store_stats {
	uint64_t tiles;	      /* entries held */
	uint64_t bytes;	      /* bytes they take at rest (values rounded to pages, plus index) */
	uint64_t budget;      /* the byte budget (0: none) */
	uint64_t file_bytes;  /* size of the backing file(s) */
	uint64_t hits;	      /* gets that returned a tile */
	uint64_t misses;      /* gets and contains that found nothing */
	uint64_t puts;	      /* tiles written (committed) */
	uint64_t evictions;   /* entries dropped to stay under the budget */
	uint64_t evictions_prefetched; /* of them, entries kept for prefetch (STORE_KEEP_PREFETCHED):
					* what operators prefetched no longer all on disk */
	uint64_t corrupt;     /* entries that failed their checksum (dropped) */
	uint64_t write_drops; /* puts dropped because the write queue was full */
	uint64_t write_errors; /* batches that failed to commit (disk full, I/O error) */
	uint64_t queued;      /* writes queued or being committed */
	uint64_t recovered;   /* times the file failed at run time (MDB_PANIC, MDB_CORRUPTED…)
			       * and was moved aside and recreated empty */
	int last_write;	      /* the last batch: 1 committed, -1 failed, 0 none yet */
};

/* Why a tile was stored, which decides the eviction order: incidental tiles (what viewers
 * happened to ask for) go first, least recently used first; prefetched tiles (what an operator
 * asked to keep ready) only when no incidental one is left. */
enum store_keep {
	STORE_KEEP_INCIDENTAL = 0,
	STORE_KEEP_PREFETCHED = 1,
};

/* One entry, as iterate reports it. */
struct store_entry {
	struct tile_key key;
	uint32_t bytes;	      /* the value's length */
	uint64_t stamp;	      /* last use, a store-wide increasing counter (larger: more recent) */
	enum store_keep keep;
};

typedef int (*store_iter_fn)(void *ud, const struct store_entry *e);
/* verify's report: an entry, and whether its value passed (ok) — a damaged one was counted
 * (corrupt) and its removal queued. Non-zero stops. */
typedef int (*store_verify_fn)(void *ud, const struct store_entry *e, bool ok);

struct store;

struct store_ops {
	const char *name;
	/* The tile for k, decoded with tc (caller's scratch), as an owned reference in *out;
	 * type and size are what the caller expects (a stored tile of another format or size is
	 * a miss). Returns 0, -ENOENT (absent), -EBADMSG (corrupt: counted and dropped) or
	 * -errno. A hit also refreshes the entry's recency (write-behind). */
	int (*get)(struct store *s, const struct tile_key *k, enum pix_type type, uint32_t size,
		   struct tilecodec *tc, struct tile **out);
	/* Whether k is present (no checksum, no decode; a miss is counted). The caller is
	 * about to get it: a backend may start reading the value in the background (the disk
	 * tier asks the kernel to read the value's pages in, so loads queued one after another
	 * overlap their I/O instead of faulting a page at a time). */
	bool (*contains)(struct store *s, const struct tile_key *k);
	/* Queues t for writing with its eviction class (an entry once prefetched stays so);
	 * returns 0, or -EAGAIN when the queue is full (counted: the tile is simply not
	 * stored). Never waits for I/O. */
	int (*put)(struct store *s, struct tile *t, enum store_keep keep);
	/* Queues the removal of k. Returns 0 or -EAGAIN. */
	int (*del)(struct store *s, const struct tile_key *k);
	/* Calls fn for every entry (key order) from one consistent snapshot; stops when fn
	 * returns non-zero and returns that, else 0 or -errno. fn must not call the store. */
	int (*iterate)(struct store *s, store_iter_fn fn, void *ud);
	/* Checks every value (header, checksum over key and payload; not decoded) from one
	 * snapshot, calling fn for each; stops when fn returns non-zero and returns that, else 0
	 * or -errno. fn must not call the store. */
	int (*verify)(struct store *s, store_verify_fn fn, void *ud);
	void (*stat)(struct store *s, struct store_stats *out);
	/* Waits until every write queued before the call is committed; 0 or the first write
	 * error since the last flush. */
	int (*flush)(struct store *s);
	/* Flushes what is queued, stops the backend's threads and frees it. */
	void (*destroy)(struct store *s);
};

/* Every backend embeds this first. */
struct store {
	const struct store_ops *ops;
};

/* Whether tiles of node n go to the tiers below memory: those of the planet's published
 * layers (what clients ask for). Intermediate nodes stay in memory only: storing them would
 * multiply the writes (the procedural planet makes ~14 tiles per layer tile) for tiles a
 * stored layer tile no longer needs. */
bool store_keeps(const struct node *n);

/* Thin wrappers over the vtable (s must not be NULL, except store_destroy). */
static inline int store_get(struct store *s, const struct tile_key *k, enum pix_type type,
			    uint32_t size, struct tilecodec *tc, struct tile **out)
{
	return s->ops->get(s, k, type, size, tc, out);
}
static inline bool store_contains(struct store *s, const struct tile_key *k)
{
	return s->ops->contains(s, k);
}
static inline int store_put(struct store *s, struct tile *t, enum store_keep keep)
{
	return s->ops->put(s, t, keep);
}
static inline int store_del(struct store *s, const struct tile_key *k) { return s->ops->del(s, k); }
static inline int store_iterate(struct store *s, store_iter_fn fn, void *ud)
{
	return s->ops->iterate(s, fn, ud);
}
static inline void store_stat(struct store *s, struct store_stats *out) { s->ops->stat(s, out); }
static inline int store_verify(struct store *s, store_verify_fn fn, void *ud)
{
	return s->ops->verify(s, fn, ud);
}
static inline int store_flush(struct store *s) { return s->ops->flush(s); }
void store_destroy(struct store *s); /* NULL is a no-op */

/* ---- the disk tier (store_lmdb.c) ---- */

struct store_lmdb_desc {
	const char *path;     /* the LMDB file (MDB_NOSUBDIR; PATH-lock beside it); required */
	uint64_t budget;      /* bytes at rest to stay under; 0: 1 GiB */
	size_t queue_max;     /* writes queued before puts are dropped; 0: 1024 */
	uint64_t queue_bytes; /* raw tile bytes queued before puts are dropped; 0: 256 MiB */
	int zstd_level;	      /* 0: 1 */
	enum tcodec codec;    /* what is written: TCODEC_LZ4, else (0 too) zstd; either is read */
};

/* Opens (creating) the store file. Returns 0 with *out owned, or -errno with err filled. A
 * file LMDB cannot read (damaged, not LMDB) is renamed PATH.corrupt-TIME and an empty store
 * created: then 0 is returned with err saying so (err[0] is '\0' otherwise — clear it first).
 * The same happens at run time when LMDB reports the file damaged (MDB_PANIC, MDB_CORRUPTED,
 * MDB_PAGE_NOTFOUND) to a read or a write: the writer thread moves it aside and recreates it
 * (counted in store_stats.recovered); reads meanwhile miss, and the caller generates. */
int store_lmdb_open(const struct store_lmdb_desc *d, struct store **out, char err[256]);

/* ---- a store file shared with other processes (clipmapctl render --store, clipmapview
 * --store; the rules: clipmapd.conf(5), [store] path) ---- */

/* Opens the store file at path with a budget of mb MiB (0: 1024, clipmapd's disk_mb default).
 * Returns as store_lmdb_open (a note in err on success when the file was moved aside). */
int store_open_file(const char *path, uint32_t mb, struct store **out, char err[256]);
/* Commits what is queued, then writes what the store did into line: "N hits, M misses, K
 * tiles written, C corrupt; T tiles in it". */
void store_summary(struct store *s, char *line, size_t n);

/* ---- the value format (shared by backends; pure) ---- */

#define STORE_KEY_LEN 18  /* node u64, lx u8, ly u8, x u32, y u32 — big-endian, so key order
			   * groups a node's tiles by level */
#define STORE_HDR_LEN 40

void store_key_encode(const struct tile_key *k, uint8_t out[STORE_KEY_LEN]);
/* Returns 0 or -EINVAL (wrong length). */
int store_key_decode(const void *p, size_t n, struct tile_key *k);
/* Encodes tile t under key kb into a new buffer (*out, owned by the caller: free) of *n bytes:
 * header + tile codec payload (the format's default filter, then codec: TCODEC_LZ4, else zstd
 * at `level`). Decoding reads the codec from the value: a store may hold both. */
void store_value_encode(struct tilecodec *tc, const struct tile *t, enum tcodec codec, int level,
			void **out, size_t *n);
/* Whether value v (n bytes) stored under kb has a sound header and checksum (the payload is
 * not decoded). Returns 0 or -EBADMSG. */
int store_value_check(const uint8_t kb[STORE_KEY_LEN], const void *v, size_t n);
/* Verifies value v (n bytes, borrowed: may point into a map) stored under kb and decodes it
 * into a new tile of the expected type and size (*out, owned). Returns 0, -ENOENT (a tile of
 * another type or size: not this one), or -EBADMSG (checksum, header or payload damaged). */
int store_value_decode(struct tilecodec *tc, const uint8_t kb[STORE_KEY_LEN], const void *v,
		       size_t n, const struct tile_key *k, enum pix_type type, uint32_t size,
		       struct tile **out);

#endif
