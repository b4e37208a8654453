/* noise_avx512 — the simplex row kernel, 16 texels per vector (AVX-512 F/DQ/BW/VL). It
 * mirrors noise_row_scalar (noise.c) operation for operation, so both give the same bits; keep
 * them in step. Compiled with the AVX-512 flags; called only when the CPU has them.
 * Thread-safe (pure).
 */
#include <immintrin.h>

#include "noise.h"
#include "noise_sums.h"

const struct noise_sums noise_sums_avx512 = NOISE_SUMS_INIT;

static inline __m512 corner(__m512i h, __m512 x, __m512 y, __m512 z)
{
	h = _mm512_mullo_epi32(h, _mm512_set1_epi32((int)NOISE_HMUL));
	__m512i g = _mm512_srli_epi32(h, 28);
	__mmask16 lt8 = _mm512_cmplt_epu32_mask(g, _mm512_set1_epi32(8));
	__mmask16 lt4 = _mm512_cmplt_epu32_mask(g, _mm512_set1_epi32(4));
	__mmask16 is12 = _mm512_cmpeq_epi32_mask(_mm512_and_si512(g, _mm512_set1_epi32(13)),
						 _mm512_set1_epi32(12));
	__m512 u = _mm512_mask_blend_ps(lt8, y, x);
	__m512 v = _mm512_mask_blend_ps(lt4, _mm512_mask_blend_ps(is12, z, x), y);
	__m512 su = _mm512_xor_ps(u, _mm512_castsi512_ps(_mm512_slli_epi32(g, 31)));
	__m512 sv = _mm512_xor_ps(v, _mm512_castsi512_ps(_mm512_slli_epi32(
					     _mm512_and_si512(g, _mm512_set1_epi32(2)), 30)));
	__m512 grad = _mm512_add_ps(su, sv);
	__m512 t = _mm512_fnmadd_ps(x, x, _mm512_set1_ps(0.5f));
	t = _mm512_fnmadd_ps(y, y, t);
	t = _mm512_fnmadd_ps(z, z, t);
	t = _mm512_max_ps(t, _mm512_setzero_ps());
	__m512 t2 = _mm512_mul_ps(t, t);
	__m512 t4 = _mm512_mul_ps(t2, t2);
	return _mm512_mul_ps(t4, grad);
}

static inline __m512i hash3(__m512i seed, __m512i hx, __m512i hy, __m512i hz)
{
	/* 0x96 = a ^ b ^ c */
	return _mm512_xor_si512(seed, _mm512_ternarylogic_epi32(hx, hy, hz, 0x96));
}

