/* clipmapd — the daemon's main: arguments, configuration, the planet set, signals through a
 * signalfd watched by the event loop (SIGTERM/SIGINT: graceful stop; SIGHUP: re-read
 * clipmapd.conf for the keys that can change live, then reload the planet files), and
 * systemd notification (READY, RELOADING, STOPPING, WATCHDOG).
 * Exit status: 0 after a clean stop, 1 on a runtime failure, 2 on bad usage or configuration.
 */
#include <errno.h>
#include <fcntl.h>
#include <malloc.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/signalfd.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/img.h"
#include "common/log.h"
#include "common/xthread.h"
#include "engine/cache.h"
#include "engine/fault.h"
#include "engine/planets.h"
#include "engine/sched.h"
#include "engine/store.h"
#include "engine/tilemem.h"
#include "store_redis.h"
#include "conf.h"
#include "http.h"
#include "metrics.h"
#include "server.h"
#include "tls.h"

#define DEFAULT_CONF "/etc/clipmap/clipmapd.conf"

struct daemon {
	struct conf conf;
	struct server *srv;
	int sigfd;
	uint64_t generation;
	uint64_t watchdog_usec, last_watchdog_ns;
	struct store *store; /* the disk tier, NULL without [store] path */
	struct remote *remote; /* the fleet's Redis tier, NULL without [store] redis */
	struct store_stats store_seen; /* its counters at the last tick */
	bool store_failing;	       /* its writes fail (logged once) */
	bool store_pf_evicting;	       /* evicting prefetched tiles (logged when it starts) */
	uint64_t store_pf_from;	       /* the count when it started */
	uint64_t store_pf_last_ns;     /* when the count last grew */
	struct http *http;	       /* the HTTP endpoint, NULL without [http] listen */
	uint64_t metrics_ns;	       /* when its /metrics text was last gathered */
	struct prefault {	       /* [engine] prefault: the tile pool faulted in at start */
		pthread_t th;
		bool started;
		_Atomic bool stop;
		size_t tile_bytes, bytes;
	} pf;
};

static void usage(FILE *f)
{
	fprintf(f, "usage: clipmapd [-c FILE] [--check-config]\n"
		   "  -c, --config FILE   configuration (default " DEFAULT_CONF ")\n"
		   "      --check-config  validate the configuration and the planet files, then exit\n"
		   "  -V, --version       the version\n"
		   "  -h, --help          this text\n"
		   "exit status: 0 stopped cleanly, 1 runtime failure, 2 bad usage or configuration\n");
}

/* The planets of d->conf's directory into *ps (returned owned), every file on its own unless
 * strict_planets; the files left out are logged as errors. Returns 0 or -errno with err. */
static int load_planets(struct daemon *d, struct img_cache *images, struct planet_set **ps,
			char err[256])
{
	int rc = d->conf.strict_planets
			 ? planet_set_load(d->conf.planets_dir, ++d->generation, images, ps, err)
			 : planet_set_load_each(d->conf.planets_dir, ++d->generation, images, ps, err);
	for (size_t i = 0; rc == 0 && i < (*ps)->nskipped; i++)
		log_msg(LOG_ERROR, "planet file skipped (strict_planets = false): %s",
			(*ps)->skipped[i]);
	return rc;
}

static bool same_str(const char *a, const char *b)
{
	return (!a && !b) || (a && b && strcmp(a, b) == 0);
}

/* The keys of nc that only a restart applies and that differ from the running c, named in a
 * warning each. */
