/* net — see net.h. Reads go into one growable buffer that proto_decode looks at until a frame
 * is whole; a decoded frame is consumed at the start of the next net_recv, because a TILE's
 * payload points into it. A tile sent in parts (TILE_PART) is put together in a buffer of
 * its own and handed out as one TILE; any other frame before its last part means the server
 * stopped it (its bytes are dropped and counted). Deadlines are absolute (CLOCK_MONOTONIC)
 * so EINTR and partial reads never stretch a timeout.
 */
#include "net.h"

#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/xalloc.h"
#include "net_tls.h"

#define READ_CHUNK 65536

struct net_conn {
	int fd;
	int timeout_ms;
	char peer[272];
	struct pbuf rd;	     /* bytes received, not yet consumed */
	size_t consume;	     /* size of the frame returned last (consumed on the next recv) */
	struct proto_hello_ok hello;
	char server_name[PROTO_MAX_NAME + 1];
	uint32_t next_req;
	struct tilecodec *tc; /* created on first tile */
	struct net_tls *tls;  /* NULL: plain */
	/* Until the handshake is done (net_connect_step): */
	enum {
		PH_READY = 0,
		PH_CONNECTING,
		PH_CONNECTED,
		PH_TLS,
		PH_HELLO_SEND,
		PH_HELLO_WAIT
	} phase;
	uint32_t offered;		    /* codecs offered in HELLO */
	struct pbuf part;		    /* a tile arriving in parts: its payload so far */
	struct proto_tile part_tile;	    /* its fields (from the first part) */
	bool part_open;			    /* some of its parts came, not the last */
	uint64_t part_wire;		    /* its parts' bytes on the wire so far */
	uint64_t last_wire, parts_dropped;  /* net_last_wire, net_parts_dropped */
	struct pbuf out;		    /* HELLO's bytes not yet sent */
	struct addrinfo *ai_list, *ai;	    /* a TCP name's addresses, the one being tried */
	bool use_tls;			    /* TLS before HELLO: */
	char *tls_ca;			    /* its CA file (NULL: the system's trust store) */
	char tls_host[256];		    /* the name its certificate must carry */
};

/* Milliseconds left until deadline (-1: no deadline), never negative. */
static int left_ms(int64_t deadline)
{
	if (deadline < 0)
		return -1;
	int64_t l = deadline - (int64_t)(clock_now_ns() / 1000000u);
	return l < 0 ? 0 : l > 0x7fffffff ? 0x7fffffff : (int)l;
}

static int64_t deadline_of(int timeout_ms)
{
	return timeout_ms < 0 ? -1 : (int64_t)(clock_now_ns() / 1000000u) + timeout_ms;
}

/* Waits for events on fd until deadline. Returns 1 ready, 0 timed out, -errno. */
static int wait_fd(int fd, short ev, int64_t deadline)
{
	for (;;) {
		struct pollfd p = { .fd = fd, .events = ev };
		int r = poll(&p, 1, left_ms(deadline));
		if (r > 0)
			return 1;
		if (r == 0)
			return 0;
		if (errno != EINTR)
			return -errno;
	}
}

int net_code_errno(uint16_t code)
{
	switch (code) {
	case PROTO_E_NOT_FOUND: return ENOENT;
	case PROTO_E_AUTH: return EACCES;
	case PROTO_E_VERSION: return EPROTONOSUPPORT;
	case PROTO_E_LIMIT: return E2BIG;
	case PROTO_E_INVALID: return EINVAL;
	case PROTO_E_UNAVAILABLE: return EIO;
	case PROTO_E_BUSY: return EBUSY;
	case PROTO_E_SHUTDOWN: return ESHUTDOWN;
	case PROTO_E_PROTOCOL:
	case PROTO_E_STATE: return EPROTO;
	default: return EREMOTEIO;
	}
}

void net_error_text(const struct net_conn *c, const struct proto_error *e, char err[256])
{
	const char *name = proto_code_name(e->code);
	err_set(err, "%s: %s: %s", c->peer, name ? name : "internal",
		e->message && e->message[0] ? e->message : "(no message)");
}

