/* Store tests (engine/store.h) on a real LMDB file in a temporary directory: put / get /
 * contains / delete / iterate / stat through the vtable, persistence across reopening, a
 * value damaged inside the file (detected, counted, dropped — never returned), a value moved
 * under another key, the byte budget (least recently used evicted first, prefetched tiles
 * after every incidental one), the write queue's
 * accounting (every put is either written or counted as dropped), a file that is not
 * LMDB (moved aside, a fresh store created), and contains starting to read a value whose
 * pages are not in the page cache (the file's pages counted with mincore). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <lmdb.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "common/tilecodec.h"
#include "engine/store.h"
#include "engine/tile.h"
#include "support/pagecache.h"

#define T 64

struct env {
	char dir[64];
	char path[128];
	struct tilecodec *tc;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	snprintf(e->dir, sizeof e->dir, "/tmp/test_store_XXXXXX");
	if (!mkdtemp(e->dir))
		return -1;
	snprintf(e->path, sizeof e->path, "%s/tiles.lmdb", e->dir);
	e->tc = tilecodec_create();
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", e->dir);
	if (system(cmd) != 0)
		fprintf(stderr, "could not remove %s\n", e->dir);
	tilecodec_destroy(e->tc);
	free(e);
	return 0;
}

static struct store *open_store_as(struct env *e, uint64_t budget, size_t qmax,
				   enum tcodec codec)
{
	struct store *s = NULL;
	char err[256] = "";
	int rc = store_lmdb_open(&(struct store_lmdb_desc){ .path = e->path, .budget = budget,
							    .queue_max = qmax, .codec = codec },
				 &s, err);
	if (rc)
		fail_msg("open: %s", err);
	return s;
}

static struct store *open_store(struct env *e, uint64_t budget, size_t qmax)
{
	return open_store_as(e, budget, qmax, TCODEC_ZSTD);
}

static struct tile_key key(uint64_t node, uint32_t x, uint32_t y)
{
	return (struct tile_key){ .node = node, .lx = 5, .ly = 4, .x = x, .y = y };
}

/* A height tile with smooth, key-dependent texels (compressible) or noise (not). */
static struct tile *make_tile(const struct tile_key *k, bool noisy)
{
	struct tile *t = tile_create(k, PIX_HEIGHT, T);
	uint32_t r = (uint32_t)(k->node * 2654435761u + k->x * 40503u + k->y);
	for (int i = 0; i < T * T; i++) {
		r = r * 1664525u + 1013904223u;
		tile_f32(t)[i] = noisy ? (float)(r >> 8) : (float)(k->x * 100 + i % T + k->y);
	}
	return t;
}

static void assert_same(const struct tile *a, const struct tile *b)
{
	assert_int_equal(a->type, b->type);
	assert_int_equal(a->size, b->size);
	assert_true(grid_key_equal(&a->key, &b->key));
	assert_memory_equal(a->data, b->data, a->nbytes);
}

/* Noisy tiles (14, 0..n-1, row) stored as prefetched. */
static void put_prefetched_row(struct store *s, uint32_t row, uint32_t n)
{
	for (uint32_t i = 0; i < n; i++) {
		struct tile_key k = key(14, i, row);
		struct tile *t = make_tile(&k, true);
		assert_int_equal(store_put(s, t, STORE_KEEP_PREFETCHED), 0);
		tile_unref(t);
	}
}

static void put_new(struct store *s, const struct tile_key *k, bool noisy)
{
	struct tile *t = make_tile(k, noisy);
	assert_int_equal(store_put(s, t, STORE_KEEP_INCIDENTAL), 0);
	tile_unref(t);
}

static int count_fn(void *ud, const struct store_entry *e)
{
	(void)e;
	(*(int *)ud)++;
	return 0;
}

static int count(struct store *s)
{
	int n = 0;
	assert_int_equal(store_iterate(s, count_fn, &n), 0);
	return n;
}

