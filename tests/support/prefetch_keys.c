/* prefetch_keys — see prefetch_keys.h. */
#include "prefetch_keys.h"

#include <stdio.h>
#include <stdlib.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "prefetch.h"

int tile_key_cmp(const void *a, const void *b)
{
	const struct tile_key *x = a, *y = b;
	if (x->lx != y->lx)
		return x->lx < y->lx ? -1 : 1;
	if (x->ly != y->ly)
		return x->ly < y->ly ? -1 : 1;
	if (x->y != y->y)
		return x->y < y->y ? -1 : 1;
	if (x->x != y->x)
		return x->x < y->x ? -1 : 1;
	return 0;
}

void keyset_sort_unique(struct keyset *ks)
{
	qsort(ks->k, ks->n, sizeof *ks->k, tile_key_cmp);
	size_t n = ks->n ? 1 : 0;
	for (size_t i = 1; i < ks->n; i++)
		if (tile_key_cmp(&ks->k[i], &ks->k[n - 1]))
			ks->k[n++] = ks->k[i];
	ks->n = n;
}

bool keyset_has(const struct keyset *ks, const struct tile_key *k)
{
	return bsearch(k, ks->k, ks->n, sizeof *ks->k, tile_key_cmp) != NULL;
}

int prefetch_job_keys(const struct planet *p, const struct proto_prefetch *m, struct keyset *ks,
		      uint64_t *est, char err[256])
{
	struct prefetch_iter *it;
	ks->k = NULL;
	ks->n = 0;
	if (prefetch_iter_create(p, m, PREFETCH_MAX_TILES, &it, err) != 0)
		return -1;
	*est = prefetch_iter_total(it);
	size_t cap = 1 << 16;
	ks->k = xmalloc(cap * sizeof *ks->k);
	struct want w[512];
	size_t got;
	while ((got = prefetch_iter_next(it, w, 512)) > 0) {
		if (ks->n + got > cap) {
			cap *= 2;
			ks->k = xrealloc(ks->k, cap * sizeof *ks->k);
		}
		for (size_t i = 0; i < got; i++) {
			ks->k[ks->n] = w[i].key;
			ks->k[ks->n++].node = 0;
		}
	}
	int rc = 0;
	if (prefetch_iter_error(it, err) != 0)
		rc = -1;
	else if (ks->n != prefetch_iter_total(it)) {
		err_set(err, "%zu keys, total %llu", ks->n,
			(unsigned long long)prefetch_iter_total(it));
		rc = -1;
	}
	prefetch_iter_destroy(it);
	double ratio = (double)*est / (double)(ks->n ? ks->n : 1);
	if (rc == 0 && !(ratio >= 0.5 && ratio <= 4.0)) {
		err_set(err, "estimate %llu for %zu tiles", (unsigned long long)*est, ks->n);
		rc = -1;
	}
	size_t n0 = ks->n;
	keyset_sort_unique(ks);
	if (rc == 0 && ks->n != n0) {
		err_set(err, "%zu keys yielded twice", n0 - ks->n);
		rc = -1;
	}
	return rc;
}
