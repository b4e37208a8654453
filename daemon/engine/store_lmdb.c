/* store_lmdb — the disk tier: one LMDB file (MDB_NOSUBDIR) with four databases:
 *   tiles  key (18 bytes, store.h) → value (store.c's format: header, checksum, zstd payload)
 *   meta   key → stamp u64, accounted bytes u32, value length u32 (little-endian), keep u8
 *   lru    keep u8 ‖ stamp u64 big-endian ‖ key → empty: incidental entries oldest first,
 *          then prefetched ones oldest first — the order eviction takes them in
 *   info   "totals" → accounted bytes u64, tiles u64, next stamp u64 (little-endian)
 * A stamp is a store-wide counter (continued across restarts from the largest in lru), set on
 * write and refreshed on every hit (keeping the entry's class), so eviction takes lru's first
 * entries: prefetched tiles go only once no incidental one is left.
 *
 * Reads run on the caller's thread in a read-only transaction (MDB_NOTLS: any thread, any
 * number) and decode straight from the map. Every change goes through one writer thread:
 * put / touch / delete requests wait in a bounded queue (full: puts are dropped and counted);
 * the writer encodes the batch's tiles (zstd-1: smaller and faster than 3 after the
 * codec's filters, tests/bench/bench_store.c) before opening the write transaction, applies
 * the batch, evicts while the accounted bytes exceed the budget (down to 90 % of it), and
 * commits (fsync). On MDB_MAP_FULL it evicts a quarter more and retries the batch once.
 *
 * Accounting: a value larger than half a page lives in overflow pages, so it counts whole
 * pages; each entry adds a fixed estimate for its three index records. The map is the budget
 * plus half of it plus 32 MiB, room for copy-on-write pages of a batch and the free list.
 *
 * Reads see writes not yet committed: a miss in the file looks through the queue and the batch
 * being committed (newest first; a delete hides an older put), so a tile put a moment ago is
 * found — bulk work written only to the store is not generated twice while it waits.
 *
 * Several processes, one file (clipmapd and `clipmapctl render --store`, docs/man/clipmapd.8):
 * LMDB serialises write transactions across processes, and every one reads the totals from
 * info when it begins and writes them back before it commits, so each writer accounts and
 * evicts against what the file holds, whoever wrote it; stamps continue from info's, so the
 * LRU order is one order for every process. Each process evicts down to its own budget (the
 * smallest budget wins: give them the same). stat re-reads info, so it counts the other
 * processes' tiles too. The map is at least as large as the file's (another process may have
 * opened it with a larger budget).
 *
 * Locks: mu protects the queue, the batch's count (inflight: the batch's keys and tiles may
 * be read under mu while it is non-zero), the stop flag, the flush sequence numbers and the
 * write error; nothing is encoded or written under it. Counters are atomics. The accounted
 * bytes, tile count and stamp are atomics too: the writer sets them after each commit and stat
 * from the file's totals.
 */
#include <errno.h>
#include <lmdb.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "common/errbuf.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "store.h"

#define META_LEN 17
#define LRU_LEN (1 + 8 + STORE_KEY_LEN)
#define ENTRY_OVERHEAD 128 /* three index records, estimated */
#define BATCH_MAX 256

enum wop_kind { W_NONE = 0, W_PUT, W_TOUCH, W_DEL };

struct wop {
	enum wop_kind kind;
	struct tile *t; /* W_PUT: owned reference */
	uint8_t keep;	/* W_PUT: enum store_keep */
	struct tile_key key;
	void *val; /* W_PUT: the encoded value (writer) */
	size_t vlen;
};

struct lstore {
	struct store base;
	MDB_env *env;
	MDB_dbi tiles, meta, lru, info;
	char *path;
	uint64_t budget, mapsize;
	size_t psize;
	int level;
	enum tcodec codec;
	size_t qmax;
	uint64_t qbytes_max;

	pthread_t writer;
	/* Readers and the writer's transactions hold it shared; the writer holds it exclusive
	 * while it replaces a damaged file (env is NULL if that failed). */
	pthread_rwlock_t envlock;
	atomic_bool broken; /* LMDB said the file is damaged: the writer replaces it */
	pthread_mutex_t mu; /* protects the fields up to `stop` */
	pthread_cond_t cv;  /* the writer waits for work */
	pthread_cond_t done_cv; /* flushers wait for done_seq */
	struct wop *q;
	size_t qn, inflight; /* queued, and taken by the writer but not yet committed */
	uint64_t qbytes;
	uint64_t enq_seq, done_seq;
	int flush_err;
	bool stop;

	/* Writer only. */
	struct wop *batch;
	struct tilecodec *tc;

	atomic_uint_fast64_t bytes, ntiles, stamp;
	atomic_uint_fast64_t hits, misses, puts, evictions, corrupt, drops, werrs, queued;
	atomic_uint_fast64_t evictions_pf; /* of them, entries kept for prefetch */
	atomic_int last_write; /* store_stats.last_write */
	atomic_uint_fast64_t recovered;
};

/* Whether an LMDB code says the file itself is damaged (not one entry). */
static bool fatal(int rc)
{
	return rc == MDB_PANIC || rc == MDB_CORRUPTED || rc == MDB_PAGE_NOTFOUND;
}

