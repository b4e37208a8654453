/* bench_server — clipmapd over loopback TCP: round trip of a cached quad (4 tiles of 256²
 * RGBA8: WANT sent → 4th TILE decoded), p50/p99; cached-tile throughput to 1 and to 50
 * sessions, and its peers measured in the same run: a bare loopback TCP stream of TILE frames
 * of the same size, sent by a thread from one prepared buffer and received and decoded by the
 * same client code — from 8 frames (2 MiB, in the CPU's cache: the most the client and the
 * loopback take) and from 512 distinct frames (128 MiB in memory, as the session's tiles are) —
 * and 50 such streams. Each figure is the median of 5 trials, the daemon's and the peers'
 * alternated. Prints the ratios (1 session / bare stream, 50 sessions / 1 session), which stay
 * meaningful on a loaded machine where the absolute figures do not. Starts build/clipmapd on a temporary config
 * (tests/support/daemon_env).
 */
#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "support/bench_planet.h"
#include "support/daemon_env.h"

static const char planet[] = BENCH_PLANET_INI;

static void die(const char *what)
{
	fprintf(stderr, "bench_server: %s\n", what);
	exit(1);
}

struct cl {
	int fd;
	struct pbuf in; /* bytes [off, len) not yet decoded */
	size_t off;
	struct tilecodec *tc;
	uint8_t *px;
};

/* Consumes n decoded bytes: an offset, so a 1 MiB read of several frames is not moved once
 * per frame (the client's cost would cap what is measured). */
static void cl_consume(struct cl *c, size_t n)
{
	c->off += n;
	if (c->off == c->in.len)
		c->off = c->in.len = 0;
}

/* Receives once (up to 1 MiB) after the undecoded bytes, moved to the front first. */
static ssize_t cl_read(struct cl *c)
{
	if (c->off) {
		memmove(c->in.data, c->in.data + c->off, c->in.len - c->off);
		c->in.len -= c->off;
		c->off = 0;
	}
	pbuf_reserve(&c->in, 1 << 20);
	ssize_t n = recv(c->fd, c->in.data + c->in.len, 1 << 20, 0);
	if (n > 0)
		c->in.len += (size_t)n;
	return n;
}

static struct cl *cl_tcp(int port)
{
	struct cl *c = calloc(1, sizeof *c);
	c->fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)port),
				  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	if (connect(c->fd, (struct sockaddr *)&sa, sizeof sa))
		die("connect");
	int one = 1;
	setsockopt(c->fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
	pbuf_init(&c->in);
	c->tc = tilecodec_create();
	c->px = malloc(256 * 256 * 4);
	return c;
}

static void cl_send(struct cl *c, const struct proto_msg *m)
{
	struct pbuf b;
	pbuf_init(&b);
	if (proto_encode(&b, m, NULL) < 0 || send(c->fd, b.data, b.len, MSG_NOSIGNAL) != (ssize_t)b.len)
		die("send");
	pbuf_fini(&b);
}

/* Reads until one whole message is decoded into *m (the caller finis it; a TILE's payload
 * points into the input, valid until the next read). */
static void cl_msg(struct cl *c, struct proto_msg *m)
{
	for (;;) {
		*m = (struct proto_msg){ 0 };
		size_t need;
		ssize_t r = proto_decode(c->in.data + c->off, c->in.len - c->off, m, &need, NULL);
		if (r < 0)
			die("bad frame");
		if (r > 0) {
			if (m->type == PROTO_ERROR)
				die(m->error.message);
			cl_consume(c, (size_t)r);
			return;
		}
		if (cl_read(c) <= 0)
			die("recv");
	}
}

/* The next message's type (TILEs are decoded and checked). */
static uint16_t cl_next(struct cl *c)
{
	struct proto_msg m;
	cl_msg(c, &m);
	if (m.type == PROTO_TILE &&
	    tilecodec_decode(c->tc, &m.tile.enc, m.tile.payload, m.tile.payload_len, c->px,
			     256 * 256 * 4, NULL))
		die("tile decode");
	uint16_t t = m.type;
	proto_msg_fini(&m);
	return t;
}

static void cl_until(struct cl *c, uint16_t type)
{
	while (cl_next(c) != type) {
	}
}

static uint32_t cl_open(struct cl *c)
{
	struct proto_msg h = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .name = "bench" } };
	cl_send(c, &h);
	cl_until(c, PROTO_HELLO_OK);
	struct proto_msg o = { .type = PROTO_OPEN, .open = { .req = 1, .name = "b" } };
	cl_send(c, &o);
	cl_until(c, PROTO_OPENED);
	return 1;
}

