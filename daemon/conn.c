/* conn — see conn.h. Output: the pieces are an array used from `head`; pieces that went
 * out are freed as they go and the array is slid back only once its head is over half of it
 * (a few dozen bytes per piece, never payload bytes). A message piece stops taking appends
 * at MSG_SEG bytes. Plain sockets get up to IOV_MAX_OUT pieces per sendmsg; over TLS each
 * piece is handed to the stream in turn. Input is consumed frame by frame (pbuf_consume), so
 * a partial frame simply waits for more bytes.
 */
#include "conn.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <sys/uio.h>
#include <unistd.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "encq.h"
#include "tls.h"

#define RECV_CHUNK 65536
#define MSG_SEG (64u << 10)
#define IOV_MAX_OUT 64
#define TILE_HEAD (PROTO_HDR + 44u)

void conn_init(struct conn *c, int fd)
{
	*c = (struct conn){ .fd = fd, .reading = true };
	pbuf_init(&c->in);
}

int conn_start_tls(struct conn *c, struct tls_server *tls)
{
	c->tls = tls_stream_create(tls, c->fd);
	return c->tls ? 0 : -ENOMEM;
}

const char *conn_strerror(const struct conn *c, int rc)
{
	if (c->tls && tls_stream_error(c->tls)[0])
		return tls_stream_error(c->tls);
	if (c->tls && rc == -ENOTCONN)
		return "output before the TLS handshake completed";
	return strerror(rc < 0 ? -rc : rc);
}

int conn_close(struct conn *c)
{
	if (c->fd < 0)
		return 0;
	tls_stream_destroy(c->tls);
	c->tls = NULL;
	int rc = close(c->fd) ? -errno : 0;
	c->fd = -1;
	return rc;
}

static void seg_fini(struct conn *c, struct conn_seg *g)
{
	c->owned -= g->b.cap;
	pbuf_fini(&g->b);
	etile_unref(g->e);
}

void conn_fini(struct conn *c)
{
	pbuf_fini(&c->in);
	for (size_t i = c->head; i < c->n; i++)
		seg_fini(c, &c->seg[i]);
	free(c->seg);
	c->seg = NULL;
	c->head = c->n = c->cap = 0;
	c->pending = 0;
}

uint32_t conn_events(const struct conn *c)
{
	return (c->reading ? EPOLLIN | EPOLLRDHUP : 0) | (c->want_out ? EPOLLOUT : 0);
}

uint64_t conn_pending(const struct conn *c)
{
	return c->pending;
}

/* conn_recv over TLS: every record GnuTLS holds is taken, so none waits unseen by epoll. */
static ssize_t recv_tls(struct conn *c)
{
	int rc = tls_stream_handshake(c->tls);
	if (rc)
		return rc;
	ssize_t got = 0;
	do {
		if ((rc = pbuf_reserve(&c->in, RECV_CHUNK)))
			return rc;
		ssize_t n = tls_stream_recv(c->tls, c->in.data + c->in.len, RECV_CHUNK);
		if (n <= 0)
			return got ? got : n;
		c->in.len += (size_t)n;
		got += n;
	} while (tls_stream_pending(c->tls));
	return got;
}

ssize_t conn_recv(struct conn *c)
{
	if (c->tls)
		return recv_tls(c);
	int rc = pbuf_reserve(&c->in, RECV_CHUNK);
	if (rc)
		return rc;
	for (;;) {
		ssize_t n = recv(c->fd, c->in.data + c->in.len, RECV_CHUNK, MSG_DONTWAIT);
		if (n >= 0) {
			c->in.len += (size_t)n;
			return n;
		}
		if (errno != EINTR)
			return errno == EWOULDBLOCK ? -EAGAIN : -errno;
	}
}

