/* geo — the C interface to GeographicLib (geo.cpp is the only C++ that touches it).
 * A body is an ellipsoid (a, f): WGS84 for Earth, f = 0 for a sphere.
 * Thread-safety: a body is immutable after creation; all functions may be called from any
 * thread. Angles in degrees, lengths in metres.
 */
#ifndef CLIPMAP_GEO_H
#define CLIPMAP_GEO_H

#define GEO_WGS84_A 6378137.0
#define GEO_WGS84_F (1.0 / 298.257223563)

#ifdef __cplusplus
extern "C" {
#endif

struct geo_body;

/* Creates a body with equatorial radius a > 0 and flattening 0 ≤ f < 1. Returns 0 or -EINVAL
 * with err filled ("flattening must be in [0, 1)"); *out is owned by the caller. */
int geo_body_create(double a, double f, struct geo_body **out, char err[256]);
void geo_body_destroy(struct geo_body *b);
double geo_body_a(const struct geo_body *b);
double geo_body_f(const struct geo_body *b);

/* Geodetic (lat, lon, h) → Earth-centred Earth-fixed xyz. */
void geo_forward(const struct geo_body *b, double lat, double lon, double h, double xyz[3]);
/* ECEF → geodetic. */
void geo_reverse(const struct geo_body *b, const double xyz[3], double *lat, double *lon,
		 double *h);
/* Radii of curvature at latitude lat: meridional M (north–south) and transverse N
 * (east–west: a parallel's radius is N·cos(lat)). */
void geo_radii(const struct geo_body *b, double lat, double *meridional, double *transverse);
/* Geodesic inverse: distance s12 and azimuths from point 1 to point 2. */
void geo_inverse(const struct geo_body *b, double lat1, double lon1, double lat2, double lon2,
		 double *s12, double *azi1, double *azi2);
/* Geodesic direct: the point s12 metres from (lat1, lon1) along azimuth azi1. */
void geo_direct(const struct geo_body *b, double lat1, double lon1, double azi1, double s12,
		double *lat2, double *lon2);
/* The same, with the geodesic's azimuth at the destination (its bearing there). */
void geo_direct_azi(const struct geo_body *b, double lat1, double lon1, double azi1, double s12,
		    double *lat2, double *lon2, double *azi2);

#ifdef __cplusplus
}
#endif
#endif
