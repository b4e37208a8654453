/* test_linkest — the send window sized from a measured link (daemon/linkest.c) on real
 * sockets: a Unix socket is not measured (its window is the cap); a TCP socket gets
 * TCP_NOTSENT_LOWAT, starts at the floor, and after megabytes through loopback measures a rate
 * and an RTT, its window growing to send_queue_ms of that rate within [floor, cap]; 0 ms means
 * the cap (the old queue) and no TCP_NOTSENT_LOWAT.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <stdlib.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <linux/socket.h>
#include <unistd.h>

#include "common/clock.h"
#include "linkest.h"

/* A connected loopback TCP pair: fds[0] the accepted (server) end; mss > 0 sets the segment
 * size (loopback's own is 64 KB: a paced link of those would be measured in bursts). */
static void tcp_pair_mss(int fds[2], int mss)
{
	int l = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (mss)
		assert_int_equal(setsockopt(l, IPPROTO_TCP, TCP_MAXSEG, &mss, sizeof mss), 0);
	struct sockaddr_in sa = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t len = sizeof sa;
	assert_int_equal(bind(l, (struct sockaddr *)&sa, sizeof sa), 0);
	assert_int_equal(listen(l, 1), 0);
	assert_int_equal(getsockname(l, (struct sockaddr *)&sa, &len), 0);
	fds[1] = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (mss)
		assert_int_equal(setsockopt(fds[1], IPPROTO_TCP, TCP_MAXSEG, &mss, sizeof mss), 0);
	assert_int_equal(connect(fds[1], (struct sockaddr *)&sa, sizeof sa), 0);
	fds[0] = accept(l, NULL, NULL);
	assert_true(fds[0] >= 0);
	close(l);
}

static void tcp_pair(int fds[2])
{
	tcp_pair_mss(fds, 0);
}

/* Sends total bytes from fds[0] to fds[1] through loopback, the reader draining as it goes
 * (le, when not NULL, sampled on the way); returns the bytes received (total unless 20 s
 * passed). */
static uint64_t stream(int fds[2], uint64_t total, struct linkest *le)
{
	static uint8_t buf[1 << 16];
	uint64_t sent = 0, got = 0, end = clock_now_ns() + 20000000000ull;
	while (got < total && clock_now_ns() < end) {
		struct pollfd pf[2] = { { .fd = fds[0], .events = sent < total ? POLLOUT : 0 },
					{ .fd = fds[1], .events = POLLIN } };
		assert_true(poll(pf, 2, 1000) >= 0);
		if (pf[0].revents & POLLOUT) {
			size_t want = total - sent < sizeof buf ? (size_t)(total - sent) : sizeof buf;
			ssize_t n = send(fds[0], buf, want, MSG_DONTWAIT);
			if (n > 0)
				sent += (uint64_t)n;
		}
		if (pf[1].revents & POLLIN) {
			ssize_t n = recv(fds[1], buf, sizeof buf, MSG_DONTWAIT);
			if (n > 0)
				got += (uint64_t)n;
		}
		if (le)
			linkest_sample(le, clock_now_ns(), false);
	}
	return got;
}

static void test_unix_not_measured(void **state)
{
	(void)state;
	int sv[2];
	assert_int_equal(socketpair(AF_UNIX, SOCK_STREAM, 0, sv), 0);
	struct linkest le;
	linkest_init(&le, sv[0], false, true, true, clock_now_ns());
	linkest_sample(&le, clock_now_ns(), true);
	assert_int_equal(linkest_window(&le, 100, 8u << 20), 8u << 20);
	assert_true(linkest_delay_ms(&le, 1u << 20) == 0.0);
	assert_int_equal(le.rate, 0);
	close(sv[0]);
	close(sv[1]);
}

