/* geoimg — images encoded through GDAL, to memory or to a file, optionally georeferenced in
 * EPSG:4326 (plate carrée, the tile grid's map space): PNG, JPEG, WebP and GeoTIFF. The HTTP
 * endpoint encodes tiles with it; exports write files readable by gdalinfo, QGIS and
 * gdal_translate in place.
 *
 * Threads: reentrant (every call has its own in-memory dataset); GDAL's drivers are
 * registered once. Errors: -errno plus a message in err (256 bytes, optional).
 */
#ifndef CLIPMAP_GEOIMG_H
#define CLIPMAP_GEOIMG_H
#include <stdbool.h>
#include <stddef.h>

#include "common/grid.h"
#include "common/img.h"

enum geoimg_format {
	GEOIMG_NONE = 0,
	GEOIMG_PNG,  /* U8 or U16, 1–4 channels; lossless */
	GEOIMG_JPEG, /* U8, 1 or 3 channels (alpha dropped); quality 90 */
	GEOIMG_WEBP, /* U8, 3 or 4 channels; lossless */
	GEOIMG_TIFF, /* any type; deflate-compressed GeoTIFF */
};

/* "png", "jpg"/"jpeg", "webp", "tif"/"tiff" → a format; GEOIMG_NONE when unknown. */
enum geoimg_format geoimg_format_parse(const char *ext);
const char *geoimg_mime(enum geoimg_format f);

struct geoimg {
	int width, height, channels;
	enum img_type type;	  /* IMG_U8, IMG_U16 or IMG_F32 */
	const void *pixels;	  /* row-major, interleaved, north row first */
	const struct geo_rect *bounds; /* NULL: not georeferenced */
	bool has_nodata;
	double nodata;
};

/* Encodes im as f into a malloc'ed buffer (*out, *n; free() it). Returns 0, -EINVAL (a type or
 * channel count the format cannot hold), -EIO (GDAL failed; err has its message). */
int geoimg_encode(const struct geoimg *im, enum geoimg_format f, unsigned char **out, size_t *n,
		  char err[256]);
/* The same, written to path (replaced atomically: a temporary file renamed). */
int geoimg_write(const struct geoimg *im, enum geoimg_format f, const char *path, char err[256]);

#endif
