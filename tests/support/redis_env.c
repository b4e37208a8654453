/* redis_env — see redis_env.h. */
#include "redis_env.h"

#include <errno.h>
#include <hiredis/hiredis.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "common/clock.h"
#include "support/daemon_env.h"

bool redis_env_installed(void)
{
	char out[256];
	char *const argv[] = { "redis-server", "--version", NULL };
	return daemon_env_run(argv, out, sizeof out) == 0;
}

static bool answers(const char *sock)
{
	redisContext *c = redisConnectUnix(sock);
	bool ok = c && !c->err;
	if (ok) {
		redisReply *r = redisCommand(c, "PING");
		ok = r && r->type == REDIS_REPLY_STATUS;
		if (r)
			freeReplyObject(r);
	}
	if (c)
		redisFree(c);
	return ok;
}

int redis_env_start(struct redis_env *r, const char *dir)
{
	snprintf(r->sock, sizeof r->sock, "%s/redis.sock", dir);
	snprintf(r->log, sizeof r->log, "%s/redis.log", dir);
	pid_t pid = fork();
	if (pid < 0)
		return -errno;
	if (pid == 0) {
		execlp("redis-server", "redis-server", "--port", "0", "--unixsocket", r->sock,
		       "--unixsocketperm", "700", "--save", "", "--appendonly", "no", "--logfile",
		       r->log, "--daemonize", "no", (char *)NULL);
		_exit(127);
	}
	r->pid = pid;
	uint64_t end = clock_now_ms() + 10000;
	while (clock_now_ms() < end) {
		if (answers(r->sock))
			return 0;
		if (waitpid(pid, NULL, WNOHANG) == pid) {
			r->pid = 0;
			return -ECHILD;
		}
		usleep(10000);
	}
	redis_env_stop(r);
	return -ETIMEDOUT;
}

void redis_env_stop(struct redis_env *r)
{
	if (r->pid <= 0)
		return;
	kill(r->pid, SIGKILL);
	waitpid(r->pid, NULL, 0);
	r->pid = 0;
	unlink(r->sock);
	unlink(r->log);
}