static void warn_restart_keys(const struct conf *c, const struct conf *nc)
{
	bool tcp = c->ntcp == nc->ntcp;
	for (int i = 0; tcp && i < c->ntcp; i++)
		tcp = strcmp(c->tcp[i], nc->tcp[i]) == 0;
	const struct {
		bool same;
		const char *key;
	} k[] = {
		{ same_str(c->unix_path, nc->unix_path), "[listen] unix" },
		{ c->unix_mode == nc->unix_mode, "[listen] unix_mode" },
		{ tcp, "[listen] tcp" },
		{ same_str(c->token_file, nc->token_file), "[listen] token_file" },
		{ c->require_token == nc->require_token, "[listen] require_token" },
		{ c->workers == nc->workers, "[engine] workers" },
		{ c->worker_nice == nc->worker_nice, "[engine] worker_nice" },
		{ c->prefault == nc->prefault, "[engine] prefault" },
		{ c->cache_bytes == nc->cache_bytes, "[engine] cache_mb" },
		{ c->image_cache_mb == nc->image_cache_mb, "[engine] image_cache_mb" },
		{ c->compress == nc->compress, "[session] compress" },
		{ same_str(c->store_redis, nc->store_redis), "[store] redis" },
		{ same_str(c->store_redis_password, nc->store_redis_password),
		  "[store] redis_password" },
		{ c->store_redis_lease_ms == nc->store_redis_lease_ms, "[store] redis_lease_ms" },
		/* turning TLS on or off changes the listeners; new files are reloaded */
		{ !c->tls_cert == !nc->tls_cert, "[tls] cert" },
	};
	for (size_t i = 0; i < sizeof k / sizeof k[0]; i++)
		if (!k[i].same)
			log_msg(LOG_WARN, "reload: %s changed in %s: not applied until a restart",
				k[i].key, c->path);
}

/* [tls] cert and key of c as PEM text, for the HTTPS endpoint. Returns 0 with both owned
 * (free_pems), or -errno with err naming the file (nothing owned then). */
static int read_pems(const struct conf *c, char **cert, char **key, char err[256])
{
	*cert = *key = NULL;
	int rc = tls_pem_read("cert", c->tls_cert, cert, err);
	if (!rc && (rc = tls_pem_read("key", c->tls_key, key, err))) {
		free(*cert);
		*cert = NULL;
	}
	return rc;
}

static void free_pems(char *cert, char *key)
{
	if (key)
		memset(key, 0, strlen(key)); /* the key's bytes do not stay in freed memory */
	free(key);
	free(cert);
}

/* [tls] cert and key read again (a renewed certificate, or new paths): new TCP connections
 * and HTTPS handshakes get them, open connections keep theirs. Files that do not load change
 * nothing. */
static void reload_tls(struct daemon *d, struct conf *c, struct conf *nc)
{
	char err[256], warn[256];
	int rc = server_reload_tls(d->srv, nc->tls_cert, nc->tls_key, err, warn);
	if (rc) {
		log_msg(LOG_ERROR, "reload: %s; the listeners keep the running certificate", err);
		return;
	}
	if (warn[0])
		log_msg(LOG_WARN, "reload: %s", warn);
	char *cert = NULL, *key = NULL;
	if (d->http && (read_pems(nc, &cert, &key, err) || http_reload_tls(d->http, cert, key, err)))
		log_msg(LOG_ERROR, "reload: %s; the HTTPS endpoint keeps the running certificate",
			err);
	free_pems(cert, key);
	char *t = c->tls_cert; /* swapped: nc frees the old ones */
	c->tls_cert = nc->tls_cert;
	nc->tls_cert = t;
	t = c->tls_key;
	c->tls_key = nc->tls_key;
	nc->tls_key = t;
	log_msg(LOG_INFO, "reload: TLS certificate %s loaded for new connections", c->tls_cert);
}

/* Re-reads clipmapd.conf and applies the keys that can change while running: [log] level,
 * [engine] planets and strict_planets, [listen] max_sessions, max_preauth, max_preauth_per_peer,
 * handshake_timeout, frame_timeout, [session] max_want, max_rate, max_pending_kb,
 * send_queue_ms, bbr, raw_above_mbit, lossy_below_mbit, webp_quality, max_frame_kb, max_jobs, [tls] cert and key (read
 * again even when unchanged: a renewed certificate). The others keep their running
 * values (a warning names each one that changed). A file that does not load changes nothing. */
