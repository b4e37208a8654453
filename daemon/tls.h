/* tls — clipmapd's TLS on TCP listeners (GnuTLS): the server's credentials from [tls] cert and
 * key, and one non-blocking TLS stream per accepted connection, driven by the event loop (the
 * handshake advances whenever the socket is readable or writable; records are read and
 * written without blocking). The handshake first looks at the peer's first bytes: a client
 * speaking the plain clipmap protocol gets a plain ERROR saying the listener wants TLS.
 * A failed handshake is logged once (a warning with the peer and the reason), at most 5 lines
 * per 10 s per server: a flood of bad handshakes does not flood the log, and the next line
 * says how many went unlogged.
 *
 * Credentials are reloaded by making a new tls_server: new connections use it, connections
 * already open keep the one they began with. So a tls_server is counted: each stream holds a
 * reference, and tls_server_destroy drops its creator's; the last one frees it.
 *
 * Threads: the event loop's thread only. Ownership: the creator owns a reference to the
 * tls_server and each tls_stream one; a stream borrows its fd (the connection owns it).
 */
#ifndef CLIPMAP_TLS_H
#define CLIPMAP_TLS_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

struct tls_server;
struct tls_stream;

/* What every generation of a listener's credentials adds to (the caller owns it; it must
 * outlive every tls_server and stream made with it). The log window of failed handshakes is
 * here too, so a reload does not reset it. */
struct tls_tally {
	uint64_t handshakes; /* completed */
	uint64_t failed;     /* failed (each also logged, within the window's limit) */
	unsigned long unlogged; /* failed handshakes not logged since the last line */
	uint64_t window_ns;	/* the current logging window began then */
	int lines;		/* lines logged in it */
};

/* Loads the certificate chain (PEM, server first) and its private key (PEM, unencrypted).
 * Returns 0 with *out owned, or -errno with err naming the file and the problem (-ENOENT and
 * friends for a file that cannot be read, -EINVAL for one that is not PEM, a key that does
 * not match the certificate). warn (may be NULL) receives a warning that is no reason to
 * refuse (a certificate expired or not yet valid: clients will refuse it), else "".
 * tally (borrowed, may be NULL: then the server keeps its own) receives the counts. */
int tls_server_create(const char *cert, const char *key, struct tls_tally *tally,
		      struct tls_server **out, char err[256], char warn[256]);
/* The PEM file [tls] `key` names (key: "cert" or "key", for messages), as a NUL-terminated
 * string. Returns 0 with *out owned (free), or -errno with err naming the file. */
int tls_pem_read(const char *key, const char *path, char **out, char err[256]);
/* Drops the creator's reference: the credentials are freed once no stream uses them either.
 * NULL is a no-op. */
void tls_server_destroy(struct tls_server *t);

/* A server-side TLS stream on fd (borrowed, non-blocking); it holds a reference to t.
 * Returns NULL only when GnuTLS cannot make a session (out of memory). */
struct tls_stream *tls_stream_create(struct tls_server *t, int fd);
/* Says close_notify when the handshake completed (best effort, without blocking) and frees.
 * The fd stays open. NULL is a no-op. */
void tls_stream_destroy(struct tls_stream *s);
/* Advances the handshake. Returns 0 once it is complete, -EAGAIN while it waits for the
 * socket (to read; or to write while tls_stream_unsent), -EPROTO when it failed
 * (tls_stream_error says why; the failure was logged), or -errno when the socket failed. */
int tls_stream_handshake(struct tls_stream *s);
bool tls_stream_ready(const struct tls_stream *s);
/* Encrypted bytes the socket has not taken yet: while there are, the stream waits for
 * EPOLLOUT and takes no new plaintext. */
size_t tls_stream_unsent(const struct tls_stream *s);
/* Reads decrypted bytes (the handshake must be complete) into buf[0 .. n), n ≥ 16 KiB so a
 * whole record fits. Returns the count (> 0), 0 at the end of the stream (close_notify or
 * the peer closed), -EAGAIN, or -ECONNRESET / -EPROTO (tls_stream_error says why). */
ssize_t tls_stream_recv(struct tls_stream *s, void *buf, size_t n);
/* Decrypted bytes GnuTLS holds that the socket will not signal (read them now). */
size_t tls_stream_pending(const struct tls_stream *s);
/* Writes out what earlier calls left unsent, then encrypts p[0 .. n) (up to 256 KiB of it)
 * in chunks of 16, 32, 64 … KiB, each written with one system call, while the socket takes
 * whole chunks; what it does not take of the last stays unsent, owned by the stream (at most
 * that chunk: bytes a new want-set can no longer recall). Returns the plaintext bytes taken (> 0 when n > 0), -EAGAIN
 * when earlier bytes are still unsent (nothing taken), or -EPIPE / -ECONNRESET / -EPROTO. */
ssize_t tls_stream_send(struct tls_stream *s, const void *p, size_t n);
/* Why the stream failed ("" while it has not). Borrowed. */
const char *tls_stream_error(const struct tls_stream *s);

#endif
