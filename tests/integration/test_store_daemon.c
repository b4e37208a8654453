/* test_store_daemon — the persistent tile store through a real clipmapd (tests/support/daemon_env)
 * with [store] path on a real LMDB file in the test's temporary directory, and a client over
 * client/net.h. What an operator would notice:
 *   - tiles generated before a restart are served from disk after it (0 generated);
 *   - a value damaged inside the file is detected, counted, logged, regenerated — and the
 *     tile served is the right one (compared with in-process generation, byte for byte);
 *   - kill -9 during heavy writes, five times: every restart opens the store and serves no
 *     damaged tile;
 *   - writes that fail (the file may not grow, as on a full disk) leave it serving, logged
 *     once, and it recovers when the file may grow again;
 *   - a small disk_mb holds: the bytes at rest stay under it while tiles are evicted.
 * Skipped when build/clipmapd was not built. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <lmdb.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/store.h"
#include "support/daemon_env.h"
#include "support/slow.h"
#include "support/net_stat.h"

static const char planet_text[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 12\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 4\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

#define MAXW 2048

struct env {
	struct daemon_env d;
	char planet[128];
	char store[160];
	char set_store[200];
	char set_disk[64];
	struct planet *p; /* in-process reference */
	struct cache *cache;
	struct sched *sched;
};

static int setup_mb(void **state, int disk_mb)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_store") ||
	    daemon_env_planet_text(&e->d, "test.ini", planet_text, e->planet))
		return -1;
	if (!daemon_env_built(&e->d, "clipmapd"))
		return 0;
	snprintf(e->store, sizeof e->store, "%s/tiles.lmdb", e->d.dir);
	snprintf(e->set_store, sizeof e->set_store, "store.path = %s", e->store);
	snprintf(e->set_disk, sizeof e->set_disk, "store.disk_mb = %d", disk_mb);
	const char *const set[] = { e->set_store, e->set_disk, "engine.workers = 2",
				    "session.max_rate = 0", "log.level = info", NULL };
	char err[256];
	if (daemon_env_start(&e->d, &(struct daemon_env_conf){ .set = set }, err)) {
		fprintf(stderr, "test_store: %s\n", err);
		return -1;
	}
	char perr[256];
	if (planet_load(e->planet, &e->p, perr)) {
		fprintf(stderr, "test_store: %s\n", perr);
		return -1;
	}
	e->cache = cache_create(0);
	e->sched = sched_create(&(struct sched_desc){ .cache = e->cache, .workers = 1 });
	return 0;
}

static int setup(void **state)
{
	return setup_mb(state, 64);
}

static int setup_small(void **state)
{
	return setup_mb(state, 1);
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (!e)
		return 0;
	if (e->d.daemon > 0)
		daemon_env_stop(&e->d, SIGKILL, NULL);
	daemon_env_fini(&e->d);
	sched_destroy(e->sched);
	cache_destroy(e->cache);
	planet_unref(e->p);
	free(e);
	return 0;
}

#define NEED_DAEMON(e)                  \
	do {                            \
		if ((e)->d.daemon <= 0) \
			skip();         \
	} while (0)

