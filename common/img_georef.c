/* img_georef — the libtiff side of img.h: img_georef_read and, for img_check_readable,
 * img_tiff_check_extents (img_tiff.h). img_georef_read: a TIFF's own GeoTIFF georeferencing, read with libtiff
 * (the tags as libtiff's anonymous fields: ModelPixelScale 33550, ModelTiepoint 33922,
 * ModelTransformation 34264, GeoKeyDirectory 34735, GDAL_NODATA 42113). The bounds come from
 * a north-up transform whose model type is geographic (GTModelTypeGeoKey = 2), snapped as
 * clipmapctl import snaps them (float32 coordinate noise to the half-pixel lattice, 360°/180°
 * spans exactly); anything else (no transform, a projected or missing model type, rotation)
 * is reported, never turned into bounds. Not GDAL: GDAL's GeoTIFF driver changes libtiff's
 * process-wide tag extenders, after which OpenImageIO's TIFF writes lose tags.
 * Reentrant: libtiff's messages go to per-handle handlers that drop them.
 */
#include "img.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <tiffio.h>

#include "errbuf.h"
#include "img_tiff.h"

enum {
	TAG_PIXEL_SCALE = 33550,
	TAG_TIEPOINT = 33922,
	TAG_TRANSFORM = 34264,
	TAG_GEOKEYS = 34735,
	TAG_NODATA = 42113,
	KEY_MODEL_TYPE = 1024, /* 1 projected, 2 geographic, 3 geocentric */
	KEY_RASTER_TYPE = 1025, /* 1 PixelIsArea, 2 PixelIsPoint */
	KEY_GEOG_TYPE = 2048,	/* an EPSG code */
	KEY_PROJ_TYPE = 3072,	/* an EPSG code */
};

static int quiet(TIFF *tif, void *user, const char *module, const char *fmt, va_list ap)
{
	(void)tif, (void)user, (void)module, (void)fmt, (void)ap;
	return 1; /* handled: libtiff prints nothing */
}

/* An error handler that remembers the first error (user: a struct tiff_err). */
struct tiff_err {
	bool seen;
	char msg[160];
};

static int remember(TIFF *tif, void *user, const char *module, const char *fmt, va_list ap)
{
	(void)tif;
	(void)module;
	struct tiff_err *e = user;
	if (!e->seen) {
		e->seen = true;
		vsnprintf(e->msg, sizeof e->msg, fmt, ap);
	}
	return 1;
}

static double snap(double v, double q, double p)
{
	double r = round(v / q) * q;
	return fabs(r - v) < 0.1 * p ? r : v;
}

/* A double-array tag: its values and count (0 when absent). */
static uint32_t doubles(TIFF *tif, uint32_t tag, const double **v)
{
	const TIFFField *fld = TIFFFieldWithTag(tif, tag);
	*v = NULL;
	if (!fld || TIFFFieldDataType(fld) != TIFF_DOUBLE)
		return 0;
	uint32_t n = 0;
	if (TIFFFieldPassCount(fld) && TIFFFieldReadCount(fld) == TIFF_VARIABLE2) {
		if (!TIFFGetField(tif, tag, &n, v))
			return 0;
	} else if (TIFFFieldPassCount(fld)) {
		uint16_t n16 = 0;
		if (!TIFFGetField(tif, tag, &n16, v))
			return 0;
		n = n16;
	} else {
		return 0;
	}
	return *v ? n : 0;
}

/* A GeoKey's SHORT value stored in the directory itself; -1 when absent. */
static int geokey(const uint16_t *k, uint32_t n, int key)
{
	if (n < 4)
		return -1;
	uint32_t nk = k[3];
	for (uint32_t i = 0; i < nk && 4 + 4 * i + 3 < n; i++) {
		const uint16_t *e = k + 4 + 4 * i;
		if (e[0] == key)
			return e[1] == 0 && e[2] == 1 ? e[3] : -2; /* -2: stored elsewhere */
	}
	return -1;
}

