/* test_img — the OpenImageIO shim: write/read round trips per format, region reads through
 * the cache (strides, MIP levels, concurrency), and the errors a user sees for missing,
 * corrupt and unwritable files. */
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
#include <unistd.h>

#include "common/img.h"
#include "common/xthread.h"

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
	snprintf(dir, sizeof dir, "/tmp/test_img.XXXXXX");
	return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
	return system(cmd) == 0 ? 0 : -1;
}

static void round_trip(const char *name, int w, int h, int c, enum img_type t, const void *px)
{
	char err[256] = "";
	const char *p = tpath(name);
	int rc = img_write(p, w, h, c, t, px, err);
	if (rc)
		fail_msg("img_write %s: %d %s", name, rc, err);
	assert_int_equal(access(tpath("x.tmp"), F_OK), -1);
	void *back = NULL;
	struct img_info info;
	rc = img_read(p, t, &back, &info, err);
	if (rc)
		fail_msg("img_read %s: %d %s", name, rc, err);
	assert_int_equal(info.width, w);
	assert_int_equal(info.height, h);
	assert_int_equal(info.channels, c);
	assert_int_equal(info.type, t);
	assert_memory_equal(back, px, (size_t)w * h * c * img_type_bytes(t));
	free(back);
}

static void png8_rgb(void **state)
{
	(void)state;
	int w = 37, h = 23;
	uint8_t *px = malloc((size_t)w * h * 3);
	for (int i = 0; i < w * h * 3; i++)
		px[i] = (uint8_t)(i * 7 + i / 3);
	round_trip("a.png", w, h, 3, IMG_U8, px);
	free(px);
}

static void png16_grey(void **state)
{
	(void)state;
	int w = 40, h = 9;
	uint16_t *px = malloc((size_t)w * h * 2);
	for (int i = 0; i < w * h; i++)
		px[i] = (uint16_t)(i * 1021 + 3);
	round_trip("b.png", w, h, 1, IMG_U16, px);
	free(px);
}

static void tiff_f32_and_i16(void **state)
{
	(void)state;
	int w = 33, h = 17;
	float *f = malloc((size_t)w * h * sizeof *f);
	int16_t *s = malloc((size_t)w * h * sizeof *s);
	for (int i = 0; i < w * h; i++) {
		f[i] = (float)(sin(i * 0.1) * 8848.5 - 1e-3 * i);
		s[i] = (int16_t)(i * 37 - 10000);
	}
	round_trip("c.tif", w, h, 1, IMG_F32, f);
	/* int16 keeps its raw (negative) values: what SRTM-style heights need. */
	round_trip("d.tiff", w, h, 1, IMG_I16, s);
	free(f);
	free(s);
}

static void exr_f32(void **state)
{
	(void)state;
	int w = 20, h = 11;
	float *f = malloc((size_t)w * h * 2 * sizeof *f);
	for (int i = 0; i < w * h * 2; i++)
		f[i] = (float)(i * 0.37 - 30);
	round_trip("e.exr", w, h, 2, IMG_F32, f);
	free(f);
}

static void bad_writes(void **state)
{
	(void)state;
	char err[256] = "";
	float f[4] = { 0 };
	assert_int_equal(img_write(tpath("x.jpg2"), 2, 2, 1, IMG_F32, f, err), -EINVAL);
	assert_non_null(strstr(err, "extension"));
	assert_int_equal(img_write(tpath("x.png"), 2, 2, 1, IMG_F32, f, err), -EINVAL);
	assert_non_null(strstr(err, "png"));
	assert_int_equal(img_write("/nonexistent-dir/x.tif", 2, 2, 1, IMG_F32, f, err), -EIO);
	assert_non_null(strstr(err, "/nonexistent-dir/x.tif"));
	assert_int_equal(access(tpath("x.png"), F_OK), -1);
}

