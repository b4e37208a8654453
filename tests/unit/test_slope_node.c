/* Tests of the `slope` node type: zero on flat ground, the metric slope of analytic planes
 * (east spacing shrinking with cos φ), seams (every tile of a level, at its own level and
 * interpolated from a coarser one, equals one computation over the whole level: wrapping at the
 * antimeridian, reflecting across the poles, fading to 0 on the pole rows), determinism and
 * parameter errors. Heights come
 * from a hand-made node type that evaluates a function at texel centres. */
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

#include "common/geo.h"
#include "common/ini.h"
#include "common/xalloc.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"

#define R 6371000.0

enum fn { FN_FLAT, FN_EAST, FN_NORTH, FN_BUMPS };

static double eval(enum fn fn, double lon, double lat)
{
	double la = lat * M_PI / 180, lo = lon * M_PI / 180;
	switch (fn) {
	case FN_FLAT: return 250.0;
	case FN_EAST: return 0.3 * R * lo; /* slope 0.3 / cos φ */
	case FN_NORTH: return 0.2 * R * la; /* slope 0.2 */
	case FN_BUMPS: {
		/* smooth in 3-D: any seam in the output is the node's fault */
		double p[3] = { cos(la) * cos(lo), cos(la) * sin(lo), sin(la) };
		return 4e5 * p[0] * p[2] + 3e5 * p[1] + 2e5 * sin(7 * p[0]) * p[1] +
		       1e5 * cos(11 * p[2] + 3 * p[1]);
	}
	}
	return 0;
}

static int an_create(struct node *n, struct node_parse *p)
{
	(void)p;
	n->out = PIX_HEIGHT;
	return 0;
}

static int an_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		       struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	(void)in;
	(void)nin;
	const enum fn *fn = n->impl;
	float *h = tile_f32(out);
	for (uint32_t j = 0; j < out->size; j++)
		for (uint32_t i = 0; i < out->size; i++) {
			double lon, lat;
			grid_texel_center(k, out->size, i, j, &lon, &lat);
			h[(size_t)j * out->size + i] = (float)eval(*fn, lon, lat);
		}
	return 0;
}

static const struct node_type analytic_type = {
	.name = "analytic", .doc = "test heights", .version = 1, .create = an_create,
	.generate = an_generate,
};

struct fixture {
	struct planet planet;
	enum fn fn;
	struct node src, sl;
	struct ini_file *ini;
	char err[256];
};

/* A sphere of tile size T, an analytic source and a slope node with `params` on it. */
static int setup(struct fixture *fx, uint32_t T, enum fn fn, const char *params)
{
	memset(fx, 0, sizeof *fx);
	fx->planet.a = R;
	fx->planet.tile_size = T;
	fx->planet.max_level = 12;
	assert_int_equal(geo_body_create(R, 0, &fx->planet.body, fx->err), 0);
	fx->fn = fn;
	fx->src = (struct node){ .name = "dem", .type = &analytic_type, .out = PIX_HEIGHT,
				 .hash = 77, .impl = &fx->fn, .planet = &fx->planet };
	char text[256];
	snprintf(text, sizeof text, "[node s]\n%s\n", params);
	assert_int_equal(ini_parse("s.ini", text, strlen(text), &fx->ini, fx->err), 0);
	fx->sl.name = "s";
	fx->sl.planet = &fx->planet;
	fx->sl.in[0] = &fx->src;
	return node_init(&fx->sl, &node_type_slope, "s.ini", &fx->ini->sections[0], fx->err);
}

static void teardown(struct fixture *fx)
{
	node_fini(&fx->sl);
	ini_free(fx->ini);
	geo_body_destroy(fx->planet.body);
}

/* Generates slope tile k the way a worker would: deps, then their tiles, then generate. */
static struct tile *slope_tile(struct fixture *fx, const struct tile_key *k)
{
	uint32_t T = fx->planet.tile_size;
	struct node_dep deps[NODE_MAX_DEPS];
	int nd = fx->sl.type->deps(&fx->sl, k, deps);
	assert_true(nd >= 1 && nd <= 9);
	struct tile *in[NODE_MAX_DEPS];
	struct gen_ctx g = { 0 };
	for (int d = 0; d < nd; d++) {
		assert_ptr_equal(deps[d].node, &fx->src);
		assert_int_equal(deps[d].key.node, fx->src.hash);
		in[d] = tile_create(&deps[d].key, PIX_HEIGHT, T);
		assert_int_equal(an_generate(&fx->src, &g, &deps[d].key, NULL, 0, in[d]), 0);
	}
	struct tile_key ok = *k;
	ok.node = fx->sl.hash;
	struct tile *out = tile_create(&ok, PIX_HEIGHT, T);
	assert_int_equal(fx->sl.type->generate(&fx->sl, &g, &ok, in, nd, out), 0);
	for (int d = 0; d < nd; d++)
		tile_unref(in[d]);
	gen_ctx_fini(&g);
	return out;
}

