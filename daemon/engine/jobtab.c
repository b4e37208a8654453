/* jobtab — see jobtab.h. A chained hash map over tile keys, the job graph, and a binary
 * min-heap of entries that carry their own ordering key.
 *
 * Graph invariants: j->dep[k] is the job producing input k while it is missing (j is then in
 * that job's dependents list once, however many slots it fills); a job the current marking
 * pass reached has all its pending dependencies marked too, so cancelling unmarked jobs never
 * strands a wanted one; wanters are valid only for the epoch they were recorded in.
 */
#include "jobtab.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"
#include "planet.h"

bool job_prio_less(const struct job_prio *a, const struct job_prio *b)
{
	if (a->cls != b->cls)
		return a->cls < b->cls;
	if (a->ly != b->ly)
		return a->ly < b->ly;
	if (a->lx != b->lx)
		return a->lx < b->lx;
	return a->order < b->order;
}

void jobmap_init(struct jobmap *m)
{
	m->nb = 256;
	m->n = 0;
	m->b = xcalloc(m->nb, sizeof *m->b);
}

void jobmap_fini(struct jobmap *m)
{
	free(m->b);
	m->b = NULL;
	m->nb = m->n = 0;
}

struct job *jobmap_find(const struct jobmap *m, const struct tile_key *k)
{
	return jobmap_find_hashed(m, k, grid_key_hash(k));
}

struct job *jobmap_find_hashed(const struct jobmap *m, const struct tile_key *k, uint64_t h)
{
	for (struct job *j = m->b[h & (m->nb - 1)]; j; j = j->hnext)
		if (j->hash == h && grid_key_equal(&j->key, k))
			return j;
	return NULL;
}

static void grow(struct jobmap *m)
{
	size_t nb = m->nb * 2;
	struct job **b = xcalloc(nb, sizeof *b);
	/* Each old chain splits into two new ones, its order kept (oldest first). */
	struct job **tail[2];
	for (size_t i = 0; i < m->nb; i++) {
		tail[0] = &b[i];
		tail[1] = &b[i + m->nb];
		for (struct job *j = m->b[i], *next; j; j = next) {
			next = j->hnext;
			int hi = (j->hash & m->nb) != 0;
			*tail[hi] = j;
			tail[hi] = &j->hnext;
		}
		*tail[0] = NULL;
		*tail[1] = NULL;
	}
	free(m->b);
	m->b = b;
	m->nb = nb;
}

/* At the chain's tail: jobs mostly finish in the order they were created, so the one removed
 * is then at the head and removal reads no other job. The chain was just walked by the
 * jobmap_find that preceded the insert, so reaching its tail costs no cache miss. */
void jobmap_insert(struct jobmap *m, struct job *j)
{
	j->hash = grid_key_hash(&j->key);
	j->hnext = NULL;
	struct job **p = &m->b[j->hash & (m->nb - 1)];
	while (*p)
		p = &(*p)->hnext;
	*p = j;
	if (++m->n > m->nb / 2) /* short chains: each link is a cache miss on a big map */
		grow(m);
}

void jobmap_remove(struct jobmap *m, struct job *j)
{
	struct job **p = &m->b[j->hash & (m->nb - 1)];
	while (*p && *p != j)
		p = &(*p)->hnext;
	if (*p) {
		*p = j->hnext;
		m->n--;
	}
}

struct job **jobmap_list(const struct jobmap *m, size_t *n)
{
	struct job **out = xmalloc((m->n ? m->n : 1) * sizeof *out);
	size_t k = 0;
	for (size_t i = 0; i < m->nb; i++)
		for (struct job *j = m->b[i]; j; j = j->hnext)
			out[k++] = j;
	*n = k;
	return out;
}

#define SPARE_MAX 4096 /* freed jobs kept for reuse */
#define JOB_BLOCK 64

enum { BL_PARTIAL, BL_ALL }; /* a block's two lists */

struct jobblock {
	struct {
		struct jobblock *prev, *next;
	} l[2];
	struct job *free; /* its free jobs, linked by next */
	unsigned nfree;
	struct job jobs[JOB_BLOCK];
};

static void block_push(struct jobblock **head, struct jobblock *b, int l)
{
	b->l[l].prev = NULL;
	b->l[l].next = *head;
	if (*head)
		(*head)->l[l].prev = b;
	*head = b;
}

