/* tilecodec_lossy — the lossy tile codecs for slow links (tilecodec.h, docs/PROTOCOL.md
 * §"Lossy codecs"): `webp` for colour and normals, `q16` for heights.
 *
 * webp: lossy WebP (libwebp) of the tile as an image. Colour whose alpha is all 255 goes as
 * RGB (no alpha plane: a third fewer bytes to code), other colour as RGBA (libwebp keeps the
 * alpha plane lossless). Normals (rg8) go as one grey image of 2T × T pixels, the east
 * components on the left, the north ones on the right: lossy WebP subsamples colour (4:2:0)
 * but not grey, so each component keeps its full resolution. The decoder checks the image's
 * size before decoding into the caller's buffer.
 *
 * q16: heights quantised to a step s ≥ (max − min) / 65535, q = round((h − min) / s), sent
 * as [f64 min][f64 s][zstd(byte planes of the grad residuals of q)]: decoded h' = min + q·s,
 * |h − h'| ≤ s / 2 (plus float rounding). A tile holding a non-finite height is not
 * quantised: tilecodec_encode_lossy codes it losslessly instead (zstd + grad).
 *
 * For both, the header's checksum is the XXH3-64 of the payload: the receiver's texels are
 * not the sender's, so the payload is what can be checked end to end.
 */
#include "tilecodec.h"

#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <webp/decode.h>
#include <webp/encode.h>
#include <xxhash.h>
#include <zstd.h>

#include "errbuf.h"
#include "tilecodec_lossy.h"
#include "xalloc.h"

#define Q16_HEAD 16 /* f64 min, f64 step */
#define WEBP_QUALITY 80
#define WEBP_METHOD 2 /* 0 fastest … 6 smallest; 2: within a few % of 4's bytes, ~2× faster */

static void st64(unsigned char *p, double d)
{
	uint64_t v;
	memcpy(&v, &d, 8);
	for (int i = 0; i < 8; i++)
		p[i] = (unsigned char)(v >> (8 * i));
}

static double ld64(const unsigned char *p)
{
	uint64_t v = 0;
	for (int i = 0; i < 8; i++)
		v |= (uint64_t)p[i] << (8 * i);
	double d;
	memcpy(&d, &v, 8);
	return d;
}

static inline uint16_t zz16(uint16_t d) { return (uint16_t)((d << 1) ^ (0u - (d >> 15))); }
static inline uint16_t unzz16(uint16_t z) { return (uint16_t)((z >> 1) ^ (0u - (z & 1))); }

/* The grad prediction of q at (x, y) from the decoded neighbours (tilecodec's rule). */
static inline uint16_t pred16(const uint16_t *q, uint32_t T, uint32_t x, uint32_t y)
{
	if (x == 0)
		return y ? q[(size_t)(y - 1) * T] : 0;
	if (y == 0)
		return q[x - 1];
	size_t i = (size_t)y * T + x;
	return (uint16_t)(q[i - 1] + q[i - T] - q[i - T - 1]);
}

/* ---- q16 -------------------------------------------------------------------------------- */

/* Quantises the heights; returns the payload bytes, 0 when it does not pay or cannot be done
 * (a non-finite height), -ENOSPC. */
