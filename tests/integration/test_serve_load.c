/* test_serve_load — clipmapd under the loads of issue 14 that concern tile serving, each on
 * its own real daemon (tests/support/daemon_env) with a planet of 256² tiles (256 KiB each):
 * - four sessions that never read, wanting 4096 tiles each, with cache_mb = 64: the daemon's
 *   resident memory (/proc/PID/status VmRSS) stays within cache_mb + image_cache_mb + the
 *   documented per-session allowance (2 × max_pending) × sessions + a fixed overhead, and goes
 *   back down once they close; their wants are withdrawn while they do not read;
 * - a client paused that way gets every tile, once, coarse first, when it reads again;
 * - 100 sessions with large want-sets closing at once: a new client's HELLO is answered
 *   promptly (the loop does not wait for the scheduler's manager per closed session);
 * - 100 sessions with want-sets being generated, then SIGTERM: the daemon is gone within the
 *   bound below (the manager is not waited for once per closed session);
 * - the loop-iteration histogram (loop.*) is in STATS;
 * - [engine] prefault: cache_mb of tile memory resident within seconds of start (RSS, the
 *   pool's STATS), and nothing mapped at idle with it off.
 * Timing bounds are generous for a loaded machine; the figures are printed.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
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

#include "common/clock.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/proc_rss.h"

#define MIB (1024.0 * 1024.0)

/* Sanitizers' allocators keep freed memory (quarantine) and add shadow memory: RSS figures
 * mean nothing there, the rest of the checks still run. */
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define RSS_CHECKS 0
#else
#define RSS_CHECKS 1
#endif

/* 256² tiles, cheap to make: one octave of noise and a colour ramp (two 256 KiB layers). */
static const char planet[] =
	"[planet]\nname = big\nbody = sphere\nradius = 1000000\ntile_size = 256\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 3\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\nstops = -500 0 0 255, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

/* ---- a minimal client over common/proto.h --------------------------------------------- */

struct cl {
	int fd;
	struct pbuf in;
	struct proto_msg m;
	uint8_t *frame;
	bool eof;
};

static struct cl *cl_connect(const struct daemon_env *e, int rcvbuf)
{
	struct cl *c = calloc(1, sizeof *c);
	assert_non_null(c);
	c->fd = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	assert_true(c->fd >= 0);
	if (rcvbuf)
		setsockopt(c->fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof rcvbuf);
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	assert_true(strlen(e->sock) < sizeof sa.sun_path);
	memcpy(sa.sun_path, e->sock, strlen(e->sock) + 1);
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

/* The next whole message into c->m: 1, 0 on timeout, -1 at end of stream. */
static int cl_recv(struct cl *c, int timeout_ms)
{
	proto_msg_fini(&c->m);
	free(c->frame);
	c->frame = NULL;
	int64_t end = clock_now_ms() + timeout_ms;
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
			if (proto_decode(c->frame, (size_t)r, &c->m, &need, err) != r)
				fail_msg("bad message from server: %s", err);
			return 1;
		}
		int64_t left = end - clock_now_ms();
		if (left <= 0)
			return 0;
		struct pollfd pf = { .fd = c->fd, .events = POLLIN };
		if (poll(&pf, 1, (int)left) <= 0)
			return 0;
		pbuf_reserve(&c->in, 1 << 16);
		ssize_t n = recv(c->fd, c->in.data + c->in.len, 1 << 16, 0);
		if (n <= 0)
			return -1;
		c->in.len += (size_t)n;
	}
}

static void cl_expect(struct cl *c, uint16_t type, int timeout_ms)
{
	int64_t end = clock_now_ms() + timeout_ms;
	while (clock_now_ms() < end) {
		int r = cl_recv(c, (int)(end - clock_now_ms()));
		if (r < 0)
			fail_msg("connection closed waiting for %s", proto_type_name(type));
		if (r == 0)
			break;
		if (c->m.type == type)
			return;
		if (c->m.type == PROTO_ERROR)
			fail_msg("ERROR %u waiting for %s: %s", c->m.error.code, proto_type_name(type),
				 c->m.error.message);
	}
	fail_msg("timeout waiting for %s", proto_type_name(type));
}

