/* vector_raster — the coverage accumulator (vector_raster.h). The cell arithmetic follows
 * Raph Levien's font-rs accumulate rasterizer; clipping is done here in doubles so that tile
 * coordinates far outside [0, W] (a wide line at a fine level, a polygon spanning the globe)
 * keep their precision. */
#include "vector_raster.h"

#include <math.h>
#include <string.h>

void vr_acc_init(struct vr_acc *acc, float *buf, int w, int h)
{
	acc->a = buf;
	acc->w = w;
	acc->h = h;
	acc->y0 = h;
	acc->y1 = 0;
	acc->zeroed = 0;
}

/* An edge inside the rows [0, H] and the columns [0, W]: font-rs's draw_line. */
static void line(struct vr_acc *acc, double x0, double y0, double x1, double y1)
{
	if (y0 == y1)
		return;
	if (!acc->zeroed) {
		memset(acc->a, 0, vr_acc_floats(acc->w, acc->h) * sizeof *acc->a);
		acc->zeroed = 1;
	}
	double dir = 1;
	if (y0 > y1) {
		double t = x0;
		x0 = x1, x1 = t;
		t = y0, y0 = y1, y1 = t;
		dir = -1;
	}
	const int W = acc->w, stride = W + 2;
	double dxdy = (x1 - x0) / (y1 - y0);
	double x = x0;
	int ya = (int)y0, yb = (int)ceil(y1);
	yb = yb < acc->h ? yb : acc->h;
	if (ya < acc->y0)
		acc->y0 = ya;
	if (yb > acc->y1)
		acc->y1 = yb;
	for (int y = ya; y < yb; y++) {
		float *row = acc->a + (size_t)y * stride;
		double dy = fmin(y + 1.0, y1) - fmax((double)y, y0);
		double xnext = x + dxdy * dy;
		double d = dy * dir;
		double xa = x < xnext ? x : xnext, xb = x < xnext ? xnext : x;
		xa = xa < 0 ? 0 : xa > W ? W : xa;
		xb = xb < 0 ? 0 : xb > W ? W : xb;
		double xaf = floor(xa), xbc = ceil(xb);
		int xai = (int)xaf, xbi = (int)xbc;
		if (xbi <= xai + 1) {
			double xm = 0.5 * (xa + xb) - xaf;
			row[xai] += (float)(d - d * xm);
			row[xai + 1] += (float)(d * xm);
		} else {
			double s = 1 / (xb - xa);
			double x0f = xa - xaf;
			double a0 = 0.5 * s * (1 - x0f) * (1 - x0f);
			double x1f = xb - xbc + 1;
			double am = 0.5 * s * x1f * x1f;
			row[xai] += (float)(d * a0);
			if (xbi == xai + 2) {
				row[xai + 1] += (float)(d * (1 - a0 - am));
			} else {
				double a1 = s * (1.5 - x0f);
				row[xai + 1] += (float)(d * (a1 - a0));
				for (int xi = xai + 2; xi < xbi - 1; xi++)
					row[xi] += (float)(d * s);
				double a2 = a1 + (xbi - xai - 3) * s;
				row[xbi - 1] += (float)(d * (1 - a2 - am));
			}
			row[xbi] += (float)(d * am);
		}
		x = xnext;
	}
}

/* Splits at x = 0 and x = W so that each piece clamps to a straight edge. */
static void clamp_x(struct vr_acc *acc, double x0, double y0, double x1, double y1)
{
	const double W = acc->w;
	double cut[2];
	int nc = 0;
	double lo = x0 < x1 ? x0 : x1, hi = x0 < x1 ? x1 : x0;
	if (lo < 0 && hi > 0)
		cut[nc++] = (0 - x0) / (x1 - x0);
	if (lo < W && hi > W)
		cut[nc++] = (W - x0) / (x1 - x0);
	if (nc == 2 && cut[0] > cut[1]) {
		double t = cut[0];
		cut[0] = cut[1], cut[1] = t;
	}
	double px = x0, py = y0;
	for (int i = 0; i <= nc; i++) {
		double qx, qy;
		if (i < nc) {
			qx = x0 + (x1 - x0) * cut[i];
			qy = y0 + (y1 - y0) * cut[i];
		} else {
			qx = x1, qy = y1;
		}
		double a = px < 0 ? 0 : px > W ? W : px, b = qx < 0 ? 0 : qx > W ? W : qx;
		line(acc, a, py, b, qy);
		px = qx, py = qy;
	}
}

void vr_edge(struct vr_acc *acc, double x0, double y0, double x1, double y1)
{
	const double H = acc->h;
	if ((y0 <= 0 && y1 <= 0) || (y0 >= H && y1 >= H) || y0 == y1)
		return;
	if (x0 >= acc->w && x1 >= acc->w)
		return; /* east of the tile: winds nothing inside it */
	/* Clip to the rows [0, H]. */
	if (y0 < 0 || y1 < 0 || y0 > H || y1 > H) {
		double t0 = 0, t1 = 1, dy = y1 - y0;
		double ta = (0 - y0) / dy, tb = (H - y0) / dy;
		double lo = ta < tb ? ta : tb, hi = ta < tb ? tb : ta;
		t0 = lo > t0 ? lo : t0;
		t1 = hi < t1 ? hi : t1;
		if (t0 >= t1)
			return;
		double dx = x1 - x0;
		double nx0 = x0 + dx * t0, ny0 = y0 + dy * t0;
		double nx1 = x0 + dx * t1, ny1 = y0 + dy * t1;
		x0 = nx0, y0 = ny0, x1 = nx1, y1 = ny1;
		y0 = y0 < 0 ? 0 : y0 > H ? H : y0;
		y1 = y1 < 0 ? 0 : y1 > H ? H : y1;
	}
	if (x0 <= 0 && x1 <= 0)
		line(acc, 0, y0, 0, y1);
	else
		clamp_x(acc, x0, y0, x1, y1);
}

void vr_convex(struct vr_acc *acc, const double *xy, int n)
{
	double a = 0;
	for (int i = 0; i < n; i++) {
		int j = (i + 1) % n;
		a += xy[2 * i] * xy[2 * j + 1] - xy[2 * j] * xy[2 * i + 1];
	}
	/* Rings counter-clockwise in (lon, lat) are clockwise in (x east, y south): a < 0. */
	if (a < 0)
		for (int i = 0; i < n; i++) {
			int j = (i + 1) % n;
			vr_edge(acc, xy[2 * i], xy[2 * i + 1], xy[2 * j], xy[2 * j + 1]);
		}
	else
		for (int i = n; i > 0; i--) {
			int j = i - 1, k = i % n;
			vr_edge(acc, xy[2 * k], xy[2 * k + 1], xy[2 * j], xy[2 * j + 1]);
		}
}

void vr_resolve(struct vr_acc *acc, float *cov, int *ya, int *yb)
{
	*ya = acc->y0;
	*yb = acc->y1 > acc->y0 ? acc->y1 : acc->y0;
	const int W = acc->w, stride = W + 2;
	for (int y = acc->y0; y < acc->y1; y++) {
		float *row = acc->a + (size_t)y * stride, *c = cov + (size_t)y * W;
		float s = 0;
		for (int x = 0; x < W; x++) {
			s += row[x];
			float v = fabsf(s);
			c[x] = v < 1 ? v : 1;
		}
		memset(row, 0, (size_t)stride * sizeof *row);
	}
	acc->y0 = acc->h;
	acc->y1 = 0;
}
