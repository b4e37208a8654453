/* http — see http.h. A request's life: the access handler parses the path (http_route), checks
 * the token, and answers at once what needs no tile. A tile found in the memory cache is
 * encoded and answered at once too; otherwise the connection is suspended and a sched_req of
 * its own wants the tile; the ready callback (manager thread) keeps the tile and resumes the
 * connection, whose handler runs again and answers. Suspended requests are linked in h->live
 * so shutdown can stop their scheduler requests and resume them (libmicrohttpd refuses to
 * stop with suspended connections), and so the hang-up watcher can find them.
 *
 * Hang-ups: libmicrohttpd does not watch a suspended connection's socket, so a client that
 * closes while its tile is made would go unnoticed until the tile is sent. A thread of ours
 * (watch_hangups) polls the sockets of the suspended connections for POLLRDHUP/POLLHUP (every
 * 100 ms, picking up new ones as it goes); on a hang-up it withdraws the request's want, so
 * the scheduler drops the queued work nobody else wants (work merged with another requester
 * goes on for that one), and resumes the connection, whose handler then closes it. Whoever
 * unlinks a request from h->live (the ready callback, the watcher, or shutdown) is the one
 * that resumes it, exactly once. */
#include "http.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <microhttpd.h>
#include <netdb.h>
#include <poll.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "common/errbuf.h"
#include "common/geoimg.h"
#include "common/log.h"
#include "common/pixfmt.h"
#include "common/strbuf.h"
#include "common/xalloc.h"
#include "conf.h"
#include "http_cache.h"
#include "http_cesium.h"
#include "http_page.h"
#include "http_route.h"
#include "http_tls.h"
#include "http_wmts.h"

struct http {
	struct MHD_Daemon *d;
	struct sched *sched;
	struct cache *cache;
	uint8_t token[256];
	size_t token_len;
	int max_age;
	uint16_t port;
	char *cesium_dir; /* NULL: no browser page */
	bool tls; /* HTTPS: the certificate is http_tls's (replaceable by http_reload_tls) */
	struct http_cache *bodies; /* encoded tiles by ETag */
	pthread_mutex_t mu; /* guards the fields below */
	struct planet_set *ps;
	char *metrics;
	size_t metrics_len;
	struct hreq *live; /* suspended requests */
	uint64_t serial;   /* of the last request suspended */
	bool stopping;
	pthread_cond_t live_cv; /* a request joined h->live, or stopping */
	pthread_t watcher;
	atomic_uint_fast64_t st_requests, st_tiles, st_304, st_4xx, st_5xx, st_auth, st_bytes,
		st_cancelled;
};

/* A tile request that had to wait for the scheduler. */
struct hreq {
	struct http *h;
	struct MHD_Connection *c;
	struct planet_set *ps; /* the reference that keeps the nodes alive */
	const struct planet *terrain; /* Cesium terrain of this planet; NULL: an image */
	int nkeys;		      /* 1, or 2: a terrain tile with its normals */
	struct node *node[2];
	struct tile_key key[2];
	enum geoimg_format fmt;
	char etag[64];
	struct sched_req *req;
	int fd;			  /* the connection's socket, watched while suspended */
	uint64_t serial;	  /* unique among the requests of this http (h->mu) */
	struct hreq *prev, *next; /* in h->live while linked (h->mu) */
	bool linked;		  /* (h->mu) */
	pthread_mutex_t mu;	  /* guards tile, err, done, hungup */
	struct tile *tile[2];	  /* as key[] */
	int err;
	bool done, hungup;
};

/* ---- responses -------------------------------------------------------------------------- */

static bool takes_gzip(struct MHD_Connection *c);
static unsigned char *gzip(const void *data, size_t n, size_t *out_n);

static enum MHD_Result send_buf(struct http *h, struct MHD_Connection *c, unsigned status,
				const char *type, void *data, size_t n, bool take)
{
	size_t zn = 0;
	unsigned char *z = n >= 1024 && takes_gzip(c) ? gzip(data, n, &zn) : NULL;
	if (z) {
		if (take)
			free(data);
		data = z;
		n = zn;
		take = true;
	}
	struct MHD_Response *r = MHD_create_response_from_buffer(
		n, data, take ? MHD_RESPMEM_MUST_FREE : MHD_RESPMEM_MUST_COPY);
	if (!r) {
		if (take)
			free(data);
		return MHD_NO;
	}
	MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, type);
	MHD_add_response_header(r, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_ORIGIN, "*");
	MHD_add_response_header(r, MHD_HTTP_HEADER_VARY, MHD_HTTP_HEADER_ACCEPT_ENCODING);
	if (z)
		MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_ENCODING, "gzip");
	if (status == MHD_HTTP_UNAUTHORIZED)
		MHD_add_response_header(r, MHD_HTTP_HEADER_WWW_AUTHENTICATE,
					"Bearer realm=\"clipmapd\"");
	enum MHD_Result rc = MHD_queue_response(c, status, r);
	MHD_destroy_response(r);
	if (status >= 500)
		atomic_fetch_add(&h->st_5xx, 1);
	else if (status >= 400)
		atomic_fetch_add(&h->st_4xx, 1);
	atomic_fetch_add(&h->st_bytes, n);
	return rc;
}

