/* Tests of the per-texel node types: color_filter, height_filter, color_mask, ramp, blend. Nodes are built
 * from INI snippets exactly as the planet loader would (node_init), their inputs are bare
 * nodes with a type and a hash, and generate() runs on hand-filled tiles. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdbool.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/nodes/colormask.h"
#include "engine/nodes/node_ramp.h"
#include "engine/nodes/noise.h"
#include "engine/tile.h"

#define T 16
#define N (T * T)

struct tnode {
	struct node n;
	struct ini_file *ini;
	char err[256];
};

static struct node input_color = { .name = "photo", .out = PIX_COLOR, .hash = 11 };
static struct node input_height = { .name = "dem", .out = PIX_HEIGHT, .hash = 12 };
static struct node input_height2 = { .name = "detail", .out = PIX_HEIGHT, .hash = 13 };
static struct node input_color2 = { .name = "overlay", .out = PIX_COLOR, .hash = 14 };

/* Builds a node of type t from "key = value" lines; returns node_init's result. */
static int make(struct tnode *tn, const struct node_type *t, struct node *in0, struct node *in1,
		struct node *in2, const char *params)
{
	char text[1024];
	snprintf(text, sizeof text, "[node x]\n%s\n", params);
	memset(tn, 0, sizeof *tn);
	assert_int_equal(ini_parse("test.ini", text, strlen(text), &tn->ini, tn->err), 0);
	tn->n.name = "x";
	tn->n.in[0] = in0;
	tn->n.in[1] = in1;
	tn->n.in[2] = in2;
	return node_init(&tn->n, t, "test.ini", &tn->ini->sections[0], tn->err);
}

static void unmake(struct tnode *tn)
{
	node_fini(&tn->n);
	ini_free(tn->ini);
}

static const struct tile_key key0 = { .node = 1, .lx = 3, .ly = 2, .x = 1, .y = 1 };

static struct tile *run1(struct tnode *tn, struct tile *in0, struct tile *in1, struct tile *in2)
{
	struct tile *in[3] = { in0, in1, in2 };
	int nin = in2 ? 3 : in1 ? 2 : 1;
	struct tile *out = tile_create(&key0, tn->n.out, in0->size);
	struct gen_ctx g = { 0 };
	assert_int_equal(tn->n.type->generate(&tn->n, &g, &key0, in, nin, out), 0);
	gen_ctx_fini(&g);
	return out;
}

static struct tile *color_tile(const uint8_t px[4])
{
	struct tile *t = tile_create(&key0, PIX_COLOR, T);
	for (int i = 0; i < N; i++)
		memcpy(t->data + 4 * i, px, 4);
	return t;
}

static struct tile *height_tile(float v)
{
	struct tile *t = tile_create(&key0, PIX_HEIGHT, T);
	for (int i = 0; i < N; i++)
		tile_f32(t)[i] = v;
	return t;
}

/* The filtered colour of one texel value (every texel of the tile holds it). */
static void filter1(const char *params, const uint8_t in[4], uint8_t out[4])
{
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_filter, &input_color, NULL, NULL, params), 0);
	struct tile *a = color_tile(in), *o = run1(&tn, a, NULL, NULL);
	memcpy(out, o->data + 4 * 37, 4);
	assert_memory_equal(o->data, o->data + 4 * (N - 1), 4);
	tile_unref(a);
	tile_unref(o);
	unmake(&tn);
}

static void color_identity(void **state)
{
	(void)state;
	const char *ids[] = { "", "brightness = 0\ncontrast = 1\ngamma = 1\nhue = 0\nsaturation = 1",
			      "in_black = 0\nin_white = 255\nout_black = 0\nout_white = 255",
			      "hue = 360" };
	for (size_t c = 0; c < sizeof ids / sizeof *ids; c++) {
		struct tnode tn;
		assert_int_equal(make(&tn, &node_type_color_filter, &input_color, NULL, NULL, ids[c]),
				 0);
		struct tile *a = tile_create(&key0, PIX_COLOR, T);
		for (int i = 0; i < 4 * N; i++)
			a->data[i] = (uint8_t)(i * 7 + i / 5);
		struct tile *o = run1(&tn, a, NULL, NULL);
		assert_memory_equal(o->data, a->data, 4 * N);
		tile_unref(a);
		tile_unref(o);
		unmake(&tn);
	}
}

static void color_gamma_levels(void **state)
{
	(void)state;
	uint8_t o[4];
	/* 255 · (128/255)^(1/2.2) = 186.4; alpha untouched */
	filter1("gamma = 2.2", (const uint8_t[]){ 128, 0, 255, 77 }, o);
	assert_int_equal(o[0], 186);
	assert_int_equal(o[1], 0);
	assert_int_equal(o[2], 255);
	assert_int_equal(o[3], 77);
	/* input levels 50..200: 50 → 0, 100 → 85, 200 → 255 */
	filter1("in_black = 50\nin_white = 200", (const uint8_t[]){ 50, 100, 200, 3 }, o);
	assert_int_equal(o[0], 0);
	assert_int_equal(o[1], 85);
	assert_int_equal(o[2], 255);
	assert_int_equal(o[3], 3);
	filter1("in_black = 50\nin_white = 200", (const uint8_t[]){ 10, 230, 125, 0 }, o);
	assert_int_equal(o[0], 0);
	assert_int_equal(o[1], 255);
	/* output levels 20..220 */
	filter1("out_black = 20\nout_white = 220", (const uint8_t[]){ 0, 255, 51, 9 }, o);
	assert_int_equal(o[0], 20);
	assert_int_equal(o[1], 220);
	assert_int_equal(o[2], 60);
	/* brightness adds 0.2·255 = 51 */
	filter1("brightness = 0.2", (const uint8_t[]){ 100, 0, 250, 9 }, o);
	assert_int_equal(o[0], 151);
	assert_int_equal(o[1], 51);
	assert_int_equal(o[2], 255);
	/* contrast 1.5 about mid-grey: v → 1.5·v − 63.75 */
	filter1("contrast = 1.5", (const uint8_t[]){ 100, 200, 20, 9 }, o);
	assert_int_equal(o[0], 86);
	assert_int_equal(o[1], 236);
	assert_int_equal(o[2], 0);
}

static void color_hue_saturation(void **state)
{
	(void)state;
	uint8_t o[4];
	filter1("hue = 120", (const uint8_t[]){ 255, 0, 0, 200 }, o);
	assert_in_range(o[0], 0, 2);
	assert_in_range(o[1], 253, 255);
	assert_in_range(o[2], 0, 2);
	assert_int_equal(o[3], 200);
	filter1("hue = -120", (const uint8_t[]){ 255, 0, 0, 200 }, o);
	assert_in_range(o[0], 0, 2);
	assert_in_range(o[1], 0, 2);
	assert_in_range(o[2], 253, 255);
	/* a grey stays grey under any rotation */
	filter1("hue = 77", (const uint8_t[]){ 90, 90, 90, 1 }, o);
	assert_in_range(o[0], 89, 91);
	assert_in_range(o[1], 89, 91);
	assert_in_range(o[2], 89, 91);
	/* saturation 0: grey at the Rec. 601 luma, 0.299·200 + 0.587·50 + 0.114·100 = 100.55 */
	filter1("saturation = 0", (const uint8_t[]){ 200, 50, 100, 5 }, o);
	assert_in_range(o[0], 100, 101);
	assert_int_equal(o[1], o[0]);
	assert_int_equal(o[2], o[0]);
	assert_int_equal(o[3], 5);
	/* saturation 2 pushes channels away from grey */
	filter1("saturation = 2", (const uint8_t[]){ 120, 100, 100, 5 }, o);
	assert_true(o[0] > 130 && o[1] < 100 && o[2] < 100);
	/* table and matrix together: levels first, then the rotation */
	filter1("in_white = 128\nhue = 120", (const uint8_t[]){ 64, 0, 0, 5 }, o);
	assert_in_range(o[0], 0, 2);
	assert_in_range(o[1], 126, 130);
}

static uint32_t rng(uint32_t *st)
{
	*st ^= *st << 13;
	*st ^= *st >> 17;
	*st ^= *st << 5;
	return *st;
}

/* Varied texels (every lane of a vector path differs) against the documented formulas in
 * double precision: levels → contrast → gamma, then rotation about the grey axis and
 * saturation about Rec. 601 luma. */
