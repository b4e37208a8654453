/* pixfmt — see pixfmt.h. */
#include "pixfmt.h"

#include <math.h>
#include <string.h>

size_t pix_bytes(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return 4;
	case PIX_COLOR: return 4;
	case PIX_NORMAL: return 2;
	default: return 0;
	}
}

const char *pix_type_name(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return "height";
	case PIX_COLOR: return "color";
	case PIX_NORMAL: return "normal";
	default: return "none";
	}
}

const char *pix_format_name(enum pix_type t)
{
	switch (t) {
	case PIX_HEIGHT: return "f32";
	case PIX_COLOR: return "rgba8";
	case PIX_NORMAL: return "rg8";
	default: return "none";
	}
}

enum pix_type pix_type_parse(const char *s)
{
	for (enum pix_type t = PIX_HEIGHT; t < PIX_COUNT; t++)
		if (strcmp(s, pix_type_name(t)) == 0)
			return t;
	return PIX_NONE;
}

enum pix_type pix_format_parse(const char *s)
{
	for (enum pix_type t = PIX_HEIGHT; t < PIX_COUNT; t++)
		if (strcmp(s, pix_format_name(t)) == 0)
			return t;
	return PIX_NONE;
}

void pix_normals_rgb(const unsigned char *rg, unsigned char *rgb, size_t n)
{
	for (size_t i = 0; i < n; i++) {
		double e = rg[2 * i] / 127.5 - 1.0, no = rg[2 * i + 1] / 127.5 - 1.0;
		double up2 = 1.0 - e * e - no * no;
		rgb[3 * i] = rg[2 * i];
		rgb[3 * i + 1] = rg[2 * i + 1];
		rgb[3 * i + 2] = (unsigned char)lrint(((up2 > 0 ? sqrt(up2) : 0) + 1.0) * 127.5);
	}
}
