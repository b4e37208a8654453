/* clipmapview — the viewer. Offline mode renders pictures of a planet evaluated in this
 * process (--planet FILE) or served by clipmapd (--connect SOCKET|HOST:PORT --planet NAME):
 * one camera (--camera) or a flight (--flight CSV), EGL surfaceless or OSMesa, no display
 * needed. Window mode (--window) flies the same views interactively in a GLFW window at up to
 * 60 frames/s, never waiting for tiles. Exit status: 0 ok, 1 runtime failure, 2 bad usage,
 * 3 when a --wait-complete picture was not complete within --timeout (written anyway).
 */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "client/planet_path.h"
#include "common/args.h"
#include "common/clock.h"
#include "common/errbuf.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "gl_context.h"
#include "gl_window.h"
#include "view.h"
#include "view_fly.h"
#include "view_source_local.h"
#include "view_source_net.h"

static void usage(FILE *f)
{
	fprintf(f,
		"usage: clipmapview --planet FILE|NAME [options]         (in-process engine)\n"
		"       clipmapview --connect SOCKET|HOST:PORT --planet NAME [--token-file F] [options]\n"
		"  --connect TARGET    clipmapd's Unix socket path, or HOST:PORT (TCP)\n"
		"  --token-file F      the daemon's shared secret (default: $CLIPMAP_TOKEN)\n"
		"  --tls-ca FILE       HOST:PORT over TLS, the daemon's certificate checked against\n"
		"                      this CA (PEM) and the HOST (default: $CLIPMAP_TLS_CA)\n"
		"  --tls               TLS with the system's trust store (without --tls-ca)\n"
		"  --lossless          refuse the lossy tile codecs (webp, q16) the daemon uses on\n"
		"                      slow links: exact texels, more bytes\n"
		"  --connect-wait S    at the start, keep trying to reach the daemon for up to S\n"
		"                      seconds (default 0: fail at once); a connection lost later\n"
		"                      is always retried (backoff 0.1 s doubling to 5 s)\n"
		"  --camera LAT,LON,ALT,HEADING,PITCH  degrees; ALT metres above the ground (the\n"
		"                      water where the planet's sea covers it)\n"
		"  --flight FILE       CSV of camera keys (lat,lon,alt,heading,pitch per line)\n"
		"  --steps N           frames from one key to the next (default 1)\n"
		"  -o PATH             PNG to write, required without --window (a flight: a pattern\n"
		"                      with one frame number, e.g. f/%%05d.png; its directory must exist)\n"
		"  --size WxH          framebuffer (default 1280x720)\n"
		"  --wait-complete     wait for every wanted level before writing a picture\n"
		"  --timeout S         give up waiting after S seconds (default 300): the picture\n"
		"                      is written as it is and the exit status is 3\n"
		"  --fps N             without --wait-complete: frames paced at N per second in real\n"
		"                      time, tiles taken between them (default 30; 0: unpaced)\n"
		"  --budget MS         real time (window, paced flights): a frame stops refining once\n"
		"                      its texture uploads have taken MS ms (default 12; 0: never)\n"
		"  --stats FILE        one JSON line per frame\n"
		"  --fov DEG           vertical field of view (default 60)\n"
		"  --sun AZ,EL         sun azimuth (clockwise from north) and elevation at the\n"
		"                      camera (default 315,35: a north-up view lit from its upper\n"
		"                      left)\n"
		"  --exaggerate X      vertical exaggeration of the relief (default 1)\n"
		"  --haze X            atmosphere density, 1 Earth's, 0 none (default: the\n"
		"                      planet's atmosphere, from its file)\n"
		"  --rings N,M         N steps around, M rings per level (default 256,16)\n"
		"  --color-layer NAME  the colour layer drawn (default: \"color\"; earth: annotated\n"
		"                      for coast, borders and rivers)\n"
		"  --normals auto|fetch|derive  shading's normals: the planet's normal layer\n"
		"                      (fetch), or made here from the heights (derive: never\n"
		"                      asks for them, ~1/3 fewer bytes, same picture); auto\n"
		"                      (default): derive where the planet says that is the same\n"
		"  --switch-layer-at FRAME:NAME  switch to colour layer NAME before frame FRAME\n"
		"                      (0-based; repeatable): scripted L presses\n"
		"  --backend egl|osmesa, --workers N, --no-prefetch\n"
		"  --store FILE        (in-process) read tiles from and write the generated ones to\n"
		"                      an LMDB tile store, possibly the one a running clipmapd uses;\n"
		"                      prints what it did on exit. --store-mb N: its budget (1024)\n"
		"  --window            fly interactively in a window (--camera optional):\n"
		"                      left drag orbit, right drag look, wheel zoom, WASD/arrows move,\n"
		"                      E/PageUp climb, Q/PageDown descend, Shift faster, R reset,\n"
		"                      L next colour layer, Esc quit\n"
		"  --exit-after N      (window) close after N frames\n"
		"  --screenshot FILE   (window) write the last frame as PNG on exit\n"
		"  -V, --version       the version\n"
		"exit status: 0 ok, 1 failure, 2 bad usage, 3 incomplete after --timeout\n");
}

/* --switch-layer-at FRAME:NAME: the colour layer NAME from frame FRAME on. */
#define MAX_SWITCHES 16
struct layer_switch {
	long frame;
	const char *name; /* borrowed from argv */
};

/* What the command line asks for (parse_args). */
struct args {
	const char *planet, *connect_to, *token_file, *tls_ca;
	bool tls, lossless;
	double connect_wait; /* --connect-wait, seconds */
	const char *camera, *flight; /* one of them, or neither with --window */
	const char *outp;	     /* -o: a path, or for a flight a frame-number pattern */
	const char *statsp, *screenshot;
	const char *store; /* --store FILE (in-process), --store-mb */
	uint32_t store_mb;
	int width, height, steps, workers;
	bool wait_complete, window;
	long exit_after;
	double timeout, fov, fps, budget;
	struct view_desc d; /* --sun, --rings, --exaggerate, --haze, --no-prefetch */
	enum gl_backend backend;
	struct layer_switch sw[MAX_SWITCHES]; /* --switch-layer-at, in command-line order */
	int nsw;
};

