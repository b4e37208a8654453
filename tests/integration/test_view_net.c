/* clipmapview --connect against a real clipmapd: the daemon runs as a process on a temporary
 * Unix socket with a temporary config and planets directory (the procedural planet: no data
 * files); clipmapview runs as a real process twice per camera, once over the daemon
 * (--connect SOCKET --planet procedural) and once with the engine in-process (--planet FILE),
 * both --wait-complete. The two pictures must be the same (decoded pixels, within a small
 * tolerance for the GL rasteriser). A flight without --wait-complete is paced in real time
 * and takes tiles between its frames. A socket nobody listens on is exit 1 with a message
 * naming it. Skipped when the daemon or the viewer was not built, or no GL context exists.
 */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/clock.h"
#include "common/img.h"
#include "support/daemon_env.h"
#include "support/picture.h"
#include "support/slow.h"

struct env {
	struct daemon_env d;
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	return e ? daemon_env_setup(&e->d, "test_view_net", "clipmapview") : -1;
}

static int teardown(void **state)
{
	struct env *e = *state;
	daemon_env_teardown(&e->d);
	free(e);
	return 0;
}


#define NEED_DAEMON(e)                 \
	do {                           \
		if ((e)->d.daemon <= 0)\
			skip();        \
	} while (0)

/* Runs clipmapview with the given arguments (NULL-terminated) plus the common ones. */
static int view(struct env *e, char *out, size_t n, const char *camera, const char *png,
		const char *a0, ...)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->d.bindir);
	char limit[32];
	snprintf(limit, sizeof limit, "%.0f", test_slow(60));
	char *argv[32] = { exe, "--camera", (char *)camera, "--size", "320x240", "--wait-complete",
			   "--timeout", limit, "-o", (char *)png };
	int argc = 10;
	va_list ap;
	va_start(ap, a0);
	for (const char *a = a0; a && argc < 31; a = va_arg(ap, const char *))
		argv[argc++] = (char *)a;
	va_end(ap);
	argv[argc] = NULL;
	return daemon_env_run(argv, out, n);
}

/* Mean absolute difference per channel, and the share of pixels differing by more than 8. */
static void compare(const char *a, const char *b, double *mad, double *share)
{
	void *pa, *pb;
	struct img_info ia, ib;
	char err[256];
	assert_int_equal(img_read(a, IMG_U8, &pa, &ia, err), 0);
	assert_int_equal(img_read(b, IMG_U8, &pb, &ib, err), 0);
	assert_int_equal(ia.width, 320);
	assert_int_equal(ia.height, 240);
	assert_int_equal(ib.width, ia.width);
	assert_int_equal(ib.height, ia.height);
	assert_int_equal(ib.channels, ia.channels);
	const unsigned char *x = pa, *y = pb;
	size_t np = (size_t)ia.width * ia.height, nc = (size_t)ia.channels, far = 0;
	double sum = 0;
	for (size_t i = 0; i < np; i++) {
		bool big = false;
		for (size_t c = 0; c < nc; c++) {
			int d = abs((int)x[i * nc + c] - (int)y[i * nc + c]);
			sum += d;
			big |= d > 8;
		}
		far += big;
	}
	*mad = sum / (double)(np * nc);
	*share = (double)far / (double)np;
	free(pa);
	free(pb);
}