static void reload_conf(struct daemon *d)
{
	struct conf nc;
	char err[256];
	if (conf_load(d->conf.path, &nc, err)) {
		log_msg(LOG_ERROR, "reload: %s; keeping the running configuration", err);
		return;
	}
	struct conf *c = &d->conf;
	warn_restart_keys(c, &nc);
	char *dir = c->planets_dir; /* swapped: nc frees the old one */
	c->planets_dir = nc.planets_dir;
	nc.planets_dir = dir;
	c->strict_planets = nc.strict_planets;
	c->log_level = nc.log_level;
	c->max_sessions = nc.max_sessions;
	c->max_preauth = nc.max_preauth;
	c->max_preauth_per_peer = nc.max_preauth_per_peer;
	c->handshake_timeout = nc.handshake_timeout;
	c->frame_timeout = nc.frame_timeout;
	c->max_want = nc.max_want;
	c->max_rate = nc.max_rate;
	c->max_pending = nc.max_pending;
	c->send_queue_ms = nc.send_queue_ms;
	c->bbr = nc.bbr;
	c->raw_above_mbit = nc.raw_above_mbit;
	c->lossy_below_mbit = nc.lossy_below_mbit;
	c->webp_quality = nc.webp_quality;
	c->max_frame = nc.max_frame;
	c->max_jobs = nc.max_jobs;
	if (c->tls_cert && nc.tls_cert)
		reload_tls(d, c, &nc);
	conf_fini(&nc);
	log_set_level(c->log_level);
	server_conf_changed(d->srv);
	log_msg(LOG_INFO, "reload: %s re-read", c->path);
}

static void reload(struct daemon *d)
{
	sd_notify(0, "RELOADING=1\nSTATUS=reloading");
	reload_conf(d);
	char err[256];
	struct planet_set *ps = NULL;
	/* the same image cache: unchanged files stay cached */
	int rc = load_planets(d, server_planets(d->srv)->images, &ps, err);
	if (rc) {
		log_msg(LOG_ERROR, "reload failed, keeping the loaded planets: %s", err);
	} else {
		size_t nodes = 0, kept = 0;
		const struct planet_set *old = server_planets(d->srv);
		for (size_t i = 0; i < ps->n; i++)
			for (size_t j = 0; j < ps->planets[i]->nnodes; j++) {
				nodes++;
				kept += planet_set_has_node(old, ps->planets[i]->nodes[j]->hash);
			}
		server_set_planets(d->srv, ps);
		if (d->http)
			http_set_planets(d->http, ps);
		log_msg(LOG_INFO, "reloaded %zu planets from %s: %zu of %zu nodes unchanged%s", ps->n,
			d->conf.planets_dir, kept, nodes, ps->nskipped ? " (some files skipped)" : "");
	}
	sd_notify(0, "READY=1\nSTATUS=serving");
}

static void on_signal(void *ud)
{
	struct daemon *d = ud;
	struct signalfd_siginfo si;
	while (read(d->sigfd, &si, sizeof si) == (ssize_t)sizeof si) {
		if (si.ssi_signo == SIGHUP) {
			log_msg(LOG_INFO, "SIGHUP: reloading the configuration and the planets");
			reload(d);
		} else {
			log_msg(LOG_INFO, "%s: stopping", strsignal((int)si.ssi_signo));
			sd_notify(0, "STOPPING=1\nSTATUS=stopping");
			server_stop(d->srv);
		}
	}
}

/* Says what went wrong in the store (the engine only counts): damaged entries once per tick
 * in which some were found; a damaged file replaced; failing writes (disk full, I/O) once when they start and once
 * when a batch commits again; a full write queue the first time; prefetched tiles evicted to
 * stay within the budget once when it starts and once, with the count, when none were for
 * STORE_QUIET_NS (a job's batches come in bursts: one episode, not a line per burst). */
