/* vector_src — reading a vector source through GDAL/OGR's C API (the same libgdal common/
 * encodes GeoTIFFs with; OGR is part of it) into flat arrays, and the 1° grid index.
 * Called from node create only (planet load); nothing here runs per tile except the query.
 */
#include "vector_src.h"

#include <errno.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include <gdal/cpl_error.h>
#include <gdal/gdal.h>
#include <gdal/ogr_api.h>
#include <gdal/ogr_srs_api.h>

#include "common/xalloc.h"

static pthread_once_t once = PTHREAD_ONCE_INIT;
static void init(void) { GDALAllRegister(); }

/* Growing arrays while reading. */
struct build {
	struct vec_source *s;
	size_t cpts, cparts, cfeats;
	bool bad; /* a coordinate that is not a longitude and latitude */
	const char *path;
	char *err;
};

static int fail(char *err, int rc, const char *fmt, ...) __attribute__((format(printf, 3, 4)));
static int fail(char *err, int rc, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(err, 256, fmt, ap);
	va_end(ap);
	return rc;
}

static void push_pt(struct build *b, double lon, double lat)
{
	struct vec_source *s = b->s;
	if (s->npts == b->cpts) {
		b->cpts = b->cpts ? 2 * b->cpts : 4096;
		s->xy = xrealloc(s->xy, b->cpts * 2 * sizeof *s->xy);
	}
	s->xy[2 * s->npts] = lon;
	s->xy[2 * s->npts + 1] = lat;
	s->npts++;
}

static double ring_area2(const double *xy, uint32_t n) /* twice the signed area, closed ring */
{
	double a = 0;
	for (uint32_t i = 0; i + 1 < n; i++)
		a += xy[2 * i] * xy[2 * i + 3] - xy[2 * i + 2] * xy[2 * i + 1];
	return a;
}

static void reverse(double *xy, uint32_t n)
{
	for (uint32_t i = 0, j = n - 1; i < j; i++, j--)
		for (int c = 0; c < 2; c++) {
			double t = xy[2 * i + c];
			xy[2 * i + c] = xy[2 * j + c];
			xy[2 * j + c] = t;
		}
}

/* One part (a line, or a ring when ring ≥ 0: 0 outer, 1 hole) from an OGR simple curve. */
static void add_part(struct build *b, OGRGeometryH g, int ring)
{
	struct vec_source *s = b->s;
	int n = OGR_G_GetPointCount(g);
	if (n < 1)
		return;
	size_t first = s->npts;
	double prev = 0, lat_sum = 0;
	for (int i = 0; i < n; i++) {
		double lon = OGR_G_GetX(g, i), lat = OGR_G_GetY(g, i);
		if (!(fabs(lon) <= 720 && fabs(lat) <= 90.5)) { /* NaN too */
			b->bad = true;
			s->npts = first;
			return;
		}
		lat = lat < -90 ? -90 : lat > 90 ? 90 : lat;
		if (i > 0) /* unwrap: consecutive vertices less than 180° apart */
			lon += 360 * round((prev - lon) / 360);
		prev = lon;
		lat_sum += lat;
		push_pt(b, lon, lat);
	}
	if (ring >= 0) {
		double dl = s->xy[2 * (s->npts - 1)] - s->xy[2 * first];
		if (fabs(dl) > 180) { /* once around a pole: close it through that pole */
			double pole = lat_sum < 0 ? -90 : 90;
			push_pt(b, s->xy[2 * (s->npts - 1)], pole);
			push_pt(b, s->xy[2 * first], pole);
		}
		double lon0 = s->xy[2 * first], lat0 = s->xy[2 * first + 1];
		if (s->xy[2 * (s->npts - 1)] != lon0 || s->xy[2 * (s->npts - 1) + 1] != lat0)
			push_pt(b, lon0, lat0);
		uint32_t m = (uint32_t)(s->npts - first);
		if (m < 4) { /* fewer than three distinct vertices: no area */
			s->npts = first;
			return;
		}
		double a = ring_area2(s->xy + 2 * first, m);
		if ((ring == 0) != (a > 0))
			reverse(s->xy + 2 * first, m);
	}
	if (s->nparts == b->cparts) {
		b->cparts = b->cparts ? 2 * b->cparts : 1024;
		s->parts = xrealloc(s->parts, b->cparts * sizeof *s->parts);
	}
	s->parts[s->nparts++] = (struct vec_part){ .first = (uint32_t)first,
						   .n = (uint32_t)(s->npts - first) };
}

