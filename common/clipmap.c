/* clipmap — see clipmap.h. */
#include "clipmap.h"

#include <math.h>

#define DEG (M_PI / 180.0)
/* Longitude windows may be filled to 85 % of their half-width (staleness margin 15 %); a
 * coarser lx is left for a finer one only when the ring fits in 75 % (hysteresis). */
#define K_LON 0.85
#define K_LON_BACK 0.75

double clipmap_ring_radius(int i)
{
	if (i <= 0)
		return 2 * M_PI / 3;
	return CLIPMAP_RING_K * (M_PI / 2) / (double)((uint64_t)1 << i);
}

double clipmap_lon_extent(double lat_deg, double r)
{
	double colat = M_PI / 2 - fabs(lat_deg) * DEG;
	if (r >= colat * 0.999)
		return M_PI; /* the disk holds a pole: every longitude */
	return asin(fmin(1.0, sin(r) / cos(lat_deg * DEG)));
}

int clipmap_level_lx(int ly, double lat_deg, int cur_lx)
{
	const double n = CLIPMAP_WINDOW_TILES;
	/* The coarsest candidate: a level as narrow as the window covers every longitude. */
	int lo = 0;
	while (lo < ly + 1 && ldexp(1.0, lo + 1) <= n)
		lo++;
	double ext = clipmap_lon_extent(lat_deg, clipmap_ring_radius(ly - CLIPMAP_DETAIL));
	int lx = lo;
	for (int cand = ly + 1; cand > lo; cand--) {
		double half = n * M_PI / ldexp(1.0, cand);
		if (ext <= K_LON * half) {
			lx = cand;
			break;
		}
	}
	if (cur_lx >= lo && cur_lx < lx) {
		/* Kept one step coarser than the fit at most: a current lx several steps coarser
		 * (a camera that crossed several lx bands between two calls, fast near a pole,
		 * or a path walked ahead) moves to lx − 1, which always fits with room (its
		 * half-width is twice lx's). Until 6 December the current lx itself was kept,
		 * however coarse: a viewer from a pole held lx 2 at level 7 at 77°N, where the
		 * fit is 6, and so did the look-ahead's walk along its path. */
		double half = n * M_PI / ldexp(1.0, lx);
		if (ext > K_LON_BACK * half)
			return cur_lx > lx - 1 ? cur_lx : lx - 1;
	}
	return lx;
}

void clipmap_level_lx_range(int ly, double lat_lo, double lat_hi, int *lx_lo, int *lx_hi)
{
	/* The ring's longitude extent grows with |lat|: the finest lx is the one nearest the
	 * equator, the coarsest the one nearest a pole — or the next coarser one where hysteresis
	 * keeps it for a viewer that came from higher latitudes. */
	double amin = grid_band_equator_lat(lat_lo, lat_hi);
	double amax = fmax(fabs(lat_lo), fabs(lat_hi));
	*lx_hi = clipmap_level_lx(ly, amin, -1);
	int lo = clipmap_level_lx(ly, amax, -1);
	if (lo > 0 && clipmap_level_lx(ly, amax, lo - 1) == lo - 1)
		lo--;
	*lx_lo = lo;
}
