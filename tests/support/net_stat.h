/* net_stat — one STATS value from a running daemon over client/net.h, for tests that check
 * the daemon's counters (store.*, sched.*), and a block of wanted tiles to ask it for.
 * Test-only code. */
#ifndef CLIPMAP_TEST_NET_STAT_H
#define CLIPMAP_TEST_NET_STAT_H
#include <stdint.h>

struct net_conn;

/* Sends STATS_REQ on c and stores key's value (u64) in *out. Returns 0, -ENOENT (no such key:
 * err says which), or -errno from the connection (err filled). */
int net_stat_u64(struct net_conn *c, const char *key, uint64_t *out, char err[256]);

/* Polls key (every 20 ms, at most timeout_ms) until it reads 0, e.g. store.disk.queued: the
 * store's writer has committed everything queued. Returns 0, -ETIMEDOUT (err says the last
 * value) or what net_stat_u64 returns. */
int net_stat_wait_zero(struct net_conn *c, const char *key, int timeout_ms, char err[256]);

struct proto_want_entry;

/* Appends to w[n ..] (at most cap entries in all) both layers of every tile of level
 * (ly + 1, ly) in [x0, x0 + wd) × [y0, y0 + h), x wrapping; VISIBLE class. Returns the new n. */
uint32_t net_want_block(struct proto_want_entry *w, uint32_t n, uint32_t cap, int ly,
			uint32_t x0, uint32_t y0, uint32_t wd, uint32_t h);

#endif
