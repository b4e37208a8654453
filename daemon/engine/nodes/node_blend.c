/* node_blend — `blend`: combines inputs a and b (same pixel type; the output has a's type),
 * optionally weighted per texel by `mask` (heights read as a 0..1 weight, clamped).
 *   over      colour: b over a (straight alpha), b's alpha × opacity × mask;
 *             heights/normals: lerp(a, b, opacity × mask); a NaN height in b keeps a, a NaN in
 *             a takes b (NaN is "no data").
 *   mask      lerp(a, b, clamp(mask, 0, 1) × opacity) on every channel (needs `mask`).
 *   add       heights only: a + b × weight × opacity × mask.
 *   Heights are a's own where the weight is 0 (version 2: a NaN in b there no longer reached
 *   an add's sum, and −0 stays −0).
 *   multiply  colour only: rgb = lerp(a, a·b/255, opacity × mask); alpha stays a's.
 * With a mask that is 0 (or NaN) over a whole tile the output is a, and b is not made at all
 * (node_type.lazy): a noise masked to a small part of the planet costs nothing elsewhere.
 * Except where a decides it (a NaN height in a takes b; over on colours clears a texel whose
 * a and b are both transparent): then b is made as usual.
 * Thread-safety: parameters are set in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "blend_kernels.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "noise.h"

enum blend_mode { BLEND_OVER, BLEND_MASK, BLEND_ADD, BLEND_MULTIPLY };

static const char *const blend_modes[] = { "over", "mask", "add", "multiply", NULL };

struct blend {
	int mode;
	bool lazy_b; /* b is made only where the mask lets it through (blend_lazy) */
	float opacity, weight;
	uint32_t kb[256]; /* over, colour, no mask: b's weight in 1/65536 by b's alpha */
};

enum { SLOT_A, SLOT_B, SLOT_MASK };

static int blend_create(struct node *n, struct node_parse *p)
{
	int mode, rc;
	double opacity, weight;
	if ((rc = np_enum(p, "mode", blend_modes, BLEND_OVER, &mode)) ||
	    (rc = np_double(p, "opacity", 1, 0, 1, &opacity)) ||
	    (rc = np_double(p, "weight", 1, -1e6, 1e6, &weight)))
		return rc;
	enum pix_type ta = n->in[SLOT_A]->out, tb = n->in[SLOT_B]->out;
	if (ta != tb)
		return np_error(p, "b", "node \"%s\" gives %s tiles but a (\"%s\") gives %s; blend "
				"needs both of one type", n->in[SLOT_B]->name, pix_type_name(tb),
				n->in[SLOT_A]->name, pix_type_name(ta));
	if (mode == BLEND_MASK && !n->in[SLOT_MASK])
		return np_error(p, "mode", "mode mask needs input \"mask\"");
	if (mode == BLEND_ADD && ta != PIX_HEIGHT)
		return np_error(p, "mode", "add works on heights, not %s", pix_type_name(ta));
	if (mode == BLEND_MULTIPLY && ta != PIX_COLOR)
		return np_error(p, "mode", "multiply works on colours, not %s", pix_type_name(ta));
	struct blend *b = xmalloc(sizeof *b);
	b->mode = mode;
	b->opacity = (float)opacity;
	b->weight = (float)weight;
	for (int a = 0; a < 256; a++)
		b->kb[a] = blend_over_kb((uint8_t)a, b->opacity);
	/* Deferring b pays only where skipping it saves costly work that a and the mask do not
	 * need anyway; elsewhere it would only make b's inputs later, when the cache may have
	 * let them go (measured: Earth's colour blends over its dunes and canopy made those
	 * again). */
	const struct node *others[2] = { n->in[SLOT_A], n->in[SLOT_MASK] };
	b->lazy_b = n->in[SLOT_MASK] && node_exclusive_costly(n->in[SLOT_B], others, 2);
	n->impl = b;
	n->out = ta;
	return 0;
}

static inline float weight_at(const float *mask, size_t i, float opacity)
{
	if (!mask)
		return opacity;
	float m = mask[i];
	m = m > 0.0f ? m : 0.0f; /* NaN → 0 */
	m = m < 1.0f ? m : 1.0f;
	return m * opacity;
}

static void blend_heights(const struct blend *bl, const float *a, const float *b,
			  const float *mask, float *o, size_t count)
{
	for (size_t i = 0; i < count; i++) {
		float w = weight_at(mask, i, bl->opacity);
		float x = a[i], y = b[i];
		switch (bl->mode) {
		case BLEND_ADD:
			o[i] = w > 0.0f ? x + y * (bl->weight * w) : x;
			break;
		default: /* over, mask */
			o[i] = y != y ? x : x != x ? y : w > 0.0f ? x + (y - x) * w : x;
			break;
		}
	}
}