static void test_tcp_measured(void **state)
{
	(void)state;
	int fds[2];
	tcp_pair(fds);
	struct linkest le;
	linkest_init(&le, fds[0], true, true, true, clock_now_ns());
	int v = 0;
	socklen_t vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], IPPROTO_TCP, TCP_NOTSENT_LOWAT, &v, &vl), 0);
	assert_int_equal(v, LINKEST_LOWAT_MIN);
	/* nothing measured yet: the floor, or the cap when it is lower, or the cap with 0 ms */
	assert_int_equal(linkest_window(&le, 100, 8u << 20), LINKEST_FLOOR);
	assert_int_equal(linkest_window(&le, 100, 16u << 10), 16u << 10);
	assert_int_equal(linkest_window(&le, 0, 8u << 20), 8u << 20);
	/* 32 MiB through loopback, the reader draining as it goes */
	assert_int_equal(stream(fds, 32u << 20, &le), 32u << 20);
	linkest_sample(&le, clock_now_ns(), true);
	/* loopback: far faster than 10 Mbit/s; an RTT under a second */
	assert_true(le.rate > 10000000u / 8);
	assert_true(le.rtt_us > 0 && le.rtt_us < 1000000u);
	assert_true(le.min_rtt_us > 0 && le.min_rtt_us <= le.rtt_us * 2);
	uint64_t w = linkest_window(&le, 100, 64u << 20);
	uint64_t want = le.rate / 1000 * 100;
	assert_int_equal(w, want < LINKEST_FLOOR ? LINKEST_FLOOR : want > (64u << 20) ? 64u << 20 : want);
	assert_int_equal(linkest_window(&le, 100, 1u << 20), w < (1u << 20) ? w : 1u << 20);
	/* the delay of a queue at that rate */
	double d = linkest_delay_ms(&le, le.rate);
	assert_true(d > 999.0 && d < 1001.0);
	/* TCP_NOTSENT_LOWAT followed the rate: 10 ms of it, within its bounds */
	vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], IPPROTO_TCP, TCP_NOTSENT_LOWAT, &v, &vl), 0);
	uint64_t lw = le.rate * LINKEST_LOWAT_MS / 1000;
	lw = lw < LINKEST_LOWAT_MIN ? LINKEST_LOWAT_MIN : lw > LINKEST_LOWAT_MAX ? LINKEST_LOWAT_MAX : lw;
	assert_true((uint64_t)v * 5 >= lw * 4 && (uint64_t)v * 4 <= lw * 5);
	close(fds[0]);
	close(fds[1]);
}

/* The slow-link cap: below LINKEST_CAP_BELOW the send buffer is held to the rate's BDP and
 * LINKEST_CAP_MS more, once the link was measured; rises of a sixteenth are followed, falls of
 * a quarter; a link found faster (1.25 × the threshold) goes back to the kernel's autotuning.
 * (Loopback cannot be made slow enough to be measured as a slow link — paced, its delivery
 * samples still see microsecond RTTs — so the rate is set here; test_link_shaped measures a
 * real slow link end to end.) */