static struct vec_feature *new_feature(struct build *b, int kind, int style)
{
	struct vec_source *s = b->s;
	if (s->nfeats == b->cfeats) {
		b->cfeats = b->cfeats ? 2 * b->cfeats : 1024;
		s->feats = xrealloc(s->feats, b->cfeats * sizeof *s->feats);
	}
	struct vec_feature *f = &s->feats[s->nfeats++];
	*f = (struct vec_feature){ .kind = (uint8_t)kind, .style = (uint16_t)style,
				   .part0 = (uint32_t)s->nparts };
	return f;
}

static void end_feature(struct build *b)
{
	struct vec_source *s = b->s;
	struct vec_feature *f = &s->feats[s->nfeats - 1];
	f->nparts = (uint32_t)s->nparts - f->part0;
	if (!f->nparts) {
		s->nfeats--;
		return;
	}
	double *bb = f->bbox;
	bb[0] = bb[1] = INFINITY;
	bb[2] = bb[3] = -INFINITY;
	for (uint32_t p = 0; p < f->nparts; p++) {
		const struct vec_part *pa = &s->parts[f->part0 + p];
		for (uint32_t i = 0; i < pa->n; i++) {
			const double *q = s->xy + 2 * (pa->first + i);
			bb[0] = fmin(bb[0], q[0]), bb[2] = fmax(bb[2], q[0]);
			bb[1] = fmin(bb[1], q[1]), bb[3] = fmax(bb[3], q[1]);
		}
	}
	memcpy(f->gbox, bb, sizeof f->gbox);
}

/* Flattens g (linearised) into features of one kind each. */
static void add_geometry(struct build *b, OGRGeometryH g, int style)
{
	OGRwkbGeometryType t = wkbFlatten(OGR_G_GetGeometryType(g));
	int n = OGR_G_GetGeometryCount(g);
	switch (t) {
	case wkbPoint:
	case wkbLineString:
		new_feature(b, t == wkbPoint ? VEC_POINT : VEC_LINE, style);
		add_part(b, g, -1);
		end_feature(b);
		break;
	case wkbPolygon:
		new_feature(b, VEC_POLYGON, style);
		for (int i = 0; i < n; i++)
			add_part(b, OGR_G_GetGeometryRef(g, i), i == 0 ? 0 : 1);
		end_feature(b);
		break;
	case wkbMultiPoint:
	case wkbMultiLineString:
		new_feature(b, t == wkbMultiPoint ? VEC_POINT : VEC_LINE, style);
		for (int i = 0; i < n; i++)
			add_part(b, OGR_G_GetGeometryRef(g, i), -1);
		end_feature(b);
		break;
	case wkbMultiPolygon:
	case wkbGeometryCollection:
		for (int i = 0; i < n; i++)
			add_geometry(b, OGR_G_GetGeometryRef(g, i), style);
		break;
	default:
		break;
	}
}

