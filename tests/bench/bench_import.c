/* bench_import — the fast path for huge inputs: a global int16 raster written as a plain
 * (striped) GeoTIFF with GDAL, `clipmapctl import`ed (GDAL read, OIIO tiled + mipmapped
 * write), then served by the `file` node: tile rate and memory for random access (any level,
 * anywhere) and for a flight (adjacent fine tiles along a path, the clipmap's pattern).
 * Default 10800×5400 (2′, 117 MB); CLIPMAP_BENCH_SCALE=1 runs the 43200×21600 (30″,
 * 1.8 GB raw, minutes on 2 cores). Files live in /tmp and are removed. One worker.
 * The source is generated and imported in child processes of their own, so "import peak
 * RSS" is the import's alone: ru_maxrss of the import child (wait4). "serve peak RSS" is
 * this process's ru_maxrss (getrusage RUSAGE_SELF) after serving. */
#include <errno.h>
#include <gdal/cpl_error.h>
#include <gdal/gdal.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "client/ctl/import.h"
#include "common/clock.h"
#include "common/ini.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/tile.h"

static void die(const char *what, const char *err)
{
	fprintf(stderr, "bench_import: %s: %s\n", what, err);
	exit(1);
}

static double rss_mb(void)
{
	FILE *f = fopen("/proc/self/statm", "r");
	long pages = 0, res = 0;
	if (f) {
		if (fscanf(f, "%ld %ld", &pages, &res) != 2)
			res = 0;
		fclose(f);
	}
	return (double)res * (double)sysconf(_SC_PAGESIZE) / 1048576.0;
}

static double peak_mb(void)
{
	struct rusage ru;
	getrusage(RUSAGE_SELF, &ru);
	return ru.ru_maxrss / 1024.0;
}

static void make_source(const char *path, int w, int h)
{
	GDALAllRegister();
	GDALDriverH drv = GDALGetDriverByName("GTiff");
	char *opts[] = { "BIGTIFF=IF_SAFER", NULL };
	GDALDatasetH ds = GDALCreate(drv, path, w, h, 1, GDT_Int16, opts);
	if (!ds)
		die(path, CPLGetLastErrorMsg());
	double gt[6] = { -180, 360.0 / w, 0, 90, 0, -180.0 / h };
	GDALSetGeoTransform(ds, gt);
	GDALRasterBandH b = GDALGetRasterBand(ds, 1);
	int rows = 256;
	int16_t *buf = malloc(sizeof *buf * (size_t)w * rows);
	if (!buf)
		die("malloc", "out of memory");
	for (int y0 = 0; y0 < h; y0 += rows) {
		int n = h - y0 < rows ? h - y0 : rows;
		for (int y = 0; y < n; y++)
			for (int x = 0; x < w; x++) {
				uint32_t q = (uint32_t)x * 73856093u ^ (uint32_t)(y0 + y) * 19349663u;
				q ^= q >> 13;
				double v = 3000 * sin(x * 6.0 / w * 3.14159) *
						   cos((y0 + y) * 9.0 / h * 3.14159) +
					   900 * sin(x * 0.013 + (y0 + y) * 0.007) + (q & 63);
				buf[(size_t)y * w + x] = (int16_t)v;
			}
		if (GDALRasterIO(b, GF_Write, 0, y0, w, n, buf, w, n, GDT_Int16, 0, 0) != CE_None)
			die(path, CPLGetLastErrorMsg());
	}
	free(buf);
	GDALClose(ds);
}

