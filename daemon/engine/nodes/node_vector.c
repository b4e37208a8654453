/* node_vector — the `vector` node: a GDAL/OGR vector source (vector_src.h, read once at load)
 * rasterized per tile in map space with exact area coverage (vector_raster.h).
 *
 * Parameters ([node NAME] with type = vector):
 *   path         the source (GeoJSON, GeoPackage, Shapefile, FlatGeobuf, KML, …; relative paths
 *                resolve against the planet file's directory). Read at load: a missing or
 *                unreadable file, a layer without a coordinate system, or a coordinate that
 *                does not transform is refused naming the file.
 *   layer        the layer to draw (default: every layer)
 *   output       color (RGBA, transparent where nothing is drawn: put it on a colour layer
 *                with `blend` mode over) | mask (heights in [0, 1]: the coverage of every
 *                feature whose colour is not fully transparent; use it as a blend's mask)
 *   color        the default style's colour (#rrggbb[aa], r,g,b[,a]; default white)
 *   width        the default width of lines, outlines and point discs: NUMBER with a unit,
 *                px (texels of the tile's level) or m / km (on the ground); default 1px
 *   polygons     fill | outline | both (default fill)
 *   fill_opacity the fill's alpha, times the style colour's (0..1, default 1)
 *   style_field  an attribute; `styles` then lists "VALUE #colour WIDTH" items, comma
 *                separated: a feature whose field equals VALUE takes that colour and width,
 *                any other the default. Drawn in order: default style first, then `styles`
 *                from first to last (later ones on top).
 *   feather      (output = mask) a soft edge: a distance on the ground (300m, 0.5km) over
 *                which the mask falls from 1 at the shapes' edge to 0, as 1 − smoothstep of
 *                the distance; default none (0: a hard edge, the exact coverage alone).
 *                Inside the shapes the mask stays exactly 1, beyond the feather exactly 0, so
 *                a blend with mode mask flattens exactly the polygon and leaves the terrain
 *                farther than the feather bit for bit as it was.
 * Geometry: edges join their vertices with straight lines in (lon, lat), as the source's
 * segments are drawn by GIS tools in plate carrée (a border that follows a parallel stays on
 * it; a great circle would cut across it), and the tile grid is plate carrée itself. Lines are
 * stroked with round joins and caps; a width in metres is converted per vertex with the
 * ellipsoid's radii: M(φ) north-south, N(φ)·cos φ east-west (a texel is narrower in metres
 * east-west by cos φ, so a line keeps its ground width at every latitude and widens in
 * longitude towards the poles). Features crossing the antimeridian (unwrapped longitudes) and
 * polygons around a pole are drawn whole on every tile they touch; coverage is exact area in
 * map space, so neighbouring tiles (and a level and its parent, averaged) agree.
 * Feather: a texel's distance to the shapes is measured from its centre in metres, in the
 * plane tangent there (east by N(φ)·cos φ, north by M(φ) of the centre's latitude), to every
 * edge (a polygon's ring, a line's centreline less its half-width, a point less its radius)
 * near it: the value depends only on where the texel is, so tiles agree at their borders; a
 * shape's index box grows by the feather, so a tile sees the shapes within it (also across the
 * antimeridian). A texel partly covered (coverage c) takes c + (1 − c)·w, w the feather's
 * weight at its centre: continuous from the inside (1) to the feather's end (0). Cost: per
 * edge near the tile, the texels within the feather of it.
 * Threads: immutable after create; generate() on any worker (scratch from gen_ctx).
 */
#include "engine/node_types.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"
#include "engine/planet.h"

#include "vector_raster.h"
#include "vector_src.h"

#define MAX_STYLES 64

enum { OUT_COLOR, OUT_MASK };
enum { POLY_FILL, POLY_OUTLINE, POLY_BOTH };

static const char *const out_names[] = { "color", "mask", NULL };
static const char *const poly_names[] = { "fill", "outline", "both", NULL };

struct vstyle {
	float rgba[4]; /* 0..1, straight alpha */
	double width;  /* full width: texels when px, else metres */
	bool px;
};

struct vector {
	struct vec_source *src;
	int output, polygons;
	float fill_opacity;
	int nstyles; /* styles[0] the default, styles[1..] from `styles` */
	struct vstyle styles[MAX_STYLES + 1];
	double a, e2;		   /* the planet's ellipsoid */
	double max_px;		   /* widest px half-width: the query grows by it */
	double feather;		   /* metres; 0: none */
};

