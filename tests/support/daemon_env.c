/* daemon_env — see daemon_env.h. The waits poll (the socket, the log) every 10 ms: the
 * daemon is another process and tells nobody when it is ready, and tests only wait at start
 * and after a signal. */
#include "daemon_env.h"

#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/clock.h"
#include "common/errbuf.h"

#define POLL_NS 10000000L
#define STOP_MS 10000

static void nap(void)
{
	nanosleep(&(struct timespec){ .tv_nsec = POLL_NS }, NULL);
}

/* snprintf into a path buffer; -ENAMETOOLONG when it does not fit. */
static int __attribute__((format(printf, 3, 4))) pathf(char *dst, size_t n, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	int r = vsnprintf(dst, n, fmt, ap);
	va_end(ap);
	return r < 0 || (size_t)r >= n ? -ENAMETOOLONG : 0;
}

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
		return -errno;
	int rc = fputs(text, f) < 0 ? -EIO : 0;
	if (fclose(f) && !rc)
		rc = -errno;
	return rc;
}

int daemon_env_bindir(char *out, size_t n)
{
	ssize_t l = readlink("/proc/self/exe", out, n - 1);
	if (l <= 0)
		return l < 0 ? -errno : -ENOENT;
	out[l] = '\0';
	for (int up = 0; up < 2; up++) { /* build/tests/PROG -> build */
		char *slash = strrchr(out, '/');
		if (!slash || slash == out)
			return -ENOENT;
		*slash = '\0';
	}
	return 0;
}

int daemon_env_init(struct daemon_env *e, const char *tag)
{
	memset(e, 0, sizeof *e);
	e->log_fd = -1;
	int rc = daemon_env_bindir(e->bindir, sizeof e->bindir);
	if (rc)
		return rc;
	snprintf(e->root, sizeof e->root, "%s/..", e->bindir);
	snprintf(e->dir, sizeof e->dir, "/tmp/%s_XXXXXX", tag);
	if (!mkdtemp(e->dir)) {
		rc = -errno;
		e->dir[0] = '\0';
		return rc;
	}
	snprintf(e->sock, sizeof e->sock, "%s/d.sock", e->dir);
	snprintf(e->conf, sizeof e->conf, "%s/clipmapd.conf", e->dir);
	snprintf(e->planets, sizeof e->planets, "%s/planets", e->dir);
	snprintf(e->log, sizeof e->log, "%s/daemon.log", e->dir);
	return mkdir(e->planets, 0755) ? -errno : 0;
}

bool daemon_env_built(const struct daemon_env *e, const char *prog)
{
	char p[700];
	snprintf(p, sizeof p, "%s/%s", e->bindir, prog);
	return access(p, X_OK) == 0;
}

int daemon_env_planet_text(struct daemon_env *e, const char *file, const char *text, char *path)
{
	char p[128];
	int rc = pathf(p, sizeof p, "%s/%s", e->planets, file);
	if (rc)
		return rc;
	if (path)
		memcpy(path, p, sizeof p);
	rc = write_text(p, text);
	e->nplanets += rc == 0;
	return rc;
}

int daemon_env_planet_copy(struct daemon_env *e, const char *from, char *name, size_t nname)
{
	char absdir[PATH_MAX];
	if (!realpath(from, absdir))
		return -errno;
	*strrchr(absdir, '/') = '\0';
	const char *base = strrchr(from, '/') ? strrchr(from, '/') + 1 : from;
	if (name)
		snprintf(name, nname, "%.*s", (int)strcspn(base, "."), base);
	char to[300];
	snprintf(to, sizeof to, "%s/%s", e->planets, base);
	FILE *a = fopen(from, "r"), *b = fopen(to, "w");
	if (!a || !b) {
		int rc = -errno;
		if (a)
			fclose(a);
		if (b)
			fclose(b);
		return rc;
	}
	char line[4096];
	int rc = 0;
	while (rc == 0 && fgets(line, sizeof line, a)) {
		const char *p = line + strspn(line, " \t");
		if (strncmp(p, "path", 4) == 0 && strchr(p, '=')) {
			const char *v = strchr(p, '=') + 1;
			v += strspn(v, " \t");
			if (*v != '/') {
				if (fprintf(b, "path = %s/%s", absdir, v) < 0)
					rc = -EIO;
				continue;
			}
		}
		if (fputs(line, b) < 0)
			rc = -EIO;
	}
	fclose(a);
	if (fclose(b) && !rc)
		rc = -errno;
	e->nplanets += rc == 0;
	return rc;
}

