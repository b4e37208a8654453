/* Tests for the noise synthesis (noise.h) and the `noise` node: ISA paths give the same bits,
 * the tile kernel matches the double-precision oracle, no seams (tiles, antimeridian, poles),
 * no pole pinch, precision at the finest levels of an Earth-size body, band limiting by level,
 * seeds, detail over an input, and parameter errors.
 */
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
#include "common/xalloc.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/nodes/noise.h"
#include "engine/planet.h"
#include "engine/tile.h"

#define EARTH_A 6378137.0

static struct noise_params params(enum noise_kind kind, int octaves, double wavelength)
{
	return (struct noise_params){ .seed = 42, .kind = kind, .octaves = octaves,
				      .wavelength = wavelength, .lacunarity = 2.0, .gain = 0.5,
				      .ridge_offset = 1.0, .ridge_gain = 2.0, .radius = EARTH_A };
}

/* Owned T·T floats of tile k. */
static float *gen(const struct noise *nz, struct tile_key k, uint32_t T, enum noise_isa isa,
		  int *noct)
{
	void *scratch = xaligned_alloc(64, noise_scratch_size(T));
	float *out = xaligned_alloc(64, (size_t)T * T * sizeof *out);
	int rc = noise_tile(nz, &k, T, isa, scratch, out);
	free(scratch);
	assert_true(rc >= 0);
	if (noct)
		*noct = rc;
	return out;
}

static struct tile_key key(int lx, int ly, uint32_t x, uint32_t y)
{
	return (struct tile_key){ .lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x, .y = y };
}

/* ---- ISA paths ---- */

static void isa_paths_identical(void **state)
{
	(void)state;
	const struct tile_key keys[] = {
		key(1, 0, 0, 0),		   /* level 0: half the planet, both poles */
		key(1, 0, 1, 0),
		key(5, 4, 0, 0),		   /* north pole, antimeridian (west) */
		key(5, 4, 31, 15),		   /* south pole, antimeridian (east) */
		key(3, 10, 7, 300),		   /* anisotropic */
		key(13, 12, 4000, 1234),	   /* mid level */
		key(21, 20, (1u << 21) - 1, 5000), /* fine, antimeridian */
		key(29, 28, 123456789, 98765432),  /* finest (texel 0.3 mm) */
	};
	for (int kind = 0; kind < 3; kind++) { /* fbm, ridged, ridged with a weight floor */
		struct noise nz;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 24, 4e6);
		p.ridge_floor = kind == 2 ? 0.3 : 0;
		assert_int_equal(noise_init(&nz, &p), 0);
		for (size_t i = 0; i < sizeof keys / sizeof *keys; i++) {
			uint32_t T = i == 5 ? 256 : 64;
			float *ref = gen(&nz, keys[i], T, NOISE_ISA_SCALAR, NULL);
			for (enum noise_isa isa = NOISE_ISA_AVX2; isa <= NOISE_ISA_AVX512; isa++) {
				if (!noise_isa_supported(isa)) {
					if (kind == 0 && i == 0)
						printf("noise: %s path skipped: CPU lacks it\n",
						       noise_isa_name(isa));
					continue;
				}
				float *v = gen(&nz, keys[i], T, isa, NULL);
				size_t diff = 0;
				for (size_t t = 0; t < (size_t)T * T; t++)
					diff += memcmp(&v[t], &ref[t], sizeof *v) != 0;
				if (diff)
					printf("%s kind %d key %zu: %zu texels differ from scalar\n",
					       noise_isa_name(isa), kind, i, diff);
				assert_int_equal(diff, 0);
				free(v);
			}
			free(ref);
		}
	}
}

/* The tile kernel (float, relative to a per-tile origin) agrees with the double oracle at
 * every level, including the finest with large octave frequencies. */
static void matches_double_oracle(void **state)
{
	(void)state;
	const struct tile_key keys[] = { key(1, 0, 1, 0), key(5, 4, 31, 0), key(17, 16, 70000, 30000),
					 key(29, 28, 536870911, 100000000) };
	for (int kind = 0; kind < 3; kind++) { /* fbm, ridged, ridged with a weight floor */
		struct noise nz;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 24, 4e6);
		p.lacunarity = 2.5;
		p.ridge_floor = kind == 2 ? 0.3 : 0;
		assert_int_equal(noise_init(&nz, &p), 0);
		for (size_t i = 0; i < sizeof keys / sizeof *keys; i++) {
			uint32_t T = 64;
			float *v = gen(&nz, keys[i], T, NOISE_ISA_AUTO, NULL);
			double worst = 0;
			for (uint32_t j = 0; j < T; j += 7)
				for (uint32_t c = 0; c < T; c += 5) {
					double lon, lat;
					grid_texel_center(&keys[i], T, c, j, &lon, &lat);
					double r = noise_point(&nz, lon, lat, keys[i].ly, T);
					worst = fmax(worst, fabs(r - v[j * T + c]));
				}
			if (worst > 2e-5)
				printf("kind %d key %zu: worst error %g\n", kind, i, worst);
			assert_true(worst <= 2e-5);
			free(v);
		}
	}
}

/* Pole fade: with pole_amplitude, octaves that bend over a texel fade out on the rows nearest a
 * pole — the pole row of tiles all round varies far less with longitude than without the fade,
 * the rows further out keep them, and the tile matches the oracle there. */
static double pole_row_spread(const struct noise *nz, int ly, uint32_t T, uint32_t j)
{
	double lo = INFINITY, hi = -INFINITY;
	for (int lx = 0; lx <= 2; lx++)
		for (uint32_t x = 0; x < (1u << lx); x++) {
			float *v = gen(nz, key(lx, ly, x, 0), T, NOISE_ISA_AUTO, NULL);
			for (uint32_t i = 0; i < T; i++) {
				lo = fmin(lo, v[j * T + i]);
				hi = fmax(hi, v[j * T + i]);
			}
			free(v);
		}
	return hi - lo;
}

