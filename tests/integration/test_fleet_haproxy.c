/* A fleet behind HAProxy, and viewers that survive losing their daemon. Real processes: three
 * clipmapd (tests/support/daemon_env, loopback TCP on free ports), a real haproxy on free
 * loopback ports with the health check of conf/haproxy.cfg.example (its tcp-check lines,
 * copied) and a decoy backend that accepts connections but speaks no protocol, and
 * clipmapview flying offscreen (--stats, one JSON line per frame).
 *  - The example config is valid for haproxy and its check bytes are the protocol's HELLO,
 *    HELLO_OK header and BYE (encoded here by common/proto).
 *  - The check marks the decoy down and the daemons up.
 *  - A viewer flies through HAProxy; its daemon is killed with kill -9 mid-flight; the viewer
 *    reconnects through HAProxy to another daemon, keeps drawing, and its flight completes.
 *  - The same with a daemon that hangs (SIGSTOP: its sockets stay open): the health check
 *    marks it down, HAProxy cuts its sessions, the viewer reconnects to the third daemon.
 *  - Directly on a daemon's socket: the daemon is down for 3 s; frames go on at their pace
 *    (no frame waits for the reconnect), drawing what is resident, saying "reconnecting
 *    (attempt N)"; when the daemon is back the viewer reconnects, sends its want-set again
 *    and gets tiles again.
 *  - A viewer started before its daemon (--connect-wait) connects once the daemon is up.
 * Skipped when the programs were not built, no GL context exists, or (the HAProxy cases)
 * haproxy is not installed.
 */
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netinet/in.h>
#include <setjmp.h>
#include <signal.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <cmocka.h>

#include "common/clock.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/picture.h"
#include "support/slow.h"

#define NDAEMONS 3

struct env {
	struct daemon_env d[NDAEMONS];
	struct daemon_env solo; /* a daemon of its own, for the direct cases */
	bool built, haproxy;
	pid_t hap, viewer;
	int front, stats; /* HAProxy's frontend and stats ports */
	int decoy;	  /* a listening socket that never answers */
	char viewer_log[200];
};

static void sleep_s(double s)
{
	struct timespec ts = { (time_t)s, (long)((s - (double)(time_t)s) * 1e9) };
	while (nanosleep(&ts, &ts) < 0 && errno == EINTR) {
	}
}

/* A free loopback port (bound to 0 and released), or with listening: the socket itself. */
static int loopback_port(bool listening, int *fd)
{
	int s = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	if (s < 0)
		return -1;
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t al = sizeof a;
	if (bind(s, (struct sockaddr *)&a, sizeof a) || getsockname(s, (struct sockaddr *)&a, &al) ||
	    (listening && listen(s, 16))) {
		close(s);
		return -1;
	}
	int port = ntohs(a.sin_port);
	if (listening)
		*fd = s;
	else
		close(s);
	return port;
}

