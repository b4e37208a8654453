/* bench_planet — the planet the server benchmarks serve (bench_server, bench_tls): one RGBA8
 * layer of 2-octave noise through a ramp, 256² tiles, cheap to generate, so what they measure
 * after the first round is the daemon serving cached tiles; and the want entries of a block of
 * its tiles. Test-only. */
#ifndef CLIPMAP_TEST_BENCH_PLANET_H
#define CLIPMAP_TEST_BENCH_PLANET_H

#include <stdint.h>

#include "common/proto.h"

#define BENCH_PLANET_NAME "b"
#define BENCH_PLANET_INI                                                                        \
	"[planet]\nname = b\nbody = sphere\nradius = 1000000\ntile_size = 256\nmax_level = 12\n" \
	"[node base]\ntype = noise\nseed = 3\noctaves = 2\nwavelength = 300000\namplitude = 500\n" \
	"[node tint]\ntype = ramp\ninput = base\nstops = -500 0 0 255, 500 255 255 255\n"          \
	"[layer color]\nnode = tint\nformat = rgba8\n"

/* Want entries for the w × h tiles from (x0, y0) of level (ly + 1, ly) of its layer, into e.
 * Returns how many (w × h). */
static inline uint32_t bench_planet_block(struct proto_want_entry *e, int ly, uint32_t x0,
					  uint32_t y0, uint32_t w, uint32_t h)
{
	uint32_t n = 0;
	for (uint32_t y = y0; y < y0 + h; y++)
		for (uint32_t x = x0; x < x0 + w; x++)
			e[n++] = (struct proto_want_entry){ .layer = 0, .cls = 1, .lx = (uint8_t)(ly + 1),
							    .ly = (uint8_t)ly, .x = x, .y = y };
	return n;
}

#endif