static void put_get_delete_iterate(void **state)
{
	struct env *e = *state;
	struct store *s = open_store(e, 0, 0);
	struct tile_key a = key(7, 1, 2), b = key(7, 3, 2), c = key(8, 1, 2);
	struct tile *ta = make_tile(&a, false), *tb = make_tile(&b, true);
	assert_int_equal(store_put(s, ta, STORE_KEEP_INCIDENTAL), 0);
	assert_int_equal(store_put(s, tb, STORE_KEEP_INCIDENTAL), 0);
	assert_int_equal(store_flush(s), 0);

	struct tile *got = NULL;
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(ta, got);
	tile_unref(got);
	assert_int_equal(store_get(s, &b, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(tb, got);
	tile_unref(got);
	assert_int_equal(store_get(s, &c, PIX_HEIGHT, T, e->tc, &got), -ENOENT);
	assert_null(got);
	/* Another format or size under the same key is not this tile. */
	assert_int_equal(store_get(s, &a, PIX_COLOR, T, e->tc, &got), -ENOENT);
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T * 2, e->tc, &got), -ENOENT);
	assert_true(store_contains(s, &a));
	assert_false(store_contains(s, &c));

	struct store_stats st;
	store_stat(s, &st);
	assert_int_equal(st.tiles, 2);
	assert_int_equal(st.puts, 2);
	assert_int_equal(st.hits, 2);
	assert_int_equal(st.misses, 4);
	assert_int_equal(st.corrupt, 0);
	assert_true(st.bytes > 0 && st.file_bytes > 0);
	assert_int_equal(count(s), 2);

	/* Putting a key again replaces its value; the accounting does not double. */
	assert_int_equal(store_put(s, ta, STORE_KEEP_INCIDENTAL), 0);
	assert_int_equal(store_flush(s), 0);
	struct store_stats st2;
	store_stat(s, &st2);
	assert_int_equal(st2.tiles, 2);
	assert_int_equal(st2.bytes, st.bytes);

	assert_int_equal(store_del(s, &a), 0);
	assert_int_equal(store_flush(s), 0);
	assert_false(store_contains(s, &a));
	assert_int_equal(count(s), 1);
	store_stat(s, &st);
	assert_int_equal(st.tiles, 1);
	store_destroy(s);

	/* Reopened: what was written is there, with its accounting. */
	s = open_store(e, 0, 0);
	store_stat(s, &st2);
	assert_int_equal(st2.tiles, 1);
	assert_int_equal(st2.bytes, st.bytes);
	assert_int_equal(store_get(s, &b, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(tb, got);
	tile_unref(got);
	store_destroy(s);
	tile_unref(ta);
	tile_unref(tb);
}

/* Rewrites the value stored under k with fn applied, in the file, with the store closed. */
static void edit_value(struct env *e, const struct tile_key *k, const struct tile_key *to,
		       void (*fn)(uint8_t *v, size_t n))
{
	MDB_env *env;
	MDB_txn *txn;
	MDB_dbi dbi;
	assert_int_equal(mdb_env_create(&env), 0);
	assert_int_equal(mdb_env_set_maxdbs(env, 4), 0);
	assert_int_equal(mdb_env_open(env, e->path, MDB_NOSUBDIR, 0644), 0);
	assert_int_equal(mdb_txn_begin(env, NULL, 0, &txn), 0);
	assert_int_equal(mdb_dbi_open(txn, "tiles", 0, &dbi), 0);
	uint8_t kb[STORE_KEY_LEN], kt[STORE_KEY_LEN];
	store_key_encode(k, kb);
	store_key_encode(to, kt);
	MDB_val mk = { sizeof kb, kb }, mt = { sizeof kt, kt }, v;
	assert_int_equal(mdb_get(txn, dbi, &mk, &v), 0);
	uint8_t *copy = malloc(v.mv_size);
	memcpy(copy, v.mv_data, v.mv_size);
	MDB_val nv = { v.mv_size, copy };
	if (fn)
		fn(copy, v.mv_size);
	assert_int_equal(mdb_put(txn, dbi, &mt, &nv, 0), 0);
	assert_int_equal(mdb_txn_commit(txn), 0);
	mdb_env_close(env);
	free(copy);
}

static void flip_payload(uint8_t *v, size_t n)
{
	v[n / 2] ^= 0x5a;
	v[n - 1] ^= 0x01;
}

/* The codec byte of the value edit_value last saw. */
static int seen_codec = -1;
static void see_codec(uint8_t *v, size_t n)
{
	seen_codec = n > 6 ? v[6] : -1;
}

/* [store] disk_codec = lz4: values are written with lz4 and read back exact; a store opened
 * to write zstd reads them as well, and writes zstd beside them (a changed setting needs no
 * conversion). */
static void lz4_at_rest_read_by_either(void **state)
{
	struct env *e = *state;
	struct tile_key a = key(21, 1, 1), b = key(21, 2, 1);
	struct tile *ta = make_tile(&a, true), *tb = make_tile(&b, true), *got = NULL;
	struct store *s = open_store_as(e, 0, 0, TCODEC_LZ4);
	assert_int_equal(store_put(s, ta, STORE_KEEP_INCIDENTAL), 0);
	assert_int_equal(store_flush(s), 0);
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(ta, got);
	tile_unref(got);
	store_destroy(s);
	edit_value(e, &a, &a, see_codec);
	assert_int_equal(seen_codec, TCODEC_LZ4);

	s = open_store(e, 0, 0);
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(ta, got);
	tile_unref(got);
	assert_int_equal(store_put(s, tb, STORE_KEEP_INCIDENTAL), 0);
	assert_int_equal(store_flush(s), 0);
	assert_int_equal(store_get(s, &b, PIX_HEIGHT, T, e->tc, &got), 0);
	assert_same(tb, got);
	tile_unref(got);
	struct store_stats st;
	store_stat(s, &st);
	assert_int_equal(st.corrupt, 0);
	store_destroy(s);
	edit_value(e, &b, &b, see_codec);
	assert_int_equal(seen_codec, TCODEC_ZSTD);
	tile_unref(ta);
	tile_unref(tb);
}

static void corrupt_value_detected(void **state)
{
	struct env *e = *state;
	struct store *s = open_store(e, 0, 0);
	struct tile_key a = key(9, 4, 4), b = key(9, 5, 4);
	put_new(s, &a, false);
	put_new(s, &b, false);
	store_destroy(s);

	edit_value(e, &a, &a, flip_payload);
	/* b's intact value copied under a third key: the checksum binds a value to its key. */
	struct tile_key c = key(9, 6, 4);
	edit_value(e, &b, &c, NULL);

	s = open_store(e, 0, 0);
	struct tile *got = (struct tile *)&got;
	assert_true(store_contains(s, &a));
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), -EBADMSG);
	assert_null(got);
	assert_int_equal(store_get(s, &c, PIX_HEIGHT, T, e->tc, &got), -EBADMSG);
	assert_int_equal(store_get(s, &b, PIX_HEIGHT, T, e->tc, &got), 0);
	tile_unref(got);
	struct store_stats st;
	store_stat(s, &st);
	assert_int_equal(st.corrupt, 2);
	/* The damaged entries are dropped (write-behind): a later get is a plain miss. */
	assert_int_equal(store_flush(s), 0);
	assert_false(store_contains(s, &a));
	assert_false(store_contains(s, &c));
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), -ENOENT);
	/* Writing it again serves it again. */
	put_new(s, &a, false);
	assert_int_equal(store_flush(s), 0);
	assert_int_equal(store_get(s, &a, PIX_HEIGHT, T, e->tc, &got), 0);
	struct tile *want = make_tile(&a, false);
	assert_same(want, got);
	tile_unref(want);
	tile_unref(got);
	store_destroy(s);
}

