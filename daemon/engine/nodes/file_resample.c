/* file_resample — see file_resample.h (the design). Per tile: file_plan.h picks the level and
 * builds the tables; here the region is read once through the img_cache and converted to
 * float (with masks where samples can be missing), the polar caps' virtual rows are computed
 * from whole rows of the level, then a horizontal pass (source rows → T texel columns) and a
 * vertical pass (→ the tile). A tile that maps 1:1 onto a level is copied instead.
 * Thread-safety: pure functions of the immutable source, the caller's plan and scratch; the
 * img_cache is thread-safe.
 */
#include "file_resample.h"

#include <errno.h>
#include <math.h>
#include <string.h>

#include "common/xthread.h"
#include "engine/fault.h"
#include "engine/node.h"
#include "file_plan.h"

/* Reads source rows [ay->lo, ay->hi) × columns [ax->lo, ax->hi) (wrapping x modulo the
 * level width) into dst, rows `stride` bytes apart. */
static int read_region(const struct file_source *f, int m, const struct file_axis *ax,
		       const struct file_axis *ay, void *dst, size_t stride)
{
	int64_t wm = f->lw[m];
	size_t px = img_type_bytes(f->rtype) * (size_t)f->nch;
	for (int64_t c = ax->lo; c < ax->hi;) {
		int64_t s = c % wm;
		if (s < 0)
			s += wm;
		int64_t len = ax->hi - c < wm - s ? ax->hi - c : wm - s;
		char err[256];
		int rc = img_cache_read(f->cache, f->path, m, (int)s, (int)(s + len), (int)ay->lo,
					(int)ay->hi, f->channel, f->channel + f->nch, f->rtype,
					(char *)dst + (size_t)(c - ax->lo) * px, stride, err);
		if (rc) {
			/* The tile fails with -EIO; the why (file, level, region) is told once. */
			size_t pl = strlen(f->path);
			const char *why = strncmp(err, f->path, pl) == 0 && err[pl] == ':'
						  ? err + pl + 2 : err; /* err names the file too */
			if (!atomic_exchange(&f->poles->read_failed, true))
				engine_fault("%s: read failed at MIP level %d, pixels [%lld,%lld) x "
					     "[%lld,%lld): %s (tiles of this file fail; further "
					     "failures not reported)", f->path, m, (long long)s,
					     (long long)(s + len), (long long)ay->lo,
					     (long long)ay->hi, why);
			return rc;
		}
		c += len;
	}
	return 0;
}

/* Raw samples → float, with nodata/NaN → value 0, mask 0. Returns whether any sample was
 * missing (mask is only written when the source can have missing samples: mask != NULL). */
static bool to_float(const struct file_source *f, const void *raw, float *dst, float *mask,
		     size_t n)
{
	bool missing = false;
	switch (f->rtype) {
	case IMG_U8: {
		const uint8_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_U16: {
		const uint16_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_I16: {
		const int16_t *s = raw;
		for (size_t i = 0; i < n; i++)
			dst[i] = s[i];
		break;
	}
	case IMG_F32:
		if (dst != raw)
			memcpy(dst, raw, n * sizeof *dst);
		break;
	default:
		break;
	}
	if (!mask)
		return false;
	bool nd = f->has_nodata;
	float v = f->nodata;
	/* A huge float nodata (-1e34, -3.4e38: GDAL's favourites) averaged into a coarser MIP
	 * level (OIIO's automip, or the file's own pyramid) no longer equals itself but stays
	 * beyond 1e20 in magnitude (diluted at most 4^m-fold: 1e34 / 4^20 ≈ 9e21 at level 20 of
	 * a 2^20-pixel image): no height or colour is that large, so such a sample is missing
	 * too. A moderate nodata (-9999, int16 -32768) mixed into coarse levels cannot be told
	 * from data: import such files (float nodata becomes NaN, which averaging keeps). */
	float huge = nd && f->rtype == IMG_F32 && fabsf(v) >= 1e30f ? 1e20f : INFINITY;
	for (size_t i = 0; i < n; i++) {
		bool bad = dst[i] != dst[i] || (nd && dst[i] == v) || fabsf(dst[i]) >= huge;
		mask[i] = bad ? 0.0f : 1.0f;
		dst[i] = bad ? 0.0f : dst[i];
		missing |= bad;
	}
	return missing;
}

/* Explicit 4-wide vectors (GCC/clang vector extensions, SSE2 baseline): gcc -O2 leaves
 * these loops scalar (its very-cheap cost model will not add an epilogue). */
typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));
typedef uint16_t v4u16 __attribute__((vector_size(8)));

