/* clipmapview over the real poles of the shipped planets (conf/planets/earth.ini, moon.ini,
 * mars.ini on the data `make data` installs) on Mesa llvmpipe, every frame rendered complete
 * into a 320×180 framebuffer with a magenta clear colour, looking straight down over each
 * pole from 500 km, 20 km, 100 m and 2 m: the horizon is outside the frame at each of those
 * heights, so every pixel is terrain — none may be the clear colour (a pole whose height
 * depends on longitude left sectors of sky inside the terrain: 159 000 of 230 400 px at the
 * Earth's south pole at 2 m). And, from 100 m and 2 m, no radial streaks: round a circle of
 * 40 px about the pole the colour varies by at most 10 levels, or less than 0.8× as much as
 * round one of 80 px (streaks converge on the pole and keep their contrast at every radius;
 * from that low, real colour detail round the pole is faint).
 * VIEW_POLES_PNG=DIR writes every frame; VIEW_POLES_VERBOSE=1 prints a line per frame.
 * Skipped with a message without GL or without the planet data.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "client/view/view_source_local.h"
#include "common/img.h"
#include "support/slow.h"

#define FW 320
#define FH 180

struct pole_planet {
	const char *path, *probe, *name;
	double radius; /* metres, for the horizon check */
};

static const struct pole_planet planets[] = {
	{ "conf/planets/earth.ini", "data/earth/etopo5.tif", "earth", 6356752 },
	{ "conf/planets/moon.ini", "data/moon/moon.tif", "moon", 1735300 },
	{ "conf/planets/mars.ini", "data/mars/mars.tif", "mars", 3376200 },
};

static const double alts[] = { 500e3, 20e3, 100, 2 };

/* Luminance at (x, y), bilinear between pixel centres. */
static double lum(const unsigned char *px, double x, double y)
{
	int x0 = (int)floor(x - 0.5), y0 = (int)floor(y - 0.5);
	double fx = x - 0.5 - x0, fy = y - 0.5 - y0, l = 0;
	for (int dy = 0; dy < 2; dy++)
		for (int dx = 0; dx < 2; dx++) {
			const unsigned char *p = px + ((size_t)(y0 + dy) * FW + x0 + dx) * 4;
			double w = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
			l += w * (0.3 * p[0] + 0.59 * p[1] + 0.11 * p[2]);
		}
	return l;
}

/* Radial streaks about the frame's centre (the pole): the mean luminance step of 1 px round
 * circles of 20..80 px (*ang) and along radii (*rad). Streaks converging on the pole change
 * round a circle and not along a radius; texture and shading change both ways alike. */
static void streakiness(const unsigned char *px, double *ang, double *rad)
{
	double sa = 0, sr = 0;
	int n = 0;
	for (int r = 20; r <= 80; r += 5)
		for (int a = 0; a < 720; a++) {
			double t = a * M_PI / 360, c = cos(t), s = sin(t), u = t + 1.0 / r;
			double l = lum(px, FW / 2.0 + r * c, FH / 2.0 + r * s);
			sa += fabs(lum(px, FW / 2.0 + r * cos(u), FH / 2.0 + r * sin(u)) - l);
			sr += fabs(lum(px, FW / 2.0 + (r + 1) * c, FH / 2.0 + (r + 1) * s) - l);
			n++;
		}
	*ang = sa / n;
	*rad = sr / n;
}

static void fly_poles(const struct pole_planet *pp)
{
	if (access(pp->probe, R_OK)) {
		fprintf(stderr, "test_view_poles: planet data missing (%s): run `make data` (as "
				"root) first — skipped\n", pp->probe);
		skip();
	}
	struct gl_context *gl = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &gl, err) < 0) {
		fprintf(stderr, "test_view_poles: no GL context: %s — skipped\n", err);
		skip();
	}
	struct view_source *src = NULL;
	struct view_source_local_opts so = { .workers = 2, .cache_mb = 256 };
	if (view_source_local_create(pp->path, &so, &src, err) < 0)
		fail_msg("%s: %s", pp->path, err);
	struct view_desc d = { .width = FW, .height = FH, .no_prefetch = true,
			       .background_set = true, .background = { 1, 0, 1 } };
	struct view *v = NULL;
	if (view_create(gl_context_api(gl), src, &d, &v, err) < 0)
		fail_msg("view_create: %s", err);
	unsigned char *px = malloc((size_t)FW * FH * 4);
	assert_non_null(px);
	/* Half the frame's diagonal, seen from the camera (vertical field of view 60°). */
	double half_diag = atan(tan(30 * M_PI / 180) * hypot(FW, FH) / FH);
	int bad = 0;
	for (int pole = 0; pole < 2; pole++) {
		for (size_t a = 0; a < sizeof alts / sizeof alts[0]; a++) {
			/* The horizon (below the nadir by asin(R / (R + h))) is outside the frame. */
			assert_true(asin(pp->radius / (pp->radius + alts[a])) > half_diag);
			struct view_camera cam = { .lat = pole ? -90 : 90, .lon = 0, .alt = alts[a],
						   .heading = 0, .pitch = -90, .width = FW,
						   .height = FH };
			struct view_frame_stats st;
			int rc = view_frame_complete(v, &cam, test_slow(120), &st, NULL);
			if (rc < 0 || !st.complete)
				fail_msg("%s %s pole %.0f m: frame not complete (%d)", pp->name,
					 pole ? "south" : "north", alts[a], rc);
			view_read_rgba(v, px);
			unsigned char bg[4];
			view_background_rgba(v, bg);
			int sky = 0;
			for (size_t i = 0; i < (size_t)FW * FH; i++)
				sky += px[4 * i] == bg[0] && px[4 * i + 1] == bg[1] &&
				       px[4 * i + 2] == bg[2];
			double ang, rad;
			streakiness(px, &ang, &rad);
			bool streaks = ang > 0.3 && ang > 2 * rad;
			bool ok = sky == 0 && !streaks;
			const char *dir = getenv("VIEW_POLES_PNG");
			if (dir || !ok) {
				char path[512];
				snprintf(path, sizeof path, "%s/view_poles_%s_%s_%.0f.png",
					 dir ? dir : "/tmp", pp->name, pole ? "S" : "N", alts[a]);
				if (img_write(path, FW, FH, 4, IMG_U8, px, err) < 0)
					fprintf(stderr, "%s\n", err);
			}
			if (!ok || getenv("VIEW_POLES_VERBOSE"))
				fprintf(stderr, "%s %s pole %8.0f m: levels %d..%d, %d px of sky, "
						"luminance steps %.2f round, %.2f along radii%s\n",
					pp->name, pole ? "south" : "north", alts[a], st.lfirst,
					st.llast, sky, ang, rad, ok ? "" : "  FAIL");
			bad += !ok;
		}
	}
	free(px);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(gl);
	if (bad)
		fail_msg("%s: %d pole views with sky inside the terrain or radial streaks (frames "
			 "in /tmp/view_poles_*.png)", pp->name, bad);
}

static void earth(void **state)
{
	(void)state;
	fly_poles(&planets[0]);
}

static void moon(void **state)
{
	(void)state;
	fly_poles(&planets[1]);
}

static void mars(void **state)
{
	(void)state;
	fly_poles(&planets[2]);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(earth),
		cmocka_unit_test(moon),
		cmocka_unit_test(mars),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
