/* test_file_node — the `file` node on synthetic images written to a temp dir: texel values
 * against the analytic function the image was made from, seams between tiles and across the
 * antimeridian, sub-region bounds with fill, filtering at coarse levels (no aliasing),
 * nodata, colour channel expansion, parameter errors with file:line, the content hash, and
 * the image cache a planet shares between nodes (one open file per path; a changed file is
 * reread); load-time checks (truncated files, kind mismatches, georeferencing read from
 * GeoTIFF tags or refused) and a run-time read failure reported once; `magnify = bspline`'s
 * smooth contour of a 0/1 mask. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gdal/gdal.h>
#include <gdal/ogr_srs_api.h>

#include "common/grid.h"
#include "common/img.h"
#include "common/ini.h"
#include "common/xthread.h"
#include "engine/fault.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "engine/nodes/file_digest.h"

static char dir[64];
static struct planet pl;

static const char *tpath(const char *name)
{
	static char buf[4][128];
	static int k;
	k = (k + 1) % 4;
	snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
	return buf[k];
}

static int setup(void **state)
{
	(void)state;
	snprintf(dir, sizeof dir, "/tmp/test_file_node.XXXXXX");
	if (!mkdtemp(dir))
		return -1;
	memset(&pl, 0, sizeof pl);
	pl.dir = dir;
	pl.tile_size = 64;
	pl.max_level = 10;
	pl.a = 6378137.0;
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
	return system(cmd) == 0 ? 0 : -1;
}

/* A node built from an INI snippet (its first line is "[node x]"); owns the parsed INI. */
struct fnode {
	struct ini_file *ini;
	struct node n;
	struct gen_ctx g;
};

/* Bounds for test images without georeferencing (img_write writes none). */
#define GLOBAL "bounds = -180,-90,180,90\n"
/* ... and without the east–west prefilter, for tests of the resampling itself (1:1 copies,
 * bilinear against an analytic function, the caps' formula) at every latitude. */
#define GLOBAL_RAW GLOBAL "isotropic = false\n"

static int fnode_init(struct fnode *f, const char *text, char err[256])
{
	memset(f, 0, sizeof *f);
	int rc = ini_parse("test.ini", text, strlen(text), &f->ini, err);
	if (rc)
		return rc;
	struct ini_section *sec = NULL;
	for (size_t i = 0; i < f->ini->n; i++)
		if (strcmp(f->ini->sections[i].name, "node x") == 0)
			sec = &f->ini->sections[i];
	if (!sec)
		return -EINVAL;
	struct ini_entry *t = ini_find(sec, "type");
	if (t)
		t->used = true;
	f->n.name = "x";
	f->n.planet = &pl;
	return node_init(&f->n, &node_type_file, "test.ini", sec, err);
}

static void fnode_fini(struct fnode *f)
{
	node_fini(&f->n);
	gen_ctx_fini(&f->g);
	ini_free(f->ini);
}

/* Builds a node that must succeed. */
static void fnode_ok(struct fnode *f, const char *fmt, ...)
{
	char text[1024], err[256] = "";
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(text, sizeof text, fmt, ap);
	va_end(ap);
	int rc = fnode_init(f, text, err);
	if (rc)
		fail_msg("node_init: %d %s\n%s", rc, err, text);
}

static struct tile *gen(struct fnode *f, int lx, int ly, uint32_t x, uint32_t y, uint32_t T)
{
	struct tile_key k = { .node = f->n.hash, .x = x, .y = y, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
	struct tile *t = tile_create(&k, f->n.out, T);
	int rc = f->n.type->generate(&f->n, &f->g, &k, NULL, 0, t);
	if (rc)
		fail_msg("generate (%d,%d) %u,%u: %d", lx, ly, x, y, rc);
	return t;
}

static double fn(double lon, double lat)
{
	double r = M_PI / 180;
	return 1000 * sin(lon * r) * cos(lat * r) + 300 * sin(2 * lat * r) + 100;
}

/* A global (or bounded) image of fn at pixel centres. */
static void write_fn(const char *name, int w, int h, double W, double S, double E, double N)
{
	float *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[(size_t)y * w + x] = (float)fn(W + (x + 0.5) * (E - W) / w,
							  N - (y + 0.5) * (N - S) / h);
	char err[256];
	int rc = img_write(tpath(name), w, h, 1, IMG_F32, px, err);
	if (rc)
		fail_msg("%s", err);
	free(px);
}

/* Every texel of t within tol of fn at its centre, except rows within `pole` degrees of a
 * pole (bilinear clamps there). Returns the largest error. */
static double check_fn(const struct tile *t, double tol, double pole)
{
	const float *v = tile_f32(t);
	double worst = 0;
	for (uint32_t j = 0; j < t->size; j++) {
		for (uint32_t i = 0; i < t->size; i++) {
			double lon, lat;
			grid_texel_center(&t->key, t->size, i, j, &lon, &lat);
			if (fabs(lat) > 90 - pole)
				continue;
			double e = fabs(v[j * t->size + i] - fn(lon, lat));
			if (e > worst)
				worst = e;
			if (e > tol)
				fail_msg("texel (%u,%u) at %.4f,%.4f: %.4f, expected %.4f (tol %g)", i,
					 j, lon, lat, v[j * t->size + i], fn(lon, lat), tol);
		}
	}
	return worst;
}

/* 512×256 global float image: 1:1 levels are exact, finer levels bilinear, coarser levels
 * filtered from the MIP pyramid. */
static void analytic_global(void **state)
{
	(void)state;
	write_fn("g.tif", 512, 256, -180, -90, 180, 90);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = g.tif\n" GLOBAL_RAW);
	assert_int_equal(f.n.out, PIX_HEIGHT);
	static const uint32_t xy[][2] = { { 0, 0 }, { 5, 2 }, { 7, 3 }, { 3, 1 } };
	for (int i = 0; i < 4; i++) {
		struct tile *t = gen(&f, 3, 2, xy[i][0], xy[i][1], 64); /* 512 texels across */
		check_fn(t, 2e-3, 0);
		tile_unref(t);
	}
	/* 4× finer than the image: bilinear error ≤ h²/8 · |f''| ≈ 0.04, clamped at the poles. */
	static const uint32_t xy5[][2] = { { 0, 3 }, { 31, 7 }, { 17, 0 }, { 9, 15 } };
	double pole = 0.5 * 180.0 / 256;
	for (int i = 0; i < 4; i++) {
		struct tile *t = gen(&f, 5, 4, xy5[i][0], xy5[i][1], 64);
		check_fn(t, 0.05, pole);
		tile_unref(t);
	}
	/* 4× coarser: MIP level 2 (a 4×4 box), error ≈ |f''|·(4h)²/24 ≈ 0.2 */
	struct tile *t = gen(&f, 1, 0, 1, 0, 64);
	double e = check_fn(t, 0.5, 0);
	assert_true(e > 1e-3); /* it is filtered, not point-sampled */
	tile_unref(t);
	fnode_fini(&f);
}

/* The four tiles of level (lx + 1, ly + 1) under tile (x, y) of level (lx, ly), T / 2
 * texels square, equal the quadrants of that tile, T square (the same texel spacing). */
static void quadrants_join(struct fnode *f, int lx, int ly, uint32_t x, uint32_t y, uint32_t T)
{
	uint32_t H = T / 2;
	struct tile *big = gen(f, lx, ly, x, y, T);
	for (uint32_t q = 0; q < 4; q++) {
		uint32_t qx = q & 1, qy = q >> 1;
		struct tile *s = gen(f, lx + 1, ly + 1, 2 * x + qx, 2 * y + qy, H);
		for (uint32_t j = 0; j < H; j++)
			for (uint32_t i = 0; i < H; i++)
				assert_float_equal(tile_f32(s)[j * H + i],
						   tile_f32(big)[(qy * H + j) * T + qx * H + i], 1e-3);
		tile_unref(s);
	}
	tile_unref(big);
}

/* Neighbouring tiles join: four T tiles equal the quadrants of one 2T tile with the same
 * texel spacing, and the antimeridian columns are bilinear across the wrap. */
static void tiles_join(void **state)
{
	(void)state;
	write_fn("j.tif", 500, 250, -180, -90, 180, 90); /* not a power of two: never aligned */
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = j.tif\n" GLOBAL);
	quadrants_join(&f, 3, 2, 3, 1, 64);
	fnode_fini(&f);
	/* The antimeridian: 512 texels over 100 pixels (3.6°), so the edge texels lie between
	 * the image's last and first columns. Bilinear error ≤ h²/8·|f''| ≈ 1.1 m; clamping
	 * instead of wrapping would be off by up to ~17 m. */
	write_fn("am100.tif", 100, 50, -180, -90, 180, 90);
	fnode_ok(&f, "[node x]\ntype = file\npath = am100.tif\n" GLOBAL);
	struct tile *west = gen(&f, 4, 3, 0, 2, 32), *east = gen(&f, 4, 3, 15, 2, 32);
	check_fn(west, 2, 0);
	check_fn(east, 2, 0);
	tile_unref(west);
	tile_unref(east);
	fnode_fini(&f);
}

/* A sub-region lands at its bounds, with the fill outside; integer data with scale/offset. */
static void sub_region(void **state)
{
	(void)state;
	int w = 200, h = 100;
	double W = 10, S = 20, E = 30, N = 40;
	uint16_t *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[y * w + x] = (uint16_t)lrint((fn(W + (x + 0.5) * 0.1, N - (y + 0.5) * 0.2) +
							 2000) * 10);
	char err[256];
	assert_int_equal(img_write(tpath("sub.png"), w, h, 1, IMG_U16, px, err), 0);
	free(px);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = %s\nbounds = 10, 20, 30, 40\n"
		     "scale = 0.1\noffset = -2000\nfill = -500\n", tpath("sub.png"));
	/* Tile lon 0..45, lat 45..0: 0.7° texels over 0.1°×0.2° pixels. */
	struct tile *t = gen(&f, 3, 2, 4, 1, 64);
	int inside = 0, outside = 0;
	for (uint32_t j = 0; j < 64; j++) {
		for (uint32_t i = 0; i < 64; i++) {
			double lon, lat;
			grid_texel_center(&t->key, 64, i, j, &lon, &lat);
			float v = tile_f32(t)[j * 64 + i];
			if (lon < W || lon > E || lat < S || lat > N) {
				assert_float_equal(v, -500, 0);
				outside++;
			} else if (lon > W + 0.8 && lon < E - 0.8 && lat > S + 0.8 && lat < N - 0.8) {
				assert_float_equal(v, fn(lon, lat), 1.0);
				inside++;
			} else {
				assert_true(v > -300); /* near the edge: data, not fill */
			}
		}
	}
	assert_true(inside > 300 && outside > 2000);
	tile_unref(t);
	/* Far away: every texel is the fill. */
	t = gen(&f, 3, 2, 0, 3, 64);
	for (int i = 0; i < 64 * 64; i++)
		assert_float_equal(tile_f32(t)[i], -500, 0);
	tile_unref(t);
	fnode_fini(&f);

