/* test_http — clipmapd's HTTP endpoint (daemon/http.c) with a real daemon and real clients:
 * curl for the protocol-level checks and GDAL (gdal_translate through its WMTS driver reading
 * our capabilities; gdalinfo) as the GIS client. What a user would notice:
 *   - a whole level read by GDAL from the WMTS endpoint equals `clipmapctl render --world` of
 *     the same level, pixel for pixel (colour), at two levels, and a window of a third;
 *   - a height tile as 16-bit PNG holds round(metres) + 32768 of the float32 GeoTIFF tile, and
 *     gdalinfo reads that GeoTIFF as EPSG:4326 with the tile's corners;
 *   - TMS addresses the same tile with y counted from the south;
 *   - ETag + If-None-Match → 304; keep-alive;
 *   - bad paths, levels, layers and formats get 4xx with a body saying why, a slow client is
 *     cut off after timeout_s, and others are served meanwhile;
 *   - /metrics counts the tiles served; /healthz and /readyz answer;
 *   - with require_token = tcp the endpoint asks for the bearer token.
 * Skipped when build/clipmapd or curl is missing. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <arpa/inet.h>
#include <math.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/img.h"
#include "support/daemon_env.h"
#include "support/slow.h"

static const char planet_text[] =
	"[planet]\nname = test\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 8\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 4\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[node shade]\ntype = normal\ninput = base\nexaggeration = 30\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n"
	"[layer normal]\nnode = shade\nformat = rg8\n";

struct env {
	struct daemon_env d;
	char planet[128];
	int port;
	char url[64]; /* http://127.0.0.1:PORT */
};

/* The port of the "http: listening on http://127.0.0.1:PORT/" log line. */
static int http_port_from_log(const struct daemon_env *d)
{
	char *l = daemon_env_log_read(d);
	const char *p = strstr(l, "http: listening on http://127.0.0.1:");
	int port = p ? atoi(p + strlen("http: listening on http://127.0.0.1:")) : 0;
	free(l);
	return port;
}

/* A planet whose tiles take long to make (1024² texels of noise: 20–100 ms each on one worker,
 * by the machine): the hang-up test's. */
static const char slow_planet_text[] =
	"[planet]\nname = slow\nbody = sphere\nradius = 1000000\ntile_size = 1024\nmax_level = 10\n"
	"[node base]\ntype = noise\nseed = 9\noctaves = 24\nwavelength = 300000\namplitude = 500\n"
	"[layer height]\nnode = base\nformat = f32\n";

static int start(void **state, const char *const *extra, const char *token, bool slow)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_http") ||
	    daemon_env_planet_text(&e->d, "test.ini", planet_text, e->planet) ||
	    (slow && daemon_env_planet_text(&e->d, "slow.ini", slow_planet_text, NULL)))
		return -1;
	char out[256];
	char *const which[] = { "curl", "--version", NULL };
	if (!daemon_env_built(&e->d, "clipmapd") || daemon_env_run(which, out, sizeof out) != 0)
		return 0;
	const char *set[16] = { "engine.workers = 2", "log.level = info",
				"http.listen = 127.0.0.1:0", "http.timeout_s = 2" };
	int n = 4;
	for (int i = 0; extra && extra[i] && n < 15; i++)
		set[n++] = extra[i];
	set[n] = NULL;
	char err[256];
	if (daemon_env_start(&e->d, &(struct daemon_env_conf){ .set = set, .token = token }, err)) {
		fprintf(stderr, "test_http: %s\n", err);
		return -1;
	}
	daemon_env_log_wait(&e->d, "http: listening on", 1, 5000);
	e->port = http_port_from_log(&e->d);
	snprintf(e->url, sizeof e->url, "http://127.0.0.1:%d", e->port);
	return e->port > 0 ? 0 : -1;
}

static int setup(void **state) { return start(state, NULL, NULL, false); }

static int setup_token(void **state)
{
	static const char *const x[] = { "listen.require_token = tcp", NULL };
	return start(state, x, "s3cret", false);
}

static int setup_slow(void **state)
{
	static const char *const x[] = { "engine.workers = 1", "http.max_per_address = 64", NULL };
	return start(state, x, NULL, true);
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (e)
		daemon_env_fini(&e->d);
	free(e);
	return 0;
}

#define NEED_DAEMON(e)                  \
	do {                            \
		if ((e)->d.daemon <= 0) \
			skip();         \
	} while (0)

/* GETs path into file (NULL: discarded) with an optional header; returns the HTTP status. */
static int get(struct env *e, const char *path, const char *file, const char *header)
{
	char url[1200], out[4096];
	snprintf(url, sizeof url, "%s%s", e->url, path);
	char *argv[16] = { "curl", "-s", "--path-as-is", "-m", "60", "-o",
			   (char *)(file ? file : "/dev/null"), "-w", "%{http_code}" };
	int n = 9;
	if (header) {
		argv[n++] = "-H";
		argv[n++] = (char *)header;
	}
	argv[n++] = url;
	argv[n] = NULL;
	if (daemon_env_run(argv, out, sizeof out) != 0)
		fail_msg("curl %s failed: %s", url, out);
	return atoi(out);
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return strdup("");
	char *s = calloc(1, 1 << 20);
	size_t n = fread(s, 1, (1 << 20) - 1, f);
	s[n] = '\0';
	fclose(f);
	return s;
}

static void *read_img(const char *path, enum img_type t, struct img_info *info)
{
	void *px = NULL;
	char err[256];
	if (img_read(path, t, &px, info, err))
		fail_msg("%s", err);
	return px;
}

