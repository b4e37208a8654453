/* test_import — `clipmapctl import` (client/ctl/import.c) on small GeoTIFFs written with GDAL in
 * the test: pixels and bounds survive the round trip (tiled, mipmapped, bounds in the
 * description) and the `file` node places them from the recorded bounds; a global raster
 * from 0..360° comes out starting at −180°, a south-up one north-up; integer nodata is
 * recorded and honoured; errors name the file and the problem. The import streams: sources
 * read in several bands (rows not a multiple of the band) give the same pixels, the same MIP
 * levels as OpenImageIO's make_texture of the whole image (the old in-memory path) and as a
 * box/bilinear reference computed here; a truncated source fails clearly and leaves neither
 * the destination nor its .tmp behind (an older destination stays as it was). The row streak
 * repair mends a scan-line defect across a band's edge and leaves short, shallow, void-cut
 * and edge rows as they are. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <gdal/gdal.h>
#include <gdal/cpl_conv.h>
#include <gdal/gdalwarper.h>
#include <gdal/ogr_srs_api.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "client/ctl/import.h"
#include "common/img.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"

static char dir[64];

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
	snprintf(dir, sizeof dir, "/tmp/test_import.XXXXXX");
	if (!mkdtemp(dir))
		return -1;
	GDALAllRegister();
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
	return system(cmd) == 0 ? 0 : -1;
}

static int16_t pix(int x, int y)
{
	return (int16_t)(x * 100 - y * 7 + 3 + (x * x + 3 * y * y) % 97); /* not linear */
}

/* A w×h int16 GeoTIFF of the pixels px (rows as GDAL stores them) with geotransform gt in
 * EPSG:epsg. */
static void write_geotiff_px(const char *path, int w, int h, const double gt[6], int epsg,
			     const double *nodata, const int16_t *px)
{
	GDALDriverH drv = GDALGetDriverByName("GTiff");
	assert_non_null(drv);
	GDALDatasetH ds = GDALCreate(drv, path, w, h, 1, GDT_Int16, NULL);
	assert_non_null(ds);
	assert_int_equal(GDALSetGeoTransform(ds, (double *)gt), CE_None);
	OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(srs, epsg), OGRERR_NONE);
	assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
	OSRDestroySpatialReference(srs);
	GDALRasterBandH b = GDALGetRasterBand(ds, 1);
	if (nodata)
		assert_int_equal(GDALSetRasterNoDataValue(b, *nodata), CE_None);
	assert_int_equal(GDALRasterIO(b, GF_Write, 0, 0, w, h, (void *)px, w, h, GDT_Int16, 0,
				      0),
			 CE_None);
	GDALClose(ds);
}

/* A w×h int16 GeoTIFF with geotransform gt in EPSG:epsg (pixel (x, y) = pix(x, y)). */
static void write_geotiff(const char *path, int w, int h, const double gt[6], int epsg,
			  const double *nodata)
{
	int16_t *buf = malloc(sizeof *buf * (size_t)w * h);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			buf[(size_t)y * w + x] = pix(x, y);
	write_geotiff_px(path, w, h, gt, epsg, nodata, buf);
	free(buf);
}

static void read_back(const char *path, int w, int h, int16_t **px, char desc[256])
{
	struct img_info info;
	char err[256];
	void *p;
	if (img_read(path, IMG_NONE, &p, &info, err))
		fail_msg("%s", err);
	assert_int_equal(info.width, w);
	assert_int_equal(info.height, h);
	assert_int_equal(info.type, IMG_I16);
	assert_true(info.tiled);
	struct img_cache *c = img_cache_create(16);
	struct img_info ci;
	assert_int_equal(img_cache_info(c, path, &ci, err), 0);
	assert_true(ci.mip_levels > 1);
	assert_int_equal(img_cache_description(c, path, desc, 256, err), 0);
	img_cache_unref(c);
	*px = p;
}

