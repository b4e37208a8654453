/* Prefetch coverages (issue 13): a polygon's job is the tiles viewers focused anywhere inside
 * it ask for, with bbox prefetch's per-latitude level choice. Checked as exact tile sets: a
 * rectangle's job is its bbox's job (equator, 46°N, across the antimeridian, a polar cap); a
 * multipolygon's is the union of its parts'; a triangle's covers every viewer placed every
 * quarter tile inside it (brute force, independent of the row intervals) and not much more;
 * a hole drops the tiles no viewer inside reaches. Then the files: GeoJSON written here
 * (RFC 7946 antimeridian split, EPSG:3857, a polar stereographic square round the pole, a
 * hole), a GeoPackage made with ogr2ogr (skipped without it), and bad files whose error names
 * them. The procedural planet (no data).
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
#include <unistd.h>

#include "client/ctl/coverage.h"
#include "common/clipmap.h"
#include "common/lonpoly.h"
#include "common/xalloc.h"
#include "engine/planet.h"
#include "prefetch.h"
#include "support/prefetch_keys.h"

/* Every key of the job (one layer), sorted; fails on a duplicate or a bad estimate. */
static void job_keys(const struct planet *p, const struct proto_prefetch *m, struct keyset *ks)
{
	uint64_t est;
	char err[256];
	if (prefetch_job_keys(p, m, ks, &est, err))
		fail_msg("prefetch job: %s", err);
}

/* a and b hold the same tiles; else prints the first few differences and fails. */
static void same_set(const char *what, const struct keyset *a, const struct keyset *b)
{
	size_t only_a = 0, only_b = 0;
	for (size_t i = 0; i < a->n; i++)
		if (!keyset_has(b, &a->k[i]) && only_a++ < 3)
			printf("  %s: (%u,%u) at (%u,%u) only in the polygon's job\n", what,
			       a->k[i].x, a->k[i].y, a->k[i].lx, a->k[i].ly);
	for (size_t i = 0; i < b->n; i++)
		if (!keyset_has(a, &b->k[i]) && only_b++ < 3)
			printf("  %s: (%u,%u) at (%u,%u) only in the reference\n", what, b->k[i].x,
			       b->k[i].y, b->k[i].lx, b->k[i].ly);
	printf("%s: %zu tiles, %zu in the reference; %zu / %zu differ\n", what, a->n, b->n,
	       only_a, only_b);
	assert_int_equal(only_a, 0);
	assert_int_equal(only_b, 0);
}

static struct planet *load(void)
{
	struct planet *p = NULL;
	char err[256];
	if (planet_load("conf/planets/procedural.ini", &p, err) != 0)
		fail_msg("%s", err);
	return p;
}

static struct proto_prefetch poly_job(int lmin, int lmax, uint32_t nrings, const uint32_t *rings,
				      const struct proto_lonlat *pts)
{
	uint32_t n = 0;
	for (uint32_t i = 0; i < nrings; i++)
		n += rings[i];
	return (struct proto_prefetch){ .id = 1, .layers = 1, .shape = PROTO_SHAPE_POLYGON,
					.lmin = (uint8_t)lmin, .lmax = (uint8_t)lmax,
					.nrings = nrings, .rings = rings, .npoints = n,
					.points = pts };
}

static void rect_ring(struct proto_lonlat *o, double w, double s, double e, double n)
{
	o[0] = (struct proto_lonlat){ w, s };
	o[1] = (struct proto_lonlat){ e, s };
	o[2] = (struct proto_lonlat){ e, n };
	o[3] = (struct proto_lonlat){ w, n };
}

static void brute(const struct planet *p, const struct lonpoly *poly, int lmin, int lmax,
		  struct keyset *ref);

/* A rectangle (unwrapped past 180° where it crosses) is its bbox, exactly; over a pole, where
 * the bbox's rows take a margin, a subset of it that still holds every tile of the viewers
 * inside (brute force, levels 3-8). */
