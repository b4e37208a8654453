/* node_slope — `slope`: heights → the magnitude of their gradient |∇h| (rise over run: 0 flat,
 * 1 at 45°), by central differences with metric texel spacing from the body's ellipsoid (east
 * N(φ)·cos φ·Δλ, north M(φ)·Δφ, as the normal node). Read as a mask (through a height_filter)
 * it drives colour by steepness and detail amplitude by local relief.
 *
 * `scale` (metres, default 0: every level its own texels) fixes the distance the slope is
 * measured over: a level whose texels are finer than scale / 2 takes the slope of the finest
 * level ls whose texels are at least that (its "source level") and interpolates it with a
 * cubic B-spline (C2, weights ≥ 0: never past the field's own range) to its texel centres (a tile with lx < ly − ls, near a pole, keeps lx 0 in longitude). Every finer level so shows one smooth field: no colour popping from
 * level to level, no steps along the cells of a coarse raster (whose bilinear gradient is
 * piecewise constant), and no creases along the source level's rows and columns (bilinear's
 * were: a detail amplitude scaled by it showed straight lines across the Earth's mountains,
 * one 9.8 km apart each way, a seam under a camera flying along one).
 *
 * Seamless: deps() asks for the source level's tiles under the tile's footprint and three
 * texels around it (up to 3×3: x wraps, and beyond a pole the rows continue on the far side; on its
 * own level only the four edge neighbours, as the normal node, whose tiles those are), so a
 * texel's value depends only on its position and the heights, never on which tile holds it.
 * Near the poles the east spacing is held at ≥ 1/8 of the north one (the float differences
 * over millimetre-wide texels are rounding noise), so east slopes there read low, and the
 * slope fades to 0 over the source level's last texel before a pole: a slope is a direction
 * there, and the pole rows of every level must not depend on longitude. NaN heights give no
 * slope. Thread-safety: parameters are set in create; generate uses the worker's
 * scratch.
 */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/geo.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"

#define PAD 3 /* height texels around the footprint: the spline's two, plus the stencil's */

struct slope {
	int source_ly; /* the finest level whose texels are ≥ scale / 2; -1: every level its own */
};

/* Where tile k reads: the source level's tile holding its footprint, d levels up. */
struct footprint {
	struct tile_key src; /* the source tile (node = the input's hash) */
	int d;		     /* levels between k and src in latitude (ly) */
	int dx;		     /* and in longitude: d, or lx when lx < d (tiles near a pole) */
	uint32_t W, H;	     /* the source level's size in texels */
	int64_t u0, v0;	     /* the source tile's first texel */
	struct tile_key key[9];
	int ndeps;
};

static int slope_create(struct node *n, struct node_parse *p)
{
	double scale;
	int rc = np_double(p, "scale", 0, 0, 1e8, &scale);
	if (rc)
		return rc;
	if (!n->planet || !n->planet->body || !n->planet->tile_size)
		return np_error(p, NULL, "node \"%s\": the planet has no body (ellipsoid)", n->name);
	struct slope *s = xmalloc(sizeof *s);
	s->source_ly = -1;
	if (scale > 0) {
		uint32_t T = n->planet->tile_size;
		s->source_ly = 0;
		while (s->source_ly < 60 &&
		       M_PI * n->planet->a / (ldexp(1.0, s->source_ly + 1) * T) >= scale / 2)
			s->source_ly++;
	}
	n->impl = s;
	n->out = PIX_HEIGHT;
	return 0;
}

/* Global source texel (u, v), v possibly beyond a pole, → the texel it is on the sphere. */
static void wrap_texel(const struct footprint *f, int64_t *u, int64_t *v)
{
	if (*v < 0 || *v >= (int64_t)f->H) {
		*v = *v < 0 ? -1 - *v : 2 * (int64_t)f->H - 1 - *v;
		*u += f->W / 2;
	}
	*u %= (int64_t)f->W;
	if (*u < 0)
		*u += f->W;
}

