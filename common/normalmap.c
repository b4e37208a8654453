/* normalmap — see normalmap.h. */
#include "normalmap.h"

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