/* HELLO and OPEN "big"; returns the planet id. */
static uint32_t cl_open(struct cl *c)
{
	struct proto_msg h = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .name = "test_serve_load" } };
	cl_send(c, &h);
	cl_expect(c, PROTO_HELLO_OK, 10000);
	struct proto_msg o = { .type = PROTO_OPEN, .open = { .req = 1, .name = "big" } };
	cl_send(c, &o);
	cl_expect(c, PROTO_OPENED, 10000);
	return c->m.opened.planet_id;
}

/* WANT both layers of a w × h block at level ly from (x0, y0). */
static void cl_want_block(struct cl *c, uint32_t pid, int ly, uint32_t x0, uint32_t y0,
			  uint32_t w, uint32_t h)
{
	uint32_t n = 0;
	struct proto_want_entry *e = calloc(2 * w * h, sizeof *e);
	for (uint32_t y = y0; y < y0 + h; y++)
		for (uint32_t x = x0; x < x0 + w; x++)
			for (uint8_t l = 0; l < 2; l++)
				e[n++] = (struct proto_want_entry){ .layer = l,
								    .cls = PROTO_CLASS_VISIBLE,
								    .lx = (uint8_t)(ly + 1),
								    .ly = (uint8_t)ly,
								    .x = x % (2u << ly), .y = y };
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 1, .count = n, .entries = e } };
	cl_send(c, &m);
	free(e);
}

/* A STATS value (u64 or f64); NAN when the key is missing. */
static double cl_stat_opt(struct cl *c, const char *key)
{
	struct proto_msg m = { .type = PROTO_STATS_REQ, .stats_req = { .req = 9 } };
	cl_send(c, &m);
	cl_expect(c, PROTO_STATS, 10000);
	for (uint16_t i = 0; i < c->m.stats.count; i++) {
		const struct proto_stat *s = &c->m.stats.items[i];
		if (strcmp(s->key, key) == 0)
			return s->kind == PROTO_STAT_F64 ? s->f : (double)s->u;
	}
	return NAN;
}

/* A STATS value; fails when the key is missing. */
static double cl_stat(struct cl *c, const char *key)
{
	double v = cl_stat_opt(c, key);
	if (isnan(v))
		fail_msg("no stat %s", key);
	return v;
}

static bool has_stat(struct cl *c, const char *key)
{
	for (uint16_t i = 0; i < c->m.stats.count; i++)
		if (strcmp(c->m.stats.items[i].key, key) == 0)
			return true;
	return false;
}

/* The daemon's resident memory in bytes (VmRSS). */
static double rss(pid_t pid)
{
	uint64_t kb = proc_rss_kb(pid);
	assert_true(kb > 0);
	return (double)kb * 1024.0;
}

/* Each test's daemon; the teardown stops it even when the test failed. */
static struct daemon_env E;

/* Starts a daemon on the test planet with the config lines set; skips the test when
 * clipmapd was not built. */
static void start(const char *tag, const char *const *set)
{
	char err[256];
	assert_int_equal(daemon_env_init(&E, tag), 0);
	assert_int_equal(daemon_env_planet_text(&E, "big.ini", planet, NULL), 0);
	if (!daemon_env_built(&E, "clipmapd"))
		skip();
	if (daemon_env_start(&E, &(struct daemon_env_conf){ .set = set }, err))
		fail_msg("clipmapd: %s", err);
}

/* Stops the daemon (SIGTERM): a failed exit or a sanitizer report in its log (sanitized
 * builds) fails the test. */
static int teardown(void **state)
{
	(void)state;
	int rc = 0, st = 0;
	if (E.daemon > 0 && daemon_env_stop(&E, SIGTERM, &st) == 0 &&
	    !(WIFEXITED(st) && WEXITSTATUS(st) == 0)) {
		fprintf(stderr, "test_serve_load: clipmapd exit status %#x\n", st);
		rc = -1;
	}
	char *log = E.dir[0] ? daemon_env_log_read(&E) : NULL;
	if (log && (strstr(log, "Sanitizer") || strstr(log, "runtime error"))) {
		fprintf(stderr, "test_serve_load: clipmapd log:\n%s\n", log);
		rc = -1;
	}
	free(log);
	daemon_env_fini(&E);
	memset(&E, 0, sizeof E);
	return rc;
}

