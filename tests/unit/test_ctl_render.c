/* clipmapctl's offline commands as a user runs them: real processes, real files. The pictures
 * are decoded and compared with the same tiles generated in-process; errors are checked for
 * their exit codes and for naming what is wrong. Runs from the repository root. */
#include <libgen.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/grid.h"
#include "common/img.h"
#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "support/daemon_env.h"

#define PLANET "conf/planets/procedural.ini"

struct env {
	char ctl[4096];
	char dir[64];
	struct planet *p;
	struct cache *c;
	struct sched *s;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	char bin[4000];
	if (daemon_env_bindir(bin, sizeof bin))
		return -1;
	snprintf(e->ctl, sizeof e->ctl, "%s/clipmapctl", bin);
	snprintf(e->dir, sizeof e->dir, "/tmp/clipmap-ctl-XXXXXX");
	if (!mkdtemp(e->dir))
		return -1;
	char err[256];
	if (planet_load(PLANET, &e->p, err))
		return -1;
	e->c = cache_create(256u << 20);
	e->s = sched_create(&(struct sched_desc){ .cache = e->c, .workers = 2 });
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	char cmd[256];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", e->dir);
	if (system(cmd) != 0)
		fprintf(stderr, "could not remove %s\n", e->dir);
	sched_destroy(e->s);
	cache_destroy(e->c);
	planet_unref(e->p);
	free(e);
	return 0;
}

/* Runs clipmapctl with args; returns its exit status and its output (stdout+stderr). */
static int run(struct env *e, char *out, size_t cap, const char *fmt, ...)
{
	char args[2048], cmd[8192];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(args, sizeof args, fmt, ap);
	va_end(ap);
	snprintf(cmd, sizeof cmd, "'%s' %s 2>&1", e->ctl, args);
	FILE *f = popen(cmd, "r");
	assert_non_null(f);
	size_t n = fread(out, 1, cap - 1, f);
	out[n] = '\0';
	int st = pclose(f);
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128;
}

static struct tile *fetch(struct env *e, const char *layer, int lx, int ly, uint32_t x, uint32_t y)
{
	const struct planet_layer *L = planet_find_layer(e->p, layer);
	assert_non_null(L);
	struct want w = { .node = L->node, .cls = SCHED_VISIBLE,
			  .key = { .node = L->node->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly,
				   .x = x, .y = y } };
	struct tile *t = NULL;
	assert_int_equal(sched_fetch(e->s, &w, 1, &t), 0);
	return t;
}

static void colour_tile_png(void **state)
{
	struct env *e = *state;
	char out[4096], path[256], err[256];
	snprintf(path, sizeof path, "%s/c.png", e->dir);
	assert_int_equal(run(e, out, sizeof out, "render %s color 6 5 17 9 -o %s", PLANET, path), 0);
	assert_non_null(strstr(out, "wrote"));
	void *px;
	struct img_info info;
	assert_int_equal(img_read(path, IMG_U8, &px, &info, err), 0);
	assert_int_equal(info.width, 256);
	assert_int_equal(info.channels, 4);
	struct tile *t = fetch(e, "color", 6, 5, 17, 9);
	assert_memory_equal(px, t->data, t->nbytes);
	tile_unref(t);
	free(px);
}

