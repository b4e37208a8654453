/* TLS on clipmapd's TCP listener, end to end: the test makes its own CA and server certificate
 * with certtool (GnuTLS's CLI) in its temporary directory, starts a real clipmapd whose TCP
 * listener speaks TLS ([tls] cert, key; a token required), and drives it with the real
 * programs and the net.h client. What a user notices: `clipmapctl status` with the right CA
 * works (also through $CLIPMAP_TLS_CA), a wrong CA or a host name the certificate does not
 * carry is exit 1 with GnuTLS's verification status in the message and the daemon logs the
 * failed handshake; a plain client is told the listener speaks TLS, a non-TLS byte stream and
 * a silent connection are closed (the pre-auth guard's handshake_timeout covers the TLS
 * handshake); the token never crosses the wire in clear (a relay thread between client and
 * daemon records every byte; the control: a plain client's HELLO does show it); tiles over TLS
 * are the same bytes as over the Unix socket, also to a client that stops reading for a while;
 * clipmapview draws a complete frame over TLS;
 * the HTTP endpoint is HTTPS on the same certificate (curl, when installed).
 * Bad [tls] files stop clipmapd at start with the file and the problem named (an expired
 * certificate is a warning). SIGHUP loads a renewed certificate for new connections while an
 * open one keeps working, and the HTTPS endpoint shows it too; a bad renewal is refused and
 * the running certificate kept; the handshakes are counted in STATS.
 * Skipped, saying so, without certtool (package gnutls-bin) or the programs.
 */
#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>
#include <cmocka.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/img.h"
#include "common/proto.h"
#include "support/daemon_env.h"
#include "support/slow.h"

#define TOKEN "tls-test-token-7c1e94b2"
#define OUT_CAP (64u << 10)

static struct daemon_env E;
static bool have_certtool;
static char ca[200], wrong_ca[200], host_port[64];
static int http_port; /* [http] listen, HTTPS with [tls] */

/* ---- certificates ------------------------------------------------------------------- */

static int write_text(const char *path, const char *text)
{
	FILE *f = fopen(path, "w");
	if (!f)
		return -1;
	int rc = fputs(text, f) < 0 ? -1 : 0;
	return fclose(f) || rc ? -1 : 0;
}

/* Runs prog (a path, or a program in $PATH) with the arguments a0, ap (NULL-terminated),
 * its output into out. Returns its exit status. */
static int vrun(const char *prog, char *out, size_t n, const char *a0, va_list ap)
{
	char *argv[32] = { (char *)prog, (char *)a0 };
	int argc = 2;
	for (const char *a; a0 && argc < 31 && (a = va_arg(ap, const char *));)
		argv[argc++] = (char *)a;
	argv[argc] = NULL;
	return daemon_env_run(argv, out, n);
}

/* Runs certtool with args (NULL-terminated); says why when it fails. */
static int certtool(const char *a0, ...)
{
	static char out[OUT_CAP];
	va_list ap;
	va_start(ap, a0);
	int rc = vrun("certtool", out, sizeof out, a0, ap);
	va_end(ap);
	if (rc)
		fprintf(stderr, "certtool %s: exit %d: %s\n", a0, rc, out);
	return rc;
}

/* DIR/NAME.key and a certificate DIR/NAME.pem from template text, self-signed (a CA) or
 * signed by DIR/CA_NAME.{pem,key}. */
static int make_cert(const char *name, const char *tmpl, const char *ca_name)
{
	char key[200], pem[200], tp[200], cap[200], cak[200];
	snprintf(key, sizeof key, "%s/%s.key", E.dir, name);
	snprintf(pem, sizeof pem, "%s/%s.pem", E.dir, name);
	snprintf(tp, sizeof tp, "%s/%s.tmpl", E.dir, name);
	if (write_text(tp, tmpl) ||
	    certtool("--generate-privkey", "--key-type=ecdsa", "--outfile", key, NULL))
		return -1;
	if (!ca_name)
		return certtool("--generate-self-signed", "--load-privkey", key, "--template", tp,
				"--outfile", pem, NULL);
	snprintf(cap, sizeof cap, "%s/%s.pem", E.dir, ca_name);
	snprintf(cak, sizeof cak, "%s/%s.key", E.dir, ca_name);
	return certtool("--generate-certificate", "--load-privkey", key, "--load-ca-certificate",
			cap, "--load-ca-privkey", cak, "--template", tp, "--outfile", pem, NULL);
}

