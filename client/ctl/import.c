/* import — GDAL in, OpenImageIO out (see import.h). The steps: open with GDAL, take the
 * geotransform (snapping float32 coordinate noise to the half-pixel lattice) and decide the
 * bounds and the column rotation (a global raster starts at −180°), then per band of tile
 * rows: read every wanted band pixel-interleaved, turn it north-up and west→east, rotate the
 * columns, and hand it to the streaming tiled writer (img_tiled_rows).
 * Thread-safety: reentrant; GDALAllRegister runs once.
 */
#include "import.h"

#include <errno.h>
#include <gdal/cpl_error.h>
#include <gdal/gdal.h>
#include <gdal/ogr_srs_api.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "common/xalloc.h"

#define IMPORT_MAX_PIXELS ((int64_t)1 << 34) /* 16 Gpx: more would not fit OIIO's int sizes */

static pthread_once_t reg_once = PTHREAD_ONCE_INIT;

static void reg(void)
{
	GDALAllRegister();
}

static double now_s(void)
{
	struct timespec t;
	clock_gettime(CLOCK_MONOTONIC, &t);
	return (double)t.tv_sec + t.tv_nsec * 1e-9;
}

int import_parse_bounds(const char *s, double b[4])
{
	char *end;
	const char *p = s;
	for (int i = 0; i < 4; i++) {
		errno = 0;
		b[i] = strtod(p, &end);
		if (end == p || errno || !isfinite(b[i]))
			return -EINVAL;
		p = end;
		while (*p == ' ')
			p++;
		if (i < 3) {
			if (*p != ',')
				return -EINVAL;
			p++;
		}
	}
	if (*p)
		return -EINVAL;
	if (!(b[0] < b[2] && b[2] - b[0] <= 360 && b[0] >= -360 && b[2] <= 360 && b[1] < b[3] &&
	      b[1] >= -90 && b[3] <= 90))
		return -EINVAL;
	return 0;
}

static enum img_type out_type(GDALDataType t, GDALDataType *read_as)
{
	switch (t) {
	case GDT_Byte:
		*read_as = GDT_Byte;
		return IMG_U8;
	case GDT_UInt16:
		*read_as = GDT_UInt16;
		return IMG_U16;
	case GDT_Int16:
		*read_as = GDT_Int16;
		return IMG_I16;
	default: /* Int8, (U)Int32/64, Float32/64: float keeps the values (and NaN for nodata) */
		*read_as = GDT_Float32;
		return IMG_F32;
	}
}

/* v snapped to the nearest multiple of q when within 10 % of a pixel p (NetCDF coordinate
 * variables are often float32: 0.0833341 for 1/12). */
static double snap(double v, double q, double p)
{
	double r = round(v / q) * q;
	return fabs(r - v) < 0.1 * p ? r : v;
}

static void rotate_cols(unsigned char *buf, int64_t w, int64_t h, size_t px, int64_t c0)
{
	size_t row = (size_t)w * px;
	unsigned char *tmp = xmalloc(row);
	for (int64_t y = 0; y < h; y++) {
		unsigned char *r = buf + (size_t)y * row;
		size_t a = (size_t)c0 * px;
		memcpy(tmp, r + a, row - a);
		memcpy(tmp + (row - a), r, a);
		memcpy(r, tmp, row);
	}
	free(tmp);
}

static void flip_rows(unsigned char *buf, int64_t h, size_t row)
{
	unsigned char *tmp = xmalloc(row);
	for (int64_t y = 0; y < h / 2; y++) {
		unsigned char *a = buf + (size_t)y * row, *b = buf + (size_t)(h - 1 - y) * row;
		memcpy(tmp, a, row);
		memcpy(a, b, row);
		memcpy(b, tmp, row);
	}
	free(tmp);
}