static int read_layer(struct build *b, OGRLayerH L, const struct vec_load_opts *o)
{
	const char *lname = OGR_L_GetName(L);
	OGRSpatialReferenceH src = OGR_L_GetSpatialRef(L);
	if (!src)
		return fail(b->err, -EINVAL, "%s: layer %s has no coordinate system (write one into "
			    "the file, e.g. ogr2ogr -a_srs EPSG:4326)", b->path, lname);
	OGRSpatialReferenceH from = OSRClone(src), to = OSRCloneGeogCS(src);
	OSRSetAxisMappingStrategy(from, OAMS_TRADITIONAL_GIS_ORDER);
	OSRSetAxisMappingStrategy(to, OAMS_TRADITIONAL_GIS_ORDER);
	OGRCoordinateTransformationH ct = OCTNewCoordinateTransformation(from, to);
	OSRDestroySpatialReference(from);
	OSRDestroySpatialReference(to);
	if (!ct)
		return fail(b->err, -EINVAL, "%s: layer %s: no transformation to geographic "
			    "coordinates: %s", b->path, lname, CPLGetLastErrorMsg());
	int field = -1, rc = 0;
	OGRFeatureDefnH defn = OGR_L_GetLayerDefn(L);
	if (o->field && (field = OGR_FD_GetFieldIndex(defn, o->field)) < 0) {
		OCTDestroyCoordinateTransformation(ct);
		return fail(b->err, -EINVAL, "%s: layer %s has no field \"%s\"", b->path, lname,
			    o->field);
	}
	OGR_L_ResetReading(L);
	OGRFeatureH f;
	CPLErrorReset();
	while ((f = OGR_L_GetNextFeature(L))) {
		OGRGeometryH g0 = OGR_F_GetGeometryRef(f);
		int style = 0;
		if (field >= 0 && OGR_F_IsFieldSetAndNotNull(f, field)) {
			const char *v = OGR_F_GetFieldAsString(f, field);
			for (int i = 0; i < o->nvalues && !style; i++)
				if (strcmp(v, o->values[i]) == 0)
					style = i + 1;
		}
		if (g0) {
			OGRGeometryH g = OGR_G_GetLinearGeometry(g0, 0, NULL);
			if (g && OGR_G_Transform(g, ct) != OGRERR_NONE) {
				rc = fail(b->err, -EINVAL, "%s: layer %s, feature %lld: coordinates do "
					  "not transform to geographic: %s", b->path, lname,
					  (long long)OGR_F_GetFID(f), CPLGetLastErrorMsg());
				OGR_G_DestroyGeometry(g);
				OGR_F_Destroy(f);
				break;
			}
			if (g)
				add_geometry(b, g, style);
			OGR_G_DestroyGeometry(g);
			if (b->bad) {
				rc = fail(b->err, -EINVAL, "%s: layer %s, feature %lld: a coordinate "
					  "is not a longitude and latitude (NaN, or beyond ±720°, ±90°)",
					  b->path, lname, (long long)OGR_F_GetFID(f));
				OGR_F_Destroy(f);
				break;
			}
		}
		OGR_F_Destroy(f);
	}
	if (!rc && CPLGetLastErrorType() >= CE_Failure)
		rc = fail(b->err, -EIO, "%s: layer %s: reading failed: %s", b->path, lname,
			  CPLGetLastErrorMsg());
	OCTDestroyCoordinateTransformation(ct);
	return rc;
}

static void make_chunks(struct vec_source *s)
{
	size_t n = 0;
	for (size_t p = 0; p < s->nparts; p++) {
		s->parts[p].chunk0 = (uint32_t)n;
		uint32_t m = s->parts[p].n;
		n += m > 1 ? (m - 2) / VEC_CHUNK + 1 : 1;
	}
	s->chunks = xmalloc((n ? n : 1) * sizeof *s->chunks);
	s->nchunks = n;
	for (size_t p = 0; p < s->nparts; p++) {
		const struct vec_part *pa = &s->parts[p];
		uint32_t nc = pa->n > 1 ? (pa->n - 2) / VEC_CHUNK + 1 : 1;
		for (uint32_t c = 0; c < nc; c++) {
			double *bb = s->chunks[pa->chunk0 + c];
			bb[0] = bb[1] = INFINITY;
			bb[2] = bb[3] = -INFINITY;
			uint32_t i1 = (c + 1) * VEC_CHUNK;
			i1 = i1 < pa->n - 1 ? i1 : pa->n - 1;
			for (uint32_t i = c * VEC_CHUNK; i <= i1; i++) {
				const double *q = s->xy + 2 * (pa->first + i);
				bb[0] = fmin(bb[0], q[0]), bb[2] = fmax(bb[2], q[0]);
				bb[1] = fmin(bb[1], q[1]), bb[3] = fmax(bb[3], q[1]);
			}
		}
	}
}

int vec_source_load(const char *path, const struct vec_load_opts *o, struct vec_source **out,
		    char err[256])
{
	pthread_once(&once, init);
	*out = NULL;
	struct stat st;
	if (stat(path, &st) != 0)
		return fail(err, -EINVAL, "cannot open %s: %s", path, strerror(errno));
	CPLErrorReset();
	CPLPushErrorHandler(CPLQuietErrorHandler);
	GDALDatasetH ds = GDALOpenEx(path, GDAL_OF_VECTOR | GDAL_OF_READONLY, NULL, NULL, NULL);
	int rc = 0;
	if (!ds) {
		const char *m = CPLGetLastErrorMsg();
		rc = fail(err, -EINVAL, "cannot open %s as vector data: %s", path,
			  m && m[0] ? m : "not a format GDAL/OGR reads");
		CPLPopErrorHandler();
		return rc;
	}
	struct vec_source *s = xcalloc(1, sizeof *s);
	struct build b = { .s = s, .path = path, .err = err };
	if (o->layer) {
		OGRLayerH L = GDALDatasetGetLayerByName(ds, o->layer);
		rc = L ? read_layer(&b, L, o)
		       : fail(err, -EINVAL, "%s has no layer \"%s\"", path, o->layer);
	} else {
		int nl = GDALDatasetGetLayerCount(ds);
		if (nl == 0)
			rc = fail(err, -EINVAL, "%s: no vector layers", path);
		for (int i = 0; i < nl && !rc; i++)
			rc = read_layer(&b, GDALDatasetGetLayer(ds, i), o);
	}
	GDALClose(ds);
	CPLPopErrorHandler();
	if (rc) {
		vec_source_destroy(s);
		return rc;
	}
	make_chunks(s);
	*out = s;
	return 0;
}

