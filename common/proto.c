/* proto — framing and message codec of the clipmap protocol. See proto.h and docs/PROTOCOL.md.
 *
 * Design note: each message has one decoder (decode_*), which is the single statement of
 * what is valid. The encoder writes the fields and then runs that decoder over what it wrote,
 * so a peer never receives a message it must reject, without a second copy of the rules.
 * Every integer is written byte by byte, little-endian; floats are their IEEE-754 bits.
 * Decoded strings and arrays live in a per-message arena whose size is bounded by the list
 * caps (each array's count is checked against the cap and the bytes left before allocating).
 */
#include "proto.h"

#include <math.h>
#include <stdalign.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "errbuf.h"
#include "xalloc.h"

struct type_info {
	uint16_t type;
	const char *name;
	uint32_t cap;  /* payload bytes */
	uint8_t sides; /* 1: from client, 2: from server, 3: both */
};

#define FROM_CLIENT 1
#define FROM_SERVER 2

static const struct type_info types[] = {
	{ PROTO_HELLO, "HELLO", 2048, FROM_CLIENT },
	{ PROTO_HELLO_OK, "HELLO_OK", 512, FROM_SERVER },
	{ PROTO_BYE, "BYE", 0, FROM_CLIENT | FROM_SERVER },
	{ PROTO_ERROR, "ERROR", 8192, FROM_CLIENT | FROM_SERVER },
	{ PROTO_LIST_PLANETS, "LIST_PLANETS", 4, FROM_CLIENT },
	{ PROTO_PLANETS, "PLANETS", 8u << 20, FROM_SERVER },
	{ PROTO_OPEN, "OPEN", 512, FROM_CLIENT },
	{ PROTO_OPENED, "OPENED", (32u << 10) + 2u * SEA_GRID_MAX_ROWS * SEA_GRID_MAX_COLS,
	  FROM_SERVER }, /* the planet and its sea's lattice */
	{ PROTO_WANT, "WANT", 64u << 10, FROM_CLIENT },
	{ PROTO_TILE, "TILE", PROTO_MAX_FRAME, FROM_SERVER },
	{ PROTO_TILE_FAIL, "TILE_FAIL", 8192, FROM_SERVER },
	{ PROTO_TILE_PART, "TILE_PART", PROTO_MAX_FRAME, FROM_SERVER },
	{ PROTO_STATS_REQ, "STATS_REQ", 4, FROM_CLIENT },
	{ PROTO_STATS, "STATS", 8u << 20, FROM_SERVER },
	{ PROTO_CACHE_LS, "CACHE_LS", 512, FROM_CLIENT },
	{ PROTO_CACHE_ENTRIES, "CACHE_ENTRIES", 512u << 10, FROM_SERVER },
	{ PROTO_CACHE_OP, "CACHE_OP", 128u << 10, FROM_CLIENT },
	{ PROTO_CACHE_STAT, "CACHE_STAT", 4u << 20, FROM_SERVER },
	{ PROTO_CACHE_DONE, "CACHE_DONE", 64, FROM_SERVER },
	{ PROTO_PREFETCH, "PREFETCH", 128u << 10, FROM_CLIENT },
	{ PROTO_PREFETCH_PROGRESS, "PREFETCH_PROGRESS", 64, FROM_SERVER },
	{ PROTO_PREFETCH_CANCEL, "PREFETCH_CANCEL", 4, FROM_CLIENT },
	{ PROTO_PREFETCH_DRY, "PREFETCH_DRY", 128u << 10, FROM_CLIENT },
	{ PROTO_PREFETCH_ESTIMATE, "PREFETCH_ESTIMATE", 1024, FROM_SERVER },
};

static const char *const code_names[PROTO_E_COUNT] = {
	"none", "protocol", "version", "auth", "state", "not-found", "limit", "invalid",
	"unavailable", "busy", "internal", "shutdown",
};

#define TILE_HEAD 44 /* TILE fields before the payload */


static const struct type_info *type_info(uint16_t type)
{
	for (size_t i = 0; i < sizeof(types) / sizeof(types[0]); i++)
		if (types[i].type == type)
			return &types[i];
	return NULL;
}

uint32_t proto_type_cap(uint16_t type)
{
	const struct type_info *ti = type_info(type);
	return ti ? ti->cap : 0;
}

const char *proto_type_name(uint16_t type)
{
	const struct type_info *ti = type_info(type);
	return ti ? ti->name : NULL;
}

const char *proto_code_name(uint16_t code)
{
	return code < PROTO_E_COUNT ? code_names[code] : NULL;
}

uint16_t proto_code_from_err(int err)
{
	switch (err) {
	case 0:
		return PROTO_E_NONE;
	case PROTO_ERR_VERSION:
		return PROTO_E_VERSION;
	case PROTO_ERR_STATE:
		return PROTO_E_STATE;
	case PROTO_ERR_LIMIT:
		return PROTO_E_LIMIT;
	case PROTO_ERR_MAGIC:
	case PROTO_ERR_TOOBIG:
	case PROTO_ERR_TRUNC:
	case PROTO_ERR_TYPE:
	case PROTO_ERR_FIELD:
		return PROTO_E_PROTOCOL;
	case -ENOENT:
		return PROTO_E_NOT_FOUND;
	case -EACCES:
		return PROTO_E_AUTH;
	case -EAGAIN:
	case -EBUSY:
		return PROTO_E_BUSY;
	default:
		return PROTO_E_INTERNAL;
	}
}

/* ---- framing ---------------------------------------------------------------------------- */

