/* bench_noise — figures for the noise synthesis: ns per sample per octave for each ISA path
 * (8-octave fBm and ridged, T = 256 and 512, one core, best of several tiles), and tiles per
 * second of the `noise` node with 1 and 2 plain threads generating distinct tiles, and ms per
 * tile of procedural.ini's three noise nodes at levels 12 and 18.
 * Runs in well under 30 s.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "common/clock.h"
#include "common/ini.h"
#include "common/xalloc.h"
#include "common/xthread.h"
#include "engine/node.h"
#include "engine/node_types.h"
#include "engine/nodes/noise.h"
#include "engine/planet.h"
#include "engine/tile.h"

/* A level fine enough that all 8 octaves of the default parameters are evaluated. */
static struct tile_key bench_key(int i)
{
	return (struct tile_key){ .lx = 13, .ly = 12, .x = 2000u + (uint32_t)i % 4096u,
				  .y = 1500 };
}

/* The kernel itself: every octave evaluated at every texel (exact, no coarse lattice), so
 * ns/sample/octave is the SIMD simplex cost the target is about. */
static void bench_isa(enum noise_kind kind, enum noise_isa isa, uint32_t T)
{
	struct noise nz;
	struct noise_params p = { .seed = 1, .kind = kind, .octaves = 8, .wavelength = 4e6,
				  .lacunarity = 2, .gain = 0.5, .ridge_offset = 1, .ridge_gain = 2,
				  .radius = 6378137.0, .exact = true };
	if (noise_init(&nz, &p)) {
		printf("noise %s: noise_init failed\n", noise_isa_name(isa));
		return;
	}
	void *scratch = xaligned_alloc(64, noise_scratch_size(T));
	float *out = xaligned_alloc(64, (size_t)T * T * sizeof *out);
	double best = 1e30, budget = isa == NOISE_ISA_SCALAR ? 0.4 : 0.3, t0 = clock_now_s();
	int oct = 0;
	for (int i = 0; i < 200 && (i < 3 || clock_now_s() - t0 < budget); i++) {
		struct tile_key k = bench_key(i);
		double a = clock_now_s();
		oct = noise_tile(&nz, &k, T, isa, scratch, out);
		double dt = clock_now_s() - a;
		if (oct < 0) {
			printf("noise %s: %s\n", noise_isa_name(isa), strerror(-oct));
			goto out;
		}
		if (dt < best)
			best = dt;
	}
	printf("noise %s %s T=%u (every octave at every texel): %.2f ns/sample/octave, "
	       "%.2f ms/tile (%d oct)\n",
	       kind == NOISE_FBM ? "fbm" : "ridged", noise_isa_name(isa), T,
	       best * 1e9 / ((double)T * T * oct), best * 1e3, oct);
out:
	free(scratch);
	free(out);
}

/* procedural.ini's continents (fBm, 9 octaves from 9000 km) and ranges (ridged, 14 octaves
 * from 700 km) at a fine level: most octaves are far longer than the tile's texels. */
static void bench_planet(const char *name, enum noise_kind kind, int octaves, double wavelength,
			 double gain, int ly, uint32_t T)
{
	struct noise nz;
	struct noise_params p = { .seed = 7, .kind = kind, .octaves = octaves,
				  .wavelength = wavelength, .lacunarity = 2, .gain = gain,
				  .ridge_offset = 1, .ridge_gain = 2, .radius = 6378137.0 };
	if (noise_init(&nz, &p)) {
		printf("noise %s: noise_init failed\n", name);
		return;
	}
	void *scratch = xaligned_alloc(64, noise_scratch_size(T));
	float *out = xaligned_alloc(64, (size_t)T * T * sizeof *out);
	double best = 1e30, t0 = clock_now_s();
	int oct = 0;
	/* Tiles near lat -68, lon -9. */
	uint32_t x0 = (uint32_t)((180.0 - 9.0) / 360.0 * (double)(1u << (ly + 1)));
	uint32_t y0 = (uint32_t)((90.0 + 68.0) / 180.0 * (double)(1u << ly));
	for (int i = 0; i < 200 && (i < 3 || clock_now_s() - t0 < 0.3); i++) {
		struct tile_key k = { .lx = (uint8_t)(ly + 1), .ly = (uint8_t)ly,
				      .x = x0 + (uint32_t)i, .y = y0 };
		double a = clock_now_s();
		oct = noise_tile(&nz, &k, T, NOISE_ISA_AUTO, scratch, out);
		double dt = clock_now_s() - a;
		if (oct < 0) {
			printf("noise %s: %s\n", name, strerror(-oct));
			break;
		}
		if (dt < best)
			best = dt;
	}
	if (oct >= 0)
		printf("noise %s ly %d T=%u %s: %.3f ms/tile (%d oct)\n", name, ly, T,
		       noise_isa_name(noise_isa_best()), best * 1e3, oct);
	free(scratch);
	free(out);
}

