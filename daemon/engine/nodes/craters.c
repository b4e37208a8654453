/* craters — see craters.h. A tile is evaluated class by class: the 3-D box around the tile's
 * texel points, grown by one cell, gives the cells whose craters can reach it (a crater's
 * centre lies within s/2 of its candidate point and its ejecta reach 2R ≤ 4R_k = s/2); each
 * crater is then stamped onto the texels inside its latitude/longitude box only. Positions
 * are doubles on the unit sphere (a 10 m crater on an Earth-size body is 1.6e-6 units), the
 * sums are doubles, so the tile and the point oracle agree to rounding.
 * Thread-safety: pure functions of an immutable struct.
 */
#include "craters.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#include "noise.h"

#define DEG (M_PI / 180.0)

static uint64_t mix64(uint64_t x)
{
	x ^= x >> 33;
	x *= 0xff51afd7ed558ccdULL;
	x ^= x >> 33;
	x *= 0xc4ceb9fe1a85ec53ULL;
	x ^= x >> 33;
	return x;
}

/* The next uniform in [0, 1) of a hash stream. */
static double next_u(uint64_t *h)
{
	*h = mix64(*h + 0x9e3779b97f4a7c15ULL);
	return (double)(*h >> 11) * (1.0 / 9007199254740992.0);
}

double craters_band_weight(double radius_m, double s)
{
	return noise_band_weight(2 * radius_m, s);
}

/* Depth and rim height (metres) of a crater of radius R and wear factor a (depth × a,
 * rim × a²); for boulders, depth is the rock's height. */
static void shape(const struct craters_params *p, double R, double a, double *depth, double *rim,
		  int *complex_)
{
	double D = 2 * R;
	if (p->boulders) {
		*depth = p->depth_ratio * D * a;
		*rim = 0;
		*complex_ = -1;
		return;
	}
	double d = D < p->transition ? p->depth_ratio * D
				     : p->depth_ratio * p->transition * pow(D / p->transition, 0.3);
	*depth = d * a;
	*rim = p->rim_ratio * d * a * a;
	*complex_ = D >= p->transition;
}

/* Height at normalised distance r = dist / R (0 ≤ r < 2). */
static double profile(double r, double depth, double rim, int complex_)
{
	if (complex_ < 0) { /* a boulder: flat-topped dome with steep sides */
		double r2 = r * r;
		return r < 1 ? depth * (1 - r2 * r2) : 0;
	}
	if (r >= 1) {
		/* Ejecta: rim · r⁻³, shifted to reach 0 at r = 2. */
		double r3 = r * r * r;
		return rim * (1 / r3 - 0.125) * (8.0 / 7.0);
	}
	double r2 = r * r;
	if (!complex_)
		return rim - depth * (1 - r2);
	/* Complex: a steeper wall clipped by a flat floor, with a central peak. */
	double h = rim - 1.6 * depth * (1 - r2);
	if (h < rim - depth)
		h = rim - depth;
	double q = r / 0.2;
	if (q < 1)
		h += 0.5 * depth * (1 - q * q) * (1 - q * q);
	return h;
}

/* Radius of a crater of class radius Rk from a uniform u: N(>R) ∝ R⁻² on [Rk, 2Rk). */
static double draw_radius(double Rk, double u)
{
	return Rk / sqrt(1 - 0.75 * u);
}

