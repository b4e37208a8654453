/* http_page — see http_page.h. */
#include "http_page.h"

#include <stdbool.h>
#include <string.h>
#include <strings.h>

#include "common/pixfmt.h"
#include "common/strbuf.h"

static const char page[] =
	"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
	"<title>clipmapd</title>\n"
	"<script>window.CESIUM_BASE_URL = '/cesium-js/';</script>\n"
	"<script src=\"/cesium-js/Cesium.js\"></script>\n"
	"<link href=\"/cesium-js/Widgets/widgets.css\" rel=\"stylesheet\">\n"
	"<style>html,body,#globe{width:100%;height:100%;margin:0;padding:0;overflow:hidden}\n"
	"#bar{position:absolute;top:8px;left:8px;z-index:10;background:rgba(30,30,30,.8);"
	"color:#eee;font:13px sans-serif;padding:6px 8px;border-radius:4px}\n"
	"#bar a{color:#9cf;margin-left:6px}</style>\n"
	"</head><body>\n<div id=\"bar\">planet <select id=\"planet\"></select> layer "
	"<select id=\"layer\"></select><span id=\"links\"></span> <span id=\"status\"></span></div>\n"
	"<div id=\"globe\"></div>\n<script>\n"
	"'use strict';\n"
	"const errors = [];\n"
	"function report(msg) { errors.push(String(msg)); document.title = 'clipmapd: error'; "
	"document.getElementById('status').textContent = 'error: ' + msg; }\n"
	"window.addEventListener('error', e => report(e.message));\n"
	"window.addEventListener('unhandledrejection', e => report(e.reason));\n"
	"const consoleError = console.error; console.error = (...a) => { report(a.join(' ')); "
	"consoleError(...a); };\n"
	"let viewer = null, tilesLoaded = false;\n"
	"async function show(p, layerName) {\n"
	"  const ellipsoid = new Cesium.Ellipsoid(p.a, p.a, p.a * (1 - p.f));\n"
	"  Cesium.Ellipsoid.default = ellipsoid;\n"
	"  if (viewer) viewer.destroy();\n"
	"  const tiling = new Cesium.GeographicTilingScheme({ ellipsoid });\n"
	"  const imagery = new Cesium.UrlTemplateImageryProvider({\n"
	"    url: '/wmts/' + p.name + '/' + layerName + '/{z}/{y}/{x}.png', tilingScheme: tiling,\n"
	"    maximumLevel: p.max_level, tileWidth: p.tile_size, tileHeight: p.tile_size,\n"
	"    credit: 'clipmapd ' + p.name });\n"
	"  const terrain = p.heights ? await Cesium.CesiumTerrainProvider.fromUrl('/cesium/' + "
	"p.name, { ellipsoid, requestVertexNormals: true }) : new Cesium.EllipsoidTerrainProvider("
	"{ ellipsoid });\n"
	"  viewer = new Cesium.Viewer('globe', { baseLayer: new Cesium.ImageryLayer(imagery),\n"
	"    terrainProvider: terrain, globe: new Cesium.Globe(ellipsoid),\n"
	"    baseLayerPicker: false, geocoder: false, timeline: false, animation: false,\n"
	"    homeButton: true, sceneModePicker: false, navigationHelpButton: false,\n"
	"    fullscreenButton: false, infoBox: false, selectionIndicator: false,\n"
	"    skyBox: false, skyAtmosphere: p.air ? undefined : false });\n"
	"  viewer.scene.globe.depthTestAgainstTerrain = true;\n"
	/* With vertex normals the terrain is lit: by a light over the viewer's left shoulder
	 * (following the camera), not the sun of the clock, so the side in view is never night. */
	"  if (terrain.hasVertexNormals) {\n"
	"    const light = new Cesium.DirectionalLight({ direction: Cesium.Cartesian3.UNIT_X });\n"
	"    viewer.scene.light = light; viewer.scene.globe.enableLighting = true;\n"
	"    viewer.scene.globe.dynamicAtmosphereLighting = false;\n"
	"    const t = new Cesium.Cartesian3();\n"
	"    viewer.scene.preRender.addEventListener(() => { const c = viewer.camera, "
	"d = Cesium.Cartesian3.clone(c.directionWC);\n"
	"      Cesium.Cartesian3.add(d, Cesium.Cartesian3.multiplyByScalar(c.rightWC, 0.6, t), d);\n"
	"      Cesium.Cartesian3.subtract(d, Cesium.Cartesian3.multiplyByScalar(c.upWC, 0.6, t), d);\n"
	"      light.direction = Cesium.Cartesian3.normalize(d, d); });\n"
	"  }\n"
	"  const q = new URLSearchParams(location.search);\n"
	"  const lon = Number(q.get('lon') || 10), lat = Number(q.get('lat') || 30), "
	"alt = Number(q.get('alt') || 3 * p.a);\n"
	"  viewer.camera.setView({ destination: Cesium.Cartesian3.fromDegrees(lon, lat, alt, "
	"ellipsoid), orientation: { heading: 0, pitch: Cesium.Math.toRadians(Number(q.get('pitch') "
	"|| -90)) } });\n"
	"  tilesLoaded = false;\n"
	"  viewer.scene.globe.tileLoadProgressEvent.addEventListener(n => {\n"
	"    document.getElementById('status').textContent = n ? n + ' tiles loading' : 'loaded';\n"
	"    if (n === 0 && !errors.length) { tilesLoaded = true; document.title = 'clipmapd: "
	"loaded'; }\n"
	"  });\n"
	"  const links = document.getElementById('links'); links.textContent = '';\n"
	"  for (const l of p.layers) { const a = document.createElement('a');\n"
	"    a.href = '/wmts/' + p.name + '/' + l.name + '/0/0/0.png'; a.textContent = l.name;\n"
	"    links.appendChild(a); }\n"
	"}\n"
	"(async () => {\n"
	"  const planets = await (await fetch('/planets.json')).json();\n"
	"  const q = new URLSearchParams(location.search);\n"
	"  const ps = document.getElementById('planet'), ls = document.getElementById('layer');\n"
	"  for (const p of planets) ps.add(new Option(p.name + (p.description ? ' — ' + "
	"p.description : ''), p.name));\n"
	"  const pick = () => planets.find(p => p.name === ps.value) || planets[0];\n"
	"  const fillLayers = p => { ls.textContent = ''; for (const l of p.layers) if (l.type "
	"!== 'height') ls.add(new Option(l.name, l.name)); };\n"
	"  if (q.get('planet')) ps.value = q.get('planet');\n"
	"  fillLayers(pick()); if (q.get('layer')) ls.value = q.get('layer');\n"
	"  ps.onchange = () => { fillLayers(pick()); show(pick(), ls.value).catch(report); };\n"
	"  ls.onchange = () => show(pick(), ls.value).catch(report);\n"
	"  await show(pick(), ls.value);\n"
	"})().catch(report);\n"
	"</script>\n</body></html>\n";

