/* clipmapctl — the operator's command line. This file is only argument handling and output;
 * the work lives in render.c (offline evaluation), ctl_*.c (online commands, through net.c)
 * and the library. Exit codes: 0 ok, 1 runtime failure, 2 bad usage or config, 130 when a
 * prefetch was interrupted. */
#include <errno.h>
#include <getopt.h>
#include <signal.h>
#include <stdbool.h>
#include <sys/signalfd.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "ctl_args.h"
#include "ctl_cache.h"
#include "ctl_conn.h"
#include "ctl_prefetch.h"
#include "ctl_status.h"
#include "ctl_tile.h"
#include "import_cli.h"
#include "engine/planet.h"
#include "planet_path.h"
#include "render.h"

static void usage(FILE *f)
{
	fputs("usage: clipmapctl [-s SOCKET | -H HOST:PORT] [--token-file FILE] [--timeout SEC] "
	      "COMMAND ...\n"
	      "online (through clipmapd; socket default $CLIPMAP_SOCKET or " CTL_DEFAULT_SOCKET ",\n"
	      "token default $CLIPMAP_TOKEN):\n"
	      "  clipmapctl status [--json]                         uptime, queues, cache, nodes\n"
	      "  clipmapctl tile PLANET LAYER LX LY X Y -o FILE     one tile through the daemon\n"
	      "  clipmapctl cache ls PLANET [--near LAT,LON [--radius KM]] [--level L]\n"
	      "                          [--limit N] [--json]       what is cached\n"
	      "  clipmapctl prefetch PLANET --bbox W,S,E,N --levels A-B [--layers a,b]\n"
	      "  clipmapctl prefetch PLANET --path LAT,LON:LAT,LON --width KM --levels A-B\n"
	      "                          [--layers a,b]             fill the cache (Ctrl-C cancels)\n"
	      "offline (evaluates the planet file here):\n"
	      "  clipmapctl render PLANET LAYER LX LY X Y -o FILE   one tile\n"
	      "  clipmapctl render PLANET LAYER --level L --world -o FILE\n"
	      "                                                     a whole level (lx = L+1, ly = L)\n"
	      "  clipmapctl render PLANET LAYER --level L --at LAT,LON [--tiles N] -o FILE\n"
	      "                                                     N×N tiles around a place (N = 3)\n"
	      "      options: --workers N  --cache-mb N  --shade (colour × hillshade)  --quiet\n"
	      "      heights: .tif/.tiff/.exr (float metres) or .png (16-bit, scale printed);\n"
	      "      colour and normals: .png\n"
	      "  clipmapctl graph PLANET                            the node graph as Graphviz dot\n"
	      "  clipmapctl layers PLANET                           layers, nodes and hashes\n"
	      "  clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N]\n"
	      "                     any GDAL raster -> tiled, mipmapped TIFF with its bounds\n"
	      "PLANET is a planet file or a name in $CLIPMAP_PLANETS or conf/planets/.\n",
	      f);
}

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

static void progress(void *ud, size_t done, size_t total)
{
	const struct timespec *t0 = ud;
	struct timespec now;
	clock_gettime(CLOCK_MONOTONIC, &now);
	double el = (double)(now.tv_sec - t0->tv_sec) + (now.tv_nsec - t0->tv_nsec) * 1e-9;
	fprintf(stderr, "\r  %zu/%zu tiles  %.1f tiles/s", done, total, el > 0 ? done / el : 0.0);
	if (done == total)
		fputc('\n', stderr);
}

