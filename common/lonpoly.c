/* lonpoly — see lonpoly.h. */
#include "lonpoly.h"

#include <math.h>
#include <stdlib.h>

void lonpoly_bounds(const struct lonpoly *p, double *west, double *south, double *east,
		    double *north)
{
	*west = *south = INFINITY;
	*east = *north = -INFINITY;
	size_t n = 0;
	for (uint32_t r = 0; r < p->nrings; r++)
		n += p->rings[r];
	for (size_t i = 0; i < n; i++) {
		*west = fmin(*west, p->pts[i].lon);
		*east = fmax(*east, p->pts[i].lon);
		*south = fmin(*south, p->pts[i].lat);
		*north = fmax(*north, p->pts[i].lat);
	}
}

/* Runs the code after A, B for every edge A-B (the rings' closing edges included). */
#define FOR_EDGES(p, A, B, ...)                                                              \
	do {                                                                                   \
		size_t base_ = 0;                                                              \
		for (uint32_t r_ = 0; r_ < (p)->nrings; r_++) {                                \
			uint32_t n_ = (p)->rings[r_];                                          \
			for (uint32_t i_ = 0; i_ < n_; i_++) {                                 \
				const struct proto_lonlat *A = &(p)->pts[base_ + i_];          \
				const struct proto_lonlat *B = &(p)->pts[base_ + (i_ + 1) % n_]; \
				__VA_ARGS__                                                    \
			}                                                                      \
			base_ += n_;                                                           \
		}                                                                              \
	} while (0)

bool lonpoly_contains(const struct lonpoly *p, double lon, double lat)
{
	bool in = false;
	FOR_EDGES(p, a, b, {
		if ((a->lat > lat) != (b->lat > lat)) {
			double x = a->lon + (lat - a->lat) / (b->lat - a->lat) * (b->lon - a->lon);
			if (x > lon)
				in = !in;
		}
	});
	return in;
}

/* Liang-Barsky: clips the segment a-b to the closed rectangle; returns false when nothing is
 * left, else the parameters t0 ≤ t1 of what is. */
static bool clip(const struct proto_lonlat *a, const struct proto_lonlat *b, double w, double s,
		 double e, double n, double *t0, double *t1)
{
	double dx = b->lon - a->lon, dy = b->lat - a->lat;
	double pp[4] = { -dx, dx, -dy, dy };
	double qq[4] = { a->lon - w, e - a->lon, a->lat - s, n - a->lat };
	*t0 = 0;
	*t1 = 1;
	for (int i = 0; i < 4; i++) {
		if (pp[i] == 0) {
			if (qq[i] < 0)
				return false;
			continue;
		}
		double t = qq[i] / pp[i];
		if (pp[i] < 0)
			*t0 = fmax(*t0, t);
		else
			*t1 = fmin(*t1, t);
	}
	return *t0 <= *t1;
}

bool lonpoly_touches_rect(const struct lonpoly *p, double west, double south, double east,
			  double north)
{
	if (lonpoly_contains(p, (west + east) / 2, (south + north) / 2))
		return true;
	bool hit = false;
	FOR_EDGES(p, a, b, {
		double t0, t1;
		if (!hit && clip(a, b, west, south, east, north, &t0, &t1)) {
			double t = (t0 + t1) / 2;
			double x = a->lon + t * (b->lon - a->lon), y = a->lat + t * (b->lat - a->lat);
			if (x > west && x < east && y > south && y < north)
				hit = true;
		}
	});
	return hit;
}

static int cmp_iv(const void *x, const void *y)
{
	const double *a = x, *b = y;
	return a[0] < b[0] ? -1 : a[0] > b[0] ? 1 : 0;
}

static int cmp_d(const void *x, const void *y)
{
	double a = *(const double *)x, b = *(const double *)y;
	return a < b ? -1 : a > b ? 1 : 0;
}

/* The crossings of the line at lat with the edges (half-open: an edge counts when exactly one
 * end lies above), sorted into xs; returns their count. */
static size_t crossings(const struct lonpoly *p, double lat, double *xs)
{
	size_t k = 0;
	FOR_EDGES(p, a, b, {
		if ((a->lat > lat) != (b->lat > lat))
			xs[k++] = a->lon + (lat - a->lat) / (b->lat - a->lat) * (b->lon - a->lon);
	});
	qsort(xs, k, sizeof *xs, cmp_d);
	return k;
}

long lonpoly_strip(const struct lonpoly *p, double a, double b, double (*iv)[2], size_t cap,
		   double *lat_lo, double *lat_hi)
{
	size_t npts = 0, k = 0;
	for (uint32_t r = 0; r < p->nrings; r++)
		npts += p->rings[r];
	if (cap < 2 * npts + 2)
		return -1;
	double *xs = malloc((npts + 1) * sizeof *xs);
	if (!xs)
		return -1;
	double lo = INFINITY, hi = -INFINITY;
	/* the boundary's pieces within the strip */
	FOR_EDGES(p, e0, e1, {
		double t0, t1;
		if (clip(e0, e1, -INFINITY, a, INFINITY, b, &t0, &t1)) {
			double x0 = e0->lon + t0 * (e1->lon - e0->lon),
			       x1 = e0->lon + t1 * (e1->lon - e0->lon);
			double y0 = e0->lat + t0 * (e1->lat - e0->lat),
			       y1 = e0->lat + t1 * (e1->lat - e0->lat);
			iv[k][0] = fmin(x0, x1);
			iv[k][1] = fmax(x0, x1);
			k++;
			lo = fmin(lo, fmin(y0, y1));
			hi = fmax(hi, fmax(y0, y1));
		}
	});
	/* the inside across the whole strip, where no boundary is: on its middle line */
	size_t nx = crossings(p, (a + b) / 2, xs);
	for (size_t i = 0; i + 1 < nx; i += 2) {
		iv[k][0] = xs[i];
		iv[k][1] = xs[i + 1];
		k++;
	}
	if (nx >= 2)
		lo = fmin(lo, (a + b) / 2), hi = fmax(hi, (a + b) / 2);
	/* the latitudes: the strip's edges where the inside reaches them */
	if (crossings(p, a, xs) >= 2)
		lo = a, hi = fmax(hi, a);
	if (crossings(p, b, xs) >= 2)
		hi = b, lo = fmin(lo, b);
	free(xs);
	if (k == 0)
		return 0;
	qsort(iv, k, sizeof *iv, cmp_iv);
	size_t m = 0;
	for (size_t i = 1; i < k; i++) {
		if (iv[i][0] <= iv[m][1])
			iv[m][1] = fmax(iv[m][1], iv[i][1]);
		else
			m++, iv[m][0] = iv[i][0], iv[m][1] = iv[i][1];
	}
	*lat_lo = lo;
	*lat_hi = hi;
	return (long)(m + 1);
}