/* Copies DIR/FROM to DIR/TO through a rename, as certificate renewal tools do. Returns 0 or
 * -1. */
static int replace_file(const char *from, const char *to)
{
	char a[220], b[220], t[240], buf[16384];
	snprintf(a, sizeof a, "%s/%s", E.dir, from);
	snprintf(b, sizeof b, "%s/%s", E.dir, to);
	snprintf(t, sizeof t, "%s.new", b);
	FILE *in = fopen(a, "rb"), *out = in ? fopen(t, "wb") : NULL;
	size_t n = in ? fread(buf, 1, sizeof buf, in) : 0;
	int rc = in && out && n > 0 && n < sizeof buf && fwrite(buf, 1, n, out) == n ? 0 : -1;
	if (in)
		fclose(in);
	if (out && fclose(out))
		rc = -1;
	return rc || rename(t, b) ? -1 : 0;
}

static const char ca_tmpl[] = "cn = \"clipmap test CA\"\nca\ncert_signing_key\n"
			      "expiration_days = 2\n";
/* The server's certificate names 127.0.0.1 only: "localhost" is a name it does not carry. */
static const char server_tmpl[] = "cn = \"clipmap test server\"\nip_address = \"127.0.0.1\"\n"
				  "tls_www_server\nsigning_key\nexpiration_days = 2\n";

/* A certificate that expired on 2020-01-01. */
static const char old_tmpl[] = "cn = \"old\"\nip_address = \"127.0.0.1\"\ntls_www_server\n"
			       "signing_key\nactivation_date = \"2019-01-01 00:00:00\"\n"
			       "expiration_date = \"2020-01-01 00:00:00\"\n";

static int setup(void **state)
{
	(void)state;
	if (daemon_env_init(&E, "test_tls"))
		return -1;
	char out[256];
	char *v[] = { "certtool", "--version", NULL };
	have_certtool = daemon_env_run(v, out, sizeof out) == 0;
	if (!have_certtool) {
		print_message("skipped: certtool not found (Debian package gnutls-bin)\n");
		return 0;
	}
	if (!daemon_env_built(&E, "clipmapd") || !daemon_env_built(&E, "clipmapctl")) {
		print_message("skipped: build/clipmapd or build/clipmapctl not built\n");
		return 0;
	}
	if (make_cert("ca", ca_tmpl, NULL) || make_cert("server", server_tmpl, "ca") ||
	    make_cert("wrong", ca_tmpl, NULL) || make_cert("old", old_tmpl, "ca") ||
	    make_cert("ca2", ca_tmpl, NULL) || make_cert("server2", server_tmpl, "ca2"))
		return -1;
	if (replace_file("server.pem", "server-ca.pem") || replace_file("server.key", "server-ca.key"))
		return -1;
	snprintf(ca, sizeof ca, "%s/ca.pem", E.dir);
	snprintf(wrong_ca, sizeof wrong_ca, "%s/wrong.pem", E.dir);
	char cert[220], key[220];
	snprintf(cert, sizeof cert, "tls.cert = %s/server.pem", E.dir);
	snprintf(key, sizeof key, "tls.key = %s/server.key", E.dir);
	const char *set[] = { "listen.tcp = 127.0.0.1:0", "listen.handshake_timeout = 2",
			      "http.listen = 127.0.0.1:0", "log.level = info", cert, key, NULL };
	char err[256];
	if (daemon_env_start(&E, &(struct daemon_env_conf){ .set = set, .token = TOKEN }, err)) {
		fprintf(stderr, "clipmapd: %s\n", err);
		return -1;
	}
	snprintf(host_port, sizeof host_port, "127.0.0.1:%d", E.port);
	char *log = daemon_env_log_read(&E);
	const char *h = strstr(log, "http: listening on https://127.0.0.1:");
	http_port = h ? atoi(h + strlen("http: listening on https://127.0.0.1:")) : 0;
	free(log);
	return 0;
}

static int teardown(void **state)
{
	(void)state;
	daemon_env_fini(&E);
	return 0;
}

#define NEED_DAEMON()                \
	do {                         \
		if (E.daemon <= 0)   \
			skip();      \
	} while (0)

/* Runs build/clipmapctl with the given arguments (NULL-terminated). */
static int ctl(char *out, size_t n, const char *a0, ...)
{
	char exe[600];
	snprintf(exe, sizeof exe, "%s/clipmapctl", E.bindir);
	va_list ap;
	va_start(ap, a0);
	int rc = vrun(exe, out, n, a0, ap);
	va_end(ap);
	return rc;
}

