/* noise_avx2 — the simplex row kernel, 8 texels per vector (AVX2 + FMA). It mirrors
 * noise_row_scalar (noise.c) operation for operation, so both give the same bits; keep them in
 * step. Compiled with -mavx2 -mfma; called only when the CPU has them. Thread-safe (pure).
 */
#include <immintrin.h>

#include "noise.h"
#include "noise_sums.h"

const struct noise_sums noise_sums_avx2 = NOISE_SUMS_INIT;

static inline __m256 corner(__m256i h, __m256 x, __m256 y, __m256 z)
{
	h = _mm256_mullo_epi32(h, _mm256_set1_epi32((int)NOISE_HMUL));
	__m256i g = _mm256_srli_epi32(h, 28);
	__m256 lt8 = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32(8), g));
	__m256 lt4 = _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32(4), g));
	__m256 is12 = _mm256_castsi256_ps(_mm256_cmpeq_epi32(
		_mm256_and_si256(g, _mm256_set1_epi32(13)), _mm256_set1_epi32(12)));
	__m256 u = _mm256_blendv_ps(y, x, lt8);
	__m256 v = _mm256_blendv_ps(_mm256_blendv_ps(z, x, is12), y, lt4);
	__m256 su = _mm256_xor_ps(u, _mm256_castsi256_ps(_mm256_slli_epi32(g, 31)));
	__m256 sv = _mm256_xor_ps(v, _mm256_castsi256_ps(_mm256_slli_epi32(
					     _mm256_and_si256(g, _mm256_set1_epi32(2)), 30)));
	__m256 grad = _mm256_add_ps(su, sv);
	__m256 t = _mm256_fnmadd_ps(x, x, _mm256_set1_ps(0.5f));
	t = _mm256_fnmadd_ps(y, y, t);
	t = _mm256_fnmadd_ps(z, z, t);
	t = _mm256_max_ps(t, _mm256_setzero_ps());
	__m256 t2 = _mm256_mul_ps(t, t);
	__m256 t4 = _mm256_mul_ps(t2, t2);
	return _mm256_mul_ps(t4, grad);
}

static inline __m256i hash3(__m256i seed, __m256i hx, __m256i hy, __m256i hz)
{
	return _mm256_xor_si256(_mm256_xor_si256(seed, hx), _mm256_xor_si256(hy, hz));
}

