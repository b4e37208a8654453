/* file_plan — see file_plan.h; the design (why the narrower axis picks the level, the polar
 * caps) is in file_resample.h. Coordinates: a texel's centre in source pixel units has pixel
 * edges at integers; the taps sample at s = coordinate - 0.5, pixel i's centre at s = i.
 * Thread-safety: pure functions of the source and the plan, which the caller owns.
 */
#include "file_plan.h"

#include <errno.h>
#include <math.h>

#include "engine/node.h"

#define FILE_REGION_BUDGET ((size_t)1 << 22) /* source pixels a tile reads, unless... */
#define FILE_MAX_REGION ((size_t)1 << 26)    /* ...its level is the coarsest: then this */
/* The prefilter (file_resample.h) leaves footprints up to this many times narrower east–west
 * than the rows are apart on the ground. 1: isotropic (2 left short dashes converging on the
 * Earth's south pole from 20 km: ETOPO5's runs of one value, 2:1 and shaded). */
#define FILE_ISO_RATIO 1.0
/* Rows whose box is wider than this many pixels are read whole (file_resample.c, iso_rows)
 * instead of widening the whole region for them: near a pole only its last rows need boxes
 * that wide (a 1:1 tile of 256 columns at 80–90° read 8192-pixel rows for all 260 rows). */
#define FILE_ISO_WIDE 256.0

/* Tap indices a latitude table holds for the virtual rows of the polar caps until axis_build
 * rebases them to the rows just after the buffer's: bh + (index - TAP_VIRTUAL). */
#define TAP_VIRTUAL INT32_MIN

static int subtaps(double r)
{
	if (r < 2)
		return 1;
	double n = ceil(r - 1e-9);
	return n > FILE_MAX_SUBTAPS ? FILE_MAX_SUBTAPS : (int)n;
}

/* Between the last row centre short of a pole (the cap row, at a distance ρ1 from the pole)
 * and the pole itself. The rows of a global plate-carrée image are areas: the edge row's
 * pixels are wedges that all meet at the pole, which has no longitude — its value P is the
 * edge row's mean (for a pixel-is-point grid like ETOPO5, whose edge row is centred on the
 * pole, the same). Clamping to the edge row instead made the texels next to the pole copy the
 * row's longitude variation into a point (radial streaks in colour, a pole of many heights);
 * a linear blend towards P (h = P + t·(R(λ) - P), t = ρ/ρ1) is a cone whose east slope
 * R'(λ)/ρ1 keeps every kink of the cap row R between its columns down to the pole: creases
 * converging on it. So the cap is P + t·R1(λ) + t²·(R(λ) - P - R1(λ)) with R1 the first
 * harmonic of R (the plane through the pole that best fits the row): a plane at the pole
 * (one slope, no creases: the kinks fade as t²), R exactly at the cap row, and exactly the
 * plane where R is one. In taps: the cap row with t², the mean row with 1 - t², the harmonic
 * row with t - t². Returns whether s is in a cap (taps filled). */
static bool pole_taps(struct file_axis *a, double s, int64_t t[4], double w[4])
{
	double u;
	if (!isnan(a->cap_s) && s > a->cap_s) {
		u = (s - a->cap_s) / (a->pole_s - a->cap_s);
		t[0] = (int64_t)a->cap_s;
		t[1] = TAP_VIRTUAL + VROW_MEAN_S, t[2] = TAP_VIRTUAL + VROW_HARM_S;
		a->use_s = true;
	} else if (!isnan(a->cap_n) && s < a->cap_n) {
		u = (a->cap_n - s) / (a->cap_n - a->pole_n);
		t[0] = (int64_t)a->cap_n;
		t[1] = TAP_VIRTUAL + VROW_MEAN_N, t[2] = TAP_VIRTUAL + VROW_HARM_N;
		a->use_n = true;
	} else {
		return false;
	}
	double r = 1 - (u < 1 ? u : 1); /* ρ/ρ1 */
	w[0] = r * r, w[1] = 1 - r * r, w[2] = r - r * r;
	t[3] = t[0], w[3] = 0;
	return true;
}

