/* clipmapview rendering on Mesa llvmpipe (EGL surfaceless, OSMesa fallback): toroidal
 * clipmap textures after focus moves, geometry (a marker lands on the predicted pixel, from
 * 1 km and from 2 m), coverage against the ellipsoid's analytic silhouette from orbit, low
 * altitude, across the north pole and across the antimeridian. Small framebuffers and rings.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "client/view/view_levels.h"
#include "client/view/view_source_local.h"
#include "common/geo.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "support/slow.h"
#include "support/synth_source.h"

#define DEG (M_PI / 180.0)
#define WGS_A 6378137.0
#define WGS_F (1 / 298.257223563)

/* ---- a synthetic source: tiles computed from their key, delivered as soon as wanted ---- */

enum synth_mode { SYNTH_PATTERN = 1, SYNTH_MARKER };

/* What the tiles hold: a hash pattern of the texel coordinates, or a flat planet with a
 * red cone marker. */
struct synth {
	enum synth_mode mode;
	double mlat, mlon, mrad, height; /* marker: degrees, radius in metres; flat height */
};

static float pattern_height(int lx, int ly, uint64_t u, uint64_t v)
{
	return (float)((((u * 7919u) ^ (v * 104729u)) + (uint64_t)lx * 31 + (uint64_t)ly * 1031) &
		       0xFFFFFu);
}

static void fill(void *ctx, const struct view_want *w, uint32_t T, enum pix_type f, void *data)
{
	const struct synth *s = ctx;
	for (uint32_t j = 0; j < T; j++)
		for (uint32_t i = 0; i < T; i++) {
			uint64_t u = (uint64_t)w->key.x * T + i, v = (uint64_t)w->key.y * T + j;
			size_t o = (size_t)j * T + i;
			double mark = 0;
			if (s->mode == SYNTH_MARKER && f == PIX_COLOR) {
				double lon, lat;
				grid_texel_center(&w->key, T, i, j, &lon, &lat);
				double dl = remainder(lon - s->mlon, 360.0);
				double dy = (lat - s->mlat) * DEG * WGS_A;
				double dx = dl * DEG * WGS_A * cos(s->mlat * DEG);
				/* A cone: smooth enough that filtering keeps its centre. */
				mark = fmax(0, 1 - sqrt(dx * dx + dy * dy) / s->mrad);
			}
			switch (f) {
			case PIX_HEIGHT:
				((float *)data)[o] = s->mode == SYNTH_PATTERN
							     ? pattern_height(w->key.lx, w->key.ly, u, v)
							     : (float)s->height;
				break;
			case PIX_NORMAL: {
				unsigned char *p = (unsigned char *)data + o * 2;
				p[0] = s->mode == SYNTH_PATTERN ? (unsigned char)(u * 3 + v) : 128;
				p[1] = s->mode == SYNTH_PATTERN ? (unsigned char)(v * 5 + w->key.ly) : 128;
				break;
			}
			default: {
				unsigned char *p = (unsigned char *)data + o * 4;
				p[0] = (unsigned char)lrint(230 + 25 * mark);
				p[1] = (unsigned char)lrint(230 * (1 - mark));
				p[2] = (unsigned char)lrint(230 * (1 - mark));
				p[3] = 255;
				break;
			}
			}
		}
}

static struct view_source *synth_create(struct synth *s, uint32_t T, int max_level)
{
	static const char *const names[] = { "color", "height", "normal" };
	static const enum pix_type formats[] = { PIX_COLOR, PIX_HEIGHT, PIX_NORMAL };
	return synth_source_create(T, max_level, 3, names, formats, fill, s);
}

/* ---- helpers ---- */

static struct gl_context *ctx_or_skip(void)
{
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		fprintf(stderr, "no GL context: %s\n", err);
		return NULL;
	}
	return ctx;
}

/* The procedural planet in-process (2 workers, a 256 MiB cache), or the test fails. */
static struct view_source *procedural_source(void)
{
	struct view_source *src;
	char err[256];
	if (view_source_local_create("conf/planets/procedural.ini",
				     &(struct view_source_local_opts){ .workers = 2, .cache_mb = 256 }, &src,
				     err) < 0)
		fail_msg("%s", err);
	return src;
}

