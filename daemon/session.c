/* session — see session.h. Design note: a session owns one scheduler request for its want-set
 * (all planets it opened, concatenated) and one per prefetch job. Ready reports come back
 * through the server's queue as (session, job, key, tile); the want-set's hash table says
 * whether the key is still wanted, the heap orders what waits for output room. Output is one
 * growable buffer with a read offset; TILE frames are encoded straight into it (header space
 * reserved, payload encoded after it, header written last) so a tile is copied once.
 * A closed session goes to the server's graveyard and is freed at the end of the loop
 * iteration, so pointers in the current epoll batch or ready batch never dangle.
 */
#include "session.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "common/log.h"
#include "prefetch.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"

#define MAX_OPEN 16	       /* planets per session */
#define PUMP_BUDGET (4u << 20) /* output bytes produced per pump call (fairness) */
#define READ_BUDGET (1u << 20) /* input bytes read per event */
#define CLOSE_GRACE_NS 2000000000ull
#define CACHE_LS_DEFAULT 10000u
#define CACHE_LS_MAX (1u << 20)

enum went_state { W_WANTED = 0, W_READY, W_SENT };

struct went {
	struct tile_key key;
	struct node *node;
	struct tile *t; /* W_READY: owned reference (NULL when err < 0) */
	int err;
	uint32_t pid, seq, order;
	uint8_t layer, cls, state;
};

struct wset {
	struct went *e;
	size_t n, cap;
	uint32_t *tab; /* open addressing: index + 1, 0 empty */
	size_t tcap;   /* power of two */
};

struct sopen {
	struct planet *p;	/* NULL: dropped by a reload (the id may be given again) */
	struct planet_set *set; /* reference keeping p alive; NULL with p */
};

struct session {
	struct evsrc ev;
	struct server *srv;
	int fd;
	uint64_t id;
	char name[64];
	bool need_token, compress, is_unix;
	enum proto_state st;
	bool closing, dead, reading, want_out, in_pump;
	uint64_t close_deadline;
	struct session *prev, *next, *pump_next, *grave_next;

	struct pbuf in, out;
	size_t out_off;
	struct proto_rate rate;
	uint32_t rate_viol;
	uint8_t codec;

	struct sopen opened[MAX_OPEN];
	int nopened;
	/* Sets this session's earlier want lists named nodes of: the scheduler may still be
	 * working on them after a reload rebinds the session, so they live as long as it. */
	struct planet_set **retired;
	size_t nretired;

	struct wset ws;
	uint32_t *heap;
	size_t nheap, capheap;
	struct sched_req *req;
	bool has_focus;
	double lon, lat, vel[3];

	struct prefetch_job **jobs;
	struct planet_set **jobsets; /* jobsets[i]: reference keeping jobs[i]'s planet alive */
	size_t njobs;

	uint64_t tiles_sent, tiles_dropped;
};

/* ---- want-set table ------------------------------------------------------------------- */

static size_t wslot(const struct wset *w, const struct tile_key *k)
{
	return (size_t)grid_key_hash(k) & (w->tcap - 1);
}

static long wset_find(const struct wset *w, const struct tile_key *k)
{
	if (!w->tcap)
		return -1;
	for (size_t i = wslot(w, k);; i = (i + 1) & (w->tcap - 1)) {
		uint32_t v = w->tab[i];
		if (!v)
			return -1;
		if (grid_key_equal(&w->e[v - 1].key, k))
			return (long)(v - 1);
	}
}

/* Appends e unless its key is present (then returns false). The table must have room. */
static bool wset_add(struct wset *w, const struct went *e)
{
	size_t i = wslot(w, &e->key);
	for (; w->tab[i]; i = (i + 1) & (w->tcap - 1))
		if (grid_key_equal(&w->e[w->tab[i] - 1].key, &e->key))
			return false;
	if (w->n == w->cap) {
		w->cap = w->cap ? w->cap * 2 : 64;
		w->e = xrealloc(w->e, w->cap * sizeof *w->e);
	}
	w->e[w->n] = *e;
	w->tab[i] = (uint32_t)++w->n;
	return true;
}

static void wset_reserve_table(struct wset *w, size_t n)
{
	size_t need = 16;
	while (need < n * 2 + 2)
		need *= 2;
	free(w->tab);
	w->tab = xcalloc(need, sizeof *w->tab);
	w->tcap = need;
}

/* ---- ready heap ------------------------------------------------------------------------ */

static uint64_t prio(const struct went *e)
{
	return (uint64_t)e->cls << 56 | (uint64_t)e->key.ly << 48 | (uint64_t)e->key.lx << 40 |
	       e->order;
}

static void heap_push(struct session *s, uint32_t idx)
{
	if (s->nheap == s->capheap) {
		s->capheap = s->capheap ? s->capheap * 2 : 64;
		s->heap = xrealloc(s->heap, s->capheap * sizeof *s->heap);
	}
	size_t i = s->nheap++;
	uint64_t p = prio(&s->ws.e[idx]);
	while (i > 0) {
		size_t up = (i - 1) / 2;
		if (prio(&s->ws.e[s->heap[up]]) <= p)
			break;
		s->heap[i] = s->heap[up];
		i = up;
	}
	s->heap[i] = idx;
}

