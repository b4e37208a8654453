/* http — clipmapd's HTTP endpoint (libmicrohttpd): OGC WMTS and TMS tiles, Prometheus metrics,
 * health checks (docs/HTTP.md). Web requests are one more requester of the scheduler: a tile
 * not in the memory cache is wanted through a sched_req of its own, so it shares the caches,
 * the store and the merging with every viewer; the connection is suspended meanwhile (no
 * thread waits) and resumed by the ready callback. Its requests are of their own class,
 * SCHED_WEB (after what viewers show, before prefetch), and a client that hangs up while it
 * waits withdraws its want, so work nobody else wants is cancelled.
 *
 * Threads: libmicrohttpd's own (a pool of `threads`), never the loop thread; encoding (PNG,
 * GeoTIFF, …) happens there. http_set_planets and http_set_metrics are called by the loop
 * thread; everything they hand over is guarded by the http's mutex.
 */
#ifndef CLIPMAP_HTTP_H
#define CLIPMAP_HTTP_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "engine/cache.h"
#include "engine/planets.h"
#include "engine/sched.h"

struct http_desc {
	const char *listen; /* "host:port" (port 0: ephemeral) */
	struct sched *sched;
	struct cache *cache;
	struct planet_set *planets; /* borrowed: the http takes its own reference */
	const uint8_t *token;	    /* required as "Authorization: Bearer TOKEN"; NULL: none */
	size_t token_len;
	int threads, max_conns, max_per_addr, timeout_s, max_age_s;
	size_t cache_bytes; /* encoded tiles kept by ETag; 0: 64 MiB */
	const char *cesium_dir; /* CesiumJS's Build/Cesium directory for the browser page; NULL:
				 * no page ("/" is the plain index) */
	const char *tls_cert, *tls_key; /* PEM texts ([tls] cert, key; copied): HTTPS; NULL:
					 * plain HTTP */
};

struct http_stats {
	uint64_t requests, tiles, not_modified, client_errors, server_errors, auth_failures,
		bytes, cache_hits, cache_misses, cache_bytes;
	uint64_t cancelled; /* waiting requests whose client hung up (their want withdrawn) */
};

struct http;

/* Starts listening. Returns 0 or -errno with err filled (address in use, bad address,
 * -ENOTSUP: TLS asked of a libmicrohttpd built without it). */
int http_create(const struct http_desc *d, struct http **out, char err[256]);
/* Stops listening (and the hang-up watcher), answers suspended requests 503, joins the threads, frees. NULL: no-op. */
void http_destroy(struct http *h);
/* Replaces the HTTPS certificate and key (PEM text, copied) for handshakes from now on.
 * Returns 0, or -EINVAL with err (the endpoint is plain HTTP, or the PEM does not parse):
 * the running certificate stays then. Any thread. */
int http_reload_tls(struct http *h, const char *cert_pem, const char *key_pem, char err[256]);
/* The port listened on (the ephemeral one when 0 was asked). */
uint16_t http_port(const struct http *h);
/* The planets served from now on (a new reference is taken; requests in flight keep theirs). */
void http_set_planets(struct http *h, struct planet_set *ps);
/* The text /metrics answers with until the next call (copied). */
void http_set_metrics(struct http *h, const char *text, size_t n);
void http_get_stats(struct http *h, struct http_stats *out);

#endif
