/* node_ramp internals shared with its vector kernel (ramp_avx2.c): one list of stops and its
 * lookup tables. Not a public interface. */
#ifndef CLIPMAP_NODE_RAMP_H
#define CLIPMAP_NODE_RAMP_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define RAMP_MAX_STOPS 64
#define RAMP_BINS 2048

struct ramp_table {
	int nstops;
	float h[RAMP_MAX_STOPS + 1]; /* stop heights + sea level, then +∞ */
	float c[RAMP_MAX_STOPS][4];  /* stop colours, alpha 255 */
	float dc[RAMP_MAX_STOPS][4]; /* colour per metre from stop s to s + 1; 0 at the end */
	float inv_bin;		     /* bins per metre */
	uint8_t bin_seg[RAMP_BINS + 4]; /* the segment where the bin starts (+4: 32-bit gathers) */
};

/* The segment holding h ∈ [h[0], h[last]]: the one s with h[s] ≤ h < h[s + 1] (h[last + 1] is
 * +∞), from the bin table and a short walk (the bin holds a stop; rounding put h just below
 * the bin's start). */
static inline int ramp_segment_of(const struct ramp_table *r, float h)
{
	int b = (int)((h - r->h[0]) * r->inv_bin);
	int s = r->bin_seg[b < RAMP_BINS ? b : RAMP_BINS - 1];
	while (h >= r->h[s + 1])
		s++;
	while (h < r->h[s])
		s--;
	return s;
}

/* The steep ramp's blend over a ramp already drawn: texels whose slope is past `from` (weight
 * w = clamp((slope − from)·inv, 0, 1) > 0, height not NaN) become base + (steep − base)·w. */
struct ramp_steep {
	const struct ramp_table *base, *steep;
	float from, inv;
};

/* One row's snow: t = (h − line)·inv, or with sea ice (sea_ice) 4·(ice + min(h, 0)/6000) where
 * that is more; where t > 0 the colour fades towards snow by min(t, 1)·(1 − w) (w the steep
 * weight when there is a slope row). */
struct ramp_snow {
	float line, inv, ice;
	bool sea_ice;
	float snow[4];
	float from, inv_steep;
};

/* The base ramp over count texels, one at a time (node_ramp.c). */
void ramp_base_scalar(const struct ramp_table *r, const float *h, uint8_t *d, size_t count);
/* The base ramp over count texels (a multiple of 8) with AVX2, the same bytes as the scalar
 * loop without a slope (NaN → transparent black). */
void ramp_base_avx2(const struct ramp_table *r, const float *h, uint8_t *d, size_t count);
/* The steep blend over count texels, one at a time / eight at a time (count a multiple of 8),
 * the same bytes. */
void ramp_steep_scalar(const struct ramp_steep *r, const float *h, const float *slope,
		       uint8_t *d, size_t count);
void ramp_steep_avx2(const struct ramp_steep *r, const float *h, const float *slope, uint8_t *d,
		     size_t count);
/* The snow over n texels of a row (slope NULL: none), one at a time / eight at a time (n a
 * multiple of 8), the same bytes. */
void ramp_snow_scalar(const struct ramp_snow *s, const float *h, const float *slope, uint8_t *d,
		      size_t n);
void ramp_snow_avx2(const struct ramp_snow *s, const float *h, const float *slope, uint8_t *d,
		    size_t n);

#endif
