/* Scheduler tests with test-only node types: `count` writes a value derived from its key and
 * counts generations per key; `sum` adds its two inputs (default deps); `pair` adds two
 * neighbouring tiles of one input (custom deps, so neighbours share a dependency); `fail`
 * returns -EIO; `badeps` fails in deps(); `wide` adds six neighbouring tiles of one input
 * (more inputs than a job holds in itself). Every generate passes a gate the test can close, so
 * with one worker the order of generation is observable. A key already in the cache serves
 * as a "sync" marker: its callback arrives after the manager has queued everything else in
 * the same want list. Waits have deadlines, and an alarm backs them up: a hang fails. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <sched.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/node.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/store.h"
#include "engine/tile.h"

#define T 16
#define NCOUNT (8 * 8 * 64 * 32)
#define LOGMAX 4096
#define WAIT_S 20

struct tstate {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	bool gate_closed;
	int at_gate;
	struct tile_key log[LOGMAX];
	int nlog;
	int nice_seen;
	int policy_seen; /* the generating thread's scheduling policy */
	atomic_int counts[NCOUNT];
};

static size_t count_idx(const struct tile_key *k)
{
	return (((k->node % 8) * 8 + k->ly) * 64 + k->x % 64) * 32 + k->y % 32;
}

static float value(uint64_t h, const struct tile_key *k)
{
	return (float)(h * 1000000 + k->lx * 100000u + k->ly * 10000u + k->x * 100u + k->y);
}

static struct tile_key key_at(const struct node *n, int ly, uint32_t x, uint32_t y)
{
	struct tile_key k = { .node = n->hash, .x = x, .y = y, .lx = (uint8_t)(ly + 1),
			      .ly = (uint8_t)ly };
	return k;
}

static void pass_gate(struct tstate *st, const struct tile_key *k)
{
	xmutex_lock(&st->mu);
	if (st->nlog < LOGMAX)
		st->log[st->nlog++] = *k;
	st->nice_seen = getpriority(PRIO_PROCESS, (id_t)syscall(SYS_gettid));
	st->policy_seen = sched_getscheduler(0);
	if (st->gate_closed) {
		st->at_gate++;
		xcond_broadcast(&st->cv);
		while (st->gate_closed)
			xcond_wait(&st->cv, &st->mu);
		st->at_gate--;
	}
	xmutex_unlock(&st->mu);
	atomic_fetch_add(&st->counts[count_idx(k)], 1);
}

static int gen_count(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		     struct tile *const *in, int nin, struct tile *out)
{
	(void)g, (void)in, (void)nin;
	pass_gate(n->impl, k);
	float v = value(n->hash, k);
	for (uint32_t i = 0; i < out->size * out->size; i++)
		tile_f32(out)[i] = v;
	return 0;
}

static int gen_sum(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		   struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	pass_gate(n->impl, k);
	if (nin != 2 || in[0]->size != out->size || in[1]->size != out->size)
		return -EINVAL;
	for (uint32_t i = 0; i < out->size * out->size; i++)
		tile_f32(out)[i] = tile_f32(in[0])[i] + tile_f32(in[1])[i];
	return 0;
}

static int gen_fail(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		    struct tile *const *in, int nin, struct tile *out)
{
	(void)g, (void)in, (void)nin, (void)out;
	pass_gate(n->impl, k);
	return -EIO;
}

/* pair: input tile k and its east neighbour. */
static int deps_pair(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	for (int i = 0; i < 2; i++) {
		out[i].node = n->in[0];
		out[i].key = *k;
		out[i].key.node = n->in[0]->hash;
		out[i].key.x = grid_wrap_x(k->lx, (int64_t)k->x + i);
	}
	return 2;
}

/* wide: input tiles k .. k + WIDE - 1 along x. */
#define WIDE 6
static int deps_wide(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	for (int i = 0; i < WIDE; i++) {
		out[i].node = n->in[0];
		out[i].key = *k;
		out[i].key.node = n->in[0]->hash;
		out[i].key.x = grid_wrap_x(k->lx, (int64_t)k->x + i);
	}
	return WIDE;
}

/* The sum of every input, weighted by its slot (1, 2, 3...): inputs out of order show. */
static int gen_wsum(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		    struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	pass_gate(n->impl, k);
	if (nin != WIDE)
		return -EINVAL;
	for (uint32_t i = 0; i < out->size * out->size; i++) {
		float v = 0;
		for (int s = 0; s < nin; s++)
			v += (float)(s + 1) * tile_f32(in[s])[i];
		tile_f32(out)[i] = v;
	}
	return 0;
}

static int deps_bad(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	(void)n, (void)k, (void)out;
	return -EINVAL;
}

static const struct node_slot slots2[] = { { .name = "a", .type = PIX_HEIGHT },
					   { .name = "b", .type = PIX_HEIGHT } };
static const struct node_type t_count = { .name = "count", .generate = gen_count };
static const struct node_type t_sum = { .name = "sum", .slots = slots2, .nslots = 2,
					.generate = gen_sum };
static const struct node_type t_pair = { .name = "pair", .slots = slots2, .nslots = 1,
					 .deps = deps_pair, .generate = gen_sum };
static const struct node_type t_fail = { .name = "fail", .generate = gen_fail };
static const struct node_type t_badeps = { .name = "badeps", .deps = deps_bad,
					   .generate = gen_count };
static const struct node_type t_wide = { .name = "wide", .slots = slots2, .nslots = 1,
					 .deps = deps_wide, .generate = gen_wsum };

/* What a node's tile at k must hold. */
static float expect(const struct node *n, const struct tile_key *k)
{
	if (n->type == &t_count || n->type == &t_badeps)
		return value(n->hash, k);
	struct tile_key a = *k, b = *k;
	a.node = n->in[0]->hash;
	if (n->type == &t_wide) {
		float v = 0; /* as gen_wsum adds them, rounding included */
		for (int s = 0; s < WIDE; s++) {
			b = a;
			b.x = grid_wrap_x(k->lx, (int64_t)k->x + s);
			v += (float)(s + 1) * expect(n->in[0], &b);
		}
		return v;
	}
	if (n->type == &t_pair) {
		b = a;
		b.x = grid_wrap_x(k->lx, (int64_t)k->x + 1);
		return expect(n->in[0], &a) + expect(n->in[0], &b);
	}
	b.node = n->in[1]->hash;
	return expect(n->in[0], &a) + expect(n->in[1], &b);
}