static void height_tile_tiff_and_png16(void **state)
{
	struct env *e = *state;
	char out[4096], path[256], err[256];
	struct tile *t = fetch(e, "height", 10, 9, 300, 200);
	snprintf(path, sizeof path, "%s/h.tif", e->dir);
	assert_int_equal(run(e, out, sizeof out, "render %s height 10 9 300 200 -o %s", PLANET,
			     path), 0);
	void *px;
	struct img_info info;
	assert_int_equal(img_read(path, IMG_F32, &px, &info, err), 0);
	assert_int_equal(info.channels, 1);
	assert_memory_equal(px, t->data, t->nbytes);
	free(px);
	/* 16-bit PNG: the printed scale turns values back into metres within one step */
	snprintf(path, sizeof path, "%s/h.png", e->dir);
	assert_int_equal(run(e, out, sizeof out, "render %s height 10 9 300 200 -o %s", PLANET,
			     path), 0);
	double lo, scale;
	const char *note = strstr(out, "metres = ");
	assert_non_null(note);
	assert_int_equal(sscanf(note, "metres = %lf + value * %lf", &lo, &scale), 2);
	assert_int_equal(img_read(path, IMG_U16, &px, &info, err), 0);
	const uint16_t *q = px;
	const float *h = tile_f32(t);
	for (size_t i = 0; i < (size_t)t->size * t->size; i++)
		assert_true(fabs(lo + q[i] * scale - h[i]) <= scale * 0.51 + 1e-3);
	free(px);
	tile_unref(t);
}

static void whole_level_assembles_tiles(void **state)
{
	struct env *e = *state;
	char out[4096], path[256], err[256];
	snprintf(path, sizeof path, "%s/w.png", e->dir);
	assert_int_equal(run(e, out, sizeof out, "render %s normal --level 1 --world -q -o %s",
			     PLANET, path), 0);
	void *px;
	struct img_info info;
	assert_int_equal(img_read(path, IMG_U8, &px, &info, err), 0);
	assert_int_equal(info.width, 4 * 256);
	assert_int_equal(info.height, 2 * 256);
	assert_int_equal(info.channels, 3);
	/* tile (3, 1) sits at the bottom right; its RG bytes match the normal tile */
	struct tile *t = fetch(e, "normal", 2, 1, 3, 1);
	const unsigned char *img = px;
	for (uint32_t j = 0; j < 256; j += 17)
		for (uint32_t i = 0; i < 256; i += 13) {
			const unsigned char *p = img + 3 * ((size_t)(256 + j) * info.width + 768 + i);
			assert_int_equal(p[0], t->data[2 * ((size_t)j * 256 + i)]);
			assert_int_equal(p[1], t->data[2 * ((size_t)j * 256 + i) + 1]);
			assert_true(p[2] >= 128); /* the up component: the surface faces outwards */
		}
	tile_unref(t);
	free(px);
}

/* --at renders a block whose texels are about as wide as tall at the place: lx = ly + 1 at
 * the equator, coarser towards the poles (at 89.5° the level-11 columns would be 0.4 m wide
 * and 76 m tall: every feature a horizontal streak). The block's tiles are the engine's. */
static void block_at_a_place_has_square_texels(void **state)
{
	struct env *e = *state;
	static const struct {
		double lat, lon;
		int lx;
	} at[] = { { 0.5, 10, 11 }, { 46.5, 9.9, 10 }, { -70, -150, 9 }, { 89.5, 0, 4 },
		   { -89.5, 179.9, 4 }, { 90, 0, 0 } };
	for (size_t i = 0; i < sizeof at / sizeof *at; i++) {
		char out[4096], path[256], want[64], err[256];
		snprintf(path, sizeof path, "%s/at%zu.tif", e->dir, i);
		assert_int_equal(run(e, out, sizeof out, "render %s height --level 10 --at %.2f,%.2f "
				     "--tiles 2 -o %s", PLANET, at[i].lat, at[i].lon, path), 0);
		snprintf(want, sizeof want, "lx %d ly 10", at[i].lx);
		if (!strstr(out, want))
			fail_msg("--at %.2f,%.2f: expected %s in: %s", at[i].lat, at[i].lon, want, out);
		uint32_t cols = at[i].lx == 0 ? 1 : 2;
		void *px;
		struct img_info info;
		assert_int_equal(img_read(path, IMG_F32, &px, &info, err), 0);
		assert_int_equal(info.width, cols * 256);
		assert_int_equal(info.height, 2 * 256);
		/* a texel's width over its height, in metres, at the place */
		double aspect = 360.0 / ldexp(256.0, at[i].lx) * cos(at[i].lat * M_PI / 180.0) /
				(180.0 / ldexp(256.0, 10));
		if (fabs(at[i].lat) < 90)
			assert_true(aspect > 0.5 && aspect < 2.0);
		/* the block's top-left tile: the one holding the place, less (n − 1) / 2 = 0 */
		uint32_t x = (uint32_t)floor(grid_lon_to_u(at[i].lx, 1, at[i].lon));
		uint32_t y = (uint32_t)floor(grid_lat_to_v(10, 1, at[i].lat));
		if (y > (1u << 10) - 2)
			y = (1u << 10) - 2; /* clamped at the south pole */
		if (at[i].lx == 0)
			x = 0;
		struct tile *t = fetch(e, "height", at[i].lx, 10, x, y);
		for (uint32_t j = 0; j < 256; j++)
			assert_memory_equal((float *)px + (size_t)j * info.width,
					    (const float *)t->data + (size_t)j * 256, 256 * sizeof(float));
		tile_unref(t);
		free(px);
	}
}