static struct net_conn *conn(struct env *e, uint32_t *pid)
{
	struct net_conn *c = NULL;
	char err[256];
	if (net_connect(&(struct net_opts){ .socket_path = e->d.sock, .name = "test_store" }, &c,
			err))
		fail_msg("%s", err);
	struct proto_msg m = { 0 };
	if (net_open_planet(c, "test", &m, 5000, err))
		fail_msg("%s", err);
	*pid = m.opened.planet_id;
	assert_int_equal(m.opened.planet.nlayers, 2);
	assert_int_equal(m.opened.planet.layers[0].node, e->p->layers[0].node->hash);
	assert_int_equal(m.opened.planet.layers[1].node, e->p->layers[1].node->hash);
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

/* The tile in-process, for comparison (owned). */
static struct tile *reference(struct env *e, int layer, const struct tile_key *k)
{
	struct node *nd = e->p->layers[layer].node;
	struct want w = { .node = nd, .key = *k, .cls = SCHED_VISIBLE };
	w.key.node = nd->hash;
	struct tile *t = NULL;
	assert_int_equal(sched_fetch(e->sched, &w, 1, &t), 0);
	return t;
}

/* Sends the WANT and receives every tile (at most `stop_after` when non-zero), checking each
 * against in-process generation when `check`. Returns how many arrived. */
static uint32_t fetch(struct env *e, struct net_conn *c, uint32_t pid, uint32_t seq,
		      const struct proto_want_entry *w, uint32_t n, uint32_t stop_after, bool check)
{
	char err[256];
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .count = n, .entries = w } };
	if (net_send(c, &m, err))
		fail_msg("%s", err);
	uint32_t got = 0;
	size_t cap = 64 * 64 * 4;
	uint8_t *px = malloc(cap);
	while (got < n && (!stop_after || got < stop_after)) {
		struct proto_msg r = { 0 };
		int rc = net_recv(c, &r, 20000, err);
		if (rc)
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		if (r.type == PROTO_TILE && r.tile.seq == seq) {
			const struct proto_tile *t = &r.tile;
			if (net_tile_decode(c, t, px, cap, err))
				fail_msg("%s", err);
			if (check) {
				struct tile *ref = reference(e, t->layer, &t->key);
				assert_int_equal(ref->nbytes, t->enc.raw_len);
				if (memcmp(ref->data, px, ref->nbytes) != 0)
					fail_msg("tile layer %u (%u,%u) %u,%u differs from in-process "
						 "generation", t->layer, t->key.lx, t->key.ly, t->key.x,
						 t->key.y);
				tile_unref(ref);
			}
			got++;
		}
		proto_msg_fini(&r);
	}
	free(px);
	return got;
}

/* Waits (bounded) until the writer has committed everything queued (write-behind). */
static void wait_written(struct net_conn *c)
{
	char err[256];
	if (net_stat_wait_zero(c, "store.disk.queued", 10000, err))
		fail_msg("%s", err);
}

static void restart(struct env *e, int sig)
{
	char err[256];
	if (e->d.daemon > 0)
		assert_int_equal(daemon_env_stop(&e->d, sig, NULL), 0);
	if (daemon_env_restart(&e->d, err)) /* on the same config */
		fail_msg("restart: %s", err);
}

/* Tiles generated before a restart come from disk after it: nothing is generated again. */
static void survives_restart(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static struct proto_want_entry w[MAXW];
	uint32_t n = 0;
	n = block(w, n, 0, 0, 0, 2, 1);
	n = block(w, n, 2, 2, 0, 4, 2);
	n = block(w, n, 4, 10, 4, 6, 4);
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, true), n);
	uint64_t gen1 = stat_of(c, "sched.generated");
	assert_true(gen1 >= n);
	net_close(c);

	restart(e, SIGTERM); /* a clean stop commits the writes still queued */
	c = conn(e, &pid);
	assert_int_equal(stat_of(c, "store.disk.tiles"), gen1);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "sched.generated"), 0);
	assert_int_equal(stat_of(c, "sched.loaded"), n);
	assert_int_equal(stat_of(c, "store.disk.hits"), n);
	assert_int_equal(stat_of(c, "store.disk.corrupt"), 0);
	net_close(c);
}

static void flip(MDB_val *v)
{
	uint8_t *p = v->mv_data;
	p[v->mv_size / 2] ^= 0xa5;
	p[v->mv_size - 3] ^= 0x10;
}

/* Overwrites the stored value of k with damaged bytes, with the daemon stopped. */
static void damage(struct env *e, const struct tile_key *k)
{
	MDB_env *env;
	MDB_txn *txn;
	MDB_dbi dbi;
	assert_int_equal(mdb_env_create(&env), 0);
	assert_int_equal(mdb_env_set_maxdbs(env, 4), 0);
	assert_int_equal(mdb_env_open(env, e->store, MDB_NOSUBDIR, 0644), 0);
	assert_int_equal(mdb_txn_begin(env, NULL, 0, &txn), 0);
	assert_int_equal(mdb_dbi_open(txn, "tiles", 0, &dbi), 0);
	uint8_t kb[STORE_KEY_LEN];
	store_key_encode(k, kb);
	MDB_val mk = { sizeof kb, kb }, v;
	assert_int_equal(mdb_get(txn, dbi, &mk, &v), 0);
	MDB_val nv = { v.mv_size, malloc(v.mv_size) };
	memcpy(nv.mv_data, v.mv_data, v.mv_size);
	flip(&nv);
	assert_int_equal(mdb_put(txn, dbi, &mk, &nv, 0), 0);
	assert_int_equal(mdb_txn_commit(txn), 0);
	mdb_env_close(env);
	free(nv.mv_data);
}

