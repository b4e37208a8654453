/* test_fleet_redis — the fleet's shared Redis tier ([store] redis) through real clipmapd
 * processes (tests/support/daemon_env) and a real redis-server the test starts on a Unix socket
 * in its temporary directory (--port 0, no persistence) and kills at the end. What an operator
 * would notice:
 *   - three daemons, a client on each asking for overlapping tile sets: every unique tile is
 *     generated once fleet-wide (the daemons' store.redis.generated add up to the unique tiles;
 *     any extra only with a lease takeover counted), and every client gets the same bytes;
 *   - kill -9 of the daemon holding a tile's lease: a client of another daemon waiting for that
 *     tile still gets it once the lease has expired (a takeover, counted);
 *   - leases much shorter than the queues: every tile arrives, duplicates only counted ones;
 *   - Redis stopped mid-run: clients see no error (the daemon generates), the daemon counts it
 *     and logs it once; Redis restarted: the daemon reconnects and sharing resumes; Redis
 *     not up yet when the daemons start: the same;
 *   - a record damaged in Redis is never served (counted, regenerated, the right bytes);
 *   - a daemon whose planet differs (another seed) never reads the others' tiles.
 * Skipped when build/clipmapd was not built or redis-server is not installed. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <hiredis/hiredis.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <xxhash.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/net_stat.h"
#include "support/redis_env.h"

static const char planet_fmt[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = %d\noctaves = 4\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

#define ND 3
#define MAXW 1024
#define MAXSEEN 4096

struct fleet {
	char dir[64];	     /* the test's own temporary directory (redis socket, its log) */
	struct redis_env redis; /* the private redis-server (redis.sock) */
	struct daemon_env d[ND];
	bool skip;
};

/* Starts daemon i on planet seed `seed` with the shared tier (lease lease_ms). */
static int daemon_start(struct fleet *f, int i, int seed, int lease_ms)
{
	struct daemon_env *e = &f->d[i];
	char text[1024], tag[32], set_redis[200], set_lease[64];
	snprintf(tag, sizeof tag, "test_fleet%d", i);
	snprintf(text, sizeof text, planet_fmt, seed);
	if (daemon_env_init(e, tag) || daemon_env_planet_text(e, "test.ini", text, NULL))
		return -1;
	snprintf(set_redis, sizeof set_redis, "store.redis = unix:%s", f->redis.sock);
	snprintf(set_lease, sizeof set_lease, "store.redis_lease_ms = %d", lease_ms);
	const char *const set[] = { set_redis, set_lease, "engine.workers = 2",
				    "session.max_rate = 0", "log.level = info", NULL };
	char err[256];
	if (daemon_env_start(e, &(struct daemon_env_conf){ .set = set }, err)) {
		fprintf(stderr, "test_fleet_redis: %s\n", err);
		return -1;
	}
	return 0;
}

/* n daemons on planet seeds[i] sharing one Redis with leases of lease_ms; with late, Redis is
 * not started (its socket path is configured all the same). */
static int setup_fleet(void **state, int n, const int *seeds, int lease_ms, bool late)
{
	struct fleet *f = calloc(1, sizeof *f);
	*state = f;
	if (!f)
		return -1;
	for (int i = 0; i < ND; i++)
		f->d[i].log_fd = -1;
	char bindir[512];
	if (daemon_env_bindir(bindir, sizeof bindir))
		return -1;
	char prog[600];
	snprintf(prog, sizeof prog, "%s/clipmapd", bindir);
	if (access(prog, X_OK) != 0) {
		f->skip = true;
		return 0;
	}
	if (!redis_env_installed()) {
		fprintf(stderr, "test_fleet_redis: redis-server is not installed (Debian package "
				"redis-server, `make deps`): skipped\n");
		f->skip = true;
		return 0;
	}
	snprintf(f->dir, sizeof f->dir, "/tmp/test_fleet_XXXXXX");
	if (!mkdtemp(f->dir))
		return -1;
	snprintf(f->redis.sock, sizeof f->redis.sock, "%s/redis.sock", f->dir);
	if (!late && redis_env_start(&f->redis, f->dir)) {
		fprintf(stderr, "test_fleet_redis: redis-server did not start\n");
		return -1;
	}
	for (int i = 0; i < n; i++)
		if (daemon_start(f, i, seeds[i], lease_ms))
			return -1;
	return 0;
}

