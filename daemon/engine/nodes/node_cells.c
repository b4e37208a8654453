/* node_cells — the `cells` node type: a patchwork of cells on the sphere (fields, pastures,
 * parcels), each cell one value, with optional borders between them (hedgerows, tracks,
 * ditches) — for colour detail below a raster's resolution where the land is farmed.
 *
 * The cells are the Voronoi cells of a jittered 3-D lattice (spacing `wavelength`, one feature
 * point per lattice cube, moved from its centre by up to ± jitter/2 of the spacing along each
 * axis, the lattice turned by a rotation drawn from the seed) cut by the sphere: convex
 * polygons about `wavelength` across, seamless everywhere (no tile, antimeridian or pole
 * enters their definition). Each cell's value is a hash of its lattice cube and the seed,
 * uniform in [0, 1).
 *
 * Parameters (planet file, [node NAME] with type = cells):
 *   seed        integer 0..4294967295 (default 0)
 *   wavelength  metres between cells (default 400): the lattice's spacing
 *   jitter      0..1 (default 0.9): how far feature points leave their cube's centre; 0 gives
 *               the lattice's own cubes cut by the sphere, 1 irregular polygons
 *   border      metres (default 0: none): the width of the borders between cells, where the
 *               value is −1 (a profile falling linearly to the cell's value at border/2 from
 *               the edge). A border narrower than a texel is drawn a texel wide and as faint
 *               as it is narrow (its share of the texel), so it neither flickers nor vanishes
 *               from level to level
 *   amplitude   metres per unit (default 1); offset: metres added (default 0)
 *   input       optional height node: output = input + offset + amplitude · value
 * Band limit: where a cell spans fewer than 4 texels of the level (latitude texels, one
 * decision per level so neighbouring tiles agree) the value fades to 0.5 (the cells' mean),
 * reached at 2 texels: a coarse level shows no aliased cells. Near a pole, the two texel rows
 * nearest it take the value at the pole itself: every level's pole rows are independent of
 * longitude.
 * Output: height (f32). Cost: 27 feature points per lattice cube a row enters, and 27
 * distances at a texel farther from the last one evaluated than that one was from the nearest
 * edge (or border): most texels of a level that shows the cells are that near, and cost a
 * rotation. Node `costly`: a blend masking it to farmland makes it only there.
 * Thread-safety: the impl is immutable after create.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <emmintrin.h>

#include "common/grid.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "noise.h"

struct cells {
	uint32_t seed;
	double lambda, jitter, border, amplitude, offset;
	double scale;	  /* lattice units per unit-sphere unit: radius / wavelength */
	double rot[3][3]; /* unit sphere → lattice orientation */
};

static const struct node_slot slots[] = {
	{ .name = "input", .type = PIX_HEIGHT, .optional = true },
};

/* Lattice cube (x, y, z)'s feature point (offset from the cube's corner, each coordinate in
 * 0.5 ± jitter/2) and value (uniform in [0, 1)): hashes of the cube and the seed. */
static void cube_point(const struct cells *c, int32_t x, int32_t y, int32_t z, double fp[3],
		       double *v)
{
	uint32_t h = noise_mix32(c->seed ^ 0x9e3779b9u);
	h = noise_mix32(h ^ (uint32_t)x);
	h = noise_mix32(h ^ (uint32_t)y * 0x85ebca6bu);
	h = noise_mix32(h ^ (uint32_t)z * 0xc2b2ae35u);
	for (int a = 0; a < 3; a++)
		fp[a] = 0.5 + c->jitter * (noise_mix32(h + 0x27d4eb2fu * (uint32_t)(a + 1)) / 4294967296.0 - 0.5);
	*v = noise_mix32(h + 0x165667b1u) / 4294967296.0;
}

/* A tile's cubes seen so far (direct-mapped by a hash of their coordinates): adjacent rows
 * cross the same cubes, whose points are then hashed once per tile, not once per row. */
#define CUBE_CACHE 2048
struct cube {
	int32_t x, y, z;
	bool used;
	double fp[3], v;
};

/* The 27 feature points round lattice cube b (relative to b's corner; float: within ±2 of it,
 * to 1e-7 of a cell) and their values, in lanes (a 28th, far away, pads them to vectors). */
#define LANES 28
struct block {
	int32_t b[3];
	bool valid;
	struct cube *cache; /* CUBE_CACHE entries; NULL: every cube hashed anew */
	_Alignas(16) float fx[LANES], fy[LANES], fz[LANES];
	double v[LANES];
};