/* Prints an argument error (err from common/args) and returns false. */
static bool complain(const char *err)
{
	fprintf(stderr, "clipmapview: %s\n", err);
	return false;
}

/* ---- -o for a flight: one frame-number conversion ------------------------------------- */

/* The length of the printf conversion at p (p[0] == '%') when it is one an int frame number
 * may fill: up to 4 flags, a width and a precision of up to 3 digits, then d or i ("%d",
 * "%04d"; at most 13 characters); 0 for any other. */
static size_t frame_conversion(const char *p)
{
	size_t flags = strspn(p + 1, "-+ 0");
	if (flags > 4)
		return 0;
	size_t i = 1 + flags;
	size_t digits = strspn(p + i, "0123456789");
	if (digits > 3)
		return 0; /* a width that long makes no file name */
	i += digits;
	if (p[i] == '.') {
		digits = strspn(p + i + 1, "0123456789");
		if (digits > 3)
			return 0;
		i += 1 + digits;
	}
	return p[i] == 'd' || p[i] == 'i' ? i + 1 : 0;
}

/* Whether pat takes a frame number safely: at most one frame_conversion, any other '%'
 * only as "%%". */
static bool frame_pattern_ok(const char *pat)
{
	int conversions = 0;
	for (const char *p = pat; (p = strchr(p, '%'));) {
		if (p[1] == '%') {
			p += 2;
			continue;
		}
		size_t n = frame_conversion(p);
		if (!n || ++conversions > 1)
			return false;
		p += n;
	}
	return true;
}

/* pat (checked by frame_pattern_ok) with frame f in it, into out[n]. Returns false when the
 * path does not fit. */
static bool frame_path(const char *pat, int f, char *out, size_t n)
{
	size_t len = 0;
	for (const char *p = pat; *p && len < n;) {
		if (*p != '%') {
			out[len++] = *p++;
		} else if (p[1] == '%') {
			out[len++] = '%';
			p += 2;
		} else {
			char spec[16];
			size_t sl = frame_conversion(p);
			memcpy(spec, p, sl);
			spec[sl] = '\0';
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wformat-nonliteral"
			/* spec is one int conversion, checked by frame_conversion */
			int w = snprintf(out + len, n - len, spec, f);
#pragma GCC diagnostic pop
			len += w > 0 ? (size_t)w : 0;
			p += sl;
		}
	}
	if (len >= n)
		return false;
	out[len] = '\0';
	return true;
}

/* ---- arguments ------------------------------------------------------------------------ */

static bool parse_sun(const char *opt, const char *s, struct view_desc *d)
{
	static const double lo[2] = { -360, -90 }, hi[2] = { 360, 90 };
	double v[2];
	char err[256];
	if (args_doubles(opt, s, 2, lo, hi, "AZ,EL in degrees", v, err))
		return complain(err);
	d->sun_az = (float)v[0];
	d->sun_el = (float)v[1];
	return true;
}

static bool parse_rings(const char *opt, const char *s, struct view_desc *d)
{
	static const double lo[2] = { 8, 1 }, hi[2] = { 4096, 64 };
	double v[2];
	char err[256];
	if (args_doubles(opt, s, 2, lo, hi, "N,M (steps around, rings per level)", v, err))
		return complain(err);
	if (v[0] != floor(v[0]) || v[1] != floor(v[1])) {
		snprintf(err, sizeof err, "%s: \"%s\": N and M are whole numbers", opt, s);
		return complain(err);
	}
	d->n_phi = (int)v[0];
	d->m_rings = (int)v[1];
	return true;
}

static bool parse_backend(const char *s, enum gl_backend *b)
{
	if (!strcmp(s, "egl"))
		*b = GL_BACKEND_EGL;
	else if (!strcmp(s, "osmesa"))
		*b = GL_BACKEND_OSMESA;
	else {
		fprintf(stderr, "clipmapview: --backend: expected egl or osmesa, got \"%s\"\n", s);
		return false;
	}
	return true;
}

/* "FRAME:NAME" into a->sw (the name is checked against the planet once it is open). */
static bool parse_switch(const char *s, struct args *a)
{
	char err[256], num[32];
	const char *colon = strchr(s, ':');
	if (!colon || colon == s || !colon[1] || (size_t)(colon - s) >= sizeof num) {
		snprintf(err, sizeof err, "--switch-layer-at: \"%s\": expected FRAME:NAME (a frame "
			 "number, a colour layer's name)", s);
		return complain(err);
	}
	if (a->nsw == MAX_SWITCHES) {
		snprintf(err, sizeof err, "--switch-layer-at: at most %d", MAX_SWITCHES);
		return complain(err);
	}
	snprintf(num, sizeof num, "%.*s", (int)(colon - s), s);
	struct layer_switch *w = &a->sw[a->nsw];
	if (args_long("--switch-layer-at", num, 0, 1L << 40, &w->frame, err))
		return complain(err);
	w->name = colon + 1;
	a->nsw++;
	return true;
}

enum {
	O_PLANET = 256, O_CAMERA, O_FLIGHT, O_STEPS, O_SIZE, O_WAIT, O_TIMEOUT, O_STATS, O_FOV,
	O_SUN, O_RINGS, O_BACKEND, O_WORKERS, O_NOPF, O_HELP, O_CONNECT, O_TOKEN, O_EXAG, O_HAZE,
	O_WINDOW, O_EXIT_AFTER, O_SCREENSHOT, O_FPS, O_BUDGET, O_VERSION, O_TLS_CA, O_TLS, O_LOSSLESS,
	O_CLAYER,
	O_CONNECT_WAIT, O_SWITCH_LAYER, O_STORE, O_STORE_MB, O_NORMALS
};