/* GDAL's WMTS driver reads level z of layer test.color (optionally a window) into out. */
static void gdal_level(struct env *e, int z, const char *srcwin, const char *out)
{
	char ds[300], log[8192], z_s[16];
	snprintf(ds, sizeof ds, "WMTS:%s/wmts/1.0.0/WMTSCapabilities.xml,layer=test.color,"
				"tilematrix=%d", e->url, z);
	snprintf(z_s, sizeof z_s, "%d", z);
	char *argv[16] = { "gdal_translate", "-q", "-of", "PNG" };
	int n = 4;
	char a[4][16];
	if (srcwin) {
		argv[n++] = "-srcwin";
		sscanf(srcwin, "%15s %15s %15s %15s", a[0], a[1], a[2], a[3]);
		for (int i = 0; i < 4; i++)
			argv[n++] = a[i];
	}
	argv[n++] = ds;
	argv[n++] = (char *)out;
	argv[n] = NULL;
	int rc = daemon_env_run(argv, log, sizeof log);
	if (rc)
		fail_msg("gdal_translate level %s: exit %d: %s", z_s, rc, log);
}

static void render_level(struct env *e, int z, const char *out)
{
	char exe[600], lv[16], log[4096];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	snprintf(lv, sizeof lv, "%d", z);
	char *const argv[] = { exe, "render", e->planet, "color", "--level", lv, "--world",
			       "--quiet", "-o", (char *)out, NULL };
	int rc = daemon_env_run(argv, log, sizeof log);
	if (rc)
		fail_msg("clipmapctl render: exit %d: %s", rc, log);
}

/* Counts RGBA pixels that differ between a (w×h) and the window (x0, y0) of b (bw wide). */
static long differing(const uint8_t *a, int w, int h, const uint8_t *b, int bw, int x0, int y0)
{
	long bad = 0;
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++)
			bad += memcmp(a + 4 * ((size_t)y * w + x),
				      b + 4 * ((size_t)(y + y0) * bw + x + x0), 4) != 0;
	return bad;
}

static bool have_gdal(void)
{
	char out[256];
	char *const argv[] = { "gdal_translate", "--version", NULL };
	return daemon_env_run(argv, out, sizeof out) == 0;
}

/* GDAL reads levels 1 and 3 whole, and a window of level 4, through WMTS: the same pixels as
 * clipmapctl render. */
static void gdal_equals_render(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	if (!have_gdal())
		skip();
	char a[200], b[200];
	for (int z = 1; z <= 4; z += z == 1 ? 2 : 1) {
		snprintf(a, sizeof a, "%s/gdal%d.png", e->d.dir, z);
		snprintf(b, sizeof b, "%s/render%d.png", e->d.dir, z);
		/* level 4 (2048×1024): a window across the antimeridian's east side and a pole */
		gdal_level(e, z, z == 4 ? "1536 0 512 384" : NULL, a);
		render_level(e, z, b);
		struct img_info ia, ib;
		uint8_t *pa = read_img(a, IMG_U8, &ia), *pb = read_img(b, IMG_U8, &ib);
		int W = 64 << (z + 1), H = 64 << z;
		assert_int_equal(ib.width, W);
		assert_int_equal(ib.height, H);
		assert_int_equal(ia.channels, 4);
		long bad;
		if (z == 4) {
			assert_int_equal(ia.width, 512);
			assert_int_equal(ia.height, 384);
			bad = differing(pa, 512, 384, pb, W, 1536, 0);
		} else {
			assert_int_equal(ia.width, W);
			assert_int_equal(ia.height, H);
			bad = differing(pa, W, H, pb, W, 0, 0);
		}
		if (bad)
			fail_msg("level %d: %ld pixels differ between GDAL (WMTS) and clipmapctl render "
				 "(%s, %s)", z, bad, a, b);
		free(pa);
		free(pb);
	}
}

/* The 16-bit PNG of a height tile is round(metres) + 32768 of its float32 GeoTIFF, gdalinfo
 * reads the GeoTIFF's georeferencing, and TMS's y runs from the south. */
static void heights_and_georeference(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char png[200], tif[200], tms[200];
	snprintf(png, sizeof png, "%s/h.png", e->d.dir);
	snprintf(tif, sizeof tif, "%s/h.tif", e->d.dir);
	snprintf(tms, sizeof tms, "%s/tms.png", e->d.dir);
	/* level 3: 16 × 8 tiles; row 2, column 11 → TMS y = 8 - 1 - 2 = 5 */
	assert_int_equal(get(e, "/wmts/test/height/3/2/11.png", png, NULL), 200);
	assert_int_equal(get(e, "/wmts/test/height/3/2/11.tif", tif, NULL), 200);
	assert_int_equal(get(e, "/tms/1.0.0/test/height/3/11/5.png", tms, NULL), 200);
	struct img_info ip, it, im;
	uint16_t *p = read_img(png, IMG_U16, &ip), *q = read_img(tms, IMG_U16, &im);
	float *h = read_img(tif, IMG_F32, &it);
	assert_int_equal(ip.width, 64);
	assert_int_equal(ip.height, 64);
	assert_int_equal(it.width, 64);
	int moved = 0;
	for (int i = 0; i < 64 * 64; i++) {
		if ((long)p[i] != lround(h[i]) + 32768)
			fail_msg("texel %d: PNG %u, GeoTIFF %.3f m", i, p[i], (double)h[i]);
		moved |= p[i] != p[0];
	}
	assert_true(moved); /* a tile of real relief, not a constant */
	assert_memory_equal(p, q, 64 * 64 * 2);
	free(p);
	free(q);
	free(h);
	if (!have_gdal())
		return;
	char out[8192];
	char *const argv[] = { "gdalinfo", tif, NULL };
	assert_int_equal(daemon_env_run(argv, out, sizeof out), 0);
	if (!strstr(out, "ID[\"EPSG\",4326]"))
		fail_msg("gdalinfo shows no EPSG:4326:\n%s", out);
	/* column 11 of 16: west = -180 + 11·22.5 = 67.5; row 2 of 8: north = 90 - 2·22.5 = 45 */
	if (!strstr(out, "Upper Left  (  67.5000000,  45.0000000)") ||
	    !strstr(out, "Lower Right (  90.0000000,  22.5000000)"))
		fail_msg("gdalinfo's corners are not the tile's:\n%s", out);
}

