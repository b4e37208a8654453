/* test_view_core — a level is drawn from the middle of its window before the rest arrives
 * (view_clipmap_update's cores) and its tiles are asked for from the middle out
 * (view_clipmap_wants).
 * - Order: within a level the wanted tiles go from the window's middle out (Chebyshev
 *   distance of their centres from its centre never decreases) and each tile's layers come
 *   together.
 * - Partial: tiles arriving one at a time in that order, a level's texture holds a window that
 *   covers the level's own ring after at most 4 tiles of each layer (the window is 16-25), and
 *   the ring one coarser (whose colour and normals it gives) after at most 9; the target is
 *   held only when every tile is in. Whatever is held, every texel of the held window is the
 *   tile's texel (heights, colour; normals made from the heights equal a direct upload's).
 * - Nothing twice: growing core → half → window uploads exactly the bytes one upload of the
 *   window does.
 * - Never less: a window that moved by a tile keeps drawing the old window (which covers the
 *   ring) while the new column is missing; a core never replaces a held window that holds it.
 * At the equator, 46°N, 70°S, across the antimeridian and next to both poles (where a window
 * holds whole parallels: its cores are fewer rows). Needs a GL context (llvmpipe);
 * skipped without one.
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
#include "client/view/view_clipmap.h"
#include "client/view/view_levels.h"
#include "common/clipmap.h"
#include "common/xalloc.h"
#include "support/synth_source.h"

#define T 16
#define NLEVELS 9
#define LEVEL 6 /* W and H both wider than the window (S = 4·T) at every place tried */
#define MAX_WANTS 4096

/* Every texel tells where it is: heights and colour from the level texel (u, v). */
static float height_at(int ly, int64_t u, int64_t v)
{
	return (float)((u * 7 + v * 13 + ly * 101) % 100003);
}

static void fill(void *ctx, const struct view_want *w, uint32_t n, enum pix_type f, void *data)
{
	(void)ctx;
	for (uint32_t j = 0; j < n; j++)
		for (uint32_t i = 0; i < n; i++) {
			int64_t u = (int64_t)w->key.x * n + i, v = (int64_t)w->key.y * n + j;
			size_t at = (size_t)j * n + i;
			if (f == PIX_HEIGHT) {
				((float *)data)[at] = height_at(w->key.ly, u, v);
			} else if (f == PIX_COLOR) {
				unsigned char *p = (unsigned char *)data + 4 * at;
				p[0] = (unsigned char)u, p[1] = (unsigned char)v;
				p[2] = (unsigned char)w->key.ly, p[3] = 255;
			} else {
				unsigned char *p = (unsigned char *)data + 2 * at;
				p[0] = (unsigned char)(u * 3), p[1] = (unsigned char)(v * 5);
			}
		}
}

struct rig {
	struct view_source *src;
	struct view_clipmap *cm;
	struct view_want *w;
};

static void rig_open(struct rig *r, struct gl_context *ctx, bool normals)
{
	static const char *const names[] = { "height", "normal", "color" };
	static const enum pix_type formats[] = { PIX_HEIGHT, PIX_NORMAL, PIX_COLOR };
	char err[256];
	r->src = synth_source_create(T, NLEVELS - 1, 3, names, formats, fill, NULL);
	assert_non_null(r->src);
	assert_int_equal(view_clipmap_create_layer(gl_context_api(ctx), r->src, NLEVELS, NULL,
						   normals, &r->cm, err),
			 0);
	r->w = xmalloc(MAX_WANTS * sizeof *r->w);
}

static void rig_close(struct rig *r)
{
	free(r->w);
	view_clipmap_destroy(r->cm);
	view_source_destroy(r->src);
}

