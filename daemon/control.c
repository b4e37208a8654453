/* control — see control.h. CACHE_LS walks the cache under its lock (cache_foreach), so the
 * filter is cheap and the entries are copied out before any reply is encoded. A job's ready
 * reports come back through the ready queue naming the job; one finished or cancelled since
 * is recognised by its absence from the job list.
 */
#include "control.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "common/clock.h"
#include "common/log.h"
#include "common/xalloc.h"

#define CACHE_LS_DEFAULT 10000u
#define CACHE_LS_MAX (1u << 20)

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

/* ---- CACHE_LS --------------------------------------------------------------------------- */

struct lsctx {
	const struct proto_cache_ls *q;
	const uint64_t *nodes;
	size_t nnodes;
	struct proto_cache_entry *out;
	size_t n, limit;
	uint64_t total;
	uint64_t now_ns; /* cache_now_ns() when the listing started */
};

/* Great-circle distance (metres, mean Earth-like radius r) from (lon, lat) to the nearest
 * point of the tile's rectangle: a spherical approximation, good enough for a listing filter
 * and cheap enough to run under the cache lock. */
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

static int ls_fn(void *ud, const struct tile *t, uint64_t used_ns)
{
	struct lsctx *c = ud;
	const struct proto_cache_ls *q = c->q;
	if (q->filter & PROTO_CLS_PLANET) {
		bool found = false;
		for (size_t i = 0; i < c->nnodes && !found; i++)
			found = c->nodes[i] == t->key.node;
		if (!found)
			return 0;
	}
	if ((q->filter & PROTO_CLS_LEVEL) &&
	    ((q->lx != PROTO_ANY_LX && t->key.lx != q->lx) || t->key.ly != q->ly))
		return 0;
	if (q->filter & PROTO_CLS_NEAR) {
		struct geo_rect rc;
		grid_tile_rect(&t->key, &rc);
		if (rect_distance(&rc, q->lon, q->lat, 6371008.8) > q->radius_m)
			return 0;
	}
	c->total++;
	uint64_t age = c->now_ns > used_ns ? (c->now_ns - used_ns) / 1000000000ull : 0;
	if (c->n < c->limit)
		c->out[c->n++] = (struct proto_cache_entry){ .key = t->key, .format = (uint8_t)t->type,
							    .tier = PROTO_TIER_MEMORY,
							    .bytes = (uint32_t)t->nbytes,
							    .age_s = age > UINT32_MAX ? UINT32_MAX
										      : (uint32_t)age };
	return 0;
}

void control_cache_ls(struct control *ctl, const struct proto_cache_ls *q)
{
	struct lsctx c = { .q = q };
	uint64_t *nodes = NULL;
	if (q->filter & PROTO_CLS_PLANET) {
		const struct planet *p = planet_set_find(*ctl->env->planets, q->planet);
		if (!p) {
			errorf(ctl, PROTO_E_NOT_FOUND, PROTO_CACHE_LS, q->req, "no planet \"%s\"",
			       q->planet);
			return;
		}
		nodes = xmalloc((p->nnodes + 1) * sizeof *nodes);
		for (size_t i = 0; i < p->nnodes; i++)
			nodes[i] = p->nodes[i]->hash;
		c.nodes = nodes;
		c.nnodes = p->nnodes;
	}
	c.limit = q->limit ? q->limit : CACHE_LS_DEFAULT;
	if (c.limit > CACHE_LS_MAX)
		c.limit = CACHE_LS_MAX;
	struct cache_stats cs;
	cache_stats(ctl->env->cache, &cs);
	size_t cap = cs.tiles + 64 < c.limit ? cs.tiles + 64 : c.limit;
	c.out = xmalloc((cap ? cap : 1) * sizeof *c.out);
	c.limit = cap;
	c.now_ns = cache_now_ns();
	cache_foreach(ctl->env->cache, ls_fn, &c);
	size_t off = 0;
	do {
		size_t k = c.n - off > PROTO_MAX_CACHE_ENTRIES ? PROTO_MAX_CACHE_ENTRIES : c.n - off;
		struct proto_msg m = { .type = PROTO_CACHE_ENTRIES,
				       .cache_entries = { .req = q->req, .more = off + k < c.n,
							  .total = c.total, .count = (uint32_t)k,
							  .entries = c.out + off } };
		ctl->host.send(ctl->host.s, &m);
		off += k;
	} while (off < c.n);
	free(c.out);
	free(nodes);
}

/* ---- PREFETCH --------------------------------------------------------------------------- */

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

void control_prefetch(struct control *c, const struct proto_prefetch *m)
{
	const struct session_env *env = c->env;
	const struct planet *p = planet_set_find(*env->planets, m->planet);
	if (!p) {
		errorf(c, PROTO_E_NOT_FOUND, PROTO_PREFETCH, m->id, "no planet \"%s\"", m->planet);
		return;
	}
	for (size_t i = 0; i < c->njobs; i++) {
		if (c->jobs[i]->id == m->id) {
			errorf(c, PROTO_E_INVALID, PROTO_PREFETCH, m->id, "job %u is already running",
			       m->id);
			return;
		}
	}
	if (c->njobs >= env->max_jobs) {
		errorf(c, PROTO_E_LIMIT, PROTO_PREFETCH, m->id,
		       "%zu prefetch jobs running: this session's limit is %u", c->njobs,
		       env->max_jobs);
		return;
	}
	struct prefetch_job *j;
	char err[256];
	int rc = prefetch_job_create(p, m, clock_now_ns(), &j, err);
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
	log_msg(LOG_INFO, "session %llu: prefetch job %u on %s: %llu tiles, levels %u-%u",
		(unsigned long long)c->host.id, j->id, p->name, (unsigned long long)j->total,
		m->lmin, m->lmax);
	send_progress(c, j);
	prefetch_job_start(j);
	if (j->state != PROTO_JOB_RUNNING) { /* nothing to do */
		send_progress(c, j);
		job_remove(c, c->njobs - 1);
	}
}

bool control_job_ready(struct control *c, const struct ready_item *it)
{
	size_t i = 0;
	while (i < c->njobs && c->jobs[i] != it->job)
		i++;
	if (i == c->njobs)
		return false; /* cancelled since */
	struct prefetch_job *j = it->job;
	if (!prefetch_job_ready(j, &it->key, it->err))
		return false;
	prefetch_job_tick(j, clock_now_ns());
	send_progress(c, j);
	if (j->state == PROTO_JOB_FAILED)
		errorf(c, PROTO_E_UNAVAILABLE, PROTO_PREFETCH, j->id,
		       "prefetch job %u: %llu of %llu tiles failed", j->id,
		       (unsigned long long)j->failed, (unsigned long long)j->total);
	log_msg(LOG_INFO, "session %llu: prefetch job %u finished: %llu tiles, %llu failed",
		(unsigned long long)c->host.id, j->id, (unsigned long long)j->done,
		(unsigned long long)j->failed);
	job_remove(c, i);
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
	for (size_t i = 0; i < c->njobs; i++) {
		prefetch_job_tick(c->jobs[i], now_ns);
		send_progress(c, c->jobs[i]);
	}
	return c->njobs > 0;
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
}

void control_fini(struct control *c)
{
	control_stop(c);
	free(c->jobs);
	free(c->jobsets);
	for (size_t i = 0; i < c->nretired; i++)
		planet_set_unref(c->retired[i]);
	free(c->retired);
	*c = (struct control){ 0 };
}