static void block_del(struct jobblock **head, struct jobblock *b, int l)
{
	if (b->l[l].prev)
		b->l[l].prev->l[l].next = b->l[l].next;
	else
		*head = b->l[l].next;
	if (b->l[l].next)
		b->l[l].next->l[l].prev = b->l[l].prev;
}

static void free_block(struct jobblock *b)
{
	for (int i = 0; i < JOB_BLOCK; i++) {
		free(b->jobs[i].dependents);
		free(b->jobs[i].wanters);
	}
	free(b);
}

/* A new block, all free, at the head of both lists. */
static void add_block(struct jobgraph *g)
{
	struct jobblock *b = xcalloc(1, sizeof *b);
	for (int i = JOB_BLOCK; i-- > 0;) {
		b->jobs[i].block = b;
		b->jobs[i].next = b->free;
		b->free = &b->jobs[i];
	}
	b->nfree = JOB_BLOCK;
	g->nspare += JOB_BLOCK;
	block_push(&g->partial, b, BL_PARTIAL);
	block_push(&g->blocks, b, BL_ALL);
}

static void free_job(struct jobgraph *g, struct job *j)
{
	for (int k = 0; k < j->nin; k++)
		tile_unref(j->in[k]);
	if (j->in != j->in_s) {
		free(j->in);
		free(j->dep);
	}
	tile_unref(j->result);
	planet_unref(j->node->planet);
	if (!g)
		return; /* jobgraph_fini frees the blocks */
	struct jobblock *b = j->block;
	j->next = b->free;
	b->free = j;
	g->nspare++;
	if (b->nfree++ == 0) /* it has a free job again */
		block_push(&g->partial, b, BL_PARTIAL);
	if (b->nfree == JOB_BLOCK && g->nspare > SPARE_MAX) {
		block_del(&g->partial, b, BL_PARTIAL);
		block_del(&g->blocks, b, BL_ALL);
		g->nspare -= JOB_BLOCK;
		free_block(b);
	}
}

void jobgraph_ready(struct jobgraph *g, struct job *j)
{
	if (g->npush == g->cappush) {
		g->cappush = g->cappush ? g->cappush * 2 : 256;
		g->push = xrealloc(g->push, g->cappush * sizeof *g->push);
	}
	g->push[g->npush++] = j;
}

/* A zeroed job from a block (keeping its lists' buffers). */
static struct job *alloc_job(struct jobgraph *g)
{
	if (!g->partial)
		add_block(g);
	struct jobblock *b = g->partial;
	struct job *j = b->free;
	b->free = j->next;
	g->nspare--;
	if (--b->nfree == 0)
		block_del(&g->partial, b, BL_PARTIAL);
	struct job **dependents = j->dependents;
	struct job_wanter *wanters = j->wanters;
	size_t capdependents = j->capdependents, capwanters = j->capwanters;
	memset(j, 0, sizeof *j);
	j->block = b;
	j->dependents = dependents;
	j->capdependents = capdependents;
	j->wanters = wanters;
	j->capwanters = capwanters;
	j->in = j->in_s;
	j->dep = j->dep_s;
	return j;
}

static void waiting_add(struct jobgraph *g, struct job *j)
{
	j->mstate = JOB_WAITING;
	atomic_fetch_add(&g->waiting, 1);
	j->wprev = NULL;
	j->wnext = g->waiting_list;
	if (j->wnext)
		j->wnext->wprev = j;
	g->waiting_list = j;
}

/* Takes j (JOB_WAITING) off the waiting list; the caller sets its new state. */
static void waiting_del(struct jobgraph *g, struct job *j)
{
	atomic_fetch_sub(&g->waiting, 1);
	if (j->wprev)
		j->wprev->wnext = j->wnext;
	else
		g->waiting_list = j->wnext;
	if (j->wnext)
		j->wnext->wprev = j->wprev;
	j->wprev = j->wnext = NULL;
}

static void remove_dependent(struct job *dj, struct job *j)
{
	for (size_t i = 0; i < dj->ndependents;)
		if (dj->dependents[i] == j)
			dj->dependents[i] = dj->dependents[--dj->ndependents];
		else
			i++;
}