ssize_t conn_decode(struct conn *c, enum proto_state st, uint32_t max_frame, struct proto_msg *m,
		    uint16_t *code, uint16_t *type, char err[256])
{
	struct proto_hdr h = { 0 };
	size_t need = 0;
	err[0] = '\0';
	ssize_t r = proto_frame_check(c->in.data, c->in.len, &h, &need, err);
	if (r >= 0 && c->in.len >= PROTO_HDR) {
		/* Decided at the header, so a body that may not come costs nothing. */
		if (proto_check_state(st, false, h.type, err)) {
			*code = PROTO_E_STATE;
			*type = h.type;
			return -EPROTO;
		}
		uint64_t size = (uint64_t)h.length + PROTO_HDR;
		if (st == PROTO_ST_HANDSHAKE && size > CONN_PREAUTH_FRAME) {
			*code = PROTO_E_LIMIT;
			*type = h.type;
			err_set(err, "frame of %llu bytes before the handshake exceeds the limit of %u",
				(unsigned long long)size, CONN_PREAUTH_FRAME);
			return -EPROTO;
		}
		if (max_frame && size > max_frame) {
			*code = PROTO_E_LIMIT;
			*type = h.type;
			err_set(err, "frame of %llu bytes exceeds this session's limit of %u",
				(unsigned long long)size, max_frame);
			return -EPROTO;
		}
	}
	if (r == 0)
		return 0;
	if (r > 0)
		r = proto_decode(c->in.data, c->in.len, m, &need, err);
	if (r < 0) {
		/* Malformed is `protocol` whatever the class, except a bad version. */
		*code = r == PROTO_ERR_VERSION ? PROTO_E_VERSION
			: r == PROTO_ERR_STATE ? PROTO_E_STATE
					       : PROTO_E_PROTOCOL;
		*type = c->in.len >= PROTO_HDR ? h.type : 0;
		return -EPROTO;
	}
	return r;
}

void conn_consume(struct conn *c, size_t n)
{
	pbuf_consume(&c->in, n);
}

/* A tile in parts (conn_seg.part): part i is its frame header and fields (the first part's
 * are longer: they carry the TILE's) and then payload bytes [i·P, min((i + 1)·P, len)).
 * The headers lie one after another in the piece's `b`; the piece's bytes are the parts in
 * order. */
#define PART_H0 (PROTO_HDR + PROTO_PART_FIRST_HEAD)
#define PART_H (PROTO_HDR + PROTO_PART_HEAD)

struct part_at {
	size_t start;	     /* where part i starts among the piece's bytes */
	size_t hoff, hlen;   /* its header in b */
	size_t poff, plen;   /* its payload bytes */
};

static struct part_at part_of(const struct conn_seg *g, size_t off)
{
	size_t P = g->part, len = g->e->len;
	size_t i = off < PART_H0 + P ? 0 : 1 + (off - PART_H0 - P) / (PART_H + P);
	struct part_at a = { .start = i ? PART_H0 + P + (i - 1) * (PART_H + P) : 0,
			     .hoff = i ? PART_H0 + (i - 1) * PART_H : 0,
			     .hlen = i ? PART_H : PART_H0,
			     .poff = i * P };
	a.plen = len - a.poff < P ? len - a.poff : P;
	return a;
}

/* The headers of g's parts, into g->b. Returns 0 or -EINVAL. */
static int part_heads(struct conn_seg *g)
{
	size_t P = g->part, len = g->e->len, np = (len + P - 1) / P;
	if (pbuf_reserve(&g->b, PART_H0 + (np - 1) * PART_H))
		return -ENOMEM;
	for (size_t i = 0; i < np; i++) {
		size_t n = len - i * P < P ? len - i * P : P;
		if (proto_encode_tile_part_head(&g->b, &g->pt, (uint32_t)(i * P), (uint32_t)n,
						NULL) != (ssize_t)(i ? PART_H : PART_H0))
			return -EINVAL;
	}
	return 0;
}

/* Whether piece g can go out; a TILE whose encoding became ready gets its header now (and
 * its count corrected), one whose encoding failed is emptied (skipped). */
static bool settle(struct conn *c, struct conn_seg *g)
{
	if (!g->e || g->b.len)
		return true;
	if (!g->e->ready)
		return false;
	uint64_t now = 0;
	if (!g->e->err) {
		g->pt.enc = g->e->enc;
		g->pt.payload = g->e->payload;
		g->pt.payload_len = g->e->len;
		if (g->part && g->e->len > g->part) {
			size_t was = g->b.cap;
			if (part_heads(g) == 0)
				now = g->b.len + g->e->len;
			else
				g->b.len = 0;
			c->owned += g->b.cap - was;
		} else {
			g->part = 0;
			pbuf_reserve(&g->b, TILE_HEAD);
			c->owned += g->b.cap;
			if (proto_encode_tile_head(&g->b, &g->pt, NULL) == (ssize_t)TILE_HEAD)
				now = TILE_HEAD + g->e->len;
			else
				g->b.len = 0;
		}
	}
	if (!now) {
		/* nothing to send: an empty header and no payload */
		etile_unref(g->e);
		g->e = NULL;
	}
	g->end = now;
	c->pending = c->pending - g->counted + now;
	g->counted = now;
	return true;
}

