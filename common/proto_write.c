/* proto_write — the writing half of the protocol module (proto.h): output buffers, message
 * encoders and the pure session helpers (state table, limits, rate bucket). Split from
 * proto.c only to keep each file readable; the decoder there is the single statement of
 * what is valid, and every encoder checks its output with it before returning.
 *
 * Thread-safety: reentrant; a pbuf has one owner. Ownership: see proto.h.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "errbuf.h"
#include "proto.h"
#include "xalloc.h"


/* ---- pbuf ------------------------------------------------------------------------------- */

void pbuf_init(struct pbuf *b)
{
	*b = (struct pbuf){ 0 };
}

void pbuf_init_fixed(struct pbuf *b, void *mem, size_t cap)
{
	*b = (struct pbuf){ .data = mem, .cap = cap, .fixed = true };
}

void pbuf_fini(struct pbuf *b)
{
	if (!b->fixed)
		free(b->data);
	*b = (struct pbuf){ 0 };
}

int pbuf_reserve(struct pbuf *b, size_t n)
{
	if (b->cap - b->len >= n)
		return 0;
	if (b->fixed)
		return -ENOSPC;
	size_t cap = b->cap ? b->cap : 256;
	while (cap - b->len < n)
		cap *= 2;
	b->data = xrealloc(b->data, cap);
	b->cap = cap;
	return 0;
}

int pbuf_append(struct pbuf *b, const void *p, size_t n)
{
	int rc = pbuf_reserve(b, n);
	if (rc)
		return rc;
	if (n)
		memcpy(b->data + b->len, p, n);
	b->len += n;
	return 0;
}

void pbuf_consume(struct pbuf *b, size_t n)
{
	if (n >= b->len) {
		b->len = 0;
		return;
	}
	memmove(b->data, b->data + n, b->len - n);
	b->len -= n;
}

/* ---- writer ----------------------------------------------------------------------------- */

struct wr {
	struct pbuf *b;
	int err; /* sticky: -ENOSPC or -EINVAL */
	char *errbuf;
};

static void put(struct wr *w, const void *p, size_t n)
{
	if (!w->err && pbuf_append(w->b, p, n)) {
		w->err = -ENOSPC;
		err_set(w->errbuf, "output buffer full");
	}
}

static void w8(struct wr *w, uint8_t v)
{
	put(w, &v, 1);
}

static void w16(struct wr *w, uint16_t v)
{
	uint8_t b[2] = { (uint8_t)v, (uint8_t)(v >> 8) };
	put(w, b, 2);
}

static void w32(struct wr *w, uint32_t v)
{
	uint8_t b[4] = { (uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24) };
	put(w, b, 4);
}

static void w64(struct wr *w, uint64_t v)
{
	w32(w, (uint32_t)v);
	w32(w, (uint32_t)(v >> 32));
}

static void wf64(struct wr *w, double d)
{
	uint64_t u;
	memcpy(&u, &d, sizeof(u));
	w64(w, u);
}

static void wbytes(struct wr *w, const void *p, size_t n, const char *what)
{
	if (n > UINT16_MAX) {
		if (!w->err)
			err_set(w->errbuf, "%s of %zu bytes is too long", what, n);
		w->err = w->err ? w->err : -EINVAL;
		return;
	}
	w16(w, (uint16_t)n);
	put(w, p, n);
}

static void wstr(struct wr *w, const char *s, const char *what)
{
	wbytes(w, s ? s : "", s ? strlen(s) : 0, what);
}

static bool wcount(struct wr *w, size_t count, size_t cap, const char *what)
{
	if (count <= cap)
		return true;
	if (!w->err) {
		err_set(w->errbuf, "%zu %s exceed the cap of %zu", count, what, cap);
		w->err = PROTO_ERR_LIMIT;
	}
	return false;
}

