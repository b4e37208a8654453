/* test_view_look — the planet's look in the viewer (Mesa llvmpipe): a planet without air has a
 * black sky and unhazed ground, Earth's air a blue sky and a bluish haze on the far ground,
 * Mars' air a butterscotch sky, --haze (view_desc.haze) overrides the planet's; the default
 * sun lights a north-up view from its upper left (a slope facing north-west is bright, one
 * facing south-east dark: craters read as bowls); a sea draws water over the ground below
 * it (dark blue, a glint of the sun) and the camera's height is above the water, except where
 * the colour layer shows ice there; and the
 * look reaches the viewer from the planet file through the in-process source. Synthetic flat
 * grey planets, small framebuffers.
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
#include "common/xalloc.h"
#include "support/synth_source.h"
#include "support/slow.h"

#define W 64
#define H 64

/* A flat grey planet whose normals all face (east, north) = ne[0], ne[1]. */
struct flat {
	double ne[2];
	unsigned char grey;
	float height;
	bool tint; /* sand instead of grey: grey, 0.85 grey, 0.55 grey */
	bool dry_west; /* the colour's alpha 254 west of 0° (a sea mask: dry land there) */
};

static void fill(void *ctx, const struct view_want *w, uint32_t T, enum pix_type f, void *data)
{
	const struct flat *s = ctx;
	for (size_t o = 0; o < (size_t)T * T; o++) {
		switch (f) {
		case PIX_HEIGHT: ((float *)data)[o] = s->height; break;
		case PIX_NORMAL:
			for (int i = 0; i < 2; i++)
				((unsigned char *)data)[o * 2 + i] =
					(unsigned char)lrint((s->ne[i] + 1) * 127.5);
			break;
		default:
			memset((unsigned char *)data + o * 4, s->grey, 3);
			if (s->tint) {
				((unsigned char *)data)[o * 4 + 1] = (unsigned char)(s->grey * 0.85);
				((unsigned char *)data)[o * 4 + 2] = (unsigned char)(s->grey * 0.55);
			}
			((unsigned char *)data)[o * 4 + 3] = 255;
			if (s->dry_west) {
				double lon, lat;
				grid_texel_center(&w->key, T, (uint32_t)(o % T), (uint32_t)(o / T), &lon,
						  &lat);
				((unsigned char *)data)[o * 4 + 3] = lon < 0 ? 254 : 255;
			}
			break;
		}
	}
}

static const struct view_look earth_look = { .air_density = 1, .air_height = 8000,
					     .air_color = { 133, 173, 222 } };
static const struct view_look mars_look = { .air_density = 0.3, .air_height = 11100,
					    .air_color = { 196, 150, 108 } };

/* Renders the flat planet (with `look`) from cam until complete; px gets W×H RGBA, top row
 * first, bg the clear colour, *stp (may be NULL) the last frame's stats. Returns false when
 * there is no GL context. */
static bool render_stats(const struct flat *s, const struct view_look *look, float haze,
			 const struct view_camera *cam, unsigned char *px, unsigned char bg[4],
			 struct view_frame_stats *stp)
{
	struct gl_context *ctx = NULL;
	char err[256] = "";
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		fprintf(stderr, "no GL context: %s\n", err);
		return false;
	}
	static const char *const names[] = { "color", "height", "normal" };
	static const enum pix_type formats[] = { PIX_COLOR, PIX_HEIGHT, PIX_NORMAL };
	struct view_source *src = synth_source_create(32, 12, 3, names, formats, fill, (void *)s);
	if (look)
		src->planet.look = *look;
	struct view_desc d = { .width = W, .height = H, .n_phi = 96, .m_rings = 12, .haze = haze };
	struct view *v = NULL;
	int rc = view_create(gl_context_api(ctx), src, &d, &v, err);
	if (rc < 0)
		fail_msg("view_create: %s", err);
	struct view_frame_stats st;
	assert_int_equal(view_frame_complete(v, cam, test_slow(30), &st, NULL), 0);
	if (stp)
		*stp = st;
	assert_int_equal(view_read_rgba(v, px), 0);
	view_background_rgba(v, bg);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
	return true;
}

static bool render(const struct flat *s, const struct view_look *look, float haze,
		   const struct view_camera *cam, unsigned char *px, unsigned char bg[4])
{
	return render_stats(s, look, haze, cam, px, bg, NULL);
}

static const unsigned char *at(const unsigned char *px, int x, int y)
{
	return px + ((size_t)y * W + (size_t)x) * 4;
}

/* At 2 km looking 3° down through a 12° lens: sky above, the ground 60 km away under the
 * horizon, ground 15 km away at the bottom. */
struct horizon {
	unsigned char sky[4], far[4], near[4];
	int row; /* the first ground row from the top */
};