int img_georef_read(const char *path, struct img_georef *out, char err[256])
{
	memset(out, 0, sizeof *out);
	struct stat st;
	if (stat(path, &st) != 0) {
		int e = errno;
		err_set(err, "%s: %s", path, strerror(e));
		return -e;
	}
	TIFFOpenOptions *opts = TIFFOpenOptionsAlloc();
	if (!opts)
		return 0;
	TIFFOpenOptionsSetErrorHandlerExtR(opts, quiet, NULL);
	TIFFOpenOptionsSetWarningHandlerExtR(opts, quiet, NULL);
	TIFF *tif = TIFFOpenExt(path, "rm", opts); /* m: no memory mapping */
	TIFFOpenOptionsFree(opts);
	if (!tif)
		return 0; /* not a TIFF: no GeoTIFF georeferencing */
	uint32_t w = 0, h = 0;
	TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &w);
	TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &h);

	const TIFFField *nfld = TIFFFieldWithTag(tif, TAG_NODATA);
	if (nfld && TIFFFieldDataType(nfld) == TIFF_ASCII) {
		const char *s = NULL;
		uint32_t n32 = 0;
		uint16_t n16 = 0;
		int ok = !TIFFFieldPassCount(nfld) ? TIFFGetField(tif, TAG_NODATA, &s)
			 : TIFFFieldReadCount(nfld) == TIFF_VARIABLE2 ? TIFFGetField(tif, TAG_NODATA, &n32, &s)
								      : TIFFGetField(tif, TAG_NODATA, &n16, &s);
		char *end;
		if (ok && s) {
			double v = strtod(s, &end);
			if (end != s) {
				out->has_nodata = true;
				out->nodata = v;
			}
		}
	}

	const double *scale, *tie, *mt;
	uint32_t ns = doubles(tif, TAG_PIXEL_SCALE, &scale);
	uint32_t nt = doubles(tif, TAG_TIEPOINT, &tie);
	uint32_t nm = doubles(tif, TAG_TRANSFORM, &mt);
	double gt[6] = { 0, 1, 0, 0, 0, 1 };
	bool have = false;
	if (ns >= 2 && nt >= 6) {
		gt[1] = scale[0], gt[5] = -scale[1], gt[2] = gt[4] = 0;
		gt[0] = tie[3] - tie[0] * gt[1];
		gt[3] = tie[4] - tie[1] * gt[5];
		have = true;
	} else if (nm >= 16) {
		gt[0] = mt[3], gt[1] = mt[0], gt[2] = mt[1];
		gt[3] = mt[7], gt[4] = mt[4], gt[5] = mt[5];
		have = true;
	}
	const TIFFField *kfld = TIFFFieldWithTag(tif, TAG_GEOKEYS);
	const uint16_t *keys = NULL;
	uint32_t nkeys = 0;
	if (kfld && TIFFFieldDataType(kfld) == TIFF_SHORT && TIFFFieldPassCount(kfld)) {
		if (TIFFFieldReadCount(kfld) == TIFF_VARIABLE2) {
			if (!TIFFGetField(tif, TAG_GEOKEYS, &nkeys, &keys))
				nkeys = 0;
		} else {
			uint16_t n16 = 0;
			if (TIFFGetField(tif, TAG_GEOKEYS, &n16, &keys))
				nkeys = n16;
		}
	}
	int model = geokey(keys, nkeys, KEY_MODEL_TYPE);
	int raster = geokey(keys, nkeys, KEY_RASTER_TYPE);
	int code = geokey(keys, nkeys, model == 1 ? KEY_PROJ_TYPE : KEY_GEOG_TYPE);
	if (code > 0 && code < 32767)
		snprintf(out->crs, sizeof out->crs, "EPSG:%d", code);
	else if (model == 1 || model == 2)
		snprintf(out->crs, sizeof out->crs, "%s", model == 1 ? "projected" : "geographic");
	if (have && w > 0 && h > 0) {
		if (raster == 2) { /* PixelIsPoint: the tiepoint is a pixel's centre */
			gt[0] -= 0.5 * gt[1] + 0.5 * gt[2];
			gt[3] -= 0.5 * gt[4] + 0.5 * gt[5];
		}
		if (gt[2] != 0 || gt[4] != 0) {
			out->rotated = true;
		} else if (model < 0) {
			out->no_crs = true;
		} else if (model != 2) {
			out->projected = true;
			if (!out->crs[0])
				snprintf(out->crs, sizeof out->crs, "model type %d", model);
		} else if (gt[1] > 0 && gt[5] < 0) {
			double dx = gt[1], dy = -gt[5];
			if (fabs(w * dx - 360) < 0.1 * dx)
				dx = 360.0 / w;
			if (fabs(h * dy - 180) < 0.1 * dy)
				dy = 180.0 / h;
			double x0 = snap(gt[0], dx / 2, dx), y1 = snap(gt[3], dy / 2, dy);
			out->west = x0, out->east = x0 + dx * w;
			out->north = y1, out->south = y1 - dy * h;
			out->georeferenced = true;
		} else {
			out->rotated = true; /* flipped rows or columns */
		}
	}
	TIFFClose(tif);
	return 0;
}

