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
		cmocka_unit_test(test_quantile_capped_by_max),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
