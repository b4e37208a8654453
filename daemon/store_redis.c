/* store_redis — see store_redis.h. Design note:
 *
 * Health: `up` says whether Redis is reachable. Any failed connection or command marks it down
 * (logged once, the idle connections of that epoch dropped); only the waiter thread dials
 * again, with backoff (100 ms doubling to 5 s), and marks it up (logged once). While down, get
 * answers "generate" without touching the network, writes are dropped, waits are woken.
 *
 * get is one round trip: a Lua script returns the value if there is one, else takes the lease
 * (SET NX PX; this daemon's own lease is renewed, so a job cancelled and wanted again does not
 * wait for itself) or reports another holder. confirm, right before generating, renews it the
 * same way (a job may have queued for longer than the lease). Waiting is polling, not pub/sub: the waiter
 * thread sends one pipeline of EXISTS value / EXISTS lease for every due key (backoff per key
 * from 2 ms to 50 ms), which needs no subscriber connection, notices a dead holder's expired
 * lease the same way as a finished tile, and costs one round trip per poll for all waits.
 */
#include "store_redis.h"

#include <errno.h>
#include <hiredis/hiredis.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/log.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/store.h"

#define POOL_MAX 16
#define BATCH_MAX 64
#define KEY_HEX (2 * STORE_KEY_LEN)
#define NAME_LEN (KEY_HEX + 8) /* "cm:t:{" HEX "}" */
#define POLL_MIN_NS 2000000ull
#define POLL_MAX_NS 50000000ull
#define BACKOFF_MIN_NS 100000000ull
#define BACKOFF_MAX_NS 5000000000ull
#define CMD_TIMEOUT_MS 1000

/* KEYS[1] value, KEYS[2] lease; ARGV[1] owner, ARGV[2] lease ms, ARGV[3] mode: "1" return
 * the value if present, "2" delete the (bad) value first. Returns the value, 0 (the lease is
 * ours: generate) or 1 (another daemon holds it). */
static const char LEASE_LUA[] =
	"if ARGV[3] == '1' then local v = redis.call('GET', KEYS[1]) if v then return v end "
	"else redis.call('DEL', KEYS[1]) end "
	"local l = redis.call('GET', KEYS[2]) "
	"if not l then redis.call('SET', KEYS[2], ARGV[1], 'PX', ARGV[2]) return 0 end "
	"if l == ARGV[1] then redis.call('PEXPIRE', KEYS[2], ARGV[2]) return 0 end "
	"return 1";

/* KEYS[1] value, KEYS[2] lease; ARGV[1] owner, ARGV[2] lease ms. Returns 0 (the lease is ours
 * again, renewed) or 1 (another daemon holds it, or the tile exists). */
static const char CONFIRM_LUA[] =
	"if redis.call('EXISTS', KEYS[1]) == 1 then return 1 end "
	"local l = redis.call('GET', KEYS[2]) "
	"if l and l ~= ARGV[1] then return 1 end "
	"redis.call('SET', KEYS[2], ARGV[1], 'PX', ARGV[2]) return 0";

/* KEYS[1] value, KEYS[2] lease; ARGV[1] owner, ARGV[2] the value. Writes the value and drops
 * the lease if it is still ours: returns 0, or 1 when it was not ours any more (expired). */
static const char PUT_LUA[] =
	"redis.call('SET', KEYS[1], ARGV[2]) "
	"if redis.call('GET', KEYS[2]) == ARGV[1] then redis.call('DEL', KEYS[2]) return 0 end "
	"return 1";

/* KEYS[1] lease; ARGV[1] owner. Drops the lease if it is ours. */
static const char RELEASE_LUA[] =
	"if redis.call('GET', KEYS[1]) == ARGV[1] then redis.call('DEL', KEYS[1]) end return 0";

enum wkind { W_PUT, W_RELEASE };

struct witem {
	enum wkind kind;
	struct tile_key key;
	struct tile *t; /* W_PUT: owned reference */
	bool leased;	/* W_PUT: generated under this daemon's lease */
};

struct waitent {
	struct tile_key key;
	void *token;
	uint64_t next_ns, step_ns, deadline_ns;
};

struct rds {
	struct remote base;
	char *addr, *password, *path, host[256];
	int port;
	uint32_t lease_ms;
	size_t queue_max;
	int zstd_level;
	char owner[96];