static void missing_and_corrupt(void **state)
{
	(void)state;
	char err[256] = "";
	struct img_info info;
	void *px = (void *)1;
	struct img_cache *c = img_cache_create(16);
	assert_non_null(c);
	assert_int_equal(img_cache_info(c, tpath("nope.png"), &info, err), -ENOENT);
	assert_non_null(strstr(err, "nope.png"));
	assert_int_equal(img_read(tpath("nope.tif"), IMG_U8, &px, NULL, err), -ENOENT);
	assert_null(px);
	assert_non_null(strstr(err, "nope.tif"));

	/* A PNG signature followed by garbage, and a file of no known format. */
	FILE *f = fopen(tpath("bad.png"), "wb");
	assert_non_null(f);
	fputs("\x89PNG\r\n\x1a\n this is not a png at all", f);
	assert_int_equal(fclose(f), 0);
	err[0] = 0;
	assert_int_equal(img_cache_info(c, tpath("bad.png"), &info, err), -EIO);
	assert_true(strlen(err) > strlen(tpath("bad.png")) + 2);
	err[0] = 0;
	assert_int_equal(img_read(tpath("bad.png"), IMG_U8, &px, NULL, err), -EIO);
	assert_non_null(strstr(err, "bad.png"));
	f = fopen(tpath("text.tif"), "wb");
	assert_non_null(f);
	fputs("hello", f);
	assert_int_equal(fclose(f), 0);
	uint8_t v[4];
	err[0] = 0;
	assert_int_equal(img_cache_read(c, tpath("text.tif"), 0, 0, 1, 0, 1, 0, 1, IMG_U8, v, 0,
					err),
			 -EIO);
	assert_non_null(strstr(err, "text.tif"));
	/* A bad region is the caller's mistake. */
	assert_int_equal(img_cache_read(c, tpath("text.tif"), 0, 1, 1, 0, 1, 0, 1, IMG_U8, v, 0,
					err),
			 -EINVAL);
	img_cache_unref(c);
	img_cache_unref(NULL);
}

/* Region reads: sub-rectangles, a row stride, channel subsets, MIP levels of a tiled TIFF. */
static void cache_regions_and_mips(void **state)
{
	(void)state;
	char err[256] = "";
	int w = 256, h = 128;
	uint16_t *px = malloc((size_t)w * h * 2 * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++) {
			px[(y * w + x) * 2] = (uint16_t)(x * 256 + y);
			px[(y * w + x) * 2 + 1] = (uint16_t)((x + y) & 1 ? 60000 : 0);
		}
	const char *p = tpath("t.tif");
	int rc = img_write_tiled(p, w, h, 2, IMG_U16, px, 64, true, err);
	if (rc)
		fail_msg("img_write_tiled: %d %s", rc, err);
	struct img_cache *c = img_cache_create(16);
	struct img_info info;
	assert_int_equal(img_cache_info(c, p, &info, err), 0);
	assert_true(info.tiled);
	assert_int_equal(info.tile_width, 64);
	assert_int_equal(info.mip_levels, 9); /* 256×128 … 1×1 */
	assert_int_equal(info.type, IMG_U16);
	int lw, lh;
	assert_int_equal(img_cache_level_size(c, p, 2, &lw, &lh, err), 0);
	assert_int_equal(lw, 64);
	assert_int_equal(lh, 32);
	assert_int_equal(img_cache_level_size(c, p, 9, &lw, &lh, err), -EINVAL);

	/* Channel 0 of [70, 75) × [60, 63) into rows 8 elements apart. */
	uint16_t out[3 * 8];
	memset(out, 0xff, sizeof out);
	assert_int_equal(img_cache_read(c, p, 0, 70, 75, 60, 63, 0, 1, IMG_U16, out, 8 * 2, err), 0);
	for (int y = 0; y < 3; y++) {
		for (int x = 0; x < 5; x++)
			assert_int_equal(out[y * 8 + x], (70 + x) * 256 + 60 + y);
		assert_int_equal(out[y * 8 + 5], 0xffff);
	}
	/* Level 1 of the checkerboard channel is its 2×2 mean; as float it is normalised. */
	float g[4];
	assert_int_equal(img_cache_read(c, p, 1, 10, 12, 20, 22, 1, 2, IMG_F32, g, 0, err), 0);
	for (int i = 0; i < 4; i++)
		assert_float_equal(g[i], 30000.0 / 65535.0, 1e-4);
	img_cache_unref(c);
	free(px);
}