/* Index of the dependency holding source texel (u, v) (already wrapped), or -1. */
static int find_dep(const struct footprint *f, int64_t u, int64_t v, uint32_t T)
{
	struct tile_key key = f->src;
	key.x = (uint32_t)(u / T);
	key.y = (uint32_t)(v / T);
	for (int i = 0; i < f->ndeps; i++)
		if (grid_key_equal(&f->key[i], &key))
			return i;
	return -1;
}

/* Adds the tile holding source texel (u, v) (already wrapped) to the deps if new. */
static void add_dep(struct footprint *f, int64_t u, int64_t v, uint32_t T)
{
	if (find_dep(f, u, v, T) >= 0)
		return;
	f->key[f->ndeps] = f->src;
	f->key[f->ndeps].x = (uint32_t)(u / T);
	f->key[f->ndeps].y = (uint32_t)(v / T);
	f->ndeps++;
}

static void footprint(const struct node *n, const struct tile_key *k, struct footprint *f)
{
	const struct slope *s = n->impl;
	const uint32_t T = n->planet->tile_size;
	int d = s->source_ly >= 0 && k->ly > s->source_ly ? k->ly - s->source_ly : 0;
	int dx = d < k->lx ? d : k->lx;
	f->d = d;
	f->dx = dx;
	f->src = (struct tile_key){ .node = n->in[0]->hash, .lx = (uint8_t)(k->lx - dx),
				    .ly = (uint8_t)(k->ly - d), .x = k->x >> dx, .y = k->y >> d };
	f->W = grid_tiles_x(f->src.lx) * T;
	f->H = grid_tiles_y(f->src.ly) * T;
	f->u0 = (int64_t)f->src.x * T;
	f->v0 = (int64_t)f->src.y * T;
	f->ndeps = 0;
	/* one texel before, the first one on and one after the tile, each way; the corners
	 * only when interpolating (on its own level no stencil reaches them) */
	const int64_t at[3] = { -1, 0, T };
	for (int j = 0; j < 3; j++)
		for (int i = 0; i < 3; i++) {
			if (d == 0 && i != 1 && j != 1)
				continue;
			int64_t u = f->u0 + at[i], v = f->v0 + at[j];
			wrap_texel(f, &u, &v);
			add_dep(f, u, v, T);
		}
}

static int slope_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	struct footprint f;
	footprint(n, k, &f);
	for (int i = 0; i < f.ndeps; i++) {
		out[i].node = n->in[0];
		out[i].key = f.key[i];
	}
	return f.ndeps;
}

/* Columns [c0, c1) of row r of the padded heights (padded texel (c, r) is source texel
 * (u0 + c − PAD, v0 + r − PAD)), copied run by run from the tiles that hold them. Returns 0,
 * or -EINVAL if one is not among the deps. */
static int gather_row(const struct footprint *f, struct tile *const *in, uint32_t T, uint32_t r,
		      uint32_t c0, uint32_t c1, float *dst)
{
	for (uint32_t c = c0; c < c1;) {
		int64_t u = f->u0 + (int64_t)c - PAD, v = f->v0 + (int64_t)r - PAD;
		wrap_texel(f, &u, &v);
		int dep = find_dep(f, u, v, T);
		if (dep < 0)
			return -EINVAL;
		uint32_t tu = (uint32_t)(u % T), run = T - tu;
		run = run < c1 - c ? run : c1 - c;
		memcpy(dst + c, tile_f32(in[dep]) + (size_t)(v % T) * T + tu, run * sizeof *dst);
		c += run;
	}
	return 0;
}

