/* view_clipmap_receive against a source that never runs dry (a daemon with a burst of tiles
 * ready over a fast link, faster than the viewer takes them): with a deadline it returns,
 * having taken tiles, and what it left is taken by the next call; without one (offline
 * rendering) it takes everything a finite source has. A frame once stayed in here for as long
 * as the burst lasted (0.1-1.2 s in bench_keepup's flights from a disk store), so a viewer
 * with its picture complete showed nothing new for a second. Needs a GL context (llvmpipe);
 * skipped without one.
 */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/view/gl_context.h"
#include "client/view/view_clipmap.h"
#include "common/clock.h"
#include "common/xalloc.h"
#include "support/synth_source.h"

#define T 16

/* A source whose poll always has one more tile: the level-0 height tile, again and again
 * (the clipmap drops the copies it does not want). Counts the tiles handed out and released. */
struct flood {
	struct view_source base; /* first */
	long polled, released;
	long dry_after; /* polls that find a tile (< 0: for ever) */
};

static int fl_want(struct view_source *s, const struct view_want *w, size_t n,
		   const struct view_focus *f)
{
	(void)s, (void)w, (void)n, (void)f;
	return 0;
}

static int fl_poll(struct view_source *s, struct view_tile *out)
{
	struct flood *fl = (struct flood *)s;
	if (fl->dry_after >= 0 && fl->polled >= fl->dry_after)
		return 0;
	fl->polled++;
	void *px = xcalloc((size_t)T * T, 4);
	*out = (struct view_tile){ .layer = 0, .key = { .lx = 0, .ly = 0, .x = 0, .y = 0 },
				   .format = PIX_HEIGHT, .size = T, .texels = px, .handle = px };
	return 1;
}

static int fl_wait(struct view_source *s, int timeout_ms)
{
	(void)s, (void)timeout_ms;
	return 1;
}

static void fl_release(struct view_source *s, struct view_tile *t)
{
	((struct flood *)s)->released++;
	free(t->handle);
	t->handle = NULL;
	t->texels = NULL;
}

static void fl_destroy(struct view_source *s)
{
	(void)s;
}

static const struct view_source_ops fl_ops = { fl_want, fl_poll, fl_wait, fl_release, fl_destroy };

static void endless_burst(void **state)
{
	(void)state;
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		printf("view_receive: skipped (no GL: %s)\n", err);
		skip();
	}
	/* The planet's description from a synthetic source of the same shape. */
	static const char *const names[] = { "height", "normal", "color" };
	static const enum pix_type formats[] = { PIX_HEIGHT, PIX_NORMAL, PIX_COLOR };
	struct view_source *proto = synth_source_create(T, 4, 3, names, formats, NULL, NULL);
	struct flood fl = { .base = { .ops = &fl_ops, .planet = proto->planet }, .dry_after = -1 };
	struct view_clipmap *cm = NULL;
	assert_int_equal(view_clipmap_create(gl_context_api(ctx), &fl.base, 5, &cm, err), 0);

	/* With a deadline 5 ms ahead, ten calls in a row: each returns with tiles taken (the
	 * first VIEW_RECEIVE_MIN always, even past its deadline), and every tile it took and did
	 * not keep went back to the source. Without the bound the first call never returned. */
	long total = 0;
	for (int k = 0; k < 10; k++) {
		int got = view_clipmap_receive(cm, clock_now_ms() + 5);
		assert_true(got >= VIEW_RECEIVE_MIN);
		total += got;
	}
	assert_int_equal(total, fl.polled);
	int got = view_clipmap_receive(cm, clock_now_ms() - 1000); /* already past */
	assert_int_equal(got, VIEW_RECEIVE_MIN);

	/* No deadline (offline rendering): everything a finite source has, in one call. */
	fl.dry_after = fl.polled + 5000;
	got = view_clipmap_receive(cm, 0);
	assert_int_equal(got, 5000);
	assert_int_equal(fl.polled, fl.dry_after);
	assert_int_equal(view_clipmap_receive(cm, clock_now_ms() + 5), 0); /* dry: nothing */

	view_clipmap_destroy(cm);
	/* Every tile handed out came back (held ones at the clipmap's end). */
	assert_int_equal(fl.released, fl.polled);
	view_source_destroy(proto);
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(endless_burst),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
