#ifndef CLIPMAP_TESTS_SLOW_H
#define CLIPMAP_TESTS_SLOW_H
/* Deadlines in tests that wait for real work (a frame to complete, a viewer to finish) are
 * scaled by CLIPMAP_TEST_SLOW (a number ≥ 1, default 1): the sanitizer builds set it (make tsan:
 * 8, make asan: 2), since ThreadSanitizer makes synthesis and llvmpipe 5–15× slower. A deadline
 * is a bound on "never finishes", not a speed figure, so scaling it keeps the test's meaning. */
#include <stdlib.h>

static inline double test_slow(double seconds)
{
	const char *s = getenv("CLIPMAP_TEST_SLOW");
	double k = s ? strtod(s, NULL) : 1;
	return seconds * (k >= 1 ? k : 1);
}
#endif