static enum MHD_Result __attribute__((format(printf, 4, 5)))
text(struct http *h, struct MHD_Connection *c, unsigned status, const char *fmt, ...)
{
	char msg[512];
	va_list ap;
	va_start(ap, fmt);
	int k = vsnprintf(msg, sizeof msg - 1, fmt, ap);
	va_end(ap);
	size_t n = k < 0 ? 0 : (size_t)k < sizeof msg - 1 ? (size_t)k : sizeof msg - 2;
	msg[n++] = '\n';
	return send_buf(h, c, status, "text/plain; charset=utf-8", msg, n, false);
}

/* The texels of t as the format wants them: colour as is, heights as 16-bit (round(m) + 32768)
 * or float32, normals as RGB with the up component. Returns a malloc'ed image or NULL with
 * *why set (a format the layer is not offered in). */
static void *pixels_for(const struct tile *t, enum geoimg_format fmt, struct geoimg *im,
			const char **why)
{
	uint32_t T = t->size;
	size_t n = (size_t)T * T;
	*im = (struct geoimg){ .width = (int)T, .height = (int)T };
	switch (t->type) {
	case PIX_COLOR:
		im->channels = 4;
		im->type = IMG_U8;
		im->pixels = t->data;
		return NULL;
	case PIX_HEIGHT: {
		const float *h = tile_f32(t);
		if (fmt == GEOIMG_TIFF) {
			im->channels = 1;
			im->type = IMG_F32;
			im->pixels = h;
			return NULL;
		}
		if (fmt != GEOIMG_PNG) {
			*why = "heights are served as .png (16-bit: round(metres) + 32768) or .tif "
			       "(float32 metres)";
			return NULL;
		}
		uint16_t *o = xmalloc(n * 2);
		for (size_t i = 0; i < n; i++) {
			double v = isfinite(h[i]) ? lround(h[i]) + 32768.0 : 0;
			o[i] = (uint16_t)(v < 0 ? 0 : v > 65535 ? 65535 : v);
		}
		im->channels = 1;
		im->type = IMG_U16;
		im->pixels = o;
		return o;
	}
	case PIX_NORMAL: {
		if (fmt == GEOIMG_JPEG) {
			*why = "normals are served as .png, .webp or .tif";
			return NULL;
		}
		uint8_t *o = xmalloc(n * 3);
		pix_normals_rgb(t->data, o, n);
		im->channels = 3;
		im->type = IMG_U8;
		im->pixels = o;
		return o;
	}
	default: *why = "this layer's pixels have no web format"; return NULL;
	}
}

static void release_body(void *cls) { http_cache_release(cls); }

/* Whether the client takes gzip (Accept-Encoding names it without q=0). */
static bool takes_gzip(struct MHD_Connection *c)
{
	const char *a = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
						    MHD_HTTP_HEADER_ACCEPT_ENCODING);
	const char *g = a ? strstr(a, "gzip") : NULL;
	return g && strncmp(g + 4, ";q=0", 4) != 0;
}

/* data (n bytes) gzip-compressed into a malloc'ed buffer, or NULL when that does not pay
 * (less than a tenth smaller) or fails. */
static unsigned char *gzip(const void *data, size_t n, size_t *out_n)
{
	z_stream z = { 0 };
	if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK)
		return NULL;
	size_t cap = deflateBound(&z, (uLong)n);
	unsigned char *out = xmalloc(cap);
	z.next_in = (Bytef *)data;
	z.avail_in = (uInt)n;
	z.next_out = out;
	z.avail_out = (uInt)cap;
	int rc = deflate(&z, Z_FINISH);
	*out_n = z.total_out;
	deflateEnd(&z);
	if (rc != Z_STREAM_END || *out_n > n - n / 10) {
		free(out);
		return NULL;
	}
	return out;
}

/* Answers with an encoded tile (a reference the response takes over). */
static enum MHD_Result send_body(struct http *h, struct MHD_Connection *c,
				 const struct http_body *b, enum geoimg_format fmt, bool terrain,
				 bool gz, const char *etag)
{
	struct MHD_Response *resp = MHD_create_response_from_buffer_with_free_callback_cls(
		b->n, (void *)b->data, release_body, (void *)b);
	if (!resp) {
		http_cache_release(b);
		return MHD_NO;
	}
	char cc[64];
	snprintf(cc, sizeof cc, "public, max-age=%d", h->max_age);
	MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE,
				terrain ? "application/vnd.quantized-mesh" : geoimg_mime(fmt));
	MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
	MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, cc);
	MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCESS_CONTROL_ALLOW_ORIGIN, "*");
	if (terrain) /* gzip or not, vertex normals or not */
		MHD_add_response_header(resp, MHD_HTTP_HEADER_VARY, "Accept-Encoding, Accept");
	if (gz)
		MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_ENCODING, "gzip");
	enum MHD_Result res = MHD_queue_response(c, MHD_HTTP_OK, resp);
	MHD_destroy_response(resp);
	atomic_fetch_add(&h->st_tiles, 1);
	atomic_fetch_add(&h->st_bytes, b->n);
	return res;
}

/* Answers with tile t: an image in fmt, or (terrain set) a quantized-mesh tile of that
 * planet, with vertex normals from tile `normals` when not NULL; the encoding is kept under its ETag for the next request. */
