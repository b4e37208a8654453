/* noise — tile driver (per-tile double-precision set-up, band limiting, fractal sums), the
 * run-time ISA dispatch, the scalar row kernel and the double-precision oracle. See noise.h.
 *
 * Bit-identity: only the row kernel differs between ISAs; it performs the same float
 * operations in the same order in every path (fmaf here where the vector code uses FMA), and
 * everything else (set-up, fractal sums) is this file's code for all paths.
 */
#include "noise.h"
#include "noise_sums.h"

#include <errno.h>
#include <math.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

/* ---- scalar kernel ---- */

static inline float flip_sign(float v, uint32_t bit31)
{
	uint32_t u;
	memcpy(&u, &v, sizeof u);
	u ^= bit31;
	memcpy(&v, &u, sizeof v);
	return v;
}

static inline float corner(uint32_t h, float x, float y, float z)
{
	h *= NOISE_HMUL;
	uint32_t g = h >> 28;
	float u = g < 8 ? x : y;
	float v = g < 4 ? y : ((g & 13) == 12 ? x : z);
	float grad = flip_sign(u, g << 31) + flip_sign(v, (g & 2) << 30);
	float t = fmaf(-x, x, 0.5f);
	t = fmaf(-y, y, t);
	t = fmaf(-z, z, t);
	t = t > 0.0f ? t : 0.0f;
	float t2 = t * t;
	float t4 = t2 * t2;
	return t4 * grad;
}

void noise_row_scalar(const struct noise_row *o, const float *dx, const float *dy, const float *dz,
		      float *out, uint32_t n)
{
	const float G3 = NOISE_G3, G3x2 = 2.0f * NOISE_G3, G3x3 = 3.0f * NOISE_G3;
	for (uint32_t i = 0; i < n; i++) {
		float x = fmaf(dx[i], o->f, o->cx);
		float y = fmaf(dy[i], o->f, o->cy);
		float z = fmaf(dz[i], o->f, o->cz);
		float s = ((x + y) + z) * NOISE_F3;
		float fi = floorf(x + s), fj = floorf(y + s), fk = floorf(z + s);
		float t = ((fi + fj) + fk) * G3;
		float x0 = (x - fi) + t, y0 = (y - fj) + t, z0 = (z - fk) + t;
		int xy = x0 >= y0, yz = y0 >= z0, xz = x0 >= z0;
		int i1 = xy & xz, j1 = (!xy) & yz, k1 = (!xz) & (!yz);
		int i2 = xy | xz, j2 = (!xy) | yz, k2 = !(xz & yz);
		float x1 = (x0 - (i1 ? 1.0f : 0.0f)) + G3;
		float y1 = (y0 - (j1 ? 1.0f : 0.0f)) + G3;
		float z1 = (z0 - (k1 ? 1.0f : 0.0f)) + G3;
		float x2 = (x0 - (i2 ? 1.0f : 0.0f)) + G3x2;
		float y2 = (y0 - (j2 ? 1.0f : 0.0f)) + G3x2;
		float z2 = (z0 - (k2 ? 1.0f : 0.0f)) + G3x2;
		float x3 = (x0 - 1.0f) + G3x3;
		float y3 = (y0 - 1.0f) + G3x3;
		float z3 = (z0 - 1.0f) + G3x3;
		uint32_t hx = o->hx + (uint32_t)(int32_t)fi * NOISE_PX;
		uint32_t hy = o->hy + (uint32_t)(int32_t)fj * NOISE_PY;
		uint32_t hz = o->hz + (uint32_t)(int32_t)fk * NOISE_PZ;
		float n0 = corner(o->seed ^ hx ^ hy ^ hz, x0, y0, z0);
		float n1 = corner(o->seed ^ (hx + (i1 ? NOISE_PX : 0)) ^ (hy + (j1 ? NOISE_PY : 0)) ^
					  (hz + (k1 ? NOISE_PZ : 0)),
				  x1, y1, z1);
		float n2 = corner(o->seed ^ (hx + (i2 ? NOISE_PX : 0)) ^ (hy + (j2 ? NOISE_PY : 0)) ^
					  (hz + (k2 ? NOISE_PZ : 0)),
				  x2, y2, z2);
		float n3 = corner(o->seed ^ (hx + NOISE_PX) ^ (hy + NOISE_PY) ^ (hz + NOISE_PZ), x3,
				  y3, z3);
		out[i] = (((n0 + n1) + n2) + n3) * NOISE_SCALE;
	}
}

/* ---- double-precision oracle ---- */

static double corner_ref(uint32_t h, double x, double y, double z)
{
	h *= NOISE_HMUL;
	uint32_t g = h >> 28;
	double u = g < 8 ? x : y;
	double v = g < 4 ? y : ((g & 13) == 12 ? x : z);
	double grad = ((g & 1) ? -u : u) + ((g & 2) ? -v : v);
	double t = 0.5 - x * x - y * y - z * z;
	if (t <= 0)
		return 0;
	return t * t * t * t * grad;
}

double noise_simplex_ref(double x, double y, double z, uint32_t seed)
{
	double s = (x + y + z) / 3.0;
	double fi = floor(x + s), fj = floor(y + s), fk = floor(z + s);
	double t = (fi + fj + fk) / 6.0;
	double x0 = x - fi + t, y0 = y - fj + t, z0 = z - fk + t;
	int xy = x0 >= y0, yz = y0 >= z0, xz = x0 >= z0;
	int i1 = xy & xz, j1 = (!xy) & yz, k1 = (!xz) & (!yz);
	int i2 = xy | xz, j2 = (!xy) | yz, k2 = !(xz & yz);
	uint32_t hx = (uint32_t)(int64_t)fi * NOISE_PX;
	uint32_t hy = (uint32_t)(int64_t)fj * NOISE_PY;
	uint32_t hz = (uint32_t)(int64_t)fk * NOISE_PZ;
	double n = corner_ref(seed ^ hx ^ hy ^ hz, x0, y0, z0);
	n += corner_ref(seed ^ (hx + (i1 ? NOISE_PX : 0)) ^ (hy + (j1 ? NOISE_PY : 0)) ^
				(hz + (k1 ? NOISE_PZ : 0)),
			x0 - i1 + 1.0 / 6, y0 - j1 + 1.0 / 6, z0 - k1 + 1.0 / 6);
	n += corner_ref(seed ^ (hx + (i2 ? NOISE_PX : 0)) ^ (hy + (j2 ? NOISE_PY : 0)) ^
				(hz + (k2 ? NOISE_PZ : 0)),
			x0 - i2 + 2.0 / 6, y0 - j2 + 2.0 / 6, z0 - k2 + 2.0 / 6);
	n += corner_ref(seed ^ (hx + NOISE_PX) ^ (hy + NOISE_PY) ^ (hz + NOISE_PZ), x0 - 0.5,
			y0 - 0.5, z0 - 0.5);
	return n * NOISE_SCALE;
}

