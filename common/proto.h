/* proto — the clipmap wire protocol: framing and the codec of every message (docs/PROTOCOL.md
 * is the specification; this is its reference implementation). No sockets, no threads:
 * encoding appends to a struct pbuf, decoding is a pure function over a byte buffer that may
 * hold a partial frame ("need N more bytes" is a normal answer), so it can be fuzzed.
 *
 * Thread-safety: every function is reentrant; distinct objects may be used from any thread.
 * Ownership: a decoded struct proto_msg owns its strings and arrays (an arena freed by
 * proto_msg_fini), except proto_tile.payload, which borrows from the decoded buffer. Structs
 * passed to proto_encode are borrowed. Decoding never allocates more than a small multiple of
 * the payload bytes actually present, and every list count is capped before allocation.
 */
#ifndef CLIPMAP_PROTO_H
#define CLIPMAP_PROTO_H
#include <errno.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include "grid.h"
#include "seagrid.h"
#include "tilecodec.h"

/* ---- framing ---------------------------------------------------------------------------- */

#define PROTO_MAGIC "CLMP" /* the first 4 bytes of every frame */
#define PROTO_VERSION 4	   /* frame layout and message set; HELLO negotiates it */
#define PROTO_HDR 12	   /* frame header bytes */
#define PROTO_MAX_FRAME (16u << 20) /* payload bytes, any type */

/* Caps on every list and string (a decoder rejects more with PROTO_ERR_LIMIT / _FIELD). */
#define PROTO_MAX_NAME 255	       /* names: clients, servers, planets, layers, stat keys */
#define PROTO_MAX_TEXT 4096	       /* descriptions, error messages, stat strings */
#define PROTO_MAX_TOKEN 1024	       /* auth token bytes */
#define PROTO_MAX_PLANETS 256
#define PROTO_MAX_LAYERS 64	       /* per planet; layer indices are < this */
#define PROTO_MAX_WANT 4096	       /* want-set entries (a session may allow fewer) */
#define PROTO_MAX_STATS 1024
#define PROTO_MAX_CACHE_ENTRIES 16384 /* per CACHE_ENTRIES message */
#define PROTO_MAX_PATH 4096	       /* prefetch path points */
#define PROTO_MAX_WIDTH 2e7	       /* prefetch corridor width, metres */
#define PROTO_MAX_RINGS 512	       /* prefetch / purge polygon rings */
#define PROTO_MAX_POLY 7680	       /* prefetch / purge polygon points, every ring */

enum proto_type {
	PROTO_NONE = 0,
	PROTO_HELLO = 1,	/* C→S */
	PROTO_HELLO_OK = 2,	/* S→C */
	PROTO_BYE = 3,		/* both */
	PROTO_ERROR = 4,	/* both */
	PROTO_LIST_PLANETS = 16, /* C→S */
	PROTO_PLANETS = 17,	/* S→C */
	PROTO_OPEN = 18,	/* C→S */
	PROTO_OPENED = 19,	/* S→C */
	PROTO_WANT = 32,	/* C→S */
	PROTO_TILE = 33,	/* S→C */
	PROTO_TILE_FAIL = 34,	/* S→C */
	PROTO_TILE_PART = 35,	/* S→C: a TILE in parts, to a client that offered PROTO_FEAT_PARTS */
	PROTO_STATS_REQ = 48,	/* C→S */
	PROTO_STATS = 49,	/* S→C */
	PROTO_CACHE_LS = 50,	/* C→S */
	PROTO_CACHE_ENTRIES = 51, /* S→C */
	PROTO_CACHE_OP = 52,	  /* C→S: stat, purge, gc, verify */
	PROTO_CACHE_STAT = 53,	  /* S→C */
	PROTO_CACHE_DONE = 54,	  /* S→C */
	PROTO_PREFETCH = 64,	/* C→S */
	PROTO_PREFETCH_PROGRESS = 65, /* S→C */
	PROTO_PREFETCH_CANCEL = 66,   /* C→S */
	PROTO_PREFETCH_DRY = 67,      /* C→S: a PREFETCH only estimated */
	PROTO_PREFETCH_ESTIMATE = 68, /* S→C */
};