/* A read or write met a damaged file: the writer replaces it at its next turn. */
static void mark_broken(struct lstore *s)
{
	atomic_store(&s->broken, true);
	xmutex_lock(&s->mu);
	xcond_signal(&s->cv);
	xmutex_unlock(&s->mu);
}

static void rdlock(struct lstore *s);
static void rwunlock(struct lstore *s);

/* mdb_txn_begin, first adopting a map another process sharing the file has grown
 * (MDB_MAP_RESIZED: it opened the file with a larger budget). Called with envlock held shared
 * and no transaction of the caller's open; takes the lock exclusive for the resize (no
 * transaction of this process is open then) and shared again. The exclusive lock is tried for
 * 2 s at most (a thread holding the lock shared twice, or a long listing, would keep it): then
 * this one attempt fails (MDB_MAP_RESIZED) and a later one resizes. */
static int begin(struct lstore *s, unsigned flags, MDB_txn **txn)
{
	int rc = s->env ? mdb_txn_begin(s->env, NULL, flags, txn) : EIO;
	if (rc != MDB_MAP_RESIZED)
		return rc;
	rwunlock(s);
	bool got = false;
	for (int i = 0; i < 2000 && !(got = pthread_rwlock_trywrlock(&s->envlock) == 0); i++)
		usleep(1000);
	if (got) {
		if (s->env)
			mdb_env_set_mapsize(s->env, 0);
		rwunlock(s);
	}
	rdlock(s);
	return s->env ? mdb_txn_begin(s->env, NULL, flags, txn) : EIO;
}

static void rdlock(struct lstore *s)
{
	if (pthread_rwlock_rdlock(&s->envlock))
		abort();
}

static void rwunlock(struct lstore *s)
{
	if (pthread_rwlock_unlock(&s->envlock))
		abort();
}

static int open_env(struct lstore *s, char err[256]);

static int mdb_errno(int rc)
{
	/* LMDB returns errno values or its own codes (negative, MDB_KEYEXIST and up). */
	if (rc == 0)
		return 0;
	if (rc > 0)
		return -rc;
	switch (rc) {
	case MDB_NOTFOUND: return -ENOENT;
	case MDB_MAP_FULL: return -ENOSPC;
	case MDB_READERS_FULL: return -EAGAIN;
	case MDB_CORRUPTED:
	case MDB_PAGE_NOTFOUND:
	case MDB_INVALID:
	case MDB_VERSION_MISMATCH: return -EBADMSG;
	default: return -EIO;
	}
}

static uint64_t at_rest(const struct lstore *s, size_t vlen)
{
	size_t p = s->psize;
	uint64_t v = vlen > p / 2 ? (vlen + 16 + p - 1) / p * p : vlen + 32;
	return v + ENTRY_OVERHEAD;
}

static void le64(uint8_t *p, uint64_t v)
{
	for (int i = 0; i < 8; i++, v >>= 8)
		p[i] = (uint8_t)v;
}
static uint64_t rle64(const uint8_t *p)
{
	uint64_t v = 0;
	for (int i = 7; i >= 0; i--)
		v = v << 8 | p[i];
	return v;
}
static void be64(uint8_t *p, uint64_t v)
{
	for (int i = 7; i >= 0; i--, v >>= 8)
		p[i] = (uint8_t)v;
}

struct meta {
	uint64_t stamp;
	uint32_t at_rest, vlen;
	uint8_t keep; /* enum store_keep */
};

static int meta_read(const MDB_val *m, struct meta *o)
{
	if (m->mv_size != META_LEN)
		return MDB_CORRUPTED;
	const uint8_t *p = m->mv_data;
	uint64_t av = rle64(p + 8);
	*o = (struct meta){ .stamp = rle64(p), .at_rest = (uint32_t)av,
			    .vlen = (uint32_t)(av >> 32), .keep = p[16] };
	return 0;
}

static void lru_key(uint8_t lk[LRU_LEN], uint8_t keep, uint64_t stamp,
		    const uint8_t kb[STORE_KEY_LEN])
{
	lk[0] = keep;
	be64(lk + 1, stamp);
	memcpy(lk + 9, kb, STORE_KEY_LEN);
}

#define TOTALS_LEN 24
static const char totals_key[] = "totals";

/* The file's totals (info) as txn sees them. Returns 0, or MDB_NOTFOUND (not written yet). */
static int totals_get(struct lstore *s, MDB_txn *txn, uint64_t *nb, uint64_t *nt,
		      uint64_t *stamp)
{
	MDB_val k = { sizeof totals_key - 1, (void *)totals_key }, v;
	int rc = mdb_get(txn, s->info, &k, &v);
	if (rc)
		return rc;
	if (v.mv_size != TOTALS_LEN)
		return MDB_NOTFOUND; /* foreign: recomputed by the next open */
	*nb = rle64(v.mv_data);
	*nt = rle64((const uint8_t *)v.mv_data + 8);
	*stamp = rle64((const uint8_t *)v.mv_data + 16);
	return 0;
}

