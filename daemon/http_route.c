/* http_route — see http_route.h. */
#include "http_route.h"

#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "common/grid.h"
#include "http_page.h"

#define MAX_PARTS 8

/* Splits path into at most MAX_PARTS non-empty segments (copied into buf). Returns the count,
 * or -1 when there are more, a segment is empty ("//") or the path is too long. */
static int split(const char *path, char buf[512], char *parts[MAX_PARTS])
{
	size_t n = strlen(path);
	if (n >= 512 || path[0] != '/')
		return -1;
	memcpy(buf, path + 1, n); /* includes the terminator */
	int k = 0;
	if (!buf[0])
		return 0;
	for (char *s = buf;;) {
		char *slash = strchr(s, '/');
		if (slash)
			*slash = '\0';
		if (!*s && slash) /* "//" or a trailing "/" before more */
			return -1;
		if (*s) {
			if (k == MAX_PARTS)
				return -1;
			parts[k++] = s;
		}
		if (!slash)
			return k;
		s = slash + 1;
	}
}

static bool name_ok(const char *s)
{
	size_t n = strlen(s);
	if (n == 0 || n >= HTTP_NAME_MAX || s[0] == '.')
		return false;
	for (; *s; s++)
		if (!((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9') ||
		      *s == '_' || *s == '-' || *s == '.'))
			return false;
	return true;
}

/* A decimal number without sign or leading zeros (except "0"), at most max. */
static bool number(const char *s, uint32_t max, uint32_t *out)
{
	if (!*s || (s[0] == '0' && s[1]) || strlen(s) > 10)
		return false;
	uint64_t v = 0;
	for (; *s; s++) {
		if (*s < '0' || *s > '9')
			return false;
		v = v * 10 + (uint64_t)(*s - '0');
	}
	if (v > max)
		return false;
	*out = (uint32_t)v;
	return true;
}

static void bad(struct http_route *r, const char *why)
{
	r->kind = HTTP_BAD;
	r->why = why;
}

/* Level z, then a, b: (row, col) for WMTS, (x, y) for TMS, each a decimal string. */
static void tile_at(struct http_route *r, const char *zs, const char *as, const char *bs, bool tms);

/* planet layer z a b.ext */
static void tile(struct http_route *r, char **p, bool tms)
{
	if (!name_ok(p[0]) || !name_ok(p[1]))
		return bad(r, "bad planet or layer name");
	strcpy(r->planet, p[0]);
	strcpy(r->layer, p[1]);
	char *dot = strrchr(p[4], '.');
	if (!dot)
		return bad(r, "the tile needs an extension: .png, .jpg, .webp or .tif");
	*dot = '\0';
	r->fmt = geoimg_format_parse(dot + 1);
	if (r->fmt == GEOIMG_NONE)
		return bad(r, "unknown format: use .png, .jpg, .webp or .tif");
	tile_at(r, p[2], p[3], p[4], tms);
}

/* planet z x y.terrain */
static void cesium_tile(struct http_route *r, char **p)
{
	if (!name_ok(p[0]))
		return bad(r, "bad planet name");
	strcpy(r->planet, p[0]);
	size_t n = strlen(p[3]);
	if (n < 9 || strcmp(p[3] + n - 8, ".terrain"))
		return bad(r, "Cesium tiles end in .terrain");
	p[3][n - 8] = '\0';
	tile_at(r, p[1], p[2], p[3], true);
	if (r->kind == HTTP_TILE)
		r->kind = HTTP_CESIUM_TILE;
}

static void tile_at(struct http_route *r, const char *zs, const char *as, const char *bs, bool tms)
{
	uint32_t z, a, b;
	if (!number(zs, GRID_MAX_LEVEL - 1, &z))
		return bad(r, "bad level");
	if (!number(as, UINT32_MAX, &a) || !number(bs, UINT32_MAX, &b))
		return bad(r, "bad tile column or row");
	uint64_t nx = (uint64_t)1 << (z + 1), ny = (uint64_t)1 << z;
	uint32_t x, y;
	if (tms) {
		x = a;
		if (b >= ny)
			return bad(r, "tile row outside the level");
		y = (uint32_t)(ny - 1 - b);
	} else {
		x = b;
		y = a;
	}
	if (x >= nx || y >= ny)
		return bad(r, "tile outside the level");
	r->z = z;
	r->x = x;
	r->y = y;
	r->kind = HTTP_TILE;
}

void http_route_parse(const char *url, const char *service, const char *request,
		      struct http_route *r)
{
	*r = (struct http_route){ .kind = HTTP_NOT_FOUND };
	static const char js[] = "/cesium-js/";
	if (url && !strncmp(url, js, sizeof js - 1)) {
		const char *rel = url + sizeof js - 1;
		if (strlen(rel) < sizeof r->rel && http_static_path_ok(rel)) {
			strcpy(r->rel, rel);
			r->kind = HTTP_STATIC;
		} else {
			bad(r, "bad file name");
		}
		return;
	}
	char buf[512], *p[MAX_PARTS];
	int n = split(url ? url : "", buf, p);
	if (n < 0)
		return;
	if (n == 0) {
		r->kind = HTTP_PAGE;
		return;
	}
	if (n == 1 && !strcmp(p[0], "healthz"))
		r->kind = HTTP_HEALTH;
	else if (n == 1 && !strcmp(p[0], "readyz"))
		r->kind = HTTP_READY;
	else if (n == 1 && !strcmp(p[0], "metrics"))
		r->kind = HTTP_METRICS;
	else if (n == 1 && !strcmp(p[0], "planets.json"))
		r->kind = HTTP_PLANETS_JSON;
	else if (n == 1 && !strcmp(p[0], "list"))
		r->kind = HTTP_INDEX;
	else if (n == 1 && !strcmp(p[0], "wmts")) {
		if (service && request && !strcasecmp(service, "WMTS") &&
		    !strcasecmp(request, "GetCapabilities"))
			r->kind = HTTP_WMTS_CAPS;
		else
			bad(r, "/wmts takes SERVICE=WMTS&REQUEST=GetCapabilities (tiles are RESTful: "
			       "/wmts/{planet}/{layer}/{z}/{row}/{col}.png)");
	} else if (n == 3 && !strcmp(p[0], "wmts") && !strcmp(p[1], "1.0.0") &&
		   !strcmp(p[2], "WMTSCapabilities.xml"))
		r->kind = HTTP_WMTS_CAPS;
	else if (n == 6 && !strcmp(p[0], "wmts"))
		tile(r, p + 1, false);
	else if (n == 7 && !strcmp(p[0], "tms") && !strcmp(p[1], "1.0.0"))
		tile(r, p + 2, true);
	else if (n == 3 && !strcmp(p[0], "cesium") && !strcmp(p[2], "layer.json")) {
		if (!name_ok(p[1]))
			return bad(r, "bad planet name");
		strcpy(r->planet, p[1]);
		r->kind = HTTP_CESIUM_LAYER;
	} else if (n == 5 && !strcmp(p[0], "cesium"))
		cesium_tile(r, p + 1);
}
