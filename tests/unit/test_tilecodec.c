/* Tile payload codec tests: every format × codec × filter round-trips bit-exactly on
 * realistic data (smooth heights with noise, a colour gradient, random normals) and on odd
 * floats (NaN, ±0, ±inf, denormals, sign changes); compression pays where it should and is
 * skipped where it cannot; corrupted payloads, checksums and headers are detected. The lossy
 * codecs: heights within half the quantisation step, colour and normals within a stated
 * error, several times smaller than zstd; what they cannot code goes lossless. */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdbool.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <cmocka.h>

#include "common/tilecodec.h"
#include "common/xalloc.h"

static uint32_t rng(uint64_t *s)
{
	*s = *s * 6364136223846793005ull + 1442695040888963407ull;
	return (uint32_t)(*s >> 33);
}

static void *make_tile(enum pix_type fmt, uint32_t T, int kind)
{
	size_t n = (size_t)T * T;
	uint64_t s = 12345 + (uint64_t)kind;
	if (fmt == PIX_HEIGHT) {
		float *h = xmalloc(n * 4);
		for (uint32_t y = 0; y < T; y++)
			for (uint32_t x = 0; x < T; x++) {
				double v = 800 * sin(x * 0.031) * cos(y * 0.023) + 3.0 * x - 2.0 * y +
					   (rng(&s) % 1000) * 0.01; /* ±cm noise */
				if (kind == 1) /* crosses sea level: negative and positive */
					v -= 400;
				h[(size_t)y * T + x] = (float)v;
			}
		if (kind == 2) { /* odd floats */
			const float odd[] = { NAN, -0.0f, 0.0f, INFINITY, -INFINITY, 1e-40f,
					      -1e-40f, 3.4e38f, -3.4e38f };
			for (size_t i = 0; i < n; i++)
				if (rng(&s) % 4 == 0)
					h[i] = odd[rng(&s) % 9];
		}
		return h;
	}
	size_t bpp = pix_bytes(fmt);
	uint8_t *p = xmalloc(n * bpp);
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++) {
			uint8_t *t = p + ((size_t)y * T + x) * bpp;
			if (fmt == PIX_COLOR) { /* gradient with a little noise */
				t[0] = (uint8_t)(x * 255 / (T > 1 ? T - 1 : 1) + rng(&s) % 2);
				t[1] = (uint8_t)(y * 200 / (T > 1 ? T - 1 : 1));
				t[2] = (uint8_t)(64 + (x + y) % 32);
				t[3] = 255;
			} else { /* random normals */
				t[0] = (uint8_t)rng(&s);
				t[1] = (uint8_t)rng(&s);
			}
		}
	return p;
}

static void round_trip_all(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	const uint32_t sizes[] = { 1, 2, 64, 256 };
	for (int fmt = PIX_HEIGHT; fmt < PIX_COUNT; fmt++)
		for (int kind = 0; kind < (fmt == PIX_HEIGHT ? 3 : 1); kind++)
			for (size_t si = 0; si < 4; si++) {
				uint32_t T = sizes[si];
				size_t raw = (size_t)T * T * pix_bytes(fmt);
				void *tex = make_tile(fmt, T, kind);
				void *back = xmalloc(raw);
				for (int c = 0; c <= TCODEC_ZSTD; c++) /* the lossless ones */
					for (int f = 0; f < TFILTER_COUNT; f++) {
						size_t cap = tilecodec_bound(c, raw);
						void *out = xmalloc(cap);
						struct tilecodec_hdr h;
						ssize_t n = tilecodec_encode(tc, fmt, T, c, f, 0, tex,
									     &h, out, cap);
						assert_true(n > 0);
						assert_true((size_t)n <= cap);
						assert_int_equal(h.raw_len, raw);
						assert_int_equal(h.size, T);
						assert_int_equal(h.format, fmt);
						char err[256];
						memset(back, 0xa5, raw);
						int rc = tilecodec_decode(tc, &h, out, (size_t)n, back,
									  raw, err);
						if (rc)
							fail_msg("%s T=%u %s+%s: %s",
								 pix_format_name(fmt), T,
								 tilecodec_filter_name(f),
								 tilecodec_codec_name(c), err);
						assert_memory_equal(back, tex, raw);
						free(out);
					}
				/* the filters alone are exact inverses */
				void *filt = xmalloc(raw);
				for (int f = 0; f < TFILTER_COUNT; f++) {
					assert_int_equal(tilecodec_filter(fmt, T, f, tex, filt), 0);
					memset(back, 0, raw);
					assert_int_equal(tilecodec_unfilter(fmt, T, f, filt, back), 0);
					assert_memory_equal(back, tex, raw);
				}
				free(filt);
				free(back);
				free(tex);
			}
	tilecodec_destroy(tc);
}

