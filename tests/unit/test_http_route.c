/* test_http_route — the HTTP endpoint's pure parts: what a path asks for (http_route) and
 * the Prometheus text (metrics). Paths from the hostile side too: traversal, huge numbers,
 * leading zeros, empty segments, levels and tiles outside the grid. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "http_route.h"
#include "metrics.h"

static struct http_route parse(const char *url)
{
	struct http_route r;
	http_route_parse(url, NULL, NULL, &r);
	return r;
}

static void routes(void **state)
{
	(void)state;
	assert_int_equal(parse("/").kind, HTTP_PAGE);
	assert_int_equal(parse("/list").kind, HTTP_INDEX);
	assert_int_equal(parse("/planets.json").kind, HTTP_PLANETS_JSON);
	struct http_route st = parse("/cesium-js/Widgets/widgets.css");
	assert_int_equal(st.kind, HTTP_STATIC);
	assert_string_equal(st.rel, "Widgets/widgets.css");
	static const char *const bad_files[] = { "/cesium-js/../x.js", "/cesium-js/a/../../x",
						 "/cesium-js/.hidden", "/cesium-js/a//b.js",
						 "/cesium-js/", "/cesium-js/a b.js", "/cesium-js/a/" };
	for (size_t i = 0; i < sizeof bad_files / sizeof bad_files[0]; i++)
		if (parse(bad_files[i]).kind != HTTP_BAD)
			fail_msg("%s accepted", bad_files[i]);
	assert_int_equal(parse("/healthz").kind, HTTP_HEALTH);
	assert_int_equal(parse("/readyz").kind, HTTP_READY);
	assert_int_equal(parse("/metrics").kind, HTTP_METRICS);
	assert_int_equal(parse("/wmts/1.0.0/WMTSCapabilities.xml").kind, HTTP_WMTS_CAPS);
	struct http_route r;
	http_route_parse("/wmts", "wmts", "getcapabilities", &r);
	assert_int_equal(r.kind, HTTP_WMTS_CAPS);
	http_route_parse("/wmts", "WMTS", "GetTile", &r);
	assert_int_equal(r.kind, HTTP_BAD);
	assert_int_equal(parse("/metrics/x").kind, HTTP_NOT_FOUND);
	assert_int_equal(parse("").kind, HTTP_NOT_FOUND);
	assert_int_equal(parse("healthz").kind, HTTP_NOT_FOUND);
	assert_int_equal(parse("//healthz").kind, HTTP_NOT_FOUND);
}

static void tiles(void **state)
{
	(void)state;
	/* WMTS: z, row, col */
	struct http_route r = parse("/wmts/earth/color/3/2/11.png");
	assert_int_equal(r.kind, HTTP_TILE);
	assert_string_equal(r.planet, "earth");
	assert_string_equal(r.layer, "color");
	assert_int_equal(r.z, 3);
	assert_int_equal(r.x, 11);
	assert_int_equal(r.y, 2);
	assert_int_equal(r.fmt, GEOIMG_PNG);
	/* TMS: z, x, y from the south: the same tile */
	r = parse("/tms/1.0.0/earth/color/3/11/5.webp");
	assert_int_equal(r.kind, HTTP_TILE);
	assert_int_equal(r.x, 11);
	assert_int_equal(r.y, 2);
	assert_int_equal(r.fmt, GEOIMG_WEBP);
	/* the corners of level 0 (2 × 1 tiles) and of level 29 */
	assert_int_equal(parse("/wmts/p/l/0/0/1.tif").kind, HTTP_TILE);
	assert_int_equal(parse("/wmts/p/l/0/0/2.tif").kind, HTTP_BAD);
	assert_int_equal(parse("/wmts/p/l/0/1/0.tif").kind, HTTP_BAD);
	r = parse("/wmts/p/l/29/536870911/1073741823.jpg");
	assert_int_equal(r.kind, HTTP_TILE);
	assert_int_equal(r.x, 1073741823u);
	assert_int_equal(parse("/wmts/p/l/29/536870912/0.jpg").kind, HTTP_BAD);
	assert_int_equal(parse("/wmts/p/l/30/0/0.png").kind, HTTP_BAD);
	assert_int_equal(parse("/wmts/p/l/99999999999/0/0.png").kind, HTTP_BAD);
	assert_int_equal(parse("/tms/1.0.0/p/l/1/0/2.png").kind, HTTP_BAD);
	/* hostile and malformed */
	static const char *const bad[] = {
		"/wmts/p/l/1/0/0",	"/wmts/p/l/1/0/0.gif",	"/wmts/p/l/01/0/0.png",
		"/wmts/p/l/1/-0/0.png", "/wmts/p/l/1/0/+1.png", "/wmts/p/l/1/0/0x1.png",
		"/wmts/../l/1/0/0.png", "/wmts/p/..x/1/0/0.png", "/wmts/p q/l/1/0/0.png",
		"/wmts/p/l/1/0/.png",	"/wmts/p/l//0/0.png",
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		r = parse(bad[i]);
		if (r.kind == HTTP_TILE)
			fail_msg("%s parsed as a tile", bad[i]);
	}
	/* a 64-byte name is too long, 63 fits */
	char url[300];
	snprintf(url, sizeof url, "/wmts/%063d/l/0/0/0.png", 0);
	assert_int_equal(parse(url).kind, HTTP_TILE);
	snprintf(url, sizeof url, "/wmts/%064d/l/0/0/0.png", 0);
	assert_int_equal(parse(url).kind, HTTP_BAD);
	/* longer than any route: not found, not a crash */
	char *huge = malloc(70000);
	memset(huge, 'a', 69999);
	huge[0] = '/';
	huge[69999] = '\0';
	assert_int_equal(parse(huge).kind, HTTP_NOT_FOUND);
	free(huge);
}

