/* clipmapview's derived normals (view_desc.normals, --normals derive): the viewer makes the
 * shading's normals from its heights as they are uploaded instead of fetching the normal
 * layer. In-process on Mesa llvmpipe, over a planet written here (ridged relief on WGS84, a
 * `normal` node of it as the normal layer, no colour: grey, so the pixels are the shading
 * alone), every frame complete at 320×180:
 *  - derived and fetched pictures agree: at the equator from 20 km, at 60°N from 3 km and
 *    looking down on the north pole from 2 km, the mean luminance difference is at most 0.3
 *    levels and under a twentieth of what flat shading (no normals) differs by, and 99.9 %
 *    of pixels are within 3 levels (measured: 0.00 and 0.0);
 *  - the normal slices hold the node's bytes: at least 97 % of their texels equal the
 *    fetched ones (the rest: each window's outermost texels, whose stencils are cut to the
 *    window);
 *  - deriving asks for no normal tile: half the tiles fetching takes (heights only, not
 *    heights and normals);
 *  - by default (auto) the viewer derives where the planet says its normal layer is the
 *    plain `normal` of its heights (as many tiles as deriving), fetches where that layer is
 *    exaggerated (as many as fetching; a steeper picture), and shades a planet without a
 *    normal layer (derived): not flat.
 * VIEW_NORMALS_PNG=DIR writes the frames; VIEW_NORMALS_VERBOSE=1 prints the figures.
 * Skipped with a message without GL.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "client/view/view_clipmap.h"
#include "client/view/view_source_local.h"
#include "common/img.h"
#include "support/slow.h"

#define FW 320
#define FH 180

static const char planet_text[] =
	"[planet]\nbody = wgs84\ntile_size = 64\nmax_level = 20\natmosphere = none\n"
	"[node relief]\ntype = noise\nkind = ridged\nseed = 7\noctaves = 16\nwavelength = 60000\n"
	"gain = 0.55\namplitude = 3000\n"
	"[node normals]\ntype = normal\ninput = relief\n"
	"[layer height]\nnode = relief\n";
static const char normal_layer[] = "[layer normal]\nnode = normals\n";

struct shot {
	double lat, lon, alt, heading, pitch;
	const char *name;
};

static const struct shot shots[] = {
	{ 0.5, 10, 20e3, 30, -35, "equator-20km" },
	{ 60, -40, 3e3, 200, -30, "60n-3km" },
	{ 90, 0, 2e3, 0, -90, "north-pole-2km" },
};

static char dir[64];

static void write_planet(const char *name, bool with_normals, bool exaggerated)
{
	char path[128];
	snprintf(path, sizeof path, "%s/%s.ini", dir, name);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	fputs(planet_text, f);
	if (exaggerated) /* not the plain normal of the heights: a viewer must fetch it */
		fputs("[node steep]\ntype = normal\ninput = relief\nexaggeration = 2\n"
		      "[layer normal]\nnode = steep\n", f);
	else if (with_normals)
		fputs(normal_layer, f);
	assert_int_equal(fclose(f), 0);
}

struct run {
	unsigned char px[3][FW * FH * 4];
	uint64_t tiles;
	bool normal_texture;
	uint8_t *normals; /* the normal slices after the last shot (RG8), or NULL */
	size_t nsize;
};

