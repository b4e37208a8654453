/* node_color — `color_filter`: per-channel levels → brightness → contrast → gamma baked into one
 * 256-entry table at create time, then (only when not identity) hue rotation and saturation as
 * one 3×3 fixed-point matrix. Alpha passes through, except with the optional `sea_mask` input
 * (a 0..1 mask, a height: where a sea may lie, e.g. open_sea's): where it is below ½ an opaque
 * texel's alpha becomes 254, the mark a viewer reads as dry land even below sea level (the
 * planet's sea_mask = color_alpha; 99.6 % opaque, so every other use of the colour shows it
 * as opaque).
 *
 * Hue rotates about the grey axis (1,1,1) of RGB, so +120° maps red → green → blue exactly;
 * saturation scales the distance from Rec. 601 luma (0 gives grey). gamma > 1 brightens
 * (out = in^(1/gamma), as in an image editor's levels dialog).
 * Thread-safety: the tables are built once in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "common/xalloc.h"
#include "engine/node_types.h"

#define MAT_SHIFT 12

struct color_filter {
	/* lut[c][v] = the filtered value of v placed at byte c of an RGBA texel read as uint32 */
	uint32_t lut[3][256];
	uint32_t alpha_mask; /* the alpha byte of a texel read as uint32 */
	bool lut_identity;
	bool matrix;
	/* RGBA→RGBA, Q12, as madd coefficients for two texels: row c is (m[c][0..3]) twice;
	 * the alpha row is (0, 0, 0, 1). |entries| ≤ 7 (saturation ≤ 4), so they fit int16. */
	int16_t m[4][8];
};

static double clamp01(double x)
{
	return x < 0 ? 0 : x > 1 ? 1 : x;
}

static uint32_t byte_at(int pos, uint8_t v)
{
	uint8_t b[4] = { 0, 0, 0, 0 };
	uint32_t w;
	b[pos] = v;
	memcpy(&w, b, 4);
	return w;
}

/* R(θ) about the unit grey axis, then S(s) = (1 - s)·L + s·I with L's rows the luma weights. */
static void hue_sat_matrix(double hue_deg, double sat, double out[9])
{
	double t = hue_deg * (M_PI / 180.0);
	double c = cos(t), s = sin(t), k = 1.0 / sqrt(3.0);
	double r[9] = {
		c + (1 - c) / 3,     (1 - c) / 3 - s * k, (1 - c) / 3 + s * k,
		(1 - c) / 3 + s * k, c + (1 - c) / 3,     (1 - c) / 3 - s * k,
		(1 - c) / 3 - s * k, (1 - c) / 3 + s * k, c + (1 - c) / 3,
	};
	static const double luma[3] = { 0.299, 0.587, 0.114 };
	double sm[9];
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			sm[i * 3 + j] = (1 - sat) * luma[j] + (i == j ? sat : 0);
	for (int i = 0; i < 3; i++)
		for (int j = 0; j < 3; j++)
			out[i * 3 + j] = sm[i * 3 + 0] * r[0 * 3 + j] + sm[i * 3 + 1] * r[1 * 3 + j] +
					 sm[i * 3 + 2] * r[2 * 3 + j];
}