static enum MHD_Result send_tile(struct http *h, struct MHD_Connection *c, const struct tile *t,
				 const struct tile *normals, enum geoimg_format fmt,
				 const struct planet *terrain, const char *etag)
{
	unsigned char *out = NULL;
	size_t n = 0;
	if (terrain) {
		cesium_quantized_mesh(terrain, t, normals, &out, &n);
		/* meshes compress (images do not): a gzip variant for clients that take it */
		if (takes_gzip(c)) {
			size_t zn;
			unsigned char *z = gzip(out, n, &zn);
			if (z) {
				char key[80];
				snprintf(key, sizeof key, "%s+gzip", etag);
				http_cache_release(http_cache_put(h->bodies, etag, out, n));
				return send_body(h, c, http_cache_put(h->bodies, key, z, zn), fmt,
						 true, true, etag);
			}
		}
	} else {
		struct geoimg im;
		const char *why = NULL;
		void *own = pixels_for(t, fmt, &im, &why);
		if (why)
			return text(h, c, MHD_HTTP_BAD_REQUEST, "%s", why);
		struct geo_rect r;
		grid_tile_rect(&t->key, &r);
		im.bounds = &r;
		char err[256];
		int rc = geoimg_encode(&im, fmt, &out, &n, err);
		free(own);
		if (rc < 0) {
			log_msg(LOG_WARN, "http: encoding a tile: %s", err);
			return text(h, c, MHD_HTTP_INTERNAL_SERVER_ERROR, "encoding failed: %s",
				    err);
		}
	}
	return send_body(h, c, http_cache_put(h->bodies, etag, out, n), fmt, terrain != NULL, false,
			 etag);
}

/* ---- waiting for the scheduler ---------------------------------------------------------- */

/* Takes q out of h->live (h->mu held, q linked). */
static void unlink_live(struct http *h, struct hreq *q)
{
	if (q->prev)
		q->prev->next = q->next;
	else
		h->live = q->next;
	if (q->next)
		q->next->prev = q->prev;
	q->prev = q->next = NULL;
	q->linked = false;
}

static void on_ready(void *ud, const struct want *w, struct tile *t, int err)
{
	struct hreq *q = ud;
	pthread_mutex_lock(&q->mu);
	bool first = false;
	if (!q->done) {
		int i = q->nkeys > 1 && w->key.node == q->key[1].node; /* same place, other node */
		if (!t) {
			q->err = err ? err : -EIO;
			q->done = first = true;
		} else if (!q->tile[i]) {
			q->tile[i] = tile_ref(t);
			q->done = first = !q->tile[0] ? false : q->nkeys < 2 || q->tile[1];
		}
	}
	pthread_mutex_unlock(&q->mu);
	if (!first)
		return;
	struct http *h = q->h;
	pthread_mutex_lock(&h->mu);
	/* Once stopping, http_destroy owns the list and resumes every request on it; a request
	 * the watcher unlinked (its client hung up) is resumed by the watcher. */
	bool resume = !h->stopping && q->linked;
	if (resume)
		unlink_live(h, q);
	pthread_mutex_unlock(&h->mu);
	if (resume)
		MHD_resume_connection(q->c);
}

/* Withdraws the want of a request whose client hung up and resumes its connection (its
 * handler closes it). q was unlinked by the caller, so nobody else resumes it. */
static void hung_up(struct http *h, struct hreq *q)
{
	pthread_mutex_lock(&q->mu);
	q->hungup = true;
	bool done = q->done;
	pthread_mutex_unlock(&q->mu);
	if (!done) {
		sched_req_want(q->req, NULL, 0); /* the scheduler cancels what no one else wants */
		atomic_fetch_add(&h->st_cancelled, 1);
	}
	MHD_resume_connection(q->c);
}

/* The hang-up watcher's thread (see the top of the file). */
static void *watch_hangups(void *arg)
{
	struct http *h = arg;
	struct pollfd *pf = NULL;
	struct watched { struct hreq *q; uint64_t serial; } *who = NULL;
	size_t cap = 0;
	pthread_mutex_lock(&h->mu);
	while (!h->stopping) {
		if (!h->live) {
			pthread_cond_wait(&h->live_cv, &h->mu);
			continue;
		}
		size_t n = 0;
		for (struct hreq *q = h->live; q; q = q->next)
			n++;
		if (n > cap) {
			cap = n * 2;
			pf = xrealloc(pf, cap * sizeof *pf);
			who = xrealloc(who, cap * sizeof *who);
		}
		n = 0;
		for (struct hreq *q = h->live; q; q = q->next, n++) {
			pf[n] = (struct pollfd){ .fd = q->fd, .events = POLLRDHUP };
			who[n] = (struct watched){ q, q->serial };
		}
		pthread_mutex_unlock(&h->mu);
		int k = poll(pf, (nfds_t)n, 100);
		pthread_mutex_lock(&h->mu);
		for (size_t i = 0; k > 0 && i < n && !h->stopping; i++) {
			if (!(pf[i].revents & (POLLRDHUP | POLLHUP | POLLERR)))
				continue;
			/* Still suspended (else its socket may be another connection's by now)? */
			struct hreq *q = h->live;
			while (q && (q != who[i].q || q->serial != who[i].serial))
				q = q->next;
			if (!q)
				continue;
			unlink_live(h, q);
			pthread_mutex_unlock(&h->mu);
			hung_up(h, q);
			pthread_mutex_lock(&h->mu);
		}
	}
	pthread_mutex_unlock(&h->mu);
	free(pf);
	free(who);
	return NULL;
}