static int totals_put(struct lstore *s, MDB_txn *txn, uint64_t nb, uint64_t nt, uint64_t stamp)
{
	uint8_t b[TOTALS_LEN];
	le64(b, nb);
	le64(b + 8, nt);
	le64(b + 16, stamp);
	MDB_val k = { sizeof totals_key - 1, (void *)totals_key }, v = { TOTALS_LEN, b };
	return mdb_put(txn, s->info, &k, &v, 0);
}

/* ---- the queue ---- */

/* Queues op (its tile reference taken). Returns 0 or -EAGAIN when full. */
static int enqueue(struct lstore *s, const struct wop *op)
{
	uint64_t nb = op->t ? op->t->nbytes : 0;
	/* Recency updates only use the first half of the queue, so a burst of hits (a viewer
	 * after a restart) never crowds out the tiles being generated. */
	size_t cap = op->kind == W_TOUCH ? s->qmax / 2 : s->qmax;
	xmutex_lock(&s->mu);
	if (s->stop || s->qn >= cap || (nb && s->qbytes + nb > s->qbytes_max)) {
		xmutex_unlock(&s->mu);
		return -EAGAIN;
	}
	s->q[s->qn++] = *op;
	s->qbytes += nb;
	s->enq_seq++;
	atomic_store(&s->queued, s->qn + s->inflight);
	if (s->qn == 1)
		xcond_signal(&s->cv);
	xmutex_unlock(&s->mu);
	return 0;
}

/* ---- the writer ---- */

/* Removes k's entry from the three databases in txn, updating the byte and tile counts;
 * *keep (optional) receives its class (0 when absent). */
static int remove_entry(struct lstore *s, MDB_txn *txn, const uint8_t kb[STORE_KEY_LEN],
			uint64_t *nb, uint64_t *nt, uint8_t *keep)
{
	MDB_val k = { STORE_KEY_LEN, (void *)kb }, m;
	if (keep)
		*keep = 0;
	int rc = mdb_get(txn, s->meta, &k, &m);
	if (rc == MDB_NOTFOUND) {
		rc = mdb_del(txn, s->tiles, &k, NULL); /* a value without meta: drop it too */
		return rc == MDB_NOTFOUND ? 0 : rc;
	}
	struct meta md;
	if (rc || (rc = meta_read(&m, &md)))
		return rc;
	if (keep)
		*keep = md.keep;
	uint8_t lk[LRU_LEN];
	lru_key(lk, md.keep, md.stamp, kb);
	MDB_val l = { LRU_LEN, lk };
	if ((rc = mdb_del(txn, s->lru, &l, NULL)) && rc != MDB_NOTFOUND)
		return rc;
	if ((rc = mdb_del(txn, s->meta, &k, NULL)))
		return rc;
	if ((rc = mdb_del(txn, s->tiles, &k, NULL)) && rc != MDB_NOTFOUND)
		return rc;
	*nb -= *nb >= md.at_rest ? md.at_rest : *nb;
	*nt -= *nt ? 1 : 0;
	return 0;
}

/* Records k's meta and lru records. */
static int stamp_entry(struct lstore *s, MDB_txn *txn, const uint8_t kb[STORE_KEY_LEN],
		       const struct meta *md)
{
	uint8_t mv[META_LEN], lk[LRU_LEN];
	le64(mv, md->stamp);
	le64(mv + 8, (uint64_t)md->vlen << 32 | md->at_rest);
	mv[16] = md->keep;
	lru_key(lk, md->keep, md->stamp, kb);
	MDB_val k = { STORE_KEY_LEN, (void *)kb }, m = { META_LEN, mv }, l = { LRU_LEN, lk },
		e = { 0, NULL };
	int rc = mdb_put(txn, s->meta, &k, &m, 0);
	return rc ? rc : mdb_put(txn, s->lru, &l, &e, 0);
}

static int touch_entry(struct lstore *s, MDB_txn *txn, const uint8_t kb[STORE_KEY_LEN],
		       uint64_t *stamp)
{
	MDB_val k = { STORE_KEY_LEN, (void *)kb }, m;
	int rc = mdb_get(txn, s->meta, &k, &m);
	if (rc == MDB_NOTFOUND)
		return 0;
	struct meta md;
	if (rc || (rc = meta_read(&m, &md)))
		return rc;
	uint8_t lk[LRU_LEN];
	lru_key(lk, md.keep, md.stamp, kb);
	MDB_val l = { LRU_LEN, lk };
	if ((rc = mdb_del(txn, s->lru, &l, NULL)) && rc != MDB_NOTFOUND)
		return rc;
	md.stamp = (*stamp)++;
	return stamp_entry(s, txn, kb, &md);
}

/* Entries a transaction evicted: all, and those kept for prefetch. */
struct evicted {
	uint64_t n, pf;
};

