/* view_clipmap look-ahead (view_clipmap_motion): a camera moving east gets the lines of tiles
 * beyond the ring on the levels it crosses quickly, ranked after every quad and ring tile;
 * the tiles it got ahead make the next quad complete without asking again; reversing drops
 * them. While it moves, the ring is asked for only on the side it moves to. Flying north
 * towards where a level's lx changes, the new lx's window is asked for before the switch;
 * over the pole, every switch and every new row is here well before it is due. A
 * synthetic source delivers every wanted tile at once (zeros). Needs a GL context
 * (llvmpipe); skipped without one.
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
#define NLEVELS 11
#define LAT 0.3
#define MAX_WANTS 2048

/* A planet of zeros, every wanted tile delivered at once (fill: told of each, or NULL). */
static struct view_source *src_create(synth_fill_fn fill)
{
	static const char *const names[] = { "height", "normal", "color" };
	static const enum pix_type formats[] = { PIX_HEIGHT, PIX_NORMAL, PIX_COLOR };
	return synth_source_create(T, NLEVELS - 1, 3, names, formats, fill, NULL);
}

/* Targets at (lon, LAT) on every level; returns whether any changed. */
static bool aim(struct view_clipmap *cm, double lon)
{
	bool changed = false;
	for (int l = 0; l < NLEVELS; l++) {
		struct grid_quad q;
		grid_window(l + 1, l, T, CLIPMAP_WINDOW_TILES * T, lon, LAT, &q);
		changed |= view_clipmap_target(cm, l, &q);
	}
	return changed;
}

static size_t ask(struct view_clipmap *cm, struct view_source *s, struct view_want *w)
{
	size_t n = view_clipmap_wants(cm, true, w, MAX_WANTS);
	struct view_focus f = { 0 };
	assert_int_equal(s->ops->want(s, w, n, &f), 0);
	return n;
}

/* Which lines of level l's ring the want-set asks for (prefetch class): the column west of
 * the quad (behind an eastward camera), the rows north and south of it. */
static void ring_lines(const struct view_clipmap *cm, const struct view_want *w, size_t n, int l,
		       bool *west, bool *north, bool *south)
{
	const struct grid_quad *q = view_clipmap_target_of(cm, l);
	assert_non_null(q);
	*west = *north = *south = false;
	for (size_t i = 0; i < n; i++) {
		if (w[i].key.ly != l || w[i].cls != VIEW_CLASS_PREFETCH)
			continue;
		*west |= w[i].key.x == grid_wrap_x(q->lx, (int64_t)q->tx0 - 1);
		*north |= w[i].key.y + 1 == q->ty0;
		*south |= w[i].key.y == q->ty0 + q->nty;
	}
}

/* A GL context (the test is skipped without one), the synthetic source, a clipmap over it
 * and room for a want-set. */
struct rig {
	struct gl_context *ctx;
	struct view_source *s;
	struct view_clipmap *cm;
	struct view_want *w;
};

static struct rig rig_open(synth_fill_fn fill)
{
	struct rig g = { 0 };
	char err[256];
	if (gl_context_create(GL_BACKEND_AUTO, &g.ctx, err) < 0) {
		printf("view_ahead: skipped (no GL: %s)\n", err);
		skip();
	}
	g.s = src_create(fill);
	assert_int_equal(view_clipmap_create(gl_context_api(g.ctx), g.s, NLEVELS, &g.cm, err), 0);
	g.w = xmalloc(MAX_WANTS * sizeof *g.w);
	return g;
}

static void rig_close(struct rig *g)
{
	free(g->w);
	view_clipmap_destroy(g->cm);
	view_source_destroy(g->s);
	gl_context_destroy(g->ctx);
}

