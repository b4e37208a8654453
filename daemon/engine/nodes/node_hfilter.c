/* node_hfilter — `height_filter`: out = clamp(in · scale + offset, min, max) per texel; min and
 * max are optional (no clamp when absent). NaN (no data) stays NaN.
 * Thread-safety: the parameters are set in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdlib.h>

#include "common/xalloc.h"
#include "engine/node_types.h"

struct height_filter {
	float scale, offset, lo, hi;
};

#define HF_LIMIT 1e9

static int hf_create(struct node *n, struct node_parse *p)
{
	double scale, offset, lo, hi;
	int rc;
	if ((rc = np_double(p, "scale", 1, -1e6, 1e6, &scale)) ||
	    (rc = np_double(p, "offset", 0, -HF_LIMIT, HF_LIMIT, &offset)) ||
	    (rc = np_double(p, "min", -INFINITY, -HF_LIMIT, HF_LIMIT, &lo)) ||
	    (rc = np_double(p, "max", INFINITY, -HF_LIMIT, HF_LIMIT, &hi)))
		return rc;
	if (lo > hi)
		return np_error(p, "max", "max (%g) is below min (%g)", hi, lo);
	struct height_filter *f = xmalloc(sizeof *f);
	*f = (struct height_filter){ (float)scale, (float)offset, (float)lo, (float)hi };
	n->impl = f;
	n->out = PIX_HEIGHT;
	return 0;
}

/* Fixed 16-texel blocks so the loop vectorises even at -O2 (T is a multiple of 16). The
 * comparisons are written so NaN fails both and passes through. */
static void hf_run(const float *restrict src, float *restrict dst, size_t count,
		   struct height_filter f)
{
	for (size_t i0 = 0; i0 < count; i0 += 16) {
		const float *restrict s = src + i0;
		float *restrict d = dst + i0;
		for (int i = 0; i < 16; i++) {
			float v = s[i] * f.scale + f.offset;
			v = v < f.lo ? f.lo : v;
			d[i] = v > f.hi ? f.hi : v;
		}
	}
}

/* One texel, as hf_run computes it. */
static float hf_one(float s, struct height_filter f)
{
	float v = s * f.scale + f.offset;
	v = v < f.lo ? f.lo : v;
	return v > f.hi ? f.hi : v;
}

/* With the input's summary the output's is known without a scan: the filter is monotone
 * (non-decreasing, or non-increasing for a negative scale, in every float step), so the
 * extreme outputs are the extreme inputs' images. Where every texel lands strictly beyond a
 * clamp (no NaN) the tile is that bound throughout: a shared uniform tile, nothing written.
 * Strictly: a texel landing exactly on a bound could be −0 where the bound is +0. */
static int hf_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		       struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	(void)k;
	const struct height_filter *f = n->impl;
	if (nin < 1 || in[0]->type != PIX_HEIGHT || in[0]->size != out->size || out->size % 16)
		return -EINVAL;
	const struct tile *src = in[0];
	if (src->uniform) { /* one height in, one out */
		float v = hf_one(tile_f32(src)[0], *f);
		tile_fill_uniform(out, &v);
		return 0;
	}
	bool known = src->summarized && src->lo <= src->hi;
	float a = 0, b = 0;
	if (known) {
		a = src->lo * f->scale + f->offset;
		b = src->hi * f->scale + f->offset;
		float vmin = a < b ? a : b, vmax = a < b ? b : a;
		if (!src->any_nan && vmax < f->lo) {
			tile_fill_uniform(out, &f->lo);
			return 0;
		}
		if (!src->any_nan && vmin > f->hi) {
			tile_fill_uniform(out, &f->hi);
			return 0;
		}
	}
	hf_run(tile_f32(src), tile_f32(out), (size_t)out->size * out->size, *f);
	if (known) {
		float x = hf_one(src->lo, *f), y = hf_one(src->hi, *f);
		out->lo = x < y ? x : y;
		out->hi = x < y ? y : x;
		out->any_nan = src->any_nan;
		out->summarized = true;
	} else if (src->summarized) { /* every texel NaN, and so every output */
		out->lo = src->lo;
		out->hi = src->hi;
		out->any_nan = true;
		out->summarized = true;
	}
	return 0;
}

static const struct node_slot hf_slots[] = {
	{ .name = "input", .type = PIX_HEIGHT, .summary = true },
};

const struct node_type node_type_height_filter = {
	.name = "height_filter",
	.doc = "scale, offset and clamp heights",
	.version = 1,
	.slots = hf_slots,
	.nslots = 1,
	.create = hf_create,
	.destroy = node_free_impl,
	.generate = hf_generate,
};