/* The taps (a->taps of them) of a sample at s (pixel i's centre at s = i): bilinear (2);
 * Catmull-Rom (4) on a magnified axis of heights, so the surface has no crease along the
 * source's rows and columns (bilinear's slope jumps there: shaded, every 9 km cell edge of
 * ETOPO5 was a straight line across the terrain, one under the camera's track a seam), or
 * with `magnify = bspline` a cubic B-spline (4): C2 and not through the samples, it keeps
 * almost nothing of the source's pixel grid (its response has fourth-order zeros at every
 * multiple of the sampling rate, Catmull-Rom's third order, bilinear's second), so the ½
 * contour of a 0/1 mask — earth.ini's water, GSHHG rasterised on a 2′ grid — runs smoothly
 * along a coast where Catmull-Rom's drew the pixels' staircase (steps of 3.7 km along the
 * IJsselmeer seen from 30 km); it narrows a one-pixel channel to a peak of ⅔. The polar
 * caps' three (pole_taps) where they are in reach. Unused taps have weight 0. */
static void sample_taps(struct file_axis *a, double s, int size, bool wrap, int64_t t[4],
			double w[4])
{
	if (a->caps && pole_taps(a, s, t, w))
		return;
	double fl = floor(s), fr = s - fl;
	if (fr < 1e-6) {
		fr = 0;
	} else if (fr > 1 - 1e-6) {
		fl += 1;
		fr = 0;
	}
	int64_t i0 = (int64_t)fl;
	/* Catmull-Rom where its four pixels exist (at an edge of a bounded axis, bilinear: a
	 * clamped tap would bend the curve towards the edge pixel, 0.5 m in 1000 at a pole).
	 * A B-spline takes its clamped taps there too: it does not pass through the pixels, so
	 * switching to bilinear would step by (p0 − 2p1 + p2)/6 where it switched. */
	if (a->taps == 4 && (wrap || a->bspline || (i0 >= 1 && i0 + 2 < size))) {
		double f2 = fr * fr, f3 = f2 * fr, g = 1 - fr;
		if (a->bspline) {
			w[0] = g * g * g / 6;
			w[1] = (3 * f3 - 6 * f2 + 4) / 6;
			w[2] = (-3 * f3 + 3 * f2 + 3 * fr + 1) / 6;
			w[3] = f3 / 6;
		} else {
			w[0] = 0.5 * (-f3 + 2 * f2 - fr);
			w[1] = 0.5 * (3 * f3 - 5 * f2 + 2);
			w[2] = 0.5 * (-3 * f3 + 4 * f2 + fr);
			w[3] = 0.5 * (f3 - f2);
		}
		for (int k = 0; k < 4; k++) {
			int64_t i = i0 - 1 + k;
			t[k] = wrap ? i : i < 0 ? 0 : i >= size ? size - 1 : i;
		}
		/* on a pixel: that pixel alone (no taps past the edges); a B-spline still
		 * weighs its neighbours there */
		if (fr == 0 && !a->bspline)
			t[0] = t[2] = t[3] = t[1], w[0] = w[2] = w[3] = 0;
		return;
	}
	int64_t i1 = fr > 0 ? i0 + 1 : i0;
	if (!wrap) {
		i0 = i0 < 0 ? 0 : i0 >= size ? size - 1 : i0;
		i1 = i1 < 0 ? 0 : i1 >= size ? size - 1 : i1;
	}
	t[0] = i0, t[1] = i1, t[2] = t[3] = i0;
	w[0] = 1 - fr, w[1] = fr, w[2] = w[3] = 0;
}

/* c[i]: texel i's centre in source pixel units (edges at integers), NAN when outside. */
static void axis_build(struct file_axis *a, const double *c, uint32_t T, double r, int size,
		       bool wrap)
{
	int n = a->n, K = a->K, nt = a->taps;
	int64_t lo = INT64_MAX, hi = INT64_MIN;
	a->any = false;
	a->all = true;
	for (uint32_t i = 0; i < T; i++) {
		int32_t *ix = a->idx + (size_t)i * K;
		float *w = a->w + (size_t)i * K;
		a->in[i] = !isnan(c[i]);
		if (!a->in[i]) {
			a->all = false;
			continue;
		}
		for (int t = 0; t < n; t++) {
			int64_t tp[4];
			double wt[4];
			sample_taps(a, c[i] + ((t + 0.5) / n - 0.5) * r - 0.5, size, wrap, tp, wt);
			for (int q = 0; q < nt; q++) {
				ix[nt * t + q] = (int32_t)tp[q];
				w[nt * t + q] = (float)(wt[q] / n);
				if (tp[q] >= TAP_VIRTUAL && tp[q] < TAP_VIRTUAL + VROWS)
					continue;
				lo = tp[q] < lo ? tp[q] : lo;
				hi = tp[q] + 1 > hi ? tp[q] + 1 : hi;
			}
		}
		a->any = true;
	}
	if (!a->any)
		lo = hi = 0;
	for (uint32_t i = 0; i < T; i++) {
		for (int k = 0; k < K; k++) {
			size_t q = (size_t)i * K + k;
			int32_t v = a->idx[q];
			if (!a->in[i]) {
				a->idx[q] = 0;
				a->w[q] = 0;
			} else if (v >= TAP_VIRTUAL && v < TAP_VIRTUAL + VROWS) {
				a->idx[q] = (int32_t)(hi - lo) + (v - TAP_VIRTUAL);
			} else {
				a->idx[q] = (int32_t)(v - lo);
			}
		}
	}
	a->lo = lo;
	a->hi = hi;
}