/* ---- ISA dispatch ---- */

/* The best ISA + 1, 0 until detected. Detection is idempotent, so concurrent first calls
 * may both run it and store the same value: a relaxed atomic is all it needs. */
static atomic_int isa_cached;

static enum noise_isa isa_detect(void)
{
	__builtin_cpu_init();
	if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
	    __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512vl") &&
	    __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
		return NOISE_ISA_AVX512;
	if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
	    __builtin_cpu_supports("bmi2"))
		return NOISE_ISA_AVX2;
	return NOISE_ISA_SCALAR;
}

bool noise_isa_has_avx2(void)
{
	enum noise_isa isa = noise_isa_best();
	return isa == NOISE_ISA_AVX2 || isa == NOISE_ISA_AVX512;
}

enum noise_isa noise_isa_best(void)
{
	int v = atomic_load_explicit(&isa_cached, memory_order_relaxed);
	if (v == 0) {
		v = (int)isa_detect() + 1;
		atomic_store_explicit(&isa_cached, v, memory_order_relaxed);
	}
	return (enum noise_isa)(v - 1);
}

int noise_isa_supported(enum noise_isa isa)
{
	switch (isa) {
	case NOISE_ISA_AUTO:
	case NOISE_ISA_SCALAR:
		return 1;
	case NOISE_ISA_AVX2:
		return noise_isa_best() >= NOISE_ISA_AVX2;
	case NOISE_ISA_AVX512:
		return noise_isa_best() >= NOISE_ISA_AVX512;
	}
	return 0;
}

const char *noise_isa_name(enum noise_isa isa)
{
	switch (isa) {
	case NOISE_ISA_AUTO:
		return "auto";
	case NOISE_ISA_SCALAR:
		return "scalar";
	case NOISE_ISA_AVX2:
		return "avx2";
	case NOISE_ISA_AVX512:
		return "avx512";
	}
	return "?";
}

/* ---- set-up ---- */

#define mix32 noise_mix32

uint32_t noise_mix32(uint32_t h)
{
	h ^= h >> 16;
	h *= 0x7feb352du;
	h ^= h >> 15;
	h *= 0x846ca68bu;
	h ^= h >> 16;
	return h;
}

double noise_texel_size(double a, int ly, uint32_t T)
{
	return M_PI * a / (ldexp(1.0, ly) * T);
}

double noise_pole_texels(double lat, int ly, uint32_t T)
{
	return (90 - fabs(lat)) * (ldexp(1.0, ly) * T / 180.0);
}

double noise_pole_weight(double bend, double t)
{
	double g = 2 - bend / NOISE_POLE_BEND;
	if (g >= 1)
		return 1;
	g = g > 0 ? g : 0;
	double f = (t - 1.5) / 2;
	f = f <= 0 ? 0 : f >= 1 ? 1 : f;
	return g + (1 - g) * f;
}

/* Octave k's bend over a texel of size s metres: its curvature, amplitude (metres) ×
 * (2π / shortest wavelength)², times s. 0 without pole_amplitude. */
static double octave_bend(const struct noise *nz, int k, double s)
{
	const struct noise_octave *o = &nz->oct[k];
	double kw = 2 * M_PI / o->lmin;
	return nz->p.pole_amplitude * o->amp * kw * kw * s;
}

double noise_band_weight(double lambda, double s)
{
	double w = log2(lambda / (2.0 * s));
	return w <= 0 ? 0 : w >= 1 ? 1 : w;
}

/* Expected weighted ridged signal per octave, from a fixed sample of simplex values used as
 * independent octaves: centring with it keeps the mean of a coarse tile (fewer octaves) equal
 * to that of its children. Deterministic: depends only on the parameters. */
static void ridged_means(struct noise *nz, int k0)
{
	enum { N = 2048 };
	static const double R3[3] = { 0.8191725133961645, 0.6710436067037893, 0.5497004779019703 };
	float vals[N];
	for (int j = 0; j < N; j++) {
		double x = fmod(0.5 + R3[0] * (j + 1), 1.0) * 97.0;
		double y = fmod(0.5 + R3[1] * (j + 1), 1.0) * 97.0;
		double z = fmod(0.5 + R3[2] * (j + 1), 1.0) * 97.0;
		vals[j] = (float)noise_simplex_ref(x, y, z, 0x5eedu);
	}
	double sum[NOISE_MAX_OCTAVES] = { 0 };
	for (int j = 0; j < N; j++) {
		double w = 1.0;
		for (int k = k0; k < nz->p.octaves; k++) {
			double n = vals[(unsigned)(j * 1237 + k * 613) % N];
			double s = nz->p.ridge_offset - fabs(n);
			s = s * s * w;
			w = s * nz->p.ridge_gain;
			w = w > nz->p.ridge_floor ? (w > 1 ? 1 : w) : nz->p.ridge_floor;
			sum[k] += s;
		}
	}
	for (int k = k0; k < nz->p.octaves; k++)
		nz->oct[k].mean = sum[k] / N;
}

void noise_seed_rotation(uint32_t seed, double r[3][3])
{
	double u1 = mix32(seed ^ 0x1b873593u) / 4294967296.0;
	double u2 = mix32(seed ^ 0xcc9e2d51u) / 4294967296.0 * 2 * M_PI;
	double u3 = mix32(seed ^ 0xe6546b64u) / 4294967296.0 * 2 * M_PI;
	double a = sqrt(1 - u1), b = sqrt(u1);
	double w = a * sin(u2), x = a * cos(u2), y = b * sin(u3), z = b * cos(u3);
	r[0][0] = 1 - 2 * (y * y + z * z);
	r[0][1] = 2 * (x * y - z * w);
	r[0][2] = 2 * (x * z + y * w);
	r[1][0] = 2 * (x * y + z * w);
	r[1][1] = 1 - 2 * (x * x + z * z);
	r[1][2] = 2 * (y * z - x * w);
	r[2][0] = 2 * (x * z - y * w);
	r[2][1] = 2 * (y * z + x * w);
	r[2][2] = 1 - 2 * (x * x + y * y);
}