static const struct option long_opts[] = {
	{ "planet", required_argument, NULL, O_PLANET },
	{ "camera", required_argument, NULL, O_CAMERA },
	{ "flight", required_argument, NULL, O_FLIGHT },
	{ "steps", required_argument, NULL, O_STEPS },
	{ "size", required_argument, NULL, O_SIZE },
	{ "wait-complete", no_argument, NULL, O_WAIT },
	{ "timeout", required_argument, NULL, O_TIMEOUT },
	{ "fps", required_argument, NULL, O_FPS },
	{ "budget", required_argument, NULL, O_BUDGET },
	{ "stats", required_argument, NULL, O_STATS },
	{ "fov", required_argument, NULL, O_FOV },
	{ "sun", required_argument, NULL, O_SUN },
	{ "rings", required_argument, NULL, O_RINGS },
	{ "backend", required_argument, NULL, O_BACKEND },
	{ "workers", required_argument, NULL, O_WORKERS },
	{ "no-prefetch", no_argument, NULL, O_NOPF },
	{ "help", no_argument, NULL, O_HELP },
	{ "version", no_argument, NULL, O_VERSION },
	{ "connect", required_argument, NULL, O_CONNECT },
	{ "token-file", required_argument, NULL, O_TOKEN },
	{ "tls-ca", required_argument, NULL, O_TLS_CA },
	{ "tls", no_argument, NULL, O_TLS },
	{ "lossless", no_argument, NULL, O_LOSSLESS },
	{ "connect-wait", required_argument, NULL, O_CONNECT_WAIT },
	{ "exaggerate", required_argument, NULL, O_EXAG },
	{ "haze", required_argument, NULL, O_HAZE },
	{ "color-layer", required_argument, NULL, O_CLAYER },
	{ "switch-layer-at", required_argument, NULL, O_SWITCH_LAYER },
	{ "window", no_argument, NULL, O_WINDOW },
	{ "exit-after", required_argument, NULL, O_EXIT_AFTER },
	{ "screenshot", required_argument, NULL, O_SCREENSHOT },
	{ "store", required_argument, NULL, O_STORE },
	{ "store-mb", required_argument, NULL, O_STORE_MB },
	{ "normals", required_argument, NULL, O_NORMALS },
	{ NULL, 0, NULL, 0 },
};

/* Takes option c (getopt_long's answer) with its argument s into a. Returns false on a bad
 * value (after saying so, naming the option). */
static bool take_option(int c, const char *s, struct args *a)
{
	char err[256];
	double v;
	int rc = 0;
	switch (c) {
	case O_PLANET: a->planet = s; return true;
	case O_CONNECT: a->connect_to = s; return true;
	case O_TOKEN: a->token_file = s; return true;
	case O_TLS_CA: a->tls_ca = s; return true;
	case O_TLS: a->tls = true; return true;
	case O_LOSSLESS: a->lossless = true; return true;
	case O_CONNECT_WAIT:
		rc = args_double("--connect-wait", s, 0, 86400, &a->connect_wait, err);
		break;
	case O_EXAG:
		if ((rc = args_double("--exaggerate", s, 0.1, 100, &v, err)) == 0)
			a->d.exaggeration = (float)v;
		break;
	case O_CLAYER: a->d.color_layer = s; return true;
	case O_SWITCH_LAYER: return parse_switch(s, a);
	case O_HAZE:
		if ((rc = args_double("--haze", s, 0, 100, &v, err)) == 0)
			a->d.haze = v > 0 ? (float)v : -1;
		break;
	case O_WINDOW: a->window = true; return true;
	case O_EXIT_AFTER: rc = args_long("--exit-after", s, 1, 1L << 40, &a->exit_after, err); break;
	case O_SCREENSHOT: a->screenshot = s; return true;
	case O_CAMERA: a->camera = s; return true;
	case O_FLIGHT: a->flight = s; return true;
	case O_STEPS: rc = args_int("--steps", s, 1, 100000, &a->steps, err); break;
	case 'o': a->outp = s; return true;
	case O_SIZE: rc = args_size("--size", s, 16, 16384, &a->width, &a->height, err); break;
	case O_WAIT: a->wait_complete = true; return true;
	case O_TIMEOUT: rc = args_double("--timeout", s, 0.001, 86400 * 7, &a->timeout, err); break;
	case O_BUDGET: rc = args_double("--budget", s, 0, 10000, &a->budget, err); break;
	case O_FPS: rc = args_double("--fps", s, 0, 1000, &a->fps, err); break;
	case O_STATS: a->statsp = s; return true;
	case O_FOV: rc = args_double("--fov", s, 1, 170, &a->fov, err); break;
	case O_SUN: return parse_sun("--sun", s, &a->d);
	case O_RINGS: return parse_rings("--rings", s, &a->d);
	case O_BACKEND: return parse_backend(s, &a->backend);
	case O_NORMALS:
		if (!strcmp(s, "auto") || !strcmp(s, "fetch") || !strcmp(s, "derive")) {
			a->d.normals = s[0] == 'a'   ? VIEW_NORMALS_AUTO
				       : s[0] == 'f' ? VIEW_NORMALS_FETCH
						     : VIEW_NORMALS_DERIVE;
			return true;
		}
		fprintf(stderr, "clipmapview: --normals: expected auto, fetch or derive, got \"%s\"\n",
			s);
		return false;
	case O_WORKERS: rc = args_int("--workers", s, 0, 1024, &a->workers, err); break;
	case O_NOPF: a->d.no_prefetch = true; return true;
	case O_STORE: a->store = s; return true;
	case O_STORE_MB:
		if ((rc = args_double("--store-mb", s, 1, 1 << 26, &v, err)) == 0)
			a->store_mb = (uint32_t)v;
		break;
	default: usage(stderr); return false;
	}
	return rc ? complain(err) : true;
}

/* Whether the directory the picture path goes into exists and is writable (else says so,
 * naming -o, and returns false): a flight into a missing directory fails before its first
 * frame rather than at it. */
