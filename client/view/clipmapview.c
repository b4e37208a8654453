/* clipmapview — the viewer. Offline mode renders pictures of a planet evaluated in this
 * process (--planet FILE) or served by clipmapd (--connect SOCKET|HOST:PORT --planet NAME):
 * one camera (--camera) or a flight (--flight CSV), EGL surfaceless or OSMesa, no display
 * needed. Window mode (--window) flies the same views interactively in a GLFW window at up to
 * 60 frames/s, never waiting for tiles. Exit status: 0 ok, 1 runtime failure, 2 bad usage.
 */
#include <errno.h>
#include <getopt.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gl_context.h"
#include "gl_window.h"
#include "common/img.h"
#include "view.h"
#include "view_fly.h"
#include "view_source_local.h"
#include "view_source_net.h"
#include "common/xalloc.h"

static void usage(FILE *f)
{
	fprintf(f,
		"usage: clipmapview --planet FILE [options]              (in-process engine)\n"
		"       clipmapview --connect SOCKET|HOST:PORT --planet NAME [--token-file F] [options]\n"
		"  --connect TARGET    clipmapd's Unix socket path, or HOST:PORT (TCP)\n"
		"  --token-file F      the daemon's shared secret (default: $CLIPMAP_TOKEN)\n"
		"  --camera LAT,LON,ALT,HEADING,PITCH  degrees; ALT metres above the ground\n"
		"  --flight FILE       CSV of camera keys (lat,lon,alt,heading,pitch per line)\n"
		"  --steps N           frames from one key to the next (default 1)\n"
		"  -o PATH             PNG to write (a flight: a printf pattern, e.g. f/%%05d.png)\n"
		"  --size WxH          framebuffer (default 1280x720)\n"
		"  --wait-complete     wait for every wanted level before writing a picture\n"
		"  --timeout S         give up waiting after S seconds (default 300)\n"
		"  --fps N             without --wait-complete: frames paced at N per second in real\n"
		"                      time, tiles taken between them (default 30; 0: unpaced)\n"
		"  --budget MS         real time (window, paced flights): a frame stops refining once\n"
		"                      its texture uploads have taken MS ms (default 12; 0: never)\n"
		"  --stats FILE        one JSON line per frame\n"
		"  --fov DEG           vertical field of view (default 60)\n"
		"  --sun AZ,EL         sun azimuth and elevation at the camera (default 135,35)\n"
		"  --exaggerate X      vertical exaggeration of the relief (default 1)\n"
		"  --haze X            atmosphere density, 1 Earth's, 0 none (default 1)\n"
		"  --rings N,M         N steps around, M rings per level (default 256,16)\n"
		"  --backend egl|osmesa, --workers N, --no-prefetch\n"
		"  --window            fly interactively in a window (--camera optional):\n"
		"                      left drag orbit, right drag look, wheel zoom, WASD/arrows move,\n"
		"                      E/PageUp climb, Q/PageDown descend, Shift faster, R reset, Esc quit\n"
		"  --exit-after N      (window) close after N frames\n"
		"  --screenshot FILE   (window) write the last frame as PNG on exit\n");
}

/* Whether all of s is a number in [lo, hi] (then stored in *out). */
static bool number(const char *s, double lo, double hi, double *out)
{
	char *end;
	double v = strtod(s, &end);
	if (end == s || *end || !(v >= lo && v <= hi))
		return false;
	*out = v;
	return true;
}

static double mono_s(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (double)ts.tv_sec + (double)ts.tv_nsec / 1e9;
}

