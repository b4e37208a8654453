/* Tests for noise tiles built from their parents (`from_parent = true`, noise_carry.c), on the
 * shipped procedural planet with every fBm noise node switched to from_parent, through the real
 * graph, cache and scheduler, against the same planet evaluated directly:
 * - the carry's dependencies (parent level, neighbours, across the antimeridian and the poles);
 * - the error against the direct evaluation at levels 1..22, at the equator, 46°N, 70°N
 *   (anisotropic levels), the antimeridian and both poles, for `terrain` and `ranges` (metres)
 *   and for each fBm node (a fraction of its amplitude);
 * - the same bytes whatever the order tiles are generated in and the number of workers;
 * - no seam: the step across tile borders, the antimeridian and the poles matches the direct
 *   evaluation's;
 * - ridged noise is refused with a clear error;
 * - the carry and the tile from it give the same bits with every ISA the CPU runs.
 * Runs from the repository root (tests/run.sh does).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/clipmap.h"
#include "engine/cache.h"
#include "engine/nodes/noise.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "support/planet_variant.h"

#define PLANET "conf/planets/procedural.ini"

/* The bounds this file states and checks (see the report in test output): the max |from_parent
 * − direct| of the `terrain` and `ranges` nodes anywhere tested, in metres, and of an fBm
 * node's own output as a fraction of its amplitude. */
#define BOUND_TERRAIN_M 1.0
#define BOUND_RANGES_M 0.5
#define BOUND_FBM_REL 1e-2
#define BOUND_TERRAIN_DEEP_M 0.1 /* ly ≥ 15 */
#define BOUND_SEAM_REL 3e-3 /* the step across a tile edge, pole or antimeridian */

static char planet_fp[64], planet_direct[64]; /* from_parent, direct (planet_variant.h) */

static int write_planets(void)
{
	return planet_variant_write(PLANET, "test_noise_parent", planet_fp, planet_direct,
				    sizeof planet_fp);
}

struct env {
	struct planet *pd, *pp; /* direct, from_parent */
	struct cache *cd, *cp;
	struct sched *sd, *sp;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	char err[256];
	if (write_planets() || planet_load(planet_direct, &e->pd, err) ||
	    planet_load(planet_fp, &e->pp, err)) {
		fprintf(stderr, "setup: %s\n", err);
		return -1;
	}
	e->cd = cache_create(768u << 20);
	e->cp = cache_create(768u << 20);
	e->sd = sched_create(&(struct sched_desc){ .cache = e->cd, .workers = 2 });
	e->sp = sched_create(&(struct sched_desc){ .cache = e->cp, .workers = 2 });
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	sched_destroy(e->sd);
	sched_destroy(e->sp);
	cache_destroy(e->cd);
	cache_destroy(e->cp);
	planet_unref(e->pd);
	planet_unref(e->pp);
	unlink(planet_fp);
	unlink(planet_direct);
	free(e);
	return 0;
}

static struct tile_key tkey(int lx, int ly, uint32_t x, uint32_t y)
{
	return (struct tile_key){ .lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x, .y = y };
}

static struct tile *fetch(struct sched *s, const struct planet *p, const char *node,
			  struct tile_key k)
{
	struct node *n = planet_find_node(p, node);
	assert_non_null(n);
	k.node = n->hash;
	struct want w = { .node = n, .cls = SCHED_VISIBLE, .key = k };
	struct tile *t = NULL;
	assert_int_equal(sched_fetch(s, &w, 1, &t), 0);
	assert_non_null(t);
	return t;
}

/* The tile of level (lx, ly) holding (lon, lat). */
static struct tile_key at(int lx, int ly, double lon, double lat, uint32_t T)
{
	double u = grid_lon_to_u(lx, T, lon), v = grid_lat_to_v(ly, T, lat);
	uint32_t x = grid_wrap_x(lx, (int64_t)floor(u / T));
	int64_t y = (int64_t)floor(v / T);
	if (y < 0)
		y = 0;
	if (y >= (int64_t)grid_tiles_y(ly))
		y = grid_tiles_y(ly) - 1;
	return tkey(lx, ly, x, (uint32_t)y);
}

