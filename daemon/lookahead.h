/* lookahead — the server's look-ahead along a session's path (seed 003 §10): from the focus
 * and velocity of a WANT, the tiles the viewer will want over the next seconds, so that they
 * are generated (at bulk class, into the cache and the store: nothing is sent) before it asks.
 * The client itself looks ~0.15 s ahead (the lines of tiles it is about to reach); what the
 * server adds is the time synthesis takes: a level's tiles must be ready when the camera gets
 * there, and generating one costs 5–50 ms of a worker, a level's block of 16–25 tiles
 * 0.1–1 s on this machine's workers.
 *
 * How far ahead: where the focus will be after 1, 2 and 4 s of the current velocity, along the
 * great circle it moves on (on the planet's own radius; across a pole too). At each of those
 * places, each level the WANT shows (its visible entries) gets the window a viewer focused
 * there asks for (common/clipmap.h, as the viewer and prefetch: the longitude level lx that
 * clipmap_level_lx gives at that latitude, the window grid_window centres on the focus), in
 * every layer the level shows; what the WANT already holds (its window and ring) is left out,
 * so a slow flight adds nothing and a fast one its fine levels first (coarse windows move
 * slowly). At the seed's velocities (Table 1: about 0.8 × the altitude per second) 4 s is ~3
 * altitudes of ground: beyond the finest rings, inside the coarse ones. The lx is the one the
 * viewer will use there, not the one it has now: near a pole it changes within a few hundred
 * kilometres, and a tile of the old lx there is one no viewer (and no prefetch) asks for.
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
	uint32_t tile_size; /* the planet's tiles, texels a side (the window is
			     * CLIPMAP_WINDOW_TILES of them) */
};

/* The look-ahead for the levels and layers of the visible entries of w[0 .. n) (the lx of a
 * level's first visible entry is the viewer's now, for clipmap_level_lx's hysteresis):
 * entries (class bulk) for tiles not in w, most urgent first (1 s before 2 s before 4 s;
 * coarse levels first within each), into out[0 .. cap). Returns the count. */
size_t lookahead_wants(const struct lookahead_motion *m, const struct proto_want_entry *w,
		       size_t n, struct proto_want_entry *out, size_t cap);

/* How many seconds ahead the look-ahead reaches at most (its last horizon). */
#define LOOKAHEAD_REACH_S 4.0

/* The look-ahead's horizons, seconds ahead, nearest first (the last is LOOKAHEAD_REACH_S):
 * the places whose windows it asks for, which the cache keeps as foci (server.c). */
#define LOOKAHEAD_NHORIZONS 3
extern const double lookahead_horizons[LOOKAHEAD_NHORIZONS];

/* Where m's focus is after t seconds at its velocity, along the great circle it moves on
 * (the place the look-ahead's windows centre on): *lon, *lat in degrees. A still focus stays. */
void lookahead_point(const struct lookahead_motion *m, double t, double *lon, double *lat);

/* A velocity from two foci t seconds apart (the client sent none): east and north m/s at the
 * second focus, along the great circle through both on a sphere of radius r (across a pole,
 * the direction it goes on in). Returns 0, or -EINVAL when t is outside (0.02, 5] s or a focus is not
 * finite. */
int lookahead_velocity(double lon0, double lat0, double lon1, double lat1, double t, double r,
		       double *ve, double *vn);

#endif