	/* Health. */
	atomic_bool up;
	atomic_uint epoch; /* bumped when marked down: older connections are dropped */
	pthread_mutex_t h_mu;
	uint64_t backoff_ns, retry_ns;

	/* Idle connections for get (under p_mu). */
	pthread_mutex_t p_mu;
	redisContext *pool[POOL_MAX];
	unsigned pool_epoch[POOL_MAX];
	int npool;

	/* The writer's queue (under w_mu). */
	pthread_mutex_t w_mu;
	pthread_cond_t w_cv, w_idle;
	struct witem *q;
	size_t qn, qcap, busy;
	bool w_stop;
	pthread_t writer;

	/* The waits (under a_mu, also held while waking). */
	pthread_mutex_t a_mu;
	pthread_cond_t a_cv;
	struct waitent *wt;
	size_t nwt, capwt;
	uint64_t a_gen; /* bumped by cancel_waits: a poll in flight is discarded */
	bool a_stop;
	pthread_t waiter;

	atomic_uint_fast64_t hits, misses, writes, drops, bad, waits, takeovers, expired, generated,
		errors;
};

static void key_names(const struct tile_key *k, char val[NAME_LEN], char lease[NAME_LEN])
{
	uint8_t kb[STORE_KEY_LEN];
	static const char hx[] = "0123456789abcdef";
	store_key_encode(k, kb);
	char h[KEY_HEX + 1];
	for (int i = 0; i < STORE_KEY_LEN; i++) {
		h[2 * i] = hx[kb[i] >> 4];
		h[2 * i + 1] = hx[kb[i] & 15];
	}
	h[KEY_HEX] = '\0';
	snprintf(val, NAME_LEN, "cm:t:{%s}", h);
	snprintf(lease, NAME_LEN, "cm:l:{%s}", h);
}

/* ---- health and connections ---- */

static void mark_down(struct rds *r, const char *why)
{
	atomic_fetch_add(&r->errors, 1);
	xmutex_lock(&r->h_mu);
	if (atomic_exchange(&r->up, false)) {
		atomic_fetch_add(&r->epoch, 1);
		r->backoff_ns = BACKOFF_MIN_NS;
		r->retry_ns = clock_now_ns() + r->backoff_ns;
		log_msg(LOG_WARN, "redis %s: unreachable (%s): serving from this daemon's own tiers "
			"and generation, retrying with backoff", r->addr, why);
	}
	xmutex_unlock(&r->h_mu);
}

/* A new connection (authenticated), or NULL with why filled. */
static redisContext *dial(struct rds *r, char why[128])
{
	struct timeval tv = { .tv_sec = 0, .tv_usec = 500000 };
	redisContext *c = r->path ? redisConnectUnixWithTimeout(r->path, tv)
				  : redisConnectWithTimeout(r->host, r->port, tv);
	if (!c) {
		snprintf(why, 128, "out of memory");
		return NULL;
	}
	if (c->err) {
		snprintf(why, 128, "%s", c->errstr);
		redisFree(c);
		return NULL;
	}
	redisSetTimeout(c, (struct timeval){ .tv_sec = CMD_TIMEOUT_MS / 1000,
					     .tv_usec = (CMD_TIMEOUT_MS % 1000) * 1000 });
	const char *cmd = r->password ? "AUTH %s" : "PING";
	redisReply *rep = r->password ? redisCommand(c, cmd, r->password) : redisCommand(c, cmd);
	bool ok = rep && rep->type != REDIS_REPLY_ERROR;
	if (!ok)
		snprintf(why, 128, "%s", rep ? rep->str : c->errstr);
	if (rep)
		freeReplyObject(rep);
	if (!ok) {
		redisFree(c);
		return NULL;
	}
	return c;
}

/* An idle or new connection for get, or NULL while Redis is down. *ep: its epoch. */
static redisContext *pool_take(struct rds *r, unsigned *ep)
{
	if (!atomic_load(&r->up))
		return NULL;
	unsigned cur = atomic_load(&r->epoch);
	redisContext *c = NULL;
	xmutex_lock(&r->p_mu);
	while (!c && r->npool > 0) {
		r->npool--;
		if (r->pool_epoch[r->npool] == cur)
			c = r->pool[r->npool];
		else
			redisFree(r->pool[r->npool]);
	}
	xmutex_unlock(&r->p_mu);
	if (c) {
		*ep = cur;
		return c;
	}
	char why[128];
	if (!(c = dial(r, why))) {
		mark_down(r, why);
		return NULL;
	}
	*ep = cur;
	return c;
}

