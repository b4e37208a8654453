/* vector_src — the vector node's data: every feature of a GDAL/OGR vector source (GeoJSON,
 * GeoPackage, Shapefile, FlatGeobuf, KML, …) read once, transformed to the geographic
 * coordinates of the source's own datum (lon/lat degrees), flattened into polygons, lines and
 * points, and indexed on a 1° grid so a tile only visits features near it.
 *
 * Longitudes are unwrapped along every part (consecutive vertices differ by less than 180°),
 * so a feature crossing the antimeridian has a bounding box reaching past ±180; callers test
 * it shifted by −360, 0 and +360. A polygon ring going once around a pole (its unwrapped
 * longitudes gain ±360°) is closed through the pole on the side of its mean latitude. Outer
 * rings are stored counter-clockwise in (lon, lat), holes clockwise.
 *
 * Threads: built once, read-only afterwards (any thread). Errors fill err (256 bytes).
 */
#ifndef CLIPMAP_VECTOR_SRC_H
#define CLIPMAP_VECTOR_SRC_H
#include <stddef.h>
#include <stdint.h>

enum vec_kind { VEC_NONE = 0, VEC_POLYGON, VEC_LINE, VEC_POINT };

#define VEC_CHUNK 64 /* vertices per chunk (a part's chunks share their end vertices) */

struct vec_part {
	uint32_t first, n; /* vertices xy[first .. first + n); a ring repeats its first vertex */
	uint32_t chunk0;   /* its chunks: chunks[chunk0 ..], ceil((n - 1) / VEC_CHUNK) of them */
};

struct vec_feature {
	uint8_t kind;	   /* enum vec_kind */
	uint16_t style;	   /* 0: the default style; i ≥ 1: styles[i - 1] matched */
	uint32_t part0, nparts;
	double bbox[4];	   /* W, S, E, N of its vertices (unwrapped: W may be < -180, E > 180) */
	double gbox[4];	   /* bbox grown by vec_source_index */
};

struct vec_source {
	double *xy; /* lon, lat pairs */
	size_t npts;
	struct vec_part *parts;
	size_t nparts;
	double (*chunks)[4]; /* W, S, E, N per chunk */
	size_t nchunks;
	struct vec_feature *feats;
	size_t nfeats;
	/* The index: 360 × 180 one-degree cells, CSR (cell c lists ids[start[c] .. start[c+1]));
	 * features whose (expanded) box covers more than VEC_BIG_CELLS cells are in big[]. */
	uint32_t *start, *ids;
	uint32_t *big;
	size_t nbig;
};

#define VEC_BIG_CELLS 4096

/* What to read: the layer (NULL: every layer), the attribute that picks a style (NULL: none)
 * and the values it is matched against (nvalues strings, borrowed). */
struct vec_load_opts {
	const char *layer;
	const char *field;
	const char *const *values;
	int nvalues;
};

/* Reads the source at path. Returns 0 with *out owned by the caller (vec_source_destroy), or
 * -EINVAL / -EIO with err naming the file and what is wrong (cannot open, no such layer, no
 * coordinate system, a coordinate that does not transform, no such field). */
int vec_source_load(const char *path, const struct vec_load_opts *o, struct vec_source **out,
		    char err[256]);
/* Builds (or rebuilds) the index from each feature's gbox (bbox after load; the caller may
 * grow it first, e.g. by a line's half-width). */
void vec_source_index(struct vec_source *s);
void vec_source_destroy(struct vec_source *s);

/* The ids of features whose box may intersect [w, e] × [s, n] (degrees, -180 ≤ w < e ≤ 180),
 * each once, into ids (room for s->nfeats); seen is scratch of s->nfeats bytes, zero on entry
 * and on return. Returns the count. */
size_t vec_source_query(const struct vec_source *s, double w, double so, double e, double n,
			uint32_t *ids, uint8_t *seen);

#endif
