/* node_noise — the `noise` node type: seeded fBm or ridged multifractal simplex noise on the
 * sphere (noise.h) as a height source, or as detail added to an input height.
 *
 * Parameters (planet file, [node NAME] with type = noise):
 *   seed           integer 0..4294967295 (default 0): different seeds, unrelated fields
 *   kind           fbm | ridged (default fbm)
 *   octaves        1..24 (default 8): most octaves a tile evaluates; coarse levels evaluate
 *                  fewer (an octave whose wavelength is under 2 texels is skipped, the one
 *                  between 2 and 4 texels fades in)
 *   wavelength     metres of the first octave (default 4e6)
 *   lacunarity     wavelength ratio between octaves, 1.5..3 (default 2)
 *   gain           amplitude ratio between octaves, 0..1 (default 0.5)
 *   amplitude      metres per unit of noise (default 1000); the fractal is roughly in [-1, 1]
 *   offset         metres added (default 0)
 *   ridge_offset   ridged: signal = (ridge_offset − |n|)², 0..2 (default 1)
 *   ridge_gain     ridged: next octave's weight = clamp(signal · ridge_gain, ridge_floor, 1),
 *                  0..16 (default 2)
 *   ridge_floor    ridged: that weight's least, 0..1 (default 0, Musgrave's): the weight is
 *                  small away from the crests, so with 0 the finer octaves vanish on the long
 *                  crests' flanks and leave plain, smooth sheets between sharp rims; a floor
 *                  keeps that share of them everywhere
 *   max_wavelength metres (default: wavelength): only octaves with a wavelength ≤ this
 *                  contribute — with an input, the "detail below the data's resolution"
 *   stretch        1..16 (default 1): features that many times narrower north–south than
 *                  east–west (space compressed along the polar axis): crests run east–west,
 *                  like ripples under a meridional wind; isotropic at the poles, no seam
 *   warp           metres, 0..warp_wavelength/4 (default 0: none): domain warp — the field is
 *                  evaluated at p + w(p), w a smooth 3-D vector fBm reaching about ± warp
 *                  (noise.h): one octave's crests, which isotropic noise closes into cells of
 *                  one size (a honeycomb seen from afar), bend, stretch and join into longer
 *                  ranges. Octaves fade in by the wavelength the warp can compress them to
 *   warp_wavelength metres of the warp's first octave (default 4 × the first octave kept,
 *                  min(wavelength, max_wavelength))
 *   warp_octaves   1..4 (default 2): the warp's octaves (gain 0.5, lacunarity 2)
 *   warp_depth     0..24 (default 0: all): only octaves 0 .. warp_depth − 1 (counted from the
 *                  first, wavelength) are warped — the coarse ones whose crests make the
 *                  cells; the finer ones keep their places and their full band
 * Near a pole, octaves that are not planar over a texel of the level (curvature × amplitude ×
 * texel size over NOISE_POLE_BEND) fade to 0 on the two rows nearest it (noise.h), so every
 * level's pole rows are independent of longitude.
 *   input          optional height node: output = input + offset + amplitude · noise
 *   from_parent    true | false (default false), fBm only: build each tile from its parent
 *                  level (noise.h, "building a tile from its parent"): the octaves of at least
 *                  NOISE_CARRY_TEXELS texels come upsampled from the parent level's carry, the
 *                  rest are evaluated. The carry is a hidden node of this one (its tiles named
 *                  by its own hash, from the noise parameters alone), an explicit dependency:
 *                  the scheduler resolves it like any input, so a tile never depends on what
 *                  happened to be cached. Ridged noise is refused (its crests are kinks no
 *                  upsample keeps: see noise.h). The node's generation time (STATS
 *                  node.*.mean_ms) includes its carry tiles'.
 * Output: height (f32 metres). Thread-safety: the impl is immutable after create.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <xxhash.h>

#include "common/clock.h"
#include "common/xalloc.h"
#include "engine/node_types.h"
#include "engine/planet.h"
#include "noise.h"

struct noise_impl {
	struct noise nz;
	float amplitude, offset;
	bool from_parent;
	struct node carry; /* with from_parent: the hidden carry node (impl = this struct) */
	struct node *owner; /* the noise node: its gen_ns also counts its carry tiles' time */
	char carry_name[96];
};

static const struct node_type node_type_noise_carry;

static const struct node_slot slots[] = {
	{ .name = "input", .type = PIX_HEIGHT, .optional = true },
};

