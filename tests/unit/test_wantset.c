/* wantset tests: the want table and ready heap alone, with hand-made nodes (only their hash
 * and address matter) and tiles whose reference counts show what the set still holds. The
 * order tiles leave the heap, what a WANT carries over (sent stays sent, ready stays ready),
 * what it drops and counts, and how a reload's rebind treats changed and vanished nodes. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdlib.h>

#include "daemon/wantset.h"
#include "engine/node.h"
#include "engine/planet.h"
#include "engine/sched.h"
#include "engine/tile.h"

static struct planet planet4 = { .tile_size = 4 }; /* 4 × 4 f32: 64 bytes a tile */
static struct node node_a = { .hash = 0xa, .planet = &planet4, .out = PIX_HEIGHT },
		   node_b = { .hash = 0xb, .planet = &planet4, .out = PIX_HEIGHT },
		   node_c = { .hash = 0xc, .planet = &planet4, .out = PIX_HEIGHT };

static struct wantset_entry ent(struct node *n, uint32_t pid, int ly, uint32_t x, uint32_t y,
				uint8_t cls, uint32_t order)
{
	return (struct wantset_entry){ .key = { .node = n->hash, .lx = (uint8_t)(ly + 1),
						.ly = (uint8_t)ly, .x = x, .y = y },
				       .node = n, .pid = pid, .seq = 7, .order = order,
				       .cls = cls };
}

static struct tile *mk_tile(const struct tile_key *k)
{
	return tile_create(k, PIX_HEIGHT, 4);
}

#define ALL UINT64_MAX /* no budget for held tiles */
static bool parked;

static int refs(struct tile *t)
{
	return atomic_load(&t->refs);
}

static size_t nwanted(const struct wantset *ws)
{
	size_t n;
	bool left;
	free(wantset_wants_within(ws, UINT64_MAX, NULL, NULL, &n, &left));
	return n;
}

/* Five wants of planet 1, in want order 0..4: levels 5, 2, 2 (visible), 0 (prefetch), 9. */
static void five_entries(struct wantset_entry add[5])
{
	add[0] = ent(&node_a, 1, 5, 0, 0, SCHED_VISIBLE, 0);
	add[1] = ent(&node_a, 1, 2, 1, 0, SCHED_VISIBLE, 1);
	add[2] = ent(&node_a, 1, 2, 0, 0, SCHED_VISIBLE, 2);
	add[3] = ent(&node_a, 1, 0, 0, 0, SCHED_PREFETCH, 3);
	add[4] = ent(&node_a, 1, 9, 0, 0, SCHED_VISIBLE, 4);
}

/* Tiles leave the heap by class, then level coarse first, then want order, whatever the order
 * they became ready in. */
static void test_ready_order(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry add[5];
	five_entries(add);
	size_t n = sizeof add / sizeof add[0];
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, add, n, &d);
	assert_int_equal(ws.n, n);
	assert_int_equal(nwanted(&ws), n);
	assert_int_equal(d.dropped, 0);
	for (size_t i = n; i-- > 0;)
		assert_true(wantset_ready(&ws, &add[i].key, mk_tile(&add[i].key), 0, false, ALL, &parked));
	assert_int_equal(wantset_nready(&ws), n);
	assert_int_equal(nwanted(&ws), 0);
	const size_t expect[] = { 1, 2, 0, 4, 3 }; /* ly 2 (order 1, 2), ly 5, ly 9, prefetch */
	for (size_t i = 0; i < n; i++) {
		struct wantset_entry *e = wantset_pop(&ws);
		assert_non_null(e);
		assert_int_equal(e->order, expect[i]);
		assert_int_equal(e->state, WS_READY);
		wantset_sent(&ws, e);
		assert_int_equal(e->state, WS_SENT);
		assert_null(e->t);
	}
	assert_null(wantset_pop(&ws));
	wantset_fini(&ws);
}