static uint32_t heap_pop(struct session *s)
{
	uint32_t top = s->heap[0];
	uint32_t last = s->heap[--s->nheap];
	size_t i = 0, n = s->nheap;
	uint64_t p = n ? prio(&s->ws.e[last]) : 0;
	for (;;) {
		size_t c = 2 * i + 1;
		if (c >= n)
			break;
		if (c + 1 < n && prio(&s->ws.e[s->heap[c + 1]]) < prio(&s->ws.e[s->heap[c]]))
			c++;
		if (prio(&s->ws.e[s->heap[c]]) >= p)
			break;
		s->heap[i] = s->heap[c];
		i = c;
	}
	if (n)
		s->heap[i] = last;
	return top;
}

/* ---- output ----------------------------------------------------------------------------- */

uint64_t session_pending_bytes(const struct session *s)
{
	return s->out.len - s->out_off;
}

static void update_epoll(struct session *s)
{
	if (s->dead)
		return;
	struct epoll_event ev = { .events = (s->reading ? EPOLLIN | EPOLLRDHUP : 0) |
					    (s->want_out ? EPOLLOUT : 0),
				  .data.ptr = &s->ev };
	if (epoll_ctl(s->srv->epfd, EPOLL_CTL_MOD, s->fd, &ev))
		log_msg(LOG_WARN, "session %llu: epoll_ctl: %s", (unsigned long long)s->id,
			strerror(errno));
}

static void pump_add(struct session *s)
{
	if (s->in_pump || s->dead)
		return;
	s->in_pump = true;
	s->pump_next = s->srv->pump;
	s->srv->pump = s;
}

struct session *session_pump_next(struct session *s)
{
	struct session *next = s->pump_next;
	s->pump_next = NULL;
	s->in_pump = false;
	return next;
}

void session_pump_readd(struct session *s)
{
	pump_add(s);
}

/* Writes what it can. Returns 0, or -errno after closing the session. */
static int flush(struct session *s)
{
	bool was_out = s->want_out, was_reading = s->reading;
	while (s->out_off < s->out.len) {
		ssize_t n = send(s->fd, s->out.data + s->out_off, s->out.len - s->out_off,
				 MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			if (errno == EAGAIN || errno == EWOULDBLOCK)
				break;
			int e = -errno;
			char why[96];
			snprintf(why, sizeof why, "send: %s", strerror(-e));
			session_close(s, why);
			return e;
		}
		s->out_off += (size_t)n;
		s->srv->bytes_sent += (uint64_t)n;
	}
	if (s->out_off == s->out.len) {
		s->out.len = s->out_off = 0;
	} else if (s->out_off > (1u << 20) && s->out_off > s->out.len / 2) {
		memmove(s->out.data, s->out.data + s->out_off, s->out.len - s->out_off);
		s->out.len -= s->out_off;
		s->out_off = 0;
	}
	s->want_out = s->out_off < s->out.len;
	uint64_t pend = session_pending_bytes(s);
	if (s->closing) {
		if (!s->want_out) {
			session_close(s, NULL);
			return -EPIPE;
		}
	} else if (!s->reading && pend < s->srv->limits.max_pending) {
		s->reading = true; /* resume input once the client reads again */
	} else if (s->reading && pend > 2 * s->srv->limits.max_pending) {
		s->reading = false;
	}
	if (was_out != s->want_out || was_reading != s->reading)
		update_epoll(s);
	return 0;
}

static void send_msg(struct session *s, const struct proto_msg *m)
{
	char err[256];
	ssize_t n = proto_encode(&s->out, m, err);
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
	s->srv->errors_sent++;
	log_msg(code == PROTO_E_SHUTDOWN ? LOG_DEBUG : LOG_INFO, "session %llu (%s): error %s: %s",
		(unsigned long long)s->id, s->name, proto_code_name(code), msg);
}

