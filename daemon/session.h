/* session — one client connection: the protocol state machine (handshake, ready, closing),
 * framing and decoding of what arrives (proto_decode over an accumulating buffer), the
 * want-set (one scheduler request per session; each WANT replaces the planet's previous set),
 * the bounded output queue, control requests (LIST_PLANETS, OPEN, STATS, CACHE_LS) and the
 * session's prefetch jobs.
 *
 * Want-set: entries are kept in a hash table keyed by tile key, each WANTED (asked of the
 * scheduler), READY (generated, waiting for output room; held in a priority heap: class, then
 * level coarse first, then want order) or SENT. Ready tiles go out while the output queue holds
 * less than max_pending bytes; otherwise they wait, and a WANT that drops them frees them
 * (stale fine tiles are skipped on a slow link).
 *
 * Threads: loop thread only; the scheduler callback only pushes onto the server's ready
 * queue. Ownership: the server owns sessions; a session owns its fd, buffers, jobs, tile
 * references and planet-set references (one per opened planet, one per prefetch job, and
 * those retired by reloads, released when the session is freed).
 */
#ifndef CLIPMAP_SESSION_H
#define CLIPMAP_SESSION_H
#include <stdbool.h>
#include <stdint.h>

#include "server.h"

/* Starts a session on an accepted, non-blocking socket fd (taken). Returns NULL only when
 * the fd cannot be registered with epoll (fd closed). */
struct session *session_create(struct server *srv, int fd, const struct listener *l);
/* epoll events on the session's socket. */
void session_on_event(struct session *s, uint32_t events);
/* A ready item for this session or one of its jobs (takes the item's tile reference). */
void session_on_ready(struct session *s, struct ready_item *it);
/* Produces more output if there is room (called from the pump list). Returns true while the
 * session still has ready tiles and output room (stays on the pump list). */
bool session_pump(struct session *s);
/* Takes s off the pump list (the server is walking it) and returns the next one. */
struct session *session_pump_next(struct session *s);
/* Puts s back on the pump list (session_pump said it has more to do). */
void session_pump_readd(struct session *s);
/* Housekeeping every 250 ms: prefetch progress, close deadlines. */
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
/* Closes now: destroys the scheduler request and jobs, unlinks from the server and moves the
 * session to the graveyard (freed by session_free at the end of the loop iteration). */
void session_close(struct session *s, const char *why);
void session_free(struct session *s);
/* Frees a graveyard list (linked through the sessions' graveyard links). */
void session_free_list(struct session *head);
/* Whether a focus is known, and it (for cache pruning). */
bool session_focus(const struct session *s, double *lon, double *lat, double vel[3]);
/* The next session of the server's list (iteration). */
struct session *session_next(const struct session *s);
uint64_t session_pending_bytes(const struct session *s);

#endif
