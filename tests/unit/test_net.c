/* net.c and clipmapctl's helpers against a fake server: a thread on a socketpair (or a temp
 * Unix socket) that speaks the protocol through common/proto.h and follows a script —
 * handshake with a token, answers written one byte at a time, an ERROR, EOF in the middle of
 * a frame, silence (timeout), garbage. Then the pure helpers: bbox/path/levels parsing, the
 * progress line, the status table and JSON from a canned STATS, the cache listing, tile →
 * picture, and a whole prefetch (and its cancellation) through the fake server.
 * Scripts run on their own thread and report failure by a return code checked after join. */
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <pthread.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <signal.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "client/ctl/ctl_args.h"
#include "client/ctl/ctl_cache.h"
#include "client/ctl/ctl_conn.h"
#include "client/ctl/ctl_prefetch.h"
#include "client/ctl/ctl_status.h"
#include "client/ctl/ctl_tile.h"
#include "client/net.h"
#include "common/clock.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "support/daemon_env.h"

/* ---- the fake server --------------------------------------------------------------------- */

struct srv;
typedef int (*script_fn)(struct srv *s);

struct srv {
	int fd;	       /* the server's end */
	int listen_fd; /* ≥ 0: accept fd from it first */
	script_fn script;
	struct pbuf rb;
	bool bytewise; /* send every frame one byte per write */
	int result;    /* 0 when the script saw what it expected */
	pthread_t th;
	const char *token; /* expected in HELLO (NULL: any) */
	/* what the script saw, for the test to check */
	struct proto_prefetch seen_pf;
	uint64_t seen_layers;
	bool seen_cancel;
	pid_t kill_pid; /* > 0: script_prefetch_cancel sends it SIGINT */
};

static int srv_recv(struct srv *s, struct proto_msg *m)
{
	for (;;) {
		size_t need;
		ssize_t r = proto_decode(s->rb.data, s->rb.len, m, &need, NULL);
		if (r > 0) {
			/* strings of m live in its arena; a tile payload would borrow, we have none */
			pbuf_consume(&s->rb, (size_t)r);
			return 0;
		}
		if (r < 0)
			return (int)r;
		uint8_t buf[4096];
		ssize_t n = read(s->fd, buf, sizeof buf);
		if (n <= 0)
			return -ECONNRESET;
		pbuf_append(&s->rb, buf, (size_t)n);
	}
}

static int srv_write(struct srv *s, const uint8_t *p, size_t n)
{
	size_t step = s->bytewise ? 1 : n;
	for (size_t i = 0; i < n; i += step) {
		size_t k = n - i < step ? n - i : step;
		if (send(s->fd, p + i, k, MSG_NOSIGNAL) != (ssize_t)k)
			return -EIO;
	}
	return 0;
}

static int srv_send(struct srv *s, const struct proto_msg *m)
{
	struct pbuf b;
	pbuf_init(&b);
	int rc = proto_encode(&b, m, NULL) > 0 ? srv_write(s, b.data, b.len) : -EINVAL;
	pbuf_fini(&b);
	return rc;
}

static int srv_handshake(struct srv *s)
{
	struct proto_msg m = { 0 };
	int rc = srv_recv(s, &m);
	if (rc || m.type != PROTO_HELLO) {
		proto_msg_fini(&m);
		return -1;
	}
	if (s->token && (m.hello.token_len != strlen(s->token) ||
			 memcmp(m.hello.token, s->token, m.hello.token_len) != 0)) {
		proto_msg_fini(&m);
		struct proto_msg e = { .type = PROTO_ERROR,
				       .error = { .code = PROTO_E_AUTH, .ref_type = PROTO_HELLO,
						  .message = "wrong token" } };
		srv_send(s, &e);
		return 1; /* refused, as scripted */
	}
	uint32_t codecs = m.hello.codecs & TCODEC_ALL_MASK;
	proto_msg_fini(&m);
	struct proto_msg ok = { .type = PROTO_HELLO_OK,
				.hello_ok = { .version = PROTO_VERSION, .codecs = codecs,
					      .session = 42, .name = "fake/1",
					      .limits = { .max_want = 4096, .max_frame = 1 << 20 } } };
	return srv_send(s, &ok);
}

static void *srv_main(void *ud)
{
	struct srv *s = ud;
	if (s->listen_fd >= 0) {
		s->fd = accept(s->listen_fd, NULL, NULL);
		if (s->fd < 0) {
			s->result = -errno;
			return NULL;
		}
	}
	s->result = s->script(s);
	close(s->fd);
	pbuf_fini(&s->rb);
	return NULL;
}

/* Starts script on a socketpair; returns the client's end. */
static int srv_start(struct srv *s, script_fn script)
{
	int sv[2];
	assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, sv), 0);
	s->fd = sv[1];
	s->listen_fd = -1;
	s->script = script;
	pbuf_init(&s->rb);
	assert_int_equal(xthread_create(&s->th, srv_main, s), 0);
	return sv[0];
}

static int srv_join(struct srv *s)
{
	xthread_join(s->th);
	return s->result;
}

/* Waits for the client to hang up (BYE then EOF). */
static int srv_drain(struct srv *s)
{
	for (;;) {
		struct proto_msg m = { 0 };
		int rc = srv_recv(s, &m);
		proto_msg_fini(&m);
		if (rc)
			return 0;
	}
}

/* ---- canned data ------------------------------------------------------------------------ */

static const struct proto_layer test_layers[] = {
	{ .name = "height", .format = PIX_HEIGHT, .node = 0x1111 },
	{ .name = "color", .format = PIX_COLOR, .node = 0x2222 },
	{ .name = "normal", .format = PIX_NORMAL, .node = 0x3333 },
};
static const struct proto_planet test_planet = { .name = "testplanet", .description = "fake",
						 .a = 6378137.0, .f = 0, .tile_size = 8,
						 .max_level = 5, .nlayers = 3,
						 .layers = test_layers };

