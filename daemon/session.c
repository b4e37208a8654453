/* session — see session.h. Design note: a session owns one scheduler request for its want-set
 * (all planets it opened, concatenated); ready reports come back through env->ready as
 * (session, job, key, tile), the want-set says whether the key is still wanted and orders what
 * waits for output room. A TILE frame's payload is an encoding shared by every session that
 * wants the tile in that codec, made once off the loop (encq.h); the output queues a
 * reference to it with this session's header (conn.h), and writes it with sendmsg from the
 * shared bytes: nothing on the loop scales with tile bytes. A closed session stays allocated until the server frees it at the end of the loop
 * iteration, so pointers in the current epoll batch or ready batch never dangle.
 *
 * Memory: ready tiles waiting for output room are held up to the session's allowance
 * (max_pending bytes of raw tiles, the same figure that caps its queued output, in which a
 * shared encoding counts its whole frame, as if copied, and one still being encoded its raw
 * size); beyond it they are parked (released) and looked up in the cache again when room
 * appears, or wanted again when the cache let them go. Reports still waiting for the loop hold
 * at most max_pending more (ready_src.queue_cap; beyond it they arrive parked). A session thus
 * holds at most about 3 × max_pending, and its output buffer is given back whenever it drains.
 *
 * Asking: a session gives the scheduler only what it can take, its first WANTED entries in
 * the order the scheduler serves them (class, level, want order) whose bytes, with those of
 * its READY entries not yet sent, fit in its credit (2 × max_pending + the send window), and
 * beyond it those the cache holds (nothing to make: one trip through the scheduler instead of
 * one per quarter of the credit for a want-set of cached tiles). Sending frees credit; each
 * time a quarter of it is free the next entries are asked for.
 * (Asking for the whole want-set at once made a slow reader's tiles several times over:
 * parked, let go by the cache before it read them, made again.) Once it parks with its output
 * full, its wants are withdrawn from the scheduler (paused: nothing is made for a client that
 * does not read) until the output drains to half of max_pending; then they are asked for
 * again, in order, so coarse-first and replacement work as before.
 *
 * Closing never waits for the scheduler: the request is released (sched_req_release) and the
 * manager frees it later; reports for it that still come are marked with the session's
 * ready_src, which the close marks dead, and the loop drops them.
 */
#include "session.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <netinet/in.h>
#include <arpa/inet.h>

#include "common/clock.h"
#include "common/log.h"
#include "common/xalloc.h"
#include "conn.h"
#include "control.h"
#include "encpick.h"
#include "lookahead.h"
#include "encq.h"
#include "linkest.h"
#include "wantset.h"

#define MAX_OPEN 16	       /* planets per session */
#define PUMP_BUDGET (4u << 20) /* output bytes produced per pump call (fairness) */
#define READ_BUDGET (1u << 20) /* input bytes read per event */
#define CLOSE_GRACE_NS 2000000000ull

struct sopen {
	struct planet *p;	/* NULL: dropped by a reload (the id may be given again) */
	struct planet_set *set; /* reference keeping p alive; NULL with p */
};

struct session {
	const struct session_env *env;
	struct session_link *link;
	struct conn c;
	uint64_t id;
	char name[64];
	char peer[64]; /* "127.0.0.1:40312", "[::1]:40312", "unix" (pid when known) */
	const struct listener *l;
	uint64_t born_ns;    /* accepted: the handshake deadline counts from here */
	uint64_t partial_ns; /* when the frame at the head of the input started to wait; 0: none */
	bool need_token, compress;
	enum proto_state st;
	bool closing, dead;
	uint64_t close_deadline;
	struct proto_rate rate;
	uint32_t rate_viol;
	uint8_t codec;	 /* the lossless codec */
	uint32_t codecs; /* HELLO_OK's: codec, and the lossy ones agreed */
	bool parts;	 /* the client reassembles TILE_PART (PROTO_FEAT_PARTS) */

	struct sopen opened[MAX_OPEN];
	int nopened;
	/* Sets this session's earlier want lists named nodes of: the scheduler may still be
	 * working on them after a reload rebinds the session, so they live as long as it. */
	struct planet_set **retired;
	size_t nretired;

	struct wantset ws;
	struct wantset_entry *scratch; /* a WANT's entries, reused */
	size_t capscratch;
	struct sched_req *req;
	struct sched_req *ahead; /* the look-ahead along the path (lookahead.h): unsent */
	uint64_t focus_ns;	 /* when the last WANT's focus came */
	size_t nahead;		 /* tiles the look-ahead holds wanted now */
	struct ready_src *src; /* this session's handle on the ready queue (reference) */
	bool paused; /* its wants are withdrawn while its output is full (see the top) */
	bool sub_left;	   /* the last submission left WANTED entries out (credit) */
	uint64_t sub_freed; /* bytes sent or dropped since that submission */
	bool has_focus;
	double lon, lat, vel[3];
	double focus_a; /* the focus planet's equatorial radius (m) */

	struct control ctl;
	uint64_t tiles_sent, tiles_dropped;

	/* The link and the send window (linkest.h). TILE frames still wholly in the output can
	 * be taken back by a new want-set (conn_recall) before the kernel has them. */
	struct linkest le;
};

/* ---- output ----------------------------------------------------------------------------- */

static void update_interest(struct session *s)
{
	if (!s->dead)
		s->env->interest(s->env->ud, s->link, conn_events(&s->c));
}

static void pump_add(struct session *s)
{
	if (!s->dead)
		s->env->pump(s->env->ud, s->link);
}

static void submit_wants(struct session *s, uint16_t ref_type, uint32_t ref_id);

