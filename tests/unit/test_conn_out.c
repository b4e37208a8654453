/* test_conn_out — a connection's output queue (daemon/conn.c) with shared encodings
 * (daemon/encq.c) on a real socket with a small send buffer: messages and TILE frames go out
 * in the order queued, byte for byte what proto_encode makes of them, nothing after a TILE
 * whose encoding is still under way, partial writes resumed anywhere (in a header, in a
 * payload); the pending count ends at zero; a recall takes out the TILE frames not yet begun
 * and never the one the socket has begun; the same encoding is shared (one encoding for two
 * requests) and an encoding outlives the cache that made it while a queue refers to it. Tiles
 * in parts (TILE_PART): the frames proto_encode makes of each part, in order, and a recall
 * that stops a begun tile after the part the socket has begun.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include "common/proto.h"
#include "common/tilecodec.h"
#include "conn.h"
#include "encq.h"

static void no_wake(struct session *s)
{
	(void)s;
}

/* A Unix stream pair: fds[0] non-blocking with a small send buffer (the daemon's end). */
static void pair(int fds[2])
{
	assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds), 0);
	int small = 4096;
	assert_int_equal(setsockopt(fds[0], SOL_SOCKET, SO_SNDBUF, &small, sizeof small), 0);
	assert_int_equal(fcntl(fds[0], F_SETFL, O_NONBLOCK), 0);
}

static struct tile *make_tile(uint32_t x, uint8_t seed)
{
	struct tile_key k = { .node = 77, .lx = 6, .ly = 5, .x = x, .y = 3 };
	struct tile *t = tile_create(&k, PIX_COLOR, 64);
	for (size_t i = 0; i < t->nbytes; i++)
		t->data[i] = (uint8_t)((i / 4 % 64) * seed + (i % 4)); /* compressible */
	return t;
}

/* Waits for the encoders and drains until e is ready. */
static void wait_ready(struct encq *q, struct etile *e)
{
	for (int i = 0; i < 1000 && !e->ready; i++) {
		struct pollfd pf = { .fd = encq_fd(q), .events = POLLIN };
		(void)poll(&pf, 1, 20);
		encq_drain(q);
	}
	assert_true(e->ready);
	assert_int_equal(e->err, 0);
}

static void put_msg(struct conn *c, uint32_t req)
{
	struct proto_msg m = { .type = PROTO_ERROR,
			       .error = { .code = PROTO_E_LIMIT, .ref_id = req, .message = "m" } };
	assert_true(proto_encode(conn_msg_begin(c), &m, NULL) > 0);
	conn_msg_end(c);
}

static void expect_msg(struct pbuf *b, uint32_t req)
{
	struct proto_msg m = { .type = PROTO_ERROR,
			       .error = { .code = PROTO_E_LIMIT, .ref_id = req, .message = "m" } };
	assert_true(proto_encode(b, &m, NULL) > 0);
}

static struct proto_tile tile_fields(uint32_t seq, const struct tile *t)
{
	return (struct proto_tile){ .seq = seq, .planet_id = 2, .layer = 1, .key = t->key };
}

static void expect_tile(struct pbuf *b, uint32_t seq, const struct tile *t, const struct etile *e)
{
	struct proto_msg m = { .type = PROTO_TILE, .tile = tile_fields(seq, t) };
	m.tile.enc = e->enc;
	m.tile.payload = e->payload;
	m.tile.payload_len = e->len;
	assert_true(proto_encode(b, &m, NULL) > 0);
}

/* Flushes c until nothing is pending, each call capped at a different byte count (the
 * server's per-iteration write budget), reading the peer meanwhile into got. */
static uint64_t pump_out(struct conn *c, int peer, struct pbuf *got)
{
	uint64_t sent = 0;
	for (int i = 0; i < 100000 && conn_pending(c); i++) {
		uint64_t was = sent;
		size_t cap = i % 5 == 4 ? SIZE_MAX : 1 + (size_t)i * 7919 % 70000;
		assert_int_equal(conn_flush(c, &sent, cap), 0);
		assert_true(sent - was <= cap);
		pbuf_reserve(got, 1000); /* small reads: partial frames on both sides */
		ssize_t n = recv(peer, got->data + got->len, 1000, MSG_DONTWAIT);
		if (n > 0)
			got->len += (size_t)n;
	}
	for (;;) {
		pbuf_reserve(got, 65536);
		ssize_t n = recv(peer, got->data + got->len, 65536, MSG_DONTWAIT);
		if (n <= 0)
			break;
		got->len += (size_t)n;
	}
	return sent;
}

