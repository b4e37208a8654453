/* test_open_sea — the `open_sea` node on a synthetic 64 × 32 height raster (5.625° cells):
 * an ocean round a continent; in it a small closed basin below sea level (dry), a large one (a
 * sea of its own, above min_area) and ground far from any sea (no sea even where detail would
 * dip below sea level); a coast cell next to the ocean (the sea may reach it); a pocket below
 * sea level at the north pole that joins the ocean only across the pole (the sea); and the
 * errors a planet file can make. The whole world as one 64² tile of level (0, 0): texel i
 * is cell column i, texel row j lies a quarter of a cell from a cell row's centre.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdbool.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/grid.h"
#include "common/img.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "support/node_ini.h"

#define W 64
#define H 32

static char dir[] = "/tmp/test_open_sea.XXXXXX";
static char path[64];
static struct planet pl;

static void fill(float *h, int x0, int x1, int y0, int y1, float v)
{
	for (int y = y0; y <= y1; y++)
		for (int x = x0; x <= x1; x++)
			h[y * W + x] = v;
}

static int setup(void **state)
{
	(void)state;
	if (!mkdtemp(dir))
		return -1;
	snprintf(path, sizeof path, "%s/dem.tif", dir);
	static float h[W * H];
	fill(h, 0, W - 1, 0, H - 1, -1000); /* the ocean */
	fill(h, 10, 53, 4, 27, 100);	     /* a continent */
	fill(h, 14, 16, 8, 10, -50);	     /* a small closed basin: dry */
	fill(h, 25, 45, 8, 22, -50);	     /* a large one: a sea of its own */
	fill(h, 0, W - 1, 0, 2, 100);	     /* land round the north pole */
	fill(h, 2, 2, 0, 0, -50);	     /* a pocket at the pole … */
	fill(h, 34, 34, 0, 2, -50);	     /* … half a turn from a channel to the ocean */
	char err[256];
	if (img_write(path, W, H, 1, IMG_F32, h, err)) {
		fprintf(stderr, "%s\n", err);
		return -1;
	}
	pl.a = 6371000;
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	unlink(path);
	return rmdir(dir);
}

/* The node's mask over the whole world (a 64² tile), into out (owned by the caller). */
static void world(const char *extra, float *out)
{
	char text[512], err[256];
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\n%s", path, extra);
	struct node_ini ni;
	if (node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err))
		fail_msg("open_sea: %s", err);
	assert_int_equal(ni.n.out, PIX_HEIGHT);
	struct tile_key k = { .node = ni.n.hash, .lx = 0, .ly = 0 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, W);
	assert_int_equal(ni.n.type->generate(&ni.n, &ni.g, &k, NULL, 0, t), 0);
	memcpy(out, tile_f32(t), sizeof(float) * W * W);
	tile_unref(t);
	node_ini_fini(&ni);
}

/* The texel of cell (x, y): its column, the texel row a quarter cell north of its centre
 * (weights ¾ on row y, ¼ on row y − 1). */
static float cell(const float *m, int x, int y)
{
	return m[(2 * y) * W + x];
}

static void basins(void **state)
{
	(void)state;
	float *m = malloc(sizeof(float) * W * W);
	world("min_area = 10000000\n", m);
	assert_true(cell(m, 5, 15) == 1);   /* the ocean */
	assert_true(cell(m, 35, 15) == 1);  /* the large basin */
	assert_true(cell(m, 15, 9) == 0);   /* the small basin: dry */
	assert_true(cell(m, 50, 24) == 0);  /* inland, far from the sea */
	assert_true(cell(m, 10, 15) == 1);  /* the coast: land next to the ocean */
	assert_true(cell(m, 2, 1) == 1);    /* land next to the pole's pocket: the ocean's coast */
	for (int i = 0; i < W * W; i++)
		assert_true(m[i] >= 0 && m[i] <= 1);
	/* a larger min_area: the large basin is dry too */
	world("min_area = 1e9\n", m);
	assert_true(cell(m, 35, 15) == 0);
	assert_true(cell(m, 5, 15) == 1); /* the ocean is always a sea */
	/* sea_level: the raster's zero moved up 200 m: the continent (100 m) is sea floor */
	world("sea_level = 200\n", m);
	assert_true(cell(m, 50, 24) == 1);
	free(m);
}