/* Starts argv with stdout and stderr into log. Returns the pid, or -1. */
static pid_t spawn(char *const argv[], const char *log)
{
	pid_t pid = fork();
	if (pid != 0)
		return pid;
	int fd = open(log, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
	if (fd >= 0) {
		dup2(fd, 1);
		dup2(fd, 2);
	}
	execvp(argv[0], argv);
	_exit(127);
}

/* Waits for pid up to timeout_s; returns its exit status (128 + signal), or -1 on timeout
 * (the process is then killed). */
static int reap(pid_t pid, double timeout_s)
{
	double end = clock_now_s() + timeout_s;
	for (;;) {
		int st;
		pid_t r = waitpid(pid, &st, WNOHANG);
		if (r == pid)
			return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
		if (r < 0 || clock_now_s() > end) {
			kill(pid, SIGKILL);
			waitpid(pid, NULL, 0);
			return -1;
		}
		sleep_s(0.05);
	}
}

static char *slurp(const char *path)
{
	FILE *f = fopen(path, "rb");
	if (!f)
		return calloc(1, 1);
	fseek(f, 0, SEEK_END);
	long n = ftell(f);
	fseek(f, 0, SEEK_SET);
	char *s = calloc(1, (size_t)(n > 0 ? n : 0) + 1);
	if (s && n > 0 && fread(s, 1, (size_t)n, f) != (size_t)n)
		s[0] = '\0';
	fclose(f);
	return s;
}

static void print_file(const char *what, const char *path)
{
	char *s = slurp(path);
	fprintf(stderr, "---- %s (%s)\n%s\n----\n", what, path, s ? s : "");
	free(s);
}

/* The number after "key": in line (a --stats JSON line or clipmapctl status --json), or -1. */
static double num(const char *line, const char *key)
{
	char k[80];
	snprintf(k, sizeof k, "\"%s\":", key);
	const char *p = strstr(line, k);
	return p ? strtod(p + strlen(k), NULL) : -1;
}

/* A daemon's STATS figure, from clipmapctl status --json over its Unix socket. */
static double dstat(const struct daemon_env *d, const char *key)
{
	char exe[600], out[65536];
	snprintf(exe, sizeof exe, "%s/clipmapctl", d->bindir);
	char *argv[] = { exe, "-s", (char *)d->sock, "status", "--json", NULL };
	if (daemon_env_run(argv, out, sizeof out) != 0)
		return -1;
	/* "key": value, with a space after the colon */
	char k[80];
	snprintf(k, sizeof k, "\"%s\": ", key);
	const char *p = strstr(out, k);
	return p ? strtod(p + strlen(k), NULL) : -1;
}

/* HAProxy's status ("UP", "DOWN", …) of server `name` in backend clipmapd, from its CSV
 * stats page, into st[32]; "" when it does not answer. */
static void hap_status(struct env *e, const char *name, char st[32])
{
	st[0] = '\0';
	int s = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)e->stats),
				 .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	if (s < 0 || connect(s, (struct sockaddr *)&a, sizeof a)) {
		if (s >= 0)
			close(s);
		return;
	}
	static const char req[] = "GET /;csv HTTP/1.0\r\nHost: haproxy\r\n\r\n";
	char buf[16384];
	size_t len = 0;
	ssize_t r;
	if (write(s, req, sizeof req - 1) == (ssize_t)(sizeof req - 1))
		while (len < sizeof buf - 1 && (r = read(s, buf + len, sizeof buf - 1 - len)) > 0)
			len += (size_t)r;
	close(s);
	buf[len] = '\0';
	char want[64];
	snprintf(want, sizeof want, "\nclipmapd,%s,", name);
	const char *p = strstr(buf, want);
	if (!p)
		return;
	p++;
	for (int field = 1; field < 18 && p; field++) { /* status is the 18th field */
		p = strchr(p, ',');
		p = p ? p + 1 : NULL;
	}
	if (p)
		snprintf(st, 32, "%.*s", (int)strcspn(p, ",\n"), p);
}

/* The tcp-check lines of conf/haproxy.cfg.example, in order, each "\t…\n", into out. */
static void example_check_lines(const char *root, char *out, size_t n)
{
	char path[700], line[512];
	snprintf(path, sizeof path, "%s/conf/haproxy.cfg.example", root);
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	out[0] = '\0';
	while (fgets(line, sizeof line, f)) {
		const char *s = line + strspn(line, " \t");
		if (strncmp(s, "option tcp-check", 16) == 0 || strncmp(s, "tcp-check ", 10) == 0) {
			size_t l = strlen(out);
			snprintf(out + l, n - l, "\t%s", s);
		}
	}
	fclose(f);
}

