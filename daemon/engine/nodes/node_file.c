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
 * pass into the tile. Filtering (seed 000 §4.3): with r = texel spacing / pixel spacing per
 * axis, the read uses MIP level m = floor(log2(min(rx, ry))) (the file's own levels or OIIO's
 * automip, each a 2×2 box of the one above): there the narrower axis is at most 2× finer than
 * the output and bilinear suffices. The wider axis (anisotropic levels, lx < ly + 1: texels
 * up to 2^20 times wider in longitude than tall) is averaged by n = ceil(r) bilinear sub-taps
 * spread across the texel (a box of bilinears) at that same level; m rises only when n would
 * pass FILE_MAX_SUBTAPS or the region FILE_REGION_BUDGET pixels.
 * Why the narrower axis decides: a MIP level is a box in both axes at once, so reading a
 * coarser one for the wide axis blurs the narrow one. That was the poles' bug: a polar tile
 * at (lx 0, ly 19) is 38 m of latitude but 1.4° of longitude per texel; choosing the level
 * until 8 taps covered the 17 ETOPO5 columns a texel spans read level 2, whose rows are
 * 0.33° (37 km) tall, so the texels next to the pole averaged rows 9..37 km from it and
 * varied by 68 m (230 m at the north pole) with longitude, against 0.003 m in the source
 * over those 38 m. Measuring in metres instead would not help: along a parallel a texel and
 * a source pixel both shrink by cos(latitude), so r in x is the same ratio on the ground as
 * in degrees; what differs near the pole is only that texels are very anisotropic, and an
 * anisotropic footprint needs an anisotropic filter (rows kept at the narrow axis's level,
 * many cheap taps across: the region is then few rows high). When the tile maps 1:1 onto
 * the pixels of a level, the read is a plain copy (straight into the tile for float heights
 * with scale 1, offset 0). Known limit of the floor() choice: for 1 < r < 2, content at the
 * source's Nyquist frequency still aliases (a 0/250 1-pixel checkerboard at r = 1.5 gives
 * texels of about 94..156 instead of 125); from r = 2 on it averages out.
 *
 * The poles. A global image's rows are areas (pixel-is-point grids like ETOPO5 aside, whose
 * edge rows are centred on the poles): the edge row's pixels are wedges meeting at the pole,
 * which therefore holds the row's mean. Between the last row centre short of a pole and the
 * pole (a polar cap) samples blend from that row to a plane through the pole (its first
 * harmonic) and the mean (pole_taps; the rows are read whole at the level in use). So the
 * texels nearest a pole do not depend on longitude, at every level, the viewer's pole (one
 * point, reached from every meridian) is one value, and no crease converges on it.
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
#define FILE_MAX_SUBTAPS 256
#define FILE_REGION_BUDGET ((size_t)1 << 22) /* source pixels a tile reads, unless... */
#define FILE_MAX_REGION ((size_t)1 << 26)    /* ...its level is the coarsest: then this */

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

/* Tap indices a latitude table holds for the virtual rows of the polar caps until axis_build
 * rebases them to the rows just after the buffer's: bh + (index - TAP_VIRTUAL). */
#define TAP_VIRTUAL INT32_MIN
enum { VROW_MEAN_N, VROW_MEAN_S, VROW_HARM_N, VROW_HARM_S, VROWS };

/* The per-axis resampling table: output texel i reads taps idx[i·K + k] (relative to the
 * buffer's first source pixel `lo`) with weights w[i·K + k], K = taps·n. */
struct axis {
	int n, K, taps;
	int32_t *idx;
	float *w;
	uint8_t *in; /* texel centre inside the bounds */
	int64_t lo, hi;	 /* source pixels the buffer holds (unwrapped when wrapping) */
	bool any, all; /* some / every texel inside */
	/* Latitude axis of a global image, the polar caps (pole_taps): in sample coordinates
	 * (row i's centre at i) the last row centre short of each pole and the pole (NAN: no
	 * cap in this tile's reach: clamp); whether some tap reads a cap's virtual rows. */
	double cap_n, cap_s, pole_n, pole_s;
	bool use_n, use_s;
};

static int subtaps(double r)
{
	if (r < 2)
		return 1;
	double n = ceil(r - 1e-9);
	return n > FILE_MAX_SUBTAPS ? FILE_MAX_SUBTAPS : (int)n;
}