static void vector_destroy(struct node *n)
{
	struct vector *v = n->impl;
	if (!v)
		return;
	vec_source_destroy(v->src);
	free(v);
	n->impl = NULL;
}

/* "2px", "0.5px", "100m", "1.5km". */
static int parse_width(const char *s, double *w, bool *px)
{
	char *end;
	double x = strtod(s, &end);
	if (end == s || !(x > 0) || x > 1e7)
		return -EINVAL;
	if (!strcmp(end, "px"))
		*px = true;
	else if (!strcmp(end, "m"))
		*px = false;
	else if (!strcmp(end, "km"))
		*px = false, x *= 1000;
	else
		return -EINVAL;
	if (*px && x > 1024)
		return -EINVAL;
	*w = x;
	return 0;
}

/* "#rrggbb" or "#rrggbbaa". */
static int parse_hex(const char *s, float rgba[4])
{
	size_t n = strlen(s);
	if (s[0] != '#' || (n != 7 && n != 9) || strspn(s + 1, "0123456789abcdefABCDEF") != n - 1)
		return -EINVAL;
	unsigned long v = strtoul(s + 1, NULL, 16);
	if (n == 7)
		v = v << 8 | 0xff;
	for (int c = 0; c < 4; c++)
		rgba[c] = (float)((v >> (24 - 8 * c)) & 0xff) / 255.0f;
	return 0;
}

/* `styles`: "VALUE #colour WIDTH, …" into v->styles[1..] and the values (pointers into buf). */
static int parse_styles(struct node_parse *p, struct vector *v, const char *text, char *buf,
			const char **values)
{
	if (strlen(text) >= 4096)
		return np_error(p, "styles", "longer than 4095 characters");
	snprintf(buf, 4096, "%s", text);
	char *save = NULL;
	for (char *item = strtok_r(buf, ",", &save); item; item = strtok_r(NULL, ",", &save)) {
		char *f[4], *s2 = NULL;
		int nf = 0;
		for (char *w = strtok_r(item, " \t", &s2); w && nf < 4; w = strtok_r(NULL, " \t", &s2))
			f[nf++] = w;
		if (v->nstyles > MAX_STYLES)
			return np_error(p, "styles", "more than %d styles", MAX_STYLES);
		struct vstyle *st = &v->styles[v->nstyles];
		if (nf != 3 || parse_hex(f[1], st->rgba) || parse_width(f[2], &st->width, &st->px))
			return np_error(p, "styles", "item %d: expected \"VALUE #rrggbb[aa] WIDTH\" "
					"(WIDTH like 2px or 100m)", v->nstyles);
		values[v->nstyles - 1] = f[0];
		v->nstyles++;
	}
	return 0;
}

/* Metres per degree north (M) and east (N·cos φ) at latitude lat. */
static void metres_per_degree(const struct vector *v, double lat, double *my, double *mx)
{
	double s = sin(lat * (M_PI / 180)), c = cos(lat * (M_PI / 180));
	double w = 1 - v->e2 * s * s;
	*my = v->a * (1 - v->e2) / (w * sqrt(w)) * (M_PI / 180);
	*mx = v->a / sqrt(w) * fabs(c) * (M_PI / 180);
}