static size_t seg_len(const struct conn_seg *g)
{
	return g->e ? g->end : g->b.len;
}

/* Whether the head piece is ready to go (settling the pieces at the head). */
static bool head_ready(struct conn *c)
{
	return c->head < c->n && settle(c, &c->seg[c->head]);
}

/* Frees the pieces wholly sent at the head and the array once empty. */
static void drop_sent(struct conn *c)
{
	while (c->head < c->n && settle(c, &c->seg[c->head]) &&
	       c->seg[c->head].off == seg_len(&c->seg[c->head])) {
		seg_fini(c, &c->seg[c->head]);
		c->head++;
	}
	if (c->head == c->n) {
		c->head = c->n = 0;
		if (c->cap > 256) {
			free(c->seg);
			c->seg = NULL;
			c->cap = 0;
		}
	}
}

/* The unsent part of piece g as at most maxv (>= 2) iovecs: a whole TILE as its header and
 * payload, a tile in parts as each part's header and bytes in turn. */
static int seg_iov(const struct conn_seg *g, struct iovec *v, int maxv)
{
	int k = 0;
	size_t off = g->off;
	if (g->e && g->part) {
		while (off < g->end && k + 2 <= maxv) {
			struct part_at a = part_of(g, off);
			size_t in = off - a.start;
			if (in < a.hlen) {
				v[k++] = (struct iovec){ g->b.data + a.hoff + in, a.hlen - in };
				in = a.hlen;
			}
			in -= a.hlen;
			v[k++] = (struct iovec){ (void *)(g->e->payload + a.poff + in), a.plen - in };
			off = a.start + a.hlen + a.plen;
		}
		return k;
	}
	if (off < g->b.len) {
		v[k++] = (struct iovec){ g->b.data + off, g->b.len - off };
		off = 0;
	} else {
		off -= g->b.len;
	}
	if (g->e && off < g->e->len)
		v[k++] = (struct iovec){ (void *)(g->e->payload + off), g->e->len - off };
	return k;
}

/* Marks n bytes sent from the head on. */
static void advance(struct conn *c, size_t n, uint64_t *sent)
{
	*sent += n;
	c->pending -= n;
	for (size_t i = c->head; n && i < c->n; i++) {
		struct conn_seg *g = &c->seg[i];
		size_t left = seg_len(g) - g->off;
		size_t take = n < left ? n : left;
		g->off += take;
		g->counted -= take;
		n -= take;
	}
	drop_sent(c);
}

/* Writes over TLS as far as the socket takes (TLS's own unsent records first). Returns 1 when
 * that was done, 0 while the handshake waits with nothing to send (want_out set while the
 * handshake has bytes to write), or -errno. */
static int flush_tls(struct conn *c, uint64_t *sent, size_t max)
{
	if (!tls_stream_ready(c->tls)) {
		int rc = tls_stream_handshake(c->tls);
		if (rc == -EAGAIN && !c->pending) {
			c->want_out = tls_stream_unsent(c->tls) > 0;
			return 0;
		}
		if (rc)
			return rc == -EAGAIN ? -ENOTCONN : rc;
	}
	uint64_t was = *sent;
	while (head_ready(c) && !tls_stream_unsent(c->tls) && *sent - was < max) {
		struct iovec v[2];
		int k = seg_iov(&c->seg[c->head], v, 2);
		ssize_t n = k ? tls_stream_send(c->tls, v[0].iov_base, v[0].iov_len) : 0;
		if (n == -EAGAIN)
			break;
		if (n < 0)
			return (int)n;
		advance(c, (size_t)n, sent); /* a part (BATCH): the rest on the next turn */
	}
	if (tls_stream_unsent(c->tls)) {
		ssize_t n = tls_stream_send(c->tls, NULL, 0); /* pushes its records, if it can */
		if (n < 0 && n != -EAGAIN)
			return (int)n;
	}
	return 1;
}

