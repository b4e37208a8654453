/* test_vector_node — the `vector` node on GeoJSON written to a temp dir: the area a spherical
 * cap covers (coverage × each texel's area on the sphere) against the cap's analytic area at
 * several levels, also across the antimeridian and around a pole; a 100 m line measured
 * across in fine tiles (east-west at 45° and 70°: the cos φ conversion, north-south); tiles
 * that meet at the antimeridian and at a pole agree on their border texels; a mask through
 * `blend` mode mask flattens exactly the polygon, and with a feather blends into the terrain
 * over that distance on the ground (exact inside, untouched beyond, as the reference distance
 * across tile borders, the antimeridian and near a pole); styles by attribute; and files
 * refused at load with a message naming them. */
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

#include "common/grid.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"
#include "support/node_ini.h"

#define R 6371000.0
#define T 64

static char dir[64];
static struct planet pl;

static const char *tpath(const char *name)
{
	static char buf[4][128];
	static int k;
	k = (k + 1) % 4;
	snprintf(buf[k], sizeof buf[k], "%s/%s", dir, name);
	return buf[k];
}

static int setup(void **state)
{
	(void)state;
	snprintf(dir, sizeof dir, "/tmp/test_vector_node.XXXXXX");
	if (!mkdtemp(dir))
		return -1;
	memset(&pl, 0, sizeof pl);
	pl.dir = dir;
	pl.tile_size = T;
	pl.max_level = 20;
	pl.a = R; /* a sphere: the caps' areas are analytic */
	pl.f = 0;
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
	return system(cmd) == 0 ? 0 : -1;
}

static int vnode_init(struct node_ini *v, const char *text, char err[256])
{
	return node_ini_init(v, &node_type_vector, &pl, text, NULL, 0, err);
}

static void vnode_ok(struct node_ini *v, const char *fmt, ...)
{
	char text[2048], err[256] = "";
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(text, sizeof text, fmt, ap);
	va_end(ap);
	int rc = vnode_init(v, text, err);
	if (rc)
		fail_msg("node_init: %d %s\n%s", rc, err, text);
}