static double max_diff(const struct tile *a, const struct tile *b)
{
	double m = 0;
	const float *fa = tile_f32(a), *fb = tile_f32(b);
	for (size_t i = 0; i < (size_t)a->size * a->size; i++) {
		double d = fabs((double)fa[i] - fb[i]);
		if (!(d <= m))
			m = d;
	}
	return m;
}

/* ---- the carry's dependencies ---- */

static bool has(const struct tile_key *d, int n, struct tile_key k)
{
	for (int i = 0; i < n; i++)
		if (d[i].lx == k.lx && d[i].ly == k.ly && d[i].x == k.x && d[i].y == k.y)
			return true;
	return false;
}

static void carry_deps(void **state)
{
	(void)state;
	const uint32_t T = 256;
	struct noise nz, few;
	struct noise_params p = { .seed = 3, .kind = NOISE_FBM, .octaves = 24, .wavelength = 4e6,
				  .lacunarity = 2, .gain = 0.5, .radius = 6378137.0 };
	assert_int_equal(noise_init(&nz, &p), 0);
	p.octaves = 8;
	assert_int_equal(noise_init(&few, &p), 0);
	struct tile_key d[NOISE_CARRY_MAX_DEPS];
	/* level 0: evaluated, no parent */
	struct tile_key k = tkey(1, 0, 1, 0);
	assert_false(noise_carry_upsampled(&nz, 1, 0, T));
	assert_int_equal(noise_carry_deps(&nz, &k, T, 7, d), 0);
	/* 8 octaves from 4000 km at level 16 (texels of 0.6 m): all of them on the in-tile
	 * lattice already, nothing to gain from the parent — no dependency */
	k = tkey(17, 16, 5, 5);
	assert_false(noise_carry_upsampled(&few, 17, 16, T));
	assert_int_equal(noise_carry_deps(&few, &k, T, 7, d), 0);
	assert_true(noise_carry_upsampled(&nz, 17, 16, T));
	/* ridged: never */
	p.kind = NOISE_RIDGED;
	p.ridge_offset = 1;
	p.ridge_gain = 2;
	assert_int_equal(noise_init(&few, &p), 0);
	assert_false(noise_carry_upsampled(&few, 6, 5, T));
	/* an isotropic interior child: the parent and the three neighbours on its side */
	k = tkey(6, 5, 21, 9); /* odd x, odd y: the parent's south-east quadrant */
	int n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_int_equal(n, 4);
	assert_true(has(d, n, tkey(5, 4, 10, 4)) && has(d, n, tkey(5, 4, 11, 4)) &&
		    has(d, n, tkey(5, 4, 10, 5)) && has(d, n, tkey(5, 4, 11, 5)));
	assert_int_equal(d[0].node, 7);
	/* the antimeridian: x = 0 reads the last column of tiles */
	k = tkey(6, 5, 0, 8);
	n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_int_equal(n, 4);
	assert_true(has(d, n, tkey(5, 4, 31, 3)) && has(d, n, tkey(5, 4, 0, 4)));
	/* the north pole: the rows beyond it are the tiles half a turn round */
	k = tkey(6, 5, 2, 0);
	n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_true(has(d, n, tkey(5, 4, 1, 0)) && has(d, n, tkey(5, 4, 0, 0)) &&
		    has(d, n, tkey(5, 4, 17, 0)) && has(d, n, tkey(5, 4, 16, 0)));
	/* the south pole */
	k = tkey(6, 5, 63, 31);
	n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_true(has(d, n, tkey(5, 4, 31, 15)) && has(d, n, tkey(5, 4, 15, 15)) &&
		    has(d, n, tkey(5, 4, 0, 15)));
	/* an anisotropic level near the pole it is made for (texels 1.17 times wider than tall
	 * at 85.8°S): the diagonal parent, the level a viewer there uses next */
	k = tkey(9, 12, 300, 4000);
	assert_true(fabs(noise_carry_aspect(&k, T) - 1.17) < 0.01);
	n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_int_equal(n, 4);
	assert_true(has(d, n, tkey(8, 11, 150, 2000)) && has(d, n, tkey(8, 11, 149, 1999)));
	/* the same level at 45°S (texels 11 times wider than tall) keeps its columns */
	k = tkey(9, 12, 300, 3072);
	assert_true(noise_carry_aspect(&k, T) > 11);
	n = noise_carry_deps(&nz, &k, T, 7, d);
	assert_int_equal(n, 2);
	assert_true(has(d, n, tkey(9, 11, 300, 1536)) && has(d, n, tkey(9, 11, 300, 1535)));
	int plx, ply;
	k = tkey(0, 3, 0, 4);
	assert_int_equal(noise_carry_parent(&k, T, &plx, &ply), 0);
	assert_true(plx == 0 && ply == 2);
	k = tkey(4, 3, 1, 1);
	assert_int_equal(noise_carry_parent(&k, T, &plx, &ply), 0);
	assert_true(plx == 3 && ply == 2);
	k = tkey(1, 0, 0, 0);
	assert_int_equal(noise_carry_parent(&k, T, &plx, &ply), -EINVAL);
}

