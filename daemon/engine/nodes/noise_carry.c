/* noise_carry — a noise tile built from its parent level (the Proland way; noise.h, "building
 * a tile from its parent"): the carry (octaves of at least NOISE_CARRY_TEXELS texels) upsampled
 * from the parent level's carry with a separable C1 cubic (6 taps), plus the band the parent did not
 * hold; the tile's value is its carry plus its fine octaves.
 *
 * Determinism: the carry of a tile depends only on its key, the parameters and the parent
 * level's carry tiles (themselves so defined, down to ly = 0, evaluated directly): the same
 * bits whatever the order tiles are generated in. Every float operation runs in a fixed order
 * (no contraction in C11 mode), the upsample's passes (noise_sums.h) at each ISA's width with
 * scalar tails of the same expression, so the ISA changes nothing here either.
 * Pure functions over caller-owned memory: thread-safe.
 */
#include <errno.h>
#include <math.h>
#include <string.h>

#include "noise.h"
#define NOISE_SUMS_DECL_ONLY /* the struct; the bodies are noise.c's and each ISA's */
#include "noise_sums.h"

/* The upsample's kernel: the cubic Hermite whose slopes are 4th-order central differences
 * (the in-tile lattice's interpolation, noise.h), as six taps p−2 .. p+3 at t ∈ [0, 1) past p:
 * C1, exact for cubics. The child texel centres of a halved level sit at t = 1/4 and 3/4 of
 * the parent's, where the weights are exact binary fractions (k/256). Against Catmull-Rom
 * (4 taps) it errs 6× less on content at 8 texels per wavelength and 2× less at 4 (the simplex
 * octaves hold some at twice their nominal frequency). */
#define TAPS 6
#define MARGIN 3 /* parent texels read beyond the footprint on each side */

void noise_carry_kernel(double t, float w[TAPS])
{
	double t2 = t * t, t3 = t2 * t;
	double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = 3 * t2 - 2 * t3,
	       h11 = t3 - t2;
	/* slope at p: (f[p−2] − 8 f[p−1] + 8 f[p+1] − f[p+2]) / 12; at p + 1 likewise */
	double v[TAPS] = { 0 };
	static const double d[4] = { 1.0 / 12, -8.0 / 12, 8.0 / 12, -1.0 / 12 };
	static const int off[4] = { -2, -1, 1, 2 };
	v[2] += h00;
	v[3] += h01;
	for (int q = 0; q < 4; q++) {
		v[2 + off[q]] += h10 * d[q];
		v[3 + off[q]] += h11 * d[q];
	}
	for (int q = 0; q < TAPS; q++)
		w[q] = (float)v[q];
}

double noise_carry_aspect(const struct tile_key *k, uint32_t T)
{
	return noise_tile_cos_eq(k, T) * ldexp(1.0, k->ly + 1 - k->lx);
}

int noise_carry_parent(const struct tile_key *k, uint32_t T, int *plx, int *ply)
{
	if (k->ly < 1 || !grid_level_valid(k->lx, k->ly))
		return -EINVAL;
	*ply = k->ly - 1;
	bool diagonal = k->lx == k->ly + 1 ||
			(k->lx >= 1 && noise_carry_aspect(k, T) <= NOISE_CARRY_MAX_ASPECT);
	*plx = diagonal ? k->lx - 1 : k->lx;
	return 0;
}

/* Where a tile's upsample reads: parent-level texels [pu0, pu0 + gw) × [pv0, pv0 + gh). */
struct carry_geom {
	int plx, ply;
	bool dlx;	 /* the parent level has half the columns (else the same columns) */
	int64_t PW, PH;	 /* the parent level's texels across and down */
	int64_t pu0, pv0;
	uint32_t gw, gh;
};

static int carry_geom(const struct tile_key *k, uint32_t T, struct carry_geom *g)
{
	if (noise_carry_parent(k, T, &g->plx, &g->ply))
		return -EINVAL;
	g->dlx = g->plx != k->lx;
	g->PW = (int64_t)grid_tiles_x(g->plx) * T;
	g->PH = (int64_t)grid_tiles_y(g->ply) * T;
	/* child texel u's centre sits at parent index u/2 − 1/4: taps floor − 2 .. floor + 3 */
	if (g->dlx) {
		g->pu0 = (int64_t)k->x * (T / 2) - MARGIN;
		g->gw = T / 2 + 2 * MARGIN;
	} else {
		g->pu0 = (int64_t)k->x * T;
		g->gw = T;
	}
	g->pv0 = (int64_t)k->y * (T / 2) - MARGIN;
	g->gh = T / 2 + 2 * MARGIN;
	return 0;
}

