/* Placeholder replaced below by the real grid tests (same commit series). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include "grid.h"

static void level0(void **state)
{
	(void)state;
	struct tile_key k = { .lx = 1, .ly = 0, .x = 1, .y = 0 };
	struct geo_rect r;
	grid_tile_rect(&k, &r);
	assert_true(r.west == 0.0 && r.east == 180.0 && r.north == 90.0 && r.south == -90.0);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(level0) };
	return cmocka_run_group_tests_name("grid", tests, NULL, NULL);
}
