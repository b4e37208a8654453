/* test_prefetch_daemon — PREFETCH that cannot hurt the daemon (issue 14) and its estimate
 * (issue 13), through a real clipmapd (tests/support/daemon_env) with a disk store, over
 * client/net.h. What an operator or an attacker would notice:
 *   - the 67-byte PREFETCH of a corridor 9.55e6 m wide at level 22 is answered with ERROR
 *     `limit` naming the estimate at once (printed; asserted under a generous 2 s on this
 *     loaded machine), the daemon's RSS does not grow, and `status` answers meanwhile; the
 *     same for a 4096-point path at the widest width the protocol takes;
 *   - the whole planet at levels 0-11 (25 M tiles) is refused with its estimate to a local
 *     client without the token, and to one with it (over [prefetch] max_tiles);
 *   - caps: one job at a time without the token ([prefetch] max_jobs_local), [session]
 *     max_jobs with it, [prefetch] max_jobs_total over every session;
 *   - PREFETCH_DRY answers the estimate per level with the disk tier's budget, and a
 *     PREFETCH larger than that budget is refused with the same estimate;
 *   - a job that runs ends with done = total (the total made exact as its levels are built);
 *   - a region prefetched at 46°N, the daemon restarted: a viewer there generates 0 tiles;
 *   - prefetched tiles are written through to the disk tier: no memory-cache insert or
 *     eviction, a viewer's tiles still served from memory; a second run generates nothing;
 *   - jobs that each fit the store's budget but not together: the last succeeds and
 *     clipmapctl, the log and status say the store evicted prefetched tiles.
 * Skipped when build/clipmapd was not built. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <errno.h>
#include <lmdb.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clipmap.h"
#include "common/clock.h"
#include "common/grid.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/net_stat.h"
#include "support/proc_rss.h"

#define TOKEN "pf-token-123"
/* overflowing_prefetches_say_so: jobs that each fit a 10 MiB store, not all together. The
 * first is estimated at its raw size (~20 KiB a 64² tile: nothing is stored yet), so it is
 * small (436 tiles); the next ones at what stored tiles take (~2.4 KiB): 3160 and 3254 tiles,
 * ~7.5 MiB each. */
#define PF_FULL_MB "10"
#define PF_FULL_A "10,10,10.4,10.4"
#define PF_FULL_A_LEVELS "8-9"
#define PF_FULL_B "20,10,21,11"
#define PF_FULL_C "30,10,31,11"
#define PF_FULL_BC_LEVELS "4-11"

static const char planet_text[] =
	"[planet]\nname = test\nbody = sphere\nradius = 6371000\ntile_size = 64\nmax_level = 22\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 2\nwavelength = 3000000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

struct env {
	struct daemon_env d;
	char store[160], set_store[200], token_file[160];
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_prefetch") ||
	    daemon_env_planet_text(&e->d, "test.ini", planet_text, NULL))
		return -1;
	if (!daemon_env_built(&e->d, "clipmapd"))
		return 0;
	snprintf(e->store, sizeof e->store, "%s/tiles.lmdb", e->d.dir);
	snprintf(e->set_store, sizeof e->set_store, "store.path = %s", e->store);
	snprintf(e->token_file, sizeof e->token_file, "%s/token", e->d.dir);
	const char *const set[] = { e->set_store,
				    "store.disk_mb = 1024",
				    "engine.workers = 1",
				    "session.max_rate = 0",
				    "session.max_jobs = 2",
				    "prefetch.max_jobs_total = 3",
				    "log.level = info",
				    NULL };
	char err[256];
	if (daemon_env_start(&e->d, &(struct daemon_env_conf){ .set = set, .token = TOKEN },
			     err)) {
		fprintf(stderr, "test_prefetch_daemon: %s\n", err);
		return -1;
	}
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (!e)
		return 0;
	if (e->d.daemon > 0)
		daemon_env_stop(&e->d, SIGKILL, NULL);
	daemon_env_fini(&e->d);
	free(e);
	return 0;
}

#define NEED_DAEMON(e)                  \
	do {                            \
		if ((e)->d.daemon <= 0) \
			skip();         \
	} while (0)

/* A session on the Unix socket, with the token or without. */
static struct net_conn *conn(struct env *e, bool token)
{
	struct net_conn *c = NULL;
	char err[256];
	/* without: a file with another token would be refused; none at all is what we want */
	unsetenv("CLIPMAP_TOKEN");
	if (net_connect(&(struct net_opts){ .socket_path = e->d.sock, .name = "test_prefetch",
					    .token_file = token ? e->token_file : NULL },
			&c, err))
		fail_msg("%s", err);
	return c;
}

/* Sends m (a PREFETCH or PREFETCH_DRY) and waits for its first answer: ERROR (returned 1,
 * *out filled), PREFETCH_PROGRESS or PREFETCH_ESTIMATE (0). What answers another job of the
 * session (the progress a running job sends every tick) is skipped: on a machine where a
 * tick falls between the request and its answer, that progress is not the answer.
 * *ms: how long the answer took. */
static int ask(struct net_conn *c, const struct proto_msg *m, struct proto_msg *out, double *ms)
{
	char err[256];
	uint32_t id = m->type == PROTO_PREFETCH_DRY ? m->prefetch_dry.id : m->prefetch.id;
	double t0 = clock_now_s();
	if (net_send(c, m, err))
		fail_msg("%s", err);
	for (;;) {
		*out = (struct proto_msg){ 0 };
		if (net_recv(c, out, 10000, err))
			fail_msg("no answer: %s", err);
		if ((out->type == PROTO_ERROR && out->error.ref_type == m->type &&
		     out->error.ref_id == id) ||
		    (out->type == PROTO_PREFETCH_PROGRESS && out->prefetch_progress.id == id) ||
		    (out->type == PROTO_PREFETCH_ESTIMATE && out->prefetch_estimate.id == id))
			break;
		proto_msg_fini(out);
	}
	*ms = (clock_now_s() - t0) * 1000.0;
	return out->type == PROTO_ERROR;
}

