/* unfilter_sse2 — tilecodec's DELTA, GRAD and XOR filters undone 16 bytes at a time (the
 * byte-plane layout and arithmetic: tilecodec.c, docs/PROTOCOL.md). Byte for byte what the
 * scalar loops give; about 3-5x faster (bench_codec's filter lines). Only for the filters and
 * sizes unfilter_sse2_fits accepts; on a build without SSE2 it accepts none.
 * Threads: any; no state. */
#ifndef CLIPMAP_UNFILTER_SSE2_H
#define CLIPMAP_UNFILTER_SSE2_H
#include <stdbool.h>
#include <stdint.h>

#include "tilecodec.h"

/* T a multiple of 16 and f DELTA, GRAD or XOR (and the build has SSE2). */
bool unfilter_sse2_fits(uint32_t T, enum tfilter f);
/* nc = 2 (rg8) or 4 (rgba8) byte planes of T × T in → interleaved texels out. */
void unfilter_u8_sse2(uint32_t T, unsigned nc, enum tfilter f, const void *in, void *out);
/* 4 byte planes of order-preserving f32 residuals in → float bits out; rows: 2 × T words of
 * scratch. */
void unfilter_f32_sse2(uint32_t T, enum tfilter f, const void *in, void *out, uint32_t *rows);
#endif