static struct view *make_view(struct gl_context *ctx, struct view_source *src, int w, int h)
{
	struct view_desc d = { .width = w, .height = h, .n_phi = 96, .m_rings = 12,
			       .background_set = true, .background = { 1, 0, 1 } };
	struct view *v = NULL;
	char err[256] = "";
	int rc = view_create(gl_context_api(ctx), src, &d, &v, err);
	if (rc < 0)
		fprintf(stderr, "view_create: %s\n", err);
	assert_int_equal(rc, 0);
	return v;
}

/* ---- the frame's time budget (Algorithm 1) ---- */

/* The budget limits refining, never what is drawn. Without one the second frame (the first
 * takes the tiles) uploads and draws every wanted level. With one that any upload spends, a
 * frame still uploads one level, the coarsest missing, and draws every level resident: the
 * levels drawn grow by one a frame, never shrink, and the picture completes. */
static void budget_stops_refining(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	/* flat: the levels wanted stay the same as the ground height becomes known */
	struct synth flat = { .mode = SYNTH_MARKER, .mrad = 1 };
	struct view_camera cam = { 10, 20, 50000, 0, -30, 60, 0, 0 };
	struct view_frame_stats st;
	for (int b = 0; b < 2; b++) {
		struct view_source *src = synth_create(&flat, 32, 10);
		struct view_desc d = { .width = 64, .height = 64, .n_phi = 96, .m_rings = 12,
				       .budget_ms = b ? 1e-9 : 0 };
		struct view *v = NULL;
		char err[256];
		assert_int_equal(view_create(gl_context_api(ctx), src, &d, &v, err), 0);
		assert_int_equal(view_frame(v, &cam, 0, &st), 0);
		assert_int_equal(st.llast, -1); /* nothing yet */
		int prev = -1, complete_at = -1;
		for (int k = 1; k < 50; k++) {
			assert_int_equal(view_frame(v, &cam, 0, &st), 0);
			assert_true(st.lmax > st.lmin);
			if (b) {
				assert_true(st.levels_uploaded <= 1);
				assert_true(st.llast >= prev);
				assert_true(st.llast <= (prev < 0 ? st.lmin : prev + 1));
			} else {
				assert_int_equal(st.llast, st.lmax);
			}
			if (st.llast >= 0)
				assert_int_equal(st.lfirst, st.lmin);
			prev = st.llast;
			if (st.complete && complete_at < 0)
				complete_at = k;
		}
		assert_true(st.complete);
		assert_int_equal(st.llast, st.lmax);
		/* one level a frame with the budget: lmin .. dmax (the finer ones textures only) */
		assert_int_equal(complete_at, b ? 1 + st.dmax - st.lmin : 1);
		view_destroy(v);
		view_source_destroy(src);
	}
	gl_context_destroy(ctx);
}

/* ---- toroidal textures ---- */

static void check_toroidal(struct view *v, const float *hbuf, const unsigned char *nbuf)
{
	struct view_clipmap *cm = view_get_clipmap(v);
	uint32_t T = view_clipmap_tile_size(cm), S = view_clipmap_window_size(cm);
	int checked = 0;
	for (int l = 0; l < view_clipmap_levels(cm); l++) {
		const struct grid_quad *q = view_clipmap_held(cm, l);
		if (!q)
			continue;
		uint64_t W = (uint64_t)grid_tiles_x(q->lx) * T;
		const float *hs = hbuf + (size_t)l * S * S;
		const unsigned char *ns = nbuf + (size_t)l * S * S * 2;
		/* a level narrower than the texture repeats across it */
		uint64_t period = W < S ? W : S;
		for (uint32_t j = 0; j < q->h; j++)
			for (uint32_t i = 0; i < q->w; i++)
				for (uint64_t rep = 0; rep < S; rep += period) {
					uint64_t u = ((uint64_t)q->u0 + i) % W, vv = (uint64_t)q->v0 + j;
					size_t o = (size_t)(vv % S) * S + (size_t)((u + rep) % S);
					float want = pattern_height(q->lx, q->ly, u, vv);
					if (hs[o] != want) {
						fail_msg("level %d (%d,%d) window texel (%u,%u): height "
							 "%g, want %g",
							 l, q->lx, q->ly, i, j, hs[o], want);
					}
					assert_int_equal(ns[o * 2], (unsigned char)(u * 3 + vv));
					assert_int_equal(ns[o * 2 + 1], (unsigned char)(vv * 5 + q->ly));
				}
		checked++;
	}
	assert_true(checked >= 3);
}

