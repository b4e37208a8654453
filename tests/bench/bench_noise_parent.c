/* bench_noise_parent — per-level generation time of each noise node of the procedural planet,
 * evaluated directly and built from its parent level (`from_parent = true` on the
 * fBm nodes: the carry tile — upsample plus one band — and the node's tile from it), measured
 * in the same run, alternating, best of several, one thread, tiles at 46°N (isotropic levels)
 * and at 80°N (anisotropic). Ridged nodes are evaluated directly either way (noise.h says why)
 * and show their direct time only. The ratio is the figure: absolute times depend on the
 * machine and its load. Last, why ridged nodes stay direct: the error of carrying a ridged
 * octave through the carry's upsample, creased before or after it (ridge_carry_error).
 * Runs from the repository root in about a minute.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "common/clipmap.h"
#include "common/clock.h"
#include "engine/cache.h"
#include "engine/node.h"
#include "engine/nodes/noise.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "support/planet_variant.h"

#define PLANET "conf/planets/procedural.ini"
#define RUNS 5

static char planet_fp[64], planet_direct[64]; /* from_parent, direct (planet_variant.h) */

static int write_planets(void)
{
	return planet_variant_write(PLANET, "bench_noise_parent", planet_fp, planet_direct,
				    sizeof planet_fp);
}

static struct tile_key at(int lx, int ly, double lon, double lat, uint32_t T, uint64_t node)
{
	double u = grid_lon_to_u(lx, T, lon), v = grid_lat_to_v(ly, T, lat);
	int64_t y = (int64_t)floor(v / T);
	y = y < 0 ? 0 : y >= (int64_t)grid_tiles_y(ly) ? grid_tiles_y(ly) - 1 : y;
	return (struct tile_key){ .node = node, .x = grid_wrap_x(lx, (int64_t)floor(u / T)),
				  .y = (uint32_t)y, .lx = (uint8_t)lx, .ly = (uint8_t)ly };
}

static struct tile *fetch(struct sched *s, struct node *n, struct tile_key k)
{
	k.node = n->hash;
	struct want w = { .node = n, .cls = SCHED_VISIBLE, .key = k };
	struct tile *t = NULL;
	if (sched_fetch(s, &w, 1, &t) || !t) {
		fprintf(stderr, "fetch %s failed\n", n->name);
		exit(1);
	}
	return t;
}

static double cpu_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
	return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* Seconds for one generate of n at k from the tiles in[]. */
static double time_gen(struct node *n, struct gen_ctx *g, struct tile_key k, struct tile **in,
		       int nin, uint32_t T)
{
	k.node = n->hash;
	struct tile *out = tile_create(&k, n->out, T);
	double a = clock_now_s();
	int rc = n->type->generate(n, g, &k, in, nin, out);
	double dt = clock_now_s() - a;
	tile_unref(out);
	if (rc) {
		fprintf(stderr, "generate %s: %d\n", n->name, rc);
		exit(1);
	}
	return dt;
}

/* One ridged octave's signal (1 − |n|)², n raw simplex noise (noise_simplex_ref, wavelength
 * 1), sampled along lines at spw samples per wavelength and upsampled at t = ¼ and ¾ with the
 * carry's kernel (noise_carry_kernel), against the exact signal there: as a ridged carry would
 * be made (the creased signal upsampled), and as it would have to be made to keep its crests
 * (each octave's raw value upsampled, creased after). Errors are fractions of the octave's
 * amplitude; the ridges are where |n| is near 0. */
static double ridge_signal(double n)
{
	double s = 1 - fabs(n);
	return s * s;
}

