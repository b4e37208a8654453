/* test_planet — the planet loader: good planets (bodies, tile size, layers, graph order), every
 * class of config error with its file:line: key, the content-hash properties, dot output, the
 * node-type registry and the constant node. Graph tests use three test-only node types with
 * input slots (t_mix, t_tint, t_shade) next to the built-in ones, through planet_load_types.
 * Planet sets: one image cache shared by every file node of every planet, and a reload with
 * that cache after a file was rewritten reads the new pixels.
 * Fixtures live in tests/data/planets/ (CLIPMAP_TEST_DATA overrides tests/data). */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "common/geo.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "engine/planets.h"

/* ---- test-only node types ---- */

static int t_height_out(struct node *n, struct node_parse *p)
{
	double k;
	n->out = PIX_HEIGHT;
	return np_double(p, "k", 1.0, -100, 100, &k);
}

static int t_color_out(struct node *n, struct node_parse *p)
{
	double gain;
	n->out = PIX_COLOR;
	return np_double(p, "gain", 1.0, 0, 10, &gain);
}

static int t_normal_out(struct node *n, struct node_parse *p)
{
	(void)p;
	n->out = PIX_NORMAL;
	return 0;
}

static int t_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
		      struct tile *const *in, int nin, struct tile *out)
{
	(void)n, (void)g, (void)k, (void)in, (void)nin;
	memset(out->data, 0, out->nbytes);
	return 0;
}

static const struct node_slot mix_slots[] = {
	{ .name = "a", .type = PIX_HEIGHT },
	{ .name = "b", .type = PIX_HEIGHT, .optional = true },
};
static const struct node_slot tint_slots[] = { { .name = "input", .type = PIX_COLOR } };
static const struct node_slot shade_slots[] = { { .name = "height", .type = PIX_HEIGHT } };

static const struct node_type t_mix = {
	.name = "t_mix", .doc = "test: a + k·b", .version = 1, .slots = mix_slots, .nslots = 2,
	.create = t_height_out, .generate = t_generate,
};
static const struct node_type t_tint = {
	.name = "t_tint", .doc = "test: colour filter", .version = 1, .slots = tint_slots,
	.nslots = 1, .create = t_color_out, .generate = t_generate,
};
static const struct node_type t_shade = {
	.name = "t_shade", .doc = "test: normals", .version = 1, .slots = shade_slots,
	.nslots = 1, .create = t_normal_out, .generate = t_generate,
};

/* The built-in types plus the test types, NULL-terminated. */
static const struct node_type *const *test_types(void)
{
	static const struct node_type *types[64];
	if (!types[0]) {
		size_t n = 0;
		for (const struct node_type *const *t = node_types_all(); *t && n < 60; t++)
			types[n++] = *t;
		types[n++] = &t_mix;
		types[n++] = &t_tint;
		types[n++] = &t_shade;
		types[n] = NULL;
	}
	return types;
}

/* ---- helpers ---- */

static char tmpdir[64];

static int setup(void **state)
{
	(void)state;
	snprintf(tmpdir, sizeof tmpdir, "/tmp/test_planet.XXXXXX");
	return mkdtemp(tmpdir) ? 0 : -1;
}

static int teardown(void **state)
{
	(void)state;
	char path[128];
	snprintf(path, sizeof path, "%s/p.ini", tmpdir);
	unlink(path);
	snprintf(path, sizeof path, "%s/q.ini", tmpdir);
	unlink(path);
	return rmdir(tmpdir);
}

static const char *data_dir(void)
{
	const char *d = getenv("CLIPMAP_TEST_DATA");
	return d ? d : "tests/data";
}

static void fixture(const char *name, char path[256])
{
	snprintf(path, 256, "%s/planets/%s", data_dir(), name);
}

/* Writes text to tmpdir/<file> and loads it with the test types. */
static int load_text(const char *file, const char *text, struct planet **p, char err[256])
{
	char path[128];
	snprintf(path, sizeof path, "%s/%s", tmpdir, file);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	assert_int_equal(fputs(text, f) >= 0, 1);
	assert_int_equal(fclose(f), 0);
	err[0] = '\0';
	return planet_load_types(path, test_types(), p, err);
}

static struct planet *load_ok(const char *text)
{
	struct planet *p = NULL;
	char err[256];
	int rc = load_text("p.ini", text, &p, err);
	if (rc)
		fail_msg("load failed (%d): %s", rc, err);
	return p;
}

static void load_fails(const char *text, const char *expect)
{
	struct planet *p = NULL;
	char err[256];
	int rc = load_text("p.ini", text, &p, err);
	if (rc != -EINVAL)
		fail_msg("expected -EINVAL for \"%s\", got %d (%s)", expect, rc, err);
	assert_null(p);
	if (!strstr(err, expect))
		fail_msg("error \"%s\" lacks \"%s\"", err, expect);
}

static uint64_t hash_of(const struct planet *p, const char *name)
{
	struct node *n = planet_find_node(p, name);
	if (!n)
		fail_msg("no node %s", name);
	return n->hash;
}

/* ---- registry and the constant node ---- */

static void registry(void **state)
{
	(void)state;
	assert_ptr_equal(node_type_find("constant"), &node_type_constant);
	assert_null(node_type_find("bogus"));
	assert_null(node_type_find(""));
	size_t n = 0;
	for (const struct node_type *const *t = node_types_all(); *t; t++, n++) {
		const struct node_type *ty = *t;
		assert_non_null(ty->name);
		assert_non_null(ty->doc);
		assert_non_null(ty->create);
		assert_non_null(ty->generate);
		assert_true(ty->version > 0);
		assert_true(ty->nslots >= 0 && ty->nslots <= NODE_MAX_INPUTS);
		assert_ptr_equal(node_type_find(ty->name), ty);
		for (const struct node_type *const *u = node_types_all(); u != t; u++)
			assert_string_not_equal((*u)->name, ty->name);
	}
	assert_true(n >= 1);
}