static void pool_give(struct rds *r, redisContext *c, unsigned ep)
{
	if (!c)
		return;
	xmutex_lock(&r->p_mu);
	if (c->err == 0 && ep == atomic_load(&r->epoch) && r->npool < POOL_MAX) {
		r->pool[r->npool] = c;
		r->pool_epoch[r->npool++] = ep;
		c = NULL;
	}
	xmutex_unlock(&r->p_mu);
	if (c)
		redisFree(c);
}

/* ---- get ---- */

static int rds_get(struct remote *base, const struct tile_key *k, enum pix_type type,
		   uint32_t size, struct tilecodec *tc, bool retry, struct tile **out)
{
	struct rds *r = (struct rds *)base;
	*out = NULL;
	char val[NAME_LEN], lease[NAME_LEN], ms[16];
	key_names(k, val, lease);
	snprintf(ms, sizeof ms, "%u", r->lease_ms);
	const char *mode = "1";
	for (int attempt = 0; attempt < 3; attempt++) {
		unsigned ep;
		redisContext *c = pool_take(r, &ep);
		if (!c)
			return -ENOLINK; /* down: every daemon fends for itself */
		redisReply *rep = redisCommand(c, "EVAL %s 2 %s %s %s %s %s", LEASE_LUA, val, lease,
					       r->owner, ms, mode);
		if (!rep) {
			char why[128];
			snprintf(why, sizeof why, "%s", c->errstr);
			redisFree(c);
			if (attempt == 0)
				continue; /* a stale idle connection (Redis restarted): once more */
			mark_down(r, why);
			return -ENOLINK;
		}
		if (rep->type == REDIS_REPLY_ERROR) {
			/* Reachable but refusing (OOM under noeviction, a script error): this
			 * tile is generated here, unshared. */
			atomic_fetch_add(&r->errors, 1);
			freeReplyObject(rep);
			pool_give(r, c, ep);
			return -ENOLINK;
		}
		int rc;
		if (rep->type == REDIS_REPLY_STRING) {
			uint8_t kb[STORE_KEY_LEN];
			store_key_encode(k, kb);
			rc = store_value_decode(tc, kb, rep->str, rep->len, k, type, size, out);
			if (rc == 0) {
				atomic_fetch_add(&r->hits, 1);
			} else {
				/* Damaged (or not this tile): never served; delete it and take the
				 * lease as for a miss. */
				atomic_fetch_add(&r->bad, 1);
				mode = "2";
				freeReplyObject(rep);
				pool_give(r, c, ep);
				continue;
			}
		} else if (rep->type == REDIS_REPLY_INTEGER && rep->integer == 0) {
			atomic_fetch_add(&r->misses, 1);
			if (retry)
				atomic_fetch_add(&r->takeovers, 1); /* the holder never delivered */
			rc = -ENOENT;
		} else if (rep->type == REDIS_REPLY_INTEGER) {
			atomic_fetch_add(&r->misses, 1);
			atomic_fetch_add(&r->waits, 1);
			rc = -EINPROGRESS;
		} else {
			atomic_fetch_add(&r->errors, 1);
			rc = -ENOLINK;
		}
		freeReplyObject(rep);
		pool_give(r, c, ep);
		return rc;
	}
	return -ENOLINK;
}

static int rds_confirm(struct remote *base, const struct tile_key *k)
{
	struct rds *r = (struct rds *)base;
	char val[NAME_LEN], lease[NAME_LEN], ms[16];
	key_names(k, val, lease);
	snprintf(ms, sizeof ms, "%u", r->lease_ms);
	unsigned ep;
	redisContext *c = pool_take(r, &ep);
	if (!c)
		return 0; /* down: generate */
	redisReply *rep = redisCommand(c, "EVAL %s 2 %s %s %s %s", CONFIRM_LUA, val, lease,
				       r->owner, ms);
	int rc = 0;
	if (!rep) {
		char why[128];
		snprintf(why, sizeof why, "%s", c->errstr);
		redisFree(c);
		mark_down(r, why);
		return 0;
	}
	if (rep->type == REDIS_REPLY_INTEGER && rep->integer == 1) {
		atomic_fetch_add(&r->waits, 1);
		rc = -EINPROGRESS;
	} else if (rep->type != REDIS_REPLY_INTEGER) {
		atomic_fetch_add(&r->errors, 1);
	}
	freeReplyObject(rep);
	pool_give(r, c, ep);
	return rc;
}

