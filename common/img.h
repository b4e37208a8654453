/* img — the C interface to OpenImageIO (img.cpp is the only C++ that touches it): a region
 * reader over a private OIIO::ImageCache, whole-image read/write for tools and tests, and a
 * streaming writer of tiled, mipmapped TIFFs for images larger than memory (img_tiled_*).
 *
 * Threads: an img_cache may be used by any number of threads at once (OIIO's cache is
 * thread-safe and its error messages are per thread); img_write/img_read are reentrant.
 * No C++ exception ever crosses into C: every failure becomes -errno plus a message in err.
 * Paths are UTF-8 file names; err is an optional 256-byte buffer (NULL: no message).
 */
#ifndef CLIPMAP_IMG_H
#define CLIPMAP_IMG_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* A pixel channel type. Integer types keep their stored integer values (no normalisation)
 * when read as themselves; converting between types goes through OIIO, which normalises
 * integers to [0, 1] (unsigned) or [-1, 1] (signed) as floats. */
enum img_type {
	IMG_NONE = 0,
	IMG_U8,
	IMG_U16,
	IMG_I16,
	IMG_F32,
};

size_t img_type_bytes(enum img_type t); /* 1, 2, 2, 4; 0 for IMG_NONE */

struct img_info {
	int width, height; /* of MIP level 0 */
	int channels;
	/* The type that holds the file's values exactly: U8, U16, I16 as stored; F32 for half,
	 * float and double (double loses precision); IMG_NONE for other integer types (read
	 * those as F32: normalised). */
	enum img_type type;
	char format[16]; /* the stored type's name as OIIO spells it: "uint8", "half", ... */
	int mip_levels;	 /* levels readable through an img_cache (file's own, or automip) */
	bool tiled;
	int tile_width, tile_height; /* 0 when untiled */
};

/* An OIIO::ImageCache of its own (not the process-wide shared one) holding at most max_mb
 * MiB of pixels, with automip on (untiled, unmipped files get virtual MIP levels, each a 2×2
 * box of the one above). Files are keyed by path string: every user of one img_cache that
 * reads the same path shares its open handle and cached tiles. Returns a cache with one
 * reference owned by the caller, NULL only when OIIO cannot create one. */
struct img_cache *img_cache_create(size_t max_mb);
/* Another reference (atomic; any thread). Returns c; NULL is a no-op. */
struct img_cache *img_cache_ref(struct img_cache *c);
/* Drops a reference; the last one frees the cache and closes its files. NULL is a no-op. */
void img_cache_unref(struct img_cache *c);

/* Records that path is now `version` (n opaque bytes, e.g. its size, mtime and inode). When
 * a different version was recorded before, everything cached about path is invalidated (its
 * next read reopens the file) and true is returned; the first call for a path invalidates
 * only what OIIO itself sees as stale (a newer mtime). Thread-safe. Readers of the old
 * version that are still running get the new file's pixels from then on. */
bool img_cache_set_version(struct img_cache *c, const char *path, const void *version, size_t n);

struct img_cache_stats {
	uint64_t max_bytes;   /* the budget given to img_cache_create */
	uint64_t memory_used; /* bytes of tiles held now */
	int files;	      /* distinct file names ever referenced */
	int opens;	      /* times a file was opened (reopens after invalidation count) */
	int open_now;	      /* files open now */
};
/* OIIO's counters for c (zeros where OIIO does not answer). */
void img_cache_get_stats(struct img_cache *c, struct img_cache_stats *out);

/* Describes the image at path. Returns 0, or -ENOENT (no such file) / -EIO (unreadable or
 * not an image) with err = OIIO's message. */
int img_cache_info(struct img_cache *c, const char *path, struct img_info *out, char err[256]);
/* Size of MIP level `miplevel`. Returns 0 or -EINVAL (no such level) / -EIO. */
int img_cache_level_size(struct img_cache *c, const char *path, int miplevel, int *width,
			 int *height, char err[256]);

/* Reads pixels [x0, x1) × [y0, y1) (row y0 first, inside the level's data window), channels
 * [chbegin, chend), converted to `type`, into dst (borrowed), rows dst_stride bytes apart
 * (0: packed). Returns 0, -EINVAL (bad region or channels) or -EIO with err filled. After a
 * read of path fails (a tile OIIO cannot read, which it would serve as black from then on),
 * every read of path fails with that message until the next img_cache_set_version or
 * img_cache_invalidate of it (a load or reload retries the file from scratch). */
int img_cache_read(struct img_cache *c, const char *path, int miplevel, int x0, int x1, int y0,
		   int y1, int chbegin, int chend, enum img_type type, void *dst, size_t dst_stride,
		   char err[256]);
/* Forgets everything cached about path (e.g. after it changed on disk). */
void img_cache_invalidate(struct img_cache *c, const char *path);

/* Writes a width × height image of `channels` interleaved channels of `type` (rows north/top
 * first, packed), in the format chosen by the extension: .png (u8/u16), .tif/.tiff
 * (u8/u16/i16/f32), .exr (f32, stored as float). Writes path.tmp then renames it over path.
 * Returns 0, -EINVAL (unsupported extension/type combination) or -EIO with err filled. */
int img_write(const char *path, int width, int height, int channels, enum img_type type,
	      const void *pixels, char err[256]);
/* Like img_write but a tiled TIFF (tile × tile pixels, zip) with, when mip is true, a full
 * box-filtered MIP pyramid: the layout that reads fastest through an img_cache. */
int img_write_tiled(const char *path, int width, int height, int channels, enum img_type type,
		    const void *pixels, int tile, bool mip, char err[256]);