/* A node built by hand from an INI snippet, as the loader would. */
static int hand_node(struct node *n, const char *name, const struct node_type *t,
		     struct planet *p, struct ini_file **ini, const char *text, char err[256])
{
	memset(n, 0, sizeof *n);
	assert_int_equal(ini_parse("t.ini", text, strlen(text), ini, err), 0);
	struct ini_section *sec = &(*ini)->sections[0];
	struct ini_entry *te = ini_find(sec, "type");
	if (te)
		te->used = true;
	for (int i = 0; i < t->nslots; i++) {
		struct ini_entry *e = ini_find(sec, t->slots[i].name);
		if (e)
			e->used = true;
	}
	n->name = (char *)name;
	n->planet = p;
	n->line = sec->line;
	return node_init(n, t, "t.ini", sec, err);
}

static void constant_node(void **state)
{
	(void)state;
	struct planet p = { .tile_size = 64, .a = GEO_WGS84_A, .f = GEO_WGS84_F };
	struct ini_file *ini;
	struct node n;
	char err[256];
	struct tile_key k = { .lx = 3, .ly = 2, .x = 5, .y = 1 };

	assert_int_equal(hand_node(&n, "h", &node_type_constant, &p, &ini,
				   "[node h]\ntype = constant\nheight = -4321.5\n", err), 0);
	assert_int_equal(n.out, PIX_HEIGHT);
	assert_int_equal(n.type->deps(&n, &k, NULL), 0);
	k.node = n.hash;
	struct tile *t = tile_create(&k, PIX_HEIGHT, 64);
	struct gen_ctx g = { 0 };
	assert_int_equal(n.type->generate(&n, &g, &k, NULL, 0, t), 0);
	for (size_t i = 0; i < 64 * 64; i++)
		assert_true(tile_f32(t)[i] == -4321.5f);
	tile_unref(t);
	node_fini(&n);
	ini_free(ini);

	/* "#rrggbbaa" needs no space before '#': the INI reader takes " #" as a comment. */
	assert_int_equal(hand_node(&n, "c", &node_type_constant, &p, &ini,
				   "[node c]\ntype = constant\ncolor=#10203040\n", err), 0);
	assert_int_equal(n.out, PIX_COLOR);
	t = tile_create(&k, PIX_COLOR, 64);
	assert_int_equal(n.type->generate(&n, &g, &k, NULL, 0, t), 0);
	for (size_t i = 0; i < 64 * 64; i++) {
		assert_int_equal(t->data[4 * i + 0], 0x10);
		assert_int_equal(t->data[4 * i + 1], 0x20);
		assert_int_equal(t->data[4 * i + 2], 0x30);
		assert_int_equal(t->data[4 * i + 3], 0x40);
	}
	tile_unref(t);
	uint64_t hex_hash = n.hash;
	node_fini(&n);
	ini_free(ini);

	/* The same colour written as numbers is the same content. */
	assert_int_equal(hand_node(&n, "c2", &node_type_constant, &p, &ini,
				   "[node c2]\ntype = constant\ncolor = 16, 32, 48, 64\n", err), 0);
	assert_true(n.hash == hex_hash);
	node_fini(&n);
	ini_free(ini);
	gen_ctx_fini(&g);

	assert_int_equal(hand_node(&n, "x", &node_type_constant, &p, &ini,
				   "[node x]\ntype = constant\nheight = 1\ncolor = 1,2,3\n", err),
			 -EINVAL);
	assert_non_null(strstr(err, "t.ini:4: color: "));
	assert_non_null(strstr(err, "not both"));
	ini_free(ini);

	assert_int_equal(hand_node(&n, "x", &node_type_constant, &p, &ini,
				   "[node x]\ntype = constant\n", err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:1: "));
	assert_non_null(strstr(err, "height"));
	ini_free(ini);

	assert_int_equal(hand_node(&n, "x", &node_type_constant, &p, &ini,
				   "[node x]\ntype = constant\ncolor =\n", err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:3: color: empty"));
	ini_free(ini);

	assert_int_equal(hand_node(&n, "x", &node_type_constant, &p, &ini,
				   "[node x]\ntype = constant\ncolor = 300,0,0\n", err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:3: color: "));
	ini_free(ini);
}

/* node_init refuses an input of the wrong type and a missing required input. */
static void node_init_checks_inputs(void **state)
{
	(void)state;
	struct planet p = { .tile_size = 64 };
	struct ini_file *ini_src, *ini_user;
	struct node src, user;
	char err[256];
	assert_int_equal(hand_node(&src, "paint", &node_type_constant, &p, &ini_src,
				   "[node paint]\ntype = constant\ncolor = 1,2,3\n", err), 0);

	memset(&user, 0, sizeof user);
	static const char text[] = "[node sum]\ntype = t_mix\na = paint\n";
	assert_int_equal(ini_parse("t.ini", text, strlen(text), &ini_user, err), 0);
	struct ini_section *sec = &ini_user->sections[0];
	ini_find(sec, "type")->used = true;
	ini_find(sec, "a")->used = true;
	user.name = "sum";
	user.planet = &p;
	user.in[0] = &src;
	assert_int_equal(node_init(&user, &t_mix, "t.ini", sec, err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:3: a: node \"paint\" gives color tiles"));
	assert_non_null(strstr(err, "needs height"));

	user.in[0] = NULL;
	assert_int_equal(node_init(&user, &t_mix, "t.ini", sec, err), -EINVAL);
	assert_non_null(strstr(err, "t.ini:1: "));
	assert_non_null(strstr(err, "needs input \"a\""));
	ini_free(ini_user);
	node_fini(&src);
	ini_free(ini_src);
}

/* ---- good planets ---- */

static void earth(void **state)
{
	(void)state;
	char path[256], err[256];
	struct planet *p = NULL;
	fixture("earth.ini", path);
	int rc = planet_load(path, &p, err);
	if (rc)
		fail_msg("%s", err);
	assert_string_equal(p->name, "earth");
	assert_string_equal(p->description, "Earth, flat ocean floor");
	assert_string_equal(p->path, path);
	char dir[256];
	snprintf(dir, sizeof dir, "%s/planets", data_dir());
	assert_string_equal(p->dir, dir);
	assert_true(p->a == 6378137.0);
	assert_true(p->f == 1 / 298.257223563);
	assert_non_null(p->body);
	assert_true(geo_body_a(p->body) == 6378137.0);
	assert_true(geo_body_f(p->body) == 1 / 298.257223563);
	assert_int_equal(p->tile_size, 512);
	assert_int_equal(p->max_level, 18);
	assert_int_equal(p->nnodes, 2);
	assert_int_equal(p->nlayers, 2);

	const struct planet_layer *h = planet_find_layer(p, "height");
	const struct planet_layer *c = planet_find_layer(p, "color");
	assert_non_null(h);
	assert_non_null(c);
	assert_null(planet_find_layer(p, "normal"));
	assert_int_equal(h->type, PIX_HEIGHT);
	assert_int_equal(c->type, PIX_COLOR);
	assert_ptr_equal(h->node, planet_find_node(p, "sea_floor"));
	assert_ptr_equal(c->node, planet_find_node(p, "green"));
	assert_null(planet_find_node(p, "height"));
	assert_ptr_equal(h->node->planet, p);
	assert_int_equal(h->node->line, 9);
	assert_true(h->node->hash != c->node->hash);

	/* The layer's node generates what the file says. */
	struct tile_key k = { .node = h->node->hash, .lx = 1, .ly = 0 };
	struct tile *t = tile_create(&k, h->type, p->tile_size);
	struct gen_ctx g = { 0 };
	assert_int_equal(h->node->type->generate(h->node, &g, &k, NULL, 0, t), 0);
	assert_true(tile_f32(t)[0] == -4000.0f && tile_f32(t)[512 * 512 - 1] == -4000.0f);
	tile_unref(t);
	k.node = c->node->hash;
	t = tile_create(&k, c->type, p->tile_size);
	assert_int_equal(c->node->type->generate(c->node, &g, &k, NULL, 0, t), 0);
	assert_memory_equal(t->data + 4 * 1000, ((uint8_t[]){ 34, 139, 34, 255 }), 4);
	tile_unref(t);
	gen_ctx_fini(&g);
	planet_unref(p);
	planet_unref(NULL);
}

static void sphere_and_custom(void **state)
{
	(void)state;
	char path[256], err[256];
	struct planet *p = NULL;
	fixture("moon.ini", path);
	if (planet_load(path, &p, err))
		fail_msg("%s", err);
	assert_string_equal(p->name, "moon"); /* from the file name */
	assert_true(p->a == 1737400.0);
	assert_true(p->f == 0.0);
	assert_true(geo_body_a(p->body) == 1737400.0 && geo_body_f(p->body) == 0.0);
	assert_int_equal(p->tile_size, 256);
	assert_int_equal(p->max_level, 20);
	planet_unref(p);

	fixture("mars.ini", path);
	if (planet_load(path, &p, err))
		fail_msg("%s", err);
	assert_string_equal(p->name, "mars");
	assert_true(p->a == 3396190.0);
	assert_true(fabs(p->f - 1 / 169.894447) < 1e-15);
	assert_true(fabs(geo_body_f(p->body) - 1 / 169.894447) < 1e-15);
	planet_unref(p);

	/* Defaults: no [planet] section at all is WGS84, named after the file. */
	p = load_ok("[node z]\ntype = constant\nheight = 0\n[layer h]\nnode = z\n");
	assert_string_equal(p->name, "p");
	assert_string_equal(p->description, "");
	assert_true(p->a == GEO_WGS84_A && p->f == GEO_WGS84_F);
	planet_unref(p);

	/* body = sphere with its radius; radius + flattening without body is custom. */
	p = load_ok("[planet]\nbody = sphere\nradius = 6371000\ntile_size = 64\nmax_level = 29\n"
		    "[node z]\ntype = constant\nheight = 0\n[layer h]\nnode = z\n");
	assert_true(p->a == 6371000.0 && p->f == 0.0);
	assert_int_equal(p->tile_size, 64);
	assert_int_equal(p->max_level, 29);
	planet_unref(p);
	p = load_ok("[planet]\nradius = 1000\nflattening = 0.25\ntile_size = 1024\n"
		    "[node z]\ntype = constant\nheight = 0\n[layer h]\nnode = z\n");
	assert_true(p->a == 1000.0 && p->f == 0.25);
	assert_int_equal(p->tile_size, 1024);
	planet_unref(p);
}

static void graph_order(void **state)
{
	(void)state;
	char path[256], err[256];
	struct planet *p = NULL;
	fixture("graph.ini", path);
	if (planet_load_types(path, test_types(), &p, err))
		fail_msg("%s", err);
	assert_int_equal(p->nnodes, 6);
	assert_int_equal(p->nlayers, 3);
	/* Every node after its inputs. */
	for (size_t i = 0; i < p->nnodes; i++) {
		const struct node *n = p->nodes[i];
		assert_ptr_equal(n->planet, p);
		for (int s = 0; s < NODE_MAX_INPUTS; s++) {
			if (!n->in[s])
				continue;
			size_t j = 0;
			while (p->nodes[j] != n->in[s])
				j++;
			assert_true(j < i);
		}
	}
	struct node *sum = planet_find_node(p, "sum");
	assert_ptr_equal(sum->type, &t_mix);
	assert_ptr_equal(sum->in[0], planet_find_node(p, "base"));
	assert_ptr_equal(sum->in[1], planet_find_node(p, "detail"));
	assert_ptr_equal(planet_find_node(p, "shade")->in[0], sum);
	assert_int_equal(planet_find_layer(p, "normal")->type, PIX_NORMAL);
	assert_int_equal(planet_find_layer(p, "height")->type, PIX_HEIGHT);
	assert_int_equal(planet_find_layer(p, "color")->type, PIX_COLOR);
	/* Optional slots may stay empty. */
	struct planet *q = load_ok("[node b]\ntype = constant\nheight = 1\n"
				   "[node m]\ntype = t_mix\na = b\n[layer h]\nnode = m\n");
	assert_non_null(planet_find_node(q, "m")->in[0]);
	assert_null(planet_find_node(q, "m")->in[1]);
	planet_unref(q);
	planet_unref(p);
}

/* ---- errors ---- */

static void fixture_errors(void **state)
{
	(void)state;
	static const struct {
		const char *file, *expect;
	} cases[] = {
		{ "bad_tile_size.ini", "bad_tile_size.ini:3: tile_size: expected a power of two" },
		{ "unknown_type.ini", "unknown_type.ini:5: type: unknown node type \"bogus\"" },
		{ "unknown_input.ini", "unknown_input.ini:8: b: unknown input node \"nowhere\"" },
		{ "cycle.ini", "cycle.ini:11: a: cycle: a -> b -> c -> a" },
		{ "type_mismatch.ini",
		  "type_mismatch.ini:7: a: node \"paint\" gives color tiles, but t_mix.a needs "
		  "height" },
		{ "layer_format.ini", "layer_format.ini:7: format: layer \"color\" is declared f32" },
		{ "no_layers.ini", "no_layers.ini: no [layer NAME] section" },
		{ "duplicate_node.ini", "duplicate_node.ini:5: [node flat]: duplicate node name" },
		{ "unknown_section.ini", "unknown_section.ini:4: [nodes flat]: unknown section" },
		{ "unknown_planet_key.ini", "unknown_planet_key.ini:3: radius_km: unknown key" },
		{ "unknown_node_key.ini",
		  "unknown_node_key.ini:4: heigth: unknown key for node type constant" },
	};
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		char path[256], err[256] = "";
		struct planet *p = NULL;
		fixture(cases[i].file, path);
		int rc = planet_load_types(path, test_types(), &p, err);
		if (rc != -EINVAL || p)
			fail_msg("%s: expected -EINVAL, got %d (%s)", cases[i].file, rc, err);
		if (!strstr(err, cases[i].expect))
			fail_msg("%s: error \"%s\" lacks \"%s\"", cases[i].file, err,
				 cases[i].expect);
		/* The message starts with the full path of the file. */
		assert_memory_equal(err, path, strlen(path));
	}
}

static void missing_file(void **state)
{
	(void)state;
	char path[128], err[256], expect[300];
	struct planet *p = NULL;
	snprintf(path, sizeof path, "%s/no-such-planet.ini", tmpdir);
	assert_int_equal(planet_load(path, &p, err), -ENOENT);
	assert_null(p);
	snprintf(expect, sizeof expect, "%s: %s", path, strerror(ENOENT));
	assert_string_equal(err, expect);
	/* err may be NULL. */
	assert_int_equal(planet_load(path, &p, NULL), -ENOENT);
}

#define NODE_Z "[node z]\ntype = constant\nheight = 0\n"
#define LAYER_Z "[layer h]\nnode = z\n"

static void planet_errors(void **state)
{
	(void)state;
	load_fails("[planet]\nname = x\nthis is not ini\n", "p.ini:3: expected");
	load_fails("stray = 1\n" NODE_Z LAYER_Z, "p.ini:1: stray: key outside any section");
	load_fails("[planet]\n[planet]\n" NODE_Z LAYER_Z, "p.ini:2: [planet]: duplicate [planet]");
	load_fails("[planet]\nname = a\nname = b\n" NODE_Z LAYER_Z,
		   "p.ini:3: name: duplicate key (first set at line 2)");
	load_fails("[planet]\nname =\n" NODE_Z LAYER_Z, "p.ini:2: name: must not be empty");
	load_fails("[planet]\nbody = pear\n" NODE_Z LAYER_Z,
		   "p.ini:2: body: \"pear\" is not one of: wgs84, sphere, custom");
	load_fails("[planet]\nbody = wgs84\nradius = 6371000\n" NODE_Z LAYER_Z,
		   "p.ini:3: radius: body = wgs84 fixes");
	load_fails("[planet]\nbody = sphere\n" NODE_Z LAYER_Z,
		   "p.ini:2: body: body = sphere needs a radius");
	load_fails("[planet]\nbody = sphere\nradius = 10\nflattening = 0.1\n" NODE_Z LAYER_Z,
		   "p.ini:4: flattening: a sphere has no flattening");
	load_fails("[planet]\nbody = custom\nradius = 10\n" NODE_Z LAYER_Z,
		   "p.ini:2: body: body = custom needs a flattening");
	load_fails("[planet]\nflattening = 0.1\n" NODE_Z LAYER_Z, "p.ini:2: flattening: needs a radius");
	load_fails("[planet]\nradius = -5\n" NODE_Z LAYER_Z, "p.ini:2: radius: expected a positive");
	load_fails("[planet]\nradius = big\n" NODE_Z LAYER_Z, "p.ini:2: radius: expected a positive");
	load_fails("[planet]\nradius = 10\nflattening = 1\n" NODE_Z LAYER_Z,
		   "p.ini:3: flattening: expected a number in [0, 1)");
	load_fails("[planet]\nradius = 10\nflattening = 1/0\n" NODE_Z LAYER_Z,
		   "p.ini:3: flattening: expected");
	static const char *const bad_sizes[] = { "32", "2048", "100", "256.0", "abc", "", "-256" };
	for (size_t i = 0; i < sizeof bad_sizes / sizeof bad_sizes[0]; i++) {
		char text[256];
		snprintf(text, sizeof text, "[planet]\ntile_size = %s\n" NODE_Z LAYER_Z, bad_sizes[i]);
		load_fails(text, "p.ini:2: tile_size: expected a power of two from 64 to 1024");
	}
	load_fails("[planet]\nmax_level = 0\n" NODE_Z LAYER_Z, "p.ini:2: max_level: expected an integer");
	load_fails("[planet]\nmax_level = 30\n" NODE_Z LAYER_Z, "p.ini:2: max_level: expected an integer");
}

/* The look: Earth's air and no sea by default, the presets, keys overriding a preset one by
 * one, a sea level; and every bad value with its file:line: key. */
static void look(void **state)
{
	(void)state;
	struct planet *p = load_ok("[planet]\n" NODE_Z LAYER_Z);
	assert_true(p->look.air_density == 1 && p->look.air_height == 8000);
	assert_memory_equal(p->look.air_color, ((uint8_t[3]){ 133, 173, 222 }), 3);
	assert_false(p->look.sea);
	assert_true(p->look.sea_level == 0);
	planet_unref(p);

	p = load_ok("[planet]\natmosphere = none\nsea_level = -120.5\n" NODE_Z LAYER_Z);
	assert_true(p->look.air_density == 0 && p->look.air_height == 0);
	assert_true(p->look.sea && p->look.sea_level == -120.5);
	planet_unref(p);

	p = load_ok("[planet]\natmosphere = mars\n" NODE_Z LAYER_Z);
	assert_true(p->look.air_density == 0.3 && p->look.air_height == 11100);
	assert_memory_equal(p->look.air_color, ((uint8_t[3]){ 196, 150, 108 }), 3);
	planet_unref(p);

	p = load_ok("[planet]\natmosphere = mars\natmosphere_density = 2.5\n"
		    "atmosphere_height = 20000\natmosphere_color = #ff8000\n" NODE_Z LAYER_Z);
	assert_true(p->look.air_density == 2.5 && p->look.air_height == 20000);
	assert_memory_equal(p->look.air_color, ((uint8_t[3]){ 255, 128, 0 }), 3);
	planet_unref(p);
	p = load_ok("[planet]\natmosphere_color = 1, 2,3\n" NODE_Z LAYER_Z);
	assert_true(p->look.air_density == 1); /* earth's, recoloured */
	assert_memory_equal(p->look.air_color, ((uint8_t[3]){ 1, 2, 3 }), 3);
	planet_unref(p);

	load_fails("[planet]\natmosphere = venus\n" NODE_Z LAYER_Z,
		   "p.ini:2: atmosphere: \"venus\" is not one of: none, earth, mars");
	load_fails("[planet]\natmosphere = none\natmosphere_density = 1\n" NODE_Z LAYER_Z,
		   "p.ini:3: atmosphere_density: atmosphere = none has no air");
	load_fails("[planet]\natmosphere = none\natmosphere_color = #000000\n" NODE_Z LAYER_Z,
		   "p.ini:3: atmosphere_color: atmosphere = none has no air");
	static const char *const bad_density[] = { "0", "-1", "101", "thick", "" };
	for (size_t i = 0; i < sizeof bad_density / sizeof bad_density[0]; i++) {
		char text[256];
		snprintf(text, sizeof text, "[planet]\natmosphere_density = %s\n" NODE_Z LAYER_Z,
			 bad_density[i]);
		load_fails(text, "p.ini:2: atmosphere_density: expected a number in (0, 100]");
	}
	load_fails("[planet]\natmosphere_height = 0\n" NODE_Z LAYER_Z,
		   "p.ini:2: atmosphere_height: expected a scale height");
	load_fails("[planet]\natmosphere_height = 2e6\n" NODE_Z LAYER_Z,
		   "p.ini:2: atmosphere_height: expected a scale height");
	static const char *const bad_color[] = { "#12345", "#1234567", "#gg0000", "1,2",
						 "1,2,3,4", "256,0,0", "-1,0,0", "blue" };
	for (size_t i = 0; i < sizeof bad_color / sizeof bad_color[0]; i++) {
		char text[256];
		snprintf(text, sizeof text, "[planet]\natmosphere_color = %s\n" NODE_Z LAYER_Z,
			 bad_color[i]);
		load_fails(text, "p.ini:2: atmosphere_color: expected \"#rrggbb\" or \"r,g,b\"");
	}
	load_fails("[planet]\nsea_level = deep\n" NODE_Z LAYER_Z,
		   "p.ini:2: sea_level: expected metres");
	load_fails("[planet]\nsea_level = 2e5\n" NODE_Z LAYER_Z,
		   "p.ini:2: sea_level: expected metres");
	load_fails("[planet]\nsea = 0\n" NODE_Z LAYER_Z, "p.ini:2: sea: unknown key in [planet]");

	/* A sea on a geoid node (EGM96 from proj-data): a 1° lattice of its undulation, in
	 * decimetres; sea_geoid without sea_level, or naming a node that is not a geoid. */
#define NODE_G "[node g]\ntype = geoid\ninput = z\n"
	p = load_ok("[planet]\nsea_level = 0\nsea_geoid = g\n" NODE_Z NODE_G LAYER_Z);
	const struct sea_grid *g = &p->look.sea_grid;
	assert_int_equal(g->rows, 181);
	assert_int_equal(g->cols, 360);
	double n_lanka = sea_grid_at(g, 9.5, 80.5), n_guinea = sea_grid_at(g, -5, 145);
	fprintf(stderr, "geoid: %.1f m off Sri Lanka, %.1f m over New Guinea\n", n_lanka, n_guinea);
	assert_true(n_lanka < -80 && n_lanka > -110);  /* EGM96's low south of India */
	assert_true(n_guinea > 55 && n_guinea < 86);   /* and its high */
	planet_unref(p);
	p = load_ok("[planet]\nsea_level = 0\n" NODE_Z NODE_G LAYER_Z);
	assert_int_equal(p->look.sea_grid.rows, 0); /* a geoid node alone moves no sea */
	planet_unref(p);
	load_fails("[planet]\nsea_geoid = g\n" NODE_Z NODE_G LAYER_Z,
		   "p.ini:2: sea_geoid: a sea that follows a geoid or lies in basins needs sea_level");
	load_fails("[planet]\nsea_level = 0\nsea_geoid = nope\n" NODE_Z NODE_G LAYER_Z,
		   "p.ini:3: sea_geoid: unknown node \"nope\"");
	load_fails("[planet]\nsea_level = 0\nsea_geoid = z\n" NODE_Z NODE_G LAYER_Z,
		   "p.ini:3: sea_geoid: node \"z\" is of type constant; sea_geoid names a node of type "
		   "geoid");
	/* sea_basins names an open_sea node (test_open_sea, test_earth: the Caspian) */
	load_fails("[planet]\nsea_basins = z\n" NODE_Z LAYER_Z,
		   "p.ini:2: sea_basins: a sea that follows a geoid or lies in basins needs "
		   "sea_level");
	load_fails("[planet]\nsea_level = 0\nsea_basins = nope\n" NODE_Z LAYER_Z,
		   "p.ini:3: sea_basins: unknown node \"nope\"");
	load_fails("[planet]\nsea_level = 0\nsea_geoid = g\nsea_basins = g\n" NODE_Z NODE_G LAYER_Z,
		   "p.ini:4: sea_basins: node \"g\" is of type geoid; sea_basins names a node of "
		   "type open_sea");
#undef NODE_G

	/* sea_mask = color_alpha: the colour layers' alpha says where the sea may lie */
	p = load_ok("[planet]\nsea_level = 0\nsea_mask = color_alpha\n" NODE_Z LAYER_Z);
	assert_true(p->look.sea && p->look.sea_mask);
	planet_unref(p);
	load_fails("[planet]\nsea_mask = color_alpha\n" NODE_Z LAYER_Z,
		   "p.ini:2: sea_mask: a mask of where the sea lies needs a sea (sea_level)");
	load_fails("[planet]\nsea_level = 0\nsea_mask = alpha\n" NODE_Z LAYER_Z,
		   "p.ini:3: sea_mask: \"alpha\" is not one of: color_alpha");
}

static void node_and_layer_errors(void **state)
{
	(void)state;
	load_fails("[node]\ntype = constant\nheight = 0\n" LAYER_Z, "p.ini:1: [node]: bad name \"\"");
	load_fails("[node a/b]\ntype = constant\nheight = 0\n" LAYER_Z,
		   "p.ini:1: [node a/b]: bad name \"a/b\"");
	load_fails("[node a b]\ntype = constant\nheight = 0\n" LAYER_Z, "p.ini:1: [node a b]: bad name");
	load_fails("[node z]\nheight = 0\n" LAYER_Z, "p.ini:1: [node z]: missing \"type = ...\"");
	load_fails("[node z]\ntype = constant\nheight = 0\nheight = 1\n" LAYER_Z,
		   "p.ini:4: height: duplicate key (first set at line 3)");
	load_fails("[node z]\ntype = constant\nheight = tall\n" LAYER_Z,
		   "p.ini:3: height: expected a number");
	/* A node that names itself. */
	load_fails(NODE_Z "[node m]\ntype = t_mix\na = z\nb = m\n[layer h]\nnode = m\n",
		   "p.ini:7: b: cycle: m -> m");
	/* A cycle reached from a node outside it. */
	load_fails(NODE_Z "[node top]\ntype = t_mix\na = x\n"
			  "[node x]\ntype = t_mix\na = y\n[node y]\ntype = t_mix\na = z\nb = x\n"
			  "[layer h]\nnode = top\n",
		   "p.ini:13: b: cycle: x -> y -> x");
	/* Slot keys are only inputs for types that have such a slot. */
	load_fails("[node z]\ntype = constant\nheight = 0\ninput = z\n" LAYER_Z,
		   "p.ini:4: input: unknown key for node type constant");
	load_fails(NODE_Z "[node m]\ntype = t_mix\nb = z\n[layer h]\nnode = m\n",
		   "needs input \"a\"");
	load_fails(NODE_Z "[layer]\nnode = z\n", "p.ini:4: [layer]: bad name");
	load_fails(NODE_Z "[layer h]\nformat = f32\n", "p.ini:4: [layer h]: missing \"node = NAME\"");
	load_fails(NODE_Z "[layer h]\nnode = y\n", "p.ini:5: node: unknown node \"y\"");
	load_fails(NODE_Z "[layer h]\nnode = z\nformat = png\n",
		   "p.ini:6: format: \"png\" is not one of: f32, rgba8, rg8");
	load_fails(NODE_Z "[layer h]\nnode = z\nformat = rgba8\n",
		   "p.ini:6: format: layer \"h\" is declared rgba8, but node \"z\" gives f32 (height)");
	load_fails(NODE_Z "[layer h]\nnode = z\nsize = 3\n", "p.ini:6: size: unknown key in [layer]");
	load_fails(NODE_Z LAYER_Z "[layer h]\nnode = z\n", "p.ini:6: [layer h]: duplicate layer name");
	load_fails(NODE_Z, "p.ini: no [layer NAME] section");
	load_fails("", "p.ini: no [layer NAME] section");
}

/* ---- content hashes ---- */

static const char hash_base[] = "[planet]\nname = h\n"
				"[node base]\ntype = constant\nheight = 100\n"
				"[node detail]\ntype = constant\nheight = 5\n"
				"[node sum]\ntype = t_mix\na = base\nb = detail\nk = 1.0\n"
				"[node top]\ntype = t_mix\na = sum\n"
				"[node other]\ntype = constant\ncolor = 16,32,48\n"
				"[layer h]\nnode = top\n[layer c]\nnode = other\n";

static const char *const hash_nodes[] = { "base", "detail", "sum", "top", "other" };
#define NHASH 5

static void hashes(const char *text, uint64_t out[NHASH])
{
	struct planet *p = load_ok(text);
	for (int i = 0; i < NHASH; i++)
		out[i] = hash_of(p, hash_nodes[i]);
	planet_unref(p);
}

static void content_hashes(void **state)
{
	(void)state;
	uint64_t a[NHASH], b[NHASH];
	hashes(hash_base, a);
	for (int i = 0; i < NHASH; i++)
		for (int j = 0; j < i; j++)
			assert_true(a[i] != a[j]);

	/* The same file twice. */
	hashes(hash_base, b);
	assert_memory_equal(a, b, sizeof a);

	/* Sections reordered, numbers and colours written differently, comments and blanks,
	 * another planet name: the same content. */
	hashes("; reordered\n[layer c]\nnode = other\n"
	       "[node top]\n  type=t_mix\n  a=sum\n\n"
	       "[node other]\ntype = constant\ncolor = 16, 32, 48, 255\n"
	       "[node sum]\nk = 1\nb = detail\na = base\ntype = t_mix\n"
	       "[layer h]\nnode = top\n"
	       "[node detail]\ntype = constant\nheight = 5.000\n"
	       "[node base]\ntype = constant\nheight = 1e2 ; metres\n"
	       "[planet]\nname = renamed\n",
	       b);
	assert_memory_equal(a, b, sizeof a);

	/* A parameter left at its default hashes like the default written out. */
	char text[1024];
	snprintf(text, sizeof text, "%s", hash_base);
	char *k = strstr(text, "k = 1.0\n");
	memmove(k, k + 8, strlen(k + 8) + 1);
	hashes(text, b);
	assert_memory_equal(a, b, sizeof a);

	/* Change one parameter: that node and everything downstream change, nothing else. */
	snprintf(text, sizeof text, "%s", hash_base);
	memcpy(strstr(text, "height = 5\n"), "height = 6\n", 11);
	hashes(text, b);
	assert_true(b[0] == a[0]); /* base */
	assert_true(b[1] != a[1]); /* detail */
	assert_true(b[2] != a[2]); /* sum */
	assert_true(b[3] != a[3]); /* top */
	assert_true(b[4] == a[4]); /* other */

	snprintf(text, sizeof text, "%s", hash_base);
	memcpy(strstr(text, "k = 1.0\n"), "k = 2.0\n", 8);
	hashes(text, b);
	assert_true(b[0] == a[0] && b[1] == a[1] && b[4] == a[4]);
	assert_true(b[2] != a[2] && b[3] != a[3]);

	/* Rewiring an input changes the user (and downstream) too. */
	snprintf(text, sizeof text, "%s", hash_base);
	memcpy(strstr(text, "a = base\nb = detail"), "a = detail\nb = base", 19);
	hashes(text, b);
	assert_true(b[0] == a[0] && b[1] == a[1] && b[4] == a[4]);
	assert_true(b[2] != a[2] && b[3] != a[3]);
}

/* ---- dot ---- */

static size_t count(const char *s, const char *what)
{
	size_t n = 0;
	for (const char *q = s; (q = strstr(q, what)); q += strlen(what))
		n++;
	return n;
}

static void dot_output(void **state)
{
	(void)state;
	struct planet *p = load_ok("[planet]\nname = dotty\ndescription = say \"hi\" \\o/\n"
				   "[node base]\ntype = constant\nheight = 100\n"
				   "[node detail]\ntype = constant\nheight = 5\n"
				   "[node sum]\ntype = t_mix\na = base\nb = detail\n"
				   "[node shade]\ntype = t_shade\nheight = sum\n"
				   "[layer height]\nnode = sum\n[layer normal]\nnode = shade\n");
	char *buf = NULL;
	size_t len = 0;
	FILE *f = open_memstream(&buf, &len);
	assert_non_null(f);
	assert_int_equal(planet_write_dot(p, f), 0);
	assert_int_equal(fclose(f), 0);

	assert_int_equal(strncmp(buf, "digraph \"dotty\" {\n", 18), 0);
	assert_string_equal(buf + len - 2, "}\n");
	assert_int_equal(count(buf, "{"), 1);
	assert_int_equal(count(buf, "}"), 1);
	/* Quotes and backslashes in the description are escaped. */
	assert_non_null(strstr(buf, "label=\"say \\\"hi\\\" \\\\o/\""));
	/* Quotes balance on every line. */
	for (char *line = buf; *line;) {
		char *nl = strchr(line, '\n');
		size_t q = 0;
		for (char *c = line; c < nl; c++)
			if (*c == '"' && (c == line || c[-1] != '\\'))
				q++;
		assert_int_equal(q % 2, 0);
		line = nl + 1;
	}
	assert_non_null(strstr(buf, "\"node:sum\" [label=\"sum\\nt_mix \u2192 height\"]"));
	assert_non_null(strstr(buf, "\"node:shade\" [label=\"shade\\nt_shade \u2192 normal\"]"));
	assert_non_null(strstr(buf, "\"node:sum\" -> \"node:base\" [label=\"a\"]"));
	assert_non_null(strstr(buf, "\"node:sum\" -> \"node:detail\" [label=\"b\"]"));
	assert_non_null(strstr(buf, "\"node:shade\" -> \"node:sum\" [label=\"height\"]"));
	assert_non_null(strstr(buf, "\"layer:normal\" [shape=ellipse"));
	assert_non_null(strstr(buf, "label=\"layer normal\\nrg8\""));
	assert_non_null(strstr(buf, "\"layer:height\" -> \"node:sum\""));
	assert_non_null(strstr(buf, "\"layer:normal\" -> \"node:shade\""));
	/* 3 input edges + 2 layer edges, 4 node boxes + 2 layer shapes. */
	assert_int_equal(count(buf, " -> "), 5);
	size_t boxes = 0, shapes = 0;
	for (char *line = buf; *line; line = strchr(line, '\n') + 1) {
		char *nl = strchr(line, '\n');
		bool edge = strstr(line, " -> ") && strstr(line, " -> ") < nl;
		boxes += !edge && strncmp(line, "\t\"node:", 7) == 0;
		shapes += !edge && strncmp(line, "\t\"layer:", 8) == 0;
	}
	assert_int_equal(boxes, 4);
	assert_int_equal(shapes, 2);
	free(buf);
	planet_unref(p);
}

/* ---- planet sets and the shared image cache ---- */

/* dir/name: a 16 × 8 float image, every pixel v. */
static void write_flat(const char *dir, const char *name, float v)
{
	float px[16 * 8];
	for (int i = 0; i < 16 * 8; i++)
		px[i] = v;
	char path[128], err[256];
	snprintf(path, sizeof path, "%s/%s", dir, name);
	if (img_write(path, 16, 8, 1, IMG_F32, px, err))
		fail_msg("%s", err);
}

static void write_text(const char *dir, const char *name, const char *text)
{
	char path[128];
	snprintf(path, sizeof path, "%s/%s", dir, name);
	FILE *f = fopen(path, "w");
	assert_non_null(f);
	assert_true(fputs(text, f) >= 0);
	assert_int_equal(fclose(f), 0);
}

/* The first texel of the level-(1, 0) tile (0, 0) of node `node` of planet `planet`. */
static float texel(const struct planet_set *s, const char *planet, const char *node)
{
	struct planet *p = planet_set_find(s, planet);
	assert_non_null(p);
	struct node *n = planet_find_node(p, node);
	assert_non_null(n);
	struct tile_key k = { .node = n->hash, .lx = 1, .ly = 0 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, p->tile_size);
	struct gen_ctx g = { 0 };
	assert_int_equal(n->type->generate(n, &g, &k, NULL, 0, t), 0);
	float v = tile_f32(t)[0];
	tile_unref(t);
	gen_ctx_fini(&g);
	return v;
}

static uint64_t node_hash(const struct planet_set *s, const char *planet, const char *node)
{
	return planet_find_node(planet_set_find(s, planet), node)->hash;
}

static void shared_images_and_reload(void **state)
{
	(void)state;
	char dir[64] = "/tmp/test_planets.XXXXXX";
	assert_non_null(mkdtemp(dir));
	write_flat(dir, "h.tif", 100);
	write_flat(dir, "g.tif", 7);
	/* Two planets, three file nodes on h.tif (cache_mb still accepted), one on g.tif. */
	write_text(dir, "a.ini",
		   "[planet]\nname = a\ntile_size = 64\n"
		   "[node h]\ntype = file\npath = h.tif\ncache_mb = 4\nbounds = -180,-90,180,90\n"
		   "[node g]\ntype = file\npath = g.tif\nbounds = -180,-90,180,90\n"
		   "[layer height]\nnode = h\n");
	write_text(dir, "b.ini",
		   "[planet]\nname = b\ntile_size = 64\n"
		   "[node h]\ntype = file\npath = h.tif\nbounds = -180,-90,180,90\n"
		   "[node h2]\ntype = file\npath = h.tif\nscale = 2\nbounds = -180,-90,180,90\n"
		   "[layer height]\nnode = h2\n");
	struct img_cache *ic = img_cache_create(16);
	assert_non_null(ic);
	struct planet_set *s1 = NULL, *s2 = NULL, *s3 = NULL, *s4 = NULL;
	char err[256] = "";
	if (planet_set_load(dir, 1, ic, &s1, err))
		fail_msg("%s", err);
	assert_int_equal(s1->n, 2);
	assert_ptr_equal(s1->images, ic);
	assert_ptr_equal(s1->planets[0]->images, ic);
	assert_ptr_equal(s1->planets[1]->images, ic);
	assert_true(texel(s1, "a", "h") == 100.0f);
	assert_true(texel(s1, "b", "h") == 100.0f);
	assert_true(texel(s1, "b", "h2") == 200.0f);
	struct img_cache_stats st;
	img_cache_get_stats(ic, &st);
	assert_int_equal(st.max_bytes, (uint64_t)16 << 20);
	assert_int_equal(st.files, 2); /* h.tif and g.tif, each once for all nodes */
	assert_int_equal(st.opens, 2);
	assert_true(st.memory_used > 0 && st.memory_used <= st.max_bytes);

	/* The file is rewritten (same size; replaced by rename); the reload reuses the cache. */
	write_flat(dir, "h.tif", 300);
	if (planet_set_load(dir, 2, s1->images, &s2, err))
		fail_msg("%s", err);
	assert_true(node_hash(s2, "a", "h") != node_hash(s1, "a", "h"));
	assert_true(node_hash(s2, "a", "g") == node_hash(s1, "a", "g"));
	assert_true(texel(s2, "a", "h") == 300.0f);
	assert_true(texel(s2, "b", "h2") == 600.0f);
	assert_true(texel(s2, "a", "g") == 7.0f);
	img_cache_get_stats(ic, &st);
	assert_int_equal(st.files, 2);
	assert_int_equal(st.opens, 3); /* h.tif once more; g.tif still open */

	/* Nothing changed: the same hashes, nothing reopened. */
	if (planet_set_load(dir, 3, ic, &s3, err))
		fail_msg("%s", err);
	assert_true(node_hash(s3, "a", "h") == node_hash(s2, "a", "h"));
	assert_true(texel(s3, "a", "h") == 300.0f);
	img_cache_get_stats(ic, &st);
	assert_int_equal(st.opens, 3);

	/* Without a cache the set makes its own (tools, tests). */
	if (planet_set_load(dir, 4, NULL, &s4, err))
		fail_msg("%s", err);
	assert_non_null(s4->images);
	assert_true(s4->images != ic);
	assert_ptr_equal(s4->planets[0]->images, s4->images);
	assert_true(texel(s4, "b", "h2") == 600.0f);
	img_cache_get_stats(s4->images, &st);
	assert_int_equal(st.max_bytes, (uint64_t)PLANET_IMAGE_CACHE_MB << 20);

	/* A planet held past its set and the caller's cache reference still reads. */
	struct planet *held = planet_set_find(s3, "a");
	planet_ref(held);
	planet_set_unref(s1);
	planet_set_unref(s2);
	planet_set_unref(s3);
	planet_set_unref(s4);
	img_cache_unref(ic);
	struct node *n = planet_find_node(held, "h");
	struct tile_key k = { .node = n->hash, .lx = 1, .ly = 0 };
	struct tile *t = tile_create(&k, PIX_HEIGHT, held->tile_size);
	struct gen_ctx g = { 0 };
	assert_int_equal(n->type->generate(n, &g, &k, NULL, 0, t), 0);
	assert_true(tile_f32(t)[0] == 300.0f);
	tile_unref(t);
	gen_ctx_fini(&g);
	planet_unref(held);

	/* A planet loaded alone gets a cache of its own. */
	char path[128];
	snprintf(path, sizeof path, "%s/a.ini", dir);
	struct planet *p = NULL;
	if (planet_load(path, &p, err))
		fail_msg("%s", err);
	assert_non_null(p->images);
	planet_unref(p);

	static const char *const files[] = { "a.ini", "b.ini", "h.tif", "g.tif" };
	for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
		snprintf(path, sizeof path, "%s/%s", dir, files[i]);
		assert_int_equal(unlink(path), 0);
	}
	assert_int_equal(rmdir(dir), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(registry),
		cmocka_unit_test(constant_node),
		cmocka_unit_test(node_init_checks_inputs),
		cmocka_unit_test(earth),
		cmocka_unit_test(sphere_and_custom),
		cmocka_unit_test(graph_order),
		cmocka_unit_test(fixture_errors),
		cmocka_unit_test(missing_file),
		cmocka_unit_test(planet_errors),
		cmocka_unit_test(look),
		cmocka_unit_test(node_and_layer_errors),
		cmocka_unit_test(content_hashes),
		cmocka_unit_test(dot_output),
		cmocka_unit_test(shared_images_and_reload),
	};
	return cmocka_run_group_tests_name("planet", tests, setup, teardown);
}