/* clipmapctl's exports carry their place: gdalinfo reads EPSG:4326 and the corners of a whole
 * level, of a block across the antimeridian and of one tile fetched through the daemon. */
static void exports_georeferenced(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	if (!have_gdal())
		skip();
	char exe[600], f[3][200], out[8192];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	for (int i = 0; i < 3; i++)
		snprintf(f[i], sizeof f[i], "%s/export%d.tif", e->d.dir, i);
	char *const world[] = { exe, "render", e->planet, "color", "--level", "1", "--world",
				"--quiet", "-o", f[0], NULL };
	/* level 3 (16 × 8 tiles of 22.5°): 2 × 2 tiles around 10°S 179°E: x 15..16 → 157.5..202.5 */
	char *const block[] = { exe, "render", e->planet, "height", "--level", "3", "--at",
				"-10,179", "--tiles", "2", "--quiet", "-o", f[1], NULL };
	char *const tile[] = { exe, "-s", e->d.sock, "tile", "test", "height", "4", "3", "13", "2",
			       "-o", f[2], NULL };
	char *const *cmds[] = { world, block, tile };
	static const char *const corners[][2] = {
		{ "Upper Left  (-180.0000000,  90.0000000)", "Lower Right ( 180.0000000, -90.0000000)" },
		{ "Upper Left  ( 157.5000000,   0.0000000)", "Lower Right (     202.500,     -45.000)" },
		/* lx 4, ly 3: 16 × 8 tiles; x 13 → 112.5..135, y 2 → 45..22.5 */
		{ "Upper Left  ( 112.5000000,  45.0000000)", "Lower Right ( 135.0000000,  22.5000000)" },
	};
	for (int i = 0; i < 3; i++) {
		int rc = daemon_env_run(cmds[i], out, sizeof out);
		if (rc)
			fail_msg("export %d: exit %d: %s", i, rc, out);
		char *const info[] = { "gdalinfo", f[i], NULL };
		assert_int_equal(daemon_env_run(info, out, sizeof out), 0);
		if (!strstr(out, "ID[\"EPSG\",4326]") || !strstr(out, corners[i][0]) ||
		    !strstr(out, corners[i][1]))
			fail_msg("export %d: gdalinfo shows no EPSG:4326 or wrong corners (want %s, "
				 "%s):\n%s", i, corners[i][0], corners[i][1], out);
	}
}

/* CesiumJS (npm `cesium` in Node) reads layer.json and decodes quantized-mesh tiles: at texel
 * corners (the mesh's vertices) the height it interpolates equals the mean of the four texels
 * around the corner in the daemon's float32 height tile, to the mesh's quantization; a level-0
 * tile decodes too, and children are declared available. */
/* CesiumJS in Node: skips the test without the npm package (make deps puts it in build/npm)
 * or a node ≥ 20; script receives tests/http/cesium_heights.mjs. */
static void need_cesium_in_node(struct env *e, char script[700])
{
	char npm[700], probe[800], ver[64] = "";
	snprintf(npm, sizeof npm, "%s/build/npm", e->d.root);
	snprintf(script, 700, "%s/tests/http/cesium_heights.mjs", e->d.root);
	snprintf(probe, sizeof probe, "%s/node_modules/cesium/package.json", npm);
	if (access(probe, R_OK) != 0) {
		print_message("no CesiumJS in %s (make deps installs it): skipped\n", npm);
		skip();
	}
	/* CesiumJS asks for Node 22; 20 runs what this test uses, Debian 12's 18 is not tried */
	char *const nv[] = { "node", "--version", NULL };
	if (daemon_env_run(nv, ver, sizeof ver) != 0 || atoi(ver + (ver[0] == 'v')) < 20) {
		print_message("node %s is older than 20: CesiumJS in Node skipped\n", ver);
		skip();
	}
	setenv("CLIPMAP_NPM", npm, 1);
}

static void cesium_terrain(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char script[700];
	need_cesium_in_node(e, script);
	char base[128], tif[200];
	snprintf(base, sizeof base, "%s/cesium/test", e->url);
	/* level 3 (16 × 8 tiles of 22.5°, 64² texels): row 2, column 11 */
	snprintf(tif, sizeof tif, "%s/h3.tif", e->d.dir);
	assert_int_equal(get(e, "/wmts/test/height/3/2/11.tif", tif, NULL), 200);
	struct img_info ii;
	float *h = read_img(tif, IMG_F32, &ii);
	static const int corner[][2] = { { 10, 20 }, { 33, 47 }, { 63, 1 }, { 1, 63 } };
	char pts[4][64];
	double want[4], lo = INFINITY, hi = -INFINITY;
	for (int i = 0; i < 64 * 64; i++) {
		lo = h[i] < lo ? h[i] : lo;
		hi = h[i] > hi ? h[i] : hi;
	}
	for (int k = 0; k < 4; k++) {
		int ci = corner[k][0], cj = corner[k][1];
		/* where the mesh put the vertex: u, v quantized to 1/32767 of the tile */
		double lon = 67.5 + round(ci * 32767.0 / 64) / 32767 * 22.5,
		       lat = 22.5 + round((64 - cj) * 32767.0 / 64) / 32767 * 22.5;
		snprintf(pts[k], sizeof pts[k], "%.12f,%.12f", lon, lat);
		want[k] = (h[(cj - 1) * 64 + ci - 1] + h[(cj - 1) * 64 + ci] + h[cj * 64 + ci - 1] +
			   h[cj * 64 + ci]) / 4.0;
	}
	free(h);
	char out[8192];
	char *const argv[] = { "node", script, base, "1000000", "0", "3", "11", "2", pts[0], pts[1],
			       pts[2], pts[3], NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc)
		fail_msg("cesium_heights.mjs: exit %d:\n%s", rc, out);
	/* The mesh quantizes heights to 1/32767 of the tile's range (corners lie inside it). */
	double tol = (hi - lo) / 32767.0 + 1e-3;
	const char *p = out;
	for (int k = 0; k < 4; k++) {
		double lon, lat, got;
		if (sscanf(p, "%lf %lf %lf", &lon, &lat, &got) != 3)
			fail_msg("unexpected output:\n%s", out);
		print_message("Cesium at %s: %.3f m, daemon %.3f m\n", pts[k], got, want[k]);
		if (fabs(got - want[k]) > tol)
			fail_msg("Cesium reads %.3f m at %s, the daemon's tile says %.3f m (±%.4f)",
				 got, pts[k], want[k], tol);
		p = strchr(p, '\n') + 1;
	}
	assert_non_null(strstr(out, "available 4 22 4 yes"));
	/* level 0: the western hemisphere tile, wider than any horizon */
	char *const l0[] = { "node", script, base, "1000000", "0", "0", "0", "0", "-90,0", NULL };
	rc = daemon_env_run(l0, out, sizeof out);
	if (rc)
		fail_msg("cesium_heights.mjs level 0: exit %d:\n%s", rc, out);
	double lon, lat, got;
	assert_int_equal(sscanf(out, "%lf %lf %lf", &lon, &lat, &got), 3);
	assert_true(fabs(got) < 600); /* the planet's amplitude is 500 m */
	/* bad requests */
	assert_int_equal(get(e, "/cesium/test/9/0/0.terrain", NULL, NULL), 404);
	assert_int_equal(get(e, "/cesium/test/1/0/2.terrain", NULL, NULL), 400);
	assert_int_equal(get(e, "/cesium/nope/layer.json", NULL, NULL), 404);
}

