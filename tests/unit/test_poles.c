/* test_poles — the shipped planets made from raster files (conf/planets/earth.ini, moon.ini,
 * mars.ini on the data `make data` installs) at their poles: for the tiles touching each pole
 * at isotropic levels and at the anisotropic levels (lx = ly, ly − 1, … 0) the viewer asks for
 * near the poles, down to ly 19, the texels of the row nearest the pole may vary with
 * longitude by no more than the source itself varies over that latitude band (its level-0
 * pixels, read independently through the image cache). Every file node of the three planets
 * (ETOPO5 heights, Blue Marble, the Moon's and Mars's colour) goes through node generate()
 * directly; skipped with a message when data/ is missing, as test_earth is. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/ctl/render.h"
#include "common/grid.h"
#include "common/img.h"
#include "engine/node.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "engine/nodes/file_resample.h"

/* A file node of a shipped planet and what the test needs to know of its source. */
struct pole_case {
	const char *planet, *node, *image;
	double north, south; /* the image's bounds (as clipmapctl import recorded them) */
	int channels;	     /* compared: 1 (heights, metres) or 3 (colour, 0..255) */
};

static const struct pole_case cases[] = {
	{ "conf/planets/earth.ini", "etopo", "data/earth/etopo5.tif", 90 + 1.0 / 24,
	  -90 - 1.0 / 24, 1 },
	{ "conf/planets/earth.ini", "bluemarble", "data/earth/bluemarble.tif", 90, -90, 3 },
	{ "conf/planets/moon.ini", "albedo", "data/moon/moon.tif", 90, -90, 3 },
	{ "conf/planets/mars.ini", "albedo", "data/mars/mars.tif", 90, -90, 3 },
};

/* The source's range per channel over latitudes [lat_a, lat_b] (a band touching a pole) and
 * every longitude: level-0 pixels, bilinear in latitude between row centres. An image whose
 * last row is an area ending at the pole (its centre short of it) means, between that centre
 * and the pole, a blend towards the row's mean: the wedges of the row meet at the pole, the
 * one point they share. (The node's cap, pole_taps, is a smoother blend of the same scale: a
 * reference for how much a pole row may vary, not for its values.) Extremes lie at the
 * band's ends or on row centres inside it, on some column. */
