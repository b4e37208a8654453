/* conf — see conf.h. A table maps each (section, key) to a parser and a field; a pass over the
 * file refuses unknown sections and keys, then each entry is parsed by its table row, then
 * cross-key checks (a non-loopback listener needs a token file) run with the line of the key
 * that made them fail. */
#include "conf.h"

#include <arpa/inet.h>
#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/ini.h"
#include "common/proto.h"
#include "common/xalloc.h"

enum kind { K_PATH, K_INT, K_SIZE_MB, K_SIZE_KB, K_MODE, K_ENUM, K_TCP, K_LOG, K_BOOL, K_ADDR,
	    K_REDIS, K_STR };

struct row {
	const char *sec, *key;
	enum kind kind;
	long lo, hi;
	const char *const *names; /* K_ENUM */
};

static const char *const token_names[] = { "auto", "tcp", "all", NULL };
static const char *const compress_names[] = { "auto", "never", "always", NULL };
static const char *const disk_codec_names[] = { "zstd", "lz4", NULL };

static const struct row rows[] = {
	{ "listen", "unix", K_PATH, 0, 0, NULL },
	{ "listen", "unix_mode", K_MODE, 0, 0777, NULL },
	{ "listen", "tcp", K_TCP, 0, 0, NULL },
	{ "listen", "token_file", K_PATH, 0, 0, NULL },
	{ "listen", "require_token", K_ENUM, 0, 0, token_names },
	{ "listen", "max_sessions", K_INT, 1, 100000, NULL },
	{ "listen", "max_preauth", K_INT, 1, 100000, NULL },
	{ "listen", "max_preauth_per_peer", K_INT, 1, 100000, NULL },
	{ "listen", "handshake_timeout", K_INT, 1, 3600, NULL },
	{ "listen", "frame_timeout", K_INT, 1, 3600, NULL },
	{ "engine", "planets", K_PATH, 0, 0, NULL },
	{ "engine", "strict_planets", K_BOOL, 0, 1, NULL },
	{ "engine", "prefault", K_BOOL, 0, 1, NULL },
	{ "engine", "workers", K_INT, 0, 1024, NULL },
	{ "engine", "worker_nice", K_INT, 0, 19, NULL },
	{ "engine", "cache_mb", K_SIZE_MB, 16, 1L << 24, NULL },
	{ "engine", "image_cache_mb", K_SIZE_MB, 16, 1L << 20, NULL },
	{ "session", "max_want", K_INT, 1, PROTO_MAX_WANT, NULL },
	{ "session", "max_rate", K_INT, 0, 1000000, NULL },
	{ "session", "max_pending_kb", K_SIZE_KB, 64, 1L << 22, NULL },
	{ "session", "max_frame_kb", K_SIZE_KB, 0, 16384, NULL },
	{ "session", "send_queue_ms", K_INT, 0, 10000, NULL },
	{ "session", "bbr", K_BOOL, 0, 1, NULL },
	{ "session", "raw_above_mbit", K_INT, 0, 1000000, NULL },
	{ "session", "lossy_below_mbit", K_INT, 0, 1000000, NULL },
	{ "session", "webp_quality", K_INT, 1, 100, NULL },
	{ "session", "max_jobs", K_INT, 0, 64, NULL },
	{ "session", "compress", K_ENUM, 0, 0, compress_names },
	{ "prefetch", "max_tiles", K_INT, 1, 1L << 26, NULL },
	{ "prefetch", "max_tiles_local", K_INT, 0, 1L << 26, NULL },
	{ "prefetch", "max_jobs_local", K_INT, 0, 64, NULL },
	{ "prefetch", "max_jobs_total", K_INT, 1, 4096, NULL },
	{ "prefetch", "max_tiles_total", K_INT, 1, 1L << 32, NULL },
	{ "log", "level", K_LOG, 0, 0, NULL },
	{ "store", "path", K_PATH, 0, 0, NULL },
	{ "store", "disk_mb", K_SIZE_MB, 1, 1L << 26, NULL },
	{ "store", "disk_codec", K_ENUM, 0, 0, disk_codec_names },
	{ "store", "redis", K_REDIS, 0, 0, NULL },
	{ "store", "redis_password", K_STR, 0, 0, NULL },
	{ "store", "redis_lease_ms", K_INT, 50, 600000, NULL },
	{ "http", "listen", K_ADDR, 0, 0, NULL },
	{ "http", "open", K_BOOL, 0, 1, NULL },
	{ "http", "cesium", K_PATH, 0, 0, NULL },
	{ "http", "threads", K_INT, 1, 64, NULL },
	{ "http", "max_connections", K_INT, 1, 100000, NULL },
	{ "http", "max_per_address", K_INT, 0, 100000, NULL },
	{ "http", "timeout_s", K_INT, 1, 3600, NULL },
	{ "http", "max_age_s", K_INT, 0, 31536000, NULL },
	{ "http", "cache_mb", K_INT, 1, 1 << 20, NULL },
	{ "tls", "cert", K_PATH, 0, 0, NULL },
	{ "tls", "key", K_PATH, 0, 0, NULL },
};

