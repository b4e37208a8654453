/* noise — seeded fractal noise (fBm and Musgrave's ridged multifractal) of 3-D simplex noise
 * evaluated on the unit sphere, tile by tile, band-limited by level, with explicit SIMD
 * kernels (AVX2, AVX-512) chosen at run time and a scalar fallback that gives the same bits.
 *
 * Precision design: per tile and octave the tile centre pc (unit sphere, double) times the
 * octave frequency f picks an integer origin I0 in the simplex's skewed space and O =
 * unskew(I0); each texel's input is r = d·f + c with d = p − pc (float, from double) and
 * c = pc·f − O (small), so every float stays small even at the finest level of an Earth-size
 * body. Lattice points are I0 + floor(skew(r)), hashed as wrapping 32-bit integers with the
 * seed and octave (no permutation tables).
 *
 * Threads: a struct noise is immutable after noise_init; any number of threads may call
 * noise_tile on it concurrently with their own scratch. The ISA detection runs once
 * (pthread_once). Ownership: nothing here allocates except noise_init's caller-owned struct.
 */
#ifndef CLIPMAP_NOISE_H
#define CLIPMAP_NOISE_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "engine/node.h"
#include "engine/tile.h"

#define NOISE_MAX_OCTAVES 24

enum noise_kind {
	NOISE_FBM = 0, /* Σ gain^k · n_k, normalised by Σ gain^k */
	NOISE_RIDGED,  /* Musgrave's ridged multifractal, centred and normalised */
};

/* Which kernel evaluates the rows. AUTO = the best the CPU supports. */
enum noise_isa {
	NOISE_ISA_AUTO = 0,
	NOISE_ISA_SCALAR,
	NOISE_ISA_AVX2,	  /* 8 texels per vector */
	NOISE_ISA_AVX512, /* 16 texels per vector */
};

/* What a noise field is; a zeroed struct plus radius is not valid: fill every field. */
struct noise_params {
	uint32_t seed;
	enum noise_kind kind;
	int octaves;		/* 1..NOISE_MAX_OCTAVES */
	double wavelength;	/* metres, octave 0; octave k has wavelength / lacunarity^k */
	double lacunarity;	/* > 1 */
	double gain;		/* amplitude ratio between octaves */
	double ridge_offset;	/* ridged: signal = (ridge_offset − |n|)² */
	double ridge_gain;	/* ridged: next octave weight = clamp(signal · ridge_gain, floor, 1) */
	double ridge_floor;	/* ridged: that floor, 0..1 (0: Musgrave's; more keeps some detail
				 * on the smooth sides of the long crests, which 0 leaves plain) */
	double max_wavelength;	/* octaves with a longer wavelength are skipped; 0 = none */
	double radius;		/* body radius in metres (the sphere the noise lives on) */
	double stretch;		/* ≥ 1 (0 reads as 1): space is compressed by this factor along
				 * the polar axis before the noise is evaluated, so features are
				 * that much narrower north–south than east–west (crests running
				 * east–west, isotropic at the poles); band limits use
				 * wavelength / stretch */
	double pole_amplitude;	/* metres per unit of noise as the caller scales it (the node's
				 * |amplitude|); > 0 turns on the pole fade (noise_pole_weight):
				 * octaves that bend more than NOISE_POLE_BEND over a texel fade
				 * out over the last texels before a pole. 0: no fade */
	bool exact;		/* evaluate every octave at every texel (no coarse lattice): for
				 * tests and benchmarks; false (the default) in the node */
	double warp;		/* metres, ≥ 0 (0: none): domain warp — every octave is evaluated
				 * at p + w(p) instead of p, w a smooth 3-D vector fBm (each
				 * component its own seed) whose components reach about ± warp:
				 * the crests of one octave, which isotropic noise closes into
				 * cells of one size (a honeycomb from afar), bend, stretch and
				 * merge. Band limits use the warp's measured strain (noise.strain) */
	double warp_wavelength; /* metres of the warp's first octave (> 0 with warp) */
	int warp_octaves;	/* 1..NOISE_WARP_MAX_OCTAVES (0 reads as 2); gain 0.5, lacunarity 2 */
	int warp_depth;		/* only octaves 0..warp_depth-1 are warped (0: all): the coarse
				 * ones whose crests would form the cells; finer octaves keep their
				 * own positions and their full band */
};

