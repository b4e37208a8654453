/* lonpoly — polygons in plate carrée (longitude, latitude degrees) as prefetch coverages and
 * cache purges take them (docs/PROTOCOL.md, PREFETCH shape 3): rings of points, filled by the
 * even-odd rule over every ring, so a multipolygon's parts and their holes are simply more
 * rings. Edges are straight in (lon, lat). Longitudes may leave [-180, 180] (a ring that
 * crosses the antimeridian continues past it); the tests here are in that unwrapped space,
 * and callers that work modulo 360 try the shifts they need.
 *
 * Pure functions (lonpoly_strip allocates scratch and frees it): thread-safe.
 */
#ifndef CLIPMAP_LONPOLY_H
#define CLIPMAP_LONPOLY_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"

struct lonpoly {
	uint32_t nrings;
	const uint32_t *rings; /* points per ring (each ≥ 3; a ring closes by itself) */
	const struct proto_lonlat *pts; /* the rings' points one after the other */
};

/* The polygon's extent: west, east (unwrapped), south, north. */
void lonpoly_bounds(const struct lonpoly *p, double *west, double *south, double *east,
		    double *north);
/* Whether (lon, lat) is inside (even-odd; a point on an edge may go either way). */
bool lonpoly_contains(const struct lonpoly *p, double lon, double lat);
/* Whether the polygon and the open rectangle (west < east, south < north, same unwrapped
 * space) share some area: an edge passes through the rectangle's inside, or its centre is
 * inside the polygon. Edges that only touch its border do not count. */
bool lonpoly_touches_rect(const struct lonpoly *p, double west, double south, double east,
			  double north);
/* The longitudes of the part of the polygon within the latitudes [a, b] (a ≤ b): sorted,
 * disjoint closed intervals [iv[i][0], iv[i][1]], at most cap of them (cap ≥ 2·points + 2 is
 * always enough; less: -1); *lat_lo, *lat_hi get that part's latitude extent. Returns the count (0:
 * the polygon does not reach those latitudes), or -1 when cap was too small or memory ran out. */
long lonpoly_strip(const struct lonpoly *p, double a, double b, double (*iv)[2], size_t cap,
		     double *lat_lo, double *lat_hi);

#endif