/* The unit normal (east, north, up) of an RGB normal texel ((c + 1) · 127.5; up from east and
 * north, as the daemon's RG8 has it). */
static void texel_normal(const uint8_t *px, double out[3])
{
	double e = px[0] / 127.5 - 1, n = px[1] / 127.5 - 1, u2 = 1 - e * e - n * n;
	out[0] = e;
	out[1] = n;
	out[2] = u2 > 0 ? sqrt(u2) : 0;
}

static double angle_deg(const double a[3], const double b[3])
{
	double d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
	double la = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]),
	       lb = sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2]);
	d /= la * lb;
	return acos(d > 1 ? 1 : d < -1 ? -1 : d) * 180 / M_PI;
}

/* Runs cesium_heights.mjs with vertex normals for tile (3, x, y) at the points; reads its
 * "normal LON LAT E N U" lines into out. */
static void cesium_normals_at(struct env *e, const char *script, int x, int y,
			      char pts[][64], int n, double out[][3])
{
	char base[128], xs[16], ys[16], o[16384];
	snprintf(base, sizeof base, "%s/cesium/test", e->url);
	snprintf(xs, sizeof xs, "%d", x);
	snprintf(ys, sizeof ys, "%d", y);
	char *argv[16] = { "node", (char *)script, base, "1000000", "0", "3", xs, ys };
	int k = 8;
	for (int i = 0; i < n; i++)
		argv[k++] = pts[i];
	argv[k] = NULL;
	setenv("CLIPMAP_NORMALS", "1", 1);
	int rc = daemon_env_run(argv, o, sizeof o);
	unsetenv("CLIPMAP_NORMALS");
	if (rc)
		fail_msg("cesium_heights.mjs (normals): exit %d:\n%s", rc, o);
	const char *p = o;
	for (int i = 0; i < n; i++) {
		p = strstr(p, "normal ");
		double lon, lat;
		if (!p || sscanf(p, "normal %lf %lf %lf %lf %lf", &lon, &lat, &out[i][0], &out[i][1],
				 &out[i][2]) != 5)
			fail_msg("no normal %d in:\n%s", i, o);
		p++;
	}
}

/* Vertex normals (the octvertexnormals extension), decoded by CesiumJS itself: layer.json
 * lists the extension; a tile asked with Cesium's Accept header carries 2 bytes per vertex
 * more than one asked without; at texel corners the normal Cesium decodes is the daemon's
 * normal tile there (the mean of the four texels around the corner) within the 8-bit
 * oct-encoding's precision; and two neighbouring tiles give nearly the same normal at a
 * vertex of their shared edge. */
