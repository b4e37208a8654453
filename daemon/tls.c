/* tls — see tls.h. GnuTLS reads a record's header and then exactly its body from the socket
 * (no read-ahead), and tls_stream_recv is given room for a whole record, so after a read the
 * only bytes GnuTLS may hold are a record still incomplete: the socket signals when its rest
 * arrives, and epoll (level-triggered) never forgets readable data. tls_stream_pending is
 * there for the caller to make sure of it.
 * Writes: GnuTLS pushes each record (16 KiB at most) on its own; sent straight to the socket
 * that is a system call per record. Instead its push function appends to the stream's own
 * buffer, which goes out in one send() per chunk of records (growing while the socket takes
 * whole chunks, up to BATCH bytes of plaintext per call), as far as the socket takes; the
 * rest waits there (tls_stream_unsent) for EPOLLOUT. So a record is never half written inside
 * GnuTLS, and its EAGAIN never happens.
 */
#include "tls.h"

#include <arpa/inet.h>
#include <errno.h>
#include <gnutls/gnutls.h>
#include <gnutls/x509.h>
#include <netinet/in.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <time.h>

#include "common/clock.h"
#include "common/errbuf.h"
#include "common/log.h"
#include "common/proto.h"
#include "common/xalloc.h"

#define PRIORITIES "NORMAL:-VERS-ALL:+VERS-TLS1.3:+VERS-TLS1.2"
#define FAIL_LOG_WINDOW_NS 10000000000ull /* failed handshakes: at most FAIL_LOG_LINES lines */
#define FAIL_LOG_LINES 5		      /* per 10 s */
#define MAX_PEM (1u << 20)
#define TLS_HANDSHAKE_BYTE 0x16 /* a TLS record of type handshake: a ClientHello begins so */
#define BATCH (256u << 10)	/* plaintext encrypted per tls_stream_send */

struct tls_server {
	gnutls_certificate_credentials_t cred;
	gnutls_priority_t prio;
	int refs;		 /* the creator's and one per stream */
	struct tls_tally *tally; /* borrowed, or own */
	struct tls_tally own;
};

struct tls_stream {
	struct tls_server *srv;
	gnutls_session_t s;
	int fd;
	bool sniffed;	 /* the first byte was looked at */
	bool ready;	 /* handshake complete */
	bool failed;
	struct pbuf wb;	 /* encrypted records not yet taken by the socket: [wb_off, len) */
	size_t wb_off;
	char peer[64];
	char err[200];
};

/* Reads a PEM file of the conf into *d (gnutls_free it). Returns 0 or -errno with err. */
static int load_pem(const char *key, const char *path, gnutls_datum_t *d, char err[256])
{
	FILE *f = fopen(path, "rb");
	if (!f) {
		int e = errno;
		err_set(err, "[tls] %s %s: %s", key, path, strerror(e));
		return -e;
	}
	struct stat st;
	int e = fstat(fileno(f), &st) ? errno : !S_ISREG(st.st_mode) ? EINVAL : 0;
	if (!e && st.st_size > MAX_PEM)
		e = EFBIG;
	if (e) {
		err_set(err, "[tls] %s %s: %s", key, path,
			e == EINVAL ? "not a regular file" : e == EFBIG ? "larger than 1 MiB" : strerror(e));
		fclose(f);
		return -e;
	}
	d->data = gnutls_malloc((size_t)st.st_size + 1);
	if (!d->data)
		abort();
	size_t n = fread(d->data, 1, (size_t)st.st_size, f);
	bool bad = ferror(f) != 0;
	fclose(f);
	if (bad) {
		gnutls_free(d->data);
		d->data = NULL;
		err_set(err, "[tls] %s %s: read error", key, path);
		return -EIO;
	}
	d->data[n] = 0;
	d->size = (unsigned)n;
	return 0;
}

int tls_pem_read(const char *key, const char *path, char **out, char err[256])
{
	gnutls_datum_t d = { 0 };
	*out = NULL;
	int rc = load_pem(key, path, &d, err);
	if (rc)
		return rc;
	*out = xmalloc(d.size + 1);
	memcpy(*out, d.data, d.size + 1); /* load_pem terminated it */
	memset(d.data, 0, d.size);
	gnutls_free(d.data);
	return 0;
}