static void source_range(struct img_cache *ic, const struct pole_case *pc, double lat_a,
			 double lat_b, double lo[3], double hi[3])
{
	struct img_info info;
	char err[256];
	if (img_cache_info(ic, pc->image, &info, err))
		fail_msg("%s", err);
	int W = info.width, H = info.height, C = pc->channels;
	double rpd = H / (pc->north - pc->south);
	/* Row coordinates s (row i's centre at s = i) of the band and of the pole it touches. */
	double sa = (pc->north - lat_b) * rpd - 0.5, sb = (pc->north - lat_a) * rpd - 0.5;
	bool south = lat_a < 0;
	double sp = (pc->north - (south ? -90 : 90)) * rpd - 0.5;
	int edge = south ? H - 1 : 0; /* the row nearest the pole */
	bool virt = south ? sp > edge + 1e-6 : sp < -1e-6;
	int r0 = (int)floor(sa), r1 = (int)ceil(sb);
	r0 = r0 < 0 ? 0 : r0 > H - 1 ? H - 1 : r0;
	r1 = r1 < 0 ? 0 : r1 > H - 1 ? H - 1 : r1;
	int nr = r1 - r0 + 1;
	/* Colour as stored (u8: F32 would normalise it to 0..1), heights as float. */
	size_t np = (size_t)nr * W * C;
	float *px = malloc(np * sizeof *px);
	assert_non_null(px);
	if (C == 1) {
		if (img_cache_read(ic, pc->image, 0, 0, W, r0, r1 + 1, 0, C, IMG_F32, px, 0, err))
			fail_msg("%s", err);
	} else {
		uint8_t *u = malloc(np);
		assert_non_null(u);
		if (img_cache_read(ic, pc->image, 0, 0, W, r0, r1 + 1, 0, C, IMG_U8, u, 0, err))
			fail_msg("%s", err);
		for (size_t i = 0; i < np; i++)
			px[i] = u[i];
		free(u);
	}
	assert_true(edge >= r0 && edge <= r1);
	double mean[3] = { 0, 0, 0 };
	for (int x = 0; x < W; x++)
		for (int c = 0; c < C; c++)
			mean[c] += px[((size_t)(edge - r0) * W + x) * C + c] / W;
	for (int c = 0; c < C; c++)
		lo[c] = INFINITY, hi[c] = -INFINITY;
	/* The sample rows: both ends and every row centre between. */
	double ss[64];
	int ns = 0;
	ss[ns++] = sa;
	for (int r = (int)ceil(sa); r <= sb && ns < 63; r++)
		ss[ns++] = r;
	ss[ns++] = sb;
	for (int q = 0; q < ns; q++) {
		double s = ss[q];
		/* Past the edge row's centre: towards the pole's mean (or clamped). */
		double tp = 0;
		if (virt && (south ? s > edge : s < edge)) {
			tp = (s - edge) / (sp - edge);
			tp = tp > 1 ? 1 : tp;
		}
		s = s < 0 ? 0 : s > H - 1 ? H - 1 : s;
		int i0 = (int)floor(s), i1 = i0 + 1 < H ? i0 + 1 : i0;
		double t = s - i0;
		i0 -= r0, i1 -= r0;
		i0 = i0 < 0 ? 0 : i0 >= nr ? nr - 1 : i0;
		i1 = i1 < 0 ? 0 : i1 >= nr ? nr - 1 : i1;
		for (int x = 0; x < W; x++)
			for (int c = 0; c < C; c++) {
				double v = (1 - t) * px[((size_t)i0 * W + x) * C + c] +
					   t * px[((size_t)i1 * W + x) * C + c];
				v = (1 - tp) * v + tp * mean[c];
				lo[c] = v < lo[c] ? v : lo[c];
				hi[c] = v > hi[c] ? v : hi[c];
			}
	}
	free(px);
}

/* The pole row's spread per channel over tiles spread around the level (up to 8). */
static void pole_row_spread(struct node *n, struct gen_ctx *g, int lx, int ly, bool south,
			    uint32_t T, int C, double spread[3])
{
	double lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
	uint32_t nx = 1u << lx, step = nx > 8 ? nx / 8 : 1;
	uint32_t y = south ? (1u << ly) - 1 : 0, j = south ? T - 1 : 0;
	for (uint32_t x = 0; x < nx; x += step) {
		struct tile_key k = { .node = n->hash, .x = x, .y = y, .lx = (uint8_t)lx,
				      .ly = (uint8_t)ly };
		struct tile *t = tile_create(&k, n->out, T);
		int rc = n->type->generate(n, g, &k, NULL, 0, t);
		if (rc)
			fail_msg("%s (%d,%d) %u,%u: generate %d", n->name, lx, ly, x, y, rc);
		for (uint32_t i = 0; i < T; i++)
			for (int c = 0; c < C; c++) {
				double v = C == 1 ? tile_f32(t)[(size_t)j * T + i]
						  : t->data[((size_t)j * T + i) * 4 + c];
				lo[c] = v < lo[c] ? v : lo[c];
				hi[c] = v > hi[c] ? v : hi[c];
			}
		tile_unref(t);
	}
	for (int c = 0; c < C; c++)
		spread[c] = hi[c] - lo[c];
}

/* Levels: isotropic and anisotropic, from coarse to ly 19. */
static const int test_ly[] = { 0, 2, 4, 6, 8, 10, 12, 14, 16, 19 };
static const int test_dlx[] = { -1, 0, 1, 2, 3, 5, 8, 12, 19 }; /* lx = ly - dlx */

