/* listen — see listen.h. A listener's policy flags come from the address it is actually bound
 * to (getsockname), so "tcp:0.0.0.0:…" and systemd-passed sockets are classified alike; names
 * are what the logs and server_listeners show.
 */
#include "listen.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "common/errbuf.h"
#include "common/log.h"

#define UNIX_SNDBUF (4 << 20) /* bytes asked for per Unix session */
/* Connections the kernel queues before accept (capped by net.core.somaxconn): deep, so a
 * burst of connections (an attacker's) does not make the kernel drop a client's SYN, which
 * costs it a 1 s retransmission; the pre-auth pools bound what is accepted. */
#define BACKLOG 4096

static bool sa_loopback(const struct sockaddr_storage *ss)
{
	if (ss->ss_family == AF_INET)
		return (ntohl(((const struct sockaddr_in *)ss)->sin_addr.s_addr) >> 24) == 127;
	if (ss->ss_family == AF_INET6) {
		const struct in6_addr *a = &((const struct sockaddr_in6 *)ss)->sin6_addr;
		if (IN6_IS_ADDR_V4MAPPED(a))
			return a->s6_addr[12] == 127;
		return IN6_IS_ADDR_LOOPBACK(a);
	}
	return ss->ss_family == AF_UNIX;
}

static void sa_name(const struct sockaddr_storage *ss, char *out, size_t n)
{
	char host[INET6_ADDRSTRLEN] = "?";
	if (ss->ss_family == AF_UNIX) {
		snprintf(out, n, "unix:%s", ((const struct sockaddr_un *)ss)->sun_path);
	} else if (ss->ss_family == AF_INET) {
		const struct sockaddr_in *a = (const struct sockaddr_in *)ss;
		inet_ntop(AF_INET, &a->sin_addr, host, sizeof host);
		snprintf(out, n, "tcp:%s:%u", host, ntohs(a->sin_port));
	} else {
		const struct sockaddr_in6 *a = (const struct sockaddr_in6 *)ss;
		inet_ntop(AF_INET6, &a->sin6_addr, host, sizeof host);
		snprintf(out, n, "tcp:[%s]:%u", host, ntohs(a->sin6_port));
	}
}

/* Fills the listener's flags from its bound address and the conf's policies. */
static void classify(const struct conf *c, struct listener *l)
{
	struct sockaddr_storage ss;
	socklen_t sl = sizeof ss;
	memset(&ss, 0, sizeof ss);
	if (getsockname(l->fd, (struct sockaddr *)&ss, &sl) == 0) {
		l->is_unix = ss.ss_family == AF_UNIX;
		l->loopback = sa_loopback(&ss);
		sa_name(&ss, l->name, sizeof l->name);
	}
	if (l->is_unix)
		l->need_token = c->require_token == CONF_TOKEN_ALL;
	else
		l->need_token = c->require_token != CONF_TOKEN_AUTO || !l->loopback;
	l->compress = c->compress == CONF_COMPRESS_ALWAYS ||
		      (c->compress == CONF_COMPRESS_AUTO && !l->is_unix && !l->loopback);
}

/* Whether a server answers on the Unix socket at path: 0 when none does (the file is stale:
 * the connection is refused), -EADDRINUSE when one accepts or its backlog is full, another
 * -errno when the path cannot be tried (err filled). */
static int probe_unix(const struct sockaddr_un *sa, char err[256])
{
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (fd < 0) {
		int e = -errno;
		err_set(err, "unix socket: %s", strerror(-e));
		return e;
	}
	int rc = connect(fd, (const struct sockaddr *)sa, sizeof *sa) ? -errno : 0;
	close(fd);
	if (rc == -ECONNREFUSED)
		return 0;
	if (rc == 0 || rc == -EAGAIN || rc == -EINPROGRESS) {
		err_set(err, "%s: already in use by a running server (it accepted a connection); "
			"stop it first, or set another [listen] unix path", sa->sun_path);
		return -EADDRINUSE;
	}
	err_set(err, "%s: exists and cannot be tried: %s", sa->sun_path, strerror(-rc));
	return rc;
}

/* Opens l's listening fd on path. Returns 0 or -errno with err filled. */
static int listen_unix(const struct conf *c, const char *path, struct listener *l, char err[256])
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	if (strlen(path) >= sizeof sa.sun_path) {
		err_set(err, "%s: longer than a Unix socket path may be (%zu bytes)", path,
			sizeof sa.sun_path - 1);
		return -ENAMETOOLONG;
	}
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", path);
	struct stat st;
	if (lstat(path, &st) == 0 && S_ISSOCK(st.st_mode)) {
		int rc = probe_unix(&sa, err);
		if (rc)
			return rc;
		unlink(path); /* a stale socket from a previous run */
	}
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (fd < 0) {
		int e = -errno;
		err_set(err, "unix socket: %s", strerror(-e));
		return e;
	}
	if (bind(fd, (struct sockaddr *)&sa, sizeof sa) || lstat(path, &st) ||
	    chmod(path, c->unix_mode) || listen(fd, BACKLOG)) {
		int e = -errno;
		err_set(err, "%s: %s", path, strerror(-e));
		close(fd);
		return e;
	}
	*l = (struct listener){ .fd = fd, .own_path = true, .path_dev = st.st_dev,
				.path_ino = st.st_ino };
	return 0;
}