static void flip_cols(unsigned char *buf, int64_t w, int64_t h, size_t px)
{
	unsigned char tmp[32];
	for (int64_t y = 0; y < h; y++) {
		unsigned char *r = buf + (size_t)y * (size_t)w * px;
		for (int64_t x = 0; x < w / 2; x++) {
			memcpy(tmp, r + (size_t)x * px, px);
			memcpy(r + (size_t)x * px, r + (size_t)(w - 1 - x) * px, px);
			memcpy(r + (size_t)(w - 1 - x) * px, tmp, px);
		}
	}
}

static const char *gdal_msg(void)
{
	const char *m = CPLGetLastErrorMsg();
	return m && m[0] ? m : "format not recognised";
}

/* Georeferencing → bounds; returns 0 or -EINVAL with err filled. */
static int georef(GDALDatasetH ds, const char *src, int64_t w, int64_t h,
		  struct import_result *r, char *err)
{
	double gt[6];
	r->georeferenced = GDALGetGeoTransform(ds, gt) == CE_None &&
			   !(gt[0] == 0 && gt[1] == 1 && gt[2] == 0 && gt[3] == 0 && gt[4] == 0 &&
			     gt[5] == 1);
	if (!r->georeferenced)
		return 0;
	if (gt[2] != 0 || gt[4] != 0) {
		snprintf(err, 256, "%s: rotated or sheared georeferencing is not supported "
			 "(warp it north-up first)", src);
		return -EINVAL;
	}
	OGRSpatialReferenceH srs = GDALGetSpatialRef(ds);
	if (srs && OSRIsProjected(srs)) {
		snprintf(err, 256, "%s: projected coordinates (%s) are not supported: the grid is "
			 "geographic (reproject to EPSG:4326 first)", src,
			 OSRGetAttrValue(srs, "PROJCS", 0) ? OSRGetAttrValue(srs, "PROJCS", 0) : "?");
		return -EINVAL;
	}
	double dx = fabs(gt[1]), dy = fabs(gt[5]);
	if (!(dx > 0) || !(dy > 0)) {
		snprintf(err, 256, "%s: georeferencing has a zero pixel size", src);
		return -EINVAL;
	}
	if (fabs((double)w * dx - 360) < 0.1 * dx)
		dx = 360.0 / (double)w;
	if (fabs((double)h * dy - 180) < 0.1 * dy)
		dy = 180.0 / (double)h;
	double x0 = gt[1] > 0 ? gt[0] : gt[0] + gt[1] * (double)w; /* west edge */
	double y1 = gt[5] < 0 ? gt[3] : gt[3] + gt[5] * (double)h; /* north edge */
	x0 = snap(x0, dx / 2, dx);
	y1 = snap(y1, dy / 2, dy);
	r->west = x0;
	r->east = x0 + dx * (double)w;
	r->north = y1;
	r->south = y1 - dy * (double)h;
	r->flipped_rows = gt[5] > 0;
	if (gt[1] < 0)
		r->shifted_cols = -1; /* marker: columns run east→west */
	return 0;
}

int import_raster(const char *src, const char *dst, const struct import_opts *o,
		  struct import_result *res, char err[256])
{
	static const struct import_opts defaults = { 0 };
	struct import_result r;
	char ebuf[256];
	if (!err)
		err = ebuf;
	err[0] = 0;
	if (!o)
		o = &defaults;
	memset(&r, 0, sizeof r);
	pthread_once(&reg_once, reg);

