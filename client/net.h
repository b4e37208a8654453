/* net — a small blocking client connection to clipmapd (docs/PROTOCOL.md): connect to a Unix
 * socket or HOST:PORT, handshake, send messages, receive the next complete message (with a
 * timeout), decode tile payloads. Used by clipmapctl and the viewer.
 *
 * Thread-safety: a net_conn has one owner thread; distinct connections are independent.
 * Ownership: net_connect returns an owned connection (net_close frees it). A received
 * proto_msg owns its storage (proto_msg_fini), except a TILE's payload, which borrows from the
 * connection's buffer and stays valid until the next net_recv/net_close on that connection.
 * Errors: every function returns 0 or -errno and fills err[256] with a message that names the
 * peer; nothing logs, nothing exits. Writes use MSG_NOSIGNAL, so no SIGPIPE.
 */
#ifndef CLIPMAP_NET_H
#define CLIPMAP_NET_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"

#define NET_DEFAULT_TIMEOUT_MS 10000

struct net_opts {
	const char *socket_path; /* Unix socket path (used when hostport is NULL) */
	const char *hostport;	 /* "HOST:PORT" or "[V6ADDR]:PORT" (TCP); wins over socket_path */
	const char *token_file;	 /* token read from this file (trailing whitespace dropped);
				  * NULL: $CLIPMAP_TOKEN if set, else an empty token */
	const char *name;	 /* client name for HELLO; NULL: "clipmap-client/1" */
	uint32_t codecs;	 /* tile codecs offered (1 << enum tcodec); 0: the lossless ones
				  * (the lossy ones only where the caller asks: a viewer) */
	int timeout_ms;		 /* connect, handshake and send limit; 0: NET_DEFAULT_TIMEOUT_MS,
				  * < 0: none */
	/* TLS (TCP only; a Unix socket is always plain). The server's certificate must lead to
	 * a CA in tls_ca (PEM) and name the host of hostport; the HELLO (and so the token) is
	 * sent only after that. tls_ca NULL: $CLIPMAP_TLS_CA when set and non-empty (net_connect
	 * only), else TLS only with `tls`, trusting the system's store. */
	const char *tls_ca;
	bool tls;
	bool whole_tiles; /* do not offer PROTO_FEAT_PARTS: every tile in one TILE frame */
};

struct net_conn;

/* Connects and handshakes (TLS first when asked). Returns 0 with *out owned, or -errno with
 * err filled: connect failures keep the connect errno (-ENOENT, -ECONNREFUSED, …) and read
 * "cannot connect to PEER: REASON"; a refused handshake maps the server's ERROR code
 * (net_code_errno); a TLS failure is -EKEYREJECTED (the certificate: GnuTLS's verification
 * status in err), -EPROTO (no TLS there, or no common ground) or -ECONNRESET. */
int net_connect(const struct net_opts *o, struct net_conn **out, char err[256]);
/* Handshakes over an already connected stream socket fd (taken: closed by net_close, or on
 * failure). peer names it in messages (copied). TLS when o->tls_ca or o->tls, for the host of
 * o->hostport (else of peer). */
int net_connect_fd(int fd, const char *peer, const struct net_opts *o, struct net_conn **out,
		   char err[256]);
/* Connecting without waiting, for a caller that must not block (the viewer's frame loop while
 * it reconnects): net_connect_start opens the socket and starts connecting (a TCP connect
 * goes on in the background; name resolution, getaddrinfo, may still wait: numeric addresses
 * and /etc/hosts names do not), and returns the connection in *out. net_connect_step then
 * advances it without blocking: the connect's outcome (the next address of the name when one
 * is refused), HELLO, HELLO_OK. Returns 0 once the handshake is done (the connection is then
 * as net_connect's), -EAGAIN while it goes on (wait on net_fd for net_connect_events), or
 * -errno with err filled as net_connect fills it; the caller net_closes it either way. Neither
 * bounds the time: the caller gives up when it has waited long enough. */
int net_connect_start(const struct net_opts *o, struct net_conn **out, char err[256]);
int net_connect_step(struct net_conn *c, char err[256]);
/* POLLOUT while the connect is in progress, else POLLIN. */
short net_connect_events(const struct net_conn *c);

/* The delay before reconnect attempt `attempt` (1, 2, …), milliseconds: base_ms doubling with
 * each attempt up to cap_ms, of which a random half is taken away ("equal jitter": in
 * [d/2, d]) so that clients cut off together do not come back together. *seed is the
 * caller's random state (rand_r). */
