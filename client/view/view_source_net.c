/* view_source_net — see view_source_net.h. The frame loop holds several polled tiles at once
 * (until it uploads them), so each decoded tile has its own buffer: the tile's handle, freed
 * by release (up to SPARE_BYTES of released buffers are kept for reuse).
 *
 * The link is a small state machine advanced by poll and wait, never blocking:
 *   UP ──(read/send error, BYE, ERROR other than limit)──▶ WAIT (backoff)
 *   WAIT ──(delay over)──▶ CONNECTING (net_connect_start/step: connect, HELLO, HELLO_OK)
 *   CONNECTING ──▶ OPENING (OPEN sent; OPENED awaited) ──▶ UP (want-set sent again)
 * and any failure or an attempt older than ATTEMPT_MS back to WAIT with the next delay.
 * While the link is down the want-set the view gives is kept, and sent when it is up again,
 * less the tiles delivered since it was given (the view does not want those again).
 */
#include "view_source_net.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/errbuf.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"

#define BACKOFF_BASE_MS 100
#define BACKOFF_CAP_MS 5000
#define ATTEMPT_MS 5000 /* an attempt (connect, handshake, OPEN) that takes longer is given up */
#define RX_SLOT_MS 100	 /* the received-bytes rate: RX_SLOTS slots of RX_SLOT_MS, */
#define RX_SLOTS 10	 /* i.e. over the last second */
#define PING_MS 1000	 /* a LIST_PLANETS this often: its round trip is the RTT figure */

enum link_state { LINK_UP = 0, LINK_WAIT, LINK_CONNECTING, LINK_OPENING };

/* A tile delivered since the last want-set: (layer, key) packed for sorting. */
struct got {
	uint64_t hi, lo;
};

/* The spare buffers' bounds: 256 tiles of 256² RGBA. */
#define SPARE_MAX 256
#define SPARE_BYTES ((size_t)64 << 20)

struct net_source {
	struct view_source base; /* first: the frame loop holds &base */
	struct net_conn *c;	 /* NULL while waiting to reconnect */
	struct net_opts o;	 /* its strings point into the copies below */
	char *target, *token_file, *client_name, *planet, *tls_ca;
	uint32_t planet_id, seq, open_req;
	/* The last want-set the view gave, in wire form, and its focus. */
	struct proto_want_entry *entries;
	size_t n_entries, cap_entries;
	double focus[6]; /* lon, lat, alt, vel east, north, up */
	struct got *got; /* delivered since that want-set */
	size_t n_got, cap_got;
	/* The link. */
	enum link_state state;
	unsigned attempt, reconnects, lost;
	unsigned last_attempts; /* the last reconnect's attempts */
	double last_down_ms;	/* and how long the link was down then */
	unsigned seed;
	double lost_ms, next_ms, attempt_ms; /* clock_now_ms: lost, next attempt, this one began */
	char why[256];	    /* why the link is down: the loss, then the last attempt's failure */
	char lost_why[256]; /* why it was lost last */
	/* The link's figures: tile bytes received per RX_SLOT_MS slot (the newest rx_slot,
	 * counted in clock_now_ms / RX_SLOT_MS), and the round trips of LIST_PLANETS requests. */
	uint64_t rx[RX_SLOTS];
	long rx_slot;
	uint64_t rx_total; /* since the start, over every connection */
	double up_ms;			  /* when the link came up */
	uint32_t ping_req;		  /* the LIST_PLANETS awaited (0: none) */
	double ping_ms, next_ping_ms;	  /* sent at; the next one due */
	double rtt_min_ms, rtt_last_ms;	  /* 0: none yet on this connection */
	/* Released tile buffers, any size, for the next tiles: tiles are held until their
	 * level's window moves past them, a fast flight releases hundreds in a burst, and buffers
	 * given back to malloc come back as fresh pages (glibc maps or trims them), whose first
	 * write costs 20-30x a warm one under this project's VMs (bench_machine's last line). */
	struct spare {
		void *p;
		size_t len;
	} spare[SPARE_MAX];
	int nspare;
	size_t spare_bytes;
	char err[256];
};