static void test_order_bytes_and_waiting(void **state)
{
	(void)state;
	int fds[2];
	pair(fds);
	struct encq *q;
	assert_int_equal(encq_create(2, 1u << 20, no_wake, &q), 0);
	struct tile *t1 = make_tile(1, 3), *t2 = make_tile(2, 5);
	struct conn c;
	conn_init(&c, fds[0]);

	put_msg(&c, 1);
	struct etile *e1 = encq_get(q, t1, TCODEC_NONE, NULL, NULL);
	struct etile *e2 = encq_get(q, t2, TCODEC_ZSTD, NULL, NULL);
	struct etile *e2b = encq_get(q, t2, TCODEC_ZSTD, NULL, NULL); /* the same encoding */
	assert_ptr_equal(e2, e2b);
	struct proto_tile f1 = tile_fields(5, t1), f2 = tile_fields(6, t2);
	conn_put_tile(&c, e1, &f1, 0);
	conn_put_tile(&c, e2, &f2, 0);
	conn_put_tile(&c, e2b, &f2, 0);
	put_msg(&c, 2);
	etile_unref(e2b);
	/* before any encoding is ready: the first message only */
	uint64_t sent = 0;
	if (!e1->ready) {
		assert_int_equal(conn_flush(&c, &sent, SIZE_MAX), 0);
		assert_true(sent <= 64);
	}
	wait_ready(q, e1);
	wait_ready(q, e2);
	struct encq_stats st;
	encq_stats(q, &st);
	assert_int_equal(st.encoded, 2);
	assert_int_equal(st.shared, 1);
	assert_int_equal(e2->enc.codec, TCODEC_ZSTD);
	assert_true(e2->len < t2->nbytes);
	assert_ptr_equal(e1->payload, t1->data); /* `none`: the tile's own texels */

	/* a spent budget writes nothing and keeps the output waiting (EPOLLOUT) */
	uint64_t none = 0;
	assert_int_equal(conn_flush(&c, &none, 0), 0);
	assert_int_equal(none, 0);
	assert_true(c.want_out);
	struct pbuf got, want;
	pbuf_init(&got);
	pbuf_init(&want);
	sent += pump_out(&c, fds[1], &got);
	expect_msg(&want, 1);
	expect_tile(&want, 5, t1, e1);
	expect_tile(&want, 6, t2, e2);
	expect_tile(&want, 6, t2, e2);
	expect_msg(&want, 2);
	assert_int_equal(got.len, want.len);
	assert_memory_equal(got.data, want.data, want.len);
	assert_int_equal(sent, want.len);
	assert_int_equal(conn_pending(&c), 0);
	assert_false(c.want_out);

	/* the cache goes first; the queue's references keep nothing dangling */
	conn_put_tile(&c, e2, &f2, 0);
	size_t f2len = PROTO_HDR + 44 + e2->len;
	etile_unref(e1);
	etile_unref(e2);
	encq_destroy(q);
	pbuf_fini(&got);
	pbuf_init(&got);
	pump_out(&c, fds[1], &got);
	assert_int_equal(got.len, f2len);
	struct proto_msg m = { 0 };
	size_t need;
	assert_int_equal(proto_decode(got.data, got.len, &m, &need, NULL), (ssize_t)got.len);
	assert_int_equal(m.type, PROTO_TILE);
	proto_msg_fini(&m);

	conn_close(&c);
	conn_fini(&c);
	close(fds[1]);
	tile_unref(t1);
	tile_unref(t2);
	pbuf_fini(&got);
	pbuf_fini(&want);
}

/* Closes the connection and its peer, and lets go of n tiles, their encodings and q. */
static void finish(struct conn *c, int peer, struct tile **t, struct etile **e, int n,
		   struct encq *q)
{
	conn_close(c);
	conn_fini(c);
	close(peer);
	for (int i = 0; i < n; i++) {
		etile_unref(e[i]);
		tile_unref(t[i]);
	}
	encq_destroy(q);
}

static bool drop_all(void *ud, const struct tile_key *k)
{
	(void)k;
	(*(int *)ud)++;
	return true;
}

static void test_recall(void **state)
{
	(void)state;
	int fds[2];
	pair(fds);
	struct encq *q;
	assert_int_equal(encq_create(1, 1u << 20, no_wake, &q), 0);
	struct tile *t[3];
	struct etile *e[3];
	struct conn c;
	conn_init(&c, fds[0]);
	for (int i = 0; i < 3; i++) {
		t[i] = make_tile((uint32_t)i + 10, (uint8_t)(i + 2));
		e[i] = encq_get(q, t[i], TCODEC_NONE, NULL, NULL);
		wait_ready(q, e[i]);
		struct proto_tile f = tile_fields(9, t[i]);
		conn_put_tile(&c, e[i], &f, 0);
	}
	uint64_t frame = PROTO_HDR + 44 + t[0]->nbytes;
	assert_int_equal(conn_pending(&c), 3 * frame);
	/* the peer does not read: the socket takes part of the first frame only */
	uint64_t sent = 0;
	assert_int_equal(conn_flush(&c, &sent, SIZE_MAX), 0);
	assert_true(sent > 0 && sent < frame);
	int asked = 0;
	uint64_t bytes = 0;
	assert_int_equal(conn_recall(&c, drop_all, &asked, &bytes), 2);
	assert_int_equal(bytes, 2 * frame);
	assert_int_equal(conn_pending(&c), frame - sent);
	struct pbuf got;
	pbuf_init(&got);
	sent += pump_out(&c, fds[1], &got);
	assert_int_equal(got.len, frame); /* the begun frame, whole */
	assert_int_equal(sent, frame);
	struct proto_msg m = { 0 };
	size_t need;
	assert_int_equal(proto_decode(got.data, got.len, &m, &need, NULL), (ssize_t)frame);
	assert_int_equal(m.tile.key.x, 10);
	assert_memory_equal(m.tile.payload, t[0]->data, t[0]->nbytes);
	proto_msg_fini(&m);
	finish(&c, fds[1], t, e, 3, q);
	pbuf_fini(&got);
}

