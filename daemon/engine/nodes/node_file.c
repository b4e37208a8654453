/* node_file — the `file` node: an image file (through OpenImageIO, common/img.h) resampled
 * onto the tile grid. Threads: the node is immutable after create; generate() runs on any
 * worker concurrently (the img_cache is thread-safe, buffers come from gen_scratch).
 * The node owns its path string; it reads through its planet's img_cache (shared by every
 * file node of the planet, and of the daemon's planet set), so two nodes on one path share
 * the open file and its cached tiles.
 *
 * Parameters ([node NAME] with type = file):
 *   path      the image (relative paths resolve against the planet file's directory)
 *   kind      height | color: PIX_HEIGHT or PIX_COLOR output (default height)
 *   bounds    W,S,E,N in degrees covered by the image (default: the bounds `clipmapctl import`
 *             recorded in the file, else -180,-90,180,90). Row 0 is the north edge, column 0
 *             the west edge; pixels are areas with centres at +0.5. S and N may reach half
 *             a pixel past the poles (pixel-is-point grids with rows centred on the poles).
 *   channel   (height) the channel holding heights (default 0)
 *   scale, offset  (height) height = raw·scale + offset; raw is the stored value, integers
 *             unnormalised (int16 metres: scale 1; uint16 in 0.1 m: scale 0.1)
 *   nodata    (height) a raw value meaning "no data" (default: one recorded by import); NaN
 *             in float files always is
 *   fill      height in metres (default 0) or colour (default 0,0,0,0) outside the bounds and
 *             where data is missing
 *   lon_wrap  true | false: bilinear wraps across the east/west edges (default true when the
 *             bounds span 360°; only allowed then)
 *   cache_mb  deprecated and ignored (still checked: 1..1048576): the image cache is the
 *             planet's, sized by clipmapd's [engine] image_cache_mb. Not hashed.
 * The file's size, mtime and inode are hashed: a changed file gets new tile names after a
 * reload, and the shared cache forgets the old file's pixels (img_cache_set_version).
 *
 * Resampling. A tile's texels are evenly spaced in degrees, so the texel → source pixel map
 * is separable: per output column a few (source column, weight) taps, per output row the
 * same. generate() reads the source region the tile needs (plus the bilinear border; for a
 * 360° image the columns wrap, read as two pieces when the tile straddles the image's edge)
 * once through img_cache_read, then runs a horizontal pass over those rows and a vertical
 * pass into the tile. Filtering (seed 000 §4.3): with r = texel spacing / pixel spacing, the
 * read uses MIP level m = floor(log2(min(rx, ry))) (the file's own levels or OIIO's automip,
 * each a 2×2 box of the one above), where the source is at most 2× finer than the output and
 * bilinear suffices. On anisotropic levels (lx < ly + 1, wider texels in longitude) the
 * wider axis is still up to 8× finer at level m: there n = ceil(r) bilinear sub-taps spread
 * across the texel average it (a box of bilinears), and m rises until n ≤ 8. When the tile
 * maps 1:1 onto the pixels of a level, the read is a plain copy (straight into the tile for
 * float heights with scale 1, offset 0). Known limit of the floor() choice: for 1 < r < 2,
 * content at the source's Nyquist frequency still aliases (a 0/250 1-pixel checkerboard at
 * r = 1.5 gives texels of about 94..156 instead of 125); from r = 2 on it averages out.
 *
 * Missing data. A texel whose centre is outside the bounds gets the fill. Inside, nodata
 * (and NaN) samples get weight 0 and the others are renormalised: the texel keeps the
 * weighted mean of its valid samples when they carry at least half of its weight, and gets
 * the fill otherwise — so a coastline neither grows nor shrinks by a texel.
 * Colour is filtered as straight (not premultiplied) RGBA.
 */
#include "engine/node_types.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "common/img.h"
#include "engine/planet.h"
#include "common/xalloc.h"

#define FILE_MAX_LEVELS 32
#define FILE_MAX_SUBTAPS 8
#define FILE_MAX_REGION ((size_t)1 << 26) /* source pixels one tile may read */

enum file_kind { KIND_HEIGHT, KIND_COLOR };

struct file_impl {
	char *path; /* resolved; owned */
	struct img_cache *cache; /* the planet's (borrowed), or own_cache */
	struct img_cache *own_cache; /* owned; only for a planet without an image cache */
	struct img_info info;
	int nlev;
	int lw[FILE_MAX_LEVELS], lh[FILE_MAX_LEVELS]; /* MIP level sizes */
	int kind;
	double west, south, east, north;
	bool wrap;
	int channel;	     /* first channel read */
	int nch;	     /* channels read: 1 for heights, 1..4 for colour */
	enum img_type rtype; /* type read: the file's own for heights, U8 for colour */
	float scale, offset;
	bool has_nodata;
	float nodata;
	float fill_h;
	uint8_t fill_c[4];
};