static int setup_n(void **state, int n, const int *seeds, int lease_ms)
{
	return setup_fleet(state, n, seeds, lease_ms, false);
}

static int setup_late(void **state)
{
	return setup_fleet(state, 2, (const int[]){ 5, 5 }, 3000, true);
}

static int setup3(void **state)
{
	return setup_n(state, 3, (const int[]){ 5, 5, 5 }, 3000);
}

static int setup_kill(void **state)
{
	return setup_n(state, 2, (const int[]){ 5, 5 }, 1500);
}

static int setup_pair(void **state)
{
	return setup_n(state, 2, (const int[]){ 5, 5 }, 3000);
}

static int setup_short(void **state)
{
	return setup_n(state, 2, (const int[]){ 5, 5 }, 50);
}

static int setup_other(void **state)
{
	return setup_n(state, 2, (const int[]){ 5, 6 }, 3000);
}

static int teardown(void **state)
{
	struct fleet *f = *state;
	if (!f)
		return 0;
	for (int i = 0; i < ND; i++) {
		if (f->d[i].daemon > 0)
			daemon_env_stop(&f->d[i], SIGKILL, NULL);
		if (f->d[i].dir[0])
			daemon_env_fini(&f->d[i]);
	}
	redis_env_stop(&f->redis);
	if (f->dir[0])
		rmdir(f->dir);
	free(f);
	return 0;
}

#define NEED(f)               \
	do {                  \
		if ((f)->skip) \
			skip(); \
	} while (0)

static struct net_conn *conn(struct daemon_env *e, uint32_t *pid)
{
	struct net_conn *c = NULL;
	char err[256];
	if (net_connect(&(struct net_opts){ .socket_path = e->sock, .name = "test_fleet" }, &c,
			err))
		fail_msg("%s", err);
	struct proto_msg m = { 0 };
	if (net_open_planet(c, "test", &m, 5000, err))
		fail_msg("%s", err);
	*pid = m.opened.planet_id;
	proto_msg_fini(&m);
	return c;
}

static uint64_t stat_of(struct net_conn *c, const char *key)
{
	char err[256];
	uint64_t v = 0;
	if (net_stat_u64(c, key, &v, err))
		fail_msg("%s", err);
	return v;
}

/* Both layers of every tile of level (ly + 1, ly) in [x0, x0 + w) × [y0, y0 + h). */
static uint32_t block(struct proto_want_entry *w, uint32_t n, int ly, uint32_t x0, uint32_t y0,
		      uint32_t wd, uint32_t h)
{
	return net_want_block(w, n, MAXW, ly, x0, y0, wd, h);
}

/* The tiles every client received: (layer, key) → XXH3 of the texels, to compare across
 * daemons, and how many distinct there are. */
struct seen {
	struct {
		uint8_t layer;
		struct tile_key key;
		uint64_t h;
	} a[MAXSEEN];
	size_t n;
};

static void seen_add(struct seen *s, uint8_t layer, const struct tile_key *k, uint64_t h)
{
	for (size_t i = 0; i < s->n; i++)
		if (s->a[i].layer == layer && s->a[i].key.lx == k->lx && s->a[i].key.ly == k->ly &&
		    s->a[i].key.x == k->x && s->a[i].key.y == k->y) {
			if (s->a[i].h != h)
				fail_msg("layer %u tile (%u,%u) %u,%u: two daemons sent different "
					 "bytes", layer, k->lx, k->ly, k->x, k->y);
			return;
		}
	assert_true(s->n < MAXSEEN);
	s->a[s->n].layer = layer;
	s->a[s->n].key = *k;
	s->a[s->n++].h = h;
}

static void send_want(struct net_conn *c, uint32_t pid, uint32_t seq,
		      const struct proto_want_entry *w, uint32_t n)
{
	char err[256];
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .count = n, .entries = w } };
	if (net_send(c, &m, err))
		fail_msg("%s", err);
}

