/* prefetch's tiles are the ones viewers ask for (issue 13): for a bbox and for a corridor, at
 * the equator, 46°N, 70°S and over the north pole, every tile of the window and ring of a
 * viewer focused anywhere in the region — on the lx it uses at that latitude, or the coarser
 * one hysteresis may keep — is in the job (viewers placed every quarter tile, independently of
 * the job's own enumeration), and the job is not much more than that. A long high-latitude
 * corridor (Oslo → Anchorage, 100 km wide) keeps its width all along the route: viewers at
 * 0.95 × the half-width on either side of the geodesic, placed with GeographicLib at the
 * route's own bearing there, are covered from start to end. The procedural planet (no data).
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

#include "common/clipmap.h"
#include "common/geo.h"
#include "common/xalloc.h"
#include "engine/planet.h"
#include "prefetch.h"
#include "support/prefetch_keys.h"

/* Every key the job yields (one layer), sorted; fails on a duplicate. The job's total, exact
 * once done, matches; the estimate made before is within a small factor of it. */
static void job_keys(const struct planet *p, const struct proto_prefetch *m, struct keyset *ks)
{
	uint64_t est;
	char err[256];
	if (prefetch_job_keys(p, m, ks, &est, err))
		fail_msg("prefetch job: %s", err);
	printf("  estimate %llu for %zu tiles (x%.2f)\n", (unsigned long long)est, ks->n,
	       (double)est / (double)(ks->n ? ks->n : 1));
}

static bool has(const struct keyset *ks, const struct tile_key *k)
{
	struct tile_key probe = *k;
	probe.node = 0;
	return keyset_has(ks, &probe);
}

/* What a viewer focused at (lat, lon) asks for at level ly holding lx: its window and ring.
 * Appends the missing ones' count to *missing and the distinct tiles to *want (may be NULL). */