static struct net_source *ns_of(struct view_source *s)
{
	return (struct net_source *)s;
}

static struct got got_of(uint8_t layer, const struct tile_key *k)
{
	return (struct got){ (uint64_t)layer << 16 | (uint64_t)k->lx << 8 | k->ly,
			     (uint64_t)k->x << 32 | k->y };
}

static int got_cmp(const void *a, const void *b)
{
	const struct got *x = a, *y = b;
	if (x->hi != y->hi)
		return x->hi < y->hi ? -1 : 1;
	return x->lo < y->lo ? -1 : x->lo > y->lo;
}

static void got_add(struct net_source *ns, uint8_t layer, const struct tile_key *k)
{
	if (ns->n_got == ns->cap_got) {
		ns->cap_got = ns->cap_got ? 2 * ns->cap_got : 256;
		ns->got = xrealloc(ns->got, ns->cap_got * sizeof *ns->got);
	}
	ns->got[ns->n_got++] = got_of(layer, k);
}

static void link_down(struct net_source *ns, const char *why);

/* Clears the slots that ended since the newest one, now in slot `slot`. */
static void rx_advance(struct net_source *ns, long slot)
{
	if (slot - ns->rx_slot >= RX_SLOTS)
		memset(ns->rx, 0, sizeof ns->rx);
	else
		for (long i = ns->rx_slot + 1; i <= slot; i++)
			ns->rx[i % RX_SLOTS] = 0;
	if (slot > ns->rx_slot)
		ns->rx_slot = slot;
}

static void rx_count(struct net_source *ns, uint64_t bytes)
{
	long slot = (long)(clock_now_ms() / RX_SLOT_MS);
	rx_advance(ns, slot);
	ns->rx[slot % RX_SLOTS] += bytes;
	ns->rx_total += bytes;
}

/* A LIST_PLANETS when one is due and none is awaited: its round trip (the link's RTT plus
 * what queues before the answer: the daemon's send queue, the kernel's, the bottleneck's) is
 * the RTT figure, the least of them the link's own. LIST_PLANETS rather than STATS: its answer
 * is a few hundred bytes whatever the daemon serves, where STATS grows with every session
 * (a fleet of viewers asking once a second would cost the loop O(sessions²) a second). */
static void ping(struct net_source *ns)
{
	double now = clock_now_ms();
	if (ns->ping_req || now < ns->next_ping_ms)
		return;
	uint32_t req = net_next_req(ns->c);
	struct proto_msg m = { .type = PROTO_LIST_PLANETS, .list_planets = { .req = req } };
	if (net_send(ns->c, &m, ns->err)) {
		link_down(ns, ns->err);
		return;
	}
	ns->ping_req = req;
	ns->ping_ms = now;
	ns->next_ping_ms = now + PING_MS;
}

/* Sends the kept want-set: all of it (fresh) or, after a reconnect, less what was delivered
 * since the view gave it. */
static int send_want(struct net_source *ns, bool resend)
{
	size_t n = ns->n_entries;
	if (resend && ns->n_got) {
		qsort(ns->got, ns->n_got, sizeof *ns->got, got_cmp);
		size_t k = 0;
		for (size_t i = 0; i < n; i++) {
			const struct proto_want_entry *e = &ns->entries[i];
			struct got g = got_of(e->layer, &(struct tile_key){ 0, e->x, e->y, e->lx,
									     e->ly });
			if (!bsearch(&g, ns->got, ns->n_got, sizeof g, got_cmp))
				ns->entries[k++] = *e;
		}
		ns->n_entries = n = k;
		ns->n_got = 0;
	}
	const double *f = ns->focus;
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = ns->planet_id, .seq = ++ns->seq,
					 .lon = f[0], .lat = f[1], .alt = f[2],
					 .vel = { f[3], f[4], f[5] },
					 .count = (uint32_t)n, .entries = ns->entries } };
	return net_send(ns->c, &m, ns->err);
}