/* Random bit patterns (every float class, every byte) survive each filter. */
static void filters_random_bits(void **state)
{
	(void)state;
	uint64_t s = 7;
	const uint32_t T = 32;
	uint8_t in[32 * 32 * 4], mid[32 * 32 * 4], out[32 * 32 * 4];
	for (int rep = 0; rep < 20; rep++) {
		for (size_t i = 0; i < sizeof(in); i++)
			in[i] = (uint8_t)rng(&s);
		for (int fmt = PIX_HEIGHT; fmt < PIX_COUNT; fmt++)
			for (int f = 0; f < TFILTER_COUNT; f++) {
				size_t raw = (size_t)T * T * pix_bytes(fmt);
				assert_int_equal(tilecodec_filter(fmt, T, f, in, mid), 0);
				assert_int_equal(tilecodec_unfilter(fmt, T, f, mid, out), 0);
				assert_memory_equal(in, out, raw);
			}
	}
}

/* ---- the filters' format, written the plain way (docs/PROTOCOL.md) ------------------------ */

/* Float bits as an order-preserving unsigned integer, and the zigzag of a difference. */
static uint32_t ref_f2o(uint32_t b) { return (b & 0x80000000u) ? ~b : (b | 0x80000000u); }
static uint32_t ref_zz32(uint32_t d) { return (d << 1) ^ (0u - (d >> 31)); }
static uint8_t ref_zz8(uint8_t d) { return (uint8_t)((d << 1) ^ (0u - (d >> 7))); }

/* The component c of texel i: f32 as its ordered bits, bytes as themselves. */
static uint32_t ref_comp(enum pix_type fmt, const uint8_t *t, size_t i, unsigned c, bool planes)
{
	if (fmt == PIX_HEIGHT) {
		uint32_t b = (uint32_t)t[4 * i] | (uint32_t)t[4 * i + 1] << 8 |
			     (uint32_t)t[4 * i + 2] << 16 | (uint32_t)t[4 * i + 3] << 24;
		return planes ? b : ref_f2o(b);
	}
	return t[pix_bytes(fmt) * i + c];
}

/* The filtered bytes texel by texel: a component's prediction is its left neighbour (the
 * first column: the one above; the first texel: 0), GRAD's left + above - above-left inside;
 * its residual (zigzagged difference, or xor) goes into byte planes. */
static void ref_filter(enum pix_type fmt, uint32_t T, enum tfilter f, const uint8_t *in,
		       uint8_t *out)
{
	size_t n = (size_t)T * T;
	unsigned nc = fmt == PIX_HEIGHT ? 1 : pix_bytes(fmt);
	bool planes = f == TFILTER_PLANES;
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++)
			for (unsigned c = 0; c < nc; c++) {
				size_t i = (size_t)y * T + x;
				uint32_t v = ref_comp(fmt, in, i, c, planes), p = 0, r;
				if (x && y && f == TFILTER_GRAD)
					p = ref_comp(fmt, in, i - 1, c, false) +
					    ref_comp(fmt, in, i - T, c, false) -
					    ref_comp(fmt, in, i - T - 1, c, false);
				else if (x)
					p = ref_comp(fmt, in, i - 1, c, false);
				else if (y)
					p = ref_comp(fmt, in, i - T, c, false);
				if (planes)
					r = v;
				else if (f == TFILTER_XOR)
					r = v ^ p;
				else
					r = fmt == PIX_HEIGHT ? ref_zz32(v - p)
							      : ref_zz8((uint8_t)(v - p));
				if (fmt == PIX_HEIGHT)
					for (int k = 0; k < 4; k++)
						out[k * n + i] = (uint8_t)(r >> 8 * k);
				else
					out[c * n + i] = (uint8_t)r;
			}
}