/* Decoder errors: one distinct negative errno per malformed class. */
enum proto_err {
	PROTO_ERR_MAGIC = -EPROTO,	      /* the stream is not this protocol */
	PROTO_ERR_VERSION = -EPROTONOSUPPORT, /* frame version other than PROTO_VERSION */
	PROTO_ERR_TOOBIG = -EMSGSIZE,	      /* length over the type's cap (before the body) */
	PROTO_ERR_TRUNC = -EBADMSG,	      /* body shorter than its fields */
	PROTO_ERR_TYPE = -ENOMSG,	      /* unknown message type */
	PROTO_ERR_FIELD = -EINVAL,	      /* a field out of range, bad UTF-8, trailing bytes */
	PROTO_ERR_LIMIT = -E2BIG,	      /* a list longer than its cap */
	PROTO_ERR_STATE = -EPERM,	      /* valid message, wrong side or wrong time */
};

/* Error codes carried by ERROR and TILE_FAIL messages. */
enum proto_code {
	PROTO_E_NONE = 0,
	PROTO_E_PROTOCOL = 1,	 /* malformed frame or message */
	PROTO_E_VERSION = 2,	 /* no common protocol version */
	PROTO_E_AUTH = 3,	 /* missing or wrong token */
	PROTO_E_STATE = 4,	 /* message not allowed now */
	PROTO_E_NOT_FOUND = 5,	 /* no such planet, layer, planet id or job */
	PROTO_E_LIMIT = 6,	 /* a per-session limit was exceeded (want-set, rate, jobs) */
	PROTO_E_INVALID = 7,	 /* a well-formed request with unusable values */
	PROTO_E_UNAVAILABLE = 8, /* tile generation failed or source missing */
	PROTO_E_BUSY = 9,	 /* server overloaded, try later */
	PROTO_E_INTERNAL = 10,
	PROTO_E_SHUTDOWN = 11, /* server going away */
	PROTO_E_COUNT
};

/* A parsed frame header. */
struct proto_hdr {
	uint8_t version;
	uint8_t flags; /* must be 0 in version 1 */
	uint16_t type;
	uint32_t length; /* payload bytes following the header */
};

/* Looks at the start of buf[0 .. len). Returns the whole frame's size (PROTO_HDR + length,
 * > 0) when it is complete; 0 when more bytes are needed, with *need set to how many more at
 * least (the header is validated as far as it has arrived, so a bad magic is reported after
 * 1 byte and an oversize length before any of the body); or a negative PROTO_ERR_* with err
 * filled (may be NULL). h (may be NULL) is filled once the header is complete. */
ssize_t proto_frame_check(const void *buf, size_t len, struct proto_hdr *h, size_t *need,
			  char err[256]);
/* The payload cap of a message type (0 for unknown types). */
uint32_t proto_type_cap(uint16_t type);
/* "HELLO", "TILE", …; NULL for unknown types. */
const char *proto_type_name(uint16_t type);
const char *proto_code_name(uint16_t code); /* "protocol", "auth", …; NULL if unknown */
/* The wire code to report a negative decoder/errno error with (PROTO_E_PROTOCOL, …). */
uint16_t proto_code_from_err(int err);

/* ---- messages --------------------------------------------------------------------------- */

/* Strings are UTF-8 without NUL; decoded strings are NUL-terminated and owned by the message.
 * When encoding, NULL means "". */

struct proto_hello {
	uint8_t ver_min, ver_max; /* protocol versions the client speaks, 1 ≤ min ≤ max */
	uint32_t codecs;	  /* bit (1 << enum tcodec) per codec it decodes (NONE implied) */
	const uint8_t *token;	  /* auth token bytes (may be NULL when token_len = 0) */
	uint16_t token_len;	  /* ≤ PROTO_MAX_TOKEN */
	const char *name;	  /* client name and version, e.g. "clipmapview/0.1" */
};

struct proto_limits {
	uint32_t max_want;    /* want-set entries */
	uint32_t max_rate;    /* messages per second (sustained; bursts up to max_rate) */
	uint64_t max_pending; /* TILE bytes queued to this session before finer tiles wait */
	uint32_t max_frame;   /* largest frame the server accepts from the client */
};

struct proto_hello_ok {
	uint8_t version;   /* the chosen version */
	uint32_t codecs;   /* codecs the server may use for tiles: a subset of the client's */
	uint64_t session;  /* server-chosen session id (for logs) */
	const char *name;  /* server name and version */
	struct proto_limits limits;
};