/* Pauses a session whose output is full while some of its ready tiles are parked (held tiles
 * full too): its wants leave the scheduler until the output drains (resume_if_drained).
 * Checked when a tile arrives and after each pump: a tile parked while an encode was still
 * settling its frame's size left the output just under max_pending, the pump then filled it
 * from the held tiles, nothing more arrived, and the session sat stalled by its credit without
 * counting as paused. */
static void pause_if_full(struct session *s)
{
	if (!s->paused && !s->closing && !s->dead && wantset_nparked(&s->ws) &&
	    conn_pending(&s->c) >= s->env->limits->max_pending) {
		s->paused = true;
		s->env->counters->pauses++;
		(void)sched_req_want(s->req, NULL, 0);
	}
}

/* A paused session's wants go back in once its output drained to half of max_pending. */
static void resume_if_drained(struct session *s)
{
	if (s->paused && !s->closing && !s->dead &&
	    conn_pending(&s->c) <= s->env->limits->max_pending / 2) {
		s->paused = false;
		submit_wants(s, 0, 0);
	}
}

/* Writes what it can. Returns 0, or -errno after closing the session. */
static int flush(struct session *s)
{
	uint32_t was = conn_events(&s->c);
	uint64_t w = 0;
	size_t *budget = s->env->write_budget;
	int rc = conn_flush(&s->c, &w, budget ? *budget : SIZE_MAX);
	if (budget)
		*budget = w < *budget ? *budget - (size_t)w : 0;
	s->env->counters->bytes_sent += w;
	linkest_sample(&s->le, clock_now_ns(), false);
	if (rc) {
		char why[240];
		snprintf(why, sizeof why, "send: %s", conn_strerror(&s->c, rc));
		session_close(s, why);
		return rc;
	}
	if (s->closing) {
		if (!s->c.want_out && !conn_pending(&s->c)) {
			session_close(s, NULL);
			return -EPIPE;
		}
	} else {
		conn_throttle(&s->c, s->env->limits->max_pending);
	}
	resume_if_drained(s); /* the client reads again */
	if (was != conn_events(&s->c))
		update_interest(s);
	return 0;
}

static void send_msg(struct session *s, const struct proto_msg *m)
{
	char err[256];
	ssize_t n = proto_encode(conn_msg_begin(&s->c), m, err);
	conn_msg_end(&s->c);
	if (n < 0)
		log_msg(LOG_ERROR, "session %llu: cannot encode %s: %s", (unsigned long long)s->id,
			proto_type_name(m->type), err);
}

static void __attribute__((format(printf, 5, 6)))
send_error(struct session *s, uint16_t code, uint16_t ref_type, uint32_t ref_id, const char *fmt,
	   ...)
{
	char msg[512];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(msg, sizeof msg, fmt, ap);
	va_end(ap);
	struct proto_msg m = { .type = PROTO_ERROR,
			       .error = { .code = code, .ref_type = ref_type, .ref_id = ref_id,
					  .message = msg } };
	send_msg(s, &m);
	s->env->counters->errors_sent++;
	/* A failed authentication is an operator's business: a warning, with the peer. Errors
	 * before the handshake are otherwise chatter (a garbage flood must not flood the log). */
	enum log_level lv = LOG_INFO;
	if (code == PROTO_E_AUTH)
		lv = LOG_WARN;
	else if (code == PROTO_E_SHUTDOWN || s->st == PROTO_ST_HANDSHAKE)
		lv = LOG_DEBUG;
	char esc[700];
	log_msg(lv, "session %llu (%s, %s): error %s: %s", (unsigned long long)s->id, s->name,
		s->peer, proto_code_name(code), log_escape(esc, sizeof esc, msg));
}

/* control's way out (control_host). */
static void ctl_error(struct session *s, uint16_t code, uint16_t ref_type, uint32_t ref_id,
		      const char *msg)
{
	send_error(s, code, ref_type, ref_id, "%s", msg);
}

static void begin_close(struct session *s)
{
	if (s->closing || s->dead)
		return;
	s->closing = true;
	s->c.reading = false;
	s->close_deadline = clock_now_ns() + CLOSE_GRACE_NS;
	if (s->req)
		(void)sched_req_want(s->req, NULL, 0);
	if (s->ahead)
		(void)sched_req_want(s->ahead, NULL, 0);
	update_interest(s);
	flush(s);
}

/* Keeps the reference ps (taken) until the session is freed: the scheduler may still be
 * generating tiles of nodes this session wanted from it (it has no way to say it is done). */
static void retire(struct session *s, struct planet_set *ps)
{
	if (!ps)
		return;
	for (size_t i = 0; i < s->nretired; i++) {
		if (s->retired[i] == ps) {
			planet_set_unref(ps); /* one reference per set is enough */
			return;
		}
	}
	s->retired = xrealloc(s->retired, (s->nretired + 1) * sizeof *s->retired);
	s->retired[s->nretired++] = ps;
}

/* The look-ahead's tiles are made for the cache and the store only: nothing to tell. */
static void ahead_ready_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	(void)ud;
	(void)w;
	(void)t;
	(void)err;
}

/* ---- tiles ---------------------------------------------------------------------------- */

