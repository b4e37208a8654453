/* clipmapctl — the operator's command line. This file is only argument handling and output;
 * the work lives in render.c (offline evaluation), ctl_*.c (online commands, through net.c)
 * and the library. Exit codes: 0 ok, 1 runtime failure, 2 bad usage or config, 130 when a
 * prefetch was interrupted.
 *
 * Built twice: clipmapctl-offline is everything; clipmapctl (CTL_THIN) is the commands that
 * need neither the engine nor OpenImageIO (which alone loads some 260 shared libraries):
 * `status`, `cache`, `prefetch`, `help` start in milliseconds. It runs the others (`tile`,
 * which writes pictures, and the offline ones) by executing clipmapctl-offline from its own
 * directory, the global options passed on. */
#include <errno.h>
#include <getopt.h>
#include <signal.h>
#include <stdbool.h>
#include <sys/signalfd.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/args.h"
#include "common/clock.h"
#include "common/errbuf.h"
#ifndef CTL_THIN
#include "engine/planet.h"
#endif
#include "coverage.h"
#include "ctl_args.h"
#include "ctl_cache.h"
#include "ctl_conn.h"
#include "ctl_prefetch.h"
#include "ctl_status.h"
#include "ctl_tile.h"
#include "client/planet_path.h"
#ifndef CTL_THIN
#include "import_cli.h"
#include "render.h"
#endif

#define GLOBAL_USAGE                                                                         \
	"usage: clipmapctl [-s SOCKET | -H HOST:PORT | --connect SOCKET|HOST:PORT]\n"           \
	"                  [--token-file FILE] [--tls-ca FILE | --tls] [--timeout SEC]\n"        \
	"                  COMMAND ...\n"

/* Each command's lines of the usage, in the order the full usage lists them. */
static const struct cmd_usage {
	const char *name, *text;
} cmd_usages[] = {
	{ "status", "  clipmapctl status [--json]                         uptime, planets served, "
		    "queues, cache\n" },
	{ "tile", "  clipmapctl tile PLANET LAYER LX LY X Y -o FILE     one tile through the "
		  "daemon\n" },
	{ "cache", "  clipmapctl cache ls PLANET [--near LAT,LON [--radius KM]] [--level L]\n"
		   "                          [--limit N] [--json]       what is cached\n"
		   "  clipmapctl cache stat [PLANET] [--json]          tiles and bytes per planet,\n"
		   "                                                     layer, level and tier\n"
		   "  clipmapctl cache purge PLANET [--bbox W,S,E,N | --coverage FILE] [--levels A-B]\n"
		   "                          [--json]\n"
		   "                                                     drop its tiles from disk\n"
		   "  clipmapctl cache gc [--json]                     drop disk entries no planet uses\n"
		   "  clipmapctl cache verify [PLANET] [--json]        check every stored checksum\n" },
	{ "prefetch",
	  "  clipmapctl prefetch PLANET --bbox W,S,E,N --levels A-B [--layers a,b]\n"
	  "  clipmapctl prefetch PLANET --path LAT,LON:LAT,LON --width KM --levels A-B\n"
	  "                          [--layers a,b]             fill the cache (Ctrl-C cancels)\n"
	  "  clipmapctl prefetch PLANET --coverage FILE --levels A-B [--layers a,b]\n"
	  "      --coverage: the polygons of a GeoJSON, GeoPackage, Shapefile… (any CRS)\n"
	  "      --dry-run [--json]: the estimate per level and the tier's budget, nothing run\n"
	  "      --bbox: W < E; across the antimeridian write E + 360 (170,-10,190,10)\n" },
	{ "render",
	  "  clipmapctl render PLANET LAYER LX LY X Y -o FILE   one tile\n"
	  "  clipmapctl render PLANET LAYER --level L --world -o FILE\n"
	  "                                                     a whole level (lx = L+1, ly = L)\n"
	  "  clipmapctl render PLANET LAYER --level L --at LAT,LON [--tiles N] -o FILE\n"
	  "                                                     N×N tiles around a place (N = 3),\n"
	  "                                                     texels about square there\n"
	  "      options: --workers N  --cache-mb N  --shade (colour × hillshade)  --quiet\n"
	  "               --store PATH [--store-mb N]  read and fill an LMDB tile store (the\n"
	  "               one a running clipmapd uses too)\n"
	  "      heights: .tif/.tiff/.exr (float metres) or .png (16-bit, scale printed);\n"
	  "      colour and normals: .png\n" },
	{ "graph", "  clipmapctl graph PLANET                            the node graph as "
		   "Graphviz dot\n" },
	{ "layers", "  clipmapctl layers PLANET                           layers, nodes and "
		    "hashes\n" },
	{ "import", "  clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N]\n"
		    "                     any GDAL raster -> tiled, mipmapped TIFF with its bounds\n" },
};
#define ONLINE_CMDS 4 /* the first four go through clipmapd */

static const struct cmd_usage *find_usage(const char *cmd)
{
	for (size_t i = 0; i < sizeof cmd_usages / sizeof cmd_usages[0]; i++)
		if (cmd && strcmp(cmd_usages[i].name, cmd) == 0)
			return &cmd_usages[i];
	return NULL;
}

