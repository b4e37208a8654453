/* node_geoid — `geoid`: heights relative to the geoid (mean sea level, as most elevation data
 * sets give them) turned into heights above the ellipsoid, which is what the grid and the
 * viewer use: out = input + N(lat, lon), N from a geoid grid in the GTX format PROJ ships
 * (default /usr/share/proj/egm96_15.gtx from Debian's proj-data: EGM96 on a 15′ grid,
 * −107 m south of India to +85 m over New Guinea). `sign = -1` goes the other way.
 *
 * GTX: a 40-byte big-endian header (south latitude, west longitude, Δlat, Δlon as doubles;
 * rows, columns as int32), then rows × columns big-endian float32 values, rows south → north,
 * values at grid nodes. Longitude wraps when the columns span 360°. N is bilinear between
 * nodes.
 * Thread-safety: the grid is read once at create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"

#define GTX_HEADER 40
#define GTX_MAX_NODES (64u << 20)

struct geoid {
	double lat0, lon0, dlat, dlon;
	int32_t rows, cols;
	int wrap;
	float sign;
	float *n; /* rows × cols, south → north */
};

static double be_double(const unsigned char *p)
{
	uint64_t u = 0;
	for (int i = 0; i < 8; i++)
		u = u << 8 | p[i];
	double d;
	memcpy(&d, &u, sizeof d);
	return d;
}

static uint32_t be_u32(const unsigned char *p)
{
	return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* Reads a GTX grid; returns 0 or an np_error. */
static int read_gtx(struct node_parse *p, const char *path, struct geoid *g)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return np_error(p, "path", "cannot open %s: %s", path, strerror(errno));
	unsigned char h[GTX_HEADER];
	int rc = 0;
	if (fread(h, 1, sizeof h, f) != sizeof h) {
		rc = np_error(p, "path", "%s: shorter than a GTX header", path);
		goto out;
	}
	g->lat0 = be_double(h);
	g->lon0 = be_double(h + 8);
	g->dlat = be_double(h + 16);
	g->dlon = be_double(h + 24);
	g->rows = (int32_t)be_u32(h + 32);
	g->cols = (int32_t)be_u32(h + 36);
	if (!(g->dlat > 0 && g->dlon > 0) || g->rows < 2 || g->cols < 2 ||
	    (uint64_t)g->rows * (uint64_t)g->cols > GTX_MAX_NODES || !isfinite(g->lat0) ||
	    !isfinite(g->lon0)) {
		rc = np_error(p, "path", "%s: not a GTX geoid grid (header: %d x %d nodes, "
			      "step %g x %g)", path, g->rows, g->cols, g->dlat, g->dlon);
		goto out;
	}
	size_t n = (size_t)g->rows * (size_t)g->cols;
	unsigned char *raw = xmalloc(n * 4);
	if (fread(raw, 4, n, f) != n) {
		free(raw);
		rc = np_error(p, "path", "%s: truncated: expected %d x %d values", path, g->rows,
			      g->cols);
		goto out;
	}
	g->n = xmalloc(n * sizeof *g->n);
	for (size_t i = 0; i < n; i++) {
		uint32_t u = be_u32(raw + 4 * i);
		memcpy(&g->n[i], &u, 4);
		if (!isfinite(g->n[i]) || fabsf(g->n[i]) > 1000.0f)
			g->n[i] = 0.0f; /* GTX "no data" (-88.8888) never occurs in global models */
	}
	free(raw);
	g->wrap = fabs(g->cols * g->dlon - 360.0) < 1e-6;
out:
	fclose(f);
	return rc;
}

static int geoid_create(struct node *n, struct node_parse *p)
{
	const char *path;
	long sign;
	int rc;
	if ((rc = np_string(p, "path", "/usr/share/proj/egm96_15.gtx", &path)) ||
	    (rc = np_int(p, "sign", 1, -1, 1, &sign)))
		return rc;
	if (sign == 0)
		return np_error(p, "sign", "must be 1 (geoid → ellipsoid) or -1");
	char *full = planet_resolve_path(n->planet, path);
	struct stat st;
	if (stat(full, &st) == 0) {
		int64_t id[2] = { (int64_t)st.st_size, (int64_t)st.st_mtime };
		np_hash_bytes(p, id, sizeof id);
	}
	struct geoid *g = xcalloc(1, sizeof *g);
	rc = read_gtx(p, full, g);
	free(full);
	if (rc) {
		free(g);
		return rc;
	}
	g->sign = (float)sign;
	n->impl = g;
	n->out = PIX_HEIGHT;
	return 0;
}

