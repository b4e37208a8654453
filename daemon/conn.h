/* conn — a framed, non-blocking stream connection: input accumulates in a buffer and is cut
 * into protocol frames (proto_decode, with the session's frame-size cap); output is a queue
 * of pieces (conn_seg: owned message bytes, or TILE frames whose payload is a shared
 * encoding, whole or as TILE_PART frames) that conn_flush writes out with sendmsg as far as
 * the socket takes, without copying the payloads. Reading pauses while too much output is pending (a peer that does
 * not read cannot make us queue without bound).
 *
 * With TLS (conn_start_tls, on a TCP listener with [tls]) the same calls carry the stream
 * through a tls_stream (tls.h): reading and flushing advance its handshake first, and the
 * frames are records' plaintext (each piece is handed to GnuTLS in turn, which copies it
 * into records); the caller sees no difference but the events it is asked to wait for.
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

struct etile;

/* One piece of the output: bytes the conn owns (messages, appended to while it is the last),
 * or a TILE frame: a header of its own and the shared payload of an encoding (encq.h), which
 * may still be under way (nothing after it goes out before it is ready). */
struct conn_seg {
	struct etile *e;    /* a TILE frame (owned reference); NULL: bytes */
	struct pbuf b;	    /* bytes: the data; TILE: its header, made once e is ready */
	size_t off;	    /* bytes of this piece the socket already took */
	uint64_t counted;   /* bytes counted in the conn's pending for it */
	struct proto_tile pt; /* TILE: this session's fields (seq, planet id, layer, key) */
	uint32_t part;	      /* TILE: sent as TILE_PART frames of this many payload bytes; 0: whole */
	size_t end;	      /* TILE: bytes of the piece that go out (less once a recall cut it) */
};

struct conn {
	int fd;
	struct pbuf in;	 /* received bytes not yet consumed */
	/* frames to send, in order: seg[head, n) */
	struct conn_seg *seg;
	size_t head, n, cap;
	uint64_t pending; /* unsent bytes (a TILE not yet encoded: its upper bound) */
	uint64_t owned;	  /* bytes of buffers the output owns (headers and messages) */
	bool reading;  /* wants input (EPOLLIN) */
	bool want_out; /* has output ready to send, or its TLS handshake waits to write */
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
/* Writes what the socket takes, at most max bytes (SIZE_MAX: no cap; over TLS whole records,
 * so up to a record past it), and updates want_out (still set when max stopped it); the bytes
 * written are added to *sent. Over TLS, advances the handshake first; output queued before the handshake completed
 * cannot go out and fails the connection (-ENOTCONN). Returns 0 or -errno (the connection
 * failed). */
int conn_flush(struct conn *c, uint64_t *sent, size_t max);
/* Output backpressure: stops reading above 2 × max_pending unsent bytes, resumes below
 * max_pending. */
void conn_throttle(struct conn *c, uint64_t max_pending);
/* The buffer a message is appended to (proto_encode), then conn_msg_end. */
struct pbuf *conn_msg_begin(struct conn *c);
void conn_msg_end(struct conn *c);
/* Queues a TILE frame: e's payload (a reference is taken) with a header made from pt's seq,
 * planet_id, layer and key once e is ready. An encoding that failed is skipped. part > 0 (the
 * peer reassembles TILE_PART): a payload longer than part bytes goes as TILE_PART frames of
 * part bytes each, so that a recall can stop it between two of them. */
void conn_put_tile(struct conn *c, struct etile *e, const struct proto_tile *pt, uint32_t part);
/* Takes the TILE frames of which no byte went out yet and for which drop(ud, key) is true
 * out of the output, and cuts a tile sent in parts after the part the socket has begun.
 * Returns how many tiles, and the bytes taken back in *bytes. */
size_t conn_recall(struct conn *c, bool (*drop)(void *ud, const struct tile_key *k), void *ud,
		   uint64_t *bytes);

#endif
