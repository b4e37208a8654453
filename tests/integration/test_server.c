/* test_server — integration tests of clipmapd: a real daemon (build/clipmapd, started by
 * tests/support/daemon_env) on a temporary Unix socket and an ephemeral loopback port, a small
 * fast test planet written by the test, and a minimal client over common/proto.h. Checks what
 * a viewer or operator would notice: tile bytes equal in-process generation, coarse before
 * fine, want-set replacement, many sessions, a stalled session, malformed frames, tokens,
 * prefetch, cache listing and its ages, SIGHUP reload (and sessions rebound across it) and
 * SIGTERM.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/clipmap.h"
#include "common/clock.h"
#include "common/grid.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "support/daemon_env.h"

#define TOKEN "s3cret-token"

static const char planet_v1[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 3\noctaves = 3\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";
/* The same planet with the colour ramp changed: only the colour layer is downstream. */
static const char planet_v2[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 3\noctaves = 3\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 255 0 0, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

/* The daemon (tests/support/daemon_env) and the test planet's file, rewritten before SIGHUPs. */
static struct daemon_env E;
static char planet_path[128];

static void write_file(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	assert_int_equal(fputs(text, f) >= 0, 1);
	assert_int_equal(fclose(f), 0);
}

static int start_daemon(void **state)
{
	(void)state;
	static const char *const set[] = { "listen.tcp = 127.0.0.1:0",
					   "listen.require_token = tcp",
					   "engine.workers = 1",
					   "engine.cache_mb = 256",
					   "session.max_want = 4096",
					   "session.max_rate = 1000",
					   "session.max_pending_kb = 256",
					   "log.level = info",
					   NULL };
	const struct daemon_env_conf conf = { .set = set, .token = TOKEN };
	char err[256];
	if (daemon_env_init(&E, "clipmapd-test") ||
	    daemon_env_planet_text(&E, "test.ini", planet_v1, planet_path)) {
		daemon_env_fini(&E);
		return -1;
	}
	if (daemon_env_start(&E, &conf, err)) {
		fprintf(stderr, "test_server: %s\n", err);
		daemon_env_fini(&E); /* cmocka runs no group teardown after a failed setup */
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

/* ---- a minimal client --------------------------------------------------------------- */

struct cl {
	int fd;
	struct pbuf in;
	struct proto_msg m; /* the last message received */
	uint8_t *frame;	    /* its frame (TILE payloads point into it) */
};

static struct cl *cl_unix(void)
{
	struct cl *c = calloc(1, sizeof *c);
	c->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	assert_true(strlen(E.sock) < sizeof sa.sun_path);
	memcpy(sa.sun_path, E.sock, strlen(E.sock) + 1);
	assert_int_equal(connect(c->fd, (struct sockaddr *)&sa, sizeof sa), 0);
	pbuf_init(&c->in);
	return c;
}

static struct cl *cl_tcp(void)
{
	struct cl *c = calloc(1, sizeof *c);
	c->fd = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_port = htons((uint16_t)E.port),
				  .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	assert_int_equal(connect(c->fd, (struct sockaddr *)&sa, sizeof sa), 0);
	pbuf_init(&c->in);
	return c;
}

static void cl_free(struct cl *c)
{
	if (!c)
		return;
	proto_msg_fini(&c->m);
	free(c->frame);
	pbuf_fini(&c->in);
	close(c->fd);
	free(c);
}

static void cl_raw(struct cl *c, const void *p, size_t n)
{
	assert_int_equal(send(c->fd, p, n, MSG_NOSIGNAL), (ssize_t)n);
}

static void cl_send(struct cl *c, const struct proto_msg *m)
{
	struct pbuf b;
	pbuf_init(&b);
	char err[256];
	ssize_t n = proto_encode(&b, m, err);
	if (n < 0)
		fail_msg("encode: %s", err);
	cl_raw(c, b.data, b.len);
	pbuf_fini(&b);
}

/* Next message into c->m: 1, 0 on timeout, -1 on EOF. */
static int cl_recv(struct cl *c, int timeout_ms)
{
	proto_msg_fini(&c->m);
	free(c->frame);
	c->frame = NULL;
	uint64_t end = (uint64_t)clock_now_ms() + (uint64_t)timeout_ms;
	for (;;) {
		size_t need = 0;
		char err[256];
		struct proto_hdr h;
		ssize_t r = proto_frame_check(c->in.data, c->in.len, &h, &need, err);
		if (r < 0)
			fail_msg("bad frame from server: %s", err);
		if (r > 0) {
			c->frame = malloc((size_t)r);
			memcpy(c->frame, c->in.data, (size_t)r);
			pbuf_consume(&c->in, (size_t)r);
			ssize_t d = proto_decode(c->frame, (size_t)r, &c->m, &need, err);
			if (d != r)
				fail_msg("bad message from server: %s", err);
			return 1;
		}
		int left = (int)(end - (uint64_t)clock_now_ms());
		if ((int64_t)(end - (uint64_t)clock_now_ms()) <= 0)
			return 0;
		struct pollfd pf = { .fd = c->fd, .events = POLLIN };
		if (poll(&pf, 1, left) <= 0)
			return 0;
		pbuf_reserve(&c->in, 1 << 16);
		ssize_t n = recv(c->fd, c->in.data + c->in.len, 1 << 16, 0);
		if (n <= 0)
			return -1;
		c->in.len += (size_t)n;
	}
}

/* Receives until a message of `type` (skipping others); fails after timeout. */
static void cl_expect(struct cl *c, uint16_t type, int timeout_ms)
{
	uint64_t end = (uint64_t)clock_now_ms() + (uint64_t)timeout_ms;
	while ((uint64_t)clock_now_ms() < end) {
		int r = cl_recv(c, (int)(end - (uint64_t)clock_now_ms()));
		if (r < 0)
			fail_msg("connection closed waiting for %s", proto_type_name(type));
		if (r == 0)
			break;
		if (c->m.type == type)
			return;
		if (c->m.type == PROTO_ERROR && type != PROTO_ERROR)
			fail_msg("ERROR %u waiting for %s: %s", c->m.error.code, proto_type_name(type),
				 c->m.error.message);
	}
	fail_msg("timeout waiting for %s", proto_type_name(type));
}

static void cl_hello(struct cl *c, const char *token)
{
	struct proto_msg m = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .codecs = 1u << TCODEC_ZSTD | 1u << TCODEC_LZ4,
					  .token = (const uint8_t *)token,
					  .token_len = token ? (uint16_t)strlen(token) : 0,
					  .name = "test_server" } };
	cl_send(c, &m);
}

/* HELLO + OPEN "test": returns the planet id; fills layer node hashes. */
static uint32_t cl_open(struct cl *c, uint64_t nodes[2])
{
	cl_hello(c, NULL);
	cl_expect(c, PROTO_HELLO_OK, 5000);
	struct proto_msg m = { .type = PROTO_OPEN, .open = { .req = 7, .name = "test" } };
	cl_send(c, &m);
	cl_expect(c, PROTO_OPENED, 5000);
	assert_int_equal(c->m.opened.req, 7);
	assert_int_equal(c->m.opened.planet.nlayers, 2);
	if (nodes)
		for (int i = 0; i < 2; i++)
			nodes[i] = c->m.opened.planet.layers[i].node;
	return c->m.opened.planet_id;
}

static void cl_want(struct cl *c, uint32_t pid, uint32_t seq, double lon, double lat,
		    const struct proto_want_entry *e, uint32_t n)
{
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .lon = lon, .lat = lat,
					 .count = n, .entries = e } };
	cl_send(c, &m);
}

