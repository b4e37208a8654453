/* daemon_env — the one launcher of a real build/clipmapd for tests and benchmarks: finds the
 * build directory (this program lives in build/tests/), makes a temporary directory with a
 * planets/ directory, writes a config there, starts the daemon with its stderr in a log file,
 * waits (bounded) until it accepts, signals, restarts and stops it. Also runs a program
 * capturing its output. Test-only code (linked into test and bench programs, never into the
 * product). Not thread-safe: one thread drives a struct daemon_env; it owns the directory,
 * the log descriptor and the daemon process, and daemon_env_fini releases them.
 *
 * Typical use: daemon_env_init, then daemon_env_planet_text/_copy (none: the procedural
 * planet), then daemon_env_start; or daemon_env_setup for all three with the defaults.
 */
#ifndef CLIPMAP_TEST_DAEMON_ENV_H
#define CLIPMAP_TEST_DAEMON_ENV_H
#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

/* Bound on daemon_env_start's wait for the daemon to accept. */
#define DAEMON_ENV_START_MS 10000

struct daemon_env {
	char bindir[512]; /* build/ */
	char root[600];	  /* the repository (build/..) */
	char dir[64];	  /* the temporary directory ("" before daemon_env_init) */
	char sock[128];	  /* the Unix socket; "" when the config has none */
	char conf[128];	  /* the config file */
	char planets[128]; /* the planets directory */
	char log[128];	  /* the daemon's stderr (appended to across restarts) */
	int port;	  /* the first TCP listener's port once started; 0 without one */
	bool tcp;	  /* the config has a TCP listener */
	pid_t daemon;	  /* 0 when not running (also: not built, and the tests skip) */
	int log_fd;	  /* the log, open for the daemon's stderr; 0 or -1 when closed */
	int nplanets;	  /* planet files written or copied into planets/ */
	int starts;	  /* daemons started so far (counts "clipmapd ready" across restarts) */
};

/* The config daemon_env_start writes. A zeroed struct is the default: a Unix socket in the
 * temporary directory and no TCP, workers = 2, cache_mb = 64, log level warn (info when a TCP
 * listener is set: its port is read from the log). */
struct daemon_env_conf {
	/* Further "section.key = value" lines (NULL-terminated; NULL: none). A key named here
	 * replaces the launcher's default for it, e.g. "engine.workers = 1",
	 * "listen.tcp = 127.0.0.1:0", "session.max_rate = 0", "log.level = info";
	 * "listen.unix =" turns the Unix socket off. Borrowed for the call. */
	const char *const *set;
	/* Written to DIR/token and named as [listen] token_file (NULL: none). Borrowed. */
	const char *token;
};

/* The build directory: this program's directory's parent (programs live in build/tests/).
 * Returns 0 or -errno. */
int daemon_env_bindir(char *out, size_t n);
/* Finds build/ and makes DIR=/tmp/TAG_XXXXXX with DIR/planets; starts nothing. Returns 0 or
 * -errno. Call daemon_env_fini afterwards even when it fails. */
int daemon_env_init(struct daemon_env *e, const char *tag);
/* Whether build/PROG was built (an executable file). */
bool daemon_env_built(const struct daemon_env *e, const char *prog);
/* Writes planets/FILE (e.g. "test.ini") with text. path (optional, 128 bytes) receives the
 * file's path, for tests that rewrite it before a SIGHUP. Returns 0 or -errno. */
int daemon_env_planet_text(struct daemon_env *e, const char *file, const char *text, char *path);
/* Copies the planet file `from` (absolute, or relative to the working directory) into
 * planets/, making its relative `path =` values absolute (they resolve against the original
 * file's directory). name (optional, nname bytes) receives the planet's name as clients ask
 * for it (the file name without its extension). Returns 0 or -errno. */
int daemon_env_planet_copy(struct daemon_env *e, const char *from, char *name, size_t nname);

/* Writes the config (c may be NULL: the defaults) and starts build/clipmapd -c CONFIG with
 * its stderr appended to e->log; with no planet added yet it first copies
 * conf/planets/procedural.ini. Waits up to DAEMON_ENV_START_MS until the Unix socket accepts
 * and, with a TCP listener, the log says the daemon is ready (then e->port is set). Returns 0,
 * or -errno with err (optional) saying why; a daemon that exits at start has its log printed
 * to stderr. */
int daemon_env_start(struct daemon_env *e, const struct daemon_env_conf *c, char err[256]);
/* The bounded wait daemon_env_start does, for a daemon started (or restarted) by it: returns 0
 * once it accepts, -ETIMEDOUT after timeout_ms, -ECHILD when it exited (e->daemon is then 0).
 * Sets e->port when there is a TCP listener. */
int daemon_env_wait_ready(struct daemon_env *e, int timeout_ms);
/* Sends sig to the running daemon. Returns 0 or -errno (-ESRCH when none runs). */
int daemon_env_signal(struct daemon_env *e, int sig);
/* Sends sig (0: none, only wait) and waits for the daemon to exit; *status (optional)
 * receives its waitpid status. e->daemon is 0 afterwards. Returns 0 or -errno. */
int daemon_env_stop(struct daemon_env *e, int sig, int *status);
/* Stops the daemon (SIGTERM, wait) and starts it again on the same config, socket and log.
 * Returns what daemon_env_start returns. */
int daemon_env_restart(struct daemon_env *e, char err[256]);
/* Stops a running daemon (SIGTERM; SIGKILL when it has not exited after 10 s), closes the log
 * and removes the temporary directory. Safe on a zeroed or failed env; idempotent. */
void daemon_env_fini(struct daemon_env *e);

/* The daemon's log so far, NUL-terminated; returns owned memory (free), "" when unreadable. */
char *daemon_env_log_read(const struct daemon_env *e);
/* How many times the log contains `what`. */
int daemon_env_log_count(const struct daemon_env *e, const char *what);
/* Waits until the log contains `what` at least count times, up to timeout_ms. */
bool daemon_env_log_wait(const struct daemon_env *e, const char *what, int count, int timeout_ms);

/* daemon_env_init, then (when build/clipmapd and build/CLIENT exist) daemon_env_start with
 * the defaults; CLIENT is the program the test drives (NULL: none). When one is missing,
 * e->daemon stays 0 and the tests skip. Returns 0 (also when skipping) or -1. */
int daemon_env_setup(struct daemon_env *e, const char *tag, const char *client);
/* daemon_env_fini. */
void daemon_env_teardown(struct daemon_env *e);

/* Runs argv (argv[0] a path, or a program found in $PATH), stdout and stderr into out
 * (NUL-terminated); returns the exit status, 128 + signal, or -1. */
int daemon_env_run(char *const argv[], char *out, size_t n);

#endif
