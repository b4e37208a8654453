/* prefetch — see prefetch.h. A level's tiles are what a clipmapview with its focus anywhere in
 * the region would ask for there (common/clipmap.h): the window of CLIPMAP_WINDOW_TILES tiles
 * centred on the focus and the ring around it, on every lx a viewer at that latitude may use.
 * A bbox level is a list of row segments (one per row and lx: a run of columns, wrapping at the
 * antimeridian), enumerated arithmetically. A path level is materialised as a sorted,
 * deduplicated list of keys: focus points every tile along each geodesic (GeographicLib) and
 * across the corridor (perpendicular to the geodesic's bearing at that point), each adding its
 * window and ring. Levels are built one at a time, so a job holds one level at most (and at
 * most PREFETCH_MAX_TILES keys in total are accepted). */
#include "prefetch.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "common/clipmap.h"
#include "common/errbuf.h"
#include "common/geo.h"
#include "common/xalloc.h"

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

/* Adds the window and ring of a viewer focused at (lat, lon), on every lx it may use there. */
static void add_focus(struct prefetch_iter *it, size_t *cap, size_t *compacted, int ly,
		      double lat, double lon)
{
	int lxa, lxb;
	clipmap_level_lx_range(ly, lat, lat, &lxa, &lxb);
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

/* Builds the corridor's tile list for level ly. Returns 0 or -E2BIG (too many samples). */
static int build_path_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	free(it->list);
	it->list = NULL;
	it->nlist = 0;
	size_t cap = 0, compacted = 0;
	/* a tile north-south: the focus points are a tile apart (a window reaches two tiles and
	 * its ring a third from its focus, so nothing between two points is missed) */
	double tile_m = M_PI * geo_body_a(body) / (double)grid_tiles_y(ly);
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
			/* across: a tile of longitude is cos(lat) shorter */
			double c = fmax(cos(lat * M_PI / 180.0), 0.02);
			double step = tile_m * c;
			int kmax = (int)ceil(it->width * 0.5 / step);
			add_focus(it, &cap, &compacted, ly, lat, lon);
			for (int k = 1; k <= kmax; k++) {
				double off = fmin(k * step, it->width * 0.5), la, lo;
				geo_direct(body, lat, lon, azi + 90.0, off, &la, &lo);
				add_focus(it, &cap, &compacted, ly, la, lo);
				geo_direct(body, lat, lon, azi - 90.0, off, &la, &lo);
				add_focus(it, &cap, &compacted, ly, la, lo);
			}
			samples += 1 + 2 * (uint64_t)kmax;
			if (samples > (uint64_t)PREFETCH_MAX_TILES / 8)
				return -E2BIG;
			if (s >= s12)
				break;
			s = fmin(s + step, s12);
		}
	}
	compact(it);
	return 0;
}

/* Tile row y's latitude band at level ly. */
static void row_lats(int ly, uint32_t y, double *south, double *north)
{
	double h = 180.0 / (double)grid_tiles_y(ly);
	*north = 90.0 - h * y;
	*south = *north - h;
}

static void bbox_level(struct prefetch_iter *it, int ly)
{
	const struct geo_rect *b = &it->bbox;
	free(it->segs);
	it->segs = NULL;
	it->nsegs = 0;
	it->ntiles = 0;
	size_t cap = 0;
	/* rows: from the northernmost viewer's window to the southernmost's */
	uint32_t ya, yb, y0, y1;
	window_rows(it, ly, b->north, &y0, &ya);
	window_rows(it, ly, b->south, &yb, &y1);
	(void)ya;
	(void)yb;
	double span = b->west <= b->east ? b->east - b->west : b->east + 360.0 - b->west;
	double reach = (CLIPMAP_REACH_TILES + 1) * 180.0 / (double)grid_tiles_y(ly);
	for (uint32_t y = y0; y <= y1; y++) {
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
			if (it->nsegs == cap) {
				cap = cap ? cap * 2 : 64;
				it->segs = xrealloc(it->segs, cap * sizeof *it->segs);
			}
			it->segs[it->nsegs++] = (struct segment){ x0, n, y, (uint8_t)lx };
			it->ntiles += n;
		}
	}
}

static int enter_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	it->ly = ly;
	it->pos = 0;
	it->li = 0;
	it->seg = 0;
	it->col = 0;
	if (it->shape == PROTO_SHAPE_BBOX) {
		bbox_level(it, ly);
		return 0;
	}
	int rc = build_path_level(it, ly, body);
	it->ntiles = it->nlist;
	return rc;
}

