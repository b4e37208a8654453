/* view_source_net — see view_source_net.h. The frame loop holds several polled tiles at once
 * (until it uploads them), so each decoded tile has its own buffer: the tile's handle, freed
 * by release (a few spare buffers are kept for reuse). */
#include "view_source_net.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "client/net.h"
#include "common/errbuf.h"
#include "common/proto.h"
#include "common/tilecodec.h"
#include "common/xalloc.h"

struct net_source {
	struct view_source base; /* first: the frame loop holds &base */
	struct net_conn *c;
	uint32_t planet_id, seq;
	struct proto_want_entry *entries;
	size_t cap_entries;
	void *spare[8]; /* released buffers of spare_len bytes, for the next tiles */
	int nspare;
	size_t spare_len;
	char err[256];
};

static struct net_source *ns_of(struct view_source *s)
{
	return (struct net_source *)s;
}

static int ns_want(struct view_source *s, const struct view_want *w, size_t n,
		   const struct view_focus *f)
{
	struct net_source *ns = ns_of(s);
	if (n > PROTO_MAX_WANT)
		n = PROTO_MAX_WANT; /* priority order: the tail is the least wanted */
	if (n > ns->cap_entries) {
		ns->cap_entries = n;
		ns->entries = xrealloc(ns->entries, n * sizeof *ns->entries);
	}
	for (size_t i = 0; i < n; i++)
		ns->entries[i] = (struct proto_want_entry){
			.layer = w[i].layer,
			.cls = w[i].cls == VIEW_CLASS_VISIBLE	 ? PROTO_CLASS_VISIBLE
			       : w[i].cls == VIEW_CLASS_AHEAD ? PROTO_CLASS_BULK
							      : PROTO_CLASS_PREFETCH,
			.lx = w[i].key.lx, .ly = w[i].key.ly, .x = w[i].key.x, .y = w[i].key.y,
		};
	struct proto_msg m = { .type = PROTO_WANT,
			       .want = { .planet_id = ns->planet_id, .seq = ++ns->seq,
					 .lon = f->lon, .lat = f->lat, .alt = f->alt,
					 .vel = { f->vel[0], f->vel[1], f->vel[2] },
					 .count = (uint32_t)n, .entries = ns->entries } };
	return net_send(ns->c, &m, ns->err);
}

static int ns_poll(struct view_source *s, struct view_tile *out)
{
	struct net_source *ns = ns_of(s);
	for (;;) {
		struct proto_msg m;
		int rc = net_recv(ns->c, &m, 0, ns->err);
		if (rc == -EAGAIN)
			return 0;
		if (rc)
			return rc;
		if (m.type == PROTO_TILE && m.tile.planet_id == ns->planet_id) {
			size_t need = m.tile.enc.raw_len;
			void *buf;
			if (need == ns->spare_len && ns->nspare > 0) {
				buf = ns->spare[--ns->nspare];
			} else {
				buf = xaligned_alloc(64, need ? need : 64);
			}
			rc = net_tile_decode(ns->c, &m.tile, buf, need, ns->err);
			if (rc) {
				free(buf);
				buf = NULL;
			}
			*out = (struct view_tile){ .layer = m.tile.layer, .key = m.tile.key,
						   .format = m.tile.enc.format,
						   .size = m.tile.enc.size, .texels = buf, .err = rc,
						   .handle = buf };
			proto_msg_fini(&m);
			return 1;
		}
		if (m.type == PROTO_TILE_FAIL && m.tile_fail.planet_id == ns->planet_id) {
			uint8_t l = m.tile_fail.layer;
			*out = (struct view_tile){ .layer = l, .key = m.tile_fail.key, .err = -EIO,
						   .size = s->planet.tile_size,
						   .format = l < s->planet.nlayers
								     ? s->planet.layer[l].format
								     : PIX_NONE };
			proto_msg_fini(&m);
			return 1;
		}
		if (m.type == PROTO_ERROR || m.type == PROTO_BYE) {
			if (m.type == PROTO_ERROR)
				net_error_text(ns->c, &m.error, ns->err);
			else
				err_set(ns->err, "%s: the daemon closed the session", net_peer(ns->c));
			proto_msg_fini(&m);
			return -ECONNRESET;
		}
		proto_msg_fini(&m); /* anything else (progress, stats) is not the viewer's */
	}
}

static int ns_wait(struct view_source *s, int timeout_ms)
{
	struct net_source *ns = ns_of(s);
	struct pollfd p = { .fd = net_fd(ns->c), .events = POLLIN };
	int rc = poll(&p, 1, timeout_ms);
	if (rc < 0)
		return errno == EINTR ? 0 : -errno;
	return rc > 0;
}

static void ns_release(struct view_source *s, struct view_tile *t)
{
	struct net_source *ns = ns_of(s);
	if (t->handle) {
		size_t len = (size_t)t->size * t->size * pix_bytes(t->format);
		if (len && ns->nspare < (int)(sizeof ns->spare / sizeof ns->spare[0]) &&
		    (ns->nspare == 0 || len == ns->spare_len)) {
			ns->spare_len = len;
			ns->spare[ns->nspare++] = t->handle;
		} else {
			free(t->handle);
		}
	}
	t->handle = NULL;
	t->texels = NULL;
}

static void ns_destroy(struct view_source *s)
{
	struct net_source *ns = ns_of(s);
	net_close(ns->c);
	free(ns->entries);
	for (int i = 0; i < ns->nspare; i++)
		free(ns->spare[i]);
	free(ns);
}

static const struct view_source_ops ops = {
	.want = ns_want, .poll = ns_poll, .wait = ns_wait, .release = ns_release,
	.destroy = ns_destroy,
};

int view_source_net_create(const struct net_opts *o, const char *planet, struct view_source **out,
			   char err[256])
{
	struct net_conn *c;
	int rc = net_connect(o, &c, err);
	if (rc)
		return rc;
	struct proto_msg m;
	rc = net_open_planet(c, planet, &m, o->timeout_ms > 0 ? o->timeout_ms : 10000, err);
	if (rc) {
		net_close(c);
		return rc;
	}
	struct net_source *ns = xcalloc(1, sizeof *ns);
	ns->base.ops = &ops;
	ns->c = c;
	ns->planet_id = m.opened.planet_id;
	struct view_planet *vp = &ns->base.planet;
	const struct proto_planet *pp = &m.opened.planet;
	snprintf(vp->name, sizeof vp->name, "%s", pp->name);
	vp->a = pp->a;
	vp->f = pp->f;
	vp->tile_size = pp->tile_size;
	vp->max_level = pp->max_level;
	vp->look = (struct view_look){ .air_density = pp->air_density, .air_height = pp->air_height,
				       .air_color = { pp->air_color[0], pp->air_color[1],
						      pp->air_color[2] },
				       .sea = pp->sea != 0, .sea_level = pp->sea_level };
	vp->nlayers = pp->nlayers < VIEW_MAX_LAYERS ? pp->nlayers : VIEW_MAX_LAYERS;
	for (int i = 0; i < vp->nlayers; i++) {
		snprintf(vp->layer[i].name, sizeof vp->layer[i].name, "%s", pp->layers[i].name);
		vp->layer[i].format = pp->layers[i].format;
	}
	proto_msg_fini(&m);
	*out = &ns->base;
	return 0;
}
