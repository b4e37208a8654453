/* node_ramp — `ramp`: heights → colour (hypsometric tint). `stops` lists "height r g b" items
 * separated by commas, heights strictly increasing; colours are interpolated linearly between
 * stops and clamped beyond the ends; `sea_level` shifts every stop up. NaN heights (no data)
 * become transparent black. Without `stops` a default Earth-like ramp is used.
 *
 * Optional polar and high-altitude snow: `snow_equator` and `snow_pole` (metres) set a snow line
 * that falls from the equator to the poles as cos²(latitude); `snow_blend` (metres, default
 * 400) is the fade above it; `sea_ice_latitude` (degrees) freezes the sea poleward of it,
 * shallow water first and deep water 8° further;
 * `snow_color` (default #f2f5fa).
 *
 * Optional steepness: with input `slope` (a height node read as the slope, e.g. a `slope`
 * node) texels whose slope exceeds `steep_from` (default 0.6) blend towards a second ramp,
 * `steep_stops` (same form: rock and scree by height), fully from `steep_to` (default 1.2);
 * snow thins by the same weight (it does not hold on cliffs).
 *
 * Speed: a table of bins over [first stop, last stop] gives a lower bound on each height's
 * segment, so a texel costs a table load, (almost always) one comparison and three FMAs;
 * colours at stop heights come out exact.
 * Thread-safety: the tables are built in create and only read by generate.
 */
#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "common/xalloc.h"
#include "engine/node_types.h"
#include "node_ramp.h"
#include "noise.h"

enum { SLOT_INPUT, SLOT_SLOPE };

/* "not set" for snow_equator: above any real snow line, so the default is no snow */
#define NAN_DEFAULT 1e9

/* Deep ocean → shallow cyan below sea level; green lowlands → tan → brown → grey rock → snow. */
static const char default_stops[] =
	"-11000 4 8 38, -6000 10 28 86, -3000 24 66 146, -1000 44 110 182, -150 86 164 210, "
	"-1 140 208 222, 0 72 128 64, 300 104 152 76, 800 176 170 112, 1600 168 128 84, "
	"2400 128 96 70, 3200 128 124 120, 4200 216 216 216, 5200 250 250 252";

struct ramp {
	struct ramp_table base;
	struct ramp_table steep; /* with a slope input */
	float steep_from, inv_steep; /* slope where steep begins; 1 / (steep_to − steep_from) */
	/* Snow line by latitude (off when snow_equator is NaN): land above
	 * snow_pole + (snow_equator − snow_pole)·cos²(lat) fades to snow over snow_blend metres;
	 * beyond ±sea_ice_latitude everything is ice. */
	double snow_equator, snow_pole, snow_blend, sea_ice_latitude;
	float snow[4];
};

/* Parses one "height r g b" item of [s, e). Returns 0 or -EINVAL. */
static int parse_stop(const char *s, const char *e, double v[4])
{
	char buf[128];
	size_t len = (size_t)(e - s);
	if (len >= sizeof buf)
		return -EINVAL;
	memcpy(buf, s, len);
	buf[len] = '\0';
	const char *q = buf;
	for (int i = 0; i < 4; i++) {
		char *end;
		v[i] = strtod(q, &end);
		if (end == q || !isfinite(v[i]))
			return -EINVAL;
		q = end;
	}
	while (*q == ' ' || *q == '\t')
		q++;
	return *q ? -EINVAL : 0;
}

/* Copies [s, e) trimmed into out (cut at 48 bytes) for messages. */
static void item_text(const char *s, const char *e, char out[52])
{
	while (s < e && (*s == ' ' || *s == '\t'))
		s++;
	while (e > s && (e[-1] == ' ' || e[-1] == '\t'))
		e--;
	size_t len = (size_t)(e - s);
	if (len > 48)
		len = 48;
	memcpy(out, s, len);
	strcpy(out + len, len == 48 ? "..." : "");
}

