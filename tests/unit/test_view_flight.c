/* clipmapview along whole flights on Mesa llvmpipe (EGL surfaceless, OSMesa fallback), every
 * frame rendered complete (view_frame_complete) into a 320×180 framebuffer:
 * - coverage from orbit (20 000 km) down to 2 m above the ground and on along the ground at
 *   2 m (one descent across the antimeridian), on the shipped procedural planet: no background
 *   pixel where every ray within 1 px hits the ellipsoid shrunk to the terrain's lowest
 *   height, no terrain where every such ray misses the ellipsoid grown to its highest;
 * - flights across the north pole, the south pole and the antimeridian at 500 km, 20 km,
 *   100 m and 2 m over a synthetic planet (heights 0, flat normals, colour a smooth function
 *   of the 3-D surface normal with a wavelength of 4× the altitude): the same coverage check,
 *   plus texture continuity — each clearly predictable pixel against the colour the CPU
 *   computes at its ray's hit point, after fitting a grey shading factor (so any near-grey
 *   lighting passes; a smear, a wrong column or a wrong level does not).
 * VIEW_FLIGHT_PNG=DIR writes every frame (and an error map) to DIR; VIEW_FLIGHT_VERBOSE=1
 * prints a line per frame; VIEW_FLIGHT_ONLY=PATTERN runs the matching tests only.
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
#include "client/view/view_source_local.h"
#include "common/geo.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "support/slow.h"
#include "support/synth_source.h"

#define DEG (M_PI / 180.0)
#define WGS_A 6378137.0
#define WGS_F (1 / 298.257223563)
#define WGS_B (WGS_A * (1 - WGS_F))

#define FW 320
#define FH 180

/* ---- a synthetic planet: heights 0, flat normals, colour a smooth function of the normal ---- */

/* Three directions (one per channel) and phases: the pattern has no symmetry a wrong
 * longitude, a mirrored tile or a swapped axis could satisfy. */
static const double synth_dir[3][3] = {
	{ 0.48, 0.60, 0.64 },
	{ -0.70, 0.10, 0.707 },
	{ 0.20, -0.93, 0.31 },
};
static const double synth_phase[3] = { 0.3, 2.1, 4.4 };

/* Albedo in 0..1 (sRGB-encoded, as a colour layer holds it) at unit surface normal n. */
static void synth_albedo(double lambda, const double n[3], double out[3])
{
	double k = 2 * M_PI * WGS_A / lambda;
	for (int c = 0; c < 3; c++) {
		const double *d = synth_dir[c];
		double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
		double t = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]) / len;
		out[c] = 0.5 + 0.4 * sin(k * t + synth_phase[c]);
	}
}

static void normal_at(double lat, double lon, double n[3])
{
	n[0] = cos(lat * DEG) * cos(lon * DEG);
	n[1] = cos(lat * DEG) * sin(lon * DEG);
	n[2] = sin(lat * DEG);
}

/* The planet's tiles; ctx points at the pattern's wavelength on the ground (metres). */
static void synth_fill(void *ctx, const struct view_want *w, uint32_t T, enum pix_type f,
		       void *data)
{
	double lambda = *(const double *)ctx;
	for (uint32_t j = 0; j < T; j++)
		for (uint32_t i = 0; i < T; i++) {
			size_t o = (size_t)j * T + i;
			if (f == PIX_HEIGHT) {
				((float *)data)[o] = 0;
			} else if (f == PIX_NORMAL) {
				((unsigned char *)data)[o * 2] = 128;
				((unsigned char *)data)[o * 2 + 1] = 128;
			} else {
				double lon, lat, n[3], a[3];
				grid_texel_center(&w->key, T, i, j, &lon, &lat);
				normal_at(lat, lon, n);
				synth_albedo(lambda, n, a);
				unsigned char *p = (unsigned char *)data + o * 4;
				for (int c = 0; c < 3; c++)
					p[c] = (unsigned char)lrint(a[c] * 255);
				p[3] = 255;
			}
		}
}

static struct view_source *synth_create(double *lambda)
{
	static const char *const names[] = { "color", "height", "normal" };
	static const enum pix_type formats[] = { PIX_COLOR, PIX_HEIGHT, PIX_NORMAL };
	return synth_source_create(128, 22, 3, names, formats, synth_fill, lambda);
}