static struct tile *gen(struct node_ini *v, int lx, int ly, uint32_t x, uint32_t y)
{
	struct tile_key k = { .node = v->n.hash, .x = x, .y = y, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
	struct tile *t = tile_create(&k, v->n.out, T);
	int rc = v->n.type->generate(&v->n, &v->g, &k, NULL, 0, t);
	if (rc)
		fail_msg("generate (%d,%d) %u,%u: %d", lx, ly, x, y, rc);
	return t;
}

static void write_file(const char *name, const char *text)
{
	FILE *f = fopen(tpath(name), "w");
	assert_non_null(f);
	fputs(text, f);
	assert_int_equal(fclose(f), 0);
}

/* A spherical cap of angular radius th (degrees) around (lon0, lat0) as a GeoJSON polygon of
 * n vertices, longitudes wrapped into [-180, 180] (so a cap over the antimeridian jumps). */
static void write_cap(const char *name, double lon0, double lat0, double th, int n)
{
	FILE *f = fopen(tpath(name), "w");
	assert_non_null(f);
	fprintf(f, "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		   "\"properties\":{\"kind\":\"site\"},\"geometry\":{\"type\":\"Polygon\","
		   "\"coordinates\":[[");
	double d = M_PI / 180, p1 = lat0 * d, t = th * d;
	for (int i = 0; i <= n; i++) {
		double az = 2 * M_PI * (i % n) / n;
		double p2 = asin(sin(p1) * cos(t) + cos(p1) * sin(t) * cos(az));
		double l2 = lon0 * d + atan2(sin(az) * sin(t) * cos(p1), cos(t) - sin(p1) * sin(p2));
		double lon = remainder(l2 / d, 360);
		fprintf(f, "%s[%.12f,%.12f]", i ? "," : "", lon, p2 / d);
	}
	fprintf(f, "]]}}]}\n");
	assert_int_equal(fclose(f), 0);
}

/* Σ coverage × texel area on the sphere over the tiles of level ly (lx = ly + 1) within
 * [w, e] × [s, n] degrees (w > e: across the antimeridian). */
static double covered_area(struct node_ini *v, int ly, double w, double s, double e, double n)
{
	int lx = ly + 1;
	uint32_t nx = grid_tiles_x(lx), ny = grid_tiles_y(ly);
	double tw = 360.0 / nx, th = 180.0 / ny, d = M_PI / 180;
	int x0 = (int)floor((w + 180) / tw), x1 = (int)floor((e + 180) / tw);
	if (x1 < x0)
		x1 += (int)nx;
	int y0 = (int)floor((90 - n) / th), y1 = (int)floor((90 - s) / th);
	y0 = y0 < 0 ? 0 : y0;
	y1 = y1 >= (int)ny ? (int)ny - 1 : y1;
	double area = 0;
	for (int y = y0; y <= y1; y++)
		for (int xx = x0; xx <= x1; xx++) {
			uint32_t x = (uint32_t)xx % nx;
			struct tile *t = gen(v, lx, ly, x, (uint32_t)y);
			const float *c = tile_f32(t);
			for (int j = 0; j < T; j++) {
				double latn = 90 - (y * T + j) * th / T, lats = latn - th / T;
				double ta = R * R * (tw / T * d) * (sin(latn * d) - sin(lats * d));
				double row = 0;
				for (int i = 0; i < T; i++)
					row += c[j * T + i];
				area += row * ta;
			}
			tile_unref(t);
		}
	return area;
}

static void cap_case(double lon0, double lat0, double th, const int *levels, int nlev)
{
	write_cap("cap.geojson", lon0, lat0, th, 1440);
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = cap.geojson\noutput = mask\n");
	double want = 2 * M_PI * R * R * (1 - cos(th * M_PI / 180));
	double s = fmax(lat0 - th - 0.5, -90), n = fmin(lat0 + th + 0.5, 90);
	double w = -180, e = 180 - 1e-9;
	if (fabs(lat0) + th < 80) { /* away from the poles: only the tiles around the cap */
		double dl = (th + 0.5) / cos((fabs(lat0) + th) * M_PI / 180);
		w = remainder(lon0 - dl, 360), e = remainder(lon0 + dl, 360);
	}
	for (int i = 0; i < nlev; i++) {
		double got = covered_area(&v, levels[i], w, s, e, n);
		double rel = (got - want) / want;
		printf("# cap (%g, %g) r=%g° level %d: %.6g km² vs %.6g km² (%+.4f %%)\n", lon0, lat0,
		       th, levels[i], got / 1e6, want / 1e6, 100 * rel);
		if (fabs(rel) > 0.005)
			fail_msg("cap at level %d: area off by %.3f %%", levels[i], 100 * rel);
	}
	node_ini_fini(&v);
}

/* A cap in mid-latitudes at levels 3 (texels of 0.7°: the cap is 11 texels across), 6, 9. */
static void cap_area(void **state)
{
	(void)state;
	static const int lv[] = { 3, 6, 9 };
	cap_case(30, 45, 4, lv, 3);
}

/* Over the antimeridian (the file's longitudes jump from 180 to -180) and round a pole (the
 * ring goes once around it and is closed through it). */
static void cap_area_antimeridian_pole(void **state)
{
	(void)state;
	static const int lv[] = { 4, 7 };
	cap_case(180, -20, 3, lv, 2);
	static const int lp[] = { 2, 5 };
	cap_case(0, 90, 6, lp, 2);
	cap_case(77, -90, 6, lp, 2);
}

/* A country from real data: Egypt's border polygons (with its islands) from GMT's Digital
 * Chart of the World (Debian gmt-dcw; `gmt coast -EEG -M`), rasterized as a mask at levels 5
 * (texels of 39 km) and 8 (4.9 km). The reference is the exact area of the polygons the node
 * draws — edges straight in longitude and latitude (PLANETS.md) — on the test's sphere:
 * R² |Σ over edges of ∫ sin φ dλ|, φ linear in λ along an edge. (A geodesic area, GEOS/OGR's,
 * differs from it by the curvature of the edges: with DCW's 1–2 km segments, by far less than
 * the 0.5 % asked.) Skips without gmt. */
static void country_area(void **state)
{
	(void)state;
	/* gmt writes gmt.history and gmt.conf into its working directory: run it in ours */
	char cmd[160];
	snprintf(cmd, sizeof cmd, "cd '%s' && gmt coast -EEG -M 2>/dev/null", dir);
	FILE *g = popen(cmd, "r");
	assert_non_null(g);
	FILE *f = fopen(tpath("egypt.geojson"), "w");
	assert_non_null(f);
	fprintf(f, "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		   "\"properties\":{},\"geometry\":{\"type\":\"MultiPolygon\",\"coordinates\":[");
	char line[256];
	int rings = 0, pts = 0;
	double d = M_PI / 180, sum = 0, ring = 0, lon0 = 0, lat0 = 0, lonp = 0, latp = 0;
	bool open_ring = false;
	while (fgets(line, sizeof line, g)) {
		double lon, lat;
		if (line[0] == '>' || sscanf(line, "%lf %lf", &lon, &lat) != 2) {
			if (open_ring) {
				fprintf(f, "]]");
				/* close the ring for the reference: the last point back to the first */
				double k = (lat0 - latp) * d, dl = (lon0 - lonp) * d;
				ring += dl == 0 ? 0 : k == 0 ? sin(latp * d) * dl
						  : (cos(latp * d) - cos(lat0 * d)) / (k / dl);
				sum += fabs(ring);
				open_ring = false;
			}
			continue;
		}
		if (!open_ring) {
			fprintf(f, "%s[[", rings++ ? "," : "");
			open_ring = true;
			ring = 0;
			lon0 = lon, lat0 = lat;
		} else {
			double k = (lat - latp) * d, dl = (lon - lonp) * d;
			ring += dl == 0 ? 0 : k == 0 ? sin(latp * d) * dl
					  : (cos(latp * d) - cos(lat * d)) / (k / dl);
			fprintf(f, ",");
		}
		fprintf(f, "[%.10f,%.10f]", lon, lat);
		lonp = lon, latp = lat;
		pts++;
	}
	if (open_ring) {
		fprintf(f, "]]");
		double k = (lat0 - latp) * d, dl = (lon0 - lonp) * d;
		ring += dl == 0 ? 0 : k == 0 ? sin(latp * d) * dl : (cos(latp * d) - cos(lat0 * d)) / (k / dl);
		sum += fabs(ring);
	}
	fprintf(f, "]}}]}\n");
	assert_int_equal(fclose(f), 0);
	int rc = pclose(g);
	if (pts < 100) {
		print_message("skipped: gmt coast -EEG gave no polygon (gmt, gmt-dcw missing?) rc %d\n",
			      rc);
		skip();
	}
	double want = R * R * sum;
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = egypt.geojson\noutput = mask\n");
	static const int lv[] = { 5, 8 };
	for (int i = 0; i < 2; i++) {
		double got = covered_area(&v, lv[i], 24, 21, 37.5, 32.5);
		double rel = (got - want) / want;
		printf("# Egypt (%d rings, %d points) level %d: %.6g km² vs %.6g km² (%+.4f %%)\n",
		       rings, pts, lv[i], got / 1e6, want / 1e6, 100 * rel);
		if (fabs(rel) > 0.005)
			fail_msg("Egypt at level %d: area off by %.3f %%", lv[i], 100 * rel);
	}
	node_ini_fini(&v);
}

/* The same cap through other formats GDAL/OGR reads — GeoPackage, FlatGeobuf, KML, and a
 * Shapefile in UTM zone 33N (projected: the node transforms it back to degrees) — covers the
 * same area as the GeoJSON. Needs ogr2ogr (gdal-bin). */
static void formats(void **state)
{
	(void)state;
	if (system("command -v ogr2ogr >/dev/null 2>&1") != 0) {
		print_message("skipped: ogr2ogr (gdal-bin) missing\n");
		skip();
	}
	write_cap("fmt.geojson", 15, 45, 2, 720);
	static const char *const outs[][2] = { { "fmt.gpkg", "-f GPKG" },
					       { "fmt.fgb", "-f FlatGeobuf" },
					       { "fmt.kml", "-f KML" },
					       { "fmt.shp", "-f 'ESRI Shapefile' -t_srs EPSG:32633" } };
	double ref = 0;
	for (int i = -1; i < 4; i++) {
		const char *name = i < 0 ? "fmt.geojson" : outs[i][0];
		if (i >= 0) {
			char cmd[512];
			snprintf(cmd, sizeof cmd, "ogr2ogr %s '%s' '%s' 2>&1", outs[i][1], tpath(name),
				 tpath("fmt.geojson"));
			assert_int_equal(system(cmd), 0);
		}
		struct node_ini v;
		vnode_ok(&v, "[node x]\ntype = vector\npath = %s\noutput = mask\n", name);
		double a = covered_area(&v, 6, 12, 42.5, 18, 47.5);
		node_ini_fini(&v);
		if (i < 0)
			ref = a;
		printf("# %s: %.6g km² (%+.5f %% against the GeoJSON)\n", name, a / 1e6,
		       100 * (a - ref) / ref);
		assert_true(fabs(a - ref) < 1e-4 * ref);
	}
}

/* Width of a line, in metres, across one row (east-west: the line runs north-south) or one
 * column of a tile. */
static double across(const float *c, int j, bool row, double texel_m)
{
	double s = 0;
	for (int i = 0; i < T; i++)
		s += row ? c[j * T + i] : c[i * T + j];
	return s * texel_m;
}

static void line_width_at(double lat)
{
	char gj[512];
	/* A meridian segment and a parallel segment crossing at (10.01, lat). */
	snprintf(gj, sizeof gj,
		 "{\"type\":\"FeatureCollection\",\"features\":["
		 "{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"LineString\","
		 "\"coordinates\":[[10.003,%.6f],[10.003,%.6f]]}},"
		 "{\"type\":\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"LineString\","
		 "\"coordinates\":[[9.9,%.6f],[10.1,%.6f]]}}]}",
		 lat - 0.1, lat + 0.1, lat - 0.003, lat - 0.003);
	write_file("line.geojson", gj);
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = line.geojson\noutput = mask\nwidth = 100m\n");
	int ly = 14, lx = 15;
	double tw = 360.0 / grid_tiles_x(lx) / T, th = 180.0 / grid_tiles_y(ly) / T;
	double d = M_PI / 180;
	uint32_t x = (uint32_t)floor((10.003 + 180) / (tw * T));
	uint32_t y = (uint32_t)floor((90 - lat) / (th * T));
	struct tile *t = gen(&v, lx, ly, x, y);
	const float *c = tile_f32(t);
	/* Rows away from the crossing: the north-south line measured east-west at that row's
	 * latitude (R cos φ Δλ per texel). */
	double tile_n = 90 - y * th * T, tile_w = -180 + x * tw * T;
	int jc = (int)floor((tile_n - (lat - 0.003)) / th);
	int ic = (int)floor((10.003 - tile_w) / tw);
	int checked = 0;
	for (int j = 0; j < T; j++) {
		if (abs(j - jc) < 12)
			continue;
		double latj = tile_n - (j + 0.5) * th;
		double wm = across(c, j, true, R * cos(latj * d) * tw * d);
		if (fabs(wm - 100) > R * cos(latj * d) * tw * d)
			fail_msg("lat %g row %d: the north-south line is %.2f m wide, not 100 m", lat, j, wm);
		checked++;
	}
	for (int i = 0; i < T; i++) {
		if (abs(i - ic) < 12)
			continue;
		double wm = across(c, i, false, R * th * d);
		if (fabs(wm - 100) > R * th * d)
			fail_msg("lat %g column %d: the east-west line is %.2f m wide, not 100 m", lat, i, wm);
		checked++;
	}
	printf("# 100 m lines at %g°: texels %.1f m east-west, %.1f m north-south; %d profiles\n",
	       lat, R * cos(lat * d) * tw * d, R * th * d, checked);
	assert_true(checked > 40);
	tile_unref(t);
	node_ini_fini(&v);
}

static void line_width(void **state)
{
	(void)state;
	line_width_at(45);
	line_width_at(70);
}

/* A 3-texel line along 10°N across the antimeridian: the last column of the tile west of it
 * and the first column of the tile east of it hold the same profile as the line's interior
 * (no gap, no double). A cap round the north pole: every tile of the polar row is the same
 * (the cap's edge is a parallel), so tiles meet without a seam at every x border. */
static void seams(void **state)
{
	(void)state;
	write_file("am.geojson",
		   "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		   "\"properties\":{},\"geometry\":{\"type\":\"LineString\",\"coordinates\":"
		   "[[170,10.3],[179.5,10.3],[-179.5,10.3],[-170,10.3]]}}]}");
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = am.geojson\noutput = mask\nwidth = 3px\n");
	int ly = 4, lx = 5;
	uint32_t nx = grid_tiles_x(lx);
	uint32_t y = (uint32_t)floor((90 - 10.3) / (180.0 / grid_tiles_y(ly)));
	struct tile *west = gen(&v, lx, ly, nx - 1, y), *east = gen(&v, lx, ly, 0, y);
	const float *a = tile_f32(west), *b = tile_f32(east);
	double sum = 0;
	for (int j = 0; j < T; j++) {
		float mid = a[j * T + T / 2];
		assert_float_equal(a[j * T + T - 1], mid, 1e-4);
		assert_float_equal(b[j * T], mid, 1e-4);
		sum += mid;
	}
	assert_float_equal(sum, 3.0, 1e-3);
	tile_unref(west);
	tile_unref(east);
	node_ini_fini(&v);

	write_cap("pole.geojson", 0, 90, 1.3, 720);
	vnode_ok(&v, "[node x]\ntype = vector\npath = pole.geojson\noutput = mask\n");
	ly = 3, lx = 4;
	nx = grid_tiles_x(lx);
	struct tile *t0 = gen(&v, lx, ly, 0, 0);
	const float *c0 = tile_f32(t0);
	double th = 180.0 / grid_tiles_y(ly) / T;
	for (int j = 0; j < T; j++) {
		double ls = 90 - (j + 1) * th, ln = 90 - j * th;
		float want = ls >= 88.7 ? 1.0f : ln <= 88.7 ? 0.0f : -1;
		if (want >= 0)
			assert_float_equal(c0[j * T + 5], want, 1e-3);
	}
	for (uint32_t x = 1; x < nx; x++) {
		struct tile *t = gen(&v, lx, ly, x, 0);
		const float *c = tile_f32(t);
		for (int j = 0; j < 8; j++) {
			/* This tile's west column against the last tile's east column, and both
			 * against the row's value. */
			assert_float_equal(c[j * T], c0[j * T + T - 1], 2e-3);
			assert_float_equal(c[j * T + T / 2], c0[j * T + 5], 2e-3);
		}
		tile_unref(t);
	}
	tile_unref(t0);
	node_ini_fini(&v);
}

/* Exact area coverage: a texel's coverage is the mean of its four children's, for a polygon
 * crossing the antimeridian (the children of the level's first and last tiles). */
static void parent_is_mean(void **state)
{
	(void)state;
	write_cap("pm.geojson", 180, 30, 7, 360);
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = pm.geojson\noutput = mask\n");
	int ly = 3, lx = 4;
	uint32_t nx = grid_tiles_x(lx), y = (uint32_t)floor((90 - 30) / (180.0 / grid_tiles_y(ly)));
	double worst = 0, sum = 0;
	for (int side = 0; side < 2; side++) {
		uint32_t x = side ? 0 : nx - 1;
		struct tile *p = gen(&v, lx, ly, x, y), *c[4];
		for (int q = 0; q < 4; q++)
			c[q] = gen(&v, lx + 1, ly + 1, 2 * x + (q & 1), 2 * y + (q >> 1));
		const float *pc = tile_f32(p);
		for (int j = 0; j < T; j++)
			for (int i = 0; i < T; i++) {
				const float *cc = tile_f32(c[(j >= T / 2) * 2 + (i >= T / 2)]);
				int ci = 2 * (i % (T / 2)), cj = 2 * (j % (T / 2));
				double m = 0.25 * (cc[cj * T + ci] + cc[cj * T + ci + 1] +
						   cc[(cj + 1) * T + ci] + cc[(cj + 1) * T + ci + 1]);
				worst = fmax(worst, fabs(m - pc[j * T + i]));
				sum += pc[j * T + i];
			}
		tile_unref(p);
		for (int q = 0; q < 4; q++)
			tile_unref(c[q]);
	}
	printf("# parent against the mean of its children: worst %.2g over %.0f texels covered\n",
	       worst, sum);
	assert_true(sum > 100);
	assert_true(worst < 1e-4);
	node_ini_fini(&v);
}

/* Mask tile m of vector node v as the weight of a blend with mode mask: a = a rough terrain
 * (returned owned in *terrain), b = 312.5 m everywhere. Returns the heights (owned). */
static struct tile *flatten_with(struct node_ini *v, struct tile *m, struct tile **terrain)
{
	struct node tn = { .name = "terrain", .out = PIX_HEIGHT, .hash = 21 };
	struct node level = { .name = "level", .out = PIX_HEIGHT, .hash = 22 };
	struct node *ins[3] = { &tn, &level, &v->n };
	struct node_ini bn;
	char err[256];
	if (node_ini_init(&bn, &node_type_blend, &pl, "[node f]\ntype = blend\nmode = mask\n", ins,
			  3, err))
		fail_msg("%s", err);
	struct tile_key k = m->key;
	k.node = 21;
	struct tile *a = tile_create(&k, PIX_HEIGHT, T), *b = tile_create(&k, PIX_HEIGHT, T);
	struct tile *o = tile_create(&k, PIX_HEIGHT, T);
	for (int i = 0; i < T * T; i++) {
		tile_f32(a)[i] = 300.0f + 37.123f * sinf(i * 0.37f) + (float)(i % T) * 0.731f;
		tile_f32(b)[i] = 312.5f;
	}
	struct tile *in[3] = { a, b, m };
	assert_int_equal(node_type_blend.generate(&bn.n, &bn.g, &k, in, 3, o), 0);
	tile_unref(b);
	node_ini_fini(&bn);
	*terrain = a;
	return o;
}

/* The mask as a blend's mask over heights, b a constant target: inside the polygon every
 * height is the target, outside every height is unchanged (bit for bit). */
static void flatten(void **state)
{
	(void)state;
	write_file("site.geojson",
		   "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		   "\"properties\":{},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":"
		   "[[[10.01,45.01],[10.05,45.012],[10.06,45.04],[10.02,45.05],[10.01,45.01]]]}}]}");
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = site.geojson\noutput = mask\n");
	int ly = 12, lx = 13;
	double tw = 360.0 / grid_tiles_x(lx), th = 180.0 / grid_tiles_y(ly);
	uint32_t x = (uint32_t)floor((10.03 + 180) / tw), y = (uint32_t)floor((90 - 45.03) / th);
	struct tile *m = gen(&v, lx, ly, x, y);
	/* The blend: a = terrain, b = the site's height, mask = the vector node. */
	struct tile *a, *o = flatten_with(&v, m, &a);
	int inside = 0, outside = 0, edge = 0;
	for (int i = 0; i < T * T; i++) {
		float c = tile_f32(m)[i], h = tile_f32(o)[i];
		if (c >= 1.0f) {
			assert_float_equal(h, 312.5f, 312.5f * 2e-7f);
			inside++;
		} else if (c <= 0.0f) {
			assert_true(h == tile_f32(a)[i]);
			outside++;
		} else {
			edge++;
		}
	}
	printf("# flatten: %d texels at the target, %d unchanged, %d on the edge\n", inside,
	       outside, edge);
	assert_true(inside > 200 && outside > 200 && edge < inside);
	tile_unref(a), tile_unref(o), tile_unref(m);
	node_ini_fini(&v);
}

/* Colours picked by an attribute; others in the default colour (here transparent). */
static void styles(void **state)
{
	(void)state;
	write_file("styled.geojson",
		   "{\"type\":\"FeatureCollection\",\"features\":["
		   "{\"type\":\"Feature\",\"properties\":{\"kind\":\"river\"},\"geometry\":"
		   "{\"type\":\"LineString\",\"coordinates\":[[-100,30],[-100,60]]}},"
		   "{\"type\":\"Feature\",\"properties\":{\"kind\":\"border\"},\"geometry\":"
		   "{\"type\":\"LineString\",\"coordinates\":[[-80,30],[-80,60]]}},"
		   "{\"type\":\"Feature\",\"properties\":{\"kind\":\"road\"},\"geometry\":"
		   "{\"type\":\"LineString\",\"coordinates\":[[-60,30],[-60,60]]}},"
		   "{\"type\":\"Feature\",\"properties\":{\"kind\":\"lake\"},\"geometry\":"
		   "{\"type\":\"Point\",\"coordinates\":[-40,45]}}]}");
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = styled.geojson\nstyle_field = kind\n"
		     "color = #00000000\nstyles = river #0000ff 4px, border #ff0000 4px, lake "
		     "#00ff0080 10px\n");
	assert_int_equal(v.n.out, PIX_COLOR);
	/* Level 0 (2 × 1 tiles): texel 2.8°; x = 0 covers the western hemisphere. */
	struct tile *t = gen(&v, 1, 0, 0, 0);
	const uint8_t *p = t->data;
	int j = (int)((90 - 45) / (180.0 / T));
	int ir = (int)((-100 + 180) / (180.0 / T)), ib = (int)((-80 + 180) / (180.0 / T));
	int io = (int)((-60 + 180) / (180.0 / T)), il = (int)((-40 + 180) / (180.0 / T));
	const uint8_t *r = p + 4 * (j * T + ir), *b = p + 4 * (j * T + ib), *o = p + 4 * (j * T + io);
	const uint8_t *l = p + 4 * (j * T + il);
	printf("# river %d,%d,%d,%d border %d,%d,%d,%d road alpha %d lake %d,%d,%d,%d\n", r[0], r[1],
	       r[2], r[3], b[0], b[1], b[2], b[3], o[3], l[0], l[1], l[2], l[3]);
	assert_true(r[2] == 255 && r[0] == 0 && r[3] == 255);
	assert_true(b[0] == 255 && b[2] == 0 && b[3] == 255);
	assert_int_equal(o[3], 0);
	assert_true(l[1] == 255 && l[3] >= 126 && l[3] <= 129);
	tile_unref(t);
	node_ini_fini(&v);
}