static void link_dep(struct job *j, int k, struct job *dj)
{
	bool seen = false;
	for (int i = 0; i < k; i++)
		seen |= j->dep[i] == dj;
	j->dep[k] = dj;
	j->missing++;
	if (seen)
		return;
	if (dj->ndependents == dj->capdependents) {
		dj->capdependents = dj->capdependents ? dj->capdependents * 2 : 4;
		dj->dependents = xrealloc(dj->dependents, dj->capdependents * sizeof *dj->dependents);
	}
	dj->dependents[dj->ndependents++] = j;
}

/* The skip memory (jobgraph.skip): lazy inputs pay only where they are not needed, and a
 * job that defers what it then needs is only later (each masked noise waits for its mask's
 * chain: over land a cold flight at 6000 m fell from 96 % to 50-61 % full frames, measured).
 * A tile's mask is much like its parent's, so a job defers only where its parent key (level
 * lx - 1, ly - 1: its quarter) found them not needed; the top levels, and keys whose parent
 * was not made lately, make them at once, as before there were lazy inputs. The table is
 * exact (whole keys compared), so a guess is never another key's. */

/* The slot of k in s: where it is, or the empty one where it would go. */
static size_t skip_slot(const struct skipset *s, const struct tile_key *k, uint64_t h)
{
	size_t i = h & (JOBGRAPH_SKIPMEM - 1);
	while (s->h[i] && !(s->h[i] == h && grid_key_equal(&s->k[i], k)))
		i = (i + 1) & (JOBGRAPH_SKIPMEM - 1);
	return i;
}

static void skip_remember(struct jobgraph *g, const struct tile_key *k)
{
	struct skipset *s = &g->skip[0];
	if (!s->h) {
		for (int i = 0; i < 2; i++) {
			g->skip[i].k = xcalloc(JOBGRAPH_SKIPMEM, sizeof *g->skip[i].k);
			g->skip[i].h = xcalloc(JOBGRAPH_SKIPMEM, sizeof *g->skip[i].h);
		}
	}
	uint64_t h = grid_key_hash(k) | 1;
	size_t i = skip_slot(s, k, h);
	if (s->h[i])
		return;
	if (s->n == JOBGRAPH_SKIPMEM / 2) { /* full: the older generation goes */
		struct skipset old = g->skip[1];
		g->skip[1] = *s;
		memset(old.h, 0, JOBGRAPH_SKIPMEM * sizeof *old.h);
		old.n = 0;
		*s = old;
		i = skip_slot(s, k, h);
	}
	s->h[i] = h;
	s->k[i] = *k;
	s->n++;
}

static bool parent_skipped(const struct jobgraph *g, const struct tile_key *k)
{
	if (!g->skip[0].h || k->lx == 0 || k->ly == 0)
		return false;
	struct tile_key p = *k;
	p.lx--, p.ly--, p.x >>= 1, p.y >>= 1;
	uint64_t h = grid_key_hash(&p) | 1;
	for (int i = 0; i < 2; i++)
		if (g->skip[i].h[skip_slot(&g->skip[i], &p, h)])
			return true;
	return false;
}

static int deps_of(const struct job *j, struct node_dep *deps)
{
	const struct node *node = j->node;
	return node->type->deps ? node->type->deps(node, &j->key, deps)
				: node_default_deps(node, &j->key, deps);
}

/* Links j to the job making dependency k, or holds the cached tile, or (create) makes the
 * job. Returns the job linked (NULL: held, or absent without create). Without create it
 * only looks: an absent tile is not counted as a cache miss (nobody asked for it yet). */
static struct job *hold_or_link(struct jobgraph *g, struct job *j, int k, const struct node_dep *d,
				bool create)
{
	struct job *dj = jobmap_find(&g->map, &d->key);
	if (dj) {
		atomic_fetch_add(&g->merged, 1);
	} else {
		if (create || cache_contains(g->cache, &d->key))
			j->in[k] = cache_lookup(g->cache, &d->key);
		if (j->in[k] || !create)
			return NULL;
		dj = jobgraph_create(g, d->node, &d->key);
	}
	link_dep(j, k, dj);
	return dj;
}

/* j holds every dependency but its lazy ones: asks the node which of those it needs and
 * makes (or holds) them, each new job at j's priority. */
