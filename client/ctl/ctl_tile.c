/* ctl_tile — see ctl_tile.h. Pictures are built like the offline renderer's (normals through
 * pix_normals_rgb), so `tile` and `render` write the same bytes. */
#include "ctl_tile.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "common/errbuf.h"
#include "common/xalloc.h"
#include "ctl_args.h"
#include "ctl_conn.h"

int ctl_tile_image(enum pix_type format, uint32_t T, const void *texels,
		   struct render_image *out)
{
	memset(out, 0, sizeof *out);
	size_t n = (size_t)T * T;
	if (T == 0 || !pix_bytes(format))
		return -EINVAL;
	out->width = out->height = (int)T;
	out->hmin = INFINITY;
	out->hmax = -INFINITY;
	if (format == PIX_HEIGHT) {
		out->channels = 1;
		out->is_float = 1;
		float *px = xmalloc(n * sizeof *px);
		memcpy(px, texels, n * sizeof *px);
		for (size_t i = 0; i < n; i++) {
			if (px[i] < out->hmin)
				out->hmin = px[i];
			if (px[i] > out->hmax)
				out->hmax = px[i];
		}
		out->pixels = px;
	} else if (format == PIX_COLOR) {
		out->channels = 4;
		out->pixels = xmalloc(n * 4);
		memcpy(out->pixels, texels, n * 4);
	} else {
		out->channels = 3;
		unsigned char *d = xmalloc(n * 3);
		pix_normals_rgb(texels, d, n);
		out->pixels = d;
	}
	return 0;
}

static bool same_key(const struct tile_key *a, uint8_t la, const struct ctl_tile_req *r,
		     uint8_t layer)
{
	return la == layer && a->lx == r->lx && a->ly == r->ly && a->x == r->x && a->y == r->y;
}

int ctl_tile_fetch(struct net_conn *c, const struct ctl_tile_req *r, int timeout_ms,
		   struct render_image *out, char err[256])
{
	memset(out, 0, sizeof *out);
	struct proto_msg op = { 0 };
	int rc = net_open_planet(c, r->planet, &op, timeout_ms, err);
	if (rc)
		return rc;
	const struct proto_planet *p = &op.opened.planet;
	uint32_t pid = op.opened.planet_id;
	int layer = ctl_find_layer(p, r->layer, err);
	if (layer < 0) {
		proto_msg_fini(&op);
		return -ENOENT;
	}
	if (!grid_level_valid(r->lx, r->ly) || r->ly > p->max_level ||
	    r->x >= grid_tiles_x(r->lx) || r->y >= grid_tiles_y(r->ly)) {
		err_set(err, "tile (%u, %u, %u, %u) is not in planet %.64s: need "
			"0 <= ly <= %u, 0 <= lx <= ly + 1, x < 2^lx, y < 2^ly", r->lx, r->ly,
			r->x, r->y, p->name, p->max_level);
		proto_msg_fini(&op);
		return -EINVAL;
	}
	proto_msg_fini(&op);

	struct proto_want_entry e = { .layer = (uint8_t)layer, .cls = PROTO_CLASS_VISIBLE,
				      .lx = r->lx, .ly = r->ly, .x = r->x, .y = r->y };
	struct tile_key k = { .lx = r->lx, .ly = r->ly, .x = r->x, .y = r->y };
	struct geo_rect gr;
	grid_tile_rect(&k, &gr);
	struct proto_msg w = { .type = PROTO_WANT,
			       .want = { .planet_id = pid, .seq = 1,
					 .lon = (gr.west + gr.east) / 2,
					 .lat = (gr.south + gr.north) / 2, .count = 1,
					 .entries = &e } };
	rc = net_send(c, &w, err);
	if (rc)
		return rc;
	for (;;) {
		struct proto_msg m = { 0 };
		rc = net_recv(c, &m, timeout_ms, err);
		if (rc)
			return rc;
		if (m.type == PROTO_ERROR) {
			net_error_text(c, &m.error, err);
			rc = -net_code_errno(m.error.code);
			proto_msg_fini(&m);
			return rc;
		}
		if (m.type == PROTO_TILE_FAIL && m.tile_fail.planet_id == pid &&
		    same_key(&m.tile_fail.key, m.tile_fail.layer, r, (uint8_t)layer)) {
			const char *cn = proto_code_name(m.tile_fail.code);
			err_set(err, "%s: cannot make %.32s tile (%u, %u, %u, %u) of %.64s: "
				"%s: %.120s", net_peer(c), r->layer, r->lx, r->ly, r->x, r->y,
				r->planet, cn ? cn : "internal",
				m.tile_fail.message ? m.tile_fail.message : "");
			proto_msg_fini(&m);
			return -EIO;
		}
		if (m.type == PROTO_TILE && m.tile.planet_id == pid &&
		    same_key(&m.tile.key, m.tile.layer, r, (uint8_t)layer)) {
			uint32_t T = m.tile.enc.size;
			void *tex = xmalloc(m.tile.enc.raw_len ? m.tile.enc.raw_len : 1);
			rc = net_tile_decode(c, &m.tile, tex, m.tile.enc.raw_len, err);
			if (rc == 0 && ctl_tile_image(m.tile.enc.format, T, tex, out)) {
				err_set(err, "%s: tile in unknown format %u", net_peer(c),
					m.tile.enc.format);
				rc = -EPROTO;
			} else if (rc == 0) {
				grid_tile_rect(&m.tile.key, &out->bounds);
				out->georef = 1;
			}
			free(tex);
			proto_msg_fini(&m);
			return rc;
		}
		proto_msg_fini(&m);
	}
}
