/* ramp_avx2 — node_ramp's base ramp, eight texels at a time (AVX2 gathers). The arithmetic is
 * the scalar loop's, step for step (clamp, bin, segment walk, c + t·dc, + 0.5, truncate,
 * saturate), with no fused multiply-add (ISO C mode: no contraction), so the bytes match it.
 * Thread-safety: reads its arguments only. */
#include <immintrin.h>

#include "node_ramp.h"

static inline float hmin8(__m256 v)
{
	__m128 m = _mm_min_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
	m = _mm_min_ps(m, _mm_movehl_ps(m, m));
	m = _mm_min_ss(m, _mm_shuffle_ps(m, m, 1));
	return _mm_cvtss_f32(m);
}

static inline float hmax8(__m256 v)
{
	__m128 m = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
	m = _mm_max_ps(m, _mm_movehl_ps(m, m));
	m = _mm_max_ss(m, _mm_shuffle_ps(m, m, 1));
	return _mm_cvtss_f32(m);
}


/* Eight texels of one segment s: the colours from broadcasts, no gathers. */
static inline __m256i one_segment(const struct ramp_table *r, int s, __m256 hc)
{
	const __m256 half = _mm256_set1_ps(0.5f);
	const __m256i zero = _mm256_setzero_si256(), lo8 = _mm256_set1_epi32(0xff);
	__m256 t = _mm256_sub_ps(hc, _mm256_set1_ps(r->h[s]));
	__m256i px = _mm256_set1_epi32((int)0xff000000u);
	for (int ch = 0; ch < 3; ch++) {
		__m256 v = _mm256_add_ps(_mm256_add_ps(_mm256_set1_ps(r->c[s][ch]),
						       _mm256_mul_ps(t, _mm256_set1_ps(r->dc[s][ch]))),
					 half);
		__m256i q = _mm256_cvttps_epi32(v);
		q = _mm256_min_epi32(_mm256_max_epi32(q, zero), lo8);
		px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
	}
	return px;
}

void ramp_base_avx2(const struct ramp_table *r, const float *h, uint8_t *d, size_t count)
{
	const __m256 h0 = _mm256_set1_ps(r->h[0]), hl = _mm256_set1_ps(r->h[r->nstops - 1]);
	const __m256 inv_bin = _mm256_set1_ps(r->inv_bin), half = _mm256_set1_ps(0.5f);
	const __m256i last_bin = _mm256_set1_epi32(RAMP_BINS - 1), one = _mm256_set1_epi32(1);
	const __m256i lo8 = _mm256_set1_epi32(0xff), zero = _mm256_setzero_si256();
	const __m256i alpha = _mm256_set1_epi32((int)0xff000000u);
	const float *c = &r->c[0][0], *dc = &r->dc[0][0];
	for (size_t i = 0; i < count; i += 8) {
		__m256 x = _mm256_loadu_ps(h + i);
		__m256 nan = _mm256_cmp_ps(x, x, _CMP_UNORD_Q);
		/* the scalar's h < h0 ? h0 : h > hl ? hl : h (a −0 made +0 here only adds ±0) */
		__m256 hc = _mm256_min_ps(_mm256_max_ps(x, h0), hl);
		hc = _mm256_blendv_ps(hc, h0, nan); /* NaN lanes: any valid segment, cleared below */
		/* Neighbours nearly always share a segment: then no gathers at all. */
		float lo = hmin8(hc), hi = hmax8(hc);
		int s0 = ramp_segment_of(r, lo);
		if (hi < r->h[s0 + 1]) {
			__m256i px = _mm256_andnot_si256(_mm256_castps_si256(nan),
							 one_segment(r, s0, hc));
			_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
			continue;
		}
		__m256i b = _mm256_cvttps_epi32(_mm256_mul_ps(_mm256_sub_ps(hc, h0), inv_bin));
		b = _mm256_min_epi32(b, last_bin);
		__m256i s = _mm256_and_si256(
			_mm256_i32gather_epi32((const int *)(const void *)r->bin_seg, b, 1), lo8);
		for (;;) { /* the bin holds a stop */
			__m256 hn = _mm256_i32gather_ps(r->h, _mm256_add_epi32(s, one), 4);
			__m256i up = _mm256_castps_si256(_mm256_cmp_ps(hc, hn, _CMP_GE_OQ));
			if (_mm256_testz_si256(up, up))
				break;
			s = _mm256_sub_epi32(s, up);
		}
		__m256 hs;
		for (;;) { /* rounding put h just below the bin's start */
			hs = _mm256_i32gather_ps(r->h, s, 4);
			__m256i down = _mm256_castps_si256(_mm256_cmp_ps(hc, hs, _CMP_LT_OQ));
			if (_mm256_testz_si256(down, down))
				break;
			s = _mm256_add_epi32(s, down);
		}
		__m256 t = _mm256_sub_ps(hc, hs);
		__m256i s4 = _mm256_slli_epi32(s, 2), px = alpha;
		for (int ch = 0; ch < 3; ch++) {
			__m256i idx = _mm256_add_epi32(s4, _mm256_set1_epi32(ch));
			__m256 v = _mm256_add_ps(
				_mm256_add_ps(_mm256_i32gather_ps(c, idx, 4),
					      _mm256_mul_ps(t, _mm256_i32gather_ps(dc, idx, 4))),
				half);
			__m256i q = _mm256_cvttps_epi32(v);
			q = _mm256_min_epi32(_mm256_max_epi32(q, zero), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
		}
		px = _mm256_andnot_si256(_mm256_castps_si256(nan), px);
		_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
	}
}
