/* The viewer in real time after a jump (seed 003 Algorithm 1): the tiles of the new place come
 * in over many frames, and taking them is slow on some frames (a network source decodes them
 * as it polls), longer than the frame's time budget. A still camera never draws fewer levels
 * than the frame before, never fewer than are resident, and reaches the complete picture; the
 * budget counts uploads, not the time taken to receive; the jump is no motion (one want-set,
 * quads coarse first, no look-ahead along it); a late level or a newly wanted coarser one
 * hides none of the levels held; before the new place's levels arrive, the level-0 stand-in
 * puts the horizon where it belongs. A synthetic flat planet (every texel zero) behind a
 * throttle. Needs a GL context (llvmpipe); skipped without one.
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
#include <time.h>

#include "client/view/gl_context.h"
#include "client/view/view.h"
#include "common/clock.h"
#include "common/xalloc.h"
#include "support/synth_source.h"

/* ---- a throttled source: at most `quota` tiles until the test refills it; the poll that
 * hands out a frame's first tile takes `slow_ms` (a decode longer than the budget) ---- */

struct throttle {
	struct view_source base;
	struct view_source *in;
	int quota;
	double slow_ms;
	bool slowed; /* this refill's slow poll has happened */
	size_t wants, ahead; /* want-sets received; look-ahead entries in them */
	bool disordered;     /* a want-set put a finer quad, or a ring tile, before a quad */
	int hold;	     /* tiles of this level are kept back (-1: none) */
	struct view_tile kept[512];
	int nkept;
};

static struct throttle *th_of(struct view_source *s) { return (struct throttle *)s; }

static int th_want(struct view_source *s, const struct view_want *w, size_t n,
		   const struct view_focus *f)
{
	struct throttle *t = th_of(s);
	t->wants++;
	for (size_t i = 0; i < n; i++) {
		t->ahead += w[i].cls == VIEW_CLASS_AHEAD;
		if (i > 0 && w[i].cls == VIEW_CLASS_VISIBLE &&
		    (w[i - 1].cls != VIEW_CLASS_VISIBLE || w[i - 1].key.ly > w[i].key.ly))
			t->disordered = true;
	}
	return t->in->ops->want(t->in, w, n, f);
}

static int th_poll(struct view_source *s, struct view_tile *out)
{
	struct throttle *t = th_of(s);
	if (t->quota <= 0)
		return 0;
	int rc;
	if (t->hold < 0 && t->nkept > 0) {
		*out = t->kept[--t->nkept];
		rc = 1;
	} else {
		while ((rc = t->in->ops->poll(t->in, out)) == 1 && out->key.ly == t->hold) {
			bool dup = false; /* asked for again by a later want-set */
			for (int i = 0; i < t->nkept && !dup; i++) {
				const struct view_tile *k = &t->kept[i];
				dup = k->layer == out->layer && k->key.x == out->key.x &&
				      k->key.y == out->key.y && k->key.lx == out->key.lx;
			}
			if (dup) {
				t->in->ops->release(t->in, out);
				continue;
			}
			assert_true(t->nkept < 512);
			t->kept[t->nkept++] = *out;
		}
	}
	if (rc != 1)
		return rc;
	t->quota--;
	if (!t->slowed && t->slow_ms > 0) {
		/* the time a decode would take (sleeping: the machine's cores are shared) */
		uint64_t end = clock_now_ns() + (uint64_t)(t->slow_ms * 1e6);
		for (uint64_t now; (now = clock_now_ns()) < end;) {
			struct timespec ts = { (time_t)((end - now) / 1000000000u),
					       (long)((end - now) % 1000000000u) };
			nanosleep(&ts, NULL);
		}
		t->slowed = true;
	}
	return 1;
}

static int th_wait(struct view_source *s, int ms)
{
	(void)s;
	(void)ms;
	return 0;
}

