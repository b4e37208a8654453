/* Tests for a blend's b made only where its mask lets it through (node_type.lazy/needed,
 * jobtab's open_lazy), through the real planet loader, cache and scheduler:
 * - a mask that is 0 everywhere: b is never made, the blend gives a's bytes;
 * - a mask that is 1 everywhere: b is made for every key;
 * - a mask that is 0 on part of a level (land above a noise's sea level): with the parent
 *   level made first, b is made for exactly the tiles whose mask, or whose parent's mask, is
 *   not 0 on the whole tile (a job defers only where its parent found b not needed: jobtab's
 *   skip memory), and every blend tile — heights
 *   (add, mask), colours (multiply, over, mask) — has the bytes the blend gives when it is
 *   handed every input (what it made before there was a lazy input);
 * - the exceptions where a decides and b is needed even under a zero mask (a NaN height in
 *   a with over/mask, a transparent colour texel in a with over);
 * - b already cached when the blend is wanted: held, the same bytes;
 * - which blends of the shipped procedural planet defer b (only where that saves a noise).
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

#include "engine/cache.h"
#include "engine/planet.h"
#include "engine/sched.h"

#define T 64
#ifndef BLOCK_X
#define BLOCK_X 0
#define BLOCK_Y 28
#endif

static const char *const PLANET_INI =
	"[planet]\nname = lazy\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 10\n"
	/* continents: about half the planet above 0 m */
	"[node base]\ntype = noise\nkind = fbm\nseed = 1\noctaves = 3\nwavelength = 900000\n"
	"amplitude = 1000\n"
	"[node land]\ntype = height_filter\ninput = base\nscale = 0.01\nmin = 0\nmax = 1\n"
	"[node zero]\ntype = constant\nheight = 0\n"
	"[node one]\ntype = constant\nheight = 1\n"
	/* one b per blend, so each b's generations count that blend's needs alone */
	"[node b_zero]\ntype = noise\nkind = fbm\nseed = 2\noctaves = 4\nwavelength = 20000\n"
	"amplitude = 50\n"
	"[node b_one]\ntype = noise\nkind = fbm\nseed = 3\noctaves = 4\nwavelength = 20000\n"
	"amplitude = 50\n"
	"[node b_land]\ntype = noise\nkind = ridged\nseed = 4\noctaves = 4\nwavelength = 20000\n"
	"amplitude = 50\n"
	"[node b_mask]\ntype = noise\nkind = fbm\nseed = 5\noctaves = 4\nwavelength = 30000\n"
	"amplitude = 80\n"
	"[node add_zero]\ntype = blend\nmode = add\na = base\nb = b_zero\nmask = zero\n"
	"[node add_one]\ntype = blend\nmode = add\na = base\nb = b_one\nmask = one\n"
	"[node add_land]\ntype = blend\nmode = add\na = base\nb = b_land\nmask = land\n"
	"weight = -0.5\n"
	"[node mask_land]\ntype = blend\nmode = mask\na = base\nb = b_mask\nmask = land\n"
	"opacity = 0.7\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"[node tint_b]\ntype = ramp\ninput = b_land\nstops = -50 40 60 20, 50 250 240 200\n"
	"[node mult]\ntype = blend\nmode = multiply\na = tint\nb = tint_b\nmask = land\n"
	"[node over]\ntype = blend\nmode = over\na = tint\nb = tint_b\nmask = land\n"
	"[node cmask]\ntype = blend\nmode = mask\na = tint\nb = tint_b\nmask = land\n"
	"[layer height]\nnode = add_land\nformat = f32\n";

struct env {
	char path[64];
	struct planet *p;
	struct cache *c;
	struct sched *s;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	snprintf(e->path, sizeof e->path, "/tmp/test_blend_lazy_%d.ini", (int)getpid());
	FILE *f = fopen(e->path, "w");
	if (!f || fputs(PLANET_INI, f) < 0 || fclose(f))
		return -1;
	char err[256] = "";
	if (planet_load(e->path, &e->p, err)) {
		fprintf(stderr, "setup: %s\n", err);
		return -1;
	}
	e->c = cache_create(256u << 20);
	e->s = sched_create(&(struct sched_desc){ .cache = e->c, .workers = 2 });
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (e->s)
		sched_destroy(e->s);
	if (e->c)
		cache_destroy(e->c);
	if (e->p)
		planet_unref(e->p);
	unlink(e->path);
	free(e);
	return 0;
}

