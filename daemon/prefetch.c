/* prefetch — see prefetch.h. A level's tiles are what a clipmapview with its focus anywhere in
 * the region would ask for there (common/clipmap.h): the window of CLIPMAP_WINDOW_TILES tiles
 * centred on the focus and the ring around it, on every lx a viewer at that latitude may use.
 * A bbox level is a list of row segments (one per row and lx: a run of columns, wrapping at the
 * antimeridian), enumerated arithmetically. A path level is materialised as a sorted,
 * deduplicated list of keys: focus points every half tile (of the finest lx viewers use there)
 * along each geodesic (GeographicLib) and across the corridor (perpendicular to the geodesic's
 * bearing at that point), each adding its window and ring on the lx of viewers near it. Levels are built one at a time, so a job holds one level at most, and a
 * level larger than the iterator's limit stops the job (-E2BIG) as soon as it is seen.
 *
 * The estimate (prefetch_estimate) is analytic and touches nothing per tile: a bbox level's
 * rows are sampled (at most ESTIMATE_ROWS of them), a corridor is cut into pieces (up to
 * ESTIMATE_PIECES per geodesic, on a sphere) and each piece counts the area it sweeps — its
 * length by the corridor's width plus the width a viewer's window and ring sweep moving along
 * it — in tiles of the lx used at its latitude. Levels are capped at what they hold.
 *
 * A job's iterator runs on a builder thread of its own, which fills a bounded queue of keys
 * (FEED_CAP) that the owner's thread takes from; the owner never builds a level.
 */
#include "prefetch.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/clipmap.h"
#include "common/errbuf.h"
#include "common/geo.h"
#include "common/lonpoly.h"
#include "common/xalloc.h"
#include "common/xthread.h"

#define ESTIMATE_ROWS 4096  /* bbox rows sampled per level */
#define ESTIMATE_POLY_ROWS 256 /* polygon rows sampled per level */
#define ESTIMATE_PIECES 16  /* pieces per geodesic */
#define ESTIMATE_MAX 1e15   /* the estimate saturates there */
#define FEED_CAP 8192	    /* keys queued between a builder and its job */

/* A run of tiles in one row: (x0 .. x0 + n − 1 wrapping, y) at level (lx, ly). */
struct segment {
	uint32_t x0, n, y;
	uint8_t lx;
};

struct prefetch_iter {
	const struct planet *p;
	uint8_t shape;
	int lmin, lmax;
	struct geo_rect bbox;
	double width;
	struct proto_lonlat *pts;
	uint32_t npts;
	uint32_t *rings; /* polygon: points per ring (pts holds them) */
	uint32_t nrings;
	double (*iv)[2]; /* polygon: a row's longitude intervals (scratch) */
	size_t ivcap;
	int layers[PROTO_MAX_LAYERS];
	int nlayers;
	/* position */
	int ly;		 /* current level */
	uint64_t pos;	 /* tile index within the level */
	int li;		 /* layer index within layers[] */
	uint64_t ntiles; /* tiles at the current level */
	/* bbox level: its row segments; the position: segment seg, column col */
	struct segment *segs;
	size_t nsegs, seg;
	uint32_t col;
	/* path level */
	struct tile_key *list;
	size_t nlist;
	/* limits and totals */
	uint64_t max_tiles;  /* per level, every layer */
	uint64_t counted;    /* tiles (every layer) of the levels entered */
	struct prefetch_estimate est;
	bool started, done;
	int err;
	char errmsg[256];
	const atomic_bool *cancel; /* the builder's: stops a level being built (may be NULL) */
};

static int cmp_key(const void *a, const void *b)
{
	const struct tile_key *x = a, *y = b;
	if (x->lx != y->lx)
		return x->lx < y->lx ? -1 : 1;
	if (x->y != y->y)
		return x->y < y->y ? -1 : 1;
	if (x->x != y->x)
		return x->x < y->x ? -1 : 1;
	return 0;
}

/* Sorts and deduplicates the path list. */
static void compact(struct prefetch_iter *it)
{
	if (it->nlist < 2)
		return;
	qsort(it->list, it->nlist, sizeof *it->list, cmp_key);
	size_t n = 1;
	for (size_t i = 1; i < it->nlist; i++)
		if (cmp_key(&it->list[i], &it->list[n - 1]))
			it->list[n++] = it->list[i];
	it->nlist = n;
}

static void push_key(struct prefetch_iter *it, size_t *cap, size_t *compacted,
		     const struct tile_key *k)
{
	if (it->nlist == *cap) {
		/* mostly repeats of the last focus's window: compact before growing */
		if (it->nlist > 2 * *compacted + 4096) {
			compact(it);
			*compacted = it->nlist;
		}
		if (it->nlist == *cap) {
			*cap = *cap ? *cap * 2 : 4096;
			it->list = xrealloc(it->list, *cap * sizeof *it->list);
		}
	}
	it->list[it->nlist++] = *k;
}

/* The rows a viewer's window and ring cover at level ly with its focus at lat: *y0 .. *y1. */
static void window_rows(const struct prefetch_iter *it, int ly, double lat, uint32_t *y0,
			uint32_t *y1)
{
	uint32_t T = it->p->tile_size;
	struct grid_quad q;
	grid_window(0, ly, T, CLIPMAP_WINDOW_TILES * T, 0, lat, &q);
	*y0 = q.ty0 > 0 ? q.ty0 - 1 : 0;
	uint32_t last = q.ty0 + q.nty; /* the ring's row below the window */
	*y1 = last < grid_tiles_y(ly) ? last : grid_tiles_y(ly) - 1;
}

/* The columns at level lx that the windows and rings of viewers focused anywhere in
 * longitudes [lon, lon + span] (span ≥ 0 degrees) cover: from *x0, *n of them (wrapping; all
 * of them, from 0, where the windows go round the globe or a window is the whole level). */
