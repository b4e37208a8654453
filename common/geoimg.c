/* geoimg — see geoimg.h. Each encoding builds a GDAL MEM dataset over a copy of the pixels and
 * CreateCopy's it into /vsimem/ (PNG, JPEG and WebP are CreateCopy-only drivers), then takes the
 * bytes out of the in-memory file. */
#include "common/geoimg.h"

#include <gdal/cpl_conv.h>
#include <gdal/cpl_error.h>
#include <gdal/cpl_string.h>
#include <gdal/cpl_vsi.h>
#include <errno.h>
#include <gdal/gdal.h>
#include <gdal/ogr_srs_api.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <unistd.h>

#include "common/errbuf.h"

static pthread_once_t once = PTHREAD_ONCE_INIT;
static atomic_uint serial;

static void init(void) { GDALAllRegister(); }

enum geoimg_format geoimg_format_parse(const char *ext)
{
	static const struct { const char *ext; enum geoimg_format f; } t[] = {
		{ "png", GEOIMG_PNG },	 { "jpg", GEOIMG_JPEG }, { "jpeg", GEOIMG_JPEG },
		{ "webp", GEOIMG_WEBP }, { "tif", GEOIMG_TIFF }, { "tiff", GEOIMG_TIFF },
	};
	for (size_t i = 0; ext && i < sizeof t / sizeof t[0]; i++)
		if (!strcasecmp(ext, t[i].ext))
			return t[i].f;
	return GEOIMG_NONE;
}

const char *geoimg_mime(enum geoimg_format f)
{
	switch (f) {
	case GEOIMG_PNG: return "image/png";
	case GEOIMG_JPEG: return "image/jpeg";
	case GEOIMG_WEBP: return "image/webp";
	case GEOIMG_TIFF: return "image/tiff";
	default: return "application/octet-stream";
	}
}

static const char *driver_name(enum geoimg_format f)
{
	switch (f) {
	case GEOIMG_PNG: return "PNG";
	case GEOIMG_JPEG: return "JPEG";
	case GEOIMG_WEBP: return "WEBP";
	case GEOIMG_TIFF: return "GTiff";
	default: return NULL;
	}
}

/* The bands to write and whether the format holds im at all. */
static int bands_for(const struct geoimg *im, enum geoimg_format f, int *bands, char err[256])
{
	int ch = im->channels;
	if (im->width <= 0 || im->height <= 0 || ch < 1 || ch > 4 || !im->pixels)
		return err_inval(err, "geoimg: bad image (%dx%d, %d channels)", im->width, im->height, ch);
	*bands = ch;
	switch (f) {
	case GEOIMG_PNG:
		if (im->type != IMG_U8 && im->type != IMG_U16)
			return err_inval(err, "geoimg: PNG holds 8- or 16-bit integers only");
		return 0;
	case GEOIMG_JPEG:
		if (im->type != IMG_U8 || ch == 2)
			return err_inval(err, "geoimg: JPEG holds 8-bit grey or RGB only");
		*bands = ch == 4 ? 3 : ch;
		return 0;
	case GEOIMG_WEBP:
		if (im->type != IMG_U8 || ch < 3)
			return err_inval(err, "geoimg: WebP holds 8-bit RGB or RGBA only");
		return 0;
	case GEOIMG_TIFF:
		if (im->type != IMG_U8 && im->type != IMG_U16 && im->type != IMG_F32)
			return err_inval(err, "geoimg: unsupported pixel type for GeoTIFF");
		return 0;
	default: return err_inval(err, "geoimg: unknown format");
	}
}

static GDALDataType gdal_type(enum img_type t)
{
	return t == IMG_U8 ? GDT_Byte : t == IMG_U16 ? GDT_UInt16 : GDT_Float32;
}

static void georeference(GDALDatasetH ds, const struct geoimg *im)
{
	const struct geo_rect *b = im->bounds;
	double gt[6] = { b->west, (b->east - b->west) / im->width, 0,
			 b->north, 0, -(b->north - b->south) / im->height };
	GDALSetGeoTransform(ds, gt);
	OGRSpatialReferenceH srs = OSRNewSpatialReference(NULL);
	OSRImportFromEPSG(srs, 4326);
	OSRSetAxisMappingStrategy(srs, OAMS_TRADITIONAL_GIS_ORDER);
	GDALSetSpatialRef(ds, srs);
	OSRDestroySpatialReference(srs);
}