static bool tile_ok(const struct node *n, const struct tile *t, const struct tile_key *k)
{
	if (!t || !grid_key_equal(&t->key, k) || t->size != T || t->type != PIX_HEIGHT)
		return false;
	float v = expect(n, k);
	for (uint32_t i = 0; i < T * T; i++)
		if (tile_f32(t)[i] != v)
			return false;
	return true;
}

/* A world: planet, nodes A, B (count), S = A + B, P = pair(A), F (fail), G = F + A,
 * D (badeps), a cache and a scheduler. */
struct world {
	struct planet planet;
	struct tstate *st;
	struct node a, b, s, p, f, g, d;
	struct cache *cache;
	struct sched *sched;
};

static void mknode(struct world *w, struct node *n, const struct node_type *t, uint64_t hash,
		   struct node *in0, struct node *in1)
{
	memset(n, 0, sizeof *n);
	n->name = (char *)t->name;
	n->type = t;
	n->out = PIX_HEIGHT;
	n->hash = hash;
	n->in[0] = in0;
	n->in[1] = in1;
	n->planet = &w->planet;
	n->impl = w->st;
	atomic_init(&n->generated, 0);
	atomic_init(&n->gen_ns, 0);
}

static struct world *world_new(int workers, size_t budget)
{
	struct world *w = calloc(1, sizeof *w);
	assert_non_null(w);
	w->planet.tile_size = T;
	w->planet.max_level = 6;
	w->st = calloc(1, sizeof *w->st);
	assert_non_null(w->st);
	xmutex_init(&w->st->mu);
	xcond_init(&w->st->cv);
	for (int i = 0; i < NCOUNT; i++)
		atomic_init(&w->st->counts[i], 0);
	mknode(w, &w->a, &t_count, 1, NULL, NULL);
	mknode(w, &w->b, &t_count, 2, NULL, NULL);
	mknode(w, &w->s, &t_sum, 3, &w->a, &w->b);
	mknode(w, &w->p, &t_pair, 4, &w->a, NULL);
	mknode(w, &w->f, &t_fail, 5, NULL, NULL);
	mknode(w, &w->g, &t_sum, 6, &w->f, &w->a);
	mknode(w, &w->d, &t_badeps, 7, NULL, NULL);
	w->cache = cache_create(budget);
	struct sched_desc d = { .cache = w->cache, .workers = workers };
	w->sched = sched_create(&d);
	assert_non_null(w->sched);
	return w;
}

static void world_free(struct world *w)
{
	sched_destroy(w->sched);
	cache_destroy(w->cache);
	xmutex_destroy(&w->st->mu);
	xcond_destroy(&w->st->cv);
	free(w->st);
	free(w);
}

static int count_of(struct world *w, const struct node *n, int ly, uint32_t x, uint32_t y)
{
	struct tile_key k = key_at(n, ly, x, y);
	return atomic_load(&w->st->counts[count_idx(&k)]);
}

static uint64_t deadline(void)
{
	return clock_now_ns() + WAIT_S * 1000000000ull;
}

static void gate_close(struct world *w)
{
	xmutex_lock(&w->st->mu);
	w->st->gate_closed = true;
	xmutex_unlock(&w->st->mu);
}

static void gate_open(struct world *w)
{
	xmutex_lock(&w->st->mu);
	w->st->gate_closed = false;
	xcond_broadcast(&w->st->cv);
	xmutex_unlock(&w->st->mu);
}

/* Waits until n generations are blocked at the gate. */
static void gate_wait(struct world *w, int n)
{
	uint64_t dl = deadline();
	bool more = true;
	xmutex_lock(&w->st->mu);
	while (w->st->at_gate < n && more)
		more = xcond_wait_until(&w->st->cv, &w->st->mu, dl);
	int got = w->st->at_gate;
	xmutex_unlock(&w->st->mu);
	assert_int_equal(got, n);
}

/* Callback recorder. */
struct rec {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	struct tile_key keys[LOGMAX];
	int errs[LOGMAX];
	int n, bad;
	bool closed; /* set after sched_req_destroy: any later callback is a bug */
};

static void rec_init(struct rec *r)
{
	memset(r, 0, sizeof *r);
	xmutex_init(&r->mu);
	xcond_init(&r->cv);
}

static void rec_fini(struct rec *r)
{
	xmutex_destroy(&r->mu);
	xcond_destroy(&r->cv);
}

static void on_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	struct rec *r = ud;
	xmutex_lock(&r->mu);
	if (r->closed || (t && !tile_ok(w->node, t, &w->key)) || (!t && err >= 0))
		r->bad++;
	if (r->n < LOGMAX) {
		r->keys[r->n] = w->key;
		r->errs[r->n] = err;
		r->n++;
	}
	xcond_broadcast(&r->cv);
	xmutex_unlock(&r->mu);
}

static int rec_find(struct rec *r, const struct tile_key *k)
{
	int found = -1;
	for (int i = 0; i < r->n; i++)
		if (grid_key_equal(&r->keys[i], k))
			found = i;
	return found;
}

/* Waits for a callback about k; returns its err. */
static int rec_wait(struct rec *r, const struct tile_key *k)
{
	uint64_t dl = deadline();
	bool more = true;
	int i;
	xmutex_lock(&r->mu);
	while ((i = rec_find(r, k)) < 0 && more)
		more = xcond_wait_until(&r->cv, &r->mu, dl);
	int err = i >= 0 ? r->errs[i] : 1;
	xmutex_unlock(&r->mu);
	assert_true(i >= 0);
	return err;
}

static struct want mkwant(struct node *n, int ly, uint32_t x, uint32_t y, enum sched_class c)
{
	struct want w = { .node = n, .key = key_at(n, ly, x, y), .cls = c };
	return w;
}

/* Puts A's tile at (ly 0, x, 0) in the cache to serve as a sync marker. */
static struct want sync_marker(struct world *w, uint32_t x)
{
	struct want m = mkwant(&w->a, 0, x, 0, SCHED_VISIBLE);
	struct tile *t = tile_create(&m.key, PIX_HEIGHT, T);
	for (int i = 0; i < T * T; i++)
		tile_f32(t)[i] = value(w->a.hash, &m.key);
	cache_insert(w->cache, t);
	tile_unref(t);
	return m;
}