/* img_write_tiled plus `description` (NULL: none), stored as the TIFF ImageDescription, and
 * BigTIFF chosen automatically when the pyramid's uncompressed size nears 4 GiB. */
int img_write_tiled_desc(const char *path, int width, int height, int channels, enum img_type type,
			 const void *pixels, int tile, bool mip, const char *description,
			 char err[256]);
/* A streaming writer for the layout img_write_tiled_desc makes (tiled tile² zip TIFF, BigTIFF
 * when large, description, and with mip a MIP pyramid with make_texture's box filter, bit for
 * bit: levels computed in float from the level above, a 2×2 box where both sides are even,
 * OIIO's bilinear resample otherwise), fed rows top to bottom, so memory is O(width × tile)
 * instead of O(image). Level 0 goes straight to path.tmp band by band; the coarser levels are
 * built at the same time through a cascade of two-row windows and spooled (already converted
 * to `type`) to an anonymous temporary file in path's directory (1/3 of the image's raw size
 * at most), then appended once level 0 is complete. One writer is used by one thread. */
struct img_tiled_out;

/* Starts writing path (through path.tmp). Returns 0 with *out owned, or -EINVAL (bad size,
 * tile, type or extension: only .tif/.tiff) / -EIO with err filled. */
int img_tiled_open(struct img_tiled_out **out, const char *path, int width, int height,
		   int channels, enum img_type type, int tile, bool mip, const char *description,
		   char err[256]);
/* From now on the coarser MIP levels treat `nodata` (in the stored type's values) as missing:
 * a box or bilinear tap holding it takes the mean of its other samples, or nodata when all
 * are missing (a void stays a void instead of dragging its neighbours towards nodata). Call
 * before the first img_tiled_rows. Without it, every level is make_texture's, bit for bit. */
void img_tiled_set_nodata(struct img_tiled_out *o, double nodata);
/* Appends n rows (packed, `type`, channels interleaved) below those written so far. n must be
 * a multiple of the tile size unless these rows complete the image. Returns 0, -EINVAL (bad
 * n) or -EIO with err filled; after an error only img_tiled_abort is allowed. */
int img_tiled_rows(struct img_tiled_out *o, const void *rows, int n, char err[256]);
/* Writes the MIP levels, closes, fsyncs and renames path.tmp over path. Always frees o.
 * Returns 0, -EINVAL (not every row was given) or -EIO with err filled (path.tmp removed). */
int img_tiled_finish(struct img_tiled_out *o, char err[256]);
/* Abandons the file: closes it, removes path.tmp and frees o. NULL is a no-op. */
void img_tiled_abort(struct img_tiled_out *o);
/* Copies the image's ImageDescription (TIFF) into buf (n bytes, NUL-terminated, truncated).
 * Returns 0, -ENODATA (the file has none) or -ENOENT / -EIO with err filled. */
int img_cache_description(struct img_cache *c, const char *path, char *buf, size_t n,
			  char err[256]);

/* Checks that path is readable to its end, cheaply: for every MIP level (and subimage) the
 * file itself stores, its first and last tile (or scanline) are read and decoded, and for a
 * TIFF every tile's or strip's extent is checked against the file's size (directories only);
 * a file cut short (a truncated download or copy) fails there, wherever the cut. Virtual (automip) levels are not read:
 * they come from level 0. *levels (may be NULL) gets the MIP levels the file stores for its
 * first subimage (1: none beyond the image; coarser ones would be OIIO's automip). Returns 0,
 * or -ENOENT / -EIO with err naming the file, the level and the region that cannot be read. */
int img_check_readable(const char *path, int *levels, char err[256]);

/* Where a file says it lies: a TIFF's GeoTIFF tags, read with libtiff (img_georef.c);
 * nothing is guessed, so a plain TIFF without georeferencing gives georeferenced = false. */
struct img_georef {
	bool georeferenced; /* a north-up geotransform in geographic degrees: the bounds below */
	bool projected;	    /* a geotransform in a projected CRS (UTM...): not usable as degrees */
	bool rotated;	    /* a rotated or sheared geotransform */
	bool no_crs;	    /* a geotransform without a coordinate reference system */
	char crs[96];	    /* the CRS's name when there is one */
	double west, south, east, north; /* pixel-area edges, degrees (snapped as import does) */
	bool has_nodata;		 /* the first band's nodata value (GDAL_NODATA) */
	double nodata;
};
/* Fills out (zeroed first). Returns 0 (also for a file that is not a TIFF: nothing known), or
 * -ENOENT. Reentrant. Other formats (PNG, EXR...) have none: all false. */
int img_georef_read(const char *path, struct img_georef *out, char err[256]);
/* Adds GeoTIFF tags to the TIFF at path (its first image): EPSG:4326 (WGS 84 degrees; other
 * bodies read them as their own degrees), pixels as areas, a north-up transform from the
 * given edges, so gdalinfo and QGIS place the file. The pixel data and the other directories
 * (MIP levels) are left as they are. Returns 0 or -EIO/-ENOMEM with err filled. */
int img_georef_write(const char *path, double west, double south, double east, double north,
		     char err[256]);

/* Reads the whole first image of path, all channels, converted to `type` (IMG_NONE: the
 * file's own img_info.type). *pixels is returned owned (free() it); info may be NULL.
 * Returns 0, -ENOENT or -EIO with err filled. */
int img_read(const char *path, enum img_type type, void **pixels, struct img_info *info,
	     char err[256]);

#ifdef __cplusplus
}
#endif
#endif