/* "about N tiles" in an ERROR's message. */
static uint64_t about(const char *msg)
{
	const char *p = strstr(msg, "about ");
	assert_non_null(p);
	return strtoull(p + 6, NULL, 10);
}

static void status_answers(struct net_conn *c)
{
	char err[256];
	struct proto_msg m = { .type = PROTO_STATS_REQ, .stats_req = { .req = net_next_req(c) } };
	assert_int_equal(net_send(c, &m, err), 0);
	struct proto_msg r = { 0 };
	if (net_expect(c, PROTO_STATS, &r, 2000, NULL, NULL, err))
		fail_msg("STATS: %s", err);
	proto_msg_fini(&r);
}

static void cancel(struct net_conn *c, uint32_t id)
{
	char err[256];
	struct proto_msg m = { .type = PROTO_PREFETCH_CANCEL, .prefetch_cancel = { .req = id } };
	assert_int_equal(net_send(c, &m, err), 0);
	for (;;) {
		struct proto_msg r = { 0 };
		if (net_recv(c, &r, 10000, err))
			fail_msg("cancel %u: %s", id, err);
		bool end = r.type == PROTO_PREFETCH_PROGRESS && r.prefetch_progress.id == id &&
			   r.prefetch_progress.state != PROTO_JOB_RUNNING;
		proto_msg_fini(&r);
		if (end)
			return;
	}
}

static void wide_corridor_refused_at_once(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *c = conn(e, false), *auth = conn(e, true);
	status_answers(c);
	/* the baseline after the start-up prefault ([engine] prefault), which is not growth */
	char err[256];
	if (net_stat_wait_zero(c, "memory.pool.prefault_left", 60000, err))
		fail_msg("%s", err);
	uint64_t rss0 = proc_rss_kb(e->d.daemon);
	assert_true(rss0 > 0);
	struct proto_lonlat pt = { 8.0, 46.0 };
	struct proto_msg m = { .type = PROTO_PREFETCH,
			       .prefetch = { .id = 1, .planet = "test", .shape = PROTO_SHAPE_PATH,
					     .lmin = 22, .lmax = 22, .width_m = 9.55e6,
					     .npoints = 1, .points = &pt } };
	struct net_conn *who[2] = { c, auth };
	for (int k = 0; k < 2; k++) {
		struct proto_msg r;
		double ms;
		assert_int_equal(ask(who[k], &m, &r, &ms), 1);
		printf("wide corridor (%s token): ERROR %u in %.1f ms: %s\n", k ? "with" : "without",
		       r.error.code, ms, r.error.message);
		assert_int_equal(r.error.code, PROTO_E_LIMIT);
		assert_int_equal(r.error.ref_id, 1);
		assert_true(about(r.error.message) > 4000000);
		assert_non_null(strstr(r.error.message, k ? "max_tiles)" : "max_tiles_local"));
		assert_true(ms < 2000);
		proto_msg_fini(&r);
		status_answers(who[k]);
	}
	/* the widest corridor the protocol takes along 4096 points: the estimate's worst case */
	struct proto_lonlat *pts = calloc(PROTO_MAX_PATH, sizeof *pts);
	for (int i = 0; i < PROTO_MAX_PATH; i++)
		pts[i] = (struct proto_lonlat){ (i % 2) ? 170.0 : -170.0, -80.0 + (i % 160) };
	m.prefetch.width_m = PROTO_MAX_WIDTH;
	m.prefetch.npoints = PROTO_MAX_PATH;
	m.prefetch.points = pts;
	m.prefetch.lmin = 0;
	struct proto_msg r;
	double ms;
	assert_int_equal(ask(auth, &m, &r, &ms), 1);
	printf("4096-point corridor %.0f m wide, levels 0-22: ERROR in %.1f ms: %s\n",
	       PROTO_MAX_WIDTH, ms, r.error.message);
	assert_int_equal(r.error.code, PROTO_E_LIMIT);
	assert_true(ms < 2000);
	proto_msg_fini(&r);
	free(pts);
	status_answers(c);
	uint64_t rss1 = proc_rss_kb(e->d.daemon);
	assert_true(rss1 > 0);
	printf("daemon RSS %lu kB before, %lu kB after\n", (unsigned long)rss0,
	       (unsigned long)rss1);
	assert_true(rss1 < rss0 + 16 * 1024);
	net_close(c);
	net_close(auth);
}

static void whole_planet_refused_with_estimate(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *c = conn(e, false), *auth = conn(e, true);
	struct proto_msg m = { .type = PROTO_PREFETCH,
			       .prefetch = { .id = 7, .planet = "test", .shape = PROTO_SHAPE_BBOX,
					     .lmin = 0, .lmax = 11,
					     .bbox = { -180, -90, 180, 90 } } };
	struct proto_msg r;
	double ms;
	assert_int_equal(ask(c, &m, &r, &ms), 1);
	printf("whole planet, levels 0-11, no token: %.1f ms: %s\n", ms, r.error.message);
	assert_int_equal(r.error.code, PROTO_E_LIMIT);
	uint64_t n = about(r.error.message);
	/* 2 layers: the finest level alone holds ≈ 2 × 6.2 M tiles on the lx viewers use */
	assert_true(n > 12000000 && n < 40000000);
	assert_non_null(strstr(r.error.message, "levels 0-11"));
	assert_non_null(strstr(r.error.message, "250000 tiles per job"));
	proto_msg_fini(&r);
	assert_int_equal(ask(auth, &m, &r, &ms), 1);
	printf("the same with the token: %s\n", r.error.message);
	assert_int_equal(r.error.code, PROTO_E_LIMIT);
	assert_non_null(strstr(r.error.message, "4000000 tiles per job"));
	proto_msg_fini(&r);
	net_close(c);
	net_close(auth);
}