/* The full usage. */
static void usage(FILE *f)
{
	fputs(GLOBAL_USAGE
	      "online (through clipmapd; socket default $CLIPMAP_SOCKET or " CTL_DEFAULT_SOCKET ",\n"
	      "token default $CLIPMAP_TOKEN; over TCP, TLS with --tls-ca FILE or\n"
	      "$CLIPMAP_TLS_CA, or --tls for the system's trust store):\n",
	      f);
	for (size_t i = 0; i < sizeof cmd_usages / sizeof cmd_usages[0]; i++) {
		if (i == ONLINE_CMDS)
			fputs("offline (evaluates the planet file here):\n", f);
		fputs(cmd_usages[i].text, f);
	}
	fputs("PLANET is a planet file or a name in $CLIPMAP_PLANETS, conf/planets/ or\n"
	      "/etc/clipmap/planets/.\n"
	      "  -V, --version  the version;  clipmapctl COMMAND --help: one command's usage\n"
	      "exit status: 0 ok, 1 failure, 2 bad usage, 130 prefetch interrupted\n",
	      f);
}

/* The command being run (set once by run_command), for its own usage. */
static const char *current_cmd;

/* The usage of the current command (the full usage when there is none). */
static void cmd_usage(FILE *f)
{
	const struct cmd_usage *u = find_usage(current_cmd);
	if (!u) {
		usage(f);
		return;
	}
	fputs(GLOBAL_USAGE, f);
	fputs(u->text, f);
	if (u - cmd_usages < ONLINE_CMDS)
		fputs("  (global options may also follow the command; socket default "
		      "$CLIPMAP_SOCKET or " CTL_DEFAULT_SOCKET ")\n", f);
}

#ifndef CTL_THIN
static int load(const char *arg, struct planet **p)
{
	char path[4096], err[256];
	if (planet_path_resolve(arg, path, sizeof path)) {
		fprintf(stderr, "clipmapctl: planet \"%s\" not found (tried %s)\n", arg, path);
		return 2;
	}
	if (planet_load(path, p, err)) {
		fprintf(stderr, "clipmapctl: %s\n", err);
		return 2;
	}
	return 0;
}
#endif

#ifndef CTL_THIN
static int parse_u32(const char *s, const char *what, long max, uint32_t *out)
{
	char *end;
	errno = 0;
	long v = strtol(s, &end, 10);
	if (end == s || *end || errno || v < 0 || v > max) {
		fprintf(stderr, "clipmapctl: %s must be an integer in [0, %ld], got \"%s\"\n", what,
			max, s);
		return -1;
	}
	*out = (uint32_t)v;
	return 0;
}
#endif

/* ---- options -------------------------------------------------------------------------- */

/* Long-only global options (outside the range of the short ones). */
enum { OPT_TLS_CA = 1000, OPT_TLS };

/* Options every online command takes (also before the command). Returns 1 if c was one. */
static int global_opt(int c, struct ctl_target *t)
{
	switch (c) {
	case 'S': t->socket_path = optarg; return 1;
	case 'H': t->hostport = optarg; return 1;
	case 'C': /* clipmapview's spelling: HOST:PORT when it has a colon and no slash */
		if (strchr(optarg, ':') && !strchr(optarg, '/'))
			t->hostport = optarg;
		else
			t->socket_path = optarg;
		return 1;
	case 'T': t->token_file = optarg; return 1;
	case OPT_TLS_CA: t->tls_ca = optarg; return 1;
	case OPT_TLS: t->tls = true; return 1;
	case 'W': {
		uint64_t v;
		char err[256];
		if (ctl_parse_uint(optarg, "--timeout", 86400, &v, err) || v == 0) {
			fprintf(stderr, "clipmapctl: --timeout wants seconds in [1, 86400], got \"%s\"\n",
				optarg);
			return -1;
		}
		t->timeout_ms = (int)(v * 1000);
		return 1;
	}
	default: return 0;
	}
}

#define GLOBAL_OPTS                                                                          \
	{ "socket", required_argument, NULL, 'S' }, { "host", required_argument, NULL, 'H' },   \
	{ "connect", required_argument, NULL, 'C' },                                             \
	{ "token-file", required_argument, NULL, 'T' },                                          \
	{ "tls-ca", required_argument, NULL, OPT_TLS_CA }, { "tls", no_argument, NULL, OPT_TLS },  \
	{ "timeout", required_argument, NULL, 'W' }, { "help", no_argument, NULL, 'h' },        \
	{ "version", no_argument, NULL, 'V' }

/* The next option for a command to handle (getopt_long over shorts and longs), after the
 * ones every command shares: with t (an online command) the global options go into t (-s is
 * --socket); --help prints the usage. Returns the option ('?' for an unknown one), -1 at the
 * end, or OPT_EXIT with *status the exit status (0 after --help, 2 after a bad global
 * option). */
#define OPT_EXIT (-2)
static int next_opt(int argc, char **argv, const char *shorts, const struct option *longs,
		    struct ctl_target *t, int *status)
{
	int c;
	while ((c = getopt_long(argc, argv, shorts, longs, NULL)) != -1) {
		int g = t ? global_opt(c == 's' ? 'S' : c, t) : 0;
		if (g < 0) {
			*status = 2;
			return OPT_EXIT;
		}
		if (g)
			continue;
		if (c == 'h') {
			cmd_usage(stdout);
			*status = 0;
			return OPT_EXIT;
		}
		if (c == 'V') {
			printf("clipmapctl %s\n", CLIPMAP_VERSION);
			*status = 0;
			return OPT_EXIT;
		}
		return c;
	}
	return -1;
}

/* ---- offline commands ----------------------------------------------------------------- */

#ifdef CTL_THIN
/* Runs argv (a command and its arguments; argc of them) in clipmapctl-offline, found beside
 * this program, the global options in t given before it. Returns only on failure, with the
 * exit status. */