static void th_release(struct view_source *s, struct view_tile *tile)
{
	th_of(s)->in->ops->release(th_of(s)->in, tile);
}

static void th_destroy(struct view_source *s)
{
	struct throttle *t = th_of(s);
	while (t->nkept > 0)
		t->in->ops->release(t->in, &t->kept[--t->nkept]);
	view_source_destroy(th_of(s)->in);
	free(s);
}

static const struct view_source_ops th_ops = { th_want, th_poll, th_wait, th_release,
					       th_destroy };

static struct throttle *throttle_create(void)
{
	static const char *const names[] = { "color", "height", "normal" };
	static const enum pix_type formats[] = { PIX_COLOR, PIX_HEIGHT, PIX_NORMAL };
	struct throttle *t = xcalloc(1, sizeof *t);
	t->in = synth_source_create(32, 12, 3, names, formats, NULL, NULL);
	t->base.ops = &th_ops;
	t->base.planet = t->in->planet;
	t->hold = -1;
	return t;
}

static void refill(struct throttle *t, int quota, double slow_ms)
{
	t->quota = quota;
	t->slow_ms = slow_ms;
	t->slowed = false;
}

static struct gl_context *ctx_or_skip(void)
{
	struct gl_context *ctx = NULL;
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &ctx, err) < 0) {
		fprintf(stderr, "no GL context: %s\n", err);
		return NULL;
	}
	return ctx;
}

static struct view *make_view(struct gl_context *ctx, struct throttle *t, int w, int h,
			      double budget_ms)
{
	struct view_desc d = { .width = w, .height = h, .n_phi = 96, .m_rings = 12,
			       .budget_ms = budget_ms, .haze = -1, .background_set = true,
			       .background = { 1, 0, 1 } };
	struct view *v = NULL;
	char err[256] = "";
	int rc = view_create(gl_context_api(ctx), &t->base, &d, &v, err);
	if (rc < 0)
		fprintf(stderr, "view_create: %s\n", err);
	assert_int_equal(rc, 0);
	return v;
}

/* Frames with every tile handed out at once until one is complete. */
static void settle(struct view *v, struct throttle *t, const struct view_camera *c, double *now)
{
	struct view_frame_stats st = { 0 };
	for (int k = 0; k < 60 && !st.complete; k++) {
		refill(t, 1 << 20, 0);
		*now += 1.0 / 30;
		assert_int_equal(view_frame(v, c, *now, &st), 0);
	}
	assert_true(st.complete);
}

/* Whether level l's texture holds its target quad. */
static bool resident(struct view *v, int l)
{
	struct view_clipmap *cm = view_get_clipmap(v);
	const struct grid_quad *h = view_clipmap_held(cm, l), *q = view_clipmap_target_of(cm, l);
	return h && q && grid_quad_equal(h, q);
}

/* ---- a still camera after a jump ---- */

/* Tiles trickle in, 8 on every other frame, and taking them takes longer than the budget
 * (which the plan once counted from the frame's start). The levels drawn only grow, every
 * resident level is drawn, and the picture completes. (Before the fix the frames that took
 * tiles drew their first level alone.) */