static void fetch_bytes_and_deps(void **state)
{
	(void)state;
	struct world *w = world_new(2, 0);
	struct want list[64];
	size_t n = 0;
	for (int ly = 0; ly <= 3; ly++)
		for (uint32_t x = 0; x < 2; x++) {
			list[n++] = mkwant(&w->s, ly, x, 0, SCHED_VISIBLE);
			list[n++] = mkwant(&w->a, ly, x, 0, SCHED_PREFETCH); /* also S's input */
		}
	list[n++] = list[0]; /* the same key twice in one list */
	struct tile *out[64];
	assert_int_equal(sched_fetch(w->sched, list, n, out), 0);
	for (size_t i = 0; i < n; i++) {
		assert_true(tile_ok(list[i].node, out[i], &list[i].key));
		tile_unref(out[i]);
	}
	for (int ly = 0; ly <= 3; ly++)
		for (uint32_t x = 0; x < 2; x++) {
			assert_int_equal(count_of(w, &w->a, ly, x, 0), 1);
			assert_int_equal(count_of(w, &w->b, ly, x, 0), 1);
			assert_int_equal(count_of(w, &w->s, ly, x, 0), 1);
		}
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, 24);
	assert_int_equal(st.failed, 0);
	assert_int_equal(atomic_load(&w->s.generated), 8);
	/* Everything is cached now: a second fetch generates nothing. */
	assert_int_equal(sched_fetch(w->sched, list, n, out), 0);
	for (size_t i = 0; i < n; i++) {
		assert_true(tile_ok(list[i].node, out[i], &list[i].key));
		tile_unref(out[i]);
	}
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, 24);
	world_free(w);
}

static void shared_dep_generated_once(void **state)
{
	(void)state;
	struct world *w = world_new(2, 0);
	struct want list[8];
	for (uint32_t x = 0; x < 8; x++)
		list[x] = mkwant(&w->p, 2, x, 1, SCHED_VISIBLE);
	struct tile *out[8];
	assert_int_equal(sched_fetch(w->sched, list, 8, out), 0);
	for (int i = 0; i < 8; i++) {
		assert_true(tile_ok(&w->p, out[i], &list[i].key));
		tile_unref(out[i]);
	}
	/* P(x) needs A(x) and A(x+1 mod 8): every A is shared by two jobs. */
	for (uint32_t x = 0; x < 8; x++)
		assert_int_equal(count_of(w, &w->a, 2, x, 1), 1);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.merged, 8);
	assert_int_equal(st.generated, 8 + 8);
	world_free(w);
}

static void priority_order(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	struct rec rb, r;
	rec_init(&rb);
	rec_init(&r);
	gate_close(w);
	struct sched_req *blocker = sched_req_create(w->sched, on_ready, &rb);
	struct want bw = mkwant(&w->b, 0, 0, 0, SCHED_BULK);
	assert_int_equal(sched_req_want(blocker, &bw, 1), 0);
	gate_wait(w, 1);
	/* Scrambled: expected order is class, then level (coarse first), then list order. */
	struct want list[] = {
		mkwant(&w->a, 1, 0, 0, SCHED_BULK),	mkwant(&w->a, 4, 3, 2, SCHED_VISIBLE),
		mkwant(&w->a, 3, 1, 1, SCHED_PREFETCH), mkwant(&w->a, 0, 1, 0, SCHED_BULK),
		mkwant(&w->a, 2, 2, 2, SCHED_VISIBLE),	mkwant(&w->a, 4, 5, 5, SCHED_VISIBLE),
		mkwant(&w->a, 1, 2, 1, SCHED_PREFETCH), mkwant(&w->a, 0, 1, 0, SCHED_VISIBLE),
		mkwant(&w->a, 3, 7, 0, SCHED_VISIBLE),	sync_marker(w, 0),
	};
	const int order[] = { 7, 4, 8, 1, 5, 6, 2, 3, 0 };
	/* List entries 3 and 7 are the same key: it is wanted once, as VISIBLE. */
	struct sched_req *req = sched_req_create(w->sched, on_ready, &r);
	assert_int_equal(sched_req_want(req, list, 10), 0);
	assert_int_equal(rec_wait(&r, &list[9].key), 0);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.queued[SCHED_VISIBLE], 5);
	assert_int_equal(st.queued[SCHED_PREFETCH], 2);
	assert_int_equal(st.queued[SCHED_BULK], 1);
	assert_int_equal(st.running, 1);
	gate_open(w);
	for (int i = 0; i < 9; i++)
		assert_int_equal(rec_wait(&r, &list[order[i]].key), 0);
	xmutex_lock(&w->st->mu);
	assert_int_equal(w->st->nlog, 9);
	assert_true(grid_key_equal(&w->st->log[0], &bw.key));
	int k = 1;
	for (int i = 0; i < 9; i++) {
		if (order[i] == 3)
			continue;
		assert_true(grid_key_equal(&w->st->log[k], &list[order[i]].key));
		k++;
	}
	xmutex_unlock(&w->st->mu);
	assert_int_equal(r.bad, 0);
	assert_int_equal(r.n, 9); /* the duplicate entry is reported once */
	sched_req_destroy(req);
	sched_req_destroy(blocker);
	world_free(w);
	rec_fini(&rb);
	rec_fini(&r);
}

/* A queued job another request now wants as visible moves ahead of the queue though no job
 * left it, and the per-class counts follow it. */
