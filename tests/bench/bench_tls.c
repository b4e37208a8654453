/* bench_tls — what TLS costs on clipmapd's TCP listener, against plain TCP measured in the same
 * run: two daemons (tests/support/daemon_env) on one planet, one plain, one with [tls] (a CA
 * and an ECDSA P-256 server certificate made by certtool here), driven by the net.h client:
 * connect + handshake(s) + HELLO_OK (p50, p99), a cached quad's round trip (WANT → 4th TILE),
 * and cached-tile throughput to one session (256² RGBA8, decoded), plain and TLS samples taken
 * in alternation. Prints each figure for both and the ratio TLS / plain. Skips, saying so,
 * without certtool.
 */
#include <signal.h>
#include <stdbool.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/net.h"
#include "common/clock.h"
#include "common/proto.h"
#include "support/bench_planet.h"
#include "support/daemon_env.h"

static const char planet[] = BENCH_PLANET_INI;

static void die(const char *what)
{
	fprintf(stderr, "bench_tls: %s\n", what);
	exit(1);
}

static int run(char *out, size_t n, const char *a0, ...)
{
	char *argv[16] = { "certtool", (char *)a0 };
	int argc = 2;
	va_list ap;
	va_start(ap, a0);
	for (const char *a; argc < 15 && (a = va_arg(ap, const char *));)
		argv[argc++] = (char *)a;
	va_end(ap);
	argv[argc] = NULL;
	return daemon_env_run(argv, out, n);
}

/* A CA and a server certificate for 127.0.0.1 in dir. */
static void make_certs(const char *dir)
{
	char p[8][256], out[8192];
	const char *names[] = { "ca.tmpl", "ca.key", "ca.pem", "s.tmpl", "s.key", "s.pem" };
	for (int i = 0; i < 6; i++)
		snprintf(p[i], sizeof p[i], "%s/%s", dir, names[i]);
	FILE *f = fopen(p[0], "w");
	if (!f || fputs("cn = \"bench CA\"\nca\ncert_signing_key\nexpiration_days = 2\n", f) < 0 ||
	    fclose(f))
		die("cannot write the CA template");
	f = fopen(p[3], "w");
	if (!f || fputs("cn = \"bench\"\nip_address = \"127.0.0.1\"\ntls_www_server\nsigning_key\n"
			"expiration_days = 2\n", f) < 0 || fclose(f))
		die("cannot write the server template");
	if (run(out, sizeof out, "--generate-privkey", "--key-type=ecdsa", "--outfile", p[1], NULL) ||
	    run(out, sizeof out, "--generate-self-signed", "--load-privkey", p[1], "--template", p[0],
		"--outfile", p[2], NULL) ||
	    run(out, sizeof out, "--generate-privkey", "--key-type=ecdsa", "--outfile", p[4], NULL) ||
	    run(out, sizeof out, "--generate-certificate", "--load-privkey", p[4],
		"--load-ca-certificate", p[2], "--load-ca-privkey", p[1], "--template", p[3],
		"--outfile", p[5], NULL))
		die(out);
}

/* Starts a daemon on bench_server's cheap planet (its tiles stay cached); with tls, [tls] on a certificate made here and the CA's
 * path into ca. */
static void start(struct daemon_env *d, const char *tag, bool tls, char ca[300])
{
	char cert[300] = "", key[300] = "", err[256];
	if (daemon_env_init(d, tag) || daemon_env_planet_text(d, "b.ini", planet, NULL))
		die("cannot prepare a temporary directory");
	if (tls) {
		make_certs(d->dir);
		snprintf(cert, sizeof cert, "tls.cert = %s/s.pem", d->dir);
		snprintf(key, sizeof key, "tls.key = %s/s.key", d->dir);
		snprintf(ca, 300, "%s/ca.pem", d->dir);
	}
	const char *keys[] = { "listen.unix =", "listen.tcp = 127.0.0.1:0", "engine.workers = 0",
			       "engine.cache_mb = 1024", "session.max_rate = 0",
			       "session.max_pending_kb = 16384", "log.level = info",
			       tls ? cert : NULL, key, NULL };
	if (daemon_env_start(d, &(struct daemon_env_conf){ .set = keys }, err))
		die(err);
}

static struct net_conn *conn(int port, const char *ca)
{
	char hp[64], err[256];
	snprintf(hp, sizeof hp, "127.0.0.1:%d", port);
	struct net_opts o = { .hostport = hp, .tls_ca = ca, .name = "bench_tls" };
	struct net_conn *c;
	if (net_connect(&o, &c, err))
		die(err);
	return c;
}

/* WANT e[0 .. n) and receive (and decode) its n tiles. */
static void fetch(struct net_conn *c, uint32_t pid, uint32_t seq, const struct proto_want_entry *e,
		  uint32_t n)
{
	static uint8_t px[256 * 256 * 4];
	char err[256];
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = seq, .count = n, .entries = e } };
	if (net_send(c, &m, err))
		die(err);
	for (uint32_t k = 0; k < n; k++) {
		if (net_expect(c, PROTO_TILE, &m, 120000, NULL, NULL, err) ||
		    net_tile_decode(c, &m.tile, px, sizeof px, err))
			die(err);
		proto_msg_fini(&m);
	}
}

