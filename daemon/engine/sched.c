/* sched — see sched.h. Design note:
 *
 * Locks (never nested; none is held across generation, callbacks or a cache call):
 *   in_mu  the manager's inbox: pending want lists, destroy requests, stop, and the manager's
 *          sleep. Requesters post under it and never wait on generation.
 *   q_mu   the ready heap, per-class queued counts, idle-worker count, worker stop flag.
 *   cache  taken by the manager (lookups) and workers (inserts) with neither lock above held.
 * Lock-free: finished jobs go back to the manager on `done`, a multi-producer stack that the
 * manager takes whole with one exchange (release push, acquire take: the job's result, err
 * and remote state travel with it). Only the push that finds the stack empty takes in_mu to
 * wake the manager, which checks the stack under in_mu before sleeping, so no wake is lost;
 * while the manager is busy, workers hand back any number of jobs with one atomic operation
 * each and no lock. `running` is an atomic counter, lowered before the job is pushed (so a
 * requester told of a tile never still sees its worker counted as running).
 * The manager owns everything else (job map, active requests, want lists and their entry
 * states, dependency links) and touches it without locks. A job moves to a worker through
 * q_mu (the worker reads only node, key and inputs) and back through `done` (result, err).
 *
 * Serial work per tile (the scheduler's ceiling is the manager thread): one creation (job
 * from a block, map insert), one heap push in a batch under q_mu, one completion (taken in a
 * batch; dependents, report with the job's own tile reference, map removal, job back to its
 * block) and one callback. Most of it is cache misses on a big map and on lines workers
 * wrote, so the loops over want entries, finished jobs and reports prefetch AHEAD entries
 * early (jobtab.h says what each structure does to avoid reading other jobs).
 * Workers signal q_cv only for the idle workers a batch needs, not a broadcast to all.
 *
 * Manager iteration: snapshot the inbox; install new want lists and apply destroys; when any
 * changed, recompute (an epoch-stamped marking pass over every active list: report cached
 * keys, find or create jobs depth-first, propagate the best priority to dependencies, record
 * which want entries wait on each job; then cancel queued and waiting jobs the pass did not
 * reach); process finished jobs incrementally (report to the waiting entries, hand the tile
 * to dependents); push newly ready jobs; run the callbacks with no lock held; finally free
 * destroyed requests (calling a released request's fin) and wake whoever waits in
 * sched_req_destroy.
 */
#include "sched.h"

#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "jobtab.h"
#include "planet.h"

enum entry_state { ENTRY_NEW = 0, ENTRY_PENDING, ENTRY_REPORTED, ENTRY_DUP };

struct sched_req {
	struct sched *s;
	sched_ready_fn fn;
	void *ud;

	/* Under s->in_mu. */
	struct want *pending;
	size_t npending;
	bool has_pending, destroy, in_changes;
	bool *ack; /* the destroyer's flag; NULL when destroyed on the manager thread */
	void (*fin)(void *ud); /* sched_req_release's: called when r is freed */
	struct sched_req *next_change;

	/* Manager only. */
	struct want *pend_m; /* snapshot of the inbox fields above */
	size_t npend_m;
	bool has_pend_m, destroy_m;
	bool *ack_m;
	struct sched_req *next_change_m;
	struct want *list; /* the installed want list; callbacks get pointers into it */
	size_t n;
	uint8_t *st;	 /* enum entry_state per entry */
	uint32_t *first; /* index of the first entry with the same key */
	uint64_t *hash;	 /* grid_key_hash of each entry's key */
	struct job **job; /* the job a PENDING entry waits for (alive while it is pending: it is
			   * reported when the job completes or fails, and a job a pending entry
			   * waits for is marked by every pass, so never cancelled) */
	bool active, dead;
	struct sched_req *prev, *next; /* active list */
};

struct report {
	struct sched_req *r;
	const struct want *w;
	struct tile *t; /* owned reference or NULL */
	int err;
};

struct sched {
	struct cache *cache;
	struct store *store; /* borrowed, optional */
	struct remote *remote; /* borrowed, optional */
	int nworkers, nice;
	pthread_t manager;
	pthread_t *workers;

	pthread_mutex_t in_mu;
	pthread_cond_t in_cv;  /* the manager waits for work */
	pthread_cond_t ack_cv; /* destroyers wait for the manager */
	struct sched_req *changes;
	bool in_stop;
	_Atomic(struct job *) done; /* finished jobs (and woken parked ones), linked by next_done */