static void window_cols(const struct prefetch_iter *it, int lx, double lon, double span,
			uint32_t *x0, uint32_t *n)
{
	int64_t T = it->p->tile_size, S = CLIPMAP_WINDOW_TILES * T, W = grid_tiles_x(lx);
	/* window origins in texels (unwrapped), as grid_window places them */
	double fw = (lon + 180.0) / 360.0 * (double)(W * T), fe = fw + span / 360.0 * (double)(W * T);
	int64_t uw = (int64_t)floor(fw - S / 2.0 + 0.5), ue = (int64_t)floor(fe - S / 2.0 + 0.5);
	int64_t first = (int64_t)floor((double)uw / (double)T) - 1;
	int64_t last = (int64_t)floor((double)(ue + S - 1) / (double)T) + 1;
	if (W * T <= S || last - first + 1 >= W) {
		*x0 = 0;
		*n = (uint32_t)W;
		return;
	}
	*x0 = grid_wrap_x(lx, first);
	*n = (uint32_t)(last - first + 1);
}

/* Adds the window and ring of a viewer focused at (lat, lon), on every lx a viewer may use
 * within dlat degrees north or south of it (the foci are a step apart: a viewer between two
 * that holds an lx neither holds — just past the latitude where it becomes possible — has a
 * window and ring reaching rows the farther focus's do not). */
static void add_focus(struct prefetch_iter *it, size_t *cap, size_t *compacted, int ly,
		      double lat, double lon, double dlat)
{
	int lxa, lxb;
	clipmap_level_lx_range(ly, fmax(lat - dlat, -90.0), fmin(lat + dlat, 90.0), &lxa, &lxb);
	uint32_t y0, y1;
	window_rows(it, ly, lat, &y0, &y1);
	for (int lx = lxa; lx <= lxb; lx++) {
		uint32_t x0, n;
		window_cols(it, lx, lon, 0, &x0, &n);
		for (uint32_t y = y0; y <= y1; y++)
			for (uint32_t i = 0; i < n; i++) {
				struct tile_key k = { .lx = (uint8_t)lx, .ly = (uint8_t)ly, .y = y,
						      .x = grid_wrap_x(lx, (int64_t)x0 + i) };
				push_key(it, cap, compacted, &k);
			}
	}
}

/* Foci a tile of the finest lx may hold (build_path_level's sample bound). */
#define PATH_FOCI_PER_TILE 8

/* Builds the corridor's tile list for level ly. Returns 0 or -E2BIG (too many samples). */
static int build_path_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	free(it->list);
	it->list = NULL;
	it->nlist = 0;
	size_t cap = 0, compacted = 0;
	/* a tile north-south (the foci are half of one apart at most, below) */
	double tile_m = M_PI * geo_body_a(body) / (double)grid_tiles_y(ly);
	/* the corridor's half width in degrees of latitude */
	double dlat = it->width * 0.5 / geo_body_a(body) * (180.0 / M_PI);
	uint64_t samples = 0;
	for (uint32_t i = 0; i < it->npts; i++) {
		double lat1 = it->pts[i].lat, lon1 = it->pts[i].lon;
		double s12 = 0, azi1 = 0, azi2 = 0;
		if (i + 1 < it->npts)
			geo_inverse(body, lat1, lon1, it->pts[i + 1].lat, it->pts[i + 1].lon, &s12,
				    &azi1, &azi2);
		for (double s = 0;;) {
			double lat = lat1, lon = lon1, azi = azi1;
			if (s > 0)
				geo_direct_azi(body, lat1, lon1, azi1, s, &lat, &lon, &azi);
			/* A step of half a tile of the finest lx a viewer uses across the corridor
			 * here (half its width north or south: the finest lx and the widest cos
			 * over that band, cos floored for the pole itself), and half a tile
			 * north–south at most: no column or row falls between two foci, nor the
			 * corner of a ring between four (near a pole the grid of foci along and
			 * across the route lies askew on the columns; whole-tile steps left ring
			 * corners out there, test_prefetch). Until 6 December the step was
			 * tile_m · cos(lat), a tile of lx ly + 1, which no viewer near a pole
			 * uses: the corridor was sampled ~50 times a tile of the lx viewers hold
			 * there, and the keep-up bench's pole corridor at level 10 (157 km wide)
			 * stopped on the job's limit with 1 308 tiles to make. */
			double band_s = fmax(lat - dlat, -90.0), band_n = fmin(lat + dlat, 90.0);
			double eq = grid_band_equator_lat(band_s, band_n);
			int lxa, lxb;
			clipmap_level_lx_range(ly, band_s, band_n, &lxa, &lxb);
			double c = fmax(cos(eq * M_PI / 180.0), 0.02);
			double step = 0.5 * fmin(tile_m, 2 * M_PI * geo_body_a(body) * c /
								 (double)grid_tiles_x(lxb));
			double kd = ceil(it->width * 0.5 / step); /* no int conversion: huge */
			if (kd > (double)it->max_tiles + 4096.0)
				return -E2BIG;
			uint64_t kmax = (uint64_t)kd;
			/* Samples are geometry, made once whatever the layers: bounded by the
			 * job's limit itself, not its share per layer, times the foci a tile of
			 * the finest lx can hold (4 on the half-tile grid, up to ~7 where the
			 * viewers' tiles are wider than tall) — so the tile count, not the
			 * sampling, is what stops a corridor the estimate let through. */
			samples += 1 + 2 * kmax;
			if (samples > PATH_FOCI_PER_TILE * (uint64_t)it->max_tiles + 4096)
				return -E2BIG;
			double half = 1.5 * step / geo_body_a(body) * (180.0 / M_PI);
			add_focus(it, &cap, &compacted, ly, lat, lon, half);
			for (uint64_t k = 1; k <= kmax; k++) {
				double off = fmin((double)k * step, it->width * 0.5), la, lo;
				geo_direct(body, lat, lon, azi + 90.0, off, &la, &lo);
				add_focus(it, &cap, &compacted, ly, la, lo, half);
				geo_direct(body, lat, lon, azi - 90.0, off, &la, &lo);
				add_focus(it, &cap, &compacted, ly, la, lo, half);
			}
			if (it->nlist > 4 * (it->max_tiles / it->nlayers) + 65536)
				return -E2BIG;
			if (it->cancel && atomic_load_explicit(it->cancel, memory_order_relaxed))
				return -ECANCELED;
			if (s >= s12)
				break;
			s = fmin(s + step, s12);
		}
	}
	compact(it);
	return it->nlist * it->nlayers > it->max_tiles ? -E2BIG : 0;
}