static int parse_stops(struct node_parse *p, const char *key, const char *text, double sea,
		       struct ramp_table *r)
{
	const char *s = text;
	r->nstops = 0;
	for (int item = 1;; item++) {
		const char *e = strchr(s, ',');
		if (!e)
			e = s + strlen(s);
		char shown[52];
		item_text(s, e, shown);
		double v[4];
		if (parse_stop(s, e, v))
			return np_error(p, key, "item %d \"%s\": expected \"height r g b\"", item,
					shown);
		for (int i = 1; i < 4; i++)
			if (v[i] < 0 || v[i] > 255)
				return np_error(p, key, "item %d \"%s\": colour %g is outside 0..255",
						item, shown, v[i]);
		if (r->nstops == RAMP_MAX_STOPS)
			return np_error(p, key, "more than %d stops", RAMP_MAX_STOPS);
		float h = (float)(v[0] + sea);
		if (r->nstops > 0 && !(h > r->h[r->nstops - 1]))
			return np_error(p, key, "item %d \"%s\": height %g is not above the "
					"previous stop's", item, shown, v[0]);
		r->h[r->nstops] = h;
		for (int i = 0; i < 3; i++)
			r->c[r->nstops][i] = (float)v[i + 1];
		r->c[r->nstops][3] = 255;
		r->nstops++;
		if (!*e)
			break;
		s = e + 1;
	}
	return 0;
}

/* The colour-per-metre slopes and the bin table of parsed stops. */
static void build_table(struct ramp_table *r)
{
	int last = r->nstops - 1;
	r->h[r->nstops] = INFINITY;
	for (int s = 0; s < last; s++)
		for (int i = 0; i < 3; i++)
			r->dc[s][i] = (r->c[s + 1][i] - r->c[s][i]) / (r->h[s + 1] - r->h[s]);
	if (last > 0) {
		double span = (double)r->h[last] - r->h[0];
		r->inv_bin = (float)(RAMP_BINS / span);
		int seg = 0;
		for (int b = 0; b < RAMP_BINS; b++) {
			double start = r->h[0] + b * (span / RAMP_BINS);
			while (seg + 1 < last && r->h[seg + 1] <= start)
				seg++;
			r->bin_seg[b] = (uint8_t)seg;
		}
	}
}

/* The steep ramp's keys: needed with a slope input, refused without one. */
static int parse_steep(struct node *n, struct node_parse *p, double sea, struct ramp *r)
{
	const char *stops;
	double from, to;
	int rc;
	if ((rc = np_string(p, "steep_stops", NULL, &stops)) ||
	    (rc = np_double(p, "steep_from", 0.6, 0, 1e3, &from)) ||
	    (rc = np_double(p, "steep_to", 1.2, 0, 1e3, &to)))
		return rc;
	if (!n->in[SLOT_SLOPE]) {
		if (stops || ini_find(p->sec, "steep_from") || ini_find(p->sec, "steep_to"))
			return np_error(p, stops ? "steep_stops" : ini_find(p->sec, "steep_from")
							       ? "steep_from" : "steep_to",
					"needs input \"slope\"");
		return 0;
	}
	if (!stops)
		return np_error(p, "slope", "input slope needs steep_stops (\"height r g b, ...\")");
	if (!(to > from))
		return np_error(p, "steep_to", "steep_to (%g) is not above steep_from (%g)", to, from);
	r->steep_from = (float)from;
	r->inv_steep = (float)(1 / (to - from));
	if ((rc = parse_stops(p, "steep_stops", stops, sea, &r->steep)))
		return rc;
	build_table(&r->steep);
	return 0;
}

static int ramp_create(struct node *n, struct node_parse *p)
{
	const char *stops;
	double sea;
	int rc;
	static const uint8_t snow_def[4] = { 242, 245, 250, 255 };
	uint8_t snow[4];
	struct ramp *r = xcalloc(1, sizeof *r);
	if ((rc = np_double(p, "sea_level", 0, -1e5, 1e5, &sea)) ||
	    (rc = np_string(p, "stops", default_stops, &stops)) ||
	    (rc = np_double(p, "snow_equator", NAN_DEFAULT, -1e5, 1e5, &r->snow_equator)) ||
	    (rc = np_double(p, "snow_pole", 0, -1e5, 1e5, &r->snow_pole)) ||
	    (rc = np_double(p, "snow_blend", 400, 1, 1e5, &r->snow_blend)) ||
	    (rc = np_double(p, "sea_ice_latitude", 91, 0, 91, &r->sea_ice_latitude)) ||
	    (rc = np_color(p, "snow_color", snow_def, snow)) ||
	    (rc = parse_stops(p, "stops", stops, sea, &r->base)) ||
	    (rc = parse_steep(n, p, sea, r))) {
		free(r);
		return rc;
	}
	for (int i = 0; i < 4; i++)
		r->snow[i] = snow[i];
	build_table(&r->base);
	n->impl = r;
	n->out = PIX_COLOR;
	return 0;
}

