/* server — see server.h. An iteration: wait (timeout 0 while some session has more output to
 * produce), dispatch, let the pump list produce output, free the sessions closed during the
 * iteration. A closed session's record stays allocated (the graveyard) until the iteration
 * ends, so pointers in the current epoll batch or ready batch never dangle. The sessions see
 * the server only through srv->env: the callbacks below are its half of that contract.
 * Every iteration's work (from epoll_wait's return to its end) goes into the loop.*
 * histogram (loopstat.h). Memory that closed sessions held goes back to the system at the
 * next tick (malloc_trim, on a thread of its own so that its tens of milliseconds never
 * block the loop: glibc keeps freed heap otherwise, see clipmapd.c's mallopt).
 *
 * Admission: a connection is first not yet authenticated (pre-auth). Pre-auth connections
 * have pools of their own, one per listener kind (Unix, TCP) of max_preauth each, and on TCP
 * at most max_preauth_per_peer per peer address; a new connection over a cap closes the
 * oldest pre-auth one of its pool (or of its peer) rather than being refused, so idle
 * connections that hold every slot cannot lock a client out, and those on a TCP listener
 * never touch the Unix socket's. max_sessions counts authenticated sessions only, checked at
 * HELLO; the Unix socket has UNIX_RESERVE slots beyond it that TCP sessions cannot take.
 */
#include "server.h"

#include <errno.h>
#include <fcntl.h>
#include <malloc.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <netinet/in.h>
#include <sys/epoll.h>
#include <sys/resource.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/timerfd.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/log.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "encq.h"
#include "engine/tilemem.h"
#include "lookahead.h"
#include "loopstat.h"
#include "prefetch.h"
#include "readyq.h"
#include "session.h"
#include "tls.h"

#define TICK_NS 250000000ull
/* The cache's foci are recomputed at most this often (a WANT marks them stale): each pass
 * visits every session, so recomputing per WANT made 200 moving sessions cost 200² a second */
#define FOCI_EVERY_NS 100000000ull
#define STOP_GRACE_NS 1250000000ull /* + one tick + teardown: SIGTERM done within 2 s */
#define MAX_WATCH 4
#define MAX_FOCI 512
#define LOOP_OUT_BUDGET (4u << 20) /* output bytes produced per loop iteration */
/* Bytes written to sockets per loop iteration, all sessions together. The kernel copies each
 * into a socket buffer on this thread: fast while its pages are warm, but a fresh page costs
 * ~11 µs to fault on this VM kind (docs/ARCHITECTURE.md, "Memory"). Without the cap, an
 * iteration in which many sessions' EPOLLOUT came up wrote a socket buffer's worth to each:
 * with 200 moving sessions iterations reached 74-114 ms (tests/load/attack.py moving). */
#define LOOP_WRITE_BUDGET (2u << 20)
#define TRIM_EVERY_NS 1000000000ull /* at most one malloc_trim a second */
#define ACCEPT_BATCH 16
#define UNIX_RESERVE 8		       /* sessions over max_sessions kept for the Unix socket */
#define EVICT_WARN_NS 10000000000ull /* at most one eviction warning per 10 s */
#define MAX_LINK_STATS 32	       /* sessions whose link STATS shows */

enum ev_kind { EV_NONE = 0, EV_LISTENER, EV_SESSION, EV_READY, EV_TIMER, EV_WATCH, EV_ENCODED,
	       EV_FRONT };

/* What epoll hands back: the kind of source and its object. */
struct evsrc {
	enum ev_kind kind;
	void *obj;
};

/* The server's record of a session: its place in the lists and in the epoll set. */
struct session_link {
	struct evsrc ev;
	struct session *s;
	uint64_t id;
	int fd;
	bool in_pump, dead;
	bool preauth, is_unix;
	bool heard; /* read once before an eviction (its HELLO may be waiting) */
	bool front; /* watched in the front set (pre-auth), else in the main one */
	uint32_t events; /* its epoll interest */
	struct sockaddr_storage peer;		  /* TCP: the per-peer cap compares addresses */
	struct session_link *pre_prev, *pre_next; /* its pre-auth pool, oldest first */
	struct session_link *prev, *next;	  /* the live sessions */
	struct session_link *pump_next;	  /* the pump list */
	struct session_link *grave_next;  /* closed this iteration */
};

struct watch {
	struct evsrc ev;
	int fd;
	void (*fn)(void *ud);
	void *ud;
};

struct server {
	const struct conf *conf;
	struct sched *sched;
	struct cache *cache;
	struct planet_set *planets; /* current snapshot (owned reference) */
	uint8_t token[PROTO_MAX_TOKEN];
	size_t token_len;
	bool have_token;
	struct prefetch_limits prefetch; /* caps from the conf, counts from the sessions */

	int epfd, timerfd;
	/* The front set, in the main one: the listeners and the connections that have not said
	 * HELLO. Each iteration serves it first, whatever the main set's ready list holds: with
	 * hundreds of sessions ready for output (EPOLLOUT is level-triggered) a new client's
	 * accept and HELLO otherwise waited their turn behind them, 250-600 ms under 200
	 * moving sessions. */
	int epfd_front;
	struct evsrc ev_ready, ev_timer, ev_encoded, ev_front;
	struct readyq ready;
	struct listener ls[LISTEN_MAX];
	struct tls_server *tls; /* [tls]: the TCP listeners' credentials; NULL: plain */
	struct tls_tally tls_tally; /* their handshakes, across reloads */
	uint64_t tls_reloads;
	struct evsrc ls_ev[LISTEN_MAX];
	int nls;
	struct watch watches[MAX_WATCH];
	int nwatch;
	void (*tick_fn)(void *ud);
	void *tick_ud;
	bool stopping;
	uint64_t stop_deadline_ns;

	struct session_link *sessions; /* doubly linked */
	size_t nsessions;	       /* every connection */
	struct session_link *pre_head[2], *pre_tail[2]; /* [is_unix]: pre-auth pools */
	size_t npre[2], nauth;
	uint64_t evicted, refused, evict_warn_ns;
	bool accept_unix; /* the connection being accepted (for sess_attach) */
	struct sockaddr_storage accept_peer;
	uint64_t next_session_id, sessions_total;
	struct session_link *pump;	/* sessions with more output to produce */
	struct session_link *graveyard; /* closed this iteration, freed at its end */

