/* control — see control.h. CACHE_LS and CACHE_OP run on a thread of their own (cacheop.h)
 * whose end comes back through the ready queue (err OP_DONE, the op's slot in the job field);
 * their replies are then sent in one go. A job's ready reports come back through the ready
 * queue naming the job; one finished or cancelled since is recognised by its absence from the
 * job list. Jobs are sized (prefetch_estimate) and checked against the [prefetch] caps and
 * the budget of the tier they fill before anything is enumerated.
 */
#include "control.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "cacheop.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/xalloc.h"


static void __attribute__((format(printf, 5, 6)))
errorf(struct control *c, uint16_t code, uint16_t ref_type, uint32_t ref_id, const char *fmt, ...)
{
	char msg[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	c->host.error(c->host.s, code, ref_type, ref_id, msg);
}

void control_init(struct control *c, const struct session_env *env,
		  const struct control_host *host)
{
	*c = (struct control){ .env = env, .host = *host };
}

/* ---- CACHE_OP ----------------------------------------------------------------------------- */

#define CONTROL_MAX_OPS 4 /* CACHE_LS / CACHE_OP running at once per session */
#define OP_DONE 2 /* a ready item's err: its job pointer is a struct control_op whose op is done */

struct control_op {
	struct control *c;
	struct cacheop *op;
};

/* Runs on the op's thread: only tells the loop. The ready item's job field carries the slot
 * (never dereferenced as a job: control_job_ready looks at err first). */
static void op_done_cb(void *ud)
{
	struct control_op *slot = ud;
	const struct control *c = slot->c;
	struct ready_item it = { .s = c->host.s, .job = (struct prefetch_job *)(void *)slot,
				 .err = OP_DONE };
	readyq_push(c->env->ready, &it);
}

static void op_remove(struct control *c, size_t i)
{
	cacheop_destroy(c->ops[i]->op);
	free(c->ops[i]);
	c->ops[i] = c->ops[--c->nops];
}

/* Whether another listing or maintenance op may start (each has a thread): else ERROR busy. */
static bool op_room(struct control *c, uint16_t ref_type, uint32_t req)
{
	if (c->nops < CONTROL_MAX_OPS)
		return true;
	errorf(c, PROTO_E_BUSY, ref_type, req,
	       "%zu cache listings or operations running: this session's limit is %d", c->nops,
	       CONTROL_MAX_OPS);
	return false;
}

void control_cache_op(struct control *c, const struct proto_cache_op *q)
{
	if (!op_room(c, PROTO_CACHE_OP, q->req))
		return;
	struct control_op *slot = xcalloc(1, sizeof *slot);
	slot->c = c;
	char err[256];
	int rc = cacheop_start(q, *c->env->planets, c->env->cache, sched_store(c->env->sched),
			       op_done_cb, slot, &slot->op, err);
	if (rc) {
		free(slot);
		errorf(c, rc == -ENOENT ? PROTO_E_NOT_FOUND : PROTO_E_UNAVAILABLE, PROTO_CACHE_OP,
		       q->req, "%s", err);
		return;
	}
	c->ops = xrealloc(c->ops, (c->nops + 1) * sizeof *c->ops);
	c->ops[c->nops++] = slot;
}

/* The op of slot is done: its replies, then it goes. Returns whether it was still ours. */
static bool op_finished(struct control *c, const struct control_op *slot)
{
	for (size_t i = 0; i < c->nops; i++) {
		if (c->ops[i] != slot)
			continue;
		const struct proto_msg *msgs;
		size_t n = cacheop_replies(slot->op, &msgs);
		for (size_t k = 0; k < n; k++)
			c->host.send(c->host.s, &msgs[k]);
		if (n && msgs[n - 1].type == PROTO_CACHE_DONE && msgs[n - 1].cache_done.removed)
			log_msg(LOG_INFO, "session %llu: cache op %u removed %llu entries",
				(unsigned long long)c->host.id, msgs[n - 1].cache_done.op,
				(unsigned long long)msgs[n - 1].cache_done.removed);
		op_remove(c, i);
		return true;
	}
	return false;
}

void control_cache_ls(struct control *c, const struct proto_cache_ls *q)
{
	if (!op_room(c, PROTO_CACHE_LS, q->req))
		return;
	struct control_op *slot = xcalloc(1, sizeof *slot);
	slot->c = c;
	char err[256];
	int rc = cacheop_start_ls(q, *c->env->planets, c->env->cache, sched_store(c->env->sched),
				  op_done_cb, slot, &slot->op, err);
	if (rc) {
		free(slot);
		errorf(c, rc == -ENOENT ? PROTO_E_NOT_FOUND : PROTO_E_INTERNAL, PROTO_CACHE_LS,
		       q->req, "%s", err);
		return;
	}
	c->ops = xrealloc(c->ops, (c->nops + 1) * sizeof *c->ops);
	c->ops[c->nops++] = slot;
}

/* ---- PREFETCH ---------------------------------------------------------------------------- */

#define JOB_FED 1 /* a ready item's err: the job's builder has keys (not a tile report) */
/* Jobs take no new keys while the disk tier has this many writes queued: bulk work waits for
 * the writer rather than have its writes dropped (viewers' writes keep the rest of the queue). */
#define STORE_QUEUE_HOLD 256

/* Whether the disk tier's writer is behind (jobs pause until the next tick). */
static bool store_behind(const struct control *c)
{
	struct store *st = sched_store(c->env->sched);
	if (!st)
		return false;
	struct store_stats ss;
	store_stat(st, &ss);
	return ss.queued >= STORE_QUEUE_HOLD;
}

bool control_token_ok(const struct session_env *env, const struct proto_hello *h)
{
	if (!env->have_token || h->token_len != env->token_len)
		return false;
	unsigned diff = 0;
	for (size_t i = 0; i < env->token_len; i++)
		diff |= env->token[i] ^ h->token[i];
	return diff == 0;
}

static void send_progress(struct control *c, struct prefetch_job *j)
{
	struct proto_msg m = { .type = PROTO_PREFETCH_PROGRESS,
			       .prefetch_progress = { .id = j->id, .state = (uint8_t)j->state,
						      .done = j->done, .total = j->total,
						      .rate = j->rate } };
	c->host.send(c->host.s, &m);
}

/* Keeps the reference ps (taken) until control_fini: the scheduler may still be generating
 * tiles of nodes the job wanted from it (it has no way to say it is done). */
static void retire(struct control *c, struct planet_set *ps)
{
	for (size_t i = 0; i < c->nretired; i++) {
		if (c->retired[i] == ps) {
			planet_set_unref(ps); /* one reference per set is enough */
			return;
		}
	}
	c->retired = xrealloc(c->retired, (c->nretired + 1) * sizeof *c->retired);
	c->retired[c->nretired++] = ps;
}

static void job_remove(struct control *c, size_t i)
{
	struct prefetch_limits *lim = c->env->prefetch;
	if (lim) {
		lim->jobs--;
		lim->tiles -= c->jobs[i]->charged;
	}
	prefetch_job_destroy(c->jobs[i]); /* stops its scheduler request first */
	retire(c, c->jobsets[i]);
	c->njobs--;
	c->jobs[i] = c->jobs[c->njobs];
	c->jobsets[i] = c->jobsets[c->njobs];
}

/* Runs on the scheduler's manager thread: only hands the report to the loop. */
static void job_ready_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	struct prefetch_job *j = ud;
	const struct control *c = j->owner;
	(void)t;
	struct ready_item it = { .s = c->host.s, .job = j, .key = w->key, .err = err };
	readyq_push(c->env->ready, &it);
}