int net_token_load(const char *file, uint8_t buf[PROTO_MAX_TOKEN], uint16_t *len, char err[256])
{
	size_t n = 0;
	*len = 0;
	if (file) {
		FILE *f = fopen(file, "rb");
		if (!f) {
			int e = errno;
			err_set(err, "token file %s: %s", file, strerror(e));
			return -e;
		}
		uint8_t tmp[PROTO_MAX_TOKEN + 2];
		n = fread(tmp, 1, sizeof tmp, f);
		int bad = ferror(f);
		fclose(f);
		if (bad) {
			err_set(err, "token file %s: read error", file);
			return -EIO;
		}
		while (n && (tmp[n - 1] == '\n' || tmp[n - 1] == '\r' || tmp[n - 1] == ' ' ||
			     tmp[n - 1] == '\t'))
			n--;
		if (n > PROTO_MAX_TOKEN) {
			err_set(err, "token file %s: longer than %d bytes", file,
				PROTO_MAX_TOKEN);
			return -E2BIG;
		}
		memcpy(buf, tmp, n);
	} else {
		const char *s = getenv("CLIPMAP_TOKEN");
		if (s) {
			n = strlen(s);
			while (n && (s[n - 1] == '\n' || s[n - 1] == ' '))
				n--;
			if (n > PROTO_MAX_TOKEN) {
				err_set(err, "$CLIPMAP_TOKEN is longer than %d bytes",
					PROTO_MAX_TOKEN);
				return -E2BIG;
			}
			memcpy(buf, s, n);
		}
	}
	*len = (uint16_t)n;
	return 0;
}

/* Waits for the socket until deadline; what for says what for ("sending"). Returns 0, or
 * -ETIMEDOUT / -errno with err filled. */
static int wait_or_fail(struct net_conn *c, short ev, int64_t deadline, const char *what,
			char err[256])
{
	int r = wait_fd(c->fd, ev, deadline);
	if (r > 0)
		return 0;
	if (r == 0) {
		err_set(err, "%s: timed out %s", c->peer, what);
		return -ETIMEDOUT;
	}
	err_set(err, "%s: poll: %s", c->peer, strerror(-r));
	return r;
}

/* Sends what the socket takes of p[0 .. n) once. Returns the count (0: interrupted, try
 * again), -EAGAIN, or -errno with err filled. */