static void cesium_normals(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char script[700];
	need_cesium_in_node(e, script);
	char f[200], g[200];
	snprintf(f, sizeof f, "%s/layer.json", e->d.dir);
	assert_int_equal(get(e, "/cesium/test/layer.json", f, NULL), 200);
	char *lj = slurp(f);
	if (!strstr(lj, "\"extensions\": [\"octvertexnormals\"]"))
		fail_msg("layer.json lists no octvertexnormals:\n%s", lj);
	free(lj);
	/* with and without: 65² vertices · 2 bytes + the extension's 5-byte header */
	snprintf(g, sizeof g, "%s/n.terrain", e->d.dir);
	assert_int_equal(get(e, "/cesium/test/3/11/5.terrain", f, NULL), 200);
	assert_int_equal(get(e, "/cesium/test/3/11/5.terrain", g,
			     "Accept: application/vnd.quantized-mesh;extensions=octvertexnormals,"
			     "application/octet-stream;q=0.9,*/*;q=0.01"), 200);
	struct stat sf, sg;
	assert_int_equal(stat(f, &sf), 0);
	assert_int_equal(stat(g, &sg), 0);
	assert_int_equal((long)(sg.st_size - sf.st_size), 65 * 65 * 2 + 5);
	/* the daemon's normal tile: level 3, row 2, column 11 (Cesium's y from the north: 2) */
	char tif[200];
	snprintf(tif, sizeof tif, "%s/n3.tif", e->d.dir);
	assert_int_equal(get(e, "/wmts/test/normal/3/2/11.tif", tif, NULL), 200);
	struct img_info ii;
	uint8_t *px = read_img(tif, IMG_U8, &ii);
	assert_int_equal(ii.channels, 3);
	static const int corner[][2] = { { 10, 20 }, { 33, 47 }, { 63, 1 }, { 1, 63 }, { 40, 12 } };
	enum { NC = 5 };
	char pts[NC + 1][64];
	double want[NC][3], got[NC + 1][3], tilt = 0;
	for (int k = 0; k < NC; k++) {
		int ci = corner[k][0], cj = corner[k][1];
		double lon = 67.5 + round(ci * 32767.0 / 64) / 32767 * 22.5,
		       lat = 22.5 + round((64 - cj) * 32767.0 / 64) / 32767 * 22.5;
		snprintf(pts[k], sizeof pts[k], "%.12f,%.12f", lon, lat);
		want[k][0] = want[k][1] = want[k][2] = 0;
		for (int d = 0; d < 4; d++) {
			double t[3];
			texel_normal(px + 3 * ((size_t)(cj - 1 + d / 2) * 64 + ci - 1 + d % 2), t);
			for (int j = 0; j < 3; j++)
				want[k][j] += t[j] / 4;
		}
	}
	for (int i = 0; i < 64 * 64; i++) {
		double t[3], up[3] = { 0, 0, 1 };
		texel_normal(px + 3 * (size_t)i, t);
		double a = angle_deg(t, up);
		tilt = a > tilt ? a : tilt;
	}
	free(px);
	/* a vertex of the east edge (column 64 = the next tile's column 0), row 20 */
	snprintf(pts[NC], sizeof pts[NC], "90,%.12f", 22.5 + round(44 * 32767.0 / 64) / 32767 * 22.5);
	cesium_normals_at(e, script, 11, 2, pts, NC + 1, got);
	for (int k = 0; k < NC; k++) {
		double a = angle_deg(got[k], want[k]);
		print_message("normal at %s: Cesium (%.3f %.3f %.3f), daemon (%.3f %.3f %.3f): %.2f°\n",
			      pts[k], got[k][0], got[k][1], got[k][2], want[k][0], want[k][1], want[k][2], a);
		/* 8-bit oct encoding: within about 1°; texels quantized to 1/127.5 */
		if (a > 2)
			fail_msg("Cesium's normal at %s is %.2f° off the daemon's", pts[k], a);
	}
	print_message("the tile's normals tilt up to %.1f° from straight up\n", tilt);
	assert_true(tilt > 5); /* real relief (exaggeration 30), not a flat planet */
	double other[1][3];
	cesium_normals_at(e, script, 12, 2, &pts[NC], 1, other);
	double seam = angle_deg(got[NC], other[0]);
	print_message("at the shared edge (%s): tile 11 (%.3f %.3f %.3f), tile 12 (%.3f %.3f %.3f): "
		      "%.2f° apart\n", pts[NC], got[NC][0], got[NC][1], got[NC][2], other[0][0],
		      other[0][1], other[0][2], seam);
	assert_true(seam < 4);
}

/* Headless Chromium (a real browser, driven over the DevTools protocol) opens the page: CesiumJS
 * from build/npm shows the planet with the daemon's imagery on the daemon's terrain, no
 * console error or exception, and the screenshot is the planet's colours (the test planet's
 * ramp: blue, green, white), not blank. The screenshot is kept in
 * build/test-output/test_http_browser.png. */
