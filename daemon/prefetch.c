/* prefetch — see prefetch.h. A bbox level is enumerated arithmetically (rows of tile columns,
 * wrapping at the antimeridian). A path level is materialised as a sorted, deduplicated list:
 * points every half tile along each geodesic (GeographicLib geo_inverse / geo_direct) and
 * across the corridor, each mapped to its tile. Levels are built one at a time, so a job holds
 * one level's corridor at most (and at most PREFETCH_MAX_TILES keys in total are accepted). */
#include "prefetch.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/geo.h"
#include "common/xalloc.h"

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
	/* bbox level: columns x0 .. x0+ncols-1 (wrapping), rows y0 .. y1 */
	uint32_t x0, ncols, y0;
	/* path level */
	struct tile_key *list;
	size_t nlist;
};

static int cmp_key(const void *a, const void *b)
{
	const struct tile_key *x = a, *y = b;
	if (x->y != y->y)
		return x->y < y->y ? -1 : 1;
	if (x->x != y->x)
		return x->x < y->x ? -1 : 1;
	return 0;
}

static uint32_t lon_to_x(int lx, double lon)
{
	double t = (lon + 180.0) / 360.0 * (double)grid_tiles_x(lx);
	return grid_wrap_x(lx, (int64_t)floor(t));
}

static uint32_t lat_to_y(int ly, double lat)
{
	double t = (90.0 - lat) / 180.0 * (double)grid_tiles_y(ly);
	int64_t y = (int64_t)floor(t);
	int64_t max = (int64_t)grid_tiles_y(ly) - 1;
	return (uint32_t)(y < 0 ? 0 : y > max ? max : y);
}

/* Appends the tile under (lat, lon) to the list unless it equals the last one. */
static void add_point(struct prefetch_iter *it, size_t *cap, int ly, double lat, double lon)
{
	struct tile_key k = { .lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly,
			      .x = lon_to_x(ly + 1, lon), .y = lat_to_y(ly, lat) };
	if (it->nlist && it->list[it->nlist - 1].x == k.x && it->list[it->nlist - 1].y == k.y)
		return;
	if (it->nlist == *cap) {
		*cap = *cap ? *cap * 2 : 1024;
		it->list = xrealloc(it->list, *cap * sizeof *it->list);
	}
	it->list[it->nlist++] = k;
}

/* Builds the corridor's tile list for level ly. Returns 0 or -E2BIG (too many samples). */
static int build_path_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	free(it->list);
	it->list = NULL;
	it->nlist = 0;
	size_t cap = 0;
	double tile_m = M_PI * geo_body_a(body) / (double)grid_tiles_y(ly); /* north-south */
	uint64_t samples = 0;
	for (uint32_t i = 0; i < it->npts; i++) {
		double lat1 = it->pts[i].lat, lon1 = it->pts[i].lon;
		double s12 = 0, azi1 = 0, azi2 = 0;
		if (i + 1 < it->npts)
			geo_inverse(body, lat1, lon1, it->pts[i + 1].lat, it->pts[i + 1].lon, &s12,
				    &azi1, &azi2);
		double s = 0;
		for (;;) {
			double lat, lon;
			if (s > 0)
				geo_direct(body, lat1, lon1, azi1, s, &lat, &lon);
			else
				lat = lat1, lon = lon1;
			double c = fmax(cos(lat * M_PI / 180.0), 0.02);
			double step = tile_m * 0.5 * c;
			int kmax = (int)ceil(it->width * 0.5 / step);
			add_point(it, &cap, ly, lat, lon);
			for (int k = 1; k <= kmax; k++) {
				double off = fmin(k * step, it->width * 0.5), la, lo;
				geo_direct(body, lat, lon, azi1 + 90.0, off, &la, &lo);
				add_point(it, &cap, ly, la, lo);
				geo_direct(body, lat, lon, azi1 - 90.0, off, &la, &lo);
				add_point(it, &cap, ly, la, lo);
			}
			samples += 1 + 2 * (uint64_t)kmax;
			if (samples > 4 * (uint64_t)PREFETCH_MAX_TILES)
				return -E2BIG;
			if (s >= s12)
				break;
			s = fmin(s + step, s12);
		}
	}
	if (it->nlist) {
		qsort(it->list, it->nlist, sizeof *it->list, cmp_key);
		size_t n = 1;
		for (size_t i = 1; i < it->nlist; i++)
			if (cmp_key(&it->list[i], &it->list[n - 1]))
				it->list[n++] = it->list[i];
		it->nlist = n;
	}
	return 0;
}

static void bbox_level(struct prefetch_iter *it, int ly)
{
	int lx = ly + 1;
	const struct geo_rect *b = &it->bbox;
	uint32_t W = grid_tiles_x(lx);
	uint32_t xa = lon_to_x(lx, b->west);
	/* east edge: the tile holding the point just west of it */
	double e = b->east;
	double te = (e + 180.0) / 360.0 * W;
	int64_t xe = (int64_t)ceil(te) - 1;
	uint32_t xb = grid_wrap_x(lx, xe);
	uint32_t ncols = xb >= xa ? xb - xa + 1 : W - xa + xb + 1;
	if (b->west > b->east && ncols > W)
		ncols = W;
	if (b->west > b->east && xa == xb && ncols == 1 && b->west - b->east < 360.0)
		ncols = W; /* crosses the antimeridian and covers all but a sliver */
	it->x0 = xa;
	it->ncols = ncols > W ? W : ncols;
	it->y0 = lat_to_y(ly, b->north);
	double tn = (90.0 - b->south) / 180.0 * (double)grid_tiles_y(ly);
	int64_t ys = (int64_t)ceil(tn) - 1;
	uint32_t y1 = ys < (int64_t)it->y0 ? it->y0 : (uint32_t)ys;
	if (y1 >= grid_tiles_y(ly))
		y1 = grid_tiles_y(ly) - 1;
	it->ntiles = (uint64_t)it->ncols * (y1 - it->y0 + 1);
}

static int enter_level(struct prefetch_iter *it, int ly, struct geo_body *body)
{
	it->ly = ly;
	it->pos = 0;
	it->li = 0;
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
			int lx = it->ly + 1;
			key.lx = (uint8_t)lx;
			key.ly = (uint8_t)it->ly;
			key.x = grid_wrap_x(lx, (int64_t)it->x0 + (int64_t)(it->pos % it->ncols));
			key.y = it->y0 + (uint32_t)(it->pos / it->ncols);
		} else {
			key = it->list[it->pos];
		}
		const struct planet_layer *L = &it->p->layers[it->layers[it->li]];
		key.node = L->node->hash;
		out[k++] = (struct want){ .node = L->node, .key = key, .cls = SCHED_BULK };
		if (++it->li == it->nlayers) {
			it->li = 0;
			it->pos++;
		}
	}
	return k;
}

void prefetch_iter_destroy(struct prefetch_iter *it)
{
	if (!it)
		return;
	free(it->list);
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
