/* control — a session's control requests: CACHE_LS (the memory and disk tiers' tiles,
 * filtered by planet, level or distance), CACHE_OP (stat, purge, gc, verify), PREFETCH_DRY,
 * and PREFETCH / PREFETCH_CANCEL with the prefetch jobs they start (prefetch.h enumerates a
 * job's tiles; here they are sized, capped, run, reported and cancelled).
 *
 * Threads: the loop thread; a job's scheduler callback only pushes onto env->ready.
 * Ownership: a control belongs to one session and owns its jobs and the planet-set references
 * keeping their planets alive (kept until control_fini: the scheduler may still hold nodes of
 * a cancelled job). Replies go out through the host's callbacks.
 */
#ifndef CLIPMAP_CONTROL_H
#define CLIPMAP_CONTROL_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"
#include "prefetch.h"
#include "readyq.h"
#include "session.h"

/* The session a control answers for. */
struct control_host {
	struct session *s; /* ready items and the callbacks name it */
	uint64_t id;	   /* for logs */
	void (*send)(struct session *s, const struct proto_msg *m);
	void (*error)(struct session *s, uint16_t code, uint16_t ref_type, uint32_t ref_id,
		      const char *msg);
};

struct control {
	const struct session_env *env; /* borrowed */
	struct control_host host;
	struct prefetch_job **jobs;
	struct planet_set **jobsets; /* jobsets[i]: reference keeping jobs[i]'s planet alive */
	size_t njobs;
	struct planet_set **retired; /* sets of finished jobs, released by control_fini */
	size_t nretired;
	bool authed; /* the client presented the token: [prefetch] max_tiles, else the _local caps */
	struct control_op **ops; /* CACHE_OPs running (cacheop.h) */
	size_t nops;
};

void control_init(struct control *c, const struct session_env *env,
		  const struct control_host *host);
/* Stops every job without a report (the session is closing). */
void control_stop(struct control *c);
/* control_stop, then releases the retired sets. */
void control_fini(struct control *c);
void control_cache_ls(struct control *c, const struct proto_cache_ls *q);
/* CACHE_OP: stat, purge, gc or verify, run off the loop; its replies follow when it is done. */
void control_cache_op(struct control *c, const struct proto_cache_op *q);
void control_prefetch(struct control *c, const struct proto_prefetch *m);
void control_prefetch_cancel(struct control *c, uint32_t id);
/* PREFETCH_DRY: the job's estimate (PREFETCH_ESTIMATE), nothing started. */
void control_prefetch_dry(struct control *c, const struct proto_prefetch *m);
/* Whether HELLO h carries the server's token (constant time in the token's content). */
bool control_token_ok(const struct session_env *env, const struct proto_hello *h);
/* A ready report of one of the jobs (it->job), or of a CACHE_OP done. Returns true when it
 * finished a job or an op (its last reply was sent: flush). */
bool control_job_ready(struct control *c, const struct ready_item *it);
/* Progress reports of every running job. Returns true when one was sent. */
bool control_tick(struct control *c, uint64_t now_ns);
/* Server shutdown: each job reports itself cancelled and is stopped. */
void control_cancel_all(struct control *c);

#endif
