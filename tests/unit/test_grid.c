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
	struct tile_key keys[GRID_WINDOW_MAX_KEYS];
	grid_quad(1, 0, 256, 0.0, 0.0, &q); /* level 0: the window is the whole height */
	assert_int_equal(q.u0, 128);
	assert_int_equal(q.v0, 0);
	assert_int_equal(q.tx0, 0);
	assert_int_equal(q.ntx, 2);
	assert_int_equal(q.ty0, 0);
	assert_int_equal(q.nty, 1);
	assert_int_equal(grid_quad_tiles(&q, 9, keys), 2);
	assert_int_equal(keys[1].x, 1);
	assert_true(keys[1].node == 9);

	grid_quad(2, 1, 256, 179.9, 10.0, &q); /* straddles the antimeridian */
	assert_int_equal(q.u0, 896);
	assert_int_equal(q.tx0, 3);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 4);
	assert_int_equal(keys[1].x, 0);
	grid_quad(2, 1, 256, -180.0, 10.0, &q);
	assert_int_equal(q.u0, 896);
	assert_int_equal(q.ntx, 2);

	grid_quad(2, 1, 256, 30.0, 89.99, &q); /* north pole: clamped, no wrap in y */
	assert_int_equal(q.v0, 0);
	assert_int_equal(q.ty0, 0);
	assert_int_equal(q.nty, 1);
	grid_quad(2, 1, 256, 30.0, -90.0, &q); /* south pole */
	assert_int_equal(q.v0, 256);
	assert_int_equal(q.ty0, 1);
	assert_int_equal(q.nty, 1);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 2);

	grid_quad(4, 3, 256, 10.0, 20.0, &q);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 4);
	/* every key of the window is distance 0, the ring 1 */
	for (int i = 0; i < 4; i++)
		assert_int_equal(grid_quad_distance(&q, &keys[i]), 0);
	struct tile_key far = keys[0];
	far.x = grid_wrap_x(4, (int64_t)q.tx0 + 2);
	assert_int_equal(grid_quad_distance(&q, &far), 1);
	far.x = grid_wrap_x(4, (int64_t)q.tx0 + 8);
	assert_int_equal(grid_quad_distance(&q, &far), 7);
	far.lx = 5;
	assert_int_equal(grid_quad_distance(&q, &far), UINT32_MAX);
	/* distance wraps the short way round the antimeridian */
	grid_quad(4, 3, 256, 179.0, 0.0, &q);
	struct tile_key w = { .lx = 4, .ly = 3, .x = 1, .y = q.ty0 };
	assert_int_equal(grid_quad_distance(&q, &w), 1);
}

/* Windows of 4×4 tiles: 5×5 tiles touched when unaligned, the whole level where it is smaller
 * than the window, clamped at the poles, wrapping at the antimeridian. */
static void windows(void **state)
{
	(void)state;
	const uint32_t T = 256, S = 4 * T;
	struct grid_quad q;
	struct tile_key keys[GRID_WINDOW_MAX_KEYS];
	grid_window(9, 8, T, S, 10.3, 20.7, &q);
	assert_int_equal(q.w, S);
	assert_int_equal(q.h, S);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 25);
	/* the focus is in the middle of the window */
	double fu = grid_lon_to_u(9, T, 10.3), fv = grid_lat_to_v(8, T, 20.7);
	assert_true(fabs(fu - (double)q.u0 - S / 2.0) <= 0.5);
	assert_true(fabs(fv - (double)q.v0 - S / 2.0) <= 0.5);
	for (int i = 0; i < 25; i++)
		assert_int_equal(grid_quad_distance(&q, &keys[i]), 0);
	struct tile_key k = keys[0];
	k.x = grid_wrap_x(9, (int64_t)q.tx0 - 1);
	assert_int_equal(grid_quad_distance(&q, &k), 1);
	k.x = grid_wrap_x(9, (int64_t)q.tx0 + 5);
	assert_int_equal(grid_quad_distance(&q, &k), 1);
	k.x = grid_wrap_x(9, (int64_t)q.tx0 + 7);
	assert_int_equal(grid_quad_distance(&q, &k), 3);

	/* level (1, 0): 512 × 256 texels, smaller than the window both ways: all of it */
	grid_window(1, 0, T, S, 123.0, -45.0, &q);
	assert_int_equal(q.u0, 0);
	assert_int_equal(q.v0, 0);
	assert_int_equal(q.w, 512);
	assert_int_equal(q.h, 256);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 2);
	/* level (2, 2): 1024 × 1024, exactly the window: all of it wherever the focus */
	grid_window(2, 2, T, S, -170.0, 80.0, &q);
	assert_int_equal(q.u0, 0);
	assert_int_equal(q.v0, 0);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 16);

	/* the south pole: clamped to the last four rows */
	grid_window(6, 5, T, S, 0.0, -89.9, &q);
	assert_int_equal(q.v0, (int64_t)(32 - 4) * T);
	assert_int_equal(q.nty, 4);
	/* the antimeridian: the columns wrap */
	grid_window(6, 5, T, S, 179.9, 0.3, &q);
	assert_int_equal(grid_quad_tiles(&q, 0, keys), 25);
	bool east = false, west = false;
	for (int i = 0; i < 25; i++) {
		east |= keys[i].x == 63;
		west |= keys[i].x == 0;
	}
	assert_true(east && west);
}