static struct node *node(struct env *e, const char *name)
{
	struct node *n = planet_find_node(e->p, name);
	assert_non_null(n);
	return n;
}

static struct tile_key tkey(const struct node *n, int lx, int ly, uint32_t x, uint32_t y)
{
	return (struct tile_key){ .node = n->hash, .lx = (uint8_t)lx, .ly = (uint8_t)ly, .x = x,
				  .y = y };
}

static struct tile *fetch(struct env *e, struct node *n, struct tile_key k)
{
	k.node = n->hash;
	struct want w = { .node = n, .cls = SCHED_VISIBLE, .key = k };
	struct tile *t = NULL;
	assert_int_equal(sched_fetch(e->s, &w, 1, &t), 0);
	assert_non_null(t);
	return t;
}

static uint64_t made(struct node *n) { return atomic_load(&n->generated); }

static uint64_t skipped(struct env *e)
{
	struct sched_stats st;
	sched_get_stats(e->s, &st);
	return st.skipped;
}

/* The blend n's tile at k as it is made with every input handed to it. */
static struct tile *eager(struct env *e, struct node *n, struct tile_key k)
{
	struct tile *in[3];
	for (int i = 0; i < 3; i++)
		in[i] = fetch(e, n->in[i], k);
	k.node = n->hash;
	struct tile *t = tile_create(&k, n->out, T);
	struct gen_ctx g = { 0 };
	assert_int_equal(n->type->generate(n, &g, &k, in, 3, t), 0);
	gen_ctx_fini(&g);
	for (int i = 0; i < 3; i++)
		tile_unref(in[i]);
	return t;
}

static bool all_zero(const struct tile *m)
{
	const float *f = tile_f32(m);
	for (size_t i = 0; i < (size_t)T * T; i++)
		if (f[i] > 0)
			return false;
	return true;
}

/* Under a mask that is 0 everywhere, b is made only for the top level's keys (no parent to
 * tell that deferring pays: made at once, as before there were lazy inputs); below it, with
 * the parent made first, never. The blend gives a's bytes throughout. */
static void zero_mask_makes_nothing(void **state)
{
	struct env *e = *state;
	struct node *bl = node(e, "add_zero"), *b = node(e, "b_zero"), *a = node(e, "base");
	uint64_t s0 = skipped(e);
	int n = 0;
	for (int ly = 0; ly <= 6; ly++)
		for (uint32_t y = 0; y < 2 && y < (1u << ly); y++)
			for (uint32_t x = 0; x < 2; x++) {
				struct tile_key k = tkey(bl, ly + 1, ly, x, y);
				struct tile *t = fetch(e, bl, k), *ta = fetch(e, a, k);
				assert_memory_equal(t->data, ta->data, t->nbytes);
				tile_unref(t);
				tile_unref(ta);
				n++;
			}
	assert_int_equal(made(b), 2); /* (1, 0, 0..1, 0) */
	assert_true(skipped(e) - s0 >= (uint64_t)n - 2);
}

static void one_mask_makes_b(void **state)
{
	struct env *e = *state;
	struct node *bl = node(e, "add_one"), *b = node(e, "b_one");
	for (uint32_t x = 0; x < 4; x++) {
		struct tile_key k = tkey(bl, 4, 3, x, 2);
		struct tile *t = fetch(e, bl, k), *ref = eager(e, bl, k);
		assert_memory_equal(t->data, ref->data, t->nbytes);
		tile_unref(t);
		tile_unref(ref);
	}
	assert_int_equal(made(b), 4);
}

/* A block of 16 × 8 tiles of level (7, 6) round a coast, of each blend masked by `land`: b is
 * made for exactly the tiles where land is not 0 throughout or the parent's land was not 0
 * throughout, and the bytes equal the eager blend's. */