#define STORE_QUIET_NS 10000000000ull
static void store_watch(struct daemon *d)
{
	struct store_stats st, *old = &d->store_seen;
	store_stat(d->store, &st);
	if (st.corrupt > old->corrupt)
		log_msg(LOG_WARN, "store %s: %llu corrupt tiles dropped (regenerated, never served)",
			d->conf.store_path, (unsigned long long)(st.corrupt - old->corrupt));
	if (st.write_errors > old->write_errors && !d->store_failing) {
		log_msg(LOG_WARN, "store %s: writes fail (disk full or I/O error?): serving from "
			"memory and generation, tiles left unstored", d->conf.store_path);
		d->store_failing = true;
	} else if (d->store_failing && st.puts > old->puts && st.last_write > 0) {
		/* a batch committed since the last tick and the last one did: a tick that saw a
		 * failing batch and then good ones (queued before and after the disk had room) is
		 * the recovery, not more failure */
		log_msg(LOG_INFO, "store %s: writes succeed again", d->conf.store_path);
		d->store_failing = false;
	}
	if (st.recovered > old->recovered)
		log_msg(LOG_WARN, "store %s: the file was damaged (LMDB could not read it): moved "
			"aside as %s.corrupt-TIME and started empty; its tiles will be generated "
			"again", d->conf.store_path, d->conf.store_path);
	uint64_t now = clock_now_ns();
	if (st.evictions_prefetched > old->evictions_prefetched) {
		if (!d->store_pf_evicting) {
			log_msg(LOG_WARN, "store %s: full ([store] disk_mb = %llu): evicting "
				"prefetched tiles to make room; what was prefetched is no longer "
				"all on disk", d->conf.store_path,
				(unsigned long long)(st.budget >> 20));
			d->store_pf_evicting = true;
			d->store_pf_from = old->evictions_prefetched;
		}
		d->store_pf_last_ns = now;
	} else if (d->store_pf_evicting && now - d->store_pf_last_ns > STORE_QUIET_NS) {
		log_msg(LOG_INFO, "store %s: %llu prefetched tiles evicted (store.disk."
			"evictions_prefetched)", d->conf.store_path,
			(unsigned long long)(st.evictions_prefetched - d->store_pf_from));
		d->store_pf_evicting = false;
	}
	if (st.write_drops > 0 && old->write_drops == 0)
		log_msg(LOG_WARN, "store %s: write queue full, tiles left unstored (counted as "
			"store.disk.write_drops)", d->conf.store_path);
	*old = st;
}

/* The STATS figures plus the HTTP endpoint's own, as /metrics text: gathered on the loop
 * thread (where the figures live) once a second. */
static void gather_metrics(struct daemon *d)
{
	uint64_t now = clock_now_ns();
	if (now - d->metrics_ns < 1000000000ull)
		return;
	d->metrics_ns = now;
	enum { CAP = PROTO_MAX_STATS };
	struct proto_stat *it = calloc(CAP, sizeof *it);
	char(*keys)[128] = calloc(CAP, sizeof *keys);
	if (!it || !keys) {
		free(it);
		free(keys);
		return;
	}
	size_t n = server_stats(d->srv, it, keys, CAP - 11);
	struct http_stats hs;
	http_get_stats(d->http, &hs);
	const struct { const char *k; uint64_t v; } h[] = {
		{ "http.requests", hs.requests },	{ "http.tiles.sent", hs.tiles },
		{ "http.not_modified.sent", hs.not_modified }, { "http.client_errors.sent", hs.client_errors },
		{ "http.server_errors.sent", hs.server_errors }, { "http.auth_failures", hs.auth_failures },
		{ "http.bytes.sent", hs.bytes },
		{ "http.cache.hits", hs.cache_hits }, { "http.cache.misses", hs.cache_misses },
		{ "http.cache.bytes", hs.cache_bytes }, { "http.cancelled", hs.cancelled },
	};
	for (size_t i = 0; i < sizeof h / sizeof h[0]; i++, n++)
		it[n] = (struct proto_stat){ .key = h[i].k, .kind = PROTO_STAT_U64, .u = h[i].v };
	size_t len;
	char *text = metrics_format(it, n, CLIPMAP_VERSION, server_planets(d->srv), &len);
	http_set_metrics(d->http, text, len);
	free(text);
	free(it);
	free(keys);
}

static void on_tick(void *ud)
{
	struct daemon *d = ud;
	if (d->http)
		gather_metrics(d);
	if (d->store)
		store_watch(d);
	if (!d->watchdog_usec)
		return;
	uint64_t now = clock_now_ns();
	if (now - d->last_watchdog_ns >= d->watchdog_usec * 1000 / 2) {
		sd_notify(0, "WATCHDOG=1");
		d->last_watchdog_ns = now;
	}
}

static int check_token(const struct conf *c, char err[256])
{
	if (!c->token_file)
		return 0;
	int fd = open(c->token_file, O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		err_set(err, "%s: token_file %s: %s", c->path, c->token_file, strerror(errno));
		return -EINVAL;
	}
	char b[8];
	ssize_t n = read(fd, b, sizeof b);
	close(fd);
	if (n <= 0 || (n == 1 && b[0] == '\n')) {
		err_set(err, "%s: token_file %s is empty or unreadable", c->path, c->token_file);
		return -EINVAL;
	}
	return 0;
}

/* [tls] cert and key load and match (the server loads them again when it starts). A
 * certificate out of its dates is a warning. Returns 0 or -errno with err filled. */