static void toroidal_after_moves(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct synth pat = { .mode = SYNTH_PATTERN };
	struct view_source *src = synth_create(&pat, 32, 10);
	struct view *v = make_view(ctx, src, 64, 64);
	uint32_t S = 32 * CLIPMAP_WINDOW_TILES;
	int nl = 11;
	float *hbuf = xmalloc((size_t)S * S * nl * 4);
	unsigned char *nbuf = xmalloc((size_t)S * S * nl * 2);
	/* Small steps (partial updates), a jump, the antimeridian, towards the pole (anisotropic
	 * levels), and back. */
	static const double path[][3] = {
		{ 10, 20, 50000 },  { 10.01, 20.02, 50000 }, { 10.05, 20.1, 50000 },
		{ 9.9, 19.8, 50000 }, { -40, 179.95, 80000 }, { -40, -179.9, 80000 },
		{ -40.2, -179.7, 80000 }, { 70, 5, 50000 },    { 80, 5.5, 50000 },
		{ 88, 6, 50000 },    { 89.9, 100, 50000 },  { 10, 20, 50000 },
	};
	struct view_clipmap_stats cs;
	uint64_t prev_bytes = 0;
	for (size_t k = 0; k < sizeof path / sizeof path[0]; k++) {
		struct view_camera cam = { path[k][0], path[k][1], path[k][2], 0, -30, 60, 0, 0 };
		struct view_frame_stats st;
		assert_int_equal(view_frame_complete(v, &cam, test_slow(20), &st, NULL), 0);
		assert_true(st.complete);
		assert_int_equal(view_clipmap_read(view_get_clipmap(v), VIEW_HEIGHT, hbuf,
						   (size_t)S * S * nl * 4), 0);
		assert_int_equal(view_clipmap_read(view_get_clipmap(v), VIEW_NORMAL, nbuf,
						   (size_t)S * S * nl * 2), 0);
		check_toroidal(v, hbuf, nbuf);
		view_clipmap_get_stats(view_get_clipmap(v), &cs);
		if (k == 1) {
			/* A move of a few texels uploads a few strips, not whole levels. */
			uint64_t d = cs.bytes_uploaded - prev_bytes;
			assert_true(d > 0);
			if (d >= (uint64_t)S * S * 10) /* a whole window of one level */
				fail_msg("a small move uploaded %llu bytes", (unsigned long long)d);
		}
		prev_bytes = cs.bytes_uploaded;
	}
	/* Thin: only windows and their rings are held ((n + 3)² tiles per level and role at
	 * most, n = CLIPMAP_WINDOW_TILES). */
	const size_t ring = (CLIPMAP_WINDOW_TILES + 3) * (CLIPMAP_WINDOW_TILES + 3);
	assert_true(cs.tiles_held <= (size_t)nl * 3 * ring);
	free(hbuf);
	free(nbuf);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
}

/* ---- geometry: a marker lands where the CPU projects it ---- */