	struct encq *encq; /* the shared encodings and their threads */
	struct proto_limits limits;
	uint64_t start_ns;
	struct session_counters counters;
	struct session_env env; /* lent to every session */
	size_t write_budget;	/* this iteration's (env.write_budget points here) */
	bool foci_stale;	/* a focus moved since update_foci last ran */
	uint64_t foci_ns;	/* when it last ran */

	struct loopstat loop;	/* iteration times */
	bool trim_due;		/* sessions were freed since the last trim */
	uint64_t last_trim_ns;
	pthread_t trimmer;	/* the last trim's thread, joined before the next */
	bool trimmer_started;
	atomic_bool trimming;	/* the trimmer runs */
	atomic_uint_fast64_t trims, trim_max_ns; /* written by the trimmer */
};

static int ep_add_to(int epfd, int fd, struct evsrc *ev)
{
	struct epoll_event e = { .events = EPOLLIN, .data.ptr = ev };
	return epoll_ctl(epfd, EPOLL_CTL_ADD, fd, &e) ? -errno : 0;
}

static int ep_add(struct server *srv, int fd, struct evsrc *ev)
{
	return ep_add_to(srv->epfd, fd, ev);
}

static int sess_epfd(const struct server *srv, const struct session_link *l)
{
	return l->front ? srv->epfd_front : srv->epfd;
}

/* ---- the sessions' half of session_env -------------------------------------------------- */

static struct session_link *sess_attach(void *ud, struct session *s, int fd, uint64_t *id)
{
	struct server *srv = ud;
	*id = ++srv->next_session_id;
	struct session_link *l = xcalloc(1, sizeof *l);
	*l = (struct session_link){ .ev = { EV_SESSION, l }, .s = s, .id = *id, .fd = fd,
				    .front = true, .events = EPOLLIN | EPOLLRDHUP };
	struct epoll_event ev = { .events = l->events, .data.ptr = &l->ev };
	if (epoll_ctl(srv->epfd_front, EPOLL_CTL_ADD, fd, &ev)) {
		log_msg(LOG_ERROR, "session: epoll_ctl: %s", strerror(errno));
		free(l);
		return NULL;
	}
	l->next = srv->sessions;
	if (srv->sessions)
		srv->sessions->prev = l;
	srv->sessions = l;
	srv->nsessions++;
	srv->sessions_total++;
	/* into its pre-auth pool, newest last */
	int k = l->is_unix = srv->accept_unix;
	l->peer = srv->accept_peer;
	l->preauth = true;
	l->pre_prev = srv->pre_tail[k];
	if (srv->pre_tail[k])
		srv->pre_tail[k]->pre_next = l;
	else
		srv->pre_head[k] = l;
	srv->pre_tail[k] = l;
	srv->npre[k]++;
	return l;
}

static void pre_unlink(struct server *srv, struct session_link *l)
{
	int k = l->is_unix;
	if (l->pre_prev)
		l->pre_prev->pre_next = l->pre_next;
	else
		srv->pre_head[k] = l->pre_next;
	if (l->pre_next)
		l->pre_next->pre_prev = l->pre_prev;
	else
		srv->pre_tail[k] = l->pre_prev;
	l->pre_prev = l->pre_next = NULL;
	l->preauth = false;
	srv->npre[k]--;
}

static int sess_authenticated(void *ud, struct session_link *l)
{
	struct server *srv = ud;
	size_t cap = (size_t)srv->conf->max_sessions + (l->is_unix ? UNIX_RESERVE : 0);
	if (!l->preauth)
		return 0;
	if (srv->nauth >= cap) {
		srv->refused++;
		log_msg(LOG_WARN, "session %llu: refused at HELLO: %zu sessions (max_sessions %d%s)",
			(unsigned long long)l->id, srv->nauth, srv->conf->max_sessions,
			l->is_unix ? " + the Unix socket's reserve" : "");
		return -EBUSY;
	}
	pre_unlink(srv, l);
	srv->nauth++;
	/* from the front set to the main one */
	struct epoll_event ev = { .events = l->events, .data.ptr = &l->ev };
	if (epoll_ctl(srv->epfd_front, EPOLL_CTL_DEL, l->fd, NULL) ||
	    epoll_ctl(srv->epfd, EPOLL_CTL_ADD, l->fd, &ev))
		log_msg(LOG_WARN, "session %llu: epoll_ctl move: %s", (unsigned long long)l->id,
			strerror(errno));
	else
		l->front = false;
	return 0;
}

static void sess_interest(void *ud, struct session_link *l, uint32_t events)
{
	struct server *srv = ud;
	struct epoll_event ev = { .events = events, .data.ptr = &l->ev };
	l->events = events;
	if (epoll_ctl(sess_epfd(srv, l), EPOLL_CTL_MOD, l->fd, &ev))
		log_msg(LOG_WARN, "session %llu: epoll_ctl: %s", (unsigned long long)l->id,
			strerror(errno));
}

static void sess_pump(void *ud, struct session_link *l)
{
	struct server *srv = ud;
	if (l->in_pump || l->dead)
		return;
	l->in_pump = true;
	l->pump_next = srv->pump;
	srv->pump = l;
}

static void sess_detach(void *ud, struct session_link *l)
{
	struct server *srv = ud;
	l->dead = true;
	if (epoll_ctl(sess_epfd(srv, l), EPOLL_CTL_DEL, l->fd, NULL))
		log_msg(LOG_WARN, "session %llu: epoll_ctl del: %s", (unsigned long long)l->id,
			strerror(errno));
	if (l->prev)
		l->prev->next = l->next;
	else
		srv->sessions = l->next;
	if (l->next)
		l->next->prev = l->prev;
	srv->nsessions--;
	if (l->preauth)
		pre_unlink(srv, l);
	else
		srv->nauth--;
	l->grave_next = srv->graveyard;
	srv->graveyard = l;
}

/* Recomputes the cache's pruning foci from every session's focus and velocity: where it is,
 * and where it will be 1, 2 and 4 s on (the look-ahead's horizons, lookahead.h), so that the tiles
 * generated for the path ahead are the last to go and those left behind the first. Every
 * session's own focus comes first; the foci ahead fill what room is left. */