static void rotate(const double r[3][3], const double v[3], double out[3])
{
	for (int a = 0; a < 3; a++)
		out[a] = r[a][0] * v[0] + r[a][1] * v[1] + r[a][2] * v[2];
}

static bool included(const struct noise *nz, int k)
{
	return !(nz->p.max_wavelength > 0 && nz->oct[k].lambda > nz->p.max_wavelength * (1 + 1e-9));
}

/* Whether octave k is evaluated at the warped point (noise_params.warp, warp_depth). */
static bool noise_warped(const struct noise *nz, int k)
{
	return nz->nwarp > 0 && (nz->p.warp_depth <= 0 || k < nz->p.warp_depth);
}

/* The warp's octaves (noise.nwarp, noise.warp): per octave q a wavelength warp_wavelength/2^q,
 * amplitude ∝ 0.5^q summing to warp metres, one hashed seed per component and one rotation. */
static void warp_setup(struct noise *nz)
{
	const struct noise_params *p = &nz->p;
	nz->nwarp = p->warp > 0 ? (p->warp_octaves > 0 ? p->warp_octaves : 2) : 0;
	double total = 0;
	for (int q = 0; q < nz->nwarp; q++)
		total += ldexp(1.0, -q);
	for (int q = 0; q < nz->nwarp; q++)
		for (int c = 0; c < 3; c++) {
			struct noise_octave *o = &nz->warp[q][c];
			o->lambda = o->lmin = ldexp(p->warp_wavelength, -q);
			o->freq = (double)(float)(p->radius / o->lambda);
			o->amp = p->warp * ldexp(1.0, -q) / total / p->radius;
			o->seed = mix32(p->seed ^ mix32((uint32_t)(q * 3 + c) * 0x85ebca6bu +
							0x2f1a7c33u));
			noise_seed_rotation(nz->warp[q][0].seed, o->rot);
		}
}

/* Largest singular value of a 3×3 matrix (power iteration on AᵀA). */
static double sigma_max(const double a[3][3])
{
	double m[3][3], v[3] = { 0.6, 0.5, 0.62 }, lam = 0;
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			m[i][j] = a[0][i] * a[0][j] + a[1][i] * a[1][j] + a[2][i] * a[2][j];
	for (int it = 0; it < 40; it++) {
		double u[3];
		rotate((const double(*)[3])m, v, u);
		lam = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
		if (!(lam > 0))
			return 0;
		for (int i = 0; i < 3; i++)
			v[i] = u[i] / lam;
	}
	return sqrt(lam);
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* noise.strain: I + ∂w/∂p (w in metres over metres) by central differences of the reference
 * simplex at a fixed sample of points in the warp's space (stationary: any region is as good
 * as another), its largest singular value's 99th percentile. Deterministic. */
static void warp_strain(struct noise *nz)
{
	enum { N = 512 };
	static const double R3[3] = { 0.8191725133961645, 0.6710436067037893, 0.5497004779019703 };
	double s[N];
	nz->strain = 1;
	if (nz->nwarp == 0)
		return;
	const double h = 1e-3; /* noise units of each octave */
	for (int j = 0; j < N; j++) {
		double x0[3], jac[3][3] = { { 1, 0, 0 }, { 0, 1, 0 }, { 0, 0, 1 } };
		for (int a = 0; a < 3; a++)
			x0[a] = fmod(0.5 + R3[a] * (j + 1), 1.0) * 61.0; /* warp_wavelength units */
		for (int q = 0; q < nz->nwarp; q++) {
			/* metres of displacement per metre: amp·radius (m) × 1/λ_q per noise unit */
			double g = nz->warp[q][0].amp * nz->p.radius / nz->warp[q][0].lambda;
			for (int c = 0; c < 3; c++)
				for (int d = 0; d < 3; d++) {
					double xp[3], xm[3];
					for (int a = 0; a < 3; a++)
						xp[a] = xm[a] = x0[a] * ldexp(1.0, q);
					xp[d] += h;
					xm[d] -= h;
					uint32_t sd = nz->warp[q][c].seed;
					double dn = noise_simplex_ref(xp[0], xp[1], xp[2], sd) -
						    noise_simplex_ref(xm[0], xm[1], xm[2], sd);
					jac[c][d] += g * dn / (2 * h);
				}
		}
		s[j] = sigma_max(jac);
	}
	qsort(s, N, sizeof *s, cmp_double);
	double v = s[(int)(0.99 * (N - 1))];
	nz->strain = v > 1 ? v : 1;
}

int noise_init(struct noise *nz, const struct noise_params *p)
{
	if (p->octaves < 1 || p->octaves > NOISE_MAX_OCTAVES || !(p->wavelength > 0) ||
	    !(p->lacunarity > 1) || !(p->gain >= 0) || !(p->radius > 0) ||
	    !isfinite(p->wavelength) || !isfinite(p->radius) || !isfinite(p->gain) ||
	    !(p->max_wavelength >= 0) || !isfinite(p->ridge_offset) || !isfinite(p->ridge_gain) ||
	    !(p->ridge_floor >= 0 && p->ridge_floor <= 1) ||
	    !(p->stretch == 0 || (p->stretch >= 1 && p->stretch <= 16)) || !(p->warp >= 0) ||
	    !isfinite(p->warp) || p->warp_octaves < 0 || p->warp_octaves > NOISE_WARP_MAX_OCTAVES ||
	    p->warp_depth < 0 ||
	    (p->warp > 0 && !(p->warp_wavelength > 0 && isfinite(p->warp_wavelength))))
		return -EINVAL;
	memset(nz, 0, sizeof *nz);
	nz->p = *p;
	warp_setup(nz);
	warp_strain(nz);
	double total = 0;
	for (int k = 0; k < p->octaves; k++)
		total += pow(p->gain, k);
	for (int k = 0; k < p->octaves; k++) {
		struct noise_octave *o = &nz->oct[k];
		o->lambda = p->wavelength / pow(p->lacunarity, k);
		o->freq = (double)(float)(p->radius / o->lambda);
		o->amp = pow(p->gain, k) / total * (p->kind == NOISE_RIDGED ? 2.0 : 1.0);
		o->seed = mix32(p->seed ^ mix32((uint32_t)k * 0x9e3779b9u + 0x632be5abu));
		noise_seed_rotation(o->seed, o->rot);
		/* Stretch: rotate(S·p) with S scaling z by the factor, folded into the matrix. */
		double st = p->stretch > 1 ? p->stretch : 1;
		for (int a = 0; a < 3; a++)
			o->rot[a][2] *= st;
		o->lmin = o->lambda / st / (noise_warped(nz, k) ? nz->strain : 1);
	}
	if (p->kind == NOISE_RIDGED) {
		int k0 = 0;
		while (k0 < p->octaves && !included(nz, k0))
			k0++;
		ridged_means(nz, k0);
	}
	return 0;
}