/* Runs on the job's builder thread: keys are queued; only tells the loop. */
static void job_fed_cb(void *ud)
{
	struct prefetch_job *j = ud;
	const struct control *c = j->owner;
	struct ready_item it = { .s = c->host.s, .job = j, .err = JOB_FED };
	readyq_push(c->env->ready, &it);
}

/* Where a job's tiles go and what they take there: the disk tier when there is one (bytes at
 * rest: the store's mean value size once it holds a few tiles, else the raw size, an upper
 * bound), else the memory cache (raw bytes). */
struct budget {
	uint8_t tier;
	uint64_t budget, used;
	double per_raw; /* bytes held per raw tile byte */
};

static void tier_budget(const struct control *c, struct budget *b)
{
	struct store *st = sched_store(c->env->sched);
	if (st) {
		struct store_stats ss;
		store_stat(st, &ss);
		*b = (struct budget){ .tier = PROTO_TIER_DISK, .budget = ss.budget, .used = ss.bytes,
				      .per_raw = 1.0 };
		return;
	}
	struct cache_stats cs;
	cache_stats(c->env->cache, &cs);
	*b = (struct budget){ .tier = PROTO_TIER_MEMORY, .budget = cs.budget, .used = cs.bytes,
			      .per_raw = 1.0 };
}