/* Evicts the least recent entries until *nb ≤ target. */
static int evict_to(struct lstore *s, MDB_txn *txn, uint64_t target, uint64_t *nb, uint64_t *nt,
		    struct evicted *evicted)
{
	int rc = 0;
	while (*nb > target && *nt > 0) {
		MDB_cursor *c;
		if ((rc = mdb_cursor_open(txn, s->lru, &c)))
			return rc;
		MDB_val l, e;
		rc = mdb_cursor_get(c, &l, &e, MDB_FIRST);
		/* Copied at once: a write in this transaction may move the page l points into. */
		uint8_t lk[LRU_LEN];
		bool bad = rc == 0 && l.mv_size != LRU_LEN;
		if (rc == 0 && !bad)
			memcpy(lk, l.mv_data, LRU_LEN);
		if (bad)
			rc = mdb_cursor_del(c, 0);
		mdb_cursor_close(c);
		if (rc == MDB_NOTFOUND) {
			/* Nothing left to rank: the accounting drifted; trust what is there. */
			*nb = 0;
			*nt = 0;
			return 0;
		}
		if (rc)
			return rc;
		if (bad)
			continue;
		uint64_t before = *nt;
		if ((rc = remove_entry(s, txn, lk + 9, nb, nt, NULL)))
			return rc;
		if (*nt == before) {
			/* An lru record without meta: drop the record itself. */
			MDB_val lv = { LRU_LEN, lk };
			if ((rc = mdb_del(txn, s->lru, &lv, NULL)) && rc != MDB_NOTFOUND)
				return rc;
		}
		evicted->n++;
		evicted->pf += lk[0] == STORE_KEEP_PREFETCHED;
	}
	return 0;
}

/* Applies ops[0..n) in one transaction. Returns 0 or an LMDB code. */
static int apply(struct lstore *s, struct wop *ops, size_t n, uint64_t extra_evict)
{
	MDB_txn *txn;
	int rc = begin(s, 0, &txn);
	if (rc)
		return rc;
	uint64_t nb = atomic_load(&s->bytes), nt = atomic_load(&s->ntiles);
	uint64_t stamp = atomic_load(&s->stamp), written = 0;
	struct evicted evicted = { 0 };
	/* what the file holds now: other processes may have written since our last batch */
	uint64_t fb, ft, fs;
	if ((rc = totals_get(s, txn, &fb, &ft, &fs)) == 0) {
		nb = fb;
		nt = ft;
		stamp = fs > stamp ? fs : stamp;
	} else if (rc != MDB_NOTFOUND) {
		mdb_txn_abort(txn);
		return rc;
	}
	rc = 0;
	if (extra_evict)
		rc = evict_to(s, txn, nb > extra_evict ? nb - extra_evict : 0, &nb, &nt, &evicted);
	for (size_t i = 0; i < n && rc == 0; i++) {
		struct wop *op = &ops[i];
		uint8_t kb[STORE_KEY_LEN];
		store_key_encode(&op->key, kb);
		if (op->kind == W_PUT) {
			uint8_t keep;
			if ((rc = remove_entry(s, txn, kb, &nb, &nt, &keep)))
				break;
			MDB_val k = { STORE_KEY_LEN, kb }, v = { op->vlen, op->val };
			if ((rc = mdb_put(txn, s->tiles, &k, &v, 0)))
				break;
			/* A tile once prefetched stays prefetched when written again. */
			struct meta md = { .stamp = stamp++, .at_rest = (uint32_t)at_rest(s, op->vlen),
					   .vlen = (uint32_t)op->vlen,
					   .keep = keep > op->keep ? keep : op->keep };
			if ((rc = stamp_entry(s, txn, kb, &md)))
				break;
			nb += md.at_rest;
			nt++;
			written++;
		} else if (op->kind == W_TOUCH) {
			rc = touch_entry(s, txn, kb, &stamp);
		} else if (op->kind == W_DEL) {
			rc = remove_entry(s, txn, kb, &nb, &nt, NULL);
		}
	}
	if (rc == 0 && s->budget && nb > s->budget)
		rc = evict_to(s, txn, s->budget / 10 * 9, &nb, &nt, &evicted);
	if (rc == 0)
		rc = totals_put(s, txn, nb, nt, stamp);
	if (rc == 0)
		rc = mdb_txn_commit(txn);
	else
		mdb_txn_abort(txn);
	if (rc == 0) {
		atomic_store(&s->bytes, nb);
		atomic_store(&s->ntiles, nt);
		atomic_store(&s->stamp, stamp);
		atomic_fetch_add(&s->evictions, evicted.n);
		atomic_fetch_add(&s->evictions_pf, evicted.pf);
		atomic_fetch_add(&s->puts, written);
	}
	return rc;
}

/* Moves the damaged file aside (PATH.corrupt-TIME) and opens an empty one in its place;
 * nobody reads meanwhile. Writer thread. */
static void replace_file(struct lstore *s)
{
	if (pthread_rwlock_wrlock(&s->envlock))
		abort();
	atomic_store(&s->broken, false);
	if (s->env)
		mdb_env_close(s->env);
	s->env = NULL;
	char aside[600], lock[600], err[256];
	snprintf(aside, sizeof aside, "%s.corrupt-%lld", s->path, (long long)time(NULL));
	snprintf(lock, sizeof lock, "%s-lock", s->path);
	if (rename(s->path, aside) != 0)
		unlink(s->path);
	unlink(lock);
	if (open_env(s, err) == 0)
		atomic_fetch_add(&s->recovered, 1);
	rwunlock(s);
}

