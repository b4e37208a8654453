/* clipmapview --window as a real process on a virtual X display (xvfb-run -a): 60 frames of
 * the procedural planet from the default orbit camera, then --screenshot. It must exit 0 and
 * the picture must show the planet: many pixels away from the background (the corner pixel,
 * space), the centre among them. Also: the window-only options are usage errors (exit 2)
 * without --window, and --window refuses --flight. Skipped when xvfb-run or the viewer is
 * missing.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/img.h"
#include "support/daemon_env.h"

struct env {
	struct daemon_env d; /* build/ and a temporary directory; no daemon */
	char view[700];
	char planet[700];
	char shot[128];
};

/* daemon_env_run, with TSan told to spare the viewer's X libraries. */
static int run_capture(char *const argv[], char *out, size_t n)
{
#ifdef __SANITIZE_THREAD__
	/* libX11/libXi (not built with TSan) take and release their display lock in ways TSan
	 * reports as mutex misuse; only the viewer under X gets this. This process read its own
	 * options at start, so only the child sees the change. */
	const char *old = getenv("TSAN_OPTIONS");
	char *saved = old ? strdup(old) : NULL;
	char opts[1024];
	snprintf(opts, sizeof opts, "%s%sreport_mutex_bugs=0", old ? old : "",
		 old && *old ? ":" : "");
	setenv("TSAN_OPTIONS", opts, 1);
	int rc = daemon_env_run(argv, out, n);
	if (saved)
		setenv("TSAN_OPTIONS", saved, 1);
	else
		unsetenv("TSAN_OPTIONS");
	free(saved);
	return rc;
#else
	return daemon_env_run(argv, out, n);
#endif
}

static bool in_path(const char *prog)
{
	const char *path = getenv("PATH");
	if (!path)
		path = "/usr/bin:/bin";
	char buf[1024];
	while (*path) {
		size_t n = strcspn(path, ":");
		snprintf(buf, sizeof buf, "%.*s/%s", (int)n, path, prog);
		if (access(buf, X_OK) == 0)
			return true;
		path += n;
		if (*path == ':')
			path++;
	}
	return false;
}

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e || daemon_env_init(&e->d, "test_view_window"))
		return -1;
	snprintf(e->view, sizeof e->view, "%s/clipmapview", e->d.bindir);
	snprintf(e->planet, sizeof e->planet, "%s/conf/planets/procedural.ini", e->d.root);
	snprintf(e->shot, sizeof e->shot, "%s/shot.png", e->d.dir);
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (e)
		daemon_env_fini(&e->d);
	free(e);
	return 0;
}

static void test_window_screenshot(void **state)
{
	struct env *e = *state;
	if (access(e->view, X_OK) != 0) {
		print_message("skipped: %s not built\n", e->view);
		skip();
	}
	if (!in_path("xvfb-run")) {
		print_message("skipped: xvfb-run not installed (apt-get install xvfb xauth)\n");
		skip();
	}
	char out[8192];
	char *argv[] = { "timeout", "120", "xvfb-run", "-a", "-s", "-screen 0 1024x768x24",
			 e->view, "--window", "--planet", e->planet, "--size", "640x360",
			 "--exit-after", "60", "--screenshot", e->shot, NULL };
	int rc = run_capture(argv, out, sizeof out);
	if (rc != 0)
		print_message("clipmapview --window: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	void *p = NULL;
	struct img_info in;
	char err[256];
	assert_int_equal(img_read(e->shot, IMG_U8, &p, &in, err), 0);
	assert_int_equal(in.width, 640);
	assert_int_equal(in.height, 360);
	assert_true(in.channels >= 3);
	const unsigned char *px = p;
	int ch = in.channels;
	const unsigned char *bg = px; /* the top-left corner: space */
	size_t differ = 0, n = (size_t)in.width * in.height;
	for (size_t i = 0; i < n; i++) {
		const unsigned char *q = px + i * ch;
		int d = abs(q[0] - bg[0]) + abs(q[1] - bg[1]) + abs(q[2] - bg[2]);
		differ += d > 30;
	}
	const unsigned char *c = px + ((size_t)(in.height / 2) * in.width + in.width / 2) * ch;
	int dc = abs(c[0] - bg[0]) + abs(c[1] - bg[1]) + abs(c[2] - bg[2]);
	print_message("planet covers %.1f %% of the screenshot\n", 100.0 * differ / n);
	assert_true(dc > 30);		  /* the planet is under the camera */
	assert_true(differ > n / 20);	  /* a disc, not a few stray pixels */
	assert_true(differ < n * 19 / 20); /* and space around it */
	free(p);
}

static void test_window_usage(void **state)
{
	struct env *e = *state;
	if (access(e->view, X_OK) != 0) {
		print_message("skipped: %s not built\n", e->view);
		skip();
	}
	char out[4096];
	char *a1[] = { e->view, "--planet", e->planet, "--camera", "0,0,1000,0,0", "--exit-after",
		       "5", NULL };
	assert_int_equal(run_capture(a1, out, sizeof out), 2);
	assert_non_null(strstr(out, "--window"));
	char *a2[] = { e->view, "--window", "--planet", e->planet, "--flight", "x.csv", NULL };
	assert_int_equal(run_capture(a2, out, sizeof out), 2);
	char *a3[] = { e->view, "--window", "--planet", e->planet, "--exit-after", "0", NULL };
	assert_int_equal(run_capture(a3, out, sizeof out), 2);
	char *a4[] = { e->view, "--help", NULL };
	assert_int_equal(run_capture(a4, out, sizeof out), 0);
	assert_non_null(strstr(out, "--window"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_window_usage),
		cmocka_unit_test(test_window_screenshot),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
