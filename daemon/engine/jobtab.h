/* jobtab — the scheduler's jobs: the job record, the key → job hash map, the job graph
 * (dependency links, depth-first creation, priority marking, completion, failure and
 * cancellation) and the ready queue (a binary heap ordered by priority). Internal to sched.c.
 *
 * Threads: none of this locks. The graph, the map and the manager-only fields of a job belong
 * to the manager thread; the heap and the fields marked "queue" are protected by the
 * scheduler's queue mutex; a job's node, key, inputs and result move between threads only
 * through that mutex or the manager's inbox mutex (see sched.c).
 * Ownership: the graph allocates and frees jobs; the map and heap only point at them.
 */
#ifndef CLIPMAP_JOBTAB_H
#define CLIPMAP_JOBTAB_H
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "cache.h"
#include "node.h"
#include "remote.h"
#include "store.h"
#include "tile.h"

struct sched_req;
struct jobblock;

/* Smaller is more urgent: class, then level (ly, then lx; coarse first), then want order. */
struct job_prio {
	uint8_t cls, ly, lx;
	uint32_t order;
};

/* One entry of a want list that waits for a job: request and index in its list. */
struct job_wanter {
	struct sched_req *r;
	uint32_t idx;
};

/* A from_store job and the remote tier's lease (remote.h). */
enum job_rstate {
	JOB_R_NONE = 0,
	JOB_R_WAIT,   /* the worker found another daemon's lease: park it (remote wait) */
	JOB_R_PARKED, /* waiting in the remote tier for its wake */
	JOB_R_WOKEN,  /* woken: ask the remote tier again (a lease taken now is a takeover) */
};

enum job_mstate {
	JOB_WAITING = 1, /* some inputs still missing */
	JOB_SUBMITTED,	 /* handed to the ready queue (queued, running or done, not yet seen) */
	JOB_CANCELLED,
};

/* Inputs a job holds in itself; a node with more gets both arrays allocated (most nodes have
 * one to four: keeping NODE_MAX_DEPS in every job made it twice as large). */
#define JOB_INLINE_DEPS 4

struct job {
	struct tile_key key;
	struct node *node; /* borrowed */
	uint64_t seq;	   /* creation order: the last tie-break */
	uint64_t hash;
	struct job *hnext; /* map chain */
	bool from_store;   /* set by the manager before queueing: load from the tiers below
			    * memory (disk store, then remote), no inputs */
	bool from_disk;	   /* with from_store: the disk store holds it */
	uint8_t rstate;	   /* enum job_rstate: the remote tier's wait (worker ↔ manager) */
	bool leased;	   /* this daemon may hold the remote tier's lease on key: released
			    * when the job is dropped without its tile written (remote.h) */

	/* Manager only. */
	enum job_mstate mstate;
	uint64_t mark; /* epoch of the last marking pass that reached it */
	struct job_prio prio;
	int nin, missing;
	uint32_t lazy;	   /* deps not made yet, until the others are held (node_type.lazy) */
	struct tile **in;  /* held inputs (owned references): nin slots, in_s or allocated */
	struct job **dep;  /* pending input jobs (NULL once held): nin slots, dep_s or allocated */
	struct tile *in_s[JOB_INLINE_DEPS];
	struct job *dep_s[JOB_INLINE_DEPS];
	struct job **dependents;	 /* jobs with this one in their dep[] */
	size_t ndependents, capdependents;
	struct job_wanter wanter0;  /* want entries waiting for it, valid for wanters_epoch: */
	struct job_wanter *wanters; /* the first, then the others (wanters[i - 1]) */
	size_t nwanters, capwanters;
	uint64_t wanters_epoch;
	struct job *next; /* manager's scratch lists; a free job's block list */
	struct jobblock *block; /* the block it lives in */
	struct job *wprev, *wnext; /* the graph's list of JOB_WAITING jobs */

	/* Queue (under the queue mutex). */
	struct job_prio qprio; /* the priority it was queued with (its heap entry holds a copy) */

	/* Worker → manager, published through the inbox mutex. */
	struct tile *result; /* owned reference, NULL on error */
	int err;
	struct job *next_done;
};

bool job_prio_less(const struct job_prio *a, const struct job_prio *b);

struct jobmap {
	struct job **b;
	size_t nb, n;
};

void jobmap_init(struct jobmap *m);
void jobmap_fini(struct jobmap *m); /* frees the table, not the jobs */
struct job *jobmap_find(const struct jobmap *m, const struct tile_key *k);
/* Adds j (j->key set, not present yet); sets j->hash. */
void jobmap_insert(struct jobmap *m, struct job *j);
/* Asks the CPU to fetch the bucket of hash h (grid_key_hash) ahead of a find or remove. */
static inline void jobmap_prefetch(const struct jobmap *m, uint64_t h)
{
	__builtin_prefetch(&m->b[h & (m->nb - 1)]);
}
/* jobmap_find with the key's grid_key_hash already computed. */
struct job *jobmap_find_hashed(const struct jobmap *m, const struct tile_key *k, uint64_t h);
void jobmap_remove(struct jobmap *m, struct job *j);
/* Every job into a new array (owned by the caller); *n = how many. */
struct job **jobmap_list(const struct jobmap *m, size_t *n);

/* The manager's job graph. Every live job is in the map until it completes, fails or is
 * cancelled. */
