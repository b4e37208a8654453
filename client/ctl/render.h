/* render — offline evaluation of a planet: one tile or a whole level assembled into a picture,
 * through the same cache and scheduler the daemon uses (`clipmapctl render`).
 * Not thread-safe per object; creates its own scheduler threads. Library code: never logs,
 * reports through err[256]; progress goes to an optional callback.
 */
#ifndef CLIPMAP_RENDER_H
#define CLIPMAP_RENDER_H
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "engine/planet.h"
#include "engine/store.h"

struct render_opts {
	int workers;	  /* 0: one per CPU */
	size_t cache_mb;  /* 0: 1024 */
	int shade;	  /* colour pictures: multiply by a hillshade from the "normal" layer */
	struct store *store; /* borrowed, optional: a disk tier under the cache (store.h), read
			      * and filled — possibly the one a running clipmapd uses */
	void (*progress)(void *ud, size_t done, size_t total);
	void *ud;
};

/* An assembled picture in memory (owned; free with render_image_free). */
struct render_image {
	int width, height, channels; /* channels: 1 (heights, f32) or 4 (RGBA8) or 3 (normals) */
	int is_float;
	void *pixels; /* rows north → south */
	double hmin, hmax; /* heights: the range found */
	struct geo_rect bounds; /* the area covered (east may pass 180 across the antimeridian) */
	int georef;		/* bounds are set: .tif files are written as EPSG:4326 GeoTIFFs */
};

/* A block of tiles at one level: cols × rows tiles from (x, y); x wraps around the
 * antimeridian, rows must stay inside the level. */
struct render_region {
	int lx, ly;
	uint32_t x, y, cols, rows;
};

/* The whole level (lx, ly). */
void render_region_level(int lx, int ly, struct render_region *r);
/* The longitude level of a block of tiles of level ly around latitude lat whose texels are
 * about as wide as tall there (within √2): ly + 1 at the equator, one less per halving of
 * cos(lat), so a block near a pole is not a few metres wide and stretched into streaks. */
int render_lx_at(int ly, double lat);
/* n × n tiles of level (lx, ly) centred on the tile holding (lat, lon), clamped at the poles. */
void render_region_around(int lx, int ly, double lat, double lon, uint32_t n,
			  struct render_region *r);

/* Renders the region of `layer` into one picture, tiles side by side. Returns 0 or -errno
 * with err filled. */
int render_layer(const struct planet *p, const char *layer, const struct render_region *rg,
		 const struct render_opts *o, struct render_image *out, char err[256]);
/* Writes the picture by the file's extension: heights as .tif/.tiff/.exr (float) or .png
 * (16-bit, min..max mapped to 0..65535 — *scale_note tells how); colour and normals as .png
 * or .tif. A .tif of a georeferenced picture is a GeoTIFF (EPSG:4326, its bounds), written
 * through GDAL, that gdalinfo and QGIS place on the map.
 * Returns 0 or -errno with err filled. */
int render_write(const struct render_image *im, const char *path, char note[256], char err[256]);
void render_image_free(struct render_image *im);

#endif