static int vector_create(struct node *n, struct node_parse *p)
{
	struct vector *v = xcalloc(1, sizeof *v);
	n->impl = v;
	const struct planet *pl = n->planet;
	if (!pl || !(pl->a > 0))
		return np_error(p, NULL, "node \"%s\": the planet has no body (ellipsoid)", n->name);
	v->a = pl->a;
	v->e2 = pl->f * (2 - pl->f);
	const char *path, *layer, *field, *styles, *width, *feather;
	static const uint8_t white[4] = { 255, 255, 255, 255 };
	uint8_t col[4];
	double fo;
	int rc;
	struct ini_entry *pe = ini_find(p->sec, "path");
	if (pe)
		pe->used = true;
	if (!pe || !pe->value[0])
		return np_error(p, "path", "missing: the vector file to read");
	if ((rc = np_string(p, "layer", NULL, &layer)) || (rc = np_string(p, "style_field", NULL, &field)) ||
	    (rc = np_string(p, "styles", NULL, &styles)) || (rc = np_string(p, "width", "1px", &width)) ||
	    (rc = np_enum(p, "output", out_names, OUT_COLOR, &v->output)) ||
	    (rc = np_enum(p, "polygons", poly_names, POLY_FILL, &v->polygons)) ||
	    (rc = np_color(p, "color", white, col)) ||
	    (rc = np_double(p, "fill_opacity", 1, 0, 1, &fo)) ||
	    (rc = np_string(p, "feather", NULL, &feather)))
		return rc;
	if (feather) {
		bool fpx = false;
		if (parse_width(feather, &v->feather, &fpx) || fpx)
			return np_error(p, "feather", "expected a distance on the ground like 300m or "
					"0.5km, got \"%s\"", feather);
		if (v->output != OUT_MASK)
			return np_error(p, "feather", "softens a mask's edge: needs output = mask");
	}
	v->fill_opacity = (float)fo;
	for (int c = 0; c < 4; c++)
		v->styles[0].rgba[c] = col[c] / 255.0f;
	if (parse_width(width, &v->styles[0].width, &v->styles[0].px))
		return np_error(p, "width", "expected a width like 2px (texels) or 100m, 1.5km (on "
				"the ground), got \"%s\"", width);
	v->nstyles = 1;
	char buf[4096];
	const char *values[MAX_STYLES];
	if (styles && !field)
		return np_error(p, "styles", "needs style_field (the attribute the values match)");
	if (styles && (rc = parse_styles(p, v, styles, buf, values)))
		return rc;
	path = pe->value;
	char full[4096], err[256];
	if (path[0] != '/' && pl->dir && pl->dir[0])
		snprintf(full, sizeof full, "%s/%s", pl->dir, path);
	else
		snprintf(full, sizeof full, "%s", path);
	struct vec_load_opts o = { .layer = layer, .field = field, .values = values,
				   .nvalues = v->nstyles - 1 };
	rc = vec_source_load(full, &o, &v->src, err);
	if (rc)
		return np_error(p, "path", "%s", err);
	/* The tiles are named by the data read, not by where it lies. */
	np_hash_bytes(p, "vdata", 6);
	const struct vec_source *s = v->src;
	np_hash_bytes(p, s->xy, s->npts * 2 * sizeof *s->xy);
	for (size_t i = 0; i < s->nparts; i++)
		np_hash_bytes(p, &s->parts[i].n, sizeof s->parts[i].n);
	for (size_t i = 0; i < s->nfeats; i++) {
		uint32_t ks[3] = { s->feats[i].kind, s->feats[i].style, s->feats[i].nparts };
		np_hash_bytes(p, ks, sizeof ks);
	}
	/* Index boxes grown by each style's half-width in metres (px widths grow the query):
	 * north-south by the smallest meridional radius, east-west also by 1/cos of the box's
	 * most poleward latitude (global within a metre-wide line of a pole). */
	for (size_t i = 0; i < s->nfeats; i++) {
		struct vec_feature *f = &s->feats[i];
		const struct vstyle *st = &v->styles[f->style];
		double g = ((st->px ? 0 : st->width / 2) + v->feather) /
			   (v->a * (1 - v->e2) * (M_PI / 180)) * 1.001;
		double phi = fmax(fabs(f->bbox[1]), fabs(f->bbox[3])) + g;
		double c = phi >= 89.999 ? 0 : cos(phi * (M_PI / 180));
		double gx = g == 0 ? 0 : c > 0 ? g / c * 1.001 : 360;
		f->gbox[0] = f->bbox[0] - gx, f->gbox[2] = f->bbox[2] + gx;
		f->gbox[1] = f->bbox[1] - g, f->gbox[3] = f->bbox[3] + g;
	}
	for (int i = 0; i < v->nstyles; i++)
		if (v->styles[i].px)
			v->max_px = fmax(v->max_px, v->styles[i].width / 2);
	vec_source_index(v->src);
	n->out = v->output == OUT_MASK ? PIX_HEIGHT : PIX_COLOR;
	return 0;
}

/* One tile's frame: texel coordinates of (lon, lat) and the half-width of strokes. */
struct frame {
	const struct vector *v;
	double west, north, dlon, dlat; /* the tile's corner and texel size (degrees) */
	int T;
	struct vr_acc *acc;
	const struct vstyle *st;
	double off; /* the copy's longitude shift: −360, 0 or +360 */
};

