/* ctl_args — see ctl_args.h. Numbers go through strtod/strtoull with full-string checks, so
 * "12x" or "" is an error rather than 12 or 0. */
#include "ctl_args.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/args.h"
#include "common/errbuf.h"
#include "common/xalloc.h"

/* Parses a double from *p up to a delimiter in delims (or the end); advances *p past it. */
static int num(const char **p, const char *delims, double *v)
{
	char *end;
	errno = 0;
	if (**p == '\0' || strchr(" \t", **p))
		return -1;
	*v = strtod(*p, &end);
	if (end == *p || errno || !isfinite(*v))
		return -1;
	if (*end && !strchr(delims, *end))
		return -1;
	*p = end;
	return 0;
}

int ctl_parse_uint(const char *s, const char *what, uint64_t max, uint64_t *out, char err[256])
{
	char *end;
	errno = 0;
	if (!s || *s < '0' || *s > '9')
		return err_inval(err, "%s must be an integer in [0, %llu], got \"%s\"", what,
			   (unsigned long long)max, s ? s : "");
	unsigned long long v = strtoull(s, &end, 10);
	if (*end || errno || v > max)
		return err_inval(err, "%s must be an integer in [0, %llu], got \"%s\"", what,
			   (unsigned long long)max, s);
	*out = v;
	return 0;
}

int ctl_parse_levels(const char *s, int max_level, uint8_t *lmin, uint8_t *lmax, char err[256])
{
	const char *dash = strchr(s, '-');
	char a[16], b[16];
	size_t la = dash ? (size_t)(dash - s) : strlen(s);
	if (la == 0 || la >= sizeof a || (dash && (!dash[1] || strlen(dash + 1) >= sizeof b)))
		return err_inval(err, "--levels wants A-B (0 <= A <= B <= %d), got \"%s\"", max_level, s);
	memcpy(a, s, la);
	a[la] = '\0';
	snprintf(b, sizeof b, "%s", dash ? dash + 1 : a);
	uint64_t va, vb;
	char e2[256];
	if (ctl_parse_uint(a, "level", (uint64_t)max_level, &va, e2) ||
	    ctl_parse_uint(b, "level", (uint64_t)max_level, &vb, e2))
		return err_inval(err, "--levels wants A-B (0 <= A <= B <= %d), got \"%s\"", max_level, s);
	if (va > vb)
		return err_inval(err, "--levels %s: the first level must not exceed the second", s);
	*lmin = (uint8_t)va;
	*lmax = (uint8_t)vb;
	return 0;
}

int ctl_parse_bbox(const char *s, struct geo_rect *r, char err[256])
{
	double v[4];
	int rc = args_bbox("--bbox", s, v, err);
	if (rc)
		return rc;
	/* the protocol's form: east in [-180, 180], west > east across the antimeridian */
	*r = (struct geo_rect){ .west = v[0], .south = v[1], .east = v[2] > 180 ? v[2] - 360 : v[2],
				.north = v[3] };
	return 0;
}

static int latlon(const char **p, const char *end_delims, double *lat, double *lon)
{
	if (num(p, ",", lat) || **p != ',')
		return -1;
	(*p)++;
	if (num(p, end_delims, lon))
		return -1;
	if (*lat < -90 || *lat > 90 || *lon < -180 || *lon > 180)
		return -2;
	return 0;
}

int ctl_parse_latlon(const char *s, double *lat, double *lon, char err[256])
{
	const char *p = s;
	int rc = latlon(&p, "", lat, lon);
	if (rc == -1 || *p)
		return err_inval(err, "want LAT,LON in degrees, got \"%s\"", s);
	if (rc)
		return err_inval(err, "%s: latitude must be in [-90, 90] and longitude in [-180, 180]", s);
	return 0;
}

int ctl_parse_path(const char *s, struct proto_lonlat **pts, uint32_t *n, char err[256])
{
	*pts = NULL;
	*n = 0;
	size_t cap = 1;
	for (const char *q = s; *q; q++)
		cap += *q == ':';
	if (cap < 2)
		return err_inval(err, "--path wants LAT,LON:LAT,LON (two or more places), got \"%s\"", s);
	if (cap > PROTO_MAX_PATH)
		return err_inval(err, "--path has %zu places; at most %d", cap, PROTO_MAX_PATH);
	struct proto_lonlat *a = xcalloc(cap, sizeof *a);
	const char *p = s;
	for (size_t i = 0; i < cap; i++) {
		double lat, lon;
		int rc = latlon(&p, ":", &lat, &lon);
		if (rc || (i + 1 < cap && *p != ':') || (i + 1 == cap && *p)) {
			free(a);
			if (rc == -2)
				return err_inval(err, "--path %s: place %zu is out of range (latitude -90..90, "
					   "longitude -180..180)", s, i + 1);
			return err_inval(err, "--path wants LAT,LON:LAT,LON (two or more places), got "
				   "\"%s\"", s);
		}
		if (*p == ':')
			p++;
		a[i] = (struct proto_lonlat){ .lon = lon, .lat = lat };
	}
	*pts = a;
	*n = (uint32_t)cap;
	return 0;
}

