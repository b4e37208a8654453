/* clipmapview switching its colour layer while it runs (the L key; scripted with
 * --switch-layer-at FRAME:NAME), as real processes: a small planet with two colour layers
 * ("color": blue–green–white, "warm": red–orange–cream, over the same heights) served by a
 * real clipmapd on a temporary Unix socket, and evaluated in-process. A flight holding one
 * camera switches color → warm → color; every frame before a switch must match the picture
 * of the layer drawn from the start (--color-layer), every frame after it (once complete) the
 * other layer's: so the colour clipmap refilled from the new layer, and switching back made
 * the daemon send the first layer's tiles again. Paced in real time, the frames right after
 * the switch are incomplete and the last one matches; so does a window's (xvfb-run) last
 * frame. A name the planet has no colour layer
 * of is exit 2 with a message listing its colour layers. Skipped when the daemon or the
 * viewer was not built, or no GL context exists.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/img.h"
#include "support/daemon_env.h"
#include "support/picture.h"
#include "support/slow.h"

static const char planet_text[] =
	"[planet]\nname = two\nbody = sphere\nradius = 1000000\ntile_size = 64\nmax_level = 8\n"
	"[node base]\ntype = noise\nseed = 5\noctaves = 4\nwavelength = 300000\namplitude = 500\n"
	"[node tint]\ntype = ramp\ninput = base\n"
	"stops = -500 0 0 255, 0 0 128 0, 500 255 255 255\n"
	"[node warm]\ntype = ramp\ninput = base\n"
	"stops = -500 120 0 0, 0 220 120 0, 500 255 240 200\n"
	"[node shade]\ntype = normal\ninput = base\nexaggeration = 30\n"
	"[layer height]\nnode = base\nformat = f32\n"
	"[layer color]\nnode = tint\nformat = rgba8\n"
	"[layer warm]\nnode = warm\nformat = rgba8\n"
	"[layer normal]\nnode = shade\nformat = rg8\n";

#define CAMERA "-10,20,400000,0,-60"

struct env {
	struct daemon_env d;
	char planet[128]; /* the planet file, for the in-process viewer */
	char flight[160]; /* two keys at CAMERA */
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_view_layers"))
		return -1;
	if (!daemon_env_built(&e->d, "clipmapd") || !daemon_env_built(&e->d, "clipmapview"))
		return 0; /* the tests skip */
	if (daemon_env_planet_text(&e->d, "two.ini", planet_text, e->planet))
		return -1;
	snprintf(e->flight, sizeof e->flight, "%s/flight.csv", e->d.dir);
	FILE *f = fopen(e->flight, "w");
	if (!f || fprintf(f, "%s\n%s\n", CAMERA, CAMERA) < 0 || fclose(f) != 0)
		return -1;
	char err[256];
	if (daemon_env_start(&e->d, NULL, err)) {
		fprintf(stderr, "daemon_env: %s\n", err);
		return -1;
	}
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	daemon_env_teardown(&e->d);
	free(e);
	return 0;
}

/* Runs clipmapview over the daemon (net) or in-process with the common arguments and the
 * given ones (NULL-terminated); skips the test when there is no GL context. */
static int view(struct env *e, bool net, char *out, size_t n, const char *a0, ...)
{
	if (e->d.daemon <= 0)
		skip();
	char exe[600], limit[32];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->d.bindir);
	snprintf(limit, sizeof limit, "%.0f", test_slow(60));
	char *argv[40] = { exe, "--size", "160x120", "--timeout", limit };
	int argc = 5;
	if (net) {
		argv[argc++] = "--connect";
		argv[argc++] = e->d.sock;
		argv[argc++] = "--planet";
		argv[argc++] = "two";
	} else {
		argv[argc++] = "--planet";
		argv[argc++] = e->planet;
	}
	va_list ap;
	va_start(ap, a0);
	for (const char *a = a0; a && argc < 39; a = va_arg(ap, const char *))
		argv[argc++] = (char *)a;
	va_end(ap);
	argv[argc] = NULL;
	int rc = daemon_env_run(argv, out, n);
	if (rc == 1 && strstr(out, "no OpenGL context")) {
		fprintf(stderr, "no GL context here: %s", out);
		skip();
	}
	return rc;
}

/* Mean absolute difference per channel of two pictures of the same size. */
static double mad(const char *a, const char *b)
{
	void *pa, *pb;
	struct img_info ia, ib;
	char err[256];
	assert_int_equal(img_read(a, IMG_U8, &pa, &ia, err), 0);
	assert_int_equal(img_read(b, IMG_U8, &pb, &ib, err), 0);
	assert_int_equal(ia.width, ib.width);
	assert_int_equal(ia.height, ib.height);
	assert_int_equal(ia.channels, ib.channels);
	size_t n = (size_t)ia.width * ia.height * ia.channels;
	double sum = 0;
	for (size_t i = 0; i < n; i++)
		sum += abs((int)((unsigned char *)pa)[i] - (int)((unsigned char *)pb)[i]);
	free(pa);
	free(pb);
	return sum / (double)n;
}