static int start_haproxy(struct env *e)
{
	struct daemon_env *d0 = &e->d[0];
	char checks[2048], cfg[4096], path[200], log[200];
	example_check_lines(d0->root, checks, sizeof checks);
	e->front = loopback_port(false, NULL);
	e->stats = loopback_port(false, NULL);
	int decoy_port = loopback_port(true, &e->decoy);
	if (e->front <= 0 || e->stats <= 0 || decoy_port <= 0)
		return -1;
	int n = snprintf(cfg, sizeof cfg,
			 "global\n\tmaxconn 256\n"
			 "defaults\n\tmode tcp\n\ttimeout connect 2s\n\tretries 3\n"
			 "\toption redispatch\n\ttimeout client 1h\n\ttimeout server 1h\n"
			 "\ttimeout tunnel 24h\n\ttimeout check 1s\n"
			 "frontend clipmap\n\tbind 127.0.0.1:%d\n\tdefault_backend clipmapd\n"
			 "backend clipmapd\n\tbalance leastconn\n%s"
			 "\tdefault-server check inter 300ms fall 2 rise 1 "
			 "on-marked-down shutdown-sessions\n"
			 "\tserver decoy 127.0.0.1:%d\n",
			 e->front, checks, decoy_port);
	for (int i = 0; i < NDAEMONS; i++)
		n += snprintf(cfg + n, sizeof cfg - (size_t)n, "\tserver d%d 127.0.0.1:%d\n", i,
			      e->d[i].port);
	snprintf(cfg + n, sizeof cfg - (size_t)n,
		 "listen stats\n\tmode http\n\tbind 127.0.0.1:%d\n\tstats enable\n"
		 "\tstats uri /\n\ttimeout client 10s\n\ttimeout server 10s\n", e->stats);
	snprintf(path, sizeof path, "%s/haproxy.cfg", d0->dir);
	snprintf(log, sizeof log, "%s/haproxy.log", d0->dir);
	FILE *f = fopen(path, "w");
	if (!f || fputs(cfg, f) < 0 || fclose(f))
		return -1;
	char *argv[] = { "haproxy", "-db", "-f", path, NULL };
	e->hap = spawn(argv, log);
	return e->hap > 0 ? 0 : -1;
}

static int setup(void **state)
{
	struct env *e = calloc(1, sizeof *e);
	*state = e;
	if (!e)
		return -1;
	e->decoy = -1;
	static const char *const set[] = { "listen.tcp = 127.0.0.1:0", "engine.workers = 1",
					   "listen.max_preauth_per_peer = 32", NULL };
	struct daemon_env_conf c = { .set = set };
	char err[256];
	if (daemon_env_init(&e->solo, "test_fleet_solo"))
		return -1;
	for (int i = 0; i < NDAEMONS; i++)
		if (daemon_env_init(&e->d[i], "test_fleet"))
			return -1;
	e->built = daemon_env_built(&e->d[0], "clipmapd") &&
		   daemon_env_built(&e->d[0], "clipmapview") &&
		   daemon_env_built(&e->d[0], "clipmapctl");
	if (!e->built)
		return 0;
	char out[512];
	char *hv[] = { "haproxy", "-v", NULL };
	e->haproxy = daemon_env_run(hv, out, sizeof out) == 0;
	if (!e->haproxy) {
		fprintf(stderr, "haproxy is not installed: the HAProxy cases skip (make deps)\n");
		return 0;
	}
	for (int i = 0; i < NDAEMONS; i++)
		if (daemon_env_start(&e->d[i], &c, err)) {
			fprintf(stderr, "daemon %d: %s\n", i, err);
			return -1;
		}
	return start_haproxy(e);
}

static int teardown(void **state)
{
	struct env *e = *state;
	if (e->viewer > 0)
		reap(e->viewer, 0);
	if (e->hap > 0) {
		kill(e->hap, SIGTERM);
		reap(e->hap, 10);
	}
	if (e->decoy >= 0)
		close(e->decoy);
	for (int i = 0; i < NDAEMONS; i++) {
		daemon_env_signal(&e->d[i], SIGCONT); /* a hung one, so that it can stop */
		daemon_env_fini(&e->d[i]);
	}
	daemon_env_fini(&e->solo);
	free(e);
	return 0;
}

/* Skips (saying so) when the viewer found no GL context. */
static void skip_without_gl(const char *log)
{
	char *s = slurp(log);
	bool none = s && strstr(s, "no OpenGL context");
	free(s);
	if (none) {
		fprintf(stderr, "no GL context here\n");
		skip();
	}
}

/* Waits (up to timeout_s) for the viewer to end; it must end with status 0 (its log is
 * printed when not). */
static void viewer_done(struct env *e, double timeout_s)
{
	int rc = reap(e->viewer, timeout_s);
	e->viewer = 0;
	if (rc != 0) {
		skip_without_gl(e->viewer_log);
		print_file("viewer", e->viewer_log);
	}
	assert_int_equal(rc, 0);
}