void noise_row_avx512(const struct noise_row *o, const float *dx, const float *dy,
		      const float *dz, float *out, uint32_t n)
{
	const __m512 f = _mm512_set1_ps(o->f), cx = _mm512_set1_ps(o->cx),
		     cy = _mm512_set1_ps(o->cy), cz = _mm512_set1_ps(o->cz);
	const __m512 F3 = _mm512_set1_ps(NOISE_F3), G3 = _mm512_set1_ps(NOISE_G3),
		     G3x2 = _mm512_set1_ps(2.0f * NOISE_G3), G3x3 = _mm512_set1_ps(3.0f * NOISE_G3);
	const __m512 one = _mm512_set1_ps(1.0f);
	const __m512i PX = _mm512_set1_epi32((int)NOISE_PX), PY = _mm512_set1_epi32((int)NOISE_PY),
		      PZ = _mm512_set1_epi32((int)NOISE_PZ);
	const __m512i ohx = _mm512_set1_epi32((int)o->hx), ohy = _mm512_set1_epi32((int)o->hy),
		      ohz = _mm512_set1_epi32((int)o->hz), seed = _mm512_set1_epi32((int)o->seed);
	for (uint32_t i = 0; i < n; i += 16) {
		__m512 x = _mm512_fmadd_ps(_mm512_loadu_ps(dx + i), f, cx);
		__m512 y = _mm512_fmadd_ps(_mm512_loadu_ps(dy + i), f, cy);
		__m512 z = _mm512_fmadd_ps(_mm512_loadu_ps(dz + i), f, cz);
		__m512 s = _mm512_mul_ps(_mm512_add_ps(_mm512_add_ps(x, y), z), F3);
		__m512 fi = _mm512_roundscale_ps(_mm512_add_ps(x, s), _MM_FROUND_TO_NEG_INF);
		__m512 fj = _mm512_roundscale_ps(_mm512_add_ps(y, s), _MM_FROUND_TO_NEG_INF);
		__m512 fk = _mm512_roundscale_ps(_mm512_add_ps(z, s), _MM_FROUND_TO_NEG_INF);
		__m512 t = _mm512_mul_ps(_mm512_add_ps(_mm512_add_ps(fi, fj), fk), G3);
		__m512 x0 = _mm512_add_ps(_mm512_sub_ps(x, fi), t);
		__m512 y0 = _mm512_add_ps(_mm512_sub_ps(y, fj), t);
		__m512 z0 = _mm512_add_ps(_mm512_sub_ps(z, fk), t);
		__mmask16 xy = _mm512_cmp_ps_mask(x0, y0, _CMP_GE_OQ);
		__mmask16 yz = _mm512_cmp_ps_mask(y0, z0, _CMP_GE_OQ);
		__mmask16 xz = _mm512_cmp_ps_mask(x0, z0, _CMP_GE_OQ);
		__mmask16 i1 = xy & xz, j1 = (__mmask16)(~xy & yz), k1 = (__mmask16)~(xz | yz);
		__mmask16 i2 = xy | xz, j2 = (__mmask16)(~xy | yz), k2 = (__mmask16)~(xz & yz);
		/* x − 0 = x exactly, so a masked subtract equals the scalar x − (m ? 1 : 0). */
		__m512 x1 = _mm512_add_ps(_mm512_mask_sub_ps(x0, i1, x0, one), G3);
		__m512 y1 = _mm512_add_ps(_mm512_mask_sub_ps(y0, j1, y0, one), G3);
		__m512 z1 = _mm512_add_ps(_mm512_mask_sub_ps(z0, k1, z0, one), G3);
		__m512 x2 = _mm512_add_ps(_mm512_mask_sub_ps(x0, i2, x0, one), G3x2);
		__m512 y2 = _mm512_add_ps(_mm512_mask_sub_ps(y0, j2, y0, one), G3x2);
		__m512 z2 = _mm512_add_ps(_mm512_mask_sub_ps(z0, k2, z0, one), G3x2);
		__m512 x3 = _mm512_add_ps(_mm512_sub_ps(x0, one), G3x3);
		__m512 y3 = _mm512_add_ps(_mm512_sub_ps(y0, one), G3x3);
		__m512 z3 = _mm512_add_ps(_mm512_sub_ps(z0, one), G3x3);
		__m512i hx = _mm512_add_epi32(ohx, _mm512_mullo_epi32(_mm512_cvttps_epi32(fi), PX));
		__m512i hy = _mm512_add_epi32(ohy, _mm512_mullo_epi32(_mm512_cvttps_epi32(fj), PY));
		__m512i hz = _mm512_add_epi32(ohz, _mm512_mullo_epi32(_mm512_cvttps_epi32(fk), PZ));
		__m512 n0 = corner(hash3(seed, hx, hy, hz), x0, y0, z0);
		__m512 n1 = corner(hash3(seed, _mm512_mask_add_epi32(hx, i1, hx, PX),
					 _mm512_mask_add_epi32(hy, j1, hy, PY),
					 _mm512_mask_add_epi32(hz, k1, hz, PZ)),
				   x1, y1, z1);
		__m512 n2 = corner(hash3(seed, _mm512_mask_add_epi32(hx, i2, hx, PX),
					 _mm512_mask_add_epi32(hy, j2, hy, PY),
					 _mm512_mask_add_epi32(hz, k2, hz, PZ)),
				   x2, y2, z2);
		__m512 n3 = corner(hash3(seed, _mm512_add_epi32(hx, PX), _mm512_add_epi32(hy, PY),
					 _mm512_add_epi32(hz, PZ)),
				   x3, y3, z3);
		__m512 sum = _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(n0, n1), n2), n3);
		_mm512_storeu_ps(out + i, _mm512_mul_ps(sum, _mm512_set1_ps(NOISE_SCALE)));
	}
}