struct proto_error {
	uint16_t code;	   /* enum proto_code */
	uint16_t ref_type; /* type of the message it answers (0: none) */
	uint32_t ref_id;   /* its req / id / seq (0: none) */
	const char *message;
};

struct proto_layer {
	const char *name;
	uint8_t format;	   /* enum pix_type */
	uint64_t node;	   /* content hash of the layer's node: part of every tile key */
	uint8_t normal_of; /* version 4: 0; or, for a normal layer that is the plain `normal`
			    * (exaggeration 1) of height layer i, i + 1: a client may make these
			    * normals itself from that layer's tiles instead of asking for them */
};

/* Whether layer i of the n layers l may carry its normal_of (0 always may): a normal layer
 * naming another layer, a height layer. The encoder and the decoder both check it. */
bool proto_layer_normal_of_valid(const struct proto_layer *l, uint16_t n, uint16_t i);

struct proto_planet {
	const char *name;
	const char *description;
	double a, f;	    /* body: equatorial radius (m), flattening */
	uint32_t tile_size; /* T: power of two ≤ TILECODEC_MAX_SIZE */
	uint8_t max_level;  /* finest ly ≤ GRID_MAX_LEVEL */
	uint16_t nlayers;   /* ≤ PROTO_MAX_LAYERS */
	const struct proto_layer *layers;
	/* The look (version 2): the air and the sea; all zero: no air, no sea. */
	double air_density;   /* haze relative to Earth's, [0, 100]; 0: no atmosphere */
	double air_height;    /* scale height, metres: [1, 1e6] with air, 0 without */
	uint8_t air_color[3]; /* the sky's colour at the ground, sRGB */
	uint8_t sea;	      /* 1: a sea at sea_level; 0: none (sea_level 0) */
	double sea_level;     /* metres above the ellipsoid, |x| ≤ 1e5 */
	uint8_t sea_mask;     /* version 3: 1: the colour layers' alpha says where a sea may lie
			       * (255: it may; 254 or less: dry land even below sea level) */
	/* Version 3: where the sea follows a geoid, its surface above sea_level (common/seagrid.h;
	 * OPENED carries it, PLANETS never); 0 × 0: the sea is at sea_level everywhere. */
	struct sea_grid sea_grid;
};

struct proto_req { uint32_t req; }; /* LIST_PLANETS, STATS_REQ */

struct proto_planets {
	uint32_t req;
	uint16_t count; /* ≤ PROTO_MAX_PLANETS */
	const struct proto_planet *planets;
};

struct proto_open {
	uint32_t req;
	const char *name; /* planet name */
};

struct proto_opened {
	uint32_t req;
	uint32_t planet_id; /* names the planet in WANT and TILE for this session; ≥ 1 */
	struct proto_planet planet;
};

enum proto_class {
	PROTO_CLASS_NONE = 0,
	PROTO_CLASS_VISIBLE = 1,
	PROTO_CLASS_PREFETCH = 2,
	PROTO_CLASS_BULK = 3,
};

struct proto_want_entry {
	uint8_t layer; /* index into the planet's layers */
	uint8_t cls;   /* enum proto_class */
	uint8_t lx, ly;
	uint32_t x, y;
};

struct proto_want {
	uint32_t planet_id;
	uint32_t seq;	  /* increases with every WANT of the session */
	double lon, lat;  /* focus, degrees */
	double alt;	  /* focus height above the ellipsoid, metres */
	double vel[3];	  /* focus velocity east, north, up, m/s */
	uint32_t count;	  /* ≤ PROTO_MAX_WANT; 0 cancels everything */
	const struct proto_want_entry *entries; /* priority order, most wanted first */
};

struct proto_tile {
	uint32_t seq;	    /* the WANT it answers */
	uint32_t planet_id;
	uint8_t layer;
	struct tile_key key;	  /* node = the layer's node hash */
	struct tilecodec_hdr enc; /* format, codec, filter, size, raw_len, checksum */
	const uint8_t *payload;	  /* decoded: borrowed from the frame buffer */
	uint32_t payload_len;
};

/* HELLO / HELLO_OK `codecs` bit 31 (not a codec): the client reassembles TILE_PART frames, so
 * the server may send a tile in parts and stop between two parts when the tile is no longer
 * wanted (docs/PROTOCOL.md "TILE_PART"). */
