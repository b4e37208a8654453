/* node_blend's vector kernels (blend_avx2.c) and the scalar step they share with it. Not a
 * public interface. */
#ifndef CLIPMAP_BLEND_KERNELS_H
#define CLIPMAP_BLEND_KERNELS_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

static inline uint8_t blend_u8(float v)
{
	return (uint8_t)(int)(v + 0.5f); /* v ∈ [0, 255] */
}

/* b over a on one RGBA8 texel, straight alpha, b's alpha scaled by w: the general case (a not
 * opaque), in node_blend's scalar path and the vector kernel's alike. */
static inline void blend_over_general(const uint8_t *x, const uint8_t *y, float w, uint8_t *d)
{
	float ab = y[3] * (w * (1.0f / 255)), aa = x[3] * (1.0f / 255);
	float ao = ab + aa * (1 - ab);
	if (ao <= 0) {
		d[0] = d[1] = d[2] = d[3] = 0;
		return;
	}
	float ka = aa * (1 - ab) / ao, kb = ab / ao;
	for (int c = 0; c < 3; c++)
		d[c] = blend_u8(x[c] * ka + y[c] * kb);
	d[3] = blend_u8(ao * 255);
}

/* b's weight over an opaque base in 1/65536, for b's alpha y3 and weight w (node_blend's
 * table kb[] holds it for w = the opacity). */
static inline uint32_t blend_over_kb(uint8_t y3, float w)
{
	return (uint32_t)(y3 * w * (65536.0f / 255) + 0.5f);
}

/* b over an opaque a on one RGBA8 texel with b's weight kb (blend_over_kb): a lerp in 16-bit
 * fixed point, no division. */
static inline void blend_over_opaque(const uint8_t *x, const uint8_t *y, uint32_t kb, uint8_t *d)
{
	uint32_t ka = 65536 - kb;
	for (int c = 0; c < 3; c++)
		d[c] = (uint8_t)((x[c] * ka + y[c] * kb + 32768) >> 16);
	d[3] = 255;
}

/* Mode multiply on count RGBA8 texels (a multiple of 8), mask optional: blend_bytes's bytes. */
void blend_multiply_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
			 uint8_t *o, size_t count);

/* A height kernel's summary, kept as it writes (count a multiple of 16): the lanes
 * tile_summary_from_lanes takes. */
struct blend_lanes {
	float lo[16], hi[16];
	bool nan;
};

/* Heights, count a multiple of 8, mask optional (weight = clamp(mask, 0, 1) · opacity, NaN 0):
 * add: o = w > 0 ? a + b·(weight·w) : a; lerp (over, mask): o = b NaN ? a : a NaN ? b :
 * w > 0 ? a + (b − a)·w : a. blend_heights's bits. With lanes (count a multiple of 16), the
 * output's summary lanes too. */
void blend_add_avx2(const float *a, const float *b, const float *mask, float opacity,
		    float weight, float *o, size_t count, struct blend_lanes *lanes);
void blend_lerp_avx2(const float *a, const float *b, const float *mask, float opacity,
		     float *o, size_t count, struct blend_lanes *lanes);

/* Mode over on RGBA8 colours, count a multiple of 8, mask optional: where a is opaque, rgb =
 * (x·(65536 − kb) + y·kb + 32768) >> 16 with kb = y_alpha · w · 65536/255 + 0.5 truncated
 * (w = clamp(mask) · opacity, or opacity), alpha 255; elsewhere blend_over_general.
 * blend_bytes's and over_color's bytes. */
void blend_over_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
		     uint8_t *o, size_t count);

#endif