/* Tile row y's latitude band at level ly. */
static void row_lats(int ly, uint32_t y, double *south, double *north)
{
	double h = 180.0 / (double)grid_tiles_y(ly);
	*north = 90.0 - h * y;
	*south = *north - h;
}

/* The rows of a bbox level, every stride-th one: with segs, stores each row's segments (and
 * stops past it->max_tiles tiles: returns UINT64_MAX); without, only counts. Returns the tiles
 * of one layer in the rows visited. */
static uint64_t bbox_rows(struct prefetch_iter *it, int ly, uint32_t stride, bool segs,
			  uint64_t *nrows)
{
	const struct geo_rect *b = &it->bbox;
	size_t cap = 0;
	uint64_t n_tiles = 0;
	/* rows: from the northernmost viewer's window to the southernmost's */
	uint32_t ya, yb, y0, y1;
	window_rows(it, ly, b->north, &y0, &ya);
	window_rows(it, ly, b->south, &yb, &y1);
	(void)ya;
	(void)yb;
	*nrows = (uint64_t)y1 - y0 + 1;
	double span = b->west <= b->east ? b->east - b->west : b->east + 360.0 - b->west;
	double reach = (CLIPMAP_REACH_TILES + 1) * 180.0 / (double)grid_tiles_y(ly);
	for (uint64_t yy = y0; yy <= y1; yy += stride) {
		uint32_t y = (uint32_t)yy;
		/* the viewers in the bbox whose window or ring may reach row y */
		double rs, rn;
		row_lats(ly, y, &rs, &rn);
		double vs = fmax(rs - reach, b->south), vn = fmin(rn + reach, b->north);
		if (vs > vn)
			vs = vn = rs > b->north ? b->north : b->south;
		int lxa, lxb;
		clipmap_level_lx_range(ly, vs, vn, &lxa, &lxb);
		for (int lx = lxa; lx <= lxb; lx++) {
			uint32_t x0, n;
			window_cols(it, lx, b->west, span, &x0, &n);
			n_tiles += n;
			if (!segs)
				continue;
			if (n_tiles * it->nlayers > it->max_tiles)
				return UINT64_MAX;
			if (it->nsegs == cap) {
				cap = cap ? cap * 2 : 64;
				it->segs = xrealloc(it->segs, cap * sizeof *it->segs);
			}
			it->segs[it->nsegs++] = (struct segment){ x0, n, y, (uint8_t)lx };
		}
	}
	return n_tiles;
}

static uint64_t poly_rows(struct prefetch_iter *it, int ly, uint32_t stride, bool segs,
			  uint64_t *nrows);

static int bbox_level(struct prefetch_iter *it, int ly)
{
	free(it->segs);
	it->segs = NULL;
	it->nsegs = 0;
	uint64_t rows;
	uint64_t n = it->shape == PROTO_SHAPE_POLYGON ? poly_rows(it, ly, 1, true, &rows)
						       : bbox_rows(it, ly, 1, true, &rows);
	if (n == UINT64_MAX) {
		it->ntiles = 0;
		return -E2BIG;
	}
	it->ntiles = n;
	return 0;
}

#define LX_BREAKS 128 /* latitudes where the lx viewers use changes, per level */

/* The lx range (clipmap_level_lx_range) of viewers at lat, as one number to compare. */
static int lx_code(int ly, double lat)
{
	int a, b;
	clipmap_level_lx_range(ly, lat, lat, &a, &b);
	return a * 64 + b;
}

/* The latitudes where the lx range of a viewer there changes, at level ly, ascending: found
 * every 0.05° and refined by bisection. Returns how many (at most LX_BREAKS). */
static size_t lx_breaks(int ly, double *out)
{
	size_t n = 0;
	double prev = -90.0;
	int pc = lx_code(ly, prev);
	for (int i = 1; i <= 3600 && n < LX_BREAKS; i++) {
		double lat = -90.0 + 0.05 * i;
		int c = lx_code(ly, lat);
		if (c != pc) {
			double a = prev, b = lat;
			for (int k = 0; k < 40; k++) {
				double m = (a + b) / 2;
				if (lx_code(ly, m) == pc)
					a = m;
				else
					b = m;
			}
			out[n++] = (a + b) / 2;
		}
		prev = lat;
		pc = c;
	}
	return n;
}

/* The latitudes [*lo, *hi] of the viewers whose window and ring (window_rows) reach row y at
 * level ly: a focus's rows move south as it does, so both ends are found by bisection. */
static void reach_lats(const struct prefetch_iter *it, int ly, uint32_t y, double *lo, double *hi)
{
	double a = -90.0, b = 90.0;
	for (int k = 0; k < 50; k++) { /* the northernmost focus whose last row is ≥ y */
		double m = (a + b) / 2;
		uint32_t y0, y1;
		window_rows(it, ly, m, &y0, &y1);
		if (y1 >= y)
			a = m;
		else
			b = m;
	}
	*hi = b;
	a = -90.0, b = 90.0;
	for (int k = 0; k < 50; k++) { /* the southernmost focus whose first row is ≤ y */
		double m = (a + b) / 2;
		uint32_t y0, y1;
		window_rows(it, ly, m, &y0, &y1);
		if (y0 <= y)
			b = m;
		else
			a = m;
	}
	*lo = a;
}