static const struct proto_stat test_stats[] = {
	{ .key = "uptime_s", .kind = PROTO_STAT_F64, .f = 3723.2 },
	{ .key = "sessions", .kind = PROTO_STAT_U64, .u = 3 },
	{ .key = "sessions.total", .kind = PROTO_STAT_U64, .u = 17 },
	{ .key = "version", .kind = PROTO_STAT_STR, .s = "clipmapd 0.1 \"dev\"" },
	{ .key = "sched.queued.visible", .kind = PROTO_STAT_U64, .u = 2 },
	{ .key = "sched.queued.bulk", .kind = PROTO_STAT_U64, .u = 350 },
	{ .key = "sched.running", .kind = PROTO_STAT_U64, .u = 4 },
	{ .key = "cache.bytes", .kind = PROTO_STAT_U64, .u = 3u << 20 },
	{ .key = "cache.hits", .kind = PROTO_STAT_U64, .u = 15 },
	{ .key = "cache.misses", .kind = PROTO_STAT_U64, .u = 5 },
	{ .key = "cache.evictions", .kind = PROTO_STAT_U64, .u = 7 },
	{ .key = "bytes.sent", .kind = PROTO_STAT_U64, .u = UINT64_C(5) << 30 },
	{ .key = "node.earth.terrain.generated", .kind = PROTO_STAT_U64, .u = 1234 },
	{ .key = "node.earth.terrain.mean_ms", .kind = PROTO_STAT_F64, .f = 3.25 },
	{ .key = "node.earth.colour.generated", .kind = PROTO_STAT_U64, .u = 99 },
	{ .key = "node.earth.colour.mean_ms", .kind = PROTO_STAT_F64, .f = 0.5 },
};

static int reply_stats(struct srv *s)
{
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_STATS_REQ) {
		proto_msg_fini(&m);
		return -1;
	}
	uint32_t req = m.stats_req.req;
	proto_msg_fini(&m);
	struct proto_msg st = { .type = PROTO_STATS,
				.stats = { .req = req, .count = 16, .items = test_stats } };
	return srv_send(s, &st);
}

/* A FILE writing into *buf (valid after fclose; free() it). */
static FILE *capture(char **buf, size_t *n)
{
	*buf = NULL;
	FILE *f = open_memstream(buf, n);
	assert_non_null(f);
	return f;
}

/* ---- net.c ------------------------------------------------------------------------------- */

static int script_stats_bytewise(struct srv *s)
{
	s->bytewise = true;
	if (srv_handshake(s) || reply_stats(s))
		return -1;
	return srv_drain(s);
}

/* A real Unix socket, a token from a file, every answer written one byte per write. */
static void handshake_token_bytewise(void **state)
{
	(void)state;
	char dir[] = "/tmp/test_net_XXXXXX";
	assert_non_null(mkdtemp(dir));
	char sock[64], tokf[64];
	snprintf(sock, sizeof sock, "%s/d.sock", dir);
	snprintf(tokf, sizeof tokf, "%s/token", dir);
	FILE *tf = fopen(tokf, "w");
	assert_non_null(tf);
	fputs("s3cret\n", tf);
	fclose(tf);
	int l = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	snprintf(a.sun_path, sizeof a.sun_path, "%s", sock);
	assert_int_equal(bind(l, (struct sockaddr *)&a, sizeof a), 0);
	assert_int_equal(listen(l, 4), 0);

	struct srv s = { .listen_fd = l, .script = script_stats_bytewise, .token = "s3cret" };
	pbuf_init(&s.rb);
	assert_int_equal(xthread_create(&s.th, srv_main, &s), 0);

	struct net_opts o = { .socket_path = sock, .token_file = tokf, .name = "test/1" };
	struct net_conn *c;
	char err[256] = "";
	int rc = net_connect(&o, &c, err);
	assert_int_equal(rc, 0);
	assert_string_equal(net_hello(c)->name, "fake/1");
	assert_int_equal(net_hello(c)->session, 42);
	assert_string_equal(net_peer(c), sock);
	FILE *f;
	size_t n;
	char *buf;
	f = capture(&buf, &n);
	assert_int_equal(ctl_status_run(c, true, 5000, f, err), 0);
	fclose(f);
	/* the whole STATS decoded from single bytes */
	assert_non_null(strstr(buf, "\"node.earth.colour.mean_ms\": 0.5,"));
	free(buf);
	net_close(c);
	assert_int_equal(srv_join(&s), 0);

	/* the same path with the server gone: ENOENT naming the path, and the hint */
	close(l);
	unlink(sock);
	rc = net_connect(&o, &c, err);
	assert_int_equal(rc, -ENOENT);
	assert_non_null(strstr(err, sock));
	assert_non_null(strstr(err, "No such file or directory"));
	struct ctl_target t = { .socket_path = sock };
	assert_int_equal(ctl_connect(&t, &c, err), -ENOENT);
	assert_non_null(strstr(err, "is clipmapd running? (-s SOCKET)"));
	unlink(tokf);
	rmdir(dir);
}


/* HOST:PORT over TCP (loopback, an ephemeral port); malformed and refused addresses. */
static void tcp_hostport(void **state)
{
	(void)state;
	int l = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	assert_int_equal(bind(l, (struct sockaddr *)&a, sizeof a), 0);
	socklen_t al = sizeof a;
	assert_int_equal(getsockname(l, (struct sockaddr *)&a, &al), 0);
	assert_int_equal(listen(l, 4), 0);
	char hp[64];
	snprintf(hp, sizeof hp, "127.0.0.1:%u", ntohs(a.sin_port));
	struct srv s = { .listen_fd = l, .script = script_stats_bytewise };
	pbuf_init(&s.rb);
	assert_int_equal(xthread_create(&s.th, srv_main, &s), 0);
	struct net_opts o = { .hostport = hp, .socket_path = "/unused" };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect(&o, &c, err), 0);
	assert_string_equal(net_peer(c), hp);
	FILE *f = fopen("/dev/null", "w");
	assert_int_equal(ctl_status_run(c, false, 5000, f, err), 0);
	fclose(f);
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
	close(l); /* now nobody listens there */
	assert_int_equal(net_connect(&o, &c, err), -ECONNREFUSED);
	assert_non_null(strstr(err, hp));
	struct ctl_target t = { .hostport = hp };
	assert_int_equal(ctl_connect(&t, &c, err), -ECONNREFUSED);
	assert_non_null(strstr(err, "(-H HOST:PORT)"));
	o.hostport = "no-port-here";
	assert_int_equal(net_connect(&o, &c, err), -EINVAL);
	assert_non_null(strstr(err, "want HOST:PORT"));
}

static int script_wrong_token(struct srv *s)
{
	return srv_handshake(s) == 1 ? 0 : -1;
}

static void handshake_refused(void **state)
{
	(void)state;
	struct srv s = { .token = "right" };
	int fd = srv_start(&s, script_wrong_token);
	setenv("CLIPMAP_TOKEN", "wrong", 1);
	struct net_opts o = { 0 };
	struct net_conn *c = NULL;
	char err[256];
	int rc = net_connect_fd(fd, "fake-peer", &o, &c, err);
	unsetenv("CLIPMAP_TOKEN");
	assert_int_equal(rc, -EACCES);
	assert_null(c);
	assert_non_null(strstr(err, "fake-peer"));
	assert_non_null(strstr(err, "auth"));
	assert_non_null(strstr(err, "wrong token"));
	assert_int_equal(srv_join(&s), 0);
}