/* ---- the writer ---- */

static void enqueue(struct rds *r, const struct witem *it)
{
	xmutex_lock(&r->w_mu);
	bool ok = atomic_load(&r->up) && !r->w_stop && r->qn < r->queue_max;
	if (ok) {
		if (r->qn == r->qcap) {
			r->qcap = r->qcap ? r->qcap * 2 : 64;
			r->q = xrealloc(r->q, r->qcap * sizeof *r->q);
		}
		r->q[r->qn++] = *it;
		xcond_signal(&r->w_cv);
	}
	xmutex_unlock(&r->w_mu);
	if (!ok) {
		if (it->kind == W_PUT)
			atomic_fetch_add(&r->drops, 1);
		tile_unref(it->t);
	}
}

static void rds_put(struct remote *base, struct tile *t, bool leased)
{
	struct rds *r = (struct rds *)base;
	atomic_fetch_add(&r->generated, 1);
	enqueue(r, &(struct witem){ .kind = W_PUT, .key = t->key, .t = tile_ref(t),
				    .leased = leased });
}

static void rds_release(struct remote *base, const struct tile_key *k)
{
	enqueue((struct rds *)base, &(struct witem){ .kind = W_RELEASE, .key = *k });
}

/* Sends one batch as a pipeline: each tile's value, dropping its lease if still ours in the
 * same script (so a waiter never sees neither); a tile generated without a lease is SET
 * alone; a release drops the lease if ours. Returns how many tiles were written; a lost
 * connection marks the tier down and frees *c. */
static uint64_t write_batch(struct rds *r, redisContext **c, struct tilecodec *tc, struct witem *b,
		       size_t n)
{
	for (size_t i = 0; i < n; i++) {
		char val[NAME_LEN], lease[NAME_LEN];
		key_names(&b[i].key, val, lease);
		if (b[i].kind == W_PUT) {
			uint8_t kb[STORE_KEY_LEN];
			void *v;
			size_t vn;
			store_key_encode(&b[i].key, kb);
			store_value_encode(tc, b[i].t, TCODEC_ZSTD, r->zstd_level, &v, &vn);
			if (b[i].leased)
				redisAppendCommand(*c, "EVAL %s 2 %s %s %s %b", PUT_LUA, val, lease,
						   r->owner, v, vn);
			else
				redisAppendCommand(*c, "SET %s %b", val, v, vn);
			free(v);
		} else {
			redisAppendCommand(*c, "EVAL %s 1 %s %s", RELEASE_LUA, lease, r->owner);
		}
	}
	/* One reply per item, in order. */
	int rc = 0;
	uint64_t written = 0;
	for (size_t i = 0; i < n; i++) {
		redisReply *rep = NULL;
		if (redisGetReply(*c, (void **)&rep) != REDIS_OK || !rep) {
			rc = -EIO;
			break;
		}
		if (rep->type == REDIS_REPLY_ERROR) { /* e.g. OOM under noeviction */
			atomic_fetch_add(&r->errors, 1);
		} else if (b[i].kind == W_PUT) {
			written++;
			if (rep->type == REDIS_REPLY_INTEGER && rep->integer == 1)
				atomic_fetch_add(&r->expired, 1);
		}
		freeReplyObject(rep);
	}
	atomic_fetch_add(&r->writes, written);
	if (rc) {
		mark_down(r, (*c)->errstr[0] ? (*c)->errstr : "write failed");
		redisFree(*c);
		*c = NULL;
	}
	return written;
}