static void prometheus_text(void **state)
{
	(void)state;
	const struct proto_stat st[] = {
		{ .key = "uptime_s", .kind = PROTO_STAT_F64, .f = 12.5 },
		{ .key = "cache.hits", .kind = PROTO_STAT_U64, .u = 7 },
		{ .key = "sessions.total", .kind = PROTO_STAT_U64, .u = 3 },
		{ .key = "cache.bytes", .kind = PROTO_STAT_U64, .u = 4096 },
		{ .key = "node.earth.relief.generated", .kind = PROTO_STAT_U64, .u = 5 },
		{ .key = "node.earth.relief.mean_ms", .kind = PROTO_STAT_F64, .f = 2.0 },
		{ .key = "node.moon.base.generated", .kind = PROTO_STAT_U64, .u = 1 },
		{ .key = "version", .kind = PROTO_STAT_STR, .s = "x" },
	};
	size_t n;
	char *t = metrics_format(st, sizeof st / sizeof st[0], "v1\"x", &n);
	assert_int_equal(strlen(t), n);
	assert_non_null(strstr(t, "clipmapd_build_info{version=\"v1\\\"x\"} 1\n"));
	assert_non_null(strstr(t, "# TYPE clipmapd_uptime_seconds gauge\nclipmapd_uptime_seconds 12.5\n"));
	assert_non_null(strstr(t, "# TYPE clipmapd_cache_hits_total counter\nclipmapd_cache_hits_total 7\n"));
	assert_non_null(strstr(t, "# TYPE clipmapd_sessions_total counter\nclipmapd_sessions_total 3\n"));
	assert_non_null(strstr(t, "clipmapd_cache_bytes 4096\n"));
	assert_non_null(strstr(t, "clipmapd_node_generated_total{planet=\"earth\",node=\"relief\"} 5\n"));
	assert_non_null(strstr(t, "clipmapd_node_generated_total{planet=\"moon\",node=\"base\"} 1\n"));
	assert_non_null(strstr(t, "clipmapd_node_mean_seconds{planet=\"earth\",node=\"relief\"} 0.002\n"));
	/* one TYPE line per metric name */
	const char *p = strstr(t, "# TYPE clipmapd_node_generated_total");
	assert_non_null(p);
	assert_null(strstr(p + 1, "# TYPE clipmapd_node_generated_total"));
	assert_null(strstr(t, "version\""));
	free(t);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(routes),
		cmocka_unit_test(tiles),
		cmocka_unit_test(prometheus_text),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
