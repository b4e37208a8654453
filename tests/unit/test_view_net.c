/* clipmapview --connect against a real clipmapd: the daemon runs as a process on a temporary
 * Unix socket with a temporary config and planets directory (the procedural planet: no data
 * files); clipmapview runs as a real process twice per camera, once over the daemon
 * (--connect SOCKET --planet procedural) and once with the engine in-process (--planet FILE),
 * both --wait-complete. The two pictures must be the same (decoded pixels, within a small
 * tolerance for the GL rasteriser). A socket nobody listens on is exit 1 with a message
 * naming it. Skipped when the daemon or the viewer was not built, or no GL context exists.
 */
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <setjmp.h>
#include <signal.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "img.h"

struct env {
	char bindir[512];  /* build/ */
	char root[600];	   /* the repository (build/..) */
	char dir[64];	   /* temporary */
	char sock[128];
	char conf[128];
	char planets[128];
	pid_t daemon;
	int daemon_log; /* its stderr, read at teardown when something failed */
};

static int run_capture(char *const argv[], char *out, size_t n)
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
		execv(argv[0], argv);
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

static int write_file(const char *path, const char *text)
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

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	ssize_t l = readlink("/proc/self/exe", e->bindir, sizeof e->bindir - 1);
	if (l <= 0)
		return -1;
	e->bindir[l] = '\0';
	*strrchr(e->bindir, '/') = '\0'; /* build/tests */
	*strrchr(e->bindir, '/') = '\0'; /* build */
	snprintf(e->root, sizeof e->root, "%s/..", e->bindir);
	*state = e;
	char d[600], c[600];
	snprintf(d, sizeof d, "%s/clipmapd", e->bindir);
	snprintf(c, sizeof c, "%s/clipmapview", e->bindir);
	if (access(d, X_OK) || access(c, X_OK)) {
		e->daemon = 0;
		return 0; /* the tests skip */
	}
	snprintf(e->dir, sizeof e->dir, "/tmp/test_view_net_XXXXXX");
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
	if (write_file(e->conf, text))
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

static int teardown(void **state)
{
	struct env *e = *state;
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
	free(e);
	return 0;
}

#define NEED_DAEMON(e)                 \
	do {                           \
		if ((e)->daemon <= 0)  \
			skip();        \
	} while (0)

/* Runs clipmapview with the given arguments (NULL-terminated) plus the common ones. */
static int view(struct env *e, char *out, size_t n, const char *camera, const char *png,
		const char *a0, ...)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->bindir);
	char *argv[32] = { exe, "--camera", (char *)camera, "--size", "320x240", "--wait-complete",
			   "--timeout", "60", "-o", (char *)png };
	int argc = 10;
	va_list ap;
	va_start(ap, a0);
	for (const char *a = a0; a && argc < 31; a = va_arg(ap, const char *))
		argv[argc++] = (char *)a;
	va_end(ap);
	argv[argc] = NULL;
	return run_capture(argv, out, n);
}

/* Mean absolute difference per channel, and the share of pixels differing by more than 8. */
static void compare(const char *a, const char *b, double *mad, double *share)
{
	void *pa, *pb;
	struct img_info ia, ib;
	char err[256];
	assert_int_equal(img_read(a, IMG_U8, &pa, &ia, err), 0);
	assert_int_equal(img_read(b, IMG_U8, &pb, &ib, err), 0);
	assert_int_equal(ia.width, 320);
	assert_int_equal(ia.height, 240);
	assert_int_equal(ib.width, ia.width);
	assert_int_equal(ib.height, ia.height);
	assert_int_equal(ib.channels, ia.channels);
	const unsigned char *x = pa, *y = pb;
	size_t np = (size_t)ia.width * ia.height, nc = (size_t)ia.channels, far = 0;
	double sum = 0;
	for (size_t i = 0; i < np; i++) {
		bool big = false;
		for (size_t c = 0; c < nc; c++) {
			int d = abs((int)x[i * nc + c] - (int)y[i * nc + c]);
			sum += d;
			big |= d > 8;
		}
		far += big;
	}
	*mad = sum / (double)(np * nc);
	*share = (double)far / (double)np;
	free(pa);
	free(pb);
}

/* Whether the picture has terrain in it (not one flat colour): a broken source shows the
 * clear colour only, and two such pictures would compare equal. */
static double spread(const char *path)
{
	void *p;
	struct img_info in;
	assert_int_equal(img_read(path, IMG_U8, &p, &in, NULL), 0);
	const unsigned char *x = p;
	int lo = 255, hi = 0;
	for (size_t i = 0; i < (size_t)in.width * in.height; i++) {
		int g = x[i * (size_t)in.channels + 1];
		lo = g < lo ? g : lo;
		hi = g > hi ? g : hi;
	}
	free(p);
	return hi - lo;
}

static void connect_equals_local(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	static const char *const cams[] = {
		"20,30,6000000,0,-90",	   /* the planet from orbit */
		"-9,-68,3000,30,-20",	   /* low over a range, oblique */
	};
	char planet[300];
	snprintf(planet, sizeof planet, "%s/procedural.ini", e->planets);
	for (size_t i = 0; i < sizeof cams / sizeof cams[0]; i++) {
		char out[8192], a[200], b[200];
		snprintf(a, sizeof a, "%s/net%zu.png", e->dir, i);
		snprintf(b, sizeof b, "%s/local%zu.png", e->dir, i);
		int rc = view(e, out, sizeof out, cams[i], b, "--planet", planet, NULL);
		if (rc == 1 && strstr(out, "no OpenGL context")) {
			fprintf(stderr, "no GL context here: %s", out);
			skip();
		}
		if (rc != 0)
			fprintf(stderr, "local: %s", out);
		assert_int_equal(rc, 0);
		rc = view(e, out, sizeof out, cams[i], a, "--connect", e->sock, "--planet",
			  "procedural", NULL);
		if (rc != 0)
			fprintf(stderr, "connect: %s", out);
		assert_int_equal(rc, 0);
		double mad, share;
		compare(a, b, &mad, &share);
		fprintf(stderr, "camera %s: mean |diff| %.3f, pixels off by > 8: %.4f%%\n", cams[i],
			mad, 100 * share);
		assert_true(spread(a) > 40);
		assert_true(mad < 0.5);
		assert_true(share < 0.002);
	}
}

static void unknown_planet_is_exit_1(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[8192], a[200];
	snprintf(a, sizeof a, "%s/none.png", e->dir);
	int rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", e->sock, "--planet",
		      "atlantis", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "atlantis"));
	assert_int_equal(access(a, F_OK), -1);
}

static void bad_socket_is_exit_1_naming_it(void **state)
{
	struct env *e = *state;
	NEED_DAEMON(e);
	char out[8192], a[200], s[200];
	snprintf(a, sizeof a, "%s/none.png", e->dir);
	snprintf(s, sizeof s, "%s/nobody-here.sock", e->dir);
	int rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", s, "--planet",
		      "procedural", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, s));
	assert_non_null(strstr(out, "cannot connect"));
	assert_non_null(strstr(out, "clipmapd running"));
	assert_int_equal(access(a, F_OK), -1);
	/* a TCP port nobody listens on (port 1 on loopback) */
	rc = view(e, out, sizeof out, "0,0,1000,0,-30", a, "--connect", "127.0.0.1:1", "--planet",
		  "procedural", NULL);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "127.0.0.1:1"));
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(connect_equals_local),
		cmocka_unit_test(unknown_planet_is_exit_1),
		cmocka_unit_test(bad_socket_is_exit_1_naming_it),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