static void round_trip(void **state)
{
	(void)state;
	const double gt[6] = { 10, 0.5, 0, 50, 0, -0.5 }; /* 10..30°E, 40..50°N */
	write_geotiff(tpath("a.tif"), 40, 20, gt, 4326, NULL);
	struct import_result r;
	char err[256] = "", desc[256];
	if (import_raster(tpath("a.tif"), tpath("a_out.tif"), NULL, &r, err))
		fail_msg("%s", err);
	assert_true(r.georeferenced);
	assert_false(r.flipped_rows);
	assert_int_equal(r.shifted_cols, 0);
	assert_true(r.west == 10 && r.east == 30 && r.south == 40 && r.north == 50);
	int16_t *px;
	read_back(tpath("a_out.tif"), 40, 20, &px, desc);
	for (int y = 0; y < 20; y++)
		for (int x = 0; x < 40; x++)
			if (px[y * 40 + x] != pix(x, y))
				fail_msg("pixel %d,%d = %d, want %d", x, y, px[y * 40 + x], pix(x, y));
	free(px);
	assert_string_equal(desc, "clipmap:bounds=10,40,30,50");
	/* GeoTIFF tags too: GDAL (what gdalinfo and QGIS use) reads EPSG:4326 and the corners */
	struct img_georef geo;
	assert_int_equal(img_georef_read(tpath("a_out.tif"), &geo, err), 0);
	assert_true(geo.georeferenced);
	assert_true(geo.west == 10 && geo.east == 30 && geo.south == 40 && geo.north == 50);
	GDALDatasetH gd = GDALOpen(tpath("a_out.tif"), GA_ReadOnly);
	assert_non_null(gd);
	double ogt[6];
	assert_int_equal(GDALGetGeoTransform(gd, ogt), CE_None);
	assert_true(ogt[0] == 10 && ogt[1] == 0.5 && ogt[3] == 50 && ogt[5] == -0.5);
	OGRSpatialReferenceH osr = GDALGetSpatialRef(gd);
	assert_non_null(osr);
	const char *code = OSRGetAuthorityCode(osr, NULL);
	assert_non_null(code);
	assert_string_equal(code, "4326");
	assert_true(GDALGetRasterCount(gd) == 1 && GDALGetRasterXSize(gd) == 40);
	GDALClose(gd);

	/* The file node places the image from the recorded bounds alone. */
	static struct planet pl = { .tile_size = 64, .max_level = 10, .a = 6378137.0 };
	pl.dir = dir;
	char text[256];
	snprintf(text, sizeof text, "[node x]\ntype = file\npath = a_out.tif\nfill = -999\n");
	struct ini_file *ini;
	assert_int_equal(ini_parse("t.ini", text, strlen(text), &ini, err), 0);
	struct ini_section *sec = &ini->sections[0];
	ini_find(sec, "type")->used = true;
	struct node n = { .name = "x", .planet = &pl };
	if (node_init(&n, &node_type_file, "t.ini", sec, err))
		fail_msg("%s", err);
	/* Level (12, 11) with T = 64: texels of 360/2^18 ≈ 0.00137°; pixel (x, y) covers
	 * [10 + x/2, 10.5 + x/2] × [49.5 - y/2, 50 - y/2]: its centre texel holds pix(x, y). */
	double lon = 10 + 7 * 0.5 + 0.25, lat = 50 - 3 * 0.5 - 0.25;
	uint32_t u = (uint32_t)floor((lon + 180) / 360 * 4096 * 64);
	uint32_t v = (uint32_t)floor((90 - lat) / 180 * 2048 * 64);
	struct tile_key k = { .node = n.hash, .lx = 12, .ly = 11, .x = u / 64, .y = v / 64 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, 64);
	struct gen_ctx g = { 0 };
	assert_int_equal(n.type->generate(&n, &g, &k, NULL, 0, t), 0);
	float got = tile_f32(t)[(v % 64) * 64 + u % 64];
	if (fabsf(got - pix(7, 3)) > 0.5f)
		fail_msg("file node at %g,%g: %g, want %d", lat, lon, got, pix(7, 3));
	/* Outside the bounds: the fill. */
	k.x = 0;
	assert_int_equal(n.type->generate(&n, &g, &k, NULL, 0, t), 0);
	assert_true(tile_f32(t)[0] == -999);
	tile_unref(t);
	gen_ctx_fini(&g);
	node_fini(&n);
	ini_free(ini);
}

static void global_shift_and_flip(void **state)
{
	(void)state;
	/* 36×18 pixels of 10°, longitudes 0..360, rows south→north (positive y step). */
	const double gt[6] = { 0, 10, 0, -90, 0, 10 };
	double nd = -32768;
	write_geotiff(tpath("g.tif"), 36, 18, gt, 4326, &nd);
	struct import_result r;
	char err[256] = "", desc[256];
	if (import_raster(tpath("g.tif"), tpath("g_out.tif"), NULL, &r, err))
		fail_msg("%s", err);
	assert_true(r.flipped_rows);
	assert_int_equal(r.shifted_cols, 18);
	assert_true(r.west == -180 && r.east == 180 && r.south == -90 && r.north == 90);
	int16_t *px;
	read_back(tpath("g_out.tif"), 36, 18, &px, desc);
	/* Output (x, y): lon -180 + 10x (source column x + 18 mod 36), north row first (source
	 * row 17 - y). */
	for (int y = 0; y < 18; y++)
		for (int x = 0; x < 36; x++) {
			int16_t want = pix((x + 18) % 36, 17 - y);
			if (px[y * 36 + x] != want)
				fail_msg("pixel %d,%d = %d, want %d", x, y, px[y * 36 + x], want);
		}
	free(px);
	assert_string_equal(desc, "clipmap:bounds=-180,-90,180,90 clipmap:nodata=-32768");

	/* --bounds overrides; --band picks a band. */
	struct import_opts o = { .has_bounds = true, .bounds = { -10, -5, 10, 5 }, .band = 1 };
	if (import_raster(tpath("g.tif"), tpath("g2.tif"), &o, &r, err))
		fail_msg("%s", err);
	assert_int_equal(r.shifted_cols, 0);
	assert_true(r.west == -10 && r.north == 5);
}