static char *token_file(void)
{
	static char p[200];
	snprintf(p, sizeof p, "%s/token", E.dir);
	return p;
}

/* ---- a relay that records the bytes ------------------------------------------------- */

/* Forwards the connections it accepts to the daemon's TCP port, one at a time, and keeps
 * every byte either way. */
struct relay {
	int lfd, stop[2];
	char hp[32]; /* "127.0.0.1:PORT" to give clients */
	pthread_t th;
	pthread_mutex_t mu; /* protects buf, len */
	uint8_t *buf;
	size_t len, cap;
};

static void relay_keep(struct relay *r, const uint8_t *p, size_t n)
{
	pthread_mutex_lock(&r->mu);
	if (r->len + n > r->cap) {
		r->cap = (r->len + n) * 2;
		r->buf = realloc(r->buf, r->cap);
		assert_non_null(r->buf);
	}
	memcpy(r->buf + r->len, p, n);
	r->len += n;
	pthread_mutex_unlock(&r->mu);
}

/* Copies one connection both ways until either side closes or stop is written. */
static void relay_pipe(struct relay *r, int c, int s)
{
	static uint8_t b[65536];
	for (;;) {
		struct pollfd p[3] = { { .fd = c, .events = POLLIN }, { .fd = s, .events = POLLIN },
				       { .fd = r->stop[0], .events = POLLIN } };
		if (poll(p, 3, -1) < 0)
			return;
		if (p[2].revents)
			return;
		for (int i = 0; i < 2; i++) {
			if (!p[i].revents)
				continue;
			ssize_t n = recv(p[i].fd, b, sizeof b, 0);
			if (n <= 0)
				return;
			relay_keep(r, b, (size_t)n);
			for (ssize_t off = 0; off < n;) {
				ssize_t w = send(p[1 - i].fd, b + off, (size_t)(n - off), MSG_NOSIGNAL);
				if (w <= 0)
					return;
				off += w;
			}
		}
	}
}

static void *relay_main(void *arg)
{
	struct relay *r = arg;
	for (;;) {
		struct pollfd p[2] = { { .fd = r->lfd, .events = POLLIN },
				       { .fd = r->stop[0], .events = POLLIN } };
		if (poll(p, 2, -1) < 0 || p[1].revents)
			return NULL;
		int c = accept(r->lfd, NULL, NULL);
		if (c < 0)
			continue;
		int s = socket(AF_INET, SOCK_STREAM, 0);
		struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)E.port),
					 .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
		if (s >= 0 && connect(s, (struct sockaddr *)&a, sizeof a) == 0)
			relay_pipe(r, c, s);
		if (s >= 0)
			close(s);
		close(c);
	}
}

static void relay_start(struct relay *r)
{
	*r = (struct relay){ .lfd = socket(AF_INET, SOCK_STREAM, 0) };
	assert_true(r->lfd >= 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	socklen_t al = sizeof a;
	assert_int_equal(bind(r->lfd, (struct sockaddr *)&a, sizeof a), 0);
	assert_int_equal(listen(r->lfd, 8), 0);
	assert_int_equal(getsockname(r->lfd, (struct sockaddr *)&a, &al), 0);
	snprintf(r->hp, sizeof r->hp, "127.0.0.1:%u", (unsigned)ntohs(a.sin_port));
	assert_int_equal(pipe(r->stop), 0);
	pthread_mutex_init(&r->mu, NULL);
	assert_int_equal(pthread_create(&r->th, NULL, relay_main, r), 0);
}

static void relay_stop(struct relay *r)
{
	assert_int_equal(write(r->stop[1], "x", 1), 1);
	pthread_join(r->th, NULL);
	close(r->lfd);
	close(r->stop[0]);
	close(r->stop[1]);
	pthread_mutex_destroy(&r->mu);
	free(r->buf);
}

static bool recorded(struct relay *r, const char *what)
{
	pthread_mutex_lock(&r->mu);
	bool in = r->len && memmem(r->buf, r->len, what, strlen(what)) != NULL;
	pthread_mutex_unlock(&r->mu);
	return in;
}

/* ---- tests -------------------------------------------------------------------------- */

static void status_with_the_right_ca(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	int rc = ctl(out, sizeof out, "-H", host_port, "--tls-ca", ca, "--token-file", token_file(),
		     "status", NULL);
	if (rc)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "sessions"));
	/* the same through the environment */
	setenv("CLIPMAP_TLS_CA", ca, 1);
	rc = ctl(out, sizeof out, "-H", host_port, "--token-file", token_file(), "status", "--json",
		 NULL);
	unsetenv("CLIPMAP_TLS_CA");
	if (rc)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "{"));
	/* the daemon's log names the listener as TLS */
	assert_true(daemon_env_log_count(&E, "(TLS)") >= 1);
}

