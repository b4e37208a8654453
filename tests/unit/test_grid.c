/* Tile grid tests: hand-worked cases (level 0, antimeridian, both poles, anisotropic steps)
 * and a toroidal simulation that replays focus moves through grid_update_regions and checks
 * every texel of the texture against the window it should hold. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "common/grid.h"

#define NEAR(a, b) assert_true(fabs((a) - (b)) < 1e-9)

static void tile_rects(void **state)
{
	(void)state;
	struct geo_rect r;
	struct tile_key k = { .lx = 1, .ly = 0, .x = 1, .y = 0 };
	grid_tile_rect(&k, &r);
	NEAR(r.west, 0); NEAR(r.east, 180); NEAR(r.north, 90); NEAR(r.south, -90);
	k = (struct tile_key){ .lx = 2, .ly = 1, .x = 3, .y = 1 };
	grid_tile_rect(&k, &r);
	NEAR(r.west, 90); NEAR(r.east, 180); NEAR(r.north, 0); NEAR(r.south, -90);
	/* anisotropic: 2 tiles across longitude, 4 down latitude */
	k = (struct tile_key){ .lx = 1, .ly = 2, .x = 0, .y = 0 };
	grid_tile_rect(&k, &r);
	NEAR(r.west, -180); NEAR(r.east, 0); NEAR(r.north, 90); NEAR(r.south, 45);
}

static void validity_and_wrap(void **state)
{
	(void)state;
	assert_true(grid_level_valid(1, 0));
	assert_true(grid_level_valid(0, 0));
	assert_true(grid_level_valid(3, 7));  /* wider longitude coverage: legal */
	assert_false(grid_level_valid(3, 1)); /* more tiles across than isotropic: illegal */
	assert_false(grid_level_valid(-1, 0));
	assert_false(grid_level_valid(GRID_MAX_LEVEL + 1, GRID_MAX_LEVEL + 1));
	struct tile_key k = { .lx = 1, .ly = 0, .x = 2, .y = 0 };
	assert_false(grid_key_valid(&k));
	k.x = 1;
	assert_true(grid_key_valid(&k));
	k.y = 1;
	assert_false(grid_key_valid(&k)); /* y does not wrap */
	assert_int_equal(grid_wrap_x(2, -1), 3);
	assert_int_equal(grid_wrap_x(2, 4), 0);
	assert_int_equal(grid_wrap_x(2, -9), 3);
	assert_int_equal(grid_wrap_x(0, 5), 0);
}

static void texel_centres(void **state)
{
	(void)state;
	struct tile_key k = { .lx = 1, .ly = 0, .x = 0, .y = 0 };
	double lon, lat;
	grid_texel_center(&k, 256, 0, 0, &lon, &lat);
	NEAR(lon, -180 + 0.5 * 180.0 / 256);
	NEAR(lat, 90 - 0.5 * 180.0 / 256);
	grid_texel_center(&k, 256, 255, 255, &lon, &lat);
	NEAR(lon, -0.5 * 180.0 / 256);
	NEAR(lat, -90 + 0.5 * 180.0 / 256);
	/* u/v ↔ lon/lat round trip, edges at integers */
	NEAR(grid_lon_to_u(3, 256, grid_u_to_lon(3, 256, 1234.25)), 1234.25);
	NEAR(grid_lat_to_v(2, 256, grid_v_to_lat(2, 256, 77.5)), 77.5);
	NEAR(grid_lon_to_u(1, 256, -180), 0);
	NEAR(grid_lat_to_v(0, 256, 90), 0);
	NEAR(grid_lat_to_v(0, 256, -90), 256);
}

/* A texel at (lx, ly) is exactly the 2×2 (isotropic) or 2×1/1×2 (anisotropic) texels under
 * it: its centre is the mean of their centres and its area their union. */