/* ---- rays against the ellipsoid ---- */

static void enu_to_ecef(double lat, double lon, const double e[3], double out[3])
{
	double sp = sin(lat * DEG), cp = cos(lat * DEG), sl = sin(lon * DEG), cl = cos(lon * DEG);
	out[0] = -sl * e[0] - sp * cl * e[1] + cp * cl * e[2];
	out[1] = cl * e[0] - sp * sl * e[1] + cp * sl * e[2];
	out[2] = cp * e[1] + sp * e[2];
}

/* The nearest t > 0 where o + t·d meets the ellipsoid grown by dh (a + dh, b + dh), or -1. */
static double ray_hit(const double o[3], const double d[3], double dh)
{
	double a = WGS_A + dh, b = WGS_B + dh;
	double A = (d[0] * d[0] + d[1] * d[1]) / (a * a) + d[2] * d[2] / (b * b);
	double B = 2 * ((o[0] * d[0] + o[1] * d[1]) / (a * a) + o[2] * d[2] / (b * b));
	double C = (o[0] * o[0] + o[1] * o[1]) / (a * a) + o[2] * o[2] / (b * b) - 1;
	double disc = B * B - 4 * A * C;
	if (disc < 0)
		return -1;
	double q = sqrt(disc);
	double t0 = (-B - q) / (2 * A), t1 = (-B + q) / (2 * A);
	return t0 > 0 ? t0 : t1 > 0 ? t1 : -1;
}

/* Per pixel centre of camera c (alt above the ellipsoid): the ECEF ray, and whether it hits
 * the ellipsoid grown by lo and by hi. */
struct rays {
	int W, H;
	double o[3], nadir[3], alt; /* the camera, the ground under it, its height */
	double *d; /* W·H·3 */
	unsigned char *lo, *hi;
};

static void rays_cast(const struct view_camera *c, struct geo_body *gb, double lo, double hi,
		      struct rays *r)
{
	r->W = c->width;
	r->H = c->height;
	size_t n = (size_t)r->W * r->H;
	r->d = xrealloc(r->d, n * 3 * sizeof *r->d);
	r->lo = xrealloc(r->lo, n);
	r->hi = xrealloc(r->hi, n);
	geo_forward(gb, c->lat, c->lon, c->alt, r->o);
	geo_forward(gb, c->lat, c->lon, 0, r->nadir);
	r->alt = c->alt;
	for (int y = 0; y < r->H; y++)
		for (int x = 0; x < r->W; x++) {
			size_t k = (size_t)y * r->W + x;
			double e[3];
			view_camera_ray(c, x + 0.5, y + 0.5, e);
			enu_to_ecef(c->lat, c->lon, e, r->d + k * 3);
			r->lo[k] = ray_hit(r->o, r->d + k * 3, lo) > 0;
			r->hi[k] = ray_hit(r->o, r->d + k * 3, hi) > 0;
		}
}

static void rays_free(struct rays *r)
{
	free(r->d);
	free(r->lo);
	free(r->hi);
}

/* Whether every pixel within rad (square) of (x, y) has m set (want = 1) or clear (0);
 * pixels beyond the frame count as unknown (false). */
static bool all_near(const unsigned char *m, int W, int H, int x, int y, int rad, int want)
{
	for (int j = y - rad; j <= y + rad; j++)
		for (int i = x - rad; i <= x + rad; i++) {
			if (i < 0 || j < 0 || i >= W || j >= H)
				return false;
			if ((m[(size_t)j * W + i] != 0) != (want != 0))
				return false;
		}
	return true;
}

/* ---- judging a frame ---- */

struct verdict {
	int inside, holes, outside, stray; /* coverage */
	int hole_x, hole_y, stray_x, stray_y;
	int judged, bad, max_run; /* continuity */
	double max_err, sum_err;
	int bad_x, bad_y;
	double bad_got[3], bad_want[3];
	double agl; /* the camera's height above the ground (last frame of a flight) */
};

static bool is_bg(const unsigned char *p, const unsigned char bg[4])
{
	return p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2];
}

