/* test_shared_encode — a real clipmapd (compress = always) and many sessions wanting the same
 * tiles: every session gets byte-identical TILE frames for a tile (same codec, same seq and
 * planet id), the daemon encodes each tile once per encoding however many sessions want it
 * and whenever they come (STATS tiles.encoded against tiles.sent and encode.shared), the
 * frames decode to the same texels in both encodings, and a session that never reads, or
 * one closed with frames queued, changes none of it; the daemon then stops cleanly. And a
 * new WANT still takes unsent shared frames back out of a session's output.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "support/daemon_env.h"

static const char planet[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 3\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

static struct daemon_env E;

static int start_daemon(void **state)
{
	(void)state;
	static const char *const set[] = { "listen.tcp = 127.0.0.1:0",
					   "engine.workers = 1",
					   "engine.cache_mb = 64",
					   "session.max_want = 4096",
					   "session.max_rate = 0",
					   "session.max_pending_kb = 256",
					   "session.compress = always",
					   "log.level = info",
					   NULL };
	const struct daemon_env_conf conf = { .set = set };
	char err[256];
	if (daemon_env_init(&E, "clipmapd-shenc") ||
	    daemon_env_planet_text(&E, "test.ini", planet, NULL)) {
		daemon_env_fini(&E);
		return -1;
	}
	if (daemon_env_start(&E, &conf, err)) {
		fprintf(stderr, "test_shared_encode: %s\n", err);
		daemon_env_fini(&E);
		return -1;
	}
	return 0;
}

static int stop_daemon(void **state)
{
	(void)state;
	if (E.daemon > 0)
		daemon_env_stop(&E, SIGKILL, NULL);
	daemon_env_fini(&E);
	return 0;
}

/* ---- a minimal client ------------------------------------------------------------------ */

struct cl {
	int fd;
	struct pbuf in;
	struct proto_msg m;
	uint8_t *frame; /* the last message's whole frame */
	size_t frame_len;
};

static struct cl *cl_connect(bool tcp)
{
	struct cl *c = calloc(1, sizeof *c);
	assert_non_null(c);
	if (tcp) {
		c->fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
		struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)E.port),
					  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
		assert_int_equal(connect(c->fd, (struct sockaddr *)&sa, sizeof sa), 0);
	} else {
		c->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
		struct sockaddr_un sa = { .sun_family = AF_UNIX };
		assert_true(strlen(E.sock) < sizeof sa.sun_path);
		memcpy(sa.sun_path, E.sock, strlen(E.sock) + 1);
		assert_int_equal(connect(c->fd, (struct sockaddr *)&sa, sizeof sa), 0);
	}
	pbuf_init(&c->in);
	return c;
}

static void cl_free(struct cl *c)
{
	proto_msg_fini(&c->m);
	free(c->frame);
	pbuf_fini(&c->in);
	close(c->fd);
	free(c);
}

static void cl_send(struct cl *c, const struct proto_msg *m)
{
	struct pbuf b;
	pbuf_init(&b);
	char err[256];
	if (proto_encode(&b, m, err) < 0)
		fail_msg("encode: %s", err);
	assert_int_equal(send(c->fd, b.data, b.len, MSG_NOSIGNAL), (ssize_t)b.len);
	pbuf_fini(&b);
}

/* The next message into c->m (its frame in c->frame); fails on timeout, EOF or ERROR. */
static void cl_next(struct cl *c, int timeout_ms)
{
	proto_msg_fini(&c->m);
	free(c->frame);
	c->frame = NULL;
	uint64_t end = clock_now_ms() + (uint64_t)timeout_ms;
	for (;;) {
		size_t need = 0;
		char err[256];
		struct proto_hdr h;
		ssize_t r = proto_frame_check(c->in.data, c->in.len, &h, &need, err);
		if (r < 0)
			fail_msg("bad frame from the server: %s", err);
		if (r > 0) {
			c->frame = malloc((size_t)r);
			memcpy(c->frame, c->in.data, (size_t)r);
			c->frame_len = (size_t)r;
			pbuf_consume(&c->in, (size_t)r);
			if (proto_decode(c->frame, (size_t)r, &c->m, &need, err) != r)
				fail_msg("bad message from the server: %s", err);
			if (c->m.type == PROTO_ERROR)
				fail_msg("ERROR %u: %s", c->m.error.code, c->m.error.message);
			return;
		}
		int64_t left = (int64_t)(end - clock_now_ms());
		if (left <= 0)
			fail_msg("timeout waiting for a message");
		struct pollfd pf = { .fd = c->fd, .events = POLLIN };
		if (poll(&pf, 1, (int)left) <= 0)
			continue;
		pbuf_reserve(&c->in, 1 << 16);
		ssize_t n = recv(c->fd, c->in.data + c->in.len, 1 << 16, 0);
		if (n <= 0)
			fail_msg("connection closed by the server");
		c->in.len += (size_t)n;
	}
}