/* Largest second difference around the ring of row j of the lx 0 tile (all longitudes): small
 * for content planar over the pole (a sinusoid once round), large for finer content. */
static double ring_roughness(const struct noise *nz, int ly, uint32_t T, uint32_t j)
{
	float *v = gen(nz, key(0, ly, 0, 0), T, NOISE_ISA_AUTO, NULL);
	double m = 0;
	for (uint32_t i = 0; i < T; i++) {
		double a = v[j * T + (i + T - 1) % T], b = v[j * T + i], c = v[j * T + (i + 1) % T];
		m = fmax(m, fabs(a - 2 * b + c));
	}
	free(v);
	return m;
}

static void pole_fade(void **state)
{
	(void)state;
	const double moon = 1737400;
	const int ly = 21; /* 4 cm texels with T = 64 */
	const uint32_t T = 64;
	for (int kind = 0; kind < 2; kind++) {
		struct noise plain, faded;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 9, 12);
		p.radius = moon;
		p.gain = 0.6;
		assert_int_equal(noise_init(&plain, &p), 0);
		p.pole_amplitude = 0.25;
		assert_int_equal(noise_init(&faded, &p), 0);
		double s0 = pole_row_spread(&plain, ly, T, 0), s1 = pole_row_spread(&faded, ly, T, 0);
		double far0 = pole_row_spread(&plain, ly, T, 40),
		       far1 = pole_row_spread(&faded, ly, T, 40);
		double r0 = ring_roughness(&plain, ly, T, 0), r1 = ring_roughness(&faded, ly, T, 0);
		if (getenv("TEST_NOISE_VERBOSE"))
			printf("kind %d: pole row spread %g faded %g, roughness %g faded %g; row 40 "
			       "%g / %g\n", kind, s0, s1, r0, r1, far0, far1);
		/* what is left at the pole row: the planar octaves, once round the ring (fBm; the
		 * ridged field's fine octaves are weighted by the coarse ones, so how much they
		 * vary at one pole is down to the seed) */
		if (kind == 0) {
			assert_true(r1 < 0.25 * r0);
			assert_true(s1 < 0.5 * s0);
		}
		assert_true(s1 < 0.02);
		assert_true(far1 == far0);
		float *v = gen(&faded, key(1, ly, 1, 0), T, NOISE_ISA_AUTO, NULL);
		for (uint32_t j = 0; j < 6; j++)
			for (uint32_t c = 0; c < T; c += 5) {
				double lon, lat;
				struct tile_key k = key(1, ly, 1, 0);
				grid_texel_center(&k, T, c, j, &lon, &lat);
				assert_true(fabs(noise_point(&faded, lon, lat, ly, T) - v[j * T + c]) <
					    2e-5);
			}
		free(v);
	}
}

/* stretch: tile = oracle; crests run east-west (the field changes faster north-south than
 * east-west, by about the factor) at mid latitude; band limit by wavelength / stretch. */
static void stretched(void **state)
{
	(void)state;
	const uint32_t T = 64;
	const double a = 3396190;
	for (int kind = 0; kind < 2; kind++) {
		struct noise nz;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 3, 12);
		p.radius = a;
		p.stretch = 4;
		assert_int_equal(noise_init(&nz, &p), 0);
		int ly = 18;
		struct tile_key k = key(ly + 1, ly, 300000, 100000); /* about -9.3 deg */
		float *v = gen(&nz, k, T, NOISE_ISA_AUTO, NULL);
		double worst = 0, de = 0, dn = 0;
		for (uint32_t j = 0; j < T; j += 3)
			for (uint32_t c = 0; c < T; c += 3) {
				double lon, lat;
				grid_texel_center(&k, T, c, j, &lon, &lat);
				worst = fmax(worst, fabs(noise_point(&nz, lon, lat, ly, T) - v[j * T + c]));
			}
		for (uint32_t j = 0; j + 1 < T; j++)
			for (uint32_t c = 0; c + 1 < T; c++) {
				de += fabs(v[j * T + c + 1] - v[j * T + c]);
				dn += fabs(v[(j + 1) * T + c] - v[j * T + c]);
			}
		/* texels are twice as long east-west as north-south (lx = ly + 1 at ~9°S) */
		double ratio = (dn / 1) / (de / 2);
		if (!(worst <= 2e-5 && ratio > 2.5))
			fail_msg("kind %d: worst %g, north/east gradient ratio %g", kind, worst, ratio);
		free(v);
		/* 12 m / 4 = 3 m: gone at texels of 2 m, which would keep a 12 m octave */
		assert_true(noise_band_weight(12, 2) > 0);
		float *c0 = gen(&nz, key(13, 12, 1000, 1000), T, NOISE_ISA_AUTO, NULL);
		double amax = 0;
		for (uint32_t i = 0; i < T * T; i++)
			amax = fmax(amax, fabs(c0[i]));
		assert_true(amax < 1e-6 || kind == 1); /* ridged keeps its centring constant */
		free(c0);
	}
	struct noise nz;
	struct noise_params p = params(NOISE_FBM, 3, 12);
	p.stretch = 0.5;
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
}

/* ---- multi-resolution ---- */

/* The lattice-interpolated low octaves (noise.h) against every octave evaluated at every
 * texel, over whole tiles at levels 2..24 (near the equator, at mid latitude and at a pole
 * row; and the anisotropic tiles a viewer asks for at 70°, 80°, 88.5°N and beside the pole,
 * whose lattice takes more octaves than their level's at the equator would), for the planet's
 * kinds of field: max |multires − exact| relative to the total amplitude (1 for fBm, 2 for
 * ridged). */