static ssize_t send_some(struct net_conn *c, const uint8_t *p, size_t n, char err[256])
{
	if (c->tls)
		return net_tls_send(c->tls, p, n, err);
	ssize_t w = send(c->fd, p, n, MSG_NOSIGNAL);
	if (w > 0 || (w < 0 && errno == EINTR))
		return w > 0 ? w : 0;
	if (w < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
		return -EAGAIN;
	int e = w < 0 ? errno : EPIPE;
	err_set(err, "%s: sending: %s", c->peer, strerror(e));
	return -e;
}

/* Writes all of p[0 .. n) before deadline. */
static int write_all(struct net_conn *c, const uint8_t *p, size_t n, int64_t deadline,
		     char err[256])
{
	while (n) {
		ssize_t w = send_some(c, p, n, err);
		if (w == -EAGAIN) {
			int rc = wait_or_fail(c, POLLOUT, deadline, "sending", err);
			if (rc)
				return rc;
			continue;
		}
		if (w < 0)
			return (int)w;
		p += w;
		n -= (size_t)w;
	}
	return 0;
}

int net_send(struct net_conn *c, const struct proto_msg *m, char err[256])
{
	struct pbuf b;
	char e2[256];
	pbuf_init(&b);
	ssize_t n = proto_encode(&b, m, e2);
	if (n < 0) {
		const char *t = proto_type_name(m->type);
		err_set(err, "cannot encode %s for %s: %s", t ? t : "message", c->peer, e2);
		pbuf_fini(&b);
		return (int)n;
	}
	int rc = write_all(c, b.data, b.len, deadline_of(c->timeout_ms), err);
	pbuf_fini(&b);
	return rc;
}

/* A TILE_PART of wire bytes: returns 1 when it completed its tile (in c->part), 0 when more
 * parts are to come, or -EBADMSG (a part out of order, or parts never agreed in HELLO_OK). */
static int take_part(struct net_conn *c, const struct proto_tile_part *p, size_t wire,
		     char err[256])
{
	if (!(c->hello.codecs & PROTO_FEAT_PARTS)) {
		err_set(err, "%s: bad message from server: TILE_PART, which this session did not "
			"agree to", c->peer);
		return -EBADMSG;
	}
	if (p->offset == 0) {
		c->part.len = 0;
		if (pbuf_reserve(&c->part, p->total)) {
			err_set(err, "%s: no memory for a tile of %u bytes", c->peer, p->total);
			return -ENOMEM;
		}
		c->part_tile = p->tile;
		c->part_open = true;
		c->part_wire = 0;
	} else if (!c->part_open || p->offset != c->part.len ||
		   p->total != c->part_tile.payload_len) {
		err_set(err, "%s: bad message from server: a part at byte %u of a %u-byte tile, "
			"where %zu bytes of a %u-byte tile came", c->peer, p->offset, p->total,
			c->part_open ? c->part.len : 0,
			c->part_open ? c->part_tile.payload_len : 0);
		return -EBADMSG;
	}
	memcpy(c->part.data + c->part.len, p->bytes, p->len);
	c->part.len += p->len;
	c->part_wire += wire;
	if (c->part.len < p->total)
		return 0;
	c->part_open = false;
	return 1;
}

int net_recv(struct net_conn *c, struct proto_msg *m, int timeout_ms, char err[256])
{
	if (c->consume) {
		pbuf_consume(&c->rd, c->consume);
		c->consume = 0;
	}
	int64_t deadline = deadline_of(timeout_ms);
	for (;;) {
		size_t need = 0;
		char e2[256];
		ssize_t r = proto_decode(c->rd.data, c->rd.len, m, &need, e2);
		if (r > 0 && c->part_open &&
		    !(m->type == PROTO_TILE_PART && m->tile_part.offset != 0)) {
			c->parts_dropped += c->part_wire; /* the server stopped that tile */
			c->part_open = false;
		}
		if (r > 0 && m->type == PROTO_TILE_PART) {
			int rc = take_part(c, &m->tile_part, (size_t)r, err);
			proto_msg_fini(m);
			pbuf_consume(&c->rd, (size_t)r);
			if (rc < 0)
				return rc;
			if (rc == 0)
				continue;
			*m = (struct proto_msg){ .type = PROTO_TILE, .tile = c->part_tile };
			m->tile.payload = c->part.data;
			m->tile.payload_len = (uint32_t)c->part.len;
			c->last_wire = c->part_wire;
			return 0;
		}
		if (r > 0) {
			c->consume = (size_t)r;
			c->last_wire = (size_t)r;
			return 0;
		}
		if (r < 0) {
			err_set(err, "%s: bad message from server: %s", c->peer, e2);
			return (int)r;
		}
		size_t want = need > READ_CHUNK ? need : READ_CHUNK;
		pbuf_reserve(&c->rd, want);
		ssize_t n;
		if (c->tls) {
			n = net_tls_recv(c->tls, c->rd.data + c->rd.len, c->rd.cap - c->rd.len, err);
			if (n < 0 && n != -EAGAIN)
				return (int)n;
			if (n == -EAGAIN) {
				n = -1;
				errno = EAGAIN;
			}
		} else {
			n = recv(c->fd, c->rd.data + c->rd.len, c->rd.cap - c->rd.len, MSG_DONTWAIT);
		}
		if (n > 0) {
			c->rd.len += (size_t)n;
			continue;
		}
		if (n == 0) {
			if (c->rd.len)
				err_set(err, "%s: connection closed by the server in the middle "
					"of a message (%zu bytes of it received)", c->peer, c->rd.len);
			else
				err_set(err, "%s: connection closed by the server", c->peer);
			return -ECONNRESET;
		}
		if (errno == EINTR)
			continue;
		if (errno != EAGAIN && errno != EWOULDBLOCK) {
			int e = errno;
			err_set(err, "%s: receiving: %s", c->peer, strerror(e));
			return -e;
		}
		if (timeout_ms == 0) {
			err_set(err, "%s: no complete message yet", c->peer);
			return -EAGAIN;
		}
		int w = wait_fd(c->fd, POLLIN, deadline);
		if (w == 0) {
			err_set(err, "%s: no answer from the server within %.1f s", c->peer,
				timeout_ms / 1000.0);
			return -ETIMEDOUT;
		}
		if (w < 0) {
			err_set(err, "%s: poll: %s", c->peer, strerror(-w));
			return w;
		}
	}
}

int net_expect(struct net_conn *c, uint16_t type, struct proto_msg *m, int timeout_ms,
	       void (*skip_fn)(void *ud, const struct proto_msg *m), void *ud, char err[256])
{
	int64_t deadline = deadline_of(timeout_ms);
	for (;;) {
		int rc = net_recv(c, m, deadline < 0 ? -1 : left_ms(deadline), err);
		if (rc == -EAGAIN) { /* timeout_ms was 0 or the deadline passed */
			err_set(err, "%s: no answer from the server within %.1f s", c->peer,
				timeout_ms / 1000.0);
			return -ETIMEDOUT;
		}
		if (rc)
			return rc;
		if (m->type == type)
			return 0;
		if (m->type == PROTO_ERROR) {
			net_error_text(c, &m->error, err);
			rc = -net_code_errno(m->error.code);
			proto_msg_fini(m);
			return rc;
		}
		if (m->type == PROTO_TILE || m->type == PROTO_TILE_FAIL ||
		    m->type == PROTO_PREFETCH_PROGRESS) {
			if (skip_fn)
				skip_fn(ud, m);
			proto_msg_fini(m);
			continue;
		}
		if (m->type == PROTO_BYE) {
			err_set(err, "%s: the server ended the session", c->peer);
			proto_msg_fini(m);
			return -ECONNRESET;
		}
		const char *got = proto_type_name(m->type), *exp = proto_type_name(type);
		err_set(err, "%s: expected %s, got %s", c->peer, exp ? exp : "?",
			got ? got : "?");
		proto_msg_fini(m);
		return -EPROTO;
	}
}

/* The HELLO for o, encoded into b (the token read as net_token_load reads it). */
static int hello_encode(const struct net_opts *o, uint32_t codecs, struct pbuf *b, char err[256])
{
	uint8_t tok[PROTO_MAX_TOKEN];
	uint16_t toklen = 0;
	int rc = net_token_load(o->token_file, tok, &toklen, err);
	if (rc)
		return rc;
	struct proto_msg h = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .codecs = codecs, .token = tok, .token_len = toklen,
					  .name = o->name ? o->name : "clipmap-client/1" } };
	char e2[256];
	ssize_t n = proto_encode(b, &h, e2);
	if (n < 0) {
		err_set(err, "cannot encode HELLO: %s", e2);
		return (int)n;
	}
	return 0;
}