static void color_reference(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_filter, &input_color, NULL, NULL,
			      "in_black = 10\nin_white = 240\ncontrast = 1.2\ngamma = 1.4\n"
			      "hue = 40\nsaturation = 1.5"), 0);
	struct tile *a = tile_create(&key0, PIX_COLOR, T);
	uint32_t seed = 99;
	for (int i = 0; i < 4 * N; i++)
		a->data[i] = (uint8_t)rng(&seed);
	struct tile *o = run1(&tn, a, NULL, NULL);
	double th = 40 * M_PI / 180, c = cos(th), sn = sin(th) / sqrt(3.0), k = (1 - c) / 3;
	const double rot[3][3] = { { c + k, k - sn, k + sn }, { k + sn, c + k, k - sn },
				   { k - sn, k + sn, c + k } };
	const double luma[3] = { 0.299, 0.587, 0.114 };
	for (int i = 0; i < N; i++) {
		double v[3], w[3];
		for (int ch = 0; ch < 3; ch++) {
			double x = (a->data[4 * i + ch] - 10) / 230.0;
			x = x < 0 ? 0 : x > 1 ? 1 : x;
			x = (x - 0.5) * 1.2 + 0.5;
			x = x < 0 ? 0 : x > 1 ? 1 : x;
			v[ch] = round(pow(x, 1 / 1.4) * 255);
		}
		for (int r = 0; r < 3; r++)
			w[r] = rot[r][0] * v[0] + rot[r][1] * v[1] + rot[r][2] * v[2];
		double y = luma[0] * w[0] + luma[1] * w[1] + luma[2] * w[2];
		for (int ch = 0; ch < 3; ch++) {
			double want = y + 1.5 * (w[ch] - y);
			want = want < 0 ? 0 : want > 255 ? 255 : want;
			int got = o->data[4 * i + ch];
			if (fabs(got - want) > 1.0)
				fail_msg("texel %d channel %d: %d, want %.2f", i, ch, got, want);
		}
		assert_int_equal(o->data[4 * i + 3], a->data[4 * i + 3]);
	}
	tile_unref(a);
	tile_unref(o);
	unmake(&tn);
}

/* Random heights against linear interpolation in double. */
static void ramp_reference(void **state)
{
	(void)state;
	static const double st[][4] = { { -500, 10, 20, 200 }, { -1, 0, 250, 250 },
					 { 0, 30, 160, 20 }, { 40, 90, 100, 50 },
					 { 3000, 255, 255, 255 } };
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_ramp, &input_height, NULL, NULL,
			      "stops = -500 10 20 200, -1 0 250 250, 0 30 160 20, 40 90 100 50, "
			      "3000 255 255 255"), 0);
	struct tile *a = height_tile(0);
	uint32_t seed = 7;
	for (int i = 0; i < N; i++)
		tile_f32(a)[i] = (float)((int)(rng(&seed) % 400000) - 100000) / 100.0f;
	struct tile *o = run1(&tn, a, NULL, NULL);
	for (int i = 0; i < N; i++) {
		double h = tile_f32(a)[i];
		int s = 0;
		while (s < 3 && h >= st[s + 1][0])
			s++;
		double t = (h - st[s][0]) / (st[s + 1][0] - st[s][0]);
		t = t < 0 ? 0 : t > 1 ? 1 : t;
		for (int ch = 0; ch < 3; ch++) {
			double want = st[s][ch + 1] + t * (st[s + 1][ch + 1] - st[s][ch + 1]);
			int got = o->data[4 * i + ch];
			if (fabs(got - want) > 0.51)
				fail_msg("height %.2f channel %d: %d, want %.2f", h, ch, got, want);
		}
		assert_int_equal(o->data[4 * i + 3], 255);
	}
	tile_unref(a);
	tile_unref(o);
	unmake(&tn);
}

static void color_errors(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_filter, &input_color, NULL, NULL,
			      "in_black = 200\nin_white = 100"), -EINVAL);
	assert_non_null(strstr(tn.err, "test.ini:3: in_white:"));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_color_filter, &input_color, NULL, NULL,
			      "gamma = 0"), -EINVAL);
	assert_non_null(strstr(tn.err, "gamma"));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_color_filter, &input_height, NULL, NULL, ""),
			 -EINVAL);
	assert_non_null(strstr(tn.err, "input"));
	unmake(&tn);
}

/* color_filter's `sea_mask` input: an opaque texel where the mask is below ½ (NaN too) gets
 * alpha 254, the viewer's mark of dry land; a mask of ½ or more, and a texel already not
 * opaque, keep their alpha; the colour is untouched, with and without a filter; a non-height
 * mask is refused. */
static void color_alpha_mask(void **state)
{
	(void)state;
	static const char *const params[] = { "", "gamma = 2" };
	const float m[6] = { 0, 0.49f, 0.5f, 1, 7, NAN };
	const uint8_t want_a[6] = { 254, 254, 255, 255, 255, 254 };
	for (int p = 0; p < 2; p++) {
		struct tnode tn;
		assert_int_equal(make(&tn, &node_type_color_filter, &input_color, &input_height, NULL,
				      params[p]),
				 0);
		struct tile *c = color_tile((const uint8_t[4]){ 10, 120, 240, 255 });
		c->data[4 * 7 + 3] = 100; /* not opaque (mask 0.49): left as it is */
		struct tile *mask = height_tile(0);
		for (int i = 0; i < N; i++)
			tile_f32(mask)[i] = m[i % 6];
		struct tile *out = run1(&tn, c, mask, NULL);
		struct tile *plain = NULL;
		struct tnode tp;
		assert_int_equal(make(&tp, &node_type_color_filter, &input_color, NULL, NULL,
				      params[p]),
				 0);
		plain = run1(&tp, c, NULL, NULL);
		for (int i = 0; i < N; i++) {
			assert_int_equal(out->data[4 * i + 3], i == 7 ? 100 : want_a[i % 6]);
			assert_memory_equal(out->data + 4 * i, plain->data + 4 * i, 3);
		}
		assert_int_equal(plain->data[3], 255); /* without the input alpha passes */
		tile_unref(out);
		tile_unref(plain);
		tile_unref(c);
		tile_unref(mask);
		unmake(&tn);
		unmake(&tp);
	}
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_filter, &input_color, &input_color2, NULL, ""),
			 -EINVAL);
	unmake(&tn);
}

static void height_filter(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_height_filter, &input_height, NULL, NULL,
			      "scale = 2\noffset = 10\nmin = 0\nmax = 100"), 0);
	struct tile *a = tile_create(&key0, PIX_HEIGHT, T);
	float *h = tile_f32(a);
	for (int i = 0; i < N; i++)
		h[i] = (float)(i % 80) - 20;
	h[5] = NAN;
	struct tile *o = run1(&tn, a, NULL, NULL);
	const float *r = tile_f32(o);
	for (int i = 0; i < N; i++) {
		if (i == 5) {
			assert_true(isnan(r[i]));
			continue;
		}
		float want = h[i] * 2 + 10;
		want = want < 0 ? 0 : want > 100 ? 100 : want;
		assert_true(r[i] == want);
	}
	tile_unref(o);
	unmake(&tn);

	/* defaults: unchanged, no clamp even far out */
	assert_int_equal(make(&tn, &node_type_height_filter, &input_height, NULL, NULL, ""), 0);
	h[7] = -11000.0f;
	h[8] = 1e7f;
	o = run1(&tn, a, NULL, NULL);
	assert_memory_equal(o->data, a->data, 4 * N);
	tile_unref(o);
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_height_filter, &input_height, NULL, NULL,
			      "min = 5\nmax = 1"), -EINVAL);
	assert_non_null(strstr(tn.err, "max"));
	unmake(&tn);
	tile_unref(a);
}

/* Runs a ramp over heights hs[0..n) and returns the colours (4 per height). */
/* color_mask: 1 within `near` of the nearest reference colour, 0 from `far` on, smoothstep
 * between (and monotone in the distance); alpha ignored; bad keys named. */
static void color_mask(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_mask, &input_color, NULL, NULL,
			      "colors = 200 150 100, 20 40 10\nnear = 10\nfar = 50"), 0);
	assert_int_equal(tn.n.out, PIX_HEIGHT);
	struct tile *a = tile_create(&key0, PIX_COLOR, T);
	uint8_t *px = a->data;
	/* texel i: the first colour moved i units along red (alpha varies, ignored) */
	for (int i = 0; i < N; i++) {
		int r = 200 - (i < 200 ? i : 200);
		px[4 * i] = (uint8_t)r;
		px[4 * i + 1] = 150;
		px[4 * i + 2] = 100;
		px[4 * i + 3] = (uint8_t)(i * 7);
	}
	/* the last texel: exactly the second colour */
	px[4 * (N - 1)] = 20, px[4 * (N - 1) + 1] = 40, px[4 * (N - 1) + 2] = 10;
	struct tile *o = run1(&tn, a, NULL, NULL);
	const float *m = tile_f32(o);
	for (int d = 0; d <= 10; d++)
		assert_true(m[d] == 1.0f);
	for (int d = 50; d < 200; d++)
		assert_true(m[d] == 0.0f);
	assert_true(fabsf(m[30] - 0.5f) < 1e-6f); /* the middle of the smoothstep */
	for (int d = 11; d < 50; d++)
		assert_true(m[d] < m[d - 1] && m[d] > 0 && m[d] < 1);
	assert_true(m[N - 1] == 1.0f);
	tile_unref(o);
	tile_unref(a);
	unmake(&tn);
	static const struct {
		const char *params, *key;
	} bad[] = {
		{ "near = 10", "colors" },
		{ "colors = 1 2", "colors" },
		{ "colors = 1 2 300", "colors" },
		{ "colors = 1 2 3\nnear = 40\nfar = 20", "far" },
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		assert_int_equal(make(&tn, &node_type_color_mask, &input_color, NULL, NULL,
				      bad[i].params),
				 -EINVAL);
		if (!strstr(tn.err, bad[i].key))
			fail_msg("%s: \"%s\" does not name %s", bad[i].params, tn.err, bad[i].key);
		unmake(&tn);
	}
}