static void promotion_reorders_queue(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	struct rec rb, ra, rv;
	rec_init(&rb);
	rec_init(&ra);
	rec_init(&rv);
	gate_close(w);
	struct sched_req *blocker = sched_req_create(w->sched, on_ready, &rb);
	struct want bw = mkwant(&w->b, 0, 0, 0, SCHED_BULK);
	assert_int_equal(sched_req_want(blocker, &bw, 1), 0);
	gate_wait(w, 1);
	struct want bulk[7];
	for (uint32_t x = 0; x < 6; x++)
		bulk[x] = mkwant(&w->a, 3, x, 1, SCHED_BULK);
	bulk[6] = sync_marker(w, 0);
	struct sched_req *qa = sched_req_create(w->sched, on_ready, &ra);
	assert_int_equal(sched_req_want(qa, bulk, 7), 0);
	assert_int_equal(rec_wait(&ra, &bulk[6].key), 0);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.queued[SCHED_BULK], 6);
	assert_int_equal(st.queued[SCHED_VISIBLE], 0);
	struct want vis[] = { bulk[4], sync_marker(w, 1) };
	vis[0].cls = SCHED_VISIBLE;
	struct sched_req *qv = sched_req_create(w->sched, on_ready, &rv);
	assert_int_equal(sched_req_want(qv, vis, 2), 0);
	assert_int_equal(rec_wait(&rv, &vis[1].key), 0);
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.queued[SCHED_BULK], 5);
	assert_int_equal(st.queued[SCHED_VISIBLE], 1);
	assert_int_equal(st.cancelled, 0);
	assert_int_equal(st.merged, 1);
	gate_open(w);
	for (int x = 0; x < 6; x++)
		assert_int_equal(rec_wait(&ra, &bulk[x].key), 0);
	assert_int_equal(rec_wait(&rv, &vis[0].key), 0);
	const int order[] = { 4, 0, 1, 2, 3, 5 };
	xmutex_lock(&w->st->mu);
	assert_int_equal(w->st->nlog, 7);
	assert_true(grid_key_equal(&w->st->log[0], &bw.key));
	for (int i = 0; i < 6; i++)
		assert_true(grid_key_equal(&w->st->log[1 + i], &bulk[order[i]].key));
	xmutex_unlock(&w->st->mu);
	assert_int_equal(ra.bad + rv.bad, 0);
	sched_req_destroy(qa);
	sched_req_destroy(qv);
	sched_req_destroy(blocker);
	world_free(w);
	rec_fini(&rb);
	rec_fini(&ra);
	rec_fini(&rv);
}

struct fetch_arg {
	struct world *w;
	struct want want;
	int rc;
	bool ok;
};

static void *fetch_thread(void *p)
{
	struct fetch_arg *a = p;
	struct tile *t = NULL;
	a->rc = sched_fetch(a->w->sched, &a->want, 1, &t);
	a->ok = tile_ok(a->want.node, t, &a->want.key);
	tile_unref(t);
	return NULL;
}

static void duplicates_merged(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	gate_close(w);
	struct fetch_arg fa = { .w = w, .want = mkwant(&w->s, 2, 1, 1, SCHED_VISIBLE) };
	pthread_t th;
	assert_int_equal(xthread_create(&th, fetch_thread, &fa), 0);
	gate_wait(w, 1); /* the fetch's first input is running, the rest wait */
	struct rec r1, r2;
	rec_init(&r1);
	rec_init(&r2);
	struct want l1[] = { fa.want, mkwant(&w->a, 2, 1, 1, SCHED_PREFETCH), sync_marker(w, 0) };
	struct want l2[] = { mkwant(&w->b, 2, 1, 1, SCHED_BULK), fa.want, sync_marker(w, 1) };
	struct sched_req *q1 = sched_req_create(w->sched, on_ready, &r1);
	struct sched_req *q2 = sched_req_create(w->sched, on_ready, &r2);
	assert_int_equal(sched_req_want(q1, l1, 3), 0);
	assert_int_equal(rec_wait(&r1, &l1[2].key), 0);
	assert_int_equal(sched_req_want(q2, l2, 3), 0);
	assert_int_equal(rec_wait(&r2, &l2[2].key), 0);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.merged, 4);
	assert_int_equal(st.waiting, 1);
	gate_open(w);
	assert_int_equal(rec_wait(&r1, &l1[0].key), 0);
	assert_int_equal(rec_wait(&r1, &l1[1].key), 0);
	assert_int_equal(rec_wait(&r2, &l2[0].key), 0);
	assert_int_equal(rec_wait(&r2, &l2[1].key), 0);
	xthread_join(th);
	assert_int_equal(fa.rc, 0);
	assert_true(fa.ok);
	assert_int_equal(r1.bad + r2.bad, 0);
	assert_int_equal(count_of(w, &w->s, 2, 1, 1), 1);
	assert_int_equal(count_of(w, &w->a, 2, 1, 1), 1);
	assert_int_equal(count_of(w, &w->b, 2, 1, 1), 1);
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, 3);
	sched_req_destroy(q1);
	sched_req_destroy(q2);
	world_free(w);
	rec_fini(&r1);
	rec_fini(&r2);
}

static void cancellation(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	struct rec rb, r;
	rec_init(&rb);
	rec_init(&r);
	gate_close(w);
	struct sched_req *blocker = sched_req_create(w->sched, on_ready, &rb);
	struct want bw = mkwant(&w->b, 0, 1, 0, SCHED_VISIBLE);
	assert_int_equal(sched_req_want(blocker, &bw, 1), 0);
	gate_wait(w, 1);
	/* 16 plain keys and 4 sums (each with 2 inputs of its own): 28 jobs. */
	struct want list[21];
	int n = 0;
	for (uint32_t x = 0; x < 16; x++)
		list[n++] = mkwant(&w->a, 3, x, 3, SCHED_VISIBLE);
	for (uint32_t x = 0; x < 4; x++)
		list[n++] = mkwant(&w->s, 3, x, 5, SCHED_PREFETCH);
	list[n++] = sync_marker(w, 0);
	struct sched_req *req = sched_req_create(w->sched, on_ready, &r);
	assert_int_equal(sched_req_want(req, list, 21), 0);
	assert_int_equal(rec_wait(&r, &list[20].key), 0);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.queued[SCHED_VISIBLE] + st.queued[SCHED_PREFETCH], 24);
	assert_int_equal(st.waiting, 4);
	/* Keep the first three plain keys and one sum. */
	struct want keep[] = { list[0], list[1], list[2], list[16], sync_marker(w, 1) };
	assert_int_equal(sched_req_want(req, keep, 5), 0);
	assert_int_equal(rec_wait(&r, &keep[4].key), 0);
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.cancelled, 28 - 6);
	assert_int_equal(st.queued[SCHED_VISIBLE] + st.queued[SCHED_PREFETCH], 5);
	assert_int_equal(st.waiting, 1);
	gate_open(w);
	for (int i = 0; i < 4; i++)
		assert_int_equal(rec_wait(&r, &keep[i].key), 0);
	/* Flush: once this fetch returns, every completion before it has been handled. */
	struct want fl = mkwant(&w->b, 1, 0, 0, SCHED_VISIBLE);
	struct tile *t;
	assert_int_equal(sched_fetch(w->sched, &fl, 1, &t), 0);
	tile_unref(t);
	for (uint32_t x = 3; x < 16; x++)
		assert_int_equal(count_of(w, &w->a, 3, x, 3), 0);
	for (uint32_t x = 1; x < 4; x++) {
		assert_int_equal(count_of(w, &w->s, 3, x, 5), 0);
		assert_int_equal(count_of(w, &w->a, 3, x, 5), 0);
		assert_int_equal(count_of(w, &w->b, 3, x, 5), 0);
	}
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, 1 + 6 + 1);
	xmutex_lock(&r.mu);
	assert_int_equal(r.n, 2 + 4); /* two sync markers and the four kept keys */
	assert_int_equal(r.bad, 0);
	xmutex_unlock(&r.mu);
	sched_req_destroy(req);
	sched_req_destroy(blocker);
	world_free(w);
	rec_fini(&rb);
	rec_fini(&r);
}