	pthread_mutex_t q_mu;
	pthread_cond_t q_cv; /* workers wait for ready jobs */
	struct jobheap heap;
	uint64_t queued[SCHED_NCLASS];
	int idle; /* workers waiting on q_cv */
	bool q_stop;
	atomic_uint_fast64_t running;

	/* Manager only. */
	struct jobgraph g;
	struct sched_req *reqs; /* active requests */
	struct report *batch;	/* callbacks to run at the end of the iteration */
	size_t nbatch, capbatch;

	atomic_uint_fast64_t generated, loaded;
	atomic_int nice_err;
};

static void die(const char *what, int rc)
{
	fprintf(stderr, "sched: %s: %s\n", what, strerror(rc));
	abort();
}

/* first[i] = index of the first entry with w[i]'s key, hash[i] (when not NULL) its
 * grid_key_hash. Returns how many distinct keys. */
static size_t dedupe(const struct want *w, size_t n, uint32_t *first, uint64_t *hash)
{
	size_t cap = 16;
	while (cap < 2 * n)
		cap *= 2;
	uint32_t *tab = xmalloc(cap * sizeof *tab);
	memset(tab, 0xff, cap * sizeof *tab);
	size_t distinct = 0;
	for (size_t i = 0; i < n; i++) {
		uint64_t kh = grid_key_hash(&w[i].key);
		if (hash)
			hash[i] = kh;
		size_t h = kh & (cap - 1);
		first[i] = (uint32_t)i;
		while (tab[h] != UINT32_MAX) {
			if (grid_key_equal(&w[tab[h]].key, &w[i].key)) {
				first[i] = tab[h];
				break;
			}
			h = (h + 1) & (cap - 1);
		}
		if (first[i] == i) {
			tab[h] = (uint32_t)i;
			distinct++;
		}
	}
	free(tab);
	return distinct;
}

/* ---- manager: requests ---- */

static void add_report(struct sched *s, struct sched_req *r, size_t idx, struct tile *t, int err)
{
	if (s->nbatch == s->capbatch) {
		s->capbatch = s->capbatch ? s->capbatch * 2 : 64;
		s->batch = xrealloc(s->batch, s->capbatch * sizeof *s->batch);
	}
	r->st[idx] = ENTRY_REPORTED;
	s->batch[s->nbatch++] = (struct report){ r, &r->list[idx], t, err };
}

/* The graph's report hook (t owned): queues the callback unless the entry was already
 * reported. */
static void report_entry(void *ud, const struct job_wanter *w, struct tile *t, int err)
{
	struct sched *s = ud;
	struct sched_req *r = w->r;
	if (!r->dead && w->idx < r->n && r->st[w->idx] == ENTRY_PENDING)
		add_report(s, r, w->idx, t, err);
	else
		tile_unref(t);
}

static void activate(struct sched *s, struct sched_req *r)
{
	r->active = true;
	r->prev = NULL;
	r->next = s->reqs;
	if (s->reqs)
		s->reqs->prev = r;
	s->reqs = r;
}

static void deactivate(struct sched *s, struct sched_req *r)
{
	if (!r->active)
		return;
	if (r->prev)
		r->prev->next = r->next;
	else
		s->reqs = r->next;
	if (r->next)
		r->next->prev = r->prev;
	r->active = false;
}

/* Installs new lists and applies destroys from the snapshot ch. Returns whether any did. */
static bool apply_changes(struct sched *s, struct sched_req *ch)
{
	bool changed = false;
	for (struct sched_req *r = ch; r; r = r->next_change_m) {
		if (r->destroy_m) {
			deactivate(s, r);
			r->dead = true;
			free(r->pend_m);
			r->pend_m = NULL;
			changed = true;
			continue;
		}
		if (!r->has_pend_m)
			continue;
		free(r->list);
		free(r->st);
		free(r->first);
		free(r->hash);
		free(r->job);
		r->list = r->pend_m;
		r->n = r->npend_m;
		r->pend_m = NULL;
		size_t n1 = r->n ? r->n : 1;
		r->st = xcalloc(n1, 1);
		r->first = xmalloc(n1 * sizeof *r->first);
		r->hash = xmalloc(n1 * sizeof *r->hash);
		r->job = xmalloc(n1 * sizeof *r->job);
		dedupe(r->list, r->n, r->first, r->hash);
		for (size_t i = 0; i < r->n; i++)
			if (r->first[i] != i)
				r->st[i] = ENTRY_DUP;
		if (!r->active)
			activate(s, r);
		changed = true;
	}
	return changed;
}