static bool out_dir_ok(const char *opt, const char *path)
{
	char dir[4096];
	const char *slash = strrchr(path, '/');
	if (!slash)
		snprintf(dir, sizeof dir, ".");
	else if (slash == path)
		snprintf(dir, sizeof dir, "/");
	else
		snprintf(dir, sizeof dir, "%.*s", (int)(slash - path), path);
	if (access(dir, W_OK | X_OK) != 0) {
		fprintf(stderr, "clipmapview: %s: \"%s\": directory %s: %s\n", opt, path, dir,
			strerror(errno));
		return false;
	}
	return true;
}

/* The options that only make sense together (or apart). Returns 0 or 2 (after saying why). */
static int check_args(const struct args *a)
{
	const char *why = NULL;
	if (a->window && (a->flight || a->outp || a->wait_complete))
		why = "--window flies interactively: no --flight, -o or --wait-complete (use "
		      "--screenshot)";
	else if (!a->window && (a->exit_after || a->screenshot))
		why = "--exit-after and --screenshot need --window";
	else if (a->connect_wait > 0 && !a->connect_to)
		why = "--connect-wait needs --connect";
	else if ((a->store || a->store_mb) && a->connect_to)
		why = "--store is the in-process engine's (with --connect the daemon's own [store] "
		      "path serves)";
	else if (a->store_mb && !a->store)
		why = "--store-mb needs --store";
	else if (!a->planet)
		why = "--planet is required (a planet file, or with --connect a planet name)";
	else if (!a->window && !a->camera == !a->flight)
		why = "give --camera or --flight (one of them), or --window";
	else if (!a->window && !a->outp && !a->statsp)
		why = "-o PATH is required without --window (or --stats FILE for figures only)";
	if (why) {
		fprintf(stderr, "clipmapview: %s\n", why);
		return 2;
	}
	if (a->flight && a->outp && !frame_pattern_ok(a->outp)) {
		fprintf(stderr, "clipmapview: -o: \"%s\": a flight's pattern takes one %%d-style "
				"frame number (e.g. f/%%05d.png); write %%%% for a literal %%\n", a->outp);
		return 2;
	}
	char first[4096];
	if (a->outp && a->flight && !frame_path(a->outp, 0, first, sizeof first)) {
		fprintf(stderr, "clipmapview: -o: \"%s\": path too long\n", a->outp);
		return 2;
	}
	if ((a->outp && !out_dir_ok("-o", a->flight ? first : a->outp)) ||
	    (a->statsp && !out_dir_ok("--stats", a->statsp)) ||
	    (a->screenshot && !out_dir_ok("--screenshot", a->screenshot)))
		return 2;
	return 0;
}

/* The command line into a. Returns -1 to go on, else the exit status (0: --help,
 * --version). */
static int parse_args(int argc, char **argv, struct args *a)
{
	*a = (struct args){ .width = 1280, .height = 720, .steps = 1, .timeout = 300,
			    .fov = 60, .fps = 30, .budget = 12, .backend = GL_BACKEND_AUTO };
	int c;
	while ((c = getopt_long(argc, argv, "o:hV", long_opts, NULL)) != -1) {
		if (c == O_HELP || c == 'h') {
			usage(stdout);
			return 0;
		}
		if (c == O_VERSION || c == 'V') {
			printf("clipmapview %s\n", CLIPMAP_VERSION);
			return 0;
		}
		if (!take_option(c, optarg, a))
			return 2;
	}
	if (optind < argc) {
		fprintf(stderr, "clipmapview: unexpected argument \"%s\"\n", argv[optind]);
		return 2;
	}
	int rc = check_args(a);
	return rc ? rc : -1;
}

/* ---- camera keys ---------------------------------------------------------------------- */

struct key {
	double v[5]; /* lat, lon, alt, heading, pitch */
};

/* "LAT,LON,ALT,HEADING,PITCH" (trailing blanks allowed, for flight file lines) into k.
 * Returns 0 or -EINVAL with err naming opt. */
static int parse_camera(const char *opt, const char *s, struct key *k, char err[256])
{
	static const double lo[5] = { -90, -180, 0, -360, -90 }, hi[5] = { 90, 180, 1e10, 360, 90 };
	char line[512];
	size_t n = strlen(s);
	while (n && strchr(" \t\r\n", s[n - 1]))
		n--;
	snprintf(line, sizeof line, "%.*s", (int)n, s);
	return args_doubles(opt, line, 5, lo, hi,
			    "LAT,LON,ALT,HEADING,PITCH (degrees, ALT metres above the ground)",
			    k->v, err);
}

/* The keys of a flight file into *out (returned owned), saying what is wrong if anything.
 * Returns 0 or -errno. */
static int read_flight(const char *path, struct key **out, size_t *n)
{
	FILE *f = fopen(path, "r");
	if (!f) {
		int rc = -errno;
		fprintf(stderr, "clipmapview: --flight: %s: %s\n", path, strerror(-rc));
		return rc;
	}
	char line[512];
	size_t cap = 0, ln = 0;
	*out = NULL;
	*n = 0;
	while (fgets(line, sizeof line, f)) {
		ln++;
		char *s = line;
		while (*s == ' ' || *s == '\t')
			s++;
		if (*s == '#' || *s == '\n' || *s == '\r' || !*s || (*s >= 'a' && *s <= 'z'))
			continue; /* comments, blank lines, a header */
		struct key k;
		char err[256];
		if (parse_camera("camera", s, &k, err) < 0) {
			fprintf(stderr, "clipmapview: --flight: %s:%zu: %s\n", path, ln, err);
			fclose(f);
			free(*out);
			*out = NULL;
			return -EINVAL;
		}
		if (*n == cap) {
			cap = cap ? 2 * cap : 64;
			*out = xrealloc(*out, cap * sizeof **out);
		}
		(*out)[(*n)++] = k;
	}
	fclose(f);
	if (!*n) {
		fprintf(stderr, "clipmapview: --flight: %s: no camera keys\n", path);
		return -EINVAL;
	}
	return 0;
}

/* --camera (one key) or --flight (a file of them) into *keys (returned owned; NULL when
 * neither). Returns 0 or 2. */