static int script_error_reply(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_OPEN) {
		proto_msg_fini(&m);
		return -1;
	}
	struct proto_msg e = { .type = PROTO_ERROR,
			       .error = { .code = PROTO_E_NOT_FOUND, .ref_type = PROTO_OPEN,
					  .ref_id = m.open.req, .message = "no planet \"pluto\"" } };
	proto_msg_fini(&m);
	return srv_send(s, &e) ? -1 : srv_drain(s);
}

static void server_error_message(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_error_reply);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerX", &o, &c, err), 0);
	struct proto_msg m = { 0 };
	int rc = net_open_planet(c, "pluto", &m, 5000, err);
	assert_int_equal(rc, -ENOENT);
	assert_string_equal(err, "peerX: not-found: no planet \"pluto\"");
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

static int script_eof_mid_frame(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_STATS_REQ)
		return -1;
	proto_msg_fini(&m);
	struct pbuf b;
	pbuf_init(&b);
	struct proto_msg st = { .type = PROTO_STATS,
				.stats = { .req = 1, .count = 16, .items = test_stats } };
	proto_encode(&b, &st, NULL);
	int rc = srv_write(s, b.data, b.len / 2); /* then close */
	pbuf_fini(&b);
	return rc;
}

static void eof_mid_frame(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_eof_mid_frame);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerY", &o, &c, err), 0);
	FILE *f = fopen("/dev/null", "w");
	int rc = ctl_status_run(c, false, 5000, f, err);
	fclose(f);
	assert_int_equal(rc, -ECONNRESET);
	assert_non_null(strstr(err, "peerY"));
	assert_non_null(strstr(err, "closed by the server in the middle of a message"));
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

static int script_silent(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	return srv_drain(s); /* reads the request, never answers */
}

static void timeout(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_silent);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerZ", &o, &c, err), 0);
	double t0 = clock_now_s();
	FILE *f = fopen("/dev/null", "w");
	int rc = ctl_status_run(c, false, 200, f, err);
	fclose(f);
	double el = clock_now_s() - t0;
	assert_int_equal(rc, -ETIMEDOUT);
	assert_non_null(strstr(err, "peerZ: no answer"));
	assert_true(el >= 0.19);
	assert_true(el < 5.0);
	/* timeout 0: nothing buffered, nothing waiting: EAGAIN at once */
	struct proto_msg m = { 0 };
	assert_int_equal(net_recv(c, &m, 0, err), -EAGAIN);
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

static int script_garbage(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	return srv_write(s, (const uint8_t *)"HTTP/1.1 400 Bad Request\r\n", 26) ? -1 : srv_drain(s);
}

static void garbage(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_garbage);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerG", &o, &c, err), 0);
	struct proto_msg m = { 0 };
	assert_int_equal(net_recv(c, &m, 5000, err), PROTO_ERR_MAGIC);
	assert_non_null(strstr(err, "peerG: bad message from server"));
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

/* ---- tile through the fake server ---------------------------------------------------------- */

static float tile_heights[64];

static int script_tile(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_OPEN || strcmp(m.open.name, "testplanet")) {
		proto_msg_fini(&m);
		return -1;
	}
	struct proto_msg op = { .type = PROTO_OPENED,
				.opened = { .req = m.open.req, .planet_id = 9,
					    .planet = test_planet } };
	proto_msg_fini(&m);
	if (srv_send(s, &op))
		return -1;
	if (srv_recv(s, &m) || m.type != PROTO_WANT || m.want.count != 1 ||
	    m.want.entries[0].layer != 0 || m.want.entries[0].cls != PROTO_CLASS_VISIBLE ||
	    m.want.entries[0].lx != 2 || m.want.entries[0].ly != 1 ||
	    m.want.entries[0].x != 3 || m.want.entries[0].y != 1 || m.want.planet_id != 9) {
		proto_msg_fini(&m);
		return -2;
	}
	uint32_t seq = m.want.seq;
	proto_msg_fini(&m);
	/* an unrelated tile first (another layer), then the wanted one, zstd + grad */
	struct tilecodec *tc = tilecodec_create();
	uint8_t payload[4096];
	struct tilecodec_hdr h;
	uint8_t rgba[64 * 4] = { 0 };
	ssize_t n = tilecodec_encode(tc, PIX_COLOR, 8, TCODEC_NONE, TFILTER_NONE, 0, rgba, &h,
				     payload, sizeof payload);
	struct proto_msg t = { .type = PROTO_TILE,
			       .tile = { .seq = seq, .planet_id = 9, .layer = 1,
					 .key = { .node = 0x2222, .lx = 2, .ly = 1, .x = 3, .y = 1 },
					 .enc = h, .payload = payload,
					 .payload_len = (uint32_t)n } };
	int rc = srv_send(s, &t);
	n = tilecodec_encode(tc, PIX_HEIGHT, 8, TCODEC_ZSTD, TFILTER_GRAD, 1, tile_heights, &h,
			     payload, sizeof payload);
	t.tile.layer = 0;
	t.tile.key.node = 0x1111;
	t.tile.enc = h;
	t.tile.payload_len = (uint32_t)n;
	s->bytewise = true;
	rc = rc || n < 0 || srv_send(s, &t);
	tilecodec_destroy(tc);
	return rc ? -3 : srv_drain(s);
}

