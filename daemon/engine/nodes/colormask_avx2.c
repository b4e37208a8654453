/* colormask_avx2 — node_colormask's texel loop eight texels at a time. The arithmetic is
 * cm_texel's step for step (integer channels to float, squared distances summed in the same
 * order, the least of them, the two thresholds, a correctly rounded square root, the
 * smoothstep), with no fused multiply-add (ISO C mode: no contraction), so the bytes match it.
 * Thread-safety: reads its arguments only. */
#include <immintrin.h>
#include <math.h>

#include "colormask.h"

bool color_mask_avx2(const struct color_mask *m, const uint8_t *src, float *dst, size_t count)
{
	const __m256 near2 = _mm256_set1_ps(m->near2), far2 = _mm256_set1_ps(m->far2);
	const __m256 nearv = _mm256_set1_ps(m->near), inv = _mm256_set1_ps(m->inv);
	const __m256 one = _mm256_set1_ps(1), two = _mm256_set1_ps(2), three = _mm256_set1_ps(3);
	const __m256 zero = _mm256_setzero_ps();
	const __m256i lo8 = _mm256_set1_epi32(0xff);
	__m256 any = zero;
	for (size_t i = 0; i < count; i += 8) {
		__m256i px = _mm256_loadu_si256((const __m256i *)(const void *)(src + 4 * i));
		__m256 r = _mm256_cvtepi32_ps(_mm256_and_si256(px, lo8));
		__m256 g = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(px, 8), lo8));
		__m256 b = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(px, 16), lo8));
		__m256 best = _mm256_set1_ps(INFINITY);
		for (int k = 0; k < m->n; k++) {
			__m256 dr = _mm256_sub_ps(r, _mm256_set1_ps(m->ref[k][0]));
			__m256 dg = _mm256_sub_ps(g, _mm256_set1_ps(m->ref[k][1]));
			__m256 db = _mm256_sub_ps(b, _mm256_set1_ps(m->ref[k][2]));
			__m256 d2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dr, dr),
								_mm256_mul_ps(dg, dg)),
						  _mm256_mul_ps(db, db));
			best = _mm256_min_ps(d2, best); /* d2 < best ? d2 : best */
		}
		__m256 t = _mm256_mul_ps(_mm256_sub_ps(_mm256_sqrt_ps(best), nearv), inv);
		__m256 v = _mm256_sub_ps(one, _mm256_mul_ps(_mm256_mul_ps(t, t),
							    _mm256_sub_ps(three, _mm256_mul_ps(two, t))));
		v = _mm256_blendv_ps(v, zero, _mm256_cmp_ps(best, far2, _CMP_GE_OQ));
		v = _mm256_blendv_ps(v, one, _mm256_cmp_ps(best, near2, _CMP_LE_OQ));
		any = _mm256_or_ps(any, v);
		_mm256_storeu_ps(dst + i, v);
	}
	return !_mm256_testz_si256(_mm256_castps_si256(any), _mm256_castps_si256(any));
}