static inline v4f ld4(const float *p)
{
	v4f v;
	memcpy(&v, p, sizeof v);
	return v;
}

static inline void st4(float *p, v4f v)
{
	memcpy(p, &v, sizeof v);
}

static bool has_nan(const float *v, size_t n)
{
	/* Four independent accumulators: one would make a loop-carried chain. */
	v4i a0 = { 0, 0, 0, 0 }, a1 = a0, a2 = a0, a3 = a0;
	size_t i = 0;
	for (; i + 16 <= n; i += 16) {
		v4f x0 = ld4(v + i), x1 = ld4(v + i + 4), x2 = ld4(v + i + 8), x3 = ld4(v + i + 12);
		a0 |= x0 != x0;
		a1 |= x1 != x1;
		a2 |= x2 != x2;
		a3 |= x3 != x3;
	}
	v4i acc = (a0 | a1) | (a2 | a3);
	bool any = (acc[0] | acc[1] | acc[2] | acc[3]) != 0;
	for (; i < n; i++)
		any |= v[i] != v[i];
	return any;
}

/* dst[i] = (Σ_q w[q]·src[q][i])·sc + off for i < n: the vertical pass. */
static void wsum(float *dst, const float *const *src, const float *w, int K, size_t n, float sc,
		 float off)
{
	size_t i = 0;
	for (; i + 4 <= n; i += 4) {
		v4f acc = ld4(src[0] + i) * w[0];
		for (int q = 1; q < K; q++)
			acc += ld4(src[q] + i) * w[q];
		st4(dst + i, acc * sc + off);
	}
	for (; i < n; i++) {
		float acc = src[0][i] * w[0];
		for (int q = 1; q < K; q++)
			acc += src[q][i] * w[q];
		dst[i] = acc * sc + off;
	}
}

static uint8_t to_u8(float v)
{
	return v <= 0 ? 0 : v >= 255 ? 255 : (uint8_t)(v + 0.5f);
}

/* Writes C channels of colour (0–255 floats) as RGBA8. */
static void put_rgba(uint8_t *o, const float *v, int C)
{
	switch (C) {
	case 1:
		o[0] = o[1] = o[2] = to_u8(v[0]);
		o[3] = 255;
		break;
	case 2:
		o[0] = o[1] = o[2] = to_u8(v[0]);
		o[3] = to_u8(v[1]);
		break;
	case 3:
		o[0] = to_u8(v[0]), o[1] = to_u8(v[1]), o[2] = to_u8(v[2]);
		o[3] = 255;
		break;
	default:
		o[0] = to_u8(v[0]), o[1] = to_u8(v[1]), o[2] = to_u8(v[2]), o[3] = to_u8(v[3]);
		break;
	}
}

/* put_rgba over a row of n RGB texels, without its switch per texel. */
static void put_rgb_row(uint8_t *restrict o, const float *restrict v, uint32_t n)
{
	for (uint32_t i = 0; i < n; i++) {
		o[4 * i] = to_u8(v[3 * i]);
		o[4 * i + 1] = to_u8(v[3 * i + 1]);
		o[4 * i + 2] = to_u8(v[3 * i + 2]);
		o[4 * i + 3] = 255;
	}
}

