/* daemon_env — see daemon_env.h. */
#include "daemon_env.h"

#include <fcntl.h>
#include <signal.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>


int daemon_env_run(char *const argv[], char *out, size_t n)
{
	int p[2];
	if (pipe(p))
		return -1;
	pid_t pid = fork();
	if (pid < 0)
		return -1;
	if (pid == 0) {
		dup2(p[1], 1);
		dup2(p[1], 2);
		close(p[0]);
		close(p[1]);
		execvp(argv[0], argv);
		_exit(127);
	}
	close(p[1]);
	size_t len = 0;
	ssize_t r;
	while ((r = read(p[0], out + len, n - 1 - len)) > 0)
		len += (size_t)r;
	out[len] = '\0';
	close(p[0]);
	int st;
	if (waitpid(pid, &st, 0) != pid)
		return -1;
	return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
}

static int write_text(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	fputs(text, f);
	return fclose(f);
}

static int copy_file(const char *from, const char *to)
{
	FILE *a = fopen(from, "rb"), *b = fopen(to, "wb");
	if (!a || !b) {
		if (a)
			fclose(a);
		if (b)
			fclose(b);
		return -1;
	}
	char buf[8192];
	size_t n;
	while ((n = fread(buf, 1, sizeof buf, a)) > 0)
		fwrite(buf, 1, n, b);
	fclose(a);
	return fclose(b);
}

/* Whether the daemon accepts connections yet. */
static bool socket_up(const char *path)
{
	int s = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	snprintf(a.sun_path, sizeof a.sun_path, "%s", path);
	bool ok = connect(s, (struct sockaddr *)&a, sizeof a) == 0;
	close(s);
	return ok;
}

int daemon_env_setup(struct daemon_env *e, const char *tag, const char *client)
{
	memset(e, 0, sizeof *e);
	ssize_t l = readlink("/proc/self/exe", e->bindir, sizeof e->bindir - 1);
	if (l <= 0)
		return -1;
	e->bindir[l] = '\0';
	*strrchr(e->bindir, '/') = '\0'; /* build/tests */
	*strrchr(e->bindir, '/') = '\0'; /* build */
	snprintf(e->root, sizeof e->root, "%s/..", e->bindir);
	char d[600], c[600];
	snprintf(d, sizeof d, "%s/clipmapd", e->bindir);
	snprintf(c, sizeof c, "%s/%s", e->bindir, client);
	if (access(d, X_OK) || access(c, X_OK)) {
		e->daemon = 0;
		return 0; /* the tests skip */
	}
	snprintf(e->dir, sizeof e->dir, "/tmp/%s_XXXXXX", tag);
	if (!mkdtemp(e->dir))
		return -1;
	snprintf(e->sock, sizeof e->sock, "%s/d.sock", e->dir);
	snprintf(e->conf, sizeof e->conf, "%s/clipmapd.conf", e->dir);
	snprintf(e->planets, sizeof e->planets, "%s/planets", e->dir);
	if (mkdir(e->planets, 0755))
		return -1;
	char from[700], to[300], text[1024];
	snprintf(from, sizeof from, "%s/conf/planets/procedural.ini", e->root);
	snprintf(to, sizeof to, "%s/procedural.ini", e->planets);
	if (copy_file(from, to))
		return -1;
	snprintf(text, sizeof text,
		 "[listen]\nunix = %s\ntcp =\n[engine]\nplanets = %s\nworkers = 2\ncache_mb = 64\n"
		 "[log]\nlevel = warn\n", e->sock, e->planets);
	if (write_text(e->conf, text))
		return -1;
	char logpath[200];
	snprintf(logpath, sizeof logpath, "%s/daemon.log", e->dir);
	e->daemon_log = open(logpath, O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
	pid_t pid = fork();
	if (pid < 0)
		return -1;
	if (pid == 0) {
		dup2(e->daemon_log, 2);
		execl(d, d, "-c", e->conf, (char *)NULL);
		_exit(127);
	}
	e->daemon = pid;
	/* wait (bounded) for the socket to accept: the daemon loads the planets first */
	for (int i = 0; i < 400 && !socket_up(e->sock); i++) {
		int st;
		if (waitpid(pid, &st, WNOHANG) == pid) {
			char log[2048];
			ssize_t n = pread(e->daemon_log, log, sizeof log - 1, 0);
			log[n > 0 ? n : 0] = '\0';
			fprintf(stderr, "clipmapd exited at start:\n%s", log);
			e->daemon = 0;
			return -1;
		}
		nanosleep(&(struct timespec){ .tv_nsec = 25000000 }, NULL);
	}
	return socket_up(e->sock) ? 0 : -1;
}

void daemon_env_teardown(struct daemon_env *e)
{
	if (e->daemon > 0) {
		kill(e->daemon, SIGTERM);
		int st;
		waitpid(e->daemon, &st, 0);
	}
	if (e->dir[0]) {
		char cmd[200];
		snprintf(cmd, sizeof cmd, "rm -rf '%s'", e->dir);
		if (system(cmd) != 0)
			fprintf(stderr, "could not remove %s\n", e->dir);
	}
	if (e->daemon_log > 0)
		close(e->daemon_log);
}