/* The TILE_PART frames of t's payload (e) in parts of P bytes, from part i0 to i1 − 1. */
static void expect_parts(struct pbuf *b, uint32_t seq, const struct tile *t,
			 const struct etile *e, uint32_t P, uint32_t i0, uint32_t i1)
{
	struct proto_tile f = tile_fields(seq, t);
	f.enc = e->enc;
	f.payload = e->payload;
	f.payload_len = e->len;
	for (uint32_t i = i0; i < i1; i++) {
		uint32_t off = i * P, n = e->len - off < P ? e->len - off : P;
		struct proto_msg m = { .type = PROTO_TILE_PART,
				       .tile_part = { .offset = off, .total = e->len,
						      .bytes = e->payload + off, .len = n } };
		if (!off)
			m.tile_part.tile = f;
		assert_true(proto_encode(b, &m, NULL) > 0);
	}
}

static void test_parts(void **state)
{
	(void)state;
	int fds[2];
	pair(fds);
	struct encq *q;
	assert_int_equal(encq_create(1, 1u << 20, no_wake, &q), 0);
	enum { P = 3000 }; /* 16 KiB tiles: five parts of 3000 and one of 1384 */
	struct tile *t[3];
	struct etile *e[3];
	struct conn c;
	conn_init(&c, fds[0]);
	for (int i = 0; i < 3; i++) {
		t[i] = make_tile((uint32_t)i + 20, (uint8_t)(i + 3));
		e[i] = encq_get(q, t[i], TCODEC_NONE, NULL, NULL);
		wait_ready(q, e[i]);
	}
	/* all of it goes out: a message between the tiles, a tile that fits one part whole */
	struct proto_tile f0 = tile_fields(4, t[0]), f1 = tile_fields(4, t[1]);
	conn_put_tile(&c, e[0], &f0, P);
	put_msg(&c, 3);
	conn_put_tile(&c, e[1], &f1, P);
	conn_put_tile(&c, e[1], &f1, 1u << 20);
	struct pbuf got, want;
	pbuf_init(&got);
	pbuf_init(&want);
	uint64_t sent = pump_out(&c, fds[1], &got);
	uint32_t np = (t[0]->nbytes + P - 1) / P;
	expect_parts(&want, 4, t[0], e[0], P, 0, np);
	expect_msg(&want, 3);
	expect_parts(&want, 4, t[1], e[1], P, 0, np);
	expect_tile(&want, 4, t[1], e[1]);
	assert_int_equal(got.len, want.len);
	assert_memory_equal(got.data, want.data, want.len);
	assert_int_equal(sent, want.len);
	assert_int_equal(conn_pending(&c), 0);

	/* the peer does not read: a recall stops the begun tile after its part in flight */
	for (int i = 0; i < 3; i++) {
		struct proto_tile f = tile_fields(5, t[i]);
		conn_put_tile(&c, e[i], &f, P);
	}
	sent = 0;
	assert_int_equal(conn_flush(&c, &sent, SIZE_MAX), 0);
	uint64_t h0 = PROTO_HDR + PROTO_PART_FIRST_HEAD, h = PROTO_HDR + PROTO_PART_HEAD;
	uint64_t frames = h0 + (np - 1) * h + t[0]->nbytes;
	assert_true(sent > 0 && sent < frames);
	/* the part the socket has begun: the first whose end is past `sent` */
	uint32_t k = 1;
	while (h0 + P + (k - 1) * (h + P) < sent)
		k++;
	uint64_t cut = h0 + P + (k - 1) * (h + P);
	int asked = 0;
	uint64_t bytes = 0;
	assert_int_equal(conn_recall(&c, drop_all, &asked, &bytes), 3);
	assert_int_equal(conn_pending(&c), cut - sent);
	assert_int_equal(bytes, frames - cut + 2 * frames);
	pbuf_fini(&got);
	pbuf_init(&got);
	sent += pump_out(&c, fds[1], &got);
	pbuf_fini(&want);
	pbuf_init(&want);
	expect_parts(&want, 5, t[0], e[0], P, 0, k);
	assert_int_equal(got.len, cut);
	assert_int_equal(sent, cut);
	assert_memory_equal(got.data, want.data, want.len);
	assert_int_equal(conn_pending(&c), 0);
	assert_false(c.want_out);

	finish(&c, fds[1], t, e, 3, q);
	pbuf_fini(&got);
	pbuf_fini(&want);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_order_bytes_and_waiting),
		cmocka_unit_test(test_recall),
		cmocka_unit_test(test_parts),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