static void enc_planet(struct wr *w, const struct proto_planet *p)
{
	wstr(w, p->name, "planet name");
	wstr(w, p->description, "description");
	wf64(w, p->a);
	wf64(w, p->f);
	w32(w, p->tile_size);
	w8(w, p->max_level);
	w16(w, p->nlayers);
	if (!wcount(w, p->nlayers, PROTO_MAX_LAYERS, "layers"))
		return;
	for (uint16_t i = 0; i < p->nlayers; i++) {
		const struct proto_layer *l = &p->layers[i];
		if (!proto_layer_normal_of_valid(p->layers, p->nlayers, i)) {
			if (!w->err) {
				err_set(w->errbuf, "layer %s: normal_of %u is not a normal layer made "
					"of a height layer", l->name ? l->name : "?", l->normal_of);
				w->err = PROTO_ERR_FIELD;
			}
			return;
		}
		wstr(w, l->name, "layer name");
		w8(w, l->format);
		w64(w, l->node);
		w8(w, l->normal_of);
	}
	wf64(w, p->air_density);
	wf64(w, p->air_height);
	for (int i = 0; i < 3; i++)
		w8(w, p->air_color[i]);
	w8(w, p->sea);
	wf64(w, p->sea_level);
	w8(w, p->sea_mask);
	const struct sea_grid *g = &p->sea_grid;
	if (!sea_grid_valid_size(g->rows, g->cols) || (g->rows && !g->dm)) {
		if (!w->err) {
			err_set(w->errbuf, "sea grid %u × %u is not a lattice", g->rows, g->cols);
			w->err = PROTO_ERR_FIELD;
		}
		return;
	}
	w16(w, g->rows);
	w16(w, g->cols);
	for (size_t i = 0; i < (size_t)g->rows * g->cols; i++)
		w16(w, (uint16_t)g->dm[i]);
}

static void enc_tile_head(struct wr *w, const struct proto_tile *t)
{
	w32(w, t->seq);
	w32(w, t->planet_id);
	w8(w, t->layer);
	w8(w, t->key.lx);
	w8(w, t->key.ly);
	w8(w, t->enc.format);
	w8(w, t->enc.codec);
	w8(w, t->enc.filter);
	w16(w, (uint16_t)t->enc.size);
	w32(w, t->key.x);
	w32(w, t->key.y);
	w64(w, t->key.node);
	w32(w, t->enc.raw_len);
	w64(w, t->enc.checksum);
}

/* One encoder per message kind: the fields in wire order (docs/PROTOCOL.md). */

static void enc_hello(struct wr *w, const struct proto_msg *m)
{
	const struct proto_hello *h = &m->hello;
	w8(w, h->ver_min);
	w8(w, h->ver_max);
	w32(w, h->codecs);
	wbytes(w, h->token, h->token_len, "token");
	wstr(w, h->name, "client name");
}

static void enc_hello_ok(struct wr *w, const struct proto_msg *m)
{
	const struct proto_hello_ok *h = &m->hello_ok;
	w8(w, h->version);
	w32(w, h->codecs);
	w64(w, h->session);
	w32(w, h->limits.max_want);
	w32(w, h->limits.max_rate);
	w64(w, h->limits.max_pending);
	w32(w, h->limits.max_frame);
	wstr(w, h->name, "server name");
}

static void enc_error(struct wr *w, const struct proto_msg *m)
{
	w16(w, m->error.code);
	w16(w, m->error.ref_type);
	w32(w, m->error.ref_id);
	wstr(w, m->error.message, "message");
}

/* LIST_PLANETS, STATS_REQ and PREFETCH_CANCEL: the same struct proto_req in all three. */
static void enc_req(struct wr *w, const struct proto_msg *m)
{
	w32(w, m->list_planets.req);
}

static void enc_planets(struct wr *w, const struct proto_msg *m)
{
	w32(w, m->planets.req);
	w16(w, m->planets.count);
	if (!wcount(w, m->planets.count, PROTO_MAX_PLANETS, "planets"))
		return;
	for (uint16_t i = 0; i < m->planets.count; i++)
		enc_planet(w, &m->planets.planets[i]);
}

static void enc_open(struct wr *w, const struct proto_msg *m)
{
	w32(w, m->open.req);
	wstr(w, m->open.name, "planet name");
}

static void enc_opened(struct wr *w, const struct proto_msg *m)
{
	w32(w, m->opened.req);
	w32(w, m->opened.planet_id);
	enc_planet(w, &m->opened.planet);
}

