/* args — strict parsing of command-line option values for the three programs: the whole
 * string must be the value (no "12x", no "", no leading blanks), numbers must lie in the
 * range given, and every error message names the option ("--steps: expected an integer in
 * [1, 100000], got \"abc\""), so main can print it and exit 2. Pure functions over their
 * arguments: thread-safe, no I/O, no allocation. Each returns 0 or -EINVAL with err[256]
 * (optional) filled; on failure the outputs are left untouched.
 */
#ifndef CLIPMAP_ARGS_H
#define CLIPMAP_ARGS_H

/* A decimal integer in [lo, hi]. */
int args_long(const char *opt, const char *s, long lo, long hi, long *out, char err[256]);
/* args_long into an int (lo and hi within int's range). */
int args_int(const char *opt, const char *s, int lo, int hi, int *out, char err[256]);
/* A finite decimal number in [lo, hi]. */
int args_double(const char *opt, const char *s, double lo, double hi, double *out,
		char err[256]);
/* n finite numbers separated by commas ("1,2.5,-3"), each in [lo[i], hi[i]]; what says what
 * they are, for the message (e.g. "AZ,EL"). */
int args_doubles(const char *opt, const char *s, int n, const double *lo, const double *hi,
		 const char *what, double *out, char err[256]);
/* "LAT,LON" in degrees: latitude in [-90, 90], longitude in [-180, 180]. */
int args_latlon(const char *opt, const char *s, double *lat, double *lon, char err[256]);
/* "W,S,E,N" in degrees into wsen[4]: -90 <= S < N <= 90, -180 <= W < E <= 180 — or, for a
 * box across the antimeridian, W < E with 180 < E <= W + 360 (e.g. "170,-10,190,10"); such an
 * east is returned as written (callers that want [-180, 180] subtract 360, which then makes
 * west > east). West > east as written is refused: it would silently mean the band round the
 * other side of the planet. */
int args_bbox(const char *opt, const char *s, double wsen[4], char err[256]);
/* "WxH", both integers in [lo, hi]. */
int args_size(const char *opt, const char *s, int lo, int hi, int *w, int *h, char err[256]);

#endif