/* Back to WAIT after attempt `attempt` (0: the link was just lost), the next attempt after
 * its backoff. why: the reason (copied). */
static void link_down(struct net_source *ns, const char *why)
{
	double now = clock_now_ms();
	net_close(ns->c);
	ns->c = NULL;
	if (ns->state == LINK_UP) {
		ns->attempt = 0;
		ns->lost++;
		ns->lost_ms = now;
		snprintf(ns->lost_why, sizeof ns->lost_why, "%s", why);
	}
	ns->state = LINK_WAIT;
	ns->ping_req = 0; /* the next connection measures afresh */
	ns->rtt_min_ms = ns->rtt_last_ms = 0;
	snprintf(ns->why, sizeof ns->why, "%s", why);
	ns->next_ms = now + net_backoff_ms(ns->attempt + 1, BACKOFF_BASE_MS, BACKOFF_CAP_MS,
					   &ns->seed);
}

/* The OPENED answer m: the planet must have the shape the view was built for. */
static int check_planet(struct net_source *ns, const struct proto_opened *op)
{
	const struct view_planet *vp = &ns->base.planet;
	const struct proto_planet *pp = &op->planet;
	bool same = pp->tile_size == vp->tile_size && pp->max_level == vp->max_level &&
		    pp->a == vp->a && pp->f == vp->f &&
		    (pp->nlayers < VIEW_MAX_LAYERS ? pp->nlayers : VIEW_MAX_LAYERS) == vp->nlayers;
	for (int i = 0; same && i < vp->nlayers; i++)
		same = pp->layers[i].format == vp->layer[i].format &&
		       pp->layers[i].normal_of == vp->layer[i].normal_of &&
		       strcmp(pp->layers[i].name, vp->layer[i].name) == 0;
	if (!same) {
		err_set(ns->err, "%s serves planet %s with another shape (tile size, levels or "
			"layers) than the one this view was built for", net_peer(ns->c), pp->name);
		return -EPROTO;
	}
	return 0;
}

/* LINK_OPENING: reads what has arrived; OPENED brings the link up. Returns 0 (up), -EAGAIN
 * (not yet) or -errno with ns->err filled. */
static int step_opening(struct net_source *ns)
{
	for (;;) {
		struct proto_msg m;
		int rc = net_recv(ns->c, &m, 0, ns->err);
		if (rc)
			return rc;
		if (m.type == PROTO_ERROR) {
			net_error_text(ns->c, &m.error, ns->err);
			rc = -net_code_errno(m.error.code);
		} else if (m.type == PROTO_BYE) {
			err_set(ns->err, "%s: the daemon closed the session", net_peer(ns->c));
			rc = -ECONNRESET;
		} else if (m.type == PROTO_OPENED && m.opened.req == ns->open_req) {
			rc = check_planet(ns, &m.opened);
			if (rc == 0) {
				ns->planet_id = m.opened.planet_id;
				proto_msg_fini(&m);
				return 0;
			}
		} else {
			proto_msg_fini(&m); /* nothing else is ours before OPENED */
			continue;
		}
		proto_msg_fini(&m);
		return rc;
	}
}

