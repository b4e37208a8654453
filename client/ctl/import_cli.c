/* import_cli — `clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N] [--tile N]
 * [--no-mip] [--quiet]`. Argument handling and output only; see import.h. */
#include "import_cli.h"

#include <errno.h>
#include <getopt.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "import.h"

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

int import_cli(int argc, char **argv)
{
	static const struct option opts[] = {
		{ "output", required_argument, NULL, 'o' }, { "bounds", required_argument, NULL, 'b' },
		{ "band", required_argument, NULL, 'n' },   { "tile", required_argument, NULL, 't' },
		{ "no-mip", no_argument, NULL, 'm' },	    { "quiet", no_argument, NULL, 'q' },
		{ "help", no_argument, NULL, 'h' },	    { 0, 0, 0, 0 },
	};
	struct import_opts o = { 0 };
	const char *dst = NULL;
	int quiet = 0, c;
	optind = 0; /* 0: glibc re-initialises (main parsed its options with "+") */
	while ((c = getopt_long(argc, argv, "o:qh", opts, NULL)) != -1) {
		char *end;
		long v;
		switch (c) {
		case 'o': dst = optarg; break;
		case 'b':
			if (import_parse_bounds(optarg, o.bounds)) {
				fprintf(stderr, "clipmapctl import: --bounds wants W,S,E,N in degrees "
					"(W < E, S < N, -90..90), got \"%s\"\n", optarg);
				return 2;
			}
			o.has_bounds = true;
			break;
		case 'n':
		case 't':
			errno = 0;
			v = strtol(optarg, &end, 10);
			if (end == optarg || *end || errno || v < 1 || v > 65536 ||
			    (c == 't' && v % 16)) {
				fprintf(stderr, "clipmapctl import: --%s wants %s, got \"%s\"\n",
					c == 'n' ? "band" : "tile",
					c == 'n' ? "a band number from 1" : "a multiple of 16", optarg);
				return 2;
			}
			if (c == 'n')
				o.band = (int)v;
			else
				o.tile = (int)v;
			break;
		case 'm': o.no_mip = true; break;
		case 'q': quiet = 1; break;
		case 'h':
			printf("usage: clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] [--band N] "
			       "[--tile N] [--no-mip] [--quiet]\n");
			return 0;
		default: return 2;
		}
	}
	if (argc - optind != 1 || !dst) {
		fprintf(stderr, "usage: clipmapctl import SRC -o DST.tif [--bounds W,S,E,N] "
			"[--band N] [--tile N] [--no-mip] [--quiet]\n");
		return 2;
	}
	struct import_result r;
	char err[256];
	int rc = import_raster(argv[optind], dst, &o, &r, err);
	if (rc) {
		fprintf(stderr, "clipmapctl import: %s\n", err);
		return rc == -EIO || rc == -ENOMEM ? 1 : 2;
	}
	if (!quiet) {
		printf("wrote %s: %dx%d, %d channel%s %s, bounds %.6f,%.6f,%.6f,%.6f%s%s", dst,
		       r.width, r.height, r.channels, r.channels == 1 ? "" : "s",
		       type_name(r.type), r.west, r.south, r.east, r.north,
		       r.georeferenced ? " (georeferenced)" : o.has_bounds ? " (given)" : " (global)",
		       r.flipped_rows ? ", rows flipped north-up" : "");
		if (r.shifted_cols)
			printf(", columns shifted by %d", r.shifted_cols);
		printf("; read %.2f s, write %.2f s\n", r.read_s, r.write_s);
	}
	return 0;
}
