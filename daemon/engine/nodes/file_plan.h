/* file_plan — one tile's resampling plan, internal to the `file` node's resampler
 * (file_resample.h has the design): the MIP level read, the per-axis tap tables (bilinear
 * sub-taps, the polar caps' three-tap blends), the source region they reach, the 1:1 test,
 * and the layout of every buffer in one gen_scratch block. file_resample.c reads the region
 * and runs the passes over these tables.
 * Threads: a struct file_plan lives on one worker's stack for one tile; nothing is shared.
 * Ownership: the plan borrows its file_source; its buffers point into the gen_ctx's scratch
 * (valid until that ctx's next gen_scratch), and the plan frees nothing.
 */
#ifndef CLIPMAP_FILE_PLAN_H
#define CLIPMAP_FILE_PLAN_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "file_resample.h"

#define FILE_MAX_SUBTAPS 256

/* The virtual rows of the polar caps (pole_taps), after the region's bh rows in the
 * horizontal pass's output: the edge rows' means and the cap rows' first harmonics. */
enum { VROW_MEAN_N, VROW_MEAN_S, VROW_HARM_N, VROW_HARM_S, VROWS };

/* The per-axis resampling table: output texel i reads taps idx[i·K + k] (relative to the
 * buffer's first source pixel `lo`) with weights w[i·K + k], K = taps·n: taps 2 (bilinear),
 * 3 (with the polar caps in reach), 4 (heights magnified: Catmull-Rom, or a cubic B-spline
 * with `magnify = bspline`). */
struct file_axis {
	int n, K, taps;
	bool bspline; /* 4 taps: a cubic B-spline's weights, not Catmull-Rom's */
	int32_t *idx;
	float *w;
	uint8_t *in; /* texel centre inside the bounds */
	int64_t lo, hi;	 /* source pixels the buffer holds (unwrapped when wrapping) */
	bool any, all; /* some / every texel inside */
	/* Latitude axis of a global image, the polar caps (pole_taps): in sample coordinates
	 * (row i's centre at i) the last row centre short of each pole and the pole (NAN: no
	 * cap in this tile's reach: clamp); whether some tap reads a cap's virtual rows. */
	double cap_n, cap_s, pole_n, pole_s;
	bool caps; /* a cap is in this tile's reach: taps may be pole_taps */
	bool use_n, use_s;
};

/* One tile's resampling: the level and tables, then the buffers (one gen_scratch block). */
struct file_plan {
	const struct file_source *f; /* borrowed */
	uint32_t T;
	int C;		 /* channels read */
	size_t tsz;	 /* bytes per raw sample */
	struct geo_rect r;
	double dlon, dlat; /* texel size, degrees */
	int m, wm, hm;	 /* the MIP level read and its size */
	double rx, ry;	 /* texel spacing in level-m pixels */
	struct file_axis ax, ay;
	size_t bwmax, bhmax; /* bounds of the region read */
	bool maskable;	     /* the source can have missing samples */
	double base;	     /* with wrapping: texel 0's offset east of the west bound, degrees */
	/* The east–west prefilter (`isotropic`, file_resample.h): a level-m pixel's height over
	 * its width in degrees, the horizontal pass's own footprint in pixels, and the widest
	 * box a row of this tile's reach may need (0: none; the region grows by half of it). */
	double iso_aspect, iso_rx, iso_wmax;
	double iso_wreg;	/* the widest box the region's widening serves (FILE_ISO_WIDE at
				 * most); a row needing more is read whole (a few rows by a pole) */
	int64_t iso_t0, iso_t1; /* the columns the taps read, relative to the region's first */
	double *psum; /* one row's prefix sums: (max(bwmax, level width) + 1) doubles */
	double *cx, *cy;     /* texel centres, level-m pixel units */
	void *raw;	     /* the region as read */
	float *src, *mask;   /* ... as float (sv: src, or raw itself for float files) */
	float *tmp, *tmpm;   /* horizontal pass: bh rows + VROWS virtual rows of T texels */
	float *row;	     /* one output row (and its weights) */
	void *praw;	     /* one whole level-m row, for a pole's mean */
	float *pv, *pm;
	/* filled by file_resample.c's read */
	float *sv;
	size_t bw, bh;
	bool missing; /* some sample read is missing: masks are live */
};

/* The level, the per-axis tap counts and the region bounds of tile k, T texels square.
 * Borrows f (kept in q->f) and k. Returns 0 or -EFBIG (the region would be too large). */
int file_plan_init(struct file_plan *q, const struct file_source *f, const struct tile_key *k,
		   uint32_t T);
/* The prefilter's box width in level-m pixels for source row Y (0: no filter), at most the
 * level's width (a whole row: its mean). */
double file_plan_iso_width(const struct file_plan *q, int64_t Y);
/* Carves q's buffers out of g's scratch (valid until g's next gen_scratch). */
void file_plan_buffers(struct file_plan *q, struct gen_ctx *g);
/* Texel centres in level-m pixel units: rows all, columns texel 0's only (the rest in
 * file_plan_tables, once file_plan_aligned has said no). */
void file_plan_coords(struct file_plan *q);
/* Whether the tile maps 1:1 onto the pixels of level m; if so, sets the axes' lo, hi to the
 * T × T pixels to copy (and builds no tables). After file_plan_coords. */
bool file_plan_aligned(struct file_plan *q);
/* The remaining column centres and both axes' tap tables (idx, w, in, lo, hi, any, all,
 * use_n, use_s). After file_plan_coords. */
void file_plan_tables(struct file_plan *q);

/* Whether axis a is Catmull-Rom (four taps, some weights negative): what a tile with missing
 * samples cannot use (file_plan_bilinear). */
static inline bool file_axis_catmull_rom(const struct file_axis *a)
{
	return a->taps == 4 && !a->bspline;
}

/* The tables again, bilinear where they were Catmull-Rom, over the region already read
 * (its bounds kept): for a tile whose samples turned out to have missing ones (a cubic's
 * negative weights would extrapolate past the valid data; a B-spline's are never negative and
 * stay). After file_plan_tables. */
void file_plan_bilinear(struct file_plan *q);

#endif
