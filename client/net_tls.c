/* net_tls — see net_tls.h. The transport functions given to GnuTLS use MSG_DONTWAIT and
 * MSG_NOSIGNAL on the (blocking) socket, so no call here waits and no SIGPIPE is raised; the
 * pull function keeps the server's first bytes, so that a server answering in the plain
 * protocol is recognised and named as such rather than as a garbled record.
 * GnuTLS reads a record's 5-byte header and then its body, two system calls per 16 KiB
 * record; the pull function reads ahead instead (up to READ_AHEAD bytes at a time) and serves
 * GnuTLS from that buffer. net_tls_recv reads records until GnuTLS says EAGAIN (or the
 * caller's room is full), so when it says EAGAIN the buffer holds no whole record and the
 * socket's readability is again the signal.
 */
#include "net_tls.h"

#include <arpa/inet.h>
#include <errno.h>
#include <gnutls/gnutls.h>
#include <gnutls/x509.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>

#include "common/errbuf.h"
#include "common/proto.h"
#include "common/xalloc.h"

#define PRIORITIES "NORMAL:-VERS-ALL:+VERS-TLS1.3:+VERS-TLS1.2"
#define READ_AHEAD (256u << 10)

struct net_tls {
	gnutls_session_t s;
	gnutls_certificate_credentials_t cred;
	int fd;
	bool ready, resend, want_write;
	unsigned char first[4]; /* the server's first bytes */
	size_t nfirst;
	unsigned char *ra; /* read ahead: [ra_off, ra_len) not given to GnuTLS yet */
	size_t ra_off, ra_len;
	char host[256], ca[200], peer[272];
};

static ssize_t push(gnutls_transport_ptr_t p, const void *data, size_t n)
{
	struct net_tls *t = p;
	ssize_t w = send(t->fd, data, n, MSG_NOSIGNAL | MSG_DONTWAIT);
	if (w < 0)
		gnutls_transport_set_errno(t->s, errno);
	return w;
}

static ssize_t pull(gnutls_transport_ptr_t p, void *data, size_t n)
{
	struct net_tls *t = p;
	if (t->ra_off == t->ra_len) {
		ssize_t r = recv(t->fd, t->ra, READ_AHEAD, MSG_DONTWAIT);
		if (r < 0) {
			gnutls_transport_set_errno(t->s, errno);
			return r;
		}
		t->ra_off = 0;
		t->ra_len = (size_t)r;
		for (ssize_t i = 0; i < r && t->nfirst < sizeof t->first; i++)
			t->first[t->nfirst++] = t->ra[i];
	}
	size_t k = t->ra_len - t->ra_off < n ? t->ra_len - t->ra_off : n;
	memcpy(data, t->ra + t->ra_off, k);
	t->ra_off += k;
	return (ssize_t)k;
}

static int pull_timeout(gnutls_transport_ptr_t p, unsigned int ms)
{
	struct net_tls *t = p;
	if (t->ra_off < t->ra_len)
		return 1;
	struct pollfd pf = { .fd = t->fd, .events = POLLIN };
	int r = poll(&pf, 1, ms == GNUTLS_INDEFINITE_TIMEOUT ? -1 : (int)ms);
	if (r < 0)
		gnutls_transport_set_errno(t->s, errno);
	return r;
}

/* Whether s is an IPv4 or IPv6 address (no SNI for those: RFC 6066). */
static bool is_ip(const char *s)
{
	unsigned char a[16];
	return inet_pton(AF_INET, s, a) == 1 || inet_pton(AF_INET6, s, a) == 1;
}