static int load_keys(const struct args *a, struct key **keys, size_t *nkeys)
{
	*keys = NULL;
	*nkeys = 0;
	if (a->camera) {
		*keys = xmalloc(sizeof **keys);
		*nkeys = 1;
		char err[256];
		if (parse_camera("--camera", a->camera, *keys, err) < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			free(*keys);
			*keys = NULL;
			return 2;
		}
	} else if (a->flight) {
		if (read_flight(a->flight, keys, nkeys) < 0)
			return 2;
	}
	return 0;
}

static double lerp_angle(double a, double b, double t)
{
	double d = fmod(b - a + 540.0, 360.0) - 180.0;
	return a + d * t;
}

/* Frame f of the flight: steps frames from each key to the next, lat, alt and pitch
 * interpolated linearly, lon and heading the short way round. */
static struct view_camera flight_camera(const struct key *keys, size_t nkeys, int steps,
					double fov, size_t f)
{
	size_t k = f / (size_t)steps;
	double t = (double)(f % (size_t)steps) / steps;
	const struct key *a = &keys[k], *b = &keys[k + 1 < nkeys ? k + 1 : k];
	struct view_camera cam = {
		.lat = a->v[0] + (b->v[0] - a->v[0]) * t,
		.lon = lerp_angle(a->v[1], b->v[1], t),
		.alt = a->v[2] + (b->v[2] - a->v[2]) * t,
		.heading = lerp_angle(a->v[3], b->v[3], t),
		.pitch = a->v[4] + (b->v[4] - a->v[4]) * t,
		.fov_y = fov,
	};
	if (cam.lon >= 180)
		cam.lon -= 360;
	if (cam.lon < -180)
		cam.lon += 360;
	return cam;
}

/* ---- the link to the daemon ---------------------------------------------------------- */

/* What the HUD, --stats and stderr say about the link (net: NULL in-process). */
struct link_report {
	const struct view_source *net;
	struct view_net_link now; /* at the last frame */
	unsigned said_lost, said_reconnects; /* losses and reconnects reported on stderr */
	unsigned said_attempt; /* the last failed attempt reported on stderr */
	double t0;	       /* clock_now_s at the start, for "t" in --stats */
};

/* After a frame: the link's state into r->now, what happened since the last frame on stderr
 * (a loss, failed attempts 1, 2, 4, 8, …, the reconnect; a loss and its reconnect may both
 * fall between two frames). */
static void link_note(struct link_report *r)
{
	if (!r->net)
		return;
	view_source_net_link(r->net, &r->now);
	const struct view_net_link *l = &r->now;
	if (l->lost > r->said_lost) {
		fprintf(stderr, "clipmapview: lost the connection to %s: %s; reconnecting\n",
			l->peer, l->lost_why);
		r->said_lost = l->lost;
		r->said_attempt = 0;
	}
	if (!l->up && l->failed > r->said_attempt && !(l->failed & (l->failed - 1))) {
		fprintf(stderr, "clipmapview: reconnect attempt %u failed: %s\n", l->failed,
			l->why);
		r->said_attempt = l->failed;
	}
	if (l->reconnects > r->said_reconnects) {
		fprintf(stderr, "clipmapview: reconnected to %s after %u attempt%s (%.1f s down); "
			"%u reconnect%s so far\n", l->peer, l->last_attempts,
			l->last_attempts == 1 ? "" : "s", l->last_down_s, l->reconnects,
			l->reconnects == 1 ? "" : "s");
		r->said_reconnects = l->reconnects;
	}
}

/* "up" or "reconnecting (attempt N)" into buf. */
static const char *link_text(const struct view_net_link *l, char *buf, size_t n)
{
	if (l->up)
		snprintf(buf, n, "up");
	else
		snprintf(buf, n, "reconnecting (attempt %u)", l->attempt ? l->attempt : 1);
	return buf;
}

/* ---- output --------------------------------------------------------------------------- */

static void stats_line(FILE *f, int frame, const struct view_frame_stats *s,
		       const struct link_report *lr)
{
	if (lr->net) {
		char lt[64];
		fprintf(f, "{\"t\":%.3f,\"link\":\"%s\",\"reconnects\":%u,\"link_bps\":%.0f,"
			"\"link_bytes\":%llu,\"rtt_ms\":%.1f,\"queue_ms\":%.1f,", clock_now_s() - lr->t0,
			link_text(&lr->now, lt, sizeof lt), lr->now.reconnects, lr->now.rate_bps,
			(unsigned long long)lr->now.rx_bytes,
			lr->now.rtt_ms, lr->now.queue_ms);
	} else {
		fprintf(f, "{\"t\":%.3f,", clock_now_s() - lr->t0);
	}
	fprintf(f,
		"\"frame\":%d,\"ms\":%.3f,\"lmin\":%d,\"lmax\":%d,\"lfirst\":%d,\"llast\":%d,"
		"\"levels_drawn\":%d,\"dmax\":%d,\"ldetail\":%d,\"triangles\":%llu,\"bytes_uploaded\":%llu,\"tiles_received\":%d,"
		"\"wants_sent\":%zu,\"complete\":%s,\"alt\":%.3f,\"agl\":%.3f,\"color_layer\":\"",
		frame, s->cpu_ms, s->lmin, s->lmax, s->lfirst, s->llast, s->levels_drawn, s->dmax,
		s->ldetail, (unsigned long long)s->triangles, (unsigned long long)s->bytes_uploaded,
		s->tiles_received, s->wants_sent, s->complete ? "true" : "false", s->alt, s->agl);
	/* a layer's name as a JSON string (names are UTF-8: only quotes, backslashes and
	 * control characters need escapes) */
	for (const unsigned char *c = (const unsigned char *)(s->color_layer ? s->color_layer : "");
	     *c; c++)
		fprintf(f, *c == '"' || *c == '\\' ? "\\%c" : *c < 0x20 ? "\\u%04x" : "%c", *c);
	fprintf(f, "\"}\n");
}