static void wrong_ca_is_refused_and_logged(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	struct relay r;
	relay_start(&r);
	int before = daemon_env_log_count(&E, "tls: handshake with");
	int rc = ctl(out, sizeof out, "-H", r.hp, "--tls-ca", wrong_ca, "--token-file", token_file(),
		     "status", NULL);
	fprintf(stderr, "wrong CA: exit %d: %s", rc, out);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "certificate is refused"));
	assert_non_null(strstr(out, wrong_ca)); /* the CA it was checked against */
	assert_non_null(strstr(out, "NOT trusted"));	 /* GnuTLS's verification status */
	assert_non_null(strstr(out, "issuer is unknown"));
	assert_true(daemon_env_log_wait(&E, "tls: handshake with", before + 1, 5000));
	char *log = daemon_env_log_read(&E);
	assert_non_null(strstr(log, "the client refused it"));
	free(log);
	/* nothing of the protocol went out: no HELLO, no token */
	assert_false(recorded(&r, TOKEN));
	assert_false(recorded(&r, PROTO_MAGIC));
	relay_stop(&r);
}

static void host_not_in_the_certificate_is_refused(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	char hp[64];
	snprintf(hp, sizeof hp, "localhost:%d", E.port);
	int rc = ctl(out, sizeof out, "-H", hp, "--tls-ca", ca, "--token-file", token_file(),
		     "status", NULL);
	fprintf(stderr, "wrong name: exit %d: %s", rc, out);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "certificate is refused"));
	assert_non_null(strstr(out, "for the name localhost"));
	assert_non_null(strstr(out, "does not match"));
}

static void plain_client_is_told_and_closed(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	struct relay r;
	relay_start(&r);
	double t0 = clock_now_s();
	int rc = ctl(out, sizeof out, "-H", r.hp, "--token-file", token_file(), "status", NULL);
	double took = clock_now_s() - t0;
	fprintf(stderr, "plain client: exit %d after %.2f s: %s", rc, took, out);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "this listener speaks TLS"));
	assert_non_null(strstr(out, "--tls-ca"));
	assert_true(took < test_slow(8)); /* answered, not left to a timeout */
	assert_true(daemon_env_log_wait(&E, "a plain clipmap client", 1, 5000));
	/* The control for the relay: a plain client's HELLO carries the token in clear (which
	 * is why the TLS client checks the certificate before it says anything). */
	assert_true(recorded(&r, TOKEN));
	relay_stop(&r);
}

/* A connected TCP socket to the daemon's TLS port. */
static int raw_connect(void)
{
	int fd = socket(AF_INET, SOCK_STREAM, 0);
	assert_true(fd >= 0);
	struct sockaddr_in a = { .sin_family = AF_INET, .sin_port = htons((uint16_t)E.port),
				 .sin_addr.s_addr = htonl(INADDR_LOOPBACK) };
	assert_int_equal(connect(fd, (struct sockaddr *)&a, sizeof a), 0);
	return fd;
}

/* Seconds until the daemon closes fd (reading and dropping what it says), or -1 after
 * limit_s. */
static double closed_within(int fd, double limit_s)
{
	double t0 = clock_now_s();
	char b[4096];
	while (clock_now_s() - t0 < limit_s) {
		struct pollfd p = { .fd = fd, .events = POLLIN };
		if (poll(&p, 1, 100) > 0) {
			ssize_t n = recv(fd, b, sizeof b, 0);
			if (n <= 0)
				return clock_now_s() - t0;
		}
	}
	return -1;
}