static void expect_error(const char *src, const char *dst, const struct import_opts *o,
			 int want_rc, const char *want1, const char *want2)
{
	char err[256] = "";
	int rc = import_raster(src, dst, o, NULL, err);
	if (rc != want_rc || !strstr(err, want1) || (want2 && !strstr(err, want2)))
		fail_msg("import %s: rc %d \"%s\", want %d with \"%s\" and \"%s\"", src, rc, err,
			 want_rc, want1, want2 ? want2 : "");
	assert_int_equal(access(dst, F_OK), -1);
}

static void errors(void **state)
{
	(void)state;
	expect_error(tpath("nope.tif"), tpath("e1.tif"), NULL, -ENOENT, "nope.tif",
		     "No such file");
	FILE *f = fopen(tpath("text.dat"), "w");
	assert_non_null(f);
	fputs("this is not a raster\n", f);
	assert_int_equal(fclose(f), 0);
	expect_error(tpath("text.dat"), tpath("e2.tif"), NULL, -EINVAL, "text.dat",
		     "not a raster GDAL can read");
	const double gt[6] = { 10, 0.5, 0, 50, 0, -0.5 };
	write_geotiff(tpath("b.tif"), 8, 4, gt, 4326, NULL);
	struct import_opts o = { .band = 3 };
	expect_error(tpath("b.tif"), tpath("e3.tif"), &o, -EINVAL, "b.tif", "no band 3");
	expect_error(tpath("b.tif"), tpath("e4.png"), NULL, -EINVAL, "e4.png", "extension");
}

/* All MIP levels of path as int16, level m at lv[m] (sizes in lw, lh); returns the count. */
static int read_levels(const char *path, int16_t *lv[16], int lw[16], int lh[16])
{
	struct img_cache *c = img_cache_create(64);
	struct img_info ci;
	char err[256];
	if (img_cache_info(c, path, &ci, err))
		fail_msg("%s", err);
	assert_true(ci.mip_levels <= 16);
	for (int m = 0; m < ci.mip_levels; m++) {
		assert_int_equal(img_cache_level_size(c, path, m, &lw[m], &lh[m], err), 0);
		lv[m] = malloc(sizeof(int16_t) * (size_t)lw[m] * (size_t)lh[m]);
		if (img_cache_read(c, path, m, 0, lw[m], 0, lh[m], 0, 1, IMG_I16, lv[m], 0, err))
			fail_msg("%s", err);
	}
	img_cache_unref(c);
	return ci.mip_levels;
}

/* The pyramid the importer promises, computed independently in double: each level halves
 * (rounding down, not below 1); a 2×2 box where both sides of the level above are even,
 * otherwise a bilinear sample of the level above at the destination pixel's centre (edges
 * clamped). Values stay unrounded from level to level; the stored int16 is the rounded one. */
static double *ref_level(const double *src, int sw, int sh, int dw, int dh)
{
	double *d = malloc(sizeof *d * (size_t)dw * (size_t)dh);
	for (int y = 0; y < dh; y++)
		for (int x = 0; x < dw; x++) {
			double v;
			if (sw % 2 == 0 && sh % 2 == 0) {
				const double *a = src + (size_t)(2 * y) * sw + 2 * x;
				v = (a[0] + a[1] + a[sw] + a[sw + 1]) / 4;
			} else {
				double fx = (x + 0.5) * sw / dw - 0.5, fy = (y + 0.5) * sh / dh - 0.5;
				int x0 = (int)floor(fx), y0 = (int)floor(fy);
				double ax = fx - x0, ay = fy - y0;
				int xa = x0 < 0 ? 0 : x0, xb = x0 + 1 > sw - 1 ? sw - 1 : x0 + 1;
				int ya = y0 < 0 ? 0 : y0, yb = y0 + 1 > sh - 1 ? sh - 1 : y0 + 1;
				if (xb < 0)
					xb = 0;
				if (yb < 0)
					yb = 0;
				v = (1 - ay) * ((1 - ax) * src[(size_t)ya * sw + xa] +
						ax * src[(size_t)ya * sw + xb]) +
				    ay * ((1 - ax) * src[(size_t)yb * sw + xa] +
					  ax * src[(size_t)yb * sw + xb]);
			}
			d[(size_t)y * dw + x] = v;
		}
	return d;
}