/* Between the last row centre short of a pole (the cap row, at a distance ρ1 from the pole)
 * and the pole itself. The rows of a global plate-carrée image are areas: the edge row's
 * pixels are wedges that all meet at the pole, which has no longitude — its value P is the
 * edge row's mean (for a pixel-is-point grid like ETOPO5, whose edge row is centred on the
 * pole, the same). Clamping to the edge row instead made the texels next to the pole copy the
 * row's longitude variation into a point (radial streaks in colour, a pole of many heights);
 * a linear blend towards P (h = P + t·(R(λ) - P), t = ρ/ρ1) is a cone whose east slope
 * R'(λ)/ρ1 keeps every kink of the cap row R between its columns down to the pole: creases
 * converging on it. So the cap is P + t·R1(λ) + t²·(R(λ) - P - R1(λ)) with R1 the first
 * harmonic of R (the plane through the pole that best fits the row): a plane at the pole
 * (one slope, no creases: the kinks fade as t²), R exactly at the cap row, and exactly the
 * plane where R is one. In taps: the cap row with t², the mean row with 1 - t², the harmonic
 * row with t - t². Returns whether s is in a cap (taps filled). */
static bool pole_taps(struct axis *a, double s, int64_t t[3], double w[3])
{
	double u;
	if (!isnan(a->cap_s) && s > a->cap_s) {
		u = (s - a->cap_s) / (a->pole_s - a->cap_s);
		t[0] = (int64_t)a->cap_s;
		t[1] = TAP_VIRTUAL + VROW_MEAN_S, t[2] = TAP_VIRTUAL + VROW_HARM_S;
		a->use_s = true;
	} else if (!isnan(a->cap_n) && s < a->cap_n) {
		u = (a->cap_n - s) / (a->cap_n - a->pole_n);
		t[0] = (int64_t)a->cap_n;
		t[1] = TAP_VIRTUAL + VROW_MEAN_N, t[2] = TAP_VIRTUAL + VROW_HARM_N;
		a->use_n = true;
	} else {
		return false;
	}
	double r = 1 - (u < 1 ? u : 1); /* ρ/ρ1 */
	w[0] = r * r, w[1] = 1 - r * r, w[2] = r - r * r;
	return true;
}

/* The taps (a->taps of them: bilinear, and a third of weight 0 where caps are in reach) of a
 * sample at s (pixel i's centre at s = i). */
static void sample_taps(struct axis *a, double s, int size, bool wrap, int64_t t[3], double w[3])
{
	if (a->taps == 3 && pole_taps(a, s, t, w))
		return;
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
	t[0] = i0, t[1] = i1, t[2] = i0;
	w[0] = 1 - fr, w[1] = fr, w[2] = 0;
}