int conn_flush(struct conn *c, uint64_t *sent, size_t max)
{
	if (c->tls) {
		int rc = flush_tls(c, sent, max);
		if (rc <= 0)
			return rc;
	}
	size_t left = max;
	while (!c->tls && head_ready(c) && left) {
		struct iovec v[IOV_MAX_OUT];
		int k = 0;
		size_t len = 0;
		for (size_t i = c->head; i < c->n && k + 2 <= IOV_MAX_OUT && len < left; i++) {
			if (!settle(c, &c->seg[i]))
				break;
			int j = seg_iov(&c->seg[i], v + k, IOV_MAX_OUT - k);
			for (int q = k; q < k + j; q++)
				len += v[q].iov_len;
			k += j;
		}
		if (!k) {
			drop_sent(c); /* empty pieces (failed encodings) */
			continue;
		}
		for (; len > left; k--) { /* no more than left: the last pieces cut or left out */
			size_t over = len - left;
			if (v[k - 1].iov_len > over) {
				v[k - 1].iov_len -= over;
				break;
			}
			len -= v[k - 1].iov_len;
		}
		struct msghdr mh = { .msg_iov = v, .msg_iovlen = (size_t)k };
		ssize_t n = sendmsg(c->fd, &mh, MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			if (errno == EAGAIN || errno == EWOULDBLOCK)
				break;
			return -errno;
		}
		advance(c, (size_t)n, sent);
		left -= (size_t)n;
	}
	c->want_out = head_ready(c) || (c->tls && tls_stream_unsent(c->tls));
	return 0;
}

void conn_throttle(struct conn *c, uint64_t max_pending)
{
	uint64_t pend = conn_pending(c);
	if (!c->reading && pend < max_pending)
		c->reading = true; /* resume input once the peer reads again */
	else if (c->reading && pend > 2 * max_pending)
		c->reading = false;
}

static struct conn_seg *seg_new(struct conn *c)
{
	if (c->n == c->cap && c->head > c->n / 2) {
		memmove(c->seg, c->seg + c->head, (c->n - c->head) * sizeof *c->seg);
		c->n -= c->head;
		c->head = 0;
	}
	if (c->n == c->cap) {
		c->cap = c->cap ? 2 * c->cap : 16;
		c->seg = xrealloc(c->seg, c->cap * sizeof *c->seg);
	}
	struct conn_seg *g = &c->seg[c->n++];
	*g = (struct conn_seg){ 0 };
	pbuf_init(&g->b);
	return g;
}

struct pbuf *conn_msg_begin(struct conn *c)
{
	struct conn_seg *g = c->n > c->head ? &c->seg[c->n - 1] : NULL;
	if (!g || g->e || g->b.len >= MSG_SEG)
		g = seg_new(c);
	c->owned -= g->b.cap;
	return &g->b;
}

void conn_msg_end(struct conn *c)
{
	struct conn_seg *g = &c->seg[c->n - 1];
	c->owned += g->b.cap;
	uint64_t unsent = g->b.len - g->off;
	c->pending = c->pending - g->counted + unsent;
	g->counted = unsent;
}

void conn_put_tile(struct conn *c, struct etile *e, const struct proto_tile *pt, uint32_t part)
{
	struct conn_seg *g = seg_new(c);
	g->e = etile_ref(e);
	g->part = part;
	g->pt = *pt;
	g->pt.payload = NULL;
	g->pt.payload_len = 0;
	g->counted = etile_frame_bytes(e);
	c->pending += g->counted;
	settle(c, g);
}

size_t conn_recall(struct conn *c, bool (*drop)(void *ud, const struct tile_key *k), void *ud,
		   uint64_t *bytes)
{
	size_t keep = c->head, gone = 0;
	*bytes = 0;
	for (size_t i = c->head; i < c->n; i++) {
		struct conn_seg *g = &c->seg[i];
		if (g->e && !g->off && drop(ud, &g->pt.key)) {
			*bytes += g->counted;
			c->pending -= g->counted;
			seg_fini(c, g);
			gone++;
			continue;
		}
		if (g->e && g->part && g->off && g->off < g->end && drop(ud, &g->pt.key)) {
			/* begun: it stops after the part the socket has (the peer drops it) */
			struct part_at a = part_of(g, g->off);
			size_t cut = g->off == a.start ? g->off : a.start + a.hlen + a.plen;
			if (cut < g->end) {
				*bytes += g->end - cut;
				c->pending -= g->end - cut;
				g->counted -= g->end - cut;
				g->end = cut;
				gone++;
			}
		}
		c->seg[keep++] = *g;
	}
	c->n = keep;
	drop_sent(c);
	c->want_out = head_ready(c) || (c->tls && tls_stream_unsent(c->tls));
	return gone;
}
