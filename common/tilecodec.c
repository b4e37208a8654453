/* tilecodec — tile payload coding: pre-filter + lz4/zstd + XXH3 checksum. See tilecodec.h.
 *
 * Design note: filters work on "components": for f32 the float's bit pattern mapped to an
 * order-preserving u32 (so a smooth surface gives small integer differences on both sides of
 * zero), for rgba8/rg8 each byte channel. The residual of each component is written as its
 * little-endian bytes into byte planes (plane k = byte k of every texel), which puts the
 * near-constant high bytes of height residuals next to each other for the entropy coder.
 */
#include "tilecodec.h"

#include <errno.h>
#include <limits.h>
#include <lz4.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <xxhash.h>
#include <zstd.h>

#include "errbuf.h"
#include "tilecodec_lossy.h"
#include "unfilter_sse2.h"
#include "xalloc.h"

/* The filters' loops run over rows T texels long. GCC's -O2 vectorises only loops whose length
 * it knows (its "very cheap" cost model): with the full model the filters run 2-5x faster
 * (bench_codec). Clang vectorises them at -O2 already. */
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC optimize("O3")
#endif

struct tilecodec {
	unsigned char *scratch;
	size_t scratch_cap;
	unsigned char *alt; /* tilecodec_encode_lossy's lossless try */
	size_t alt_cap;
	ZSTD_CCtx *cctx;
	ZSTD_DCtx *dctx;
};

static const char *const codec_names[TCODEC_COUNT] = { "none", "lz4", "zstd", "webp", "q16" };
static const char *const filter_names[TFILTER_COUNT] = { "none", "planes", "delta", "grad",
							 "xor" };


const char *tilecodec_codec_name(enum tcodec c)
{
	return (unsigned)c < TCODEC_COUNT ? codec_names[c] : NULL;
}

const char *tilecodec_filter_name(enum tfilter f)
{
	return (unsigned)f < TFILTER_COUNT ? filter_names[f] : NULL;
}

int tilecodec_codec_parse(const char *s)
{
	for (int c = 0; c < TCODEC_COUNT; c++)
		if (s && strcmp(s, codec_names[c]) == 0)
			return c;
	return -EINVAL;
}

enum tfilter tilecodec_default_filter(enum pix_type f)
{
	/* Measured by tests/bench/bench_codec.c (see docs/PROTOCOL.md). */
	switch (f) {
	case PIX_HEIGHT:
		return TFILTER_GRAD;
	case PIX_COLOR:
		return TFILTER_DELTA;
	case PIX_NORMAL:
		return TFILTER_DELTA;
	default:
		return TFILTER_NONE;
	}
}

int tilecodec_codec_fits(unsigned c, unsigned format)
{
	if (c >= TCODEC_COUNT || !pix_valid(format))
		return 0;
	if (c == TCODEC_WEBP)
		return format == PIX_COLOR || format == PIX_NORMAL;
	if (c == TCODEC_Q16)
		return format == PIX_HEIGHT;
	return 1;
}

uint64_t tilecodec_checksum(const void *p, size_t n)
{
	return XXH3_64bits(p, n);
}

static bool pow2_size(uint32_t t)
{
	return t >= 1 && t <= TILECODEC_MAX_SIZE && (t & (t - 1)) == 0;
}