/* ---- the config --------------------------------------------------------------------------- */

enum { MAX_KEYS = 48 };

struct kv {
	char sec[32], key[48], val[200];
};

/* Sets sec.key = val in the table, replacing an earlier value. */
static int kv_set(struct kv *t, int *n, const char *sec, size_t nsec, const char *key, size_t nkey,
		  const char *val, size_t nval)
{
	int i = 0;
	while (i < *n && !(strlen(t[i].sec) == nsec && strncmp(t[i].sec, sec, nsec) == 0 &&
			   strlen(t[i].key) == nkey && strncmp(t[i].key, key, nkey) == 0))
		i++;
	if (i == *n) {
		if (*n == MAX_KEYS)
			return -E2BIG;
		(*n)++;
	}
	snprintf(t[i].sec, sizeof t[i].sec, "%.*s", (int)nsec, sec);
	snprintf(t[i].key, sizeof t[i].key, "%.*s", (int)nkey, key);
	snprintf(t[i].val, sizeof t[i].val, "%.*s", (int)nval, val);
	return 0;
}

static int kv_set0(struct kv *t, int *n, const char *sec, const char *key, const char *val)
{
	return kv_set(t, n, sec, strlen(sec), key, strlen(key), val, strlen(val));
}

static const char *kv_get(const struct kv *t, int n, const char *sec, const char *key)
{
	for (int i = 0; i < n; i++)
		if (strcmp(t[i].sec, sec) == 0 && strcmp(t[i].key, key) == 0)
			return t[i].val;
	return NULL;
}

/* Parses "section.key = value" (surrounding blanks trimmed) into the table. */
static int kv_line(struct kv *t, int *n, const char *line, char *err)
{
	const char *dot = strchr(line, '.'), *eq = strchr(line, '=');
	if (!dot || !eq || dot > eq) {
		err_set(err, "bad config line \"%s\": want section.key = value", line);
		return -EINVAL;
	}
	const char *s = line + strspn(line, " \t");
	const char *k = dot + 1, *ke = eq, *v = eq + 1;
	while (ke > k && (ke[-1] == ' ' || ke[-1] == '\t'))
		ke--;
	v += strspn(v, " \t");
	size_t nv = strlen(v);
	while (nv && (v[nv - 1] == ' ' || v[nv - 1] == '\t' || v[nv - 1] == '\n'))
		nv--;
	return kv_set(t, n, s, (size_t)(dot - s), k, (size_t)(ke - k), v, nv);
}

static int write_conf(struct daemon_env *e, const struct daemon_env_conf *c, char *err)
{
	struct kv t[MAX_KEYS];
	int n = 0, rc = 0;
	kv_set0(t, &n, "listen", "unix", e->sock);
	kv_set0(t, &n, "listen", "tcp", "");
	kv_set0(t, &n, "engine", "planets", e->planets);
	kv_set0(t, &n, "engine", "workers", "2");
	kv_set0(t, &n, "engine", "cache_mb", "64");
	kv_set0(t, &n, "log", "level", "warn");
	if (c && c->token) {
		char p[128], tok[256];
		snprintf(p, sizeof p, "%s/token", e->dir);
		snprintf(tok, sizeof tok, "%s\n", c->token);
		if ((rc = write_text(p, tok)) || (rc = kv_set0(t, &n, "listen", "token_file", p)))
			return rc;
	}
	bool level_set = false;
	for (const char *const *s = c && c->set ? c->set : NULL; s && *s; s++) {
		if ((rc = kv_line(t, &n, *s, err)))
			return rc;
		level_set |= strncmp(*s + strspn(*s, " \t"), "log.level", 9) == 0;
	}
	const char *u = kv_get(t, n, "listen", "unix");
	if (!*u)
		e->sock[0] = '\0';
	else if ((rc = *u == '/' ? pathf(e->sock, sizeof e->sock, "%s", u)
				 : pathf(e->sock, sizeof e->sock, "%s/%s", e->dir, u)))
		return rc;
	e->tcp = *kv_get(t, n, "listen", "tcp") != '\0';
	if (e->tcp && !level_set)
		kv_set0(t, &n, "log", "level", "info"); /* the port is read from the log */

	FILE *f = fopen(e->conf, "w");
	if (!f)
		return -errno;
	/* grouped by section, in the order each first appears */
	for (int i = 0; i < n; i++) {
		bool first = true;
		for (int j = 0; j < i && first; j++)
			first = strcmp(t[j].sec, t[i].sec) != 0;
		if (!first)
			continue;
		fprintf(f, "[%s]\n", t[i].sec);
		for (int j = i; j < n; j++)
			if (strcmp(t[j].sec, t[i].sec) == 0)
				fprintf(f, "%s = %s\n", t[j].key, t[j].val);
	}
	return fclose(f) ? -errno : 0;
}