#define NOISE_WARP_MAX_OCTAVES 4

/* Per-octave constants, precomputed by noise_init. */
struct noise_octave {
	double lambda; /* wavelength, metres */
	double lmin;   /* shortest wavelength in any direction: lambda / stretch */
	double freq;   /* noise units per unit-sphere unit, exactly representable as float */
	double amp;    /* normalised amplitude of this octave */
	double mean;   /* ridged: expected weighted signal, subtracted so the sum is centred */
	uint32_t seed; /* hash seed of this octave */
	double rot[3][3]; /* this octave's rotation of the sphere: octaves whose lattices nest
			   * (lacunarity 2) would otherwise line their creases up into long straight
			   * features along the lattice planes */
};

struct noise {
	struct noise_params p;
	struct noise_octave oct[NOISE_MAX_OCTAVES];
	/* Domain warp: nwarp octaves (0: none), each with one field per component x, y, z
	 * (freq, seed; amp in unit-sphere units; the three share the rotation of [q][0]).
	 * strain: the factor by which the warp compresses features at most, but for the
	 * rarest 1 % of places (the 99th percentile of the largest singular value of
	 * I + ∂w/∂p over a fixed sample of the field; 1 without warp): a warped octave's lmin is
	 * divided by it, so it still fades in from 2–4 texels. */
	int nwarp;
	double strain;
	struct noise_octave warp[NOISE_WARP_MAX_OCTAVES][3];
};

/* Checks p and precomputes per-octave constants into nz. Returns 0 or -EINVAL. */
int noise_init(struct noise *nz, const struct noise_params *p);

/* Multi-resolution evaluation. The leading octaves whose wavelength is at least
 * NOISE_MR_MIN_TEXELS texels (the tile's larger texel side: its width at its latitude nearest
 * the equator, or its height; one decision per tile row, so east–west neighbours agree and a
 * north–south neighbour differs by at most the interpolation error) are evaluated only at lattice
 * points: the centres of the level texels (u, v) with u and v multiples of NOISE_MR_STRIDE —
 * a grid global to the level, so neighbouring tiles share it — over the tile and 2 lattice
 * points beyond each edge (across a pole those are the real sphere points beyond it). Their
 * weighted sum (fBm) is interpolated to every texel with a separable cubic Hermite whose
 * slopes are 4th-order central differences of the lattice values (6-point stencil): C1, exact
 * at lattice points, error O((stride/wavelength)^4), and the same formula on the same lattice
 * points on either side of a tile border. Ridged noise interpolates each coarse octave's raw
 * simplex value instead (smooth, unlike the creased ridge signal, whose kinks a cubic would
 * round off by several hundredths of the octave's amplitude even at the lattice's 64 points per
 * wavelength: bench_noise_parent's last lines) and runs the ridge/weight recurrence per texel on the interpolated
 * values, so the finer octaves get the same weights as in an exact evaluation up to the
 * interpolation error. Measured max |multires − exact| ≤ 4e-7 (fBm) and 1.1e-6 (ridged) of
 * the amplitude (test_noise). Levels whose circumference is under NOISE_MR_MIN_TEXELS texels
 * get no lattice (the texel→sphere map itself is not smooth enough at that stride). */
#define NOISE_MR_STRIDE 8
#define NOISE_MR_MIN_TEXELS 512.0

/* How many of the octaves a tile of level (lx, ly) evaluates go through the lattice wherever
 * it lies (its texels measured at the equator). */
int noise_coarse_octaves(const struct noise *nz, int lx, int ly, uint32_t T);
/* How many go through tile k's lattice: at least noise_coarse_octaves of its level, more off
 * the equator, where a texel is cos(latitude) as wide — the wavelength test takes the tile's
 * texels as they are, their width at its latitude nearest the equator or their height,
 * whichever is larger (so the interpolation's error bound is the same everywhere; near a pole
 * the viewer's levels of few columns would otherwise evaluate every octave at every texel).
 * Before the pole fade, which keeps the octaves it touches off the lattice in a pole tile. */