static void streaming_bands(void **state)
{
	(void)state;
	/* 72×100 pixels of 5°, longitudes 0..360, rows south→north: read in bands of 32 rows
	 * (tile 16) from the bottom up, the last band 4 rows; columns rotated by 36. */
	enum { W = 72, H = 100 };
	const double gt[6] = { 0, 5, 0, -90, 0, 1.8 };
	write_geotiff(tpath("s.tif"), W, H, gt, 4326, NULL);
	struct import_opts o = { .tile = 16, .band_rows = 32 };
	struct import_result r;
	char err[256] = "", desc[256];
	if (import_raster(tpath("s.tif"), tpath("s_out.tif"), &o, &r, err))
		fail_msg("%s", err);
	assert_true(r.flipped_rows);
	assert_int_equal(r.shifted_cols, 36);
	struct img_cache *c = img_cache_create(16);
	assert_int_equal(img_cache_description(c, tpath("s_out.tif"), desc, sizeof desc, err), 0);
	img_cache_unref(c);
	assert_string_equal(desc, "clipmap:bounds=-180,-90,180,90");
	assert_int_equal(access(tpath("s_out.tif.tmp"), F_OK), -1);

	/* Level 0: every pixel where it belongs. */
	int16_t *want = malloc(sizeof *want * W * H);
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++)
			want[y * W + x] = pix((x + 36) % W, H - 1 - y);
	int16_t *lv[16];
	int lw[16], lh[16];
	int nl = read_levels(tpath("s_out.tif"), lv, lw, lh);
	assert_int_equal(nl, 7); /* 72×100 36×50 18×25 9×12 4×6 2×3 1×1 */
	assert_int_equal(lw[0], W);
	assert_int_equal(lh[0], H);
	assert_memory_equal(lv[0], want, sizeof *want * W * H);

	/* Every level: the independent reference (within the last unit: ties round either way
	 * in float) ... */
	double *ref = malloc(sizeof *ref * W * H);
	for (int i = 0; i < W * H; i++)
		ref[i] = want[i];
	int w = W, h = H;
	for (int m = 1; m < nl; m++) {
		int dw = w > 1 ? w / 2 : 1, dh = h > 1 ? h / 2 : 1;
		assert_int_equal(lw[m], dw);
		assert_int_equal(lh[m], dh);
		double *d = ref_level(ref, w, h, dw, dh);
		for (int i = 0; i < dw * dh; i++)
			if (fabs(lv[m][i] - d[i]) > 1.0)
				fail_msg("level %d pixel %d,%d = %d, reference %.3f", m, i % dw, i / dw,
					 lv[m][i], d[i]);
		free(ref);
		ref = d, w = dw, h = dh;
	}
	free(ref);

	/* ... and exactly what the in-memory writer (OIIO make_texture) makes of the image. */
	assert_int_equal(img_write_tiled_desc(tpath("s_ref.tif"), W, H, 1, IMG_I16, want, 16, true,
					      desc, err), 0);
	int16_t *rv[16];
	int rw[16], rh[16];
	assert_int_equal(read_levels(tpath("s_ref.tif"), rv, rw, rh), nl);
	for (int m = 0; m < nl; m++) {
		assert_int_equal(rw[m], lw[m]);
		assert_int_equal(rh[m], lh[m]);
		if (memcmp(rv[m], lv[m], sizeof(int16_t) * (size_t)lw[m] * (size_t)lh[m]))
			fail_msg("level %d differs from make_texture's", m);
		free(rv[m]);
		free(lv[m]);
	}

	/* The same source in one band: the same file contents. */
	o.band_rows = 0;
	if (import_raster(tpath("s.tif"), tpath("s_one.tif"), &o, &r, err))
		fail_msg("%s", err);
	nl = read_levels(tpath("s_one.tif"), rv, rw, rh);
	int n2 = read_levels(tpath("s_out.tif"), lv, lw, lh);
	assert_int_equal(nl, n2);
	for (int m = 0; m < nl; m++) {
		assert_memory_equal(rv[m], lv[m], sizeof(int16_t) * (size_t)lw[m] * (size_t)lh[m]);
		free(rv[m]);
		free(lv[m]);
	}
	free(want);
}

/* --repair-rows (client/ctl/streaks.h) on a source laid out as ETOPO5 is (0..360°, rows
 * south→north, so the repair sees rows after the flip and the column rotation), read in
 * bands of 16 rows so that the two streaks sit on either side of a band's edge, side by side
 * in columns as ETOPO5's do. Output pixel (x, y) is clean(x, y) = 1000 + 10x + 5y wherever
 * the repair should leave or make it so. */
static int16_t clean(int x, int y)
{
	return (int16_t)(1000 + 10 * x + 5 * y);
}