static void multires_matches_exact(void **state)
{
	(void)state;
	const uint32_t T = 64;
	static const struct {
		enum noise_kind kind;
		int octaves;
		double wavelength, gain, floor;
	} fields[] = {
		{ NOISE_FBM, 9, 9e6, 0.45, 0 },	    /* procedural.ini continents */
		{ NOISE_RIDGED, 14, 7e5, 0.56, 0 }, /* ranges */
		{ NOISE_FBM, 20, 4e4, 0.53, 0 },    /* terrain */
		{ NOISE_RIDGED, 24, 4e6, 0.5, 0 },
		{ NOISE_RIDGED, 20, 8000, 0.5, 0.3 }, /* earth.ini's detail, its weight floor */
	};
	double worst_all[2] = { 0, 0 };
	int lattice_only_all = 0;
	for (size_t f = 0; f < sizeof fields / sizeof *fields; f++) {
		struct noise mr, ex;
		struct noise_params p = params(fields[f].kind, fields[f].octaves, fields[f].wavelength);
		p.gain = fields[f].gain;
		p.ridge_floor = fields[f].floor;
		assert_int_equal(noise_init(&mr, &p), 0);
		p.exact = true;
		assert_int_equal(noise_init(&ex, &p), 0);
		double worst = 0;
		int coarse = 0, high_level = 0, high_tile = 0, lattice_only_tile = 0, lattice_used = 0;
		for (int ly = 2; ly <= 24; ly += 2) {
			int lx = ly + 1;
			uint32_t ny = 1u << ly;
			/* isotropic tiles at the equator, 54°N and the pole row; then the viewer's
			 * levels at 70°, 80° and 88.5°N and in the row next to the pole: a column
			 * count as near square texels as the grid has (lx = ly + 1 + ⌊log2 cos⌋),
			 * whose texels are narrower than the level's widest, at the equator */
			struct tile_key keys[7] = { key(lx, ly, 3, ny / 2), key(lx, ly, 7, ny / 5),
						    key(lx, ly, (1u << lx) - 1, 0) };
			size_t nk = 3;
			static const double lats[] = { 70, 80, 88.5, 90 };
			for (size_t q = 0; q < 4; q++) {
				uint32_t y = lats[q] >= 90 ? (ny > 1 ? 1 : 0)
							   : (uint32_t)((90 - lats[q]) / 180 * ny);
				double la = 90 - 180.0 * y / ny; /* the row's edge nearest the pole */
				double c = cos((la - 180.0 / ny) * M_PI / 180);
				int hx = ly + 1 + (int)floor(log2(fmax(c, 1e-9)));
				hx = hx < 0 ? 0 : hx > lx ? lx : hx;
				keys[nk] = key(hx, ly, (1u << hx) / 3, y);
				high_level += noise_coarse_octaves(&mr, hx, ly, T);
				high_tile += noise_tile_coarse_octaves(&mr, &keys[nk], T);
				nk++;
			}
			coarse += noise_coarse_octaves(&mr, lx, ly, T);
			for (size_t i = 0; i < nk; i++) {
				float *a = gen(&mr, keys[i], T, NOISE_ISA_AUTO, NULL);
				float *b = gen(&ex, keys[i], T, NOISE_ISA_AUTO, NULL);
				double d = 0;
				for (size_t t = 0; t < (size_t)T * T; t++)
					d = fmax(d, fabs((double)a[t] - b[t]));
				worst = fmax(worst, d);
				/* a tile whose level at the equator has no lattice octave would
				 * be the exact evaluation bit for bit; one whose own texels put
				 * some on its lattice is not: the evaluation uses them */
				if (i >= 3 && keys[i].y > 0 &&
				    noise_coarse_octaves(&mr, keys[i].lx, ly, T) == 0 &&
				    noise_tile_coarse_octaves(&mr, &keys[i], T) > 0) {
					lattice_only_tile++;
					lattice_used += d > 0;
				}
				free(a);
				free(b);
			}
		}
		double rel = worst / (fields[f].kind == NOISE_RIDGED ? 2.0 : 1.0);
		printf("multires %s %d oct %.0f m: %d coarse octave-levels; high-latitude tiles %d "
		       "(their levels at the equator: %d; %d tiles with a lattice only their own "
		       "texels allow); max |multires - exact| %.2e of the amplitude\n",
		       fields[f].kind == NOISE_RIDGED ? "ridged" : "fbm", fields[f].octaves,
		       fields[f].wavelength, coarse, high_tile, high_level, lattice_only_tile, rel);
		assert_true(coarse > 0);
		assert_true(high_tile > high_level); /* the tiles' own texels put more on the lattice */
		assert_int_equal(lattice_used, lattice_only_tile); /* and the evaluation uses it */
		lattice_only_all += lattice_only_tile;
		worst_all[fields[f].kind == NOISE_RIDGED] = fmax(worst_all[fields[f].kind == NOISE_RIDGED], rel);
	}
	/* Measured: ≤ 4e-7 (fBm), ≤ 1.1e-6 (ridged) — float rounding level; the oracle tests
	 * (2e-5 absolute against the exact double field) therefore still hold unchanged. */
	assert_true(worst_all[0] <= 5e-6);
	assert_true(worst_all[1] <= 5e-6);
	assert_true(lattice_only_all > 0);
}

/* ---- seams ---- */

/* East-west neighbours a (west) and b (east): in each row the step across the border is no
 * larger than the noise's slope over one texel there, taken as the largest step of the three
 * texel pairs on either side, with a margin of 2 (the finest octaves are near the Nyquist limit
 * and ridged noise has creases, so steps vary a lot from texel to texel). Returns the number
 * of rows that violate it. */
static int seam_violations(const float *a, const float *b, uint32_t T)
{
	int bad = 0;
	for (uint32_t j = 0; j < T; j++) {
		const float *ra = a + (size_t)j * T, *rb = b + (size_t)j * T;
		double slope = 0;
		for (uint32_t i = 0; i < 3; i++)
			slope = fmax(slope, fmax(fabs(ra[T - 1 - i] - ra[T - 2 - i]),
						 fabs(rb[i + 1] - rb[i])));
		bad += fabs(ra[T - 1] - rb[0]) > 2.0 * slope + 1e-6;
	}
	return bad;
}