/* "2027-01-31 12:00 UTC" */
static void fmt_time(time_t t, char *out, size_t n)
{
	struct tm tm;
	if (!gmtime_r(&t, &tm) || !strftime(out, n, "%Y-%m-%d %H:%M UTC", &tm))
		snprintf(out, n, "%lld", (long long)t);
}

/* Checks the certificate's dates against now into warn. */
static void check_dates(gnutls_x509_crt_t crt, const char *path, char warn[256])
{
	time_t now = time(NULL), from = gnutls_x509_crt_get_activation_time(crt),
	       to = gnutls_x509_crt_get_expiration_time(crt);
	char when[64];
	if (to != (time_t)-1 && to < now) {
		fmt_time(to, when, sizeof when);
		err_set(warn, "[tls] cert %s expired on %s: clients will refuse it", path, when);
	} else if (from != (time_t)-1 && from > now) {
		fmt_time(from, when, sizeof when);
		err_set(warn, "[tls] cert %s is not valid before %s: clients will refuse it", path,
			when);
	}
}

int tls_server_create(const char *cert, const char *key, struct tls_tally *tally,
		      struct tls_server **out, char err[256], char warn[256])
{
	*out = NULL;
	if (warn)
		warn[0] = '\0';
	gnutls_datum_t cd = { 0 }, kd = { 0 };
	gnutls_x509_crt_t *crts = NULL;
	unsigned ncrt = 0;
	gnutls_x509_privkey_t pk = NULL;
	struct tls_server *t = xcalloc(1, sizeof *t);
	t->refs = 1;
	t->tally = tally ? tally : &t->own;
	int rc, g;
	if ((rc = load_pem("cert", cert, &cd, err)) || (rc = load_pem("key", key, &kd, err)))
		goto fail;
	rc = -EINVAL;
	g = gnutls_x509_crt_list_import2(&crts, &ncrt, &cd, GNUTLS_X509_FMT_PEM, 0);
	if (g < 0 || ncrt == 0) {
		err_set(err, "[tls] cert %s: no PEM certificate in it (%s)", cert,
			g < 0 ? gnutls_strerror(g) : "none found");
		goto fail;
	}
	if ((g = gnutls_x509_privkey_init(&pk)) < 0) {
		err_set(err, "[tls] key: %s", gnutls_strerror(g));
		goto fail;
	}
	g = gnutls_x509_privkey_import2(pk, &kd, GNUTLS_X509_FMT_PEM, NULL, GNUTLS_PKCS_PLAIN);
	if (g < 0) {
		err_set(err, "[tls] key %s: not an unencrypted PEM private key (%s)", key,
			g == GNUTLS_E_DECRYPTION_FAILED ? "it is encrypted: clipmapd cannot ask for "
							  "a passphrase"
							: gnutls_strerror(g));
		goto fail;
	}
	if ((g = gnutls_certificate_allocate_credentials(&t->cred)) < 0) {
		err_set(err, "[tls]: %s", gnutls_strerror(g));
		goto fail;
	}
	g = gnutls_certificate_set_x509_key(t->cred, crts, ncrt, pk);
	if (g < 0) {
		if (g == GNUTLS_E_CERTIFICATE_KEY_MISMATCH)
			err_set(err, "[tls] key %s is not the key of the certificate in %s", key, cert);
		else
			err_set(err, "[tls] cert %s with key %s: %s", cert, key, gnutls_strerror(g));
		goto fail;
	}
	const char *pos = NULL;
	if ((g = gnutls_priority_init(&t->prio, PRIORITIES, &pos)) < 0) {
		err_set(err, "[tls] priorities \"%s\" at \"%s\": %s", PRIORITIES, pos ? pos : "",
			gnutls_strerror(g));
		goto fail;
	}
	if (warn)
		check_dates(crts[0], cert, warn);
	rc = 0;
	*out = t;
	t = NULL;
fail:
	for (unsigned i = 0; i < ncrt; i++)
		gnutls_x509_crt_deinit(crts[i]);
	gnutls_free(crts);
	if (pk)
		gnutls_x509_privkey_deinit(pk);
	if (kd.data) {
		memset(kd.data, 0, kd.size); /* the key's bytes do not stay in freed memory */
		gnutls_free(kd.data);
	}
	gnutls_free(cd.data);
	tls_server_destroy(t);
	return rc;
}

