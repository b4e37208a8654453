/* args — see args.h. strtol/strtod with full-string, range and errno checks; one message
 * shape for every option: "OPT: expected WHAT, got \"S\"". */
#include "args.h"

#include <errno.h>
#include <math.h>
#include <stdbool.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "errbuf.h"

/* A number at s up to the first character of delims (or the end); *end past it. strtod
 * accepts leading blanks, "inf" and "nan": refused here. */
static int num(const char *s, const char *delims, double *v, const char **end)
{
	if (!s || !*s || strchr(" \t\n", *s))
		return -1;
	char *e;
	errno = 0;
	*v = strtod(s, &e);
	if (e == s || errno || !isfinite(*v) || (*e && !strchr(delims, *e)))
		return -1;
	*end = e;
	return 0;
}

int args_long(const char *opt, const char *s, long lo, long hi, long *out, char err[256])
{
	char *end;
	errno = 0;
	long v = 0;
	bool ok = s && *s && ((*s >= '0' && *s <= '9') || *s == '-' || *s == '+');
	if (ok) {
		v = strtol(s, &end, 10);
		ok = *end == '\0' && !errno && v >= lo && v <= hi;
	}
	if (!ok)
		return err_inval(err, "%s: expected an integer in [%ld, %ld], got \"%s\"", opt, lo, hi,
			   s ? s : "");
	*out = v;
	return 0;
}

int args_int(const char *opt, const char *s, int lo, int hi, int *out, char err[256])
{
	long v;
	int rc = args_long(opt, s, lo, hi, &v, err);
	if (rc == 0)
		*out = (int)v;
	return rc;
}

int args_double(const char *opt, const char *s, double lo, double hi, double *out,
		char err[256])
{
	double v;
	const char *end;
	if (num(s, "", &v, &end) || *end || !(v >= lo && v <= hi))
		return err_inval(err, "%s: expected a number in [%g, %g], got \"%s\"", opt, lo, hi,
			   s ? s : "");
	*out = v;
	return 0;
}

int args_doubles(const char *opt, const char *s, int n, const double *lo, const double *hi,
		 const char *what, double *out, char err[256])
{
	double v[16];
	const char *p = s;
	if (n < 1 || n > 16)
		return err_inval(err, "%s: bad parser call", opt);
	for (int i = 0; i < n; i++) {
		const char *end;
		if (num(p, i + 1 < n ? "," : "", &v[i], &end) || (i + 1 < n && *end != ',') ||
		    (i + 1 == n && *end))
			return err_inval(err, "%s: expected %s (%d numbers separated by commas), got \"%s\"",
				   opt, what, n, s ? s : "");
		if (!(v[i] >= lo[i] && v[i] <= hi[i]))
			return err_inval(err, "%s: \"%s\": value %d of %s must be in [%g, %g]", opt, s,
				   i + 1, what, lo[i], hi[i]);
		p = end + (i + 1 < n);
	}
	memcpy(out, v, (size_t)n * sizeof *v);
	return 0;
}

int args_latlon(const char *opt, const char *s, double *lat, double *lon, char err[256])
{
	static const double lo[2] = { -90, -180 }, hi[2] = { 90, 180 };
	double v[2];
	int rc = args_doubles(opt, s, 2, lo, hi, "LAT,LON in degrees", v, err);
	if (rc == 0) {
		*lat = v[0];
		*lon = v[1];
	}
	return rc;
}

int args_bbox(const char *opt, const char *s, double wsen[4], char err[256])
{
	static const double lo[4] = { -180, -90, -180, -90 }, hi[4] = { 180, 90, 360, 90 };
	double v[4];
	int rc = args_doubles(opt, s, 4, lo, hi, "W,S,E,N in degrees", v, err);
	if (rc)
		return rc;
	if (v[1] >= v[3])
		return err_inval(err, "%s: \"%s\": south must be less than north", opt, s);
	if (v[0] >= v[2])
		return err_inval(err, "%s: \"%s\": west must be less than east (to cross the antimeridian "
			   "write east + 360, e.g. 170,-10,190,10)", opt, s);
	if (v[2] > 180 && v[2] - v[0] > 360)
		return err_inval(err, "%s: \"%s\": a box across the antimeridian spans at most 360 "
			   "degrees", opt, s);
	memcpy(wsen, v, sizeof v);
	return 0;
}

int args_size(const char *opt, const char *s, int lo, int hi, int *w, int *h, char err[256])
{
	const char *x = s ? strchr(s, 'x') : NULL;
	char a[16];
	long vw, vh;
	if (x && (size_t)(x - s) < sizeof a) {
		memcpy(a, s, (size_t)(x - s));
		a[x - s] = '\0';
		if (args_long(opt, a, lo, hi, &vw, NULL) == 0 &&
		    args_long(opt, x + 1, lo, hi, &vh, NULL) == 0) {
			*w = (int)vw;
			*h = (int)vh;
			return 0;
		}
	}
	return err_inval(err, "%s: expected WxH with each in [%d, %d], got \"%s\"", opt, lo, hi,
		   s ? s : "");
}