/* ---- tests ----------------------------------------------------------------------------- */

/* Four sessions that never read, each wanting 4096 tiles of 256 KiB (1 GiB each): the
 * daemon's RSS stays within the formula, their wants are withdrawn from the scheduler once
 * their output and held tiles are full (nothing more is made for them), and the memory drops
 * after they close. */
static void test_slow_readers_memory(void **state)
{
	(void)state;
	enum { NS = 4, CACHE_MB = 64, IMAGE_MB = 16, PENDING_KB = 8192, FIXED_MB = 80 };
	static const char *const set[] = { "engine.cache_mb = 64", "engine.image_cache_mb = 16",
					   "engine.workers = 2", "session.max_rate = 0",
					   "session.max_pending_kb = 8192", NULL };
	start("clipmapd-load-mem", set);
	struct cl *obs = cl_connect(&E, 0); /* a reading session for STATS */
	cl_open(obs);
	double base = rss(E.daemon);
	struct cl *c[NS];
	for (int i = 0; i < NS; i++) {
		c[i] = cl_connect(&E, 4096);
		uint32_t pid = cl_open(c[i]);
		cl_want_block(c[i], pid, 8, 0, (uint32_t)(32 * i), 64, 32); /* disjoint blocks */
	}
	double allowance = 2.0 * PENDING_KB * 1024.0;
	double bound = base + (CACHE_MB + IMAGE_MB + FIXED_MB) * MIB + NS * allowance;
	double peak = 0, gen = 0, held_max = 0, paused = 0, gen_paused = -1;
	int64_t t0 = clock_now_ms(), t_paused = 0;
	/* Until all four are paused (their wants withdrawn) and 2 s more, or 2400 tiles made
	 * (600 MiB: a daemon that held them all would be far over the bound). */
	while (clock_now_ms() - t0 < 60000) {
		usleep(200000);
		double r = rss(E.daemon);
		peak = r > peak ? r : peak;
		gen = cl_stat(obs, "sched.generated");
		double h = cl_stat_opt(obs, "sessions.held_bytes.max");
		held_max = isnan(h) || h > held_max ? h : held_max;
		paused = cl_stat_opt(obs, "sessions.paused");
		if (paused == NS && !t_paused) {
			t_paused = clock_now_ms();
			usleep(300000); /* jobs already running finish */
			gen_paused = cl_stat(obs, "sched.generated");
		}
		if (gen >= 2400 || (t_paused && clock_now_ms() - t_paused > 2000))
			break;
	}
	double parked = cl_stat_opt(obs, "tiles.parked");
	print_message("at the end: cache %.1f MiB, held %.1f MiB, output buffers %.1f MiB, "
		      "queued output %.1f MiB\n", cl_stat(obs, "cache.bytes") / MIB,
		      cl_stat_opt(obs, "sessions.held_bytes") / MIB,
		      cl_stat_opt(obs, "sessions.out_bytes") / MIB,
		      cl_stat(obs, "sessions.pending_bytes") / MIB);
	for (int i = 0; i < NS; i++)
		cl_free(c[i]);
	/* Closed sessions' memory goes back at the next housekeeping tick (malloc_trim). */
	double after = 0;
	for (int k = 0; k < 20; k++) {
		usleep(250000);
		after = rss(E.daemon);
		if (cl_stat(obs, "sessions") == 1 && cl_stat_opt(obs, "memory.trims") >= 1 &&
		    after <= base + (CACHE_MB + FIXED_MB) * MIB)
			break;
	}
	print_message("malloc_trim took up to %.1f ms\n", cl_stat_opt(obs, "memory.trim_max_ms"));
	/* The tile pool (off under ASan: all 0): what closed sessions held is free again, and
	 * the free memory it keeps resident is within its bound (cache_mb / 4 + 64 MiB). */
	double pool = cl_stat(obs, "memory.pool.mapped"), in_use = cl_stat(obs, "memory.pool.in_use");
	double warm = cl_stat(obs, "memory.pool.free_warm");
	print_message("tile pool after they closed: %.0f MiB mapped, %.0f MiB in use, %.0f MiB "
		      "free and resident, %.0f MiB released\n", pool / MIB, in_use / MIB, warm / MIB,
		      cl_stat(obs, "memory.pool.released") / MIB);
	if (pool > 0) {
		assert_true(in_use <= pool);
		assert_true(in_use <= (CACHE_MB + 16) * MIB);
		assert_true(warm <= (CACHE_MB / 4 + 64) * MIB + 1);
	}
	print_message("slow readers: RSS at start %.0f MiB, peak %.0f MiB (bound %.0f MiB), "
		      "%.0f MiB after they closed; %.0f tiles made, %.0f parked, held max %.1f MiB\n",
		      base / MIB, peak / MIB, bound / MIB, after / MIB, gen, parked, held_max / MIB);
	print_message("all %d paused after %lld ms; %.0f tiles made after that\n", NS,
		      (long long)(t_paused ? t_paused - t0 : -1), gen - gen_paused);
	if (RSS_CHECKS)
		assert_true(peak <= bound);
	assert_true(held_max <= PENDING_KB * 1024.0 + 256 * 1024);
	assert_true(parked > 0);
	assert_true(t_paused > 0);
	/* paused: nothing more is made for them (a few reports in flight at most) */
	assert_true(gen - gen_paused <= 8);
	if (RSS_CHECKS) {
		assert_true(after <= base + (CACHE_MB + FIXED_MB) * MIB);
		assert_true(after < peak);
	}
	cl_free(obs);
}