struct jobgraph {
	struct jobmap map;
	struct cache *cache; /* borrowed: dependency lookups */
	struct store *store; /* borrowed, optional: tried before generating (store.h) */
	struct remote *remote; /* borrowed, optional: tried after the store (remote.h) */
	uint64_t epoch;	     /* of the current marking pass */
	uint64_t marked_waiting; /* jobs this epoch's pass marked while they were waiting */
	uint64_t seq;
	struct job **push; /* jobs that became ready, in that order, for the caller to queue */
	size_t npush, cappush;
	struct job *fails; /* jobs whose deps() failed, linked by next, for jobgraph_complete */
	struct job *waiting_list; /* every JOB_WAITING job (wprev/wnext): what cancellation walks */
	/* Jobs come from blocks of JOB_BLOCK (one allocation for many: a long want list creates
	 * its jobs at a few hundred ns each otherwise); a freed job goes back to its block, kept
	 * for reuse with its lists' buffers, and a block all free is released once more than
	 * SPARE_MAX jobs are free. */
	struct jobblock *partial; /* blocks with a free job (link BL_PARTIAL) */
	struct jobblock *blocks;  /* every block (link BL_ALL) */
	size_t nspare;		  /* free jobs in all blocks */
	/* Tells one waiting want entry about its job: t an owned reference the hook keeps or
	 * unrefs, NULL with err < 0 on failure. */
	void (*report)(void *ud, const struct job_wanter *w, struct tile *t, int err);
	void *ud;
	atomic_uint_fast64_t merged, waiting, cancelled, failed;
	atomic_uint_fast64_t skipped; /* lazy dependencies found not needed (node_type.lazy) */
	/* Keys whose lazy inputs were found not needed lately (skipped, or made and found so by
	 * generate: tile.lazy_unneeded): a
	 * job defers its lazy inputs only when its parent key's were not needed. Two generations
	 * of up to JOBGRAPH_SKIPMEM / 2 keys each (open addressing, JOBGRAPH_SKIPMEM slots); when
	 * the newer fills, the older is dropped. Allocated on first use. */
	struct skipset {
		struct tile_key *k;
		uint64_t *h; /* 0: an empty slot */
		size_t n;
	} skip[2];
};

#define JOBGRAPH_SKIPMEM (1u << 15)

void jobgraph_init(struct jobgraph *g, struct cache *c,
		   void (*report)(void *ud, const struct job_wanter *w, struct tile *t, int err),
		   void *ud);
/* Appends j to g->push (its mstate set by the caller). */
void jobgraph_ready(struct jobgraph *g, struct job *j);
/* Frees every job still in the graph (threads stopped). */
void jobgraph_fini(struct jobgraph *g);
/* A new job for (node, key), its missing dependencies created depth-first (cached ones are
 * held as tile references). Ready jobs go on g->push, failed ones on g->fails. A key the store
 * holds, or any layer tile when there is a remote tier, becomes a from_store job with no
 * inputs, ready at once. */
struct job *jobgraph_create(struct jobgraph *g, struct node *node, const struct tile_key *key);
/* A from_store job whose load failed (absent after all, or corrupt): resolves its inputs as
 * for a new job so that it is generated, marking new dependencies with j's priority. */
void jobgraph_regenerate(struct jobgraph *g, struct job *j);
/* Marks j and its pending dependencies for this epoch with priority p, keeping the best. */
void jobgraph_visit(struct jobgraph *g, struct job *j, const struct job_prio *p);
/* Records that want entry (r, idx) waits for j (valid for this epoch). */
void jobgraph_add_wanter(struct jobgraph *g, struct job *j, struct sched_req *r, size_t idx);
/* j finished with j->result (owned) or j->err: reports to its wanters, hands the tile to its
 * dependents (those now ready go on g->push) or fails them, and frees j. */
void jobgraph_complete(struct jobgraph *g, struct job *j);
/* Starts a marking pass: a new epoch. */
void jobgraph_new_epoch(struct jobgraph *g);
/* Cancels and frees `cancel` (jobs taken out of the heap, linked by next, mstate
 * JOB_CANCELLED) and every waiting job this epoch's pass did not mark. after_pass: called
 * right after the pass (no job has left the waiting state since it began), so that when
 * the pass marked as many waiting jobs as there are, the waiting list is not walked. */
void jobgraph_cancel_unmarked(struct jobgraph *g, struct job *cancel, bool after_pass);

/* A heap entry carries its ordering key, so that sifting reads no job (each one a cache miss,
 * under the queue mutex, when the heap is large): the job's qprio packed so that it compares
 * as one integer (job_prio_key), then its seq. */
struct jobheap_ent {
	uint64_t key;
	uint64_t seq;
	struct job *j;
};

/* p as an integer that orders as job_prio_less: class, ly, lx, then order. */
static inline uint64_t job_prio_key(const struct job_prio *p)
{
	return (uint64_t)p->cls << 48 | (uint64_t)p->ly << 40 | (uint64_t)p->lx << 32 | p->order;
}

struct jobheap {
	struct jobheap_ent *a;
	size_t n, cap;
};

void jobheap_fini(struct jobheap *h);
void jobheap_push(struct jobheap *h, struct job *j); /* orders by j->qprio, then j->seq */
struct job *jobheap_pop(struct jobheap *h);	     /* NULL when empty */
/* Restores heap order after entries' prio changed or entries were replaced in place. */
void jobheap_heapify(struct jobheap *h);

#endif
