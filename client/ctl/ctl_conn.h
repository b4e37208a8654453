/* ctl_conn — how clipmapctl reaches the daemon: the target (Unix socket or HOST:PORT, token
 * file), and connecting with an operator-friendly message.
 * No state of its own; thread-safe as far as net.h is. Messages go to err[256], never out.
 */
#ifndef CLIPMAP_CTL_CONN_H
#define CLIPMAP_CTL_CONN_H
#include "client/net.h"

/* The socket clipmapd listens on by default (conf/clipmapd.conf, [listen] unix). */
#define CTL_DEFAULT_SOCKET "/run/clipmapd/clipmapd.sock"

struct ctl_target {
	const char *socket_path; /* -s; NULL: $CLIPMAP_SOCKET, else CTL_DEFAULT_SOCKET */
	const char *hostport;	 /* -H HOST:PORT; wins over socket_path */
	const char *token_file;	 /* --token-file; NULL: $CLIPMAP_TOKEN */
	const char *tls_ca;	 /* --tls-ca; NULL: $CLIPMAP_TLS_CA (net.h) */
	bool tls;		 /* --tls: TLS, the system's trust store when no CA is given */
	int timeout_ms;		 /* 0: NET_DEFAULT_TIMEOUT_MS */
};

/* The socket path t names (borrowed from t or the environment, or the default). */
const char *ctl_socket_path(const struct ctl_target *t);
/* Connects as "clipmapctl/1". On failure err reads e.g. "cannot connect to /run/…: No such
 * file or directory — is clipmapd running? (-s SOCKET)". Returns 0 or -errno. */
int ctl_connect(const struct ctl_target *t, struct net_conn **c, char err[256]);

#endif
