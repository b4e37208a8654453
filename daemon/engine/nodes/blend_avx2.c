/* blend_avx2 — node_blend's multiply on colours eight texels at a time. The arithmetic is
 * blend_bytes's step for step (the mask's weight clamped to [0, 1] with NaN as 0, times the
 * opacity; rgb = x + (x·y/255 − x)·w rounded by + 0.5 and truncation; alpha kept), with no
 * fused multiply-add (ISO C mode: no contraction), so the bytes match it.
 * Thread-safety: reads its arguments only. */
#include <immintrin.h>

#include "blend_kernels.h"

void blend_multiply_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
			 uint8_t *o, size_t count)
{
	const __m256i lo8 = _mm256_set1_epi32(0xff), alpha = _mm256_set1_epi32((int)0xff000000u);
	const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1);
	const __m256 op = _mm256_set1_ps(opacity), k = _mm256_set1_ps(1.0f / 255);
	const __m256 half = _mm256_set1_ps(0.5f);
	for (size_t i = 0; i < count; i += 8) {
		__m256i xa = _mm256_loadu_si256((const __m256i *)(const void *)(a + 4 * i));
		__m256i yb = _mm256_loadu_si256((const __m256i *)(const void *)(b + 4 * i));
		__m256 w = op;
		if (mask) {
			__m256 m = _mm256_loadu_ps(mask + i);
			m = _mm256_max_ps(m, zero); /* m > 0 ? m : 0 (NaN → 0) */
			m = _mm256_min_ps(m, one);  /* m < 1 ? m : 1 */
			w = _mm256_mul_ps(m, op);
		}
		__m256i px = _mm256_and_si256(xa, alpha);
		for (int c = 0; c < 3; c++) {
			__m256 x = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(xa, 8 * c), lo8));
			__m256 y = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(yb, 8 * c), lo8));
			__m256 prod = _mm256_mul_ps(_mm256_mul_ps(x, y), k);
			__m256 v = _mm256_add_ps(_mm256_add_ps(x, _mm256_mul_ps(_mm256_sub_ps(prod, x), w)),
						 half);
			__m256i q = _mm256_and_si256(_mm256_cvttps_epi32(v), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * c));
		}
		_mm256_storeu_si256((__m256i *)(void *)(o + 4 * i), px);
	}
}