static const char *const kind_names[] = { "height", "color", NULL };
/* Index parity is the value. */
static const char *const bool_names[] = { "false", "true", "no", "yes", "0", "1", NULL };

static void file_destroy(struct node *nd)
{
	struct file_impl *f = nd->impl;
	if (!f)
		return;
	img_cache_unref(f->own_cache);
	free(f->path);
	free(f);
	nd->impl = NULL;
}

static char *resolve_path(const struct planet *pl, const char *path)
{
	if (path[0] == '/' || !pl || !pl->dir || !pl->dir[0])
		return xstrdup(path);
	size_t a = strlen(pl->dir), b = strlen(path);
	char *s = xmalloc(a + b + 2);
	memcpy(s, pl->dir, a);
	s[a] = '/';
	memcpy(s + a + 1, path, b + 1);
	return s;
}

/* Rejects a height-only key on a colour node (rather than "unknown key"). */
static int height_only(struct node_parse *p, const char *key)
{
	if (ini_find(p->sec, key))
		return np_error(p, key, "only applies to kind = height");
	return 0;
}

static int parse_cache_mb(struct node_parse *p, long *out)
{
	/* Deprecated: file nodes read through their planet's shared image cache (clipmapd's
	 * [engine] image_cache_mb). Still checked, and it sizes the node's own cache in a
	 * hand-built planet that has none. Not hashed: the cache size never changes a texel. */
	struct ini_entry *e = ini_find(p->sec, "cache_mb");
	*out = 256;
	if (!e)
		return 0;
	e->used = true;
	char *end;
	errno = 0;
	long v = strtol(e->value, &end, 10);
	if (end == e->value || *end || errno || v < 1 || v > 1 << 20)
		return np_error(p, "cache_mb", "expected MiB in [1, 1048576], got \"%s\"", e->value);
	*out = v;
	return 0;
}

/* What `clipmapctl import` records in the ImageDescription (client/ctl/import.h):
 * "clipmap:bounds=W,S,E,N" and optionally "clipmap:nodata=V". Returns how many were found
 * (bit 0: bounds, bit 1: nodata). */
static int file_desc(struct file_impl *f, double b[4], double *nodata)
{
	char d[512];
	int found = 0;
	if (img_cache_description(f->cache, f->path, d, sizeof d, NULL))
		return 0;
	const char *s = strstr(d, "clipmap:bounds=");
	if (s && sscanf(s, "clipmap:bounds=%lf,%lf,%lf,%lf", &b[0], &b[1], &b[2], &b[3]) == 4)
		found |= 1;
	s = strstr(d, "clipmap:nodata=");
	if (s && sscanf(s, "clipmap:nodata=%lf", nodata) == 1)
		found |= 2;
	return found;
}

static int parse_bounds(struct node_parse *p, struct file_impl *f)
{
	double b[4], nd;
	int nb, rc = np_doubles(p, "bounds", b, 4, &nb);
	if (rc)
		return rc;
	if (nb == 0) {
		if (!(file_desc(f, b, &nd) & 1))
			b[0] = -180, b[1] = -90, b[2] = 180, b[3] = 90;
	} else if (nb != 4) {
		return np_error(p, "bounds", "expected 4 numbers W,S,E,N (degrees), got %d", nb);
	}
	/* A pixel-is-point global grid (ETOPO5: 2161 rows centred from pole to pole) reaches
	 * half a pixel past each pole; allow that much (and never more than a degree). */
	double py = b[3] > b[1] ? 0.5 * (b[3] - b[1]) / f->info.height * (1 + 1e-9) : 0;
	py = py < 1 ? py : 0;
	if (!(b[0] < b[2] && b[2] - b[0] <= 360 + 1e-9 && b[0] >= -360 && b[2] <= 360))
		return np_error(p, "bounds", "need -360 <= W < E <= 360 and E - W <= 360, got W=%g E=%g",
				b[0], b[2]);
	if (!(b[1] < b[3] && b[1] >= -90 - py && b[3] <= 90 + py))
		return np_error(p, "bounds", "need -90 <= S < N <= 90, got S=%g N=%g", b[1], b[3]);
	if (fabs(b[2] - b[0] - 360) < 1e-9)
		b[2] = b[0] + 360; /* "global" below compares exactly */
	f->west = b[0], f->south = b[1], f->east = b[2], f->north = b[3];
	return 0;
}