/* A job that takes a while (thousands of tiles at one worker), started; its first PROGRESS. */
static void start_job(struct net_conn *c, uint32_t id, double west)
{
	struct proto_msg m = { .type = PROTO_PREFETCH,
			       .prefetch = { .id = id, .planet = "test", .layers = 1,
					     .shape = PROTO_SHAPE_BBOX, .lmin = 10, .lmax = 10,
					     .bbox = { west, 0, west + 10, 10 } } };
	struct proto_msg r;
	double ms;
	if (ask(c, &m, &r, &ms))
		fail_msg("job %u refused: %s", id, r.error.message);
	assert_int_equal(r.prefetch_progress.id, id);
	assert_int_equal(r.prefetch_progress.state, PROTO_JOB_RUNNING);
	assert_true(r.prefetch_progress.total > 1000);
	proto_msg_fini(&r);
}

static void refused(struct net_conn *c, uint32_t id, uint16_t code, const char *what)
{
	struct proto_msg m = { .type = PROTO_PREFETCH,
			       .prefetch = { .id = id, .planet = "test", .layers = 1,
					     .shape = PROTO_SHAPE_BBOX, .lmin = 4, .lmax = 4,
					     .bbox = { 0, 0, 1, 1 } } };
	struct proto_msg r;
	double ms;
	assert_int_equal(ask(c, &m, &r, &ms), 1);
	printf("job %u: %s\n", id, r.error.message);
	assert_int_equal(r.error.code, code);
	assert_non_null(strstr(r.error.message, what));
	proto_msg_fini(&r);
}

static void caps_enforced(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *c = conn(e, false), *a1 = conn(e, true), *a2 = conn(e, true);
	start_job(c, 1, 0);
	refused(c, 2, PROTO_E_LIMIT, "max_jobs_local");
	start_job(a1, 1, 20);
	start_job(a1, 2, 40);
	refused(a1, 3, PROTO_E_LIMIT, "this session's limit is 2");
	/* three jobs run on the server: [prefetch] max_jobs_total = 3 */
	refused(a2, 1, PROTO_E_BUSY, "its limit is 3");
	cancel(a1, 2);
	start_job(a2, 1, 60);
	cancel(c, 1);
	cancel(a1, 1);
	cancel(a2, 1);
	status_answers(c);
	net_close(c);
	net_close(a1);
	net_close(a2);
}

static void dry_run_and_budget(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *c = conn(e, true);
	struct proto_prefetch pf = { .id = 11, .planet = "test", .shape = PROTO_SHAPE_BBOX,
				     .lmin = 6, .lmax = 12, .bbox = { 0, 40, 20, 50 } };
	struct proto_msg m = { .type = PROTO_PREFETCH_DRY, .prefetch_dry = pf };
	struct proto_msg r;
	double ms;
	assert_int_equal(ask(c, &m, &r, &ms), 0);
	const struct proto_prefetch_estimate *est = &r.prefetch_estimate;
	assert_int_equal(r.type, PROTO_PREFETCH_ESTIMATE);
	assert_int_equal(est->id, 11);
	assert_int_equal(est->tier, PROTO_TIER_DISK);
	assert_int_equal(est->budget, 1024u << 20);
	assert_int_equal(est->max_tiles, 4000000);
	assert_int_equal(est->nlevels, 7);
	uint64_t t = 0, b = 0;
	for (int i = 0; i < est->nlevels; i++) {
		printf("  level %u: %lu tiles, %lu bytes\n", est->levels[i].ly,
		       (unsigned long)est->levels[i].tiles, (unsigned long)est->levels[i].bytes);
		assert_int_equal(est->levels[i].ly, 6 + i);
		assert_true(i == 0 || est->levels[i].tiles > est->levels[i - 1].tiles);
		t += est->levels[i].tiles;
		b += est->levels[i].bytes;
	}
	assert_int_equal(t, est->tiles);
	assert_int_equal(b, est->bytes);
	printf("dry run: %lu tiles, %lu bytes; the disk tier's budget %lu\n",
	       (unsigned long)est->tiles, (unsigned long)est->bytes, (unsigned long)est->budget);
	uint64_t tiles = est->tiles;
	assert_true(est->bytes > est->budget); /* 1 GiB holds ~50000 such tiles */
	proto_msg_fini(&r);
	/* run, it is refused with the same estimate instead of evicting itself */
	m = (struct proto_msg){ .type = PROTO_PREFETCH, .prefetch = pf };
	assert_int_equal(ask(c, &m, &r, &ms), 1);
	printf("%s\n", r.error.message);
	assert_int_equal(r.error.code, PROTO_E_LIMIT);
	assert_int_equal(about(r.error.message), tiles);
	assert_non_null(strstr(r.error.message, "disk_mb"));
	proto_msg_fini(&r);
	/* a small one fits and runs to the end: done = total, the total exact */
	pf.lmin = 3;
	pf.lmax = 5;
	m = (struct proto_msg){ .type = PROTO_PREFETCH_DRY, .prefetch_dry = pf };
	assert_int_equal(ask(c, &m, &r, &ms), 0);
	assert_true(r.prefetch_estimate.bytes < r.prefetch_estimate.budget);
	uint64_t guess = r.prefetch_estimate.tiles;
	proto_msg_fini(&r);
	m = (struct proto_msg){ .type = PROTO_PREFETCH, .prefetch = pf };
	assert_int_equal(ask(c, &m, &r, &ms), 0);
	char err[256];
	while (r.prefetch_progress.state == PROTO_JOB_RUNNING) {
		proto_msg_fini(&r);
		if (net_recv(c, &r, 60000, err))
			fail_msg("%s", err);
		if (r.type == PROTO_ERROR)
			fail_msg("%s", r.error.message);
	}
	printf("small job: estimated %lu, done %lu of %lu\n", (unsigned long)guess,
	       (unsigned long)r.prefetch_progress.done, (unsigned long)r.prefetch_progress.total);
	assert_int_equal(r.prefetch_progress.state, PROTO_JOB_DONE);
	assert_int_equal(r.prefetch_progress.done, r.prefetch_progress.total);
	proto_msg_fini(&r);
	net_close(c);
}