static void tile_fetch(void **state)
{
	(void)state;
	for (int i = 0; i < 64; i++)
		tile_heights[i] = (float)(i * 10.25 - 100.0);
	tile_heights[5] = NAN; /* NaN is not a height: hmin/hmax skip it */
	struct srv s = { 0 };
	int fd = srv_start(&s, script_tile);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerT", &o, &c, err), 0);
	struct ctl_tile_req r = { .planet = "testplanet", .layer = "height", .lx = 2, .ly = 1,
				  .x = 3, .y = 1 };
	struct render_image im;
	int rc = ctl_tile_fetch(c, &r, 5000, &im, err);
	assert_int_equal(rc, 0);
	assert_int_equal(im.width, 8);
	assert_int_equal(im.channels, 1);
	assert_true(im.is_float);
	assert_memory_equal(im.pixels, tile_heights, sizeof tile_heights);
	assert_true(im.hmin == -100.0);
	assert_true(im.hmax == (float)(63 * 10.25 - 100.0));
	render_image_free(&im);
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

/* ---- a tile in parts (TILE_PART) ---------------------------------------------------------- */

static uint8_t part_rgba[8 * 8 * 4];

/* Sends bytes [off, off + n) of t's payload as a TILE_PART; returns its frame's size or < 0. */
static ssize_t send_part(struct srv *s, const struct proto_tile *t, uint32_t off, uint32_t n)
{
	struct proto_msg m = { .type = PROTO_TILE_PART,
			       .tile_part = { .offset = off, .total = t->payload_len,
					      .bytes = t->payload + off, .len = n } };
	if (off == 0)
		m.tile_part.tile = *t;
	struct pbuf b;
	pbuf_init(&b);
	ssize_t r = proto_encode(&b, &m, NULL);
	if (r > 0 && srv_write(s, b.data, b.len))
		r = -EIO;
	pbuf_fini(&b);
	return r;
}

static int script_parts(struct srv *s)
{
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_HELLO || !(m.hello.codecs & PROTO_FEAT_PARTS)) {
		proto_msg_fini(&m);
		return -1;
	}
	proto_msg_fini(&m);
	struct proto_msg ok = { .type = PROTO_HELLO_OK,
				.hello_ok = { .version = PROTO_VERSION,
					      .codecs = PROTO_FEAT_PARTS, .session = 43,
					      .name = "fake/1" } };
	if (srv_send(s, &ok))
		return -1;
	struct tilecodec_hdr h;
	struct tilecodec *tc = tilecodec_create();
	uint8_t payload[1024];
	ssize_t n = tilecodec_encode(tc, PIX_COLOR, 8, TCODEC_NONE, TFILTER_NONE, 0, part_rgba,
				     &h, payload, sizeof payload);
	tilecodec_destroy(tc);
	if (n != 256)
		return -2;
	struct proto_tile t = { .seq = 7, .planet_id = 1, .layer = 1,
				.key = { .node = 0x33, .lx = 2, .ly = 1, .x = 1, .y = 1 },
				.enc = h, .payload = payload, .payload_len = 256 };
	s->bytewise = true;
	/* A whole, in three parts; B stopped after its first; C whole; then a stray part */
	bool bad = send_part(s, &t, 0, 100) != PROTO_HDR + PROTO_PART_FIRST_HEAD + 100 ||
		   send_part(s, &t, 100, 100) != PROTO_HDR + PROTO_PART_HEAD + 100 ||
		   send_part(s, &t, 200, 56) < 0;
	s->bytewise = false;
	t.key.x = 2;
	bad = bad || send_part(s, &t, 0, 100) < 0;
	t.key.x = 3;
	struct proto_msg whole = { .type = PROTO_TILE, .tile = t };
	bad = bad || srv_send(s, &whole) || send_part(s, &t, 100, 100) < 0;
	if (bad)
		return -3;
	/* wait for the client to hang up */
	char c;
	while (read(s->fd, &c, 1) > 0)
		;
	return 0;
}

static void tile_parts(void **state)
{
	(void)state;
	for (size_t i = 0; i < sizeof part_rgba; i++)
		part_rgba[i] = (uint8_t)(i * 7 + 1);
	struct srv s = { 0 };
	int fd = srv_start(&s, script_parts);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerP", &o, &c, err), 0);
	assert_true(net_hello(c)->codecs & PROTO_FEAT_PARTS);
	struct proto_msg m = { 0 };
	assert_int_equal(net_recv(c, &m, 5000, err), 0);
	assert_int_equal(m.type, PROTO_TILE);
	assert_int_equal(m.tile.key.x, 1);
	assert_int_equal(m.tile.seq, 7);
	assert_int_equal(m.tile.payload_len, 256);
	assert_memory_equal(m.tile.payload, part_rgba, 256);
	uint64_t three = 3 * PROTO_HDR + PROTO_PART_FIRST_HEAD + 2 * PROTO_PART_HEAD + 256;
	assert_int_equal(net_last_wire(c), three);
	assert_int_equal(net_parts_dropped(c), 0);
	proto_msg_fini(&m);
	/* B's first part is dropped when C comes whole */
	assert_int_equal(net_recv(c, &m, 5000, err), 0);
	assert_int_equal(m.type, PROTO_TILE);
	assert_int_equal(m.tile.key.x, 3);
	assert_memory_equal(m.tile.payload, part_rgba, 256);
	assert_int_equal(net_last_wire(c), PROTO_HDR + 44 + 256);
	assert_int_equal(net_parts_dropped(c), PROTO_HDR + PROTO_PART_FIRST_HEAD + 100);
	proto_msg_fini(&m);
	/* a part with no first part before it: the stream is broken, said so */
	assert_int_equal(net_recv(c, &m, 5000, err), -EBADMSG);
	assert_non_null(strstr(err, "a part at byte 100 of a 256-byte tile"));
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}

/* ---- prefetch through the fake server ------------------------------------------------------ */

static int open_reply(struct srv *s)
{
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_OPEN) {
		proto_msg_fini(&m);
		return -1;
	}
	struct proto_msg op = { .type = PROTO_OPENED,
				.opened = { .req = m.open.req, .planet_id = 1,
					    .planet = test_planet } };
	proto_msg_fini(&m);
	return srv_send(s, &op);
}

static int progress(struct srv *s, uint32_t id, uint8_t st, uint64_t done, uint64_t total)
{
	struct proto_msg p = { .type = PROTO_PREFETCH_PROGRESS,
			       .prefetch_progress = { .id = id, .state = st, .done = done,
						      .total = total, .rate = 50.0 } };
	return srv_send(s, &p);
}

static int script_prefetch(struct srv *s)
{
	if (srv_handshake(s) || open_reply(s))
		return -1;
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_PREFETCH) {
		proto_msg_fini(&m);
		return -2;
	}
	s->seen_pf = m.prefetch;
	s->seen_pf.planet = NULL;
	s->seen_pf.points = NULL;
	uint32_t id = m.prefetch.id;
	proto_msg_fini(&m);
	int rc = progress(s, id, PROTO_JOB_RUNNING, 0, 100) ||
		 progress(s, 77, PROTO_JOB_RUNNING, 5, 10) || /* another job: ignored */
		 progress(s, id, PROTO_JOB_RUNNING, 60, 100) ||
		 progress(s, id, PROTO_JOB_DONE, 100, 100);
	return rc ? -3 : srv_drain(s);
}