static int __attribute__((format(printf, 5, 6)))
cerr(char *err, const char *path, int line, const char *key, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	err_vset_at(err, path, line, key, fmt, ap);
	va_end(ap);
	return -EINVAL;
}

static char *resolve(const char *cfg, const char *v)
{
	if (v[0] == '/' || !strchr(cfg, '/'))
		return xstrdup(v);
	const char *slash = strrchr(cfg, '/');
	size_t d = (size_t)(slash - cfg);
	size_t n = d + 1 + strlen(v) + 1;
	char *s = xmalloc(n);
	snprintf(s, n, "%.*s/%s", (int)d, cfg, v);
	return s;
}

static int parse_long(const char *s, int base, long *out)
{
	char *end;
	errno = 0;
	long v = strtol(s, &end, base);
	if (end == s || *end != '\0' || errno == ERANGE)
		return -EINVAL;
	*out = v;
	return 0;
}

int conf_split_hostport(const char *s, char *host, size_t hostcap, char *port, size_t portcap)
{
	const char *colon;
	const char *h = s;
	size_t hl;
	if (s[0] == '[') {
		const char *close = strchr(s, ']');
		if (!close || close[1] != ':')
			return -EINVAL;
		h = s + 1;
		hl = (size_t)(close - h);
		colon = close + 1;
	} else {
		colon = strrchr(s, ':');
		if (!colon || strchr(s, ':') != colon)
			return -EINVAL;
		hl = (size_t)(colon - s);
	}
	const char *p = colon + 1;
	long v;
	if (hl == 0 || hl >= hostcap || strlen(p) >= portcap || parse_long(p, 10, &v) || v < 0 ||
	    v > 65535)
		return -EINVAL;
	memcpy(host, h, hl);
	host[hl] = '\0';
	strcpy(port, p);
	return 0;
}

bool conf_addr_is_loopback(const char *hostport)
{
	char host[256], port[16];
	if (conf_split_hostport(hostport, host, sizeof host, port, sizeof port))
		return false;
	if (strcmp(host, "localhost") == 0)
		return true;
	struct in_addr a4;
	struct in6_addr a6;
	if (inet_pton(AF_INET, host, &a4) == 1)
		return (ntohl(a4.s_addr) >> 24) == 127;
	if (inet_pton(AF_INET6, host, &a6) == 1)
		return memcmp(&a6, &in6addr_loopback, sizeof a6) == 0;
	return false;
}

static void defaults(struct conf *c)
{
	memset(c, 0, sizeof *c);
	c->unix_path = xstrdup("/run/clipmapd/clipmapd.sock");
	c->unix_mode = 0660;
	c->tcp[0] = xstrdup("127.0.0.1:7878");
	c->ntcp = 1;
	c->max_sessions = 256;
	c->max_preauth = 32;
	c->max_preauth_per_peer = 8;
	c->handshake_timeout = 10;
	c->frame_timeout = 30;
	c->planets_dir = xstrdup("/etc/clipmap/planets");
	c->worker_nice = 5;
	c->prefault = true;
	c->cache_bytes = (size_t)1024 << 20;
	c->image_cache_mb = 256; /* PLANET_IMAGE_CACHE_MB (test_conf checks they agree) */
	c->max_want = PROTO_MAX_WANT;
	c->max_rate = 200;
	c->max_pending = (uint64_t)8 << 20;
	c->send_queue_ms = 100;
	c->bbr = true;
	c->raw_above_mbit = 800;
	c->lossy_below_mbit = 50;
	c->webp_quality = 80;
	c->max_frame = 0;
	c->max_jobs = 4;
	c->pf_max_tiles = 4000000;
	c->pf_max_tiles_local = 250000;
	c->pf_max_jobs_local = 1;
	c->pf_max_jobs_total = 16;
	c->pf_max_tiles_total = 16000000;
	c->log_level = LOG_INFO;
	c->store_bytes = (uint64_t)1024 << 20;
	c->store_redis_lease_ms = 2000;
	c->http_threads = 2;
	c->http_max_conns = 256;
	c->http_max_per_addr = 32;
	c->http_timeout_s = 15;
	c->http_max_age_s = 600;
	c->http_cache_mb = 64;
}