static void open_lazy(struct jobgraph *g, struct job *j)
{
	struct node_dep deps[NODE_MAX_DEPS];
	uint32_t lazy = j->lazy;
	j->lazy = 0;
	int nd = deps_of(j, deps);
	for (int k = 0; k < nd && k < j->nin; k++) {
		if (!(lazy & 1u << k))
			continue;
		if (!j->node->type->needed(j->node, k, j->in, j->nin)) {
			atomic_fetch_add(&g->skipped, 1);
			skip_remember(g, &j->key);
			continue;
		}
		struct job *dj = hold_or_link(g, j, k, &deps[k], true);
		if (dj)
			jobgraph_visit(g, dj, &j->prio);
	}
}

/* Creates j's missing dependencies (or holds cached ones) and queues j when none is missing. */
static void resolve(struct jobgraph *g, struct job *j)
{
	struct node_dep deps[NODE_MAX_DEPS];
	struct node *node = j->node;
	int nd = deps_of(j, deps);
	if (nd < 0 || nd > NODE_MAX_DEPS) {
		j->err = nd < 0 ? nd : -E2BIG;
		j->mstate = JOB_SUBMITTED;
		j->next = g->fails;
		g->fails = j;
		return;
	}
	if (nd > JOB_INLINE_DEPS && j->in == j->in_s) {
		j->in = xcalloc(NODE_MAX_DEPS, sizeof *j->in);
		j->dep = xcalloc(NODE_MAX_DEPS, sizeof *j->dep);
	}
	j->nin = nd;
	j->lazy = node->type->lazy && node->type->needed && parent_skipped(g, &j->key)
			  ? node->type->lazy(node, &j->key)
			  : 0;
	j->lazy &= nd < 32 ? (1u << nd) - 1 : ~0u;
	for (int k = 0; k < nd; k++)
		if (!(j->lazy & 1u << k))
			hold_or_link(g, j, k, &deps[k], true);
	/* A lazy input that is cached or being made anyway (often by the other inputs' own
	 * subgraphs, just created) costs nothing: hold it now rather than miss it later, when the
	 * cache may have let it go. */
	for (int k = 0; k < nd && j->lazy; k++)
		if ((j->lazy & 1u << k) && (hold_or_link(g, j, k, &deps[k], false) || j->in[k]))
			j->lazy &= ~(1u << k);
	if (j->missing == 0 && j->lazy)
		open_lazy(g, j); /* its new jobs get j's priority when the caller visits j */
	if (j->missing == 0) {
		j->mstate = JOB_SUBMITTED;
		jobgraph_ready(g, j);
	} else {
		waiting_add(g, j);
	}
}

struct job *jobgraph_create(struct jobgraph *g, struct node *node, const struct tile_key *key)
{
	struct job *j = alloc_job(g);
	j->key = *key;
	j->node = node;
	planet_ref(node->planet); /* the planet outlives every job on its nodes */
	j->seq = g->seq++;
	jobmap_insert(&g->map, j);
	bool keeps = store_keeps(node);
	bool disk = g->store && keeps && store_contains(g->store, key);
	if (disk || (g->remote && keeps)) {
		/* A worker loads it (disk, then the remote tier, which the manager does not ask:
		 * that is a network round trip); its inputs are resolved only if that fails. */
		j->from_store = true;
		j->from_disk = disk;
		j->mstate = JOB_SUBMITTED;
		jobgraph_ready(g, j);
		return j;
	}
	resolve(g, j);
	return j;
}

void jobgraph_regenerate(struct jobgraph *g, struct job *j)
{
	j->from_store = false;
	j->from_disk = false;
	j->rstate = JOB_R_NONE;
	j->err = 0;
	resolve(g, j);
	for (int k = 0; k < j->nin; k++)
		if (j->dep[k])
			jobgraph_visit(g, j->dep[k], &j->prio);
}

void jobgraph_new_epoch(struct jobgraph *g)
{
	g->epoch++;
	g->marked_waiting = 0;
}

void jobgraph_visit(struct jobgraph *g, struct job *j, const struct job_prio *p)
{
	if (j->mark != g->epoch) {
		j->mark = g->epoch;
		j->prio = *p;
		if (j->mstate == JOB_WAITING)
			g->marked_waiting++;
	} else if (job_prio_less(p, &j->prio)) {
		j->prio = *p;
	} else {
		return;
	}
	for (int k = 0; k < j->nin; k++)
		if (j->dep[k])
			jobgraph_visit(g, j->dep[k], p);
}