/* The filters write exactly the format above, and undo it: on every format and filter, at
 * sizes 1 to 1024 (the vector loops from 16 on), on smooth tiles and random bits. (A round trip alone would pass a filter
 * that changed the format on both sides; a viewer of another build would then decode
 * garbage.) */
static void filters_match_the_format(void **state)
{
	(void)state;
	uint64_t s = 99;
	const uint32_t sizes[] = { 1, 2, 4, 8, 16, 64, 256, 1024 };
	for (int fmt = PIX_HEIGHT; fmt < PIX_COUNT; fmt++)
		for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++)
			for (int kind = 0; kind < 2; kind++) {
				uint32_t T = sizes[k];
				size_t raw = (size_t)T * T * pix_bytes(fmt);
				uint8_t *tex = make_tile(fmt, T, 0), *want = xmalloc(raw),
					*got = xmalloc(raw), *back = xmalloc(raw);
				if (kind == 1)
					for (size_t i = 0; i < raw; i++)
						tex[i] = (uint8_t)rng(&s);
				for (int f = TFILTER_PLANES; f < TFILTER_COUNT; f++) {
					ref_filter(fmt, T, f, tex, want);
					assert_int_equal(tilecodec_filter(fmt, T, f, tex, got), 0);
					if (memcmp(want, got, raw) != 0)
						fail_msg("%s T=%u %s: the filtered bytes are not the "
							 "format's", pix_format_name(fmt), T,
							 tilecodec_filter_name(f));
					memset(back, 0x5a, raw);
					assert_int_equal(tilecodec_unfilter(fmt, T, f, want, back), 0);
					assert_memory_equal(back, tex, raw);
				}
				free(tex), free(want), free(got), free(back);
			}
}

/* What a user notices: smooth data gets smaller, incompressible data is sent raw. */
static void compression_pays(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	const uint32_t T = 256;
	float *h = make_tile(PIX_HEIGHT, T, 0);
	size_t raw = (size_t)T * T * 4;
	size_t cap = tilecodec_bound(TCODEC_LZ4, raw) > tilecodec_bound(TCODEC_ZSTD, raw)
			     ? tilecodec_bound(TCODEC_LZ4, raw)
			     : tilecodec_bound(TCODEC_ZSTD, raw);
	void *out = xmalloc(cap);
	struct tilecodec_hdr hd;
	ssize_t plain = tilecodec_encode(tc, PIX_HEIGHT, T, TCODEC_ZSTD, TFILTER_NONE, 1, h, &hd,
					 out, cap);
	ssize_t grad = tilecodec_encode(tc, PIX_HEIGHT, T, TCODEC_ZSTD,
					tilecodec_default_filter(PIX_HEIGHT), 1, h, &hd, out, cap);
	assert_int_equal(hd.codec, TCODEC_ZSTD);
	assert_true(grad > 0 && plain > 0);
	assert_true((double)raw / (double)grad > 1.3); /* smooth heights: ≥ 1.3× */
	assert_true(grad < plain);		      /* and the filter helps */

	uint8_t *nrm = make_tile(PIX_NORMAL, T, 0); /* random: cannot compress */
	ssize_t n = tilecodec_encode(tc, PIX_NORMAL, T, TCODEC_LZ4, TFILTER_PLANES, 0, nrm, &hd, out,
				     cap);
	assert_int_equal(n, (ssize_t)T * T * 2);
	assert_int_equal(hd.codec, TCODEC_NONE);
	assert_int_equal(hd.filter, TFILTER_NONE);
	assert_memory_equal(out, nrm, (size_t)n);

	uint8_t *col = make_tile(PIX_COLOR, T, 0);
	n = tilecodec_encode(tc, PIX_COLOR, T, TCODEC_LZ4, tilecodec_default_filter(PIX_COLOR),
			     0, col, &hd, out, cap);
	assert_int_equal(hd.codec, TCODEC_LZ4);
	assert_true((double)(T * T * 4) / (double)n > 4); /* gradient */
	ssize_t none = tilecodec_encode(tc, PIX_COLOR, T, TCODEC_LZ4, TFILTER_NONE, 0, col, &hd,
					out, cap);
	assert_true(none > 2 * n); /* the filter is what makes it pay */
	free(col);
	free(nrm);
	free(out);
	free(h);
	tilecodec_destroy(tc);
}