/* Advances a link that is down by what can be done without waiting. */
static void link_step(struct net_source *ns)
{
	double now = clock_now_ms();
	if (ns->state == LINK_WAIT) {
		if (now < ns->next_ms)
			return;
		ns->attempt++;
		ns->attempt_ms = now;
		if (net_connect_start(&ns->o, &ns->c, ns->err)) {
			link_down(ns, ns->err);
			return;
		}
		ns->state = LINK_CONNECTING;
	}
	int rc = 0;
	if (ns->state == LINK_CONNECTING) {
		rc = net_connect_step(ns->c, ns->err);
		if (rc == 0) {
			ns->open_req = net_next_req(ns->c);
			struct proto_msg o = { .type = PROTO_OPEN,
					       .open = { .req = ns->open_req, .name = ns->planet } };
			rc = net_send(ns->c, &o, ns->err);
			if (rc == 0)
				ns->state = LINK_OPENING;
		}
	}
	if (rc == 0 && ns->state == LINK_OPENING) {
		rc = step_opening(ns);
		if (rc == 0) {
			ns->state = LINK_UP;
			ns->up_ms = now;
			ns->next_ping_ms = now;
			ns->reconnects++;
			ns->last_attempts = ns->attempt;
			ns->last_down_ms = now - ns->lost_ms;
			ns->attempt = 0;
			ns->why[0] = '\0';
			if (ns->n_entries && (rc = send_want(ns, true))) {
				link_down(ns, ns->err);
				return;
			}
			return;
		}
	}
	if (rc == -EAGAIN && now - ns->attempt_ms > ATTEMPT_MS) {
		err_set(ns->err, "%s: no session within %.0f s", ns->target, ATTEMPT_MS / 1000.0);
		rc = -ETIMEDOUT;
	}
	if (rc && rc != -EAGAIN)
		link_down(ns, ns->err);
}

static int ns_want(struct view_source *s, const struct view_want *w, size_t n,
		   const struct view_focus *f)
{
	struct net_source *ns = ns_of(s);
	if (n > PROTO_MAX_WANT)
		n = PROTO_MAX_WANT; /* priority order: the tail is the least wanted */
	if (n > ns->cap_entries) {
		ns->cap_entries = n;
		ns->entries = xrealloc(ns->entries, n * sizeof *ns->entries);
	}
	for (size_t i = 0; i < n; i++)
		ns->entries[i] = (struct proto_want_entry){
			.layer = w[i].layer,
			.cls = w[i].cls == VIEW_CLASS_VISIBLE	 ? PROTO_CLASS_VISIBLE
			       : w[i].cls == VIEW_CLASS_AHEAD ? PROTO_CLASS_BULK
							      : PROTO_CLASS_PREFETCH,
			.lx = w[i].key.lx, .ly = w[i].key.ly, .x = w[i].key.x, .y = w[i].key.y,
		};
	ns->n_entries = n;
	ns->n_got = 0;
	double foc[6] = { f->lon, f->lat, f->alt, f->vel[0], f->vel[1], f->vel[2] };
	memcpy(ns->focus, foc, sizeof foc);
	if (ns->state != LINK_UP)
		return 0; /* sent when the link is up again */
	if (send_want(ns, false))
		link_down(ns, ns->err);
	return 0;
}

/* A TILE of our planet into out. */
static void take_tile(struct net_source *ns, struct proto_msg *m, struct view_tile *out)
{
	size_t need = m->tile.enc.raw_len;
	void *buf = NULL;
	for (int i = ns->nspare - 1; i >= 0 && need; i--) {
		if (ns->spare[i].len == need) {
			buf = ns->spare[i].p;
			ns->spare[i] = ns->spare[--ns->nspare];
			ns->spare_bytes -= need;
			break;
		}
	}
	if (!buf)
		buf = xaligned_alloc(64, need ? need : 64);
	int rc = net_tile_decode(ns->c, &m->tile, buf, need, ns->err);
	if (rc) {
		free(buf);
		buf = NULL;
	}
	*out = (struct view_tile){ .layer = m->tile.layer, .key = m->tile.key,
				   .format = m->tile.enc.format, .size = m->tile.enc.size,
				   .texels = buf, .err = rc, .handle = buf };
	got_add(ns, m->tile.layer, &m->tile.key);
}