/* The centre of cell (x, y): degrees. */
static double cell_lon(int x) { return -180 + (x + 0.5) * 360.0 / W; }
static double cell_lat(int y) { return 90 - (y + 0.5) * 180.0 / H; }

/* levels: the large basin's sea at its own surface (where a planet's sea_basins lays its sea),
 * within reach of its cells only; the ocean and everything else at sea level. */
static void levels(void **state)
{
	(void)state;
	char text[512], err[256];
	snprintf(text, sizeof text,
		 "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\nlevels = %g %g -28\n",
		 path, cell_lat(15), cell_lon(35));
	struct node_ini ni;
	if (node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err))
		fail_msg("open_sea: %s", err);
	double lev = 99;
	bool mixed = true;
	assert_true(open_sea_level(&ni.n, cell_lat(15), cell_lon(35), 0.1, &lev, &mixed));
	assert_true(lev == -28 && !mixed); /* in the basin, and only it */
	assert_true(open_sea_level(&ni.n, cell_lat(8), cell_lon(25), 0.1, &lev, NULL));
	assert_true(lev == -28); /* its corner cell */
	/* a cell beyond its edge: only within reach of it */
	assert_true(open_sea_level(&ni.n, cell_lat(15), cell_lon(47), 0.1, &lev, NULL));
	assert_true(lev == 0);
	assert_true(open_sea_level(&ni.n, cell_lat(15), cell_lon(47), 2 * 5.625, &lev, NULL));
	assert_true(lev == -28);
	/* a window that holds the basin and the ocean: mixed (no 1° lattice value serves both) */
	assert_true(open_sea_level(&ni.n, cell_lat(15), cell_lon(17), 9 * 5.625, &lev, &mixed));
	assert_true(lev == -28 && mixed);
	/* the ocean, the small dry basin: sea level */
	assert_true(open_sea_level(&ni.n, cell_lat(15), cell_lon(5), 0.1, &lev, NULL));
	assert_true(lev == 0);
	assert_true(open_sea_level(&ni.n, cell_lat(9), cell_lon(15), 0.1, &lev, NULL));
	assert_true(lev == 0);
	/* the mask is the same with or without levels */
	float *m = malloc(sizeof(float) * W * W);
	world("min_area = 10000000\n", m);
	struct tile_key k = { .node = ni.n.hash, .lx = 0, .ly = 0 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, W);
	assert_int_equal(ni.n.type->generate(&ni.n, &ni.g, &k, NULL, 0, t), 0);
	assert_memory_equal(tile_f32(t), m, sizeof(float) * W * W);
	tile_unref(t);
	free(m);
	node_ini_fini(&ni);
	/* not an open_sea node */
	assert_false(open_sea_level(NULL, 0, 0, 1, &lev, NULL));
	/* a point in no closed sea: the ocean, dry land, a basin under min_area; a bad list */
	double where[][2] = { { cell_lat(15), cell_lon(5) },
			      { cell_lat(24), cell_lon(50) },
			      { cell_lat(9), cell_lon(15) } };
	for (int i = 0; i < 3; i++) {
		char extra[128];
		snprintf(extra, sizeof extra, "levels = %g %g -28\n", where[i][0], where[i][1]);
		snprintf(text, sizeof text,
			 "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\n%s", path,
			 extra);
		assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err),
				 -EINVAL);
		assert_non_null(strstr(err, "levels"));
		assert_non_null(strstr(err, "no closed sea there"));
		node_ini_fini(&ni);
	}
	/* two points in one basin */
	snprintf(text, sizeof text,
		 "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\n"
		 "levels = %g %g -28, %g %g -20\n",
		 path, cell_lat(15), cell_lon(35), cell_lat(10), cell_lon(30));
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "in the same closed sea as a point before it"));
	node_ini_fini(&ni);
	/* a level the sea grid cannot hold */
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\nlevels = 1 2 -5000\n",
		 path);
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "within ±3000"));
	node_ini_fini(&ni);
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\nlevels = 1 2\n", path);
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "expected \"LAT LON LEVEL"));
	node_ini_fini(&ni);
}