static int set_tcp(struct conf *c, const char *path, const struct ini_entry *e, char *err)
{
	for (int i = 0; i < c->ntcp; i++)
		free(c->tcp[i]);
	c->ntcp = 0;
	const char *s = e->value;
	while (*s) {
		while (*s == ',' || isspace((unsigned char)*s))
			s++;
		if (!*s)
			break;
		const char *end = s;
		while (*end && *end != ',' && !isspace((unsigned char)*end))
			end++;
		char item[300], host[256], port[16];
		if ((size_t)(end - s) >= sizeof item)
			return cerr(err, path, e->line, e->key, "address too long");
		memcpy(item, s, (size_t)(end - s));
		item[end - s] = '\0';
		if (conf_split_hostport(item, host, sizeof host, port, sizeof port))
			return cerr(err, path, e->line, e->key,
				    "\"%s\" is not host:port (IPv6 as [addr]:port, port 0-65535)", item);
		if (c->ntcp == CONF_MAX_TCP)
			return cerr(err, path, e->line, e->key, "at most %d addresses", CONF_MAX_TCP);
		c->tcp[c->ntcp++] = xstrdup(item);
		s = end;
	}
	return 0;
}

static int apply(struct conf *c, const char *path, const struct row *r, const struct ini_entry *e,
		 char *err)
{
	const char *v = e->value;
	long n = 0;
	switch (r->kind) {
	case K_PATH: {
		char **dst = strcmp(r->key, "unix") == 0	 ? &c->unix_path
			     : strcmp(r->key, "token_file") == 0 ? &c->token_file
			     : strcmp(r->key, "path") == 0	 ? &c->store_path
			     : strcmp(r->key, "cesium") == 0	 ? &c->http_cesium
			     : strcmp(r->key, "cert") == 0	 ? &c->tls_cert
			     : strcmp(r->key, "key") == 0	 ? &c->tls_key
								 : &c->planets_dir;
		free(*dst);
		*dst = NULL;
		if (*v)
			*dst = resolve(path, v);
		else if (dst == &c->planets_dir)
			return cerr(err, path, e->line, e->key, "must not be empty");
		return 0;
	}
	case K_TCP:
		return set_tcp(c, path, e, err);
	case K_BOOL: {
		bool *dst = strcmp(r->key, "open") == 0	 ? &c->http_open
			    : strcmp(r->key, "bbr") == 0 ? &c->bbr
			    : strcmp(r->key, "prefault") == 0 ? &c->prefault
							 : &c->strict_planets;
		if (strcmp(v, "true") == 0 || strcmp(v, "yes") == 0 || strcmp(v, "1") == 0)
			*dst = true;
		else if (strcmp(v, "false") == 0 || strcmp(v, "no") == 0 || strcmp(v, "0") == 0)
			*dst = false;
		else
			return cerr(err, path, e->line, e->key, "\"%s\": expected true or false", v);
		return 0;
	}
	case K_REDIS: { /* [store] redis: unix:/path (relative to the file) or host:port */
		char host[256], port[16];
		free(c->store_redis);
		c->store_redis = NULL;
		if (!*v)
			return 0;
		if (strncmp(v, "unix:", 5) == 0) {
			if (!v[5])
				return cerr(err, path, e->line, e->key, "unix: needs a socket path");
			char *p = resolve(path, v + 5);
			size_t len = strlen(p) + 6;
			c->store_redis = xmalloc(len);
			snprintf(c->store_redis, len, "unix:%s", p);
			free(p);
			return 0;
		}
		if (conf_split_hostport(v, host, sizeof host, port, sizeof port) || !host[0])
			return cerr(err, path, e->line, e->key,
				    "\"%s\" is not unix:/path or host:port (IPv6 as [addr]:port)", v);
		c->store_redis = xstrdup(v);
		return 0;
	}
	case K_STR: /* [store] redis_password */
		free(c->store_redis_password);
		c->store_redis_password = *v ? xstrdup(v) : NULL;
		return 0;
	case K_ADDR: { /* [http] listen: one host:port, or empty for none */
		char host[256], port[16];
		free(c->http_listen);
		c->http_listen = NULL;
		if (!*v)
			return 0;
		if (conf_split_hostport(v, host, sizeof host, port, sizeof port))
			return cerr(err, path, e->line, e->key,
				    "\"%s\" is not host:port (IPv6 as [addr]:port, port 0-65535)", v);
		c->http_listen = xstrdup(v);
		return 0;
	}
	case K_LOG:
		if (log_parse_level(v, &c->log_level))
			return cerr(err, path, e->line, e->key,
				    "\"%s\": expected error, warn, info or debug", v);
		return 0;
	case K_ENUM:
		for (int i = 0; r->names[i]; i++) {
			if (strcmp(v, r->names[i]) == 0) {
				if (strcmp(r->key, "require_token") == 0)
					c->require_token = (enum conf_token_policy)i;
				else if (strcmp(r->key, "disk_codec") == 0)
					c->disk_codec = (enum conf_disk_codec)i;
				else
					c->compress = (enum conf_compress)i;
				return 0;
			}
		}
		{
			char names[128] = "";
			for (int i = 0; r->names[i]; i++)
				snprintf(names + strlen(names), sizeof names - strlen(names), "%s%s",
					 i == 0 ? "" : r->names[i + 1] ? ", " : " or ", r->names[i]);
			return cerr(err, path, e->line, e->key, "\"%s\": expected %s", v, names);
		}
	case K_MODE:
		if (parse_long(v, 8, &n) || n < r->lo || n > r->hi)
			return cerr(err, path, e->line, e->key, "\"%s\": expected an octal mode like 0660",
				    v);
		c->unix_mode = (unsigned)n;
		return 0;
	case K_INT:
	case K_SIZE_MB:
	case K_SIZE_KB:
		if (parse_long(v, 10, &n) || n < r->lo || n > r->hi)
			return cerr(err, path, e->line, e->key, "\"%s\": expected an integer in [%ld, %ld]",
				    v, r->lo, r->hi);
		break;
	}
	const char *k = r->key;
	if (strcmp(k, "max_sessions") == 0)
		c->max_sessions = (int)n;
	else if (strcmp(k, "max_preauth") == 0)
		c->max_preauth = (int)n;
	else if (strcmp(k, "max_preauth_per_peer") == 0)
		c->max_preauth_per_peer = (int)n;
	else if (strcmp(k, "handshake_timeout") == 0)
		c->handshake_timeout = (int)n;
	else if (strcmp(k, "frame_timeout") == 0)
		c->frame_timeout = (int)n;
	else if (strcmp(k, "workers") == 0)
		c->workers = (int)n;
	else if (strcmp(k, "worker_nice") == 0)
		c->worker_nice = (int)n;
	else if (strcmp(k, "cache_mb") == 0 && strcmp(r->sec, "engine") == 0)
		c->cache_bytes = (size_t)n << 20;
	else if (strcmp(k, "image_cache_mb") == 0)
		c->image_cache_mb = (size_t)n;
	else if (strcmp(k, "max_want") == 0)
		c->max_want = (uint32_t)n;
	else if (strcmp(k, "max_rate") == 0)
		c->max_rate = (uint32_t)n;
	else if (strcmp(k, "max_pending_kb") == 0)
		c->max_pending = (uint64_t)n << 10;
	else if (strcmp(k, "raw_above_mbit") == 0)
		c->raw_above_mbit = (uint32_t)n;
	else if (strcmp(k, "lossy_below_mbit") == 0)
		c->lossy_below_mbit = (uint32_t)n;
	else if (strcmp(k, "webp_quality") == 0)
		c->webp_quality = (int)n;
	else if (strcmp(k, "send_queue_ms") == 0)
		c->send_queue_ms = (uint32_t)n;
	else if (strcmp(k, "max_frame_kb") == 0)
		c->max_frame = (uint32_t)n << 10;
	else if (strcmp(k, "max_jobs") == 0)
		c->max_jobs = (uint32_t)n;
	else if (strcmp(k, "max_tiles") == 0)
		c->pf_max_tiles = (uint64_t)n;
	else if (strcmp(k, "max_tiles_local") == 0)
		c->pf_max_tiles_local = (uint64_t)n;
	else if (strcmp(k, "max_jobs_local") == 0)
		c->pf_max_jobs_local = (uint32_t)n;
	else if (strcmp(k, "max_jobs_total") == 0)
		c->pf_max_jobs_total = (uint32_t)n;
	else if (strcmp(k, "max_tiles_total") == 0)
		c->pf_max_tiles_total = (uint64_t)n;
	else if (strcmp(k, "disk_mb") == 0)
		c->store_bytes = (uint64_t)n << 20;
	else if (strcmp(k, "redis_lease_ms") == 0)
		c->store_redis_lease_ms = (uint32_t)n;
	else if (strcmp(k, "threads") == 0)
		c->http_threads = (int)n;
	else if (strcmp(k, "max_connections") == 0)
		c->http_max_conns = (int)n;
	else if (strcmp(k, "max_per_address") == 0)
		c->http_max_per_addr = (int)n;
	else if (strcmp(k, "timeout_s") == 0)
		c->http_timeout_s = (int)n;
	else if (strcmp(k, "max_age_s") == 0)
		c->http_max_age_s = (int)n;
	else if (strcmp(k, "cache_mb") == 0 && strcmp(r->sec, "http") == 0)
		c->http_cache_mb = (int)n;
	return 0;
}