static void aim(struct view_clipmap *cm, double lon, double lat)
{
	for (int l = 0; l < NLEVELS; l++) {
		const struct grid_quad *cur = view_clipmap_target_of(cm, l);
		struct grid_quad q;
		grid_window(clipmap_level_lx(l, lat, cur ? cur->lx : -1), l, T,
			    CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
		view_clipmap_target(cm, l, &q);
	}
}

/* Delivers the first n of the current want-set (all of it: n = SIZE_MAX); returns how many
 * were wanted. */
static size_t deliver(struct rig *r, size_t n)
{
	struct view_focus f = { 0 };
	size_t nw = view_clipmap_wants(r->cm, false, r->w, MAX_WANTS);
	assert_int_equal(r->src->ops->want(r->src, r->w, n < nw ? n : nw, &f), 0);
	view_clipmap_receive(r->cm, 0);
	return nw;
}

/* Every texel of the level's held window is its tile's: heights and colour. */
static void check_held_texels(struct view_clipmap *cm, int l)
{
	const struct grid_quad *h = view_clipmap_held(cm, l);
	assert_non_null(h);
	size_t S = view_clipmap_window_size(cm), nl = (size_t)NLEVELS;
	float *hp = xmalloc(S * S * nl * sizeof *hp);
	unsigned char *cp = xmalloc(S * S * nl * 4);
	assert_int_equal(view_clipmap_read(cm, VIEW_HEIGHT, hp, S * S * nl * sizeof *hp), 0);
	assert_int_equal(view_clipmap_read(cm, VIEW_COLOR, cp, S * S * nl * 4), 0);
	int64_t W = (int64_t)grid_tiles_x(h->lx) * T;
	size_t bad = 0;
	for (int64_t j = 0; j < (int64_t)h->h; j++)
		for (int64_t i = 0; i < (int64_t)h->w; i++) {
			int64_t u = (h->u0 + i) % W, v = h->v0 + j;
			size_t at = (size_t)l * S * S + (size_t)(v % (int64_t)S) * S +
				    (size_t)(u % (int64_t)S);
			const unsigned char *c = cp + 4 * at;
			bad += hp[at] != height_at(l, u, v) || c[0] != (unsigned char)u ||
			       c[1] != (unsigned char)v || c[2] != l;
		}
	if (bad)
		printf("# level %d: %zu texels of the held window (%ux%u at %lld,%lld) are not "
		       "their tiles'\n",
		       l, bad, h->w, h->h, (long long)h->u0, (long long)h->v0);
	assert_int_equal(bad, 0);
	free(hp);
	free(cp);
}

static double chebyshev(const struct grid_quad *q, const struct tile_key *k)
{
	int64_t W = grid_tiles_x(q->lx);
	int64_t dx = ((int64_t)k->x - (int64_t)q->tx0) % W;
	if (dx < 0)
		dx += W;
	double cx = ((double)q->tx0 + dx + 0.5) * T - ((double)q->u0 + q->w / 2.0);
	double cy = ((double)k->y + 0.5) * T - ((double)q->v0 + q->h / 2.0);
	return fmax(fabs(cx), fabs(cy));
}

/* bound: assert the tile counts (not over a pole, where the window holds whole parallels
 * and its cores only fewer rows). */
static void one_place(struct gl_context *ctx, double lon, double lat, bool bound)
{
	printf("# %.1f, %.1f\n", lon, lat);
	struct rig a, b;
	rig_open(&a, ctx, true);
	aim(a.cm, lon, lat);

	/* Order: per level from the middle out, each tile's layers together. */
	size_t n = view_clipmap_wants(a.cm, false, a.w, MAX_WANTS);
	assert_true(n > 0);
	for (size_t i = 1; i < n; i++) {
		const struct view_want *p = &a.w[i - 1], *c = &a.w[i];
		assert_true(c->key.ly >= p->key.ly);
		if (c->key.ly != p->key.ly)
			continue;
		const struct grid_quad *q = view_clipmap_target_of(a.cm, c->key.ly);
		assert_true(chebyshev(q, &c->key) >= chebyshev(q, &p->key));
		if (c->key.x != p->key.x || c->key.y != p->key.y)
			assert_int_equal(p->layer, 2); /* a tile's layers end with its colour */
	}

	/* Every coarser level whole, then LEVEL one tile (three layers) at a time. */
	size_t before = 0;
	while (before < n && a.w[before].key.ly < LEVEL)
		before++;
	deliver(&a, before);
	for (int l = 0; l < LEVEL; l++)
		assert_int_equal(view_clipmap_update(a.cm, l), 1);
	const struct grid_quad *target = view_clipmap_target_of(a.cm, LEVEL);
	int total = target->ntx * target->nty;
	int own = -1, coarser = -1; /* tiles in when the ring, and the ring one coarser, show */
	for (int k = 1; k <= total; k++) {
		deliver(&a, 3);
		int done = view_clipmap_update(a.cm, LEVEL);
		assert_int_equal(done, k == total);
		const struct grid_quad *h = view_clipmap_held(a.cm, LEVEL);
		if (!h)
			continue;
		check_held_texels(a.cm, LEVEL);
		if (own < 0 && view_window_covers(h, lon, lat, clipmap_ring_radius(LEVEL), 1.5))
			own = k;
		if (coarser < 0 &&
		    view_window_covers(h, lon, lat, clipmap_ring_radius(LEVEL - 1), 1.5))
			coarser = k;
	}
	printf("# level %d: its ring drawn after %d tiles, the coarser ring's detail after %d, "
	       "the window has %d\n",
	       LEVEL, own, coarser, total);
	assert_true(own >= 1 && own <= total);
	if (bound) {
		assert_true(own <= 4);
		assert_true(coarser >= own && coarser <= 9);
		assert_true(total >= 16);
	}
	assert_true(grid_quad_equal(view_clipmap_held(a.cm, LEVEL), target));
	check_held_texels(a.cm, LEVEL);

	/* Nothing twice: the same levels uploaded at once by a second clipmap. */
	rig_open(&b, ctx, true);
	aim(b.cm, lon, lat);
	deliver(&b, before);
	deliver(&b, SIZE_MAX);
	for (int l = 0; l <= LEVEL; l++)
		assert_int_equal(view_clipmap_update(b.cm, l), 1);
	struct view_clipmap_stats sa, sb;
	view_clipmap_get_stats(a.cm, &sa);
	view_clipmap_get_stats(b.cm, &sb);
	printf("# bytes uploaded: grown %llu, at once %llu\n", (unsigned long long)sa.bytes_uploaded,
	       (unsigned long long)sb.bytes_uploaded);
	assert_true(sa.bytes_uploaded == sb.bytes_uploaded);
	rig_close(&b);

	/* Never less: the window moves a tile east; while the new column is missing the old
	 * window stays held (it still covers the ring), no core replaces it. (Not where the
	 * window holds whole parallels: there it does not move.) */
	if (!bound) {
		rig_close(&a);
		return;
	}
	int64_t W = (int64_t)grid_tiles_x(target->lx) * T;
	double step = 360.0 * T / (double)W;
	struct grid_quad old = *target;
	aim(a.cm, lon + step, lat);
	assert_false(grid_quad_equal(view_clipmap_target_of(a.cm, LEVEL), &old));
	assert_int_equal(view_clipmap_update(a.cm, LEVEL), 0);
	assert_true(grid_quad_equal(view_clipmap_held(a.cm, LEVEL), &old));
	rig_close(&a);
}

/* A GL context, or the test is skipped (saying why). */
static struct gl_context *gl_or_skip(void)
{
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		printf("view_core: skipped (no GL: %s)\n", err);
		skip();
	}
	return ctx;
}

