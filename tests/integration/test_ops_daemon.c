/* clipmapd as an operator runs it: the session log names the peer (ADDR:PORT over TCP, the
 * pid over the Unix socket) and a failed authentication is a warning; a broken planet file is
 * logged and skipped while the others are served (and `clipmapctl status` lists the planets
 * served and counts the skipped file), unless strict_planets = true, which makes it fatal at
 * start and in --check-config; SIGHUP re-reads clipmapd.conf (the log level at once, a
 * restart-only key named in a warning, a bad file changing nothing). Real processes: build/clipmapd through tests/support/daemon_env
 * and build/clipmapctl. Skipped when they were not built.
 */
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <cmocka.h>

#include "support/daemon_env.h"

#define BROKEN_PLANET "[planet\nname = broken\n" /* not even INI */

static bool built(const struct daemon_env *e)
{
	if (daemon_env_built(e, "clipmapd") && daemon_env_built(e, "clipmapctl"))
		return true;
	print_message("skipped: clipmapd or clipmapctl not built\n");
	return false;
}

/* clipmapctl ARGS... (NULL-terminated), output into out. Returns the exit status. */
static int ctl(const struct daemon_env *e, char *out, size_t n, ...)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapctl", e->bindir);
	char *argv[24] = { exe };
	int k = 1;
	va_list ap;
	va_start(ap, n);
	for (char *a; (a = va_arg(ap, char *)) && k < 23;)
		argv[k++] = a;
	va_end(ap);
	argv[k] = NULL;
	return daemon_env_run(argv, out, n);
}

static int setup(void **state)
{
	*state = calloc(1, sizeof(struct daemon_env));
	return *state ? 0 : -1;
}

/* Stops the daemon and removes the directory even after a failed assertion. */
static int teardown(void **state)
{
	daemon_env_fini(*state);
	free(*state);
	return 0;
}

static void test_peer_and_auth_in_log(void **state)
{
	struct daemon_env *ep = *state;
#define e (*ep) /* both tests: the env the fixture owns */
	char err[256], out[8192], hp[64], good[128], bad[128];
	assert_int_equal(daemon_env_init(&e, "test_ops_peer"), 0);
	if (!built(&e))
		skip();
	static const char *const set[] = { "listen.tcp = 127.0.0.1:0", "listen.require_token = tcp",
					   "log.level = info", NULL };
	struct daemon_env_conf c = { .set = set, .token = "s3cret" };
	if (daemon_env_start(&e, &c, err))
		fail_msg("daemon: %s", err);
	snprintf(hp, sizeof hp, "127.0.0.1:%d", e.port);
	snprintf(good, sizeof good, "%s/token", e.dir);
	snprintf(bad, sizeof bad, "%s/wrong", e.dir);
	FILE *f = fopen(bad, "w");
	assert_non_null(f);
	fputs("wrong\n", f);
	assert_int_equal(fclose(f), 0);

	int rc = ctl(&e, out, sizeof out, "-H", hp, "--token-file", bad, "status", NULL);
	assert_int_not_equal(rc, 0);
	assert_true(daemon_env_log_wait(&e, "error auth", 1, 5000));
	/* --connect is clipmapview's spelling of -H and -s */
	rc = ctl(&e, out, sizeof out, "--connect", hp, "--token-file", good, "status", NULL);
	if (rc != 0)
		print_message("%s\n", out);
	assert_int_equal(rc, 0);
	rc = ctl(&e, out, sizeof out, "status", "--connect", e.sock, NULL);
	assert_int_equal(rc, 0);
	/* one info line per session, at its HELLO (the refused one has its warning) */
	assert_true(daemon_env_log_wait(&e, "hello, codec", 2, 5000));

	char *log = daemon_env_log_read(&e);
	/* the TCP sessions name their peer, the address and a port */
	const char *from = strstr(log, "from 127.0.0.1:");
	if (!from)
		print_message("log:\n%s\n", log);
	assert_non_null(from);
	assert_true(from[strlen("from 127.0.0.1:")] >= '1' && from[strlen("from 127.0.0.1:")] <= '9');
	/* the Unix one its pid */
	assert_non_null(strstr(log, "from unix pid "));
	/* a wrong token is a warning naming the peer */
	const char *auth = strstr(log, "error auth");
	assert_non_null(auth);
	const char *line = auth;
	while (line > log && line[-1] != '\n')
		line--;
	if (strncmp(line, "warning: ", 9) != 0 || !strstr(line, "127.0.0.1:"))
		print_message("auth line: %.*s\n", (int)(strchr(auth, '\n') - line), line);
	assert_int_equal(strncmp(line, "warning: ", 9), 0);
	assert_true(strstr(line, "127.0.0.1:") < strchr(auth, '\n'));
	free(log);
}