/* The server's answer m to HELLO: HELLO_OK is kept in c, anything else is the error. */
static int hello_answer(struct net_conn *c, const struct proto_msg *m, char err[256])
{
	uint32_t codecs = c->offered;
	if (m->type == PROTO_ERROR) {
		const char *name = proto_code_name(m->error.code);
		err_set(err, "%s refused the connection: %s: %s", c->peer,
			name ? name : "internal", m->error.message ? m->error.message : "");
		return -net_code_errno(m->error.code);
	}
	if (m->type != PROTO_HELLO_OK) {
		const char *t = proto_type_name(m->type);
		err_set(err, "%s: expected HELLO_OK, got %s", c->peer, t ? t : "?");
		return -EPROTO;
	}
	if (m->hello_ok.version != PROTO_VERSION || (m->hello_ok.codecs & ~codecs)) {
		err_set(err, "%s: server chose version %u and codecs 0x%x, we offered %u and "
			"0x%x", c->peer, m->hello_ok.version, m->hello_ok.codecs, PROTO_VERSION, codecs);
		return -EPROTO;
	}
	c->hello = m->hello_ok;
	snprintf(c->server_name, sizeof c->server_name, "%s",
		 m->hello_ok.name ? m->hello_ok.name : "");
	c->hello.name = c->server_name;
	return 0;
}

