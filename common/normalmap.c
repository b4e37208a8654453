/* normalmap — see normalmap.h. */
#include "normalmap.h"

#ifdef __SSE2__
#include <emmintrin.h>
#endif

uint32_t normalmap_east_stencil(double r, double dlam, double dy, uint32_t kmax, double *len)
{
	double dx = r * dlam;
	uint32_t k = 1;
	if (dy >= 8 * dx) {
		double kk = floor(dy / (4 * dx));
		k = kk < kmax ? (uint32_t)kk : kmax;
	}
	*len = k == 1 ? 2 * dx : 2 * r * sin(k * dlam);
	return k;
}

static void row_scalar(const float *restrict we, const float *restrict ea,
		       const float *restrict up, const float *restrict dn, float fx, float fy,
		       uint8_t *restrict out, uint32_t from, uint32_t T)
{
	for (uint32_t i = from; i < T; i++)
		normalmap_texel(we[i], ea[i], up[i], dn[i], fx, fy, out + 2 * i);
}

#ifdef __SSE2__
/* The same arithmetic, 8 texels at a time (SSE2 is baseline on x86-64; results are identical
 * to the scalar code: sqrt and division are correctly rounded in both). */
void normalmap_row(const float *restrict we, const float *restrict ea, const float *restrict up,
		   const float *restrict dn, float fx, float fy, uint8_t *restrict out, uint32_t T)
{
	const __m128 vfx = _mm_set1_ps(fx), vfy = _mm_set1_ps(fy), one = _mm_set1_ps(1.0f);
	const __m128 k = _mm_set1_ps(-127.5f), bias = _mm_set1_ps(128.0f);
	uint32_t i = 0;
	for (; i + 8 <= T; i += 8) {
		__m128i e[2], nn[2];
		for (int h = 0; h < 2; h++) {
			uint32_t o = i + 4 * (uint32_t)h;
			__m128 gx = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(ea + o),
							  _mm_loadu_ps(we + o)), vfx);
			__m128 gy = _mm_mul_ps(_mm_sub_ps(_mm_loadu_ps(up + o), _mm_loadu_ps(dn + o)),
					       vfy);
			gx = _mm_and_ps(gx, _mm_cmpord_ps(gx, gx));
			gy = _mm_and_ps(gy, _mm_cmpord_ps(gy, gy));
			__m128 s = _mm_add_ps(_mm_add_ps(_mm_mul_ps(gx, gx), _mm_mul_ps(gy, gy)), one);
			__m128 inv = _mm_div_ps(one, _mm_sqrt_ps(s));
			e[h] = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(_mm_mul_ps(gx, inv), k), bias));
			nn[h] = _mm_cvttps_epi32(_mm_add_ps(_mm_mul_ps(_mm_mul_ps(gy, inv), k), bias));
		}
		__m128i eb = _mm_packs_epi32(e[0], e[1]), nb = _mm_packs_epi32(nn[0], nn[1]);
		eb = _mm_packus_epi16(eb, eb);
		nb = _mm_packus_epi16(nb, nb);
		_mm_storeu_si128((__m128i *)(void *)(out + 2 * i), _mm_unpacklo_epi8(eb, nb));
	}
	row_scalar(we, ea, up, dn, fx, fy, out, i, T);
}
#else
void normalmap_row(const float *restrict we, const float *restrict ea, const float *restrict up,
		   const float *restrict dn, float fx, float fy, uint8_t *restrict out, uint32_t T)
{
	row_scalar(we, ea, up, dn, fx, fy, out, 0, T);
}
#endif