static int ns_poll(struct view_source *s, struct view_tile *out)
{
	struct net_source *ns = ns_of(s);
	if (ns->state != LINK_UP) {
		link_step(ns);
		if (ns->state != LINK_UP)
			return 0;
	}
	ping(ns);
	if (ns->state != LINK_UP)
		return 0;
	for (;;) {
		struct proto_msg m;
		int rc = net_recv(ns->c, &m, 0, ns->err);
		if (rc == -EAGAIN)
			return 0;
		if (rc) {
			link_down(ns, ns->err);
			return 0;
		}
		if (m.type == PROTO_TILE)
			rx_count(ns, PROTO_HDR + (uint64_t)m.tile.payload_len);
		if (m.type == PROTO_PLANETS && ns->ping_req && m.planets.req == ns->ping_req) {
			double rtt = clock_now_ms() - ns->ping_ms;
			ns->rtt_last_ms = rtt;
			if (ns->rtt_min_ms <= 0 || rtt < ns->rtt_min_ms)
				ns->rtt_min_ms = rtt;
			ns->ping_req = 0;
		}
		if (m.type == PROTO_TILE && m.tile.planet_id == ns->planet_id) {
			take_tile(ns, &m, out);
			proto_msg_fini(&m);
			return 1;
		}
		if (m.type == PROTO_TILE_FAIL && m.tile_fail.planet_id == ns->planet_id) {
			uint8_t l = m.tile_fail.layer;
			*out = (struct view_tile){ .layer = l, .key = m.tile_fail.key, .err = -EIO,
						   .size = s->planet.tile_size,
						   .format = l < s->planet.nlayers
								     ? s->planet.layer[l].format
								     : PIX_NONE };
			got_add(ns, l, &m.tile_fail.key);
			proto_msg_fini(&m);
			return 1;
		}
		if ((m.type == PROTO_ERROR && m.error.code != PROTO_E_LIMIT) ||
		    m.type == PROTO_BYE) {
			/* The session is over (shutdown, the planet gone, a protocol error): a new
			 * one, perhaps with another daemon behind the same address. */
			if (m.type == PROTO_ERROR)
				net_error_text(ns->c, &m.error, ns->err);
			else
				err_set(ns->err, "%s: the daemon closed the session", net_peer(ns->c));
			proto_msg_fini(&m);
			link_down(ns, ns->err);
			return 0;
		}
		proto_msg_fini(&m); /* anything else (limit notices, progress) is not the viewer's */
	}
}

static int ns_wait(struct view_source *s, int timeout_ms)
{
	struct net_source *ns = ns_of(s);
	double end = clock_now_ms() + (timeout_ms > 0 ? timeout_ms : 0);
	for (;;) {
		if (ns->state != LINK_UP)
			link_step(ns);
		double now = clock_now_ms();
		int ms = (int)(end - now + 0.999);
		if (ms < 0)
			ms = 0;
		struct pollfd p = { .fd = -1 };
		if (ns->state == LINK_UP) {
			p = (struct pollfd){ .fd = net_fd(ns->c), .events = POLLIN };
		} else if (ns->state == LINK_WAIT) {
			double due = ns->next_ms - now;
			ms = due < ms ? (int)(due > 0 ? due + 0.999 : 0) : ms;
		} else {
			p = (struct pollfd){ .fd = net_fd(ns->c), .events = net_connect_events(ns->c) };
			double due = ns->attempt_ms + ATTEMPT_MS - now;
			ms = due < ms ? (int)(due > 0 ? due + 0.999 : 0) : ms;
		}
		int rc = poll(&p, p.fd >= 0 ? 1 : 0, ms);
		if (rc < 0 && errno != EINTR)
			return -errno;
		if (ns->state == LINK_UP)
			return rc > 0; /* a tile, or the link's end: poll sees which */
		if (clock_now_ms() >= end) {
			link_step(ns);
			return ns->state == LINK_UP;
		}
	}
}