/* Renders every shot of planet `name` with normals `mode` into r. */
static void render(struct gl_context *gl, const char *name, enum view_normals mode, struct run *r)
{
	char path[128], err[256];
	snprintf(path, sizeof path, "%s/%s.ini", dir, name);
	struct view_source *src = NULL;
	struct view_source_local_opts so = { .workers = 2, .cache_mb = 128 };
	if (view_source_local_create(path, &so, &src, err) < 0)
		fail_msg("%s: %s", path, err);
	struct view_desc d = { .width = FW, .height = FH, .no_prefetch = true, .normals = mode };
	struct view *v = NULL;
	if (view_create(gl_context_api(gl), src, &d, &v, err) < 0)
		fail_msg("view_create: %s", err);
	for (size_t i = 0; i < sizeof shots / sizeof *shots; i++) {
		const struct shot *s = &shots[i];
		struct view_camera cam = { .lat = s->lat, .lon = s->lon, .alt = s->alt,
					   .heading = s->heading, .pitch = s->pitch, .width = FW,
					   .height = FH };
		struct view_frame_stats st;
		int rc = view_frame_complete(v, &cam, test_slow(120), &st, NULL);
		if (rc < 0 || !st.complete)
			fail_msg("%s %s: frame not complete (%d)", name, s->name, rc);
		view_read_rgba(v, r->px[i]);
		const char *png = getenv("VIEW_NORMALS_PNG");
		if (png) {
			char out[256];
			const char *m = mode == VIEW_NORMALS_DERIVE ? "derive"
					: mode == VIEW_NORMALS_FETCH ? "fetch" : "auto";
			snprintf(out, sizeof out, "%s/%s-%s-%s.png", png, name, s->name, m);
			if (img_write(out, FW, FH, 4, IMG_U8, r->px[i], err) < 0)
				fprintf(stderr, "%s\n", err);
		}
	}
	struct view_clipmap_stats cs;
	view_clipmap_get_stats(view_get_clipmap(v), &cs);
	r->tiles = cs.tiles_received;
	struct view_clipmap *cm = view_get_clipmap(v);
	r->normal_texture = view_clipmap_texture(cm, VIEW_NORMAL) != 0;
	r->normals = NULL;
	if (r->normal_texture) {
		uint32_t S = view_clipmap_window_size(cm);
		r->nsize = (size_t)S * S * (size_t)view_clipmap_levels(cm) * 2;
		r->normals = malloc(r->nsize);
		assert_non_null(r->normals);
		assert_int_equal(view_clipmap_read(cm, VIEW_NORMAL, r->normals, r->nsize), 0);
	}
	view_destroy(v);
	src->ops->destroy(src);
}

/* Mean |luminance difference| over the frame, in 8-bit levels. */
static double mean_diff(const unsigned char *a, const unsigned char *b)
{
	double s = 0;
	for (size_t p = 0; p < (size_t)FW * FH; p++) {
		const unsigned char *x = a + 4 * p, *y = b + 4 * p;
		s += fabs(0.3 * (x[0] - y[0]) + 0.59 * (x[1] - y[1]) + 0.11 * (x[2] - y[2]));
	}
	return s / ((double)FW * FH);
}

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

/* The q-quantile of the per-pixel |luminance difference| over the frame, in 8-bit levels. */
static double pixel_diff(const unsigned char *a, const unsigned char *b, double q)
{
	static double d[FW * FH];
	for (size_t p = 0; p < (size_t)FW * FH; p++) {
		const unsigned char *u = a + 4 * p, *v = b + 4 * p;
		d[p] = fabs(0.3 * (u[0] - v[0]) + 0.59 * (u[1] - v[1]) + 0.11 * (u[2] - v[2]));
	}
	qsort(d, (size_t)FW * FH, sizeof *d, cmp_double);
	return d[(size_t)(q * (double)(FW * FH - 1))];
}

/* Standard deviation of the luminance: how much the shading varies. */
static double lum_sd(const unsigned char *a)
{
	double s = 0, s2 = 0, n = (double)FW * FH;
	for (size_t p = 0; p < (size_t)FW * FH; p++) {
		const unsigned char *x = a + 4 * p;
		double l = 0.3 * x[0] + 0.59 * x[1] + 0.11 * x[2];
		s += l;
		s2 += l * l;
	}
	return sqrt(fmax(0, s2 / n - (s / n) * (s / n)));
}

