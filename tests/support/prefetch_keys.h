/* prefetch_keys — the tiles a prefetch job yields, as a sorted set, for the tests that check
 * them against references (test_prefetch, test_coverage). Test-only code. */
#ifndef CLIPMAP_TEST_PREFETCH_KEYS_H
#define CLIPMAP_TEST_PREFETCH_KEYS_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"
#include "engine/planet.h"

struct keyset {
	struct tile_key *k; /* owned (free()) */
	size_t n;
};

/* Orders keys by lx, ly, y, x (the node is not compared). */
int tile_key_cmp(const void *a, const void *b);
/* Sorts ks and drops repeats. */
void keyset_sort_unique(struct keyset *ks);
bool keyset_has(const struct keyset *ks, const struct tile_key *k);
/* Every key the job yields (one layer: the nodes zeroed), sorted, in ks; *est receives the
 * estimate made before the iteration. Returns 0, or -1 with err saying what went wrong: the
 * job refused, an iteration error, a total that is not the count, a key yielded twice, or an
 * estimate outside [0.5, 4] × the count. */
int prefetch_job_keys(const struct planet *p, const struct proto_prefetch *m, struct keyset *ks,
		      uint64_t *est, char err[256]);

#endif