/* The viewer's stderr says both a and b. */
static void viewer_said(struct env *e, const char *a, const char *b)
{
	char *log = slurp(e->viewer_log);
	bool ok = log && strstr(log, a) && strstr(log, b);
	free(log);
	if (!ok)
		print_file("viewer", e->viewer_log);
	assert_true(ok);
}

/* Starts clipmapview flying keys (CSV lines) through target at 10 frames a second with
 * --stats into stats, and -o png (a frame pattern) unless NULL. */
static void fly(struct env *e, const char *dir, const char *target, const char *keys, int steps,
		const char *stats, const char *png)
{
	char exe[600], csv[200], st[16];
	snprintf(exe, sizeof exe, "%s/clipmapview", e->d[0].bindir);
	snprintf(csv, sizeof csv, "%s/flight.csv", dir);
	snprintf(st, sizeof st, "%d", steps);
	snprintf(e->viewer_log, sizeof e->viewer_log, "%s/viewer.log", dir);
	FILE *f = fopen(csv, "w");
	assert_non_null(f);
	fprintf(f, "lat,lon,alt,heading,pitch\n%s", keys);
	assert_int_equal(fclose(f), 0);
	char *argv[] = { exe, "--connect", (char *)target, "--planet", "procedural", "--flight",
			 csv, "--steps", st, "--fps", "10", "--size", "160x120", "--stats",
			 (char *)stats, png ? "-o" : NULL, (char *)png, NULL };
	e->viewer = spawn(argv, e->viewer_log);
	assert_true(e->viewer > 0);
}

/* The --stats lines of a finished flight. */
struct frames {
	char **line;
	int n;
};

static void frames_read(const char *path, struct frames *fr)
{
	FILE *f = fopen(path, "r");
	assert_non_null(f);
	char buf[2048];
	fr->line = NULL;
	fr->n = 0;
	while (fgets(buf, sizeof buf, f)) {
		fr->line = realloc(fr->line, (size_t)(fr->n + 1) * sizeof *fr->line);
		assert_non_null(fr->line);
		fr->line[fr->n++] = strdup(buf);
	}
	fclose(f);
}

static void frames_free(struct frames *fr)
{
	for (int i = 0; i < fr->n; i++)
		free(fr->line[i]);
	free(fr->line);
}

/* ---- the example config ------------------------------------------------------------------ */

static void hex_of(const struct proto_msg *m, char *out, size_t n)
{
	struct pbuf b;
	pbuf_init(&b);
	assert_true(proto_encode(&b, m, NULL) > 0);
	out[0] = '\0';
	for (size_t i = 0; i < b.len && 2 * i + 3 < n; i++)
		snprintf(out + 2 * i, 3, "%02x", b.data[i]);
	pbuf_fini(&b);
}

static void example_config_checks_with_the_protocol(void **state)
{
	struct env *e = *state;
	if (!e->built || !e->haproxy)
		skip();
	char path[700], out[4096];
	snprintf(path, sizeof path, "%s/conf/haproxy.cfg.example", e->d[0].root);
	char *argv[] = { "haproxy", "-c", "-f", path, NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc != 0)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	char checks[2048], hello[256], bye[64], want[600];
	example_check_lines(e->d[0].root, checks, sizeof checks);
	hex_of(&(struct proto_msg){ .type = PROTO_HELLO,
				    .hello = { .ver_min = PROTO_VERSION, .ver_max = PROTO_VERSION,
					       .name = "haproxy-check" } },
	       hello, sizeof hello);
	hex_of(&(struct proto_msg){ .type = PROTO_BYE }, bye, sizeof bye);
	snprintf(want, sizeof want,
		 "\toption tcp-check\n\ttcp-check connect\n\ttcp-check send-binary %s\n"
		 "\ttcp-check expect binary 434c4d50%02x000200\n\ttcp-check send-binary %s\n",
		 hello, PROTO_VERSION, bye);
	assert_string_equal(checks, want);
}

