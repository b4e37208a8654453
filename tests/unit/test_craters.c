/* test_craters — the `craters` node and field: tiles equal the point oracle at texel centres
 * (ordinary, antimeridian and pole tiles), continuity across tile borders, the antimeridian
 * and the pole, determinism and seeds, band-limiting by level, craters actually dug, input
 * added, parameter errors with file:line. */
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

#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/nodes/craters.h"
#include "engine/planet.h"
#include "engine/tile.h"

#define T 64

static struct planet pl = { .a = 1737400.0, .tile_size = T, .max_level = 16 };

struct cnode {
	struct ini_file *ini;
	struct node n;
	struct gen_ctx g;
};

static int cnode_init(struct cnode *c, const char *text, char err[256])
{
	memset(c, 0, sizeof *c);
	int rc = ini_parse("test.ini", text, strlen(text), &c->ini, err);
	if (rc)
		return rc;
	struct ini_section *sec = &c->ini->sections[0];
	struct ini_entry *t = ini_find(sec, "type");
	if (t)
		t->used = true;
	c->n.name = "x";
	c->n.planet = &pl;
	return node_init(&c->n, &node_type_craters, "test.ini", sec, err);
}

static void cnode_ok(struct cnode *c, const char *text)
{
	char err[256] = "";
	if (cnode_init(c, text, err))
		fail_msg("node_init: %s", err);
}

static void cnode_fini(struct cnode *c)
{
	node_fini(&c->n);
	gen_ctx_fini(&c->g);
	ini_free(c->ini);
}

static const char *const MOON = "[node x]\ntype = craters\nseed = 7\nmin_radius = 50\n"
				"max_radius = 80000\ndensity = 1\n";

static struct tile *gen(struct cnode *c, int lx, int ly, uint32_t x, uint32_t y)
{
	struct tile_key k = { .node = c->n.hash, .x = x, .y = y, .lx = (uint8_t)lx,
			      .ly = (uint8_t)ly };
	struct tile *t = tile_create(&k, PIX_HEIGHT, T);
	int rc = c->n.type->generate(&c->n, &c->g, &k, NULL, 0, t);
	if (rc)
		fail_msg("generate (%d,%d) %u,%u: %d", lx, ly, x, y, rc);
	return t;
}

static float at(const struct tile *t, uint32_t i, uint32_t j)
{
	return tile_f32(t)[(size_t)j * T + i];
}

/* Every 3rd texel of the tile against craters_point at its centre. */
static void check_oracle(struct cnode *c, int lx, int ly, uint32_t x, uint32_t y)
{
	const struct craters *cr = c->n.impl;
	struct tile *t = gen(c, lx, ly, x, y);
	double worst = 0, amp = 0;
	for (uint32_t j = 0; j < T; j += 3) {
		for (uint32_t i = 0; i < T; i += 3) {
			double lon, lat;
			grid_texel_center(&t->key, T, i, j, &lon, &lat);
			double want = craters_point(cr, lon, lat, ly, T);
			double e = fabs(at(t, i, j) - want);
			worst = e > worst ? e : worst;
			amp = fabs(want) > amp ? fabs(want) : amp;
		}
	}
	if (worst > 1e-3 + 1e-6 * amp)
		fail_msg("tile (%d,%d) %u,%u differs from the oracle by %g m (field up to %g m)", lx,
			 ly, x, y, worst, amp);
	if (!(amp > 1))
		fail_msg("tile (%d,%d) %u,%u has no craters (max |h| %g m)", lx, ly, x, y, amp);
	tile_unref(t);
}

static void oracle(void **state)
{
	(void)state;
	struct cnode c;
	cnode_ok(&c, MOON);
	check_oracle(&c, 1, 2, 0, 1); /* 180° wide: craters wrap across the antimeridian */
	check_oracle(&c, 0, 2, 0, 2); /* all longitudes in one tile */
	check_oracle(&c, 3, 2, 5, 1);
	check_oracle(&c, 6, 5, 0, 7);	/* west edge at -180° */
	check_oracle(&c, 6, 5, 63, 20); /* east edge at 180° */
	check_oracle(&c, 6, 5, 17, 0);	/* touches the north pole */
	check_oracle(&c, 5, 5, 3, 31);	/* anisotropic, touches the south pole */
	check_oracle(&c, 12, 11, 1000, 700);
	cnode_fini(&c);
}