/* A grid-registered raster (ETOPO5's layout: one row more, rows and columns centred on the
 * poles and on −180°): the levels' points and reach in its own cell centres. */
static void grid_registered(void **state)
{
	(void)state;
	enum { GH = H + 1 };
	static float h[W * GH];
	for (int i = 0; i < W * GH; i++)
		h[i] = -1000;
	for (int y = 4; y <= 28; y++)
		for (int x = 10; x <= 53; x++)
			h[y * W + x] = (x >= 25 && x <= 45 && y >= 8 && y <= 22) ? -50 : 100;
	char p2[80], text[512], err[256];
	snprintf(p2, sizeof p2, "%s/grid.tif", dir);
	assert_int_equal(img_write(p2, W, GH, 1, IMG_F32, h, err), 0);
	double step = 360.0 / W; /* 5.625° both ways */
#define GLAT(y) (90 - (y) * step)
#define GLON(x) (-180 + (x) * step)
	snprintf(text, sizeof text,
		 "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\nlevels = %g %g -28\n",
		 p2, GLAT(15), GLON(35));
	struct node_ini ni;
	if (node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err))
		fail_msg("open_sea: %s", err);
	double lev;
	bool mixed;
	assert_true(open_sea_level(&ni.n, GLAT(15), GLON(35), 0.1, &lev, &mixed));
	assert_true(lev == -28 && !mixed);
	assert_true(open_sea_level(&ni.n, GLAT(8), GLON(25), 0.1, &lev, NULL));
	assert_true(lev == -28); /* the basin's corner */
	assert_true(open_sea_level(&ni.n, GLAT(15), GLON(47), 0.1, &lev, NULL));
	assert_true(lev == 0); /* two cells beyond its edge */
	assert_true(open_sea_level(&ni.n, GLAT(15), GLON(47), 2 * step, &lev, NULL));
	assert_true(lev == -28);
	assert_true(open_sea_level(&ni.n, GLAT(15), GLON(5), 0.1, &lev, NULL));
	assert_true(lev == 0); /* the ocean */
	node_ini_fini(&ni);
	/* a point one cell off the basin, on its coast: no closed sea there */
	snprintf(text, sizeof text,
		 "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\nlevels = %g %g -28\n",
		 p2, GLAT(15), GLON(46));
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "no closed sea there"));
	node_ini_fini(&ni);
#undef GLAT
#undef GLON
	unlink(p2);
}

static void errors(void **state)
{
	(void)state;
	char err[256];
	struct node_ini ni;
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, "[node s]\ntype = open_sea\n",
				       NULL, 0, err),
			 -EINVAL);
	assert_non_null(strstr(err, "path: missing"));
	node_ini_fini(&ni);
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl,
				       "[node s]\ntype = open_sea\npath = /nonexistent.tif\n", NULL,
				       0, err),
			 -EINVAL);
	assert_non_null(strstr(err, "cannot open /nonexistent.tif"));
	node_ini_fini(&ni);
	/* not a global raster */
	char p2[80], text[256];
	snprintf(p2, sizeof p2, "%s/strip.tif", dir);
	static float h[W * 10];
	assert_int_equal(img_write(p2, W, 10, 1, IMG_F32, h, err), 0);
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\n", p2);
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "64 × 10: open_sea reads a global equirectangular raster"));
	node_ini_fini(&ni);
	unlink(p2);
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\nmin_area = -1\n", path);
	assert_int_equal(node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err), -EINVAL);
	assert_non_null(strstr(err, "min_area"));
	node_ini_fini(&ni);
}

/* Every tile of finer levels (isotropic and anisotropic, 16² texels) against the mask's
 * bilinear interpolation between cell centres, computed here from the cells: the world tile
 * above gives them (its texel rows lie a quarter cell from a cell row, ¾ of the weight on it,
 * and every cell is 0 or 1). Tiles whose cells all agree come out as the shared uniform tile
 * (mid-ocean, inland, across the antimeridian, at the poles); the others texel by texel. */
