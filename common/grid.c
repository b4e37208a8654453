/* grid — see grid.h for the conventions. Everything here is integer or double arithmetic on
 * values, no state. */
#include "grid.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>

bool grid_level_valid(int lx, int ly)
{
	return ly >= 0 && ly <= GRID_MAX_LEVEL && lx >= 0 && lx <= GRID_MAX_LEVEL && lx <= ly + 1;
}

bool grid_key_valid(const struct tile_key *k)
{
	return grid_level_valid(k->lx, k->ly) && k->x < grid_tiles_x(k->lx) &&
	       k->y < grid_tiles_y(k->ly);
}

uint32_t grid_wrap_x(int lx, int64_t x)
{
	int64_t n = (int64_t)1 << lx;
	int64_t m = x % n;
	return (uint32_t)(m < 0 ? m + n : m);
}

bool grid_key_equal(const struct tile_key *a, const struct tile_key *b)
{
	return a->node == b->node && a->x == b->x && a->y == b->y && a->lx == b->lx &&
	       a->ly == b->ly;
}

static uint64_t mix64(uint64_t z)
{
	z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
	z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
	return z ^ (z >> 31);
}

uint64_t grid_key_hash(const struct tile_key *k)
{
	uint64_t pos = ((uint64_t)k->x << 32 | k->y) ^ ((uint64_t)k->lx << 58 | (uint64_t)k->ly << 52);
	return mix64(mix64(k->node) ^ mix64(pos + 0x9e3779b97f4a7c15ULL));
}

double grid_u_to_lon(int lx, uint32_t T, double u)
{
	return -180.0 + u * (360.0 / ((double)grid_tiles_x(lx) * T));
}

double grid_v_to_lat(int ly, uint32_t T, double v)
{
	return 90.0 - v * (180.0 / ((double)grid_tiles_y(ly) * T));
}

double grid_lon_to_u(int lx, uint32_t T, double lon)
{
	return (lon + 180.0) * ((double)grid_tiles_x(lx) * T / 360.0);
}

double grid_lat_to_v(int ly, uint32_t T, double lat)
{
	return (90.0 - lat) * ((double)grid_tiles_y(ly) * T / 180.0);
}

void grid_tile_rect(const struct tile_key *k, struct geo_rect *r)
{
	double w = 360.0 / grid_tiles_x(k->lx), h = 180.0 / grid_tiles_y(k->ly);
	r->west = -180.0 + k->x * w;
	r->east = r->west + w;
	r->north = 90.0 - k->y * h;
	r->south = r->north - h;
}

void grid_texel_center(const struct tile_key *k, uint32_t T, uint32_t i, uint32_t j, double *lon,
		       double *lat)
{
	*lon = grid_u_to_lon(k->lx, T, (double)k->x * T + i + 0.5);
	*lat = grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5);
}

static bool step_valid(int dlx, int dly)
{
	return (dlx == 0 || dlx == 1) && (dly == 0 || dly == 1) && (dlx | dly);
}

int grid_parent(const struct tile_key *k, int dlx, int dly, uint32_t T, struct tile_key *parent,
		uint32_t *off_x, uint32_t *off_y)
{
	if (!step_valid(dlx, dly) || k->lx < dlx || k->ly < dly ||
	    !grid_level_valid(k->lx - dlx, k->ly - dly))
		return -EINVAL;
	*parent = *k;
	parent->lx = (uint8_t)(k->lx - dlx);
	parent->ly = (uint8_t)(k->ly - dly);
	parent->x = k->x >> dlx;
	parent->y = k->y >> dly;
	if (off_x)
		*off_x = dlx ? (k->x & 1) * (T / 2) : 0;
	if (off_y)
		*off_y = dly ? (k->y & 1) * (T / 2) : 0;
	return 0;
}

int grid_children(const struct tile_key *k, int dlx, int dly, struct tile_key out[4])
{
	if (!step_valid(dlx, dly) || !grid_level_valid(k->lx + dlx, k->ly + dly))
		return -EINVAL;
	int n = 0;
	for (uint32_t j = 0; j <= (uint32_t)dly; j++) {
		for (uint32_t i = 0; i <= (uint32_t)dlx; i++) {
			out[n] = *k;
			out[n].lx = (uint8_t)(k->lx + dlx);
			out[n].ly = (uint8_t)(k->ly + dly);
			out[n].x = (k->x << dlx) + i;
			out[n].y = (k->y << dly) + j;
			n++;
		}
	}
	return n;
}