/* Largest |difference| between horizontally / vertically adjacent texels inside t. */
static double max_step(const struct tile *t)
{
	double m = 0;
	for (uint32_t j = 0; j < T; j++)
		for (uint32_t i = 0; i + 1 < T; i++) {
			double a = fabs(at(t, i + 1, j) - at(t, i, j));
			double b = fabs(at(t, j, i + 1) - at(t, j, i));
			m = a > m ? a : m;
			m = b > m ? b : m;
		}
	return m;
}

static void seams(void **state)
{
	(void)state;
	struct cnode c;
	cnode_ok(&c, MOON);
	const int lx = 5, ly = 4; /* texels of ~5 km: big craters are several texels wide */
	uint32_t nx = 1u << lx;
	/* Antimeridian: the east column of the last tile against the west column of tile 0. */
	struct tile *e = gen(&c, lx, ly, nx - 1, 6), *w = gen(&c, lx, ly, 0, 6);
	double lim = fmax(max_step(e), max_step(w));
	double across = 0;
	for (uint32_t j = 0; j < T; j++)
		across = fmax(across, fabs(at(e, T - 1, j) - at(w, 0, j)));
	if (!(across <= lim * 1.05 + 1e-3))
		fail_msg("antimeridian step %g m, inside the tiles at most %g m", across, lim);
	if (!(lim > 10))
		fail_msg("tiles are flat (max step %g m)", lim);
	tile_unref(e);
	tile_unref(w);

	/* An ordinary vertical border. */
	struct tile *n = gen(&c, lx, ly, 9, 5), *s = gen(&c, lx, ly, 9, 6);
	lim = fmax(max_step(n), max_step(s));
	across = 0;
	for (uint32_t i = 0; i < T; i++)
		across = fmax(across, fabs(at(n, i, T - 1) - at(s, i, 0)));
	if (!(across <= lim * 1.05 + 1e-3))
		fail_msg("border step %g m, inside the tiles at most %g m", across, lim);
	tile_unref(n);
	tile_unref(s);

	/* North pole: row 0 of tile x and of the tile half-way round are neighbours across the
	 * pole (column i of one faces column T-1-i of the other). */
	struct tile *a = gen(&c, lx, ly, 3, 0), *b = gen(&c, lx, ly, 3 + nx / 2, 0);
	lim = fmax(max_step(a), max_step(b));
	across = 0;
	for (uint32_t i = 0; i < T; i++)
		across = fmax(across, fabs(at(a, i, 0) - at(b, T - 1 - i, 0)));
	if (!(across <= lim * 1.05 + 1e-3))
		fail_msg("step across the pole %g m, inside the tiles at most %g m", across, lim);
	tile_unref(a);
	tile_unref(b);
	cnode_fini(&c);
}

static void determinism_and_seed(void **state)
{
	(void)state;
	struct cnode c1, c2, c3;
	cnode_ok(&c1, MOON);
	cnode_ok(&c2, MOON);
	cnode_ok(&c3, "[node x]\ntype = craters\nseed = 8\nmin_radius = 50\nmax_radius = 80000\n"
		      "density = 1\n");
	assert_int_equal(c1.n.hash, c2.n.hash);
	assert_true(c1.n.hash != c3.n.hash);
	struct tile *a = gen(&c1, 7, 6, 40, 20), *b = gen(&c2, 7, 6, 40, 20),
		    *d = gen(&c3, 7, 6, 40, 20);
	assert_memory_equal(a->data, b->data, a->nbytes);
	size_t differ = 0;
	for (uint32_t i = 0; i < T * T; i++)
		differ += tile_f32(a)[i] != tile_f32(d)[i];
	if (differ < T * T / 2)
		fail_msg("seeds 7 and 8 share %zu of %d texels", (size_t)T * T - differ, T * T);
	tile_unref(a);
	tile_unref(b);
	tile_unref(d);
	cnode_fini(&c1);
	cnode_fini(&c2);
	cnode_fini(&c3);
}

