/* bench_file — the `file` node generating 256² and 512² height tiles from a large tiled,
 * MIP-mapped TIFF (8192×4096, 256² tiles, zip; created once in /tmp and reused) on a hot
 * image cache, against memcpy bandwidth measured in the same run. Also: the OIIO region read
 * alone (to tell which step costs), the bilinear path, a MIP level, and a first (cold-cache)
 * read; the east–west prefilter (`isotropic`) against the node without it. One worker.
 * Prints one line per figure. */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/img.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"

#define W 8192
#define H 4096

static void die(const char *what, const char *err)
{
	fprintf(stderr, "bench_file: %s: %s\n", what, err);
	exit(1);
}

/* Creates the test image unless a matching one is already there. */
static void ensure_image(const char *path, enum img_type type)
{
	char err[256];
	struct img_cache *c = img_cache_create(16);
	struct img_info info;
	bool ok = c && img_cache_info(c, path, &info, err) == 0 && info.width == W &&
		  info.height == H && info.type == type && info.tiled && info.tile_width == 256;
	img_cache_unref(c);
	if (ok)
		return;
	double t0 = clock_now_s();
	size_t n = (size_t)W * H;
	void *px = malloc(n * img_type_bytes(type));
	if (!px)
		die("malloc", "out of memory");
	for (size_t y = 0; y < H; y++) {
		for (size_t x = 0; x < W; x++) {
			/* smooth relief plus a little hash detail, so compression is realistic */
			uint32_t h = (uint32_t)(x * 73856093u ^ y * 19349663u);
			h ^= h >> 13;
			double v = 3000 * sin(x * 0.0021) * cos(y * 0.0033) + 900 * sin(x * 0.013 + y * 0.007) +
				   (h & 63);
			if (type == IMG_F32)
				((float *)px)[y * W + x] = (float)v;
			else
				((uint16_t *)px)[y * W + x] = (uint16_t)(v + 10000);
		}
	}
	if (img_write_tiled(path, W, H, 1, type, px, 256, true, err))
		die("img_write_tiled", err);
	free(px);
	printf("file/setup: wrote %s in %.1f s\n", path, clock_now_s() - t0);
}

struct bnode {
	struct ini_file *ini;
	struct node n;
	struct gen_ctx g;
};

static void bnode_init(struct bnode *b, struct planet *pl, const char *text)
{
	char err[256];
	memset(b, 0, sizeof *b);
	if (ini_parse("bench.ini", text, strlen(text), &b->ini, err))
		die("ini_parse", err);
	struct ini_section *sec = &b->ini->sections[b->ini->n - 1];
	struct ini_entry *t = ini_find(sec, "type");
	if (t)
		t->used = true;
	b->n.name = "bench";
	b->n.planet = pl;
	if (node_init(&b->n, &node_type_file, "bench.ini", sec, err))
		die("node_init", err);
}

static void bnode_fini(struct bnode *b)
{
	node_fini(&b->n);
	gen_ctx_fini(&b->g);
	ini_free(b->ini);
}

/* Generates every tile of level (lx, ly) in the rows [y0, y1), `passes` times; returns the
 * best pass's output bytes per second. */
static double run_level(struct bnode *b, int lx, int ly, uint32_t T, uint32_t y0, uint32_t y1,
			int passes)
{
	struct tile_key k = { .node = b->n.hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
	struct tile *t = tile_create(&k, PIX_HEIGHT, T);
	double best = 1e30;
	size_t bytes = 0;
	for (int p = 0; p < passes; p++) {
		bytes = 0;
		double t0 = clock_now_s();
		for (uint32_t y = y0; y < y1; y++) {
			for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
				k.x = x;
				k.y = y;
				if (b->n.type->generate(&b->n, &b->g, &k, NULL, 0, t))
					die("generate", "failed");
				bytes += t->nbytes;
			}
		}
		double dt = clock_now_s() - t0;
		if (dt < best)
			best = dt;
	}
	tile_unref(t);
	return bytes / best;
}

