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

void grid_quad(int lx, int ly, uint32_t T, double lon, double lat, struct grid_quad *q)
{
	int64_t W = (int64_t)grid_tiles_x(lx) * T, H = (int64_t)grid_tiles_y(ly) * T;
	double fu = grid_lon_to_u(lx, T, lon), fv = grid_lat_to_v(ly, T, lat);
	int64_t u0 = (int64_t)floor(fu - T / 2.0 + 0.5);
	int64_t v0 = (int64_t)floor(fv - T / 2.0 + 0.5);
	u0 %= W;
	if (u0 < 0)
		u0 += W;
	if (v0 < 0)
		v0 = 0;
	if (v0 > H - T)
		v0 = H - T;
	q->lx = (uint8_t)lx;
	q->ly = (uint8_t)ly;
	q->T = T;
	q->u0 = u0;
	q->v0 = v0;
	q->tx[0] = (uint32_t)(u0 / T);
	q->tx[1] = grid_wrap_x(lx, (int64_t)q->tx[0] + 1);
	q->ty[0] = (uint32_t)(v0 / T);
	q->ty[1] = q->ty[0] + 1 < grid_tiles_y(ly) ? q->ty[0] + 1 : q->ty[0];
}

int grid_quad_tiles(const struct grid_quad *q, uint64_t node, struct tile_key out[4])
{
	/* A window aligned to tile borders touches one tile along that axis; a level one tile
	 * across longitude has both cells on the same column. */
	int ni = (q->u0 % q->T == 0 || q->tx[1] == q->tx[0]) ? 1 : 2;
	int nj = (q->v0 % q->T == 0 || q->ty[1] == q->ty[0]) ? 1 : 2;
	int n = 0;
	for (int j = 0; j < nj; j++) {
		for (int i = 0; i < ni; i++) {
			out[n].node = node;
			out[n].lx = q->lx;
			out[n].ly = q->ly;
			out[n].x = q->tx[i];
			out[n].y = q->ty[j];
			n++;
		}
	}
	return n;
}

bool grid_quad_equal(const struct grid_quad *a, const struct grid_quad *b)
{
	return a->lx == b->lx && a->ly == b->ly && a->T == b->T && a->u0 == b->u0 &&
	       a->v0 == b->v0;
}

/* Splits [a, a+T) at the tile border inside it and at the edges of [ia, ib) (the part the old
 * window already covered, in the same unwrapped frame). Returns the cut points, ascending,
 * first = a and last = a+T; the count of intervals is (return value - 1). */
static int cuts(int64_t a, int64_t T, int64_t ia, int64_t ib, int64_t out[5])
{
	int64_t pts[4] = { a, a + T, 0, 0 };
	int n = 2;
	int64_t border = (a / T + 1) * T; /* a ≥ 0 in every frame used here */
	if (a % T != 0)
		pts[n++] = border;
	if (ia > a && ia < a + T)
		pts[n++] = ia;
	if (ib > a && ib < a + T)
		pts[n++] = ib;
	/* sort and dedupe (n ≤ 5) */
	for (int i = 1; i < n; i++)
		for (int j = i; j > 0 && pts[j - 1] > pts[j]; j--) {
			int64_t t = pts[j];
			pts[j] = pts[j - 1];
			pts[j - 1] = t;
		}
	int m = 0;
	for (int i = 0; i < n; i++)
		if (m == 0 || pts[i] != out[m - 1])
			out[m++] = pts[i];
	return m;
}

int grid_update_regions(const struct grid_quad *prev, const struct grid_quad *next,
			struct grid_region out[9])
{
	int64_t T = next->T;
	int64_t W = (int64_t)grid_tiles_x(next->lx) * T;
	/* The old window in next's unwrapped frame: x shifted by the shortest wrapped delta. */
	int64_t ia = 0, ib = 0, ja = 0, jb = 0;
	bool overlap = prev && prev->lx == next->lx && prev->ly == next->ly && prev->T == next->T;
	if (overlap) {
		int64_t du = (next->u0 - prev->u0) % W;
		if (du > W / 2)
			du -= W;
		if (du < -W / 2)
			du += W;
		int64_t dv = next->v0 - prev->v0;
		if (W == T)
			du = 0; /* the window is the whole level: it cannot move in x */
		if (du >= T || du <= -T || dv >= T || dv <= -T)
			overlap = false;
		ia = next->u0 - du;
		ib = ia + T;
		ja = next->v0 - dv;
		jb = ja + T;
	}
	if (!overlap) {
		ia = ib = next->u0;
		ja = jb = next->v0;
	}
	int64_t xs[5], ys[5];
	int nx = cuts(next->u0, T, ia, ib, xs) - 1;
	int ny = cuts(next->v0, T, ja, jb, ys) - 1;
	int n = 0;
	for (int j = 0; j < ny; j++) {
		for (int i = 0; i < nx; i++) {
			bool held = xs[i] >= ia && xs[i + 1] <= ib && ys[j] >= ja && ys[j + 1] <= jb &&
				    ia < ib;
			if (held)
				continue;
			struct grid_region *r = &out[n++];
			r->x = (uint32_t)(xs[i] % T);
			r->y = (uint32_t)(ys[j] % T);
			r->w = (uint32_t)(xs[i + 1] - xs[i]);
			r->h = (uint32_t)(ys[j + 1] - ys[j]);
			r->qi = (uint8_t)(xs[i] / T != next->u0 / T);
			r->qj = (uint8_t)(ys[j] / T != next->v0 / T);
		}
	}
	return n;
}

uint32_t grid_quad_distance(const struct grid_quad *q, const struct tile_key *k)
{
	if (k->lx != q->lx || k->ly != q->ly)
		return UINT32_MAX;
	int64_t nx = grid_tiles_x(q->lx);
	/* x: distance to the nearer of the two quad columns, the short way round. */
	int64_t dx = INT64_MAX;
	for (int i = 0; i < 2; i++) {
		int64_t d = ((int64_t)k->x - q->tx[i]) % nx;
		if (d < 0)
			d += nx;
		if (nx - d < d)
			d = nx - d;
		if (d < dx)
			dx = d;
	}
	int64_t dy = 0;
	if (k->y < q->ty[0])
		dy = q->ty[0] - k->y;
	else if (k->y > q->ty[1])
		dy = k->y - q->ty[1];
	return (uint32_t)(dx > dy ? dx : dy);
}