/* c[i]: texel i's centre in source pixel units (edges at integers), NAN when outside. */
static void axis_build(struct axis *a, const double *c, uint32_t T, double r, int size, bool wrap)
{
	int n = a->n, K = a->K, nt = a->taps;
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
			int64_t tp[3];
			double wt[3];
			sample_taps(a, c[i] + ((t + 0.5) / n - 0.5) * r - 0.5, size, wrap, tp, wt);
			for (int q = 0; q < nt; q++) {
				ix[nt * t + q] = (int32_t)tp[q];
				w[nt * t + q] = (float)(wt[q] / n);
				if (tp[q] >= TAP_VIRTUAL && tp[q] < TAP_VIRTUAL + VROWS)
					continue;
				lo = tp[q] < lo ? tp[q] : lo;
				hi = tp[q] + 1 > hi ? tp[q] + 1 : hi;
			}
		}
		a->any = true;
	}
	if (!a->any)
		lo = hi = 0;
	for (uint32_t i = 0; i < T; i++) {
		for (int k = 0; k < K; k++) {
			size_t q = (size_t)i * K + k;
			int32_t v = a->idx[q];
			if (!a->in[i]) {
				a->idx[q] = 0;
				a->w[q] = 0;
			} else if (v >= TAP_VIRTUAL && v < TAP_VIRTUAL + VROWS) {
				a->idx[q] = (int32_t)(hi - lo) + (v - TAP_VIRTUAL);
			} else {
				a->idx[q] = (int32_t)(v - lo);
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

/* The source region (columns × rows of level m) a tile with texel spacings rx × ry level-m
 * pixels may read: (T-1)·r + r + 2 taps per axis (see axis_build), within the level. */
static void region_bounds(const struct file_impl *f, int m, double rx, double ry, uint32_t T,
			  size_t *bw, size_t *bh)
{
	*bw = (size_t)ceil(T * rx) + 4;
	*bh = (size_t)ceil(T * ry) + 4;
	if (!f->wrap && *bw > (size_t)f->lw[m])
		*bw = (size_t)f->lw[m];
	if (*bh > (size_t)f->lh[m])
		*bh = (size_t)f->lh[m];
}

/* The MIP level a tile with texels dlon × dlat degrees reads: from the narrower axis (see
 * "Filtering" above), coarser only when the wider one would need more than FILE_MAX_SUBTAPS
 * taps or the region would exceed FILE_REGION_BUDGET pixels. */
static int pick_level(const struct file_impl *f, double dlon, double dlat, uint32_t T)
{
	double rx = dlon * f->lw[0] / (f->east - f->west);
	double ry = dlat * f->lh[0] / (f->north - f->south);
	double rmin = rx < ry ? rx : ry;
	int m = rmin > 1 ? (int)floor(log2(rmin) + 1e-9) : 0;
	m = m < f->nlev ? m : f->nlev - 1;
	for (; m + 1 < f->nlev; m++) {
		double rxm = rx * f->lw[m] / f->lw[0], rym = ry * f->lh[m] / f->lh[0];
		size_t bw, bh;
		region_bounds(f, m, rxm, rym, T, &bw, &bh);
		if ((rxm > rym ? rxm : rym) <= FILE_MAX_SUBTAPS && bw * bh <= FILE_REGION_BUDGET)
			break;
	}
	return m;
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

/* One tile's resampling: the level and tables, then the buffers (one gen_scratch block). */
struct file_gen {
	const struct file_impl *f;
	uint32_t T;
	int C;		 /* channels read */
	size_t tsz;	 /* bytes per raw sample */
	struct geo_rect r;
	double dlon, dlat; /* texel size, degrees */
	int m, wm, hm;	 /* the MIP level read and its size */
	double rx, ry;	 /* texel spacing in level-m pixels */
	struct axis ax, ay;
	size_t bwmax, bhmax; /* bounds of the region read */
	bool maskable;	     /* the source can have missing samples */
	double *cx, *cy;     /* texel centres, level-m pixel units */
	void *raw;	     /* the region as read */
	float *src, *mask;   /* ... as float (sv: src, or raw itself for float files) */
	float *tmp, *tmpm;   /* horizontal pass: bh rows + VROWS virtual rows of T texels */
	float *row;	     /* one output row (and its weights) */
	void *praw;	     /* one whole level-m row, for a pole's mean */
	float *pv, *pm;
	/* after gen_read */
	float *sv;
	size_t bw, bh;
	bool missing; /* some sample read is missing: masks are live */
};

/* The polar caps in this tile's reach (pole_taps): sample coordinates of each pole and of
 * the last row centre short of it (the edge row for area rows, the one before it when the
 * edge row is centred on the pole). With a cap, latitude taps come in threes. */
static void plan_caps(struct file_gen *q, double spany)
{
	const struct file_impl *f = q->f;
	struct axis *a = &q->ay;
	double k = q->hm / spany;
	double ps = (f->north + 90) * k - 0.5, pn = (f->north - 90) * k - 0.5;
	/* The samples the tile's texels take lie between its edges. */
	double smin = (f->north - q->r.north) * k - 0.5, smax = (f->north - q->r.south) * k - 0.5;
	double cs = ceil(ps - 1e-6) - 1, cn = floor(pn + 1e-6) + 1;
	if (f->south <= -90 && cs >= 0 && cs <= q->hm - 1 && smax > cs) {
		a->cap_s = cs;
		a->pole_s = ps;
	}
	if (f->north >= 90 && cn >= 0 && cn <= q->hm - 1 && smin < cn) {
		a->cap_n = cn;
		a->pole_n = pn;
	}
	if (!isnan(a->cap_s) || !isnan(a->cap_n))
		a->taps = 3;
}

/* The level, the per-axis tap counts and the region bounds. Returns 0 or -EFBIG. */
static int gen_plan(struct file_gen *q, const struct file_impl *f, const struct tile_key *k,
		    uint32_t T)
{
	q->f = f;
	q->T = T;
	q->C = f->nch;
	q->tsz = img_type_bytes(f->rtype);
	grid_tile_rect(k, &q->r);
	q->dlon = (q->r.east - q->r.west) / T;
	q->dlat = (q->r.north - q->r.south) / T;
	q->m = pick_level(f, q->dlon, q->dlat, T);
	q->wm = f->lw[q->m];
	q->hm = f->lh[q->m];
	double spanx = f->east - f->west, spany = f->north - f->south;
	q->rx = q->dlon * q->wm / spanx;
	q->ry = q->dlat * q->hm / spany;
	q->ax = (struct axis){ .n = subtaps(q->rx), .taps = 2, .cap_n = NAN, .cap_s = NAN };
	q->ay = (struct axis){ .n = subtaps(q->ry), .taps = 2, .cap_n = NAN, .cap_s = NAN };
	if (spanx == 360) /* exact: parse_bounds snaps near-360 spans */
		plan_caps(q, spany);
	q->ax.K = q->ax.taps * q->ax.n;
	q->ay.K = q->ay.taps * q->ay.n;
	region_bounds(f, q->m, q->rx, q->ry, T, &q->bwmax, &q->bhmax);
	if (q->bwmax * q->bhmax > FILE_MAX_REGION)
		return -EFBIG; /* only a file with a truncated MIP pyramid, at a very coarse level */
	q->maskable = f->has_nodata || f->rtype == IMG_F32;
	return 0;
}

/* Carves the buffers out of the worker's scratch. */
static void gen_buffers(struct file_gen *q, struct gen_ctx *g)
{
	size_t T = q->T, C = (size_t)q->C, bwh = q->bwmax * q->bhmax, wm = (size_t)q->wm;
	size_t rows = q->bhmax + VROWS;
	size_t s_coord = align64(2 * T * sizeof(double));
	size_t s_tabx = align64(T * q->ax.K * 8), s_taby = align64(T * q->ay.K * 8);
	size_t s_in = align64(2 * T);
	size_t s_raw = align64(bwh * C * q->tsz);
	size_t s_src = align64(bwh * C * sizeof(float));
	size_t s_mask = q->maskable ? align64(bwh * sizeof(float)) : 0;
	size_t s_tmp = align64(rows * T * C * sizeof(float));
	size_t s_tmpm = q->maskable ? align64(rows * T * sizeof(float)) : 0;
	size_t s_row = align64(T * (C + 1) * sizeof(float));
	size_t s_praw = align64(wm * C * q->tsz), s_pv = align64(wm * C * sizeof(float));
	size_t s_pm = q->maskable ? align64(wm * sizeof(float)) : 0;
	char *sp = gen_scratch(g, s_coord + s_tabx + s_taby + s_in + s_raw + s_src + s_mask +
					  s_tmp + s_tmpm + s_row + s_praw + s_pv + s_pm);
	q->cx = (double *)(void *)sp;
	q->cy = q->cx + T;
	sp += s_coord;
	q->ax.idx = (int32_t *)(void *)sp;
	q->ax.w = (float *)(void *)(sp + T * q->ax.K * 4);
	sp += s_tabx;
	q->ay.idx = (int32_t *)(void *)sp;
	q->ay.w = (float *)(void *)(sp + T * q->ay.K * 4);
	sp += s_taby;
	q->ax.in = (uint8_t *)sp;
	q->ay.in = q->ax.in + T;
	sp += s_in;
	q->raw = sp;
	sp += s_raw;
	q->src = (float *)(void *)sp;
	sp += s_src;
	q->mask = q->maskable ? (float *)(void *)sp : NULL;
	sp += s_mask;
	q->tmp = (float *)(void *)sp;
	sp += s_tmp;
	q->tmpm = q->maskable ? (float *)(void *)sp : NULL;
	sp += s_tmpm;
	q->row = (float *)(void *)sp;
	sp += s_row;
	q->praw = sp;
	sp += s_praw;
	q->pv = (float *)(void *)sp;
	sp += s_pv;
	q->pm = q->maskable ? (float *)(void *)sp : NULL;
}

/* Texel centres in level-m pixel units: rows all, columns texel 0's only (the rest once the
 * 1:1 test has failed). Returns texel column coordinates' base for col_coord. */
static double gen_coords(struct file_gen *q)
{
	const struct file_impl *f = q->f;
	double base = 0, spany = f->north - f->south;
	if (f->wrap) {
		base = fmod(q->r.west - f->west, 360.0);
		if (base < 0)
			base += 360.0;
	}
	q->cx[0] = col_coord(f, &q->r, q->dlon, q->wm, base, 0);
	for (uint32_t j = 0; j < q->T; j++) {
		double lat = q->r.north - (j + 0.5) * q->dlat;
		q->cy[j] = lat >= f->south && lat <= f->north ? (f->north - lat) * (q->hm / spany)
							      : NAN;
	}
	return base;
}

/* Whether the tile maps 1:1 onto the pixels of level m; then reads it so: one read, no
 * tables, no filtering, straight into the tile when there is nothing to convert. *rc: 0 or
 * -EIO. */
static bool gen_aligned(struct file_gen *q, struct tile *out, int *rc)
{
	const struct file_impl *f = q->f;
	uint32_t T = q->T;
	struct axis *ax = &q->ax, *ay = &q->ay;
	if (!aligned_axis(q->cx[0], q->rx, T, q->wm, f->wrap, &ax->lo) ||
	    !aligned_axis(q->cy[0], q->ry, T, q->hm, false, &ay->lo))
		return false;
	ax->hi = ax->lo + T;
	ay->hi = ay->lo + T;
	bool direct = (f->kind == KIND_HEIGHT && f->rtype == IMG_F32 && !f->has_nodata) ||
		      (f->kind == KIND_COLOR && q->C == 4);
	void *dst = direct ? (void *)out->data : q->raw;
	*rc = 0;
	if (read_region(f, q->m, ax, ay, dst, (size_t)T * q->C * q->tsz))
		*rc = -EIO;
	else if (!direct || f->kind == KIND_HEIGHT)
		copy_aligned(f, dst, out);
	return true;
}

/* Reads level m's row y whole as float (q->pv; masks in q->pm). Returns whether a sample
 * was missing, or -EIO. */
static int read_row(struct file_gen *q, int64_t y, float **v)
{
	const struct file_impl *f = q->f;
	struct axis cols = { .lo = 0, .hi = q->wm }, rows = { .lo = y, .hi = y + 1 };
	size_t wm = (size_t)q->wm;
	if (read_region(f, q->m, &cols, &rows, q->praw, 0))
		return -EIO;
	*v = f->rtype == IMG_F32 ? (float *)q->praw : q->pv;
	if (f->kind != KIND_HEIGHT) {
		to_float(f, q->praw, *v, NULL, wm * q->C);
		return 0;
	}
	return to_float(f, q->praw, *v, q->pm, wm);
}

/* A cap's virtual rows (pole_taps) in the horizontal pass's rows `mean` and `harm` (T texels
 * each; with masks, like every row of a pass with masks: valid sum / width, and the valid
 * share in meanm, harmm): the edge row's mean, and the first harmonic of the cap row at each
 * texel's longitude (none where the cap row misses samples). Returns whether a sample was
 * missing, or -EIO. */
static int cap_rows(struct file_gen *q, int64_t edge, int64_t cap, float *mean, float *meanm,
		    float *harm, float *harmm)
{
	const struct file_impl *f = q->f;
	size_t wm = (size_t)q->wm, C = (size_t)q->C;
	float *v;
	int missing = read_row(q, edge, &v);
	if (missing < 0)
		return missing;
	double sum[4] = { 0, 0, 0, 0 }, valid = 0;
	for (size_t i = 0; i < wm; i++) {
		for (size_t c = 0; c < C; c++)
			sum[c] += v[i * C + c];
		valid += missing ? q->pm[i] : 1;
	}
	for (uint32_t i = 0; i < q->T; i++)
		for (size_t c = 0; c < C; c++)
			mean[i * C + c] = (float)(sum[c] / wm);
	if (cap != edge) {
		int rc = read_row(q, cap, &v);
		if (rc < 0)
			return rc;
		missing |= rc;
	}
	double ca[4] = { 0, 0, 0, 0 }, sa[4] = { 0, 0, 0, 0 };
	for (size_t i = 0; i < wm && !missing; i++) {
		double lam = (f->west + (i + 0.5) * 360.0 / wm) * (M_PI / 180);
		double cl = cos(lam), sl = sin(lam);
		for (size_t c = 0; c < C; c++)
			ca[c] += v[i * C + c] * cl, sa[c] += v[i * C + c] * sl;
	}
	for (uint32_t i = 0; i < q->T; i++) {
		double lam = (q->r.west + (i + 0.5) * q->dlon) * (M_PI / 180);
		double cl = cos(lam), sl = sin(lam);
		for (size_t c = 0; c < C; c++)
			harm[i * C + c] = (float)(2 * (ca[c] * cl + sa[c] * sl) / wm);
	}
	if (meanm)
		for (uint32_t i = 0; i < q->T; i++)
			meanm[i] = (float)(valid / wm), harmm[i] = 0;
	return missing;
}

/* Reads the region the tables reach (and the pole rows they blend into) as float samples;
 * q->missing tells whether masks are live. Returns 0 or -EIO / -EFAULT. */
static int gen_read(struct file_gen *q)
{
	const struct file_impl *f = q->f;
	q->bw = (size_t)(q->ax.hi - q->ax.lo);
	q->bh = (size_t)(q->ay.hi - q->ay.lo);
	if (q->bw > q->bwmax || q->bh > q->bhmax)
		return -EFAULT; /* a bound above is wrong: never read past the scratch */
	if (read_region(f, q->m, &q->ax, &q->ay, q->raw, q->bw * q->C * q->tsz))
		return -EIO;
	size_t nsrc = q->bw * q->bh * q->C;
	q->sv = f->rtype == IMG_F32 ? (float *)q->raw : q->src;
	q->missing = false;
	if (f->kind == KIND_HEIGHT) {
		bool check = f->has_nodata || has_nan(f->rtype == IMG_F32 ? (float *)q->raw : NULL,
						       f->rtype == IMG_F32 ? nsrc : 0);
		q->missing = to_float(f, q->raw, q->sv, check ? q->mask : NULL, nsrc);
	} else {
		to_float(f, q->raw, q->sv, NULL, nsrc);
	}
	/* The caps' virtual rows after the region's bh rows of the horizontal pass. */
	size_t TC = (size_t)q->T * q->C, T = q->T;
	bool pole_missing = false;
	for (int p = 0; p < 2; p++) {
		if (!(p ? q->ay.use_s : q->ay.use_n))
			continue;
		size_t mr = q->bh + (p ? VROW_MEAN_S : VROW_MEAN_N);
		size_t hr = q->bh + (p ? VROW_HARM_S : VROW_HARM_N);
		int rc = cap_rows(q, p ? q->hm - 1 : 0, (int64_t)(p ? q->ay.cap_s : q->ay.cap_n),
				  q->tmp + mr * TC, q->tmpm ? q->tmpm + mr * T : NULL,
				  q->tmp + hr * TC, q->tmpm ? q->tmpm + hr * T : NULL);
		if (rc < 0)
			return rc;
		pole_missing |= rc > 0;
	}
	if (pole_missing && !q->missing) {
		for (size_t i = 0; i < q->bw * q->bh; i++)
			q->mask[i] = 1; /* the region had nothing missing */
		q->missing = true;
	}
	return 0;
}

/* Horizontal pass: every source row of the region → T texel columns (and their valid
 * weights when masks are live). */
static void gen_hpass(struct file_gen *q)
{
	uint32_t T = q->T;
	int C = q->C, Kx = q->ax.K;
	const int32_t *idx = q->ax.idx;
	const float *wx = q->ax.w;
	size_t bw = q->bw, bh = q->bh, y0 = 0;
	if (C == 1 && Kx == 2 && !q->missing) {
		hpass_bilinear(q->sv, bw, bh, idx, wx, T, q->tmp);
		y0 = bh;
	}
	for (size_t y = y0; y < bh; y++) {
		const float *s = q->sv + y * bw * C;
		float *t = q->tmp + y * T * C;
		for (uint32_t i = 0; i < T; i++) {
			const int32_t *ix = idx + (size_t)i * Kx;
			const float *w = wx + (size_t)i * Kx;
			for (int c = 0; c < C; c++) {
				float acc = 0;
				for (int k = 0; k < Kx; k++)
					acc += w[k] * s[(size_t)ix[k] * C + c];
				t[(size_t)i * C + c] = acc;
			}
		}
		if (q->missing) {
			const float *ms = q->mask + y * bw;
			float *tm = q->tmpm + y * T;
			for (uint32_t i = 0; i < T; i++) {
				const int32_t *ix = idx + (size_t)i * Kx;
				const float *w = wx + (size_t)i * Kx;
				float acc = 0;
				for (int k = 0; k < Kx; k++)
					acc += w[k] * ms[ix[k]];
				tm[i] = acc;
			}
		}
	}
}

/* Output row j, all texels the fill. */
static void fill_row(const struct file_impl *f, struct tile *out, uint32_t j)
{
	uint32_t T = out->size;
	if (f->kind == KIND_HEIGHT) {
		float *o = tile_f32(out) + (size_t)j * T;
		for (uint32_t i = 0; i < T; i++)
			o[i] = f->fill_h;
	} else {
		for (uint32_t i = 0; i < T; i++)
			memcpy(out->data + ((size_t)j * T + i) * 4, f->fill_c, 4);
	}
}

/* Vertical pass: the horizontal pass's rows → the tile; heights with missing samples
 * renormalised by their valid weight. */
static void gen_vpass(const struct file_gen *q, struct tile *out)
{
	const struct file_impl *f = q->f;
	uint32_t T = q->T;
	int C = q->C, Ky = q->ay.K;
	size_t TC = (size_t)T * C;
	float *row = q->row, *rowm = q->row + TC;
	for (uint32_t j = 0; j < T; j++) {
		if (!q->ay.in[j]) {
			fill_row(f, out, j);
			continue;
		}
		const int32_t *iy = q->ay.idx + (size_t)j * Ky;
		const float *wy = q->ay.w + (size_t)j * Ky;
		const float *rows[3 * FILE_MAX_SUBTAPS];
		for (int k = 0; k < Ky; k++)
			rows[k] = q->tmp + (size_t)iy[k] * TC;
		if (f->kind == KIND_HEIGHT && !q->missing) {
			/* Straight into the tile; columns outside the bounds patched after. */
			float *o = tile_f32(out) + (size_t)j * T;
			wsum(o, rows, wy, Ky, T, f->scale, f->offset);
			if (!q->ax.all)
				for (uint32_t i = 0; i < T; i++)
					o[i] = q->ax.in[i] ? o[i] : f->fill_h;
			continue;
		}
		wsum(row, rows, wy, Ky, TC, 1, 0);
		if (f->kind == KIND_COLOR) {
			uint8_t *o = out->data + (size_t)j * T * 4;
			for (uint32_t i = 0; i < T; i++) {
				if (q->ax.in[i])
					put_rgba(o + 4 * i, row + (size_t)i * C, C);
				else
					memcpy(o + 4 * i, f->fill_c, 4);
			}
			continue;
		}
		const float *mrows[3 * FILE_MAX_SUBTAPS];
		for (int k = 0; k < Ky; k++)
			mrows[k] = q->tmpm + (size_t)iy[k] * T;
		wsum(rowm, mrows, wy, Ky, T, 1, 0);
		float *o = tile_f32(out) + (size_t)j * T;
		float sc = f->scale, off = f->offset, fill = f->fill_h;
		for (uint32_t i = 0; i < T; i++)
			o[i] = q->ax.in[i] && rowm[i] >= 0.5f ? row[i] / rowm[i] * sc + off : fill;
	}
}

static int file_generate(const struct node *nd, struct gen_ctx *g, const struct tile_key *k,
			 struct tile *const *in, int nin, struct tile *out)
{
	(void)in;
	(void)nin;
	struct file_gen q;
	int rc = gen_plan(&q, nd->impl, k, out->size);
	if (rc)
		return rc;
	gen_buffers(&q, g);
	double base = gen_coords(&q);
	if (gen_aligned(&q, out, &rc))
		return rc;
	for (uint32_t i = 1; i < q.T; i++)
		q.cx[i] = col_coord(q.f, &q.r, q.dlon, q.wm, base, i);
	axis_build(&q.ax, q.cx, q.T, q.rx, q.wm, q.f->wrap);
	axis_build(&q.ay, q.cy, q.T, q.ry, q.hm, false);
	if (!q.ax.any || !q.ay.any) {
		fill_tile(q.f, out);
		return 0;
	}
	if ((rc = gen_read(&q)))
		return rc;
	gen_hpass(&q);
	gen_vpass(&q, out);
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
