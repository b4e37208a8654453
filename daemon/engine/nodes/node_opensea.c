/* node_opensea — `open_sea`: where a sea may lie. Everything below sea level is not sea: the
 * Qattara Depression, Death Valley, the Danakil and the Turpan lie below it and are dry land.
 * The node reads a global height raster (`path`: equirectangular, the whole sphere, heights
 * relative to `sea_level` as in the data — ETOPO5 gives them above mean sea level) once, at
 * load, and finds its closed basins: the 8-connected regions of cells below sea level
 * (longitude wraps; the first and last rows connect across the pole). The largest is the
 * world ocean; a basin of at least `min_area` km² (default 100 000) is a sea of its own (the
 * Caspian: 371 000 km², its surface 28 m below the ocean's; at 5′ also the Black Sea, whose
 * Bosporus the raster does not resolve); every other basin is dry. The mask is 1 where the sea
 * may lie (the cells of the ocean and of the large basins, and the ground next to them: the
 * coast) and 0 elsewhere (dry basins, and ground away from the sea, where detail that dips
 * below sea level is no sea either). `levels` = "LAT LON LEVEL, …" puts the sea of the basin
 * holding each point at its own LEVEL (metres relative to sea_level; the Caspian's −28); the
 * others lie at sea level. The planet's `sea_basins = NODE` lays its sea surface there
 * (open_sea_level).
 *
 * Output: a 0..1 mask (a height), bilinear between the raster's cell centres. A colour
 * layer carries it to the viewer in its alpha (color_filter's `alpha` input; the planet key
 * sea_mask = color_alpha, docs/PLANETS.md).
 * Rasters wider than OPENSEA_MAX_W cells are read from a coarser MIP level (the mask of a
 * 5′ grid finds every basin a 9 km viewer would show).
 * Thread-safety: the mask is built in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "common/img.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "file_digest.h"

#define OPENSEA_MAX_W 4320 /* 5′: ETOPO5 itself; about 100 MB while the basins are found */
#define OPENSEA_MAX_LEVELS 8 /* basins with a level of their own */

struct open_sea {
	int w, h;
	bool point;  /* grid-registered (h = w/2 + 1: cells centred on the poles and on −180°,
		      * as ETOPO5), else cell-registered (h = w/2: centres half a cell in) */
	uint8_t *m; /* w × h, row 0 north: 255 the sea may lie here, 0 dry */
	uint8_t *closed;	   /* w × h: k + 1 on a cell of the basin of levels[k], 255 on
				    * another sea's (the ocean's, or a basin's at sea level), 0 */
	double level[OPENSEA_MAX_LEVELS]; /* those seas' surfaces, metres from sea_level */
};

/* Latitude of row y's centre, degrees. */
static double row_lat(const struct open_sea *s, double y)
{
	return s->point ? 90 - y * 180 / (s->h - 1) : 90 - (y + 0.5) * 180 / s->h;
}

static void os_destroy(struct node *n)
{
	struct open_sea *s = n->impl;
	if (s) {
		free(s->m);
		free(s->closed);
	}
	free(s);
	n->impl = NULL;
}

/* Cell (x, y)'s up to 8 neighbours into nb (indices); returns how many. x wraps; across the
 * pole the first and last rows meet the cell half a turn round. */
static int neighbours(int w, int h, int x, int y, uint32_t nb[9])
{
	int k = 0;
	for (int dy = -1; dy <= 1; dy++)
		for (int dx = -1; dx <= 1; dx++) {
			if (!dx && !dy)
				continue;
			int yy = y + dy, xx = ((x + dx) % w + w) % w;
			if (yy < 0 || yy >= h)
				continue;
			nb[k++] = (uint32_t)yy * (uint32_t)w + (uint32_t)xx;
		}
	if (y == 0 || y == h - 1)
		nb[k++] = (uint32_t)y * (uint32_t)w + (uint32_t)((x + w / 2) % w);
	return k;
}