/* Texel column i's centre in pixel units of a level wm wide (NAN: outside the bounds). With
 * wrapping, coordinates run on from texel 0's (base = its offset east of the west bound) past
 * the image's east edge: the read wraps them (file_resample.c, read_region). */
static double col_coord(const struct file_source *f, const struct geo_rect *r, double dlon, int wm,
			double base, uint32_t i)
{
	double span = f->east - f->west;
	if (f->wrap)
		return (base + (i + 0.5) * dlon) * (wm / span);
	double d = fmod(r->west + (i + 0.5) * dlon - f->west, 360.0);
	if (d < 0)
		d += 360.0;
	return d <= span ? d * (wm / span) : NAN;
}

/* Whether texels map 1:1 onto source pixels along an axis: spacing exactly one pixel, texel
 * 0's centre on a pixel centre, all T texels inside [0, size) (or wrapping). *lo = the pixel
 * under texel 0 (unwrapped). */
static bool aligned_axis(double c0, double r, uint32_t T, int size, bool wrap, int64_t *lo)
{
	if (isnan(c0) || fabs(r - 1) > 1e-9)
		return false;
	double s0 = c0 - 0.5, i0 = nearbyint(s0);
	if (fabs(s0 - i0) > 1e-6)
		return false;
	if (!wrap && (i0 < 0 || i0 + T > size))
		return false;
	*lo = (int64_t)i0;
	return true;
}

/* The source region (columns × rows of level m) a tile with texel spacings rx × ry level-m
 * pixels may read: (T-1)·r + r + 4 taps per axis (see axis_build), within the level. */
static void region_bounds(const struct file_source *f, int m, double rx, double ry, uint32_t T,
			  size_t *bw, size_t *bh)
{
	*bw = (size_t)ceil(T * rx) + 6;
	*bh = (size_t)ceil(T * ry) + 6;
	if (!f->wrap && *bw > (size_t)f->lw[m])
		*bw = (size_t)f->lw[m];
	if (*bh > (size_t)f->lh[m])
		*bh = (size_t)f->lh[m];
}

/* The MIP level a tile with texels dlon × dlat degrees reads: from the narrower axis (see
 * "Filtering" in file_resample.h), coarser only when the wider one would need more than
 * FILE_MAX_SUBTAPS taps or the region would exceed FILE_REGION_BUDGET pixels. */
static int pick_level(const struct file_source *f, double dlon, double dlat, uint32_t T)
{
	double rx = dlon * f->lw[0] / (f->east - f->west);
	double ry = dlat * f->lh[0] / (f->north - f->south);
	double rmin = rx < ry ? rx : ry;
	int m = rmin > 1 ? (int)floor(log2(rmin) + 1e-9) : 0;
	m = m < f->nlev ? m : f->nlev - 1;
	for (; m + 1 < f->nlev; m++) {
		double rxm = rx * f->lw[m] / f->lw[0], rym = ry * f->lh[m] / f->lh[0];
		size_t bw, bh;
		region_bounds(f, m, rxm, rym, T, &bw, &bh);
		if ((rxm > rym ? rxm : rym) <= FILE_MAX_SUBTAPS && bw * bh <= FILE_REGION_BUDGET)
			break;
	}
	return m;
}

static size_t align64(size_t n)
{
	return (n + 63) & ~(size_t)63;
}

