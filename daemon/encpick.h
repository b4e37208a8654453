/* encpick — how a session's tile travels: the codec, filter and lossy knobs for one tile,
 * from what the client offered, what the daemon allows and the session's measured link.
 *   - raw (`none`) on a link measured faster than raw_above (the encoder would be slower);
 *   - a lossy codec (webp for colour and normals, q16 for heights) on a TCP link measured
 *     slower than lossy_below, when the client offered it: a 256² tile then costs 3–30 KiB
 *     instead of 90–180 KiB, and on a 4 Mbit/s link that is what makes a jump arrive in
 *     seconds rather than tens of seconds;
 *   - otherwise the session's lossless codec (zstd, lz4 or none) with the format's filter.
 * Until the link is measured (its first round trips) tiles go lossless.
 * q16's step follows the level: a 64th of the level's texel (north–south, on the planet's
 * radius), and never finer than the tile's range allows (tilecodec.h): the 306 m texels of
 * Earth level 8 get 4.8 m steps, the 1.2 m texels of level 16 1.9 cm. A height is then within
 * 1/128 of a texel, a 64th of a pixel where the texel covers two: nothing the mesh built from
 * it can show. Against a 256th, Earth's heights cost 4.3× fewer bytes than zstd instead of 3×
 * (bench_codec).
 *
 * Pure functions, any thread.
 */
#ifndef CLIPMAP_ENCPICK_H
#define CLIPMAP_ENCPICK_H
#include <stdbool.h>
#include <stdint.h>

#include "common/pixfmt.h"
#include "common/tilecodec.h"

#define ENCPICK_STEP_DIV 64.0 /* q16: steps per texel */

struct encpick_policy {
	enum tcodec lossless;	/* the session's lossless codec (TCODEC_NONE: compress off) */
	uint32_t offered;	/* the client's HELLO codec bits */
	uint64_t raw_above_bps; /* bits/s; 0: never raw for speed */
	uint64_t lossy_below_bps; /* bits/s; 0: never lossy */
	int webp_quality;	/* 1–100; 0: the codec's default */
};

struct encpick {
	enum tcodec codec;
	enum tfilter filter; /* lossless codecs only */
	struct tilecodec_lossy_opts lossy; /* lossy codecs only */
};

/* The choice for a tile of format f at level ly (its texels T², on a planet of equatorial
 * radius a metres), on a link measured at rate_bps bits/s (0: not measured, or a Unix
 * socket). */
void encpick(const struct encpick_policy *p, enum pix_type f, int ly, uint32_t T, double a,
	     uint64_t rate_bps, struct encpick *out);
/* The HELLO_OK codec bits for the policy: the lossless codec and the lossy ones the client
 * offered and the daemon may use. */
uint32_t encpick_agreed(const struct encpick_policy *p);

#endif