static void look_ahead(void **state)
{
	(void)state;
	struct rig g = rig_open(NULL);
	struct view_clipmap *cm = g.cm;
	struct view_source *s = g.s;
	struct view_want *w = g.w;

	/* At rest: no look-ahead. */
	double lon = 20.0, t = 0;
	aim(cm, lon);
	assert_false(view_clipmap_motion(cm, lon, LAT, t));
	size_t n = ask(cm, s, w);
	for (size_t i = 0; i < n; i++)
		assert_true(w[i].cls != VIEW_CLASS_AHEAD);
	bool west, north, south;
	ring_lines(cm, w, n, 10, &west, &north, &south); /* at rest: the whole ring */
	assert_true(west && north && south);
	assert_true(view_clipmap_receive(cm, 0) > 0);

	/* Moving east at 5°/s: level 10 tiles are 360/2^11 ≈ 0.18° wide (≈ 4 crossed in 0.15 s:
	 * 4 lines), level 9 0.35° (2 lines), level 6 tiles 2.8° (0.27: none); at most 6 lines
	 * (level 11 and finer). */
	bool changed = false;
	for (int k = 0; k < 3; k++) {
		t += 0.1;
		lon += 0.5;
		changed |= aim(cm, lon);
		changed |= view_clipmap_motion(cm, lon, LAT, t);
	}
	assert_true(changed);
	n = ask(cm, s, w);
	size_t ahead = 0;
	bool seen_ahead = false, far10 = false;
	for (size_t i = 0; i < n; i++) {
		if (w[i].cls != VIEW_CLASS_AHEAD) {
			assert_false(seen_ahead); /* every quad and ring tile first */
			continue;
		}
		seen_ahead = true;
		ahead++;
		int l = w[i].key.ly;
		assert_true(l >= 7);
		const struct grid_quad *q = view_clipmap_target_of(cm, l);
		assert_non_null(q);
		int64_t east = (int64_t)q->tx0 + q->ntx - 1; /* the window's last column */
		int64_t d = ((int64_t)w[i].key.x - east) & (((int64_t)1 << q->lx) - 1);
		int most = l < 9 ? 2 : l == 9 ? 3 : l == 10 ? 5 : 7; /* 1 + lines */
		assert_true(d >= 2 && d <= most);
		far10 |= l == 10 && d == 5;
	}
	assert_true(ahead > 0 && ahead <= 160);
	assert_true(far10); /* the whole 0.15 s of lead at level 10, not 2 lines of it */
	/* Moving: the ring on the side the camera moves to — not the column behind it, and of
	 * the rows north and south (it does not move north or south) only the nearer one. */
	ring_lines(cm, w, n, 10, &west, &north, &south);
	assert_false(west);
	assert_true(north != south);
	while (view_clipmap_receive(cm, 0) > 0)
		;

	/* One level-10 tile further east: the new quad and its ring are already here. */
	struct view_clipmap_stats st0, st1;
	view_clipmap_get_stats(cm, &st0);
	const struct grid_quad *q10 = view_clipmap_target_of(cm, 10);
	uint32_t tx0 = q10->tx0;
	double step = 360.0 / (1u << 11);
	for (int k = 0; k < 40 && view_clipmap_target_of(cm, 10)->tx0 == tx0; k++) {
		t += 0.01;
		lon += step / 8;
		aim(cm, lon);
		view_clipmap_motion(cm, lon, LAT, t);
	}
	assert_int_not_equal(view_clipmap_target_of(cm, 10)->tx0, tx0);
	assert_int_equal(view_clipmap_update(cm, 10), 1);
	n = ask(cm, s, w);
	for (size_t i = 0; i < n; i++)
		if (w[i].key.ly == 10)
			assert_int_equal(w[i].cls, VIEW_CLASS_AHEAD); /* only the new far line */

	/* Turning back west: the lines ahead in the east are released. */
	while (view_clipmap_receive(cm, 0) > 0)
		;
	view_clipmap_get_stats(cm, &st0);
	for (int k = 0; k < 3; k++) {
		t += 0.1;
		lon -= 0.5;
		aim(cm, lon);
		view_clipmap_motion(cm, lon, LAT, t);
	}
	view_clipmap_get_stats(cm, &st1);
	assert_true(st1.tiles_held < st0.tiles_held);

	rig_close(&g);
}