/* Receives the n tiles of WANT seq (every one must arrive, none may fail) into s (optional). */
static void receive(struct net_conn *c, uint32_t seq, uint32_t n, int timeout_ms, struct seen *s)
{
	char err[256];
	uint32_t got = 0;
	size_t cap = 64 * 64 * 4;
	uint8_t *px = malloc(cap);
	while (got < n) {
		struct proto_msg r = { 0 };
		if (net_recv(c, &r, timeout_ms, err))
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		if (r.type == PROTO_ERROR)
			fail_msg("ERROR from the daemon");
		if (r.type == PROTO_TILE && r.tile.seq == seq) {
			if (net_tile_decode(c, &r.tile, px, cap, err))
				fail_msg("%s", err);
			if (s)
				seen_add(s, r.tile.layer, &r.tile.key, XXH3_64bits(px, r.tile.enc.raw_len));
			got++;
		}
		proto_msg_fini(&r);
	}
	free(px);
}

static uint64_t fleet_sum(struct net_conn **c, int n, const char *key)
{
	uint64_t s = 0;
	for (int i = 0; i < n; i++)
		s += stat_of(c[i], key);
	return s;
}

/* Asks for w on c and receives every tile. */
static void fetch(struct net_conn *c, uint32_t pid, uint32_t seq, const struct proto_want_entry *w,
		  uint32_t n, struct seen *s)
{
	send_want(c, pid, seq, w, n);
	receive(c, seq, n, 60000, s);
}

/* Waits (bounded) until every tile the n daemons generated is written or dropped (the writes
 * are write-behind). */
static void wait_written(struct net_conn **c, int n)
{
	uint64_t end = clock_now_ms() + 10000;
	while (fleet_sum(c, n, "store.redis.writes") + fleet_sum(c, n, "store.redis.drops") <
		       fleet_sum(c, n, "store.redis.generated") &&
	       clock_now_ms() < end)
		usleep(20000);
	assert_int_equal(fleet_sum(c, n, "store.redis.writes") +
				 fleet_sum(c, n, "store.redis.drops"),
			 fleet_sum(c, n, "store.redis.generated"));
}

/* Three daemons, overlapping sets: each unique tile generated once fleet-wide. */
static void generated_once(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[ND][MAXW];
	static struct seen seen;
	seen.n = 0;
	uint32_t n[ND] = { 0 }, pid[ND];
	struct net_conn *c[ND];
	/* Overlapping windows: at level 3 (x 0..15, y 0..7) and level 5, shifted by two columns
	 * per daemon, so most tiles are wanted by two or three daemons. */
	for (int i = 0; i < ND; i++) {
		n[i] = block(w[i], 0, 3, (uint32_t)(2 * i), 0, 10, 8);
		n[i] = block(w[i], n[i], 5, (uint32_t)(20 + 2 * i), 10, 8, 6);
		c[i] = conn(&f->d[i], &pid[i]);
		assert_int_equal(stat_of(c[i], "store.redis.connected"), 1);
	}
	for (int i = 0; i < ND; i++)
		send_want(c[i], pid[i], 1, w[i], n[i]);
	for (int i = 0; i < ND; i++)
		receive(c[i], 1, n[i], 60000, &seen);
	wait_written(c, ND);
	uint64_t gen = fleet_sum(c, ND, "store.redis.generated");
	uint64_t take = fleet_sum(c, ND, "store.redis.takeovers") +
			fleet_sum(c, ND, "store.redis.expired");
	uint64_t hits = fleet_sum(c, ND, "store.redis.hits");
	uint64_t waits = fleet_sum(c, ND, "store.redis.waits");
	uint64_t all = (uint64_t)n[0] + n[1] + n[2];
	printf("fleet: %zu unique tiles wanted (%llu wants), %llu generated fleet-wide "
	       "(%.3f per unique), %llu Redis hits, %llu waits, %llu takeovers or expired leases\n",
	       seen.n, (unsigned long long)all, (unsigned long long)gen,
	       (double)gen / (double)seen.n, (unsigned long long)hits, (unsigned long long)waits,
	       (unsigned long long)take);
	assert_true(gen >= seen.n);
	if (gen > seen.n) /* duplicates only where a lease expired, and counted */
		assert_true(gen - seen.n <= take);
	assert_true(gen * 100 <= seen.n * 101);
	assert_int_equal(fleet_sum(c, ND, "store.redis.bad"), 0);
	assert_int_equal(fleet_sum(c, ND, "store.redis.drops"), 0);
	/* What was not generated here came from the fleet: every want is a hit or a generation
	 * (or a wait, then a hit). */
	assert_true(hits + gen >= seen.n);
	assert_true(hits > 0);
	for (int i = 0; i < ND; i++)
		net_close(c[i]);
}