static void rect_is_bbox(void **state)
{
	(void)state;
	struct planet *p = load();
	static const struct {
		const char *name;
		double w, s, e, n; /* the polygon's (unwrapped) */
		struct geo_rect bbox;
	} cases[] = {
		{ "equator", 19.0, -0.2, 21.0, 0.8, { 19.0, -0.2, 21.0, 0.8 } },
		{ "46N", 7.0, 45.5, 9.5, 47.0, { 7.0, 45.5, 9.5, 47.0 } },
		{ "antimeridian", 178.5, -17.0, 181.5, -15.5, { 178.5, -17.0, -178.5, -15.5 } },
		{ "70S", -62.0, -71.0, -58.0, -69.0, { -62.0, -71.0, -58.0, -69.0 } },
		{ "polar cap", -180.0, 88.5, 180.0, 90.0, { -180.0, 88.5, 180.0, 90.0 } },
	};
	for (size_t c = 0; c < sizeof cases / sizeof cases[0]; c++) {
		struct proto_lonlat r[4];
		rect_ring(r, cases[c].w, cases[c].s, cases[c].e, cases[c].n);
		uint32_t rings[1] = { 4 };
		struct proto_prefetch m = poly_job(3, 10, 1, rings, r);
		struct proto_prefetch b = { .id = 1, .layers = 1, .shape = PROTO_SHAPE_BBOX,
					    .lmin = 3, .lmax = 10, .bbox = cases[c].bbox };
		struct keyset kp, kb;
		job_keys(p, &m, &kp);
		job_keys(p, &b, &kb);
		if (cases[c].n < 90.0) {
			same_set(cases[c].name, &kp, &kb);
		} else {
			size_t extra = 0, missing = 0;
			for (size_t i = 0; i < kp.n; i++)
				extra += !keyset_has(&kb, &kp.k[i]);
			struct lonpoly lp = { 1, rings, r };
			struct keyset ref;
			brute(p, &lp, 3, 8, &ref);
			for (size_t i = 0; i < ref.n; i++)
				missing += !keyset_has(&kp, &ref.k[i]);
			size_t upto8 = 0;
			for (size_t i = 0; i < kp.n; i++)
				upto8 += kp.k[i].ly <= 8;
			printf("%s: %zu tiles, %zu in the bbox's job, %zu not in it; levels 3-8: "
			       "%zu, viewers inside ask for %zu, %zu missing\n",
			       cases[c].name, kp.n, kb.n, extra, upto8, ref.n, missing);
			assert_int_equal(extra, 0);
			assert_int_equal(missing, 0);
			assert_true(upto8 <= ref.n + ref.n / 5);
			free(ref.k);
		}
		free(kp.k);
		free(kb.k);
	}
	planet_unref(p);
}

/* Two far apart rectangles in one polygon (two rings), and an RFC 7946 antimeridian split
 * (two rectangles meeting at ±180°): the union of their bboxes' jobs. */
static void multipolygon_is_union(void **state)
{
	(void)state;
	struct planet *p = load();
	static const double parts[][2][4] = {
		{ { 5.0, 44.0, 7.0, 45.5 }, { -75.0, 40.0, -73.0, 41.0 } },
		{ { 170.0, -20.0, 180.0, -15.0 }, { -180.0, -20.0, -172.0, -15.0 } },
	};
	for (size_t c = 0; c < 2; c++) {
		struct proto_lonlat r[8];
		rect_ring(r, parts[c][0][0], parts[c][0][1], parts[c][0][2], parts[c][0][3]);
		rect_ring(r + 4, parts[c][1][0], parts[c][1][1], parts[c][1][2], parts[c][1][3]);
		uint32_t rings[2] = { 4, 4 };
		struct proto_prefetch m = poly_job(2, 9, 2, rings, r);
		struct keyset kp, ka, kb;
		job_keys(p, &m, &kp);
		struct proto_prefetch b = { .id = 1, .layers = 1, .shape = PROTO_SHAPE_BBOX,
					    .lmin = 2, .lmax = 9 };
		b.bbox = (struct geo_rect){ parts[c][0][0], parts[c][0][1], parts[c][0][2],
					    parts[c][0][3] };
		job_keys(p, &b, &ka);
		b.bbox = (struct geo_rect){ parts[c][1][0], parts[c][1][1], parts[c][1][2],
					    parts[c][1][3] };
		job_keys(p, &b, &kb);
		ka.k = xrealloc(ka.k, (ka.n + kb.n) * sizeof *ka.k);
		memcpy(ka.k + ka.n, kb.k, kb.n * sizeof *kb.k);
		ka.n += kb.n;
		keyset_sort_unique(&ka);
		same_set(c ? "antimeridian split" : "two parts", &kp, &ka);
		free(kp.k);
		free(ka.k);
		free(kb.k);
	}
	planet_unref(p);
}