static void fill_tile(const struct file_source *f, struct tile *out)
{
	size_t n = (size_t)out->size * out->size;
	if (f->kind == FILE_KIND_HEIGHT) {
		float *o = tile_f32(out);
		for (size_t i = 0; i < n; i++)
			o[i] = f->fill_h;
	} else {
		for (size_t i = 0; i < n; i++)
			memcpy(out->data + 4 * i, f->fill_c, 4);
	}
}

/* 1:1 aligned: texel (i, j) is source pixel (lo + i, lo + j); raw holds the region. */
static void copy_aligned(const struct file_source *f, const void *raw, struct tile *out)
{
	uint32_t T = out->size;
	size_t n = (size_t)T * T;
	if (f->kind == FILE_KIND_COLOR) {
		const uint8_t *s = raw;
		int C = f->nch;
		float v[4];
		for (size_t i = 0; i < n; i++) {
			for (int c = 0; c < C; c++)
				v[c] = s[i * C + c];
			put_rgba(out->data + 4 * i, v, C);
		}
		return;
	}
	float *o = tile_f32(out);
	float sc = f->scale, off = f->offset, fill = f->fill_h;
	bool nd = f->has_nodata;
	float ndv = f->nodata;
	if (f->rtype == IMG_U16 && !nd) {
		const uint16_t *s = raw;
		size_t i = 0;
		for (; i + 4 <= n; i += 4) {
			v4u16 u;
			memcpy(&u, s + i, sizeof u);
			st4(o + i, __builtin_convertvector(u, v4f) * sc + off);
		}
		for (; i < n; i++)
			o[i] = (float)s[i] * sc + off;
		return;
	}
	if (f->rtype == IMG_F32 && raw == (const void *)o && !nd) {
		if (sc != 1 || off != 0)
			for (size_t i = 0; i < n; i++)
				o[i] = o[i] * sc + off;
		if (has_nan(o, n))
			for (size_t i = 0; i < n; i++)
				o[i] = o[i] != o[i] ? fill : o[i];
		return;
	}
	for (size_t i = 0; i < n; i++) {
		float v;
		switch (f->rtype) {
		case IMG_U8:
			v = ((const uint8_t *)raw)[i];
			break;
		case IMG_U16:
			v = ((const uint16_t *)raw)[i];
			break;
		case IMG_I16:
			v = ((const int16_t *)raw)[i];
			break;
		default:
			v = ((const float *)raw)[i];
			break;
		}
		bool bad = v != v || (nd && v == ndv);
		o[i] = bad ? fill : v * sc + off;
	}
}

/* The horizontal pass for one channel and plain bilinear taps (the common case): 4 source
 * rows per table entry fetched, so the gather's index and weight loads are shared. */
static void hpass_bilinear(const float *restrict sv, size_t bw, size_t bh,
			   const int32_t *restrict idx, const float *restrict w, uint32_t T,
			   float *restrict tmp)
{
	size_t y = 0;
	for (; y + 4 <= bh; y += 4) {
		const float *s0 = sv + y * bw, *s1 = s0 + bw, *s2 = s1 + bw, *s3 = s2 + bw;
		float *t0 = tmp + y * T, *t1 = t0 + T, *t2 = t1 + T, *t3 = t2 + T;
		for (uint32_t i = 0; i < T; i++) {
			int32_t a = idx[2 * i], b = idx[2 * i + 1];
			float wa = w[2 * i], wb = w[2 * i + 1];
			t0[i] = wa * s0[a] + wb * s0[b];
			t1[i] = wa * s1[a] + wb * s1[b];
			t2[i] = wa * s2[a] + wb * s2[b];
			t3[i] = wa * s3[a] + wb * s3[b];
		}
	}
	for (; y < bh; y++) {
		const float *s0 = sv + y * bw;
		float *t0 = tmp + y * T;
		for (uint32_t i = 0; i < T; i++)
			t0[i] = w[2 * i] * s0[idx[2 * i]] + w[2 * i + 1] * s0[idx[2 * i + 1]];
	}
}