void jobgraph_add_wanter(struct jobgraph *g, struct job *j, struct sched_req *r, size_t idx)
{
	if (j->wanters_epoch != g->epoch) {
		j->wanters_epoch = g->epoch;
		j->nwanters = 0;
	}
	struct job_wanter w = { r, (uint32_t)idx };
	if (j->nwanters == 0) {
		j->wanter0 = w; /* most jobs have one: no allocation */
		j->nwanters = 1;
		return;
	}
	if (j->nwanters - 1 == j->capwanters) {
		j->capwanters = j->capwanters ? j->capwanters * 2 : 2;
		j->wanters = xrealloc(j->wanters, j->capwanters * sizeof *j->wanters);
	}
	j->wanters[j->nwanters++ - 1] = w;
}

/* Reports j's outcome to every want entry waiting for it, each with a reference of its own:
 * the last one gets j->result's (one reference count change less per tile, on a line the
 * worker that made the tile last wrote). */
static void report_job(struct jobgraph *g, struct job *j, int err)
{
	if (j->wanters_epoch != g->epoch || j->nwanters == 0)
		return;
	struct tile *t = j->result;
	size_t n = j->nwanters;
	j->nwanters = 0;
	for (size_t i = 0; i + 1 < n; i++)
		g->report(g->ud, i ? &j->wanters[i - 1] : &j->wanter0, t ? tile_ref(t) : NULL, err);
	j->result = NULL;
	g->report(g->ud, n > 1 ? &j->wanters[n - 2] : &j->wanter0, t, err);
}

/* Unlinks j from the jobs it waits for, drops it from the map and frees it. */
static void drop_job(struct jobgraph *g, struct job *j)
{
	for (int k = 0; k < j->nin; k++)
		if (j->dep[k])
			remove_dependent(j->dep[k], j);
	if (j->mstate == JOB_WAITING)
		waiting_del(g, j);
	if (j->leased && g->remote) /* cancelled or failed before it was generated */
		g->remote->ops->release(g->remote, &j->key);
	jobmap_remove(&g->map, j);
	free_job(g, j);
}

/* j failed with err: its wanters hear of it, and so does everything that depends on it. */
static void fail_job(struct jobgraph *g, struct job *j, int err)
{
	report_job(g, j, err);
	while (j->ndependents > 0)
		fail_job(g, j->dependents[0], err); /* unlinks itself from j */
	drop_job(g, j);
}

void jobgraph_complete(struct jobgraph *g, struct job *j)
{
	struct tile *t = j->result;
	if (!t) {
		fail_job(g, j, j->err);
		return;
	}
	if (t->lazy_unneeded)
		skip_remember(g, &j->key);
	for (size_t i = 0; i < j->ndependents; i++) {
		struct job *d = j->dependents[i];
		for (int k = 0; k < d->nin; k++) {
			if (d->dep[k] != j)
				continue;
			d->dep[k] = NULL;
			d->in[k] = tile_ref(t);
			d->missing--;
		}
		if (d->missing == 0 && d->lazy)
			open_lazy(g, d);
		if (d->missing == 0) {
			waiting_del(g, d);
			d->mstate = JOB_SUBMITTED;
			jobgraph_ready(g, d);
		}
	}
	j->ndependents = 0;
	report_job(g, j, 0); /* last: it may give t's reference away */
	drop_job(g, j);
}


void jobgraph_init(struct jobgraph *g, struct cache *c,
		   void (*report)(void *ud, const struct job_wanter *w, struct tile *t, int err),
		   void *ud)
{
	jobmap_init(&g->map);
	g->cache = c;
	g->epoch = g->seq = 0;
	g->marked_waiting = 0;
	g->push = NULL;
	g->npush = g->cappush = 0;
	g->fails = NULL;
	g->waiting_list = NULL;
	g->blocks = g->partial = NULL;
	g->nspare = 0;
	g->report = report;
	g->ud = ud;
	atomic_init(&g->merged, 0);
	atomic_init(&g->skipped, 0);
	memset(g->skip, 0, sizeof g->skip);
	atomic_init(&g->waiting, 0);
	atomic_init(&g->cancelled, 0);
	atomic_init(&g->failed, 0);
}