static const struct cube *cube_get(const struct cells *c, struct cube *cache, int32_t x,
				   int32_t y, int32_t z)
{
	uint32_t h = ((uint32_t)x * 73856093u ^ (uint32_t)y * 19349663u ^ (uint32_t)z * 83492791u);
	struct cube *e = &cache[(h ^ h >> 13) & (CUBE_CACHE - 1)];
	if (!e->used || e->x != x || e->y != y || e->z != z) {
		e->x = x, e->y = y, e->z = z, e->used = true;
		cube_point(c, x, y, z, e->fp, &e->v);
	}
	return e;
}

static void block_fill(const struct cells *c, struct block *k, const int32_t b[3])
{
	int i = 0;
	for (int dz = -1; dz <= 1; dz++)
		for (int dy = -1; dy <= 1; dy++)
			for (int dx = -1; dx <= 1; dx++, i++) {
				struct cube own;
				const struct cube *e = &own;
				if (k->cache)
					e = cube_get(c, k->cache, b[0] + dx, b[1] + dy, b[2] + dz);
				else
					cube_point(c, b[0] + dx, b[1] + dy, b[2] + dz, own.fp, &own.v);
				k->fx[i] = (float)(dx + e->fp[0]);
				k->fy[i] = (float)(dy + e->fp[1]);
				k->fz[i] = (float)(dz + e->fp[2]);
				k->v[i] = e->v;
			}
	k->fx[27] = k->fy[27] = k->fz[27] = 1e9f;
	k->v[27] = 0;
	memcpy(k->b, b, sizeof k->b);
	k->valid = true;
}

/* Unit-sphere point p in lattice units. */
static void to_lattice(const struct cells *c, const double p[3], double q[3])
{
	for (int a = 0; a < 3; a++)
		q[a] = (c->rot[a][0] * p[0] + c->rot[a][1] * p[1] + c->rot[a][2] * p[2]) * c->scale;
}

/* The value at lattice point q: its cell's value, pulled to −1 within `half` (lattice units:
 * half the border's drawn width) of the cell's edge, by `faint` (0: no borders). *slack: how
 * far q may move (lattice units) with the value unchanged: the distance to the edge less
 * half (or the whole distance without borders; 0 inside a border). */
static double cells_at(const struct cells *c, struct block *k, const double q[3], double half,
		       double faint, double *slack)
{
	int32_t b[3];
	for (int a = 0; a < 3; a++) { /* floor, without a libm call on a baseline x86-64 */
		int32_t t = (int32_t)q[a];
		b[a] = t - (q[a] < t);
	}
	if (!k->valid || b[0] != k->b[0] || b[1] != k->b[1] || b[2] != k->b[2])
		block_fill(c, k, b);
	/* SSE2 (the x86-64 baseline), 4 lanes at a time: the squared distances, the nearest
	 * (the least, then its lane), then the edge — the nearest bisecting plane of the
	 * nearest point and another, at (d_j² − d_1²) / (2 |p_j − p_1|). */
	__m128 rx = _mm_set1_ps((float)(q[0] - b[0])), ry = _mm_set1_ps((float)(q[1] - b[1])),
	       rz = _mm_set1_ps((float)(q[2] - b[2]));
	__m128 d2[LANES / 4], lo = _mm_set1_ps(INFINITY);
	for (int i = 0; i < LANES / 4; i++) {
		__m128 x = _mm_sub_ps(rx, _mm_load_ps(k->fx + 4 * i));
		__m128 y = _mm_sub_ps(ry, _mm_load_ps(k->fy + 4 * i));
		__m128 z = _mm_sub_ps(rz, _mm_load_ps(k->fz + 4 * i));
		d2[i] = _mm_add_ps(_mm_add_ps(_mm_mul_ps(x, x), _mm_mul_ps(y, y)), _mm_mul_ps(z, z));
		lo = _mm_min_ps(lo, d2[i]);
	}
	lo = _mm_min_ps(lo, _mm_shuffle_ps(lo, lo, _MM_SHUFFLE(2, 3, 0, 1)));
	lo = _mm_min_ps(lo, _mm_shuffle_ps(lo, lo, _MM_SHUFFLE(1, 0, 3, 2)));
	int best = 0;
	for (int i = 0; i < LANES / 4; i++) {
		int m = _mm_movemask_ps(_mm_cmpeq_ps(d2[i], lo));
		if (m) {
			best = 4 * i + __builtin_ctz((unsigned)m);
			break;
		}
	}
	__m128 bx = _mm_set1_ps(k->fx[best]), by = _mm_set1_ps(k->fy[best]),
	       bz = _mm_set1_ps(k->fz[best]), two = _mm_set1_ps(2), tiny = _mm_set1_ps(1e-30f);
	__m128 em = _mm_set1_ps(INFINITY);
	for (int i = 0; i < LANES / 4; i++) {
		__m128 x = _mm_sub_ps(_mm_load_ps(k->fx + 4 * i), bx);
		__m128 y = _mm_sub_ps(_mm_load_ps(k->fy + 4 * i), by);
		__m128 z = _mm_sub_ps(_mm_load_ps(k->fz + 4 * i), bz);
		__m128 sep = _mm_sqrt_ps(
			_mm_add_ps(_mm_add_ps(_mm_mul_ps(x, x), _mm_mul_ps(y, y)), _mm_mul_ps(z, z)));
		__m128 dd = _mm_div_ps(_mm_sub_ps(d2[i], lo), _mm_add_ps(_mm_mul_ps(two, sep), tiny));
		/* the nearest point's own lane (sep 0, dd 0) is no edge */
		dd = _mm_or_ps(_mm_and_ps(_mm_cmpgt_ps(sep, tiny), dd),
			       _mm_andnot_ps(_mm_cmpgt_ps(sep, tiny), _mm_set1_ps(INFINITY)));
		em = _mm_min_ps(em, dd);
	}
	em = _mm_min_ps(em, _mm_shuffle_ps(em, em, _MM_SHUFFLE(2, 3, 0, 1)));
	em = _mm_min_ps(em, _mm_shuffle_ps(em, em, _MM_SHUFFLE(1, 0, 3, 2)));
	float edge = _mm_cvtss_f32(em);
	/* Points beyond the 27 cubes are at least g away (two cubes along an axis, moved in by
	 * jitter/2 at most): an edge with one of them lies at least (g − d_1) / 2 away, so the
	 * slack never reaches past what the block can tell (nearly always g − d_1 > 2·edge). */
	double fr = 1;
	for (int a = 0; a < 3; a++) {
		double r = q[a] - b[a];
		fr = fmin(fr, fmin(r, 1 - r));
	}
	double far = (1.5 - c->jitter / 2 + fr - sqrt((double)_mm_cvtss_f32(lo))) / 2;
	double reach = far < edge ? (far > 0 ? far : 0) : edge; /* what the slack may use */
	double v = k->v[best];
	if (faint <= 0) {
		*slack = reach;
		return v;
	}
	if (edge >= half) {
		*slack = reach > half ? reach - half : 0;
		return v;
	}
	*slack = 0;
	double e = (1 - edge / half) * faint;
	return v + (-1 - v) * e;
}