static void texel_nesting(void **state)
{
	(void)state;
	const uint32_t T = 8;
	const int steps[3][2] = { { 1, 1 }, { 1, 0 }, { 0, 1 } };
	srand(7);
	for (int it = 0; it < 300; it++) {
		int s = it % 3, dlx = steps[s][0], dly = steps[s][1];
		int ly = rand() % 10, lx = ly + 1 - rand() % 3;
		if (lx < 0)
			lx = 0;
		if (!grid_level_valid(lx + dlx, ly + dly))
			continue;
		struct tile_key k = { .lx = (uint8_t)lx, .ly = (uint8_t)ly };
		k.x = (uint32_t)rand() % grid_tiles_x(lx);
		k.y = (uint32_t)rand() % grid_tiles_y(ly);
		struct tile_key kids[4];
		int n = grid_children(&k, dlx, dly, kids);
		assert_int_equal(n, (1 + dlx) * (1 + dly));
		for (int c = 0; c < n; c++) {
			struct tile_key p;
			uint32_t ox, oy;
			assert_int_equal(grid_parent(&kids[c], dlx, dly, T, &p, &ox, &oy), 0);
			assert_true(grid_key_equal(&p, &k));
			/* child texel (i, j) lies in parent texel (ox + i>>dlx, oy + j>>dly) */
			for (uint32_t j = 0; j < T; j += 3) {
				for (uint32_t i = 0; i < T; i += 3) {
					double clon, clat, plon, plat;
					grid_texel_center(&kids[c], T, i, j, &clon, &clat);
					grid_texel_center(&p, T, ox + (i >> dlx), oy + (j >> dly), &plon, &plat);
					double hw = 180.0 / ((double)grid_tiles_x(p.lx) * T);
					double hh = 90.0 / ((double)grid_tiles_y(p.ly) * T);
					assert_true(fabs(clon - plon) < hw && fabs(clat - plat) < hh);
				}
			}
		}
		/* parent texel centre = mean of its children's texel centres */
		struct tile_key p;
		uint32_t ox, oy;
		grid_parent(&kids[0], dlx, dly, T, &p, &ox, &oy);
		double plon, plat, slon = 0, slat = 0;
		grid_texel_center(&p, T, ox, oy, &plon, &plat);
		for (uint32_t j = 0; j <= (uint32_t)dly; j++)
			for (uint32_t i = 0; i <= (uint32_t)dlx; i++) {
				double lon, lat;
				grid_texel_center(&kids[0], T, i, j, &lon, &lat);
				slon += lon;
				slat += lat;
			}
		NEAR(slon / n, plon);
		NEAR(slat / n, plat);
	}
	struct tile_key top = { .lx = 0, .ly = 0 }, out;
	assert_int_equal(grid_parent(&top, 1, 1, 8, &out, NULL, NULL), -22);
	struct tile_key lim = { .lx = GRID_MAX_LEVEL, .ly = GRID_MAX_LEVEL };
	struct tile_key kids[4];
	assert_int_equal(grid_children(&lim, 0, 1, kids), -22);
}

static void neighbours(void **state)
{
	(void)state;
	struct tile_key k = { .lx = 2, .ly = 1, .x = 0, .y = 0 }, n;
	bool flip;
	grid_neighbor(&k, -1, 0, &n, &flip); /* across the antimeridian */
	assert_int_equal(n.x, 3);
	assert_int_equal(n.y, 0);
	assert_false(flip);
	grid_neighbor(&k, 0, -1, &n, &flip); /* across the north pole */
	assert_int_equal(n.x, 2);
	assert_int_equal(n.y, 0);
	assert_true(flip);
	k.x = 3;
	k.y = 1;
	grid_neighbor(&k, 1, 1, &n, &flip); /* south pole corner */
	assert_int_equal(n.x, grid_wrap_x(2, 3 + 1 + 2));
	assert_int_equal(n.y, 1);
	assert_true(flip);
}