int craters_init(struct craters *c, const struct craters_params *p)
{
	if (!(p->radius > 0) || !(p->min_radius > 0) || !(p->max_radius >= p->min_radius) ||
	    !(p->density >= 0 && p->density <= 4) || !(p->depth_ratio >= 0) ||
	    !(p->rim_ratio >= 0) || !(p->transition > 0) || p->max_radius > p->radius ||
	    !(p->degradation >= 0 && p->degradation <= 1))
		return -EINVAL;
	memset(c, 0, sizeof *c);
	c->p = *p;
	for (int k = 0; k < CRATERS_MAX_CLASSES; k++) {
		double Rk = p->max_radius / ldexp(1, k);
		if (Rk < p->min_radius * (1 - 1e-9))
			break;
		c->r[k] = Rk;
		/* Expected height: craters per unit area (density / s²) × the mean over the
		 * radius distribution of ∫ profile dA, by midpoint quadrature. */
		double s = 8 * Rk, sum = 0;
		const int nu = 16, nr = 256, nf = p->degradation > 0 ? 16 : 1;
		for (int a = 0; a < nu; a++) {
			for (int f = 0; f < nf; f++) {
				double R = draw_radius(Rk, (a + 0.5) / nu), depth, rim;
				int cx;
				shape(p, R, 1 - p->degradation * (f + 0.5) / nf, &depth, &rim, &cx);
				double integral = 0;
				for (int b = 0; b < nr; b++) {
					double r = (b + 0.5) * 2.0 / nr;
					integral += profile(r, depth, rim, cx) * 2 * M_PI * r *
						    (2.0 / nr);
				}
				sum += integral * R * R / (nu * nf);
			}
		}
		c->mean[k] = p->density * sum / (s * s);
		c->nclass = k + 1;
	}
	return c->nclass > 0 ? 0 : -EINVAL;
}

size_t craters_scratch_size(uint32_t T)
{
	/* acc[T²], px/py/pz[T²], lon/lat tables (sin/cos, degrees), per-row weights and bases */
	return ((size_t)4 * T * T + 8 * (size_t)T) * sizeof(double);
}

struct crater {
	double cx, cy, cz; /* centre on the unit sphere */
	double R;	   /* radius, metres */
	double a;	   /* wear: depth × a, rim × a² */
};

/* The craters cell (ix, iy, iz) of class k holds, accepted (near the sphere) ones only.
 * Returns how many (≤ 4). */
static int cell_craters(const struct craters *c, int k, int64_t ix, int64_t iy, int64_t iz,
			struct crater out[4])
{
	const struct craters_params *p = &c->p;
	double s = 8 * c->r[k] / p->radius;
	uint64_t h = mix64(((uint64_t)p->seed << 32 | (uint32_t)k) ^
			   mix64((uint64_t)ix * 0x9e3779b97f4a7c15ULL ^
				 (uint64_t)iy * 0xc2b2ae3d27d4eb4fULL ^
				 (uint64_t)iz * 0x165667b19e3779f9ULL));
	double dens = p->density;
	int n = (int)dens;
	if (next_u(&h) < dens - n)
		n++;
	int m = 0;
	for (int i = 0; i < n && i < 4; i++) {
		double qx = ((double)ix + next_u(&h)) * s;
		double qy = ((double)iy + next_u(&h)) * s;
		double qz = ((double)iz + next_u(&h)) * s;
		double u = next_u(&h);
		double len = sqrt(qx * qx + qy * qy + qz * qz);
		if (!(len >= 1 - s / 2 && len < 1 + s / 2) || len == 0)
			continue;
		out[m].cx = qx / len;
		out[m].cy = qy / len;
		out[m].cz = qz / len;
		out[m].R = draw_radius(c->r[k], u);
		/* Wear from a side stream of this crater's hash: the draws above are unchanged. */
		uint64_t hf = h ^ 0x5851f42d4c957f2dULL;
		out[m].a = p->degradation > 0 ? 1 - p->degradation * next_u(&hf) : 1;
		m++;
	}
	return m;
}

static double class_weight(const struct craters *c, int k, int ly, uint32_t T)
{
	return craters_band_weight(c->r[k], noise_texel_size(c->p.radius, ly, T));
}

/* Class k's bend over a texel of level ly (noise_pole_weight): the curvature of its smallest,
 * freshest crater (bowl 2·depth/R², complex wall 3.2·depth/R², the ejecta at the rim
 * 14·rim/R²; a boulder's shoulder 12·height/R²) times the texel size. */
static double class_bend(const struct craters *c, int k, int ly, uint32_t T)
{
	double R = c->r[k], depth, rim;
	int cx;
	shape(&c->p, R, 1, &depth, &rim, &cx);
	double curv = cx < 0 ? 12 * depth : fmax((cx ? 3.2 : 2) * depth, 14 * rim);
	return curv / (R * R) * noise_texel_size(c->p.radius, ly, T);
}