/* ---- error against the direct evaluation ---- */

struct place {
	const char *name;
	double lon, lat;
};

static const struct place places[] = {
	{ "equator", 10.3, 0.4 },     { "46N", 7.7, 46.1 },	     { "70N", -40.2, 70.3 },
	{ "antimeridian", 179.99, -12.5 }, { "north pole", 33.0, 89.999 }, { "south pole", -120.0, -89.999 },
};

static const char *const fbm_nodes[] = { "continents", "hill_noise", "grain", "jitter",
					 "patches" };
static const double fbm_amp[] = { 5200, 150, 1.2, 250, 1 };

static void error_against_direct(void **state)
{
	struct env *e = *state;
	const uint32_t T = e->pd->tile_size;
	static const int levels[] = { 1, 2, 4, 6, 9, 12, 15, 18, 20, 22 };
	double worst_t = 0, worst_r = 0, worst_f = 0, worst_deep = 0;
	printf("%-4s %-13s %4s %12s %12s %12s\n", "ly", "place", "lx", "terrain m", "ranges m",
	       "fbm rel");
	for (size_t li = 0; li < sizeof levels / sizeof *levels; li++) {
		int ly = levels[li];
		for (size_t pi = 0; pi < sizeof places / sizeof *places; pi++) {
			const struct place *pl = &places[pi];
			int lx = clipmap_level_lx(ly, pl->lat, -1);
			struct tile_key k = at(lx, ly, pl->lon, pl->lat, T);
			double et = 0, er = 0, ef = 0;
			const char *wn = "-";
			const char *names[] = { "terrain", "ranges" };
			double *errs[] = { &et, &er };
			for (int q = 0; q < 2; q++) {
				struct tile *a = fetch(e->sd, e->pd, names[q], k);
				struct tile *b = fetch(e->sp, e->pp, names[q], k);
				*errs[q] = max_diff(a, b);
				tile_unref(a);
				tile_unref(b);
			}
			for (size_t q = 0; q < sizeof fbm_nodes / sizeof *fbm_nodes; q++) {
				struct tile *a = fetch(e->sd, e->pd, fbm_nodes[q], k);
				struct tile *b = fetch(e->sp, e->pp, fbm_nodes[q], k);
				double r = max_diff(a, b) / fbm_amp[q];
				if (r > ef) {
					ef = r;
					wn = fbm_nodes[q];
				}
				tile_unref(a);
				tile_unref(b);
			}
			printf("%-4d %-13s %4d %12.3g %12.3g %12.3g %s\n", ly, pl->name, lx, et, er,
			       ef, wn);
			worst_t = fmax(worst_t, et);
			if (ly >= 15)
				worst_deep = fmax(worst_deep, et);
			worst_r = fmax(worst_r, er);
			worst_f = fmax(worst_f, ef);
		}
	}
	printf("max |from_parent - direct|: terrain %.3g m (bound %g; at ly >= 15 %.3g m, bound "
	       "%g), ranges %.3g m (bound %g), fBm nodes %.3g of the amplitude (bound %g)\n",
	       worst_t, BOUND_TERRAIN_M, worst_deep, BOUND_TERRAIN_DEEP_M, worst_r, BOUND_RANGES_M,
	       worst_f, BOUND_FBM_REL);
	assert_true(worst_deep <= BOUND_TERRAIN_DEEP_M);
	assert_true(worst_t <= BOUND_TERRAIN_M);
	assert_true(worst_r <= BOUND_RANGES_M);
	assert_true(worst_f <= BOUND_FBM_REL);
	/* and it is built from the parent, not evaluated: the planets differ somewhere */
	assert_true(worst_f > 0);
}


