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

/* `cache stat [PLANET]`, `cache purge PLANET [--bbox] [--levels]`, `cache gc`, `cache
 * verify [PLANET]`: one CACHE_OP, its replies printed (stat: a row per planet, layer, level and
 * tier with totals; the others: what was checked and removed). */
struct ctl_cache_op_opts {
	uint8_t op;	    /* enum proto_cache_opk */
	const char *planet; /* NULL or "": every planet (stat, verify) */
	uint8_t filter;	    /* PROTO_COF_* (purge) */
	struct geo_rect bbox;
	uint8_t lmin, lmax;
	/* with PROTO_COF_POLYGON: the polygon (borrowed; client/ctl/coverage.h) */
	uint32_t nrings, npoints;
	const uint32_t *rings;
	const struct proto_lonlat *points;
	bool json;
};

/* Returns 0 or -errno with err filled. timeout_ms bounds the whole wait (0: 10 minutes). */
int ctl_cache_op(struct net_conn *c, const struct ctl_cache_op_opts *o, int timeout_ms,
		 FILE *out, char err[256]);

#endif
