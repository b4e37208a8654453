/* server — see server.h. One epoll set holds the listeners, the sessions, the ready eventfd,
 * the 250 ms timerfd and main's watched fds (its signalfd). An iteration: wait (timeout 0 while
 * some session has more output to produce), dispatch, let the pump list produce output, free
 * the sessions closed during the iteration. The ready queue is swapped out under rq_mu and
 * processed without it; the eventfd is written only on the empty → non-empty transition.
 */
#include "server.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/timerfd.h>
#include <sys/un.h>
#include <systemd/sd-daemon.h>
#include <time.h>
#include <unistd.h>

#include "common/log.h"
#include "session.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"

#define UNIX_SNDBUF (4 << 20) /* bytes asked for per Unix session */

#define TICK_NS 250000000ull
#define STOP_GRACE_NS 2000000000ull

uint64_t server_now_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

static int ep_add(struct server *srv, int fd, struct evsrc *ev)
{
	struct epoll_event e = { .events = EPOLLIN, .data.ptr = ev };
	return epoll_ctl(srv->epfd, EPOLL_CTL_ADD, fd, &e) ? -errno : 0;
}

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
static void classify(struct server *srv, struct listener *l)
{
	struct sockaddr_storage ss;
	socklen_t sl = sizeof ss;
	memset(&ss, 0, sizeof ss);
	if (getsockname(l->fd, (struct sockaddr *)&ss, &sl) == 0) {
		l->is_unix = ss.ss_family == AF_UNIX;
		l->loopback = sa_loopback(&ss);
		sa_name(&ss, l->name, sizeof l->name);
	}
	const struct conf *c = srv->conf;
	if (l->is_unix)
		l->need_token = c->require_token == CONF_TOKEN_ALL;
	else
		l->need_token = c->require_token != CONF_TOKEN_AUTO || !l->loopback;
	l->compress = c->compress == CONF_COMPRESS_ALWAYS ||
		      (c->compress == CONF_COMPRESS_AUTO && !l->is_unix && !l->loopback);
}

static int listen_unix(struct server *srv, const char *path, char err[256])
{
	struct sockaddr_un sa = { .sun_family = AF_UNIX };
	snprintf(sa.sun_path, sizeof sa.sun_path, "%s", path);
	int fd = socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	if (fd < 0) {
		int e = -errno;
		snprintf(err, 256, "unix socket: %s", strerror(-e));
		return e;
	}
	struct stat st;
	if (lstat(path, &st) == 0 && S_ISSOCK(st.st_mode))
		unlink(path); /* a stale socket from a previous run */
	if (bind(fd, (struct sockaddr *)&sa, sizeof sa) || chmod(path, srv->conf->unix_mode) ||
	    listen(fd, 128)) {
		int e = -errno;
		snprintf(err, 256, "%s: %s", path, strerror(-e));
		close(fd);
		return e;
	}
	struct listener *l = &srv->ls[srv->nls++];
	l->fd = fd;
	return 0;
}

static int listen_tcp(struct server *srv, const char *hostport, char err[256])
{
	char host[256], port[16];
	if (conf_split_hostport(hostport, host, sizeof host, port, sizeof port)) {
		snprintf(err, 256, "%s: not host:port", hostport);
		return -EINVAL;
	}
	struct addrinfo hints = { .ai_family = AF_UNSPEC, .ai_socktype = SOCK_STREAM,
				  .ai_flags = AI_PASSIVE | AI_NUMERICSERV };
	struct addrinfo *ai = NULL;
	int g = getaddrinfo(host, port, &hints, &ai);
	if (g) {
		snprintf(err, 256, "%s: %s", hostport, gai_strerror(g));
		return -EINVAL;
	}
	int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
	int one = 1;
	if (fd < 0 || setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one) ||
	    bind(fd, ai->ai_addr, ai->ai_addrlen) || listen(fd, 128)) {
		int e = -errno;
		snprintf(err, 256, "%s: %s", hostport, strerror(-e));
		if (fd >= 0)
			close(fd);
		freeaddrinfo(ai);
		return e;
	}
	freeaddrinfo(ai);
	srv->ls[srv->nls++].fd = fd;
	return 0;
}

static int load_token(struct server *srv, char err[256])
{
	const char *path = srv->conf->token_file;
	if (!path)
		return 0;
	int fd = open(path, O_RDONLY | O_CLOEXEC);
	if (fd < 0) {
		int e = -errno;
		snprintf(err, 256, "%s: %s", path, strerror(-e));
		return e;
	}
	ssize_t n = read(fd, srv->token, sizeof srv->token);
	int e = n < 0 ? -errno : 0;
	close(fd);
	if (e) {
		snprintf(err, 256, "%s: %s", path, strerror(-e));
		return e;
	}
	while (n > 0 && (srv->token[n - 1] == '\n' || srv->token[n - 1] == '\r'))
		n--;
	if (n == 0) {
		snprintf(err, 256, "%s: the token file is empty", path);
		return -EINVAL;
	}
	srv->token_len = (size_t)n;
	srv->have_token = true;
	return 0;
}

