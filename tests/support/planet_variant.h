/* planet_variant — two copies of a shipped planet file for the build-from-parent test and
 * bench: one with `from_parent = true` on every fBm noise node, one with none (the direct
 * evaluation), whatever the shipped file sets. Relative `path =` lines (data files beside the
 * planet, such as the site's GeoJSON) are written by their full path, since the copies live
 * in /tmp. Test-only. */
#ifndef CLIPMAP_TEST_PLANET_VARIANT_H
#define CLIPMAP_TEST_PLANET_VARIANT_H

#include <stddef.h>

/* Writes /tmp/TAG_PID.ini (from_parent) and /tmp/TAG_dPID.ini (direct) from the planet file
 * at src; their paths into fp and direct (size bytes each). Returns 0, or -1 when a file
 * cannot be read or written or src has no fBm node. */
int planet_variant_write(const char *src, const char *tag, char *fp, char *direct, size_t size);

#endif