static void hreq_free(struct hreq *q)
{
	if (q->req)
		sched_req_destroy(q->req); /* no callback after this */
	tile_unref(q->tile[0]);
	tile_unref(q->tile[1]);
	planet_set_unref(q->ps);
	pthread_mutex_destroy(&q->mu);
	free(q);
}

/* *con_cls after the first call of a request that is not waiting for a tile. */
static int headers_seen;

static void on_completed(void *cls, struct MHD_Connection *c, void **con_cls,
			 enum MHD_RequestTerminationCode toe)
{
	(void)cls;
	(void)c;
	(void)toe;
	if (*con_cls && *con_cls != &headers_seen)
		hreq_free(*con_cls);
	*con_cls = NULL;
}

/* ---- routes ----------------------------------------------------------------------------- */

static bool authorized(struct http *h, struct MHD_Connection *c)
{
	if (!h->token_len)
		return true;
	const char *a = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_AUTHORIZATION);
	if (!a || strncmp(a, "Bearer ", 7))
		return false;
	a += 7;
	size_t n = strlen(a);
	unsigned diff = n != h->token_len;
	for (size_t i = 0; i < h->token_len; i++) /* constant time in the token's length */
		diff |= (unsigned)(h->token[i] ^ (uint8_t)(i < n ? a[i] : 0));
	return diff == 0;
}

/* A query argument by either spelling (OGC KVP names are case-insensitive). */
static const char *query(struct MHD_Connection *c, const char *upper, const char *lower)
{
	const char *v = MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, upper);
	return v ? v : MHD_lookup_connection_value(c, MHD_GET_ARGUMENT_KIND, lower);
}

static struct planet_set *current(struct http *h)
{
	pthread_mutex_lock(&h->mu);
	struct planet_set *ps = planet_set_ref(h->ps);
	pthread_mutex_unlock(&h->mu);
	return ps;
}

/* "http://" + the Host header the client used (our own address when it sent none). */
static void base_url(struct http *h, struct MHD_Connection *c, char *out, size_t n)
{
	const char *host = MHD_lookup_connection_value(c, MHD_HEADER_KIND, MHD_HTTP_HEADER_HOST);
	bool ok = host && *host && strlen(host) < 200;
	for (const char *s = host; ok && *s; s++)
		ok = *s > ' ' && *s != '"' && *s != '<' && *s != '>' && *s != '/' && *s != '\\';
	if (ok)
		snprintf(out, n, "http://%s", host);
	else
		snprintf(out, n, "http://127.0.0.1:%u", h->port);
}

static enum MHD_Result index_page(struct http *h, struct MHD_Connection *c)
{
	struct planet_set *ps = current(h);
	struct strbuf b = { 0 };
	strbuf_printf(&b, "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>clipmapd"
			  "</title></head><body>\n<h1>clipmapd</h1>\n<p><a href=\"/wmts/1.0.0/"
			  "WMTSCapabilities.xml\">WMTS capabilities</a> · <a href=\"/metrics\">"
			  "metrics</a></p>\n<ul>\n");
	for (size_t i = 0; i < ps->n; i++) {
		const struct planet *p = ps->planets[i];
		strbuf_printf(&b, "<li><b>");
		strbuf_xml(&b, p->name);
		strbuf_printf(&b, "</b> — ");
		strbuf_xml(&b, p->description);
		strbuf_printf(&b, " (levels 0–%d):", p->max_level);
		for (size_t j = 0; j < p->nlayers; j++) {
			strbuf_printf(&b, " <a href=\"/wmts/");
			strbuf_xml(&b, p->name);
			strbuf_printf(&b, "/");
			strbuf_xml(&b, p->layers[j].name);
			strbuf_printf(&b, "/0/0/0.png\">");
			strbuf_xml(&b, p->layers[j].name);
			strbuf_printf(&b, "</a>");
		}
		strbuf_printf(&b, "</li>\n");
	}
	strbuf_printf(&b, "</ul>\n</body></html>\n");
	planet_set_unref(ps);
	size_t n;
	char *s = strbuf_take(&b, &n);
	return send_buf(h, c, MHD_HTTP_OK, "text/html; charset=utf-8", s, n, true);
}

/* The layer Cesium terrain is made from: the planet's first height layer. */
static const struct planet_layer *height_layer(const struct planet *p)
{
	for (size_t i = 0; i < p->nlayers; i++)
		if (p->layers[i].type == PIX_HEIGHT)
			return &p->layers[i];
	return NULL;
}