/* The polar caps in this tile's reach (pole_taps): sample coordinates of each pole and of
 * the last row centre short of it (the edge row for area rows, the one before it when the
 * edge row is centred on the pole). With a cap, latitude taps come in threes. */
static void plan_caps(struct file_plan *q, double spany)
{
	const struct file_source *f = q->f;
	struct file_axis *a = &q->ay;
	double k = q->hm / spany;
	double ps = (f->north + 90) * k - 0.5, pn = (f->north - 90) * k - 0.5;
	/* The samples the tile's texels take lie between its edges. */
	double smin = (f->north - q->r.north) * k - 0.5, smax = (f->north - q->r.south) * k - 0.5;
	double cs = ceil(ps - 1e-6) - 1, cn = floor(pn + 1e-6) + 1;
	if (f->south <= -90 && cs >= 0 && cs <= q->hm - 1 && smax > cs) {
		a->cap_s = cs;
		a->pole_s = ps;
	}
	if (f->north >= 90 && cn >= 0 && cn <= q->hm - 1 && smin < cn) {
		a->cap_n = cn;
		a->pole_n = pn;
	}
	if (!isnan(a->cap_s) || !isnan(a->cap_n)) {
		a->caps = true;
		a->taps = a->taps > 3 ? a->taps : 3;
	}
}

/* The prefilter's box at latitude lat (see file_plan_iso_width). */
static double iso_width_lat(const struct file_plan *q, double lat)
{
	double c = cos(fmin(fabs(lat), 90) * (M_PI / 180));
	double w = c > 1e-300 ? q->iso_aspect / (FILE_ISO_RATIO * c) : INFINITY, r = q->iso_rx;
	double p = w > r ? sqrt(w * w - r * r) : 0; /* inf stays inf */
	return p < 1 ? 0 : p < q->wm ? p : q->wm;
}

double file_plan_iso_width(const struct file_plan *q, int64_t Y)
{
	if (q->iso_wmax <= 0)
		return 0;
	const struct file_source *f = q->f;
	double w = iso_width_lat(q, f->north - (Y + 0.5) * ((f->north - f->south) / q->hm));
	return w < q->iso_wmax ? w : q->iso_wmax;
}

/* The prefilter's widest box for the rows this tile may read (its edges and two rows more),
 * and the region bound that leaves room for it. */
static void plan_iso(struct file_plan *q, double spanx, double spany)
{
	const struct file_source *f = q->f;
	q->iso_wmax = 0;
	if (!f->isotropic)
		return;
	q->iso_aspect = (spany / q->hm) / (spanx / q->wm);
	q->iso_rx = q->rx < 2 ? 1 : q->rx; /* one bilinear tap, or a box of rx sub-taps */
	double reach = fmax(fabs(q->r.north), fabs(q->r.south)) + 2 * spany / q->hm;
	q->iso_wmax = iso_width_lat(q, reach);
	q->iso_wreg = q->iso_wmax < FILE_ISO_WIDE ? q->iso_wmax : FILE_ISO_WIDE;
	size_t e = (size_t)ceil(q->iso_wreg / 2) + 1, wm = (size_t)q->wm;
	if (q->iso_wmax > 0 && q->bwmax < wm)
		q->bwmax = q->bwmax + 2 * e < wm ? q->bwmax + 2 * e : wm;
}

/* Widens the columns read by half the widest box the region's rows need (file_resample.c
 * filters them before the horizontal pass): to the whole row at most, where the filter runs
 * round the circle. The tap indices follow the new first column. */
static void iso_extend(struct file_plan *q)
{
	struct file_axis *a = &q->ax;
	double w = fmax(file_plan_iso_width(q, q->ay.lo), file_plan_iso_width(q, q->ay.hi - 1));
	w = w < q->iso_wreg ? w : q->iso_wreg;
	q->iso_t0 = 0;
	q->iso_t1 = a->hi - a->lo;
	if (w <= 0 || !a->any || !q->ay.any)
		return;
	int64_t wm = q->wm, bw = a->hi - a->lo, e = (int64_t)ceil(w / 2) + 1, lo, hi;
	if (q->f->wrap) {
		if (bw >= wm)
			return;
		lo = bw + 2 * e >= wm ? a->lo - (wm - bw) / 2 : a->lo - e;
		hi = bw + 2 * e >= wm ? lo + wm : a->hi + e;
	} else {
		lo = a->lo - e > 0 ? a->lo - e : 0;
		hi = a->hi + e < wm ? a->hi + e : wm;
	}
	int32_t shift = (int32_t)(a->lo - lo);
	for (size_t i = 0; i < (size_t)q->T * a->K; i++)
		a->idx[i] += shift;
	q->iso_t0 = shift;
	q->iso_t1 = shift + (a->hi - a->lo);
	a->lo = lo;
	a->hi = hi;
}

