/* lookahead — the server's look-ahead along a session's path (seed 003 §10): from the focus
 * and velocity of a WANT, the tiles the viewer will want over the next seconds, so that they
 * are generated (at bulk class, into the cache and the store: nothing is sent) before it asks.
 * The client itself looks ~0.15 s ahead (the lines of tiles it is about to reach); what the
 * server adds is the time synthesis takes: a level's tiles must be ready when the camera gets
 * there, and generating one costs 5–50 ms of a worker, a level's block of 16–25 tiles
 * 0.1–1 s on this machine's workers.
 *
 * How far ahead: where the focus will be after 1, 2 and 4 s of the current velocity (on the
 * planet's own radius), each visible want moved by the whole tiles the focus moves at its
 * level — only levels where that is at least half a tile, so a slow flight adds nothing and
 * a fast one adds its fine levels first (coarse levels cross tiles slowly). At the seed's
 * velocities (Table 1: about 0.8 × the altitude per second) 4 s is ~3 altitudes of ground:
 * beyond the finest rings, inside the coarse ones. Levels switch their longitude level lx at
 * 28° and 64° of latitude (common/clipmap.h); the moved tiles keep the lx of the want they
 * come from, which near those latitudes may be the one the viewer leaves.
 *
 * Pure functions, any thread.
 */
#ifndef CLIPMAP_LOOKAHEAD_H
#define CLIPMAP_LOOKAHEAD_H
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"

#define LOOKAHEAD_MAX 1024 /* entries a session's look-ahead adds at most */

struct lookahead_motion {
	double lon, lat; /* focus, degrees */
	double ve, vn;	 /* ground velocity east and north, m/s */
	double radius;	 /* the planet's equatorial radius, m */
};

/* The look-ahead for the visible entries of w[0 .. n): entries (class bulk) for tiles not in
 * w, most urgent first (1 s before 2 s before 4 s; coarse levels first within each), into
 * out[0 .. cap). Returns the count. */
size_t lookahead_wants(const struct lookahead_motion *m, const struct proto_want_entry *w,
		       size_t n, struct proto_want_entry *out, size_t cap);

/* A velocity from two foci t seconds apart (the client sent none): east and north m/s on a
 * sphere of radius r. Returns 0, or -EINVAL when t is outside (0.02, 5] s or a focus is not
 * finite. */
int lookahead_velocity(double lon0, double lat0, double lon1, double lat1, double t, double r,
		       double *ve, double *vn);

#endif