/* 6 octaves from 512 texels down to 16 texels at level ly: detail that float heights can
 * resolve at any level, with octave frequencies as large as the level needs. */
static struct noise level_noise(enum noise_kind kind, int ly, uint32_t T)
{
	struct noise nz;
	struct noise_params p = params(kind, 6, 512 * noise_texel_size(EARTH_A, ly, T));
	p.gain = 0.7;
	assert_int_equal(noise_init(&nz, &p), 0);
	return nz;
}

/* Both edge columns of an east-west pair equal the double oracle: the field is as continuous
 * across the border as it is anywhere. */
static void edges_match_oracle(const struct noise *nz, struct tile_key wk, const float *a,
			       struct tile_key ek, const float *b, uint32_t T)
{
	double worst = 0;
	for (uint32_t j = 0; j < T; j++) {
		double lon, lat;
		grid_texel_center(&wk, T, T - 1, j, &lon, &lat);
		worst = fmax(worst, fabs(noise_point(nz, lon, lat, wk.ly, T) - a[j * T + T - 1]));
		grid_texel_center(&ek, T, 0, j, &lon, &lat);
		worst = fmax(worst, fabs(noise_point(nz, lon, lat, ek.ly, T) - b[j * T]));
	}
	assert_true(worst <= 2e-5);
}

static void seamless_east_west(void **state)
{
	(void)state;
	const uint32_t T = 64;
	const int levels[] = { 0, 6, 16, 24, 28 };
	for (size_t l = 0; l < sizeof levels / sizeof *levels; l++) {
		int ly = levels[l], lx = ly + 1;
		for (int kind = 0; kind < 2; kind++) {
			struct noise nz = level_noise(kind ? NOISE_RIDGED : NOISE_FBM, ly, T);
			uint32_t last = (1u << lx) - 1, y = (1u << ly) / 3;
			struct tile_key ka = key(lx, ly, 5 % (last + 1), y);
			struct tile_key kb = key(lx, ly, 6 % (last + 1), y);
			struct tile_key ke = key(lx, ly, last, y), kw = key(lx, ly, 0, y);
			float *a = gen(&nz, ka, T, NOISE_ISA_AUTO, NULL);
			float *b = gen(&nz, kb, T, NOISE_ISA_AUTO, NULL);
			float *e = gen(&nz, ke, T, NOISE_ISA_AUTO, NULL);
			float *w = gen(&nz, kw, T, NOISE_ISA_AUTO, NULL);
			edges_match_oracle(&nz, ka, a, kb, b, T);
			edges_match_oracle(&nz, ke, e, kw, w, T);
			if (ly > 0) {
				assert_int_equal(seam_violations(a, b, T), 0);
				/* The check can fail: tiles that are not neighbours violate it. */
				assert_true(seam_violations(b, a, T) > (int)T / 4);
			}
			assert_int_equal(seam_violations(e, w, T), 0); /* across the antimeridian */
			free(a);
			free(b);
			free(e);
			free(w);
		}
	}
}

/* Row 0 of tile x and row 0 of tile x + n/2 are one texel apart across the north pole (and
 * the last rows across the south pole). */
static void seamless_across_poles(void **state)
{
	(void)state;
	const uint32_t T = 64;
	const int levels[] = { 3, 12, 22, 28 };
	for (size_t l = 0; l < sizeof levels / sizeof *levels; l++) {
		int ly = levels[l], lx = ly + 1;
		struct noise nz = level_noise(l % 2 ? NOISE_RIDGED : NOISE_FBM, ly, T);
		uint32_t n = 1u << lx, ys = (1u << ly) - 1;
		for (int south = 0; south < 2; south++) {
			uint32_t y = south ? ys : 0, r0 = south ? T - 1 : 0, r1 = south ? T - 2 : 1;
			float *a = gen(&nz, key(lx, ly, 3, y), T, NOISE_ISA_AUTO, NULL);
			float *b = gen(&nz, key(lx, ly, 3 + n / 2, y), T, NOISE_ISA_AUTO, NULL);
			int bad = 0;
			for (uint32_t i = 0; i < T; i++) {
				double slope = fmax(fabs(a[r0 * T + i] - a[r1 * T + i]),
						    fabs(b[r0 * T + i] - b[r1 * T + i]));
				bad += fabs(a[r0 * T + i] - b[r0 * T + i]) > 2.0 * slope + 1e-6;
			}
			assert_int_equal(bad, 0);
			free(a);
			free(b);
		}
	}
}

/* At the row nearest a pole all tiles of the level meet in (nearly) one point: values along
 * the row barely change, far less than from row 0 to row 1. */
static void no_pole_pinch(void **state)
{
	(void)state;
	struct noise nz;
	struct noise_params p = params(NOISE_FBM, 8, 2e6);
	assert_int_equal(noise_init(&nz, &p), 0);
	const uint32_t T = 64;
	const int ly = 4, lx = 5;
	double lo = 1e9, hi = -1e9, along = 0, across = 0;
	for (uint32_t x = 0; x < (1u << lx); x++) {
		float *a = gen(&nz, key(lx, ly, x, 0), T, NOISE_ISA_AUTO, NULL);
		for (uint32_t i = 0; i < T; i++) {
			lo = fmin(lo, a[i]);
			hi = fmax(hi, a[i]);
			across = fmax(across, fabs(a[T + i] - a[i]));
			if (i + 1 < T)
				along = fmax(along, fabs(a[i + 1] - a[i]));
		}
		free(a);
	}
	assert_true(across > 1e-4);
	assert_true(along <= 0.1 * across);
	assert_true(hi - lo <= 2.0 * across);
}