/* A tile that maps 1:1 onto the pixels of level m (file_plan_aligned): one read, no tables,
 * no filtering, straight into the tile when there is nothing to convert. Returns 0 or -EIO. */
static int read_aligned(const struct file_plan *q, struct tile *out)
{
	const struct file_source *f = q->f;
	uint32_t T = q->T;
	bool direct = (f->kind == FILE_KIND_HEIGHT && f->rtype == IMG_F32 && !f->has_nodata) ||
		      (f->kind == FILE_KIND_COLOR && q->C == 4);
	void *dst = direct ? (void *)out->data : q->raw;
	if (read_region(f, q->m, &q->ax, &q->ay, dst, (size_t)T * q->C * q->tsz))
		return -EIO;
	if (!direct || f->kind == FILE_KIND_HEIGHT)
		copy_aligned(f, dst, out);
	return 0;
}

/* Reads level m's row y whole as float (q->pv; masks in q->pm). Returns whether a sample
 * was missing, or -EIO. */
static int read_row(struct file_plan *q, int64_t y, float **v)
{
	const struct file_source *f = q->f;
	struct file_axis cols = { .lo = 0, .hi = q->wm }, rows = { .lo = y, .hi = y + 1 };
	size_t wm = (size_t)q->wm;
	if (read_region(f, q->m, &cols, &rows, q->praw, 0))
		return -EIO;
	*v = f->rtype == IMG_F32 ? (float *)q->praw : q->pv;
	if (f->kind != FILE_KIND_HEIGHT) {
		to_float(f, q->praw, *v, NULL, wm * q->C);
		return 0;
	}
	return to_float(f, q->praw, *v, q->pm, wm);
}

/* The statistics of pole p (0 north, 1 south) at the plan's level: edge is the edge row,
 * cap the last row centre short of the pole. Computed from the file once per level and
 * pole (two threads may both compute it the first time; they get the same numbers).
 * Returns 0, or -EIO. */
static int pole_stats(struct file_plan *q, int p, int64_t edge, int64_t cap,
		      struct file_pole_stats *out)
{
	const struct file_source *f = q->f;
	struct file_pole_stats *st = &f->poles->s[q->m][p];
	xmutex_lock(&f->poles->mu);
	*out = *st;
	xmutex_unlock(&f->poles->mu);
	if (out->done)
		return 0;
	struct file_pole_stats n = { .done = true };
	size_t wm = (size_t)q->wm, C = (size_t)q->C;
	float *v;
	int missing = read_row(q, edge, &v);
	if (missing < 0)
		return missing;
	for (size_t i = 0; i < wm; i++) {
		for (size_t c = 0; c < C; c++)
			n.sum[c] += v[i * C + c];
		n.valid += missing ? q->pm[i] : 1;
	}
	if (cap != edge) {
		int rc = read_row(q, cap, &v);
		if (rc < 0)
			return rc;
		missing |= rc;
	}
	for (size_t i = 0; i < wm && !missing; i++) {
		double lam = (f->west + (i + 0.5) * 360.0 / wm) * (M_PI / 180);
		double cl = cos(lam), sl = sin(lam);
		for (size_t c = 0; c < C; c++)
			n.ca[c] += v[i * C + c] * cl, n.sa[c] += v[i * C + c] * sl;
	}
	n.missing = missing;
	xmutex_lock(&f->poles->mu);
	*st = n;
	xmutex_unlock(&f->poles->mu);
	*out = n;
	return 0;
}

/* A cap's virtual rows (pole_taps) in the horizontal pass's rows `mean` and `harm` (T texels
 * each; with masks, like every row of a pass with masks: valid sum / width, and the valid
 * share in meanm, harmm): the edge row's mean, and the first harmonic of the cap row at each
 * texel's longitude (none where the cap row misses samples). Returns whether a sample was
 * missing, or -EIO. */