/* Labels the basins of `below` (one label per 8-connected region, from 1) into lab and their
 * areas (km², on a sphere of radius a) into *area (owned); returns how many. */
static int basins(const struct open_sea *os, const uint8_t *below, double a, int32_t *lab,
		  double **area)
{
	int w = os->w, h = os->h;
	size_t n = (size_t)w * h, cap = 64;
	int count = 0;
	double *ar = xmalloc(cap * sizeof *ar);
	uint32_t *queue = xmalloc(n * sizeof *queue);
	double cell = (2 * M_PI / w) * (M_PI / h) * (a / 1e3) * (a / 1e3); /* km² × cos φ */
	double *cosr = xmalloc((size_t)h * sizeof *cosr);
	for (int y = 0; y < h; y++)
		cosr[y] = cos(row_lat(os, y) * M_PI / 180);
	for (size_t s = 0; s < n; s++) {
		if (!below[s] || lab[s])
			continue;
		if ((size_t)count + 1 >= cap)
			ar = xrealloc(ar, (cap *= 2) * sizeof *ar);
		int id = ++count;
		double sum = 0;
		size_t head = 0, tail = 0;
		queue[tail++] = (uint32_t)s;
		lab[s] = id;
		while (head < tail) {
			uint32_t c = queue[head++];
			int x = (int)(c % (uint32_t)w), y = (int)(c / (uint32_t)w);
			sum += cell * cosr[y];
			uint32_t nb[9];
			int k = neighbours(w, h, x, y, nb);
			for (int i = 0; i < k; i++)
				if (below[nb[i]] && !lab[nb[i]]) {
					lab[nb[i]] = id;
					queue[tail++] = nb[i];
				}
		}
		ar[id] = sum;
	}
	free(queue);
	free(cosr);
	*area = ar;
	return count;
}

/* (lon, lat) in cells: the column and row, fractional, whose centre is there. */
static void cell_coords(const struct open_sea *s, double lon, double lat, double *fx, double *fy)
{
	*fx = (lon + 180) / 360 * s->w - (s->point ? 0 : 0.5);
	*fy = s->point ? (90 - lat) / 180 * (s->h - 1) : (90 - lat) / 180 * s->h - 0.5;
}

/* The cell (column, row) whose centre is nearest (lat, lon). */
static size_t cell_at(const struct open_sea *s, double lat, double lon)
{
	double fx, fy;
	cell_coords(s, lon, lat, &fx, &fy);
	int x = (int)lround(fx), y = (int)lround(fy);
	x = ((x % s->w) + s->w) % s->w;
	y = y < 0 ? 0 : y > s->h - 1 ? s->h - 1 : y;
	return (size_t)y * s->w + (size_t)x;
}

/* The mask of the raster's heights hv (w × h, row 0 north), and the cells of the basins that
 * hold the points of lv (nlv triples lat, lon, level). Returns 0, or k + 1 when the point of
 * triple k lies in no closed sea (not below sea level, the ocean, or a basin under
 * min_area). */