/* The planet of a case, loaded, and its file node in *n (skipped without the data). */
static struct planet *load_case(const struct pole_case *pc, struct node **n)
{
	if (access(pc->image, R_OK)) {
		fprintf(stderr, "test_poles: planet data missing (%s): run `make data` (as root) "
				"first — skipped\n", pc->image);
		skip();
	}
	struct planet *pl;
	char err[256];
	if (planet_load(pc->planet, &pl, err))
		fail_msg("%s", err);
	*n = planet_find_node(pl, pc->node);
	assert_non_null(*n);
	return pl;
}

static void check_case(const struct pole_case *pc)
{
	struct node *n;
	struct planet *pl = load_case(pc, &n);
	char err[256];
	struct gen_ctx g = { 0 };
	uint32_t T = pl->tile_size;
	int C = pc->channels, bad = 0;
	struct img_info info;
	if (img_cache_info(pl->images, pc->image, &info, err))
		fail_msg("%s", err);
	double row0 = (pc->north - pc->south) / info.height; /* degrees */
	for (size_t a = 0; a < sizeof test_ly / sizeof test_ly[0]; a++) {
		int ly = test_ly[a];
		double dlat = 180.0 / ((double)T * (1u << ly));
		/* The band a pole-row texel's filter may reach: the texel and one more (the
		 * bilinear reach on a MIP level as coarse as the texel), plus a source row once
		 * texels are as tall as half a row. */
		double depth = 2 * dlat + (dlat >= row0 / 2 ? row0 : 0);
		for (int pole = 0; pole < 2; pole++) {
			bool south = pole == 1;
			double slo[3], shi[3];
			if (south)
				source_range(pl->images, pc, -90, -90 + depth, slo, shi);
			else
				source_range(pl->images, pc, 90 - depth, 90, slo, shi);
			for (size_t b = 0; b < sizeof test_dlx / sizeof test_dlx[0]; b++) {
				int lx = ly - test_dlx[b];
				if (lx < 0 || lx > ly + 1 || (b > 0 && lx == ly - test_dlx[b - 1]))
					continue;
				double sp[3];
				pole_row_spread(n, &g, lx, ly, south, T, C, sp);
				for (int c = 0; c < C; c++) {
					double tol = shi[c] - slo[c] + (C == 1 ? 0.5 : 1.5);
					bool ok = sp[c] <= tol;
					if (!ok || getenv("TEST_POLES_VERBOSE"))
						fprintf(stderr,
							"%s %s %s pole (%d,%d) ch %d: pole row "
							"spread %.3f, source %.3f over %.4f°%s\n",
							pc->planet, pc->node, south ? "south" : "north",
							lx, ly, c, sp[c], shi[c] - slo[c], depth,
							ok ? "" : "  FAIL");
					bad += !ok;
				}
			}
		}
	}
	gen_ctx_fini(&g);
	planet_unref(pl);
	if (bad)
		fail_msg("%s %s: %d pole rows vary with longitude more than the source", pc->planet,
			 pc->node, bad);
}

static void earth_etopo(void **state)
{
	(void)state;
	check_case(&cases[0]);
}

static void earth_bluemarble(void **state)
{
	(void)state;
	check_case(&cases[1]);
}

static void moon_albedo(void **state)
{
	(void)state;
	check_case(&cases[2]);
}

static void mars_albedo(void **state)
{
	(void)state;
	check_case(&cases[3]);
}

/* One tile of a layer through render_layer (the daemon's cache and scheduler: a node's inputs
 * and neighbours as the daemon generates them). */
static void layer_tile(const struct planet *pl, const char *layer, int lx, int ly, uint32_t x,
		       uint32_t y, struct render_image *im)
{
	struct render_region rg = { .lx = lx, .ly = ly, .x = x, .y = y, .cols = 1, .rows = 1 };
	struct render_opts o = { .workers = 1, .cache_mb = 64 };
	char err[256];
	if (render_layer(pl, layer, &rg, &o, im, err))
		fail_msg("render %s (%d,%d) %u,%u: %s", layer, lx, ly, x, y, err);
}