static bool horizon_view(const struct view_look *look, float haze, struct horizon *h)
{
	struct flat s = { { 0, 0 }, 40, 0, false, false }; /* dark: the haze shows */
	struct view_camera cam = { 0, 0, 2000, 0, -3, 12, W, H };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	if (!render(&s, look, haze, &cam, px, bg)) {
		free(px);
		return false;
	}
	int x = W / 2;
	h->row = -1;
	for (int y = 0; y < H && h->row < 0; y++)
		if (memcmp(at(px, x, y), bg, 3) != 0)
			h->row = y;
	if (h->row < 2 || h->row > H - 10)
		fail_msg("the horizon is at row %d of %d", h->row, H);
	memcpy(h->sky, at(px, x, 0), 4);
	memcpy(h->far, at(px, x, h->row + 3), 4);
	memcpy(h->near, at(px, x, H - 1), 4);
	fprintf(stderr, "horizon row %d: sky %u,%u,%u far %u,%u,%u near %u,%u,%u\n", h->row,
		h->sky[0], h->sky[1], h->sky[2], h->far[0], h->far[1], h->far[2], h->near[0],
		h->near[1], h->near[2]);
	free(px);
	return true;
}

/* No air: the sky is black and the far ground has the near ground's colour (no haze). */
static void airless(void **state)
{
	(void)state;
	struct horizon h;
	if (!horizon_view(NULL, 0, &h))
		skip();
	for (int i = 0; i < 3; i++) {
		assert_true(h.sky[i] <= 12);
		if (abs(h.far[i] - h.near[i]) > 4)
			fail_msg("channel %d: far ground %u, near %u: hazed without air", i,
				 h.far[i], h.near[i]);
	}
	/* the planet has Earth's air, but --haze 0 (view_desc.haze < 0) removes it */
	if (!horizon_view(&earth_look, -1, &h))
		skip();
	for (int i = 0; i < 3; i++) {
		assert_true(h.sky[i] <= 12);
		assert_true(abs(h.far[i] - h.near[i]) <= 4);
	}
}

/* Earth's air: a blue sky and a bluish haze over the far ground. */
static void earth_air(void **state)
{
	(void)state;
	struct horizon h;
	if (!horizon_view(&earth_look, 0, &h))
		skip();
	assert_true(h.sky[2] > 150 && h.sky[2] > h.sky[0] + 40);
	/* the ground is grey: the haze makes the far ground lighter and bluer than the near */
	assert_true(h.far[2] > h.near[2] + 10);
	assert_true(h.far[2] - h.far[0] > h.near[2] - h.near[0] + 5);
	/* an airless planet given Earth's air by --haze 1 */
	if (!horizon_view(NULL, 1, &h))
		skip();
	assert_true(h.sky[2] > 150 && h.sky[2] > h.sky[0] + 40);
}

/* Mars' dusty air: a butterscotch sky (red over blue), a warm haze. */
static void mars_air(void **state)
{
	(void)state;
	struct horizon h;
	if (!horizon_view(&mars_look, 0, &h))
		skip();
	assert_true(h.sky[0] > 150 && h.sky[0] > h.sky[2] + 40);
	assert_true(h.far[0] - h.far[2] > h.near[0] - h.near[2]);
}

/* Looking straight down, north up: the mean of the frame's middle. */
static bool slope_brightness(double e, double n, double *out)
{
	struct flat s = { { e, n }, 140, 0, false, false };
	struct view_camera cam = { 0, 0, 5000, 0, -90, 60, W, H };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	if (!render(&s, NULL, 0, &cam, px, bg)) {
		free(px);
		return false;
	}
	double sum = 0;
	int k = 0;
	for (int y = H / 4; y < 3 * H / 4; y++)
		for (int x = W / 4; x < 3 * W / 4; x++, k++)
			sum += at(px, x, y)[0] + at(px, x, y)[1] + at(px, x, y)[2];
	*out = sum / (3.0 * k);
	free(px);
	return true;
}

/* The default sun is in the north-west: a slope facing the upper left of a north-up view (its
 * normal tilted north-west) is lit, one facing the lower right is in shade. */
static void sun_from_upper_left(void **state)
{
	(void)state;
	double nw, se, flat;
	if (!slope_brightness(-0.45, 0.45, &nw) || !slope_brightness(0.45, -0.45, &se) ||
	    !slope_brightness(0, 0, &flat))
		skip();
	fprintf(stderr, "facing north-west %.1f, flat %.1f, facing south-east %.1f\n", nw, flat,
		se);
	assert_true(nw > flat + 10);
	assert_true(flat > se + 10);
}

