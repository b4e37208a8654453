/* conn — see conn.h. Output is compacted only once more than 1 MiB at its head has gone out
 * and that is over half the buffer, so a steady stream does not memmove on every send. Input
 * is consumed frame by frame (pbuf_consume), so a partial frame simply waits for more bytes.
 */
#include "conn.h"

#include <errno.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/socket.h>
#include <unistd.h>

#include "common/errbuf.h"
#include "tls.h"

#define RECV_CHUNK 65536

void conn_init(struct conn *c, int fd)
{
	*c = (struct conn){ .fd = fd, .reading = true };
	pbuf_init(&c->in);
	pbuf_init(&c->out);
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

void conn_fini(struct conn *c)
{
	pbuf_fini(&c->in);
	pbuf_fini(&c->out);
}

uint32_t conn_events(const struct conn *c)
{
	return (c->reading ? EPOLLIN | EPOLLRDHUP : 0) | (c->want_out ? EPOLLOUT : 0);
}

uint64_t conn_pending(const struct conn *c)
{
	return c->out.len - c->out_off;
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

/* Writes over TLS as far as the socket takes (TLS's own unsent records first). Returns 1 when
 * that was done (the caller updates the buffer), 0 while the handshake waits with nothing to
 * send (want_out set while the handshake has bytes to write), or -errno. */
static int flush_tls(struct conn *c, uint64_t *sent)
{
	if (!tls_stream_ready(c->tls)) {
		int rc = tls_stream_handshake(c->tls);
		if (rc == -EAGAIN && c->out_off == c->out.len) {
			c->want_out = tls_stream_unsent(c->tls) > 0;
			return 0;
		}
		if (rc)
			return rc == -EAGAIN ? -ENOTCONN : rc;
	}
	do {
		ssize_t n = tls_stream_send(c->tls, c->out.data + c->out_off, c->out.len - c->out_off);
		if (n == -EAGAIN)
			break;
		if (n < 0)
			return (int)n;
		c->out_off += (size_t)n;
		*sent += (uint64_t)n;
	} while (c->out_off < c->out.len && !tls_stream_unsent(c->tls));
	return 1;
}

int conn_flush(struct conn *c, uint64_t *sent)
{
	if (c->tls) {
		int rc = flush_tls(c, sent);
		if (rc <= 0)
			return rc;
	}
	while (!c->tls && c->out_off < c->out.len) {
		ssize_t n = send(c->fd, c->out.data + c->out_off, c->out.len - c->out_off,
				 MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			if (errno == EAGAIN || errno == EWOULDBLOCK)
				break;
			return -errno;
		}
		c->out_off += (size_t)n;
		*sent += (uint64_t)n;
	}
	if (c->out_off == c->out.len) {
		c->out.len = c->out_off = 0;
	} else if (c->out_off > (1u << 20) && c->out_off > c->out.len / 2) {
		memmove(c->out.data, c->out.data + c->out_off, c->out.len - c->out_off);
		c->out.len -= c->out_off;
		c->out_off = 0;
	}
	c->want_out = c->out_off < c->out.len || (c->tls && tls_stream_unsent(c->tls));
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

void conn_compact(struct conn *c)
{
	if (!c->out_off)
		return;
	memmove(c->out.data, c->out.data + c->out_off, c->out.len - c->out_off);
	c->out.len -= c->out_off;
	c->out_off = 0;
}