static void marker_case(struct gl_context *ctx, double lat, double lon, double agl,
			double heading, double pitch, double mlat, double mlon, double mrad,
			double height)
{
	struct synth mk = { SYNTH_MARKER, mlat, mlon, mrad, height };
	struct view_source *src = synth_create(&mk, 64, 22);
	int W = 128, H = 128;
	struct view *v = make_view(ctx, src, W, H);
	struct view_camera cam = { lat, lon, agl, heading, pitch, 60, 0, 0 };
	struct view_frame_stats st;
	assert_int_equal(view_frame_complete(v, &cam, test_slow(30), &st, NULL), 0);
	assert_true(st.complete);
	if (fabs(st.ground - height) > 1e-3)
		fail_msg("ground %g, want %g (complete %d, levels %d..%d drawn %d..%d)", st.ground, height, st.complete, st.lmin, st.lmax, st.lfirst, st.llast);
	unsigned char *px = xmalloc((size_t)W * H * 4);
	view_read_rgba(v, px);
	/* Redness-weighted centroid of the blob (filtering blurs it symmetrically). */
	double sx = 0, sy = 0, n = 0, rmax = 0;
	for (int pass = 0; pass < 2; pass++)
		for (int y = 0; y < H; y++)
			for (int x = 0; x < W; x++) {
				const unsigned char *p = px + ((size_t)y * W + x) * 4;
				double red = p[0] - 0.5 * (p[1] + p[2]);
				if (pass == 0) {
					rmax = fmax(rmax, red);
				} else if (red > 0.3 * rmax && red > 10) {
					sx += red * (x + 0.5);
					sy += red * (y + 0.5);
					n += red;
				}
			}
	double wsum = n;
	n /= fmax(rmax, 1);
	struct view_camera c;
	view_last_camera(v, &c);
	struct geo_body *b;
	char err[256];
	assert_int_equal(geo_body_create(WGS_A, WGS_F, &b, err), 0);
	double pc[3], pm[3], d[3], e[3];
	geo_forward(b, c.lat, c.lon, c.alt, pc);
	geo_forward(b, mlat, mlon, height, pm);
	for (int i = 0; i < 3; i++)
		d[i] = pm[i] - pc[i];
	view_ecef_to_enu(c.lat, c.lon, d, e);
	double ex, ey;
	assert_true(view_camera_project(&c, e, &ex, &ey));
	if (n < 4) {
		char e2[256];
		img_write("/tmp/view_marker_fail.png", W, H, 4, IMG_U8, px, e2);
		fail_msg("marker not seen (%g px; predicted at %.1f, %.1f)", n, ex, ey);
	}
	double gx = sx / wsum, gy = sy / wsum;
	fprintf(stderr, "marker case: at (%.2f, %.2f), predicted (%.2f, %.2f)\n", gx, gy, ex, ey);
	if (getenv("VIEW_DEBUG"))
		img_write("/tmp/view_marker.png", W, H, 4, IMG_U8, px, err);
	if (!getenv("VIEW_DEBUG") && (fabs(gx - ex) > 1 || fabs(gy - ey) > 1))
		fail_msg("marker at (%.2f, %.2f) px (%g px), predicted (%.2f, %.2f)", gx, gy, n, ex, ey);
	geo_body_destroy(b);
	free(px);
	view_destroy(v);
	view_source_destroy(src);
}

static void marker_projects_to_predicted_pixel(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	/* Looking straight down (the ground plane is parallel to the image: the blob's centroid
	 * is its centre's projection). From 1 km over a 1200 m plateau, 300 m off the nadir. */
	marker_case(ctx, 45.0, 7.0, 1000, 30, -90, 45.0 + 0.0017, 7.0 + 0.0021, 120, 1200);
	/* From 2 m above the ground, a 30 cm marker 70 cm away: float precision at 1 m scale
	 * on an Earth-size body. */
	marker_case(ctx, -33.0, 151.0, 2, 0, -90, -33.0 + 0.5 / 111000.0, 151.0 - 0.6 / 93000.0,
		    0.3, 250);
	/* 220 m from the north pole, a marker 110 m beyond it. */
	marker_case(ctx, 89.998, 40.0, 1500, 0, -90, 89.999, -140.0, 60, 0);
	/* From 1 km looking ahead at 40° down, a marker about 1.2 km ahead, centred on a texel
	 * corner of level 8 (a corner of every finer level too: the filtered blob stays
	 * symmetric about it). */
	double mlat = grid_v_to_lat(8, 64, round(grid_lat_to_v(8, 64, 10.0108)));
	double mlon = grid_u_to_lon(9, 64, round(grid_lon_to_u(9, 64, -60.0)));
	marker_case(ctx, mlat - 0.0108, mlon, 1000, 0, -40, mlat, mlon, 60, 0);
	gl_context_destroy(ctx);
}

/* ---- coverage against the ellipsoid's silhouette ---- */

/* Whether the ray from ECEF o along unit d hits the ellipsoid (a + dh, b + dh). */
static bool hits(const double o[3], const double d[3], double a, double b)
{
	double A = (d[0] * d[0] + d[1] * d[1]) / (a * a) + d[2] * d[2] / (b * b);
	double B = 2 * ((o[0] * d[0] + o[1] * d[1]) / (a * a) + o[2] * d[2] / (b * b));
	double C = (o[0] * o[0] + o[1] * o[1]) / (a * a) + o[2] * o[2] / (b * b) - 1;
	double disc = B * B - 4 * A * C;
	return disc >= 0 && (-B + sqrt(disc)) > 0;
}