/* Leases far shorter than the queues (50 ms): jobs outlive their leases, are confirmed or
 * found taken over before generating; every tile still arrives, the same bytes everywhere,
 * and any duplicate is counted (a takeover or an expired lease). */
static void short_lease(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[MAXW];
	static struct seen seen;
	seen.n = 0;
	uint32_t pid[2];
	struct net_conn *c[2] = { conn(&f->d[0], &pid[0]), conn(&f->d[1], &pid[1]) };
	uint32_t n = block(w, 0, 5, 0, 0, 12, 8);
	for (int i = 0; i < 2; i++)
		send_want(c[i], pid[i], 1, w, n);
	for (int i = 0; i < 2; i++)
		receive(c[i], 1, n, 60000, &seen);
	wait_written(c, 2);
	uint64_t gen = fleet_sum(c, 2, "store.redis.generated");
	uint64_t counted = fleet_sum(c, 2, "store.redis.takeovers") +
			   fleet_sum(c, 2, "store.redis.expired");
	printf("short lease: %zu unique tiles, %llu generated, %llu waits, %llu takeovers or "
	       "expired leases\n", seen.n, (unsigned long long)gen,
	       (unsigned long long)fleet_sum(c, 2, "store.redis.waits"),
	       (unsigned long long)counted);
	assert_int_equal(seen.n, n);
	assert_true(gen >= n);
	assert_true(gen - n <= counted);
	assert_int_equal(fleet_sum(c, 2, "store.redis.bad"), 0);
	net_close(c[0]);
	net_close(c[1]);
}

static bool any_lease(redisContext *rc)
{
	redisReply *r = redisCommand(rc, "KEYS cm:l:*");
	bool any = r && r->type == REDIS_REPLY_ARRAY && r->elements > 0;
	if (r)
		freeReplyObject(r);
	return any;
}

static bool any_value(redisContext *rc)
{
	redisReply *r = redisCommand(rc, "KEYS cm:t:*");
	bool any = r && r->type == REDIS_REPLY_ARRAY && r->elements > 0;
	if (r)
		freeReplyObject(r);
	return any;
}

/* kill -9 of the daemon holding a lease: the tile still reaches the other daemon's client. */
static void holder_killed(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	redisContext *rc = redisConnectUnix(f->redis.sock);
	assert_true(rc && !rc->err);
	uint32_t pa, pb;
	struct net_conn *a = conn(&f->d[0], &pa), *b = conn(&f->d[1], &pb);
	/* One height tile at a time on daemon A; A is stopped the moment its lease shows and
	 * before its tile does (else try the next tile: A was faster than the poll). */
	struct proto_want_entry w = { 0 };
	bool caught = false;
	for (uint32_t x = 0; x < 64 && !caught; x++) {
		w = (struct proto_want_entry){ .layer = 0, .cls = PROTO_CLASS_VISIBLE, .lx = 9,
					       .ly = 8, .x = 100 + x, .y = 50 };
		redisReply *r = redisCommand(rc, "FLUSHALL");
		if (r)
			freeReplyObject(r);
		send_want(a, pa, x + 1, &w, 1);
		uint64_t end = clock_now_ms() + 5000;
		while (!any_lease(rc) && !any_value(rc) && clock_now_ms() < end)
			;
		kill(f->d[0].daemon, SIGSTOP);
		caught = any_lease(rc) && !any_value(rc);
		if (!caught)
			kill(f->d[0].daemon, SIGCONT);
	}
	if (!caught) {
		redisFree(rc);
		net_close(a);
		net_close(b);
		fail_msg("daemon A never held a lease long enough to be stopped");
	}
	assert_int_equal(daemon_env_stop(&f->d[0], SIGKILL, NULL), 0);
	net_close(a);
	uint64_t t0 = clock_now_ms();
	send_want(b, pb, 1, &w, 1);
	receive(b, 1, 1, 30000, NULL);
	uint64_t dt = clock_now_ms() - t0;
	printf("holder killed: tile delivered by the other daemon after %llu ms (lease 1500 ms)\n",
	       (unsigned long long)dt);
	assert_true(stat_of(b, "store.redis.waits") >= 1);
	assert_int_equal(stat_of(b, "store.redis.takeovers"), 1);
	assert_int_equal(stat_of(b, "store.redis.generated"), 1);
	uint64_t end = clock_now_ms() + 10000; /* and B shared it (write-behind) */
	while (!any_value(rc) && clock_now_ms() < end)
		usleep(10000);
	assert_true(any_value(rc));
	net_close(b);
	redisFree(rc);
}

