/* test_view_texels — texels at screen resolution (issue 11): how many screen pixels one texel
 * of the colour layer covers, measured on the picture. A synthetic flat planet (tile size 256,
 * as the shipped ones) whose colour texels carry their own level-texel coordinates (red: u mod
 * 256, green: v mod 256, blue: 10 × the level) is drawn unlit at 1280×720 from the views a
 * flight passes through; on a grid of pixels, the texel coordinates 12 pixels right and 12 down
 * give the Jacobian J = ∂(u, v)/∂(x, y), and 1 / σ_min(J) is how far (in pixels) one texel
 * stretches on screen where it is magnified most. Pixels where neighbours show different
 * levels (ring boundaries, the blend towards the coarser level) and sky are left out; so is
 * ground where the coordinates alias (over ~10 texels a pixel, towards the horizon).
 *
 * With detail levels (colour from CLIPMAP_DETAIL levels finer than a ring's geometry, in windows
 * of 4×4 tiles) a texel covers about 2 pixels by area (the median over the picture, 1.5–2.1
 * on these views) and 3–4 along its most magnified direction, on average; with each ring's
 * own level it was 4–8 by area (median 4–7) and 8–16. Why not ≤ 1.5 px everywhere:
 * at distance d from the nadir the finest level whose window (S texels wide) reaches d has
 * texels of at least 2d/S, which a 60° view 720 pixels tall shows at 1.2 px or more near its
 * centre for S = 1024 — and levels are powers of two, so up to twice that at each level's
 * inner edge. ≤ 1.5 px everywhere needs windows of 4096 texels (16×16 tiles).
 * Needs a GL context (llvmpipe); skipped without one.
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

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "common/xalloc.h"
#include "support/slow.h"
#include "support/synth_source.h"

#define T 256
#define W 1280
#define H 720
#define STEP 12 /* pixels between the samples of a difference */

static void fill(void *ctx, const struct view_want *w, uint32_t size, enum pix_type f, void *data)
{
	(void)ctx;
	if (f != PIX_COLOR) {
		memset(data, 0, (size_t)size * size * pix_bytes(f)); /* flat, facing up */
		if (f == PIX_NORMAL)
			memset(data, 128, (size_t)size * size * 2);
		return;
	}
	unsigned char *p = data;
	for (uint32_t j = 0; j < size; j++)
		for (uint32_t i = 0; i < size; i++, p += 4) {
			uint64_t u = (uint64_t)w->key.x * size + i, v = (uint64_t)w->key.y * size + j;
			p[0] = (unsigned char)(u & 255);
			p[1] = (unsigned char)(v & 255);
			p[2] = (unsigned char)(10 * w->key.ly);
			p[3] = 255;
		}
}

/* a − b on a circle of 256 (the coordinates wrap every 256 texels) */
static double wrapdiff(int a, int b)
{
	int d = (a - b) & 255;
	return d >= 128 ? d - 256 : d;
}

struct measure {
	size_t n;	   /* ground samples measured */
	size_t over15;	   /* of which a texel covers more than 1.5 px */
	double worst, p99; /* pixels per texel */
	double mean;
	double area_mean, area_p50, area_p90; /* √(pixels per texel): its size by area */
};

static int cmp_double(const void *a, const void *b)
{
	double x = *(const double *)a, y = *(const double *)b;
	return (x > y) - (x < y);
}

static void measure(const unsigned char *px, struct measure *m)
{
	size_t cap = (size_t)(W / STEP + 1) * (H / STEP + 1), n = 0;
	double *r = xmalloc(cap * sizeof *r), *ra = xmalloc(cap * sizeof *ra);
	for (int y = 0; y + STEP < H; y += STEP)
		for (int x = 0; x + STEP < W; x += STEP) {
			const unsigned char *a = px + ((size_t)y * W + x) * 4;
			const unsigned char *bx = a + STEP * 4, *by = a + (size_t)STEP * W * 4;
			/* the same level at all three (blue: 10 × level exactly) */
			if (a[2] % 10 || a[2] != bx[2] || a[2] != by[2] || a[3] != 255)
				continue;
			double dudx = wrapdiff(bx[0], a[0]) / STEP, dvdx = wrapdiff(bx[1], a[1]) / STEP;
			double dudy = wrapdiff(by[0], a[0]) / STEP, dvdy = wrapdiff(by[1], a[1]) / STEP;
			/* over ~10 texels a pixel (towards the horizon) the coordinates alias: such
			 * minified ground is not what this measures */
			if (fmax(fmax(fabs(dudx), fabs(dvdx)), fmax(fabs(dudy), fabs(dvdy))) > 10)
				continue;
			/* σ_min of [[dudx, dudy], [dvdx, dvdy]] */
			double p = dudx * dudx + dudy * dudy + dvdx * dvdx + dvdy * dvdy;
			double det = fabs(dudx * dvdy - dudy * dvdx);
			double q = sqrt(fmax(0, p * p / 4 - det * det));
			double smin = sqrt(fmax(0, p / 2 - q));
			if (smin <= 0)
				continue; /* a texel border's interpolation, or a degenerate patch */
			ra[n] = 1 / sqrt(det);
			r[n++] = 1 / smin;
		}
	qsort(r, n, sizeof *r, cmp_double);
	qsort(ra, n, sizeof *ra, cmp_double);
	m->area_mean = 0;
	for (size_t i = 0; i < n; i++)
		m->area_mean += ra[i] / (double)(n ? n : 1);
	m->area_p50 = n ? ra[n / 2] : 0;
	m->area_p90 = n ? ra[(size_t)(0.9 * (double)(n - 1))] : 0;
	free(ra);
	m->n = n;
	m->over15 = 0;
	m->mean = 0;
	for (size_t i = 0; i < n; i++) {
		m->over15 += r[i] > 1.5;
		m->mean += r[i] / (double)n;
	}
	m->worst = n ? r[n - 1] : 0;
	m->p99 = n ? r[(size_t)(0.99 * (double)(n - 1))] : 0;
	free(r);
}