/* The trust: the CA file's certificates, or the system's. Returns 0 or -errno with err. */
static int load_trust(struct net_tls *t, const char *ca_file, char err[256])
{
	if (!ca_file) {
		int n = gnutls_certificate_set_x509_system_trust(t->cred);
		if (n <= 0) {
			err_set(err, "%s: TLS: no system trust store to check the server's certificate "
				"against (%s): give the CA with --tls-ca FILE", t->peer,
				n < 0 ? gnutls_strerror(n) : "it is empty");
			return -ENOENT;
		}
		snprintf(t->ca, sizeof t->ca, "the system's trust store");
		return 0;
	}
	struct stat st;
	int e = stat(ca_file, &st) ? errno : S_ISREG(st.st_mode) ? 0 : EISDIR;
	if (e) {
		err_set(err, "TLS CA file %s: %s", ca_file,
			e == EISDIR ? "not a regular file" : strerror(e));
		return -e;
	}
	int n = gnutls_certificate_set_x509_trust_file(t->cred, ca_file, GNUTLS_X509_FMT_PEM);
	if (n <= 0) {
		err_set(err, "TLS CA file %s: no PEM certificate in it%s%s", ca_file,
			n < 0 ? ": " : "", n < 0 ? gnutls_strerror(n) : "");
		return n < 0 ? -EINVAL : -ENOENT;
	}
	snprintf(t->ca, sizeof t->ca, "CA %.190s", ca_file);
	return 0;
}

int net_tls_create(int fd, const char *host, const char *ca_file, const char *peer,
		   struct net_tls **out, char err[256])
{
	*out = NULL;
	struct net_tls *t = xcalloc(1, sizeof *t);
	t->fd = fd;
	t->ra = xmalloc(READ_AHEAD);
	snprintf(t->host, sizeof t->host, "%s", host);
	snprintf(t->peer, sizeof t->peer, "%s", peer);
	int g = gnutls_certificate_allocate_credentials(&t->cred);
	if (g < 0) {
		err_set(err, "%s: TLS: %s", peer, gnutls_strerror(g));
		free(t);
		return -ENOMEM;
	}
	int rc = load_trust(t, ca_file, err);
	if (rc)
		goto fail;
	rc = -EINVAL;
	if ((g = gnutls_init(&t->s, GNUTLS_CLIENT | GNUTLS_NONBLOCK | GNUTLS_NO_SIGNAL)) < 0 ||
	    (g = gnutls_priority_set_direct(t->s, PRIORITIES, NULL)) < 0 ||
	    (g = gnutls_credentials_set(t->s, GNUTLS_CRD_CERTIFICATE, t->cred)) < 0 ||
	    (!is_ip(host) &&
	     (g = gnutls_server_name_set(t->s, GNUTLS_NAME_DNS, host, strlen(host))) < 0)) {
		err_set(err, "%s: TLS: %s", peer, gnutls_strerror(g));
		goto fail;
	}
	/* The handshake fails unless the chain leads to the trust and the certificate names
	 * host (a DNS name, or an IP address against its IP addresses). */
	gnutls_session_set_verify_cert(t->s, t->host, 0);
	gnutls_handshake_set_timeout(t->s, 0); /* net.c's deadline bounds it */
	gnutls_transport_set_ptr(t->s, t);
	gnutls_transport_set_push_function(t->s, push);
	gnutls_transport_set_pull_function(t->s, pull);
	gnutls_transport_set_pull_timeout_function(t->s, pull_timeout);
	*out = t;
	return 0;
fail:
	net_tls_destroy(t);
	return rc;
}

void net_tls_destroy(struct net_tls *t)
{
	if (!t)
		return;
	if (t->s) {
		if (t->ready)
			(void)gnutls_bye(t->s, GNUTLS_SHUT_WR); /* best effort, never waits */
		gnutls_deinit(t->s);
	}
	gnutls_certificate_free_credentials(t->cred);
	free(t->ra);
	free(t);
}