static uint64_t stat_of(struct net_conn *c, const char *key)
{
	char err[256];
	uint64_t v = 0;
	if (net_stat_u64(c, key, &v, err))
		fail_msg("%s", err);
	return v;
}

/* A viewer's WANT of both layers of an 8 × 4 block at level (7, 6), every tile received. */
static void view_block(struct net_conn *c, uint32_t seq)
{
	char err[256];
	struct proto_msg op = { 0 };
	if (net_open_planet(c, "test", &op, 5000, err))
		fail_msg("%s", err);
	uint32_t pid = op.opened.planet_id;
	proto_msg_fini(&op);
	struct proto_want_entry w[64];
	uint32_t n = 0;
	for (uint32_t y = 20; y < 24; y++)
		for (uint32_t x = 64; x < 72; x++)
			for (uint8_t l = 0; l < 2; l++)
				w[n++] = (struct proto_want_entry){ .layer = l,
								    .cls = PROTO_CLASS_VISIBLE,
								    .lx = 7, .ly = 6, .x = x, .y = y };
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .count = n, .entries = w } };
	if (net_send(c, &m, err))
		fail_msg("%s", err);
	for (uint32_t got = 0; got < n;) {
		struct proto_msg r = { 0 };
		if (net_recv(c, &r, 30000, err))
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		got += r.type == PROTO_TILE && r.tile.seq == seq;
		proto_msg_fini(&r);
	}
}

/* Runs a prefetch to its end; returns its total. */
static uint64_t run_job(struct net_conn *c, const struct proto_prefetch *pf)
{
	char err[256];
	struct proto_msg m = { .type = PROTO_PREFETCH, .prefetch = *pf }, r;
	double ms;
	if (ask(c, &m, &r, &ms))
		fail_msg("%s", r.error.message);
	while (r.prefetch_progress.state == PROTO_JOB_RUNNING) {
		proto_msg_fini(&r);
		if (net_recv(c, &r, 60000, err))
			fail_msg("%s", err);
		if (r.type == PROTO_ERROR)
			fail_msg("%s", r.error.message);
		if (r.type != PROTO_PREFETCH_PROGRESS)
			r.prefetch_progress.state = PROTO_JOB_RUNNING;
	}
	assert_int_equal(r.prefetch_progress.state, PROTO_JOB_DONE);
	assert_int_equal(r.prefetch_progress.done, r.prefetch_progress.total);
	uint64_t t = r.prefetch_progress.total;
	proto_msg_fini(&r);
	return t;
}

/* Waits (bounded) until no tile is being generated or queued and the writer has committed
 * everything (earlier tests' cancelled jobs may still have had tiles in flight). */
static void wait_written(struct net_conn *c)
{
	uint64_t end = clock_now_ms() + 20000;
	while ((stat_of(c, "store.disk.queued") > 0 || stat_of(c, "sched.workers.busy") > 0 ||
		stat_of(c, "sched.queued.bulk") > 0) &&
	       clock_now_ms() < end)
		usleep(20000);
	assert_int_equal(stat_of(c, "store.disk.queued"), 0);
}

/* Issue 13: prefetched (bulk) tiles are written through to the disk tier and leave the memory
 * cache live viewers use alone — no insert, no eviction — and a viewer's tiles are still
 * served from memory after it; a second run of the same prefetch generates nothing. */
static void bulk_writes_through(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *v = conn(e, false), *op = conn(e, true);
	view_block(v, 1);
	wait_written(op);
	uint64_t ins0 = stat_of(op, "cache.inserts"), ev0 = stat_of(op, "cache.evictions");
	uint64_t puts0 = stat_of(op, "store.disk.puts"), drops0 = stat_of(op, "store.disk.write_drops");
	uint64_t gen0 = stat_of(op, "sched.generated");
	struct proto_prefetch pf = { .id = 21, .planet = "test", .shape = PROTO_SHAPE_BBOX,
				     .lmin = 7, .lmax = 8, .bbox = { 100, -20, 110, -10 } };
	uint64_t total = run_job(op, &pf);
	wait_written(op);
	uint64_t ins1 = stat_of(op, "cache.inserts"), ev1 = stat_of(op, "cache.evictions");
	uint64_t puts1 = stat_of(op, "store.disk.puts"), drops1 = stat_of(op, "store.disk.write_drops");
	uint64_t gen1 = stat_of(op, "sched.generated");
	printf("prefetch of %lu tiles: %lu generated, %lu written to disk, %lu dropped, %lu cache "
	       "inserts, %lu evictions\n",
	       (unsigned long)total, (unsigned long)(gen1 - gen0), (unsigned long)(puts1 - puts0),
	       (unsigned long)(drops1 - drops0), (unsigned long)(ins1 - ins0),
	       (unsigned long)(ev1 - ev0));
	assert_int_equal(gen1 - gen0, total);
	/* the job waits for the writer rather than have its writes dropped */
	assert_int_equal(drops1 - drops0, 0);
	assert_int_equal(puts1 - puts0, total);
	assert_int_equal(ins1 - ins0, 0);
	assert_int_equal(ev1 - ev0, 0);
	/* the viewer's tiles: still in memory */
	uint64_t hits0 = stat_of(op, "cache.hits"), load0 = stat_of(op, "sched.loaded");
	struct net_conn *v2 = conn(e, false);
	view_block(v2, 1);
	assert_int_equal(stat_of(op, "sched.generated"), gen1);
	assert_int_equal(stat_of(op, "sched.loaded"), load0);
	assert_true(stat_of(op, "cache.hits") - hits0 >= 64);
	/* again: nothing generated, nothing put in memory (the tiles are on disk) */
	pf.id = 22;
	assert_int_equal(run_job(op, &pf), total);
	assert_int_equal(stat_of(op, "sched.generated"), gen1);
	assert_int_equal(stat_of(op, "cache.inserts"), ins1);
	net_close(v);
	net_close(v2);
	net_close(op);
}

/* What a clipmapview focused at (lat, lon) asks for at levels 0..lmax (common/clipmap.h):
 * at each level the lx it uses there, its window and the ring around it, both layers; appended
 * to w (distinct entries) from *n. */