/* The picture v shows as PNG at path (pix: scratch of width × height × 4 bytes). Returns 0
 * or 1 (after saying why). */
static int write_picture(struct view *v, const char *path, int width, int height,
			 unsigned char *pix)
{
	char err[256];
	view_read_rgba(v, pix);
	if (img_write(path, width, height, 4, IMG_U8, pix, err) < 0) {
		fprintf(stderr, "clipmapview: %s\n", err);
		return 1;
	}
	return 0;
}

/* ---- colour layers -------------------------------------------------------------------- */

/* Whether every --switch-layer-at names a colour layer of the planet (else says which does
 * not, and the planet's colour layers). Returns 0 or 2. */
static int check_switches(const struct args *a, const struct view *v)
{
	char err[256];
	for (int i = 0; i < a->nsw; i++)
		if (view_find_color_layer(v, a->sw[i].name, err) < 0) {
			fprintf(stderr, "clipmapview: --switch-layer-at %ld:%s: %s\n", a->sw[i].frame,
				a->sw[i].name, err);
			return 2;
		}
	return 0;
}

/* The --switch-layer-at entries due at frame f (checked by check_switches). */
static void scripted_switches(const struct args *a, struct view *v, long f)
{
	char err[256];
	for (int i = 0; i < a->nsw; i++)
		if (a->sw[i].frame == f)
			view_set_color_layer(v, a->sw[i].name, err);
}

/* L: the planet's next colour layer after the one drawn (the planet's order, wrapping). */
static void next_color_layer(struct view *v, const struct view_planet *p)
{
	const char *cur = view_color_layer(v);
	int at = -1, ncolor = 0;
	for (int i = 0; cur && i < p->nlayers; i++)
		if (p->layer[i].format == PIX_COLOR) {
			ncolor++;
			if (!strcmp(p->layer[i].name, cur))
				at = i;
		}
	if (at < 0 || ncolor < 2)
		return;
	for (int k = 1; k <= p->nlayers; k++) {
		int i = (at + k) % p->nlayers;
		if (p->layer[i].format == PIX_COLOR) {
			char err[256];
			view_set_color_layer(v, p->layer[i].name, err);
			return;
		}
	}
}

/* ---- window mode ---------------------------------------------------------------------- */

struct window_opts {
	const char *title;
	int width, height;
	long exit_after; /* frames; 0: until closed */
	const char *screenshot;
	FILE *stats;
	struct link_report *link;
	const struct args *args; /* --switch-layer-at */
	const struct view_planet *planet;
};

static void fly_input(const struct gl_window_input *in, struct view_fly_input *f)
{
	memset(f, 0, sizeof *f);
	f->key[FLY_FORWARD] = in->key[GLW_W] || in->key[GLW_UP];
	f->key[FLY_BACK] = in->key[GLW_S] || in->key[GLW_DOWN];
	f->key[FLY_LEFT] = in->key[GLW_A] || in->key[GLW_LEFT];
	f->key[FLY_RIGHT] = in->key[GLW_D] || in->key[GLW_RIGHT];
	f->key[FLY_UP] = in->key[GLW_E] || in->key[GLW_PAGE_UP];
	f->key[FLY_DOWN] = in->key[GLW_Q] || in->key[GLW_PAGE_DOWN];
	f->key[FLY_FAST] = in->key[GLW_SHIFT];
	if (in->left) {
		f->orbit_dx = in->dx;
		f->orbit_dy = in->dy;
	} else if (in->right) {
		f->look_dx = in->dx;
		f->look_dy = in->dy;
	}
	f->wheel = in->wheel;
	f->reset = in->reset;
}

/* The HUD in the window title: rates over the frames since it was last refreshed. */
struct hud {
	double since; /* clock_now_s of the last refresh */
	long frames, tiles;
	uint64_t bytes;
};

/* Counts frame st in; twice a second refreshes the title. */
static void hud_frame(struct hud *h, struct gl_window *w, const char *title,
		      const struct view_frame_stats *st, const struct view_camera *cam,
		      const struct link_report *lr)
{
	h->frames++;
	h->tiles += st->tiles_received;
	h->bytes += st->bytes_uploaded;
	double now = clock_now_s();
	if (now - h->since < 0.5)
		return;
	double dt = now - h->since;
	char text[512], link[128] = "", layer[48] = "";
	if (st->color_layer && st->color_layer[0])
		snprintf(layer, sizeof layer, " | colour %.32s", st->color_layer);
	if (lr->net && !lr->now.up)
		snprintf(link, sizeof link, " | reconnecting (attempt %u)",
			 lr->now.attempt ? lr->now.attempt : 1);
	else if (lr->net)
		snprintf(link, sizeof link, " | link %.2f Mbit/s, rtt %.0f ms, queue %.0f ms%s",
			 lr->now.rate_bps * 1e-6, lr->now.rtt_ms, lr->now.queue_ms,
			 lr->now.reconnects ? ", reconnected" : "");
	snprintf(text, sizeof text,
		 "%s | %.1f fps | levels %d-%d (%d drawn, texels %d) of %d-%d%s | %.0f tiles/s"
		 " | %.2f MB/s | %.4f, %.4f, %.0f m%s%s",
		 title, h->frames / dt, st->lfirst, st->llast, st->levels_drawn, st->ldetail,
		 st->lmin, st->lmax, st->complete ? " ready" : "", h->tiles / dt, h->bytes / dt / 1e6, cam->lat,
		 cam->lon, st->agl, layer, link);
	gl_window_set_title(w, text);
	*h = (struct hud){ .since = now };
}

/* The interactive loop: input → camera → view_frame → blit → swap, paced to 60 Hz (vsync
 * when the system gives it, else a clock). The title carries the HUD, refreshed twice a
 * second. Returns the exit status. */