int noise_tile_coarse_octaves(const struct noise *nz, const struct tile_key *k, uint32_t T);
/* cos of the latitude of tile k's texels nearest the equator (its equatorward edge's: 1 for a
 * tile across the equator): its widest texels' share of the level's width at the equator. */
double noise_tile_cos_eq(const struct tile_key *k, uint32_t T);

/* Bytes of scratch noise_tile needs for tile size T. */
size_t noise_scratch_size(uint32_t T);

/* Fills out[T·T] (row 0 = north) with the band-limited fractal value, roughly in [-1, 1], of
 * tile k (k->node is ignored) using kernel `isa`. scratch: noise_scratch_size(T) bytes,
 * 64-byte aligned, borrowed. Octaves with wavelength < 2 texels are not evaluated; the ones
 * between 2 and 4 texels fade in. Returns the number of octaves evaluated (≥ 0), -EINVAL for
 * a bad key or size, -ENOTSUP when the CPU lacks `isa`. */
int noise_tile(const struct noise *nz, const struct tile_key *k, uint32_t T, enum noise_isa isa,
	       void *scratch, float *out);

/* noise_tile, then out = base + (offset + amplitude · value) texel by texel (base NULL: no
 * base), each row while it is in cache — what the noise node stores. Same bits as doing that
 * in float after noise_tile. */
int noise_tile_scaled(const struct noise *nz, const struct tile_key *k, uint32_t T,
		      enum noise_isa isa, void *scratch, const float *base, float amplitude,
		      float offset, float *out);

/* The same field at one point (degrees) for a tile of level ly and size T, computed in double
 * with the reference simplex: a slow oracle for tests. */
double noise_point(const struct noise *nz, double lon, double lat, int ly, uint32_t T);

/* One octave of raw 3-D simplex noise at point (x, y, z) (noise units), in double, with the
 * hash seed `seed`; roughly in [-1, 1]. The oracle the kernels are checked against. */
double noise_simplex_ref(double x, double y, double z, uint32_t seed);

/* The 32-bit hash finaliser the noise's lattice hashes use (a bijection). */
uint32_t noise_mix32(uint32_t h);

/* A uniformly random rotation from three hashed uniforms of seed (Shoemake's quaternion):
 * each octave's turn of the sphere, and the `cells` node's lattice. */
void noise_seed_rotation(uint32_t seed, double r[3][3]);

/* Octave weight (0..1) for wavelength lambda at texel size s: 0 below 2s, 1 above 4s. */
double noise_band_weight(double lambda, double s);