static void *writer_main(void *arg)
{
	struct lstore *s = arg;
	xthread_batch("store-writer");
	xmutex_lock(&s->mu);
	for (;;) {
		while (!s->stop && s->qn == 0 && !atomic_load(&s->broken))
			xcond_wait(&s->cv, &s->mu);
		if (atomic_load(&s->broken)) {
			xmutex_unlock(&s->mu);
			replace_file(s);
			xmutex_lock(&s->mu);
			continue;
		}
		if (s->qn == 0)
			break; /* stopping and drained */
		size_t n = s->qn < BATCH_MAX ? s->qn : BATCH_MAX;
		memcpy(s->batch, s->q, n * sizeof *s->q);
		memmove(s->q, s->q + n, (s->qn - n) * sizeof *s->q);
		s->qn -= n;
		uint64_t seq = s->enq_seq - s->qn; /* every op up to this one is in the batch */
		for (size_t i = 0; i < n; i++)
			if (s->batch[i].t)
				s->qbytes -= s->batch[i].t->nbytes;
		s->inflight = n;
		atomic_store(&s->queued, s->qn + n); /* the batch counts until committed */
		xmutex_unlock(&s->mu);

		for (size_t i = 0; i < n; i++) {
			struct wop *op = &s->batch[i];
			if (op->kind == W_PUT)
				store_value_encode(s->tc, op->t, s->codec, s->level, &op->val,
						   &op->vlen);
		}
		rdlock(s);
		int rc = s->env ? apply(s, s->batch, n, 0) : EIO;
		if (rc == MDB_MAP_FULL)
			rc = apply(s, s->batch, n, s->budget / 4 + (uint64_t)s->psize * 64);
		rwunlock(s);
		if (rc)
			atomic_fetch_add(&s->werrs, 1);
		atomic_store(&s->last_write, rc ? -1 : 1);
		/* MDB_BAD_TXN: LMDB met a damaged page inside the transaction (it flags the
		 * transaction and fails what follows) */
		if (fatal(rc) || rc == MDB_BAD_TXN)
			mark_broken(s); /* the batch is lost; the file is replaced next */

		xmutex_lock(&s->mu);
		s->inflight = 0; /* readers no longer look at the batch */
		xmutex_unlock(&s->mu);
		for (size_t i = 0; i < n; i++) {
			free(s->batch[i].val);
			s->batch[i].val = NULL;
			tile_unref(s->batch[i].t);
			s->batch[i].t = NULL;
		}

		xmutex_lock(&s->mu);
		s->done_seq = seq;
		atomic_store(&s->queued, s->qn);
		if (rc && !s->flush_err)
			s->flush_err = mdb_errno(rc);
		xcond_broadcast(&s->done_cv);
	}
	xmutex_unlock(&s->mu);
	return NULL;
}

/* ---- the vtable ---- */

/* The newest queued or in-flight put or delete of k (not yet committed): a new reference to
 * the put's tile in *t (NULL for a delete). Returns whether there is one. */
static bool pending(struct lstore *s, const struct tile_key *k, struct tile **t)
{
	bool found = false;
	*t = NULL;
	xmutex_lock(&s->mu);
	for (size_t i = s->qn; i-- > 0 && !found;)
		if (s->q[i].kind != W_TOUCH && grid_key_equal(&s->q[i].key, k)) {
			found = true;
			*t = s->q[i].kind == W_PUT ? tile_ref(s->q[i].t) : NULL;
		}
	for (size_t i = s->inflight; i-- > 0 && !found;)
		if (s->batch[i].kind != W_TOUCH && grid_key_equal(&s->batch[i].key, k)) {
			found = true;
			*t = s->batch[i].kind == W_PUT ? tile_ref(s->batch[i].t) : NULL;
		}
	xmutex_unlock(&s->mu);
	return found;
}

static int l_get(struct store *base, const struct tile_key *k, enum pix_type type, uint32_t size,
		 struct tilecodec *tc, struct tile **out)
{
	struct lstore *s = (struct lstore *)base;
	*out = NULL;
	uint8_t kb[STORE_KEY_LEN];
	store_key_encode(k, kb);
	MDB_txn *txn;
	rdlock(s);
	int rc = begin(s, MDB_RDONLY, &txn);
	if (rc) {
		rwunlock(s);
		if (fatal(rc))
			mark_broken(s);
		atomic_fetch_add(&s->misses, 1);
		return -ENOENT; /* the caller generates */
	}
	MDB_val key = { STORE_KEY_LEN, kb }, v;
	rc = mdb_get(txn, s->tiles, &key, &v);
	bool broken = fatal(rc);
	if (rc == 0)
		rc = store_value_decode(tc, kb, v.mv_data, v.mv_size, k, type, size, out);
	else
		rc = broken ? -ENOENT : mdb_errno(rc);
	mdb_txn_abort(txn);
	rwunlock(s);
	if (broken)
		mark_broken(s);
	struct tile *pt;
	if (rc == -ENOENT && pending(s, k, &pt)) {
		if (pt && pt->type == type && pt->size == size) {
			atomic_fetch_add(&s->hits, 1);
			*out = pt;
			return 0;
		}
		tile_unref(pt);
	}
	if (rc == -EBADMSG) {
		atomic_fetch_add(&s->corrupt, 1);
		enqueue(s, &(struct wop){ .kind = W_DEL, .key = *k });
	} else if (rc) {
		atomic_fetch_add(&s->misses, 1);
	} else {
		atomic_fetch_add(&s->hits, 1);
		enqueue(s, &(struct wop){ .kind = W_TOUCH, .key = *k });
	}
	return rc;
}