static void update_foci(void *ud)
{
	struct server *srv = ud;
	struct cache_focus f[MAX_FOCI];
	struct lookahead_motion moving[MAX_FOCI];
	size_t n = 0, nm = 0;
	for (struct session_link *l = srv->sessions; l && n < MAX_FOCI; l = l->next) {
		double lon, lat, v[3], r;
		if (!session_focus(l->s, &lon, &lat, v, &r))
			continue;
		f[n++] = (struct cache_focus){ lon, lat };
		if (r > 0 && isfinite(v[0]) && isfinite(v[1]) && (v[0] != 0 || v[1] != 0))
			moving[nm++] = (struct lookahead_motion){ .lon = lon, .lat = lat, .ve = v[0],
								  .vn = v[1], .radius = r };
	}
	/* where the look-ahead's windows are (every horizon: the tiles it makes for 1 s on are
	 * kept as those for 2 and 4 s) */
	for (size_t i = 0; i < nm; i++)
		for (size_t h = 0; h < LOOKAHEAD_NHORIZONS && n < MAX_FOCI; h++) {
			lookahead_point(&moving[i], lookahead_horizons[h], &f[n].lon, &f[n].lat);
			n++;
		}
	uint32_t T = srv->planets && srv->planets->n ? srv->planets->planets[0]->tile_size : 256;
	cache_set_foci(srv->cache, f, n, T);
	srv->foci_stale = false;
	srv->foci_ns = clock_now_ns();
}

/* A session's focus moved: update_foci runs at the end of this loop iteration, or of the first
 * one FOCI_EVERY_NS after the last run (the timer's tick comes at least every TICK_NS). */
static void foci_moved(void *ud)
{
	((struct server *)ud)->foci_stale = true;
}

/* ---- STATS ------------------------------------------------------------------------------ */

struct statb {
	struct proto_stat *it;
	char (*keys)[128];
	size_t n, cap;
};

static struct proto_stat *stat_add(struct statb *b, const char *fmt, ...)
	__attribute__((format(printf, 2, 3)));
static struct proto_stat *stat_add(struct statb *b, const char *fmt, ...)
{
	if (b->n == b->cap)
		return NULL;
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(b->keys[b->n], sizeof b->keys[b->n], fmt, ap);
	va_end(ap);
	struct proto_stat *st = &b->it[b->n];
	*st = (struct proto_stat){ .key = b->keys[b->n] };
	b->n++;
	return st;
}

static void stat_u(struct statb *b, const char *key, uint64_t v)
{
	struct proto_stat *st = stat_add(b, "%s", key);
	if (st) {
		st->kind = PROTO_STAT_U64;
		st->u = v;
	}
}

static void stat_f(struct statb *b, const char *key, double v)
{
	struct proto_stat *st = stat_add(b, "%s", key);
	if (st) {
		st->kind = PROTO_STAT_F64;
		st->f = v;
	}
}

/* The generation figures of every node of every planet. */
static void stat_nodes(struct statb *b, const struct planet_set *ps)
{
	for (size_t i = 0; i < ps->n; i++) {
		const struct planet *p = ps->planets[i];
		for (size_t j = 0; j < p->nnodes; j++) {
			const struct node *n = p->nodes[j];
			uint64_t g = atomic_load(&n->generated), ns = atomic_load(&n->gen_ns);
			struct proto_stat *st = stat_add(b, "node.%s.%s.generated", p->name, n->name);
			if (st) {
				st->kind = PROTO_STAT_U64;
				st->u = g;
			}
			st = stat_add(b, "node.%s.%s.mean_ms", p->name, n->name);
			if (st) {
				st->kind = PROTO_STAT_F64;
				st->f = g ? (double)ns / (double)g * 1e-6 : 0.0;
			}
		}
	}
}

/* The disk tier's counters (store.disk.*), when there is one. */
static void stat_store(struct statb *b, struct store *st)
{
	if (!st)
		return;
	struct store_stats s;
	store_stat(st, &s);
	stat_u(b, "store.disk.tiles", s.tiles);
	stat_u(b, "store.disk.bytes", s.bytes);
	stat_u(b, "store.disk.budget", s.budget);
	stat_u(b, "store.disk.file_bytes", s.file_bytes);
	stat_u(b, "store.disk.hits", s.hits);
	stat_u(b, "store.disk.misses", s.misses);
	stat_u(b, "store.disk.puts", s.puts);
	stat_u(b, "store.disk.evictions", s.evictions);
	stat_u(b, "store.disk.evictions_prefetched", s.evictions_prefetched);
	stat_u(b, "store.disk.corrupt", s.corrupt);
	stat_u(b, "store.disk.write_drops", s.write_drops);
	stat_u(b, "store.disk.write_errors", s.write_errors);
	stat_u(b, "store.disk.queued", s.queued);
	stat_u(b, "store.disk.recovered", s.recovered);
}

/* The fleet's Redis tier's counters (store.redis.*), when there is one. */
static void stat_remote(struct statb *b, struct remote *r)
{
	if (!r)
		return;
	struct remote_stats s;
	r->ops->stat(r, &s);
	stat_u(b, "store.redis.connected", s.connected);
	stat_u(b, "store.redis.hits", s.hits);
	stat_u(b, "store.redis.misses", s.misses);
	stat_u(b, "store.redis.generated", s.generated);
	stat_u(b, "store.redis.writes", s.writes);
	stat_u(b, "store.redis.drops", s.drops);
	stat_u(b, "store.redis.bad", s.bad);
	stat_u(b, "store.redis.waits", s.waits);
	stat_u(b, "store.redis.takeovers", s.takeovers);
	stat_u(b, "store.redis.expired", s.expired);
	stat_u(b, "store.redis.errors", s.errors);
}

/* The loop-iteration histogram: count, maximum, p99 (a bucket bound), per bucket. */
static void stat_loop(struct statb *b, const struct loopstat *ls)
{
	stat_u(b, "loop.iterations", ls->n);
	stat_f(b, "loop.max_ms", (double)ls->max_ns * 1e-6);
	stat_f(b, "loop.p99_ms", loopstat_quantile_ms(ls, 0.99));
	stat_u(b, "loop.over_50ms", loopstat_over(ls, 50));
	stat_u(b, "loop.over_50ms.work", ls->slow_work);
	stat_u(b, "loop.over_50ms.blocked", ls->slow_blocked);
	stat_u(b, "loop.over_50ms.preempted", ls->slow_preempted);
	stat_f(b, "loop.cpu_max_ms", (double)ls->cpu_max_ns * 1e-6);
	for (int i = 0; i < LOOPSTAT_NB; i++) {
		struct proto_stat *st =
			i < LOOPSTAT_NB - 1
				? stat_add(b, "loop.le_%ums", loopstat_bound_ms(i))
				: stat_add(b, "loop.gt_%ums", loopstat_bound_ms(LOOPSTAT_NB - 2));
		if (st) {
			st->kind = PROTO_STAT_U64;
			st->u = ls->b[i];
		}
	}
}