/* polygons = outline: the ring's edge drawn, its inside left clear; both: the inside at the
 * fill's opacity under the outline. */
static void outline(void **state)
{
	(void)state;
	write_file("sq.geojson", "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":"
		   "\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Polygon\","
		   "\"coordinates\":[[[-150,20],[-30,20],[-30,70],[-150,70],[-150,20]]]}}]}");
	static const char *const modes[] = { "outline", "both" };
	for (int m = 0; m < 2; m++) {
		struct node_ini v;
		vnode_ok(&v, "[node x]\ntype = vector\npath = sq.geojson\ncolor = #ff0000\n"
			     "width = 2px\npolygons = %s\nfill_opacity = 0.5\n", modes[m]);
		struct tile *t = gen(&v, 1, 0, 0, 0); /* texels of 180/64 = 2.8125° */
		const uint8_t *p = t->data;
		double d = 180.0 / T;
		int jn = (int)((90 - 70) / d), je = (int)((-30 + 180) / d);
		int jm = (int)((90 - 45) / d), im = (int)((-90 + 180) / d);
		/* The north edge (lat 70 falls inside a texel row: that row and the next share
		 * the 2-texel line) and the middle. */
		int edge_a = p[4 * (jn * T + im) + 3] + p[4 * ((jn + 1) * T + im) + 3];
		assert_true(edge_a >= 255);
		assert_int_equal(p[4 * (jn * T + im)], 255);
		assert_true(p[4 * (jm * T + je) + 3] > 0); /* the east edge */
		uint8_t mid = p[4 * (jm * T + im) + 3];
		printf("# %s: north edge alpha %d, middle alpha %d\n", modes[m], edge_a, mid);
		assert_int_equal(mid, m == 0 ? 0 : 128);
		tile_unref(t);
		node_ini_fini(&v);
	}
}