static int check(struct conf *c, const struct ini_file *f, char *err)
{
	const char *path = f->path;
	/* The line to blame for a cross-key error: the key that asked for the listener. */
	int tcp_line = 0, tok_line = 0, unix_line = 0, frame_line = 0, http_line = 0, tls_line = 0;
	for (size_t i = 0; i < f->n; i++)
		for (size_t j = 0; j < f->sections[i].n; j++) {
			const struct ini_entry *e = &f->sections[i].entries[j];
			if (strcmp(f->sections[i].name, "listen") == 0 && strcmp(e->key, "tcp") == 0)
				tcp_line = e->line;
			if (strcmp(f->sections[i].name, "listen") == 0 &&
			    strcmp(e->key, "require_token") == 0)
				tok_line = e->line;
			if (strcmp(f->sections[i].name, "listen") == 0 && strcmp(e->key, "unix") == 0)
				unix_line = e->line;
			if (strcmp(f->sections[i].name, "session") == 0 &&
			    strcmp(e->key, "max_frame_kb") == 0)
				frame_line = e->line;
			if (strcmp(f->sections[i].name, "http") == 0 && strcmp(e->key, "listen") == 0)
				http_line = e->line;
			if (strcmp(f->sections[i].name, "tls") == 0)
				tls_line = e->line;
		}
	if (!c->tls_cert != !c->tls_key)
		return cerr(err, path, tls_line, c->tls_cert ? "cert" : "key",
			    "[tls] needs both cert and key (%s is not set)",
			    c->tls_cert ? "key" : "cert");
	if (!c->token_file) {
		for (int i = 0; i < c->ntcp; i++) {
			bool need = c->require_token != CONF_TOKEN_AUTO ||
				    !conf_addr_is_loopback(c->tcp[i]);
			if (need)
				return cerr(err, path, tcp_line, "tcp",
					    "listener %s requires a token: set token_file", c->tcp[i]);
		}
		if (c->require_token == CONF_TOKEN_ALL && c->unix_path)
			return cerr(err, path, tok_line, "require_token",
				    "\"all\" requires a token: set token_file");
	}
	if (c->http_listen && !c->http_open && !c->token_file &&
	    !conf_addr_is_loopback(c->http_listen))
		return cerr(err, path, http_line, "listen",
			    "HTTP on %s (not loopback) requires a token (set [listen] token_file) "
			    "or open = true",
			    c->http_listen);
	if (c->unix_path && strlen(c->unix_path) >= 108)
		return cerr(err, path, unix_line, "unix", "path longer than 107 bytes");
	if (!c->unix_path && c->ntcp == 0)
		return cerr(err, path, 0, NULL, "no listener: set [listen] unix or tcp");
	if (c->max_frame && c->max_frame < 64u << 10)
		return cerr(err, path, frame_line, "max_frame_kb",
			    "%u KiB is below the 64 KiB a full want-set needs", c->max_frame >> 10);
	return 0;
}