#define PROTO_FEAT_PARTS (1u << 31)
/* Bytes of TILE_PART's fields before its bytes: offset and total, and in the first part the
 * TILE's own 44 bytes. */
#define PROTO_PART_HEAD 8u
#define PROTO_PART_FIRST_HEAD (PROTO_PART_HEAD + 44u)

/* TILE_PART: bytes [offset, offset + len) of a tile's payload of `total` bytes. The first
 * part (offset 0) carries the tile's fields (tile, its payload_len = total); a part that is
 * not the first has only offset, total and bytes (tile zeroed). */
struct proto_tile_part {
	uint32_t offset, total;
	struct proto_tile tile; /* offset 0: the TILE's fields; tile.payload unset */
	const uint8_t *bytes;	/* decoded: borrowed from the frame buffer */
	uint32_t len;
};

struct proto_tile_fail {
	uint32_t seq;
	uint32_t planet_id;
	uint8_t layer;
	struct tile_key key;
	uint16_t code; /* enum proto_code */
	const char *message;
};

enum proto_stat_kind { PROTO_STAT_NONE = 0, PROTO_STAT_U64 = 1, PROTO_STAT_F64 = 2,
		       PROTO_STAT_STR = 3 };

struct proto_stat {
	const char *key; /* dotted name, e.g. "cache.bytes" */
	uint8_t kind;	 /* enum proto_stat_kind */
	uint64_t u;
	double f;
	const char *s;
};

struct proto_stats {
	uint32_t req;
	uint16_t count; /* ≤ PROTO_MAX_STATS */
	const struct proto_stat *items;
};

#define PROTO_CLS_PLANET 1u /* cache_ls.filter bits */
#define PROTO_CLS_LEVEL 2u
#define PROTO_ANY_LX 255 /* CACHE_LS level filter: every lx of the ly */
#define PROTO_CLS_NEAR 4u

struct proto_cache_ls {
	uint32_t req;
	uint8_t filter;	    /* PROTO_CLS_* bits; fields of unset filters are ignored */
	const char *planet; /* planet name */
	uint8_t lx, ly;	    /* level */
	double lon, lat, radius_m; /* tiles whose area comes within radius_m of the point */
	uint32_t limit;	    /* most entries wanted (0: server default) */
};

enum proto_tier { PROTO_TIER_NONE = 0, PROTO_TIER_MEMORY = 1, PROTO_TIER_DISK = 2,
		  PROTO_TIER_REMOTE = 3 };

struct proto_cache_entry {
	struct tile_key key;
	uint8_t format; /* enum pix_type */
	uint8_t tier;	/* enum proto_tier */
	uint32_t bytes;
	uint32_t age_s; /* seconds since last use */
};

struct proto_cache_entries {
	uint32_t req;
	uint8_t more;	/* 1: more CACHE_ENTRIES messages follow for this req */
	uint64_t total; /* entries matching the filter (may exceed what is sent) */
	uint32_t count; /* ≤ PROTO_MAX_CACHE_ENTRIES */
	const struct proto_cache_entry *entries;
};

enum proto_cache_opk { PROTO_COP_STAT = 1, PROTO_COP_PURGE = 2, PROTO_COP_GC = 3,
		       PROTO_COP_VERIFY = 4 };
#define PROTO_COF_BBOX 1u   /* cache_op.filter bits (purge) */
#define PROTO_COF_LEVELS 2u
#define PROTO_COF_POLYGON 4u /* tiles touching a polygon (rings as PREFETCH's shape 3) */
#define PROTO_MAX_STAT_ROWS 4096 /* per CACHE_STAT message */

struct proto_cache_op {
	uint32_t req;
	uint8_t op;	    /* enum proto_cache_opk */
	const char *planet; /* stat, verify: "" every planet; purge: required; gc: "" */
	uint8_t filter;	    /* purge: PROTO_COF_* bits */
	struct geo_rect bbox; /* with PROTO_COF_BBOX: tiles touching it (west > east crosses) */
	uint8_t lmin, lmax;   /* with PROTO_COF_LEVELS: ly range */
	uint32_t nrings, npoints; /* with PROTO_COF_POLYGON: as struct proto_prefetch's */
	const uint32_t *rings;
	const struct proto_lonlat *points;
};