static int cmp_run(const void *a, const void *b)
{
	const uint32_t *x = a, *y = b;
	return x[0] < y[0] ? -1 : x[0] > y[0];
}

/* The rows of a polygon level, as bbox_rows: the viewers whose window or ring may reach row y
 * are those inside the polygon within (CLIPMAP_REACH_TILES + 1) rows of it; each stretch of
 * longitudes they span adds the columns window_cols gives it, merged per row and lx. */
static uint64_t poly_rows(struct prefetch_iter *it, int ly, uint32_t stride, bool segs,
			  uint64_t *nrows)
{
	struct lonpoly poly = { it->nrings, it->rings, it->pts };
	double pw, ps, pe, pn;
	lonpoly_bounds(&poly, &pw, &ps, &pe, &pn);
	size_t cap = 0;
	uint64_t n_tiles = 0;
	uint32_t ya, yb, y0, y1;
	window_rows(it, ly, pn, &y0, &ya);
	window_rows(it, ly, ps, &yb, &y1);
	(void)ya;
	(void)yb;
	*nrows = (uint64_t)y1 - y0 + 1;
	if (!it->iv) {
		it->ivcap = 2 * (size_t)it->npts + 2;
		it->iv = xmalloc(it->ivcap * sizeof *it->iv);
	}
	size_t runcap = 2 * it->ivcap;
	uint32_t(*runs)[2] = xmalloc(runcap * sizeof *runs);
	double brk[LX_BREAKS];
	size_t nbrk = lx_breaks(ly, brk);
	double reach = (CLIPMAP_REACH_TILES + 1) * 180.0 / (double)grid_tiles_y(ly);
	for (uint64_t yy = y0; yy <= y1; yy += stride) {
		uint32_t y = (uint32_t)yy;
		double rs, rn;
		row_lats(ly, y, &rs, &rn);
		double vs = fmax(rs - reach, ps), vn = fmin(rn + reach, pn);
		if (vs > vn) /* a row only the window's rounding reaches: the nearest edge */
			vs = vn = rs > pn ? pn : ps;
		/* only the viewers whose window and ring reach row y (as a bbox's rows) */
		double ra, rb;
		reach_lats(it, ly, y, &ra, &rb);
		vs = fmax(vs, ra);
		vn = fmin(vn, rb);
		if (vs > vn)
			continue;
		double lo, hi;
		if (lonpoly_strip(&poly, vs, vn, it->iv, it->ivcap, &lo, &hi) <= 0)
			continue;
		int lxa, lxb;
		clipmap_level_lx_range(ly, lo, hi, &lxa, &lxb);
		/* the strip cut where the lx viewers use changes: each lx gets only the
		 * longitudes of the polygon's part at the latitudes that use it */
		double cut[LX_BREAKS + 2];
		size_t ncut = 0;
		cut[ncut++] = lo;
		for (size_t i = 0; i < nbrk; i++)
			if (brk[i] > lo && brk[i] < hi)
				cut[ncut++] = brk[i];
		cut[ncut++] = hi;
		for (int lx = lxa; lx <= lxb; lx++) {
			uint32_t W = grid_tiles_x(lx);
			size_t nr = 0;
			bool all = false;
			for (size_t c = 0; c + 1 < ncut && !all; c++) {
				double slo, shi;
				long niv = lonpoly_strip(&poly, cut[c], cut[c + 1], it->iv, it->ivcap,
							 &slo, &shi);
				if (niv <= 0)
					continue;
				int sa, sb;
				clipmap_level_lx_range(ly, slo, shi, &sa, &sb);
				if (lx < sa || lx > sb)
					continue;
				for (long i = 0; i < niv; i++) {
					uint32_t x0, n;
					window_cols(it, lx, it->iv[i][0], it->iv[i][1] - it->iv[i][0],
						    &x0, &n);
					if (n >= W) {
						all = true;
						break;
					}
					if (nr + 2 > runcap) {
						runcap *= 2;
						runs = xrealloc(runs, runcap * sizeof *runs);
					}
					uint64_t end = (uint64_t)x0 + n;
					runs[nr][0] = x0;
					runs[nr++][1] = (uint32_t)(end < W ? end : W);
					if (end > W) {
						runs[nr][0] = 0;
						runs[nr++][1] = (uint32_t)(end - W);
					}
				}
			}
			if (all) {
				runs[0][0] = 0;
				runs[0][1] = W;
				nr = 1;
			}
			qsort(runs, nr, sizeof *runs, cmp_run);
			size_t m = 0;
			for (size_t i = 1; i < nr; i++) {
				if (runs[i][0] <= runs[m][1]) {
					if (runs[i][1] > runs[m][1])
						runs[m][1] = runs[i][1];
				} else {
					m++;
					runs[m][0] = runs[i][0];
					runs[m][1] = runs[i][1];
				}
			}
			for (size_t i = 0; nr && i <= m; i++) {
				uint32_t n = runs[i][1] - runs[i][0];
				n_tiles += n;
				if (!segs)
					continue;
				if (n_tiles * it->nlayers > it->max_tiles) {
					free(runs);
					return UINT64_MAX;
				}
				if (it->nsegs == cap) {
					cap = cap ? cap * 2 : 64;
					it->segs = xrealloc(it->segs, cap * sizeof *it->segs);
				}
				it->segs[it->nsegs++] = (struct segment){ runs[i][0], n, y, (uint8_t)lx };
			}
		}
		if (segs && it->cancel && atomic_load_explicit(it->cancel, memory_order_relaxed))
			break;
	}
	free(runs);
	return n_tiles;
}

static int enter_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	it->ly = ly;
	it->pos = 0;
	it->li = 0;
	it->seg = 0;
	it->col = 0;
	if (it->shape == PROTO_SHAPE_BBOX || it->shape == PROTO_SHAPE_POLYGON)
		return bbox_level(it, ly);
	int rc = build_path_level(it, ly, body);
	it->ntiles = rc ? 0 : it->nlist;
	return rc;
}