	struct stat st;
	if (stat(src, &st) != 0 && strchr(src, ':') == NULL) {
		int e = errno;
		snprintf(err, 256, "%s: cannot open: %s", src, strerror(e));
		return -e;
	}
	CPLPushErrorHandler(CPLQuietErrorHandler);
	CPLErrorReset();
	unsigned char *buf = NULL;
	struct img_tiled_out *tw = NULL;
	int rc = 0;
	GDALDatasetH ds = GDALOpenEx(src, GDAL_OF_RASTER | GDAL_OF_READONLY, NULL, NULL, NULL);
	if (!ds) {
		snprintf(err, 256, "%s: not a raster GDAL can read: %s", src, gdal_msg());
		rc = -EINVAL;
		goto out;
	}
	int64_t w = GDALGetRasterXSize(ds), h = GDALGetRasterYSize(ds);
	int nb = GDALGetRasterCount(ds);
	if (nb == 0) {
		char **sub = GDALGetMetadata(ds, "SUBDATASETS");
		snprintf(err, 256, "%s: no raster bands%s%s", src,
			 sub && sub[0] ? "; it has subdatasets, e.g. " : "",
			 sub && sub[0] && strchr(sub[0], '=') ? strchr(sub[0], '=') + 1 : "");
		rc = -EINVAL;
		goto out;
	}
	if (w <= 0 || h <= 0 || w * h > IMPORT_MAX_PIXELS || w > INT32_MAX / 8 ||
	    h > INT32_MAX / 8) {
		snprintf(err, 256, "%s: %lldx%lld pixels is beyond what import handles", src,
			 (long long)w, (long long)h);
		rc = -EFBIG;
		goto out;
	}
	int bands[4], nch;
	if (o->band) {
		if (o->band < 1 || o->band > nb) {
			snprintf(err, 256, "%s: has %d band%s, there is no band %d", src, nb,
				 nb == 1 ? "" : "s", o->band);
			rc = -EINVAL;
			goto out;
		}
		bands[0] = o->band;
		nch = 1;
	} else {
		if (nb > 4) {
			snprintf(err, 256, "%s: has %d bands; pick one with --band N", src, nb);
			rc = -EINVAL;
			goto out;
		}
		for (int i = 0; i < nb; i++)
			bands[i] = i + 1;
		nch = nb;
	}
	GDALRasterBandH b0 = GDALGetRasterBand(ds, bands[0]);
	GDALDataType rt;
	enum img_type type = out_type(GDALGetRasterDataType(b0), &rt);
	for (int i = 1; i < nch; i++) {
		GDALDataType t2;
		if (out_type(GDALGetRasterDataType(GDALGetRasterBand(ds, bands[i])), &t2) != type) {
			snprintf(err, 256, "%s: bands have different sample types; import one with "
				 "--band N", src);
			rc = -EINVAL;
			goto out;
		}
	}
	int has_nd = 0;
	double nd = GDALGetRasterNoDataValue(b0, &has_nd);

	if ((rc = georef(ds, src, w, h, &r, err)))
		goto out;
	bool colflip = r.shifted_cols == -1;
	r.shifted_cols = 0;
	if (o->has_bounds) {
		r.west = o->bounds[0], r.south = o->bounds[1];
		r.east = o->bounds[2], r.north = o->bounds[3];
	} else if (!r.georeferenced) {
		r.west = -180, r.south = -90, r.east = 180, r.north = 90;
	}

	/* Every decision about bounds and column order comes from the georeferencing alone, so
	 * it is made (and refused) before a pixel is read. */
	double span = r.east - r.west;
	int64_t c0 = 0;
	if (r.georeferenced && !o->has_bounds && fabs(span - 360) < 1e-9 * 360) {
		double dx = span / (double)w;
		/* west' in [-180 - dx/2, -180 + dx/2): a raster already there stays put */
		c0 = (int64_t)ceil((-180 - r.west) / dx - 0.5 - 1e-9) % w;
		if (c0 < 0)
			c0 += w;
		if (c0) {
			r.shifted_cols = (int)c0;
			r.west += (double)c0 * dx;
			while (r.west > -180 + dx)
				r.west -= 360;
			r.east = r.west + 360;
		}
	} else if (r.west >= 180) {
		r.west -= 360;
		r.east -= 360;
	}
	if (!(r.west < r.east && r.east - r.west <= 360 + 1e-9 && r.west >= -360 &&
	      r.east <= 360 && r.south < r.north && r.south >= -91 && r.north <= 91)) {
		snprintf(err, 256, "%s: bounds W=%g S=%g E=%g N=%g are not geographic degrees "
			 "(give --bounds W,S,E,N)", src, r.west, r.south, r.east, r.north);
		rc = -EINVAL;
		goto out;
	}
	if (has_nd && type != IMG_F32) {
		r.has_nodata = true;
		r.nodata = nd;
	}