static void viewer_wants(double lat, double lon, int lmax, struct proto_want_entry *w,
			 uint32_t *n, uint32_t cap)
{
	for (int ly = 0; ly <= lmax; ly++) {
		int lx = clipmap_level_lx(ly, lat, -1);
		struct grid_quad q;
		grid_window(lx, ly, 64, CLIPMAP_WINDOW_TILES * 64, lon, lat, &q);
		for (int64_t dy = -1; dy <= q.nty; dy++)
			for (int64_t dx = -1; dx <= q.ntx; dx++) {
				int64_t y = (int64_t)q.ty0 + dy;
				if (y < 0 || y >= grid_tiles_y(ly))
					continue;
				uint32_t x = grid_wrap_x(lx, (int64_t)q.tx0 + dx);
				for (uint8_t l = 0; l < 2; l++) {
					bool dup = false;
					for (uint32_t i = 0; i < *n && !dup; i++)
						dup = w[i].layer == l && w[i].lx == lx && w[i].ly == ly &&
						      w[i].x == x && w[i].y == (uint32_t)y;
					if (!dup && *n < cap)
						w[(*n)++] = (struct proto_want_entry){
							.layer = l, .cls = PROTO_CLASS_VISIBLE,
							.lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x,
							.y = (uint32_t)y };
				}
			}
	}
}

/* Issue 13: prefetch a region at 46°N, restart the daemon; a viewer anywhere in it then gets
 * every tile it asks for (window and ring, levels 0-9, on the lx it uses at 46°N) from disk:
 * 0 generated. */
static void restart_then_viewer_generates_nothing(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *op = conn(e, true);
	struct proto_prefetch pf = { .id = 31, .planet = "test", .shape = PROTO_SHAPE_BBOX,
				     .lmin = 0, .lmax = 9, .bbox = { 7, 45.5, 10, 46.8 } };
	uint64_t total = run_job(op, &pf);
	net_close(op);
	char err[256];
	assert_int_equal(daemon_env_stop(&e->d, SIGTERM, NULL), 0); /* commits what is queued */
	if (daemon_env_restart(&e->d, err))
		fail_msg("restart: %s", err);
	static struct proto_want_entry w[4096];
	uint32_t n = 0;
	static const double foci[][2] = { { 46.0, 8.0 }, { 46.5, 9.6 }, { 45.6, 7.1 },
					  { 46.79, 9.99 } };
	for (int i = 0; i < 4; i++)
		viewer_wants(foci[i][0], foci[i][1], 9, w, &n, 4096);
	struct net_conn *v = conn(e, false);
	struct proto_msg opn = { 0 };
	if (net_open_planet(v, "test", &opn, 5000, err))
		fail_msg("%s", err);
	uint32_t pid = opn.opened.planet_id;
	proto_msg_fini(&opn);
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 5, .count = n, .entries = w } };
	assert_int_equal(net_send(v, &m, err), 0);
	for (uint32_t got = 0; got < n;) {
		struct proto_msg r = { 0 };
		if (net_recv(v, &r, 30000, err))
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		got += r.type == PROTO_TILE && r.tile.seq == 5;
		proto_msg_fini(&r);
	}
	uint64_t gen = stat_of(v, "sched.generated"), loaded = stat_of(v, "sched.loaded");
	printf("prefetched %lu tiles at 46°N; after a restart a viewer's %u tiles: %lu generated, "
	       "%lu loaded from disk\n",
	       (unsigned long)total, n, (unsigned long)gen, (unsigned long)loaded);
	assert_int_equal(gen, 0);
	assert_int_equal(loaded, n);
	assert_int_equal(stat_of(v, "store.disk.corrupt"), 0);
	net_close(v);
}

/* Runs clipmapctl -s SOCKET with the arguments; returns its exit status, output in out. */
static int ctl_va(const struct daemon_env *d, char *out, size_t n, const char *a0, va_list ap)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapctl", d->bindir);
	char *argv[32] = { exe, "-s", (char *)d->sock };
	int argc = 3;
	for (const char *a = a0; a && argc < 31; a = va_arg(ap, const char *))
		argv[argc++] = (char *)a;
	argv[argc] = NULL;
	return daemon_env_run(argv, out, n);
}

static int ctl(struct env *e, char *out, size_t n, const char *a0, ...)
{
	va_list ap;
	va_start(ap, a0);
	int rc = ctl_va(&e->d, out, n, a0, ap);
	va_end(ap);
	return rc;
}

/* clipmapctl against another daemon. */
static int ctl_at(const struct daemon_env *d, char *out, size_t n, const char *a0, ...)
{
	va_list ap;
	va_start(ap, a0);
	int rc = ctl_va(d, out, n, a0, ap);
	va_end(ap);
	return rc;
}

/* Sum of "key": N after every occurrence of `after` in a JSON text. */
static uint64_t sum_after(const char *text, const char *after, const char *key)
{
	uint64_t t = 0;
	for (const char *p = strstr(text, after); p; p = strstr(p + 1, after)) {
		const char *k = strstr(p, key);
		if (k)
			t += strtoull(k + strlen(key), NULL, 10);
	}
	return t;
}

static uint64_t json_u(const char *text, const char *key)
{
	const char *k = strstr(text, key);
	if (!k)
		fail_msg("no %s in %s", key, text);
	return strtoull(k + strlen(key), NULL, 10);
}