static void cl_expect(struct cl *c, uint16_t type)
{
	for (;;) {
		cl_next(c, 20000);
		if (c->m.type == type)
			return;
	}
}

/* HELLO (announcing zstd or no codec) and OPEN "test": the planet id. */
static uint32_t cl_open(struct cl *c, bool zstd)
{
	struct proto_msg h = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .codecs = zstd ? 1u << TCODEC_ZSTD : 0,
					  .name = "test_shared_encode" } };
	cl_send(c, &h);
	cl_expect(c, PROTO_HELLO_OK);
	assert_int_equal(c->m.hello_ok.codecs, zstd ? 1u << TCODEC_ZSTD : 0);
	struct proto_msg o = { .type = PROTO_OPEN, .open = { .req = 1, .name = "test" } };
	cl_send(c, &o);
	cl_expect(c, PROTO_OPENED);
	return c->m.opened.planet_id;
}

static void cl_want(struct cl *c, uint32_t seq, const struct proto_want_entry *e, uint32_t n)
{
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = 1, .seq = seq, .count = n, .entries = e } };
	cl_send(c, &m);
}

static uint64_t cl_stat(struct cl *c, const char *key)
{
	struct proto_msg m = { .type = PROTO_STATS_REQ, .stats_req = { .req = 9 } };
	cl_send(c, &m);
	cl_expect(c, PROTO_STATS);
	for (uint16_t i = 0; i < c->m.stats.count; i++)
		if (strcmp(c->m.stats.items[i].key, key) == 0)
			return c->m.stats.items[i].u;
	fail_msg("no stat %s", key);
	return 0;
}

/* ---- the test --------------------------------------------------------------------------- */

enum { NX = 8, NY = 4, K = NX * NY * 2 }; /* tiles wanted: both layers of an 8×4 block */
enum { NS = 12 };			    /* sessions that read */

/* Session i: zstd or not, TCP or Unix, first or second wave. */
static bool zstd_of(int i) { return i % 3 != 2; }
static bool tcp_of(int i) { return i % 4 == 1; }

struct got {
	uint8_t *frame[K]; /* the frame of want entry k */
	size_t len[K];
};

static int entry_of(const struct proto_want_entry *e, const struct proto_tile *t)
{
	for (int k = 0; k < K; k++)
		if (e[k].layer == t->layer && e[k].lx == t->key.lx && e[k].ly == t->key.ly &&
		    e[k].x == t->key.x && e[k].y == t->key.y)
			return k;
	return -1;
}

/* Receives the K TILEs of session c into g. */
static void receive_all(struct cl *c, const struct proto_want_entry *e, struct got *g)
{
	for (int n = 0; n < K; n++) {
		cl_expect(c, PROTO_TILE);
		int k = entry_of(e, &c->m.tile);
		assert_true(k >= 0);
		assert_null(g->frame[k]); /* each tile once */
		g->frame[k] = c->frame;
		g->len[k] = c->frame_len;
		c->frame = NULL;
	}
}

