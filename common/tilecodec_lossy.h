/* tilecodec_lossy — internal to tilecodec.c: the lossy codecs' coding (tilecodec_lossy.c
 * says how each works). tilecodec.c checks the arguments and the header, owns the scratch
 * buffer (tilecodec_lossy_scratch bytes) and the zstd contexts, and falls back to a lossless
 * codec when these return 0.
 */
#ifndef CLIPMAP_TILECODEC_LOSSY_H
#define CLIPMAP_TILECODEC_LOSSY_H
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "tilecodec.h"

size_t tilecodec_lossy_scratch(uint32_t T);
/* The payload into out[0 .. cap): bytes, 0 when it cannot be done or would not be smaller
 * than cap (the caller sends the tile another way), -ENOSPC. zctx: a ZSTD_CCtx. */
ssize_t tilecodec_lossy_encode(void *zctx, unsigned char *scratch, enum pix_type f, uint32_t T,
			       enum tcodec c, const struct tilecodec_lossy_opts *o,
			       const void *texels, void *out, size_t cap);
/* Checks the payload's checksum and decodes it into texels (h->raw_len bytes). 0, -EILSEQ or
 * -EBADMSG with err. dctx: a ZSTD_DCtx. */
int tilecodec_lossy_decode(void *dctx, unsigned char *scratch, const struct tilecodec_hdr *h,
			   const void *payload, size_t n, void *texels, char err[256]);

#endif