static void band_limit(void **state)
{
	(void)state;
	struct cnode c;
	cnode_ok(&c, MOON);
	const struct craters *cr = c.n.impl;
	float *buf = malloc(sizeof(float) * T * T);
	void *scratch = malloc(craters_scratch_size(T));
	struct tile_key k0 = { .lx = 2, .ly = 1 }, k9 = { .lx = 10, .ly = 9, .x = 300, .y = 200 };
	int used0 = craters_tile(cr, &k0, T, scratch, buf);
	int used9 = craters_tile(cr, &k9, T, scratch, buf);
	/* Level 1 texels are ~43 km: only the largest class (R 80..160 km, ≥ 2 texels across)
	 * shows; level 9 texels are ~170 m: classes down to R ≈ 170 m. */
	if (!(used0 == 1 && used9 > used0 + 6))
		fail_msg("classes evaluated: level 0 %d, level 9 %d", used0, used9);
	for (int k = 0; k < cr->nclass; k++) {
		double s9 = 2 * M_PI * pl.a / 2 / (512.0 * T); /* latitudinal texel at ly 9 */
		double w = craters_band_weight(cr->r[k], s9);
		if (cr->r[k] < s9 / 2 && w != 0)
			fail_msg("class R=%g m is under a texel (%g m) but has weight %g", cr->r[k],
				 s9, w);
	}
	/* A coarse tile keeps roughly the mean of its children: the classes are centred. */
	struct tile_key p = { .lx = 6, .ly = 5, .x = 20, .y = 10 };
	assert_true(craters_tile(cr, &p, T, scratch, buf) > 0);
	double mp = 0, mc = 0, var = 0;
	for (int i = 0; i < T * T; i++)
		mp += buf[i] / (T * T), var += (double)buf[i] * buf[i] / (T * T);
	for (int q = 0; q < 4; q++) {
		struct tile_key ch = { .lx = 7, .ly = 6, .x = 40 + (q & 1), .y = 20 + (q >> 1) };
		assert_true(craters_tile(cr, &ch, T, scratch, buf) > 0);
		for (int i = 0; i < T * T; i++)
			mc += buf[i] / (4.0 * T * T);
	}
	double sd = sqrt(var - mp * mp);
	if (!(fabs(mp - mc) < 0.5 * sd))
		fail_msg("parent mean %g m, children mean %g m (parent sd %g m)", mp, mc, sd);
	free(buf);
	free(scratch);
	cnode_fini(&c);
}

static void digs_craters(void **state)
{
	(void)state;
	struct cnode c;
	cnode_ok(&c, MOON);
	/* Over a level-3 world (texels ~11 km) there are bowls kilometres deep and rims. */
	double lo = 0, hi = 0;
	for (uint32_t x = 0; x < 16; x += 3) {
		struct tile *t = gen(&c, 4, 3, x, 3);
		for (int i = 0; i < T * T; i++) {
			lo = fmin(lo, tile_f32(t)[i]);
			hi = fmax(hi, tile_f32(t)[i]);
		}
		tile_unref(t);
	}
	if (!(lo < -1500 && hi > 200 && lo > -40000 && hi < 20000))
		fail_msg("crater heights %g .. %g m", lo, hi);
	cnode_fini(&c);
}

/* Small, worn craters (0.6-19.5 m, degradation) and boulders: tile = oracle at a fine level
 * (texels ~8 cm, every class at full weight) and across a tile border; worn craters are
 * shallower on average than fresh ones in the same places; boulders only raise the ground
 * (a tile's minimum is minus the class means: no bowls). */
static const char *const SMALL = "[node x]\ntype = craters\nseed = 2\nmin_radius = 0.6\n"
				 "max_radius = 19.5\ndensity = 1.6\ndegradation = 0.85\n";

static void small_worn_and_boulders(void **state)
{
	(void)state;
	struct cnode c, f, b;
	cnode_ok(&c, SMALL);
	cnode_ok(&f, "[node x]\ntype = craters\nseed = 2\nmin_radius = 0.6\n"
		     "max_radius = 19.5\ndensity = 1.6\n");
	cnode_ok(&b, "[node x]\ntype = craters\nkind = boulder\nseed = 6\nmin_radius = 0.08\n"
		     "max_radius = 1.3\ndensity = 0.35\ndepth_ratio = 0.35\n");
	const struct craters *cr = c.n.impl;
	assert_int_equal(cr->nclass, 6);
	check_oracle(&c, 19, 18, 300000, 70000);
	check_oracle(&c, 19, 18, 300001, 70000);
	/* worn vs fresh: same seeds, so the same craters; the spread of heights shrinks */
	double vw = 0, vf = 0;
	for (uint32_t x = 0; x < 16; x++) {
		struct tile *tw = gen(&c, 17, 16, 70000 + 3 * x, 17000),
			    *tf = gen(&f, 17, 16, 70000 + 3 * x, 17000);
		double mw = 0, mf = 0;
		for (int i = 0; i < T * T; i++)
			mw += tile_f32(tw)[i], mf += tile_f32(tf)[i];
		mw /= T * T, mf /= T * T;
		for (int i = 0; i < T * T; i++) {
			vw += (tile_f32(tw)[i] - mw) * (tile_f32(tw)[i] - mw) / (T * T);
			vf += (tile_f32(tf)[i] - mf) * (tile_f32(tf)[i] - mf) / (T * T);
		}
		tile_unref(tw);
		tile_unref(tf);
	}
	if (!(vw < 0.85 * vf && vw > 0.05 * vf))
		fail_msg("worn variance %g m², fresh %g m²", vw, vf);
	/* boulders, at level 20 (texels ~2 cm) */
	const struct craters *bc = b.n.impl;
	double base = 0;
	for (int k = 0; k < bc->nclass; k++)
		base += bc->mean[k];
	assert_true(base > 0);
	struct tile *tb = gen(&b, 21, 20, 1200000, 280000);
	double lo = 1e9, hi = -1e9;
	for (int i = 0; i < T * T; i++)
		lo = fmin(lo, tile_f32(tb)[i]), hi = fmax(hi, tile_f32(tb)[i]);
	if (!(lo > -base - 1e-4 && hi > 0.05))
		fail_msg("boulders: %g .. %g m (class means %g m)", lo, hi, base);
	tile_unref(tb);
	cnode_fini(&b);
	cnode_fini(&f);
	cnode_fini(&c);
}