/* A client that stops reading is paused (its held tiles and output full); when it reads
 * again it gets every tile it wants, each once, coarse levels first, and few are made twice. */
static void test_paused_session_resumes(void **state)
{
	(void)state;
	static const char *const set[] = { "engine.cache_mb = 64", "engine.workers = 2",
					   "session.max_rate = 0", "session.max_pending_kb = 1024",
					   NULL };
	start("clipmapd-load-resume", set);
	struct cl *obs = cl_connect(&E, 0);
	cl_open(obs);
	struct cl *c = cl_connect(&E, 4096);
	uint32_t pid = cl_open(c);
	/* 2 × 1024 tiles at level 8 and 2 × 4 at level 6 (coarser, wanted last). Enough that
	 * making them all takes longer than pausing: on huge pages two workers made 136 such
	 * tiles within one 100 ms poll, and a session whose tiles are all made has nothing to
	 * pause for (with the ramp twice as fast, 2 × 576 were once all made first, 1 run in 7). */
	enum { W8 = 32, N = 2 * W8 * W8 + 8 };
	struct proto_want_entry e[N];
	uint32_t n = 0;
	for (int ly = 8; ly >= 6; ly -= 2) {
		uint32_t w = ly == 8 ? W8 : 2;
		for (uint32_t y = 0; y < w; y++)
			for (uint32_t x = 0; x < w; x++)
				for (uint8_t l = 0; l < 2; l++)
					e[n++] = (struct proto_want_entry){
						.layer = l, .cls = PROTO_CLASS_VISIBLE,
						.lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly, .x = x,
						.y = y };
	}
	assert_int_equal(n, N);
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 3, .count = n, .entries = e } };
	cl_send(c, &m);
	int64_t t0 = clock_now_ms();
	while (cl_stat(obs, "sessions.paused") < 1 && clock_now_ms() - t0 < 30000)
		usleep(100000);
	assert_int_equal(cl_stat(obs, "sessions.paused"), 1);
	double made = cl_stat(obs, "sched.generated");
	bool seen[N] = { false };
	int got = 0, last_coarse = 0;
	while (got < N) {
		int r = cl_recv(c, 60000);
		if (r <= 0)
			fail_msg("%d of %d tiles, then %s", got, N, r ? "EOF" : "a timeout");
		if (c->m.type != PROTO_TILE)
			continue;
		const struct proto_tile *t = &c->m.tile;
		int k = -1;
		for (int i = 0; i < N; i++)
			if (e[i].ly == t->key.ly && e[i].x == t->key.x && e[i].y == t->key.y &&
			    e[i].layer == t->layer)
				k = i;
		assert_true(k >= 0);
		assert_false(seen[k]); /* each once */
		seen[k] = true;
		got++;
		if (t->key.ly == 6)
			last_coarse = got;
	}
	print_message("paused after %.0f tiles made; all %d received, %.0f made in all, "
		      "%.0f re-looked up in the cache, %.0f made again\n", made, N,
		      cl_stat(obs, "sched.generated"), cl_stat(obs, "tiles.relooked"),
		      cl_stat(obs, "tiles.rewanted"));
	assert_true(made < N); /* it did stop making them */
	/* it asked for no more than it could hold: tiles made, parked beyond its held budget and
	 * let go by the 64 MiB cache before it read them, made again, were 2 039 (of 3 754 made)
	 * when a session asked for its whole want-set at once; now 94-265 (11 runs, 5 December,
	 * with and without [engine] prefault), so the bound is N / 6 (N / 8 failed one make
	 * check at 265) */
	assert_true(cl_stat(obs, "tiles.rewanted") <= N / 6);
	/* coarse first: the 8 level-6 tiles, wanted last, are among the first sent (what the
	 * socket held at the pause, ≤ 40 tiles, plus themselves) */
	assert_true(last_coarse <= 48);
	cl_free(c);
	cl_free(obs);
}

