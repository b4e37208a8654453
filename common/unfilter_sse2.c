/* unfilter_sse2 — see unfilter_sse2.h.
 *
 * Undoing DELTA, GRAD and XOR is a running sum (xor) along each row: a chain of dependent
 * adds, one per component, which no compiler turns into vector code. Here the sum runs 16
 * bytes (or 4 words) at a time: the prefix within a vector in log2 steps of shift-and-add,
 * then the previous vector's last lane added to every lane (the only dependency from one
 * vector to the next). The byte planes are gathered back into pixels with unpacks, and the
 * residuals' zigzag undone in the same registers. SSE2 only: every x86-64 CPU has it.
 * Exactly the scalar arithmetic (all modular), so the bytes are the same
 * (tests/unit/test_tilecodec.c compares both with a reference).
 */
#include "unfilter_sse2.h"

#if defined(__SSE2__)
#include <emmintrin.h>

/* Bytes: z >> 1 ^ -(z & 1), lane by lane. */
static inline __m128i unzz8v(__m128i z)
{
	__m128i hi = _mm_and_si128(_mm_srli_epi16(z, 1), _mm_set1_epi8(0x7f));
	__m128i lo = _mm_sub_epi8(_mm_setzero_si128(), _mm_and_si128(z, _mm_set1_epi8(1)));
	return _mm_xor_si128(hi, lo);
}

static inline __m128i unzz32v(__m128i z)
{
	return _mm_xor_si128(_mm_srli_epi32(z, 1),
			     _mm_sub_epi32(_mm_setzero_si128(), _mm_and_si128(z, _mm_set1_epi32(1))));
}

/* Byte 15 of x in every lane. */
static inline __m128i last8(__m128i x)
{
	__m128i t = _mm_srli_si128(x, 15);
	t = _mm_unpacklo_epi8(t, t);
	t = _mm_unpacklo_epi16(t, t);
	return _mm_shuffle_epi32(t, 0);
}

/* The running sum (xor) of 16 bytes, carried on from c (every lane the previous total). */
static inline __m128i scan8(__m128i x, __m128i c, int xor)
{
	if (xor) {
		x = _mm_xor_si128(x, _mm_slli_si128(x, 1));
		x = _mm_xor_si128(x, _mm_slli_si128(x, 2));
		x = _mm_xor_si128(x, _mm_slli_si128(x, 4));
		x = _mm_xor_si128(x, _mm_slli_si128(x, 8));
		return _mm_xor_si128(x, c);
	}
	x = _mm_add_epi8(x, _mm_slli_si128(x, 1));
	x = _mm_add_epi8(x, _mm_slli_si128(x, 2));
	x = _mm_add_epi8(x, _mm_slli_si128(x, 4));
	x = _mm_add_epi8(x, _mm_slli_si128(x, 8));
	return _mm_add_epi8(x, c);
}

static inline __m128i scan32(__m128i x, __m128i c, int xor)
{
	if (xor) {
		x = _mm_xor_si128(x, _mm_slli_si128(x, 4));
		x = _mm_xor_si128(x, _mm_slli_si128(x, 8));
		return _mm_xor_si128(x, c);
	}
	x = _mm_add_epi32(x, _mm_slli_si128(x, 4));
	x = _mm_add_epi32(x, _mm_slli_si128(x, 8));
	return _mm_add_epi32(x, c);
}

static inline __m128i ld(const void *p) { return _mm_loadu_si128((const __m128i *)p); }
static inline void st(void *p, __m128i v) { _mm_storeu_si128((__m128i *)p, v); }

/* One filter (a constant where called), nc = 2 or 4 channels. */
static inline __attribute__((always_inline)) void u8_rows(uint32_t T, unsigned nc,
							 enum tfilter f, const unsigned char *in,
							 unsigned char *out)
{
	const size_t n = (size_t)T * T;
	const int xor = f == TFILTER_XOR;
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *r = in + (size_t)y * T;
		unsigned char *dst = out + (size_t)nc * y * T;
		const unsigned char *up = y ? dst - (size_t)nc * T : NULL;
		__m128i c[4];
		for (unsigned k = 0; k < nc; k++) /* GRAD sums from 0, then adds the row above */
			c[k] = _mm_set1_epi8((char)(up && f != TFILTER_GRAD ? up[k] : 0));
		for (uint32_t x = 0; x < T; x += 16) {
			__m128i p[4];
			for (unsigned k = 0; k < nc; k++) {
				__m128i z = ld(r + k * n + x);
				p[k] = scan8(xor ? z : unzz8v(z), c[k], xor);
				c[k] = last8(p[k]);
			}
			__m128i o[4];
			if (nc == 2) {
				o[0] = _mm_unpacklo_epi8(p[0], p[1]);
				o[1] = _mm_unpackhi_epi8(p[0], p[1]);
			} else {
				__m128i a = _mm_unpacklo_epi8(p[0], p[1]), b = _mm_unpacklo_epi8(p[2], p[3]);
				__m128i e = _mm_unpackhi_epi8(p[0], p[1]), g = _mm_unpackhi_epi8(p[2], p[3]);
				o[0] = _mm_unpacklo_epi16(a, b);
				o[1] = _mm_unpackhi_epi16(a, b);
				o[2] = _mm_unpacklo_epi16(e, g);
				o[3] = _mm_unpackhi_epi16(e, g);
			}
			unsigned char *d = dst + (size_t)nc * x;
			for (unsigned k = 0; k < nc; k++) {
				if (f == TFILTER_GRAD && up)
					o[k] = _mm_add_epi8(o[k], ld(up + (size_t)nc * x + 16 * k));
				st(d + 16 * k, o[k]);
			}
		}
	}
}