/* Near a pole, classes that bend over a texel (every boulder class at 4 cm texels) fade out:
 * 0 on the two rows nearest each pole whatever the longitude, full from the fourth; the tile
 * still matches the oracle there. */
static void pole_fade(void **state)
{
	(void)state;
	struct cnode b;
	cnode_ok(&b, "[node x]\ntype = craters\nkind = boulder\nseed = 6\nmin_radius = 0.08\n"
		     "max_radius = 1.3\ndensity = 4\ndepth_ratio = 0.35\n");
	const int ly = 21; /* texels of 4 cm */
	double far = 0;
	for (int pole = 0; pole < 2; pole++) {
		uint32_t y = pole ? (1u << ly) - 1 : 0;
		for (int lx = 0; lx <= 2; lx++)
			for (uint32_t x = 0; x < (1u << lx); x++) {
				struct tile *t = gen(&b, lx, ly, x, y);
				for (uint32_t i = 0; i < T; i++)
					for (uint32_t r = 0; r < 2; r++) {
						uint32_t j = pole ? T - 1 - r : r;
						if (fabs(at(t, i, j)) > 1e-6)
							fail_msg("pole %d (%d,%d) %u: texel %u,%u = %g m",
								 pole, lx, ly, x, i, j, at(t, i, j));
					}
				for (uint32_t j = 8; j < T - 8; j++)
					for (uint32_t i = 0; i < T; i++)
						far = fmax(far, fabs(at(t, i, j)));
				tile_unref(t);
			}
	}
	assert_true(far > 0.01); /* boulders away from the pole rows */
	const struct craters *cr = b.n.impl;
	struct tile *t = gen(&b, 0, ly, 0, 0);
	for (uint32_t j = 0; j < 6; j++)
		for (uint32_t i = 0; i < T; i += 5) {
			double lon, lat;
			grid_texel_center(&t->key, T, i, j, &lon, &lat);
			assert_true(fabs(at(t, i, j) - craters_point(cr, lon, lat, ly, T)) < 1e-4);
		}
	tile_unref(t);
	cnode_fini(&b);
}

static void errors(void **state)
{
	(void)state;
	static const struct {
		const char *text, *want;
	} cases[] = {
		{ "[node x]\ntype = craters\nmin_radius = 500\nmax_radius = 100\n",
		  "test.ini:4: max_radius: must be at least min_radius" },
		{ "[node x]\ntype = craters\ndensity = 5\n", "test.ini:3: density: " },
		{ "[node x]\ntype = craters\nmax_radius = 1000000\n",
		  "test.ini:3: max_radius: 1e+06 m is more than a quarter" },
		{ "[node x]\ntype = craters\nmin_radius = 0.001\nmax_radius = 100000\n",
		  "test.ini:3: min_radius: max_radius / min_radius spans more than" },
		{ "[node x]\ntype = craters\nsize = 3\n", "test.ini:3: size: unknown key" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		struct cnode c;
		char err[256] = "";
		int rc = cnode_init(&c, cases[i].text, err);
		if (rc != -EINVAL || strncmp(err, cases[i].want, strlen(cases[i].want)) != 0)
			fail_msg("case %zu: rc %d, err \"%s\", want \"%s\"", i, rc, err,
				 cases[i].want);
		cnode_fini(&c);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(oracle),	cmocka_unit_test(seams),
		cmocka_unit_test(determinism_and_seed), cmocka_unit_test(band_limit),
		cmocka_unit_test(digs_craters), cmocka_unit_test(small_worn_and_boulders),
		cmocka_unit_test(pole_fade),	cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
