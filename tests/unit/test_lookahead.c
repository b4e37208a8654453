/* lookahead: the tiles the server generates ahead of a moving viewer — none while it holds
 * still, the windows a viewer focused where it will be in 1, 2 and 4 s asks for on the
 * levels it shows (fine levels first: coarse windows move slowly), across the antimeridian,
 * over a pole, on the lx a viewer uses there (clipmap_level_lx), never one already wanted,
 * and a velocity from two foci when the client sends none (across a pole too). */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "common/clipmap.h"
#include "common/grid.h"
#include "daemon/lookahead.h"

#define R 6378137.0
#define T 256

/* What a viewer focused at (lon, lat) asks for at level ly, layer 0: its window (visible) on
 * the lx it uses there, then (ring) the tiles around it at class prefetch. */
static size_t block(struct proto_want_entry *w, int ly, double lon, double lat)
{
	struct grid_quad q;
	grid_window(clipmap_level_lx(ly, lat, -1), ly, T, CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
	struct tile_key k[GRID_WINDOW_MAX_KEYS];
	int nk = grid_quad_tiles(&q, 0, k);
	size_t n = 0;
	for (int i = 0; i < nk; i++)
		w[n++] = (struct proto_want_entry){ .layer = 0, .cls = PROTO_CLASS_VISIBLE,
						    .lx = k[i].lx, .ly = k[i].ly, .x = k[i].x,
						    .y = k[i].y };
	int64_t ny = grid_tiles_y(ly);
	for (int64_t y = (int64_t)q.ty0 - 1; y <= (int64_t)q.ty0 + q.nty; y++)
		for (int64_t x = (int64_t)q.tx0 - 1; x <= (int64_t)q.tx0 + q.ntx; x++) {
			struct tile_key r = { 0, grid_wrap_x(q.lx, x), (uint32_t)y, q.lx, q.ly };
			if (y >= 0 && y < ny && grid_quad_distance(&q, &r) == 1)
				w[n++] = (struct proto_want_entry){ .layer = 0,
								    .cls = PROTO_CLASS_PREFETCH,
								    .lx = r.lx, .ly = r.ly, .x = r.x,
								    .y = r.y };
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
	struct lookahead_motion m = { 7.5, 46.5, 0, 0, R, T };
	assert_int_equal(lookahead_wants(&m, w, n, out, 64), 0);
	m.ve = 1.0; /* 4 m in 4 s: no level-10 tile (39 km) is crossed */
	assert_int_equal(lookahead_wants(&m, w, n, out, 64), 0);
}

static void east_at_the_finest_level_first(void **state)
{
	(void)state;
	struct proto_want_entry w[128], out[256];
	size_t n4 = block(w, 4, 10, 0), n = n4;
	n += block(w + n, 12, 10, 0);
	/* a level-12 tile is 360° / 2^13 = 4.9 km wide at the equator: 6 km/s crosses ~1.2 of
	 * them in 1 s, 4.9 in 4 s; level 4's 1250 km tiles are not crossed */
	struct lookahead_motion m = { 10, 0, 6000, 0, R, T };
	size_t k = lookahead_wants(&m, w, n, out, 256);
	assert_true(k > 0);
	for (size_t i = 0; i < k; i++) {
		assert_int_equal(out[i].ly, 12);
		assert_int_equal(out[i].cls, PROTO_CLASS_BULK);
		assert_false(contains(w, n, out[i].ly, out[i].x, out[i].y)); /* never one wanted */
		for (size_t j = 0; j < i; j++) /* no duplicates */
			assert_false(out[j].x == out[i].x && out[j].y == out[i].y);
	}
	/* the window moved east: columns beyond its ring's east edge, the same rows */
	struct grid_quad q;
	grid_window(13, 12, T, CLIPMAP_WINDOW_TILES * T, 10, 0, &q);
	uint32_t east = q.tx0 + q.ntx - 1, row = q.ty0;
	assert_false(contains(out, k, 12, east + 1, row)); /* the ring: wanted already */
	assert_true(contains(out, k, 12, east + 2, row));
	assert_true(contains(out, k, 12, east + 5, row)); /* 4 s: ~5 tiles on */
	assert_false(contains(out, k, 12, q.tx0 - 2, row)); /* nothing behind it */
	/* 2 s's tiles come before 4 s's */
	size_t i2 = k, i4 = k;
	for (size_t i = 0; i < k; i++) {
		if (out[i].x == east + 2 && i2 == k)
			i2 = i;
		if (out[i].x == east + 5 && i4 == k)
			i4 = i;
	}
	assert_true(i2 < i4);
	/* the cap holds */
	assert_int_equal(lookahead_wants(&m, w, n, out, 3), 3);
}

static void across_the_antimeridian(void **state)
{
	(void)state;
	struct proto_want_entry w[64], out[256];
	size_t n = block(w, 8, 179.5, 0);
	struct lookahead_motion m = { 179.5, 0, 40000, 0, R, T }; /* east, over 180° */
	size_t k = lookahead_wants(&m, w, n, out, 256);
	assert_true(k > 0);
	bool wrapped = false;
	for (size_t i = 0; i < k; i++) {
		assert_true(out[i].x < 512u);
		wrapped |= out[i].x < 8; /* columns just east of -180° */
	}
	assert_true(wrapped);
}

/* Whether every entry's lx is one a viewer focused somewhere in [lat_lo, lat_hi] uses at its
 * level (what prefetch warms there). */
static bool lx_viewers_use(const struct proto_want_entry *o, size_t k, double lat_lo,
			   double lat_hi)
{
	for (size_t i = 0; i < k; i++) {
		int a, b;
		clipmap_level_lx_range(o[i].ly, lat_lo, lat_hi, &a, &b);
		if (o[i].lx < a || o[i].lx > b)
			return false;
	}
	return true;
}

/* Near a pole the lx of a level changes within a few hundred kilometres: a viewer leaving the
 * pole at 200 km/s will use finer ones, and the look-ahead asks for those (a tile of the lx
 * it has now, 800 km further, is one no viewer asks for: 492 such tiles were generated in a
 * flight over a prefetched route over the pole). And over the pole itself: the other side. */
static void on_the_lx_viewers_use_there_and_over_a_pole(void **state)
{
	(void)state;
	struct proto_want_entry w[512], out[1024];
	size_t n = 0;
	for (int ly = 5; ly <= 9; ly++)
		n += block(w + n, ly, 0, 89.5);
	struct lookahead_motion m = { 0, 89.5, 0, -200000, R, T }; /* south: 800 km in 4 s */
	size_t k = lookahead_wants(&m, w, n, out, 1024);
	assert_true(k > 0);
	assert_true(lx_viewers_use(out, k, 82, 89.5));
	bool finer = false;
	for (size_t i = 0; i < k; i++)
		finer |= out[i].ly == 7 && out[i].lx > clipmap_level_lx(7, 89.5, -1);
	assert_true(finer);
	/* north over the pole at 89.9°, 40 km/s: 1 s on, the focus is at 89.74°N on the other
	 * side (longitude 180°); nothing north of row 0 is invented */
	n = block(w, 8, 0, 89.9);
	m = (struct lookahead_motion){ 0, 89.9, 0, 40000, R, T };
	k = lookahead_wants(&m, w, n, out, 1024);
	assert_true(k > 0);
	for (size_t i = 0; i < k; i++)
		assert_true(out[i].y < 256u);
	assert_true(lx_viewers_use(out, k, 88.5, 90));
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
	/* over the north pole: from 89.9°N at 0° to 89.9°N at 180°, 0.2° of arc on, going south */
	assert_int_equal(lookahead_velocity(0, 89.9, 180, 89.9, 1.0, R, &ve, &vn), 0);
	assert_true(fabs(vn + 0.2 * M_PI / 180 * R) < 1e-3);
	assert_true(fabs(ve) < 1e-3);
	assert_int_equal(lookahead_velocity(0, 0, 1, 0, 0.0, R, &ve, &vn), -EINVAL);
	assert_int_equal(lookahead_velocity(0, 0, 1, 0, 60, R, &ve, &vn), -EINVAL);
	assert_int_equal(lookahead_velocity(NAN, 0, 1, 0, 1, R, &ve, &vn), -EINVAL);
}

/* Where the cache's foci ahead go (server.c update_foci): along the great circle, across the
 * antimeridian and over a pole; a still focus stays. */
static void point_ahead(void **state)
{
	(void)state;
	double lon, lat;
	struct lookahead_motion m = { .lon = 179.5, .lat = 0, .ve = 1000, .vn = 0, .radius = R };
	lookahead_point(&m, 2 * M_PI / 180 * R / 1000, &lon, &lat); /* 2° of arc east */
	assert_true(fabs(lon - (-178.5)) < 1e-6 && fabs(lat) < 1e-6);
	m = (struct lookahead_motion){ .lon = 30, .lat = 89, .ve = 0, .vn = 500, .radius = R };
	lookahead_point(&m, 2 * M_PI / 180 * R / 500, &lon, &lat); /* 2° north: over the pole */
	assert_true(fabs(lat - 89) < 1e-6);
	assert_true(fabs(fabs(lon) - 150) < 1e-6);
	m.vn = 0;
	lookahead_point(&m, 4, &lon, &lat);
	assert_true(lon == 30 && lat == 89);
	/* a velocity computed from two foci carries on from the second */
	double ve, vn;
	assert_int_equal(lookahead_velocity(10, 20, 10.1, 20.05, 0.5, R, &ve, &vn), 0);
	m = (struct lookahead_motion){ .lon = 10.1, .lat = 20.05, .ve = ve, .vn = vn, .radius = R };
	lookahead_point(&m, 0.5, &lon, &lat);
	assert_true(fabs(lon - 10.2) < 2e-3 && fabs(lat - 20.1) < 2e-3);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(still_adds_nothing),
		cmocka_unit_test(east_at_the_finest_level_first),
		cmocka_unit_test(across_the_antimeridian),
		cmocka_unit_test(on_the_lx_viewers_use_there_and_over_a_pole),
		cmocka_unit_test(velocity_from_two_foci),
		cmocka_unit_test(point_ahead),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