static inline __attribute__((always_inline)) void f32_rows(uint32_t T, enum tfilter f,
							  const unsigned char *in,
							  unsigned char *out, uint32_t *rows)
{
	const size_t n = (size_t)T * T;
	const int xor = f == TFILTER_XOR;
	const __m128i top = _mm_set1_epi32((int)0x80000000u), ones = _mm_set1_epi32(-1);
	for (uint32_t y = 0; y < T; y++) {
		const unsigned char *p = in + (size_t)y * T;
		uint32_t *v = rows + (size_t)(y & 1) * T, *u = y ? rows + (size_t)(~y & 1) * T : NULL;
		unsigned char *dst = out + (size_t)4 * y * T;
		__m128i c = _mm_set1_epi32((int)(u && f != TFILTER_GRAD ? u[0] : 0));
		for (uint32_t x = 0; x < T; x += 16) {
			__m128i b0 = ld(p + x), b1 = ld(p + n + x), b2 = ld(p + 2 * n + x),
				b3 = ld(p + 3 * n + x);
			__m128i a = _mm_unpacklo_epi8(b0, b1), b = _mm_unpacklo_epi8(b2, b3);
			__m128i e = _mm_unpackhi_epi8(b0, b1), g = _mm_unpackhi_epi8(b2, b3);
			__m128i w[4] = { _mm_unpacklo_epi16(a, b), _mm_unpackhi_epi16(a, b),
					 _mm_unpacklo_epi16(e, g), _mm_unpackhi_epi16(e, g) };
			for (int k = 0; k < 4; k++) {
				__m128i s = scan32(xor ? w[k] : unzz32v(w[k]), c, xor);
				c = _mm_shuffle_epi32(s, 0xff);
				if (f == TFILTER_GRAD && u)
					s = _mm_add_epi32(s, ld(u + x + 4 * k));
				st(v + x + 4 * k, s);
				/* order-preserving form back to float bits: top bit set → clear it,
				 * else all bits flipped */
				__m128i m = _mm_srai_epi32(s, 31);
				st(dst + 4 * (x + 4 * k),
				   _mm_xor_si128(s, _mm_or_si128(_mm_andnot_si128(m, ones), top)));
			}
		}
	}
}

/* u8_rows with the filter a constant in each call (nc a constant from the caller). */
static inline __attribute__((always_inline)) void u8_any(uint32_t T, unsigned nc,
							enum tfilter f, const void *in, void *out)
{
	if (f == TFILTER_DELTA)
		u8_rows(T, nc, TFILTER_DELTA, in, out);
	else if (f == TFILTER_GRAD)
		u8_rows(T, nc, TFILTER_GRAD, in, out);
	else
		u8_rows(T, nc, TFILTER_XOR, in, out);
}

void unfilter_u8_sse2(uint32_t T, unsigned nc, enum tfilter f, const void *in, void *out)
{
	if (nc == 4)
		u8_any(T, 4, f, in, out);
	else
		u8_any(T, 2, f, in, out);
}

void unfilter_f32_sse2(uint32_t T, enum tfilter f, const void *in, void *out, uint32_t *rows)
{
	if (f == TFILTER_DELTA)
		f32_rows(T, TFILTER_DELTA, in, out, rows);
	else if (f == TFILTER_GRAD)
		f32_rows(T, TFILTER_GRAD, in, out, rows);
	else
		f32_rows(T, TFILTER_XOR, in, out, rows);
}

bool unfilter_sse2_fits(uint32_t T, enum tfilter f)
{
	return T >= 16 && T % 16 == 0 &&
	       (f == TFILTER_DELTA || f == TFILTER_GRAD || f == TFILTER_XOR);
}
#else
bool unfilter_sse2_fits(uint32_t T, enum tfilter f)
{
	(void)T;
	(void)f;
	return false;
}

void unfilter_u8_sse2(uint32_t T, unsigned nc, enum tfilter f, const void *in, void *out)
{
	(void)T, (void)nc, (void)f, (void)in, (void)out;
}

void unfilter_f32_sse2(uint32_t T, enum tfilter f, const void *in, void *out, uint32_t *rows)
{
	(void)T, (void)f, (void)in, (void)out, (void)rows;
}
#endif
