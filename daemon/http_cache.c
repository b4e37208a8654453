/* http_cache — see http_cache.h. A chained hash table over the keys plus a doubly linked
 * recency list; the body is the first member of an entry, so a released body finds its
 * entry. */
#include "http_cache.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"

#define NBUCKETS 4096

struct entry {
	struct http_body body; /* first: http_cache_release casts back */
	atomic_int refs;       /* the cache's one while stored, plus one per user */
	char *key;
	uint64_t hash;
	struct entry *chain;	   /* bucket */
	struct entry *newer, *older; /* recency */
};

struct http_cache {
	pthread_mutex_t mu;
	struct entry *buckets[NBUCKETS];
	struct entry *newest, *oldest;
	size_t budget, bytes, entries;
	uint64_t hits, misses, evictions;
};

static uint64_t hash_of(const char *s)
{
	uint64_t h = 1469598103934665603ull; /* FNV-1a */
	for (; *s; s++)
		h = (h ^ (unsigned char)*s) * 1099511628211ull;
	return h;
}

static void unref(struct entry *e)
{
	if (atomic_fetch_sub(&e->refs, 1) == 1) {
		free((void *)e->body.data);
		free(e->key);
		free(e);
	}
}

struct http_cache *http_cache_create(size_t budget)
{
	struct http_cache *c = xcalloc(1, sizeof *c);
	pthread_mutex_init(&c->mu, NULL);
	c->budget = budget;
	return c;
}

static void unlink_lru(struct http_cache *c, struct entry *e)
{
	if (e->newer)
		e->newer->older = e->older;
	else
		c->newest = e->older;
	if (e->older)
		e->older->newer = e->newer;
	else
		c->oldest = e->newer;
	e->newer = e->older = NULL;
}

static void push_newest(struct http_cache *c, struct entry *e)
{
	e->older = c->newest;
	e->newer = NULL;
	if (c->newest)
		c->newest->newer = e;
	c->newest = e;
	if (!c->oldest)
		c->oldest = e;
}

static struct entry *find(struct http_cache *c, const char *key, uint64_t h)
{
	for (struct entry *e = c->buckets[h % NBUCKETS]; e; e = e->chain)
		if (e->hash == h && !strcmp(e->key, key))
			return e;
	return NULL;
}

/* Unlinks e from its bucket and the recency list (under mu); the caller drops the cache's
 * reference after unlocking. */
static void remove_entry(struct http_cache *c, struct entry *e)
{
	struct entry **pp = &c->buckets[e->hash % NBUCKETS];
	while (*pp != e)
		pp = &(*pp)->chain;
	*pp = e->chain;
	unlink_lru(c, e);
	c->bytes -= e->body.n;
	c->entries--;
}

void http_cache_destroy(struct http_cache *c)
{
	if (!c)
		return;
	for (struct entry *e = c->oldest, *next; e; e = next) {
		next = e->newer;
		unref(e);
	}
	pthread_mutex_destroy(&c->mu);
	free(c);
}

const struct http_body *http_cache_get(struct http_cache *c, const char *key)
{
	uint64_t h = hash_of(key);
	pthread_mutex_lock(&c->mu);
	struct entry *e = find(c, key, h);
	if (e) {
		atomic_fetch_add(&e->refs, 1);
		unlink_lru(c, e);
		push_newest(c, e);
		c->hits++;
	} else {
		c->misses++;
	}
	pthread_mutex_unlock(&c->mu);
	return e ? &e->body : NULL;
}

const struct http_body *http_cache_put(struct http_cache *c, const char *key, unsigned char *data,
				       size_t n)
{
	uint64_t h = hash_of(key);
	struct entry *e = xcalloc(1, sizeof *e);
	*e = (struct entry){ .body = { data, n }, .key = xstrdup(key), .hash = h };
	atomic_init(&e->refs, 2);
	struct entry *gone[64];
	int ngone = 0;
	pthread_mutex_lock(&c->mu);
	struct entry *old = find(c, key, h);
	if (old) {
		atomic_fetch_add(&old->refs, 1);
		pthread_mutex_unlock(&c->mu);
		atomic_store(&e->refs, 1);
		unref(e);
		return &old->body;
	}
	e->chain = c->buckets[h % NBUCKETS];
	c->buckets[h % NBUCKETS] = e;
	push_newest(c, e);
	c->bytes += n;
	c->entries++;
	while (c->bytes > c->budget && c->oldest != e && ngone < 64) {
		struct entry *v = c->oldest;
		remove_entry(c, v);
		c->evictions++;
		gone[ngone++] = v;
	}
	pthread_mutex_unlock(&c->mu);
	for (int i = 0; i < ngone; i++)
		unref(gone[i]);
	return &e->body;
}

void http_cache_release(const struct http_body *b)
{
	if (b)
		unref((struct entry *)(void *)b);
}

void http_cache_stats(struct http_cache *c, struct http_cache_stats *o)
{
	pthread_mutex_lock(&c->mu);
	*o = (struct http_cache_stats){ .hits = c->hits, .misses = c->misses, .bytes = c->bytes,
					.entries = c->entries, .evictions = c->evictions };
	pthread_mutex_unlock(&c->mu);
}
