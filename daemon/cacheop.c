/* cacheop — see cacheop.h. Node hashes are looked up in a table sorted by hash (every node of
 * every planet: a layer's node labelled with the layer's name, another with "node NAME"); an
 * entry whose hash is not there belongs to no planet (gc's garbage). stat counts into a dense
 * array [node or garbage][ly][tier] and turns the non-zero cells into rows. purge and gc
 * collect the keys first (the store's iterate may not call the store), then queue their
 * removal, waiting for the writer when its queue is full, and flush before answering so a
 * stat right after sees the result.
 */
#include "cacheop.h"

#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/node.h"

#define NLY (GRID_MAX_LEVEL + 1)

struct nodeent {
	uint64_t hash;
	uint32_t planet, label; /* indices into names */
};

struct cacheop {
	struct proto_cache_op q;
	char **names; /* planet names and labels */
	size_t nnames;
	struct nodeent *nodes; /* sorted by hash */
	size_t nnodes;
	int target; /* names index of the planet q names; -1: every planet */
	struct cache *cache;
	struct store *store;
	void (*done)(void *ud);
	void *ud;
	pthread_t th;
	bool started;
	pthread_mutex_t mu; /* done is called under it; destroy sets cancel under it */
	atomic_bool cancel;
	/* work */
	uint64_t *cnt; /* stat: [(node or garbage) · NLY · 2 + ly · 2 + tier − 1] × {tiles, bytes} */
	struct tile_key *del;
	size_t ndel, cap;
	uint64_t checked, removed, bytes, corrupt;
	int err;
	/* replies */
	struct proto_cache_stat_row *rows;
	size_t nrows;
	struct proto_msg *msgs;
	size_t nmsgs;
};

static int cmp_node(const void *a, const void *b)
{
	const struct nodeent *x = a, *y = b;
	return x->hash < y->hash ? -1 : x->hash > y->hash;
}

/* The node table index of hash h, or nnodes (garbage). */
static size_t node_of(const struct cacheop *op, uint64_t h)
{
	size_t lo = 0, hi = op->nnodes;
	while (lo < hi) {
		size_t mid = (lo + hi) / 2;
		if (op->nodes[mid].hash < h)
			lo = mid + 1;
		else
			hi = mid;
	}
	return lo < op->nnodes && op->nodes[lo].hash == h ? lo : op->nnodes;
}

static uint32_t add_name(struct cacheop *op, const char *s)
{
	op->names = xrealloc(op->names, (op->nnames + 1) * sizeof *op->names);
	op->names[op->nnames] = xstrdup(s);
	return (uint32_t)op->nnames++;
}

static bool cancelled(struct cacheop *op)
{
	return atomic_load_explicit(&op->cancel, memory_order_relaxed);
}

/* Whether entry k is one q asks for (planet, levels, bbox). */
static bool wanted(const struct cacheop *op, const struct tile_key *k)
{
	size_t i = node_of(op, k->node);
	if (op->target >= 0 && (i == op->nnodes || (int)op->nodes[i].planet != op->target))
		return false;
	const struct proto_cache_op *q = &op->q;
	if ((q->filter & PROTO_COF_LEVELS) && (k->ly < q->lmin || k->ly > q->lmax))
		return false;
	if (q->filter & PROTO_COF_BBOX) {
		struct geo_rect r;
		grid_tile_rect(k, &r);
		const struct geo_rect *b = &q->bbox;
		if (!(r.south < b->north && r.north > b->south))
			return false;
		bool lon = b->west < b->east ? r.west < b->east && r.east > b->west
					     : r.east > b->west || r.west < b->east;
		if (!lon)
			return false;
	}
	return true;
}

static void count(struct cacheop *op, const struct tile_key *k, int tier, uint64_t bytes)
{
	if (k->ly >= NLY)
		return;
	size_t i = node_of(op, k->node);
	if (op->target >= 0 && (i == op->nnodes || (int)op->nodes[i].planet != op->target))
		return;
	uint64_t *c = &op->cnt[((i * NLY + k->ly) * 2 + (size_t)(tier - 1)) * 2];
	c[0]++;
	c[1] += bytes;
}