static inline double tx(const struct frame *f, double lon) { return (lon + f->off - f->west) / f->dlon; }
static inline double ty(const struct frame *f, double lat) { return (f->north - lat) / f->dlat; }

/* Half-width of a stroke at latitude lat, in texels east (hx) and south (hy). */
static void half_width(const struct frame *f, double lat, double *hx, double *hy)
{
	const struct vstyle *st = f->st;
	if (st->px) {
		*hx = *hy = st->width / 2;
		return;
	}
	double my, mx;
	metres_per_degree(f->v, lat, &my, &mx);
	*hy = st->width / 2 / my / f->dlat;
	*hx = mx > 1e-9 * my ? st->width / 2 / mx / f->dlon : 1e12;
	*hx = *hx < 1e12 ? *hx : 1e12;
}

/* A disc (ellipse in texels) at (x, y); culled when outside the tile. */
static void disc(const struct frame *f, double x, double y, double hx, double hy)
{
	if (x + hx <= 0 || x - hx >= f->T || y + hy <= 0 || y - hy >= f->T)
		return;
	double r = fmin(fmax(hx, hy), (double)f->T);
	int n = (int)ceil(2 * M_PI * r / 0.7);
	n = n < 8 ? 8 : n > 64 ? 64 : n;
	double xy[128];
	for (int i = 0; i < n; i++) {
		double t = 2 * M_PI * i / n;
		xy[2 * i] = x + hx * cos(t);
		xy[2 * i + 1] = y + hy * sin(t);
	}
	vr_convex(f->acc, xy, n);
}

/* The quad of segment p → q, each end offset by its own half-width across the segment. */
static void quad(const struct frame *f, const double p[4], const double q[4])
{
	double hxm = 0.5 * (p[2] + q[2]), hym = 0.5 * (p[3] + q[3]);
	double dx = (q[0] - p[0]) / hxm, dy = (q[1] - p[1]) / hym, l = hypot(dx, dy);
	if (!(l > 0))
		return;
	double nx = -dy / l, ny = dx / l;
	double xy[8] = { p[0] - nx * p[2], p[1] - ny * p[3], q[0] - nx * q[2], q[1] - ny * q[3],
			 q[0] + nx * q[2], q[1] + ny * q[3], p[0] + nx * p[2], p[1] + ny * p[3] };
	double x0 = fmin(fmin(xy[0], xy[2]), fmin(xy[4], xy[6]));
	double x1 = fmax(fmax(xy[0], xy[2]), fmax(xy[4], xy[6]));
	double y0 = fmin(fmin(xy[1], xy[3]), fmin(xy[5], xy[7]));
	double y1 = fmax(fmax(xy[1], xy[3]), fmax(xy[5], xy[7]));
	if (x1 <= 0 || x0 >= f->T || y1 <= 0 || y0 >= f->T)
		return;
	vr_convex(f->acc, xy, 4);
}

/* Is a box (degrees, unshifted) away from the tile by more than its stroke? */
static bool chunk_out(const struct frame *f, const double *bb, bool stroke)
{
	double hx = 0, hy = 0;
	if (stroke) {
		double hx2, hy2;
		half_width(f, bb[1], &hx, &hy);
		half_width(f, bb[3], &hx2, &hy2);
		hx = fmax(hx, hx2), hy = fmax(hy, hy2);
		if (bb[1] < 0 && bb[3] > 0) { /* the equator: widest north-south */
			half_width(f, 0, &hx2, &hy2);
			hy = fmax(hy, hy2);
		}
	}
	return tx(f, bb[2]) + hx <= 0 || tx(f, bb[0]) - hx >= f->T || ty(f, bb[1]) + hy <= 0 ||
	       ty(f, bb[3]) - hy >= f->T;
}

/* Strokes a part (a line, or a ring's outline) with round joins and caps. Vertices closer
 * than half a texel to the last one kept are skipped, per chunk (chunks are the same on every
 * tile of a level, so neighbours skip the same ones). */