int img_tiff_check_extents(const char *path, char err[256])
{
	struct stat st;
	if (stat(path, &st) != 0)
		return 0; /* the caller's open reports it */
	TIFFOpenOptions *opts = TIFFOpenOptionsAlloc();
	if (!opts)
		return 0;
	struct tiff_err te = { 0 };
	TIFFOpenOptionsSetErrorHandlerExtR(opts, remember, &te);
	TIFFOpenOptionsSetWarningHandlerExtR(opts, quiet, NULL);
	TIFF *tif = TIFFOpenExt(path, "rm", opts);
	TIFFOpenOptionsFree(opts);
	if (!tif)
		return 0; /* not a TIFF (or unreadable: the caller's open said so) */
	int rc = 0, dir = 0;
	do {
		bool tiled = TIFFIsTiled(tif);
		uint32_t n = tiled ? TIFFNumberOfTiles(tif) : TIFFNumberOfStrips(tif);
		uint64_t *off = NULL, *cnt = NULL;
		if (!TIFFGetField(tif, tiled ? TIFFTAG_TILEOFFSETS : TIFFTAG_STRIPOFFSETS, &off) ||
		    !TIFFGetField(tif, tiled ? TIFFTAG_TILEBYTECOUNTS : TIFFTAG_STRIPBYTECOUNTS, &cnt) ||
		    !off || !cnt)
			n = 0; /* no extents to check (libtiff's own reads will say more) */
		for (uint32_t i = 0; i < n; i++) {
			if (cnt[i] && off[i] + cnt[i] > (uint64_t)st.st_size) {
				err_set(err, "%s: truncated: %s %u of %u in directory %d (MIP level or "
					"subimage) ends at byte %llu, the file has %llu", path,
					tiled ? "tile" : "strip", i, n, dir,
					(unsigned long long)(off[i] + cnt[i]),
					(unsigned long long)st.st_size);
				rc = -EIO;
				break;
			}
		}
		dir++;
	} while (rc == 0 && TIFFReadDirectory(tif));
	/* The chain of directories (one per MIP level) broken: a file cut where a level's
	 * directory was, which would otherwise look like a file with fewer levels. */
	if (rc == 0 && te.seen) {
		err_set(err, "%s: truncated or corrupt after directory %d (MIP level or subimage): "
			"%s", path, dir - 1, te.msg);
		rc = -EIO;
	}
	TIFFClose(tif);
	return rc;
}

int img_georef_write(const char *path, double west, double south, double east, double north,
		     char err[256])
{
	TIFFOpenOptions *opts = TIFFOpenOptionsAlloc();
	if (!opts)
		return -ENOMEM;
	struct tiff_err te = { 0 };
	TIFFOpenOptionsSetErrorHandlerExtR(opts, remember, &te);
	TIFFOpenOptionsSetWarningHandlerExtR(opts, quiet, NULL);
	TIFF *tif = TIFFOpenExt(path, "r+m", opts);
	TIFFOpenOptionsFree(opts);
	if (!tif) {
		err_set(err, "%s: %s", path, te.seen ? te.msg : "cannot open the TIFF to georeference it");
		return -EIO;
	}
	/* The three GeoTIFF tags, known to this handle only (a process-wide tag extender would
	 * change how OpenImageIO writes TIFFs, as GDAL's does). */
	static const TIFFFieldInfo fi[] = {
		{ TAG_PIXEL_SCALE, -1, -1, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1, "ModelPixelScaleTag" },
		{ TAG_TIEPOINT, -1, -1, TIFF_DOUBLE, FIELD_CUSTOM, 1, 1, "ModelTiepointTag" },
		{ TAG_GEOKEYS, -1, -1, TIFF_SHORT, FIELD_CUSTOM, 1, 1, "GeoKeyDirectoryTag" },
	};
	uint32_t w = 0, h = 0;
	TIFFGetField(tif, TIFFTAG_IMAGEWIDTH, &w);
	TIFFGetField(tif, TIFFTAG_IMAGELENGTH, &h);
	int rc = 0;
	if (!w || !h || TIFFMergeFieldInfo(tif, fi, 3) != 0) {
		err_set(err, "%s: cannot add GeoTIFF tags", path);
		rc = -EIO;
	} else {
		double scale[3] = { (east - west) / w, (north - south) / h, 0 };
		double tie[6] = { 0, 0, 0, west, north, 0 };
		/* version 1.1.0, 4 keys: geographic model, pixels are areas, WGS 84, degrees */
		uint16_t keys[20] = { 1, 1, 0, 4, KEY_MODEL_TYPE, 0, 1, 2, KEY_RASTER_TYPE, 0, 1, 1,
				      KEY_GEOG_TYPE, 0, 1, 4326, 2054, 0, 1, 9102 };
		if (!TIFFSetField(tif, TAG_PIXEL_SCALE, 3, scale) ||
		    !TIFFSetField(tif, TAG_TIEPOINT, 6, tie) ||
		    !TIFFSetField(tif, TAG_GEOKEYS, 20, keys) || !TIFFRewriteDirectory(tif)) {
			err_set(err, "%s: writing GeoTIFF tags: %s", path,
				te.seen ? te.msg : "libtiff refused");
			rc = -EIO;
		}
	}
	TIFFClose(tif);
	return rc;
}