static void partial_mask_level(void **state)
{
	struct env *e = *state;
	static const char *const names[] = { "add_land", "mask_land", "mult", "over", "cmask" };
	const int lx = 7, ly = 6;
	const uint32_t W = 16, H = 8, X0 = BLOCK_X, Y0 = BLOCK_Y;
	struct node *land = node(e, "land");
	struct node *bnodes[2] = { node(e, "b_land"), node(e, "b_mask") };
	/* The parent level first, as a flight makes it: where a parent's mask was 0 on the whole
	 * tile its children defer b (and skip it where theirs is 0 too); elsewhere b is made at
	 * once, as before there were lazy inputs. */
	for (int i = 0; i < 5; i++) {
		struct node *bl = node(e, names[i]);
		for (uint32_t y = 0; y < H / 2; y++)
			for (uint32_t x = 0; x < W / 2; x++)
				tile_unref(fetch(e, bl, tkey(bl, lx - 1, ly - 1, X0 / 2 + x, Y0 / 2 + y)));
	}
	uint64_t m0[2] = { made(bnodes[0]), made(bnodes[1]) };
	int zero = 0, predicted = 0, expect_made = 0;
	for (uint32_t y = 0; y < H; y++)
		for (uint32_t x = 0; x < W; x++) {
			uint32_t cx = X0 + x, cy = Y0 + y;
			struct tile *p = fetch(e, land, tkey(land, lx - 1, ly - 1, cx >> 1, cy >> 1));
			struct tile *m = fetch(e, land, tkey(land, lx, ly, cx, cy));
			bool pz = all_zero(p), z = all_zero(m);
			zero += z;
			predicted += pz;
			expect_made += !pz || !z;
			tile_unref(m);
			tile_unref(p);
		}
	int nonzero = (int)(W * H) - zero;
	print_message("level (%d, %d) from tile (%u, %u): %d of %u tiles with land 0 throughout, "
		      "%d foreseen from the parent's mask\n", lx, ly, X0, Y0, zero, W * H, predicted);
	assert_true(zero >= 8 && nonzero >= 8 && predicted >= 8); /* each case, many times */
	struct tile *got[5][16 * 8];
	for (int i = 0; i < 5; i++) {
		struct node *bl = node(e, names[i]);
		for (uint32_t y = 0; y < H; y++)
			for (uint32_t x = 0; x < W; x++)
				got[i][y * W + x] = fetch(e, bl, tkey(bl, lx, ly, X0 + x, Y0 + y));
	}
	/* b_land feeds add_land and (through tint_b) mult, over, cmask; b_mask feeds mask_land:
	 * each is made once per key whose mask lets it through or whose parent's mask did not
	 * foresee a zero, never elsewhere */
	assert_true(expect_made < (int)(W * H));
	assert_int_equal(made(bnodes[0]) - m0[0], expect_made);
	assert_int_equal(made(bnodes[1]) - m0[1], expect_made);
	for (int i = 0; i < 5; i++) {
		struct node *bl = node(e, names[i]);
		for (uint32_t y = 0; y < H; y++)
			for (uint32_t x = 0; x < W; x++) {
				struct tile *t = got[i][y * W + x];
				struct tile *ref = eager(e, bl, tkey(bl, lx, ly, X0 + x, Y0 + y));
				if (memcmp(t->data, ref->data, t->nbytes))
					fail_msg("%s (%d, %d, %u, %u): bytes differ from the eager blend",
						 names[i], lx, ly, X0 + x, Y0 + y);
				tile_unref(t);
				tile_unref(ref);
			}
	}
}

/* b already cached (wanted on its own first): the blend under a zero mask still gives a. */
static void cached_b_same_bytes(void **state)
{
	struct env *e = *state;
	struct node *bl = node(e, "add_zero"), *b = node(e, "b_zero"), *a = node(e, "base");
	struct tile_key k = tkey(bl, 9, 8, 17, 40);
	uint64_t m0 = made(b);
	struct tile *tb = fetch(e, b, k);
	struct want w[2] = { { .node = bl, .cls = SCHED_VISIBLE, .key = tkey(bl, 9, 8, 17, 40) },
			     { .node = b, .cls = SCHED_VISIBLE, .key = tkey(b, 9, 8, 18, 40) } };
	struct tile *out[2] = { NULL, NULL };
	assert_int_equal(sched_fetch(e->s, w, 2, out), 0);
	struct tile *ta = fetch(e, a, k);
	assert_memory_equal(out[0]->data, ta->data, ta->nbytes);
	assert_int_equal(made(b) - m0, 2); /* the two wanted on their own, none for the blend */
	tile_unref(out[0]);
	tile_unref(out[1]);
	tile_unref(ta);
	tile_unref(tb);
}