/* The parent-level texel that holds the sphere point of (pu, pv), which may lie beyond the
 * level: x wraps; past a pole it is the texel across it (half a turn round, rows reversed). */
static void carry_map(const struct carry_geom *g, int64_t pu, int64_t pv, int64_t *ou, int64_t *ov)
{
	if (pv < 0) {
		pv = -1 - pv;
		pu += g->PW / 2;
	} else if (pv >= g->PH) {
		pv = 2 * g->PH - 1 - pv;
		pu += g->PW / 2;
	}
	pu %= g->PW;
	if (pu < 0)
		pu += g->PW;
	*ou = pu;
	*ov = pv;
}

bool noise_carry_upsampled(const struct noise *nz, int lx, int ly, uint32_t T)
{
	if (ly < 1 || nz->p.kind != NOISE_FBM || !grid_level_valid(lx, ly))
		return false;
	double lo = NOISE_CARRY_TEXELS * noise_texel_size(nz->p.radius, ly, T);
	int mid = noise_band_full(nz, lx, ly, T, lo, INFINITY);
	int band = noise_band_full(nz, lx, ly, T, lo, 2 * lo);
	return mid >= band + 2;
}

int noise_carry_deps(const struct noise *nz, const struct tile_key *k, uint32_t T, uint64_t node,
		     struct tile_key *out)
{
	struct carry_geom g;
	if (!noise_carry_upsampled(nz, k->lx, k->ly, T) || carry_geom(k, T, &g))
		return 0;
	/* The columns where the tile changes: the region's ends and the tile borders inside. */
	int64_t cand[8];
	int nc = 0;
	cand[nc++] = g.pu0;
	int64_t f = g.pu0 >= 0 ? g.pu0 / (int64_t)T : -((-g.pu0 + (int64_t)T - 1) / (int64_t)T);
	for (int64_t u = (f + 1) * (int64_t)T; u < g.pu0 + g.gw && nc < 6; u += T)
		cand[nc++] = u;
	cand[nc++] = g.pu0 + g.gw - 1;
	int n = 0;
	for (int64_t v = g.pv0; v < g.pv0 + g.gh; v++) {
		for (int c = 0; c < nc; c++) {
			int64_t mu, mv;
			carry_map(&g, cand[c], v, &mu, &mv);
			struct tile_key q = { .node = node, .x = (uint32_t)(mu / T),
					      .y = (uint32_t)(mv / T), .lx = (uint8_t)g.plx,
					      .ly = (uint8_t)g.ply };
			bool seen = false;
			for (int i = 0; i < n && !seen; i++)
				seen = grid_key_equal(&out[i], &q);
			if (!seen && n < NOISE_CARRY_MAX_DEPS)
				out[n++] = q;
		}
	}
	return n;
}

static size_t gather_floats(uint32_t T)
{
	return ((size_t)T * (T / 2 + 2 * MARGIN) + 2 * (size_t)T + 15) / 16 * 16;
}

size_t noise_carry_scratch_size(uint32_t T)
{
	return (noise_scratch_size(T) + 63) / 64 * 64 + gather_floats(T) * sizeof(float) + 64;
}

/* The input tile holding parent-level tile (tx, ty), or NULL. */
static const struct tile *find_in(struct tile *const *in, int nin, const struct carry_geom *g,
				  uint32_t tx, uint32_t ty, uint32_t T)
{
	for (int i = 0; i < nin; i++)
		if (in[i] && in[i]->key.lx == g->plx && in[i]->key.ly == g->ply &&
		    in[i]->key.x == tx && in[i]->key.y == ty && in[i]->size == T &&
		    in[i]->type == PIX_HEIGHT)
			return in[i];
	return NULL;
}

/* The parent level's texels of the region into G (gw × gh), a run of columns within one tile
 * at a time. */