static void *writer_main(void *arg)
{
	struct rds *r = arg;
	xthread_batch("redis-writer");
	struct tilecodec *tc = tilecodec_create();
	redisContext *c = NULL;
	unsigned cep = 0;
	struct witem batch[BATCH_MAX];
	xmutex_lock(&r->w_mu);
	for (;;) {
		while (!r->w_stop && r->qn == 0)
			xcond_wait(&r->w_cv, &r->w_mu);
		if (r->qn == 0)
			break; /* stopping with nothing left */
		size_t n = r->qn < BATCH_MAX ? r->qn : BATCH_MAX;
		memcpy(batch, r->q, n * sizeof *batch);
		memmove(r->q, r->q + n, (r->qn - n) * sizeof *r->q);
		r->qn -= n;
		r->busy = n;
		xmutex_unlock(&r->w_mu);

		if (c && cep != atomic_load(&r->epoch)) {
			redisFree(c);
			c = NULL;
		}
		if (!c && atomic_load(&r->up)) {
			char why[128];
			cep = atomic_load(&r->epoch);
			if (!(c = dial(r, why)))
				mark_down(r, why);
		}
		uint64_t puts = 0;
		for (size_t i = 0; i < n; i++)
			puts += batch[i].kind == W_PUT;
		uint64_t written = c ? write_batch(r, &c, tc, batch, n) : 0;
		atomic_fetch_add(&r->drops, puts - written); /* refused or connection lost */
		for (size_t i = 0; i < n; i++)
			tile_unref(batch[i].t);

		xmutex_lock(&r->w_mu);
		r->busy = 0;
		if (r->qn == 0)
			xcond_broadcast(&r->w_idle);
	}
	xmutex_unlock(&r->w_mu);
	if (c)
		redisFree(c);
	tilecodec_destroy(tc);
	return NULL;
}

/* ---- waits and health (the waiter thread) ---- */

static void rds_wait(struct remote *base, const struct tile_key *k, void *token)
{
	struct rds *r = (struct rds *)base;
	uint64_t now = clock_now_ns();
	xmutex_lock(&r->a_mu);
	if (r->nwt == r->capwt) {
		r->capwt = r->capwt ? r->capwt * 2 : 64;
		r->wt = xrealloc(r->wt, r->capwt * sizeof *r->wt);
	}
	/* Bounded: woken after four lease lifetimes whatever the polls saw (get decides again). */
	r->wt[r->nwt++] = (struct waitent){ .key = *k, .token = token, .next_ns = now + POLL_MIN_NS,
					    .step_ns = POLL_MIN_NS,
					    .deadline_ns = now + 4ull * r->lease_ms * 1000000ull };
	xcond_signal(&r->a_cv);
	xmutex_unlock(&r->a_mu);
}

static void rds_cancel_waits(struct remote *base)
{
	struct rds *r = (struct rds *)base;
	xmutex_lock(&r->a_mu); /* wakes run under it: none is running once we hold it */
	r->nwt = 0;
	r->a_gen++;
	xmutex_unlock(&r->a_mu);
}

/* Wakes wait i (under a_mu) and removes it. */
static void wake_at(struct rds *r, size_t i)
{
	void *token = r->wt[i].token;
	r->wt[i] = r->wt[--r->nwt];
	r->base.wake(r->base.wake_ud, token);
}

/* Polls the due waits; returns with a_mu held. Those whose tile arrived or whose lease is gone
 * are woken; the others back off. */
static void poll_due(struct rds *r, redisContext **c, uint64_t now)
{
	size_t cap = 256, n = 0;
	struct tile_key keys[256];
	for (size_t i = 0; i < r->nwt && n < cap; i++)
		if (r->wt[i].next_ns <= now)
			keys[n++] = r->wt[i].key;
	uint64_t gen = r->a_gen;
	xmutex_unlock(&r->a_mu);
	bool ok = true;
	uint8_t ready[256];
	for (size_t i = 0; i < n; i++) {
		char val[NAME_LEN], lease[NAME_LEN];
		key_names(&keys[i], val, lease);
		redisAppendCommand(*c, "EXISTS %s", val);
		redisAppendCommand(*c, "EXISTS %s", lease);
	}
	for (size_t i = 0; i < n && ok; i++) {
		long long v[2] = { 0, 0 };
		for (int j = 0; j < 2 && ok; j++) {
			redisReply *rep = NULL;
			ok = redisGetReply(*c, (void **)&rep) == REDIS_OK && rep &&
			     rep->type == REDIS_REPLY_INTEGER;
			if (ok)
				v[j] = rep->integer;
			if (rep)
				freeReplyObject(rep);
		}
		ready[i] = v[0] > 0 || v[1] == 0;
	}
	if (!ok) {
		mark_down(r, (*c)->errstr[0] ? (*c)->errstr : "poll failed");
		redisFree(*c);
		*c = NULL;
	}
	xmutex_lock(&r->a_mu);
	if (gen != r->a_gen || !ok)
		return; /* cancelled meanwhile; or down: the caller wakes everything */
	for (size_t k = 0; k < n; k++) {
		for (size_t i = 0; i < r->nwt; i++) {
			struct waitent *w = &r->wt[i];
			if (!grid_key_equal(&w->key, &keys[k]) || w->next_ns > now)
				continue;
			if (ready[k] || now >= w->deadline_ns) {
				wake_at(r, i);
			} else {
				w->step_ns = w->step_ns * 2 > POLL_MAX_NS ? POLL_MAX_NS : w->step_ns * 2;
				w->next_ns = now + w->step_ns;
			}
			break;
		}
	}
}