static void enu_to_ecef(double lat, double lon, const double e[3], double out[3])
{
	double sp = sin(lat * DEG), cp = cos(lat * DEG), sl = sin(lon * DEG), cl = cos(lon * DEG);
	out[0] = -sl * e[0] - sp * cl * e[1] + cp * cl * e[2];
	out[1] = cl * e[0] - sp * sl * e[1] + cp * sl * e[2];
	out[2] = cp * e[1] + sp * e[2];
}

static void coverage_case(struct view *v, struct geo_body *gb, const struct view_camera *cam,
			  const char *name, int *inside_px)
{
	struct view_frame_stats st;
	assert_int_equal(view_frame_complete(v, cam, test_slow(60), &st, NULL), 0);
	struct view_camera c;
	view_last_camera(v, &c);
	int W = c.width, H = c.height;
	unsigned char *px = xmalloc((size_t)W * H * 4), bg[4];
	view_read_rgba(v, px);
	view_background_rgba(v, bg);
	double o[3];
	geo_forward(gb, c.lat, c.lon, c.alt, o);
	double b0 = WGS_A * (1 - WGS_F);
	double shrink = 30e3, grow = 12e3;
	int holes = 0, outside_bad = 0, inside = 0;
	for (int y = 0; y < H; y++)
		for (int x = 0; x < W; x++) {
			bool in = true, out = true;
			/* The pixel and its 4 neighbours (1 px for rasterisation). */
			for (int k = 0; k < 5; k++) {
				static const int dx[5] = { 0, 1, -1, 0, 0 }, dy[5] = { 0, 0, 0, 1, -1 };
				double e[3], d[3];
				view_camera_ray(&c, x + 0.5 + dx[k], y + 0.5 + dy[k], e);
				enu_to_ecef(c.lat, c.lon, e, d);
				in &= hits(o, d, WGS_A - shrink, b0 - shrink);
				out &= !hits(o, d, WGS_A + grow, b0 + grow);
			}
			const unsigned char *p = px + ((size_t)y * W + x) * 4;
			bool is_bg = p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2];
			if (in) {
				inside++;
				holes += is_bg;
			}
			if (out)
				outside_bad += !is_bg;
		}
	if (holes || outside_bad)
		fail_msg("%s: %d background pixels inside the silhouette, %d terrain pixels outside",
			 name, holes, outside_bad);
	*inside_px = inside;
	free(px);
}

static void coverage_views(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct view_source *src = procedural_source();
	char err[256];
	struct view *v = make_view(ctx, src, 96, 96);
	struct geo_body *gb;
	assert_int_equal(geo_body_create(WGS_A, WGS_F, &gb, err), 0);
	static const struct {
		const char *name;
		struct view_camera c;
		int min_inside;
	} cases[] = {
		{ "orbit", { 20, -30, 15e6, 0, -90, 60, 0, 0 }, 1500 },
		{ "low, at the horizon", { -14, -76, 4000, 45, -5, 60, 0, 0 }, 2000 },
		{ "across the north pole", { 88.5, 30, 300e3, 0, -30, 60, 0, 0 }, 2000 },
		{ "across the antimeridian", { -5, 179.8, 200e3, 90, -25, 60, 0, 0 }, 2000 },
		{ "oblique orbit", { -60, 120, 3e6, 180, -60, 60, 0, 0 }, 1500 },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		int inside = 0;
		coverage_case(v, gb, &cases[i].c, cases[i].name, &inside);
		if (inside < cases[i].min_inside)
			fail_msg("%s: only %d pixels inside the silhouette", cases[i].name, inside);
	}
	geo_body_destroy(gb);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
}

/* ---- frustum culling: the same pixels, fewer triangles ---- */

/* Horizon culling's bounds: every ring point of a sector, at any height in [lo, hi], is seen
 * at an elevation within [view_sector_elev_min(lo), view_sector_elev_max(hi)] — cameras from
 * 2 m to orbit, near the equator and a pole, sectors from a metre to a continent. */