/* The references: the camera's picture with each layer drawn from the start. */
static void references(struct env *e, bool net, char plain[200], char warm[200])
{
	char out[4096];
	snprintf(plain, 200, "%s/%s_plain.png", e->d.dir, net ? "net" : "local");
	snprintf(warm, 200, "%s/%s_warm.png", e->d.dir, net ? "net" : "local");
	int rc = view(e, net, out, sizeof out, "--camera", CAMERA, "--wait-complete", "-o", plain,
		      NULL);
	if (rc != 0)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	rc = view(e, net, out, sizeof out, "--camera", CAMERA, "--wait-complete", "--color-layer",
		  "warm", "-o", warm, NULL);
	if (rc != 0)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	assert_true(picture_spread(plain) > 40);
	/* the two layers are told apart by the pictures: the test can fail */
	double d = mad(plain, warm);
	fprintf(stderr, "%s: plain vs warm: mean |diff| %.1f\n", net ? "net" : "local", d);
	assert_true(d > 20);
}

/* The color_layer of each line of a --stats file into names[] (up to n). Returns the count. */
static int stats_layers(const char *path, char names[][16], int n)
{
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	char line[2048];
	int k = 0;
	while (k < n && fgets(line, sizeof line, f)) {
		const char *p = strstr(line, "\"color_layer\":\"");
		assert_non_null(p);
		p += strlen("\"color_layer\":\"");
		size_t l = strcspn(p, "\"");
		snprintf(names[k++], 16, "%.*s", (int)l, p);
	}
	fclose(f);
	return k;
}

/* Four complete frames of one camera: color, color, warm (switched at 2), color (at 3). */
static void switch_complete(struct env *e, bool net)
{
	char plain[200], warm[200], pat[200], stats[200], out[4096];
	references(e, net, plain, warm);
	const char *tag = net ? "net" : "local";
	snprintf(pat, sizeof pat, "%s/%s_sw_%%d.png", e->d.dir, tag);
	snprintf(stats, sizeof stats, "%s/%s_sw.json", e->d.dir, tag);
	int rc = view(e, net, out, sizeof out, "--flight", e->flight, "--steps", "3",
		      "--wait-complete", "--switch-layer-at", "2:warm", "--switch-layer-at",
		      "3:color", "--stats", stats, "-o", pat, NULL);
	if (rc != 0)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	static const int is_warm[4] = { 0, 0, 1, 0 };
	char names[8][16];
	assert_int_equal(stats_layers(stats, names, 8), 4);
	for (int f = 0; f < 4; f++) {
		char path[220];
		snprintf(path, sizeof path, "%s/%s_sw_%d.png", e->d.dir, tag, f);
		double to_plain = mad(path, plain), to_warm = mad(path, warm);
		fprintf(stderr, "%s frame %d (%s): |diff| to color %.3f, to warm %.3f\n", tag, f,
			names[f], to_plain, to_warm);
		assert_string_equal(names[f], is_warm[f] ? "warm" : "color");
		assert_true((is_warm[f] ? to_warm : to_plain) < 0.5);
	}
}

static void switch_local(void **state) { switch_complete(*state, false); }
static void switch_net(void **state) { switch_complete(*state, true); }

/* Real time over the daemon (--fps 30, no waiting): the switch at frame 5 leaves the frames
 * after it incomplete until the new layer's tiles are in; the last frame shows it whole. */