/* Domain warp: every ISA path gives the scalar bits, tiles match the double oracle (which
 * warps the point itself) where the warp is evaluated per texel (level 8) and where it is
 * interpolated from the lattice (level 12), at a pole tile and across the antimeridian; the
 * field moves (it is not the unwarped one) and its octaves fade in by the compressed
 * wavelength (noise.strain), so a warped level never evaluates more octaves. */
static void warped(void **state)
{
	(void)state;
	const uint32_t T = 64;
	const struct tile_key keys[] = {
		key(9, 8, 100, 70),		     /* warp per texel (16 km = 52 texels) */
		key(13, 12, 4000, 1234),	     /* warp on the lattice (840 texels) */
		key(13, 12, 8191, 0),		     /* north pole, antimeridian (east) */
		key(13, 12, 0, 0),		     /* its western neighbour */
		key(21, 20, (1u << 21) - 1, 300000), /* fine */
	};
	for (int run = 0; run < 4; run++) {
		int kind = run % 2, depth = run / 2 ? 2 : 0; /* all octaves warped, or the first 2 */
		struct noise nz, plain;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 12, 8000);
		p.pole_amplitude = 900;
		assert_int_equal(noise_init(&plain, &p), 0);
		p.warp = 1500;
		p.warp_wavelength = 16000;
		p.warp_depth = depth;
		assert_int_equal(noise_init(&nz, &p), 0);
		assert_true(nz.strain > 1.2 && nz.strain < 2.0);
		/* warped octaves fade in by their compressed wavelength, the others by their own */
		for (int o = 0; o < 12; o++)
			assert_true(nz.oct[o].lmin == (depth && o >= depth ? plain.oct[o].lmin
									   : plain.oct[o].lmin / nz.strain));
		float *v[5];
		double all_moved = 0, all_rms = 0;
		for (size_t i = 0; i < 5; i++) {
			int n_w, n_p;
			v[i] = gen(&nz, keys[i], T, NOISE_ISA_SCALAR, &n_w);
			float *u = gen(&plain, keys[i], T, NOISE_ISA_AUTO, &n_p);
			assert_true(n_w > 0 && n_w <= n_p);
			assert_true(depth == 0 || n_w >= n_p - 1);
			for (enum noise_isa isa = NOISE_ISA_AVX2; isa <= NOISE_ISA_AVX512; isa++) {
				if (!noise_isa_supported(isa))
					continue;
				float *x = gen(&nz, keys[i], T, isa, NULL);
				assert_memory_equal(x, v[i], (size_t)T * T * sizeof *x);
				free(x);
			}
			double worst = 0, moved = 0, rms = 0;
			for (uint32_t j = 0; j < T; j += 3)
				for (uint32_t c = 0; c < T; c += 3) {
					double lon, lat;
					grid_texel_center(&keys[i], T, c, j, &lon, &lat);
					double r = noise_point(&nz, lon, lat, keys[i].ly, T);
					worst = fmax(worst, fabs(r - v[i][j * T + c]));
					moved += fabs((double)v[i][j * T + c] - u[j * T + c]);
					rms += (double)u[j * T + c] * u[j * T + c];
				}
			if (worst > 2e-5)
				fail_msg("kind %d key %zu: worst error %g against the oracle", kind, i,
					 worst);
			if (getenv("TEST_NOISE_VERBOSE"))
				printf("warp kind %d depth %d key %zu: oracle %g, moved %g, rms %g, "
				       "octaves %d/%d\n", kind, depth, i, worst, moved / 484,
				       sqrt(rms / 484), n_w, n_p);
			all_moved += moved / 484;
			all_rms += sqrt(rms / 484);
			free(u);
		}
		/* the warp moves the field by a fair part of its own size */
		assert_true(all_moved > 0.2 * all_rms);
		edges_match_oracle(&nz, keys[2], v[2], keys[3], v[3], T); /* antimeridian */
		assert_int_equal(seam_violations(v[2], v[3], T), 0);
		for (size_t i = 0; i < 5; i++)
			free(v[i]);
	}
	struct noise nz;
	struct noise_params p = params(NOISE_FBM, 6, 8000);
	p.warp = 1000; /* no warp_wavelength */
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
	p.warp_wavelength = 16000;
	p.warp_octaves = NOISE_WARP_MAX_OCTAVES + 1;
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
}

/* ---- precision ---- */

struct smooth {
	int zeros;		  /* adjacent texels with exactly the same value */
	double max_d1, max_d2;	  /* largest first and second differences */
};

static struct smooth row_smoothness(const float *v, uint32_t n)
{
	struct smooth s = { 0 };
	for (uint32_t i = 0; i + 1 < n; i++) {
		double d1 = (double)v[i + 1] - v[i];
		s.zeros += d1 == 0;
		s.max_d1 = fmax(s.max_d1, fabs(d1));
		if (i + 2 < n)
			s.max_d2 = fmax(s.max_d2, fabs((double)v[i + 2] - 2.0 * v[i + 1] + v[i]));
	}
	return s;
}

/* A 64-texel wavelength at levels whose texels are 1.2 m .. 0.3 mm on Earth: adjacent texels
 * differ smoothly. A naive evaluation (float unit-sphere coordinates) staircases there. */