static int run_offline(int argc, char **argv, const struct ctl_target *t)
{
	char self[4096], path[4200];
	ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
	if (n <= 0) {
		fprintf(stderr, "clipmapctl: /proc/self/exe: %s\n", strerror(errno));
		return 1;
	}
	self[n] = 0;
	char *slash = strrchr(self, '/');
	*slash = 0;
	snprintf(path, sizeof path, "%s/clipmapctl-offline", self);
	char **av = calloc((size_t)argc + 14, sizeof *av), tmo[32];
	if (!av)
		return 1;
	int k = 0;
	av[k++] = path;
	if (t->socket_path)
		av[k++] = "--socket", av[k++] = (char *)t->socket_path;
	if (t->hostport)
		av[k++] = "--host", av[k++] = (char *)t->hostport;
	if (t->token_file)
		av[k++] = "--token-file", av[k++] = (char *)t->token_file;
	if (t->tls_ca)
		av[k++] = "--tls-ca", av[k++] = (char *)t->tls_ca;
	if (t->tls)
		av[k++] = "--tls";
	if (t->timeout_ms) {
		snprintf(tmo, sizeof tmo, "%d", t->timeout_ms / 1000);
		av[k++] = "--timeout", av[k++] = tmo;
	}
	for (int i = 0; i < argc; i++)
		av[k++] = argv[i];
	execv(path, av);
	free(av);
	fprintf(stderr, "clipmapctl %s: needs %s (installed with clipmapctl): %s\n", argv[0], path,
		strerror(errno));
	return 1;
}
#else

static void progress(void *ud, size_t done, size_t total)
{
	const double *t0 = ud;
	double el = clock_now_s() - *t0;
	fprintf(stderr, "\r  %zu/%zu tiles  %.1f tiles/s", done, total, el > 0 ? done / el : 0.0);
	if (done == total)
		fputc('\n', stderr);
}

/* `clipmapctl render`'s options. */
struct render_args {
	const char *outpath;
	long level; /* --level; -1: a tile given as LX LY X Y */
	bool world, at, quiet;
	double lat, lon; /* --at */
	uint32_t ntiles; /* --tiles */
	const char *store;  /* --store PATH: an LMDB tile store, shared with clipmapd if it runs */
	uint32_t store_mb;  /* --store-mb: its budget (0: 1024, as clipmapd's disk_mb) */
	struct render_opts ro;
};

static bool parse_at(const char *s, struct render_args *ra)
{
	char err[256];
	if (args_latlon("--at", s, &ra->lat, &ra->lon, err)) {
		fprintf(stderr, "clipmapctl render: %s\n", err);
		return false;
	}
	ra->at = true;
	return true;
}

/* Takes render option c with its argument s into ra. Returns false on a bad one (after
 * saying so). */
static bool render_option(int c, const char *s, struct render_args *ra)
{
	uint32_t v;
	switch (c) {
	case 'o': ra->outpath = s; return true;
	case 'S': ra->store = s; return true;
	case 'B':
		if (parse_u32(s, "--store-mb", 1u << 26, &v))
			return false;
		ra->store_mb = v;
		return true;
	case 'l':
		if (parse_u32(s, "--level", GRID_MAX_LEVEL - 1, &v))
			return false;
		ra->level = v;
		return true;
	case 'w': ra->world = true; return true;
	case 'a': return parse_at(s, ra);
	case 't':
		if (parse_u32(s, "--tiles", 64, &v))
			return false;
		if (v == 0) {
			fprintf(stderr, "clipmapctl render: --tiles must be at least 1\n");
			return false;
		}
		ra->ntiles = v;
		return true;
	case 'j':
		if (parse_u32(s, "--workers", 256, &v))
			return false;
		ra->ro.workers = (int)v;
		return true;
	case 'c':
		if (parse_u32(s, "--cache-mb", 1 << 20, &v))
			return false;
		ra->ro.cache_mb = v;
		return true;
	case 's': ra->ro.shade = 1; return true;
	case 'q': ra->quiet = true; return true;
	default: cmd_usage(stderr); return false;
	}
}

/* What the positional arguments and the options ask to render. Returns 0 or 2 (after
 * saying why). */
static int render_region_of(const struct render_args *ra, int npos, char **pos,
			    struct render_region *rg)
{
	if (ra->level >= 0) {
		if (npos != 2) {
			fprintf(stderr, "clipmapctl render: with --level give PLANET LAYER only\n");
			return 2;
		}
		if (ra->world == ra->at) {
			fprintf(stderr, "clipmapctl render: --level needs --world (the whole level) or "
				"--at LAT,LON (tiles around a place)\n");
			return 2;
		}
		int ly = (int)ra->level;
		if (ra->world)
			render_region_level(ly + 1, ly, rg);
		else
			render_region_around(render_lx_at(ly, ra->lat), ly, ra->lat, ra->lon,
					     ra->ntiles, rg);
		return 0;
	}
	if (ra->world || ra->at) {
		fprintf(stderr, "clipmapctl render: --world and --at go with --level\n");
		return 2;
	}
	if (npos != 6) {
		cmd_usage(stderr);
		return 2;
	}
	uint32_t lx, ly, x, y;
	if (parse_u32(pos[2], "LX", GRID_MAX_LEVEL, &lx) ||
	    parse_u32(pos[3], "LY", GRID_MAX_LEVEL, &ly) ||
	    parse_u32(pos[4], "X", 0x7fffffff, &x) || parse_u32(pos[5], "Y", 0x7fffffff, &y))
		return 2;
	*rg = (struct render_region){ .lx = (int)lx, .ly = (int)ly, .x = x, .y = y, .cols = 1,
				      .rows = 1 };
	return 0;
}

/* Evaluates rg of layer on planet (a file or a name) and writes the picture. Returns the
 * exit status. */
