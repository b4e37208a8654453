/* tile — see tile.h. */
#include "tile.h"

#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"

size_t pix_bytes(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return 4;
	case PIX_COLOR: return 4;
	case PIX_NORMAL: return 2;
	default: return 0;
	}
}

const char *pix_type_name(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return "height";
	case PIX_COLOR: return "color";
	case PIX_NORMAL: return "normal";
	default: return "none";
	}
}

const char *pix_format_name(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return "f32";
	case PIX_COLOR: return "rgba8";
	case PIX_NORMAL: return "rg8";
	default: return "none";
	}
}

enum pix_type pix_type_parse(const char *s)
{
	for (int t = PIX_HEIGHT; t <= PIX_NORMAL; t++)
		if (strcmp(s, pix_type_name((enum pix_type)t)) == 0)
			return (enum pix_type)t;
	return PIX_NONE;
}

struct tile *tile_create(const struct tile_key *key, enum pix_type type, uint32_t size)
{
	struct tile *t = xcalloc(1, sizeof *t);
	atomic_init(&t->refs, 1);
	t->type = type;
	t->size = size;
	t->key = *key;
	t->nbytes = (size_t)size * size * pix_bytes(type);
	t->data = xaligned_alloc(64, t->nbytes);
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
		free(t->data);
		free(t);
	}
}