static void ramp_run(const char *params, const float *hs, int n, uint8_t *out)
{
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_ramp, &input_height, NULL, NULL, params), 0);
	assert_int_equal(tn.n.out, PIX_COLOR);
	struct tile *a = height_tile(0);
	memcpy(tile_f32(a), hs, (size_t)n * sizeof *hs);
	struct tile *o = run1(&tn, a, NULL, NULL);
	memcpy(out, o->data, (size_t)n * 4);
	tile_unref(a);
	tile_unref(o);
	unmake(&tn);
}

static void ramp_stops(void **state)
{
	(void)state;
	const char *p = "stops = 0 0 0 0, 100 200 100 50, 300 0 255 255";
	const float hs[] = { 0, 100, 300, 50, 250, -10, 1000, NAN, 99.999f, 100.001f };
	uint8_t o[10][4];
	ramp_run(p, hs, 10, &o[0][0]);
	static const uint8_t want[10][4] = {
		{ 0, 0, 0, 255 },	 { 200, 100, 50, 255 },	 { 0, 255, 255, 255 },
		{ 100, 50, 25, 255 },	 { 50, 216, 204, 255 },	 { 0, 0, 0, 255 },
		{ 0, 255, 255, 255 },	 { 0, 0, 0, 0 },	 { 200, 100, 50, 255 },
		{ 200, 100, 50, 255 },
	};
	for (int i = 0; i < 10; i++) {
		for (int c = 0; c < 4; c++) {
			if (o[i][c] != want[i][c])
				fail_msg("height %g: channel %d is %d, want %d", (double)hs[i], c,
					 o[i][c], want[i][c]);
		}
	}
	/* sea_level shifts every stop */
	const float hs2[] = { 1100, 1000, 1050 };
	ramp_run("sea_level = 1000\nstops = 0 0 0 0, 100 200 100 50, 300 0 255 255", hs2, 3,
		 &o[0][0]);
	assert_memory_equal(o[0], want[1], 4);
	assert_memory_equal(o[1], want[0], 4);
	assert_memory_equal(o[2], want[3], 4);
	/* many close stops: every height lands in its own segment */
	char many[2048] = "stops = ";
	for (int s = 0; s < 40; s++) {
		size_t l = strlen(many);
		snprintf(many + l, sizeof many - l, "%s%d %d %d %d", s ? ", " : "", s * s,
			 s * 6, 255 - s * 6, s % 2 * 255);
	}
	float hm[40];
	for (int s = 0; s < 40; s++)
		hm[s] = (float)(s * s);
	uint8_t om[40][4];
	ramp_run(many, hm, 40, &om[0][0]);
	for (int s = 0; s < 40; s++) {
		assert_int_equal(om[s][0], s * 6);
		assert_int_equal(om[s][1], 255 - s * 6);
		assert_int_equal(om[s][2], s % 2 * 255);
	}
}

static void ramp_default(void **state)
{
	(void)state;
	const float hs[] = { -5000, -20, 100, 1200, 6000 };
	uint8_t o[5][4];
	ramp_run("", hs, 5, &o[0][0]);
	assert_true(o[0][2] > o[0][0] + 50 && o[0][2] > o[0][1] + 30); /* deep blue */
	assert_true(o[1][2] > 180 && o[1][1] > 150);			 /* shallow cyan */
	assert_true(o[2][1] > o[2][0] && o[2][1] > o[2][2]);		 /* green */
	assert_true(o[3][0] > o[3][2] + 30);				 /* tan/brown */
	assert_true(o[4][0] > 240 && o[4][1] > 240 && o[4][2] > 240);	 /* snow */
	/* sea_level raises the coast: at 100 m under a 200 m sea it is water */
	ramp_run("sea_level = 200", hs + 2, 1, &o[0][0]);
	assert_true(o[0][2] > o[0][0] + 50);
}

static void ramp_errors(void **state)
{
	(void)state;
	static const struct {
		const char *stops, *want;
	} cases[] = {
		{ "0 0 0, 100 1 2 3", "stops: item 1 \"0 0 0\": expected \"height r g b\"" },
		{ "0 1 2 3, 0 4 5 6", "stops: item 2 \"0 4 5 6\": height 0 is not above" },
		{ "0 1 2 3, 10 4 5 6, 5 1 1 1", "item 3 \"5 1 1 1\"" },
		{ "0 1 2 300", "item 1 \"0 1 2 300\": colour 300 is outside 0..255" },
		{ "0 1 2 3, sea 1 2 3", "item 2 \"sea 1 2 3\"" },
		{ "0 1 2 3,", "item 2 \"\"" },
		{ "0 1 2 3 4", "item 1 \"0 1 2 3 4\"" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
		struct tnode tn;
		char params[256];
		snprintf(params, sizeof params, "stops = %s", cases[i].stops);
		assert_int_equal(make(&tn, &node_type_ramp, &input_height, NULL, NULL, params),
				 -EINVAL);
		if (!strstr(tn.err, cases[i].want))
			fail_msg("stops \"%s\": error \"%s\" lacks \"%s\"", cases[i].stops, tn.err,
				 cases[i].want);
		assert_non_null(strstr(tn.err, "test.ini:2:"));
		unmake(&tn);
	}
}

/* With a slope input: flat texels keep the ramp's colour, steep ones take steep_stops',
 * between steep_from and steep_to they blend linearly, and snow thins on steep texels. */
static void ramp_steep(void **state)
{
	(void)state;
	static const char base[] = "stops = 0 0 100 0, 1000 0 200 0\n"
				   "steep_stops = 0 100 100 100, 1000 200 200 200\n"
				   "steep_from = 0.5\nsteep_to = 1\n";
	static const float slopes[] = { 0, 0.2f, 0.5f, 0.75f, 1, 3, NAN };
	static const uint8_t want[][3] = { { 0, 150, 0 },	  { 0, 150, 0 },     { 0, 150, 0 },
					   { 75, 150, 75 },	  { 150, 150, 150 }, { 150, 150, 150 },
					   { 0, 150, 0 } };
	const int ns = (int)(sizeof slopes / sizeof *slopes);
	char params[512];
	for (int snow = 0; snow < 2; snow++) {
		snprintf(params, sizeof params, "%s%s", base,
			 snow ? "snow_equator = -100\nsnow_pole = -100\nsnow_blend = 1\n"
				"snow_color = 255,255,255" : "");
		struct tnode tn;
		assert_int_equal(make(&tn, &node_type_ramp, &input_height, &input_height2, NULL,
				      params), 0);
		struct tile *h = height_tile(500), *sl = height_tile(0);
		for (int i = 0; i < N; i++)
			tile_f32(sl)[i] = slopes[i % ns];
		struct tile *o = run1(&tn, h, sl, NULL);
		for (int i = 0; i < N; i++) {
			const uint8_t *d = o->data + 4 * i;
			float w = (float)(slopes[i % ns] == slopes[i % ns] ? slopes[i % ns] : 0);
			w = w < 0.5f ? 0 : w > 1 ? 1 : (w - 0.5f) * 2;
			for (int c = 0; c < 3; c++) {
				/* snow (white) covers the flat share, the steep share stays rock */
				float e = snow ? 255 + (want[i % ns][c] - 255) * w : want[i % ns][c];
				if (fabsf(d[c] - e) > 1)
					fail_msg("snow %d slope %g channel %d: %d, want %g", snow,
						 slopes[i % ns], c, d[c], e);
			}
			assert_int_equal(d[3], 255);
		}
		tile_unref(h);
		tile_unref(sl);
		tile_unref(o);
		unmake(&tn);
	}
}

static void ramp_steep_errors(void **state)
{
	(void)state;
	static const struct {
		bool slope;
		const char *params, *want;
	} cases[] = {
		{ false, "steep_stops = 0 1 2 3", "test.ini:2: steep_stops: needs input \"slope\"" },
		{ false, "steep_to = 2", "test.ini:2: steep_to: needs input \"slope\"" },
		{ true, "steep_from = 0.5", "slope: input slope needs steep_stops" },
		{ true, "steep_stops = 0 1 2 3\nsteep_from = 1\nsteep_to = 0.5",
		  "test.ini:4: steep_to: steep_to (0.5) is not above steep_from (1)" },
		{ true, "steep_stops = 0 1 2", "test.ini:2: steep_stops: item 1 \"0 1 2\"" },
		{ true, "steep_from = -1\nsteep_stops = 0 1 2 3", "test.ini:2: steep_from:" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof *cases; i++) {
		struct tnode tn;
		assert_int_equal(make(&tn, &node_type_ramp, &input_height,
				      cases[i].slope ? &input_height2 : NULL, NULL, cases[i].params),
				 -EINVAL);
		if (!strstr(tn.err, cases[i].want))
			fail_msg("\"%s\": error \"%s\" lacks \"%s\"", cases[i].params, tn.err,
				 cases[i].want);
		unmake(&tn);
	}
}

static float blend_h(const char *params, float a, float b, const float *mask)
{
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2,
			      mask ? &input_height2 : NULL, params), 0);
	assert_int_equal(tn.n.out, PIX_HEIGHT);
	struct tile *ta = height_tile(a), *tb = height_tile(b), *tm = mask ? height_tile(*mask)
									     : NULL;
	struct tile *o = run1(&tn, ta, tb, tm);
	float r = tile_f32(o)[N / 2];
	tile_unref(ta);
	tile_unref(tb);
	tile_unref(tm);
	tile_unref(o);
	unmake(&tn);
	return r;
}