static ssize_t q16_encode(void *zctx, unsigned char *scratch, uint32_t T, double step_hint,
			  const float *h, unsigned char *out, size_t cap)
{
	size_t n = (size_t)T * T;
	float lo = INFINITY, hi = -INFINITY;
	for (size_t i = 0; i < n; i++) {
		if (!isfinite(h[i]))
			return 0;
		lo = h[i] < lo ? h[i] : lo;
		hi = h[i] > hi ? h[i] : hi;
	}
	double step = ((double)hi - lo) / 65535.0;
	if (step_hint > step)
		step = step_hint;
	if (!(step > 0))
		step = 1; /* a flat tile: every q is 0 */
	uint16_t *q = (uint16_t *)(void *)scratch;
	unsigned char *planes = scratch + n * 2;
	for (size_t i = 0; i < n; i++) {
		double v = nearbyint(((double)h[i] - lo) / step);
		q[i] = (uint16_t)(v < 0 ? 0 : v > 65535 ? 65535 : v);
	}
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++) {
			size_t i = (size_t)y * T + x;
			uint16_t r = zz16((uint16_t)(q[i] - pred16(q, T, x, y)));
			planes[i] = (unsigned char)r;
			planes[n + i] = (unsigned char)(r >> 8);
		}
	if (cap < Q16_HEAD + 1)
		return -ENOSPC;
	st64(out, lo);
	st64(out + 8, step);
	size_t z = ZSTD_compressCCtx(zctx, out + Q16_HEAD, cap - Q16_HEAD, planes, n * 2, 1);
	if (ZSTD_isError(z))
		return 0;
	return (ssize_t)(Q16_HEAD + z);
}

static int q16_decode(void *dctx, unsigned char *scratch, uint32_t T, const unsigned char *p,
		      size_t len, float *h, char err[256])
{
	size_t n = (size_t)T * T;
	if (len <= Q16_HEAD) {
		err_set(err, "q16 payload of %zu bytes is too short", len);
		return -EBADMSG;
	}
	double lo = ld64(p), step = ld64(p + 8);
	if (!isfinite(lo) || !(step > 0) || !isfinite(step) || !isfinite(lo + 65535.0 * step)) {
		err_set(err, "q16 payload with base %g and step %g", lo, step);
		return -EBADMSG;
	}
	unsigned char *planes = scratch + n * 2;
	size_t r = ZSTD_decompressDCtx(dctx, planes, n * 2, p + Q16_HEAD, len - Q16_HEAD);
	if (ZSTD_isError(r) || r != n * 2) {
		err_set(err, "corrupt q16 payload (%s)",
			ZSTD_isError(r) ? ZSTD_getErrorName(r) : "wrong length");
		return -EBADMSG;
	}
	uint16_t *q = (uint16_t *)(void *)scratch;
	for (uint32_t y = 0; y < T; y++)
		for (uint32_t x = 0; x < T; x++) {
			size_t i = (size_t)y * T + x;
			uint16_t z = (uint16_t)(planes[i] | planes[n + i] << 8);
			q[i] = (uint16_t)(unzz16(z) + pred16(q, T, x, y));
			h[i] = (float)(lo + q[i] * step);
		}
	return 0;
}

/* ---- webp ------------------------------------------------------------------------------- */

/* Where libwebp's writer puts the payload. */
struct webp_out {
	unsigned char *p;
	size_t len, cap;
};

static int webp_write(const uint8_t *data, size_t n, const WebPPicture *pic)
{
	struct webp_out *w = pic->custom_ptr;
	if (w->len + n > w->cap)
		return 0; /* larger than the raw tile would be: give up */
	memcpy(w->p + w->len, data, n);
	w->len += n;
	return 1;
}

/* Encodes colour or normals; returns the payload bytes, 0 when it does not pay or fails. */
static ssize_t webp_encode(unsigned char *scratch, enum pix_type f, uint32_t T, int quality,
			   const unsigned char *tex, unsigned char *out, size_t cap)
{
	size_t n = (size_t)T * T;
	bool alpha = false;
	const unsigned char *src = tex;
	int stride = (int)T * 4;
	if (f == PIX_COLOR) {
		for (size_t i = 0; i < n && !alpha; i++)
			alpha = tex[i * 4 + 3] != 255;
	} else { /* rg8 → a grey 2T × T image (R = G = B), east | north */
		for (size_t y = 0; y < T; y++)
			for (size_t x = 0; x < T; x++) {
				const unsigned char *t = tex + (y * T + x) * 2;
				unsigned char *e = scratch + (y * 2 * T + x) * 3, *no = e + (size_t)T * 3;
				e[0] = e[1] = e[2] = t[0];
				no[0] = no[1] = no[2] = t[1];
			}
		src = scratch;
		stride = (int)T * 6;
	}
	WebPConfig cfg;
	WebPPicture pic;
	if (!WebPConfigPreset(&cfg, WEBP_PRESET_DEFAULT, (float)quality) || !WebPPictureInit(&pic))
		return 0;
	cfg.method = WEBP_METHOD;
	pic.use_argb = 0;
	pic.width = (int)T * (f == PIX_COLOR ? 1 : 2);
	pic.height = (int)T;
	struct webp_out w = { out, 0, cap };
	pic.writer = webp_write;
	pic.custom_ptr = &w;
	int ok = f == PIX_COLOR ? (alpha ? WebPPictureImportRGBA(&pic, src, stride)
					 : WebPPictureImportRGBX(&pic, src, stride))
				: WebPPictureImportRGB(&pic, src, stride);
	ok = ok && WebPEncode(&cfg, &pic);
	WebPPictureFree(&pic);
	return ok ? (ssize_t)w.len : 0;
}