	char desc[256];
	int dl = snprintf(desc, sizeof desc, "clipmap:bounds=%.17g,%.17g,%.17g,%.17g", r.west,
			  r.south, r.east, r.north);
	if (r.has_nodata)
		snprintf(desc + dl, sizeof desc - (size_t)dl, " clipmap:nodata=%.17g", r.nodata);

	/* Stream: bands of whole tile rows (several when rows are short, up to ~32 MiB), read
	 * in output order (a south→north source from the bottom up), turned north-up and
	 * west→east in place, and handed to the tiled writer, which builds the MIP levels as
	 * the rows pass. */
	size_t sz = img_type_bytes(type), px = sz * (size_t)nch;
	size_t row = px * (size_t)w;
	int tile = o->tile ? o->tile : 256;
	int64_t k = ((int64_t)32 << 20) / ((int64_t)row * tile);
	int band = tile * (int)(k < 1 ? 1 : k > 16 ? 16 : k);
	if (o->band_rows > 0)
		band = (o->band_rows + tile - 1) / tile * tile;
	if (band > h)
		band = (int)h;
	buf = xmalloc(row * (size_t)band);
	if ((rc = img_tiled_open(&tw, dst, (int)w, (int)h, nch, type, tile, !o->no_mip, desc,
				 err)))
		goto out;
	GDALRasterIOExtraArg extra;
	INIT_RASTERIO_EXTRA_ARG(extra);
	for (int64_t y0 = 0; y0 < h; y0 += band) {
		int n = (int)(h - y0 < band ? h - y0 : band);
		int64_t sy = r.flipped_rows ? h - y0 - n : y0;
		double t0 = now_s();
		CPLErrorReset();
		if (GDALDatasetRasterIOEx(ds, GF_Read, 0, (int)sy, (int)w, n, buf, (int)w, n, rt,
					  nch, bands, (GSpacing)px, (GSpacing)row, (GSpacing)sz,
					  &extra) != CE_None) {
			snprintf(err, 256, "%s: read failed at rows %lld..%lld of %lld: %s", src,
				 (long long)sy, (long long)sy + n - 1, (long long)h, gdal_msg());
			rc = -EIO;
			goto out;
		}
		GDALFlushCache(ds); /* drop the blocks just read: GDAL's cache would keep them */
		r.read_s += now_s() - t0;
		if (has_nd && type == IMG_F32) {
			float *f = (float *)(void *)buf, ndf = (float)nd;
			size_t cnt = (size_t)w * (size_t)n * (size_t)nch;
			for (size_t i = 0; i < cnt; i++)
				if (f[i] == ndf)
					f[i] = NAN;
		}
		if (r.flipped_rows)
			flip_rows(buf, n, row);
		if (colflip)
			flip_cols(buf, w, n, px);
		if (c0)
			rotate_cols(buf, w, n, px, c0);
		t0 = now_s();
		rc = img_tiled_rows(tw, buf, n, err);
		r.write_s += now_s() - t0;
		if (rc)
			goto out;
	}
	double t1 = now_s();
	rc = img_tiled_finish(tw, err);
	tw = NULL;
	r.write_s += now_s() - t1;
	if (rc)
		goto out;
	r.width = (int)w, r.height = (int)h, r.channels = nch, r.type = type;
	if (res)
		*res = r;
out:
	img_tiled_abort(tw); /* a failed import leaves neither dst nor dst.tmp behind */
	free(buf);
	if (ds)
		GDALClose(ds);
	CPLPopErrorHandler();
	return rc;
}