/* ---- building a tile from its parent (noise_carry.c; fBm only) ----
 *
 * The carry of a tile of level (lx, ly) is the sum of its octaves whose shortest wavelength is
 * at least NOISE_CARRY_TEXELS texels of level ly (band weight 1 there), at its texel centres,
 * without the pole fade. At ly = 0 it is evaluated directly. Below, it is the carry of the
 * parent level, upsampled (a separable C1 cubic Hermite with 4th-order slopes: 6 taps), plus the one band of octaves the parent
 * did not carry (NOISE_CARRY_TEXELS to twice that). The parent level is (lx − 1, ly − 1) — the
 * level a viewer at that latitude uses one step coarser, so the chain is the levels it asks
 * for anyway — where the tile's texels are at most NOISE_CARRY_MAX_ASPECT times wider than
 * tall (in metres, at its latitude nearest the equator: isotropic levels, and the anisotropic
 * levels near the latitudes they are made for: the viewer's are 1.37 at 70°N, 1.39 at 80°N),
 * and (lx, ly − 1) otherwise: an anisotropic tile far from the poles keeps its columns (only
 * latitude is interpolated, never its wide texels). With (lx, ly − 1) everywhere, a viewer at
 * 80°N needed carries on levels it never asks for and the whole keys cost 1.3× more than
 * evaluating directly (bench_noise_parent). Either is a valid level; the choice is a function
 * of the key. The upsample reads the parent level's texels over the tile's footprint and three
 * beyond each side: from the parent tile and up to three of its neighbours (x wraps; beyond a
 * pole, the texels on the far side of it, rows reversed, as in grid_neighbor). A tile's value
 * is then that carry plus its octaves under NOISE_CARRY_TEXELS texels evaluated directly (2 at
 * lacunarity 2 instead of up to 8): noise_tile_from_carry.
 *
 * Ridged multifractal is not built this way, and should not be: its carry would be the sum of
 * creased signals (ro − |n|)² and the running weight after them, both with kinks along every
 * crest, which no interpolation reproduces. Measured (bench_noise_parent's last lines: this
 * kernel at t = ¼ and ¾ on one octave's signal sampled along 400 random lines): at 8 samples
 * per wavelength, where the carry takes an octave over, the upsampled creased signal errs by
 * up to 0.40 of the octave's amplitude at its crests (rms 0.040), 0.20 at 16 and 0.10 at 32 —
 * first order, halving per level, so every finer level keeps a rounded crest (the `ranges`
 * node of the procedural planet would lose hundreds of metres off its ridges). Upsampling
 * each octave's raw (smooth) value and creasing after errs 0.015 at 8 samples, 0.0010 at 16:
 * that is the only carry that keeps the crests, and it is one channel per
 * carried octave — what the in-tile lattice already does for a ridged node's coarse octaves.
 * Its gain was measured the cheap way, the lattice's threshold at 128 texels instead of 512
 * (16 lattice points per wavelength; error 3.8e-4 of the amplitude against 1.1e-6, test_noise):
 * `massifs` 17–30 % faster at ly 10–16, the nine noise nodes of a key 7–14 %, whole keys
 * (their colour included) not measurably (bench_noise_parent, 6 December) — not worth 350
 * times the error. A ridged node keeps the direct path. */
#define NOISE_CARRY_TEXELS 8.0

/* Whether level (lx, ly) builds its carry from the parent level, and its tiles from their
 * carry: where that evaluates at least 2 octaves fewer per texel than the direct path (whose
 * octaves of at least NOISE_MR_MIN_TEXELS texels already cost little, on the lattice), i.e.
 * where the upsample (about one octave's cost) pays. Elsewhere the carry, wherever a finer
 * level needs it, is evaluated directly (no parent: the chain stops there) and the tiles are
 * exactly the direct path's. One decision per level and parameters: every tile agrees. fBm
 * only (false for ridged). */
bool noise_carry_upsampled(const struct noise *nz, int lx, int ly, uint32_t T);
#define NOISE_CARRY_MAX_ASPECT 1.5
/* Width over height of tile k's texels in metres at its latitude nearest the equator. */
double noise_carry_aspect(const struct tile_key *k, uint32_t T);
/* The parent level of tile k for the carry; -EINVAL at ly = 0 (no parent). */
int noise_carry_parent(const struct tile_key *k, uint32_t T, int *plx, int *ply);
/* The parent-level tiles the carry of tile k needs (their node field set to `node`), without
 * duplicates, in a fixed order; none where the level's carry is evaluated directly. Returns
 * how many (≤ NOISE_CARRY_MAX_DEPS). */
#define NOISE_CARRY_MAX_DEPS 8
int noise_carry_deps(const struct noise *nz, const struct tile_key *k, uint32_t T, uint64_t node,
		     struct tile_key *out);
/* Scratch for noise_carry_tile (≥ noise_scratch_size). */
size_t noise_carry_scratch_size(uint32_t T);
/* The carry of tile k into out[T·T] from the parent-level tiles noise_carry_deps named (in any
 * order; their keys are matched), or evaluated directly where the level does not upsample. Returns 0, -EINVAL (bad key or size, a kind other than fBm,
 * a missing or wrong-sized input), -ENOTSUP (isa). */
int noise_carry_tile(const struct noise *nz, const struct tile_key *k, uint32_t T,
		     enum noise_isa isa, void *scratch, struct tile *const *in, int nin, float *out);
/* What noise_tile_scaled gives, from the tile's carry (on a level that upsamples): the carry
 * plus the octaves under NOISE_CARRY_TEXELS texels, then out = base + (offset + amplitude · value). In a pole tile
 * where a carried octave would be faded (noise_pole_fades) the tile is evaluated directly.
 * Returns 0 or as noise_tile. */