static enum MHD_Result tile_request(struct http *h, struct MHD_Connection *c,
				    const struct http_route *rt, void **con_cls)
{
	struct planet_set *ps = current(h);
	struct planet *p = planet_set_find(ps, rt->planet);
	bool terrain = rt->kind == HTTP_CESIUM_TILE;
	const struct planet_layer *l = !p ? NULL : terrain ? height_layer(p)
							   : planet_find_layer(p, rt->layer);
	if (!p || !l) {
		planet_set_unref(ps);
		if (p && terrain)
			return text(h, c, MHD_HTTP_NOT_FOUND, "planet %s has no height layer", p->name);
		return text(h, c, MHD_HTTP_NOT_FOUND, "no %s %s (see /wmts/1.0.0/WMTSCapabilities.xml)",
			    p ? "layer" : "planet", p ? rt->layer : rt->planet);
	}
	if ((int)rt->z > p->max_level) {
		planet_set_unref(ps);
		return text(h, c, MHD_HTTP_NOT_FOUND, "level %u is beyond %s's finest level %d",
			    rt->z, p->name, p->max_level);
	}
	struct tile_key key = { .node = l->node->hash, .x = rt->x, .y = rt->y,
				.lx = (uint8_t)(rt->z + 1), .ly = (uint8_t)rt->z };
	/* Terrain with vertex normals when the client asks for them (Cesium's Accept header:
	 * "application/vnd.quantized-mesh;extensions=octvertexnormals,...") and the planet has
	 * the normals of these heights. */
	const struct planet_layer *nl = NULL;
	if (terrain) {
		const char *acc = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
							      MHD_HTTP_HEADER_ACCEPT);
		if (acc && strstr(acc, "octvertexnormals"))
			nl = cesium_normal_layer(p, l);
	}
	struct tile_key nkey = key;
	if (nl)
		nkey.node = nl->node->hash;
	char etag[64];
	snprintf(etag, sizeof etag, "\"%016llx-%u-%u-%u-%s\"", (unsigned long long)nkey.node, rt->z,
		 rt->x, rt->y, nl ? "qmn" : terrain ? "qm" : geoimg_mime(rt->fmt) + 6);
	const char *inm = MHD_lookup_connection_value(c, MHD_HEADER_KIND,
						      MHD_HTTP_HEADER_IF_NONE_MATCH);
	if (inm && (strstr(inm, etag) || !strcmp(inm, "*"))) {
		planet_set_unref(ps);
		atomic_fetch_add(&h->st_304, 1);
		struct MHD_Response *r = MHD_create_response_from_buffer(0, NULL,
									 MHD_RESPMEM_PERSISTENT);
		MHD_add_response_header(r, MHD_HTTP_HEADER_ETAG, etag);
		enum MHD_Result res = MHD_queue_response(c, MHD_HTTP_NOT_MODIFIED, r);
		MHD_destroy_response(r);
		return res;
	}
	char gzkey[80];
	snprintf(gzkey, sizeof gzkey, "%s+gzip", etag);
	bool gz = terrain && takes_gzip(c);
	const struct http_body *body = gz ? http_cache_get(h->bodies, gzkey) : NULL;
	if (!body) {
		gz = false;
		body = http_cache_get(h->bodies, etag);
	}
	if (body) {
		planet_set_unref(ps);
		return send_body(h, c, body, rt->fmt, terrain, gz, etag);
	}
	struct tile *t = cache_lookup(h->cache, &key), *nt = nl ? cache_lookup(h->cache, &nkey) : NULL;
	if (t && (!nl || nt)) {
		enum MHD_Result res = send_tile(h, c, t, nt, rt->fmt, terrain ? p : NULL, etag);
		tile_unref(t);
		tile_unref(nt);
		planet_set_unref(ps);
		return res;
	}
	tile_unref(t);
	tile_unref(nt);
	struct hreq *q = xcalloc(1, sizeof *q);
	*q = (struct hreq){ .h = h, .c = c, .ps = ps, .nkeys = nl ? 2 : 1,
			    .node = { l->node, nl ? nl->node : NULL }, .key = { key, nkey },
			    .fmt = rt->fmt, .terrain = terrain ? p : NULL };
	memcpy(q->etag, etag, sizeof etag);
	const union MHD_ConnectionInfo *ci = MHD_get_connection_info(c,
								     MHD_CONNECTION_INFO_CONNECTION_FD);
	q->fd = ci ? ci->connect_fd : -1; /* -1: poll ignores it */
	pthread_mutex_init(&q->mu, NULL);
	q->req = sched_req_create(h->sched, on_ready, q);
	if (!q->req) {
		hreq_free(q);
		return text(h, c, MHD_HTTP_SERVICE_UNAVAILABLE, "out of memory");
	}
	pthread_mutex_lock(&h->mu);
	if (h->stopping) {
		pthread_mutex_unlock(&h->mu);
		hreq_free(q);
		return text(h, c, MHD_HTTP_SERVICE_UNAVAILABLE, "shutting down");
	}
	q->next = h->live;
	if (h->live)
		h->live->prev = q;
	h->live = q;
	q->linked = true;
	q->serial = ++h->serial;
	pthread_cond_signal(&h->live_cv);
	/* Suspended before the want (a cached tile is reported at once, from the manager
	 * thread) and under the lock, so shutdown never resumes a request not yet suspended. */
	MHD_suspend_connection(c);
	pthread_mutex_unlock(&h->mu);
	*con_cls = q;
	struct want w[2] = { { .node = q->node[0], .key = key, .cls = SCHED_WEB },
			     { .node = q->node[1], .key = nkey, .cls = SCHED_WEB } };
	int rc = sched_req_want(q->req, w, (size_t)q->nkeys);
	if (rc < 0)
		on_ready(q, &w[0], NULL, rc);
	return MHD_YES;
}