/* Replays moves through a simulated S×S toroidal texture holding, per texel, the level texel
 * (u, v) it was copied from, and checks the whole window after each move. */
struct sim {
	uint32_t T, S;
	int64_t *u, *v; /* what each texture texel holds; -1 = nothing */
	struct grid_quad cur;
	int have;
};

static void apply(struct sim *s, const struct grid_quad *next, int64_t *copied)
{
	struct grid_region r[GRID_MAX_REGIONS];
	int n = grid_update_regions(s->have ? &s->cur : NULL, next, r);
	assert_true(n >= 0 && n <= GRID_MAX_REGIONS);
	int64_t W = (int64_t)grid_tiles_x(next->lx) * s->T;
	uint32_t S = s->S;
	*copied = 0;
	for (int i = 0; i < n; i++) {
		assert_true(r[i].x + r[i].w <= S && r[i].y + r[i].h <= S);
		assert_true(r[i].sx + r[i].w <= s->T && r[i].sy + r[i].h <= s->T);
		for (uint32_t y = 0; y < r[i].h; y++)
			for (uint32_t x = 0; x < r[i].w; x++) {
				/* texel (sx + x, sy + y) of tile (tx, ty) is level texel
				 * (tx·T + sx + x, ty·T + sy + y) */
				size_t at = (size_t)(r[i].y + y) * S + r[i].x + x;
				s->u[at] = (int64_t)r[i].tx * s->T + r[i].sx + x;
				s->v[at] = (int64_t)r[i].ty * s->T + r[i].sy + y;
				(*copied)++;
			}
	}
	s->cur = *next;
	s->have = 1;
	/* the invariant: every window texel is in the texture at (u mod S, v mod S) */
	for (int64_t dv = 0; dv < next->h; dv++)
		for (int64_t du = 0; du < next->w; du++) {
			int64_t u = (next->u0 + du) % W, v = next->v0 + dv;
			size_t at = (size_t)((v % S) * S + (u % S));
			assert_int_equal(s->u[at], u);
			assert_int_equal(s->v[at], v);
		}
}

/* Texels the old and new windows share along one axis (w: the window's extent there; a
 * window as wide as the level W never moves). */
static int64_t overlap_1d(int64_t a, int64_t b, int64_t w, int64_t W)
{
	int64_t d = (b - a) % W;
	if (d > W / 2)
		d -= W;
	if (d < -W / 2)
		d += W;
	if (W <= w)
		d = 0;
	d = d < 0 ? -d : d;
	return d >= w ? 0 : w - d;
}

static void replay(struct sim *s, int lx, int ly)
{
	uint32_t T = s->T, S = s->S;
	int64_t W = (int64_t)grid_tiles_x(lx) * T;
	memset(s->u, 0xff, (size_t)S * S * sizeof *s->u);
	memset(s->v, 0xff, (size_t)S * S * sizeof *s->v);
	s->have = 0;
	double lon = -179.0, lat = 80.0;
	for (int step = 0; step < 300; step++) {
		/* mostly small moves, sometimes jumps; cross the antimeridian and poles */
		double scale = (rand() % 10 == 0) ? 90.0 : 360.0 / W * 3;
		lon += scale * ((rand() % 2001) / 1000.0 - 1.0);
		lat += scale * ((rand() % 2001) / 1000.0 - 1.0);
		if (lon >= 180) lon -= 360;
		if (lon < -180) lon += 360;
		if (lat > 90) lat = 90;
		if (lat < -90) lat = -90;
		struct grid_quad next, prev = s->cur;
		int had = s->have;
		grid_window(lx, ly, T, S, lon, lat, &next);
		int64_t copied;
		if (step % 3 == 1) {
			/* the viewer's partial level: the window's core first (half or a quarter
			 * of it, as view_clipmap_update), then the window grown from it */
			struct grid_quad core;
			grid_window_core(&next, S / (step % 2 ? 2 : 4), &core);
			assert_true(core.w <= next.w && core.h <= next.h);
			assert_true(core.v0 >= next.v0 && core.v0 + core.h <= next.v0 + next.h);
			apply(s, &core, &copied);
			apply(s, &next, &copied);
			assert_int_equal(copied, (int64_t)next.w * next.h -
							 (int64_t)core.w * core.h);
			continue;
		}
		apply(s, &next, &copied);
		int64_t all = (int64_t)next.w * next.h;
		if (had) {
			/* exactly the texels the old window lacked were copied */
			int64_t keep = overlap_1d(prev.u0, next.u0, next.w, W) *
				       overlap_1d(prev.v0, next.v0, next.h, (int64_t)1 << 62);
			assert_int_equal(copied, all - keep);
		} else {
			assert_int_equal(copied, all);
		}
	}
}