static bool prio_equal(const struct job_prio *a, const struct job_prio *b)
{
	return a->cls == b->cls && a->ly == b->ly && a->lx == b->lx && a->order == b->order;
}

/* How far ahead the manager's loops ask for the lines they will touch (__builtin_prefetch). */
#define AHEAD 8

/* The marking pass over every active want list, then cancellation of what it missed. */
static void recompute(struct sched *s)
{
	jobgraph_new_epoch(&s->g);
	for (struct sched_req *r = s->reqs; r; r = r->next) {
		for (size_t i = 0; i < r->n; i++) {
			/* A new entry looks its key up in the job map: its bucket is fetched
			 * AHEAD entries early (a miss each on a big map). */
			if (i + AHEAD < r->n && r->st[i + AHEAD] == ENTRY_NEW)
				jobmap_prefetch(&s->g.map, r->hash[i + AHEAD]);
			const struct want *w = &r->list[i];
			struct job_prio p = { (uint8_t)w->cls, w->key.ly, w->key.lx, (uint32_t)i };
			if (r->st[i] == ENTRY_REPORTED)
				continue;
			if (r->st[i] == ENTRY_DUP) {
				/* Reported with its first entry, but its class may be better. */
				if (r->st[r->first[i]] == ENTRY_PENDING)
					jobgraph_visit(&s->g, r->job[r->first[i]], &p);
				continue;
			}
			struct job *j;
			if (r->st[i] == ENTRY_PENDING) {
				j = r->job[i]; /* no lookup: a pending entry's job is alive */
			} else if ((j = jobmap_find_hashed(&s->g.map, &w->key, r->hash[i]))) {
				atomic_fetch_add(&s->g.merged, 1);
			} else {
				struct tile *t = cache_lookup(s->cache, &w->key);
				if (t) {
					add_report(s, r, i, t, 0);
					continue;
				}
				j = jobgraph_create(&s->g, w->node, &w->key);
			}
			r->st[i] = ENTRY_PENDING;
			r->job[i] = j;
			jobgraph_visit(&s->g, j, &p);
			jobgraph_add_wanter(&s->g, j, r, i);
		}
	}

	/* Queued jobs the pass did not reach leave the heap; the rest take their new priority.
	 * Running jobs are not in the heap and finish regardless. */
	struct job *cancel = NULL;
	xmutex_lock(&s->q_mu);
	size_t kept = 0;
	bool reorder = false;
	for (size_t i = 0; i < s->heap.n; i++) {
		struct jobheap_ent e = s->heap.a[i];
		struct job *j = e.j;
		if (j->mark != s->g.epoch) {
			j->mstate = JOB_CANCELLED;
			j->next = cancel;
			cancel = j;
			s->queued[j->qprio.cls]--;
			reorder = true;
		} else {
			if (!prio_equal(&j->qprio, &j->prio)) {
				s->queued[j->qprio.cls]--;
				s->queued[j->prio.cls]++;
				j->qprio = j->prio;
				e.key = job_prio_key(&j->prio);
				reorder = true;
			}
			s->heap.a[kept++] = e;
		}
	}
	s->heap.n = kept;
	if (reorder) /* else the heap is as it was, in order */
		jobheap_heapify(&s->heap);
	xmutex_unlock(&s->q_mu);

	jobgraph_cancel_unmarked(&s->g, cancel, true);
}

static void submit(struct sched *s)
{
	size_t n = s->g.npush;
	if (n == 0)
		return;
	struct job **push = s->g.push;
	/* In the order they became ready: mostly increasing seq, so each heap push stops at
	 * once. The job lines are read before taking q_mu, not under it. */
	for (size_t i = 0; i < n; i++) {
		if (i + AHEAD < n)
			__builtin_prefetch(push[i + AHEAD], 1);
		push[i]->qprio = push[i]->prio;
	}
	int pushed = (int)n;
	xmutex_lock(&s->q_mu);
	for (size_t i = 0; i < n; i++) {
		struct job *j = push[i];
		jobheap_push(&s->heap, j);
		s->queued[j->qprio.cls]++;
	}
	s->g.npush = 0;
	/* Wake as many idle workers as there are new jobs: a busy worker takes the next job
	 * without waiting, and waking more would only have them contend for q_mu. */
	if (pushed >= s->idle)
		xcond_broadcast(&s->q_cv);
	else
		for (int i = 0; i < pushed; i++)
			xcond_signal(&s->q_cv);
	xmutex_unlock(&s->q_mu);
}

