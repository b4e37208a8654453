/* make install and make uninstall as an operator or a packager runs them: into a DESTDIR with
 * PREFIX=/usr, every file lands under DESTDIR with the units naming /usr/bin (not
 * /usr/local), the socket owned by the group clipmap that sysusers.d creates, the planets'
 * data paths pointing at /var/lib/clipmap, man pages (when scdoc is here), no test or bench
 * program; then into a throwaway prefix (every directory in a temporary root, no DESTDIR),
 * where the installed clipmapd --check-config accepts the installed config and planets — none
 * of which names a path in this checkout — and systemd-analyze accepts the installed units;
 * make uninstall removes the programs and units and keeps the config. CesiumJS (when make
 * deps put it in the build tree) is installed too, and the installed clipmapd, run from the
 * DESTDIR with no [http] cesium, serves the browser page and CesiumJS's files from it. Runs
 * make on this
 * checkout's build directory (the programs are already built). Skipped when the programs
 * were not built or make is not here.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <signal.h>
#include <string.h>
#include <sys/types.h>
#include <unistd.h>
#include <cmocka.h>

#include "support/daemon_env.h"

struct env {
	char bindir[512], root[600], build[128];
	char tmp[64];
};

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	char bin[512]; /* a local copy: snprintf from *e into *e may overlap, says GCC */
	if (!e || daemon_env_bindir(bin, sizeof bin))
		return -1;
	snprintf(e->bindir, sizeof e->bindir, "%s", bin);
	snprintf(e->root, sizeof e->root, "%s/..", bin);
	snprintf(e->build, sizeof e->build, "%s", strrchr(bin, '/') + 1);
	snprintf(e->tmp, sizeof e->tmp, "/tmp/test_install.XXXXXX");
	if (!mkdtemp(e->tmp))
		return -1;
	*state = e;
	return 0;
}

static int teardown(void **state)
{
	struct env *e = *state;
	char cmd[128];
	snprintf(cmd, sizeof cmd, "rm -rf '%s'", e->tmp);
	int rc = system(cmd);
	free(e);
	return rc == 0 ? 0 : -1;
}

/* sh -c cmd (printf-style), output into out. Returns the exit status. */
static int __attribute__((format(printf, 3, 4))) sh(char *out, size_t n, const char *fmt, ...)
{
	char cmd[4096];
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(cmd, sizeof cmd, fmt, ap);
	va_end(ap);
	char *argv[] = { "sh", "-c", cmd, NULL };
	return daemon_env_run(argv, out, n);
}

/* make -C ROOT TARGET with the build directory of this test and ARGS; the test's own make
 * (make test) is not inherited. */
static int make(const struct env *e, char *out, size_t n, const char *target, const char *args)
{
	return sh(out, n,
		  "env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL make --no-print-directory -s -C '%s' "
		  "BUILD='%s' %s %s 2>&1",
		  e->root, e->build, target, args);
}

static void need(const struct env *e)
{
	char out[256];
	if (access(e->bindir, X_OK) != 0 || sh(out, sizeof out, "command -v make") != 0) {
		print_message("skipped: make or %s missing\n", e->bindir);
		skip();
	}
	char p[700];
	snprintf(p, sizeof p, "%s/clipmapd", e->bindir);
	if (access(p, X_OK) != 0)
		skip();
}

static bool has(const char *file, const char *text)
{
	char out[64];
	return sh(out, sizeof out, "grep -qF -- '%s' '%s'", text, file) == 0;
}

/* The installed clipmapd (ROOT/usr/bin) with an HTTP listener and no [http] cesium: it finds
 * the installed CesiumJS, serves the page at / and Cesium.js byte for byte. */
