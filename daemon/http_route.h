/* http_route — what an HTTP path asks for, parsed without touching any state (so it is tested
 * and fuzzed alone). The paths (docs/HTTP.md):
 *   /                                   the browser viewer (CesiumJS), or without CesiumJS the
 *                                       index of the planets and their layers (HTML)
 *   /planets.json                       the planets the viewer can show
 *   /cesium-js/{path}                   CesiumJS's own files
 *   /healthz, /readyz                   liveness, readiness (planets loaded)
 *   /metrics                            Prometheus text exposition
 *   /wmts/1.0.0/WMTSCapabilities.xml    OGC WMTS 1.0.0 capabilities (also the KVP form
 *                                       /wmts?SERVICE=WMTS&REQUEST=GetCapabilities)
 *   /wmts/{planet}/{layer}/{z}/{row}/{col}.{ext}   a tile, WorldCRS84Quad (row 0 north)
 *   /tms/1.0.0/{planet}/{layer}/{z}/{x}/{y}.{ext}  the same tile, TMS global-geodetic (y 0 south)
 *   /cesium/{planet}/layer.json         Cesium terrain: the tileset (quantized-mesh-1.0, TMS)
 *   /cesium/{planet}/{z}/{x}/{y}.terrain  a quantized-mesh tile of the planet's heights
 * Level z of the web grids is the daemon's level (lx, ly) = (z + 1, z): 2^(z+1) × 2^z tiles.
 */
#ifndef CLIPMAP_HTTP_ROUTE_H
#define CLIPMAP_HTTP_ROUTE_H
#include <stdint.h>

#include "common/geoimg.h"

enum http_kind {
	HTTP_NOT_FOUND = 0,
	HTTP_BAD,	/* a tile path that is malformed: 400 with route.why */
	HTTP_PAGE,  /* "/": the browser viewer */
	HTTP_INDEX, /* "/list": the plain index */
	HTTP_HEALTH,
	HTTP_READY,
	HTTP_METRICS,
	HTTP_WMTS_CAPS,
	HTTP_TILE,
	HTTP_CESIUM_LAYER, /* planet set */
	HTTP_CESIUM_TILE,  /* planet, z, x, y set; layer empty (the planet's heights) */
	HTTP_PLANETS_JSON,
	HTTP_STATIC, /* rel set: a file under the CesiumJS directory */
};

#define HTTP_NAME_MAX 64

struct http_route {
	enum http_kind kind;
	char planet[HTTP_NAME_MAX], layer[HTTP_NAME_MAX];
	uint32_t z, x, y; /* the daemon's grid: x east from -180°, y south from the north pole */
	enum geoimg_format fmt;
	const char *why; /* HTTP_BAD: a static message */
	char rel[512];	 /* HTTP_STATIC: the path below /cesium-js/ */
};

/* Parses url (the path, without the query) and, for /wmts, the query's SERVICE and REQUEST
 * values (either may be NULL). The tile's range against a planet's levels is checked by the
 * caller (z against the planet's max_level); here only against the grid (z ≤ 30, x, y inside
 * level z). */
void http_route_parse(const char *url, const char *service, const char *request,
		      struct http_route *out);

#endif
