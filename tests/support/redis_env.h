/* redis_env — a private redis-server for tests and benchmarks: started on a Unix socket in a
 * directory the caller owns (--port 0: no TCP; no RDB, no AOF), waited for (bounded), killed
 * and reaped. Test-only code. Not thread-safe: one thread drives a struct redis_env.
 */
#ifndef CLIPMAP_TEST_REDIS_ENV_H
#define CLIPMAP_TEST_REDIS_ENV_H
#include <stdbool.h>
#include <sys/types.h>

struct redis_env {
	char sock[160]; /* DIR/redis.sock */
	char log[160];	/* DIR/redis.log */
	pid_t pid;	/* 0: not running */
};

/* Whether redis-server is installed (found in $PATH and runs). */
bool redis_env_installed(void);
/* Starts redis-server with its socket and log in dir and waits up to 10 s until it answers
 * PING. Returns 0, or -errno (-ETIMEDOUT: it never answered; it is then killed). */
int redis_env_start(struct redis_env *r, const char *dir);
/* Kills (SIGKILL) and reaps it, removes its socket and log; a no-op when not running. */
void redis_env_stop(struct redis_env *r);

#endif
