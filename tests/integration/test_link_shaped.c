/* test_link_shaped — clipmapd over a real shaped link (issue 15): a network namespace and a
 * veth pair made by the test (tests/support/shaped_link: a relay in a middle namespace holds
 * what the daemon sends to 1, 4 and 20 Mbit/s with 40 ms of delay and a tail-drop queue; this
 * kernel has no netem), the daemon in one namespace and the client's socket in the other.
 * After a jump (a new want-set at a place with no tile in common), what
 * a viewer notices: the new place's first tile arrives within 2 RTT + 100 ms + the
 * transmission of that new tile itself (+ LOAD_SLACK_MS for a loaded machine); the old
 * place's bytes still delivered are at most the link's rate × 150 ms (the daemon stops a
 * begun tile after the part in flight: TILE_PART, docs/PROTOCOL.md); the new place's coarsest
 * level completes; and the session's link figures in STATS (rate, RTT, queue) match the link.
 * With raw_above_mbit = 10, tiles go raw at 20 Mbit/s and zstd at 1 and 4 (compress auto).
 * At 1 Mbit/s also with the lossy codecs offered (tiles of 2-3 KB, smaller than a part).
 * The figures are printed (docs/LINKS.md has them, and the daemon's before this change).
 *
 * Skips, saying why, where namespaces cannot be made (not root, no ip).
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/net.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "support/daemon_env.h"
#include "support/shaped_link.h"

#define TOKEN "shaped-link-token"
#define DELAY_MS 40
#define LOAD_SLACK_MS 400 /* scheduling on a loaded 2-core machine; the figures are printed */

static struct daemon_env E;
static struct shaped_link L;
static char skip_why[256];

static void stop_daemon(void)
{
	daemon_env_fini(&E);
}

static int setup(void **state)
{
	(void)state;
	char err[256];
	int rc = shaped_link_init(&L, skip_why);
	if (rc == -ENOTSUP) {
		fprintf(stderr, "test_link_shaped: skipped: %s\n", skip_why);
		return 0;
	}
	if (rc) {
		fprintf(stderr, "test_link_shaped: %s\n", skip_why);
		return -1;
	}
	skip_why[0] = 0;
	shaped_link_on_fini(stop_daemon);
	const char *extra[] = { "session.raw_above_mbit = 10", NULL };
	if (shaped_link_daemon_start(&L, &E, "clipmapd-link", TOKEN, extra, err)) {
		fprintf(stderr, "test_link_shaped: %s\n", err);
		shaped_link_fini(&L);
		return -1;
	}
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	daemon_env_fini(&E);
	shaped_link_fini(&L);
	return 0;
}

/* This session's link figure FIELD from STATS (link.ID.FIELD, ID the largest: the newest
 * session); NAN when absent (a daemon without link figures). */
static double link_stat(struct net_conn *c, const char *field)
{
	struct proto_msg req = { .type = PROTO_STATS_REQ, .stats_req = { .req = net_next_req(c) } };
	struct proto_msg m = { 0 };
	char err[256];
	if (net_send(c, &req, err) || net_expect(c, PROTO_STATS, &m, 20000, NULL, NULL, err))
		fail_msg("STATS: %s", err);
	double v = NAN;
	unsigned long best = 0;
	for (uint16_t i = 0; i < m.stats.count; i++) {
		const struct proto_stat *s = &m.stats.items[i];
		unsigned long id;
		int end = 0;
		if (sscanf(s->key, "link.%lu.%n", &id, &end) != 1 || !end ||
		    strcmp(s->key + end, field) != 0 || id < best)
			continue;
		best = id;
		v = s->kind == PROTO_STAT_U64 ? (double)s->u : s->f;
	}
	proto_msg_fini(&m);
	return v;
}

/* codecs: what the client offers besides its lossless one (TCODEC_ALL_MASK: the lossy ones,
 * as clipmapview does below lossy_below_mbit) */