static void budget_evicts_least_recent(void **state)
{
	struct env *e = *state;
	const uint64_t budget = (uint64_t)1 << 20; /* 1 MiB: about 60 noisy 16 KiB tiles */
	struct store *s = open_store(e, budget, 0);
	struct tile_key first = key(11, 0, 0);
	put_new(s, &first, true);
	assert_int_equal(store_flush(s), 0);
	struct tile *got;
	for (uint32_t i = 1; i < 300; i++) {
		struct tile_key k = key(11, i, 0);
		put_new(s, &k, true);
		if (i % 16 == 0) {
			/* Keep the first tile recently used: it must survive. */
			assert_int_equal(store_flush(s), 0);
			assert_int_equal(store_get(s, &first, PIX_HEIGHT, T, e->tc, &got), 0);
			tile_unref(got);
		}
	}
	assert_int_equal(store_flush(s), 0);
	struct store_stats st;
	store_stat(s, &st);
	assert_true(st.bytes <= budget);
	assert_true(st.evictions > 0);
	assert_int_equal(st.tiles + st.evictions, 300);
	assert_int_equal((int)st.tiles, count(s));
	assert_true(st.file_bytes <= budget + budget / 2 + ((uint64_t)32 << 20));
	assert_true(store_contains(s, &first));
	struct tile_key last = key(11, 299, 0), old = key(11, 1, 0);
	assert_true(store_contains(s, &last));
	assert_false(store_contains(s, &old));
	store_destroy(s);
}