static int mem_fn(void *ud, const struct tile *t, uint64_t used_ns)
{
	struct cacheop *op = ud;
	(void)used_ns;
	count(op, &t->key, PROTO_TIER_MEMORY, t->nbytes);
	return cancelled(op);
}

static int disk_fn(void *ud, const struct store_entry *e)
{
	struct cacheop *op = ud;
	count(op, &e->key, PROTO_TIER_DISK, e->bytes);
	return cancelled(op);
}

static int collect_fn(void *ud, const struct store_entry *e)
{
	struct cacheop *op = ud;
	op->checked++;
	bool take = op->q.op == PROTO_COP_GC ? node_of(op, e->key.node) == op->nnodes
					     : wanted(op, &e->key);
	if (take) {
		if (op->ndel == op->cap) {
			op->cap = op->cap ? op->cap * 2 : 1024;
			op->del = xrealloc(op->del, op->cap * sizeof *op->del);
		}
		op->del[op->ndel++] = e->key;
		op->bytes += e->bytes;
	}
	return cancelled(op);
}

static int verify_fn(void *ud, const struct store_entry *e, bool ok)
{
	struct cacheop *op = ud;
	if (op->target < 0 || wanted(op, &e->key))
		op->checked++;
	if (!ok) {
		op->corrupt++;
		op->removed++;
		op->bytes += e->bytes;
	}
	return cancelled(op);
}

/* Queues the removal of the collected keys, waiting for the writer when its queue is full. */
static void remove_collected(struct cacheop *op)
{
	for (size_t i = 0; i < op->ndel && !cancelled(op); i++) {
		int rc;
		for (int tries = 0; (rc = store_del(op->store, &op->del[i])) == -EAGAIN && tries < 100;
		     tries++)
			store_flush(op->store);
		if (rc == 0)
			op->removed++;
	}
}

static void build_rows(struct cacheop *op)
{
	for (size_t i = 0; i <= op->nnodes; i++)
		for (int ly = 0; ly < NLY; ly++)
			for (int tier = 1; tier <= 2; tier++) {
				const uint64_t *c = &op->cnt[((i * NLY + (size_t)ly) * 2 +
							      (size_t)(tier - 1)) * 2];
				if (!c[0])
					continue;
				op->rows = xrealloc(op->rows, (op->nrows + 1) * sizeof *op->rows);
				bool g = i == op->nnodes;
				op->rows[op->nrows++] = (struct proto_cache_stat_row){
					.planet = g ? "" : op->names[op->nodes[i].planet],
					.layer = g ? "" : op->names[op->nodes[i].label],
					.ly = (uint8_t)ly, .tier = (uint8_t)tier, .tiles = c[0],
					.bytes = c[1] };
			}
}

static void build_replies(struct cacheop *op)
{
	size_t parts = op->q.op == PROTO_COP_STAT
			       ? (op->nrows + PROTO_MAX_STAT_ROWS - 1) / PROTO_MAX_STAT_ROWS
			       : 0;
	if (op->q.op == PROTO_COP_STAT && parts == 0)
		parts = 1; /* an empty CACHE_STAT: nothing held */
	op->msgs = xcalloc(parts + 1, sizeof *op->msgs);
	for (size_t p = 0; p < parts; p++) {
		size_t off = p * PROTO_MAX_STAT_ROWS;
		size_t n = op->nrows - off < PROTO_MAX_STAT_ROWS ? op->nrows - off
								  : PROTO_MAX_STAT_ROWS;
		op->msgs[op->nmsgs++] = (struct proto_msg){
			.type = PROTO_CACHE_STAT,
			.cache_stat = { .req = op->q.req, .more = p + 1 < parts,
					.count = (uint32_t)n, .rows = op->rows + off } };
	}
	op->msgs[op->nmsgs++] = (struct proto_msg){
		.type = PROTO_CACHE_DONE,
		.cache_done = { .req = op->q.req, .op = op->q.op, .checked = op->checked,
				.removed = op->removed, .bytes = op->bytes, .corrupt = op->corrupt } };
}

