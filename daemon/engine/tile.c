/* tile — see tile.h. */
#include "tile.h"

#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "common/xalloc.h"
#include "common/xthread.h"
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

static void drop_bytes(struct tile *t)
{
	if (t->base)
		tile_unref(t->base);
	else
		tilemem_free(t->data, t->nbytes);
	t->base = NULL;
	t->data = NULL;
	t->uniform = false;
}

void tile_alias(struct tile *t, struct tile *src)
{
	struct tile *owner = src->base ? src->base : src; /* never a chain */
	tile_ref(owner);
	drop_bytes(t);
	t->base = owner;
	t->data = owner->data;
	t->uniform = src->uniform;
	t->summarized = src->summarized;
	t->any_nan = src->any_nan;
	t->lo = src->lo;
	t->hi = src->hi;
}

/* The shared uniform buffers: one owner tile per (type, size, value), kept for the process's
 * life (reachable from here, so not a leak to the sanitizers). */
#define UNIFORM_MAX 64
static struct {
	pthread_mutex_t mu;
	int n;
	struct tile *t[UNIFORM_MAX];
} uniform = { .mu = PTHREAD_MUTEX_INITIALIZER };

static void fill(unsigned char *d, size_t count, const void *texel, size_t pb)
{
	if (pb == 4) {
		uint32_t v;
		memcpy(&v, texel, 4);
		uint32_t *w = (uint32_t *)(void *)d;
		for (size_t i = 0; i < count; i++)
			w[i] = v;
		return;
	}
	for (size_t i = 0; i < count; i++)
		memcpy(d + pb * i, texel, pb);
}

static struct tile *uniform_owner(enum pix_type type, uint32_t size, const void *texel)
{
	size_t pb = pix_bytes(type);
	struct tile *found = NULL;
	xmutex_lock(&uniform.mu);
	for (int i = 0; i < uniform.n && !found; i++) {
		struct tile *u = uniform.t[i];
		if (u->type == type && u->size == size && memcmp(u->data, texel, pb) == 0)
			found = u;
	}
	if (!found && uniform.n < UNIFORM_MAX) {
		struct tile_key k = { 0 };
		found = tile_create(&k, type, size);
		fill(found->data, (size_t)size * size, texel, pb);
		uniform.t[uniform.n++] = found; /* the registry's reference, never dropped */
	}
	xmutex_unlock(&uniform.mu);
	return found;
}

/* t's texels become u's (the shared buffer of texel's value): one reference to u held. */
static void use_uniform(struct tile *t, struct tile *u)
{
	tile_ref(u);
	drop_bytes(t);
	t->base = u;
	t->data = u->data;
	t->uniform = true;
}

/* A height tile's summary when every texel is *texel. */
static void summarize_uniform(struct tile *t, const void *texel)
{
	if (t->type != PIX_HEIGHT)
		return;
	float v;
	memcpy(&v, texel, sizeof v);
	t->summarized = true;
	t->any_nan = v != v;
	t->lo = v != v ? INFINITY : v;
	t->hi = v != v ? -INFINITY : v;
}

void tile_fill_uniform(struct tile *t, const void *texel)
{
	struct tile *u = uniform_owner(t->type, t->size, texel);
	if (u)
		use_uniform(t, u);
	else
		fill(t->data, (size_t)t->size * t->size, texel, pix_bytes(t->type));
	summarize_uniform(t, texel);
}

/* Whether each of the count 4-byte texels at d equals the first, bit for bit: blocks of 64
 * texels folded by OR of XORs (vectorised at -O2), leaving at the first block that differs. */
static bool all_like_first(const uint32_t *d, size_t count)
{
	const uint32_t v = d[0];
	size_t i = 0;
	for (; i + 64 <= count; i += 64) {
		uint32_t x = 0;
		for (int k = 0; k < 64; k++)
			x |= d[i + k] ^ v;
		if (x)
			return false;
	}
	for (; i < count; i++)
		if (d[i] != v)
			return false;
	return true;
}