static void ns_release(struct view_source *s, struct view_tile *t)
{
	struct net_source *ns = ns_of(s);
	if (t->handle) {
		size_t len = (size_t)t->size * t->size * pix_bytes(t->format);
		if (len && ns->nspare < SPARE_MAX && ns->spare_bytes + len <= SPARE_BYTES) {
			ns->spare[ns->nspare++] = (struct spare){ t->handle, len };
			ns->spare_bytes += len;
		} else {
			free(t->handle);
		}
	}
	t->handle = NULL;
	t->texels = NULL;
}

static void ns_destroy(struct view_source *s)
{
	struct net_source *ns = ns_of(s);
	net_close(ns->c);
	free(ns->entries);
	free(ns->got);
	for (int i = 0; i < ns->nspare; i++)
		free(ns->spare[i].p);
	free(ns->target);
	free(ns->token_file);
	free(ns->client_name);
	free(ns->planet);
	free(ns->tls_ca);
	free(ns->base.planet.look.sea_grid.dm);
	free(ns);
}

static const struct view_source_ops ops = {
	.want = ns_want, .poll = ns_poll, .wait = ns_wait, .release = ns_release,
	.destroy = ns_destroy,
};

void view_source_net_link(const struct view_source *s, struct view_net_link *out)
{
	struct net_source *ns = (struct net_source *)s; /* the rate's slots move on */
	bool up = ns->state == LINK_UP;
	double now = clock_now_ms();
	rx_advance(ns, (long)(now / RX_SLOT_MS));
	uint64_t rx = 0;
	for (int i = 0; i < RX_SLOTS; i++)
		rx += ns->rx[i];
	/* the slots span the last second, less what the current slot has not reached yet and
	 * what came before the link was up */
	double span = (RX_SLOTS - 1) * RX_SLOT_MS + (now - (double)ns->rx_slot * RX_SLOT_MS);
	if (now - ns->up_ms < span)
		span = now - ns->up_ms;
	unsigned failed = up ? 0 : ns->state == LINK_WAIT ? ns->attempt : ns->attempt - 1;
	*out = (struct view_net_link){ .up = up, .attempt = up ? 0 : ns->attempt, .failed = failed,
				       .reconnects = ns->reconnects, .lost = ns->lost,
				       .down_s = up ? 0 : (clock_now_ms() - ns->lost_ms) / 1e3,
				       .why = up ? "" : ns->why, .lost_why = ns->lost_why,
				       .peer = ns->target,
				       .last_attempts = ns->last_attempts,
				       .last_down_s = ns->last_down_ms / 1e3,
				       .rate_bps = up && span > 0 ? (double)rx * 8e3 / span : 0,
				       .rx_bytes = ns->rx_total,
				       .rtt_ms = up ? ns->rtt_min_ms : 0,
				       .queue_ms = up && ns->rtt_last_ms > 0
							   ? ns->rtt_last_ms - ns->rtt_min_ms
							   : 0 };
}

static char *dup_or_null(const char *s)
{
	return s ? xstrdup(s) : NULL;
}

/* One blocking attempt: connect, handshake, OPEN. *final: the daemon answered and refused
 * (a wrong token, an unknown planet): trying again will not help. */
static int open_once(const struct net_opts *o, const char *planet, struct net_conn **c,
		     struct proto_msg *m, bool *final, char err[256])
{
	int rc = net_connect(o, c, err);
	if (rc) {
		*final = rc == -EACCES || rc == -EPROTONOSUPPORT || rc == -EPROTO ||
			 rc == -EINVAL || rc == -ENAMETOOLONG || rc == -EKEYREJECTED;
		return rc;
	}
	rc = net_open_planet(*c, planet, m, o->timeout_ms > 0 ? o->timeout_ms : 10000, err);
	if (rc) {
		*final = rc == -ENOENT || rc == -EINVAL || rc == -EACCES;
		net_close(*c);
		*c = NULL;
	}
	return rc;
}