static void *waiter_main(void *arg)
{
	struct rds *r = arg;
	redisContext *c = NULL;
	unsigned cep = 0;
	uint64_t last_ping = 0;
	xmutex_lock(&r->a_mu);
	while (!r->a_stop) {
		uint64_t now = clock_now_ns();
		if (c && cep != atomic_load(&r->epoch)) {
			redisFree(c);
			c = NULL;
		}
		if (!atomic_load(&r->up)) {
			while (r->nwt > 0) /* nobody will deliver: let get decide (generate) */
				wake_at(r, r->nwt - 1);
			xmutex_lock(&r->h_mu);
			bool due = now >= r->retry_ns;
			xmutex_unlock(&r->h_mu);
			if (due) {
				xmutex_unlock(&r->a_mu);
				char why[128];
				unsigned ep = atomic_load(&r->epoch);
				redisContext *nc = dial(r, why);
				xmutex_lock(&r->h_mu);
				if (nc) {
					atomic_store(&r->up, true);
					log_msg(LOG_INFO, "redis %s: connected, sharing tiles", r->addr);
				} else {
					r->backoff_ns = r->backoff_ns * 2 > BACKOFF_MAX_NS
								? BACKOFF_MAX_NS
								: r->backoff_ns * 2;
					r->retry_ns = clock_now_ns() + r->backoff_ns;
				}
				xmutex_unlock(&r->h_mu);
				xmutex_lock(&r->a_mu);
				if (nc) {
					c = nc;
					cep = ep;
				}
				continue;
			}
			xcond_wait_until(&r->a_cv, &r->a_mu, now + BACKOFF_MIN_NS);
			continue;
		}
		if (!c) {
			xmutex_unlock(&r->a_mu);
			char why[128];
			cep = atomic_load(&r->epoch);
			c = dial(r, why);
			if (!c)
				mark_down(r, why);
			xmutex_lock(&r->a_mu);
			continue;
		}
		uint64_t next = now + 1000000000ull;
		bool due = false;
		for (size_t i = 0; i < r->nwt; i++) {
			if (r->wt[i].next_ns <= now)
				due = true;
			if (r->wt[i].next_ns < next)
				next = r->wt[i].next_ns;
		}
		if (due) {
			poll_due(r, &c, now);
			continue;
		}
		if (now - last_ping >= 1000000000ull) { /* idle: notice a Redis that went away */
			last_ping = now;
			xmutex_unlock(&r->a_mu);
			redisReply *rep = redisCommand(c, "PING");
			if (!rep) {
				mark_down(r, c->errstr[0] ? c->errstr : "ping failed");
				redisFree(c);
				c = NULL;
			} else {
				freeReplyObject(rep);
			}
			xmutex_lock(&r->a_mu);
			continue;
		}
		xcond_wait_until(&r->a_cv, &r->a_mu, next);
	}
	xmutex_unlock(&r->a_mu);
	if (c)
		redisFree(c);
	return NULL;
}

/* ---- stats, open, destroy ---- */

static void rds_stat(struct remote *base, struct remote_stats *o)
{
	struct rds *r = (struct rds *)base;
	*o = (struct remote_stats){
		.hits = atomic_load(&r->hits),
		.misses = atomic_load(&r->misses),
		.writes = atomic_load(&r->writes),
		.drops = atomic_load(&r->drops),
		.bad = atomic_load(&r->bad),
		.waits = atomic_load(&r->waits),
		.takeovers = atomic_load(&r->takeovers),
		.expired = atomic_load(&r->expired),
		.generated = atomic_load(&r->generated),
		.errors = atomic_load(&r->errors),
		.connected = atomic_load(&r->up) ? 1 : 0,
	};
}

static const struct remote_ops rds_ops = {
	.get = rds_get,
	.confirm = rds_confirm,
	.put = rds_put,
	.release = rds_release,
	.wait = rds_wait,
	.cancel_waits = rds_cancel_waits,
	.stat = rds_stat,
};