/* Waits (bounded: the daemons retry with backoff up to 5 s) until both daemons share again. */
static void wait_connected(struct net_conn *a, struct net_conn *b)
{
	uint64_t end = clock_now_ms() + 20000;
	while ((stat_of(a, "store.redis.connected") != 1 ||
		stat_of(b, "store.redis.connected") != 1) && clock_now_ms() < end)
		usleep(50000);
	assert_int_equal(stat_of(a, "store.redis.connected"), 1);
	assert_int_equal(stat_of(b, "store.redis.connected"), 1);
}

/* Redis stopped mid-run: no client error, counted, logged once; restarted: sharing resumes. */
static void redis_restart(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[MAXW];
	uint32_t pa, pb;
	struct net_conn *a = conn(&f->d[0], &pa), *b = conn(&f->d[1], &pb);
	uint32_t n = block(w, 0, 4, 0, 0, 6, 4);
	fetch(a, pa, 1, w, n, NULL);

	redis_env_stop(&f->redis);
	/* B asks for new tiles while Redis is gone: all arrive, generated by B. */
	n = block(w, 0, 4, 8, 6, 6, 4);
	uint64_t gen0 = stat_of(b, "store.redis.generated");
	fetch(b, pb, 2, w, n, NULL);
	assert_int_equal(stat_of(b, "store.redis.generated") - gen0, n);
	assert_int_equal(stat_of(b, "store.redis.connected"), 0);
	assert_true(stat_of(b, "store.redis.errors") >= 1);
	/* More tiles while down: still no error, and the log says it once, not per tile. */
	n = block(w, 0, 5, 0, 0, 6, 4);
	fetch(b, pb, 3, w, n, NULL);
	assert_int_equal(daemon_env_log_count(&f->d[1], "unreachable"), 1);

	assert_int_equal(redis_env_start(&f->redis, f->dir), 0);
	wait_connected(a, b);
	assert_true(daemon_env_log_count(&f->d[1], "connected, sharing tiles") >= 2);

	/* Sharing resumed: what A generates now, B takes from Redis. */
	n = block(w, 0, 6, 30, 20, 6, 4);
	fetch(a, pa, 4, w, n, NULL);
	wait_written(&a, 1);
	uint64_t hits0 = stat_of(b, "store.redis.hits");
	gen0 = stat_of(b, "store.redis.generated");
	fetch(b, pb, 4, w, n, NULL);
	assert_int_equal(stat_of(b, "store.redis.hits") - hits0, n);
	assert_int_equal(stat_of(b, "store.redis.generated"), gen0);
	net_close(a);
	net_close(b);
	/* A clean stop with Redis up (A) and with Redis gone again (B): exit status 0. */
	int st;
	assert_int_equal(daemon_env_stop(&f->d[0], SIGTERM, &st), 0);
	assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
	redis_env_stop(&f->redis);
	assert_int_equal(daemon_env_stop(&f->d[1], SIGTERM, &st), 0);
	assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
}

/* Redis not up when the daemons start: they start and serve all the same (logged once each),
 * and share once it is. */
