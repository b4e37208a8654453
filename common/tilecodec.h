/* tilecodec — how a tile's texels travel: an optional pre-filter (byte planes, left/gradient
 * prediction, xor) followed by a lossless codec (none, lz4, zstd), with an XXH3-64 checksum of
 * the raw texels; or, for slow links, a lossy codec (webp for colour and normals, q16 for
 * heights) whose checksum is of the payload. docs/PROTOCOL.md §"Tile payloads" is the
 * normative description of every filter and codec.
 *
 * Thread-safety: a struct tilecodec holds scratch buffers and zstd contexts; use one per
 * thread. The pure helpers (bounds, names, checksum) are thread-safe.
 * Ownership: callers own every buffer passed in; nothing returned points into the codec.
 * Decoding validates everything (identifiers, sizes, decompressed length, checksum) and never
 * writes past the caller's buffer, whatever the payload bytes are.
 */
#ifndef CLIPMAP_TILECODEC_H
#define CLIPMAP_TILECODEC_H
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "pixfmt.h"

/* Codecs; capability bit for codec c is (1u << c). */
enum tcodec {
	TCODEC_NONE = 0,
	TCODEC_LZ4 = 1,
	TCODEC_ZSTD = 2,
	TCODEC_WEBP = 3, /* lossy: colour (rgba8) and normals (rg8) as WebP images */
	TCODEC_Q16 = 4,	 /* lossy: heights (f32) quantised to 16 bits, then zstd */
	TCODEC_COUNT
};
#define TCODEC_ALL_MASK ((1u << TCODEC_COUNT) - 1)
#define TCODEC_LOSSY_MASK ((1u << TCODEC_WEBP) | (1u << TCODEC_Q16))
#define TCODEC_LOSSLESS_MASK (TCODEC_ALL_MASK & ~TCODEC_LOSSY_MASK)

/* Whether c is lossy, and whether it can code tiles of format f (lossless codecs: all). */
static inline int tilecodec_is_lossy(unsigned c)
{
	return c < 32 && ((1u << c) & TCODEC_LOSSY_MASK);
}
int tilecodec_codec_fits(unsigned c, unsigned format);

/* The lossy codecs' knobs. */
struct tilecodec_lossy_opts {
	int quality; /* webp: 1–100 (0: 80) */
	double step; /* q16: the quantisation step in metres at least (0: (max − min) / 65535);
		      * the error of a height is at most half the step actually used */
};

/* Pre-filters, applied per component (f32: the float's bits mapped to an order-preserving
 * u32; rgba8/rg8: each byte channel) before the codec. DELTA and GRAD store zigzag-coded
 * residuals modulo the component width. Every filter but NONE ends with a byte-plane split. */
enum tfilter {
	TFILTER_NONE = 0,
	TFILTER_PLANES = 1, /* byte planes only */
	TFILTER_DELTA = 2,  /* residual from the left neighbour (first column: from above) */
	TFILTER_GRAD = 3,   /* residual from left + up - upleft (edges: as DELTA) */
	TFILTER_XOR = 4,    /* xor with the left neighbour (first column: with above) */
	TFILTER_COUNT
};

#define TILECODEC_MAX_SIZE 1024u /* largest T */

/* What a receiver needs to decode a tile payload (the TILE message carries all of it). */
struct tilecodec_hdr {
	uint8_t format;	   /* enum pix_type */
	uint8_t codec;	   /* enum tcodec */
	uint8_t filter;	   /* enum tfilter */
	uint32_t size;	   /* T: a power of two, 1 ≤ T ≤ TILECODEC_MAX_SIZE */
	uint32_t raw_len;  /* T · T · bytes per texel */
	uint64_t checksum; /* XXH3_64bits of the raw texels */
};

const char *tilecodec_codec_name(enum tcodec c);       /* "none", "lz4", "zstd", "webp", "q16"; NULL if invalid */
const char *tilecodec_filter_name(enum tfilter f);     /* "none", "planes", "delta", "grad", "xor" */
/* Parses a codec name; returns the codec or -EINVAL. */
int tilecodec_codec_parse(const char *s);
/* The filter that compressed best for each format in tests/bench/bench_codec.c. */
enum tfilter tilecodec_default_filter(enum pix_type f);
/* XXH3_64bits of n bytes. */
uint64_t tilecodec_checksum(const void *p, size_t n);

