/* net_stat — one STATS value from a running daemon over client/net.h, for tests that check
 * the daemon's counters (store.*, sched.*). Test-only code. */
#ifndef CLIPMAP_TEST_NET_STAT_H
#define CLIPMAP_TEST_NET_STAT_H
#include <stdint.h>

struct net_conn;

/* Sends STATS_REQ on c and stores key's value (u64) in *out. Returns 0, -ENOENT (no such key:
 * err says which), or -errno from the connection (err filled). */
int net_stat_u64(struct net_conn *c, const char *key, uint64_t *out, char err[256]);

#endif
