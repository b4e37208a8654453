/* http_page — the browser viewer: an HTML page running CesiumJS (served from the build tree or
 * the installed share directory, never fetched from the internet) over the daemon's own
 * Cesium terrain and WMTS imagery, with a planet and layer picker; /planets.json describes
 * what it can show; /cesium-js/... serves CesiumJS's files. */
#ifndef CLIPMAP_HTTP_PAGE_H
#define CLIPMAP_HTTP_PAGE_H
#include <stddef.h>

#include "engine/planets.h"

/* The page (static text). */
const char *http_page_html(size_t *len);
/* Every planet: name, description, ellipsoid (a, f), finest level, tile size, layers (name,
 * type). A malloc'ed JSON text. */
char *http_planets_json(const struct planet_set *ps, size_t *len);
/* The MIME type of a static file by its extension ("application/octet-stream" when unknown). */
const char *http_mime_of(const char *path);
/* Whether rel (a path under the CesiumJS directory, from the URL) is safe to open: no "..",
 * no empty, hidden or over-long segments, only [A-Za-z0-9_.-/]. */
int http_static_path_ok(const char *rel);

#endif