/* Returns the listening fd or -errno with err filled. */
static int listen_tcp(const char *hostport, char err[256])
{
	char host[256], port[16];
	if (conf_split_hostport(hostport, host, sizeof host, port, sizeof port)) {
		err_set(err, "%s: not host:port", hostport);
		return -EINVAL;
	}
	struct addrinfo hints = { .ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
				  .ai_flags = AI_PASSIVE | AI_NUMERICSERV };
	struct addrinfo *ai = NULL;
	int g = getaddrinfo(host, port, &hints, &ai);
	if (g) {
		err_set(err, "%s: %s", hostport, gai_strerror(g));
		return -EINVAL;
	}
	int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	int one = 1;
	if (fd < 0 || setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) ||
	    bind(fd, ai->ai_addr, ai->ai_addrlen) || listen(fd, BACKLOG)) {
		int e = -errno;
		err_set(err, "%s: %s", hostport, strerror(-e));
		if (fd >= 0)
			close(fd);
		freeaddrinfo(ai);
		return e;
	}
	freeaddrinfo(ai);
	return fd;
}

/* The sockets systemd passed, made non-blocking. Returns 0 or -errno with err filled. */
static int listen_activated(int nfds, struct listener *ls, int *n, char err[256])
{
	for (int i = 0; i < nfds && *n < LISTEN_MAX; i++) {
		int fd = SD_LISTEN_FDS_START + i;
		if (sd_is_socket(fd, AF_UNSPEC, SOCK_STREAM, 1) <= 0) {
			err_set(err, "socket activation: fd %d is not a listening stream socket", fd);
			return -EINVAL;
		}
		int fl = fcntl(fd, F_GETFL);
		if (fl < 0 || fcntl(fd, F_SETFL, fl | O_NONBLOCK) || fcntl(fd, F_SETFD, FD_CLOEXEC)) {
			int e = -errno;
			err_set(err, "socket activation: fd %d: %s", fd, strerror(-e));
			return e;
		}
		ls[(*n)++].fd = fd;
	}
	return 0;
}

int listen_open(const struct conf *c, struct listener *ls, int *n, char err[256])
{
	*n = 0;
	int nfds = sd_listen_fds(1), fd;
	if (nfds > 0) {
		int rc = listen_activated(nfds, ls, n, err);
		if (rc)
			return rc;
	} else {
		if (c->unix_path) {
			int rc = listen_unix(c, c->unix_path, &ls[*n], err);
			if (rc)
				return rc;
			(*n)++;
		}
		for (int i = 0; i < c->ntcp; i++) {
			if ((fd = listen_tcp(c->tcp[i], err)) < 0)
				return fd;
			ls[(*n)++] = (struct listener){ .fd = fd };
		}
	}
	for (int i = 0; i < *n; i++)
		classify(c, &ls[i]);
	return 0;
}

void listen_close(const struct conf *c, struct listener *l)
{
	if (l->fd < 0)
		return;
	if (close(l->fd))
		log_msg(LOG_WARN, "%s: close: %s", l->name, strerror(errno));
	/* Only the file this listener created: a daemon started since on the same path (after
	 * this one's was removed by hand) keeps its socket. */
	struct stat st;
	if (l->own_path && c->unix_path && lstat(c->unix_path, &st) == 0 &&
	    st.st_dev == l->path_dev && st.st_ino == l->path_ino && unlink(c->unix_path))
		log_msg(LOG_WARN, "%s: unlink: %s", c->unix_path, strerror(errno));
	l->fd = -1;
	l->own_path = false;
}

int listen_accept(const struct listener *l, struct sockaddr_storage *peer)
{
	for (;;) {
		socklen_t len = sizeof *peer;
		if (peer)
			memset(peer, 0, sizeof *peer);
		int fd = accept4(l->fd, (struct sockaddr *)peer, peer ? &len : NULL,
				 SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd >= 0)
			return fd;
		if (errno == EINTR || errno == ECONNABORTED)
			continue;
		return errno == EWOULDBLOCK ? -EAGAIN : -errno;
	}
}

void listen_tune(const struct listener *l, int fd)
{
	if (!l->is_unix) {
		int one = 1;
		if (setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one))
			log_msg(LOG_WARN, "%s: TCP_NODELAY: %s", l->name, strerror(errno));
		return;
	}
	/* A Unix stream queues what the sender's buffer holds: the default (~208 KiB) is less
	 * than one 256² RGBA tile, so ask for room for a few (the kernel caps it at
	 * net.core.wmem_max; TCP keeps its autotuning). */
	int sz = UNIX_SNDBUF;
	if (setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &sz, sizeof sz))
		log_msg(LOG_DEBUG, "%s: SO_SNDBUF: %s", l->name, strerror(errno));
}