static int cap_rows(struct file_plan *q, int p, int64_t edge, int64_t cap, float *mean,
		    float *meanm, float *harm, float *harmm)
{
	size_t wm = (size_t)q->wm, C = (size_t)q->C;
	struct file_pole_stats st;
	int rc = pole_stats(q, p, edge, cap, &st);
	if (rc < 0)
		return rc;
	for (uint32_t i = 0; i < q->T; i++)
		for (size_t c = 0; c < C; c++)
			mean[i * C + c] = (float)(st.sum[c] / wm);
	/* The cap row is box-filtered (iso_rows): its first harmonic by sinc(π w / wm). */
	double x = M_PI * file_plan_iso_width(q, cap) / (double)wm;
	double damp = x > 0 ? sin(x) / x : 1;
	for (uint32_t i = 0; i < q->T; i++) {
		double lam = (q->r.west + (i + 0.5) * q->dlon) * (M_PI / 180);
		double cl = cos(lam), sl = sin(lam);
		for (size_t c = 0; c < C; c++)
			harm[i * C + c] = (float)(2 * damp * (st.ca[c] * cl + st.sa[c] * sl) / wm);
	}
	if (meanm)
		for (uint32_t i = 0; i < q->T; i++)
			meanm[i] = (float)(st.valid / wm), harmm[i] = 0;
	return st.missing;
}

/* Reads the region the tables reach (and the pole rows they blend into) as float samples;
 * q->missing tells whether masks are live. Returns 0 or -EIO / -EFAULT. */
static int read_source(struct file_plan *q)
{
	const struct file_source *f = q->f;
	q->bw = (size_t)(q->ax.hi - q->ax.lo);
	q->bh = (size_t)(q->ay.hi - q->ay.lo);
	if (q->bw > q->bwmax || q->bh > q->bhmax)
		return -EFAULT; /* a bound above is wrong: never read past the scratch */
	if (read_region(f, q->m, &q->ax, &q->ay, q->raw, q->bw * q->C * q->tsz))
		return -EIO;
	size_t nsrc = q->bw * q->bh * q->C;
	q->sv = f->rtype == IMG_F32 ? (float *)q->raw : q->src;
	q->missing = false;
	if (f->kind == FILE_KIND_HEIGHT) {
		bool check = f->has_nodata || has_nan(f->rtype == IMG_F32 ? (float *)q->raw : NULL,
						       f->rtype == IMG_F32 ? nsrc : 0);
		q->missing = to_float(f, q->raw, q->sv, check ? q->mask : NULL, nsrc);
	} else {
		to_float(f, q->raw, q->sv, NULL, nsrc);
	}
	/* The caps' virtual rows after the region's bh rows of the horizontal pass. */
	size_t TC = (size_t)q->T * q->C, T = q->T;
	bool pole_missing = false;
	for (int p = 0; p < 2; p++) {
		if (!(p ? q->ay.use_s : q->ay.use_n))
			continue;
		size_t mr = q->bh + (p ? VROW_MEAN_S : VROW_MEAN_N);
		size_t hr = q->bh + (p ? VROW_HARM_S : VROW_HARM_N);
		int rc = cap_rows(q, p, p ? q->hm - 1 : 0, (int64_t)(p ? q->ay.cap_s : q->ay.cap_n),
				  q->tmp + mr * TC, q->tmpm ? q->tmpm + mr * T : NULL,
				  q->tmp + hr * TC, q->tmpm ? q->tmpm + hr * T : NULL);
		if (rc < 0)
			return rc;
		pole_missing |= rc > 0;
	}
	if (pole_missing && !q->missing) {
		for (size_t i = 0; i < q->bw * q->bh; i++)
			q->mask[i] = 1; /* the region had nothing missing */
		q->missing = true;
	}
	return 0;
}