/* over on colours without a mask: the opaque-base fast path with b's weight from a table. */
static void over_color(const struct blend *bl, const uint8_t *a, const uint8_t *b, uint8_t *o,
		       size_t count)
{
	for (size_t i = 0; i < count; i++) {
		const uint8_t *x = a + 4 * i, *y = b + 4 * i;
		uint8_t *d = o + 4 * i;
		if (x[3] != 255)
			blend_over_general(x, y, bl->opacity, d);
		else
			blend_over_opaque(x, y, bl->kb[y[3]], d);
	}
}

/* Colour (RGBA8) and normal (RG8: ch = 2) texels. */
static void blend_bytes(const struct blend *bl, const uint8_t *a, const uint8_t *b,
			const float *mask, uint8_t *o, size_t count, int ch)
{
	for (size_t i = 0; i < count; i++) {
		const uint8_t *x = a + ch * i, *y = b + ch * i;
		uint8_t *d = o + ch * i;
		float w = weight_at(mask, i, bl->opacity);
		if (bl->mode == BLEND_OVER && ch == 4 && x[3] == 255) {
			/* opaque base (the usual case) */
			blend_over_opaque(x, y, mask ? blend_over_kb(y[3], w) : bl->kb[y[3]], d);
		} else if (bl->mode == BLEND_OVER && ch == 4) {
			blend_over_general(x, y, w, d);
		} else if (bl->mode == BLEND_MULTIPLY) {
			for (int c = 0; c < 3; c++) {
				float prod = x[c] * (float)y[c] * (1.0f / 255);
				d[c] = blend_u8(x[c] + (prod - x[c]) * w);
			}
			d[3] = x[3];
		} else { /* mask, or over on normals */
			for (int c = 0; c < ch; c++)
				d[c] = blend_u8(x[c] + (float)(y[c] - x[c]) * w);
		}
	}
}

/* b may be skipped when the mask is given (deps: a, b, mask). */
static uint32_t blend_lazy(const struct node *n, const struct tile_key *k)
{
	(void)k;
	const struct blend *bl = n->impl;
	return bl->lazy_b ? 1u << SLOT_B : 0;
}

/* Whether every weight of the mask tile is 0 (≤ 0 or NaN: weight_at): from its summary when
 * it has one, else by a scan. */
static bool mask_zero(const struct tile *mt)
{
	if (mt->summarized)
		return !(mt->hi > 0.0f);
	const float *m = tile_f32(mt);
	size_t count = (size_t)mt->size * mt->size;
	int any = 0;
	for (size_t i = 0; i < count; i++)
		any |= m[i] > 0.0f; /* no early exit: a whole zero tile is the case that pays */
	return !any;
}

/* Whether a, at weight 0 everywhere, gives itself whatever b holds (the header's exceptions):
 * then the output is a's bytes. */
static bool a_decides(const struct blend *bl, const struct tile *a)
{
	size_t count = (size_t)a->size * a->size;
	if (a->type == PIX_HEIGHT && bl->mode != BLEND_ADD) {
		if (a->summarized)
			return !a->any_nan;
		const float *x = tile_f32(a);
		int nan = 0;
		for (size_t i = 0; i < count; i++)
			nan |= x[i] != x[i];
		return !nan;
	}
	if (a->type == PIX_COLOR && bl->mode == BLEND_OVER) {
		int clear = 0;
		for (size_t i = 0; i < count; i++)
			clear |= a->data[4 * i + 3] == 0;
		return !clear;
	}
	return true;
}

/* Whether a and b are one uniform height tile of a finite value other than −0 in a lerp
 * (over, mask): then every texel is x + (x − x)·w = x, a's bytes, whatever the mask. */
static bool same_uniform(const struct blend *bl, const struct tile *a, const struct tile *b)
{
	if (!b || a->type != PIX_HEIGHT || !a->uniform || a->data != b->data ||
	    (bl->mode != BLEND_OVER && bl->mode != BLEND_MASK))
		return false;
	float v = tile_f32(a)[0];
	return isfinite(v) && !(v == 0 && signbit(v));
}

/* Whether an add's b is ±0 on every texel and a has no −0 and no NaN texel (a uniform a's one
 * value, or a's summary all on one side of 0): then a + b·(weight·w) = a + ±0 = a, bit for
 * bit, whatever the mask (weight·w is finite), and the output is a's bytes. */