/* Asks the kernel to read a value's pages in the background (its mapping has no read-ahead:
 * MDB_NORDAHEAD). A value in overflow pages is contiguous in the file; faulted a page at a
 * time, a 150 KiB height tile out of the page cache took ~40 synchronous reads on the worker
 * that loaded it (tests/bench/bench_store.c: 725 tiles/s against 3 077 with this hint). Only
 * a hint: if a writer frees and reuses those pages before the load, the read was wasted, and
 * a failure loses nothing. */
static void read_soon(const struct lstore *s, const void *p, size_t n)
{
	if (n <= s->psize / 2)
		return; /* in its leaf page, which the lookup just read */
	uintptr_t a = (uintptr_t)p & ~(uintptr_t)(s->psize - 1);
	(void)madvise((void *)a, (uintptr_t)p + n - a, MADV_WILLNEED);
}

static bool l_contains(struct store *base, const struct tile_key *k)
{
	struct lstore *s = (struct lstore *)base;
	uint8_t kb[STORE_KEY_LEN];
	store_key_encode(k, kb);
	MDB_txn *txn;
	rdlock(s);
	int rc = begin(s, MDB_RDONLY, &txn);
	if (rc) {
		rwunlock(s);
		if (fatal(rc))
			mark_broken(s);
		atomic_fetch_add(&s->misses, 1);
		return false;
	}
	MDB_val key = { STORE_KEY_LEN, kb }, v;
	rc = mdb_get(txn, s->tiles, &key, &v);
	bool found = rc == 0;
	if (found)
		read_soon(s, v.mv_data, v.mv_size);
	mdb_txn_abort(txn);
	rwunlock(s);
	if (fatal(rc))
		mark_broken(s);
	struct tile *pt;
	if (!found && pending(s, k, &pt)) {
		found = pt != NULL;
		tile_unref(pt);
	}
	if (!found)
		atomic_fetch_add(&s->misses, 1);
	return found;
}

static int l_put(struct store *base, struct tile *t, enum store_keep keep)
{
	struct lstore *s = (struct lstore *)base;
	int rc = enqueue(s, &(struct wop){ .kind = W_PUT, .t = tile_ref(t), .key = t->key,
					   .keep = (uint8_t)keep });
	if (rc) {
		tile_unref(t);
		atomic_fetch_add(&s->drops, 1);
	}
	return rc;
}

static int l_del(struct store *base, const struct tile_key *k)
{
	return enqueue((struct lstore *)base, &(struct wop){ .kind = W_DEL, .key = *k });
}

/* A read transaction and a cursor on db, under the read lock: 0, or -errno (nothing held). */
static int read_cursor(struct lstore *s, MDB_dbi db, MDB_txn **txn, MDB_cursor **c)
{
	rdlock(s);
	int rc = begin(s, MDB_RDONLY, txn);
	if (rc) {
		rwunlock(s);
		if (fatal(rc))
			mark_broken(s);
		return mdb_errno(rc);
	}
	if ((rc = mdb_cursor_open(*txn, db, c))) {
		mdb_txn_abort(*txn);
		rwunlock(s);
		return mdb_errno(rc);
	}
	return 0;
}

/* Ends what read_cursor began; rc is the cursor walk's last LMDB code, r the callback's. */
static int end_cursor(struct lstore *s, MDB_txn *txn, MDB_cursor *c, int rc, int r)
{
	mdb_cursor_close(c);
	mdb_txn_abort(txn);
	rwunlock(s);
	if (fatal(rc))
		mark_broken(s);
	if (r)
		return r;
	return rc == MDB_NOTFOUND ? 0 : mdb_errno(rc);
}

static int l_iterate(struct store *base, store_iter_fn fn, void *ud)
{
	struct lstore *s = (struct lstore *)base;
	MDB_txn *txn;
	MDB_cursor *c;
	int rc = read_cursor(s, s->meta, &txn, &c);
	if (rc)
		return rc;
	MDB_val k, m;
	int r = 0;
	for (rc = mdb_cursor_get(c, &k, &m, MDB_FIRST); rc == 0 && r == 0;
	     rc = mdb_cursor_get(c, &k, &m, MDB_NEXT)) {
		struct store_entry e;
		struct meta md;
		if (store_key_decode(k.mv_data, k.mv_size, &e.key) || meta_read(&m, &md))
			continue;
		e.stamp = md.stamp;
		e.bytes = md.vlen;
		e.keep = (enum store_keep)md.keep;
		r = fn(ud, &e);
	}
	return end_cursor(s, txn, c, rc, r);
}