static void judge_coverage(const unsigned char *px, const unsigned char bg[4],
			   const struct rays *r, struct verdict *v)
{
	for (int y = 0; y < r->H; y++)
		for (int x = 0; x < r->W; x++) {
			const unsigned char *p = px + ((size_t)y * r->W + x) * 4;
			bool b = is_bg(p, bg);
			if (all_near(r->lo, r->W, r->H, x, y, 1, 1)) {
				v->inside++;
				if (b && !v->holes++) {
					v->hole_x = x;
					v->hole_y = y;
				}
			}
			if (all_near(r->hi, r->W, r->H, x, y, 1, 0) && !b && !v->stray++) {
				v->stray_x = x;
				v->stray_y = y;
			}
		}
}

static double srgb_to_linear(double c)
{
	return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

/* The surface point where pixel k's ray meets the ellipsoid (heights are 0), or false. */
static bool surface_hit(const struct rays *r, size_t k, double p[3])
{
	double t = ray_hit(r->o, r->d + k * 3, 0);
	if (t <= 0)
		return false;
	for (int i = 0; i < 3; i++)
		p[i] = r->o[i] + t * r->d[k * 3 + i];
	return true;
}

/* Colour error allowed (0..1 per channel in the frame's encoding) for the filtering of
 * coarse texels and the light's tint; measured: at most 0.027, mean 0.005. A frame fails when
 * more than 0.2 % of its judged pixels exceed it, when 4 in a row do, or when any pixel is
 * off by COLOR_WRONG: a wrong colour, not a filtered one. */
#define COLOR_TOL 0.04
#define COLOR_WRONG 0.12
/* Which pixels can be predicted: the clipmap's texels grow with the distance from the nadir
 * (and the coarsest level is one tile for the globe), so only ground within JUDGE_R·alt of the
 * nadir is judged, and only where a pixel's footprint is below FOOT_FRAC·λ. */
#define JUDGE_R 3.0
#define FOOT_FRAC 0.02

static void judge_continuity(const unsigned char *px, const struct rays *r, double lambda,
			     struct verdict *v, unsigned char *map)
{
	int W = r->W, H = r->H;
	for (int y = 0; y < H - 1; y++) {
		int run = 0;
		for (int x = 0; x < W - 1; x++) {
			size_t k = (size_t)y * W + x;
			double p[3], px1[3], py1[3];
			/* clearly on the ground: 2 px from the limb, footprint small against λ */
			bool ok = all_near(r->lo, W, H, x, y, 2, 1) && surface_hit(r, k, p) &&
				  surface_hit(r, k + 1, px1) && surface_hit(r, k + (size_t)W, py1);
			if (ok) {
				double fx = 0, fy = 0;
				for (int i = 0; i < 3; i++) {
					fx += (px1[i] - p[i]) * (px1[i] - p[i]);
					fy += (py1[i] - p[i]) * (py1[i] - p[i]);
				}
				double g = 0;
				for (int i = 0; i < 3; i++)
					g += (p[i] - r->nadir[i]) * (p[i] - r->nadir[i]);
				ok = sqrt(fmax(fx, fy)) < FOOT_FRAC * lambda &&
				     sqrt(g) < JUDGE_R * r->alt;
			}
			if (!ok) {
				run = 0;
				continue;
			}
			if (map)
				map[k * 4 + 1] = 60;
			double n[3] = { p[0] / (WGS_A * WGS_A), p[1] / (WGS_A * WGS_A),
					p[2] / (WGS_B * WGS_B) };
			double nl = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
			for (int i = 0; i < 3; i++)
				n[i] /= nl;
			double a[3], lw[3], lg[3], num = 0, den = 0;
			synth_albedo(lambda, n, a);
			const unsigned char *q = px + k * 4;
			for (int c = 0; c < 3; c++) {
				lw[c] = srgb_to_linear(lrint(a[c] * 255) / 255.0);
				lg[c] = pow(q[c] / 255.0, 2.2); /* the frame's gamma */
				num += lg[c] * lw[c];
				den += lw[c] * lw[c];
			}
			/* The grey shading factor that fits best; the error in the frame's encoding. */
			double shade = num / den, err = 0;
			for (int c = 0; c < 3; c++)
				err = fmax(err, fabs(q[c] / 255.0 - pow(shade * lw[c], 1 / 2.2)));
			v->judged++;
			if (map)
				map[k * 4] = (unsigned char)fmin(255, err / COLOR_TOL * 128);
			v->sum_err += err;
			v->max_err = fmax(v->max_err, err);
			if (err > COLOR_TOL) {
				if (!v->bad++) {
					v->bad_x = x;
					v->bad_y = y;
					for (int c = 0; c < 3; c++) {
						v->bad_got[c] = q[c];
						v->bad_want[c] = a[c] * 255;
					}
				}
				run++;
				if (run > v->max_run)
					v->max_run = run;
			} else {
				run = 0;
			}
		}
	}
}

/* ---- flights ---- */

struct ctx {
	struct gl_context *gl;
	struct geo_body *gb;
	unsigned char *px;
	struct rays r;
};

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

static int setup(void **state)
{
	struct ctx *c = xcalloc(1, sizeof *c);
	c->gl = ctx_or_skip();
	char err[256];
	if (geo_body_create(WGS_A, WGS_F, &c->gb, err) < 0)
		return -1;
	c->px = xmalloc((size_t)FW * FH * 4);
	*state = c;
	return 0;
}

static int teardown(void **state)
{
	struct ctx *c = *state;
	rays_free(&c->r);
	free(c->px);
	geo_body_destroy(c->gb);
	if (c->gl)
		gl_context_destroy(c->gl);
	free(c);
	return 0;
}

/* flat_light: no haze and a sun overhead, so that the shading is a near-grey factor and all
 * visible ground is lit; else the viewer's default sun and haze. */
static struct view *make_view(struct ctx *c, struct view_source *src, bool flat_light)
{
	struct view_desc d = { .width = FW, .height = FH, .no_prefetch = true,
			       .background_set = true, .background = { 1, 0, 1 } };
	if (flat_light) {
		d.sun_el = 90;
		d.haze = -1;
	}
	struct view *v = NULL;
	char err[256] = "";
	int rc = view_create(gl_context_api(c->gl), src, &d, &v, err);
	if (rc < 0)
		fail_msg("view_create: %s", err);
	return v;
}

static void save_png(const char *dir, const char *name, int k, const unsigned char *px)
{
	char path[512], err[256];
	snprintf(path, sizeof path, "%s/%s_%02d.png", dir, name, k);
	for (char *s = path + strlen(dir) + 1; *s; s++)
		if (*s == ' ' || *s == ',')
			*s = '_';
	if (img_write(path, FW, FH, 4, IMG_U8, px, err) < 0)
		fprintf(stderr, "%s\n", err);
}

/* Renders camera cam complete, judges it; lambda > 0: judge continuity too. hlo, hhi: the
 * terrain's height bounds. Fails with the frame written to /tmp on a hole or smear. */
static void fly_frame(struct ctx *c, struct view *v, const struct view_camera *cam,
		      const char *name, int k, double hlo, double hhi, double lambda,
		      struct verdict *sum)
{
	struct view_frame_stats st;
	int rc = view_frame_complete(v, cam, test_slow(60), &st, NULL);
	if (rc < 0 || !st.complete)
		fail_msg("%s frame %d: not complete (%d)", name, k, rc);
	struct view_camera lc;
	view_last_camera(v, &lc);
	view_read_rgba(v, c->px);
	unsigned char bg[4];
	view_background_rgba(v, bg);
	rays_cast(&lc, c->gb, hlo, hhi, &c->r);
	struct verdict f = { 0 };
	judge_coverage(c->px, bg, &c->r, &f);
	const char *dir = getenv("VIEW_FLIGHT_PNG");
	unsigned char *map = NULL;
	if (dir && lambda > 0) {
		map = xcalloc((size_t)FW * FH, 4); /* red: error (128 = the tolerance), green: judged */
		for (size_t i = 0; i < (size_t)FW * FH; i++)
			map[i * 4 + 3] = 255;
	}
	if (lambda > 0)
		judge_continuity(c->px, &c->r, lambda, &f, map);
	if (dir) {
		save_png(dir, name, k, c->px);
		if (map) {
			char n2[80];
			snprintf(n2, sizeof n2, "%s_err", name);
			save_png(dir, n2, k, map);
			free(map);
		}
	}
	if (dir || getenv("VIEW_FLIGHT_VERBOSE"))
		fprintf(stderr,
			"%s %2d: lat %9.5f lon %10.5f alt %11.1f hdg %5.1f pitch %5.1f levels %d..%d: "
			"inside %5d holes %d stray %d; judged %5d bad %d max %.3f mean %.4f run %d\n",
			name, k, lc.lat, lc.lon, lc.alt, lc.heading, lc.pitch, st.lfirst, st.llast,
			f.inside, f.holes, f.stray, f.judged, f.bad, f.max_err,
			f.judged ? f.sum_err / f.judged : 0.0, f.max_run);
	bool fails = f.holes || f.stray;
	if (lambda > 0)
		fails |= f.bad > f.judged / 500 || f.max_run > 3 || f.max_err > COLOR_WRONG;
	if (fails && getenv("VIEW_FLIGHT_NOFAIL")) { /* debugging: see every frame */
		fprintf(stderr, "%s %d: FAILS\n", name, k);
		fails = false;
	}
	if (fails) {
		save_png("/tmp", name, k, c->px);
		fail_msg("%s frame %d (lat %.6f lon %.6f alt %.1f hdg %.1f pitch %.1f): "
			 "%d holes (first at %d,%d) in %d px inside the silhouette, %d terrain px "
			 "outside (first at %d,%d); %d of %d px off colour (first at %d,%d: got "
			 "%.0f %.0f %.0f, albedo %.0f %.0f %.0f), longest run %d; frame in /tmp/%s_%02d.png",
			 name, k, lc.lat, lc.lon, lc.alt, lc.heading, lc.pitch, f.holes, f.hole_x,
			 f.hole_y, f.inside, f.stray, f.stray_x, f.stray_y, f.bad, f.judged, f.bad_x,
			 f.bad_y, f.bad_got[0], f.bad_got[1], f.bad_got[2], f.bad_want[0],
			 f.bad_want[1], f.bad_want[2], f.max_run, name, k);
	}
	sum->inside += f.inside;
	sum->judged += f.judged;
	sum->max_err = fmax(sum->max_err, f.max_err);
	sum->agl = st.agl;
}

/* The point s metres from (lat, lon) along azimuth az, and the heading there towards the
 * point a little further on. */
static void walk(struct geo_body *gb, double lat, double lon, double az, double s, double *olat,
		 double *olon, double *ohdg)
{
	double la2, lo2, la3, lo3, d, a1, a2;
	geo_direct(gb, lat, lon, az, s, &la2, &lo2);
	geo_direct(gb, lat, lon, az, s + 1, &la3, &lo3);
	geo_inverse(gb, la2, lo2, la3, lo3, &d, &a1, &a2);
	*olat = la2;
	*olon = lo2;
	*ohdg = a1;
}

/* ---- 1: coverage from orbit to 2 m ---- */

/* A descent ending at (lat, lon): altitudes log-spaced from 20 000 km to 2 m over n frames,
 * each camera dist = min(3·alt, 3000 km) back along the geodesic that arrives from azimuth
 * `from`; pitch from straight down to 4° below the horizon; heading along the path plus a
 * turn. Then `ground` frames on at 2 m, 1.5 m apart. */
static void descent(struct ctx *c, struct view *v, const char *name, double lat, double lon,
		    double from, double turn, int n, int ground, double hlo, double hhi)
{
	struct verdict sum = { 0 };
	for (int k = 0; k < n + ground; k++) {
		double t = k < n ? (double)k / (n - 1) : 1;
		double alt = 2e7 * pow(2 / 2e7, t);
		double s = k < n ? fmin(3 * alt, 3e6) : 1.5 * (k - n + 1);
		double clat, clon, hdg;
		if (k < n) {
			walk(c->gb, lat, lon, from, s, &clat, &clon, &hdg);
			hdg = fmod(hdg + 180 + turn * (1 - t) + 720, 360); /* towards the end */
		} else { /* on past the end point, the way the descent was going */
			walk(c->gb, lat, lon, fmod(from + 180, 360), s, &clat, &clon, &hdg);
		}
		double pitch = -90 + 86 * pow(t, 0.6);
		struct view_camera cam = { clat, clon, alt, hdg, pitch, 60, 0, 0 };
		fly_frame(c, v, &cam, name, k, hlo, hhi, 0, &sum);
	}
	fprintf(stderr, "%s: %d frames, %d px inside the silhouette, no hole; %.2f m above the "
		"ground at the end\n", name, n + ground, sum.inside, sum.agl);
	assert_true(sum.inside > (n + ground) * FW * FH / 8);
	assert_true(fabs(sum.agl - 2) < 0.5);
}

static void coverage_orbit_to_ground(void **state)
{
	struct ctx *c = *state;
	if (!c->gl)
		skip();
	struct view_source *src;
	char err[256];
	int rc = view_source_local_create("conf/planets/procedural.ini",
					  &(struct view_source_local_opts){ .workers = 2, .cache_mb = 256 }, &src, err);
	if (rc < 0)
		fail_msg("%s", err);
	struct view *v = make_view(c, src, false);
	const struct view_body *b = view_get_body(v);
	/* The bounds the viewer assumes, 1 km wider for the chords of coarse rings. */
	double hlo = b->hmin - 1000, hhi = b->hmax + 1000;
	/* Ends 100 m east of the antimeridian, on land, coming from the west: crosses it at
	 * ~30 m, then goes on east along the ground at 2 m. */
	descent(c, v, "descent_antimeridian", 36.0, -179.999, 270, 120, 30, 5, hlo, hhi);
	/* From the north-east into the mountains of the northern continent, turning the other
	 * way. */
	descent(c, v, "descent_mountains", 54.5, 44.5, 40, -150, 26, 3, hlo, hhi);
	view_destroy(v);
	view_source_destroy(src);
}

/* ---- 2: poles and antimeridian: coverage and texture continuity ---- */

/* A straight flight at constant height alt: n frames along the geodesic from (lat, lon) at
 * azimuth az, `len` metres in all, looking ahead at `pitch`. */
static void crossing(struct ctx *c, const char *name, double lat, double lon, double az,
		     double len, double alt, double pitch, int n)
{
	double lambda = 4 * alt;
	struct view_source *src = synth_create(&lambda);
	struct view *v = make_view(c, src, true);
	struct verdict sum = { 0 };
	for (int k = 0; k < n; k++) {
		double clat, clon, hdg;
		walk(c->gb, lat, lon, az, len * k / (n - 1), &clat, &clon, &hdg);
		struct view_camera cam = { clat, clon, alt, hdg, pitch, 60, 0, 0 };
		fly_frame(c, v, &cam, name, k, -1, 1, lambda, &sum);
	}
	fprintf(stderr, "%s: %d frames, %d px inside the silhouette, no hole; %d px judged for "
		"colour, worst error %.3f\n", name, n, sum.inside, sum.judged, sum.max_err);
	assert_true(sum.judged > n * FW * FH / 10);
	view_destroy(v);
	view_source_destroy(src);
}

static void poles_and_antimeridian(void **state)
{
	struct ctx *c = *state;
	if (!c->gl)
		skip();
	static const struct {
		double alt, pitch;
	} hs[] = { { 500e3, -50 }, { 20e3, -35 }, { 100, -30 }, { 2, -40 } };
	for (size_t i = 0; i < sizeof hs / sizeof hs[0]; i++) {
		double alt = hs[i].alt, len = alt * 8;
		char name[64];
		/* Over the north pole: starts len/2 short of it heading north. */
		snprintf(name, sizeof name, "north_pole_%.0fm", alt);
		double lat0, lon0, h;
		walk(c->gb, 90, 0, 180 + 35, len / 2, &lat0, &lon0, &h);
		crossing(c, name, lat0, lon0, 0, len, alt, hs[i].pitch, 7);
		snprintf(name, sizeof name, "south_pole_%.0fm", alt);
		walk(c->gb, -90, 0, 80, len / 2, &lat0, &lon0, &h);
		crossing(c, name, lat0, lon0, 180, len, alt, hs[i].pitch, 7);
		snprintf(name, sizeof name, "antimeridian_%.0fm", alt);
		walk(c->gb, -40, 180, 250, len / 2, &lat0, &lon0, &h);
		crossing(c, name, lat0, lon0, 70, len, alt, hs[i].pitch, 7);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(coverage_orbit_to_ground),
		cmocka_unit_test(poles_and_antimeridian),
	};
	const char *only = getenv("VIEW_FLIGHT_ONLY"); /* a test name pattern, for debugging */
	if (only)
		cmocka_set_test_filter(only);
	return cmocka_run_group_tests(tests, setup, teardown);
}