static void deliver(struct sched *s)
{
	for (size_t i = 0; i < s->nbatch; i++) {
		if (i + AHEAD < s->nbatch && s->batch[i + AHEAD].t)
			__builtin_prefetch(s->batch[i + AHEAD].t, 1); /* its count, last written
									 * by a worker */
		struct report *e = &s->batch[i];
		if (!e->r->dead)
			e->r->fn(e->r->ud, e->w, e->t, e->err);
		tile_unref(e->t);
	}
	s->nbatch = 0;
}

/* Frees r (with in_mu held by the manager, or at sched_destroy); r's fin runs first. */
static void free_req(struct sched_req *r)
{
	if (r->fin)
		r->fin(r->ud);
	free(r->pending);
	free(r->pend_m);
	free(r->list);
	free(r->st);
	free(r->first);
	free(r->hash);
	free(r->job);
	free(r);
}

/* Pushes j on the done stack (any thread); wakes the manager when the stack was empty. */
static void post_done(struct sched *s, struct job *j)
{
	struct job *old = atomic_load_explicit(&s->done, memory_order_relaxed);
	do
		j->next_done = old;
	while (!atomic_compare_exchange_weak_explicit(&s->done, &old, j, memory_order_release,
						      memory_order_relaxed));
	if (!old) {
		/* Under in_mu: the manager tests the stack under it before it sleeps. */
		xmutex_lock(&s->in_mu);
		xcond_signal(&s->in_cv);
		xmutex_unlock(&s->in_mu);
	}
}

/* The manager takes every finished job, oldest first. */
static struct job *take_done(struct sched *s)
{
	struct job *j = atomic_exchange_explicit(&s->done, NULL, memory_order_acquire), *fifo = NULL;
	while (j) {
		struct job *next = j->next_done;
		j->next_done = fifo;
		fifo = j;
		j = next;
	}
	return fifo;
}

static void *manager_main(void *arg)
{
	struct sched *s = arg;
	xthread_batch("sched-manager"); /* named for top -H, perf, gdb */
	xmutex_lock(&s->in_mu);
	for (;;) {
		while (!s->in_stop && !s->changes &&
		       !atomic_load_explicit(&s->done, memory_order_relaxed))
			xcond_wait(&s->in_cv, &s->in_mu);
		if (s->in_stop)
			break;
		struct sched_req *ch = s->changes;
		s->changes = NULL;
		for (struct sched_req *r = ch; r; r = r->next_change) {
			r->in_changes = false;
			r->next_change_m = r->next_change;
			free(r->pend_m);
			r->pend_m = r->pending;
			r->npend_m = r->npending;
			r->has_pend_m = r->has_pending;
			r->destroy_m = r->destroy;
			r->ack_m = r->ack;
			r->pending = NULL;
			r->has_pending = false;
		}
		xmutex_unlock(&s->in_mu);
		struct job *done = take_done(s);

		if (apply_changes(s, ch))
			recompute(s);
		while (s->g.fails) {
			struct job *j = s->g.fails;
			s->g.fails = j->next;
			atomic_fetch_add(&s->g.failed, 1);
			jobgraph_complete(&s->g, j);
		}
		while (done) {
			struct job *j = done;
			done = j->next_done;
			if (done) /* its map removal, next */
				jobmap_prefetch(&s->g.map, done->hash);
			bool remote = !j->result &&
				      (j->rstate == JOB_R_WAIT || j->rstate == JOB_R_WOKEN);
			if (remote && j->mark != s->g.epoch) {
				/* Another daemon makes it and nobody here wants it any more. */
				j->mstate = JOB_CANCELLED;
				j->next = NULL;
				jobgraph_cancel_unmarked(&s->g, j, false);
			} else if (remote && j->rstate == JOB_R_WAIT) {
				/* Another daemon generates it: park it until the remote tier
				 * wakes it (no worker and no manager time spent waiting), then
				 * load it. A job found taken over just before its generation
				 * lets its inputs go (all held: it was ready). */
				for (int k = 0; k < j->nin; k++) {
					tile_unref(j->in[k]);
					j->in[k] = NULL;
				}
				j->nin = 0;
				j->from_store = true;
				j->from_disk = false;
				j->rstate = JOB_R_PARKED;
				s->remote->ops->wait(s->remote, &j->key, j);
			} else if (remote) {
				j->from_disk = false; /* woken: ask the remote tier again */
				jobgraph_ready(&s->g, j);
			} else if (j->from_store && !j->result)
				jobgraph_regenerate(&s->g, j); /* not loaded after all: generate */
			else
				jobgraph_complete(&s->g, j);
		}
		submit(s);
		deliver(s);

		xmutex_lock(&s->in_mu);
		bool acked = false;
		for (struct sched_req *r = ch, *next; r; r = next) {
			next = r->next_change_m;
			if (!r->destroy_m)
				continue;
			if (r->ack_m) {
				*r->ack_m = true;
				acked = true;
			}
			free_req(r);
		}
		if (acked)
			xcond_broadcast(&s->ack_cv);
	}
	xmutex_unlock(&s->in_mu);
	return NULL;
}

