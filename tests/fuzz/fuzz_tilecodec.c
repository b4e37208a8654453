/* fuzz_tilecodec — libFuzzer target for the tile codec (common/tilecodec.c), whose decoder
 * reads bytes from the network. Built and run by `make fuzz`.
 *
 * The first 8 bytes choose: the mode (decode or round trip), format, codec, filter, the tile
 * size (a power of two up to 128, kept small so runs stay fast), a level, and for decode the
 * header's raw_len and checksum perturbations; the rest is the payload (decode) or the texels
 * (round trip, repeated to fill the tile).
 * Properties checked, beyond "no crash, no leak, no undefined behaviour":
 *  - decode of any header and payload returns 0 or a documented error (-EINVAL, -EBADMSG,
 *    -EILSEQ) with a message, and never writes past raw_len (the buffer is raw_len bytes,
 *    followed by a guard checked after the call);
 *  - encode → decode gives back exactly the texels (every format, codec, filter, level),
 *    and the payload fits tilecodec_bound;
 *  - filter → unfilter gives back exactly the texels;
 *  - flipping one payload byte of a compressed round trip never yields success with other
 *    texels (the checksum catches it);
 *  - a lossy round trip (q16) decodes, to heights within half the step, and a flipped
 *    payload byte is an error (the payload's checksum);
 *  - WebP payloads the daemon made (colour with and without alpha, normals; encoded once),
 *    corrupted at positions and by values the input chooses and given a matching checksum,
 *    reach libwebp's decoder: an error or texels, never a crash or a write past them.
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/tilecodec.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static struct tilecodec *tc; /* fuzzer-only: reused across inputs */

static void check_rc(int rc, const char *err)
{
	if (rc != 0 && rc != -EINVAL && rc != -EBADMSG && rc != -EILSEQ)
		abort();
	if (rc && !err[0])
		abort();
}

/* Valid WebP payloads of 32² tiles, made once: colour with alpha, colour opaque, normals. */
enum { WEBP_T = 32, NWEBP = 3 };
static uint8_t *webp_pay[NWEBP];
static size_t webp_len[NWEBP];
static struct tilecodec_hdr webp_hdr[NWEBP];

static void webp_seeds(void)
{
	static const enum pix_type fmt[NWEBP] = { PIX_COLOR, PIX_COLOR, PIX_NORMAL };
	for (int k = 0; k < NWEBP; k++) {
		size_t raw = (size_t)WEBP_T * WEBP_T * pix_bytes(fmt[k]);
		uint8_t *tex = malloc(raw);
		size_t bpp = pix_bytes(fmt[k]);
		uint32_t r = 12345u + (uint32_t)k; /* noise (zstd cannot shrink it, WebP can) */
		for (size_t i = 0; i < raw; i++) { /* alpha 255 but in the first */
			r = r * 1664525u + 1013904223u;
			size_t x = i / bpp % WEBP_T;
			tex[i] = fmt[k] == PIX_COLOR && i % bpp == 3 ? (k ? 255 : (uint8_t)(128 + x * 2))
								     : (uint8_t)(r >> 24);
		}
		size_t cap = tilecodec_bound(TCODEC_ZSTD, raw);
		webp_pay[k] = malloc(cap);
		struct tilecodec_lossy_opts o = { .quality = 60 };
		ssize_t len = tilecodec_encode_lossy(tc, fmt[k], WEBP_T, TCODEC_WEBP, &o, tex,
						     &webp_hdr[k], webp_pay[k], cap);
		if (len <= 0 || webp_hdr[k].codec != TCODEC_WEBP)
			abort();
		webp_len[k] = (size_t)len;
		free(tex);
	}
}

