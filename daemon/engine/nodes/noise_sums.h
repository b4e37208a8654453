/* noise_sums — internal to the noise module: the loops around the simplex kernel (rotation of
 * the texel offsets into an octave's frame, fractal sums, the lattice interpolation), written
 * once with GCC vector extensions and compiled into each ISA's translation unit (noise.c for
 * the baseline, noise_avx2.c, noise_avx512.c), so each path runs them at its own width.
 * Bit-identity: elementwise IEEE adds and multiplies in a fixed order, no FMA (C11 mode, so
 * no contraction), the scalar tails use the same expressions: every path gives the same bits.
 * Pure functions, thread-safe; nothing allocates.
 */
#ifndef CLIPMAP_NOISE_SUMS_H
#define CLIPMAP_NOISE_SUMS_H
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "noise.h"

_Static_assert(NOISE_MR_STRIDE == 8, "the row pass puts one lattice cell in one vector");

struct noise_sums {
	/* (rx, ry, rz) = R·(dx, dy, dz) over n (a multiple of 8) texels. */
	void (*rotate_row)(const float r[9], const float *dx, const float *dy, const float *dz,
			   float *rx, float *ry, float *rz, uint32_t n);
	/* row += a · nb over T texels. */
	void (*acc_fbm)(float *row, const float *nb, float a, uint32_t T);
	/* Musgrave: s = (ro − |n|)² · weight; weight = clamp(s · rg, rf, 1); row += (s − mu) · a. */
	void (*acc_ridged)(float *row, float *wt, const float *nb, float a, float mu, float ro,
			   float rg, float rf, int first, uint32_t T);
	/* Column pass of lattice row j: c[0..M) interpolated down the lattice columns. The
	 * lattice l (M×M) must be followed by NOISE_LATTICE_PAD(M) readable floats, c must have
	 * room for M + NOISE_ROW_PAD. */
	void (*interp_cols)(const float *l, uint32_t M, uint32_t j, const float b[4][NOISE_MR_STRIDE],
			    float *c);
	/* d[2..M-2): the slopes of c along the row (d: room for M + NOISE_ROW_PAD). A separate
	 * call, so several rows' c can be stored before any is read back unaligned (a load
	 * straddling two fresh stores waits for them). */
	void (*interp_slopes)(const float *c, uint32_t M, float *d);
	/* Row pass: out[0..(M-5)·h) from c, d. */
	void (*interp_row)(const float *c, const float *d, uint32_t M,
			   const float b[4][NOISE_MR_STRIDE], float *out);
	/* Ridged coarse octaves 0..mc-1 of one texel row at once (their c, d at c + o·stride,
	 * d + o·stride): row = Σ (s − mu)·a from 0 with the weight recurrence, wt = the weight
	 * after the last one. Same bits as interp_row then acc_ridged per octave. */
	void (*ridged_coarse)(float *row, float *wt, int mc, const float *c, const float *d,
			      size_t stride, uint32_t M, const float b[4][NOISE_MR_STRIDE],
			      const float *amp, const float *mean, float ro, float rg, float rf);
	/* row = base + (off + a·row), or off + a·row when base is NULL, over T texels. */
	void (*finish)(float *row, const float *base, float a, float off, uint32_t T);
	/* row += b over n texels (a multiple of 8). */
	void (*add)(float *row, const float *b, size_t n);
	/* The carry upsample's passes (noise_carry.c), with its six-tap sum
	 * ((((w0·f0 + w1·f1) + w2·f2) + w3·f3) + w4·f4) + w5·f5 in that order, so every path gives
	 * the bits of the scalar expression. Down the columns: col[c] = Σ w[q]·g[c + q·stride]
	 * for c < n (any n). Along a row whose parent has half the columns: row[2m] += Σ
	 * we[q]·col[m + q], row[2m + 1] += Σ wo[q]·col[m + 1 + q] for 2m < T (T a multiple of 16;
	 * col holds T/2 + 6 values). */
	void (*carry_cols)(const float w[6], const float *g, size_t stride, float *col, uint32_t n);
	void (*carry_rows)(const float we[6], const float wo[6], const float *col, float *row,
			   uint32_t T);
	/* A texel row's offsets from the tile's centre: dx = (float)(cl·ccos − px), dy =
	 * (float)(cl·csin − py) (in double, then rounded), dz = fz, over T texels. */
	void (*offsets_row)(const double *ccos, const double *csin, double cl, double px,
			    double py, float fz, float *dx, float *dy, float *dz, uint32_t T);
};