/* ---- workers ---- */

struct worker_arg {
	struct sched *s;
	int idx;
};

static void lower_priority(struct sched *s)
{
	if (s->nice <= 0)
		return;
	id_t tid = (id_t)syscall(SYS_gettid);
	int err = 0;
	errno = 0;
	int cur = getpriority(PRIO_PROCESS, tid);
	if (cur == -1 && errno != 0)
		err = -errno;
	else if (setpriority(PRIO_PROCESS, tid, cur + s->nice) != 0 && errno != EPERM &&
		 errno != EACCES)
		err = -errno;
	int zero = 0;
	if (err)
		atomic_compare_exchange_strong(&s->nice_err, &zero, err);
}

/* A from_store job: the tile from the store, else the job goes back to the manager with no
 * result to be generated. Bulk work (operator prefetch) finding it there leaves the memory
 * cache alone; every other class, a viewer's look-ahead (SCHED_AHEAD) included, puts it there. */
static void load(struct sched *s, struct tilecodec *tc, struct job *j, enum sched_class cls)
{
	const struct node *n = j->node;
	struct tile *t = NULL;
	int rc = -ENOENT;
	if (j->from_disk)
		rc = store_get(s->store, &j->key, n->out, n->planet->tile_size, tc, &t);
	if (rc == 0) {
		t->layer = true; /* the stores keep layer tiles only (set before it is shared) */
		if (n->summarize)
			tile_summarize(t);
		atomic_fetch_add(&s->loaded, 1);
	} else if (s->remote) {
		/* The fleet's tier: another daemon's tile, or this daemon's turn to make it. */
		bool retry = j->rstate == JOB_R_WOKEN;
		j->rstate = JOB_R_NONE;
		rc = s->remote->ops->get(s->remote, &j->key, n->out, n->planet->tile_size, tc,
					 retry, &t);
		if (rc == 0)
			t->layer = true;
		if (rc == 0 && n->summarize)
			tile_summarize(t); /* before the store's writer sees it */
		if (rc == 0 && s->store)
			store_put(s->store, t, cls == SCHED_BULK ? STORE_KEEP_PREFETCHED
								 : STORE_KEEP_INCIDENTAL);
		else if (rc == -EINPROGRESS)
			j->rstate = JOB_R_WAIT;
		else if (rc == -ENOENT)
			j->leased = true; /* generate it under this daemon's lease */
	}
	if (rc == 0 && cls != SCHED_BULK)
		cache_insert(s->cache, t);
	j->result = t;
	j->err = rc;
}

/* The remote tier's wake (its own thread): the parked job goes back to the manager. */
static void remote_wake(void *ud, void *token)
{
	struct sched *s = ud;
	struct job *j = token;
	j->rstate = JOB_R_WOKEN;
	post_done(s, j);
}

/* A generated tile's cost (tile.h cost_ms): dt ns of its own, plus each input node's cost
 * once (the dearest of that node's input tiles); inputs of the job's own node (its parent,
 * its neighbours) are left out. */
static float chain_cost_ms(const struct job *j, uint64_t dt)
{
	double c = (double)dt * 1e-6;
	for (int i = 0; i < j->nin; i++) {
		const struct tile *a = j->in[i];
		if (!a || a->key.node == j->key.node)
			continue;
		bool seen = false;
		float most = a->cost_ms;
		for (int k = 0; k < j->nin && !seen; k++) {
			const struct tile *b = j->in[k];
			if (!b || b->key.node != a->key.node)
				continue;
			if (k < i)
				seen = true; /* counted with the first of its node */
			else if (b->cost_ms > most)
				most = b->cost_ms;
		}
		if (!seen)
			c += most;
	}
	return (float)fmin(c, 1e6);
}