static void blend_c(const char *params, const uint8_t a[4], const uint8_t b[4], const float *mask,
		    uint8_t out[4])
{
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &input_color, &input_color2,
			      mask ? &input_height : NULL, params), 0);
	assert_int_equal(tn.n.out, PIX_COLOR);
	struct tile *ta = color_tile(a), *tb = color_tile(b), *tm = mask ? height_tile(*mask) : NULL;
	struct tile *o = run1(&tn, ta, tb, tm);
	memcpy(out, o->data + 4 * (N / 2), 4);
	tile_unref(ta);
	tile_unref(tb);
	tile_unref(tm);
	tile_unref(o);
	unmake(&tn);
}

static void blend_heights(void **state)
{
	(void)state;
	const float half = 0.5f, neg = -1, big = 2, nan = NAN;
	assert_float_equal(blend_h("", 100, 200, NULL), 200, 0);
	assert_float_equal(blend_h("opacity = 0.25", 100, 200, NULL), 125, 1e-4);
	assert_float_equal(blend_h("opacity = 0.25", 100, NAN, NULL), 100, 0);
	assert_float_equal(blend_h("opacity = 0.25", NAN, 200, NULL), 200, 0);
	assert_float_equal(blend_h("mode = mask", 100, 200, &half), 150, 1e-4);
	assert_float_equal(blend_h("mode = mask\nopacity = 0.5", 100, 200, &half), 125, 1e-4);
	assert_float_equal(blend_h("mode = mask", 100, 200, &neg), 100, 0);
	assert_float_equal(blend_h("mode = mask", 100, 200, &big), 200, 0);
	assert_float_equal(blend_h("mode = mask", 100, 200, &nan), 100, 0);
	assert_float_equal(blend_h("mode = add", 100, 200, NULL), 300, 0);
	assert_float_equal(blend_h("mode = add\nweight = -0.5", 100, 200, NULL), 0, 0);
	assert_float_equal(blend_h("mode = add\nweight = 0.5", 100, 200, &half), 150, 1e-4);
}

static void blend_colors(void **state)
{
	(void)state;
	uint8_t o[4];
	const float half = 0.5f;
	/* b (half transparent red) over opaque grey: 100·(1 − 128/255) + 200·128/255 = 150.2 */
	blend_c("", (const uint8_t[]){ 100, 100, 100, 255 }, (const uint8_t[]){ 200, 0, 0, 128 },
		NULL, o);
	assert_memory_equal(o, ((const uint8_t[]){ 150, 50, 50, 255 }), 4);
	/* over a transparent a: b's colour, b's alpha × opacity */
	blend_c("opacity = 0.5", (const uint8_t[]){ 9, 9, 9, 0 },
		(const uint8_t[]){ 200, 40, 60, 200 }, NULL, o);
	assert_memory_equal(o, ((const uint8_t[]){ 200, 40, 60, 100 }), 4);
	/* both half transparent: alpha = 0.5 + 0.5·0.5 */
	blend_c("", (const uint8_t[]){ 0, 0, 0, 128 }, (const uint8_t[]){ 255, 255, 255, 128 }, NULL,
		o);
	assert_in_range(o[3], 191, 192);
	assert_in_range(o[0], 169, 171); /* 255 · 0.502 / 0.752 */
	/* nothing at all stays transparent */
	blend_c("", (const uint8_t[]){ 1, 2, 3, 0 }, (const uint8_t[]){ 4, 5, 6, 0 }, NULL, o);
	assert_int_equal(o[3], 0);
	/* mask: lerp of every channel, b's alpha ignored */
	blend_c("mode = mask", (const uint8_t[]){ 100, 0, 50, 255 },
		(const uint8_t[]){ 200, 100, 51, 0 }, &half, o);
	assert_memory_equal(o, ((const uint8_t[]){ 150, 50, 51, 128 }), 4);
	/* multiply: a·b/255, a's alpha */
	blend_c("mode = multiply", (const uint8_t[]){ 200, 100, 50, 200 },
		(const uint8_t[]){ 128, 255, 0, 10 }, NULL, o);
	assert_memory_equal(o, ((const uint8_t[]){ 100, 100, 0, 200 }), 4);
	blend_c("mode = multiply\nopacity = 0.5", (const uint8_t[]){ 200, 100, 50, 200 },
		(const uint8_t[]){ 0, 255, 0, 10 }, NULL, o);
	assert_memory_equal(o, ((const uint8_t[]){ 100, 100, 25, 200 }), 4);
}

static void blend_masked_and_normals(void **state)
{
	(void)state;
	uint8_t o[4];
	const float quarter = 0.25f;
	/* over with a mask scales b's alpha: 100 + (200 − 100)·(255/255)·0.25 = 125 */
	blend_c("", (const uint8_t[]){ 100, 100, 100, 255 }, (const uint8_t[]){ 200, 0, 20, 255 },
		&quarter, o);
	assert_memory_equal(o, ((const uint8_t[]){ 125, 75, 80, 255 }), 4);
	/* normals blend as a lerp of both components */
	struct node n1 = { .name = "n1", .out = PIX_NORMAL, .hash = 21 };
	struct node n2 = { .name = "n2", .out = PIX_NORMAL, .hash = 22 };
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &n1, &n2, NULL, "opacity = 0.5"), 0);
	assert_int_equal(tn.n.out, PIX_NORMAL);
	struct tile *ta = tile_create(&key0, PIX_NORMAL, T), *tb = tile_create(&key0, PIX_NORMAL, T);
	memset(ta->data, 100, ta->nbytes);
	memset(tb->data, 200, tb->nbytes);
	tb->data[1] = 0;
	struct tile *out = run1(&tn, ta, tb, NULL);
	assert_int_equal(out->data[0], 150);
	assert_int_equal(out->data[1], 50);
	assert_int_equal(out->data[2 * N - 1], 150);
	tile_unref(ta);
	tile_unref(tb);
	tile_unref(out);
	unmake(&tn);
}

static void blend_errors(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_color, NULL, ""),
			 -EINVAL);
	if (!strstr(tn.err, "test.ini:1: b:") || !strstr(tn.err, "\"photo\" gives color"))
		fail_msg("unexpected error \"%s\"", tn.err);
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_blend, &input_color, &input_color2, NULL,
			      "mode = add"), -EINVAL);
	assert_non_null(strstr(tn.err, "test.ini:2: mode: add works on heights"));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2, NULL,
			      "mode = multiply"), -EINVAL);
	assert_non_null(strstr(tn.err, "mode: multiply works on colours"));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2, NULL,
			      "mode = mask"), -EINVAL);
	assert_non_null(strstr(tn.err, "mode: mode mask needs input \"mask\""));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2, NULL,
			      "mode = screen"), -EINVAL);
	assert_non_null(strstr(tn.err, "not one of: over, mask, add, multiply"));
	unmake(&tn);
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2, &input_color,
			      ""), -EINVAL);
	assert_non_null(strstr(tn.err, "mask"));
	unmake(&tn);
}

/* Parameters feed the content hash: a different value names different tiles. */
static void hashes_differ(void **state)
{
	(void)state;
	struct tnode a, b, c;
	assert_int_equal(make(&a, &node_type_color_filter, &input_color, NULL, NULL, "gamma = 2"),
			 0);
	assert_int_equal(make(&b, &node_type_color_filter, &input_color, NULL, NULL, "gamma = 2.1"),
			 0);
	assert_int_equal(make(&c, &node_type_ramp, &input_height, NULL, NULL, "sea_level = 1"), 0);
	assert_true(a.n.hash != b.n.hash);
	uint64_t h = c.n.hash;
	unmake(&c);
	assert_int_equal(make(&c, &node_type_ramp, &input_height, NULL, NULL, "sea_level = 2"), 0);
	assert_true(c.n.hash != h);
	unmake(&a);
	unmake(&b);
	unmake(&c);
}

/* The AVX2 base ramp gives the scalar loop's bytes for one table: random heights across every
 * stop and beyond both ends, on the stops, just either side of them (one ulp), ±∞, ±0, NaN. */
static void ramp_vector_table(const char *table)
{
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_ramp, &input_height, NULL, NULL, table), 0);
	const struct ramp_table *rt = tn.n.impl; /* struct ramp's first member */
	enum { M = 1 << 16 };
	float *h = malloc(M * sizeof *h);
	uint8_t *a = malloc(4 * M), *b = malloc(4 * M);
	uint32_t seed = 99;
	float span = rt->h[rt->nstops - 1] - rt->h[0] + 2;
	for (int i = 0; i < M; i++)
		h[i] = rt->h[0] - 1 + span * (float)(rng(&seed) % 1000000) / 1e6f;
	int k = 0;
	for (int s = 0; s < rt->nstops; s++) {
		h[k++] = rt->h[s];
		h[k++] = nextafterf(rt->h[s], -INFINITY);
		h[k++] = nextafterf(rt->h[s], INFINITY);
	}
	float odd[] = { NAN, INFINITY, -INFINITY, -0.0f, 0.0f, 1e30f, -1e30f, 3.5f, -3.5f };
	for (size_t i = 0; i < sizeof odd / sizeof odd[0]; i++)
		h[k++] = odd[i];
	ramp_base_scalar(rt, h, a, M);
	ramp_base_avx2(rt, h, b, M);
	for (int i = 0; i < M; i++)
		if (memcmp(a + 4 * i, b + 4 * i, 4))
			fail_msg("%s: height %.9g: scalar %d %d %d %d, avx2 %d %d %d %d", table,
				 (double)h[i], a[4 * i], a[4 * i + 1], a[4 * i + 2], a[4 * i + 3],
				 b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]);
	free(h);
	free(a);
	free(b);
	unmake(&tn);
}