/* The second call for a suspended request, once resumed. */
static enum MHD_Result tile_ready(struct http *h, struct MHD_Connection *c, struct hreq *q)
{
	pthread_mutex_lock(&q->mu);
	bool done = q->done, hungup = q->hungup;
	int err = q->err;
	struct tile *t = done && !err ? tile_ref(q->tile[0]) : NULL,
		    *nt = done && !err && q->tile[1] ? tile_ref(q->tile[1]) : NULL;
	pthread_mutex_unlock(&q->mu);
	if (hungup) {
		tile_unref(t);
		tile_unref(nt);
		return MHD_NO; /* the client is gone: close */
	}
	if (!done)
		return text(h, c, MHD_HTTP_SERVICE_UNAVAILABLE, "shutting down");
	if (!t)
		return text(h, c, MHD_HTTP_INTERNAL_SERVER_ERROR, "the tile could not be made: %s",
			    strerror(-err));
	enum MHD_Result res = send_tile(h, c, t, nt, q->fmt, q->terrain, q->etag);
	tile_unref(t);
	tile_unref(nt);
	return res;
}

/* A file of CesiumJS (rel checked by http_static_path_ok), sent from its descriptor. */
static enum MHD_Result static_file(struct http *h, struct MHD_Connection *c, const char *rel)
{
	if (!h->cesium_dir)
		return text(h, c, MHD_HTTP_NOT_FOUND, "no CesiumJS here (make deps installs it)");
	char path[1024];
	snprintf(path, sizeof path, "%s/%s", h->cesium_dir, rel);
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	struct stat st;
	if (fd < 0 || fstat(fd, &st) < 0 || !S_ISREG(st.st_mode)) {
		if (fd >= 0)
			close(fd);
		return text(h, c, MHD_HTTP_NOT_FOUND, "no such file: %s", rel);
	}
	struct MHD_Response *r = MHD_create_response_from_fd((uint64_t)st.st_size, fd);
	if (!r) {
		close(fd);
		return MHD_NO;
	}
	MHD_add_response_header(r, MHD_HTTP_HEADER_CONTENT_TYPE, http_mime_of(rel));
	MHD_add_response_header(r, MHD_HTTP_HEADER_CACHE_CONTROL, "public, max-age=86400");
	enum MHD_Result res = MHD_queue_response(c, MHD_HTTP_OK, r);
	MHD_destroy_response(r);
	atomic_fetch_add(&h->st_bytes, (uint64_t)st.st_size);
	return res;
}