/* cls: the class the job was queued with; bulk work (operator prefetch) is kept on disk
 * ahead of what viewers happened to ask for, and does not flush the memory cache viewers use:
 * with a store its stored tiles are written through to the store only, the others
 * (intermediate nodes, or a tile the store's full queue dropped) go in at the cache's cold
 * end; without one its layer tiles warm the memory cache as any others. */
static void generate(struct sched *s, struct gen_ctx *g, struct job *j, enum sched_class cls)
{
	const struct node *n = j->node;
	if (j->leased && s->remote && s->remote->ops->confirm(s->remote, &j->key) == -EINPROGRESS) {
		/* The lease expired while the job queued and another daemon took it: wait. */
		j->leased = false;
		j->rstate = JOB_R_WAIT;
		j->result = NULL;
		j->err = 0;
		return;
	}
	struct tile *t = tile_create(&j->key, n->out, n->planet->tile_size);
	uint64_t t0 = clock_now_ns();
	int rc = n->type->generate(n, g, &j->key, j->in, j->nin, t);
	/* A mask that is 0 or 1 over the whole tile (the sea, a land cover absent there) costs
	 * the cache nothing and its consumers can tell. Counted in the tile's time. */
	if (rc == 0)
		tile_share_if_uniform(t);
	uint64_t dt = clock_now_ns() - t0;
	if (rc == 0) {
		if (n->summarize)
			tile_summarize(t); /* no-op when generate() set it */
		t->cost_ms = chain_cost_ms(j, dt);
		t->layer = store_keeps(n); /* one walk of the planet's layers, read below */
		t->lineage = n->type->lineage;
		bool bulk = cls == SCHED_BULK, stored = false;
		if (s->store && t->layer)
			/* Write-behind: never waits; a full queue drops it. */
			stored = store_put(s->store, t,
					   bulk ? STORE_KEEP_PREFETCHED : STORE_KEEP_INCIDENTAL) == 0;
		if (!bulk || (!s->store && t->layer))
			cache_insert(s->cache, t); /* without a disk tier, prefetch warms memory */
		else if (!stored)
			cache_insert_cold(s->cache, t);
		if (s->remote && t->layer)
			s->remote->ops->put(s->remote, t, j->leased); /* write-behind; releases
								       * the lease */
		j->leased = false;
		node_count_generation(j->node, dt);
		atomic_fetch_add(&s->generated, 1);
		j->result = t;
		j->err = 0;
	} else {
		tile_unref(t);
		if (j->leased && s->remote)
			s->remote->ops->release(s->remote, &j->key);
		j->leased = false;
		atomic_fetch_add(&s->g.failed, 1);
		j->result = NULL;
		j->err = rc < 0 ? rc : -EIO;
	}
}

static void *worker_main(void *arg)
{
	struct worker_arg *wa = arg;
	struct sched *s = wa->s;
	struct gen_ctx g = { .worker = wa->idx };
	/* This worker's reads from the store and the remote tier. */
	struct tilecodec *tc = s->store || s->remote ? tilecodec_create() : NULL;
	free(wa);
	xthread_batch("sched-worker");
	lower_priority(s);
	xmutex_lock(&s->q_mu);
	for (;;) {
		while (!s->q_stop && s->heap.n == 0) {
			s->idle++;
			xcond_wait(&s->q_cv, &s->q_mu);
			s->idle--;
		}
		if (s->q_stop)
			break;
		struct job *j = jobheap_pop(&s->heap);
		enum sched_class cls = (enum sched_class)j->qprio.cls;
		s->queued[cls]--;
		atomic_fetch_add_explicit(&s->running, 1, memory_order_relaxed);
		xmutex_unlock(&s->q_mu);

		if (j->from_store)
			load(s, tc, j, cls);
		else
			generate(s, &g, j, cls);

		atomic_fetch_sub_explicit(&s->running, 1, memory_order_relaxed);
		post_done(s, j);
		xmutex_lock(&s->q_mu);
	}
	xmutex_unlock(&s->q_mu);
	gen_ctx_fini(&g);
	tilecodec_destroy(tc);
	return NULL;
}

/* ---- public ---- */

