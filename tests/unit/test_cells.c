/* test_cells — the `cells` node (a patchwork of Voronoi cells on the sphere) on an Earth-size
 * planet: cells of about the wavelength asked for, each one value in [0, 1); no seam at a tile
 * border or at the antimeridian (the columns either side agree as often as two columns inside a
 * tile do); borders of about the width asked for, −1 on the edge, drawn as faint as they are
 * narrow under a texel (the same darkness on average at every level); no aliased cells where
 * they are under 2 texels (½); pole rows independent of longitude; an optional input added; the
 * same bytes on every run and a different patchwork for another seed; clear errors.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/grid.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "support/node_ini.h"

#define T 256u
#define LAMBDA 450.0

static struct planet pl = { .a = 6378137 };

/* A cells node (seed 41 unless `extra` gives one, wavelength LAMBDA, then `extra`) into ni. */
static void cells_node(const char *extra, struct node_ini *ni)
{
	char text[512], err[256];
	snprintf(text, sizeof text, "[node c]\ntype = cells\n%swavelength = %g\n%s",
		 strstr(extra, "seed") ? "" : "seed = 41\n", LAMBDA, extra);
	if (node_ini_init(ni, &node_type_cells, &pl, text, NULL, 0, err))
		fail_msg("cells: %s", err);
	assert_int_equal(ni->n.out, PIX_HEIGHT);
}

/* Tile (lx, ly, x, y) of a cells node with parameters `extra`, into out[T·T]. */
static void make(const char *extra, int lx, int ly, uint32_t x, uint32_t y, float *out)
{
	struct node_ini ni;
	cells_node(extra, &ni);
	struct tile_key k = { .node = ni.n.hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x, .y = y };
	struct tile *t = tile_create(&k, PIX_HEIGHT, T);
	assert_int_equal(ni.n.type->generate(&ni.n, &ni.g, &k, NULL, 0, t), 0);
	memcpy(out, tile_f32(t), sizeof(float) * T * T);
	tile_unref(t);
	node_ini_fini(&ni);
}

/* Texel size of level ly, metres (latitude). */
static double texel_m(int ly)
{
	return M_PI * pl.a / (ldexp(1.0, ly) * T);
}

static void cells_and_values(void **state)
{
	(void)state;
	/* level (15, 14) near 46°N: texels 4.8 m (north–south) × 3.3 m, cells ~100 texels */
	int ly = 14, lx = 15;
	uint32_t y = (uint32_t)((90 - 46.0) / 180 * grid_tiles_y(ly)), x = 12345;
	float *a = malloc(sizeof(float) * T * T);
	make("jitter = 0.9\n", lx, ly, x, y, a);
	/* values in [0, 1); runs along rows: how long a cell is on average */
	int changes = 0;
	for (uint32_t j = 0; j < T; j++)
		for (uint32_t i = 0; i < T; i++) {
			float v = a[j * T + i];
			assert_true(v >= 0 && v < 1);
			if (i > 0 && v != a[j * T + i - 1])
				changes++;
		}
	/* chords of cells ~LAMBDA across, lon texels 4.8 · cos 46° = 3.3 m: a row of 256 texels
	 * (850 m) crosses an edge about twice */
	double row_m = T * 2 * M_PI * pl.a / (ldexp(1.0, lx) * T) * cos(46 * M_PI / 180);
	double per_row = (double)changes / T, expect = row_m / LAMBDA;
	print_message("edges per row %.2f, %.2f expected for cells of %.0f m\n", per_row, expect,
		      LAMBDA);
	assert_true(per_row > expect / 2.5 && per_row < expect * 2.5);
	free(a);
	/* the values' mean over many cells (a level where a tile holds ~1000): ~½ */
	float *b = malloc(sizeof(float) * T * T);
	make("", 11, 10, 700, 300, b);
	double m = 0;
	for (uint32_t i = 0; i < T * T; i++)
		m += b[i];
	m /= T * T;
	print_message("mean at level 10: %.3f\n", m);
	assert_true(m > 0.4 && m < 0.6);
	free(b);
}

/* How often two adjacent columns differ: inside tiles, and across a border (also across the
 * antimeridian). A seam would make the border's rate stand out. */
static double col_diff(const float *l, uint32_t li, const float *r, uint32_t ri)
{
	int d = 0;
	for (uint32_t j = 0; j < T; j++)
		d += l[j * T + li] != r[j * T + ri];
	return (double)d / T;
}