/* ---- the process -------------------------------------------------------------------------- */

/* Whether the daemon accepts connections on its Unix socket yet. */
static bool socket_up(const char *path)
{
	int s = socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (s < 0)
		return false;
	struct sockaddr_un a = { .sun_family = AF_UNIX };
	bool ok = pathf(a.sun_path, sizeof a.sun_path, "%s", path) == 0 &&
		  connect(s, (struct sockaddr *)&a, sizeof a) == 0;
	close(s);
	return ok;
}

/* The port of the last "listening on tcp:HOST:PORT" line in the log (0: none). */
static int log_port(const struct daemon_env *e)
{
	char *l = daemon_env_log_read(e);
	int port = 0;
	for (char *p = l; (p = strstr(p, "listening on tcp:")); p++) {
		char *end = p + strcspn(p, "\n");
		char *colon = end;
		while (colon > p && *colon != ':')
			colon--;
		port = atoi(colon + 1);
	}
	free(l);
	return port;
}

static void print_log(const struct daemon_env *e, const char *why)
{
	char *l = daemon_env_log_read(e);
	size_t len = strlen(l);
	fprintf(stderr, "clipmapd %s; its log (end):\n%s\n", why, l + (len > 3000 ? len - 3000 : 0));
	free(l);
}

int daemon_env_wait_ready(struct daemon_env *e, int timeout_ms)
{
	if (e->daemon <= 0)
		return -ESRCH;
	long long end = (long long)clock_now_ms() + timeout_ms;
	for (;;) {
		int st;
		if (waitpid(e->daemon, &st, WNOHANG) == e->daemon) {
			e->daemon = 0;
			return -ECHILD;
		}
		bool up = (!e->sock[0] || socket_up(e->sock)) &&
			  (!e->tcp || daemon_env_log_count(e, "clipmapd ready") >= e->starts);
		if (up) {
			e->port = e->tcp ? log_port(e) : 0;
			return e->tcp && e->port <= 0 ? -EPROTO : 0;
		}
		if ((long long)clock_now_ms() >= end)
			return -ETIMEDOUT;
		nap();
	}
}

/* Starts the daemon on the config already written and waits for it. */
static int launch(struct daemon_env *e, char *err)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapd", e->bindir);
	if (e->log_fd <= 0)
		e->log_fd = open(e->log, O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
	if (e->log_fd <= 0) {
		int rc = -errno;
		err_set(err, "%s: %s", e->log, strerror(-rc));
		return rc;
	}
	pid_t pid = fork();
	if (pid < 0) {
		int rc = -errno;
		err_set(err, "fork: %s", strerror(-rc));
		return rc;
	}
	if (pid == 0) {
		dup2(e->log_fd, 2);
		execl(exe, exe, "-c", e->conf, (char *)NULL);
		_exit(127);
	}
	e->daemon = pid;
	e->port = 0;
	e->starts++;
	int rc = daemon_env_wait_ready(e, DAEMON_ENV_START_MS);
	if (rc == -ECHILD) {
		print_log(e, "exited at start");
		err_set(err, "clipmapd exited at start (config %s)", e->conf);
	} else if (rc == -ETIMEDOUT) {
		print_log(e, "did not get ready in time");
		err_set(err, "clipmapd did not accept on %s within %d ms",
		    e->sock[0] ? e->sock : "tcp", DAEMON_ENV_START_MS);
	} else if (rc) {
		err_set(err, "clipmapd: no TCP port in its log %s", e->log);
	}
	return rc;
}