static void still_after_jump_keeps_levels(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct throttle *t = throttle_create();
	struct view *v = make_view(ctx, t, 64, 64, 20);
	struct view_camera a = { 20, 10, 5000, 0, -20, 60, 0, 0 };
	struct view_camera b = { -30, 100, 5000, 0, -20, 60, 0, 0 };
	double now = 1;
	settle(v, t, &a, &now);
	/* a few frames at rest, so the look-ahead has no motion left */
	for (int k = 0; k < 30; k++) {
		refill(t, 1 << 20, 0);
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &a, now, NULL), 0);
	}

	struct view_frame_stats st, prev = { .lfirst = -1, .llast = -1 };
	t->wants = t->ahead = 0;
	int complete_at = -1, slow_frames = 0, most_uploads = 0;
	for (int f = 0; f < 400 && complete_at < 0; f++) {
		bool slow = f % 2 == 0;
		refill(t, slow ? 8 : 0, slow ? 30 : 0);
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &b, now, &st), 0);
		slow_frames += st.tiles_received > 0;
		if (st.levels_uploaded > most_uploads)
			most_uploads = st.levels_uploaded;
		assert_true(st.lfirst >= 0);
		if (f > 0) {
			assert_int_equal(st.lmin, prev.lmin);
			assert_int_equal(st.lmax, prev.lmax);
			if (st.llast < prev.llast || st.levels_drawn < prev.levels_drawn)
				fail_msg("frame %d after the jump drew levels %d..%d, the frame "
					 "before %d..%d (%d tiles received)",
					 f, st.lfirst, st.llast, prev.lfirst, prev.llast,
					 st.tiles_received);
		}
		/* The picture is never less than what is resident: every level finer than the
		 * first whose texture holds its quad is drawn (and a drawn level's own window may
		 * lag its target while the budget holds its upload back). */
		int res = 1;
		for (int l = st.lfirst + 1; l <= st.lmax; l++)
			res += resident(v, l);
		if (st.levels_drawn < res)
			fail_msg("frame %d: %d levels drawn (%d..%d), %d resident", f,
				 st.levels_drawn, st.lfirst, st.llast, res);
		if (st.complete)
			complete_at = f;
		prev = st;
	}
	if (complete_at < 0)
		fail_msg("not complete 400 frames after the jump (last drew %d..%d of %d..%d)",
			 st.lfirst, st.llast, st.lmin, st.lmax);
	assert_true(slow_frames >= 3); /* the slow frames did happen */
	/* A jump is no motion: one want-set for the new place, its quads coarse first, no
	 * look-ahead along the jump. */
	if (t->wants != 1 || t->ahead != 0)
		fail_msg("%zu want-sets after the jump, %zu look-ahead tiles asked for", t->wants,
			 t->ahead);
	assert_false(t->disordered);
	/* A slow frame uploads one level; a quick one may upload more. */
	assert_true(most_uploads >= 1);
	/* at rest once complete: every level stays */
	for (int f = 0; f < 10; f++) {
		refill(t, f % 2 ? 0 : 8, f % 2 ? 0 : 30);
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &b, now, &st), 0);
		assert_int_equal(st.lfirst, st.lmin);
		assert_int_equal(st.llast, st.lmax);
	}
	view_destroy(v);
	view_source_destroy(&t->base);
	gl_context_destroy(ctx);
}

/* The budget counts the frame's uploads, not the time it took to take the tiles: frames
 * whose tiles took longer than the budget to come in (each frame's first poll a 30 ms decode,
 * the budget 20 ms) still upload the levels whose quads they completed, and the new place is
 * complete after a few frames. A frame takes VIEW_RECEIVE_MIN tiles after its deadline passed,
 * not the whole burst (view_clipmap_receive), so the place comes in over several frames.
 * (Before the budget fix such a frame uploaded one level and drew that one alone.) */
static void slow_tiles_leave_the_budget(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct throttle *t = throttle_create();
	struct view *v = make_view(ctx, t, 64, 64, 20);
	struct view_camera a = { 20, 10, 5000, 0, -20, 60, 0, 0 };
	struct view_camera b = { -30, 100, 5000, 0, -20, 60, 0, 0 };
	double now = 1;
	settle(v, t, &a, &now);
	struct view_frame_stats st;
	refill(t, 0, 0);
	now += 1.0 / 30;
	assert_int_equal(view_frame(v, &b, now, &st), 0); /* asks for the new place */
	int frames = 0, uploading = 0;
	do {
		refill(t, 1 << 20, 30);
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &b, now, &st), 0);
		assert_true(st.tiles_received >= VIEW_RECEIVE_MIN || st.complete);
		uploading += st.levels_uploaded >= 1;
		frames++;
	} while (!st.complete && frames < 300);
	assert_true(st.complete);
	assert_true(uploading >= 2); /* levels went up on slow frames, not only the last */
	for (int l = st.lmin; l <= st.dmax; l++)
		assert_true(resident(v, l));
	print_message("slow_tiles_leave_the_budget: complete after %d slow frames, %d uploaded\n",
		      frames, uploading);
	view_destroy(v);
	view_source_destroy(&t->base);
	gl_context_destroy(ctx);
}