/* The integral from -1/2 to x of the piecewise-constant row whose prefix sums are P (pixel k
 * spans [k - 1/2, k + 1/2]; 0 <= x + 1/2 <= n). */
static double row_integral(const double *P, size_t n, double x)
{
	double u = x + 0.5;
	size_t k = (size_t)u;
	if (k >= n)
		return P[n];
	return P[k] + (u - (double)k) * (P[k + 1] - P[k]);
}

/* Prefix sums P[0..m] of m samples v[0], v[stride], … */
static void prefix_sums(const float *v, size_t stride, size_t m, double *P)
{
	P[0] = 0;
	for (size_t i = 0; i < m; i++)
		P[i + 1] = P[i] + v[i * stride];
}

/* The mean over the box [x - w/2, x + w/2] of the piecewise-constant row whose prefix sums
 * are P (n samples; the prefilter of file_resample.h). Circular when p > 0 (period p = n:
 * any x), else the box is clipped to the row and renormalised. */
static double box_mean(const double *P, size_t n, bool circular, double x, double w)
{
	double a = x - w / 2, b = x + w / 2;
	if (circular) {
		/* Whole turns, then the rest within [-1/2, n - 1/2). */
		double fa = floor((a + 0.5) / (double)n), fb = floor((b + 0.5) / (double)n);
		return ((fb - fa) * P[n] + row_integral(P, n, b - fb * (double)n) -
			row_integral(P, n, a - fa * (double)n)) / w;
	}
	a = a < -0.5 ? -0.5 : a;
	b = b > (double)n - 0.5 ? (double)n - 0.5 : b;
	return (row_integral(P, n, b) - row_integral(P, n, a)) / (b - a);
}

/* Region row samples v[j·stride], j in [o0, o1), become the box means of a row with prefix
 * sums P (n samples, circular or not) at x = base + j. The box's ends move one pixel a
 * sample, their fractions fixed: no floor() or division per sample (box_mean only where a
 * clipped box needs renormalising). */
static void box_write(float *v, size_t stride, size_t o0, size_t o1, const double *P, size_t n,
		      bool circular, double base, double w)
{
	double ua = base + (double)o0 - w / 2 + 0.5, ub = ua + w; /* pixel k spans [k, k + 1) */
	double fla = floor(ua), flb = floor(ub), fa = ua - fla, fb = ub - flb, inv = 1 / w;
	int64_t ka = (int64_t)fla, kb = (int64_t)flb, N = (int64_t)n;
	double turns = 0; /* whole turns between the box's ends' pixels, times the row's sum */
	if (circular) {
		int64_t ta = ka >= 0 ? ka / N : -((-ka + N - 1) / N);
		int64_t tb = kb >= 0 ? kb / N : -((-kb + N - 1) / N);
		ka -= ta * N;
		kb -= tb * N;
		turns = (double)(tb - ta) * P[n];
	}
	for (size_t j = o0; j < o1; j++) {
		if (!circular && (ka < 0 || kb >= N)) {
			v[j * stride] = (float)box_mean(P, n, false, base + (double)j, w);
		} else {
			double Ga = P[ka] + fa * (P[ka + 1] - P[ka]);
			double Gb = P[kb] + fb * (P[kb + 1] - P[kb]);
			v[j * stride] = (float)((turns + Gb - Ga) * inv);
		}
		ka++, kb++;
		if (circular) {
			if (ka == N)
				ka = 0, turns -= P[n];
			if (kb == N)
				kb = 0, turns += P[n];
		}
	}
}

/* The east–west prefilter (`isotropic`, file_resample.h) of every region row that needs
 * it, values and valid weights alike, at the columns the taps read. A row whose box is
 * wider than the region's widening serves (the last rows before a pole) is read whole.
 * Before the horizontal pass. Returns 0 or -EIO. */
