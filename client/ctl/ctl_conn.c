/* ctl_conn — see ctl_conn.h. */
#include "ctl_conn.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

const char *ctl_socket_path(const struct ctl_target *t)
{
	if (t->socket_path)
		return t->socket_path;
	const char *e = getenv("CLIPMAP_SOCKET");
	return e && *e ? e : CTL_DEFAULT_SOCKET;
}

int ctl_connect(const struct ctl_target *t, struct net_conn **c, char err[256])
{
	struct net_opts o = { .socket_path = t->hostport ? NULL : ctl_socket_path(t),
			      .hostport = t->hostport, .token_file = t->token_file,
			      .name = "clipmapctl/1", .timeout_ms = t->timeout_ms,
			      .tls_ca = t->tls_ca, .tls = t->tls };
	char e2[256];
	int rc = net_connect(&o, c, e2);
	if (rc == 0)
		return 0;
	const char *hint = "";
	if (strncmp(e2, "cannot connect", 14) == 0 &&
	    (rc == -ENOENT || rc == -ECONNREFUSED || rc == -ETIMEDOUT || rc == -EHOSTUNREACH))
		hint = t->hostport ? " \xe2\x80\x94 is clipmapd running and listening there? (-H HOST:PORT)"
				   : " \xe2\x80\x94 is clipmapd running? (-s SOCKET)";
	else if (rc == -EACCES && !t->hostport)
		hint = " (check the socket's permissions or --token-file)";
	size_t l = strlen(e2), hl = strlen(hint);
	if (l + hl >= 256)
		l = 255 - hl;
	memcpy(err, e2, l);
	memcpy(err + l, hint, hl + 1);
	return rc;
}