int file_plan_init(struct file_plan *q, const struct file_source *f, const struct tile_key *k,
		   uint32_t T)
{
	q->f = f;
	q->T = T;
	q->C = f->nch;
	q->tsz = img_type_bytes(f->rtype);
	grid_tile_rect(k, &q->r);
	q->dlon = (q->r.east - q->r.west) / T;
	q->dlat = (q->r.north - q->r.south) / T;
	q->m = pick_level(f, q->dlon, q->dlat, T);
	q->wm = f->lw[q->m];
	q->hm = f->lh[q->m];
	double spanx = f->east - f->west, spany = f->north - f->south;
	q->rx = q->dlon * q->wm / spanx;
	q->ry = q->dlat * q->hm / spany;
	/* Heights magnified (texels finer than the level's pixels): Catmull-Rom, or with
	 * `magnify = bspline` a cubic B-spline (sample_taps). */
	bool cubic = f->kind == FILE_KIND_HEIGHT;
	q->ax = (struct file_axis){ .n = subtaps(q->rx), .taps = cubic && q->rx < 1 ? 4 : 2,
				    .bspline = f->bspline, .cap_n = NAN, .cap_s = NAN };
	q->ay = (struct file_axis){ .n = subtaps(q->ry), .taps = cubic && q->ry < 1 ? 4 : 2,
				    .bspline = f->bspline, .cap_n = NAN, .cap_s = NAN };
	if (spanx == 360) /* exact: parse_bounds snaps near-360 spans */
		plan_caps(q, spany);
	q->ax.K = q->ax.taps * q->ax.n;
	q->ay.K = q->ay.taps * q->ay.n;
	region_bounds(f, q->m, q->rx, q->ry, T, &q->bwmax, &q->bhmax);
	plan_iso(q, spanx, spany);
	if (q->bwmax * q->bhmax > FILE_MAX_REGION)
		return -EFBIG; /* only a file with a truncated MIP pyramid, at a very coarse level */
	q->maskable = f->has_nodata || f->rtype == IMG_F32;
	return 0;
}

void file_plan_buffers(struct file_plan *q, struct gen_ctx *g)
{
	size_t T = q->T, C = (size_t)q->C, bwh = q->bwmax * q->bhmax, wm = (size_t)q->wm;
	size_t rows = q->bhmax + VROWS;
	size_t s_coord = align64(2 * T * sizeof(double));
	size_t s_tabx = align64(T * q->ax.K * 8), s_taby = align64(T * q->ay.K * 8);
	size_t s_in = align64(2 * T);
	size_t s_raw = align64(bwh * C * q->tsz);
	size_t s_src = align64(bwh * C * sizeof(float));
	size_t s_mask = q->maskable ? align64(bwh * sizeof(float)) : 0;
	size_t s_tmp = align64(rows * T * C * sizeof(float));
	size_t s_tmpm = q->maskable ? align64(rows * T * sizeof(float)) : 0;
	size_t s_row = align64(T * (C + 1) * sizeof(float));
	size_t s_praw = align64(wm * C * q->tsz), s_pv = align64(wm * C * sizeof(float));
	size_t s_pm = q->maskable ? align64(wm * sizeof(float)) : 0;
	size_t s_psum = q->iso_wmax > 0
				? align64(((q->bwmax > wm ? q->bwmax : wm) + 1) * sizeof(double))
				: 0;
	char *sp = gen_scratch(g, s_coord + s_tabx + s_taby + s_in + s_raw + s_src + s_mask +
					  s_tmp + s_tmpm + s_row + s_praw + s_pv + s_pm + s_psum);
	q->cx = (double *)(void *)sp;
	q->cy = q->cx + T;
	sp += s_coord;
	q->ax.idx = (int32_t *)(void *)sp;
	q->ax.w = (float *)(void *)(sp + T * q->ax.K * 4);
	sp += s_tabx;
	q->ay.idx = (int32_t *)(void *)sp;
	q->ay.w = (float *)(void *)(sp + T * q->ay.K * 4);
	sp += s_taby;
	q->ax.in = (uint8_t *)sp;
	q->ay.in = q->ax.in + T;
	sp += s_in;
	q->raw = sp;
	sp += s_raw;
	q->src = (float *)(void *)sp;
	sp += s_src;
	q->mask = q->maskable ? (float *)(void *)sp : NULL;
	sp += s_mask;
	q->tmp = (float *)(void *)sp;
	sp += s_tmp;
	q->tmpm = q->maskable ? (float *)(void *)sp : NULL;
	sp += s_tmpm;
	q->row = (float *)(void *)sp;
	sp += s_row;
	q->praw = sp;
	sp += s_praw;
	q->pv = (float *)(void *)sp;
	sp += s_pv;
	q->pm = q->maskable ? (float *)(void *)sp : NULL;
	sp += s_pm;
	q->psum = s_psum ? (double *)(void *)sp : NULL;
}

