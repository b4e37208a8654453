/* ramp_avx2 — node_ramp's base ramp, its steep blend and its snow, eight texels at a time
 * (AVX2 gathers). The arithmetic is the scalar loops', step for step (clamp, bin, segment
 * walk, c + t·dc, + 0.5, truncate, saturate; the steep weight's clamps as max/min in the
 * scalar's operand order), with no fused multiply-add (ISO C mode: no contraction), so the
 * bytes match them. Thread-safety: reads its arguments only. */
#include <immintrin.h>
#include <stdbool.h>

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

/* The segments of table r holding eight heights hc (within its ends, no NaN), and in *t the
 * metres into them: ramp_segment_of's bin and walk, gathered. */
static inline __m256i seg8(const struct ramp_table *r, __m256 hc, __m256 *t)
{
	const __m256 h0 = _mm256_set1_ps(r->h[0]), inv_bin = _mm256_set1_ps(r->inv_bin);
	const __m256i last_bin = _mm256_set1_epi32(RAMP_BINS - 1), one = _mm256_set1_epi32(1);
	__m256i b = _mm256_cvttps_epi32(_mm256_mul_ps(_mm256_sub_ps(hc, h0), inv_bin));
	b = _mm256_min_epi32(b, last_bin);
	__m256i s = _mm256_and_si256(
		_mm256_i32gather_epi32((const int *)(const void *)r->bin_seg, b, 1),
		_mm256_set1_epi32(0xff));
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
	*t = _mm256_sub_ps(hc, hs);
	return s;
}

/* Channel ch of table r's colour at segments s, t metres in: c + t·dc. */
static inline __m256 colour8(const struct ramp_table *r, __m256i s, __m256 t, int ch)
{
	__m256i idx = _mm256_add_epi32(_mm256_slli_epi32(s, 2), _mm256_set1_epi32(ch));
	return _mm256_add_ps(_mm256_i32gather_ps(&r->c[0][0], idx, 4),
			     _mm256_mul_ps(t, _mm256_i32gather_ps(&r->dc[0][0], idx, 4)));
}

/* x clamped to table r's ends as the scalar does it (h < h0 ? h0 : h > hl ? hl : h; a −0 made
 * +0 here only adds ±0), NaN lanes set to h0 (any valid segment: their result is discarded). */
static inline __m256 clamp8(const struct ramp_table *r, __m256 x, __m256 nan)
{
	__m256 hc = _mm256_min_ps(_mm256_max_ps(x, _mm256_set1_ps(r->h[0])),
				  _mm256_set1_ps(r->h[r->nstops - 1]));
	return _mm256_blendv_ps(hc, _mm256_set1_ps(r->h[0]), nan);
}

/* A table of at most REG_STOPS stops (every shipped planet's ramps) held in registers: a
 * texel's segment by comparisons — s = #{k ≥ 1 : hc ≥ h[k]}, the one s with h[s] ≤ hc <
 * h[s + 1] since the stops increase — and the segment's start, colour and slope by permutes:
 * no gathers and no scalar lookup, whatever segments the eight texels fall in. The same
 * values as seg8 and colour8. */
#define REG_STOPS 32
#define REG_N (REG_STOPS / 8)

struct regtab {
	int n, nreg; /* stops; registers of eight segments each */
	__m256 stop[REG_STOPS];
	__m256 h[REG_N], c[3][REG_N], dc[3][REG_N]; /* segments 8q .. 8q + 7 in [q] */
};

static void regtab_init(struct regtab *t, const struct ramp_table *r)
{
	float hv[REG_STOPS], cv[3][REG_STOPS], dv[3][REG_STOPS];
	t->n = r->nstops;
	t->nreg = (r->nstops + 7) / 8;
	for (int s = 0; s < REG_STOPS; s++) {
		hv[s] = s < r->nstops ? r->h[s] : 0;
		for (int ch = 0; ch < 3; ch++) {
			cv[ch][s] = s < r->nstops ? r->c[s][ch] : 0;
			dv[ch][s] = s < r->nstops ? r->dc[s][ch] : 0;
		}
		t->stop[s] = _mm256_set1_ps(r->h[s < r->nstops ? s : 0]);
	}
	for (int q = 0; q < REG_N; q++) {
		t->h[q] = _mm256_loadu_ps(hv + 8 * q);
		for (int ch = 0; ch < 3; ch++) {
			t->c[ch][q] = _mm256_loadu_ps(cv[ch] + 8 * q);
			t->dc[ch][q] = _mm256_loadu_ps(dv[ch] + 8 * q);
		}
	}
}

/* v[s] for segments s: each register's permute (it reads s's low three bits), the one for
 * s's eight taken */
