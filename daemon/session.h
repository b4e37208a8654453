/* session — one client connection's protocol state machine (handshake, ready, closing) and
 * the messages it answers; CACHE_LS and PREFETCH go to control.h. Its want-set (wantset.h, one
 * scheduler request) streams in priority order while the bounded output (conn.h) has room.
 * It sees the server only through one borrowed struct session_env: shared objects, and the
 * callbacks with which the server keeps its session list, epoll set and pump list.
 *
 * Threads: loop thread only; the scheduler's callbacks only push onto env->ready.
 * Ownership: the server owns sessions (session_free once detached); a session owns its
 * connection, want-set, jobs, tile references and planet-set references.
 */
#ifndef CLIPMAP_SESSION_H
#define CLIPMAP_SESSION_H
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "common/proto.h"
#include "common/tilecodec.h"
#include "engine/cache.h"
#include "engine/planets.h"
#include "engine/sched.h"
#include "listen.h"
#include "readyq.h"

struct session;
struct prefetch_limits;
struct session_link; /* the server's record of a session (opaque here) */

/* Server-wide counters the sessions add to (STATS). */
struct session_counters {
	uint64_t tiles_sent, tiles_failed, tiles_dropped, tiles_stale, bytes_sent, errors_sent;
	/* held-tile allowance: ready tiles released for want of output room, found again in
	 * the cache when room came, wanted again because the cache had let them go */
	uint64_t tiles_parked, tiles_relooked, tiles_rewanted;
	/* encoded tiles taken back out of the output before the kernel had them (a new want-set
	 * no longer wanted them), and their bytes */
	uint64_t tiles_recalled, bytes_recalled;
	uint64_t pauses; /* times a session's wants were withdrawn while its output was full */
	uint64_t ahead_wants; /* look-ahead tiles asked of the scheduler (lookahead.h) */
};

/* What the server lends every session; every pointer is borrowed and outlives the sessions. */
struct session_env {
	const struct proto_limits *limits;
	uint32_t max_jobs; /* prefetch jobs per session */
	uint32_t queue_ms; /* TCP send window: this much of the measured rate (0: max_pending) */
	bool bbr;	   /* TCP sessions ask for BBR (where the kernel allows it) */
	/* compress = auto: a TCP session's tiles go raw while its link is measured faster than
	 * this (bits/s; 0: never) — there the encoder, not the link, would be the bottleneck */
	uint64_t raw_above_bps;
	/* lossy codecs to TCP sessions that offered them, on links measured slower than this
	 * (bits/s; 0: never; encpick.h), at this WebP quality */
	uint64_t lossy_below_bps;
	int webp_quality;
	struct prefetch_limits *prefetch; /* the server's caps on prefetch jobs (prefetch.h) */
	uint64_t handshake_ns; /* accept to HELLO_OK, at most ([listen] handshake_timeout) */
	uint64_t frame_ns;     /* a frame's first byte to its last, at most (frame_timeout) */
	struct sched *sched;
	struct cache *cache;
	struct readyq *ready;	 /* the scheduler's callbacks push here */
	struct encq *encq;	 /* the shared encodings (encq.h) */
	const uint8_t *token;	 /* the token listeners may require */
	size_t token_len;
	bool have_token;
	struct planet_set *const *planets; /* the current set (replaced by reloads) */
	struct session_counters *counters;
	/* Bytes the sessions may still write in this loop iteration (the server resets it each
	 * turn; NULL: no cap). A session that meets 0 keeps its output, and EPOLLOUT (level-
	 * triggered) brings it back next turn: the kernel's copy into socket buffers is the
	 * loop's one cost per byte, and this bounds an iteration's share of it. */
	size_t *write_budget;