int store_redis_open(const struct store_redis_desc *d, struct remote **out, char err[256])
{
	*out = NULL;
	const char *a = d->addr ? d->addr : "";
	struct rds *r = xcalloc(1, sizeof *r);
	if (strncmp(a, "unix:", 5) == 0 && a[5]) {
		r->path = xstrdup(a + 5);
	} else {
		const char *colon = strrchr(a, ':');
		char *end = NULL;
		long port = colon ? strtol(colon + 1, &end, 10) : -1;
		size_t hl = colon ? (size_t)(colon - a) : 0;
		if (!colon || !end || *end || port <= 0 || port > 65535 || hl == 0 ||
		    hl >= sizeof r->host) {
			snprintf(err, 256, "redis address \"%s\" is not unix:/path or host:port", a);
			free(r);
			return -EINVAL;
		}
		memcpy(r->host, a, hl);
		if (hl > 2 && r->host[0] == '[' && r->host[hl - 1] == ']') {
			memmove(r->host, r->host + 1, hl - 2);
			r->host[hl - 2] = '\0';
		}
		r->port = (int)port;
	}
	r->base.ops = &rds_ops;
	r->addr = xstrdup(a);
	r->password = d->password ? xstrdup(d->password) : NULL;
	r->lease_ms = d->lease_ms ? d->lease_ms : 2000;
	r->queue_max = d->queue_max ? d->queue_max : 1024;
	r->zstd_level = d->zstd_level ? d->zstd_level : 1;
	char host[64] = "";
	gethostname(host, sizeof host - 1);
	snprintf(r->owner, sizeof r->owner, "%s:%ld:%llx", host, (long)getpid(),
		 (unsigned long long)clock_now_ns());
	xmutex_init(&r->h_mu);
	xmutex_init(&r->p_mu);
	xmutex_init(&r->w_mu);
	xmutex_init(&r->a_mu);
	xcond_init(&r->w_cv);
	xcond_init(&r->w_idle);
	xcond_init(&r->a_cv);
	/* Connected at once if Redis is up; else the waiter thread keeps trying. */
	char why[128];
	redisContext *c = dial(r, why);
	if (c) {
		atomic_store(&r->up, true);
		redisFree(c);
		log_msg(LOG_INFO, "redis %s: connected, sharing tiles (lease %u ms)", r->addr,
			r->lease_ms);
	} else {
		r->backoff_ns = BACKOFF_MIN_NS;
		r->retry_ns = clock_now_ns() + r->backoff_ns;
		atomic_fetch_add(&r->errors, 1);
		log_msg(LOG_WARN, "redis %s: unreachable (%s): serving from this daemon's own tiers "
			"and generation, retrying with backoff", r->addr, why);
	}
	int rc;
	if ((rc = xthread_create(&r->writer, writer_main, r)) ||
	    (rc = xthread_create(&r->waiter, waiter_main, r))) {
		fprintf(stderr, "store_redis: pthread_create: %s\n", strerror(rc));
		abort();
	}
	*out = &r->base;
	return 0;
}

void store_redis_destroy(struct remote *base)
{
	if (!base)
		return;
	struct rds *r = (struct rds *)base;
	/* What is queued is written if Redis answers (bounded: 2 s); the lease of anything not
	 * written expires by itself. */
	xmutex_lock(&r->w_mu);
	uint64_t until = clock_now_ns() + 2000000000ull;
	while ((r->qn > 0 || r->busy > 0) && atomic_load(&r->up) &&
	       xcond_wait_until(&r->w_idle, &r->w_mu, until))
		;
	r->w_stop = true;
	for (size_t i = 0; i < r->qn; i++) {
		tile_unref(r->q[i].t);
		if (r->q[i].kind == W_PUT)
			atomic_fetch_add(&r->drops, 1);
	}
	r->qn = 0;
	xcond_broadcast(&r->w_cv);
	xmutex_unlock(&r->w_mu);
	xthread_join(r->writer);
	xmutex_lock(&r->a_mu);
	r->a_stop = true;
	r->nwt = 0;
	xcond_broadcast(&r->a_cv);
	xmutex_unlock(&r->a_mu);
	xthread_join(r->waiter);
	for (int i = 0; i < r->npool; i++)
		redisFree(r->pool[i]);
	free(r->q);
	free(r->wt);
	free(r->addr);
	free(r->password);
	free(r->path);
	free(r);
}
