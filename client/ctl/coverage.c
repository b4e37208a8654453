/* coverage — see coverage.h. */
#include "coverage.h"

#include <errno.h>
#include <gdal/cpl_error.h>
#include <gdal/gdal.h>
#include <gdal/ogr_api.h>
#include <gdal/ogr_srs_api.h>
#include <math.h>
#include <pthread.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"

static pthread_once_t reg_once = PTHREAD_ONCE_INIT;

static void reg(void)
{
	GDALAllRegister();
}

struct acc {
	struct coverage *cv;
	size_t rcap, pcap;
	bool over; /* past the protocol's caps */
	uint32_t outer_first; /* the first point of the current polygon's outer ring */
};

static void push_pt(struct acc *a, double lon, double lat)
{
	struct coverage *cv = a->cv;
	if (cv->npoints == a->pcap) {
		a->pcap = a->pcap ? a->pcap * 2 : 256;
		cv->pts = xrealloc(cv->pts, a->pcap * sizeof *cv->pts);
	}
	cv->pts[cv->npoints++] = (struct proto_lonlat){ lon, lat };
}

static double wrap180(double d)
{
	d = fmod(d, 360.0);
	if (d > 180.0)
		d -= 360.0;
	else if (d <= -180.0)
		d += 360.0;
	return d;
}

/* Adds ring g (a linear ring in lon/lat); outer: it starts a polygon. */
static void add_ring(struct acc *a, OGRGeometryH g, bool outer)
{
	int n = OGR_G_GetPointCount(g);
	if (n >= 2 && OGR_G_GetX(g, 0) == OGR_G_GetX(g, n - 1) &&
	    OGR_G_GetY(g, 0) == OGR_G_GetY(g, n - 1))
		n--; /* the closing point: rings close by themselves */
	if (n < 3)
		return;
	struct coverage *cv = a->cv;
	uint32_t first = cv->npoints;
	double lon = wrap180(OGR_G_GetX(g, 0)), lat0 = OGR_G_GetY(g, 0), sumlat = 0;
	push_pt(a, lon, fmax(-90.0, fmin(90.0, lat0)));
	for (int i = 1; i < n; i++) {
		lon += wrap180(OGR_G_GetX(g, i) - OGR_G_GetX(g, i - 1));
		double lat = fmax(-90.0, fmin(90.0, OGR_G_GetY(g, i)));
		sumlat += lat;
		push_pt(a, lon, lat);
	}
	/* once round a pole: close the ring through it */
	double back = wrap180(OGR_G_GetX(g, 0) - OGR_G_GetX(g, n - 1));
	double end = lon + back, start = cv->pts[first].lon;
	if (fabs(end - start) > 180.0) {
		double pole = sumlat + lat0 >= 0 ? 90.0 : -90.0;
		push_pt(a, end, fmax(-90.0, fmin(90.0, lat0)));
		push_pt(a, end, pole);
		push_pt(a, start, pole);
	}
	/* the outer ring west of its first point in [-180, 180): holes next to it */
	double w = INFINITY, e = -INFINITY;
	for (uint32_t i = first; i < cv->npoints; i++)
		w = fmin(w, cv->pts[i].lon), e = fmax(e, cv->pts[i].lon);
	double shift = 0;
	if (outer) {
		shift = -360.0 * floor((w + 180.0) / 360.0);
		a->outer_first = first;
	} else {
		double ow = INFINITY;
		for (uint32_t i = a->outer_first; i < first; i++)
			ow = fmin(ow, cv->pts[i].lon);
		shift = 360.0 * round((ow - w) / 360.0);
	}
	for (uint32_t i = first; i < cv->npoints; i++)
		cv->pts[i].lon += shift;
	if (cv->nrings == a->rcap) {
		a->rcap = a->rcap ? a->rcap * 2 : 16;
		cv->rings = xrealloc(cv->rings, a->rcap * sizeof *cv->rings);
	}
	cv->rings[cv->nrings++] = cv->npoints - first;
	if (cv->nrings > PROTO_MAX_RINGS || cv->npoints > PROTO_MAX_POLY || e - w > 360.0 + 1e-9 ||
	    w + shift < -540.0 || e + shift > 540.0)
		a->over = true;
}

/* Adds the polygons of g (already in lon/lat). Returns how many. */
static int add_geom(struct acc *a, OGRGeometryH g)
{
	OGRwkbGeometryType t = wkbFlatten(OGR_G_GetGeometryType(g));
	if (t == wkbPolygon) {
		int nr = OGR_G_GetGeometryCount(g);
		for (int i = 0; i < nr; i++)
			add_ring(a, OGR_G_GetGeometryRef(g, i), i == 0);
		return nr > 0;
	}
	if (t == wkbMultiPolygon || t == wkbGeometryCollection) {
		int k = 0;
		for (int i = 0; i < OGR_G_GetGeometryCount(g); i++)
			k += add_geom(a, OGR_G_GetGeometryRef(g, i));
		return k;
	}
	return 0;
}