static void geoid_destroy(struct node *n)
{
	struct geoid *g = n->impl;
	if (g)
		free(g->n);
	free(g);
}

/* Where a longitude falls between grid columns: c0, c1 and the weight of c1. */
struct gcol {
	int c0, c1;
	double wc;
};

static struct gcol geoid_col(const struct geoid *g, double lon)
{
	double fc = (lon - g->lon0) / g->dlon;
	if (g->wrap) {
		fc = fmod(fc, g->cols);
		if (fc < 0)
			fc += g->cols;
	}
	if (!g->wrap && fc < 0)
		fc = 0;
	if (!g->wrap && fc > g->cols - 1)
		fc = g->cols - 1;
	int c0 = (int)fc;
	return (struct gcol){ c0, c0 + 1 < g->cols ? c0 + 1 : (g->wrap ? 0 : c0), fc - c0 };
}

/* The two grid rows round a latitude and the weight of the second. */
static const float *geoid_rows(const struct geoid *g, double lat, const float **b, double *wr)
{
	double fr = (lat - g->lat0) / g->dlat;
	if (fr < 0)
		fr = 0;
	if (fr > g->rows - 1)
		fr = g->rows - 1;
	int r0 = (int)fr, r1 = r0 + 1 < g->rows ? r0 + 1 : r0;
	*wr = fr - r0;
	*b = g->n + (size_t)r1 * g->cols;
	return g->n + (size_t)r0 * g->cols;
}

/* N between the rows a, b (weight wr) at column c: bilinear between grid nodes. */
static inline float geoid_at(const float *a, const float *b, double wr, struct gcol c)
{
	double top = a[c.c0] + (a[c.c1] - a[c.c0]) * c.wc;
	double bot = b[c.c0] + (b[c.c1] - b[c.c0]) * c.wc;
	return (float)(top + (bot - top) * wr);
}

/* N at (lat, lon). */
static float undulation(const struct geoid *g, double lat, double lon)
{
	const float *b;
	double wr;
	const float *a = geoid_rows(g, lat, &b, &wr);
	return geoid_at(a, b, wr, geoid_col(g, lon));
}

bool geoid_undulation(const struct node *n, double lat, double lon, double *out)
{
	if (!n || n->type != &node_type_geoid || !n->impl)
		return false;
	*out = undulation(n->impl, lat, lon);
	return true;
}

static int geoid_generate(const struct node *n, struct gen_ctx *gc, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	const struct geoid *g = n->impl;
	if (nin < 1 || in[0]->type != PIX_HEIGHT || in[0]->size != out->size)
		return -EINVAL;
	uint32_t T = out->size;
	/* The grid columns depend on the texel's longitude only and the rows on its latitude:
	 * worked out once per column and per row, the same arithmetic as undulation(). */
	struct gcol *cols = gen_scratch(gc, (size_t)T * sizeof *cols);
	for (uint32_t i = 0; i < T; i++) {
		double lon, lat;
		grid_texel_center(k, T, i, 0, &lon, &lat);
		cols[i] = geoid_col(g, (double)(float)lon);
	}
	const float *src = tile_f32(in[0]);
	float *dst = tile_f32(out);
	for (uint32_t j = 0; j < T; j++) {
		double lon, lat, wr;
		grid_texel_center(k, T, 0, j, &lon, &lat);
		const float *b, *a = geoid_rows(g, lat, &b, &wr);
		for (uint32_t i = 0; i < T; i++) {
			size_t at = (size_t)j * T + i;
			dst[at] = src[at] + g->sign * geoid_at(a, b, wr, cols[i]);
		}
	}
	return 0;
}

static const struct node_slot geoid_slots[] = {
	{ .name = "input", .type = PIX_HEIGHT },
};

const struct node_type node_type_geoid = {
	.name = "geoid",
	.doc = "heights above the geoid (sea level) to heights above the ellipsoid (EGM96 grid)",
	.version = 1,
	.slots = geoid_slots,
	.nslots = 1,
	.create = geoid_create,
	.destroy = geoid_destroy,
	.generate = geoid_generate,
};
