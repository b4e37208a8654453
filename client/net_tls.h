/* net_tls — the client side of TLS for net.c (GnuTLS): a TLS stream over a connected TCP
 * socket whose server certificate is checked against a CA file (or the system's trust store)
 * and the host name the user gave. Its reads and writes never block (the socket is driven
 * with MSG_DONTWAIT): they return -EAGAIN and net.c waits on the fd with its own deadline.
 * Messages name the peer, the CA and GnuTLS's verification status.
 *
 * Thread-safety: one owner thread per stream. Ownership: a net_tls borrows its fd (the
 * net_conn owns it) and owns its GnuTLS session and credentials.
 */
#ifndef CLIPMAP_NET_TLS_H
#define CLIPMAP_NET_TLS_H
#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

struct net_tls;

/* Prepares TLS on fd for the server `host` (a name or an IP address: the certificate must
 * name it), trusting the certificates in ca_file (PEM), or the system's store when NULL. peer
 * names the server in messages. Returns 0 with *out owned, or -errno with err filled (a CA
 * file that cannot be read or holds no certificate, no system store). */
int net_tls_create(int fd, const char *host, const char *ca_file, const char *peer,
		   struct net_tls **out, char err[256]);
/* Says close_notify (best effort, without blocking) once the handshake completed, and frees.
 * The fd stays open. NULL is a no-op. */
void net_tls_destroy(struct net_tls *t);
/* Advances the handshake (the certificate is verified in it). Returns 0 when complete,
 * -EAGAIN while it waits for the socket (net_tls_wants_write says which way), or -errno with
 * err filled: -EKEYREJECTED for a certificate that is not trusted or does not name the host
 * (GnuTLS's verification status quoted), -EPROTO for a server that does not speak TLS or a
 * failed negotiation, -ECONNRESET when the server closed. */
int net_tls_handshake(struct net_tls *t, char err[256]);
/* Whether the last -EAGAIN waits for the socket to take bytes (POLLOUT) rather than give. */
bool net_tls_wants_write(const struct net_tls *t);
/* Writes from p[0 .. n) (at most one record). After -EAGAIN call again with the same bytes.
 * Returns the count (> 0), -EAGAIN, or -errno with err filled. */
ssize_t net_tls_send(struct net_tls *t, const void *p, size_t n, char err[256]);
/* Reads into p[0 .. n) every whole record GnuTLS can give without blocking (n ≥ 16 KiB).
 * Returns the count (> 0), 0 at the end of the stream, -EAGAIN, or -errno with err filled. */
ssize_t net_tls_recv(struct net_tls *t, void *p, size_t n, char err[256]);

#endif