static void stroke_part(const struct frame *f, const struct vec_source *s, const struct vec_part *pa)
{
	uint32_t nc = pa->n > 1 ? (pa->n - 2) / VEC_CHUNK + 1 : 1;
	for (uint32_t c = 0; c < nc; c++) {
		if (chunk_out(f, s->chunks[pa->chunk0 + c], true))
			continue;
		uint32_t i0 = c * VEC_CHUNK, i1 = (c + 1) * VEC_CHUNK;
		i1 = i1 < pa->n - 1 ? i1 : pa->n - 1;
		double prev[4];
		for (uint32_t i = i0; i <= i1; i++) {
			const double *g = s->xy + 2 * (pa->first + i);
			double cur[4] = { tx(f, g[0]), ty(f, g[1]) };
			if (i > i0 && i < i1 && fabs(cur[0] - prev[0]) < 0.5 && fabs(cur[1] - prev[1]) < 0.5)
				continue;
			half_width(f, g[1], &cur[2], &cur[3]);
			disc(f, cur[0], cur[1], cur[2], cur[3]);
			if (i > i0)
				quad(f, prev, cur);
			memcpy(prev, cur, sizeof prev);
		}
	}
}

/* A ring's edges into the fill; chunks wholly west of the tile collapse to one edge on
 * x = 0 (their clamped edges would sum to it), wholly east or above/below: nothing. */
static void fill_ring(const struct frame *f, const struct vec_source *s, const struct vec_part *pa)
{
	uint32_t nc = (pa->n - 2) / VEC_CHUNK + 1;
	for (uint32_t c = 0; c < nc; c++) {
		const double *bb = s->chunks[pa->chunk0 + c];
		if (ty(f, bb[1]) <= 0 || ty(f, bb[3]) >= f->T || tx(f, bb[0]) >= f->T)
			continue;
		uint32_t i0 = c * VEC_CHUNK, i1 = (c + 1) * VEC_CHUNK;
		i1 = i1 < pa->n - 1 ? i1 : pa->n - 1;
		const double *g = s->xy + 2 * pa->first;
		if (tx(f, bb[2]) <= 0) {
			vr_edge(f->acc, 0, ty(f, g[2 * i0 + 1]), 0, ty(f, g[2 * i1 + 1]));
			continue;
		}
		for (uint32_t i = i0; i < i1; i++)
			vr_edge(f->acc, tx(f, g[2 * i]), ty(f, g[2 * i + 1]), tx(f, g[2 * i + 2]),
				ty(f, g[2 * i + 3]));
	}
}

/* Feature f's parts into the accumulator: what = 0 fills, 1 strokes. */
static void draw_feature(struct frame *fr, const struct vec_source *s, const struct vec_feature *ft,
			 int what)
{
	const struct vector *v = fr->v;
	double e = fr->west + fr->T * fr->dlon, south = fr->north - fr->T * fr->dlat;
	if (ft->gbox[1] > fr->north || ft->gbox[3] < south)
		return;
	double pad = v->max_px * fr->dlon;
	int k0 = (int)ceil((fr->west - pad - ft->gbox[2]) / 360);
	int k1 = (int)floor((e + pad - ft->gbox[0]) / 360);
	for (int k = k0; k <= k1; k++) {
		fr->off = 360.0 * k;
		for (uint32_t p = 0; p < ft->nparts; p++) {
			const struct vec_part *pa = &s->parts[ft->part0 + p];
			if (ft->kind == VEC_POLYGON && what == 0)
				fill_ring(fr, s, pa);
			else if (ft->kind == VEC_POLYGON || ft->kind == VEC_LINE)
				stroke_part(fr, s, pa);
			else /* points */
				for (uint32_t i = 0; i < pa->n; i++) {
					const double *g = s->xy + 2 * (pa->first + i);
					double hx, hy;
					half_width(fr, g[1], &hx, &hy);
					disc(fr, tx(fr, g[0]), ty(fr, g[1]), hx, hy);
				}
		}
	}
}

static bool wants(const struct vector *v, const struct vec_feature *ft, int what)
{
	if (ft->kind != VEC_POLYGON)
		return what == 1;
	return what == 0 ? v->polygons != POLY_OUTLINE : v->polygons != POLY_FILL;
}

/* The feather of a mask tile: each texel's distance in metres to the nearest shape, up to
 * the feather. */
struct feather {
	const struct vector *v;
	double west, north, dlon, dlat; /* as struct frame */
	int T;
	float *dist;	  /* T × T metres, from v->feather down */
	const double *mx; /* per row: metres per degree east and north at its centres */
	const double *my;
	double my_min;	  /* the least metres per degree north (the equator's) */
};

