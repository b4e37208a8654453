/* render_write — the pictures render and tile write (see render.h), apart from the engine so
 * the online clipmapctl links them without it. */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include "common/errbuf.h"
#include "common/geoimg.h"
#include "common/img.h"
#include "common/xalloc.h"
#include "render.h"

static int ends_with(const char *s, const char *suffix)
{
	size_t a = strlen(s), b = strlen(suffix);
	return a >= b && strcasecmp(s + a - b, suffix) == 0;
}

int render_write(const struct render_image *im, const char *path, char note[256], char err[256])
{
	note[0] = '\0';
	int png = ends_with(path, ".png");
	if (!png && !ends_with(path, ".tif") && !ends_with(path, ".tiff") && !ends_with(path, ".exr")) {
		err_set(err, "%s: unknown picture type: use .png, .tif, .tiff or .exr", path);
		return -EINVAL;
	}
	if (im->georef && !png && !ends_with(path, ".exr")) {
		struct geoimg g = { .width = im->width, .height = im->height,
				    .channels = im->is_float ? 1 : im->channels,
				    .type = im->is_float ? IMG_F32 : IMG_U8, .pixels = im->pixels,
				    .bounds = &im->bounds };
		return geoimg_write(&g, GEOIMG_TIFF, path, err);
	}
	if (!im->is_float) {
		if (!png && ends_with(path, ".exr")) {
			err_set(err, "%s: colour and normal pictures are written as .png or .tif",
				path);
			return -EINVAL;
		}
		return img_write(path, im->width, im->height, im->channels, IMG_U8, im->pixels, err);
	}
	if (!png)
		return img_write(path, im->width, im->height, 1, IMG_F32, im->pixels, err);
	/* 16-bit PNG: map [hmin, hmax] onto [0, 65535] and say how to get metres back. */
	size_t n = (size_t)im->width * im->height;
	uint16_t *q = xmalloc(n * sizeof *q);
	const float *f = im->pixels;
	double lo = im->hmin, hi = im->hmax > im->hmin ? im->hmax : im->hmin + 1.0;
	double scale = (hi - lo) / 65535.0;
	for (size_t i = 0; i < n; i++)
		q[i] = (uint16_t)lrint((f[i] - lo) / scale);
	int rc = img_write(path, im->width, im->height, 1, IMG_U16, q, err);
	free(q);
	if (rc == 0)
		snprintf(note, 256, "heights %.2f .. %.2f m: metres = %.6f + value * %.9f", lo, hi, lo,
			 scale);
	return rc;
}

void render_image_free(struct render_image *im)
{
	free(im->pixels);
	im->pixels = NULL;
}