static void row_streaks(void **state)
{
	(void)state;
	enum { W = 96, H = 64, ND = -32768 };
	static int16_t out[H][W], src[H * W];
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++)
			out[y][x] = clean(x, y);
	for (int x = 10; x < 70; x++) /* a trench: 60 pixels, 2 km deep, last row of band 0 */
		out[15][x] -= 2000;
	out[15][8] -= 300, out[15][9] -= 300; /* its ends continue it beyond 500 / 8 ... */
	out[15][7] -= 50;		      /* ... and end where it no longer does */
	for (int x = 70; x < 94; x++)	      /* a wall: 24 pixels, first row of band 1 */
		out[16][x] += 1500;
	for (int x = 20; x < 30; x++) /* kept: a narrow valley 10 pixels long */
		out[40][x] -= 3000;
	for (int x = 0; x < W; x++) /* kept: a whole row 400 below, under the threshold */
		out[45][x] -= 400;
	for (int x = 10; x < 50; x++) /* kept: a nodata void cuts it into runs of 20 and 19 */
		out[50][x] += 1000;
	out[50][30] = ND;
	for (int x = 0; x < W; x++) /* kept: the first and last rows have one neighbour */
		out[0][x] += 1000, out[H - 1][x] += 1000;
	/* kept: under the trench, 1200 down over 28 pixels, between the trench as read and the
	 * row below it (against the trench as repaired it would be a streak of its own); the
	 * trench above it is mended to the mean of its neighbours as read, 600 below clean */
	for (int x = 20; x < 48; x++)
		out[16][x] -= 1200;
	/* output (x, y) is source column (x + 48) mod 96 at source row H - 1 - y */
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++)
			src[(H - 1 - y) * W + (x + 48) % W] = out[y][x];
	const double gt[6] = { 0, 3.75, 0, -90, 0, 180.0 / H };
	double nd = ND;
	write_geotiff_px(tpath("k.tif"), W, H, gt, 4326, &nd, src);

	for (int pass = 0; pass < 2; pass++) {
		struct import_opts o = { .tile = 16, .band_rows = pass ? 0 : 16,
					 .repair_rows = 500, .repair_len = 24 };
		struct import_result r;
		char err[256] = "", desc[256];
		if (import_raster(tpath("k.tif"), tpath("k_out.tif"), &o, &r, err))
			fail_msg("%s", err);
		assert_true(r.flipped_rows);
		assert_int_equal(r.shifted_cols, 48);
		assert_int_equal(r.repaired, 62 + 24);
		int16_t *px;
		read_back(tpath("k_out.tif"), W, H, &px, desc);
		for (int y = 0; y < H; y++)
			for (int x = 0; x < W; x++) {
				bool fixed = (y == 15 && x >= 8 && x < 70) ||
					     (y == 16 && x >= 70 && x < 94);
				int16_t want = !fixed		    ? out[y][x]
					       : y == 15 && x >= 20 && x < 48 ? clean(x, y) - 600
									 : clean(x, y);
				if (px[y * W + x] != want)
					fail_msg("band rows %d: pixel %d,%d = %d, want %d (read %d)",
						 o.band_rows, x, y, px[y * W + x], want, out[y][x]);
			}
		free(px);
	}
	/* Off by default: the same pixels as read. */
	struct import_result r;
	char err[256] = "", desc[256];
	if (import_raster(tpath("k.tif"), tpath("k_raw.tif"), NULL, &r, err))
		fail_msg("%s", err);
	assert_int_equal(r.repaired, 0);
	int16_t *px;
	read_back(tpath("k_raw.tif"), W, H, &px, desc);
	assert_memory_equal(px, out, sizeof out);
	free(px);
}

static void truncated_source(void **state)
{
	(void)state;
	/* An uncompressed striped GeoTIFF cut to 40 %: its header is intact, rows past the cut
	 * are missing. */
	enum { W = 64, H = 200 };
	const double gt[6] = { -180, 360.0 / W, 0, 90, 0, -180.0 / H };
	write_geotiff(tpath("t.tif"), W, H, gt, 4326, NULL);
	FILE *f = fopen(tpath("t.tif"), "rb");
	assert_non_null(f);
	unsigned char *all = malloc(1 << 20);
	size_t n = fread(all, 1, 1 << 20, f);
	fclose(f);
	assert_true(n > (size_t)W * H * 2);
	f = fopen(tpath("t_cut.tif"), "wb");
	assert_non_null(f);
	assert_int_equal(fwrite(all, 1, n * 4 / 10, f), n * 4 / 10);
	assert_int_equal(fclose(f), 0);
	free(all);

	/* An older destination survives a failed import untouched. */
	struct import_opts o = { .tile = 16, .band_rows = 16 };
	char err[256] = "";
	if (import_raster(tpath("t.tif"), tpath("t_out.tif"), &o, NULL, err))
		fail_msg("%s", err);
	struct stat st0, st1;
	assert_int_equal(stat(tpath("t_out.tif"), &st0), 0);
	int rc = import_raster(tpath("t_cut.tif"), tpath("t_out.tif"), &o, NULL, err);
	if (rc != -EIO || !strstr(err, "t_cut.tif") || !strstr(err, "read failed"))
		fail_msg("truncated source: rc %d \"%s\"", rc, err);
	assert_int_equal(stat(tpath("t_out.tif"), &st1), 0);
	assert_true(st0.st_ino == st1.st_ino && st0.st_size == st1.st_size &&
		    st0.st_mtim.tv_sec == st1.st_mtim.tv_sec &&
		    st0.st_mtim.tv_nsec == st1.st_mtim.tv_nsec);
	assert_int_equal(access(tpath("t_out.tif.tmp"), F_OK), -1);
	/* And with no older destination: nothing at all. */
	expect_error(tpath("t_cut.tif"), tpath("t_new.tif"), &o, -EIO, "t_cut.tif", "read failed");
	assert_int_equal(access(tpath("t_new.tif.tmp"), F_OK), -1);
}

