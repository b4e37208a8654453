/* Several processes, one store (issue 13): a running clipmapd and `clipmapctl render --store`
 * on the same LMDB file. Both fill it and both read each other's tiles (the render's store
 * hits, the daemon's store.disk.hits with nothing generated); `cache verify` finds no damaged
 * entry; kill -9 of the render while both write leaves the daemon serving and writing, and
 * kill -9 of the daemon leaves the render finishing (and the restarted daemon reading what the
 * render wrote). The shared totals: the daemon's store.disk.tiles counts the render's tiles.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/net_stat.h"

static const char planet_text[] =
	"[planet]\nname = test\nbody = sphere\nradius = 6371000\ntile_size = 64\nmax_level = 22\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 2\nwavelength = 3000000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n";

#define MAXW 512

struct env {
	struct daemon_env d;
	char planet[256], store[160], set_store[200];
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_store_shared") ||
	    daemon_env_planet_text(&e->d, "test.ini", planet_text, e->planet))
		return -1;
	if (!daemon_env_built(&e->d, "clipmapd") || !daemon_env_built(&e->d, "clipmapctl-offline"))
		return 0;
	snprintf(e->store, sizeof e->store, "%s/tiles.lmdb", e->d.dir);
	snprintf(e->set_store, sizeof e->set_store, "store.path = %s", e->store);
	const char *const set[] = { e->set_store, "store.disk_mb = 1024", "engine.workers = 1",
				    "session.max_rate = 0", NULL };
	char err[256];
	if (daemon_env_start(&e->d, &(struct daemon_env_conf){ .set = set }, err)) {
		fprintf(stderr, "test_store_shared: %s\n", err);
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

static struct net_conn *conn(struct env *e, uint32_t *pid)
{
	struct net_conn *c;
	char err[256];
	struct net_opts o = { .socket_path = e->d.sock, .name = "test_store_shared" };
	if (net_connect(&o, &c, err))
		fail_msg("%s", err);
	if (pid) {
		struct proto_msg m = { 0 };
		if (net_open_planet(c, "test", &m, 10000, err))
			fail_msg("%s", err);
		*pid = m.opened.planet_id;
		proto_msg_fini(&m);
	}
	return c;
}

static uint64_t stat_of(struct net_conn *c, const char *key)
{
	uint64_t v;
	char err[256];
	if (net_stat_u64(c, key, &v, err))
		fail_msg("%s", err);
	return v;
}

static void wait_written(struct net_conn *c)
{
	char err[256];
	if (net_stat_wait_zero(c, "store.disk.queued", 20000, err))
		fail_msg("%s", err);
}

/* Sends the WANT (both layers of the block) and receives every tile. Returns how many. */
static uint32_t fetch_block(struct net_conn *c, uint32_t pid, uint32_t seq, int ly, uint32_t x0,
			    uint32_t y0, uint32_t wd, uint32_t h)
{
	static struct proto_want_entry w[MAXW];
	uint32_t n = net_want_block(w, 0, MAXW, ly, x0, y0, wd, h);
	char err[256];
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .count = n, .entries = w } };
	if (net_send(c, &m, err))
		fail_msg("%s", err);
	uint32_t got = 0;
	while (got < n) {
		struct proto_msg r = { 0 };
		if (net_recv(c, &r, 30000, err))
			fail_msg("after %u of %u tiles: %s", got, n, err);
		if (r.type == PROTO_TILE_FAIL)
			fail_msg("TILE_FAIL: %s", r.tile_fail.message);
		got += r.type == PROTO_TILE && r.tile.seq == seq;
		proto_msg_fini(&r);
	}
	return got;
}

/* The argv of `clipmapctl-offline render` of tile (ly + 1, ly, x, y) of layer into the store. */
static const char *store_mb = "1024"; /* --store-mb of the renders */

static void render_argv(struct env *e, char **av, char *exe, size_t nexe, char *out, size_t nout,
			char nums[4][16], const char *layer, int ly, uint32_t x, uint32_t y)
{
	snprintf(exe, nexe, "%s/clipmapctl-offline", e->d.bindir);
	snprintf(out, nout, "%s/%s-%d-%u-%u.%s", e->d.dir, layer, ly, x, y,
		 strcmp(layer, "height") ? "png" : "tif");
	snprintf(nums[0], 16, "%d", ly + 1);
	snprintf(nums[1], 16, "%d", ly);
	snprintf(nums[2], 16, "%u", x);
	snprintf(nums[3], 16, "%u", y);
	char *const v[] = { exe,	   "render",	     e->planet, (char *)layer, nums[0],
			    nums[1],	   nums[2],	     nums[3],	"--store",     e->store,
			    "--workers",   "1",		     "-o",	out,	       "--store-mb",
			    (char *)store_mb, NULL };
	memcpy(av, v, sizeof v);
}