static int split_hostport(const char *hp, char *host, size_t hn, char *port, size_t pn);

/* A connection in phase PH_CONNECTED over fd (or PH_CONNECTING with fd -1), its HELLO
 * encoded. Returns 0 or -errno with err filled (nothing allocated then). */
static int conn_new(int fd, const char *peer, const struct net_opts *o, struct net_conn **out,
		    char err[256])
{
	struct net_conn *c = xcalloc(1, sizeof *c);
	c->fd = fd;
	c->timeout_ms = o->timeout_ms ? o->timeout_ms : NET_DEFAULT_TIMEOUT_MS;
	c->offered = (o->codecs ? o->codecs : TCODEC_LOSSLESS_MASK) |
		     (o->whole_tiles ? 0 : PROTO_FEAT_PARTS);
	c->phase = fd >= 0 ? PH_CONNECTED : PH_CONNECTING;
	snprintf(c->peer, sizeof c->peer, "%s", peer ? peer : "server");
	/* TLS over TCP (the daemon's Unix socket is always plain): --tls-ca, $CLIPMAP_TLS_CA or
	 * --tls; the certificate must name the host of o->hostport (else of the peer's name). */
	const char *ca = o->tls_ca;
	const char *env = getenv("CLIPMAP_TLS_CA");
	if (!ca && o->hostport && env && *env)
		ca = env;
	c->use_tls = (ca || o->tls) && !(fd < 0 && !o->hostport);
	if (c->use_tls) {
		char port[32];
		const char *hp = o->hostport ? o->hostport : c->peer;
		if (split_hostport(hp, c->tls_host, sizeof c->tls_host, port, sizeof port))
			snprintf(c->tls_host, sizeof c->tls_host, "%.255s", hp);
		c->tls_ca = ca ? xstrdup(ca) : NULL;
	}
	pbuf_init(&c->rd);
	pbuf_init(&c->out);
	pbuf_init(&c->part);
	int rc = hello_encode(o, c->offered, &c->out, err);
	if (rc) {
		pbuf_fini(&c->out);
		pbuf_fini(&c->rd);
		free(c->tls_ca);
		free(c);
		return rc;
	}
	*out = c;
	return 0;
}

/* Frees c without a word to the server (a connection that never completed its handshake). */
static void conn_free(struct net_conn *c)
{
	net_tls_destroy(c->tls);
	free(c->tls_ca);
	if (c->fd >= 0)
		close(c->fd);
	if (c->ai_list)
		freeaddrinfo(c->ai_list);
	pbuf_fini(&c->out);
	pbuf_fini(&c->rd);
	pbuf_fini(&c->part);
	tilecodec_destroy(c->tc);
	free(c);
}

/* Connects to the Unix socket path; the socket is left non-blocking. may_wait: a full listen
 * queue is waited for (blocking connect), else it fails the attempt (EAGAIN). */
static int start_unix(struct net_conn *c, const char *path, bool may_wait, char err[256])
{
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof a.sun_path) {
		err_set(err, "cannot connect to %s: socket path longer than %zu bytes", path,
			sizeof a.sun_path - 1);
		return -ENAMETOOLONG;
	}
	memcpy(a.sun_path, path, strlen(path) + 1);
	int s = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | (may_wait ? 0 : SOCK_NONBLOCK), 0);
	if (s < 0) {
		int e = errno;
		err_set(err, "cannot connect to %s: socket: %s", path, strerror(e));
		return -e;
	}
	/* A Unix connect does not wait for the peer, only for room in its listen queue. */
	int fl;
	while (connect(s, (struct sockaddr *)&a, sizeof a) < 0) {
		if (errno == EINTR)
			continue;
		int e = errno;
		err_set(err, "cannot connect to %s: %s", path, strerror(e));
		close(s);
		return -e;
	}
	if (may_wait && ((fl = fcntl(s, F_GETFL)) < 0 || fcntl(s, F_SETFL, fl | O_NONBLOCK) < 0)) {
		int e = errno;
		err_set(err, "cannot connect to %s: fcntl: %s", path, strerror(e));
		close(s);
		return -e;
	}
	c->fd = s;
	c->phase = PH_HELLO_SEND;
	return 0;
}

