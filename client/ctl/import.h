/* import — `clipmapctl import`: any raster GDAL reads (GeoTIFF, NetCDF, PNG, JPEG, VRT, ...)
 * with its georeferencing, rewritten through OpenImageIO as the layout the `file` node reads
 * fastest: tiled 256², box-filtered MIP pyramid, zip-compressed TIFF (BigTIFF when large),
 * north-up, west→east, with its bounds recorded in the ImageDescription:
 *     clipmap:bounds=W,S,E,N [clipmap:nodata=V]
 * (degrees; the `file` node takes them when the planet file gives no `bounds`; integer
 * nodata is left out of the MIP levels' averages (img_tiled_set_nodata); a re-import
 * keeps them). A projected source (UTM, national grids) or a rotated one is reprojected with
 * GDAL's warper onto geographic degrees (WGS 84 for the Earth's ellipsoids, else the source's
 * own geographic CRS), nodata outside the source.
 *
 * Library code: never logs (GDAL's own messages are silenced and returned through err).
 * Reentrant; GDAL's driver registration runs once (pthread_once). Streams: reads the source
 * in bands of whole tile rows and writes them as they come (img_tiled_*), so memory is
 * O(width × tile × bands) whatever the height; the coarser MIP levels are spooled to an
 * unlinked temporary file beside dst (at most 1/3 of the raw image) until level 0 is done.
 */
#ifndef CLIPMAP_IMPORT_H
#define CLIPMAP_IMPORT_H
#include <stdbool.h>

#include "common/img.h"

struct import_opts {
	bool has_bounds; /* bounds override the file's georeferencing (or stand in for none) */
	double bounds[4]; /* W, S, E, N in degrees */
	int band;	  /* 1-based band to import; 0: all bands (at most 4) */
	int tile;	  /* tile edge in pixels; 0: 256 */
	bool no_mip;	  /* skip the MIP pyramid */
	int band_rows;	  /* rows read per band, a multiple of tile; 0: automatic (about
			   * 32 MiB, at least one tile row) */
	const char *resample; /* how a projected source is resampled onto the geographic grid
			       * (GDAL's warper): near, bilinear, cubic, cubicspline, lanczos,
			       * average, mode; NULL: bilinear */
	double repair_rows;   /* > 0: repair row streaks departing more than this from both
			       * neighbouring rows (streaks.h); 0: off */
	int repair_len;	      /* the shortest streak, in pixels; 0: STREAKS_LEN */
};

struct import_result {
	int width, height, channels;
	enum img_type type;		/* what the output stores */
	double west, south, east, north; /* the bounds recorded */
	bool georeferenced;		/* bounds came from the file, not from opts or the default */
	bool reprojected;		/* a projected source warped to geographic degrees */
	bool flipped_rows;		/* the source ran south→north */
	int shifted_cols;		/* columns rotated to start at −180° (global rasters) */
	bool has_nodata;
	double nodata;			/* integer outputs: the recorded nodata value */
	int64_t repaired;		/* samples replaced by the streak repair */
	double read_s, write_s;		/* seconds spent reading (GDAL) and writing (OIIO,
					 * including the MIP levels) */
};

/* Converts src into dst (a .tif/.tiff path; written to dst.tmp, then renamed). o may be NULL
 * (defaults), res may be NULL. Float outputs carry the source's nodata as NaN; integer
 * outputs record it in the description. Returns 0, or -ENOENT (no such src), -EINVAL (not a
 * raster GDAL reads, no such band, too many bands, a projection GDAL cannot invert, bad
 * bounds, unsupported output name), -EFBIG (too large), -EIO (read or write failure); err
 * names the file and what is wrong. */
int import_raster(const char *src, const char *dst, const struct import_opts *o,
		  struct import_result *res, char err[256]);

/* Whether s names a resampling import_opts.resample accepts. */
bool import_resample_ok(const char *s);
/* Parses "W,S,E,N" (degrees) into b. Returns 0 or -EINVAL. */
int import_parse_bounds(const char *s, double b[4]);

#endif
