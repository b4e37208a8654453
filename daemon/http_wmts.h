/* http_wmts — the OGC WMTS 1.0.0 capabilities document of a planet set: one layer per planet
 * layer ("planet.layer"), RESTful tile URLs under base (e.g. "http://host:8080"), on the
 * WorldCRS84Quad tile matrix set (2^(z+1) × 2^z tiles of 256², -180 90 top left), limited per
 * layer to its planet's finest level. Planets whose tiles are not 256² get a set of their own
 * ("WorldCRS84Quad-T512"). */
#ifndef CLIPMAP_HTTP_WMTS_H
#define CLIPMAP_HTTP_WMTS_H
#include <stddef.h>

#include "engine/planets.h"

/* A malloc'ed, NUL-terminated XML document (*len bytes). */
char *wmts_capabilities(const struct planet_set *ps, const char *base, size_t *len);

#endif