/* Splits "host:port" / "[v6]:port". Returns 0 or -EINVAL. */
static int split_hostport(const char *hp, char *host, size_t hn, char *port, size_t pn)
{
	const char *colon;
	const char *h0 = hp;
	size_t hl;
	if (hp[0] == '[') {
		const char *rb = strchr(hp, ']');
		if (!rb || rb[1] != ':')
			return -EINVAL;
		h0 = hp + 1;
		hl = (size_t)(rb - h0);
		colon = rb + 1;
	} else {
		colon = strrchr(hp, ':');
		if (!colon)
			return -EINVAL;
		hl = (size_t)(colon - hp);
	}
	if (hl == 0 || hl >= hn || !colon[1] || strlen(colon + 1) >= pn)
		return -EINVAL;
	memcpy(host, h0, hl);
	host[hl] = '\0';
	strcpy(port, colon + 1);
	return 0;
}

/* Tries c->ai and the addresses after it until a connect succeeds or is in progress.
 * rc: the last failure so far (for the message when every address fails). */
static int try_next_address(struct net_conn *c, int rc, char err[256])
{
	for (; c->ai; c->ai = c->ai->ai_next) {
		struct addrinfo *ai = c->ai;
		int s = socket(ai->ai_family, ai->ai_socktype | SOCK_CLOEXEC | SOCK_NONBLOCK,
			       ai->ai_protocol);
		if (s < 0) {
			rc = -errno;
			continue;
		}
		int r;
		while ((r = connect(s, ai->ai_addr, ai->ai_addrlen)) < 0 && errno == EINTR)
			;
		if (r == 0 || errno == EINPROGRESS) {
			c->fd = s;
			c->phase = r == 0 ? PH_CONNECTED : PH_CONNECTING;
			return 0;
		}
		rc = -errno;
		close(s);
	}
	err_set(err, "cannot connect to %s: %s", c->peer, strerror(-rc));
	return rc;
}

static int start_tcp(struct net_conn *c, const char *hp, char err[256])
{
	char host[256], port[32];
	if (split_hostport(hp, host, sizeof host, port, sizeof port)) {
		err_set(err, "cannot connect to %s: want HOST:PORT or [ADDR]:PORT", hp);
		return -EINVAL;
	}
	struct addrinfo hints = { .ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM };
	int g = getaddrinfo(host, port, &hints, &c->ai_list);
	if (g) {
		c->ai_list = NULL;
		err_set(err, "cannot connect to %s: %s", hp, gai_strerror(g));
		return g == EAI_SYSTEM ? -errno : g == EAI_NONAME ? -ENOENT : -EHOSTUNREACH;
	}
	c->ai = c->ai_list;
	return try_next_address(c, -ECONNREFUSED, err);
}

/* net_connect_start; may_wait: see start_unix. */
static int connect_begin(const struct net_opts *o, bool may_wait, struct net_conn **out,
			 char err[256])
{
	*out = NULL;
	const char *peer = o->hostport ? o->hostport : o->socket_path;
	if (!peer) {
		err_set(err, "no socket path or HOST:PORT to connect to");
		return -EINVAL;
	}
	struct net_conn *c;
	int rc = conn_new(-1, peer, o, &c, err);
	if (rc)
		return rc;
	rc = o->hostport ? start_tcp(c, o->hostport, err)
			 : start_unix(c, o->socket_path, may_wait, err);
	if (rc) {
		conn_free(c);
		return rc;
	}
	*out = c;
	return 0;
}

int net_connect_start(const struct net_opts *o, struct net_conn **out, char err[256])
{
	return connect_begin(o, false, out, err);
}