static uint64_t cl_stat(struct cl *c, const char *key)
{
	struct proto_msg m = { .type = PROTO_STATS_REQ, .stats_req = { .req = 99 } };
	cl_send(c, &m);
	cl_expect(c, PROTO_STATS, 5000);
	for (uint16_t i = 0; i < c->m.stats.count; i++)
		if (strcmp(c->m.stats.items[i].key, key) == 0)
			return c->m.stats.items[i].u;
	fail_msg("no stat %s", key);
	return 0;
}

/* Entries: both layers of a block of tiles at level (ly + 1, ly). */
static uint32_t block(struct proto_want_entry *e, int layers, int ly, uint32_t x0, uint32_t y0,
		      uint32_t w, uint32_t h)
{
	uint32_t n = 0;
	for (uint32_t y = y0; y < y0 + h; y++)
		for (uint32_t x = x0; x < x0 + w; x++)
			for (int l = 0; l < 2; l++)
				if (layers & (1 << l))
					e[n++] = (struct proto_want_entry){
						.layer = (uint8_t)l, .cls = PROTO_CLASS_VISIBLE,
						.lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly,
						.x = x % (2u << ly), .y = y };
	return n;
}

/* Decodes the last TILE's texels into out (caller frees). */
static uint8_t *tile_texels(struct cl *c)
{
	const struct proto_tile *t = &c->m.tile;
	uint8_t *px = malloc(t->enc.raw_len);
	struct tilecodec *tc = tilecodec_create();
	char err[256];
	int rc = tilecodec_decode(tc, &t->enc, t->payload, t->payload_len, px, t->enc.raw_len, err);
	tilecodec_destroy(tc);
	if (rc)
		fail_msg("tile decode: %s", err);
	return px;
}

/* ---- tests -------------------------------------------------------------------------- */

/* Received tiles are byte-identical to the same keys generated in-process, and node hashes
 * agree; coarse levels arrive before finer ones. */
static void test_tiles_match_inprocess(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint64_t nodes[2];
	uint32_t pid = cl_open(c, nodes);
	struct proto_want_entry e[256];
	/* Finest first in the list: the server must still send coarse levels first. */
	uint32_t n = 0;
	n += block(e + n, 3, 4, 10, 5, 4, 2);
	n += block(e + n, 3, 2, 3, 1, 2, 2);
	n += block(e + n, 3, 0, 0, 0, 2, 1);
	cl_want(c, pid, 1, 0, 0, e, n);

	struct planet *p;
	char err[256];
	assert_int_equal(planet_load(planet_path, &p, err), 0);
	assert_int_equal(p->layers[0].node->hash, nodes[0]);
	assert_int_equal(p->layers[1].node->hash, nodes[1]);
	struct cache *cache = cache_create(0);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = cache, .workers = 1 });

	int last_ly[2] = { -1, -1 }, got = 0;
	while (got < (int)n) {
		cl_expect(c, PROTO_TILE, 10000);
		const struct proto_tile *t = &c->m.tile;
		assert_int_equal(t->seq, 1);
		assert_int_equal(t->planet_id, pid);
		/* Coarse before fine for the height layer, whose tiles have no inputs. (A colour
		 * tile waits for its height input, and a worker may take a finer job before the
		 * manager queues the coarser dependent, so colour order is not strict.) */
		if (t->layer == 0)
			assert_true(t->key.ly >= last_ly[0]);
		last_ly[t->layer] = t->key.ly;
		assert_int_equal(t->enc.codec, TCODEC_NONE); /* Unix socket: raw */
		uint8_t *px = tile_texels(c);
		struct want w = { .node = p->layers[t->layer].node, .key = t->key,
				  .cls = SCHED_VISIBLE };
		struct tile *ref = NULL;
		assert_int_equal(sched_fetch(s, &w, 1, &ref), 0);
		assert_int_equal(ref->nbytes, t->enc.raw_len);
		assert_memory_equal(px, ref->data, ref->nbytes);
		tile_unref(ref);
		free(px);
		got++;
	}
	/* Nothing is sent twice. */
	assert_int_equal(cl_recv(c, 200), 0);
	sched_destroy(s);
	cache_destroy(cache);
	planet_unref(p);
	cl_free(c);
}