static void browser_page(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char npm[700], script[700], probe[800], out[8192];
	snprintf(npm, sizeof npm, "%s/build/npm", e->d.root);
	snprintf(script, sizeof script, "%s/tests/http/browser_shot.mjs", e->d.root);
	snprintf(probe, sizeof probe, "%s/node_modules/cesium/Build/Cesium/Cesium.js", npm);
	char *const which[] = { "chromium", "--version", NULL };
	if (access(probe, R_OK) != 0 || daemon_env_run(which, out, sizeof out) != 0) {
		print_message("no CesiumJS or no chromium (make deps installs both): skipped\n");
		skip();
	}
	char dir[700], png[800], url[200];
	snprintf(dir, sizeof dir, "%s/test-output", e->d.bindir);
	mkdir(dir, 0755);
	snprintf(png, sizeof png, "%s/test_http_browser.png", dir);
	unlink(png);
	snprintf(url, sizeof url, "%s/?planet=test&lon=60&lat=20&alt=2500000", e->url);
	char *const argv[] = { "node", script, url, png, "240", NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	print_message("browser: %s", out);
	if (rc)
		fail_msg("the page did not load cleanly in Chromium (exit %d):\n%s", rc, out);
	struct img_info ii;
	uint8_t *px = read_img(png, IMG_U8, &ii);
	long n = (long)ii.width * ii.height, dark = 0, blue = 0, green = 0, white = 0;
	double lit[2] = { 0, 0 }; /* brightness of the globe's upper-left and lower-right quarters */
	long nlit[2] = { 0, 0 };
	for (long i = 0; i < n; i++) {
		const uint8_t *p = px + (size_t)i * ii.channels;
		int r = p[0], g = p[1], b = p[2];
		long x = i % ii.width, y = i / ii.width;
		int q = x < ii.width / 2 && y < ii.height / 2 ? 0
			: x >= ii.width / 2 && y >= ii.height / 2 ? 1 : -1;
		if (q >= 0 && r + g + b >= 40 && y > 60) { /* on the globe, below the toolbar */
			lit[q] += r + g + b;
			nlit[q]++;
		}
		dark += r + g + b < 40;
		blue += b > 100 && b > r + 40 && b > g + 20;
		green += g > 60 && g > r + 20 && g > b + 20;
		white += r > 200 && g > 200 && b > 200;
	}
	free(px);
	print_message("screenshot %s: %dx%d, %.0f %% dark, %.1f %% blue, %.1f %% green, "
		      "%.1f %% white\n", png, ii.width, ii.height, 100.0 * dark / n, 100.0 * blue / n,
		      100.0 * green / n, 100.0 * white / n);
	assert_true(dark < n * 0.75);	     /* a globe, not a black page */
	assert_true(blue + green > n / 20); /* in the planet's own colours */
	/* lit by the terrain's vertex normals, the light over the viewer's left shoulder: the
	 * upper-left of the globe is brighter than its lower-right (flat, they are alike) */
	double ul = nlit[0] ? lit[0] / nlit[0] : 0, lr = nlit[1] ? lit[1] / nlit[1] : 1;
	print_message("lighting: upper-left quarter %.0f, lower-right %.0f (ratio %.2f)\n", ul, lr,
		      ul / lr);
	assert_true(ul > 1.15 * lr);
}

static void revalidation_and_keepalive(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char hdr[200], out[8192];
	snprintf(hdr, sizeof hdr, "%s/headers", e->d.dir);
	char url[200];
	snprintf(url, sizeof url, "%s/wmts/test/color/2/1/3.png", e->url);
	char *const argv[] = { "curl", "-s", "-D", hdr, "-o", "/dev/null", url, NULL };
	assert_int_equal(daemon_env_run(argv, out, sizeof out), 0);
	char *h = slurp(hdr), *et = strstr(h, "ETag: ");
	assert_non_null(et);
	assert_non_null(strstr(h, "Cache-Control: public, max-age="));
	assert_non_null(strstr(h, "Content-Type: image/png"));
	char inm[128];
	snprintf(inm, sizeof inm, "If-None-Match: %.*s", (int)strcspn(et + 6, "\r\n"), et + 6);
	free(h);
	assert_int_equal(get(e, "/wmts/test/color/2/1/3.png", NULL, inm), 304);
	assert_int_equal(get(e, "/wmts/test/color/2/1/3.jpg", NULL, inm), 200); /* another ETag */
	/* two requests on one connection */
	char u1[200], u2[200];
	snprintf(u1, sizeof u1, "%s/healthz", e->url);
	snprintf(u2, sizeof u2, "%s/readyz", e->url);
	char *const two[] = { "curl", "-sv", u1, u2, NULL };
	assert_int_equal(daemon_env_run(two, out, sizeof out), 0);
	if (!strstr(out, "Re-using existing connection"))
		fail_msg("no keep-alive:\n%s", out);
	assert_non_null(strstr(out, "ready: 1 planets"));
	/* gzip where it pays: the capabilities (text) and a terrain tile, and the bytes intact */
	const char *zpaths[] = { "/wmts/1.0.0/WMTSCapabilities.xml", "/cesium/test/2/3/1.terrain" };
	for (int i = 0; i < 2; i++) {
		char zf[200], pf[200];
		snprintf(zf, sizeof zf, "%s/z%d", e->d.dir, i);
		snprintf(pf, sizeof pf, "%s/p%d", e->d.dir, i);
		snprintf(url, sizeof url, "%s%s", e->url, zpaths[i]);
		char *const zc[] = { "curl", "-s", "--compressed", "-D", hdr, "-o", zf, url, NULL };
		assert_int_equal(daemon_env_run(zc, out, sizeof out), 0);
		char *zh = slurp(hdr);
		if (!strstr(zh, "Content-Encoding: gzip"))
			fail_msg("%s: not gzip-encoded:\n%s", zpaths[i], zh);
		free(zh);
		assert_int_equal(get(e, zpaths[i], pf, NULL), 200);
		char *const cmp[] = { "cmp", zf, pf, NULL };
		assert_int_equal(daemon_env_run(cmp, out, sizeof out), 0);
	}
}

/* A client that sends half a request and stalls; returns its socket. */
static int slow_client(struct env *e)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)e->port) };
	a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
	assert_int_equal(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
	const char half[] = "GET /wmts/test/color/0/0/0.png HTTP/1.1\r\nHost: x\r\n";
	assert_int_equal(write(fd, half, sizeof half - 1), (ssize_t)(sizeof half - 1));
	return fd;
}