static void precise_at_fine_levels(void **state)
{
	(void)state;
	const uint32_t T = 256;
	const int levels[] = { 16, 20, 24, 28 };
	for (size_t l = 0; l < 4; l++) {
		int ly = levels[l], lx = ly + 1;
		double s = noise_texel_size(EARTH_A, ly, T);
		struct noise nz;
		struct noise_params p = params(NOISE_FBM, 1, 64 * s);
		assert_int_equal(noise_init(&nz, &p), 0);
		/* A tile near lon 10°, lat 45°. */
		uint32_t x = (uint32_t)((10.0 + 180.0) / 360.0 * ldexp(1, lx));
		uint32_t y = (uint32_t)((90.0 - 45.0) / 180.0 * ldexp(1, ly));
		struct tile_key k = key(lx, ly, x, y);
		float *v = gen(&nz, k, T, NOISE_ISA_AUTO, NULL);
		struct smooth sm = row_smoothness(v + (size_t)(T / 2) * T, T);
		if (sm.zeros > 2 || sm.max_d2 > 0.25 * sm.max_d1)
			printf("ly %d: %d zero steps, d1 %g d2 %g\n", ly, sm.zeros, sm.max_d1,
			       sm.max_d2);
		assert_true(sm.max_d1 > 1e-3);
		assert_true(sm.zeros <= 2);
		assert_true(sm.max_d2 <= 0.25 * sm.max_d1);

		if (ly == 24) { /* the same field evaluated naively quantises: the test can fail */
			float naive[256];
			const struct noise_octave *o = &nz.oct[0];
			for (uint32_t i = 0; i < T; i++) {
				double lon, lat;
				grid_texel_center(&k, T, i, T / 2, &lon, &lat);
				lon *= M_PI / 180, lat *= M_PI / 180;
				float px = (float)(cos(lat) * cos(lon)), py = (float)(cos(lat) * sin(lon));
				float pz = (float)sin(lat), f = (float)o->freq;
				naive[i] = (float)noise_simplex_ref(px * f, py * f, pz * f, o->seed);
			}
			struct smooth ns = row_smoothness(naive, T);
			assert_true(ns.zeros > 50 || ns.max_d2 > 0.5 * ns.max_d1);
		}
		free(v);
	}
}

/* ---- band limiting ---- */

static void coarse_tiles_evaluate_fewer_octaves(void **state)
{
	(void)state;
	struct noise nz;
	struct noise_params p = params(NOISE_FBM, 8, 4e6);
	assert_int_equal(noise_init(&nz, &p), 0);
	const uint32_t T = 64;
	int prev = 0;
	for (int ly = 0; ly <= 6; ly++) {
		double s = noise_texel_size(EARTH_A, ly, T);
		int expect = 0;
		for (int k = 0; k < 8; k++)
			expect += 4e6 / pow(2, k) > 2 * s;
		int got;
		free(gen(&nz, key(ly + 1, ly, 0, 0), T, NOISE_ISA_AUTO, &got));
		assert_int_equal(got, expect);
		assert_true(got >= prev);
		prev = got;
	}
	int got;
	free(gen(&nz, key(1, 0, 0, 0), T, NOISE_ISA_AUTO, &got));
	assert_true(got < 8);
	assert_true(noise_band_weight(100, 50) == 0.0 && noise_band_weight(200, 50) == 1.0);
	assert_true(noise_band_weight(150, 50) > 0.0 && noise_band_weight(150, 50) < 1.0);
}

/* A parent texel ≈ the mean of the 2×2 child texels under it; the difference is bounded by
 * the octaves whose band weight changes between the levels. */
static void parent_approximates_children(void **state)
{
	(void)state;
	const uint32_t T = 64;
	for (int kind = 0; kind < 2; kind++) {
		struct noise nz;
		struct noise_params p = params(kind ? NOISE_RIDGED : NOISE_FBM, 8, 4e6);
		assert_int_equal(noise_init(&nz, &p), 0);
		struct tile_key pk = key(4, 3, 5, 2), ck[4];
		assert_int_equal(grid_children(&pk, 1, 1, ck), 4);
		float *par = gen(&nz, pk, T, NOISE_ISA_AUTO, NULL), *ch[4];
		for (int c = 0; c < 4; c++)
			ch[c] = gen(&nz, ck[c], T, NOISE_ISA_AUTO, NULL);
		double sp = noise_texel_size(EARTH_A, 3, T), sc = sp / 2, bound2 = 0;
		for (int k = 0; k < 8; k++) {
			double dw = noise_band_weight(nz.oct[k].lambda, sc) -
				    noise_band_weight(nz.oct[k].lambda, sp);
			bound2 += dw * nz.oct[k].amp * dw * nz.oct[k].amp;
		}
		double err2 = 0, var = 0, mean = 0;
		for (uint32_t j = 0; j < T; j++)
			for (uint32_t i = 0; i < T; i++) {
				const float *c = ch[(j >= T / 2) * 2 + (i >= T / 2)];
				uint32_t ci = (i % (T / 2)) * 2, cj = (j % (T / 2)) * 2;
				double avg = (c[cj * T + ci] + c[cj * T + ci + 1] +
					      c[(cj + 1) * T + ci] + c[(cj + 1) * T + ci + 1]) / 4;
				double d = par[j * T + i] - avg;
				err2 += d * d;
				mean += par[j * T + i];
				var += (double)par[j * T + i] * par[j * T + i];
			}
		double rms = sqrt(err2 / (T * T));
		mean /= T * T;
		double sd = sqrt(var / (T * T) - mean * mean);
		printf("%s: parent vs 2x2 children rms %.5f, fade bound %.5f, field sd %.4f\n",
		       kind ? "ridged" : "fbm", rms, sqrt(bound2), sd);
		assert_true(bound2 > 0);
		assert_true(rms <= sqrt(bound2));
		assert_true(rms <= 0.1 * sd);
		free(par);
		for (int c = 0; c < 4; c++)
			free(ch[c]);
	}
}

/* ---- the node ---- */

struct fixture {
	struct ini_file *ini;
	struct planet pl;
	struct node n;
	char err[256];
};

static int make_node(struct fixture *f, const char *text, struct node *input)
{
	memset(f, 0, sizeof *f);
	f->pl.a = EARTH_A;
	f->pl.tile_size = 64;
	f->pl.max_level = 30;
	if (ini_parse("test.ini", text, strlen(text), &f->ini, f->err))
		return -1;
	struct ini_section *sec = &f->ini->sections[0];
	ini_find(sec, "type")->used = true;
	struct ini_entry *in = ini_find(sec, "input");
	if (in)
		in->used = true;
	f->n.name = "n";
	f->n.planet = &f->pl;
	f->n.in[0] = input;
	return node_init(&f->n, &node_type_noise, "test.ini", sec, f->err);
}