static void test_slow_cap(void **state)
{
	(void)state;
	/* the arithmetic: 1 Mbit/s with 40 ms is 5 KB a BDP, the cap LINKEST_CAP_MS more */
	assert_int_equal(linkest_cap(125000, 40000), 125000u * (40 + LINKEST_CAP_MS) / 1000);
	assert_int_equal(linkest_cap(0, 40000), 0);
	assert_int_equal(linkest_cap(LINKEST_CAP_BELOW, 40000), 0);
	assert_int_equal(linkest_cap(LINKEST_CAP_BELOW - 1, 40000),
			 (uint64_t)(LINKEST_CAP_BELOW - 1) * (40 + LINKEST_CAP_MS) / 1000);
	assert_int_equal(linkest_cap(1000, 40000), LINKEST_CAP_MIN);
	/* no RTT (or the kernel's ~0 "none yet", or one past belief): no cap */
	assert_int_equal(linkest_cap(125000, 0), 0);
	assert_int_equal(linkest_cap(125000, ~0u), 0);
	assert_int_equal(linkest_cap(LINKEST_CAP_BELOW - 1, LINKEST_CAP_RTT_MAX),
			 (uint64_t)(LINKEST_CAP_BELOW - 1) * (LINKEST_CAP_RTT_MAX + LINKEST_CAP_MS * 1000) /
				 1000000);
	int fds[2];
	tcp_pair(fds);
	struct linkest le;
	linkest_init(&le, fds[0], true, true, false, clock_now_ns());
	int v = 0;
	socklen_t vl = sizeof v;
	/* 1 Mbit/s, 40 ms, but only ever application-limited samples: not capped */
	le.rate = 125000;
	le.min_rtt_us = 40000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, 0);
	assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_BUF_LOCK, &v, &vl), 0);
	assert_int_equal(v & SOCK_SNDBUF_LOCK, 0);
	/* measured: capped */
	le.measured = true;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(125000, 40000));
	vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_SNDBUF, &v, &vl), 0);
	assert_int_equal(v, 2 * (int)le.sndbuf); /* the kernel doubles what it is asked */
	/* a rise of less than a sixteenth is left, more is followed; a fall of less than a
	 * quarter is left, more is followed */
	le.rate = 128000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(125000, 40000));
	le.rate = 140000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(140000, 40000));
	le.rate = 120000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(140000, 40000));
	le.rate = 100000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(100000, 40000));
	vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_SNDBUF, &v, &vl), 0);
	assert_int_equal(v, 2 * (int)le.sndbuf);
	/* just over the threshold: still capped, at the threshold's cap (no flapping) */
	le.rate = LINKEST_CAP_BELOW + 1000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(LINKEST_CAP_BELOW - 1, 40000));
	/* 1.25 × the threshold: back to the kernel's own (the lock let go) */
	le.rate = LINKEST_CAP_BELOW * 5 / 4;
	linkest_set_cap(&le);
	assert_true(le.sndbuf == 0 || le.sndbuf == LINKEST_UNCAPPED);
	vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_BUF_LOCK, &v, &vl), 0);
	if (le.sndbuf == 0) {
		assert_int_equal(v & SOCK_SNDBUF_LOCK, 0);
		/* and the kernel grows it again: 8 MiB through loopback, the reader draining */
		int small = 0, grown = 0;
		vl = sizeof small;
		assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_SNDBUF, &small, &vl), 0);
		assert_int_equal(stream(fds, 8u << 20, NULL), 8u << 20);
		vl = sizeof grown;
		assert_int_equal(getsockopt(fds[0], SOL_SOCKET, SO_SNDBUF, &grown, &vl), 0);
		printf("let go: SO_SNDBUF %d while capped, %d after 8 MiB\n", small, grown);
		assert_true(grown > small);
	}
	/* and capped again if it turns slow */
	le.rate = 125000;
	linkest_set_cap(&le);
	assert_int_equal(le.sndbuf, linkest_cap(125000, 40000));
	close(fds[0]);
	close(fds[1]);
}

/* send_queue_ms 0: the kernel's default stays (no TCP_NOTSENT_LOWAT) and the window is the cap. */
static void test_tcp_unshaped(void **state)
{
	(void)state;
	int fds[2];
	tcp_pair(fds);
	int before = 0, v = 0;
	socklen_t vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], IPPROTO_TCP, TCP_NOTSENT_LOWAT, &before, &vl), 0);
	struct linkest le;
	linkest_init(&le, fds[0], true, false, false, clock_now_ns());
	vl = sizeof v;
	assert_int_equal(getsockopt(fds[0], IPPROTO_TCP, TCP_NOTSENT_LOWAT, &v, &vl), 0);
	assert_int_equal(v, before);
	assert_int_equal(linkest_window(&le, 0, 8u << 20), 8u << 20);
	close(fds[0]);
	close(fds[1]);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_unix_not_measured),
		cmocka_unit_test(test_tcp_measured),
		cmocka_unit_test(test_tcp_unshaped),
		cmocka_unit_test(test_slow_cap),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
