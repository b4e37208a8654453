/* view_clipmap's colour layer switch (view_clipmap_set_color): after a switch the want-set
 * asks for the new layer's colour tiles only (no heights or normals), coarse levels first;
 * while only some have arrived, the levels whose new tiles are all in hold the new layer in
 * their whole colour slice and the others still hold the old one whole — no slice ever holds
 * texels of both; the heights are not uploaded again; once everything arrived no level is
 * stale. Switching back asks for the first layer again; a non-colour layer is refused. A
 * synthetic source fills each colour layer with its own value. Needs a GL context
 * (llvmpipe); skipped without one.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/view/gl_context.h"
#include "client/view/view_clipmap.h"
#include "client/view/view_levels.h"
#include "common/xalloc.h"
#include "support/synth_source.h"

#define T 16
#define NLEVELS 9
#define MAX_WANTS 4096

enum { L_HEIGHT, L_NORMAL, L_COLOR, L_WARM };
static const unsigned char red_of[4] = { 0, 0, 10, 200 }; /* each colour layer's red */

static void fill(void *ctx, const struct view_want *w, uint32_t n, enum pix_type f, void *data)
{
	(void)ctx;
	if (f == PIX_COLOR)
		for (size_t i = 0; i < (size_t)n * n; i++) {
			unsigned char *p = (unsigned char *)data + 4 * i;
			p[0] = red_of[w->layer], p[1] = 50, p[2] = 60, p[3] = 255;
		}
	else
		memset(data, 0, (size_t)n * n * pix_bytes(f));
}

static void aim(struct view_clipmap *cm)
{
	for (int l = 0; l < NLEVELS; l++) {
		struct grid_quad q;
		grid_window(clipmap_level_lx(l, 35, -1), l, T, CLIPMAP_WINDOW_TILES * T, 12, 35, &q);
		view_clipmap_target(cm, l, &q);
	}
}

/* Which layers each level's colour slice holds: bit 0 the first ("color"), bit 1 "warm",
 * bit 2 anything else. */
static void slices(const struct view_clipmap *cm, int out[NLEVELS])
{
	size_t S = view_clipmap_window_size(cm), n = S * S * NLEVELS * 4;
	unsigned char *px = xmalloc(n);
	assert_int_equal(view_clipmap_read(cm, VIEW_COLOR, px, n), 0);
	for (int l = 0; l < NLEVELS; l++) {
		out[l] = 0;
		for (size_t i = 0; i < S * S; i++) {
			const unsigned char *p = px + ((size_t)l * S * S + i) * 4;
			if (p[3] == 0)
				continue; /* outside what a coarse level's window holds: never written */
			out[l] |= p[0] == red_of[L_COLOR] ? 1 : p[0] == red_of[L_WARM] ? 2 : 4;
		}
	}
	free(px);
}