/* ramp_vector_table on a table of n stops 311 m apart. */
static void ramp_vector_stops(int n)
{
	char t[2048] = "stops = ";
	for (int q = 0; q < n; q++)
		snprintf(t + strlen(t), sizeof t - strlen(t), "%s%d %d %d %d", q ? ", " : "",
			 -9000 + 311 * q, (7 * q) % 256, 255 - (13 * q) % 256, (40 + 29 * q) % 256);
	ramp_vector_table(t);
}

/* Up to 32 stops the kernel compares and permutes (from one to four registers of eight
 * segments), beyond that it gathers: tables of 2, 3, 7, 8, 14, 17, 32 and 40 stops. */
static void ramp_vector_bytes(void **state)
{
	(void)state;
	if (!noise_isa_supported(NOISE_ISA_AVX2))
		skip();
	ramp_vector_table("stops = -9000 4 10 40, -5000 10 30 90, -1 140 208 222, 0 196 184 140, "
			  "20 96 130 62, 350 66 108 48, 3700 190 188 184\nsea_level = 3.5");
	ramp_vector_table("stops = -14 120 135 120, 0 205 215 205, 14 255 255 255");
	ramp_vector_table("stops = -5 10 20 30, 5 200 100 0");
	ramp_vector_table("stops = -8 1 2 3, -7 4 5 6, -6 7 8 9, -5 10 11 12, -4 13 14 15, "
			  "-3 16 17 18, -2 19 20 21, -1 22 23 24");
	ramp_vector_table("sea_level = -2.5"); /* the default ramp: 14 stops */
	ramp_vector_stops(17);
	ramp_vector_stops(32);
	ramp_vector_stops(40);
}

/* The steep blend and the snow, eight texels at a time, give the scalar loops' bytes: random
 * heights across both tables' stops (and at them, and NaN, ±∞), slopes across the weight's
 * ramp (and NaN), over random colours; snow lines with and without sea ice and a slope row. */
static void ramp_steep_snow_vector_bytes(void **state)
{
	(void)state;
	if (!noise_isa_supported(NOISE_ISA_AVX2))
		skip();
	struct tnode ta, tb;
	assert_int_equal(make(&ta, &node_type_ramp, &input_height, NULL, NULL,
			      "stops = -9000 4 10 40, -1 140 208 222, 0 196 184 140, 20 96 130 62, "
			      "350 66 108 48, 3700 190 188 184"),
			 0);
	assert_int_equal(make(&tb, &node_type_ramp, &input_height, NULL, NULL,
			      "stops = -9000 4 10 40, 0 156 146 124, 300 134 128 116, "
			      "2600 132 130 126, 3600 152 150 148"),
			 0);
	const struct ramp_table *base = ta.n.impl, *steep = tb.n.impl;
	enum { M = 1 << 16 };
	float *h = malloc(M * sizeof *h), *sl = malloc(M * sizeof *sl);
	uint8_t *d0 = malloc(4 * M), *a = malloc(4 * M), *b = malloc(4 * M);
	uint32_t seed = 7;
	for (int i = 0; i < M; i++) {
		h[i] = (float)((int)(rng(&seed) % 1400000) - 1000000) / 100.0f;
		sl[i] = (float)(rng(&seed) % 1000) / 1000.0f;
		for (int c = 0; c < 4; c++)
			d0[4 * i + c] = (uint8_t)rng(&seed);
	}
	int k = 0;
	for (int s = 0; s < base->nstops; s++, k += 3) {
		h[k] = base->h[s];
		h[k + 1] = nextafterf(base->h[s], -INFINITY);
		h[k + 2] = nextafterf(base->h[s], INFINITY);
	}
	float odd[] = { NAN, INFINITY, -INFINITY, -0.0f, 0.0f, 1e30f, -1e30f };
	for (size_t i = 0; i < sizeof odd / sizeof odd[0]; i++, k++)
		h[k] = odd[i];
	for (int i = 0; i < 64; i++)
		sl[k + i] = i % 3 ? 0.25f + (float)i / 256.0f : NAN;
	const struct ramp_steep st = { base, steep, 0.25f, 4.0f };
	memcpy(a, d0, 4 * M);
	memcpy(b, d0, 4 * M);
	ramp_steep_scalar(&st, h, sl, a, M);
	ramp_steep_avx2(&st, h, sl, b, M);
	for (int i = 0; i < M; i++)
		if (memcmp(a + 4 * i, b + 4 * i, 4))
			fail_msg("steep: height %.9g slope %.9g: scalar %d %d %d %d, avx2 %d %d %d %d",
				 (double)h[i], (double)sl[i], a[4 * i], a[4 * i + 1], a[4 * i + 2],
				 a[4 * i + 3], b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]);
	assert_true(memcmp(a, d0, 4 * M) != 0); /* it did blend */
	/* a base of more than 32 stops: the kernel's gathers instead of its registers */
	struct tnode tc;
	char many[2048] = "stops = ";
	for (int q = 0; q < 40; q++)
		snprintf(many + strlen(many), sizeof many - strlen(many), "%s%d %d %d %d",
			 q ? ", " : "", -9000 + 350 * q, 6 * q, 255 - 5 * q, 40 + 4 * q);
	assert_int_equal(make(&tc, &node_type_ramp, &input_height, NULL, NULL, many), 0);
	const struct ramp_steep sm = { tc.n.impl, steep, 0.25f, 4.0f };
	assert_true(sm.base->nstops == 40);
	memcpy(a, d0, 4 * M);
	memcpy(b, d0, 4 * M);
	ramp_steep_scalar(&sm, h, sl, a, M);
	ramp_steep_avx2(&sm, h, sl, b, M);
	assert_memory_equal(a, b, 4 * M);
	unmake(&tc);
	struct ramp_snow sn[] = {
		{ .line = 1033.5f, .inv = 1.0f / 400, .ice = -0.25f, .sea_ice = true,
		  .snow = { 242, 245, 250, 255 }, .from = 0.25f, .inv_steep = 4.0f },
		{ .line = 600.0f, .inv = 1.0f / 400, .ice = 0.6f, .sea_ice = true,
		  .snow = { 242, 245, 250, 255 }, .from = 0.25f, .inv_steep = 4.0f },
		{ .line = 4300.0f, .inv = 1.0f / 250, .ice = 0, .sea_ice = false,
		  .snow = { 10, 200, 255, 255 } },
	};
	for (size_t c = 0; c < sizeof sn / sizeof sn[0]; c++)
		for (int withslope = 0; withslope < 2; withslope++) {
			memcpy(a, d0, 4 * M);
			memcpy(b, d0, 4 * M);
			ramp_snow_scalar(&sn[c], h, withslope ? sl : NULL, a, M);
			ramp_snow_avx2(&sn[c], h, withslope ? sl : NULL, b, M);
			for (int i = 0; i < M; i++)
				if (memcmp(a + 4 * i, b + 4 * i, 4))
					fail_msg("snow %zu/%d: height %.9g: scalar %d %d %d %d, avx2 "
						 "%d %d %d %d", c, withslope, (double)h[i], a[4 * i],
						 a[4 * i + 1], a[4 * i + 2], a[4 * i + 3], b[4 * i],
						 b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]);
			assert_true(memcmp(a, d0, 4 * M) != 0); /* it did snow */
		}
	free(h);
	free(sl);
	free(d0);
	free(a);
	free(b);
	unmake(&ta);
	unmake(&tb);
}

/* The AVX2 colour mask gives color_mask_texel's values bit for bit over a lattice of the RGB
 * cube (every third level of each channel, the references' own colours among them), and
 * says whether any is not 0; a tile nowhere near becomes the shared all-zero tile. */
static void color_mask_vector(void **state)
{
	(void)state;
	if (!noise_isa_supported(NOISE_ISA_AVX2))
		skip();
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_color_mask, &input_color, NULL, NULL,
			      "colors = 188 142 98, 208 184 146, 25 42 11\nnear = 20\nfar = 60"),
			 0);
	const struct color_mask *m = tn.n.impl;
	enum { L = 86, M = L * L * L + 8 - (L * L * L) % 8 };
	uint8_t *px = calloc(M, 4);
	float *a = malloc(M * sizeof *a), *b = malloc(M * sizeof *b);
	size_t k = 0;
	for (int r = 0; r < L; r++)
		for (int g = 0; g < L; g++)
			for (int bl = 0; bl < L; bl++, k++) {
				px[4 * k] = (uint8_t)(3 * r);
				px[4 * k + 1] = (uint8_t)(3 * g);
				px[4 * k + 2] = (uint8_t)(3 * bl);
				px[4 * k + 3] = (uint8_t)k;
			}
	static const uint8_t refs[][3] = { { 188, 142, 98 }, { 208, 184, 146 }, { 25, 42, 11 } };
	for (int i = 0; i < 3 && k < M; i++, k++)
		memcpy(px + 4 * k, refs[i], 3);
	for (size_t i = 0; i < M; i++)
		a[i] = color_mask_texel(m, px + 4 * i);
	assert_true(color_mask_avx2(m, px, b, M));
	for (size_t i = 0; i < M; i++)
		if (memcmp(&a[i], &b[i], sizeof a[i]))
			fail_msg("rgb %d %d %d: %.9g against %.9g", px[4 * i], px[4 * i + 1],
				 px[4 * i + 2], (double)a[i], (double)b[i]);
	/* deep blue sea, nowhere near a reference */
	const uint8_t sea[4] = { 10, 20, 90, 255 };
	struct tile *in = color_tile(sea), *o = run1(&tn, in, NULL, NULL);
	assert_false(color_mask_avx2(m, in->data, b, N));
	assert_true(o->uniform && o->summarized && o->hi == 0 && tile_f32(o)[N - 1] == 0);
	tile_unref(in);
	tile_unref(o);
	free(px);
	free(a);
	free(b);
	unmake(&tn);
}