static void want(struct cl *c, uint32_t seq, const struct proto_want_entry *e, uint32_t n)
{
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = 1, .seq = seq, .count = n, .entries = e } };
	cl_send(c, &m);
}

/* Receives from n clients until each has had left[i] TILE frames (decoded as frames, not
 * as texels: the client's cost stays small beside the server's). Returns the tiles. */
static uint64_t drain(struct cl **s, int n, int *left)
{
	uint64_t tiles = 0;
	int busy = 0;
	if (n <= 0)
		return 0;
	for (int i = 0; i < n; i++)
		busy += left[i] > 0;
	struct pollfd *pf = calloc((size_t)n, sizeof *pf);
	while (busy) {
		for (int i = 0; i < n; i++)
			pf[i] = (struct pollfd){ .fd = left[i] ? s[i]->fd : -1, .events = POLLIN };
		if (poll(pf, (nfds_t)n, 10000) <= 0)
			die("poll timeout");
		for (int i = 0; i < n; i++) {
			if (!(pf[i].revents & POLLIN))
				continue;
			/* one recv worth, then decode whatever is complete */
			if (cl_read(s[i]) <= 0)
				die("recv");
			for (;;) {
				struct proto_msg m = { 0 };
				size_t need;
				ssize_t rr = proto_decode(s[i]->in.data + s[i]->off,
							  s[i]->in.len - s[i]->off, &m, &need, NULL);
				if (rr < 0)
					die("bad frame");
				if (rr == 0)
					break;
				if (m.type == PROTO_TILE) {
					tiles++;
					if (--left[i] == 0)
						busy--;
				}
				proto_msg_fini(&m);
				cl_consume(s[i], (size_t)rr);
			}
		}
	}
	free(pf);
	return tiles;
}

/* ---- the peer: a bare loopback stream of TILE frames --------------------------------------- */

struct bare {
	int lfd;
	size_t frames;	/* to send: whole passes over buf */
	int distinct;	/* frames in buf */
	struct pbuf buf; /* distinct frames, sent over and over */
};
#define BARE_BATCH 8	 /* frames in the hot peer's buffer: 2 MiB, in the CPU's cache */
#define BARE_DISTINCT 512 /* the cold peer's: 128 MiB, as many tiles as the session's set */

static void *bare_send(void *arg)
{
	struct bare *b = arg;
	int fd = accept(b->lfd, NULL, NULL);
	if (fd < 0)
		die("bare: accept");
	size_t passes = b->frames / (size_t)b->distinct;
	size_t chunk = b->buf.len / (size_t)b->distinct * BARE_BATCH; /* 2 MiB a call, at most */
	for (size_t i = 0; i < passes; i++) {
		size_t off = 0;
		while (off < b->buf.len) {
			size_t k = b->buf.len - off < chunk ? b->buf.len - off : chunk;
			ssize_t n = send(fd, b->buf.data + off, k, MSG_NOSIGNAL);
			if (n <= 0)
				die("bare: send");
			off += (size_t)n;
		}
	}
	close(fd);
	return NULL;
}

/* n raw 256² RGBA8 TILE frames, one after the other, in b (each in its own memory). */
static void bare_frames(struct pbuf *b, int n)
{
	static uint8_t px[256 * 256 * 4];
	for (size_t i = 0; i < sizeof px; i++)
		px[i] = (uint8_t)(i * 2654435761u >> 13);
	pbuf_init(b);
	for (int i = 0; i < n; i++) {
		struct proto_msg m = {
			.type = PROTO_TILE,
			.tile = { .seq = 1, .planet_id = 1, .layer = 0,
				  .key = { .node = 1, .lx = 8, .ly = 7, .x = (uint32_t)i % 256,
					  .y = 1 + (uint32_t)i / 256 },
				  .enc = { .format = PIX_COLOR, .codec = TCODEC_NONE,
					   .filter = TFILTER_NONE, .size = 256,
					   .raw_len = sizeof px,
					   .checksum = tilecodec_checksum(px, sizeof px) },
				  .payload = px, .payload_len = sizeof px } };
		if (proto_encode(b, &m, NULL) < 0)
			die("bare: encode");
	}
}

static int bare_listen(int backlog)
{
	int fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t sl = sizeof sa;
	if (fd < 0 || bind(fd, (struct sockaddr *)&sa, sizeof sa) || listen(fd, backlog) ||
	    getsockname(fd, (struct sockaddr *)&sa, &sl))
		die("bare: listen");
	return fd;
}