static int check_tls(const struct conf *c, char err[256])
{
	if (!c->tls_cert)
		return 0;
	struct tls_server *t;
	char e2[256], warn[256];
	int rc = tls_server_create(c->tls_cert, c->tls_key, NULL, &t, e2, warn);
	if (rc) {
		err_set(err, "%s: %s", c->path, e2);
		return rc;
	}
	tls_server_destroy(t);
	if (warn[0])
		log_msg(LOG_WARN, "%s", warn);
	return 0;
}

/* The command line into *cfg and *check. Returns -1 to go on, else the exit status (0:
 * --help, --version). */
static int parse_args(int argc, char **argv, const char **cfg, bool *check)
{
	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "-c") || !strcmp(argv[i], "--config")) {
			if (i + 1 >= argc || !argv[i + 1][0]) {
				fprintf(stderr, "clipmapd: %s: expected a FILE\n", argv[i]);
				return 2;
			}
			*cfg = argv[++i];
		} else if (!strncmp(argv[i], "--config=", 9)) {
			*cfg = argv[i] + 9;
			if (!**cfg) {
				fprintf(stderr, "clipmapd: --config: expected a FILE\n");
				return 2;
			}
		} else if (!strcmp(argv[i], "--check-config")) {
			*check = true;
		} else if (!strcmp(argv[i], "-h") || !strcmp(argv[i], "--help")) {
			usage(stdout);
			return 0;
		} else if (!strcmp(argv[i], "-V") || !strcmp(argv[i], "--version")) {
			printf("clipmapd %s\n", CLIPMAP_VERSION);
			return 0;
		} else {
			fprintf(stderr, "clipmapd: unknown argument \"%s\"\n", argv[i]);
			usage(stderr);
			return 2;
		}
	}
	return -1;
}

/* The configuration cfg into d->conf and the planet files it names into *ps (returned
 * owned), the token file checked. Returns 0, or 2 after saying what is wrong (nothing left
 * to free). */
static int configure(struct daemon *d, const char *cfg, struct planet_set **ps)
{
	char err[256];
	if (conf_load(cfg, &d->conf, err)) {
		fprintf(stderr, "clipmapd: %s\n", err);
		return 2;
	}
	log_set_level(d->conf.log_level);
	*ps = NULL;
	struct img_cache *images = img_cache_create(d->conf.image_cache_mb); /* the set holds it */
	int rc = load_planets(d, images, ps, err);
	img_cache_unref(images);
	if (rc || check_token(&d->conf, err) || check_tls(&d->conf, err)) {
		fprintf(stderr, "clipmapd: %s\n", err);
		planet_set_unref(*ps);
		*ps = NULL;
		conf_fini(&d->conf);
		return 2;
	}
	return 0;
}

/* SIGTERM, SIGINT and SIGHUP blocked (in this thread and the ones it starts) and readable
 * from d->sigfd; SIGPIPE ignored. Returns 0 or -errno. */
static int take_signals(struct daemon *d)
{
	sigset_t mask;
	sigemptyset(&mask);
	sigaddset(&mask, SIGTERM);
	sigaddset(&mask, SIGINT);
	sigaddset(&mask, SIGHUP);
	signal(SIGPIPE, SIG_IGN);
	signal(SIGXFSZ, SIG_IGN); /* a store write past a file size limit fails (EFBIG), counted */
	int rc = pthread_sigmask(SIG_BLOCK, &mask, NULL);
	if (rc)
		return -rc;
	d->sigfd = signalfd(-1, &mask, SFD_NONBLOCK | SFD_CLOEXEC);
	return d->sigfd < 0 ? -errno : 0;
}

/* Tiles are 64 KiB to 1 MiB. By default glibc maps each one afresh (or trims its heaps back
 * to the system when the cache frees them), and the kernel zeroes every page on its first
 * touch: a quarter of the daemon's time in the keep-up bench went to those page faults and to
 * munmap. Tile pixels now live in the engine's pool (engine/tilemem.h), which keeps freed
 * buffers resident up to a quarter of the cache's budget beyond what the cache holds (its
 * prune frees a tenth at a time; with [engine] prefault, whatever the budget leaves free);
 * the heap keeps the rest (encoded tiles, want lists) in the
 * same way, bounded by the cache's budget too. */