/* Bytes for n tiles whose raw size averages raw bytes each. */
static uint64_t est_bytes(const struct control *c, const struct budget *b, uint64_t n,
			  double raw)
{
	double per = raw;
	struct store *st = b->tier == PROTO_TIER_DISK ? sched_store(c->env->sched) : NULL;
	if (st) {
		struct store_stats ss;
		store_stat(st, &ss);
		if (ss.tiles >= 64)
			per = fmin((double)ss.bytes / (double)ss.tiles, raw + 4096.0);
		else
			per = raw + 4096.0; /* uncompressed, a page of header and index */
	}
	double v = per * (double)n;
	return v >= 1.8e19 ? UINT64_MAX : (uint64_t)v;
}

static uint64_t job_limit(const struct control *c)
{
	const struct prefetch_limits *lim = c->env->prefetch;
	if (!lim)
		return PREFETCH_MAX_TILES;
	uint64_t t = c->authed ? lim->max_tiles : lim->max_tiles_local;
	return t < PREFETCH_MAX_TILES ? t : PREFETCH_MAX_TILES;
}

static double mib(uint64_t b) { return (double)b / (1024.0 * 1024.0); }

/* Estimates m; on a failure answers the ERROR (ref_type) and returns false. */
static bool estimate(struct control *c, uint16_t ref_type, const struct proto_prefetch *m,
		     const struct planet **pp, struct prefetch_estimate *e)
{
	const struct planet *p = planet_set_find(*c->env->planets, m->planet);
	if (!p) {
		errorf(c, PROTO_E_NOT_FOUND, ref_type, m->id, "no planet \"%s\"", m->planet);
		return false;
	}
	char err[256];
	if (prefetch_estimate(p, m, e, err)) {
		errorf(c, PROTO_E_INVALID, ref_type, m->id, "%s", err);
		return false;
	}
	*pp = p;
	return true;
}

static unsigned nlayers_of(const struct planet *p, const struct proto_prefetch *m)
{
	unsigned n = 0;
	for (size_t i = 0; i < p->nlayers && i < 64; i++)
		n += m->layers == 0 || (m->layers >> i) & 1;
	return n ? n : 1;
}

void control_prefetch_dry(struct control *c, const struct proto_prefetch *m)
{
	const struct planet *p;
	struct prefetch_estimate e;
	if (!estimate(c, PROTO_PREFETCH_DRY, m, &p, &e))
		return;
	struct budget b;
	tier_budget(c, &b);
	double raw = (double)e.tile_bytes / nlayers_of(p, m);
	struct proto_estimate_level lv[GRID_MAX_LEVEL + 1];
	uint8_t n = 0;
	uint64_t bytes = 0;
	for (int ly = e.lmin; ly <= e.lmax; ly++) {
		lv[n] = (struct proto_estimate_level){ .ly = (uint8_t)ly,
						       .tiles = e.level_tiles[ly],
						       .bytes = est_bytes(c, &b, e.level_tiles[ly], raw) };
		bytes = bytes + lv[n].bytes < bytes ? UINT64_MAX : bytes + lv[n].bytes;
		n++;
	}
	struct proto_msg r = { .type = PROTO_PREFETCH_ESTIMATE,
			       .prefetch_estimate = { .id = m->id, .tier = b.tier, .tiles = e.tiles,
						      .bytes = bytes, .budget = b.budget,
						      .used = b.used, .max_tiles = job_limit(c),
						      .nlevels = n, .levels = lv } };
	c->host.send(c->host.s, &r);
}