/* A damaged value is detected, counted, logged and regenerated: the right tile is served. */
static void corrupt_entry_regenerated(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static struct proto_want_entry w[MAXW];
	uint32_t n = block(w, 0, 3, 4, 2, 4, 2);
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, false), n);
	net_close(c);
	assert_int_equal(daemon_env_stop(&e->d, SIGTERM, NULL), 0);

	/* Two values damaged: a height tile and a colour tile of the set. */
	struct tile_key kh = { .node = e->p->layers[0].node->hash, .lx = 4, .ly = 3, .x = 5, .y = 3 };
	struct tile_key kc = { .node = e->p->layers[1].node->hash, .lx = 4, .ly = 3, .x = 6, .y = 2 };
	damage(e, &kh);
	damage(e, &kc);

	restart(e, 0);
	c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "store.disk.corrupt"), 2);
	assert_true(stat_of(c, "sched.generated") >= 2);
	assert_int_equal(stat_of(c, "sched.loaded"), n - 2);
	net_close(c);
	assert_true(daemon_env_log_wait(&e->d, "corrupt tiles dropped", 1, 3000));

	/* The regenerated tiles were written again: after another restart all come from disk. */
	restart(e, SIGTERM);
	c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 2, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "store.disk.corrupt"), 0);
	assert_int_equal(stat_of(c, "sched.generated"), 0);
	net_close(c);
}

/* kill -9 while the writer is busy, five times (STORE_KILL_LOOPS=100 for the long run): each
 * restart opens the store and every tile served is exactly what generation gives. */
static void kill9_during_writes(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static struct proto_want_entry w[MAXW];
	uint64_t prev_tiles = 0;
	int loops = getenv("STORE_KILL_LOOPS") ? atoi(getenv("STORE_KILL_LOOPS")) : 5;
	if (loops < 1)
		loops = 1;
	for (int it = 0; it < loops; it++) {
		/* 128 tiles, new ones for the first eight rounds */
		uint32_t n = block(w, 0, 5, (uint32_t)(it % 8) * 8, 8, 8, 8);
		n = block(w, n, 4, 0, 0, 16, 8);		       /* 256 tiles, the same each time */
		uint32_t pid;
		struct net_conn *c = conn(e, &pid);
		/* Served after the previous kill: from disk or generated, never damaged. */
		assert_int_equal(fetch(e, c, pid, 1, w + 128, n - 128, 0, true), n - 128);
		assert_int_equal(stat_of(c, "store.disk.corrupt"), 0);
		uint64_t tiles = stat_of(c, "store.disk.tiles");
		assert_true(tiles >= prev_tiles); /* committed batches survived the kill */
		/* Heavy writes: new tiles, killed partway. */
		uint32_t got = fetch(e, c, pid, 2, w, 128, 40 + (uint32_t)(it % 5) * 17, false);
		assert_true(got > 0);
		prev_tiles = stat_of(c, "store.disk.tiles");
		print_message("kill -9 #%d: %u tiles received, %llu stored, %llu writes queued\n", it + 1,
			      got, (unsigned long long)prev_tiles,
			      (unsigned long long)stat_of(c, "store.disk.queued"));
		net_close(c);
		restart(e, SIGKILL);
	}
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	uint32_t n = 0;
	for (int it = 0; it < loops && it < 8; it++)
		n = block(w, n, 5, (uint32_t)it * 8, 8, 8, 8);
	assert_int_equal(fetch(e, c, pid, 3, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "store.disk.corrupt"), 0);
	/* Once the writer has committed them (nothing queued), a kill -9 loses none. */
	wait_written(c);
	net_close(c);
	restart(e, SIGKILL);
	c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 4, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "sched.generated"), 0);
	assert_int_equal(stat_of(c, "sched.loaded"), n);
	net_close(c);
}

