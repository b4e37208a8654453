/* metrics — the daemon's STATS figures in the Prometheus text exposition format (version
 * 0.0.4), for the HTTP endpoint's /metrics. Names: "clipmapd_" + the dotted key with dots as
 * underscores; counters (keys ending in a count of events: hits, misses, generated, sent, …)
 * get TYPE counter and the "_total" suffix; times in ms or s become seconds; per-node keys
 * ("node.PLANET.NODE.what") become one metric with planet and node labels.
 */
#ifndef CLIPMAP_METRICS_H
#define CLIPMAP_METRICS_H
#include <stddef.h>

#include "common/proto.h"

/* Formats n items into a malloc'ed, NUL-terminated text (*len bytes without the NUL). version:
 * the build's version string for clipmapd_build_info. */
char *metrics_format(const struct proto_stat *items, size_t n, const char *version, size_t *len);

#endif