void control_prefetch(struct control *c, const struct proto_prefetch *m)
{
	const struct session_env *env = c->env;
	struct prefetch_limits *lim = env->prefetch;
	for (size_t i = 0; i < c->njobs; i++) {
		if (c->jobs[i]->id == m->id) {
			errorf(c, PROTO_E_INVALID, PROTO_PREFETCH, m->id, "job %u is already running",
			       m->id);
			return;
		}
	}
	uint32_t max_jobs = env->max_jobs;
	if (lim && !c->authed && lim->max_jobs_local < max_jobs)
		max_jobs = lim->max_jobs_local;
	if (c->njobs >= max_jobs) {
		errorf(c, PROTO_E_LIMIT, PROTO_PREFETCH, m->id,
		       "%zu prefetch jobs running: this session's limit is %u%s", c->njobs, max_jobs,
		       !c->authed && lim && max_jobs == lim->max_jobs_local
			       ? " ([prefetch] max_jobs_local: no token presented)"
			       : "");
		return;
	}
	if (lim && lim->jobs >= lim->max_jobs_total) {
		errorf(c, PROTO_E_BUSY, PROTO_PREFETCH, m->id,
		       "%u prefetch jobs running on this server: its limit is %u", lim->jobs,
		       lim->max_jobs_total);
		return;
	}
	/* Sized before anything is enumerated. */
	const struct planet *p;
	struct prefetch_estimate e;
	if (!estimate(c, PROTO_PREFETCH, m, &p, &e))
		return;
	uint64_t limit = job_limit(c);
	if (e.tiles > limit) {
		errorf(c, PROTO_E_LIMIT, PROTO_PREFETCH, m->id,
		       "prefetch job %u: about %llu tiles (levels %u-%u) exceeds this session's "
		       "limit of %llu tiles per job%s",
		       m->id, (unsigned long long)e.tiles, m->lmin, m->lmax,
		       (unsigned long long)limit,
		       c->authed ? " ([prefetch] max_tiles)"
				 : " ([prefetch] max_tiles_local: no token presented)");
		return;
	}
	if (lim && lim->tiles + e.tiles > lim->max_tiles_total) {
		errorf(c, PROTO_E_BUSY, PROTO_PREFETCH, m->id,
		       "prefetch job %u: about %llu tiles; running jobs hold %llu of this server's "
		       "%llu ([prefetch] max_tiles_total)",
		       m->id, (unsigned long long)e.tiles, (unsigned long long)lim->tiles,
		       (unsigned long long)lim->max_tiles_total);
		return;
	}
	struct budget b;
	tier_budget(c, &b);
	uint64_t bytes = est_bytes(c, &b, e.tiles, (double)e.tile_bytes / nlayers_of(p, m));
	if (b.budget && bytes > b.budget) {
		errorf(c, PROTO_E_LIMIT, PROTO_PREFETCH, m->id,
		       "prefetch job %u: about %llu tiles, %.1f MiB in the %s tier (levels %u-%u), "
		       "exceeds its budget of %.1f MiB (%s): it would evict itself",
		       m->id, (unsigned long long)e.tiles, mib(bytes),
		       b.tier == PROTO_TIER_DISK ? "disk" : "memory", m->lmin, m->lmax,
		       mib(b.budget),
		       b.tier == PROTO_TIER_DISK ? "[store] disk_mb" : "[engine] cache_mb");
		return;
	}
	struct prefetch_job *j;
	char err[256];
	int rc = prefetch_job_create(p, m, limit, e.tiles, clock_now_ns(), &j, err);
	if (rc) {
		errorf(c, rc == -E2BIG ? PROTO_E_LIMIT : PROTO_E_INVALID, PROTO_PREFETCH, m->id, "%s",
		       err);
		return;
	}
	j->owner = c;
	j->req = sched_req_create(env->sched, job_ready_cb, j);
	c->jobs = xrealloc(c->jobs, (c->njobs + 1) * sizeof *c->jobs);
	c->jobsets = xrealloc(c->jobsets, (c->njobs + 1) * sizeof *c->jobsets);
	/* The job borrows p: it keeps the set holding it (a reload does not move jobs). */
	c->jobsets[c->njobs] = planet_set_ref(*env->planets);
	c->jobs[c->njobs++] = j;
	if (lim) {
		lim->jobs++;
		lim->tiles += e.tiles;
		j->charged = e.tiles;
	}
	if ((rc = prefetch_job_start(j, job_fed_cb, j))) {
		errorf(c, PROTO_E_INTERNAL, PROTO_PREFETCH, m->id, "prefetch job %u: no thread: %s",
		       m->id, strerror(-rc));
		job_remove(c, c->njobs - 1);
		return;
	}
	log_msg(LOG_INFO, "session %llu: prefetch job %u on %s: about %llu tiles, levels %u-%u",
		(unsigned long long)c->host.id, j->id, p->name, (unsigned long long)j->total,
		m->lmin, m->lmax);
	send_progress(c, j);
}