/* The layers' pole rows at ly 19 (texel centres 7.5 cm from the pole on the Earth): heights
 * within tol_h metres of each other all round, colours within 2 levels, and normals (RG8 east, north in each texel's
 * own tangent frame) one 3-D vector within tol_deg — normals at lx ≤ 3 only: the viewer asks
 * for lx 0 wherever its ring holds a pole, and at finer lx the texels next to the pole are
 * so narrow (2 µm at lx 10) that a tile and its neighbours span too little of the ring for
 * an east slope out of float heights (node_normal.c, east_stencil). */
static void check_layers(const char *planet, const char *probe, double tol_h, double tol_deg)
{
	if (access(probe, R_OK)) {
		fprintf(stderr, "test_poles: planet data missing (%s): run `make data` (as root) "
				"first — skipped\n", probe);
		skip();
	}
	struct planet *pl;
	char err[256];
	if (planet_load(planet, &pl, err))
		fail_msg("%s", err);
	uint32_t T = pl->tile_size;
	int ly = 19, bad = 0;
	static const int lxs[] = { 0, 1, 3, 10, 20 };
	for (int pole = 0; pole < 2; pole++) {
		bool south = pole == 1;
		uint32_t y = south ? (1u << ly) - 1 : 0, j = south ? T - 1 : 0;
		for (size_t a = 0; a < sizeof lxs / sizeof lxs[0]; a++) {
			int lx = lxs[a];
			uint32_t nx = 1u << lx, step = nx > 4 ? nx / 4 : 1;
			double hlo = INFINITY, hhi = -INFINITY, nmin[3] = { 0 }, worst = 0;
			int clo[3] = { 255, 255, 255 }, chi[3] = { 0, 0, 0 }, cspread = 0;
			bool first = true;
			for (uint32_t x = 0; x < nx; x += step) {
				struct render_image h, n, col;
				layer_tile(pl, "height", lx, ly, x, y, &h);
				layer_tile(pl, "normal", lx, ly, x, y, &n);
				layer_tile(pl, "color", lx, ly, x, y, &col);
				for (uint32_t i = 0; i < T; i++) {
					const uint8_t *cp = (const uint8_t *)col.pixels +
							    ((size_t)j * T + i) * 4;
					for (int c = 0; c < 3; c++) {
						clo[c] = cp[c] < clo[c] ? cp[c] : clo[c];
						chi[c] = cp[c] > chi[c] ? cp[c] : chi[c];
					}
					float v = ((const float *)h.pixels)[(size_t)j * T + i];
					hlo = v < hlo ? v : hlo;
					hhi = v > hhi ? v : hhi;
					const uint8_t *q = (const uint8_t *)n.pixels +
							   ((size_t)j * T + i) * n.channels;
					double e = q[0] / 127.5 - 1, nn = q[1] / 127.5 - 1;
					double u = sqrt(fmax(0, 1 - e * e - nn * nn));
					double lon, lat;
					struct tile_key k = { .lx = (uint8_t)lx, .ly = (uint8_t)ly,
							      .x = x, .y = y };
					grid_texel_center(&k, T, i, j, &lon, &lat);
					double L = lon * M_PI / 180, P = lat * M_PI / 180;
					double E[3] = { -sin(L), cos(L), 0 };
					double N[3] = { -sin(P) * cos(L), -sin(P) * sin(L), cos(P) };
					double U[3] = { cos(P) * cos(L), cos(P) * sin(L), sin(P) };
					double w[3];
					for (int c = 0; c < 3; c++)
						w[c] = e * E[c] + nn * N[c] + u * U[c];
					if (first) {
						memcpy(nmin, w, sizeof w);
						first = false;
					}
					double d = w[0] * nmin[0] + w[1] * nmin[1] + w[2] * nmin[2];
					double ang = acos(fmin(1, d)) * 180 / M_PI;
					worst = ang > worst ? ang : worst;
				}
				render_image_free(&h);
				render_image_free(&n);
				render_image_free(&col);
			}
			for (int c = 0; c < 3; c++)
				cspread = chi[c] - clo[c] > cspread ? chi[c] - clo[c] : cspread;
			bool ok = hhi - hlo <= tol_h && (lx > 3 || worst <= tol_deg) && cspread <= 2;
			if (!ok || getenv("TEST_POLES_VERBOSE"))
				fprintf(stderr, "%s %s pole (%d,%d): heights spread %.4f m, normals "
						"%.2f° apart%s, colour spread %d%s\n", planet,
					south ? "south" : "north", lx, ly, hhi - hlo, worst,
					lx > 3 ? " (not judged)" : "", cspread,
					ok ? "" : "  FAIL");
			bad += !ok;
		}
	}
	planet_unref(pl);
	if (bad)
		fail_msg("%s: %d pole rows of the height or normal layer depend on longitude", planet,
			 bad);
}