static enum MHD_Result on_request(void *cls, struct MHD_Connection *c, const char *url,
				  const char *method, const char *version, const char *upload,
				  size_t *upload_size, void **con_cls)
{
	(void)version;
	(void)upload;
	struct http *h = cls;
	/* The first call comes with the headers: answering then would make libmicrohttpd close
	 * the connection (the request not read to its end), so answer from the second. */
	if (!*con_cls) {
		*con_cls = &headers_seen;
		return MHD_YES;
	}
	if (*con_cls != &headers_seen)
		return tile_ready(h, c, *con_cls);
	if (*upload_size) {
		*upload_size = 0; /* bodies are ignored: nothing here takes one */
		return MHD_YES;
	}
	atomic_fetch_add(&h->st_requests, 1);
	if (strcmp(method, MHD_HTTP_METHOD_GET) && strcmp(method, MHD_HTTP_METHOD_HEAD))
		return text(h, c, MHD_HTTP_METHOD_NOT_ALLOWED, "only GET and HEAD");
	struct http_route rt;
	http_route_parse(url, query(c, "SERVICE", "service"), query(c, "REQUEST", "request"), &rt);
	if (rt.kind == HTTP_HEALTH)
		return text(h, c, MHD_HTTP_OK, "ok");
	if (!authorized(h, c)) {
		atomic_fetch_add(&h->st_auth, 1);
		const union MHD_ConnectionInfo *ci =
			MHD_get_connection_info(c, MHD_CONNECTION_INFO_CLIENT_ADDRESS);
		char host[64] = "?";
		if (ci && ci->client_addr)
			getnameinfo(ci->client_addr, sizeof(struct sockaddr_storage), host, sizeof host,
				    NULL, 0, NI_NUMERICHOST);
		log_msg(LOG_WARN, "http: %s: missing or wrong bearer token", host);
		return text(h, c, MHD_HTTP_UNAUTHORIZED, "this endpoint requires "
							 "\"Authorization: Bearer TOKEN\"");
	}
	switch (rt.kind) {
	case HTTP_NOT_FOUND:
		return text(h, c, MHD_HTTP_NOT_FOUND, "no such path (see / for what is served)");
	case HTTP_BAD: return text(h, c, MHD_HTTP_BAD_REQUEST, "%s", rt.why);
	case HTTP_INDEX: return index_page(h, c);
	case HTTP_PAGE:
		if (!h->cesium_dir)
			return index_page(h, c);
		{
			size_t n;
			const char *pg = http_page_html(&n);
			return send_buf(h, c, MHD_HTTP_OK, "text/html; charset=utf-8", (void *)pg, n,
					false);
		}
	case HTTP_PLANETS_JSON: {
		struct planet_set *ps = current(h);
		size_t n;
		char *j = http_planets_json(ps, &n);
		planet_set_unref(ps);
		return send_buf(h, c, MHD_HTTP_OK, "application/json", j, n, true);
	}
	case HTTP_STATIC: return static_file(h, c, rt.rel);
	case HTTP_HEALTH: return text(h, c, MHD_HTTP_OK, "ok");
	case HTTP_READY: {
		struct planet_set *ps = current(h);
		size_t n = ps->n;
		planet_set_unref(ps);
		return n ? text(h, c, MHD_HTTP_OK, "ready: %zu planets", n)
			 : text(h, c, MHD_HTTP_SERVICE_UNAVAILABLE, "no planets loaded");
	}
	case HTTP_METRICS: {
		pthread_mutex_lock(&h->mu);
		char *m = h->metrics ? xmalloc(h->metrics_len + 1) : NULL;
		size_t n = h->metrics_len;
		if (m)
			memcpy(m, h->metrics, n + 1);
		pthread_mutex_unlock(&h->mu);
		if (!m)
			return text(h, c, MHD_HTTP_SERVICE_UNAVAILABLE, "metrics not gathered yet");
		return send_buf(h, c, MHD_HTTP_OK, "text/plain; version=0.0.4; charset=utf-8", m, n,
				true);
	}
	case HTTP_WMTS_CAPS: {
		char base[256];
		base_url(h, c, base, sizeof base);
		struct planet_set *ps = current(h);
		size_t n;
		char *x = wmts_capabilities(ps, base, &n);
		planet_set_unref(ps);
		return send_buf(h, c, MHD_HTTP_OK, "application/xml", x, n, true);
	}
	case HTTP_TILE:
	case HTTP_CESIUM_TILE: return tile_request(h, c, &rt, con_cls);
	case HTTP_CESIUM_LAYER: {
		struct planet_set *ps = current(h);
		const struct planet *p = planet_set_find(ps, rt.planet);
		if (!p || !height_layer(p)) {
			planet_set_unref(ps);
			return text(h, c, MHD_HTTP_NOT_FOUND, "no planet %s with heights", rt.planet);
		}
		size_t n;
		char *j = cesium_layer_json(p, cesium_normal_layer(p, height_layer(p)) != NULL, &n);
		planet_set_unref(ps);
		return send_buf(h, c, MHD_HTTP_OK, "application/json", j, n, true);
	}
	}
	return MHD_NO;
}

/* ---- life ------------------------------------------------------------------------------- */

int http_create(const struct http_desc *d, struct http **out, char err[256])
{
	char host[256], port[16];
	if (conf_split_hostport(d->listen, host, sizeof host, port, sizeof port))
		return err_inval(err, "http: \"%s\" is not host:port", d->listen);
	if (d->tls_cert && MHD_is_feature_supported(MHD_FEATURE_TLS) != MHD_YES) {
		err_set(err, "http: this libmicrohttpd has no TLS: [http] cannot serve HTTPS with "
			"[tls] cert and key");
		return -ENOTSUP;
	}
	struct addrinfo hints = { .ai_socktype = SOCK_STREAM, .ai_flags = AI_PASSIVE }, *ai = NULL;
	int g = getaddrinfo(host, port, &hints, &ai);
	if (g)
		return err_inval(err, "http: %s: %s", d->listen, gai_strerror(g));
	struct http *h = xcalloc(1, sizeof *h);
	h->sched = d->sched;
	h->cache = d->cache;
	h->max_age = d->max_age_s;
	h->cesium_dir = d->cesium_dir ? xstrdup(d->cesium_dir) : NULL;
	h->bodies = http_cache_create(d->cache_bytes ? d->cache_bytes : (size_t)64 << 20);
	h->ps = planet_set_ref(d->planets);
	if (d->token && d->token_len && d->token_len <= sizeof h->token) {
		memcpy(h->token, d->token, d->token_len);
		h->token_len = d->token_len;
	}
	pthread_mutex_init(&h->mu, NULL);
	pthread_cond_init(&h->live_cv, NULL);
	unsigned flags = MHD_USE_AUTO_INTERNAL_THREAD | MHD_ALLOW_SUSPEND_RESUME;
	if (ai->ai_family == AF_INET6)
		flags |= MHD_USE_IPv6;
	struct MHD_OptionItem tls[2] = { { MHD_OPTION_END, 0, NULL } };
	if (d->tls_cert) {
		int rc = http_tls_set(d->tls_cert, d->tls_key, err);
		if (rc) {
			freeaddrinfo(ai);
			planet_set_unref(h->ps);
			pthread_cond_destroy(&h->live_cv);
			pthread_mutex_destroy(&h->mu);
			http_cache_destroy(h->bodies);
			free(h->cesium_dir);
			free(h);
			return rc;
		}
		h->tls = true;
		flags |= MHD_USE_TLS;
		/* the certificate through a callback, so that a reload can replace it */
		tls[0] = (struct MHD_OptionItem){ MHD_OPTION_HTTPS_CERT_CALLBACK, 0,
						  http_tls_callback() };
		tls[1] = (struct MHD_OptionItem){ MHD_OPTION_END, 0, NULL };
	}
	h->d = MHD_start_daemon(
		flags, 0, NULL, NULL, on_request, h, MHD_OPTION_SOCK_ADDR, ai->ai_addr,
		MHD_OPTION_THREAD_POOL_SIZE, (unsigned)(d->threads > 0 ? d->threads : 2),
		MHD_OPTION_CONNECTION_LIMIT, (unsigned)(d->max_conns > 0 ? d->max_conns : 256),
		MHD_OPTION_PER_IP_CONNECTION_LIMIT, (unsigned)(d->max_per_addr > 0 ? d->max_per_addr : 0),
		MHD_OPTION_CONNECTION_TIMEOUT, (unsigned)(d->timeout_s > 0 ? d->timeout_s : 15),
		/* A request's headers and path fit in 32 KiB (the default is 32 KiB too). */
		MHD_OPTION_CONNECTION_MEMORY_LIMIT, (size_t)32 << 10, MHD_OPTION_NOTIFY_COMPLETED,
		on_completed, h, MHD_OPTION_ARRAY, tls, MHD_OPTION_END);
	freeaddrinfo(ai);
	if (!h->d) {
		int e = errno ? errno : EADDRINUSE;
		err_set(err, "http: cannot listen on %s: %s", d->listen, strerror(e));
		planet_set_unref(h->ps);
		pthread_cond_destroy(&h->live_cv);
		pthread_mutex_destroy(&h->mu);
		http_cache_destroy(h->bodies);
		free(h->cesium_dir);
		if (h->tls)
			http_tls_clear();
		free(h);
		return -e;
	}
	const union MHD_DaemonInfo *di = MHD_get_daemon_info(h->d, MHD_DAEMON_INFO_BIND_PORT);
	h->port = di ? di->port : 0;
	int e = pthread_create(&h->watcher, NULL, watch_hangups, h);
	if (e) {
		log_msg(LOG_ERROR, "http: cannot start the hang-up watcher: %s", strerror(e));
		abort(); /* as the scheduler does: the daemon does not run without its threads */
	}
	*out = h;
	return 0;
}