/* ---- determinism ---- */

struct fresh {
	struct cache *c;
	struct sched *s;
};

static void fresh_open(struct fresh *f, int workers)
{
	f->c = cache_create(512u << 20);
	f->s = sched_create(&(struct sched_desc){ .cache = f->c, .workers = workers });
}

static void fresh_close(struct fresh *f)
{
	sched_destroy(f->s);
	cache_destroy(f->c);
}

static void drop(struct tile *t)
{
	tile_unref(t);
}

/* The same bytes for a tile generated cold with 1 worker, after its children (which need its
 * level's carry) with 3, and after its parent and neighbours with 2. */
static void same_bytes_any_order(void **state)
{
	struct env *e = *state;
	const uint32_t T = e->pp->tile_size;
	const struct {
		int ly;
		double lon, lat;
	} cases[] = { { 16, 7.7, 46.1 }, { 14, 120.0, 89.999 }, { 18, -179.999, -3.0 },
		      { 11, -60.0, -89.999 } };
	const char *nodes[] = { "terrain", "grain", "jitter", "patches" };
	for (size_t c = 0; c < sizeof cases / sizeof *cases; c++) {
		int lx = clipmap_level_lx(cases[c].ly, cases[c].lat, -1);
		struct tile_key k = at(lx, cases[c].ly, cases[c].lon, cases[c].lat, T);
		struct tile *ref[4], *t;
		struct fresh f;
		fresh_open(&f, 1);
		for (int q = 0; q < 4; q++)
			ref[q] = fetch(f.s, e->pp, nodes[q], k);
		fresh_close(&f);

		fresh_open(&f, 3);
		struct tile_key ch[4];
		int nch = grid_children(&k, k.lx < k.ly + 1 ? 0 : 1, 1, ch);
		assert_true(nch > 0);
		for (int i = 0; i < nch; i++)
			drop(fetch(f.s, e->pp, "terrain", ch[i]));
		for (int q = 0; q < 4; q++) {
			t = fetch(f.s, e->pp, nodes[q], k);
			assert_memory_equal(t->data, ref[q]->data, t->nbytes);
			drop(t);
		}
		fresh_close(&f);

		fresh_open(&f, 2);
		int plx, ply;
		assert_int_equal(noise_carry_parent(&k, T, &plx, &ply), 0);
		struct tile_key pk;
		uint32_t ox, oy;
		assert_int_equal(grid_parent(&k, k.lx - plx, k.ly - ply, T, &pk, &ox, &oy), 0);
		drop(fetch(f.s, e->pp, "terrain", pk));
		for (int dx = -1; dx <= 1; dx++) {
			struct tile_key nk;
			bool flip;
			grid_neighbor(&k, dx, dx == 0 ? 1 : 0, &nk, &flip);
			drop(fetch(f.s, e->pp, "terrain", nk));
		}
		for (int q = 0; q < 4; q++) {
			t = fetch(f.s, e->pp, nodes[q], k);
			assert_memory_equal(t->data, ref[q]->data, t->nbytes);
			drop(t);
		}
		fresh_close(&f);
		/* and the shared cache, warm with everything the other tests fetched */
		for (int q = 0; q < 4; q++) {
			t = fetch(e->sp, e->pp, nodes[q], k);
			assert_memory_equal(t->data, ref[q]->data, t->nbytes);
			drop(t);
			drop(ref[q]);
		}
	}
}