/* The plane a UTM test raster holds: metres east and north of its origin, scaled. */
static double utm_plane(double e, double n)
{
	return 0.01 * (e - 400000) + 0.02 * (n - 5580000) + 100;
}

/* A float32 UTM 33N raster (w×h pixels of 100 m from 400000 E, 5600000 N: about 13.6°E,
 * 50.5°N) holding utm_plane at pixel centres. */
static void write_utm(const char *path, int w, int h)
{
	GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), path, w, h, 1, GDT_Float32, NULL);
	assert_non_null(ds);
	double gt[6] = { 400000, 100, 0, 5600000, 0, -100 };
	assert_int_equal(GDALSetGeoTransform(ds, gt), CE_None);
	OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(srs, 32633), OGRERR_NONE);
	assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
	OSRDestroySpatialReference(srs);
	float *buf = malloc(sizeof *buf * (size_t)w * h);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			buf[(size_t)y * w + x] = (float)utm_plane(gt[0] + (x + 0.5) * 100,
								  gt[3] - (y + 0.5) * 100);
	assert_int_equal(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Write, 0, 0, w, h, buf, w, h,
				      GDT_Float32, 0, 0), CE_None);
	free(buf);
	GDALClose(ds);
}

/* Issue 19: a UTM raster is reprojected at import (not refused): its pixels equal what
 * GDAL's warper to EPSG:4326 makes of it (gdalwarp -t_srs EPSG:4326 -r bilinear), at the
 * same place, and every pixel holds the plane at its centre projected back to UTM (checked
 * with OGR's transform: the place is right, not just the same as the warper's). */