/* A colour multiply gives, texel for texel, rgb = x + (x·y/255 − x)·w rounded, alpha x's, w the
 * mask clamped to [0, 1] (NaN 0) times the opacity: the vector kernel's bytes against that
 * formula over random colours and masks (NaN, −0, below 0, above 1 among them). */
static void blend_multiply_bytes(void **state)
{
	(void)state;
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &input_color, &input_color2, &input_height,
			      "mode = multiply\nopacity = 0.8"),
			 0);
	uint32_t seed = 5;
	for (int rep = 0; rep < 64; rep++) {
		struct tile *a = tile_create(&key0, PIX_COLOR, T), *b = tile_create(&key0, PIX_COLOR, T);
		struct tile *m = tile_create(&key0, PIX_HEIGHT, T);
		for (size_t i = 0; i < a->nbytes; i++) {
			a->data[i] = (uint8_t)rng(&seed);
			b->data[i] = (uint8_t)rng(&seed);
		}
		static const float odd[] = { NAN, -0.0f, -3.0f, 0.0f, 1.0f, 7.5f, 0.5f };
		for (int i = 0; i < N; i++)
			tile_f32(m)[i] = i % 5 == 0 ? odd[(i / 5) % 7] : (float)(rng(&seed) % 1000) / 999.0f;
		struct tile *o = run1(&tn, a, b, m);
		for (int i = 0; i < N; i++) {
			float w = tile_f32(m)[i];
			w = w > 0.0f ? w : 0.0f;
			w = (w < 1.0f ? w : 1.0f) * 0.8f;
			for (int c = 0; c < 3; c++) {
				uint8_t x = a->data[4 * i + c], y = b->data[4 * i + c];
				float prod = x * (float)y * (1.0f / 255);
				uint8_t want = (uint8_t)(int)(x + (prod - x) * w + 0.5f);
				if (o->data[4 * i + c] != want)
					fail_msg("x %d y %d mask %g: %d, want %d", x, y,
						 (double)tile_f32(m)[i], o->data[4 * i + c], want);
			}
			assert_int_equal(o->data[4 * i + 3], a->data[4 * i + 3]);
		}
		tile_unref(a);
		tile_unref(b);
		tile_unref(m);
		tile_unref(o);
	}
	unmake(&tn);
}

/* Blends of heights (add, over, mask): the node's bits, texel for texel, against the formulas
 * of node_blend's header — w = clamp(mask, 0, 1) · opacity (NaN 0); add a + b·weight·w where
 * w > 0, else a; over and mask lerp(a, b, w) where w > 0, else a, a NaN in b keeping a and a
 * NaN in a taking b — over random heights and masks with NaN, ±0, ±∞ and weights outside
 * [0, 1] among them (the vector kernel and the scalar loop must agree to the bit). */
static float odd_height(uint32_t *seed, int i)
{
	static const float odd[] = { NAN, -0.0f, 0.0f, INFINITY, -INFINITY, 1e30f, -5.5f };
	return i % 7 == 3 ? odd[(uint32_t)i / 7 % 7] : ((float)(rng(seed) % 20001) - 10000.0f) / 7.0f;
}

static void blend_heights_bits(void **state)
{
	(void)state;
	static const char *const modes[] = { "mode = add\nweight = 2.5\nopacity = 0.8",
					     "mode = add", "mode = over\nopacity = 0.8",
					     "mode = over", "mode = mask\nopacity = 0.7" };
	uint32_t seed = 9;
	for (size_t mi = 0; mi < sizeof modes / sizeof modes[0]; mi++)
		for (int masked = 0; masked < 2; masked++) {
			bool add = strstr(modes[mi], "add") != NULL;
			if (!masked && strstr(modes[mi], "mask"))
				continue;
			float op = strstr(modes[mi], "0.8") ? 0.8f : strstr(modes[mi], "0.7") ? 0.7f : 1.0f;
			float weight = strstr(modes[mi], "2.5") ? 2.5f : 1.0f;
			struct tnode tn;
			assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2,
					      masked ? &input_height : NULL, modes[mi]),
					 0);
			tn.n.summarize = true; /* as when a node reads it as a mask */
			for (int rep = 0; rep < 16; rep++) {
				/* 10×10: 100 texels, not a multiple of 8, take the scalar loop */
				uint32_t S = rep % 2 ? 10 : T;
				int NS = (int)(S * S);
				struct tile *a = tile_create(&key0, PIX_HEIGHT, S);
				struct tile *b = tile_create(&key0, PIX_HEIGHT, S);
				struct tile *m = tile_create(&key0, PIX_HEIGHT, S);
				for (int i = 0; i < NS; i++) {
					tile_f32(a)[i] = odd_height(&seed, i + rep);
					tile_f32(b)[i] = odd_height(&seed, i + 2 * rep + 1);
					float mv = (float)(rng(&seed) % 1000) / 800.0f - 0.1f;
					tile_f32(m)[i] = i % 11 == 5 ? odd_height(&seed, i) : mv;
				}
				struct tile *o = run1(&tn, a, b, masked ? m : NULL);
				for (int i = 0; i < NS; i++) {
					float x = tile_f32(a)[i], y = tile_f32(b)[i], w = op;
					if (masked) {
						w = tile_f32(m)[i];
						w = w > 0.0f ? w : 0.0f;
						w = (w < 1.0f ? w : 1.0f) * op;
					}
					float want;
					if (add)
						want = w > 0.0f ? x + y * (weight * w) : x;
					else
						want = isnan(y) ? x : isnan(x) ? y : w > 0.0f ? x + (y - x) * w : x;
					float got = tile_f32(o)[i];
					if (memcmp(&got, &want, sizeof got))
						fail_msg("%s, mask %d: a %g b %g w %g: %g, want %g", modes[mi],
							 masked, (double)x, (double)y, (double)w, (double)got,
							 (double)want);
				}
				/* the summary the vector kernel kept as it wrote (the scalar loop leaves it
				 * to the worker's scan): the scan's, to the bit */
				struct tile *c = tile_create(&key0, PIX_HEIGHT, S);
				memcpy(c->data, o->data, o->nbytes);
				tile_summarize(c);
				assert_int_equal(o->summarized, noise_isa_has_avx2() && S == T);
				if (o->summarized) {
					assert_memory_equal(&o->lo, &c->lo, sizeof c->lo);
					assert_memory_equal(&o->hi, &c->hi, sizeof c->hi);
					assert_int_equal(o->any_nan, c->any_nan);
				}
				tile_unref(c);
				tile_unref(a);
				tile_unref(b);
				tile_unref(m);
				tile_unref(o);
			}
			unmake(&tn);
		}
}

/* Colour over, with and without a mask: where a is opaque rgb = (x·(65536 − kb) + y·kb +
 * 32768) >> 16, kb = y_alpha · w · 65536/255 + 0.5 truncated, alpha 255; where it is not,
 * straight-alpha compositing (ao = ab + aa(1 − ab), rgb (x·aa(1 − ab) + y·ab)/ao) — over random
 * colours where most bases are opaque and some are not (so the kernel's groups of eight take
 * both of its paths), and odd masks. */