int grid_neighbor(const struct tile_key *k, int dx, int dy, struct tile_key *out, bool *flip)
{
	int64_t ny = grid_tiles_y(k->ly);
	int64_t x = (int64_t)k->x + dx, y = (int64_t)k->y + dy;
	*out = *k;
	*flip = false;
	if (y < 0 || y >= ny) {
		/* Across a pole: the same row on the far side of the globe. */
		y = y < 0 ? 0 : ny - 1;
		x += grid_tiles_x(k->lx) / 2;
		*flip = true;
	}
	out->x = grid_wrap_x(k->lx, x);
	out->y = (uint32_t)y;
	return 0;
}

/* The tiles q's window touches (tx0, ty0, ntx, nty), from its origin and extent. */
static void touched_tiles(struct grid_quad *q)
{
	int64_t T = q->T;
	q->tx0 = (uint32_t)(q->u0 / T);
	q->ty0 = (uint32_t)(q->v0 / T);
	q->ntx = (uint8_t)((q->u0 % T + q->w + T - 1) / T);
	q->nty = (uint8_t)((q->v0 % T + q->h + T - 1) / T);
}

void grid_window(int lx, int ly, uint32_t T, uint32_t S, double lon, double lat,
		 struct grid_quad *q)
{
	int64_t W = (int64_t)grid_tiles_x(lx) * T, H = (int64_t)grid_tiles_y(ly) * T;
	int64_t w = W < S ? W : S, h = H < S ? H : S;
	double fu = grid_lon_to_u(lx, T, lon), fv = grid_lat_to_v(ly, T, lat);
	int64_t u0 = W <= S ? 0 : (int64_t)floor(fu - S / 2.0 + 0.5);
	int64_t v0 = (int64_t)floor(fv - S / 2.0 + 0.5);
	u0 %= W;
	if (u0 < 0)
		u0 += W;
	if (v0 > H - h)
		v0 = H - h;
	if (v0 < 0)
		v0 = 0;
	q->lx = (uint8_t)lx;
	q->ly = (uint8_t)ly;
	q->T = T;
	q->S = S;
	q->u0 = u0;
	q->v0 = v0;
	q->w = (uint32_t)w;
	q->h = (uint32_t)h;
	touched_tiles(q);
}

void grid_quad(int lx, int ly, uint32_t T, double lon, double lat, struct grid_quad *q)
{
	grid_window(lx, ly, T, T, lon, lat, q);
}

int grid_quad_tiles(const struct grid_quad *q, uint64_t node, struct tile_key *out)
{
	int n = 0;
	for (uint32_t j = 0; j < q->nty; j++)
		for (uint32_t i = 0; i < q->ntx; i++)
			out[n++] = (struct tile_key){ node, grid_wrap_x(q->lx, (int64_t)q->tx0 + i),
						      q->ty0 + j, q->lx, q->ly };
	return n;
}

bool grid_quad_equal(const struct grid_quad *a, const struct grid_quad *b)
{
	return a->lx == b->lx && a->ly == b->ly && a->T == b->T && a->S == b->S &&
	       a->u0 == b->u0 && a->v0 == b->v0 && a->w == b->w && a->h == b->h;
}

void grid_window_core(const struct grid_quad *q, uint32_t w, struct grid_quad *out)
{
	int64_t T = q->T, W = (int64_t)grid_tiles_x(q->lx) * T, H = (int64_t)grid_tiles_y(q->ly) * T;
	*out = *q;
	/* columns: the middle of q's (they wrap), unless q holds whole parallels: then all */
	if (w < q->w && (int64_t)q->w < W) {
		out->u0 = (q->u0 + (int64_t)(q->w - w) / 2) % W;
		out->w = w;
	}
	/* rows: the middle of q's, unless q was kept inside the level at a pole's edge: then
	 * the core keeps to that edge too */
	if (w < q->h) {
		int64_t v0 = q->v0 + (int64_t)(q->h - w) / 2;
		if (q->v0 == 0)
			v0 = 0;
		else if (q->v0 + (int64_t)q->h >= H)
			v0 = H - w;
		out->v0 = v0;
		out->h = w;
	}
	touched_tiles(out);
}

double grid_window_rel_u(const struct grid_quad *q, double u)
{
	double W = (double)grid_tiles_x(q->lx) * q->T;
	double rel = fmod(u - (double)q->u0, W);
	if (rel < 0)
		rel += W;
	if (rel > (W + q->w) / 2)
		rel -= W;
	return rel;
}

