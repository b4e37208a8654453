/* node_blend's vector kernels (blend_avx2.c). Not a public interface. */
#ifndef CLIPMAP_BLEND_KERNELS_H
#define CLIPMAP_BLEND_KERNELS_H
#include <stddef.h>
#include <stdint.h>

/* Mode multiply on count RGBA8 texels (a multiple of 8), mask optional: blend_bytes's bytes. */
void blend_multiply_avx2(const uint8_t *a, const uint8_t *b, const float *mask, float opacity,
			 uint8_t *o, size_t count);

#endif
