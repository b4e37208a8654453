/* view_source_net — the viewer's tiles from a clipmapd session (docs/PROTOCOL.md): OPEN the
 * planet, send each want-set as a WANT (it replaces the last), and hand the TILEs that arrive
 * to the frame loop. Single-threaded: poll reads whatever whole frames the socket holds and
 * never blocks.
 *
 * A lost connection (the daemon died or closed the session, or a load balancer in front of a
 * fleet dropped it) is not an error: the source reconnects with backoff (0.1 s doubling to
 * 5 s, equal jitter), repeats the handshake and OPEN, and sends the want-set again (the last
 * one less the tiles delivered since), all without blocking: poll and wait advance it one
 * step at a time while the frame loop keeps drawing what it holds. A daemon that serves the
 * planet with another shape (tile size, layers, formats) is a failed attempt, retried.
 *
 * Ownership: the source owns its connection and copies of the options' strings; polled
 * texels are borrowed until release.
 */
#ifndef CLIPMAP_VIEW_SOURCE_NET_H
#define CLIPMAP_VIEW_SOURCE_NET_H
#include <stdbool.h>

#include "client/net.h"
#include "view_source.h"

/* Connects (o: socket or host, token), opens `planet` and fills the source's view_planet.
 * Returns 0 or -errno with err filled ("PEER: not-found: no planet ..."). */
int view_source_net_create(const struct net_opts *o, const char *planet, struct view_source **out,
			   char err[256]);
/* view_source_net_create, retrying with the reconnect backoff for up to wait_s seconds while
 * the daemon cannot be reached (not after it refused: a wrong token or an unknown planet is
 * final). *attempts (may be NULL) receives how many connections were tried. Blocks: for the
 * start, before any frame. */
int view_source_net_create_wait(const struct net_opts *o, const char *planet, double wait_s,
				unsigned *attempts, struct view_source **out, char err[256]);

/* The state of the source's link to the daemon. */
struct view_net_link {
	bool up;	     /* a session is open and the want-set sent */
	unsigned attempt;    /* while down: attempts made since it was lost (the last one may
			      * still be going on) */
	unsigned failed;     /* while down: of those, the ones that failed (why: the last) */
	unsigned reconnects; /* links restored since the start */
	unsigned lost;	     /* links lost since the start */
	double down_s;	     /* while down: seconds since it was lost */
	const char *why;     /* while down: why (the loss, then the last attempt's failure);
			      * borrowed until the next call on the source */
	const char *lost_why; /* why the link was lost the last time ("" never); borrowed */
	const char *peer;    /* the target (socket or HOST:PORT), borrowed */
	unsigned last_attempts; /* the last reconnect: attempts it took */
	double last_down_s;	/* and how long the link was down */
	/* What the viewer measures of the link while it is up (0: not yet, or down): */
	double rate_bps; /* tile bytes received over the last second, in bits per second */
	uint64_t rx_bytes; /* tile bytes received since the start (each TILE frame's encoded
			    * texels and 12-byte frame header) */
	double rtt_ms;	 /* the least round trip of a STATS request (one a second) */
	double queue_ms; /* the last such round trip less the least: what waits ahead of an
			  * answer in the daemon's and the link's queues */
};
/* s must come from view_source_net_create*. (Not const in effect: the rate's window moves
 * on to now.) */
void view_source_net_link(const struct view_source *s, struct view_net_link *out);

#endif