static void corruption_detected(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	const uint32_t T = 64;
	float *h = make_tile(PIX_HEIGHT, T, 0);
	size_t raw = (size_t)T * T * 4;
	float *back = xmalloc(raw);
	char err[256];
	for (int c = 0; c <= TCODEC_ZSTD; c++) {
		size_t cap = tilecodec_bound(c, raw);
		uint8_t *out = xmalloc(cap);
		struct tilecodec_hdr hd;
		ssize_t n = tilecodec_encode(tc, PIX_HEIGHT, T, c, TFILTER_DELTA, 0, h, &hd, out, cap);
		assert_true(n > 0);
		assert_int_equal(hd.codec, c); /* smooth: every codec pays */

		/* checksum */
		struct tilecodec_hdr bad = hd;
		bad.checksum ^= 1;
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err), -EILSEQ);
		assert_non_null(strstr(err, "checksum"));

		/* a bit flip anywhere in the payload is caught, or left the texels intact
		 * (e.g. a larger zstd window size in the frame header) */
		uint64_t s = 99;
		for (int k = 0; k < 200; k++) {
			size_t at = rng(&s) % (size_t)n;
			uint8_t bit = (uint8_t)(1u << (rng(&s) % 8));
			out[at] ^= bit;
			int rc = tilecodec_decode(tc, &hd, out, (size_t)n, back, raw, err);
			if (rc == 0)
				assert_memory_equal(back, h, raw);
			else
				assert_true(rc == -EILSEQ || rc == -EBADMSG);
			out[at] ^= bit;
		}
		assert_int_equal(tilecodec_decode(tc, &hd, out, (size_t)n, back, raw, err), 0);

		/* truncated payload */
		assert_int_equal(tilecodec_decode(tc, &hd, out, (size_t)n - 1, back, raw, err),
				 -EBADMSG);

		/* header lies */
		bad = hd;
		bad.size = 128;
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err), -EINVAL);
		bad = hd;
		bad.raw_len -= 4;
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err), -EINVAL);
		bad = hd;
		bad.format = PIX_COLOR; /* same byte count: decodes, then fails the checksum */
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err),
				 -EILSEQ);
		bad = hd;
		bad.filter = TFILTER_COUNT;
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err), -EINVAL);
		bad = hd;
		bad.codec = TCODEC_COUNT;
		assert_int_equal(tilecodec_decode(tc, &bad, out, (size_t)n, back, raw, err), -EINVAL);
		/* output buffer too small: refused, not overrun */
		assert_int_equal(tilecodec_decode(tc, &hd, out, (size_t)n, back, raw - 1, err),
				 -EINVAL);
		/* output buffer too small for the encoder */
		if (c != TCODEC_NONE)
			assert_int_equal(tilecodec_encode(tc, PIX_HEIGHT, T, c, 0, 0, h, &hd, out,
							  raw),
					 -ENOSPC);
		free(out);
	}
	/* garbage that claims to be lz4 / zstd */
	uint8_t junk[300];
	uint64_t s = 5;
	for (size_t i = 0; i < sizeof(junk); i++)
		junk[i] = (uint8_t)rng(&s);
	struct tilecodec_hdr g = { .format = PIX_HEIGHT, .codec = TCODEC_LZ4, .size = T,
				   .raw_len = (uint32_t)raw };
	assert_int_equal(tilecodec_decode(tc, &g, junk, sizeof(junk), back, raw, err), -EBADMSG);
	g.codec = TCODEC_ZSTD;
	assert_int_equal(tilecodec_decode(tc, &g, junk, sizeof(junk), back, raw, err), -EBADMSG);
	/* bad arguments to the encoder */
	struct tilecodec_hdr hd;
	uint8_t o[64];
	assert_int_equal(tilecodec_encode(tc, PIX_HEIGHT, 3, 0, 0, 0, h, &hd, o, sizeof(o)), -EINVAL);
	assert_int_equal(tilecodec_encode(tc, PIX_NONE, 2, 0, 0, 0, h, &hd, o, sizeof(o)), -EINVAL);
	assert_int_equal(tilecodec_encode(tc, PIX_HEIGHT, 2, 3, 0, 0, h, &hd, o, sizeof(o)), -EINVAL);
	free(back);
	free(h);
	tilecodec_destroy(tc);
}