/* A second WANT replaces the first: the old set's tiles stop, the dropped ones are counted. */
static void test_want_replace(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint32_t pid = cl_open(c, NULL);
	uint64_t dropped0 = cl_stat(c, "tiles.dropped");
	static struct proto_want_entry a[4096], b[64];
	uint32_t na = block(a, 3, 9, 100, 40, 40, 30); /* 2400 fresh tiles */
	uint32_t nb = block(b, 3, 1, 0, 0, 4, 2);
	cl_want(c, pid, 1, 0, 0, a, na);
	cl_expect(c, PROTO_TILE, 10000);
	int got_a = 1, got_b = 0, a_after_b = 0;
	cl_want(c, pid, 2, 0, 0, b, nb);
	while (got_b < (int)nb) {
		cl_expect(c, PROTO_TILE, 10000);
		if (c->m.tile.seq == 1) {
			got_a++;
			a_after_b += got_b > 0;
		} else {
			assert_int_equal(c->m.tile.seq, 2);
			assert_int_equal(c->m.tile.key.ly, 1);
			got_b++;
		}
	}
	while (cl_recv(c, 300) > 0)
		if (c->m.type == PROTO_TILE && c->m.tile.seq == 1)
			got_a++, a_after_b++;
	assert_int_equal(a_after_b, 0);
	assert_true(got_a < (int)na / 2);
	uint64_t dropped = cl_stat(c, "tiles.dropped") - dropped0;
	assert_int_equal(dropped, (uint64_t)na - (uint64_t)got_a);
	cl_free(c);
}

/* Polls STATS until the scheduler has nothing queued, waiting or running. */
static void cl_wait_idle(struct cl *c)
{
	for (int i = 0; i < 1500; i++) {
		if (cl_stat(c, "sched.queued.visible") + cl_stat(c, "sched.queued.prefetch") +
			    cl_stat(c, "sched.queued.ahead") + cl_stat(c, "sched.queued.bulk") +
			    cl_stat(c, "sched.waiting") +
			    cl_stat(c, "sched.workers.busy") ==
		    0)
			return;
		usleep(20000);
	}
	fail_msg("the scheduler did not go idle in 30 s");
}

/* A viewer's visible window at level ly focused at (lon, lat) on this planet (64² tiles): the
 * lx it uses there (common/clipmap.h), both layers, appended from e. Returns the count. */
static uint32_t window_block(struct proto_want_entry *e, int ly, double lon, double lat)
{
	struct grid_quad q;
	grid_window(clipmap_level_lx(ly, lat, -1), ly, 64, CLIPMAP_WINDOW_TILES * 64, lon, lat, &q);
	struct tile_key k[GRID_WINDOW_MAX_KEYS];
	int nk = grid_quad_tiles(&q, 0, k);
	uint32_t n = 0;
	for (int i = 0; i < nk; i++)
		for (uint8_t l = 0; l < 2; l++)
			e[n++] = (struct proto_want_entry){ .layer = l, .cls = PROTO_CLASS_VISIBLE,
							    .lx = k[i].lx, .ly = k[i].ly, .x = k[i].x,
							    .y = k[i].y };
	return n;
}

/* Entries of b not in a (the same tile and layer). */
static uint32_t count_new(const struct proto_want_entry *a, uint32_t na,
			  const struct proto_want_entry *b, uint32_t nb)
{
	uint32_t n = 0;
	for (uint32_t i = 0; i < nb; i++) {
		bool seen = false;
		for (uint32_t j = 0; j < na && !seen; j++)
			seen = a[j].layer == b[i].layer && a[j].lx == b[i].lx && a[j].ly == b[i].ly &&
			       a[j].x == b[i].x && a[j].y == b[i].y;
		n += !seen;
	}
	return n;
}

/* The server's look-ahead: a viewer moving east at 10 km/s (a level-8 tile of this 1000 km
 * planet is 12 km wide) asks for its window; the window it will ask for 4 s later (40 km on,
 * along the great circle) is made before it asks — its new columns arrive with nothing
 * generated — while the window as far behind the start was not made (the control: it
 * generates). */