static void encode_tile(struct session *s, const struct wantset_entry *e)
{
	struct session_counters *cnt = s->env->counters;
	if (!e->t) {
		char msg[200];
		snprintf(msg, sizeof msg, "tile %u/%u/%u/%u: %s", e->key.lx, e->key.ly, e->key.x,
			 e->key.y, strerror(-e->err));
		struct proto_msg m = { .type = PROTO_TILE_FAIL,
				       .tile_fail = { .seq = e->seq, .planet_id = e->pid,
						      .layer = e->layer, .key = e->key,
						      .code = PROTO_E_UNAVAILABLE, .message = msg } };
		send_msg(s, &m);
		cnt->tiles_failed++;
		return;
	}
	/* raw on fast links, lossy on slow ones where agreed, else the session's codec */
	const struct planet *p = e->pid >= 1 && e->pid <= MAX_OPEN ? s->opened[e->pid - 1].p : NULL;
	struct encpick_policy pol = { .lossless = (enum tcodec)s->codec, .offered = s->codecs,
				      .raw_above_bps = s->env->raw_above_bps,
				      .lossy_below_bps = s->env->lossy_below_bps,
				      .webp_quality = s->env->webp_quality };
	struct encpick pick;
	encpick(&pol, e->t->type, e->key.ly, e->t->size, p ? p->a : 6378137.0,
		s->le.tcp ? s->le.rate * 8 : 0, &pick);
	/* shared with every session that wants this encoding; made off the loop (encq.h) */
	struct etile *et = encq_get(s->env->encq, e->t, pick.codec, &pick.lossy, s->src);
	struct proto_tile pt = { .seq = e->seq, .planet_id = e->pid, .layer = e->layer,
				 .key = e->key };
	conn_put_tile(&s->c, et, &pt, s->parts ? linkest_part(&s->le) : 0);
	etile_unref(et);
	s->tiles_sent++;
	cnt->tiles_sent++;
}

/* The send window: output bytes this session may hold before the kernel takes them. */
static uint64_t window(const struct session *s)
{
	return linkest_window(&s->le, s->env->queue_ms, s->env->limits->max_pending);
}

/* What a session may have asked for and not yet sent (see the top): its held tiles, its
 * output window and as much again waiting in the cache. */
static uint64_t credit(const struct session *s)
{
	return 2 * s->env->limits->max_pending + window(s);
}

static bool has_room(const struct session *s)
{
	return wantset_nready(&s->ws) && conn_pending(&s->c) < window(s);
}

static bool unwanted(void *ud, const struct tile_key *k)
{
	const struct session *s = ud;
	return wantset_find(&s->ws, k) < 0;
}

/* Takes the TILE frames the kernel has not begun of keys the want-set no longer holds out of
 * the output (a new want-set: what the viewer left is not worth the link's time). */
static void recall_unwanted(struct session *s)
{
	if (!s->env->queue_ms)
		return; /* send_queue_ms 0: the queue as it was (bench_link's peer) */
	uint64_t bytes = 0;
	size_t n = conn_recall(&s->c, unwanted, s, &bytes);
	if (!n)
		return;
	s->env->counters->tiles_recalled += n;
	s->env->counters->bytes_recalled += bytes;
	s->env->counters->tiles_dropped += n; /* it left unsent after all */
	s->tiles_dropped += n;
	update_interest(s);
}

bool session_pump(struct session *s, size_t *budget)
{
	if (s->dead || s->closing)
		return false;
	struct session_counters *cnt = s->env->counters;
	uint64_t start = conn_pending(&s->c);
	size_t lim = *budget < PUMP_BUDGET ? *budget : PUMP_BUDGET;
	bool rewant = false;
	while (has_room(s) && conn_pending(&s->c) - start < lim) {
		struct wantset_entry *e = wantset_pop(&s->ws);
		if (!e)
			break;
		if (wantset_parked(e)) {
			struct tile *t = cache_lookup(s->env->cache, &e->key);
			if (!t) {
				/* the cache let it go meanwhile: the scheduler makes it again */
				wantset_rewant(&s->ws, e);
				cnt->tiles_rewanted++;
				rewant = true;
				continue;
			}
			wantset_unpark(&s->ws, e, t);
			cnt->tiles_relooked++;
		}
		encode_tile(s, e);
		s->sub_freed += wantset_entry_bytes(e);
		wantset_sent(&s->ws, e);
	}
	/* Sent tiles made room in the credit: ask for the next ones (by a quarter of it, so as
	 * not to give the scheduler a new list for every tile). */
	if (s->sub_left && s->sub_freed >= credit(s) / 4)
		rewant = true;
	if (rewant)
		submit_wants(s, 0, 0); /* when paused: resume_if_drained does it */
	resume_if_drained(s);
	pause_if_full(s);
	uint64_t made = conn_pending(&s->c) > start ? conn_pending(&s->c) - start : 0;
	*budget = made < *budget ? *budget - (size_t)made : 0;
	if (made && flush(s))
		return false;
	return has_room(s);
}

void session_on_encoded(struct session *s)
{
	if (s->dead)
		return;
	if (!flush(s) && has_room(s))
		pump_add(s);
}

void session_on_ready(struct session *s, struct ready_item *it)
{
	if (it->job) {
		if (!s->dead && control_job_ready(&s->ctl, it))
			flush(s);
		return;
	}
	if (s->dead || s->closing) {
		tile_unref(it->t);
		return;
	}
	bool parked;
	uint64_t max = s->env->limits->max_pending;
	if (wantset_ready(&s->ws, &it->key, it->t, it->err, it->parked, max, &parked)) {
		s->env->counters->tiles_parked += parked;
		pause_if_full(s); /* held tiles and output both full: make nothing more for now */
		pump_add(s);
	}
}

/* Runs on the scheduler's manager thread, possibly after the session closed: only hands the
 * report to the loop, marked with the session's handle (ud, a reference of the request's). */
static void sess_ready_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	ready_src_report(ud, &w->key, t, err);
}

/* The manager is done with the request: its reference on the handle goes. */
static void sess_req_fin(void *ud)
{
	ready_src_unref(ud);
}

/* A tile the cache holds costs nothing to make: asked for beyond the credit too. */
static bool in_cache(void *ud, const struct tile_key *k)
{
	return cache_contains(ud, k);
}

/* Gives the scheduler what is still wanted, within the credit (see the top); a failure is
 * reported as an ERROR referring to (ref_type, ref_id). */