static void no_seams(void **state)
{
	(void)state;
	int ly = 12, lx = 13;
	uint32_t y = 1000, nx = grid_tiles_x(lx);
	float *a = malloc(sizeof(float) * T * T), *b = malloc(sizeof(float) * T * T);
	const char *p = "border = 8\n";
	double inside = 0, across = 0;
	for (int t = 0; t < 4; t++) {
		uint32_t x = 100 + 7u * (uint32_t)t;
		make(p, lx, ly, x, y, a);
		make(p, lx, ly, x + 1, y, b);
		across += col_diff(a, T - 1, b, 0);
		for (uint32_t i = 0; i + 1 < T; i += 51)
			inside += col_diff(a, i, a, i + 1) / 5;
	}
	make(p, lx, ly, nx - 1, y, a);
	make(p, lx, ly, 0, y, b);
	double anti = col_diff(a, T - 1, b, 0);
	print_message("adjacent columns differ: inside %.3f, across a border %.3f, the "
		      "antimeridian %.3f\n",
		      inside / 4, across / 4, anti);
	/* where they differ it is a cell's edge or border, a few per cent of the rows */
	assert_true(across / 4 < 3 * inside / 4 + 0.02);
	assert_true(anti < 3 * inside / 4 + 0.04);
	/* rows across a tile border (y and y + 1), against rows inside a tile */
	make(p, lx, ly, 100, y, a);
	make(p, lx, ly, 100, y + 1, b);
	int d = 0, din = 0;
	for (uint32_t i = 0; i < T; i++) {
		d += a[(T - 1) * T + i] != b[i];
		din += a[(T - 2) * T + i] != a[(T - 1) * T + i];
	}
	print_message("rows differ: inside a tile in %d of %u texels, across its border in %d\n",
		      din, T, d);
	assert_true(d < 3 * din + 0.02 * T);
	free(a);
	free(b);
}

/* Border texels' share: at texels narrower than the border the width drawn, at coarser ones
 * a texel wide and fainter — the mean darkness (what a coarse view averages) kept. */
static void borders(void **state)
{
	(void)state;
	float *a = malloc(sizeof(float) * T * T), *b = malloc(sizeof(float) * T * T);
	/* level 16: texels 1.2 m, border 8 m = 7 texels */
	make("border = 8\n", 17, 16, 40000, 20000, a);
	make("", 17, 16, 40000, 20000, b);
	int in_border = 0;
	float least = 1;
	double dark16 = 0;
	for (uint32_t i = 0; i < T * T; i++) {
		in_border += a[i] < b[i];
		least = fminf(least, a[i]);
		dark16 += b[i] - a[i];
		/* outside a border the cell's own value */
		assert_true(a[i] <= b[i]);
	}
	print_message("level 16: %.1f %% of texels in a border, least %.2f\n",
		      100.0 * in_border / (T * T), least);
	assert_true(least < -0.8f);
	/* 8 m strips round cells ~450 m: some 1–6 % of the area */
	assert_true(in_border > 0.005 * T * T && in_border < 0.1 * T * T);
	/* level 12: texels 19 m (wider than the border): a texel wide, at most 8/19 dark */
	make("border = 8\n", 13, 12, 2500, 1250, a);
	make("", 13, 12, 2500, 1250, b);
	float most = 0;
	double dark12 = 0;
	for (uint32_t i = 0; i < T * T; i++) {
		most = fmaxf(most, (b[i] - a[i]) / (b[i] + 1));
		dark12 += b[i] - a[i];
	}
	print_message("level 12: deepest border %.2f of the way to -1\n", most);
	assert_true(most <= 8 / texel_m(12) + 1e-3 && most > 0.3);
	/* the darkness per unit area: the same order at both levels (texel areas differ 256×) */
	double d16 = dark16 / (T * T), d12 = dark12 / (T * T);
	print_message("mean darkness: level 16 %.4f, level 12 %.4f\n", d16, d12);
	assert_true(d12 > d16 / 3 && d12 < d16 * 3);
	free(a);
	free(b);
}

static void band_limit_and_poles(void **state)
{
	(void)state;
	float *a = malloc(sizeof(float) * T * T), *b = malloc(sizeof(float) * T * T);
	/* level 8: texels 306 m, cells under 2 texels: ½ everywhere */
	make("border = 8\n", 9, 8, 100, 60, a);
	for (uint32_t i = 0; i < T * T; i++)
		assert_true(a[i] == 0.5f);
	/* level 9: texels 153 m (cells 3 texels: fading in): between, never beyond [-1, 1) */
	make("border = 8\n", 10, 9, 200, 120, a);
	float lo = 1, hi = 0;
	for (uint32_t i = 0; i < T * T; i++) {
		lo = fminf(lo, a[i]);
		hi = fmaxf(hi, a[i]);
	}
	print_message("level 9: %.3f .. %.3f\n", lo, hi);
	assert_true(lo >= -1 && hi < 1);
	/* the two rows nearest the north pole: one value across every tile of the level */
	int ly = 14, lx = 14;
	make("border = 8\n", lx, ly, 0, 0, a);
	make("border = 8\n", lx, ly, grid_tiles_x(lx) / 2 + 5, 0, b);
	for (uint32_t j = 0; j < 2; j++)
		for (uint32_t i = 0; i < T; i++) {
			assert_true(a[j * T + i] == a[0]);
			assert_true(b[j * T + i] == a[0]);
		}
	/* the south pole too */
	uint32_t ys = grid_tiles_y(ly) - 1;
	make("border = 8\n", lx, ly, 3, ys, a);
	make("border = 8\n", lx, ly, 9000, ys, b);
	for (uint32_t i = 0; i < T; i++)
		assert_true(a[(T - 1) * T + i] == a[(T - 1) * T] &&
			    b[(T - 1) * T + i] == a[(T - 1) * T]);
	free(a);
	free(b);
}