static void installed_serves_cesium(const struct env *e, const char *root)
{
	char out[16384], f[700];
	snprintf(f, sizeof f, "%s/usr/share/clipmap/cesium/Cesium.js", root);
	if (access(f, R_OK) != 0)
		print_message("missing: %s\n", f);
	assert_int_equal(access(f, R_OK), 0);
	/* the shipped procedural planet (the others need data), our own socket and port */
	int rc = sh(out, sizeof out,
		    "mkdir -p '%s/run/planets' && cp '%s/etc/clipmap/planets/procedural.ini' "
		    "'%s/etc/clipmap/planets/site.geojson' '%s/run/planets/' && printf '[listen]\nunix = %s/run/sock\ntcp =\n[engine]\n"
		    "planets = %s/run/planets\nworkers = 1\n[log]\nlevel = info\n[http]\n"
		    "listen = 127.0.0.1:0\n' > '%s/run/c.conf'",
		    e->tmp, root, root, e->tmp, e->tmp, e->tmp, e->tmp);
	if (rc)
		print_message("%s\n", out);
	assert_int_equal(rc, 0);
	rc = sh(out, sizeof out, "'%s/usr/bin/clipmapd' -c '%s/run/c.conf' </dev/null >/dev/null "
		"2>'%s/run/log' & echo $!", root, e->tmp, e->tmp);
	assert_int_equal(rc, 0);
	pid_t pid = (pid_t)atoi(out);
	assert_true(pid > 0);
	int port = 0;
	for (int i = 0; i < 200 && !port; i++) { /* up to 20 s */
		usleep(100000);
		if (sh(out, sizeof out, "grep -o 'listening on http://127.0.0.1:[0-9]*' "
		       "'%s/run/log' | grep -o '[0-9]*$'", e->tmp) == 0)
			port = atoi(out);
	}
	if (!port) {
		sh(out, sizeof out, "cat '%s/run/log'", e->tmp);
		kill(pid, SIGKILL);
		fail_msg("the installed clipmapd did not listen for HTTP:\n%s", out);
	}
	rc = sh(out, sizeof out, "curl -s -m 30 -o '%s/run/page' -w '%%{http_code}' "
		"http://127.0.0.1:%d/", e->tmp, port);
	int page = rc == 0 ? atoi(out) : -1;
	rc = sh(out, sizeof out, "curl -s -m 30 -o '%s/run/Cesium.js' -w '%%{http_code}' "
		"http://127.0.0.1:%d/cesium-js/Cesium.js && cmp '%s/run/Cesium.js' '%s'",
		e->tmp, port, e->tmp, f);
	int js = atoi(out), same = rc;
	kill(pid, SIGTERM);
	char pf[700];
	snprintf(pf, sizeof pf, "%s/run/page", e->tmp);
	assert_int_equal(page, 200);
	if (!has(pf, "<script src=\"/cesium-js/Cesium.js\">"))
		fail_msg("/ is not the Cesium page (the installed CesiumJS not found?)");
	assert_int_equal(js, 200);
	if (same != 0)
		fail_msg("/cesium-js/Cesium.js differs from the installed file: %s", out);
	print_message("the installed clipmapd serves the page and Cesium.js from %s/usr/share/"
		      "clipmap/cesium\n", root);
}

