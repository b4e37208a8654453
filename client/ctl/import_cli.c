/* import_cli — `clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N] [--tile N]
 * [--resample ALG] [--repair-rows UNITS[,PIXELS]] [--no-mip] [--quiet]`. Argument handling and output only; see import.h. */
#include "import_cli.h"

#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "import.h"
#include "streaks.h"

static const char *type_name(enum img_type t)
{
	switch (t) {
	case IMG_U8: return "uint8";
	case IMG_U16: return "uint16";
	case IMG_I16: return "int16";
	case IMG_F32: return "float";
	default: return "?";
	}
}

#define USAGE                                                                                \
	"usage: clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N] [--tile N] "    \
	"[--resample near|bilinear|cubic|cubicspline|lanczos|average|mode] "                    \
	"[--repair-rows UNITS[,PIXELS]] [--no-mip] [--quiet]\n"

/* `import`'s command line. */
struct import_args {
	struct import_opts o;
	const char *src, *dst;
	bool quiet;
};

/* --band N or --tile N (which: 'n' or 't') into n. Returns false on a bad one (after saying
 * so). */
static bool parse_band_or_tile(int which, const char *s, int *n)
{
	char *end;
	errno = 0;
	long v = strtol(s, &end, 10);
	if (end == s || *end || errno || v < 1 || v > 65536 || (which == 't' && v % 16)) {
		fprintf(stderr, "clipmapctl import: --%s wants %s, got \"%s\"\n",
			which == 'n' ? "band" : "tile",
			which == 'n' ? "a band number from 1" : "a multiple of 16", s);
		return false;
	}
	*n = (int)v;
	return true;
}

/* --repair-rows UNITS[,PIXELS] into o. Returns false on a bad one (after saying so). */
static bool parse_repair(const char *s, struct import_opts *o)
{
	char *end;
	errno = 0;
	double t = strtod(s, &end);
	long len = 0;
	bool ok = end != s && errno == 0 && isfinite(t) && t > 0;
	if (ok && *end == ',') {
		const char *p = end + 1;
		len = strtol(p, &end, 10);
		ok = end != p && errno == 0 && len >= 2 && len <= 1 << 20;
	}
	if (!ok || *end) {
		fprintf(stderr, "clipmapctl import: --repair-rows wants UNITS[,PIXELS]: how far a "
			"row's streak sits beyond both rows beside it (> 0, the samples' unit) and "
			"its shortest run (2..1048576 pixels, default %d), got \"%s\"\n",
			STREAKS_LEN, s);
		return false;
	}
	o->repair_rows = t;
	o->repair_len = (int)len;
	return true;
}

/* The command line into a. Returns -1 to go on, else the exit status (0: --help). */
static int parse_import_args(int argc, char **argv, struct import_args *a)
{
	static const struct option opts[] = {
		{ "output", required_argument, NULL, 'o' }, { "bounds", required_argument, NULL, 'b' },
		{ "band", required_argument, NULL, 'n' },   { "tile", required_argument, NULL, 't' },
		{ "no-mip", no_argument, NULL, 'm' },	    { "quiet", no_argument, NULL, 'q' },
		{ "help", no_argument, NULL, 'h' },	    { "resample", required_argument, NULL, 'r' },
		{ "repair-rows", required_argument, NULL, 'R' },
		{ 0, 0, 0, 0 },
	};
	*a = (struct import_args){ 0 };
	int c;
	optind = 0; /* 0: glibc re-initialises (main parsed its options with "+") */
	while ((c = getopt_long(argc, argv, "o:qh", opts, NULL)) != -1) {
		switch (c) {
		case 'o': a->dst = optarg; break;
		case 'b':
			if (import_parse_bounds(optarg, a->o.bounds)) {
				fprintf(stderr, "clipmapctl import: --bounds wants W,S,E,N in degrees "
					"(W < E, S < N, -90..90), got \"%s\"\n", optarg);
				return 2;
			}
			a->o.has_bounds = true;
			break;
		case 'n':
			if (!parse_band_or_tile(c, optarg, &a->o.band))
				return 2;
			break;
		case 't':
			if (!parse_band_or_tile(c, optarg, &a->o.tile))
				return 2;
			break;
		case 'm': a->o.no_mip = true; break;
		case 'r':
			if (!import_resample_ok(optarg)) {
				fprintf(stderr, "clipmapctl import: --resample wants near, bilinear, "
					"cubic, cubicspline, lanczos, average or mode, got \"%s\"\n",
					optarg);
				return 2;
			}
			a->o.resample = optarg;
			break;
		case 'R':
			if (!parse_repair(optarg, &a->o))
				return 2;
			break;
		case 'q': a->quiet = true; break;
		case 'h': printf(USAGE); return 0;
		default: return 2;
		}
	}
	if (argc - optind != 1 || !a->dst) {
		fprintf(stderr, USAGE);
		return 2;
	}
	a->src = argv[optind];
	return -1;
}

/* The line saying what was written. */
static void report(const struct import_args *a, const struct import_result *r)
{
	printf("wrote %s: %dx%d, %d channel%s %s, bounds %.6f,%.6f,%.6f,%.6f%s%s", a->dst,
	       r->width, r->height, r->channels, r->channels == 1 ? "" : "s", type_name(r->type),
	       r->west, r->south, r->east, r->north,
	       r->reprojected	 ? " (reprojected to degrees)"
	       : r->georeferenced ? " (georeferenced)"
	       : a->o.has_bounds  ? " (given)"
				  : " (global)",
	       r->flipped_rows ? ", rows flipped north-up" : "");
	if (r->shifted_cols)
		printf(", columns shifted by %d", r->shifted_cols);
	if (a->o.repair_rows > 0)
		printf(", %lld sample%s in row streaks repaired", (long long)r->repaired,
		       r->repaired == 1 ? "" : "s");
	printf("; read %.2f s, write %.2f s\n", r->read_s, r->write_s);
}

int import_cli(int argc, char **argv)
{
	struct import_args a;
	int status = parse_import_args(argc, argv, &a);
	if (status >= 0)
		return status;
	struct import_result r;
	char err[256];
	int rc = import_raster(a.src, a.dst, &a.o, &r, err);
	if (rc) {
		fprintf(stderr, "clipmapctl import: %s\n", err);
		return rc == -EIO || rc == -ENOMEM ? 1 : 2;
	}
	if (!a.quiet)
		report(&a, &r);
	return 0;
}