static int color_create(struct node *n, struct node_parse *p)
{
	double bright, contrast, gamma, ib, iw, ob, ow, hue, sat;
	int rc;
	if ((rc = np_double(p, "brightness", 0, -1, 1, &bright)) ||
	    (rc = np_double(p, "contrast", 1, 0, 4, &contrast)) ||
	    (rc = np_double(p, "gamma", 1, 0.1, 10, &gamma)) ||
	    (rc = np_double(p, "in_black", 0, 0, 255, &ib)) ||
	    (rc = np_double(p, "in_white", 255, 0, 255, &iw)) ||
	    (rc = np_double(p, "out_black", 0, 0, 255, &ob)) ||
	    (rc = np_double(p, "out_white", 255, 0, 255, &ow)) ||
	    (rc = np_double(p, "hue", 0, -360, 360, &hue)) ||
	    (rc = np_double(p, "saturation", 1, 0, 4, &sat)))
		return rc;
	if (iw <= ib)
		return np_error(p, ini_find(p->sec, "in_white") ? "in_white" : "in_black",
				"in_white (%g) must be greater than in_black (%g)", iw, ib);

	struct color_filter *f = xcalloc(1, sizeof *f);
	f->lut_identity = true;
	for (int v = 0; v < 256; v++) {
		double x = clamp01((v - ib) / (iw - ib));
		x = (ob + x * (ow - ob)) / 255.0;
		x = clamp01(x + bright);
		x = clamp01((x - 0.5) * contrast + 0.5);
		if (gamma != 1.0)
			x = pow(x, 1.0 / gamma);
		long o = lrint(x * 255.0);
		uint8_t b = (uint8_t)(o < 0 ? 0 : o > 255 ? 255 : o);
		if (b != v)
			f->lut_identity = false;
		for (int c = 0; c < 3; c++)
			f->lut[c][v] = byte_at(c, b);
	}
	f->alpha_mask = byte_at(3, 255);

	double h = fmod(hue, 360.0);
	if (h != 0.0 || sat != 1.0) {
		double m[9];
		hue_sat_matrix(h, sat, m);
		f->matrix = true;
		for (int r = 0; r < 4; r++)
			for (int c = 0; c < 8; c++) {
				double v = r < 3 ? (c % 4 < 3 ? m[r * 3 + c % 4] : 0) : c % 4 == 3;
				f->m[r][c] = (int16_t)lrint(v * (1 << MAT_SHIFT));
			}
	}
	n->impl = f;
	n->out = PIX_COLOR;
	return 0;
}

static inline uint8_t mat_row(const int16_t *m, int r, int g, int b, int a)
{
	int32_t v = m[0] * r + m[1] * g + m[2] * b + m[3] * a + (1 << (MAT_SHIFT - 1));
	v = v < 0 ? 0 : v >> MAT_SHIFT;
	return (uint8_t)(v > 255 ? 255 : v);
}

/* The matrix on texels [from, count), one at a time. May run in place. */
static void matrix_scalar(const int16_t m[4][8], const uint8_t *src, uint8_t *dst, size_t from,
			  size_t count)
{
	for (size_t i = from; i < count; i++) {
		int r = src[4 * i], g = src[4 * i + 1], b = src[4 * i + 2], a = src[4 * i + 3];
		dst[4 * i] = mat_row(m[0], r, g, b, a);
		dst[4 * i + 1] = mat_row(m[1], r, g, b, a);
		dst[4 * i + 2] = mat_row(m[2], r, g, b, a);
		dst[4 * i + 3] = mat_row(m[3], r, g, b, a);
	}
}

#ifdef __SSE2__
/* Two texels as int16 (r0 g0 b0 a0 r1 g1 b1 a1) → the same layout, transformed: one madd
 * per output channel gives pair sums that two rounds of interleaving add up. Identical to
 * matrix_scalar (floor shift, then packus clamps to 0..255). */
static inline __m128i matrix2(__m128i v, const __m128i c[4])
{
	__m128i r = _mm_madd_epi16(v, c[0]), g = _mm_madd_epi16(v, c[1]);
	__m128i b = _mm_madd_epi16(v, c[2]), a = _mm_madd_epi16(v, c[3]);
	__m128i rg0 = _mm_unpacklo_epi32(r, g), rg1 = _mm_unpackhi_epi32(r, g);
	__m128i ba0 = _mm_unpacklo_epi32(b, a), ba1 = _mm_unpackhi_epi32(b, a);
	__m128i rg = _mm_add_epi32(_mm_unpacklo_epi64(rg0, rg1), _mm_unpackhi_epi64(rg0, rg1));
	__m128i ba = _mm_add_epi32(_mm_unpacklo_epi64(ba0, ba1), _mm_unpackhi_epi64(ba0, ba1));
	const __m128i half = _mm_set1_epi32(1 << (MAT_SHIFT - 1));
	__m128i t0 = _mm_srai_epi32(_mm_add_epi32(_mm_unpacklo_epi64(rg, ba), half), MAT_SHIFT);
	__m128i t1 = _mm_srai_epi32(_mm_add_epi32(_mm_unpackhi_epi64(rg, ba), half), MAT_SHIFT);
	return _mm_packs_epi32(t0, t1);
}