static void names(void **state)
{
	(void)state;
	assert_string_equal(tilecodec_codec_name(TCODEC_ZSTD), "zstd");
	assert_int_equal(tilecodec_codec_parse("lz4"), TCODEC_LZ4);
	assert_int_equal(tilecodec_codec_parse("gzip"), -EINVAL);
	assert_string_equal(pix_format_name(PIX_NORMAL), "rg8");
	assert_false(pix_valid(PIX_COUNT));
	assert_string_equal(pix_format_name(PIX_COUNT), "none");
	assert_int_equal(pix_bytes(PIX_COLOR), 4);
	assert_int_equal(tilecodec_bound(TCODEC_NONE, 100), 100);
	assert_true(tilecodec_bound(TCODEC_LZ4, 100) >= 100);
	assert_int_equal(tilecodec_bound(TCODEC_COUNT, 100), 0);
}

/* Terrain-like colour: a height ramp with slope shading, as a synthesised colour layer. */
static uint8_t *terrain_color(uint32_t T, bool alpha)
{
	uint8_t *p = xmalloc((size_t)T * T * 4);
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++) {
			double h = sin(x * 0.05) * cos(y * 0.04) + 0.3 * sin(x * 0.21 + y * 0.17);
			double sh = 0.8 + 0.2 * cos(x * 0.05) * cos(y * 0.04);
			uint8_t *t = p + ((size_t)y * T + x) * 4;
			t[0] = (uint8_t)(sh * (90 + 60 * h));
			t[1] = (uint8_t)(sh * (110 + 50 * h));
			t[2] = (uint8_t)(sh * (60 + 30 * h));
			t[3] = alpha ? (uint8_t)(x < T / 2 ? 255 : 128) : 255;
		}
	return p;
}

/* Normals of a smooth surface, as the normal node makes them (east, north in rg8). */
static uint8_t *terrain_normals(uint32_t T)
{
	uint8_t *p = xmalloc((size_t)T * T * 2);
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++) {
			double e = 0.4 * cos(x * 0.05) * cos(y * 0.04), n = -0.4 * sin(x * 0.05) * sin(y * 0.04);
			p[((size_t)y * T + x) * 2] = (uint8_t)lround((e + 1) * 127.5);
			p[((size_t)y * T + x) * 2 + 1] = (uint8_t)lround((n + 1) * 127.5);
		}
	return p;
}

/* Encodes lossy and lossless; returns the lossy payload's bytes, *zbytes the zstd's, decodes
 * into back. */
static size_t lossy_vs_zstd(struct tilecodec *tc, enum pix_type f, uint32_t T, enum tcodec c,
			    const struct tilecodec_lossy_opts *o, const void *tex, void *back,
			    size_t *zbytes, struct tilecodec_hdr *h)
{
	size_t raw = (size_t)T * T * pix_bytes(f), cap = tilecodec_bound(TCODEC_ZSTD, raw);
	uint8_t *out = xmalloc(cap);
	ssize_t z = tilecodec_encode(tc, f, T, TCODEC_ZSTD, tilecodec_default_filter(f), 1, tex, h,
				     out, cap);
	assert_true(z > 0);
	*zbytes = (size_t)z;
	ssize_t n = tilecodec_encode_lossy(tc, f, T, c, o, tex, h, out, cap);
	assert_true(n > 0 && (size_t)n <= raw);
	assert_int_equal(h->codec, c);
	assert_int_equal(h->filter, TFILTER_NONE);
	char err[256];
	int rc = tilecodec_decode(tc, h, out, (size_t)n, back, raw, err);
	if (rc)
		fail_msg("%s: %s", tilecodec_codec_name(c), err);
	/* one flipped byte: the payload's checksum refuses it */
	out[n / 2] ^= 0x10;
	assert_int_equal(tilecodec_decode(tc, h, out, (size_t)n, back, raw, err), -EILSEQ);
	out[n / 2] ^= 0x10;
	assert_int_equal(tilecodec_decode(tc, h, out, (size_t)n, back, raw, err), 0);
	free(out);
	return (size_t)n;
}