static int render_to_file(const struct render_args *ra, const char *planet, const char *layer,
			  const struct render_region *rg)
{
	struct planet *p;
	int rc = load(planet, &p);
	if (rc)
		return rc;
	double t0 = clock_now_s();
	struct render_opts ro = ra->ro;
	if (!ra->quiet && ra->level >= 0 && isatty(STDERR_FILENO)) {
		ro.progress = progress;
		ro.ud = &t0;
	}
	struct render_image im;
	char err[256] = "", note[256];
	if (ra->store) {
		rc = store_open_file(ra->store, ra->store_mb, &ro.store, err);
		if (rc) {
			fprintf(stderr, "clipmapctl render: --store %s\n", err);
			planet_unref(p);
			return 1;
		}
		if (err[0])
			fprintf(stderr, "clipmapctl render: --store: %s\n", err);
	}
	rc = render_layer(p, layer, rg, &ro, &im, err);
	if (ro.store) {
		/* what is queued is written before the store closes */
		char line[256];
		store_summary(ro.store, line, sizeof line);
		if (!ra->quiet)
			fprintf(stderr, "store %s: %s\n", ra->store, line);
		store_destroy(ro.store);
	}
	if (rc) {
		fprintf(stderr, "clipmapctl render: %s\n", err);
		planet_unref(p);
		return rc == -EINVAL || rc == -ENOENT || rc == -E2BIG ? 2 : 1;
	}
	rc = render_write(&im, ra->outpath, note, err);
	if (rc) {
		fprintf(stderr, "clipmapctl render: %s\n", err);
	} else if (!ra->quiet) {
		printf("wrote %s (%dx%d: %u x %u tiles of level lx %d ly %d) in %.2f s\n",
		       ra->outpath, im.width, im.height, rg->cols, rg->rows, rg->lx, rg->ly,
		       clock_now_s() - t0);
		if (note[0])
			printf("%s\n", note);
	}
	render_image_free(&im);
	planet_unref(p);
	return rc ? 1 : 0;
}

static int cmd_render(int argc, char **argv)
{
	static const struct option opts[] = {
		{ "level", required_argument, NULL, 'l' },  { "world", no_argument, NULL, 'w' },
		{ "workers", required_argument, NULL, 'j' }, { "cache-mb", required_argument, NULL, 'c' },
		{ "shade", no_argument, NULL, 's' },	    { "quiet", no_argument, NULL, 'q' },
		{ "output", required_argument, NULL, 'o' }, { "help", no_argument, NULL, 'h' },
		{ "at", required_argument, NULL, 'a' },	    { "tiles", required_argument, NULL, 't' },
		{ "version", no_argument, NULL, 'V' },	    { "store", required_argument, NULL, 'S' },
		{ "store-mb", required_argument, NULL, 'B' }, { 0, 0, 0, 0 },
	};
	struct render_args ra = { .level = -1, .ntiles = 3 };
	int c, status;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "o:l:wj:c:sqh", opts, NULL, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		if (!render_option(c, optarg, &ra))
			return 2;
	}
	if (!ra.outpath) {
		fprintf(stderr, "clipmapctl render: -o FILE is required\n");
		return 2;
	}
	char **pos = argv + optind;
	struct render_region rg;
	if ((status = render_region_of(&ra, argc - optind, pos, &rg)))
		return status;
	return render_to_file(&ra, pos[0], pos[1], &rg);
}

/* `COMMAND PLANET` (and --help): the one planet argument, loaded. Returns 0 or the exit
 * status (after --help: 0 with *p NULL). */
static int load_only_arg(int argc, char **argv, struct planet **p)
{
	static const struct option opts[] = { { "help", no_argument, NULL, 'h' },
					      { "version", no_argument, NULL, 'V' },
					      { 0, 0, 0, 0 } };
	int c, status;
	*p = NULL;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "h", opts, NULL, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		cmd_usage(stderr);
		return 2;
	}
	if (argc - optind != 1) {
		fprintf(stderr, "clipmapctl %s: want one PLANET\n", argv[0]);
		cmd_usage(stderr);
		return 2;
	}
	return load(argv[optind], p);
}

static int cmd_graph(int argc, char **argv)
{
	struct planet *p;
	int rc = load_only_arg(argc, argv, &p);
	if (rc || !p)
		return rc;
	rc = planet_write_dot(p, stdout);
	planet_unref(p);
	if (rc || fflush(stdout)) {
		fprintf(stderr, "clipmapctl graph: writing: %s\n", strerror(rc ? -rc : errno));
		return 1;
	}
	return 0;
}

static int cmd_layers(int argc, char **argv)
{
	struct planet *p;
	int rc = load_only_arg(argc, argv, &p);
	if (rc || !p)
		return rc;
	printf("planet %s: a = %.1f m, f = %.9f, tile %u, max level %d\n", p->name, p->a, p->f,
	       p->tile_size, p->max_level);
	for (size_t i = 0; i < p->nlayers; i++)
		printf("layer %-10s %-6s node %-14s %016llx\n", p->layers[i].name,
		       pix_format_name(p->layers[i].type), p->layers[i].node->name,
		       (unsigned long long)p->layers[i].node->hash);
	for (size_t i = 0; i < p->nnodes; i++)
		printf("node  %-14s %-13s -> %-6s %016llx\n", p->nodes[i]->name,
		       p->nodes[i]->type->name, pix_type_name(p->nodes[i]->out),
		       (unsigned long long)p->nodes[i]->hash);
	planet_unref(p);
	return 0;
}

#endif /* CTL_THIN */