/* The texels within reach of segment p → q (degrees, shifted to the copy; a point when p == q)
 * take their distance to it, less hw metres, where nearer than what they hold. Distances are
 * taken in the plane tangent at each texel's centre. */
static void feather_segment(struct feather *fe, const double p[2], const double q[2], double hw)
{
	const int T = fe->T;
	double reach = fe->v->feather + hw, glat = reach / fe->my_min;
	double lat0 = fmin(p[1], q[1]) - glat, lat1 = fmax(p[1], q[1]) + glat;
	double fj0 = floor((fe->north - lat1) / fe->dlat), fj1 = floor((fe->north - lat0) / fe->dlat);
	if (fj1 < 0 || fj0 > T - 1)
		return;
	int j0 = fj0 < 0 ? 0 : (int)fj0, j1 = fj1 > T - 1 ? T - 1 : (int)fj1;
	double lon0 = fmin(p[0], q[0]), lon1 = fmax(p[0], q[0]);
	for (int j = j0; j <= j1; j++) {
		double mx = fe->mx[j], my = fe->my[j], latc = fe->north - (j + 0.5) * fe->dlat;
		double fi0 = 0, fi1 = T - 1;
		if (mx * 360 > reach) { /* else every column of the row is within reach */
			double gl = reach / mx;
			fi0 = fmax(0, floor((lon0 - gl - fe->west) / fe->dlon));
			fi1 = fmin(T - 1, floor((lon1 + gl - fe->west) / fe->dlon));
			if (fi0 > fi1)
				continue; /* (before an out-of-range cast to int) */
		}
		double ay = (p[1] - latc) * my, ey = (q[1] - p[1]) * my;
		float *row = fe->dist + (size_t)j * T;
		for (int i = (int)fi0; i <= (int)fi1; i++) {
			double lonc = fe->west + (i + 0.5) * fe->dlon;
			double ax = (p[0] - lonc) * mx, ex = (q[0] - p[0]) * mx;
			double l2 = ex * ex + ey * ey;
			double t = l2 > 0 ? fmin(fmax(-(ax * ex + ay * ey) / l2, 0), 1) : 0;
			double dx = ax + t * ex, dy = ay + t * ey;
			double d = sqrt(dx * dx + dy * dy) - hw;
			if (d < row[i])
				row[i] = d > 0 ? (float)d : 0.0f;
		}
	}
}

/* Whether a chunk's box (degrees, shifted by off) is farther than reach metres from the tile. */
static bool feather_far(const struct feather *fe, const double *bb, double off, double reach)
{
	double south = fe->north - fe->T * fe->dlat, east = fe->west + fe->T * fe->dlon;
	double glat = reach / fe->my_min;
	if (bb[1] - glat > fe->north || bb[3] + glat < south)
		return true;
	double phi = fmin(fmax(fabs(bb[1]), fabs(bb[3])) + glat, 90);
	double c = cos(phi * (M_PI / 180));
	if (phi >= 89.999 || !(c > 0))
		return false;
	double glon = reach / (fe->my_min * c) * 1.001; /* N ≥ M: east-west grows less */
	return bb[0] + off - glon > east || bb[2] + off + glon < fe->west;
}