static void keep_tiles_in_heap(size_t cache_bytes)
{
	size_t keep = cache_bytes < ((size_t)1 << 30) ? cache_bytes : (size_t)1 << 30;
	if (!mallopt(M_MMAP_THRESHOLD, 32 << 20) || !mallopt(M_TRIM_THRESHOLD, (int)keep))
		log_msg(LOG_WARN, "mallopt failed: tiles will be mapped afresh");
	tilemem_keep(cache_bytes / 4 + ((size_t)64 << 20));
}

/* The tile pool faulted in up to the cache's budget, at idle priority: the tiles a
 * restarted daemon loads from its store, or makes, in its first seconds then land in memory
 * the VM already backs instead of faulting it in on the workers (tilemem_prefault). One class:
 * the largest planets' four-byte tiles (heights, colour). */
static void *prefault_main(void *arg)
{
	struct prefault *pf = arg;
	pthread_setname_np(pthread_self(), "prefault"); /* for top -H, perf */
	struct sched_param sp = { 0 };
	(void)pthread_setschedparam(pthread_self(), SCHED_IDLE, &sp); /* else it competes at 0 */
	uint64_t t0 = clock_now_ns();
	size_t done = tilemem_prefault(pf->tile_bytes, pf->bytes, &pf->stop);
	log_msg(LOG_DEBUG, "tile pool: %zu MiB faulted in in %.2f s", done >> 20,
		(double)(clock_now_ns() - t0) / 1e9);
	return NULL;
}

static void start_prefault(struct daemon *d, const struct planet_set *ps)
{
	uint32_t T = 0;
	for (size_t i = 0; i < ps->n; i++)
		if (ps->planets[i]->tile_size > T)
			T = ps->planets[i]->tile_size;
	if (!d->conf.prefault || T == 0)
		return;
	d->pf.tile_bytes = (size_t)T * T * 4;
	d->pf.bytes = d->conf.cache_bytes;
	atomic_store(&d->pf.stop, false);
	tilemem_prefault_expect(d->pf.bytes); /* STATS count it before the thread runs */
	d->pf.started = xthread_create(&d->pf.th, prefault_main, &d->pf) == 0;
	if (!d->pf.started)
		tilemem_prefault_expect(0);
}

static void stop_prefault(struct daemon *d)
{
	if (!d->pf.started)
		return;
	atomic_store(&d->pf.stop, true); /* it stops within 2 MiB */
	xthread_join(d->pf.th);
	d->pf.started = false;
}

static void log_ready(const struct daemon *d, struct sched *sched)
{
	const struct listener *ls;
	size_t nls = server_listeners(d->srv, &ls);
	for (size_t i = 0; i < nls; i++) {
		log_msg(LOG_INFO, "listening on %s%s%s%s", ls[i].name, ls[i].tls ? " (TLS)" : "",
			ls[i].need_token ? " (token required)" : "",
			ls[i].compress ? " (compressed tiles)" : "");
		if (!ls[i].is_unix && !ls[i].loopback && !ls[i].tls)
			log_msg(LOG_WARN, "%s is not loopback and has no TLS: %s tiles travel in "
				"clear (set [tls] cert and key)", ls[i].name,
				ls[i].need_token ? "the token and the" : "the");
	}
	struct sched_stats ss;
	sched_get_stats(sched, &ss);
	const struct planet_set *ps = server_planets(d->srv);
	char names[512] = "";
	for (size_t i = 0, l = 0; i < ps->n && l < sizeof names; i++, l = strlen(names))
		snprintf(names + l, sizeof names - l, "%s%s", i ? ", " : "", ps->planets[i]->name);
	log_msg(LOG_INFO, "clipmapd ready: %zu planets (%s)%s, %d workers, cache %zu MiB, version %s",
		ps->n, names, ps->nskipped ? ", some skipped" : "", ss.workers,
		d->conf.cache_bytes >> 20, CLIPMAP_VERSION);
}

/* Where CesiumJS is for the browser page: [http] cesium, else the build tree's copy beside
 * the program (build/npm/..., from make deps), else the installed copy (make install puts
 * it in BINDIR/../share/clipmap/cesium). NULL (no page) when none has Cesium.js. */
static bool has_cesium(const char *dir)
{
	char js[600];
	snprintf(js, sizeof js, "%.500s/Cesium.js", dir);
	return access(js, R_OK) == 0;
}