/* Flips bytes in the middle of the first stored value, with the daemon stopped. */
static void damage_first(struct env *e)
{
	MDB_env *env;
	MDB_txn *txn;
	MDB_dbi dbi;
	MDB_cursor *cur;
	assert_int_equal(mdb_env_create(&env), 0);
	assert_int_equal(mdb_env_set_maxdbs(env, 4), 0);
	assert_int_equal(mdb_env_open(env, e->store, MDB_NOSUBDIR, 0644), 0);
	assert_int_equal(mdb_txn_begin(env, NULL, 0, &txn), 0);
	assert_int_equal(mdb_dbi_open(txn, "tiles", 0, &dbi), 0);
	assert_int_equal(mdb_cursor_open(txn, dbi, &cur), 0);
	MDB_val k, v;
	assert_int_equal(mdb_cursor_get(cur, &k, &v, MDB_FIRST), 0);
	MDB_val nv = { v.mv_size, malloc(v.mv_size) };
	memcpy(nv.mv_data, v.mv_data, v.mv_size);
	((uint8_t *)nv.mv_data)[nv.mv_size / 2] ^= 0xa5;
	mdb_cursor_close(cur);
	assert_int_equal(mdb_put(txn, dbi, &k, &nv, 0), 0);
	assert_int_equal(mdb_txn_commit(txn), 0);
	mdb_env_close(env);
	free(nv.mv_data);
}

/* Issue 13: cache stat / purge / gc / verify through clipmapctl on a real store. */
static void cache_maintenance(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	if (!daemon_env_built(&e->d, "clipmapctl"))
		skip();
	static char out[1 << 20];
	struct net_conn *s = conn(e, false);
	wait_written(s);
	uint64_t disk = stat_of(s, "store.disk.tiles");
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "test", "--json", NULL), 0);
	assert_int_equal(sum_after(out, "\"tier\": \"disk\"", "\"tiles\": "), disk);
	assert_non_null(strstr(out, "\"layer\": \"height\", \"level\": 9, \"tier\": \"disk\""));
	assert_int_equal(json_u(strstr(out, "\"disk\": {"), "\"tiles\": "), disk);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "test", NULL), 0);
	printf("%.600s...\n", out);
	assert_non_null(strstr(out, "planet"));
	assert_non_null(strstr(out, " disk "));
	/* cache ls lists the disk tier (age unknown there) */
	assert_int_equal(ctl(e, out, sizeof out, "cache", "ls", "test", "--level", "9", "--limit",
			     "100000", "--json", NULL), 0);
	assert_non_null(strstr(out, "\"tier\": \"disk\", \"bytes\": "));
	assert_non_null(strstr(out, "\"age_s\": null"));
	uint64_t ls9 = 0;
	for (const char *p = strstr(out, "\"tier\": \"disk\""); p;
	     p = strstr(p + 1, "\"tier\": \"disk\""))
		ls9++;
	assert_int_equal(ctl(e, out, sizeof out, "cache", "ls", "test", "--level", "9", NULL), 0);
	assert_non_null(strstr(out, " disk"));
	/* purge level 9: gone from disk, the rest stays */
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", "test", "--levels", "9-9",
			     "--json", NULL), 0);
	uint64_t r9 = json_u(out, "\"removed\": ");
	printf("purge --levels 9-9: %s", out);
	assert_int_equal(r9, ls9);
	assert_int_equal(stat_of(s, "store.disk.tiles"), disk - r9);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "test", "--json", NULL), 0);
	assert_null(strstr(out, "\"level\": 9, \"tier\": \"disk\""));
	assert_non_null(strstr(out, "\"level\": 8, \"tier\": \"disk\""));
	assert_int_equal(ctl(e, out, sizeof out, "cache", "ls", "test", "--level", "9", "--json",
			     NULL), 0);
	assert_null(strstr(out, "\"tier\": \"disk\""));
	/* purge a bbox at level 8: the 46°N tiles go, those at 100°E (bulk_writes_through) stay */
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", "test", "--bbox",
			     "7,45.5,10,46.8", "--levels", "8-8", "--json", NULL), 0);
	uint64_t r8 = json_u(out, "\"removed\": ");
	assert_true(r8 > 0);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "test", "--json", NULL), 0);
	assert_non_null(strstr(out, "\"level\": 8, \"tier\": \"disk\""));
	disk -= r9 + r8;
	assert_int_equal(stat_of(s, "store.disk.tiles"), disk);
	net_close(s);
	/* verify: one value damaged with the daemon stopped is found and removed */
	char err[256];
	assert_int_equal(daemon_env_stop(&e->d, SIGTERM, NULL), 0);
	damage_first(e);
	if (daemon_env_restart(&e->d, err))
		fail_msg("restart: %s", err);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "verify", "--json", NULL), 0);
	printf("verify: %s", out);
	assert_int_equal(json_u(out, "\"checked\": "), disk);
	assert_int_equal(json_u(out, "\"corrupt\": "), 1);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "verify", NULL), 0);
	assert_non_null(strstr(out, " 0 damaged"));
	s = conn(e, false);
	assert_int_equal(stat_of(s, "store.disk.tiles"), disk - 1);
	disk--;
	/* gc: after the planet changes (another seed: every node hash changes), its old tiles are
	 * no planet's any more and gc drops them all */
	char text[sizeof planet_text + 16];
	snprintf(text, sizeof text, "%s", planet_text);
	char *seed = strstr(text, "seed = 5");
	assert_non_null(seed);
	seed[7] = '6';
	assert_int_equal(daemon_env_planet_text(&e->d, "test.ini", text, NULL), 0);
	assert_int_equal(daemon_env_signal(&e->d, SIGHUP), 0);
	uint64_t end = clock_now_ms() + 10000;
	do {
		usleep(50000);
		assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "--json", NULL), 0);
	} while (!strstr(out, "\"planet\": \"\"") && clock_now_ms() < end);
	assert_int_equal(sum_after(out, "\"planet\": \"\"", "\"tiles\": "), disk);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "gc", "--json", NULL), 0);
	printf("gc: %s", out);
	assert_int_equal(json_u(out, "\"removed\": "), disk);
	assert_int_equal(stat_of(s, "store.disk.tiles"), 0);
	/* usage errors */
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", NULL), 2);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "gc", "test", NULL), 2);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "--levels", "1-2", NULL), 2);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "stat", "nosuch", NULL), 2);
	assert_non_null(strstr(out, "no planet \"nosuch\""));
	net_close(s);
}