static void elevation_bounds_hold(void **state)
{
	(void)state;
	struct view_body b;
	view_body_init(&b, 6378137.0, 1 / 298.257223563);
	static const struct view_camera cams[] = {
		{ -14, -76, 2, 45, -5, 60, 1280, 720 },	  { 60, 10, 120, 0, 0, 60, 1280, 720 },
		{ -80, 170, 4000, 0, 0, 60, 1280, 720 }, { 5, 5, 3e5, 0, -30, 60, 1280, 720 },
	};
	srand(7);
	for (size_t ci = 0; ci < sizeof cams / sizeof cams[0]; ci++) {
		const struct view_camera *c = &cams[ci];
		for (int t = 0; t < 400; t++) {
			int lv = 2 + rand() % 20;
			double th0 = clipmap_ring_radius(lv + 1), th1 = clipmap_ring_radius(lv);
			double ph0 = 2 * M_PI * (rand() % 32) / 32, ph1 = ph0 + 2 * M_PI / 32;
			double lo = c->alt - 3000 + rand() % 4000, hi = lo + rand() % 3000;
			double emin = view_sector_elev_min(&b, c, th0, th1, ph0, ph1, lo);
			double emax = view_sector_elev_max(&b, c, th0, th1, ph0, ph1, hi);
			for (int k = 0; k < 200; k++) {
				double u = rand() / (double)RAND_MAX, w = rand() / (double)RAND_MAX;
				double th = th0 * pow(th1 / th0, u), ph = ph0 + (ph1 - ph0) * w;
				double h = lo + (hi - lo) * (rand() / (double)RAND_MAX), p[3];
				view_ring_point(&b, c->lat, c->alt, th, ph, h, p);
				double e = atan2(p[2], hypot(p[0], p[1]));
				if (e < emin || e > emax)
					fail_msg("camera %zu, level %d, h %.0f: elevation %.6f outside "
						 "[%.6f, %.6f]",
						 ci, lv, h, e, emin, emax);
			}
		}
	}
}

/* High above a planet the rings are drawn at half density (view_set_mesh: every other
 * circle and step), where no relief reaches a pixel: a quarter of the triangles or fewer and
 * the same picture but for the limb's outline and single pixels; low down every vertex is
 * drawn. Coasts do not move: the sea is found per fragment, not per vertex. */
static void half_mesh_high_up(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct view_source *src = procedural_source();
	char err[256];
	int W = 320, H = 180;
	struct view_desc d = { .width = W, .height = H, .no_prefetch = true };
	struct view *v = NULL;
	assert_int_equal(view_create(gl_context_api(ctx), src, &d, &v, err), 0);
	static const struct {
		const char *name;
		struct view_camera c;
		bool half; /* what the default (mode 0) draws */
	} cases[] = {
		{ "orbit", { 30, 10, 12e6, 0, -90, 60, 0, 0 }, true },
		{ "2000 km, oblique", { -40, 150, 2e6, 30, -50, 60, 0, 0 }, true },
		{ "500 km", { 10, 60, 5e5, 0, -60, 60, 0, 0 }, false },
	};
	size_t n = (size_t)W * H * 4;
	unsigned char *full = xmalloc(n), *half = xmalloc(n);
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		const struct view_camera *c = &cases[i].c;
		struct view_frame_stats s0, s1, s2;
		view_set_mesh(v, 1);
		assert_int_equal(view_frame_complete(v, c, test_slow(300), &s1, NULL), 0);
		view_read_rgba(v, full);
		view_set_mesh(v, 2);
		assert_int_equal(view_frame(v, c, 0, &s2), 0);
		view_read_rgba(v, half);
		view_set_mesh(v, 0);
		assert_int_equal(view_frame(v, c, 0, &s0), 0);
		size_t off = 0;
		for (size_t k = 0; k < (size_t)W * H; k++) {
			int m = 0;
			for (int ch = 0; ch < 3; ch++)
				m = fmax(m, abs(full[4 * k + ch] - half[4 * k + ch]));
			off += m > 13;
		}
		fprintf(stderr, "mesh, %s: %llu triangles at full density, %llu at half (%.2f); "
				"%.3f %% of pixels differ by more than 13/255; default: %s\n",
			cases[i].name, (unsigned long long)s1.triangles,
			(unsigned long long)s2.triangles, (double)s2.triangles / s1.triangles,
			100.0 * off / (W * H), s0.triangles == s2.triangles ? "half" : "full");
		assert_true(s2.triangles * 3 < s1.triangles);
		assert_int_equal(s0.triangles, cases[i].half ? s2.triangles : s1.triangles);
		if (cases[i].half && off * 100 > (size_t)W * H) { /* 1 % */
			img_write("/tmp/view_mesh_full.png", W, H, 4, IMG_U8, full, err);
			img_write("/tmp/view_mesh_half.png", W, H, 4, IMG_U8, half, err);
			fail_msg("%s: %zu pixels differ at half density", cases[i].name, off);
		}
	}
	free(full);
	free(half);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
}