static void enc_want(struct wr *w, const struct proto_msg *m)
{
	const struct proto_want *q = &m->want;
	w32(w, q->planet_id);
	w32(w, q->seq);
	wf64(w, q->lon);
	wf64(w, q->lat);
	wf64(w, q->alt);
	for (int i = 0; i < 3; i++)
		wf64(w, q->vel[i]);
	w32(w, q->count);
	if (!wcount(w, q->count, PROTO_MAX_WANT, "want entries"))
		return;
	for (uint32_t i = 0; i < q->count; i++) {
		const struct proto_want_entry *e = &q->entries[i];
		uint8_t b[12] = { e->layer, e->cls, e->lx, e->ly };
		for (int k = 0; k < 4; k++) {
			b[4 + k] = (uint8_t)(e->x >> 8 * k);
			b[8 + k] = (uint8_t)(e->y >> 8 * k);
		}
		put(w, b, sizeof(b));
	}
}

static void enc_tile(struct wr *w, const struct proto_msg *m)
{
	if (m->tile.payload_len && !m->tile.payload) {
		err_set(w->errbuf, "TILE without its payload");
		w->err = -EINVAL;
		return;
	}
	enc_tile_head(w, &m->tile);
	put(w, m->tile.payload, m->tile.payload_len);
}

static void enc_tile_part(struct wr *w, const struct proto_msg *m)
{
	const struct proto_tile_part *t = &m->tile_part;
	if (t->len && !t->bytes) {
		err_set(w->errbuf, "TILE_PART without its bytes");
		w->err = -EINVAL;
		return;
	}
	w32(w, t->offset);
	w32(w, t->total);
	if (t->offset == 0)
		enc_tile_head(w, &t->tile);
	put(w, t->bytes, t->len);
}

static void enc_tile_fail(struct wr *w, const struct proto_msg *m)
{
	const struct proto_tile_fail *t = &m->tile_fail;
	w32(w, t->seq);
	w32(w, t->planet_id);
	w8(w, t->layer);
	w8(w, t->key.lx);
	w8(w, t->key.ly);
	w32(w, t->key.x);
	w32(w, t->key.y);
	w64(w, t->key.node);
	w16(w, t->code);
	wstr(w, t->message, "message");
}

static void enc_stat(struct wr *w, const struct proto_stat *s)
{
	wstr(w, s->key, "stat key");
	w8(w, s->kind);
	if (s->kind == PROTO_STAT_U64)
		w64(w, s->u);
	else if (s->kind == PROTO_STAT_F64)
		wf64(w, s->f);
	else if (s->kind == PROTO_STAT_STR)
		wstr(w, s->s, "stat value");
}

static void enc_stats(struct wr *w, const struct proto_msg *m)
{
	w32(w, m->stats.req);
	w16(w, m->stats.count);
	if (!wcount(w, m->stats.count, PROTO_MAX_STATS, "stats"))
		return;
	for (uint16_t i = 0; i < m->stats.count; i++)
		enc_stat(w, &m->stats.items[i]);
}

static void enc_cache_ls(struct wr *w, const struct proto_msg *m)
{
	const struct proto_cache_ls *c = &m->cache_ls;
	w32(w, c->req);
	w8(w, c->filter);
	wstr(w, c->planet, "planet");
	w8(w, c->lx);
	w8(w, c->ly);
	wf64(w, c->lon);
	wf64(w, c->lat);
	wf64(w, c->radius_m);
	w32(w, c->limit);
}

static void enc_cache_entry(struct wr *w, const struct proto_cache_entry *e)
{
	w64(w, e->key.node);
	w8(w, e->key.lx);
	w8(w, e->key.ly);
	w8(w, e->format);
	w8(w, e->tier);
	w32(w, e->key.x);
	w32(w, e->key.y);
	w32(w, e->bytes);
	w32(w, e->age_s);
}

static void enc_cache_entries(struct wr *w, const struct proto_msg *m)
{
	const struct proto_cache_entries *c = &m->cache_entries;
	w32(w, c->req);
	w8(w, c->more);
	w64(w, c->total);
	w32(w, c->count);
	if (!wcount(w, c->count, PROTO_MAX_CACHE_ENTRIES, "cache entries"))
		return;
	for (uint32_t i = 0; i < c->count; i++)
		enc_cache_entry(w, &c->entries[i]);
}

static void enc_polygon(struct wr *w, uint32_t nrings, const uint32_t *rings,
			const struct proto_lonlat *points)
{
	w32(w, nrings);
	if (!wcount(w, nrings, PROTO_MAX_RINGS, "polygon rings"))
		return;
	size_t n = 0;
	for (uint32_t i = 0; i < nrings; i++) {
		w32(w, rings[i]);
		n += rings[i];
	}
	if (!wcount(w, n, PROTO_MAX_POLY, "polygon points"))
		return;
	for (size_t i = 0; i < n; i++) {
		wf64(w, points[i].lon);
		wf64(w, points[i].lat);
	}
}