static void graph_is_dot(void **state)
{
	struct env *e = *state;
	char out[16384];
	assert_int_equal(run(e, out, sizeof out, "graph %s", PLANET), 0);
	assert_non_null(strstr(out, "digraph"));
	for (size_t i = 0; i < e->p->nnodes; i++)
		assert_non_null(strstr(out, e->p->nodes[i]->name));
	assert_int_equal(run(e, out, sizeof out, "graph procedural"), 0); /* found by name */
}

static void errors(void **state)
{
	struct env *e = *state;
	char out[4096], path[256], bad[256];
	snprintf(path, sizeof path, "%s/x.png", e->dir);
	assert_int_equal(run(e, out, sizeof out, "render %s colour 2 1 0 0 -o %s", PLANET, path), 2);
	assert_non_null(strstr(out, "no layer \"colour\""));
	assert_non_null(strstr(out, "color")); /* lists the layers there are */
	assert_int_equal(run(e, out, sizeof out, "render %s color 9 3 0 0 -o %s", PLANET, path), 2);
	assert_non_null(strstr(out, "level (9, 3)"));
	assert_int_equal(run(e, out, sizeof out, "render %s color 2 1 4 0 -o %s", PLANET, path), 2);
	assert_non_null(strstr(out, "outside level"));
	assert_int_equal(run(e, out, sizeof out, "render nosuchplanet color 2 1 0 0 -o %s", path), 2);
	assert_non_null(strstr(out, "not found"));
	assert_int_equal(run(e, out, sizeof out, "render %s color 2 1 0 0", PLANET), 2);
	assert_non_null(strstr(out, "-o FILE"));
	assert_int_equal(run(e, out, sizeof out, "render %s color 2 1 0 0 -o %s/x.bmp", PLANET,
			     e->dir), 1);
	assert_non_null(strstr(out, "unknown picture type"));
	assert_int_equal(run(e, out, sizeof out, "render %s color 2 1 0 0 -o /nonexistent/x.png",
			     PLANET), 1);
	assert_non_null(strstr(out, "/nonexistent/x.png"));
	/* a broken planet file: the error names file:line: key */
	snprintf(bad, sizeof bad, "%s/bad.ini", e->dir);
	FILE *f = fopen(bad, "w");
	assert_non_null(f);
	fputs("[planet]\nname = bad\n[node n]\ntype = noise\noctaves = 99\n[layer h]\nnode = n\n", f);
	assert_int_equal(fclose(f), 0);
	assert_int_equal(run(e, out, sizeof out, "graph %s", bad), 2);
	assert_non_null(strstr(out, "bad.ini:5: octaves:"));
	assert_int_equal(run(e, out, sizeof out, "frobnicate"), 2);
	assert_non_null(strstr(out, "unknown command"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(colour_tile_png),
		cmocka_unit_test(height_tile_tiff_and_png16),
		cmocka_unit_test(whole_level_assembles_tiles),
		cmocka_unit_test(block_at_a_place_has_square_texels),
		cmocka_unit_test(graph_is_dot),
		cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests_name("clipmapctl offline", tests, setup, teardown);
}