static void redis_late(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[MAXW];
	uint32_t pa, pb;
	struct net_conn *a = conn(&f->d[0], &pa), *b = conn(&f->d[1], &pb);
	assert_int_equal(stat_of(a, "store.redis.connected"), 0);
	uint32_t n = block(w, 0, 4, 0, 0, 4, 4);
	fetch(a, pa, 1, w, n, NULL);
	assert_int_equal(stat_of(a, "store.redis.generated"), n);
	assert_int_equal(daemon_env_log_count(&f->d[0], "unreachable"), 1);

	assert_int_equal(redis_env_start(&f->redis, f->dir), 0);
	wait_connected(a, b);
	n = block(w, 0, 5, 10, 10, 4, 4);
	fetch(a, pa, 2, w, n, NULL);
	wait_written(&a, 1);
	fetch(b, pb, 2, w, n, NULL);
	assert_int_equal(stat_of(b, "store.redis.hits"), n);
	assert_int_equal(stat_of(b, "store.redis.generated"), 0);
	net_close(a);
	net_close(b);
}

/* A record damaged in Redis is never served: counted, regenerated, and the bytes are right. */
static void bad_record(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[MAXW];
	static struct seen seen;
	seen.n = 0;
	uint32_t pa, pb;
	struct net_conn *a = conn(&f->d[0], &pa), *b = conn(&f->d[1], &pb);
	uint32_t n = block(w, 0, 3, 0, 0, 6, 3);
	fetch(a, pa, 1, w, n, &seen);
	wait_written(&a, 1);
	/* One byte flipped at the end of every value (inside the compressed texels). */
	redisContext *rc = redisConnectUnix(f->redis.sock);
	assert_true(rc && !rc->err);
	redisReply *keys = redisCommand(rc, "KEYS cm:t:*");
	assert_true(keys && keys->type == REDIS_REPLY_ARRAY);
	assert_int_equal(keys->elements, n);
	for (size_t i = 0; i < keys->elements; i++) {
		redisReply *v = redisCommand(rc, "GET %s", keys->element[i]->str);
		assert_true(v && v->type == REDIS_REPLY_STRING && v->len > 41);
		char x = (char)(v->str[v->len - 1] ^ 0x5a);
		redisReply *r = redisCommand(rc, "SETRANGE %s %lld %b", keys->element[i]->str,
					     (long long)v->len - 1, &x, (size_t)1);
		assert_true(r && r->type == REDIS_REPLY_INTEGER);
		freeReplyObject(r);
		freeReplyObject(v);
	}
	freeReplyObject(keys);
	fetch(b, pb, 1, w, n, &seen); /* the same bytes as A sent */
	assert_int_equal(stat_of(b, "store.redis.bad"), n);
	assert_int_equal(stat_of(b, "store.redis.hits"), 0);
	assert_int_equal(stat_of(b, "store.redis.generated"), n);
	redisFree(rc);
	net_close(a);
	net_close(b);
}

/* A daemon whose planet differs (another seed: other content hashes) never reads the others'
 * tiles. */
static void other_planet(void **state)
{
	struct fleet *f = *state;
	NEED(f);
	static struct proto_want_entry w[MAXW];
	uint32_t pa, pb;
	struct net_conn *a = conn(&f->d[0], &pa), *b = conn(&f->d[1], &pb);
	uint32_t n = block(w, 0, 3, 0, 0, 8, 4);
	fetch(a, pa, 1, w, n, NULL);
	wait_written(&a, 1);
	assert_int_equal(stat_of(a, "store.redis.writes"), n);
	fetch(b, pb, 1, w, n, NULL);
	assert_int_equal(stat_of(b, "store.redis.hits"), 0);
	assert_int_equal(stat_of(b, "store.redis.waits"), 0);
	assert_int_equal(stat_of(b, "store.redis.generated"), n);
	net_close(a);
	net_close(b);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(generated_once, setup3, teardown),
		cmocka_unit_test_setup_teardown(holder_killed, setup_kill, teardown),
		cmocka_unit_test_setup_teardown(short_lease, setup_short, teardown),
		cmocka_unit_test_setup_teardown(redis_restart, setup_pair, teardown),
		cmocka_unit_test_setup_teardown(redis_late, setup_late, teardown),
		cmocka_unit_test_setup_teardown(bad_record, setup_pair, teardown),
		cmocka_unit_test_setup_teardown(other_planet, setup_other, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