static void flat_and_planes(void **state)
{
	(void)state;
	const struct tile_key k = { .lx = 5, .ly = 4, .x = 9, .y = 6 };
	enum fn fns[] = { FN_FLAT, FN_EAST, FN_NORTH };
	for (int f = 0; f < 3; f++) {
		struct fixture fx;
		assert_int_equal(setup(&fx, 32, fns[f], ""), 0);
		/* on its own level: the tile and its four edge neighbours, as the normal node */
		struct node_dep deps[NODE_MAX_DEPS];
		assert_int_equal(fx.sl.type->deps(&fx.sl, &k, deps), 5);
		struct tile *t = slope_tile(&fx, &k);
		for (uint32_t j = 0; j < 32; j++)
			for (uint32_t i = 1; i + 1 < 32; i++) { /* the east plane jumps at ±180° */
				double lon, lat;
				grid_texel_center(&k, 32, i, j, &lon, &lat);
				double want = fns[f] == FN_FLAT ? 0
					    : fns[f] == FN_EAST ? 0.3 / cos(lat * M_PI / 180) : 0.2;
				double got = tile_f32(t)[j * 32 + i];
				if (fabs(got - want) > 1e-3 * want + 1e-6)
					fail_msg("fn %d texel (%u,%u) lat %.2f: %g, want %g", f, i, j,
						 lat, got, want);
			}
		tile_unref(t);
		teardown(&fx);
	}
}

/* The slope of the whole level (lx, ly) in double, texel by texel, as the node defines it. */
static double *level_slope(struct fixture *fx, int lx, int ly)
{
	const uint32_t T = fx->planet.tile_size, W = grid_tiles_x(lx) * T, H = grid_tiles_y(ly) * T;
	double *h = xmalloc((size_t)W * H * sizeof *h), *s = xmalloc((size_t)W * H * sizeof *s);
	for (uint32_t v = 0; v < H; v++)
		for (uint32_t u = 0; u < W; u++)
			h[(size_t)v * W + u] = (float)eval(fx->fn, grid_u_to_lon(lx, T, u + 0.5),
							    grid_v_to_lat(ly, T, v + 0.5));
	for (uint32_t v = 0; v < H; v++) {
		double lat = grid_v_to_lat(ly, T, v + 0.5);
		double dy = R * M_PI / H, dx = R * cos(lat * M_PI / 180) * 2 * M_PI / W;
		dx = dx > dy / 8 ? dx : dy / 8;
		for (uint32_t u = 0; u < W; u++) {
			uint32_t opp = (u + W / 2) % W; /* across a pole */
			double hn = v > 0 ? h[(size_t)(v - 1) * W + u] : h[opp];
			double hs = v + 1 < H ? h[(size_t)(v + 1) * W + u] : h[(size_t)(H - 1) * W + opp];
			double gx = (h[(size_t)v * W + (u + 1) % W] - h[(size_t)v * W + (u + W - 1) % W]) /
				    (2 * dx);
			double gy = (hn - hs) / (2 * dy);
			s[(size_t)v * W + u] = sqrt(gx * gx + gy * gy);
		}
	}
	free(h);
	return s;
}