static int iso_rows(struct file_plan *q)
{
	if (q->iso_wmax <= 0)
		return 0;
	const struct file_source *f = q->f;
	size_t bw = q->bw, C = (size_t)q->C, wm = (size_t)q->wm;
	bool whole = f->wrap && bw >= wm; /* the region holds every column: filter round it */
	size_t o0 = (size_t)q->iso_t0, o1 = (size_t)q->iso_t1;
	for (size_t y = 0; y < q->bh; y++) {
		int64_t Y = q->ay.lo + (int64_t)y;
		double w = file_plan_iso_width(q, Y);
		if (w <= 0)
			continue;
		float *sv = q->sv + y * bw * C, *mk = q->mask ? q->mask + y * bw : NULL;
		if (whole || w <= q->iso_wreg) {
			size_t n = whole ? wm : bw;
			for (size_t c = 0; c < C; c++) {
				prefix_sums(sv + c, C, n, q->psum);
				box_write(sv + c, C, o0, o1, q->psum, n, whole, 0, w);
			}
			if (q->missing) {
				prefix_sums(mk, 1, n, q->psum);
				box_write(mk, 1, o0, o1, q->psum, n, whole, 0, w);
			}
			continue;
		}
		float *row;
		int rc = read_row(q, Y, &row);
		if (rc < 0)
			return rc;
		if (rc > 0 && !q->missing) {
			for (size_t i = 0; i < bw * q->bh; i++)
				q->mask[i] = 1; /* the region had nothing missing */
			q->missing = true;
		}
		/* Region column j is level column ax.lo + j (wrapped round a 360° row). */
		double base = (double)q->ax.lo;
		for (size_t c = 0; c < C; c++) {
			prefix_sums(row + c, C, wm, q->psum);
			box_write(sv + c, C, o0, o1, q->psum, wm, f->wrap, base, w);
		}
		if (q->missing) {
			if (rc > 0) {
				prefix_sums(q->pm, 1, wm, q->psum);
			} else { /* a whole row without a missing sample */
				q->psum[0] = 0;
				for (size_t i = 0; i < wm; i++)
					q->psum[i + 1] = (double)(i + 1);
			}
			box_write(mk, 1, o0, o1, q->psum, wm, f->wrap, base, w);
		}
	}
	return 0;
}

/* Horizontal pass: every source row of the region → T texel columns (and their valid
 * weights when masks are live). */
static void hpass(struct file_plan *q)
{
	uint32_t T = q->T;
	int C = q->C, Kx = q->ax.K;
	const int32_t *idx = q->ax.idx;
	const float *wx = q->ax.w;
	size_t bw = q->bw, bh = q->bh, y0 = 0;
	if (C == 1 && Kx == 2 && !q->missing) {
		hpass_bilinear(q->sv, bw, bh, idx, wx, T, q->tmp);
		y0 = bh;
	}
	for (size_t y = y0; y < bh; y++) {
		const float *s = q->sv + y * bw * C;
		float *t = q->tmp + y * T * C;
		for (uint32_t i = 0; i < T; i++) {
			const int32_t *ix = idx + (size_t)i * Kx;
			const float *w = wx + (size_t)i * Kx;
			for (int c = 0; c < C; c++) {
				float acc = 0;
				for (int k = 0; k < Kx; k++)
					acc += w[k] * s[(size_t)ix[k] * C + c];
				t[(size_t)i * C + c] = acc;
			}
		}
		if (q->missing) {
			const float *ms = q->mask + y * bw;
			float *tm = q->tmpm + y * T;
			for (uint32_t i = 0; i < T; i++) {
				const int32_t *ix = idx + (size_t)i * Kx;
				const float *w = wx + (size_t)i * Kx;
				float acc = 0;
				for (int k = 0; k < Kx; k++)
					acc += w[k] * ms[ix[k]];
				tm[i] = acc;
			}
		}
	}
}

