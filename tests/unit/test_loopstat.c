/* test_loopstat — the loop-iteration histogram: buckets, maximum, quantile, the count over a
 * bound. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "daemon/loopstat.h"

#define MS 1000000ull

static void test_buckets(void **state)
{
	(void)state;
	struct loopstat ls = { 0 };
	assert_true(loopstat_quantile_ms(&ls, 0.99) == 0.0);
	for (int i = 0; i < 990; i++)
		loopstat_add(&ls, MS / 2); /* 0.5 ms: bucket ≤ 1 */
	for (int i = 0; i < 9; i++)
		loopstat_add(&ls, 30 * MS); /* ≤ 50 */
	loopstat_add(&ls, 7200 * MS);	    /* the open bucket */
	assert_int_equal(ls.n, 1000);
	assert_int_equal(ls.b[0], 990);
	assert_int_equal(ls.b[5], 9);
	assert_int_equal(ls.b[LOOPSTAT_NB - 1], 1);
	assert_int_equal(ls.max_ns, 7200 * MS);
	assert_true(loopstat_quantile_ms(&ls, 0.99) == 1.0);
	assert_true(loopstat_quantile_ms(&ls, 0.995) == 50.0);
	assert_true(loopstat_quantile_ms(&ls, 1.0) == 7200.0);
	assert_int_equal(loopstat_over(&ls, 50), 1);
	assert_int_equal(loopstat_over(&ls, 20), 10);
	assert_int_equal(loopstat_over(&ls, 1), 10);
	/* A bound is inclusive: exactly 50 ms is not over 50 ms. */
	loopstat_add(&ls, 50 * MS);
	assert_int_equal(loopstat_over(&ls, 50), 1);
	assert_int_equal(loopstat_bound_ms(5), 50);
	assert_int_equal(loopstat_bound_ms(LOOPSTAT_NB - 1), 0);
}

/* Iterations over 50 ms told apart by the loop's own CPU and context switches. */
static void test_why(void **state)
{
	(void)state;
	struct loopstat ls = { 0 };
	loopstat_why(&ls, 10 * MS, 9 * MS, 3);	/* fast: not counted, its CPU is */
	loopstat_why(&ls, 80 * MS, 70 * MS, 0); /* its own work */
	loopstat_why(&ls, 80 * MS, 2 * MS, 1);	/* waited on something */
	loopstat_why(&ls, 60 * MS, 1 * MS, 0);	/* runnable, off the CPU */
	loopstat_why(&ls, 50 * MS, 1 * MS, 0);	/* exactly 50 ms is not over */
	assert_int_equal(ls.slow_work, 1);
	assert_int_equal(ls.slow_blocked, 1);
	assert_int_equal(ls.slow_preempted, 1);
	assert_int_equal(ls.cpu_max_ns, 70 * MS);
}

/* The quantile never claims more than the longest iteration seen. */
static void test_quantile_capped_by_max(void **state)
{
	(void)state;
	struct loopstat ls = { 0 };
	loopstat_add(&ls, 120 * MS); /* bucket ≤ 200 */
	assert_true(loopstat_quantile_ms(&ls, 0.99) == 120.0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_buckets),
		cmocka_unit_test(test_why),
		cmocka_unit_test(test_quantile_capped_by_max),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