static void *op_main(void *arg)
{
	struct cacheop *op = arg;
	switch (op->q.op) {
	case PROTO_COP_STAT:
		op->cnt = xcalloc((op->nnodes + 1) * NLY * 2 * 2, sizeof *op->cnt);
		if (op->cache)
			cache_foreach(op->cache, mem_fn, op);
		if (op->store && !cancelled(op))
			op->err = store_iterate(op->store, disk_fn, op);
		for (size_t i = 0; i < (op->nnodes + 1) * NLY * 2; i++)
			op->checked += op->cnt[2 * i];
		build_rows(op);
		break;
	case PROTO_COP_PURGE:
	case PROTO_COP_GC:
		op->err = store_iterate(op->store, collect_fn, op);
		remove_collected(op);
		store_flush(op->store);
		break;
	case PROTO_COP_VERIFY:
		op->err = store_verify(op->store, verify_fn, op);
		store_flush(op->store);
		break;
	}
	build_replies(op);
	xmutex_lock(&op->mu);
	if (!cancelled(op))
		op->done(op->ud);
	xmutex_unlock(&op->mu);
	return NULL;
}

int cacheop_start(const struct proto_cache_op *q, const struct planet_set *ps,
		  struct cache *cache, struct store *store, void (*done)(void *ud), void *ud,
		  struct cacheop **out, char err[256])
{
	*out = NULL;
	if (q->op != PROTO_COP_STAT && !store) {
		err_set(err, "this daemon has no disk store ([store] path): nothing to %s",
			q->op == PROTO_COP_PURGE ? "purge" : q->op == PROTO_COP_GC ? "collect"
										 : "verify");
		return -ENODEV;
	}
	struct cacheop *op = xcalloc(1, sizeof *op);
	op->q = *q;
	op->q.planet = NULL;
	op->target = -1;
	for (size_t i = 0; ps && i < ps->n; i++) {
		const struct planet *p = ps->planets[i];
		uint32_t pn = add_name(op, p->name);
		if (q->planet && q->planet[0] && strcmp(q->planet, p->name) == 0)
			op->target = (int)pn;
		for (size_t k = 0; k < p->nnodes; k++) {
			const struct node *n = p->nodes[k];
			const char *label = NULL;
			for (size_t l = 0; l < p->nlayers && !label; l++)
				if (p->layers[l].node == n)
					label = p->layers[l].name;
			char buf[300];
			if (!label) {
				snprintf(buf, sizeof buf, "node %s", n->name);
				label = buf;
			}
			op->nodes = xrealloc(op->nodes, (op->nnodes + 1) * sizeof *op->nodes);
			op->nodes[op->nnodes++] = (struct nodeent){ n->hash, pn, add_name(op, label) };
		}
	}
	if (op->nnodes > 1)
		qsort(op->nodes, op->nnodes, sizeof *op->nodes, cmp_node);
	if (q->planet && q->planet[0] && op->target < 0) {
		err_set(err, "no planet \"%s\"", q->planet);
		cacheop_destroy(op);
		return -ENOENT;
	}
	op->cache = cache;
	op->store = store;
	op->done = done;
	op->ud = ud;
	xmutex_init(&op->mu);
	atomic_init(&op->cancel, false);
	int rc = pthread_create(&op->th, NULL, op_main, op);
	if (rc) {
		err_set(err, "no thread: %s", strerror(rc));
		xmutex_destroy(&op->mu);
		op->done = NULL;
		cacheop_destroy(op);
		return -rc;
	}
	op->started = true;
	*out = op;
	return 0;
}

size_t cacheop_replies(struct cacheop *op, const struct proto_msg **msgs)
{
	*msgs = op->msgs;
	return op->nmsgs;
}

void cacheop_destroy(struct cacheop *op)
{
	if (!op)
		return;
	if (op->started) {
		xmutex_lock(&op->mu);
		atomic_store(&op->cancel, true); /* under mu: done is not called after this */
		xmutex_unlock(&op->mu);
		pthread_join(op->th, NULL);
		xmutex_destroy(&op->mu);
	}
	for (size_t i = 0; i < op->nnames; i++)
		free(op->names[i]);
	free(op->names);
	free(op->nodes);
	free(op->cnt);
	free(op->del);
	free(op->rows);
	free(op->msgs);
	free(op);
}
