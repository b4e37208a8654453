/* craters — a seeded, size-distributed field of impact craters on a sphere, evaluated per tile
 * (the `craters` node) or per point (a slow oracle for tests).
 *
 * Design: crater radii come in classes R_k = max_radius / 2^k down to min_radius. For class k,
 * 3-D space is cut into cubes of edge s_k = 8·R_k (unit-sphere units); each cube draws, from
 * a hash of (seed, class, cube), `density` candidate points on average, and keeps those within
 * s_k/2 of the unit sphere, projected onto it: crater centres are uniform over the sphere with
 * no seam at the antimeridian and no pinch at the poles, and N(>R) falls as R⁻² (as lunar
 * crater counts roughly do). A crater's profile (simple bowl with a raised rim and ejecta out
 * to 2R; past `transition` diameter shallower, flat-floored, with a central peak) is summed
 * over every crater. Each class is centred (its expected mean is subtracted) and band-limited
 * like noise: weight 0 while its smallest diameter is under 2 texels, 1 from 4 texels — so a
 * coarse tile skips tiny craters and keeps the mean of its children. `degradation` gives each
 * crater its own wear (a hash of its cell, apart from the draws that place it, so craters stay
 * where they were); `boulders` turns the field into rocks (domes) with the same distribution.
 * Near a pole a class that bends more than NOISE_POLE_BEND over a texel of the level (its
 * smallest fresh crater's curvature × the texel size) is faded out over the last texels
 * (noise_pole_weight), in the tile and the point oracle alike.
 *
 * Threads: a struct craters is immutable after craters_init; any number of threads may call
 * craters_tile with their own scratch. Nothing here allocates.
 */
#ifndef CLIPMAP_CRATERS_H
#define CLIPMAP_CRATERS_H
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"

#define CRATERS_MAX_CLASSES 24

struct craters_params {
	uint32_t seed;
	double radius;	    /* body radius, metres */
	double min_radius;  /* smallest crater radius, metres */
	double max_radius;  /* largest crater radius, metres */
	double density;	    /* expected candidates per cell, 0..4 (about 1 saturates the surface) */
	double depth_ratio; /* depth / diameter of simple craters (0.2) */
	double rim_ratio;   /* rim height / depth (0.2) */
	double transition;  /* diameter (m) from which craters are complex (shallower, flat floor,
			     * central peak) */
	double degradation; /* 0..1: each crater's depth is scaled by 1 − degradation·f and its
			     * rim (and ejecta) by the square of that, f uniform in [0, 1) per
			     * crater — a mix of fresh and worn-down craters (0: all fresh) */
	int boulders;	    /* nonzero: rocks instead of craters — domes of height
			     * depth_ratio · diameter, h·(1 − r⁴), no rim, ejecta or complex form */
};

struct craters {
	struct craters_params p;
	int nclass;
	double r[CRATERS_MAX_CLASSES];	  /* R_k, metres */
	double mean[CRATERS_MAX_CLASSES]; /* expected height of class k, metres (subtracted) */
};

/* Checks p and precomputes the classes. Returns 0 or -EINVAL. */
int craters_init(struct craters *c, const struct craters_params *p);

/* Bytes of scratch craters_tile needs for tile size T. */
size_t craters_scratch_size(uint32_t T);

/* Fills out[T·T] (row 0 = north) with the crater heights (metres) of tile k (k->node is
 * ignored). scratch: craters_scratch_size(T) bytes, 8-byte aligned, borrowed. Returns the
 * number of classes evaluated (≥ 0) or -EINVAL for a bad key or size. */
int craters_tile(const struct craters *c, const struct tile_key *k, uint32_t T, void *scratch,
		 float *out);

/* The same field at one point (degrees) for a tile of level ly and size T. */
double craters_point(const struct craters *c, double lon, double lat, int ly, uint32_t T);

/* A class's weight at texel size s metres: 0 while the class's smallest diameter 2R is under
 * 2 texels, 1 from 4 texels, smooth between (the noise node's rule). */
double craters_band_weight(double radius_m, double s);

#endif