void tls_server_destroy(struct tls_server *t)
{
	if (!t || --t->refs > 0)
		return;
	if (t->prio)
		gnutls_priority_deinit(t->prio);
	if (t->cred)
		gnutls_certificate_free_credentials(t->cred);
	free(t);
}

/* Records why s failed and logs it, at most FAIL_LOG_LINES times per FAIL_LOG_WINDOW_NS per
 * server. */
static void fail(struct tls_stream *s, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
static void fail(struct tls_stream *s, const char *fmt, ...)
{
	va_list ap;
	va_start(ap, fmt);
	vsnprintf(s->err, sizeof s->err, fmt, ap);
	va_end(ap);
	s->failed = true;
	struct tls_tally *t = s->srv->tally;
	t->failed++;
	uint64_t now = clock_now_ns();
	if (!t->window_ns || now - t->window_ns >= FAIL_LOG_WINDOW_NS) {
		t->window_ns = now;
		t->lines = 0;
	}
	if (t->lines == FAIL_LOG_LINES) {
		t->unlogged++;
		return;
	}
	char more[96] = "";
	if (t->unlogged)
		snprintf(more, sizeof more, " (and %lu more failed TLS handshakes not logged)",
			 t->unlogged);
	log_msg(LOG_WARN, "tls: handshake with %s failed: %s%s", s->peer, s->err, more);
	t->unlogged = 0;
	t->lines++;
}

/* GnuTLS's output: appended to wb (sent by write_out). */
static ssize_t push(gnutls_transport_ptr_t p, const void *data, size_t n)
{
	struct tls_stream *s = p;
	if (pbuf_append(&s->wb, data, n))
		abort(); /* growable: only ENOMEM, which aborts first */
	return (ssize_t)n;
}

static ssize_t pull(gnutls_transport_ptr_t p, void *data, size_t n)
{
	struct tls_stream *s = p;
	ssize_t r;
	do
		r = recv(s->fd, data, n, MSG_DONTWAIT);
	while (r < 0 && errno == EINTR);
	if (r < 0)
		gnutls_transport_set_errno(s->s, errno);
	return r;
}

/* Only asked with 0 (is anything there?): the stream never waits. */
static int pull_timeout(gnutls_transport_ptr_t p, unsigned int ms)
{
	struct tls_stream *s = p;
	(void)ms;
	struct pollfd pf = { .fd = s->fd, .events = POLLIN };
	int r = poll(&pf, 1, 0);
	if (r < 0)
		gnutls_transport_set_errno(s->s, errno);
	return r;
}

/* Sends what wb holds as far as the socket takes. Returns 0 or -errno (the peer is gone). */
static int write_out(struct tls_stream *s)
{
	while (s->wb_off < s->wb.len) {
		ssize_t n = send(s->fd, s->wb.data + s->wb_off, s->wb.len - s->wb_off,
				 MSG_NOSIGNAL | MSG_DONTWAIT);
		if (n < 0 && errno == EINTR)
			continue;
		if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
			break;
		if (n < 0) {
			int e = errno;
			snprintf(s->err, sizeof s->err, "send: %s", strerror(e));
			return -e;
		}
		s->wb_off += (size_t)n;
	}
	if (s->wb_off == s->wb.len) {
		s->wb.len = s->wb_off = 0;
	} else if (s->wb_off > BATCH) {
		memmove(s->wb.data, s->wb.data + s->wb_off, s->wb.len - s->wb_off);
		s->wb.len -= s->wb_off;
		s->wb_off = 0;
	}
	return 0;
}

size_t tls_stream_unsent(const struct tls_stream *s)
{
	return s->wb.len - s->wb_off;
}

struct tls_stream *tls_stream_create(struct tls_server *t, int fd)
{
	struct tls_stream *s = xcalloc(1, sizeof *s);
	s->srv = t;
	s->fd = fd;
	snprintf(s->peer, sizeof s->peer, "unknown peer");
	struct sockaddr_storage ss;
	socklen_t len = sizeof ss;
	char host[INET6_ADDRSTRLEN] = "?";
	memset(&ss, 0, sizeof ss);
	if (getpeername(fd, (struct sockaddr *)&ss, &len) != 0)
		ss.ss_family = AF_UNSPEC;
	if (ss.ss_family == AF_INET) {
		const struct sockaddr_in *a = (const struct sockaddr_in *)&ss;
		inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
		snprintf(s->peer, sizeof s->peer, "%s:%u", host, (unsigned)ntohs(a->sin_port));
	} else if (ss.ss_family == AF_INET6) {
		const struct sockaddr_in6 *a = (const struct sockaddr_in6 *)&ss;
		inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
		snprintf(s->peer, sizeof s->peer, "[%s]:%u", host, (unsigned)ntohs(a->sin6_port));
	}
	if (gnutls_init(&s->s, GNUTLS_SERVER | GNUTLS_NONBLOCK | GNUTLS_NO_SIGNAL) < 0) {
		free(s);
		return NULL;
	}
	pbuf_init(&s->wb);
	if (gnutls_priority_set(s->s, t->prio) < 0 ||
	    gnutls_credentials_set(s->s, GNUTLS_CRD_CERTIFICATE, t->cred) < 0) {
		gnutls_deinit(s->s);
		free(s);
		return NULL;
	}
	gnutls_certificate_server_set_request(s->s, GNUTLS_CERT_IGNORE);
	gnutls_handshake_set_timeout(s->s, 0); /* the session's handshake_timeout bounds it */
	t->refs++;
	gnutls_transport_set_ptr(s->s, s);
	gnutls_transport_set_push_function(s->s, push);
	gnutls_transport_set_pull_function(s->s, pull);
	gnutls_transport_set_pull_timeout_function(s->s, pull_timeout);
	return s;
}

void tls_stream_destroy(struct tls_stream *s)
{
	if (!s)
		return;
	if (s->ready && !s->failed && gnutls_bye(s->s, GNUTLS_SHUT_WR) == 0)
		(void)write_out(s); /* close_notify: best effort, never waits */
	gnutls_deinit(s->s);
	pbuf_fini(&s->wb);
	tls_server_destroy(s->srv);
	free(s);
}

/* The plain protocol's answer to a client that did not start TLS: an ERROR it can show. */
static void tell_plain_client(struct tls_stream *s)
{
	struct pbuf b;
	pbuf_init(&b);
	struct proto_msg m = { .type = PROTO_ERROR,
			       .error = { .code = PROTO_E_PROTOCOL, .ref_type = PROTO_HELLO,
					  .message = "this listener speaks TLS: connect with "
						     "--tls-ca FILE (or --tls)" } };
	if (proto_encode(&b, &m, NULL) > 0)
		(void)send(s->fd, b.data, b.len, MSG_NOSIGNAL | MSG_DONTWAIT); /* best effort */
	pbuf_fini(&b);
	/* Its HELLO is read away: closing with unread input would make the kernel reset the
	 * connection, and the client could lose the ERROR. */
	char sink[4096];
	for (int i = 0; i < 4 && recv(s->fd, sink, sizeof sink, MSG_DONTWAIT) > 0; i++)
		;
}

/* Looks at the first byte before GnuTLS reads anything. Returns 0 when it starts a TLS
 * handshake, -EAGAIN, or -EPROTO (failed). */
static int sniff(struct tls_stream *s)
{
	unsigned char b[4];
	ssize_t n;
	do
		n = recv(s->fd, b, sizeof b, MSG_PEEK | MSG_DONTWAIT);
	while (n < 0 && errno == EINTR);
	if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK))
		return -EAGAIN;
	if (n < 0) {
		fail(s, "%s", strerror(errno));
		return -EPROTO;
	}
	if (n == 0) {
		fail(s, "the peer closed the connection without a word");
		return -EPROTO;
	}
	if (b[0] == TLS_HANDSHAKE_BYTE) {
		s->sniffed = true;
		return 0;
	}
	if (memcmp(b, PROTO_MAGIC, (size_t)n < 4 ? (size_t)n : 4) == 0) {
		tell_plain_client(s);
		fail(s, "a plain clipmap client (no TLS) on a TLS listener: told to use --tls-ca");
	} else {
		fail(s, "not a TLS handshake (first byte 0x%02x)", b[0]);
	}
	return -EPROTO;
}