static void earth_layers(void **state)
{
	(void)state;
	check_layers("conf/planets/earth.ini", "data/earth/etopo5.tif", 0.05, 3);
}

static void moon_layers(void **state)
{
	(void)state;
	check_layers("conf/planets/moon.ini", "data/moon/moon.tif", 0.05, 3);
}

static void mars_layers(void **state)
{
	(void)state;
	check_layers("conf/planets/mars.ini", "data/mars/mars.tif", 0.05, 3);
}

/* No radial dashes near the Earth's south pole. ETOPO5's four rows before the pole (−89.58°
 * … −89.92°) are one row repeated, varying 2774–2865 m with longitude: read as is, each
 * column became a wedge 9–45 km long on its meridian, dashes converging on the pole once
 * shaded. The file node filters rows east–west to their spacing (file_resample.h,
 * isotropic): at the viewer's levels near the pole, isotropic and anisotropic, no texel row
 * between −89.5° and the cap may be steeper east–west than 1.5 √2 × (the range of the source's
 * last rows / their 5′ spacing) on the ground (1.5: a Catmull-Rom curve's slope is up to 1.5×
 * its steepest step), at eight places where the repeated row
 * jumps (unfiltered, tried: every row fails, by 5× or more). */
static void earth_no_radial_dashes(void **state)
{
	(void)state;
	const struct pole_case *pc = &cases[0];
	struct node *n;
	struct planet *pl = load_case(pc, &n);
	char err[256];
	struct img_info info;
	if (img_cache_info(pl->images, pc->image, &info, err))
		fail_msg("%s", err);
	int W = info.width, H = info.height, rows = 12;
	float *px = malloc((size_t)W * rows * sizeof *px);
	assert_non_null(px);
	if (img_cache_read(pl->images, pc->image, 0, 0, W, H - rows, H, 0, 1, IMG_F32, px, 0, err))
		fail_msg("%s", err);
	double lo = INFINITY, hi = -INFINITY;
	for (size_t i = 0; i < (size_t)W * rows; i++) {
		lo = px[i] < lo ? px[i] : lo;
		hi = px[i] > hi ? px[i] : hi;
	}
	/* Where dashes were: between columns of the repeated rows that differ (the row's runs
	 * of one value end there). Eight of them, spread round the pole: the longitudes half
	 * way between the two columns' centres. */
	const struct file_source *fs = n->impl;
	const float *rep = px + (size_t)(rows - 4) * W; /* −89.75° */
	int njump = 0;
	for (int c = 0; c + 1 < W; c++)
		njump += fabsf(rep[c + 1] - rep[c]) > 10;
	assert_true(njump >= 8);
	double jump_lon[8];
	for (int c = 0, seen = 0, k = 0; c + 1 < W && k < 8; c++)
		if (fabsf(rep[c + 1] - rep[c]) > 10 && seen++ == k * njump / 8)
			jump_lon[k++] = fs->west + (c + 1) * (360.0 / W);
	free(px);
	double spacing = (pc->north - pc->south) / H * (M_PI / 180);
	double bound = 1.5 * sqrt(2) * (hi - lo) / spacing; /* 1.5: Catmull-Rom's slope */
	struct gen_ctx g = { 0 };
	uint32_t T = pl->tile_size;
	static const int lys[] = { 9, 11, 13 }, dlx[] = { -1, 0, 2, 5 };
	int bad = 0;
	for (size_t a = 0; a < sizeof lys / sizeof lys[0]; a++) {
		int ly = lys[a];
		double tile_deg = 180.0 / (1u << ly);
		for (size_t b = 0; b < sizeof dlx / sizeof dlx[0]; b++) {
			int lx = ly - dlx[b];
			uint32_t nx = 1u << lx;
			/* Rows from the cap (the last row's centre, −89.917°) to −89.5°. */
			for (uint32_t y = (uint32_t)((90 + 89.5) / tile_deg); y < 1u << ly; y++) {
				double worst = 0;
				for (int q8 = 0; q8 < 8; q8++) {
					/* The tile holding the jump, and the next east. */
					double u = fmod(jump_lon[q8] + 180, 360) / 360;
					uint32_t x0 = (uint32_t)(u * nx) % nx;
					struct tile *t[2];
					for (int q = 0; q < 2; q++) {
						struct tile_key k = { .node = n->hash, .lx = (uint8_t)lx,
								      .ly = (uint8_t)ly,
								      .x = (x0 + q) % nx, .y = y };
						t[q] = tile_create(&k, n->out, T);
						int rc = n->type->generate(n, &g, &k, NULL, 0, t[q]);
						if (rc)
							fail_msg("generate (%d,%d) %u,%u: %d", lx, ly,
								 k.x, y, rc);
					}
					for (uint32_t j = 0; j < T; j++) {
						double lon0, lon1, lat;
						grid_texel_center(&t[0]->key, T, 0, j, &lon0, &lat);
						grid_texel_center(&t[0]->key, T, 1, j, &lon1, &lat);
						if (lat > -89.5 || lat < -89.9)
							continue;
						double dx = (lon1 - lon0) * (M_PI / 180) *
							    cos(lat * (M_PI / 180));
						for (uint32_t i = 0; i < T; i++) {
							float v0 = tile_f32(t[0])[j * T + i];
							float v1 = i + 1 < T || nx == 1
									   ? tile_f32(t[0])[j * T + (i + 1) % T]
									   : tile_f32(t[1])[j * T];
							double sl = fabs(v1 - v0) / dx;
							worst = sl > worst ? sl : worst;
						}
					}
					tile_unref(t[0]);
					tile_unref(t[1]);
				}
				bool ok = worst <= bound;
				if (!ok || getenv("TEST_POLES_VERBOSE"))
					fprintf(stderr, "etopo (%d,%d) row %u: east-west slope %.0f m/rad,"
							" bound %.0f%s\n", lx, ly, y, worst, bound,
						ok ? "" : "  FAIL");
				bad += !ok;
			}
		}
	}
	gen_ctx_fini(&g);
	planet_unref(pl);
	if (bad)
		fail_msg("%d tile rows near the south pole show radial dashes", bad);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(earth_etopo),
		cmocka_unit_test(earth_bluemarble),
		cmocka_unit_test(moon_albedo),
		cmocka_unit_test(mars_albedo),
		cmocka_unit_test(earth_layers),
		cmocka_unit_test(earth_no_radial_dashes),
		cmocka_unit_test(moon_layers),
		cmocka_unit_test(mars_layers),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