/* ---- online commands ------------------------------------------------------------------ */

/* The exit code for a failed online command: request errors the user can fix are usage. A
 * connection lost in the middle is said as such and not retried: behind a load balancer the
 * retry would reach another daemon (other figures, none of the jobs this one ran). */
static int fail(const char *cmd, int rc, const char *err)
{
	if (rc == -ECONNRESET || rc == -EPIPE)
		fprintf(stderr, "clipmapctl %s: lost the connection: %s \xe2\x80\x94 the daemon "
			"stopped or restarted during the command; not retried (run it again)\n",
			cmd, err);
	else
		fprintf(stderr, "clipmapctl %s: %s\n", cmd, err);
	return rc == -EINVAL || rc == -ENOENT ? 2 : 1;
}

static int connect_or_complain(const struct ctl_target *t, struct net_conn **c)
{
	char err[256];
	if (ctl_connect(t, c, err)) {
		fprintf(stderr, "clipmapctl: %s\n", err);
		return 1;
	}
	return 0;
}

static int timeout_of(const struct ctl_target *t)
{
	return t->timeout_ms ? t->timeout_ms : NET_DEFAULT_TIMEOUT_MS;
}

static int cmd_status(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = { GLOBAL_OPTS, { "json", no_argument, NULL, 'j' },
					      { 0, 0, 0, 0 } };
	bool json = false;
	int c, status;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "s:H:h", opts, t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		if (c != 'j') {
			cmd_usage(stderr);
			return 2;
		}
		json = true;
	}
	if (optind != argc) {
		fprintf(stderr, "clipmapctl status: unexpected argument \"%s\"\n", argv[optind]);
		return 2;
	}
	struct net_conn *conn;
	if (connect_or_complain(t, &conn))
		return 1;
	char err[256];
	int rc = ctl_status_run(conn, json, timeout_of(t), stdout, err);
	if (rc == 0 && !json) /* JSON: the stats' own keys only (planets, planets.skipped) */
		rc = ctl_status_planets(conn, timeout_of(t), stdout, err);
	net_close(conn);
	return rc ? fail("status", rc, err) : 0;
}

#ifndef CTL_THIN
static int cmd_tile(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = { GLOBAL_OPTS, { "output", required_argument, NULL, 'o' },
					      { "quiet", no_argument, NULL, 'q' }, { 0, 0, 0, 0 } };
	const char *outpath = NULL;
	bool quiet = false;
	int c, status;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "s:H:o:qh", opts, t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		if (c == 'o')
			outpath = optarg;
		else if (c == 'q')
			quiet = true;
		else {
			cmd_usage(stderr);
			return 2;
		}
	}
	char **pos = argv + optind;
	if (argc - optind != 6 || !outpath) {
		fprintf(stderr, "clipmapctl tile: want PLANET LAYER LX LY X Y -o FILE\n");
		return 2;
	}
	uint32_t lx, ly, x, y;
	if (parse_u32(pos[2], "LX", GRID_MAX_LEVEL, &lx) ||
	    parse_u32(pos[3], "LY", GRID_MAX_LEVEL, &ly) ||
	    parse_u32(pos[4], "X", 0x7fffffff, &x) || parse_u32(pos[5], "Y", 0x7fffffff, &y))
		return 2;
	struct net_conn *conn;
	if (connect_or_complain(t, &conn))
		return 1;
	struct ctl_tile_req r = { .planet = pos[0], .layer = pos[1], .lx = (uint8_t)lx,
				  .ly = (uint8_t)ly, .x = x, .y = y };
	struct render_image im;
	char err[256], note[256];
	/* generating a tile may take a while: at least a minute unless --timeout says */
	int rc = ctl_tile_fetch(conn, &r, t->timeout_ms ? t->timeout_ms : 60000, &im, err);
	net_close(conn);
	if (rc)
		return fail("tile", rc, err);
	rc = render_write(&im, outpath, note, err);
	render_image_free(&im);
	if (rc)
		return fail("tile", rc, err);
	if (!quiet) {
		printf("wrote %s (%dx%d)\n", outpath, im.width, im.height);
		if (note[0])
			printf("%s\n", note);
	}
	return 0;
}
#endif

/* Takes `cache ls` option c with its argument s into o. Returns 0, or the exit status after
 * saying what is wrong. */
static int cache_option(int c, const char *s, struct ctl_cache_opts *o)
{
	char err[256];
	uint64_t v;
	switch (c) {
	case 'n':
		if (ctl_parse_latlon(s, &o->lat, &o->lon, err))
			return fail("cache ls --near", -EINVAL, err);
		o->near = true;
		return 0;
	case 'r':
		if (ctl_parse_km(s, "--radius", 1e9, &o->radius_m, err))
			return fail("cache ls", -EINVAL, err);
		return 0;
	case 'l':
		if (ctl_parse_uint(s, "--level", GRID_MAX_LEVEL - 1, &v, err))
			return fail("cache ls", -EINVAL, err);
		o->level = (int)v;
		return 0;
	case 'm':
		if (ctl_parse_uint(s, "--limit", UINT32_MAX, &v, err))
			return fail("cache ls", -EINVAL, err);
		o->limit = (uint32_t)v;
		return 0;
	case 'j': o->json = true; return 0;
	default: cmd_usage(stderr); return 2;
	}
}

/* Reads a --coverage file into cv and points o at it. Returns -1 to go on, else the exit
 * status (after saying what is wrong). */
