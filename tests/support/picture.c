/* picture — see picture.h. */
#include "picture.h"

#include <stddef.h>
#include <stdlib.h>

#include "common/img.h"

double picture_spread(const char *path)
{
	void *p;
	struct img_info in;
	if (img_read(path, IMG_U8, &p, &in, NULL) != 0)
		return -1;
	const unsigned char *x = p;
	int lo = 255, hi = 0;
	for (size_t i = 0; i < (size_t)in.width * in.height; i++) {
		int g = x[i * (size_t)in.channels + 1];
		lo = g < lo ? g : lo;
		hi = g > hi ? g : hi;
	}
	free(p);
	return hi - lo;
}