/* A report for a key not in the set, or a second one, is refused and its tile released. */
static void test_ready_unknown(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry e = ent(&node_a, 1, 3, 2, 1, SCHED_VISIBLE, 0);
	struct tile *t = mk_tile(&e.key);
	tile_ref(t);
	assert_false(wantset_ready(&ws, &e.key, t, 0, false, ALL, &parked)); /* empty set */
	assert_int_equal(refs(t), 1);
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, &e, 1, &d);
	tile_ref(t);
	assert_true(wantset_ready(&ws, &e.key, t, 0, false, ALL, &parked));
	tile_ref(t);
	assert_false(wantset_ready(&ws, &e.key, t, 0, false, ALL, &parked)); /* repeated */
	assert_int_equal(refs(t), 2);
	/* A failed generation is ready too, without a tile. */
	struct wantset_entry f = ent(&node_a, 1, 3, 3, 1, SCHED_VISIBLE, 1);
	struct wantset_entry both[] = { e, f };
	wantset_replace(&ws, 1, both, 2, &d);
	assert_true(wantset_ready(&ws, &f.key, NULL, -5, false, ALL, &parked));
	assert_int_equal(wantset_nready(&ws), 2);
	wantset_fini(&ws); /* releases the ready tile */
	assert_int_equal(refs(t), 1);
	tile_unref(t);
}

/* A WANT replaces its planet's part: a kept key keeps its state (a sent tile is not wanted
 * again, a ready one stays ready with its tile), what leaves unsent is dropped (ready ones
 * also stale, their tiles released), other planets' entries stay untouched, a duplicate key
 * counts once. */
static void test_replace_carries_state(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry p1[] = {
		ent(&node_a, 1, 1, 0, 0, SCHED_VISIBLE, 0), /* will be sent, stays */
		ent(&node_a, 1, 1, 1, 0, SCHED_VISIBLE, 1), /* ready, stays */
		ent(&node_a, 1, 1, 2, 0, SCHED_VISIBLE, 2), /* ready, leaves: stale */
		ent(&node_a, 1, 1, 3, 0, SCHED_VISIBLE, 3), /* wanted, leaves: dropped */
		ent(&node_a, 1, 1, 0, 1, SCHED_VISIBLE, 4), /* sent, leaves: not dropped */
	};
	struct wantset_entry p2 = ent(&node_b, 2, 4, 0, 0, SCHED_PREFETCH, 0);
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, p1, 5, &d);
	wantset_replace(&ws, 2, &p2, 1, &d);
	assert_int_equal(ws.n, 6);
	struct tile *t[5];
	for (int i = 0; i < 5; i++)
		t[i] = tile_ref(mk_tile(&p1[i].key)); /* one reference for the test */
	tile_unref(t[3]); /* never reported ready: the set never holds it */
	for (int i = 0; i < 5; i++)
		if (i != 3)
			assert_true(wantset_ready(&ws, &p1[i].key, t[i], 0, false, ALL, &parked));
	struct wantset_entry *e = wantset_pop(&ws);
	assert_int_equal(e->order, 0);
	wantset_sent(&ws, e);
	/* pop the next two, send only the one of order 4 */
	struct wantset_entry *a = wantset_pop(&ws), *b = wantset_pop(&ws);
	assert_int_equal(a->order, 1);
	assert_int_equal(b->order, 2);
	wantset_replace(&ws, 1, p1, 5, &d); /* the same set: rebuilds the heap */
	assert_int_equal(wantset_nready(&ws), 3);
	while ((e = wantset_pop(&ws)) && e->order != 4)
		;
	assert_non_null(e);
	wantset_sent(&ws, e);

	struct wantset_entry next[] = {
		ent(&node_a, 1, 1, 0, 0, SCHED_VISIBLE, 0), ent(&node_a, 1, 1, 1, 0, SCHED_VISIBLE, 1),
		ent(&node_a, 1, 1, 1, 0, SCHED_VISIBLE, 2), /* duplicate */
		ent(&node_a, 1, 2, 5, 5, SCHED_VISIBLE, 3), /* new */
	};
	d = (struct wantset_drops){ 0 };
	wantset_replace(&ws, 1, next, 4, &d);
	assert_int_equal(d.dropped, 2); /* x 2 (ready) and x 3 (wanted) */
	assert_int_equal(d.stale, 1);	/* x 2 */
	assert_int_equal(ws.n, 4);	/* p2's entry and three of next */
	assert_int_equal(refs(t[0]), 1); /* sent: released */
	assert_int_equal(refs(t[1]), 2); /* still ready, held by the set */
	assert_int_equal(refs(t[2]), 1); /* stale: released */
	assert_int_equal(refs(t[4]), 1);
	long i0 = wantset_find(&ws, &next[0].key), i1 = wantset_find(&ws, &next[1].key);
	assert_true(i0 >= 0 && i1 >= 0);
	assert_int_equal(ws.e[i0].state, WS_SENT);
	assert_int_equal(ws.e[i1].state, WS_READY);
	assert_ptr_equal(ws.e[i1].t, t[1]);
	assert_int_equal(ws.e[i1].order, 1); /* the new want order */
	assert_int_equal(wantset_nready(&ws), 1);
	assert_int_equal(nwanted(&ws), 2); /* the new key and p2's */
	long j = wantset_find(&ws, &p2.key);
	assert_true(j >= 0);
	assert_int_equal(ws.e[j].pid, 2);
	assert_int_equal(wantset_find(&ws, &p1[3].key), -1);
	wantset_fini(&ws);
	for (int i = 0; i < 5; i++) {
		assert_int_equal(refs(t[i]), 1);
		tile_unref(t[i]);
	}
}

