/* view_fly: the window's camera controls — zoom is exponential in height, keys move along
 * the ground at a speed proportional to the height (in the heading's direction), the height
 * stays ≥ 1 m above the ground, an orbit drag moves the ground with the cursor, a move across
 * the pole turns the heading round, look turns heading/pitch within limits, reset returns.
 */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#include <cmocka.h>

#include "client/view/view_fly.h"

#define R 6371000.0
#define assert_double_equal(a, b, eps) near((a), (b), (eps), #a, __LINE__)

static void near(double a, double b, double eps, const char *what, int line)
{
	if (!(fabs(a - b) <= eps)) {
		print_error("line %d: %s = %.9g, expected %.9g ± %g\n", line, what, a, b, eps);
		fail();
	}
}
#define DEG (M_PI / 180.0)

static struct view_fly start(double lat, double lon, double alt, double heading, double pitch)
{
	struct view_fly f;
	struct view_camera c = { .lat = lat, .lon = lon, .alt = alt, .heading = heading,
				 .pitch = pitch, .fov_y = 60, .width = 1280, .height = 720 };
	view_fly_init(&f, &c, R);
	return f;
}

static void test_zoom_exponential(void **state)
{
	(void)state;
	struct view_fly f = start(10, 20, 1e6, 0, -90);
	struct view_fly_input in = { .wheel = 1 };
	view_fly_step(&f, &in, 0.016);
	double one = f.cam.alt / 1e6;
	assert_true(one < 0.95 && one > 0.5);
	view_fly_step(&f, &in, 0.016);
	assert_double_equal(f.cam.alt / 1e6, one * one, 1e-9); /* same factor per notch */
	in.wheel = -2;
	view_fly_step(&f, &in, 0.016);
	assert_double_equal(f.cam.alt, 1e6, 1e-3);
	/* zooming in forever stops 1 m above the ground */
	in.wheel = 500;
	view_fly_step(&f, &in, 0.016);
	assert_double_equal(f.cam.alt, VIEW_FLY_MIN_AGL, 1e-12);
	assert_double_equal(f.cam.lat, 10, 1e-12);
}

static void test_keys_move_with_height(void **state)
{
	(void)state;
	/* heading east at the equator, 1 km up: W for 0.1 s moves ~100 m east */
	struct view_fly f = start(0, 0, 1000, 90, -20);
	struct view_fly_input in = { 0 };
	in.key[FLY_FORWARD] = true;
	view_fly_step(&f, &in, 0.1);
	double east = f.cam.lon * DEG * R;
	assert_double_equal(east, 100, 0.5);
	assert_double_equal(f.cam.lat, 0, 1e-9);
	/* ten times higher: ten times faster; Shift five times more */
	struct view_fly g = start(0, 0, 10000, 90, -20);
	in.key[FLY_FAST] = true;
	view_fly_step(&g, &in, 0.1);
	assert_double_equal(g.cam.lon * DEG * R, 5000, 5);
	/* D moves right of the heading (south when heading east); altitude unchanged */
	struct view_fly h = start(0, 0, 1000, 90, -20);
	memset(&in, 0, sizeof in);
	in.key[FLY_RIGHT] = true;
	view_fly_step(&h, &in, 0.1);
	assert_true(h.cam.lat < 0);
	assert_double_equal(h.cam.lat * DEG * R, -100, 0.5);
	assert_double_equal(h.cam.alt, 1000, 1e-9);
}

static void test_climb_and_floor(void **state)
{
	(void)state;
	struct view_fly f = start(45, 7, 100, 0, 0);
	struct view_fly_input in = { 0 };
	in.key[FLY_UP] = true;
	view_fly_step(&f, &in, 0.1);
	assert_true(f.cam.alt > 100);
	in.key[FLY_UP] = false;
	in.key[FLY_DOWN] = true;
	view_fly_step(&f, &in, 0.1);
	assert_double_equal(f.cam.alt, 100, 1e-6); /* exponential: the same factor back */
	for (int i = 0; i < 200; i++)
		view_fly_step(&f, &in, 0.1);
	assert_double_equal(f.cam.alt, VIEW_FLY_MIN_AGL, 1e-12);
	/* a long stall does not fling the camera: dt is capped */
	struct view_fly g = start(0, 0, 1000, 0, 0);
	in.key[FLY_DOWN] = false;
	in.key[FLY_FORWARD] = true;
	view_fly_step(&g, &in, 30);
	assert_true(g.cam.lat * DEG * R < 300);
}

static void test_orbit_follows_cursor(void **state)
{
	(void)state;
	/* looking straight down, north up: dragging the ground down brings the north into view
	 * (the camera moves north); dragging right moves the camera west */
	struct view_fly f = start(0, 0, 1e6, 0, -90);
	struct view_fly_input in = { .orbit_dy = 100 };
	view_fly_step(&f, &in, 0.016);
	double mpp = 1e6 * 2 * tan(30 * DEG) / 720;
	assert_double_equal(f.cam.lat * DEG * R, 100 * mpp, 1);
	memset(&in, 0, sizeof in);
	in.orbit_dx = 50;
	struct view_fly g = start(0, 0, 1e6, 0, -90);
	view_fly_step(&g, &in, 0.016);
	assert_double_equal(g.cam.lon * DEG * R, -50 * mpp, 1);
	assert_double_equal(g.cam.alt, 1e6, 1e-6);
}

static void test_over_the_pole(void **state)
{
	(void)state;
	/* 89° N heading north, 3° of arc forward: 88° N on the other side, heading south */
	struct view_fly f = start(89, 10, 1000, 0, -10);
	view_fly_move(&f, 3 * DEG * R, 0);
	assert_double_equal(f.cam.lat, 88, 1e-6);
	assert_double_equal(f.cam.lon, -170, 1e-6);
	assert_double_equal(f.cam.heading, 180, 1e-6);
}

static void test_look_and_reset(void **state)
{
	(void)state;
	struct view_fly f = start(30, 40, 5000, 350, 0);
	struct view_fly_input in = { .look_dx = 100, .look_dy = 2000 };
	view_fly_step(&f, &in, 0.016);
	assert_true(f.cam.heading > 0 && f.cam.heading < 20); /* wrapped past north */
	assert_double_equal(f.cam.pitch, -90, 1e-12);	      /* clamped */
	in = (struct view_fly_input){ .look_dy = -5000 };
	view_fly_step(&f, &in, 0.016);
	assert_true(f.cam.pitch < 90 && f.cam.pitch > 80);
	assert_double_equal(f.cam.lat, 30, 1e-12);
	in = (struct view_fly_input){ .wheel = 3, .reset = true };
	view_fly_step(&f, &in, 0.016);
	assert_double_equal(f.cam.heading, 350, 1e-12);
	assert_double_equal(f.cam.pitch, 0, 1e-12);
	assert_double_equal(f.cam.alt, 5000, 1e-12);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_zoom_exponential),   cmocka_unit_test(test_keys_move_with_height),
		cmocka_unit_test(test_climb_and_floor),	   cmocka_unit_test(test_orbit_follows_cursor),
		cmocka_unit_test(test_over_the_pole),	   cmocka_unit_test(test_look_and_reset),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
