/* conf — clipmapd.conf (INI): listeners, token, engine sizing, planets directory, per-session
 * limits, the log level, the persistent store, the HTTP endpoint and TLS. Every key has a default (a zeroed file is a valid config) and is
 * documented in conf/clipmapd.conf. Loading refuses unknown sections and keys and reports the
 * first error as "file:line: key: message". Relative paths resolve against the config file's
 * directory.
 *
 * Ownership: conf_load fills a caller-owned struct conf whose strings it owns; conf_fini frees
 * them. Not thread-safe while loading; read-only afterwards.
 */
#ifndef CLIPMAP_CONF_H
#define CLIPMAP_CONF_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/log.h"

enum conf_token_policy {
	CONF_TOKEN_AUTO = 0, /* non-loopback TCP listeners require the token */
	CONF_TOKEN_TCP,	     /* every TCP listener requires it */
	CONF_TOKEN_ALL,	     /* every listener, the Unix socket too */
};

enum conf_compress {
	CONF_COMPRESS_AUTO = 0, /* zstd-1 on non-loopback TCP when the client decodes it */
	CONF_COMPRESS_NEVER,
	CONF_COMPRESS_ALWAYS, /* zstd-1 (else lz4) on every listener when the client decodes it */
};

/* The disk tier's codec at rest (the texels after the format's filter). */
enum conf_disk_codec {
	CONF_DISK_ZSTD = 0, /* zstd-1: the smaller file */
	CONF_DISK_LZ4,	    /* lz4: 2-3x faster to decode, a larger file (README, bench_store) */
};

#define CONF_MAX_TCP 8

struct conf {
	char *path; /* the file read, for messages */
	/* [listen] */
	char *unix_path; /* NULL: no Unix socket */
	unsigned unix_mode;
	char *tcp[CONF_MAX_TCP]; /* "host:port" (IPv6 as "[addr]:port"); port 0: ephemeral */
	int ntcp;
	char *token_file;   /* NULL: no token (then no listener may require one) */
	enum conf_token_policy require_token;
	int max_sessions;	  /* authenticated sessions (the Unix socket has UNIX_RESERVE more) */
	int max_preauth;	  /* connections before HELLO_OK, per listener kind (Unix, TCP) */
	int max_preauth_per_peer; /* of those, per TCP peer address */
	int handshake_timeout;	  /* s from accept to HELLO_OK */
	int frame_timeout;	  /* s a frame may take to arrive once its first byte has */
	/* [engine] */
	char *planets_dir;
	bool strict_planets; /* a bad planet file stops the daemon (else it is skipped) */
	bool prefault;	     /* fault the tile pool in up to cache_mb at start (clipmapd.c) */
	int workers;	 /* 0: one per CPU */
	int worker_nice; /* niceness added to workers */
	size_t cache_bytes;
	size_t image_cache_mb; /* the planets' shared OIIO image cache (file nodes), MiB */
	/* [session] */
	uint32_t max_want, max_rate, max_frame, max_jobs;
	uint64_t max_pending;
	uint32_t send_queue_ms; /* TCP sessions' send window: this much of the measured rate */
	bool bbr;		/* TCP sessions ask for BBR congestion control */
	uint32_t raw_above_mbit; /* compress auto: tiles go raw on links measured faster (0: never) */
	uint32_t lossy_below_mbit; /* lossy codecs (to clients offering them) on TCP links
				    * measured slower (0: never) */
	int webp_quality;	   /* the webp codec's quality, 1–100 */
	enum conf_compress compress;
	/* [prefetch] (prefetch.h's struct prefetch_limits) */
	uint64_t pf_max_tiles, pf_max_tiles_local, pf_max_tiles_total;
	uint32_t pf_max_jobs_local, pf_max_jobs_total;
	/* [log] */
	enum log_level log_level;
	/* [store] */
	char *store_path;     /* the disk tier's LMDB file; NULL: no disk tier */
	uint64_t store_bytes; /* its budget at rest (disk_mb) */
	enum conf_disk_codec disk_codec; /* what it writes (it reads either) */
	char *store_redis;    /* the shared tier: "unix:/abs/path" or "host:port"; NULL: none */
	char *store_redis_password; /* AUTH; NULL: none */
	uint32_t store_redis_lease_ms; /* a generation lease's lifetime (default 2000) */
	/* [http] */
	char *http_listen;     /* "host:port"; NULL: no HTTP endpoint */
	char *http_cesium;     /* CesiumJS's Build/Cesium; NULL: beside the program (build tree) */
	bool http_open;	       /* non-loopback without the token */
	int http_threads;      /* libmicrohttpd's thread pool */
	int http_max_conns;    /* connections at once */
	int http_max_per_addr; /* per client address; 0: no limit */
	int http_timeout_s;    /* an idle or slow connection is closed after it */
	int http_max_age_s;    /* Cache-Control max-age of tiles */
	int http_cache_mb;     /* encoded tiles kept by ETag, MiB */
	/* [tls] */
	char *tls_cert; /* PEM certificate chain: every TCP listener speaks TLS; NULL: plain */
	char *tls_key;	/* its PEM private key (given together with cert) */
};

/* Reads and checks a config file into c (zeroed by the call). Returns 0 or -errno with err
 * filled ("file:line: key: message"); on error c holds nothing to free. */
int conf_load(const char *path, struct conf *c, char err[256]);
/* The same from text (path used in messages and to resolve relative paths). */
int conf_parse(const char *path, const char *text, size_t len, struct conf *c, char err[256]);
void conf_fini(struct conf *c);
/* Whether "host:port" names a loopback address (127.0.0.0/8, ::1, "localhost"). */
bool conf_addr_is_loopback(const char *hostport);
/* Splits "host:port" / "[v6]:port" into host (owned by the caller's buffer) and port.
 * Returns 0 or -EINVAL. */
int conf_split_hostport(const char *s, char *host, size_t hostcap, char *port, size_t portcap);

#endif