static void determinism_seed_input(void **state)
{
	(void)state;
	float *a = malloc(sizeof(float) * T * T), *b = malloc(sizeof(float) * T * T);
	make("border = 8\n", 15, 14, 777, 4000, a);
	make("border = 8\n", 15, 14, 777, 4000, b);
	assert_memory_equal(a, b, sizeof(float) * T * T);
	make("border = 8\nseed = 42\n", 15, 14, 777, 4000, b);
	int same = 0;
	for (uint32_t i = 0; i < T * T; i++)
		same += a[i] == b[i];
	assert_true(same < (int)(T * T / 4));
	/* amplitude and offset */
	make("amplitude = 10\noffset = 100\n", 15, 14, 777, 4000, a);
	make("", 15, 14, 777, 4000, b);
	for (uint32_t i = 0; i < T * T; i++)
		assert_true(fabsf(a[i] - (100 + 10 * b[i])) < 1e-4f);
	free(a);
	free(b);
}

/* The tile skips texels near the last one evaluated (within its slack): every texel as the
 * node evaluates it alone (cells_texel) instead, at the levels where the cells fade in, are
 * whole, and are hundreds of texels wide; with borders, without, and next to a pole. */
static void skipping_is_exact(void **state)
{
	(void)state;
	static const struct {
		int lx, ly;
		uint32_t x, y;
		const char *extra;
	} cases[] = {
		{ 10, 9, 300, 130, "border = 8\n" },	  /* fading in: 150 m texels */
		{ 13, 12, 2500, 1150, "border = 8\n" }, /* 19 m texels */
		{ 13, 12, 2500, 1150, "" },
		{ 15, 14, 9000, 4400, "border = 8\n" }, /* 4.8 m */
		{ 17, 16, 40000, 20000, "border = 8\n" }, /* 1.2 m: the border 7 texels */
		{ 14, 14, 77, 0, "border = 8\n" },	  /* the north pole's rows */
	};
	float *a = malloc(sizeof(float) * T * T);
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
		make(cases[c].extra, cases[c].lx, cases[c].ly, cases[c].x, cases[c].y, a);
		struct node_ini ni;
		cells_node(cases[c].extra, &ni);
		struct tile_key k = { .node = ni.n.hash, .lx = (uint8_t)cases[c].lx,
				      .ly = (uint8_t)cases[c].ly, .x = cases[c].x, .y = cases[c].y };
		int differ = 0, values = 0;
		for (uint32_t j = 0; j < T; j++)
			for (uint32_t i = 0; i < T; i++) {
				float v = cells_texel(&ni.n, &k, T, i, j);
				differ += memcmp(&v, &a[j * T + i], sizeof v) != 0;
				values += i > 0 && a[j * T + i] != a[j * T + i - 1];
			}
		node_ini_fini(&ni);
		print_message("level (%d, %d) %s: %d of %u texels differ from one evaluated alone "
			      "(%d changes along rows)\n",
			      cases[c].lx, cases[c].ly, cases[c].extra[0] ? "borders" : "no borders",
			      differ, T * T, values);
		assert_true(values > 0); /* the tile is not one value */
		assert_int_equal(differ, 0);
	}
	free(a);
}

static void errors(void **state)
{
	(void)state;
	char err[256];
	struct node_ini ni;
	assert_int_equal(node_ini_init(&ni, &node_type_cells, &pl,
				       "[node c]\ntype = cells\nwavelength = 100\nborder = 100\n",
				       NULL, 0, err),
			 -EINVAL);
	assert_non_null(strstr(err, "border"));
	assert_non_null(strstr(err, "not narrower than the cells"));
	node_ini_fini(&ni);
	assert_int_equal(node_ini_init(&ni, &node_type_cells, &pl,
				       "[node c]\ntype = cells\njitter = 1.5\n", NULL, 0, err),
			 -EINVAL);
	assert_non_null(strstr(err, "jitter"));
	node_ini_fini(&ni);
	assert_int_equal(node_ini_init(&ni, &node_type_cells, &pl,
				       "[node c]\ntype = cells\nwavelength = 0.5\n", NULL, 0, err),
			 -EINVAL);
	assert_non_null(strstr(err, "wavelength"));
	node_ini_fini(&ni);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(cells_and_values),
		cmocka_unit_test(no_seams),
		cmocka_unit_test(borders),
		cmocka_unit_test(band_limit_and_poles),
		cmocka_unit_test(determinism_seed_input),
		cmocka_unit_test(skipping_is_exact),
		cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