static void prefetch_done(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_prefetch);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerP", &o, &c, err), 0);
	struct ctl_prefetch_opts po = { .planet = "testplanet", .layers = "normal,height",
					.shape = PROTO_SHAPE_BBOX,
					.bbox = { .west = 170, .south = -10, .east = -170,
						  .north = 10 },
					.lmin = 1, .lmax = 4 };
	FILE *pf, *sf;
	size_t pn, sn;
	char *pbufp = NULL, *sbufp = NULL;
	pf = open_memstream(&pbufp, &pn);
	sf = open_memstream(&sbufp, &sn);
	struct ctl_prefetch_ui ui = { .progress = pf, .tty = false, .summary = sf, .stop_fd = -1 };
	struct proto_prefetch_progress fin;
	int rc = ctl_prefetch_run(c, &po, &ui, &fin, err);
	assert_int_equal(rc, 0);
	assert_int_equal(fin.state, PROTO_JOB_DONE);
	assert_int_equal(fin.done, 100);
	assert_int_equal(fin.total, 100);
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
	assert_int_equal(s.seen_pf.layers, (1u << 2) | 1u);
	assert_int_equal(s.seen_pf.shape, PROTO_SHAPE_BBOX);
	assert_true(s.seen_pf.bbox.west == 170 && s.seen_pf.bbox.east == -170);
	assert_int_equal(s.seen_pf.lmin, 1);
	assert_int_equal(s.seen_pf.lmax, 4);
	fclose(pf);
	fclose(sf);
	/* non-TTY progress: plain lines, the last one complete; no carriage returns */
	assert_null(strchr(pbufp, '\r'));
	assert_non_null(strstr(pbufp, "prefetch: 100/100 tiles  100%"));
	assert_null(strstr(pbufp, "5/10")); /* the other job's progress is not ours */
	assert_non_null(strstr(sbufp, "prefetch testplanet: 100 of 100 tiles in "));
	free(pbufp);
	free(sbufp);
}

/* Answers a STATS_REQ with no figures: a daemon without a disk tier (the real clipmapctl
 * asks for store.disk.evictions_prefetched before a prefetch, and then asks nothing more). */
static int stats_reply_empty(struct srv *s)
{
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_STATS_REQ) {
		proto_msg_fini(&m);
		return -1;
	}
	struct proto_msg r = { .type = PROTO_STATS, .stats = { .req = m.stats_req.req } };
	proto_msg_fini(&m);
	return srv_send(s, &r);
}

static int script_prefetch_cancel(struct srv *s)
{
	if (srv_handshake(s) || (s->kill_pid > 0 && stats_reply_empty(s)) || open_reply(s))
		return -1;
	struct proto_msg m = { 0 };
	if (srv_recv(s, &m) || m.type != PROTO_PREFETCH) {
		proto_msg_fini(&m);
		return -2;
	}
	uint32_t id = m.prefetch.id;
	proto_msg_fini(&m);
	if (progress(s, id, PROTO_JOB_RUNNING, 3, 1000))
		return -3;
	/* With kill_pid (the real program): the client blocked SIGINT into its signalfd before it
	 * sent PREFETCH; this is its Ctrl-C. */
	if (s->kill_pid > 0)
		kill(s->kill_pid, SIGINT);
	if (srv_recv(s, &m) || m.type != PROTO_PREFETCH_CANCEL || m.prefetch_cancel.req != id) {
		proto_msg_fini(&m);
		return -4;
	}
	s->seen_cancel = true;
	proto_msg_fini(&m);
	return progress(s, id, PROTO_JOB_CANCELLED, 4, 1000) ? -5 : srv_drain(s);
}

static void prefetch_interrupted(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_prefetch_cancel);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerC", &o, &c, err), 0);
	struct proto_lonlat pts[2] = { { 10, 50 }, { 11, 51 } };
	struct ctl_prefetch_opts po = { .planet = "testplanet", .shape = PROTO_SHAPE_PATH,
					.points = pts, .npoints = 2, .width_m = 1000, .lmin = 0,
					.lmax = 5 };
	int stop[2];
	assert_int_equal(pipe(stop), 0);
	assert_int_equal(write(stop[1], "x", 1), 1); /* Ctrl-C already pressed */
	struct ctl_prefetch_ui ui = { .progress = NULL, .summary = NULL, .stop_fd = stop[0],
				      .cancel_wait_ms = 5000 };
	struct proto_prefetch_progress fin;
	int rc = ctl_prefetch_run(c, &po, &ui, &fin, err);
	assert_int_equal(rc, -ECANCELED);
	assert_int_equal(fin.state, PROTO_JOB_CANCELLED); /* the daemon acknowledged */
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
	assert_true(s.seen_cancel);
	close(stop[0]);
	close(stop[1]);
}

/* Levels beyond the planet are refused before anything is sent. */
static int script_open_only(struct srv *s)
{
	if (srv_handshake(s))
		return -1;
	for (;;) {
		struct proto_msg m = { 0 };
		if (srv_recv(s, &m))
			return 0;
		uint16_t type = m.type;
		uint32_t req = m.open.req;
		proto_msg_fini(&m);
		if (type == PROTO_BYE)
			return 0;
		if (type != PROTO_OPEN)
			return -2; /* a PREFETCH got through */
		struct proto_msg op = { .type = PROTO_OPENED,
					.opened = { .req = req, .planet_id = 1,
						    .planet = test_planet } };
		if (srv_send(s, &op))
			return -3;
	}
}

static void prefetch_bad_levels(void **state)
{
	(void)state;
	struct srv s = { 0 };
	int fd = srv_start(&s, script_open_only);
	struct net_opts o = { 0 };
	struct net_conn *c;
	char err[256];
	assert_int_equal(net_connect_fd(fd, "peerL", &o, &c, err), 0);
	struct ctl_prefetch_opts po = { .planet = "testplanet", .shape = PROTO_SHAPE_BBOX,
					.bbox = { 0, 0, 1, 1 }, .lmin = 2, .lmax = 9,
					.layers = "height" };
	struct ctl_prefetch_ui ui = { .stop_fd = -1 };
	assert_int_equal(ctl_prefetch_run(c, &po, &ui, NULL, err), -EINVAL);
	assert_non_null(strstr(err, "has levels 0-5"));
	po.lmax = 3;
	po.layers = "height,lava";
	assert_int_equal(ctl_prefetch_run(c, &po, &ui, NULL, err), -EINVAL);
	assert_non_null(strstr(err, "no layer \"lava\" (layers: height, color, normal)"));
	net_close(c);
	assert_int_equal(srv_join(&s), 0);
}


/* ---- the clipmapctl program ---------------------------------------------------------------- */

/* build/clipmapctl next to build/tests/test_net, or NULL when it was not built. */
static const char *ctl_path(char *buf, size_t n)
{
	if (daemon_env_bindir(buf, n) || strlen(buf) + 12 >= n)
		return NULL;
	strcat(buf, "/clipmapctl");
	return access(buf, X_OK) == 0 ? buf : NULL;
}

/* Starts argv with stdout and stderr into one pipe (*out_fd). */
static pid_t spawn(char *const argv[], int *out_fd)
{
	int p[2];
	assert_int_equal(pipe(p), 0);
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid == 0) {
		dup2(p[1], 1);
		dup2(p[1], 2);
		close(p[0]);
		close(p[1]);
		execv(argv[0], argv);
		_exit(127);
	}
	close(p[1]);
	*out_fd = p[0];
	return pid;
}