/* ---- seams ---- */

enum edge { EAST, SOUTH, POLE_N, POLE_S };

/* The largest difference, over the texel pairs across the edge between tiles a and b, of the
 * step from_parent makes and the step the direct evaluation makes, over amp. */
static double seam(struct env *e, const char *node, double amp, struct tile_key a,
		   struct tile_key b, enum edge ed)
{
	struct tile *fa = fetch(e->sp, e->pp, node, a), *fb = fetch(e->sp, e->pp, node, b);
	struct tile *da = fetch(e->sd, e->pd, node, a), *db = fetch(e->sd, e->pd, node, b);
	const uint32_t T = fa->size;
	double m = 0, step = 0;
	for (uint32_t q = 0; q < T; q++) {
		size_t ia, ib;
		switch (ed) {
		case EAST:
			ia = (size_t)q * T + T - 1;
			ib = (size_t)q * T;
			break;
		case SOUTH:
			ia = (size_t)(T - 1) * T + q;
			ib = q;
			break;
		case POLE_N:
			ia = ib = q;
			break;
		default:
			ia = ib = (size_t)(T - 1) * T + q;
			break;
		}
		double sf = (double)tile_f32(fb)[ib] - tile_f32(fa)[ia];
		double sd = (double)tile_f32(db)[ib] - tile_f32(da)[ia];
		m = fmax(m, fabs(sf - sd));
		step = fmax(step, fabs(sd));
	}
	(void)step;
	tile_unref(fa);
	tile_unref(fb);
	tile_unref(da);
	tile_unref(db);
	return m / amp;
}

static void no_seams(void **state)
{
	struct env *e = *state;
	const uint32_t T = e->pp->tile_size;
	double worst = 0;
	for (size_t q = 0; q < sizeof fbm_nodes / sizeof *fbm_nodes; q++) {
		for (int ly = 3; ly <= 21; ly += 6) {
			int lx = ly + 1;
			uint32_t W = grid_tiles_x(lx), H = grid_tiles_y(ly);
			double s[6];
			/* the antimeridian */
			s[0] = seam(e, fbm_nodes[q], fbm_amp[q], tkey(lx, ly, W - 1, H / 2 - 1),
				    tkey(lx, ly, 0, H / 2 - 1), EAST);
			/* a north–south border between tiles of different parents */
			s[1] = seam(e, fbm_nodes[q], fbm_amp[q], tkey(lx, ly, 5, H / 2 + 1),
				    tkey(lx, ly, 5, H / 2 + 2), SOUTH);
			/* across both poles, on an anisotropic level */
			int alx = clipmap_level_lx(ly, 89.99, -1);
			uint32_t AW = grid_tiles_x(alx);
			s[2] = seam(e, fbm_nodes[q], fbm_amp[q], tkey(alx, ly, 0, 0),
				    tkey(alx, ly, AW / 2, 0), POLE_N);
			s[3] = seam(e, fbm_nodes[q], fbm_amp[q], tkey(alx, ly, AW - 1, H - 1),
				    tkey(alx, ly, AW / 2 - 1, H - 1), POLE_S);
			/* east–west on the anisotropic level at 70°N */
			int blx = clipmap_level_lx(ly, 70.3, -1);
			struct tile_key k = at(blx, ly, -40.2, 70.3, T), kb = k;
			kb.x = grid_wrap_x(blx, (int64_t)k.x + 1);
			s[4] = seam(e, fbm_nodes[q], fbm_amp[q], k, kb, EAST);
			/* across the north pole on the isotropic level */
			s[5] = seam(e, fbm_nodes[q], fbm_amp[q], tkey(lx, ly, 3, 0),
				    tkey(lx, ly, 3 + W / 2, 0), POLE_N);
			printf("%-11s ly %2d: step error / amplitude: antimeridian %.2g, N-S %.2g, "
			       "N pole %.2g, S pole %.2g, 70N %.2g, N pole iso %.2g\n",
			       fbm_nodes[q], ly, s[0], s[1], s[2], s[3], s[4], s[5]);
			for (int i = 0; i < 6; i++)
				worst = fmax(worst, s[i]);
		}
	}
	printf("worst seam step error: %.3g of the amplitude (bound %g)\n", worst,
	       BOUND_SEAM_REL);
	assert_true(worst <= BOUND_SEAM_REL);
	assert_true(worst > 0); /* some of these levels are built from their parent */
}