static void garbage_and_silence_are_closed(void **state)
{
	(void)state;
	NEED_DAEMON();
	int fd = raw_connect();
	const char get[] = "GET / HTTP/1.0\r\n\r\n";
	assert_int_equal(send(fd, get, sizeof get - 1, 0), (ssize_t)(sizeof get - 1));
	double t = closed_within(fd, test_slow(5));
	fprintf(stderr, "garbage: closed after %.2f s\n", t);
	assert_true(t >= 0);
	close(fd);
	assert_true(daemon_env_log_wait(&E, "not a TLS handshake (first byte 0x47)", 1, 5000));
	/* Silent: the pre-auth guard's handshake_timeout (2 s here) applies before TLS too. */
	fd = raw_connect();
	t = closed_within(fd, test_slow(10));
	fprintf(stderr, "silent: closed after %.2f s\n", t);
	assert_true(t >= 1.5);
	assert_true(t >= 0 && t < test_slow(6));
	close(fd);
	/* A client that stops in the middle of the TLS handshake: the same deadline. */
	fd = raw_connect();
	static const uint8_t partial[] = { 0x16, 0x03, 0x01, 0x02, 0x00, 0x01, 0x00, 0x01 };
	assert_int_equal(send(fd, partial, sizeof partial, 0), (ssize_t)sizeof partial);
	t = closed_within(fd, test_slow(10));
	fprintf(stderr, "half a ClientHello: closed after %.2f s\n", t);
	assert_true(t >= 0 && t < test_slow(6));
	close(fd);
}

static void token_never_in_clear(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	struct relay r;
	relay_start(&r);
	/* a session that authenticates, lists planets and gets stats */
	int rc = ctl(out, sizeof out, "-H", r.hp, "--tls-ca", ca, "--token-file", token_file(),
		     "status", NULL);
	if (rc)
		fprintf(stderr, "%s", out);
	assert_int_equal(rc, 0);
	pthread_mutex_lock(&r.mu);
	size_t len = r.len;
	pthread_mutex_unlock(&r.mu);
	fprintf(stderr, "relay recorded %zu bytes of a TLS status session\n", len);
	assert_true(len > 500);
	assert_false(recorded(&r, TOKEN));
	assert_false(recorded(&r, PROTO_MAGIC)); /* no frame in clear at all */
	assert_false(recorded(&r, "procedural")); /* nor the planet's name in STATS */
	relay_stop(&r);
}

/* One WANT of the height and colour tiles of level 3 near (0, 0), received into tiles[2]
 * (caller frees). */
static void fetch_tiles(struct net_conn *c, uint8_t *tiles[2], size_t len[2])
{
	char err[256];
	struct proto_msg m = { 0 };
	int rc = net_open_planet(c, "procedural", &m, 20000, err);
	if (rc)
		fail_msg("open: %s", err);
	uint32_t pid = m.opened.planet_id;
	proto_msg_fini(&m);
	struct proto_want_entry e[2];
	for (int l = 0; l < 2; l++)
		e[l] = (struct proto_want_entry){ .layer = (uint8_t)l, .cls = PROTO_CLASS_VISIBLE,
						  .lx = 4, .ly = 3, .x = 8, .y = 4 };
	struct proto_msg w = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 1, .count = 2, .entries = e } };
	assert_int_equal(net_send(c, &w, err), 0);
	tiles[0] = tiles[1] = NULL;
	for (int got = 0; got < 2;) {
		rc = net_expect(c, PROTO_TILE, &m, (int)test_slow(30000), NULL, NULL, err);
		if (rc)
			fail_msg("tile: %s", err);
		int l = m.tile.layer;
		assert_true(l < 2 && !tiles[l]);
		len[l] = m.tile.enc.raw_len;
		tiles[l] = malloc(len[l]);
		assert_int_equal(net_tile_decode(c, &m.tile, tiles[l], len[l], err), 0);
		proto_msg_fini(&m);
		got++;
	}
}

static void tiles_over_tls_match_the_unix_socket(void **state)
{
	(void)state;
	NEED_DAEMON();
	char err[256];
	struct net_conn *t = NULL, *u = NULL;
	struct net_opts ot = { .hostport = host_port, .tls_ca = ca, .token_file = token_file() };
	int rc = net_connect(&ot, &t, err);
	if (rc)
		fail_msg("TLS: %s", err);
	assert_true(net_is_tls(t));
	struct net_opts ou = { .socket_path = E.sock, .tls_ca = ca };
	rc = net_connect(&ou, &u, err);
	if (rc)
		fail_msg("unix: %s", err);
	assert_false(net_is_tls(u)); /* a Unix socket is always plain */
	uint8_t *a[2], *b[2];
	size_t la[2], lb[2];
	fetch_tiles(t, a, la);
	fetch_tiles(u, b, lb);
	for (int l = 0; l < 2; l++) {
		assert_int_equal(la[l], lb[l]);
		assert_true(la[l] >= 65536); /* many TLS records per tile */
		assert_memory_equal(a[l], b[l], la[l]);
		free(a[l]);
		free(b[l]);
	}
	net_close(t);
	net_close(u);
	/* The library's own messages: a wrong CA is -EKEYREJECTED, a missing file named. */
	struct net_opts ow = { .hostport = host_port, .tls_ca = wrong_ca,
			       .token_file = token_file() };
	assert_int_equal(net_connect(&ow, &t, err), -EKEYREJECTED);
	assert_non_null(strstr(err, "issuer is unknown"));
	char missing[220];
	snprintf(missing, sizeof missing, "%s/no-such-ca.pem", E.dir);
	ow.tls_ca = missing;
	assert_int_equal(net_connect(&ow, &t, err), -ENOENT);
	assert_non_null(strstr(err, missing));
}