int prefetch_check(const struct planet *p, const struct proto_prefetch *m, char err[256])
{
	if (m->lmax > p->max_level) {
		err_set(err, "level %u is finer than planet %s's max_level %d", m->lmax, p->name,
			p->max_level);
		return -EINVAL;
	}
	if (m->lmin > m->lmax) {
		err_set(err, "level range %u..%u", m->lmin, m->lmax);
		return -EINVAL;
	}
	if (m->shape != PROTO_SHAPE_BBOX && m->shape != PROTO_SHAPE_PATH &&
	    m->shape != PROTO_SHAPE_POLYGON) {
		err_set(err, "unknown shape %u", m->shape);
		return -EINVAL;
	}
	if (m->shape == PROTO_SHAPE_PATH && (m->npoints == 0 || !(m->width_m >= 0))) {
		err_set(err, "a path needs points and a width ≥ 0");
		return -EINVAL;
	}
	if (m->shape == PROTO_SHAPE_POLYGON) {
		uint64_t n = 0;
		for (uint32_t i = 0; i < m->nrings && m->rings; i++) {
			if (m->rings[i] < 3) {
				err_set(err, "polygon ring %u has %u points (3 at least)", i,
					m->rings[i]);
				return -EINVAL;
			}
			n += m->rings[i];
		}
		if (m->nrings == 0 || m->nrings > PROTO_MAX_RINGS || n != m->npoints ||
		    n > PROTO_MAX_POLY || !m->points) {
			err_set(err, "a polygon needs 1-%u rings of %u points in all at most",
				PROTO_MAX_RINGS, PROTO_MAX_POLY);
			return -EINVAL;
		}
	}
	if (p->nlayers == 0 || (p->nlayers < 64 && m->layers >> p->nlayers)) {
		err_set(err, "layer mask 0x%llx names layers planet %s does not have (it has %zu)",
			(unsigned long long)m->layers, p->name, p->nlayers);
		return -EINVAL;
	}
	return 0;
}

/* Fills it's request fields (no level entered). */
static void iter_init(struct prefetch_iter *it, const struct planet *p,
		      const struct proto_prefetch *m)
{
	it->p = p;
	it->shape = m->shape;
	it->lmin = m->lmin;
	it->lmax = m->lmax;
	it->bbox = m->bbox;
	it->width = m->width_m;
	for (size_t i = 0; i < p->nlayers && i < PROTO_MAX_LAYERS; i++)
		if (m->layers == 0 || (m->layers >> i) & 1)
			it->layers[it->nlayers++] = (int)i;
	it->npts = m->shape == PROTO_SHAPE_PATH || m->shape == PROTO_SHAPE_POLYGON ? m->npoints : 0;
	if (m->shape == PROTO_SHAPE_POLYGON) {
		/* the estimate's iterator borrows them; prefetch_iter_create copies */
		it->pts = (struct proto_lonlat *)m->points;
		it->rings = (uint32_t *)m->rings;
		it->nrings = m->nrings;
	}
}

static double bbox_level_estimate(struct prefetch_iter *it, int ly)
{
	uint64_t rows;
	bool poly = it->shape == PROTO_SHAPE_POLYGON;
	/* one pass to learn the row count, without visiting more than two rows */
	if (poly)
		(void)poly_rows(it, ly, UINT32_MAX, false, &rows);
	else
		(void)bbox_rows(it, ly, UINT32_MAX, false, &rows);
	/* a polygon row costs a pass over its edges: fewer of them sampled */
	uint32_t sample = poly ? ESTIMATE_POLY_ROWS : ESTIMATE_ROWS;
	uint64_t stride64 = (rows + sample - 1) / sample;
	uint32_t stride = stride64 ? (uint32_t)stride64 : 1;
	uint64_t n = poly ? poly_rows(it, ly, stride, false, &rows)
			  : bbox_rows(it, ly, stride, false, &rows);
	uint64_t visited = (rows + stride - 1) / stride;
	return (double)n * (double)rows / (double)(visited ? visited : 1);
}

struct piece {
	double ds, lat; /* metres along the path; latitude of its middle */
	double e, n;	/* its direction: east and north components of a unit vector */
};

/* The point at fraction t of the great circle from v1 to v2 (ang apart): lat, lon degrees. */
static void slerp(const double v1[3], const double v2[3], double ang, double t, double *lat,
		  double *lon)
{
	double v[3];
	if (ang < 1e-9) {
		memcpy(v, v1, sizeof v);
	} else {
		double s = sin(ang), wa = sin((1 - t) * ang) / s, wb = sin(t * ang) / s;
		for (int i = 0; i < 3; i++)
			v[i] = wa * v1[i] + wb * v2[i];
	}
	*lat = atan2(v[2], sqrt(v[0] * v[0] + v[1] * v[1])) * 180.0 / M_PI;
	*lon = atan2(v[1], v[0]) * 180.0 / M_PI;
}

/* The path's pieces on a sphere of radius a: ESTIMATE_PIECES per geodesic. Returns an owned
 * array of *n. */