int tls_stream_handshake(struct tls_stream *s)
{
	if (s->ready)
		return 0;
	if (s->failed)
		return -EPROTO;
	if (!s->sniffed) {
		int rc = sniff(s);
		if (rc)
			return rc;
	}
	for (int tries = 0; tries < 16; tries++) {
		int g = gnutls_handshake(s->s);
		int w = write_out(s);
		if (w) {
			s->failed = true;
			return w;
		}
		if (g == GNUTLS_E_SUCCESS) {
			s->ready = true;
			s->srv->tally->handshakes++;
			return 0;
		}
		if (g == GNUTLS_E_AGAIN)
			return -EAGAIN;
		if (g == GNUTLS_E_INTERRUPTED || !gnutls_error_is_fatal(g))
			continue; /* a warning alert: go on */
		if (g == GNUTLS_E_FATAL_ALERT_RECEIVED) {
			fail(s, "the client refused it: %s (does the client trust the CA that "
				"signed [tls] cert, and is the name it connected to in it?)",
			     gnutls_alert_get_name(gnutls_alert_get(s->s)));
			return -EPROTO;
		}
		if (gnutls_alert_send_appropriate(s->s, g) == 0)
			(void)write_out(s);
		fail(s, "%s", gnutls_strerror(g));
		return -EPROTO;
	}
	fail(s, "too many warnings during the handshake");
	return -EPROTO;
}