static void quads(void **state)
{
	(void)state;
	struct grid_quad q;
	struct tile_key keys[4];
	grid_quad(1, 0, 256, 0.0, 0.0, &q); /* level 0: the window is the whole height */
	assert_int_equal(q.u0, 128);
	assert_int_equal(q.v0, 0);
	assert_int_equal(q.tx[0], 0);
	assert_int_equal(q.tx[1], 1);
	assert_int_equal(q.ty[0], 0);
	assert_int_equal(q.ty[1], 0);
	assert_int_equal(grid_quad_tiles(&q, 9, keys), 2);
	assert_int_equal(keys[1].x, 1);
	assert_true(keys[1].node == 9);

	grid_quad(2, 1, 256, 179.9, 10.0, &q); /* straddles the antimeridian */
	assert_int_equal(q.u0, 896);
	assert_int_equal(q.tx[0], 3);
	assert_int_equal(q.tx[1], 0);
	grid_quad(2, 1, 256, -180.0, 10.0, &q);
	assert_int_equal(q.u0, 896);
	assert_int_equal(q.tx[1], 0);

	grid_quad(2, 1, 256, 30.0, 89.99, &q); /* north pole: clamped, no wrap in y */
	assert_int_equal(q.v0, 0);
	assert_int_equal(q.ty[0], 0);
	assert_int_equal(q.ty[1], 1);
	grid_quad(2, 1, 256, 30.0, -90.0, &q); /* south pole */
	assert_int_equal(q.v0, 256);
	assert_int_equal(q.ty[0], 1);
	assert_int_equal(q.ty[1], 1);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 2);

	grid_quad(4, 3, 256, 10.0, 20.0, &q);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 4);
	/* every key of the window is distance 0, the ring 1 */
	for (int i = 0; i < 4; i++)
		assert_int_equal(grid_quad_distance(&q, &keys[i]), 0);
	struct tile_key far = keys[0];
	far.x = grid_wrap_x(4, (int64_t)q.tx[1] + 1);
	assert_int_equal(grid_quad_distance(&q, &far), 1);
	far.x = grid_wrap_x(4, (int64_t)q.tx[0] + 8);
	assert_int_equal(grid_quad_distance(&q, &far), 7);
	far.lx = 5;
	assert_int_equal(grid_quad_distance(&q, &far), UINT32_MAX);
	/* distance wraps the short way round the antimeridian */
	grid_quad(4, 3, 256, 179.0, 0.0, &q);
	struct tile_key w = { .lx = 4, .ly = 3, .x = 1, .y = q.ty[0] };
	assert_int_equal(grid_quad_distance(&q, &w), 1);
}

/* Replays moves through a simulated T×T toroidal texture holding, per texel, the level texel
 * (u, v) it was copied from, and checks the whole window after each move. */
struct sim {
	uint32_t T;
	int64_t *u, *v; /* what each texture texel holds; -1 = nothing */
	struct grid_quad cur;
	int have;
};

static void apply(struct sim *s, const struct grid_quad *next, int64_t *copied)
{
	struct grid_region r[9];
	int n = grid_update_regions(s->have ? &s->cur : NULL, next, r);
	assert_true(n >= 0 && n <= 9);
	int64_t W = (int64_t)grid_tiles_x(next->lx) * s->T;
	*copied = 0;
	for (int i = 0; i < n; i++) {
		assert_true(r[i].x + r[i].w <= s->T && r[i].y + r[i].h <= s->T);
		uint32_t tx = next->tx[r[i].qi], ty = next->ty[r[i].qj];
		for (uint32_t y = r[i].y; y < r[i].y + r[i].h; y++)
			for (uint32_t x = r[i].x; x < r[i].x + r[i].w; x++) {
				/* texel (x, y) of tile (tx, ty) is level texel (tx·T + x, ty·T + y) */
				s->u[y * s->T + x] = (int64_t)tx * s->T + x;
				s->v[y * s->T + x] = (int64_t)ty * s->T + y;
				(*copied)++;
			}
	}
	s->cur = *next;
	s->have = 1;
	/* the invariant: every window texel is in the texture at (u mod T, v mod T) */
	for (int64_t dv = 0; dv < s->T; dv++)
		for (int64_t du = 0; du < s->T; du++) {
			int64_t u = (next->u0 + du) % W, v = next->v0 + dv;
			size_t at = (size_t)((v % s->T) * s->T + (u % s->T));
			assert_int_equal(s->u[at], u);
			assert_int_equal(s->v[at], v);
		}
}