/* ---- through HAProxy ------------------------------------------------------------------- */

/* A flight through HAProxy (60 frames over 0.1° and down, then 100 hovering, 10 a second);
 * mid-flight its daemon gets sig: SIGKILL (dead: its sockets close), or SIGSTOP (hung: its
 * sockets stay open; the health check marks it down and HAProxy cuts its sessions, SIGCONT
 * afterwards). The viewer must reconnect through HAProxy to another daemon, keep its pace
 * and complete frames, and end with status 0. */
static void lose_daemon_mid_flight(struct env *e, int sig, const char *tag)
{
	const char *dir = e->d[0].dir;
	char target[64], stats[200], png[200];
	double sent_before[NDAEMONS];
	for (int i = 0; i < NDAEMONS; i++)
		sent_before[i] = e->d[i].daemon > 0 ? dstat(&e->d[i], "tiles.sent") : -1;
	snprintf(target, sizeof target, "127.0.0.1:%d", e->front);
	snprintf(stats, sizeof stats, "%s/%s.jsonl", dir, tag);
	snprintf(png, sizeof png, "%s/%s_%%03d.png", dir, tag);
	fly(e, dir, target, "20,30,20000,70,-30\n20.02,30.1,15000,70,-30\n20.02,30.1,15000,70,-30\n",
	    80, stats, png);
	/* Its daemon: the one that sends it tiles. */
	int victim = -1;
	double end = clock_now_s() + test_slow(30);
	while (victim < 0 && clock_now_s() < end) {
		for (int i = 0; i < NDAEMONS && victim < 0; i++)
			if (sent_before[i] >= 0 && dstat(&e->d[i], "tiles.sent") > sent_before[i])
				victim = i;
		if (victim < 0)
			sleep_s(0.2);
		if (waitpid(e->viewer, NULL, WNOHANG) == e->viewer) {
			e->viewer = 0;
			skip_without_gl(e->viewer_log);
			print_file("viewer", e->viewer_log);
			fail_msg("the viewer ended before any daemon sent a tile");
		}
	}
	assert_true(victim >= 0);
	sleep_s(1.5); /* mid-flight, tiles coming in */
	for (int i = 0; i < NDAEMONS; i++)
		if (sent_before[i] >= 0)
			sent_before[i] = dstat(&e->d[i], "tiles.sent");
	if (sig == SIGKILL)
		assert_int_equal(daemon_env_stop(&e->d[victim], SIGKILL, NULL), 0);
	else
		assert_int_equal(daemon_env_signal(&e->d[victim], sig), 0);
	fprintf(stderr, "daemon d%d: signal %d (%s)\n", victim, sig, strsignal(sig));

	viewer_done(e, test_slow(120));
	/* Another daemon took it over and sent it tiles. */
	bool other = false;
	for (int i = 0; i < NDAEMONS; i++)
		if (i != victim && sent_before[i] >= 0 &&
		    dstat(&e->d[i], "tiles.sent") > sent_before[i])
			other = true;
	if (sig == SIGSTOP)
		assert_int_equal(daemon_env_signal(&e->d[victim], SIGCONT), 0);
	assert_true(other);

	struct frames fr;
	frames_read(stats, &fr);
	assert_int_equal(fr.n, 161);
	int after = 0, complete_after = 0;
	double prev_t = -1;
	bool lost = false;
	for (int i = 0; i < fr.n; i++) {
		const char *l = fr.line[i];
		/* From the loss on, no frame waits on the network: each is short and they keep
		 * their pace (the first frames, which compile shaders, are not the point). */
		lost |= strstr(l, "\"link\":\"reconnecting") || num(l, "reconnects") >= 1;
		double t = num(l, "t");
		if (lost && num(l, "ms") >= 1000)
			fail_msg("frame %d took %.0f ms: %s", i, num(l, "ms"), l);
		if (lost && t - prev_t > 1.5)
			fail_msg("frame %d came %.2f s after the one before: %s", i, t - prev_t, l);
		prev_t = t;
		if (num(l, "reconnects") >= 1) {
			after++;
			assert_true(num(l, "levels_drawn") >= 1);
			complete_after += strstr(l, "\"complete\":true") != NULL;
		}
	}
	fprintf(stderr, "%d frames after the reconnect, %d of them complete\n", after,
		complete_after);
	bool rec_last = num(fr.line[fr.n - 1], "reconnects") >= 1;
	bool up_last = strstr(fr.line[fr.n - 1], "\"link\":\"up\"") != NULL;
	frames_free(&fr);
	assert_true(after >= 20);
	/* A sanitizer build's viewer (llvmpipe under ASan) may not complete a frame in the
	 * flight's time: there the tiles the other daemon sent (above) and the picture (below)
	 * say the flight went on. */
	if (test_slow(1) <= 1)
		assert_true(complete_after >= 1);
	assert_true(rec_last);
	assert_true(up_last);
	snprintf(png, sizeof png, "%s/%s_160.png", dir, tag);
	assert_true(picture_spread(png) > 40);
	viewer_said(e, "lost the connection to 127.0.0.1:", "reconnected to 127.0.0.1:");
}