static void failure_delivered(void **state)
{
	(void)state;
	struct world *w = world_new(2, 0);
	struct want l[] = { mkwant(&w->f, 1, 0, 0, SCHED_VISIBLE),
			    mkwant(&w->g, 1, 1, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 1, 2, 0, SCHED_VISIBLE) };
	struct tile *out[3];
	assert_int_equal(sched_fetch(w->sched, l, 3, out), -EIO);
	assert_null(out[0]);
	assert_null(out[1]); /* G = F + A fails with its input */
	assert_true(tile_ok(&w->a, out[2], &l[2].key));
	tile_unref(out[2]);
	assert_int_equal(count_of(w, &w->g, 1, 1, 0), 0);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.failed, 2); /* F at two keys; G never ran */

	struct rec r;
	rec_init(&r);
	struct sched_req *req = sched_req_create(w->sched, on_ready, &r);
	struct want d = mkwant(&w->d, 1, 0, 0, SCHED_VISIBLE);
	assert_int_equal(sched_req_want(req, &d, 1), 0);
	assert_int_equal(rec_wait(&r, &d.key), -EINVAL);
	assert_int_equal(r.bad, 0);
	/* A key whose node field does not match the node is refused. */
	struct want bad = l[2];
	bad.key.node = 99;
	assert_int_equal(sched_req_want(req, &bad, 1), -EINVAL);
	sched_req_destroy(req);
	world_free(w);
	rec_fini(&r);
}

struct destroy_arg {
	struct sched_req *req;
	struct rec *r;
	atomic_bool *cb_done;
	bool waited;
};

static void *destroy_thread(void *p)
{
	struct destroy_arg *a = p;
	sched_req_destroy(a->req);
	a->waited = atomic_load(a->cb_done);
	xmutex_lock(&a->r->mu);
	a->r->closed = true;
	xmutex_unlock(&a->r->mu);
	return NULL;
}

struct slow_cb {
	struct rec rec;
	struct world *w;
	atomic_bool in_cb, cb_done, release;
};

static void on_ready_slow(void *ud, const struct want *wt, struct tile *t, int err)
{
	struct slow_cb *c = ud;
	on_ready(&c->rec, wt, t, err);
	atomic_store(&c->in_cb, true);
	xmutex_lock(&c->rec.mu);
	xcond_broadcast(&c->rec.cv);
	uint64_t dl = deadline();
	while (!atomic_load(&c->release))
		if (!xcond_wait_until(&c->rec.cv, &c->rec.mu, dl))
			break;
	xmutex_unlock(&c->rec.mu);
	atomic_store(&c->cb_done, true);
}

static void destroy_stops_callbacks(void **state)
{
	(void)state;
	struct world *w = world_new(2, 0);
	/* 1. Destroyed while its jobs run: no callback afterwards. */
	struct rec r;
	rec_init(&r);
	gate_close(w);
	struct sched_req *req = sched_req_create(w->sched, on_ready, &r);
	struct want l[] = { mkwant(&w->a, 2, 0, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 2, 1, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 2, 2, 0, SCHED_VISIBLE) };
	assert_int_equal(sched_req_want(req, l, 3), 0);
	gate_wait(w, 2);
	sched_req_destroy(req);
	xmutex_lock(&r.mu);
	r.closed = true;
	xmutex_unlock(&r.mu);
	gate_open(w);
	struct tile *out[3];
	assert_int_equal(sched_fetch(w->sched, l, 3, out), 0);
	for (int i = 0; i < 3; i++)
		tile_unref(out[i]);
	assert_int_equal(r.n, 0);
	assert_int_equal(count_of(w, &w->a, 2, 0, 0), 1);
	rec_fini(&r);

	/* 2. Destroyed from another thread while its callback runs: destroy waits for it. */
	struct slow_cb *c = calloc(1, sizeof *c);
	assert_non_null(c);
	rec_init(&c->rec);
	struct sched_req *q = sched_req_create(w->sched, on_ready_slow, c);
	struct want m = sync_marker(w, 1);
	assert_int_equal(sched_req_want(q, &m, 1), 0);
	xmutex_lock(&c->rec.mu);
	uint64_t dl = deadline();
	while (!atomic_load(&c->in_cb))
		if (!xcond_wait_until(&c->rec.cv, &c->rec.mu, dl))
			break;
	xmutex_unlock(&c->rec.mu);
	assert_true(atomic_load(&c->in_cb));
	struct destroy_arg da = { .req = q, .r = &c->rec, .cb_done = &c->cb_done };
	pthread_t th;
	assert_int_equal(xthread_create(&th, destroy_thread, &da), 0);
	struct timespec pause = { 0, 30 * 1000 * 1000 }; /* let destroy reach its wait */
	nanosleep(&pause, NULL);
	xmutex_lock(&c->rec.mu);
	atomic_store(&c->release, true);
	xcond_broadcast(&c->rec.cv);
	xmutex_unlock(&c->rec.mu);
	xthread_join(th);
	assert_true(da.waited);
	assert_int_equal(c->rec.bad, 0);
	rec_fini(&c->rec);
	free(c); /* ASan: a late callback would touch freed memory */
	world_free(w);
}

/* sched_req_release (what the event loop uses): returns at once even while the request's
 * callback runs on the manager thread; fin comes once, after the last callback; a released
 * request's queued work is cancelled; sched_barrier waits for every earlier release. */
static atomic_int fin_calls;

static void fin_slow(void *ud)
{
	struct slow_cb *c = ud;
	xmutex_lock(&c->rec.mu);
	c->rec.closed = true; /* a callback after this is a bug (rec.bad) */
	xmutex_unlock(&c->rec.mu);
	atomic_fetch_add(&fin_calls, 1);
}