static int finish(pid_t pid, int fd, char *out, size_t n)
{
	size_t len = 0;
	ssize_t r;
	while ((r = read(fd, out + len, n - 1 - len)) > 0)
		len += (size_t)r;
	out[len] = '\0';
	close(fd);
	int st;
	assert_int_equal(waitpid(pid, &st, 0), pid);
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

/* Exit codes and messages of the real program: no daemon → 1 with the hint; bad arguments
 * → 2; Ctrl-C during a prefetch → PREFETCH_CANCEL, then 130. */
static void cli_exit_codes(void **state)
{
	(void)state;
	char exe[512], out[4096];
	if (!ctl_path(exe, sizeof exe))
		skip(); /* build/clipmapctl not built (make all builds it) */
	int fd;
	char *a1[] = { exe, "-s", "/nonexistent/clipmapd.sock", "status", NULL };
	pid_t pid = spawn(a1, &fd);
	int rc = finish(pid, fd, out, sizeof out);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "cannot connect to /nonexistent/clipmapd.sock: No such file "
				    "or directory \xe2\x80\x94 is clipmapd running? (-s SOCKET)"));
	char *a2[] = { exe, "prefetch", "earth", "--bbox", "1,2,3", "--levels", "0-3", NULL };
	pid = spawn(a2, &fd);
	rc = finish(pid, fd, out, sizeof out);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "--bbox: expected W,S,E,N"));

	char dir[] = "/tmp/test_net_XXXXXX";
	assert_non_null(mkdtemp(dir));
	char sock[64];
	snprintf(sock, sizeof sock, "%s/d.sock", dir);
	int l = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	snprintf(a.sun_path, sizeof a.sun_path, "%s", sock);
	assert_int_equal(bind(l, (struct sockaddr *)&a, sizeof a), 0);
	assert_int_equal(listen(l, 4), 0);
	char *a3[] = { exe, "-s", sock, "prefetch", "testplanet", "--bbox", "0,0,1,1",
		       "--levels", "0-2", NULL };
	struct srv s = { .listen_fd = l, .script = script_prefetch_cancel };
	pbuf_init(&s.rb);
	pid = spawn(a3, &fd);
	s.kill_pid = pid;
	assert_int_equal(xthread_create(&s.th, srv_main, &s), 0);
	rc = finish(pid, fd, out, sizeof out);
	assert_int_equal(srv_join(&s), 0);
	assert_true(s.seen_cancel);
	assert_int_equal(rc, 130);
	assert_non_null(strstr(out, "prefetch: 3/1000 tiles"));
	assert_non_null(strstr(out, "interrupted after 4 of 1000 tiles"));
	/* the daemon gone in the middle of the answer: said so, not retried, exit 1 */
	char *a4[] = { exe, "-s", sock, "status", NULL };
	struct srv s2 = { .listen_fd = l, .script = script_eof_mid_frame };
	pbuf_init(&s2.rb);
	assert_int_equal(xthread_create(&s2.th, srv_main, &s2), 0);
	pid = spawn(a4, &fd);
	rc = finish(pid, fd, out, sizeof out);
	assert_int_equal(srv_join(&s2), 0);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "clipmapctl status: lost the connection: "));
	assert_non_null(strstr(out, "closed by the server in the middle of a message"));
	assert_non_null(strstr(out, "not retried (run it again)"));
	close(l);
	unlink(sock);
	rmdir(dir);
}

/* ---- parsers and formatters ----------------------------------------------------------------- */

static void parse_bbox_path_levels(void **state)
{
	(void)state;
	char err[256];
	struct geo_rect r;
	assert_int_equal(ctl_parse_bbox("-10.5,40,5,52.25", &r, err), 0);
	assert_true(r.west == -10.5 && r.south == 40 && r.east == 5 && r.north == 52.25);
	/* across the antimeridian: east + 360 as written, west > east in the protocol's form */
	assert_int_equal(ctl_parse_bbox("170,-5,190,5", &r, err), 0);
	assert_true(r.west == 170 && r.south == -5 && r.east == -170 && r.north == 5);
	/* west > east as written would be the band round the other side: refused */
	const char *bad_boxes[] = { "1,2,3", "1,2,3,4,5", "a,2,3,4", "1,2,3,4x", "", "1,,3,4",
				    "-181,0,10,10", "0,10,10,5", "0,-91,10,10", "5,0,5,10",
				    "1, 2,3,4", "170,-5,-170,5", "88,27,86,28", "10,0,371,1" };
	for (size_t i = 0; i < sizeof bad_boxes / sizeof *bad_boxes; i++) {
		err[0] = 0;
		assert_int_equal(ctl_parse_bbox(bad_boxes[i], &r, err), -EINVAL);
		assert_non_null(strstr(err, "--bbox"));
	}
	assert_int_equal(ctl_parse_bbox("0,10,10,5", &r, err), -EINVAL);
	assert_non_null(strstr(err, "south must be less than north"));

	struct proto_lonlat *p;
	uint32_t n;
	assert_int_equal(ctl_parse_path("48.85,2.35:51.5,-0.12:40.7,-74", &p, &n, err), 0);
	assert_int_equal(n, 3);
	assert_true(p[0].lat == 48.85 && p[0].lon == 2.35 && p[2].lon == -74);
	free(p);
	const char *bad_paths[] = { "48.85,2.35", "48.85,2.35:", "48.85:2.35", "1,2:3",
				    "1,2:3,4:", "91,0:0,0", "" };
	for (size_t i = 0; i < sizeof bad_paths / sizeof *bad_paths; i++) {
		assert_int_equal(ctl_parse_path(bad_paths[i], &p, &n, err), -EINVAL);
		assert_null(p);
	}
	assert_int_equal(ctl_parse_path("91,0:0,0", &p, &n, err), -EINVAL);
	assert_non_null(strstr(err, "place 1 is out of range"));

	uint8_t a, b;
	assert_int_equal(ctl_parse_levels("3-7", 22, &a, &b, err), 0);
	assert_true(a == 3 && b == 7);
	assert_int_equal(ctl_parse_levels("5", 22, &a, &b, err), 0);
	assert_true(a == 5 && b == 5);
	const char *bad_levels[] = { "7-3", "-3", "3-", "a-b", "3-99", "", "1-2-3", "+1-2" };
	for (size_t i = 0; i < sizeof bad_levels / sizeof *bad_levels; i++)
		assert_int_equal(ctl_parse_levels(bad_levels[i], 22, &a, &b, err), -EINVAL);
	assert_int_equal(ctl_parse_levels("7-3", 22, &a, &b, err), -EINVAL);
	assert_non_null(strstr(err, "must not exceed"));

	double lat, lon, m;
	assert_int_equal(ctl_parse_latlon("-33.9,18.4", &lat, &lon, err), 0);
	assert_true(lat == -33.9 && lon == 18.4);
	assert_int_equal(ctl_parse_latlon("18.4", &lat, &lon, err), -EINVAL);
	assert_int_equal(ctl_parse_km("2.5", "--width", 20000, &m, err), 0);
	assert_true(m == 2500);
	assert_int_equal(ctl_parse_km("-1", "--width", 20000, &m, err), -EINVAL);
	assert_non_null(strstr(err, "--width"));
	assert_int_equal(ctl_parse_km("20000", "--width", 20000, &m, err), 0);
	assert_int_equal(ctl_parse_km("20001", "--width", 20000, &m, err), -EINVAL);
	assert_non_null(strstr(err, "0..20000"));
	assert_int_equal(ctl_parse_km("nan", "--width", 20000, &m, err), -EINVAL);

	uint64_t mask;
	assert_int_equal(ctl_parse_layers("color", &test_planet, &mask, err), 0);
	assert_int_equal(mask, 2);
	assert_int_equal(ctl_parse_layers(NULL, &test_planet, &mask, err), 0);
	assert_int_equal(mask, 0);
	assert_int_equal(ctl_parse_layers(",", &test_planet, &mask, err), -EINVAL);
}