static char *find_cesium(const struct conf *c, char *buf, size_t n)
{
	if (c->http_cesium) {
		snprintf(buf, n, "%s", c->http_cesium);
		if (has_cesium(buf))
			return buf;
		log_msg(LOG_WARN, "http: no Cesium.js in %s: the browser page is off", buf);
		return NULL;
	}
	char exe[512];
	ssize_t k = readlink("/proc/self/exe", exe, sizeof exe - 1);
	if (k <= 0)
		return NULL;
	exe[k] = '\0';
	char *slash = strrchr(exe, '/');
	if (slash)
		*slash = '\0';
	/* build/npm beside the program, or the build tree's for the sanitizer builds
	 * (build-asan/clipmapd finds build/npm) */
	static const char *const rel[] = { "npm", "../build/npm" };
	for (size_t i = 0; i < sizeof rel / sizeof rel[0]; i++) {
		snprintf(buf, n, "%.400s/%s/node_modules/cesium/Build/Cesium", exe, rel[i]);
		if (has_cesium(buf))
			return buf;
	}
	snprintf(buf, n, "%.400s/../share/clipmap/cesium", exe);
	return has_cesium(buf) ? buf : NULL;
}

/* The HTTP endpoint of [http], with the token where the listener is not loopback (or
 * require_token asks for it everywhere) unless `open`. */
static int start_http(struct daemon *d, struct sched *sched, struct cache *cache,
		      struct planet_set *ps)
{
	const struct conf *c = &d->conf;
	size_t tlen;
	const uint8_t *tok = server_token(d->srv, &tlen);
	bool need = tok && !c->http_open &&
		    (!conf_addr_is_loopback(c->http_listen) || c->require_token != CONF_TOKEN_AUTO);
	char err[256], cesium[512], *cert = NULL, *key = NULL;
	const char *cdir = find_cesium(c, cesium, sizeof cesium);
	int rc = 0;
	if (c->tls_cert && (rc = read_pems(c, &cert, &key, err))) {
		log_msg(LOG_ERROR, "http: %s", err);
		return rc;
	}
	rc = http_create(&(struct http_desc){ .listen = c->http_listen, .sched = sched,
						  .cache = cache, .planets = ps,
						  .token = need ? tok : NULL, .token_len = need ? tlen : 0,
						  .threads = c->http_threads,
						  .max_conns = c->http_max_conns,
						  .max_per_addr = c->http_max_per_addr,
						  .timeout_s = c->http_timeout_s,
						  .max_age_s = c->http_max_age_s,
						  .cache_bytes = (size_t)c->http_cache_mb << 20,
						  .cesium_dir = cdir, .tls_cert = cert,
						  .tls_key = key },
			     &d->http, err);
	free_pems(cert, key);
	if (rc) {
		log_msg(LOG_ERROR, "%s", err);
		return rc;
	}
	char host[256], port[16];
	conf_split_hostport(c->http_listen, host, sizeof host, port, sizeof port);
	log_msg(LOG_INFO, "http: listening on http%s://%s%s%s:%u/%s%s", c->tls_cert ? "s" : "",
		strchr(host, ':') ? "[" : "", host, strchr(host, ':') ? "]" : "", http_port(d->http),
		need ? " (bearer token required)" : "", cdir ? " (browser viewer)" : "");
	return 0;
}

/* The cache, the workers and the server over the planets ps (taken), run until a signal
 * stops them. Returns the exit status. */