static inline __m256 pick(const struct regtab *t, const __m256 v[REG_N], __m256i s)
{
	__m256 r = _mm256_permutevar8x32_ps(v[0], s);
	for (int q = 1; q < t->nreg; q++)
		r = _mm256_blendv_ps(r, _mm256_permutevar8x32_ps(v[q], s),
				     _mm256_castsi256_ps(_mm256_cmpgt_epi32(s, _mm256_set1_epi32(8 * q - 1))));
	return r;
}

/* The segments of eight heights hc (within the table's ends, no NaN), and in *tt the metres
 * into them. */
static inline __m256i regseg(const struct regtab *t, __m256 hc, __m256 *tt)
{
	__m256i s = _mm256_setzero_si256();
	for (int k = 1; k < t->n; k++) /* a true compare is −1 */
		s = _mm256_sub_epi32(s, _mm256_castps_si256(_mm256_cmp_ps(hc, t->stop[k], _CMP_GE_OQ)));
	*tt = _mm256_sub_ps(hc, pick(t, t->h, s));
	return s;
}

/* Channel ch at segments s, tt metres in: c + tt·dc (colour8's value). */
static inline __m256 regcolour(const struct regtab *t, __m256i s, __m256 tt, int ch)
{
	return _mm256_add_ps(pick(t, t->c[ch], s), _mm256_mul_ps(tt, pick(t, t->dc[ch], s)));
}