static void submit_wants(struct session *s, uint16_t ref_type, uint32_t ref_id)
{
	if (s->paused)
		return; /* flush submits them when the output drains */
	size_t n;
	struct want *list =
		wantset_wants_within(&s->ws, credit(s), in_cache, s->env->cache, &n, &s->sub_left);
	s->sub_freed = 0;
	int rc = sched_req_want(s->req, list, n);
	free(list);
	if (rc)
		send_error(s, PROTO_E_INTERNAL, ref_type, ref_id, "scheduler: %s", strerror(-rc));
}

static void count_drops(struct session *s, const struct wantset_drops *d)
{
	s->tiles_dropped += d->dropped;
	s->env->counters->tiles_dropped += d->dropped;
	s->env->counters->tiles_stale += d->stale;
}

/* ---- handlers --------------------------------------------------------------------------- */

/* with_grid: the sea's surface grid too (OPENED; a PLANETS list leaves it out). */
static void fill_planet(const struct planet *p, struct proto_planet *out, struct proto_layer *ls,
			bool with_grid)
{
	for (size_t i = 0; i < p->nlayers; i++)
		ls[i] = (struct proto_layer){ .name = p->layers[i].name,
					      .format = (uint8_t)p->layers[i].type,
					      .node = p->layers[i].node->hash,
					      .normal_of = (uint8_t)(p->layers[i].normal_of + 1) };
	*out = (struct proto_planet){ .name = p->name, .description = p->description, .a = p->a,
				      .f = p->f, .tile_size = p->tile_size,
				      .max_level = (uint8_t)p->max_level,
				      .nlayers = (uint16_t)p->nlayers, .layers = ls,
				      .air_density = p->look.air_density,
				      .air_height = p->look.air_height,
				      .air_color = { p->look.air_color[0], p->look.air_color[1],
						     p->look.air_color[2] },
				      .sea = p->look.sea, .sea_level = p->look.sea_level,
				      .sea_mask = p->look.sea_mask };
	if (with_grid)
		out->sea_grid = p->look.sea_grid;
}

static void on_hello(struct session *s, const struct proto_hello *h)
{
	const struct session_env *env = s->env;
	if (h->ver_min > PROTO_VERSION || h->ver_max < PROTO_VERSION) {
		send_error(s, PROTO_E_VERSION, PROTO_HELLO, 0,
			   "client speaks versions %u-%u, this server speaks %u", h->ver_min,
			   h->ver_max, PROTO_VERSION);
		begin_close(s);
		return;
	}
	if (s->need_token) {
		/* Constant time in the token's content: every byte of ours is compared. */
		unsigned diff = h->token_len != env->token_len || !env->have_token;
		for (size_t i = 0; i < env->token_len; i++)
			diff |= env->token[i] ^ (i < h->token_len ? h->token[i] : 0u);
		if (diff) {
			send_error(s, PROTO_E_AUTH, PROTO_HELLO, 0,
				   h->token_len ? "wrong token" : "this listener requires a token");
			begin_close(s);
			return;
		}
	}
	if (env->authenticated(env->ud, s->link)) {
		send_error(s, PROTO_E_BUSY, PROTO_HELLO, 0,
			   "the server has as many sessions as it takes (max_sessions): try again "
			   "later");
		begin_close(s);
		return;
	}
	s->req = sched_req_create(env->sched, sess_ready_cb, ready_src_ref(s->src));
	s->ahead = sched_req_create(env->sched, ahead_ready_cb, NULL);
	/* Presented the token (required or not): prefetch limits of an authenticated client. */
	s->ctl.authed = s->need_token || control_token_ok(env, h);
	uint8_t codec = TCODEC_NONE;
	if (s->compress) {
		if (h->codecs & (1u << TCODEC_ZSTD))
			codec = TCODEC_ZSTD;
		else if (h->codecs & (1u << TCODEC_LZ4))
			codec = TCODEC_LZ4;
	}
	s->codec = codec;
	/* the lossy codecs too where the client offered them (encpick.h decides per tile) */
	struct encpick_policy pol = { .lossless = (enum tcodec)codec, .offered = h->codecs,
				      .lossy_below_bps = s->le.tcp ? env->lossy_below_bps : 0 };
	s->codecs = encpick_agreed(&pol);
	/* tiles in parts, where a new want-set may stop one: only over a measured link */
	s->parts = (h->codecs & PROTO_FEAT_PARTS) && s->le.tcp && env->queue_ms;
	s->st = PROTO_ST_READY;
	char nm[40];
	snprintf(s->name + strlen(s->name), sizeof s->name - strlen(s->name), " %s",
		 log_escape(nm, sizeof nm, h->name));
	struct proto_msg m = { .type = PROTO_HELLO_OK,
			       .hello_ok = { .version = PROTO_VERSION,
					     .codecs = s->codecs |
						       (s->parts ? PROTO_FEAT_PARTS : 0),
					     .session = s->id, .name = "clipmapd/0.1",
					     .limits = *env->limits } };
	send_msg(s, &m);
	/* the one info line of a session */
	log_msg(LOG_INFO, "session %llu (%s) from %s on %s: hello, codec %s%s",
		(unsigned long long)s->id, s->name, s->peer, s->l->name,
		tilecodec_codec_name((enum tcodec)codec),
		s->codecs & TCODEC_LOSSY_MASK ? " (lossy on slow links)" : "");
}

static void on_list(struct session *s, uint32_t req)
{
	const struct planet_set *ps = *s->env->planets;
	size_t n = ps->n > PROTO_MAX_PLANETS ? PROTO_MAX_PLANETS : ps->n;
	struct proto_planet *pl = xcalloc(n ? n : 1, sizeof *pl);
	struct proto_layer *ls = xcalloc(n * PROTO_MAX_LAYERS + 1, sizeof *ls);
	for (size_t i = 0; i < n; i++)
		fill_planet(ps->planets[i], &pl[i], ls + i * PROTO_MAX_LAYERS, false);
	struct proto_msg m = { .type = PROTO_PLANETS,
			       .planets = { .req = req, .count = (uint16_t)n, .planets = pl } };
	send_msg(s, &m);
	free(pl);
	free(ls);
}