/* A client that reads nothing for a while: the daemon's socket fills, its TLS records wait
 * unsent, and once the client reads every tile still arrives whole (checksums verified). */
static void slow_reader_gets_every_tile(void **state)
{
	(void)state;
	NEED_DAEMON();
	char err[256];
	struct net_conn *c = NULL;
	struct net_opts o = { .hostport = host_port, .tls_ca = ca, .token_file = token_file() };
	if (net_connect(&o, &c, err))
		fail_msg("TLS: %s", err);
	struct proto_msg m = { 0 };
	if (net_open_planet(c, "procedural", &m, 20000, err))
		fail_msg("open: %s", err);
	uint32_t pid = m.opened.planet_id;
	proto_msg_fini(&m);
	enum { N = 64 };
	struct proto_want_entry e[N];
	for (uint32_t i = 0; i < N; i++)
		e[i] = (struct proto_want_entry){ .layer = 0, .cls = PROTO_CLASS_VISIBLE, .lx = 5,
						  .ly = 4, .x = i % 16, .y = 4 + i / 16 };
	struct proto_msg w = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 1, .count = N, .entries = e } };
	assert_int_equal(net_send(c, &w, err), 0);
	usleep((useconds_t)test_slow(3000) * 1000); /* 16 MiB wanted; the socket holds far less */
	static float px[256 * 256];
	bool seen[N] = { false };
	for (int got = 0; got < N; got++) {
		if (net_expect(c, PROTO_TILE, &m, (int)test_slow(60000), NULL, NULL, err))
			fail_msg("tile %d of %d: %s", got, N, err);
		int i = (int)((m.tile.key.y - 4) * 16 + m.tile.key.x);
		assert_true(i >= 0 && i < N && !seen[i]);
		seen[i] = true;
		assert_int_equal(net_tile_decode(c, &m.tile, px, sizeof px, err), 0);
		proto_msg_fini(&m);
	}
	net_close(c);
}

static void viewer_draws_a_complete_frame_over_tls(void **state)
{
	(void)state;
	NEED_DAEMON();
	if (!daemon_env_built(&E, "clipmapview"))
		skip();
	char exe[600], png[220], limit[32];
	snprintf(exe, sizeof exe, "%s/clipmapview", E.bindir);
	snprintf(png, sizeof png, "%s/tls.png", E.dir);
	snprintf(limit, sizeof limit, "%.0f", test_slow(60));
	char *argv[] = { exe, "--connect", host_port, "--tls-ca", ca, "--token-file", token_file(),
			 "--planet", "procedural", "--camera", "20,30,6000000,0,-90", "--size",
			 "320x240", "--wait-complete", "--timeout", limit, "-o", png, NULL };
	static char out[OUT_CAP];
	int rc = daemon_env_run(argv, out, sizeof out);
	if (rc == 1 && strstr(out, "no OpenGL context")) {
		fprintf(stderr, "no GL context here: %s", out);
		skip();
	}
	if (rc)
		fprintf(stderr, "clipmapview: %s", out);
	assert_int_equal(rc, 0); /* 3 would be a frame still incomplete at --timeout */
	void *px;
	struct img_info in;
	assert_int_equal(img_read(png, IMG_U8, &px, &in, NULL), 0);
	assert_int_equal(in.width, 320);
	int lo = 255, hi = 0;
	for (size_t i = 0; i < (size_t)in.width * in.height; i++) {
		int g = ((const uint8_t *)px)[i * (size_t)in.channels + 1];
		lo = g < lo ? g : lo;
		hi = g > hi ? g : hi;
	}
	free(px);
	assert_true(hi - lo > 40); /* terrain, not the clear colour */
	/* and the wrong CA stops the viewer before it draws anything */
	argv[4] = wrong_ca;
	rc = daemon_env_run(argv, out, sizeof out);
	assert_int_equal(rc, 1);
	assert_non_null(strstr(out, "certificate is refused"));
}