/* ---- a level missing between resident ones ---- */

/* The pixels that show the background colour. */
static size_t background_mask(const unsigned char *px, int w, int h, bool *mask)
{
	size_t n = 0;
	for (size_t i = 0; i < (size_t)w * h; i++) {
		const unsigned char *p = px + i * 4;
		mask[i] = p[0] > 200 && p[1] < 50 && p[2] > 200;
		n += mask[i];
	}
	return n;
}

/* After a jump one level's tiles are late (the rest have all come): every other level is
 * drawn, the next coarser one over the late level's rings, without a hole (on a flat planet
 * the picture is the complete one); then the late level comes in and the picture completes.
 * (Before the fix the plan stopped at the late level: everything finer stayed hidden.) */
static void late_level_hides_nothing(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	enum { W = 64, H = 64 };
	struct throttle *t = throttle_create();
	struct view *v = make_view(ctx, t, W, H, 0);
	struct view_camera a = { 20, 10, 5000, 0, -20, 60, 0, 0 };
	struct view_camera b = { -30, 100, 5000, 0, -20, 60, 0, 0 };
	double now = 1;
	settle(v, t, &a, &now);
	struct view_frame_stats st;
	refill(t, 1 << 20, 0);
	now += 1.0 / 30;
	assert_int_equal(view_frame(v, &b, now, &st), 0); /* asks for the new place */
	int lmin = st.lmin, lmax = st.lmax;
	assert_true(lmax - lmin >= 4);
	int late = lmin + 4; /* a level whose ring takes much of the picture */
	t->hold = late;
	for (int k = 0; k < 10; k++) {
		refill(t, 1 << 20, 0);
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &b, now, &st), 0);
	}
	assert_true(t->nkept > 0);
	assert_int_equal(st.lfirst, lmin);
	assert_int_equal(st.llast, lmax);
	assert_int_equal(st.levels_drawn, lmax - lmin);
	assert_false(st.complete);
	unsigned char *px = xmalloc((size_t)W * H * 4);
	bool *gap = xmalloc((size_t)W * H), *full = xmalloc((size_t)W * H);
	view_read_rgba(v, px);
	size_t ngap = background_mask(px, W, H, gap);
	t->hold = -1;
	settle(v, t, &b, &now);
	view_read_rgba(v, px);
	size_t nfull = background_mask(px, W, H, full);
	size_t diff = 0;
	for (size_t i = 0; i < (size_t)W * H; i++)
		diff += gap[i] != full[i];
	if (diff > 8)
		fail_msg("%zu pixels differ in coverage (%zu background with level %d late, %zu "
			 "complete)",
			 diff, ngap, late, nfull);
	assert_true(nfull < (size_t)W * H);
	free(px);
	free(gap);
	free(full);
	view_destroy(v);
	view_source_destroy(&t->base);
	gl_context_destroy(ctx);
}

/* ---- climbing: a coarser level becomes wanted ---- */

/* The camera climbs until it wants a coarser level than it holds; no tile comes meanwhile.
 * Every level it held and still wants is drawn, level 0 standing in over the new coarsest
 * level's rings. (Before the fix the plan stopped at the missing level: level 0 alone.) */