static void on_open(struct session *s, const struct proto_open *o)
{
	struct planet_set *ps = *s->env->planets;
	struct planet *p = planet_set_find(ps, o->name);
	if (!p) {
		send_error(s, PROTO_E_NOT_FOUND, PROTO_OPEN, o->req, "no planet \"%s\"", o->name);
		return;
	}
	int id = 0, free_slot = 0;
	for (int i = 0; i < s->nopened; i++) {
		if (s->opened[i].p == p)
			id = i + 1;
		if (!s->opened[i].p && !free_slot)
			free_slot = i + 1;
	}
	if (!id) {
		if (!free_slot && s->nopened == MAX_OPEN) {
			send_error(s, PROTO_E_LIMIT, PROTO_OPEN, o->req,
				   "a session may open at most %d planets", MAX_OPEN);
			return;
		}
		id = free_slot ? free_slot : ++s->nopened;
		s->opened[id - 1] = (struct sopen){ .p = p, .set = planet_set_ref(ps) };
	}
	struct proto_layer ls[PROTO_MAX_LAYERS];
	struct proto_msg m = { .type = PROTO_OPENED,
			       .opened = { .req = o->req, .planet_id = (uint32_t)id } };
	fill_planet(p, &m.opened.planet, ls, true);
	send_msg(s, &m);
	log_msg(LOG_DEBUG, "session %llu (%s, %s): opened %s as %d", (unsigned long long)s->id,
		s->name, s->peer, p->name, id);
}

/* The protocol's class (validated by the decoder) as the scheduler's: their numbers differ
 * since the scheduler ranks web requests (SCHED_WEB) between visible and prefetch. */
static enum sched_class sched_class_of(uint8_t proto_cls)
{
	return proto_cls == PROTO_CLASS_VISIBLE	   ? SCHED_VISIBLE
	       : proto_cls == PROTO_CLASS_PREFETCH ? SCHED_PREFETCH
						   : SCHED_AHEAD; /* a viewer's, not an operator's */
}

/* Asks the scheduler, at the ahead class (into the memory cache, even from the store), for
 * the tiles this WANT's visible ones become along the focus's motion (lookahead.h); replaces the last look-ahead, so a turn or a stop cancels
 * what was queued for the old path. The velocity is the client's, else the focus's last
 * move. */
static void look_ahead(struct session *s, const struct proto_want *w, const struct planet *p,
		       double vel[2])
{
	uint64_t now = clock_now_ns();
	struct lookahead_motion m = { .lon = w->lon, .lat = w->lat, .ve = w->vel[0],
				      .vn = w->vel[1], .radius = p->a,
				      .tile_size = p->tile_size };
	if (m.ve == 0 && m.vn == 0 && s->has_focus &&
	    lookahead_velocity(s->lon, s->lat, w->lon, w->lat, (double)(now - s->focus_ns) * 1e-9,
			       p->a, &m.ve, &m.vn))
		m.ve = m.vn = 0;
	s->focus_ns = now;
	vel[0] = m.ve;
	vel[1] = m.vn;
	if (m.ve == 0 && m.vn == 0 && !s->nahead)
		return; /* still, and nothing ahead to cancel */
	struct proto_want_entry *ahead = xmalloc(LOOKAHEAD_MAX * sizeof *ahead);
	size_t n = lookahead_wants(&m, w->entries, w->count, ahead, LOOKAHEAD_MAX);
	struct want *list = n ? xmalloc(n * sizeof *list) : NULL;
	for (size_t i = 0; i < n; i++) {
		struct node *nd = p->layers[ahead[i].layer].node;
		list[i] = (struct want){ .node = nd, .cls = SCHED_AHEAD,
					 .key = { .node = nd->hash, .lx = ahead[i].lx,
						  .ly = ahead[i].ly, .x = ahead[i].x,
						  .y = ahead[i].y } };
	}
	/* a session holding still asks nothing of the scheduler (no manager work per WANT) */
	if ((n || s->nahead) && sched_req_want(s->ahead, list, n) == 0) {
		s->env->counters->ahead_wants += n;
		s->nahead = n;
	}
	free(list);
	free(ahead);
}

static void on_want(struct session *s, const struct proto_want *w)
{
	if (w->planet_id == 0 || w->planet_id > (uint32_t)s->nopened ||
	    !s->opened[w->planet_id - 1].p) {
		send_error(s, PROTO_E_NOT_FOUND, PROTO_WANT, w->seq, "planet id %u is not open",
			   w->planet_id);
		return;
	}
	const struct planet *p = s->opened[w->planet_id - 1].p;
	for (uint32_t i = 0; i < w->count; i++) {
		if (w->entries[i].layer >= p->nlayers) {
			send_error(s, PROTO_E_INVALID, PROTO_WANT, w->seq,
				   "entry %u: layer %u, but planet %s has %zu layers", i,
				   w->entries[i].layer, p->name, p->nlayers);
			return;
		}
	}
	if (s->capscratch < w->count) {
		s->capscratch = w->count;
		s->scratch = xrealloc(s->scratch, s->capscratch * sizeof *s->scratch);
	}
	for (uint32_t i = 0; i < w->count; i++) {
		const struct proto_want_entry *we = &w->entries[i];
		const struct planet_layer *L = &p->layers[we->layer];
		s->scratch[i] = (struct wantset_entry){
			.key = { .node = L->node->hash, .lx = we->lx, .ly = we->ly, .x = we->x,
				 .y = we->y },
			.node = L->node, .pid = w->planet_id, .seq = w->seq, .order = i,
			.layer = we->layer, .cls = (uint8_t)sched_class_of(we->cls)
		};
	}
	struct wantset_drops d = { 0 };
	wantset_replace(&s->ws, w->planet_id, s->scratch, w->count, &d);
	count_drops(s, &d);
	recall_unwanted(s);
	submit_wants(s, PROTO_WANT, w->seq);
	double vel[2];
	look_ahead(s, w, p, vel);
	s->has_focus = true;
	s->lon = w->lon;
	s->lat = w->lat;
	s->focus_a = p->a;
	/* the client's velocity, else the one the look-ahead estimated from the focus's moves:
	 * the cache keeps the tiles along the path (server.c update_foci) */
	s->vel[0] = vel[0];
	s->vel[1] = vel[1];
	s->vel[2] = w->vel[2];
	s->env->focus_changed(s->env->ud);
	if (wantset_nready(&s->ws))
		pump_add(s);
}

