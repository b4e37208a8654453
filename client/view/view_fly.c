/* view_fly — see view_fly.h. */
#include "view_fly.h"

#include <math.h>

#define DEG (M_PI / 180.0)
#define MAX_AGL_RADII 50.0   /* the farthest zoom out, in body radii */
#define LOOK_DEG_PER_PX 0.15
#define WHEEL_FACTOR 0.85    /* height × this per notch in */
#define CLIMB_RATE 1.2	     /* e-foldings of height per second */
#define FAST 5.0

static double clampd(double x, double lo, double hi) { return x < lo ? lo : x > hi ? hi : x; }

static double wrap180(double x)
{
	x = fmod(x + 180.0, 360.0);
	if (x < 0)
		x += 360.0;
	return x - 180.0;
}

static void clamp_cam(struct view_fly *f)
{
	struct view_camera *c = &f->cam;
	c->alt = clampd(c->alt, VIEW_FLY_MIN_AGL, MAX_AGL_RADII * f->radius);
	c->pitch = clampd(c->pitch, -90.0, 89.0);
	c->heading = fmod(c->heading, 360.0);
	if (c->heading < 0)
		c->heading += 360.0;
	c->lon = wrap180(c->lon);
	c->lat = clampd(c->lat, -90.0, 90.0);
}

void view_fly_init(struct view_fly *f, const struct view_camera *home, double radius)
{
	f->home = *home;
	if (f->home.width <= 0 || f->home.height <= 0) {
		f->home.width = 1280;
		f->home.height = 720;
	}
	if (!(f->home.fov_y > 0))
		f->home.fov_y = 60;
	f->radius = radius > 0 ? radius : 6371e3;
	f->cam = f->home;
	clamp_cam(f);
	f->home = f->cam;
}

void view_fly_move(struct view_fly *f, double forward_m, double right_m)
{
	double dist = hypot(forward_m, right_m);
	if (!(dist > 0))
		return;
	struct view_camera *c = &f->cam;
	double d = dist / f->radius;
	double b = c->heading * DEG + atan2(right_m, forward_m); /* bearing of the move */
	double lat2, lon2;
	view_sphere_direct(c->lat, c->lon, b, d, &lat2, &lon2);
	double p1 = c->lat * DEG, l1 = c->lon * DEG, p2 = lat2 * DEG, l2 = lon2 * DEG;
	/* the bearing on arrival: the reverse of the bearing from the end back to the start */
	double back = atan2(sin(l1 - l2) * cos(p1),
			    cos(p2) * sin(p1) - sin(p2) * cos(p1) * cos(l1 - l2));
	double arrive = back + M_PI;
	if (fabs(cos(p2)) > 1e-9 && fabs(cos(p1)) > 1e-9)
		c->heading += (arrive - b) / DEG;
	c->lat = p2 / DEG;
	c->lon = l2 / DEG;
	clamp_cam(f);
}

void view_fly_step(struct view_fly *f, const struct view_fly_input *in, double dt)
{
	struct view_camera *c = &f->cam;
	if (in->reset) {
		f->cam = f->home;
		return;
	}
	dt = clampd(dt, 0, 0.25); /* a stall must not fling the camera */
	int h = c->height > 0 ? c->height : f->home.height;
	double fov = (c->fov_y > 0 ? c->fov_y : 60) * DEG;
	/* Orbit: the ground under the cursor follows it (metres per pixel at the nadir). */
	if (in->orbit_dx != 0 || in->orbit_dy != 0) {
		double mpp = fmin(c->alt, 3 * f->radius) * 2 * tan(fov / 2) / h;
		view_fly_move(f, in->orbit_dy * mpp, -in->orbit_dx * mpp);
	}
	c->heading += in->look_dx * LOOK_DEG_PER_PX;
	c->pitch -= in->look_dy * LOOK_DEG_PER_PX;
	if (in->wheel != 0)
		c->alt *= pow(WHEEL_FACTOR, in->wheel);
	double fast = in->key[FLY_FAST] ? FAST : 1.0;
	double climb = (in->key[FLY_UP] ? 1.0 : 0.0) - (in->key[FLY_DOWN] ? 1.0 : 0.0);
	if (climb != 0)
		c->alt *= exp(climb * CLIMB_RATE * fast * dt);
	double fw = (in->key[FLY_FORWARD] ? 1.0 : 0.0) - (in->key[FLY_BACK] ? 1.0 : 0.0);
	double rt = (in->key[FLY_RIGHT] ? 1.0 : 0.0) - (in->key[FLY_LEFT] ? 1.0 : 0.0);
	if (fw != 0 || rt != 0) {
		double speed = fmin(c->alt, f->radius) * fast; /* one height per second */
		double n = hypot(fw, rt);
		view_fly_move(f, fw / n * speed * dt, rt / n * speed * dt);
	}
	clamp_cam(f);
}