/* Each authenticated session's link, the first MAX_LINK_STATS of them: one line to read
 * (link.ID) and its figures (link.ID.FIELD; rate in bytes/s, 0 where not measured). */
static void stat_links(struct statb *b, const struct server *srv)
{
	int shown = 0;
	for (const struct session_link *l = srv->sessions; l && shown < MAX_LINK_STATS;
	     l = l->next) {
		if (l->preauth)
			continue;
		shown++;
		struct session_load ld;
		session_get_load(l->s, &ld);
		struct proto_stat *st = stat_add(b, "link.%llu", (unsigned long long)ld.id);
		if (!st)
			return;
		char *line = b->keys[b->n - 1] + 32; /* the key is short: its tail holds the text */
		if (!ld.tcp)
			snprintf(line, 96, "%s: not measured (Unix socket), queue %llu KiB",
				 ld.peer, (unsigned long long)(ld.queue_bytes >> 10));
		else
			snprintf(line, 96, "%s: %.2f Mbit/s, rtt %.1f ms, queue %llu KiB = %.0f ms",
				 ld.peer, (double)ld.rate * 8e-6, ld.rtt_ms,
				 (unsigned long long)(ld.queue_bytes >> 10), ld.queue_ms);
		st->kind = PROTO_STAT_STR;
		st->s = line;
		const struct {
			const char *f;
			double v;
			bool u;
		} fs[] = { { "rate_bps", (double)ld.rate * 8, true },
			   { "rtt_ms", ld.rtt_ms, false },
			   { "min_rtt_ms", ld.min_rtt_ms, false },
			   { "window_bytes", (double)ld.window, true },
			   { "queue_bytes", (double)ld.queue_bytes, true },
			   { "queue_ms", ld.queue_ms, false },
			   { "inflight_bytes", (double)ld.inflight, true } };
		for (size_t i = 0; i < sizeof fs / sizeof fs[0]; i++) {
			st = stat_add(b, "link.%llu.%s", (unsigned long long)ld.id, fs[i].f);
			if (!st)
				return;
			st->kind = fs[i].u ? PROTO_STAT_U64 : PROTO_STAT_F64;
			if (fs[i].u)
				st->u = (uint64_t)fs[i].v;
			else
				st->f = fs[i].v;
		}
	}
}

static size_t fill_stats(void *ud, struct proto_stat *items, char (*keys)[128], size_t cap)
{
	const struct server *srv = ud;
	const struct session_counters *c = &srv->counters;
	struct statb b = { .it = items, .keys = keys, .cap = cap };
	struct sched_stats ss;
	struct cache_stats cs;
	sched_get_stats(srv->sched, &ss);
	cache_stats(srv->cache, &cs);
	stat_f(&b, "uptime_s", (double)(clock_now_ns() - srv->start_ns) * 1e-9);
	stat_u(&b, "sessions", srv->nsessions);
	stat_u(&b, "sessions.total", srv->sessions_total);
	stat_u(&b, "sessions.preauth", srv->npre[0] + srv->npre[1]);
	stat_u(&b, "sessions.preauth.evicted", srv->evicted);
	stat_u(&b, "sessions.refused", srv->refused);
	stat_u(&b, "sched.queued.visible", ss.queued[SCHED_VISIBLE]);
	stat_u(&b, "sched.queued.web", ss.queued[SCHED_WEB]);
	stat_u(&b, "sched.queued.prefetch", ss.queued[SCHED_PREFETCH]);
	stat_u(&b, "sched.queued.ahead", ss.queued[SCHED_AHEAD]);
	stat_u(&b, "sched.queued.bulk", ss.queued[SCHED_BULK]);
	stat_u(&b, "sched.waiting", ss.waiting);
	stat_u(&b, "sched.workers", (uint64_t)ss.workers);
	stat_u(&b, "sched.workers.busy", ss.running);
	stat_u(&b, "sched.generated", ss.generated);
	stat_u(&b, "sched.merged", ss.merged);
	stat_u(&b, "sched.skipped", ss.skipped);
	stat_u(&b, "sched.cancelled", ss.cancelled);
	stat_u(&b, "sched.failed", ss.failed);
	stat_u(&b, "cache.bytes", cs.bytes);
	stat_u(&b, "cache.budget", cs.budget);
	stat_u(&b, "cache.tiles", cs.tiles);
	stat_u(&b, "cache.hits", cs.hits);
	stat_u(&b, "cache.misses", cs.misses);
	stat_u(&b, "cache.inserts", cs.inserts);
	stat_u(&b, "cache.evictions", cs.evictions);
	stat_u(&b, "cache.prunes", cs.prunes);
	stat_f(&b, "cache.prune_ms", (double)cs.prune_ns * 1e-6);
	stat_f(&b, "cache.prune_hold_max_ms", (double)cs.prune_hold_max_ns * 1e-6);
	stat_u(&b, "sched.loaded", ss.loaded);
	stat_store(&b, sched_store(srv->sched));
	stat_remote(&b, sched_remote(srv->sched));
	stat_u(&b, "tiles.sent", c->tiles_sent);
	stat_u(&b, "tiles.failed", c->tiles_failed);
	stat_u(&b, "tiles.dropped", c->tiles_dropped);
	stat_u(&b, "tiles.stale", c->tiles_stale);
	stat_u(&b, "bytes.sent", c->bytes_sent);
	stat_u(&b, "errors.sent", c->errors_sent);
	stat_u(&b, "tiles.parked", c->tiles_parked);
	stat_u(&b, "tiles.relooked", c->tiles_relooked);
	stat_u(&b, "tiles.rewanted", c->tiles_rewanted);
	stat_u(&b, "sessions.pauses", c->pauses);
	if (srv->tls) {
		stat_u(&b, "tls.handshakes", srv->tls_tally.handshakes);
		stat_u(&b, "tls.failed", srv->tls_tally.failed);
		stat_u(&b, "tls.reloads", srv->tls_reloads);
	}
	struct encq_stats es;
	encq_stats(srv->encq, &es);
	stat_u(&b, "tiles.encoded", es.encoded);
	stat_u(&b, "encode.shared", es.shared);
	stat_u(&b, "encode.failed", es.failed);
	stat_u(&b, "encode.queued", es.queued);
	stat_u(&b, "encode.entries", es.entries);
	stat_u(&b, "encode.bytes", es.bytes);
	stat_u(&b, "encode.evicted", es.evicted);
	stat_u(&b, "lookahead.wants", c->ahead_wants);
	stat_u(&b, "tiles.recalled", c->tiles_recalled);
	stat_u(&b, "bytes.recalled", c->bytes_recalled);
	stat_u(&b, "planets", srv->planets->n);
	stat_u(&b, "planets.generation", srv->planets->generation);
	stat_u(&b, "planets.skipped", srv->planets->nskipped); /* files that did not load */
	uint64_t njobs = 0, pend = 0, pend_max = 0, ready = 0, held = 0, held_max = 0, outb = 0;
	uint64_t paused = 0;
	for (const struct session_link *l = srv->sessions; l; l = l->next) {
		struct session_load ld;
		session_get_load(l->s, &ld);
		njobs += ld.jobs;
		held += ld.held_bytes;
		held_max = ld.held_bytes > held_max ? ld.held_bytes : held_max;
		outb += ld.out_bytes;
		paused += ld.paused;
		pend += ld.pending_bytes;
		pend_max = ld.pending_bytes > pend_max ? ld.pending_bytes : pend_max;
		ready += ld.ready_tiles;
	}
	stat_u(&b, "sessions.pending_bytes", pend);
	stat_u(&b, "sessions.pending_bytes.max", pend_max);
	stat_u(&b, "sessions.ready_tiles", ready);
	stat_u(&b, "sessions.held_bytes", held);
	stat_u(&b, "sessions.held_bytes.max", held_max);
	stat_u(&b, "sessions.out_bytes", outb);
	stat_u(&b, "sessions.paused", paused);
	/* the per-session allowance: held tiles and queued output, max_pending each */
	stat_u(&b, "sessions.allowance_bytes", 2 * srv->limits.max_pending);
	stat_loop(&b, &srv->loop);
	stat_u(&b, "memory.trims", atomic_load(&srv->trims));
	stat_f(&b, "memory.trim_max_ms", (double)atomic_load(&srv->trim_max_ns) * 1e-6);
	struct tilemem_stats tm;
	tilemem_stats(&tm);
	stat_u(&b, "memory.pool.mapped", tm.mapped);
	stat_u(&b, "memory.pool.in_use", tm.in_use);
	stat_u(&b, "memory.pool.free_warm", tm.free_warm);
	stat_u(&b, "memory.pool.released", tm.released);
	stat_u(&b, "memory.pool.prefault_left", tm.prefault_left);
	stat_u(&b, "prefetch.jobs", njobs);
	stat_links(&b, srv);
	stat_nodes(&b, srv->planets);
	return b.n;
}