static void test_shared_frames(void **state)
{
	(void)state;
	struct proto_want_entry e[K];
	int n = 0;
	for (uint32_t y = 0; y < NY; y++)
		for (uint32_t x = 0; x < NX; x++)
			for (uint8_t l = 0; l < 2; l++)
				e[n++] = (struct proto_want_entry){ .layer = l, .cls = PROTO_CLASS_VISIBLE,
								    .lx = 8, .ly = 7, .x = 100 + x,
								    .y = 40 + y };
	struct cl *st = cl_connect(false);
	cl_open(st, false);
	uint64_t enc0 = cl_stat(st, "tiles.encoded"), sent0 = cl_stat(st, "tiles.sent");
	uint64_t shared0 = cl_stat(st, "encode.shared");

	/* One session that never reads, wanting the same tiles before anyone else. */
	struct cl *stuck = cl_connect(false);
	cl_open(stuck, true);
	cl_want(stuck, 1, e, K);

	/* Two waves: the second asks once the first has every tile (encodings made by then). */
	struct cl *c[NS];
	static struct got g[NS];
	memset(g, 0, sizeof g);
	for (int wave = 0; wave < 2; wave++) {
		for (int i = wave * NS / 2; i < (wave + 1) * NS / 2; i++) {
			c[i] = cl_connect(tcp_of(i));
			assert_int_equal(cl_open(c[i], zstd_of(i)), 1);
			cl_want(c[i], 1, e, K);
		}
		for (int i = wave * NS / 2; i < (wave + 1) * NS / 2; i++)
			receive_all(c[i], e, &g[i]);
	}

	/* Byte-identical frames within an encoding (seq 1 and planet id 1 for everyone), the
	 * same texels across encodings, zstd really used for some tiles. */
	struct tilecodec *tc = tilecodec_create();
	uint8_t *a = malloc(64 * 64 * 4), *b = malloc(64 * 64 * 4);
	int compressed = 0;
	for (int k = 0; k < K; k++) {
		const struct got *ref[2] = { &g[0], &g[2] }; /* zstd (Unix), none (Unix) */
		assert_true(zstd_of(0) && !zstd_of(2));
		for (int i = 0; i < NS; i++) {
			const struct got *r = ref[!zstd_of(i)];
			assert_int_equal(g[i].len[k], r->len[k]);
			if (memcmp(g[i].frame[k], r->frame[k], r->len[k]) != 0)
				fail_msg("tile %d: session %d's frame differs from its encoding's", k, i);
		}
		struct proto_msg mz = { 0 }, mn = { 0 };
		size_t need;
		assert_int_equal(proto_decode(g[0].frame[k], g[0].len[k], &mz, &need, NULL),
				 (ssize_t)g[0].len[k]);
		assert_int_equal(proto_decode(g[2].frame[k], g[2].len[k], &mn, &need, NULL),
				 (ssize_t)g[2].len[k]);
		assert_int_equal(mn.tile.enc.codec, TCODEC_NONE);
		compressed += mz.tile.enc.codec == TCODEC_ZSTD;
		char err[256];
		if (tilecodec_decode(tc, &mz.tile.enc, mz.tile.payload, mz.tile.payload_len, a,
				     64 * 64 * 4, err) ||
		    tilecodec_decode(tc, &mn.tile.enc, mn.tile.payload, mn.tile.payload_len, b,
				     64 * 64 * 4, err))
			fail_msg("tile %d: %s", k, err);
		assert_int_equal(mz.tile.enc.raw_len, mn.tile.enc.raw_len);
		assert_memory_equal(a, b, mz.tile.enc.raw_len);
		proto_msg_fini(&mz);
		proto_msg_fini(&mn);
	}
	assert_true(compressed > 0);
	tilecodec_destroy(tc);
	free(a);
	free(b);

	/* Once per tile and encoding: K zstd, K none, whatever the number of sessions. */
	uint64_t frames = cl_stat(st, "tiles.sent") - sent0;
	uint64_t encoded = cl_stat(st, "tiles.encoded") - enc0;
	uint64_t shared = cl_stat(st, "encode.shared") - shared0;
	printf("%d sessions (+1 not reading): %llu frames queued, %llu encodings made, %llu "
	       "shared\n", NS, (unsigned long long)frames, (unsigned long long)encoded,
	       (unsigned long long)shared);
	assert_true(frames >= (uint64_t)NS * K); /* the stuck session queued some too */
	assert_int_equal(encoded, 2 * K);
	assert_int_equal(shared, frames - encoded);

	/* The stuck session closed with frames queued; a new session still gets the same
	 * frames from the same encodings. */
	cl_free(stuck);
	struct cl *late = cl_connect(false);
	cl_open(late, true);
	cl_want(late, 1, e, K);
	struct got gl = { 0 };
	receive_all(late, e, &gl);
	for (int k = 0; k < K; k++) {
		assert_int_equal(gl.len[k], g[0].len[k]);
		assert_memory_equal(gl.frame[k], g[0].frame[k], gl.len[k]);
		free(gl.frame[k]);
	}
	assert_int_equal(cl_stat(st, "tiles.encoded") - enc0, 2 * K);
	cl_free(late);

	for (int i = 0; i < NS; i++) {
		for (int k = 0; k < K; k++)
			free(g[i].frame[k]);
		cl_free(c[i]);
	}
	cl_free(st);
	/* Every encoding and every output freed cleanly (a sanitizer build exits non-zero on a
	 * report). */
	int status = 0;
	assert_int_equal(daemon_env_stop(&E, SIGTERM, &status), 0);
	assert_true(WIFEXITED(status));
	assert_int_equal(WEXITSTATUS(status), 0);
}