static void on_stats(struct session *s, uint32_t req)
{
	struct proto_stat *it = xcalloc(PROTO_MAX_STATS, sizeof *it);
	char(*keys)[128] = xcalloc(PROTO_MAX_STATS, sizeof *keys);
	size_t n = s->env->stats(s->env->ud, it, keys, PROTO_MAX_STATS);
	struct proto_msg m = { .type = PROTO_STATS,
			       .stats = { .req = req, .count = (uint16_t)n, .items = it } };
	send_msg(s, &m);
	free(it);
	free(keys);
}

/* ---- reload ----------------------------------------------------------------------------- */

/* Whether a session that opened `was` may go on with `now` under the same planet id and layer
 * indices; if not, why (for the ERROR). */
static bool compatible(const struct planet *was, const struct planet *now, char *why, size_t n)
{
	if (!now) {
		snprintf(why, n, "was removed by a reload");
		return false;
	}
	bool same = now->nlayers == was->nlayers && now->tile_size == was->tile_size;
	for (size_t i = 0; same && i < now->nlayers; i++)
		same = now->layers[i].type == was->layers[i].type;
	if (!same)
		snprintf(why, n, "changed its layers (count, formats or tile size) in a reload");
	return same;
}

/* wantset_resolve_fn: the node a layer of an opened planet reads from now. */
static struct node *resolve(void *ud, uint32_t pid, uint8_t layer)
{
	const struct session *s = ud;
	const struct planet *p = s->opened[pid - 1].p;
	return p ? p->layers[layer].node : NULL;
}

void session_reload(struct session *s, struct planet_set *ps)
{
	if (s->dead || s->closing)
		return;
	bool changed = false;
	for (int i = 0; i < s->nopened; i++) {
		struct sopen *o = &s->opened[i];
		if (!o->p || o->set == ps)
			continue;
		struct planet *np = planet_set_find(ps, o->p->name);
		char why[96];
		if (!compatible(o->p, np, why, sizeof why)) {
			send_error(s, PROTO_E_NOT_FOUND, PROTO_OPEN, (uint32_t)i + 1,
				   "planet \"%s\" (id %d) %s: its tiles are no longer sent; open it "
				   "again", o->p->name, i + 1, why);
			np = NULL;
		}
		retire(s, o->set);
		*o = (struct sopen){ .p = np, .set = np ? planet_set_ref(ps) : NULL };
		changed = true;
	}
	if (!changed)
		return;
	/* Same layer, the new planet's node: unchanged keys keep their state (sent tiles are not
	 * sent again), changed ones are wanted afresh, entries of dropped planets go. */
	struct wantset_drops d = { 0 };
	size_t regen = wantset_rebind(&s->ws, resolve, s, &d);
	count_drops(s, &d);
	submit_wants(s, 0, 0);
	log_msg(LOG_DEBUG, "session %llu (%s): rebound to planets generation %llu: %zu tiles "
		"wanted again", (unsigned long long)s->id, s->name,
		(unsigned long long)ps->generation, regen);
	if (wantset_nready(&s->ws))
		pump_add(s);
	flush(s);
}

/* ---- input ------------------------------------------------------------------------------ */

static uint32_t ref_of(const struct proto_msg *m)
{
	switch (m->type) {
	case PROTO_LIST_PLANETS: return m->list_planets.req;
	case PROTO_OPEN: return m->open.req;
	case PROTO_WANT: return m->want.seq;
	case PROTO_STATS_REQ: return m->stats_req.req;
	case PROTO_CACHE_LS: return m->cache_ls.req;
	case PROTO_PREFETCH: return m->prefetch.id;
	case PROTO_PREFETCH_CANCEL: return m->prefetch_cancel.req;
	case PROTO_PREFETCH_DRY: return m->prefetch_dry.id;
	case PROTO_CACHE_OP: return m->cache_op.req;
	default: return 0;
	}
}

/* Whether m may be handled now: the state machine, the message rate and the limits. */
static bool admit(struct session *s, const struct proto_msg *m, size_t frame_len)
{
	const struct proto_limits *lim = s->env->limits;
	char err[256];
	if (proto_check_state(s->st, false, m->type, err)) {
		send_error(s, PROTO_E_STATE, m->type, ref_of(m), "%s", err);
		begin_close(s);
		return false;
	}
	if (s->st == PROTO_ST_READY && lim->max_rate &&
	    !proto_rate_take(&s->rate, clock_now_ns(), lim->max_rate, lim->max_rate)) {
		if (++s->rate_viol > 4 * lim->max_rate + 16) {
			send_error(s, PROTO_E_LIMIT, m->type, ref_of(m),
				   "message rate stays above this session's limit of %u/s: closing",
				   lim->max_rate);
			begin_close(s);
		} else {
			send_error(s, PROTO_E_LIMIT, m->type, ref_of(m),
				   "message rate above this session's limit of %u/s: %s dropped",
				   lim->max_rate, proto_type_name(m->type));
		}
		return false;
	}
	s->rate_viol = 0;
	if (proto_check_limits(lim, m, frame_len, err)) {
		send_error(s, PROTO_E_LIMIT, m->type, ref_of(m), "%s", err);
		return false;
	}
	return true;
}