/* [http] with [tls] is HTTPS on the same certificate (checked with curl). */
static void http_endpoint_is_https(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	char *v[] = { "curl", "--version", NULL };
	if (daemon_env_run(v, out, sizeof out) != 0) {
		print_message("skipped: curl not found\n");
		skip();
	}
	assert_true(http_port > 0);
	char url[128], plain[128];
	snprintf(url, sizeof url, "https://127.0.0.1:%d/healthz", http_port);
	snprintf(plain, sizeof plain, "http://127.0.0.1:%d/healthz", http_port);
	char *ok[] = { "curl", "-sS", "-m", "20", "--cacert", ca, url, NULL };
	int rc = daemon_env_run(ok, out, sizeof out);
	if (rc)
		fprintf(stderr, "curl: %s", out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "ok"));
	char *wrong[] = { "curl", "-sS", "-m", "20", "--cacert", wrong_ca, url, NULL };
	assert_int_equal(daemon_env_run(wrong, out, sizeof out), 60); /* peer certificate refused */
	char *clear[] = { "curl", "-sS", "-m", "20", plain, NULL };
	rc = daemon_env_run(clear, out, sizeof out);
	fprintf(stderr, "plain HTTP to the HTTPS endpoint: curl exit %d: %s", rc, out);
	assert_true(rc != 0);
}

/* Bad [tls] files: clipmapd exits 2 at start naming the file and the problem; an expired
 * certificate is a warning. */
static void bad_files_stop_the_daemon(void **state)
{
	(void)state;
	NEED_DAEMON();
	char conf[220], exe[600], srv[220], key[220], garbage[220];
	snprintf(conf, sizeof conf, "%s/bad.conf", E.dir);
	snprintf(exe, sizeof exe, "%s/clipmapd", E.bindir);
	snprintf(srv, sizeof srv, "%s/server.pem", E.dir);
	snprintf(key, sizeof key, "%s/wrong.key", E.dir); /* another key than the cert's */
	snprintf(garbage, sizeof garbage, "%s/token", E.dir);
	const struct {
		const char *cert, *key, *says;
	} cases[] = {
		{ "/nonexistent/server.pem", key, "/nonexistent/server.pem: No such file" },
		{ garbage, key, "no PEM certificate" },
		{ srv, garbage, "not an unencrypted PEM private key" },
		{ srv, key, "is not the key of the certificate" },
		{ srv, NULL, "needs both cert and key" },
	};
	static char out[OUT_CAP];
	for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
		char text[1200];
		snprintf(text, sizeof text,
			 "[listen]\nunix = %s/bad.sock\n[engine]\nplanets = %s\n[tls]\ncert = %s\n%s%s%s",
			 E.dir, E.planets, cases[i].cert, cases[i].key ? "key = " : "",
			 cases[i].key ? cases[i].key : "", cases[i].key ? "\n" : "");
		assert_int_equal(write_text(conf, text), 0);
		char *argv[] = { exe, "-c", conf, "--check-config", NULL };
		int rc = daemon_env_run(argv, out, sizeof out);
		fprintf(stderr, "case %zu: exit %d: %s", i, rc, out);
		assert_int_equal(rc, 2);
		assert_non_null(strstr(out, cases[i].says));
	}
	/* An expired certificate starts, with a warning: clients will refuse it. */
	char text[1200];
	snprintf(text, sizeof text,
		 "[listen]\nunix = %s/bad.sock\n[engine]\nplanets = %s\n[tls]\ncert = %s/old.pem\n"
		 "key = %s/old.key\n", E.dir, E.planets, E.dir, E.dir);
	assert_int_equal(write_text(conf, text), 0);
	char *argv[] = { exe, "-c", conf, "--check-config", NULL };
	int rc = daemon_env_run(argv, out, sizeof out);
	fprintf(stderr, "expired: exit %d: %s", rc, out);
	assert_int_equal(rc, 0);
	assert_non_null(strstr(out, "expired on 2020-01-01"));
}

/* The figure key of `clipmapctl status --json` over TLS checked against ca_file, or -1. */
static long tls_figure(const char *ca_file, const char *key)
{
	static char out[OUT_CAP];
	if (ctl(out, sizeof out, "-H", host_port, "--tls-ca", ca_file, "--token-file",
		token_file(), "status", "--json", NULL))
		return -1;
	char k[80];
	snprintf(k, sizeof k, "\"%s\":", key);
	const char *p = strstr(out, k);
	return p ? atol(p + strlen(k)) : -1;
}