static void release_never_waits(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	struct slow_cb *c = calloc(1, sizeof *c);
	assert_non_null(c);
	rec_init(&c->rec);
	atomic_store(&fin_calls, 0);
	struct sched_req *q = sched_req_create(w->sched, on_ready_slow, c);
	struct want m = sync_marker(w, 1);
	assert_int_equal(sched_req_want(q, &m, 1), 0);
	xmutex_lock(&c->rec.mu);
	uint64_t dl = deadline();
	while (!atomic_load(&c->in_cb))
		if (!xcond_wait_until(&c->rec.cv, &c->rec.mu, dl))
			break;
	xmutex_unlock(&c->rec.mu);
	assert_true(atomic_load(&c->in_cb));
	/* The manager is held inside q's callback: a waiting destroy would block here. */
	sched_req_release(q, fin_slow);
	assert_false(atomic_load(&c->cb_done));
	assert_int_equal(atomic_load(&fin_calls), 0);
	xmutex_lock(&c->rec.mu);
	atomic_store(&c->release, true);
	xcond_broadcast(&c->rec.cv);
	xmutex_unlock(&c->rec.mu);
	sched_barrier(w->sched);
	assert_int_equal(atomic_load(&fin_calls), 1);
	assert_int_equal(c->rec.bad, 0);

	/* Released with queued work behind a closed gate: no callback after fin, and the work
	 * is cancelled (not generated for nobody). */
	struct slow_cb *d = calloc(1, sizeof *d);
	assert_non_null(d);
	rec_init(&d->rec);
	atomic_store(&d->release, true);
	gate_close(w);
	struct sched_req *r = sched_req_create(w->sched, on_ready_slow, d);
	struct want l[] = { mkwant(&w->a, 4, 0, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 4, 1, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 4, 2, 0, SCHED_VISIBLE) };
	assert_int_equal(sched_req_want(r, l, 3), 0);
	gate_wait(w, 1); /* one runs, two wait in the queue */
	sched_req_release(r, fin_slow);
	sched_barrier(w->sched);
	assert_int_equal(atomic_load(&fin_calls), 2);
	gate_open(w);
	struct tile *out[1];
	assert_int_equal(sched_fetch(w->sched, &l[0], 1, out), 0); /* the running one finished */
	tile_unref(out[0]);
	assert_int_equal(d->rec.bad, 0);
	assert_int_equal(count_of(w, &w->a, 4, 2, 0), 0); /* cancelled, never generated */
	world_free(w);
	rec_fini(&c->rec);
	rec_fini(&d->rec);
	free(c);
	free(d);
}

/* Destroying another request from inside a callback (on the manager thread). */
struct cross {
	struct rec ra, rb;
	struct sched_req *b;
	bool b_destroyed;
};

static void on_ready_a(void *ud, const struct want *w, struct tile *t, int err)
{
	struct cross *x = ud;
	on_ready(&x->ra, w, t, err);
	if (!x->b_destroyed) {
		sched_req_destroy(x->b);
		x->b_destroyed = true;
	}
}

static void on_ready_b(void *ud, const struct want *w, struct tile *t, int err)
{
	struct cross *x = ud;
	on_ready(&x->rb, w, t, err);
	if (x->b_destroyed)
		x->rb.bad++;
}

static void destroy_from_callback(void **state)
{
	(void)state;
	struct world *w = world_new(1, 0);
	struct cross *x = calloc(1, sizeof *x);
	assert_non_null(x);
	rec_init(&x->ra);
	rec_init(&x->rb);
	gate_close(w);
	struct sched_req *a = sched_req_create(w->sched, on_ready_a, x);
	x->b = sched_req_create(w->sched, on_ready_b, x);
	struct want l[] = { mkwant(&w->a, 3, 0, 0, SCHED_VISIBLE),
			    mkwant(&w->a, 3, 1, 0, SCHED_VISIBLE) };
	assert_int_equal(sched_req_want(x->b, l, 2), 0);
	gate_wait(w, 1);
	assert_int_equal(sched_req_want(a, l, 2), 0);
	gate_open(w);
	assert_int_equal(rec_wait(&x->ra, &l[0].key), 0);
	assert_int_equal(rec_wait(&x->ra, &l[1].key), 0);
	assert_int_equal(x->rb.bad, 0);
	sched_req_destroy(a);
	world_free(w);
	rec_fini(&x->ra);
	rec_fini(&x->rb);
	free(x);
}

static void workers_lower_priority(void **state)
{
	(void)state;
	errno = 0;
	int mine = getpriority(PRIO_PROCESS, (id_t)syscall(SYS_gettid));
	assert_int_equal(errno, 0);
	struct world *w = world_new(1, 0);
	struct want k = mkwant(&w->a, 0, 0, 0, SCHED_VISIBLE);
	struct tile *t;
	assert_int_equal(sched_fetch(w->sched, &k, 1, &t), 0);
	tile_unref(t);
	int want = mine + 5 > 19 ? 19 : mine + 5;
	assert_int_equal(w->st->nice_seen, want);
	assert_int_equal(sched_worker_nice_error(w->sched), 0);
	/* and under SCHED_BATCH: woken by the event loop, a worker does not preempt it */
	assert_int_equal(w->st->policy_seen, SCHED_BATCH);
	assert_int_equal(sched_getscheduler(0), SCHED_OTHER); /* the caller's own is unchanged */
	world_free(w);
}

/* Stress: requesters replace random want lists while workers generate. */
struct stress_arg {
	struct world *w;
	unsigned seed;
	struct rec rec;
	int lists;
};

static struct want random_want(struct world *w, uint64_t *s)
{
	*s = *s * 6364136223846793005u + 1442695040888963407u;
	uint64_t v = *s >> 16;
	struct node *nodes[] = { &w->a, &w->b, &w->s, &w->p, &w->s, &w->p };
	int ly = (int)(v % 4);
	v /= 4;
	struct node *n = nodes[v % 6];
	v /= 6;
	uint32_t x = (uint32_t)(v % grid_tiles_x(ly + 1));
	v /= 64;
	uint32_t y = (uint32_t)(v % grid_tiles_y(ly));
	v /= 32;
	return mkwant(n, ly, x, y, (enum sched_class)(1 + v % 3));
}