/* Octaves a tile of level ly evaluates whose shortest wavelength lies in [lo, hi) metres
 * (the band: [0, ∞) for all), with their band weights; returns how many. */
static int active_octaves(const struct noise *nz, int ly, uint32_t T, double lo, double hi,
			  int idx[], float w[])
{
	double s = noise_texel_size(nz->p.radius, ly, T);
	int m = 0;
	for (int k = 0; k < nz->p.octaves; k++) {
		/* continue, not break: a warped octave's lmin may be under the next one's */
		if (!included(nz, k) || nz->oct[k].lmin >= hi || nz->oct[k].lmin < lo)
			continue;
		double bw = noise_band_weight(nz->oct[k].lmin, s);
		if (bw <= 0)
			continue;
		idx[m] = k;
		w[m] = (float)bw;
		m++;
	}
	return m;
}


/* Lattice of a tile: M = T/h + 5 points across and down (2 beyond each edge, the one at the
 * far edge included), stored row-major in P floats (M² rounded up to 16). */
static uint32_t lattice_m(uint32_t T)
{
	return T / NOISE_MR_STRIDE + 5;
}

static size_t lattice_p(uint32_t T)
{
	size_t m = lattice_m(T);
	return (m * m + NOISE_LATTICE_PAD(m) + 15) / 16 * 16;
}

/* Floats of one interpolated lattice row (and of its slopes). */
static size_t lattice_row(uint32_t T)
{
	return (lattice_m(T) + NOISE_ROW_PAD + 15) / 16 * 16;
}

size_t noise_scratch_size(uint32_t T)
{
	/* texel rows: 2 double + 8 float arrays of T and the warp's 6; lattice: 8 +
	 * NOISE_MAX_OCTAVES float arrays of P (M² and a pad) and the warp's 6; per coarse octave
	 * (and warp component) one interpolated lattice row and its slopes: 2 float arrays of M
	 * and a pad */
	return (size_t)T * (2 * sizeof(double) + 14 * sizeof(float)) +
	       lattice_p(T) * (14 + NOISE_MAX_OCTAVES) * sizeof(float) +
	       lattice_row(T) * (2 * NOISE_MAX_OCTAVES + 6) * sizeof(float) + 64;
}

/* The metres a lattice step's wavelength is measured against: the larger texel side of a tile
 * of level (lx, ly) whose texels lie at most at latitude acos(cos_eq) from the equator — its
 * width there (the widest in the tile) or its height. cos_eq = 1: the level's widest texel
 * anywhere (along the equator, ≥ the height for every level the grid has). 0: none (a level
 * whose circumference is under NOISE_MR_MIN_TEXELS texels: the map from texels to points
 * varies on that scale, so the lattice would not follow it). */
static double lattice_texel(const struct noise *nz, int lx, int ly, uint32_t T, double cos_eq)
{
	double circ = 2.0 * M_PI * nz->p.radius, su = circ / (ldexp(1.0, lx) * T);
	if (circ < NOISE_MR_MIN_TEXELS * su)
		return 0;
	return fmax(su * cos_eq, noise_texel_size(nz->p.radius, ly, T));
}

/* Active octaves 0..mc-1 have a wavelength of at least NOISE_MR_MIN_TEXELS texels, texels
 * as lattice_texel measures them. */
static int coarse_count(const struct noise *nz, int lx, int ly, uint32_t T, double cos_eq,
			const int idx[], int m)
{
	double s = lattice_texel(nz, lx, ly, T, cos_eq);
	if (nz->p.exact || !(s > 0))
		return 0;
	int mc = 0;
	while (mc < m && nz->oct[idx[mc]].lmin >= NOISE_MR_MIN_TEXELS * s)
		mc++;
	return mc;
}

/* Whether a tile interpolates the warp from its lattice: the warp's shortest octave passes
 * coarse_count's test (so it is as precise as the coarse octaves). */
static bool warp_on_lattice(const struct noise *nz, int lx, int ly, uint32_t T, double cos_eq)
{
	double s = lattice_texel(nz, lx, ly, T, cos_eq);
	if (nz->nwarp == 0 || nz->p.exact || !(s > 0))
		return false;
	return nz->warp[nz->nwarp - 1][0].lambda >= NOISE_MR_MIN_TEXELS * s;
}

double noise_tile_cos_eq(const struct tile_key *k, uint32_t T)
{
	double lat = grid_band_equator_lat(grid_v_to_lat(k->ly, T, (double)k->y * T),
					   grid_v_to_lat(k->ly, T, (double)(k->y + 1) * T));
	return cos(lat * (M_PI / 180.0));
}

int noise_coarse_octaves(const struct noise *nz, int lx, int ly, uint32_t T)
{
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	int m = active_octaves(nz, ly, T, 0, INFINITY, idx, w);
	return coarse_count(nz, lx, ly, T, 1, idx, m);
}

int noise_tile_coarse_octaves(const struct noise *nz, const struct tile_key *k, uint32_t T)
{
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	if (!grid_key_valid(k))
		return -EINVAL;
	int m = active_octaves(nz, k->ly, T, 0, INFINITY, idx, w);
	return coarse_count(nz, k->lx, k->ly, T, noise_tile_cos_eq(k, T), idx, m);
}

static noise_row_fn *kernel_for(enum noise_isa isa)
{
	switch (isa) {
	case NOISE_ISA_SCALAR:
		return noise_row_scalar;
	case NOISE_ISA_AVX2:
		return noise_row_avx2;
	case NOISE_ISA_AVX512:
		return noise_row_avx512;
	case NOISE_ISA_AUTO:
		break;
	}
	return NULL;
}

static void unit_vector(double lon_deg, double lat_deg, double v[3])
{
	double lon = lon_deg * (M_PI / 180.0), lat = lat_deg * (M_PI / 180.0);
	v[0] = cos(lat) * cos(lon);
	v[1] = cos(lat) * sin(lon);
	v[2] = sin(lat);
}

/* The octave's lattice origin and texel-independent offset for a tile centred at pc (in the
 * octave's rotated frame). */