/* Renders each tile of the block (both layers) with --store; sums the hits and tiles written
 * that each run reports. */
static void render_block(struct env *e, int ly, uint32_t x0, uint32_t y0, uint32_t wd, uint32_t h,
			 uint64_t *hits, uint64_t *written)
{
	static const char *const layers[] = { "height", "color" };
	*hits = *written = 0;
	for (uint32_t y = y0; y < y0 + h; y++)
		for (uint32_t x = x0; x < x0 + wd; x++)
			for (int l = 0; l < 2; l++) {
				char *av[18], exe[600], out[300], nums[4][16], text[4096];
				render_argv(e, av, exe, sizeof exe, out, sizeof out, nums, layers[l],
					    ly, x, y);
				int st = daemon_env_run(av, text, sizeof text);
				if (st != 0)
					fail_msg("render exit %d: %s", st, text);
				const char *p = strstr(text, "tiles.lmdb: ");
				if (!p)
					fail_msg("no store line in: %s", text);
				unsigned long long hh, mm, ww;
				if (sscanf(p, "tiles.lmdb: %llu hits, %llu misses, %llu tiles written",
					   &hh, &mm, &ww) != 3)
					fail_msg("store line: %s", p);
				*hits += hh;
				*written += ww;
			}
}

/* clipmapctl cache verify --json: the corrupt count (checked > 0). */
static uint64_t verify(struct env *e)
{
	char exe[600], text[4096];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	char *const av[] = { exe, "-s", e->d.sock, "cache", "verify", "--json", NULL };
	assert_int_equal(daemon_env_run(av, text, sizeof text), 0);
	printf("verify: %s", text);
	const char *c = strstr(text, "\"corrupt\": ");
	assert_non_null(c);
	assert_true(strtoull(strstr(text, "\"checked\": ") + 11, NULL, 10) > 0);
	return strtoull(c + 11, NULL, 10);
}

/* The daemon fills a block, the render reads it (hits, nothing written); the render fills
 * another (with a larger budget, so a larger map), the daemon serves it from disk (hits,
 * nothing generated). */
static void both_fill_both_read(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	assert_int_equal(fetch_block(c, pid, 1, 6, 10, 30, 2, 2), 8);
	wait_written(c);
	uint64_t disk0 = stat_of(c, "store.disk.tiles");
	assert_true(disk0 >= 8);
	uint64_t hits, written;
	render_block(e, 6, 10, 30, 2, 2, &hits, &written);
	printf("render of the daemon's block: %llu store hits, %llu written\n",
	       (unsigned long long)hits, (unsigned long long)written);
	assert_int_equal(hits, 8);
	assert_int_equal(written, 0);
	/* with a larger budget (a larger map) than the daemon's: both read on (LMDB says
	 * MDB_MAP_RESIZED only once the file outgrows the daemon's map, which store_lmdb's
	 * begin() handles; not reached here) */
	store_mb = "3072";
	render_block(e, 6, 40, 30, 2, 2, &hits, &written);
	store_mb = "1024";
	printf("render of a new block: %llu store hits, %llu written\n", (unsigned long long)hits,
	       (unsigned long long)written);
	assert_true(written >= 8);
	/* the daemon's totals count the render's tiles (the file's, not its own) */
	uint64_t disk1 = stat_of(c, "store.disk.tiles");
	printf("store.disk.tiles: %llu, then %llu after the render\n", (unsigned long long)disk0,
	       (unsigned long long)disk1);
	assert_int_equal(disk1, disk0 + written);
	uint64_t gen0 = stat_of(c, "sched.generated"), dh0 = stat_of(c, "store.disk.hits");
	assert_int_equal(fetch_block(c, pid, 2, 6, 40, 30, 2, 2), 8);
	uint64_t gen1 = stat_of(c, "sched.generated"), dh1 = stat_of(c, "store.disk.hits");
	printf("daemon on the render's block: %llu disk hits, %llu generated\n",
	       (unsigned long long)(dh1 - dh0), (unsigned long long)(gen1 - gen0));
	assert_int_equal(dh1 - dh0, 8);
	assert_int_equal(gen1 - gen0, 0);
	net_close(c);
	assert_int_equal(verify(e), 0);
}

/* Starts clipmapctl-offline rendering ntiles² tiles of height around (lat, lon) at level ly
 * into the store; returns its pid (output to a file). */