static int noise_create(struct node *n, struct node_parse *p)
{
	static const char *const kinds[] = { "fbm", "ridged", NULL };
	static const char *const bools[] = { "false", "true", NULL };
	struct noise_params np = { 0 };
	long seed, octaves, warp_octaves, warp_depth;
	int kind, rc, from_parent;
	double amplitude, offset;
	if ((rc = np_int(p, "seed", 0, 0, 4294967295L, &seed)) ||
	    (rc = np_enum(p, "kind", kinds, 0, &kind)) ||
	    (rc = np_int(p, "octaves", 8, 1, NOISE_MAX_OCTAVES, &octaves)) ||
	    (rc = np_double(p, "wavelength", 4e6, 1e-3, 1e10, &np.wavelength)) ||
	    (rc = np_double(p, "lacunarity", 2.0, 1.5, 3.0, &np.lacunarity)) ||
	    (rc = np_double(p, "gain", 0.5, 0.0, 1.0, &np.gain)) ||
	    (rc = np_double(p, "amplitude", 1000.0, -1e7, 1e7, &amplitude)) ||
	    (rc = np_double(p, "offset", 0.0, -1e7, 1e7, &offset)) ||
	    (rc = np_double(p, "ridge_offset", 1.0, 0.0, 2.0, &np.ridge_offset)) ||
	    (rc = np_double(p, "ridge_gain", 2.0, 0.0, 16.0, &np.ridge_gain)) ||
	    (rc = np_double(p, "ridge_floor", 0.0, 0.0, 1.0, &np.ridge_floor)) ||
	    (rc = np_double(p, "max_wavelength", np.wavelength, 1e-3, 1e10, &np.max_wavelength)) ||
	    (rc = np_double(p, "stretch", 1.0, 1.0, 16.0, &np.stretch)) ||
	    (rc = np_double(p, "warp", 0.0, 0.0, 1e7, &np.warp)) ||
	    (rc = np_double(p, "warp_wavelength", 4 * fmin(np.wavelength, np.max_wavelength), 1e-3,
			    1e10, &np.warp_wavelength)) ||
	    (rc = np_int(p, "warp_octaves", 2, 1, NOISE_WARP_MAX_OCTAVES, &warp_octaves)) ||
	    (rc = np_int(p, "warp_depth", 0, 0, NOISE_MAX_OCTAVES, &warp_depth)) ||
	    (rc = np_enum(p, "from_parent", bools, 0, &from_parent)))
		return rc;
	np.warp_octaves = (int)warp_octaves;
	np.warp_depth = (int)warp_depth;
	if (from_parent && kind == 1)
		return np_error(p, "from_parent",
				"ridged noise cannot be built from its parent (its crests would be "
				"rounded off); use it with kind = fbm");
	if (!n->planet || !(n->planet->a > 0))
		return np_error(p, NULL, "noise node \"%s\": the planet has no radius", n->name);
	np.seed = (uint32_t)seed;
	np.kind = kind == 1 ? NOISE_RIDGED : NOISE_FBM;
	np.octaves = (int)octaves;
	np.radius = n->planet->a;
	np.pole_amplitude = fabs(amplitude);
	if (np.warp > 0 && np.warp > np.warp_wavelength / 4)
		return np_error(p, "warp",
				"a warp of %g m over warp_wavelength %g m folds the field onto "
				"itself; keep warp at most a quarter of warp_wavelength",
				np.warp, np.warp_wavelength);
	struct noise_impl *im = xmalloc(sizeof *im);
	if (noise_init(&im->nz, &np)) {
		free(im);
		return np_error(p, NULL, "noise node \"%s\": invalid parameters", n->name);
	}
	im->amplitude = (float)amplitude;
	im->offset = (float)offset;
	im->from_parent = from_parent;
	memset(&im->carry, 0, sizeof im->carry);
	if (from_parent) {
		/* The carry depends on the noise field alone (not on the input, amplitude or
		 * offset): named by a hash of its type, version and the field's parameters, so
		 * equal fields share carry tiles. */
		snprintf(im->carry_name, sizeof im->carry_name, "%s~carry", n->name);
		im->carry.name = im->carry_name;
		im->carry.type = &node_type_noise_carry;
		im->carry.out = PIX_HEIGHT;
		im->carry.planet = n->planet;
		im->carry.impl = im;
		im->carry.line = n->line;
		im->owner = n;
		XXH3_state_t *st = XXH3_createState();
		if (!st)
			abort();
		XXH3_64bits_reset(st);
		XXH3_64bits_update(st, node_type_noise_carry.name,
				   strlen(node_type_noise_carry.name) + 1);
		XXH3_64bits_update(st, &node_type_noise_carry.version,
				   sizeof node_type_noise_carry.version);
		const double v[] = { np.wavelength, np.lacunarity, np.gain, np.max_wavelength,
				     np.radius, np.stretch, np.pole_amplitude,
				     (double)np.seed, (double)np.octaves, (double)n->planet->tile_size,
				     np.warp, np.warp_wavelength, (double)np.warp_octaves,
				     (double)np.warp_depth };
		XXH3_64bits_update(st, v, sizeof v);
		im->carry.hash = XXH3_64bits_digest(st);
		XXH3_freeState(st);
		if (im->carry.hash == 0)
			im->carry.hash = 1;
	}
	n->impl = im;
	n->out = PIX_HEIGHT;
	return 0;
}