static int gather(const struct carry_geom *g, uint32_t T, struct tile *const *in, int nin,
		  float *G)
{
	for (uint32_t r = 0; r < g->gh; r++) {
		for (uint32_t c = 0; c < g->gw;) {
			int64_t mu, mv;
			carry_map(g, g->pu0 + c, g->pv0 + r, &mu, &mv);
			uint32_t tx = (uint32_t)(mu / T), ty = (uint32_t)(mv / T);
			const struct tile *t = find_in(in, nin, g, tx, ty, T);
			if (!t)
				return -EINVAL;
			uint32_t i = (uint32_t)(mu % T), n = T - i;
			if (n > g->gw - c)
				n = g->gw - c;
			memcpy(G + (size_t)r * g->gw + c, tile_f32(t) + (size_t)(mv % T) * T + i,
			       n * sizeof *G);
			c += n;
		}
	}
	return 0;
}

int noise_carry_tile(const struct noise *nz, const struct tile_key *k, uint32_t T,
		     enum noise_isa isa, void *scratch, struct tile *const *in, int nin, float *out)
{
	if (nz->p.kind != NOISE_FBM || !grid_key_valid(k) || T < 16 || T > 4096 || T % 16)
		return -EINVAL;
	double s = noise_texel_size(nz->p.radius, k->ly, T), lo = NOISE_CARRY_TEXELS * s;
	if (!noise_carry_upsampled(nz, k->lx, k->ly, T)) {
		int rc = noise_tile_band(nz, k, T, isa, scratch, lo, INFINITY, false, out);
		return rc < 0 ? rc : 0;
	}
	struct carry_geom g;
	if (carry_geom(k, T, &g))
		return -EINVAL;
	/* the band the parent level did not carry: [lo, its own lo = 2·lo) */
	int rc = noise_tile_band(nz, k, T, isa, scratch, lo, 2 * lo, false, out);
	if (rc < 0)
		return rc;
	float *G = (float *)((char *)scratch + (noise_scratch_size(T) + 63) / 64 * 64);
	float *col = G + (size_t)g.gw * g.gh;
	if (gather(&g, T, in, nin, G))
		return -EINVAL;
	float w[2][TAPS];
	noise_carry_kernel(0.75, w[0]); /* even child rows and columns */
	noise_carry_kernel(0.25, w[1]); /* odd */
	const struct noise_sums *ns = noise_sums_for(isa);
	for (uint32_t j = 0; j < T; j++) {
		/* child row v = y·T + j sits at parent index v/2 − 1/4, t = 3/4 (j even) or 1/4
		 * (odd); its first tap, floor − 2, is row j/2 (even) or (j − 1)/2 + 1 (odd) of G,
		 * whose row 0 is parent row y·T/2 − MARGIN; column i likewise in col */
		uint32_t r0 = (j & 1) ? (j - 1) / 2 + 1 : j / 2;
		ns->carry_cols(w[j & 1], G + (size_t)r0 * g.gw, g.gw, col, g.gw);
		if (g.dlx)
			ns->carry_rows(w[0], w[1], col, out + (size_t)j * T, T);
		else
			ns->add(out + (size_t)j * T, col, T);
	}
	return 0;
}

int noise_tile_from_carry(const struct noise *nz, const struct tile_key *k, uint32_t T,
			  enum noise_isa isa, void *scratch, const float *carry, const float *base,
			  float amplitude, float offset, float *out)
{
	if (!grid_key_valid(k) || T < 16 || T > 4096 || T % 16)
		return -EINVAL;
	double lo = NOISE_CARRY_TEXELS * noise_texel_size(nz->p.radius, k->ly, T);
	if (noise_pole_fades(nz, k, T, lo)) {
		int rc = noise_tile_scaled(nz, k, T, isa, scratch, base, amplitude, offset, out);
		return rc < 0 ? rc : 0;
	}
	int rc = noise_tile_band(nz, k, T, isa, scratch, 0, lo, true, out);
	if (rc < 0)
		return rc;
	/* out = base + (offset + amplitude · (out + carry)) */
	const struct noise_sums *ns = noise_sums_for(isa);
	ns->add(out, carry, (size_t)T * T);
	ns->finish(out, base, amplitude, offset, T * T);
	return 0;
}