size_t server_stats(struct server *srv, struct proto_stat *items, char (*keys)[128], size_t cap)
{
	return fill_stats(srv, items, keys, cap);
}

const uint8_t *server_token(const struct server *srv, size_t *len)
{
	*len = srv->have_token ? srv->token_len : 0;
	return srv->have_token ? srv->token : NULL;
}

/* ---- setup ------------------------------------------------------------------------------ */

static int load_token(struct server *srv, char err[256])
{
	const char *path = srv->conf->token_file;
	if (!path)
		return 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		int e = -errno;
		err_set(err, "%s: %s", path, strerror(-e));
		return e;
	}
	ssize_t n = read(fd, srv->token, sizeof srv->token);
	int e = n < 0 ? -errno : 0;
	close(fd);
	if (e) {
		err_set(err, "%s: %s", path, strerror(-e));
		return e;
	}
	while (n > 0 && (srv->token[n - 1] == '\n' || srv->token[n - 1] == '\r'))
		n--;
	if (n == 0) {
		err_set(err, "%s: the token file is empty", path);
		return -EINVAL;
	}
	srv->token_len = (size_t)n;
	srv->have_token = true;
	return 0;
}

/* [session] raw_above_mbit in bits/s, for compress = auto only (0: never raw by speed). */
static uint64_t raw_above(const struct conf *c)
{
	return c->compress == CONF_COMPRESS_AUTO ? (uint64_t)c->raw_above_mbit * 1000000u : 0;
}

/* [prefetch] caps (the running jobs' counts are kept). */
static void set_prefetch_caps(struct server *srv)
{
	const struct conf *c = srv->conf;
	srv->prefetch.max_tiles = c->pf_max_tiles;
	srv->prefetch.max_tiles_local = c->pf_max_tiles_local;
	srv->prefetch.max_jobs_local = c->pf_max_jobs_local;
	srv->prefetch.max_jobs_total = c->pf_max_jobs_total;
	srv->prefetch.max_tiles_total = c->pf_max_tiles_total;
}

/* [session] lossy_below_mbit in bits/s (0: never lossy; compress = never: never either). */
static uint64_t lossy_below(const struct conf *c)
{
	return c->compress == CONF_COMPRESS_NEVER ? 0 : (uint64_t)c->lossy_below_mbit * 1000000u;
}

void server_conf_changed(struct server *srv)
{
	const struct conf *c = srv->conf;
	srv->limits = (struct proto_limits){ .max_want = c->max_want, .max_rate = c->max_rate,
					     .max_pending = c->max_pending,
					     .max_frame = c->max_frame };
	srv->env.max_jobs = c->max_jobs;
	srv->env.queue_ms = c->send_queue_ms;
	srv->env.bbr = c->bbr;
	srv->env.raw_above_bps = raw_above(c);
	srv->env.lossy_below_bps = lossy_below(c);
	srv->env.webp_quality = c->webp_quality;
	srv->env.handshake_ns = (uint64_t)c->handshake_timeout * 1000000000u;
	srv->env.frame_ns = (uint64_t)c->frame_timeout * 1000000000u;
	set_prefetch_caps(srv);
}

