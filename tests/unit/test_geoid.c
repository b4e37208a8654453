/* The geoid node: EGM96 undulations at known places (its lowest point south of India, its
 * highest over New Guinea, the Gulf of Guinea), seamless across the antimeridian, the sign
 * switch, and clear errors for a missing or broken grid. Uses proj-data's egm96_15.gtx. */
#include <errno.h>
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define GTX "/usr/share/proj/egm96_15.gtx"

static char dir[64];

static int load(const char *node_extra, struct planet **p, char err[256])
{
	char path[128];
	snprintf(path, sizeof path, "%s/g.ini", dir);
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	fprintf(f, "[planet]\nbody = wgs84\n[node zero]\ntype = constant\nheight = 0\n"
		   "[node n]\ntype = geoid\ninput = zero\n%s[layer height]\nnode = n\n",
		node_extra);
	fclose(f);
	return planet_load(path, p, err);
}

static int setup(void **state)
{
	(void)state;
	snprintf(dir, sizeof dir, "/tmp/clipmap-geoid-XXXXXX");
	return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
	return system(cmd) == 0 ? 0 : -1;
}

/* The layer's value at the texel holding (lat, lon) at level (9, 8). */
static double at(struct sched *s, const struct planet *p, double lat, double lon)
{
	const struct planet_layer *L = planet_find_layer(p, "height");
	const int ly = 8, lx = 9;
	uint32_t T = p->tile_size;
	double u = grid_lon_to_u(lx, T, lon), v = grid_lat_to_v(ly, T, lat);
	struct want w = { .node = L->node, .cls = SCHED_VISIBLE,
			  .key = { .node = L->node->hash, .lx = lx, .ly = ly,
				   .x = (uint32_t)(u / T), .y = (uint32_t)(v / T) } };
	struct tile *t;
	assert_int_equal(sched_fetch(s, &w, 1, &t), 0);
	double h = tile_f32(t)[(size_t)((uint32_t)v % T) * T + (uint32_t)u % T];
	tile_unref(t);
	return h;
}

static void known_places(void **state)
{
	(void)state;
	if (access(GTX, R_OK)) {
		printf("skipped: %s not installed (proj-data)\n", GTX);
		return;
	}
	struct planet *p;
	char err[256];
	assert_int_equal(load("", &p, err), 0);
	struct cache *c = cache_create(64u << 20);
	struct sched *s = sched_create(&(struct sched_desc){ .cache = c, .workers = 2 });
	/* EGM96's extremes and a reference point, from the grid nodes themselves */
	assert_true(fabs(at(s, p, 4.75, 78.75) - -106.99) < 0.3);
	assert_true(fabs(at(s, p, -8.25, 147.25) - 85.39) < 0.3);
	assert_true(fabs(at(s, p, 0.0, 0.0) - 17.16) < 0.3);
	/* seamless across the antimeridian: the two edge columns agree closely */
	const struct planet_layer *L = planet_find_layer(p, "height");
	struct want w[2];
	for (int i = 0; i < 2; i++)
		w[i] = (struct want){ .node = L->node, .cls = SCHED_VISIBLE,
				      .key = { .node = L->node->hash, .lx = 6, .ly = 5,
					       .x = i ? 0 : 63, .y = 12 } };
	struct tile *t[2];
	assert_int_equal(sched_fetch(s, w, 2, t), 0);
	uint32_t T = p->tile_size;
	for (uint32_t j = 0; j < T; j++) {
		float west = tile_f32(t[0])[(size_t)j * T + T - 1], east = tile_f32(t[1])[(size_t)j * T];
		float inner = fabsf(tile_f32(t[0])[(size_t)j * T + T - 1] -
				    tile_f32(t[0])[(size_t)j * T + T - 2]);
		assert_true(fabsf(west - east) <= 2 * inner + 0.01f);
	}
	tile_unref(t[0]);
	tile_unref(t[1]);
	sched_destroy(s);
	cache_destroy(c);
	planet_unref(p);
	/* sign = -1 goes from the ellipsoid back to the geoid */
	assert_int_equal(load("sign = -1\n", &p, err), 0);
	c = cache_create(64u << 20);
	s = sched_create(&(struct sched_desc){ .cache = c, .workers = 1 });
	assert_true(fabs(at(s, p, 4.75, 78.75) - 106.99) < 0.3);
	sched_destroy(s);
	cache_destroy(c);
	planet_unref(p);
}

static void errors(void **state)
{
	(void)state;
	struct planet *p;
	char err[256], extra[256], bad[128];
	assert_int_equal(load("path = /nonexistent.gtx\n", &p, err), -EINVAL);
	if (!strstr(err, "g.ini:9: path: cannot open /nonexistent.gtx"))
		fail_msg("%s", err);
	snprintf(bad, sizeof bad, "%s/short.gtx", dir);
	FILE *f = fopen(bad, "w");
	assert_non_null(f);
	fputs("not a grid", f);
	fclose(f);
	snprintf(extra, sizeof extra, "path = %s\n", bad);
	assert_int_equal(load(extra, &p, err), -EINVAL);
	assert_non_null(strstr(err, "shorter than a GTX header"));
	assert_int_equal(load("sign = 0\n", &p, err), -EINVAL);
	assert_non_null(strstr(err, "sign"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(known_places),
		cmocka_unit_test(errors),
	};
	return cmocka_run_group_tests_name("geoid", tests, setup, teardown);
}