static void bad_requests(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char body[200];
	snprintf(body, sizeof body, "%s/body", e->d.dir);
	static const struct { const char *path; int status; const char *says; } cases[] = {
		{ "/wmts/test/color/9/0/0.png", 404, "beyond test's finest level 8" },
		{ "/wmts/test/nope/1/0/0.png", 404, "no layer nope" },
		{ "/wmts/mars/color/1/0/0.png", 404, "no planet mars" },
		{ "/wmts/test/color/1/0/0.gif", 400, "unknown format" },
		{ "/wmts/test/color/1/2/0.png", 400, "outside the level" },
		{ "/wmts/test/color/1/0/4.png", 400, "outside the level" },
		{ "/wmts/test/color/-1/0/0.png", 400, "bad level" },
		{ "/wmts/test/color/1/0/00.png", 400, "bad tile" },
		{ "/wmts/test/height/1/0/0.jpg", 400, "heights are served as" },
		{ "/wmts/../color/1/0/0.png", 400, "bad planet or layer name" },
		{ "/wmts/../../etc/passwd/0/0.png", 404, "no such path" },
		{ "/nothing/here", 404, "no such path" },
		{ "/wmts", 400, "GetCapabilities" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		int st = get(e, cases[i].path, body, NULL);
		char *b = slurp(body);
		if (st != cases[i].status || !strstr(b, cases[i].says))
			fail_msg("%s: %d \"%s\", expected %d saying \"%s\"", cases[i].path, st, b,
				 cases[i].status, cases[i].says);
		free(b);
	}
	/* a 40 KiB path: refused, not buffered */
	char *huge = malloc(40 << 10);
	memset(huge, 'a', 40 << 10);
	huge[0] = '/';
	huge[(40 << 10) - 1] = '\0';
	int st = get(e, huge, NULL, NULL);
	free(huge);
	assert_true(st >= 400 && st < 500);
	/* slow clients hold no one up, and are cut off after timeout_s (2 s) */
	int slow[8];
	for (int i = 0; i < 8; i++)
		slow[i] = slow_client(e);
	uint64_t t0 = clock_now_ns();
	assert_int_equal(get(e, "/wmts/test/color/1/0/1.png", NULL, NULL), 200);
	double ms = (double)(clock_now_ns() - t0) * 1e-6;
	print_message("a tile while 8 clients stall: %.0f ms\n", ms);
	char c;
	ssize_t r = read(slow[0], &c, 1); /* blocks until the daemon closes it */
	double cut = (double)(clock_now_ns() - t0) * 1e-9;
	print_message("a stalled client cut off after %.1f s (timeout_s = 2)\n", cut);
	assert_true(r <= 0 || cut < 30);
	assert_true(cut < 30);
	for (int i = 0; i < 8; i++)
		close(slow[i]);
	assert_int_equal(get(e, "/healthz", NULL, NULL), 200);
}

static double metric(const char *text, const char *name)
{
	char key[128];
	snprintf(key, sizeof key, "\n%s ", name);
	const char *p = strstr(text, key);
	return p ? strtod(p + strlen(key), NULL) : -1;
}

static void metrics_count(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char m[200];
	snprintf(m, sizeof m, "%s/metrics", e->d.dir);
	assert_int_equal(get(e, "/healthz", NULL, NULL), 200);
	assert_int_equal(get(e, "/readyz", NULL, NULL), 200);
	daemon_env_log_wait(&e->d, "never", 1, 1200); /* metrics are gathered once a second */
	assert_int_equal(get(e, "/metrics", m, NULL), 200);
	char *a = slurp(m);
	assert_non_null(strstr(a, "# TYPE clipmapd_cache_hits_total counter"));
	assert_non_null(strstr(a, "clipmapd_build_info{version="));
	double before = metric(a, "clipmapd_http_tiles_sent_total");
	assert_true(before >= 0);
	for (int x = 0; x < 4; x++) {
		char p[64];
		snprintf(p, sizeof p, "/wmts/test/color/1/0/%d.webp", x);
		assert_int_equal(get(e, p, NULL, NULL), 200);
		assert_int_equal(get(e, p, NULL, NULL), 200); /* again: from the encoded cache */
	}
	/* metrics are gathered once a second by the daemon's tick; under a sanitizer on a loaded
	 * machine a tick can come late, so poll until the eight answers are counted (a bound) */
	char *b = NULL;
	double until = clock_now_s() + test_slow(15);
	for (;;) {
		daemon_env_log_wait(&e->d, "never", 1, 300);
		assert_int_equal(get(e, "/metrics", m, NULL), 200);
		free(b);
		b = slurp(m);
		if (metric(b, "clipmapd_http_tiles_sent_total") >= before + 8 ||
		    clock_now_s() > until)
			break;
	}
	assert_true(metric(b, "clipmapd_http_tiles_sent_total") >= before + 8);
	assert_true(metric(b, "clipmapd_http_cache_hits_total") >= 4);
	/* the generation-time histogram of the colour node: as many counted as generated */
	double gen = metric(b, "clipmapd_node_generated_total{planet=\"test\",node=\"tint\"}");
	assert_true(gen >= 4);
	assert_true(metric(b, "clipmapd_node_generate_seconds_count{planet=\"test\",node=\"tint\"}") ==
		    gen);
	assert_true(metric(b, "clipmapd_node_generate_seconds_bucket{planet=\"test\",node=\"tint\","
			      "le=\"+Inf\"}") == gen);
	assert_true(metric(b, "clipmapd_sched_generated_total") > 0);
	/* promtool's own check of the format and names, where Prometheus is installed */
	char out[8192];
	char *const pt[] = { "sh", "-c", "command -v promtool >/dev/null || exit 77; "
					  "promtool check metrics < \"$0\"", m, NULL };
	int rc = daemon_env_run(pt, out, sizeof out);
	if (rc != 77 && rc != 0)
		fail_msg("promtool check metrics: exit %d:\n%s", rc, out);
	free(a);
	free(b);
}

/* A raw client that asks for one tile and returns its socket (the answer left unread). */
static int ask(struct env *e, const char *path)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)e->port) };
	a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
	assert_int_equal(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
	char req[300];
	int n = snprintf(req, sizeof req, "GET %s HTTP/1.1\r\nHost: x\r\n\r\n", path);
	assert_int_equal(write(fd, req, (size_t)n), n);
	return fd;
}

/* /metrics, gathered anew (once a second): waits for the next gathering. */
static char *fresh_metrics(struct env *e)
{
	char m[200];
	snprintf(m, sizeof m, "%s/metrics", e->d.dir);
	daemon_env_log_wait(&e->d, "never", 1, 1200);
	assert_int_equal(get(e, "/metrics", m, NULL), 200);
	return slurp(m);
}

/* One of the daemon's live figures (`clipmapctl status --json`, not /metrics' copy of once a
 * second); 0 when it has none of that name yet. */
static double live(struct env *e, const char *key)
{
	char exe[600], out[65536], k[200];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->d.bindir);
	char *argv[] = { exe, "-s", e->d.sock, "status", "--json", NULL };
	if (daemon_env_run(argv, out, sizeof out) != 0)
		fail_msg("clipmapctl status: %s", out);
	snprintf(k, sizeof k, "\"%s\": ", key);
	const char *v = strstr(out, k);
	return v ? strtod(v + strlen(k), NULL) : 0;
}

#define SLOW_MADE "node.slow.base.generated"

/* Clients that hang up while their tiles are made cancel them: 40 connections each ask for an
 * uncached tile of the slow planet (one worker, 1024² texels of noise a tile) and close as soon
 * as the scheduler holds all of them. The daemon counts the requests cancelled (all but those
 * made by then), its scheduler drops their queued work, at most a few tiles are made after the
 * hang-ups, and other clients are served. One more client asked for the last of those tiles
 * and stays: its tile is made for it anyway. Nothing here depends on how fast a tile is made:
 * what was made before the hang-ups is read from the daemon, not assumed from a delay. */
