/* bench_nodes — every node type through the real scheduler and cache: tiles per second with
 * 1 and 2 workers at T = 256 and 512, and ns per texel per worker (best of 5 rounds of 64
 * tiles). A node's inputs are generated and cached first, so each figure is that node's own
 * cost plus scheduling.
 * Writes its planet files (and one 4096×2048 tiled TIFF for the file node) under /tmp.
 * BENCH_NODES_ONLY=TEXT runs only the cases whose name holds TEXT. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define DIR "/tmp/clipmap-bench-nodes"
#define SIDE 8 /* an 8×8 block of tiles */

struct bcase {
	const char *name;
	const char *node; /* the [node bench] body; inputs: src (height), col (colour), src2 */
	int level;	  /* ly; lx = ly + 1 */
};

static const struct bcase cases[] = {
	{ "constant", "type = constant\nheight = 5\n", 8 },
	{ "noise fbm 8 oct", "type = noise\nkind = fbm\noctaves = 8\nwavelength = 20000\n", 12 },
	{ "noise ridged 8 oct", "type = noise\nkind = ridged\noctaves = 8\nwavelength = 20000\n", 12 },
	{ "noise ridged, warp", "type = noise\nkind = ridged\noctaves = 8\nwavelength = 20000\n"
				      "warp = 4000\n", 12 },
	{ "noise ridged L8",
	  "type = noise\nkind = ridged\noctaves = 8\nwavelength = 20000\n", 8 },
	{ "noise ridged L8, warp",
	  "type = noise\nkind = ridged\noctaves = 8\nwavelength = 20000\nwarp = 4000\n", 8 },
	/* earth.ini's detail_noise (ridged, its two longest octaves warped ±2.5 km over 10 km, a
	 * weight floor of 0.3)
	 * where the warp is evaluated per texel (L11) and on the tile's lattice (L14) */
#define EARTH_DETAIL "type = noise\nkind = ridged\nseed = 5\noctaves = 20\nwavelength = 8000\n" \
		     "gain = 0.5\namplitude = 900\nmax_wavelength = 8000\nwarp = 2500\n"        \
		     "warp_wavelength = 10000\nwarp_octaves = 1\nwarp_depth = 2\n"   \
		     "ridge_floor = 0.3\n"
	{ "earth detail_noise L9", EARTH_DETAIL, 9 },
	{ "earth detail_noise L11", EARTH_DETAIL, 11 },
	{ "earth detail_noise L14", EARTH_DETAIL, 14 },
	/* earth.ini's fields: cells 450 m with 8 m borders, 23 texels a cell (L12, 19 m texels:
	 * the border drawn a texel wide) and 94 (L14, 4.8 m) */
#define EARTH_FIELDS "type = cells\nseed = 41\nwavelength = 450\njitter = 0.9\nborder = 8\n"
	/* earth.ini's canopy: fBm 90 m down; at L12 one octave fades in, at L14 three */
#define EARTH_CANOPY "type = noise\nkind = fbm\nseed = 23\noctaves = 4\nwavelength = 90\n" \
		     "gain = 0.55\namplitude = 14\nmax_wavelength = 90\n"
	{ "earth canopy_noise L10", EARTH_CANOPY, 10 },
	{ "earth canopy_noise L12", EARTH_CANOPY, 12 },
	{ "earth canopy_noise L14", EARTH_CANOPY, 14 },
	{ "earth fields (cells) L12", EARTH_FIELDS, 12 },
	{ "earth fields (cells) L14", EARTH_FIELDS, 14 },
	{ "color_filter LUT", "type = color_filter\ninput = col\ngamma = 1.4\ncontrast = 1.2\n", 8 },
	{ "color_filter LUT+hue/sat",
	  "type = color_filter\ninput = col\ngamma = 1.4\nhue = 20\nsaturation = 1.3\n", 8 },
	{ "height_filter", "type = height_filter\ninput = src\nscale = 2\noffset = 10\n", 8 },
	{ "ramp", "type = ramp\ninput = src\n", 8 },
	/* earth.ini's canopy_tint's three stops over a field crossing them every few texels */
	{ "ramp (3 stops)", "type = ramp\ninput = src2\nstops = -14 120 135 120, 0 205 215 205, "
			    "14 255 255 255\n", 8 },
	{ "blend over (colour)", "type = blend\nmode = over\na = col\nb = col\nopacity = 0.5\n", 8 },
	{ "blend add (height)", "type = blend\nmode = add\na = src\nb = src2\n", 8 },
	/* earth.ini's masks: b where the mask lets it through (a mask of heights, partly 0) */
	{ "blend add masked (height)", "type = blend\nmode = add\na = src\nb = src2\nmask = src2\n",
	  8 },
	{ "blend over masked (colour)", "type = blend\nmode = over\na = col\nb = col\nmask = src2\n",
	  8 },
	{ "normal", "type = normal\ninput = src\n", 8 },
	{ "slope", "type = slope\ninput = src\n", 8 },
	{ "slope (scale: 2 levels up)", "type = slope\ninput = src\nscale = 2000\n", 12 },
	{ "ramp + slope", "type = ramp\ninput = src\nslope = src2\nsteep_from = 0\nsteep_to = 2\n"
			  "steep_stops = 0 1 2 3, 1000 200 200 200\n", 8 },
	{ "file (f32, bilinear)", "type = file\npath = " DIR "/heights.tif\nkind = height\nbounds = -180,-90,180,90\n", 5 },
	{ "file (f32, MIP 2)", "type = file\npath = " DIR "/heights.tif\nkind = height\nbounds = -180,-90,180,90\n", 2 },
};