static void init_env(struct server *srv)
{
	srv->env = (struct session_env){
		.limits = &srv->limits, .max_jobs = srv->conf->max_jobs, .sched = srv->sched,
		.queue_ms = srv->conf->send_queue_ms, .bbr = srv->conf->bbr,
		.raw_above_bps = raw_above(srv->conf),
		.lossy_below_bps = lossy_below(srv->conf), .webp_quality = srv->conf->webp_quality,
		.cache = srv->cache, .ready = &srv->ready, .encq = srv->encq,
		.token = srv->token, .token_len = srv->token_len, .have_token = srv->have_token,
		.planets = &srv->planets, .counters = &srv->counters,
		.write_budget = &srv->write_budget, .ud = srv,
		.handshake_ns = (uint64_t)srv->conf->handshake_timeout * 1000000000u,
		.frame_ns = (uint64_t)srv->conf->frame_timeout * 1000000000u,
		.attach = sess_attach, .authenticated = sess_authenticated,
		.interest = sess_interest, .pump = sess_pump,
		.detach = sess_detach, .focus_changed = foci_moved, .stats = fill_stats,
		.prefetch = &srv->prefetch
	};
	set_prefetch_caps(srv);
}

/* The shared encodings' budget: a quarter of the tile cache's, within [16, 256] MiB (a
 * `none` encoding keeps its tile alive, so this much may outlive the cache's own budget). */
static uint64_t encq_budget(const struct conf *c)
{
	uint64_t b = (uint64_t)c->cache_bytes / 4;
	b = b < (16u << 20) ? 16u << 20 : b;
	return b > (256u << 20) ? 256u << 20 : b;
}

/* The ready eventfd, the encoders' eventfd and the housekeeping timer in the epoll set. */
static int open_loop_fds(struct server *srv, char err[256])
{
	int rc;
	srv->epfd = epoll_create1(EPOLL_CLOEXEC);
	srv->epfd_front = epoll_create1(EPOLL_CLOEXEC);
	srv->timerfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
	if (srv->epfd < 0 || srv->epfd_front < 0 || srv->timerfd < 0 ||
	    (rc = readyq_init(&srv->ready))) {
		rc = -errno;
		err_set(err, "epoll/eventfd/timerfd: %s", strerror(-rc));
		return rc;
	}
	struct itimerspec its = { .it_interval = { 0, (long)TICK_NS },
				  .it_value = { 0, (long)TICK_NS } };
	srv->ev_ready = (struct evsrc){ EV_READY, NULL };
	srv->ev_timer = (struct evsrc){ EV_TIMER, NULL };
	rc = 0;
	srv->ev_encoded = (struct evsrc){ EV_ENCODED, NULL };
	srv->ev_front = (struct evsrc){ EV_FRONT, NULL };
	if ((rc = encq_create(ENCQ_THREADS, encq_budget(srv->conf), session_on_encoded,
			      &srv->encq))) {
		err_set(err, "tile encoders: %s", strerror(-rc));
		return rc;
	}
	if (timerfd_settime(srv->timerfd, 0, &its, NULL) ||
	    (rc = ep_add(srv, srv->ready.evfd, &srv->ev_ready)) ||
	    (rc = ep_add(srv, encq_fd(srv->encq), &srv->ev_encoded)) ||
	    (rc = ep_add(srv, srv->timerfd, &srv->ev_timer)) ||
	    (rc = ep_add(srv, srv->epfd_front, &srv->ev_front))) {
		rc = rc ? rc : -errno;
		err_set(err, "timer: %s", strerror(-rc));
		return rc;
	}
	return 0;
}

int server_create(const struct conf *c, struct sched *s, struct cache *cache,
		  struct planet_set *planets, struct server **out, char err[256])
{
	*out = NULL;
	struct server *srv = xcalloc(1, sizeof *srv);
	srv->conf = c;
	srv->sched = s;
	srv->cache = cache;
	srv->planets = planets;
	srv->epfd = srv->epfd_front = srv->timerfd = srv->ready.evfd = -1;
	srv->start_ns = clock_now_ns();
	srv->limits = (struct proto_limits){ .max_want = c->max_want, .max_rate = c->max_rate,
					     .max_pending = c->max_pending,
					     .max_frame = c->max_frame };
	int rc;
	if ((rc = load_token(srv, err)) || (rc = open_loop_fds(srv, err)))
		goto fail;
	if (c->tls_cert && (rc = tls_server_create(c->tls_cert, c->tls_key, &srv->tls_tally,
						   &srv->tls, err, NULL)))
		goto fail;
	rc = listen_open(c, srv->ls, &srv->nls, err);
	if (rc)
		goto fail;
	for (int i = 0; i < srv->nls; i++) {
		struct listener *l = &srv->ls[i];
		srv->ls_ev[i] = (struct evsrc){ EV_LISTENER, l };
		l->tls = l->is_unix ? NULL : srv->tls;
		if (l->need_token && !srv->have_token) {
			err_set(err, "listener %s requires a token: set token_file", l->name);
			rc = -EINVAL;
			goto fail;
		}
		if ((rc = ep_add_to(srv->epfd_front, l->fd, &srv->ls_ev[i]))) {
			err_set(err, "%s: epoll: %s", l->name, strerror(-rc));
			goto fail;
		}
	}
	init_env(srv);
	*out = srv;
	return 0;
fail:
	srv->planets = NULL; /* not taken on failure */
	server_destroy(srv);
	return rc;
}

int server_reload_tls(struct server *srv, const char *cert, const char *key, char err[256],
		      char warn[256])
{
	if (!srv->tls) {
		err_set(err, "the listeners were started without TLS");
		return -EINVAL;
	}
	struct tls_server *t;
	int rc = tls_server_create(cert, key, &srv->tls_tally, &t, err, warn);
	if (rc)
		return rc;
	for (int i = 0; i < srv->nls; i++)
		if (srv->ls[i].tls)
			srv->ls[i].tls = t;
	tls_server_destroy(srv->tls); /* freed when the last connection that began with it ends */
	srv->tls = t;
	srv->tls_reloads++;
	return 0;
}

static void close_listeners(struct server *srv)
{
	for (int i = 0; i < srv->nls; i++) {
		struct listener *l = &srv->ls[i];
		if (l->fd < 0)
			continue;
		epoll_ctl(srv->epfd_front, EPOLL_CTL_DEL, l->fd, NULL);
		listen_close(srv->conf, l);
	}
}