/* Slope at padded texels lo … hi of rows lo … hi into s (padded texel c at index c − 1). */
static void slope_field(const struct node *n, const struct footprint *f, const float *h,
			uint32_t T, uint32_t lo, uint32_t hi, float *s)
{
	const uint32_t PW = T + 2 * PAD, SW = T + 2 * PAD - 2;
	const double dlam = 2 * M_PI / f->W, dphi = M_PI / f->H;
	for (uint32_t r = lo; r <= hi; r++) {
		int64_t v = f->v0 + (int64_t)r - PAD;
		v = v < 0 ? -1 - v : v >= (int64_t)f->H ? 2 * (int64_t)f->H - 1 - v : v;
		double lat = grid_v_to_lat(f->src.ly, T, (double)v + 0.5), m, nr;
		geo_radii(n->planet->body, lat, &m, &nr);
		double dy = m * dphi, dx = nr * cos(lat * (M_PI / 180)) * dlam;
		dx = dx > dy / 8 ? dx : dy / 8;
		const float fx = (float)(1 / (2 * dx)), fy = (float)(1 / (2 * dy));
		const float *row = h + (size_t)r * PW, *up = row - PW, *dn = row + PW;
		float *o = s + (size_t)(r - 1) * SW;
		for (uint32_t c = lo; c <= hi; c++) {
			float gx = (row[c + 1] - row[c - 1]) * fx, gy = (up[c] - dn[c]) * fy;
			gx = gx == gx ? gx : 0.0f;
			gy = gy == gy ? gy : 0.0f;
			o[c - 1] = sqrtf(gx * gx + gy * gy);
		}
	}
}

/* Texel i of a tile d levels under the source, as a position in the slope field (whose index
 * 0 is source texel −2): the first of its four field indices *i0 … *i0 + 3 and their cubic
 * B-spline weights w[0..3]. */
static void fine_to_field(uint32_t sub, int d, uint32_t T, uint32_t i, uint32_t *i0, float w[4])
{
	double x = ((double)sub * T + i + 0.5) / ldexp(1.0, d) - 0.5 + 2;
	double fl = floor(x), t = x - fl, u = 1 - t;
	*i0 = (uint32_t)fl - 1;
	w[0] = (float)(u * u * u / 6);
	w[1] = (float)((3 * t * t * t - 6 * t * t + 4) / 6);
	w[2] = (float)((-3 * t * t * t + 3 * t * t + 3 * t + 1) / 6);
	w[3] = (float)(t * t * t / 6);
}

/* Rows of tile k within one source texel of a pole scaled by (distance to the pole in source
 * texels − ½), clamped to [0, 1]: 0 on the pole row of every level. */
static void pole_fade(const struct tile_key *k, const struct footprint *f, uint32_t T, float *o)
{
	const double src_texel = 180.0 / f->H;
	for (uint32_t j = 0; j < T; j++) {
		double lat = grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5);
		double w = (90 - fabs(lat)) / src_texel - 0.5;
		if (w >= 1)
			continue;
		float fw = w > 0 ? (float)w : 0.0f;
		for (uint32_t i = 0; i < T; i++)
			o[(size_t)j * T + i] *= fw;
	}
}

typedef float v4f __attribute__((vector_size(16)));

/* d = wy₀·a + wy₁·b + wy₂·c + wy₃·e over n texels: the vertical B-spline pass in vectors of
 * four, the scalar sums' operations in their order (GCC's -O2 leaves the plain loop scalar). */
static void bspline_rows(float *d, const float *a, const float *b, const float *c,
			 const float *e, const float wy[4], uint32_t n)
{
	const v4f w0 = { wy[0], wy[0], wy[0], wy[0] }, w1 = { wy[1], wy[1], wy[1], wy[1] };
	const v4f w2 = { wy[2], wy[2], wy[2], wy[2] }, w3 = { wy[3], wy[3], wy[3], wy[3] };
	uint32_t i = 0;
	for (; i + 4 <= n; i += 4) {
		v4f va, vb, vc, ve;
		memcpy(&va, a + i, sizeof va);
		memcpy(&vb, b + i, sizeof vb);
		memcpy(&vc, c + i, sizeof vc);
		memcpy(&ve, e + i, sizeof ve);
		v4f r = w0 * va + w1 * vb + w2 * vc + w3 * ve;
		memcpy(d + i, &r, sizeof r);
	}
	for (; i < n; i++)
		d[i] = wy[0] * a[i] + wy[1] * b[i] + wy[2] * c[i] + wy[3] * e[i];
}