struct proto_cache_stat_row {
	const char *planet, *layer; /* both "": tiles of a node no planet uses (gc's garbage) */
	uint8_t ly, tier;
	uint64_t tiles, bytes;
};

struct proto_cache_stat {
	uint32_t req;
	uint8_t more; /* 1: another CACHE_STAT follows for this req */
	uint32_t count; /* ≤ PROTO_MAX_STAT_ROWS */
	const struct proto_cache_stat_row *rows;
};

struct proto_cache_done {
	uint32_t req;
	uint8_t op;
	uint64_t checked, removed, bytes, corrupt;
};

enum proto_shape { PROTO_SHAPE_NONE = 0, PROTO_SHAPE_BBOX = 1, PROTO_SHAPE_PATH = 2,
		   PROTO_SHAPE_POLYGON = 3 };

struct proto_lonlat { double lon, lat; };

struct proto_prefetch {
	uint32_t id;	    /* chosen by the client, unique among its running jobs; ≥ 1 */
	const char *planet; /* planet name */
	uint64_t layers;    /* bit i: layer i; 0: every layer */
	uint8_t shape;	    /* enum proto_shape */
	uint8_t lmin, lmax; /* ly range (lx = ly + 1), lmin ≤ lmax ≤ GRID_MAX_LEVEL */
	struct geo_rect bbox; /* SHAPE_BBOX; west may exceed east (crosses the antimeridian) */
	double width_m;	    /* SHAPE_PATH: corridor width */
	uint32_t npoints;   /* SHAPE_PATH: 1 ≤ npoints ≤ PROTO_MAX_PATH; geodesics between;
			     * SHAPE_POLYGON: the rings' points, ≤ PROTO_MAX_POLY */
	const struct proto_lonlat *points;
	uint32_t nrings;    /* SHAPE_POLYGON: 1 ≤ nrings ≤ PROTO_MAX_RINGS (common/lonpoly.h) */
	const uint32_t *rings; /* points per ring, each ≥ 3, summing to npoints */
};

enum proto_job_state { PROTO_JOB_NONE = 0, PROTO_JOB_RUNNING = 1, PROTO_JOB_DONE = 2,
		       PROTO_JOB_CANCELLED = 3, PROTO_JOB_FAILED = 4 };

struct proto_prefetch_progress {
	uint32_t id;
	uint8_t state; /* enum proto_job_state */
	uint64_t done, total; /* tiles */
	double rate;	      /* tiles per second, recent */
};

/* PREFETCH_ESTIMATE: what a PREFETCH_DRY (or the PREFETCH it describes) would take. */
struct proto_estimate_level {
	uint8_t ly;
	uint64_t tiles, bytes; /* every layer */
};

struct proto_prefetch_estimate {
	uint32_t id;	      /* the PREFETCH_DRY's */
	uint8_t tier;	      /* enum proto_tier the job's tiles would go to */
	uint64_t tiles, bytes; /* estimated, every level and layer; bytes as held in that tier */
	uint64_t budget;      /* that tier's byte budget */
	uint64_t used;	      /* bytes that tier holds now */
	uint64_t max_tiles;   /* this session's limit per job */
	uint8_t nlevels;      /* ≤ GRID_MAX_LEVEL + 1 */
	const struct proto_estimate_level *levels;
};

struct proto_arena;

struct proto_msg {
	uint16_t type; /* enum proto_type */
	union {
		struct proto_hello hello;
		struct proto_hello_ok hello_ok;
		struct proto_error error;
		struct proto_req list_planets;
		struct proto_planets planets;
		struct proto_open open;
		struct proto_opened opened;
		struct proto_want want;
		struct proto_tile tile;
		struct proto_tile_part tile_part;
		struct proto_tile_fail tile_fail;
		struct proto_req stats_req;
		struct proto_stats stats;
		struct proto_cache_ls cache_ls;
		struct proto_cache_entries cache_entries;
		struct proto_prefetch prefetch;
		struct proto_prefetch_progress prefetch_progress;
		struct proto_req prefetch_cancel; /* req = the job id */
		struct proto_prefetch prefetch_dry;
		struct proto_cache_op cache_op;
		struct proto_cache_stat cache_stat;
		struct proto_cache_done cache_done;
		struct proto_prefetch_estimate prefetch_estimate;
	};
	struct proto_arena *arena; /* owned storage of a decoded message */
};

