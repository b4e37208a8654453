/* lookahead: the tiles the server generates ahead of a moving viewer — none while it holds
 * still, the visible tiles moved by the whole tiles the focus crosses in 1, 2 and 4 s on the
 * levels it crosses, across the antimeridian, never past a pole, never one already wanted,
 * and a velocity from two foci when the client sends none. */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "daemon/lookahead.h"

#define R 6378137.0

/* The 4×4 visible block of (lx = ly + 1, ly) around (lon, lat), layer 0. */
static size_t block(struct proto_want_entry *w, int ly, double lon, double lat)
{
	int lx = ly + 1;
	double nx = ldexp(1, lx), ny = ldexp(1, ly);
	long cx = (long)floor((lon + 180) / 360 * nx), cy = (long)floor((90 - lat) / 180 * ny);
	size_t n = 0;
	for (long j = -2; j < 2; j++)
		for (long i = -2; i < 2; i++) {
			long y = cy + j;
			if (y < 0 || y >= ny)
				continue;
			w[n++] = (struct proto_want_entry){ .layer = 0, .cls = PROTO_CLASS_VISIBLE,
							    .lx = (uint8_t)lx, .ly = (uint8_t)ly,
							    .x = (uint32_t)(((cx + i) % (long)nx + (long)nx) % (long)nx),
							    .y = (uint32_t)y };
		}
	return n;
}

static bool contains(const struct proto_want_entry *w, size_t n, int ly, uint32_t x, uint32_t y)
{
	for (size_t i = 0; i < n; i++)
		if (w[i].ly == ly && w[i].x == x && w[i].y == y)
			return true;
	return false;
}

static void still_adds_nothing(void **state)
{
	(void)state;
	struct proto_want_entry w[64], out[64];
	size_t n = block(w, 10, 7.5, 46.5);
	struct lookahead_motion m = { 7.5, 46.5, 0, 0, R };
	assert_int_equal(lookahead_wants(&m, w, n, out, 64), 0);
	m.ve = 1.0; /* 4 m in 4 s: no level-10 tile (39 km) is crossed */
	assert_int_equal(lookahead_wants(&m, w, n, out, 64), 0);
}

static void east_at_the_finest_level_first(void **state)
{
	(void)state;
	struct proto_want_entry w[128], out[256];
	size_t n = block(w, 4, 10, 0) + 0;
	n += block(w + n, 12, 10, 0);
	/* a level-12 tile is 360° / 2^13 = 4.9 km wide at the equator: 6 km/s crosses ~1.2 of
	 * them in 1 s, 4.9 in 4 s; level 4's 1250 km tiles are not crossed */
	struct lookahead_motion m = { 10, 0, 6000, 0, R };
	size_t k = lookahead_wants(&m, w, n, out, 256);
	assert_true(k > 0);
	for (size_t i = 0; i < k; i++) {
		assert_int_equal(out[i].ly, 12);
		assert_int_equal(out[i].cls, PROTO_CLASS_BULK);
		assert_false(contains(w, n, out[i].ly, out[i].x, out[i].y)); /* never one wanted */
		for (size_t j = 0; j < i; j++) /* no duplicates */
			assert_false(out[j].x == out[i].x && out[j].y == out[i].y);
	}
	/* the block moved east: columns beyond its east edge, the same rows */
	uint32_t east = w[n - 1].x; /* the block's last column (row-major, east last) */
	assert_true(contains(out, k, 12, east + 1, w[n - 1].y));
	assert_true(contains(out, k, 12, east + 5, w[n - 1].y)); /* 4 s: ~5 tiles on */
	assert_false(contains(out, k, 12, w[4].x - 1, w[4].y)); /* nothing behind it */
	/* 1 s's tiles come before 4 s's */
	size_t i1 = k, i4 = k;
	for (size_t i = 0; i < k; i++) {
		if (out[i].x == east + 1 && i1 == k)
			i1 = i;
		if (out[i].x == east + 5 && i4 == k)
			i4 = i;
	}
	assert_true(i1 < i4);
	/* the cap holds */
	assert_int_equal(lookahead_wants(&m, w, n, out, 3), 3);
}

static void across_the_antimeridian_not_past_a_pole(void **state)
{
	(void)state;
	struct proto_want_entry w[64], out[256];
	size_t n = block(w, 8, 179.5, 0);
	struct lookahead_motion m = { 179.5, 0, 40000, 0, R }; /* east, over 180° */
	size_t k = lookahead_wants(&m, w, n, out, 256);
	assert_true(k > 0);
	bool wrapped = false;
	for (size_t i = 0; i < k; i++) {
		assert_true(out[i].x < 512u);
		wrapped |= out[i].x < 8; /* columns just east of -180° */
	}
	assert_true(wrapped);
	/* north over the pole at 89.9°: rows north of row 0 are not invented */
	n = block(w, 8, 0, 89.9);
	m = (struct lookahead_motion){ 0, 89.9, 0, 40000, R };
	k = lookahead_wants(&m, w, n, out, 256);
	for (size_t i = 0; i < k; i++)
		assert_true(out[i].y < 256u);
}

static void velocity_from_two_foci(void **state)
{
	(void)state;
	double ve, vn;
	assert_int_equal(lookahead_velocity(179.9, 0, -179.9, 0, 1.0, R, &ve, &vn), 0);
	assert_true(fabs(ve - 0.2 * M_PI / 180 * R) < 1e-3); /* 22 km east, not 40 000 km west */
	assert_true(fabs(vn) < 1e-9);
	assert_int_equal(lookahead_velocity(0, 10, 0, 10.1, 0.5, R, &ve, &vn), 0);
	assert_true(fabs(vn - 0.1 * M_PI / 180 * R / 0.5) < 1e-3);
	assert_int_equal(lookahead_velocity(0, 0, 1, 0, 0.0, R, &ve, &vn), -EINVAL);
	assert_int_equal(lookahead_velocity(0, 0, 1, 0, 60, R, &ve, &vn), -EINVAL);
	assert_int_equal(lookahead_velocity(NAN, 0, 1, 0, 1, R, &ve, &vn), -EINVAL);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(still_adds_nothing),
		cmocka_unit_test(east_at_the_finest_level_first),
		cmocka_unit_test(across_the_antimeridian_not_past_a_pole),
		cmocka_unit_test(velocity_from_two_foci),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
