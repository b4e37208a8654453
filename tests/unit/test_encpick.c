/* encpick: which codec a session's tile gets — raw on fast links, lossless until the link is
 * measured and on links above lossy_below, the lossy codecs below it only when the client
 * offered them, and q16's step a 64th of the level's texel. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <cmocka.h>

#include "daemon/encpick.h"

#define EARTH_A 6378137.0
#define MBIT 1000000ull

static const struct encpick_policy viewer = {
	.lossless = TCODEC_ZSTD,
	.offered = TCODEC_ALL_MASK,
	.raw_above_bps = 800 * MBIT,
	.lossy_below_bps = 50 * MBIT,
};

static void by_link_rate(void **state)
{
	(void)state;
	struct encpick e;
	encpick(&viewer, PIX_COLOR, 8, 256, EARTH_A, 0, &e); /* not measured yet */
	assert_int_equal(e.codec, TCODEC_ZSTD);
	assert_int_equal(e.filter, tilecodec_default_filter(PIX_COLOR));
	encpick(&viewer, PIX_COLOR, 8, 256, EARTH_A, 4 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_WEBP);
	assert_int_equal(e.filter, TFILTER_NONE);
	encpick(&viewer, PIX_NORMAL, 8, 256, EARTH_A, 4 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_WEBP);
	encpick(&viewer, PIX_HEIGHT, 8, 256, EARTH_A, 4 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_Q16);
	encpick(&viewer, PIX_HEIGHT, 8, 256, EARTH_A, 100 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_ZSTD);
	encpick(&viewer, PIX_HEIGHT, 8, 256, EARTH_A, 1000 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_NONE);
	assert_int_equal(e.filter, TFILTER_NONE);
}

static void only_what_was_offered(void **state)
{
	(void)state;
	struct encpick_policy p = viewer;
	struct encpick e;
	p.offered = TCODEC_LOSSLESS_MASK; /* clipmapctl, or clipmapview --lossless */
	encpick(&p, PIX_COLOR, 8, 256, EARTH_A, 1 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_ZSTD);
	assert_int_equal(encpick_agreed(&p), 1u << TCODEC_ZSTD);
	p.offered = TCODEC_LOSSLESS_MASK | (1u << TCODEC_Q16); /* heights only */
	encpick(&p, PIX_COLOR, 8, 256, EARTH_A, 1 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_ZSTD);
	encpick(&p, PIX_HEIGHT, 8, 256, EARTH_A, 1 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_Q16);
	assert_int_equal(encpick_agreed(&p), (1u << TCODEC_ZSTD) | (1u << TCODEC_Q16));
	p = viewer;
	p.lossy_below_bps = 0; /* the daemon never goes lossy */
	encpick(&p, PIX_COLOR, 8, 256, EARTH_A, 1 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_ZSTD);
	assert_int_equal(encpick_agreed(&p), 1u << TCODEC_ZSTD);
	p = viewer;
	p.lossless = TCODEC_NONE; /* compress = none: no coding at all */
	encpick(&p, PIX_COLOR, 8, 256, EARTH_A, 1 * MBIT, &e);
	assert_int_equal(e.codec, TCODEC_NONE);
	assert_int_equal(encpick_agreed(&p), 0);
	assert_int_equal(encpick_agreed(&viewer),
			 (1u << TCODEC_ZSTD) | (1u << TCODEC_WEBP) | (1u << TCODEC_Q16));
}

static void step_follows_the_level(void **state)
{
	(void)state;
	struct encpick e;
	encpick(&viewer, PIX_HEIGHT, 8, 256, EARTH_A, 4 * MBIT, &e);
	double texel = M_PI * EARTH_A / (256.0 * 256.0); /* 306 m */
	assert_true(fabs(e.lossy.step - texel / 64) < 1e-9);
	assert_true(e.lossy.step > 4.7 && e.lossy.step < 4.8); /* heights within 2.4 m */
	encpick(&viewer, PIX_HEIGHT, 16, 256, EARTH_A, 4 * MBIT, &e);
	assert_true(e.lossy.step > 0.018 && e.lossy.step < 0.019);
	encpick(&viewer, PIX_HEIGHT, 16, 64, 1737400.0, 4 * MBIT, &e); /* the Moon, 64² tiles */
	assert_true(fabs(e.lossy.step - M_PI * 1737400.0 / (65536.0 * 64) / 64) < 1e-12);
}

int main(void)
{
	const struct CMUnitTest tests[] = {
		cmocka_unit_test(by_link_rate),
		cmocka_unit_test(only_what_was_offered),
		cmocka_unit_test(step_follows_the_level),
	};
	return cmocka_run_group_tests(tests, NULL, NULL);
}