int noise_tile_from_carry(const struct noise *nz, const struct tile_key *k, uint32_t T,
			  enum noise_isa isa, void *scratch, const float *carry, const float *base,
			  float amplitude, float offset, float *out);

/* The carry upsample's six weights (taps p−2 … p+3) at t ∈ [0, 1) past parent texel p. */
void noise_carry_kernel(double t, float w[6]);

/* Internal to noise.c and noise_carry.c: noise_tile restricted to the octaves whose shortest
 * wavelength is in [lo, hi) metres (fade: with the pole fade); whether tile k fades any octave
 * of at least lo metres at its pole rows. */
int noise_tile_band(const struct noise *nz, const struct tile_key *k, uint32_t T,
		    enum noise_isa isa, void *scratch, double lo, double hi, bool fade, float *out);
bool noise_pole_fades(const struct noise *nz, const struct tile_key *k, uint32_t T, double lo);
/* How many octaves with a shortest wavelength in [lo, hi) metres a tile of level (lx, ly)
 * evaluates at every texel at most (the others of the band go through the lattice), counting
 * as at the equator: a tile off it may put more on its lattice (noise_tile_coarse_octaves).
 * The per-level decisions (noise_carry_upsampled) use this count, so they hold for every tile
 * of the level; off the equator the direct path is cheaper than they assume. */
int noise_band_full(const struct noise *nz, int lx, int ly, uint32_t T, double lo, double hi);

/* Near a pole a texel row is a ring around it, and content that is not planar over a texel
 * (it bends: its slope changes by more than NOISE_POLE_BEND radians over one texel) makes the
 * pole rows depend on longitude — in height, and worse in the normals across the pole. Such
 * content (noise octaves, crater and boulder classes; decided per level, from its curvature
 * estimate times the level's texel size) is faded to 0 on the two texel rows nearest each pole
 * and back in over the next two, as the slope node fades its slope: the pole rows of every
 * level hold only content that is planar there. Content bending less than NOISE_POLE_BEND is
 * untouched, from 2 × NOISE_POLE_BEND faded fully, linear between. */
#define NOISE_POLE_BEND 0.01

/* Texels of level ly (size T) from latitude lat (degrees) to the nearer pole: 0.5 on the pole
 * row's centre. */
double noise_pole_texels(double lat, int ly, uint32_t T);

/* The weight of content bending by `bend` radians over one texel at t texels from a pole. */
double noise_pole_weight(double bend, double t);

/* Texel size in metres (latitudinal) of level ly with tile size T on a body of radius a. */
double noise_texel_size(double a, int ly, uint32_t T);

int noise_isa_supported(enum noise_isa isa); /* 1 or 0; AUTO → 1 */
enum noise_isa noise_isa_best(void);
/* Whether 8-lane AVX2 kernels (the pixel nodes' too) may run here: the best ISA is AVX2 or
 * better. Cached after the first call. */
bool noise_isa_has_avx2(void);
const char *noise_isa_name(enum noise_isa isa); /* "scalar", "avx2", "avx512", "auto" */

/* ---- internal: per-ISA row kernels (noise.c, noise_avx2.c, noise_avx512.c) ---- */

/* One octave over a row: out[i] = simplex(d[i]·f + c) for the lattice origin folded into
 * hx/hy/hz (I0 · prime, wrapping). n is a multiple of 16; rows are 64-byte aligned. */
struct noise_row {
	float f, cx, cy, cz;
	uint32_t hx, hy, hz, seed;
};
typedef void noise_row_fn(const struct noise_row *o, const float *dx, const float *dy,
			  const float *dz, float *out, uint32_t n);
noise_row_fn noise_row_scalar, noise_row_avx2, noise_row_avx512;

/* Constants shared by every kernel (same values, same operation order → same bits). */
#define NOISE_F3 (1.0f / 3.0f)
#define NOISE_G3 (1.0f / 6.0f)
#define NOISE_PX 501125321u
#define NOISE_PY 1136930381u
#define NOISE_PZ 1720413743u
#define NOISE_HMUL 0x27d4eb2du
#define NOISE_SCALE 76.0f

#endif