static int cells_create(struct node *n, struct node_parse *p)
{
	long seed;
	int rc;
	struct cells c = { 0 };
	if ((rc = np_int(p, "seed", 0, 0, 4294967295L, &seed)) ||
	    (rc = np_double(p, "wavelength", 400, 1, 1e8, &c.lambda)) ||
	    (rc = np_double(p, "jitter", 0.9, 0, 1, &c.jitter)) ||
	    (rc = np_double(p, "border", 0, 0, 1e7, &c.border)) ||
	    (rc = np_double(p, "amplitude", 1, -1e7, 1e7, &c.amplitude)) ||
	    (rc = np_double(p, "offset", 0, -1e7, 1e7, &c.offset)))
		return rc;
	if (!n->planet || !(n->planet->a > 0))
		return np_error(p, NULL, "cells node \"%s\": the planet has no radius", n->name);
	c.scale = n->planet->a / c.lambda;
	if (c.scale > 1e9)
		return np_error(p, "wavelength",
				"%g m on a planet of radius %g m: more than 1e9 cells across; at "
				"least %g m",
				c.lambda, n->planet->a, n->planet->a / 1e9);
	if (c.border >= c.lambda)
		return np_error(p, "border", "%g m is not narrower than the cells (wavelength %g m)",
				c.border, c.lambda);
	c.seed = (uint32_t)seed;
	noise_seed_rotation(c.seed, c.rot);
	struct cells *im = xmalloc(sizeof *im);
	*im = c;
	n->impl = im;
	n->out = PIX_HEIGHT;
	return 0;
}

/* What a level draws: the cells' band weight w (1: shown whole, 0: their mean) and the borders:
 * half their drawn width (lattice units) and how faint — at least a texel wide, as faint as
 * they are narrower than that. */
struct level {
	double w, half, faint;
};

static struct level level_of(const struct node *n, const struct tile_key *k, uint32_t T)
{
	const struct cells *c = n->impl;
	double s = noise_texel_size(n->planet->a, k->ly, T);
	double drawn = fmax(c->border, s);
	return (struct level){ .w = noise_band_weight(c->lambda, s),
			       .half = drawn / 2 / c->lambda,
			       .faint = c->border > 0 ? c->border / drawn : 0 };
}

/* The two texel rows nearest a pole take the pole's own value. */
static bool pole_row(const struct tile_key *k, uint32_t T, double lat)
{
	return noise_pole_texels(lat, k->ly, T) < 2;
}