static void free_graveyard(struct server *srv)
{
	struct session_link *g = srv->graveyard;
	srv->graveyard = NULL;
	while (g) {
		struct session_link *next = g->grave_next;
		session_free(g->s);
		free(g);
		g = next;
		srv->trim_due = true;
	}
}

void server_destroy(struct server *srv)
{
	if (!srv)
		return;
	while (srv->sessions)
		session_close(srv->sessions->s, "server exiting");
	free_graveyard(srv);
	close_listeners(srv);
	tls_server_destroy(srv->tls); /* no session is left to use it */
	srv->tls = NULL;
	/* Released requests may still report into the ready queue until the manager frees them. */
	if (srv->sessions_total)
		sched_barrier(srv->sched);
	readyq_fini(&srv->ready);
	if (srv->trimmer_started)
		xthread_join(srv->trimmer);
	if (srv->epfd >= 0)
		close(srv->epfd);
	if (srv->epfd_front >= 0)
		close(srv->epfd_front);
	if (srv->timerfd >= 0)
		close(srv->timerfd);
	encq_destroy(srv->encq); /* after the sessions: none refers to an encoding any more */
	planet_set_unref(srv->planets);
	free(srv);
}

int server_watch_fd(struct server *srv, int fd, void (*fn)(void *ud), void *ud)
{
	if (srv->nwatch == MAX_WATCH)
		return -ENOSPC;
	struct watch *w = &srv->watches[srv->nwatch];
	*w = (struct watch){ .ev = { EV_WATCH, w }, .fd = fd, .fn = fn, .ud = ud };
	int rc = ep_add(srv, fd, &w->ev);
	if (!rc)
		srv->nwatch++;
	return rc;
}

void server_set_tick(struct server *srv, void (*fn)(void *ud), void *ud)
{
	srv->tick_fn = fn;
	srv->tick_ud = ud;
}

const struct planet_set *server_planets(const struct server *srv)
{
	return srv->planets;
}

size_t server_listeners(const struct server *srv, const struct listener **out)
{
	*out = srv->ls;
	return (size_t)srv->nls;
}

/* ---- the loop --------------------------------------------------------------------------- */

static void on_ready(struct server *srv)
{
	size_t n;
	struct ready_item *batch = readyq_take(&srv->ready, &n);
	/* Sessions closed while this batch runs stay allocated (graveyard) until the iteration
	 * ends; session_on_ready ignores them. An item marked with a handle whose session closed
	 * (it may be freed already) is dropped without looking at the session. */
	for (size_t i = 0; i < n; i++) {
		struct ready_item *it = &batch[i];
		if (it->src) {
			ready_item_taken(it);
			bool dead = it->src->dead;
			ready_src_unref(it->src);
			it->src = NULL;
			if (dead) {
				tile_unref(it->t);
				continue;
			}
		}
		session_on_ready(it->s, it);
	}
	free(batch);
}

/* Whether two TCP peers have the same address (ports aside). */
static bool same_host(const struct sockaddr_storage *a, const struct sockaddr_storage *b)
{
	if (a->ss_family != b->ss_family)
		return false;
	if (a->ss_family == AF_INET)
		return ((const struct sockaddr_in *)a)->sin_addr.s_addr ==
		       ((const struct sockaddr_in *)b)->sin_addr.s_addr;
	if (a->ss_family == AF_INET6)
		return memcmp(&((const struct sockaddr_in6 *)a)->sin6_addr,
			      &((const struct sockaddr_in6 *)b)->sin6_addr, sizeof(struct in6_addr)) == 0;
	return false;
}

/* Closes the pre-auth connection victim to make room for a new one (why: which cap). */
static void evict(struct server *srv, struct session_link *victim, const struct listener *l,
		  const char *why)
{
	srv->evicted++;
	uint64_t now = clock_now_ns();
	if (now >= srv->evict_warn_ns) {
		srv->evict_warn_ns = now + EVICT_WARN_NS;
		log_msg(LOG_WARN, "%s: %s reached: closing the oldest connections that have not "
			"completed HELLO (%llu so far)", l->name, why,
			(unsigned long long)srv->evicted);
	}
	session_close(victim->s, why);
}

/* Before victim is evicted: when its socket holds bytes the loop has not read yet (a client
 * whose HELLO arrived in the same instant as a flood of connections), reads them first, once.
 * Returns true when it did (the pools may have changed: the caller looks again). */
static bool hear_first(struct session_link *victim)
{
	int n = 0;
	if (victim->heard || ioctl(victim->fd, FIONREAD, &n) < 0 || n <= 0)
		return false;
	victim->heard = true;
	session_on_event(victim->s, EPOLLIN); /* authenticates it, closes it, or neither */
	return true;
}

/* Brings the pre-auth pool of a new connection from peer back within its caps, closing the
 * oldest connections first (the new one is the newest: it stays). A connection whose HELLO
 * waits unread in its socket is heard before it can be chosen. */
static void enforce_preauth(struct server *srv, const struct listener *l,
			    const struct sockaddr_storage *peer)
{
	int k = l->is_unix;
	if (!l->is_unix) {
		for (;;) {
			struct session_link *oldest = NULL;
			int same = 0;
			for (struct session_link *p = srv->pre_head[0]; p; p = p->pre_next) {
				if (same_host(&p->peer, peer)) {
					oldest = oldest ? oldest : p;
					same++;
				}
			}
			if (same <= srv->conf->max_preauth_per_peer)
				break;
			if (!hear_first(oldest))
				evict(srv, oldest, l, "max_preauth_per_peer");
		}
	}
	while (srv->npre[k] > (size_t)srv->conf->max_preauth && srv->pre_head[k])
		if (!hear_first(srv->pre_head[k]))
			evict(srv, srv->pre_head[k], l, "max_preauth");
}

static void on_accept(struct server *srv, struct listener *l)
{
	/* A batch at a time (the listener stays readable), so a flood of connections does not
	 * keep the sessions' input waiting. */
	for (int i = 0; i < ACCEPT_BATCH; i++) {
		struct sockaddr_storage peer;
		int fd = listen_accept(l, &peer);
		if (fd < 0) {
			if (fd != -EAGAIN)
				log_msg(LOG_WARN, "%s: accept: %s", l->name, strerror(-fd));
			return;
		}
		listen_tune(l, fd);
		srv->accept_unix = l->is_unix;
		srv->accept_peer = peer;
		struct session *ss = session_create(&srv->env, fd, l);
		if (!ss)
			continue;
		/* A client sends HELLO with its connect: read it now, so a well-behaved one leaves
		 * the pre-auth pool at once and costs no one a slot; then the caps. */
		session_on_event(ss, EPOLLIN);
		enforce_preauth(srv, l, &peer);
	}
}