static void toroidal_updates(void **state)
{
	(void)state;
	const uint32_t T = 16;
	const int levels[][2] = { { 1, 0 }, { 3, 2 }, { 5, 4 }, { 2, 4 }, { 0, 3 }, { 7, 6 } };
	srand(11);
	for (uint32_t S = T; S <= 4 * T; S *= 4) {
		struct sim s = { .T = T, .S = S };
		s.u = malloc((size_t)S * S * sizeof *s.u);
		s.v = malloc((size_t)S * S * sizeof *s.v);
		for (size_t L = 0; L < sizeof levels / sizeof levels[0]; L++)
			replay(&s, levels[L][0], levels[L][1]);
		free(s.u);
		free(s.v);
	}
	/* an unchanged focus copies nothing; a one-texel diagonal move copies 2S-1 texels in
	 * a few regions (seed 003 Fig. 3b: at most 5 for the quad) */
	for (uint32_t S = T; S <= 4 * T; S *= 4) {
		struct grid_quad a, b;
		struct grid_region r[GRID_MAX_REGIONS];
		grid_window(7, 6, T, S, 10.0, 10.0, &a);
		assert_int_equal(grid_update_regions(&a, &a, r), 0);
		double dl = 360.0 / (128.0 * T), dp = 180.0 / (64.0 * T);
		grid_window(7, 6, T, S, 10.0 + dl, 10.0 - dp, &b);
		assert_int_equal(b.u0, a.u0 + 1);
		assert_int_equal(b.v0, a.v0 + 1);
		int n = grid_update_regions(&a, &b, r);
		assert_true(n >= 2 && n <= (S == T ? 5 : 12));
		uint32_t area = 0;
		for (int i = 0; i < n; i++)
			area += r[i].w * r[i].h;
		assert_int_equal(area, 2 * S - 1);
	}
}

/* A window's core: centred in it (the columns wrap), kept to a pole's edge with it, whole
 * where the level is no wider or taller than the core. */
static void cores(void **state)
{
	(void)state;
	const uint32_t T = 16, S = 4 * T;
	struct grid_quad q, c;
	grid_window(7, 6, T, S, 20.3, 0.2, &q);
	grid_window_core(&q, S / 2, &c);
	assert_int_equal(c.w, S / 2);
	assert_int_equal(c.u0, q.u0 + S / 4);
	assert_int_equal(c.v0, q.v0 + S / 4);
	assert_int_equal(c.ntx, (c.u0 % T + S / 2 + T - 1) / T);
	/* across the antimeridian: u wraps */
	grid_window(7, 6, T, S, 179.99, 10.0, &q);
	grid_window_core(&q, S / 4, &c);
	int64_t W = (int64_t)grid_tiles_x(7) * T;
	assert_int_equal(c.u0, (q.u0 + 3 * S / 8) % W);
	assert_true(c.tx0 < grid_tiles_x(7));
	/* at the north pole the window keeps to the level's first row; so does the core */
	grid_window(7, 6, T, S, 0.0, 89.9, &q);
	assert_int_equal(q.v0, 0);
	grid_window_core(&q, S / 2, &c);
	assert_int_equal(c.v0, 0);
	grid_window(7, 6, T, S, 0.0, -89.9, &q);
	grid_window_core(&q, S / 2, &c);
	assert_int_equal(c.v0 + c.h, (int64_t)grid_tiles_y(6) * T);
	/* a level narrower and lower than the core: the window itself */
	grid_window(1, 1, T, S, 0.0, 0.0, &q);
	grid_window_core(&q, S / 2, &c);
	assert_true(grid_quad_equal(&c, &q));
	/* a window of whole parallels (a polar level): the core keeps every column */
	grid_window(0, 3, T, S, 0.0, 60.0, &q);
	assert_int_equal(q.w, grid_tiles_x(0) * T);
	grid_window_core(&q, S / 2, &c);
	assert_int_equal(c.u0, q.u0);
	assert_int_equal(c.w, q.w);
	assert_int_equal(c.h, S / 2);
	/* windows of two extents are never equal */
	grid_window(7, 6, T, S, 20.3, 0.2, &q);
	c = q;
	c.w /= 2;
	assert_false(grid_quad_equal(&c, &q));
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
		cmocka_unit_test(windows),
		cmocka_unit_test(toroidal_updates), cmocka_unit_test(cores),
		cmocka_unit_test(key_hash),
	};
	return cmocka_run_group_tests_name("grid", tests, NULL, NULL);
}