/* memcpy of `n`-byte blocks taken round-robin from a `pool`-byte source: big pool = DRAM. */
static double memcpy_bw(size_t n, size_t pool, int reps)
{
	char *src = malloc(pool), *dst = malloc(n);
	if (!src || !dst)
		die("malloc", "out of memory");
	memset(src, 1, pool);
	memset(dst, 2, n);
	double best = 1e30;
	size_t blocks = pool / n;
	for (int r = 0; r < 5; r++) {
		double t0 = clock_now_s();
		for (int i = 0; i < reps; i++) {
			memcpy(dst, src + (size_t)(i % blocks) * n, n);
			__asm__ volatile("" : : "r"(dst) : "memory");
		}
		double dt = clock_now_s() - t0;
		if (dt < best)
			best = dt;
	}
	free(src);
	free(dst);
	return (double)n * reps / best;
}

/* The OIIO region read alone: T×T f32 reads at the tile positions of a level. */
static double read_only(const char *path, uint32_t T, int passes)
{
	char err[256];
	struct img_cache *c = img_cache_create(512);
	float *buf = malloc((size_t)T * T * 4);
	double best = 1e30;
	size_t bytes = 0;
	for (int p = 0; p < passes + 1; p++) {
		bytes = 0;
		double t0 = clock_now_s();
		for (uint32_t y = 0; y + T <= H; y += T)
			for (uint32_t x = 0; x + T <= W; x += T) {
				if (img_cache_read(c, path, 0, (int)x, (int)(x + T), (int)y, (int)(y + T), 0,
						   1, IMG_F32, buf, 0, err))
					die("img_cache_read", err);
				bytes += (size_t)T * T * 4;
			}
		double dt = clock_now_s() - t0;
		if (p > 0 && dt < best) /* pass 0 warms the cache */
			best = dt;
	}
	free(buf);
	img_cache_unref(c);
	return bytes / best;
}

