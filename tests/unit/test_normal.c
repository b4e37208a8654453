/* Tests of the `normal` node type: straight up on flat ground, the metric slope on the
 * ellipsoid (east spacing shrinking with cos φ), and seams: height tiles come from a
 * hand-made node type that evaluates an analytic function at texel centres, and every normal
 * tile of a level must equal one computation over the whole level (wrapping at the
 * antimeridian, reflecting across the poles). */
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

#define SPHERE_R 6371000.0

enum fn { FN_FLAT, FN_EAST, FN_NORTH, FN_BUMPS, FN_FLAT_NAN };

/* The analytic height source: impl points to an enum fn; s is a slope (m/m). */
struct analytic {
	enum fn fn;
	double s, a;
};

static double bump(const double p[3], double lat, double lon, double amp, double sigma)
{
	double la = lat * M_PI / 180, lo = lon * M_PI / 180;
	double q[3] = { cos(la) * cos(lo), cos(la) * sin(lo), sin(la) };
	double d2 = (p[0] - q[0]) * (p[0] - q[0]) + (p[1] - q[1]) * (p[1] - q[1]) +
		    (p[2] - q[2]) * (p[2] - q[2]);
	return amp * exp(-d2 / (sigma * sigma));
}

static double eval(const struct analytic *an, double lon, double lat)
{
	double la = lat * M_PI / 180, lo = lon * M_PI / 180;
	switch (an->fn) {
	case FN_FLAT: return 123.0;
	case FN_FLAT_NAN: return fabs(lon - 22.5) < 2 ? NAN : -40.0;
	case FN_EAST: return an->s * an->a * lo;
	case FN_NORTH: return an->s * an->a * la;
	case FN_BUMPS: {
		/* smooth in 3-D, so any seam in the output is the node's fault; bumps sit on the
		 * antimeridian, next to both poles and on tile corners */
		double p[3] = { cos(la) * cos(lo), cos(la) * sin(lo), sin(la) };
		return 400 * p[0] * p[2] + 300 * p[1] + 250 * p[0] * p[1] +
		       bump(p, 10, 180, 3000, 0.15) + bump(p, 89, 30, 2500, 0.1) +
		       bump(p, -88.5, -100, -2000, 0.12) + bump(p, 45, 45, 1500, 0.2) +
		       bump(p, 0, -90, 1800, 0.1) + bump(p, 85, -170, 1200, 0.1);
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
	const struct analytic *an = n->impl;
	float *h = tile_f32(out);
	for (uint32_t j = 0; j < out->size; j++)
		for (uint32_t i = 0; i < out->size; i++) {
			double lon, lat;
			grid_texel_center(k, out->size, i, j, &lon, &lat);
			h[(size_t)j * out->size + i] = (float)eval(an, lon, lat);
		}
	return 0;
}

static const struct node_type analytic_type = {
	.name = "analytic", .doc = "test heights", .version = 1, .create = an_create,
	.generate = an_generate,
};

struct fixture {
	struct planet planet;
	struct analytic an;
	struct node src;
	struct node nn;
	struct ini_file *ini;
	char err[256];
};

/* A planet of the given body and tile size, an analytic source and a normal node on it. */
static int setup(struct fixture *fx, double a, double f, uint32_t T, enum fn fn, double s,
		 const char *params)
{
	memset(fx, 0, sizeof *fx);
	fx->planet.a = a;
	fx->planet.f = f;
	fx->planet.tile_size = T;
	fx->planet.max_level = 10;
	assert_int_equal(geo_body_create(a, f, &fx->planet.body, fx->err), 0);
	fx->an = (struct analytic){ fn, s, a };
	fx->src = (struct node){ .name = "dem", .type = &analytic_type, .out = PIX_HEIGHT,
				 .hash = 77, .impl = &fx->an, .planet = &fx->planet };
	char text[256];
	snprintf(text, sizeof text, "[node n]\n%s\n", params);
	assert_int_equal(ini_parse("n.ini", text, strlen(text), &fx->ini, fx->err), 0);
	fx->nn.name = "n";
	fx->nn.planet = &fx->planet;
	fx->nn.in[0] = &fx->src;
	return node_init(&fx->nn, &node_type_normal, "n.ini", &fx->ini->sections[0], fx->err);
}

static void teardown(struct fixture *fx)
{
	node_fini(&fx->nn);
	ini_free(fx->ini);
	geo_body_destroy(fx->planet.body);
}

/* Generates normal tile k the way a worker would: deps, then their tiles, then generate. */
static struct tile *normal_tile(struct fixture *fx, const struct tile_key *k)
{
	uint32_t T = fx->planet.tile_size;
	struct node_dep deps[NODE_MAX_DEPS];
	int nd = fx->nn.type->deps(&fx->nn, k, deps);
	assert_true(nd >= 1 && nd <= 5);
	struct tile *in[NODE_MAX_DEPS];
	struct gen_ctx g = { 0 };
	for (int d = 0; d < nd; d++) {
		assert_ptr_equal(deps[d].node, &fx->src);
		assert_int_equal(deps[d].key.node, fx->src.hash);
		in[d] = tile_create(&deps[d].key, PIX_HEIGHT, T);
		assert_int_equal(an_generate(&fx->src, &g, &deps[d].key, NULL, 0, in[d]), 0);
	}
	struct tile_key ok = *k;
	ok.node = fx->nn.hash;
	struct tile *out = tile_create(&ok, PIX_NORMAL, T);
	assert_int_equal(fx->nn.type->generate(&fx->nn, &g, &ok, in, nd, out), 0);
	for (int d = 0; d < nd; d++)
		tile_unref(in[d]);
	gen_ctx_fini(&g);
	return out;
}

static uint8_t enc(double c)
{
	return (uint8_t)floor((c + 1) * 127.5 + 0.5);
}

static void flat(void **state)
{
	(void)state;
	struct fixture fx;
	assert_int_equal(setup(&fx, GEO_WGS84_A, GEO_WGS84_F, 64, FN_FLAT, 0, ""), 0);
	assert_int_equal(fx.nn.out, PIX_NORMAL);
	const struct tile_key keys[] = { { .lx = 3, .ly = 2, .x = 5, .y = 1 },
					 { .lx = 3, .ly = 2, .x = 0, .y = 0 },
					 { .lx = 0, .ly = 0, .x = 0, .y = 0 } };
	for (size_t c = 0; c < 3; c++) {
		struct tile *t = normal_tile(&fx, &keys[c]);
		for (size_t i = 0; i < t->nbytes; i++)
			if (t->data[i] != 128)
				fail_msg("texel %zu: %d, want 128", i / 2, t->data[i]);
		tile_unref(t);
	}
	teardown(&fx);
	/* no data (NaN) gives straight up too, not garbage */
	assert_int_equal(setup(&fx, SPHERE_R, 0, 64, FN_FLAT_NAN, 0, ""), 0);
	struct tile_key knan = { .lx = 3, .ly = 2, .x = 4, .y = 1 }; /* NaN around 22.5°E */
	struct tile *t = normal_tile(&fx, &knan);
	for (size_t i = 0; i < t->nbytes; i++)
		assert_int_equal(t->data[i], 128);
	tile_unref(t);
	teardown(&fx);
}

/* h = s·a·λ: on a sphere the east slope is s / cos φ, so at 60° it doubles. */
static void slope_east(void **state)
{
	(void)state;
	struct fixture fx;
	const uint32_t T = 64;
	const double s = 0.5;
	assert_int_equal(setup(&fx, SPHERE_R, 0, T, FN_EAST, s, ""), 0);
	struct tile_key eq = { .lx = 3, .ly = 2, .x = 4, .y = 1 }; /* 0..45°E, 45°N..0 */
	struct tile_key hi = { .lx = 3, .ly = 2, .x = 5, .y = 0 }; /* 45..90°E, 90..45°N */
	struct tile *te = normal_tile(&fx, &eq), *th = normal_tile(&fx, &hi);
	/* next to the equator: slope 0.5 → e = -0.5/√1.25 → 70 */
	assert_int_equal(te->data[2 * ((T - 1) * T + 9)], 70);
	assert_int_equal(te->data[2 * ((T - 1) * T + 9) + 1], 128);
	/* row 42 is at 60.12°N: slope ≈ 1 → e = -1/√2 → 37 */
	assert_int_equal(th->data[2 * (42 * T + 0)], 37);
	assert_int_equal(th->data[2 * (42 * T + T - 1)], 37);
	for (int which = 0; which < 2; which++) {
		struct tile *t = which ? th : te;
		const struct tile_key *k = which ? &hi : &eq;
		for (uint32_t j = 0; j < T; j++) {
			double lon, lat;
			grid_texel_center(k, T, 0, j, &lon, &lat);
			double g = s / cos(lat * M_PI / 180);
			uint8_t want = enc(-g / sqrt(1 + g * g));
			for (uint32_t i = 0; i < T; i++) {
				int e = t->data[2 * (j * T + i)], n = t->data[2 * (j * T + i) + 1];
				/* across the pole the plane folds: row 0 of the polar tile
				 * has a north slope */
				if (which == 1 && j == 0)
					continue;
				if (abs(e - want) > 1 || n != 128)
					fail_msg("tile %d texel (%u,%u) at %.2f°: (%d,%d), want (%d,128)",
						 which, i, j, lat, e, n, want);
			}
		}
	}
	tile_unref(te);
	tile_unref(th);
	teardown(&fx);

	/* WGS84: east spacing is N(φ)·cos φ·Δλ with the transverse radius N */
	assert_int_equal(setup(&fx, GEO_WGS84_A, GEO_WGS84_F, T, FN_EAST, s, "exaggeration = 2"),
			 0);
	th = normal_tile(&fx, &hi);
	for (uint32_t j = 3; j < T; j += 7) {
		double lon, lat, m, nr;
		grid_texel_center(&hi, T, 0, j, &lon, &lat);
		geo_radii(fx.planet.body, lat, &m, &nr);
		double g = 2 * s * GEO_WGS84_A / (nr * cos(lat * M_PI / 180));
		int want = enc(-g / sqrt(1 + g * g));
		int got = th->data[2 * (j * T + 17)];
		if (abs(got - want) > 1)
			fail_msg("WGS84 row %u at %.2f°: %d, want %d", j, lat, got, want);
	}
	tile_unref(th);
	teardown(&fx);
}

/* h = s·a·φ on a sphere: north slope s everywhere; uphill to the north tilts the normal south. */
static void slope_north(void **state)
{
	(void)state;
	struct fixture fx;
	const uint32_t T = 32;
	assert_int_equal(setup(&fx, SPHERE_R, 0, T, FN_NORTH, 0.5, ""), 0);
	struct tile_key k = { .lx = 3, .ly = 2, .x = 2, .y = 1 };
	struct tile *t = normal_tile(&fx, &k);
	for (uint32_t i = 0; i < T * T; i++) {
		assert_int_equal(t->data[2 * i], 128);
		assert_int_equal(t->data[2 * i + 1], 70);
	}
	tile_unref(t);
	teardown(&fx);
}

static void deps(void **state)
{
	(void)state;
	struct fixture fx;
	assert_int_equal(setup(&fx, SPHERE_R, 0, 32, FN_FLAT, 0, ""), 0);
	struct node_dep d[NODE_MAX_DEPS];
	/* the north-west corner tile: west wraps to x = 3, north crosses the pole to x = 2 */
	struct tile_key k = { .node = 5, .lx = 2, .ly = 1, .x = 0, .y = 0 };
	int n = fx.nn.type->deps(&fx.nn, &k, d);
	assert_int_equal(n, 5);
	const uint32_t want[5][2] = { { 0, 0 }, { 3, 0 }, { 1, 0 }, { 2, 0 }, { 0, 1 } };
	for (int i = 0; i < 5; i++) {
		bool found = false;
		for (int q = 0; q < n; q++)
			found |= d[q].key.x == want[i][0] && d[q].key.y == want[i][1] &&
				 d[q].key.lx == 2 && d[q].key.ly == 1 && d[q].key.node == 77;
		if (!found)
			fail_msg("tile (%u,%u) is not among the deps", want[i][0], want[i][1]);
	}
	/* duplicates are merged: level (0,0) is one tile, level (1,0) two */
	k = (struct tile_key){ .lx = 0, .ly = 0 };
	assert_int_equal(fx.nn.type->deps(&fx.nn, &k, d), 1);
	k = (struct tile_key){ .lx = 1, .ly = 0, .x = 1 };
	assert_int_equal(fx.nn.type->deps(&fx.nn, &k, d), 2);
	teardown(&fx);
}

/* Normal tiles of a whole level against one computation over the level's texels. */
static void seamless_level(int lx, int ly, uint32_t T)
{
	struct fixture fx;
	assert_int_equal(setup(&fx, GEO_WGS84_A, GEO_WGS84_F, T, FN_BUMPS, 0,
			       "exaggeration = 1000"), 0);
	const uint32_t W = grid_tiles_x(lx) * T, H = grid_tiles_y(ly) * T;
	float *h = xmalloc((size_t)W * H * sizeof *h);
	for (uint32_t v = 0; v < H; v++)
		for (uint32_t u = 0; u < W; u++)
			h[(size_t)v * W + u] = (float)eval(&fx.an, grid_u_to_lon(lx, T, u + 0.5),
							    grid_v_to_lat(ly, T, v + 0.5));
	uint8_t *ref = xmalloc((size_t)W * H * 2);
	int steep = 0;
	for (uint32_t v = 0; v < H; v++) {
		double lat = grid_v_to_lat(ly, T, v + 0.5), m, nr;
		geo_radii(fx.planet.body, lat, &m, &nr);
		double r = nr * cos(lat * M_PI / 180), dlam = 2 * M_PI / W;
		double dx = r * dlam, dy = m * M_PI / H;
		/* The east stencil: ±1 texel, wider where texels are 8× narrower than tall (near
		 * the poles): k = dy / 4dx texels, at most T and a quarter turn, over its chord. */
		uint32_t kmax = W / 4 < T ? (W / 4 > 0 ? W / 4 : 1) : T, k = 1;
		if (dy >= 8 * dx)
			k = floor(dy / (4 * dx)) < kmax ? (uint32_t)floor(dy / (4 * dx)) : kmax;
		double len = k == 1 ? 2 * dx : 2 * r * sin(k * dlam);
		for (uint32_t u = 0; u < W; u++) {
			uint32_t opp = (u + W / 2) % W; /* across a pole */
			double hw = h[(size_t)v * W + (u + W - k) % W], he = h[(size_t)v * W + (u + k) % W];
			double hn = v > 0 ? h[(size_t)(v - 1) * W + u] : h[opp];
			double hs = v + 1 < H ? h[(size_t)(v + 1) * W + u] : h[(size_t)(H - 1) * W + opp];
			double gx = 1000 * (he - hw) / len, gy = 1000 * (hn - hs) / (2 * dy);
			double l = sqrt(1 + gx * gx + gy * gy);
			ref[2 * ((size_t)v * W + u)] = enc(-gx / l);
			ref[2 * ((size_t)v * W + u) + 1] = enc(-gy / l);
			steep += fabs(gx / l) > 0.5;
		}
	}
	/* the bumps must tilt normals a lot, or a wrong neighbour could go unnoticed */
	print_message("level (%d,%d): %d steep texels of %u\n", lx, ly, steep, W * H);
	assert_true(steep > 20);
	int off = 0;
	for (uint32_t y = 0; y < grid_tiles_y(ly); y++)
		for (uint32_t x = 0; x < grid_tiles_x(lx); x++) {
			struct tile_key k = { .lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x, .y = y };
			struct tile *t = normal_tile(&fx, &k);
			for (uint32_t j = 0; j < T; j++)
				for (uint32_t i = 0; i < T; i++)
					for (int c = 0; c < 2; c++) {
						size_t u = (size_t)x * T + i, v = (size_t)y * T + j;
						int got = t->data[2 * (j * T + i) + c];
						int want = ref[2 * (v * W + u) + c];
						off += got != want;
						if (abs(got - want) > 1)
							fail_msg("level (%d,%d) tile (%u,%u) texel "
								 "(%u,%u) comp %d: %d, want %d",
								 lx, ly, x, y, i, j, c, got, want);
					}
			tile_unref(t);
		}
	/* float vs double may round differently now and then, not often */
	assert_true(off < (int)(W * H / 100) + 2);
	free(h);
	free(ref);
	teardown(&fx);
}

static void seamless(void **state)
{
	(void)state;
	seamless_level(3, 2, 32); /* isotropic */
	seamless_level(2, 3, 16); /* anisotropic, as near the poles */
	seamless_level(5, 4, 16); /* finer: narrow tiles at the poles */
	seamless_level(1, 0, 32); /* two tiles: each is the other's pole neighbour */
	seamless_level(0, 0, 64); /* one tile: it is its own neighbour, half a turn round */
}

static void errors(void **state)
{
	(void)state;
	struct fixture fx;
	assert_int_equal(setup(&fx, SPHERE_R, 0, 32, FN_FLAT, 0, "exaggeration = lots"), -EINVAL);
	assert_non_null(strstr(fx.err, "n.ini:2: exaggeration:"));
	teardown(&fx);
	assert_int_equal(setup(&fx, SPHERE_R, 0, 32, FN_FLAT, 0, "exagerration = 2"), -EINVAL);
	assert_non_null(strstr(fx.err, "n.ini:2: exagerration: unknown key"));
	teardown(&fx);
	/* the planet's body is needed for metric spacing */
	assert_int_equal(setup(&fx, SPHERE_R, 0, 32, FN_FLAT, 0, ""), 0);
	node_fini(&fx.nn);
	const struct planet *keep = fx.nn.planet;
	struct planet nobody = { .tile_size = 32 };
	fx.nn.planet = &nobody;
	fx.nn.hash = 0;
	assert_int_equal(node_init(&fx.nn, &node_type_normal, "n.ini", &fx.ini->sections[0], fx.err),
			 -EINVAL);
	assert_non_null(strstr(fx.err, "body"));
	fx.nn.planet = keep;
	teardown(&fx);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(flat),	    cmocka_unit_test(slope_east), cmocka_unit_test(slope_north),
		cmocka_unit_test(deps),	    cmocka_unit_test(seamless),	  cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests_name("normal", tests, NULL, NULL);
}