static int parse_height(struct node_parse *p, struct file_impl *f)
{
	long ch;
	double v;
	int rc = np_int(p, "channel", 0, 0, 4096, &ch);
	if (rc)
		return rc;
	if (ch >= f->info.channels)
		return np_error(p, "channel", "%s has %d channel%s, there is no channel %ld", f->path,
				f->info.channels, f->info.channels == 1 ? "" : "s", ch);
	f->channel = (int)ch;
	f->nch = 1;
	f->rtype = f->info.type;
	if (f->rtype == IMG_NONE)
		return np_error(p, "path", "%s: %s samples are not supported for heights (use uint8, "
				"uint16, int16, half or float)", f->path, f->info.format);
	if ((rc = np_double(p, "scale", 1, -1e30, 1e30, &v)))
		return rc;
	f->scale = (float)v;
	if ((rc = np_double(p, "offset", 0, -1e30, 1e30, &v)))
		return rc;
	f->offset = (float)v;
	double b[4], fnd;
	if (ini_find(p->sec, "nodata")) {
		if ((rc = np_double(p, "nodata", 0, -1e30, 1e30, &v)))
			return rc;
		f->has_nodata = true;
		f->nodata = (float)v;
	} else if (file_desc(f, b, &fnd) & 2) {
		f->has_nodata = true; /* recorded by clipmapctl import; the file's mtime is hashed */
		f->nodata = (float)fnd;
	}
	if ((rc = np_double(p, "fill", 0, -1e30, 1e30, &v)))
		return rc;
	f->fill_h = (float)v;
	return 0;
}

static int parse_color(struct node_parse *p, struct file_impl *f)
{
	static const char *const only_h[] = { "channel", "scale", "offset", "nodata" };
	static const uint8_t clear[4] = { 0, 0, 0, 0 };
	for (size_t i = 0; i < sizeof only_h / sizeof only_h[0]; i++) {
		int rc = height_only(p, only_h[i]);
		if (rc)
			return rc;
	}
	f->channel = 0;
	f->nch = f->info.channels < 4 ? f->info.channels : 4;
	f->rtype = IMG_U8;
	return np_color(p, "fill", clear, f->fill_c);
}

static int file_create(struct node *nd, struct node_parse *p)
{
	struct file_impl *f = xcalloc(1, sizeof *f);
	nd->impl = f; /* node_init calls destroy on failure */
	/* Not np_string: the hash takes the resolved path, so "a.tif" and "/dir/a.tif" name
	 * the same tiles. */
	struct ini_entry *pe = ini_find(p->sec, "path");
	const char *path = pe ? pe->value : NULL;
	int rc;
	if (pe)
		pe->used = true;
	if (!path || !path[0])
		return np_error(p, "path", "missing: the image file to read");
	f->path = resolve_path(nd->planet, path);
	struct stat st;
	if (stat(f->path, &st) != 0)
		return np_error(p, "path", "cannot open %s: %s", f->path, strerror(errno));
	/* The inode too: a file replaced by rename (img_write, clipmapctl import) within the
	 * file system's timestamp granularity still counts as changed. */
	int64_t stamp[4] = { (int64_t)st.st_size, (int64_t)st.st_mtim.tv_sec,
			     (int64_t)st.st_mtim.tv_nsec, (int64_t)st.st_ino };
	np_hash_bytes(p, "path", 5);
	np_hash_bytes(p, f->path, strlen(f->path) + 1);
	np_hash_bytes(p, stamp, sizeof stamp);

	long cache_mb;
	if ((rc = parse_cache_mb(p, &cache_mb)))
		return rc;
	f->cache = nd->planet->images;
	if (!f->cache) {
		f->cache = f->own_cache = img_cache_create((size_t)cache_mb);
		if (!f->cache)
			return np_error(p, "path", "cannot create an image cache");
	}
	/* The cache is shared across planets and reloads and keyed by path: if an earlier node
	 * saw another version of this file, drop what is cached of it. */
	img_cache_set_version(f->cache, f->path, stamp, sizeof stamp);
	char err[256];
	if (img_cache_info(f->cache, f->path, &f->info, err))
		return np_error(p, "path", "cannot open %s", err);
	if (f->info.width <= 0 || f->info.height <= 0 || f->info.channels <= 0)
		return np_error(p, "path", "%s: empty image", f->path);
	f->nlev = 0;
	for (int m = 0; m < f->info.mip_levels && m < FILE_MAX_LEVELS; m++) {
		if (img_cache_level_size(f->cache, f->path, m, &f->lw[m], &f->lh[m], err))
			break;
		f->nlev = m + 1;
	}
	if (f->nlev == 0)
		return np_error(p, "path", "cannot open %s", err);

	int kind;
	if ((rc = np_enum(p, "kind", kind_names, KIND_HEIGHT, &kind)))
		return rc;
	f->kind = kind;
	nd->out = kind == KIND_COLOR ? PIX_COLOR : PIX_HEIGHT;
	if ((rc = parse_bounds(p, f)))
		return rc;
	bool global = f->east - f->west == 360; /* exact: parse_bounds snaps near-360 spans */
	int wrap;
	if ((rc = np_enum(p, "lon_wrap", bool_names, global ? 1 : 0, &wrap)))
		return rc;
	f->wrap = wrap & 1;
	if (f->wrap && !global)
		return np_error(p, "lon_wrap", "needs bounds spanning 360 degrees of longitude");
	return kind == KIND_COLOR ? parse_color(p, f) : parse_height(p, f);
}