static int load_coverage(const char *what, const char *path, struct coverage *cv)
{
#ifdef CTL_THIN
	(void)path;
	*cv = (struct coverage){ 0 };
	fprintf(stderr, "clipmapctl %s: --coverage needs clipmapctl-offline\n", what);
	return 1;
#else
	char err[256];
	int rc = coverage_read(path, cv, err);
	if (rc) /* a file that cannot be used is bad input, as an unknown planet (exit 2) */
		return fail(what, rc == -E2BIG ? -EINVAL : rc, err);
	if (cv->skipped)
		fprintf(stderr, "clipmapctl %s: %s: %u features that are not polygons skipped\n",
			what, path, cv->skipped);
	return -1;
#endif
}

/* `cache stat|purge|gc|verify`. */
static int cmd_cache_op(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = {
		GLOBAL_OPTS,
		{ "bbox", required_argument, NULL, 'b' }, { "levels", required_argument, NULL, 'l' },
		{ "json", no_argument, NULL, 'j' },	  { "coverage", required_argument, NULL, 'c' },
		{ 0, 0, 0, 0 },
	};
	static const char *const names[] = { "stat", "purge", "gc", "verify" };
	struct ctl_cache_op_opts o = { 0 };
	const char *coverage = NULL;
	for (int i = 0; i < 4; i++)
		if (strcmp(argv[1], names[i]) == 0)
			o.op = (uint8_t)(PROTO_COP_STAT + i);
	char what[32];
	snprintf(what, sizeof what, "cache %.16s", argv[1]);
	if (!o.op) {
		fprintf(stderr, "clipmapctl cache: unknown subcommand \"%s\" (ls, stat, purge, gc, "
				"verify)\n", argv[1]);
		return 2;
	}
	argc--;
	argv++;
	int c, status;
	char err[256];
	optind = 0;
	while ((c = next_opt(argc, argv, "s:H:h", opts, t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		switch (c) {
		case 'b':
			if (ctl_parse_bbox(optarg, &o.bbox, err))
				return fail(what, -EINVAL, err);
			o.filter |= PROTO_COF_BBOX;
			break;
		case 'l':
			if (ctl_parse_levels(optarg, GRID_MAX_LEVEL, &o.lmin, &o.lmax, err))
				return fail(what, -EINVAL, err);
			o.filter |= PROTO_COF_LEVELS;
			break;
		case 'c':
			coverage = optarg;
			o.filter |= PROTO_COF_POLYGON;
			break;
		case 'j': o.json = true; break;
		default: cmd_usage(stderr); return 2;
		}
	}
	int npos = argc - optind;
	const char *why = NULL;
	if (o.filter && o.op != PROTO_COP_PURGE)
		why = "--bbox, --coverage and --levels go with purge";
	else if ((o.filter & PROTO_COF_BBOX) && (o.filter & PROTO_COF_POLYGON))
		why = "give --bbox or --coverage, not both";
	else if (o.op == PROTO_COP_PURGE && npos != 1)
		why = "want PLANET";
	else if (o.op == PROTO_COP_GC && npos != 0)
		why = "takes no PLANET";
	else if (npos > 1)
		why = "want at most one PLANET";
	if (why) {
		fprintf(stderr, "clipmapctl %s: %s\n", what, why);
		return 2;
	}
	o.planet = npos ? argv[optind] : NULL;
	struct coverage cv = { 0 };
	if (coverage) {
		if ((status = load_coverage(what, coverage, &cv)) >= 0)
			return status;
		o.nrings = cv.nrings;
		o.npoints = cv.npoints;
		o.rings = cv.rings;
		o.points = cv.pts;
	}
	struct net_conn *conn;
	int rc = 0;
	if (connect_or_complain(t, &conn)) {
		status = 1;
	} else {
		rc = ctl_cache_op(conn, &o, t->timeout_ms, stdout, err);
		net_close(conn);
		status = rc ? fail(what, rc, err) : 0;
	}
#ifndef CTL_THIN
	coverage_free(&cv);
#endif
	return status;
}

static int cmd_cache(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = {
		GLOBAL_OPTS,
		{ "near", required_argument, NULL, 'n' },   { "radius", required_argument, NULL, 'r' },
		{ "level", required_argument, NULL, 'l' },  { "limit", required_argument, NULL, 'm' },
		{ "json", no_argument, NULL, 'j' },	    { 0, 0, 0, 0 },
	};
	if (argc == 2 && (strcmp(argv[1], "--help") == 0 || strcmp(argv[1], "-h") == 0)) {
		cmd_usage(stdout);
		return 0;
	}
	if (argc >= 2 && strcmp(argv[1], "ls") != 0)
		return cmd_cache_op(argc, argv, t);
	if (argc < 2) {
		fprintf(stderr, "clipmapctl cache: want ls, stat, purge, gc or verify\n");
		return 2;
	}
	argc--;
	argv++;
	struct ctl_cache_opts o = { .level = -1 };
	int c, status;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "s:H:h", opts, t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		if ((status = cache_option(c, optarg, &o)))
			return status;
	}
	if (argc - optind != 1) {
		fprintf(stderr, "clipmapctl cache ls: want PLANET\n");
		return 2;
	}
	o.planet = argv[optind];
	struct net_conn *conn;
	if (connect_or_complain(t, &conn))
		return 1;
	char err[256];
	int rc = ctl_cache_ls(conn, &o, timeout_of(t), stdout, err);
	net_close(conn);
	return rc ? fail("cache ls", rc, err) : 0;
}

/* `clipmapctl prefetch`'s options: what ctl_prefetch_run takes, and what was given. */
struct prefetch_args {
	struct ctl_prefetch_opts o;
	struct proto_lonlat *pts; /* --path, owned (free()) */
	const char *coverage;	  /* --coverage FILE */
	bool levels, width, dry_run;
};

/* Takes prefetch option c with its argument s into pa. Returns 0, or the exit status after
 * saying what is wrong. */
static int prefetch_option(int c, const char *s, struct prefetch_args *pa)
{
	struct ctl_prefetch_opts *o = &pa->o;
	char err[256];
	switch (c) {
	case 'c':
		if (o->shape) {
			err_set(err, "give one --bbox, --path or --coverage");
			return fail("prefetch", -EINVAL, err);
		}
		pa->coverage = s;
		o->shape = PROTO_SHAPE_POLYGON;
		return 0;
	case 'b':
	case 'p':
		if (o->shape) {
			err_set(err, "give one --bbox, --path or --coverage");
			return fail("prefetch", -EINVAL, err);
		}
		if (c == 'b' ? ctl_parse_bbox(s, &o->bbox, err)
			     : ctl_parse_path(s, &pa->pts, &o->npoints, err))
			return fail("prefetch", -EINVAL, err);
		o->shape = c == 'b' ? PROTO_SHAPE_BBOX : PROTO_SHAPE_PATH;
		return 0;
	case 'w':
		if (ctl_parse_km(s, "--width", PROTO_MAX_WIDTH / 1000, &o->width_m, err))
			return fail("prefetch", -EINVAL, err);
		pa->width = true;
		return 0;
	case 'l':
		if (ctl_parse_levels(s, GRID_MAX_LEVEL - 1, &o->lmin, &o->lmax, err))
			return fail("prefetch", -EINVAL, err);
		pa->levels = true;
		return 0;
	case 'y': o->layers = s; return 0;
	case 'n': pa->dry_run = true; return 0;
	case 'j': o->json = true; return 0;
	default: cmd_usage(stderr); return 2;
	}
}

/* The options that go together. Returns 0 or 2 (after saying why). */
static int check_prefetch_args(const struct prefetch_args *pa, int npos)
{
	const char *why = NULL;
	if (npos != 1)
		why = "want PLANET and --bbox, --path or --coverage";
	else if (!pa->o.shape)
		why = "give --bbox W,S,E,N, --path LAT,LON:LAT,LON or --coverage FILE";
	else if (!pa->levels)
		why = "--levels A-B is required";
	else if (pa->o.shape == PROTO_SHAPE_PATH && !pa->width)
		why = "--path needs --width KM";
	else if (pa->o.shape != PROTO_SHAPE_PATH && pa->width)
		why = "--width goes with --path";
	else if (pa->o.json && !pa->dry_run)
		why = "--json goes with --dry-run";
	if (!why)
		return 0;
	fprintf(stderr, "clipmapctl prefetch: %s\n", why);
	return 2;
}

/* The command line of `prefetch` into pa (pa->pts returned owned, also on failure). Returns
 * -1 to go on, else the exit status. */
static int parse_prefetch_args(int argc, char **argv, struct ctl_target *t,
			       struct prefetch_args *pa)
{
	static const struct option opts[] = {
		GLOBAL_OPTS,
		{ "bbox", required_argument, NULL, 'b' },   { "path", required_argument, NULL, 'p' },
		{ "width", required_argument, NULL, 'w' },  { "levels", required_argument, NULL, 'l' },
		{ "layers", required_argument, NULL, 'y' }, { "dry-run", no_argument, NULL, 'n' },
		{ "json", no_argument, NULL, 'j' },	    { "coverage", required_argument, NULL, 'c' },
		{ 0, 0, 0, 0 },
	};
	*pa = (struct prefetch_args){ 0 };
	int c, status;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = next_opt(argc, argv, "s:H:h", opts, t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		if ((status = prefetch_option(c, optarg, pa)))
			return status;
	}
	if ((status = check_prefetch_args(pa, argc - optind)))
		return status;
	pa->o.planet = argv[optind];
	pa->o.points = pa->pts;
	return -1;
}

/* SIGINT and SIGTERM blocked and readable from the returned signalfd, so that Ctrl-C does no
 * work in any handler. Returns the fd or -errno. */
static int stop_signals_fd(void)
{
	sigset_t set;
	sigemptyset(&set);
	sigaddset(&set, SIGINT);
	sigaddset(&set, SIGTERM);
	if (sigprocmask(SIG_BLOCK, &set, NULL) != 0)
		return -errno;
	int fd = signalfd(-1, &set, SFD_CLOEXEC);
	return fd < 0 ? -errno : fd;
}

/* Runs the prefetch job o through the daemon until it ends or Ctrl-C. Returns the exit
 * status. */
static int prefetch(const struct ctl_target *t, const struct ctl_prefetch_opts *o)
{
	struct net_conn *conn;
	if (connect_or_complain(t, &conn))
		return 1;
	int sfd = stop_signals_fd();
	if (sfd < 0) {
		fprintf(stderr, "clipmapctl prefetch: signalfd: %s\n", strerror(-sfd));
		net_close(conn);
		return 1;
	}
	struct ctl_prefetch_ui ui = { .progress = stderr, .tty = isatty(STDERR_FILENO) == 1,
				      .summary = stdout, .stop_fd = sfd,
				      .timeout_ms = t->timeout_ms };
	struct proto_prefetch_progress fin;
	char err[256], serr[256];
	/* A job that fits the disk tier's budget alone may still push out what earlier jobs
	 * prefetched (or its own first tiles): the daemon counts those evictions, and the
	 * operator is told here rather than finding out from a viewer's waits. */
	static const char pf_key[] = "store.disk.evictions_prefetched";
	uint64_t ev0 = 0, ev1 = 0;
	bool counted = ctl_stat_u64(conn, pf_key, timeout_of(t), &ev0, serr) == 0;
	int rc = ctl_prefetch_run(conn, o, &ui, &fin, err);
	/* the job's last tiles are written behind it: their batches evict too (3 s at most; not
	 * after a Ctrl-C, which is answered at once) */
	uint64_t queued = 0;
	for (int k = 0; counted && rc == 0 && k < 60 &&
			ctl_stat_u64(conn, "store.disk.queued", timeout_of(t), &queued, serr) == 0 &&
			queued > 0;
	     k++)
		usleep(50 * 1000);
	if (counted && (rc == 0 || rc == -ECANCELED) &&
	    ctl_stat_u64(conn, pf_key, timeout_of(t), &ev1, serr) == 0 && ev1 > ev0)
		fprintf(stderr, "clipmapctl prefetch: warning: the disk tier evicted %llu "
			"prefetched tiles while this job ran (%s): it is full, and what was "
			"prefetched (by earlier jobs, or this one's first tiles) is no longer all "
			"on disk; raise [store] disk_mb or prefetch less\n",
			(unsigned long long)(ev1 - ev0), pf_key);
	net_close(conn);
	close(sfd);
	if (rc == -ECANCELED) {
		fprintf(stderr, "clipmapctl prefetch: %s\n", err);
		return 130;
	}
	return rc ? fail("prefetch", rc, err) : 0;
}

static int cmd_prefetch(int argc, char **argv, struct ctl_target *t)
{
	struct prefetch_args pa;
	struct coverage cv = { 0 };
	int status = parse_prefetch_args(argc, argv, t, &pa);
	if (status < 0 && pa.coverage && (status = load_coverage("prefetch", pa.coverage, &cv)) < 0) {
		pa.o.rings = cv.rings;
		pa.o.nrings = cv.nrings;
		pa.o.points = cv.pts;
		pa.o.npoints = cv.npoints;
	}
	if (status < 0 && pa.dry_run) {
		struct net_conn *conn;
		if (connect_or_complain(t, &conn)) {
			status = 1;
		} else {
			char err[256];
			int rc = ctl_prefetch_dry(conn, &pa.o, t->timeout_ms, stdout, err);
			net_close(conn);
			status = rc ? fail("prefetch", rc, err) : 0;
		}
	} else if (status < 0) {
		status = prefetch(t, &pa.o);
	}
	free(pa.pts);
#ifndef CTL_THIN
	coverage_free(&cv);
#endif
	return status;
}

/* Whether the command line names a --coverage file (read with GDAL: clipmapctl-offline). */
static bool wants_coverage(int argc, char **argv)
{
	for (int i = 1; i < argc; i++) {
		if (strcmp(argv[i], "--") == 0)
			return false;
		if (strcmp(argv[i], "--coverage") == 0 || strncmp(argv[i], "--coverage=", 11) == 0)
			return true;
	}
	return false;
}

/* The command named argv[0], with t from the global options. */
static int run_command(int argc, char **argv, struct ctl_target *t)
{
	const char *cmd = argv[0];
	current_cmd = cmd;
#ifdef CTL_THIN
	/* a coverage file is read with GDAL, which only clipmapctl-offline loads */
	if ((!strcmp(cmd, "prefetch") || !strcmp(cmd, "cache")) && wants_coverage(argc, argv))
		return run_offline(argc, argv, t);
#else
	(void)wants_coverage;
#endif
	if (strcmp(cmd, "status") == 0)
		return cmd_status(argc, argv, t);
	if (strcmp(cmd, "cache") == 0)
		return cmd_cache(argc, argv, t);
	if (strcmp(cmd, "prefetch") == 0)
		return cmd_prefetch(argc, argv, t);
#ifdef CTL_THIN
	/* what needs the engine, or OpenImageIO to write pictures */
	if (!strcmp(cmd, "tile") || !strcmp(cmd, "render") || !strcmp(cmd, "graph") ||
	    !strcmp(cmd, "layers") || !strcmp(cmd, "import"))
		return run_offline(argc, argv, t);
#else
	if (strcmp(cmd, "tile") == 0)
		return cmd_tile(argc, argv, t);
	if (strcmp(cmd, "render") == 0)
		return cmd_render(argc, argv);
	if (strcmp(cmd, "graph") == 0)
		return cmd_graph(argc, argv);
	if (strcmp(cmd, "layers") == 0)
		return cmd_layers(argc, argv);
	if (strcmp(cmd, "import") == 0)
		return import_cli(argc, argv);
#endif
	if (strcmp(cmd, "help") == 0) { /* help [COMMAND] */
		current_cmd = argc > 1 ? argv[1] : NULL;
		if (current_cmd && !find_usage(current_cmd)) {
			fprintf(stderr, "clipmapctl help: unknown command \"%s\"\n", current_cmd);
			return 2;
		}
		cmd_usage(stdout);
		return 0;
	}
	fprintf(stderr, "clipmapctl: unknown command \"%s\"\n", cmd);
	current_cmd = NULL;
	usage(stderr);
	return 2;
}

int main(int argc, char **argv)
{
	static const struct option opts[] = { GLOBAL_OPTS, { 0, 0, 0, 0 } };
	struct ctl_target t = { 0 };
	int c, status;
	/* global options before the command ("+": stop at the command) */
	while ((c = next_opt(argc, argv, "+s:H:hV", opts, &t, &status)) != -1) {
		if (c == OPT_EXIT)
			return status;
		usage(stderr);
		return 2;
	}
	if (argc - optind < 1) {
		usage(stderr);
		return 2;
	}
	return run_command(argc - optind, argv + optind, &t);
}