static void test_broken_planet_skipped(void **state)
{
	struct daemon_env *ep = *state;
	char err[256], out[16384], from[700];
	assert_int_equal(daemon_env_init(&e, "test_ops_planets"), 0);
	if (!built(&e))
		skip();
	snprintf(from, sizeof from, "%s/conf/planets/procedural.ini", e.root);
	assert_int_equal(daemon_env_planet_copy(&e, from, NULL, 0), 0);
	assert_int_equal(daemon_env_planet_text(&e, "broken.ini", BROKEN_PLANET, NULL), 0);
	static const char *const set[] = { "log.level = info", NULL };
	struct daemon_env_conf c = { .set = set };
	if (daemon_env_start(&e, &c, err))
		fail_msg("daemon: %s", err);
	assert_int_equal(daemon_env_log_count(&e, "planet file skipped"), 1);
	assert_int_equal(daemon_env_log_count(&e, "broken.ini"), 1);

	int rc = ctl(&e, out, sizeof out, "-s", e.sock, "status", NULL);
	if (rc != 0 || !strstr(out, "planets served (1)"))
		print_message("status: exit %d\n%s\n", rc, out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "planets served (1)"));
	assert_non_null(strstr(out, "  procedural "));
	assert_non_null(strstr(out, "skipped"));
	rc = ctl(&e, out, sizeof out, "-s", e.sock, "status", "--json", NULL);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "\"planets.skipped\": 1"));

	/* --check-config: OK, saying what was skipped */
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapd", e.bindir);
	char *chk[] = { exe, "--check-config", "-c", e.conf, NULL };
	rc = daemon_env_run(chk, out, sizeof out);
	if (rc != 0)
		print_message("%s\n", out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "1 planet file skipped"));
	assert_non_null(strstr(out, "broken.ini"));
	assert_int_equal(daemon_env_stop(&e, SIGTERM, NULL), 0);

	/* strict_planets = true: fatal at start and in --check-config */
	static const char *const strict[] = { "engine.strict_planets = true", NULL };
	struct daemon_env_conf cs = { .set = strict };
	assert_int_not_equal(daemon_env_start(&e, &cs, err), 0);
	rc = daemon_env_run(chk, out, sizeof out);
	assert_int_equal(rc, 2);
	assert_non_null(strstr(out, "broken.ini"));
}

/* SIGHUP re-reads clipmapd.conf: the log level changes at once (sessions are logged at info
 * after the reload, not before), a key that needs a restart is named in a warning, a config
 * that does not load changes nothing. */
static void test_sighup_rereads_conf(void **state)
{
	struct daemon_env *ep = *state;
	char err[256], out[8192];
	assert_int_equal(daemon_env_init(&e, "test_ops_hup"), 0);
	if (!built(&e))
		skip();
	if (daemon_env_start(&e, NULL, err)) /* log level warn */
		fail_msg("daemon: %s", err);
	assert_int_equal(ctl(&e, out, sizeof out, "-s", e.sock, "status", NULL), 0);
	assert_int_equal(daemon_env_log_count(&e, "hello, codec"), 0);

	/* warn -> info, and workers 2 -> 1 (restart only) */
	char cmd[512];
	snprintf(cmd, sizeof cmd,
		 "sed -i 's/^level = warn/level = info/; s/^workers = 2/workers = 1/' '%s'", e.conf);
	char *sed[] = { "sh", "-c", cmd, NULL };
	assert_int_equal(daemon_env_run(sed, out, sizeof out), 0);
	assert_int_equal(daemon_env_signal(&e, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&e, "reloaded 1 planets", 1, 5000));
	assert_int_equal(daemon_env_log_count(&e, "[engine] workers changed"), 1);
	assert_int_equal(ctl(&e, out, sizeof out, "-s", e.sock, "status", NULL), 0);
	assert_true(daemon_env_log_wait(&e, "hello, codec", 1, 5000));

	/* a broken config: nothing changes, an error says why */
	snprintf(cmd, sizeof cmd, "printf '[log]\nlevel = loud\n' > '%s'", e.conf);
	assert_int_equal(daemon_env_run(sed, out, sizeof out), 0);
	assert_int_equal(daemon_env_signal(&e, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&e, "keeping the running configuration", 1, 5000));
	assert_true(daemon_env_log_wait(&e, "reloaded 1 planets", 2, 5000));
	assert_int_equal(ctl(&e, out, sizeof out, "-s", e.sock, "status", NULL), 0);
	assert_true(daemon_env_log_wait(&e, "hello, codec", 2, 5000)); /* still info */
}
#undef e

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test_setup_teardown(test_peer_and_auth_in_log, setup, teardown),
		cmocka_unit_test_setup_teardown(test_broken_planet_skipped, setup, teardown),
		cmocka_unit_test_setup_teardown(test_sighup_rereads_conf, setup, teardown),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