/* Encodes into the GDAL file name `name` (a /vsimem/ path or a real file). */
static int encode_to(const struct geoimg *im, enum geoimg_format f, const char *name,
		     char err[256])
{
	int bands = 0;
	int rc = bands_for(im, f, &bands, err);
	if (rc < 0)
		return rc;
	pthread_once(&once, init);
	/* No .aux.xml side files: georeferencing goes into the GeoTIFF itself or nowhere. */
	CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", "NO");
	GDALDriverH mem = GDALGetDriverByName("MEM"), drv = GDALGetDriverByName(driver_name(f));
	if (!mem || !drv) {
		err_set(err, "geoimg: GDAL has no %s driver", driver_name(f));
		return -ENOSYS;
	}
	GDALDataType gt = gdal_type(im->type);
	int px = (int)img_type_bytes(im->type);
	GDALDatasetH ds = GDALCreate(mem, "", im->width, im->height, bands, gt, NULL);
	if (!ds) {
		err_set(err, "geoimg: %s", CPLGetLastErrorMsg());
		return -ENOMEM;
	}
	rc = 0;
	if (GDALDatasetRasterIO(ds, GF_Write, 0, 0, im->width, im->height, (void *)im->pixels,
				im->width, im->height, gt, bands, NULL, px * im->channels,
				(GSpacing)px * im->channels * im->width, px) != CE_None) {
		err_set(err, "geoimg: %s", CPLGetLastErrorMsg());
		rc = -EIO;
	}
	if (!rc && bands >= 3) {
		static const GDALColorInterp ci[] = { GCI_RedBand, GCI_GreenBand, GCI_BlueBand,
						      GCI_AlphaBand };
		for (int b = 0; b < bands; b++)
			GDALSetRasterColorInterpretation(GDALGetRasterBand(ds, b + 1), ci[b]);
	}
	if (!rc && im->has_nodata)
		for (int b = 1; b <= bands; b++)
			GDALSetRasterNoDataValue(GDALGetRasterBand(ds, b), im->nodata);
	if (!rc && im->bounds)
		georeference(ds, im);
	char **opt = NULL;
	switch (f) {
	case GEOIMG_PNG: opt = CSLSetNameValue(opt, "ZLEVEL", "6"); break;
	case GEOIMG_JPEG: opt = CSLSetNameValue(opt, "QUALITY", "90"); break;
	case GEOIMG_WEBP: opt = CSLSetNameValue(opt, "LOSSLESS", "TRUE"); break;
	case GEOIMG_TIFF:
		opt = CSLSetNameValue(opt, "COMPRESS", "DEFLATE");
		opt = CSLSetNameValue(opt, "PREDICTOR", im->type == IMG_F32 ? "3" : "2");
		if (bands >= 3 && im->type == IMG_U8)
			opt = CSLSetNameValue(opt, "PHOTOMETRIC", "RGB");
		if (bands == 4 && im->type == IMG_U8)
			opt = CSLSetNameValue(opt, "ALPHA", "YES"); /* straight (unassociated) alpha */
		break;
	default: break;
	}
	if (!rc) {
		CPLErrorReset();
		GDALDatasetH out = GDALCreateCopy(drv, name, ds, FALSE, opt, NULL, NULL);
		if (!out) {
			err_set(err, "geoimg: %s: %s", name, CPLGetLastErrorMsg());
			rc = -EIO;
		} else {
			GDALClose(out); /* void before GDAL 3.7: a failed flush shows as an error */
			if (CPLGetLastErrorType() >= CE_Failure) {
				err_set(err, "geoimg: %s: %s", name, CPLGetLastErrorMsg());
				rc = -EIO;
			}
		}
	}
	CSLDestroy(opt);
	GDALClose(ds);
	return rc;
}

int geoimg_encode(const struct geoimg *im, enum geoimg_format f, unsigned char **out, size_t *n,
		  char err[256])
{
	char name[96];
	snprintf(name, sizeof name, "/vsimem/clipmap-geoimg-%ld-%u", (long)getpid(),
		 atomic_fetch_add(&serial, 1));
	int rc = encode_to(im, f, name, err);
	if (rc < 0) {
		VSIUnlink(name);
		return rc;
	}
	vsi_l_offset len = 0;
	GByte *buf = VSIGetMemFileBuffer(name, &len, TRUE);
	if (!buf) {
		err_set(err, "geoimg: the encoded image vanished from %s", name);
		return -EIO;
	}
	*out = malloc(len ? (size_t)len : 1);
	if (!*out) {
		CPLFree(buf);
		return -ENOMEM;
	}
	memcpy(*out, buf, (size_t)len);
	*n = (size_t)len;
	CPLFree(buf);
	return 0;
}

int geoimg_write(const struct geoimg *im, enum geoimg_format f, const char *path, char err[256])
{
	char tmp[4200];
	if (snprintf(tmp, sizeof tmp, "%s.tmp-%ld", path, (long)getpid()) >= (int)sizeof tmp)
		return err_inval(err, "%s: path too long", path);
	int rc = encode_to(im, f, tmp, err);
	if (rc < 0) {
		unlink(tmp);
		return rc;
	}
	if (rename(tmp, path) < 0) {
		rc = -errno;
		err_set(err, "%s: %s", path, strerror(errno));
		unlink(tmp);
	}
	return rc;
}