static void test_look_ahead(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint32_t pid = cl_open(c, NULL);
	static struct proto_want_entry e0[64], e[64];
	/* 40 km east of (31°E, 5°N) on a great circle of the 1000 km sphere */
	double d = 40.0 / 1000.0, p = 5 * M_PI / 180;
	double lat4 = asin(sin(p) * cos(d)) * 180 / M_PI;
	double dlon = atan2(sin(d) * cos(p), cos(d) - sin(p) * sin(lat4 * M_PI / 180)) * 180 / M_PI;
	uint32_t n0 = window_block(e0, 8, 31, 5);
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 1, .lon = 31, .lat = 5,
					 .vel = { 10000, 0, 0 }, .count = n0, .entries = e0 } };
	cl_send(c, &m);
	for (uint32_t i = 0; i < n0; i++)
		cl_expect(c, PROTO_TILE, 20000);
	cl_wait_idle(c);
	uint32_t n = window_block(e, 8, 31 + dlon, lat4); /* 4 s later */
	uint32_t fresh = count_new(e0, n0, e, n);
	assert_true(fresh >= 2 * 5 * 2); /* at least two new columns of 5 rows, 2 layers */
	assert_true(cl_stat(c, "lookahead.wants") >= fresh);
	uint64_t gen0 = cl_stat(c, "sched.generated");
	cl_want(c, pid, 2, 31, 5, e, n); /* the same focus, no velocity: no new look-ahead */
	uint32_t tiles = 0;
	while (tiles < fresh) /* the new columns (the others were sent already) */
		if (cl_recv(c, 20000) > 0 && c->m.type == PROTO_TILE)
			tiles++;
	cl_wait_idle(c);
	uint64_t gen1 = cl_stat(c, "sched.generated");
	printf("look-ahead: %llu tiles asked ahead; the window 4 s on: %u new tiles, %llu "
	       "generated\n",
	       (unsigned long long)cl_stat(c, "lookahead.wants"), fresh,
	       (unsigned long long)(gen1 - gen0));
	assert_int_equal(gen1, gen0);
	n = window_block(e, 8, 31 - dlon, 5); /* behind the start: never looked ahead to */
	fresh = count_new(e0, n0, e, n);
	cl_want(c, pid, 3, 31, 5, e, n);
	tiles = 0;
	while (tiles < fresh)
		if (cl_recv(c, 20000) > 0 && c->m.type == PROTO_TILE)
			tiles++;
	assert_true(cl_stat(c, "sched.generated") > gen1);
	cl_free(c);
}

/* 50 sessions fly around at once; every one receives every new tile of every step. */
static void test_fifty_sessions(void **state)
{
	(void)state;
	enum { NS = 50, STEPS = 4 };
	struct cl *c[NS];
	uint32_t pid[NS];
	for (int i = 0; i < NS; i++) {
		c[i] = cl_unix();
		pid[i] = cl_open(c[i], NULL);
	}
	struct proto_want_entry e[NS][64];
	uint32_t n[NS];
	for (int step = 0; step < STEPS; step++) {
		for (int i = 0; i < NS; i++) {
			/* A quad per level 0..5 around a focus that moves one tile per step. */
			n[i] = 0;
			for (int ly = 0; ly <= 5; ly++) {
				uint32_t W = 2u << ly, H = 1u << ly;
				uint32_t x = (uint32_t)(i * 7 + step) % W, y = (uint32_t)(i % H);
				n[i] += block(e[i] + n[i], 3, ly, x, y > H - 2 ? (H > 1 ? H - 2 : 0) : y, 2,
					      H > 1 ? 2 : 1);
			}
			cl_want(c[i], pid[i], (uint32_t)step + 1, i * 7.0, 0, e[i], n[i]);
		}
		for (int i = 0; i < NS; i++) {
			/* Tiles new in this step (the rest were sent before and stay wanted). */
			int expect = 0;
			for (uint32_t k = 0; k < n[i]; k++) {
				bool before = false;
				if (step > 0) {
					const struct proto_want_entry *q = &e[i][k];
					int ly = q->ly;
					uint32_t W = 2u << ly;
					uint32_t px = (uint32_t)(i * 7 + step - 1) % W;
					before = (q->x == px || q->x == (px + 1) % W);
				}
				expect += !before;
			}
			for (int k = 0; k < expect; k++) {
				cl_expect(c[i], PROTO_TILE, 20000);
				assert_int_equal(c[i]->m.tile.seq, (uint32_t)step + 1);
			}
		}
	}
	for (int i = 0; i < NS; i++) {
		assert_int_equal(cl_recv(c[i], i == 0 ? 200 : 1), 0);
		cl_free(c[i]);
	}
}

/* A session that never reads holds at most about max_pending bytes of output and does not
 * delay another session. */