int view_source_net_create_wait(const struct net_opts *o, const char *planet, double wait_s,
				unsigned *attempts, struct view_source **out, char err[256])
{
	unsigned seed = (unsigned)clock_now_ns() ^ (unsigned)getpid();
	double end = clock_now_ms() + wait_s * 1e3;
	struct net_conn *c = NULL;
	struct proto_msg m = { 0 };
	unsigned n = 0;
	for (;;) {
		bool final = false;
		n++;
		int rc = open_once(o, planet, &c, &m, &final, err);
		if (rc == 0)
			break;
		int delay = net_backoff_ms(n, BACKOFF_BASE_MS, BACKOFF_CAP_MS, &seed);
		if (final || clock_now_ms() + delay > end) {
			if (attempts)
				*attempts = n;
			return rc;
		}
		/* Before the first frame: nothing to keep drawing, so the start may wait. */
		struct timespec ts = { delay / 1000, (long)(delay % 1000) * 1000000L };
		while (nanosleep(&ts, &ts) < 0 && errno == EINTR)
			;
	}
	if (attempts)
		*attempts = n;
	struct net_source *ns = xcalloc(1, sizeof *ns);
	ns->base.ops = &ops;
	ns->c = c;
	ns->seed = seed;
	ns->up_ms = clock_now_ms();
	ns->planet_id = m.opened.planet_id;
	ns->target = xstrdup(o->hostport ? o->hostport : o->socket_path);
	ns->token_file = dup_or_null(o->token_file);
	ns->client_name = dup_or_null(o->name);
	ns->planet = xstrdup(planet);
	ns->tls_ca = dup_or_null(o->tls_ca);
	ns->o = (struct net_opts){ .socket_path = o->hostport ? NULL : ns->target,
				   .hostport = o->hostport ? ns->target : NULL,
				   .token_file = ns->token_file, .name = ns->client_name,
				   .codecs = o->codecs, .timeout_ms = o->timeout_ms,
				   .tls_ca = ns->tls_ca, .tls = o->tls };
	struct view_planet *vp = &ns->base.planet;
	const struct proto_planet *pp = &m.opened.planet;
	snprintf(vp->name, sizeof vp->name, "%s", pp->name);
	vp->a = pp->a;
	vp->f = pp->f;
	vp->tile_size = pp->tile_size;
	vp->max_level = pp->max_level;
	vp->look = (struct view_look){ .air_density = pp->air_density, .air_height = pp->air_height,
				       .air_color = { pp->air_color[0], pp->air_color[1],
						      pp->air_color[2] },
				       .sea = pp->sea != 0, .sea_level = pp->sea_level,
				       .sea_mask = pp->sea_mask != 0 };
	if (pp->sea_grid.rows) {
		size_t bytes = (size_t)pp->sea_grid.rows * pp->sea_grid.cols * sizeof(int16_t);
		vp->look.sea_grid = (struct sea_grid){ .rows = pp->sea_grid.rows,
						       .cols = pp->sea_grid.cols,
						       .dm = xmalloc(bytes) };
		memcpy(vp->look.sea_grid.dm, pp->sea_grid.dm, bytes);
	}
	vp->nlayers = pp->nlayers < VIEW_MAX_LAYERS ? pp->nlayers : VIEW_MAX_LAYERS;
	for (int i = 0; i < vp->nlayers; i++) {
		snprintf(vp->layer[i].name, sizeof vp->layer[i].name, "%s", pp->layers[i].name);
		vp->layer[i].format = pp->layers[i].format;
		vp->layer[i].normal_of = pp->layers[i].normal_of;
	}
	proto_msg_fini(&m);
	*out = &ns->base;
	return 0;
}

int view_source_net_create(const struct net_opts *o, const char *planet, struct view_source **out,
			   char err[256])
{
	return view_source_net_create_wait(o, planet, 0, NULL, out, err);
}