struct worker {
	const struct node *n;
	uint32_t T;
	int id, nthreads;
	double seconds;
	long tiles;
	int rc;
};

static void *run_worker(void *arg)
{
	struct worker *w = arg;
	struct gen_ctx g = { .worker = w->id };
	double t0 = clock_now_s();
	for (int i = w->id; clock_now_s() - t0 < w->seconds; i += w->nthreads) {
		struct tile_key k = bench_key(i);
		k.node = w->n->hash;
		struct tile *t = tile_create(&k, PIX_HEIGHT, w->T);
		int rc = w->n->type->generate(w->n, &g, &k, NULL, 0, t);
		tile_unref(t);
		if (rc) {
			w->rc = rc;
			break;
		}
		w->tiles++;
	}
	gen_ctx_fini(&g);
	return NULL;
}

static void bench_node(uint32_t T, int nthreads)
{
	static const char conf[] = "[node n]\ntype = noise\nseed = 7\noctaves = 8\n";
	struct ini_file *ini = NULL;
	char err[256];
	struct planet pl = { .a = 6378137.0, .f = 0, .tile_size = T, .max_level = 20 };
	struct node n = { .name = "n", .planet = &pl };
	if (ini_parse("bench.ini", conf, sizeof conf - 1, &ini, err) == 0)
		ini_find(&ini->sections[0], "type")->used = true;
	if (!ini || node_init(&n, &node_type_noise, "bench.ini", &ini->sections[0], err)) {
		printf("noise node: %s\n", err);
		ini_free(ini);
		return;
	}
	struct worker w[2];
	pthread_t th[2];
	double seconds = 1.0, t0 = clock_now_s();
	int started = 0, rc = 0;
	for (int i = 0; i < nthreads; i++) {
		w[i] = (struct worker){ .n = &n, .T = T, .id = i, .nthreads = nthreads,
					.seconds = seconds };
		rc = xthread_create(&th[i], run_worker, &w[i]);
		if (rc) {
			printf("noise node: pthread_create: %s\n", strerror(-rc));
			break;
		}
		started++;
	}
	long tiles = 0;
	for (int i = 0; i < started; i++) {
		xthread_join(th[i]);
		tiles += w[i].tiles;
		if (w[i].rc)
			printf("noise node: generate: %s\n", strerror(-w[i].rc));
	}
	double dt = clock_now_s() - t0;
	if (!rc)
		printf("noise node fbm8 T=%u %d thread%s: %.1f tiles/s (%s)\n", T, nthreads,
		       nthreads > 1 ? "s" : "", tiles / dt, noise_isa_name(noise_isa_best()));
	node_fini(&n);
	ini_free(ini);
}

int main(void)
{
	static const enum noise_isa isas[] = { NOISE_ISA_SCALAR, NOISE_ISA_AVX2, NOISE_ISA_AVX512 };
	static const uint32_t sizes[] = { 256, 512 };
	for (int s = 0; s < 2; s++)
		for (int kind = 0; kind < 2; kind++)
			for (int i = 0; i < 3; i++) {
				if (!noise_isa_supported(isas[i])) {
					printf("noise %s: skipped (CPU lacks it)\n",
					       noise_isa_name(isas[i]));
					continue;
				}
				bench_isa(kind ? NOISE_RIDGED : NOISE_FBM, isas[i], sizes[s]);
			}
	for (int s = 0; s < 2; s++)
		for (int t = 1; t <= 2; t++)
			bench_node(sizes[s], t);
	for (int ly = 12; ly <= 18; ly += 6) {
		bench_planet("continents fbm9 9000km", NOISE_FBM, 9, 9e6, 0.45, ly, 256);
		bench_planet("ranges ridged14 700km", NOISE_RIDGED, 14, 7e5, 0.56, ly, 256);
		bench_planet("terrain fbm20 40km", NOISE_FBM, 20, 4e4, 0.53, ly, 256);
	}
	return 0;
}