double craters_point(const struct craters *c, double lon, double lat, int ly, uint32_t T)
{
	double tp = noise_pole_texels(lat, ly, T);
	double px = cos(lat * DEG) * cos(lon * DEG), py = cos(lat * DEG) * sin(lon * DEG),
	       pz = sin(lat * DEG);
	double sum = 0;
	for (int k = 0; k < c->nclass; k++) {
		double w = class_weight(c, k, ly, T);
		if (w <= 0)
			continue;
		double s = 8 * c->r[k] / c->p.radius, acc = 0;
		int64_t bx = (int64_t)floor(px / s), by = (int64_t)floor(py / s),
			bz = (int64_t)floor(pz / s);
		for (int64_t ix = bx - 1; ix <= bx + 1; ix++)
			for (int64_t iy = by - 1; iy <= by + 1; iy++)
				for (int64_t iz = bz - 1; iz <= bz + 1; iz++) {
					struct crater cr[4];
					int n = cell_craters(c, k, ix, iy, iz, cr);
					for (int i = 0; i < n; i++) {
						double dx = px - cr[i].cx, dy = py - cr[i].cy,
						       dz = pz - cr[i].cz;
						double d = sqrt(dx * dx + dy * dy + dz * dz) *
							   c->p.radius / cr[i].R;
						if (d >= 2)
							continue;
						double depth, rim;
						int cx;
						shape(&c->p, cr[i].R, cr[i].a, &depth, &rim,
						      &cx);
						acc += profile(d, depth, rim, cx);
					}
				}
		sum += w * noise_pole_weight(class_bend(c, k, ly, T), tp) * (acc - c->mean[k]);
	}
	return sum;
}

/* Stamps one crater onto the tile's texels inside its lat/lon box, with weight w[row]. */
static void stamp(const struct craters *c, const struct crater *cr, const double *w, uint32_t T,
		  const struct geo_rect *r, const double *px, const double *py, const double *pz,
		  double *acc)
{
	double Ru = cr->R / c->p.radius;	     /* unit-sphere radius */
	double reach = (c->p.boulders ? 1 : 2) * Ru; /* chord */
	double ang = 2 * asin(fmin(1.0, reach / 2)); /* radians */
	double clat = asin(fmax(-1.0, fmin(1.0, cr->cz))) / DEG;
	double clon = atan2(cr->cy, cr->cx) / DEG;
	double angd = ang / DEG;
	double dlat = (r->north - r->south) / T, dlon = (r->east - r->west) / T;
	double lat0 = clat - angd, lat1 = clat + angd;
	if (lat1 < r->south || lat0 > r->north)
		return;
	int64_t j0 = (int64_t)floor((r->north - lat1) / dlat - 0.5);
	int64_t j1 = (int64_t)ceil((r->north - lat0) / dlat - 0.5);
	j0 = j0 < 0 ? 0 : j0;
	j1 = j1 > (int64_t)T - 1 ? (int64_t)T - 1 : j1;
	/* Column ranges: the whole row near a pole, else the box at the crater's longitude and
	 * (for a tile wider than 180°) its copies 360° away. */
	int64_t ci0[3], ci1[3];
	int nr = 0;
	if (fabs(clat) + angd >= 89.0) {
		ci0[0] = 0, ci1[0] = (int64_t)T - 1;
		nr = 1;
	} else {
		double half = asin(fmin(1.0, sin(ang) / cos(clat * DEG))) / DEG;
		double mid = 0.5 * (r->west + r->east);
		double rel = fmod(clon - mid + 540.0, 360.0) - 180.0; /* [-180, 180) */
		for (int sh = -1; sh <= 1; sh++) {
			double a = mid + rel + 360.0 * sh - half, b = mid + rel + 360.0 * sh + half;
			if (b < r->west || a > r->east)
				continue;
			int64_t i0 = (int64_t)floor((a - r->west) / dlon - 0.5);
			int64_t i1 = (int64_t)ceil((b - r->west) / dlon - 0.5);
			ci0[nr] = i0 < 0 ? 0 : i0;
			ci1[nr] = i1 > (int64_t)T - 1 ? (int64_t)T - 1 : i1;
			nr++;
		}
	}
	double depth, rim;
	int cx;
	shape(&c->p, cr->R, cr->a, &depth, &rim, &cx);
	double inv = 1 / Ru, reach2 = reach * reach;
	for (int q = 0; q < nr; q++) {
		for (int64_t j = j0; j <= j1; j++) {
			for (int64_t i = ci0[q]; i <= ci1[q]; i++) {
				size_t t = (size_t)j * T + (size_t)i;
				double dx = px[t] - cr->cx, dy = py[t] - cr->cy, dz = pz[t] - cr->cz;
				double d2 = dx * dx + dy * dy + dz * dz;
				if (d2 < reach2)
					acc[t] += w[j] * profile(sqrt(d2) * inv, depth, rim, cx);
			}
		}
	}
}