static void ridge_carry_error(void)
{
	printf("a ridged octave carried through the upsample (noise.h): error / its amplitude, "
	       "400 random lines\n");
	float w[2][6];
	noise_carry_kernel(0.25, w[0]);
	noise_carry_kernel(0.75, w[1]);
	for (int spw = 4; spw <= 64; spw *= 2) {
		double h = 1.0 / spw, maxc = 0, sumc = 0, maxr = 0, sumr = 0;
		long n = 0;
		int N = 40 * spw;
		double *raw = malloc(sizeof *raw * (size_t)N);
		unsigned rs = 1;
		for (int line = 0; raw && line < 400; line++) {
			double o[3], d[3], l = 0;
			for (int a = 0; a < 3; a++)
				o[a] = rand_r(&rs) / (double)RAND_MAX * 100;
			for (int a = 0; a < 3; a++) {
				d[a] = rand_r(&rs) / (double)RAND_MAX - 0.5;
				l += d[a] * d[a];
			}
			for (int a = 0; a < 3; a++)
				d[a] /= sqrt(l);
			for (int i = 0; i < N; i++)
				raw[i] = noise_simplex_ref(o[0] + d[0] * i * h, o[1] + d[1] * i * h,
							   o[2] + d[2] * i * h, 7);
			for (int p = 2; p + 3 < N; p++)
				for (int q = 0; q < 2; q++) {
					double x = (p + (q ? 0.75 : 0.25)) * h;
					double ex = ridge_signal(noise_simplex_ref(
						o[0] + d[0] * x, o[1] + d[1] * x, o[2] + d[2] * x, 7));
					double cs = 0, cr = 0;
					for (int k = 0; k < 6; k++) {
						cs += w[q][k] * ridge_signal(raw[p - 2 + k]);
						cr += w[q][k] * raw[p - 2 + k];
					}
					double ec = fabs(cs - ex), er = fabs(ridge_signal(cr) - ex);
					maxc = fmax(maxc, ec);
					maxr = fmax(maxr, er);
					sumc += ec * ec;
					sumr += er * er;
					n++;
				}
		}
		free(raw);
		if (n)
			printf("  %2d samples per wavelength: creased, then upsampled: max %.4f rms %.4f; "
			       "upsampled raw, then creased: max %.5f rms %.6f\n",
			       spw, maxc, sqrt(sumc / (double)n), maxr, sqrt(sumr / (double)n));
	}
}