static void blend_over_bytes(void **state)
{
	(void)state;
	uint32_t seed = 17;
	for (int masked = 0; masked < 2; masked++)
		for (int oi = 0; oi < 2; oi++) {
			float op = oi ? 0.8f : 1.0f;
			struct tnode tn;
			assert_int_equal(make(&tn, &node_type_blend, &input_color, &input_color2,
					      masked ? &input_height : NULL,
					      oi ? "mode = over\nopacity = 0.8" : "mode = over"),
					 0);
			for (int rep = 0; rep < 32; rep++) {
				uint32_t S = rep % 2 ? 10 : T; /* 10×10: the scalar loops */
				int NS = (int)(S * S);
				struct tile *a = tile_create(&key0, PIX_COLOR, S);
				struct tile *b = tile_create(&key0, PIX_COLOR, S);
				struct tile *m = tile_create(&key0, PIX_HEIGHT, S);
				for (size_t i = 0; i < a->nbytes; i++) {
					a->data[i] = (uint8_t)rng(&seed);
					b->data[i] = (uint8_t)rng(&seed);
				}
				for (int i = 0; i < NS; i++) {
					if (rng(&seed) % 29 != 0) /* opaque, but a few */
						a->data[4 * i + 3] = 255;
					if (i % 13 == 0)
						b->data[4 * i + 3] = (uint8_t)(i % 2 ? 255 : 0);
					static const float odd[] = { NAN, -0.0f, -3.0f, 0.0f, 1.0f, 7.5f };
					tile_f32(m)[i] = i % 5 == 0 ? odd[(i / 5) % 6]
								    : (float)(rng(&seed) % 1000) / 999.0f;
				}
				struct tile *o = run1(&tn, a, b, masked ? m : NULL);
				for (int i = 0; i < NS; i++) {
					const uint8_t *x = a->data + 4 * i, *y = b->data + 4 * i;
					float w = op;
					if (masked) {
						w = tile_f32(m)[i];
						w = w > 0.0f ? w : 0.0f;
						w = (w < 1.0f ? w : 1.0f) * op;
					}
					uint8_t want[4];
					if (x[3] == 255) {
						uint32_t kb = (uint32_t)(y[3] * w * (65536.0f / 255) + 0.5f);
						for (int c = 0; c < 3; c++)
							want[c] = (uint8_t)((x[c] * (65536 - kb) + y[c] * kb +
									     32768) >> 16);
						want[3] = 255;
					} else {
						float ab = y[3] * (w * (1.0f / 255)), aa = x[3] * (1.0f / 255);
						float ao = ab + aa * (1 - ab);
						if (ao <= 0) {
							memset(want, 0, 4);
						} else {
							float ka = aa * (1 - ab) / ao, kb = ab / ao;
							for (int c = 0; c < 3; c++)
								want[c] = (uint8_t)(int)(x[c] * ka + y[c] * kb + 0.5f);
							want[3] = (uint8_t)(int)(ao * 255 + 0.5f);
						}
					}
					if (memcmp(o->data + 4 * i, want, 4))
						fail_msg("mask %d opacity %g texel %d: a %d %d %d %d b %d %d %d %d "
							 "w %g: %d %d %d %d, want %d %d %d %d", masked, (double)op, i,
							 x[0], x[1], x[2], x[3], y[0], y[1], y[2], y[3], (double)w,
							 o->data[4 * i], o->data[4 * i + 1], o->data[4 * i + 2],
							 o->data[4 * i + 3], want[0], want[1], want[2], want[3]);
				}
				tile_unref(a);
				tile_unref(b);
				tile_unref(m);
				tile_unref(o);
			}
			unmake(&tn);
		}
}

/* ---- shared bytes: summaries, uniform tiles, aliases (tile.h) ------------------------------ */

/* A T×T height tile of a wavy field in [lo, lo + span], optionally with NaN and −0 texels. */
static struct tile *field_tile(float lo, float span, bool nan, bool neg0)
{
	struct tile *t = tile_create(&key0, PIX_HEIGHT, T);
	for (int i = 0; i < N; i++)
		tile_f32(t)[i] = lo + span * (0.5f + 0.5f * sinf((float)i * 0.37f));
	if (nan)
		tile_f32(t)[N / 3] = NAN;
	if (neg0)
		tile_f32(t)[N / 2] = -0.0f;
	return t;
}

static void tile_summaries(void **state)
{
	(void)state;
	struct tile *t = field_tile(-5, 10, true, false);
	tile_f32(t)[7] = -7.5f;
	tile_f32(t)[9] = 12.25f;
	tile_summarize(t);
	assert_true(t->summarized && t->any_nan);
	assert_true(t->lo == -7.5f && t->hi == 12.25f);
	tile_unref(t);
	struct tile *all_nan = height_tile(NAN);
	tile_summarize(all_nan);
	assert_true(all_nan->any_nan && all_nan->lo > all_nan->hi);
	tile_unref(all_nan);
	/* Uniform tiles: one buffer per type, size and value, held by every such tile; no
	 * memory charged to the cache; the summary set without a scan. */
	float one = 1, other = 2;
	struct tile *u1 = tile_create(&key0, PIX_HEIGHT, T), *u2 = tile_create(&key0, PIX_HEIGHT, T);
	struct tile *u3 = tile_create(&key0, PIX_HEIGHT, T);
	tile_fill_uniform(u1, &one);
	tile_fill_uniform(u2, &one);
	tile_fill_uniform(u3, &other);
	assert_ptr_equal(u1->data, u2->data);
	assert_ptr_not_equal(u1->data, u3->data);
	assert_true(u1->uniform && tile_charge(u1) == 0 && u1->summarized && u1->lo == 1 &&
		    u1->hi == 1 && !u1->any_nan);
	for (int i = 0; i < N; i++)
		assert_true(tile_f32(u3)[i] == 2);
	uint8_t px[4] = { 1, 2, 3, 4 };
	struct tile *c = tile_create(&key0, PIX_COLOR, T);
	tile_fill_uniform(c, px);
	assert_memory_equal(c->data + 4 * (N - 1), px, 4);
	assert_ptr_not_equal((void *)c->data, (void *)u1->data);
	/* An alias of an alias holds the owner, and outlives the tiles it was made from. */
	struct tile *f = field_tile(0, 100, false, false);
	tile_summarize(f);
	struct tile *a1 = tile_create(&key0, PIX_HEIGHT, T), *a2 = tile_create(&key0, PIX_HEIGHT, T);
	tile_alias(a1, f);
	tile_alias(a2, a1);
	assert_ptr_equal(a1->base, f);
	assert_ptr_equal(a2->base, f);
	assert_true(a2->summarized && a2->lo == f->lo && a2->hi == f->hi && !a2->uniform);
	assert_int_equal(tile_charge(a2), a2->nbytes);
	float v = tile_f32(f)[5];
	tile_unref(f);
	tile_unref(a1);
	assert_true(tile_f32(a2)[5] == v);
	struct tile *a3 = tile_create(&key0, PIX_HEIGHT, T);
	tile_alias(a3, u1);
	assert_true(a3->uniform && tile_charge(a3) == 0);
	tile_unref(a2);
	tile_unref(a3);
	tile_unref(u1);
	tile_unref(u2);
	tile_unref(u3);
	tile_unref(c);
}

/* A generated height tile whose texels are one value, bit for bit, moves onto the shared
 * buffer (as the scheduler does after every generation); anything else keeps its own. */
static void share_if_uniform(void **state)
{
	(void)state;
	float one = 1;
	struct tile *u = tile_create(&key0, PIX_HEIGHT, T);
	tile_fill_uniform(u, &one);
	struct tile *t = height_tile(1);
	assert_false(t->uniform);
	assert_true(tile_share_if_uniform(t));
	assert_ptr_equal(t->data, u->data);
	assert_true(t->uniform && tile_charge(t) == 0 && t->summarized && t->lo == 1 &&
		    t->hi == 1 && !t->any_nan);
	assert_false(tile_share_if_uniform(t)); /* already */
	tile_unref(t);
	/* one texel off, at either end or in the middle; −0 among +0; NaN among numbers */
	int at[] = { 0, N / 2 + 3, N - 1 };
	for (int i = 0; i < 3; i++) {
		t = height_tile(1);
		tile_f32(t)[at[i]] = 1.0000001f;
		assert_false(tile_share_if_uniform(t));
		assert_false(t->uniform);
		assert_true(tile_charge(t) == t->nbytes && tile_f32(t)[at[i]] == 1.0000001f);
		tile_unref(t);
	}
	t = height_tile(0);
	tile_f32(t)[N - 5] = -0.0f;
	assert_false(tile_share_if_uniform(t));
	assert_true(signbit(tile_f32(t)[N - 5]));
	tile_unref(t);
	t = height_tile(2);
	tile_f32(t)[7] = NAN;
	assert_false(tile_share_if_uniform(t));
	tile_unref(t);
	/* all NaN is one value too: shared, summary says so */
	t = height_tile(NAN);
	assert_true(tile_share_if_uniform(t));
	assert_true(t->uniform && t->any_nan && t->lo > t->hi);
	tile_unref(t);
	/* colour tiles and aliases are left alone */
	struct tile *c = tile_create(&key0, PIX_COLOR, T);
	memset(c->data, 7, c->nbytes);
	assert_false(tile_share_if_uniform(c));
	assert_false(c->uniform);
	tile_unref(c);
	struct tile *f = height_tile(3), *a = tile_create(&key0, PIX_HEIGHT, T);
	tile_alias(a, f);
	assert_false(tile_share_if_uniform(a));
	assert_ptr_equal(a->base, f);
	tile_unref(a);
	tile_unref(f);
	tile_unref(u);
}

/* A height_filter with a summarized input gives the bytes it gives without one (a shared
 * uniform tile where every texel clamps, strictly), and a summary equal to a scan's. */