static void begin_close(struct session *s)
{
	if (s->closing || s->dead)
		return;
	s->closing = true;
	s->reading = false;
	s->close_deadline = server_now_ns() + CLOSE_GRACE_NS;
	if (s->req)
		(void)sched_req_want(s->req, NULL, 0);
	update_epoll(s);
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

/* ---- tiles ---------------------------------------------------------------------------- */

static void encode_tile(struct session *s, struct went *e)
{
	struct server *srv = s->srv;
	if (!e->t) {
		char msg[200];
		snprintf(msg, sizeof msg, "tile %u/%u/%u/%u: %s", e->key.lx, e->key.ly, e->key.x,
			 e->key.y, strerror(-e->err));
		struct proto_msg m = { .type = PROTO_TILE_FAIL,
				       .tile_fail = { .seq = e->seq, .planet_id = e->pid,
						      .layer = e->layer, .key = e->key,
						      .code = PROTO_E_UNAVAILABLE, .message = msg } };
		send_msg(s, &m);
		srv->tiles_failed++;
		return;
	}
	const struct tile *t = e->t;
	enum pix_type fmt = t->type;
	enum tcodec codec = (enum tcodec)s->codec;
	enum tfilter filt = codec == TCODEC_NONE ? TFILTER_NONE : tilecodec_default_filter(fmt);
	size_t bound = tilecodec_bound(codec, t->nbytes);
	size_t head = PROTO_HDR + 44;
	if (pbuf_reserve(&s->out, head + bound))
		return;
	uint8_t *at = s->out.data + s->out.len;
	struct proto_tile pt = { .seq = e->seq, .planet_id = e->pid, .layer = e->layer,
				 .key = e->key };
	ssize_t n = tilecodec_encode(srv->codec, fmt, t->size, codec, filt, 1, t->data, &pt.enc,
				     at + head, bound);
	char err[256];
	if (n >= 0) {
		pt.payload = at + head;
		pt.payload_len = (uint32_t)n;
		struct pbuf hb;
		pbuf_init_fixed(&hb, at, head);
		ssize_t h = proto_encode_tile_head(&hb, &pt, err);
		if (h == (ssize_t)head) {
			s->out.len += head + (size_t)n;
			s->tiles_sent++;
			srv->tiles_sent++;
			return;
		}
		n = h < 0 ? h : -EINVAL;
	} else {
		snprintf(err, sizeof err, "%s", strerror((int)-n));
	}
	log_msg(LOG_ERROR, "session %llu: cannot encode tile %u/%u/%u/%u: %s",
		(unsigned long long)s->id, e->key.lx, e->key.ly, e->key.x, e->key.y, err);
}

bool session_pump(struct session *s)
{
	if (s->dead || s->closing)
		return false;
	uint64_t max = s->srv->limits.max_pending;
	size_t start = s->out.len;
	while (s->nheap && session_pending_bytes(s) < max && s->out.len - start < PUMP_BUDGET) {
		struct went *e = &s->ws.e[heap_pop(s)];
		if (e->state != W_READY)
			continue;
		encode_tile(s, e);
		e->state = W_SENT;
		tile_unref(e->t);
		e->t = NULL;
	}
	if (s->out.len != start && flush(s))
		return false;
	return s->nheap && session_pending_bytes(s) < max;
}

static void on_job_ready(struct session *s, struct ready_item *it);

void session_on_ready(struct session *s, struct ready_item *it)
{
	if (it->job) {
		on_job_ready(s, it);
		return;
	}
	long i = s->dead || s->closing ? -1 : wset_find(&s->ws, &it->key);
	if (i < 0 || s->ws.e[i].state != W_WANTED) {
		tile_unref(it->t); /* left the want-set, or a repeated report */
		return;
	}
	struct went *e = &s->ws.e[i];
	e->state = W_READY;
	e->t = it->t;
	e->err = it->err;
	heap_push(s, (uint32_t)i);
	pump_add(s);
}

static void sess_ready_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	struct session *s = ud;
	struct ready_item it = { .s = s, .key = w->key, .t = t ? tile_ref(t) : NULL, .err = err };
	server_ready_push(s->srv, &it);
}

static void job_ready_cb(void *ud, const struct want *w, struct tile *t, int err)
{
	struct prefetch_job *j = ud;
	struct session *s = j->owner;
	(void)t;
	struct ready_item it = { .s = s, .job = j, .key = w->key, .err = err };
	server_ready_push(s->srv, &it);
}

/* ---- handlers --------------------------------------------------------------------------- */

static void fill_planet(const struct planet *p, struct proto_planet *out, struct proto_layer *ls)
{
	for (size_t i = 0; i < p->nlayers; i++)
		ls[i] = (struct proto_layer){ .name = p->layers[i].name,
					      .format = (uint8_t)p->layers[i].type,
					      .node = p->layers[i].node->hash };
	*out = (struct proto_planet){ .name = p->name, .description = p->description, .a = p->a,
				      .f = p->f, .tile_size = p->tile_size,
				      .max_level = (uint8_t)p->max_level,
				      .nlayers = (uint16_t)p->nlayers, .layers = ls,
				      .air_density = p->look.air_density,
				      .air_height = p->look.air_height,
				      .air_color = { p->look.air_color[0], p->look.air_color[1],
						     p->look.air_color[2] },
				      .sea = p->look.sea, .sea_level = p->look.sea_level };
}

static void on_hello(struct session *s, const struct proto_hello *h)
{
	struct server *srv = s->srv;
	if (h->ver_min > PROTO_VERSION || h->ver_max < PROTO_VERSION) {
		send_error(s, PROTO_E_VERSION, PROTO_HELLO, 0,
			   "client speaks versions %u-%u, this server speaks %u", h->ver_min,
			   h->ver_max, PROTO_VERSION);
		begin_close(s);
		return;
	}
	if (s->need_token) {
		/* Constant time in the token's content: every byte of ours is compared. */
		unsigned diff = h->token_len != srv->token_len || !srv->have_token;
		for (size_t i = 0; i < srv->token_len; i++)
			diff |= srv->token[i] ^ (i < h->token_len ? h->token[i] : 0u);
		if (diff) {
			send_error(s, PROTO_E_AUTH, PROTO_HELLO, 0,
				   h->token_len ? "wrong token" : "this listener requires a token");
			begin_close(s);
			return;
		}
	}
	uint8_t codec = TCODEC_NONE;
	if (s->compress) {
		if (h->codecs & (1u << TCODEC_ZSTD))
			codec = TCODEC_ZSTD;
		else if (h->codecs & (1u << TCODEC_LZ4))
			codec = TCODEC_LZ4;
	}
	s->codec = codec;
	s->st = PROTO_ST_READY;
	snprintf(s->name + strlen(s->name), sizeof s->name - strlen(s->name), " %.20s",
		 h->name ? h->name : "");
	struct proto_msg m = { .type = PROTO_HELLO_OK,
			       .hello_ok = { .version = PROTO_VERSION,
					     .codecs = codec ? 1u << codec : 0,
					     .session = s->id, .name = "clipmapd/0.1",
					     .limits = srv->limits } };
	send_msg(s, &m);
	log_msg(LOG_INFO, "session %llu (%s): hello, codec %s", (unsigned long long)s->id, s->name,
		tilecodec_codec_name((enum tcodec)codec));
}

