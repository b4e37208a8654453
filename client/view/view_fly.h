/* view_fly — the window's camera controls as pure functions (no GL, no window system):
 * orbit (drag: the ground follows the cursor), zoom (wheel: exponential in height), move
 * along the ground (speed ∝ height above it), climb/descend, look (heading/pitch), reset.
 * The camera's alt is its height above the ground (as view_frame takes it), kept ≥ 1 m.
 * Moves follow great circles on a sphere of the body's radius, so crossing a pole works.
 *
 * Thread-safety: none needed (plain values). Ownership: none.
 */
#ifndef CLIPMAP_VIEW_FLY_H
#define CLIPMAP_VIEW_FLY_H
#include <stdbool.h>

#include "view_levels.h"

#define VIEW_FLY_MIN_AGL 1.0

enum view_fly_key {
	FLY_FORWARD, /* W, ↑ */
	FLY_BACK,    /* S, ↓ */
	FLY_LEFT,    /* A, ← */
	FLY_RIGHT,   /* D, → */
	FLY_UP,	     /* E, PageUp */
	FLY_DOWN,    /* Q, PageDown */
	FLY_FAST,    /* Shift: ×5 */
	FLY_NKEYS
};

struct view_fly_input {
	bool key[FLY_NKEYS];	  /* held this frame */
	double orbit_dx, orbit_dy; /* pixels dragged with the orbit button (x right, y down) */
	double look_dx, look_dy;   /* pixels dragged with the look button */
	double wheel;		  /* notches; > 0 zooms in */
	bool reset;		  /* back to the home camera */
};

struct view_fly {
	struct view_camera cam, home;
	double radius; /* metres: the body's mean radius */
};

/* home: the start (and reset) camera, alt above the ground; its width/height/fov_y are the
 * screen the drags are measured on (0: 1280×720, 60°). */
void view_fly_init(struct view_fly *f, const struct view_camera *home, double radius);
/* Applies one frame's input over dt seconds. */
void view_fly_step(struct view_fly *f, const struct view_fly_input *in, double dt);
/* Moves the camera forward_m along its heading and right_m to its right over the ground
 * (great circle), turning the heading with the path. */
void view_fly_move(struct view_fly *f, double forward_m, double right_m);

#endif