static void texels_per_pixel(void **state)
{
	(void)state;
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		printf("view_texels: skipped (no GL: %s)\n", err);
		skip();
	}
	static const char *const names[] = { "height", "normal", "color" };
	static const enum pix_type formats[] = { PIX_HEIGHT, PIX_NORMAL, PIX_COLOR };
	struct view_source *src = synth_source_create(T, 22, 3, names, formats, fill, NULL);
	struct view_desc d = { .width = W, .height = H, .haze = -1, .unlit = true,
			       .background_set = true, .background = { 1, 0, 1 } };
	struct view *v = NULL;
	assert_int_equal(view_create(gl_context_api(ctx), src, &d, &v, err), 0);
	/* lat, lon, alt, heading, pitch, fov */
	static const struct view_camera cams[] = {
		{ 10, 20, 2000, 30, -15, 60, 0, 0 },   /* the horizon in view */
		{ 10, 20, 200, 30, -30, 60, 0, 0 },
		{ 10, 20, 20000, 30, -40, 60, 0, 0 },
		{ 10, 20, 1000, 0, -90, 60, 0, 0 },    /* straight down */
		{ 71, -40, 3000, 300, -25, 60, 0, 0 }, /* high latitude: anisotropic levels */
	};
	unsigned char *px = xmalloc((size_t)W * H * 4);
	int bad = 0;
	for (size_t c = 0; c < sizeof cams / sizeof cams[0]; c++) {
		struct view_frame_stats st;
		assert_int_equal(view_frame_complete(v, &cams[c], test_slow(300), &st, NULL), 0);
		assert_int_equal(view_read_rgba(v, px), 0);
		const char *dump = getenv("TEXELS_PPM"); /* a directory: the pictures as PPM */
		if (dump) {
			char path[512];
			snprintf(path, sizeof path, "%s/texels-%zu.ppm", dump, c);
			FILE *f = fopen(path, "wb");
			if (f) {
				fprintf(f, "P6 %d %d 255\n", W, H);
				for (size_t i = 0; i < (size_t)W * H; i++)
					fwrite(px + i * 4, 1, 3, f);
				fclose(f);
			}
		}
		struct measure m;
		measure(px, &m);
		printf("camera %zu (%.0f m, pitch %.0f°): levels %d..%d, colour to %d; %zu samples: "
		       "a texel covers %.2f px on average, %.2f at the 99th percentile, %.2f at "
		       "most; %.2f %% over 1.5 px; by area %.2f px (median %.2f, 90th %.2f)\n",
		       c, cams[c].alt, cams[c].pitch, st.lfirst, st.llast, st.ldetail, m.n, m.mean,
		       m.p99, m.worst, 100.0 * (double)m.over15 / (double)(m.n ? m.n : 1),
		       m.area_mean, m.area_p50, m.area_p90);
		assert_true(m.n > 1000); /* the ground fills much of the picture */
		assert_true(st.ldetail >= st.llast);
		/* Sized by area a texel covers about 2 pixels (4–8 with each ring's own level);
		 * along its most magnified direction 3–4 on average (8–16). */
		if (m.area_p50 > 2.4 || m.area_p90 > 3.5 || m.mean > 4.5) {
			printf("camera %zu: texels too large on screen\n", c);
			bad++;
		}
	}
	free(px);
	assert_int_equal(bad, 0);
	view_destroy(v);
	view_source_destroy(src);
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(texels_per_pixel) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