int main(void)
{
	const char *f32 = "/tmp/clipmap_bench_file_f32.tif", *u16 = "/tmp/clipmap_bench_file_u16.tif";
	ensure_image(f32, IMG_F32);
	ensure_image(u16, IMG_U16);
	struct planet pl = { .tile_size = 256, .max_level = 12, .a = 6378137.0, .dir = "/tmp" };
	char text[512];

	double mc_dram = memcpy_bw(1 << 20, (size_t)256 << 20, 400);
	double mc_hot = memcpy_bw(256 << 10, 256 << 10, 4000);
	printf("file/memcpy 1 MiB blocks from 256 MiB: %.0f MB/s\n", mc_dram / 1e6);
	printf("file/memcpy 256 KiB hot (L2): %.0f MB/s\n", mc_hot / 1e6);

	struct bnode b;
	snprintf(text, sizeof text, "[node bench]\ntype = file\npath = %s\ncache_mb = 512\n"
		 "bounds = -180,-90,180,90\n", f32);
	bnode_init(&b, &pl, text);
	/* Cold-ish: a fresh cache, file in the page cache (written or read just before). */
	double cold = run_level(&b, 5, 4, 256, 0, 16, 1);
	printf("file/f32 T=256 1:1 first read (cold cache, file in page cache): %.0f MB/s\n",
	       cold / 1e6);
	static const struct {
		int lx, ly;
		uint32_t T;
		const char *what;
	} lv[] = {
		{ 5, 4, 256, "1:1 aligned" },
		{ 4, 3, 512, "1:1 aligned" },
		{ 6, 5, 256, "2x magnified (bilinear)" },
		{ 4, 3, 256, "MIP level 1, 1:1" },
		{ 3, 2, 256, "MIP level 2, 1:1" },
	};
	for (size_t i = 0; i < sizeof lv / sizeof lv[0]; i++) {
		uint32_t rows = grid_tiles_y(lv[i].ly);
		uint32_t y1 = rows > 16 ? 16 : rows; /* 16 tile rows at most per pass */
		run_level(&b, lv[i].lx, lv[i].ly, lv[i].T, 0, y1, 1); /* warm */
		double bw = run_level(&b, lv[i].lx, lv[i].ly, lv[i].T, 0, y1, 3);
		printf("file/f32 T=%u %s, hot: %.0f MB/s = %.0f%% of memcpy (%.0f%% of hot memcpy)\n",
		       lv[i].T, lv[i].what, bw / 1e6, 100 * bw / mc_dram, 100 * bw / mc_hot);
	}
	bnode_fini(&b);

	/* Half a pixel off the grid: every texel is a true bilinear blend at 1:1 spacing. */
	double hp = 0.5 * 360.0 / W;
	snprintf(text, sizeof text,
		 "[node bench]\ntype = file\npath = %s\ncache_mb = 512\nbounds = %.12f,-90,%.12f,90\n",
		 f32, -180 + hp, 180 + hp);
	bnode_init(&b, &pl, text);
	for (uint32_t T = 256; T <= 512; T *= 2) {
		int lx = T == 256 ? 5 : 4;
		run_level(&b, lx, lx - 1, T, 0, 8, 1);
		double bw = run_level(&b, lx, lx - 1, T, 0, 8, 3);
		printf("file/f32 T=%u 1:1 half-pixel offset (bilinear), hot: %.0f MB/s = %.0f%% of "
		       "memcpy\n", T, bw / 1e6, 100 * bw / mc_dram);
	}
	bnode_fini(&b);

	snprintf(text, sizeof text, "[node bench]\ntype = file\npath = %s\ncache_mb = 512\n"
		 "scale = 0.5\noffset = -5000\nbounds = -180,-90,180,90\n", u16);
	bnode_init(&b, &pl, text);
	for (uint32_t T = 256; T <= 512; T *= 2) {
		int lx = T == 256 ? 5 : 4;
		run_level(&b, lx, lx - 1, T, 0, 16, 1);
		double bw = run_level(&b, lx, lx - 1, T, 0, 16, 3);
		printf("file/u16→f32 T=%u 1:1 aligned (scale, offset), hot: %.0f MB/s = %.0f%% of "
		       "memcpy\n", T, bw / 1e6, 100 * bw / mc_dram);
	}
	bnode_fini(&b);

	/* The east–west prefilter (isotropic, file_resample.h) against the same node without
	 * it: a whole level (rows above ~69° filtered, the rest unchanged) and a polar band
	 * (the 2 tile rows nearest each pole of a 4× magnified level, viewer-like lx = ly). */
	static const struct {
		int lx, ly;
		uint32_t y0, y1;
		bool poles;
		const char *what;
	} iv[] = {
		{ 5, 4, 0, 16, false, "whole level, 1:1" },
		{ 6, 5, 0, 32, false, "whole level, 2x magnified" },
		{ 6, 6, 0, 2, true, "polar rows (84-90 deg), 4x magnified, lx = ly" },
	};
	struct bnode raw;
	snprintf(text, sizeof text, "[node bench]\ntype = file\npath = %s\ncache_mb = 512\n"
		 "bounds = -180,-90,180,90\n", f32);
	bnode_init(&b, &pl, text);
	snprintf(text, sizeof text, "[node bench]\ntype = file\npath = %s\ncache_mb = 512\n"
		 "bounds = -180,-90,180,90\nisotropic = false\n", f32);
	bnode_init(&raw, &pl, text);
	for (size_t i = 0; i < sizeof iv / sizeof iv[0]; i++) {
		double bw[2];
		for (int a = 0; a < 2; a++) {
			struct bnode *nb = a ? &raw : &b;
			uint32_t n = grid_tiles_y(iv[i].ly);
			run_level(nb, iv[i].lx, iv[i].ly, 256, iv[i].y0, iv[i].y1, 1);
			double t = run_level(nb, iv[i].lx, iv[i].ly, 256, iv[i].y0, iv[i].y1, 3);
			if (iv[i].poles) /* the south's rows too: the harmonic mean of both rates */
				t = 2 / (1 / t + 1 / run_level(nb, iv[i].lx, iv[i].ly, 256,
								 n - iv[i].y1, n - iv[i].y0, 3));
			bw[a] = t;
		}
		printf("file/f32 T=256 %s, isotropic: %.0f MB/s vs %.0f without = %.2fx the time\n",
		       iv[i].what, bw[0] / 1e6, bw[1] / 1e6, bw[1] / bw[0]);
	}
	bnode_fini(&b);
	bnode_fini(&raw);

	for (uint32_t T = 256; T <= 512; T *= 2) {
		double bw = read_only(f32, T, 2);
		printf("file/img_cache_read alone (OIIO), f32 %u² aligned, hot: %.0f MB/s = %.0f%% of memcpy\n",
		       T, bw / 1e6, 100 * bw / mc_dram);
	}
	return 0;
}