static void matrix_run(const int16_t m[4][8], const uint8_t *src, uint8_t *dst, size_t count)
{
	__m128i c[4];
	for (int r = 0; r < 4; r++)
		c[r] = _mm_loadu_si128((const __m128i *)(const void *)m[r]);
	const __m128i zero = _mm_setzero_si128();
	size_t i = 0;
	for (; i + 4 <= count; i += 4) {
		__m128i x = _mm_loadu_si128((const __m128i *)(const void *)(src + 4 * i));
		__m128i lo = matrix2(_mm_unpacklo_epi8(x, zero), c);
		__m128i hi = matrix2(_mm_unpackhi_epi8(x, zero), c);
		_mm_storeu_si128((__m128i *)(void *)(dst + 4 * i), _mm_packus_epi16(lo, hi));
	}
	matrix_scalar(m, src, dst, i, count);
}
#else
static void matrix_run(const int16_t m[4][8], const uint8_t *src, uint8_t *dst, size_t count)
{
	matrix_scalar(m, src, dst, 0, count);
}
#endif

static int color_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	(void)k;
	const struct color_filter *f = n->impl;
	if (nin < 1 || in[0]->type != PIX_COLOR || in[0]->size != out->size)
		return -EINVAL;
	bool mark_dry = n->in[1] != NULL; /* the sea_mask input */
	if (mark_dry && (nin < 2 || in[1]->type != PIX_HEIGHT || in[1]->size != out->size))
		return -EINVAL;
	size_t count = (size_t)out->size * out->size;
	/* Not restrict: the matrix pass runs in place over the table pass's output. */
	const uint8_t *src = in[0]->data;
	uint8_t *dst = out->data;
	if (f->lut_identity && !f->matrix) {
		memcpy(dst, src, count * 4);
		src = dst;
	}
	if (!f->lut_identity) {
		const uint32_t *l0 = f->lut[0], *l1 = f->lut[1], *l2 = f->lut[2];
		uint32_t am = f->alpha_mask;
		for (size_t i = 0; i < count; i++) {
			uint32_t w;
			memcpy(&w, src + 4 * i, 4);
			w = l0[src[4 * i]] | l1[src[4 * i + 1]] | l2[src[4 * i + 2]] | (w & am);
			memcpy(dst + 4 * i, &w, 4);
		}
		src = dst; /* the matrix, if any, works in place on the filtered texels */
	}
	if (f->matrix)
		matrix_run(f->m, src, dst, count);
	if (mark_dry) {
		const float *m = tile_f32(in[1]);
		for (size_t i = 0; i < count; i++)
			if (!(m[i] >= 0.5f) && dst[4 * i + 3] == 255) /* NaN: dry */
				dst[4 * i + 3] = 254;
	}
	return 0;
}

static const struct node_slot color_slots[] = {
	{ .name = "input", .type = PIX_COLOR },
	{ .name = "sea_mask", .type = PIX_HEIGHT, .optional = true },
};

const struct node_type node_type_color_filter = {
	.name = "color_filter",
	.doc = "levels, brightness, contrast, gamma, hue and saturation of a colour input",
	.version = 1,
	.slots = color_slots,
	.nslots = 2,
	.create = color_create,
	.destroy = node_free_impl,
	.generate = color_generate,
};