/* A sea at 0 over a grey floor 500 m down: the camera's height is above the water, the water
 * is dark blue where the dry floor is grey, and the sun glints on it where it mirrors the sun
 * (which dry ground does not). */
static void sea(void **state)
{
	(void)state;
	struct flat s = { { 0, 0 }, 140, -500, false, false };
	struct view_look wet = { .sea = true, .sea_level = 0 }, dry = { .sea = false };
	struct view_camera down = { 0, 0, 2000, 0, -90, 60, W, H };
	/* towards the sun (azimuth 315), looking 35° down: the sun's mirror image in the middle */
	struct view_camera glint = { 0, 0, 2000, 315, -35, 30, W, H };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	struct view_frame_stats st;
	unsigned char d_wet[4], d_dry[4], g_wet[4], g_dry[4];
	if (!render_stats(&s, &wet, -1, &down, px, bg, &st))
		skip();
	memcpy(d_wet, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == 0 && fabs(st.alt - 2000) < 1e-6);
	assert_true(render_stats(&s, &dry, -1, &down, px, bg, &st));
	memcpy(d_dry, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == -500 && fabs(st.alt - 1500) < 1e-6);
	assert_true(render(&s, &wet, -1, &glint, px, bg));
	memcpy(g_wet, at(px, W / 2, H / 2), 4);
	assert_true(render(&s, &dry, -1, &glint, px, bg));
	memcpy(g_dry, at(px, W / 2, H / 2), 4);
	fprintf(stderr, "down: water %u,%u,%u floor %u,%u,%u; towards the sun: water %u,%u,%u "
		"floor %u,%u,%u\n", d_wet[0], d_wet[1], d_wet[2], d_dry[0], d_dry[1], d_dry[2],
		g_wet[0], g_wet[1], g_wet[2], g_dry[0], g_dry[1], g_dry[2]);
	assert_true(d_wet[2] > d_wet[0] + 15);		   /* blue */
	assert_true(d_wet[0] + d_wet[1] + d_wet[2] < d_dry[0] + d_dry[1] + d_dry[2]); /* darker */
	assert_true(g_wet[0] > 200 && g_wet[0] > g_dry[0] + 50); /* the glint */
	free(px);
}

/* A sea on a geoid (sea_geoid): its surface follows the planet's lattice, so the same floor,
 * 50 m below the ellipsoid, is dry land where the geoid lies lower (it is 80 m down at
 * 45°W: the floor stands 30 m above that sea) and sea floor where it lies higher (30 m down
 * at 45°E) — the viewer's water and its camera height follow. A sea at one level everywhere
 * (the lattice ignored) would drown both. */
static void sea_on_a_geoid(void **state)
{
	(void)state;
	struct flat s = { { 0, 0 }, 140, -50, false, false };
	/* rows: south pole, equator, north pole; columns at −180, −90, 0, 90 */
	int16_t dm[12] = { 0, 0, 0, 0, 0, -1000, -600, 0, 0, 0, 0, 0 };
	struct view_look geoid = { .sea = true, .sea_grid = { .rows = 3, .cols = 4, .dm = dm } };
	struct view_look level = { .sea = true };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	unsigned char land[4], water[4], drowned[4];
	struct view_frame_stats st;
	struct view_camera west = { 0, -45, 2000, 0, -90, 60, W, H };
	struct view_camera east = { 0, 45, 2000, 0, -90, 60, W, H };
	if (!render_stats(&s, &geoid, -1, &west, px, bg, &st))
		skip();
	memcpy(land, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == -50);		/* the floor, above this sea (−80 m) */
	assert_true(render_stats(&s, &geoid, -1, &east, px, bg, &st));
	memcpy(water, at(px, W / 2, H / 2), 4);
	assert_true(fabs(st.ground - (-30)) < 0.05); /* the water's surface, bilinear: −30 m */
	assert_true(render_stats(&s, &level, -1, &west, px, bg, &st));
	memcpy(drowned, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == 0);
	fprintf(stderr, "geoid sea: 45°W land %u,%u,%u; 45°E water %u,%u,%u; at sea level 0 "
		"45°W %u,%u,%u\n", land[0], land[1], land[2], water[0], water[1], water[2],
		drowned[0], drowned[1], drowned[2]);
	assert_true(abs(land[0] - land[2]) < 12);	  /* grey ground, not water */
	assert_true(water[2] > water[0] + 15);		  /* blue */
	assert_true(drowned[2] > drowned[0] + 15);	  /* drowned without the lattice */
	free(px);
}

/* A sea mask in the colour's alpha (sea_mask = color_alpha): the same floor 50 m below sea
 * level is sea east of 0°, where the colour's alpha is 255, and dry land west of it, where it
 * is 254 (a polder, a closed depression): drawn as ground, and the camera's height is above
 * that ground, not above a sea that is not there. Without the mask both sides are sea. */