static void climb_keeps_levels(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	struct throttle *t = throttle_create();
	struct view *v = make_view(ctx, t, 64, 64, 0);
	struct view_camera c = { 20, 10, 30e3, 0, -20, 60, 0, 0 };
	double now = 1;
	settle(v, t, &c, &now);
	struct view_frame_stats st;
	assert_int_equal(view_frame(v, &c, now, &st), 0);
	int lmin0 = st.lmin, lmax0 = st.lmax;
	assert_true(lmin0 >= 2);
	refill(t, 0, 0);
	for (int k = 0; k < 40 && st.lmin == lmin0; k++) {
		c.alt *= 1.25;
		now += 1.0 / 30;
		assert_int_equal(view_frame(v, &c, now, &st), 0);
	}
	assert_int_equal(st.lmin, lmin0 - 1);
	assert_true(st.lmax <= lmax0);
	assert_int_equal(st.lfirst, 0);
	assert_int_equal(st.llast, st.lmax);
	assert_int_equal(st.levels_drawn, 1 + st.lmax - lmin0 + 1);
	assert_false(st.complete);
	settle(v, t, &c, &now);
	view_destroy(v);
	view_source_destroy(&t->base);
	gl_context_destroy(ctx);
}

/* ---- the stand-in while the new place's levels are missing ---- */

/* The mean over the columns of the first row from the top that is not background. */
static double horizon_row(const unsigned char *px, int w, int h)
{
	double sum = 0;
	for (int x = 0; x < w; x++) {
		int y = 0;
		while (y < h) {
			const unsigned char *p = px + ((size_t)y * w + x) * 4;
			if (!(p[0] > 200 && p[1] < 50 && p[2] > 200))
				break;
			y++;
		}
		sum += y;
	}
	return sum / w;
}

/* Right after a jump only the whole-globe levels (0, and up to 2 whose 4×4-tile window is
 * the whole level) can be drawn. The coarsest's disk must still have
 * the shape of the ground: on a flat planet, the horizon at 10 km lies on the same row as in
 * the complete picture. (Before the fix the visible ground was all in level 0's fan, a cone
 * from the nadir to the horizon cap, and the horizon sank by about 0.7°.) */
static void level0_stand_in_has_horizon(void **state)
{
	(void)state;
	struct gl_context *ctx = ctx_or_skip();
	if (!ctx)
		skip();
	enum { W = 96, H = 128 };
	struct throttle *t = throttle_create();
	struct view *v = make_view(ctx, t, W, H, 0);
	struct view_camera a = { 20, 10, 10e3, 0, -3, 12, 0, 0 };
	struct view_camera b = { -30, 100, 10e3, 0, -3, 12, 0, 0 };
	double now = 1;
	settle(v, t, &a, &now);
	unsigned char *px = xmalloc((size_t)W * H * 4);
	struct view_frame_stats st;
	refill(t, 0, 0);
	now += 1.0 / 30;
	assert_int_equal(view_frame(v, &b, now, &st), 0);
	/* the whole-globe levels alone: level 0, and every level whose window (4×4 tiles) is the
	 * whole level — up to level 2 */
	assert_true(st.lfirst <= 2);
	assert_int_equal(st.llast, st.lfirst);
	assert_true(st.lmax >= st.lfirst + 4);
	view_read_rgba(v, px);
	double stand_in = horizon_row(px, W, H);
	settle(v, t, &b, &now);
	view_read_rgba(v, px);
	double full = horizon_row(px, W, H);
	free(px);
	/* 12° over 128 rows: 0.7° is 7 rows */
	if (fabs(stand_in - full) > 1.5)
		fail_msg("horizon on row %.1f with level 0 alone, %.1f complete", stand_in, full);
	assert_true(full > 2 && full < H - 2);
	view_destroy(v);
	view_source_destroy(&t->base);
	gl_context_destroy(ctx);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(still_after_jump_keeps_levels),
		cmocka_unit_test(slow_tiles_leave_the_budget),
		cmocka_unit_test(late_level_hides_nothing),
		cmocka_unit_test(climb_keeps_levels),
		cmocka_unit_test(level0_stand_in_has_horizon),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