static void on_list(struct session *s, uint32_t req)
{
	const struct planet_set *ps = s->srv->planets;
	size_t n = ps->n > PROTO_MAX_PLANETS ? PROTO_MAX_PLANETS : ps->n;
	struct proto_planet *pl = xcalloc(n ? n : 1, sizeof *pl);
	struct proto_layer *ls = xcalloc(n * PROTO_MAX_LAYERS + 1, sizeof *ls);
	for (size_t i = 0; i < n; i++)
		fill_planet(ps->planets[i], &pl[i], ls + i * PROTO_MAX_LAYERS);
	struct proto_msg m = { .type = PROTO_PLANETS,
			       .planets = { .req = req, .count = (uint16_t)n, .planets = pl } };
	send_msg(s, &m);
	free(pl);
	free(ls);
}

static void on_open(struct session *s, const struct proto_open *o)
{
	struct planet *p = planet_set_find(s->srv->planets, o->name);
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
		s->opened[id - 1] = (struct sopen){ .p = p, .set = planet_set_ref(s->srv->planets) };
	}
	struct proto_layer ls[PROTO_MAX_LAYERS];
	struct proto_msg m = { .type = PROTO_OPENED,
			       .opened = { .req = o->req, .planet_id = (uint32_t)id } };
	fill_planet(p, &m.opened.planet, ls);
	send_msg(s, &m);
	log_msg(LOG_DEBUG, "session %llu: opened %s as %d", (unsigned long long)s->id, p->name, id);
}

static int submit_wants(struct session *s);

/* Makes nw the session's want-set (the old one's entries already moved or released) and
 * submits it; a scheduler failure is reported as an ERROR referring to (ref_type, ref_id). */
static void install_wants(struct session *s, struct wset *old, struct wset nw, uint16_t ref_type,
			  uint32_t ref_id)
{
	free(old->e);
	free(old->tab);
	s->ws = nw;
	int rc = submit_wants(s);
	if (rc)
		send_error(s, PROTO_E_INTERNAL, ref_type, ref_id, "scheduler: %s", strerror(-rc));
}

/* Rebuilds the ready heap from the want-set and gives the scheduler what is still wanted.
 * Returns sched_req_want's result. */
static int submit_wants(struct session *s)
{
	const struct wset *w = &s->ws;
	s->nheap = 0;
	size_t nwant = 0;
	for (size_t i = 0; i < w->n; i++) {
		if (w->e[i].state == W_READY)
			heap_push(s, (uint32_t)i);
		nwant += w->e[i].state == W_WANTED;
	}
	struct want *list = xmalloc((nwant ? nwant : 1) * sizeof *list);
	size_t k = 0;
	for (size_t i = 0; i < w->n; i++)
		if (w->e[i].state == W_WANTED)
			list[k++] = (struct want){ .node = w->e[i].node, .key = w->e[i].key,
						   .cls = (enum sched_class)w->e[i].cls };
	int rc = sched_req_want(s->req, list, k);
	free(list);
	return rc;
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

	/* The new set: other planets' entries as they are, then this WANT's, carrying the state
	 * of entries that stay. */
	struct wset old = s->ws, nw = { 0 };
	size_t total = w->count;
	for (size_t i = 0; i < old.n; i++)
		total += old.e[i].pid != w->planet_id;
	wset_reserve_table(&nw, total);
	for (size_t i = 0; i < old.n; i++)
		if (old.e[i].pid != w->planet_id)
			wset_add(&nw, &old.e[i]);
	for (uint32_t i = 0; i < w->count; i++) {
		const struct proto_want_entry *we = &w->entries[i];
		const struct planet_layer *L = &p->layers[we->layer];
		struct went e = { .key = { .node = L->node->hash, .lx = we->lx, .ly = we->ly,
					   .x = we->x, .y = we->y },
				  .node = L->node, .pid = w->planet_id, .seq = w->seq, .order = i,
				  .layer = we->layer, .cls = we->cls };
		long oi = wset_find(&old, &e.key);
		if (oi >= 0 && old.e[oi].pid == w->planet_id) {
			struct went *o = &old.e[oi];
			if (o->state == W_SENT) {
				e.state = W_SENT;
			} else if (o->state == W_READY) {
				e.state = W_READY;
				e.t = o->t;
				e.err = o->err;
			}
		}
		if (wset_add(&nw, &e) && oi >= 0 && old.e[oi].pid == w->planet_id)
			old.e[oi].state = 0xff; /* moved */
	}
	/* What left the set unsent is dropped (and freed when it was ready). */
	for (size_t i = 0; i < old.n; i++) {
		struct went *o = &old.e[i];
		if (o->pid != w->planet_id || o->state == 0xff || o->state == W_SENT)
			continue;
		if (o->state == W_READY) {
			tile_unref(o->t);
			s->srv->tiles_stale++;
		}
		s->tiles_dropped++;
		s->srv->tiles_dropped++;
	}
	install_wants(s, &old, nw, PROTO_WANT, w->seq);
	s->has_focus = true;
	s->lon = w->lon;
	s->lat = w->lat;
	memcpy(s->vel, w->vel, sizeof s->vel);
	server_update_foci(s->srv);
	if (s->nheap)
		pump_add(s);
}

