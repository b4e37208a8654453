/* clipmapview's command line as a real process: -o for a flight is a pattern that takes the
 * frame number through one %d-style conversion (%d, %04d), %% being a literal percent; any
 * other conversion (%s, %n, two %d, ...) is refused before anything is loaded, exit 2 with a
 * message naming -o (it used to reach snprintf as the format and crash). A flight with a good
 * pattern writes one numbered PNG per frame; a single camera's -o is a plain path. Skipped
 * when the viewer is not built; the rendering test when there is no OpenGL (Mesa) here.
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

struct env {
	char bindir[512]; /* build/ */
	char view[700];
	char planet[700];
	char andes[700];
	char dir[64];
	char flight[128];
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	if (!e)
		return -1;
	ssize_t l = readlink("/proc/self/exe", e->bindir, sizeof e->bindir - 1);
	if (l <= 0)
		return -1;
	e->bindir[l] = '\0';
	*strrchr(e->bindir, '/') = '\0'; /* build/tests */
	*strrchr(e->bindir, '/') = '\0'; /* build */
	snprintf(e->view, sizeof e->view, "%s/clipmapview", e->bindir);
	snprintf(e->planet, sizeof e->planet, "%s/../conf/planets/procedural.ini", e->bindir);
	snprintf(e->andes, sizeof e->andes, "%s/../conf/demo/andes.csv", e->bindir);
	snprintf(e->dir, sizeof e->dir, "/tmp/test_view_cli.XXXXXX");
	if (!mkdtemp(e->dir))
		return -1;
	/* two keys, --steps 2: three frames */
	snprintf(e->flight, sizeof e->flight, "%s/flight.csv", e->dir);
	FILE *f = fopen(e->flight, "w");
	if (!f)
		return -1;
	fprintf(f, "# lat,lon,alt,heading,pitch\n-16,-70,300000,180,-30\n-20,-70,250000,180,-30\n");
	if (fclose(f) != 0)
		return -1;
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", e->dir);
	if (system(cmd) != 0)
		return -1;
	free(e);
	return 0;
}

static void need_viewer(const struct env *e)
{
	if (access(e->view, X_OK) != 0) {
		print_message("skipped: %s not built\n", e->view);
		skip();
	}
}

/* Whether the directory holds nothing but the flight file. */
static bool dir_untouched(const struct env *e)
{
	char cmd[160], out[256];
	snprintf(cmd, sizeof cmd, "ls -A '%s'", e->dir);
	char *argv[] = { "sh", "-c", cmd, NULL };
	return daemon_env_run(argv, out, sizeof out) == 0 && strcmp(out, "flight.csv\n") == 0;
}

static void test_pattern_refused(void **state)
{
	struct env *e = *state;
	need_viewer(e);
	static const char *const bad[] = {
		"x%s.png", "x%d%d.png", "x%n.png", "x%ld.png", "x%*d.png", "x%.png", "x%",
		"x%%%s.png", "x%1234d.png",
	};
	for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
		char pat[200], out[4096];
		snprintf(pat, sizeof pat, "%s/%s", e->dir, bad[i]);
		char *argv[] = { e->view, "--planet", e->planet, "--flight", e->andes, "--size",
				 "64x48", "-o", pat, NULL };
		int rc = daemon_env_run(argv, out, sizeof out);
		if (rc != 2)
			print_message("-o %s: exit %d:\n%s\n", bad[i], rc, out);
		assert_int_equal(rc, 2);
		assert_non_null(strstr(out, "-o"));
		assert_true(dir_untouched(e));
	}
}

/* Whether path is a 64×48 PNG. */
static bool picture_at(const char *path)
{
	void *p = NULL;
	struct img_info in;
	char err[256];
	if (img_read(path, IMG_U8, &p, &in, err) != 0) {
		print_message("%s\n", err);
		return false;
	}
	free(p);
	return in.width == 64 && in.height == 48;
}

static void test_pattern_frames(void **state)
{
	struct env *e = *state;
	need_viewer(e);
	char pat[200], out[4096], path[256];
	snprintf(pat, sizeof pat, "%s/f%%%%_%%03d.png", e->dir); /* f%%_%03d.png */
	char *argv[] = { e->view, "--planet", e->planet, "--flight", e->flight, "--steps", "2",
			 "--size", "64x48", "--fps", "0", "-o", pat, NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc == 1 && strstr(out, "no OpenGL context")) {
		print_message("skipped: %s", out);
		skip();
	}
	if (rc != 0)
		print_message("clipmapview: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	for (int f = 0; f < 3; f++) {
		snprintf(path, sizeof path, "%s/f%%_%03d.png", e->dir, f);
		assert_true(picture_at(path));
		unlink(path);
	}
	snprintf(path, sizeof path, "%s/f%%_003.png", e->dir);
	assert_int_not_equal(access(path, F_OK), 0);

	/* one camera: -o is the path itself, percent signs and all */
	snprintf(pat, sizeof pat, "%s/c%%s%%d.png", e->dir);
	char *a2[] = { e->view, "--planet", e->planet, "--camera", "-16,-70,300000,180,-30",
		       "--size", "64x48", "--fps", "0", "-o", pat, NULL };
	rc = daemon_env_run(a2, out, sizeof out);
	if (rc != 0)
		print_message("clipmapview --camera: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	assert_true(picture_at(pat));
	unlink(pat);
}

/* --planet takes a name too, found as clipmapctl finds it (conf/planets/NAME.ini from the
 * checkout here); an unknown name is exit 2 naming it. */
static void test_planet_by_name(void **state)
{
	struct env *e = *state;
	need_viewer(e);
	char pic[200], out[4096];
	snprintf(pic, sizeof pic, "%s/byname.png", e->dir);
	char *argv[] = { e->view, "--planet", "procedural", "--camera", "0,0,5000000,0,-90",
			 "--size", "64x48", "--wait-complete", "-o", pic, NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc == 1 && strstr(out, "no OpenGL context"))
		skip();
	if (rc != 0)
		print_message("clipmapview --planet procedural: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	assert_true(picture_at(pic));
	unlink(pic);
	char *bad[] = { e->view, "--planet", "vulcan", "--camera", "0,0,5000000,0,-90", "-o", pic,
			NULL };
	rc = daemon_env_run(bad, out, sizeof out);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "vulcan"));
	assert_int_not_equal(access(pic, F_OK), 0);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_pattern_refused),
		cmocka_unit_test(test_pattern_frames),
		cmocka_unit_test(test_planet_by_name),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
