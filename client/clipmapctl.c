/* clipmapctl — the operator's command line. This file is only argument handling and output;
 * the work lives in render.c (offline evaluation) and the library. Exit codes: 0 ok,
 * 1 runtime failure, 2 bad usage or config. */
#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "import_cli.h"
#include "planet.h"
#include "planet_path.h"
#include "render.h"

static void usage(FILE *f)
{
	fputs("usage:\n"
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
	optind = 1;
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
		planet_destroy(p);
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
	planet_destroy(p);
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
	planet_destroy(p);
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
	planet_destroy(p);
	return 0;
}

int main(int argc, char **argv)
{
	if (argc < 2) {
		usage(stderr);
		return 2;
	}
	const char *cmd = argv[1];
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