static void test_destdir_layout(void **state)
{
	struct env *e = *state;
	need(e);
	char out[16384], args[512], f[700];
	snprintf(args, sizeof args, "PREFIX=/usr DESTDIR='%s/root'", e->tmp);
	int rc = make(e, out, sizeof out, "install", args);
	if (rc != 0)
		print_message("make install: exit %d\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	const char *files[] = { "usr/bin/clipmapd", "usr/bin/clipmapctl", "usr/bin/clipmapview",
				"etc/clipmap/clipmapd.conf", "etc/clipmap/planets/procedural.ini",
				"usr/lib/systemd/system/clipmapd.service",
				"usr/lib/systemd/system/clipmapd.socket", "usr/lib/sysusers.d/clipmap.conf",
				"usr/share/doc/clipmap/LICENSE",
				"usr/share/bash-completion/completions/clipmapctl" };
	for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
		snprintf(f, sizeof f, "%s/root/%s", e->tmp, files[i]);
		if (access(f, R_OK) != 0)
			print_message("missing: %s\n", f);
		assert_int_equal(access(f, R_OK), 0);
	}
	snprintf(f, sizeof f, "%s/root/usr/lib/systemd/system/clipmapd.service", e->tmp);
	assert_true(has(f, "ExecStart=/usr/bin/clipmapd -c /etc/clipmap/clipmapd.conf"));
	assert_false(has(f, "/usr/local"));
	assert_false(has(f, "@BINDIR@") || has(f, "@CONFDIR@") || has(f, "@DOCDIR@"));
	snprintf(f, sizeof f, "%s/root/usr/lib/systemd/system/clipmapd.socket", e->tmp);
	assert_true(has(f, "SocketGroup=clipmap"));
	snprintf(f, sizeof f, "%s/root/usr/lib/sysusers.d/clipmap.conf", e->tmp);
	assert_true(has(f, "g clipmap"));
	snprintf(f, sizeof f, "%s/root/etc/clipmap/planets/earth.ini", e->tmp);
	assert_true(has(f, "path = /var/lib/clipmap/earth/"));
	if (sh(out, sizeof out, "command -v scdoc") == 0) {
		const char *man[] = { "man8/clipmapd.8", "man1/clipmapctl.1", "man1/clipmapview.1",
				      "man5/clipmapd.conf.5", "man5/clipmap-planet.5" };
		for (size_t i = 0; i < 5; i++) {
			snprintf(f, sizeof f, "%s/root/usr/share/man/%s", e->tmp, man[i]);
			if (access(f, R_OK) != 0)
				print_message("missing: %s\n", f);
			assert_int_equal(access(f, R_OK), 0);
		}
	} else {
		print_message("scdoc not here: man pages not checked\n");
	}
	/* no test or bench program is installed */
	rc = sh(out, sizeof out, "find '%s/root' -name 'test_*' -o -name 'bench_*' | grep -q .",
		e->tmp);
	assert_int_not_equal(rc, 0);
	/* CesiumJS, where make deps put it in the build tree */
	snprintf(f, sizeof f, "%s/npm/node_modules/cesium/Build/Cesium/Cesium.js", e->bindir);
	char root[128];
	snprintf(root, sizeof root, "%s/root", e->tmp);
	if (access(f, R_OK) != 0)
		print_message("no CesiumJS in the build tree (make deps): its install not checked\n");
	else if (sh(out, sizeof out, "command -v curl") != 0)
		print_message("no curl: the installed browser page not checked\n");
	else
		installed_serves_cesium(e, root);

	rc = make(e, out, sizeof out, "uninstall", args);
	if (rc != 0)
		print_message("make uninstall: exit %d\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	snprintf(f, sizeof f, "%s/root/usr/bin/clipmapd", e->tmp);
	assert_int_not_equal(access(f, F_OK), 0);
	snprintf(f, sizeof f, "%s/root/usr/lib/systemd/system/clipmapd.service", e->tmp);
	assert_int_not_equal(access(f, F_OK), 0);
	snprintf(f, sizeof f, "%s/root/usr/share/clipmap/cesium", e->tmp);
	assert_int_not_equal(access(f, F_OK), 0);
	snprintf(f, sizeof f, "%s/root/etc/clipmap/clipmapd.conf", e->tmp); /* kept */
	assert_int_equal(access(f, R_OK), 0);
}

static void test_installed_tree_checks(void **state)
{
	struct env *e = *state;
	need(e);
	char out[16384], args[1024], p[128];
	snprintf(p, sizeof p, "%s/p", e->tmp);
	snprintf(args, sizeof args,
		 "PREFIX='%s' SYSCONFDIR='%s/etc' STATEDIR='%s/var/lib/clipmap' RUN_SYSUSERS=no", p, p,
		 p);
	int rc = make(e, out, sizeof out, "install", args);
	if (rc != 0)
		print_message("make install: exit %d\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	/* nothing installed refers to the checkout (relative ../../data paths or its root) */
	char real[4096];
	assert_non_null(realpath(e->root, real));
	rc = sh(out, sizeof out, "grep -rlE -e '\\.\\./\\.\\./data' -e '%s' '%s/etc'", real, p);
	if (rc == 0)
		print_message("files naming the checkout:\n%s\n", out);
	assert_int_not_equal(rc, 0);
	/* the installed daemon accepts the installed config and planets */
	rc = sh(out, sizeof out, "'%s/bin/clipmapd' --check-config -c '%s/etc/clipmap/clipmapd.conf'",
		p, p);
	if (rc != 0 || !strstr(out, ": OK ("))
		print_message("clipmapd --check-config: exit %d\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, ": OK ("));
	/* and systemd the installed units */
	if (sh(out, sizeof out, "command -v systemd-analyze") == 0) {
		rc = sh(out, sizeof out,
			"SYSTEMD_LOG_LEVEL=warning systemd-analyze verify --man=no "
			"'%s/etc/systemd/system/clipmapd.socket' "
			"'%s/etc/systemd/system/clipmapd.service'",
			p, p);
		if (rc != 0)
			print_message("systemd-analyze verify: exit %d\n%s\n", rc, out);
		assert_int_equal(rc, 0);
	}
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(test_destdir_layout),
		cmocka_unit_test(test_installed_tree_checks),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