static int bare_port(int lfd)
{
	struct sockaddr_in sa;
	socklen_t sl = sizeof sa;
	getsockname(lfd, (struct sockaddr *)&sa, &sl);
	return ntohs(sa.sin_port);
}

static void cl_free(struct cl *c)
{
	close(c->fd);
	pbuf_fini(&c->in);
	tilecodec_destroy(c->tc);
	free(c->px);
	free(c);
}

/* Tiles/s of `frames` raw 256² RGBA8 TILE frames over a bare loopback TCP stream, sent from
 * a buffer of `distinct` frames over and over. */
static double bare_stream(size_t frames, int distinct)
{
	struct bare b = { .frames = frames / (size_t)distinct * (size_t)distinct,
			  .distinct = distinct };
	bare_frames(&b.buf, distinct);
	b.lfd = bare_listen(1);
	pthread_t th;
	if (pthread_create(&th, NULL, bare_send, &b))
		die("bare: thread");
	struct cl *c = cl_tcp(bare_port(b.lfd));
	uint64_t t0 = clock_now_ns();
	for (size_t k = 0; k < b.frames; k++)
		cl_until(c, PROTO_TILE);
	double dt = (clock_now_ns() - t0) * 1e-9;
	pthread_join(th, NULL);
	close(b.lfd);
	cl_free(c);
	pbuf_fini(&b.buf);
	return (double)b.frames / dt;
}

/* The peer of the 50 sessions: one sender thread streams `each` frames to each of n
 * connections at once (non-blocking, whichever socket has room), received by drain(), the
 * 50 sessions' own loop: the most this client and the loopback take over n streams. */
struct bare_many {
	int lfd, n;
	size_t each;
	struct pbuf buf;
};

static void *bare_many_send(void *arg)
{
	struct bare_many *b = arg;
	int *fd = calloc((size_t)b->n, sizeof *fd);
	size_t *pos = calloc((size_t)b->n, sizeof *pos), *rem = calloc((size_t)b->n, sizeof *rem);
	struct pollfd *pf = calloc((size_t)b->n, sizeof *pf);
	for (int i = 0; i < b->n; i++) {
		if ((fd[i] = accept4(b->lfd, NULL, NULL, SOCK_NONBLOCK)) < 0)
			die("bare: accept");
		rem[i] = b->each / BARE_BATCH * b->buf.len;
	}
	for (int busy = b->n; busy;) {
		for (int i = 0; i < b->n; i++)
			pf[i] = (struct pollfd){ .fd = rem[i] ? fd[i] : -1, .events = POLLOUT };
		if (poll(pf, (nfds_t)b->n, 10000) <= 0)
			die("bare: poll");
		for (int i = 0; i < b->n; i++) {
			if (!(pf[i].revents & POLLOUT))
				continue;
			size_t k = b->buf.len - pos[i];
			k = k < rem[i] ? k : rem[i];
			ssize_t r = send(fd[i], b->buf.data + pos[i], k, MSG_NOSIGNAL);
			if (r < 0 && errno != EAGAIN)
				die("bare: send");
			if (r <= 0)
				continue;
			pos[i] = (pos[i] + (size_t)r) % b->buf.len;
			rem[i] -= (size_t)r;
			busy -= rem[i] == 0;
		}
	}
	for (int i = 0; i < b->n; i++)
		close(fd[i]);
	free(fd);
	free(pos);
	free(rem);
	free(pf);
	return NULL;
}

static double bare_streams(int n, size_t each)
{
	struct bare_many b = { .n = n, .each = each / BARE_BATCH * BARE_BATCH };
	bare_frames(&b.buf, BARE_BATCH);
	b.lfd = bare_listen(n);
	pthread_t th;
	if (pthread_create(&th, NULL, bare_many_send, &b))
		die("bare: thread");
	struct cl **c = calloc((size_t)n, sizeof *c);
	int *left = calloc((size_t)n, sizeof *left);
	for (int i = 0; i < n; i++) {
		c[i] = cl_tcp(bare_port(b.lfd));
		left[i] = (int)b.each;
	}
	uint64_t t0 = clock_now_ns();
	uint64_t tiles = drain(c, n, left);
	double dt = (clock_now_ns() - t0) * 1e-9;
	pthread_join(th, NULL);
	close(b.lfd);
	for (int i = 0; i < n; i++)
		cl_free(c[i]);
	free(c);
	free(left);
	pbuf_fini(&b.buf);
	return (double)tiles / dt;
}

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