/* The set for an ISA (NOISE_ISA_AUTO: the best this CPU runs). */
const struct noise_sums *noise_sums_for(enum noise_isa isa);

#define NOISE_LATTICE_PAD(M) (2 * (M) + 16)
#define NOISE_ROW_PAD 16

extern const struct noise_sums noise_sums_scalar, noise_sums_avx2, noise_sums_avx512;

#ifndef NOISE_SUMS_DECL_ONLY
/* ---- the shared bodies (static: one copy per including translation unit) ---- */

/* The baseline build has no 256-bit registers: these vectors live in pairs of SSE registers
 * and the helpers taking or returning them are static and always inlined, so the ABI note
 * GCC gives about passing them does not apply. */
#pragma GCC diagnostic ignored "-Wpsabi"
#define NS_INLINE static inline __attribute__((always_inline))
typedef float ns_v8f __attribute__((vector_size(32)));
typedef int ns_v8i __attribute__((vector_size(32)));

NS_INLINE ns_v8f ns_load(const float *p)
{
	ns_v8f v;
	memcpy(&v, p, sizeof v);
	return v;
}

/* A macro, not a function: GCC notes the vector parameter's ABI even when inlined. */
#define ns_store(p, v)                                                                           \
	do {                                                                                     \
		ns_v8f ns_st_ = (v);                                                             \
		memcpy((p), &ns_st_, sizeof ns_st_);                                             \
	} while (0)

NS_INLINE ns_v8f ns_set1(float a) { return (ns_v8f){ a, a, a, a, a, a, a, a }; }

static void ns_rotate_row(const float r[9], const float *dx, const float *dy, const float *dz,
			  float *rx, float *ry, float *rz, uint32_t n)
{
	const ns_v8f r0 = ns_set1(r[0]), r1 = ns_set1(r[1]), r2 = ns_set1(r[2]),
		     r3 = ns_set1(r[3]), r4 = ns_set1(r[4]), r5 = ns_set1(r[5]),
		     r6 = ns_set1(r[6]), r7 = ns_set1(r[7]), r8 = ns_set1(r[8]);
	for (uint32_t i = 0; i < n; i += 8) {
		ns_v8f x = ns_load(dx + i), y = ns_load(dy + i), z = ns_load(dz + i);
		ns_store(rx + i, (r0 * x + r1 * y) + r2 * z);
		ns_store(ry + i, (r3 * x + r4 * y) + r5 * z);
		ns_store(rz + i, (r6 * x + r7 * y) + r8 * z);
	}
}

static void ns_acc_fbm(float *row, const float *nb, float a, uint32_t T)
{
	const ns_v8f va = ns_set1(a);
	for (uint32_t i = 0; i < T; i += 8)
		ns_store(row + i, ns_load(row + i) + va * ns_load(nb + i));
}

/* One ridged step on vectors (a macro for the same reason as ns_store): s = (ro − |n|)²·w;
 * w = clamp(s·rg, rf, 1); r += (s − mu)·a. (NaN s·rg: rf, as the scalar's comparisons.) */
#define ns_ridge(r, w, n, va, vmu, vro, vrg, vrf)                                               \
	do {                                                                                     \
		const ns_v8i am_ = { 0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff,            \
				     0x7fffffff, 0x7fffffff, 0x7fffffff, 0x7fffffff };           \
		const ns_v8f one_ = ns_set1(1.0f);                                               \
		ns_v8f s_ = (vro) - (ns_v8f)((ns_v8i)(n) & am_);                                 \
		s_ = s_ * s_ * (w);                                                              \
		ns_v8f nw_ = s_ * (vrg);                                                         \
		ns_v8i up_ = nw_ > (vrf);                                                        \
		nw_ = (ns_v8f)(((ns_v8i)nw_ & up_) | ((ns_v8i)(vrf) & ~up_));                    \
		ns_v8i big_ = nw_ > one_;                                                        \
		(w) = (ns_v8f)(((ns_v8i)one_ & big_) | ((ns_v8i)nw_ & ~big_));                   \
		(r) = (r) + (s_ - (vmu)) * (va);                                                 \
	} while (0)