static void utm_reprojected(void **state)
{
	(void)state;
	int w = 300, h = 200;
	write_utm(tpath("utm.tif"), w, h);
	struct import_result r;
	char err[256] = "";
	if (import_raster(tpath("utm.tif"), tpath("utm_out.tif"), NULL, &r, err))
		fail_msg("%s", err);
	assert_true(r.reprojected);
	assert_true(r.georeferenced);
	assert_int_equal(r.type, IMG_F32);

	/* The reference: GDAL's warper, as gdalwarp -t_srs EPSG:4326 -r bilinear (the VRT that
	 * gdalwarp -of VRT makes). */
	GDALDatasetH src = GDALOpen(tpath("utm.tif"), GA_ReadOnly);
	assert_non_null(src);
	OGRSpatialReferenceH geo = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(geo, 4326), OGRERR_NONE);
	OSRSetAxisMappingStrategy(geo, OAMS_TRADITIONAL_GIS_ORDER);
	char *wkt = NULL;
	assert_int_equal(OSRExportToWkt(geo, &wkt), OGRERR_NONE);
	GDALDatasetH ref = GDALAutoCreateWarpedVRT(src, NULL, wkt, GRA_Bilinear, 0.125, NULL);
	CPLFree(wkt);
	assert_non_null(ref);
	int rw = GDALGetRasterXSize(ref), rh = GDALGetRasterYSize(ref);
	double rgt[6];
	assert_int_equal(GDALGetGeoTransform(ref, rgt), CE_None);
	assert_int_equal(r.width, rw);
	assert_int_equal(r.height, rh);
	double tol = 1e-9;
	if (fabs(r.west - rgt[0]) > tol || fabs(r.north - rgt[3]) > tol ||
	    fabs(r.east - (rgt[0] + rw * rgt[1])) > tol || fabs(r.south - (rgt[3] + rh * rgt[5])) > tol)
		fail_msg("bounds %.9f,%.9f,%.9f,%.9f, gdalwarp's %.9f,%.9f,%.9f,%.9f", r.west,
			 r.south, r.east, r.north, rgt[0], rgt[3] + rh * rgt[5], rgt[0] + rw * rgt[1],
			 rgt[3]);
	assert_true(r.west > 13 && r.east < 15 && r.south > 50 && r.north < 51);
	float *want = malloc(sizeof *want * (size_t)rw * rh);
	assert_int_equal(GDALRasterIO(GDALGetRasterBand(ref, 1), GF_Read, 0, 0, rw, rh, want, rw, rh,
				      GDT_Float32, 0, 0), CE_None);
	GDALClose(ref);
	GDALClose(src);

	/* The import, read back (GDAL: level 0 of the pyramid). */
	GDALDatasetH out = GDALOpen(tpath("utm_out.tif"), GA_ReadOnly);
	assert_non_null(out);
	const char *desc = GDALGetMetadataItem(out, "TIFFTAG_IMAGEDESCRIPTION", NULL);
	assert_non_null(desc);
	assert_non_null(strstr(desc, "clipmap:bounds="));
	float *got = malloc(sizeof *got * (size_t)rw * rh);
	assert_int_equal(GDALRasterIO(GDALGetRasterBand(out, 1), GF_Read, 0, 0, rw, rh, got, rw, rh,
				      GDT_Float32, 0, 0), CE_None);
	GDALClose(out);

	OGRSpatialReferenceH utm = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(utm, 32633), OGRERR_NONE);
	OSRSetAxisMappingStrategy(utm, OAMS_TRADITIONAL_GIS_ORDER);
	OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(geo, utm);
	assert_non_null(ct);
	int inside = 0, outside = 0;
	double worst = 0;
	for (int y = 0; y < rh; y++) {
		for (int x = 0; x < rw; x++) {
			float a = got[(size_t)y * rw + x], b = want[(size_t)y * rw + x];
			/* outside the source: gdalwarp without -dstnodata writes 0 (the plane is
			 * 100..800 inside); the import writes nodata, NaN in a float output */
			if (b == 0) {
				if (!isnan(a))
					fail_msg("pixel %d,%d: %g, gdalwarp: nodata", x, y, a);
				outside++;
				continue;
			}
			if (!(fabsf(a - b) <= 1e-3f * fabsf(b) + 1e-3f))
				fail_msg("pixel %d,%d: %.6g, gdalwarp %.6g", x, y, a, b);
			double lon = r.west + (x + 0.5) * (r.east - r.west) / rw;
			double lat = r.north - (y + 0.5) * (r.north - r.south) / rh;
			double e = lon, n = lat;
			assert_true(OCTTransform(ct, 1, &e, &n, NULL));
			/* well inside the source (a pixel from its edges): the plane there */
			if (e > 400100 && e < 400000 + w * 100 - 100 && n < 5599900 &&
			    n > 5600000 - h * 100 + 100) {
				double d = fabs(a - utm_plane(e, n));
				worst = d > worst ? d : worst;
				inside++;
			}
		}
	}
	OCTDestroyCoordinateTransformation(ct);
	OSRDestroySpatialReference(utm);
	OSRDestroySpatialReference(geo);
	/* The plane changes 0.0224 per metre (its gradient); the warper's approximate transform
	 * (gdalwarp's default: within 0.125 pixel, about 12.5 m here) allows 0.28. */
	if (!(worst < 0.3 && inside > rw * rh / 2 && outside > 0))
		fail_msg("worst %g over %d pixels inside, %d outside", worst, inside, outside);
	printf("# UTM import: %dx%d, %d pixels checked, worst %.4f (plane units), %d nodata\n", rw,
	       rh, inside, worst, outside);
	free(want);
	free(got);

	/* --resample near and a bad name. */
	struct import_opts o = { .resample = "near" };
	if (import_raster(tpath("utm.tif"), tpath("utm_near.tif"), &o, &r, err))
		fail_msg("%s", err);
	assert_true(r.reprojected);
	assert_false(import_resample_ok("bicubic"));
	o.resample = "bicubic";
	expect_error(tpath("utm.tif"), tpath("utm_bad.tif"), &o, -EINVAL, "bicubic", "lanczos");
	assert_true(import_resample_ok("lanczos"));
}

/* Issue 19: re-importing an imported file keeps its bounds (and integer nodata); it does not
 * become global. */
static void reimport_keeps_bounds(void **state)
{
	(void)state;
	const double gt[6] = { 10, 0.5, 0, 50, 0, -0.5 };
	double nd = -32768;
	write_geotiff(tpath("ri.tif"), 40, 20, gt, 4326, &nd);
	struct import_result r1, r2;
	char err[256] = "";
	if (import_raster(tpath("ri.tif"), tpath("ri1.tif"), NULL, &r1, err))
		fail_msg("%s", err);
	if (import_raster(tpath("ri1.tif"), tpath("ri2.tif"), NULL, &r2, err))
		fail_msg("%s", err);
	assert_true(r2.georeferenced);
	assert_true(r2.west == 10 && r2.east == 30 && r2.south == 40 && r2.north == 50);
	assert_true(r2.has_nodata && r2.nodata == -32768);
	int16_t *px;
	char desc[256];
	read_back(tpath("ri2.tif"), 40, 20, &px, desc);
	assert_string_equal(desc, "clipmap:bounds=10,40,30,50 clipmap:nodata=-32768");
	for (int y = 0; y < 20; y++)
		for (int x = 0; x < 40; x++)
			assert_int_equal(px[y * 40 + x], pix(x, y));
	free(px);
}

/* A UTM RGB image (8-bit, no nodata) gains an alpha band: opaque over the source,
 * transparent in the wedges outside it (not black). */