/* Issue 13: the store file damaged under a running daemon (B-tree pages overwritten, the meta
 * pages intact): the first read that meets it has the file moved aside and recreated, the
 * daemon keeps serving every tile (generated again) and writes to the new file. */
static void damaged_file_replaced_at_run_time(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	struct net_conn *op = conn(e, true);
	struct proto_prefetch pf = { .id = 41, .planet = "test", .shape = PROTO_SHAPE_BBOX,
				     .lmin = 5, .lmax = 6, .bbox = { 60, 10, 80, 30 } };
	uint64_t total = run_job(op, &pf);
	wait_written(op);
	assert_true(stat_of(op, "store.disk.tiles") >= total);
	assert_int_equal(stat_of(op, "store.disk.recovered"), 0);
	/* zeros over every page but the two meta pages (as a lost write-back would leave) */
	FILE *f = fopen(e->store, "r+b");
	assert_non_null(f);
	assert_int_equal(fseek(f, 0, SEEK_END), 0);
	long size = ftell(f);
	static uint8_t junk[4096];
	memset(junk, 0, sizeof junk); /* a page of zeros: neither branch nor leaf */
	for (long off = 2 * 4096; off + 4096 <= size; off += 4096) {
		assert_int_equal(fseek(f, off, SEEK_SET), 0);
		assert_int_equal(fwrite(junk, 1, sizeof junk, f), sizeof junk);
	}
	assert_int_equal(fclose(f), 0);
	/* a viewer over the prefetched region (its tiles are on disk only) */
	struct net_conn *v = conn(e, false);
	char err[256];
	struct proto_msg opn = { 0 };
	if (net_open_planet(v, "test", &opn, 5000, err))
		fail_msg("%s", err);
	uint32_t pid = opn.opened.planet_id;
	proto_msg_fini(&opn);
	static struct proto_want_entry w[4096];
	uint32_t n = 0;
	viewer_wants(20, 70, 6, w, &n, 4096);
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 9, .count = n, .entries = w } };
	assert_int_equal(net_send(v, &m, err), 0);
	for (uint32_t got = 0; got < n;) {
		struct proto_msg r = { 0 };
		if (net_recv(v, &r, 30000, err))
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		got += r.type == PROTO_TILE && r.tile.seq == 9;
		proto_msg_fini(&r);
	}
	uint64_t end = clock_now_ms() + 10000;
	while (stat_of(op, "store.disk.recovered") == 0 && clock_now_ms() < end)
		usleep(20000);
	printf("after the damage: %u tiles served, store recovered %lu time(s), %lu tiles on "
	       "disk\n",
	       n, (unsigned long)stat_of(op, "store.disk.recovered"),
	       (unsigned long)stat_of(op, "store.disk.tiles"));
	assert_int_equal(stat_of(op, "store.disk.recovered"), 1);
	char aside[200];
	snprintf(aside, sizeof aside, "%s.corrupt-", e->store);
	bool found = false;
	DIR *d = opendir(e->d.dir);
	assert_non_null(d);
	for (struct dirent *de; (de = readdir(d));) {
		char full[600];
		snprintf(full, sizeof full, "%s/%s", e->d.dir, de->d_name);
		found |= strncmp(full, aside, strlen(aside)) == 0;
	}
	closedir(d);
	assert_true(found);
	/* the operator is told, once (the tick after the counter moved) */
	assert_true(daemon_env_log_wait(&e->d, "was damaged (LMDB could not read it)", 1, 5000));
	/* it goes on: the tiles generated again are written to the new file */
	wait_written(op);
	struct net_conn *v2 = conn(e, false);
	view_block(v2, 3);
	wait_written(op);
	assert_true(stat_of(op, "store.disk.tiles") > 0);
	net_close(v2);
	net_close(v);
	net_close(op);
}

/* Writes text to the file name in the test's directory; its path in out. */
static void write_in_dir(struct env *e, const char *name, const char *text, char *out, size_t n)
{
	snprintf(out, n, "%s/%s", e->d.dir, name);
	FILE *f = fopen(out, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
}

/* Issue 13: prefetch --coverage and cache purge --coverage through the thin clipmapctl (which
 * hands them to clipmapctl-offline, GDAL): a rectangle's dry run and job are its bbox's, the
 * job runs to the end, purging the coverage removes its stored tiles (a bbox purge of the same
 * place then finds none), and bad files are errors naming them (exit 2, as bad input). */
static void coverage_prefetch_and_purge(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	if (!daemon_env_built(&e->d, "clipmapctl") || !daemon_env_built(&e->d, "clipmapctl-offline"))
		skip();
	static char out[1 << 16], out2[1 << 16];
	char rect[256], line[256], missing[256];
	write_in_dir(e, "rect.geojson",
		     "{\"type\":\"Polygon\",\"coordinates\":[[[-30,10.5],[-29,10.5],[-29,11.5],"
		     "[-30,11.5],[-30,10.5]]]}", rect, sizeof rect);
	write_in_dir(e, "line.geojson",
		     "{\"type\":\"LineString\",\"coordinates\":[[0,0],[1,1]]}", line,
		     sizeof line);
	snprintf(missing, sizeof missing, "%s/none.gpkg", e->d.dir);
	assert_int_equal(ctl(e, out, sizeof out, "prefetch", "test", "--coverage", rect,
			     "--levels", "3-8", "--dry-run", "--json", NULL), 0);
	assert_int_equal(ctl(e, out2, sizeof out2, "prefetch", "test", "--bbox", "-30,10.5,-29,11.5",
			     "--levels", "3-8", "--dry-run", "--json", NULL), 0);
	printf("coverage dry run: %s", out);
	uint64_t tiles = json_u(out, "\"tiles\": ");
	assert_true(tiles > 0);
	assert_int_equal(tiles, json_u(out2, "\"tiles\": "));
	assert_int_equal(ctl(e, out, sizeof out, "prefetch", "test", "--coverage", rect,
			     "--levels", "3-8", NULL), 0);
	printf("coverage job: %s", out);
	char want[96];
	snprintf(want, sizeof want, "%llu of %llu tiles", (unsigned long long)tiles,
		 (unsigned long long)tiles);
	assert_non_null(strstr(out, want));
	struct net_conn *s = conn(e, false);
	wait_written(s);
	net_close(s);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", "test", "--coverage", rect,
			     "--levels", "8-8", "--json", NULL), 0);
	printf("purge --coverage: %s", out);
	assert_true(json_u(out, "\"removed\": ") > 0);
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", "test", "--bbox",
			     "-29.9,10.6,-29.1,11.4", "--levels", "8-8", "--json", NULL), 0);
	assert_int_equal(json_u(out, "\"removed\": "), 0);
	/* bad files and usage */
	assert_int_equal(ctl(e, out, sizeof out, "prefetch", "test", "--coverage", missing,
			     "--levels", "1-2", NULL), 2);
	printf("missing: %s", out);
	assert_non_null(strstr(out, missing));
	assert_int_equal(ctl(e, out, sizeof out, "cache", "purge", "test", "--coverage", line,
			     NULL), 2);
	printf("line: %s", out);
	assert_non_null(strstr(out, line));
	assert_non_null(strstr(out, "no polygon"));
	assert_int_equal(ctl(e, out, sizeof out, "prefetch", "test", "--coverage", rect, "--bbox",
			     "1,1,2,2", "--levels", "1-2", NULL), 2);
}