/* ---- bad input ---- */

static void ridged_refused(void **state)
{
	(void)state;
	char path[64], err[256];
	snprintf(path, sizeof path, "/tmp/test_noise_parent_r%d.ini", (int)getpid());
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs("[planet]\nname = r\nbody = wgs84\ntile_size = 64\n\n[node n]\ntype = noise\n"
	      "kind = ridged\nfrom_parent = true\n\n[layer height]\nnode = n\nformat = f32\n",
	      f);
	fclose(f);
	struct planet *p = NULL;
	assert_int_equal(planet_load(path, &p, err), -EINVAL);
	printf("%s\n", err);
	assert_non_null(strstr(err, ":9: from_parent: ridged noise cannot be built from its parent"));
	f = fopen(path, "w");
	assert_non_null(f);
	fputs("[planet]\nname = r\nbody = wgs84\ntile_size = 64\n\n[node n]\ntype = noise\n"
	      "from_parent = maybe\n\n[layer height]\nnode = n\nformat = f32\n", f);
	fclose(f);
	assert_int_equal(planet_load(path, &p, err), -EINVAL);
	assert_non_null(strstr(err, ":8: from_parent: "));
	unlink(path);
}

/* ---- every ISA the same bits ---- */

/* The carry of k, its parent level's carries computed the same way (recursively, down to the
 * first level that does not upsample), with isa. */
static struct tile *carry_of(const struct noise *nz, struct tile_key k, uint32_t T,
			     enum noise_isa isa)
{
	struct tile_key deps[NOISE_CARRY_MAX_DEPS];
	struct tile *in[NOISE_CARRY_MAX_DEPS];
	int m = noise_carry_deps(nz, &k, T, 1, deps);
	for (int i = 0; i < m; i++)
		in[i] = carry_of(nz, deps[i], T, isa);
	struct tile *t = tile_create(&k, PIX_HEIGHT, T);
	size_t sb = (noise_carry_scratch_size(T) + 63) / 64 * 64;
	void *scratch = aligned_alloc(64, sb);
	assert_non_null(scratch);
	assert_int_equal(noise_carry_tile(nz, &k, T, isa, scratch, in, m, tile_f32(t)), 0);
	free(scratch);
	for (int i = 0; i < m; i++)
		tile_unref(in[i]);
	return t;
}

static float ref_tap6(const float w[6], const float *f, size_t st)
{
	return ((((w[0] * f[0] + w[1] * f[st]) + w[2] * f[2 * st]) + w[3] * f[3 * st]) +
		w[4] * f[4 * st]) +
	       w[5] * f[5 * st];
}

/* The carry of an isotropic tile away from the poles and the antimeridian, texel by texel in
 * scalar C: the band [lo, 2·lo) plus the parent level's carry (tiles from carry_of, scalar)
 * upsampled with noise_carry_kernel's weights down the columns, then along the rows. Child
 * texel u's centre sits at parent index u/2 − 1/4: its first tap is parent texel
 * floor(u/2 − 1/4) − 2. */
