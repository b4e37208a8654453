/* vector_raster — exact area coverage of polygons in a tile's texel space (the signed-area
 * accumulation of font-rs / stb_truetype): each edge adds, to the cells of the rows it
 * crosses, the signed area between it and the cell's right side; a running sum along a row
 * then gives the winding integrated over each texel, and min(1, |sum|) its coverage (the
 * non-zero rule, so overlapping shapes of one orientation form their union).
 *
 * Edges are clipped to the rows [0, H) and clamped to the columns [0, W]: an edge west of the
 * tile still winds the texels east of it; one east of it adds nothing. Exact for polygons
 * (up to float sums), so tiles that share a border get complementary areas.
 *
 * Threads: a vr_acc is one caller's (per-call scratch); nothing is shared.
 */
#ifndef CLIPMAP_VECTOR_RASTER_H
#define CLIPMAP_VECTOR_RASTER_H
#include <stddef.h>
#include <stdint.h>

struct vr_acc {
	float *a;     /* H rows of W + 2 cells */
	int w, h;
	int y0, y1;   /* rows touched since the last clear: [y0, y1) */
	int zeroed;   /* a is zero (cleared on the first edge: empty tiles skip it) */
};

/* Scratch floats a vr_acc of w × h needs. */
static inline size_t vr_acc_floats(int w, int h) { return (size_t)(w + 2) * (size_t)h; }
/* Points acc at buf (vr_acc_floats(w, h) floats, borrowed); it is zeroed before the first
 * edge lands in it. */
void vr_acc_init(struct vr_acc *acc, float *buf, int w, int h);
/* Adds the directed edge (x0, y0) → (x1, y1) in texel coordinates (x east, y south). */
void vr_edge(struct vr_acc *acc, double x0, double y0, double x1, double y1);
/* Adds the closed convex polygon xy[0..n) (n points, not repeated), oriented so that every
 * shape added this way winds the same way as rings stored counter-clockwise in (lon, lat). */
void vr_convex(struct vr_acc *acc, const double *xy, int n);
/* Turns the rows touched, [*ya, *yb), into coverage in [0, 1] (cov: w × h, row-major; other
 * rows are not written: their coverage is 0), and clears the accumulator for reuse. */
void vr_resolve(struct vr_acc *acc, float *cov, int *ya, int *yb);

#endif