static void cores(void **state)
{
	(void)state;
	struct gl_context *ctx = gl_or_skip();
	one_place(ctx, 20.3, 0.2, true);
	one_place(ctx, 7.4, 46.3, true);
	one_place(ctx, -60.2, -70.1, true);
	one_place(ctx, 179.95, 10.0, true); /* the window and its cores across the antimeridian */
	one_place(ctx, 30.0, 89.3, false);  /* whole parallels: the cores are fewer rows */
	one_place(ctx, -150.0, -89.6, false);
	gl_context_destroy(ctx);
}

/* Normals made from the heights: the core's outer texels (stencils cut to the core) are made
 * again once their neighbours arrive, so the grown slice equals a direct upload's. */
static void derived_normals(void **state)
{
	(void)state;
	struct gl_context *ctx = gl_or_skip();
	static const double place[][2] = { { 20.3, 0.2 }, { 7.4, 46.3 }, { 179.95, -35.0 } };
	for (size_t p = 0; p < sizeof place / sizeof place[0]; p++) {
		struct rig a, b;
		rig_open(&a, ctx, false);
		rig_open(&b, ctx, false);
		aim(a.cm, place[p][0], place[p][1]);
		aim(b.cm, place[p][0], place[p][1]);
		size_t n = view_clipmap_wants(a.cm, false, a.w, MAX_WANTS), before = 0;
		while (before < n && a.w[before].key.ly < LEVEL)
			before++;
		deliver(&a, before);
		for (int l = 0; l < LEVEL; l++)
			view_clipmap_update(a.cm, l);
		int cores = 0;
		for (;;) {
			size_t left = deliver(&a, 2); /* height and colour: a tile */
			const struct grid_quad *h0 = view_clipmap_held(a.cm, LEVEL);
			uint32_t w0 = h0 ? h0->w : 0;
			int done = view_clipmap_update(a.cm, LEVEL);
			const struct grid_quad *h1 = view_clipmap_held(a.cm, LEVEL);
			cores += !done && h1 && h1->w != w0;
			if (done || left == 0)
				break;
		}
		assert_true(cores >= 1);
		deliver(&b, SIZE_MAX);
		for (int l = 0; l <= LEVEL; l++)
			assert_int_equal(view_clipmap_update(b.cm, l), 1);
		size_t S = view_clipmap_window_size(a.cm), sz = S * S * NLEVELS * 2;
		unsigned char *na = xmalloc(sz), *nb = xmalloc(sz);
		assert_int_equal(view_clipmap_read(a.cm, VIEW_NORMAL, na, sz), 0);
		assert_int_equal(view_clipmap_read(b.cm, VIEW_NORMAL, nb, sz), 0);
		size_t off = (size_t)LEVEL * S * S * 2, diff = 0;
		for (size_t i = 0; i < S * S * 2; i++)
			diff += na[off + i] != nb[off + i];
		printf("# derived normals at %.2f, %.2f: %d cores first, %zu bytes differ from a "
		       "direct upload\n",
		       place[p][0], place[p][1], cores, diff);
		assert_int_equal(diff, 0);
		free(na);
		free(nb);
		rig_close(&a);
		rig_close(&b);
	}
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(cores),
					    cmocka_unit_test(derived_normals) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