static void progress_line(void **state)
{
	(void)state;
	char s[256];
	ctl_fmt_progress(s, sizeof s, 50, 200, 10.0, 10);
	assert_string_equal(s, "[##        ] 50/200 tiles   25%  10.0 tiles/s  ETA 15s");
	ctl_fmt_progress(s, sizeof s, 0, 200, 0.0, 0);
	assert_string_equal(s, "0/200 tiles    0%  0.0 tiles/s  ETA ?");
	ctl_fmt_progress(s, sizeof s, 200, 200, 33.3, 4);
	assert_string_equal(s, "[####] 200/200 tiles  100%  33.3 tiles/s  ETA 0s");
	ctl_fmt_progress(s, sizeof s, 1, 7201, 2.0, 0);
	assert_string_equal(s, "1/7201 tiles    0%  2.0 tiles/s  ETA 1h00m00s");
	ctl_fmt_progress(s, sizeof s, 0, 0, NAN, 0); /* an empty job */
	assert_string_equal(s, "0/0 tiles    0%  0.0 tiles/s  ETA ?");
	ctl_fmt_duration(3723, s, sizeof s);
	assert_string_equal(s, "1h02m03s");
	ctl_fmt_duration(4.25, s, sizeof s);
	assert_string_equal(s, "4.2s");
	ctl_fmt_bytes(3u << 20, s, sizeof s);
	assert_string_equal(s, "3.0 MiB");
	ctl_fmt_bytes(1000, s, sizeof s);
	assert_string_equal(s, "1000 B");
}

static void status_table_and_json(void **state)
{
	(void)state;
	struct proto_stats st = { .req = 1, .count = 16, .items = test_stats };
	FILE *f;
	size_t n;
	char *buf;
	f = capture(&buf, &n);
	assert_int_equal(ctl_status_print(&st, "/run/x.sock", false, f), 0);
	fclose(f);
	assert_non_null(strstr(buf, "clipmapd at /run/x.sock\n"));
	assert_non_null(strstr(buf, "  uptime_s                1h02m03s\n"));
	assert_non_null(strstr(buf, "bytes\n  sent                    5368709120   (5.0 GiB)\n"));
	/* "sessions" heads the section of "sessions.total" */
	assert_non_null(strstr(buf, "sessions                  3\n  total                   17\n"));
	assert_non_null(strstr(buf, "sched\n  queued.visible          2\n"));
	assert_non_null(strstr(buf, "  bytes                   3145728      (3.0 MiB)\n"));
	/* the hit ratio right after misses: 15 / 20 */
	assert_non_null(strstr(buf, "  misses                  5\n  hit ratio               75.0 %\n"));
	/* the node table: one row per node, columns aligned under their headers */
	assert_non_null(strstr(buf, "nodes                      generated     mean_ms\n"));
	assert_non_null(strstr(buf, "  earth.terrain                 1234       3.250\n"));
	assert_non_null(strstr(buf, "  earth.colour                    99       0.500\n"));
	free(buf);

	f = capture(&buf, &n);
	assert_int_equal(ctl_status_print(&st, NULL, true, f), 0);
	fclose(f);
	assert_int_equal(buf[0], '{');
	assert_non_null(strstr(buf, "\"uptime_s\": 3723.1999999999998,"));
	assert_non_null(strstr(buf, "\"version\": \"clipmapd 0.1 \\\"dev\\\"\","));
	assert_non_null(strstr(buf, "\"node.earth.terrain.mean_ms\": 3.25,"));
	assert_non_null(strstr(buf, "\"cache.hit_ratio\": 0.75\n}\n"));
	free(buf);
}

static void cache_listing(void **state)
{
	(void)state;
	struct proto_cache_entry e[3] = {
		{ .key = { .node = 0x2222, .lx = 3, .ly = 2, .x = 1, .y = 0 }, .format = PIX_COLOR,
		  .tier = PROTO_TIER_MEMORY, .bytes = 262144, .age_s = 75 },
		{ .key = { .node = 0x1111, .lx = 3, .ly = 2, .x = 5, .y = 2 }, .format = PIX_HEIGHT,
		  .tier = PROTO_TIER_MEMORY, .bytes = 262144, .age_s = 3 },
		{ .key = { .node = 0xabcdef, .lx = 1, .ly = 0, .x = 0, .y = 0 }, .format = PIX_HEIGHT,
		  .tier = PROTO_TIER_DISK, .bytes = 262144, .age_s = 4000 },
	};
	FILE *f;
	size_t n;
	char *buf;
	f = capture(&buf, &n);
	assert_int_equal(ctl_cache_print(e, 3, 10, &test_planet, false, f), 0);
	fclose(f);
	const char *h = strstr(buf, "height"), *c = strstr(buf, "color"),
		   *x = strstr(buf, "0000000000abcdef");
	assert_non_null(h);
	assert_non_null(c);
	assert_non_null(x); /* not a layer: shown by its hash */
	assert_true(h < c && c < x); /* sorted by node */
	assert_non_null(strstr(buf, "  3/2           5           2      262144       3.0s  memory"));
	assert_non_null(strstr(buf, "1m15s"));
	assert_non_null(strstr(buf, "3 tiles shown, 768.0 KiB; 10 match"));
	free(buf);
	f = capture(&buf, &n);
	assert_int_equal(ctl_cache_print(e, 1, 1, &test_planet, true, f), 0);
	fclose(f);
	assert_non_null(strstr(buf, "{\"layer\": \"height\", \"node\": \"0000000000001111\", "
				    "\"lx\": 3, \"ly\": 2, \"x\": 5, \"y\": 2, \"format\": \"f32\", "
				    "\"tier\": \"memory\", \"bytes\": 262144, \"age_s\": 3}"));
	free(buf);
}