struct window_opts {
	const char *title;
	int width, height;
	long exit_after; /* frames; 0: until closed */
	const char *screenshot;
	FILE *stats;
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

static void stats_line(FILE *f, int frame, const struct view_frame_stats *s);

/* The interactive loop: input → camera → view_frame → blit → swap, paced to 60 Hz (vsync
 * when the system gives it, else a clock). The title carries the HUD, refreshed twice a
 * second. Returns the exit status. */
static int window_loop(struct gl_window *w, struct view *v, const struct view_camera *home,
		       double radius, const struct window_opts *o)
{
	struct view_fly fly;
	view_fly_init(&fly, home, radius);
	const double period = 1.0 / 60;
	double t_start = mono_s(), t_prev = t_start, t_hud = t_start;
	long frames = 0, hud_frames = 0;
	uint64_t hud_bytes = 0;
	long hud_tiles = 0;
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
		double t = mono_s();
		struct view_fly_input fi;
		fly_input(&in, &fi);
		struct view_camera last;
		view_last_camera(v, &last);
		fly.cam.width = last.width > 0 ? last.width : fw;
		fly.cam.height = last.height > 0 ? last.height : fh;
		view_fly_step(&fly, &fi, t - t_prev);
		t_prev = t;
		struct view_frame_stats st;
		int rc = view_frame(v, &fly.cam, t - t_start, &st);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: frame %ld: %s\n", frames, strerror(-rc));
			return 1;
		}
		if (o->stats)
			stats_line(o->stats, (int)frames, &st);
		gl_window_present(w, view_framebuffer(v), fw, fh);
		frames++;
		hud_frames++;
		hud_tiles += st.tiles_received;
		hud_bytes += st.bytes_uploaded;
		double now = mono_s();
		if (now - t_hud >= 0.5) {
			double dt = now - t_hud;
			char title[256];
			snprintf(title, sizeof title,
				 "%s | %.1f fps | levels %d-%d of %d-%d%s | %.0f tiles/s | %.2f MB/s"
				 " | %.4f, %.4f, %.0f m",
				 o->title, hud_frames / dt, st.lfirst, st.llast, st.lmin, st.lmax,
				 st.complete ? " ready" : "", hud_tiles / dt, hud_bytes / dt / 1e6,
				 fly.cam.lat, fly.cam.lon, st.agl);
			gl_window_set_title(w, title);
			t_hud = now;
			hud_frames = 0;
			hud_tiles = 0;
			hud_bytes = 0;
		}
		if (o->exit_after > 0 && frames >= o->exit_after)
			break;
		/* 60 Hz (vsync already waited when the frame took a full period); tiles that
		 * arrive meanwhile are taken now and uploaded by the next frame. */
		double left = period - (mono_s() - t);
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
		view_read_rgba(v, pix);
		int rc = img_write(o->screenshot, last.width, last.height, 4, IMG_U8, pix, err);
		free(pix);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			return 1;
		}
	}
	return 0;
}

struct key {
	double v[5];
};

static int parse_camera(const char *s, struct key *k)
{
	char *end;
	const char *p = s;
	for (int i = 0; i < 5; i++) {
		k->v[i] = strtod(p, &end);
		if (end == p)
			return -EINVAL;
		p = end;
		if (i < 4) {
			if (*p != ',')
				return -EINVAL;
			p++;
		}
	}
	while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
		p++;
	return *p ? -EINVAL : 0;
}

static int read_flight(const char *path, struct key **out, size_t *n)
{
	FILE *f = fopen(path, "r");
	if (!f)
		return -errno;
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
		if (parse_camera(s, &k) < 0) {
			fprintf(stderr, "%s:%zu: camera: expected lat,lon,alt,heading,pitch\n", path, ln);
			fclose(f);
			free(*out);
			return -EINVAL;
		}
		if (*n == cap) {
			cap = cap ? 2 * cap : 64;
			*out = xrealloc(*out, cap * sizeof **out);
		}
		(*out)[(*n)++] = k;
	}
	fclose(f);
	return *n ? 0 : -EINVAL;
}

static double lerp_angle(double a, double b, double t)
{
	double d = fmod(b - a + 540.0, 360.0) - 180.0;
	return a + d * t;
}

static void stats_line(FILE *f, int frame, const struct view_frame_stats *s)
{
	fprintf(f,
		"{\"frame\":%d,\"ms\":%.3f,\"lmin\":%d,\"lmax\":%d,\"lfirst\":%d,\"llast\":%d,"
		"\"triangles\":%llu,\"bytes_uploaded\":%llu,\"tiles_received\":%d,"
		"\"wants_sent\":%zu,\"complete\":%s,\"alt\":%.3f,\"agl\":%.3f}\n",
		frame, s->cpu_ms, s->lmin, s->lmax, s->lfirst, s->llast,
		(unsigned long long)s->triangles, (unsigned long long)s->bytes_uploaded,
		s->tiles_received, s->wants_sent, s->complete ? "true" : "false", s->alt, s->agl);
}

