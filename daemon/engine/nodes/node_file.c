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
 *   bounds    W,S,E,N in degrees covered by the image (default: the file's own georeferencing
 *             (GeoTIFF tags, read with libtiff), else the bounds `clipmapctl import` recorded in
 *             it; a file with none of these and no key is refused, a key contradicting the
 *             georeferencing too: nothing is guessed). Row 0 is the north edge, column 0
 *             the west edge; pixels are areas with centres at +0.5. S and N may reach half
 *             a pixel past the poles (pixel-is-point grids with rows centred on the poles).
 *   channel   (height) the channel holding heights (default 0)
 *   scale, offset  (height) height = raw·scale + offset; raw is the stored value, integers
 *             unnormalised (int16 metres: scale 1; uint16 in 0.1 m: scale 0.1)
 *   nodata    (height) a raw value meaning "no data" (default: one recorded by import, else the
 *             file's own GDAL_NODATA); NaN in float files always is
 *   fill      height in metres (default 0) or colour (default 0,0,0,0) outside the bounds and
 *             where data is missing
 *   lon_wrap  true | false: bilinear wraps across the east/west edges (default true when the
 *             bounds span 360°; only allowed then)
 *   magnify   (height) cubic | bspline: heights finer than the data are Catmull-Rom
 *             (`cubic`, the default: passes through every sample) or a cubic B-spline
 *             (`bspline`: smooth, not through the samples; a 0/1 mask's ½ contour then
 *             follows a coast instead of the pixels' staircase: file_plan.c)
 *   isotropic true | false: east–west detail no finer on the ground than the rows are apart
 *             (default true: global products near the poles; file_resample.h); false keeps
 *             every column (a regional survey whose columns are genuine)
 *   cache_mb  deprecated and ignored (still checked: 1..1048576): the image cache is the
 *             planet's, sized by clipmapd's [engine] image_cache_mb. Not hashed.
 * Checked at load: the file reads to its end (img_check_readable: a truncated file is refused
 * naming it and the level), and its channels fit the kind (kind = height refuses 3+ channels
 * unless `channel` is given; kind = color wants 8-bit, or 16-bit RGB[A]), and a height file
 * with nodata has MIP levels of its own (or a huge float nodata: file_resample.c), since
 * OIIO's automip would average nodata into heights.
 * The file's bytes are hashed (file_digest.h: a digest, kept beside files of 64 MiB or more):
 * identical copies at other paths or on other machines name the same tiles (a fleet shares
 * them), a changed file gets new tile names after a reload, and the shared cache forgets the
 * old file's pixels (img_cache_set_version, keyed by size, mtime and inode).
 * How tiles are made (the MIP level, anisotropic taps, the polar caps, missing data):
 * file_resample.h.
 */
#include "engine/node_types.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "common/img.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/planet.h"

#include "file_digest.h"
#include "file_resample.h"

static const char *const kind_names[] = { "height", "color", NULL };
/* Index parity is the value. */
static const char *const bool_names[] = { "false", "true", "no", "yes", "0", "1", NULL };

static void file_destroy(struct node *nd)
{
	struct file_source *f = nd->impl;
	if (!f)
		return;
	img_cache_unref(f->own_cache);
	if (f->poles) {
		xmutex_destroy(&f->poles->mu);
		free(f->poles);
	}
	free(f->path);
	free(f);
	nd->impl = NULL;
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
static int file_desc(struct file_source *f, double b[4], double *nodata)
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

/* Why a file without a `bounds` key cannot be placed: the message for np_error. */
static int no_bounds(struct node_parse *p, const struct file_source *f, const struct img_georef *g)
{
	if (g->projected)
		return np_error(p, "bounds", "missing, and %s is in a projected coordinate system "
				"(%s), not degrees: reproject it with `clipmapctl import %s -o OUT.tif`",
				f->path, g->crs, f->path);
	if (g->rotated)
		return np_error(p, "bounds", "missing, and %s has rotated, sheared or flipped "
				"georeferencing: turn it north-up with `clipmapctl import`", f->path);
	if (g->no_crs)
		return np_error(p, "bounds", "missing, and %s has a geotransform but no coordinate "
				"system: add bounds = W,S,E,N (degrees)", f->path);
	return np_error(p, "bounds", "missing, and %s has no georeferencing (no GeoTIFF tags, no "
			"bounds recorded by clipmapctl import): add bounds = W,S,E,N (degrees)",
			f->path);
}

/* The bounds: the `bounds` key, else the file's own georeferencing (GeoTIFF), else what
 * clipmapctl import recorded; never guessed. A key contradicting the file's georeferencing
 * by more than half a pixel is refused (one of them is wrong). */
static int parse_bounds(struct node_parse *p, struct file_source *f, const struct img_georef *g)
{
	double b[4], nd;
	int nb, rc = np_doubles(p, "bounds", b, 4, &nb);
	if (rc)
		return rc;
	if (nb == 0) {
		if (g->georeferenced)
			b[0] = g->west, b[1] = g->south, b[2] = g->east, b[3] = g->north;
		else if (!(file_desc(f, b, &nd) & 1))
			return no_bounds(p, f, g);
	} else if (nb != 4) {
		return np_error(p, "bounds", "expected 4 numbers W,S,E,N (degrees), got %d", nb);
	} else if (g->projected || g->rotated) {
		/* Degrees cannot place a projected grid: it would be stretched, not warped. */
		return np_error(p, "bounds", "%s is %s (%s): bounds cannot place it; reproject it "
				"with `clipmapctl import`", f->path,
				g->projected ? "in a projected coordinate system" : "rotated or flipped",
				g->crs[0] ? g->crs : "?");
	} else if (g->georeferenced) {
		double tx = 0.5 * (g->east - g->west) / f->info.width;
		double ty = 0.5 * (g->north - g->south) / f->info.height;
		if (fabs(b[0] - g->west) > tx || fabs(b[2] - g->east) > tx ||
		    fabs(b[1] - g->south) > ty || fabs(b[3] - g->north) > ty)
			return np_error(p, "bounds", "%g,%g,%g,%g contradicts the georeferencing of "
					"%s (%.10g,%.10g,%.10g,%.10g): remove the key", b[0], b[1],
					b[2], b[3], f->path, g->west, g->south, g->east, g->north);
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

static int parse_height(struct node_parse *p, struct file_source *f, const struct img_georef *g)
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
	if (ini_find(p->sec, "nodata")) { /* any float: GDAL's -1e34 and -3.4028235e38 too */
		if ((rc = np_double(p, "nodata", 0, -FLT_MAX, FLT_MAX, &v)))
			return rc;
		f->has_nodata = true;
		f->nodata = (float)v;
	} else if (file_desc(f, b, &fnd) & 2) {
		f->has_nodata = true; /* recorded by clipmapctl import; the file is hashed */
		f->nodata = (float)fnd;
	} else if (g->has_nodata && !isnan(g->nodata)) {
		f->has_nodata = true; /* the file's own (GDAL_NODATA); the file is hashed */
		f->nodata = (float)g->nodata;
	}
	if ((rc = np_double(p, "fill", 0, -1e30, 1e30, &v)))
		return rc;
	f->fill_h = (float)v;
	if (ini_find(p->sec, "magnify")) { /* hashed only when given: older hashes stand */
		static const char *const magnify_names[] = { "cubic", "bspline", NULL };
		int m;
		if ((rc = np_enum(p, "magnify", magnify_names, 0, &m)))
			return rc;
		f->bspline = m == 1;
	}
	return 0;
}

static int parse_color(struct node_parse *p, struct file_source *f)
{
	static const char *const only_h[] = { "channel", "scale", "offset", "nodata", "magnify" };
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

/* The file's channels and samples must fit the node's kind: a colour image used as heights
 * (or heights as colour) is a mistake in the planet file, refused naming both. */
static int check_kind(struct node_parse *p, const struct node *nd, const struct file_source *f)
{
	const struct img_info *in = &f->info;
	if (f->kind == FILE_KIND_HEIGHT) {
		/* Several channels: colour, unless `channel` says which one holds heights. */
		if (in->channels >= 3 && !ini_find(p->sec, "channel"))
			return np_error(p, "kind", "node %s: %s has %d %s channels (a colour image?); "
					"kind = height expects one channel of heights (or name it "
					"with channel = N)", nd->name, f->path, in->channels,
					in->format);
		return 0;
	}
	bool ok = in->type == IMG_U8 || (in->type == IMG_U16 && in->channels >= 3);
	if (!ok || in->channels > 4)
		return np_error(p, "kind", "node %s: %s has %d %s channel%s (heights?); kind = color "
				"expects 8-bit grey, grey+alpha, RGB or RGBA (or 16-bit RGB[A])",
				nd->name, f->path, in->channels, in->format,
				in->channels == 1 ? "" : "s");
	return 0;
}

static int file_create(struct node *nd, struct node_parse *p)
{
	struct file_source *f = xcalloc(1, sizeof *f);
	nd->impl = f; /* node_init calls destroy on failure */
	f->poles = xcalloc(1, sizeof *f->poles);
	xmutex_init(&f->poles->mu);
	/* Not np_string: the hash takes the resolved path, so "a.tif" and "/dir/a.tif" name
	 * the same tiles. */
	struct ini_entry *pe = ini_find(p->sec, "path");
	const char *path = pe ? pe->value : NULL;
	int rc;
	if (pe)
		pe->used = true;
	if (!path || !path[0])
		return np_error(p, "path", "missing: the image file to read");
	f->path = planet_resolve_path(nd->planet, path);
	struct stat st;
	if (stat(f->path, &st) != 0)
		return np_error(p, "path", "cannot open %s: %s", f->path, strerror(errno));
	/* The inode too: a file replaced by rename (img_write, clipmapctl import) within the
	 * file system's timestamp granularity still counts as changed. */
	int64_t stamp[4] = { (int64_t)st.st_size, (int64_t)st.st_mtim.tv_sec,
			     (int64_t)st.st_mtim.tv_nsec, (int64_t)st.st_ino };
	/* The hash names the data, not where it lies: identical copies (other paths, inodes,
	 * mtimes: another machine of a fleet) share tiles; any changed byte gives new names. */
	uint8_t digest[16];
	char derr[256];
	if ((rc = file_digest(f->path, &st, FILE_DIGEST_CACHE_MIN, digest, derr)))
		return np_error(p, "path", "%s", derr);
	np_hash_bytes(p, "data", 5);
	np_hash_bytes(p, digest, sizeof digest);

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

	/* Readable to the end: a truncated file is refused here, not by every tile. */
	int stored_levels;
	if (img_check_readable(f->path, &stored_levels, err))
		return np_error(p, "path", "%s", err);

	int kind;
	if ((rc = np_enum(p, "kind", kind_names, FILE_KIND_HEIGHT, &kind)))
		return rc;
	f->kind = kind;
	nd->out = kind == FILE_KIND_COLOR ? PIX_COLOR : PIX_HEIGHT;
	if ((rc = check_kind(p, nd, f)))
		return rc;
	struct img_georef geo;
	if (img_georef_read(f->path, &geo, err))
		return np_error(p, "path", "cannot open %s", err);
	if ((rc = parse_bounds(p, f, &geo)))
		return rc;
	bool global = f->east - f->west == 360; /* exact: parse_bounds snaps near-360 spans */
	int wrap;
	if ((rc = np_enum(p, "lon_wrap", bool_names, global ? 1 : 0, &wrap)))
		return rc;
	f->wrap = wrap & 1;
	if (f->wrap && !global)
		return np_error(p, "lon_wrap", "needs bounds spanning 360 degrees of longitude");
	int iso;
	if ((rc = np_enum(p, "isotropic", bool_names, 1, &iso)))
		return rc;
	f->isotropic = iso & 1;
	if (kind == FILE_KIND_COLOR)
		return parse_color(p, f);
	if ((rc = parse_height(p, f, &geo)))
		return rc;
	/* OIIO's automip averages nodata into the coarser levels as if it were a height (-32768
	 * mixed into a box: -8000 m). A huge float nodata stays recognisable (file_resample.c);
	 * any other needs levels built around it: clipmapctl import builds them. */
	if (f->has_nodata && !(f->rtype == IMG_F32 && fabsf(f->nodata) >= 1e30f) &&
	    stored_levels <= 1 && f->nlev > 1)
		return np_error(p, "path", "%s: no MIP levels, so nodata %g would be averaged into "
				"coarse heights: convert it with clipmapctl import", f->path,
				f->nodata);
	return 0;
}

static int file_generate(const struct node *nd, struct gen_ctx *g, const struct tile_key *k,
			 struct tile *const *in, int nin, struct tile *out)
{
	(void)in;
	(void)nin;
	return file_resample(nd->impl, g, k, out);
}

const struct node_type node_type_file = {
	.name = "file",
	.doc = "an image file (OpenImageIO) resampled onto the grid: heights or colour",
	.version = 2, /* 2: the east–west prefilter (isotropic), Catmull-Rom magnified heights */
	.slots = NULL,
	.nslots = 0,
	.create = file_create,
	.destroy = file_destroy,
	.deps = NULL,
	.generate = file_generate,
};
