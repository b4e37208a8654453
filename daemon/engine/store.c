/* store — see store.h. The value format, little-endian:
 *
 *   0  magic "CMS1"          4  version u8 (1), format u8, codec u8, filter u8
 *   8  size u32 (T)         12  raw_len u32        16  payload_len u32     20  reserved u32 (0)
 *  24  texels' XXH3-64 (the tile codec's checksum)
 *  32  value checksum: XXH3-64 of bytes [0, 32), then the 18 key bytes, then the payload
 *  40  payload (the tile codec's output)
 *
 * The value checksum binds the value to its key (an entry copied under another key is caught)
 * and is checked before anything is decoded. A value that passes it holds the bytes that
 * were written, so the texels' own checksum is not computed again on a read (an XXH3 pass
 * over 128–256 KiB per tile: with the value checksum, 5 % of a restarted flight's samples);
 * it stays in the header.
 */
#include "store.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#define XXH_STATIC_LINKING_ONLY /* XXH3_state_t on the stack */
#include <xxhash.h>

#include "common/tilecodec.h"
#include "common/xalloc.h"
#include "node.h"
#include "planet.h"

#define MAGIC 0x31534d43u /* "CMS1" little-endian */
#define VERSION 1

void store_destroy(struct store *s)
{
	if (s)
		s->ops->destroy(s);
}

int store_open_file(const char *path, uint32_t mb, struct store **out, char err[256])
{
	return store_lmdb_open(&(struct store_lmdb_desc){
				       .path = path, .budget = (uint64_t)(mb ? mb : 1024) << 20 },
			       out, err);
}

void store_summary(struct store *s, char *line, size_t n)
{
	struct store_stats st;
	store_flush(s);
	store_stat(s, &st);
	snprintf(line, n, "%llu hits, %llu misses, %llu tiles written, %llu corrupt; %llu tiles in it",
		 (unsigned long long)st.hits, (unsigned long long)st.misses,
		 (unsigned long long)st.puts, (unsigned long long)st.corrupt,
		 (unsigned long long)st.tiles);
}

bool store_keeps(const struct node *n)
{
	const struct planet *p = n->planet;
	for (size_t i = 0; p && i < p->nlayers; i++)
		if (p->layers[i].node == n)
			return true;
	return false;
}

static void put_be64(uint8_t *p, uint64_t v)
{
	for (int i = 7; i >= 0; i--, v >>= 8)
		p[i] = (uint8_t)v;
}
static void put_be32(uint8_t *p, uint32_t v)
{
	for (int i = 3; i >= 0; i--, v >>= 8)
		p[i] = (uint8_t)v;
}
static uint64_t get_be64(const uint8_t *p)
{
	uint64_t v = 0;
	for (int i = 0; i < 8; i++)
		v = v << 8 | p[i];
	return v;
}
static uint32_t get_be32(const uint8_t *p)
{
	return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}
static void put_le32(uint8_t *p, uint32_t v)
{
	for (int i = 0; i < 4; i++, v >>= 8)
		p[i] = (uint8_t)v;
}
static void put_le64(uint8_t *p, uint64_t v)
{
	for (int i = 0; i < 8; i++, v >>= 8)
		p[i] = (uint8_t)v;
}
static uint32_t get_le32(const uint8_t *p)
{
	return (uint32_t)p[3] << 24 | (uint32_t)p[2] << 16 | (uint32_t)p[1] << 8 | p[0];
}
static uint64_t get_le64(const uint8_t *p)
{
	uint64_t v = 0;
	for (int i = 7; i >= 0; i--)
		v = v << 8 | p[i];
	return v;
}

void store_key_encode(const struct tile_key *k, uint8_t out[STORE_KEY_LEN])
{
	put_be64(out, k->node);
	out[8] = k->lx;
	out[9] = k->ly;
	put_be32(out + 10, k->x);
	put_be32(out + 14, k->y);
}

int store_key_decode(const void *p, size_t n, struct tile_key *k)
{
	if (n != STORE_KEY_LEN)
		return -EINVAL;
	const uint8_t *b = p;
	*k = (struct tile_key){ .node = get_be64(b), .lx = b[8], .ly = b[9],
				.x = get_be32(b + 10), .y = get_be32(b + 14) };
	return 0;
}

