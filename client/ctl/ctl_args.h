/* ctl_args — clipmapctl's argument parsers (levels, boxes, paths, places, layer lists) and
 * small text formatters (byte sizes, durations, the prefetch progress line). Pure functions
 * over their arguments: thread-safe, no I/O. Parsers return 0 or -EINVAL with err[256] saying
 * what was expected and what was given.
 */
#ifndef CLIPMAP_CTL_ARGS_H
#define CLIPMAP_CTL_ARGS_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/grid.h"
#include "common/proto.h"

/* An unsigned decimal in [0, max]. */
int ctl_parse_uint(const char *s, const char *what, uint64_t max, uint64_t *out, char err[256]);
/* "A-B" or "A": a ly range, 0 ≤ A ≤ B ≤ max_level. */
int ctl_parse_levels(const char *s, int max_level, uint8_t *lmin, uint8_t *lmax, char err[256]);
/* "W,S,E,N" in degrees (args_bbox): W < E, -90 ≤ S < N ≤ 90; a box across the antimeridian
 * is written with E > 180 (170,-10,190,10) and returned with E - 360 (then W > E, as the
 * protocol has it). West > east as written is refused. */
int ctl_parse_bbox(const char *s, struct geo_rect *r, char err[256]);
/* "LAT,LON" in degrees (-90..90, -180..180). */
int ctl_parse_latlon(const char *s, double *lat, double *lon, char err[256]);
/* "LAT,LON:LAT,LON[:…]" (2 … PROTO_MAX_PATH points). *pts is returned owned (free()). */
int ctl_parse_path(const char *s, struct proto_lonlat **pts, uint32_t *n, char err[256]);
/* A distance in kilometres from 0 to max_km ("12", "0.5"), returned in metres. */
int ctl_parse_km(const char *s, const char *what, double max_km, double *metres,
		 char err[256]);
/* "a,b": layer names of planet p → bit mask of their indices. NULL or "" → 0 (every layer). */
int ctl_parse_layers(const char *s, const struct proto_planet *p, uint64_t *mask, char err[256]);
/* Index of the layer named s in p, or -ENOENT with err listing the planet's layers. */
int ctl_find_layer(const struct proto_planet *p, const char *s, char err[256]);

/* "812.4 MiB", "17 B". */
void ctl_fmt_bytes(uint64_t b, char *out, size_t n);
/* "1h02m03s", "4m05s", "12.3s"; negative or non-finite: "?". */
void ctl_fmt_duration(double s, char *out, size_t n);

/* The prefetch progress line: with bar_width > 0 a bar "[#####     ]" first, then
 * "done/total tiles  P%  R tiles/s  ETA D" (ETA "?" while the rate is 0; "0s" when done). */
void ctl_fmt_progress(char *out, size_t n, uint64_t done, uint64_t total, double rate,
		      int bar_width);

#endif