static void enc_prefetch(struct wr *w, const struct proto_msg *m)
{
	const struct proto_prefetch *p = &m->prefetch;
	w32(w, p->id);
	wstr(w, p->planet, "planet");
	w64(w, p->layers);
	w8(w, p->shape);
	w8(w, p->lmin);
	w8(w, p->lmax);
	if (p->shape == PROTO_SHAPE_BBOX) {
		wf64(w, p->bbox.west);
		wf64(w, p->bbox.south);
		wf64(w, p->bbox.east);
		wf64(w, p->bbox.north);
	} else if (p->shape == PROTO_SHAPE_PATH) {
		wf64(w, p->width_m);
		w32(w, p->npoints);
		if (!wcount(w, p->npoints, PROTO_MAX_PATH, "path points"))
			return;
		for (uint32_t i = 0; i < p->npoints; i++) {
			wf64(w, p->points[i].lon);
			wf64(w, p->points[i].lat);
		}
	} else if (p->shape == PROTO_SHAPE_POLYGON) {
		enc_polygon(w, p->nrings, p->rings, p->points);
	}
}

static void enc_prefetch_progress(struct wr *w, const struct proto_msg *m)
{
	const struct proto_prefetch_progress *p = &m->prefetch_progress;
	w32(w, p->id);
	w8(w, p->state);
	w64(w, p->done);
	w64(w, p->total);
	wf64(w, p->rate);
}

static void enc_cache_op(struct wr *w, const struct proto_msg *m)
{
	const struct proto_cache_op *c = &m->cache_op;
	w32(w, c->req);
	w8(w, c->op);
	wstr(w, c->planet, "planet");
	w8(w, c->filter);
	wf64(w, c->bbox.west);
	wf64(w, c->bbox.south);
	wf64(w, c->bbox.east);
	wf64(w, c->bbox.north);
	w8(w, c->lmin);
	w8(w, c->lmax);
	if ((c->filter & PROTO_COF_POLYGON) && c->op == PROTO_COP_PURGE)
		enc_polygon(w, c->nrings, c->rings, c->points);
}

static void enc_cache_stat(struct wr *w, const struct proto_msg *m)
{
	const struct proto_cache_stat *c = &m->cache_stat;
	w32(w, c->req);
	w8(w, c->more);
	w32(w, c->count);
	if (!wcount(w, c->count, PROTO_MAX_STAT_ROWS, "stat rows"))
		return;
	for (uint32_t i = 0; i < c->count; i++) {
		wstr(w, c->rows[i].planet, "planet");
		wstr(w, c->rows[i].layer, "layer");
		w8(w, c->rows[i].ly);
		w8(w, c->rows[i].tier);
		w64(w, c->rows[i].tiles);
		w64(w, c->rows[i].bytes);
	}
}

static void enc_cache_done(struct wr *w, const struct proto_msg *m)
{
	const struct proto_cache_done *c = &m->cache_done;
	w32(w, c->req);
	w8(w, c->op);
	w64(w, c->checked);
	w64(w, c->removed);
	w64(w, c->bytes);
	w64(w, c->corrupt);
}

static void enc_prefetch_dry(struct wr *w, const struct proto_msg *m)
{
	struct proto_msg p = { .type = PROTO_PREFETCH, .prefetch = m->prefetch_dry };
	enc_prefetch(w, &p);
}

static void enc_prefetch_estimate(struct wr *w, const struct proto_msg *m)
{
	const struct proto_prefetch_estimate *e = &m->prefetch_estimate;
	w32(w, e->id);
	w8(w, e->tier);
	w64(w, e->tiles);
	w64(w, e->bytes);
	w64(w, e->budget);
	w64(w, e->used);
	w64(w, e->max_tiles);
	w8(w, e->nlevels);
	if (!wcount(w, e->nlevels, GRID_MAX_LEVEL + 1, "estimate levels"))
		return;
	for (uint32_t i = 0; i < e->nlevels; i++) {
		w8(w, e->levels[i].ly);
		w64(w, e->levels[i].tiles);
		w64(w, e->levels[i].bytes);
	}
}

typedef void enc_fn(struct wr *w, const struct proto_msg *m);