const char *http_page_html(size_t *len)
{
	*len = sizeof page - 1;
	return page;
}

char *http_planets_json(const struct planet_set *ps, size_t *len)
{
	struct strbuf b = { 0 };
	strbuf_printf(&b, "[");
	for (size_t i = 0; i < ps->n; i++) {
		const struct planet *p = ps->planets[i];
		bool heights = false;
		for (size_t j = 0; j < p->nlayers; j++)
			heights |= p->layers[j].type == PIX_HEIGHT;
		strbuf_printf(&b, "%s{\"name\":", i ? "," : "");
		strbuf_json(&b, p->name);
		strbuf_printf(&b, ",\"description\":");
		strbuf_json(&b, p->description ? p->description : "");
		strbuf_printf(&b, ",\"a\":%.17g,\"f\":%.17g,\"max_level\":%d,\"tile_size\":%u,"
				  "\"heights\":%s,\"air\":%s,\"layers\":[",
			      p->a, p->f, p->max_level, p->tile_size, heights ? "true" : "false",
			      p->look.air_density > 0 ? "true" : "false");
		for (size_t j = 0; j < p->nlayers; j++) {
			strbuf_printf(&b, "%s{\"name\":", j ? "," : "");
			strbuf_json(&b, p->layers[j].name);
			strbuf_printf(&b, ",\"type\":\"%s\"}", pix_type_name(p->layers[j].type));
		}
		strbuf_printf(&b, "]}");
	}
	strbuf_printf(&b, "]\n");
	return strbuf_take(&b, len);
}

const char *http_mime_of(const char *path)
{
	static const char *const t[][2] = {
		{ ".js", "text/javascript" },	 { ".css", "text/css" },
		{ ".json", "application/json" }, { ".html", "text/html; charset=utf-8" },
		{ ".png", "image/png" },	 { ".jpg", "image/jpeg" },
		{ ".svg", "image/svg+xml" },	 { ".wasm", "application/wasm" },
		{ ".xml", "application/xml" },	 { ".glb", "model/gltf-binary" },
		{ ".ktx2", "image/ktx2" },	 { ".woff", "font/woff" },
		{ ".woff2", "font/woff2" },	 { ".gif", "image/gif" },
	};
	const char *dot = strrchr(path, '.');
	for (size_t i = 0; dot && i < sizeof t / sizeof t[0]; i++)
		if (!strcasecmp(dot, t[i][0]))
			return t[i][1];
	return "application/octet-stream";
}

int http_static_path_ok(const char *rel)
{
	size_t n = strlen(rel);
	if (n == 0 || n > 400)
		return 0;
	const char *seg = rel;
	for (const char *s = rel;; s++) {
		if (*s == '/' || !*s) {
			if (s == seg || *seg == '.')
				return 0; /* empty, ".", ".." or hidden */
			if (!*s)
				return 1;
			seg = s + 1;
			continue;
		}
		unsigned char c = (unsigned char)*s;
		if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
		      c == '_' || c == '-' || c == '.'))
			return 0;
	}
}