/* 100 sessions reading their tiles while the workers make them and 10 that never read;
 * SIGTERM: every one ends (the readers after their BYE, the others cut off after the grace
 * period), and the daemon exits 0 within the bound (9.6 s in issue 14's run). */
static void test_sigterm_hundred(void **state)
{
	(void)state;
	enum { NS = 100 };
	/* 1 MiB of output queued per session at most: the test is about closing, not about
	 * how fast this one thread reads 100 sessions' queues */
	static const char *const set[] = { "engine.cache_mb = 64", "engine.workers = 2",
					   "session.max_rate = 0", "session.max_pending_kb = 1024",
					   NULL };
	start("clipmapd-load-term", set);
	enum { NX = 10 };
	static struct cl *c[NS], *x[NX];
	for (int i = 0; i < NX; i++) {
		x[i] = cl_connect(&E, 4096);
		uint32_t pid = cl_open(x[i]);
		cl_want_block(x[i], pid, 9, 0, (uint32_t)(32 * i), 64, 32);
	}
	for (int i = 0; i < NS; i++) {
		c[i] = cl_connect(&E, 0);
		uint32_t pid = cl_open(c[i]);
		/* 32 × 8 tiles at level 7 each, overlapping in pairs: plenty of work queued */
		cl_want_block(c[i], pid, 7, (uint32_t)(16 * (i / 2)) % 256, 0, 32, 8);
	}
	/* Read everything (1 s of tiles, then SIGTERM) until every session ends and the
	 * daemon exits. */
	int open = NS, status = 0;
	int64_t exited = 0, last_eof = 0, t0 = clock_now_ms() + 1000;
	uint64_t bytes = 0, before = 0;
	bool termed = false;
	pid_t pid = E.daemon;
	while ((open || !exited) && clock_now_ms() - t0 < 30000) {
		if (!termed && clock_now_ms() >= t0) {
			t0 = clock_now_ms();
			assert_int_equal(daemon_env_signal(&E, SIGTERM), 0);
			termed = true;
			before = bytes;
		}
		struct pollfd pf[NS];
		int np = 0;
		for (int i = 0; i < NS; i++)
			if (!c[i]->eof)
				pf[np++] = (struct pollfd){ .fd = c[i]->fd, .events = POLLIN };
		if (np)
			poll(pf, (nfds_t)np, 20);
		else
			usleep(5000);
		for (int i = 0; i < NS; i++) {
			if (c[i]->eof)
				continue;
			char buf[1 << 16];
			ssize_t n;
			while ((n = recv(c[i]->fd, buf, sizeof buf, MSG_DONTWAIT)) > 0)
				bytes += (uint64_t)n;
			if (!termed && n == 0)
				fail_msg("session %d ended before SIGTERM", i);
			if (n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK)) {
				c[i]->eof = true;
				last_eof = clock_now_ms();
				open--;
			}
		}
		if (!exited && waitpid(pid, &status, WNOHANG) == pid) {
			exited = clock_now_ms();
			E.daemon = 0;
		}
	}
	int64_t dt = exited ? exited - t0 : -1;
	print_message("SIGTERM with %d reading sessions and %d that never read: the readers "
		      "ended after %lld ms (%.1f MiB read meanwhile), the daemon exited after "
		      "%lld ms\n", NS, NX,
		      (long long)(last_eof - t0), (double)(bytes - before) / MIB, (long long)dt);
	assert_int_equal(open, 0);
	assert_true(exited);
	assert_true(WIFEXITED(status) && WEXITSTATUS(status) == 0);
	/* 2 s is the goal (1.25 s of grace for the non-readers, one 250 ms tick); the margin
	 * is for a loaded 2-core machine. */
	assert_true(dt <= 3500);
	for (int i = 0; i < NS; i++)
		cl_free(c[i]);
	for (int i = 0; i < NX; i++)
		cl_free(x[i]);
}