static void jump_at(unsigned mbit, uint32_t codecs)
{
	if (skip_why[0]) {
		fprintf(stderr, "skipped: %s\n", skip_why);
		skip();
	}
	char err[256];
	if (shaped_link_shape(&L, mbit * 1000, DELAY_MS, err))
		fail_msg("%s", err);
	uint32_t pid;
	struct net_conn *c = shaped_link_session(&L, &E, false, codecs, &pid, err);
	if (!c)
		fail_msg("%s", err);
	const struct link_jump_plan plan = { .warm_ms = 2500, .a_lmin = 2, .a_lmax = 9,
					     .a_side = 6, .b_lmin = 3, .b_lmax = 9, .b_side = 2,
					     .full = false, .deadline_ms = 30000 };
	struct link_jump_result r;
	if (link_jump_run(c, pid, &plan, &r, err))
		fail_msg("jump at %u Mbit/s: %s", mbit, err);
	double rate = mbit * 1e6, rtt = 2.0 * DELAY_MS / 2; /* delayed one way: RTT = delay */
	double tile_ms = (double)r.max_frame * 8e3 / rate;
	/* issue 15's bounds: the new place's first tile within 2 RTT + its own transmission +
	 * 100 ms (+ LOAD_SLACK_MS of scheduling on a loaded machine: printed without it); the old
	 * place's bytes after the jump at most 150 ms of the link — a tile the kernel had begun
	 * is stopped after its part in flight (TILE_PART), so no whole old tile is owed */
	double first_bound = 2 * rtt + (double)r.first_frame * 8e3 / rate + 100;
	double first_max = first_bound + LOAD_SLACK_MS;
	double stale_max = rate * 0.150 / 8;
	double est = link_stat(c, "rate_bps"), srtt = link_stat(c, "min_rtt_ms");
	double qms = link_stat(c, "queue_ms"), rtt_now = link_stat(c, "rtt_ms");
	double inflight = link_stat(c, "inflight_bytes");
	printf("link %u Mbit/s%s, %d ms: goodput before the jump %.2f Mbit/s; after the jump: first "
	       "new tile %.0f ms (bound %.0f; tiles up to %llu B = %.0f ms), coarse level %.0f ms, stale "
	       "%llu B in %llu tiles + %llu B of a tile stopped (bound %.0f); STATS rate %.2f "
	       "Mbit/s, min rtt %.1f ms, rtt %.1f ms, in flight %.0f B, queue %.0f ms\n",
	       mbit, codecs ? " (lossy tiles)" : "", DELAY_MS, r.warm_bps * 1e-6, r.first_ms, first_bound,
	       (unsigned long long)r.max_frame, tile_ms, r.coarse_ms,
	       (unsigned long long)r.stale_bytes, (unsigned long long)r.stale_tiles,
	       (unsigned long long)r.stale_cut, stale_max, est * 1e-6, srtt, rtt_now, inflight, qms);
	fflush(stdout);
	if (r.first_ms < 0)
		fail_msg("no tile of the new place within %d ms of the jump", plan.deadline_ms);
	assert_true(r.first_ms <= first_max);
	assert_true((double)r.stale_bytes <= stale_max);
	if (r.coarse_ms < 0)
		fail_msg("the new place's coarsest level did not complete in %d ms",
			 plan.deadline_ms);
	/* the link as the daemon measured it: within a factor of two of what it is */
	assert_true(est >= rate / 2 && est <= rate * 2);
	assert_true(srtt >= DELAY_MS - 1 && srtt <= DELAY_MS * 4);
	assert_true(qms >= 0 && qms < 1000);
	/* the encoding by the measured link: raw above raw_above_mbit (10), zstd below */
	printf("new place's tiles sent raw: %u of %u\n", r.b_raw, r.b_tiles);
	if (mbit > 10)
		assert_int_equal(r.b_raw, r.b_tiles);
	else
		assert_true(r.b_raw * 2 < r.b_tiles);
	/* and what an operator sees: clipmapctl status lists this session's link */
	char exe[600], out[16384];
	snprintf(exe, sizeof exe, "%s/clipmapctl", E.bindir);
	char *argv[] = { exe, "-s", E.sock, "status", NULL };
	assert_int_equal(daemon_env_run(argv, out, sizeof out), 0);
	char *line = strstr(out, L.peer_addr);
	if (!line || !strstr(line, "Mbit/s, rtt "))
		fail_msg("clipmapctl status shows no link line for %s:\n%s", L.peer_addr, out);
	printf("clipmapctl status: %.*s\n", (int)strcspn(line, "\n"), line);
	net_close(c);
}

static void test_jump_1mbit(void **state)
{
	(void)state;
	jump_at(1, 0);
}

/* Lossy tiles are smaller than a part: what the new place waits behind is what the kernel
 * holds, which BBR's packet-count floors make 150 ms and more of a 1 Mbit/s link unless the
 * daemon caps the send buffer (linkest.h, LINKEST_CAP_MS). */
static void test_jump_1mbit_lossy(void **state)
{
	(void)state;
	jump_at(1, TCODEC_ALL_MASK);
}

static void test_jump_4mbit(void **state)
{
	(void)state;
	jump_at(4, 0);
}

static void test_jump_20mbit(void **state)
{
	(void)state;
	jump_at(20, 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_jump_4mbit),
		cmocka_unit_test(test_jump_1mbit),
		cmocka_unit_test(test_jump_1mbit_lossy),
		cmocka_unit_test(test_jump_20mbit),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