static void free_node(struct fixture *f)
{
	node_fini(&f->n);
	ini_free(f->ini);
}

static struct tile *node_tile(const struct node *n, struct tile_key k, struct tile *input)
{
	struct gen_ctx g = { 0 };
	k.node = n->hash;
	struct tile *t = tile_create(&k, PIX_HEIGHT, 64);
	struct tile *in[1] = { input };
	assert_int_equal(n->type->generate(n, &g, &k, in, input ? 1 : 0, t), 0);
	gen_ctx_fini(&g);
	return t;
}

static void node_deterministic_and_in_range(void **state)
{
	(void)state;
	const char *kinds[] = { "fbm", "ridged" };
	for (int kind = 0; kind < 2; kind++) {
		char text[200];
		snprintf(text, sizeof text, "[node n]\ntype = noise\nkind = %s\namplitude = 500\n"
			 "offset = 100\nseed = 9\n", kinds[kind]);
		struct fixture f;
		assert_int_equal(make_node(&f, text, NULL), 0);
		assert_int_equal(f.n.out, PIX_HEIGHT);
		double lo = 1e9, hi = -1e9, sum = 0;
		size_t cnt = 0;
		for (uint32_t x = 0; x < 8; x++) {
			struct tile_key k = key(4, 3, (x * 5 + 1) % 16, x);
			struct tile *a = node_tile(&f.n, k, NULL), *b = node_tile(&f.n, k, NULL);
			assert_memory_equal(a->data, b->data, a->nbytes);
			const float *v = tile_f32(a);
			for (size_t i = 0; i < 64 * 64; i++) {
				double u = (v[i] - 100.0) / 500.0;
				lo = fmin(lo, u);
				hi = fmax(hi, u);
				sum += u;
				cnt++;
			}
			tile_unref(a);
			tile_unref(b);
		}
		printf("%s: range [%.3f, %.3f], mean %.3f\n", kinds[kind], lo, hi, sum / cnt);
		assert_true(lo >= -1.3 && hi <= 1.3);
		assert_true(hi - lo >= 0.5);
		assert_true(fabs(sum / cnt) < 0.35);
		free_node(&f);
	}
}

/* A level whose texels are wider than every octave (a 90 m canopy noise seen from far away)
 * holds the offset alone: the node gives the shared uniform tile, summarized, with the
 * bytes the evaluation gives; on a uniform input too, and not on a varying one. The next
 * level that evaluates an octave is not uniform. */
static void node_no_octave_uniform(void **state)
{
	(void)state;
	struct fixture f;
	assert_int_equal(make_node(&f, "[node n]\ntype = noise\nkind = fbm\nseed = 23\noctaves = 4\n"
				   "wavelength = 90\nmax_wavelength = 90\namplitude = 14\n"
				   "offset = 2.5\n", NULL),
			 0);
	struct tile *t = node_tile(&f.n, key(10, 9, 400, 200), NULL); /* 610 m texels */
	assert_true(t->uniform && t->summarized && !t->any_nan);
	for (size_t i = 0; i < 64 * 64; i++)
		assert_true(tile_f32(t)[i] == 2.5f);
	assert_true(t->lo == 2.5f && t->hi == 2.5f);
	struct tile *fine = node_tile(&f.n, key(16, 15, 700, 300), NULL); /* 9.5 m */
	assert_false(fine->uniform);
	/* on an input: uniform only where the input is */
	free_node(&f);
	struct node src = { .name = "src", .out = PIX_HEIGHT, .hash = 77 };
	assert_int_equal(make_node(&f, "[node n]\ntype = noise\ninput = src\nwavelength = 90\n"
				   "max_wavelength = 90\namplitude = 14\n", &src),
			 0);
	struct tile *u = tile_create(&(struct tile_key){ 0 }, PIX_HEIGHT, 64);
	float h = 812.25f;
	tile_fill_uniform(u, &h);
	struct tile *v = tile_create(&(struct tile_key){ 0 }, PIX_HEIGHT, 64);
	for (size_t i = 0; i < 64 * 64; i++)
		tile_f32(v)[i] = (float)i;
	struct tile *ou = node_tile(&f.n, key(10, 9, 400, 200), u);
	struct tile *ov = node_tile(&f.n, key(10, 9, 400, 200), v);
	assert_true(ou->uniform && tile_f32(ou)[0] == 812.25f && tile_f32(ou)[4095] == 812.25f);
	assert_false(ov->uniform);
	for (size_t i = 0; i < 64 * 64; i++)
		assert_true(tile_f32(ov)[i] == (float)i);
	tile_unref(t);
	tile_unref(fine);
	tile_unref(u);
	tile_unref(v);
	tile_unref(ou);
	tile_unref(ov);
	free_node(&f);
}

static void seeds_differ(void **state)
{
	(void)state;
	struct fixture f1, f2;
	assert_int_equal(make_node(&f1, "[node n]\ntype = noise\nseed = 1\n", NULL), 0);
	assert_int_equal(make_node(&f2, "[node n]\ntype = noise\nseed = 2\n", NULL), 0);
	assert_true(f1.n.hash != f2.n.hash);
	struct tile_key k = key(6, 5, 10, 10);
	struct tile *a = node_tile(&f1.n, k, NULL), *b = node_tile(&f2.n, k, NULL);
	size_t differ = 0;
	for (size_t i = 0; i < 64 * 64; i++)
		differ += fabsf(tile_f32(a)[i] - tile_f32(b)[i]) > 1.0f;
	assert_true(differ > 64 * 64 * 9 / 10);
	tile_unref(a);
	tile_unref(b);
	free_node(&f1);
	free_node(&f2);
}

