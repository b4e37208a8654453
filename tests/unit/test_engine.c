/* End-to-end engine tests on the shipped procedural planet: every layer through the real
 * graph, cache and scheduler. Seams between neighbouring tiles (east–west, across the
 * antimeridian, across both poles), parent against its children, and determinism whatever
 * the number of workers. Runs from the repository root (tests/run.sh does). */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define PLANET "conf/planets/procedural.ini"

struct env {
	struct planet *p;
	struct cache *c;
	struct sched *s;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	char err[256];
	if (planet_load(PLANET, &e->p, err)) {
		fprintf(stderr, "%s\n", err);
		return -1;
	}
	e->c = cache_create(512u << 20);
	e->s = sched_create(&(struct sched_desc){ .cache = e->c, .workers = 2 });
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	sched_destroy(e->s);
	cache_destroy(e->c);
	planet_unref(e->p);
	free(e);
	return 0;
}

static struct tile *fetch(struct sched *s, const struct planet *p, const char *layer, int lx, int ly,
			  uint32_t x, uint32_t y)
{
	const struct planet_layer *L = planet_find_layer(p, layer);
	assert_non_null(L);
	struct want w = { .node = L->node, .cls = SCHED_VISIBLE,
			  .key = { .node = L->node->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly,
				   .x = x, .y = y } };
	struct tile *t = NULL;
	assert_int_equal(sched_fetch(s, &w, 1, &t), 0);
	assert_non_null(t);
	return t;
}

static double hget(const struct tile *t, uint32_t i, uint32_t j)
{
	return tile_f32(t)[(size_t)j * t->size + i];
}

/* Largest step between neighbouring texels along x inside a tile, near column c. */
static double interior_step_x(const struct tile *t, uint32_t c)
{
	double m = 0;
	for (uint32_t j = 0; j < t->size; j++) {
		double d = fabs(hget(t, c + 1, j) - hget(t, c, j));
		if (d > m)
			m = d;
	}
	return m;
}

/* West tile's last column against east tile's first: the step across the border is no
 * larger than steps inside the tiles (a seam would be a jump). */
static void check_ew(const struct tile *w, const struct tile *e)
{
	uint32_t T = w->size;
	double inner = fmax(interior_step_x(w, T - 2), interior_step_x(e, 0));
	double worst = 0;
	for (uint32_t j = 0; j < T; j++) {
		double d = fabs(hget(e, 0, j) - hget(w, T - 1, j));
		if (d > worst)
			worst = d;
	}
	if (!(worst <= 2.0 * inner + 1e-3))
		fail_msg("border step %.3f m vs interior step %.3f m", worst, inner);
}

static void heights_seamless(void **state)
{
	struct env *e = *state;
	const int levels[][2] = { { 4, 3 }, { 9, 8 }, { 15, 14 }, { 21, 20 } };
	for (size_t l = 0; l < 4; l++) {
		int lx = levels[l][0], ly = levels[l][1];
		uint32_t nx = grid_tiles_x(lx), ny = grid_tiles_y(ly);
		uint32_t x = nx / 3, y = ny / 2 - 1;
		struct tile *a = fetch(e->s, e->p, "height", lx, ly, x, y);
		struct tile *b = fetch(e->s, e->p, "height", lx, ly, x + 1, y);
		check_ew(a, b);
		tile_unref(a);
		tile_unref(b);
		/* across the antimeridian */
		a = fetch(e->s, e->p, "height", lx, ly, nx - 1, y);
		b = fetch(e->s, e->p, "height", lx, ly, 0, y);
		check_ew(a, b);
		tile_unref(a);
		tile_unref(b);
		/* across each pole: row 0 (or T-1) against the same row half a globe away, whose
		 * texel centres lie one texel apart over the pole */
		for (int pole = 0; pole < 2; pole++) {
			uint32_t py = pole ? ny - 1 : 0;
			a = fetch(e->s, e->p, "height", lx, ly, 0, py);
			b = fetch(e->s, e->p, "height", lx, ly, nx / 2, py);
			uint32_t T = a->size, r = pole ? T - 1 : 0;
			double inner = 0, worst = 0;
			/* Near the pole a fine tile's row spans a tiny arc, so its texels sample
			 * nearly one meridian: take the interior steps along 16 rows of it. */
			for (uint32_t i = 0; i < T; i++) {
				for (uint32_t s = 0; s < 16; s++) {
					uint32_t r1 = pole ? T - 1 - s : s, r2 = pole ? r1 - 1 : r1 + 1;
					inner = fmax(inner, fabs(hget(a, i, r1) - hget(a, i, r2)));
					inner = fmax(inner, fabs(hget(b, i, r1) - hget(b, i, r2)));
				}
				worst = fmax(worst, fabs(hget(a, i, r) - hget(b, i, r)));
			}
			if (!(worst <= 2.0 * inner + 1e-3))
				fail_msg("pole %d level %d: step over the pole %.3f m vs %.3f m", pole,
					 ly, worst, inner);
			tile_unref(a);
			tile_unref(b);
		}
	}
}