/* A renewed certificate (another CA here, so the test can tell them apart) is loaded by
 * SIGHUP for new connections; a connection open before it goes on with the old one; a
 * renewal whose key does not match is refused and the running certificate stays. */
static void sighup_reloads_the_certificate(void **state)
{
	(void)state;
	NEED_DAEMON();
	static char out[OUT_CAP];
	char err[256], ca2[220];
	snprintf(ca2, sizeof ca2, "%s/ca2.pem", E.dir);
	long hs0 = tls_figure(ca, "tls.handshakes"), failed0 = tls_figure(ca, "tls.failed");
	assert_true(hs0 >= 1 && failed0 >= 1); /* the earlier cases' handshakes, good and bad */
	struct net_conn *old = NULL;
	struct net_opts o = { .hostport = host_port, .tls_ca = ca, .token_file = token_file() };
	if (net_connect(&o, &old, err))
		fail_msg("TLS: %s", err);

	assert_int_equal(replace_file("server2.pem", "server.pem"), 0);
	assert_int_equal(replace_file("server2.key", "server.key"), 0);
	int n = daemon_env_log_count(&E, "TLS certificate");
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&E, "TLS certificate", n + 1, 5000));
	assert_int_equal(tls_figure(ca2, "tls.reloads"), 1); /* new connections: the new CA */
	int rc = ctl(out, sizeof out, "-H", host_port, "--tls-ca", ca, "--token-file", token_file(),
		     "status", NULL);
	assert_int_equal(rc, 1); /* the old CA no longer signs what the listener shows */
	assert_non_null(strstr(out, "issuer is unknown"));
	uint8_t *t[2];
	size_t len[2];
	fetch_tiles(old, t, len); /* the connection made before the reload still works */
	free(t[0]);
	free(t[1]);
	net_close(old);
	/* the HTTPS endpoint too (when curl is here): the new CA, not the old one */
	char *cv[] = { "curl", "--version", NULL };
	if (http_port > 0 && daemon_env_run(cv, out, sizeof out) == 0) {
		char url[128];
		snprintf(url, sizeof url, "https://127.0.0.1:%d/healthz", http_port);
		char *ok[] = { "curl", "-sS", "-m", "20", "--cacert", ca2, url, NULL };
		int r2 = daemon_env_run(ok, out, sizeof out);
		if (r2)
			fprintf(stderr, "curl with the new CA: %s", out);
		assert_int_equal(r2, 0);
		char *old_ca[] = { "curl", "-sS", "-m", "20", "--cacert", ca, url, NULL };
		assert_int_equal(daemon_env_run(old_ca, out, sizeof out), 60);
	}

	/* A renewal gone wrong: the certificate of ca but server2's key. */
	assert_int_equal(replace_file("server-ca.pem", "server.pem"), 0);
	n = daemon_env_log_count(&E, "keep the running certificate");
	assert_int_equal(daemon_env_signal(&E, SIGHUP), 0);
	assert_true(daemon_env_log_wait(&E, "keep the running certificate", n + 1, 5000));
	char *log = daemon_env_log_read(&E);
	assert_non_null(strstr(log, "is not the key of the certificate"));
	free(log);
	assert_int_equal(tls_figure(ca2, "tls.reloads"), 1); /* still server2's */
	assert_true(tls_figure(ca2, "tls.handshakes") > hs0);
	assert_true(tls_figure(ca2, "tls.failed") > failed0); /* the refused `status` above */
	assert_int_equal(replace_file("server-ca.key", "server.key"), 0); /* as it was */
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(status_with_the_right_ca),
		cmocka_unit_test(wrong_ca_is_refused_and_logged),
		cmocka_unit_test(host_not_in_the_certificate_is_refused),
		cmocka_unit_test(plain_client_is_told_and_closed),
		cmocka_unit_test(garbage_and_silence_are_closed),
		cmocka_unit_test(token_never_in_clear),
		cmocka_unit_test(tiles_over_tls_match_the_unix_socket),
		cmocka_unit_test(slow_reader_gets_every_tile),
		cmocka_unit_test(viewer_draws_a_complete_frame_over_tls),
		cmocka_unit_test(http_endpoint_is_https),
		cmocka_unit_test(bad_files_stop_the_daemon),
		cmocka_unit_test(sighup_reloads_the_certificate),
	};
	return cmocka_run_group_tests(tests, setup, teardown);
}