struct sched *sched_create(const struct sched_desc *d)
{
	struct sched *s = xcalloc(1, sizeof *s);
	s->cache = d->cache;
	s->store = d->store;
	s->remote = d->remote;
	if (s->remote) {
		s->remote->wake = remote_wake;
		s->remote->wake_ud = s;
	}
	s->nworkers = d->workers;
	if (s->nworkers <= 0) {
		long n = sysconf(_SC_NPROCESSORS_ONLN);
		s->nworkers = n > 0 ? (int)n : 1;
	}
	s->nice = d->worker_nice == 0 ? 5 : d->worker_nice;
	atomic_init(&s->done, NULL);
	atomic_init(&s->running, 0);
	atomic_init(&s->generated, 0);
	atomic_init(&s->loaded, 0);
	atomic_init(&s->nice_err, 0);
	xmutex_init(&s->in_mu);
	xmutex_init(&s->q_mu);
	xcond_init(&s->in_cv);
	xcond_init(&s->ack_cv);
	xcond_init(&s->q_cv);
	int rc;
	jobgraph_init(&s->g, s->cache, report_entry, s);
	s->g.store = s->store;
	s->g.remote = s->remote;
	if ((rc = xthread_create(&s->manager, manager_main, s)))
		die("pthread_create (manager)", -rc);
	s->workers = xcalloc((size_t)s->nworkers, sizeof *s->workers);
	for (int i = 0; i < s->nworkers; i++) {
		struct worker_arg *wa = xmalloc(sizeof *wa);
		wa->s = s;
		wa->idx = i;
		if ((rc = xthread_create(&s->workers[i], worker_main, wa)))
			die("pthread_create (worker)", -rc);
	}
	return s;
}

void sched_destroy(struct sched *s)
{
	if (!s)
		return;
	xmutex_lock(&s->in_mu);
	s->in_stop = true;
	xcond_broadcast(&s->in_cv);
	xmutex_unlock(&s->in_mu);
	xthread_join(s->manager);
	/* No wait starts now; no wake runs after this (parked jobs are in the graph, freed below). */
	if (s->remote)
		s->remote->ops->cancel_waits(s->remote);
	xmutex_lock(&s->q_mu);
	s->q_stop = true;
	xcond_broadcast(&s->q_cv);
	xmutex_unlock(&s->q_mu);
	for (int i = 0; i < s->nworkers; i++)
		xthread_join(s->workers[i]);
	jobgraph_fini(&s->g); /* every job, finished or not, is still in it */
	/* Requests should be gone already; free what a careless caller left (a request may be
	 * both active and queued as a change). */
	for (struct sched_req *r = s->reqs, *next; r; r = next) {
		next = r->next;
		if (!r->in_changes)
			free_req(r);
	}
	for (struct sched_req *r = s->changes, *next; r; r = next) {
		next = r->next_change;
		free_req(r);
	}
	for (size_t i = 0; i < s->nbatch; i++)
		tile_unref(s->batch[i].t);
	free(s->batch);
	jobheap_fini(&s->heap);
	free(s->workers);
	xmutex_destroy(&s->in_mu);
	xmutex_destroy(&s->q_mu);
	xcond_destroy(&s->in_cv);
	xcond_destroy(&s->ack_cv);
	xcond_destroy(&s->q_cv);
	free(s);
}

struct sched_req *sched_req_create(struct sched *s, sched_ready_fn fn, void *ud)
{
	struct sched_req *r = xcalloc(1, sizeof *r);
	r->s = s;
	r->fn = fn;
	r->ud = ud;
	return r;
}

/* Queues r for the manager's next iteration. Needs s->in_mu. */
static void post_change(struct sched *s, struct sched_req *r)
{
	if (!r->in_changes) {
		r->in_changes = true;
		r->next_change = s->changes;
		s->changes = r;
	}
	xcond_signal(&s->in_cv);
}

int sched_req_want(struct sched_req *r, const struct want *w, size_t n)
{
	for (size_t i = 0; i < n; i++) {
		const struct node *nd = w[i].node;
		if (!nd || !nd->type || !nd->type->generate || !nd->planet ||
		    w[i].key.node != nd->hash || !grid_key_valid(&w[i].key) ||
		    w[i].cls <= SCHED_NONE || w[i].cls >= SCHED_NCLASS)
			return -EINVAL;
	}
	struct want *copy = NULL;
	if (n) {
		copy = xmalloc(n * sizeof *copy);
		memcpy(copy, w, n * sizeof *copy);
	}
	struct sched *s = r->s;
	xmutex_lock(&s->in_mu);
	struct want *old = r->pending;
	r->pending = copy;
	r->npending = n;
	r->has_pending = true;
	post_change(s, r);
	xmutex_unlock(&s->in_mu);
	free(old);
	return 0;
}