static int cmd_render(int argc, char **argv)
{
	static const struct option opts[] = {
		{ "level", required_argument, NULL, 'l' },  { "world", no_argument, NULL, 'w' },
		{ "workers", required_argument, NULL, 'j' }, { "cache-mb", required_argument, NULL, 'c' },
		{ "shade", no_argument, NULL, 's' },	    { "quiet", no_argument, NULL, 'q' },
		{ "output", required_argument, NULL, 'o' }, { "help", no_argument, NULL, 'h' },
		{ "at", required_argument, NULL, 'a' },	    { "tiles", required_argument, NULL, 't' },
		{ 0, 0, 0, 0 },
	};
	const char *outpath = NULL;
	long level = -1;
	int world = 0, quiet = 0, at = 0;
	double lat = 0, lon = 0;
	uint32_t ntiles = 3;
	struct render_opts ro = { 0 };
	int c;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = getopt_long(argc, argv, "o:l:wj:c:sqh", opts, NULL)) != -1) {
		uint32_t v;
		switch (c) {
		case 'o': outpath = optarg; break;
		case 'l':
			if (parse_u32(optarg, "--level", GRID_MAX_LEVEL - 1, &v))
				return 2;
			level = v;
			break;
		case 'w': world = 1; break;
		case 'a': {
			char *end;
			lat = strtod(optarg, &end);
			if (*end == ',')
				lon = strtod(end + 1, &end);
			if (*end || end == optarg || lat < -90 || lat > 90 || lon < -180 || lon > 180) {
				fprintf(stderr, "clipmapctl render: --at wants LAT,LON in degrees "
					"(-90..90, -180..180), got \"%s\"\n", optarg);
				return 2;
			}
			at = 1;
			break;
		}
		case 't':
			if (parse_u32(optarg, "--tiles", 64, &v) || v == 0) {
				if (v == 0)
					fprintf(stderr, "clipmapctl render: --tiles must be at least 1\n");
				return 2;
			}
			ntiles = v;
			break;
		case 'j':
			if (parse_u32(optarg, "--workers", 256, &v))
				return 2;
			ro.workers = (int)v;
			break;
		case 'c':
			if (parse_u32(optarg, "--cache-mb", 1 << 20, &v))
				return 2;
			ro.cache_mb = v;
			break;
		case 's': ro.shade = 1; break;
		case 'q': quiet = 1; break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	int npos = argc - optind;
	char **pos = argv + optind;
	if (!outpath) {
		fprintf(stderr, "clipmapctl render: -o FILE is required\n");
		return 2;
	}
	uint32_t lx, ly, x = 0, y = 0;
	struct render_region rg;
	if (level >= 0) {
		if (npos != 2) {
			fprintf(stderr, "clipmapctl render: with --level give PLANET LAYER only\n");
			return 2;
		}
		if (world == at) {
			fprintf(stderr, "clipmapctl render: --level needs --world (the whole level) or "
				"--at LAT,LON (tiles around a place)\n");
			return 2;
		}
		lx = (uint32_t)level + 1;
		ly = (uint32_t)level;
		if (world)
			render_region_level((int)lx, (int)ly, &rg);
		else
			render_region_around((int)lx, (int)ly, lat, lon, ntiles, &rg);
	} else {
		if (world || at) {
			fprintf(stderr, "clipmapctl render: --world and --at go with --level\n");
			return 2;
		}
		if (npos != 6) {
			usage(stderr);
			return 2;
		}
		if (parse_u32(pos[2], "LX", GRID_MAX_LEVEL, &lx) ||
		    parse_u32(pos[3], "LY", GRID_MAX_LEVEL, &ly) ||
		    parse_u32(pos[4], "X", 0x7fffffff, &x) || parse_u32(pos[5], "Y", 0x7fffffff, &y))
			return 2;
		rg = (struct render_region){ .lx = (int)lx, .ly = (int)ly, .x = x, .y = y, .cols = 1,
					     .rows = 1 };
	}
	struct planet *p;
	int rc = load(pos[0], &p);
	if (rc)
		return rc;
	struct timespec t0;
	clock_gettime(CLOCK_MONOTONIC, &t0);
	if (!quiet && level >= 0 && isatty(STDERR_FILENO)) {
		ro.progress = progress;
		ro.ud = &t0;
	}
	struct render_image im;
	char err[256], note[256];
	rc = render_layer(p, pos[1], &rg, &ro, &im, err);
	if (rc) {
		fprintf(stderr, "clipmapctl render: %s\n", err);
		planet_unref(p);
		return rc == -EINVAL || rc == -ENOENT || rc == -E2BIG ? 2 : 1;
	}
	rc = render_write(&im, outpath, note, err);
	if (rc) {
		fprintf(stderr, "clipmapctl render: %s\n", err);
	} else if (!quiet) {
		struct timespec t1;
		clock_gettime(CLOCK_MONOTONIC, &t1);
		double el = (double)(t1.tv_sec - t0.tv_sec) + (t1.tv_nsec - t0.tv_nsec) * 1e-9;
		printf("wrote %s (%dx%d) in %.2f s\n", outpath, im.width, im.height, el);
		if (note[0])
			printf("%s\n", note);
	}
	render_image_free(&im);
	planet_unref(p);
	return rc ? 1 : 0;
}

static int cmd_graph(int argc, char **argv)
{
	if (argc != 2) {
		usage(stderr);
		return 2;
	}
	struct planet *p;
	int rc = load(argv[1], &p);
	if (rc)
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
	if (argc != 2) {
		usage(stderr);
		return 2;
	}
	struct planet *p;
	int rc = load(argv[1], &p);
	if (rc)
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


/* ---- online commands ------------------------------------------------------------------ */

/* Options every online command takes (also before the command). Returns 1 if c was one. */
static int global_opt(int c, struct ctl_target *t)
{
	switch (c) {
	case 'S': t->socket_path = optarg; return 1;
	case 'H': t->hostport = optarg; return 1;
	case 'T': t->token_file = optarg; return 1;
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
	{ "token-file", required_argument, NULL, 'T' },                                          \
	{ "timeout", required_argument, NULL, 'W' }, { "help", no_argument, NULL, 'h' }

/* The exit code for a failed online command: request errors the user can fix are usage. */
static int fail(const char *cmd, int rc, const char *err)
{
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
	int c;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = getopt_long(argc, argv, "s:H:h", opts, NULL)) != -1) {
		int g = global_opt(c == 's' ? 'S' : c, t);
		if (g < 0)
			return 2;
		if (g)
			continue;
		if (c == 'j')
			json = true;
		else if (c == 'h') {
			usage(stdout);
			return 0;
		} else {
			usage(stderr);
			return 2;
		}
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
	net_close(conn);
	return rc ? fail("status", rc, err) : 0;
}

static int cmd_tile(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = { GLOBAL_OPTS, { "output", required_argument, NULL, 'o' },
					      { "quiet", no_argument, NULL, 'q' }, { 0, 0, 0, 0 } };
	const char *outpath = NULL;
	bool quiet = false;
	int c;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = getopt_long(argc, argv, "s:H:o:qh", opts, NULL)) != -1) {
		int g = global_opt(c == 's' ? 'S' : c, t);
		if (g < 0)
			return 2;
		if (g)
			continue;
		if (c == 'o')
			outpath = optarg;
		else if (c == 'q')
			quiet = true;
		else if (c == 'h') {
			usage(stdout);
			return 0;
		} else {
			usage(stderr);
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

static int cmd_cache(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = {
		GLOBAL_OPTS,
		{ "near", required_argument, NULL, 'n' },   { "radius", required_argument, NULL, 'r' },
		{ "level", required_argument, NULL, 'l' },  { "limit", required_argument, NULL, 'm' },
		{ "json", no_argument, NULL, 'j' },	    { 0, 0, 0, 0 },
	};
	if (argc < 2 || strcmp(argv[1], "ls") != 0) {
		fprintf(stderr, "clipmapctl cache: the only subcommand is \"ls\"\n");
		return 2;
	}
	argc--;
	argv++;
	struct ctl_cache_opts o = { .level = -1 };
	char err[256];
	int c;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while ((c = getopt_long(argc, argv, "s:H:h", opts, NULL)) != -1) {
		int g = global_opt(c == 's' ? 'S' : c, t);
		uint64_t v;
		if (g < 0)
			return 2;
		if (g)
			continue;
		switch (c) {
		case 'n':
			if (ctl_parse_latlon(optarg, &o.lat, &o.lon, err))
				return fail("cache ls --near", -EINVAL, err);
			o.near = true;
			break;
		case 'r':
			if (ctl_parse_km(optarg, "--radius", &o.radius_m, err))
				return fail("cache ls", -EINVAL, err);
			break;
		case 'l':
			if (ctl_parse_uint(optarg, "--level", GRID_MAX_LEVEL - 1, &v, err))
				return fail("cache ls", -EINVAL, err);
			o.level = (int)v;
			break;
		case 'm':
			if (ctl_parse_uint(optarg, "--limit", UINT32_MAX, &v, err))
				return fail("cache ls", -EINVAL, err);
			o.limit = (uint32_t)v;
			break;
		case 'j': o.json = true; break;
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (argc - optind != 1) {
		fprintf(stderr, "clipmapctl cache ls: want PLANET\n");
		return 2;
	}
	o.planet = argv[optind];
	struct net_conn *conn;
	if (connect_or_complain(t, &conn))
		return 1;
	int rc = ctl_cache_ls(conn, &o, timeout_of(t), stdout, err);
	net_close(conn);
	return rc ? fail("cache ls", rc, err) : 0;
}

static int cmd_prefetch(int argc, char **argv, struct ctl_target *t)
{
	static const struct option opts[] = {
		GLOBAL_OPTS,
		{ "bbox", required_argument, NULL, 'b' },   { "path", required_argument, NULL, 'p' },
		{ "width", required_argument, NULL, 'w' },  { "levels", required_argument, NULL, 'l' },
		{ "layers", required_argument, NULL, 'y' }, { 0, 0, 0, 0 },
	};
	struct ctl_prefetch_opts o = { 0 };
	struct proto_lonlat *pts = NULL;
	bool levels = false, width = false;
	char err[256];
	int c, rc = 0;
	optind = 0; /* 0: glibc re-initialises (main parsed with "+") */
	while (rc == 0 && (c = getopt_long(argc, argv, "s:H:h", opts, NULL)) != -1) {
		int g = global_opt(c == 's' ? 'S' : c, t);
		if (g < 0) {
			rc = 2;
			break;
		}
		if (g)
			continue;
		switch (c) {
		case 'b':
			if (o.shape || ctl_parse_bbox(optarg, &o.bbox, err)) {
				if (o.shape)
					snprintf(err, sizeof err, "give one --bbox or one --path");
				rc = fail("prefetch", -EINVAL, err);
			}
			o.shape = PROTO_SHAPE_BBOX;
			break;
		case 'p':
			if (o.shape || ctl_parse_path(optarg, &pts, &o.npoints, err)) {
				if (o.shape)
					snprintf(err, sizeof err, "give one --bbox or one --path");
				rc = fail("prefetch", -EINVAL, err);
			}
			o.shape = PROTO_SHAPE_PATH;
			break;
		case 'w':
			if (ctl_parse_km(optarg, "--width", &o.width_m, err))
				rc = fail("prefetch", -EINVAL, err);
			width = true;
			break;
		case 'l':
			if (ctl_parse_levels(optarg, GRID_MAX_LEVEL - 1, &o.lmin, &o.lmax, err))
				rc = fail("prefetch", -EINVAL, err);
			levels = true;
			break;
		case 'y': o.layers = optarg; break;
		case 'h': usage(stdout); free(pts); return 0;
		default: usage(stderr); rc = 2; break;
		}
	}
	if (rc == 0 && argc - optind != 1) {
		fprintf(stderr, "clipmapctl prefetch: want PLANET and --bbox or --path\n");
		rc = 2;
	} else if (rc == 0 && !o.shape) {
		fprintf(stderr, "clipmapctl prefetch: give --bbox W,S,E,N or --path LAT,LON:LAT,LON\n");
		rc = 2;
	} else if (rc == 0 && !levels) {
		fprintf(stderr, "clipmapctl prefetch: --levels A-B is required\n");
		rc = 2;
	} else if (rc == 0 && o.shape == PROTO_SHAPE_PATH && !width) {
		fprintf(stderr, "clipmapctl prefetch: --path needs --width KM\n");
		rc = 2;
	} else if (rc == 0 && o.shape == PROTO_SHAPE_BBOX && width) {
		fprintf(stderr, "clipmapctl prefetch: --width goes with --path\n");
		rc = 2;
	}
	if (rc) {
		free(pts);
		return rc;
	}
	o.planet = argv[optind];
	o.points = pts;

	struct net_conn *conn;
	if (connect_or_complain(t, &conn)) {
		free(pts);
		return 1;
	}
	/* Ctrl-C arrives as a readable signalfd: no work in any handler. */
	sigset_t set;
	sigemptyset(&set);
	sigaddset(&set, SIGINT);
	sigaddset(&set, SIGTERM);
	int sfd = -1;
	if (sigprocmask(SIG_BLOCK, &set, NULL) == 0)
		sfd = signalfd(-1, &set, SFD_CLOEXEC);
	if (sfd < 0) {
		fprintf(stderr, "clipmapctl prefetch: signalfd: %s\n", strerror(errno));
		net_close(conn);
		free(pts);
		return 1;
	}
	struct ctl_prefetch_ui ui = { .progress = stderr, .tty = isatty(STDERR_FILENO) == 1,
				      .summary = stdout, .stop_fd = sfd,
				      .timeout_ms = t->timeout_ms };
	struct proto_prefetch_progress fin;
	rc = ctl_prefetch_run(conn, &o, &ui, &fin, err);
	net_close(conn);
	close(sfd);
	free(pts);
	if (rc == -ECANCELED) {
		fprintf(stderr, "clipmapctl prefetch: %s\n", err);
		return 130;
	}
	return rc ? fail("prefetch", rc, err) : 0;
}

int main(int argc, char **argv)
{
	static const struct option opts[] = { GLOBAL_OPTS, { 0, 0, 0, 0 } };
	struct ctl_target t = { 0 };
	int c;
	/* global options before the command ("+": stop at the command) */
	while ((c = getopt_long(argc, argv, "+s:H:h", opts, NULL)) != -1) {
		int g = global_opt(c == 's' ? 'S' : c, &t);
		if (g < 0)
			return 2;
		if (g)
			continue;
		if (c == 'h') {
			usage(stdout);
			return 0;
		}
		usage(stderr);
		return 2;
	}
	argc -= optind - 1;
	argv += optind - 1;
	if (argc < 2) {
		usage(stderr);
		return 2;
	}
	const char *cmd = argv[1];
	if (strcmp(cmd, "status") == 0)
		return cmd_status(argc - 1, argv + 1, &t);
	if (strcmp(cmd, "tile") == 0)
		return cmd_tile(argc - 1, argv + 1, &t);
	if (strcmp(cmd, "cache") == 0)
		return cmd_cache(argc - 1, argv + 1, &t);
	if (strcmp(cmd, "prefetch") == 0)
		return cmd_prefetch(argc - 1, argv + 1, &t);
	if (strcmp(cmd, "render") == 0)
		return cmd_render(argc - 1, argv + 1);
	if (strcmp(cmd, "graph") == 0)
		return cmd_graph(argc - 1, argv + 1);
	if (strcmp(cmd, "layers") == 0)
		return cmd_layers(argc - 1, argv + 1);
	if (strcmp(cmd, "import") == 0)
		return import_cli(argc - 1, argv + 1);
	if (strcmp(cmd, "help") == 0 || strcmp(cmd, "--help") == 0 || strcmp(cmd, "-h") == 0) {
		usage(stdout);
		return 0;
	}
	fprintf(stderr, "clipmapctl: unknown command \"%s\"\n", cmd);
	usage(stderr);
	return 2;
}