static int l_verify(struct store *base, store_verify_fn fn, void *ud)
{
	struct lstore *s = (struct lstore *)base;
	MDB_txn *txn;
	MDB_cursor *c;
	int rc = read_cursor(s, s->tiles, &txn, &c);
	if (rc)
		return rc;
	MDB_val k, v, m;
	int r = 0;
	for (rc = mdb_cursor_get(c, &k, &v, MDB_FIRST); rc == 0 && r == 0;
	     rc = mdb_cursor_get(c, &k, &v, MDB_NEXT)) {
		struct store_entry e = { .bytes = (uint32_t)v.mv_size };
		if (k.mv_size != STORE_KEY_LEN || store_key_decode(k.mv_data, k.mv_size, &e.key))
			continue;
		struct meta md;
		if (mdb_get(txn, s->meta, &k, &m) == 0 && meta_read(&m, &md) == 0) {
			e.stamp = md.stamp;
			e.keep = (enum store_keep)md.keep;
		}
		bool ok = store_value_check(k.mv_data, v.mv_data, v.mv_size) == 0;
		if (!ok) {
			atomic_fetch_add(&s->corrupt, 1);
			enqueue(s, &(struct wop){ .kind = W_DEL, .key = e.key });
		}
		r = fn(ud, &e, ok);
	}
	return end_cursor(s, txn, c, rc, r);
}

static void l_stat(struct store *base, struct store_stats *o)
{
	struct lstore *s = (struct lstore *)base;
	struct stat st;
	/* the file's totals: other processes' tiles count too */
	rdlock(s);
	MDB_txn *txn;
	if (begin(s, MDB_RDONLY, &txn) == 0) {
		uint64_t nb, nt, stamp;
		if (totals_get(s, txn, &nb, &nt, &stamp) == 0) {
			atomic_store(&s->bytes, nb);
			atomic_store(&s->ntiles, nt);
		}
		mdb_txn_abort(txn);
	}
	rwunlock(s);
	*o = (struct store_stats){
		.tiles = atomic_load(&s->ntiles), .bytes = atomic_load(&s->bytes),
		.budget = s->budget, .hits = atomic_load(&s->hits),
		.misses = atomic_load(&s->misses), .puts = atomic_load(&s->puts),
		.evictions = atomic_load(&s->evictions),
		.evictions_prefetched = atomic_load(&s->evictions_pf), .corrupt = atomic_load(&s->corrupt),
		.write_drops = atomic_load(&s->drops), .write_errors = atomic_load(&s->werrs),
		.last_write = atomic_load(&s->last_write),
		.queued = atomic_load(&s->queued), .recovered = atomic_load(&s->recovered),
		.file_bytes = stat(s->path, &st) == 0 ? (uint64_t)st.st_size : 0 };
}

static int l_flush(struct store *base)
{
	struct lstore *s = (struct lstore *)base;
	xmutex_lock(&s->mu);
	uint64_t want = s->enq_seq;
	while (s->done_seq < want)
		xcond_wait(&s->done_cv, &s->mu);
	int rc = s->flush_err;
	s->flush_err = 0;
	xmutex_unlock(&s->mu);
	return rc;
}

static void close_env(struct lstore *s)
{
	if (s->env)
		mdb_env_close(s->env);
	s->env = NULL;
}

/* Everything but the writer thread: the environment, the codec, the locks, the memory. */
static void free_store(struct lstore *s)
{
	close_env(s);
	tilecodec_destroy(s->tc);
	xmutex_destroy(&s->mu);
	xcond_destroy(&s->cv);
	xcond_destroy(&s->done_cv);
	pthread_rwlock_destroy(&s->envlock);
	free(s->q);
	free(s->batch);
	free(s->path);
	free(s);
}

static void l_destroy(struct store *base)
{
	struct lstore *s = (struct lstore *)base;
	xmutex_lock(&s->mu);
	s->stop = true;
	xcond_signal(&s->cv);
	xmutex_unlock(&s->mu);
	xthread_join(s->writer);
	for (size_t i = 0; i < s->qn; i++)
		tile_unref(s->q[i].t);
	free_store(s);
}

static const struct store_ops lmdb_ops = {
	.name = "lmdb", .get = l_get, .contains = l_contains, .put = l_put, .del = l_del,
	.iterate = l_iterate, .verify = l_verify, .stat = l_stat, .flush = l_flush, .destroy = l_destroy,
};

/* ---- opening ---- */