/* A TARGET with a colon and no slash is HOST:PORT, anything else a Unix socket path. */
static int open_net(const char *target, const char *token_file, const char *planet,
		    struct view_source **src, char err[256])
{
	bool tcp = strchr(target, ':') && !strchr(target, '/');
	struct net_opts o = { .socket_path = tcp ? NULL : target, .hostport = tcp ? target : NULL,
			      .token_file = token_file, .name = "clipmapview/1" };
	char e2[256];
	int rc = view_source_net_create(&o, planet, src, e2);
	if (rc == 0)
		return 0;
	const char *hint = "";
	if (strncmp(e2, "cannot connect", 14) == 0)
		hint = " \xe2\x80\x94 is clipmapd running and listening there? (--connect)";
	else if (rc == -EACCES)
		hint = " (--token-file)";
	snprintf(err, 256, "%.180s%s", e2, hint);
	return rc;
}

int main(int argc, char **argv)
{
	const char *planet = NULL, *connect_to = NULL, *token_file = NULL, *camera = NULL, *flight = NULL, *outp = NULL, *statsp = NULL;
	int width = 1280, height = 720, steps = 1, workers = 0;
	bool wait_complete = false, window = false;
	long exit_after = 0;
	const char *screenshot = NULL;
	double timeout = 300, fov = 60, fps = 30, budget = 12;
	struct view_desc d = { 0 };
	enum gl_backend backend = GL_BACKEND_AUTO;
	enum { O_PLANET = 256, O_CAMERA, O_FLIGHT, O_STEPS, O_SIZE, O_WAIT, O_TIMEOUT, O_STATS,
	       O_FOV, O_SUN, O_RINGS, O_BACKEND, O_WORKERS, O_NOPF, O_HELP,
	       O_CONNECT, O_TOKEN, O_EXAG, O_HAZE, O_WINDOW, O_EXIT_AFTER, O_SCREENSHOT, O_FPS,
	       O_BUDGET };
	static const struct option opts[] = {
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
		{ "connect", required_argument, NULL, O_CONNECT },
		{ "token-file", required_argument, NULL, O_TOKEN },
		{ "exaggerate", required_argument, NULL, O_EXAG },
		{ "haze", required_argument, NULL, O_HAZE },
		{ "window", no_argument, NULL, O_WINDOW },
		{ "exit-after", required_argument, NULL, O_EXIT_AFTER },
		{ "screenshot", required_argument, NULL, O_SCREENSHOT },
		{ NULL, 0, NULL, 0 },
	};
	int c;
	while ((c = getopt_long(argc, argv, "o:h", opts, NULL)) != -1) {
		switch (c) {
		case O_PLANET: planet = optarg; break;
		case O_CONNECT: connect_to = optarg; break;
		case O_TOKEN: token_file = optarg; break;
		case O_EXAG:
			d.exaggeration = strtof(optarg, NULL);
			if (!(d.exaggeration >= 0.1f && d.exaggeration <= 100)) {
				fprintf(stderr, "clipmapview: --exaggerate: 0.1 to 100\n");
				return 2;
			}
			break;
		case O_HAZE: {
			float hz = strtof(optarg, NULL);
			if (!(hz >= 0 && hz <= 100)) {
				fprintf(stderr, "clipmapview: --haze: 0 to 100\n");
				return 2;
			}
			d.haze = hz > 0 ? hz : -1;
			break;
		}
		case O_WINDOW: window = true; break;
		case O_EXIT_AFTER: {
			char *end;
			exit_after = strtol(optarg, &end, 10);
			if (*end || exit_after < 1) {
				fprintf(stderr, "clipmapview: --exit-after: a number of frames >= 1\n");
				return 2;
			}
			break;
		}
		case O_SCREENSHOT: screenshot = optarg; break;
		case O_CAMERA: camera = optarg; break;
		case O_FLIGHT: flight = optarg; break;
		case O_STEPS: steps = atoi(optarg); break;
		case 'o': outp = optarg; break;
		case O_SIZE:
			if (sscanf(optarg, "%dx%d", &width, &height) != 2 || width < 16 ||
			    height < 16 || width > 16384 || height > 16384) {
				fprintf(stderr, "clipmapview: --size: expected WxH\n");
				return 2;
			}
			break;
		case O_WAIT: wait_complete = true; break;
		case O_TIMEOUT: timeout = atof(optarg); break;
		case O_BUDGET:
			if (!number(optarg, 0, 10000, &budget)) {
				fprintf(stderr, "clipmapview: --budget: milliseconds, 0 to 10000\n");
				return 2;
			}
			break;
		case O_FPS:
			if (!number(optarg, 0, 1000, &fps)) {
				fprintf(stderr, "clipmapview: --fps: frames per second, 0 to 1000\n");
				return 2;
			}
			break;
		case O_STATS: statsp = optarg; break;
		case O_FOV: fov = atof(optarg); break;
		case O_SUN:
			if (sscanf(optarg, "%f,%f", &d.sun_az, &d.sun_el) != 2) {
				fprintf(stderr, "clipmapview: --sun: expected AZ,EL\n");
				return 2;
			}
			break;
		case O_RINGS:
			if (sscanf(optarg, "%d,%d", &d.n_phi, &d.m_rings) != 2 || d.n_phi < 8 ||
			    d.m_rings < 1 || d.n_phi > 4096 || d.m_rings > 64) {
				fprintf(stderr, "clipmapview: --rings: expected N,M\n");
				return 2;
			}
			break;
		case O_BACKEND:
			if (!strcmp(optarg, "egl"))
				backend = GL_BACKEND_EGL;
			else if (!strcmp(optarg, "osmesa"))
				backend = GL_BACKEND_OSMESA;
			else {
				fprintf(stderr, "clipmapview: --backend: egl or osmesa\n");
				return 2;
			}
			break;
		case O_WORKERS: workers = atoi(optarg); break;
		case O_NOPF: d.no_prefetch = true; break;
		case O_HELP:
		case 'h': usage(stdout); return 0;
		default: usage(stderr); return 2;
		}
	}
	if (window && (flight || outp || wait_complete)) {
		fprintf(stderr, "clipmapview: --window flies interactively: no --flight, -o or "
				"--wait-complete (use --screenshot)\n");
		return 2;
	}
	if (!window && (exit_after || screenshot)) {
		fprintf(stderr, "clipmapview: --exit-after and --screenshot need --window\n");
		return 2;
	}
	if (!planet || (!window && !camera == !flight) || steps < 1 || fov <= 1 || fov >= 170) {
		usage(stderr);
		return 2;
	}
	struct key *keys = NULL;
	size_t nkeys = 0;
	if (camera) {
		keys = xmalloc(sizeof *keys);
		nkeys = 1;
		if (parse_camera(camera, keys) < 0) {
			fprintf(stderr, "clipmapview: --camera: expected LAT,LON,ALT,HEADING,PITCH\n");
			free(keys);
			return 2;
		}
	} else if (flight) {
		int rc = read_flight(flight, &keys, &nkeys);
		if (rc < 0) {
			if (rc != -EINVAL)
				fprintf(stderr, "clipmapview: %s: %s\n", flight, strerror(-rc));
			else if (!nkeys)
				fprintf(stderr, "clipmapview: %s: no camera keys\n", flight);
			return 2;
		}
	}
	char err[256] = "";
	int status = 1;
	struct gl_context *ctx = NULL;
	struct gl_window *win = NULL;
	struct view_source *src = NULL;
	struct view *v = NULL;
	FILE *sf = NULL;
	unsigned char *pix = NULL;
	int rc;
	if (connect_to) {
		rc = open_net(connect_to, token_file, planet, &src, err);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			goto out;
		}
	} else {
		rc = view_source_local_create(planet, &(struct view_source_local_opts){ workers, 0 },
					      &src, err);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			status = 2;
			goto out;
		}
	}
	if (statsp && !(sf = fopen(statsp, "w"))) {
		fprintf(stderr, "clipmapview: %s: %s\n", statsp, strerror(errno));
		goto out;
	}
	if (window) {
		char title[128];
		snprintf(title, sizeof title, "clipmapview %s", src->planet.name);
		rc = gl_window_create(width, height, title, &win, err);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: --window: %s\n", err);
			goto out;
		}
		gl_window_framebuffer_size(win, &d.width, &d.height);
		d.budget_ms = budget;
		rc = view_create(gl_window_api(win), src, &d, &v, err);
		if (rc < 0) {
			fprintf(stderr, "clipmapview: %s\n", err);
			goto out;
		}
		double radius = src->planet.a * (1 - src->planet.f / 3);
		/* default: the whole planet from above, north up */
		struct view_camera home = { .lat = 20, .lon = 0, .alt = 2.2 * radius,
					    .heading = 0, .pitch = -90, .fov_y = fov,
					    .width = d.width, .height = d.height };
		if (keys) {
			home.lat = keys->v[0];
			home.lon = keys->v[1];
			home.alt = keys->v[2];
			home.heading = keys->v[3];
			home.pitch = keys->v[4];
		}
		struct window_opts wo = { title, width, height, exit_after, screenshot, sf };
		status = window_loop(win, v, &home, radius, &wo);
		goto out;
	}
	rc = gl_context_create(backend, &ctx, err);
	if (rc < 0) {
		fprintf(stderr, "clipmapview: no OpenGL context: %s\n", err);
		goto out;
	}
	d.width = width;
	d.height = height;
	/* --wait-complete pictures wait for every level; real time keeps its frames short. */
	d.budget_ms = wait_complete ? 0 : budget;
	rc = view_create(gl_context_api(ctx), src, &d, &v, err);
	if (rc < 0) {
		fprintf(stderr, "clipmapview: %s\n", err);
		goto out;
	}
	pix = xmalloc((size_t)width * height * 4);
	size_t nframes = nkeys == 1 ? 1 : (nkeys - 1) * (size_t)steps + 1;
	double t_start = mono_s();
	for (size_t f = 0; f < nframes; f++) {
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
		struct view_frame_stats st;
		if (wait_complete)
			rc = view_frame_complete(v, &cam, timeout, &st, NULL);
		else
			rc = view_frame(v, &cam, fps > 0 ? mono_s() - t_start : (double)f / 30.0, &st);
		if (rc == -ETIMEDOUT)
			fprintf(stderr, "clipmapview: frame %zu: not complete after %.0f s\n", f,
				timeout);
		else if (rc < 0) {
			fprintf(stderr, "clipmapview: frame %zu: %s\n", f, strerror(-rc));
			goto out;
		}
		if (sf)
			stats_line(sf, (int)f, &st);
		if (outp) {
			char path[4096];
			if (flight) {
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wformat-nonliteral"
				snprintf(path, sizeof path, outp, (int)f);
#pragma GCC diagnostic pop
			} else {
				snprintf(path, sizeof path, "%s", outp);
			}
			view_read_rgba(v, pix);
			rc = img_write(path, width, height, 4, IMG_U8, pix, err);
			if (rc < 0) {
				fprintf(stderr, "clipmapview: %s\n", err);
				goto out;
			}
		}
		/* Real time: the next frame is due at (f + 1) / fps; tiles come in meanwhile. */
		double left = t_start + (double)(f + 1) / fps - mono_s();
		if (!wait_complete && fps > 0 && f + 1 < nframes && left > 0) {
			rc = view_idle(v, left);
			if (rc < 0) {
				fprintf(stderr, "clipmapview: %s\n", strerror(-rc));
				goto out;
			}
		}
	}
	status = 0;
out:
	if (sf && fclose(sf) != 0 && status == 0) {
		fprintf(stderr, "clipmapview: %s: %s\n", statsp, strerror(errno));
		status = 1;
	}
	free(pix);
	view_destroy(v);
	gl_context_destroy(ctx);
	gl_window_destroy(win);
	view_source_destroy(src);
	free(keys);
	return status;
}