/* 100 sessions with large want-sets close at once: the loop does not wait for the manager
 * once per closed session, so a new client's HELLO is answered promptly and the loop's
 * longest iteration stays short. */
static void test_close_at_once(void **state)
{
	(void)state;
	enum { NS = 100 };
	static const char *const set[] = { "engine.cache_mb = 64", "engine.workers = 2",
					   "session.max_rate = 0", "session.max_pending_kb = 1024",
					   NULL };
	start("clipmapd-load-close", set);
	static struct cl *c[NS];
	for (int i = 0; i < NS; i++) {
		c[i] = cl_connect(&E, 0);
		uint32_t pid = cl_open(c[i]);
		/* 512 distinct tiles each at level 9: every session's list stays active */
		cl_want_block(c[i], pid, 9, (uint32_t)(16 * i), 0, 16, 16);
	}
	usleep(1000000);
	struct cl *probe = cl_connect(&E, 0);
	cl_open(probe);
	double max0 = cl_stat_opt(probe, "loop.max_ms");
	for (int i = 0; i < NS; i++) {
		cl_free(c[i]);
		c[i] = NULL;
	}
	int64_t t0 = clock_now_ms();
	struct cl *fresh = cl_connect(&E, 0);
	struct proto_msg h = { .type = PROTO_HELLO,
			       .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					  .name = "fresh" } };
	cl_send(fresh, &h);
	cl_expect(fresh, PROTO_HELLO_OK, 30000);
	int64_t hello_ms = clock_now_ms() - t0;
	while (cl_stat(probe, "sessions") > 2 && clock_now_ms() - t0 < 30000)
		usleep(20000);
	int64_t closed_ms = clock_now_ms() - t0;
	double max1 = cl_stat_opt(probe, "loop.max_ms");
	print_message("malloc_trim took up to %.1f ms\n", cl_stat_opt(probe, "memory.trim_max_ms"));
	print_message("%d sessions closed at once: all gone after %lld ms, a new HELLO answered "
		      "in %lld ms; loop max %.1f ms before, %.1f ms after\n", NS,
		      (long long)closed_ms, (long long)hello_ms, max0, max1);
	/* 100 ms is the goal; the margin is for a loaded 2-core machine */
	assert_true(hello_ms <= 1000);
	cl_free(fresh);
	cl_free(probe);
}

