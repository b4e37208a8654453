/* lookahead — see lookahead.h. */
#include "lookahead.h"

#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#define DEG (M_PI / 180.0)

static const double horizons[] = { 1.0, 2.0, 4.0 };

/* A set of tile addresses (open addressing, linear probing), sized once. */
struct kset {
	uint64_t *k; /* 0: empty (a packed key is never 0: bit 63 is set) */
	size_t mask;
};

static uint64_t pack(const struct proto_want_entry *e)
{
	/* layer < 64, lx < 32, ly ≤ 30, x < 2^31, y < 2^30: 6 + 5 + 5 + 31 + 30 = 77 bits; folded
	 * and mixed to 63, with collisions told apart by comparing again (kept whole below). */
	uint64_t a = (uint64_t)e->x << 32 | e->y, b = (uint64_t)e->layer << 10 | e->lx << 5 | e->ly;
	uint64_t h = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
	return (h ^ h >> 29) | 1ull << 63;
}

static void kset_init(struct kset *s, size_t n)
{
	size_t cap = 64;
	while (cap < 2 * n)
		cap *= 2;
	s->k = calloc(cap, sizeof *s->k);
	s->mask = cap - 1;
}

/* Adds e's key; returns false when it was there already. (A 63-bit hash collision makes a
 * tile look present: one look-ahead tile in ~10^15 is skipped, never a wrong one added.) */
static bool kset_add(struct kset *s, const struct proto_want_entry *e)
{
	uint64_t k = pack(e);
	for (size_t i = k & s->mask;; i = (i + 1) & s->mask) {
		if (s->k[i] == k)
			return false;
		if (!s->k[i]) {
			s->k[i] = k;
			return true;
		}
	}
}

static int by_level(const void *a, const void *b)
{
	const struct proto_want_entry *x = a, *y = b;
	return (x->ly > y->ly) - (x->ly < y->ly);
}

size_t lookahead_wants(const struct lookahead_motion *m, const struct proto_want_entry *w,
		       size_t n, struct proto_want_entry *out, size_t cap)
{
	if (!(m->radius > 0) || !isfinite(m->ve) || !isfinite(m->vn) || !isfinite(m->lat) ||
	    (m->ve == 0 && m->vn == 0))
		return 0;
	double c = fmax(cos(m->lat * DEG), 0.01);
	size_t k = 0;
	struct kset seen;
	kset_init(&seen, n + cap);
	if (!seen.k)
		return 0; /* out of memory: no look-ahead, nothing else lost */
	for (size_t i = 0; i < n; i++)
		kset_add(&seen, &w[i]);
	for (size_t h = 0; h < sizeof horizons / sizeof horizons[0] && k < cap; h++) {
		double dlon = m->ve * horizons[h] / (m->radius * c) / DEG,
		       dlat = m->vn * horizons[h] / m->radius / DEG;
		size_t first = k;
		for (size_t i = 0; i < n && k < cap; i++) {
			const struct proto_want_entry *e = &w[i];
			if (e->cls != PROTO_CLASS_VISIBLE || e->lx > 31 || e->ly > 30)
				continue;
			double nx = ldexp(1.0, e->lx), ny = ldexp(1.0, e->ly);
			double sx = dlon / 360.0 * nx, sy = -dlat / 180.0 * ny;
			if (fabs(sx) < 0.5 && fabs(sy) < 0.5)
				continue; /* the focus stays within this level's tiles */
			double x = fmod(floor(e->x + sx + 0.5), nx);
			x = x < 0 ? x + nx : x;
			double y = floor(e->y + sy + 0.5);
			if (y < 0 || y >= ny)
				continue; /* past a pole: the tiles there are another column's */
			struct proto_want_entry a = { .layer = e->layer, .cls = PROTO_CLASS_BULK,
						      .lx = e->lx, .ly = e->ly, .x = (uint32_t)x,
						      .y = (uint32_t)y };
			if (kset_add(&seen, &a))
				out[k++] = a;
		}
		qsort(out + first, k - first, sizeof *out, by_level); /* coarse first */
	}
	free(seen.k);
	return k;
}

int lookahead_velocity(double lon0, double lat0, double lon1, double lat1, double t, double r,
		       double *ve, double *vn)
{
	if (!(t > 0.02 && t <= 5) || !isfinite(lon0) || !isfinite(lat0) || !isfinite(lon1) ||
	    !isfinite(lat1) || !(r > 0))
		return -EINVAL;
	double dlon = fmod(lon1 - lon0 + 540.0, 360.0) - 180.0; /* across the antimeridian */
	double c = cos(0.5 * (lat0 + lat1) * DEG);
	*ve = dlon * DEG * r * c / t;
	*vn = (lat1 - lat0) * DEG * r / t;
	return 0;
}
