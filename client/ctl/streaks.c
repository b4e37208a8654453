/* streaks — row streak repair (see streaks.h). */
#include "streaks.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "common/xalloc.h"

static double get(enum img_type t, const unsigned char *p, int64_t i)
{
	switch (t) {
	case IMG_U8: return p[i];
	case IMG_U16: { uint16_t v; memcpy(&v, p + 2 * i, 2); return v; }
	case IMG_I16: { int16_t v; memcpy(&v, p + 2 * i, 2); return v; }
	case IMG_F32: { float v; memcpy(&v, p + 4 * i, 4); return v; }
	default: return NAN;
	}
}

static void set(enum img_type t, unsigned char *p, int64_t i, double v)
{
	switch (t) {
	case IMG_U8: p[i] = (uint8_t)lround(v); break;
	case IMG_U16: { uint16_t u = (uint16_t)lround(v); memcpy(p + 2 * i, &u, 2); break; }
	case IMG_I16: { int16_t u = (int16_t)lround(v); memcpy(p + 2 * i, &u, 2); break; }
	case IMG_F32: { float u = (float)v; memcpy(p + 4 * i, &u, 4); break; }
	default: break;
	}
}

void streaks_init(struct streaks *s, double thresh, int len, int64_t w, int nch,
		  enum img_type t, bool has_nd, double nd)
{
	*s = (struct streaks){ .thresh = thresh, .len = len < 1 ? 1 : len, .w = w, .nch = nch,
			       .type = t, .has_nd = has_nd && t != IMG_F32, .nd = nd };
	s->row = img_type_bytes(t) * (size_t)nch * (size_t)w;
	s->dep = xmalloc(sizeof *s->dep * (size_t)w);
	s->orig[0] = xmalloc(s->row);
	s->orig[1] = xmalloc(s->row);
}

void streaks_free(struct streaks *s)
{
	free(s->dep);
	free(s->orig[0]);
	free(s->orig[1]);
	*s = (struct streaks){ 0 };
}

static bool valid(const struct streaks *s, double v)
{
	return isfinite(v) && !(s->has_nd && v == s->nd);
}

/* Whether column i sits beyond both neighbours by more than lim, on the side sign gives. */
static bool beyond(const struct streaks *s, int64_t i, double lim, bool up)
{
	double d = s->dep[i];
	return up ? d > lim : d < -lim;
}

/* Channel c of row cur against north N and south S: returns the samples replaced. */
static int64_t repair_channel(struct streaks *s, unsigned char *cur, const unsigned char *N,
			      const unsigned char *S, int c)
{
	int64_t w = s->w, k = s->nch, fixed = 0;
	for (int64_t i = 0; i < w; i++) {
		double v = get(s->type, cur, i * k + c), a = get(s->type, N, i * k + c),
		       b = get(s->type, S, i * k + c);
		double lo = a < b ? a : b, hi = a < b ? b : a;
		s->dep[i] = !valid(s, v) || !valid(s, a) || !valid(s, b) ? 0
			    : v > hi				       ? v - hi
			    : v < lo				       ? v - lo
								       : 0;
	}
	for (int64_t i = 0; i < w;) {
		bool up = s->dep[i] > 0;
		if (!beyond(s, i, s->thresh, up)) {
			i++;
			continue;
		}
		int64_t j = i;
		while (j < w && beyond(s, j, s->thresh, up))
			j++;
		if (j - i < s->len) {
			i = j;
			continue;
		}
		int64_t a = i, b = j;
		while (a > 0 && beyond(s, a - 1, s->thresh / 8, up))
			a--;
		while (b < w && beyond(s, b, s->thresh / 8, up))
			b++;
		for (int64_t x = a; x < b; x++) {
			double m = (get(s->type, N, x * k + c) + get(s->type, S, x * k + c)) / 2;
			/* an integer mean may round onto nodata: never make a void */
			if (s->has_nd && (double)lround(m) == s->nd)
				m += m < s->nd ? -1 : 1;
			set(s->type, cur, x * k + c, m);
		}
		fixed += b - a;
		i = b;
	}
	return fixed;
}

int64_t streaks_repair(struct streaks *s, unsigned char *buf, int nrows, int first, int n)
{
	int64_t fixed = 0;
	for (int r = first; r < first + n; r++) {
		unsigned char *cur = buf + (size_t)r * s->row;
		memcpy(s->orig[r & 1], cur, s->row);
		if (r < 1 || r + 1 >= nrows)
			continue;
		/* the row above as it was read: its copy, when it was repaired here */
		const unsigned char *N = r - 1 >= first ? s->orig[(r - 1) & 1]
						       : buf + (size_t)(r - 1) * s->row;
		const unsigned char *S = cur + s->row;
		for (int c = 0; c < s->nch; c++)
			fixed += repair_channel(s, cur, N, S, c);
	}
	return fixed;
}
