/* normalmap — the arithmetic of a normal map from heights, shared by the `normal` node
 * (daemon/engine/nodes/node_normal.c) and the viewer that makes its normals itself
 * (clipmapview --normals derive), so both give the same bytes: RG8 east and north components
 * of the unit normal from central differences with metric texel spacing.
 * Pure functions; thread-safe.
 */
#ifndef CLIPMAP_NORMALMAP_H
#define CLIPMAP_NORMALMAP_H
#include <math.h>
#include <stdint.h>

/* The east stencil's half-width in texels for a row whose texels are r·dlam metres apart east
 * (r: the parallel's radius) and dy north, and its length in metres. Near a pole the east
 * spacing shrinks with cos(latitude) and a difference of float heights over ±1 texel is
 * rounding noise: where dy ≥ 8·dx the stencil widens to k = dy / (4·dx) texels (at most
 * kmax), and its length is the chord 2·r·sin(k·dlam) of the parallel — parallel to the east
 * direction at the texel, so the difference over it is the exact east slope of any plane.
 * Elsewhere (k = 1) the length is the plain 2·dx. */
uint32_t normalmap_east_stencil(double r, double dlam, double dy, uint32_t kmax, double *len);

/* One texel: we, ea the heights at the east stencil's ends, up, dn the heights north and
 * south; fx, fy: exaggeration over the stencils' lengths. A NaN difference counts as flat.
 * out[0], out[1]: round((c + 1)·127.5) of the normal's east and north components. */
static inline void normalmap_texel(float we, float ea, float up, float dn, float fx, float fy,
				   uint8_t *out)
{
	float gx = (ea - we) * fx;
	float gy = (up - dn) * fy;
	gx = gx == gx ? gx : 0.0f;
	gy = gy == gy ? gy : 0.0f;
	float inv = 1.0f / sqrtf(gx * gx + gy * gy + 1.0f);
	/* round((c + 1)·127.5) = floor(c·127.5 + 128) and the argument is ≥ 0.5 */
	out[0] = (uint8_t)(int)(-gx * inv * 127.5f + 128.0f);
	out[1] = (uint8_t)(int)(-gy * inv * 127.5f + 128.0f);
}

/* normalmap_texel for n texels of a row: we[i], ea[i] the heights at texel i's east stencil
 * ends, up[i], dn[i] north and south of it; fx, fy as there. 8 texels at a time where the
 * build has SSE2, with the same bytes. */
void normalmap_row(const float *restrict we, const float *restrict ea, const float *restrict up,
		   const float *restrict dn, float fx, float fy, uint8_t *restrict out, uint32_t n);

#endif