static int window_loop(struct gl_window *w, struct view *v, const struct view_camera *home,
		       double radius, const struct window_opts *o)
{
	struct view_fly fly;
	view_fly_init(&fly, home, radius);
	const double period = 1.0 / 60;
	double t_start = clock_now_s(), t_prev = t_start;
	struct hud hud = { .since = t_start };
	long frames = 0;
	char err[256];
	for (;;) {
		struct gl_window_input in;
		gl_window_poll(w, &in);
		if (in.quit)
			break;
		int fw, fh;
		gl_window_framebuffer_size(w, &fw, &fh);
		if (fw > 0 && fh > 0 && view_resize(v, fw, fh, err) < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			return 1;
		}
		double t = clock_now_s();
		struct view_fly_input fi;
		fly_input(&in, &fi);
		struct view_camera last;
		view_last_camera(v, &last);
		fly.cam.width = last.width > 0 ? last.width : fw;
		fly.cam.height = last.height > 0 ? last.height : fh;
		view_fly_step(&fly, &fi, t - t_prev);
		t_prev = t;
		for (int k = 0; k < in.next_layer; k++)
			next_color_layer(v, o->planet);
		scripted_switches(o->args, v, frames);
		struct view_frame_stats st;
		int rc = view_frame(v, &fly.cam, t - t_start, &st);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: frame %ld: %s\n", frames, strerror(-rc));
			return 1;
		}
		link_note(o->link);
		if (o->stats)
			stats_line(o->stats, (int)frames, &st, o->link);
		gl_window_present(w, view_framebuffer(v), fw, fh);
		frames++;
		hud_frame(&hud, w, o->title, &st, &fly.cam, o->link);
		if (o->exit_after > 0 && frames >= o->exit_after)
			break;
		/* 60 Hz (vsync already waited when the frame took a full period); tiles that
		 * arrive meanwhile are taken now and uploaded by the next frame. */
		double left = period - (clock_now_s() - t);
		rc = left > 0 ? view_idle(v, left) : 0;
		if (rc < 0) {
			fprintf(stderr, "clipmapview: after frame %ld: %s\n", frames, strerror(-rc));
			return 1;
		}
	}
	if (o->screenshot && frames > 0) {
		struct view_camera last;
		view_last_camera(v, &last);
		unsigned char *pix = xmalloc((size_t)last.width * last.height * 4);
		int status = write_picture(v, o->screenshot, last.width, last.height, pix);
		free(pix);
		return status;
	}
	return 0;
}

/* --window: the views of src in a window, starting at the first key (or above the whole
 * planet). Returns the exit status. */
static int run_window(const struct args *a, struct view_source *src, const struct key *keys,
		      FILE *stats, struct link_report *lr)
{
	char title[128], err[256];
	struct gl_window *win = NULL;
	struct view *v = NULL;
	struct view_desc d = a->d;
	int status = 1;
	snprintf(title, sizeof title, "clipmapview %s", src->planet.name);
	if (gl_window_create(a->width, a->height, title, &win, err) < 0) {
		fprintf(stderr, "clipmapview: --window: %s\n", err);
		goto out;
	}
	gl_window_framebuffer_size(win, &d.width, &d.height);
	d.budget_ms = a->budget;
	if (view_create(gl_window_api(win), src, &d, &v, err) < 0) {
		fprintf(stderr, "clipmapview: %s\n", err);
		goto out;
	}
	double radius = src->planet.a * (1 - src->planet.f / 3);
	/* default: the whole planet from above, north up */
	struct view_camera home = { .lat = 20, .lon = 0, .alt = 2.2 * radius, .heading = 0,
				    .pitch = -90, .fov_y = a->fov, .width = d.width,
				    .height = d.height };
	if (keys) {
		home.lat = keys->v[0];
		home.lon = keys->v[1];
		home.alt = keys->v[2];
		home.heading = keys->v[3];
		home.pitch = keys->v[4];
	}
	if ((status = check_switches(a, v)))
		goto out;
	struct window_opts wo = { title, a->width, a->height, a->exit_after, a->screenshot,
				  stats, lr, a, &src->planet };
	status = window_loop(win, v, &home, radius, &wo);
out:
	view_destroy(v);
	gl_window_destroy(win);
	return status;
}

/* ---- offline mode --------------------------------------------------------------------- */

/* Renders the frames of the keys (one camera, or a flight) into v, writing each picture
 * when -o asks, in real time (--fps) or complete (--wait-complete). Returns the exit status. */
static int render_frames(const struct args *a, struct view *v, const struct key *keys,
			 size_t nkeys, FILE *stats, struct link_report *lr)
{
	unsigned char *pix = xmalloc((size_t)a->width * a->height * 4);
	size_t nframes = nkeys == 1 ? 1 : (nkeys - 1) * (size_t)a->steps + 1;
	double t_start = clock_now_s();
	int status = 1;
	size_t incomplete = 0; /* --wait-complete frames written after --timeout */
	for (size_t f = 0; f < nframes; f++) {
		struct view_camera cam = flight_camera(keys, nkeys, a->steps, a->fov, f);
		struct view_frame_stats st;
		int rc;
		scripted_switches(a, v, (long)f);
		if (a->wait_complete)
			rc = view_frame_complete(v, &cam, a->timeout, &st, NULL);
		else
			rc = view_frame(v, &cam,
					a->fps > 0 ? clock_now_s() - t_start : (double)f / 30.0, &st);
		if (rc == -ETIMEDOUT) {
			fprintf(stderr, "clipmapview: frame %zu: not complete after %g s (--timeout)\n",
				f, a->timeout);
			incomplete++;
		} else if (rc < 0) {
			fprintf(stderr, "clipmapview: frame %zu: %s\n", f, strerror(-rc));
			goto out;
		}
		link_note(lr);
		if (stats)
			stats_line(stats, (int)f, &st, lr);
		if (a->outp) {
			char path[4096];
			if (!a->flight)
				snprintf(path, sizeof path, "%s", a->outp);
			else if (!frame_path(a->outp, (int)f, path, sizeof path)) {
				fprintf(stderr, "clipmapview: -o: frame %zu: path too long\n", f);
				goto out;
			}
			if (write_picture(v, path, a->width, a->height, pix))
				goto out;
		}
		/* Real time: the next frame is due at (f + 1) / fps; tiles come in meanwhile. */
		double left = t_start + (double)(f + 1) / a->fps - clock_now_s();
		if (!a->wait_complete && a->fps > 0 && f + 1 < nframes && left > 0) {
			rc = view_idle(v, left);
			if (rc < 0) {
				fprintf(stderr, "clipmapview: %s\n", strerror(-rc));
				goto out;
			}
		}
	}
	status = incomplete ? 3 : 0;
	if (incomplete)
		fprintf(stderr, "clipmapview: %zu of %zu frames incomplete (written anyway); exit "
				"status 3\n", incomplete, nframes);
out:
	free(pix);
	return status;
}

