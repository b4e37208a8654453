/* node_colormask — `color_mask`: a 0..1 mask (a height) where a colour input is near one of
 * a few reference colours: 1 within `near` of the nearest of `colors` (Euclidean distance in
 * 8-bit RGB), 0 beyond `far`, smoothstep between. It tells land cover from a photographic
 * colour layer (Blue Marble's dark green forests, tan sand seas), so detail can follow it
 * (earth.ini: dunes on the sand, a canopy on the forests). Alpha is ignored.
 * Thread-safety: the parameters are set in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#include "colormask.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "noise.h"

static int cm_create(struct node *n, struct node_parse *p)
{
	double v[CM_MAX * 3], near, far;
	int nv = 0, rc;
	if ((rc = np_doubles(p, "colors", v, CM_MAX * 3, &nv)) ||
	    (rc = np_double(p, "near", 20, 0, 442, &near)) ||
	    (rc = np_double(p, "far", 60, 0, 442, &far)))
		return rc;
	if (nv == 0 || nv % 3)
		return np_error(p, "colors",
				"give 1 to %d colours as \"r g b, r g b, ...\" (0-255 each), got %d "
				"numbers",
				CM_MAX, nv);
	for (int i = 0; i < nv; i++)
		if (v[i] < 0 || v[i] > 255)
			return np_error(p, "colors", "%g is outside 0-255", v[i]);
	if (far <= near)
		return np_error(p, "far", "far (%g) must be above near (%g)", far, near);
	struct color_mask *m = xmalloc(sizeof *m);
	m->n = nv / 3;
	for (int i = 0; i < m->n; i++)
		for (int c = 0; c < 3; c++)
			m->ref[i][c] = (float)v[3 * i + c];
	m->near = (float)near;
	m->near2 = (float)(near * near);
	m->far2 = (float)(far * far);
	m->inv = (float)(1 / (far - near));
	n->impl = m;
	n->out = PIX_HEIGHT;
	return 0;
}

float color_mask_texel(const struct color_mask *m, const uint8_t *px)
{
	float best = INFINITY;
	for (int i = 0; i < m->n; i++) {
		float dr = px[0] - m->ref[i][0], dg = px[1] - m->ref[i][1], db = px[2] - m->ref[i][2];
		float d2 = dr * dr + dg * dg + db * db;
		best = d2 < best ? d2 : best;
	}
	if (best <= m->near2)
		return 1;
	if (best >= m->far2)
		return 0;
	float t = (sqrtf(best) - m->near) * m->inv;
	return 1 - t * t * (3 - 2 * t);
}

static int cm_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		       struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	(void)k;
	const struct color_mask *m = n->impl;
	if (nin < 1 || in[0]->type != PIX_COLOR || in[0]->size != out->size)
		return -EINVAL;
	size_t count = (size_t)out->size * out->size;
	const uint8_t *src = in[0]->data;
	float *dst = tile_f32(out);
	if (count % 8 == 0 && noise_isa_has_avx2()) {
		if (!color_mask_avx2(m, src, dst, count)) {
			static const float zero = 0; /* nowhere near: the shared all-zero tile */
			tile_fill_uniform(out, &zero);
		}
		return 0;
	}
	for (size_t i = 0; i < count; i++)
		dst[i] = color_mask_texel(m, src + 4 * i);
	return 0;
}

static const struct node_slot cm_slots[] = {
	{ .name = "input", .type = PIX_COLOR },
};

const struct node_type node_type_color_mask = {
	.name = "color_mask",
	.doc = "a 0..1 mask where a colour input is near reference colours (land cover)",
	.version = 1,
	.slots = cm_slots,
	.nslots = 1,
	.create = cm_create,
	.destroy = node_free_impl,
	.generate = cm_generate,
};