static int slope_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	const uint32_t T = out->size;
	if (!n->planet || !n->planet->body || T != n->planet->tile_size)
		return -EINVAL;
	struct footprint f;
	footprint(n, k, &f);
	if (nin != f.ndeps)
		return -EINVAL;
	for (int i = 0; i < nin; i++)
		if (in[i]->type != PIX_HEIGHT || in[i]->size != T)
			return -EINVAL;
	const uint32_t PW = T + 2 * PAD, SW = T + 2 * PAD - 2;
	float *h = gen_scratch(g, ((size_t)PW * PW + (size_t)SW * SW + 5 * (size_t)T +
				   (size_t)SW * T) * sizeof *h);
	float *s = h + (size_t)PW * PW, *wx = s + (size_t)SW * SW, *sx = wx + 5 * (size_t)T;
	uint32_t *ix = (uint32_t *)(void *)(wx + 4 * (size_t)T);
	/* On its own level the slope is needed on the tile only (padded texels PAD … PAD + T − 1),
	 * from the heights one texel around it, corners excepted; interpolating, two texels more
	 * each way (the spline's reach), corners included. */
	const uint32_t lo = f.d ? PAD - 2 : PAD, hi = PW - 1 - lo;
	for (uint32_t r = lo - 1; r <= hi + 1; r++) {
		bool outside = r < PAD || r >= PAD + T;
		uint32_t c0 = outside && !f.d ? PAD : lo - 1, c1 = outside && !f.d ? PAD + T : hi + 2;
		if (gather_row(&f, in, T, r, c0, c1, h + (size_t)r * PW))
			return -EINVAL;
	}
	slope_field(n, &f, h, T, lo, hi, s);
	float *o = tile_f32(out);
	if (!f.d) {
		for (uint32_t j = 0; j < T; j++)
			memcpy(o + (size_t)j * T, s + (size_t)(j + PAD - 1) * SW + PAD - 1,
			       T * sizeof *o);
		pole_fade(k, &f, T, o);
		return 0;
	}
	const uint32_t mx = ((uint32_t)1 << f.dx) - 1, my = ((uint32_t)1 << f.d) - 1;
	for (uint32_t i = 0; i < T; i++)
		fine_to_field(k->x & mx, f.dx, T, i, &ix[i], wx + 4 * (size_t)i);
	/* Separable: the field rows the tile reaches, in x (sx), then each texel row in y. */
	uint32_t jlo, jhi;
	float wy[4];
	fine_to_field(k->y & my, f.d, T, 0, &jlo, wy);
	fine_to_field(k->y & my, f.d, T, T - 1, &jhi, wy);
	for (uint32_t r = jlo; r <= jhi + 3; r++) {
		const float *row = s + (size_t)r * SW;
		float *d = sx + (size_t)r * T;
		for (uint32_t i = 0; i < T; i++) {
			const float *w = wx + 4 * (size_t)i, *v = row + ix[i];
			d[i] = w[0] * v[0] + w[1] * v[1] + w[2] * v[2] + w[3] * v[3];
		}
	}
	for (uint32_t j = 0; j < T; j++) {
		uint32_t j0;
		fine_to_field(k->y & my, f.d, T, j, &j0, wy);
		const float *a = sx + (size_t)j0 * T;
		bspline_rows(o + (size_t)j * T, a, a + T, a + 2 * (size_t)T, a + 3 * (size_t)T, wy, T);
	}
	pole_fade(k, &f, T, o);
	return 0;
}

static const struct node_slot slope_slots[] = {
	{ .name = "input", .type = PIX_HEIGHT },
};

const struct node_type node_type_slope = {
	.name = "slope",
	.doc = "slope magnitude |grad h| of heights (metric, seamless), measured over `scale` m",
	.version = 2, /* 2: cubic B-spline between levels (was bilinear) */
	.slots = slope_slots,
	.nslots = 1,
	.create = slope_create,
	.destroy = node_free_impl,
	.deps = slope_deps,
	.generate = slope_generate,
};