static void tile_to_picture(void **state)
{
	(void)state;
	/* normals: flat (128,128) → up 1 → blue 255; tilted (255,128) → up 0 → blue 128 */
	uint8_t rg[2 * 4] = { 128, 128, 255, 128, 0, 128, 128, 0 };
	struct render_image im;
	assert_int_equal(ctl_tile_image(PIX_NORMAL, 2, rg, &im), 0);
	assert_int_equal(im.channels, 3);
	const uint8_t *p = im.pixels;
	assert_int_equal(p[0], 128);
	assert_int_equal(p[2], 255);
	assert_int_equal(p[3], 255);
	assert_int_equal(p[5], 128);
	render_image_free(&im);
	uint8_t rgba[16] = { 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16 };
	assert_int_equal(ctl_tile_image(PIX_COLOR, 2, rgba, &im), 0);
	assert_int_equal(im.channels, 4);
	assert_false(im.is_float);
	assert_memory_equal(im.pixels, rgba, 16);
	render_image_free(&im);
	assert_int_equal(ctl_tile_image(PIX_NONE, 2, rgba, &im), -EINVAL);
}

/* ---- connecting without waiting (the viewer's reconnects) ------------------------------- */

/* net_connect_start/step against a Unix socket driven by hand from this thread: every step
 * returns at once (-EAGAIN while the server is silent), the handshake completes when it
 * answers, a refusal and a server that hangs up come back as errors. */
static void connect_without_waiting(void **state)
{
	(void)state;
	char dir[] = "/tmp/test_net_XXXXXX";
	assert_non_null(mkdtemp(dir));
	char sock[64];
	snprintf(sock, sizeof sock, "%s/d.sock", dir);
	struct net_opts o = { .socket_path = sock, .name = "test/1" };
	struct net_conn *c = NULL;
	char err[256] = "";
	/* nobody there: the start itself fails, naming the path */
	assert_int_equal(net_connect_start(&o, &c, err), -ENOENT);
	assert_null(c);
	assert_non_null(strstr(err, "cannot connect to "));
	assert_non_null(strstr(err, sock));

	int l = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	snprintf(a.sun_path, sizeof a.sun_path, "%s", sock);
	assert_int_equal(bind(l, (struct sockaddr *)&a, sizeof a), 0);
	assert_int_equal(listen(l, 4), 0);
	for (int round = 0; round < 3; round++) {
		assert_int_equal(net_connect_start(&o, &c, err), 0);
		/* a silent server: each step returns at once */
		double t0 = clock_now_ms();
		for (int i = 0; i < 100; i++)
			assert_int_equal(net_connect_step(c, err), -EAGAIN);
		assert_true(clock_now_ms() - t0 < 1000);
		assert_int_equal(net_connect_events(c), POLLIN); /* HELLO sent, answer awaited */
		struct srv s = { .fd = accept(l, NULL, NULL), .listen_fd = -1 };
		assert_true(s.fd >= 0);
		pbuf_init(&s.rb);
		if (round == 0) { /* answered: done */
			assert_int_equal(srv_handshake(&s), 0);
			int rc;
			while ((rc = net_connect_step(c, err)) == -EAGAIN)
				;
			assert_int_equal(rc, 0);
			assert_string_equal(net_hello(c)->name, "fake/1");
			assert_int_equal(net_connect_step(c, err), 0); /* stays done */
		} else if (round == 1) { /* refused */
			s.token = "not-this";
			assert_int_equal(srv_handshake(&s), 1);
			int rc;
			while ((rc = net_connect_step(c, err)) == -EAGAIN)
				;
			assert_int_equal(rc, -EACCES);
			assert_non_null(strstr(err, "refused the connection: auth: wrong token"));
		} else { /* hung up before answering */
			close(s.fd);
			s.fd = -1;
			int rc;
			while ((rc = net_connect_step(c, err)) == -EAGAIN)
				;
			assert_int_equal(rc, -ECONNRESET); /* an EOF or a reset (HELLO unread) */
			assert_non_null(strstr(err, sock));
		}
		net_close(c);
		c = NULL;
		if (s.fd >= 0)
			close(s.fd);
		pbuf_fini(&s.rb);
	}
	close(l);
	unlink(sock);
	rmdir(dir);
}

/* The reconnect delays: base doubling to the cap, each in [d/2, d], not all alike. */
static void backoff_doubles_with_jitter(void **state)
{
	(void)state;
	unsigned seed = 7;
	int expect[] = { 100, 200, 400, 800, 1600, 3200, 5000, 5000, 5000 };
	for (unsigned a = 1; a <= 9; a++) {
		int d = expect[a - 1], lo = d, hi = 0;
		for (int i = 0; i < 200; i++) {
			int ms = net_backoff_ms(a, 100, 5000, &seed);
			assert_true(ms >= d / 2);
			assert_true(ms <= d);
			lo = ms < lo ? ms : lo;
			hi = ms > hi ? ms : hi;
		}
		assert_true(hi - lo > d / 4); /* jitter: spread over the range */
	}
	/* far attempts stay at the cap (no overflow) */
	int ms = net_backoff_ms(100000, 100, 5000, &seed);
	assert_true(ms >= 2500 && ms <= 5000);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(handshake_token_bytewise),
		cmocka_unit_test(tcp_hostport),
		cmocka_unit_test(handshake_refused),
		cmocka_unit_test(server_error_message),
		cmocka_unit_test(eof_mid_frame),
		cmocka_unit_test(timeout),
		cmocka_unit_test(garbage),
		cmocka_unit_test(tile_fetch),
		cmocka_unit_test(tile_parts),
		cmocka_unit_test(prefetch_done),
		cmocka_unit_test(prefetch_interrupted),
		cmocka_unit_test(prefetch_bad_levels),
		cmocka_unit_test(cli_exit_codes),
		cmocka_unit_test(parse_bbox_path_levels),
		cmocka_unit_test(progress_line),
		cmocka_unit_test(status_table_and_json),
		cmocka_unit_test(cache_listing),
		cmocka_unit_test(tile_to_picture),
		cmocka_unit_test(connect_without_waiting),
		cmocka_unit_test(backoff_doubles_with_jitter),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