/* Offline: an OpenGL context without a display, a view of src in it, the frames. Returns the
 * exit status. */
static int run_offline(const struct args *a, struct view_source *src, const struct key *keys,
		       size_t nkeys, FILE *stats, struct link_report *lr)
{
	char err[256];
	struct gl_context *ctx = NULL;
	struct view *v = NULL;
	int status = 1;
	if (gl_context_create(a->backend, &ctx, err) < 0) {
		fprintf(stderr, "clipmapview: no OpenGL context: %s\n", err);
		goto out;
	}
	struct view_desc d = a->d;
	d.width = a->width;
	d.height = a->height;
	/* --wait-complete pictures wait for every level; real time keeps its frames short. */
	d.budget_ms = a->wait_complete ? 0 : a->budget;
	if (view_create(gl_context_api(ctx), src, &d, &v, err) < 0) {
		fprintf(stderr, "clipmapview: %s\n", err);
		goto out;
	}
	if ((status = check_switches(a, v)) == 0)
		status = render_frames(a, v, keys, nkeys, stats, lr);
out:
	view_destroy(v);
	gl_context_destroy(ctx);
	return status;
}

/* ---- the source of tiles -------------------------------------------------------------- */

/* A TARGET with a colon and no slash is HOST:PORT, anything else a Unix socket path. */
static int open_net(const struct args *a, struct view_source **src, char err[256])
{
	const char *target = a->connect_to;
	bool tcp = strchr(target, ':') && !strchr(target, '/');
	struct net_opts o = { .socket_path = tcp ? NULL : target, .hostport = tcp ? target : NULL,
			      .token_file = a->token_file, .name = "clipmapview/1",
			      .tls_ca = a->tls_ca, .tls = a->tls,
			      /* a picture can take approximate texels; the daemon decides by link */
			      .codecs = a->lossless ? TCODEC_LOSSLESS_MASK : TCODEC_ALL_MASK };
	char e2[256];
	unsigned attempts = 0;
	int rc = view_source_net_create_wait(&o, a->planet, a->connect_wait, &attempts, src, e2);
	if (rc == 0) {
		if (attempts > 1)
			fprintf(stderr, "clipmapview: connected to %s at attempt %u\n", target,
				attempts);
		return 0;
	}
	const char *hint = "";
	if (strncmp(e2, "cannot connect", 14) == 0)
		hint = " \xe2\x80\x94 is clipmapd running and listening there? (--connect)";
	else if (rc == -EACCES)
		hint = " (--token-file)";
	if (a->connect_wait > 0)
		err_set(err, "%.150s%s (gave up after %u attempts, --connect-wait %g)", e2, hint,
			attempts, a->connect_wait);
	else
		err_set(err, "%.180s%s", e2, hint);
	return rc;
}

/* The daemon's planet (--connect) or the planet file evaluated here. Returns 0, or the exit
 * status after saying why not: 1 when the daemon fails, 2 for a bad planet file. */
static int open_source(const struct args *a, struct view_source **src)
{
	char err[256] = "";
	if (a->connect_to) {
		if (open_net(a, src, err) < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			return 1;
		}
		return 0;
	}
	/* a planet file, or a planet's name looked up as clipmapctl does */
	char path[4096];
	if (planet_path_resolve(a->planet, path, sizeof path) < 0) {
		fprintf(stderr, "clipmapview: planet %s not found (tried %s)\n", a->planet, path);
		return 2;
	}
	struct view_source_local_opts lo = { .workers = a->workers, .store = a->store,
					     .store_mb = a->store_mb };
	int rc = view_source_local_create(path, &lo, src, err);
	if (rc < 0 || err[0]) /* a failure, or a note on the store */
		fprintf(stderr, "clipmapview: %s\n", err);
	return rc < 0 ? 2 : 0;
}

int main(int argc, char **argv)
{
	struct args a;
	int status = parse_args(argc, argv, &a);
	if (status >= 0)
		return status;
	struct key *keys;
	size_t nkeys;
	if ((status = load_keys(&a, &keys, &nkeys)))
		return status;
	struct view_source *src = NULL;
	FILE *stats = NULL;
	if ((status = open_source(&a, &src)))
		goto out;
	status = 1;
	if (a.statsp && !(stats = fopen(a.statsp, "w"))) {
		fprintf(stderr, "clipmapview: %s: %s\n", a.statsp, strerror(errno));
		goto out;
	}
	struct link_report lr = { .net = a.connect_to ? src : NULL, .t0 = clock_now_s() };
	if (a.window)
		status = run_window(&a, src, keys, stats, &lr);
	else
		status = run_offline(&a, src, keys, nkeys, stats, &lr);
	if (lr.net && lr.now.lost)
		fprintf(stderr, "clipmapview: the connection was lost %u time%s, restored %u "
			"time%s\n", lr.now.lost, lr.now.lost == 1 ? "" : "s", lr.now.reconnects,
			lr.now.reconnects == 1 ? "" : "s");
	if (a.store) {
		char line[512];
		view_source_local_report(src, line, sizeof line);
		fprintf(stderr, "clipmapview: %s\n", line);
	}
out:
	if (stats && fclose(stats) != 0 && status == 0) {
		fprintf(stderr, "clipmapview: %s: %s\n", a.statsp, strerror(errno));
		status = 1;
	}
	view_source_destroy(src);
	free(keys);
	return status;
}