/* -- reload -- */

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

	/* Re-resolve the want-set: same layer, the new planet's node. A key whose node hash did
	 * not change keeps its state (sent tiles are not sent again); a changed one is wanted
	 * afresh under its new key. Entries of dropped planets go. */
	struct wset old = s->ws, nw = { 0 };
	wset_reserve_table(&nw, old.n);
	size_t regen = 0;
	for (size_t i = 0; i < old.n; i++) {
		struct went e = old.e[i];
		const struct planet *p = s->opened[e.pid - 1].p;
		struct node *nd = p ? p->layers[e.layer].node : NULL;
		bool keep = nd != NULL;
		if (keep && nd->hash != e.key.node) {
			if (e.state == W_READY) {
				tile_unref(e.t);
				s->srv->tiles_stale++;
			}
			e.key.node = nd->hash;
			e.state = W_WANTED;
			e.t = NULL;
			e.err = 0;
			regen++;
		}
		e.node = nd;
		if (keep && wset_add(&nw, &e))
			continue;
		if (e.state == W_READY) /* dropped (or a duplicate key) */
			tile_unref(e.t);
		if (e.state != W_SENT) {
			s->tiles_dropped++;
			s->srv->tiles_dropped++;
		}
	}
	install_wants(s, &old, nw, 0, 0);
	log_msg(LOG_DEBUG, "session %llu (%s): rebound to planets generation %llu: %zu tiles "
		"wanted again", (unsigned long long)s->id, s->name,
		(unsigned long long)ps->generation, regen);
	if (s->nheap)
		pump_add(s);
	flush(s);
}

/* -- STATS -- */

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

static void on_stats(struct session *s, uint32_t req)
{
	struct server *srv = s->srv;
	struct statb b = { .cap = PROTO_MAX_STATS };
	b.it = xcalloc(b.cap, sizeof *b.it);
	b.keys = xcalloc(b.cap, sizeof *b.keys);
	struct sched_stats ss;
	struct cache_stats cs;
	sched_get_stats(srv->sched, &ss);
	cache_stats(srv->cache, &cs);
	stat_f(&b, "uptime_s", (double)(server_now_ns() - srv->start_ns) * 1e-9);
	stat_u(&b, "sessions", srv->nsessions);
	stat_u(&b, "sessions.total", srv->sessions_total);
	stat_u(&b, "sched.queued.visible", ss.queued[SCHED_VISIBLE]);
	stat_u(&b, "sched.queued.prefetch", ss.queued[SCHED_PREFETCH]);
	stat_u(&b, "sched.queued.bulk", ss.queued[SCHED_BULK]);
	stat_u(&b, "sched.waiting", ss.waiting);
	stat_u(&b, "sched.workers", (uint64_t)ss.workers);
	stat_u(&b, "sched.workers.busy", ss.running);
	stat_u(&b, "sched.generated", ss.generated);
	stat_u(&b, "sched.merged", ss.merged);
	stat_u(&b, "sched.cancelled", ss.cancelled);
	stat_u(&b, "sched.failed", ss.failed);
	stat_u(&b, "cache.bytes", cs.bytes);
	stat_u(&b, "cache.budget", cs.budget);
	stat_u(&b, "cache.tiles", cs.tiles);
	stat_u(&b, "cache.hits", cs.hits);
	stat_u(&b, "cache.misses", cs.misses);
	stat_u(&b, "cache.inserts", cs.inserts);
	stat_u(&b, "cache.evictions", cs.evictions);
	stat_u(&b, "tiles.sent", srv->tiles_sent);
	stat_u(&b, "tiles.failed", srv->tiles_failed);
	stat_u(&b, "tiles.dropped", srv->tiles_dropped);
	stat_u(&b, "tiles.stale", srv->tiles_stale);
	stat_u(&b, "bytes.sent", srv->bytes_sent);
	stat_u(&b, "errors.sent", srv->errors_sent);
	stat_u(&b, "planets", srv->planets->n);
	stat_u(&b, "planets.generation", srv->planets->generation);
	uint64_t njobs = 0, pend = 0, pend_max = 0, ready = 0;
	for (struct session *t = srv->sessions; t; t = t->next) {
		njobs += t->njobs;
		uint64_t p = session_pending_bytes(t);
		pend += p;
		pend_max = p > pend_max ? p : pend_max;
		ready += t->nheap;
	}
	stat_u(&b, "sessions.pending_bytes", pend);
	stat_u(&b, "sessions.pending_bytes.max", pend_max);
	stat_u(&b, "sessions.ready_tiles", ready);
	stat_u(&b, "prefetch.jobs", njobs);
	for (size_t i = 0; i < srv->planets->n; i++) {
		const struct planet *p = srv->planets->planets[i];
		for (size_t j = 0; j < p->nnodes; j++) {
			const struct node *n = p->nodes[j];
			uint64_t g = atomic_load(&n->generated), ns = atomic_load(&n->gen_ns);
			struct proto_stat *st = stat_add(&b, "node.%s.%s.generated", p->name, n->name);
			if (st) {
				st->kind = PROTO_STAT_U64;
				st->u = g;
			}
			st = stat_add(&b, "node.%s.%s.mean_ms", p->name, n->name);
			if (st) {
				st->kind = PROTO_STAT_F64;
				st->f = g ? (double)ns / (double)g * 1e-6 : 0.0;
			}
		}
	}
	struct proto_msg m = { .type = PROTO_STATS,
			       .stats = { .req = req, .count = (uint16_t)b.n, .items = b.it } };
	send_msg(s, &m);
	free(b.it);
	free(b.keys);
}

