/* bench_pixel — ns per texel on one core for the per-texel node types and the normal map, at
 * T = 256 and 512. Each figure is the best of several batches of generate() calls on
 * realistic input (noisy colours, an opaque base under a translucent overlay, heights from
 * -8 km to +8 km). Prints one line per figure. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/geo.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"

static uint32_t rng(uint32_t *s)
{
	*s ^= *s << 13;
	*s ^= *s >> 17;
	*s ^= *s << 5;
	return *s;
}

struct bnode {
	struct node n;
	struct ini_file *ini;
};

static void make(struct bnode *b, const struct node_type *t, struct planet *pl, struct node *in0,
		 struct node *in1, const char *params)
{
	char text[512], err[256];
	snprintf(text, sizeof text, "[node x]\n%s\n", params);
	memset(b, 0, sizeof *b);
	if (ini_parse("bench.ini", text, strlen(text), &b->ini, err)) {
		fprintf(stderr, "%s\n", err);
		exit(1);
	}
	b->n.name = "x";
	b->n.planet = pl;
	b->n.in[0] = in0;
	b->n.in[1] = in1;
	if (node_init(&b->n, t, "bench.ini", &b->ini->sections[0], err)) {
		fprintf(stderr, "%s\n", err);
		exit(1);
	}
}

static void unmake(struct bnode *b)
{
	node_fini(&b->n);
	ini_free(b->ini);
}

/* Best ns/texel over 5 batches of generate(k) with inputs in[0..nin). */
static double measure(const struct bnode *b, const struct tile_key *k, struct tile *const *in,
		      int nin, uint32_t T)
{
	struct tile *out = tile_create(k, b->n.out, T);
	struct gen_ctx g = { 0 };
	double best = 1e30;
	int reps = 1;
	for (int batch = 0; batch < 6; batch++) {
		double t0 = clock_now_s();
		for (int r = 0; r < reps; r++)
			if (b->n.type->generate(&b->n, &g, k, in, nin, out)) {
				fprintf(stderr, "generate failed\n");
				exit(1);
			}
		double dt = clock_now_s() - t0;
		if (batch > 0 && dt / reps < best)
			best = dt / reps;
		if (dt < 0.05) /* aim for ≥ 50 ms per batch */
			reps = (int)(reps * (0.06 / (dt > 1e-6 ? dt : 1e-6))) + 1;
	}
	gen_ctx_fini(&g);
	tile_unref(out);
	return best * 1e9 / ((double)T * T);
}

int main(void)
{
	struct planet pl = { .a = GEO_WGS84_A, .f = GEO_WGS84_F, .max_level = 20 };
	char err[256];
	if (geo_body_create(pl.a, pl.f, &pl.body, err)) {
		fprintf(stderr, "%s\n", err);
		return 1;
	}
	struct node color = { .name = "photo", .out = PIX_COLOR, .hash = 3 };
	struct node color2 = { .name = "overlay", .out = PIX_COLOR, .hash = 4 };
	struct node height = { .name = "dem", .out = PIX_HEIGHT, .hash = 5 };
	static const uint32_t sizes[] = { 256, 512 };
	for (size_t si = 0; si < 2; si++) {
		const uint32_t T = sizes[si];
		pl.tile_size = T;
		struct tile_key k = { .node = 9, .lx = 12, .ly = 11, .x = 2300, .y = 500 };
		uint32_t seed = 12345;
		struct tile *col[2], *hts[5];
		for (int c = 0; c < 2; c++) {
			col[c] = tile_create(&k, PIX_COLOR, T);
			for (size_t i = 0; i < col[c]->nbytes; i++)
				col[c]->data[i] = (uint8_t)rng(&seed);
			/* the base (photo) is opaque, the overlay has varying alpha */
			for (size_t i = 3; c == 0 && i < col[c]->nbytes; i += 4)
				col[c]->data[i] = 255;
		}
		for (int c = 0; c < 5; c++) {
			hts[c] = tile_create(&k, PIX_HEIGHT, T);
			float *h = tile_f32(hts[c]);
			for (uint32_t j = 0; j < T; j++)
				for (uint32_t i = 0; i < T; i++)
					h[j * T + i] = (float)(8000 * sin(i * 0.031 + c) *
								cos(j * 0.027 - c) +
							(rng(&seed) % 100));
		}
		struct {
			const char *label;
			const struct node_type *type;
			struct node *in0, *in1;
			const char *params;
			struct tile *const *in;
			int nin;
		} cases[] = {
			{ "color_filter/lut", &node_type_color_filter, &color, NULL,
			  "gamma = 2.2\ncontrast = 1.2\nin_black = 10", col, 1 },
			{ "color_filter/lut+hue+sat", &node_type_color_filter, &color, NULL,
			  "gamma = 2.2\nhue = 30\nsaturation = 1.3", col, 1 },
			{ "color_filter/hue+sat", &node_type_color_filter, &color, NULL,
			  "hue = 30\nsaturation = 1.3", col, 1 },
			{ "height_filter", &node_type_height_filter, &height, NULL,
			  "scale = 1.5\noffset = 20\nmin = -500\nmax = 6000", hts, 1 },
			{ "ramp", &node_type_ramp, &height, NULL, "", hts, 1 },
			{ "blend/over color", &node_type_blend, &color, &color2, "opacity = 0.7", col,
			  2 },
			{ "blend/over height", &node_type_blend, &height, &height, "opacity = 0.7",
			  hts, 2 },
			{ "normal", &node_type_normal, &height, NULL, "exaggeration = 2", hts, 5 },
		};
		for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
			struct bnode b;
			make(&b, cases[c].type, &pl, cases[c].in0, cases[c].in1, cases[c].params);
			double ns = measure(&b, &k, cases[c].in, cases[c].nin, T);
			printf("pixel/%s T=%u 1 worker: %.2f ns/texel\n", cases[c].label, T, ns);
			fflush(stdout);
			unmake(&b);
		}
		for (int c = 0; c < 2; c++)
			tile_unref(col[c]);
		for (int c = 0; c < 5; c++)
			tile_unref(hts[c]);
	}
	geo_body_destroy(pl.body);
	return 0;
}
