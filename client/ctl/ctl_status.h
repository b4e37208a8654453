/* ctl_status — `clipmapctl status`: asks for STATS and prints them as an aligned table (or
 * JSON). Keys are shown as the daemon names them, grouped by their first dotted component;
 * a few are made readable (durations, byte sizes, the cache hit ratio) and keys of the form
 * node.NAME.FIELD become one table row per node. Unknown keys are shown as they come.
 * Thread-safety: none needed (no state). Output goes to the caller's FILE.
 */
#ifndef CLIPMAP_CTL_STATUS_H
#define CLIPMAP_CTL_STATUS_H
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "client/net.h"

/* Prints the stats of a STATS message: a table, or with json one JSON object of the keys
 * (u64 and f64 as numbers, strings as strings, plus "cache.hit_ratio" when hits and misses
 * are there). peer (may be NULL) heads the table. Returns 0 or -EIO (write error). */
int ctl_status_print(const struct proto_stats *st, const char *peer, bool json, FILE *out);
/* Sends STATS_REQ, waits for STATS and prints it. Returns 0 or -errno with err filled. */
int ctl_status_run(struct net_conn *c, bool json, int timeout_ms, FILE *out, char err[256]);
/* Sends STATS_REQ and reads one u64 figure (`key`) from the STATS. Returns 0, -ENOENT (the
 * daemon has no such figure) or -errno, with err filled. */
int ctl_stat_u64(struct net_conn *c, const char *key, int timeout_ms, uint64_t *v, char err[256]);
/* Sends LIST_PLANETS, waits for PLANETS and prints the planets served, one line each (name,
 * layers, levels, radius). Returns 0 or -errno with err filled. */
int ctl_status_planets(struct net_conn *c, int timeout_ms, FILE *out, char err[256]);

#endif