static bool adds_zero(const struct blend *bl, const struct tile *a, const struct tile *b)
{
	if (bl->mode != BLEND_ADD || a->type != PIX_HEIGHT || !b->uniform || tile_f32(b)[0] != 0.0f)
		return false;
	if (a->uniform) {
		float v = tile_f32(a)[0];
		return v == v && !(v == 0 && signbit(v));
	}
	return a->summarized && !a->any_nan && (a->lo > 0.0f || a->hi < 0.0f);
}

static bool blend_needed(const struct node *n, int k, struct tile *const *in, int nin)
{
	const struct blend *bl = n->impl;
	if (k != SLOT_B || nin < 3 || !in[SLOT_A] || !in[SLOT_MASK] ||
	    in[SLOT_MASK]->type != PIX_HEIGHT || in[SLOT_MASK]->size != in[SLOT_A]->size)
		return true;
	return !mask_zero(in[SLOT_MASK]) || !a_decides(bl, in[SLOT_A]);
}

static int blend_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	(void)k;
	const struct blend *bl = n->impl;
	int want = n->in[SLOT_MASK] ? 3 : 2;
	if (nin < want)
		return -EINVAL;
	for (int i = 0; i < want; i++)
		if ((!in[i] && i != SLOT_B) ||
		    (in[i] && (in[i]->size != out->size ||
			       in[i]->type != (i == 2 ? PIX_HEIGHT : out->type))))
			return -EINVAL;
	const float *mask = want == 3 ? tile_f32(in[2]) : NULL;
	size_t count = (size_t)out->size * out->size;
	if (!in[SLOT_B]) {
		/* skipped (blend_needed): the mask is 0 everywhere and a decides */
		if (!mask)
			return -EINVAL;
		tile_alias(out, in[SLOT_A]);
		out->lazy_unneeded = true;
		return 0;
	}
	/* A mask 0 everywhere gives a's bytes (a_decides): shared, not copied. Known for free
	 * from a summarized mask; a lazy b's children want to know anyway. */
	bool zero = mask && (in[2]->summarized || bl->lazy_b) && mask_zero(in[2]);
	if (bl->lazy_b && mask) /* made at once: tell the children whether it was worth it */
		out->lazy_unneeded = zero;
	if ((zero && a_decides(bl, in[SLOT_A])) || same_uniform(bl, in[SLOT_A], in[SLOT_B]) ||
	    adds_zero(bl, in[SLOT_A], in[SLOT_B])) {
		tile_alias(out, in[SLOT_A]);
		return 0;
	}
	bool avx2 = count % 8 == 0 && noise_isa_has_avx2();
	/* heights a node reads as a summary: summarized as they are written, not scanned after */
	struct blend_lanes lanes, *lp = n->summarize && count % 16 == 0 ? &lanes : NULL;
	if (out->type == PIX_HEIGHT && avx2) {
		if (bl->mode == BLEND_ADD)
			blend_add_avx2(tile_f32(in[0]), tile_f32(in[1]), mask, bl->opacity,
				       bl->weight, tile_f32(out), count, lp);
		else
			blend_lerp_avx2(tile_f32(in[0]), tile_f32(in[1]), mask, bl->opacity,
					tile_f32(out), count, lp);
		if (lp)
			tile_summary_from_lanes(out, lanes.lo, lanes.hi, lanes.nan);
	} else if (out->type == PIX_HEIGHT)
		blend_heights(bl, tile_f32(in[0]), tile_f32(in[1]), mask, tile_f32(out), count);
	else if (bl->mode == BLEND_OVER && out->type == PIX_COLOR && avx2)
		blend_over_avx2(in[0]->data, in[1]->data, mask, bl->opacity, out->data, count);
	else if (bl->mode == BLEND_OVER && out->type == PIX_COLOR && !mask)
		over_color(bl, in[0]->data, in[1]->data, out->data, count);
	else if (bl->mode == BLEND_MULTIPLY && avx2)
		blend_multiply_avx2(in[0]->data, in[1]->data, mask, bl->opacity, out->data, count);
	else
		blend_bytes(bl, in[0]->data, in[1]->data, mask, out->data, count,
			    (int)pix_bytes(out->type));
	return 0;
}

static const struct node_slot blend_slots[] = {
	{ .name = "a", .type = PIX_NONE, .summary = true },
	{ .name = "b", .type = PIX_NONE },
	{ .name = "mask", .type = PIX_HEIGHT, .optional = true, .summary = true },
};

const struct node_type node_type_blend = {
	.name = "blend",
	.doc = "combine two inputs: over, mask, add (heights), multiply (colours)",
	.version = 2, /* 2: add gives a where the weight is 0 */
	.slots = blend_slots,
	.nslots = 3,
	.create = blend_create,
	.destroy = node_free_impl,
	.generate = blend_generate,
	.lazy = blend_lazy,
	.needed = blend_needed,
};