void sched_req_destroy(struct sched_req *r)
{
	if (!r)
		return;
	struct sched *s = r->s;
	bool done = false;
	bool on_manager = pthread_equal(pthread_self(), s->manager);
	xmutex_lock(&s->in_mu);
	r->destroy = true;
	r->ack = on_manager ? NULL : &done;
	/* Called from a callback: the manager is this thread, so mark the request dead now
	 * (no further callbacks in this batch) and let the next iteration free it. */
	if (on_manager)
		r->dead = true;
	post_change(s, r);
	while (!on_manager && !done)
		xcond_wait(&s->ack_cv, &s->in_mu);
	xmutex_unlock(&s->in_mu);
}

void sched_req_release(struct sched_req *r, void (*fin)(void *ud))
{
	if (!r)
		return;
	struct sched *s = r->s;
	bool on_manager = pthread_equal(pthread_self(), s->manager);
	xmutex_lock(&s->in_mu);
	r->destroy = true;
	r->ack = NULL;
	r->fin = fin;
	if (on_manager)
		r->dead = true; /* no further callbacks in this iteration's batch */
	post_change(s, r);
	xmutex_unlock(&s->in_mu);
}

static void barrier_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	(void)ud, (void)w, (void)t, (void)err;
}

void sched_barrier(struct sched *s)
{
	/* The manager takes the whole change list at once and frees its destroyed requests at the
	 * end of that iteration: once this request's destroy is acknowledged, every change posted
	 * before it went through the same iteration or an earlier one. */
	sched_req_destroy(sched_req_create(s, barrier_cb, NULL));
}

struct fetch {
	pthread_mutex_t mu;
	pthread_cond_t cv;
	size_t left;
	struct sched_req *r;
	struct tile **out;
	int *err;
};

/* Runs on the manager thread, which owns r->list: w's index is its offset in it. */
static void fetch_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	struct fetch *f = ud;
	size_t i = (size_t)(w - f->r->list);
	f->out[i] = t ? tile_ref(t) : NULL;
	f->err[i] = t ? 0 : (err < 0 ? err : -EIO);
	xmutex_lock(&f->mu);
	if (--f->left == 0)
		xcond_signal(&f->cv);
	xmutex_unlock(&f->mu);
}

int sched_fetch(struct sched *s, const struct want *w, size_t n, struct tile **out)
{
	if (n == 0)
		return 0;
	struct fetch f = { .out = out };
	uint32_t *first = xmalloc(n * sizeof *first);
	f.err = xcalloc(n, sizeof *f.err);
	f.left = dedupe(w, n, first, NULL);
	for (size_t i = 0; i < n; i++)
		out[i] = NULL;
	xmutex_init(&f.mu);
	xcond_init(&f.cv);
	f.r = sched_req_create(s, fetch_ready, &f);
	int rc = sched_req_want(f.r, w, n);
	if (rc == 0) {
		xmutex_lock(&f.mu);
		while (f.left > 0)
			xcond_wait(&f.cv, &f.mu);
		xmutex_unlock(&f.mu);
	}
	sched_req_destroy(f.r);
	if (rc == 0) {
		for (size_t i = 0; i < n; i++) {
			if (first[i] != i) {
				out[i] = out[first[i]] ? tile_ref(out[first[i]]) : NULL;
				f.err[i] = f.err[first[i]];
			}
			if (f.err[i] && rc == 0)
				rc = f.err[i];
		}
	}
	xmutex_destroy(&f.mu);
	xcond_destroy(&f.cv);
	free(first);
	free(f.err);
	return rc;
}

void sched_get_stats(struct sched *s, struct sched_stats *out)
{
	memset(out, 0, sizeof *out);
	xmutex_lock(&s->q_mu);
	for (int c = 0; c < SCHED_NCLASS; c++)
		out->queued[c] = s->queued[c];
	xmutex_unlock(&s->q_mu);
	out->running = atomic_load(&s->running);
	out->waiting = atomic_load(&s->g.waiting);
	out->generated = atomic_load(&s->generated);
	out->loaded = atomic_load(&s->loaded);
	out->merged = atomic_load(&s->g.merged);
	out->skipped = atomic_load(&s->g.skipped);
	out->cancelled = atomic_load(&s->g.cancelled);
	out->failed = atomic_load(&s->g.failed);
	out->workers = s->nworkers;
}

int sched_worker_nice_error(struct sched *s)
{
	return atomic_load(&s->nice_err);
}

struct remote *sched_remote(struct sched *s)
{
	return s->remote;
}

struct store *sched_store(struct sched *s)
{
	return s->store;
}