/* One of the WebP payloads, with the input's bytes as (position, xor) pairs applied. */
static void decode_webp(const uint8_t *h8, const uint8_t *p, size_t n)
{
	int k = h8[1] % NWEBP;
	size_t len = webp_len[k];
	if (h8[6] & 1) /* cut short */
		len = len * (size_t)(h8[6] >> 1) / 128 + 1;
	uint8_t *pay = malloc(len);
	memcpy(pay, webp_pay[k], len);
	for (size_t i = 0; i + 1 < n; i += 2)
		pay[((size_t)p[i] * 131 + i * 17) % len] ^= p[i + 1];
	struct tilecodec_hdr h = webp_hdr[k];
	h.checksum = h8[7] & 1 ? h.checksum : tilecodec_checksum(pay, len);
	uint8_t *out = malloc(h.raw_len + 16);
	memset(out + h.raw_len, 0xA5, 16);
	char err[256] = "";
	check_rc(tilecodec_decode(tc, &h, pay, len, out, h.raw_len, err), err);
	for (int i = 0; i < 16; i++)
		if (out[h.raw_len + (size_t)i] != 0xA5)
			abort();
	free(out);
	free(pay);
}

static void decode_any(const uint8_t *h8, const uint8_t *p, size_t n)
{
	if ((h8[2] & 0x30) == 0x30) {
		decode_webp(h8, p, n);
		return;
	}
	struct tilecodec_hdr h = {
		.format = h8[1] % 5,
		.codec = h8[2] % (TCODEC_COUNT + 1),
		.filter = h8[3] % 6,
		.size = h8[4] & 0x80 ? (uint32_t)h8[4] : 1u << (h8[4] % 8),
	};
	size_t bpp = h.format >= 1 && h.format <= 3 ? pix_bytes(h.format) : 4;
	h.raw_len = (uint32_t)((size_t)h.size * h.size * bpp);
	if (h8[5] & 1)
		h.raw_len += h8[6]; /* a wrong length */
	if (h.raw_len > (1u << 20))
		return;
	h.checksum = h8[7] & 1 ? tilecodec_checksum(p, n) : (uint64_t)h8[7] * 0x9E3779B97F4A7C15ull;
	size_t cap = h.raw_len;
	uint8_t *out = malloc(cap + 16);
	memset(out + cap, 0xA5, 16);
	char err[256] = "";
	int rc = tilecodec_decode(tc, &h, p, n, out, cap, err);
	check_rc(rc, err);
	for (int i = 0; i < 16; i++)
		if (out[cap + (size_t)i] != 0xA5)
			abort(); /* wrote past the texels */
	free(out);
}

/* A q16 round trip of heights: decodes, within half a step (of the range / 65535 or the asked
 * step), a corrupted byte refused. */
static void q16_trip(const uint8_t *h8, const uint8_t *p, size_t n)
{
	const enum pix_type fmt = PIX_HEIGHT;
	uint32_t T = 1u << (h8[4] % 8);
	size_t raw = (size_t)T * T * pix_bytes(fmt);
	uint8_t *tex = malloc(raw), *back = malloc(raw);
	for (size_t i = 0; i < raw; i++)
		tex[i] = n ? p[i % n] : (uint8_t)i;
	for (size_t i = 0; i < raw / 4; i++) /* finite heights of a few km, from the bytes */
		((float *)(void *)tex)[i] = (float)((int)(tex[i * 4] | tex[i * 4 + 1] << 8) - 32768) *
					    (float)(1 + h8[5] % 8) * 0.05f;
	size_t cap = tilecodec_bound(TCODEC_ZSTD, raw);
	uint8_t *pay = malloc(cap);
	struct tilecodec_hdr h;
	struct tilecodec_lossy_opts o = { .step = (h8[7] % 4) * 0.25 };
	ssize_t k = tilecodec_encode_lossy(tc, fmt, T, TCODEC_Q16, &o, tex, &h, pay, cap);
	if (k <= 0 || (size_t)k > raw || h.raw_len != raw || h.size != T || h.format != fmt)
		abort();
	char err[256] = "";
	if (tilecodec_decode(tc, &h, pay, (size_t)k, back, raw, err))
		abort();
	if (h.codec == TCODEC_Q16) {
		const float *a = (const float *)(void *)tex, *b = (const float *)(void *)back;
		float lo = a[0], hi = a[0];
		for (size_t i = 0; i < raw / 4; i++) {
			lo = a[i] < lo ? a[i] : lo;
			hi = a[i] > hi ? a[i] : hi;
		}
		double step = ((double)hi - lo) / 65535.0;
		step = o.step > step ? o.step : step;
		for (size_t i = 0; i < raw / 4; i++)
			if (fabs((double)a[i] - b[i]) > step * 0.5 + 1e-3)
				abort();
	} else if (h.codec == TCODEC_ZSTD || h.codec == TCODEC_NONE) {
		if (memcmp(tex, back, raw)) /* the lossless fallback */
			abort();
	}
	if (tilecodec_is_lossy(h.codec)) {
		pay[h8[6] % (size_t)k] ^= (uint8_t)(1 + h8[7] % 255);
		if (tilecodec_decode(tc, &h, pay, (size_t)k, back, raw, err) != -EILSEQ)
			abort();
	}
	free(tex);
	free(back);
	free(pay);
}