	/* Bounds across the antimeridian (170..190 = -170): tile lon -180..-135. */
	write_fn("am.tif", 80, 80, 170, -10, 190, 10);
	fnode_ok(&f, "[node x]\ntype = file\npath = am.tif\nbounds = 170,-10,190,10\nfill = 7\n");
	t = gen(&f, 3, 2, 0, 1, 64); /* lon -180..-135, lat 45..0 */
	for (uint32_t j = 0; j < 64; j++) {
		for (uint32_t i = 0; i < 64; i++) {
			double lon, lat;
			grid_texel_center(&t->key, 64, i, j, &lon, &lat);
			float v = tile_f32(t)[j * 64 + i];
			if (lon < -170.2 && lat < 9.8)
				assert_float_equal(v, fn(lon, lat), 0.5);
			else if (lon > -170 || lat > 10)
				assert_float_equal(v, 7, 0);
		}
	}
	tile_unref(t);
	fnode_fini(&f);
}

/* A 1-pixel checkerboard, 384×192: at 128 texels across (3 pixels per texel) point sampling
 * would hit pixel centres of one parity per texel and make a full-contrast checkerboard; a
 * filtered read gives the mean. Also on anisotropic levels: 6 × 3 and 6 × 1.5 pixels per
 * texel (x is averaged by sub-taps). */
static void coarse_is_filtered(void **state)
{
	(void)state;
	int w = 384, h = 192;
	uint8_t *g = malloc((size_t)w * h), *rgb = malloc((size_t)w * h * 3);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++) {
			uint8_t v = (x + y) & 1 ? 250 : 0;
			g[y * w + x] = v;
			rgb[(y * w + x) * 3] = v;
			rgb[(y * w + x) * 3 + 1] = (uint8_t)(250 - v);
			rgb[(y * w + x) * 3 + 2] = v;
		}
	char err[256];
	assert_int_equal(img_write(tpath("cb.png"), w, h, 1, IMG_U8, g, err), 0);
	assert_int_equal(img_write(tpath("cbc.png"), w, h, 3, IMG_U8, rgb, err), 0);
	free(g);
	free(rgb);
	struct fnode f, c;
	fnode_ok(&f, "[node x]\ntype = file\npath = cb.png\n" GLOBAL);
	fnode_ok(&c, "[node x]\ntype = file\npath = cbc.png\nkind = color\n" GLOBAL);
	assert_int_equal(c.n.out, PIX_COLOR);
	static const int lv[][2] = { { 1, 0 }, { 0, 0 }, { 0, 1 } };
	for (int l = 0; l < 3; l++) {
		struct tile *t = gen(&f, lv[l][0], lv[l][1], 0, 0, 64);
		struct tile *tc = gen(&c, lv[l][0], lv[l][1], 0, 0, 64);
		for (int i = 0; i < 64 * 64; i++) {
			if (fabsf(tile_f32(t)[i] - 125) > 1)
				fail_msg("level %d texel %d: %g", l, i, tile_f32(t)[i]);
			const uint8_t *p = tc->data + 4 * i;
			assert_in_range(p[0], 124, 126);
			assert_in_range(p[1], 124, 126);
			assert_in_range(p[2], 124, 126);
			assert_int_equal(p[3], 255);
		}
		tile_unref(t);
		tile_unref(tc);
	}
	/* At a level finer than the image the pattern is there (so the test can fail). */
	struct tile *t = gen(&f, 3, 2, 1, 1, 64);
	float lo = 1e9f, hi = -1e9f;
	for (int i = 0; i < 64 * 64; i++) {
		lo = fminf(lo, tile_f32(t)[i]);
		hi = fmaxf(hi, tile_f32(t)[i]);
	}
	assert_true(hi - lo > 100); /* vs ±1 when filtered */
	tile_unref(t);
	fnode_fini(&f);
	fnode_fini(&c);
}

/* nodata samples never leak into heights: texels are the fill or a mean of valid data. */
static void nodata(void **state)
{
	(void)state;
	int w = 360, h = 180;
	int16_t *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[y * w + x] = (x >= 100 && x < 140 && y >= 50 && y < 90) ? INT16_MIN
										     : (int16_t)(100 + x);
	char err[256];
	/* With MIP levels of its own (without, nodata would be refused: automip averages it). */
	assert_int_equal(img_write_tiled(tpath("nd.tif"), w, h, 1, IMG_I16, px, 64, true, err), 0);
	free(px);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = nd.tif\nnodata = -32768\nfill = -7\n" GLOBAL_RAW);
	/* Level (1,0) T=256: 512 texels over 360 pixels (bilinear), and (0,0) T=64 (filtered). */
	static const int lv[][3] = { { 1, 0, 256 }, { 0, 0, 64 }, { 2, 1, 64 } };
	for (int l = 0; l < 3; l++) {
		uint32_t T = (uint32_t)lv[l][2];
		struct tile *t = gen(&f, lv[l][0], lv[l][1], 0, 0, T);
		int fills = 0, exact = 0;
		for (uint32_t j = 0; j < T; j++) {
			for (uint32_t i = 0; i < T; i++) {
				double lon, lat;
				grid_texel_center(&t->key, T, i, j, &lon, &lat);
				double px_x = lon + 180, px_y = 90 - lat; /* 1 pixel per degree */
				float v = tile_f32(t)[j * T + i];
				bool deep = px_x > 103 && px_x < 137 && px_y > 53 && px_y < 87;
				bool far = px_x < 95 || px_x > 145 || px_y < 45 || px_y > 95;
				if (deep) {
					assert_float_equal(v, -7, 0);
					fills++;
				} else if (far && px_x > 6 && px_x < 170 &&
					   (px_y < 0.5 || px_y > 179.5)) {
					/* Past an edge row's centre, the polar cap: r² of the
					 * row, 1 - r² of its mean (100 + 179.5) and r - r² of
					 * its first harmonic, r = ρ / ρ1 (file_plan.c, pole_taps). */
					double r = 180 - fabs(90 - px_y) / 0.5;
					double ca = 0, sa = 0, lam = (px_x - 180) * M_PI / 180;
					for (int k = 0; k < 360; k++) {
						ca += (100 + k) * cos((k + 0.5 - 180) * M_PI / 180);
						sa += (100 + k) * sin((k + 0.5 - 180) * M_PI / 180);
					}
					double harm = 2 * (ca * cos(lam) + sa * sin(lam)) / 360;
					assert_float_equal(v, r * r * (100 + px_x - 0.5) +
								      (1 - r * r) * 279.5 + (r - r * r) * harm,
							   2.0);
				} else if (far && px_x > 6 && px_x < 170) {
					assert_float_equal(v, 100 + px_x - 0.5, 2.0);
					exact++;
				} else {
					assert_true(v == -7 || (v >= 99 && v <= 460));
				}
			}
		}
		if (lv[l][0] == 1)
			assert_true(fills > 100 && exact > 1000);
		tile_unref(t);
	}
	fnode_fini(&f);

	/* NaN in a float file is missing data too, on the 1:1 path and the filtered one. */
	float fp[64 * 32];
	for (int i = 0; i < 64 * 32; i++)
		fp[i] = (i % 64 >= 16 && i % 64 < 24) ? NAN : 5.0f;
	assert_int_equal(img_write(tpath("nan.exr"), 64, 32, 1, IMG_F32, fp, err), 0);
	fnode_ok(&f, "[node x]\ntype = file\npath = nan.exr\nfill = -1\n" GLOBAL_RAW);
	struct tile *t = gen(&f, 0, 0, 0, 0, 64); /* 64×64 over 64×32: 1:1 in x, 2× in y */
	for (int j = 0; j < 64; j++)
		for (int i = 0; i < 64; i++) {
			float v = tile_f32(t)[j * 64 + i];
			/* In the polar caps (the outer texel rows, within half a source row of a
			 * pole) the pole's value, the mean of the edge row's valid samples, may
			 * carry a missing column's texel. */
			if ((j == 0 || j == 63) && i >= 16 && i < 24 && v == 5)
				continue;
			assert_float_equal(v, (i >= 16 && i < 24) ? -1 : 5, 0);
		}
	tile_unref(t);
	t = gen(&f, 1, 0, 0, 0, 32); /* 1:1 aligned */
	for (int j = 0; j < 32; j++)
		for (int i = 0; i < 32; i++)
			assert_float_equal(tile_f32(t)[j * 32 + i], (i >= 16 && i < 24) ? -1 : 5, 0);
	tile_unref(t);
	fnode_fini(&f);
}