static int build_mask(struct open_sea *s, const float *hv, double sea, double min_km2, double a,
		      const double *lv, int nlv)
{
	int w = s->w, h = s->h;
	size_t n = (size_t)w * h;
	uint8_t *below = xmalloc(n);
	for (size_t i = 0; i < n; i++)
		below[i] = hv[i] < sea; /* NaN: not below */
	int32_t *lab = xcalloc(n, sizeof *lab);
	double *area;
	int count = basins(s, below, a, lab, &area);
	int ocean = 0;
	for (int i = 1; i <= count; i++)
		if (!ocean || area[i] > area[ocean])
			ocean = i;
	uint8_t *keep = xcalloc((size_t)count + 1, 1);
	for (int i = 1; i <= count; i++)
		keep[i] = i == ocean || area[i] >= min_km2;
	int bad = 0;
	int32_t own[OPENSEA_MAX_LEVELS];
	for (int k = 0; k < nlv; k++) {
		size_t c = cell_at(s, lv[3 * k], lv[3 * k + 1]);
		own[k] = lab[c];
		s->level[k] = lv[3 * k + 2];
		if (!below[c] || !keep[lab[c]] || lab[c] == ocean)
			bad = bad ? bad : k + 1;
		for (int j = 0; j < k; j++)
			if (own[j] == own[k] && below[c])
				bad = bad ? bad : -(k + 1); /* two points in one basin */
	}
	/* The sea's cells and the ground next to them (the coast: the mask's bilinear ramp then
	 * lies beyond the data's coastline, so detail that dips below sea level at the shore is
	 * sea); nowhere else: no sea shows inland where detail (dunes, relief) dips below sea
	 * level, nor in a dry basin. */
	for (int y = 0; y < h; y++)
		for (int x = 0; x < w; x++) {
			size_t c = (size_t)y * w + x;
			bool sea_cell = below[c] && keep[lab[c]], by_sea = false;
			if (!below[c]) {
				uint32_t nb[9];
				int k = neighbours(w, h, x, y, nb);
				for (int i = 0; i < k && !by_sea; i++)
					by_sea = below[nb[i]] && keep[lab[nb[i]]];
			}
			s->m[c] = sea_cell || by_sea ? 255 : 0;
			s->closed[c] = sea_cell ? 255 : 0;
			for (int k = 0; k < nlv && sea_cell; k++)
				if (lab[c] == own[k] && s->closed[c] == 255)
					s->closed[c] = (uint8_t)(k + 1);
		}
	free(keep);
	free(area);
	free(lab);
	free(below);
	return bad;
}

static int os_create(struct node *n, struct node_parse *p)
{
	const char *rel;
	double sea, min_km2, lv[3 * OPENSEA_MAX_LEVELS];
	int rc, nlv;
	if ((rc = np_string(p, "path", NULL, &rel)) ||
	    (rc = np_double(p, "sea_level", 0, -1e5, 1e5, &sea)) ||
	    (rc = np_double(p, "min_area", 100000, 0, 1e9, &min_km2)) ||
	    (rc = np_doubles(p, "levels", lv, 3 * OPENSEA_MAX_LEVELS, &nlv)))
		return rc;
	if (nlv % 3)
		return np_error(p, "levels", "expected \"LAT LON LEVEL, …\" (a point in a closed "
					     "sea and its surface in metres), got %d numbers", nlv);
	for (int k = 0; k < nlv; k += 3)
		if (fabs(lv[k]) > 90 || fabs(lv[k + 1]) > 360 || fabs(lv[k + 2]) > 3000)
			return np_error(p, "levels", "%g %g %g: expected a latitude, a longitude "
						     "and metres (within ±3000: the sea grid's range)",
					lv[k], lv[k + 1], lv[k + 2]);
	if (!rel || !rel[0])
		return np_error(p, "path", "missing: a global height raster (e.g. the one the "
					   "planet's heights come from)");
	char *path = planet_resolve_path(n->planet, rel);
	struct stat st;
	uint8_t digest[16];
	char err[256];
	if (stat(path, &st) != 0) {
		rc = np_error(p, "path", "cannot open %s: %s", path, strerror(errno));
		free(path);
		return rc;
	}
	if ((rc = file_digest(path, &st, FILE_DIGEST_CACHE_MIN, digest, err))) {
		free(path);
		return np_error(p, "path", "%s", err);
	}
	np_hash_bytes(p, digest, sizeof digest);
	struct img_cache *own = NULL, *c = n->planet ? n->planet->images : NULL;
	if (!c)
		c = own = img_cache_create(64);
	struct img_info info;
	rc = img_cache_info(c, path, &info, err);
	int lev = 0, w = 0, h = 0;
	if (rc == 0)
		while ((rc = img_cache_level_size(c, path, lev, &w, &h, err)) == 0 &&
		       w > OPENSEA_MAX_W && lev + 1 < info.mip_levels)
			lev++;
	if (rc)
		rc = np_error(p, "path", "cannot read %s", err);
	else if (w < 4 || (h != w / 2 && h != w / 2 + 1))
		rc = np_error(p, "path", "%s is %d × %d: open_sea reads a global equirectangular "
					 "raster, twice as wide as high (or one row more: "
					 "grid-registered, as ETOPO5)",
			      path, w, h);
	float *hv = NULL;
	if (rc == 0) {
		hv = xmalloc((size_t)w * h * sizeof *hv);
		if (img_cache_read(c, path, lev, 0, w, 0, h, 0, 1, IMG_F32, hv, 0, err))
			rc = np_error(p, "path", "cannot read %s", err);
	}
	img_cache_unref(own);
	free(path);
	if (rc) {
		free(hv);
		return rc;
	}
	struct open_sea *s = xcalloc(1, sizeof *s);
	s->w = w;
	s->h = h;
	s->point = h == w / 2 + 1;
	s->m = xmalloc((size_t)w * h);
	s->closed = xmalloc((size_t)w * h);
	int bad = build_mask(s, hv, sea, min_km2, n->planet ? n->planet->a : 6371000.0, lv,
			     nlv / 3);
	free(hv);
	if (bad) {
		n->impl = s;
		os_destroy(n);
		int k = bad > 0 ? bad - 1 : -bad - 1;
		if (bad < 0)
			return np_error(p, "levels", "%g %g: in the same closed sea as a point before "
						     "it (one point a sea)",
					lv[3 * k], lv[3 * k + 1]);
		return np_error(p, "levels", "%g %g: no closed sea there (below sea level, apart "
					     "from the ocean, at least min_area)",
				lv[3 * k], lv[3 * k + 1]);
	}
	n->impl = s;
	n->out = PIX_HEIGHT;
	return 0;
}

