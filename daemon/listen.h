/* listen — clipmapd's listening sockets: the fds systemd passed (socket activation) or else the
 * conf's Unix socket and TCP addresses, each classified from its bound address (loopback or
 * not) against the conf's token and compression policies; accepting a connection and giving
 * it the listener's socket options.
 *
 * Threads: the event loop's thread only. Ownership: a listener owns its fd; the conf is
 * borrowed.
 */
#ifndef CLIPMAP_LISTEN_H
#define CLIPMAP_LISTEN_H
#include <stdbool.h>
#include <sys/socket.h>
#include <sys/types.h>

#include "conf.h"

#define LISTEN_MAX (CONF_MAX_TCP + 1)

struct tls_server;

struct listener {
	int fd; /* non-blocking; -1 once closed */
	bool is_unix, loopback, need_token, compress;
	struct tls_server *tls; /* TCP with [tls]: its sessions speak TLS (borrowed); NULL: plain */
	char name[160]; /* "unix:/path" or "tcp:127.0.0.1:7878" */
	bool own_path;	/* a Unix socket this process bound: the file it created is... */
	dev_t path_dev; /* ...this one, removed at close only while the path still names it */
	ino_t path_ino;
};

/* Opens and classifies the listeners into ls (room for LISTEN_MAX), *n of them. A Unix socket
 * path that exists is first connected to: when something accepts (another clipmapd), this
 * fails with -EADDRINUSE and "PATH: already in use by a running server"; a stale socket (the
 * connection refused) is replaced. Returns 0, or -errno with err filled and those opened so
 * far in ls[0..*n) (listen_close them). */
int listen_open(const struct conf *c, struct listener *ls, int *n, char err[256]);
/* Closes l (logs a failure); a Unix socket it bound itself is removed while the path is still
 * that socket (same device and inode: a daemon started since on the same path keeps its own);
 * an activated one belongs to systemd. */
void listen_close(const struct conf *c, struct listener *l);
/* Accepts one connection (non-blocking, close-on-exec); the peer's address goes to *peer
 * (may be NULL). Returns its fd (owned), -EAGAIN when none is waiting, or another -errno. */
int listen_accept(const struct listener *l, struct sockaddr_storage *peer);
/* Gives an accepted fd the listener's socket options (TCP_NODELAY; a larger send buffer on
 * Unix sockets). A failure is logged and otherwise ignored. */
void listen_tune(const struct listener *l, int fd);

#endif