/* needed() with a zero mask: b is still needed where a decides the texel. */
static void a_decides_exceptions(void **state)
{
	struct env *e = *state;
	struct tile_key k = { 0 };
	struct tile *mask = tile_create(&k, PIX_HEIGHT, T), *h = tile_create(&k, PIX_HEIGHT, T);
	struct tile *c = tile_create(&k, PIX_COLOR, T);
	memset(mask->data, 0, mask->nbytes);
	for (size_t i = 0; i < (size_t)T * T; i++) {
		tile_f32(h)[i] = (float)i;
		memcpy(c->data + 4 * i, (uint8_t[4]){ 10, 20, 30, 255 }, 4);
	}
	struct node *hmask = node(e, "mask_land"), *hadd = node(e, "add_land");
	struct node *cover = node(e, "over"), *cmult = node(e, "mult");
	struct tile *hin[3] = { h, NULL, mask }, *cin[3] = { c, NULL, mask };
	assert_false(hmask->type->needed(hmask, 1, hin, 3));
	assert_false(cover->type->needed(cover, 1, cin, 3));
	tile_f32(h)[77] = NAN; /* no data in a: over and mask take b there */
	assert_true(hmask->type->needed(hmask, 1, hin, 3));
	assert_false(hadd->type->needed(hadd, 1, hin, 3)); /* add keeps a's NaN */
	c->data[4 * 300 + 3] = 0; /* a transparent texel: over clears it only with b */
	assert_true(cover->type->needed(cover, 1, cin, 3));
	assert_false(cmult->type->needed(cmult, 1, cin, 3)); /* multiply keeps a's alpha */
	tile_f32(mask)[4000] = 1e-6f; /* any weight above 0: b is read */
	c->data[4 * 300 + 3] = 255;
	assert_true(cmult->type->needed(cmult, 1, cin, 3));
	tile_f32(mask)[4000] = NAN; /* NaN weighs 0 */
	assert_false(cmult->type->needed(cmult, 1, cin, 3));
	tile_unref(mask);
	tile_unref(h);
	tile_unref(c);
}

/* Which blends of the shipped procedural planet defer b: those where skipping b saves a
 * noise that neither a nor the mask needs anyway (node_exclusive_costly). */
static void shipped_choice(void **state)
{
	(void)state;
	struct planet *p = NULL;
	char err[256] = "";
	if (planet_load("conf/planets/procedural.ini", &p, err))
		fail_msg("%s", err);
	static const struct {
		const char *name;
		bool lazy;
	} want[] = {
		{ "relief", true },	/* ranges, only in the uplands */
		{ "mountains", true },	/* massifs, only where alpine */
		{ "rocky", true },	/* outcrops, only where rocky */
		{ "tint_rock", true },	/* outcrops again: a needs them only through rocky's mask */
		{ "varied", true },	/* patches, only on land */
		{ "terrain", false },	/* b a constant: nothing to save */
		{ "land", false },	/* b a height filter of the terrain, needed anyway */
	};
	for (size_t i = 0; i < sizeof want / sizeof want[0]; i++) {
		struct node *n = planet_find_node(p, want[i].name);
		assert_non_null(n);
		bool lazy = n->type->lazy(n, NULL) != 0;
		if (lazy != want[i].lazy)
			fail_msg("%s: b %s lazy", want[i].name, lazy ? "is" : "is not");
	}
	planet_unref(p);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(zero_mask_makes_nothing),
		cmocka_unit_test(one_mask_makes_b),
		cmocka_unit_test(partial_mask_level),
		cmocka_unit_test(cached_b_same_bytes),
		cmocka_unit_test(a_decides_exceptions),
		cmocka_unit_test(shipped_choice),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