static uint64_t value_sum(const uint8_t *hdr, const uint8_t kb[STORE_KEY_LEN],
			  const uint8_t *payload, size_t n)
{
	XXH3_state_t st;
	XXH3_64bits_reset(&st);
	XXH3_64bits_update(&st, hdr, 32);
	XXH3_64bits_update(&st, kb, STORE_KEY_LEN);
	XXH3_64bits_update(&st, payload, n);
	return XXH3_64bits_digest(&st);
}

void store_value_encode(struct tilecodec *tc, const struct tile *t, enum tcodec codec, int level,
			void **out, size_t *n)
{
	if (codec != TCODEC_LZ4)
		codec = TCODEC_ZSTD;
	size_t cap = STORE_HDR_LEN + tilecodec_bound(codec, t->nbytes);
	uint8_t *v = xmalloc(cap);
	struct tilecodec_hdr h;
	ssize_t len = tilecodec_encode(tc, t->type, t->size, codec,
				       tilecodec_default_filter(t->type), level ? level : 3, t->data,
				       &h, v + STORE_HDR_LEN, cap - STORE_HDR_LEN);
	/* Only programmer errors make encoding fail: a published tile is always valid. */
	if (len < 0)
		abort();
	put_le32(v, MAGIC);
	v[4] = VERSION;
	v[5] = h.format;
	v[6] = h.codec;
	v[7] = h.filter;
	put_le32(v + 8, h.size);
	put_le32(v + 12, h.raw_len);
	put_le32(v + 16, (uint32_t)len);
	put_le32(v + 20, 0);
	put_le64(v + 24, h.checksum);
	uint8_t kb[STORE_KEY_LEN];
	store_key_encode(&t->key, kb);
	put_le64(v + 32, value_sum(v, kb, v + STORE_HDR_LEN, (size_t)len));
	*out = v;
	*n = STORE_HDR_LEN + (size_t)len;
}

int store_value_check(const uint8_t kb[STORE_KEY_LEN], const void *vp, size_t n)
{
	const uint8_t *v = vp;
	if (n < STORE_HDR_LEN || get_le32(v) != MAGIC || v[4] != VERSION ||
	    get_le32(v + 16) != n - STORE_HDR_LEN ||
	    get_le64(v + 32) != value_sum(v, kb, v + STORE_HDR_LEN, n - STORE_HDR_LEN))
		return -EBADMSG;
	struct tilecodec_hdr h = { .format = v[5], .codec = v[6], .filter = v[7],
				   .size = get_le32(v + 8), .raw_len = get_le32(v + 12),
				   .checksum = get_le64(v + 24) };
	return tilecodec_hdr_check(&h, NULL) ? -EBADMSG : 0;
}

int store_value_decode(struct tilecodec *tc, const uint8_t kb[STORE_KEY_LEN], const void *vp,
		       size_t n, const struct tile_key *k, enum pix_type type, uint32_t size,
		       struct tile **out)
{
	*out = NULL;
	const uint8_t *v = vp;
	if (n < STORE_HDR_LEN || get_le32(v) != MAGIC || v[4] != VERSION ||
	    get_le32(v + 16) != n - STORE_HDR_LEN ||
	    get_le64(v + 32) != value_sum(v, kb, v + STORE_HDR_LEN, n - STORE_HDR_LEN))
		return -EBADMSG;
	struct tilecodec_hdr h = { .format = v[5], .codec = v[6], .filter = v[7],
				   .size = get_le32(v + 8), .raw_len = get_le32(v + 12),
				   .checksum = get_le64(v + 24) };
	if (tilecodec_hdr_check(&h, NULL))
		return -EBADMSG;
	if (h.format != (uint8_t)type || h.size != size)
		return -ENOENT;
	struct tile *t = tile_create(k, type, size);
	if (t->nbytes != h.raw_len ||
	    tilecodec_decode_trusted(tc, &h, v + STORE_HDR_LEN, n - STORE_HDR_LEN, t->data,
				     t->nbytes, NULL)) {
		tile_unref(t);
		return -EBADMSG;
	}
	*out = t;
	return 0;
}