void http_destroy(struct http *h)
{
	if (!h)
		return;
	/* Stop the scheduler's requests first (no callback after sched_req_destroy), then resume
	 * every suspended connection: its handler answers 503. */
	pthread_mutex_lock(&h->mu);
	h->stopping = true;
	pthread_cond_signal(&h->live_cv);
	pthread_mutex_unlock(&h->mu);
	pthread_join(h->watcher, NULL);
	pthread_mutex_lock(&h->mu);
	struct hreq *live = h->live;
	h->live = NULL;
	pthread_mutex_unlock(&h->mu);
	for (struct hreq *q = live; q; q = q->next) {
		sched_req_destroy(q->req);
		q->req = NULL;
	}
	for (struct hreq *q = live, *next; q; q = next) {
		next = q->next;
		q->prev = q->next = NULL;
		MHD_resume_connection(q->c);
	}
	MHD_stop_daemon(h->d);
	planet_set_unref(h->ps);
	free(h->metrics);
	http_cache_destroy(h->bodies);
	free(h->cesium_dir);
	if (h->tls)
		http_tls_clear(); /* after MHD stopped: no handshake is left */
	pthread_cond_destroy(&h->live_cv);
	pthread_mutex_destroy(&h->mu);
	free(h);
}

uint16_t http_port(const struct http *h) { return h->port; }

int http_reload_tls(struct http *h, const char *cert_pem, const char *key_pem, char err[256])
{
	if (!h->tls) {
		err_set(err, "https: the endpoint was started without TLS");
		return -EINVAL;
	}
	return http_tls_set(cert_pem, key_pem, err);
}

void http_set_planets(struct http *h, struct planet_set *ps)
{
	struct planet_set *n = planet_set_ref(ps);
	pthread_mutex_lock(&h->mu);
	struct planet_set *old = h->ps;
	h->ps = n;
	pthread_mutex_unlock(&h->mu);
	planet_set_unref(old);
}

void http_set_metrics(struct http *h, const char *text_, size_t n)
{
	char *m = xmalloc(n + 1);
	memcpy(m, text_, n);
	m[n] = '\0';
	pthread_mutex_lock(&h->mu);
	char *old = h->metrics;
	h->metrics = m;
	h->metrics_len = n;
	pthread_mutex_unlock(&h->mu);
	free(old);
}

void http_get_stats(struct http *h, struct http_stats *o)
{
	struct http_cache_stats cs;
	http_cache_stats(h->bodies, &cs);
	*o = (struct http_stats){ .requests = atomic_load(&h->st_requests),
				  .tiles = atomic_load(&h->st_tiles),
				  .not_modified = atomic_load(&h->st_304),
				  .client_errors = atomic_load(&h->st_4xx),
				  .server_errors = atomic_load(&h->st_5xx),
				  .auth_failures = atomic_load(&h->st_auth),
				  .bytes = atomic_load(&h->st_bytes),
				  .cancelled = atomic_load(&h->st_cancelled),
				  .cache_hits = cs.hits, .cache_misses = cs.misses,
				  .cache_bytes = cs.bytes };
}
