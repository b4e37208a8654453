/* blend_avx2 — node_blend's modes eight texels at a time. The arithmetic is blend_heights's
 * and blend_bytes's step for step (the mask's weight clamped to [0, 1] with NaN as 0, times
 * the opacity; the same products and sums in the same order), with no fused multiply-add (ISO
 * C mode: no contraction) and branches turned into selects, so the bits match the scalar
 * path's.
 * Thread-safety: reads its arguments only. */
#include <immintrin.h>

#include "blend_kernels.h"

/* clamp(mask, 0, 1) · opacity, NaN → 0 (weight_at); opacity without a mask */
static inline __m256 weight8(const float *mask, size_t i, __m256 op)
{
	if (!mask)
		return op;
	__m256 m = _mm256_loadu_ps(mask + i);
	m = _mm256_max_ps(m, _mm256_setzero_ps()); /* m > 0 ? m : 0 (NaN → 0) */
	m = _mm256_min_ps(m, _mm256_set1_ps(1));    /* m < 1 ? m : 1 */
	return _mm256_mul_ps(m, op);
}

void blend_multiply_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
			 uint8_t *o, size_t count)
{
	const __m256i lo8 = _mm256_set1_epi32(0xff), alpha = _mm256_set1_epi32((int)0xff000000u);
	const __m256 op = _mm256_set1_ps(opacity), k = _mm256_set1_ps(1.0f / 255);
	const __m256 half = _mm256_set1_ps(0.5f);
	for (size_t i = 0; i < count; i += 8) {
		__m256i xa = _mm256_loadu_si256((const __m256i *)(const void *)(a + 4 * i));
		__m256i yb = _mm256_loadu_si256((const __m256i *)(const void *)(b + 4 * i));
		__m256 w = weight8(mask, i, op);
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

/* Summary lanes of the texels written: group q = (i / 8) mod 2 of each 16 holds lanes 8q ..
 * 8q + 7; min(v, lo) is v < lo ? v : lo and max(v, hi) v > hi ? v : hi, as tile_summarize. */
struct lanes8 {
	__m256 lo[2], hi[2], nan;
};

static inline void lanes_start(struct lanes8 *z)
{
	for (int q = 0; q < 2; q++) {
		z->lo[q] = _mm256_set1_ps(__builtin_inff());
		z->hi[q] = _mm256_set1_ps(-__builtin_inff());
	}
	z->nan = _mm256_setzero_ps();
}

static inline void lanes_add(struct lanes8 *z, __m256 v, size_t i)
{
	int q = (int)(i >> 3) & 1;
	z->lo[q] = _mm256_min_ps(v, z->lo[q]);
	z->hi[q] = _mm256_max_ps(v, z->hi[q]);
	z->nan = _mm256_or_ps(z->nan, _mm256_cmp_ps(v, v, _CMP_UNORD_Q));
}

static inline void lanes_end(const struct lanes8 *z, struct blend_lanes *out)
{
	for (int q = 0; q < 2; q++) {
		_mm256_storeu_ps(out->lo + 8 * q, z->lo[q]);
		_mm256_storeu_ps(out->hi + 8 * q, z->hi[q]);
	}
	out->nan = _mm256_movemask_ps(z->nan) != 0;
}

void blend_add_avx2(const float *a, const float *b, const float *mask, float opacity,
		    float weight, float *o, size_t count, struct blend_lanes *lanes)
{
	const __m256 op = _mm256_set1_ps(opacity), wt = _mm256_set1_ps(weight);
	const __m256 zero = _mm256_setzero_ps();
	struct lanes8 z;
	lanes_start(&z);
	for (size_t i = 0; i < count; i += 8) {
		__m256 x = _mm256_loadu_ps(a + i), y = _mm256_loadu_ps(b + i);
		__m256 w = weight8(mask, i, op);
		__m256 sum = _mm256_add_ps(x, _mm256_mul_ps(y, _mm256_mul_ps(wt, w)));
		__m256 on = _mm256_cmp_ps(w, zero, _CMP_GT_OQ);
		__m256 r = _mm256_blendv_ps(x, sum, on);
		_mm256_storeu_ps(o + i, r);
		if (lanes)
			lanes_add(&z, r, i);
	}
	if (lanes)
		lanes_end(&z, lanes);
}

void blend_lerp_avx2(const float *a, const float *b, const float *mask, float opacity,
		     float *o, size_t count, struct blend_lanes *lanes)
{
	const __m256 op = _mm256_set1_ps(opacity), zero = _mm256_setzero_ps();
	struct lanes8 z;
	lanes_start(&z);
	for (size_t i = 0; i < count; i += 8) {
		__m256 x = _mm256_loadu_ps(a + i), y = _mm256_loadu_ps(b + i);
		__m256 w = weight8(mask, i, op);
		__m256 lerp = _mm256_add_ps(x, _mm256_mul_ps(_mm256_sub_ps(y, x), w));
		__m256 r = _mm256_blendv_ps(x, lerp, _mm256_cmp_ps(w, zero, _CMP_GT_OQ));
		r = _mm256_blendv_ps(r, y, _mm256_cmp_ps(x, x, _CMP_UNORD_Q)); /* a NaN: b */
		r = _mm256_blendv_ps(r, x, _mm256_cmp_ps(y, y, _CMP_UNORD_Q)); /* b NaN: a */
		_mm256_storeu_ps(o + i, r);
		if (lanes)
			lanes_add(&z, r, i);
	}
	if (lanes)
		lanes_end(&z, lanes);
}

void blend_over_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
		     uint8_t *o, size_t count)
{
	const __m256i lo8 = _mm256_set1_epi32(0xff), alpha = _mm256_set1_epi32((int)0xff000000u);
	const __m256i full = _mm256_set1_epi32(65536), round = _mm256_set1_epi32(32768);
	const __m256 op = _mm256_set1_ps(opacity), k = _mm256_set1_ps(65536.0f / 255);
	const __m256 half = _mm256_set1_ps(0.5f);
	for (size_t i = 0; i < count; i += 8) {
		__m256i xa = _mm256_loadu_si256((const __m256i *)(const void *)(a + 4 * i));
		__m256i yb = _mm256_loadu_si256((const __m256i *)(const void *)(b + 4 * i));
		__m256 w = weight8(mask, i, op);
		if (!_mm256_testc_si256(xa, alpha)) { /* some base texel not opaque */
			float wl[8];
			_mm256_storeu_ps(wl, w);
			for (int j = 0; j < 8; j++) {
				const uint8_t *x = a + 4 * (i + j), *y = b + 4 * (i + j);
				uint8_t *d = o + 4 * (i + j);
				if (x[3] != 255)
					blend_over_general(x, y, wl[j], d);
				else
					blend_over_opaque(x, y, blend_over_kb(y[3], wl[j]), d);
			}
			continue;
		}
		__m256 ya = _mm256_cvtepi32_ps(_mm256_srli_epi32(yb, 24));
		__m256i kb = _mm256_cvttps_epi32(
			_mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(ya, w), k), half));
		__m256i ka = _mm256_sub_epi32(full, kb);
		__m256i px = alpha;
		for (int c = 0; c < 3; c++) {
			__m256i x = _mm256_and_si256(_mm256_srli_epi32(xa, 8 * c), lo8);
			__m256i y = _mm256_and_si256(_mm256_srli_epi32(yb, 8 * c), lo8);
			__m256i v = _mm256_add_epi32(_mm256_add_epi32(_mm256_mullo_epi32(x, ka),
								      _mm256_mullo_epi32(y, kb)),
						     round);
			px = _mm256_or_si256(px, _mm256_slli_epi32(_mm256_srli_epi32(v, 16), 8 * c));
		}
		_mm256_storeu_si256((__m256i *)(void *)(o + 4 * i), px);
	}
}