static void test_stalled_session(void **state)
{
	(void)state;
	struct cl *x = cl_unix();
	int small = 4096;
	setsockopt(x->fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
	uint32_t px = cl_open(x, NULL);
	static struct proto_want_entry a[4096];
	uint32_t na = block(a, 3, 8, 0, 10, 64, 32); /* 4096 tiles, ~48 MiB */
	cl_want(x, px, 1, 0, 0, a, na);

	struct cl *y = cl_unix();
	uint32_t py = cl_open(y, NULL);
	struct proto_want_entry b[64];
	uint32_t nb = block(b, 3, 3, 0, 0, 8, 2);
	uint64_t t0 = (uint64_t)clock_now_ms();
	cl_want(y, py, 1, 0, 0, b, nb);
	for (uint32_t i = 0; i < nb; i++)
		cl_expect(y, PROTO_TILE, 10000);
	uint64_t dt = (uint64_t)clock_now_ms() - t0;
	/* Let x's tiles pile up, then look at its output queue. */
	uint64_t sent0 = cl_stat(y, "tiles.sent");
	usleep(500000);
	uint64_t pend_max = cl_stat(y, "sessions.pending_bytes.max");
	uint64_t sent1 = cl_stat(y, "tiles.sent");
	usleep(300000);
	uint64_t sent2 = cl_stat(y, "tiles.sent");
	print_message("stalled: other session's %u tiles in %llu ms, stalled queue %llu bytes, "
		      "%llu tiles into its socket\n", nb, (unsigned long long)dt,
		      (unsigned long long)pend_max, (unsigned long long)(sent1 - sent0));
	assert_true(pend_max <= 256 * 1024 + 64 * 64 * 4 + 100);
	/* x got what its socket holds (clipmapd asks for 4 MiB on Unix sessions, the kernel may
	 * double it: ≤ ~530 of these 16 KiB tiles), far from the 4096 it wants, and then nothing */
	assert_true(sent1 - sent0 < 1024);
	assert_true(sent2 - sent1 < 100);
	assert_true(dt < 5000);
	cl_free(x);
	cl_free(y);
}

struct badcase {
	const char *name;
	uint8_t bytes[64];
	size_t n;
	bool hello_first;
	uint16_t code;
};

static void put_hdr(uint8_t *b, uint8_t ver, uint16_t type, uint32_t len)
{
	memcpy(b, "CLMP", 4);
	b[4] = ver;
	b[5] = 0;
	b[6] = (uint8_t)type;
	b[7] = (uint8_t)(type >> 8);
	b[8] = (uint8_t)len;
	b[9] = (uint8_t)(len >> 8);
	b[10] = (uint8_t)(len >> 16);
	b[11] = (uint8_t)(len >> 24);
}

/* Each malformed-frame class gets an ERROR and a closed connection; another session goes on. */
static void test_malformed(void **state)
{
	(void)state;
	struct badcase cs[7] = {
		{ .name = "bad magic", .n = 12, .code = PROTO_E_PROTOCOL },
		{ .name = "bad version", .n = 12, .code = PROTO_E_VERSION },
		{ .name = "oversize", .n = 12, .hello_first = true, .code = PROTO_E_PROTOCOL },
		{ .name = "truncated", .n = 16, .hello_first = true, .code = PROTO_E_PROTOCOL },
		{ .name = "unknown type", .n = 12, .hello_first = true, .code = PROTO_E_PROTOCOL },
		{ .name = "want before hello", .n = 12 + 4, .code = PROTO_E_STATE },
		{ .name = "server message from client", .n = 12 + 4, .hello_first = true,
		  .code = PROTO_E_STATE },
	};
	memcpy(cs[0].bytes, "XLMP\1\0\0\0\0\0\0\0", 12);
	put_hdr(cs[1].bytes, PROTO_VERSION + 1, PROTO_STATS_REQ, 4);
	put_hdr(cs[2].bytes, PROTO_VERSION, PROTO_WANT, 1u << 20);
	put_hdr(cs[3].bytes, PROTO_VERSION, PROTO_OPEN, 4); /* req only, no name length */
	put_hdr(cs[4].bytes, PROTO_VERSION, 999, 0);
	put_hdr(cs[5].bytes, PROTO_VERSION, PROTO_STATS_REQ, 4);
	put_hdr(cs[6].bytes, PROTO_VERSION, PROTO_PREFETCH_PROGRESS, 4);
	/* STATS_REQ before HELLO is a state error; PREFETCH_PROGRESS is a server message and its
	 * body is too short, but the direction is checked: either way the peer must close. */
	struct cl *good = cl_unix();
	cl_open(good, NULL);
	for (int i = 0; i < 7; i++) {
		struct cl *c = cl_unix();
		if (cs[i].hello_first) {
			cl_hello(c, NULL);
			cl_expect(c, PROTO_HELLO_OK, 5000);
		}
		cl_raw(c, cs[i].bytes, cs[i].n);
		int r = cl_recv(c, 5000);
		if (r != 1 || c->m.type != PROTO_ERROR)
			fail_msg("%s: no ERROR (r=%d type=%u)", cs[i].name, r, c->m.type);
		if (i == 6)
			assert_true(c->m.error.code == PROTO_E_STATE ||
				    c->m.error.code == PROTO_E_PROTOCOL);
		else if (c->m.error.code != cs[i].code)
			fail_msg("%s: code %u, expected %u (%s)", cs[i].name, c->m.error.code,
				 cs[i].code, c->m.error.message);
		if (cl_recv(c, 5000) != -1)
			fail_msg("%s: connection not closed", cs[i].name);
		cl_free(c);
	}
	/* The good session carries on. */
	assert_true(cl_stat(good, "sessions") >= 1);
	cl_free(good);
}

/* The TCP listener requires the token: none or a wrong one is refused, the right one works,
 * and over TCP the negotiated codec is none on loopback. */
static void test_token(void **state)
{
	(void)state;
	const char *toks[3] = { NULL, "wrong", TOKEN };
	for (int i = 0; i < 3; i++) {
		struct cl *c = cl_tcp();
		cl_hello(c, toks[i]);
		int r = cl_recv(c, 5000);
		assert_int_equal(r, 1);
		if (i < 2) {
			assert_int_equal(c->m.type, PROTO_ERROR);
			assert_int_equal(c->m.error.code, PROTO_E_AUTH);
			assert_int_equal(cl_recv(c, 5000), -1);
		} else {
			assert_int_equal(c->m.type, PROTO_HELLO_OK);
			assert_int_equal(c->m.hello_ok.codecs, 0);
			assert_int_equal(c->m.hello_ok.limits.max_pending, 256 * 1024);
		}
		cl_free(c);
	}
}

/* Limits: an oversize want-set is refused with a clear message, the session stays usable. */
static void test_limits(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint32_t pid = cl_open(c, NULL);
	struct proto_want_entry e[4];
	uint32_t n = block(e, 1, 0, 0, 0, 2, 1);
	e[0].layer = 9;
	cl_want(c, pid, 1, 0, 0, e, n);
	cl_expect(c, PROTO_ERROR, 5000);
	assert_int_equal(c->m.error.code, PROTO_E_INVALID);
	cl_want(c, 42, 2, 0, 0, e, n);
	cl_expect(c, PROTO_ERROR, 5000);
	assert_int_equal(c->m.error.code, PROTO_E_NOT_FOUND);
	assert_true(cl_stat(c, "sessions") >= 1);
	cl_free(c);
}

/* PREFETCH over a bbox and a path: progress to done == total, tiles land in the cache
 * (CACHE_LS by level); a cancelled job says so. */
static void test_prefetch_and_cache_ls(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	cl_open(c, NULL);
	struct proto_msg m = { .type = PROTO_PREFETCH,
			       .prefetch = { .id = 1, .planet = "test", .layers = 1, .shape =
						     PROTO_SHAPE_BBOX, .lmin = 6, .lmax = 6,
					     .bbox = { 10, 10, 30, 20 } } };
	cl_send(c, &m);
	uint64_t total = 0;
	for (;;) {
		cl_expect(c, PROTO_PREFETCH_PROGRESS, 20000);
		assert_int_equal(c->m.prefetch_progress.id, 1);
		total = c->m.prefetch_progress.total;
		if (c->m.prefetch_progress.state != PROTO_JOB_RUNNING)
			break;
	}
	assert_int_equal(c->m.prefetch_progress.state, PROTO_JOB_DONE);
	assert_int_equal(c->m.prefetch_progress.done, total);
	/* 20° × 10° at level 6 (tiles of 180/64 ° = 2.8125°): what viewers anywhere in the box
	 * ask for, their 4×4-tile windows and the ring around them — rows 21..31, on lx 7
	 * columns 64..77 and on lx 6 (which a viewer coming from the north keeps there by
	 * hysteresis) columns 30..40. */
	assert_int_equal(total, 11 * (14 + 11));
	struct proto_msg ls = { .type = PROTO_CACHE_LS,
				.cache_ls = { .req = 5, .filter = PROTO_CLS_LEVEL | PROTO_CLS_PLANET,
					      .planet = "test", .lx = PROTO_ANY_LX, .ly = 6 } };
	cl_send(c, &ls);
	cl_expect(c, PROTO_CACHE_ENTRIES, 5000);
	assert_int_equal(c->m.cache_entries.req, 5);
	assert_true(c->m.cache_entries.total >= total);
	for (uint32_t i = 0; i < c->m.cache_entries.count; i++)
		assert_int_equal(c->m.cache_entries.entries[i].key.ly, 6);
	/* near filter: a tile far away is not listed */
	ls.cache_ls.filter = PROTO_CLS_NEAR | PROTO_CLS_LEVEL;
	ls.cache_ls.lon = -150;
	ls.cache_ls.lat = -60;
	ls.cache_ls.radius_m = 1000;
	cl_send(c, &ls);
	cl_expect(c, PROTO_CACHE_ENTRIES, 5000);
	assert_int_equal(c->m.cache_entries.total, 0);

	struct proto_lonlat pts[2] = { { 0, 0 }, { 10, 5 } };
	m.prefetch = (struct proto_prefetch){ .id = 2, .planet = "test", .shape = PROTO_SHAPE_PATH,
					      .lmin = 3, .lmax = 5, .width_m = 20000,
					      .npoints = 2, .points = pts };
	cl_send(c, &m);
	for (;;) {
		cl_expect(c, PROTO_PREFETCH_PROGRESS, 20000);
		if (c->m.prefetch_progress.state != PROTO_JOB_RUNNING)
			break;
	}
	assert_int_equal(c->m.prefetch_progress.state, PROTO_JOB_DONE);
	assert_true(c->m.prefetch_progress.total > 0);
	assert_int_equal(c->m.prefetch_progress.done, c->m.prefetch_progress.total);

	/* A big job, cancelled (within max_tiles_local and the 256 MiB cache: ~12 k tiles). */
	m.prefetch = (struct proto_prefetch){ .id = 3, .planet = "test", .shape = PROTO_SHAPE_BBOX,
					      .lmin = 9, .lmax = 10,
					      .bbox = { 0, 0, 10, 10 } };
	cl_send(c, &m);
	cl_expect(c, PROTO_PREFETCH_PROGRESS, 5000);
	struct proto_msg cancel = { .type = PROTO_PREFETCH_CANCEL, .prefetch_cancel = { .req = 3 } };
	cl_send(c, &cancel);
	for (;;) {
		cl_expect(c, PROTO_PREFETCH_PROGRESS, 5000);
		if (c->m.prefetch_progress.state != PROTO_JOB_RUNNING)
			break;
	}
	assert_int_equal(c->m.prefetch_progress.state, PROTO_JOB_CANCELLED);
	assert_true(c->m.prefetch_progress.done < c->m.prefetch_progress.total);
	cl_send(c, &cancel);
	cl_expect(c, PROTO_ERROR, 5000);
	assert_int_equal(c->m.error.code, PROTO_E_NOT_FOUND);
	cl_free(c);
}

/* SIGHUP after changing the colour ramp: the height layer keeps its node hash and cached
 * tiles; only the colour tiles are generated again. */
static void test_sighup_reload(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint64_t n1[2];
	uint32_t pid = cl_open(c, n1);
	struct proto_want_entry e[128];
	uint32_t n = block(e, 3, 2, 0, 0, 8, 4); /* 32 tiles × 2 layers */
	cl_want(c, pid, 1, 0, 0, e, n);
	for (uint32_t i = 0; i < n; i++)
		cl_expect(c, PROTO_TILE, 10000);
	uint64_t gen0 = cl_stat(c, "sched.generated");
	cl_free(c);

	write_file(planet_path, planet_v2);
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&E, "reloaded 1 planets", 1, 5000));

	c = cl_unix();
	uint64_t n2[2];
	pid = cl_open(c, n2);
	assert_int_equal(n1[0], n2[0]); /* height unchanged */
	assert_true(n1[1] != n2[1]);	/* colour downstream of the change */
	cl_want(c, pid, 1, 0, 0, e, n);
	for (uint32_t i = 0; i < n; i++) {
		cl_expect(c, PROTO_TILE, 10000);
		assert_int_equal(c->m.tile.key.node, n2[c->m.tile.layer]);
	}
	uint64_t gen1 = cl_stat(c, "sched.generated");
	assert_int_equal(gen1 - gen0, 32);
	cl_free(c);
}