/* Opens the environment and the databases, and reads the accounting back. */
static int open_env(struct lstore *s, char err[256])
{
	int rc;
	if ((rc = mdb_env_create(&s->env))) {
		s->env = NULL;
		err_set(err, "%s: %s", s->path, mdb_strerror(rc));
		return mdb_errno(rc);
	}
	if ((rc = mdb_env_set_maxdbs(s->env, 4)) || (rc = mdb_env_set_maxreaders(s->env, 1024)) ||
	    (rc = mdb_env_set_mapsize(s->env, s->mapsize)) ||
	    (rc = mdb_env_open(s->env, s->path, MDB_NOSUBDIR | MDB_NOTLS | MDB_NORDAHEAD, 0644))) {
		err_set(err, "%s: %s", s->path, mdb_strerror(rc));
		close_env(s);
		return mdb_errno(rc);
	}
	int dead = 0;
	mdb_reader_check(s->env, &dead); /* slots of processes killed while reading */
	MDB_envinfo info;
	MDB_stat est;
	if ((rc = mdb_env_info(s->env, &info)) || (rc = mdb_env_stat(s->env, &est)))
		goto fail;
	s->psize = est.ms_psize;
	MDB_txn *txn;
	if ((rc = mdb_txn_begin(s->env, NULL, 0, &txn)))
		goto fail;
	if ((rc = mdb_dbi_open(txn, "tiles", MDB_CREATE, &s->tiles)) ||
	    (rc = mdb_dbi_open(txn, "meta", MDB_CREATE, &s->meta)) ||
	    (rc = mdb_dbi_open(txn, "lru", MDB_CREATE, &s->lru)) ||
	    (rc = mdb_dbi_open(txn, "info", MDB_CREATE, &s->info))) {
		mdb_txn_abort(txn);
		goto fail;
	}
	/* The accounting: the sum over meta; the next stamp: after lru's last. */
	MDB_cursor *c;
	MDB_val k, v;
	uint64_t nb = 0, nt = 0, stamp = 1;
	if ((rc = mdb_cursor_open(txn, s->meta, &c))) {
		mdb_txn_abort(txn);
		goto fail;
	}
	for (rc = mdb_cursor_get(c, &k, &v, MDB_FIRST); rc == 0;
	     rc = mdb_cursor_get(c, &k, &v, MDB_NEXT)) {
		struct meta md;
		if (meta_read(&v, &md) == 0) {
			nb += md.at_rest;
			stamp = md.stamp >= stamp ? md.stamp + 1 : stamp;
		}
		nt++;
	}
	mdb_cursor_close(c);
	if (rc != MDB_NOTFOUND) {
		mdb_txn_abort(txn);
		goto fail;
	}
	/* the totals every process sharing the file keeps up to date from now on */
	uint64_t fb, ft, fs;
	if (totals_get(s, txn, &fb, &ft, &fs) == 0 && fs > stamp)
		stamp = fs;
	if ((rc = totals_put(s, txn, nb, nt, stamp))) {
		mdb_txn_abort(txn);
		goto fail;
	}
	if ((rc = mdb_txn_commit(txn)))
		goto fail;
	/* another process may have opened the file with a larger map: never a smaller one */
	if ((rc = mdb_env_info(s->env, &info)))
		goto fail;
	if (info.me_mapsize > s->mapsize)
		s->mapsize = info.me_mapsize;
	atomic_store(&s->bytes, nb);
	atomic_store(&s->ntiles, nt);
	atomic_store(&s->stamp, stamp);
	return 0;
fail:
	err_set(err, "%s: %s", s->path, mdb_strerror(rc));
	close_env(s);
	return mdb_errno(rc);
}

int store_lmdb_open(const struct store_lmdb_desc *d, struct store **out, char err[256])
{
	*out = NULL;
	if (!d->path || !*d->path) {
		err_set(err, "store: no path");
		return -EINVAL;
	}
	struct lstore *s = xcalloc(1, sizeof *s);
	s->base.ops = &lmdb_ops;
	s->path = xstrdup(d->path);
	s->budget = d->budget ? d->budget : (uint64_t)1 << 30;
	s->mapsize = s->budget + s->budget / 2 + ((uint64_t)32 << 20);
	s->level = d->zstd_level ? d->zstd_level : 1;
	s->codec = d->codec == TCODEC_LZ4 ? TCODEC_LZ4 : TCODEC_ZSTD;
	s->qmax = d->queue_max ? d->queue_max : 1024;
	s->qbytes_max = d->queue_bytes ? d->queue_bytes : (uint64_t)256 << 20;
	int rc = open_env(s, err);
	if (rc == -EBADMSG) {
		/* A damaged or foreign file: move it aside and start an empty store. */
		char aside[600];
		snprintf(aside, sizeof aside, "%s.corrupt-%lld", s->path, (long long)time(NULL));
		if (rename(s->path, aside) == 0) {
			char lock[600];
			snprintf(lock, sizeof lock, "%s-lock", s->path);
			unlink(lock);
			rc = open_env(s, err);
			if (rc == 0)
				err_set(err, "%s was damaged: moved aside to %s", s->path, aside);
		}
	}
	if (rc) {
		free(s->path);
		free(s);
		return rc;
	}
	s->q = xcalloc(s->qmax, sizeof *s->q);
	s->batch = xcalloc(BATCH_MAX, sizeof *s->batch);
	s->tc = tilecodec_create();
	xmutex_init(&s->mu);
	xcond_init(&s->cv);
	xcond_init(&s->done_cv);
	pthread_rwlock_init(&s->envlock, NULL);
	atomic_init(&s->broken, false);
	if ((rc = xthread_create(&s->writer, writer_main, s))) {
		err_set(err, "store writer thread: %s", strerror(-rc));
		free_store(s);
		return rc;
	}
	*out = &s->base;
	return 0;
}