/* RGB gets alpha 255, grey is replicated, grey+alpha keeps its alpha, RGBA is copied. */
static void color_channels(void **state)
{
	(void)state;
	char err[256];
	uint8_t rgb[32 * 16 * 3], grey[32 * 16], ga[32 * 16 * 2];
	for (int i = 0; i < 32 * 16; i++) {
		rgb[3 * i] = 10, rgb[3 * i + 1] = 200, rgb[3 * i + 2] = 30;
		grey[i] = 77;
		ga[2 * i] = 99, ga[2 * i + 1] = 128;
	}
	assert_int_equal(img_write(tpath("rgb.png"), 32, 16, 3, IMG_U8, rgb, err), 0);
	assert_int_equal(img_write(tpath("grey.png"), 32, 16, 1, IMG_U8, grey, err), 0);
	assert_int_equal(img_write(tpath("ga.png"), 32, 16, 2, IMG_U8, ga, err), 0);
	static const struct {
		const char *file;
		uint8_t want[4];
	} cases[] = { { "rgb.png", { 10, 200, 30, 255 } },
		      { "grey.png", { 77, 77, 77, 255 } },
		      { "ga.png", { 99, 99, 99, 128 } } };
	for (int c = 0; c < 3; c++) {
		struct fnode f;
		fnode_ok(&f, "[node x]\ntype = file\npath = %s\nkind = color\n" GLOBAL_RAW, cases[c].file);
		for (int lv = 0; lv < 2; lv++) {
			struct tile *t = gen(&f, 2 + lv, 1 + lv, 1, 1, 64);
			for (int i = 0; i < 64 * 64; i++)
				assert_memory_equal(t->data + 4 * i, cases[c].want, 4);
			tile_unref(t);
		}
		fnode_fini(&f);
	}
	/* RGBA, 1:1 aligned: the bytes themselves. */
	uint8_t *rgba = malloc(256 * 128 * 4);
	for (int i = 0; i < 256 * 128 * 4; i++)
		rgba[i] = (uint8_t)(i * 13 + i / 1024);
	assert_int_equal(img_write(tpath("rgba.png"), 256, 128, 4, IMG_U8, rgba, err), 0);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = rgba.png\nkind = color\n" GLOBAL_RAW);
	struct tile *t = gen(&f, 2, 1, 3, 1, 64);
	for (int j = 0; j < 64; j++)
		assert_memory_equal(t->data + j * 64 * 4, rgba + ((64 + j) * 256 + 192) * 4, 64 * 4);
	tile_unref(t);
	fnode_fini(&f);
	free(rgba);
}