static struct piece *path_pieces(const struct proto_prefetch *m, double a, size_t *n_out)
{
	const double d2r = M_PI / 180.0;
	/* at most ESTIMATE_PIECES per geodesic, PROTO_MAX_PATH in all */
	size_t nseg = m->npoints > 1 ? m->npoints - 1 : 0;
	int per = nseg ? (int)(PROTO_MAX_PATH / nseg) : 1;
	per = per < 1 ? 1 : per > ESTIMATE_PIECES ? ESTIMATE_PIECES : per;
	size_t cap = nseg ? nseg * (size_t)per : 1;
	struct piece *pc = xmalloc(cap * sizeof *pc);
	*n_out = 0;
	for (uint32_t i = 0; i + 1 < m->npoints; i++) {
		double p1 = m->points[i].lat * d2r, l1 = m->points[i].lon * d2r;
		double p2 = m->points[i + 1].lat * d2r, l2 = m->points[i + 1].lon * d2r;
		double v1[3] = { cos(p1) * cos(l1), cos(p1) * sin(l1), sin(p1) };
		double v2[3] = { cos(p2) * cos(l2), cos(p2) * sin(l2), sin(p2) };
		double dot = v1[0] * v2[0] + v1[1] * v2[1] + v1[2] * v2[2];
		double ang = acos(fmax(-1.0, fmin(1.0, dot)));
		for (int k = 0; k < per; k++) {
			double la0, lo0, la1, lo1, lam, lom;
			slerp(v1, v2, ang, (double)k / per, &la0, &lo0);
			slerp(v1, v2, ang, (k + 1.0) / per, &la1, &lo1);
			slerp(v1, v2, ang, (k + 0.5) / per, &lam, &lom);
			double dl = fmod(lo1 - lo0 + 540.0, 360.0) - 180.0;
			double e = dl * cos(lam * d2r), n = la1 - la0, h = hypot(e, n);
			pc[(*n_out)++] = (struct piece){ ang * a / per, lam,
							 h > 0 ? e / h : 0, h > 0 ? n / h : 1 };
		}
	}
	return pc;
}

/* Tiles of one layer at level ly that a corridor piece of length ds (metres; 0 for an end)
 * sweeps at latitude lat: its length by the corridor's width plus a window and ring, over
 * every lx a viewer there may use. An end adds half a window's length. */
/* The lx range viewers use at a latitude, per level, memoised in 1/8° bins (the estimate asks
 * for it once per piece and level: up to PROTO_MAX_PATH pieces). */
#define LX_BINS (180 * 8 + 1)
struct lx_memo {
	int ly;
	int8_t lo[LX_BINS], hi[LX_BINS]; /* -1: not yet */
};

static void lx_range(struct lx_memo *mm, int ly, double lat, int *lxa, int *lxb)
{
	if (mm->ly != ly) {
		mm->ly = ly;
		memset(mm->lo, -1, sizeof mm->lo);
	}
	int b = (int)lround((fmax(-90.0, fmin(90.0, lat)) + 90.0) * 8.0);
	if (mm->lo[b] < 0) {
		int lo, hi;
		double bl = b / 8.0 - 90.0;
		clipmap_level_lx_range(ly, bl, bl, &lo, &hi);
		mm->lo[b] = (int8_t)lo;
		mm->hi[b] = (int8_t)hi;
	}
	*lxa = mm->lo[b];
	*lxb = mm->hi[b];
}

static double piece_tiles(struct lx_memo *mm, double a, int ly, double lat, double ds, double w,
			  double e, double n, bool end)
{
	const double K = CLIPMAP_WINDOW_TILES + 2; /* window and ring, in tiles */
	double th = M_PI * a / (double)grid_tiles_y(ly);
	/* the lx of viewers anywhere across the corridor, half its width north and south (near
	 * a pole the equatorward edge's are finer) */
	double dlat = 0.5 * w / a * (180.0 / M_PI);
	double band_s = fmax(lat - dlat, -90.0), band_n = fmin(lat + dlat, 90.0);
	/* the range grows with |lat|: its ends are at the band's edges, and at the equator if
	 * the band holds it (as clipmap_level_lx_range over the band; memoised per latitude) */
	const double at[3] = { band_s, band_n, 0 };
	int lxa = INT_MAX, lxb = -1;
	for (int q = 0; q < (grid_band_equator_lat(band_s, band_n) == 0 ? 3 : 2); q++) {
		int lo, hi;
		lx_range(mm, ly, at[q], &lo, &hi);
		lxa = lo < lxa ? lo : lxa;
		lxb = hi > lxb ? hi : lxb;
	}
	double sum = 0;
	for (int lx = lxa; lx <= lxb; lx++) {
		double cols = (double)grid_tiles_x(lx);
		double tw = fmax(2 * M_PI * a * cos(lat * M_PI / 180.0) / cols, 1e-9 * th);
		double mx = fmax(th, tw);
		/* a window K tiles square moving along (e, n) sweeps this wide across it */
		double sweep = K * (tw * fabs(n) + th * fabs(e));
		double len = end ? 0.5 * K * mx : ds;
		double area = len * (w + (end ? K * mx : sweep)) / (th * tw);
		double bound = ((len + w) / th + K) * cols; /* rows it can reach, every column */
		sum += fmin(area, bound);
	}
	return sum;
}

int prefetch_estimate(const struct planet *p, const struct proto_prefetch *m,
		      struct prefetch_estimate *e, char err[256])
{
	*e = (struct prefetch_estimate){ .lmin = m->lmin, .lmax = m->lmax };
	int rc = prefetch_check(p, m, err);
	if (rc)
		return rc;
	struct prefetch_iter it = { 0 };
	iter_init(&it, p, m);
	for (int i = 0; i < it.nlayers; i++) {
		const struct node *n = p->layers[it.layers[i]].node;
		e->tile_bytes += (uint64_t)p->tile_size * p->tile_size * pix_bytes(n->out);
	}
	double a = p->a, total = 0;
	size_t npc = 0;
	struct piece *pc = m->shape == PROTO_SHAPE_PATH ? path_pieces(m, a, &npc) : NULL;
	struct lx_memo *mm = pc ? xmalloc(sizeof *mm) : NULL;
	if (mm)
		mm->ly = -1;
	for (int ly = m->lmin; ly <= m->lmax; ly++) {
		double t;
		if (m->shape == PROTO_SHAPE_BBOX || m->shape == PROTO_SHAPE_POLYGON) {
			t = bbox_level_estimate(&it, ly);
		} else {
			double w = fmin(m->width_m, M_PI * a); /* wider wraps round the planet */
			t = piece_tiles(mm, a, ly, m->points[0].lat, 0, w, 0, 1, true) +
			    piece_tiles(mm, a, ly, m->points[m->npoints - 1].lat, 0, w, 0, 1,
					true);
			for (size_t i = 0; i < npc; i++)
				t += piece_tiles(mm, a, ly, pc[i].lat, pc[i].ds, w, pc[i].e,
						 pc[i].n, false);
		}
		/* never more than the level holds on the lx viewers use there */
		int lxa, lxb;
		clipmap_level_lx_range(ly, 0, 90, &lxa, &lxb);
		double all = 0;
		for (int lx = lxa; lx <= lxb; lx++)
			all += (double)grid_tiles_x(lx) * (double)grid_tiles_y(ly);
		t = fmin(ceil(t), all) * it.nlayers;
		t = fmin(t, ESTIMATE_MAX);
		e->level_tiles[ly] = (uint64_t)t;
		total = fmin(total + t, ESTIMATE_MAX);
	}
	free(pc);
	free(mm);
	free(it.iv);
	e->tiles = (uint64_t)total;
	return 0;
}