int tilecodec_hdr_check(const struct tilecodec_hdr *h, char err[256])
{
	if (!pix_valid(h->format)) {
		err_set(err, "unknown tile format %u", h->format);
		return -EINVAL;
	}
	if (h->codec >= TCODEC_COUNT) {
		err_set(err, "unknown tile codec %u", h->codec);
		return -EINVAL;
	}
	if (h->filter >= TFILTER_COUNT) {
		err_set(err, "unknown tile filter %u", h->filter);
		return -EINVAL;
	}
	if (!tilecodec_codec_fits(h->codec, h->format)) {
		err_set(err, "codec %s cannot code %s tiles", tilecodec_codec_name(h->codec),
			pix_format_name(h->format));
		return -EINVAL;
	}
	if (tilecodec_is_lossy(h->codec) && h->filter != TFILTER_NONE) {
		err_set(err, "codec %s takes no filter (filter %s)", tilecodec_codec_name(h->codec),
			tilecodec_filter_name(h->filter));
		return -EINVAL;
	}
	if (!pow2_size(h->size)) {
		err_set(err, "tile size %u is not a power of two in [1, %u]", h->size,
		       TILECODEC_MAX_SIZE);
		return -EINVAL;
	}
	size_t raw = (size_t)h->size * h->size * pix_bytes(h->format);
	if (h->raw_len != raw) {
		err_set(err, "raw length %u does not match a %u×%u %s tile (%zu bytes)", h->raw_len,
		       h->size, h->size, pix_format_name(h->format), raw);
		return -EINVAL;
	}
	return 0;
}

size_t tilecodec_bound(enum tcodec c, size_t raw_len)
{
	switch (c) {
	case TCODEC_NONE:
		return raw_len;
	case TCODEC_LZ4:
		return raw_len > LZ4_MAX_INPUT_SIZE ? 0 : (size_t)LZ4_compressBound((int)raw_len);
	case TCODEC_ZSTD:
		return ZSTD_compressBound(raw_len);
	case TCODEC_WEBP:
	case TCODEC_Q16:
		return raw_len;
	default:
		return 0;
	}
}

struct tilecodec *tilecodec_create(void)
{
	struct tilecodec *tc = xcalloc(1, sizeof(*tc));
	tc->cctx = ZSTD_createCCtx();
	tc->dctx = ZSTD_createDCtx();
	if (!tc->cctx || !tc->dctx) {
		fprintf(stderr, "clipmap: out of memory creating zstd contexts\n");
		abort();
	}
	return tc;
}

void tilecodec_destroy(struct tilecodec *tc)
{
	if (!tc)
		return;
	ZSTD_freeCCtx(tc->cctx);
	ZSTD_freeDCtx(tc->dctx);
	free(tc->scratch);
	free(tc->alt);
	free(tc);
}

static unsigned char *scratch(struct tilecodec *tc, size_t n)
{
	if (tc->scratch_cap < n) {
		free(tc->scratch);
		tc->scratch = xmalloc(n);
		tc->scratch_cap = n;
	}
	return tc->scratch;
}

/* ---- filters ---------------------------------------------------------------------------- */