/* Each error names file:line: key. */
static void bad_params(void **state)
{
	(void)state;
	write_fn("ok.tif", 16, 8, -180, -90, 180, 90);
	uint8_t grey8[16 * 8] = { 0 };
	char werr[256];
	assert_int_equal(img_write(tpath("ok8.png"), 16, 8, 1, IMG_U8, grey8, werr), 0);
	FILE *fp = fopen(tpath("corrupt.png"), "wb");
	assert_non_null(fp);
	/* Not a truncated one: OIIO 2.4 leaks a string when libpng longjmps out of a short read. */
	fputs("\x89PNG\r\n\x1a\n this is not a png at all", fp);
	assert_int_equal(fclose(fp), 0);
	static const struct {
		const char *text, *want, *also;
	} cases[] = {
		{ "[node x]\ntype = file\n", "test.ini:1: path: missing", NULL },
		{ "[node x]\ntype = file\npath = nope.tif\n" GLOBAL, "test.ini:3: path: cannot open ",
		  "nope.tif" },
		{ "[node x]\ntype = file\n\npath = corrupt.png\n" GLOBAL, "test.ini:4: path: cannot open ",
		  "corrupt.png" },
		{ "[node x]\ntype = file\npath = ok.tif\nkind = normal\n" GLOBAL, "test.ini:4: kind: ",
		  "height, color" },
		{ "[node x]\ntype = file\npath = ok.tif\nbounds = 1,2,3\n", "test.ini:4: bounds: ",
		  "4 numbers" },
		{ "[node x]\ntype = file\npath = ok.tif\nbounds = 10,20,5,40\n",
		  "test.ini:4: bounds: ", "W < E" },
		{ "[node x]\ntype = file\npath = ok.tif\nbounds = 0,-95,10,0\n",
		  "test.ini:4: bounds: ", "S < N" },
		{ "[node x]\ntype = file\npath = ok.tif\nchannel = 1\n" GLOBAL, "test.ini:4: channel: ",
		  "1 channel" },
		{ "[node x]\ntype = file\npath = ok8.png\nkind = color\nnodata = 0\n" GLOBAL,
		  "test.ini:5: nodata: only applies to kind = height", NULL },
		{ "[node x]\ntype = file\npath = ok.tif\nbounds = 0,0,10,10\nlon_wrap = true\n",
		  "test.ini:5: lon_wrap: ", "360" },
		{ "[node x]\ntype = file\npath = ok.tif\nlon_wrap = maybe\n" GLOBAL,
		  "test.ini:4: lon_wrap: ", NULL },
		{ "[node x]\ntype = file\npath = ok.tif\nscale = x\n" GLOBAL, "test.ini:4: scale: ", NULL },
		{ "[node x]\ntype = file\npath = ok8.png\nkind = color\nfill = 1,2\n" GLOBAL,
		  "test.ini:5: fill: ", NULL },
		{ "[node x]\ntype = file\npath = ok.tif\ncache_mb = 0\n" GLOBAL, "test.ini:4: cache_mb: ",
		  NULL },
		{ "[node x]\ntype = file\npath = ok.tif\ncolour = red\n" GLOBAL, "test.ini:4: colour: ",
		  "unknown key" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		struct fnode f;
		char err[256] = "";
		int rc = fnode_init(&f, cases[i].text, err);
		if (rc != -EINVAL || strncmp(err, cases[i].want, strlen(cases[i].want)) != 0 ||
		    (cases[i].also && !strstr(err, cases[i].also)))
			fail_msg("case %zu: rc %d, err \"%s\", want \"%s\"…\"%s\"", i, rc, err,
				 cases[i].want, cases[i].also ? cases[i].also : "");
		fnode_fini(&f);
	}
}

/* The content hash follows the parameters and the file (size, mtime, inode), not cache_mb. */
static void content_hash(void **state)
{
	(void)state;
	write_fn("h.tif", 16, 8, -180, -90, 180, 90);
	struct fnode a, b, c, d;
	fnode_ok(&a, "[node x]\ntype = file\npath = h.tif\n" GLOBAL);
	fnode_ok(&b, "[node x]\ntype = file\npath = %s\ncache_mb = 8\n" GLOBAL, tpath("h.tif"));
	fnode_ok(&c, "[node x]\ntype = file\npath = h.tif\nfill = 1\n" GLOBAL);
	assert_true(a.n.hash == b.n.hash);
	assert_true(a.n.hash != c.n.hash);
	write_fn("h.tif", 16, 9, -180, -90, 180, 90); /* the file changes */
	fnode_ok(&d, "[node x]\ntype = file\npath = h.tif\n" GLOBAL);
	assert_true(a.n.hash != d.n.hash);
	fnode_fini(&a);
	fnode_fini(&b);
	fnode_fini(&c);
	fnode_fini(&d);
}

/* Copies a file byte for byte (a fresh inode and mtime). */
static void copy_file(const char *from, const char *to)
{
	FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
	assert_non_null(a);
	assert_non_null(b);
	int ch;
	while ((ch = fgetc(a)) != EOF)
		fputc(ch, b);
	fclose(a);
	assert_int_equal(fclose(b), 0);
}

/* The hash names the data, not where it lies: a copy at another path (another inode, another
 * mtime: another machine of a fleet) has the same hash; one changed byte another. */
static void content_hash_copies(void **state)
{
	(void)state;
	float px[16 * 8];
	char err[256];
	for (int i = 0; i < 16 * 8; i++)
		px[i] = (float)i * 0.5f;
	assert_int_equal(img_write(tpath("orig.tif"), 16, 8, 1, IMG_F32, px, err), 0);
	assert_int_equal(mkdir(tpath("elsewhere"), 0755), 0);
	usleep(20000); /* another mtime */
	copy_file(tpath("orig.tif"), tpath("elsewhere/copy.tif"));
	/* The same image but one texel a last bit higher. */
	px[37] = nextafterf(px[37], 1e9f);
	assert_int_equal(img_write(tpath("changed.tif"), 16, 8, 1, IMG_F32, px, err), 0);
	struct stat st;
	assert_int_equal(stat(tpath("orig.tif"), &st), 0);
	struct fnode a, b, c;
	fnode_ok(&a, "[node x]\ntype = file\npath = orig.tif\n" GLOBAL);
	fnode_ok(&b, "[node x]\ntype = file\npath = elsewhere/copy.tif\n" GLOBAL);
	assert_true(a.n.hash == b.n.hash);
	uint8_t d1[16], d2[16];
	struct stat sc;
	assert_int_equal(stat(tpath("changed.tif"), &sc), 0);
	assert_int_equal(file_digest(tpath("orig.tif"), &st, UINT64_MAX, d1, err), 0);
	assert_int_equal(file_digest(tpath("changed.tif"), &sc, UINT64_MAX, d2, err), 0);
	assert_memory_not_equal(d1, d2, 16);
	fnode_ok(&c, "[node x]\ntype = file\npath = changed.tif\n" GLOBAL);
	assert_true(a.n.hash != c.n.hash);
	fnode_fini(&c);
	fnode_fini(&a);
	fnode_fini(&b);
}

/* From cache_min bytes on the digest is kept in FILE.digest and reused while the file's size,
 * mtime and inode match; a changed file is hashed again. Smaller files leave no sidecar. */
static void digest_sidecar(void **state)
{
	(void)state;
	write_fn("side.tif", 16, 8, -180, -90, 180, 90);
	char err[256], side[160];
	snprintf(side, sizeof side, "%s.digest", tpath("side.tif"));
	struct stat st;
	uint8_t d[16], d2[16];
	assert_int_equal(stat(tpath("side.tif"), &st), 0);
	assert_int_equal(file_digest(tpath("side.tif"), &st, UINT64_MAX, d, err), 0);
	assert_int_not_equal(access(side, F_OK), 0); /* small: no sidecar */
	assert_int_equal(file_digest(tpath("side.tif"), &st, 0, d2, err), 0);
	assert_memory_equal(d, d2, 16);
	assert_int_equal(access(side, F_OK), 0);
	/* The sidecar is what is used while the stamp matches: forge its digest to see it. */
	FILE *f = fopen(side, "r");
	char line[256];
	assert_non_null(fgets(line, sizeof line, f));
	fclose(f);
	char *hex = strrchr(line, ' ') + 1;
	hex[0] = hex[0] == '0' ? '1' : '0';
	f = fopen(side, "w");
	fputs(line, f);
	fclose(f);
	assert_int_equal(file_digest(tpath("side.tif"), &st, 0, d2, err), 0);
	assert_memory_not_equal(d, d2, 16);
	/* The file changes (rewritten: new mtime and inode): hashed again, sidecar rewritten. The
	 * rewrite may get the same inode back and, within the clock's tick, the same mtime: the
	 * mtime is moved a second on, as any later write would. */
	struct timespec was = st.st_mtim;
	write_fn("side.tif", 16, 8, -180, -90, 180, 90);
	was.tv_sec++;
	assert_int_equal(utimensat(AT_FDCWD, tpath("side.tif"), (struct timespec[2]){ was, was }, 0), 0);
	assert_int_equal(stat(tpath("side.tif"), &st), 0);
	assert_int_equal(file_digest(tpath("side.tif"), &st, 0, d2, err), 0);
	assert_memory_equal(d, d2, 16); /* the same bytes as the first time */
	/* Unreadable: a clear error naming the file. */
	assert_int_equal(file_digest(tpath("none.tif"), &st, 0, d2, err), -ENOENT);
	assert_non_null(strstr(err, "none.tif"));
}

struct job {
	struct fnode *f;
	struct gen_ctx g;
	int bad;
	const float *want[8];
};

static void *job_main(void *arg)
{
	struct job *jb = arg;
	for (int it = 0; it < 3; it++) {
		for (uint32_t x = 0; x < 8; x++) {
			struct tile_key k = { .node = jb->f->n.hash, .x = x, .y = 1, .lx = 3, .ly = 2 };
			struct tile *t = tile_create(&k, PIX_HEIGHT, 32);
			if (jb->f->n.type->generate(&jb->f->n, &jb->g, &k, NULL, 0, t) ||
			    memcmp(t->data, jb->want[x], t->nbytes) != 0)
				jb->bad++;
			tile_unref(t);
		}
	}
	return NULL;
}

/* Two workers generating from one node at once get what one worker gets. */
static void concurrent_generate(void **state)
{
	(void)state;
	write_fn("c.tif", 300, 150, -180, -90, 180, 90);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = c.tif\ncache_mb = 1\n" GLOBAL);
	struct tile *ref[8];
	struct job jobs[2];
	memset(jobs, 0, sizeof jobs);
	for (uint32_t x = 0; x < 8; x++) {
		ref[x] = gen(&f, 3, 2, x, 1, 32);
		jobs[0].want[x] = jobs[1].want[x] = tile_f32(ref[x]);
	}
	pthread_t th[2];
	for (int i = 0; i < 2; i++) {
		jobs[i].f = &f;
		assert_int_equal(xthread_create(&th[i], job_main, &jobs[i]), 0);
	}
	for (int i = 0; i < 2; i++) {
		xthread_join(th[i]);
		assert_int_equal(jobs[i].bad, 0);
		gen_ctx_fini(&jobs[i].g);
	}
	for (int x = 0; x < 8; x++)
		tile_unref(ref[x]);
	fnode_fini(&f);
}

/* Nodes of a planet with an image cache read through it: two nodes on one path (one spelled
 * relative, one absolute) open the file once and give the same pixels; cache_mb is accepted
 * but does not size anything. A node on another file adds a file. */
static void shared_cache(void **state)
{
	(void)state;
	write_fn("s.tif", 360, 180, -180, -90, 180, 90);
	write_fn("s2.tif", 36, 18, -180, -90, 180, 90);
	struct img_cache *ic = img_cache_create(16);
	assert_non_null(ic);
	pl.images = ic;
	struct fnode a, b, c;
	fnode_ok(&a, "[node x]\ntype = file\npath = s.tif\ncache_mb = 1\n" GLOBAL);
	fnode_ok(&b, "[node x]\ntype = file\npath = %s\nscale = 2\n" GLOBAL, tpath("s.tif"));
	struct tile *ta = gen(&a, 2, 1, 1, 0, 64), *tb = gen(&b, 2, 1, 1, 0, 64);
	for (size_t i = 0; i < 64 * 64; i++)
		if (tile_f32(tb)[i] != 2 * tile_f32(ta)[i])
			fail_msg("texel %zu: %g vs 2 × %g", i, tile_f32(tb)[i], tile_f32(ta)[i]);
	struct img_cache_stats st;
	img_cache_get_stats(ic, &st);
	assert_int_equal(st.files, 1);
	assert_int_equal(st.opens, 1);
	assert_int_equal(st.max_bytes, (uint64_t)16 << 20); /* not cache_mb's 1 */
	assert_true(st.memory_used > 0);
	fnode_ok(&c, "[node x]\ntype = file\npath = s2.tif\n" GLOBAL);
	tile_unref(gen(&c, 2, 1, 1, 0, 64));
	img_cache_get_stats(ic, &st);
	assert_int_equal(st.files, 2);
	assert_int_equal(st.opens, 2);
	tile_unref(ta);
	tile_unref(tb);
	fnode_fini(&a);
	fnode_fini(&b);
	fnode_fini(&c);
	pl.images = NULL;
	img_cache_unref(ic);
}

/* A node created for a file that changed since another node on the same path read it through
 * the shared cache reads the new file, not the cached pixels. */
static void changed_file_reread(void **state)
{
	(void)state;
	struct img_cache *ic = img_cache_create(16);
	pl.images = ic;
	float px[8 * 4];
	char err[256];
	for (int i = 0; i < 8 * 4; i++)
		px[i] = 5;
	assert_int_equal(img_write(tpath("v.tif"), 8, 4, 1, IMG_F32, px, err), 0);
	struct fnode a, b;
	fnode_ok(&a, "[node x]\ntype = file\npath = v.tif\n" GLOBAL);
	struct tile *t = gen(&a, 1, 0, 0, 0, 64);
	assert_true(tile_f32(t)[0] == 5.0f);
	tile_unref(t);
	for (int i = 0; i < 8 * 4; i++)
		px[i] = -9;
	assert_int_equal(img_write(tpath("v.tif"), 8, 4, 1, IMG_F32, px, err), 0);
	fnode_ok(&b, "[node x]\ntype = file\npath = v.tif\n" GLOBAL);
	assert_true(a.n.hash != b.n.hash);
	t = gen(&b, 1, 0, 0, 0, 64);
	assert_true(tile_f32(t)[0] == -9.0f);
	tile_unref(t);
	fnode_fini(&a);
	fnode_fini(&b);
	pl.images = NULL;
	img_cache_unref(ic);
}

/* A GeoTIFF made with GDAL (what users bring): W..E × S..N at 0.05°, 100 except a nodata
 * block in its north-east quarter: int16 with nodata -32768, or (huge) float32 with GDAL's
 * -1e34; crs 4326 or the UTM zone 33N. */
static void write_geotiff_here(const char *name, double W, double N, int epsg, bool with_gt,
			       bool huge)
{
	GDALAllRegister();
	int w = 200, h = 200;
	GDALDataType t = huge ? GDT_Float32 : GDT_Int16;
	double nd = huge ? -1e34 : -32768;
	GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), tpath(name), w, h, 1, t, NULL);
	assert_non_null(ds);
	if (with_gt) {
		double gt[6] = { W, epsg == 4326 ? 0.05 : 100, 0, N, 0, epsg == 4326 ? -0.05 : -100 };
		assert_int_equal(GDALSetGeoTransform(ds, gt), CE_None);
		OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
		assert_int_equal(OSRImportFromEPSG(srs, epsg), OGRERR_NONE);
		assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
		OSRDestroySpatialReference(srs);
	}
	GDALRasterBandH b = GDALGetRasterBand(ds, 1);
	assert_int_equal(GDALSetRasterNoDataValue(b, nd), CE_None);
	double *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[y * w + x] = x >= w / 2 && y < h / 2 ? nd : 100;
	assert_int_equal(GDALRasterIO(b, GF_Write, 0, 0, w, h, px, w, h, GDT_Float64, 0, 0), CE_None);
	free(px);
	GDALClose(ds);
}