static int64_t overlap_1d(int64_t a, int64_t b, int64_t T, int64_t W)
{
	int64_t d = (b - a) % W;
	if (d > W / 2)
		d -= W;
	if (d < -W / 2)
		d += W;
	if (W == T)
		d = 0;
	d = d < 0 ? -d : d;
	return d >= T ? 0 : T - d;
}

static void toroidal_updates(void **state)
{
	(void)state;
	const uint32_t T = 16;
	struct sim s = { .T = T };
	s.u = malloc(T * T * sizeof *s.u);
	s.v = malloc(T * T * sizeof *s.v);
	srand(11);
	const int levels[][2] = { { 1, 0 }, { 3, 2 }, { 5, 4 }, { 2, 4 }, { 0, 3 } };
	for (size_t L = 0; L < sizeof levels / sizeof levels[0]; L++) {
		int lx = levels[L][0], ly = levels[L][1];
		int64_t W = (int64_t)grid_tiles_x(lx) * T;
		memset(s.u, 0xff, T * T * sizeof *s.u);
		memset(s.v, 0xff, T * T * sizeof *s.v);
		s.have = 0;
		double lon = -179.0, lat = 80.0;
		for (int step = 0; step < 400; step++) {
			/* mostly small moves, sometimes jumps; cross the antimeridian and poles */
			double scale = (rand() % 10 == 0) ? 90.0 : 360.0 / W * 3;
			lon += scale * ((rand() % 2001) / 1000.0 - 1.0);
			lat += scale * ((rand() % 2001) / 1000.0 - 1.0);
			if (lon >= 180) lon -= 360;
			if (lon < -180) lon += 360;
			if (lat > 90) lat = 90;
			if (lat < -90) lat = -90;
			struct grid_quad next, prev = s.cur;
			int had = s.have;
			grid_quad(lx, ly, T, lon, lat, &next);
			int64_t copied;
			apply(&s, &next, &copied);
			if (had) {
				/* exactly the texels the old window lacked were copied */
				int64_t keep = overlap_1d(prev.u0, next.u0, T, W) *
					       overlap_1d(prev.v0, next.v0, T, (int64_t)1 << 62);
				assert_int_equal(copied, (int64_t)T * T - keep);
			} else {
				assert_int_equal(copied, (int64_t)T * T);
			}
		}
	}
	/* an unchanged focus copies nothing; a one-texel diagonal move copies 2T-1 texels in
	 * at most 5 regions (seed 003 Fig. 3b) */
	struct grid_quad a, b;
	struct grid_region r[9];
	grid_quad(5, 4, T, 10.0, 10.0, &a);
	assert_int_equal(grid_update_regions(&a, &a, r), 0);
	b = a;
	b.u0 += 1;
	b.v0 += 1;
	b.tx[0] = (uint32_t)(b.u0 / T);
	b.tx[1] = grid_wrap_x(5, b.tx[0] + 1);
	b.ty[0] = (uint32_t)(b.v0 / T);
	b.ty[1] = b.ty[0] + 1;
	int n = grid_update_regions(&a, &b, r);
	assert_true(n >= 2 && n <= 5);
	uint32_t area = 0;
	for (int i = 0; i < n; i++)
		area += r[i].w * r[i].h;
	assert_int_equal(area, 2 * T - 1);
	free(s.u);
	free(s.v);
}

static void key_hash(void **state)
{
	(void)state;
	struct tile_key a = { .node = 1, .lx = 3, .ly = 2, .x = 5, .y = 1 }, b = a;
	assert_true(grid_key_hash(&a) == grid_key_hash(&b));
	b.x = 4;
	assert_true(grid_key_hash(&a) != grid_key_hash(&b));
	b = a;
	b.node = 2;
	assert_true(grid_key_hash(&a) != grid_key_hash(&b));
	b = a;
	b.lx = 2;
	assert_false(grid_key_equal(&a, &b));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(tile_rects),	   cmocka_unit_test(validity_and_wrap),
		cmocka_unit_test(texel_centres),   cmocka_unit_test(texel_nesting),
		cmocka_unit_test(neighbours),	   cmocka_unit_test(quads),
		cmocka_unit_test(toroidal_updates), cmocka_unit_test(key_hash),
	};
	return cmocka_run_group_tests_name("grid", tests, NULL, NULL);
}