int prefetch_iter_create(const struct planet *p, const struct proto_prefetch *m,
			 struct prefetch_iter **out, uint64_t *total, char err[256])
{
	*out = NULL;
	if (m->lmax > p->max_level) {
		err_set(err, "level %u is finer than planet %s's max_level %d", m->lmax, p->name,
			p->max_level);
		return -EINVAL;
	}
	if (m->shape != PROTO_SHAPE_BBOX && m->shape != PROTO_SHAPE_PATH) {
		err_set(err, "unknown shape %u", m->shape);
		return -EINVAL;
	}
	struct prefetch_iter *it = xcalloc(1, sizeof *it);
	it->p = p;
	it->shape = m->shape;
	it->lmin = m->lmin;
	it->lmax = m->lmax;
	it->bbox = m->bbox;
	it->width = m->width_m;
	for (size_t i = 0; i < p->nlayers; i++)
		if (m->layers == 0 || (m->layers >> i) & 1)
			it->layers[it->nlayers++] = (int)i;
	if (m->layers >> p->nlayers || it->nlayers == 0) {
		err_set(err, "layer mask 0x%llx names layers planet %s does not have (it has %zu)",
			(unsigned long long)m->layers, p->name, p->nlayers);
		free(it);
		return -EINVAL;
	}
	if (m->shape == PROTO_SHAPE_PATH) {
		it->npts = m->npoints;
		it->pts = xmalloc(m->npoints * sizeof *it->pts);
		memcpy(it->pts, m->points, m->npoints * sizeof *it->pts);
	}
	uint64_t t = 0;
	int rc = 0;
	for (int ly = it->lmin; ly <= it->lmax && !rc; ly++) {
		rc = enter_level(it, ly, p->body);
		t += it->ntiles * (uint64_t)it->nlayers;
		if (!rc && t > PREFETCH_MAX_TILES)
			rc = -E2BIG;
	}
	if (!rc)
		rc = enter_level(it, it->lmin, p->body);
	if (rc) {
		err_set(err, "prefetch job too large: more than %u tiles", PREFETCH_MAX_TILES);
		prefetch_iter_destroy(it);
		return rc;
	}
	*total = t;
	*out = it;
	return 0;
}

size_t prefetch_iter_next(struct prefetch_iter *it, struct want *out, size_t n)
{
	size_t k = 0;
	while (k < n) {
		if (it->pos >= it->ntiles) {
			if (it->ly >= it->lmax)
				break;
			if (enter_level(it, it->ly + 1, it->p->body))
				break; /* counted at creation: cannot happen */
			continue;
		}
		struct tile_key key;
		if (it->shape == PROTO_SHAPE_BBOX) {
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
			if (it->shape == PROTO_SHAPE_BBOX && ++it->col == it->segs[it->seg].n) {
				it->col = 0;
				it->seg++;
			}
		}
	}
	return k;
}

void prefetch_iter_destroy(struct prefetch_iter *it)
{
	if (!it)
		return;
	free(it->list);
	free(it->segs);
	free(it->pts);
	free(it);
}

static void refill(struct prefetch_job *j)
{
	if (!j->exhausted && j->nwin <= PREFETCH_WINDOW / 2) {
		size_t got = prefetch_iter_next(j->it, j->win + j->nwin, PREFETCH_WINDOW - j->nwin);
		if (got == 0)
			j->exhausted = true;
		if (got) {
			j->nwin += got;
			(void)sched_req_want(j->req, j->win, j->nwin);
		}
	}
	if (j->exhausted && j->nwin == 0 && j->state == PROTO_JOB_RUNNING)
		j->state = j->failed ? PROTO_JOB_FAILED : PROTO_JOB_DONE;
}

int prefetch_job_create(const struct planet *p, const struct proto_prefetch *m, uint64_t now_ns,
			struct prefetch_job **out, char err[256])
{
	*out = NULL;
	struct prefetch_job *j = xcalloc(1, sizeof *j);
	int rc = prefetch_iter_create(p, m, &j->it, &j->total, err);
	if (rc) {
		free(j);
		return rc;
	}
	j->id = m->id;
	j->state = PROTO_JOB_RUNNING;
	j->t0_ns = j->last_ns = now_ns;
	*out = j;
	return 0;
}

void prefetch_job_start(struct prefetch_job *j)
{
	refill(j);
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
	prefetch_iter_destroy(j->it);
	free(j);
}