/* The cubic B-spline's weights of the four samples around t ∈ [0, 1) (t from the second). */
static void bspline(double t, double w[4])
{
	double u = 1 - t;
	w[0] = u * u * u / 6;
	w[1] = (3 * t * t * t - 6 * t * t + 4) / 6;
	w[2] = (-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6;
	w[3] = t * t * t / 6;
}

/* Every tile of level (lx + dx, ly + d) against the level (lx, ly) slope interpolated with a
 * cubic B-spline at its texel centres (d = 0: the level's own slope). */
static void seamless_level(const char *params, int lx, int ly, int d, int dx, uint32_t T)
{
	struct fixture fx;
	assert_int_equal(setup(&fx, T, FN_BUMPS, params), 0);
	const int W = (int)(grid_tiles_x(lx) * T), H = (int)(grid_tiles_y(ly) * T);
	double *s = level_slope(&fx, lx, ly), big = 0;
	for (int i = 0; i < W * H; i++)
		big = s[i] > big ? s[i] : big;
	assert_true(big > 0.05); /* the field must vary, or a wrong neighbour goes unnoticed */
	const double step = ldexp(1.0, -d);
	for (uint32_t y = 0; y < grid_tiles_y(ly + d); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx + dx); x++) {
			struct tile_key k = { .lx = (uint8_t)(lx + dx), .ly = (uint8_t)(ly + d),
					      .x = x, .y = y };
			struct tile *t = slope_tile(&fx, &k);
			for (uint32_t j = 0; j < T; j++)
				for (uint32_t i = 0; i < T; i++) {
					double fu = ((double)x * T + i + 0.5) * ldexp(1.0, -dx) - 0.5;
					double fv = ((double)y * T + j + 0.5) * step - 0.5;
					int u0 = (int)floor(fu), v0 = (int)floor(fv);
					double bu[4], bv[4], want = 0;
					bspline(fu - u0, bu);
					bspline(fv - v0, bv);
					for (int b = 0; b < 4; b++)
						for (int a = 0; a < 4; a++) {
							int u = u0 - 1 + a, v = v0 - 1 + b;
							if (v < 0 || v >= H) {
								v = v < 0 ? -1 - v : 2 * H - 1 - v;
								u += W / 2;
							}
							want += bu[a] * bv[b] *
								s[(size_t)v * W + (size_t)((u % W + W) % W)];
						}
					if (d == 0) /* on its own level: the texel itself */
						want = s[(size_t)(y * T + j) * W + x * T + i];
					/* faded to 0 over the last source texel before a pole */
					double lat = fabs(grid_v_to_lat(ly + d, T, (double)y * T + j + 0.5));
					double fade = (90 - lat) / (180.0 / H) - 0.5;
					want *= fade < 0 ? 0 : fade > 1 ? 1 : fade;
					double got = tile_f32(t)[j * T + i];
					if (fabs(got - want) > 2e-3 * big)
						fail_msg("%s level (%d,%d)+%d tile (%u,%u) texel (%u,%u): "
							 "%g, want %g", params, lx, ly, d, x, y, i, j,
							 got, want);
				}
			tile_unref(t);
		}
	free(s);
	teardown(&fx);
}

static void seamless(void **state)
{
	(void)state;
	seamless_level("", 3, 2, 0, 0, 32); /* isotropic, own level */
	seamless_level("", 2, 3, 0, 0, 16); /* anisotropic, as near the poles */
	seamless_level("", 1, 0, 0, 0, 32); /* two tiles: each is the other's pole neighbour */
	seamless_level("", 0, 0, 0, 0, 64); /* one tile: its own neighbour, half a turn round */
	/* scale 600 km on T = 16: texels ≥ 300 km are level 2; levels 3 and 4 interpolate it */
	seamless_level("scale = 600000", 3, 2, 1, 1, 16);
	seamless_level("scale = 600000", 3, 2, 2, 2, 16);
	/* (0, 4) next to a pole: lx 0 stays lx 0, ly 4 interpolates ly 2 */
	seamless_level("scale = 600000", 0, 2, 2, 0, 16);
}

static void deterministic(void **state)
{
	(void)state;
	struct fixture fx;
	assert_int_equal(setup(&fx, 16, FN_BUMPS, "scale = 600000"), 0);
	const struct tile_key k = { .lx = 6, .ly = 5, .x = 40, .y = 3 };
	struct tile *a = slope_tile(&fx, &k), *b = slope_tile(&fx, &k);
	assert_memory_equal(a->data, b->data, 16 * 16 * sizeof(float));
	tile_unref(a);
	tile_unref(b);
	teardown(&fx);
}

static void errors(void **state)
{
	(void)state;
	struct fixture fx;
	assert_int_equal(setup(&fx, 32, FN_FLAT, "scale = -5"), -EINVAL);
	assert_non_null(strstr(fx.err, "s.ini:2: scale:"));
	teardown(&fx);
	assert_int_equal(setup(&fx, 32, FN_FLAT, "scale = far"), -EINVAL);
	assert_non_null(strstr(fx.err, "s.ini:2: scale:"));
	teardown(&fx);
	assert_int_equal(setup(&fx, 32, FN_FLAT, "scael = 5"), -EINVAL);
	assert_non_null(strstr(fx.err, "s.ini:2: scael: unknown key"));
	teardown(&fx);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(flat_and_planes), cmocka_unit_test(seamless),
		cmocka_unit_test(deterministic),   cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests_name("slope", tests, NULL, NULL);
}
