/* lookahead — see lookahead.h. */
#include "lookahead.h"

#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "common/clipmap.h"
#include "common/grid.h"

#define DEG (M_PI / 180.0)

const double lookahead_horizons[LOOKAHEAD_NHORIZONS] = { 1.0, 2.0, LOOKAHEAD_REACH_S };

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

/* The unit vector of (lon, lat) and its east and north directions. */
static void frame(double lon, double lat, double p[3], double e[3], double nv[3])
{
	double cl = cos(lon * DEG), sl = sin(lon * DEG), cp = cos(lat * DEG), sp = sin(lat * DEG);
	p[0] = cp * cl, p[1] = cp * sl, p[2] = sp;
	e[0] = -sl, e[1] = cl, e[2] = 0;
	nv[0] = -sp * cl, nv[1] = -sp * sl, nv[2] = cp;
}

/* Where the focus is after moving dist metres along the great circle of its velocity. */
static void move(const struct lookahead_motion *m, double dist, double *lon, double *lat)
{
	double p[3], e[3], nv[3], v = hypot(m->ve, m->vn), d = dist / m->radius;
	frame(m->lon, m->lat, p, e, nv);
	double q[3];
	for (int i = 0; i < 3; i++)
		q[i] = p[i] * cos(d) + (m->ve * e[i] + m->vn * nv[i]) / v * sin(d);
	*lat = asin(fmax(-1.0, fmin(1.0, q[2]))) / DEG;
	*lon = atan2(q[1], q[0]) / DEG;
}

void lookahead_point(const struct lookahead_motion *m, double t, double *lon, double *lat)
{
	double v = hypot(m->ve, m->vn);
	if (!(v > 0) || !(m->radius > 0) || !isfinite(v)) {
		*lon = m->lon;
		*lat = m->lat;
		return;
	}
	move(m, v * t, lon, lat);
}

/* A level the WANT shows: its lx now and the layers shown (bit per layer). */
struct shown {
	int lx; /* -1: not shown */
	uint64_t layers;
};

size_t lookahead_wants(const struct lookahead_motion *m, const struct proto_want_entry *w,
		       size_t n, struct proto_want_entry *out, size_t cap)
{
	if (!(m->radius > 0) || !isfinite(m->ve) || !isfinite(m->vn) || !isfinite(m->lat) ||
	    !isfinite(m->lon) || (m->ve == 0 && m->vn == 0) || m->tile_size == 0 ||
	    m->tile_size > UINT32_MAX / GRID_WINDOW_MAX_TILES)
		return 0;
	struct shown lv[GRID_MAX_LEVEL + 1];
	for (int l = 0; l <= GRID_MAX_LEVEL; l++)
		lv[l] = (struct shown){ -1, 0 };
	for (size_t i = 0; i < n; i++) {
		const struct proto_want_entry *e = &w[i];
		if (e->cls != PROTO_CLASS_VISIBLE || e->ly > GRID_MAX_LEVEL || e->lx > e->ly + 1 ||
		    e->layer >= 64)
			continue;
		if (lv[e->ly].lx < 0)
			lv[e->ly].lx = e->lx;
		lv[e->ly].layers |= 1ull << e->layer;
	}
	size_t k = 0;
	struct kset seen;
	kset_init(&seen, n + cap);
	if (!seen.k)
		return 0; /* out of memory: no look-ahead, nothing else lost */
	for (size_t i = 0; i < n; i++)
		kset_add(&seen, &w[i]);
	double v = hypot(m->ve, m->vn);
	uint32_t T = m->tile_size;
	for (size_t h = 0; h < LOOKAHEAD_NHORIZONS && k < cap; h++) {
		double lon, lat;
		move(m, v * lookahead_horizons[h], &lon, &lat);
		for (int ly = 0; ly <= GRID_MAX_LEVEL && k < cap; ly++) {
			if (lv[ly].lx < 0)
				continue;
			/* The lx a viewer arriving there uses: the fresh one, or one coarser where
			 * the hysteresis keeps it (it passed through that one on the way; never
			 * more than one coarser: clipmap_level_lx). */
			int lx = clipmap_level_lx(ly, lat, lv[ly].lx);
			struct grid_quad q;
			grid_window(lx, ly, T, CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
			struct tile_key keys[GRID_WINDOW_MAX_KEYS];
			int nk = grid_quad_tiles(&q, 0, keys);
			for (int layer = 0; layer < 64 && k < cap; layer++) {
				if (!(lv[ly].layers >> layer & 1))
					continue;
				for (int i = 0; i < nk && k < cap; i++) {
					struct proto_want_entry a = {
						.layer = (uint8_t)layer, .cls = PROTO_CLASS_BULK,
						.lx = keys[i].lx, .ly = keys[i].ly, .x = keys[i].x,
						.y = keys[i].y
					};
					if (kset_add(&seen, &a))
						out[k++] = a;
				}
			}
		}
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
	double p0[3], p1[3], e[3], nv[3], unused[3];
	frame(lon0, lat0, p0, unused, unused);
	frame(lon1, lat1, p1, e, nv);
	double c = p0[0] * p1[0] + p0[1] * p1[1] + p0[2] * p1[2];
	double away[3], len = 0; /* at p1, the direction away from p0 along their great circle */
	for (int i = 0; i < 3; i++) {
		away[i] = c * p1[i] - p0[i];
		len += away[i] * away[i];
	}
	len = sqrt(len);
	*ve = *vn = 0;
	if (len == 0)
		return 0; /* the same place (or antipodes: no direction) */
	double speed = atan2(len, c) * r / t;
	for (int i = 0; i < 3; i++) {
		*ve += away[i] / len * e[i] * speed;
		*vn += away[i] / len * nv[i] * speed;
	}
	return 0;
}
