/* file_resample — the `file` node's resampler: one tile of a `file` node's image (common/img.h,
 * read through an img_cache) resampled onto the tile grid. node_file.c parses the parameters
 * into a struct file_source; file_resample() turns it into tiles. file_plan.h (internal) chooses
 * the level and builds the tap tables, file_resample.c reads the region and runs the passes.
 * Threads: a struct file_source is immutable once created; any number of workers may call
 * file_resample on it at once, each with its own gen_ctx (all buffers come from gen_scratch).
 * Ownership: struct file_source owns nothing itself: path and own_cache belong to the node
 * (node_file.c frees them), cache is borrowed from the planet (or is own_cache).
 *
 * Resampling. A tile's texels are evenly spaced in degrees, so the texel → source pixel map is
 * separable: per output column a few (source column, weight) taps, per output row the same.
 * file_resample() reads the source region the tile needs (plus the bilinear border; for a 360°
 * image the columns wrap, read as two pieces when the tile straddles the image's edge) once
 * through img_cache_read, then runs a horizontal pass over those rows and a vertical pass into
 * the tile. Filtering (seed 000 §4.3): with r = texel spacing / pixel spacing per axis, the
 * read uses MIP level m = floor(log2(min(rx, ry))) (the file's own levels or OIIO's automip,
 * each a 2×2 box of the one above): there the narrower axis is at most 2× finer than the output
 * and bilinear suffices (heights magnified, r < 1: Catmull-Rom, C1 across the source's
 * rows and columns where bilinear facets crease; bilinear at a bounded axis's edge pixels and
 * for a tile whose samples include missing ones, whose renormalised negative weights would
 * extrapolate; or with `magnify = bspline` a cubic B-spline everywhere, edges and missing
 * samples included: its weights are never negative). The wider axis (anisotropic levels, lx < ly + 1: texels up to 2^20
 * times wider in longitude than tall) is averaged by n = ceil(r) bilinear sub-taps spread
 * across the texel (a box of bilinears) at that same level; m rises only when n would pass
 * FILE_MAX_SUBTAPS or the region FILE_REGION_BUDGET pixels.
 * Why the narrower axis decides: a MIP level is a box in both axes at once, so reading a
 * coarser one for the wide axis blurs the narrow one. That was the poles' bug: a polar tile at
 * (lx 0, ly 19) is 38 m of latitude but 1.4° of longitude per texel; choosing the level until 8
 * taps covered the 17 ETOPO5 columns a texel spans read level 2, whose rows are 0.33° (37 km)
 * tall, so the texels next to the pole averaged rows 9..37 km from it and varied by 68 m (230 m
 * at the north pole) with longitude, against 0.003 m in the source over those 38 m. Measuring
 * in metres instead would not help: along a parallel a texel and a source pixel both shrink by
 * cos(latitude), so r in x is the same ratio on the ground as in degrees; what differs near the
 * pole is only that texels are very anisotropic, and an anisotropic footprint needs an
 * anisotropic filter (rows kept at the narrow axis's level, many cheap taps across: the region
 * is then few rows high). When the tile maps 1:1 onto the pixels of a level, the read is a
 * plain copy (straight into the tile for float heights with scale 1, offset 0). Known limit of
 * the floor() choice: for 1 < r < 2, content at the source's Nyquist frequency still aliases
 * (a 0/250 1-pixel checkerboard at r = 1.5 gives texels of about 94..156 instead of 125); from
 * r = 2 on it averages out.
 *
 * The poles. A global image's rows are areas (pixel-is-point grids like ETOPO5 aside, whose
 * edge rows are centred on the poles): the edge row's pixels are wedges meeting at the pole,
 * which therefore holds the row's mean. Between the last row centre short of a pole and the
 * pole (a polar cap) samples blend from that row to a plane through the pole (its first
 * harmonic) and the mean (pole_taps; the rows are read whole at the level in use). So the
 * texels nearest a pole do not depend on longitude, at every level, the viewer's pole (one
 * point, reached from every meridian) is one value, and no crease converges on it.
 *
 * East–west detail no finer than the rows (key `isotropic`, on by default). A plate-carrée
 * image's pixels narrow east–west as cos(latitude) while its rows stay as far apart: at
 * 89.8° an ETOPO5 pixel is 30 m wide and 9 km tall. Global products are resampled onto that
 * grid from sources whose ground resolution is about the same both ways (ETOPO5 repeats its
 * last four rows before the south pole, each varying 90 m with longitude), so near a pole
 * their columns carry no real detail: read as is, every column becomes a wedge 9–45 km long
 * on its meridian, and shaded relief shows radial dashes converging on the pole. So each
 * source row of level m is first box-filtered east–west (a box over the piecewise-constant
 * row, fractional at its ends, circular on a 360° image) to the width w = (row height /
 * pixel width) / cos(latitude) pixels that makes its footprint as wide on the ground as the
 * rows are apart (FILE_ISO_RATIO), less what the horizontal pass averages anyway (the widths
 * add as box variances: w_pre = sqrt(w² − r_x²), r_x the texel spacing, 1 below two
 * sub-taps). A box narrower than a pixel is no filter, so below 45° (square pixels) nothing
 * changes, and at 60° a magnified texel averages 1.7 pixels across. The region read grows by
 * half the box each side (FILE_ISO_WIDE pixels at most: the few rows by a pole that need
 * more are read whole) and a tile that reaches such rows is never copied 1:1. The cap's
 * harmonic row is damped like the cap row (sinc of the box). A texel row's east–west slope
 * is then at most √2 × its source row's range / the row spacing on the ground. A regional
 * survey in latitude/longitude whose columns are genuine (LiDAR at 78°N) sets
 * `isotropic = false`.
 *
 * Missing data. A texel whose centre is outside the bounds gets the fill. Inside, nodata
 * (and NaN) samples get weight 0 and the others are renormalised: the texel keeps the
 * weighted mean of its valid samples when they carry at least half of its weight, and gets
 * the fill otherwise — so a coastline neither grows nor shrinks by a texel.
 * Colour is filtered as straight (not premultiplied) RGBA.
 *
 * Read failures. A read that fails (the file cut short or changed on disk after load) fails
 * the tile with -EIO and is reported once per node through engine_fault (engine/fault.h) with
 * the file, the MIP level and the pixel region; the img_cache keeps the file failed until it
 * changes (OIIO would otherwise serve the unreadable tiles as zeros from then on).
 */