/* The trimmer thread: one malloc_trim, timed. */
static void *trim_main(void *arg)
{
	struct server *srv = arg;
	xthread_batch("trim");
	uint64_t t0 = clock_now_ns();
	malloc_trim(0);
	uint64_t dt = clock_now_ns() - t0;
	if (dt > atomic_load(&srv->trim_max_ns))
		atomic_store(&srv->trim_max_ns, dt);
	atomic_fetch_add(&srv->trims, 1);
	atomic_store(&srv->trimming, false);
	return NULL;
}

static void on_timer(struct server *srv)
{
	uint64_t v;
	ssize_t n = read(srv->timerfd, &v, sizeof v);
	(void)n;
	uint64_t now = clock_now_ns();
	if (srv->tick_fn)
		srv->tick_fn(srv->tick_ud);
	for (struct session_link *l = srv->sessions, *next; l; l = next) {
		next = l->next; /* l may close */
		session_tick(l->s, now);
	}
	if (srv->stopping && now > srv->stop_deadline_ns)
		while (srv->sessions)
			session_close(srv->sessions->s, "shutdown: flush timed out");
	if (srv->trim_due && !srv->stopping && now - srv->last_trim_ns > TRIM_EVERY_NS &&
	    !atomic_load(&srv->trimming)) {
		/* give back what closed sessions held (their tiles, buffers) */
		if (srv->trimmer_started)
			xthread_join(srv->trimmer); /* finished: trimming is false */
		atomic_store(&srv->trimming, true);
		srv->trimmer_started = xthread_create(&srv->trimmer, trim_main, srv) == 0;
		if (!srv->trimmer_started)
			atomic_store(&srv->trimming, false);
		srv->trim_due = false;
		srv->last_trim_ns = now;
	}
}

void server_set_planets(struct server *srv, struct planet_set *ps)
{
	planet_set_unref(srv->planets);
	srv->planets = ps;
	for (struct session_link *l = srv->sessions, *next; l; l = next) {
		next = l->next; /* l may close (a failed send) */
		session_reload(l->s, ps);
	}
}

void server_stop(struct server *srv)
{
	if (srv->stopping)
		return;
	srv->stopping = true;
	srv->stop_deadline_ns = clock_now_ns() + STOP_GRACE_NS;
	close_listeners(srv);
	for (struct session_link *l = srv->sessions, *next; l; l = next) {
		next = l->next;
		session_shutdown(l->s);
	}
}

static void dispatch(struct server *srv, const struct epoll_event *e)
{
	struct evsrc *ev = e->data.ptr;
	switch (ev->kind) {
	case EV_LISTENER:
		if (!srv->stopping)
			on_accept(srv, ev->obj);
		break;
	case EV_SESSION:
		session_on_event(((struct session_link *)ev->obj)->s, e->events);
		break;
	case EV_READY: on_ready(srv); break;
	case EV_TIMER: on_timer(srv); break;
	case EV_ENCODED: encq_drain(srv->encq); break;
	case EV_FRONT: break; /* served at the start of every iteration */
	case EV_WATCH: {
		struct watch *w = ev->obj;
		w->fn(w->ud);
		break;
	}
	default: break;
	}
}

/* This thread's CPU time, ns. CLOCK_THREAD_CPUTIME_ID, not getrusage(RUSAGE_THREAD): the
 * latter reads the runtime as of the thread's last scheduler accounting (up to a tick stale),
 * so an iteration's difference could exceed its wall time by a tick (test_serve_load's
 * loop.cpu_max_ms ≤ loop.max_ms failed so under load). */
static uint64_t thread_cpu_ns(void)
{
	struct timespec ts;
	if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts))
		return 0;
	return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

int server_run(struct server *srv)
{
	struct epoll_event evs[64], front[64];
	while (!(srv->stopping && srv->nsessions == 0)) {
		int n = epoll_wait(srv->epfd, evs, 64, srv->pump ? 0 : -1);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			int e = -errno;
			log_msg(LOG_ERROR, "epoll_wait: %s", strerror(-e));
			return e;
		}
		uint64_t t0 = clock_now_ns(), c0 = thread_cpu_ns();
		struct rusage r0, r1;
		getrusage(RUSAGE_THREAD, &r0);
		srv->write_budget = LOOP_WRITE_BUDGET;
		int nf = epoll_wait(srv->epfd_front, front, 64, 0);
		for (int i = 0; i < nf; i++)
			dispatch(srv, &front[i]);
		for (int i = 0; i < n; i++)
			dispatch(srv, &evs[i]);
		/* Output for at most LOOP_OUT_BUDGET bytes per iteration (queuing a shared
		 * encoding costs nothing per byte, but the kernel copies what sendmsg hands it):
		 * sessions not reached stay listed, at the front, for the next iteration, which
		 * then does not wait. */
		struct session_link *p = srv->pump;
		srv->pump = NULL;
		size_t budget = LOOP_OUT_BUDGET;
		while (p && budget) {
			struct session_link *next = p->pump_next;
			p->pump_next = NULL;
			p->in_pump = false;
			if (session_pump(p->s, &budget))
				sess_pump(srv, p);
			p = next;
		}
		while (p) {
			struct session_link *next = p->pump_next;
			p->pump_next = NULL;
			p->in_pump = false;
			sess_pump(srv, p);
			p = next;
		}
		free_graveyard(srv);
		if (srv->foci_stale && clock_now_ns() - srv->foci_ns >= FOCI_EVERY_NS)
			update_foci(srv);
		uint64_t c1 = thread_cpu_ns(), dt = clock_now_ns() - t0;
		loopstat_add(&srv->loop, dt);
		getrusage(RUSAGE_THREAD, &r1);
		loopstat_why(&srv->loop, dt, c1 > c0 ? c1 - c0 : 0,
			     (uint64_t)(r1.ru_nvcsw - r0.ru_nvcsw));
	}
	free_graveyard(srv);
	return 0;
}