/* Feature ft's edges, centrelines and points into the feather (every copy near the tile). */
static void feather_feature(struct feather *fe, const struct vec_source *s,
			    const struct vec_feature *ft)
{
	const struct vector *v = fe->v;
	const struct vstyle *st = &v->styles[ft->style];
	double latc = fe->north - fe->T * fe->dlat / 2, my, mx;
	metres_per_degree(v, latc, &my, &mx);
	double hw = st->px ? st->width / 2 * fe->dlat * my : st->width / 2;
	if (ft->kind == VEC_POLYGON && v->polygons == POLY_FILL)
		hw = 0;
	double east = fe->west + fe->T * fe->dlon, pad = v->max_px * fe->dlon;
	int k0 = (int)ceil((fe->west - pad - ft->gbox[2]) / 360);
	int k1 = (int)floor((east + pad - ft->gbox[0]) / 360);
	for (int k = k0; k <= k1; k++) {
		double off = 360.0 * k;
		for (uint32_t pi = 0; pi < ft->nparts; pi++) {
			const struct vec_part *pa = &s->parts[ft->part0 + pi];
			const double *g = s->xy + 2 * pa->first;
			if (ft->kind == VEC_POINT) {
				for (uint32_t i = 0; i < pa->n; i++) {
					double q[2] = { g[2 * i] + off, g[2 * i + 1] };
					feather_segment(fe, q, q, hw);
				}
				continue;
			}
			if (pa->n < 2)
				continue;
			uint32_t nc = (pa->n - 2) / VEC_CHUNK + 1;
			for (uint32_t c = 0; c < nc; c++) {
				if (feather_far(fe, s->chunks[pa->chunk0 + c], off, v->feather + hw))
					continue;
				uint32_t i0 = c * VEC_CHUNK, i1 = (c + 1) * VEC_CHUNK;
				i1 = i1 < pa->n - 1 ? i1 : pa->n - 1;
				for (uint32_t i = i0; i < i1; i++) {
					double a[2] = { g[2 * i] + off, g[2 * i + 1] };
					double b[2] = { g[2 * i + 2] + off, g[2 * i + 3] };
					feather_segment(fe, a, b, hw);
				}
			}
		}
	}
}

/* The feather over the coverage o: c + (1 − c)·(1 − smoothstep(d / feather)). */
static void feather_mask(struct feather *fe, const struct vec_source *s, const uint32_t *ids,
			 size_t nids, float *o)
{
	const struct vector *v = fe->v;
	const int T = fe->T;
	for (size_t i = 0; i < (size_t)T * T; i++)
		fe->dist[i] = (float)v->feather;
	for (size_t i = 0; i < nids; i++) {
		const struct vec_feature *ft = &s->feats[ids[i]];
		if (v->styles[ft->style].rgba[3] > 0)
			feather_feature(fe, s, ft);
	}
	for (size_t i = 0; i < (size_t)T * T; i++) {
		float c = o[i], d = fe->dist[i];
		if (c >= 1 || d >= (float)v->feather)
			continue;
		float t = d / (float)v->feather, w = 1 - t * t * (3 - 2 * t);
		o[i] = c + (1 - c) * w;
	}
}

struct scratch {
	float *acc, *cov, *rgba;
	uint32_t *ids;
	uint8_t *seen;
};

/* Composite coverage cov (rows [ya, yb)) in colour c × alpha over the premultiplied rgba. */
static void composite(float *rgba, const float *cov, int T, int ya, int yb, const float c[4],
		      float alpha)
{
	for (size_t i = (size_t)ya * T; i < (size_t)yb * T; i++) {
		float a = cov[i] * alpha;
		if (a <= 0)
			continue;
		float *o = rgba + 4 * i;
		for (int ch = 0; ch < 3; ch++)
			o[ch] = c[ch] * a + o[ch] * (1 - a);
		o[3] = a + o[3] * (1 - a);
	}
}