static inline uint32_t ld32(const unsigned char *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline void st32(unsigned char *p, uint32_t v)
{
	p[0] = (unsigned char)v;
	p[1] = (unsigned char)(v >> 8);
	p[2] = (unsigned char)(v >> 16);
	p[3] = (unsigned char)(v >> 24);
}

/* Float bits ↔ an unsigned integer with the same order as the floats. */
static inline uint32_t f2o(uint32_t b) { return (b & 0x80000000u) ? ~b : (b | 0x80000000u); }
static inline uint32_t o2f(uint32_t o) { return (o & 0x80000000u) ? (o & 0x7fffffffu) : ~o; }

static inline uint32_t zz32(uint32_t d) { return (d << 1) ^ (0u - (d >> 31)); }
static inline uint32_t unzz32(uint32_t z) { return (z >> 1) ^ (0u - (z & 1)); }
static inline uint8_t zz8(uint8_t d) { return (uint8_t)((d << 1) ^ (0u - (d >> 7))); }
static inline uint8_t unzz8(uint8_t z) { return (uint8_t)((z >> 1) ^ (0u - (z & 1))); }

/* The filters work a row at a time, in the form the loops below can run as vectors: the
 * residual of (x, y) against its prediction (the format: docs/PROTOCOL.md) is
 *   DELTA, XOR  p = v[y][x-1]; first column v[y-1][0]; the first texel 0;
 *   GRAD        p = v[y][x-1] + v[y-1][x] - v[y-1][x-1]; the first row and column as DELTA;
 * and undoing it is a running sum (a running xor) along the row: for GRAD the sum of the
 * residuals along the row is the row's difference from the row above, since
 *   v[y][x] - v[y-1][x] = z[y][x] + (v[y][x-1] - v[y-1][x-1]).
 * A row is at most TILECODEC_MAX_SIZE wide: the row buffers live on the stack. */

/* The residual of v against p. */
static inline uint32_t resid32(enum tfilter f, uint32_t v, uint32_t p)
{
	return f == TFILTER_XOR ? v ^ p : zz32(v - p);
}

static inline uint8_t resid8(enum tfilter f, uint8_t v, uint8_t p)
{
	return f == TFILTER_XOR ? (uint8_t)(v ^ p) : zz8((uint8_t)(v - p));
}

/* The residuals of row v (above it u, or NULL on the first row) into r. */
static inline __attribute__((always_inline)) void filter_row32(uint32_t T, enum tfilter f,
							      const uint32_t *v, const uint32_t *u,
							      uint32_t *r)
{
	if (f == TFILTER_GRAD && u)
		for (uint32_t x = 1; x < T; x++)
			r[x] = zz32(v[x] - (v[x - 1] + u[x] - u[x - 1]));
	else
		for (uint32_t x = 1; x < T; x++)
			r[x] = resid32(f, v[x], v[x - 1]);
	r[0] = resid32(f, v[0], u ? u[0] : 0);
}

static inline __attribute__((always_inline)) void filter_row8(uint32_t T, enum tfilter f,
							     const uint8_t *v, const uint8_t *u,
							     uint8_t *r)
{
	if (f == TFILTER_GRAD && u)
		for (uint32_t x = 1; x < T; x++)
			r[x] = zz8((uint8_t)(v[x] - (uint8_t)(v[x - 1] + u[x] - u[x - 1])));
	else
		for (uint32_t x = 1; x < T; x++)
			r[x] = resid8(f, v[x], v[x - 1]);
	r[0] = resid8(f, v[0], u ? u[0] : 0);
}

/* Row r's residuals back into values v (above it u, or NULL on the first row). */
static inline __attribute__((always_inline)) void unfilter_row32(uint32_t T, enum tfilter f,
								const uint32_t *r, const uint32_t *u,
								uint32_t *v)
{
	if (f == TFILTER_XOR) {
		uint32_t a = u ? u[0] : 0;
		for (uint32_t x = 0; x < T; x++)
			v[x] = a ^= r[x];
		return;
	}
	if (f == TFILTER_GRAD && u) {
		uint32_t d = 0;
		for (uint32_t x = 0; x < T; x++)
			v[x] = d += unzz32(r[x]);
		for (uint32_t x = 0; x < T; x++)
			v[x] += u[x];
		return;
	}
	uint32_t a = u ? u[0] : 0;
	for (uint32_t x = 0; x < T; x++)
		v[x] = a += unzz32(r[x]);
}

/* f32: a component is the float's bits in an order-preserving unsigned form (f2o); its
 * residual is written into 4 byte planes (PLANES: the bits themselves). */
static inline __attribute__((always_inline)) void filter_f32(uint32_t T, enum tfilter f,
							    const unsigned char *in,
							    unsigned char *out)
{
	size_t n = (size_t)T * T;
	uint32_t rows[2][TILECODEC_MAX_SIZE], r[TILECODEC_MAX_SIZE];
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *src = in + (size_t)4 * y * T;
		uint32_t *v = rows[y & 1], *u = y ? rows[~y & 1] : NULL;
		if (f == TFILTER_PLANES) {
			for (uint32_t x = 0; x < T; x++)
				r[x] = ld32(src + 4 * x);
		} else {
			for (uint32_t x = 0; x < T; x++)
				v[x] = f2o(ld32(src + 4 * x));
			filter_row32(T, f, v, u, r);
		}
		unsigned char *o = out + (size_t)y * T;
		for (uint32_t x = 0; x < T; x++) {
			o[x] = (unsigned char)r[x];
			o[n + x] = (unsigned char)(r[x] >> 8);
			o[2 * n + x] = (unsigned char)(r[x] >> 16);
			o[3 * n + x] = (unsigned char)(r[x] >> 24);
		}
	}
}