/* The shipped layer (earth.ini's `lines` over data/earth/lines.gpkg from make data): the
 * Egypt–Sudan border, which follows 22°N from 25°E to the Nile (in GSHHG's low resolution
 * from (25.0022, 21.99969) to (30, 21.99863): 21.99899 at 28.3°E), is a red line there, 1.5
 * texels wide, at level 6 and at level 12 (texels of 19 m). Skips without the data. */
static void earth_border(void **state)
{
	(void)state;
	if (access("data/earth/lines.gpkg", R_OK) != 0) {
		print_message("skipped: data/earth/lines.gpkg missing (make data)\n");
		skip();
	}
	struct planet *p;
	char err[256];
	if (planet_load("conf/planets/earth.ini", &p, err))
		fail_msg("%s", err);
	struct node *lines = NULL;
	for (size_t i = 0; i < p->nnodes; i++)
		if (strcmp(p->nodes[i]->name, "lines") == 0)
			lines = p->nodes[i];
	assert_non_null(lines);
	const uint32_t Tp = p->tile_size;
	struct gen_ctx g = { 0 };
	for (int ly = 6; ly <= 12; ly += 6) {
		int lx = ly + 1;
		double tw = 360.0 / grid_tiles_x(lx), th = 180.0 / grid_tiles_y(ly);
		struct tile_key k = { .node = lines->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly,
				      .x = (uint32_t)floor((28.3 + 180) / tw),
				      .y = (uint32_t)floor((90 - 22.01) / th) };
		struct tile *t = tile_create(&k, PIX_COLOR, Tp);
		assert_int_equal(lines->type->generate(lines, &g, &k, NULL, 0, t), 0);
		double west = -180 + k.x * tw, north = 90 - k.y * th;
		int i = (int)((28.3 - west) / (tw / Tp));
		double alpha = 0;
		int jmax = 0, amax = -1;
		for (uint32_t j = 0; j < Tp; j++) {
			const uint8_t *q = t->data + 4 * (j * Tp + (uint32_t)i);
			alpha += q[3] / 255.0;
			if (q[3] > amax)
				amax = q[3], jmax = (int)j;
		}
		const uint8_t *q = t->data + 4 * ((uint32_t)jmax * Tp + (uint32_t)i);
		double lat = north - (jmax + 0.5) * th / Tp;
		printf("# level %d: border at %.4f°N, %.2f texels of alpha, colour %d,%d,%d\n", ly,
		       lat, alpha, q[0], q[1], q[2]);
		assert_true(fabs(lat - 21.99899) < th / Tp);
		assert_true(alpha > 1.2 && alpha < 1.8);
		assert_true(q[0] > 200 && q[1] < 100 && q[2] < 100);
		tile_unref(t);
	}
	gen_ctx_fini(&g);
	planet_unref(p);
}