static int serve(struct daemon *d, struct planet_set *ps)
{
	char err[256];
	/* Threads start after the mask is set, so they inherit it and signals reach the fd. */
	int rc;
	if (d->conf.store_path) {
		err[0] = '\0';
		bool lz4 = d->conf.disk_codec == CONF_DISK_LZ4;
		rc = store_lmdb_open(&(struct store_lmdb_desc){ .path = d->conf.store_path,
								.budget = d->conf.store_bytes,
								.codec = lz4 ? TCODEC_LZ4
									     : TCODEC_ZSTD },
				     &d->store, err);
		if (rc) {
			log_msg(LOG_ERROR, "store: %s", err);
			planet_set_unref(ps);
			return 1;
		}
		if (err[0])
			log_msg(LOG_WARN, "store: %s", err);
		store_stat(d->store, &d->store_seen);
		log_msg(LOG_INFO, "store %s: %llu tiles, %llu of %llu MiB; writes %s",
			d->conf.store_path, (unsigned long long)d->store_seen.tiles,
			(unsigned long long)(d->store_seen.bytes >> 20),
			(unsigned long long)(d->store_seen.budget >> 20), lz4 ? "lz4" : "zstd");
	}
	if (d->conf.store_redis &&
	    (rc = store_redis_open(&(struct store_redis_desc){
					   .addr = d->conf.store_redis,
					   .password = d->conf.store_redis_password,
					   .lease_ms = d->conf.store_redis_lease_ms },
				   &d->remote, err))) {
		log_msg(LOG_ERROR, "store: %s", err);
		planet_set_unref(ps);
		store_destroy(d->store);
		return 2;
	}
	start_prefault(d, ps);
	struct cache *cache = cache_create(d->conf.cache_bytes);
	struct sched *sched = sched_create(&(struct sched_desc){
		.cache = cache, .store = d->store, .remote = d->remote, .workers = d->conf.workers,
		.worker_nice = d->conf.worker_nice });
	rc = server_create(&d->conf, sched, cache, ps, &d->srv, err);
	if (rc) {
		log_msg(LOG_ERROR, "%s", err);
		stop_prefault(d);
		planet_set_unref(ps);
		sched_destroy(sched);
		cache_destroy(cache);
		store_redis_destroy(d->remote);
		store_destroy(d->store);
		return rc == -EINVAL ? 2 : 1;
	}
	bool ran = false;
	if (d->conf.http_listen && (rc = start_http(d, sched, cache, ps)))
		goto out;
	if ((rc = server_watch_fd(d->srv, d->sigfd, on_signal, d))) {
		log_msg(LOG_ERROR, "signalfd: %s", strerror(-rc));
		goto out;
	}
	if (sd_watchdog_enabled(0, &d->watchdog_usec) <= 0)
		d->watchdog_usec = 0;
	server_set_tick(d->srv, on_tick, d);
	log_ready(d, sched);
	sd_notify(0, "READY=1\nSTATUS=serving");
	rc = server_run(d->srv);
	ran = true;
	sd_notify(0, "STOPPING=1");
out:
	/* Exiting: the pool keeps what is freed from here on. Giving each buffer's pages back
	 * (one madvise and TLB shootdown a buffer) made a full cache's exit take 0.6-0.8 s more
	 * (14 000-24 000 tiles); the process's exit returns them all at once. */
	tilemem_keep(SIZE_MAX);
	stop_prefault(d);
	http_destroy(d->http); /* before the scheduler its requests use */
	d->http = NULL;
	server_destroy(d->srv);
	sched_destroy(sched);
	cache_destroy(cache);
	store_redis_destroy(d->remote); /* after the scheduler: writes what is queued */
	store_destroy(d->store); /* commits the writes still queued */
	if (ran)
		log_msg(LOG_INFO, "clipmapd stopped");
	return rc ? 1 : 0;
}

/* The engine's faults (a file read failing at run time): warnings in the log. */
static void log_fault(const char *line)
{
	log_msg(LOG_WARN, "%s", line);
}

int main(int argc, char **argv)
{
	const char *cfg = DEFAULT_CONF;
	bool check = false;
	int status = parse_args(argc, argv, &cfg, &check);
	if (status >= 0)
		return status;
	struct daemon d = { .sigfd = -1 };
	struct planet_set *ps;
	log_detect_journal();
	engine_fault_sink(log_fault);
	if ((status = configure(&d, cfg, &ps)))
		return status;
	if (check) {
		printf("%s: OK (%zu planets in %s", cfg, ps->n, d.conf.planets_dir);
		if (ps->nskipped)
			printf("; %zu planet file%s skipped, see above", ps->nskipped,
			       ps->nskipped == 1 ? "" : "s");
		printf(")\n");
		planet_set_unref(ps);
		conf_fini(&d.conf);
		return 0;
	}
	int rc = take_signals(&d);
	if (rc) {
		fprintf(stderr, "clipmapd: signalfd: %s\n", strerror(-rc));
		planet_set_unref(ps);
		conf_fini(&d.conf);
		return 1;
	}
	keep_tiles_in_heap(d.conf.cache_bytes);
	status = serve(&d, ps);
	close(d.sigfd);
	conf_fini(&d.conf);
	return status;
}