static void normals_and_colour_seamless(void **state)
{
	struct env *e = *state;
	const int lx = 9, ly = 8;
	uint32_t nx = grid_tiles_x(lx);
	for (int pass = 0; pass < 2; pass++) {
		uint32_t x = pass ? nx - 1 : 100, y = 70;
		struct tile *a = fetch(e->s, e->p, "normal", lx, ly, x, y);
		struct tile *b = fetch(e->s, e->p, "normal", lx, ly, grid_wrap_x(lx, x + 1), y);
		uint32_t T = a->size;
		/* the border step of each component is like the steps inside */
		int inner = 0, worst = 0;
		for (uint32_t j = 0; j < T; j++)
			for (int c = 0; c < 2; c++) {
				int wl = a->data[2 * ((size_t)j * T + T - 1) + c];
				int wl2 = a->data[2 * ((size_t)j * T + T - 2) + c];
				int ef = b->data[2 * ((size_t)j * T) + c];
				int ef2 = b->data[2 * ((size_t)j * T + 1) + c];
				inner = abs(wl - wl2) > inner ? abs(wl - wl2) : inner;
				inner = abs(ef2 - ef) > inner ? abs(ef2 - ef) : inner;
				worst = abs(ef - wl) > worst ? abs(ef - wl) : worst;
			}
		if (worst > 2 * inner + 2)
			fail_msg("normal seam: %d vs interior %d", worst, inner);
		tile_unref(a);
		tile_unref(b);
		a = fetch(e->s, e->p, "color", lx, ly, x, y);
		b = fetch(e->s, e->p, "color", lx, ly, grid_wrap_x(lx, x + 1), y);
		inner = worst = 0;
		for (uint32_t j = 0; j < T; j++)
			for (int c = 0; c < 3; c++) {
				int wl = a->data[4 * ((size_t)j * T + T - 1) + c];
				int wl2 = a->data[4 * ((size_t)j * T + T - 2) + c];
				int ef = b->data[4 * ((size_t)j * T) + c];
				int ef2 = b->data[4 * ((size_t)j * T + 1) + c];
				inner = abs(wl - wl2) > inner ? abs(wl - wl2) : inner;
				inner = abs(ef2 - ef) > inner ? abs(ef2 - ef) : inner;
				worst = abs(ef - wl) > worst ? abs(ef - wl) : worst;
			}
		if (worst > 2 * inner + 2)
			fail_msg("colour seam: %d vs interior %d", worst, inner);
		tile_unref(a);
		tile_unref(b);
	}
}

/* A parent texel is the area of its 2×2 children: the parent's heights match the children's
 * 2×2 means up to the detail the parent's band limit leaves out. */