/* A session open across reloads is rebound without reopening. A change upstream of the colour
 * layer: that layer's tiles come again (new node hash, the new bytes, equal to in-process
 * generation from the new file) and the height tiles do not. The planet removed: an ERROR
 * not-found naming it, its id no longer takes WANTs, a session that opened nothing hears
 * nothing, and once the planet is back an OPEN gives the freed id again. */
static void test_sighup_rebind(void **state)
{
	(void)state;
	enum { W = 8, H = 4 };
	struct cl *c = cl_unix(), *idle = cl_unix();
	cl_hello(idle, NULL);
	cl_expect(idle, PROTO_HELLO_OK, 5000);
	uint64_t n1[2];
	uint32_t pid = cl_open(c, n1); /* the file holds planet_v2 (test_sighup_reload) */
	struct proto_want_entry e[2 * W * H];
	uint32_t n = block(e, 3, 2, 0, 0, W, H);
	cl_want(c, pid, 1, 0, 0, e, n);
	uint8_t *old[W * H] = { 0 };
	for (uint32_t i = 0; i < n; i++) {
		cl_expect(c, PROTO_TILE, 10000);
		if (c->m.tile.layer == 1)
			old[c->m.tile.key.y * W + c->m.tile.key.x] = tile_texels(c);
	}

	int reloads = daemon_env_log_count(&E, "reloaded 1 planets");
	write_file(planet_path, planet_v1); /* the colour ramp changes back */
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	struct planet *p;
	char err[256];
	assert_int_equal(planet_load(planet_path, &p, err), 0);
	assert_int_equal(p->layers[0].node->hash, n1[0]);
	assert_true(p->layers[1].node->hash != n1[1]);
	struct cache *cache = cache_create(0);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = cache, .workers = 1 });
	int got[W * H] = { 0 }, differ = 0;
	for (int i = 0; i < W * H; i++) {
		cl_expect(c, PROTO_TILE, 10000);
		const struct proto_tile *t = &c->m.tile;
		assert_int_equal(t->planet_id, pid);
		assert_int_equal(t->layer, 1);
		assert_int_equal(t->key.node, p->layers[1].node->hash);
		int k = (int)(t->key.y * W + t->key.x);
		assert_int_equal(got[k]++, 0);
		uint8_t *px = tile_texels(c);
		struct want w = { .node = p->layers[1].node, .key = t->key, .cls = SCHED_VISIBLE };
		struct tile *ref = NULL;
		assert_int_equal(sched_fetch(s, &w, 1, &ref), 0);
		assert_int_equal(ref->nbytes, t->enc.raw_len);
		assert_memory_equal(px, ref->data, ref->nbytes);
		differ += memcmp(px, old[k], ref->nbytes) != 0;
		tile_unref(ref);
		free(px);
	}
	assert_true(differ >= W * H / 2); /* most tiles reach below 0 m, where the ramp changed */
	assert_int_equal(cl_recv(c, 300), 0); /* and no height tile again */
	assert_true(daemon_env_log_wait(&E, "reloaded 1 planets", reloads + 1, 5000));
	sched_destroy(s);
	cache_destroy(cache);
	planet_unref(p);
	for (int i = 0; i < W * H; i++)
		free(old[i]);

	char off[160];
	snprintf(off, sizeof off, "%s.off", planet_path);
	assert_int_equal(rename(planet_path, off), 0);
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	cl_expect(c, PROTO_ERROR, 5000);
	assert_int_equal(c->m.error.code, PROTO_E_NOT_FOUND);
	assert_int_equal(c->m.error.ref_type, PROTO_OPEN);
	assert_int_equal(c->m.error.ref_id, pid);
	assert_non_null(strstr(c->m.error.message, "\"test\""));
	assert_non_null(strstr(c->m.error.message, "removed"));
	cl_want(c, pid, 2, 0, 0, e, n);
	cl_expect(c, PROTO_ERROR, 5000);
	assert_int_equal(c->m.error.code, PROTO_E_NOT_FOUND);
	assert_int_equal(cl_stat(c, "planets"), 0);
	assert_int_equal(cl_recv(idle, 100), 0);
	assert_int_equal(cl_stat(idle, "planets"), 0);

	assert_int_equal(rename(off, planet_path), 0);
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&E, "reloaded 1 planets", reloads + 2, 5000));
	struct proto_msg m = { .type = PROTO_OPEN, .open = { .req = 8, .name = "test" } };
	cl_send(c, &m);
	cl_expect(c, PROTO_OPENED, 5000);
	assert_int_equal(c->m.opened.planet_id, pid);
	cl_want(c, pid, 3, 0, 0, e, 2);
	cl_expect(c, PROTO_TILE, 10000);
	assert_int_equal(c->m.tile.seq, 3);
	cl_free(c);
	cl_free(idle);
}