/* The tiles a viewer focused at (lat, lon) asks for at level ly: its window and ring, on its
 * own lx there and on the coarser one it may keep (as tests/unit/test_prefetch.c). */
static void viewer_tiles(const struct planet *p, int ly, double lat, double lon,
			 struct keyset *out, size_t *cap)
{
	int lx = clipmap_level_lx(ly, lat, -1), lxs[2] = { lx, lx }, n = 1;
	if (lx > 0 && clipmap_level_lx(ly, lat, lx - 1) == lx - 1)
		lxs[n++] = lx - 1;
	for (int i = 0; i < n; i++) {
		struct grid_quad q;
		uint32_t T = p->tile_size;
		grid_window(lxs[i], ly, T, CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
		for (int64_t dy = -1; dy <= q.nty; dy++)
			for (int64_t dx = -1; dx <= q.ntx; dx++) {
				int64_t y = (int64_t)q.ty0 + dy;
				if (y < 0 || y >= grid_tiles_y(ly))
					continue;
				if (out->n == *cap) {
					*cap = *cap ? *cap * 2 : 1 << 16;
					out->k = xrealloc(out->k, *cap * sizeof *out->k);
				}
				out->k[out->n++] = (struct tile_key){
					0, grid_wrap_x(lxs[i], (int64_t)q.tx0 + dx), (uint32_t)y,
					(uint8_t)lxs[i], (uint8_t)ly
				};
			}
	}
}

/* Brute force: viewers every quarter tile inside the polygon and along its edges. */
static void brute(const struct planet *p, const struct lonpoly *poly, int lmin, int lmax,
		  struct keyset *ref)
{
	double w, s, e, n;
	lonpoly_bounds(poly, &w, &s, &e, &n);
	size_t cap = 0;
	ref->k = NULL;
	ref->n = 0;
	for (int ly = lmin; ly <= lmax; ly++) {
		double step = 45.0 / (double)grid_tiles_y(ly);
		for (double la = s; la <= n + 1e-9; la += step)
			for (double lo = w; lo <= e + 1e-9; lo += step)
				if (lonpoly_contains(poly, lo, la))
					viewer_tiles(p, ly, la, lo, ref, &cap);
		size_t base = 0;
		for (uint32_t r = 0; r < poly->nrings; r++) {
			for (uint32_t i = 0; i < poly->rings[r]; i++) {
				const struct proto_lonlat *a = &poly->pts[base + i],
							  *b = &poly->pts[base + (i + 1) % poly->rings[r]];
				double len = hypot(b->lon - a->lon, b->lat - a->lat);
				for (double t = 0; t <= 1; t += step / len)
					viewer_tiles(p, ly, a->lat + t * (b->lat - a->lat),
						     a->lon + t * (b->lon - a->lon), ref, &cap);
			}
			base += poly->rings[r];
		}
		keyset_sort_unique(ref);
	}
}

/* A triangle and a square with a hole, at 46°N: every tile the brute force's viewers ask for
 * is in the job, and the job is not much more; the hole's middle is left out. */
static void triangle_and_hole(void **state)
{
	(void)state;
	struct planet *p = load();
	struct proto_lonlat tri[3] = { { 6.0, 45.0 }, { 10.5, 45.8 }, { 7.5, 48.0 } };
	uint32_t r1[1] = { 3 };
	struct proto_prefetch m = poly_job(4, 10, 1, r1, tri);
	struct keyset kp, ref;
	job_keys(p, &m, &kp);
	struct lonpoly lp = { 1, r1, tri };
	brute(p, &lp, 4, 10, &ref);
	size_t missing = 0;
	for (size_t i = 0; i < ref.n; i++)
		if (!keyset_has(&kp, &ref.k[i]) && missing++ < 3)
			printf("  triangle: viewer tile (%u,%u) at (%u,%u) missing\n", ref.k[i].x,
			       ref.k[i].y, ref.k[i].lx, ref.k[i].ly);
	printf("triangle: %zu tiles, %zu asked for by viewers inside, %zu missing\n", kp.n, ref.n,
	       missing);
	assert_int_equal(missing, 0);
	assert_true(kp.n <= ref.n + ref.n / 50);
	free(kp.k);
	free(ref.k);

	/* 6° square with a 4° hole: at level 10 (1024 rows) the hole's middle is ~11 tiles from
	 * any viewer inside; the square without the hole has it */
	struct proto_lonlat sq[8];
	rect_ring(sq, 5.0, 43.0, 11.0, 49.0);
	rect_ring(sq + 4, 6.0, 44.0, 10.0, 48.0);
	uint32_t r2[2] = { 4, 4 };
	struct proto_prefetch mh = poly_job(10, 10, 2, r2, sq), ms = poly_job(10, 10, 1, r2, sq);
	struct keyset kh, ks;
	job_keys(p, &mh, &kh);
	job_keys(p, &ms, &ks);
	int lx = clipmap_level_lx(10, 46.0, -1);
	struct grid_quad q;
	grid_window(lx, 10, p->tile_size, p->tile_size, 8.0, 46.0, &q);
	struct tile_key mid = { 0, q.tx0, q.ty0, (uint8_t)lx, 10 };
	assert_true(keyset_has(&ks, &mid));
	assert_false(keyset_has(&kh, &mid));
	struct lonpoly lh = { 2, r2, sq };
	brute(p, &lh, 10, 10, &ref);
	missing = 0;
	for (size_t i = 0; i < ref.n; i++)
		missing += !keyset_has(&kh, &ref.k[i]);
	printf("hole: %zu tiles (%zu without it), %zu asked for by viewers, %zu missing\n", kh.n,
	       ks.n, ref.n, missing);
	assert_int_equal(missing, 0);
	assert_true(kh.n < ks.n);
	assert_true(kh.n <= ref.n + ref.n / 50);
	free(kh.k);
	free(ks.k);
	free(ref.k);
	planet_unref(p);
}

/* ---- files ---------------------------------------------------------------------------- */

static char dir[64];

static const char *write_file(const char *name, const char *text)
{
	static char path[8][128];
	static int k;
	char *out = path[k++ % 8];
	snprintf(out, 128, "%s/%s", dir, name);
	FILE *f = fopen(out, "w");
	assert_non_null(f);
	fputs(text, f);
	fclose(f);
	return out;
}

static int setup(void **state)
{
	(void)state;
	snprintf(dir, sizeof dir, "/tmp/test_coverage.XXXXXX");
	return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	return system(cmd) == 0 ? 0 : -1;
}

static struct lonpoly as_poly(const struct coverage *cv)
{
	return (struct lonpoly){ cv->nrings, cv->rings, cv->pts };
}

/* RFC 7946's antimeridian split and a hole read back as rings whose jobs are those above. */
static void geojson_files(void **state)
{
	(void)state;
	struct planet *p = load();
	const char *f = write_file(
		"split.geojson",
		"{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		"\"properties\":{},\"geometry\":{\"type\":\"MultiPolygon\",\"coordinates\":["
		"[[[170,-20],[180,-20],[180,-15],[170,-15],[170,-20]]],"
		"[[[-180,-20],[-172,-20],[-172,-15],[-180,-15],[-180,-20]]]]}},"
		"{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Point\","
		"\"coordinates\":[0,0]}}]}");
	struct coverage cv;
	char err[256];
	assert_int_equal(coverage_read(f, &cv, err), 0);
	assert_int_equal(cv.nrings, 2);
	assert_int_equal(cv.npoints, 8);
	assert_int_equal(cv.skipped, 1); /* the point */
	struct proto_prefetch m = poly_job(2, 9, cv.nrings, cv.rings, cv.pts);
	struct proto_prefetch b = { .id = 1, .layers = 1, .shape = PROTO_SHAPE_BBOX, .lmin = 2,
				    .lmax = 9, .bbox = { 170.0, -20.0, -172.0, -15.0 } };
	struct keyset kp, kb;
	job_keys(p, &m, &kp);
	job_keys(p, &b, &kb);
	same_set("GeoJSON antimeridian split", &kp, &kb);
	free(kp.k);
	free(kb.k);
	coverage_free(&cv);

	/* one ring across the antimeridian, written with longitudes -178..178 the long way
	 * round would be wrong: the ring is unwrapped to 178..182 */
	f = write_file("across.geojson",
		       "{\"type\":\"Polygon\",\"coordinates\":[[[178,10],[-178,10],[-178,12],"
		       "[178,12],[178,10]]]}");
	assert_int_equal(coverage_read(f, &cv, err), 0);
	assert_int_equal(cv.nrings, 1);
	struct lonpoly lp = as_poly(&cv);
	assert_true(lonpoly_contains(&lp, 180.0, 11.0) || lonpoly_contains(&lp, -180.0, 11.0));
	assert_false(lonpoly_contains(&lp, 0.0, 11.0));
	double w, s, e, n;
	lonpoly_bounds(&lp, &w, &s, &e, &n);
	assert_true(e - w < 4.0 + 1e-9);
	coverage_free(&cv);

	/* a hole */
	f = write_file("hole.geojson",
		       "{\"type\":\"Polygon\",\"coordinates\":[[[5,43],[11,43],[11,49],[5,49],[5,43]],"
		       "[[6,44],[10,44],[10,48],[6,48],[6,44]]]}");
	assert_int_equal(coverage_read(f, &cv, err), 0);
	assert_int_equal(cv.nrings, 2);
	lp = as_poly(&cv);
	assert_true(lonpoly_contains(&lp, 5.5, 46.0));
	assert_false(lonpoly_contains(&lp, 8.0, 46.0));
	coverage_free(&cv);
	planet_unref(p);
}

/* Projected CRSs: a Web Mercator rectangle becomes its lon/lat rectangle; a polar
 * stereographic square centred on the north pole (EPSG:3413) becomes a cap closed through the
 * pole. */
static void projected_files(void **state)
{
	(void)state;
	/* 6°..8° E, 45°..46° N in EPSG:3857 */
	const char *f = write_file(
		"merc.geojson",
		"{\"type\":\"FeatureCollection\",\"crs\":{\"type\":\"name\",\"properties\":{\"name\":"
		"\"urn:ogc:def:crs:EPSG::3857\"}},\"features\":[{\"type\":\"Feature\",\"properties\""
		":{},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[667916.9447596414,"
		"5621521.486192066],[890555.9263461886,5621521.486192066],[890555.9263461886,"
		"5780349.220256351],[667916.9447596414,5780349.220256351],[667916.9447596414,"
		"5621521.486192066]]]}}]}");
	struct coverage cv;
	char err[256];
	assert_int_equal(coverage_read(f, &cv, err), 0);
	struct lonpoly lp = as_poly(&cv);
	double w, s, e, n;
	lonpoly_bounds(&lp, &w, &s, &e, &n);
	printf("EPSG:3857 rectangle: %.6f %.6f %.6f %.6f\n", w, s, e, n);
	assert_true(fabs(w - 6.0) < 1e-6 && fabs(e - 8.0) < 1e-6);
	assert_true(fabs(s - 45.0) < 1e-6 && fabs(n - 46.0) < 1e-6);
	coverage_free(&cv);

	/* ±1000 km round the pole in EPSG:3413: edges at ~81°N, corners at ~77°N */
	f = write_file(
		"polar.geojson",
		"{\"type\":\"FeatureCollection\",\"crs\":{\"type\":\"name\",\"properties\":{\"name\":"
		"\"urn:ogc:def:crs:EPSG::3413\"}},\"features\":[{\"type\":\"Feature\",\"properties\""
		":{},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[[-1000000,-1000000],"
		"[1000000,-1000000],[1000000,1000000],[-1000000,1000000],[-1000000,-1000000]]]}}]}");
	assert_int_equal(coverage_read(f, &cv, err), 0);
	lp = as_poly(&cv);
	lonpoly_bounds(&lp, &w, &s, &e, &n);
	for (double lon = w + 0.01; lon < w + 360; lon += 7.5) {
		assert_true(lonpoly_contains(&lp, lon, 85.0));
		assert_false(lonpoly_contains(&lp, lon, 75.0));
	}
	printf("EPSG:3413 square: %zu points, lon %.3f..%.3f, lat %.3f..%.3f\n",
	       (size_t)cv.npoints, w, e, s, n);
	assert_true(n == 90.0 && s > 76.0 && s < 78.5);
	assert_true(e - w >= 360.0 - 1e-6);
	coverage_free(&cv);
}

/* A GeoPackage made from the hole's GeoJSON with ogr2ogr reads back the same rings. */
static void geopackage(void **state)
{
	(void)state;
	if (system("command -v ogr2ogr >/dev/null 2>&1") != 0) {
		printf("SKIP: ogr2ogr not installed (gdal-bin): no GeoPackage made\n");
		skip();
	}
	const char *src = write_file(
		"g.geojson", "{\"type\":\"Polygon\",\"coordinates\":[[[5,43],[11,43],[11,49],[5,49],"
			     "[5,43]],[[6,44],[10,44],[10,48],[6,48],[6,44]]]}");
	char gpkg[160], cmd[512];
	snprintf(gpkg, sizeof gpkg, "%s/g.gpkg", dir);
	snprintf(cmd, sizeof cmd, "ogr2ogr -f GPKG %s %s 2>&1", gpkg, src);
	assert_int_equal(system(cmd), 0);
	struct coverage a, b;
	char err[256];
	assert_int_equal(coverage_read(src, &a, err), 0);
	assert_int_equal(coverage_read(gpkg, &b, err), 0);
	assert_int_equal(a.nrings, b.nrings);
	assert_int_equal(a.npoints, b.npoints);
	for (uint32_t i = 0; i < a.nrings; i++)
		assert_int_equal(a.rings[i], b.rings[i]);
	/* the same ring, maybe from another vertex or the other way round: same area inside */
	struct lonpoly la = as_poly(&a), lb = as_poly(&b);
	for (double lon = 4.75; lon < 11.5; lon += 0.5)
		for (double lat = 42.75; lat < 49.5; lat += 0.5)
			assert_int_equal(lonpoly_contains(&la, lon, lat),
					 lonpoly_contains(&lb, lon, lat));
	coverage_free(&a);
	coverage_free(&b);
}

/* Bad files: each error names the file and what is wrong. */
static void bad_files(void **state)
{
	(void)state;
	struct coverage cv;
	char err[256], missing[160];
	snprintf(missing, sizeof missing, "%s/nope.geojson", dir);
	assert_int_equal(coverage_read(missing, &cv, err), -ENOENT);
	printf("missing: %s\n", err);
	assert_non_null(strstr(err, missing));
	const char *f = write_file("junk.geojson", "{ this is not json");
	assert_true(coverage_read(f, &cv, err) < 0);
	printf("junk: %s\n", err);
	assert_non_null(strstr(err, f));
	f = write_file("line.geojson",
		       "{\"type\":\"LineString\",\"coordinates\":[[0,0],[1,1],[2,0]]}");
	assert_int_equal(coverage_read(f, &cv, err), -EINVAL);
	printf("line: %s\n", err);
	assert_non_null(strstr(err, f));
	assert_non_null(strstr(err, "no polygon"));
	/* more points than the protocol carries */
	size_t cap = 64 + 40 * (PROTO_MAX_POLY + 10);
	char *big = xmalloc(cap), *q = big;
	q += sprintf(q, "{\"type\":\"Polygon\",\"coordinates\":[[");
	for (int i = 0; i <= PROTO_MAX_POLY + 4; i++) {
		double a = 2 * M_PI * i / (PROTO_MAX_POLY + 5);
		q += sprintf(q, "[%.9f,%.9f],", 10 + cos(a), 10 + sin(a));
	}
	q += sprintf(q, "[11,10]]]}");
	f = write_file("big.geojson", big);
	free(big);
	assert_int_equal(coverage_read(f, &cv, err), -E2BIG);
	printf("big: %s\n", err);
	assert_non_null(strstr(err, f));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(rect_is_bbox),	       cmocka_unit_test(multipolygon_is_union),
		cmocka_unit_test(triangle_and_hole),   cmocka_unit_test(geojson_files),
		cmocka_unit_test(projected_files),     cmocka_unit_test(geopackage),
		cmocka_unit_test(bad_files),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