static void ref_carry(const struct noise *nz, struct tile_key k, uint32_t T, float *out)
{
	const int64_t M = 3; /* parent texels read beyond the footprint on each side */
	const int64_t gw = T / 2 + 2 * M, gh = T / 2 + 2 * M;
	const int64_t pu0 = (int64_t)k.x * (T / 2) - M, pv0 = (int64_t)k.y * (T / 2) - M;
	float *G = malloc((size_t)(gw * gh) * sizeof *G), *col = malloc((size_t)gw * sizeof *col);
	size_t sb = (noise_scratch_size(T) + 63) / 64 * 64;
	void *scratch = aligned_alloc(64, sb);
	assert_true(G && col && scratch);
	struct tile *pt[3][3] = { { NULL } };
	for (int64_t r = 0; r < gh; r++)
		for (int64_t c = 0; c < gw; c++) {
			int64_t pu = pu0 + c, pv = pv0 + r;
			int64_t tx = pu / T - ((int64_t)k.x / 2 - 1);
			int64_t ty = pv / T - ((int64_t)k.y / 2 - 1);
			assert_true(pu >= 0 && pv >= 0 && tx >= 0 && tx < 3 && ty >= 0 && ty < 3);
			if (!pt[ty][tx]) {
				struct tile_key pk = { .node = 1, .lx = (uint8_t)(k.lx - 1),
						       .ly = (uint8_t)(k.ly - 1), .x = (uint32_t)(pu / T),
						       .y = (uint32_t)(pv / T) };
				pt[ty][tx] = carry_of(nz, pk, T, NOISE_ISA_SCALAR);
			}
			G[r * gw + c] = tile_f32(pt[ty][tx])[(pv % T) * T + pu % T];
		}
	double lo = NOISE_CARRY_TEXELS * noise_texel_size(nz->p.radius, k.ly, T);
	assert_true(noise_tile_band(nz, &k, T, NOISE_ISA_SCALAR, scratch, lo, 2 * lo, false, out) >=
		    0);
	float w[2][6];
	noise_carry_kernel(0.75, w[0]);
	noise_carry_kernel(0.25, w[1]);
	for (uint32_t j = 0; j < T; j++) {
		int64_t r0 = (int64_t)floor((k.y * (double)T + j) / 2 - 0.25) - 2 - pv0;
		for (int64_t c = 0; c < gw; c++)
			col[c] = ref_tap6(w[j & 1], G + r0 * gw + c, (size_t)gw);
		for (uint32_t i = 0; i < T; i++) {
			int64_t c0 = (int64_t)floor((k.x * (double)T + i) / 2 - 0.25) - 2 - pu0;
			float *o = out + (size_t)j * T + i;
			*o = *o + ref_tap6(w[i & 1], col + c0, 1);
		}
	}
	for (int a = 0; a < 3; a++)
		for (int b = 0; b < 3; b++)
			tile_unref(pt[a][b]);
	free(scratch);
	free(col);
	free(G);
}

/* The carry and the tile from it give the same bits with every ISA this CPU runs (the
 * upsample's passes and the final sum run at each ISA's width: noise_sums.h), and the scalar
 * carry of interior isotropic tiles those of the upsample written out in ref_carry, on
 * isotropic levels (the parent has half the columns), anisotropic ones (the same columns), across the
 * antimeridian and at both poles; and the tile from the carry is the carry plus the band
 * under NOISE_CARRY_TEXELS texels, scaled, as the scalar expression gives it. */