/* ---- generation ---- */

/* The per-axis resampling table: output texel i reads taps idx[i·K + k] (relative to the
 * buffer's first source pixel `lo`) with weights w[i·K + k], K = 2n. */
struct axis {
	int n, K;
	int32_t *idx;
	float *w;
	uint8_t *in; /* texel centre inside the bounds */
	int64_t lo, hi;	 /* source pixels the buffer holds (unwrapped when wrapping) */
	bool any, all; /* some / every texel inside */
};

static int subtaps(double r)
{
	if (r < 2)
		return 1;
	double n = ceil(r - 1e-9);
	return n > FILE_MAX_SUBTAPS ? FILE_MAX_SUBTAPS : (int)n;
}

/* c[i]: texel i's centre in source pixel units (edges at integers), NAN when outside. */
static void axis_build(struct axis *a, const double *c, uint32_t T, double r, int size, bool wrap)
{
	int n = a->n, K = a->K;
	int64_t lo = INT64_MAX, hi = INT64_MIN;
	a->any = false;
	a->all = true;
	for (uint32_t i = 0; i < T; i++) {
		int32_t *ix = a->idx + (size_t)i * K;
		float *w = a->w + (size_t)i * K;
		a->in[i] = !isnan(c[i]);
		if (!a->in[i]) {
			a->all = false;
			continue;
		}
		for (int t = 0; t < n; t++) {
			double s = c[i] + ((t + 0.5) / n - 0.5) * r - 0.5;
			double fl = floor(s), fr = s - fl;
			if (fr < 1e-6) {
				fr = 0;
			} else if (fr > 1 - 1e-6) {
				fl += 1;
				fr = 0;
			}
			int64_t i0 = (int64_t)fl, i1 = fr > 0 ? i0 + 1 : i0;
			if (!wrap) {
				i0 = i0 < 0 ? 0 : i0 >= size ? size - 1 : i0;
				i1 = i1 < 0 ? 0 : i1 >= size ? size - 1 : i1;
			}
			ix[2 * t] = (int32_t)i0;
			ix[2 * t + 1] = (int32_t)i1;
			w[2 * t] = (float)((1 - fr) / n);
			w[2 * t + 1] = (float)(fr / n);
			lo = i0 < lo ? i0 : lo;
			hi = i1 + 1 > hi ? i1 + 1 : hi;
		}
		a->any = true;
	}
	if (!a->any)
		lo = hi = 0;
	for (uint32_t i = 0; i < T; i++) {
		for (int k = 0; k < K; k++) {
			size_t q = (size_t)i * K + k;
			if (a->in[i]) {
				a->idx[q] = (int32_t)(a->idx[q] - lo);
			} else {
				a->idx[q] = 0;
				a->w[q] = 0;
			}
		}
	}
	a->lo = lo;
	a->hi = hi;
}

/* Texel column i's centre in pixel units of a level wm wide (NAN: outside the bounds). With
 * wrapping, coordinates run on from texel 0's (base = its offset east of the west bound) past
 * the image's east edge: read_region wraps them. */
static double col_coord(const struct file_impl *f, const struct geo_rect *r, double dlon, int wm,
			double base, uint32_t i)
{
	double span = f->east - f->west;
	if (f->wrap)
		return (base + (i + 0.5) * dlon) * (wm / span);
	double d = fmod(r->west + (i + 0.5) * dlon - f->west, 360.0);
	if (d < 0)
		d += 360.0;
	return d <= span ? d * (wm / span) : NAN;
}

/* Whether texels map 1:1 onto source pixels along an axis: spacing exactly one pixel, texel
 * 0's centre on a pixel centre, all T texels inside [0, size) (or wrapping). *lo = the pixel
 * under texel 0 (unwrapped). */
static bool aligned_axis(double c0, double r, uint32_t T, int size, bool wrap, int64_t *lo)
{
	if (isnan(c0) || fabs(r - 1) > 1e-9)
		return false;
	double s0 = c0 - 0.5, i0 = nearbyint(s0);
	if (fabs(s0 - i0) > 1e-6)
		return false;
	if (!wrap && (i0 < 0 || i0 + T > size))
		return false;
	*lo = (int64_t)i0;
	return true;
}

static int pick_level(const struct file_impl *f, double dlon, double dlat)
{
	double rx = dlon * f->lw[0] / (f->east - f->west);
	double ry = dlat * f->lh[0] / (f->north - f->south);
	double rmin = rx < ry ? rx : ry, rmax = rx > ry ? rx : ry;
	int m = rmin > 1 ? (int)floor(log2(rmin) + 1e-9) : 0;
	while (m + 1 < f->nlev && rmax / ldexp(1, m) > FILE_MAX_SUBTAPS)
		m++;
	return m < f->nlev ? m : f->nlev - 1;
}