int net_backoff_ms(unsigned attempt, int base_ms, int cap_ms, unsigned *seed);

/* Sends BYE (best effort, without waiting) and closes. NULL is a no-op. */
void net_close(struct net_conn *c);

/* For poll() alongside other fds. Over TLS too: net_recv leaves no decrypted bytes inside
 * GnuTLS, so when it returned -EAGAIN the fd's readability is the signal to call again. */
int net_fd(const struct net_conn *c);
/* Whether the connection is TLS. */
bool net_is_tls(const struct net_conn *c);
const char *net_peer(const struct net_conn *c);		   /* "/run/…sock" or "host:port" */
const struct proto_hello_ok *net_hello(const struct net_conn *c); /* borrowed; name owned by c */
/* Bytes on the wire of the message net_recv returned last, frame headers included (a tile
 * that came in parts: all its TILE_PART frames). */
uint64_t net_last_wire(const struct net_conn *c);
/* Bytes of tiles begun in parts that the server stopped sending (it no longer wanted them
 * sent), since the connection opened: received, and dropped here. */
uint64_t net_parts_dropped(const struct net_conn *c);
/* Bytes on the wire of the parts of a tile received so far whose last part has not come. */
uint64_t net_parts_open(const struct net_conn *c);
/* A fresh request id (1, 2, …) for LIST_PLANETS/OPEN/STATS_REQ/CACHE_LS/PREFETCH. */
uint32_t net_next_req(struct net_conn *c);

/* Encodes m and writes it fully (EINTR and short writes handled; waits for the socket at
 * most the connection's timeout). Returns 0 or -errno. */
int net_send(struct net_conn *c, const struct proto_msg *m, char err[256]);

/* Receives the next message into m (zeroed or finied by the caller). timeout_ms bounds the
 * whole wait (< 0: none; 0: only what can be read without blocking — -EAGAIN when no whole
 * frame is there yet). Returns 0, or -ETIMEDOUT, -ECONNRESET (the peer closed, also in the
 * middle of a frame), a PROTO_ERR_* for a malformed frame (the connection is then unusable),
 * or a read errno. An ERROR from the server is returned as a message (type PROTO_ERROR). */
int net_recv(struct net_conn *c, struct proto_msg *m, int timeout_ms, char err[256]);

/* Receives until a message of `type` arrives, skipping TILE, TILE_FAIL and
 * PREFETCH_PROGRESS messages (pass them through skip_fn if set; then they are finied after
 * it returns). A server ERROR becomes -net_code_errno(code) with err "PEER: CODE: message".
 * Returns 0 with m filled, or -errno. */
int net_expect(struct net_conn *c, uint16_t type, struct proto_msg *m, int timeout_ms,
	       void (*skip_fn)(void *ud, const struct proto_msg *m), void *ud, char err[256]);

/* Describes a server ERROR message: "PEER: CODE: message". */
void net_error_text(const struct net_conn *c, const struct proto_error *e, char err[256]);
/* The errno a server error code stands for (positive): not-found ENOENT, auth EACCES,
 * version EPROTONOSUPPORT, limit E2BIG, invalid EINVAL, unavailable EIO, busy EBUSY,
 * shutdown ESHUTDOWN, protocol/state EPROTO, others EREMOTEIO. */
int net_code_errno(uint16_t code);

/* Decodes a received TILE's payload into texels[0 .. cap) (cap ≥ t->enc.raw_len) and checks
 * its checksum. Returns 0 or -EINVAL / -EBADMSG / -EILSEQ with err filled. */
int net_tile_decode(struct net_conn *c, const struct proto_tile *t, void *texels, size_t cap,
		    char err[256]);

/* Reads a token: from file when non-NULL, else $CLIPMAP_TOKEN, else empty. Trailing
 * whitespace is dropped. buf holds PROTO_MAX_TOKEN bytes. Returns 0 or -errno (-E2BIG when
 * longer than PROTO_MAX_TOKEN) with err filled. */
int net_token_load(const char *file, uint8_t buf[PROTO_MAX_TOKEN], uint16_t *len, char err[256]);

/* Sends OPEN for planet `name` and waits for OPENED into m (owned by the caller:
 * proto_msg_fini). Returns 0 or -errno (-ENOENT: no such planet) with err filled. */
int net_open_planet(struct net_conn *c, const char *name, struct proto_msg *m, int timeout_ms,
		    char err[256]);

#endif