/* write_geotiff_here in a child process: GDAL's GeoTIFF driver changes libtiff's process-wide
 * state (tag extenders, error handlers), which the file node's process never has. */
static void write_geotiff(const char *name, double W, double N, int epsg, bool with_gt,
			  bool huge)
{
	fflush(NULL);
	pid_t pid = fork();
	assert_true(pid >= 0);
	if (pid == 0) {
		write_geotiff_here(name, W, N, epsg, with_gt, huge);
		_exit(0);
	}
	int st;
	assert_int_equal(waitpid(pid, &st, 0), pid);
	assert_true(WIFEXITED(st) && WEXITSTATUS(st) == 0);
}

/* Issue 19: a plain GeoTIFF without a bounds key lands at its georeferenced bounds (not
 * stretched over the globe), and its nodata (GDAL's -1e34) takes the fill. */
static void geotiff_placed(void **state)
{
	(void)state;
	double W = 10, E = 20, S = 50, N = 60;
	write_geotiff("geo.tif", W, N, 4326, true, true);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = geo.tif\nfill = -5\n");
	struct tile *t = gen(&f, 3, 2, 4, 0, 64); /* lon 0..45, lat 90..45 */
	int data = 0, nodata = 0, outside = 0;
	for (uint32_t j = 0; j < 64; j++) {
		for (uint32_t i = 0; i < 64; i++) {
			double lon, lat;
			grid_texel_center(&t->key, 64, i, j, &lon, &lat);
			float v = tile_f32(t)[j * 64 + i];
			if (lon < W || lon > E || lat < S || lat > N) {
				if (v != -5)
					fail_msg("outside at %g,%g: %g", lon, lat, v);
				outside++;
			} else if (lon > 15.8 && lat > 55.8 && lon < E - 0.8 && lat < N - 0.8) {
				if (v != -5) /* nodata → fill */
					fail_msg("nodata at %g,%g: %g", lon, lat, v);
				nodata++;
			} else if ((lon < 14.2 || lat < 54.2) && lon > W + 0.8 && lat > S + 0.8 &&
				   lon < E - 0.8 && lat < N - 0.8) {
				if (v != 100)
					fail_msg("data at %g,%g: %g", lon, lat, v);
				data++;
			}
		}
	}
	if (!(data > 60 && nodata > 10 && outside > 3800))
		fail_msg("data %d nodata %d outside %d", data, nodata, outside);
	tile_unref(t);
	fnode_fini(&f);

	/* A bounds key that contradicts the georeferencing is refused; one that agrees is not. */
	char err[256] = "";
	assert_int_equal(fnode_init(&f, "[node x]\ntype = file\npath = geo.tif\n"
				    "bounds = -180,-90,180,90\n", err), -EINVAL);
	assert_non_null(strstr(err, "test.ini:4: bounds: "));
	assert_non_null(strstr(err, "contradicts the georeferencing"));
	assert_non_null(strstr(err, "geo.tif (10,50,20,60)"));
	fnode_fini(&f);
	fnode_ok(&f, "[node x]\ntype = file\npath = geo.tif\nbounds = 10,50,20,60\n");
	fnode_fini(&f);

	/* int16 -32768 without MIP levels of its own: OIIO's automip would average it into
	 * coarse heights: refused, pointing at clipmapctl import (which builds levels around
	 * the voids). */
	write_geotiff("geo_flat.tif", W, N, 4326, true, false);
	assert_int_equal(fnode_init(&f, "[node x]\ntype = file\npath = geo_flat.tif\n", err),
			 -EINVAL);
	if (!strstr(err, "test.ini:3: path: ") || !strstr(err, "geo_flat.tif: no MIP levels") ||
	    !strstr(err, "clipmapctl import"))
		fail_msg("%s", err);
	fnode_fini(&f);

	/* Projected (UTM): refused, pointing at clipmapctl import. */
	write_geotiff("utm.tif", 500000, 5600000, 32633, true, false);
	assert_int_equal(fnode_init(&f, "[node x]\ntype = file\npath = utm.tif\n", err), -EINVAL);
	assert_non_null(strstr(err, "test.ini:1: bounds: missing"));
	assert_non_null(strstr(err, "EPSG:32633"));
	assert_non_null(strstr(err, "clipmapctl import"));
	fnode_fini(&f);
	/* ... and a bounds key cannot place it (it would be stretched, not warped). */
	assert_int_equal(fnode_init(&f, "[node x]\ntype = file\npath = utm.tif\n"
				    "bounds = 13,50,14,51\n", err), -EINVAL);
	if (!strstr(err, "test.ini:4: bounds: ") || !strstr(err, "projected") ||
	    !strstr(err, "clipmapctl import"))
		fail_msg("%s", err);
	fnode_fini(&f);
}

/* Issue 19: no georeferencing and no bounds key: refused, naming the file and the key. */
static void no_georef_refused(void **state)
{
	(void)state;
	write_fn("plain.tif", 32, 16, -180, -90, 180, 90);
	write_geotiff("gdal_plain.tif", 0, 0, 4326, false, false);
	static const char *const files[] = { "plain.tif", "gdal_plain.tif" };
	for (int i = 0; i < 2; i++) {
		struct fnode f;
		char err[256] = "", text[256];
		snprintf(text, sizeof text, "[node x]\ntype = file\npath = %s\n", files[i]);
		assert_int_equal(fnode_init(&f, text, err), -EINVAL);
		if (!strstr(err, "test.ini:1: bounds: missing") || !strstr(err, files[i]) ||
		    !strstr(err, "has no georeferencing") || !strstr(err, "add bounds = W,S,E,N"))
			fail_msg("%s: %s", files[i], err);
		fnode_fini(&f);
	}
}