static inline __attribute__((always_inline)) void unfilter_f32(uint32_t T, enum tfilter f,
							      const unsigned char *in,
							      unsigned char *out)
{
	size_t n = (size_t)T * T;
	uint32_t rows[2][TILECODEC_MAX_SIZE], r[TILECODEC_MAX_SIZE];
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *p = in + (size_t)y * T;
		for (uint32_t x = 0; x < T; x++)
			r[x] = (uint32_t)p[x] | (uint32_t)p[n + x] << 8 | (uint32_t)p[2 * n + x] << 16 |
			       (uint32_t)p[3 * n + x] << 24;
		unsigned char *dst = out + (size_t)4 * y * T;
		if (f == TFILTER_PLANES) {
			for (uint32_t x = 0; x < T; x++)
				st32(dst + 4 * x, r[x]);
			continue;
		}
		uint32_t *v = rows[y & 1], *u = y ? rows[~y & 1] : NULL;
		unfilter_row32(T, f, r, u, v);
		for (uint32_t x = 0; x < T; x++)
			st32(dst + 4 * x, o2f(v[x]));
	}
}

/* Byte channels (rgba8: 4, rg8: 2): plane c = channel c. */
static inline __attribute__((always_inline)) void filter_u8(uint32_t T, unsigned nc, enum tfilter f,
							   const unsigned char *in, unsigned char *out)
{
	size_t n = (size_t)T * T;
	uint8_t rows[2][4][TILECODEC_MAX_SIZE];
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *src = in + (size_t)nc * y * T;
		for (unsigned c = 0; c < nc; c++) {
			uint8_t *v = rows[y & 1][c], *u = y ? rows[~y & 1][c] : NULL;
			unsigned char *o = out + c * n + (size_t)y * T;
			for (uint32_t x = 0; x < T; x++)
				v[x] = src[nc * x + c];
			if (f == TFILTER_PLANES)
				memcpy(o, v, T);
			else
				filter_row8(T, f, v, u, o);
		}
	}
}

/* A pixel's nc ≤ 4 channels as one word, byte c = channel c; added channel by channel (no
 * carry from one byte into the next). */
static inline uint32_t add_bytes(uint32_t a, uint32_t b)
{
	return ((a & 0x7f7f7f7fu) + (b & 0x7f7f7f7fu)) ^ ((a ^ b) & 0x80808080u);
}

/* Undone a pixel at a time, its channels together in a word: the running sum along the row
 * is one chain of adds, not nc. */
static inline __attribute__((always_inline)) void unfilter_u8(uint32_t T, unsigned nc,
							     enum tfilter f,
							     const unsigned char *in,
							     unsigned char *out)
{
	size_t n = (size_t)T * T;
	uint32_t z[TILECODEC_MAX_SIZE];
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *r = in + (size_t)y * T;
		unsigned char *dst = out + (size_t)nc * y * T, *up = y ? dst - (size_t)nc * T : NULL;
		if (f == TFILTER_PLANES) {
			for (uint32_t x = 0; x < T; x++)
				for (unsigned c = 0; c < nc; c++)
					dst[nc * x + c] = r[c * n + x];
			continue;
		}
		for (uint32_t x = 0; x < T; x++) {
			uint32_t w = 0;
			for (unsigned c = 0; c < nc; c++)
				w |= (uint32_t)(f == TFILTER_XOR ? r[c * n + x] : unzz8(r[c * n + x]))
				     << 8 * c;
			z[x] = w;
		}
		uint32_t a = 0;
		if (up && !(f == TFILTER_GRAD))
			for (unsigned c = 0; c < nc; c++)
				a |= (uint32_t)up[c] << 8 * c;
		if (f == TFILTER_XOR)
			for (uint32_t x = 0; x < T; x++)
				z[x] = a ^= z[x];
		else
			for (uint32_t x = 0; x < T; x++)
				z[x] = a = add_bytes(a, z[x]);
		for (uint32_t x = 0; x < T; x++)
			for (unsigned c = 0; c < nc; c++)
				dst[nc * x + c] = (unsigned char)(z[x] >> 8 * c);
		if (f == TFILTER_GRAD && up)
			for (size_t i = 0; i < (size_t)nc * T; i++)
				dst[i] = (unsigned char)(dst[i] + up[i]);
	}
}