struct keep_scan {
	uint64_t max_stamp;
	int prefetched;
	struct tile_key probe;
	int probe_keep;
};

static int keep_fn(void *ud, const struct store_entry *e)
{
	struct keep_scan *k = ud;
	k->max_stamp = e->stamp > k->max_stamp ? e->stamp : k->max_stamp;
	k->prefetched += e->keep == STORE_KEEP_PREFETCHED;
	if (grid_key_equal(&e->key, &k->probe))
		k->probe_keep = (int)e->keep;
	return 0;
}

/* Prefetched tiles outlive incidental ones however old they are; a prefetched tile written
 * again incidentally stays prefetched; recency stamps keep increasing across reopening. */
static void prefetched_kept_ahead(void **state)
{
	struct env *e = *state;
	const uint64_t budget = (uint64_t)1 << 20;
	struct store *s = open_store(e, budget, 0);
	put_prefetched_row(s, 0, 20);
	assert_int_equal(store_flush(s), 0);
	struct tile_key k0 = key(14, 0, 0);
	put_new(s, &k0, true); /* incidental rewrite of a prefetched tile */
	for (uint32_t i = 0; i < 200; i++) {
		struct tile_key k = key(14, i, 1);
		put_new(s, &k, true);
	}
	assert_int_equal(store_flush(s), 0);
	struct store_stats st;
	store_stat(s, &st);
	assert_true(st.evictions > 0);
	assert_int_equal(st.evictions_prefetched, 0); /* incidental ones went */
	assert_true(st.bytes <= budget);
	for (uint32_t i = 0; i < 20; i++) {
		struct tile_key k = key(14, i, 0);
		assert_true(store_contains(s, &k));
	}
	struct tile_key first_inc = key(14, 0, 1);
	assert_false(store_contains(s, &first_inc));
	struct keep_scan ks = { .probe = k0, .probe_keep = -1 };
	assert_int_equal(store_iterate(s, keep_fn, &ks), 0);
	assert_int_equal(ks.prefetched, 20);
	assert_int_equal(ks.probe_keep, STORE_KEEP_PREFETCHED);
	store_destroy(s);

	s = open_store(e, budget, 0);
	struct tile_key fresh = key(14, 999, 2);
	put_new(s, &fresh, false);
	assert_int_equal(store_flush(s), 0);
	struct keep_scan after = { .probe = fresh, .probe_keep = -1 };
	assert_int_equal(store_iterate(s, keep_fn, &after), 0);
	assert_int_equal(after.max_stamp, ks.max_stamp + 1);
	/* Prefetching past the budget: the oldest prefetched tiles go, and are counted so
	 * (what clipmapctl prefetch warns of). */
	put_prefetched_row(s, 3, 200);
	assert_int_equal(store_flush(s), 0);
	store_stat(s, &st);
	assert_true(st.evictions_prefetched > 0);
	assert_true(st.evictions_prefetched <= st.evictions);
	assert_false(store_contains(s, &k0));
	store_destroy(s);
}

static void queue_accounting(void **state)
{
	struct env *e = *state;
	struct store *s = open_store(e, 0, 2);
	int accepted = 0;
	for (uint32_t i = 0; i < 200; i++) {
		struct tile_key k = key(12, i, 1);
		struct tile *t = make_tile(&k, true);
		accepted += store_put(s, t, STORE_KEEP_INCIDENTAL) == 0;
		tile_unref(t);
	}
	assert_int_equal(store_flush(s), 0);
	struct store_stats st;
	store_stat(s, &st);
	assert_int_equal(st.puts, (uint64_t)accepted);
	assert_int_equal(st.puts + st.write_drops, 200);
	assert_int_equal(st.tiles, st.puts);
	assert_int_equal(st.queued, 0);
	store_destroy(s);
}