/* Issue 14: a truncated TIFF is refused at load, naming the file (not every tile failing
 * later with a bare EIO). */
static void truncated_refused(void **state)
{
	(void)state;
	int w = 512, h = 256;
	float *px = malloc((size_t)w * h * sizeof *px);
	for (int i = 0; i < w * h; i++)
		px[i] = (float)(i % 977) * 1.37f; /* does not compress to nothing */
	char err[256];
	assert_int_equal(img_write_tiled(tpath("cut.tif"), w, h, 1, IMG_F32, px, 64, true, err), 0);
	free(px);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = cut.tif\n" GLOBAL);
	fnode_fini(&f);
	struct stat st;
	assert_int_equal(stat(tpath("cut.tif"), &st), 0);
	/* Cut at several points: each time refused at load. */
	for (int k = 1; k <= 3; k++) {
		off_t len = st.st_size * (4 - k) / 4 - 100;
		assert_int_equal(truncate(tpath("cut.tif"), len), 0);
		char e2[256] = "";
		int rc = fnode_init(&f, "[node x]\ntype = file\npath = cut.tif\n" GLOBAL, e2);
		if (rc != -EINVAL || !strstr(e2, "test.ini:3: path: ") || !strstr(e2, tpath("cut.tif")))
			fail_msg("cut to %lld of %lld: rc %d: %s", (long long)len,
				 (long long)st.st_size, rc, e2);
		fnode_fini(&f);
	}
}

static char fault_line[512];
static int faults;
static void catch_fault(const char *line)
{
	snprintf(fault_line, sizeof fault_line, "%s", line);
	faults++;
}

/* Issue 14: a file that breaks after load (cut short on disk): its tiles fail, and the
 * failure is reported once, naming the file, the level and the region. */
static void runtime_failure_reported_once(void **state)
{
	(void)state;
	int w = 1024, h = 512;
	float *px = malloc((size_t)w * h * sizeof *px);
	for (int i = 0; i < w * h; i++)
		px[i] = (float)(i % 977) * 1.37f;
	char err[256];
	assert_int_equal(img_write_tiled(tpath("late.tif"), w, h, 1, IMG_F32, px, 64, false, err), 0);
	free(px);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = late.tif\n" GLOBAL);
	struct stat st;
	assert_int_equal(stat(tpath("late.tif"), &st), 0);
	assert_int_equal(truncate(tpath("late.tif"), st.st_size / 3), 0);
	engine_fault_sink(catch_fault);
	faults = 0;
	struct tile_key k = { .node = f.n.hash, .x = 7, .y = 2, .lx = 3, .ly = 2 };
	for (int i = 0; i < 3; i++) {
		struct tile *t = tile_create(&k, f.n.out, 64);
		assert_int_equal(f.n.type->generate(&f.n, &f.g, &k, NULL, 0, t), -EIO);
		tile_unref(t);
	}
	engine_fault_sink(NULL);
	assert_int_equal(faults, 1);
	if (!strstr(fault_line, tpath("late.tif")) || !strstr(fault_line, "read failed at MIP level ") ||
	    !strstr(fault_line, "pixels ["))
		fail_msg("%s", fault_line);
	fnode_fini(&f);
}

/* Issue 14: the file's channels must fit the kind. */
static void kind_mismatch_refused(void **state)
{
	(void)state;
	uint8_t rgb[32 * 16 * 3] = { 0 };
	float hf[32 * 16] = { 0 };
	int16_t hi[32 * 16] = { 0 };
	char err[256];
	assert_int_equal(img_write(tpath("colour.tif"), 32, 16, 3, IMG_U8, rgb, err), 0);
	assert_int_equal(img_write(tpath("hf.tif"), 32, 16, 1, IMG_F32, hf, err), 0);
	assert_int_equal(img_write(tpath("hi.tif"), 32, 16, 1, IMG_I16, hi, err), 0);
	static const struct {
		const char *text, *want[3];
	} cases[] = {
		{ "[node x]\ntype = file\npath = colour.tif\n" GLOBAL,
		  { "test.ini:1: kind: node x: ", "colour.tif has 3 uint8 channels",
		    "kind = height expects one channel" } },
		{ "[node x]\ntype = file\npath = hf.tif\nkind = color\n" GLOBAL,
		  { "test.ini:4: kind: node x: ", "hf.tif has 1 float channel",
		    "kind = color expects 8-bit" } },
		{ "[node x]\ntype = file\npath = hi.tif\nkind = color\n" GLOBAL,
		  { "test.ini:4: kind: node x: ", "hi.tif has 1 int16 channel", "kind = color" } },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		struct fnode f;
		char e[256] = "";
		int rc = fnode_init(&f, cases[i].text, e);
		if (rc != -EINVAL || strncmp(e, cases[i].want[0], strlen(cases[i].want[0])) ||
		    !strstr(e, cases[i].want[1]) || !strstr(e, cases[i].want[2]))
			fail_msg("case %zu: rc %d: %s", i, rc, e);
		fnode_fini(&f);
	}
	/* With channel = N the user says which one holds heights: accepted. */
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = colour.tif\nchannel = 1\n" GLOBAL);
	fnode_fini(&f);
}

/* Issue 19: GDAL's -1e34 nodata never becomes heights, at the data's level or at coarse ones
 * (where MIP averaging mixes it with data). */
static void huge_nodata_coarse(void **state)
{
	(void)state;
	int w = 720, h = 360;
	float *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[y * w + x] = x >= 301 && x < 423 && y >= 101 && y < 203 ? -1e34f : 1000;
	char err[256];
	assert_int_equal(img_write(tpath("huge.tif"), w, h, 1, IMG_F32, px, err), 0);
	free(px);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = huge.tif\nnodata = -1e34\nfill = -5\n" GLOBAL);
	static const int lv[][2] = { { 1, 0 }, { 2, 1 }, { 3, 2 }, { 4, 3 } };
	for (int l = 0; l < 4; l++) {
		int fills = 0;
		for (uint32_t x = 0; x < 1u << lv[l][0]; x++) {
			for (uint32_t y = 0; y < 1u << lv[l][1]; y++) {
				struct tile *t = gen(&f, lv[l][0], lv[l][1], x, y, 64);
				for (int i = 0; i < 64 * 64; i++) {
					float v = tile_f32(t)[i];
					/* 1000 to float rounding (a cubic's four weights) */
					if (fabsf(v - 1000) > 1e-3f && v != -5)
						fail_msg("level %d tile %u,%u texel %d: %g", l, x, y, i, v);
					fills += v == -5;
				}
				tile_unref(t);
			}
		}
		assert_true(fills > 0);
	}
	fnode_fini(&f);
}

/* A noise value per column (±100), the same for every row that uses it. */
static float col_noise(int x)
{
	uint32_t h = (uint32_t)x * 2654435761u;
	h ^= h >> 15;
	h *= 2246822519u;
	h ^= h >> 13;
	return (float)(h % 2001) / 10.0f - 100.0f;
}

/* A texel row's steepest east–west slope per radian of ground arc (heights per radian of
 * latitude would be the same unit), over the texels of nt tiles side by side. */
static double ew_slope(struct tile *const *t, int nt, uint32_t j)
{
	uint32_t T = t[0]->size;
	double lon0, lon1, lat;
	grid_texel_center(&t[0]->key, T, 0, j, &lon0, &lat);
	grid_texel_center(&t[0]->key, T, 1, j, &lon1, &lat);
	double dx = (lon1 - lon0) * (M_PI / 180) * cos(lat * (M_PI / 180)), worst = 0;
	for (int a = 0; a < nt; a++)
		for (uint32_t i = 0; i < T; i++) {
			bool last = i + 1 == T;
			if (last && a + 1 == nt)
				break;
			float v0 = tile_f32(t[a])[j * T + i];
			float v1 = last ? tile_f32(t[a + 1])[j * T] : tile_f32(t[a])[j * T + i + 1];
			double sl = fabs(v1 - v0) / dx;
			worst = sl > worst ? sl : worst;
		}
	return worst;
}

/* The east–west prefilter (isotropic, file_resample.h) on an image like ETOPO5 near its
 * poles: the two rows next to each pole vary with longitude (±100 m of column noise, the
 * same in both rows) over a smooth function. Near a pole no texel row may be steeper east–
 * west than 1.5 √2 × (the source rows' range / their spacing) on the ground (1.5: a
 * Catmull-Rom curve's slope is up to 1.5× its steepest step; the unfiltered
 * node is >10× steeper there: the test can fail); tiles are the quadrants of a tile of the
 * same spacing (the widened region gives every tile the same filtered rows) and join across
 * the antimeridian; below 44° nothing changes, bit for bit; missing data is still missing. */