static void lossy_heights_within_half_a_step(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	const uint32_t T = 256;
	float *h = make_tile(PIX_HEIGHT, T, 1); /* −1.6 … +1.5 km with cm noise */
	float *back = xmalloc((size_t)T * T * 4);
	float lo = h[0], hi = h[0];
	for (size_t i = 0; i < (size_t)T * T; i++) {
		lo = h[i] < lo ? h[i] : lo;
		hi = h[i] > hi ? h[i] : hi;
	}
	const double steps[] = { 0, 0.1, 2.0 };
	for (int k = 0; k < 3; k++) {
		struct tilecodec_lossy_opts o = { .step = steps[k] };
		struct tilecodec_hdr hd;
		size_t zb, n = lossy_vs_zstd(tc, PIX_HEIGHT, T, TCODEC_Q16, &o, h, back, &zb, &hd);
		double step = fmax(((double)hi - lo) / 65535.0, steps[k]), worst = 0;
		for (size_t i = 0; i < (size_t)T * T; i++)
			worst = fmax(worst, fabs((double)h[i] - back[i]));
		print_message("q16 step %.3f m: %zu bytes (zstd %zu, raw %zu), worst error %.4f m\n",
			      step, n, zb, (size_t)T * T * 4, worst);
		assert_true(worst <= step / 2 * 1.0001 + 1e-4);
		assert_true(n < zb); /* smaller than lossless even at the finest step */
		if (k == 2)
			assert_true(n * 3 < zb); /* a 2 m step: a third of zstd at most */
	}
	/* A tile with a non-finite height is not quantised: lossless, bit for bit. */
	h[77] = NAN;
	size_t raw = (size_t)T * T * 4, cap = tilecodec_bound(TCODEC_ZSTD, raw);
	uint8_t *out = xmalloc(cap);
	struct tilecodec_hdr hd;
	ssize_t n = tilecodec_encode_lossy(tc, PIX_HEIGHT, T, TCODEC_Q16, NULL, h, &hd, out, cap);
	assert_true(n > 0);
	assert_int_equal(hd.codec, TCODEC_ZSTD);
	char err[256];
	assert_int_equal(tilecodec_decode(tc, &hd, out, (size_t)n, back, raw, err), 0);
	assert_memory_equal(back, h, raw);
	free(out);
	free(back);
	free(h);
	tilecodec_destroy(tc);
}

static void lossy_colour_and_normals(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	const uint32_t T = 256;
	size_t n = (size_t)T * T;
	for (int alpha = 0; alpha < 2; alpha++) {
		uint8_t *c = terrain_color(T, alpha), *back = xmalloc(n * 4);
		struct tilecodec_hdr hd;
		size_t zb, wb = lossy_vs_zstd(tc, PIX_COLOR, T, TCODEC_WEBP, NULL, c, back, &zb, &hd);
		double se = 0;
		int amax = 0;
		for (size_t i = 0; i < n; i++) {
			for (int k = 0; k < 3; k++)
				se += pow((double)c[i * 4 + k] - back[i * 4 + k], 2);
			amax = abs(c[i * 4 + 3] - back[i * 4 + 3]) > amax ? abs(c[i * 4 + 3] - back[i * 4 + 3])
									 : amax;
		}
		double psnr = 10 * log10(255.0 * 255.0 / (se / (double)(n * 3)));
		print_message("webp colour%s: %zu bytes (zstd %zu), PSNR %.1f dB, alpha error %d\n",
			      alpha ? " with alpha" : "", wb, zb, psnr, amax);
		assert_true(psnr > 35);
		assert_int_equal(amax, 0); /* alpha is kept exactly */
		assert_true(wb * 4 < zb);
		free(c);
		free(back);
	}
	uint8_t *nm = terrain_normals(T), *back = xmalloc(n * 2);
	struct tilecodec_hdr hd;
	size_t zb, wb = lossy_vs_zstd(tc, PIX_NORMAL, T, TCODEC_WEBP, NULL, nm, back, &zb, &hd);
	double sum = 0;
	int worst = 0;
	for (size_t i = 0; i < n * 2; i++) {
		int d = abs(nm[i] - back[i]);
		sum += d;
		worst = d > worst ? d : worst;
	}
	print_message("webp normals: %zu bytes (zstd %zu), mean error %.2f, worst %d (of 255)\n", wb,
		      zb, sum / (double)(n * 2), worst);
	assert_true(sum / (double)(n * 2) < 1.5);
	assert_true(worst <= 16);
	assert_true(wb * 4 < zb);
	free(nm);
	free(back);
	tilecodec_destroy(tc);
}