#ifndef CLIPMAP_FILE_RESAMPLE_H
#define CLIPMAP_FILE_RESAMPLE_H
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>

#include "common/img.h"

#define FILE_MAX_LEVELS 32

struct gen_ctx;
struct tile;
struct tile_key;

enum file_kind { FILE_KIND_HEIGHT, FILE_KIND_COLOR };

/* A pole of one MIP level (file_resample.c, cap_rows): the edge row's channel sums and valid
 * samples, and the cap row's first harmonic. They depend only on the level, so each is
 * computed once, by the first tile that needs it, instead of rereading a whole row per tile. */
struct file_pole_stats {
	bool done;
	int missing; /* a sample of the edge or the cap row was missing */
	double sum[4], valid;
	double ca[4], sa[4];
};

/* The node's pole statistics: a cache, so mutable although the source is not. */
struct file_poles {
	pthread_mutex_t mu; /* protects s (never held while reading the file) */
	atomic_bool read_failed; /* a read failure was reported (engine_fault): once per node */
	struct file_pole_stats s[FILE_MAX_LEVELS][2]; /* [level][0 north, 1 south] */
};

/* What a `file` node reads and how: filled by node_file.c's create, immutable after (but
 * for the cache behind poles). */
struct file_source {
	char *path; /* resolved; owned by the node */
	struct img_cache *cache; /* the planet's (borrowed), or own_cache */
	struct img_cache *own_cache; /* the node's; only for a planet without an image cache */
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
	bool isotropic; /* box-filter rows east–west to their spacing on the ground (above) */
	bool bspline;	/* magnified heights: a cubic B-spline instead of Catmull-Rom */
	struct file_poles *poles; /* owned by the node */
};

/* Fills out (out->size texels square, its pixel format the kind's) with tile k of f's image,
 * scratch from g. Borrows everything. Returns 0, -EIO (a read failed), -EFBIG (the region is
 * too large: a file with a truncated MIP pyramid, at a very coarse level) or -EFAULT (a bug). */
int file_resample(const struct file_source *f, struct gen_ctx *g, const struct tile_key *k,
		  struct tile *out);

#endif

