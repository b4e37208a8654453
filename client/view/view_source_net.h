/* view_source_net — the viewer's tiles from a clipmapd session (docs/PROTOCOL.md): OPEN the
 * planet, send each want-set as a WANT (it replaces the last), and hand the TILEs that arrive
 * to the frame loop. Single-threaded: poll reads whatever whole frames the socket holds and
 * never blocks. Ownership: the source owns its connection; polled texels are borrowed until
 * release.
 */
#ifndef CLIPMAP_VIEW_SOURCE_NET_H
#define CLIPMAP_VIEW_SOURCE_NET_H

#include "client/net.h"
#include "view_source.h"

/* Connects (o: socket or host, token), opens `planet` and fills the source's view_planet.
 * Returns 0 or -errno with err filled ("PEER: not-found: no planet ..."). */
int view_source_net_create(const struct net_opts *o, const char *planet, struct view_source **out,
			   char err[256]);

#endif