static void handle(struct session *s, const struct proto_msg *m, size_t frame_len)
{
	if (!admit(s, m, frame_len))
		return;
	switch (m->type) {
	case PROTO_HELLO: on_hello(s, &m->hello); break;
	case PROTO_BYE:
		s->st = PROTO_ST_CLOSED;
		begin_close(s);
		break;
	case PROTO_ERROR: {
		char esc[700];
		log_msg(LOG_INFO, "session %llu (%s, %s): client error %s: %s",
			(unsigned long long)s->id, s->name, s->peer,
			proto_code_name(m->error.code) ? proto_code_name(m->error.code) : "?",
			log_escape(esc, sizeof esc, m->error.message));
		break;
	}
	case PROTO_LIST_PLANETS: on_list(s, m->list_planets.req); break;
	case PROTO_OPEN: on_open(s, &m->open); break;
	case PROTO_WANT: on_want(s, &m->want); break;
	case PROTO_STATS_REQ: on_stats(s, m->stats_req.req); break;
	case PROTO_CACHE_LS: control_cache_ls(&s->ctl, &m->cache_ls); break;
	case PROTO_PREFETCH: control_prefetch(&s->ctl, &m->prefetch); break;
	case PROTO_PREFETCH_CANCEL: control_prefetch_cancel(&s->ctl, m->prefetch_cancel.req); break;
	case PROTO_PREFETCH_DRY: control_prefetch_dry(&s->ctl, &m->prefetch_dry); break;
	case PROTO_CACHE_OP: control_cache_op(&s->ctl, &m->cache_op); break;
	default:
		send_error(s, PROTO_E_STATE, m->type, 0, "%s is not a client message",
			   proto_type_name(m->type));
		begin_close(s);
	}
}

static void process_input(struct session *s)
{
	while (!s->closing && !s->dead && s->c.in.len) {
		struct proto_msg m = { 0 };
		uint16_t code = 0, type = 0;
		char err[256];
		ssize_t r = conn_decode(&s->c, s->st, s->env->limits->max_frame, &m, &code, &type,
					err);
		if (r < 0) {
			send_error(s, code, type, 0, "%s", err);
			begin_close(s);
			return;
		}
		if (r == 0) {
			/* a frame has begun: frame_timeout runs from now (not from its last byte) */
			if (!s->partial_ns)
				s->partial_ns = clock_now_ns();
			return;
		}
		handle(s, &m, (size_t)r);
		proto_msg_fini(&m);
		conn_consume(&s->c, (size_t)r);
		s->partial_ns = 0;
	}
}

static void on_readable(struct session *s)
{
	size_t got = 0;
	while (!s->dead && s->c.reading && got < READ_BUDGET) {
		ssize_t n = conn_recv(&s->c);
		if (n == -EAGAIN)
			break;
		if (n < 0) {
			char why[240];
			snprintf(why, sizeof why, "recv: %s", conn_strerror(&s->c, (int)n));
			session_close(s, why);
			return;
		}
		if (n == 0) {
			session_close(s, s->st == PROTO_ST_CLOSED ? NULL : "peer closed");
			return;
		}
		got += (size_t)n;
		process_input(s);
	}
	if (!s->dead)
		flush(s);
}

void session_on_event(struct session *s, uint32_t events)
{
	if (s->dead)
		return;
	if (events & (EPOLLIN | EPOLLRDHUP | EPOLLHUP | EPOLLERR)) {
		if (s->c.reading || !(events & EPOLLOUT))
			on_readable(s);
		if (!s->dead && (events & (EPOLLHUP | EPOLLERR)) && !(events & EPOLLIN)) {
			session_close(s, "connection reset");
			return;
		}
	}
	if (s->dead)
		return;
	if (events & EPOLLOUT) {
		if (flush(s))
			return;
		if (has_room(s))
			pump_add(s);
	}
}

/* ---- lifecycle -------------------------------------------------------------------------- */

/* Who is at the other end of fd, for the logs: "ADDR:PORT" ("[ADDR]:PORT" for IPv6) for
 * TCP, "unix" (with the peer's pid and uid when the kernel tells them) for a Unix socket. */
static void peer_name(int fd, char *out, size_t n)
{
	struct sockaddr_storage ss;
	socklen_t len = sizeof ss;
	char host[INET6_ADDRSTRLEN] = "?";
	snprintf(out, n, "unknown peer");
	if (getpeername(fd, (struct sockaddr *)&ss, &len) != 0)
		return;
	if (ss.ss_family == AF_INET) {
		const struct sockaddr_in *a = (const struct sockaddr_in *)&ss;
		inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
		snprintf(out, n, "%s:%u", host, (unsigned)ntohs(a->sin_port));
	} else if (ss.ss_family == AF_INET6) {
		const struct sockaddr_in6 *a = (const struct sockaddr_in6 *)&ss;
		inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
		snprintf(out, n, "[%s]:%u", host, (unsigned)ntohs(a->sin6_port));
	} else if (ss.ss_family == AF_UNIX) {
		struct ucred cr;
		socklen_t cl = sizeof cr;
		if (getsockopt(fd, SOL_SOCKET, SO_PEERCRED, &cr, &cl) == 0)
			snprintf(out, n, "unix pid %ld uid %lu", (long)cr.pid, (unsigned long)cr.uid);
		else
			snprintf(out, n, "unix");
	}
}