int ctl_parse_km(const char *s, const char *what, double max_km, double *metres,
		 char err[256])
{
	const char *p = s;
	double v;
	if (num(&p, "", &v) || *p || !(v >= 0 && v <= max_km))
		return err_inval(err, "%s wants a distance in km (0..%g), got \"%s\"", what,
				 max_km, s);
	*metres = v * 1000.0;
	return 0;
}

int ctl_find_layer(const struct proto_planet *p, const char *s, char err[256])
{
	for (uint16_t i = 0; i < p->nlayers; i++)
		if (strcmp(p->layers[i].name, s) == 0)
			return i;
	char names[160] = "";
	for (uint16_t i = 0; i < p->nlayers; i++) {
		size_t l = strlen(names);
		snprintf(names + l, sizeof names - l, "%s%s", i ? ", " : "", p->layers[i].name);
	}
	err_inval(err, "planet %s has no layer \"%s\" (layers: %s)", p->name, s, names);
	return -ENOENT;
}

int ctl_parse_layers(const char *s, const struct proto_planet *p, uint64_t *mask, char err[256])
{
	*mask = 0;
	if (!s || !*s)
		return 0;
	char *dup = xstrdup(s), *save = NULL;
	int rc = 0;
	for (char *t = strtok_r(dup, ",", &save); t; t = strtok_r(NULL, ",", &save)) {
		int i = ctl_find_layer(p, t, err);
		if (i < 0) {
			rc = -EINVAL;
			break;
		}
		*mask |= (uint64_t)1 << i;
	}
	free(dup);
	if (rc == 0 && *mask == 0)
		return err_inval(err, "--layers wants layer names separated by commas, got \"%s\"", s);
	return rc;
}

void ctl_fmt_bytes(uint64_t b, char *out, size_t n)
{
	static const char *const unit[] = { "KiB", "MiB", "GiB", "TiB", "PiB" };
	if (b < 1024) {
		snprintf(out, n, "%llu B", (unsigned long long)b);
		return;
	}
	double v = (double)b / 1024.0;
	int u = 0;
	while (v >= 1024.0 && u < 4) {
		v /= 1024.0;
		u++;
	}
	snprintf(out, n, "%.1f %s", v, unit[u]);
}

void ctl_fmt_duration(double s, char *out, size_t n)
{
	if (!isfinite(s) || s < 0) {
		snprintf(out, n, "?");
		return;
	}
	if (s < 60) {
		snprintf(out, n, s < 10 ? "%.1fs" : "%.0fs", s);
		return;
	}
	unsigned long long t = (unsigned long long)llround(s);
	unsigned long long h = t / 3600, m = t / 60 % 60, sec = t % 60;
	if (h >= 24)
		snprintf(out, n, "%llud%02lluh%02llum", h / 24, h % 24, m);
	else if (h)
		snprintf(out, n, "%lluh%02llum%02llus", h, m, sec);
	else
		snprintf(out, n, "%llum%02llus", m, sec);
}

void ctl_fmt_progress(char *out, size_t n, uint64_t done, uint64_t total, double rate,
		      int bar_width)
{
	double frac = total ? (double)done / (double)total : (done ? 1.0 : 0.0);
	if (frac > 1)
		frac = 1;
	char bar[130] = "";
	if (bar_width > 0) {
		if (bar_width > 120)
			bar_width = 120;
		int fill = (int)(frac * bar_width);
		bar[0] = '[';
		for (int i = 0; i < bar_width; i++)
			bar[1 + i] = i < fill ? '#' : ' ';
		bar[1 + bar_width] = ']';
		bar[2 + bar_width] = ' ';
		bar[3 + bar_width] = '\0';
	}
	char eta[32];
	if (total && done >= total)
		snprintf(eta, sizeof eta, "0s");
	else if (!(rate > 0) || !isfinite(rate))
		snprintf(eta, sizeof eta, "?");
	else
		ctl_fmt_duration((double)(total - done) / rate, eta, sizeof eta);
	snprintf(out, n, "%s%llu/%llu tiles  %3.0f%%  %.1f tiles/s  ETA %s", bar,
		 (unsigned long long)done, (unsigned long long)total, frac * 100.0,
		 isfinite(rate) && rate > 0 ? rate : 0.0, eta);
}