short net_connect_events(const struct net_conn *c)
{
	if (c->phase == PH_TLS)
		return c->tls && net_tls_wants_write(c->tls) ? POLLOUT : POLLIN;
	return c->phase == PH_CONNECTING || c->phase == PH_HELLO_SEND ? POLLOUT : POLLIN;
}

/* PH_CONNECTING: the connect's outcome, when there is one. */
static int step_connecting(struct net_conn *c, char err[256])
{
	struct pollfd p = { .fd = c->fd, .events = POLLOUT };
	int r = poll(&p, 1, 0);
	if (r < 0 && errno != EINTR) {
		int e = errno;
		err_set(err, "cannot connect to %s: poll: %s", c->peer, strerror(e));
		return -e;
	}
	if (r <= 0)
		return -EAGAIN;
	int soerr = 0;
	socklen_t sl = sizeof soerr;
	if (getsockopt(c->fd, SOL_SOCKET, SO_ERROR, &soerr, &sl) < 0)
		soerr = errno;
	if (soerr) { /* this address refused: the name's next one, if any */
		close(c->fd);
		c->fd = -1;
		c->ai = c->ai->ai_next;
		int rc = try_next_address(c, -soerr, err);
		return rc ? rc : -EAGAIN;
	}
	c->phase = PH_CONNECTED;
	return 0;
}

int net_connect_step(struct net_conn *c, char err[256])
{
	int rc;
	if (c->phase == PH_CONNECTING && (rc = step_connecting(c, err)))
		return rc;
	if (c->phase == PH_CONNECTED) {
		int one = 1;
		if (c->ai_list &&
		    setsockopt(c->fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one) < 0) {
			int e = errno;
			err_set(err, "cannot connect to %s: TCP_NODELAY: %s", c->peer, strerror(e));
			return -e;
		}
		c->phase = c->use_tls ? PH_TLS : PH_HELLO_SEND;
		if (c->use_tls &&
		    (rc = net_tls_create(c->fd, c->tls_host, c->tls_ca, c->peer, &c->tls, err)))
			return rc;
	}
	if (c->phase == PH_TLS) { /* the certificate checked before a byte of HELLO leaves */
		if ((rc = net_tls_handshake(c->tls, err)))
			return rc;
		c->phase = PH_HELLO_SEND;
	}
	if (c->phase == PH_HELLO_SEND) {
		while (c->out.len) { /* a HELLO (≤ 2 KiB) into an empty socket buffer */
			ssize_t w = send_some(c, c->out.data, c->out.len, err);
			if (w < 0)
				return (int)w; /* -EAGAIN: the socket is full; or the error */
			pbuf_consume(&c->out, (size_t)w);
		}
		c->phase = PH_HELLO_WAIT;
	}
	if (c->phase == PH_HELLO_WAIT) {
		struct proto_msg m = { 0 };
		if ((rc = net_recv(c, &m, 0, err)))
			return rc;
		rc = hello_answer(c, &m, err);
		proto_msg_fini(&m);
		if (rc)
			return rc;
		int fl = fcntl(c->fd, F_GETFL);
		if (fl < 0 || fcntl(c->fd, F_SETFL, fl & ~O_NONBLOCK) < 0) {
			int e = errno;
			err_set(err, "%s: fcntl: %s", c->peer, strerror(e));
			return -e;
		}
		if (c->ai_list) {
			freeaddrinfo(c->ai_list);
			c->ai_list = c->ai = NULL;
		}
		c->phase = PH_READY;
	}
	return 0;
}

/* Drives a started connection to its end, waiting at most the connection's timeout for the
 * connect and again for the handshake. Frees c on failure. */