int server_create(const struct conf *c, struct sched *s, struct cache *cache,
		  struct planet_set *planets, struct server **out, char err[256])
{
	*out = NULL;
	struct server *srv = xcalloc(1, sizeof *srv);
	srv->conf = c;
	srv->sched = s;
	srv->cache = cache;
	srv->planets = planets;
	srv->epfd = srv->evfd = srv->timerfd = -1;
	srv->start_ns = server_now_ns();
	srv->codec = tilecodec_create();
	srv->limits = (struct proto_limits){ .max_want = c->max_want, .max_rate = c->max_rate,
					     .max_pending = c->max_pending,
					     .max_frame = c->max_frame };
	int rc = pthread_mutex_init(&srv->rq_mu, NULL);
	if (rc) {
		snprintf(err, 256, "pthread_mutex_init: %s", strerror(rc));
		free(srv);
		return -rc;
	}
	if ((rc = load_token(srv, err)))
		goto fail;
	srv->epfd = epoll_create1(EPOLL_CLOEXEC);
	srv->evfd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
	srv->timerfd = timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
	if (srv->epfd < 0 || srv->evfd < 0 || srv->timerfd < 0) {
		rc = -errno;
		snprintf(err, 256, "epoll/eventfd/timerfd: %s", strerror(-rc));
		goto fail;
	}
	struct itimerspec its = { .it_interval = { 0, (long)TICK_NS }, .it_value = { 0, (long)TICK_NS } };
	srv->ev_ready.kind = EV_READY;
	srv->ev_timer.kind = EV_TIMER;
	if (timerfd_settime(srv->timerfd, 0, &its, NULL) ||
	    (rc = ep_add(srv, srv->evfd, &srv->ev_ready)) ||
	    (rc = ep_add(srv, srv->timerfd, &srv->ev_timer))) {
		rc = rc ? rc : -errno;
		snprintf(err, 256, "timer: %s", strerror(-rc));
		goto fail;
	}

	int nfds = sd_listen_fds(1);
	if (nfds > 0) {
		for (int i = 0; i < nfds && srv->nls < SERVER_MAX_LISTENERS; i++) {
			int fd = SD_LISTEN_FDS_START + i;
			if (sd_is_socket(fd, AF_UNSPEC, SOCK_STREAM, 1) <= 0) {
				snprintf(err, 256, "socket activation: fd %d is not a listening stream socket",
					 fd);
				rc = -EINVAL;
				goto fail;
			}
			int fl = fcntl(fd, F_GETFL);
			if (fl < 0 || fcntl(fd, F_SETFL, fl | O_NONBLOCK) ||
			    fcntl(fd, F_SETFD, FD_CLOEXEC)) {
				rc = -errno;
				snprintf(err, 256, "socket activation: fd %d: %s", fd, strerror(-rc));
				goto fail;
			}
			srv->ls[srv->nls++].fd = fd;
		}
	} else {
		if (c->unix_path && (rc = listen_unix(srv, c->unix_path, err)))
			goto fail;
		for (int i = 0; i < c->ntcp; i++)
			if ((rc = listen_tcp(srv, c->tcp[i], err)))
				goto fail;
	}
	for (int i = 0; i < srv->nls; i++) {
		struct listener *l = &srv->ls[i];
		l->ev.kind = EV_LISTENER;
		classify(srv, l);
		if (l->need_token && !srv->have_token) {
			snprintf(err, 256, "listener %s requires a token: set token_file", l->name);
			rc = -EINVAL;
			goto fail;
		}
		if ((rc = ep_add(srv, l->fd, &l->ev))) {
			snprintf(err, 256, "%s: epoll: %s", l->name, strerror(-rc));
			goto fail;
		}
	}
	*out = srv;
	return 0;
fail:
	srv->planets = NULL; /* not taken on failure */
	server_destroy(srv);
	return rc;
}