static void derived_like_fetched(void **state)
{
	(void)state;
	struct gl_context *gl = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &gl, err) < 0) {
		fprintf(stderr, "test_view_normals: no GL context: %s — skipped\n", err);
		skip();
	}
	bool verbose = getenv("VIEW_NORMALS_VERBOSE") != NULL;
	snprintf(dir, sizeof dir, "/tmp/test_view_normals.XXXXXX");
	assert_non_null(mkdtemp(dir));
	write_planet("with", true, false);
	write_planet("without", false, false);
	write_planet("steep", true, true);
	struct run *fetch = malloc(sizeof *fetch), *derive = malloc(sizeof *derive),
		   *flat = malloc(sizeof *flat), *autod = malloc(sizeof *autod),
		   *autow = malloc(sizeof *autow), *autos = malloc(sizeof *autos);
	assert_true(fetch && derive && flat && autod && autow && autos);
	render(gl, "with", VIEW_NORMALS_FETCH, fetch);
	render(gl, "with", VIEW_NORMALS_DERIVE, derive);
	render(gl, "without", VIEW_NORMALS_FETCH, flat);
	render(gl, "without", VIEW_NORMALS_AUTO, autod);
	render(gl, "with", VIEW_NORMALS_AUTO, autow);	/* the plain normal: derived */
	render(gl, "steep", VIEW_NORMALS_AUTO, autos); /* exaggerated: fetched */
	if (verbose)
		printf("auto: %llu tiles with a plain normal layer, %llu with an exaggerated one\n",
		       (unsigned long long)autow->tiles, (unsigned long long)autos->tiles);
	assert_true(autow->tiles == derive->tiles);
	assert_true(autos->tiles == fetch->tiles);
	/* the exaggerated normals are steeper: not what deriving would draw */
	assert_true(mean_diff(autos->px[0], derive->px[0]) > 1);
	for (size_t i = 0; i < sizeof shots / sizeof *shots; i++) {
		double d = mean_diff(fetch->px[i], derive->px[i]);
		double f = mean_diff(fetch->px[i], flat->px[i]);
		double da = mean_diff(autod->px[i], derive->px[i]);
		double dm = pixel_diff(fetch->px[i], derive->px[i], 0.999);
		if (verbose)
			printf("%s: derived vs fetched %.2f levels (99.9 %% of pixels within %.1f), "
			       "flat vs fetched %.2f, auto (no normal layer) vs derived %.2f; luminance "
			       "sd fetched %.1f, derived %.1f, flat %.1f\n",
			       shots[i].name, d, dm, f, da, lum_sd(fetch->px[i]),
			       lum_sd(derive->px[i]), lum_sd(flat->px[i]));
		/* Nearly every pixel close (what differs most: the creases of the ridges, where
		 * blending slopes and blending 8-bit normals part). */
		if (dm > 3)
			fail_msg("%s: 99.9 %% of pixels within %.1f levels", shots[i].name, dm);
		if (!(d <= 0.3 && d < 0.05 * f))
			fail_msg("%s: derived normals differ from fetched by %.2f levels (flat: %.2f)",
				 shots[i].name, d, f);
		/* without a normal layer, auto derives: the same picture as deriving */
		assert_true(da <= 0.5);
		assert_true(mean_diff(autod->px[i], flat->px[i]) > 4); /* shaded, not flat */
	}
	if (verbose)
		printf("tiles: fetched %llu, derived %llu\n", (unsigned long long)fetch->tiles,
		       (unsigned long long)derive->tiles);
	/* the normal slices made here hold the node's bytes but for the windows' outermost
	 * texels (their stencils cut to the window) */
	assert_true(fetch->normal_texture && derive->normal_texture && autod->normal_texture);
	assert_true(fetch->nsize == derive->nsize);
	size_t same = 0;
	for (size_t b = 0; b < fetch->nsize; b += 2)
		same += fetch->normals[b] == derive->normals[b] &&
			fetch->normals[b + 1] == derive->normals[b + 1];
	double share = (double)same / (double)(fetch->nsize / 2);
	if (verbose)
		printf("normal texels identical to the fetched ones: %.3f %%\n", 100 * share);
	assert_true(share >= 0.97);
	/* the same heights, and no normal tile */
	assert_true(derive->tiles * 2 <= fetch->tiles + 8 && derive->tiles * 2 + 8 >= fetch->tiles);
	struct run *runs[] = { fetch, derive, flat, autod, autow, autos };
	for (size_t i = 0; i < sizeof runs / sizeof *runs; i++) {
		free(runs[i]->normals);
		free(runs[i]);
	}
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
	if (system(cmd) != 0)
		fprintf(stderr, "could not remove %s\n", dir);
	gl_context_destroy(gl);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(derived_like_fetched),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
