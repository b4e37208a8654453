/* fuzz_proto — libFuzzer target for the protocol decoder and the tile payload decoder.
 * Not built by the Makefile's normal rules. Build and run (from the repository root):
 *
 *   clang -std=c11 -D_GNU_SOURCE -g -O1 -fsanitize=fuzzer,address,undefined \
 *     -fno-sanitize-recover=all -Icommon -Idaemon tests/fuzz/fuzz_proto.c common/proto.c \
 *     common/proto_write.c common/tilecodec.c common/grid.c common/xalloc.c \
 *     $(pkg-config --libs libzstd liblz4 libxxhash) -lm -o build/fuzz_proto
 *   mkdir -p build/fuzz-corpus && build/fuzz_proto -max_total_time=60 build/fuzz-corpus
 *
 * Properties checked, beyond "no crash, no leak, no undefined behaviour":
 *  - the input is consumed as a stream of frames, as a socket reader would: a frame that
 *    decodes re-encodes to exactly the same bytes (the codec is canonical, nothing dropped);
 *  - feeding the same bytes in two pieces gives the same answer as feeding them whole;
 *  - a decoded TILE's payload goes through tilecodec_decode, which must never overrun.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "common/proto.h"
#include "common/tilecodec.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static void check_tile(const struct proto_tile *t)
{
	static struct tilecodec *tc; /* fuzzer-only: reused across inputs */
	if (!tc)
		tc = tilecodec_create();
	if (t->enc.raw_len > (256u << 10))
		return; /* keep each run fast */
	void *out = malloc(t->enc.raw_len ? t->enc.raw_len : 1);
	char err[256];
	int rc = tilecodec_decode(tc, &t->enc, t->payload, t->payload_len, out, t->enc.raw_len,
				  err);
	if (rc != 0 && rc != -EBADMSG && rc != -EILSEQ && rc != -EINVAL)
		abort();
	free(out);
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
	size_t off = 0;
	while (off < size) {
		struct proto_msg m;
		size_t need = 0;
		char err[256];
		ssize_t n = proto_decode(data + off, size - off, &m, &need, err);
		if (n == 0 && need == 0)
			abort(); /* "need more" must say how much */
		if (n <= 0)
			break;
		/* split feed: the first half alone must ask for more (or fail the same way) */
		struct proto_msg half;
		size_t need2 = 0;
		ssize_t h = proto_decode(data + off, (size_t)n / 2, &half, &need2, NULL);
		if (h > 0 || (h == 0 && need2 == 0))
			abort();
		proto_msg_fini(&half);

		struct pbuf b;
		pbuf_init(&b);
		ssize_t e = proto_encode(&b, &m, err);
		if (e != n || memcmp(b.data, data + off, (size_t)n) != 0)
			abort();
		pbuf_fini(&b);
		if (m.type == PROTO_TILE)
			check_tile(&m.tile);
		proto_msg_fini(&m);
		off += (size_t)n;
	}
	return 0;
}