bool tile_share_if_uniform(struct tile *t)
{
	if (t->type != PIX_HEIGHT || t->uniform || t->base) /* 4-byte texels */
		return false;
	size_t count = (size_t)t->size * t->size;
	const uint32_t *d = (const uint32_t *)(const void *)t->data;
	if (!count || !all_like_first(d, count))
		return false;
	struct tile *u = uniform_owner(t->type, t->size, t->data);
	if (!u)
		return false; /* the registry is full: t keeps its own buffer */
	use_uniform(t, u);
	summarize_uniform(t, t->data);
	return true;
}

void tile_summary_from_lanes(struct tile *t, const float lo[16], const float hi[16], bool nan)
{
	float l = INFINITY, h = -INFINITY;
	for (int k = 0; k < 16; k++) {
		l = lo[k] < l ? lo[k] : l;
		h = hi[k] > h ? hi[k] : h;
	}
	t->lo = l;
	t->hi = h;
	t->any_nan = nan;
	t->summarized = true;
}

/* 16-texel blocks so the loop vectorises at -O2 (T is a multiple of 16). NaN fails every
 * comparison, so it neither lowers lo nor raises hi. */
void tile_summarize(struct tile *t)
{
	if (t->type != PIX_HEIGHT || t->summarized)
		return;
	const float *x = tile_f32(t);
	size_t count = (size_t)t->size * t->size;
	float lo = INFINITY, hi = -INFINITY;
	int nan = 0;
	size_t i = 0;
	if (count % 16 == 0) {
		float l[16], h[16];
		int nn[16] = { 0 };
		for (int k = 0; k < 16; k++)
			l[k] = INFINITY, h[k] = -INFINITY;
#ifdef __SSE2__
		/* the loop below in four vectors: minps(v, l) is v < l ? v : l and maxps(v, h)
		 * v > h ? v : h lane for lane (NaN and ±0 alike), so the lanes end equal */
		__m128 vl[4], vh[4], vn = _mm_setzero_ps();
		for (int k = 0; k < 4; k++)
			vl[k] = _mm_set1_ps(INFINITY), vh[k] = _mm_set1_ps(-INFINITY);
		for (; i < count; i += 16)
			for (int k = 0; k < 4; k++) {
				__m128 v = _mm_loadu_ps(x + i + 4 * k);
				vl[k] = _mm_min_ps(v, vl[k]);
				vh[k] = _mm_max_ps(v, vh[k]);
				vn = _mm_or_ps(vn, _mm_cmpunord_ps(v, v));
			}
		for (int k = 0; k < 4; k++) {
			_mm_storeu_ps(l + 4 * k, vl[k]);
			_mm_storeu_ps(h + 4 * k, vh[k]);
		}
		nn[0] = _mm_movemask_ps(vn) != 0;
#else
		for (; i < count; i += 16)
			for (int k = 0; k < 16; k++) {
				float v = x[i + k];
				l[k] = v < l[k] ? v : l[k];
				h[k] = v > h[k] ? v : h[k];
				nn[k] |= v != v;
			}
#endif
		for (int k = 1; k < 16; k++)
			nn[0] |= nn[k];
		if (i == count) {
			tile_summary_from_lanes(t, l, h, nn[0] != 0);
			return;
		}
		for (int k = 0; k < 16; k++) {
			lo = l[k] < lo ? l[k] : lo;
			hi = h[k] > hi ? h[k] : hi;
		}
		nan = nn[0];
	}
	for (; i < count; i++) {
		float v = x[i];
		lo = v < lo ? v : lo;
		hi = v > hi ? v : hi;
		nan |= v != v;
	}
	t->lo = lo;
	t->hi = hi;
	t->any_nan = nan != 0;
	t->summarized = true;
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
		drop_bytes(t);
		free(t);
	}
}