static void switch_refills(void **state)
{
	(void)state;
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		printf("view_switch: skipped (no GL: %s)\n", err);
		skip();
	}
	static const char *const names[] = { "height", "normal", "color", "warm" };
	static const enum pix_type formats[] = { PIX_HEIGHT, PIX_NORMAL, PIX_COLOR, PIX_COLOR };
	struct view_source *s = synth_source_create(T, NLEVELS - 1, 4, names, formats, fill, NULL);
	struct view_clipmap *cm = NULL;
	assert_int_equal(view_clipmap_create(gl_context_api(ctx), s, NLEVELS, &cm, err), 0);
	struct view_want *w = xmalloc(MAX_WANTS * sizeof *w);
	struct view_focus f = { 0 };

	/* Everything of the first colour layer. */
	aim(cm);
	size_t n = view_clipmap_wants(cm, false, w, MAX_WANTS);
	assert_int_equal(s->ops->want(s, w, n, &f), 0);
	assert_true(view_clipmap_receive(cm, 0) > 0);
	for (int l = 0; l < NLEVELS; l++)
		assert_int_equal(view_clipmap_update(cm, l), 1);
	int held[NLEVELS];
	slices(cm, held);
	for (int l = 0; l < NLEVELS; l++)
		assert_int_equal(held[l], 1);
	uint64_t hver[NLEVELS];
	for (int l = 0; l < NLEVELS; l++)
		hver[l] = view_clipmap_height_version(cm, l);

	/* Switch: only the new layer's colour tiles are wanted, coarse first. */
	assert_int_equal(view_clipmap_set_color(cm, L_WARM), 1);
	assert_int_equal(view_clipmap_color_layer(cm), L_WARM);
	n = view_clipmap_wants(cm, false, w, MAX_WANTS);
	assert_true(n > 0);
	for (size_t i = 0; i < n; i++) {
		assert_int_equal(w[i].layer, L_WARM);
		if (i > 0)
			assert_true(w[i].key.ly >= w[i - 1].key.ly);
	}
	for (int l = 0; l < NLEVELS; l++) {
		assert_true(view_clipmap_color_stale(cm, l));
		assert_int_equal(view_clipmap_update(cm, l), 0); /* nothing of it here yet */
	}
	/* Half of it arrives (the coarse half): a level whose tiles are all in takes the new
	 * layer over its whole slice, the others keep the old one whole. */
	size_t half = n / 2;
	int split = w[half].key.ly; /* the level the half ends in (its tiles partly in) */
	assert_int_equal(s->ops->want(s, w, half, &f), 0);
	assert_true(view_clipmap_receive(cm, 0) > 0);
	for (int l = 0; l < NLEVELS; l++)
		assert_int_equal(view_clipmap_update(cm, l), l < split);
	slices(cm, held);
	for (int l = 0; l < NLEVELS; l++) {
		printf("# level %d: slice holds %s\n", l, held[l] == 1 ? "color" : held[l] == 2 ? "warm" : "both");
		assert_int_equal(held[l], l < split ? 2 : 1);
		assert_int_equal(view_clipmap_color_stale(cm, l), l >= split);
	}
	assert_true(split > 1 && split < NLEVELS);
	/* The rest. */
	n = view_clipmap_wants(cm, false, w, MAX_WANTS);
	for (size_t i = 0; i < n; i++)
		assert_true(w[i].layer == L_WARM && w[i].key.ly >= split);
	assert_int_equal(s->ops->want(s, w, n, &f), 0);
	assert_true(view_clipmap_receive(cm, 0) > 0);
	for (int l = 0; l < NLEVELS; l++) {
		assert_int_equal(view_clipmap_update(cm, l), 1);
		assert_false(view_clipmap_color_stale(cm, l));
		/* the heights stayed: never uploaded again */
		assert_true(view_clipmap_height_version(cm, l) == hver[l]);
	}
	slices(cm, held);
	for (int l = 0; l < NLEVELS; l++)
		assert_int_equal(held[l], 2);

	/* Back: the first layer's tiles are wanted again; the same layer is no switch; a height
	 * layer, or an index past the planet's layers, is refused. */
	assert_int_equal(view_clipmap_set_color(cm, L_WARM), 0);
	assert_int_equal(view_clipmap_set_color(cm, L_HEIGHT), -EINVAL);
	assert_int_equal(view_clipmap_set_color(cm, 9), -EINVAL);
	assert_int_equal(view_clipmap_set_color(cm, L_COLOR), 1);
	n = view_clipmap_wants(cm, false, w, MAX_WANTS);
	assert_true(n > 0);
	for (size_t i = 0; i < n; i++)
		assert_int_equal(w[i].layer, L_COLOR);
	assert_int_equal(view_clipmap_color_find(cm, "warm"), L_WARM);
	assert_int_equal(view_clipmap_color_find(cm, "height"), -1);
	assert_int_equal(view_clipmap_color_find(cm, "nope"), -1);

	free(w);
	view_clipmap_destroy(cm);
	view_source_destroy(s);
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(switch_refills) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