/* Issue 13: jobs that each fit the disk tier's budget but not together. The last still
 * succeeds (exit 0), and the operator is told: clipmapctl prints how many prefetched tiles
 * the store evicted while it ran, the daemon logs it, status counts it; the first job, alone,
 * warns of nothing. A daemon of its own with a 10 MiB store. */
struct full_env {
	struct env *e; /* the group's */
	struct daemon_env d;
};

/* Its daemon, stopped by the teardown whatever the test's assertions did. */
static int setup_full(void **state)
{
	struct full_env *f = calloc(1, sizeof *f);
	if (!f)
		return -1;
	f->e = *state;
	*state = f;
	char store[200], err[256];
	if (daemon_env_init(&f->d, "test_pf_full") ||
	    daemon_env_planet_text(&f->d, "test.ini", planet_text, NULL))
		return -1;
	if (f->e->d.daemon <= 0 || !daemon_env_built(&f->d, "clipmapctl"))
		return 0; /* the test skips */
	snprintf(store, sizeof store, "store.path = %s/tiles.lmdb", f->d.dir);
	const char *const set[] = { store, "store.disk_mb = " PF_FULL_MB, "engine.workers = 1",
				    "session.max_rate = 0", "log.level = info", NULL };
	if (daemon_env_start(&f->d, &(struct daemon_env_conf){ .set = set }, err)) {
		fprintf(stderr, "test_prefetch_daemon: %s\n", err);
		return -1;
	}
	return 0;
}

static int teardown_full(void **state)
{
	struct full_env *f = *state;
	if (f->d.daemon > 0)
		daemon_env_stop(&f->d, SIGKILL, NULL);
	daemon_env_fini(&f->d);
	*state = f->e;
	free(f);
	return 0;
}

static void overflowing_prefetches_say_so(void **state)
{
	struct full_env *f = *state;
	const struct daemon_env *d = &f->d;
	if (d->daemon <= 0)
		skip();
	char err[256];
	static char out[1 << 16];
	int rc = ctl_at(d, out, sizeof out, "prefetch", "test", "--bbox", PF_FULL_A, "--levels",
			PF_FULL_A_LEVELS, NULL);
	printf("first job: %s", out);
	assert_int_equal(rc, 0);
	assert_null(strstr(out, "warning"));
	struct net_conn *c = NULL;
	if (net_connect(&(struct net_opts){ .socket_path = d->sock, .name = "test_prefetch" }, &c,
			err))
		fail_msg("%s", err);
	wait_written(c);
	uint64_t first = stat_of(c, "store.disk.tiles");
	assert_int_equal(stat_of(c, "store.disk.evictions_prefetched"), 0);
	rc = ctl_at(d, out, sizeof out, "prefetch", "test", "--bbox", PF_FULL_B, "--levels",
		    PF_FULL_BC_LEVELS, NULL);
	printf("second job: %s", out);
	assert_int_equal(rc, 0);
	wait_written(c);
	rc = ctl_at(d, out, sizeof out, "prefetch", "test", "--bbox", PF_FULL_C, "--levels",
		    PF_FULL_BC_LEVELS, NULL);
	printf("third job: %s", out);
	assert_int_equal(rc, 0);
	wait_written(c);
	uint64_t ev = stat_of(c, "store.disk.evictions_prefetched");
	printf("the store held %llu tiles after the first job; the others evicted %llu; "
	       "%llu bytes held of a %llu budget\n", (unsigned long long)first,
	       (unsigned long long)ev, (unsigned long long)stat_of(c, "store.disk.bytes"),
	       (unsigned long long)stat_of(c, "store.disk.budget"));
	assert_true(ev > 0);
	assert_true(stat_of(c, "store.disk.bytes") <= stat_of(c, "store.disk.budget"));
	assert_non_null(strstr(out, "warning: the disk tier evicted"));
	assert_non_null(strstr(out, "prefetched tiles while this job ran"));
	assert_true(daemon_env_log_wait(d, "evicting prefetched tiles", 1, 3000));
	net_close(c);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(wide_corridor_refused_at_once),
		cmocka_unit_test(whole_planet_refused_with_estimate),
		cmocka_unit_test(dry_run_and_budget),
		cmocka_unit_test(bulk_writes_through),
		cmocka_unit_test(caps_enforced), /* late: its cancelled jobs' tiles may still run */
		cmocka_unit_test(restart_then_viewer_generates_nothing),
		cmocka_unit_test(cache_maintenance),
		cmocka_unit_test(coverage_prefetch_and_purge),
		cmocka_unit_test_setup_teardown(overflowing_prefetches_say_so, setup_full,
						teardown_full),
		cmocka_unit_test(damaged_file_replaced_at_run_time),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