static int vector_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			   struct tile *const *in, int nin, struct tile *out)
{
	(void)in;
	(void)nin;
	const struct vector *v = n->impl;
	const struct vec_source *s = v->src;
	const int T = (int)out->size;
	size_t tt = (size_t)T * T;
	bool mask = v->output == OUT_MASK;
	struct geo_rect r;
	grid_tile_rect(k, &r);
	struct frame fr = { .v = v, .west = r.west, .north = r.north, .T = T,
			    .dlon = (r.east - r.west) / T, .dlat = (r.north - r.south) / T };
	double pad = v->max_px * fmax(fr.dlon, fr.dlat);
	size_t nacc = vr_acc_floats(T, T), nf = s->nfeats ? s->nfeats : 1;
	size_t nrow = mask && v->feather > 0 ? 2 * (size_t)T : 0, ndist = nrow ? tt : 0;
	size_t bytes = nrow * sizeof(double) +
		       (nacc + tt + ndist + (mask ? 0 : 4 * tt)) * sizeof(float) + nf * 5 + 64;
	char *base = gen_scratch(g, bytes);
	double *rows = (double *)base; /* the feather's metres per degree, per row */
	struct scratch sc = { .acc = (float *)(rows + nrow) };
	sc.cov = sc.acc + nacc;
	sc.rgba = mask ? NULL : sc.cov + tt;
	sc.ids = (uint32_t *)(sc.cov + tt + ndist + (mask ? 0 : 4 * tt));
	sc.seen = (uint8_t *)(sc.ids + nf);
	memset(sc.seen, 0, nf);
	size_t nids = vec_source_query(s, r.west - pad, fmax(r.south - pad, -90), r.east + pad,
				       fmin(r.north + pad, 90), sc.ids, sc.seen);
	if (nids == 0) { /* nothing here: the shared all-zero tile, nothing written */
		static const uint8_t zero[4];
		tile_fill_uniform(out, zero);
		return 0;
	}
	struct vr_acc acc;
	vr_acc_init(&acc, sc.acc, T, T);
	fr.acc = &acc;
	float *o = mask ? tile_f32(out) : NULL;
	if (mask)
		memset(o, 0, tt * sizeof *o);
	int ry0 = T, ry1 = T; /* rows [ry0, ry1) of sc.rgba hold colour; the rest is clear */
	/* Colour: each style's fills, then its strokes, composited in style order. Mask: the
	 * union of everything not transparent, in one accumulation. */
	for (int st = 0; st < v->nstyles; st++) {
		fr.st = &v->styles[st];
		if (fr.st->rgba[3] <= 0)
			continue;
		for (int what = 0; what < 2; what++) {
			bool any = false;
			for (size_t i = 0; i < nids; i++) {
				const struct vec_feature *ft = &s->feats[sc.ids[i]];
				if (ft->style != st || !wants(v, ft, what))
					continue;
				draw_feature(&fr, s, ft, what);
				any = true;
			}
			if (!any || mask)
				continue;
			int ya, yb;
			vr_resolve(&acc, sc.cov, &ya, &yb);
			if (ya >= yb)
				continue;
			/* Grow the rows in use, clearing the ones added. */
			int na = ry0 < ry1 ? (ya < ry0 ? ya : ry0) : ya;
			int nb = ry0 < ry1 ? (yb > ry1 ? yb : ry1) : yb;
			for (int y = na; y < nb; y++)
				if (ry0 >= ry1 || y < ry0 || y >= ry1)
					memset(sc.rgba + (size_t)y * T * 4, 0, (size_t)T * 4 * sizeof *sc.rgba);
			ry0 = na, ry1 = nb;
			float alpha = fr.st->rgba[3] * (what == 0 ? v->fill_opacity : 1);
			composite(sc.rgba, sc.cov, T, ya, yb, fr.st->rgba, alpha);
		}
	}
	if (mask) {
		int ya, yb;
		vr_resolve(&acc, o, &ya, &yb);
		if (nrow) {
			struct feather fe = { .v = v, .west = r.west, .north = r.north, .dlon = fr.dlon,
					      .dlat = fr.dlat, .T = T, .dist = sc.cov + tt,
					      .mx = rows, .my = rows + T };
			double mxe;
			metres_per_degree(v, 0, &fe.my_min, &mxe);
			for (int j = 0; j < T; j++)
				metres_per_degree(v, r.north - (j + 0.5) * fr.dlat, rows + T + j, rows + j);
			feather_mask(&fe, s, sc.ids, nids, o);
		}
		return 0;
	}
	uint8_t *d = out->data;
	if (ry0 >= ry1)
		ry0 = ry1 = 0;
	memset(d, 0, (size_t)ry0 * T * 4);
	memset(d + (size_t)ry1 * T * 4, 0, (size_t)(T - ry1) * T * 4);
	for (size_t i = (size_t)ry0 * T; i < (size_t)ry1 * T; i++) {
		const float *p = sc.rgba + 4 * i;
		if (p[3] <= 0) {
			memset(d + 4 * i, 0, 4);
			continue;
		}
		for (int c = 0; c < 3; c++) {
			float x = p[c] / p[3] * 255 + 0.5f;
			d[4 * i + c] = (uint8_t)(x < 255 ? x : 255);
		}
		d[4 * i + 3] = (uint8_t)(p[3] * 255 + 0.5f);
	}
	return 0;
}

const struct node_type node_type_vector = {
	.name = "vector",
	.doc = "a GDAL/OGR vector source rasterized with exact coverage: colour or a mask",
	.version = 1,
	.slots = NULL,
	.nslots = 0,
	.create = vector_create,
	.destroy = vector_destroy,
	.deps = NULL,
	.generate = vector_generate,
};
