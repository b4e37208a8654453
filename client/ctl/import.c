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
#include <gdal/cpl_string.h>
#include <gdal/gdal.h>
#include <gdal/gdalwarper.h>
#include <gdal/ogr_srs_api.h>
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/xalloc.h"
#include "streaks.h"

#define IMPORT_MAX_PIXELS ((int64_t)1 << 34) /* 16 Gpx: more would not fit OIIO's int sizes */

static pthread_once_t reg_once = PTHREAD_ONCE_INIT;

static void reg(void)
{
	GDALAllRegister();
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
	if (!r->georeferenced) {
		/* A file import wrote (re-imported): its bounds are in the description. */
		const char *d = GDALGetMetadataItem(ds, "TIFFTAG_IMAGEDESCRIPTION", NULL);
		const char *b = d ? strstr(d, "clipmap:bounds=") : NULL;
		if (b && sscanf(b, "clipmap:bounds=%lf,%lf,%lf,%lf", &r->west, &r->south, &r->east,
				&r->north) == 4)
			r->georeferenced = true;
		return 0;
	}
	if (gt[2] != 0 || gt[4] != 0) {
		err_set(err, "%s: rotated or sheared georeferencing is not supported "
			 "(warp it north-up first)", src);
		return -EINVAL;
	}
	OGRSpatialReferenceH srs = GDALGetSpatialRef(ds);
	if (srs && OSRIsProjected(srs)) {
		err_set(err, "%s: projected coordinates (%s) are not supported: the grid is "
			 "geographic (reproject to EPSG:4326 first)", src,
			 OSRGetAttrValue(srs, "PROJCS", 0) ? OSRGetAttrValue(srs, "PROJCS", 0) : "?");
		return -EINVAL;
	}
	double dx = fabs(gt[1]), dy = fabs(gt[5]);
	if (!(dx > 0) || !(dy > 0)) {
		err_set(err, "%s: georeferencing has a zero pixel size", src);
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

/* One import: the source, what is read from it, and how it is turned. */
struct job {
	const char *src;
	GDALDatasetH ds;	/* the source, or a warped VRT over src_ds */
	GDALDatasetH src_ds;	/* the source when ds is a warped VRT; else NULL */
	int64_t w, h;
	int bands[4], nch;	/* the 1-based bands read, in output channel order */
	GDALDataType read_as;	/* what GDAL converts the samples to */
	enum img_type type;	/* what the output stores */
	bool has_nd;
	double nd;		/* the first band's nodata value */
	bool colflip;		/* the source runs east→west */
	int64_t c0;		/* columns rotated left by c0 (a global raster starts at −180°) */
	struct import_result r;
};

/* Opens j->src with GDAL (into j->ds) and takes its size. Returns 0 or -errno with err
 * filled. */
static int open_source(struct job *j, char *err)
{
	j->ds = GDALOpenEx(j->src, GDAL_OF_RASTER | GDAL_OF_READONLY, NULL, NULL, NULL);
	if (!j->ds) {
		err_set(err, "%s: not a raster GDAL can read: %s", j->src, gdal_msg());
		return -EINVAL;
	}
	j->w = GDALGetRasterXSize(j->ds);
	j->h = GDALGetRasterYSize(j->ds);
	if (GDALGetRasterCount(j->ds) == 0) {
		char **sub = GDALGetMetadata(j->ds, "SUBDATASETS");
		err_set(err, "%s: no raster bands%s%s", j->src,
			sub && sub[0] ? "; it has subdatasets, e.g. " : "",
			sub && sub[0] && strchr(sub[0], '=') ? strchr(sub[0], '=') + 1 : "");
		return -EINVAL;
	}
	if (j->w <= 0 || j->h <= 0 || j->w * j->h > IMPORT_MAX_PIXELS || j->w > INT32_MAX / 8 ||
	    j->h > INT32_MAX / 8) {
		err_set(err, "%s: %lldx%lld pixels is beyond what import handles", j->src,
			(long long)j->w, (long long)j->h);
		return -EFBIG;
	}
	return 0;
}

/* The geographic CRS a projected source is warped to: WGS 84 (EPSG:4326, longitude first)
 * for the Earth's ellipsoids (semi-major axis within 1 % of WGS 84's), else the source's own
 * geographic CRS (another body's degrees). NULL on failure. */
static OGRSpatialReferenceH target_srs(OGRSpatialReferenceH srs)
{
	OGRErr e = OGRERR_NONE;
	double a = OSRGetSemiMajor(srs, &e);
	OGRSpatialReferenceH t;
	if (e == OGRERR_NONE && fabs(a - 6378137.0) < 0.01 * 6378137.0) {
		t = OSRNewSpatialReference(NULL);
		if (t && OSRImportFromEPSG(t, 4326) != OGRERR_NONE) {
			OSRDestroySpatialReference(t);
			return NULL;
		}
	} else {
		t = OSRCloneGeogCS(srs);
	}
	if (t)
		OSRSetAxisMappingStrategy(t, OAMS_TRADITIONAL_GIS_ORDER);
	return t;
}

static const struct {
	const char *name;
	GDALResampleAlg alg;
} resamplers[] = {
	{ "near", GRA_NearestNeighbour }, { "bilinear", GRA_Bilinear },
	{ "cubic", GRA_Cubic },		  { "cubicspline", GRA_CubicSpline },
	{ "lanczos", GRA_Lanczos },	  { "average", GRA_Average },
	{ "mode", GRA_Mode },
};

bool import_resample_ok(const char *s)
{
	for (size_t i = 0; i < sizeof resamplers / sizeof resamplers[0]; i++)
		if (strcmp(s, resamplers[i].name) == 0)
			return true;
	return false;
}

static GDALResampleAlg resample_alg(const char *s)
{
	for (size_t i = 0; s && i < sizeof resamplers / sizeof resamplers[0]; i++)
		if (strcmp(s, resamplers[i].name) == 0)
			return resamplers[i].alg;
	return GRA_Bilinear;
}

/* The nodata value the warp gives pixels outside the source: the source's own, else NaN for
 * float data and the type's lowest (Int16, Byte) or highest (UInt16) value. */
static double warp_nodata(GDALRasterBandH b, bool *from_src)
{
	int has = 0;
	double v = GDALGetRasterNoDataValue(b, &has);
	*from_src = has != 0;
	if (has)
		return v;
	switch (GDALGetRasterDataType(b)) {
	case GDT_Byte: return 0;
	case GDT_UInt16: return 65535;
	case GDT_Int16: return -32768;
	default: return NAN;
	}
}

/* A projected (or rotated) source: j->ds becomes a warped VRT over it in geographic degrees
 * (GDAL's warper, o->resample), north-up, with nodata outside the source (8-bit grey or RGB
 * without nodata: an added alpha band, 0 outside). Returns 0 (also
 * when nothing is to be done) or -EINVAL with err filled. */
static int warp_source(struct job *j, const struct import_opts *o, char *err)
{
	OGRSpatialReferenceH srs = GDALGetSpatialRef(j->ds);
	double gt[6];
	bool have_gt = GDALGetGeoTransform(j->ds, gt) == CE_None;
	if (!srs || !have_gt)
		return 0;
	if (!OSRIsProjected(srs) && gt[2] == 0 && gt[4] == 0)
		return 0; /* geographic and north-up already */
	OGRSpatialReferenceH t = target_srs(srs);
	char *wkt = NULL;
	if (!t || OSRExportToWkt(t, &wkt) != OGRERR_NONE) {
		if (t)
			OSRDestroySpatialReference(t);
		err_set(err, "%s: no geographic coordinate system to reproject onto: %s", j->src,
			gdal_msg());
		return -EINVAL;
	}
	int nb = GDALGetRasterCount(j->ds);
	GDALWarpOptions *wo = GDALCreateWarpOptions();
	wo->eResampleAlg = resample_alg(o->resample);
	wo->nBandCount = nb;
	wo->panSrcBands = CPLMalloc(sizeof(int) * (size_t)nb);
	wo->panDstBands = CPLMalloc(sizeof(int) * (size_t)nb);
	wo->padfSrcNoDataReal = CPLMalloc(sizeof(double) * (size_t)nb);
	wo->padfDstNoDataReal = CPLMalloc(sizeof(double) * (size_t)nb);
	bool any_src_nd = false;
	for (int i = 0; i < nb; i++) {
		bool from_src;
		wo->panSrcBands[i] = wo->panDstBands[i] = i + 1;
		double nd = warp_nodata(GDALGetRasterBand(j->ds, i + 1), &from_src);
		wo->padfSrcNoDataReal[i] = wo->padfDstNoDataReal[i] = nd;
		any_src_nd |= from_src;
	}
	if (!any_src_nd) { /* the values chosen are for the destination only */
		CPLFree(wo->padfSrcNoDataReal);
		wo->padfSrcNoDataReal = NULL;
	}
	/* 8-bit imagery without nodata (grey, RGB): an alpha band instead, so the wedges
	 * outside the source are transparent rather than black. */
	bool alpha = !any_src_nd && (nb == 1 || nb == 3) &&
		     GDALGetRasterDataType(GDALGetRasterBand(j->ds, 1)) == GDT_Byte;
	if (alpha) {
		CPLFree(wo->padfDstNoDataReal);
		wo->padfDstNoDataReal = NULL;
		wo->nDstAlphaBand = nb + 1;
	}
	wo->papszWarpOptions = CSLSetNameValue(wo->papszWarpOptions, "INIT_DEST", "NO_DATA");
	CPLErrorReset();
	GDALDatasetH v = GDALAutoCreateWarpedVRTEx(j->ds, NULL, wkt, wo->eResampleAlg, 0.125, wo,
						   NULL);
	GDALDestroyWarpOptions(wo);
	CPLFree(wkt);
	OSRDestroySpatialReference(t);
	if (!v) {
		err_set(err, "%s: cannot reproject to geographic degrees: %s", j->src, gdal_msg());
		return -EINVAL;
	}
	for (int i = 0; i < nb && !alpha; i++) /* the VRT's bands carry the destination nodata */
		GDALSetRasterNoDataValue(GDALGetRasterBand(v, i + 1),
					 warp_nodata(GDALGetRasterBand(j->ds, i + 1), &(bool){ 0 }));
	j->src_ds = j->ds;
	j->ds = v;
	j->w = GDALGetRasterXSize(v);
	j->h = GDALGetRasterYSize(v);
	j->r.reprojected = true;
	if (j->w <= 0 || j->h <= 0 || j->w * j->h > IMPORT_MAX_PIXELS || j->w > INT32_MAX / 8 ||
	    j->h > INT32_MAX / 8) {
		err_set(err, "%s: reprojected, %lldx%lld pixels is beyond what import handles",
			j->src, (long long)j->w, (long long)j->h);
		return -EFBIG;
	}
	return 0;
}

/* The bands to read (--band, or all of at most 4), the sample type they share and the
 * nodata value. Returns 0 or -EINVAL with err filled. */
static int choose_bands(struct job *j, const struct import_opts *o, char *err)
{
	int nb = GDALGetRasterCount(j->ds);
	if (o->band) {
		if (o->band < 1 || o->band > nb) {
			err_set(err, "%s: has %d band%s, there is no band %d", j->src, nb,
				nb == 1 ? "" : "s", o->band);
			return -EINVAL;
		}
		j->bands[0] = o->band;
		j->nch = 1;
	} else {
		if (nb > 4) {
			err_set(err, "%s: has %d bands; pick one with --band N", j->src, nb);
			return -EINVAL;
		}
		for (int i = 0; i < nb; i++)
			j->bands[i] = i + 1;
		j->nch = nb;
	}
	GDALRasterBandH b0 = GDALGetRasterBand(j->ds, j->bands[0]);
	j->type = out_type(GDALGetRasterDataType(b0), &j->read_as);
	for (int i = 1; i < j->nch; i++) {
		GDALDataType t2;
		GDALRasterBandH b = GDALGetRasterBand(j->ds, j->bands[i]);
		if (out_type(GDALGetRasterDataType(b), &t2) != j->type) {
			err_set(err, "%s: bands have different sample types; import one with "
				"--band N", j->src);
			return -EINVAL;
		}
	}
	int has_nd = 0;
	j->nd = GDALGetRasterNoDataValue(b0, &has_nd);
	j->has_nd = has_nd;
	return 0;
}

/* Where the raster lies: its bounds (the georeferencing, --bounds or the whole globe) and
 * the column order. Every decision about them comes from the georeferencing alone, so it is
 * made (and refused) before a pixel is read. Returns 0 or -EINVAL with err filled. */
static int place(struct job *j, const struct import_opts *o, char *err)
{
	struct import_result *r = &j->r;
	int rc = georef(j->ds, j->src, j->w, j->h, r, err);
	if (rc)
		return rc;
	const char *d = GDALGetMetadataItem(j->ds, "TIFFTAG_IMAGEDESCRIPTION", NULL);
	const char *nds = d ? strstr(d, "clipmap:nodata=") : NULL;
	double ndv;
	if (!j->has_nd && nds && sscanf(nds, "clipmap:nodata=%lf", &ndv) == 1) {
		j->has_nd = true; /* re-importing an imported file: its recorded nodata */
		j->nd = ndv;
	}
	j->colflip = r->shifted_cols == -1;
	r->shifted_cols = 0;
	if (o->has_bounds) {
		r->west = o->bounds[0], r->south = o->bounds[1];
		r->east = o->bounds[2], r->north = o->bounds[3];
	} else if (!r->georeferenced) {
		r->west = -180, r->south = -90, r->east = 180, r->north = 90;
	}
	double span = r->east - r->west;
	if (r->georeferenced && !o->has_bounds && fabs(span - 360) < 1e-9 * 360) {
		double dx = span / (double)j->w;
		/* west' in [-180 - dx/2, -180 + dx/2): a raster already there stays put */
		j->c0 = (int64_t)ceil((-180 - r->west) / dx - 0.5 - 1e-9) % j->w;
		if (j->c0 < 0)
			j->c0 += j->w;
		if (j->c0) {
			r->shifted_cols = (int)j->c0;
			r->west += (double)j->c0 * dx;
			while (r->west > -180 + dx)
				r->west -= 360;
			r->east = r->west + 360;
		}
	} else if (r->west >= 180) {
		r->west -= 360;
		r->east -= 360;
	}
	if (!(r->west < r->east && r->east - r->west <= 360 + 1e-9 && r->west >= -360 &&
	      r->east <= 360 && r->south < r->north && r->south >= -91 && r->north <= 91)) {
		err_set(err, "%s: bounds W=%g S=%g E=%g N=%g are not geographic degrees "
			"(give --bounds W,S,E,N)", j->src, r->west, r->south, r->east, r->north);
		return -EINVAL;
	}
	if (j->has_nd && j->type != IMG_F32) {
		r->has_nodata = true;
		r->nodata = j->nd;
	}
	return 0;
}

/* The ImageDescription that records r's bounds (and nodata) for the `file` node. */
static void describe(const struct import_result *r, char desc[256])
{
	int dl = snprintf(desc, 256, "clipmap:bounds=%.17g,%.17g,%.17g,%.17g", r->west,
			  r->south, r->east, r->north);
	if (r->has_nodata)
		snprintf(desc + dl, 256 - (size_t)dl, " clipmap:nodata=%.17g", r->nodata);
}

/* Rows read at a time: whole tile rows, several when rows are short (up to ~32 MiB and 16
 * tile rows), or o->band_rows rounded up to a tile; at most the height. */
static int band_height(const struct job *j, const struct import_opts *o, size_t row, int tile)
{
	int64_t k = ((int64_t)32 << 20) / ((int64_t)row * tile);
	int band = tile * (int)(k < 1 ? 1 : k > 16 ? 16 : k);
	if (o->band_rows > 0)
		band = (o->band_rows + tile - 1) / tile * tile;
	return band > j->h ? (int)j->h : band;
}

/* Reads output rows y0 .. y0 + n - 1 into buf (pixel-interleaved, rows of `row` bytes,
 * pixels of px, samples of sz) and turns them north-up, west→east, starting at −180°, with
 * float nodata as NaN. Returns 0 or -EIO with err filled. */
static int read_rows(struct job *j, int64_t y0, int n, unsigned char *buf, size_t sz,
		     char *err)
{
	size_t px = sz * (size_t)j->nch, row = px * (size_t)j->w;
	/* a south→north source is read from the bottom up */
	int64_t sy = j->r.flipped_rows ? j->h - y0 - n : y0;
	GDALRasterIOExtraArg extra;
	INIT_RASTERIO_EXTRA_ARG(extra);
	double t0 = clock_now_s();
	CPLErrorReset();
	if (GDALDatasetRasterIOEx(j->ds, GF_Read, 0, (int)sy, (int)j->w, n, buf, (int)j->w, n,
				  j->read_as, j->nch, j->bands, (GSpacing)px, (GSpacing)row,
				  (GSpacing)sz, &extra) != CE_None) {
		err_set(err, "%s: read failed at rows %lld..%lld of %lld: %s", j->src,
			(long long)sy, (long long)sy + n - 1, (long long)j->h, gdal_msg());
		return -EIO;
	}
	GDALFlushCache(j->ds); /* drop the blocks just read: GDAL's cache would keep them */
	j->r.read_s += clock_now_s() - t0;
	if (j->has_nd && j->type == IMG_F32) {
		float *f = (float *)(void *)buf, ndf = (float)j->nd;
		size_t cnt = (size_t)j->w * (size_t)n * (size_t)j->nch;
		for (size_t i = 0; i < cnt; i++)
			if (f[i] == ndf)
				f[i] = NAN;
	}
	if (j->r.flipped_rows)
		flip_rows(buf, n, row);
	if (j->colflip)
		flip_cols(buf, j->w, n, px);
	if (j->c0)
		rotate_cols(buf, j->w, n, px, j->c0);
	return 0;
}

/* Stream: bands of whole tile rows read in output order and handed to the tiled writer,
 * which builds the MIP levels as the rows pass. With the streak repair each band is read
 * with a row of context on either side. Returns 0 or -errno with err filled (then neither
 * dst nor dst.tmp is left). */
static int write_tiled(struct job *j, const struct import_opts *o, const char *dst,
		       char *err)
{
	char desc[256];
	describe(&j->r, desc);
	size_t sz = img_type_bytes(j->type), row = sz * (size_t)j->nch * (size_t)j->w;
	int tile = o->tile ? o->tile : 256;
	int band = band_height(j, o, row, tile);
	int pad = o->repair_rows > 0;
	struct streaks sk;
	if (pad)
		streaks_init(&sk, o->repair_rows, o->repair_len ? o->repair_len : STREAKS_LEN,
			     j->w, j->nch, j->type, j->r.has_nodata, j->r.nodata);
	unsigned char *buf = xmalloc(row * (size_t)(band + 2 * pad));
	struct img_tiled_out *tw = NULL;
	int rc = img_tiled_open(&tw, dst, (int)j->w, (int)j->h, j->nch, j->type, tile,
				!o->no_mip, desc, err);
	if (rc == 0 && j->r.has_nodata) /* integer nodata: voids stay voids in the pyramid */
		img_tiled_set_nodata(tw, j->r.nodata);
	for (int64_t y0 = 0; rc == 0 && y0 < j->h; y0 += band) {
		int n = (int)(j->h - y0 < band ? j->h - y0 : band);
		int64_t ys = y0 > 0 ? y0 - pad : 0, ye = y0 + n + pad < j->h ? y0 + n + pad : j->h;
		if ((rc = read_rows(j, ys, (int)(ye - ys), buf, sz, err)))
			break;
		if (pad)
			j->r.repaired += streaks_repair(&sk, buf, (int)(ye - ys), (int)(y0 - ys), n);
		double t0 = clock_now_s();
		rc = img_tiled_rows(tw, buf + (size_t)(y0 - ys) * row, n, err);
		j->r.write_s += clock_now_s() - t0;
	}
	free(buf);
	if (pad)
		streaks_free(&sk);
	if (rc) {
		img_tiled_abort(tw);
		return rc;
	}
	double t1 = clock_now_s();
	rc = img_tiled_finish(tw, err);
	/* GeoTIFF tags too, so GIS tools place the file (the description is for re-imports) */
	if (rc == 0)
		rc = img_georef_write(dst, j->r.west, j->r.south, j->r.east, j->r.north, err);
	j->r.write_s += clock_now_s() - t1;
	return rc;
}

int import_raster(const char *src, const char *dst, const struct import_opts *o,
		  struct import_result *res, char err[256])
{
	static const struct import_opts defaults = { 0 };
	char ebuf[256];
	if (!err)
		err = ebuf;
	err[0] = 0;
	if (!o)
		o = &defaults;
	pthread_once(&reg_once, reg);
	if (o->resample && !import_resample_ok(o->resample)) {
		err_set(err, "resampling \"%s\": use near, bilinear, cubic, cubicspline, lanczos, "
			"average or mode", o->resample);
		return -EINVAL;
	}

	struct stat st;
	if (stat(src, &st) != 0 && strchr(src, ':') == NULL) {
		int e = errno;
		err_set(err, "%s: cannot open: %s", src, strerror(e));
		return -e;
	}
	CPLPushErrorHandler(CPLQuietErrorHandler);
	CPLErrorReset();
	struct job j = { .src = src };
	int rc = open_source(&j, err);
	if (!rc)
		rc = warp_source(&j, o, err);
	if (!rc)
		rc = choose_bands(&j, o, err);
	if (!rc)
		rc = place(&j, o, err);
	if (!rc)
		rc = write_tiled(&j, o, dst, err);
	if (!rc) {
		j.r.width = (int)j.w, j.r.height = (int)j.h, j.r.channels = j.nch;
		j.r.type = j.type;
		if (res)
			*res = j.r;
	}
	if (j.ds)
		GDALClose(j.ds);
	if (j.src_ds)
		GDALClose(j.src_ds);
	CPLPopErrorHandler();
	return rc;
}