static void culling_keeps_pixels(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct view_source *src = procedural_source();
	char err[256];
	int W = 160, H = 90;
	struct view_desc d = { .width = W, .height = H, .n_phi = 128, .m_rings = 8,
			       .no_prefetch = true, .background_set = true,
			       .background = { 1, 0, 1 } };
	struct view *v = NULL;
	assert_int_equal(view_create(gl_context_api(ctx), src, &d, &v, err), 0);
	static const struct {
		const char *name;
		struct view_camera c;
		double max_ratio; /* triangles drawn with culling / without, at most */
	} cases[] = {
		{ "2 m, at the horizon", { -14, -76, 2, 45, -5, 60, 0, 0 }, 0.3 },
		{ "4 km, at the horizon", { -14, -76, 4000, 200, 0, 60, 0, 0 }, 0.4 },
		{ "100 m, looking up", { 30, 100, 100, 300, 40, 60, 0, 0 }, 0.8 },
		{ "orbit", { 20, -30, 15e6, 0, -90, 60, 0, 0 }, 1.0 },
		{ "oblique orbit", { -60, 120, 3e6, 180, -60, 60, 0, 0 }, 0.7 },
		/* horizon culling: ground behind the ridges in front */
		{ "30 m, facing ridges", { -14, -76.01, 30, 200, 3, 60, 0, 0 }, 0.5 },
		{ "100 m, level", { -14, -76, 100, 45, 0, 60, 0, 0 }, 1.0 },
	};
	unsigned char *on = xmalloc((size_t)W * H * 4), *off = xmalloc((size_t)W * H * 4);
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		const struct view_camera *c = &cases[i].c;
		struct view_frame_stats s1, s0;
		view_set_culling(v, true);
		assert_int_equal(view_frame_complete(v, c, test_slow(300), &s1, NULL), 0);
		view_read_rgba(v, on);
		view_set_culling(v, false);
		assert_int_equal(view_frame(v, c, 0, &s0), 0);
		view_read_rgba(v, off);
		fprintf(stderr, "culling, %s: %llu triangles drawn, %llu culled; %llu without\n",
			cases[i].name, (unsigned long long)s1.triangles,
			(unsigned long long)s1.triangles_culled, (unsigned long long)s0.triangles);
		assert_int_equal(s0.triangles_culled, 0);
		assert_int_equal(s1.triangles + s1.triangles_culled, s0.triangles);
		assert_int_equal(s1.lfirst, s0.lfirst);
		assert_int_equal(s1.llast, s0.llast);
		size_t diff = 0;
		for (size_t k = 0; k < (size_t)W * H * 4; k++)
			diff += on[k] != off[k];
		if (diff) {
			img_write("/tmp/view_cull_on.png", W, H, 4, IMG_U8, on, err);
			img_write("/tmp/view_cull_off.png", W, H, 4, IMG_U8, off, err);
			fail_msg("%s: %zu bytes differ with culling", cases[i].name, diff);
		}
		if ((double)s1.triangles > cases[i].max_ratio * (double)s0.triangles)
			fail_msg("%s: culling drew %llu of %llu triangles", cases[i].name,
				 (unsigned long long)s1.triangles, (unsigned long long)s0.triangles);
	}
	free(on);
	free(off);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(toroidal_after_moves),
		cmocka_unit_test(budget_stops_refining),
		cmocka_unit_test(marker_projects_to_predicted_pixel),
		cmocka_unit_test(coverage_views),
		cmocka_unit_test(elevation_bounds_hold),
		cmocka_unit_test(culling_keeps_pixels), cmocka_unit_test(half_mesh_high_up),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