static void refused(const char *text, const char *want)
{
	struct node_ini v;
	char err[256] = "";
	int rc = vnode_init(&v, text, err);
	if (rc != -EINVAL || !strstr(err, want))
		fail_msg("want -EINVAL and \"%s\", got %d \"%s\"", want, rc, err);
	printf("# refused: %s\n", err);
	node_ini_fini(&v);
}

static void bad_files(void **state)
{
	(void)state;
	char want[160];
	snprintf(want, sizeof want, "cannot open %s/missing.geojson", dir);
	refused("[node x]\ntype = vector\npath = missing.geojson\n", want);
	write_file("broken.geojson", "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":");
	snprintf(want, sizeof want, "%s/broken.geojson", dir);
	refused("[node x]\ntype = vector\npath = broken.geojson\n", want);
	write_file("ok.geojson", "{\"type\":\"FeatureCollection\",\"features\":[]}");
	refused("[node x]\ntype = vector\npath = ok.geojson\nlayer = roads\n", "no layer \"roads\"");
	refused("[node x]\ntype = vector\npath = ok.geojson\nwidth = 3\n", "test.ini:4: width:");
	refused("[node x]\ntype = vector\npath = ok.geojson\nstyles = a #fff 1px\n",
		"needs style_field");
	refused("[node x]\ntype = vector\n", "path: missing");
	write_file("far.geojson", "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":"
		   "\"Feature\",\"properties\":{},\"geometry\":{\"type\":\"Point\","
		   "\"coordinates\":[10,95]}}]}");
	refused("[node x]\ntype = vector\npath = far.geojson\n", "not a longitude and latitude");
	refused("[node x]\ntype = vector\npath = ok.geojson\nblur = 3\n", "blur");
	/* An empty source is valid: transparent tiles. */
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = ok.geojson\n");
	struct tile *t = gen(&v, 1, 0, 1, 0);
	for (int i = 0; i < T * T * 4; i++)
		assert_int_equal(t->data[i], 0);
	tile_unref(t);
	node_ini_fini(&v);
}

/* A rectangle in (lon, lat) as GeoJSON. */
static void write_rect(const char *name, double w, double so, double e, double n)
{
	char text[512];
	snprintf(text, sizeof text,
		 "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\","
		 "\"properties\":{},\"geometry\":{\"type\":\"Polygon\",\"coordinates\":"
		 "[[[%.6f,%.6f],[%.6f,%.6f],[%.6f,%.6f],[%.6f,%.6f],[%.6f,%.6f]]]}}]}",
		 w, so, e, so, e, n, w, n, w, so);
	write_file(name, text);
}

/* What the feathered mask must be at a texel fully outside rectangle [w, e] × [so, n] whose
 * centre is (lonc, latc): 1 − smoothstep of the distance on the ground (on this sphere, in
 * the plane tangent at the centre: the nearest point of an axis-aligned rectangle). */
static double feather_ref(double w, double so, double e, double n, double lonc, double latc,
			  double feather)
{
	lonc += 360 * round(((w + e) / 2 - lonc) / 360); /* the copy nearest the rectangle */
	double dx = fmax(fmax(w - lonc, 0), lonc - e), dy = fmax(fmax(so - latc, 0), latc - n);
	double m = R * M_PI / 180;
	double d = hypot(dx * m * cos(latc * M_PI / 180), dy * m);
	double t = fmin(d / feather, 1);
	return 1 - t * t * (3 - 2 * t);
}

/* Tile (lx, ly, x, y) of the feathered rectangle against feather_ref: texels inside exactly
 * 1, texels outside as the reference within float rounding. Returns the tile (owned) and
 * counts the texels in the feather's band (0 < mask < 1, fully outside) in *band. */
static struct tile *feather_tile(struct node_ini *v, const double rect[4], double feather,
				 int lx, int ly, uint32_t x, uint32_t y, int *band, int *inside)
{
	struct tile *t = gen(v, lx, ly, x, y);
	const float *m = tile_f32(t);
	struct tile_key k = { .x = x, .y = y, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
	struct geo_rect r;
	grid_tile_rect(&k, &r);
	double dlon = (r.east - r.west) / T, dlat = (r.north - r.south) / T, worst = 0;
	for (int j = 0; j < T; j++)
		for (int i = 0; i < T; i++) {
			double w = r.west + i * dlon, e = w + dlon, n = r.north - j * dlat, so = n - dlat;
			double sh = 360 * round(((rect[0] + rect[2]) / 2 - (w + e) / 2) / 360);
			bool in = w + sh >= rect[0] && e + sh <= rect[2] && so >= rect[1] && n <= rect[3];
			bool out = e + sh <= rect[0] || w + sh >= rect[2] || n <= rect[1] || so >= rect[3];
			float got = m[j * T + i];
			if (in) {
				assert_true(got == 1.0f);
				++*inside;
			} else if (out) {
				double want = feather_ref(rect[0], rect[1], rect[2], rect[3], w + dlon / 2,
							  n - dlat / 2, feather);
				worst = fmax(worst, fabs(got - want));
				if (want == 0)
					assert_true(got == 0.0f); /* beyond the feather: exactly none */
				*band += got > 0 && got < 1;
			} else {
				assert_true(got > 0 && got <= 1);
			}
		}
	assert_true(worst < 2e-4);
	return t;
}

/* The soft edge (feather = 600m): inside the polygon the mask is exactly 1 and the blend's
 * heights exactly the target; across the feather the mask follows 1 − smoothstep of the
 * distance on the ground and the heights lie between target and terrain, nearer the target
 * the nearer the polygon (monotone along a row); beyond it the mask is exactly 0 and the
 * heights unchanged bit for bit. A polygon lying in one tile feathers into its neighbour
 * (the index box grows by the feather), so both tiles agree along their shared edge — also
 * across the antimeridian. */
static void feather(void **state)
{
	(void)state;
	const double F = 600;
	int ly = 12, lx = 13;
	double tw = 360.0 / grid_tiles_x(lx), th = 180.0 / grid_tiles_y(ly);
	/* a rectangle near the east edge of its tile, within the feather of the next one */
	uint32_t x = (uint32_t)floor((10.03 + 180) / tw), y = (uint32_t)floor((90 - 45.03) / th);
	double east = -180 + (x + 1) * tw - 0.002, north = 90 - y * th - th / 3;
	double rect[4] = { east - tw / 3, north - th / 4, east, north };
	write_rect("soft.geojson", rect[0], rect[1], rect[2], rect[3]);
	struct node_ini v;
	vnode_ok(&v, "[node x]\ntype = vector\npath = soft.geojson\noutput = mask\nfeather = 600m\n");
	int band = 0, inside = 0, band_b = 0, in_b = 0;
	struct tile *ma = feather_tile(&v, rect, F, lx, ly, x, y, &band, &inside);
	struct tile *mb = feather_tile(&v, rect, F, lx, ly, x + 1, y, &band_b, &in_b);
	printf("# feather: %d texels inside, %d in the band, %d of them in the next tile\n", inside,
	       band + band_b, band_b);
	assert_true(inside > 100 && band > 100 && band_b > 20 && in_b == 0);
	/* the shared edge: the neighbour's first column continues this tile's last one */
	const float *a = tile_f32(ma), *b = tile_f32(mb);
	for (int j = 0; j < T; j++)
		assert_true(fabsf(a[j * T + T - 1] - b[j * T]) < 0.2f);

	/* The blend over a rough terrain, target 312.5 m. */
	struct tile *ta, *o = flatten_with(&v, ma, &ta);
	int at_target = 0, unchanged = 0, between = 0;
	for (int i = 0; i < T * T; i++) {
		float c = a[i], h = tile_f32(o)[i], t0 = tile_f32(ta)[i];
		if (c >= 1.0f) {
			assert_float_equal(h, 312.5f, 312.5f * 2e-7f);
			at_target++;
		} else if (c <= 0.0f) {
			assert_true(h == t0);
			unchanged++;
		} else {
			assert_true(h >= fminf(t0, 312.5f) - 1e-3f && h <= fmaxf(t0, 312.5f) + 1e-3f);
			/* the blend's weight is the mask: |h − terrain| = mask · |target − terrain| */
			assert_float_equal(fabsf(h - t0), c * fabsf(312.5f - t0), 1e-3);
			between++;
		}
	}
	printf("# feather blend: %d at the target, %d between, %d unchanged\n", at_target, between,
	       unchanged);
	assert_true(at_target > 100 && between > 100 && unchanged > 100);
	/* monotone: west from the rectangle's west edge along its middle row, the mask falls */
	struct geo_rect gr;
	grid_tile_rect(&ma->key, &gr);
	int jm = (int)((gr.north - (rect[1] + rect[3]) / 2) / ((gr.north - gr.south) / T));
	int iw = (int)((rect[0] - gr.west) / ((gr.east - gr.west) / T));
	int falls = 0;
	for (int i = iw; i > 0; i--) {
		assert_true(a[jm * T + i - 1] <= a[jm * T + i]);
		falls += a[jm * T + i - 1] < a[jm * T + i];
	}
	assert_true(falls > 5);
	tile_unref(ta), tile_unref(o), tile_unref(ma), tile_unref(mb);
	node_ini_fini(&v);

	/* Across the antimeridian: the rectangle ends 0.002° west of it; the first tile east of
	 * it (x = 0) takes the feather, and meets the last tile. */
	double am[4] = { 179.99, 10.0, 179.998, 10.01 };
	write_rect("soft_am.geojson", am[0], am[1], am[2], am[3]);
	vnode_ok(&v, "[node x]\ntype = vector\npath = soft_am.geojson\noutput = mask\n"
		     "feather = 0.6km\n");
	uint32_t nx = grid_tiles_x(lx), ya = (uint32_t)floor((90 - 10.005) / th);
	band = inside = band_b = in_b = 0;
	ma = feather_tile(&v, am, F, lx, ly, nx - 1, ya, &band, &inside);
	mb = feather_tile(&v, am, F, lx, ly, 0, ya, &band_b, &in_b);
	printf("# feather at the antimeridian: %d inside, %d in the band west, %d east\n", inside,
	       band, band_b);
	assert_true(inside > 10 && band > 50 && band_b > 20);
	a = tile_f32(ma), b = tile_f32(mb);
	for (int j = 0; j < T; j++)
		assert_true(fabsf(a[j * T + T - 1] - b[j * T]) < 0.2f);
	tile_unref(ma), tile_unref(mb);
	node_ini_fini(&v);

	/* Near the north pole a texel is 75 times narrower east-west than north-south: the
	 * feather reaches across several tiles of the row, each as the reference. */
	double pole[4] = { 10.0, 89.2, 10.3, 89.25 };
	write_rect("soft_pole.geojson", pole[0], pole[1], pole[2], pole[3]);
	vnode_ok(&v, "[node x]\ntype = vector\npath = soft_pole.geojson\noutput = mask\n"
		     "feather = 600m\n");
	ly = 10, lx = 11;
	tw = 360.0 / grid_tiles_x(lx), th = 180.0 / grid_tiles_y(ly);
	uint32_t xp = (uint32_t)floor((10.3 + 180) / tw), yp = (uint32_t)floor((90 - 89.22) / th);
	int far_band = 0;
	for (uint32_t k2 = 0; k2 < 4; k2++) {
		band = inside = 0;
		struct tile *t2 = feather_tile(&v, pole, F, lx, ly, xp + k2, yp, &band, &inside);
		if (k2 >= 2)
			far_band += band;
		tile_unref(t2);
	}
	printf("# feather near the pole: %d texels in the band two and three tiles east\n", far_band);
	assert_true(far_band > 20);
	node_ini_fini(&v);

	/* a feather is a distance on the ground, and softens a mask only */
	refused("[node x]\ntype = vector\npath = soft.geojson\noutput = mask\nfeather = 3px\n",
		"feather: expected a distance on the ground");
	refused("[node x]\ntype = vector\npath = soft.geojson\nfeather = 300m\n",
		"feather: softens a mask's edge");
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(cap_area),
		cmocka_unit_test(cap_area_antimeridian_pole),
		cmocka_unit_test(country_area),
		cmocka_unit_test(formats),
		cmocka_unit_test(line_width),
		cmocka_unit_test(seams),
		cmocka_unit_test(parent_is_mean),
		cmocka_unit_test(flatten),
		cmocka_unit_test(styles),
		cmocka_unit_test(outline),
		cmocka_unit_test(earth_border),
		cmocka_unit_test(bad_files),
		cmocka_unit_test(feather),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