/* d = c + t·slope, rounded (c + t·slope ∈ [0, 255]). */
#ifdef __SSE2__
static inline void put(uint8_t *d, const float *c, const float *sl, float t)
{
	__m128 v = _mm_add_ps(_mm_add_ps(_mm_loadu_ps(c), _mm_mul_ps(_mm_set1_ps(t),
								      _mm_loadu_ps(sl))),
			      _mm_set1_ps(0.5f));
	__m128i q = _mm_cvttps_epi32(v);
	q = _mm_packus_epi16(_mm_packs_epi32(q, q), q);
	uint32_t w = (uint32_t)_mm_cvtsi128_si32(q);
	memcpy(d, &w, 4);
}
#else
static inline void put(uint8_t *d, const float *c, const float *sl, float t)
{
	for (int i = 0; i < 4; i++)
		d[i] = (uint8_t)(int)(c[i] + t * sl[i] + 0.5f);
}
#endif

/* 0 below steep_from, 1 from steep_to, linear between; 0 for NaN. */
static inline float steep_weight(float from, float inv, float slope)
{
	float w = (slope - from) * inv;
	w = w > 0.0f ? w : 0.0f;
	return w < 1.0f ? w : 1.0f;
}

/* The greatest of n heights, NaN left out (−∞ when every one is NaN); 8 lanes so the loop
 * vectorises at -O2. */
static float row_max(const float *h, uint32_t n)
{
	float m[8] = { -INFINITY, -INFINITY, -INFINITY, -INFINITY,
		       -INFINITY, -INFINITY, -INFINITY, -INFINITY };
	uint32_t i = 0;
	for (; i + 8 <= n; i += 8)
		for (int k = 0; k < 8; k++)
			m[k] = h[i + k] > m[k] ? h[i + k] : m[k];
	float top = -INFINITY;
	for (; i < n; i++)
		top = h[i] > top ? h[i] : top;
	for (int k = 0; k < 8; k++)
		top = m[k] > top ? m[k] : top;
	return top;
}

void ramp_snow_scalar(const struct ramp_snow *s, const float *h, const float *slope, uint8_t *d,
		      size_t n)
{
	for (size_t i = 0; i < n; i++) {
		float t = (h[i] - s->line) * s->inv;
		float ti = s->ice + (h[i] < 0 ? h[i] / 6000.0f : 0.0f);
		if (s->sea_ice && ti > t)
			t = ti * 4.0f;
		if (!(t > 0))
			continue;
		if (t > 1)
			t = 1;
		if (slope)
			t *= 1.0f - steep_weight(s->from, s->inv_steep, slope[i]);
		for (int ch = 0; ch < 3; ch++) {
			float v = d[4 * i + ch] + (s->snow[ch] - d[4 * i + ch]) * t;
			d[4 * i + ch] = (uint8_t)(v + 0.5f);
		}
	}
}

/* Fades a row towards snow above its latitude's snow line (and all of it past the sea-ice
 * latitude); with a slope row, less on steep texels. */
static void snow_row(const struct ramp *r, double lat, const float *h, const float *slope,
		     uint8_t *d, uint32_t T, bool avx2)
{
	double c = cos(lat * M_PI / 180.0);
	double line = r->snow_pole + (r->snow_equator - r->snow_pole) * c * c;
	/* Sea ice: starts at sea_ice_latitude over shallow water and reaches deep water 8° later,
	 * so its edge follows the sea floor instead of a parallel. */
	struct ramp_snow s = { .line = (float)line, .inv = (float)(1.0 / r->snow_blend),
			       .ice = (float)((fabs(lat) - r->sea_ice_latitude) / 8.0),
			       .sea_ice = r->sea_ice_latitude <= 90,
			       .from = r->steep_from, .inv_steep = r->inv_steep };
	memcpy(s.snow, r->snow, sizeof s.snow);
	/* A row whose highest texel is below the line, where the sea ice cannot reach (its ti ≤
	 * ice ≤ 0), keeps its colours: the loop would change nothing (t only grows with h, NaN
	 * never snows). */
	if (!s.sea_ice || !(s.ice > 0)) {
		float top = row_max(h, T);
		if (!((top - s.line) * s.inv > 0))
			return;
	}
	if (avx2 && T % 8 == 0)
		ramp_snow_avx2(&s, h, slope, d, T);
	else
		ramp_snow_scalar(&s, h, slope, d, T);
}

