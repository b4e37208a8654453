/* daemon_env — for integration tests: a real build/clipmapd on a temporary Unix socket (no
 * TCP), with a temporary config and a planets directory holding the procedural planet, and a
 * helper that runs a program capturing its output. Test-only code (linked into test
 * programs, never into the library). */
#ifndef CLIPMAP_TEST_DAEMON_ENV_H
#define CLIPMAP_TEST_DAEMON_ENV_H
#include <stddef.h>
#include <sys/types.h>

struct daemon_env {
	char bindir[512];  /* build/ */
	char root[600];	   /* the repository (build/..) */
	char dir[64];	   /* temporary */
	char sock[128];
	char conf[128];
	char planets[128];
	pid_t daemon;	   /* 0 when the binaries were not built: the tests skip */
	int daemon_log;	   /* its stderr */
};

/* Starts the daemon (tag names the temporary directory); `client` is the program the test
 * drives (its absence skips like the daemon's). Returns 0 (also when skipping) or -1. */
int daemon_env_setup(struct daemon_env *e, const char *tag, const char *client);
/* SIGTERM, wait, remove the directory. */
void daemon_env_teardown(struct daemon_env *e);
/* Runs argv (argv[0] a path, or a program found in $PATH), stdout and stderr into out (NUL-terminated); returns the exit
 * status, 128 + signal, or -1. */
int daemon_env_run(char *const argv[], char *out, size_t n);

#endif
