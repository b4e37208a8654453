/* bench_codec — tile payload coding: compression ratio and encode/decode speed per layer type
 * (f32 heights, RGBA8 colour, RG8 normals; 256² each, synthesized to look like terrain), per
 * pre-filter and codec, and the pre-filters alone. One line per figure; speeds are MB/s of raw texels, one thread.
 * Then real tiles of the shipped planets (conf/planets: procedural, and Earth when data/ has
 * it) at levels 4, 8, 12 and 16 near the Alps: bytes per tile, zstd (what clipmapd sends
 * below raw_above_mbit) against the lossy codecs with clipmapd's settings (encpick.h), and
 * their errors; for the height layers also what a height tile of half the texels each way would
 * save and cost the picture ("codec/half-heights", docs/LINKS.md "Per-layer tile sizes"). Also
 * times the frame codec for a WANT of 1024 entries and a TILE head.
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "daemon/encpick.h"
#include "daemon/engine/cache.h"
#include "daemon/engine/planet.h"
#include "daemon/engine/sched.h"

#define T 256

static uint32_t hash2(int x, int y, uint32_t seed)
{
	uint32_t h = (uint32_t)x * 0x8da6b343u ^ (uint32_t)y * 0xd8163841u ^ seed * 0xcb1ab31fu;
	h ^= h >> 13;
	h *= 0x85ebca6bu;
	h ^= h >> 16;
	return h;
}

/* Value noise with smoothstep interpolation, in [-1, 1]. */
static double vnoise(double x, double y, uint32_t seed)
{
	int xi = (int)floor(x), yi = (int)floor(y);
	double fx = x - xi, fy = y - yi;
	double sx = fx * fx * (3 - 2 * fx), sy = fy * fy * (3 - 2 * fy);
	double v00 = hash2(xi, yi, seed) / 2147483648.0 - 1;
	double v10 = hash2(xi + 1, yi, seed) / 2147483648.0 - 1;
	double v01 = hash2(xi, yi + 1, seed) / 2147483648.0 - 1;
	double v11 = hash2(xi + 1, yi + 1, seed) / 2147483648.0 - 1;
	double a = v00 + (v10 - v00) * sx, b = v01 + (v11 - v01) * sx;
	return a + (b - a) * sy;
}

/* Heights in metres: a regional slope plus 8 octaves of fBm, like a mid-level terrain tile. */
static void make_heights(float *h)
{
	for (int y = 0; y < T; y++)
		for (int x = 0; x < T; x++) {
			double s = 0, amp = 600, f = 1.0 / 64;
			for (int o = 0; o < 8; o++, amp *= 0.5, f *= 2)
				s += amp * vnoise(x * f, y * f, (uint32_t)o);
			h[y * T + x] = (float)(1200 + 2.0 * x - 1.5 * y + s);
		}
}

static uint8_t clamp8(double v)
{
	return (uint8_t)(v < 0 ? 0 : v > 255 ? 255 : lround(v));
}

/* Colour from height through a ramp, lit by the slope, with ±1 LSB of noise. */
static void make_color(const float *h, uint8_t *c)
{
	for (int y = 0; y < T; y++)
		for (int x = 0; x < T; x++) {
			int i = y * T + x;
			double t = (h[i] - 200) / 2500;
			t = t < 0 ? 0 : t > 1 ? 1 : t;
			double dx = h[y * T + (x + 1 < T ? x + 1 : x)] - h[i];
			double shade = 1 - 0.02 * dx;
			int n = (int)(hash2(x, y, 99) % 3) - 1;
			c[4 * i + 0] = clamp8((60 + 140 * t) * shade + n);
			c[4 * i + 1] = clamp8((110 + 60 * t) * shade + n);
			c[4 * i + 2] = clamp8((50 + 150 * t * t) * shade + n);
			c[4 * i + 3] = 255;
		}
}