static int filter_args(enum pix_type format, uint32_t size, enum tfilter filter)
{
	if (!pix_valid(format) || !pow2_size(size) ||
	    (unsigned)filter >= TFILTER_COUNT)
		return -EINVAL;
	return 0;
}

/* One format and filter, f a constant where the switches below call it (so that every loop
 * is compiled for its filter alone). */
static inline __attribute__((always_inline)) void filter_as(enum pix_type format, uint32_t T,
							   enum tfilter f, const void *in,
							   void *out)
{
	if (format == PIX_HEIGHT)
		filter_f32(T, f, in, out);
	else if (format == PIX_COLOR)
		filter_u8(T, 4, f, in, out);
	else
		filter_u8(T, 2, f, in, out);
}

static inline __attribute__((always_inline)) void unfilter_as(enum pix_type format, uint32_t T,
							     enum tfilter f, const void *in,
							     void *out)
{
	if (unfilter_sse2_fits(T, f)) {
		uint32_t rows[2 * TILECODEC_MAX_SIZE];
		if (format == PIX_HEIGHT)
			unfilter_f32_sse2(T, f, in, out, rows);
		else
			unfilter_u8_sse2(T, format == PIX_COLOR ? 4 : 2, f, in, out);
	} else if (format == PIX_HEIGHT)
		unfilter_f32(T, f, in, out);
	else if (format == PIX_COLOR)
		unfilter_u8(T, 4, f, in, out);
	else
		unfilter_u8(T, 2, f, in, out);
}

int tilecodec_filter(enum pix_type format, uint32_t size, enum tfilter filter,
		     const void *texels, void *filtered)
{
	int rc = filter_args(format, size, filter);
	if (rc)
		return rc;
	switch (filter) {
	case TFILTER_PLANES: filter_as(format, size, TFILTER_PLANES, texels, filtered); break;
	case TFILTER_DELTA: filter_as(format, size, TFILTER_DELTA, texels, filtered); break;
	case TFILTER_GRAD: filter_as(format, size, TFILTER_GRAD, texels, filtered); break;
	case TFILTER_XOR: filter_as(format, size, TFILTER_XOR, texels, filtered); break;
	default: memcpy(filtered, texels, (size_t)size * size * pix_bytes(format)); break;
	}
	return 0;
}

int tilecodec_unfilter(enum pix_type format, uint32_t size, enum tfilter filter,
		       const void *filtered, void *texels)
{
	int rc = filter_args(format, size, filter);
	if (rc)
		return rc;
	switch (filter) {
	case TFILTER_PLANES: unfilter_as(format, size, TFILTER_PLANES, filtered, texels); break;
	case TFILTER_DELTA: unfilter_as(format, size, TFILTER_DELTA, filtered, texels); break;
	case TFILTER_GRAD: unfilter_as(format, size, TFILTER_GRAD, filtered, texels); break;
	case TFILTER_XOR: unfilter_as(format, size, TFILTER_XOR, filtered, texels); break;
	default: memcpy(texels, filtered, (size_t)size * size * pix_bytes(format)); break;
	}
	return 0;
}

/* ---- codec ------------------------------------------------------------------------------ */

#define LOSSY_SMALL 2048 /* a lossy payload under this many bytes is checked against zstd */