bool tls_stream_ready(const struct tls_stream *s)
{
	return s->ready;
}


ssize_t tls_stream_recv(struct tls_stream *s, void *buf, size_t n)
{
	for (int tries = 0; tries < 16; tries++) {
		ssize_t g = gnutls_record_recv(s->s, buf, n);
		if (g >= 0)
			return g;
		if (g == GNUTLS_E_AGAIN)
			return -EAGAIN;
		if (g == GNUTLS_E_PREMATURE_TERMINATION)
			return 0; /* closed without close_notify: an end all the same */
		if (g == GNUTLS_E_INTERRUPTED || !gnutls_error_is_fatal((int)g))
			continue; /* a renegotiation request or a warning: ignored */
		snprintf(s->err, sizeof s->err, "TLS: %s", gnutls_strerror((int)g));
		s->failed = true;
		return g == GNUTLS_E_PULL_ERROR ? -ECONNRESET : -EPROTO;
	}
	return -EAGAIN;
}

size_t tls_stream_pending(const struct tls_stream *s)
{
	return gnutls_record_check_pending(s->s);
}

ssize_t tls_stream_send(struct tls_stream *s, const void *p, size_t n)
{
	int rc = write_out(s);
	if (rc)
		return rc;
	if (tls_stream_unsent(s))
		return -EAGAIN; /* the last batch first */
	/* Chunks of 16 KiB, then twice as much each time the socket took all of the last: a
	 * fast socket gets few system calls, and a slow one (or one held to TCP_NOTSENT_LOWAT)
	 * leaves at most one chunk encrypted and waiting here, where a new want-set cannot
	 * recall it. */
	size_t done = 0, chunk = 16u << 10;
	while (done < n && done < BATCH && !tls_stream_unsent(s)) {
		size_t end = done + (chunk < n - done ? chunk : n - done);
		end = end < BATCH ? end : BATCH;
		while (done < end) {
			ssize_t g = gnutls_record_send(s->s, (const uint8_t *)p + done, end - done);
			if (g == GNUTLS_E_INTERRUPTED)
				continue;
			if (g < 0) {
				snprintf(s->err, sizeof s->err, "TLS: %s", gnutls_strerror((int)g));
				s->failed = true;
				return -EPROTO;
			}
			done += (size_t)g;
		}
		if ((rc = write_out(s)))
			return rc;
		chunk *= 2;
	}
	return (ssize_t)done;
}

const char *tls_stream_error(const struct tls_stream *s)
{
	return s->err;
}