int prefetch_iter_create(const struct planet *p, const struct proto_prefetch *m,
			 uint64_t max_tiles, struct prefetch_iter **out, char err[256])
{
	*out = NULL;
	struct prefetch_estimate est;
	int rc = prefetch_estimate(p, m, &est, err);
	if (rc)
		return rc;
	struct prefetch_iter *it = xcalloc(1, sizeof *it);
	iter_init(it, p, m);
	it->est = est;
	it->max_tiles = max_tiles ? max_tiles : PREFETCH_MAX_TILES;
	if (it->npts) {
		it->pts = xmalloc(m->npoints * sizeof *it->pts);
		memcpy(it->pts, m->points, m->npoints * sizeof *it->pts);
	}
	if (it->nrings) {
		it->rings = xmalloc(m->nrings * sizeof *it->rings);
		memcpy(it->rings, m->rings, m->nrings * sizeof *it->rings);
	}
	*out = it;
	return 0;
}

/* Enters level ly, counting it; on an error the iteration stops with it. */
static bool iter_enter(struct prefetch_iter *it, int ly)
{
	it->started = true;
	int rc = enter_level(it, ly, it->p->body);
	if (rc) {
		it->err = rc;
		it->done = true;
		if (rc == -E2BIG)
			err_set(it->errmsg,
				"level %d has more than %llu tiles (every layer): the job's limit", ly,
				(unsigned long long)it->max_tiles);
		else
			err_set(it->errmsg, "level %d: %s", ly, strerror(-rc));
		return false;
	}
	it->counted += it->ntiles * (uint64_t)it->nlayers;
	return true;
}

size_t prefetch_iter_next(struct prefetch_iter *it, struct want *out, size_t n)
{
	size_t k = 0;
	if (it->done)
		return 0;
	if (!it->started && !iter_enter(it, it->lmin))
		return 0;
	while (k < n) {
		if (it->pos >= it->ntiles) {
			if (it->ly >= it->lmax) {
				it->done = true;
				break;
			}
			if (!iter_enter(it, it->ly + 1))
				break;
			continue;
		}
		struct tile_key key;
		if (it->shape != PROTO_SHAPE_PATH) {
			const struct segment *sg = &it->segs[it->seg];
			key.lx = sg->lx;
			key.ly = (uint8_t)it->ly;
			key.x = grid_wrap_x(sg->lx, (int64_t)sg->x0 + it->col);
			key.y = sg->y;
		} else {
			key = it->list[it->pos];
		}
		const struct planet_layer *L = &it->p->layers[it->layers[it->li]];
		key.node = L->node->hash;
		out[k++] = (struct want){ .node = L->node, .key = key, .cls = SCHED_BULK };
		if (++it->li == it->nlayers) {
			it->li = 0;
			it->pos++;
			if (it->shape != PROTO_SHAPE_PATH && ++it->col == it->segs[it->seg].n) {
				it->col = 0;
				it->seg++;
			}
		}
	}
	return k;
}

int prefetch_iter_error(const struct prefetch_iter *it, char err[256])
{
	if (it->err)
		err_set(err, "%s", it->errmsg);
	return it->err;
}

uint64_t prefetch_iter_total(const struct prefetch_iter *it)
{
	if (it->done && !it->err)
		return it->counted;
	uint64_t t = it->counted;
	for (int ly = it->started ? it->ly + 1 : it->lmin; ly <= it->lmax; ly++)
		t += it->est.level_tiles[ly];
	return t;
}

void prefetch_iter_destroy(struct prefetch_iter *it)
{
	if (!it)
		return;
	free(it->list);
	free(it->segs);
	free(it->pts);
	free(it->rings);
	free(it->iv);
	free(it);
}

/* ---- the builder thread and its feed ------------------------------------------------------ */

struct prefetch_feed {
	pthread_mutex_t mu;
	pthread_cond_t room; /* the builder waits here while the queue is full */
	struct want q[FEED_CAP]; /* a ring */
	size_t head, n;
	bool done;	/* the builder has queued its last key */
	int err;	/* and stopped with this error (0: the iteration completed) */
	char errmsg[256];
	uint64_t total; /* prefetch_iter_total, as last seen */
	bool starving;	/* the owner found the queue empty: wake it when keys come */
	atomic_bool cancel;
	int refs; /* the job's and the builder's */
	struct prefetch_iter *it; /* the builder's */
	const struct planet *p;	  /* a reference, the builder's */
	void (*wake)(void *ud);
	void *wake_ud;
};

static void feed_unref(struct prefetch_feed *f)
{
	xmutex_lock(&f->mu);
	bool last = --f->refs == 0;
	xmutex_unlock(&f->mu);
	if (!last)
		return;
	prefetch_iter_destroy(f->it);
	planet_unref(f->p);
	xcond_destroy(&f->room);
	xmutex_destroy(&f->mu);
	free(f);
}

