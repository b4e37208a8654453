/* ctl_cache — `clipmapctl cache ls`: asks for CACHE_ENTRIES (all parts of a reply) and prints
 * them as a table (layer or node, level, x, y, bytes, age, tier) or JSON, sorted by layer,
 * level, y, x. Node hashes are named by the planet's layers where they match.
 * No state; output goes to the caller's FILE.
 */
#ifndef CLIPMAP_CTL_CACHE_H
#define CLIPMAP_CTL_CACHE_H
#include <stdbool.h>
#include <stdio.h>

#include "client/net.h"

struct ctl_cache_opts {
	const char *planet; /* required */
	bool near;	    /* with lat, lon, radius_m */
	double lat, lon, radius_m;
	int level;	    /* ≥ 0: only (lx, ly) = (level + 1, level); < 0: every level */
	uint32_t limit;	    /* 0: the server's default */
	bool json;
};

/* Prints entries (sorted in place) with the layer names of p (may be NULL); total is what
 * the server said matched. Returns 0 or -EIO. */
int ctl_cache_print(struct proto_cache_entry *e, size_t n, uint64_t total,
		    const struct proto_planet *p, bool json, FILE *out);
/* OPENs the planet, sends CACHE_LS, gathers every CACHE_ENTRIES part and prints. Returns 0 or
 * -errno with err filled. */
int ctl_cache_ls(struct net_conn *c, const struct ctl_cache_opts *o, int timeout_ms, FILE *out,
		 char err[256]);

#endif