bool open_sea_level(const struct node *n, double lat, double lon, double reach, double *level,
		    bool *mixed)
{
	if (!n || n->type != &node_type_open_sea || !n->impl)
		return false;
	const struct open_sea *s = n->impl;
	*level = 0;
	if (mixed)
		*mixed = false;
	/* the rows and columns whose centres lie within reach (degrees) of the point */
	double cx, cy;
	cell_coords(s, lon, lat, &cx, &cy);
	double ry = reach / 180 * (s->point ? s->h - 1 : s->h), rx = reach / 360 * s->w;
	int y0 = (int)ceil(cy - ry), y1 = (int)floor(cy + ry);
	int x0 = (int)ceil(cx - rx), x1 = (int)floor(cx + rx);
	y0 = y0 < 0 ? 0 : y0;
	y1 = y1 > s->h - 1 ? s->h - 1 : y1;
	int found = 0;
	bool other = false;
	for (int y = y0; y <= y1 && !(found && other); y++)
		for (int x = x0; x <= x1 && !(found && other); x++) {
			int k = s->closed[(size_t)y * s->w + (size_t)(((x % s->w) + s->w) % s->w)];
			if (k == 255)
				other = true;
			else if (k && !found)
				found = k;
			else if (k && s->level[k - 1] != s->level[found - 1])
				other = true;
		}
	if (found) {
		*level = s->level[found - 1];
		if (mixed)
			*mixed = other;
	}
	return true;
}

/* One axis of the mask's bilinear lookup between cell centres: the two cells (columns wrap,
 * rows clamp at the poles) and the second one's weight. */
struct os_tap {
	int c0, c1;
	double t;
};

/* Whether every cell of rows r0..r1 and columns c0, c0 + 1, …, c0 + nc − 1 (mod w) is v. */
static bool os_cells_all(const struct open_sea *s, int r0, int r1, int c0, int nc, uint8_t v)
{
	for (int y = r0; y <= r1; y++) {
		const uint8_t *row = s->m + (size_t)y * s->w;
		for (int i = 0, x = c0; i < nc; i++, x = x + 1 == s->w ? 0 : x + 1)
			if (row[x] != v)
				return false;
	}
	return true;
}