static void octave_row(const struct noise_octave *oc, const double pc0[3], struct noise_row *r)
{
	double q[3], O[3], pc[3];
	int64_t I0[3];
	rotate(oc->rot, pc0, pc);
	for (int a = 0; a < 3; a++)
		q[a] = pc[a] * oc->freq;
	double sk = (q[0] + q[1] + q[2]) * (1.0 / 3.0);
	for (int a = 0; a < 3; a++)
		I0[a] = (int64_t)floor(q[a] + sk);
	double ut = (double)(I0[0] + I0[1] + I0[2]) * (1.0 / 6.0);
	for (int a = 0; a < 3; a++)
		O[a] = (double)I0[a] - ut;
	r->f = (float)oc->freq;
	r->cx = (float)(q[0] - O[0]);
	r->cy = (float)(q[1] - O[1]);
	r->cz = (float)(q[2] - O[2]);
	r->hx = (uint32_t)I0[0] * NOISE_PX;
	r->hy = (uint32_t)I0[1] * NOISE_PY;
	r->hz = (uint32_t)I0[2] * NOISE_PZ;
	r->seed = oc->seed;
}

/* The fractal sums and the rows' set-up (noise_sums.h) run at each ISA's width: elementwise
 * IEEE operations give the same bits at any width. */
const struct noise_sums noise_sums_scalar = NOISE_SUMS_INIT;

const struct noise_sums *noise_sums_for(enum noise_isa isa)
{
	if (isa == NOISE_ISA_AUTO)
		isa = noise_isa_best();
	switch (isa) {
	case NOISE_ISA_AVX2:
		return &noise_sums_avx2;
	case NOISE_ISA_AVX512:
		return &noise_sums_avx512;
	default:
		return &noise_sums_scalar;
	}
}

/* Cubic Hermite basis at t = q/h, q = 0..h-1 (from double, so the same bits on every path):
 * value = h00·f0 + h10·m0 + h01·f1 + h11·m1 with slopes m per lattice step. */
static void hermite_basis(float b[4][NOISE_MR_STRIDE])
{
	for (int q = 0; q < NOISE_MR_STRIDE; q++) {
		double t = (double)q / NOISE_MR_STRIDE, t2 = t * t, t3 = t2 * t;
		b[0][q] = (float)(2 * t3 - 3 * t2 + 1);
		b[1][q] = (float)(t3 - 2 * t2 + t);
		b[2][q] = (float)(3 * t2 - 2 * t3);
		b[3][q] = (float)(t3 - t2);
	}
}

/* A tile's domain warp (noise.warp): each warp octave's row set-up for the tile, its float
 * rotation and per-component amplitudes; n = 0: none. */
struct warp_eval {
	int n;
	struct noise_row rows[NOISE_WARP_MAX_OCTAVES][3];
	float rot[NOISE_WARP_MAX_OCTAVES][9];
	float amp[NOISE_WARP_MAX_OCTAVES];
	/* on the lattice (noise.h): the displacement at the tile's lattice points (lw, M×M),
	 * interpolated per texel row with the coarse octaves' cubic (hb; tc, td: room for an
	 * interpolated row and its slopes per component) */
	bool lattice;
	uint32_t M;
	const float (*hb)[NOISE_MR_STRIDE];
	const float *lw[3];
	float *tc[3], *td[3];
};

/* The displacement w(pc + d) at the n points pc + (dx, dy, dz) (offsets from the tile's
 * centre, unit-sphere units) into w[0..2]. tmp: 4 float arrays of n (rx, ry, rz, nb).
 * Elementwise IEEE operations in a fixed order, through the ISA's own kernels: the same bits
 * on every path. */
static void warp_points(const struct warp_eval *we, const struct noise_sums *ns,
			noise_row_fn *row_fn, const float *dx, const float *dy, const float *dz,
			uint32_t n, float *const tmp[4], float *const w[3])
{
	float *rx = tmp[0], *ry = tmp[1], *rz = tmp[2], *nb = tmp[3];
	for (int c = 0; c < 3; c++)
		memset(w[c], 0, n * sizeof *w[c]);
	for (int q = 0; q < we->n; q++) {
		ns->rotate_row(we->rot[q], dx, dy, dz, rx, ry, rz, n);
		for (int c = 0; c < 3; c++) {
			row_fn(&we->rows[q][c], rx, ry, rz, nb, n);
			ns->acc_fbm(w[c], nb, we->amp[q], n);
		}
	}
}

/* o = d + w over n points (the warped points). */
static void warp_add(const float *dx, const float *dy, const float *dz, float *const w[3],
		     float *const o[3], uint32_t n)
{
	for (uint32_t i = 0; i < n; i++) {
		o[0][i] = dx[i] + w[0][i];
		o[1][i] = dy[i] + w[1][i];
		o[2][i] = dz[i] + w[2][i];
	}
}

/* The octaves mc..m-1 of texel row j, evaluated at every texel and added into row (wt: the
 * ridged weights so far); the first nwa of all active octaves at the warped points. tmp: 13
 * float arrays of T (dx, dy, dz, rx, ry, rz, nb, the warp's wx, wy, wz and the warped points'
 * ox, oy, oz). */
static void full_res_row(const struct noise *nz, const struct noise_sums *ns, noise_row_fn *row_fn,
			 const struct tile_key *k, uint32_t T, uint32_t j, const double pc[3],
			 const double *ccos, const double *csin, const struct noise_row *rows,
			 const float (*rot)[9], const float *amp, const float *mean, int mc, int m,
			 const struct warp_eval *we, int nwa, float *row, float *wt,
			 float *const tmp[13])
{
	float *dx = tmp[0], *dy = tmp[1], *dz = tmp[2], *rx = tmp[3], *ry = tmp[4], *rz = tmp[5];
	float *nb = tmp[6];
	const float ro = (float)nz->p.ridge_offset, rg = (float)nz->p.ridge_gain,
		    rf = (float)nz->p.ridge_floor;
	const bool ridged = nz->p.kind == NOISE_RIDGED;
	double lat = grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5) * (M_PI / 180.0);
	double cl = cos(lat), sl = sin(lat);
	ns->offsets_row(ccos, csin, cl, pc[0], pc[1], (float)(sl - pc[2]), dx, dy, dz, T);
	if (mc < nwa && we->lattice) {
		for (int c = 0; c < 3; c++) {
			ns->interp_cols(we->lw[c], we->M, j, we->hb, we->tc[c]);
			ns->interp_slopes(we->tc[c], we->M, we->td[c]);
			ns->interp_row(we->tc[c], we->td[c], we->M, we->hb, tmp[7 + c]);
		}
		warp_add(dx, dy, dz, tmp + 7, tmp + 10, T);
	} else if (mc < nwa) {
		warp_points(we, ns, row_fn, dx, dy, dz, T, tmp + 3, tmp + 7);
		warp_add(dx, dy, dz, tmp + 7, tmp + 10, T);
	}
	for (int o = mc; o < m; o++) {
		if (o < nwa)
			ns->rotate_row(rot[o], tmp[10], tmp[11], tmp[12], rx, ry, rz, T);
		else
			ns->rotate_row(rot[o], dx, dy, dz, rx, ry, rz, T);
		row_fn(&rows[o], rx, ry, rz, nb, T);
		if (!ridged)
			ns->acc_fbm(row, nb, amp[o], T);
		else
			ns->acc_ridged(row, wt, nb, amp[o], mean[o], ro, rg, rf, o == 0, T);
	}
}