int main(void)
{
	char err[256];
	struct planet *pd, *pp;
	if (write_planets()) {
		fprintf(stderr, "bench_noise_parent: cannot write the variants of %s to /tmp\n", PLANET);
		return 1;
	}
	int bad = planet_load(planet_direct, &pd, err) || planet_load(planet_fp, &pp, err);
	unlink(planet_fp);
	unlink(planet_direct);
	if (bad) {
		fprintf(stderr, "bench_noise_parent: %s\n", err);
		return 1;
	}
	const uint32_t T = pd->tile_size;
	struct cache *c = cache_create(1024u << 20);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = c, .workers = 2 });
	struct gen_ctx g = { 0 };
	static const char *const names[] = { "continents", "ranges",   "massifs", "valley_net",
					     "hill_noise", "outcrops", "grain",	  "jitter",
					     "patches" };
	static const double lats[] = { 46.1, 80.0 };
	printf("levels where a node's carry is not upsampled (noise_carry_upsampled) run the "
	       "direct path either way: ratio 1 by construction, shown as '='\n");
	printf("noise node generation, ms per %u² tile, one thread, best of %d (alternating); "
	       "from parent = its carry tile + its tile from the carry\n", T, RUNS);
	printf("%-11s %3s %4s %4s %9s %9s %9s %9s %7s\n", "node", "lat", "ly", "lx", "direct",
	       "carry", "tile", "parent", "ratio");
	double sum_d[2][23] = { { 0 } }, sum_p[2][23] = { { 0 } };
	for (size_t q = 0; q < sizeof names / sizeof *names; q++) {
		struct node *nd = planet_find_node(pd, names[q]), *np = planet_find_node(pp, names[q]);
		if (!nd || !np) {
			fprintf(stderr, "no node %s\n", names[q]);
			return 1;
		}
		for (int la = 0; la < 2; la++) {
			for (int ly = 1; ly <= 22; ly += ly < 4 ? 1 : 3) {
				int lx = clipmap_level_lx(ly, lats[la], -1);
				struct tile_key k = at(lx, ly, 7.7, lats[la], T, 0);
				/* the input, if any (its time is not counted) */
				struct tile *in[2] = { NULL, NULL };
				int nin = 0;
				if (nd->in[0])
					in[nin++] = fetch(s, nd->in[0], k);
				struct node_dep deps[NODE_MAX_DEPS];
				struct tile_key kp = k;
				kp.node = np->hash;
				int nd_p = np->type->deps(np, &kp, deps);
				bool fp = nd_p > nin;
				struct node *carry = fp ? deps[nd_p - 1].node : NULL;
				struct tile *cin[NODE_MAX_DEPS];
				int ncin = 0;
				if (fp) {
					struct node_dep cd[NODE_MAX_DEPS];
					ncin = carry->type->deps(carry, &deps[nd_p - 1].key, cd);
					for (int i = 0; i < ncin; i++)
						cin[i] = fetch(s, carry, cd[i].key);
				}
				double bd = 1e30, bc = 1e30, bt = 1e30;
				for (int r = 0; r < RUNS; r++) {
					bd = fmin(bd, time_gen(nd, &g, k, in, nin, T));
					if (!fp)
						continue;
					bc = fmin(bc, time_gen(carry, &g, deps[nd_p - 1].key, cin,
							       ncin, T));
					struct tile *ct = fetch(s, carry, deps[nd_p - 1].key);
					in[nin] = ct;
					bt = fmin(bt, time_gen(np, &g, k, in, nin + 1, T));
					in[nin] = NULL;
					tile_unref(ct);
				}
				for (int i = 0; i < ncin; i++)
					tile_unref(cin[i]);
				if (nin)
					tile_unref(in[0]);
				sum_d[la][ly] += bd;
				sum_p[la][ly] += fp ? bc + bt : bd;
				if (fp)
					printf("%-11s %3.0f %4d %4d %9.3f %9.3f %9.3f %9.3f %6.2fx\n",
					       names[q], lats[la], ly, lx, bd * 1e3, bc * 1e3, bt * 1e3,
					       (bc + bt) * 1e3, bd / (bc + bt));
				else
					printf("%-11s %3.0f %4d %4d %9.3f %9s %9s %9s %7s\n", names[q],
					       lats[la], ly, lx, bd * 1e3, "-", "-", "=",
					       np->in[0] || strcmp(names[q], "ranges") ? "=" : "-");
			}
		}
	}
	printf("all 9 noise nodes of one key (ms): direct vs from parent (fBm nodes from parent, "
	       "ridged direct)\n");
	for (int la = 0; la < 2; la++)
		for (int ly = 1; ly <= 22; ly += ly < 4 ? 1 : 3)
			printf("noise key lat %2.0f ly %2d: direct %8.3f  from parent %8.3f  %5.2fx\n",
			       lats[la], ly, sum_d[la][ly] * 1e3, sum_p[la][ly] * 1e3,
			       sum_d[la][ly] / sum_p[la][ly]);
	/* Whole keys through the scheduler, cold: the height and colour layers of 3×3 tiles
	 * around a point at every level 1..22 (what a viewer arriving there asks for, its
	 * carries and everything else included), one worker, direct and from parent
	 * alternating, best of 3 cold runs each; the process's CPU time, which a loaded machine
	 * disturbs less than the wall clock. */
	printf("whole keys, cold cache, 1 worker: height + color of 3x3 tiles at levels 1-22\n");
	for (int la = 0; la < 2; la++) {
		double best[2] = { 1e30, 1e30 };
		for (int r = 0; r < 6; r++) {
			struct planet *pl = r % 2 ? pp : pd;
			struct cache *cc = cache_create(2048u << 20);
			struct sched *ss = sched_create(&(struct sched_desc){ .cache = cc, .workers = 1 });
			const struct planet_layer *lh = planet_find_layer(pl, "height");
			const struct planet_layer *lc = planet_find_layer(pl, "color");
			double a = cpu_s();
			for (int ly = 1; ly <= 22; ly++) {
				int lx = clipmap_level_lx(ly, lats[la], -1);
				struct tile_key k0 = at(lx, ly, 7.7, lats[la], T, 0);
				struct want w[18];
				int nw = 0;
				for (int dy = -1; dy <= 1; dy++)
					for (int dx = -1; dx <= 1; dx++) {
						int64_t y = (int64_t)k0.y + dy;
						if (y < 0 || y >= (int64_t)grid_tiles_y(ly))
							continue;
						struct tile_key k = k0;
						k.x = grid_wrap_x(lx, (int64_t)k0.x + dx);
						k.y = (uint32_t)y;
						for (int q = 0; q < 2; q++) {
							const struct planet_layer *L = q ? lc : lh;
							w[nw] = (struct want){ .node = L->node,
									       .cls = SCHED_VISIBLE,
									       .key = k };
							w[nw].key.node = L->node->hash;
							nw++;
						}
					}
				struct tile *out[18];
				if (sched_fetch(ss, w, (size_t)nw, out)) {
					fprintf(stderr, "whole keys: fetch failed\n");
					return 1;
				}
				for (int i = 0; i < nw; i++)
					tile_unref(out[i]);
			}
			double dt = cpu_s() - a;
			best[r % 2] = fmin(best[r % 2], dt);
			sched_destroy(ss);
			cache_destroy(cc);
		}
		printf("whole keys lat %2.0f: direct %7.1f ms CPU  from parent %7.1f ms CPU  %5.2fx\n",
		       lats[la], best[0] * 1e3, best[1] * 1e3, best[0] / best[1]);
	}
	gen_ctx_fini(&g);
	sched_destroy(s);
	cache_destroy(c);
	planet_unref(pd);
	planet_unref(pp);
	ridge_carry_error();
	return 0;
}