/* Output row j, all texels the fill. */
static void fill_row(const struct file_source *f, struct tile *out, uint32_t j)
{
	uint32_t T = out->size;
	if (f->kind == FILE_KIND_HEIGHT) {
		float *o = tile_f32(out) + (size_t)j * T;
		for (uint32_t i = 0; i < T; i++)
			o[i] = f->fill_h;
	} else {
		for (uint32_t i = 0; i < T; i++)
			memcpy(out->data + ((size_t)j * T + i) * 4, f->fill_c, 4);
	}
}

/* Vertical pass: the horizontal pass's rows → the tile; heights with missing samples
 * renormalised by their valid weight. */
static void vpass(const struct file_plan *q, struct tile *out)
{
	const struct file_source *f = q->f;
	uint32_t T = q->T;
	int C = q->C, Ky = q->ay.K;
	size_t TC = (size_t)T * C;
	float *row = q->row, *rowm = q->row + TC;
	for (uint32_t j = 0; j < T; j++) {
		if (!q->ay.in[j]) {
			fill_row(f, out, j);
			continue;
		}
		const int32_t *iy = q->ay.idx + (size_t)j * Ky;
		const float *wy = q->ay.w + (size_t)j * Ky;
		const float *rows[3 * FILE_MAX_SUBTAPS];
		for (int k = 0; k < Ky; k++)
			rows[k] = q->tmp + (size_t)iy[k] * TC;
		if (f->kind == FILE_KIND_HEIGHT && !q->missing) {
			/* Straight into the tile; columns outside the bounds patched after. */
			float *o = tile_f32(out) + (size_t)j * T;
			wsum(o, rows, wy, Ky, T, f->scale, f->offset);
			if (!q->ax.all)
				for (uint32_t i = 0; i < T; i++)
					o[i] = q->ax.in[i] ? o[i] : f->fill_h;
			continue;
		}
		wsum(row, rows, wy, Ky, TC, 1, 0);
		if (f->kind == FILE_KIND_COLOR) {
			uint8_t *o = out->data + (size_t)j * T * 4;
			if (q->ax.all && C == 3) { /* the usual RGB file inside its bounds */
				put_rgb_row(o, row, T);
				continue;
			}
			for (uint32_t i = 0; i < T; i++) {
				if (q->ax.in[i])
					put_rgba(o + 4 * i, row + (size_t)i * C, C);
				else
					memcpy(o + 4 * i, f->fill_c, 4);
			}
			continue;
		}
		const float *mrows[3 * FILE_MAX_SUBTAPS];
		for (int k = 0; k < Ky; k++)
			mrows[k] = q->tmpm + (size_t)iy[k] * T;
		wsum(rowm, mrows, wy, Ky, T, 1, 0);
		float *o = tile_f32(out) + (size_t)j * T;
		float sc = f->scale, off = f->offset, fill = f->fill_h;
		for (uint32_t i = 0; i < T; i++)
			o[i] = q->ax.in[i] && rowm[i] >= 0.5f ? row[i] / rowm[i] * sc + off : fill;
	}
}

int file_resample(const struct file_source *f, struct gen_ctx *g, const struct tile_key *k,
		  struct tile *out)
{
	struct file_plan q;
	int rc = file_plan_init(&q, f, k, out->size);
	if (rc)
		return rc;
	file_plan_buffers(&q, g);
	file_plan_coords(&q);
	if (file_plan_aligned(&q))
		return read_aligned(&q, out);
	file_plan_tables(&q);
	if (!q.ax.any || !q.ay.any) {
		fill_tile(f, out);
		return 0;
	}
	if ((rc = read_source(&q)))
		return rc;
	if (q.missing && (file_axis_catmull_rom(&q.ax) || file_axis_catmull_rom(&q.ay)))
		file_plan_bilinear(&q);
	if ((rc = iso_rows(&q)))
		return rc;
	hpass(&q);
	vpass(&q, out);
	return 0;
}