/* One tile's evaluation (tile_sum): its octaves' set-up, shared by its steps, and where its
 * scratch arrays lie. */
struct tile_eval {
	const struct noise *nz;
	const struct tile_key *k;
	uint32_t T, M, P, MP; /* texels across; lattice points across, floats, floats per row */
	noise_row_fn *row_fn;
	const struct noise_sums *ns;
	bool ridged;
	float ro, rg, rf;	/* ridge offset, gain and floor */
	int m, mc;		/* active octaves; the first mc of them on the coarse lattice */
	double pc[3];		/* the tile's centre */
	struct noise_row rows[NOISE_MAX_OCTAVES];
	float amp[NOISE_MAX_OCTAVES], mean[NOISE_MAX_OCTAVES], rot[NOISE_MAX_OCTAVES][9];
	float hb[4][NOISE_MR_STRIDE];
	struct warp_eval we;
	int nwa;		/* the first nwa active octaves are warped */
	/* scratch (noise_scratch_size): texel columns' cos/sin and rows; the lattice; per coarse
	 * octave its raw lattice (ridged) and interpolated lattice row and slopes */
	double *ccos, *csin;
	float *dx, *dy, *dz, *nb, *wt, *rx, *ry, *rz;
	float *ldx, *ldy, *ldz, *lrx, *lry, *lrz, *lnb, *ls, *ln, *tc, *td;
	float *wx, *wy, *wz, *lwx, *lwy, *lwz; /* the warp's displacements (rows, lattice) */
	float *ox, *oy, *oz, *lox, *loy, *loz; /* the warped points (rows, lattice) */
	float *wtc, *wtd; /* the warp's interpolated lattice rows and slopes: 3 × MP each */
};

static void scratch_layout(struct tile_eval *t, void *scratch)
{
	const uint32_t T = t->T, P = t->P, MP = t->MP;
	t->ccos = scratch;
	t->csin = t->ccos + T;
	t->dx = (float *)(t->csin + T);
	t->dy = t->dx + T;
	t->dz = t->dy + T;
	t->nb = t->dz + T;
	t->wt = t->nb + T;
	t->rx = t->wt + T;
	t->ry = t->rx + T;
	t->rz = t->ry + T;
	t->ldx = t->rz + T;
	t->ldy = t->ldx + P;
	t->ldz = t->ldy + P;
	t->lrx = t->ldz + P;
	t->lry = t->lrx + P;
	t->lrz = t->lry + P;
	t->lnb = t->lrz + P;
	t->ls = t->lnb + P;
	t->ln = t->ls + P; /* mc × P */
	t->tc = t->ln + (size_t)NOISE_MAX_OCTAVES * P;
	t->td = t->tc + (size_t)NOISE_MAX_OCTAVES * MP;
	t->wx = t->td + (size_t)NOISE_MAX_OCTAVES * MP;
	t->wy = t->wx + T;
	t->wz = t->wy + T;
	t->lwx = t->wz + T;
	t->lwy = t->lwx + P;
	t->lwz = t->lwy + P;
	t->ox = t->lwz + P;
	t->oy = t->ox + T;
	t->oz = t->oy + T;
	t->lox = t->oz + T;
	t->loy = t->lox + P;
	t->loz = t->loy + P;
	t->wtc = t->loz + P;
	t->wtd = t->wtc + 3 * (size_t)MP;
}

/* The tile's centre and each active octave's lattice origin, float rotation and weighted
 * amplitude (idx, w: active_octaves'). */
static void octave_setup(struct tile_eval *t, const int idx[], const float w[])
{
	const struct noise *nz = t->nz;
	const struct tile_key *k = t->k;
	const uint32_t T = t->T;
	unit_vector(grid_u_to_lon(k->lx, T, (double)k->x * T + T / 2),
		    grid_v_to_lat(k->ly, T, (double)k->y * T + T / 2), t->pc);
	for (int o = 0; o < t->m; o++) {
		octave_row(&nz->oct[idx[o]], t->pc, &t->rows[o]);
		for (int a = 0; a < 9; a++)
			t->rot[o][a] = (float)nz->oct[idx[o]].rot[a / 3][a % 3];
		t->amp[o] = (float)(nz->oct[idx[o]].amp * w[o]);
		t->mean[o] = (float)nz->oct[idx[o]].mean;
	}
	t->we.n = nz->nwarp;
	for (int q = 0; q < nz->nwarp; q++) {
		for (int c = 0; c < 3; c++)
			octave_row(&nz->warp[q][c], t->pc, &t->we.rows[q][c]);
		for (int a = 0; a < 9; a++)
			t->we.rot[q][a] = (float)nz->warp[q][0].rot[a / 3][a % 3];
		t->we.amp[q] = (float)nz->warp[q][0].amp;
	}
}

/* The coarse octaves at the lattice points (texel centres of level texels whose u and v are
 * multiples of h), as one flat array through the row kernel: fBm their weighted sum in ls;
 * ridged each octave's raw noise in ln (smooth, unlike the creased signal), put through the
 * ridge per texel after interpolation. Then the interpolation's basis. */