	void *ud; /* the server: the first argument of every callback */
	/* A new session on fd: the server registers fd for input, lists s and gives it an id.
	 * Returns the server's record of s, or NULL (logged) when fd cannot be watched. */
	struct session_link *(*attach)(void *ud, struct session *s, int fd, uint64_t *id);
	/* The session's HELLO passed (version, token): it leaves the not-yet-authenticated pool
	 * and counts against max_sessions. Returns 0, or -EBUSY when there is no room (the
	 * session answers ERROR busy and closes). */
	int (*authenticated)(void *ud, struct session_link *l);
	/* The epoll events (EPOLLIN, EPOLLRDHUP, EPOLLOUT) the session wants now. */
	void (*interest)(void *ud, struct session_link *l, uint32_t events);
	/* The session has ready tiles and output room: call session_pump before the next wait. */
	void (*pump)(void *ud, struct session_link *l);
	/* The session closed: the server forgets its fd, unlists it and frees it (session_free)
	 * at the end of the loop iteration. */
	void (*detach)(void *ud, struct session_link *l);
	/* A session's focus changed or went away (cache pruning). */
	void (*focus_changed)(void *ud);
	/* Server-wide STATS items, at most cap, into items (keys in keys). Returns how many. */
	size_t (*stats)(void *ud, struct proto_stat *items, char (*keys)[128], size_t cap);
};

/* One session's share of the server-wide figures. */
struct session_load {
	uint64_t pending_bytes, ready_tiles, jobs;
	uint64_t held_bytes; /* ready tiles' bytes held for output room */
	uint64_t out_bytes;  /* the output's own buffers (headers, messages; not shared payloads) */
	bool paused;	     /* wants withdrawn while the output is full */
	/* the link (linkest.h): TCP only; 0 when not measured (Unix sockets, no sample yet) */
	bool tcp;
	uint64_t rate;	      /* bytes/s */
	double rtt_ms, min_rtt_ms;
	uint64_t window;      /* the send window: output bytes allowed before the kernel's */
	uint64_t queue_bytes; /* committed, not yet on the wire: output + the kernel's unsent */
	double queue_ms;      /* queue_bytes at the rate */
	uint64_t inflight;    /* sent, not yet acknowledged */
	uint64_t id;
	const char *peer;
};

/* Starts a session on an accepted, non-blocking socket fd (taken) of listener l (borrowed:
 * it outlives the session).
 * Returns NULL only when the server cannot watch fd (fd closed). */
struct session *session_create(const struct session_env *env, int fd, const struct listener *l);
/* epoll events on the session's socket. */
void session_on_event(struct session *s, uint32_t events);
/* A ready item for this session or one of its jobs (takes the item's tile reference). */
void session_on_ready(struct session *s, struct ready_item *it);
/* An encoding this session's output waits for is ready: writes what can go and pumps more. */
void session_on_encoded(struct session *s);
/* Produces more output if there is room, at most *budget bytes (taken off it; the last tile
 * may overshoot). Returns true while the session still has ready tiles and output room (the
 * server calls it again). */
bool session_pump(struct session *s, size_t *budget);
/* Housekeeping every 250 ms: prefetch progress, close deadlines, the handshake deadline and
 * the partial-frame timeout (ERROR limit, then close). */
void session_tick(struct session *s, uint64_t now_ns);
/* A reload installed ps (borrowed; the session takes references of its own): every planet the
 * session opened is replaced by the planet of the same name in ps when its layers are
 * compatible (same count, formats and tile size: the planet id and layer indices stay
 * valid), and the want-set is re-resolved against the new layers' nodes and re-submitted, so
 * tiles whose node hash changed are generated and sent again while unchanged ones are not.
 * A planet that is gone or incompatible is dropped with an ERROR not-found naming it. The old
 * sets are kept until the session is freed (the scheduler may still be using their nodes). */
void session_reload(struct session *s, struct planet_set *ps);
/* Server shutdown: cancels its work and says ERROR shutdown + BYE, then closes after flush. */
void session_shutdown(struct session *s);
/* Closes now: destroys the scheduler request and jobs, drops its ready items, detaches from
 * the server and closes the socket. The session stays allocated until session_free. */
void session_close(struct session *s, const char *why);
/* Frees a closed session. NULL is a no-op. */
void session_free(struct session *s);
/* Whether a focus is known, and it (for cache pruning), with the equatorial radius (m) of the
 * planet it is on. */
bool session_focus(const struct session *s, double *lon, double *lat, double vel[3],
		   double *radius);
void session_get_load(const struct session *s, struct session_load *out);

#endif