static void sea_mask_in_alpha(void **state)
{
	(void)state;
	struct flat s = { { 0, 0 }, 140, -50, false, true };
	struct view_look masked = { .sea = true, .sea_mask = true }, plain = { .sea = true };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	unsigned char dry[4], wet[4], unmasked[4];
	struct view_frame_stats st;
	struct view_camera west = { 0, -10, 2000, 0, -90, 60, W, H };
	struct view_camera east = { 0, 10, 2000, 0, -90, 60, W, H };
	if (!render_stats(&s, &masked, -1, &west, px, bg, &st))
		skip();
	memcpy(dry, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == -50);
	assert_true(render_stats(&s, &masked, -1, &east, px, bg, &st));
	memcpy(wet, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == 0);
	assert_true(render_stats(&s, &plain, -1, &west, px, bg, &st));
	memcpy(unmasked, at(px, W / 2, H / 2), 4);
	assert_true(st.ground == 0);
	fprintf(stderr, "sea mask: west (alpha 254) %u,%u,%u; east %u,%u,%u; west without the mask "
		"%u,%u,%u\n", dry[0], dry[1], dry[2], wet[0], wet[1], wet[2], unmasked[0],
		unmasked[1], unmasked[2]);
	assert_true(abs(dry[0] - dry[2]) < 12 && dry[0] > 60); /* grey ground */
	assert_true(wet[2] > wet[0] + 15);			 /* water */
	assert_true(unmasked[2] > unmasked[0] + 15);		 /* water without the mask */
	free(px);
}

/* Ice on the sea: where the colour layer is near-white below sea level (sea ice, an ice
 * shelf), the viewer draws that white, flat and without a glint — not dark water; a light
 * but saturated floor (shallows over sand) stays water. */
static void sea_ice(void **state)
{
	(void)state;
	struct flat ice = { { 0.3, 0 }, 235, -50, false, false }, sand = { { 0.3, 0 }, 200, -50, true, false };
	struct view_look wet = { .sea = true, .sea_level = 0 };
	struct view_camera down = { 0, 0, 2000, 0, -90, 60, W, H };
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	if (!render(&ice, &wet, -1, &down, px, bg))
		skip();
	unsigned char c_ice[4], c_sand[4];
	memcpy(c_ice, at(px, W / 2, H / 2), 4);
	assert_true(render(&sand, &wet, -1, &down, px, bg));
	memcpy(c_sand, at(px, W / 2, H / 2), 4);
	fprintf(stderr, "ice on the sea %u,%u,%u; tinted shallows %u,%u,%u\n", c_ice[0], c_ice[1],
		c_ice[2], c_sand[0], c_sand[1], c_sand[2]);
	assert_true(c_ice[0] > 150 && c_ice[1] > 150 && c_ice[2] > 150); /* white, lit */
	assert_true(c_sand[0] + c_sand[1] + c_sand[2] < 300); /* water: dark, not the sand */
	free(px);
}

/* The look goes from the planet file to the viewer's source. */
static void look_from_planet_file(void **state)
{
	(void)state;
	char dir[] = "/tmp/test_view_look.XXXXXX";
	assert_non_null(mkdtemp(dir));
	char path[64];
	snprintf(path, sizeof path, "%s/p.ini", dir);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs("[planet]\nbody = sphere\nradius = 1000000\natmosphere = mars\n"
	      "atmosphere_density = 0.5\nsea_level = -25\n"
	      "[node z]\ntype = constant\nheight = 0\n[layer height]\nnode = z\n",
	      f);
	assert_int_equal(fclose(f), 0);
	struct view_source *src = NULL;
	char err[256] = "";
	int rc = view_source_local_create(path, &(struct view_source_local_opts){ .workers = 1 },
					  &src, err);
	if (rc)
		fail_msg("view_source_local_create: %s", err);
	const struct view_look *k = &src->planet.look;
	assert_true(k->air_density == 0.5 && k->air_height == 11100);
	assert_memory_equal(k->air_color, mars_look.air_color, 3);
	assert_true(k->sea && k->sea_level == -25);
	assert_int_equal(k->sea_grid.rows, 0);
	view_source_destroy(src);
	assert_int_equal(unlink(path), 0);
	assert_int_equal(rmdir(dir), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(airless),
		cmocka_unit_test(earth_air),
		cmocka_unit_test(mars_air),
		cmocka_unit_test(sun_from_upper_left),
		cmocka_unit_test(sea),
		cmocka_unit_test(sea_ice),
		cmocka_unit_test(sea_on_a_geoid),
		cmocka_unit_test(sea_mask_in_alpha),
		cmocka_unit_test(look_from_planet_file),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