/* With an input: output = input + the octaves at or below max_wavelength (detail only). */
static void detail_over_input(void **state)
{
	(void)state;
	struct node in = { .name = "h", .out = PIX_HEIGHT, .hash = 1234 };
	struct fixture fd, fn, ff;
	const char *cfg = "[node n]\ntype = noise\ninput = h\noctaves = 12\nmax_wavelength = 40000\n";
	assert_int_equal(make_node(&fd, cfg, &in), 0);
	assert_int_equal(make_node(&fn, "[node n]\ntype = noise\noctaves = 12\n"
				   "max_wavelength = 40000\n", NULL), 0);
	assert_int_equal(make_node(&ff, "[node n]\ntype = noise\noctaves = 12\n", NULL), 0);
	struct tile_key k = key(12, 11, 1000, 700);
	struct node_dep deps[NODE_MAX_DEPS];
	k.node = fd.n.hash;
	assert_int_equal(node_default_deps(&fd.n, &k, deps), 1);
	assert_ptr_equal(deps[0].node, &in);
	struct tile *src = tile_create(&k, PIX_HEIGHT, 64);
	for (size_t i = 0; i < 64 * 64; i++)
		tile_f32(src)[i] = 500.0f + (float)(i % 64);
	struct tile *d = node_tile(&fd.n, k, src), *n = node_tile(&fn.n, k, NULL);
	struct tile *full = node_tile(&ff.n, k, NULL);
	double dmax = 0, fmax_ = 0;
	for (size_t i = 0; i < 64 * 64; i++) {
		float detail = tile_f32(d)[i] - tile_f32(src)[i];
		assert_true(fabsf(detail - tile_f32(n)[i]) <= 1e-3f);
		dmax = fmax(dmax, fabs(detail));
		fmax_ = fmax(fmax_, fabs(tile_f32(full)[i]));
	}
	/* Octaves 7.. only (λ ≤ 40 km): a few metres, far below the full field. */
	assert_true(dmax > 0.01);
	assert_true(dmax < 0.1 * fmax_);
	tile_unref(src);
	tile_unref(d);
	tile_unref(n);
	tile_unref(full);
	free_node(&fd);
	free_node(&fn);
	free_node(&ff);
}

static void parameter_errors(void **state)
{
	(void)state;
	static const struct {
		const char *text, *msg;
	} cases[] = {
		{ "[node n]\ntype = noise\noctaves = 99\n", "test.ini:3: octaves: " },
		{ "[node n]\ntype = noise\nkind = perlin\n", "test.ini:3: kind: " },
		{ "[node n]\ntype = noise\n\nlacunarity = 5\n", "test.ini:4: lacunarity: " },
		{ "[node n]\ntype = noise\ngain = 2\n", "test.ini:3: gain: " },
		{ "[node n]\ntype = noise\nseed = x\n", "test.ini:3: seed: " },
		{ "[node n]\ntype = noise\noctave = 3\n", "test.ini:3: octave: unknown key" },
		{ "[node n]\ntype = noise\nwavelength = 8000\nwarp = 9000\n", "test.ini:4: warp: " },
		{ "[node n]\ntype = noise\nwarp = 10\nwarp_octaves = 5\n", "test.ini:4: warp_octaves: " },
		{ "[node n]\ntype = noise\nkind = ridged\nridge_floor = 1.5\n", "test.ini:4: ridge_floor: " },
	};
	for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
		struct fixture f;
		assert_int_equal(make_node(&f, cases[i].text, NULL), -EINVAL);
		if (strncmp(f.err, cases[i].msg, strlen(cases[i].msg)) != 0)
			printf("got \"%s\", want \"%s...\"\n", f.err, cases[i].msg);
		assert_true(strncmp(f.err, cases[i].msg, strlen(cases[i].msg)) == 0);
		free_node(&f);
	}
	struct noise nz;
	struct noise_params p = params(NOISE_FBM, 0, 4e6);
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
	p = params(NOISE_RIDGED, 8, 4e6);
	p.ridge_floor = -0.1;
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
	p.ridge_floor = NAN;
	assert_int_equal(noise_init(&nz, &p), -EINVAL);
	p = params(NOISE_FBM, 8, 4e6);
	assert_int_equal(noise_init(&nz, &p), 0);
	float out[16 * 16];
	void *scratch = xaligned_alloc(64, noise_scratch_size(16));
	struct tile_key bad = key(3, 1, 0, 0); /* lx > ly + 1 */
	assert_int_equal(noise_tile(&nz, &bad, 16, NOISE_ISA_AUTO, scratch, out), -EINVAL);
	struct tile_key ok = key(2, 1, 0, 0);
	assert_int_equal(noise_tile(&nz, &ok, 24, NOISE_ISA_AUTO, scratch, out), -EINVAL);
	free(scratch);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(isa_paths_identical),
		cmocka_unit_test(matches_double_oracle),
		cmocka_unit_test(stretched),
		cmocka_unit_test(warped),
		cmocka_unit_test(pole_fade),
		cmocka_unit_test(multires_matches_exact),
		cmocka_unit_test(node_no_octave_uniform),
		cmocka_unit_test(seamless_east_west),
		cmocka_unit_test(seamless_across_poles),
		cmocka_unit_test(no_pole_pinch),
		cmocka_unit_test(precise_at_fine_levels),
		cmocka_unit_test(coarse_tiles_evaluate_fewer_octaves),
		cmocka_unit_test(parent_approximates_children),
		cmocka_unit_test(node_deterministic_and_in_range),
		cmocka_unit_test(seeds_differ),
		cmocka_unit_test(detail_over_input),
		cmocka_unit_test(parameter_errors),
	};
	return cmocka_run_group_tests_name("noise", tests, NULL, NULL);
}