/* STATS carries the loop-iteration histogram: count, max, p99, the buckets, which add up. */
static void test_loop_histogram(void **state)
{
	(void)state;
	start("clipmapd-load-loop", NULL);
	struct cl *c = cl_connect(&E, 0);
	uint32_t pid = cl_open(c);
	cl_want_block(c, pid, 3, 0, 0, 4, 2);
	for (int i = 0; i < 16; i++)
		cl_expect(c, PROTO_TILE, 20000);
	double iters = cl_stat(c, "loop.iterations");
	static const char *const keys[] = { "loop.max_ms", "loop.p99_ms", "loop.over_50ms",
					    "loop.le_1ms", "loop.le_50ms", "loop.gt_5000ms",
					    "loop.over_50ms.work", "loop.over_50ms.blocked",
					    "loop.over_50ms.preempted", "loop.cpu_max_ms" };
	for (size_t i = 0; i < sizeof keys / sizeof keys[0]; i++)
		if (!has_stat(c, keys[i]))
			fail_msg("no stat %s", keys[i]);
	static const unsigned bounds[] = { 1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000 };
	double sum = cl_stat(c, "loop.gt_5000ms");
	for (size_t i = 0; i < sizeof bounds / sizeof bounds[0]; i++) {
		char k[32];
		snprintf(k, sizeof k, "loop.le_%ums", bounds[i]);
		sum += cl_stat(c, k);
	}
	double max = cl_stat(c, "loop.max_ms"), p99 = cl_stat(c, "loop.p99_ms");
	print_message("loop: %.0f iterations, max %.2f ms, p99 ≤ %.2f ms\n", iters, max, p99);
	assert_true(iters >= 4); /* at least: connect, HELLO, OPEN, WANT */
	assert_true(sum >= iters && sum <= iters + 40); /* STATS requests counted meanwhile */
	assert_true(max > 0 && p99 <= max);
	/* the over-50 ms iterations, by why, add up; no iteration used more CPU than time */
	assert_true(cl_stat(c, "loop.over_50ms.work") + cl_stat(c, "loop.over_50ms.blocked") +
			    cl_stat(c, "loop.over_50ms.preempted") ==
		    cl_stat(c, "loop.over_50ms"));
	assert_true(cl_stat(c, "loop.cpu_max_ms") <= cl_stat(c, "loop.max_ms") + 1.0);
	cl_free(c);
}

/* [engine] prefault (on by default): within seconds of start, before any tile is asked for,
 * the tile pool holds cache_mb of buffers, resident (the daemon's RSS), free for the first
 * tiles; memory.pool.prefault_left counts down to 0. */
static void test_prefault_at_start(void **state)
{
	(void)state;
	static const char *const set[] = { "engine.cache_mb = 128", "engine.workers = 1", NULL };
	start("clipmapd-load-prefault", set);
	struct cl *c = cl_connect(&E, 0);
	cl_open(c);
	double left = -1;
	for (int i = 0; i < 600 && left != 0; i++) { /* 60 s: an idle-priority thread */
		left = cl_stat(c, "memory.pool.prefault_left");
		if (left != 0)
			usleep(100000);
	}
	double mapped = cl_stat(c, "memory.pool.mapped"), warm = cl_stat(c, "memory.pool.free_warm");
	double r = rss(E.daemon);
	print_message("prefault: %.0f MiB mapped, %.0f MiB free and resident, RSS %.0f MiB\n",
		      mapped / MIB, warm / MIB, r / MIB);
	assert_true(left == 0);
	if (mapped > 0) { /* 0: the pool is bypassed (AddressSanitizer) */
		assert_true(mapped >= 128 * MIB);
		assert_true(warm >= 120 * MIB);
		assert_true(r >= 128 * MIB);
		assert_int_equal(cl_stat(c, "memory.pool.in_use"), 0);
	}
	cl_free(c);
}

/* prefault = false: nothing is mapped until tiles are made. */
static void test_prefault_off(void **state)
{
	(void)state;
	static const char *const set[] = { "engine.cache_mb = 128", "engine.workers = 1",
					   "engine.prefault = false", NULL };
	start("clipmapd-load-noprefault", set);
	struct cl *c = cl_connect(&E, 0);
	cl_open(c);
	usleep(1000000);
	print_message("no prefault: %.0f MiB mapped, RSS %.0f MiB\n",
		      cl_stat(c, "memory.pool.mapped") / MIB, rss(E.daemon) / MIB);
	assert_true(cl_stat(c, "memory.pool.prefault_left") == 0);
	assert_true(cl_stat(c, "memory.pool.mapped") == 0);
	cl_free(c);
}

/* An argument: run only the tests whose names match it (cmocka's filter). */
int main(int argc, char **argv)
{
	signal(SIGPIPE, SIG_IGN);
	if (argc > 1)
		cmocka_set_test_filter(argv[1]);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_teardown(test_loop_histogram, teardown),
		cmocka_unit_test_teardown(test_prefault_at_start, teardown),
		cmocka_unit_test_teardown(test_prefault_off, teardown),
		cmocka_unit_test_teardown(test_slow_readers_memory, teardown),
		cmocka_unit_test_teardown(test_paused_session_resumes, teardown),
		cmocka_unit_test_teardown(test_sigterm_hundred, teardown),
		cmocka_unit_test_teardown(test_close_at_once, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