static int noise_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	const struct noise_impl *im = n->impl;
	uint32_t T = out->size;
	if (out->type != PIX_HEIGHT)
		return -EINVAL;
	const struct tile *src;
	if (node_opt_height_input(n, in, nin, T, &src))
		return -EINVAL;
	if (im->from_parent && noise_carry_upsampled(&im->nz, k->lx, k->ly, T)) {
		const struct tile *c = nin > 0 ? in[nin - 1] : NULL;
		if (!c || c->type != PIX_HEIGHT || c->size != T || c == src)
			return -EINVAL;
		return noise_tile_from_carry(&im->nz, k, T, NOISE_ISA_AUTO,
					     gen_scratch(g, noise_scratch_size(T)), tile_f32(c),
					     src ? tile_f32(src) : NULL, im->amplitude, im->offset,
					     tile_f32(out));
	}
	/* No octave at this level (all finer than its texels) on no input or a uniform one: every
	 * texel holds input + (offset + amplitude · 0), as noise_tile_scaled would write it, so the
	 * tile is the shared uniform one, summarized, and the nodes after it can tell (a blend
	 * adding it, a ramp over it). */
	if ((!src || src->uniform) && grid_key_valid(k) &&
	    noise_coarse_octaves(&im->nz, k->lx, k->ly, T) +
			    noise_band_full(&im->nz, k->lx, k->ly, T, 0, INFINITY) ==
		    0) {
		float v = im->offset + im->amplitude * 0.0f;
		if (src)
			v = tile_f32(src)[0] + v;
		tile_fill_uniform(out, &v);
		return 0;
	}
	/* out = input + (offset + amplitude · noise), each row while it is in cache */
	int rc = noise_tile_scaled(&im->nz, k, T, NOISE_ISA_AUTO,
				   gen_scratch(g, noise_scratch_size(T)), src ? tile_f32(src) : NULL,
				   im->amplitude, im->offset, tile_f32(out));
	return rc < 0 ? rc : 0;
}

/* key k on the input (if any), then the carry at key k */
static int noise_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	const struct noise_impl *im = n->impl;
	int m = node_default_deps(n, k, out);
	if (im->from_parent && noise_carry_upsampled(&im->nz, k->lx, k->ly, n->planet->tile_size)) {
		out[m].node = (struct node *)&im->carry;
		out[m].key = *k;
		out[m].key.node = im->carry.hash;
		m++;
	}
	return m;
}

static int carry_deps(const struct node *n, const struct tile_key *k, struct node_dep *out)
{
	struct tile_key keys[NOISE_CARRY_MAX_DEPS];
	const struct noise_impl *im = n->impl;
	int m = noise_carry_deps(&im->nz, k, n->planet->tile_size, n->hash, keys);
	for (int i = 0; i < m; i++) {
		out[i].node = (struct node *)n;
		out[i].key = keys[i];
	}
	return m;
}

static int carry_generate(const struct node *n, struct gen_ctx *g, const struct tile_key *k,
			  struct tile *const *in, int nin, struct tile *out)
{
	const struct noise_impl *im = n->impl;
	uint32_t T = out->size;
	if (out->type != PIX_HEIGHT)
		return -EINVAL;
	uint64_t t0 = clock_now_ns();
	int rc = noise_carry_tile(&im->nz, k, T, NOISE_ISA_AUTO,
				  gen_scratch(g, noise_carry_scratch_size(T)), in, nin,
				  tile_f32(out));
	/* The hidden node is in no planet's list: its time shows in its noise node's mean. */
	atomic_fetch_add(&im->owner->gen_ns, clock_now_ns() - t0);
	return rc;
}

/* Not in the registry: only a from_parent noise node makes one (its impl's carry). */
static const struct node_type node_type_noise_carry = {
	.name = "noise~carry",
	.doc = "internal: a from_parent noise node's octaves of at least NOISE_CARRY_TEXELS texels",
	.version = 2, /* 2: the lattice of its directly evaluated levels as noise version 6's */
	.slots = NULL,
	.nslots = 0,
	.create = NULL,
	.destroy = NULL,
	.deps = carry_deps,
	.generate = carry_generate,
	.lineage = true,
};

const struct node_type node_type_noise = {
	.name = "noise",
	.doc = "seeded fBm/ridged simplex noise on the sphere (seed, kind=fbm|ridged, octaves, "
	       "wavelength m, lacunarity, gain, amplitude m, offset m, ridge_offset, ridge_gain, "
	       "ridge_floor, "
	       "max_wavelength m, stretch, warp m, warp_wavelength m, warp_octaves, warp_depth), "
	       "band-limited per level; optional input height gets the octaves with wavelength <= "
	       "max_wavelength added",
	.version = 6, /* 2: per-octave rotation; 3: low octaves interpolated from a lattice;
		       * 4: octaves that bend over a texel fade out at the poles; 5: from_parent
		       * (warp: new keys, hashed; without them the same bytes); 6: a tile's
		       * lattice takes the octaves its own texels allow (more off the equator) */
	.slots = slots,
	.nslots = 1,
	.costly = true,
	.create = noise_create,
	.destroy = node_free_impl,
	.deps = noise_deps,
	.generate = noise_generate,
};
