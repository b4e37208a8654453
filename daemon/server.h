/* server — clipmapd's event loop: listeners (Unix socket, TCP), accept, the sessions, the
 * queue through which the scheduler's manager thread hands ready tiles to the loop (a mutex
 * protected array plus an eventfd), a 250 ms housekeeping timer (prefetch progress, close
 * deadlines, the caller's tick for the systemd watchdog) and any extra fds main wants watched
 * (its signalfd). The loop never blocks: sockets are non-blocking, generation happens on the
 * scheduler's threads.
 *
 * Threads: everything runs on the thread that calls server_run, except server_ready_push
 * (any thread: the scheduler's callbacks). rq_mu protects the ready queue only; it is never
 * held while calling out. Ownership: the server borrows the conf, scheduler and cache, and
 * owns one reference to the current planet set, its listeners and its sessions.
 */
#ifndef CLIPMAP_SERVER_H
#define CLIPMAP_SERVER_H
#include <pthread.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "engine/cache.h"
#include "conf.h"
#include "engine/planets.h"
#include "common/proto.h"
#include "engine/sched.h"

struct session;

enum ev_kind { EV_NONE = 0, EV_LISTENER, EV_SESSION, EV_READY, EV_TIMER, EV_WATCH };

/* The first member of everything registered with epoll. */
struct evsrc {
	enum ev_kind kind;
};

struct listener {
	struct evsrc ev;
	int fd;
	bool is_unix, loopback, need_token, compress;
	char name[160]; /* "unix:/path" or "tcp:127.0.0.1:7878" */
};

struct prefetch_job;

struct ready_item {
	struct session *s;	  /* the requester's session */
	struct prefetch_job *job; /* the session's job that wanted it; NULL: the want-set */
	struct tile_key key;
	struct tile *t; /* owned reference, or NULL when err < 0 */
	int err;
};

struct watch {
	struct evsrc ev;
	int fd;
	void (*fn)(void *ud);
	void *ud;
};

#define SERVER_MAX_LISTENERS (CONF_MAX_TCP + 1)
#define SERVER_MAX_WATCH 4

struct server {
	const struct conf *conf;
	struct sched *sched;
	struct cache *cache;
	struct planet_set *planets; /* current snapshot (owned reference) */
	uint8_t token[PROTO_MAX_TOKEN];
	size_t token_len;
	bool have_token;

	int epfd;
	struct evsrc ev_ready, ev_timer;
	int evfd, timerfd;
	struct listener ls[SERVER_MAX_LISTENERS];
	int nls;
	struct watch watches[SERVER_MAX_WATCH];
	int nwatch;
	void (*tick_fn)(void *ud);
	void *tick_ud;
	bool stop, stopping;
	uint64_t stop_deadline_ns;

	struct session *sessions; /* doubly linked */
	size_t nsessions;
	uint64_t next_session_id;
	struct session *pump;	  /* sessions with more output to produce (singly linked) */
	struct session *graveyard; /* closed this iteration, freed at its end */

	pthread_mutex_t rq_mu; /* protects rq, nrq, cap_rq, rq_signalled */
	struct ready_item *rq;
	size_t nrq, cap_rq;
	bool rq_signalled;

	struct tilecodec *codec; /* loop thread's encoder */
	struct proto_limits limits;
	uint64_t start_ns;
	uint64_t tiles_sent, tiles_failed, tiles_dropped, tiles_stale, bytes_sent;
	uint64_t sessions_total, errors_sent;
};

/* Monotonic nanoseconds. */
uint64_t server_now_ns(void);

/* Creates the server and its listeners from the conf (or the fds systemd passed, when any).
 * `planets` is taken (the server owns that reference). Returns 0 or -errno with err filled. */
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
/* Hands a ready tile to the loop (any thread; takes t's reference). */
void server_ready_push(struct server *srv, const struct ready_item *it);
/* The listeners' names, for logs and tests ("tcp:127.0.0.1:41234" after binding port 0). */
size_t server_listeners(const struct server *srv, const struct listener **out);
/* Recomputes the cache's pruning foci from every session's focus and velocity. */
void server_update_foci(struct server *srv);
/* Drops the ready items of session s (after its scheduler requests are destroyed). */
void server_ready_purge(struct server *srv, const struct session *s);

#endif