/* RG8 normals from the heights (30 m texels), as daemon/engine/tile.h defines them. */
static void make_normals(const float *h, uint8_t *n)
{
	for (int y = 0; y < T; y++)
		for (int x = 0; x < T; x++) {
			int xl = x ? x - 1 : x, xr = x + 1 < T ? x + 1 : x;
			int yu = y ? y - 1 : y, yd = y + 1 < T ? y + 1 : y;
			double dzdx = (h[y * T + xr] - h[y * T + xl]) / (30.0 * (xr - xl));
			double dzdy = (h[yu * T + x] - h[yd * T + x]) / (30.0 * (yd - yu));
			double len = sqrt(dzdx * dzdx + dzdy * dzdy + 1);
			n[2 * (y * T + x) + 0] = clamp8((-dzdx / len + 1) * 127.5);
			n[2 * (y * T + x) + 1] = clamp8((-dzdy / len + 1) * 127.5);
		}
}

/* The pre-filter alone, both ways (what a store read or a zstd tile pays besides zstd). */
static void bench_filter(const char *layer, enum pix_type fmt, const void *texels, enum tfilter f)
{
	size_t raw = (size_t)T * T * pix_bytes(fmt);
	unsigned char *mid = xmalloc(raw), *back = xmalloc(raw);
	int reps = 0, rc = 0;
	double t0 = clock_now_s(), t1;
	do {
		rc |= tilecodec_filter(fmt, T, f, texels, mid);
		reps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double fil = raw * reps / (t1 - t0) / 1e6;
	int ureps = 0;
	t0 = clock_now_s();
	do {
		rc |= tilecodec_unfilter(fmt, T, f, mid, back);
		ureps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double unf = raw * ureps / (t1 - t0) / 1e6;
	printf("filter/%s T=%d %s: filter %.0f MB/s, unfilter %.0f MB/s%s\n", layer, T,
	       tilecodec_filter_name(f), fil, unf,
	       rc || memcmp(back, texels, raw) ? " ROUND TRIP FAILED" : "");
	free(mid);
	free(back);
}

static void bench_one(struct tilecodec *tc, const char *layer, enum pix_type fmt,
		      const void *texels, enum tfilter filt, enum tcodec codec, int level)
{
	size_t raw = (size_t)T * T * pix_bytes(fmt);
	size_t cap = tilecodec_bound(codec, raw);
	unsigned char *out = xmalloc(cap), *back = xmalloc(raw);
	struct tilecodec_hdr h;
	ssize_t n = 0;
	int reps = 0;
	double t0 = clock_now_s(), t1;
	do {
		n = tilecodec_encode(tc, fmt, T, codec, filt, level, texels, &h, out, cap);
		reps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double enc = raw * reps / (t1 - t0) / 1e6;
	int dreps = 0, rc = 0;
	t0 = clock_now_s();
	do {
		rc |= tilecodec_decode(tc, &h, out, (size_t)n, back, raw, NULL);
		dreps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double dec = raw * dreps / (t1 - t0) / 1e6;
	char cname[16];
	snprintf(cname, sizeof(cname), "%s%s", tilecodec_codec_name(codec),
		 codec == TCODEC_ZSTD ? (level == 3 ? "-3" : "-1") : "");
	printf("codec/%s T=%d %s+%s: ratio %.3f, encode %.0f MB/s, decode %.0f MB/s%s%s\n", layer,
	       T, tilecodec_filter_name(filt), cname, (double)raw / (double)n, enc, dec,
	       n > 0 && h.codec == TCODEC_NONE && codec != TCODEC_NONE ? " (sent raw: did not pay)"
								      : "",
	       rc || memcmp(back, texels, raw) ? " ROUND TRIP FAILED" : "");
	free(out);
	free(back);
}

/* A lossy codec: bytes, the error, and speeds (encode and decode, MB/s of raw texels). */
static void bench_lossy(struct tilecodec *tc, const char *layer, enum pix_type fmt,
			const void *texels, enum tcodec codec, double step)
{
	size_t raw = (size_t)T * T * pix_bytes(fmt), cap = tilecodec_bound(TCODEC_ZSTD, raw);
	unsigned char *out = xmalloc(cap), *back = xmalloc(raw);
	struct tilecodec_hdr h;
	struct tilecodec_lossy_opts o = { .step = step };
	ssize_t n = 0;
	int reps = 0, dreps = 0, rc = 0;
	double t0 = clock_now_s(), t1;
	do {
		n = tilecodec_encode_lossy(tc, fmt, T, codec, &o, texels, &h, out, cap);
		reps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double enc = raw * reps / (t1 - t0) / 1e6;
	t0 = clock_now_s();
	do {
		rc |= tilecodec_decode(tc, &h, out, (size_t)n, back, raw, NULL);
		dreps++;
	} while ((t1 = clock_now_s()) - t0 < 0.15);
	double dec = raw * dreps / (t1 - t0) / 1e6, worst = 0, sum = 0;
	size_t nv = fmt == PIX_HEIGHT ? (size_t)T * T : raw;
	for (size_t i = 0; i < nv; i++) {
		double d = fmt == PIX_HEIGHT ? fabs((double)((const float *)texels)[i] - ((float *)(void *)back)[i])
					     : fabs((double)((const uint8_t *)texels)[i] - back[i]);
		worst = d > worst ? d : worst;
		sum += d;
	}
	char what[32];
	if (fmt == PIX_HEIGHT)
		snprintf(what, sizeof what, " step %.2f m", step);
	else
		what[0] = '\0';
	printf("codec/%s T=%d %s%s: %zd bytes, ratio %.1f, error mean %.3f worst %.3f %s, encode %.0f "
	       "MB/s, decode %.0f MB/s%s\n",
	       layer, T, tilecodec_codec_name((enum tcodec)h.codec), what, n, (double)raw / (double)n,
	       sum / (double)nv, worst, fmt == PIX_HEIGHT ? "m" : "/255", enc, dec,
	       rc ? " DECODE FAILED" : "");
	free(out);
	free(back);
}

static void bench_frames(void)
{
	struct proto_want_entry *e = xcalloc(1024, sizeof(*e));
	for (int i = 0; i < 1024; i++)
		e[i] = (struct proto_want_entry){ .layer = (uint8_t)(i % 3), .cls = 1, .lx = 12,
						  .ly = 11, .x = (uint32_t)i, .y = (uint32_t)i };
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = 1, .seq = 7, .count = 1024, .entries = e } };
	struct pbuf b;
	pbuf_init(&b);
	int reps = 0;
	double t0 = clock_now_s(), t1;
	do {
		b.len = 0;
		if (proto_encode(&b, &m, NULL) < 0)
			abort();
		reps++;
	} while ((t1 = clock_now_s()) - t0 < 0.2);
	printf("proto/encode WANT 1024 entries: %.1f us/message\n", (t1 - t0) / reps * 1e6);
	reps = 0;
	t0 = clock_now_s();
	do {
		struct proto_msg d;
		size_t need;
		if (proto_decode(b.data, b.len, &d, &need, NULL) <= 0)
			abort();
		proto_msg_fini(&d);
		reps++;
	} while ((t1 = clock_now_s()) - t0 < 0.2);
	printf("proto/decode WANT 1024 entries: %.1f us/message\n", (t1 - t0) / reps * 1e6);
	pbuf_fini(&b);
	free(e);
}

/* A size² tile of `type` texels at level ly encoded as clipmapd sends it on a 4 Mbit/s link to a
 * client that offered the lossy codecs (encpick.h: its codec and step); payload bytes as
 * tilecodec_encode_lossy returns them. */
static ssize_t slow_link_encode(struct tilecodec *tc, const struct planet *p, enum pix_type type,
				int ly, uint32_t size, const void *texels, struct tilecodec_hdr *h,
				void *out, size_t cap)
{
	const struct encpick_policy pol = { .lossless = TCODEC_ZSTD, .offered = TCODEC_ALL_MASK,
					    .lossy_below_bps = 50000000 };
	struct encpick e;
	encpick(&pol, type, ly, size, p->a, 4000000, &e);
	return tilecodec_encode_lossy(tc, type, size, e.codec, &e.lossy, texels, h, out, cap);
}

/* One real tile of layer l: zstd bytes, lossy bytes and error, as clipmapd would send it on a
 * slow link. Accumulates into sums[3] (zstd, lossy bytes, error). */
static void real_tile(struct tilecodec *tc, const struct planet *p, size_t l, const struct tile *t,
		      int ly, double sums[3])
{
	size_t raw = t->nbytes, cap = tilecodec_bound(TCODEC_ZSTD, raw);
	unsigned char *out = xmalloc(cap), *back = xmalloc(raw);
	struct tilecodec_hdr h;
	ssize_t z = tilecodec_encode(tc, t->type, t->size, TCODEC_ZSTD,
				     tilecodec_default_filter(t->type), 1, t->data, &h, out, cap);
	ssize_t n = slow_link_encode(tc, p, t->type, ly, t->size, t->data, &h, out, cap);
	double err = 0;
	if (n > 0 && tilecodec_decode(tc, &h, out, (size_t)n, back, raw, NULL) == 0) {
		size_t nv = t->type == PIX_HEIGHT ? raw / 4 : raw;
		for (size_t i = 0; i < nv; i++)
			err += t->type == PIX_HEIGHT
				       ? fabs((double)((const float *)t->data)[i] - ((float *)(void *)back)[i])
				       : fabs((double)((const uint8_t *)t->data)[i] - back[i]);
		err /= (double)nv;
	}
	sums[0] += (double)z;
	sums[1] += (double)n;
	sums[2] += err;
	(void)l;
	free(out);
	free(back);
}

/* The 2×2 block of layer l's tiles at level ly near (7.5°E, 46.5°N) into t[4] (NULL where a
 * tile failed); returns the level used (the planet's finest where ly is past it). */
static int fetch_block(struct sched *s, const struct planet *p, size_t l, int ly, struct tile *t[4])
{
	ly = ly > p->max_level ? p->max_level : ly;
	int lx = ly + 1;
	uint32_t x0 = (uint32_t)((7.5 + 180) / 360 * ldexp(1, lx)),
		 y0 = (uint32_t)((90 - 46.5) / 180 * ldexp(1, ly));
	struct want w[4];
	for (int k = 0; k < 4; k++) {
		t[k] = NULL;
		w[k] = (struct want){ .node = p->layers[l].node, .cls = SCHED_VISIBLE,
				      .key = { .node = p->layers[l].node->hash, .lx = (uint8_t)lx,
					       .ly = (uint8_t)ly,
					       .x = (x0 + (uint32_t)(k & 1)) % (1u << lx),
					       .y = y0 + (uint32_t)(k >> 1) } };
	}
	sched_fetch(s, w, 4, t);
	return ly;
}

/* Per-layer tile sizes (issue 15; seed 003 sent 64² heights under 256² colour): what a height
 * tile of half the texels each way would save on a slow link and what it would cost the
 * picture. The half tile keeps every second texel of the real one (its texels are the next
 * coarser level's); the viewer would interpolate the rest (linearly, here). Printed per level:
 * q16 bytes of the T² and the (T/2)² tile (each with clipmapd's step for its texel, encpick.h),
 * and, inside the tile (a texel from its edge, where a real one would use its neighbour's),
 * the interpolated heights' error and the derived normals' (clipmapview --normals derive):
 * their mean angle and a Lambert shading's difference (sun 45° up in the north-west, in
 * 8-bit levels; over 8 levels is a step a person sees on a smooth slope). */
static void half_heights(struct tilecodec *tc, struct sched *s, const struct planet *p, size_t l)
{
	const int levels[] = { 4, 8, 12, 16 };
	for (int li = 0; li < 4; li++) {
		struct tile *t[4];
		int ly = fetch_block(s, p, l, levels[li], t);
		uint32_t ts = 0;
		double full = 0, half = 0, herr = 0, ang = 0, sh = 0, vis = 0, n = 0, tiles = 0;
		double dy = 0, dx; /* a texel's metres north and east, the last tile's */
		for (int k = 0; k < 4; k++) {
			if (!t[k] || t[k]->type != PIX_HEIGHT)
				goto next;
			ts = t[k]->size;
			const float *h = (const float *)(const void *)t[k]->data;
			uint32_t H = ts / 2;
			float *d = xmalloc(sizeof(float) * H * H), *u = xmalloc(sizeof(float) * ts * ts);
			size_t cap = tilecodec_bound(TCODEC_ZSTD, (size_t)ts * ts * 4);
			unsigned char *out = xmalloc(cap);
			struct tilecodec_hdr hd;
			ssize_t nf = slow_link_encode(tc, p, PIX_HEIGHT, ly, ts, h, &hd, out, cap);
			for (uint32_t y = 0; y < H; y++)
				for (uint32_t x = 0; x < H; x++)
					d[y * H + x] = h[2 * y * ts + 2 * x];
			/* its texels are the next coarser level's, and so is q16's step */
			ssize_t nh = slow_link_encode(tc, p, PIX_HEIGHT, ly > 0 ? ly - 1 : 0, H, d, &hd,
						      out, cap);
			/* back to T²: even texels as sent, odd ones between their neighbours */
			for (uint32_t y = 0; y < ts; y++)
				for (uint32_t x = 0; x < ts; x++) {
					uint32_t y0 = y / 2, x0 = x / 2;
					uint32_t y1 = y0 + 1 < H ? y0 + 1 : y0, x1 = x0 + 1 < H ? x0 + 1 : x0;
					float fy = (float)(y & 1) * 0.5f, fx = (float)(x & 1) * 0.5f;
					float a = d[y0 * H + x0] + (d[y0 * H + x1] - d[y0 * H + x0]) * fx;
					float b = d[y1 * H + x0] + (d[y1 * H + x1] - d[y1 * H + x0]) * fx;
					u[y * ts + x] = a + (b - a) * fy;
				}
			double lat = (90.0 - ((double)t[k]->key.y + 0.5) * 180.0 / ldexp(1, ly)) * M_PI / 180;
			dy = M_PI * p->a / ldexp(1, ly) / ts;
			dx = dy * cos(lat);
			const double L[3] = { -0.5, 0.5, M_SQRT1_2 }; /* sun from the north-west, 45° up */
			for (uint32_t y = 2; y + 3 < ts; y++)
				for (uint32_t x = 2; x + 3 < ts; x++) {
					const float *g[2] = { h, u };
					double nv[2][3], shade[2];
					for (int q = 0; q < 2; q++) {
						const float *f = g[q];
						double gx = (f[y * ts + x + 1] - f[y * ts + x - 1]) / (2 * dx);
						double gy = (f[(y - 1) * ts + x] - f[(y + 1) * ts + x]) / (2 * dy);
						double m = sqrt(gx * gx + gy * gy + 1);
						nv[q][0] = -gx / m, nv[q][1] = -gy / m, nv[q][2] = 1 / m;
						double c = nv[q][0] * L[0] + nv[q][1] * L[1] + nv[q][2] * L[2];
						shade[q] = 255 * (c > 0 ? c : 0);
					}
					double c = nv[0][0] * nv[1][0] + nv[0][1] * nv[1][1] + nv[0][2] * nv[1][2];
					ang += acos(c > 1 ? 1 : c) * 180 / M_PI;
					double ds = fabs(shade[0] - shade[1]);
					sh += ds;
					vis += ds > 8;
					double dh = (double)h[y * ts + x] - u[y * ts + x];
					herr += dh * dh;
					n++;
				}
			full += (double)nf;
			half += (double)nh;
			tiles++;
			free(d);
			free(u);
			free(out);
		next:
			tile_unref(t[k]);
		}
		if (!tiles || !n)
			continue;
		printf("codec/half-heights %s.%s level %d: q16 %u² %.0f bytes, %u² %.0f bytes (%.1f× "
		       "fewer, %.1f KB less a tile); interpolated: height rms %.3g m (%.3f of a "
		       "texel), normals %.2f° apart, shading %.2f levels apart, %.1f %% of texels "
		       "over 8 levels\n",
		       p->name, p->layers[l].name, ly, ts, full / tiles, ts / 2, half / tiles, full / half,
		       (full - half) / tiles / 1000, sqrt(herr / n), sqrt(herr / n) / dy, ang / n, sh / n,
		       100 * vis / n);
	}
}

/* The tiles of a 2×2 block at each level near (7.5°E, 46.5°N), every layer of the planet. */
static void bench_real(struct tilecodec *tc, const char *path)
{
	struct planet *p;
	char err[256];
	if (planet_load(path, &p, err)) {
		printf("codec/real %s: skipped (%s)\n", path, err);
		return;
	}
	struct cache *cache = cache_create(0);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = cache, .workers = 2 });
	const int levels[] = { 4, 8, 12, 16 };
	for (size_t l = 0; l < p->nlayers; l++) {
		double tot[3] = { 0 }, tiles = 0;
		for (int li = 0; li < 4; li++) {
			struct tile *t[4];
			int ly = fetch_block(s, p, l, levels[li], t);
			double sums[3] = { 0 };
			int got = 0;
			for (int k = 0; k < 4; k++)
				if (t[k]) {
					real_tile(tc, p, l, t[k], ly, sums);
					tile_unref(t[k]);
					got++;
				}
			if (!got)
				continue;
			printf("codec/real %s.%s level %d: zstd %.0f bytes, %s %.0f bytes (%.1f× fewer), "
			       "mean error %.3g %s\n",
			       p->name, p->layers[l].name, ly, sums[0] / got,
			       p->layers[l].type == PIX_HEIGHT ? "q16" : "webp", sums[1] / got,
			       sums[0] / sums[1], sums[2] / got,
			       p->layers[l].type == PIX_HEIGHT ? "m" : "/255");
			for (int k = 0; k < 3; k++)
				tot[k] += sums[k];
			tiles += got;
		}
		if (tiles)
			printf("codec/real %s.%s all levels: zstd %.0f, lossy %.0f bytes per tile "
			       "(%.1f× fewer)\n",
			       p->name, p->layers[l].name, tot[0] / tiles, tot[1] / tiles, tot[0] / tot[1]);
		if (p->layers[l].type == PIX_HEIGHT)
			half_heights(tc, s, p, l);
	}
	sched_destroy(s);
	cache_destroy(cache);
	planet_unref(p);
}

int main(void)
{
	float *h = xmalloc(sizeof(float) * T * T);
	uint8_t *c = xmalloc(4 * T * T), *n = xmalloc(2 * T * T);
	make_heights(h);
	make_color(h, c);
	make_normals(h, n);
	struct tilecodec *tc = tilecodec_create();
	const struct {
		const char *name;
		enum pix_type fmt;
		const void *data;
	} layers[] = { { "height", PIX_HEIGHT, h }, { "color", PIX_COLOR, c },
		       { "normal", PIX_NORMAL, n } };
	for (size_t l = 0; l < 3; l++) {
		bench_one(tc, layers[l].name, layers[l].fmt, layers[l].data, TFILTER_NONE,
			  TCODEC_NONE, 0);
		for (int f = 1; f < TFILTER_COUNT; f++)
			bench_filter(layers[l].name, layers[l].fmt, layers[l].data, f);
		for (int f = 0; f < TFILTER_COUNT; f++) {
			bench_one(tc, layers[l].name, layers[l].fmt, layers[l].data, f, TCODEC_LZ4, 0);
			bench_one(tc, layers[l].name, layers[l].fmt, layers[l].data, f, TCODEC_ZSTD, 1);
			bench_one(tc, layers[l].name, layers[l].fmt, layers[l].data, f, TCODEC_ZSTD, 3);
		}
	}
	/* the lossy codecs; q16 at the range's own step and at the steps clipmapd uses for Earth
	 * levels 8 (1.2 m) and 12 (7.6 cm) */
	bench_lossy(tc, "height", PIX_HEIGHT, h, TCODEC_Q16, 0);
	bench_lossy(tc, "height", PIX_HEIGHT, h, TCODEC_Q16, 0.076);
	bench_lossy(tc, "height", PIX_HEIGHT, h, TCODEC_Q16, 1.2);
	bench_lossy(tc, "color", PIX_COLOR, c, TCODEC_WEBP, 0);
	bench_lossy(tc, "normal", PIX_NORMAL, n, TCODEC_WEBP, 0);
	bench_real(tc, "conf/planets/procedural.ini");
	bench_real(tc, "conf/planets/earth.ini");
	bench_frames();
	tilecodec_destroy(tc);
	free(h);
	free(c);
	free(n);
	return 0;
}