/* Footprints up to this many cells are checked for a uniform tile (a 256² tile of Earth's
 * level 6 covers 34 × 17 ETOPO5 cells; every finer one a few): coarser ones are computed. */
#define OS_UNIFORM_MAX_CELLS 65536

static int os_generate(const struct node *n, struct gen_ctx *gc, const struct tile_key *k,
		       struct tile *const *in, int nin, struct tile *out)
{
	(void)in;
	(void)nin;
	const struct open_sea *s = n->impl;
	uint32_t T = out->size;
	/* The lookup is separable (the cell column follows longitude, the row latitude): one
	 * tap per column and per row, then two lerps a texel. */
	struct os_tap *cx = gen_scratch(gc, (size_t)2 * T * sizeof *cx), *cy = cx + T;
	double fx_first = 0, fx_last = 0;
	for (uint32_t i = 0; i < T; i++) {
		double lon, lat, fx, fy;
		grid_texel_center(k, T, i, i, &lon, &lat);
		cell_coords(s, lon, lat, &fx, &fy);
		fx_first = i ? fx_first : fx;
		fx_last = fx;
		double x0f = floor(fx);
		int x0 = (((int)x0f % s->w) + s->w) % s->w;
		cx[i] = (struct os_tap){ x0, (x0 + 1) % s->w, fx - x0f };
		fy = fy < 0 ? 0 : fy > s->h - 1 ? s->h - 1 : fy;
		int y0 = (int)fy;
		cy[i] = (struct os_tap){ y0, y0 + 1 < s->h ? y0 + 1 : y0, fy - y0 };
	}
	/* Far from every coast (the open ocean, a continent's interior) all the cells the tile
	 * reads hold one value: the tile is that value throughout, the shared uniform tile (the
	 * lerps of equal values give it exactly), and the blends after it can tell. Columns
	 * run east from cx[0].c0 (wrapping) to cx[T − 1].c1; rows are monotonic southwards. */
	int r0 = cy[0].c0, r1 = cy[T - 1].c1;
	int nc = cx[T - 1].c1 - cx[0].c0;
	nc = (nc < 0 ? nc + s->w : nc) + 1;
	if (fx_last - fx_first + 2 < s->w &&
	    (size_t)(r1 - r0 + 1) * (size_t)nc <= OS_UNIFORM_MAX_CELLS) {
		uint8_t v = s->m[(size_t)r0 * s->w + cx[0].c0];
		if (os_cells_all(s, r0, r1, cx[0].c0, nc, v)) {
			float f = (float)(v / 255.0);
			tile_fill_uniform(out, &f);
			return 0;
		}
	}
	for (uint32_t j = 0; j < T; j++) {
		const uint8_t *a = s->m + (size_t)cy[j].c0 * s->w, *b = s->m + (size_t)cy[j].c1 * s->w;
		double ty = cy[j].t;
		float *row = tile_f32(out) + (size_t)j * T;
		for (uint32_t i = 0; i < T; i++) {
			int x0 = cx[i].c0, x1 = cx[i].c1;
			double tx = cx[i].t;
			double top = a[x0] + (a[x1] - a[x0]) * tx, bot = b[x0] + (b[x1] - b[x0]) * tx;
			row[i] = (float)((top + (bot - top) * ty) / 255);
		}
	}
	return 0;
}

const struct node_type node_type_open_sea = {
	.name = "open_sea",
	.doc = "where a sea may lie: the ocean and large closed basins, not dry depressions "
	       "(path, sea_level, min_area km², levels: LAT LON LEVEL of closed seas below it)",
	.version = 1,
	.nslots = 0,
	.costly = true,
	.create = os_create,
	.destroy = os_destroy,
	.generate = os_generate,
};