static void hangup_cancels(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char *m0 = fresh_metrics(e);
	double sc0 = metric(m0, "clipmapd_sched_cancelled_total");
	assert_true(metric(m0, "clipmapd_http_cancelled_total") == 0);
	assert_non_null(strstr(m0, "clipmapd_sched_queued_web "));
	free(m0);
	double gen0 = live(e, SLOW_MADE);
	enum { N = 40 };
	int fd[N];
	for (int i = 0; i < N; i++) {
		char p[100]; /* level 7 (256 × 128 tiles), a row of them */
		snprintf(p, sizeof p, "/wmts/slow/height/7/%d/%d.tif", 40 + i / 20, 100 + i % 20);
		fd[i] = ask(e, p);
	}
	int stays = ask(e, "/wmts/slow/height/7/41/119.tif"); /* fd[N - 1]'s tile */
	/* until every request is made, running or queued (N different tiles); read in this order
	 * a job moving on between the reads is missed, never counted twice */
	double before = 0, held = 0, until = clock_now_s() + test_slow(20);
	do {
		held = live(e, SLOW_MADE) - gen0;
		held += live(e, "sched.workers.busy");
		held += live(e, "sched.queued.web");
	} while (held < N && clock_now_s() < until);
	before = live(e, SLOW_MADE) - gen0;
	if (held < N)
		fail_msg("the scheduler held %.0f of %d requests after 20 s", held, N);
	for (int i = 0; i < N; i++)
		close(fd[i]);
	/* the daemon still serves: a tile of the other planet, and health */
	uint64_t t0 = clock_now_ns();
	assert_int_equal(get(e, "/wmts/test/color/2/1/1.png", NULL, NULL), 200);
	print_message("a tile right after 40 hang-ups: %.0f ms\n",
		      (double)(clock_now_ns() - t0) * 1e-6);
	assert_int_equal(get(e, "/healthz", NULL, NULL), 200);
	/* wait until nothing is queued or running any more */
	until = clock_now_s() + test_slow(60);
	while ((live(e, "sched.queued.web") > 0 || live(e, "sched.workers.busy") > 0) &&
	       clock_now_s() < until)
		usleep(50000);
	char *m = fresh_metrics(e);
	double cancelled = metric(m, "clipmapd_http_cancelled_total");
	double gen = live(e, SLOW_MADE) - gen0, after = gen - before;
	double sc = metric(m, "clipmapd_sched_cancelled_total") - sc0;
	free(m);
	print_message("40 requests hung up: %.0f made before, %.0f counted cancelled, %.0f queued "
		      "jobs dropped, %.0f tiles made after\n", before, cancelled, sc, after);
	/* each request not made by the hang-up is cancelled (the one running, one more made
	 * since the last look, and on a busy machine one or two the worker finished before the
	 * daemon's watcher ran may finish first) */
	assert_true(cancelled <= N && cancelled >= N - before - 4);
	/* after the hang-ups: the tile running then, the staying client's, and any the worker
	 * took before the scheduler heard of the hang-ups (2-3 in every run here) */
	assert_true(after <= 6);
	assert_true(sc + after >= cancelled); /* a cancelled request's job dropped or made */
	assert_true(gen + cancelled >= N);    /* each request either made or cancelled */
	/* the client that stayed gets its tile, though another asker of it left */
	char ans[64] = "";
	struct pollfd pf = { .fd = stays, .events = POLLIN };
	assert_int_equal(poll(&pf, 1, 60000), 1);
	assert_true(read(stays, ans, sizeof ans - 1) > 12);
	if (strncmp(ans, "HTTP/1.1 200", 12))
		fail_msg("the client that stayed got \"%.12s\"", ans);
	close(stays);
	/* and the slow planet still serves a client that waits */
	assert_int_equal(get(e, "/wmts/slow/height/7/41/100.tif", NULL, NULL), 200);
	assert_int_equal(kill(e->d.daemon, 0), 0);
}

static void token_required(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	assert_int_equal(get(e, "/wmts/test/color/0/0/0.png", NULL, NULL), 401);
	assert_int_equal(get(e, "/wmts/test/color/0/0/0.png", NULL, "Authorization: Bearer nope"),
			 401);
	assert_int_equal(get(e, "/wmts/test/color/0/0/0.png", NULL, "Authorization: Bearer s3cret"),
			 200);
	assert_int_equal(get(e, "/healthz", NULL, NULL), 200); /* for load balancers */
	assert_true(daemon_env_log_count(&e->d, "http: 127.0.0.1: missing or wrong bearer token") >= 2);
}

int main(void)
{
	/* GDAL's WMS/WMTS driver would otherwise keep tiles in ./gdalwmscache across runs. */
	setenv("GDAL_ENABLE_WMS_CACHE", "NO", 1);
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(gdal_equals_render, setup, teardown),
		cmocka_unit_test_setup_teardown(heights_and_georeference, setup, teardown),
		cmocka_unit_test_setup_teardown(exports_georeferenced, setup, teardown),
		cmocka_unit_test_setup_teardown(cesium_terrain, setup, teardown),
		cmocka_unit_test_setup_teardown(cesium_normals, setup, teardown),
		cmocka_unit_test_setup_teardown(browser_page, setup, teardown),
		cmocka_unit_test_setup_teardown(revalidation_and_keepalive, setup, teardown),
		cmocka_unit_test_setup_teardown(bad_requests, setup, teardown),
		cmocka_unit_test_setup_teardown(metrics_count, setup, teardown),
		cmocka_unit_test_setup_teardown(token_required, setup_token, teardown),
		cmocka_unit_test_setup_teardown(hangup_cancels, setup_slow, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