static void coarse_lattice(struct tile_eval *t, bool octaves)
{
	const struct tile_key *k = t->k;
	const struct noise_sums *ns = t->ns;
	const uint32_t T = t->T, M = t->M, P = t->P;
	const double *pc = t->pc;
	double *ccos = t->ccos, *csin = t->csin;
	float *ldx = t->ldx, *ldy = t->ldy, *ldz = t->ldz;
	const double h = NOISE_MR_STRIDE;
	for (uint32_t a = 0; a < M; a++) {
		double u = (double)k->x * T + ((double)a - 2) * h + 0.5;
		double lon = grid_u_to_lon(k->lx, T, u) * (M_PI / 180.0);
		ccos[a] = cos(lon);
		csin[a] = sin(lon);
	}
	for (uint32_t r = 0; r < M; r++) {
		double v = (double)k->y * T + ((double)r - 2) * h + 0.5;
		double lat = grid_v_to_lat(k->ly, T, v) * (M_PI / 180.0);
		double cl = cos(lat), sl = sin(lat);
		float fz = (float)(sl - pc[2]);
		for (uint32_t a = 0; a < M; a++) {
			ldx[r * M + a] = (float)(cl * ccos[a] - pc[0]);
			ldy[r * M + a] = (float)(cl * csin[a] - pc[1]);
			ldz[r * M + a] = fz;
		}
	}
	for (uint32_t q = M * M; q < P; q++)
		ldx[q] = ldy[q] = ldz[q] = 0;
	hermite_basis(t->hb);
	if (t->nwa > 0) {
		float *const tmp[4] = { t->lrx, t->lry, t->lrz, t->lnb };
		float *const w[3] = { t->lwx, t->lwy, t->lwz }, *const o[3] = { t->lox, t->loy, t->loz };
		warp_points(&t->we, ns, t->row_fn, ldx, ldy, ldz, P, tmp, w);
		warp_add(ldx, ldy, ldz, w, o, P);
	}
	if (!octaves)
		return;
	memset(t->ls, 0, P * sizeof *t->ls);
	for (int o = 0; o < t->mc; o++) {
		if (o < t->nwa)
			ns->rotate_row(t->rot[o], t->lox, t->loy, t->loz, t->lrx, t->lry, t->lrz, P);
		else
			ns->rotate_row(t->rot[o], ldx, ldy, ldz, t->lrx, t->lry, t->lrz, P);
		if (!t->ridged) {
			t->row_fn(&t->rows[o], t->lrx, t->lry, t->lrz, t->lnb, P);
			ns->acc_fbm(t->ls, t->lnb, t->amp[o], P);
		} else {
			t->row_fn(&t->rows[o], t->lrx, t->lry, t->lrz, t->ln + (size_t)o * P, P);
		}
	}
}

/* The longitudes' cos and sin at the texel columns' centres (for full_res_row; after
 * coarse_lattice, whose lattice columns they replace). */
static void texel_columns(struct tile_eval *t)
{
	const struct tile_key *k = t->k;
	const uint32_t T = t->T;
	for (uint32_t i = 0; i < T; i++) {
		double lon = grid_u_to_lon(k->lx, T, (double)k->x * T + i + 0.5) * (M_PI / 180.0);
		t->ccos[i] = cos(lon);
		t->csin[i] = sin(lon);
	}
}

/* Texel row j's coarse octaves, interpolated from the lattice into row (ridged: and their
 * weight into wt); zeros without any. */
static void coarse_row(struct tile_eval *t, uint32_t j, float *row)
{
	const struct noise_sums *ns = t->ns;
	const uint32_t M = t->M, P = t->P, MP = t->MP;
	const int mc = t->mc;
	if (mc > 0 && !t->ridged) {
		ns->interp_cols(t->ls, M, j, t->hb, t->tc);
		ns->interp_slopes(t->tc, M, t->td);
		ns->interp_row(t->tc, t->td, M, t->hb, row);
	} else if (mc > 0) {
		for (int o = 0; o < mc; o++)
			ns->interp_cols(t->ln + (size_t)o * P, M, j, t->hb, t->tc + (size_t)o * MP);
		for (int o = 0; o < mc; o++)
			ns->interp_slopes(t->tc + (size_t)o * MP, M, t->td + (size_t)o * MP);
		ns->ridged_coarse(row, t->wt, mc, t->tc, t->td, MP, M, t->hb, t->amp, t->mean,
				  t->ro, t->rg, t->rf);
	} else {
		memset(row, 0, t->T * sizeof *row);
	}
}

/* The tile's sum of its octaves with a shortest wavelength in [lo, hi) metres into out (T×T),
 * with scale put through ns->finish (base: may be NULL); fade: the pole fade applies. Returns
 * the octaves' count, or -EINVAL (bad key or T), -ENOTSUP (isa). */