struct session *session_create(const struct session_env *env, int fd, const struct listener *l)
{
	struct session *s = xcalloc(1, sizeof *s);
	s->env = env;
	conn_init(&s->c, fd);
	s->need_token = l->need_token;
	s->compress = l->compress;
	snprintf(s->name, sizeof s->name, "%s", l->is_unix ? "unix" : l->tls ? "tls" : "tcp");
	s->l = l;
	s->born_ns = clock_now_ns();
	s->link = (l->tls && conn_start_tls(&s->c, l->tls)) ? NULL
							  : env->attach(env->ud, s, fd, &s->id);
	if (!s->link) {
		conn_close(&s->c);
		conn_fini(&s->c);
		free(s);
		return NULL;
	}
	wantset_init(&s->ws);
	struct control_host host = { .s = s, .id = s->id, .send = send_msg, .error = ctl_error };
	control_init(&s->ctl, env, &host);
	s->src = ready_src_new(env->ready, s);
	s->src->queue_cap = env->limits->max_pending;
	/* The scheduler request comes with the handshake (on_hello): closing a connection that
	 * never authenticated involves no other thread. */
	peer_name(fd, s->peer, sizeof s->peer);
	linkest_init(&s->le, fd, !l->is_unix, env->queue_ms > 0, env->bbr, s->born_ns);
	log_msg(LOG_DEBUG, "session %llu: connected on %s from %s", (unsigned long long)s->id,
		l->name, s->peer);
	return s;
}

void session_tick(struct session *s, uint64_t now_ns)
{
	if (s->dead)
		return;
	if (s->closing) {
		if (now_ns > s->close_deadline)
			session_close(s, "close timed out (peer not reading)");
		return;
	}
	const struct session_env *env = s->env;
	if (s->st == PROTO_ST_HANDSHAKE && now_ns - s->born_ns > env->handshake_ns) {
		send_error(s, PROTO_E_LIMIT, 0, 0, "no HELLO within %llu s (handshake_timeout): "
			   "closing", (unsigned long long)(env->handshake_ns / 1000000000u));
		begin_close(s);
		return;
	}
	if (!s->c.reading && s->partial_ns)
		s->partial_ns = now_ns; /* our output backpressure, not the peer's slowness */
	if (s->partial_ns && now_ns - s->partial_ns > env->frame_ns) {
		send_error(s, PROTO_E_LIMIT, 0, 0, "a frame begun %llu s ago has not arrived "
			   "(frame_timeout): closing",
			   (unsigned long long)((now_ns - s->partial_ns) / 1000000000u));
		begin_close(s);
		return;
	}
	linkest_sample(&s->le, now_ns, true); /* the STATS figures stay current when idle */
	if (control_tick(&s->ctl, now_ns))
		flush(s);
}

void session_shutdown(struct session *s)
{
	if (s->dead || s->closing)
		return;
	control_cancel_all(&s->ctl);
	if (s->st == PROTO_ST_READY)
		send_error(s, PROTO_E_SHUTDOWN, 0, 0, "server shutting down");
	struct proto_msg bye = { .type = PROTO_BYE };
	send_msg(s, &bye);
	begin_close(s);
}

void session_close(struct session *s, const char *why)
{
	if (s->dead)
		return;
	const struct session_env *env = s->env;
	s->dead = true;
	control_stop(&s->ctl);
	s->src->dead = true; /* reports still on their way are dropped (server's on_ready) */
	sched_req_release(s->req, sess_req_fin); /* NULL (never authenticated): nothing */
	s->req = NULL;
	sched_req_release(s->ahead, NULL);
	s->ahead = NULL;
	readyq_purge(env->ready, s);
	env->detach(env->ud, s->link);
	int rc = conn_close(&s->c);
	if (rc)
		log_msg(LOG_WARN, "session %llu: close: %s", (unsigned long long)s->id,
			strerror(-rc));
	log_msg(LOG_DEBUG, "session %llu (%s, %s): closed%s%s; %llu tiles sent, %llu dropped",
		(unsigned long long)s->id, s->name, s->peer, why ? ": " : "", why ? why : "",
		(unsigned long long)s->tiles_sent, (unsigned long long)s->tiles_dropped);
	env->focus_changed(env->ud);
}

void session_free(struct session *s)
{
	if (!s)
		return;
	wantset_fini(&s->ws);
	ready_src_unref(s->src);
	free(s->scratch);
	control_fini(&s->ctl);
	for (int i = 0; i < s->nopened; i++)
		planet_set_unref(s->opened[i].set);
	for (size_t i = 0; i < s->nretired; i++)
		planet_set_unref(s->retired[i]);
	free(s->retired);
	conn_fini(&s->c);
	free(s);
}

bool session_focus(const struct session *s, double *lon, double *lat, double vel[3],
		   double *radius)
{
	if (!s->has_focus || s->dead)
		return false;
	*lon = s->lon;
	*lat = s->lat;
	*radius = s->focus_a;
	memcpy(vel, s->vel, sizeof s->vel);
	return true;
}

void session_get_load(const struct session *s, struct session_load *out)
{
	const struct linkest *le = &s->le;
	uint64_t q = conn_pending(&s->c) + le->notsent;
	*out = (struct session_load){ .pending_bytes = conn_pending(&s->c),
				      .out_bytes = s->c.owned,
				      .held_bytes = wantset_held(&s->ws),
				      .paused = s->paused,
				      .ready_tiles = wantset_nready(&s->ws),
				      .jobs = s->ctl.njobs,
				      .tcp = le->tcp, .rate = le->rate,
				      .rtt_ms = le->rtt_us * 1e-3, .min_rtt_ms = le->min_rtt_us * 1e-3,
				      .window = window(s), .queue_bytes = q,
				      .queue_ms = linkest_delay_ms(le, q), .inflight = le->unacked,
				      .id = s->id, .peer = s->peer };
}