static void *builder_main(void *arg)
{
	struct prefetch_feed *f = arg;
	struct want tmp[512];
	for (;;) {
		xmutex_lock(&f->mu);
		while (f->n == FEED_CAP && !atomic_load(&f->cancel))
			xcond_wait(&f->room, &f->mu);
		size_t room = FEED_CAP - f->n;
		xmutex_unlock(&f->mu);
		if (atomic_load(&f->cancel))
			break;
		size_t got = prefetch_iter_next(f->it, tmp, room < 512 ? room : 512);
		xmutex_lock(&f->mu);
		for (size_t i = 0; i < got; i++)
			f->q[(f->head + f->n + i) % FEED_CAP] = tmp[i];
		f->n += got;
		f->total = prefetch_iter_total(f->it);
		if (got == 0) {
			f->done = true;
			f->err = prefetch_iter_error(f->it, f->errmsg);
		}
		bool cancelled = atomic_load(&f->cancel);
		if (f->starving && !cancelled) {
			f->starving = false;
			f->wake(f->wake_ud); /* under mu: destroy cannot have begun */
		}
		bool end = f->done || cancelled;
		xmutex_unlock(&f->mu);
		if (end)
			break;
	}
	feed_unref(f);
	return NULL;
}

/* Takes keys from the feed into the window (owner's thread; bounded: one window). */
static void refill(struct prefetch_job *j)
{
	if (!j->exhausted && !j->paused && j->nwin <= PREFETCH_WINDOW / 2) {
		struct prefetch_feed *f = j->feed;
		size_t got = 0, want = PREFETCH_WINDOW - j->nwin;
		xmutex_lock(&f->mu);
		while (got < want && f->n) {
			j->win[j->nwin + got++] = f->q[f->head];
			f->head = (f->head + 1) % FEED_CAP;
			f->n--;
		}
		if (got)
			xcond_signal(&f->room);
		j->total = f->total;
		if (f->n == 0 && f->done) {
			j->exhausted = true;
			if (f->err)
				snprintf(j->err, sizeof j->err, "%s", f->errmsg);
		} else if (f->n == 0) {
			f->starving = true;
		}
		xmutex_unlock(&f->mu);
		if (got) {
			j->nwin += got;
			(void)sched_req_want(j->req, j->win, j->nwin);
		}
	}
	if (j->total < j->done)
		j->total = j->done;
	if (j->exhausted && j->nwin == 0 && j->state == PROTO_JOB_RUNNING)
		j->state = j->failed || j->err[0] ? PROTO_JOB_FAILED : PROTO_JOB_DONE;
}

int prefetch_job_create(const struct planet *p, const struct proto_prefetch *m,
			uint64_t max_tiles, uint64_t est_total, uint64_t now_ns,
			struct prefetch_job **out, char err[256])
{
	*out = NULL;
	struct prefetch_iter *it;
	int rc = prefetch_iter_create(p, m, max_tiles, &it, err);
	if (rc)
		return rc;
	struct prefetch_feed *f = xcalloc(1, sizeof *f);
	xmutex_init(&f->mu);
	xcond_init(&f->room);
	atomic_init(&f->cancel, false);
	f->it = it;
	it->cancel = &f->cancel;
	planet_ref(p);
	f->p = p;
	f->refs = 1;
	f->total = est_total;
	struct prefetch_job *j = xcalloc(1, sizeof *j);
	j->feed = f;
	j->id = m->id;
	j->total = est_total;
	j->state = PROTO_JOB_RUNNING;
	j->t0_ns = j->last_ns = now_ns;
	*out = j;
	return 0;
}

int prefetch_job_start(struct prefetch_job *j, void (*wake)(void *ud), void *ud)
{
	struct prefetch_feed *f = j->feed;
	f->wake = wake;
	f->wake_ud = ud;
	f->starving = true; /* the first keys wake the owner */
	f->refs = 2;
	pthread_t th;
	pthread_attr_t at;
	pthread_attr_init(&at);
	pthread_attr_setdetachstate(&at, PTHREAD_CREATE_DETACHED);
	int rc = pthread_create(&th, &at, builder_main, f);
	pthread_attr_destroy(&at);
	if (rc) {
		f->refs = 1;
		return -rc;
	}
	return 0;
}

bool prefetch_job_fed(struct prefetch_job *j)
{
	refill(j);
	return j->state != PROTO_JOB_RUNNING;
}

bool prefetch_job_ready(struct prefetch_job *j, const struct tile_key *k, int err)
{
	for (size_t i = 0; i < j->nwin; i++) {
		if (grid_key_equal(&j->win[i].key, k)) {
			j->win[i] = j->win[--j->nwin];
			j->done++;
			if (err)
				j->failed++;
			refill(j);
			break;
		}
	}
	return j->state != PROTO_JOB_RUNNING;
}

void prefetch_job_tick(struct prefetch_job *j, uint64_t now_ns)
{
	double dt = (double)(now_ns - j->last_ns) * 1e-9;
	if (dt <= 0)
		return;
	double r = (double)(j->done - j->last_done) / dt;
	j->rate = j->last_done == 0 && j->last_ns == j->t0_ns ? r : 0.5 * j->rate + 0.5 * r;
	if (!isfinite(j->rate) || j->rate < 0)
		j->rate = 0;
	j->last_ns = now_ns;
	j->last_done = j->done;
}

void prefetch_job_destroy(struct prefetch_job *j)
{
	if (!j)
		return;
	if (j->req)
		sched_req_destroy(j->req);
	struct prefetch_feed *f = j->feed;
	xmutex_lock(&f->mu);
	atomic_store(&f->cancel, true); /* under mu: no wake after this */
	xcond_signal(&f->room);
	xmutex_unlock(&f->mu);
	feed_unref(f);
	free(j);
}