void jobgraph_fini(struct jobgraph *g)
{
	for (int i = 0; i < 2; i++) {
		free(g->skip[i].k);
		free(g->skip[i].h);
	}
	memset(g->skip, 0, sizeof g->skip);
	size_t n;
	struct job **all = jobmap_list(&g->map, &n);
	for (size_t i = 0; i < n; i++)
		free_job(NULL, all[i]);
	free(all);
	jobmap_fini(&g->map);
	free(g->push);
	g->push = NULL;
	g->npush = g->cappush = 0;
	while (g->blocks) {
		struct jobblock *b = g->blocks;
		g->blocks = b->l[BL_ALL].next;
		free_block(b);
	}
	g->partial = NULL;
	g->nspare = 0;
}

void jobgraph_cancel_unmarked(struct jobgraph *g, struct job *cancel, bool after_pass)
{
	/* Each waiting job counts once in marked_waiting (marked once per epoch) and none left
	 * the waiting state during the pass: equal counts mean every waiting job is marked. */
	bool all_marked = after_pass && g->marked_waiting == atomic_load(&g->waiting);
	for (struct job *j = all_marked ? NULL : g->waiting_list, *next; j; j = next) {
		next = j->wnext;
		if (j->mark != g->epoch) {
			waiting_del(g, j);
			j->mstate = JOB_CANCELLED;
			j->next = cancel;
			cancel = j;
		}
	}
	/* Unlink from surviving inputs first: cancelled jobs may depend on each other. */
	for (struct job *j = cancel; j; j = j->next) {
		for (int k = 0; k < j->nin; k++)
			if (j->dep[k] && j->dep[k]->mstate != JOB_CANCELLED)
				remove_dependent(j->dep[k], j);
		atomic_fetch_add(&g->cancelled, 1);
	}
	while (cancel) {
		struct job *j = cancel;
		cancel = j->next;
		if (j->leased && g->remote) /* nobody wants it now: others need not wait */
			g->remote->ops->release(g->remote, &j->key);
		jobmap_remove(&g->map, j);
		free_job(g, j);
	}
}

static bool before(const struct jobheap_ent *a, const struct jobheap_ent *b)
{
	return a->key < b->key || (a->key == b->key && a->seq < b->seq);
}

static void sift_up(struct jobheap *h, size_t i)
{
	struct jobheap_ent e = h->a[i];
	while (i > 0) {
		size_t p = (i - 1) / 2;
		if (!before(&e, &h->a[p]))
			break;
		h->a[i] = h->a[p];
		i = p;
	}
	h->a[i] = e;
}

static void sift_down(struct jobheap *h, size_t i)
{
	struct jobheap_ent e = h->a[i];
	for (;;) {
		size_t c = 2 * i + 1;
		if (c >= h->n)
			break;
		if (c + 1 < h->n && before(&h->a[c + 1], &h->a[c]))
			c++;
		if (!before(&h->a[c], &e))
			break;
		h->a[i] = h->a[c];
		i = c;
	}
	h->a[i] = e;
}

void jobheap_fini(struct jobheap *h)
{
	free(h->a);
	h->a = NULL;
	h->n = h->cap = 0;
}

void jobheap_push(struct jobheap *h, struct job *j)
{
	if (h->n == h->cap) {
		h->cap = h->cap ? h->cap * 2 : 64;
		h->a = xrealloc(h->a, h->cap * sizeof *h->a);
	}
	h->a[h->n++] = (struct jobheap_ent){ job_prio_key(&j->qprio), j->seq, j };
	sift_up(h, h->n - 1);
}

struct job *jobheap_pop(struct jobheap *h)
{
	if (h->n == 0)
		return NULL;
	struct job *top = h->a[0].j;
	if (--h->n > 0) {
		/* Bottom-up: the hole at the root goes down to a leaf by the smaller child (one
		 * comparison a level), then the last entry, mostly among the largest, rises from
		 * there: about half the comparisons of sifting it down from the root. */
		size_t i = 0, n = h->n;
		for (size_t c; (c = 2 * i + 1) < n; i = c) {
			if (c + 1 < n && before(&h->a[c + 1], &h->a[c]))
				c++;
			h->a[i] = h->a[c];
		}
		h->a[i] = h->a[n];
		sift_up(h, i);
	}
	return top;
}

void jobheap_heapify(struct jobheap *h)
{
	for (size_t i = h->n / 2; i-- > 0;)
		sift_down(h, i);
}