struct binding {
	struct node *for_pid[3]; /* NULL: the planet is gone */
};

static struct node *resolve(void *ud, uint32_t pid, uint8_t layer)
{
	(void)layer;
	return ((struct binding *)ud)->for_pid[pid];
}

/* A reload's rebind: a layer whose node hash is unchanged keeps its entries' state; a changed
 * one is wanted afresh under the new key (a ready tile of the old node is stale); a planet
 * that is gone takes its unsent entries with it (dropped). */
static void test_rebind(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry p1[] = { ent(&node_a, 1, 2, 0, 0, SCHED_VISIBLE, 0),
				      ent(&node_a, 1, 2, 1, 0, SCHED_VISIBLE, 1) };
	struct wantset_entry p2[] = { ent(&node_b, 2, 2, 0, 0, SCHED_VISIBLE, 0),
				      ent(&node_b, 2, 2, 1, 0, SCHED_VISIBLE, 1),
				      ent(&node_b, 2, 2, 2, 0, SCHED_VISIBLE, 2) };
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, p1, 2, &d);
	wantset_replace(&ws, 2, p2, 3, &d);
	struct tile *t = tile_ref(mk_tile(&p1[1].key));
	assert_true(wantset_ready(&ws, &p1[1].key, t, 0, false, ALL, &parked));
	assert_true(wantset_ready(&ws, &p2[0].key, mk_tile(&p2[0].key), 0, false, ALL, &parked));
	wantset_sent(&ws, wantset_pop(&ws)); /* p1's x 1 or p2's x 0: both ly 2, order 0 vs 1 */
	/* p2's x 0 has order 0: it went; p1's x 1 is still ready */
	long k = wantset_find(&ws, &p2[0].key);
	assert_int_equal(ws.e[k].state, WS_SENT);

	/* Planet 1's layer now reads node c (a changed hash); planet 2 is unchanged. */
	struct binding b = { .for_pid = { NULL, &node_c, &node_b } };
	size_t regen = wantset_rebind(&ws, resolve, &b, &d);
	assert_int_equal(regen, 2);
	assert_int_equal(d.stale, 1);
	assert_int_equal(d.dropped, 0);
	assert_int_equal(refs(t), 1);
	assert_int_equal(wantset_nready(&ws), 0);
	assert_int_equal(wantset_find(&ws, &p1[0].key), -1);
	struct tile_key nk = p1[1].key;
	nk.node = node_c.hash;
	long i = wantset_find(&ws, &nk);
	assert_true(i >= 0);
	assert_ptr_equal(ws.e[i].node, &node_c);
	assert_int_equal(ws.e[i].state, WS_WANTED);
	k = wantset_find(&ws, &p2[0].key);
	assert_int_equal(ws.e[k].state, WS_SENT);
	assert_int_equal(nwanted(&ws), 4);

	/* Planet 2 is gone: its two unsent entries are dropped, the sent one just leaves. */
	b.for_pid[2] = NULL;
	d = (struct wantset_drops){ 0 };
	regen = wantset_rebind(&ws, resolve, &b, &d);
	assert_int_equal(regen, 0);
	assert_int_equal(d.dropped, 2);
	assert_int_equal(ws.n, 2);
	assert_int_equal(wantset_find(&ws, &p2[1].key), -1);
	wantset_fini(&ws);
	tile_unref(t);
}