static void switch_real_time(void **state)
{
	struct env *e = *state;
	char plain[200], warm[200], pat[200], stats[200], out[4096];
	references(e, true, plain, warm);
	snprintf(pat, sizeof pat, "%s/rt_%%d.png", e->d.dir);
	snprintf(stats, sizeof stats, "%s/rt.json", e->d.dir);
	/* 3 s of frames: the tiles of a 160×120 view of this planet arrive well within that */
	int rc = view(e, true, out, sizeof out, "--flight", e->flight, "--steps", "90", "--fps",
		      "30", "--switch-layer-at", "5:warm", "--stats", stats, "-o", pat, NULL);
	if (rc != 0)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	char names[100][16];
	assert_int_equal(stats_layers(stats, names, 100), 91);
	for (int f = 0; f < 91; f++)
		assert_string_equal(names[f], f < 5 ? "color" : "warm");
	FILE *sf = fopen(stats, "r");
	assert_non_null(sf);
	char line[2048];
	bool complete[91];
	for (int f = 0; f < 91 && fgets(line, sizeof line, sf); f++)
		complete[f] = strstr(line, "\"complete\":true") != NULL;
	fclose(sf);
	assert_false(complete[5]); /* the new layer's tiles cannot be in at its first frame */
	assert_true(complete[90]);
	char last[220];
	snprintf(last, sizeof last, "%s/rt_90.png", e->d.dir);
	double d = mad(last, warm);
	fprintf(stderr, "real time: last frame |diff| to warm %.3f\n", d);
	assert_true(d < 0.5);
	/* a frame before the switch, once complete, is the first layer's */
	if (complete[4]) {
		snprintf(last, sizeof last, "%s/rt_4.png", e->d.dir);
		assert_true(mad(last, plain) < 0.5);
	}
}

/* The window (on a virtual X display, xvfb-run): the same switch scripted at frame 20 of a
 * real-time window (what L does); the stats name the layer per frame and the screenshot of
 * the last frame shows the new layer whole. Skipped without xvfb-run. */
static void switch_window(void **state)
{
	struct env *e = *state;
	if (e->d.daemon <= 0)
		skip();
	if (system("command -v xvfb-run >/dev/null 2>&1") != 0) {
		print_message("skipped: xvfb-run not installed (apt-get install xvfb xauth)\n");
		skip();
	}
	char plain[200], warm[200], shot[200], stats[200], out[8192], exe[600], limit[32];
	references(e, false, plain, warm);
	snprintf(exe, sizeof exe, "%s/clipmapview", e->d.bindir);
	snprintf(shot, sizeof shot, "%s/window.png", e->d.dir);
	snprintf(stats, sizeof stats, "%s/window.json", e->d.dir);
	snprintf(limit, sizeof limit, "%.0f", test_slow(120));
	/* 240 frames at 60 Hz: the new layer's tiles are in well before the end */
	char *argv[] = { "timeout", limit, "xvfb-run", "-a", "-s", "-screen 0 1024x768x24", exe,
			 "--window", "--planet", e->planet, "--camera", CAMERA, "--size", "160x120",
			 "--exit-after", "240", "--switch-layer-at", "20:warm", "--stats", stats,
			 "--screenshot", shot, NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc != 0)
		fprintf(stderr, "clipmapview --window: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	char names[300][16];
	assert_int_equal(stats_layers(stats, names, 300), 240);
	for (int f = 0; f < 240; f++)
		assert_string_equal(names[f], f < 20 ? "color" : "warm");
	double d = mad(shot, warm);
	fprintf(stderr, "window: last frame |diff| to warm %.3f, to color %.3f\n", d,
		mad(shot, plain));
	assert_true(d < 1.0);
}

/* A name the planet has no colour layer of (also a height layer's name): exit 2, naming it
 * and the planet's colour layers, before any picture is written. */
static void bad_name(void **state)
{
	struct env *e = *state;
	static const char *const bad[] = { "2:nope", "0:height" };
	for (int net = 0; net < 2; net++)
		for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
			char out[4096], png[200];
			snprintf(png, sizeof png, "%s/bad.png", e->d.dir);
			int rc = view(e, net, out, sizeof out, "--camera", CAMERA, "--wait-complete",
				      "--switch-layer-at", bad[i], "-o", png, NULL);
			if (rc != 2)
				fprintf(stderr, "exit %d: %s", rc, out);
			assert_int_equal(rc, 2);
			assert_non_null(strstr(out, "--switch-layer-at"));
			assert_non_null(strstr(out, strchr(bad[i], ':') + 1));
			assert_non_null(strstr(out, "its colour layers: color, warm"));
			assert_int_equal(access(png, F_OK), -1);
		}
	/* malformed: no frame, no name, a negative frame */
	static const char *const malformed[] = { "warm", ":warm", "3:", "-1:warm" };
	for (size_t i = 0; i < sizeof malformed / sizeof malformed[0]; i++) {
		char out[4096];
		int rc = view(e, false, out, sizeof out, "--camera", CAMERA, "-o", "/tmp/x.png",
			      "--switch-layer-at", malformed[i], NULL);
		if (rc != 2)
			fprintf(stderr, "%s: exit %d: %s", malformed[i], rc, out);
		assert_int_equal(rc, 2);
		assert_non_null(strstr(out, "--switch-layer-at"));
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(switch_local),
		cmocka_unit_test(switch_net),
		cmocka_unit_test(switch_real_time),
		cmocka_unit_test(switch_window),
		cmocka_unit_test(bad_name),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