/* CACHE_LS reports how long ago each tile was last used: one wanted 1.1 s ago is at least a
 * second old, one just wanted is not. */
static void test_cache_ls_age(void **state)
{
	(void)state;
	struct cl *c = cl_unix();
	uint32_t pid = cl_open(c, NULL);
	struct proto_want_entry a = { .layer = 0, .cls = PROTO_CLASS_VISIBLE, .lx = 8, .ly = 7,
				      .x = 200, .y = 50 };
	struct proto_want_entry b = a;
	b.x = 201;
	cl_want(c, pid, 1, 0, 0, &a, 1);
	cl_expect(c, PROTO_TILE, 10000);
	struct timespec d = { 1, 100000000 };
	while (nanosleep(&d, &d) != 0)
		;
	cl_want(c, pid, 2, 0, 0, &b, 1);
	cl_expect(c, PROTO_TILE, 10000);
	struct proto_msg ls = { .type = PROTO_CACHE_LS,
				.cache_ls = { .req = 6, .filter = PROTO_CLS_LEVEL | PROTO_CLS_PLANET,
					      .planet = "test", .lx = 8, .ly = 7 } };
	cl_send(c, &ls);
	cl_expect(c, PROTO_CACHE_ENTRIES, 5000);
	int seen = 0;
	for (uint32_t i = 0; i < c->m.cache_entries.count; i++) {
		const struct proto_cache_entry *x = &c->m.cache_entries.entries[i];
		if (x->key.y != 50 || (x->key.x != 200 && x->key.x != 201))
			continue;
		seen++;
		if (x->key.x == 200)
			assert_true(x->age_s >= 1 && x->age_s < 30);
		else
			assert_int_equal(x->age_s, 0);
	}
	assert_int_equal(seen, 2);
	cl_free(c);
}