/* Writes that fail (the file may not grow: a file size limit set on the running daemon, as a
 * full disk would) leave the daemon serving from memory and generation, logged once; when the
 * file may grow again writes succeed again (logged) and what they wrote survives a restart. */
static void write_failure_recovers(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static struct proto_want_entry w[MAXW];
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	uint32_t n = block(w, 0, 4, 0, 0, 8, 4);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, false), n);
	wait_written(c);
	uint64_t puts0 = stat_of(c, "store.disk.puts");

	struct stat st;
	assert_int_equal(stat(e->store, &st), 0);
	struct rlimit lim = { .rlim_cur = (rlim_t)st.st_size, .rlim_max = RLIM_INFINITY };
	assert_int_equal(prlimit(e->d.daemon, RLIMIT_FSIZE, &lim, NULL), 0);
	n = block(w, 0, 6, 0, 16, 16, 8); /* 256 new tiles: the file must grow */
	assert_int_equal(fetch(e, c, pid, 2, w, n, 0, true), n);
	wait_written(c);
	uint64_t werr = stat_of(c, "store.disk.write_errors");
	print_message("file limited to %lld bytes: %llu write batches failed\n", (long long)st.st_size,
		      (unsigned long long)werr);
	assert_true(werr > 0);
	assert_true(daemon_env_log_wait(&e->d, "writes fail", 1, (int)test_slow(5000)));

	lim.rlim_cur = RLIM_INFINITY;
	assert_int_equal(prlimit(e->d.daemon, RLIMIT_FSIZE, &lim, NULL), 0);
	n = block(w, 0, 6, 20, 16, 8, 4); /* 64 new tiles */
	assert_int_equal(fetch(e, c, pid, 3, w, n, 0, false), n);
	wait_written(c);
	assert_true(stat_of(c, "store.disk.puts") >= puts0 + n);
	assert_true(daemon_env_log_wait(&e->d, "writes succeed again", 1, (int)test_slow(5000)));
	assert_int_equal(daemon_env_log_count(&e->d, "writes fail"), 1);
	net_close(c);

	restart(e, SIGTERM);
	c = conn(e, &pid);
	assert_int_equal(fetch(e, c, pid, 1, w, n, 0, true), n);
	assert_int_equal(stat_of(c, "sched.generated"), 0);
	assert_int_equal(stat_of(c, "store.disk.corrupt"), 0);
	net_close(c);
}

/* disk_mb = 1 with many more tiles than fit: the bytes at rest stay under it. */
static void disk_budget_respected(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static struct proto_want_entry w[MAXW];
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	for (int round = 0; round < 3; round++) {
		uint32_t n = block(w, 0, 6, (uint32_t)round * 24, 20, 24, 12); /* 576 tiles */
		assert_int_equal(fetch(e, c, pid, (uint32_t)round + 1, w, n, 0, false), n);
	}
	wait_written(c);
	uint64_t bytes = stat_of(c, "store.disk.bytes"), budget = stat_of(c, "store.disk.budget");
	uint64_t tiles = stat_of(c, "store.disk.tiles"), ev = stat_of(c, "store.disk.evictions");
	uint64_t puts = stat_of(c, "store.disk.puts");
	print_message("disk_mb = 1: %llu tiles, %llu bytes at rest, %llu evicted, file %llu bytes\n",
		      (unsigned long long)tiles, (unsigned long long)bytes, (unsigned long long)ev,
		      (unsigned long long)stat_of(c, "store.disk.file_bytes"));
	assert_int_equal(budget, 1u << 20);
	assert_true(bytes <= budget);
	assert_true(ev > 0);
	assert_true(tiles > 0 && tiles < 3 * 576);
	assert_int_equal(tiles + ev, puts);
	struct stat st;
	assert_int_equal(stat(e->store, &st), 0);
	assert_true((uint64_t)st.st_size <= budget + budget / 2 + ((uint64_t)32 << 20));
	net_close(c);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(survives_restart, setup, teardown),
		cmocka_unit_test_setup_teardown(corrupt_entry_regenerated, setup, teardown),
		cmocka_unit_test_setup_teardown(kill9_during_writes, setup, teardown),
		cmocka_unit_test_setup_teardown(write_failure_recovers, setup, teardown),
		cmocka_unit_test_setup_teardown(disk_budget_respected, setup_small, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