/* The body encoder of every message type; NULL: no body (BYE). */
static const struct {
	uint16_t type;
	enc_fn *enc;
} encoders[] = {
	{ PROTO_HELLO, enc_hello },
	{ PROTO_HELLO_OK, enc_hello_ok },
	{ PROTO_BYE, NULL },
	{ PROTO_ERROR, enc_error },
	{ PROTO_LIST_PLANETS, enc_req },
	{ PROTO_PLANETS, enc_planets },
	{ PROTO_OPEN, enc_open },
	{ PROTO_OPENED, enc_opened },
	{ PROTO_WANT, enc_want },
	{ PROTO_TILE, enc_tile },
	{ PROTO_TILE_FAIL, enc_tile_fail },
	{ PROTO_TILE_PART, enc_tile_part },
	{ PROTO_STATS_REQ, enc_req },
	{ PROTO_STATS, enc_stats },
	{ PROTO_CACHE_LS, enc_cache_ls },
	{ PROTO_CACHE_ENTRIES, enc_cache_entries },
	{ PROTO_CACHE_OP, enc_cache_op },
	{ PROTO_CACHE_STAT, enc_cache_stat },
	{ PROTO_CACHE_DONE, enc_cache_done },
	{ PROTO_PREFETCH, enc_prefetch },
	{ PROTO_PREFETCH_PROGRESS, enc_prefetch_progress },
	{ PROTO_PREFETCH_CANCEL, enc_req },
	{ PROTO_PREFETCH_DRY, enc_prefetch_dry },
	{ PROTO_PREFETCH_ESTIMATE, enc_prefetch_estimate },
};

/* m's payload; its type is known (proto_type_name gave it a name). */
static void enc_body(struct wr *w, const struct proto_msg *m)
{
	for (size_t i = 0; i < sizeof(encoders) / sizeof(encoders[0]); i++) {
		if (encoders[i].type == m->type) {
			if (encoders[i].enc)
				encoders[i].enc(w, m);
			return;
		}
	}
	err_set(w->errbuf, "no encoder for message type %u", m->type);
	w->err = -EINVAL;
}

static void put_header(struct wr *w, uint16_t type, uint32_t length)
{
	put(w, PROTO_MAGIC, 4);
	w8(w, PROTO_VERSION);
	w8(w, 0);
	w16(w, type);
	w32(w, length);
}

ssize_t proto_encode(struct pbuf *b, const struct proto_msg *m, char err[256])
{
	const char *name = proto_type_name(m->type);
	if (!name) {
		err_set(err, "unknown message type %u", m->type);
		return -EINVAL;
	}
	size_t start = b->len;
	struct wr w = { .b = b, .errbuf = err };
	put_header(&w, m->type, 0);
	enc_body(&w, m);
	if (w.err)
		goto fail;
	size_t length = b->len - start - PROTO_HDR;
	if (length > proto_type_cap(m->type)) {
		err_set(err, "%s of %zu bytes exceeds its cap of %u", name, length,
		       proto_type_cap(m->type));
		w.err = -EMSGSIZE;
		goto fail;
	}
	for (int k = 0; k < 4; k++)
		b->data[start + 8 + k] = (uint8_t)(length >> 8 * k);
	struct proto_msg check;
	int rc = proto_decode_payload(m->type, b->data + start + PROTO_HDR, length, &check, err);
	proto_msg_fini(&check);
	if (rc) {
		w.err = rc == PROTO_ERR_LIMIT ? -E2BIG : -EINVAL;
		goto fail;
	}
	return (ssize_t)(b->len - start);
fail:
	b->len = start;
	return w.err;
}

ssize_t proto_encode_tile_head(struct pbuf *b, const struct proto_tile *t, char err[256])
{
	int rc = proto_tile_check(t, err);
	if (rc)
		return rc;
	size_t start = b->len;
	struct wr w = { .b = b, .errbuf = err };
	put_header(&w, PROTO_TILE, 44 + t->payload_len);
	enc_tile_head(&w, t);
	if (w.err) {
		b->len = start;
		return w.err;
	}
	return (ssize_t)(b->len - start);
}