/* The median of n values (sorts them). */
static double median(double *v, int n)
{
	for (int i = 1; i < n; i++)
		for (int j = i; j > 0 && v[j - 1] > v[j]; j--) {
			double x = v[j];
			v[j] = v[j - 1];
			v[j - 1] = x;
		}
	return n % 2 ? v[n / 2] : (v[n / 2 - 1] + v[n / 2]) / 2;
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	static const char *const keys[] = { "listen.unix =",
					   "listen.tcp = 127.0.0.1:0",
					   "engine.workers = 0",
					   "engine.cache_mb = 1024",
					   "session.max_rate = 0",
					   "session.max_pending_kb = 16384",
					   "log.level = info",
					   NULL };
	const struct daemon_env_conf conf = { .set = keys };
	struct daemon_env d;
	char err[256];
	if (daemon_env_init(&d, "clipmapd-bench") ||
	    daemon_env_planet_text(&d, "b.ini", planet, NULL)) {
		daemon_env_fini(&d);
		die("cannot prepare a temporary directory");
	}
	if (daemon_env_start(&d, &conf, err)) {
		daemon_env_fini(&d);
		die(err);
	}
	int port = d.port;

	/* Round trip of a cached quad: alternate between two quads so each WANT asks for 4 tiles. */
	struct cl *c = cl_tcp(port);
	cl_open(c);
	struct proto_want_entry qa[4], qb[4];
	bench_planet_block(qa, 5, 10, 10, 2, 2);
	bench_planet_block(qb, 5, 20, 10, 2, 2);
	uint32_t seq = 0;
	for (int i = 0; i < 2; i++) { /* warm the cache */
		want(c, ++seq, i ? qb : qa, 4);
		for (int k = 0; k < 4; k++)
			cl_until(c, PROTO_TILE);
	}
	enum { N = 2000 };
	static uint64_t lat[N];
	for (int i = 0; i < N; i++) {
		uint64_t t0 = clock_now_ns();
		want(c, ++seq, i & 1 ? qb : qa, 4);
		for (int k = 0; k < 4; k++)
			cl_until(c, PROTO_TILE);
		lat[i] = clock_now_ns() - t0;
	}
	qsort(lat, N, sizeof lat[0], cmp_u64);
	printf("server/cached quad 4x256² rgba8 loopback tcp round trip: p50 %.3f ms, p99 %.3f ms\n",
	       lat[N / 2] * 1e-6, lat[N * 99 / 100] * 1e-6);

	/* Throughput to one session: 512 cached tiles, alternating two sets. */
	static struct proto_want_entry big[2][512];
	bench_planet_block(big[0], 7, 0, 10, 32, 16);
	bench_planet_block(big[1], 7, 64, 10, 32, 16);
	for (int i = 0; i < 2; i++) {
		want(c, ++seq, big[i], 512);
		for (int k = 0; k < 512; k++)
			cl_until(c, PROTO_TILE);
	}
	/* Each figure is a median of TRIALS, the daemon's and its peer's trials alternated: one
	 * trial is 0.1-0.3 s, and single ones put the 1-session ratio anywhere in 0.71-0.97 on
	 * an idle machine. */
	enum { TRIALS = 5, ROUNDS = 6, NS = 50 };
	double one[TRIALS], bare[TRIALS], cold[TRIALS], r1[TRIALS], r1c[TRIALS];
	for (int t = 0; t < TRIALS; t++) {
		uint64_t t0 = clock_now_ns();
		for (int r = 0; r < ROUNDS; r++) {
			want(c, ++seq, big[r & 1], 512);
			for (int k = 0; k < 512; k++)
				cl_until(c, PROTO_TILE);
		}
		one[t] = ROUNDS * 512 / ((clock_now_ns() - t0) * 1e-9);
		bare[t] = bare_stream((size_t)ROUNDS * 512, BARE_BATCH);
		cold[t] = bare_stream((size_t)ROUNDS * 512, BARE_DISTINCT);
		r1[t] = one[t] / bare[t];
		r1c[t] = one[t] / cold[t];
	}
	double one_m = median(one, TRIALS), bare_m = median(bare, TRIALS);
	double cold_m = median(cold, TRIALS);
	printf("server/cached tiles 256² rgba8 to 1 session: %.0f tiles/s (%.2f GB/s; median of %d)\n",
	       one_m, one_m * 262144.0 * 1e-9, TRIALS);
	printf("server/bare loopback tcp stream of the same frames (peer): %.0f tiles/s (%.2f "
	       "GB/s), from %d frames in the CPU's cache\n", bare_m, bare_m * 262144.0 * 1e-9,
	       BARE_BATCH);
	printf("server/bare loopback tcp stream of the same frames (peer): %.0f tiles/s (%.2f "
	       "GB/s), from %d distinct frames in memory, as the session's tiles\n", cold_m,
	       cold_m * 262144.0 * 1e-9, BARE_DISTINCT);

	/* 50 sessions, each 64 cached tiles per round out of the same 512. */
	struct cl *s[NS];
	for (int i = 0; i < NS; i++) {
		s[i] = cl_tcp(port);
		cl_open(s[i]);
	}
	double fifty[TRIALS], bare50[TRIALS], r50[TRIALS];
	for (int t = 0; t < TRIALS; t++) {
		uint64_t t0 = clock_now_ns(), tiles = 0;
		for (int r = 0; r < 4; r++) {
			for (int i = 0; i < NS; i++)
				want(s[i], (uint32_t)(t * 4 + r) + 1, big[r & 1] + (i * 8) % 448, 64);
			int left[NS];
			for (int i = 0; i < NS; i++)
				left[i] = 64;
			tiles += drain(s, NS, left);
		}
		fifty[t] = tiles / ((clock_now_ns() - t0) * 1e-9);
		bare50[t] = bare_streams(NS, (size_t)tiles / NS);
		r50[t] = fifty[t] / bare50[t];
	}
	double fifty_m = median(fifty, TRIALS), bare50_m = median(bare50, TRIALS);
	printf("server/cached tiles 256² rgba8 to 50 sessions: %.0f tiles/s (%.2f GB/s)\n", fifty_m,
	       fifty_m * 262144.0 * 1e-9);
	printf("server/bare loopback tcp streams to 50 connections (peer): %.0f tiles/s (%.2f "
	       "GB/s)\n", bare50_m, bare50_m * 262144.0 * 1e-9);
	double r1_lo = r1[0], r1_hi = r1[0];
	for (int t = 1; t < TRIALS; t++)
		r1_lo = r1[t] < r1_lo ? r1[t] : r1_lo, r1_hi = r1[t] > r1_hi ? r1[t] : r1_hi;
	printf("server/ratios in this run (medians of %d alternated trials): 1 session / bare stream "
	       "%.2f (goal >= 0.8; trials %.2f-%.2f; from memory as the session's: %.2f), "
	       "50 sessions / 1 session %.2f (goal >= 1.6), 50 sessions / bare 50 streams %.2f\n",
	       TRIALS, median(r1, TRIALS), r1_lo, r1_hi, median(r1c, TRIALS), fifty_m / one_m,
	       median(r50, TRIALS));
	if (bare50_m < 1.6 * one_m)
		printf("server/note: the bare 50 streams (the most this client and the loopback take) "
		       "are %.2f x one session: 1.6 x is out of reach on this machine\n",
		       bare50_m / one_m);

	/* What the daemon did meanwhile: frames against encodings, and its loop's iterations. */
	struct proto_msg sr = { .type = PROTO_STATS_REQ, .stats_req = { .req = 1 } };
	cl_send(c, &sr);
	for (;;) {
		struct proto_msg m;
		cl_msg(c, &m);
		if (m.type != PROTO_STATS) {
			proto_msg_fini(&m);
			continue;
		}
		static const char *const show[] = { "tiles.sent", "tiles.encoded", "encode.shared",
						   "encode.evicted", "loop.p99_ms", "loop.max_ms",
						   "loop.over_50ms" };
		printf("server/daemon STATS at the end:");
		for (size_t k = 0; k < sizeof show / sizeof show[0]; k++)
			for (uint16_t i = 0; i < m.stats.count; i++)
				if (strcmp(m.stats.items[i].key, show[k]) == 0) {
					if (m.stats.items[i].kind == PROTO_STAT_F64)
						printf(" %s %.1f", show[k], m.stats.items[i].f);
					else
						printf(" %s %llu", show[k],
						       (unsigned long long)m.stats.items[i].u);
				}
		printf("\n");
		proto_msg_fini(&m);
		break;
	}

	int st = 0;
	int rc = daemon_env_stop(&d, SIGTERM, &st);
	daemon_env_fini(&d);
	return rc == 0 && WIFEXITED(st) && WEXITSTATUS(st) == 0 ? 0 : 1;
}