/* A session that does not read fills its socket and its queue with shared frames; a new WANT
 * takes the unsent ones back (tiles.recalled) and the stream stays whole: every frame that
 * arrives parses and decodes, the new want-set's tiles all arrive, and the tiles received
 * are exactly the frames queued less those taken back. */
static void test_recall_shared(void **state)
{
	(void)state;
	enum { W = 32, H = 16, N = W * H * 2, N2 = 8 };
	struct proto_want_entry *e = calloc(N, sizeof *e), e2[N2];
	int n = 0;
	for (uint32_t y = 0; y < H; y++)
		for (uint32_t x = 0; x < W; x++)
			for (uint8_t l = 0; l < 2; l++)
				e[n++] = (struct proto_want_entry){ .layer = l, .cls = PROTO_CLASS_VISIBLE,
								    .lx = 10, .ly = 9, .x = 200 + x,
								    .y = 100 + y };
	for (int k = 0; k < N2; k++)
		e2[k] = (struct proto_want_entry){ .layer = (uint8_t)(k & 1), .cls = PROTO_CLASS_VISIBLE,
						   .lx = 10, .ly = 9, .x = 400 + (uint32_t)k / 2,
						   .y = 100 };
	struct cl *st = cl_connect(false);
	cl_open(st, false);
	uint64_t sent0 = cl_stat(st, "tiles.sent"), rec0 = cl_stat(st, "tiles.recalled");
	struct cl *r = cl_connect(false);
	cl_open(r, false); /* raw: 16 KiB a tile, the socket takes a few hundred */
	cl_want(r, 1, e, N);
	/* until its output stops growing: socket and queue full */
	uint64_t last = 0, end = clock_now_ms() + 30000;
	for (int still = 0; still < 10 && clock_now_ms() < end;) {
		usleep(100 * 1000);
		uint64_t now = cl_stat(st, "tiles.sent");
		still = now == last ? still + 1 : 0;
		last = now;
	}
	uint64_t queued = last - sent0;
	if (!(queued > 0 && queued < N)) /* some waited in the want-set */
		fail_msg("%llu of %d tiles queued", (unsigned long long)queued, N);
	cl_want(r, 2, e2, N2);
	uint64_t recalled = 0; /* the WANT goes on another connection than the STATS */
	for (end = clock_now_ms() + 20000; !recalled && clock_now_ms() < end; usleep(50 * 1000))
		recalled = cl_stat(st, "tiles.recalled") - rec0;
	assert_true(recalled > 0);

	/* Everything queued for seq 1 and not taken back, then the N2 new tiles. */
	struct tilecodec *tc = tilecodec_create();
	uint8_t *px = malloc(64 * 64 * 4);
	uint64_t got1 = 0, got2 = 0;
	while (got2 < N2) {
		cl_expect(r, PROTO_TILE);
		const struct proto_tile *t = &r->m.tile;
		char err[256];
		if (tilecodec_decode(tc, &t->enc, t->payload, t->payload_len, px, 64 * 64 * 4, err))
			fail_msg("tile %u/%u: %s", t->key.x, t->key.y, err);
		if (t->seq == 1)
			got1++;
		else
			got2++;
	}
	uint64_t total = cl_stat(st, "tiles.sent") - sent0;
	recalled = cl_stat(st, "tiles.recalled") - rec0;
	printf("not reading: %llu frames queued, %llu taken back by the new WANT, %llu stale ones "
	       "received, then the %d new\n", (unsigned long long)queued,
	       (unsigned long long)recalled, (unsigned long long)got1, N2);
	assert_int_equal(got1 + got2, total - recalled);
	tilecodec_destroy(tc);
	free(px);
	free(e);
	cl_free(r);
	cl_free(st);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_recall_shared),
		cmocka_unit_test(test_shared_frames), /* last: it stops the daemon */
	};
	return cmocka_run_group_tests(tests, start_daemon, stop_daemon);
}