/* Held tiles stay within the budget: beyond it a ready tile is parked (released, still READY
 * in its place in the order); popped, it gets its tile back or is wanted again; held bytes
 * follow sends, replaces and rewants. */
static void test_held_budget(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry add[] = {
		ent(&node_a, 1, 5, 0, 0, SCHED_VISIBLE, 0), ent(&node_a, 1, 2, 1, 0, SCHED_VISIBLE, 1),
		ent(&node_a, 1, 2, 0, 0, SCHED_VISIBLE, 2), ent(&node_a, 1, 7, 0, 0, SCHED_VISIBLE, 3),
	};
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, add, 4, &d);
	struct tile *t[4];
	for (int i = 0; i < 4; i++) {
		t[i] = mk_tile(&add[i].key);
		tile_ref(t[i]); /* the test's, as the cache's would be */
	}
	size_t one = t[0]->nbytes;
	uint64_t budget = 2 * one; /* two tiles */
	assert_true(wantset_ready(&ws, &add[0].key, t[0], 0, false, budget, &parked));
	assert_false(parked);
	assert_true(wantset_ready(&ws, &add[3].key, t[3], 0, false, budget, &parked));
	assert_false(parked);
	assert_int_equal(wantset_held(&ws), 2 * one);
	assert_true(wantset_ready(&ws, &add[1].key, t[1], 0, false, budget, &parked));
	assert_true(parked);
	assert_int_equal(refs(t[1]), 1); /* released */
	assert_true(wantset_ready(&ws, &add[2].key, t[2], 0, false, budget, &parked));
	assert_true(parked);
	assert_int_equal(wantset_held(&ws), 2 * one);
	assert_int_equal(wantset_nready(&ws), 4);
	assert_int_equal(wantset_nparked(&ws), 2);
	/* Coarse first all the same: order 1 (parked), 2 (parked), 0, 3. */
	struct wantset_entry *e = wantset_pop(&ws);
	assert_int_equal(e->order, 1);
	assert_true(wantset_parked(e));
	wantset_unpark(&ws, e, tile_ref(t[1])); /* found in the cache */
	assert_int_equal(wantset_held(&ws), 3 * one);
	assert_int_equal(wantset_nparked(&ws), 1);
	wantset_sent(&ws, e);
	assert_int_equal(wantset_held(&ws), 2 * one);
	assert_int_equal(refs(t[1]), 1);
	e = wantset_pop(&ws);
	assert_int_equal(e->order, 2);
	assert_true(wantset_parked(e));
	wantset_rewant(&ws, e); /* not in the cache any more */
	assert_int_equal(nwanted(&ws), 1);
	assert_int_equal(wantset_nparked(&ws), 0);
	assert_true(wantset_ready(&ws, &add[2].key, tile_ref(t[2]), 0, false, ALL, &parked));
	assert_false(parked);
	assert_int_equal(wantset_held(&ws), 3 * one);
	/* A replace that drops the held tiles drops their bytes. */
	wantset_replace(&ws, 1, &add[1], 1, &d);
	assert_int_equal(wantset_held(&ws), 0);
	for (int i = 0; i < 4; i++) {
		assert_int_equal(refs(t[i]), 1);
		tile_unref(t[i]);
	}
	/* A failed generation is never taken for a parked tile. */
	wantset_replace(&ws, 1, add, 1, &d);
	assert_true(wantset_ready(&ws, &add[0].key, NULL, -5, false, 0, &parked));
	e = wantset_pop(&ws);
	assert_false(wantset_parked(e));
	assert_int_equal(e->err, -5);
	wantset_fini(&ws);
	/* The parked count (what pauses a session) follows replaces and sends: a key that stays
	 * keeps its parked entry, one that leaves takes it along, a parked entry sent as it is
	 * (popped, looked up, sent) counts no more. */
	wantset_init(&ws);
	wantset_replace(&ws, 1, add, 4, &d);
	assert_true(wantset_ready(&ws, &add[0].key, NULL, 0, true, ALL, &parked));
	assert_true(wantset_ready(&ws, &add[3].key, NULL, 0, true, ALL, &parked));
	assert_int_equal(wantset_nparked(&ws), 2);
	wantset_replace(&ws, 1, add, 3, &d); /* add[3] leaves */
	assert_int_equal(wantset_nparked(&ws), 1);
	e = wantset_pop(&ws);
	assert_true(wantset_parked(e));
	wantset_sent(&ws, e);
	assert_int_equal(wantset_nparked(&ws), 0);
	wantset_fini(&ws);
}