/* SIGTERM: every session gets ERROR shutdown and BYE, then EOF; the daemon exits 0. */
static void test_sigterm(void **state)
{
	(void)state;
	struct cl *a = cl_unix(), *b = cl_unix();
	uint32_t pid = cl_open(a, NULL);
	cl_open(b, NULL);
	static struct proto_want_entry e[4096];
	uint32_t n = block(e, 3, 10, 0, 0, 64, 32);
	cl_want(a, pid, 1, 0, 0, e, n);
	assert_int_equal(daemon_env_signal(&E, SIGTERM), 0);
	struct cl *cs[2] = { a, b };
	for (int i = 0; i < 2; i++) {
		bool shut = false, bye = false;
		for (;;) {
			int r = cl_recv(cs[i], 5000);
			if (r <= 0) {
				assert_int_equal(r, -1);
				break;
			}
			if (cs[i]->m.type == PROTO_ERROR)
				shut |= cs[i]->m.error.code == PROTO_E_SHUTDOWN;
			bye |= cs[i]->m.type == PROTO_BYE;
		}
		assert_true(shut);
		assert_true(bye);
	}
	int st = 0;
	assert_int_equal(daemon_env_stop(&E, 0, &st), 0);
	if (!WIFEXITED(st)) {
		char *l = daemon_env_log_read(&E);
		size_t len = l ? strlen(l) : 0;
		fprintf(stderr, "clipmapd log (end):\n%s\n", l ? l + (len > 3000 ? len - 3000 : 0) : "");
		free(l);
		fail_msg("clipmapd did not exit: signal %d", WTERMSIG(st));
	}
	assert_int_equal(WEXITSTATUS(st), 0);
	cl_free(a);
	cl_free(b);
}

/* systemd-analyze verify accepts the units (skipped where it is not installed). */
static void test_systemd_units(void **state)
{
	(void)state;
	if (system("command -v systemd-analyze >/dev/null 2>&1") != 0)
		skip();
	char exe[PATH_MAX], cmd[PATH_MAX * 3];
	snprintf(exe, sizeof exe, "%s/clipmapd", E.bindir);
	char *real = realpath(exe, NULL);
	assert_non_null(real);
	/* The units are templates (@BINDIR@: make install fills it); verify resolves ExecStart,
	 * so point a temporary copy of the units at the built binary. */
	*strrchr(real, '/') = '\0';
	snprintf(cmd, sizeof cmd,
		 "d=$(mktemp -d) && for u in service socket; do sed 's#@BINDIR@#%s#; "
		 "s#@CONFDIR@#/etc/clipmap#; s#@DOCDIR@#/usr/share/doc/clipmap#' "
		 "systemd/clipmapd.$u.in > $d/clipmapd.$u; done && "
		 "SYSTEMD_LOG_LEVEL=warning systemd-analyze verify --man=no $d/clipmapd.socket "
		 "$d/clipmapd.service > $d/out 2>&1; rc=$?; cat $d/out; rm -rf $d; exit $rc",
		 real);
	free(real);
	assert_int_equal(system(cmd), 0);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_tiles_match_inprocess),
		cmocka_unit_test(test_want_replace),
		cmocka_unit_test(test_look_ahead),
		cmocka_unit_test(test_fifty_sessions),
		cmocka_unit_test(test_stalled_session),
		cmocka_unit_test(test_malformed),
		cmocka_unit_test(test_token),
		cmocka_unit_test(test_limits),
		cmocka_unit_test(test_prefetch_and_cache_ls),
		cmocka_unit_test(test_sighup_reload),
		cmocka_unit_test(test_sighup_rebind),
		cmocka_unit_test(test_cache_ls_age),
		cmocka_unit_test(test_sigterm),
		cmocka_unit_test(test_systemd_units),
	};
	return cmocka_run_group_tests(tests, start_daemon, stop_daemon);
}
