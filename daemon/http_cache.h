/* http_cache — encoded HTTP responses (PNG, GeoTIFF, quantized-mesh, …) kept by their ETag, so
 * a tile asked for again is sent without being encoded again: encoding is what an HTTP tile
 * costs (a 256² PNG takes milliseconds; sending it, microseconds). Least recently used entries
 * go past the byte budget. Entries are reference-counted: a response being sent keeps its
 * bytes alive after eviction.
 *
 * Threads: every function is thread-safe (one mutex; no call made under it).
 */
#ifndef CLIPMAP_HTTP_CACHE_H
#define CLIPMAP_HTTP_CACHE_H
#include <stddef.h>
#include <stdint.h>

struct http_body {
	const unsigned char *data;
	size_t n;
};

struct http_cache;

struct http_cache *http_cache_create(size_t budget);
void http_cache_destroy(struct http_cache *c);
/* The body stored under key with one reference for the caller (release with
 * http_cache_release), or NULL. */
const struct http_body *http_cache_get(struct http_cache *c, const char *key);
/* Stores data (n bytes, taken: malloc'ed, freed by the cache) under key and returns it with
 * one reference for the caller. A key already present keeps its first body (data is freed
 * and the stored one returned). */
const struct http_body *http_cache_put(struct http_cache *c, const char *key, unsigned char *data,
				       size_t n);
void http_cache_release(const struct http_body *b);

struct http_cache_stats {
	uint64_t hits, misses, bytes, entries, evictions;
};
void http_cache_stats(struct http_cache *c, struct http_cache_stats *out);

#endif