static void *stress_thread(void *p)
{
	struct stress_arg *a = p;
	uint64_t s = a->seed * 0x9e3779b97f4a7c15u + 7;
	struct sched_req *req = sched_req_create(a->w->sched, on_ready, &a->rec);
	struct want list[48];
	double end = clock_now_s() + 1.5;
	while (clock_now_s() < end) {
		s = s * 6364136223846793005u + 1442695040888963407u;
		size_t n = (s >> 40) % 48;
		for (size_t i = 0; i < n; i++)
			list[i] = random_want(a->w, &s);
		if (sched_req_want(req, list, n) != 0)
			a->rec.bad++;
		a->lists++;
		if ((s >> 20) % 16 == 0) {
			sched_req_destroy(req);
			req = sched_req_create(a->w->sched, on_ready, &a->rec);
		}
		if ((s >> 30) % 4 == 0)
			sched_yield();
	}
	sched_req_destroy(req);
	return NULL;
}

static void stress(void **state)
{
	(void)state;
	struct world *w = world_new(8, 0);
	struct stress_arg a[8];
	pthread_t th[8];
	for (int i = 0; i < 8; i++) {
		a[i].w = w;
		a[i].seed = (unsigned)i + 11;
		a[i].lists = 0;
		rec_init(&a[i].rec);
		assert_int_equal(xthread_create(&th[i], stress_thread, &a[i]), 0);
	}
	int lists = 0, reports = 0;
	for (int i = 0; i < 8; i++) {
		xthread_join(th[i]);
		assert_int_equal(a[i].rec.bad, 0);
		lists += a[i].lists;
		reports += a[i].rec.n;
		rec_fini(&a[i].rec);
	}
	assert_true(lists > 8);
	assert_true(reports > 0);
	/* Every key of every node over the levels used, fetched and checked. */
	static const int nn = 4;
	struct node *nodes[] = { &w->a, &w->b, &w->s, &w->p };
	size_t cap = 0;
	for (int ly = 0; ly < 4; ly++)
		cap += (size_t)nn * grid_tiles_x(ly + 1) * grid_tiles_y(ly);
	struct want *all = calloc(cap, sizeof *all);
	struct tile **out = calloc(cap, sizeof *out);
	assert_non_null(all);
	assert_non_null(out);
	size_t n = 0;
	for (int ly = 0; ly < 4; ly++)
		for (int k = 0; k < nn; k++)
			for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
				for (uint32_t x = 0; x < grid_tiles_x(ly + 1); x++)
					all[n++] = mkwant(nodes[k], ly, x, y, SCHED_BULK);
	assert_int_equal(sched_fetch(w->sched, all, n, out), 0);
	for (size_t i = 0; i < n; i++) {
		assert_true(tile_ok(all[i].node, out[i], &all[i].key));
		tile_unref(out[i]);
		/* The cache has no budget: a key is never generated twice. */
		assert_int_equal(atomic_load(&w->st->counts[count_idx(&all[i].key)]), 1);
	}
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, n);
	assert_int_equal(st.waiting, 0);
	assert_int_equal(st.running, 0);
	free(all);
	free(out);
	world_free(w);
}

/* sched_fetch of list[0..n) into out, each tile checked and dropped: how many were wrong
 * (all of them when the fetch failed). */
static int fetch_check(struct world *w, const struct want *list, size_t n, struct tile **out)
{
	int bad = sched_fetch(w->sched, list, n, out) != 0;
	for (size_t i = 0; i < n; i++) {
		if (!tile_ok(list[i].node, out[i], &list[i].key))
			bad++;
		tile_unref(out[i]);
	}
	return bad;
}

/* Many fetches of the same wide tiles at once: jobs with more inputs than they hold in
 * themselves, several want entries waiting on each job, and more jobs than the scheduler
 * keeps for reuse (its blocks of jobs released and made again). */
struct wide_arg {
	struct world *w;
	struct node *wide;
	int ly, bad;
};

static void *wide_thread(void *p)
{
	struct wide_arg *a = p;
	size_t n = (size_t)grid_tiles_x(a->ly + 1) * grid_tiles_y(a->ly);
	struct want *list = calloc(2 * n, sizeof *list);
	struct tile **out = calloc(2 * n, sizeof *out);
	if (!list || !out) {
		a->bad++;
		free(list);
		free(out);
		return NULL;
	}
	size_t k = 0;
	for (uint32_t y = 0; y < grid_tiles_y(a->ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(a->ly + 1); x++) {
			list[k++] = mkwant(a->wide, a->ly, x, y, SCHED_WEB);
			list[k++] = mkwant(&a->w->b, a->ly, x, y, SCHED_BULK);
		}
	a->bad += fetch_check(a->w, list, k, out);
	free(list);
	free(out);
	return NULL;
}

static void wide_many_wanters(void **state)
{
	(void)state;
	struct world *w = world_new(4, 0);
	struct node wide;
	mknode(w, &wide, &t_wide, 8, &w->a, NULL);
	/* Level 5: 2048 wide tiles, 2048 of A, 2048 of B wanted by three fetches at once (6144
	 * jobs, beyond the 4096 kept for reuse); then level 4 from what was kept. */
	for (int ly = 5; ly >= 4; ly--) {
		struct wide_arg a[3];
		pthread_t th[3];
		for (int i = 0; i < 3; i++) {
			a[i] = (struct wide_arg){ .w = w, .wide = &wide, .ly = ly };
			assert_int_equal(xthread_create(&th[i], wide_thread, &a[i]), 0);
		}
		for (int i = 0; i < 3; i++) {
			xthread_join(th[i]);
			assert_int_equal(a[i].bad, 0);
		}
	}
	/* The cache has no budget: each key generated once however many waited for it. */
	size_t keys = 0;
	for (int ly = 4; ly <= 5; ly++)
		keys += 3 * (size_t)grid_tiles_x(ly + 1) * grid_tiles_y(ly);
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, keys);
	assert_int_equal(st.failed, 0);
	assert_int_equal(st.waiting, 0);
	assert_int_equal(st.running, 0);
	world_free(w);
}

/* Many workers hand jobs back at once (the manager's lock-free inbox): requesters fetch
 * overlapping levels of two nodes with shared inputs, from several threads, with 16 workers. */
struct handoff_arg {
	struct world *w;
	int idx, bad;
};

