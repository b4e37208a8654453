/* tile — see tile.h. */
#include "tile.h"

#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"
#include "tilemem.h"

struct tile *tile_create(const struct tile_key *key, enum pix_type type, uint32_t size)
{
	struct tile *t = xcalloc(1, sizeof *t);
	atomic_init(&t->refs, 1);
	t->type = type;
	t->size = size;
	t->key = *key;
	t->nbytes = (size_t)size * size * pix_bytes(type);
	t->data = tilemem_alloc(t->nbytes);
	return t;
}

struct tile *tile_ref(struct tile *t)
{
	atomic_fetch_add_explicit(&t->refs, 1, memory_order_relaxed);
	return t;
}

void tile_unref(struct tile *t)
{
	if (!t)
		return;
	if (atomic_fetch_sub_explicit(&t->refs, 1, memory_order_acq_rel) == 1) {
		tilemem_free(t->data, t->nbytes);
		free(t);
	}
}