static void round_trip(const uint8_t *h8, const uint8_t *p, size_t n)
{
	enum pix_type fmt = (enum pix_type)(1 + h8[1] % 3);
	enum tcodec codec = (enum tcodec)(h8[2] % TCODEC_COUNT);
	/* Colour and normals never take WebP's *encoder* here: libwebp allocates and clears
	 * ~11 MB for every picture with alpha, whatever its size, and under ASan those are
	 * fresh mappings each time (~30 ms an input; with them the target ran ~1 100 inputs/s,
	 * most of it in WebPEncode, and could not reach 10^7). The encoder only ever sees the
	 * daemon's own texels; the bytes a client receives, WebP payloads included, are what
	 * decode_any fuzzes, and test_tilecodec covers the WebP round trip. */
	if (tilecodec_is_lossy(codec)) {
		if (fmt == PIX_HEIGHT) {
			q16_trip(h8, p, n);
			return;
		}
		codec = TCODEC_ZSTD;
	}
	enum tfilter filter = (enum tfilter)(h8[3] % TFILTER_COUNT);
	uint32_t T = 1u << (h8[4] % 8);
	int level = h8[5] % 4;
	size_t raw = (size_t)T * T * pix_bytes(fmt);
	uint8_t *tex = malloc(raw), *filt = malloc(raw), *back = malloc(raw);
	for (size_t i = 0; i < raw; i++)
		tex[i] = n ? p[i % n] : (uint8_t)i;
	size_t cap = tilecodec_bound(codec, raw);
	uint8_t *pay = malloc(cap ? cap : 1);
	struct tilecodec_hdr h;
	ssize_t k = tilecodec_encode(tc, fmt, T, codec, filter, level, tex, &h, pay, cap);
	if (k < 0 || (size_t)k > cap || h.raw_len != raw || h.size != T || h.format != fmt)
		abort();
	char err[256] = "";
	if (tilecodec_decode(tc, &h, pay, (size_t)k, back, raw, err) || memcmp(tex, back, raw))
		abort(); /* the round trip must give back the texels */
	if (tilecodec_filter(fmt, T, filter, tex, filt) || tilecodec_unfilter(fmt, T, filter, filt, back) ||
	    memcmp(tex, back, raw))
		abort();
	if (k > 0 && h.codec != TCODEC_NONE) { /* one corrupted byte: an error or the texels */
		pay[h8[6] % (size_t)k] ^= (uint8_t)(1 + h8[7] % 255);
		int rc = tilecodec_decode(tc, &h, pay, (size_t)k, back, raw, err);
		check_rc(rc, err);
		if (rc == 0 && memcmp(tex, back, raw))
			abort();
	}
	free(tex);
	free(filt);
	free(back);
	free(pay);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	if (size < 8 || size > (1u << 18))
		return 0;
	if (!tc) {
		tc = tilecodec_create();
		webp_seeds();
	}
	if (data[0] & 1)
		round_trip(data, data + 8, size - 8);
	else
		decode_any(data, data + 8, size - 8);
	return 0;
}
