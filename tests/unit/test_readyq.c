/* readyq tests: what a session's reports hold while they wait for the loop. Reports carry their
 * tile until the session's queued bytes would pass its cap; past it they arrive parked (no
 * tile, no reference kept), the first one always with its tile; the loop taking a report gives
 * its bytes back; failures pass through as failures, never as parked tiles. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdlib.h>

#include "daemon/readyq.h"
#include "engine/tile.h"

static struct tile *mk_tile(uint32_t x)
{
	struct tile_key k = { .node = 1, .lx = 3, .ly = 2, .x = x, .y = 0 };
	return tile_create(&k, PIX_HEIGHT, 16); /* 16² f32: 1 KiB */
}

static int refs(struct tile *t)
{
	return atomic_load(&t->refs);
}

/* Takes what is queued, checking the count; the caller frees the batch. */
static struct ready_item *take(struct readyq *q, size_t want)
{
	size_t n = 0;
	struct ready_item *b = readyq_take(q, &n);
	assert_int_equal(n, want);
	return b;
}

static void release(struct ready_item *b, size_t n)
{
	for (size_t i = 0; i < n; i++) {
		ready_item_taken(&b[i]);
		tile_unref(b[i].t);
		ready_src_unref(b[i].src);
	}
	free(b);
}

static void test_cap_parks_beyond(void **state)
{
	(void)state;
	struct readyq q;
	assert_int_equal(readyq_init(&q), 0);
	struct ready_src *src = ready_src_new(&q, NULL);
	struct tile *t[6];
	for (int i = 0; i < 6; i++)
		t[i] = mk_tile((uint32_t)i);
	uint64_t one = t[0]->nbytes;
	src->queue_cap = 3 * one;
	for (int i = 0; i < 6; i++)
		ready_src_report(src, &t[i]->key, t[i], 0);
	assert_int_equal(atomic_load(&src->queued), 3 * one);
	struct ready_item *b = take(&q, 6);
	for (int i = 0; i < 6; i++) {
		assert_memory_equal(&b[i].key, &t[i]->key, sizeof b[i].key);
		assert_int_equal(b[i].err, 0);
		if (i < 3) { /* carried: a reference each, counted */
			assert_ptr_equal(b[i].t, t[i]);
			assert_false(b[i].parked);
			assert_int_equal(refs(t[i]), 2);
		} else { /* parked: nothing held for it */
			assert_null(b[i].t);
			assert_true(b[i].parked);
			assert_int_equal(refs(t[i]), 1);
		}
	}
	release(b, 6);
	assert_int_equal(atomic_load(&src->queued), 0);
	/* room again: the next report carries its tile */
	ready_src_report(src, &t[5]->key, t[5], 0);
	b = take(&q, 1);
	assert_ptr_equal(b[0].t, t[5]);
	release(b, 1);
	for (int i = 0; i < 6; i++) {
		assert_int_equal(refs(t[i]), 1);
		tile_unref(t[i]);
	}
	ready_src_unref(src);
	readyq_fini(&q);
}

/* A tile bigger than the cap still goes when nothing is queued (the loop is never starved);
 * a failure is a failure, whatever is queued; purging a session's items gives their bytes
 * back. */
static void test_first_failure_purge(void **state)
{
	(void)state;
	struct readyq q;
	assert_int_equal(readyq_init(&q), 0);
	struct ready_src *src = ready_src_new(&q, (struct session *)&q);
	struct tile *a = mk_tile(0), *b = mk_tile(1);
	src->queue_cap = a->nbytes / 2;
	ready_src_report(src, &a->key, a, 0);
	ready_src_report(src, &b->key, NULL, -5);
	ready_src_report(src, &b->key, b, 0);
	assert_int_equal(atomic_load(&src->queued), a->nbytes);
	struct ready_item *it = take(&q, 3);
	assert_ptr_equal(it[0].t, a);
	assert_null(it[1].t);
	assert_false(it[1].parked);
	assert_int_equal(it[1].err, -5);
	assert_null(it[2].t);
	assert_true(it[2].parked);
	release(it, 3);
	assert_int_equal(atomic_load(&src->queued), 0);

	ready_src_report(src, &a->key, a, 0);
	assert_int_equal(refs(a), 2);
	readyq_purge(&q, (struct session *)&q);
	assert_int_equal(refs(a), 1);
	assert_int_equal(atomic_load(&src->queued), 0);
	size_t n = 1;
	free(readyq_take(&q, &n));
	assert_int_equal(n, 0);
	tile_unref(a);
	tile_unref(b);
	ready_src_unref(src);
	readyq_fini(&q);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_cap_parks_beyond),
		cmocka_unit_test(test_first_failure_purge),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