static void *handoff_thread(void *p)
{
	struct handoff_arg *a = p;
	struct world *w = a->w;
	struct node *nodes[] = { &w->s, &w->p };
	struct want *list = calloc(2 * 32 * 16, sizeof *list);
	struct tile **out = calloc(2 * 32 * 16, sizeof *out);
	if (!list || !out) {
		a->bad++;
		free(list);
		free(out);
		return NULL;
	}
	for (int round = 0; round < 12; round++) {
		int ly = 1 + (round + a->idx) % 4;
		size_t n = 0;
		for (int k = 0; k < 2; k++)
			for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
				for (uint32_t x = 0; x < grid_tiles_x(ly + 1); x++)
					list[n++] = mkwant(nodes[k], ly, x, y,
							   (enum sched_class)(1 + (round + k) % 3));
		a->bad += fetch_check(w, list, n, out);
	}
	free(list);
	free(out);
	return NULL;
}

static void many_workers_handoff(void **state)
{
	(void)state;
	struct world *w = world_new(16, 0);
	struct handoff_arg a[6];
	pthread_t th[6];
	for (int i = 0; i < 6; i++) {
		a[i] = (struct handoff_arg){ .w = w, .idx = i };
		assert_int_equal(xthread_create(&th[i], handoff_thread, &a[i]), 0);
	}
	for (int i = 0; i < 6; i++) {
		xthread_join(th[i]);
		assert_int_equal(a[i].bad, 0);
	}
	/* The cache has no budget: every key of a, b, s and p at levels 1-4 generated once. */
	size_t keys = 0;
	struct node *nodes[] = { &w->a, &w->b, &w->s, &w->p };
	for (int k = 0; k < 4; k++)
		for (int ly = 1; ly <= 4; ly++)
			for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
				for (uint32_t x = 0; x < grid_tiles_x(ly + 1); x++) {
					assert_int_equal(count_of(w, nodes[k], ly, x, y), 1);
					keys++;
				}
	struct sched_stats st;
	sched_get_stats(w->sched, &st);
	assert_int_equal(st.generated, keys);
	assert_int_equal(st.failed, 0);
	assert_int_equal(st.running, 0);
	assert_int_equal(st.waiting, 0);
	for (int c = 0; c < SCHED_NCLASS; c++)
		assert_int_equal(st.queued[c], 0);
	assert_int_equal(st.workers, 16);

	/* A tile reported means its worker no longer counts as running, every time. */
	for (uint32_t i = 0; i < 256; i++) {
		struct want one = mkwant(&w->b, 5, i % 64, i / 64, SCHED_VISIBLE);
		struct tile *t = NULL;
		assert_int_equal(sched_fetch(w->sched, &one, 1, &t), 0);
		assert_true(tile_ok(&w->b, t, &one.key));
		tile_unref(t);
		sched_get_stats(w->sched, &st);
		assert_int_equal(st.running, 0);
		assert_int_equal(st.generated, keys + i + 1);
	}
	world_free(w);
}

/* A viewer's look-ahead (SCHED_AHEAD) loaded from the store goes into the memory cache, where
 * the viewer's WANT finds it moments later; an operator's bulk job loading the same way
 * leaves the cache alone (it must not flush what viewers use). Before SCHED_AHEAD both were
 * bulk, and over a restarted daemon's store a viewer's look-ahead only read the disk. */
static void ahead_loads_into_cache_bulk_does_not(void **state)
{
	(void)state;
	char dir[] = "/tmp/clipmap-test-sched-XXXXXX", path[64], lock[80], err[256];
	assert_non_null(mkdtemp(dir));
	snprintf(path, sizeof path, "%s/store.mdb", dir);
	snprintf(lock, sizeof lock, "%s-lock", path);
	struct store *st = NULL;
	assert_int_equal(store_open_file(path, 64, &st, err), 0);
	struct world *w = world_new(1, 0);
	struct planet_layer layer = { .name = "h", .node = &w->a, .type = PIX_HEIGHT };
	w->planet.layers = &layer;
	w->planet.nlayers = 1;
	sched_destroy(w->sched);
	w->sched = sched_create(&(struct sched_desc){ .cache = w->cache, .store = st, .workers = 1 });
	assert_non_null(w->sched);
	struct want make[2] = { mkwant(&w->a, 3, 1, 1, SCHED_VISIBLE),
				mkwant(&w->a, 3, 2, 1, SCHED_VISIBLE) };
	struct tile *out[2];
	assert_int_equal(sched_fetch(w->sched, make, 2, out), 0);
	tile_unref(out[0]);
	tile_unref(out[1]);
	assert_int_equal(store_flush(st), 0);
	cache_drop_node(w->cache, w->a.hash); /* its tiles are uniform: they cost the cache 0 bytes */
	struct want bulk = mkwant(&w->a, 3, 1, 1, SCHED_BULK), ahead = mkwant(&w->a, 3, 2, 1, SCHED_AHEAD);
	assert_false(cache_contains(w->cache, &bulk.key));
	assert_false(cache_contains(w->cache, &ahead.key));
	assert_int_equal(sched_fetch(w->sched, &bulk, 1, out), 0);
	assert_true(tile_ok(&w->a, out[0], &bulk.key));
	tile_unref(out[0]);
	assert_int_equal(sched_fetch(w->sched, &ahead, 1, out), 0);
	assert_true(tile_ok(&w->a, out[0], &ahead.key));
	tile_unref(out[0]);
	struct sched_stats ss;
	sched_get_stats(w->sched, &ss);
	assert_int_equal(ss.generated, 2);
	assert_int_equal(ss.loaded, 2);
	assert_false(cache_contains(w->cache, &bulk.key));
	assert_true(cache_contains(w->cache, &ahead.key));
	world_free(w);
	store_destroy(st);
	unlink(path);
	unlink(lock);
	rmdir(dir);
}

int main(void)
{
	alarm(240); /* a deadlock fails the run instead of hanging it */
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(fetch_bytes_and_deps),
		cmocka_unit_test(shared_dep_generated_once),
		cmocka_unit_test(priority_order),
		cmocka_unit_test(promotion_reorders_queue),
		cmocka_unit_test(duplicates_merged),
		cmocka_unit_test(cancellation),
		cmocka_unit_test(failure_delivered),
		cmocka_unit_test(release_never_waits),
		cmocka_unit_test(destroy_stops_callbacks),
		cmocka_unit_test(destroy_from_callback),
		cmocka_unit_test(workers_lower_priority),
		cmocka_unit_test(stress),
		cmocka_unit_test(many_workers_handoff),
		cmocka_unit_test(wide_many_wanters),
		cmocka_unit_test(ahead_loads_into_cache_bulk_does_not),
	};
	return cmocka_run_group_tests_name("sched", tests, NULL, NULL);
}