static void foreign_file_moved_aside(void **state)
{
	struct env *e = *state;
	FILE *f = fopen(e->path, "w");
	assert_non_null(f);
	for (int i = 0; i < 4096; i++)
		fputs("not an lmdb file ", f);
	assert_int_equal(fclose(f), 0);
	struct store *s = NULL;
	char err[256] = "";
	assert_int_equal(store_lmdb_open(&(struct store_lmdb_desc){ .path = e->path }, &s, err), 0);
	assert_non_null(strstr(err, "moved aside"));
	struct tile_key a = key(13, 0, 0);
	put_new(s, &a, false);
	assert_int_equal(store_flush(s), 0);
	assert_true(store_contains(s, &a));
	store_destroy(s);
}

static size_t resident_pages(const char *path)
{
	size_t in, np;
	assert_int_equal(pagecache_count(path, &in, &np), 0);
	return in;
}

static int value_len(void *ud, const struct store_entry *en)
{
	*(uint32_t *)ud = en->bytes;
	return 1;
}

/* A value out of the page cache (as after a reboot, or pages the kernel reclaimed) is read in
 * when contains finds it, not a page at a time by the get that follows: with the pages
 * faulted one by one, a restarted daemon's two workers waited on one 4 KiB read after
 * another (50 MB/s, the CPU a third idle, 0.2 % full-detail frames at 47.6x the seed). */
static void contains_starts_reading_the_value(void **state)
{
	struct env *e = *state;
	struct store *s = open_store(e, 0, 0);
	struct tile *t[4];
	uint32_t r = 12345;
	for (int k = 0; k < 4; k++) {
		struct tile_key a = key(9, (uint32_t)k, 1);
		t[k] = tile_create(&a, PIX_HEIGHT, 256);
		for (int i = 0; i < 256 * 256; i++) {
			r = r * 1664525u + 1013904223u;
			tile_f32(t[k])[i] = (float)(r >> 8);
		}
		assert_int_equal(store_put(s, t[k], STORE_KEEP_INCIDENTAL), 0);
	}
	assert_int_equal(store_flush(s), 0);
	uint32_t vlen = 0;
	store_iterate(s, value_len, &vlen);
	size_t pg = (size_t)sysconf(_SC_PAGESIZE), vpages = vlen / pg;
	assert_true(vpages >= 32); /* noise: the value stays large */
	/* Closed, the file's clean pages can all be dropped (mapped ones could not). */
	store_destroy(s);
	assert_int_equal(pagecache_drop(e->path), 0);
	s = open_store(e, 0, 0);
	size_t before = resident_pages(e->path);
	if (before >= vpages) {
		store_destroy(s);
		for (int k = 0; k < 4; k++)
			tile_unref(t[k]);
		skip(); /* the file system keeps its pages (tmpfs): nothing to read in */
	}
	assert_true(store_contains(s, &t[2]->key));
	/* The read is asynchronous: mincore counts a page once it has been read. Nothing else
	 * reads the file here, so without the hint the value's pages never come. */
	size_t after = resident_pages(e->path);
	for (int i = 0; i < 500 && after < before + vpages * 9 / 10; i++) {
		usleep(10000);
		after = resident_pages(e->path);
	}
	assert_true(after >= before + vpages * 9 / 10);
	struct tile *got = NULL;
	assert_int_equal(store_get(s, &t[2]->key, PIX_HEIGHT, 256, e->tc, &got), 0);
	assert_same(t[2], got);
	tile_unref(got);
	for (int k = 0; k < 4; k++)
		tile_unref(t[k]);
	store_destroy(s);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(put_get_delete_iterate, setup, teardown),
		cmocka_unit_test_setup_teardown(corrupt_value_detected, setup, teardown),
		cmocka_unit_test_setup_teardown(lz4_at_rest_read_by_either, setup, teardown),
		cmocka_unit_test_setup_teardown(budget_evicts_least_recent, setup, teardown),
		cmocka_unit_test_setup_teardown(prefetched_kept_ahead, setup, teardown),
		cmocka_unit_test_setup_teardown(queue_accounting, setup, teardown),
		cmocka_unit_test_setup_teardown(foreign_file_moved_aside, setup, teardown),
		cmocka_unit_test_setup_teardown(contains_starts_reading_the_value, setup, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