int daemon_env_start(struct daemon_env *e, const struct daemon_env_conf *c, char err[256])
{
	if (e->daemon > 0)
		return -EBUSY;
	int rc;
	if (e->nplanets == 0) {
		char from[700];
		snprintf(from, sizeof from, "%s/conf/planets/procedural.ini", e->root);
		if ((rc = daemon_env_planet_copy(e, from, NULL, 0))) {
			err_set(err, "%s: %s", from, strerror(-rc));
			return rc;
		}
	}
	if ((rc = write_conf(e, c, err))) {
		if (rc != -EINVAL)
			err_set(err, "%s: %s", e->conf, strerror(-rc));
		return rc;
	}
	return launch(e, err);
}

int daemon_env_signal(struct daemon_env *e, int sig)
{
	if (e->daemon <= 0)
		return -ESRCH;
	return kill(e->daemon, sig) ? -errno : 0;
}

int daemon_env_stop(struct daemon_env *e, int sig, int *status)
{
	if (e->daemon <= 0)
		return -ESRCH;
	if (sig && kill(e->daemon, sig))
		return -errno;
	int st = 0;
	pid_t r;
	while ((r = waitpid(e->daemon, &st, 0)) < 0 && errno == EINTR) {
	}
	if (r != e->daemon)
		return -errno;
	e->daemon = 0;
	if (status)
		*status = st;
	return 0;
}

int daemon_env_restart(struct daemon_env *e, char err[256])
{
	if (e->daemon > 0) {
		int rc = daemon_env_stop(e, SIGTERM, NULL);
		if (rc)
			return rc;
	}
	return launch(e, err);
}

void daemon_env_fini(struct daemon_env *e)
{
	if (e->daemon > 0) {
		kill(e->daemon, SIGTERM);
		long long end = (long long)clock_now_ms() + STOP_MS;
		int st;
		while (waitpid(e->daemon, &st, WNOHANG) == 0) {
			if ((long long)clock_now_ms() >= end) {
				fprintf(stderr, "clipmapd (pid %d) ignored SIGTERM for %d s: killing it\n",
					(int)e->daemon, STOP_MS / 1000);
				kill(e->daemon, SIGKILL);
				waitpid(e->daemon, &st, 0);
				break;
			}
			nap();
		}
		e->daemon = 0;
	}
	if (e->log_fd > 0) {
		close(e->log_fd);
		e->log_fd = -1;
	}
	if (e->dir[0]) {
		char cmd[200];
		snprintf(cmd, sizeof cmd, "rm -rf '%s'", e->dir);
		if (system(cmd) != 0)
			fprintf(stderr, "could not remove %s\n", e->dir);
		e->dir[0] = '\0';
	}
}

/* ---- the log ------------------------------------------------------------------------------ */

char *daemon_env_log_read(const struct daemon_env *e)
{
	FILE *f = e->log[0] ? fopen(e->log, "r") : NULL;
	char *buf = NULL;
	size_t len = 0, cap = 0, r;
	do {
		if (len + 65536 + 1 > cap) {
			cap = cap ? cap * 2 : 65536 * 2;
			char *nb = realloc(buf, cap);
			if (!nb) {
				fprintf(stderr, "daemon_env: out of memory\n");
				abort();
			}
			buf = nb;
		}
		r = f ? fread(buf + len, 1, 65536, f) : 0;
		len += r;
	} while (r > 0);
	buf[len] = '\0';
	if (f)
		fclose(f);
	return buf;
}

int daemon_env_log_count(const struct daemon_env *e, const char *what)
{
	char *l = daemon_env_log_read(e);
	int c = 0;
	for (char *p = l; (p = strstr(p, what)); p++)
		c++;
	free(l);
	return c;
}

bool daemon_env_log_wait(const struct daemon_env *e, const char *what, int count, int timeout_ms)
{
	long long end = (long long)clock_now_ms() + timeout_ms;
	do {
		if (daemon_env_log_count(e, what) >= count)
			return true;
		nap();
	} while ((long long)clock_now_ms() < end);
	return false;
}

/* ---- the common case ---------------------------------------------------------------------- */

int daemon_env_setup(struct daemon_env *e, const char *tag, const char *client)
{
	if (daemon_env_init(e, tag))
		return -1;
	if (!daemon_env_built(e, "clipmapd") || (client && !daemon_env_built(e, client)))
		return 0; /* the tests skip */
	char err[256];
	int rc = daemon_env_start(e, NULL, err);
	if (rc)
		fprintf(stderr, "daemon_env: %s\n", err);
	return rc ? -1 : 0;
}

void daemon_env_teardown(struct daemon_env *e)
{
	daemon_env_fini(e);
}