/* Targets at (lon, lat) on every level as the viewer sets them: each level's lx from
 * clipmap_level_lx, with the hysteresis of the lx it has. */
static void aim_at(struct view_clipmap *cm, double lon, double lat)
{
	for (int l = 0; l < NLEVELS; l++) {
		const struct grid_quad *cur = view_clipmap_target_of(cm, l);
		struct grid_quad q;
		grid_window(clipmap_level_lx(l, lat, cur ? cur->lx : -1), l, T,
			    CLIPMAP_WINDOW_TILES * T, lon, lat, &q);
		view_clipmap_target(cm, l, &q);
	}
}

/* Flying north towards where level 8 turns coarser in x (its lx drops): the window of the
 * new lx is asked for at look-ahead class before the level gets there, so the level is
 * complete the moment it switches, without waiting for a tile. Before, nothing of the new
 * lx was asked for until the switch (a pole flight's short frames were all such waits). */
static void next_lx_window(void **state)
{
	(void)state;
	enum { L8 = 8 };
	/* where level 8's lx first changes going north */
	int lx0 = clipmap_level_lx(L8, 40.0, -1), thr_lx = lx0;
	double thr = 40.0;
	while (thr < 89 && (thr_lx = clipmap_level_lx(L8, thr, lx0)) == lx0)
		thr += 0.01;
	assert_true(thr < 89 && thr_lx < lx0);

	struct rig g = rig_open(NULL);
	struct view_clipmap *cm = g.cm;
	struct view_source *s = g.s;
	struct view_want *w = g.w;
	double lon = 20.0, lat = thr - 0.65, t = 0; /* north at 1°/s: 0.65 s short of it */
	bool asked_next = false, switched = false;
	for (int k = 0; k < 12 && !switched; k++) {
		aim_at(cm, lon, lat);
		const struct grid_quad *q = view_clipmap_target_of(cm, L8);
		assert_non_null(q);
		if (q->lx != lx0) {
			/* the switch: every tile of the new window is here already */
			assert_int_equal(q->lx, thr_lx);
			assert_true(asked_next);
			assert_int_equal(view_clipmap_update(cm, L8), 1);
			switched = true;
			break;
		}
		view_clipmap_motion(cm, lon, lat, t);
		size_t n = ask(cm, s, w);
		for (size_t i = 0; i < n; i++)
			if (w[i].key.ly == L8 && w[i].key.lx == thr_lx) {
				assert_int_equal(w[i].cls, VIEW_CLASS_AHEAD);
				asked_next = true;
			}
		while (view_clipmap_receive(cm, 0) > 0)
			;
		for (int l = 0; l < NLEVELS; l++)
			view_clipmap_update(cm, l);
		t += 0.1;
		lat += 0.1;
	}
	assert_true(switched);
	rig_close(&g);
}

/* When each height tile was last delivered (simulated seconds), by key: a tile the viewer
 * dropped and asked for again is delivered again, later. */
static struct delivery {
	struct tile_key k;
	double t;
} deliveries[16384];
static size_t ndeliveries;
static double sim_now;

static void record_delivery(void *ctx, const struct view_want *w, uint32_t size, enum pix_type f,
			    void *data)
{
	(void)ctx;
	(void)data;
	if (f != PIX_HEIGHT || size != T)
		return;
	for (size_t i = 0; i < ndeliveries; i++)
		if (grid_key_equal(&deliveries[i].k, &w->key)) {
			deliveries[i].t = sim_now;
			return;
		}
	assert_true(ndeliveries < sizeof deliveries / sizeof deliveries[0]);
	deliveries[ndeliveries++] = (struct delivery){ w->key, sim_now };
}

static double delivered_at(const struct tile_key *k)
{
	for (size_t i = 0; i < ndeliveries; i++)
		if (grid_key_equal(&deliveries[i].k, k))
			return deliveries[i].t;
	return INFINITY;
}