/* Odd sizes: partial edge tiles, channel subsets, an untiled file (one whole-image tile). */
static void cache_edge_tiles(void **state)
{
	(void)state;
	char err[256] = "";
	int w = 100, h = 70;
	uint8_t *px = malloc((size_t)w * h * 3);
	for (int i = 0; i < w * h * 3; i++)
		px[i] = (uint8_t)(i * 31 + i / 300);
	const char *p = tpath("edge.tif"), *q = tpath("edge.png");
	assert_int_equal(img_write_tiled(p, w, h, 3, IMG_U8, px, 32, false, err), 0);
	assert_int_equal(img_write(q, w, h, 3, IMG_U8, px, err), 0);
	struct img_cache *c = img_cache_create(16);
	uint8_t *out = malloc((size_t)w * h * 3);
	for (int f = 0; f < 2; f++) {
		const char *path = f ? q : p;
		memset(out, 0, (size_t)w * h * 3);
		assert_int_equal(img_cache_read(c, path, 0, 0, w, 0, h, 0, 3, IMG_U8, out, 0, err), 0);
		assert_memory_equal(out, px, (size_t)w * h * 3);
		/* [61, 100) × [30, 70), channels 1..2, rows 100 bytes apart */
		memset(out, 0, (size_t)w * h * 3);
		assert_int_equal(img_cache_read(c, path, 0, 61, 100, 30, 70, 1, 3, IMG_U8, out, 100,
						err),
				 0);
		for (int y = 0; y < 40; y++)
			for (int x = 0; x < 39; x++)
				for (int ch = 0; ch < 2; ch++)
					assert_int_equal(out[y * 100 + x * 2 + ch],
							 px[((30 + y) * w + 61 + x) * 3 + 1 + ch]);
	}
	free(out);
	free(px);
	img_cache_unref(c);
}

/* An untiled, unmipped PNG gets automip levels. */
static void automip_png(void **state)
{
	(void)state;
	char err[256] = "";
	int w = 96, h = 48;
	uint8_t *px = malloc((size_t)w * h);
	for (int i = 0; i < w * h; i++)
		px[i] = (uint8_t)(((i % w) + (i / w)) & 1 ? 200 : 100);
	const char *p = tpath("m.png");
	assert_int_equal(img_write(p, w, h, 1, IMG_U8, px, err), 0);
	struct img_cache *c = img_cache_create(16);
	struct img_info info;
	assert_int_equal(img_cache_info(c, p, &info, err), 0);
	assert_false(info.tiled);
	assert_true(info.mip_levels >= 5);
	uint8_t v[12 * 6];
	assert_int_equal(img_cache_read(c, p, 3, 0, 12, 0, 6, 0, 1, IMG_U8, v, 0, err), 0);
	for (int i = 0; i < 12 * 6; i++)
		assert_in_range(v[i], 149, 151);
	img_cache_unref(c);
	free(px);
}

struct reader {
	struct img_cache *c;
	const char *path;
	int bad;
};

static void *reader_main(void *arg)
{
	struct reader *r = arg;
	char err[256];
	uint16_t v[16 * 16];
	for (int it = 0; it < 200; it++) {
		int x = (it * 37) % 240, y = (it * 11) % 112;
		if (img_cache_read(r->c, r->path, 0, x, x + 16, y, y + 16, 0, 1, IMG_U16, v, 0, err)) {
			r->bad++;
			continue;
		}
		for (int j = 0; j < 16; j++)
			for (int i = 0; i < 16; i++)
				if (v[j * 16 + i] != (uint16_t)((x + i) * 256 + y + j))
					r->bad++;
	}
	return NULL;
}

static void concurrent_reads(void **state)
{
	(void)state;
	char err[256];
	int w = 256, h = 128;
	uint16_t *px = malloc((size_t)w * h * sizeof *px);
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			px[y * w + x] = (uint16_t)(x * 256 + y);
	const char *p = tpath("conc.tif");
	assert_int_equal(img_write_tiled(p, w, h, 1, IMG_U16, px, 32, false, err), 0);
	struct img_cache *c = img_cache_create(1); /* small: forces eviction */
	struct reader r[3] = { { c, p, 0 }, { c, p, 0 }, { c, p, 0 } };
	pthread_t th[3];
	for (int i = 0; i < 3; i++)
		assert_int_equal(xthread_create(&th[i], reader_main, &r[i]), 0);
	for (int i = 0; i < 3; i++) {
		xthread_join(th[i]);
		assert_int_equal(r[i].bad, 0);
	}
	img_cache_unref(c);
	free(px);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(png8_rgb),
		cmocka_unit_test(png16_grey),
		cmocka_unit_test(tiff_f32_and_i16),
		cmocka_unit_test(exr_f32),
		cmocka_unit_test(bad_writes),
		cmocka_unit_test(missing_and_corrupt),
		cmocka_unit_test(cache_regions_and_mips),
		cmocka_unit_test(cache_edge_tiles),
		cmocka_unit_test(automip_png),
		cmocka_unit_test(concurrent_reads),
	};
	return cmocka_run_group_tests_name("img", tests, setup, teardown);
}