/* The transformation of layer l's CRS to lon/lat, NULL when it is lon/lat already (or has no
 * CRS). Returns 0 or -EINVAL. */
static int layer_transform(OGRLayerH l, OGRSpatialReferenceH *wgs, OGRCoordinateTransformationH *ct)
{
	*ct = NULL;
	OGRSpatialReferenceH src = OGR_L_GetSpatialRef(l);
	if (!src)
		return 0;
	if (!*wgs) {
		*wgs = OSRNewSpatialReference(NULL);
		OSRImportFromEPSG(*wgs, 4326);
		OSRSetAxisMappingStrategy(*wgs, OAMS_TRADITIONAL_GIS_ORDER);
	}
	OGRSpatialReferenceH s = OSRClone(src);
	OSRSetAxisMappingStrategy(s, OAMS_TRADITIONAL_GIS_ORDER);
	if (OSRIsGeographic(s) && OSRIsSame(s, *wgs)) {
		OSRDestroySpatialReference(s);
		return 0;
	}
	*ct = OCTNewCoordinateTransformation(s, *wgs);
	OSRDestroySpatialReference(s);
	return *ct ? 0 : -EINVAL;
}

static int read_layers(GDALDatasetH ds, const char *path, struct acc *a, char err[256])
{
	OGRSpatialReferenceH wgs = NULL;
	int rc = 0, polys = 0;
	for (int li = 0; li < GDALDatasetGetLayerCount(ds) && !rc; li++) {
		OGRLayerH l = GDALDatasetGetLayer(ds, li);
		OGRCoordinateTransformationH ct;
		if (layer_transform(l, &wgs, &ct)) {
			err_set(err, "%s: layer %s: its CRS cannot be transformed to EPSG:4326 (%s)",
				path, OGR_L_GetName(l), CPLGetLastErrorMsg());
			rc = -EINVAL;
			break;
		}
		OGR_L_ResetReading(l);
		OGRFeatureH f;
		while (!rc && (f = OGR_L_GetNextFeature(l))) {
			OGRGeometryH g0 = OGR_F_GetGeometryRef(f);
			OGRGeometryH g = g0 ? OGR_G_GetLinearGeometry(g0, 0, NULL) : NULL;
			OGRwkbGeometryType t = g ? wkbFlatten(OGR_G_GetGeometryType(g)) : wkbUnknown;
			if (g && (t == wkbPolygon || t == wkbMultiPolygon ||
				  t == wkbGeometryCollection)) {
				if (ct) {
					OGREnvelope env;
					OGR_G_GetEnvelope(g, &env);
					double ext = fmax(env.MaxX - env.MinX, env.MaxY - env.MinY);
					if (ext > 0)
						OGR_G_Segmentize(g, ext / 64);
					if (OGR_G_Transform(g, ct) != OGRERR_NONE) {
						err_set(err, "%s: feature %lld: cannot transform it to "
							"EPSG:4326", path, (long long)OGR_F_GetFID(f));
						rc = -EINVAL;
					}
				}
				int k = rc ? 0 : add_geom(a, g);
				polys += k;
				if (!k)
					a->cv->skipped++;
			} else {
				a->cv->skipped++;
			}
			if (g)
				OGR_G_DestroyGeometry(g);
			OGR_F_Destroy(f);
			if (!rc && a->over) {
				err_set(err, "%s: more than the %u rings and %u points a prefetch "
					"polygon carries, or a ring wider than 360° (simplify it, e.g. "
					"ogr2ogr -simplify)", path, PROTO_MAX_RINGS, PROTO_MAX_POLY);
				rc = -E2BIG;
			}
		}
		if (ct)
			OCTDestroyCoordinateTransformation(ct);
	}
	if (wgs)
		OSRDestroySpatialReference(wgs);
	if (!rc && polys == 0) {
		err_set(err, "%s: no polygon in it (%u features of other geometry types)", path,
			a->cv->skipped);
		rc = -EINVAL;
	}
	return rc;
}

int coverage_read(const char *path, struct coverage *cv, char err[256])
{
	*cv = (struct coverage){ 0 };
	pthread_once(&reg_once, reg);
	CPLPushErrorHandler(CPLQuietErrorHandler);
	CPLErrorReset();
	GDALDatasetH ds = GDALOpenEx(path, GDAL_OF_VECTOR | GDAL_OF_READONLY, NULL, NULL, NULL);
	int rc;
	if (!ds) {
		const char *m = CPLGetLastErrorMsg();
		err_set(err, "%s: cannot read it as a vector file (GeoJSON, GeoPackage, Shapefile…)%s%s",
			path, m && *m ? ": " : "", m ? m : "");
		rc = -ENOENT;
	} else {
		struct acc a = { .cv = cv };
		rc = read_layers(ds, path, &a, err);
		GDALClose(ds);
	}
	CPLPopErrorHandler();
	if (rc)
		coverage_free(cv);
	return rc;
}

void coverage_free(struct coverage *cv)
{
	free(cv->rings);
	free(cv->pts);
	cv->rings = NULL;
	cv->pts = NULL;
	cv->nrings = cv->npoints = 0;
}