static int write_planet(const char *path, uint32_t T, const struct bcase *c)
{
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	fprintf(f, "[planet]\nbody = wgs84\ntile_size = %u\nmax_level = 20\n"
		   "[node src]\ntype = noise\noctaves = 3\nwavelength = 200000\namplitude = 2000\n"
		   "[node src2]\ntype = noise\nseed = 3\noctaves = 3\nwavelength = 90000\n"
		   "[node col]\ntype = ramp\ninput = src\n"
		   "[node bench]\n%s"
		   "[layer bench]\nnode = bench\n"
		   "[layer src]\nnode = src\n[layer col]\nnode = col\n[layer src2]\nnode = src2\n",
		T, c->node);
	return fclose(f);
}

static size_t block(const struct node *n, int ly, struct want *w, int margin)
{
	size_t k = 0;
	int lx = ly + 1;
	uint32_t x0 = grid_tiles_x(lx) / 3, y0 = grid_tiles_y(ly) / 3;
	for (int j = -margin; j < SIDE + margin; j++)
		for (int i = -margin; i < SIDE + margin; i++) {
			if ((int64_t)y0 + j < 0 || (uint32_t)((int64_t)y0 + j) >= grid_tiles_y(ly))
				continue;
			w[k].node = (struct node *)n;
			w[k].cls = SCHED_VISIBLE;
			w[k].key = (struct tile_key){ .node = n->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly,
						      .x = grid_wrap_x(lx, (int64_t)x0 + i),
						      .y = (uint32_t)((int64_t)y0 + j) };
			k++;
		}
	return k;
}

static int fetch_all(struct sched *s, struct want *w, size_t n)
{
	struct tile **t = xcalloc(n, sizeof *t);
	int rc = sched_fetch(s, w, n, t);
	for (size_t i = 0; i < n; i++)
		tile_unref(t[i]);
	free(t);
	return rc;
}

static int run_case(const struct bcase *c, uint32_t T)
{
	char path[256], err[256];
	snprintf(path, sizeof path, DIR "/bench-%u.ini", T);
	if (write_planet(path, T, c)) {
		fprintf(stderr, "bench_nodes: cannot write %s\n", path);
		return -1;
	}
	struct planet *p;
	if (planet_load(path, &p, err)) {
		fprintf(stderr, "bench_nodes: %s\n", err);
		return -1;
	}
	struct node *bench = planet_find_node(p, "bench");
	struct want w[(SIDE + 2) * (SIDE + 2)];
	double rate[3] = { 0 };
	for (int workers = 1; workers <= 2; workers++) {
		struct cache *cache = cache_create(0);
		struct sched *s = sched_create(&(struct sched_desc){ .cache = cache,
								     .workers = workers });
		/* cache the inputs (with a one-tile margin for the normal map's neighbours) */
		for (int in = 0; in < NODE_MAX_INPUTS; in++) {
			if (!bench->in[in])
				continue;
			size_t n = block(bench->in[in], c->level, w, 1);
			if (fetch_all(s, w, n)) {
				fprintf(stderr, "bench_nodes: generating inputs failed\n");
				return -1;
			}
		}
		/* best of 5 after a warm-up (page faults, the file node's image cache): each
		 * round drops the node's tiles so they are generated again */
		size_t n = block(bench, c->level, w, 0);
		double el = 1e9;
		int rc = 0;
		for (int round = 0; round < 6 && rc == 0; round++) {
			cache_drop_node(cache, bench->hash);
			double t0 = clock_now_s();
			rc = fetch_all(s, w, n);
			double t = clock_now_s() - t0;
			if (round > 0 && t < el)
				el = t;
		}
		sched_destroy(s);
		cache_destroy(cache);
		if (rc) {
			fprintf(stderr, "bench_nodes: %s failed: %d\n", c->name, rc);
			return -1;
		}
		rate[workers] = n / el;
	}
	double texels = (double)T * T;
	printf("node %-26s T=%-3u  1 worker %7.0f tiles/s (%5.2f ns/texel)   2 workers %7.0f tiles/s"
	       " (%5.2f ns/texel/worker)\n",
	       c->name, T, rate[1], 1e9 / (rate[1] * texels), rate[2], 2e9 / (rate[2] * texels));
	planet_unref(p);
	return 0;
}

static int make_file(void)
{
	char err[256];
	const int W = 4096, H = 2048;
	FILE *f = fopen(DIR "/heights.tif", "r");
	if (f) {
		fclose(f);
		return 0;
	}
	float *px = xmalloc((size_t)W * H * sizeof *px);
	for (int j = 0; j < H; j++)
		for (int i = 0; i < W; i++)
			px[(size_t)j * W + i] = (float)(1000 * sin(i * 0.01) * cos(j * 0.013));
	int rc = img_write_tiled(DIR "/heights.tif", W, H, 1, IMG_F32, px, 256, true, err);
	free(px);
	if (rc)
		fprintf(stderr, "bench_nodes: %s\n", err);
	return rc;
}

/* BENCH_NODES_ONLY=TEXT: only the cases whose name holds TEXT */
int main(void)
{
	const char *only = getenv("BENCH_NODES_ONLY");
	if (system("mkdir -p " DIR) != 0 || make_file())
		return 1;
	for (uint32_t T = 256; T <= 512; T *= 2)
		for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++)
			if ((!only || strstr(cases[i].name, only)) && run_case(&cases[i], T))
				return 1;
	return 0;
}