static void viewer_survives_its_daemon_killed(void **state)
{
	struct env *e = *state;
	if (!e->built || !e->haproxy)
		skip();
	/* The health check: the decoy (a socket that accepts and never answers) goes down, the
	 * daemons stay up. No viewer may be sent to the decoy, so this comes first. */
	char st[32];
	bool ready = false;
	double end = clock_now_s() + test_slow(20);
	while (!ready && clock_now_s() < end) {
		hap_status(e, "decoy", st);
		ready = strcmp(st, "DOWN") == 0;
		for (int i = 0; i < NDAEMONS && ready; i++) {
			char name[16];
			snprintf(name, sizeof name, "d%d", i);
			hap_status(e, name, st);
			ready = strcmp(st, "UP") == 0;
		}
		if (!ready)
			sleep_s(0.1);
	}
	if (!ready) {
		char log[200];
		snprintf(log, sizeof log, "%s/haproxy.log", e->d[0].dir);
		print_file("haproxy", log);
	}
	assert_true(ready);

	lose_daemon_mid_flight(e, SIGKILL, "kill");
}

/* A daemon that hangs (SIGSTOP) keeps its sockets open: the viewer cannot tell, but the
 * health check can; HAProxy marks it down and cuts its sessions (on-marked-down
 * shutdown-sessions), and the viewer reconnects to another. */
static void viewer_leaves_a_hung_daemon(void **state)
{
	struct env *e = *state;
	if (!e->built || !e->haproxy)
		skip();
	lose_daemon_mid_flight(e, SIGSTOP, "hang");
}

/* ---- directly on one daemon ------------------------------------------------------------- */