/* Compresses src into out; returns bytes, or 0 when it does not fit (caller falls back). */
static size_t compress(struct tilecodec *tc, enum tcodec codec, int level, const void *src,
		       size_t n, void *out, size_t cap)
{
	if (codec == TCODEC_LZ4) {
		int cap_i = cap > (size_t)INT_MAX ? INT_MAX : (int)cap;
		int r = LZ4_compress_fast(src, out, (int)n, cap_i, level > 0 ? level : 1);
		return r > 0 ? (size_t)r : 0;
	}
	size_t r = ZSTD_compressCCtx(tc->cctx, out, cap, src, n, level > 0 ? level : 1);
	return ZSTD_isError(r) ? 0 : r;
}

ssize_t tilecodec_encode(struct tilecodec *tc, enum pix_type format, uint32_t size,
			 enum tcodec codec, enum tfilter filter, int level, const void *texels,
			 struct tilecodec_hdr *h, void *out, size_t cap)
{
	if (filter_args(format, size, filter) || (unsigned)codec >= TCODEC_COUNT ||
	    tilecodec_is_lossy(codec))
		return -EINVAL;
	size_t raw = (size_t)size * size * pix_bytes(format);
	if (cap < tilecodec_bound(codec, raw))
		return -ENOSPC;
	*h = (struct tilecodec_hdr){ .format = (uint8_t)format, .size = size,
				     .raw_len = (uint32_t)raw,
				     .checksum = XXH3_64bits(texels, raw) };
	if (codec == TCODEC_NONE) {
		h->filter = (uint8_t)filter;
		tilecodec_filter(format, size, filter, texels, out);
		return (ssize_t)raw;
	}
	const void *src = texels;
	if (filter != TFILTER_NONE) {
		unsigned char *s = scratch(tc, raw);
		tilecodec_filter(format, size, filter, texels, s);
		src = s;
	}
	size_t n = compress(tc, codec, level, src, raw, out, cap);
	if (n == 0 || n >= raw) {
		/* Compression did not pay: send the texels as they are. */
		memcpy(out, texels, raw);
		return (ssize_t)raw;
	}
	h->codec = (uint8_t)codec;
	h->filter = (uint8_t)filter;
	return (ssize_t)n;
}

ssize_t tilecodec_encode_lossy(struct tilecodec *tc, enum pix_type format, uint32_t size,
			       enum tcodec codec, const struct tilecodec_lossy_opts *o,
			       const void *texels, struct tilecodec_hdr *h, void *out, size_t cap)
{
	if (filter_args(format, size, TFILTER_NONE) || !tilecodec_is_lossy(codec) ||
	    !tilecodec_codec_fits(codec, format))
		return -EINVAL;
	size_t raw = (size_t)size * size * pix_bytes(format);
	if (cap < tilecodec_bound(TCODEC_ZSTD, raw))
		return -ENOSPC;
	/* Room for the raw copy and the lossy scratch; the filter's scratch of a fallback
	 * below is the same buffer, used after. */
	size_t need = tilecodec_lossy_scratch(size);
	unsigned char *s = scratch(tc, need > raw ? need : raw);
	ssize_t n = tilecodec_lossy_encode(tc->cctx, s, format, size, codec, o, texels, out,
					   raw - 1);
	if (n < 0 && n != -ENOSPC)
		return n;
	if (n <= 0) /* not smaller, or not codable: lossless */
		return tilecodec_encode(tc, format, size, TCODEC_ZSTD,
					tilecodec_default_filter(format), 1, texels, h, out, cap);
	if (n < LOSSY_SMALL) {
		/* A near-uniform tile (sea, ice): WebP's few hundred bytes of container and
		 * headers may be more than zstd needs for it. The smaller goes. */
		size_t zb = tilecodec_bound(TCODEC_ZSTD, raw);
		if (tc->alt_cap < zb) {
			free(tc->alt);
			tc->alt = xmalloc(zb);
			tc->alt_cap = zb;
		}
		struct tilecodec_hdr zh;
		ssize_t z = tilecodec_encode(tc, format, size, TCODEC_ZSTD,
					     tilecodec_default_filter(format), 1, texels, &zh, tc->alt,
					     zb);
		if (z > 0 && z < n) {
			memcpy(out, tc->alt, (size_t)z);
			*h = zh;
			return z;
		}
	}
	*h = (struct tilecodec_hdr){ .format = (uint8_t)format, .codec = (uint8_t)codec,
				     .filter = TFILTER_NONE, .size = size, .raw_len = (uint32_t)raw,
				     .checksum = XXH3_64bits(out, (size_t)n) };
	return n;
}