static int webp_decode(unsigned char *scratch, enum pix_type f, uint32_t T, const unsigned char *p,
		       size_t len, unsigned char *tex, char err[256])
{
	int w = 0, h = 0;
	if (!WebPGetInfo(p, len, &w, &h)) {
		err_set(err, "corrupt webp payload (no WebP header)");
		return -EBADMSG;
	}
	int want_w = (int)T * (f == PIX_COLOR ? 1 : 2);
	if (w != want_w || h != (int)T) {
		err_set(err, "webp payload of %d×%d pixels for a %u² %s tile (%d×%u expected)", w, h,
			T, pix_format_name(f), want_w, T);
		return -EBADMSG;
	}
	size_t n = (size_t)T * T;
	if (f == PIX_COLOR) {
		if (!WebPDecodeRGBAInto(p, len, tex, n * 4, (int)T * 4)) {
			err_set(err, "corrupt webp payload");
			return -EBADMSG;
		}
		return 0;
	}
	if (!WebPDecodeRGBInto(p, len, scratch, n * 6, (int)T * 6)) {
		err_set(err, "corrupt webp payload");
		return -EBADMSG;
	}
	for (size_t y = 0; y < T; y++)
		for (size_t x = 0; x < T; x++) {
			const unsigned char *e = scratch + (y * 2 * T + x) * 3;
			tex[(y * T + x) * 2] = e[1]; /* green: the least rounded of a grey's decode */
			tex[(y * T + x) * 2 + 1] = e[(size_t)T * 3 + 1];
		}
	return 0;
}

/* ---- the entry points (tilecodec.c) ----------------------------------------------------- */

size_t tilecodec_lossy_scratch(uint32_t T)
{
	return (size_t)T * T * 6; /* q16: q and its planes (4 bytes a texel); webp: 2 rgb */
}

ssize_t tilecodec_lossy_encode(void *zctx, unsigned char *scratch, enum pix_type f, uint32_t T,
			       enum tcodec c, const struct tilecodec_lossy_opts *o,
			       const void *texels, void *out, size_t cap)
{
	if (c == TCODEC_Q16)
		return q16_encode(zctx, scratch, T, o ? o->step : 0, texels, out, cap);
	int q = o && o->quality > 0 ? (o->quality > 100 ? 100 : o->quality) : WEBP_QUALITY;
	return webp_encode(scratch, f, T, q, texels, out, cap);
}

int tilecodec_lossy_decode(void *dctx, unsigned char *scratch, const struct tilecodec_hdr *h,
			   const void *payload, size_t n, void *texels, char err[256])
{
	uint64_t sum = XXH3_64bits(payload, n);
	if (sum != h->checksum) {
		err_set(err, "tile checksum mismatch: %016llx, expected %016llx",
			(unsigned long long)sum, (unsigned long long)h->checksum);
		return -EILSEQ;
	}
	if (h->codec == TCODEC_Q16)
		return q16_decode(dctx, scratch, h->size, payload, n, texels, err);
	return webp_decode(scratch, h->format, h->size, payload, n, texels, err);
}