static void ns_acc_ridged(float *row, float *wt, const float *nb, float a, float mu, float ro,
			  float rg, float rf, int first, uint32_t T)
{
	const ns_v8f va = ns_set1(a), vmu = ns_set1(mu), vro = ns_set1(ro), vrg = ns_set1(rg),
		     vrf = ns_set1(rf);
	for (uint32_t i = 0; i < T; i += 8) {
		ns_v8f w = first ? ns_set1(1.0f) : ns_load(wt + i), r = ns_load(row + i);
		ns_v8f n = ns_load(nb + i);
		ns_ridge(r, w, n, va, vmu, vro, vrg, vrf);
		ns_store(row + i, r);
		ns_store(wt + i, w);
	}
}

/* 4th-order central difference at v[0] along a stride. */
NS_INLINE ns_v8f ns_slope4v(const float *v, size_t st)
{
	return ((ns_load(v - 2 * (ptrdiff_t)st) - ns_load(v + 2 * st)) +
		ns_set1(8.0f) * (ns_load(v + st) - ns_load(v - (ptrdiff_t)st))) *
	       ns_set1(1.0f / 12.0f);
}

static void ns_interp_cols(const float *l, uint32_t M, uint32_t j,
			   const float b[4][NOISE_MR_STRIDE], float *c)
{
	const uint32_t h = NOISE_MR_STRIDE, q = j % h;
	const float *l0 = l + (size_t)(j / h + 2) * M, *l1 = l0 + M;
	const ns_v8f vb0 = ns_set1(b[0][q]), vb1 = ns_set1(b[1][q]), vb2 = ns_set1(b[2][q]),
		     vb3 = ns_set1(b[3][q]);
	/* Whole vectors only: the lattice is padded (NOISE_LATTICE_PAD) and c, d hold
	 * NOISE_ROW_PAD floats beyond M, so the values past the end are finite and unused (c up
	 * to M + 6 feeds interp_slopes' last vector). */
	for (uint32_t a = 0; a < M + 7; a += 8)
		ns_store(c + a, ((vb0 * ns_load(l0 + a) + vb1 * ns_slope4v(l0 + a, M)) +
				 vb2 * ns_load(l1 + a)) +
					vb3 * ns_slope4v(l1 + a, M));
}

static void ns_interp_slopes(const float *c, uint32_t M, float *d)
{
	for (uint32_t a = 2; a + 2 < M; a += 8)
		ns_store(d + a, ns_slope4v(c + a, 1));
}

static void ns_interp_row(const float *c, const float *d, uint32_t M,
			  const float b[4][NOISE_MR_STRIDE], float *out)
{
	const ns_v8f B0 = ns_load(b[0]), B1 = ns_load(b[1]), B2 = ns_load(b[2]),
		     B3 = ns_load(b[3]);
	for (uint32_t cell = 0; cell + 5 < M; cell++)
		ns_store(out + cell * NOISE_MR_STRIDE,
			 ((B0 * ns_set1(c[cell + 2]) + B1 * ns_set1(d[cell + 2])) +
			  B2 * ns_set1(c[cell + 3])) +
				 B3 * ns_set1(d[cell + 3]));
}

static void ns_ridged_coarse(float *row, float *wt, int mc, const float *c, const float *d,
			     size_t stride, uint32_t M, const float b[4][NOISE_MR_STRIDE],
			     const float *amp, const float *mean, float ro, float rg, float rf)
{
	const ns_v8f B0 = ns_load(b[0]), B1 = ns_load(b[1]), B2 = ns_load(b[2]),
		     B3 = ns_load(b[3]);
	const ns_v8f vro = ns_set1(ro), vrg = ns_set1(rg), vrf = ns_set1(rf);
	for (uint32_t cell = 0; cell + 5 < M; cell++) {
		ns_v8f r = ns_set1(0.0f), w = ns_set1(1.0f);
		for (int o = 0; o < mc; o++) {
			const float *co = c + (size_t)o * stride + cell, *dd = d + (size_t)o * stride + cell;
			ns_v8f n = ((B0 * ns_set1(co[2]) + B1 * ns_set1(dd[2])) + B2 * ns_set1(co[3])) +
				   B3 * ns_set1(dd[3]);
			const ns_v8f va = ns_set1(amp[o]), vmu = ns_set1(mean[o]);
			ns_ridge(r, w, n, va, vmu, vro, vrg, vrf);
		}
		ns_store(row + cell * NOISE_MR_STRIDE, r);
		ns_store(wt + cell * NOISE_MR_STRIDE, w);
	}
}