/* The line where entry j of section i was given before (the same key in a section of the
 * same name, earlier in the file), or 0. */
static int first_line(const struct ini_file *f, size_t i, size_t j)
{
	const struct ini_section *s = &f->sections[i];
	for (size_t a = 0; a <= i; a++) {
		const struct ini_section *t = &f->sections[a];
		if (strcmp(t->name, s->name) != 0)
			continue;
		for (size_t b = 0; b < (a == i ? j : t->n); b++)
			if (strcmp(t->entries[b].key, s->entries[j].key) == 0)
				return t->entries[b].line;
	}
	return 0;
}

int conf_parse(const char *path, const char *text, size_t len, struct conf *c, char err[256])
{
	struct ini_file *f = NULL;
	int rc = ini_parse(path, text, len, &f, err);
	if (rc)
		return rc;
	defaults(c);
	c->path = xstrdup(path);
	for (size_t i = 0; i < f->n && !rc; i++) {
		const struct ini_section *s = &f->sections[i];
		bool known = false;
		for (size_t r = 0; r < sizeof rows / sizeof rows[0]; r++)
			known |= strcmp(rows[r].sec, s->name) == 0;
		if (!known) {
			if (s->line == 0 && s->n)
				rc = cerr(err, path, s->entries[0].line, s->entries[0].key,
					  "key outside any section");
			else
				rc = cerr(err, path, s->line, NULL,
					  "unknown section [%s] (expected listen, engine, session, "
					  "prefetch, log, store, http, tls)",
					  s->name);
			break;
		}
		for (size_t j = 0; j < s->n && !rc; j++) {
			const struct ini_entry *e = &s->entries[j];
			const struct row *row = NULL;
			for (size_t r = 0; r < sizeof rows / sizeof rows[0]; r++)
				if (strcmp(rows[r].sec, s->name) == 0 && strcmp(rows[r].key, e->key) == 0)
					row = &rows[r];
			int first = first_line(f, i, j);
			if (!row)
				rc = cerr(err, path, e->line, e->key, "unknown key in [%s]", s->name);
			else if (first)
				rc = cerr(err, path, e->line, e->key, "given twice in [%s] (first at line %d)",
					  s->name, first);
			else
				rc = apply(c, path, row, e, err);
		}
	}
	if (!rc)
		rc = check(c, f, err);
	ini_free(f);
	if (rc)
		conf_fini(c);
	return rc;
}