static size_t cell_range(const double *bb, int *cx0, int *ncx, int *cy0, int *cy1)
{
	double w = floor(bb[0]), e = floor(bb[2]);
	*ncx = e - w >= 359 ? 360 : (int)(e - w) + 1;
	*cx0 = (int)(((long)w + 180) % 360 + 360) % 360;
	*cy0 = (int)floor(bb[1] + 90);
	*cy1 = (int)floor(bb[3] + 90);
	*cy0 = *cy0 < 0 ? 0 : *cy0 > 179 ? 179 : *cy0;
	*cy1 = *cy1 < 0 ? 0 : *cy1 > 179 ? 179 : *cy1;
	return (size_t)*ncx * (size_t)(*cy1 - *cy0 + 1);
}

void vec_source_index(struct vec_source *s)
{
	enum { NC = 360 * 180 };
	free(s->start);
	free(s->ids);
	free(s->big);
	s->start = xcalloc(NC + 1, sizeof *s->start);
	s->big = xmalloc((s->nfeats ? s->nfeats : 1) * sizeof *s->big);
	s->nbig = 0;
	for (int pass = 0; pass < 2; pass++) {
		for (size_t i = 0; i < s->nfeats; i++) {
			const struct vec_feature *f = &s->feats[i];
			int cx0, ncx, cy0, cy1;
			if (cell_range(f->gbox, &cx0, &ncx, &cy0, &cy1) > VEC_BIG_CELLS) {
				if (pass == 0)
					s->big[s->nbig++] = (uint32_t)i;
				continue;
			}
			for (int cy = cy0; cy <= cy1; cy++)
				for (int k = 0; k < ncx; k++) {
					size_t c = (size_t)cy * 360 + (size_t)((cx0 + k) % 360);
					if (pass == 0)
						s->start[c + 1]++;
					else
						s->ids[s->start[c]++] = (uint32_t)i;
				}
		}
		if (pass == 0) {
			for (size_t c = 0; c < NC; c++)
				s->start[c + 1] += s->start[c];
			s->ids = xmalloc((s->start[NC] ? s->start[NC] : 1) * sizeof *s->ids);
		} else { /* start[c] advanced to start[c + 1]: shift back */
			memmove(s->start + 1, s->start, NC * sizeof *s->start);
			s->start[0] = 0;
		}
	}
}

size_t vec_source_query(const struct vec_source *s, double w, double so, double e, double n,
			uint32_t *ids, uint8_t *seen)
{
	size_t k = 0;
	for (size_t i = 0; i < s->nbig; i++)
		if (!seen[s->big[i]]) {
			seen[s->big[i]] = 1;
			ids[k++] = s->big[i];
		}
	const double bb[4] = { w, so, e - 1e-9, n };
	int cx0, ncx, cy0, cy1;
	cell_range(bb, &cx0, &ncx, &cy0, &cy1);
	for (int cy = cy0; cy <= cy1; cy++)
		for (int c = 0; c < ncx; c++) {
			size_t cell = (size_t)cy * 360 + (size_t)((cx0 + c) % 360);
			for (uint32_t j = s->start[cell]; j < s->start[cell + 1]; j++) {
				uint32_t id = s->ids[j];
				if (!seen[id]) {
					seen[id] = 1;
					ids[k++] = id;
				}
			}
		}
	for (size_t i = 0; i < k; i++)
		seen[ids[i]] = 0;
	return k;
}

void vec_source_destroy(struct vec_source *s)
{
	if (!s)
		return;
	free(s->xy);
	free(s->parts);
	free(s->chunks);
	free(s->feats);
	free(s->start);
	free(s->ids);
	free(s->big);
	free(s);
}
