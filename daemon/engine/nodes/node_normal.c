/* node_normal — `normal`: heights → unit surface normals (RG8: east and north components in the
 * local tangent frame, up implied), by central differences with metric texel spacing from the
 * body's ellipsoid: per row, east spacing N(φ)·cos φ·Δλ and north spacing M(φ)·Δφ.
 *
 * Seamless: deps() asks for the tile and its four edge neighbours (central differences never
 * touch the diagonal ones), so border texels difference across tile borders, the antimeridian
 * (x wraps) and the poles (the neighbour is the tile on the far side with its rows reversed; at
 * lx = 0 that is the tile itself, half a turn round). NaN heights give a straight-up normal.
 * Thread-safety: parameters are set in create; generate uses only the worker's scratch.
 */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/geo.h"
#include "common/normalmap.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"

struct normal {
	double exaggeration;
};

/* The tiles a normal tile reads, by role; deps are those keys without duplicates. */
enum { NB_C, NB_W, NB_E, NB_N, NB_S, NB_COUNT };

struct nbhood {
	struct tile_key key[NB_COUNT];
	bool flip[NB_COUNT]; /* across a pole: rows run the other way */
	int dep[NB_COUNT];   /* which dependency holds the role's tile */
	int ndeps;
};

static void nbhood(const struct node *n, const struct tile_key *k, struct nbhood *nb)
{
	static const int d[NB_COUNT][2] = { { 0, 0 }, { -1, 0 }, { 1, 0 }, { 0, -1 }, { 0, 1 } };
	nb->ndeps = 0;
	for (int r = 0; r < NB_COUNT; r++) {
		grid_neighbor(k, d[r][0], d[r][1], &nb->key[r], &nb->flip[r]);
		nb->key[r].node = n->in[0]->hash;
		nb->dep[r] = -1;
		for (int q = 0; q < r; q++)
			if (grid_key_equal(&nb->key[q], &nb->key[r]))
				nb->dep[r] = nb->dep[q];
		if (nb->dep[r] < 0)
			nb->dep[r] = nb->ndeps++;
	}
}

static int normal_create(struct node *n, struct node_parse *p)
{
	double ex;
	int rc = np_double(p, "exaggeration", 1, -1e4, 1e4, &ex);
	if (rc)
		return rc;
	if (!n->planet || !n->planet->body)
		return np_error(p, NULL, "node \"%s\": the planet has no body (ellipsoid)", n->name);
	struct normal *nm = xmalloc(sizeof *nm);
	nm->exaggeration = ex;
	n->impl = nm;
	n->out = PIX_NORMAL;
	return 0;
}

const struct node *node_normal_plain_input(const struct node *n)
{
	if (!n || n->type != &node_type_normal || !n->impl || !n->in[0])
		return NULL;
	const struct normal *nm = n->impl;
	return nm->exaggeration == 1 ? n->in[0] : NULL;
}

static int normal_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	struct nbhood nb;
	nbhood(n, k, &nb);
	for (int r = 0; r < NB_COUNT; r++) {
		out[nb.dep[r]].node = n->in[0];
		out[nb.dep[r]].key = nb.key[r];
	}
	return nb.ndeps;
}

/* Row r of tile t (t's own orientation), rotated by half a turn when `half` (lx = 0 across a
 * pole: the far side is the same tile, T/2 columns round). */
static const float *pole_row(const struct tile *t, uint32_t r, bool half, float *buf)
{
	uint32_t T = t->size;
	const float *src = tile_f32(t) + (size_t)r * T;
	if (!half)
		return src;
	memcpy(buf, src + T / 2, T / 2 * sizeof *buf);
	memcpy(buf + T / 2, src, T / 2 * sizeof *buf);
	return buf;
}

static int normal_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			   struct tile *const *in, int nin, struct tile *out)
{
	const struct normal *nm = n->impl;
	const uint32_t T = out->size;
	struct nbhood nb;
	nbhood(n, k, &nb);
	if (nin != nb.ndeps || !n->planet || !n->planet->body)
		return -EINVAL;
	const struct tile *t[NB_COUNT];
	for (int r = 0; r < NB_COUNT; r++) {
		t[r] = in[nb.dep[r]];
		if (t[r]->type != PIX_HEIGHT || t[r]->size != T)
			return -EINVAL;
	}
	/* The widest east stencil: T texels (the neighbour tiles' width), a quarter turn. */
	uint64_t quarter = (uint64_t)grid_tiles_x(k->lx) * T / 4;
	uint32_t kmax = quarter < T ? (uint32_t)(quarter > 0 ? quarter : 1) : T;
	float *rowbuf = gen_scratch(g, (size_t)(3 * T + 2 * kmax + 16) * sizeof(float));
	float *northbuf = rowbuf + T + 2 * kmax + 8, *southbuf = northbuf + T;
	const float *c = tile_f32(t[NB_C]), *w = tile_f32(t[NB_W]), *e = tile_f32(t[NB_E]);
	const bool half = k->lx == 0;
	const float *north = nb.flip[NB_N] ? pole_row(t[NB_N], 0, half, northbuf)
					   : pole_row(t[NB_N], T - 1, false, northbuf);
	const float *south = nb.flip[NB_S] ? pole_row(t[NB_S], T - 1, half, southbuf)
					   : pole_row(t[NB_S], 0, false, southbuf);

	const double dlam = 2 * M_PI / ((double)grid_tiles_x(k->lx) * T);
	const double dphi = M_PI / ((double)grid_tiles_y(k->ly) * T);
	for (uint32_t j = 0; j < T; j++) {
		double lat = grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5);
		double mrad, nrad, len;
		geo_radii(n->planet->body, lat, &mrad, &nrad);
		double dy = mrad * dphi;
		uint32_t ks = normalmap_east_stencil(nrad * cos(lat * (M_PI / 180.0)), dlam, dy, kmax,
						     &len);
		float fx = (float)(nm->exaggeration / len);
		float fy = (float)(nm->exaggeration / (2 * dy));
		/* rowbuf: kmax texels of the west neighbour, the row, kmax of the east one. */
		const float *crow = c + (size_t)j * T;
		memcpy(rowbuf, w + (size_t)j * T + T - kmax, kmax * sizeof *rowbuf);
		memcpy(rowbuf + kmax, crow, T * sizeof *rowbuf);
		memcpy(rowbuf + kmax + T, e + (size_t)j * T, kmax * sizeof *rowbuf);
		const float *up = j > 0 ? crow - T : north;
		const float *dn = j + 1 < T ? crow + T : south;
		normalmap_row(rowbuf + kmax - ks, rowbuf + kmax + ks, up, dn, fx, fy,
			      out->data + (size_t)j * T * 2, T);
	}
	return 0;
}

static const struct node_slot normal_slots[] = {
	{ .name = "input", .type = PIX_HEIGHT },
};

const struct node_type node_type_normal = {
	.name = "normal",
	.doc = "surface normals from heights (metric spacing on the ellipsoid, seamless)",
	.version = 1,
	.slots = normal_slots,
	.nslots = 1,
	.create = normal_create,
	.destroy = node_free_impl,
	.deps = normal_deps,
	.generate = normal_generate,
};
