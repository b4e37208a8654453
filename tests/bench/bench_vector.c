/* bench_vector — the `vector` node on the shipped borders + rivers + coast layer (data/earth/
 * lines.gpkg from `make data`, styled as in conf/planets/earth.ini), T = 256: the source's load
 * time (read, transform, index), then ns per texel and tiles/s at levels 4, 10 and 16 over
 * tiles round a few places on land (and at level 4 the whole level), against `blend` mode
 * over on two colour tiles (the compositing every annotated tile pays anyway) measured in the
 * same run. One worker. Skips (exit 0) without the data. */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "support/node_ini.h"

#define T 256
#define DATA "data/earth/lines.gpkg"

static struct planet pl;

static void bnode_init(struct node_ini *b, const struct node_type *t, const char *text,
		       struct node *in0, struct node *in1)
{
	char err[256];
	struct node *in[2] = { in0, in1 };
	if (node_ini_init(b, t, &pl, text, in, 2, err)) {
		fprintf(stderr, "bench_vector: %s\n", err);
		exit(1);
	}
}

static const char vector_text[] =
	"[node lines]\ntype = vector\npath = " DATA "\nstyle_field = kind\ncolor = #00000000\n"
	"styles = coast #f0f0f0b0 1px, river #3c8cff 1px, border #ff4030 1.5px\n";

/* Places on land (lat, lon): Paris, Cairo, Manaus, Moscow, Delhi, Chicago. */
static const double places[][2] = { { 48.85, 2.35 },  { 30.04, 31.24 }, { -3.1, -60.02 },
				    { 55.75, 37.62 }, { 28.61, 77.21 }, { 41.88, -87.63 } };

/* Keys of 3×3 tiles round each place at level ly (lx = ly + 1). */
static int place_keys(int ly, struct tile_key *k)
{
	int n = 0, lx = ly + 1;
	uint32_t nx = 1u << lx, ny = 1u << ly;
	for (size_t p = 0; p < sizeof places / sizeof places[0]; p++) {
		int64_t x = (int64_t)floor((places[p][1] + 180) / 360 * nx);
		int64_t y = (int64_t)floor((90 - places[p][0]) / 180 * ny);
		for (int dy = -1; dy <= 1; dy++)
			for (int dx = -1; dx <= 1; dx++) {
				int64_t yy = y + dy;
				if (yy < 0 || yy >= ny)
					continue;
				k[n++] = (struct tile_key){ .x = (uint32_t)(((x + dx) % nx + nx) % nx),
							    .y = (uint32_t)yy, .lx = (uint8_t)lx,
							    .ly = (uint8_t)ly };
			}
	}
	return n;
}

/* Seconds per tile generating keys k[0..n) (each once per round, best of 3 rounds), and the
 * share of tiles with any opaque-ish texel. */
static double time_tiles(struct node_ini *b, struct gen_ctx *g, const struct tile_key *k, int n,
			 struct tile *const *in, int nin, double *drawn)
{
	double best = INFINITY;
	int nonempty = 0;
	struct tile *t = tile_create(&k[0], b->n.out, T);
	for (int r = 0; r < 3; r++) {
		double t0 = clock_now_s();
		for (int i = 0; i < n; i++) {
			struct tile_key key = k[i];
			key.node = b->n.hash;
			if (b->n.type->generate(&b->n, g, &key, in, nin, t)) {
				fprintf(stderr, "bench_vector: generate failed\n");
				exit(1);
			}
			if (r == 0) {
				bool any = false;
				for (size_t j = 3; j < (size_t)T * T * 4 && !any; j += 4)
					any = t->data[j] != 0;
				nonempty += any;
			}
		}
		double dt = (clock_now_s() - t0) / n;
		best = dt < best ? dt : best;
	}
	tile_unref(t);
	if (drawn)
		*drawn = (double)nonempty / n;
	return best;
}

int main(void)
{
	if (access(DATA, R_OK) != 0) {
		printf("vector: skipped: %s missing (make data)\n", DATA);
		return 0;
	}
	pl.a = 6378137.0;
	pl.f = 1 / 298.257223563;
	pl.tile_size = T;
	pl.max_level = 20;
	double load = INFINITY;
	struct node_ini v;
	for (int r = 0; r < 3; r++) {
		double t0 = clock_now_s();
		bnode_init(&v, &node_type_vector, vector_text, NULL, NULL);
		double dt = clock_now_s() - t0;
		load = dt < load ? dt : load;
		if (r < 2)
			node_ini_fini(&v);
	}
	printf("vector/load %s (read, transform, index): %.0f ms (best of 3)\n", DATA, load * 1e3);

	/* The peer: blend over of two colour tiles. */
	struct node ca = { .name = "a", .out = PIX_COLOR, .hash = 1 }, cb = { .name = "b", .out = PIX_COLOR, .hash = 2 };
	struct node_ini bl;
	bnode_init(&bl, &node_type_blend, "[node over]\ntype = blend\nmode = over\n", &ca, &cb);
	struct tile_key k0 = { .lx = 5, .ly = 4 };
	struct tile *ta = tile_create(&k0, PIX_COLOR, T), *tb = tile_create(&k0, PIX_COLOR, T);
	for (size_t i = 0; i < (size_t)T * T * 4; i++) {
		ta->data[i] = (uint8_t)(i * 7);
		tb->data[i] = (uint8_t)((i & 3) == 3 ? (i % 5 ? 0 : 200) : i * 13);
	}
	struct tile *bin[2] = { ta, tb };
	struct gen_ctx g = { 0 };
	double peer = time_tiles(&bl, &g, &k0, 1, bin, 2, NULL);
	for (int i = 0; i < 20; i++) {
		double p = time_tiles(&bl, &g, &k0, 1, bin, 2, NULL);
		peer = p < peer ? p : peer;
	}
	printf("vector/peer blend over, colour T=%d: %.2f ns/texel, %.0f tiles/s\n", T,
	       peer * 1e9 / (T * T), 1 / peer);

	static struct tile_key keys[512];
	static const int levels[] = { 4, 10, 16 };
	for (int li = 0; li < 3; li++) {
		int n = place_keys(levels[li], keys);
		double drawn, s = time_tiles(&v, &g, keys, n, NULL, 0, &drawn);
		printf("vector/level %d, %d tiles round 6 places (%.0f%% with lines): %.2f ns/texel, "
		       "%.0f tiles/s, %.1f× blend over\n", levels[li], n, 100 * drawn,
		       s * 1e9 / (T * T), 1 / s, s / peer);
	}
	int n = 0;
	for (uint32_t y = 0; y < 16; y++)
		for (uint32_t x = 0; x < 32; x++)
			keys[n++] = (struct tile_key){ .x = x, .y = y, .lx = 5, .ly = 4 };
	double drawn, s = time_tiles(&v, &g, keys, n, NULL, 0, &drawn);
	printf("vector/level 4 whole (%d tiles, %.0f%% with lines): %.2f ns/texel, %.0f tiles/s, "
	       "%.1f× blend over\n", n, 100 * drawn, s * 1e9 / (T * T), 1 / s, s / peer);
	tile_unref(ta);
	tile_unref(tb);
	gen_ctx_fini(&g);
	node_ini_fini(&bl);
	node_ini_fini(&v);
	return 0;
}