static pid_t render_start(struct env *e, int ly, const char *at, const char *ntiles,
			  const char *name)
{
	char exe[600], out[300], lv[16];
	snprintf(exe, sizeof exe, "%s/clipmapctl-offline", e->d.bindir);
	snprintf(out, sizeof out, "%s/%s.tif", e->d.dir, name);
	snprintf(lv, sizeof lv, "%d", ly);
	pid_t p = fork();
	assert_true(p >= 0);
	if (p == 0) {
		char log[300];
		snprintf(log, sizeof log, "%s/%s.log", e->d.dir, name);
		if (!freopen(log, "w", stdout) || !freopen(log, "a", stderr))
			_exit(126);
		execl(exe, exe, "render", e->planet, "height", "--level", lv, "--at", at, "--tiles",
		      ntiles, "--store", e->store, "--workers", "1", "--quiet", "-o", out,
		      (char *)NULL);
		_exit(127);
	}
	return p;
}

/* kill -9 of the render while both write: the daemon keeps serving and writing; kill -9 of
 * the daemon while both write: the render finishes, the restarted daemon reads its tiles. */
static void kill9_of_either(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	uint32_t pid;
	struct net_conn *c = conn(e, &pid);
	uint64_t before = stat_of(c, "store.disk.tiles");
	pid_t r = render_start(e, 10, "-30,100", "64", "big"); /* 4096 tiles: ~0.9 s here */
	/* as soon as its first tiles are in the store (not after a fixed delay, which a fast
	 * machine's render outran): the daemon writes too, then the render dies mid-block */
	uint64_t end = clock_now_ms() + 30000;
	int st;
	while (stat_of(c, "store.disk.tiles") == before) {
		if (waitpid(r, &st, WNOHANG) == r)
			fail_msg("the render exited (status %d) before it wrote a tile", st);
		if (clock_now_ms() > end)
			fail_msg("the render wrote no tile in 30 s");
		usleep(5000);
	}
	assert_int_equal(fetch_block(c, pid, 3, 7, 60, 50, 8, 4), 64); /* daemon writes too */
	assert_int_equal(kill(r, SIGKILL), 0);
	assert_int_equal(waitpid(r, &st, 0), r);
	assert_true(WIFSIGNALED(st));
	assert_int_equal(fetch_block(c, pid, 4, 7, 80, 50, 8, 4), 64);
	wait_written(c);
	assert_int_equal(stat_of(c, "store.disk.write_errors"), 0);
	net_close(c);
	assert_int_equal(verify(e), 0);

	/* now the daemon dies while the render writes */
	c = conn(e, &pid);
	r = render_start(e, 8, "30,-100", "6", "second");
	static struct proto_want_entry w[MAXW];
	uint32_t n = net_want_block(w, 0, MAXW, 8, 0, 120, 16, 8);
	char err[256];
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 5, .count = n, .entries = w } };
	assert_int_equal(net_send(c, &m, err), 0);
	usleep(800 * 1000);
	assert_int_equal(daemon_env_stop(&e->d, SIGKILL, NULL), 0);
	net_close(c);
	end = clock_now_ms() + 120000;
	while (waitpid(r, &st, WNOHANG) == 0 && clock_now_ms() < end)
		usleep(50000);
	if (clock_now_ms() >= end) {
		kill(r, SIGKILL);
		waitpid(r, &st, 0);
		fail_msg("the render did not finish in 120 s after the daemon was killed");
	}
	char logp[300], text[4096] = "";
	snprintf(logp, sizeof logp, "%s/second.log", e->d.dir);
	FILE *f = fopen(logp, "r");
	if (f) {
		size_t k = fread(text, 1, sizeof text - 1, f);
		text[k] = 0;
		fclose(f);
	}
	printf("render after the daemon's kill -9: exit %d %s\n", WIFEXITED(st) ? WEXITSTATUS(st) : -1,
	       text);
	assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
	if (daemon_env_restart(&e->d, err))
		fail_msg("restart: %s", err);
	assert_int_equal(verify(e), 0);
	/* the render's tiles are read by the restarted daemon: ask for one of them */
	uint64_t hits, written;
	render_block(e, 6, 50, 20, 1, 1, &hits, &written); /* written by this render */
	c = conn(e, &pid);
	uint64_t gen0 = stat_of(c, "sched.generated");
	assert_int_equal(fetch_block(c, pid, 6, 6, 50, 20, 1, 1), 2);
	assert_int_equal(stat_of(c, "sched.generated") - gen0, 0);
	net_close(c);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(both_fill_both_read),
		cmocka_unit_test(kill9_of_either),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
