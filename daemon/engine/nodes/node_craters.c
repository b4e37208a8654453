/* node_craters — the `craters` node type: a seeded field of impact craters on the sphere
 * (craters.h) as a height source, or added to an input height.
 *
 * Parameters (planet file, [node NAME] with type = craters):
 *   seed         integer 0..4294967295 (default 0)
 *   min_radius   smallest crater radius, metres (default 200)
 *   max_radius   largest crater radius, metres (default 60000); classes halve from it
 *   density      expected craters per cell and class, 0..4 (default 0.8; ~1 saturates)
 *   depth_ratio  depth / diameter of simple craters (default 0.2)
 *   rim_ratio    rim height / depth (default 0.2)
 *   transition   diameter in metres from which craters are complex: shallower, flat floor,
 *                central peak (default 15000, the Moon's)
 *   degradation  0..1 (default 0): each crater's wear f, uniform per crater, scales its depth
 *                by 1 − degradation·f and its rim and ejecta by the square: fresh and old craters
 *   kind         crater | boulder (default crater): boulder makes rocks — domes of height
 *                depth_ratio × diameter (flat-topped, steep-sided), no rim or ejecta
 *   input        optional height node: output = input + craters
 * Output: height (f32 metres), zero-mean per class and band-limited per level. Near a pole,
 * classes whose smallest crater (or rock) is not planar over a texel of the level fade to 0 on
 * the two rows nearest it (noise.h, noise_pole_weight): every level's pole rows are
 * independent of longitude.
 * Thread-safety: the impl is immutable after create.
 */
#include <errno.h>
#include <stdlib.h>

#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "craters.h"

static const struct node_slot slots[] = {
	{ .name = "input", .type = PIX_HEIGHT, .optional = true },
};

static int craters_create(struct node *n, struct node_parse *p)
{
	struct craters_params cp = { 0 };
	static const char *const kinds[] = { "crater", "boulder", NULL };
	long seed;
	int rc, kind;
	if ((rc = np_int(p, "seed", 0, 0, 4294967295L, &seed)) ||
	    (rc = np_double(p, "min_radius", 200, 1e-3, 1e8, &cp.min_radius)) ||
	    (rc = np_double(p, "max_radius", 60000, 1e-3, 1e8, &cp.max_radius)) ||
	    (rc = np_double(p, "density", 0.8, 0, 4, &cp.density)) ||
	    (rc = np_double(p, "depth_ratio", 0.2, 0, 1, &cp.depth_ratio)) ||
	    (rc = np_double(p, "rim_ratio", 0.2, 0, 2, &cp.rim_ratio)) ||
	    (rc = np_double(p, "transition", 15000, 1e-3, 1e9, &cp.transition)) ||
	    (rc = np_double(p, "degradation", 0, 0, 1, &cp.degradation)) ||
	    (rc = np_enum(p, "kind", kinds, 0, &kind)))
		return rc;
	cp.boulders = kind == 1;
	if (!n->planet || !(n->planet->a > 0))
		return np_error(p, NULL, "craters node \"%s\": the planet has no radius", n->name);
	if (cp.max_radius < cp.min_radius)
		return np_error(p, "max_radius", "must be at least min_radius (%g m)",
				cp.min_radius);
	if (cp.max_radius > n->planet->a / 4)
		return np_error(p, "max_radius", "%g m is more than a quarter of the planet's "
				"radius", cp.max_radius);
	if (cp.max_radius / cp.min_radius >= (double)(1u << (CRATERS_MAX_CLASSES - 1)) * 2)
		return np_error(p, "min_radius", "max_radius / min_radius spans more than %d "
				"halvings", CRATERS_MAX_CLASSES);
	cp.seed = (uint32_t)seed;
	cp.radius = n->planet->a;
	struct craters *c = xmalloc(sizeof *c);
	if (craters_init(c, &cp)) {
		free(c);
		return np_error(p, NULL, "craters node \"%s\": invalid parameters", n->name);
	}
	n->impl = c;
	n->out = PIX_HEIGHT;
	return 0;
}

static int craters_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			    struct tile *const *in, int nin, struct tile *out)
{
	const struct craters *c = n->impl;
	uint32_t T = out->size;
	if (out->type != PIX_HEIGHT)
		return -EINVAL;
	const struct tile *src;
	if (node_opt_height_input(n, in, nin, T, &src))
		return -EINVAL;
	float *dst = tile_f32(out);
	int rc = craters_tile(c, k, T, gen_scratch(g, craters_scratch_size(T)), dst);
	if (rc < 0)
		return rc;
	if (src) {
		const float *s = tile_f32(src);
		size_t nt = (size_t)T * T;
		for (size_t i = 0; i < nt; i++)
			dst[i] += s[i];
	}
	return 0;
}

const struct node_type node_type_craters = {
	.name = "craters",
	.doc = "seeded impact craters on the sphere (seed, min_radius m, max_radius m, density, "
	       "depth_ratio, rim_ratio, transition m, degradation, kind=crater|boulder), size-distributed, band-limited per level; "
	       "optional input height gets them added",
	.version = 2, /* 2: classes that bend over a texel fade out at the poles */
	.slots = slots,
	.nslots = 1,
	.costly = true,
	.create = craters_create,
	.destroy = node_free_impl,
	.deps = NULL,
	.generate = craters_generate,
};