/* Headers a lossy codec cannot have, and payloads that lie about their image. */
static void lossy_bad_input(void **state)
{
	(void)state;
	struct tilecodec *tc = tilecodec_create();
	char err[256];
	struct tilecodec_hdr h = { .format = PIX_HEIGHT, .codec = TCODEC_WEBP, .size = 64,
				   .raw_len = 64 * 64 * 4 };
	assert_int_equal(tilecodec_hdr_check(&h, err), -EINVAL);
	assert_non_null(strstr(err, "cannot code"));
	h = (struct tilecodec_hdr){ .format = PIX_COLOR, .codec = TCODEC_Q16, .size = 64,
				    .raw_len = 64 * 64 * 4 };
	assert_int_equal(tilecodec_hdr_check(&h, err), -EINVAL);
	h = (struct tilecodec_hdr){ .format = PIX_COLOR, .codec = TCODEC_WEBP, .filter = TFILTER_DELTA,
				    .size = 64, .raw_len = 64 * 64 * 4 };
	assert_int_equal(tilecodec_hdr_check(&h, err), -EINVAL);
	assert_non_null(strstr(err, "takes no filter"));
	/* a valid 64² WebP announced as a 128² tile (its checksum right): refused by size */
	uint8_t *c = terrain_color(64, false), *out = xmalloc(1 << 16), *back = xmalloc(128 * 128 * 4);
	ssize_t n = tilecodec_encode_lossy(tc, PIX_COLOR, 64, TCODEC_WEBP, NULL, c, &h, out, 1 << 16);
	assert_true(n > 0);
	h.size = 128;
	h.raw_len = 128 * 128 * 4;
	assert_int_equal(tilecodec_decode(tc, &h, out, (size_t)n, back, h.raw_len, err), -EBADMSG);
	assert_non_null(strstr(err, "64×64"));
	/* garbage with a right checksum */
	memset(out, 0x5a, 300);
	h.checksum = tilecodec_checksum(out, 300);
	assert_int_equal(tilecodec_decode(tc, &h, out, 300, back, h.raw_len, err), -EBADMSG);
	h = (struct tilecodec_hdr){ .format = PIX_HEIGHT, .codec = TCODEC_Q16, .size = 64,
				    .raw_len = 64 * 64 * 4, .checksum = tilecodec_checksum(out, 300) };
	assert_int_equal(tilecodec_decode(tc, &h, out, 300, back, h.raw_len, err), -EBADMSG);
	/* the lossless encoder refuses a lossy codec; the lossy one refuses a format it cannot code */
	assert_int_equal(tilecodec_encode(tc, PIX_COLOR, 64, TCODEC_WEBP, TFILTER_NONE, 0, c, &h, out,
					  1 << 16),
			 -EINVAL);
	assert_int_equal(tilecodec_encode_lossy(tc, PIX_HEIGHT, 64, TCODEC_WEBP, NULL, c, &h, out,
						1 << 16),
			 -EINVAL);
	free(c);
	free(out);
	free(back);
	tilecodec_destroy(tc);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(round_trip_all),
		cmocka_unit_test(filters_random_bits),
		cmocka_unit_test(filters_match_the_format),
		cmocka_unit_test(compression_pays),
		cmocka_unit_test(corruption_detected),
		cmocka_unit_test(names),
		cmocka_unit_test(lossy_heights_within_half_a_step),
		cmocka_unit_test(lossy_colour_and_normals),
		cmocka_unit_test(lossy_bad_input),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