int craters_tile(const struct craters *c, const struct tile_key *k, uint32_t T, void *scratch,
		 float *out)
{
	if (!grid_key_valid(k) || T == 0 || T > 4096)
		return -EINVAL;
	size_t n = (size_t)T * T;
	double *acc = scratch, *px = acc + n, *py = px + n, *pz = py + n;
	double *clon = pz + n, *slon = clon + T, *clat = slon + T, *slat = clat + T;
	double *wrow = slat + T, *base = wrow + T;
	struct geo_rect r;
	grid_tile_rect(k, &r);
	for (uint32_t i = 0; i < T; i++) {
		double lon = grid_u_to_lon(k->lx, T, (double)k->x * T + i + 0.5);
		double lat = grid_v_to_lat(k->ly, T, (double)k->y * T + i + 0.5);
		clon[i] = cos(lon * DEG), slon[i] = sin(lon * DEG);
		clat[i] = cos(lat * DEG), slat[i] = sin(lat * DEG);
		base[i] = 0;
	}
	/* Rows within 3.5 texels of a pole: only in a tile touching one (T ≥ 4). */
	const bool polar = k->y == 0 || k->y == grid_tiles_y(k->ly) - 1;
	double lo[3] = { 2, 2, 2 }, hi[3] = { -2, -2, -2 };
	for (uint32_t j = 0; j < T; j++) {
		for (uint32_t i = 0; i < T; i++) {
			size_t t = (size_t)j * T + i;
			px[t] = clat[j] * clon[i];
			py[t] = clat[j] * slon[i];
			pz[t] = slat[j];
			acc[t] = 0;
		}
	}
	/* The box of the tile's area: its texel points plus half a texel's chord. */
	for (size_t t = 0; t < n; t++) {
		double v[3] = { px[t], py[t], pz[t] };
		for (int a = 0; a < 3; a++) {
			lo[a] = v[a] < lo[a] ? v[a] : lo[a];
			hi[a] = v[a] > hi[a] ? v[a] : hi[a];
		}
	}
	int used = 0;
	for (int cl = 0; cl < c->nclass; cl++) {
		double w = class_weight(c, cl, k->ly, T);
		if (w <= 0)
			continue;
		used++;
		double bend = polar ? class_bend(c, cl, k->ly, T) : 0;
		for (uint32_t j = 0; j < T; j++) {
			double wp = 1;
			if (bend > NOISE_POLE_BEND) {
				double lat = grid_v_to_lat(k->ly, T, (double)k->y * T + j + 0.5);
				wp = noise_pole_weight(bend, noise_pole_texels(lat, k->ly, T));
			}
			wrow[j] = w * wp;
			base[j] += wrow[j] * c->mean[cl];
		}
		double s = 8 * c->r[cl] / c->p.radius;
		int64_t a0[3], a1[3];
		for (int a = 0; a < 3; a++) {
			a0[a] = (int64_t)floor(lo[a] / s) - 1;
			a1[a] = (int64_t)floor(hi[a] / s) + 1;
		}
		for (int64_t ix = a0[0]; ix <= a1[0]; ix++)
			for (int64_t iy = a0[1]; iy <= a1[1]; iy++)
				for (int64_t iz = a0[2]; iz <= a1[2]; iz++) {
					struct crater cr[4];
					int m = cell_craters(c, cl, ix, iy, iz, cr);
					for (int i = 0; i < m; i++)
						stamp(c, &cr[i], wrow, T, &r, px, py, pz, acc);
				}
	}
	for (size_t t = 0; t < n; t++)
		out[t] = (float)(acc[t] - base[t / T]);
	return used;
}
