/* server — clipmapd's event loop: one epoll set over the listeners (listen.h), the sessions'
 * sockets, the ready queue's eventfd (readyq.h), a 250 ms housekeeping timer (prefetch
 * progress, close deadlines, main's watchdog tick) and main's watched fds (its signalfd). It
 * owns the session list, the pump list and the server-wide STATS; sessions reach it only
 * through the struct session_env it lends them. Nothing blocks the loop.
 *
 * Threads: everything on the thread that calls server_run (the ready queue takes pushes from
 * any thread). Ownership: borrows the conf, scheduler and cache; owns one reference to the
 * current planet set, its listeners and its sessions.
 */
#ifndef CLIPMAP_SERVER_H
#define CLIPMAP_SERVER_H
#include <stddef.h>

#include "common/proto.h"
#include "engine/cache.h"
#include "engine/planets.h"
#include "engine/sched.h"
#include "conf.h"
#include "listen.h"

struct server;

/* Creates the server and its listeners from the conf (or the fds systemd passed, when any).
 * `planets` is taken (the server owns that reference) on success. Returns 0 or -errno with
 * err filled. */
int server_create(const struct conf *c, struct sched *s, struct cache *cache,
		  struct planet_set *planets, struct server **out, char err[256]);
/* Closes every session and listener (their scheduler requests first) and frees. */
void server_destroy(struct server *srv);
/* Watches fd for input; fn runs on the loop thread when it is readable. Returns 0 or -errno. */
int server_watch_fd(struct server *srv, int fd, void (*fn)(void *ud), void *ud);
/* Calls fn from the loop about every 250 ms (the systemd watchdog). */
void server_set_tick(struct server *srv, void (*fn)(void *ud), void *ud);
/* Runs the loop until server_stop and the graceful shutdown it starts complete. Returns 0 or
 * -errno (epoll failures). */
int server_run(struct server *srv);
/* Starts a graceful shutdown (loop thread): closes the listeners, cancels every session's
 * queued work, sends each session ERROR shutdown + BYE, and returns from server_run once their
 * output is flushed (or after 2 s). */
void server_stop(struct server *srv);
/* Installs a new planet set (taken). New OPENs use it, and every open session is rebound to
 * it (session_reload): its planets are replaced by the new ones of the same name and its
 * want-set re-submitted, so changed tiles are sent again; a planet that is gone or whose
 * layers changed is dropped from the session with an ERROR. Loop thread only. */
void server_set_planets(struct server *srv, struct planet_set *ps);
/* The conf given to server_create changed in place (a reload): the session limits (max_want,
 * max_rate, max_pending, max_frame, max_jobs), max_sessions, the pre-auth caps and the
 * handshake and frame timeouts follow it from now on. Loop thread. */
void server_conf_changed(struct server *srv);
/* Loads [tls] cert and key again (the same paths or new ones) for the TCP listeners: new
 * connections get the new certificate, open ones keep theirs. On failure nothing changes and
 * err says why (-errno; -EINVAL also when the server was started without TLS). warn as
 * tls_server_create's. Loop thread. */
int server_reload_tls(struct server *srv, const char *cert, const char *key, char err[256],
		      char warn[256]);
/* The current planet set (borrowed: valid until the next server_set_planets). */
const struct planet_set *server_planets(const struct server *srv);
/* The STATS figures (what clipmapctl status shows), keys written into keys[i]. Loop thread. */
size_t server_stats(struct server *srv, struct proto_stat *items, char (*keys)[128], size_t cap);
/* The token read from token_file (NULL, *len 0 without one); borrowed. */
const uint8_t *server_token(const struct server *srv, size_t *len);
/* The listeners (borrowed), for logs and tests ("tcp:127.0.0.1:41234" after binding port 0). */
size_t server_listeners(const struct server *srv, const struct listener **out);

#endif