static int decode(struct tilecodec *tc, const struct tilecodec_hdr *h, const void *payload,
		  size_t n, void *texels, size_t cap, bool verify, char err[256])
{
	int rc = tilecodec_hdr_check(h, err);
	if (rc)
		return rc;
	size_t raw = h->raw_len;
	if (cap < raw) {
		err_set(err, "output buffer of %zu bytes is smaller than the tile (%zu)", cap, raw);
		return -EINVAL;
	}
	if (tilecodec_is_lossy(h->codec)) {
		if (n == 0 || n > raw) {
			err_set(err, "%s payload of %zu bytes for a tile of %zu",
				tilecodec_codec_name(h->codec), n, raw);
			return -EBADMSG;
		}
		return tilecodec_lossy_decode(tc->dctx, scratch(tc, tilecodec_lossy_scratch(h->size)),
					      h, payload, n, texels, err);
	}
	void *dst = h->filter == TFILTER_NONE ? texels : scratch(tc, raw);
	switch (h->codec) {
	case TCODEC_NONE:
		if (n != raw) {
			err_set(err, "raw payload of %zu bytes, expected %zu", n, raw);
			return -EBADMSG;
		}
		if (h->filter == TFILTER_NONE)
			memcpy(texels, payload, raw);
		else
			dst = (void *)(uintptr_t)payload;
		break;
	case TCODEC_LZ4: {
		if (n > (size_t)LZ4_MAX_INPUT_SIZE) {
			err_set(err, "lz4 payload of %zu bytes is too large", n);
			return -EBADMSG;
		}
		int r = LZ4_decompress_safe(payload, dst, (int)n, (int)raw);
		if (r < 0 || (size_t)r != raw) {
			err_set(err, "corrupt lz4 payload (%d of %zu bytes)", r, raw);
			return -EBADMSG;
		}
		break;
	}
	case TCODEC_ZSTD: {
		size_t r = ZSTD_decompressDCtx(tc->dctx, dst, raw, payload, n);
		if (ZSTD_isError(r) || r != raw) {
			err_set(err, "corrupt zstd payload (%s)",
			       ZSTD_isError(r) ? ZSTD_getErrorName(r) : "wrong length");
			return -EBADMSG;
		}
		break;
	}
	}
	if (h->filter != TFILTER_NONE)
		tilecodec_unfilter(h->format, h->size, h->filter, dst, texels);
	if (!verify)
		return 0;
	uint64_t sum = XXH3_64bits(texels, raw);
	if (sum != h->checksum) {
		err_set(err, "tile checksum mismatch: %016llx, expected %016llx",
		       (unsigned long long)sum, (unsigned long long)h->checksum);
		return -EILSEQ;
	}
	return 0;
}

int tilecodec_decode(struct tilecodec *tc, const struct tilecodec_hdr *h, const void *payload,
		     size_t n, void *texels, size_t cap, char err[256])
{
	return decode(tc, h, payload, n, texels, cap, true, err);
}

int tilecodec_decode_trusted(struct tilecodec *tc, const struct tilecodec_hdr *h,
			     const void *payload, size_t n, void *texels, size_t cap, char err[256])
{
	return decode(tc, h, payload, n, texels, cap, false, err);
}