/* The message for a handshake that failed with g. Returns the -errno. */
static int handshake_error(struct net_tls *t, int g, char err[256])
{
	if (t->nfirst && memcmp(t->first, PROTO_MAGIC, t->nfirst) == 0) {
		err_set(err, "%s: TLS handshake failed: the server answered in the plain clipmap "
			"protocol (its listener has no [tls] in clipmapd.conf: connect without "
			"--tls-ca/--tls, or turn TLS on there)", t->peer);
		return -EPROTO;
	}
	if (g == GNUTLS_E_CERTIFICATE_VERIFICATION_ERROR || g == GNUTLS_E_CERTIFICATE_ERROR) {
		(void)gnutls_alert_send_appropriate(t->s, g); /* the server logs why */
		unsigned st = gnutls_session_get_verify_cert_status(t->s);
		gnutls_datum_t txt = { 0 };
		if (gnutls_certificate_verification_status_print(st, GNUTLS_CRT_X509, &txt, 0) < 0)
			txt.data = NULL;
		for (size_t n = txt.data ? strlen((char *)txt.data) : 0; n && txt.data[n - 1] == ' ';)
			txt.data[--n] = '\0';
		err_set(err, "%s: TLS: the server's certificate is refused for the name %s by %s: %s",
			t->peer, t->host, t->ca,
			txt.data ? (const char *)txt.data : gnutls_strerror(g));
		gnutls_free(txt.data);
		return -EKEYREJECTED;
	}
	if (g == GNUTLS_E_PREMATURE_TERMINATION || g == GNUTLS_E_PULL_ERROR ||
	    g == GNUTLS_E_PUSH_ERROR) {
		err_set(err, "%s: TLS handshake failed: the server closed the connection (%s)",
			t->peer, gnutls_strerror(g));
		return -ECONNRESET;
	}
	if (g != GNUTLS_E_FATAL_ALERT_RECEIVED)
		(void)gnutls_alert_send_appropriate(t->s, g);
	err_set(err, "%s: TLS handshake failed: %s%s%s", t->peer, gnutls_strerror(g),
		g == GNUTLS_E_FATAL_ALERT_RECEIVED ? " " : "",
		g == GNUTLS_E_FATAL_ALERT_RECEIVED ? gnutls_alert_get_name(gnutls_alert_get(t->s))
						   : "");
	return -EPROTO;
}

int net_tls_handshake(struct net_tls *t, char err[256])
{
	if (t->ready)
		return 0;
	for (int tries = 0; tries < 16; tries++) {
		int g = gnutls_handshake(t->s);
		if (g == GNUTLS_E_SUCCESS) {
			t->ready = true;
			return 0;
		}
		if (g == GNUTLS_E_AGAIN) {
			t->want_write = gnutls_record_get_direction(t->s) == 1;
			return -EAGAIN;
		}
		if (g == GNUTLS_E_INTERRUPTED || !gnutls_error_is_fatal(g))
			continue;
		return handshake_error(t, g, err);
	}
	err_set(err, "%s: TLS handshake failed: too many warnings", t->peer);
	return -EPROTO;
}

bool net_tls_wants_write(const struct net_tls *t)
{
	return t->want_write;
}

ssize_t net_tls_send(struct net_tls *t, const void *p, size_t n, char err[256])
{
	for (;;) {
		ssize_t g = t->resend ? gnutls_record_send(t->s, NULL, 0)
				      : gnutls_record_send(t->s, p, n);
		if (g >= 0) {
			t->resend = false;
			return g;
		}
		t->resend = true;
		if (g == GNUTLS_E_INTERRUPTED)
			continue;
		if (g == GNUTLS_E_AGAIN) {
			t->want_write = true;
			return -EAGAIN;
		}
		err_set(err, "%s: sending over TLS: %s", t->peer, gnutls_strerror((int)g));
		return g == GNUTLS_E_PUSH_ERROR ? -EPIPE : -EPROTO;
	}
}

ssize_t net_tls_recv(struct net_tls *t, void *p, size_t n, char err[256])
{
	size_t got = 0;
	for (int tries = 0; tries < 64;) {
		ssize_t g = gnutls_record_recv(t->s, (unsigned char *)p + got, n - got);
		if (g > 0) {
			got += (size_t)g;
			if (got < n)
				continue; /* until EAGAIN: no whole record stays in the read-ahead */
			return (ssize_t)got;
		}
		if (got)
			return (ssize_t)got; /* the end or an error shows on the next call */
		if (g == 0 || g == GNUTLS_E_PREMATURE_TERMINATION)
			return 0;
		if (g == GNUTLS_E_AGAIN) {
			t->want_write = gnutls_record_get_direction(t->s) == 1;
			return -EAGAIN;
		}
		if (g == GNUTLS_E_INTERRUPTED || !gnutls_error_is_fatal((int)g)) {
			tries++;
			continue;
		}
		err_set(err, "%s: receiving over TLS: %s", t->peer, gnutls_strerror((int)g));
		return g == GNUTLS_E_PULL_ERROR ? -ECONNRESET : -EPROTO;
	}
	return got ? (ssize_t)got : -EAGAIN;
}
