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
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/lonpoly.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/node.h"

#define NLY (GRID_MAX_LEVEL + 1)

#define CACHE_LS_DEFAULT 10000u
#define CACHE_LS_MAX (1u << 20)

struct nodeent {
	uint64_t hash;
	uint32_t planet, label; /* indices into names */
	uint8_t format;		/* enum pix_type of its tiles */
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
	/* CACHE_LS */
	bool ls;
	struct proto_cache_ls lq; /* planet unused: target names it */
	/* purge's polygon (q's rings and points, owned copies) */
	uint32_t *rings;
	struct proto_lonlat *pts;
	struct proto_cache_entry *ents;
	size_t nents, lscap, limit;
	uint64_t total, now_ns;
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
	if (q->filter & PROTO_COF_POLYGON) {
		struct geo_rect r;
		grid_tile_rect(k, &r);
		struct lonpoly poly = { q->nrings, q->rings, q->points };
		bool hit = false;
		/* the polygon's longitudes may run past ±180: the tile's copies there too */
		for (int s = -1; s <= 1 && !hit; s++)
			hit = lonpoly_touches_rect(&poly, r.west + 360.0 * s, r.south,
						   r.east + 360.0 * s, r.north);
		if (!hit)
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

/* Great-circle distance (metres, mean Earth-like radius r) from (lon, lat) to the nearest
 * point of the tile's rectangle: a spherical approximation, good enough for a listing filter. */
static double rect_distance(const struct geo_rect *rc, double lon, double lat, double r)
{
	double clat = fmin(fmax(lat, rc->south), rc->north);
	double w = rc->west, e = rc->east, l = fmod(lon + 540.0, 360.0) - 180.0;
	double clon;
	if (l >= w && l <= e) {
		clon = l;
	} else {
		double dw = fmod(w - l + 720.0, 360.0), de = fmod(l - e + 720.0, 360.0);
		clon = dw < de ? w : e;
	}
	double p1 = lat * M_PI / 180, p2 = clat * M_PI / 180;
	double dl = (clon - l) * M_PI / 180;
	double h = sin((p2 - p1) / 2) * sin((p2 - p1) / 2) +
		   cos(p1) * cos(p2) * sin(dl / 2) * sin(dl / 2);
	return 2 * r * asin(fmin(1.0, sqrt(h)));
}

/* Whether a CACHE_LS lists k. */
static bool ls_match(const struct cacheop *op, const struct tile_key *k)
{
	const struct proto_cache_ls *q = &op->lq;
	if (q->filter & PROTO_CLS_PLANET) {
		size_t i = node_of(op, k->node);
		if (i == op->nnodes || (int)op->nodes[i].planet != op->target)
			return false;
	}
	if ((q->filter & PROTO_CLS_LEVEL) &&
	    ((q->lx != PROTO_ANY_LX && k->lx != q->lx) || k->ly != q->ly))
		return false;
	if (q->filter & PROTO_CLS_NEAR) {
		struct geo_rect rc;
		grid_tile_rect(k, &rc);
		if (rect_distance(&rc, q->lon, q->lat, 6371008.8) > q->radius_m)
			return false;
	}
	return true;
}

static void ls_add(struct cacheop *op, const struct proto_cache_entry *e)
{
	op->total++;
	if (op->nents >= op->limit)
		return;
	if (op->nents == op->lscap) {
		op->lscap = op->lscap ? op->lscap * 2 : 1024;
		op->ents = xrealloc(op->ents, op->lscap * sizeof *op->ents);
	}
	op->ents[op->nents++] = *e;
}

static int ls_mem_fn(void *ud, const struct tile *t, uint64_t used_ns)
{
	struct cacheop *op = ud;
	if (ls_match(op, &t->key)) {
		uint64_t age = op->now_ns > used_ns ? (op->now_ns - used_ns) / 1000000000ull : 0;
		ls_add(op, &(struct proto_cache_entry){
				   .key = t->key, .format = (uint8_t)t->type,
				   .tier = PROTO_TIER_MEMORY, .bytes = (uint32_t)t->nbytes,
				   .age_s = age >= UINT32_MAX ? UINT32_MAX - 1 : (uint32_t)age });
	}
	return cancelled(op);
}

static int ls_disk_fn(void *ud, const struct store_entry *e)
{
	struct cacheop *op = ud;
	size_t i = node_of(op, e->key.node);
	if (i < op->nnodes && ls_match(op, &e->key)) /* entries of no planet: gc's */
		ls_add(op, &(struct proto_cache_entry){ .key = e->key,
							.format = op->nodes[i].format,
							.tier = PROTO_TIER_DISK, .bytes = e->bytes,
							.age_s = UINT32_MAX });
	return cancelled(op);
}

static void build_ls_replies(struct cacheop *op)
{
	size_t parts = (op->nents + PROTO_MAX_CACHE_ENTRIES - 1) / PROTO_MAX_CACHE_ENTRIES;
	if (!parts)
		parts = 1;
	op->msgs = xcalloc(parts, sizeof *op->msgs);
	for (size_t p = 0; p < parts; p++) {
		size_t off = p * PROTO_MAX_CACHE_ENTRIES;
		size_t k = op->nents - off < PROTO_MAX_CACHE_ENTRIES ? op->nents - off
								     : PROTO_MAX_CACHE_ENTRIES;
		op->msgs[op->nmsgs++] = (struct proto_msg){
			.type = PROTO_CACHE_ENTRIES,
			.cache_entries = { .req = op->lq.req, .more = p + 1 < parts,
					   .total = op->total, .count = (uint32_t)k,
					   .entries = op->ents + off } };
	}
}

static void *op_main(void *arg)
{
	struct cacheop *op = arg;
	if (op->ls) {
		if (op->cache)
			cache_foreach(op->cache, ls_mem_fn, op);
		if (op->store && !cancelled(op))
			op->err = store_iterate(op->store, ls_disk_fn, op);
		build_ls_replies(op);
		goto done;
	}
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
done:
	xmutex_lock(&op->mu);
	if (!cancelled(op))
		op->done(op->ud);
	xmutex_unlock(&op->mu);
	return NULL;
}

/* A new op with the node table of ps; target set when `planet` (may be NULL or "") names
 * one. Returns NULL (err filled) when it names none. */
static struct cacheop *op_new(const struct planet_set *ps, const char *planet, char err[256])
{
	struct cacheop *op = xcalloc(1, sizeof *op);
	op->target = -1;
	const char *want = planet && planet[0] ? planet : NULL;
	for (size_t i = 0; ps && i < ps->n; i++) {
		const struct planet *p = ps->planets[i];
		uint32_t pn = add_name(op, p->name);
		if (want && strcmp(want, p->name) == 0)
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
			op->nodes[op->nnodes++] = (struct nodeent){ n->hash, pn, add_name(op, label),
								    (uint8_t)n->out };
		}
	}
	if (op->nnodes > 1)
		qsort(op->nodes, op->nnodes, sizeof *op->nodes, cmp_node);
	if (want && op->target < 0) {
		err_set(err, "no planet \"%s\"", want);
		cacheop_destroy(op);
		return NULL;
	}
	return op;
}

static int op_run(struct cacheop *op, struct cache *cache, struct store *store,
		  void (*done)(void *ud), void *ud, struct cacheop **out, char err[256])
{
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
	struct cacheop *op = op_new(ps, q->planet, err);
	if (!op)
		return -ENOENT;
	op->q = *q;
	op->q.planet = NULL;
	if (q->filter & PROTO_COF_POLYGON) {
		op->rings = xmalloc(q->nrings * sizeof *op->rings);
		memcpy(op->rings, q->rings, q->nrings * sizeof *op->rings);
		op->pts = xmalloc((q->npoints ? q->npoints : 1) * sizeof *op->pts);
		memcpy(op->pts, q->points, q->npoints * sizeof *op->pts);
		op->q.rings = op->rings;
		op->q.points = op->pts;
	} else {
		op->q.rings = NULL;
		op->q.points = NULL;
	}
	return op_run(op, cache, store, done, ud, out, err);
}

int cacheop_start_ls(const struct proto_cache_ls *q, const struct planet_set *ps,
		     struct cache *cache, struct store *store, void (*done)(void *ud), void *ud,
		     struct cacheop **out, char err[256])
{
	*out = NULL;
	struct cacheop *op = op_new(ps, (q->filter & PROTO_CLS_PLANET) ? q->planet : NULL, err);
	if (!op)
		return -ENOENT;
	op->ls = true;
	op->lq = *q;
	op->lq.planet = NULL;
	op->limit = q->limit ? q->limit : CACHE_LS_DEFAULT;
	if (op->limit > CACHE_LS_MAX)
		op->limit = CACHE_LS_MAX;
	op->now_ns = cache_now_ns();
	return op_run(op, cache, store, done, ud, out, err);
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
	free(op->rings);
	free(op->pts);
	free(op->nodes);
	free(op->cnt);
	free(op->del);
	free(op->rows);
	free(op->ents);
	free(op->msgs);
	free(op);
}
