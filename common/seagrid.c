/* seagrid — see seagrid.h. */
#include "common/seagrid.h"

#include <math.h>
#include <stddef.h>

int sea_grid_valid_size(uint32_t rows, uint32_t cols)
{
	if (rows == 0 && cols == 0)
		return 1;
	return rows >= SEA_GRID_MIN && rows <= SEA_GRID_MAX_ROWS && cols >= SEA_GRID_MIN &&
	       cols <= SEA_GRID_MAX_COLS;
}

double sea_grid_at(const struct sea_grid *g, double lat, double lon)
{
	if (!g || !g->rows || !g->cols || !g->dm)
		return 0;
	double fr = (lat + 90.0) / 180.0 * (g->rows - 1);
	double fc = (lon + 180.0) / 360.0 * g->cols;
	if (!(fr > 0)) /* NaN too */
		fr = 0;
	if (fr > g->rows - 1)
		fr = g->rows - 1;
	fc = fmod(fc, g->cols);
	if (fc < 0)
		fc += g->cols;
	if (!(fc >= 0 && fc < g->cols))
		fc = 0;
	int r0 = (int)fr, c0 = (int)fc;
	int r1 = r0 + 1 < g->rows ? r0 + 1 : r0;
	int c1 = c0 + 1 < g->cols ? c0 + 1 : 0;
	double wr = fr - r0, wc = fc - c0;
	const int16_t *a = g->dm + (size_t)r0 * g->cols, *b = g->dm + (size_t)r1 * g->cols;
	double s = a[c0] + (a[c1] - a[c0]) * wc, n = b[c0] + (b[c1] - b[c0]) * wc;
	return (s + (n - s) * wr) / 10.0;
}

void sea_grid_range(const struct sea_grid *g, double *lo, double *hi)
{
	*lo = *hi = 0;
	if (!g || !g->rows || !g->cols || !g->dm)
		return;
	int mn = g->dm[0], mx = g->dm[0];
	for (size_t i = 1; i < (size_t)g->rows * g->cols; i++) {
		if (g->dm[i] < mn)
			mn = g->dm[i];
		if (g->dm[i] > mx)
			mx = g->dm[i];
	}
	*lo = mn / 10.0;
	*hi = mx / 10.0;
}