int main(void)
{
	const char *sc = getenv("CLIPMAP_BENCH_SCALE");
	int full = sc && strcmp(sc, "1") == 0;
	int w = full ? 43200 : 10800, h = w / 2;
	char src[64], dst[64], err[256];
	snprintf(src, sizeof src, "/tmp/bench_import_src_%d.tif", (int)getpid());
	snprintf(dst, sizeof dst, "/tmp/bench_import_out_%d.tif", (int)getpid());

	double t0 = clock_now_s();
	fflush(stdout);
	pid_t pid = fork();
	if (pid < 0)
		die("fork", strerror(errno));
	if (pid == 0) {
		make_source(src, w, h);
		_exit(0);
	}
	int status;
	if (waitpid(pid, &status, 0) != pid || !WIFEXITED(status) || WEXITSTATUS(status))
		die("source", "generator failed");
	double tgen = clock_now_s() - t0;
	struct stat st;
	stat(src, &st);
	printf("import/source %dx%d int16 striped GeoTIFF: %.0f MB written in %.1f s%s\n", w, h,
	       st.st_size / 1e6, tgen, full ? "" : " (CLIPMAP_BENCH_SCALE=1: 43200x21600)");

	struct import_result r;
	int fds[2];
	if (pipe(fds))
		die("pipe", strerror(errno));
	t0 = clock_now_s();
	pid = fork();
	if (pid < 0)
		die("fork", strerror(errno));
	if (pid == 0) {
		close(fds[0]);
		if (import_raster(src, dst, NULL, &r, err))
			die("import", err);
		if (write(fds[1], &r, sizeof r) != (ssize_t)sizeof r)
			_exit(1);
		_exit(0);
	}
	close(fds[1]);
	ssize_t got = read(fds[0], &r, sizeof r);
	close(fds[0]);
	struct rusage ru;
	if (wait4(pid, &status, 0, &ru) != pid || !WIFEXITED(status) || WEXITSTATUS(status) ||
	    got != (ssize_t)sizeof r)
		die("import", "child failed");
	double timp = clock_now_s() - t0;
	stat(dst, &st);
	printf("import/%dx%d: %.1f s (GDAL read %.1f s, tiled mipmapped write %.1f s), %.1f Mpx/s, "
	       "output %.0f MB, import peak RSS %.0f MB (ru_maxrss of the import child)\n", w, h,
	       timp, r.read_s, r.write_s, (double)w * h / timp / 1e6, st.st_size / 1e6,
	       ru.ru_maxrss / 1024.0);
	unlink(src);

	static struct planet pl = { .tile_size = 256, .max_level = 12, .a = 6378137.0 };
	char text[256];
	snprintf(text, sizeof text, "[node x]\ntype = file\npath = %s\ncache_mb = 256\n", dst);
	struct ini_file *ini;
	if (ini_parse("bench.ini", text, strlen(text), &ini, err))
		die("ini", err);
	ini_find(&ini->sections[0], "type")->used = true;
	struct node n = { .name = "x", .planet = &pl };
	if (node_init(&n, &node_type_file, "bench.ini", &ini->sections[0], err))
		die("node", err);
	struct gen_ctx g = { 0 };
	/* The level whose texels match the pixels: 2^(ly+1)·256 ≈ w. */
	int fine = 0;
	while ((256u << (fine + 1)) < (unsigned)w)
		fine++;
	double rss0 = rss_mb();

	/* Random: levels 0..fine, uniform, xorshift. */
	uint64_t s = 0x9e3779b97f4a7c15ULL;
	int N = full ? 3000 : 2000;
	t0 = clock_now_s();
	for (int i = 0; i < N; i++) {
		s ^= s << 13, s ^= s >> 7, s ^= s << 17;
		int ly = (int)(s % (uint64_t)(fine + 1));
		struct tile_key k = { .lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly };
		k.x = (uint32_t)((s >> 8) % (1u << (ly + 1)));
		k.y = (uint32_t)((s >> 32) % (1u << ly));
		k.node = n.hash;
		struct tile *t = tile_create(&k, PIX_HEIGHT, 256);
		if (n.type->generate(&n, &g, &k, NULL, 0, t))
			die("generate", "random tile failed");
		tile_unref(t);
	}
	double trand = clock_now_s() - t0;
	printf("import/serve random (levels 0..%d): %.0f tiles/s (%.2f ms/tile), RSS %.0f MB "
	       "(%.0f before)\n", fine, N / trand, trand / N * 1e3, rss_mb(), rss0);

	/* Flight: the 2×2 quad at the finest level moving east by half a tile per step. */
	t0 = clock_now_s();
	int steps = N / 2, made = 0;
	uint32_t y = (1u << fine) / 3;
	for (int i = 0; i < steps; i++) {
		for (int q = 0; q < 2; q++) {
			struct tile_key k = { .lx = (uint8_t)(fine + 1), .ly = (uint8_t)fine,
					      .x = (uint32_t)(i / 2 + q) % (2u << fine),
					      .y = y + (uint32_t)(i & 1), .node = n.hash };
			struct tile *t = tile_create(&k, PIX_HEIGHT, 256);
			if (n.type->generate(&n, &g, &k, NULL, 0, t))
				die("generate", "flight tile failed");
			tile_unref(t);
			made++;
		}
	}
	double tfl = clock_now_s() - t0;
	printf("import/serve flight (level %d, adjacent): %.0f tiles/s (%.2f ms/tile), RSS %.0f MB, "
	       "serve peak RSS %.0f MB (ru_maxrss of this process)\n", fine, made / tfl, tfl / made * 1e3, rss_mb(), peak_mb());
	gen_ctx_fini(&g);
	node_fini(&n);
	ini_free(ini);
	unlink(dst);
	return 0;
}