static bool made_ly9(void *ud, const struct tile_key *k)
{
	(void)ud;
	return k->ly == 9;
}

/* What a session asks the scheduler for within its credit: the WANTED entries in the order
 * the scheduler serves them (class, level coarse first, want order), as many as fit beside the
 * READY entries not yet sent (held or parked); at least one when none is READY; beyond the
 * credit, those whose tile exists already. */
static void test_wants_within(void **state)
{
	(void)state;
	struct wantset ws;
	wantset_init(&ws);
	struct wantset_entry add[5];
	five_entries(add);
	struct wantset_drops d = { 0 };
	wantset_replace(&ws, 1, add, 5, &d);
	const uint64_t one = 64;
	assert_int_equal(wantset_entry_bytes(&ws.e[0]), one);
	size_t n;
	bool left;
	struct want *w = wantset_wants_within(&ws, 3 * one, NULL, NULL, &n, &left);
	assert_int_equal(n, 3);
	assert_true(left);
	assert_true(grid_key_equal(&w[0].key, &add[1].key)); /* ly 2, order 1 */
	assert_true(grid_key_equal(&w[1].key, &add[2].key)); /* ly 2, order 2 */
	assert_true(grid_key_equal(&w[2].key, &add[0].key)); /* ly 5 */
	assert_int_equal(w[2].cls, SCHED_VISIBLE);
	free(w);
	/* Beyond the credit, a tile that exists already (the cache holds it) comes too. */
	w = wantset_wants_within(&ws, 3 * one, made_ly9, NULL, &n, &left);
	assert_int_equal(n, 4);
	assert_true(left); /* the prefetch entry */
	assert_true(grid_key_equal(&w[3].key, &add[4].key));
	free(w);
	w = wantset_wants_within(&ws, UINT64_MAX, NULL, NULL, &n, &left);
	assert_int_equal(n, 5);
	assert_false(left);
	assert_true(grid_key_equal(&w[3].key, &add[4].key)); /* ly 9 */
	assert_true(grid_key_equal(&w[4].key, &add[3].key)); /* prefetch last */
	free(w);
	/* Nothing READY: one entry even when it does not fit. */
	w = wantset_wants_within(&ws, 0, NULL, NULL, &n, &left);
	assert_int_equal(n, 1);
	assert_true(left);
	free(w);
	/* Two READY (one held, one parked) take two tiles' room from the credit. */
	assert_true(wantset_ready(&ws, &add[1].key, mk_tile(&add[1].key), 0, false, ALL, &parked));
	assert_true(wantset_ready(&ws, &add[2].key, NULL, 0, true, ALL, &parked));
	assert_true(parked);
	w = wantset_wants_within(&ws, 3 * one, NULL, NULL, &n, &left);
	assert_int_equal(n, 1);
	assert_true(left);
	assert_true(grid_key_equal(&w[0].key, &add[0].key));
	free(w);
	w = wantset_wants_within(&ws, one, NULL, NULL, &n, &left); /* no room left: none */
	assert_int_equal(n, 0);
	assert_true(left);
	free(w);
	/* Sent entries take none. */
	wantset_sent(&ws, wantset_pop(&ws));
	wantset_sent(&ws, wantset_pop(&ws));
	w = wantset_wants_within(&ws, 3 * one, NULL, NULL, &n, &left);
	assert_int_equal(n, 3);
	assert_false(left);
	free(w);
	wantset_fini(&ws);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_ready_order),
		cmocka_unit_test(test_ready_unknown),
		cmocka_unit_test(test_replace_carries_state),
		cmocka_unit_test(test_rebind),
		cmocka_unit_test(test_held_budget),
		cmocka_unit_test(test_wants_within),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