/* The segment of table r holding h (clamped to its ends, where the last stop's segment has
 * slope 0 and h[last + 1] = +∞ ends the search); *t = metres into it. */
static inline int segment(const struct ramp_table *r, float h, float *t)
{
	const float h0 = r->h[0], hl = r->h[r->nstops - 1];
	h = h < h0 ? h0 : h > hl ? hl : h;
	int s = ramp_segment_of(r, h);
	*t = h - r->h[s];
	return s;
}

void ramp_steep_scalar(const struct ramp_steep *r, const float *h, const float *slope,
		       uint8_t *d, size_t count)
{
	for (size_t i = 0; i < count; i++) {
		float w = steep_weight(r->from, r->inv, slope[i]);
		if (!(w > 0 && h[i] == h[i]))
			continue;
		float ta, tb;
		int sa = segment(r->base, h[i], &ta), sb = segment(r->steep, h[i], &tb);
		for (int ch = 0; ch < 3; ch++) {
			float a = r->base->c[sa][ch] + ta * r->base->dc[sa][ch];
			float b = r->steep->c[sb][ch] + tb * r->steep->dc[sb][ch];
			d[4 * i + ch] = (uint8_t)(int)(a + (b - a) * w + 0.5f);
		}
		d[4 * i + 3] = 255;
	}
}

void ramp_base_scalar(const struct ramp_table *r, const float *h, uint8_t *d, size_t count)
{
	for (size_t i = 0; i < count; i++) {
		float t;
		if (h[i] != h[i]) {
			memset(d + 4 * i, 0, 4); /* NaN: no data */
			continue;
		}
		int s = segment(r, h[i], &t);
		put(d + 4 * i, r->c[s], r->dc[s], t);
	}
}

static int ramp_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			 struct tile *const *in, int nin, struct tile *out)
{
	(void)g;
	const struct ramp *r = n->impl;
	const bool steep = n->in[SLOT_SLOPE] != NULL;
	if (nin < 1 + steep || in[0]->type != PIX_HEIGHT || in[0]->size != out->size ||
	    (steep && (in[1]->type != PIX_HEIGHT || in[1]->size != out->size)))
		return -EINVAL;
	size_t count = (size_t)out->size * out->size;
	const float *src = tile_f32(in[0]), *slope = steep ? tile_f32(in[1]) : NULL;
	uint8_t *dst = out->data;
	const bool snow = r->snow_equator < NAN_DEFAULT || r->sea_ice_latitude <= 90;
	if (in[0]->uniform && !steep && !snow) {
		/* one height everywhere and nothing by place: one colour, the shared uniform tile
		 * (the scalar and vector ramps give the same bytes) */
		uint8_t px[4];
		ramp_base_scalar(&r->base, src, px, 1);
		tile_fill_uniform(out, px);
		return 0;
	}
	/* The base ramp everywhere, then the steep texels over it, then the snow. */
	const bool avx2 = count % 8 == 0 && noise_isa_has_avx2();
	if (avx2)
		ramp_base_avx2(&r->base, src, dst, count);
	else
		ramp_base_scalar(&r->base, src, dst, count);
	if (steep) {
		const struct ramp_steep st = { &r->base, &r->steep, r->steep_from, r->inv_steep };
		if (avx2)
			ramp_steep_avx2(&st, src, slope, dst, count);
		else
			ramp_steep_scalar(&st, src, slope, dst, count);
	}
	if (snow) {
		uint32_t T = out->size;
		for (uint32_t j = 0; j < T; j++) {
			double lon, lat;
			grid_texel_center(k, T, 0, j, &lon, &lat);
			snow_row(r, lat, src + (size_t)j * T, slope ? slope + (size_t)j * T : NULL,
				 dst + (size_t)j * T * 4, T, avx2);
		}
	}
	return 0;
}

static const struct node_slot ramp_slots[] = {
	{ .name = "input", .type = PIX_HEIGHT },
	{ .name = "slope", .type = PIX_HEIGHT, .optional = true },
};

const struct node_type node_type_ramp = {
	.name = "ramp",
	.doc = "hypsometric tint: heights to colours through interpolated stops",
	.version = 1,
	.slots = ramp_slots,
	.nslots = 2,
	.create = ramp_create,
	.destroy = node_free_impl,
	.generate = ramp_generate,
};