/* -- CACHE_LS -- */

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
	if ((q->filter & PROTO_CLS_LEVEL) && (t->key.lx != q->lx || t->key.ly != q->ly))
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

static void on_cache_ls(struct session *s, const struct proto_cache_ls *q)
{
	struct lsctx c = { .q = q };
	uint64_t *nodes = NULL;
	if (q->filter & PROTO_CLS_PLANET) {
		const struct planet *p = planet_set_find(s->srv->planets, q->planet);
		if (!p) {
			send_error(s, PROTO_E_NOT_FOUND, PROTO_CACHE_LS, q->req, "no planet \"%s\"",
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
	cache_stats(s->srv->cache, &cs);
	size_t cap = cs.tiles + 64 < c.limit ? cs.tiles + 64 : c.limit;
	c.out = xmalloc((cap ? cap : 1) * sizeof *c.out);
	c.limit = cap;
	c.now_ns = cache_now_ns();
	cache_foreach(s->srv->cache, ls_fn, &c);
	size_t off = 0;
	do {
		size_t k = c.n - off > PROTO_MAX_CACHE_ENTRIES ? PROTO_MAX_CACHE_ENTRIES : c.n - off;
		struct proto_msg m = { .type = PROTO_CACHE_ENTRIES,
				       .cache_entries = { .req = q->req, .more = off + k < c.n,
							  .total = c.total, .count = (uint32_t)k,
							  .entries = c.out + off } };
		send_msg(s, &m);
		off += k;
	} while (off < c.n);
	free(c.out);
	free(nodes);
}

/* -- PREFETCH -- */

static void send_progress(struct session *s, struct prefetch_job *j)
{
	struct proto_msg m = { .type = PROTO_PREFETCH_PROGRESS,
			       .prefetch_progress = { .id = j->id, .state = (uint8_t)j->state,
						      .done = j->done, .total = j->total,
						      .rate = j->rate } };
	send_msg(s, &m);
}

static void job_remove(struct session *s, size_t i)
{
	prefetch_job_destroy(s->jobs[i]); /* stops its scheduler request first */
	retire(s, s->jobsets[i]);
	s->njobs--;
	s->jobs[i] = s->jobs[s->njobs];
	s->jobsets[i] = s->jobsets[s->njobs];
}

static void on_prefetch(struct session *s, const struct proto_prefetch *m)
{
	struct server *srv = s->srv;
	const struct planet *p = planet_set_find(srv->planets, m->planet);
	if (!p) {
		send_error(s, PROTO_E_NOT_FOUND, PROTO_PREFETCH, m->id, "no planet \"%s\"", m->planet);
		return;
	}
	for (size_t i = 0; i < s->njobs; i++) {
		if (s->jobs[i]->id == m->id) {
			send_error(s, PROTO_E_INVALID, PROTO_PREFETCH, m->id,
				   "job %u is already running", m->id);
			return;
		}
	}
	if (s->njobs >= srv->conf->max_jobs) {
		send_error(s, PROTO_E_LIMIT, PROTO_PREFETCH, m->id,
			   "%zu prefetch jobs running: this session's limit is %u", s->njobs,
			   srv->conf->max_jobs);
		return;
	}
	struct prefetch_job *j;
	char err[256];
	int rc = prefetch_job_create(p, m, server_now_ns(), &j, err);
	if (rc) {
		send_error(s, rc == -E2BIG ? PROTO_E_LIMIT : PROTO_E_INVALID, PROTO_PREFETCH, m->id,
			   "%s", err);
		return;
	}
	j->owner = s;
	j->req = sched_req_create(srv->sched, job_ready_cb, j);
	s->jobs = xrealloc(s->jobs, (s->njobs + 1) * sizeof *s->jobs);
	s->jobsets = xrealloc(s->jobsets, (s->njobs + 1) * sizeof *s->jobsets);
	/* The job borrows p: it keeps the set holding it (a reload does not move jobs). */
	s->jobsets[s->njobs] = planet_set_ref(srv->planets);
	s->jobs[s->njobs++] = j;
	log_msg(LOG_INFO, "session %llu: prefetch job %u on %s: %llu tiles, levels %u-%u",
		(unsigned long long)s->id, j->id, p->name, (unsigned long long)j->total, m->lmin,
		m->lmax);
	send_progress(s, j);
	prefetch_job_start(j);
	if (j->state != PROTO_JOB_RUNNING) { /* nothing to do */
		send_progress(s, j);
		job_remove(s, s->njobs - 1);
	}
}

static void on_job_ready(struct session *s, struct ready_item *it)
{
	size_t i = 0;
	while (i < s->njobs && s->jobs[i] != it->job)
		i++;
	if (i == s->njobs || s->dead)
		return; /* cancelled since */
	struct prefetch_job *j = it->job;
	if (!prefetch_job_ready(j, &it->key, it->err))
		return;
	prefetch_job_tick(j, server_now_ns());
	send_progress(s, j);
	if (j->state == PROTO_JOB_FAILED)
		send_error(s, PROTO_E_UNAVAILABLE, PROTO_PREFETCH, j->id,
			   "prefetch job %u: %llu of %llu tiles failed", j->id,
			   (unsigned long long)j->failed, (unsigned long long)j->total);
	log_msg(LOG_INFO, "session %llu: prefetch job %u finished: %llu tiles, %llu failed",
		(unsigned long long)s->id, j->id, (unsigned long long)j->done,
		(unsigned long long)j->failed);
	job_remove(s, i);
	flush(s);
}

static void on_prefetch_cancel(struct session *s, uint32_t id)
{
	for (size_t i = 0; i < s->njobs; i++) {
		if (s->jobs[i]->id == id) {
			struct prefetch_job *j = s->jobs[i];
			j->state = PROTO_JOB_CANCELLED;
			prefetch_job_tick(j, server_now_ns());
			send_progress(s, j);
			job_remove(s, i);
			return;
		}
	}
	send_error(s, PROTO_E_NOT_FOUND, PROTO_PREFETCH_CANCEL, id, "no prefetch job %u", id);
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
	default: return 0;
	}
}

static void handle(struct session *s, const struct proto_msg *m, size_t frame_len)
{
	struct server *srv = s->srv;
	char err[256];
	if (proto_check_state(s->st, false, m->type, err)) {
		send_error(s, PROTO_E_STATE, m->type, ref_of(m), "%s", err);
		begin_close(s);
		return;
	}
	if (s->st == PROTO_ST_READY && srv->limits.max_rate &&
	    !proto_rate_take(&s->rate, server_now_ns(), srv->limits.max_rate,
			     srv->limits.max_rate)) {
		if (++s->rate_viol > 4 * srv->limits.max_rate + 16) {
			send_error(s, PROTO_E_LIMIT, m->type, ref_of(m),
				   "message rate stays above this session's limit of %u/s: closing",
				   srv->limits.max_rate);
			begin_close(s);
		} else {
			send_error(s, PROTO_E_LIMIT, m->type, ref_of(m),
				   "message rate above this session's limit of %u/s: %s dropped",
				   srv->limits.max_rate, proto_type_name(m->type));
		}
		return;
	}
	s->rate_viol = 0;
	if (proto_check_limits(&srv->limits, m, frame_len, err)) {
		send_error(s, PROTO_E_LIMIT, m->type, ref_of(m), "%s", err);
		return;
	}
	switch (m->type) {
	case PROTO_HELLO: on_hello(s, &m->hello); break;
	case PROTO_BYE:
		s->st = PROTO_ST_CLOSED;
		begin_close(s);
		break;
	case PROTO_ERROR:
		log_msg(LOG_INFO, "session %llu: client error %s: %s", (unsigned long long)s->id,
			proto_code_name(m->error.code) ? proto_code_name(m->error.code) : "?",
			m->error.message);
		break;
	case PROTO_LIST_PLANETS: on_list(s, m->list_planets.req); break;
	case PROTO_OPEN: on_open(s, &m->open); break;
	case PROTO_WANT: on_want(s, &m->want); break;
	case PROTO_STATS_REQ: on_stats(s, m->stats_req.req); break;
	case PROTO_CACHE_LS: on_cache_ls(s, &m->cache_ls); break;
	case PROTO_PREFETCH: on_prefetch(s, &m->prefetch); break;
	case PROTO_PREFETCH_CANCEL: on_prefetch_cancel(s, m->prefetch_cancel.req); break;
	default:
		send_error(s, PROTO_E_STATE, m->type, 0, "%s is not a client message",
			   proto_type_name(m->type));
		begin_close(s);
	}
}

static void process_input(struct session *s)
{
	struct server *srv = s->srv;
	while (!s->closing && !s->dead && s->in.len) {
		struct proto_hdr h = { 0 };
		size_t need = 0;
		char err[256] = "";
		ssize_t r = proto_frame_check(s->in.data, s->in.len, &h, &need, err);
		if (r >= 0 && s->in.len >= PROTO_HDR && srv->limits.max_frame &&
		    (uint64_t)h.length + PROTO_HDR > srv->limits.max_frame) {
			send_error(s, PROTO_E_LIMIT, h.type, 0,
				   "frame of %u bytes exceeds this session's limit of %u",
				   h.length + PROTO_HDR, srv->limits.max_frame);
			begin_close(s);
			return;
		}
		if (r == 0)
			return;
		struct proto_msg m = { 0 };
		if (r > 0)
			r = proto_decode(s->in.data, s->in.len, &m, &need, err);
		if (r < 0) {
			/* Malformed is `protocol` whatever the class, except a bad version. */
			uint16_t code = r == PROTO_ERR_VERSION ? PROTO_E_VERSION
					: r == PROTO_ERR_STATE ? PROTO_E_STATE
							       : PROTO_E_PROTOCOL;
			send_error(s, code, s->in.len >= PROTO_HDR ? h.type : 0, 0, "%s", err);
			begin_close(s);
			return;
		}
		if (r == 0)
			return;
		handle(s, &m, (size_t)r);
		proto_msg_fini(&m);
		pbuf_consume(&s->in, (size_t)r);
	}
}

static void on_readable(struct session *s)
{
	size_t got = 0;
	while (!s->dead && s->reading && got < READ_BUDGET) {
		if (pbuf_reserve(&s->in, 65536))
			return;
		ssize_t n = recv(s->fd, s->in.data + s->in.len, 65536, MSG_DONTWAIT);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			if (errno == EAGAIN || errno == EWOULDBLOCK)
				break;
			char why[96];
			snprintf(why, sizeof why, "recv: %s", strerror(errno));
			session_close(s, why);
			return;
		}
		if (n == 0) {
			session_close(s, s->st == PROTO_ST_CLOSED ? NULL : "peer closed");
			return;
		}
		s->in.len += (size_t)n;
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
		if (s->reading || !(events & EPOLLOUT))
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
		if (s->nheap && session_pending_bytes(s) < s->srv->limits.max_pending)
			pump_add(s);
	}
}

/* ---- lifecycle -------------------------------------------------------------------------- */

struct session *session_create(struct server *srv, int fd, const struct listener *l)
{
	struct session *s = xcalloc(1, sizeof *s);
	s->ev.kind = EV_SESSION;
	s->srv = srv;
	s->fd = fd;
	s->id = ++srv->next_session_id;
	s->need_token = l->need_token;
	s->compress = l->compress;
	s->is_unix = l->is_unix;
	s->reading = true;
	snprintf(s->name, sizeof s->name, "%s", l->is_unix ? "unix" : "tcp");
	pbuf_init(&s->in);
	pbuf_init(&s->out);
	struct epoll_event ev = { .events = EPOLLIN | EPOLLRDHUP, .data.ptr = &s->ev };
	if (epoll_ctl(srv->epfd, EPOLL_CTL_ADD, fd, &ev)) {
		log_msg(LOG_ERROR, "session: epoll_ctl: %s", strerror(errno));
		close(fd);
		pbuf_fini(&s->in);
		pbuf_fini(&s->out);
		free(s);
		return NULL;
	}
	s->req = sched_req_create(srv->sched, sess_ready_cb, s);
	s->next = srv->sessions;
	if (srv->sessions)
		srv->sessions->prev = s;
	srv->sessions = s;
	srv->nsessions++;
	srv->sessions_total++;
	log_msg(LOG_INFO, "session %llu: connected on %s", (unsigned long long)s->id, l->name);
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
	bool sent = false;
	for (size_t i = 0; i < s->njobs; i++) {
		prefetch_job_tick(s->jobs[i], now_ns);
		send_progress(s, s->jobs[i]);
		sent = true;
	}
	if (sent)
		flush(s);
}

void session_shutdown(struct session *s)
{
	if (s->dead || s->closing)
		return;
	while (s->njobs) {
		struct prefetch_job *j = s->jobs[s->njobs - 1];
		j->state = PROTO_JOB_CANCELLED;
		send_progress(s, j);
		job_remove(s, s->njobs - 1);
	}
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
	struct server *srv = s->srv;
	s->dead = true;
	while (s->njobs)
		job_remove(s, s->njobs - 1);
	sched_req_destroy(s->req);
	s->req = NULL;
	server_ready_purge(srv, s);
	if (epoll_ctl(srv->epfd, EPOLL_CTL_DEL, s->fd, NULL))
		log_msg(LOG_WARN, "session %llu: epoll_ctl del: %s", (unsigned long long)s->id,
			strerror(errno));
	if (close(s->fd))
		log_msg(LOG_WARN, "session %llu: close: %s", (unsigned long long)s->id,
			strerror(errno));
	s->fd = -1;
	if (s->prev)
		s->prev->next = s->next;
	else
		srv->sessions = s->next;
	if (s->next)
		s->next->prev = s->prev;
	srv->nsessions--;
	s->grave_next = srv->graveyard;
	srv->graveyard = s;
	log_msg(LOG_INFO, "session %llu (%s): closed%s%s; %llu tiles sent, %llu dropped",
		(unsigned long long)s->id, s->name, why ? ": " : "", why ? why : "",
		(unsigned long long)s->tiles_sent, (unsigned long long)s->tiles_dropped);
	server_update_foci(srv);
}

void session_free(struct session *s)
{
	for (size_t i = 0; i < s->ws.n; i++)
		if (s->ws.e[i].state == W_READY)
			tile_unref(s->ws.e[i].t);
	free(s->ws.e);
	free(s->ws.tab);
	free(s->heap);
	free(s->jobs);
	free(s->jobsets);
	for (int i = 0; i < s->nopened; i++)
		planet_set_unref(s->opened[i].set);
	for (size_t i = 0; i < s->nretired; i++)
		planet_set_unref(s->retired[i]);
	free(s->retired);
	pbuf_fini(&s->in);
	pbuf_fini(&s->out);
	free(s);
}

struct session *session_next(const struct session *s)
{
	return s->next;
}

void session_free_list(struct session *head)
{
	while (head) {
		struct session *next = head->grave_next;
		session_free(head);
		head = next;
	}
}

bool session_focus(const struct session *s, double *lon, double *lat, double vel[3])
{
	if (!s->has_focus || s->dead)
		return false;
	*lon = s->lon;
	*lat = s->lat;
	memcpy(vel, s->vel, sizeof s->vel);
	return true;
}