static void same_bits_every_isa(void **state)
{
	(void)state;
	const uint32_t T = 64;
	struct noise nz;
	struct noise_params np = { .seed = 67, .kind = NOISE_FBM, .octaves = 14,
				   .wavelength = 2.5e6, .lacunarity = 2, .gain = 0.6,
				   .max_wavelength = 2.5e6, .radius = 6378137.0, .stretch = 1,
				   .pole_amplitude = 1 };
	assert_int_equal(noise_init(&nz, &np), 0);
	static const struct {
		double lon, lat;
	} pl[] = { { 7.7, 0.3 }, { 7.7, 46 }, { -120, 70 }, { 179.99, 10 }, { 30, 89.9 },
		   { -60, -89.9 } };
	static const enum noise_isa isas[] = { NOISE_ISA_AVX2, NOISE_ISA_AVX512 };
	float *band = malloc((size_t)T * T * sizeof *band);
	size_t sb = (noise_scratch_size(T) + 63) / 64 * 64;
	void *scratch = aligned_alloc(64, sb);
	assert_non_null(band);
	assert_non_null(scratch);
	int checked = 0, upsampled = 0, dlx = 0, referenced = 0;
	for (size_t pi = 0; pi < sizeof pl / sizeof *pl; pi++) {
		for (int ly = 3; ly <= 6; ly++) {
			int lx = clipmap_level_lx(ly, pl[pi].lat, -1);
			struct tile_key k = at(lx, ly, pl[pi].lon, pl[pi].lat, T);
			k.node = 1;
			bool up = noise_carry_upsampled(&nz, lx, ly, T);
			int plx = lx, ply = ly;
			if (up) {
				assert_int_equal(noise_carry_parent(&k, T, &plx, &ply), 0);
				upsampled++;
				dlx += plx != lx;
			}
			struct tile *c0 = carry_of(&nz, k, T, NOISE_ISA_SCALAR);
			if (up && plx == lx - 1 && fabs(pl[pi].lat) < 60 && fabs(pl[pi].lon) < 170) {
				/* the upsample itself, against the reference written out above */
				ref_carry(&nz, k, T, band);
				assert_memory_equal(band, c0->data, (size_t)T * T * sizeof *band);
				referenced++;
			}
			struct tile *t0 = tile_create(&k, PIX_HEIGHT, T);
			assert_int_equal(noise_tile_from_carry(&nz, &k, T, NOISE_ISA_SCALAR, scratch,
							       tile_f32(c0), NULL, 300.0f, 5.0f,
							       tile_f32(t0)),
					 0);
			/* the scalar expression, texel by texel (a tile the pole fade evaluates
			 * directly is not built from its carry: skipped) */
			double lo = NOISE_CARRY_TEXELS * noise_texel_size(nz.p.radius, ly, T);
			if (!noise_pole_fades(&nz, &k, T, lo)) {
				assert_true(noise_tile_band(&nz, &k, T, NOISE_ISA_SCALAR, scratch, 0,
							    lo, true, band) >= 0);
				for (size_t i = 0; i < (size_t)T * T; i++) {
					float v = 5.0f + 300.0f * (band[i] + tile_f32(c0)[i]);
					assert_memory_equal(&v, &tile_f32(t0)[i], sizeof v);
				}
			}
			for (size_t q = 0; q < sizeof isas / sizeof *isas; q++) {
				if (!noise_isa_supported(isas[q]))
					continue;
				struct tile *c1 = carry_of(&nz, k, T, isas[q]);
				struct tile *t1 = tile_create(&k, PIX_HEIGHT, T);
				assert_int_equal(noise_tile_from_carry(&nz, &k, T, isas[q], scratch,
								       tile_f32(c1), NULL, 300.0f,
								       5.0f, tile_f32(t1)),
						 0);
				if (memcmp(c0->data, c1->data, (size_t)T * T * 4) ||
				    memcmp(t0->data, t1->data, (size_t)T * T * 4))
					fail_msg("%s differs from scalar at ly %d lat %g lon %g",
						 noise_isa_name(isas[q]), ly, pl[pi].lat, pl[pi].lon);
				checked++;
				tile_unref(c1);
				tile_unref(t1);
			}
			tile_unref(c0);
			tile_unref(t0);
		}
	}
	printf("same bits on every ISA: %d tiles checked against scalar, %d upsampled (%d from "
	       "half the columns, %d against the reference upsample)\n",
	       checked, upsampled, dlx, referenced);
	/* the cases were there: upsampled tiles of both kinds */
	assert_true(upsampled >= 8 && dlx >= 4 && upsampled - dlx >= 2 && referenced >= 2);
	free(scratch);
	free(band);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(carry_deps),
		cmocka_unit_test(error_against_direct),
		cmocka_unit_test(same_bytes_any_order),
		cmocka_unit_test(no_seams),
		cmocka_unit_test(ridged_refused),
		cmocka_unit_test(same_bits_every_isa),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