/* Reads source rows [ay->lo, ay->hi) × columns [ax->lo, ax->hi) (wrapping x modulo the
 * level width) into dst, rows `stride` bytes apart. */
static int read_region(const struct file_impl *f, int m, const struct axis *ax,
		       const struct axis *ay, void *dst, size_t stride)
{
	int64_t wm = f->lw[m];
	size_t px = img_type_bytes(f->rtype) * (size_t)f->nch;
	for (int64_t c = ax->lo; c < ax->hi;) {
		int64_t s = c % wm;
		if (s < 0)
			s += wm;
		int64_t len = ax->hi - c < wm - s ? ax->hi - c : wm - s;
		int rc = img_cache_read(f->cache, f->path, m, (int)s, (int)(s + len), (int)ay->lo,
					(int)ay->hi, f->channel, f->channel + f->nch, f->rtype,
					(char *)dst + (size_t)(c - ax->lo) * px, stride, NULL);
		if (rc)
			return rc;
		c += len;
	}
	return 0;
}

/* Raw samples → float, with nodata/NaN → value 0, mask 0. Returns whether any sample was
 * missing (mask is only written when the source can have missing samples: mask != NULL). */
static bool to_float(const struct file_impl *f, const void *raw, float *dst, float *mask, size_t n)
{
	bool missing = false;
	switch (f->rtype) {
	case IMG_U8: {
		const uint8_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_U16: {
		const uint16_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_I16: {
		const int16_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_F32:
		if (dst != raw)
			memcpy(dst, raw, n * sizeof *dst);
		break;
	default:
		break;
	}
	if (!mask)
		return false;
	bool nd = f->has_nodata;
	float v = f->nodata;
	for (size_t i = 0; i < n; i++) {
		bool bad = dst[i] != dst[i] || (nd && dst[i] == v);
		mask[i] = bad ? 0.0f : 1.0f;
		dst[i] = bad ? 0.0f : dst[i];
		missing |= bad;
	}
	return missing;
}

/* Explicit 4-wide vectors (GCC/clang vector extensions, SSE2 baseline): gcc -O2 leaves
 * these loops scalar (its very-cheap cost model will not add an epilogue). */
typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));
typedef uint16_t v4u16 __attribute__((vector_size(8)));

static inline v4f ld4(const float *p)
{
	v4f v;
	memcpy(&v, p, sizeof v);
	return v;
}

static inline void st4(float *p, v4f v)
{
	memcpy(p, &v, sizeof v);
}

static bool has_nan(const float *v, size_t n)
{
	/* Four independent accumulators: one would make a loop-carried chain. */
	v4i a0 = { 0, 0, 0, 0 }, a1 = a0, a2 = a0, a3 = a0;
	size_t i = 0;
	for (; i + 16 <= n; i += 16) {
		v4f x0 = ld4(v + i), x1 = ld4(v + i + 4), x2 = ld4(v + i + 8), x3 = ld4(v + i + 12);
		a0 |= x0 != x0;
		a1 |= x1 != x1;
		a2 |= x2 != x2;
		a3 |= x3 != x3;
	}
	v4i acc = (a0 | a1) | (a2 | a3);
	bool any = (acc[0] | acc[1] | acc[2] | acc[3]) != 0;
	for (; i < n; i++)
		any |= v[i] != v[i];
	return any;
}

/* dst[i] = (Σ_q w[q]·src[q][i])·sc + off for i < n: the vertical pass. */
static void wsum(float *dst, const float *const *src, const float *w, int K, size_t n, float sc,
		 float off)
{
	size_t i = 0;
	for (; i + 4 <= n; i += 4) {
		v4f acc = ld4(src[0] + i) * w[0];
		for (int q = 1; q < K; q++)
			acc += ld4(src[q] + i) * w[q];
		st4(dst + i, acc * sc + off);
	}
	for (; i < n; i++) {
		float acc = src[0][i] * w[0];
		for (int q = 1; q < K; q++)
			acc += src[q][i] * w[q];
		dst[i] = acc * sc + off;
	}
}

static uint8_t to_u8(float v)
{
	return v <= 0 ? 0 : v >= 255 ? 255 : (uint8_t)(v + 0.5f);
}

/* Writes C channels of colour (0–255 floats) as RGBA8. */
static void put_rgba(uint8_t *o, const float *v, int C)
{
	switch (C) {
	case 1:
		o[0] = o[1] = o[2] = to_u8(v[0]);
		o[3] = 255;
		break;
	case 2:
		o[0] = o[1] = o[2] = to_u8(v[0]);
		o[3] = to_u8(v[1]);
		break;
	case 3:
		o[0] = to_u8(v[0]), o[1] = to_u8(v[1]), o[2] = to_u8(v[2]);
		o[3] = 255;
		break;
	default:
		o[0] = to_u8(v[0]), o[1] = to_u8(v[1]), o[2] = to_u8(v[2]), o[3] = to_u8(v[3]);
		break;
	}
}

static void fill_tile(const struct file_impl *f, struct tile *out)
{
	size_t n = (size_t)out->size * out->size;
	if (f->kind == KIND_HEIGHT) {
		float *o = tile_f32(out);
		for (size_t i = 0; i < n; i++)
			o[i] = f->fill_h;
	} else {
		for (size_t i = 0; i < n; i++)
			memcpy(out->data + 4 * i, f->fill_c, 4);
	}
}

/* 1:1 aligned: texel (i, j) is source pixel (lo + i, lo + j); raw holds the region. */
static void copy_aligned(const struct file_impl *f, const void *raw, struct tile *out)
{
	uint32_t T = out->size;
	size_t n = (size_t)T * T;
	if (f->kind == KIND_COLOR) {
		const uint8_t *s = raw;
		int C = f->nch;
		float v[4];
		for (size_t i = 0; i < n; i++) {
			for (int c = 0; c < C; c++)
				v[c] = s[i * C + c];
			put_rgba(out->data + 4 * i, v, C);
		}
		return;
	}
	float *o = tile_f32(out);
	float sc = f->scale, off = f->offset, fill = f->fill_h;
	bool nd = f->has_nodata;
	float ndv = f->nodata;
	if (f->rtype == IMG_U16 && !nd) {
		const uint16_t *s = raw;
		size_t i = 0;
		for (; i + 4 <= n; i += 4) {
			v4u16 u;
			memcpy(&u, s + i, sizeof u);
			st4(o + i, __builtin_convertvector(u, v4f) * sc + off);
		}
		for (; i < n; i++)
			o[i] = (float)s[i] * sc + off;
		return;
	}
	if (f->rtype == IMG_F32 && raw == (const void *)o && !nd) {
		if (sc != 1 || off != 0)
			for (size_t i = 0; i < n; i++)
				o[i] = o[i] * sc + off;
		if (has_nan(o, n))
			for (size_t i = 0; i < n; i++)
				o[i] = o[i] != o[i] ? fill : o[i];
		return;
	}
	for (size_t i = 0; i < n; i++) {
		float v;
		switch (f->rtype) {
		case IMG_U8:
			v = ((const uint8_t *)raw)[i];
			break;
		case IMG_U16:
			v = ((const uint16_t *)raw)[i];
			break;
		case IMG_I16:
			v = ((const int16_t *)raw)[i];
			break;
		default:
			v = ((const float *)raw)[i];
			break;
		}
		bool bad = v != v || (nd && v == ndv);
		o[i] = bad ? fill : v * sc + off;
	}
}

/* The horizontal pass for one channel and plain bilinear taps (the common case): 4 source
 * rows per table entry fetched, so the gather's index and weight loads are shared. */
static void hpass_bilinear(const float *restrict sv, size_t bw, size_t bh,
			   const int32_t *restrict idx, const float *restrict w, uint32_t T,
			   float *restrict tmp)
{
	size_t y = 0;
	for (; y + 4 <= bh; y += 4) {
		const float *s0 = sv + y * bw, *s1 = s0 + bw, *s2 = s1 + bw, *s3 = s2 + bw;
		float *t0 = tmp + y * T, *t1 = t0 + T, *t2 = t1 + T, *t3 = t2 + T;
		for (uint32_t i = 0; i < T; i++) {
			int32_t a = idx[2 * i], b = idx[2 * i + 1];
			float wa = w[2 * i], wb = w[2 * i + 1];
			t0[i] = wa * s0[a] + wb * s0[b];
			t1[i] = wa * s1[a] + wb * s1[b];
			t2[i] = wa * s2[a] + wb * s2[b];
			t3[i] = wa * s3[a] + wb * s3[b];
		}
	}
	for (; y < bh; y++) {
		const float *s0 = sv + y * bw;
		float *t0 = tmp + y * T;
		for (uint32_t i = 0; i < T; i++)
			t0[i] = w[2 * i] * s0[idx[2 * i]] + w[2 * i + 1] * s0[idx[2 * i + 1]];
	}
}

static size_t align64(size_t n)
{
	return (n + 63) & ~(size_t)63;
}

static int file_generate(const struct node *nd, struct gen_ctx *g, const struct tile_key *k,
			 struct tile *const *in, int nin, struct tile *out)
{
	(void)in;
	(void)nin;
	const struct file_impl *f = nd->impl;
	uint32_t T = out->size;
	struct geo_rect r;
	grid_tile_rect(k, &r);
	double dlon = (r.east - r.west) / T, dlat = (r.north - r.south) / T;
	int m = pick_level(f, dlon, dlat);
	int wm = f->lw[m], hm = f->lh[m];
	double spanx = f->east - f->west, spany = f->north - f->south;
	double rx = dlon * wm / spanx, ry = dlat * hm / spany;
	struct axis ax = { .n = subtaps(rx) }, ay = { .n = subtaps(ry) };
	ax.K = 2 * ax.n;
	ay.K = 2 * ay.n;

	/* Upper bounds of the source region (see axis_build: span (T-1)·r + r + 2 taps). */
	size_t bwmax = (size_t)ceil(T * rx) + 4, bhmax = (size_t)ceil(T * ry) + 4;
	if (!f->wrap && bwmax > (size_t)wm)
		bwmax = (size_t)wm;
	if (bhmax > (size_t)hm)
		bhmax = (size_t)hm;
	if (bwmax * bhmax > FILE_MAX_REGION)
		return -EFBIG; /* only a file with a truncated MIP pyramid, at a very coarse level */
	int C = f->nch;
	bool maskable = f->has_nodata || f->rtype == IMG_F32;
	size_t tsz = img_type_bytes(f->rtype);
	size_t s_coord = align64(2 * (size_t)T * sizeof(double));
	size_t s_tabx = align64((size_t)T * ax.K * 8), s_taby = align64((size_t)T * ay.K * 8);
	size_t s_in = align64(2 * (size_t)T);
	size_t s_raw = align64(bwmax * bhmax * C * tsz);
	size_t s_src = align64(bwmax * bhmax * C * sizeof(float));
	size_t s_mask = maskable ? align64(bwmax * bhmax * sizeof(float)) : 0;
	size_t s_tmp = align64(bhmax * T * C * sizeof(float));
	size_t s_tmpm = maskable ? align64(bhmax * T * sizeof(float)) : 0;
	size_t s_row = align64((size_t)T * (C + 1) * sizeof(float));
	char *sp = gen_scratch(g, s_coord + s_tabx + s_taby + s_in + s_raw + s_src + s_mask +
					  s_tmp + s_tmpm + s_row);
	double *cx = (double *)(void *)sp, *cy = cx + T;
	sp += s_coord;
	ax.idx = (int32_t *)(void *)sp;
	ax.w = (float *)(void *)(sp + (size_t)T * ax.K * 4);
	sp += s_tabx;
	ay.idx = (int32_t *)(void *)sp;
	ay.w = (float *)(void *)(sp + (size_t)T * ay.K * 4);
	sp += s_taby;
	ax.in = (uint8_t *)sp;
	ay.in = ax.in + T;
	sp += s_in;
	void *raw = sp;
	sp += s_raw;
	float *src = (float *)(void *)sp;
	sp += s_src;
	float *mask = maskable ? (float *)(void *)sp : NULL;
	sp += s_mask;
	float *tmp = (float *)(void *)sp;
	sp += s_tmp;
	float *tmpm = maskable ? (float *)(void *)sp : NULL;
	sp += s_tmpm;
	float *row = (float *)(void *)sp;

	/* Texel centres in source pixel units: texel 0 first, the rest once the 1:1 test has
	 * failed. */
	double base = 0;
	if (f->wrap) {
		base = fmod(r.west - f->west, 360.0);
		if (base < 0)
			base += 360.0;
	}
	cx[0] = col_coord(f, &r, dlon, wm, base, 0);
	for (uint32_t j = 0; j < T; j++) {
		double lat = r.north - (j + 0.5) * dlat;
		cy[j] = lat >= f->south && lat <= f->north ? (f->north - lat) * (hm / spany) : NAN;
	}

	if (aligned_axis(cx[0], rx, T, wm, f->wrap, &ax.lo) &&
	    aligned_axis(cy[0], ry, T, hm, false, &ay.lo)) {
		/* 1:1 on a level: one read, no tables, no filtering; straight into the tile
		 * when there is nothing to convert. */
		ax.hi = ax.lo + T;
		ay.hi = ay.lo + T;
		bool direct = (f->kind == KIND_HEIGHT && f->rtype == IMG_F32 && !f->has_nodata) ||
			      (f->kind == KIND_COLOR && C == 4);
		void *dst = direct ? (void *)out->data : raw;
		if (read_region(f, m, &ax, &ay, dst, (size_t)T * C * tsz))
			return -EIO;
		if (!direct || f->kind == KIND_HEIGHT)
			copy_aligned(f, dst, out);
		return 0;
	}
	for (uint32_t i = 1; i < T; i++)
		cx[i] = col_coord(f, &r, dlon, wm, base, i);
	axis_build(&ax, cx, T, rx, wm, f->wrap);
	axis_build(&ay, cy, T, ry, hm, false);
	if (!ax.any || !ay.any) {
		fill_tile(f, out);
		return 0;
	}
	size_t bw = (size_t)(ax.hi - ax.lo), bh = (size_t)(ay.hi - ay.lo);
	if (bw > bwmax || bh > bhmax)
		return -EFAULT; /* a bound above is wrong: never read past the scratch */

	if (read_region(f, m, &ax, &ay, raw, bw * C * tsz))
		return -EIO;
	size_t nsrc = bw * bh * C;
	float *sv = f->rtype == IMG_F32 ? (float *)raw : src;
	bool missing = false;
	if (f->kind == KIND_HEIGHT) {
		bool check = f->has_nodata || has_nan(f->rtype == IMG_F32 ? (float *)raw : NULL,
						       f->rtype == IMG_F32 ? nsrc : 0);
		missing = to_float(f, raw, sv, check ? mask : NULL, nsrc);
	} else {
		to_float(f, raw, sv, NULL, nsrc);
	}

	/* Horizontal pass: every source row → T texel columns. */
	int Kx = ax.K, Ky = ay.K;
	size_t y0 = 0;
	if (C == 1 && Kx == 2 && !missing) {
		hpass_bilinear(sv, bw, bh, ax.idx, ax.w, T, tmp);
		y0 = bh;
	}
	for (size_t y = y0; y < bh; y++) {
		const float *s = sv + y * bw * C;
		float *t = tmp + y * T * C;
		if (C == 1 && Kx == 2) {
			for (uint32_t i = 0; i < T; i++) {
				const int32_t *ix = ax.idx + 2 * i;
				const float *w = ax.w + 2 * i;
				t[i] = w[0] * s[ix[0]] + w[1] * s[ix[1]];
			}
		} else {
			for (uint32_t i = 0; i < T; i++) {
				const int32_t *ix = ax.idx + (size_t)i * Kx;
				const float *w = ax.w + (size_t)i * Kx;
				for (int c = 0; c < C; c++) {
					float acc = 0;
					for (int q = 0; q < Kx; q++)
						acc += w[q] * s[(size_t)ix[q] * C + c];
					t[(size_t)i * C + c] = acc;
				}
			}
		}
		if (missing) {
			const float *ms = mask + y * bw;
			float *tm = tmpm + y * T;
			for (uint32_t i = 0; i < T; i++) {
				const int32_t *ix = ax.idx + (size_t)i * Kx;
				const float *w = ax.w + (size_t)i * Kx;
				float acc = 0;
				for (int q = 0; q < Kx; q++)
					acc += w[q] * ms[ix[q]];
				tm[i] = acc;
			}
		}
	}

	/* Vertical pass into the tile. */
	size_t TC = (size_t)T * C;
	float *rowm = row + TC;
	for (uint32_t j = 0; j < T; j++) {
		if (!ay.in[j]) {
			if (f->kind == KIND_HEIGHT) {
				float *o = tile_f32(out) + (size_t)j * T;
				for (uint32_t i = 0; i < T; i++)
					o[i] = f->fill_h;
			} else {
				for (uint32_t i = 0; i < T; i++)
					memcpy(out->data + ((size_t)j * T + i) * 4, f->fill_c, 4);
			}
			continue;
		}
		const int32_t *iy = ay.idx + (size_t)j * Ky;
		const float *wy = ay.w + (size_t)j * Ky;
		const float *rows[2 * FILE_MAX_SUBTAPS];
		for (int q = 0; q < Ky; q++)
			rows[q] = tmp + (size_t)iy[q] * TC;
		if (f->kind == KIND_HEIGHT && !missing) {
			/* Straight into the tile; columns outside the bounds patched after. */
			float *o = tile_f32(out) + (size_t)j * T;
			wsum(o, rows, wy, Ky, T, f->scale, f->offset);
			if (!ax.all)
				for (uint32_t i = 0; i < T; i++)
					o[i] = ax.in[i] ? o[i] : f->fill_h;
			continue;
		}
		wsum(row, rows, wy, Ky, TC, 1, 0);
		if (f->kind == KIND_COLOR) {
			uint8_t *o = out->data + (size_t)j * T * 4;
			for (uint32_t i = 0; i < T; i++) {
				if (ax.in[i])
					put_rgba(o + 4 * i, row + (size_t)i * C, C);
				else
					memcpy(o + 4 * i, f->fill_c, 4);
			}
			continue;
		}
		/* Heights with missing samples: renormalise by the valid weight. */
		const float *mrows[2 * FILE_MAX_SUBTAPS];
		for (int q = 0; q < Ky; q++)
			mrows[q] = tmpm + (size_t)iy[q] * T;
		wsum(rowm, mrows, wy, Ky, T, 1, 0);
		float *o = tile_f32(out) + (size_t)j * T;
		float sc = f->scale, off = f->offset, fill = f->fill_h;
		for (uint32_t i = 0; i < T; i++)
			o[i] = ax.in[i] && rowm[i] >= 0.5f ? row[i] / rowm[i] * sc + off : fill;
	}
	return 0;
}

const struct node_type node_type_file = {
	.name = "file",
	.doc = "an image file (OpenImageIO) resampled onto the grid: heights or colour",
	.version = 1,
	.slots = NULL,
	.nslots = 0,
	.create = file_create,
	.destroy = file_destroy,
	.deps = NULL,
	.generate = file_generate,
};