static void parent_matches_children(void **state)
{
	struct env *e = *state;
	const int levels[][2] = { { 3, 2 }, { 8, 7 }, { 13, 12 }, { 19, 18 } };
	for (size_t l = 0; l < 4; l++) {
		int lx = levels[l][0], ly = levels[l][1];
		struct tile_key pk = { .lx = (uint8_t)lx, .ly = (uint8_t)ly,
				       .x = grid_tiles_x(lx) / 5, .y = grid_tiles_y(ly) / 3 };
		struct tile *par = fetch(e->s, e->p, "height", lx, ly, pk.x, pk.y);
		struct tile_key kids[4];
		assert_int_equal(grid_children(&pk, 1, 1, kids), 4);
		uint32_t T = par->size;
		double se = 0, mean = 0, var = 0;
		for (int c = 0; c < 4; c++) {
			struct tile *k = fetch(e->s, e->p, "height", kids[c].lx, kids[c].ly, kids[c].x,
					       kids[c].y);
			uint32_t ox, oy;
			struct tile_key chk;
			grid_parent(&kids[c], 1, 1, T, &chk, &ox, &oy);
			for (uint32_t j = 0; j < T / 2; j++)
				for (uint32_t i = 0; i < T / 2; i++) {
					double m = (hget(k, 2 * i, 2 * j) + hget(k, 2 * i + 1, 2 * j) +
						    hget(k, 2 * i, 2 * j + 1) +
						    hget(k, 2 * i + 1, 2 * j + 1)) / 4;
					double pv = hget(par, ox + i, oy + j);
					se += (pv - m) * (pv - m);
					mean += pv;
					var += pv * pv;
				}
			tile_unref(k);
		}
		double n = (double)T * T;
		mean /= n;
		double sd = sqrt(var / n - mean * mean), rms = sqrt(se / n);
		/* the left-out detail is a small part of the tile's own variation */
		if (!(rms <= 0.05 * sd + 0.05))
			fail_msg("level %d: parent vs children RMS %.3f m, tile sd %.3f m", ly, rms, sd);
		tile_unref(par);
	}
}

static void deterministic_across_workers(void **state)
{
	struct env *e = *state;
	struct cache *c1 = cache_create(256u << 20);
	struct sched *s1 = sched_create(&(struct sched_desc){ .cache = c1, .workers = 1 });
	const char *layers[] = { "height", "color", "normal" };
	for (int l = 0; l < 3; l++) {
		for (int k = 0; k < 6; k++) {
			int ly = 2 + 3 * k, lx = ly + 1;
			uint32_t x = (uint32_t)(k * 7919) % grid_tiles_x(lx);
			uint32_t y = (uint32_t)(k * 104729) % grid_tiles_y(ly);
			struct tile *a = fetch(e->s, e->p, layers[l], lx, ly, x, y);
			struct tile *b = fetch(s1, e->p, layers[l], lx, ly, x, y);
			assert_int_equal(a->nbytes, b->nbytes);
			assert_memory_equal(a->data, b->data, a->nbytes);
			tile_unref(a);
			tile_unref(b);
		}
	}
	sched_destroy(s1);
	cache_destroy(c1);
}

/* The planet looks like a planet: oceans and land in sensible shares, mountains but no
 * absurd heights, snow and ice near the poles. */
static void planet_is_plausible(void **state)
{
	struct env *e = *state;
	size_t land = 0, total = 0;
	double hmin = 1e9, hmax = -1e9;
	for (uint32_t y = 0; y < 4; y++)
		for (uint32_t x = 0; x < 8; x++) {
			struct tile *t = fetch(e->s, e->p, "height", 3, 2, x, y);
			for (size_t i = 0; i < (size_t)t->size * t->size; i++) {
				float h = tile_f32(t)[i];
				land += h > 0;
				total++;
				hmin = fmin(hmin, h);
				hmax = fmax(hmax, h);
			}
			tile_unref(t);
		}
	double share = (double)land / total;
	if (share < 0.15 || share > 0.6)
		fail_msg("land covers %.0f %% of the map", 100 * share);
	assert_true(hmax > 3000 && hmax < 12000);
	assert_true(hmin < -2000 && hmin > -12000);
	/* top row of the northernmost tiles: ice, i.e. near-white */
	struct tile *t = fetch(e->s, e->p, "color", 3, 2, 3, 0);
	const unsigned char *px = t->data;
	assert_true(px[0] > 200 && px[1] > 200 && px[2] > 200);
	tile_unref(t);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(heights_seamless),
		cmocka_unit_test(normals_and_colour_seamless),
		cmocka_unit_test(parent_matches_children),
		cmocka_unit_test(deterministic_across_workers),
		cmocka_unit_test(planet_is_plausible),
	};
	return cmocka_run_group_tests_name("engine", tests, setup, teardown);
}
