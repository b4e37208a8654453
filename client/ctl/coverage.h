/* coverage — `clipmapctl prefetch --coverage FILE` and `cache purge --coverage FILE`: the
 * polygons of a vector file (GeoJSON, GeoPackage, Shapefile: anything GDAL/OGR reads) as the
 * rings of a prefetch polygon (common/lonpoly.h, docs/PROTOCOL.md PREFETCH shape 3), like
 * mapproxy-seed's coverages.
 *
 * Every polygon and multipolygon of every layer is taken (holes included); other geometries
 * are skipped, and a file with no polygon is an error. A layer in another CRS is densified
 * (edges cut into pieces of 1/64 of its extent, so straight projected edges stay close to
 * themselves) and transformed to EPSG:4326 (lon, lat); a layer without a CRS is taken as
 * lon/lat. Each ring's longitudes are unwrapped (a ring crossing the antimeridian continues
 * past ±180), a ring that goes once round a pole (as a polar stereographic polygon around it
 * becomes in lon/lat) is closed through that pole, and holes are moved by 360° next to their
 * outer ring.
 *
 * Reentrant (GDAL registers its drivers once). Only clipmapctl-offline links it: the thin
 * clipmapctl hands --coverage commands to it.
 */
#ifndef CLIPMAP_COVERAGE_H
#define CLIPMAP_COVERAGE_H
#include <stdint.h>

#include "common/proto.h"

struct coverage {
	uint32_t nrings, npoints;
	uint32_t *rings;	   /* points per ring, owned */
	struct proto_lonlat *pts;  /* owned */
	uint32_t skipped;	   /* features that were not polygons */
};

/* Reads path into cv. Returns 0, or -errno with err naming the file and what is wrong (cannot
 * be opened, no polygon, more rings or points than the protocol carries, a CRS that cannot be
 * transformed). */
int coverage_read(const char *path, struct coverage *cv, char err[256]);
void coverage_free(struct coverage *cv);

#endif
