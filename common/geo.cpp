// geo — the only C++ that touches GeographicLib; see geo.h. Bodies are immutable after
// creation, and GeographicLib's Geocentric/Geodesic objects are const-safe, so every function
// may run on any thread.
#include "errbuf.h"
#include "geo.h"

#include <GeographicLib/Constants.hpp>
#include <GeographicLib/Geocentric.hpp>
#include <GeographicLib/Geodesic.hpp>

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <new>

struct geo_body {
	double a, f;
	GeographicLib::Geocentric centric;
	GeographicLib::Geodesic geodesic;
	geo_body(double a_, double f_) : a(a_), f(f_), centric(a_, f_), geodesic(a_, f_) {}
};

extern "C" int geo_body_create(double a, double f, struct geo_body **out, char err[256])
{
	if (!(a > 0) || !std::isfinite(a)) {
		err_set(err, "radius must be a positive number of metres, got %g", a);
		return -EINVAL;
	}
	if (!(f >= 0 && f < 1)) {
		err_set(err, "flattening must be in [0, 1), got %g", f);
		return -EINVAL;
	}
	try {
		*out = new geo_body(a, f);
	} catch (const std::bad_alloc &) {
		std::fprintf(stderr, "clipmap: out of memory creating a body\n");
		std::abort();
	} catch (const std::exception &e) {
		err_set(err, "bad body (a=%g, f=%g): %s", a, f, e.what());
		return -EINVAL;
	}
	return 0;
}

extern "C" void geo_body_destroy(struct geo_body *b)
{
	delete b;
}

extern "C" double geo_body_a(const struct geo_body *b)
{
	return b->a;
}

extern "C" double geo_body_f(const struct geo_body *b)
{
	return b->f;
}

extern "C" void geo_forward(const struct geo_body *b, double lat, double lon, double h,
			    double xyz[3])
{
	b->centric.Forward(lat, lon, h, xyz[0], xyz[1], xyz[2]);
}

extern "C" void geo_reverse(const struct geo_body *b, const double xyz[3], double *lat,
			    double *lon, double *h)
{
	b->centric.Reverse(xyz[0], xyz[1], xyz[2], *lat, *lon, *h);
}

extern "C" void geo_radii(const struct geo_body *b, double lat, double *meridional,
			  double *transverse)
{
	// M = a(1-e²)/W³, N = a/W with W = sqrt(1 - e² sin²φ): the ellipsoid's principal radii.
	double e2 = b->f * (2 - b->f);
	double s = std::sin(lat * M_PI / 180.0);
	double w2 = 1 - e2 * s * s;
	double w = std::sqrt(w2);
	*transverse = b->a / w;
	*meridional = b->a * (1 - e2) / (w2 * w);
}

extern "C" void geo_inverse(const struct geo_body *b, double lat1, double lon1, double lat2,
			    double lon2, double *s12, double *azi1, double *azi2)
{
	b->geodesic.Inverse(lat1, lon1, lat2, lon2, *s12, *azi1, *azi2);
}

extern "C" void geo_direct(const struct geo_body *b, double lat1, double lon1, double azi1,
			   double s12, double *lat2, double *lon2)
{
	b->geodesic.Direct(lat1, lon1, azi1, s12, *lat2, *lon2);
}

extern "C" void geo_direct_azi(const struct geo_body *b, double lat1, double lon1, double azi1,
			       double s12, double *lat2, double *lon2, double *azi2)
{
	b->geodesic.Direct(lat1, lon1, azi1, s12, *lat2, *lon2, *azi2);
}
