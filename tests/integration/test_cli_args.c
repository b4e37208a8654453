/* The three programs' command lines as real processes: a table of bad option values (not a
 * number, out of range, malformed places and boxes, a west > east box, a missing -o, an output
 * directory that does not exist) each gives exit status 2 — never a crash, never 0 — and a
 * message naming the option; --version prints the program's name and a version; every
 * clipmapctl command has its own --help (exit 0, no planet lookup); clipmapview's
 * --wait-complete running out of --timeout writes the picture and exits 3. Skipped when the
 * programs are not built; the timeout test when there is no OpenGL (Mesa) here.
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

#include "support/daemon_env.h"

struct env {
	char bindir[512];
	char prog[3][600]; /* clipmapd, clipmapctl, clipmapview */
	char planet[600];
	char conf[600];
};

enum { D, CTL, VIEW };
static const char *const names[] = { "clipmapd", "clipmapctl", "clipmapview" };

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	char bin[512]; /* a local copy: snprintf from *e into *e may overlap, says GCC */
	if (!e || daemon_env_bindir(bin, sizeof bin))
		return -1;
	snprintf(e->bindir, sizeof e->bindir, "%s", bin);
	for (int i = 0; i < 3; i++)
		snprintf(e->prog[i], sizeof e->prog[i], "%s/%s", bin, names[i]);
	snprintf(e->planet, sizeof e->planet, "%s/../conf/planets/procedural.ini", bin);
	snprintf(e->conf, sizeof e->conf, "%s/../conf/clipmapd.conf", bin);
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	free(*state);
	return 0;
}

static void need(const struct env *e, int prog)
{
	if (access(e->prog[prog], X_OK) != 0) {
		print_message("skipped: %s not built\n", e->prog[prog]);
		skip();
	}
}

/* Runs prog with up to 15 arguments (NULL-terminated; "@P" is the procedural planet file),
 * output into out. Returns the exit status. */
static int run(const struct env *e, int prog, const char *const *args, char *out, size_t n)
{
	char *argv[20];
	int k = 0;
	argv[k++] = (char *)e->prog[prog];
	for (; *args && k < 19; args++)
		argv[k++] = (char *)(strcmp(*args, "@P") == 0 ? e->planet : *args);
	argv[k] = NULL;
	return daemon_env_run(argv, out, n);
}

struct bad {
	int prog;
	const char *opt;       /* the message must name it */
	const char *args[12]; /* NULL-terminated */
};