static void connect_equals_local(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static const char *const cams[] = {
		"20,30,6000000,0,-90",	   /* the planet from orbit */
		"-9,-68,3000,30,-20",	   /* low over a range, oblique */
	};
	char planet[300];
	snprintf(planet, sizeof planet, "%s/procedural.ini", e->d.planets);
	for (size_t i = 0; i < sizeof cams / sizeof cams[0]; i++) {
		char out[8192], a[200], b[200];
		snprintf(a, sizeof a, "%s/net%zu.png", e->d.dir, i);
		snprintf(b, sizeof b, "%s/local%zu.png", e->d.dir, i);
		int rc = view(e, out, sizeof out, cams[i], b, "--planet", planet, NULL);
		if (rc == 1 && strstr(out, "no OpenGL context")) {
			fprintf(stderr, "no GL context here: %s", out);
			skip();
		}
		if (rc != 0)
			fprintf(stderr, "local: %s", out);
		assert_int_equal(rc, 0);
		rc = view(e, out, sizeof out, cams[i], a, "--connect", e->d.sock, "--planet",
			  "procedural", NULL);
		if (rc != 0)
			fprintf(stderr, "connect: %s", out);
		assert_int_equal(rc, 0);
		double mad, share;
		compare(a, b, &mad, &share);
		fprintf(stderr, "camera %s: mean |diff| %.3f, pixels off by > 8: %.4f%%\n", cams[i],
			mad, 100 * share);
		assert_true(picture_spread(a) > 40);
		assert_true(mad < 0.5);
		assert_true(share < 0.002);
	}
}

static void unknown_planet_is_exit_1(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[8192], a[200];
	snprintf(a, sizeof a, "%s/none.png", e->d.dir);
	int rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", e->d.sock, "--planet",
		      "atlantis", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "atlantis"));
	assert_int_equal(access(a, F_OK), -1);
}

static void bad_socket_is_exit_1_naming_it(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[8192], a[200], s[200];
	snprintf(a, sizeof a, "%s/none.png", e->d.dir);
	snprintf(s, sizeof s, "%s/nobody-here.sock", e->d.dir);
	int rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", s, "--planet",
		      "procedural", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, s));
	assert_non_null(strstr(out, "cannot connect"));
	assert_non_null(strstr(out, "clipmapd running"));
	assert_int_equal(access(a, F_OK), -1);
	/* a TCP port nobody listens on (port 1 on loopback) */
	rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", "127.0.0.1:1", "--planet",
		  "procedural", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "127.0.0.1:1"));
}

/* Without --wait-complete a flight is paced in real time (--fps) and the tiles that arrive
 * between frames are taken: 11 frames at 5 per second last at least 2 s, and the frames
 * show the terrain coming in (tiles received, levels drawn by the end). */
static void paced_flight_takes_tiles_between_frames(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char exe[600], fl[300], png[300], stats[300], out[8192];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->d.bindir);
	snprintf(fl, sizeof fl, "%s/hover.csv", e->d.dir);
	snprintf(png, sizeof png, "%s/paced_%%02d.png", e->d.dir);
	snprintf(stats, sizeof stats, "%s/paced.jsonl", e->d.dir);
	FILE *f = fopen(fl, "w");
	assert_non_null(f);
	fprintf(f, "lat,lon,alt,heading,pitch\n20,30,3000,0,-30\n20,30.01,3000,0,-30\n");
	assert_int_equal(fclose(f), 0);
	char *argv[] = { exe, "--connect", e->d.sock, "--planet", "procedural", "--flight", fl,
			 "--steps", "10", "--fps", "5", "--size", "160x120", "-o", png, "--stats",
			 stats, NULL };
	double t0 = clock_now_s();
	int rc = daemon_env_run(argv, out, sizeof out);
	double took = clock_now_s() - t0;
	if (rc != 0)
		fprintf(stderr, "%s\n", out);
	assert_int_equal(rc, 0);
	assert_true(took >= 1.9);
	f = fopen(stats, "r");
	assert_non_null(f);
	char line[1024];
	int frames = 0, tiles = 0, last_llast = -1;
	while (fgets(line, sizeof line, f)) {
		const char *p = strstr(line, "\"tiles_received\":");
		const char *q = strstr(line, "\"llast\":");
		assert_non_null(p);
		assert_non_null(q);
		tiles += atoi(p + strlen("\"tiles_received\":"));
		last_llast = atoi(q + strlen("\"llast\":"));
		frames++;
	}
	fclose(f);
	assert_int_equal(frames, 11);
	assert_true(tiles > 0);
	assert_true(last_llast >= 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(connect_equals_local),
		cmocka_unit_test(paced_flight_takes_tiles_between_frames),
		cmocka_unit_test(unknown_planet_is_exit_1),
		cmocka_unit_test(bad_socket_is_exit_1_naming_it),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
