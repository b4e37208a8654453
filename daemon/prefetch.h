/* prefetch — operator prefetch jobs: a region (bbox, or a corridor of given width along
 * geodesics between points) and a level range, enumerated level by level, coarse first, into
 * tile keys of the layers asked, and fed to the scheduler at SCHED_BULK in windows of
 * PREFETCH_WINDOW keys so memory stays bounded whatever the job's size.
 *
 * A job's size is first estimated analytically (prefetch_estimate: no tile is enumerated), so
 * a request too large is refused before anything is materialised. A job's levels are then
 * enumerated on a builder thread of the job's own, never on the owner's thread, into a
 * bounded queue the owner takes keys from.
 *
 * Threads: a job is owned and driven by one thread (the server's event loop); its ready
 * callback (given by the owner) runs on the scheduler's manager thread and must only hand
 * the key back to the owner's thread, which calls prefetch_job_ready. The builder's wake
 * callback (prefetch_job_start) runs on the builder thread, likewise only to hand a wake-up
 * to the owner's thread, which then calls prefetch_job_fed.
 * Ownership: prefetch_job_create returns an owned job (it and its builder take references on
 * the planet); prefetch_job_destroy stops its scheduler request first and never waits for the
 * builder (which finishes on its own and frees what it holds).
 */
#ifndef CLIPMAP_PREFETCH_H
#define CLIPMAP_PREFETCH_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define PREFETCH_WINDOW 256	      /* wanted keys in flight per job */
#define PREFETCH_MAX_TILES (1u << 26) /* the ceiling of every per-job limit */

/* A job's size before it runs: tiles (over every layer) and bytes per level. */
struct prefetch_estimate {
	uint8_t lmin, lmax;
	uint64_t tiles;				  /* over every level and layer */
	uint64_t level_tiles[GRID_MAX_LEVEL + 1]; /* per ly, every layer */
	uint64_t tile_bytes;			  /* raw bytes of one tile of each layer, summed */
};

/* Checks the request against the planet (levels, shape, layers). Returns 0 or -EINVAL with
 * err filled. */
int prefetch_check(const struct planet *p, const struct proto_prefetch *m, char err[256]);
/* Checks (prefetch_check) and estimates the job's tiles without enumerating any: bounded work
 * (at most a few thousand steps per level and path point). The estimate is within a small
 * factor of the count (tests/unit/test_prefetch.c bounds it), and saturates far above
 * PREFETCH_MAX_TILES rather than overflowing. */
int prefetch_estimate(const struct planet *p, const struct proto_prefetch *m,
		      struct prefetch_estimate *e, char err[256]);

/* The server's caps on prefetch jobs ([prefetch] in clipmapd.conf) and what running jobs
 * hold against them. Loop thread only. */
struct prefetch_limits {
	uint64_t max_tiles;	  /* per job, a session that presented the token */
	uint64_t max_tiles_local; /* per job, a session that did not */
	uint32_t max_jobs_local;  /* jobs at once, a session that did not */
	uint32_t max_jobs_total;  /* jobs at once, every session */
	uint64_t max_tiles_total; /* estimated tiles of the running jobs, every session */
	uint32_t jobs;		  /* running now */
	uint64_t tiles;		  /* their estimated tiles */
};

struct prefetch_iter;

/* Checks the request and returns an owned iterator (nothing enumerated yet), 0, or -EINVAL
 * with err filled. A level of more than max_tiles tiles (every layer) stops the iteration
 * with -E2BIG (prefetch_iter_error). */
int prefetch_iter_create(const struct planet *p, const struct proto_prefetch *m,
			 uint64_t max_tiles, struct prefetch_iter **out, char err[256]);
/* Up to n more wants (class SCHED_BULK), level by level (building each level when it is
 * reached). Returns how many; 0 when done or stopped by an error. */
size_t prefetch_iter_next(struct prefetch_iter *it, struct want *out, size_t n);
/* 0, or the error that stopped the iteration (-E2BIG) with err filled. */
int prefetch_iter_error(const struct prefetch_iter *it, char err[256]);
/* The job's tiles (every layer): exact for the levels built so far, estimated for the rest;
 * exact once the iteration is done. */
uint64_t prefetch_iter_total(const struct prefetch_iter *it);
void prefetch_iter_destroy(struct prefetch_iter *it);

struct prefetch_feed; /* the queue between a job and its builder thread */

struct prefetch_job {
	uint32_t id;
	int state; /* enum proto_job_state */
	uint64_t done, failed, total;
	struct prefetch_feed *feed;
	struct sched_req *req;
	struct want win[PREFETCH_WINDOW]; /* outstanding keys */
	size_t nwin;
	bool exhausted;
	bool paused; /* set by the owner: take no new keys (the window drains) */
	char err[256]; /* why the builder stopped the job (state FAILED), else "" */
	uint64_t charged; /* tiles counted against the server's caps (the owner's) */
	/* progress reporting */
	uint64_t t0_ns, last_ns, last_done;
	double rate;
	void *owner; /* for the owner's bookkeeping */
};

/* Creates the job: checks the request and creates its iterator (max_tiles per level, see
 * prefetch_iter_create); total starts as est_total. Returns 0, or -errno with err filled. The
 * caller then sets j->req (a scheduler request of its own, whose callback may carry j) and
 * calls prefetch_job_start. */
int prefetch_job_create(const struct planet *p, const struct proto_prefetch *m,
			uint64_t max_tiles, uint64_t est_total, uint64_t now_ns,
			struct prefetch_job **out, char err[256]);
/* Starts the builder thread. wake(ud) is called on the builder thread (never after
 * prefetch_job_destroy has begun) when keys or the end arrive after the owner found the queue
 * empty: the owner then calls prefetch_job_fed on its thread. Returns 0 or -errno (no thread:
 * the job is left unstarted, destroy it). */
int prefetch_job_start(struct prefetch_job *j, void (*wake)(void *ud), void *ud);
/* Keys arrived (after a wake): refills the window. Returns true once the job has finished
 * (state DONE or FAILED). */
bool prefetch_job_fed(struct prefetch_job *j);
/* A key of the window was generated (err 0) or failed. Refills the window; returns true once
 * the job has finished (state DONE or FAILED). Unknown keys (reports of keys already
 * accounted for) are ignored. */
bool prefetch_job_ready(struct prefetch_job *j, const struct tile_key *k, int err);
/* Updates j->rate for a progress report at now_ns (tiles per second since the last one). */
void prefetch_job_tick(struct prefetch_job *j, uint64_t now_ns);
void prefetch_job_destroy(struct prefetch_job *j); /* NULL is a no-op */

#endif