static void isotropic_rows(void **state)
{
	(void)state;
	int w = 720, h = 360; /* 0.5° pixels */
	float *px = malloc((size_t)w * h * sizeof *px);
	float lo = INFINITY, hi = -INFINITY;
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++) {
			float v = (float)fn(-180 + (x + 0.5) * 0.5, 90 - (y + 0.5) * 0.5);
			if (y < 2 || y >= h - 2) {
				v += col_noise(x);
				lo = v < lo ? v : lo;
				hi = v > hi ? v : hi;
			}
			px[(size_t)y * w + x] = v;
		}
	char err[256];
	assert_int_equal(img_write(tpath("iso.tif"), w, h, 1, IMG_F32, px, err), 0);
	struct fnode f, raw;
	fnode_ok(&f, "[node x]\ntype = file\npath = iso.tif\n" GLOBAL);
	fnode_ok(&raw, "[node x]\ntype = file\npath = iso.tif\n" GLOBAL_RAW);
	double bound = 1.5 * sqrt(2) * (hi - lo) / (0.5 * M_PI / 180); /* 1.5: Catmull-Rom */

	/* Near both poles, magnified (ly 8: texels 0.011° tall) and coarser, at the viewer's
	 * isotropic and anisotropic lx: three tiles round the antimeridian. */
	static const int lv[][2] = { { 9, 8 }, { 8, 8 }, { 6, 8 }, { 3, 8 }, { 1, 8 },
				     { 7, 6 }, { 4, 6 }, { 5, 4 }, { 2, 4 } };
	for (size_t l = 0; l < sizeof lv / sizeof lv[0]; l++) {
		int lx = lv[l][0], ly = lv[l][1];
		uint32_t nx = 1u << lx, T = 64;
		for (int pole = 0; pole < 2; pole++) {
			uint32_t y = pole ? (1u << ly) - 1 : 0;
			struct tile *t[3], *r[3];
			uint32_t xs[3] = { nx - 1, 0, nx > 1 ? 1 : 0 };
			int nt = nx > 2 ? 3 : 1;
			for (int a = 0; a < nt; a++) {
				t[a] = gen(&f, lx, ly, xs[nt == 1 ? 1 : a], y, T);
				r[a] = gen(&raw, lx, ly, xs[nt == 1 ? 1 : a], y, T);
			}
			double worst = 0, worst_raw = 0;
			for (uint32_t j = 0; j < T; j++) {
				double lon, lat;
				grid_texel_center(&t[0]->key, T, 0, j, &lon, &lat);
				/* Within the caps (past the edge rows' centres) the texels blend
				 * to the pole's mean; beyond the noise rows the image is smooth. */
				if (fabs(lat) > 89.75 || fabs(lat) < 89.25)
					continue;
				double s = ew_slope(t, nt, j), sr = ew_slope(r, nt, j);
				worst = s > worst ? s : worst;
				worst_raw = sr > worst_raw ? sr : worst_raw;
			}
			if (worst > bound || getenv("TEST_VERBOSE"))
				fprintf(stderr, "(%d,%d) %s pole: east-west slope %.0f, unfiltered "
						"%.0f, bound %.0f\n", lx, ly, pole ? "south" : "north",
					worst, worst_raw, bound);
			if (ly >= 6) {
				assert_true(worst > 0);
				assert_true(worst <= bound);
			}
			if (ly == 8 && lx >= 6)
				assert_true(worst_raw > 10 * bound);
			for (int a = 0; a < nt; a++) {
				tile_unref(t[a]);
				tile_unref(r[a]);
			}
		}
	}

	/* Quadrants of a tile with the same texel spacing, at the antimeridian's west side, near
	 * the north pole, magnified and at 1.4 texels a pixel. */
	static const int big[][2] = { { 7, 6 }, { 3, 2 } };
	for (int b = 0; b < 2; b++)
		quadrants_join(&f, big[b][0], big[b][1], 0, 0, 64);

	/* Below 44°: the same bits as without the filter; at 76°, not. */
	static const int same[][4] = { { 6, 5, 9, 10 }, { 4, 3, 5, 3 }, { 5, 4, 7, 5 },
				       { 7, 6, 40, 20 }, { 10, 9, 511, 256 }, { 9, 8, 100, 180 } };
	for (size_t l = 0; l < sizeof same / sizeof same[0]; l++) {
		struct tile *a = gen(&f, same[l][0], same[l][1], (uint32_t)same[l][2],
				     (uint32_t)same[l][3], 64);
		struct tile *b = gen(&raw, same[l][0], same[l][1], (uint32_t)same[l][2],
				     (uint32_t)same[l][3], 64);
		assert_memory_equal(a->data, b->data, 64 * 64 * sizeof(float));
		tile_unref(a);
		tile_unref(b);
	}
	struct tile *a = gen(&f, 7, 6, 40, 5, 64), *b = gen(&raw, 7, 6, 40, 5, 64); /* 75.9° */
	assert_memory_not_equal(a->data, b->data, 64 * 64 * sizeof(float));
	tile_unref(a);
	tile_unref(b);
	fnode_fini(&f);
	fnode_fini(&raw);

	/* Missing samples near the pole: never NaN, never outside the valid values or the fill. */
	for (int y = 0; y < 6; y++)
		for (int x = 300; x < 340; x++)
			px[(size_t)y * w + x] = NAN;
	assert_int_equal(img_write(tpath("isonan.tif"), w, h, 1, IMG_F32, px, err), 0);
	free(px);
	fnode_ok(&f, "[node x]\ntype = file\npath = isonan.tif\nfill = -5000\n" GLOBAL);
	int fills = 0;
	/* Rows 0–1 (filtered over 30–115 pixels: the 40 missing columns are outvoted) and
	 * 4–5 (over ~10: the block's middle stays missing), tiles over and beside the block. */
	for (uint32_t x = 0; x < 16; x++) {
		struct tile *t = gen(&f, 8, 8, 104 + (x & 7) * 3, x < 8 ? 0 : 3, 64);
		for (int i = 0; i < 64 * 64; i++) {
			float v = tile_f32(t)[i];
			if (!(v == -5000 || (v >= lo - 1 && v <= hi + 1)))
				fail_msg("tile %u texel %d: %g", x, i, v);
			fills += v == -5000;
		}
		tile_unref(t);
	}
	assert_true(fills > 0);
	fnode_fini(&f);
}

/* Magnified heights have no creases: between a coarse image's pixel centres they follow a
 * Catmull-Rom curve, whose slope is continuous, not bilinear facets whose slope jumps at
 * every row and column (shaded, each of ETOPO5's 9 km cells showed its edges as straight
 * lines). On random heights magnified 32× (x) and 64× (y): the largest change of slope from
 * one texel to the next, against the largest slope, is ≤ 0.3 (a cubic's: ~6/32; bilinear's:
 * up to 2 at a pixel edge); and the curve passes through the pixels' own values. */
static void magnified_no_creases(void **state)
{
	(void)state;
	int w = 64, h = 32;
	float px[64 * 32];
	for (int i = 0; i < w * h; i++)
		px[i] = col_noise(i * 7 + 3) * 5; /* ±500 m */
	char err[256];
	assert_int_equal(img_write(tpath("coarse.tif"), w, h, 1, IMG_F32, px, err), 0);
	struct fnode f;
	fnode_ok(&f, "[node x]\ntype = file\npath = coarse.tif\n" GLOBAL);
	struct tile *t = gen(&f, 5, 5, 10, 12, 64); /* 2048 × 2048 texels over 64 × 32 px */
	const float *v = tile_f32(t);
	for (int axis = 0; axis < 2; axis++) {
		double slope = 0, bend = 0;
		for (int j = 0; j < 64; j++)
			for (int i = 0; i + 2 < 64; i++) {
				size_t a = axis ? (size_t)i * 64 + j : (size_t)j * 64 + i;
				size_t st = axis ? 64 : 1;
				double d0 = v[a + st] - v[a], d1 = v[a + 2 * st] - v[a + st];
				slope = fmax(slope, fabs(d0));
				bend = fmax(bend, fabs(d1 - d0));
			}
		if (bend > 0.3 * slope || getenv("TEST_VERBOSE"))
			fprintf(stderr, "axis %d: largest slope %.3f m/texel, change %.3f\n", axis,
				slope, bend);
		assert_true(slope > 0);
		assert_true(bend <= 0.3 * slope);
	}
	/* Through the pixels, not shifted: pixel (20, 12)'s centre lies between texels 15, 16
	 * of the tile (x: 32 a pixel, from texel 640) and 31, 32 (y: 64 a pixel, from 768). */
	double mean = (v[31 * 64 + 15] + v[31 * 64 + 16] + v[32 * 64 + 15] + v[32 * 64 + 16]) / 4;
	assert_float_equal(mean, px[12 * w + 20], 1.0);
	tile_unref(t);
	fnode_fini(&f);
}