static int tile_sum(const struct noise *nz, const struct tile_key *k, uint32_t T,
		    enum noise_isa isa, void *scratch, bool scale, const float *base, float amplitude,
		    float offset, float *out, double lo, double hi, bool fade)
{
	if (!grid_key_valid(k) || T < 16 || T > 4096 || T % 16)
		return -EINVAL;
	if (isa == NOISE_ISA_AUTO)
		isa = noise_isa_best();
	if (!noise_isa_supported(isa))
		return -ENOTSUP;
	struct tile_eval t = {
		.nz = nz, .k = k, .T = T, .M = lattice_m(T), .P = (uint32_t)lattice_p(T),
		.MP = (uint32_t)lattice_row(T), .row_fn = kernel_for(isa),
		.ns = noise_sums_for(isa),
		.ridged = nz->p.kind == NOISE_RIDGED, .ro = (float)nz->p.ridge_offset,
		.rg = (float)nz->p.ridge_gain, .rf = (float)nz->p.ridge_floor,
	};
	const struct noise_sums *ns = t.ns;
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	t.m = active_octaves(nz, k->ly, T, lo, hi, idx, w);
	const double cos_eq = noise_tile_cos_eq(k, T);
	t.mc = coarse_count(nz, k->lx, k->ly, T, cos_eq, idx, t.m);
	scratch_layout(&t, scratch);
	if (t.m == 0) {
		memset(out, 0, (size_t)T * T * sizeof *out);
		for (uint32_t j = 0; scale && j < T; j++)
			ns->finish(out + (size_t)j * T, base ? base + (size_t)j * T : NULL, amplitude,
				   offset, T);
		return 0;
	}
	/* Pole fade (noise_pole_weight): in a tile touching a pole, the octaves that bend too
	 * much get a weight per texel row; they stay off the lattice (whose sum is shared by
	 * all rows — its interpolation error is ~1e-6 of the amplitude, no seam to speak of). */
	double bend[NOISE_MAX_OCTAVES];
	int pf = t.m; /* the first octave the pole fade touches; m: none */
	if (fade && nz->p.pole_amplitude > 0 && (k->y == 0 || k->y == grid_tiles_y(k->ly) - 1)) {
		double s = noise_texel_size(nz->p.radius, k->ly, T);
		for (int o = 0; o < t.m; o++) {
			bend[o] = octave_bend(nz, idx[o], s);
			if (bend[o] > NOISE_POLE_BEND && pf == t.m)
				pf = o;
		}
		t.mc = t.mc < pf ? t.mc : pf;
	}
	octave_setup(&t, idx, w);
	t.nwa = 0;
	while (t.nwa < t.m && noise_warped(nz, idx[t.nwa]))
		t.nwa++;
	/* the lattice carries the displacement where the full-resolution rows need it */
	t.we.lattice = t.mc < t.nwa && warp_on_lattice(nz, k->lx, k->ly, T, cos_eq);
	if (t.we.lattice) {
		t.we.M = t.M;
		t.we.hb = (const float(*)[NOISE_MR_STRIDE])t.hb;
		t.we.lw[0] = t.lwx;
		t.we.lw[1] = t.lwy;
		t.we.lw[2] = t.lwz;
		for (int c = 0; c < 3; c++) {
			t.we.tc[c] = t.wtc + (size_t)c * t.MP;
			t.we.td[c] = t.wtd + (size_t)c * t.MP;
		}
	}
	if (t.mc > 0 || t.we.lattice)
		coarse_lattice(&t, t.mc > 0);
	if (t.mc < t.m)
		texel_columns(&t);
	float *const tmp[13] = { t.dx, t.dy, t.dz, t.rx, t.ry, t.rz, t.nb, t.wx, t.wy, t.wz,
				 t.ox, t.oy, t.oz };
	float pamp[NOISE_MAX_OCTAVES];
	for (uint32_t j = 0; j < T; j++) {
		float *row = out + (size_t)j * T;
		const float *amp = t.amp;
		if (pf < t.m) {
			double tp = noise_pole_texels(
				grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5), k->ly, T);
			if (tp < 3.5) {
				for (int o = 0; o < t.m; o++)
					pamp[o] = o < pf ? t.amp[o]
							 : (float)(t.amp[o] *
								   noise_pole_weight(bend[o], tp));
				amp = pamp;
			}
		}
		coarse_row(&t, j, row);
		if (t.mc < t.m)
			full_res_row(nz, ns, t.row_fn, k, T, j, t.pc, t.ccos, t.csin, t.rows, t.rot,
				     amp, t.mean, t.mc, t.m, &t.we, t.nwa, row, t.wt, tmp);
		if (scale)
			ns->finish(row, base ? base + (size_t)j * T : NULL, amplitude, offset, T);
	}
	return t.m;
}


int noise_tile(const struct noise *nz, const struct tile_key *k, uint32_t T, enum noise_isa isa,
	       void *scratch, float *out)
{
	return tile_sum(nz, k, T, isa, scratch, false, NULL, 1, 0, out, 0, INFINITY, true);
}

int noise_tile_scaled(const struct noise *nz, const struct tile_key *k, uint32_t T,
		      enum noise_isa isa, void *scratch, const float *base, float amplitude,
		      float offset, float *out)
{
	return tile_sum(nz, k, T, isa, scratch, true, base, amplitude, offset, out, 0, INFINITY,
			true);
}

double noise_point(const struct noise *nz, double lon, double lat, int ly, uint32_t T)
{
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	int m = active_octaves(nz, ly, T, 0, INFINITY, idx, w);
	double p0[3], p[3], sum = 0, wt = 1;
	double ts = noise_texel_size(nz->p.radius, ly, T), tp = noise_pole_texels(lat, ly, T);
	unit_vector(lon, lat, p0);
	double wp[3] = { 0, 0, 0 };
	for (int q = 0; q < nz->nwarp; q++) {
		rotate(nz->warp[q][0].rot, p0, p);
		for (int c = 0; c < 3; c++) {
			const struct noise_octave *oc = &nz->warp[q][c];
			wp[c] += oc->amp * noise_simplex_ref(p[0] * oc->freq, p[1] * oc->freq,
							    p[2] * oc->freq, oc->seed);
		}
	}
	double pw[3];
	for (int a = 0; a < 3; a++)
		pw[a] = p0[a] + wp[a];
	for (int o = 0; o < m; o++) {
		const struct noise_octave *oc = &nz->oct[idx[o]];
		rotate(oc->rot, noise_warped(nz, idx[o]) ? pw : p0, p);
		double n = noise_simplex_ref(p[0] * oc->freq, p[1] * oc->freq, p[2] * oc->freq,
					     oc->seed);
		double a = oc->amp * w[o];
		if (nz->p.pole_amplitude > 0)
			a *= noise_pole_weight(octave_bend(nz, idx[o], ts), tp);
		if (nz->p.kind == NOISE_FBM) {
			sum += a * n;
			continue;
		}
		double s = nz->p.ridge_offset - fabs(n);
		s = s * s * wt;
		wt = s * nz->p.ridge_gain;
		wt = wt > nz->p.ridge_floor ? (wt > 1 ? 1 : wt) : nz->p.ridge_floor;
		sum += (s - oc->mean) * a;
	}
	return sum;
}

int noise_tile_band(const struct noise *nz, const struct tile_key *k, uint32_t T,
		    enum noise_isa isa, void *scratch, double lo, double hi, bool fade, float *out)
{
	return tile_sum(nz, k, T, isa, scratch, false, NULL, 1, 0, out, lo, hi, fade);
}

bool noise_pole_fades(const struct noise *nz, const struct tile_key *k, uint32_t T, double lo)
{
	if (!(nz->p.pole_amplitude > 0) || (k->y != 0 && k->y != grid_tiles_y(k->ly) - 1))
		return false;
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	int m = active_octaves(nz, k->ly, T, lo, INFINITY, idx, w);
	double s = noise_texel_size(nz->p.radius, k->ly, T);
	for (int o = 0; o < m; o++)
		if (octave_bend(nz, idx[o], s) > NOISE_POLE_BEND)
			return true;
	return false;
}

int noise_band_full(const struct noise *nz, int lx, int ly, uint32_t T, double lo, double hi)
{
	int idx[NOISE_MAX_OCTAVES];
	float w[NOISE_MAX_OCTAVES];
	int m = active_octaves(nz, ly, T, lo, hi, idx, w);
	return m - coarse_count(nz, lx, ly, T, 1, idx, m);
}