static void utm_rgb_alpha(void **state)
{
	(void)state;
	int w = 120, h = 80;
	GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), tpath("rgb_utm.tif"), w, h, 3,
				     GDT_Byte, NULL);
	assert_non_null(ds);
	double gt[6] = { 400000, 100, 0, 5600000, 0, -100 };
	assert_int_equal(GDALSetGeoTransform(ds, gt), CE_None);
	OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(srs, 32633), OGRERR_NONE);
	assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
	OSRDestroySpatialReference(srs);
	uint8_t *buf = malloc((size_t)w * h);
	for (int b = 1; b <= 3; b++) {
		memset(buf, 40 * b, (size_t)w * h);
		assert_int_equal(GDALRasterIO(GDALGetRasterBand(ds, b), GF_Write, 0, 0, w, h, buf, w,
					      h, GDT_Byte, 0, 0), CE_None);
	}
	free(buf);
	GDALClose(ds);
	struct import_result r;
	char err[256] = "";
	if (import_raster(tpath("rgb_utm.tif"), tpath("rgb_out.tif"), NULL, &r, err))
		fail_msg("%s", err);
	assert_true(r.reprojected);
	assert_int_equal(r.channels, 4);
	assert_int_equal(r.type, IMG_U8);
	GDALDatasetH out = GDALOpen(tpath("rgb_out.tif"), GA_ReadOnly);
	assert_non_null(out);
	int ow = GDALGetRasterXSize(out), oh = GDALGetRasterYSize(out);
	uint8_t *px = malloc((size_t)ow * oh * 4);
	int bands[4] = { 1, 2, 3, 4 };
	assert_int_equal(GDALDatasetRasterIO(out, GF_Read, 0, 0, ow, oh, px, ow, oh, GDT_Byte, 4,
					     bands, 4, (GSpacing)ow * 4, 1), CE_None);
	GDALClose(out);
	int opaque = 0, clear = 0;
	for (int i = 0; i < ow * oh; i++) {
		const uint8_t *p = px + 4 * i;
		if (p[3] == 255 && p[0] == 40 && p[1] == 80 && p[2] == 120)
			opaque++;
		else if (p[3] == 0)
			clear++;
	}
	free(px);
	/* the rest: the source's edge, partly covered */
	if (!(opaque > ow * oh / 2 && clear > 0 && opaque + clear > ow * oh * 9 / 10))
		fail_msg("%dx%d: %d opaque, %d transparent", ow, oh, opaque, clear);
}

/* Integer nodata in the imported pyramid: a void stays a void at every level, and the
 * texels around it keep data values (not dragged towards -32768 by averaging). */
static void nodata_pyramid(void **state)
{
	(void)state;
	int w = 256, h = 128;
	const double gt[6] = { 0, 0.1, 0, 50, 0, -0.1 };
	GDALDatasetH ds = GDALCreate(GDALGetDriverByName("GTiff"), tpath("void.tif"), w, h, 1,
				     GDT_Int16, NULL);
	assert_non_null(ds);
	assert_int_equal(GDALSetGeoTransform(ds, (double *)gt), CE_None);
	OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
	assert_int_equal(OSRImportFromEPSG(srs, 4326), OGRERR_NONE);
	assert_int_equal(GDALSetSpatialRef(ds, srs), CE_None);
	OSRDestroySpatialReference(srs);
	GDALRasterBandH b = GDALGetRasterBand(ds, 1);
	assert_int_equal(GDALSetRasterNoDataValue(b, -32768), CE_None);
	int16_t *buf = malloc(sizeof *buf * (size_t)w * h);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++) /* a void not aligned to any MIP box */
			buf[(size_t)y * w + x] = x >= 77 && x < 141 && y >= 33 && y < 91 ? -32768
											 : (int16_t)(500 + x);
	assert_int_equal(GDALRasterIO(b, GF_Write, 0, 0, w, h, buf, w, h, GDT_Int16, 0, 0), CE_None);
	free(buf);
	GDALClose(ds);
	char err[256] = "";
	struct import_result r;
	if (import_raster(tpath("void.tif"), tpath("void_out.tif"), NULL, &r, err))
		fail_msg("%s", err);
	int16_t *lv[16];
	int lw[16], lh[16];
	int n = read_levels(tpath("void_out.tif"), lv, lw, lh);
	assert_true(n > 4);
	for (int m = 1; m < n; m++) {
		int voids = 0;
		for (int i = 0; i < lw[m] * lh[m]; i++) {
			int v = lv[m][i];
			if (v == -32768)
				voids++;
			else if (v < 500 || v > 756)
				fail_msg("level %d pixel %d: %d", m, i, v);
		}
		if (m <= 3 && !voids)
			fail_msg("level %d: the void vanished", m);
		free(lv[m]);
	}
	free(lv[0]);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(round_trip),
		cmocka_unit_test(global_shift_and_flip),
		cmocka_unit_test(errors),
		cmocka_unit_test(streaming_bands),
		cmocka_unit_test(row_streaks),
		cmocka_unit_test(truncated_source),
		cmocka_unit_test(utm_reprojected),
		cmocka_unit_test(reimport_keeps_bounds),
		cmocka_unit_test(utm_rgb_alpha),
		cmocka_unit_test(nodata_pyramid),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
