/* prefetch — operator prefetch jobs: a region (bbox, or a corridor of given width along
 * geodesics between points) and a level range, enumerated level by level, coarse first, into
 * tile keys of the layers asked, and fed to the scheduler at SCHED_BULK in windows of
 * PREFETCH_WINDOW keys so memory stays bounded whatever the job's size.
 *
 * Threads: a job is owned and driven by one thread (the server's event loop); its ready
 * callback (given by the owner) runs on the scheduler's manager thread and must only hand
 * the key back to the owner's thread, which calls prefetch_job_ready.
 * Ownership: prefetch_job_create returns an owned job (borrows the planet: the owner keeps it
 * alive); prefetch_job_destroy stops its scheduler request first.
 */
#ifndef CLIPMAP_PREFETCH_H
#define CLIPMAP_PREFETCH_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define PREFETCH_WINDOW 256	     /* wanted keys in flight per job */
#define PREFETCH_MAX_TILES (1u << 26) /* refused above this many tiles per job */

struct prefetch_iter;

/* Checks the request against the planet and counts its tiles (*total, over every layer).
 * Returns an owned iterator, 0, or -EINVAL / -E2BIG with err filled. */
int prefetch_iter_create(const struct planet *p, const struct proto_prefetch *m,
			 struct prefetch_iter **out, uint64_t *total, char err[256]);
/* Up to n more wants (class SCHED_BULK), level by level. Returns how many; 0 when done. */
size_t prefetch_iter_next(struct prefetch_iter *it, struct want *out, size_t n);
void prefetch_iter_destroy(struct prefetch_iter *it);

struct prefetch_job {
	uint32_t id;
	int state; /* enum proto_job_state */
	uint64_t done, failed, total;
	struct prefetch_iter *it;
	struct sched_req *req;
	struct want win[PREFETCH_WINDOW]; /* outstanding keys */
	size_t nwin;
	bool exhausted;
	/* progress reporting */
	uint64_t t0_ns, last_ns, last_done;
	double rate;
	void *owner; /* for the owner's bookkeeping */
};

/* Creates the job (checks and counts its tiles). Returns 0, or -errno with err filled (the
 * iterator's checks). The caller then sets j->req (a scheduler request of its own, whose
 * callback may carry j) and calls prefetch_job_start. */
int prefetch_job_create(const struct planet *p, const struct proto_prefetch *m, uint64_t now_ns,
			struct prefetch_job **out, char err[256]);
/* Feeds the first window to j->req. */
void prefetch_job_start(struct prefetch_job *j);
/* A key of the window was generated (err 0) or failed. Refills the window; returns true once
 * the job has finished (state DONE or FAILED). Unknown keys (reports of keys already
 * accounted for) are ignored. */
bool prefetch_job_ready(struct prefetch_job *j, const struct tile_key *k, int err);
/* Updates j->rate for a progress report at now_ns (tiles per second since the last one). */
void prefetch_job_tick(struct prefetch_job *j, uint64_t now_ns);
void prefetch_job_destroy(struct prefetch_job *j); /* NULL is a no-op */

#endif