static uint32_t get32(const uint8_t *p)
{
	return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

ssize_t proto_frame_check(const void *buf, size_t len, struct proto_hdr *h, size_t *need,
			  char err[256])
{
	const uint8_t *p = buf;
	size_t nm = len < 4 ? len : 4;
	if (nm && memcmp(p, PROTO_MAGIC, nm) != 0) {
		err_set(err, "bad magic: not a clipmap protocol stream");
		return PROTO_ERR_MAGIC;
	}
	if (len > 4 && p[4] != PROTO_VERSION) {
		err_set(err, "frame version %u, this side speaks %u", p[4], PROTO_VERSION);
		return PROTO_ERR_VERSION;
	}
	if (len > 5 && p[5] != 0) {
		err_set(err, "frame flags 0x%02x: none are defined", p[5]);
		return PROTO_ERR_FIELD;
	}
	const struct type_info *ti = NULL;
	if (len >= 8) {
		uint16_t type = (uint16_t)(p[6] | p[7] << 8);
		ti = type_info(type);
		if (!ti) {
			err_set(err, "unknown message type %u", type);
			return PROTO_ERR_TYPE;
		}
	}
	if (len < PROTO_HDR) {
		if (need)
			*need = PROTO_HDR - len;
		return 0;
	}
	uint32_t length = get32(p + 8);
	if (length > ti->cap) {
		err_set(err, "%s of %u bytes exceeds its cap of %u", ti->name, length, ti->cap);
		return PROTO_ERR_TOOBIG;
	}
	if (h)
		*h = (struct proto_hdr){ .version = p[4], .flags = p[5], .type = ti->type,
					 .length = length };
	size_t total = PROTO_HDR + (size_t)length;
	if (len < total) {
		if (need)
			*need = total - len;
		return 0;
	}
	return (ssize_t)total;
}

/* ---- arena ------------------------------------------------------------------------------ */

struct proto_arena {
	struct proto_arena *next;
	size_t used, cap;
	max_align_t data[];
};

static void *arena_alloc(struct proto_msg *m, size_t n)
{
	n = (n + alignof(max_align_t) - 1) & ~(alignof(max_align_t) - 1);
	struct proto_arena *a = m->arena;
	if (!a || a->cap - a->used < n) {
		size_t cap = n > 4096 ? n : 4096;
		a = xmalloc(sizeof(*a) + cap);
		a->next = m->arena;
		a->used = 0;
		a->cap = cap;
		m->arena = a;
	}
	void *p = (unsigned char *)a->data + a->used;
	a->used += n;
	memset(p, 0, n);
	return p;
}

void proto_msg_fini(struct proto_msg *m)
{
	struct proto_arena *a = m->arena;
	while (a) {
		struct proto_arena *next = a->next;
		free(a);
		a = next;
	}
	memset(m, 0, sizeof(*m));
}

/* ---- reader ----------------------------------------------------------------------------- */

struct rd {
	const uint8_t *p;
	size_t n, off;
	int err;
	char *errbuf;
	const char *msg; /* type name for error messages */
	struct proto_msg *m;
};

static bool rd_fail(struct rd *r, int code, const char *fmt, ...)
	__attribute__((format(printf, 3, 4)));
static bool rd_fail(struct rd *r, int code, const char *fmt, ...)
{
	if (r->err)
		return false;
	r->err = code;
	if (r->errbuf) {
		char tmp[224];
		va_list ap;
		va_start(ap, fmt);
		vsnprintf(tmp, sizeof(tmp), fmt, ap);
		va_end(ap);
		err_set(r->errbuf, "%s: %s", r->msg, tmp);
	}
	return false;
}

static bool rd_need(struct rd *r, size_t k, const char *what)
{
	if (r->err)
		return false;
	if (r->n - r->off < k)
		return rd_fail(r, PROTO_ERR_TRUNC, "truncated reading %s at byte %zu (%zu bytes, %zu left)",
			       what, r->off, k, r->n - r->off);
	return true;
}

static uint8_t rd_u8(struct rd *r, const char *what)
{
	if (!rd_need(r, 1, what))
		return 0;
	return r->p[r->off++];
}

static uint16_t rd_u16(struct rd *r, const char *what)
{
	if (!rd_need(r, 2, what))
		return 0;
	const uint8_t *p = r->p + r->off;
	r->off += 2;
	return (uint16_t)(p[0] | p[1] << 8);
}

static uint32_t rd_u32(struct rd *r, const char *what)
{
	if (!rd_need(r, 4, what))
		return 0;
	uint32_t v = get32(r->p + r->off);
	r->off += 4;
	return v;
}

static uint64_t rd_u64(struct rd *r, const char *what)
{
	if (!rd_need(r, 8, what))
		return 0;
	uint64_t v = get32(r->p + r->off) | (uint64_t)get32(r->p + r->off + 4) << 32;
	r->off += 8;
	return v;
}

static double rd_f64(struct rd *r, const char *what)
{
	uint64_t u = rd_u64(r, what);
	double d;
	memcpy(&d, &u, sizeof(d));
	return d;
}

/* A finite double in [lo, hi]. */
static double rd_range(struct rd *r, double lo, double hi, const char *what)
{
	double d = rd_f64(r, what);
	if (!r->err && !(d >= lo && d <= hi)) /* NaN fails too */
		rd_fail(r, PROTO_ERR_FIELD, "%s %g outside [%g, %g]", what, d, lo, hi);
	return d;
}

/* Strict UTF-8 (no overlongs, surrogates or code points above U+10FFFF) without NUL. */
static bool utf8_valid(const uint8_t *s, size_t n)
{
	size_t i = 0;
	while (i < n) {
		uint8_t c = s[i];
		if (c == 0)
			return false;
		if (c < 0x80) {
			i++;
			continue;
		}
		size_t k;
		uint32_t cp, min;
		if ((c & 0xe0) == 0xc0) {
			k = 1, cp = c & 0x1f, min = 0x80;
		} else if ((c & 0xf0) == 0xe0) {
			k = 2, cp = c & 0x0f, min = 0x800;
		} else if ((c & 0xf8) == 0xf0) {
			k = 3, cp = c & 0x07, min = 0x10000;
		} else {
			return false;
		}
		if (n - i <= k)
			return false;
		for (size_t j = 1; j <= k; j++) {
			if ((s[i + j] & 0xc0) != 0x80)
				return false;
			cp = cp << 6 | (s[i + j] & 0x3f);
		}
		if (cp < min || cp > 0x10ffff || (cp >= 0xd800 && cp <= 0xdfff))
			return false;
		i += k + 1;
	}
	return true;
}

/* u16 length + UTF-8 bytes → an owned NUL-terminated copy. */
static const char *rd_str(struct rd *r, size_t max, bool nonempty, const char *what)
{
	uint16_t len = rd_u16(r, what);
	if (r->err)
		return "";
	if (len > max) {
		rd_fail(r, PROTO_ERR_FIELD, "%s of %u bytes exceeds %zu", what, len, max);
		return "";
	}
	if (nonempty && len == 0) {
		rd_fail(r, PROTO_ERR_FIELD, "empty %s", what);
		return "";
	}
	if (!rd_need(r, len, what))
		return "";
	const uint8_t *s = r->p + r->off;
	if (!utf8_valid(s, len)) {
		rd_fail(r, PROTO_ERR_FIELD, "%s is not valid UTF-8 (or contains NUL)", what);
		return "";
	}
	r->off += len;
	if (len == 0)
		return "";
	char *out = arena_alloc(r->m, (size_t)len + 1);
	memcpy(out, s, len);
	return out;
}

/* An array of count elements of elem bytes, each at least min_wire bytes on the wire. */
static void *rd_array(struct rd *r, uint32_t count, size_t cap, size_t min_wire, size_t elem,
		      const char *what)
{
	if (r->err)
		return NULL;
	if (count > cap) {
		rd_fail(r, PROTO_ERR_LIMIT, "%u %s exceed the cap of %zu", count, what, cap);
		return NULL;
	}
	if ((size_t)count * min_wire > r->n - r->off) {
		rd_fail(r, PROTO_ERR_TRUNC, "%u %s need at least %zu bytes, %zu left", count, what,
			(size_t)count * min_wire, r->n - r->off);
		return NULL;
	}
	return count ? arena_alloc(r->m, (size_t)count * elem) : NULL;
}

static void rd_key(struct rd *r, struct tile_key *k, bool with_node)
{
	/* Callers read lx, ly first where the layout has them; see the message layouts. */
	if (with_node)
		k->node = rd_u64(r, "node");
	if (!r->err && !grid_key_valid(k))
		rd_fail(r, PROTO_ERR_FIELD, "tile key %u/%u/%u/%u outside the grid", k->lx, k->ly,
			k->x, k->y);
}

static bool pow2_tile(uint32_t t)
{
	return t >= 1 && t <= TILECODEC_MAX_SIZE && (t & (t - 1)) == 0;
}

/* ---- message decoders ------------------------------------------------------------------- */

static void decode_hello(struct rd *r, struct proto_hello *h)
{
	h->ver_min = rd_u8(r, "ver_min");
	h->ver_max = rd_u8(r, "ver_max");
	h->codecs = rd_u32(r, "codecs");
	if (!r->err && (h->ver_min < 1 || h->ver_min > h->ver_max))
		rd_fail(r, PROTO_ERR_FIELD, "version range %u..%u", h->ver_min, h->ver_max);
	h->token_len = rd_u16(r, "token length");
	if (!r->err && h->token_len > PROTO_MAX_TOKEN)
		rd_fail(r, PROTO_ERR_FIELD, "token of %u bytes exceeds %d", h->token_len,
			PROTO_MAX_TOKEN);
	if (rd_need(r, h->token_len, "token") && h->token_len) {
		uint8_t *t = arena_alloc(r->m, h->token_len);
		memcpy(t, r->p + r->off, h->token_len);
		h->token = t;
		r->off += h->token_len;
	}
	h->name = rd_str(r, PROTO_MAX_NAME, false, "client name");
}

static void decode_hello_ok(struct rd *r, struct proto_hello_ok *h)
{
	h->version = rd_u8(r, "version");
	h->codecs = rd_u32(r, "codecs");
	h->session = rd_u64(r, "session");
	h->limits.max_want = rd_u32(r, "max_want");
	h->limits.max_rate = rd_u32(r, "max_rate");
	h->limits.max_pending = rd_u64(r, "max_pending");
	h->limits.max_frame = rd_u32(r, "max_frame");
	h->name = rd_str(r, PROTO_MAX_NAME, false, "server name");
	if (!r->err && h->version < 1)
		rd_fail(r, PROTO_ERR_FIELD, "version 0");
	if (!r->err && (h->codecs & ~(TCODEC_ALL_MASK | PROTO_FEAT_PARTS)))
		rd_fail(r, PROTO_ERR_FIELD, "unknown codec bits 0x%x", h->codecs);
}

static void decode_error(struct rd *r, struct proto_error *e)
{
	e->code = rd_u16(r, "code");
	e->ref_type = rd_u16(r, "ref_type");
	e->ref_id = rd_u32(r, "ref_id");
	e->message = rd_str(r, PROTO_MAX_TEXT, false, "message");
}

bool proto_layer_normal_of_valid(const struct proto_layer *l, uint16_t n, uint16_t i)
{
	uint8_t k = l[i].normal_of;
	return k == 0 || (l[i].format == PIX_NORMAL && k <= n && k - 1 != i &&
			  l[k - 1].format == PIX_HEIGHT);
}

static void decode_planet(struct rd *r, struct proto_planet *p)
{
	p->name = rd_str(r, PROTO_MAX_NAME, true, "planet name");
	p->description = rd_str(r, PROTO_MAX_TEXT, false, "description");
	p->a = rd_range(r, 1e-9, 1e12, "radius a");
	p->f = rd_range(r, 0, 0.999999, "flattening f");
	p->tile_size = rd_u32(r, "tile_size");
	if (!r->err && !pow2_tile(p->tile_size))
		rd_fail(r, PROTO_ERR_FIELD, "tile_size %u is not a power of two ≤ %u",
			p->tile_size, TILECODEC_MAX_SIZE);
	p->max_level = rd_u8(r, "max_level");
	if (!r->err && p->max_level > GRID_MAX_LEVEL)
		rd_fail(r, PROTO_ERR_FIELD, "max_level %u > %d", p->max_level, GRID_MAX_LEVEL);
	p->nlayers = rd_u16(r, "layer count");
	struct proto_layer *l = rd_array(r, p->nlayers, PROTO_MAX_LAYERS, 12, sizeof(*l), "layers");
	p->layers = l;
	for (uint16_t i = 0; i < p->nlayers && !r->err; i++) {
		l[i].name = rd_str(r, PROTO_MAX_NAME, true, "layer name");
		l[i].format = rd_u8(r, "layer format");
		l[i].node = rd_u64(r, "layer node");
		l[i].normal_of = rd_u8(r, "layer normal_of");
		if (!r->err && (l[i].format == PIX_NONE || l[i].format >= PIX_COUNT))
			rd_fail(r, PROTO_ERR_FIELD, "layer %s: unknown format %u", l[i].name,
				l[i].format);
	}
	for (uint16_t i = 0; i < p->nlayers && !r->err; i++)
		if (!proto_layer_normal_of_valid(l, p->nlayers, i))
			rd_fail(r, PROTO_ERR_FIELD,
				"layer %s: normal_of %u is not a normal layer made of a height layer",
				l[i].name, l[i].normal_of);
	p->air_density = rd_range(r, 0, 100, "air_density");
	p->air_height = rd_range(r, 0, 1e6, "air_height");
	for (int i = 0; i < 3; i++)
		p->air_color[i] = rd_u8(r, "air_color");
	p->sea = rd_u8(r, "sea");
	p->sea_level = rd_range(r, -1e5, 1e5, "sea_level");
	if (!r->err && (p->air_density > 0 ? p->air_height < 1 : p->air_height != 0))
		rd_fail(r, PROTO_ERR_FIELD, "air_height %g with air_density %g", p->air_height,
			p->air_density);
	if (!r->err && (p->sea > 1 || (!p->sea && p->sea_level != 0)))
		rd_fail(r, PROTO_ERR_FIELD, "sea %u with sea_level %g", p->sea, p->sea_level);
	p->sea_mask = rd_u8(r, "sea_mask");
	if (!r->err && (p->sea_mask > 1 || (p->sea_mask && !p->sea)))
		rd_fail(r, PROTO_ERR_FIELD, "sea_mask %u with sea %u", p->sea_mask, p->sea);
	struct sea_grid *g = &p->sea_grid;
	g->rows = rd_u16(r, "sea grid rows");
	g->cols = rd_u16(r, "sea grid columns");
	if (!r->err && !sea_grid_valid_size(g->rows, g->cols))
		rd_fail(r, PROTO_ERR_FIELD, "sea grid %u × %u (2..%d rows, 2..%d columns, or 0 × 0)",
			g->rows, g->cols, SEA_GRID_MAX_ROWS, SEA_GRID_MAX_COLS);
	if (!r->err && g->rows && !p->sea)
		rd_fail(r, PROTO_ERR_FIELD, "a sea grid without a sea");
	uint32_t n = r->err ? 0 : (uint32_t)g->rows * g->cols;
	g->dm = rd_array(r, n, (size_t)SEA_GRID_MAX_ROWS * SEA_GRID_MAX_COLS, 2, sizeof *g->dm,
			 "sea grid nodes");
	for (uint32_t i = 0; i < n && !r->err; i++)
		g->dm[i] = (int16_t)rd_u16(r, "sea grid node");
}

static void decode_planets(struct rd *r, struct proto_planets *p)
{
	p->req = rd_u32(r, "req");
	p->count = rd_u16(r, "planet count");
	struct proto_planet *a =
		rd_array(r, p->count, PROTO_MAX_PLANETS, 60, sizeof(*a), "planets");
	p->planets = a;
	for (uint16_t i = 0; i < p->count && !r->err; i++)
		decode_planet(r, &a[i]);
}

static void decode_want(struct rd *r, struct proto_want *w)
{
	w->planet_id = rd_u32(r, "planet_id");
	w->seq = rd_u32(r, "seq");
	w->lon = rd_range(r, -540, 540, "lon");
	w->lat = rd_range(r, -90, 90, "lat");
	w->alt = rd_range(r, -1e12, 1e12, "alt");
	for (int i = 0; i < 3; i++)
		w->vel[i] = rd_range(r, -1e12, 1e12, "velocity");
	w->count = rd_u32(r, "want count");
	struct proto_want_entry *e = rd_array(r, w->count, PROTO_MAX_WANT, 12, sizeof(*e),
					      "want entries");
	w->entries = e;
	for (uint32_t i = 0; i < w->count && !r->err; i++) {
		e[i].layer = rd_u8(r, "layer");
		e[i].cls = rd_u8(r, "class");
		struct tile_key k = { .lx = rd_u8(r, "lx"), .ly = rd_u8(r, "ly") };
		k.x = rd_u32(r, "x");
		k.y = rd_u32(r, "y");
		e[i].lx = k.lx, e[i].ly = k.ly, e[i].x = k.x, e[i].y = k.y;
		rd_key(r, &k, false);
		if (!r->err && e[i].layer >= PROTO_MAX_LAYERS)
			rd_fail(r, PROTO_ERR_FIELD, "entry %u: layer %u", i, e[i].layer);
		if (!r->err && (e[i].cls < PROTO_CLASS_VISIBLE || e[i].cls > PROTO_CLASS_BULK))
			rd_fail(r, PROTO_ERR_FIELD, "entry %u: class %u", i, e[i].cls);
	}
}

/* TILE fields up to the payload; payload_len is what follows them. */
static void decode_tile_head(struct rd *r, struct proto_tile *t, size_t payload_len)
{
	t->seq = rd_u32(r, "seq");
	t->planet_id = rd_u32(r, "planet_id");
	t->layer = rd_u8(r, "layer");
	t->key.lx = rd_u8(r, "lx");
	t->key.ly = rd_u8(r, "ly");
	t->enc.format = rd_u8(r, "format");
	t->enc.codec = rd_u8(r, "codec");
	t->enc.filter = rd_u8(r, "filter");
	t->enc.size = rd_u16(r, "size");
	t->key.x = rd_u32(r, "x");
	t->key.y = rd_u32(r, "y");
	t->key.node = rd_u64(r, "node");
	t->enc.raw_len = rd_u32(r, "raw_len");
	t->enc.checksum = rd_u64(r, "checksum");
	t->payload_len = payload_len > UINT32_MAX ? UINT32_MAX : (uint32_t)payload_len;
	char e[256];
	if (!r->err && proto_tile_check(t, e))
		rd_fail(r, PROTO_ERR_FIELD, "%s", e);
}

int proto_tile_check(const struct proto_tile *t, char err[256])
{
	int rc = tilecodec_hdr_check(&t->enc, err);
	if (rc)
		return rc;
	if (!grid_key_valid(&t->key)) {
		err_set(err, "tile key %u/%u/%u/%u outside the grid", t->key.lx, t->key.ly,
		       t->key.x, t->key.y);
		return -EINVAL;
	}
	if (t->layer >= PROTO_MAX_LAYERS) {
		err_set(err, "layer %u", t->layer);
		return -EINVAL;
	}
	if (t->enc.codec == TCODEC_NONE
		    ? t->payload_len != t->enc.raw_len
		    : t->payload_len == 0 ||
			      t->payload_len > tilecodec_bound(t->enc.codec, t->enc.raw_len)) {
		err_set(err, "payload of %u bytes impossible for %s of %u bytes", t->payload_len,
		       tilecodec_codec_name(t->enc.codec), t->enc.raw_len);
		return -EINVAL;
	}
	return 0;
}

static void decode_tile(struct rd *r, struct proto_tile *t)
{
	if (!rd_need(r, TILE_HEAD, "tile fields"))
		return;
	size_t payload_len = r->n - r->off - TILE_HEAD;
	decode_tile_head(r, t, payload_len);
	t->payload = r->p + r->off;
	r->off += r->err ? 0 : payload_len;
}

static void decode_tile_part(struct rd *r, struct proto_tile_part *t)
{
	t->offset = rd_u32(r, "offset");
	t->total = rd_u32(r, "total");
	if (!r->err && t->offset == 0 && rd_need(r, TILE_HEAD, "tile fields"))
		decode_tile_head(r, &t->tile, t->total);
	if (r->err)
		return;
	size_t len = r->n - r->off;
	if (len == 0 || len > t->total || t->offset > t->total - len) {
		rd_fail(r, PROTO_ERR_FIELD, "part of %zu bytes at %u of a %u-byte tile", len,
			t->offset, t->total);
		return;
	}
	t->bytes = r->p + r->off;
	t->len = (uint32_t)len;
	r->off += len;
}

static void decode_tile_fail(struct rd *r, struct proto_tile_fail *t)
{
	t->seq = rd_u32(r, "seq");
	t->planet_id = rd_u32(r, "planet_id");
	t->layer = rd_u8(r, "layer");
	t->key.lx = rd_u8(r, "lx");
	t->key.ly = rd_u8(r, "ly");
	t->key.x = rd_u32(r, "x");
	t->key.y = rd_u32(r, "y");
	rd_key(r, &t->key, true);
	t->code = rd_u16(r, "code");
	t->message = rd_str(r, PROTO_MAX_TEXT, false, "message");
	if (!r->err && t->layer >= PROTO_MAX_LAYERS)
		rd_fail(r, PROTO_ERR_FIELD, "layer %u", t->layer);
}

static void decode_stats(struct rd *r, struct proto_stats *s)
{
	s->req = rd_u32(r, "req");
	s->count = rd_u16(r, "stat count");
	struct proto_stat *a = rd_array(r, s->count, PROTO_MAX_STATS, 6, sizeof(*a), "stats");
	s->items = a;
	for (uint16_t i = 0; i < s->count && !r->err; i++) {
		a[i].key = rd_str(r, PROTO_MAX_NAME, true, "stat key");
		a[i].kind = rd_u8(r, "stat kind");
		if (a[i].kind == PROTO_STAT_U64)
			a[i].u = rd_u64(r, "stat value");
		else if (a[i].kind == PROTO_STAT_F64)
			a[i].f = rd_f64(r, "stat value");
		else if (a[i].kind == PROTO_STAT_STR)
			a[i].s = rd_str(r, PROTO_MAX_TEXT, false, "stat value");
		else
			rd_fail(r, PROTO_ERR_FIELD, "stat %s: kind %u", a[i].key, a[i].kind);
	}
}

static void decode_cache_ls(struct rd *r, struct proto_cache_ls *c)
{
	c->req = rd_u32(r, "req");
	c->filter = rd_u8(r, "filter");
	c->planet = rd_str(r, PROTO_MAX_NAME, false, "planet");
	c->lx = rd_u8(r, "lx");
	c->ly = rd_u8(r, "ly");
	c->lon = rd_f64(r, "lon");
	c->lat = rd_f64(r, "lat");
	c->radius_m = rd_f64(r, "radius");
	c->limit = rd_u32(r, "limit");
	if (r->err)
		return;
	if (c->filter & ~(PROTO_CLS_PLANET | PROTO_CLS_LEVEL | PROTO_CLS_NEAR))
		rd_fail(r, PROTO_ERR_FIELD, "unknown filter bits 0x%x", c->filter);
	else if ((c->filter & PROTO_CLS_PLANET) && !c->planet[0])
		rd_fail(r, PROTO_ERR_FIELD, "planet filter without a planet");
	else if ((c->filter & PROTO_CLS_LEVEL) && c->lx != PROTO_ANY_LX &&
		 !grid_level_valid(c->lx, c->ly))
		rd_fail(r, PROTO_ERR_FIELD, "level %u/%u", c->lx, c->ly);
	else if ((c->filter & PROTO_CLS_NEAR) &&
		 !(fabs(c->lon) <= 540 && fabs(c->lat) <= 90 && c->radius_m >= 0 &&
		   c->radius_m <= 1e12))
		rd_fail(r, PROTO_ERR_FIELD, "near %g, %g radius %g", c->lon, c->lat, c->radius_m);
}

static void decode_cache_entries(struct rd *r, struct proto_cache_entries *c)
{
	c->req = rd_u32(r, "req");
	c->more = rd_u8(r, "more");
	c->total = rd_u64(r, "total");
	c->count = rd_u32(r, "entry count");
	if (!r->err && c->more > 1)
		rd_fail(r, PROTO_ERR_FIELD, "more = %u", c->more);
	struct proto_cache_entry *e = rd_array(r, c->count, PROTO_MAX_CACHE_ENTRIES, 28,
					       sizeof(*e), "cache entries");
	c->entries = e;
	for (uint32_t i = 0; i < c->count && !r->err; i++) {
		e[i].key.node = rd_u64(r, "node");
		e[i].key.lx = rd_u8(r, "lx");
		e[i].key.ly = rd_u8(r, "ly");
		e[i].format = rd_u8(r, "format");
		e[i].tier = rd_u8(r, "tier");
		e[i].key.x = rd_u32(r, "x");
		e[i].key.y = rd_u32(r, "y");
		e[i].bytes = rd_u32(r, "bytes");
		e[i].age_s = rd_u32(r, "age");
		rd_key(r, &e[i].key, false);
		if (!r->err && (e[i].format == PIX_NONE || e[i].format >= PIX_COUNT))
			rd_fail(r, PROTO_ERR_FIELD, "entry %u: format %u", i, e[i].format);
		if (!r->err && (e[i].tier < PROTO_TIER_MEMORY || e[i].tier > PROTO_TIER_REMOTE))
			rd_fail(r, PROTO_ERR_FIELD, "entry %u: tier %u", i, e[i].tier);
	}
}

/* A polygon's rings and points (PREFETCH shape 3, CACHE_OP's polygon filter): counts checked
 * against the caps and the bytes left before anything is allocated. */
static void decode_polygon(struct rd *r, uint32_t *nrings, const uint32_t **rings_out,
			   uint32_t *npoints, const struct proto_lonlat **points)
{
	*nrings = rd_u32(r, "ring count");
	if (!r->err && *nrings == 0)
		rd_fail(r, PROTO_ERR_FIELD, "polygon without rings");
	uint32_t *rings = rd_array(r, *nrings, PROTO_MAX_RINGS, 4, sizeof *rings, "rings");
	*rings_out = rings;
	uint64_t total = 0;
	for (uint32_t i = 0; i < *nrings && !r->err; i++) {
		rings[i] = rd_u32(r, "ring length");
		if (!r->err && rings[i] < 3)
			rd_fail(r, PROTO_ERR_FIELD, "ring %u of %u points (3 at least)", i, rings[i]);
		total += rings[i];
	}
	if (!r->err && total > PROTO_MAX_POLY)
		rd_fail(r, PROTO_ERR_LIMIT, "%llu polygon points exceed the cap of %u",
			(unsigned long long)total, PROTO_MAX_POLY);
	*npoints = r->err ? 0 : (uint32_t)total;
	struct proto_lonlat *pt = rd_array(r, *npoints, PROTO_MAX_POLY, 16, sizeof(*pt),
					   "polygon points");
	*points = pt;
	for (uint32_t i = 0; i < *npoints && !r->err; i++) {
		pt[i].lon = rd_range(r, -540, 540, "point lon");
		pt[i].lat = rd_range(r, -90, 90, "point lat");
	}
}

static void decode_cache_op(struct rd *r, struct proto_cache_op *c)
{
	c->req = rd_u32(r, "req");
	c->op = rd_u8(r, "op");
	c->planet = rd_str(r, PROTO_MAX_NAME, false, "planet");
	c->filter = rd_u8(r, "filter");
	c->bbox.west = rd_f64(r, "west");
	c->bbox.south = rd_f64(r, "south");
	c->bbox.east = rd_f64(r, "east");
	c->bbox.north = rd_f64(r, "north");
	c->lmin = rd_u8(r, "lmin");
	c->lmax = rd_u8(r, "lmax");
	if (!r->err && (c->filter & PROTO_COF_POLYGON) && c->op == PROTO_COP_PURGE)
		decode_polygon(r, &c->nrings, &c->rings, &c->npoints, &c->points);
	if (r->err)
		return;
	const struct geo_rect *b = &c->bbox;
	if (c->op < PROTO_COP_STAT || c->op > PROTO_COP_VERIFY)
		rd_fail(r, PROTO_ERR_FIELD, "cache op %u", c->op);
	else if (c->filter & ~(PROTO_COF_BBOX | PROTO_COF_LEVELS | PROTO_COF_POLYGON))
		rd_fail(r, PROTO_ERR_FIELD, "unknown filter bits 0x%x", c->filter);
	else if (c->filter && c->op != PROTO_COP_PURGE)
		rd_fail(r, PROTO_ERR_FIELD, "filters go with purge");
	else if ((c->filter & PROTO_COF_BBOX) && (c->filter & PROTO_COF_POLYGON))
		rd_fail(r, PROTO_ERR_FIELD, "a bbox or a polygon, not both");
	else if (c->op == PROTO_COP_PURGE && !c->planet[0])
		rd_fail(r, PROTO_ERR_FIELD, "purge without a planet");
	else if (c->op == PROTO_COP_GC && c->planet[0])
		rd_fail(r, PROTO_ERR_FIELD, "gc takes no planet");
	else if ((c->filter & PROTO_COF_BBOX) &&
		 !(fabs(b->west) <= 180 && fabs(b->east) <= 180 && b->south >= -90 &&
		   b->north <= 90 && b->south < b->north && b->west != b->east))
		rd_fail(r, PROTO_ERR_FIELD, "bbox");
	else if ((c->filter & PROTO_COF_LEVELS) &&
		 (c->lmin > c->lmax || c->lmax > GRID_MAX_LEVEL))
		rd_fail(r, PROTO_ERR_FIELD, "level range %u..%u", c->lmin, c->lmax);
}

static void decode_cache_stat(struct rd *r, struct proto_cache_stat *c)
{
	c->req = rd_u32(r, "req");
	c->more = rd_u8(r, "more");
	c->count = rd_u32(r, "row count");
	if (!r->err && c->more > 1)
		rd_fail(r, PROTO_ERR_FIELD, "more = %u", c->more);
	struct proto_cache_stat_row *w = rd_array(r, c->count, PROTO_MAX_STAT_ROWS, 22,
						  sizeof(*w), "stat rows");
	c->rows = w;
	for (uint32_t i = 0; i < c->count && !r->err; i++) {
		w[i].planet = rd_str(r, PROTO_MAX_NAME, false, "planet");
		w[i].layer = rd_str(r, PROTO_MAX_NAME, false, "layer");
		w[i].ly = rd_u8(r, "ly");
		w[i].tier = rd_u8(r, "tier");
		w[i].tiles = rd_u64(r, "tiles");
		w[i].bytes = rd_u64(r, "bytes");
		if (!r->err && (w[i].ly > GRID_MAX_LEVEL || w[i].tier < PROTO_TIER_MEMORY ||
				w[i].tier > PROTO_TIER_REMOTE))
			rd_fail(r, PROTO_ERR_FIELD, "row %u: level %u tier %u", i, w[i].ly, w[i].tier);
	}
}

static void decode_cache_done(struct rd *r, struct proto_cache_done *c)
{
	c->req = rd_u32(r, "req");
	c->op = rd_u8(r, "op");
	c->checked = rd_u64(r, "checked");
	c->removed = rd_u64(r, "removed");
	c->bytes = rd_u64(r, "bytes");
	c->corrupt = rd_u64(r, "corrupt");
	if (!r->err && (c->op < PROTO_COP_STAT || c->op > PROTO_COP_VERIFY))
		rd_fail(r, PROTO_ERR_FIELD, "cache op %u", c->op);
}

static void decode_prefetch(struct rd *r, struct proto_prefetch *p)
{
	p->id = rd_u32(r, "id");
	p->planet = rd_str(r, PROTO_MAX_NAME, true, "planet");
	p->layers = rd_u64(r, "layers");
	p->shape = rd_u8(r, "shape");
	p->lmin = rd_u8(r, "lmin");
	p->lmax = rd_u8(r, "lmax");
	if (!r->err && p->id == 0)
		rd_fail(r, PROTO_ERR_FIELD, "job id 0");
	if (!r->err && (p->lmin > p->lmax || p->lmax > GRID_MAX_LEVEL))
		rd_fail(r, PROTO_ERR_FIELD, "level range %u..%u", p->lmin, p->lmax);
	if (r->err)
		return;
	if (p->shape == PROTO_SHAPE_BBOX) {
		p->bbox.west = rd_range(r, -180, 180, "west");
		p->bbox.south = rd_range(r, -90, 90, "south");
		p->bbox.east = rd_range(r, -180, 180, "east");
		p->bbox.north = rd_range(r, -90, 90, "north");
		if (!r->err && !(p->bbox.south < p->bbox.north && p->bbox.west != p->bbox.east))
			rd_fail(r, PROTO_ERR_FIELD, "empty bbox");
	} else if (p->shape == PROTO_SHAPE_PATH) {
		p->width_m = rd_range(r, 0, PROTO_MAX_WIDTH, "width");
		p->npoints = rd_u32(r, "point count");
		if (!r->err && p->npoints == 0)
			rd_fail(r, PROTO_ERR_FIELD, "path without points");
		struct proto_lonlat *pt = rd_array(r, p->npoints, PROTO_MAX_PATH, 16, sizeof(*pt),
						   "path points");
		p->points = pt;
		for (uint32_t i = 0; i < p->npoints && !r->err; i++) {
			pt[i].lon = rd_range(r, -540, 540, "point lon");
			pt[i].lat = rd_range(r, -90, 90, "point lat");
		}
	} else if (p->shape == PROTO_SHAPE_POLYGON) {
		decode_polygon(r, &p->nrings, &p->rings, &p->npoints, &p->points);
	} else {
		rd_fail(r, PROTO_ERR_FIELD, "shape %u", p->shape);
	}
}

static void decode_estimate(struct rd *r, struct proto_prefetch_estimate *e)
{
	e->id = rd_u32(r, "id");
	e->tier = rd_u8(r, "tier");
	e->tiles = rd_u64(r, "tiles");
	e->bytes = rd_u64(r, "bytes");
	e->budget = rd_u64(r, "budget");
	e->used = rd_u64(r, "used");
	e->max_tiles = rd_u64(r, "max_tiles");
	e->nlevels = rd_u8(r, "level count");
	if (!r->err && (e->tier < PROTO_TIER_MEMORY || e->tier > PROTO_TIER_REMOTE))
		rd_fail(r, PROTO_ERR_FIELD, "tier %u", e->tier);
	struct proto_estimate_level *l = rd_array(r, e->nlevels, GRID_MAX_LEVEL + 1, 17,
						  sizeof(*l), "estimate levels");
	e->levels = l;
	for (uint32_t i = 0; i < e->nlevels && !r->err; i++) {
		l[i].ly = rd_u8(r, "ly");
		l[i].tiles = rd_u64(r, "level tiles");
		l[i].bytes = rd_u64(r, "level bytes");
		if (!r->err && l[i].ly > GRID_MAX_LEVEL)
			rd_fail(r, PROTO_ERR_FIELD, "level %u", l[i].ly);
	}
}

static void decode_progress(struct rd *r, struct proto_prefetch_progress *p)
{
	p->id = rd_u32(r, "id");
	p->state = rd_u8(r, "state");
	p->done = rd_u64(r, "done");
	p->total = rd_u64(r, "total");
	p->rate = rd_range(r, 0, 1e300, "rate");
	if (!r->err && (p->state < PROTO_JOB_RUNNING || p->state > PROTO_JOB_FAILED))
		rd_fail(r, PROTO_ERR_FIELD, "state %u", p->state);
}

int proto_decode_payload(uint16_t type, const void *payload, size_t len, struct proto_msg *m,
			 char err[256])
{
	const struct type_info *ti = type_info(type);
	memset(m, 0, sizeof(*m));
	if (!ti) {
		err_set(err, "unknown message type %u", type);
		return PROTO_ERR_TYPE;
	}
	struct rd r = { .p = payload, .n = len, .errbuf = err, .msg = ti->name, .m = m };
	m->type = type;
	switch (type) {
	case PROTO_HELLO: decode_hello(&r, &m->hello); break;
	case PROTO_HELLO_OK: decode_hello_ok(&r, &m->hello_ok); break;
	case PROTO_BYE: break;
	case PROTO_ERROR: decode_error(&r, &m->error); break;
	case PROTO_LIST_PLANETS: m->list_planets.req = rd_u32(&r, "req"); break;
	case PROTO_PLANETS: decode_planets(&r, &m->planets); break;
	case PROTO_OPEN:
		m->open.req = rd_u32(&r, "req");
		m->open.name = rd_str(&r, PROTO_MAX_NAME, true, "planet name");
		break;
	case PROTO_OPENED:
		m->opened.req = rd_u32(&r, "req");
		m->opened.planet_id = rd_u32(&r, "planet_id");
		if (!r.err && m->opened.planet_id == 0)
			rd_fail(&r, PROTO_ERR_FIELD, "planet_id 0");
		decode_planet(&r, &m->opened.planet);
		break;
	case PROTO_WANT: decode_want(&r, &m->want); break;
	case PROTO_TILE: decode_tile(&r, &m->tile); break;
	case PROTO_TILE_FAIL: decode_tile_fail(&r, &m->tile_fail); break;
	case PROTO_TILE_PART: decode_tile_part(&r, &m->tile_part); break;
	case PROTO_STATS_REQ: m->stats_req.req = rd_u32(&r, "req"); break;
	case PROTO_STATS: decode_stats(&r, &m->stats); break;
	case PROTO_CACHE_LS: decode_cache_ls(&r, &m->cache_ls); break;
	case PROTO_CACHE_ENTRIES: decode_cache_entries(&r, &m->cache_entries); break;
	case PROTO_CACHE_OP: decode_cache_op(&r, &m->cache_op); break;
	case PROTO_CACHE_STAT: decode_cache_stat(&r, &m->cache_stat); break;
	case PROTO_CACHE_DONE: decode_cache_done(&r, &m->cache_done); break;
	case PROTO_PREFETCH: decode_prefetch(&r, &m->prefetch); break;
	case PROTO_PREFETCH_PROGRESS: decode_progress(&r, &m->prefetch_progress); break;
	case PROTO_PREFETCH_CANCEL: m->prefetch_cancel.req = rd_u32(&r, "id"); break;
	case PROTO_PREFETCH_DRY: decode_prefetch(&r, &m->prefetch_dry); break;
	case PROTO_PREFETCH_ESTIMATE: decode_estimate(&r, &m->prefetch_estimate); break;
	}
	if (!r.err && r.off != r.n)
		rd_fail(&r, PROTO_ERR_FIELD, "%zu trailing bytes", r.n - r.off);
	if (r.err) {
		proto_msg_fini(m);
		return r.err;
	}
	return 0;
}

ssize_t proto_decode(const void *buf, size_t len, struct proto_msg *m, size_t *need,
		     char err[256])
{
	struct proto_hdr h;
	memset(m, 0, sizeof(*m));
	ssize_t n = proto_frame_check(buf, len, &h, need, err);
	if (n <= 0)
		return n;
	int rc = proto_decode_payload(h.type, (const uint8_t *)buf + PROTO_HDR, h.length, m, err);
	return rc ? rc : n;
}