/* The ½ contour of a 0/1 mask magnified 16 times, along each texel row of a tile of level
 * (3, 2) (16 × 16 pixels of a 128 × 64 image, between 45°N and the equator): the column
 * where each row crosses ½, in pixels. What the eye sees of a staircase: the largest move of
 * the contour from one texel row to the next (*step: a riser runs nearly along the rows) and
 * the largest change of that move (*kink: the corners). Returns the rows crossed. */
static int contour_shape(const struct tile *t, uint32_t T, double *step, double *kink)
{
	const float *v = tile_f32(t);
	double xs[256];
	int n = 0;
	for (uint32_t j = 0; j < T && n < 256; j++)
		for (uint32_t i = 0; i + 1 < T; i++) {
			double a = v[j * T + i], b = v[j * T + i + 1];
			if (a < 0.5 && b >= 0.5) {
				xs[n++] = (i + (0.5 - a) / (b - a) + 0.5) / 16;
				break;
			}
		}
	*step = *kink = 0;
	for (int k = 1; k < n; k++)
		*step = fmax(*step, fabs(xs[k] - xs[k - 1]));
	for (int k = 1; k + 1 < n; k++)
		*kink = fmax(*kink, fabs(xs[k + 1] - 2 * xs[k] + xs[k - 1]));
	return n;
}

/* magnify = bspline: a 0/1 mask with a straight edge (0.6 pixels east per row, so every
 * row's edge is rounded to a whole pixel: a staircase) has a ½ contour without risers or
 * corners — from one texel row to the next (1/16 pixel) it moves at most twice the edge's
 * own 0.0375 pixels and bends by under 0.01 (measured 0.067 and 0.006), where Catmull-Rom's
 * moves 0.148 and bends 0.032. (No filter straightens it: the rounding's error repeats every
 * five rows, a wave either way wobbles 0.3–0.5 pixels off the line.) Its hash differs from
 * the default's, an absent key leaves the hash as it was (planets' stores stay valid), and
 * the key is for heights only. */
static void bspline_mask_contour(void **state)
{
	(void)state;
	enum { W = 128, H = 64, T = 256 };
	static float px[W * H];
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++)
			px[y * W + x] = x > 68 + 0.6 * (y - 16) ? 1.0f : 0.0f;
	char err[256];
	assert_int_equal(img_write(tpath("mask.tif"), W, H, 1, IMG_F32, px, err), 0);
	struct fnode cr, bs, cr2;
	fnode_ok(&cr, "[node x]\ntype = file\npath = mask.tif\n" GLOBAL_RAW);
	fnode_ok(&bs, "[node x]\ntype = file\npath = mask.tif\nmagnify = bspline\n" GLOBAL_RAW);
	fnode_ok(&cr2, "[node x]\ntype = file\npath = mask.tif\nmagnify = cubic\n" GLOBAL_RAW);
	assert_true(cr.n.hash != bs.n.hash);
	assert_true(cr.n.hash != cr2.n.hash); /* given, it is hashed */
	struct tile *tc = gen(&cr, 3, 2, 4, 1, T), *tb = gen(&bs, 3, 2, 4, 1, T);
	double sc, kc, sb, kb;
	int nc = contour_shape(tc, T, &sc, &kc), nb = contour_shape(tb, T, &sb, &kb);
	print_message("½ contour per texel row: Catmull-Rom moves ≤ %.3f px, bends ≤ %.4f px; "
		      "B-spline %.3f, %.4f\n", sc, kc, sb, kb);
	assert_int_equal(nb, T);
	assert_int_equal(nc, T);
	assert_true(sb <= 2 * 0.6 / 16 && kb < 0.01);
	assert_true(sc > 3 * 0.6 / 16 && kc > 0.02);

	/* between 0 and 1 everywhere (Catmull-Rom overshoots) */
	const float *v = tile_f32(tb);
	for (uint32_t i = 0; i < T * T; i++)
		assert_true(v[i] >= 0 && v[i] <= 1);
	tile_unref(tc);
	tile_unref(tb);
	fnode_fini(&cr);
	fnode_fini(&bs);
	fnode_fini(&cr2);

	static const struct {
		const char *text, *want;
	} bad[] = {
		{ "[node x]\ntype = file\npath = mask.tif\nmagnify = lanczos\n" GLOBAL_RAW,
		  "test.ini:4: magnify: " },
		{ "[node x]\ntype = file\npath = ok8.png\nkind = color\nmagnify = bspline\n" GLOBAL,
		  "test.ini:5: magnify: only applies to kind = height" },
	};
	uint8_t grey8[16 * 8] = { 0 };
	assert_int_equal(img_write(tpath("ok8.png"), 16, 8, 1, IMG_U8, grey8, err), 0);
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		struct fnode f;
		char e2[256] = "";
		int rc = fnode_init(&f, bad[i].text, e2);
		if (rc != -EINVAL || strncmp(e2, bad[i].want, strlen(bad[i].want)) != 0)
			fail_msg("case %zu: rc %d, err \"%s\", want \"%s\"", i, rc, e2, bad[i].want);
		fnode_fini(&f);
	}
}

/* A one-pixel line of 1 in a 0/1 mask, 16 × 16 pixels over exactly one tile of level (5, 4)
 * (0..11.25°E, 0..11.25°N: 16 texels a pixel), magnified with `magnify = bspline`: along
 * every texel row the B-spline's hump, peaking at ⅔ and changing by under 0.1 from texel to
 * texel — beside a bounded image's edge (the line in the second column, where Catmull-Rom
 * turns bilinear and a B-spline that did the same stepped by ⅓ to the pixel's 1), and in a
 * tile with a void in it (NaN at pixel 12, 12: Catmull-Rom's tile turns bilinear, a B-spline
 * that did the same would draw the line at 1 here and ⅔ in the tiles around). */
static void bspline_edges_and_voids(void **state)
{
	(void)state;
	enum { N = 16, T = 256 };
	for (int c = 0; c < 2; c++) {
		int col = c ? 8 : 1;
		float px[N * N];
		for (int i = 0; i < N * N; i++)
			px[i] = i % N == col ? 1.0f : 0.0f;
		if (c)
			px[12 * N + 12] = NAN;
		char err[256];
		assert_int_equal(img_write(tpath("line.tif"), N, N, 1, IMG_F32, px, err), 0);
		struct fnode f;
		fnode_ok(&f, "[node x]\ntype = file\npath = line.tif\nbounds = 0,0,11.25,11.25\n"
			 "isotropic = false\nmagnify = bspline\n");
		struct tile *t = gen(&f, 5, 4, 16, 7, T);
		const float *v = tile_f32(t);
		double lo = 1, hi = 0, jump = 0;
		for (uint32_t j = 0; j < 9 * 16; j++) { /* rows clear of the void's reach */
			double peak = 0;
			for (uint32_t i = 0; i < T; i++) {
				peak = fmax(peak, v[j * T + i]);
				if (i)
					jump = fmax(jump, fabs(v[j * T + i] - v[j * T + i - 1]));
			}
			lo = fmin(lo, peak), hi = fmax(hi, peak);
		}
		print_message("line in column %d%s: peaks %.3f..%.3f, largest step %.3f\n", col,
			      c ? " (a void in the tile)" : "", lo, hi, jump);
		assert_true(lo > 0.6 && hi < 0.7);
		assert_true(jump < 0.1);
		tile_unref(t);
		fnode_fini(&f);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(analytic_global),
		cmocka_unit_test(tiles_join),
		cmocka_unit_test(sub_region),
		cmocka_unit_test(coarse_is_filtered),
		cmocka_unit_test(nodata),
		cmocka_unit_test(color_channels),
		cmocka_unit_test(isotropic_rows),
		cmocka_unit_test(magnified_no_creases),
		cmocka_unit_test(bspline_mask_contour),
		cmocka_unit_test(bspline_edges_and_voids),
		cmocka_unit_test(bad_params),
		cmocka_unit_test(content_hash),
		cmocka_unit_test(content_hash_copies),
		cmocka_unit_test(digest_sidecar),
		cmocka_unit_test(concurrent_generate),
		cmocka_unit_test(shared_cache),
		cmocka_unit_test(changed_file_reread),
		cmocka_unit_test(geotiff_placed),
		cmocka_unit_test(no_georef_refused),
		cmocka_unit_test(truncated_refused),
		cmocka_unit_test(runtime_failure_reported_once),
		cmocka_unit_test(kind_mismatch_refused),
		cmocka_unit_test(huge_nodata_coarse),
	};
	return cmocka_run_group_tests_name("file_node", tests, setup, teardown);
}