/* The output at unit-sphere point p (before an input is added), and its slack (cells_at). */
static float value_at(const struct cells *c, const struct level *L, struct block *k,
		      const double p[3], double *slack)
{
	double q[3];
	to_lattice(c, p, q);
	double v = L->w * cells_at(c, k, q, L->half, L->faint, slack) + (1 - L->w) * 0.5;
	return (float)c->offset + (float)c->amplitude * (float)v;
}

float cells_texel(const struct node *n, const struct tile_key *k, uint32_t T, uint32_t i,
		  uint32_t j)
{
	const struct cells *c = n->impl;
	struct level L = level_of(n, k, T);
	if (L.w <= 0)
		return (float)c->offset + (float)c->amplitude * 0.5f;
	double lon, lat, unused, slack;
	grid_texel_center(k, T, i, 0, &lon, &unused);
	grid_texel_center(k, T, 0, j, &unused, &lat);
	double cp = cos(lat * M_PI / 180), sp = sin(lat * M_PI / 180);
	double p[3] = { cp * cos(lon * M_PI / 180), cp * sin(lon * M_PI / 180), sp };
	if (pole_row(k, T, lat))
		p[0] = p[1] = 0, p[2] = lat > 0 ? 1 : -1;
	struct block blk = { .valid = false, .cache = NULL };
	return value_at(c, &L, &blk, p, &slack);
}

static int cells_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	const struct cells *c = n->impl;
	uint32_t T = out->size;
	if (out->type != PIX_HEIGHT)
		return -EINVAL;
	const struct tile *src;
	if (node_opt_height_input(n, in, nin, T, &src))
		return -EINVAL;
	struct level L = level_of(n, k, T);
	float *dst = tile_f32(out);
	const float *base = src ? tile_f32(src) : NULL;
	if (L.w <= 0) {
		float v = (float)c->offset + (float)c->amplitude * 0.5f;
		if (!base) {
			tile_fill_uniform(out, &v);
			return 0;
		}
		for (size_t i = 0; i < (size_t)T * T; i++)
			dst[i] = base[i] + v;
		return 0;
	}
	size_t trig = (size_t)T * 2 * sizeof(double);
	char *scratch = gen_scratch(g, trig + CUBE_CACHE * sizeof(struct cube));
	double *cl = (double *)scratch, *sl = cl + T;
	struct cube *cache = (struct cube *)(scratch + trig);
	for (size_t i = 0; i < CUBE_CACHE; i++)
		cache[i].used = false;
	for (uint32_t i = 0; i < T; i++) {
		double lon, la;
		grid_texel_center(k, T, i, 0, &lon, &la);
		cl[i] = cos(lon * M_PI / 180);
		sl[i] = sin(lon * M_PI / 180);
	}
	struct block blk = { .valid = false, .cache = cache };
	double dlon = 2 * M_PI / ((double)grid_tiles_x(k->lx) * T); /* between texels, radians */
	for (uint32_t j = 0; j < T; j++) {
		double lo, lat, slack;
		grid_texel_center(k, T, 0, j, &lo, &lat);
		double cp = cos(lat * M_PI / 180), sp = sin(lat * M_PI / 180);
		float *row = dst + (size_t)j * T;
		const float *brow = base ? base + (size_t)j * T : NULL;
		if (pole_row(k, T, lat)) {
			double pp[3] = { 0, 0, lat > 0 ? 1 : -1 };
			float f = value_at(c, &L, &blk, pp, &slack);
			for (uint32_t i = 0; i < T; i++)
				row[i] = (brow ? brow[i] : 0) + f;
			continue;
		}
		/* The texels of a row are equally spaced on a circle of latitude, step apart in
		 * lattice units: after a point evaluated with slack s the next floor(s / step)
		 * texels have its value (most texels of a level that shows cells). */
		double step = 2 * cp * sin(dlon / 2) * c->scale * (1 + 1e-6) + 1e-12;
		for (uint32_t i = 0; i < T;) {
			double p[3] = { cp * cl[i], cp * sl[i], sp };
			float f = value_at(c, &L, &blk, p, &slack);
			uint32_t cnt = 1 + (slack > step ? (uint32_t)fmin(slack / step, T) : 0);
			for (uint32_t e = i + cnt < T ? i + cnt : T; i < e; i++)
				row[i] = (brow ? brow[i] : 0) + f;
		}
	}
	return 0;
}

const struct node_type node_type_cells = {
	.name = "cells",
	.doc = "a patchwork of cells on the sphere (seed, wavelength m, jitter, border m, "
	       "amplitude, offset): each cell a value in [0, 1), borders −1, band-limited per "
	       "level; optional input height gets it added",
	.version = 1,
	.slots = slots,
	.nslots = 1,
	.costly = true,
	.create = cells_create,
	.destroy = node_free_impl,
	.deps = NULL,
	.generate = cells_generate,
};