static void height_filter_summary(void **state)
{
	(void)state;
	static const char *const params[] = {
		"scale = 0.001\noffset = 0\nmin = 0\nmax = 1",	  /* ramps within the range */
		"scale = 0.001\noffset = -5\nmin = 0\nmax = 1",	  /* all below min: uniform 0 */
		"scale = 0.001\noffset = 5\nmin = 0\nmax = 1",	  /* all above max: uniform 1 */
		"scale = -0.01\noffset = 0.5\nmin = 0\nmax = 1",  /* decreasing */
		"scale = -0.01\noffset = 50\nmin = 0\nmax = 1",	  /* decreasing, all above */
		"scale = 1\noffset = 0\nmin = 0",		  /* −0 lands on min = +0 */
		"scale = 2\noffset = 1",			  /* no clamp */
	};
	struct {
		float lo, span;
		bool nan, neg0;
	} inputs[] = { { 0, 1000, false, false }, { -300, 200, false, false },
		       { 0, 1000, true, false },  { -0.0f, 0, false, true },
		       { 10, 0, false, false } };
	for (size_t p = 0; p < sizeof params / sizeof params[0]; p++)
		for (size_t k = 0; k < sizeof inputs / sizeof inputs[0]; k++) {
			struct tnode tn;
			assert_int_equal(make(&tn, &node_type_height_filter, &input_height, NULL,
					      NULL, params[p]),
					 0);
			struct tile *plain = field_tile(inputs[k].lo, inputs[k].span, inputs[k].nan,
							inputs[k].neg0);
			struct tile *summed = field_tile(inputs[k].lo, inputs[k].span,
							 inputs[k].nan, inputs[k].neg0);
			tile_summarize(summed);
			struct tile *o1 = run1(&tn, plain, NULL, NULL), *o2 = run1(&tn, summed, NULL, NULL);
			assert_memory_equal(o1->data, o2->data, o1->nbytes);
			assert_false(o1->summarized || o1->uniform);
			assert_true(o2->summarized);
			struct tile *scan = tile_create(&key0, PIX_HEIGHT, T);
			memcpy(scan->data, o2->data, scan->nbytes);
			tile_summarize(scan);
			assert_true(scan->lo == o2->lo && scan->hi == o2->hi &&
				    scan->any_nan == o2->any_nan);
			if (p == 1 || p == 2 || p == 4)
				assert_true(o2->uniform || inputs[k].nan);
			tile_unref(scan);
			tile_unref(plain);
			tile_unref(summed);
			tile_unref(o1);
			tile_unref(o2);
			unmake(&tn);
		}
}

/* A blend whose mask is 0 everywhere shares a's bytes instead of copying them, exactly
 * where the loop would give a's bytes (no NaN in a), whatever b holds. */
/* Uniform inputs make uniform outputs where nothing else varies (the shared buffer, no
 * texel written), with the bytes the loops give on a tile of the same values: a ramp without
 * slope or snow, a height filter; an add whose b is 0 everywhere gives a's own bytes where a
 * has no −0 and no NaN (adds_zero), and computes them otherwise. */
static void uniform_inputs(void **state)
{
	(void)state;
	static const float hs[] = { -50.0f, 0.0f, -0.0f, 1234.5f, NAN, 1e9f };
	static const char *const ramps[] = { "stops = -100 0 0 80, 0 40 90 40, 2000 240 240 240",
					     "snow_equator = 4000\nsnow_pole = 500" };
	for (size_t r = 0; r < 2; r++) {
		struct tnode rt, ht;
		assert_int_equal(make(&rt, &node_type_ramp, &input_height, NULL, NULL, ramps[r]), 0);
		assert_int_equal(make(&ht, &node_type_height_filter, &input_height, NULL, NULL,
				      "scale = -0.5\noffset = 3\nmin = -100\nmax = 100"),
				 0);
		for (size_t i = 0; i < sizeof hs / sizeof *hs; i++) {
			struct tile *u = tile_create(&key0, PIX_HEIGHT, T), *p = height_tile(hs[i]);
			tile_fill_uniform(u, &hs[i]);
			struct tile *o1 = run1(&rt, u, NULL, NULL), *o2 = run1(&rt, p, NULL, NULL);
			assert_memory_equal(o1->data, o2->data, o1->nbytes);
			assert_int_equal(o1->uniform, r == 0); /* snow varies by latitude */
			struct tile *f1 = run1(&ht, u, NULL, NULL), *f2 = run1(&ht, p, NULL, NULL);
			assert_memory_equal(f1->data, f2->data, f1->nbytes);
			assert_true(f1->uniform && f1->summarized);
			tile_unref(u);
			tile_unref(p);
			tile_unref(o1);
			tile_unref(o2);
			tile_unref(f1);
			tile_unref(f2);
		}
		unmake(&rt);
		unmake(&ht);
	}
	struct tnode tn;
	assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2, &input_height,
			      "mode = add\nweight = 3"),
			 0);
	for (int zsign = 0; zsign < 2; zsign++)
		for (int kind = 0; kind < 4; kind++) {
			/* a: positive, negative, spanning 0, holding a −0 */
			struct tile *a = kind == 0   ? field_tile(5, 100, false, false)
					 : kind == 1 ? field_tile(-300, 100, false, false)
					 : kind == 2 ? field_tile(-50, 100, false, false)
						     : field_tile(-50, 100, false, true);
			tile_summarize(a);
			float z = zsign ? -0.0f : 0.0f;
			struct tile *b = tile_create(&key0, PIX_HEIGHT, T), *bp = height_tile(z);
			tile_fill_uniform(b, &z);
			struct tile *mask = field_tile(-0.5f, 2, true, false);
			struct tile *o1 = run1(&tn, a, b, mask), *o2 = run1(&tn, a, bp, mask);
			assert_memory_equal(o1->data, o2->data, o1->nbytes);
			assert_int_equal(o1->data == a->data, kind < 2);
			tile_unref(a);
			tile_unref(b);
			tile_unref(bp);
			tile_unref(mask);
			tile_unref(o1);
			tile_unref(o2);
		}
	unmake(&tn);
}

static void blend_shares_a(void **state)
{
	(void)state;
	static const char *const modes[] = { "mode = mask", "mode = over", "mode = add" };
	for (int m = 0; m < 3; m++)
		for (int nan = 0; nan < 2; nan++) {
			struct tnode tn;
			assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2,
					      &input_height, modes[m]),
					 0);
			struct tile *a = field_tile(-100, 500, nan, true), *b = field_tile(7, 3, true, false);
			struct tile *mask = field_tile(-2, 1.5f, true, false); /* ≤ −0.5 and NaN */
			struct tile *mask_s = field_tile(-2, 1.5f, true, false);
			tile_summarize(mask_s);
			tile_summarize(a);
			struct tile *o1 = run1(&tn, a, b, mask), *o2 = run1(&tn, a, b, mask_s);
			assert_memory_equal(o1->data, o2->data, o1->nbytes);
			bool shared = o2->base == a;
			/* add gives a whatever a holds; over and mask take b where a is NaN */
			assert_int_equal(shared, m == 2 || !nan);
			assert_false(o1->base);
			tile_unref(a);
			tile_unref(b);
			tile_unref(mask);
			tile_unref(mask_s);
			tile_unref(o1);
			tile_unref(o2);
			unmake(&tn);
		}
	/* a and b one uniform tile: a lerp gives a's bytes whatever the mask (not for −0,
	 * whose x + 0 is +0), an add only where b is 0 and a not −0 (adds_zero) */
	static const float vals[] = { 0.0f, 3.25f, -0.0f };
	for (int m = 0; m < 3; m++)
		for (int v = 0; v < 3; v++) {
			struct tnode tn;
			assert_int_equal(make(&tn, &node_type_blend, &input_height, &input_height2,
					      &input_height, modes[m]),
					 0);
			struct tile *a = tile_create(&key0, PIX_HEIGHT, T), *b = tile_create(&key0, PIX_HEIGHT, T);
			struct tile *pa = height_tile(vals[v]), *pb = height_tile(vals[v]);
			tile_fill_uniform(a, &vals[v]);
			tile_fill_uniform(b, &vals[v]);
			struct tile *mask = field_tile(-0.5f, 2, true, false);
			struct tile *o1 = run1(&tn, pa, pb, mask), *o2 = run1(&tn, a, b, mask);
			assert_memory_equal(o1->data, o2->data, o1->nbytes);
			assert_int_equal(o2->data == a->data, (m < 2 && v < 2) || (m == 2 && v == 0));
			tile_unref(a);
			tile_unref(b);
			tile_unref(pa);
			tile_unref(pb);
			tile_unref(mask);
			tile_unref(o1);
			tile_unref(o2);
			unmake(&tn);
		}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(color_identity),    cmocka_unit_test(color_gamma_levels),
		cmocka_unit_test(color_hue_saturation), cmocka_unit_test(color_errors),
		cmocka_unit_test(height_filter),     cmocka_unit_test(ramp_stops),
		cmocka_unit_test(ramp_default),	     cmocka_unit_test(ramp_errors),
		cmocka_unit_test(ramp_steep),	     cmocka_unit_test(ramp_steep_errors),
		cmocka_unit_test(blend_heights),     cmocka_unit_test(blend_colors),
		cmocka_unit_test(blend_errors),	     cmocka_unit_test(hashes_differ),
		cmocka_unit_test(color_reference),   cmocka_unit_test(ramp_reference),
		cmocka_unit_test(blend_masked_and_normals), cmocka_unit_test(color_mask),
		cmocka_unit_test(color_alpha_mask),
		cmocka_unit_test(tile_summaries), cmocka_unit_test(share_if_uniform),
		cmocka_unit_test(height_filter_summary),
		cmocka_unit_test(blend_shares_a), cmocka_unit_test(uniform_inputs), cmocka_unit_test(ramp_vector_bytes),
		cmocka_unit_test(ramp_steep_snow_vector_bytes),
		cmocka_unit_test(color_mask_vector), cmocka_unit_test(blend_multiply_bytes),
		cmocka_unit_test(blend_heights_bits), cmocka_unit_test(blend_over_bytes),
	};
	return cmocka_run_group_tests_name("pixel_nodes", tests, NULL, NULL);
}