/* Splits [a, a+len) at every tile border inside it and at the edges of [ia, ib) (the part
 * the old window already covered, in the same unwrapped frame; a ≥ 0). Returns the cut points,
 * ascending, first = a and last = a+len; the count of intervals is (return value − 1). */
static int cuts(int64_t a, int64_t len, int64_t T, int64_t ia, int64_t ib, int64_t *out)
{
	int n = 0;
	int64_t extra[2] = { ia, ib };
	int e = 0;
	if (extra[0] > extra[1]) {
		extra[0] = ib;
		extra[1] = ia;
	}
	/* merge the tile borders (in order) with the two edges (in order) */
	for (int64_t p = a;;) {
		while (e < 2 && extra[e] <= p) {
			if (extra[e] > a && extra[e] < a + len && (n == 0 || out[n - 1] != extra[e]))
				out[n++] = extra[e];
			e++;
		}
		if (n == 0 || out[n - 1] != p)
			out[n++] = p;
		if (p >= a + len)
			break;
		int64_t next = (p / T + 1) * T;
		p = next < a + len ? next : a + len;
	}
	return n;
}

/* The shortest wrapped delta from a to b on a circle of W. */
static int64_t wrapped_delta(int64_t a, int64_t b, int64_t W)
{
	int64_t d = (b - a) % W;
	if (d > W / 2)
		d -= W;
	if (d < -W / 2)
		d += W;
	return d;
}

int grid_update_regions(const struct grid_quad *prev, const struct grid_quad *next,
			struct grid_region *out)
{
	int64_t T = next->T, S = next->S;
	int64_t W = (int64_t)grid_tiles_x(next->lx) * T;
	/* The old window in next's unwrapped frame: x shifted by the shortest wrapped delta. */
	int64_t ia = next->u0, ib = next->u0, ja = next->v0, jb = next->v0;
	if (prev && prev->lx == next->lx && prev->ly == next->ly && prev->T == T &&
	    prev->S == S) {
		int64_t du = W <= S ? 0 : wrapped_delta(prev->u0, next->u0, W);
		int64_t dv = next->v0 - prev->v0;
		if (du < prev->w && du > -(int64_t)next->w && dv < prev->h &&
		    dv > -(int64_t)next->h) {
			ia = next->u0 - du;
			ib = ia + prev->w;
			ja = next->v0 - dv;
			jb = ja + prev->h;
		}
	}
	int64_t xs[GRID_WINDOW_MAX_TILES + 5], ys[GRID_WINDOW_MAX_TILES + 5];
	int nx = cuts(next->u0, next->w, T, ia, ib, xs) - 1;
	int ny = cuts(next->v0, next->h, T, ja, jb, ys) - 1;
	int n = 0;
	for (int j = 0; j < ny; j++) {
		for (int i = 0; i < nx; i++) {
			if (ia < ib && xs[i] >= ia && xs[i + 1] <= ib && ys[j] >= ja && ys[j + 1] <= jb)
				continue; /* held */
			struct grid_region *r = &out[n++];
			r->x = (uint32_t)(xs[i] % S);
			r->y = (uint32_t)(ys[j] % S);
			r->w = (uint32_t)(xs[i + 1] - xs[i]);
			r->h = (uint32_t)(ys[j + 1] - ys[j]);
			r->tx = grid_wrap_x(next->lx, xs[i] / T);
			r->ty = (uint32_t)(ys[j] / T);
			r->sx = (uint32_t)(xs[i] % T);
			r->sy = (uint32_t)(ys[j] % T);
		}
	}
	return n;
}

uint32_t grid_quad_distance(const struct grid_quad *q, const struct tile_key *k)
{
	if (k->lx != q->lx || k->ly != q->ly)
		return UINT32_MAX;
	int64_t nx = grid_tiles_x(q->lx);
	/* x: past the window's columns eastwards, or short of them (the short way round) */
	int64_t d = ((int64_t)k->x - q->tx0) % nx;
	if (d < 0)
		d += nx;
	int64_t dx = 0;
	if (d >= q->ntx) {
		dx = d - (q->ntx - 1);
		if (nx - d < dx)
			dx = nx - d;
	}
	int64_t dy = 0, y1 = (int64_t)q->ty0 + q->nty - 1;
	if (k->y < q->ty0)
		dy = q->ty0 - k->y;
	else if (k->y > y1)
		dy = k->y - y1;
	return (uint32_t)(dx > dy ? dx : dy);
}

double grid_band_equator_lat(double a, double b)
{
	return fmin(a, b) <= 0 && fmax(a, b) >= 0 ? 0 : fmin(fabs(a), fabs(b));
}