static void tiles_everywhere(void **state)
{
	(void)state;
	float *m = malloc(sizeof(float) * W * W);
	world("min_area = 10000000\n", m);
	static float cell01[H][W];
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++)
			cell01[y][x] = cell(m, x, y) > 0.5f ? 1.0f : 0.0f;
	free(m);
	char text[512], err[256];
	snprintf(text, sizeof text, "[node s]\ntype = open_sea\npath = %s\nmin_area = 10000000\n",
		 path);
	struct node_ini ni;
	if (node_ini_init(&ni, &node_type_open_sea, &pl, text, NULL, 0, err))
		fail_msg("open_sea: %s", err);
	enum { T = 16 };
	static const int lv[][2] = { { 1, 0 }, { 2, 1 }, { 4, 3 }, { 6, 5 }, { 7, 6 }, { 5, 5 },
				     { 4, 6 } };
	int uniform_at[4] = { 0 }; /* mid-ocean, inland, the antimeridian, a pole */
	for (size_t l = 0; l < sizeof lv / sizeof lv[0]; l++) {
		int nuni = 0, nmixed = 0;
		for (uint32_t ty = 0; ty < grid_tiles_y(lv[l][1]); ty++)
			for (uint32_t tx = 0; tx < grid_tiles_x(lv[l][0]); tx++) {
				struct tile_key k = { .node = ni.n.hash, .x = tx, .y = ty,
						      .lx = (uint8_t)lv[l][0], .ly = (uint8_t)lv[l][1] };
				struct tile *t = tile_create(&k, PIX_HEIGHT, T);
				assert_int_equal(ni.n.type->generate(&ni.n, &ni.g, &k, NULL, 0, t), 0);
				for (uint32_t j = 0; j < T; j++)
					for (uint32_t i = 0; i < T; i++) {
						double lon, lat;
						grid_texel_center(&k, T, i, j, &lon, &lat);
						double fx = (lon + 180) / 360 * W - 0.5;
						double fy = (90 - lat) / 180 * H - 0.5;
						fy = fy < 0 ? 0 : fy > H - 1 ? H - 1 : fy;
						int x0 = (int)floor(fx), y0 = (int)fy;
						int y1 = y0 + 1 < H ? y0 + 1 : y0;
						double ax = fx - x0, ay = fy - y0;
						int c0 = (x0 % W + W) % W, c1 = (c0 + 1) % W;
						double top = cell01[y0][c0] * (1 - ax) + cell01[y0][c1] * ax;
						double bot = cell01[y1][c0] * (1 - ax) + cell01[y1][c1] * ax;
						double want = top * (1 - ay) + bot * ay;
						float got = tile_f32(t)[j * T + i];
						if (fabs(got - want) > 1e-6)
							fail_msg("level (%d, %d) tile (%u, %u) texel (%u, %u)"
								 ": %g, want %g",
								 lv[l][0], lv[l][1], tx, ty, i, j, got, want);
					}
				if (t->uniform) {
					nuni++;
					float v = tile_f32(t)[0];
					uniform_at[0] += v == 1 && tx == grid_tiles_x(lv[l][0]) / 16;
					uniform_at[1] += v == 0;
					uniform_at[2] += tx == 0 || tx + 1 == grid_tiles_x(lv[l][0]);
					uniform_at[3] += ty == 0 || ty + 1 == grid_tiles_y(lv[l][1]);
				} else
					nmixed++;
				tile_unref(t);
			}
		/* the whole world in one or two tiles has coasts in each; finer levels have both */
		if (lv[l][0] >= 4)
			assert_true(nuni > 0 && nmixed > 0);
		else
			assert_int_equal(nuni, 0);
	}
	for (int i = 0; i < 4; i++)
		assert_true(uniform_at[i] > 0);
	node_ini_fini(&ni);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(basins),
		cmocka_unit_test(levels),
		cmocka_unit_test(grid_registered),
		cmocka_unit_test(errors),
		cmocka_unit_test(tiles_everywhere),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