#define CAM "--camera", "0,0,100000,0,-90"
static const struct bad bads[] = {
	{ D, "--config", { "--config", NULL } },
	{ D, "--config", { "--config=", NULL } },
	{ D, "--bogus", { "--bogus", NULL } },
	{ VIEW, "--steps", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--steps", "abc", NULL } },
	{ VIEW, "--steps", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--steps", "0", NULL } },
	{ VIEW, "--fov", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--fov", "abc", NULL } },
	{ VIEW, "--fov", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--fov", "200", NULL } },
	{ VIEW, "--timeout", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--timeout", "abc", NULL } },
	{ VIEW, "--timeout", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--timeout", "", NULL } },
	{ VIEW, "--workers", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--workers", "abc", NULL } },
	{ VIEW, "--workers", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--workers", "-3", NULL } },
	{ VIEW, "--size", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--size", "640x", NULL } },
	{ VIEW, "--size", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--size", "1e9x1", NULL } },
	{ VIEW, "--fps", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--fps", "nan", NULL } },
	{ VIEW, "--budget", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--budget", "-1", NULL } },
	{ VIEW, "--sun", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--sun", "315", NULL } },
	{ VIEW, "--sun", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--sun", "315,x", NULL } },
	{ VIEW, "--rings", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--rings", "7,1", NULL } },
	{ VIEW, "--exaggerate", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--exaggerate", "0",
				  NULL } },
	{ VIEW, "--haze", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--haze", "1x", NULL } },
	{ VIEW, "--exit-after", { "--planet", "@P", "--window", "--exit-after", "0", NULL } },
	{ VIEW, "--backend", { "--planet", "@P", CAM, "-o", "/tmp/x.png", "--backend", "vk", NULL } },
	{ VIEW, "--camera", { "--planet", "@P", "--camera", "95,0,1000,0,-30", "-o", "/tmp/x.png",
			      NULL } },
	{ VIEW, "--camera", { "--planet", "@P", "--camera", "1,2,3", "-o", "/tmp/x.png", NULL } },
	{ VIEW, "--camera", { "--planet", "@P", "--camera", "", "-o", "/tmp/x.png", NULL } },
	{ VIEW, "-o", { "--planet", "@P", CAM, NULL } },
	{ VIEW, "-o", { "--planet", "@P", CAM, "-o", "/nonexistent-dir/x.png", NULL } },
	{ VIEW, "-o", { "--planet", "@P", "--flight", "/dev/null", "-o", "/nonexistent-dir/%04d.png",
			NULL } },
	{ VIEW, "-o", { "--planet", "@P", "--flight", "/dev/null", "-o", "x%s.png", NULL } },
	{ VIEW, "--planet", { CAM, "-o", "/tmp/x.png", NULL } },
	{ VIEW, "--flight", { "--planet", "@P", "--flight", "/nonexistent.csv", "-o", "/tmp/%d.png",
			      NULL } },
	{ CTL, "--timeout", { "--timeout", "abc", "status", NULL } },
	{ CTL, "--timeout", { "status", "--timeout", "0", NULL } },
	{ CTL, "--bbox", { "prefetch", "earth", "--bbox", "88,27,86,28", "--levels", "1-2", NULL } },
	{ CTL, "--bbox", { "prefetch", "earth", "--bbox", "1,2,3", "--levels", "1-2", NULL } },
	{ CTL, "--bbox", { "prefetch", "earth", "--bbox", "0,10,20,5", "--levels", "1-2", NULL } },
	{ CTL, "--levels", { "prefetch", "earth", "--bbox", "0,0,1,1", "--levels", "5-2", NULL } },
	{ CTL, "--width", { "prefetch", "earth", "--path", "0,0:1,1", "--width", "-1", "--levels",
			    "1-2", NULL } },
	{ CTL, "--width", { "prefetch", "earth", "--path", "0,0:1,1", "--width", "200000", "--levels",
			    "1-2", NULL } },
	{ CTL, "--path", { "prefetch", "earth", "--path", "0,0", "--width", "1", "--levels", "1-2",
			   NULL } },
	{ CTL, "--near", { "cache", "ls", "earth", "--near", "91,0", NULL } },
	{ CTL, "--radius", { "cache", "ls", "earth", "--near", "1,0", "--radius", "x", NULL } },
	{ CTL, "--limit", { "cache", "ls", "earth", "--limit", "-1", NULL } },
	{ CTL, "--level", { "render", "@P", "color", "--level", "abc", "--world", "-o", "/tmp/x.png",
			    NULL } },
	{ CTL, "--at", { "render", "@P", "color", "--level", "3", "--at", "95,0", "-o", "/tmp/x.png",
			 NULL } },
	{ CTL, "--workers", { "render", "@P", "color", "--level", "3", "--world", "--workers", "abc",
			      "-o", "/tmp/x.png", NULL } },
	{ CTL, "--tiles", { "render", "@P", "color", "--level", "3", "--at", "0,0", "--tiles", "0",
			    "-o", "/tmp/x.png", NULL } },
	{ CTL, "--cache-mb", { "render", "@P", "color", "--level", "3", "--world", "--cache-mb", "1x",
			       "-o", "/tmp/x.png", NULL } },
	{ CTL, "-o", { "render", "@P", "color", "--level", "3", "--world", NULL } },
	{ CTL, "LX", { "tile", "earth", "height", "x", "0", "0", "0", "-o", "/tmp/x.png", NULL } },
	{ CTL, "--band", { "import", "/dev/null", "-o", "/tmp/x.tif", "--band", "0", NULL } },
	{ CTL, "--bounds", { "import", "/dev/null", "-o", "/tmp/x.tif", "--bounds", "5,0,1,1", NULL } },
	{ CTL, "--repair-rows", { "import", "/dev/null", "-o", "/tmp/x.tif", "--repair-rows", "0",
				  NULL } },
	{ CTL, "--repair-rows", { "import", "/dev/null", "-o", "/tmp/x.tif", "--repair-rows",
				  "500,x", NULL } },
	{ CTL, "--bogus", { "status", "--bogus", NULL } },
	{ CTL, "frobnicate", { "frobnicate", NULL } },
};

static void test_bad_values(void **state)
{
	struct env *e = *state;
	need(e, D);
	need(e, CTL);
	need(e, VIEW);
	int failed = 0;
	for (size_t i = 0; i < sizeof bads / sizeof bads[0]; i++) {
		const struct bad *b = &bads[i];
		char out[16384];
		int rc = run(e, b->prog, b->args, out, sizeof out);
		/* the message names the option in the first lines, before any usage text */
		char *usage = strstr(out, "usage:");
		if (usage && usage != out)
			*usage = '\0';
		bool named = strstr(out, b->opt) != NULL;
		if (rc != 2 || !named) {
			print_message("%s", names[b->prog]);
			for (const char *const *a = b->args; *a; a++)
				print_message(" '%s'", *a);
			print_message(": exit %d (want 2), %s:\n%s\n", rc,
				      named ? "names the option" : "does NOT name the option", out);
			failed++;
		}
	}
	assert_int_equal(failed, 0);
}

/* The version the build was given (make passes its VERSION as CLIPMAP_BUILD_VERSION: `make
 * VERSION=… check` too), else `git describe --always --dirty` of the checkout the tests run
 * in, or "" outside one. */
static void checkout_version(char *out, size_t n)
{
	const char *given = getenv("CLIPMAP_BUILD_VERSION");
	if (given && *given) {
		snprintf(out, n, "%s", given);
		return;
	}
	out[0] = '\0';
	FILE *f = popen("git describe --always --dirty 2>/dev/null", "r");
	if (!f)
		return;
	if (!fgets(out, (int)n, f))
		out[0] = '\0';
	pclose(f);
	out[strcspn(out, "\n")] = '\0';
}

/* Each program prints its name and version; in a git checkout, the checkout's own (the
 * build's version.txt once stayed at an old commit: make never remade it). */
static void test_version(void **state)
{
	struct env *e = *state;
	char want[128];
	checkout_version(want, sizeof want);
	for (int p = 0; p < 3; p++) {
		need(e, p);
		const char *flags[] = { "--version", "-V" };
		for (int f = 0; f < 2; f++) {
			char out[512];
			const char *args[] = { flags[f], NULL };
			assert_int_equal(run(e, p, args, out, sizeof out), 0);
			size_t l = strlen(names[p]);
			assert_memory_equal(out, names[p], l);
			assert_int_equal(out[l], ' ');
			assert_true(strlen(out) > l + 2); /* a version, then a newline */
			assert_non_null(strchr(out, '\n'));
			size_t wl = strlen(want);
			if (wl && (strncmp(out + l + 1, want, wl) != 0 || out[l + 1 + wl] != '\n'))
				fail_msg("%s prints \"%s\", the checkout is %s: rebuild (make)",
					 names[p], out, want);
		}
	}
}

/* Every clipmapctl command answers --help with its own usage: exit 0, its name, no planet
 * lookup, no connection. */
static void test_ctl_command_help(void **state)
{
	struct env *e = *state;
	need(e, CTL);
	static const char *const cmds[] = { "status", "tile", "cache", "prefetch", "render",
					    "graph",  "layers", "import" };
	for (size_t i = 0; i < sizeof cmds / sizeof cmds[0]; i++) {
		char out[4096], want[64];
		const char *args[] = { cmds[i], "--help", NULL };
		int rc = run(e, CTL, args, out, sizeof out);
		if (rc != 0 || strstr(out, "not found"))
			print_message("clipmapctl %s --help: exit %d:\n%s\n", cmds[i], rc, out);
		assert_int_equal(rc, 0);
		assert_null(strstr(out, "not found"));
		snprintf(want, sizeof want, "clipmapctl %s ", cmds[i]);
		assert_non_null(strstr(out, want));
		/* its own lines only: graph's help does not list render */
		if (strcmp(cmds[i], "render") != 0)
			assert_null(strstr(out, "clipmapctl render "));
	}
	char out[8192];
	const char *ls[] = { "cache", "ls", "--help", NULL };
	assert_int_equal(run(e, CTL, ls, out, sizeof out), 0);
	assert_non_null(strstr(out, "clipmapctl cache ls"));
	const char *help[] = { "help", "graph", NULL };
	assert_int_equal(run(e, CTL, help, out, sizeof out), 0);
	assert_non_null(strstr(out, "clipmapctl graph PLANET"));
}

/* clipmapctl starts fast: the program the operator runs loads neither OpenImageIO nor GDAL
 * (some 260 shared libraries, ~0.2-2 s and 130 MB before main); what needs them (tile,
 * render, graph, layers, import) runs in clipmapctl-offline beside it. */
static void test_ctl_thin(void **state)
{
	struct env *e = *state;
	need(e, CTL);
	char cmd[1400], out[16384];
	snprintf(cmd, sizeof cmd, "ldd '%s' | wc -l; ldd '%s' | grep -c -i -E 'gdal|OpenImageIO'",
		 e->prog[CTL], e->prog[CTL]);
	char *argv[] = { "sh", "-c", cmd, NULL };
	daemon_env_run(argv, out, sizeof out);
	int nlibs = -1, heavy = -1;
	assert_int_equal(sscanf(out, "%d %d", &nlibs, &heavy), 2);
	print_message("clipmapctl: %d shared libraries, %d of them GDAL/OpenImageIO\n", nlibs,
		      heavy);
	assert_int_equal(heavy, 0);
	/* about 16 (GnuTLS brings nettle, hogweed, gmp, p11-kit, tasn1, idn2, unistring; a
	 * sanitizer build adds its runtimes) against ~260 with GDAL and OpenImageIO */
	assert_true(nlibs < 28);
	/* the offline commands still work through it */
	const char *layers[] = { "layers", "@P", NULL };
	assert_int_equal(run(e, CTL, layers, out, sizeof out), 0);
	assert_non_null(strstr(out, "planet procedural"));
}

/* --wait-complete that runs out of --timeout: the picture is written, exit status 3. */
static void test_view_timeout_exit(void **state)
{
	struct env *e = *state;
	need(e, VIEW);
	char dir[] = "/tmp/test_cli_args.XXXXXX", png[64], out[8192];
	assert_non_null(mkdtemp(dir));
	snprintf(png, sizeof png, "%s/t.png", dir);
	const char *args[] = { "--planet", "@P", "--camera", "27.9,86.9,2000,0,-20", "--size",
			       "64x48", "--wait-complete", "--timeout", "0.001", "-o", png, NULL };
	int rc = run(e, VIEW, args, out, sizeof out);
	bool no_gl = rc == 1 && strstr(out, "no OpenGL context");
	bool wrote = access(png, F_OK) == 0;
	unlink(png);
	rmdir(dir);
	if (no_gl) {
		print_message("skipped: %s", out);
		skip();
	}
	if (rc != 3)
		print_message("clipmapview: exit %d:\n%s\n", rc, out);
	assert_int_equal(rc, 3);
	assert_true(wrote);
	assert_non_null(strstr(out, "--timeout"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_bad_values),
		cmocka_unit_test(test_version),
		cmocka_unit_test(test_ctl_command_help),
		cmocka_unit_test(test_view_timeout_exit),
		cmocka_unit_test(test_ctl_thin),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