int conf_load(const char *path, struct conf *c, char err[256])
{
	memset(c, 0, sizeof *c);
	FILE *fp = fopen(path, "rb");
	if (!fp) {
		int e = -errno;
		if (err)
			err_set(err, "%s: %s", path, strerror(-e));
		return e;
	}
	char *buf = NULL;
	size_t n = 0, cap = 0;
	for (;;) {
		if (n + 4096 > cap) {
			cap = cap ? cap * 2 : 8192;
			buf = xrealloc(buf, cap);
		}
		size_t r = fread(buf + n, 1, cap - n, fp);
		n += r;
		if (r == 0)
			break;
		if (n > (1u << 20)) {
			free(buf);
			fclose(fp);
			return cerr(err, path, 0, NULL, "larger than 1 MiB");
		}
	}
	int bad = ferror(fp);
	fclose(fp);
	if (bad) {
		free(buf);
		if (err)
			err_set(err, "%s: read error", path);
		return -EIO;
	}
	int rc = conf_parse(path, buf, n, c, err);
	free(buf);
	return rc;
}

void conf_fini(struct conf *c)
{
	free(c->path);
	free(c->unix_path);
	for (int i = 0; i < c->ntcp; i++)
		free(c->tcp[i]);
	free(c->token_file);
	free(c->planets_dir);
	free(c->store_path);
	free(c->store_redis);
	free(c->store_redis_password);
	free(c->http_listen);
	free(c->http_cesium);
	free(c->tls_cert);
	free(c->tls_key);
	memset(c, 0, sizeof *c);
}