static void close_listeners(struct server *srv)
{
	for (int i = 0; i < srv->nls; i++) {
		struct listener *l = &srv->ls[i];
		if (l->fd < 0)
			continue;
		epoll_ctl(srv->epfd, EPOLL_CTL_DEL, l->fd, NULL);
		if (close(l->fd))
			log_msg(LOG_WARN, "%s: close: %s", l->name, strerror(errno));
		/* A socket we bound ourselves is removed; an activated one belongs to systemd. */
		if (l->is_unix && srv->conf->unix_path && sd_listen_fds(0) <= 0 &&
		    strcmp(l->name + 5, srv->conf->unix_path) == 0)
			unlink(srv->conf->unix_path);
		l->fd = -1;
	}
}

static void free_graveyard(struct server *srv)
{
	struct session *g = srv->graveyard;
	srv->graveyard = NULL;
	session_free_list(g);
}

void server_destroy(struct server *srv)
{
	if (!srv)
		return;
	while (srv->sessions)
		session_close(srv->sessions, "server exiting");
	free_graveyard(srv);
	close_listeners(srv);
	for (size_t i = 0; i < srv->nrq; i++)
		tile_unref(srv->rq[i].t);
	free(srv->rq);
	if (srv->epfd >= 0)
		close(srv->epfd);
	if (srv->evfd >= 0)
		close(srv->evfd);
	if (srv->timerfd >= 0)
		close(srv->timerfd);
	tilecodec_destroy(srv->codec);
	pthread_mutex_destroy(&srv->rq_mu);
	planet_set_unref(srv->planets);
	free(srv);
}

int server_watch_fd(struct server *srv, int fd, void (*fn)(void *ud), void *ud)
{
	if (srv->nwatch == SERVER_MAX_WATCH)
		return -ENOSPC;
	struct watch *w = &srv->watches[srv->nwatch];
	*w = (struct watch){ .ev = { EV_WATCH }, .fd = fd, .fn = fn, .ud = ud };
	int rc = ep_add(srv, fd, &w->ev);
	if (!rc)
		srv->nwatch++;
	return rc;
}

void server_set_tick(struct server *srv, void (*fn)(void *ud), void *ud)
{
	srv->tick_fn = fn;
	srv->tick_ud = ud;
}

size_t server_listeners(const struct server *srv, const struct listener **out)
{
	*out = srv->ls;
	return (size_t)srv->nls;
}

void server_ready_push(struct server *srv, const struct ready_item *it)
{
	bool wake = false;
	pthread_mutex_lock(&srv->rq_mu);
	if (srv->nrq == srv->cap_rq) {
		srv->cap_rq = srv->cap_rq ? srv->cap_rq * 2 : 256;
		srv->rq = xrealloc(srv->rq, srv->cap_rq * sizeof *srv->rq);
	}
	srv->rq[srv->nrq++] = *it;
	if (!srv->rq_signalled)
		wake = srv->rq_signalled = true;
	pthread_mutex_unlock(&srv->rq_mu);
	if (wake) {
		uint64_t one = 1;
		ssize_t n = write(srv->evfd, &one, sizeof one);
		(void)n; /* EAGAIN means the counter is already non-zero: the loop wakes anyway */
	}
}

void server_ready_purge(struct server *srv, const struct session *s)
{
	pthread_mutex_lock(&srv->rq_mu);
	size_t k = 0;
	for (size_t i = 0; i < srv->nrq; i++) {
		if (srv->rq[i].s == s)
			tile_unref(srv->rq[i].t);
		else
			srv->rq[k++] = srv->rq[i];
	}
	srv->nrq = k;
	pthread_mutex_unlock(&srv->rq_mu);
}

static void on_ready(struct server *srv)
{
	uint64_t v;
	ssize_t n = read(srv->evfd, &v, sizeof v);
	(void)n;
	pthread_mutex_lock(&srv->rq_mu);
	struct ready_item *batch = srv->rq;
	size_t nb = srv->nrq;
	srv->rq = NULL;
	srv->nrq = srv->cap_rq = 0;
	srv->rq_signalled = false;
	pthread_mutex_unlock(&srv->rq_mu);
	/* Sessions closed while this batch runs stay allocated (graveyard) until the iteration
	 * ends; session_on_ready ignores them. */
	for (size_t i = 0; i < nb; i++)
		session_on_ready(batch[i].s, &batch[i]);
	free(batch);
}