/* Checks the header's identifiers and sizes (not the checksum). 0 or -EINVAL with err filled. */
int tilecodec_hdr_check(const struct tilecodec_hdr *h, char err[256]);
/* The most payload bytes encoding raw_len bytes with codec c can produce (0 if c invalid;
 * raw_len for the lossy codecs, which fall back to another codec rather than grow). */
size_t tilecodec_bound(enum tcodec c, size_t raw_len);

struct tilecodec;
/* A codec context (scratch buffers, zstd contexts). Returns owned; aborts on ENOMEM. */
struct tilecodec *tilecodec_create(void);
void tilecodec_destroy(struct tilecodec *tc); /* NULL is a no-op */

/* Encodes one T×T tile of `format` texels (borrowed, raw_len bytes, tightly packed) with a
 * lossless codec (a lossy one is -EINVAL: tilecodec_encode_lossy).
 * level: zstd level (0 → 1) or lz4 acceleration (0 → 1). If the codec's output would not
 * be smaller than the raw texels, the tile is sent raw (codec and filter NONE) — h says what
 * was used. Fills h (format, size, codec, filter, raw_len, checksum) and writes the payload
 * into out[0 .. cap). Returns payload bytes, -EINVAL (bad arguments) or -ENOSPC (cap smaller
 * than tilecodec_bound(codec, raw_len) — always enough). */
ssize_t tilecodec_encode(struct tilecodec *tc, enum pix_type format, uint32_t size,
			 enum tcodec codec, enum tfilter filter, int level, const void *texels,
			 struct tilecodec_hdr *h, void *out, size_t cap);

/* A lossy codec c (TCODEC_WEBP for colour and normals, TCODEC_Q16 for heights; o may be
 * NULL). When it cannot code the tile or does not make it smaller (a non-finite height, a
 * tile WebP codes larger than raw), the tile goes lossless instead — zstd level 1 with the
 * format's default filter, or raw: h says what was used. The checksum is of the payload for
 * lossy codecs. Returns payload bytes (≤ raw_len), -EINVAL (bad arguments, a codec that does
 * not fit the format) or -ENOSPC (cap < tilecodec_bound(TCODEC_ZSTD, raw_len)). */
ssize_t tilecodec_encode_lossy(struct tilecodec *tc, enum pix_type format, uint32_t size,
			       enum tcodec codec, const struct tilecodec_lossy_opts *o,
			       const void *texels, struct tilecodec_hdr *h, void *out, size_t cap);

/* Decodes a payload into texels[0 .. h->raw_len) (cap must be ≥ raw_len) and verifies the
 * checksum (of the texels, or of the payload for a lossy codec). Returns 0, -EINVAL (bad header, cap too small), -EBADMSG (corrupt stream, wrong
 * decompressed length) or -EILSEQ (checksum mismatch), with err filled (may be NULL). */
int tilecodec_decode(struct tilecodec *tc, const struct tilecodec_hdr *h, const void *payload,
		     size_t n, void *texels, size_t cap, char err[256]);
/* The same for a payload whose integrity the caller has just checked itself (the store's
 * value checksum covers the header, the key and the payload): a lossless payload's texel
 * checksum is not computed again (an XXH3 pass over the raw texels, 128–256 KiB a tile).
 * A lossy payload is checked as by tilecodec_decode. */
int tilecodec_decode_trusted(struct tilecodec *tc, const struct tilecodec_hdr *h,
			     const void *payload, size_t n, void *texels, size_t cap, char err[256]);

/* The filter alone (exposed for tests and benchmarks): filtered[] ← filter(texels[]) and its
 * inverse. Both buffers hold T·T·texel bytes and must not overlap. Return 0 or -EINVAL. */
int tilecodec_filter(enum pix_type format, uint32_t size, enum tfilter filter,
		     const void *texels, void *filtered);
int tilecodec_unfilter(enum pix_type format, uint32_t size, enum tfilter filter,
		       const void *filtered, void *texels);

#endif