/* The daemon is away for 3 s: the frames go on, drawing what they hold. */
static void frames_go_on_while_the_daemon_is_away(void **state)
{
	struct env *e = *state;
	if (!e->built)
		skip();
	char err[256];
	struct daemon_env *d = &e->solo;
	static const char *const set[] = { "engine.workers = 1", NULL };
	if (d->daemon <= 0 && daemon_env_start(d, &(struct daemon_env_conf){ .set = set }, err))
		fail_msg("%s", err);
	char stats[200];
	snprintf(stats, sizeof stats, "%s/away.jsonl", d->dir);
	/* 16 s hovering, 10 frames a second */
	fly(e, d->dir, d->sock, "20,30,20000,0,-30\n20,30,20000,0,-30\n", 160, stats, NULL);
	double end = clock_now_s() + test_slow(30);
	while (dstat(d, "tiles.sent") < 20 && clock_now_s() < end)
		sleep_s(0.1);
	if (waitpid(e->viewer, NULL, WNOHANG) == e->viewer) {
		e->viewer = 0;
		skip_without_gl(e->viewer_log);
		print_file("viewer", e->viewer_log);
		fail_msg("the viewer ended early");
	}
	assert_int_equal(daemon_env_stop(d, SIGKILL, NULL), 0);
	sleep_s(3);
	if (daemon_env_restart(d, err))
		fail_msg("restart: %s", err);
	viewer_done(e, test_slow(120));

	struct frames fr;
	frames_read(stats, &fr);
	assert_int_equal(fr.n, 161);
	int away = 0, max_attempt = 0, complete_after = 0, tiles_after = 0, detail_away = -1;
	double prev_t = -1;
	for (int i = 0; i < fr.n; i++) {
		const char *l = fr.line[i];
		double t = num(l, "t");
		const char *a = strstr(l, "\"link\":\"reconnecting (attempt ");
		if (a) {
			away++;
			int n = atoi(a + strlen("\"link\":\"reconnecting (attempt "));
			max_attempt = n > max_attempt ? n : max_attempt;
			/* what it holds stays drawn, and the frame does not wait */
			assert_true(num(l, "levels_drawn") >= 1);
			detail_away = (int)fmax(detail_away, num(l, "ldetail"));
			assert_true(num(l, "ms") < 1000);
			if (prev_t >= 0 && t - prev_t > 1.0)
				fail_msg("frame %d came %.2f s after the one before while "
					 "reconnecting: %s", i, t - prev_t, l);
		}
		prev_t = t;
		if (num(l, "reconnects") == 1) {
			complete_after += strstr(l, "\"complete\":true") != NULL;
			tiles_after += (int)num(l, "tiles_received");
		}
	}
	fprintf(stderr, "%d frames while away (attempts up to %d, finest texture level %d), then "
		"%d tiles, %d frames complete\n", away, max_attempt, detail_away, tiles_after,
		complete_after);
	/* 3 s away at 10 frames a second, attempts after 0.1, 0.2, 0.4, … s (halved at most) */
	assert_true(away >= 15);
	assert_true(max_attempt >= 3);
	/* then tiles again (the want-set was sent again to a daemon with an empty cache), and
	 * the view refines from where it was (how far depends on the machine's load) */
	assert_true(tiles_after >= 10);
	assert_true(num(fr.line[fr.n - 1], "ldetail") >= detail_away);
	assert_int_equal((int)num(fr.line[fr.n - 1], "reconnects"), 1);
	frames_free(&fr);
	viewer_said(e, "reconnect attempt 1 failed: cannot connect to", "reconnected to");
}

/* A viewer started before its daemon (--connect-wait) connects once the daemon is up. */
static void viewer_waits_for_a_daemon_started_later(void **state)
{
	struct env *e = *state;
	if (!e->built)
		skip();
	struct daemon_env *d = &e->solo;
	if (d->daemon > 0)
		assert_int_equal(daemon_env_stop(d, SIGTERM, NULL), 0);
	char exe[600], png[200], limit[32], err[256];
	snprintf(exe, sizeof exe, "%s/clipmapview", d->bindir);
	snprintf(png, sizeof png, "%s/later.png", d->dir);
	snprintf(limit, sizeof limit, "%.0f", test_slow(60));
	snprintf(e->viewer_log, sizeof e->viewer_log, "%s/later.log", d->dir);
	char sock[200];
	snprintf(sock, sizeof sock, "%s/d.sock", d->dir);
	unlink(sock);
	char *argv[] = { exe, "--connect", sock, "--planet", "procedural", "--connect-wait", "30",
			 "--camera", "20,30,20000,0,-30", "--size", "160x120", "--wait-complete",
			 "--timeout", limit, "-o", png, NULL };
	e->viewer = spawn(argv, e->viewer_log);
	assert_true(e->viewer > 0);
	sleep_s(2);
	assert_int_equal(waitpid(e->viewer, NULL, WNOHANG), 0); /* still trying */
	static const char *const set[] = { "engine.workers = 1", NULL };
	if (daemon_env_start(d, &(struct daemon_env_conf){ .set = set }, err))
		fail_msg("%s", err);
	viewer_done(e, test_slow(90));
	viewer_said(e, "clipmapview: connected to ", " at attempt ");
	assert_true(picture_spread(png) > 40);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(example_config_checks_with_the_protocol),
		cmocka_unit_test(viewer_survives_its_daemon_killed),
		cmocka_unit_test(viewer_leaves_a_hung_daemon),
		cmocka_unit_test(frames_go_on_while_the_daemon_is_away),
		cmocka_unit_test(viewer_waits_for_a_daemon_started_later),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