static void check_viewer(const struct planet *p, const struct keyset *ks, int ly, int lx,
			 double lat, double lon, size_t *missing, struct keyset *want)
{
	struct grid_quad q;
	uint32_t T = p->tile_size;
	grid_window(lx, ly, T, CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
	for (int64_t dy = -1; dy <= q.nty; dy++)
		for (int64_t dx = -1; dx <= q.ntx; dx++) {
			int64_t y = (int64_t)q.ty0 + dy;
			if (y < 0 || y >= grid_tiles_y(ly))
				continue;
			struct tile_key k = { 0, grid_wrap_x(lx, (int64_t)q.tx0 + dx), (uint32_t)y,
					      (uint8_t)lx, (uint8_t)ly };
			if (!has(ks, &k)) {
				if (*missing < 5)
					printf("  missing (%u,%u) at (%d,%d) for a viewer at %.4f,%.4f\n",
					       k.x, k.y, lx, ly, lat, lon);
				(*missing)++;
			}
			if (want)
				want->k[want->n++] = k;
		}
}

/* The lx values a viewer at lat may hold at level ly: its own, and the coarser one that
 * hysteresis keeps for a viewer that came from higher latitudes. */
static int viewer_lx(int ly, double lat, int out[2])
{
	int lx = clipmap_level_lx(ly, lat, -1), n = 0;
	out[n++] = lx;
	if (lx > 0 && clipmap_level_lx(ly, lat, lx - 1) == lx - 1)
		out[n++] = lx - 1;
	return n;
}

/* A viewer keeps no lx other than the two viewer_lx names, whatever lx it comes with: one
 * that crossed several lx bands between two frames (fast, near a pole) or came from the pole
 * itself. Until 6 December clipmap_level_lx kept the current lx however coarse (a viewer from
 * the pole held lx 2 at level 7 as far as 77°N, where prefetch warms 5 and 6). */
static void any_current_lx_is_warmed(void **state)
{
	(void)state;
	int checked = 0;
	for (int ly = 1; ly <= 16; ly++)
		for (double lat = -89.9; lat < 90; lat += 0.37) {
			int lxs[2], n = viewer_lx(ly, lat, lxs);
			for (int cur = 0; cur <= ly + 1; cur++) {
				int lx = clipmap_level_lx(ly, lat, cur);
				if (lx != lxs[0] && !(n > 1 && lx == lxs[1]))
					fail_msg("level %d at %.2f° from lx %d: lx %d, prefetch warms %d%s",
						 ly, lat, cur, lx, lxs[0], n > 1 ? " and one coarser" : "");
				checked++;
			}
		}
	assert_true(checked > 10000);
}

static struct planet *load(void)
{
	struct planet *p = NULL;
	char err[256];
	if (planet_load("conf/planets/procedural.ini", &p, err) != 0)
		fail_msg("%s", err);
	return p;
}

static void bbox_covers_viewers(void **state)
{
	(void)state;
	struct planet *p = load();
	static const double places[][2] = { { 0.3, 20.0 }, { 46.5, 8.0 }, { -70.0, -60.0 },
					    { 89.5, 30.0 } };
	for (size_t pl = 0; pl < sizeof places / sizeof places[0]; pl++) {
		double lat = places[pl][0], lon = places[pl][1];
		struct proto_prefetch m = {
			.id = 1, .layers = 1, .shape = PROTO_SHAPE_BBOX, .lmin = 4, .lmax = 11,
			.bbox = { lon - 1, fmax(lat - 0.5, -90), lon + 1, fmin(lat + 0.5, 90) }
		};
		struct keyset ks;
		job_keys(p, &m, &ks);
		size_t missing = 0, cap = 0;
		struct keyset want = { NULL, 0 };
		for (int ly = m.lmin; ly <= m.lmax; ly++) {
			double step = 45.0 / (double)grid_tiles_y(ly); /* a quarter tile */
			for (double la = m.bbox.south; la <= m.bbox.north + 1e-9; la += step)
				for (double lo = m.bbox.west; lo <= m.bbox.east + 1e-9; lo += step) {
					int lxs[2];
					int n = viewer_lx(ly, la, lxs);
					for (int i = 0; i < n; i++) {
						if (want.n + 128 > cap) {
							cap = cap ? cap * 2 : 1 << 16;
							want.k = xrealloc(want.k, cap * sizeof *want.k);
						}
						check_viewer(p, &ks, ly, lxs[i], la, lo, &missing, &want);
					}
				}
		}
		qsort(want.k, want.n, sizeof *want.k, tile_key_cmp);
		size_t distinct = want.n ? 1 : 0;
		for (size_t i = 1; i < want.n; i++)
			distinct += tile_key_cmp(&want.k[i - 1], &want.k[i]) != 0;
		printf("bbox at %.1f,%.1f: %zu tiles in the job, %zu asked for by viewers, %zu "
		       "missing\n",
		       lat, lon, ks.n, distinct, missing);
		assert_int_equal(missing, 0);
		assert_true(ks.n <= distinct + distinct / 5); /* not much more */
		free(want.k);
		free(ks.k);
	}
	planet_unref(p);
}

/* Viewers along the route and at ±0.95 of the half-width across it, every tile. */
static void corridor_keeps_width(void **state)
{
	(void)state;
	struct planet *p = load();
	struct geo_body *body = p->body;
	struct proto_lonlat pts[2] = { { 10.75, 59.91 }, { -149.9, 61.22 } }; /* Oslo, Anchorage */
	const double width = 100e3;
	const int ly = 11;
	struct proto_prefetch m = { .id = 2, .layers = 1, .shape = PROTO_SHAPE_PATH, .lmin = ly,
				    .lmax = ly, .width_m = width, .npoints = 2, .points = pts };
	struct keyset ks;
	job_keys(p, &m, &ks);
	double s12, azi1, azi2;
	geo_inverse(body, pts[0].lat, pts[0].lon, pts[1].lat, pts[1].lon, &s12, &azi1, &azi2);
	double tile_m = M_PI * geo_body_a(body) / (double)grid_tiles_y(ly);
	size_t missing = 0, viewers = 0;
	size_t missing_late = 0; /* in the last tenth of the route */
	for (double s = 0; s <= s12; s += tile_m) {
		double lat, lon, azi;
		geo_direct_azi(body, pts[0].lat, pts[0].lon, azi1, s, &lat, &lon, &azi);
		for (int side = -1; side <= 1; side++) {
			double la = lat, lo = lon;
			if (side)
				geo_direct(body, lat, lon, azi + 90.0 * side, 0.95 * width / 2, &la, &lo);
			int lxs[2];
			int n = viewer_lx(ly, la, lxs);
			size_t before = missing;
			check_viewer(p, &ks, ly, lxs[0], la, lo, &missing, NULL);
			(void)n;
			viewers++;
			if (s > 0.9 * s12)
				missing_late += missing - before;
		}
	}
	printf("corridor Oslo-Anchorage, %.0f km wide, level %d: %zu tiles, %zu viewers, %zu "
	       "tiles missing (%zu in the last tenth)\n",
	       width / 1e3, ly, ks.n, viewers, missing, missing_late);
	assert_int_equal(missing, 0);
	free(ks.k);
	planet_unref(p);
}

/* The estimate against the count for corridors of several widths and latitudes, levels and a
 * single point (tiles of one layer): within a factor of 0.5-4 (job_keys asserts it). */
static void estimate_near_count(void **state)
{
	(void)state;
	struct planet *p = load();
	static const struct {
		struct proto_lonlat a, b;
		double width;
		int lmin, lmax;
		uint32_t npts;
	} cases[] = {
		{ { 139.69, 35.69 }, { -122.42, 37.77 }, 200e3, 5, 9, 2 }, /* Tokyo-San Francisco */
		{ { 10.75, 59.91 }, { -149.9, 61.22 }, 0, 6, 10, 2 },	   /* Oslo-Anchorage */
		{ { 8.0, 46.5 }, { 9.0, 46.6 }, 5e3, 10, 13, 2 },	   /* the Alps */
		{ { -60.0, -70.0 }, { 60.0, -70.0 }, 50e3, 4, 8, 2 },	   /* 70°S */
		{ { 0.0, 89.0 }, { 180.0, 89.0 }, 20e3, 4, 9, 2 },	   /* over the pole */
		{ { 20.0, 0.3 }, { 0, 0 }, 30e3, 8, 12, 1 },		   /* a point */
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		struct proto_lonlat pts[2] = { cases[i].a, cases[i].b };
		struct proto_prefetch m = { .id = 3, .layers = 1, .shape = PROTO_SHAPE_PATH,
					    .lmin = (uint8_t)cases[i].lmin,
					    .lmax = (uint8_t)cases[i].lmax, .width_m = cases[i].width,
					    .npoints = cases[i].npts, .points = pts };
		printf("path %zu:\n", i);
		struct keyset ks;
		job_keys(p, &m, &ks);
		free(ks.k);
	}
	planet_unref(p);
}

/* Runs job m to its end under the iterator limit `limit`: the wants it yielded (every layer)
 * into *made; returns prefetch_iter_error's code (0: done), its message in err. */
static int run_job(const struct planet *p, const struct proto_prefetch *m, uint64_t limit,
		   size_t *made, char err[256])
{
	struct prefetch_iter *it;
	assert_int_equal(prefetch_iter_create(p, m, limit, &it, err), 0);
	struct want w[512];
	size_t got;
	*made = 0;
	while ((got = prefetch_iter_next(it, w, 512)) > 0)
		*made += got;
	int rc = prefetch_iter_error(it, err);
	prefetch_iter_destroy(it);
	return rc;
}

/* A corridor over the pole (the keep-up bench's pole route at 80 km: 156.5 km wide at level 9,
 * every layer) runs within the daemon's default limit of 250 000 tiles. Its path was once
 * sampled some 50 times a tile near the pole (a step of cos(lat), not of the viewers' tiles
 * there, wider on their coarser lx), and the job stopped on its samples with 747 tiles to make. */
static void pole_corridor_within_limit(void **state)
{
	(void)state;
	struct planet *p = load();
	struct proto_lonlat pts[2] = { { 0.0, 88.0 }, { 180.0, 87.11 } };
	struct proto_prefetch m = { .id = 6, .layers = 0, .shape = PROTO_SHAPE_PATH, .lmin = 9,
				    .lmax = 9, .width_m = 156.5e3, .npoints = 2, .points = pts };
	char err[256];
	size_t n;
	if (run_job(p, &m, 250000, &n, err))
		fail_msg("%s", err);
	printf("pole corridor at level 9: %zu tiles (every layer)\n", n);
	assert_true(n > 0 && n < 10000);
	planet_unref(p);
}

/* The keep-up bench's pole corridors (its routes at 80, 50 and 20 km: levels 9-11, 8 tile
 * heights wide, from 88°N over the pole to 86.4°N beyond it) run within the daemon's limit of
 * 250 000 tiles and hold every tile of every viewer in them: viewers every quarter tile along
 * the route (through the pole itself) and across it out to 0.95 of the half-width, on each lx
 * they may hold. Until 6 December the corridor was sampled at a step of cos(lat) of a tile,
 * some 50 times the tiles viewers hold near the pole, and at level 10 the job stopped on its
 * samples (more than 250 000) with 1 308 tiles to make. */
static void pole_corridors_cover_viewers(void **state)
{
	(void)state;
	struct planet *p = load();
	struct geo_body *body = p->body;
	struct proto_lonlat pts[3] = { { 0.0, 88.0 }, { 0.0, 90.0 }, { 180.0, 86.4 } };
	for (int ly = 9; ly <= 11; ly++) {
		double tile_m = M_PI * geo_body_a(body) / (double)grid_tiles_y(ly);
		double width = 8 * tile_m;
		struct proto_prefetch m = { .id = 7, .layers = 0, .shape = PROTO_SHAPE_PATH,
					    .lmin = (uint8_t)ly, .lmax = (uint8_t)ly,
					    .width_m = width, .npoints = 3, .points = pts };
		char err[256];
		size_t all;
		if (run_job(p, &m, 250000, &all, err))
			fail_msg("level %d: %s", ly, err);
		m.layers = 1;
		struct keyset ks;
		job_keys(p, &m, &ks);
		size_t missing = 0, viewers = 0;
		for (uint32_t i = 0; i + 1 < 3; i++) {
			double s12, azi1, azi2;
			geo_inverse(body, pts[i].lat, pts[i].lon, pts[i + 1].lat, pts[i + 1].lon, &s12,
				    &azi1, &azi2);
			for (double s = 0; s <= s12; s += tile_m / 4) {
				double lat, lon, azi;
				geo_direct_azi(body, pts[i].lat, pts[i].lon, azi1, s, &lat, &lon, &azi);
				for (double off = -0.95 * width / 2; off <= 0.95 * width / 2 + 1;
				     off += tile_m / 4) {
					double la = lat, lo = lon;
					if (fabs(off) > 1)
						geo_direct(body, lat, lon, azi + 90.0, off, &la, &lo);
					int lxs[2], n = viewer_lx(ly, la, lxs);
					for (int q = 0; q < n; q++)
						check_viewer(p, &ks, ly, lxs[q], la, lo, &missing, NULL);
					viewers++;
				}
			}
		}
		printf("pole corridor at level %d, %.0f km wide: %zu tiles (every layer), %zu of one "
		       "layer, %zu viewers, %zu tiles missing\n",
		       ly, width / 1e3, all, ks.n, viewers, missing);
		assert_int_equal(missing, 0);
		assert_true(all > 0 && all < 20000);
		free(ks.k);
	}
	planet_unref(p);
}

/* The job's limit counts tiles, not the corridor's samples: a one-layer corridor along the
 * equator (level 11, 6 700 km long, 200 km wide, ~4 foci a tile on the half-tile grid) runs
 * under a limit just above its tile count and stops only under one below it. */
static void limit_counts_tiles(void **state)
{
	(void)state;
	struct planet *p = load();
	struct proto_lonlat pts[2] = { { -10.0, 0.2 }, { 50.0, 0.2 } };
	struct proto_prefetch m = { .id = 8, .layers = 1, .shape = PROTO_SHAPE_PATH, .lmin = 11,
				    .lmax = 11, .width_m = 200e3, .npoints = 2, .points = pts };
	struct keyset ks;
	job_keys(p, &m, &ks);
	size_t n = ks.n;
	free(ks.k);
	for (int under = 0; under <= 1; under++) {
		uint64_t limit = under ? n - n / 4 : n + n / 16;
		char err[256];
		size_t all;
		int rc = run_job(p, &m, limit, &all, err);
		printf("equator corridor, %zu tiles, limit %llu: %zu made, %s\n", n,
		       (unsigned long long)limit, all, rc ? err : "done");
		if (under)
			assert_int_not_equal(rc, 0);
		else
			assert_true(rc == 0 && all == n);
	}
	planet_unref(p);
}

/* Hostile sizes (issue 14) are seen by the estimate, which enumerates nothing: the 67-byte
 * corridor 9.55e6 m wide at level 22 and the whole planet at level 11 (25 M tiles); an
 * iterator whose level passes its limit stops with -E2BIG. */
static void hostile_sizes(void **state)
{
	(void)state;
	struct planet *p = load();
	char err[256];
	struct prefetch_estimate e;
	struct proto_lonlat pt = { 8.0, 46.0 };
	struct proto_prefetch wide = { .id = 4, .planet = "procedural", .layers = 0,
				       .shape = PROTO_SHAPE_PATH, .lmin = 22, .lmax = 22,
				       .width_m = 9.55e6, .npoints = 1, .points = &pt };
	assert_int_equal(prefetch_estimate(p, &wide, &e, err), 0);
	printf("wide corridor: about %llu tiles\n", (unsigned long long)e.tiles);
	assert_true(e.tiles > 4000000); /* [prefetch] max_tiles' default */
	struct proto_prefetch planet = { .id = 5, .layers = 0, .shape = PROTO_SHAPE_BBOX,
					 .lmin = 0, .lmax = 11,
					 .bbox = { -180, -90, 180, 90 } };
	assert_int_equal(prefetch_estimate(p, &planet, &e, err), 0);
	printf("whole planet to level 11: about %llu tiles (level 11: %llu)\n",
	       (unsigned long long)e.tiles, (unsigned long long)e.level_tiles[11]);
	assert_true(e.tiles > 20000000 && e.tiles < 80000000);
	/* the finest level every lx: rows × columns × lx in use */
	struct prefetch_iter *it;
	planet.lmin = planet.lmax = 9;
	assert_int_equal(prefetch_iter_create(p, &planet, 100000, &it, err), 0);
	struct want w[64];
	assert_int_equal(prefetch_iter_next(it, w, 64), 0);
	assert_int_equal(prefetch_iter_error(it, err), -E2BIG);
	printf("%s\n", err);
	assert_non_null(strstr(err, "level 9 has more than 100000 tiles"));
	prefetch_iter_destroy(it);
	wide.lmin = wide.lmax = 16;
	wide.width_m = 2e6;
	assert_int_equal(prefetch_iter_create(p, &wide, 100000, &it, err), 0);
	assert_int_equal(prefetch_iter_next(it, w, 64), 0);
	assert_int_equal(prefetch_iter_error(it, err), -E2BIG);
	prefetch_iter_destroy(it);
	/* bad requests */
	planet.lmax = 23;
	assert_int_equal(prefetch_estimate(p, &planet, &e, err), -EINVAL);
	assert_non_null(strstr(err, "max_level 22"));
	planet.lmax = 9;
	planet.layers = 1u << 5;
	assert_int_equal(prefetch_estimate(p, &planet, &e, err), -EINVAL);
	planet_unref(p);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(any_current_lx_is_warmed),
		cmocka_unit_test(bbox_covers_viewers),
		cmocka_unit_test(corridor_keeps_width),
		cmocka_unit_test(estimate_near_count),
		cmocka_unit_test(hostile_sizes),
		cmocka_unit_test(pole_corridor_within_limit),
		cmocka_unit_test(pole_corridors_cover_viewers),
		cmocka_unit_test(limit_counts_tiles),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