void noise_row_avx2(const struct noise_row *o, const float *dx, const float *dy, const float *dz,
		    float *out, uint32_t n)
{
	const __m256 f = _mm256_set1_ps(o->f), cx = _mm256_set1_ps(o->cx),
		     cy = _mm256_set1_ps(o->cy), cz = _mm256_set1_ps(o->cz);
	const __m256 F3 = _mm256_set1_ps(NOISE_F3), G3 = _mm256_set1_ps(NOISE_G3),
		     G3x2 = _mm256_set1_ps(2.0f * NOISE_G3), G3x3 = _mm256_set1_ps(3.0f * NOISE_G3);
	const __m256 one = _mm256_set1_ps(1.0f);
	const __m256i PX = _mm256_set1_epi32((int)NOISE_PX), PY = _mm256_set1_epi32((int)NOISE_PY),
		      PZ = _mm256_set1_epi32((int)NOISE_PZ);
	const __m256i ohx = _mm256_set1_epi32((int)o->hx), ohy = _mm256_set1_epi32((int)o->hy),
		      ohz = _mm256_set1_epi32((int)o->hz), seed = _mm256_set1_epi32((int)o->seed);
	for (uint32_t i = 0; i < n; i += 8) {
		__m256 x = _mm256_fmadd_ps(_mm256_loadu_ps(dx + i), f, cx);
		__m256 y = _mm256_fmadd_ps(_mm256_loadu_ps(dy + i), f, cy);
		__m256 z = _mm256_fmadd_ps(_mm256_loadu_ps(dz + i), f, cz);
		__m256 s = _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(x, y), z), F3);
		__m256 fi = _mm256_floor_ps(_mm256_add_ps(x, s));
		__m256 fj = _mm256_floor_ps(_mm256_add_ps(y, s));
		__m256 fk = _mm256_floor_ps(_mm256_add_ps(z, s));
		__m256 t = _mm256_mul_ps(_mm256_add_ps(_mm256_add_ps(fi, fj), fk), G3);
		__m256 x0 = _mm256_add_ps(_mm256_sub_ps(x, fi), t);
		__m256 y0 = _mm256_add_ps(_mm256_sub_ps(y, fj), t);
		__m256 z0 = _mm256_add_ps(_mm256_sub_ps(z, fk), t);
		__m256 xy = _mm256_cmp_ps(x0, y0, _CMP_GE_OQ);
		__m256 yz = _mm256_cmp_ps(y0, z0, _CMP_GE_OQ);
		__m256 xz = _mm256_cmp_ps(x0, z0, _CMP_GE_OQ);
		__m256 i1 = _mm256_and_ps(xy, xz);
		__m256 j1 = _mm256_andnot_ps(xy, yz);
		__m256 k1n = _mm256_or_ps(xz, yz); /* k1 = !k1n */
		__m256 i2 = _mm256_or_ps(xy, xz);
		__m256 j2n = _mm256_andnot_ps(yz, xy); /* j2 = !j2n */
		__m256 k2n = _mm256_and_ps(xz, yz);    /* k2 = !k2n */
		__m256 x1 = _mm256_add_ps(_mm256_sub_ps(x0, _mm256_and_ps(i1, one)), G3);
		__m256 y1 = _mm256_add_ps(_mm256_sub_ps(y0, _mm256_and_ps(j1, one)), G3);
		__m256 z1 = _mm256_add_ps(_mm256_sub_ps(z0, _mm256_andnot_ps(k1n, one)), G3);
		__m256 x2 = _mm256_add_ps(_mm256_sub_ps(x0, _mm256_and_ps(i2, one)), G3x2);
		__m256 y2 = _mm256_add_ps(_mm256_sub_ps(y0, _mm256_andnot_ps(j2n, one)), G3x2);
		__m256 z2 = _mm256_add_ps(_mm256_sub_ps(z0, _mm256_andnot_ps(k2n, one)), G3x2);
		__m256 x3 = _mm256_add_ps(_mm256_sub_ps(x0, one), G3x3);
		__m256 y3 = _mm256_add_ps(_mm256_sub_ps(y0, one), G3x3);
		__m256 z3 = _mm256_add_ps(_mm256_sub_ps(z0, one), G3x3);
		__m256i hx = _mm256_add_epi32(ohx, _mm256_mullo_epi32(_mm256_cvttps_epi32(fi), PX));
		__m256i hy = _mm256_add_epi32(ohy, _mm256_mullo_epi32(_mm256_cvttps_epi32(fj), PY));
		__m256i hz = _mm256_add_epi32(ohz, _mm256_mullo_epi32(_mm256_cvttps_epi32(fk), PZ));
		__m256 n0 = corner(hash3(seed, hx, hy, hz), x0, y0, z0);
		__m256i h1 = hash3(
			seed, _mm256_add_epi32(hx, _mm256_and_si256(_mm256_castps_si256(i1), PX)),
			_mm256_add_epi32(hy, _mm256_and_si256(_mm256_castps_si256(j1), PY)),
			_mm256_add_epi32(hz, _mm256_andnot_si256(_mm256_castps_si256(k1n), PZ)));
		__m256 n1 = corner(h1, x1, y1, z1);
		__m256i h2 = hash3(
			seed, _mm256_add_epi32(hx, _mm256_and_si256(_mm256_castps_si256(i2), PX)),
			_mm256_add_epi32(hy, _mm256_andnot_si256(_mm256_castps_si256(j2n), PY)),
			_mm256_add_epi32(hz, _mm256_andnot_si256(_mm256_castps_si256(k2n), PZ)));
		__m256 n2 = corner(h2, x2, y2, z2);
		__m256i h3 = hash3(seed, _mm256_add_epi32(hx, PX), _mm256_add_epi32(hy, PY),
				   _mm256_add_epi32(hz, PZ));
		__m256 n3 = corner(h3, x3, y3, z3);
		__m256 sum = _mm256_add_ps(_mm256_add_ps(_mm256_add_ps(n0, n1), n2), n3);
		_mm256_storeu_ps(out + i, _mm256_mul_ps(sum, _mm256_set1_ps(NOISE_SCALE)));
	}
}