static void ramp_base_reg(const struct ramp_table *r, const float *h, uint8_t *d, size_t count)
{
	const __m256 half = _mm256_set1_ps(0.5f);
	const __m256i lo8 = _mm256_set1_epi32(0xff), zero = _mm256_setzero_si256();
	struct regtab t;
	regtab_init(&t, r);
	for (size_t i = 0; i < count; i += 8) {
		__m256 x = _mm256_loadu_ps(h + i);
		__m256 nan = _mm256_cmp_ps(x, x, _CMP_UNORD_Q);
		__m256 tt;
		__m256i s = regseg(&t, clamp8(r, x, nan), &tt);
		__m256i px = _mm256_set1_epi32((int)0xff000000u);
		for (int ch = 0; ch < 3; ch++) {
			__m256 v = _mm256_add_ps(regcolour(&t, s, tt, ch), half);
			__m256i q = _mm256_cvttps_epi32(v);
			q = _mm256_min_epi32(_mm256_max_epi32(q, zero), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
		}
		px = _mm256_andnot_si256(_mm256_castps_si256(nan), px);
		_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
	}
}

void ramp_base_avx2(const struct ramp_table *r, const float *h, uint8_t *d, size_t count)
{
	if (r->nstops <= REG_STOPS) {
		ramp_base_reg(r, h, d, count);
		return;
	}
	const __m256 half = _mm256_set1_ps(0.5f);
	const __m256i lo8 = _mm256_set1_epi32(0xff), zero = _mm256_setzero_si256();
	const __m256i alpha = _mm256_set1_epi32((int)0xff000000u);
	for (size_t i = 0; i < count; i += 8) {
		__m256 x = _mm256_loadu_ps(h + i);
		__m256 nan = _mm256_cmp_ps(x, x, _CMP_UNORD_Q);
		__m256 hc = clamp8(r, x, nan);
		/* Neighbours nearly always share a segment: then no gathers at all. */
		float lo = hmin8(hc), hi = hmax8(hc);
		int s0 = ramp_segment_of(r, lo);
		if (hi < r->h[s0 + 1]) {
			__m256i px = _mm256_andnot_si256(_mm256_castps_si256(nan),
							 one_segment(r, s0, hc));
			_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
			continue;
		}
		__m256 t;
		__m256i s = seg8(r, hc, &t), px = alpha;
		for (int ch = 0; ch < 3; ch++) {
			__m256 v = _mm256_add_ps(colour8(r, s, t, ch), half);
			__m256i q = _mm256_cvttps_epi32(v);
			q = _mm256_min_epi32(_mm256_max_epi32(q, zero), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
		}
		px = _mm256_andnot_si256(_mm256_castps_si256(nan), px);
		_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
	}
}

/* The steep weight of eight slopes: max((slope − from)·inv, 0) then min(·, 1), NaN → 0 (the
 * scalar's w > 0 ? w : 0 and w < 1 ? w : 1). */
static inline __m256 weight8(float from, float inv, __m256 slope)
{
	__m256 w = _mm256_mul_ps(_mm256_sub_ps(slope, _mm256_set1_ps(from)), _mm256_set1_ps(inv));
	w = _mm256_max_ps(w, _mm256_setzero_ps());
	return _mm256_min_ps(w, _mm256_set1_ps(1.0f));
}

void ramp_steep_avx2(const struct ramp_steep *r, const float *h, const float *slope, uint8_t *d,
		     size_t count)
{
	const __m256 half = _mm256_set1_ps(0.5f), zero = _mm256_setzero_ps();
	const __m256i lo8 = _mm256_set1_epi32(0xff);
	const __m256i alpha = _mm256_set1_epi32((int)0xff000000u);
	const bool reg = r->base->nstops <= REG_STOPS && r->steep->nstops <= REG_STOPS;
	struct regtab ra, rb;
	if (reg) {
		regtab_init(&ra, r->base);
		regtab_init(&rb, r->steep);
	}
	for (size_t i = 0; i < count; i += 8) {
		__m256 w = weight8(r->from, r->inv, _mm256_loadu_ps(slope + i));
		__m256 x = _mm256_loadu_ps(h + i);
		__m256 nan = _mm256_cmp_ps(x, x, _CMP_UNORD_Q);
		__m256 on = _mm256_andnot_ps(nan, _mm256_cmp_ps(w, zero, _CMP_GT_OQ));
		if (_mm256_testz_ps(on, on))
			continue; /* most of a tile: not steep */
		__m256 ta, tb;
		__m256i sa, sb;
		if (reg) {
			sa = regseg(&ra, clamp8(r->base, x, nan), &ta);
			sb = regseg(&rb, clamp8(r->steep, x, nan), &tb);
		} else {
			sa = seg8(r->base, clamp8(r->base, x, nan), &ta);
			sb = seg8(r->steep, clamp8(r->steep, x, nan), &tb);
		}
		__m256i px = alpha;
		for (int ch = 0; ch < 3; ch++) {
			__m256 a = reg ? regcolour(&ra, sa, ta, ch) : colour8(r->base, sa, ta, ch);
			__m256 b = reg ? regcolour(&rb, sb, tb, ch) : colour8(r->steep, sb, tb, ch);
			__m256 v = _mm256_add_ps(_mm256_add_ps(a, _mm256_mul_ps(_mm256_sub_ps(b, a), w)),
						 half);
			__m256i q = _mm256_and_si256(_mm256_cvttps_epi32(v), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
		}
		__m256i old = _mm256_loadu_si256((const __m256i *)(const void *)(d + 4 * i));
		px = _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(old),
							  _mm256_castsi256_ps(px), on));
		_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
	}
}

void ramp_snow_avx2(const struct ramp_snow *s, const float *h, const float *slope, uint8_t *d,
		    size_t n)
{
	const __m256 line = _mm256_set1_ps(s->line), inv = _mm256_set1_ps(s->inv);
	const __m256 ice = _mm256_set1_ps(s->ice), zero = _mm256_setzero_ps();
	const __m256 one = _mm256_set1_ps(1.0f), half = _mm256_set1_ps(0.5f);
	const __m256 four = _mm256_set1_ps(4.0f), k6000 = _mm256_set1_ps(6000.0f);
	const __m256i lo8 = _mm256_set1_epi32(0xff);
	const __m256i alpha = _mm256_set1_epi32((int)0xff000000u);
	for (size_t i = 0; i < n; i += 8) {
		__m256 x = _mm256_loadu_ps(h + i);
		__m256 t = _mm256_mul_ps(_mm256_sub_ps(x, line), inv);
		if (s->sea_ice) {
			__m256 neg = _mm256_cmp_ps(x, zero, _CMP_LT_OQ);
			__m256 ti = _mm256_add_ps(ice, _mm256_blendv_ps(zero, _mm256_div_ps(x, k6000),
									 neg));
			t = _mm256_blendv_ps(t, _mm256_mul_ps(ti, four),
					     _mm256_cmp_ps(ti, t, _CMP_GT_OQ));
		}
		__m256 on = _mm256_cmp_ps(t, zero, _CMP_GT_OQ);
		if (_mm256_testz_ps(on, on))
			continue;
		t = _mm256_min_ps(t, one); /* t > 0 here: the scalar's t > 1 ? 1 : t */
		if (slope)
			t = _mm256_mul_ps(t, _mm256_sub_ps(one, weight8(s->from, s->inv_steep,
									 _mm256_loadu_ps(slope + i))));
		__m256i old = _mm256_loadu_si256((const __m256i *)(const void *)(d + 4 * i));
		__m256i px = _mm256_and_si256(old, alpha);
		for (int ch = 0; ch < 3; ch++) {
			__m256 c = _mm256_cvtepi32_ps(
				_mm256_and_si256(_mm256_srli_epi32(old, 8 * ch), lo8));
			__m256 v = _mm256_add_ps(c, _mm256_mul_ps(_mm256_sub_ps(_mm256_set1_ps(s->snow[ch]),
										 c), t));
			__m256i q = _mm256_and_si256(_mm256_cvttps_epi32(_mm256_add_ps(v, half)), lo8);
			px = _mm256_or_si256(px, _mm256_slli_epi32(q, 8 * ch));
		}
		px = _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(old),
							  _mm256_castsi256_ps(px), on));
		_mm256_storeu_si256((__m256i *)(void *)(d + 4 * i), px);
	}
}