ssize_t proto_encode_tile_part_head(struct pbuf *b, const struct proto_tile *t, uint32_t offset,
				    uint32_t len, char err[256])
{
	if (len == 0 || len > t->payload_len || offset > t->payload_len - len) {
		err_set(err, "part of %u bytes at %u of a %u-byte tile", len, offset,
			t->payload_len);
		return -EINVAL;
	}
	int rc = offset ? 0 : proto_tile_check(t, err);
	if (rc)
		return rc;
	size_t start = b->len;
	struct wr w = { .b = b, .errbuf = err };
	put_header(&w, PROTO_TILE_PART,
		   (offset ? PROTO_PART_HEAD : PROTO_PART_FIRST_HEAD) + len);
	w32(&w, offset);
	w32(&w, t->payload_len);
	if (!offset)
		enc_tile_head(&w, t);
	if (w.err) {
		b->len = start;
		return w.err;
	}
	return (ssize_t)(b->len - start);
}

/* ---- session helpers -------------------------------------------------------------------- */

static bool from_client(uint16_t type)
{
	switch (type) {
	case PROTO_HELLO: case PROTO_BYE: case PROTO_ERROR: case PROTO_LIST_PLANETS:
	case PROTO_OPEN: case PROTO_WANT: case PROTO_STATS_REQ: case PROTO_CACHE_LS:
	case PROTO_PREFETCH: case PROTO_PREFETCH_CANCEL: case PROTO_PREFETCH_DRY:
	case PROTO_CACHE_OP:
		return true;
	default:
		return false;
	}
}

static bool from_server(uint16_t type)
{
	switch (type) {
	case PROTO_HELLO_OK: case PROTO_BYE: case PROTO_ERROR: case PROTO_PLANETS:
	case PROTO_OPENED: case PROTO_TILE: case PROTO_TILE_FAIL: case PROTO_TILE_PART:
	case PROTO_STATS:
	case PROTO_CACHE_ENTRIES: case PROTO_PREFETCH_PROGRESS: case PROTO_PREFETCH_ESTIMATE:
	case PROTO_CACHE_STAT: case PROTO_CACHE_DONE:
		return true;
	default:
		return false;
	}
}

int proto_check_state(enum proto_state st, bool server, uint16_t type, char err[256])
{
	const char *name = proto_type_name(type);
	const char *peer = server ? "server" : "client";
	if (!name) {
		err_set(err, "unknown message type %u", type);
		return PROTO_ERR_TYPE;
	}
	if (server ? !from_server(type) : !from_client(type)) {
		err_set(err, "a %s does not send %s", peer, name);
		return PROTO_ERR_STATE;
	}
	bool handshake = type == PROTO_HELLO || type == PROTO_HELLO_OK;
	bool ok;
	switch (st) {
	case PROTO_ST_HANDSHAKE:
		ok = handshake || type == PROTO_BYE || (server && type == PROTO_ERROR);
		break;
	case PROTO_ST_READY:
		ok = !handshake;
		break;
	default:
		ok = false;
		break;
	}
	if (!ok) {
		err_set(err, "%s from the %s is not allowed %s", name, peer,
		       st == PROTO_ST_HANDSHAKE ? "before the handshake"
		       : st == PROTO_ST_READY ? "after the handshake"
					      : "after BYE");
		return PROTO_ERR_STATE;
	}
	return 0;
}

int proto_check_limits(const struct proto_limits *l, const struct proto_msg *m,
		       size_t frame_len, char err[256])
{
	if (l->max_frame && frame_len > l->max_frame) {
		err_set(err, "%s of %zu bytes exceeds this session's frame limit of %u bytes",
		       proto_type_name(m->type), frame_len, l->max_frame);
		return -E2BIG;
	}
	if (m->type == PROTO_WANT && l->max_want && m->want.count > l->max_want) {
		err_set(err, "want-set of %u entries exceeds this session's limit of %u",
		       m->want.count, l->max_want);
		return -E2BIG;
	}
	return 0;
}

bool proto_rate_take(struct proto_rate *r, uint64_t now_ns, uint32_t rate, uint32_t burst)
{
	if (rate == 0)
		return true;
	if (burst == 0)
		burst = rate;
	if (!r->started) {
		r->started = true;
		r->tokens = burst;
		r->last_ns = now_ns;
	}
	if (now_ns > r->last_ns) {
		r->tokens += (double)(now_ns - r->last_ns) * 1e-9 * rate;
		if (r->tokens > burst)
			r->tokens = burst;
		r->last_ns = now_ns;
	}
	if (r->tokens < 1.0)
		return false;
	r->tokens -= 1.0;
	return true;
}
