/* node_colormask internals shared with its vector kernel (colormask_avx2.c). Not a public
 * interface. */
#ifndef CLIPMAP_COLORMASK_H
#define CLIPMAP_COLORMASK_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define CM_MAX 8

struct color_mask {
	int n;
	float ref[CM_MAX][3];
	float near2, far2; /* squared distances */
	float near, inv;   /* near, 1 / (far - near) */
};

/* One texel's mask value (RGBA8 in, alpha ignored). */
float color_mask_texel(const struct color_mask *m, const uint8_t *px);
/* count texels (a multiple of 8) with AVX2, the same values as color_mask_texel; returns
 * whether any is not 0. */
bool color_mask_avx2(const struct color_mask *m, const uint8_t *src, float *dst, size_t count);

#endif
