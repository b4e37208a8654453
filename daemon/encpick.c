/* encpick — see encpick.h. */
#include "encpick.h"

#include <math.h>

static bool lossy_allowed(const struct encpick_policy *p, enum tcodec c)
{
	return p->lossy_below_bps && (p->offered & (1u << c)) && p->lossless != TCODEC_NONE;
}

uint32_t encpick_agreed(const struct encpick_policy *p)
{
	uint32_t bits = p->lossless != TCODEC_NONE ? 1u << p->lossless : 0;
	if (lossy_allowed(p, TCODEC_WEBP))
		bits |= 1u << TCODEC_WEBP;
	if (lossy_allowed(p, TCODEC_Q16))
		bits |= 1u << TCODEC_Q16;
	return bits;
}

void encpick(const struct encpick_policy *p, enum pix_type f, int ly, uint32_t T, double a,
	     uint64_t rate_bps, struct encpick *out)
{
	*out = (struct encpick){ .codec = p->lossless };
	if (p->raw_above_bps && rate_bps > p->raw_above_bps)
		out->codec = TCODEC_NONE; /* the link outruns the encoder (raw is always allowed) */
	else if (rate_bps && rate_bps < p->lossy_below_bps) {
		enum tcodec c = f == PIX_HEIGHT ? TCODEC_Q16 : TCODEC_WEBP;
		if (lossy_allowed(p, c) && tilecodec_codec_fits(c, f)) {
			out->codec = c;
			out->lossy.quality = p->webp_quality;
			/* a 256th of the level's texel, north–south: π·a / (2^ly · T) metres */
			out->lossy.step = M_PI * a / (ldexp(1.0, ly) * (T ? T : 1)) / ENCPICK_STEP_DIV;
			return;
		}
	}
	out->filter = out->codec == TCODEC_NONE ? TFILTER_NONE : tilecodec_default_filter(f);
}