/* Frees what a decoded message owns and zeroes it. Safe on a zeroed or encoded-only msg. */
void proto_msg_fini(struct proto_msg *m);

/* Decodes the frame at the start of buf[0 .. len) into m (which must be zeroed or finied).
 * Returns the frame's size (> 0) on success; 0 when more bytes are needed (*need as in
 * proto_frame_check); or a negative PROTO_ERR_* with err filled (may be NULL) and m zeroed.
 * On success m owns its storage (free with proto_msg_fini); a TILE's payload points into buf. */
ssize_t proto_decode(const void *buf, size_t len, struct proto_msg *m, size_t *need,
		     char err[256]);
/* Decodes a payload whose header was already checked. Returns 0 or a PROTO_ERR_*. */
int proto_decode_payload(uint16_t type, const void *payload, size_t len, struct proto_msg *m,
			 char err[256]);

/* Checks a TILE's fields (key, layer, codec header, payload length against the codec's
 * bound). Returns 0 or -EINVAL with err filled (may be NULL). The decoder applies it too. */
int proto_tile_check(const struct proto_tile *t, char err[256]);

/* ---- writer ----------------------------------------------------------------------------- */

/* An output buffer: growable (pbuf_init; grows without bound, aborts on ENOMEM) or a fixed
 * caller buffer (pbuf_init_fixed; appends that do not fit fail with -ENOSPC). */
struct pbuf {
	uint8_t *data;
	size_t len, cap;
	bool fixed;
};

void pbuf_init(struct pbuf *b);
void pbuf_init_fixed(struct pbuf *b, void *mem, size_t cap); /* mem borrowed */
void pbuf_fini(struct pbuf *b);				     /* frees growable storage */
/* Ensures room for n more bytes. Returns 0 or -ENOSPC (fixed buffers). */
int pbuf_reserve(struct pbuf *b, size_t n);
int pbuf_append(struct pbuf *b, const void *p, size_t n);
/* Drops the first n bytes (a reader consuming decoded frames). */
void pbuf_consume(struct pbuf *b, size_t n);

/* Appends one frame for m. Validates like the decoder (so a peer never receives what it must
 * reject). Returns the bytes appended, or -EINVAL / -E2BIG / -EMSGSIZE / -ENOSPC with err
 * filled (may be NULL); on error nothing is appended. */
ssize_t proto_encode(struct pbuf *b, const struct proto_msg *m, char err[256]);
/* Appends a TILE frame's header and fields but not its payload, its length counting
 * t->payload_len bytes the caller sends next (writev without copying). Same returns. */
ssize_t proto_encode_tile_head(struct pbuf *b, const struct proto_tile *t, char err[256]);
/* Appends a TILE_PART frame's header and fields for bytes [offset, offset + len) of t's
 * payload (t->payload_len bytes in all), not the bytes themselves. Same returns. */
ssize_t proto_encode_tile_part_head(struct pbuf *b, const struct proto_tile *t, uint32_t offset,
				    uint32_t len, char err[256]);

/* ---- session helpers (pure; the session owns the state) -------------------------------- */

enum proto_state {
	PROTO_ST_HANDSHAKE = 0, /* before HELLO / HELLO_OK */
	PROTO_ST_READY = 1,	/* after the handshake */
	PROTO_ST_CLOSED = 2,	/* after BYE */
};

/* Whether a message of `type` may arrive from the peer (from_server: the peer is a server)
 * in state st. Returns 0 or PROTO_ERR_STATE with err filled. */
int proto_check_state(enum proto_state st, bool from_server, uint16_t type, char err[256]);
/* Checks a decoded message from a client against the session's limits (want-set size, frame
 * size). Returns 0 or -E2BIG with a message fit for an ERROR (PROTO_E_LIMIT). */
int proto_check_limits(const struct proto_limits *l, const struct proto_msg *m,
		       size_t frame_len, char err[256]);

/* A token bucket for the message-rate limit: `rate` tokens per second, at most `burst`. */
struct proto_rate {
	double tokens;
	uint64_t last_ns;
	bool started;
};
/* Takes one token at time now_ns (monotonic). Returns true if the message is allowed. */
bool proto_rate_take(struct proto_rate *r, uint64_t now_ns, uint32_t rate, uint32_t burst);

#endif