/* Over the pole along a meridian at 10°/s (800 km up at 2.5× the seed is ~14°/s; levels 4–7,
 * the finest at that altitude), 60 frames a second: near the pole the levels change lx every
 * few tenths of a degree, several times within the look-ahead's lead (NEXT_LEAD_S). At every
 * switch the new window is all here, delivered at least SWITCH_LEAD_S before and not dropped
 * since (a tile the viewer drops and asks for again is delivered again, later); whenever a
 * window takes other tiles without a switch (a new row or column), they were here at least
 * ROW_LEAD_S before. Here: 14 switches, the least lead 0.217 s (0.117 s with the first
 * change's window alone: a switch 7 frames after another), other moves 0.2 s. Until 6
 * December the viewer looked for the switch with its current lx's hysteresis applied over
 * the whole lead (and clipmap_level_lx kept an lx several steps coarser than the fit), so the
 * predicted window came and went — dropped 50 ms before the switch it was for — and the new
 * lx's ring (the row the window moves into next) was asked for only at the switch. */
#define SWITCH_LEAD_S 0.2
#define ROW_LEAD_S 0.1
static void over_the_pole(void **state)
{
	(void)state;
	ndeliveries = 0;
	struct rig g = rig_open(record_delivery);

	const double v = 10.0, dt = 1.0 / 60;
	int switches = 0, moves = 0;
	struct grid_quad was[NLEVELS];
	double min_switch = INFINITY, min_move = INFINITY;
	for (int f = 0; f * dt < 3.0; f++) {
		sim_now = f * dt;
		double s = 80.0 + v * sim_now, lat = s <= 90 ? s : 180 - s, lon = s <= 90 ? 20 : 200;
		aim_at(g.cm, lon, lat);
		for (int l = 4; l <= 7; l++) {
			const struct grid_quad *q = view_clipmap_target_of(g.cm, l);
			assert_non_null(q);
			bool moved = f > 0 && (q->tx0 != was[l].tx0 || q->ty0 != was[l].ty0 ||
					       q->ntx != was[l].ntx || q->nty != was[l].nty ||
					       q->lx != was[l].lx);
			bool switched = f > 0 && q->lx != was[l].lx;
			if (f > 20 && moved) { /* after the first third of a second (the motion's estimate) */
				struct tile_key k[GRID_WINDOW_MAX_KEYS];
				int nk = grid_quad_tiles(q, 0, k);
				double lead = INFINITY;
				for (int i = 0; i < nk; i++)
					lead = fmin(lead, sim_now - delivered_at(&k[i]));
				if (lead < (switched ? SWITCH_LEAD_S : ROW_LEAD_S))
					fail_msg("level %d at %.2f°%s (lx %d): a tile delivered %.3f s before",
						 l, lat, switched ? ", switching" : "", q->lx, lead);
				assert_int_equal(view_clipmap_update(g.cm, l), 1);
				if (switched)
					min_switch = fmin(min_switch, lead), switches++;
				else
					min_move = fmin(min_move, lead), moves++;
			}
			was[l] = *q;
		}
		view_clipmap_motion(g.cm, lon, lat, sim_now);
		ask(g.cm, g.s, g.w);
		while (view_clipmap_receive(g.cm, 0) > 0)
			;
		for (int l = 0; l < NLEVELS; l++)
			view_clipmap_update(g.cm, l);
	}
	printf("over the pole: %d switches (the least lead %.3f s), %d other moves (%.3f s)\n",
	       switches, min_switch, moves, min_move);
	assert_true(switches >= 10);
	rig_close(&g);
}

int main(void)
{
	const struct CMUnitTest tests[] = { cmocka_unit_test(look_ahead),
					    cmocka_unit_test(next_lx_window),
					    cmocka_unit_test(over_the_pole) };
	return cmocka_run_group_tests(tests, NULL, NULL);
}