static void ns_finish(float *row, const float *base, float a, float off, uint32_t T)
{
	const ns_v8f va = ns_set1(a), voff = ns_set1(off);
	if (base)
		for (uint32_t i = 0; i < T; i += 8)
			ns_store(row + i, ns_load(base + i) + (voff + va * ns_load(row + i)));
	else
		for (uint32_t i = 0; i < T; i += 8)
			ns_store(row + i, voff + va * ns_load(row + i));
}

static void ns_add(float *row, const float *b, size_t n)
{
	for (size_t i = 0; i < n; i += 8)
		ns_store(row + i, ns_load(row + i) + ns_load(b + i));
}

/* The six-tap sum on one value (the tails) and on 8 (stride between taps). */
NS_INLINE float ns_tap6(const float w[6], const float *f, size_t st)
{
	return ((((w[0] * f[0] + w[1] * f[st]) + w[2] * f[2 * st]) + w[3] * f[3 * st]) +
		w[4] * f[4 * st]) +
	       w[5] * f[5 * st];
}

#define ns_tap6v(W, f, st)                                                                       \
	(((((W[0] * ns_load(f) + W[1] * ns_load((f) + (st))) + W[2] * ns_load((f) + 2 * (st))) +  \
	   W[3] * ns_load((f) + 3 * (st))) +                                                       \
	  W[4] * ns_load((f) + 4 * (st))) +                                                        \
	 W[5] * ns_load((f) + 5 * (st)))

static void ns_carry_cols(const float w[6], const float *g, size_t stride, float *col, uint32_t n)
{
	const ns_v8f W[6] = { ns_set1(w[0]), ns_set1(w[1]), ns_set1(w[2]),
			      ns_set1(w[3]), ns_set1(w[4]), ns_set1(w[5]) };
	uint32_t c = 0;
	for (; c + 8 <= n; c += 8)
		ns_store(col + c, ns_tap6v(W, g + c, stride));
	for (; c < n; c++)
		col[c] = ns_tap6(w, g + c, stride);
}

static void ns_carry_rows(const float we[6], const float wo[6], const float *col, float *row,
			  uint32_t T)
{
	const ns_v8f E[6] = { ns_set1(we[0]), ns_set1(we[1]), ns_set1(we[2]),
			      ns_set1(we[3]), ns_set1(we[4]), ns_set1(we[5]) };
	const ns_v8f O[6] = { ns_set1(wo[0]), ns_set1(wo[1]), ns_set1(wo[2]),
			      ns_set1(wo[3]), ns_set1(wo[4]), ns_set1(wo[5]) };
	const ns_v8i lo = { 0, 8, 1, 9, 2, 10, 3, 11 }, hi = { 4, 12, 5, 13, 6, 14, 7, 15 };
	for (uint32_t m = 0; 2 * m < T; m += 8) {
		ns_v8f e = ns_tap6v(E, col + m, 1), o = ns_tap6v(O, col + m + 1, 1);
		ns_store(row + 2 * m, ns_load(row + 2 * m) + __builtin_shuffle(e, o, lo));
		ns_store(row + 2 * m + 8, ns_load(row + 2 * m + 8) + __builtin_shuffle(e, o, hi));
	}
}

typedef double ns_v8d __attribute__((vector_size(64)));

static void ns_offsets_row(const double *ccos, const double *csin, double cl, double px,
			   double py, float fz, float *dx, float *dy, float *dz, uint32_t T)
{
	const ns_v8d vcl = { cl, cl, cl, cl, cl, cl, cl, cl };
	const ns_v8d vpx = { px, px, px, px, px, px, px, px }, vpy = { py, py, py, py, py, py, py, py };
	const ns_v8f vz = ns_set1(fz);
	for (uint32_t i = 0; i < T; i += 8) {
		ns_v8d c, s;
		memcpy(&c, ccos + i, sizeof c);
		memcpy(&s, csin + i, sizeof s);
		ns_store(dx + i, __builtin_convertvector(vcl * c - vpx, ns_v8f));
		ns_store(dy + i, __builtin_convertvector(vcl * s - vpy, ns_v8f));
		ns_store(dz + i, vz);
	}
}

#define NOISE_SUMS_INIT                                                                          \
	{ ns_rotate_row, ns_acc_fbm, ns_acc_ridged, ns_interp_cols, ns_interp_slopes, ns_interp_row, \
	  ns_ridged_coarse, ns_finish, ns_add, ns_carry_cols, ns_carry_rows, ns_offsets_row }
#endif /* NOISE_SUMS_DECL_ONLY */

#endif
