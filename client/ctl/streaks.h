/* streaks — repairs scan-line defects of a raster as it streams through import: a run of at
 * least `len` samples of one row that sits more than `thresh` (the samples' unit: metres for
 * heights) above both rows beside it, or below both, is a row of another place pasted in,
 * not relief. Each such sample, and the samples that continue the run on either side while
 * they still sit more than thresh / 8 beyond both neighbours the same way, is replaced by
 * the mean of the samples north and south of it.
 *
 * ETOPO5 as ferret-datasets ships it has two: at 81.17°S from 66.7°W to 0° (up to 1.7 km
 * above the Filchner–Ronne ice shelf, then ~2 km below the plateau) and at 81.25°S from
 * 0° to 40°E (samples of ~122 m where the rows either side hold 2 713 m and 2 682 m) — a
 * trench one row wide across Queen Maud Land that the viewer drew as a dark arc. No other row of it has a run of more than 18
 * samples beyond 500 m (scanned); real relief a row wide is short.
 *
 * Runs do not wrap from the last column to the first. The first and last rows of the raster
 * have one neighbour and are left as they are. Channels are repaired independently; a NaN,
 * an infinity or the integer nodata value in a row or its neighbours ends a run there, and a
 * mean that would round onto the nodata value is moved one unit off it.
 * Not thread-safe per struct streaks.
 */
#ifndef CLIPMAP_STREAKS_H
#define CLIPMAP_STREAKS_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/img.h"

#define STREAKS_LEN 48 /* default run length: 4° of a 5′ grid */

struct streaks {
	double thresh;
	int len;
	int64_t w;
	int nch;
	enum img_type type;
	bool has_nd; /* integer types: nd is a void, never part of a run */
	double nd;
	size_t row;		  /* bytes per row */
	double *dep;		  /* w: per column, how far the sample sits beyond both neighbours */
	unsigned char *orig[2];   /* the unrepaired copies of the last two rows repaired */
};

/* Sets s up for rows of w pixels of nch channels of type t (thresh > 0, len ≥ 1). */
void streaks_init(struct streaks *s, double thresh, int len, int64_t w, int nch,
		  enum img_type t, bool has_nd, double nd);
void streaks_free(struct streaks *s);

/* Repairs rows first .. first + n - 1 of buf (nrows rows of s->row bytes, pixel-interleaved),
 * comparing each with its neighbours as they were read: a row without a neighbour inside buf
 * is left as it is, so a caller streaming bands passes each band with one row of context on
 * each side (the raster's first and last rows have none). Returns the samples replaced. */
int64_t streaks_repair(struct streaks *s, unsigned char *buf, int nrows, int first, int n);

#endif