static int cmp_u64(const void *a, const void *b)
{
	uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
	return x < y ? -1 : x > y;
}

/* One client of each daemon, measured in alternation (the machine's load changes under a
 * run: each figure pairs a plain and a TLS sample taken back to back). */
struct side {
	int port;
	const char *ca; /* NULL: plain */
	struct net_conn *c;
	uint32_t pid, seq;
	uint64_t t[512];
};

static double median(uint64_t *t, int n)
{
	qsort(t, (size_t)n, sizeof t[0], cmp_u64);
	return (double)t[n / 2];
}

static void side_open(struct side *s)
{
	s->c = conn(s->port, s->ca);
	struct proto_msg m;
	char err[256];
	if (net_open_planet(s->c, "b", &m, 30000, err))
		die(err);
	s->pid = m.opened.planet_id;
	proto_msg_fini(&m);
}

int main(void)
{
	signal(SIGPIPE, SIG_IGN);
	char out[256];
	char *v[] = { "certtool", "--version", NULL };
	if (daemon_env_run(v, out, sizeof out) != 0) {
		printf("bench_tls: skipped: certtool not found (Debian package gnutls-bin)\n");
		return 0;
	}
	struct daemon_env plain, tls;
	char ca[300];
	start(&plain, "bench-tls-plain", false, NULL);
	start(&tls, "bench-tls", true, ca);
	struct side sd[2] = { { .port = plain.port }, { .port = tls.port, .ca = ca } };

	enum { NC = 200, NQ = 400, ROUNDS = 12 };
	for (int i = 0; i < NC; i++)
		for (int k = 0; k < 2; k++) {
			uint64_t t0 = clock_now_ns();
			net_close(conn(sd[k].port, sd[k].ca));
			sd[k].t[i] = clock_now_ns() - t0;
		}
	double cp[2], cq[2], qp[2], qq[2], tp[2];
	for (int k = 0; k < 2; k++) {
		cp[k] = median(sd[k].t, NC) * 1e-6;
		cq[k] = sd[k].t[NC * 99 / 100] * 1e-6;
	}
	struct proto_want_entry qa[4], qb[4];
	static struct proto_want_entry big[2][512];
	bench_planet_block(qa, 5, 10, 10, 2, 2);
	bench_planet_block(qb, 5, 20, 10, 2, 2);
	bench_planet_block(big[0], 7, 0, 10, 32, 16);
	bench_planet_block(big[1], 7, 64, 10, 32, 16);
	for (int k = 0; k < 2; k++) {
		side_open(&sd[k]);
		for (int i = 0; i < 2; i++) { /* generated once, then cached */
			fetch(sd[k].c, sd[k].pid, ++sd[k].seq, i ? qb : qa, 4);
			fetch(sd[k].c, sd[k].pid, ++sd[k].seq, big[i], 512);
		}
	}
	for (int i = 0; i < NQ; i++)
		for (int k = 0; k < 2; k++) {
			uint64_t t0 = clock_now_ns();
			fetch(sd[k].c, sd[k].pid, ++sd[k].seq, i & 1 ? qb : qa, 4);
			sd[k].t[i] = clock_now_ns() - t0;
		}
	for (int k = 0; k < 2; k++) {
		qp[k] = median(sd[k].t, NQ) * 1e-6;
		qq[k] = sd[k].t[NQ * 99 / 100] * 1e-6;
	}
	for (int r = 0; r < ROUNDS; r++)
		for (int k = 0; k < 2; k++) {
			uint64_t t0 = clock_now_ns();
			fetch(sd[k].c, sd[k].pid, ++sd[k].seq, big[r & 1], 512);
			sd[k].t[r] = clock_now_ns() - t0;
		}
	for (int k = 0; k < 2; k++) {
		tp[k] = 512 / (median(sd[k].t, ROUNDS) * 1e-9);
		net_close(sd[k].c);
	}
	printf("tls/connect + HELLO_OK loopback: plain p50 %.3f ms p99 %.3f ms, TLS (1.3, ECDSA "
	       "P-256) p50 %.3f ms p99 %.3f ms, ratio %.1fx\n",
	       cp[0], cq[0], cp[1], cq[1], cp[1] / cp[0]);
	printf("tls/cached quad 4x256² rgba8 round trip: plain p50 %.3f ms p99 %.3f ms, TLS p50 "
	       "%.3f ms p99 %.3f ms, ratio %.2fx\n",
	       qp[0], qq[0], qp[1], qq[1], qp[1] / qp[0]);
	printf("tls/cached tiles 256² rgba8 to 1 session (net.h, decoded; median of %d rounds of "
	       "512): plain %.0f tiles/s (%.2f GB/s), TLS %.0f tiles/s (%.2f GB/s), TLS/plain %.2f\n",
	       ROUNDS, tp[0], tp[0] * 262144e-9, tp[1], tp[1] * 262144e-9, tp[1] / tp[0]);
	daemon_env_fini(&plain);
	daemon_env_fini(&tls);
	return 0;
}
