/* conn — a framed, non-blocking stream connection: input accumulates in a buffer and is cut
 * into protocol frames (proto_decode, with the session's frame-size cap); output is one
 * growable buffer with a read offset that the owner appends frames to and conn_flush writes
 * out as far as the socket takes. Reading pauses while too much output is pending (a peer
 * that does not read cannot make us queue without bound).
 *
 * With TLS (conn_start_tls, on a TCP listener with [tls]) the same calls carry the stream
 * through a tls_stream (tls.h): reading and flushing advance its handshake first, and the
 * frames are records' plaintext; the caller sees no difference but the events it is asked
 * to wait for.
 *
 * Threads: one owner thread (the event loop). Ownership: a conn owns its fd, buffers and TLS
 * stream.
 */
#ifndef CLIPMAP_CONN_H
#define CLIPMAP_CONN_H
#include <stdbool.h>
#include <stdint.h>
#include <sys/types.h>

#include "common/proto.h"

struct conn {
	int fd;
	struct pbuf in;	 /* received bytes not yet consumed */
	struct pbuf out; /* frames to send: the owner appends, bytes [out_off, len) are unsent */
	size_t out_off;
	bool reading;  /* wants input (EPOLLIN) */
	bool want_out; /* has unsent output, or its TLS handshake waits to write (EPOLLOUT) */
	struct tls_stream *tls; /* NULL: plain */
};
struct tls_server;

/* Starts on fd (taken), reading. */
void conn_init(struct conn *c, int fd);
/* Speaks TLS from now on (server side of tls, borrowed: it outlives the conn), before any
 * byte was read. Returns 0 or -ENOMEM. */
int conn_start_tls(struct conn *c, struct tls_server *tls);
/* What a failed conn_recv / conn_flush (rc) means, for the logs: the TLS layer's reason when
 * it has one, else strerror(-rc). Borrowed until the next call. */
const char *conn_strerror(const struct conn *c, int rc);
/* Says close_notify over TLS (best effort) and closes the fd (once). Returns 0 or -errno. */
int conn_close(struct conn *c);
/* Frees the buffers (the fd must be closed). */
void conn_fini(struct conn *c);
/* The epoll events the connection wants now. */
uint32_t conn_events(const struct conn *c);
/* Unsent output bytes. */
uint64_t conn_pending(const struct conn *c);
/* Receives once (up to 64 KiB) into `in`; over TLS, advances the handshake first and reads
 * every record GnuTLS already holds. Returns the bytes read (> 0), 0 at end of stream,
 * -EAGAIN when nothing is waiting (also while the TLS handshake goes on), or another -errno
 * (-EPROTO: the TLS handshake or stream failed, conn_strerror says why). */
ssize_t conn_recv(struct conn *c);
/* The largest frame (header included) a peer may send before its HELLO is answered: a HELLO
 * at its wire cap. */
#define CONN_PREAUTH_FRAME (PROTO_HDR + 2048u)

/* Decodes the frame at the start of `in` into m (zeroed). Returns its size (> 0: handle m,
 * proto_msg_fini it, then conn_consume that size), 0 when more bytes are needed, or -EPROTO
 * when the stream cannot go on: *code is the ERROR code to answer with, *type the frame's
 * type (0 when its header has not arrived), err the message. As soon as the header is in, and
 * before any of the body is kept: a type the client may not send in state st (a server-to-
 * client type at any time, anything but HELLO and BYE before the handshake) is `state`; a
 * frame over max_frame (0: no cap), or over CONN_PREAUTH_FRAME before the handshake, is
 * `limit`. */
ssize_t conn_decode(struct conn *c, enum proto_state st, uint32_t max_frame, struct proto_msg *m,
		    uint16_t *code, uint16_t *type, char err[256]);
void conn_consume(struct conn *c, size_t n);
/* Writes what the socket takes and updates want_out; the bytes written are added to *sent.
 * Over TLS, advances the handshake first; output queued before the handshake completed
 * cannot go out and fails the connection (-ENOTCONN). Returns 0 or -errno (the connection
 * failed). */
int conn_flush(struct conn *c, uint64_t *sent);
/* Output backpressure: stops reading above 2 × max_pending unsent bytes, resumes below
 * max_pending. */
void conn_throttle(struct conn *c, uint64_t max_pending);
/* Moves the unsent output to the start of the buffer (before growing it). */
void conn_compact(struct conn *c);

#endif