static void on_accept(struct server *srv, struct listener *l)
{
	for (;;) {
		int fd = accept4(l->fd, NULL, NULL, SOCK_NONBLOCK | SOCK_CLOEXEC);
		if (fd < 0) {
			if (errno == EINTR || errno == ECONNABORTED)
				continue;
			if (errno != EAGAIN && errno != EWOULDBLOCK)
				log_msg(LOG_WARN, "%s: accept: %s", l->name, strerror(errno));
			return;
		}
		if (srv->nsessions >= (size_t)srv->conf->max_sessions) {
			log_msg(LOG_WARN, "%s: refusing a connection: %zu sessions (max_sessions)",
				l->name, srv->nsessions);
			close(fd);
			continue;
		}
		if (!l->is_unix) {
			int one = 1;
			if (setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one))
				log_msg(LOG_WARN, "%s: TCP_NODELAY: %s", l->name, strerror(errno));
		} else {
			/* A Unix stream queues what the sender's buffer holds: the default (~208 KiB)
			 * is less than one 256² RGBA tile, so ask for room for a few (the kernel caps
			 * it at net.core.wmem_max; TCP keeps its autotuning). */
			int sz = UNIX_SNDBUF;
			if (setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &sz, sizeof sz))
				log_msg(LOG_DEBUG, "%s: SO_SNDBUF: %s", l->name, strerror(errno));
		}
		session_create(srv, fd, l);
	}
}

static void on_timer(struct server *srv)
{
	uint64_t v;
	ssize_t n = read(srv->timerfd, &v, sizeof v);
	(void)n;
	uint64_t now = server_now_ns();
	if (srv->tick_fn)
		srv->tick_fn(srv->tick_ud);
	for (struct session *s = srv->sessions, *next; s; s = next) {
		next = session_next(s);
		session_tick(s, now);
	}
	if (srv->stopping && now > srv->stop_deadline_ns)
		while (srv->sessions)
			session_close(srv->sessions, "shutdown: flush timed out");
}

void server_update_foci(struct server *srv)
{
	struct cache_focus f[512];
	size_t n = 0;
	for (struct session *s = srv->sessions; s && n + 2 <= 512; s = session_next(s)) {
		double lon, lat, v[3];
		if (!session_focus(s, &lon, &lat, v))
			continue;
		f[n++] = (struct cache_focus){ lon, lat };
		/* Where the focus will be in 10 s: keep that ring too (velocity east, north). */
		double r = 6371008.8, t = 10.0;
		double c = fmax(cos(lat * M_PI / 180.0), 0.01);
		double dlat = v[1] * t / r * 180.0 / M_PI, dlon = v[0] * t / (r * c) * 180.0 / M_PI;
		if (fabs(dlat) + fabs(dlon) > 1e-9 && isfinite(dlat) && isfinite(dlon))
			f[n++] = (struct cache_focus){ fmod(lon + dlon + 540.0, 360.0) - 180.0,
						       fmin(90.0, fmax(-90.0, lat + dlat)) };
	}
	uint32_t T = srv->planets && srv->planets->n ? srv->planets->planets[0]->tile_size : 256;
	cache_set_foci(srv->cache, f, n, T);
}

void server_set_planets(struct server *srv, struct planet_set *ps)
{
	planet_set_unref(srv->planets);
	srv->planets = ps;
	struct session *next;
	for (struct session *s = srv->sessions; s; s = next) {
		next = session_next(s); /* s may close (a failed send): it stays readable */
		session_reload(s, ps);
	}
}

void server_stop(struct server *srv)
{
	if (srv->stopping)
		return;
	srv->stopping = true;
	srv->stop_deadline_ns = server_now_ns() + STOP_GRACE_NS;
	close_listeners(srv);
	for (struct session *s = srv->sessions, *next; s; s = next) {
		next = session_next(s);
		session_shutdown(s);
	}
}

int server_run(struct server *srv)
{
	struct epoll_event evs[64];
	while (!(srv->stopping && srv->nsessions == 0)) {
		int n = epoll_wait(srv->epfd, evs, 64, srv->pump ? 0 : -1);
		if (n < 0) {
			if (errno == EINTR)
				continue;
			int e = -errno;
			log_msg(LOG_ERROR, "epoll_wait: %s", strerror(-e));
			return e;
		}
		for (int i = 0; i < n; i++) {
			struct evsrc *ev = evs[i].data.ptr;
			switch (ev->kind) {
			case EV_LISTENER:
				if (!srv->stopping)
					on_accept(srv, (struct listener *)ev);
				break;
			case EV_SESSION:
				session_on_event((struct session *)ev, evs[i].events);
				break;
			case EV_READY:
				on_ready(srv);
				break;
			case EV_TIMER:
				on_timer(srv);
				break;
			case EV_WATCH: {
				struct watch *w = (struct watch *)ev;
				w->fn(w->ud);
				break;
			}
			default:
				break;
			}
		}
		struct session *p = srv->pump;
		srv->pump = NULL;
		while (p) {
			struct session *next = session_pump_next(p);
			if (session_pump(p))
				session_pump_readd(p);
			p = next;
		}
		free_graveyard(srv);
	}
	free_graveyard(srv);
	return 0;
}