/* Columns run from texel 0's base (col_coord). */
void file_plan_coords(struct file_plan *q)
{
	const struct file_source *f = q->f;
	double base = 0, spany = f->north - f->south;
	if (f->wrap) {
		base = fmod(q->r.west - f->west, 360.0);
		if (base < 0)
			base += 360.0;
	}
	q->base = base;
	q->cx[0] = col_coord(f, &q->r, q->dlon, q->wm, base, 0);
	for (uint32_t j = 0; j < q->T; j++) {
		double lat = q->r.north - (j + 0.5) * q->dlat;
		q->cy[j] = lat >= f->south && lat <= f->north ? (f->north - lat) * (q->hm / spany)
							      : NAN;
	}
}

bool file_plan_aligned(struct file_plan *q)
{
	const struct file_source *f = q->f;
	uint32_t T = q->T;
	struct file_axis *ax = &q->ax, *ay = &q->ay;
	if (q->iso_wmax > 0) /* some row is filtered first */
		return false;
	if (!aligned_axis(q->cx[0], q->rx, T, q->wm, f->wrap, &ax->lo) ||
	    !aligned_axis(q->cy[0], q->ry, T, q->hm, false, &ay->lo))
		return false;
	ax->hi = ax->lo + T;
	ay->hi = ay->lo + T;
	return true;
}

/* Rebases an axis's table, built over [a->lo, a->hi), onto the region [lo, hi) read before
 * (which holds it): pixel taps shift, the caps' virtual rows follow the region's rows. */
static void axis_rebase(struct file_axis *a, uint32_t T, int64_t lo, int64_t hi)
{
	int32_t own = (int32_t)(a->hi - a->lo), shift = (int32_t)(a->lo - lo);
	for (size_t q = 0; q < (size_t)T * a->K; q++)
		a->idx[q] = a->idx[q] >= own ? a->idx[q] - own + (int32_t)(hi - lo)
					     : a->idx[q] + shift;
	a->lo = lo;
	a->hi = hi;
}

void file_plan_bilinear(struct file_plan *q)
{
	const struct file_source *f = q->f;
	struct file_axis *ax = &q->ax, *ay = &q->ay;
	int64_t xl = ax->lo, xh = ax->hi, yl = ay->lo, yh = ay->hi;
	for (int k = 0; k < 2; k++) {
		struct file_axis *a = k ? ay : ax;
		if (file_axis_catmull_rom(a)) /* a B-spline's weights are never negative */
			a->taps = a->caps ? 3 : 2;
		a->K = a->taps * a->n;
	}
	axis_build(ax, q->cx, q->T, q->rx, q->wm, f->wrap);
	axis_build(ay, q->cy, q->T, q->ry, q->hm, false);
	axis_rebase(ax, q->T, xl, xh);
	axis_rebase(ay, q->T, yl, yh);
}

void file_plan_tables(struct file_plan *q)
{
	const struct file_source *f = q->f;
	for (uint32_t i = 1; i < q->T; i++)
		q->cx[i] = col_coord(f, &q->r, q->dlon, q->wm, q->base, i);
	axis_build(&q->ax, q->cx, q->T, q->rx, q->wm, f->wrap);
	axis_build(&q->ay, q->cy, q->T, q->ry, q->hm, false);
	iso_extend(q);
}