static int connect_finish(struct net_conn *c, struct net_conn **out, char err[256])
{
	int64_t deadline = deadline_of(c->timeout_ms);
	bool connecting = c->phase == PH_CONNECTING;
	int rc;
	while ((rc = net_connect_step(c, err)) == -EAGAIN) {
		if (connecting && c->phase != PH_CONNECTING) {
			connecting = false; /* the handshake has its own time */
			deadline = deadline_of(c->timeout_ms);
		}
		int w = wait_fd(c->fd, net_connect_events(c), deadline);
		if (w == 0 && connecting)
			err_set(err, "cannot connect to %s: %s", c->peer, strerror(ETIMEDOUT));
		else if (w == 0 && c->phase == PH_HELLO_SEND)
			err_set(err, "%s: timed out sending", c->peer);
		else if (w == 0 && c->phase == PH_TLS)
			err_set(err, "%s: timed out in the TLS handshake", c->peer);
		else if (w == 0)
			err_set(err, "%s: no answer from the server within %.1f s", c->peer,
				c->timeout_ms / 1000.0);
		else if (w < 0)
			err_set(err, "%s: poll: %s", c->peer, strerror(-w));
		if (w <= 0) {
			rc = w ? w : -ETIMEDOUT;
			break;
		}
	}
	if (rc) {
		conn_free(c);
		return rc;
	}
	*out = c;
	return 0;
}

int net_connect_fd(int fd, const char *peer, const struct net_opts *o, struct net_conn **out,
		   char err[256])
{
	*out = NULL;
	struct net_conn *c;
	int rc = conn_new(fd, peer, o, &c, err);
	if (rc) {
		close(fd);
		return rc;
	}
	return connect_finish(c, out, err);
}

int net_connect(const struct net_opts *o, struct net_conn **out, char err[256])
{
	struct net_conn *c;
	int rc = connect_begin(o, true, &c, err);
	return rc ? rc : connect_finish(c, out, err);
}

int net_backoff_ms(unsigned attempt, int base_ms, int cap_ms, unsigned *seed)
{
	int64_t d = base_ms > 0 ? base_ms : 1;
	for (unsigned i = 1; i < attempt && d < cap_ms; i++)
		d *= 2;
	if (d > cap_ms)
		d = cap_ms;
	int64_t half = d / 2;
	return (int)(d - (half ? rand_r(seed) % (half + 1) : 0));
}

void net_close(struct net_conn *c)
{
	if (!c)
		return;
	struct pbuf b;
	pbuf_init(&b);
	struct proto_msg bye = { .type = PROTO_BYE };
	char err[256];
	if (c->phase == PH_READY && proto_encode(&b, &bye, NULL) > 0) {
		if (c->tls)
			(void)net_tls_send(c->tls, b.data, b.len, err); /* best effort: never waits */
		else
			(void)send(c->fd, b.data, b.len, MSG_NOSIGNAL | MSG_DONTWAIT);
	}
	pbuf_fini(&b);
	conn_free(c);
}

int net_fd(const struct net_conn *c) { return c->fd; }
bool net_is_tls(const struct net_conn *c) { return c->tls != NULL; }
const char *net_peer(const struct net_conn *c) { return c->peer; }
const struct proto_hello_ok *net_hello(const struct net_conn *c) { return &c->hello; }
uint32_t net_next_req(struct net_conn *c) { return ++c->next_req; }
uint64_t net_last_wire(const struct net_conn *c) { return c->last_wire; }
uint64_t net_parts_dropped(const struct net_conn *c) { return c->parts_dropped; }
uint64_t net_parts_open(const struct net_conn *c) { return c->part_open ? c->part_wire : 0; }

int net_tile_decode(struct net_conn *c, const struct proto_tile *t, void *texels, size_t cap,
		    char err[256])
{
	if (!c->tc)
		c->tc = tilecodec_create();
	char e2[256];
	int rc = tilecodec_decode(c->tc, &t->enc, t->payload, t->payload_len, texels, cap, e2);
	if (rc)
		err_set(err, "%s: tile (%u, %u, %u, %u) of layer %u: %s", c->peer,
			t->key.lx, t->key.ly, t->key.x, t->key.y, t->layer, e2);
	return rc;
}

int net_open_planet(struct net_conn *c, const char *name, struct proto_msg *m, int timeout_ms,
		    char err[256])
{
	uint32_t req = net_next_req(c);
	struct proto_msg o = { .type = PROTO_OPEN, .open = { .req = req, .name = name } };
	int rc = net_send(c, &o, err);
	if (rc)
		return rc;
	return net_expect(c, PROTO_OPENED, m, timeout_ms, NULL, NULL, err);
}
