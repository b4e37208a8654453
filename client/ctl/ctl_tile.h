/* ctl_tile — `clipmapctl tile`: fetch one tile through the daemon (OPEN the planet, WANT the
 * key at visible class, wait for TILE / TILE_FAIL / ERROR) and turn it into the same picture
 * `clipmapctl render` makes, so render_write produces the same bytes.
 * No state; the connection has one owner thread. The image is returned owned.
 */
#ifndef CLIPMAP_CTL_TILE_H
#define CLIPMAP_CTL_TILE_H
#include <stdint.h>

#include "client/net.h"
#include "render.h"

struct ctl_tile_req {
	const char *planet, *layer;
	uint8_t lx, ly;
	uint32_t x, y;
};

/* Converts T×T texels of a wire format into a render_image as render_layer would make for
 * one tile: f32 heights (hmin/hmax over the non-NaN texels), RGBA8 colour, RG8 normals
 * expanded to RGB with up = sqrt(1 − e² − n²). *out is owned (render_image_free). Returns 0
 * or -EINVAL (bad format). */
int ctl_tile_image(enum pix_type format, uint32_t T, const void *texels,
		   struct render_image *out);
/* Fetches the tile and fills *out (owned). Returns 0, or -errno with err filled:
 * -ENOENT (no such planet or layer), -EINVAL (key outside the level), -EIO (the daemon
 * could not produce it: TILE_FAIL), or a connection error. */
int ctl_tile_fetch(struct net_conn *c, const struct ctl_tile_req *r, int timeout_ms,
		   struct render_image *out, char err[256]);

#endif
