/* wantset — see wantset.h. Replace and rebind build a new table and entry array from the old
 * one (moving tile references, never copying them) and then rebuild the heap from the READY
 * entries, so the heap never holds an index into a freed array. */
#include "wantset.h"

#include <errno.h>
#include <stdlib.h>

#include "common/pixfmt.h"
#include "common/xalloc.h"
#include "engine/node.h"
#include "engine/planet.h"

#define MOVED 0xff /* an old entry whose state went to the new set */

void wantset_init(struct wantset *ws)
{
	*ws = (struct wantset){ 0 };
}

void wantset_fini(struct wantset *ws)
{
	for (size_t i = 0; i < ws->n; i++)
		if (ws->e[i].state == WS_READY)
			tile_unref(ws->e[i].t);
	free(ws->e);
	free(ws->tab);
	free(ws->heap);
	*ws = (struct wantset){ 0 };
}

static size_t slot(const struct wantset *ws, const struct tile_key *k)
{
	return (size_t)grid_key_hash(k) & (ws->tcap - 1);
}

long wantset_find(const struct wantset *ws, const struct tile_key *k)
{
	if (!ws->tcap)
		return -1;
	for (size_t i = slot(ws, k);; i = (i + 1) & (ws->tcap - 1)) {
		uint32_t v = ws->tab[i];
		if (!v)
			return -1;
		if (grid_key_equal(&ws->e[v - 1].key, k))
			return (long)(v - 1);
	}
}

/* Appends e unless its key is present (then returns false). The table must have room. */
static bool add(struct wantset *ws, const struct wantset_entry *e)
{
	size_t i = slot(ws, &e->key);
	for (; ws->tab[i]; i = (i + 1) & (ws->tcap - 1))
		if (grid_key_equal(&ws->e[ws->tab[i] - 1].key, &e->key))
			return false;
	if (ws->n == ws->cap) {
		ws->cap = ws->cap ? ws->cap * 2 : 64;
		ws->e = xrealloc(ws->e, ws->cap * sizeof *ws->e);
	}
	ws->e[ws->n] = *e;
	ws->tab[i] = (uint32_t)++ws->n;
	return true;
}

/* An empty set (entries and table) with table room for n entries; the heap moves over. */
static struct wantset fresh(struct wantset *old, size_t n)
{
	struct wantset nw = { .heap = old->heap, .capheap = old->capheap };
	size_t need = 16;
	while (need < n * 2 + 2)
		need *= 2;
	nw.tab = xcalloc(need, sizeof *nw.tab);
	nw.tcap = need;
	return nw;
}

/* ---- ready heap: class, then level coarse first, then want order ---------------------- */

static uint64_t prio(const struct wantset_entry *e)
{
	return (uint64_t)e->cls << 56 | (uint64_t)e->key.ly << 48 | (uint64_t)e->key.lx << 40 |
	       e->order;
}

static void heap_push(struct wantset *ws, uint32_t idx)
{
	if (ws->nheap == ws->capheap) {
		ws->capheap = ws->capheap ? ws->capheap * 2 : 64;
		ws->heap = xrealloc(ws->heap, ws->capheap * sizeof *ws->heap);
	}
	size_t i = ws->nheap++;
	uint64_t p = prio(&ws->e[idx]);
	while (i > 0) {
		size_t up = (i - 1) / 2;
		if (prio(&ws->e[ws->heap[up]]) <= p)
			break;
		ws->heap[i] = ws->heap[up];
		i = up;
	}
	ws->heap[i] = idx;
}

static uint32_t heap_pop(struct wantset *ws)
{
	uint32_t top = ws->heap[0];
	uint32_t last = ws->heap[--ws->nheap];
	size_t i = 0, n = ws->nheap;
	uint64_t p = n ? prio(&ws->e[last]) : 0;
	for (;;) {
		size_t c = 2 * i + 1;
		if (c >= n)
			break;
		if (c + 1 < n && prio(&ws->e[ws->heap[c + 1]]) < prio(&ws->e[ws->heap[c]]))
			c++;
		if (prio(&ws->e[ws->heap[c]]) >= p)
			break;
		ws->heap[i] = ws->heap[c];
		i = c;
	}
	if (n)
		ws->heap[i] = last;
	return top;
}

/* Replaces ws's contents with nw (old entries already moved or released). */
static void install(struct wantset *ws, struct wantset nw)
{
	free(ws->e);
	free(ws->tab);
	*ws = nw;
	ws->nheap = 0;
	ws->held = 0;
	ws->parked = 0;
	for (size_t i = 0; i < ws->n; i++) {
		if (ws->e[i].state != WS_READY)
			continue;
		heap_push(ws, (uint32_t)i);
		if (ws->e[i].t)
			ws->held += ws->e[i].t->nbytes;
		ws->parked += wantset_parked(&ws->e[i]);
	}
}

void wantset_replace(struct wantset *ws, uint32_t pid, const struct wantset_entry *add_e,
		     size_t n, struct wantset_drops *d)
{
	/* The new set: other planets' entries as they are, then the new ones, carrying the state
	 * of entries that stay. */
	struct wantset *old = ws;
	size_t total = n;
	for (size_t i = 0; i < old->n; i++)
		total += old->e[i].pid != pid;
	struct wantset nw = fresh(old, total);
	for (size_t i = 0; i < old->n; i++)
		if (old->e[i].pid != pid)
			add(&nw, &old->e[i]);
	for (size_t i = 0; i < n; i++) {
		struct wantset_entry e = add_e[i];
		e.state = WS_WANTED;
		e.t = NULL;
		e.err = 0;
		long oi = wantset_find(old, &e.key);
		bool stays = oi >= 0 && old->e[oi].pid == pid;
		if (stays) {
			const struct wantset_entry *o = &old->e[oi];
			if (o->state == WS_SENT) {
				e.state = WS_SENT;
			} else if (o->state == WS_READY) {
				e.state = WS_READY;
				e.t = o->t;
				e.err = o->err;
			}
		}
		if (add(&nw, &e) && stays)
			old->e[oi].state = MOVED;
	}
	/* What left the set unsent is dropped (and freed when it was ready). */
	for (size_t i = 0; i < old->n; i++) {
		struct wantset_entry *o = &old->e[i];
		if (o->pid != pid || o->state == MOVED || o->state == WS_SENT)
			continue;
		if (o->state == WS_READY) {
			tile_unref(o->t);
			d->stale++;
		}
		d->dropped++;
	}
	install(ws, nw);
}