/* Job i has finished: its last report, then it goes. */
static void job_finished(struct control *c, size_t i)
{
	struct prefetch_job *j = c->jobs[i];
	prefetch_job_tick(j, clock_now_ns());
	send_progress(c, j);
	if (j->state == PROTO_JOB_FAILED && j->err[0])
		errorf(c, PROTO_E_LIMIT, PROTO_PREFETCH, j->id, "prefetch job %u stopped: %s", j->id,
		       j->err);
	else if (j->state == PROTO_JOB_FAILED)
		errorf(c, PROTO_E_UNAVAILABLE, PROTO_PREFETCH, j->id,
		       "prefetch job %u: %llu of %llu tiles failed", j->id,
		       (unsigned long long)j->failed, (unsigned long long)j->total);
	log_msg(LOG_INFO, "session %llu: prefetch job %u finished: %llu tiles, %llu failed",
		(unsigned long long)c->host.id, j->id, (unsigned long long)j->done,
		(unsigned long long)j->failed);
	job_remove(c, i);
}

bool control_job_ready(struct control *c, const struct ready_item *it)
{
	if (it->err == OP_DONE)
		return op_finished(c, (const struct control_op *)(const void *)it->job);
	size_t i = 0;
	while (i < c->njobs && c->jobs[i] != it->job)
		i++;
	if (i == c->njobs)
		return false; /* cancelled since */
	struct prefetch_job *j = it->job;
	j->paused = store_behind(c);
	if (!(it->err == JOB_FED ? prefetch_job_fed(j) : prefetch_job_ready(j, &it->key, it->err)))
		return false;
	job_finished(c, i);
	return true;
}

void control_prefetch_cancel(struct control *c, uint32_t id)
{
	for (size_t i = 0; i < c->njobs; i++) {
		if (c->jobs[i]->id == id) {
			struct prefetch_job *j = c->jobs[i];
			j->state = PROTO_JOB_CANCELLED;
			prefetch_job_tick(j, clock_now_ns());
			send_progress(c, j);
			job_remove(c, i);
			return;
		}
	}
	errorf(c, PROTO_E_NOT_FOUND, PROTO_PREFETCH_CANCEL, id, "no prefetch job %u", id);
}

bool control_tick(struct control *c, uint64_t now_ns)
{
	bool sent = c->njobs > 0;
	bool behind = c->njobs && store_behind(c);
	for (size_t i = 0; i < c->njobs;) {
		struct prefetch_job *j = c->jobs[i];
		if (j->paused && !behind) { /* resume a job the writer held */
			j->paused = false;
			if (prefetch_job_fed(j)) {
				prefetch_job_tick(j, now_ns);
				job_finished(c, i); /* removes it: i now names the next */
				continue;
			}
		}
		prefetch_job_tick(j, now_ns);
		send_progress(c, j);
		i++;
	}
	return sent;
}

void control_cancel_all(struct control *c)
{
	while (c->njobs) {
		struct prefetch_job *j = c->jobs[c->njobs - 1];
		j->state = PROTO_JOB_CANCELLED;
		send_progress(c, j);
		job_remove(c, c->njobs - 1);
	}
}

void control_stop(struct control *c)
{
	while (c->njobs)
		job_remove(c, c->njobs - 1);
	while (c->nops)
		op_remove(c, c->nops - 1);
}

void control_fini(struct control *c)
{
	control_stop(c);
	free(c->jobs);
	free(c->jobsets);
	free(c->ops);
	for (size_t i = 0; i < c->nretired; i++)
		planet_set_unref(c->retired[i]);
	free(c->retired);
	*c = (struct control){ 0 };
}