size_t wantset_rebind(struct wantset *ws, wantset_resolve_fn *resolve, void *ud,
		      struct wantset_drops *d)
{
	struct wantset nw = fresh(ws, ws->n);
	size_t regen = 0;
	for (size_t i = 0; i < ws->n; i++) {
		struct wantset_entry e = ws->e[i];
		struct node *nd = resolve(ud, e.pid, e.layer);
		bool keep = nd != NULL;
		if (keep && nd->hash != e.key.node) {
			if (e.state == WS_READY) {
				tile_unref(e.t);
				d->stale++;
			}
			e.key.node = nd->hash;
			e.state = WS_WANTED;
			e.t = NULL;
			e.err = 0;
			regen++;
		}
		e.node = nd;
		if (keep && add(&nw, &e))
			continue;
		if (e.state == WS_READY) /* dropped (or a duplicate key) */
			tile_unref(e.t);
		if (e.state != WS_SENT)
			d->dropped++;
	}
	install(ws, nw);
	return regen;
}

uint64_t wantset_entry_bytes(const struct wantset_entry *e)
{
	uint64_t T = e->node->planet->tile_size;
	return T * T * pix_bytes(e->node->out);
}

static int cmp_prio(const void *a, const void *b, void *ud)
{
	const struct wantset *ws = ud;
	uint64_t x = prio(&ws->e[*(const uint32_t *)a]), y = prio(&ws->e[*(const uint32_t *)b]);
	return (x > y) - (x < y);
}

struct want *wantset_wants_within(const struct wantset *ws, uint64_t credit, wantset_made_fn *made,
				  void *ud, size_t *n, bool *left)
{
	uint64_t used = 0;
	size_t nwant = 0;
	for (size_t i = 0; i < ws->n; i++) {
		if (ws->e[i].state == WS_WANTED)
			nwant++;
		else if (ws->e[i].state == WS_READY)
			used += wantset_entry_bytes(&ws->e[i]);
	}
	uint32_t *idx = xmalloc((nwant ? nwant : 1) * sizeof *idx);
	size_t k = 0;
	for (size_t i = 0; i < ws->n; i++)
		if (ws->e[i].state == WS_WANTED)
			idx[k++] = (uint32_t)i;
	qsort_r(idx, nwant, sizeof *idx, cmp_prio, (void *)ws);
	struct want *list = xmalloc((nwant ? nwant : 1) * sizeof *list);
	bool first = used == 0, full = false;
	size_t m = 0;
	for (k = 0; k < nwant; k++) {
		const struct wantset_entry *e = &ws->e[idx[k]];
		uint64_t b = wantset_entry_bytes(e);
		full = full || (used + b > credit && !first);
		if (full && !(made && made(ud, &e->key)))
			continue;
		first = false;
		used += full ? 0 : b;
		list[m++] = (struct want){ .node = e->node, .key = e->key,
					   .cls = (enum sched_class)e->cls };
	}
	free(idx);
	*n = m;
	*left = m < nwant;
	return list;
}

bool wantset_ready(struct wantset *ws, const struct tile_key *k, struct tile *t, int err,
		   bool park, uint64_t budget, bool *parked)
{
	*parked = park;
	long i = wantset_find(ws, k);
	if (i < 0 || ws->e[i].state != WS_WANTED) {
		tile_unref(t);
		return false;
	}
	struct wantset_entry *e = &ws->e[i];
	e->state = WS_READY;
	e->err = t || park ? 0 : (err < 0 ? err : -EIO);
	if (t && ws->held && ws->held + t->nbytes > budget) {
		tile_unref(t);
		t = NULL;
		*parked = true;
	}
	e->t = t;
	if (t)
		ws->held += t->nbytes;
	ws->parked += wantset_parked(e);
	heap_push(ws, (uint32_t)i);
	return true;
}

void wantset_unpark(struct wantset *ws, struct wantset_entry *e, struct tile *t)
{
	ws->parked -= wantset_parked(e);
	e->t = t;
	ws->held += t->nbytes;
}

void wantset_rewant(struct wantset *ws, struct wantset_entry *e)
{
	ws->parked -= wantset_parked(e);
	if (e->t)
		ws->held -= e->t->nbytes;
	tile_unref(e->t);
	e->t = NULL;
	e->err = 0;
	e->state = WS_WANTED;
}

size_t wantset_nready(const struct wantset *ws)
{
	return ws->nheap;
}

struct wantset_entry *wantset_pop(struct wantset *ws)
{
	while (ws->nheap) {
		struct wantset_entry *e = &ws->e[heap_pop(ws)];
		if (e->state == WS_READY)
			return e;
	}
	return NULL;
}

void wantset_sent(struct wantset *ws, struct wantset_entry *e)
{
	ws->parked -= wantset_parked(e);
	if (e->t)
		ws->held -= e->t->nbytes;
	e->state = WS_SENT;
	tile_unref(e->t);
	e->t = NULL;
}
